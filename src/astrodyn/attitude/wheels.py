"""Reaction wheels: motor torques commanded per control step, saturation, and the body's motion.

Model (a gyrostat with torque-driven rotors; H. Baruh, *Analytical Dynamics*, ch. 10;
P. C. Hughes, *Spacecraft Attitude Dynamics*, ch. 7; B. Wie, *Space Vehicle Dynamics and
Control*, sec. 7.3).  Wheel ``k`` spins about the unit body axis ``a_k`` with axial
moment ``J_k`` (kg m^2).  Its *absolute* axial momentum ``h_k = J_k (a_k . w + Omega_k)``
(N m s; ``Omega_k`` its speed relative to the body, rad/s) obeys ``dh_k/dt = g_k``, the
motor torque on the wheel (N m); the body feels ``-g_k a_k``.  With ``inertia`` the
vehicle's tensor with the wheels held fixed (kg m^2, body axes),

    H = I_kin w + sum_k h_k a_k,     I_kin = inertia - sum_k J_k a_k a_k^T,

and ``dH/dt + w x H = tau_ext`` (body axes).  Over one control step the motor torques
are held (zero-order hold), so each ``h_k`` is linear in time and ``H = I_kin w + h(t)``
with a known ``h(t)``: exactly the form :func:`astrodyn.attitude.propagate_attitude`
integrates with exact rotations (``rotor_momentum=h(t)``), which keeps ``|q| = 1`` and
the inertial momentum of body plus wheels to round-off when ``tau_ext = 0``.

Saturation, applied to each command before the step (:meth:`ReactionWheels.saturate`):
the torque is clipped to ``|g_k| <= max_torque_k``, then so that the wheel's speed at
the end of the step, predicted with the body rate held (``Omega_k + g_k dt / J_k``),
stays within ``|Omega_k| <= max_speed_k``.  A wheel at its speed limit can still be
torqued back towards zero.  The prediction ignores the change of ``a_k . w`` over the
step; with control periods much shorter than the body's motion the overshoot is of
order ``J_k |dw| / J_k``, reported by :meth:`ReactionWheels.speeds` after the step.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["ReactionWheels", "WheelStep", "step_with_wheels"]


@dataclass(frozen=True, eq=False)
class ReactionWheels:
    """``n`` reaction wheels: unit spin ``axes`` (n, 3) in body axes, ``rotor_inertia``
    (n,) kg m^2, ``max_torque`` (n,) N m, ``max_speed`` (n,) rad/s (``inf`` for no limit)."""

    axes: np.ndarray
    rotor_inertia: np.ndarray
    max_torque: np.ndarray
    max_speed: np.ndarray

    def __post_init__(self):
        axes = np.atleast_2d(np.asarray(self.axes, dtype=np.float64))
        n = axes.shape[0]
        if axes.shape != (n, 3) or n == 0:
            raise ValueError(f"axes: expected (n, 3) unit vectors in body axes, got shape {axes.shape}")
        norms = np.linalg.norm(axes, axis=1)
        if not np.all(np.abs(norms - 1.0) <= 1e-9):
            raise ValueError(f"axes: expected unit vectors (|a| = 1 within 1e-9), got norms {norms.tolist()}")
        fields = {}
        for name in ("rotor_inertia", "max_torque", "max_speed"):
            x = np.broadcast_to(np.asarray(getattr(self, name), dtype=np.float64), (n,)).copy()
            if not np.all(x > 0) or np.any(np.isnan(x)):
                raise ValueError(f"{name}: expected {n} numbers > 0, got {x.tolist()}")
            if name == "rotor_inertia" and not np.all(np.isfinite(x)):
                raise ValueError(f"rotor_inertia: expected finite kg m^2, got {x.tolist()}")
            fields[name] = x
        object.__setattr__(self, "axes", axes)
        for name, x in fields.items():
            object.__setattr__(self, name, x)

    @property
    def n(self) -> int:
        return self.axes.shape[0]

    def kinematic_inertia(self, inertia) -> np.ndarray:
        """``I_kin = inertia - sum_k J_k a_k a_k^T`` (kg m^2): the body's part of ``H``."""
        inertia = np.asarray(inertia, dtype=np.float64)
        inertia = np.diag(inertia) if inertia.shape == (3,) else inertia
        return inertia - np.einsum("k,ki,kj->ij", self.rotor_inertia, self.axes, self.axes)

    def momentum(self, h) -> np.ndarray:
        """``sum_k h_k a_k`` (N m s, body axes) of absolute axial momenta ``h`` (..., n)."""
        return np.asarray(h, dtype=np.float64) @ self.axes

    def speeds(self, h, w) -> np.ndarray:
        """Wheel speeds relative to the body, ``Omega_k = h_k / J_k - a_k . w`` (rad/s)."""
        return np.asarray(h, dtype=np.float64) / self.rotor_inertia - np.asarray(w, dtype=np.float64) @ self.axes.T

    def absolute_momentum(self, speeds, w) -> np.ndarray:
        """``h_k = J_k (a_k . w + Omega_k)`` (N m s) from relative speeds (rad/s)."""
        return self.rotor_inertia * (np.asarray(w, dtype=np.float64) @ self.axes.T + np.asarray(speeds, dtype=np.float64))

    def saturate(self, torque, h, w, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """The motor torques applied for a step of ``dt`` s when ``torque`` (n,) N m is
        commanded (module docstring), and a boolean (n,) array: which were clipped."""
        cmd = np.asarray(torque, dtype=np.float64).reshape(self.n)
        if not np.all(np.isfinite(cmd)):
            raise ValueError(f"wheel torque: expected {self.n} finite numbers in N m, got {cmd.tolist()}")
        g = np.clip(cmd, -self.max_torque, self.max_torque)
        omega = self.speeds(h, w)
        end = omega + g * dt / self.rotor_inertia
        over = np.abs(end) > self.max_speed
        limit = np.sign(end) * self.max_speed
        g = np.where(over, (limit - omega) * self.rotor_inertia / dt, g)
        # never accelerate further when already beyond the limit (only back towards it)
        g = np.where(over & (np.sign(g) == np.sign(omega)) & (np.abs(omega) >= self.max_speed), 0.0, g)
        g = np.clip(g, -self.max_torque, self.max_torque)
        return g, g != cmd


@dataclass(frozen=True)
class WheelStep:
    """The state after one control step: body rates ``w`` (3,) rad/s, ``q`` (4,) scalar
    first, wheel absolute momenta ``h`` (n,) N m s, the motor torques applied ``torque``
    (n,) N m and which commands were ``clipped``."""

    w: np.ndarray
    q: np.ndarray
    h: np.ndarray
    torque: np.ndarray
    clipped: np.ndarray


def step_with_wheels(inertia, wheels: ReactionWheels, w, q, h, wheel_torque, dt: float, *,
                     external_torque=None, step: float | None = None, body=None) -> WheelStep:
    """Advance body and wheels by one control step of ``dt`` s with the motor torques
    ``wheel_torque`` (n,) N m held (after :meth:`ReactionWheels.saturate`).

    ``inertia`` (3,) or (3, 3) kg m^2 with the wheels held fixed; ``w`` (3,) rad/s, ``q``
    (4,) scalar first, ``h`` (n,) absolute wheel momenta N m s; ``external_torque`` a
    torque model ``torque(t, q, w) -> (3,)`` N m in body axes (e.g.
    :class:`~astrodyn.attitude.torques.ConstantTorque`), with ``t`` from 0 at the start of
    the step; ``step`` the splitting step (default: the integrator's).  ``body``: a
    :class:`astrodyn.attitude.integrators.HeldInputsBody` of the kinematic inertia, set up
    once by a caller that steps the same body many times.  No torque or a constant body
    torque run the compiled held-input step (about 10 us per call instead of 200 us);
    other torque models the general :func:`astrodyn.attitude.propagate_attitude`.
    """
    from astrodyn.attitude.integrators import HeldInputsBody, propagate_attitude
    from astrodyn.attitude.torques import ConstantTorque

    if not dt > 0 or not np.isfinite(dt):
        raise ValueError(f"dt: expected a finite control step > 0 s, got {dt!r}")
    h0 = np.asarray(h, dtype=np.float64).reshape(wheels.n)
    g, clipped = wheels.saturate(wheel_torque, h0, w, dt)
    axes = wheels.axes
    if external_torque is None or (type(external_torque) is ConstantTorque and external_torque.frame == "body"):
        # held inputs: the compiled step (same splitting, stages and rotor values as below)
        body = body or HeldInputsBody(wheels.kinematic_inertia(inertia))
        tau = None if external_torque is None else external_torque.torque
        w1, q1 = body.step_held(w, q, float(dt), tau=tau, h0=h0 @ axes, hdot=g @ axes, step=step)
        return WheelStep(w1, q1, h0 + g * dt, g, clipped)

    def rotor(t):
        t = np.asarray(t, dtype=np.float64)
        return (h0 + g * t[..., None]) @ axes

    w1, q1, _ = propagate_attitude(wheels.kinematic_inertia(inertia), w, q, float(dt), torque=external_torque,
                                   rotor_momentum=rotor, method="split4", step=step, error_estimate=False)
    return WheelStep(np.asarray(w1), np.asarray(q1), h0 + g * dt, g, clipped)
