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

Saturation, applied to each command before the step (:meth:`ReactionWheels.saturate`),
only ever reduces a command (never reverses or increases it): the torque is clipped to
``|g_k| <= max_torque_k``, then into ``[lb_k, ub_k]`` with

    ub_k = max(0, (max_speed_k - Omega_k) J_k / dt),   lb_k = min(0, (-max_speed_k - Omega_k) J_k / dt),

so that the wheel's speed at the end of the step, predicted with the body rate held
(``Omega_k + g_k dt / J_k``), stays within ``|Omega_k| <= max_speed_k``.  A wheel at its
speed limit can still be torqued back towards zero.  The prediction ignores the change of
``a_k . w`` over the step, so a wheel may end a step beyond its limit (by about
``|a_k . dw|``, reported by :meth:`ReactionWheels.speeds` after the step); such a wheel
gets no torque that would speed it up further, and a command towards zero is applied as
commanded (after the torque limit): the bounds never make up a braking torque nobody
asked for.  A command of 0 is applied as 0, and the clipped wheels are exactly those whose
applied torque differs from the command.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from astrodyn.attitude.integrators import MAX_STEPS, SPLIT4_WEIGHTS, HeldInputsBody, checked_max_steps, held_torque_step
from astrodyn.inputs import real_scalar
from astrodyn.jit import jit
from astrodyn.rotation import quat_hamilton_scalar

__all__ = ["ReactionWheels", "WheelStep", "step_with_wheels", "HeldInputsBatch"]


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
        J, ms = self.rotor_inertia, self.max_speed
        end = omega + g * dt / J
        # clip(g, lb, ub) (module docstring), written so that a wheel predicted within its
        # limit keeps g as it is (lb <= g <= ub there); the same comparisons as _saturate_row
        # (the batch's: the same floats for the same speeds, signed zeros included)
        ub, lb = (ms - omega) * J / dt, (-ms - omega) * J / dt
        ub, lb = np.where(ub > 0.0, ub, 0.0), np.where(lb < 0.0, lb, 0.0)
        g = np.where(end > ms, np.where(g < ub, g, ub), np.where(end < -ms, np.where(g > lb, g, lb), g))
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
                     external_torque=None, step: float | None = None, body=None,
                     max_steps: int = MAX_STEPS) -> WheelStep:
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

    ``dt`` and ``step``: finite and > 0 (``ValueError`` naming them).  ``max_steps``: the
    most splitting steps the call may take (as :func:`propagate_attitude`'s): a ``dt`` that
    needs more is refused before any work, with a ``ValueError`` naming the step and the
    number of steps it would need.
    """
    from astrodyn.attitude.integrators import propagate_attitude
    from astrodyn.attitude.torques import ConstantTorque

    dt = real_scalar(dt, "dt", "step_with_wheels")
    if not dt > 0 or not np.isfinite(dt):
        raise ValueError(f"dt: expected a finite control step > 0 s, got {dt!r}")
    if step is not None:
        step = real_scalar(step, "step", "step_with_wheels")
        if not (step > 0.0 and math.isfinite(step)):
            raise ValueError(f"step: expected a finite splitting step > 0 s, got {step!r}")
    max_steps = checked_max_steps(max_steps)
    h0 = np.asarray(h, dtype=np.float64).reshape(wheels.n)
    g, clipped = wheels.saturate(wheel_torque, h0, w, dt)
    axes = wheels.axes
    if external_torque is None or (type(external_torque) is ConstantTorque and external_torque.frame == "body"):
        # held inputs: the compiled step (same splitting, stages and rotor values as below)
        body = body or HeldInputsBody(wheels.kinematic_inertia(inertia))
        tau = None if external_torque is None else external_torque.torque
        w1, q1 = body.step_held(w, q, dt, tau=tau, h0=h0 @ axes, hdot=g @ axes, step=step, max_steps=max_steps)
        return WheelStep(w1, q1, h0 + g * dt, g, clipped)

    def rotor(t):
        t = np.asarray(t, dtype=np.float64)
        return (h0 + g * t[..., None]) @ axes

    w1, q1, _ = propagate_attitude(wheels.kinematic_inertia(inertia), w, q, dt, torque=external_torque,
                                   rotor_momentum=rotor, method="split4", step=step, error_estimate=False,
                                   max_steps=max_steps)
    return WheelStep(np.asarray(w1), np.asarray(q1), h0 + g * dt, g, clipped)


# ---------------------------------------------------------------------------------------
# Many bodies at once: the closed loop's plant steps all its bodies in one compiled call


@jit(inline="always")
def _clip(x, limit):
    return min(max(x, -limit), limit)


@jit
def _saturate_row(axes, J, max_torque, max_speed, n, w, h, cmd, dt, g, clipped):
    """:meth:`ReactionWheels.saturate` of one body's ``n`` first wheels, into ``g``, ``clipped``."""
    for k in range(n):
        a0, a1, a2 = axes[k, 0], axes[k, 1], axes[k, 2]
        mt, ms, jk = max_torque[k], max_speed[k], J[k]
        gk = _clip(cmd[k], mt)
        omega = h[k] / jk - (w[0] * a0 + w[1] * a1 + w[2] * a2)
        end = omega + gk * dt / jk
        if end > ms:  # clip(gk, lb, ub): only ever towards 0 (ReactionWheels.saturate)
            ub = (ms - omega) * jk / dt
            ub = ub if ub > 0.0 else 0.0
            gk = gk if gk < ub else ub
        elif end < -ms:
            lb = (-ms - omega) * jk / dt
            lb = lb if lb < 0.0 else 0.0
            gk = gk if gk > lb else lb
        g[k] = gk
        clipped[k] = gk != cmd[k]


@jit(inline="always")
def _to_p(P, identity, v0, v1, v2, out):
    """``out = v @ P`` (body -> principal axes)."""
    if identity:
        out[0], out[1], out[2] = v0, v1, v2
    else:
        for j in range(3):
            out[j] = v0 * P[0, j] + v1 * P[1, j] + v2 * P[2, j]


@jit
def _default_step(P, identity, moments, min_moment, w, i):
    """:meth:`HeldInputsBody.step_held`'s default splitting step of row ``i`` (s): 1/60 of
    its fastest natural period, from its body rates at the start of the step (the body's
    own momentum ``I w``; the wheels' part cancels in ``M - h0``)."""
    wp = np.empty(3)
    _to_p(P[i], identity[i], w[i, 0], w[i, 1], w[i, 2], wp)
    d0, d1, d2 = moments[i, 0] * wp[0], moments[i, 1] * wp[1], moments[i, 2] * wp[2]
    rate = max(abs(wp[0]), abs(wp[1]), abs(wp[2]), math.sqrt(d0 * d0 + d1 * d1 + d2 * d2) / min_moment[i])
    return 0.1 if not rate > 0 else 2.0 * math.pi / (60.0 * rate)


@jit
def _step_many(P, r, identity, moments, min_moment, axes, J, max_torque, max_speed, n_wheels,
               w, q, h, cmd, tau, dt, weights, g, clipped, max_steps):
    """Every row ``i``: saturate the wheel commands, then one held-input step of ``dt`` s
    (:meth:`HeldInputsBody.step_held` with ``h0 = h @ axes``, ``hdot = g @ axes``);
    ``w``, ``q``, ``h`` updated in place.  Returns -1; or, before touching any row, the
    first row whose default step would need more than ``max_steps`` splitting steps."""
    for i in range(w.shape[0]):
        if not dt / _default_step(P, identity, moments, min_moment, w, i) <= max_steps:
            return i
    M, qp, h0p, hdp, taup = np.empty(3), np.empty(4), np.empty(3), np.empty(3), np.empty(3)
    for i in range(w.shape[0]):
        nw = n_wheels[i]
        _saturate_row(axes[i], J[i], max_torque[i], max_speed[i], nw, w[i], h[i], cmd[i], dt, g[i], clipped[i])
        hb0 = hb1 = hb2 = 0.0
        gb0 = gb1 = gb2 = 0.0
        for k in range(nw):
            hb0 += h[i, k] * axes[i, k, 0]
            hb1 += h[i, k] * axes[i, k, 1]
            hb2 += h[i, k] * axes[i, k, 2]
            gb0 += g[i, k] * axes[i, k, 0]
            gb1 += g[i, k] * axes[i, k, 1]
            gb2 += g[i, k] * axes[i, k, 2]
        Pi, ident, mom = P[i], identity[i], moments[i]
        _to_p(Pi, ident, hb0, hb1, hb2, h0p)
        _to_p(Pi, ident, gb0, gb1, gb2, hdp)
        _to_p(Pi, ident, tau[i, 0], tau[i, 1], tau[i, 2], taup)
        _to_p(Pi, ident, w[i, 0], w[i, 1], w[i, 2], M)
        wp0, wp1, wp2 = M[0], M[1], M[2]
        for j in range(3):
            M[j] = mom[j] * M[j] + h0p[j]
        if ident:
            qp[0], qp[1], qp[2], qp[3] = q[i, 0], q[i, 1], q[i, 2], q[i, 3]
        else:  # quat_multiply(r, q)
            qp[0], qp[1], qp[2], qp[3] = quat_hamilton_scalar(q[i, 0], q[i, 1], q[i, 2], q[i, 3],
                                                              r[i, 0], r[i, 1], r[i, 2], r[i, 3])
        d0, d1, d2 = M[0] - h0p[0], M[1] - h0p[1], M[2] - h0p[2]
        rate = max(abs(wp0), abs(wp1), abs(wp2), math.sqrt(d0 * d0 + d1 * d1 + d2 * d2) / min_moment[i])
        step = 0.1 if not rate > 0 else 2.0 * math.pi / (60.0 * rate)
        n_sub = max(1, int(math.ceil(abs(dt) / step)))
        held_torque_step(M, qp, mom, weights, dt, n_sub, taup, h0p, hdp)
        v0 = (M[0] - (h0p[0] + hdp[0] * dt)) / mom[0]
        v1 = (M[1] - (h0p[1] + hdp[1] * dt)) / mom[1]
        v2 = (M[2] - (h0p[2] + hdp[2] * dt)) / mom[2]
        if ident:
            w[i, 0], w[i, 1], w[i, 2] = v0, v1, v2
            q[i, 0], q[i, 1], q[i, 2], q[i, 3] = qp[0], qp[1], qp[2], qp[3]
        else:  # v @ P.T, quat_multiply(r_inv, qp)
            for j in range(3):
                w[i, j] = v0 * Pi[j, 0] + v1 * Pi[j, 1] + v2 * Pi[j, 2]
            q[i, 0], q[i, 1], q[i, 2], q[i, 3] = quat_hamilton_scalar(qp[0], qp[1], qp[2], qp[3],
                                                                      r[i, 0], -r[i, 1], -r[i, 2], -r[i, 3])
        for k in range(nw):
            h[i, k] += g[i, k] * dt
    return -1


class HeldInputsBatch:
    """Many bodies (gyrostats with up to ``m`` reaction wheels each, or plain rigid bodies)
    stepped under held inputs in one compiled call: per row what :func:`step_with_wheels`
    does with a constant body torque (or none), with :class:`HeldInputsBody`'s splitting
    and default step.  The same operations in the same order, summed as written (no BLAS),
    so it agrees with the one-body path to round-off.

    ``inertias``: each body's tensor with its wheels held fixed (3, 3) kg m^2;
    ``wheels``: each body's :class:`ReactionWheels` or None.
    """

    def __init__(self, inertias, wheels):
        n = len(inertias)
        m = max([0] + [wh.n for wh in wheels if wh is not None])
        self.n, self.m = n, m
        self.P, self.r = np.empty((n, 3, 3)), np.empty((n, 4))
        self.identity = np.empty(n, dtype=np.bool_)
        self.moments, self.min_moment = np.empty((n, 3)), np.empty(n)
        self.axes = np.zeros((n, m, 3))
        self.J, self.max_torque, self.max_speed = np.ones((n, m)), np.ones((n, m)), np.ones((n, m))
        self.n_wheels = np.zeros(n, dtype=np.int64)
        for i, (inertia, wh) in enumerate(zip(inertias, wheels)):
            body = HeldInputsBody(inertia if wh is None else wh.kinematic_inertia(inertia))
            f = body.frame
            self.P[i], self.r[i], self.identity[i] = f.P, f.r, f.identity
            self.moments[i], self.min_moment[i] = f.moments, body._min_moment
            if wh is not None:
                k = self.n_wheels[i] = wh.n
                self.axes[i, :k], self.J[i, :k] = wh.axes, wh.rotor_inertia
                self.max_torque[i, :k], self.max_speed[i, :k] = wh.max_torque, wh.max_speed

    def wheel_speeds(self, rows, w, h) -> np.ndarray:
        """:meth:`ReactionWheels.speeds` of the bodies ``rows``: ``w`` (k, 3) rad/s, ``h`` (k, m)
        N m s; (k, m) rad/s (columns past a body's wheels: meaningless)."""
        rows = np.asarray(rows, dtype=np.int64)
        axes = self.axes[rows]
        w = np.asarray(w, dtype=np.float64)
        return np.asarray(h, dtype=np.float64) / self.J[rows] - (w[:, None, 0] * axes[:, :, 0] + w[:, None, 1] * axes[:, :, 1]
                                                                   + w[:, None, 2] * axes[:, :, 2])

    def step(self, rows, w, q, h, wheel_torque, torque, dt: float,
             max_steps: int = MAX_STEPS) -> tuple[np.ndarray, np.ndarray]:
        """Advance the bodies ``rows`` (k,) int by ``dt`` s, in place: body rates ``w`` (k, 3)
        rad/s, ``q`` (k, 4), absolute wheel momenta ``h`` (k, m) N m s (columns past a body's
        wheels ignored), with the motor torque commands ``wheel_torque`` (k, m) N m (saturated
        here) and the body torque ``torque`` (k, 3) N m held.  Returns the motor torques
        applied (k, m) and which commands were clipped (k, m) bool.

        ``max_steps``: the most splitting steps one body's ``dt`` may take (as
        :meth:`HeldInputsBody.step_held`'s): when a body's rates are so high that its default
        step (1/60 of its fastest natural period) would need more, nothing is stepped and a
        ``ValueError`` names the row and the steps it would need."""
        if not dt > 0 or not np.isfinite(dt):
            raise ValueError(f"dt: expected a finite control step > 0 s, got {dt!r}")
        max_steps = checked_max_steps(max_steps)
        cmd = np.ascontiguousarray(wheel_torque, dtype=np.float64)
        if not np.all(np.isfinite(cmd)):
            raise ValueError("wheel torque: expected finite numbers in N m")
        rows = np.asarray(rows, dtype=np.int64)
        g = np.zeros((rows.shape[0], self.m))
        clipped = np.zeros((rows.shape[0], self.m), dtype=np.bool_)
        P, identity, moments, min_moment = self.P[rows], self.identity[rows], self.moments[rows], self.min_moment[rows]
        bad = _step_many(P, self.r[rows], identity, moments, min_moment, self.axes[rows], self.J[rows],
                         self.max_torque[rows], self.max_speed[rows], self.n_wheels[rows], w, q, h, cmd, np.ascontiguousarray(torque, dtype=np.float64),
                         float(dt), SPLIT4_WEIGHTS, g, clipped, max_steps)
        if bad >= 0:
            step = _default_step(P, identity, moments, min_moment, w, bad)
            raise ValueError(f"row {bad} (body {int(rows[bad])}): step {step:.6g} s (the default: 1/60 of the fastest "
                             f"natural period) over dt = {dt:.6g} s needs {math.ceil(dt / step):.6g} steps, more than "
                             f"max_steps={max_steps}; its rates are too high for the held-input step")
        return g, clipped
