"""External torques on a rigid body, as callables ``torque(t, q, w) -> body torque``.

Every torque model here is a small object with the hook signature of
:mod:`astrodyn.attitude.euler`: ``model(t, q, w)`` returns the torque in **body**
components (N m) for time ``t`` (s), Euler parameters ``q`` (scalar first,
``v_body = C(q) @ v_inertial``) and body rates ``w`` (rad/s).  The models below
depend only on ``(t, q)``, which lets :func:`astrodyn.attitude.integrators.propagate_attitude`
apply them as exact momentum kicks inside its compiled kernel; any other callable
works too (through a slower Python path).

* :class:`GravityGradientTorque`: ``tau = 3 mu / |r|^5  r_b x (I r_b)`` with
  ``r_b = C r`` the orbit position (from the attracting body's centre to the
  spacecraft) in body axes.  Baruh, *Analytical Dynamics*, sec. 8.x
  (gravity-gradient moment); Hughes, *Spacecraft Attitude Dynamics*, ch. 8,
  eq. (8.1.x).  The position comes from a callable ``r(t)``, e.g. the orbit core
  ``lambda t: astrodyn.orbit.propagate(r0, v0, t, mu)[0]``, or for a two-body
  orbit :meth:`GravityGradientTorque.kepler` (evaluated inside the compiled
  integrator kernel).
* :class:`UniformGravityTorque`: a uniform field acting at a body-fixed centre of
  mass, ``tau = r_c x (C m g)`` about a fixed point (the heavy top, Baruh 10.5).
* :class:`ConstantTorque`: fixed in body or in inertial axes.
* :class:`TorqueSum`: the sum of several models.
"""

from __future__ import annotations

import math

import numpy as np

from astrodyn.attitude.euler import inertia_tensor
from astrodyn.inputs import real_array, real_scalar
from astrodyn.rotation import quat_rotate

__all__ = [
    "gravity_gradient_torque",
    "GravityGradientTorque",
    "UniformGravityTorque",
    "ConstantTorque",
    "TorqueSum",
]


def gravity_gradient_torque(r_body, inertia, mu):
    """Gravity-gradient torque ``3 mu / |r|^5 (r_b x I r_b)`` in body axes (N m).

    ``r_body`` ``(..., 3)``: position of the body's centre of mass relative to the
    attracting centre, in body components (m); ``inertia`` ``(3,)`` principal
    moments or ``(3, 3)`` tensor about the centre of mass (kg m^2, checked by
    :func:`~astrodyn.attitude.euler.inertia_tensor`); ``mu`` gravitational parameter
    (m^3/s^2), one number > 0, as :class:`GravityGradientTorque` requires.  First-order
    term of the expansion of the gravity field over the body (Hughes, ch. 8; Baruh ch. 8).
    """
    who = "gravity_gradient_torque"
    rb = _vector(r_body, "r_body", "(..., 3) position in m", who)
    return _gravity_gradient(rb, inertia_tensor(inertia), _checked_mu(mu, who))


def _vector(x, name, what, who, batch=True):
    """``x`` as float64 of shape ``(..., 3)`` (``batch``) or ``(3,)``; ValueError naming ``name``."""
    a = real_array(x, name, who)
    if (a.shape[-1:] != (3,)) if batch else (a.shape != (3,)):
        raise ValueError(f"{name}: expected a {what}, got shape {a.shape}")
    return a


def _checked_mu(mu, who):
    mu = real_scalar(mu, "mu", who)
    if not mu > 0.0:
        raise ValueError(f"mu: expected a positive gravitational parameter in m^3/s^2, got {mu}")
    return mu


def _gravity_gradient(rb, J, mu):
    r2 = np.sum(rb * rb, axis=-1, keepdims=True)
    return 3.0 * mu / (r2 * r2 * np.sqrt(r2)) * np.cross(rb, rb @ J.T)


class GravityGradientTorque:
    """Gravity-gradient torque from an orbit ``r(t)``.

    Parameters
    ----------
    mu : float
        Gravitational parameter of the attracting body, m^3/s^2.
    position : callable
        ``position(t) -> r`` inertial position of the spacecraft (m) relative to
        the attracting centre; must accept a 1-D array of times and return
        ``(len(t), 3)`` (the integrator evaluates all kick times at once; a torque
        asked at one time, as by ``method="dop853"``, passes a 1-element array).
    inertia : array_like
        ``(3,)`` principal moments or ``(3, 3)`` tensor in body axes, kg m^2
        (the full mass distribution, rotors included).

    For a two-body (Kepler) orbit use :meth:`kepler` instead: the integrator then
    evaluates the position inside its compiled kernel (exact universal-variable
    Lagrange coefficients of :mod:`astrodyn.orbit.universal` at nodes a few
    seconds apart, quintic Hermite in between, below round-off), 2.5-4x cheaper
    per step than a ``position`` that calls :func:`astrodyn.orbit.propagate`
    (measured 125 vs 480 ns per ``split2`` step, 558 vs 1404 per ``split4`` step,
    LEO, 10 ms steps).
    """

    def __init__(self, mu, position, inertia):
        if not callable(position):
            raise ValueError("position: expected a callable r(t) -> (..., 3) inertial position in m")
        self.mu = _checked_mu(mu, "GravityGradientTorque")
        self.position = position
        self.inertia = inertia_tensor(inertia)
        self.orbit = None  # (r0, v0, t0) of a Kepler orbit, see kepler()

    @classmethod
    def kepler(cls, mu, r0, v0, inertia, t0=0.0):
        """Gravity gradient along the two-body orbit through ``(r0, v0)`` at time ``t0``.

        ``r0`` (m), ``v0`` (m/s): inertial state ``(3,)`` relative to the
        attracting centre at ``t = t0`` (s, on the integrator's clock); ``mu``
        m^3/s^2 is used for both the orbit and the torque.  ``r(t)`` is
        :func:`astrodyn.orbit.propagate` ``(r0, v0, t - t0, mu)`` (every conic).
        """
        from astrodyn.orbit.universal import propagate

        who = "GravityGradientTorque.kepler"
        r0 = np.array(real_array(r0, "r0", who), dtype=np.float64).reshape(-1)
        v0 = np.array(real_array(v0, "v0", who), dtype=np.float64).reshape(-1)
        if r0.shape != (3,) or v0.shape != (3,):
            raise ValueError(f"r0, v0: expected inertial position (3,) m and velocity (3,) m/s, got {r0.shape} and {v0.shape}")
        t0 = real_scalar(t0, "t0", who)
        mu = _checked_mu(mu, who)

        def position(t):
            return propagate(r0, v0, np.asarray(t, dtype=np.float64) - t0, mu)[0]

        model = cls(mu, position, inertia)
        model.orbit = (r0, v0, t0)
        return model

    def shifted(self, dt):
        """The same torque on a clock that starts ``dt`` seconds later: ``model_new(t) = model(t + dt)``."""
        if self.orbit is not None:
            r0, v0, t0 = self.orbit
            return GravityGradientTorque.kepler(self.mu, r0, v0, self.inertia, t0 - dt)
        position = self.position
        return GravityGradientTorque(self.mu, lambda t: position(np.asarray(t, dtype=np.float64) + dt), self.inertia)

    def __call__(self, t, q, w=None):
        # position takes a 1-D array of times (class docstring), also when one scalar t is
        # asked (propagate_attitude's dop853 and the Python torque path do): (1, 3) -> (3,)
        t = np.asarray(t, dtype=np.float64)
        r = np.asarray(self.position(np.atleast_1d(t)), dtype=np.float64)
        if t.ndim == 0:
            r = r.reshape(3)
        return _gravity_gradient(quat_rotate(q, r), self.inertia, self.mu)


class UniformGravityTorque:
    """Torque of a uniform gravity field about a fixed point: ``tau = r_c x (m C g)``.

    ``mass`` kg, finite and >= 0 (0: no torque, as a massless
    :class:`~astrodyn.attitude.top.HeavyTop`); ``center_of_mass`` ``(3,)`` position of the centre of mass
    relative to the fixed point, body axes (m); ``gravity`` ``(3,)`` field in
    inertial axes (m/s^2), default ``(0, 0, -9.80665)`` (inertial Z up).
    For the heavy symmetric top of Baruh sec. 10.5 ``center_of_mass = (0, 0, l)``.
    """

    def __init__(self, mass, center_of_mass, gravity=(0.0, 0.0, -9.80665)):
        self.mass = real_scalar(mass, "mass", "UniformGravityTorque")
        if not (math.isfinite(self.mass) and self.mass >= 0.0):
            raise ValueError(f"mass: expected a finite non-negative mass in kg, got {self.mass}")
        self.center_of_mass = _vector(center_of_mass, "center_of_mass", "(3,) body vector in m", "UniformGravityTorque", batch=False)
        self.gravity = _vector(gravity, "gravity", "(3,) inertial field in m/s^2", "UniformGravityTorque", batch=False)

    def __call__(self, t, q, w=None):
        return np.cross(self.center_of_mass, self.mass * quat_rotate(q, self.gravity))


class ConstantTorque:
    """A constant torque ``(3,)`` N m, fixed in ``frame="body"`` or ``"inertial"`` axes."""

    def __init__(self, torque, frame="body"):
        if frame not in ("body", "inertial"):
            raise ValueError(f"frame: expected 'body' or 'inertial', got {frame!r}")
        self.torque = _vector(torque, "torque", "(3,) torque in N m", "ConstantTorque", batch=False)
        self.frame = frame

    def __call__(self, t, q, w=None):
        if self.frame == "body":
            return np.broadcast_to(self.torque, np.shape(q)[:-1] + (3,)).copy()
        return quat_rotate(q, self.torque)


class TorqueSum:
    """Sum of torque models (each a callable ``torque(t, q, w)``)."""

    def __init__(self, *models):
        self.models = tuple(models)
        for m in self.models:
            if not callable(m):
                raise ValueError(f"TorqueSum: every term must be callable torque(t, q, w), got {m!r}")

    def __call__(self, t, q, w=None):
        return sum(m(t, q, w) for m in self.models)
