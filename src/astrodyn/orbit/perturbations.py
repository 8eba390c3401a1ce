"""Perturbing accelerations and the numerical propagator for perturbed scenes.

A scene declares its perturbations as small frozen objects, and
:func:`propagate_perturbed` integrates only when there is something to
integrate::

    from astrodyn.orbit.perturbations import EARTH_EGM2008, ThirdBody, KeplerOrbit, propagate_perturbed

    j2 = EARTH_EGM2008.zonal(degree=2)                 # Zonal(mu, R, J=(J2,))
    moon = ThirdBody(MOON.mu, KeplerOrbit(r_moon, v_moon, EARTH_EGM2008.mu + MOON.mu))
    out = propagate_perturbed(r0, v0, t, EARTH_EGM2008.mu, [j2, moon], method="cowell")
    out.r, out.v, out.error_r        # (..., len(t), 3), (..., len(t), 3), (..., len(t))

An empty perturbation list (or only trivial ones: all ``J = 0``, ``mu3 = 0``)
delegates to the exact two-body :func:`astrodyn.orbit.propagate` and says so
(``out.method == "kepler"``, ``out.integrated is False``).

Conventions: SI units (m, s, m^3/s^2); positions relative to the central body
in an inertial frame whose z axis is the body's pole (for the zonal terms);
times ``t`` in seconds since the epoch of ``(r0, v0)``, and every
time-dependent perturbation is evaluated on that same time axis.

Perturbation models
-------------------
``Zonal(mu, R, J=(J2, J3, ..., Jn))``: the axisymmetric part of the body's
field.  Potential (gravitational potential ``V``, acceleration ``= grad V``)::

    V = mu / r  -  (mu / r) sum_n J_n (R / r)^n P_n(z / r)

and its gradient, term by term (derived by differentiating; matches Vallado,
4th ed., eq. 8-30 for J2 and Montenbruck & Gill, *Satellite Orbits*, sec. 3.2)::

    a_n = (mu / r^2) J_n (R / r)^n [((n + 1) P_n(s) + s P_n'(s)) r_hat - P_n'(s) z_hat],  s = z / r

with ``P_n`` and ``P_n'`` from Bonnet's recurrence (exact polynomials, no
trigonometry).  J2 alone takes a fast path, the classic
``a = -(3/2) J2 mu R^2 / r^5 [x (1 - 5 z^2/r^2), y (1 - 5 z^2/r^2), z (3 - 5 z^2/r^2)]``.

``ThirdBody(mu3, r3_of_t)``: a point mass ``mu3`` at ``s = r3_of_t(t)``
(relative to the central body); the acceleration of the satellite relative to
the central body is the direct minus the indirect term,
``mu3 [(s - r)/|s - r|^3 - s/|s|^3]``, evaluated with Battin's ``f(q)``
(Battin, *An Introduction to the Mathematics and Methods of Astrodynamics*,
rev. ed. 1999, sec. 8.4, eqs. 8.55-8.61) so that the two nearly equal terms
never get subtracted::

    a3 = -mu3 / |s - r|^3 (r + f(q) s),  q = r.(r - 2 s) / s.s,
    f(q) = (1 + q)^{3/2} - 1 = q (3 + 3 q + q^2) / (1 + (1 + q)^{3/2})

``r3_of_t`` is any callable ``t -> (3,)``, e.g. a :class:`KeplerOrbit` (the
third body on an exact conic relative to the central body).

Any other object with a method ``acceleration(t, r, v) -> (..., 3)`` works as
a perturbation too (``t`` a float, ``r, v`` shape ``(N, 3)``).

Propagator
----------
``method="cowell"`` integrates ``r'' = -mu r/|r|^3 + sum a_p`` directly;
``method="encke"`` integrates only the deviation ``delta`` from an osculating
Kepler reference ``rho(t)`` (exact, from ``astrodyn.orbit.propagate``)::

    delta'' = -(mu / |r|^3) (delta - f(q) rho) + sum a_p(t, rho + delta),  q = delta.(delta + 2 rho) / rho.rho

(Battin sec. 9.3, Encke's method: the same ``f(q)`` removes the cancellation of the
two nearly equal central-body terms), and *rectifies* (restarts the reference
from the current osculating state, ``delta = 0``) when
``|delta| / |rho|`` exceeds ``rectify_ratio``.

Both use scipy's DOP853 (Dormand-Prince 8(5,3), Hairer, Norsett & Wanner,
*Solving ODEs I*, sec. II.10), stepped by hand so output times come from its
dense output and the Encke reference can be rectified between steps.  Several
bodies sharing the times are stacked into one ODE system; each body's
position is scaled by its own ``|r0|`` and its velocity by
``sqrt(mu / |r0|)``, so ``rtol`` and ``atol`` are dimensionless (``atol``: a
fraction of the body's initial radius / circular speed) and comparable across
bodies.  scipy's error norm is the RMS over all components, which would
dilute one body's error by ``sqrt(N)``, so the tolerances passed to DOP853
are divided by ``sqrt(N)`` (floored at scipy's minimum rtol, 100 eps).

Error estimate: the integration is repeated with 10x looser tolerances and
``error_r, error_v`` are ``|tight - loose|`` at each output; for a convergent
method this bounds the returned (tight) solution's error conservatively (by
about the tolerance ratio).  ``error_estimate=False`` skips the second run.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np

from astrodyn.inputs import broadcast_named, real_array, real_scalar
from astrodyn.jit import jit
from astrodyn.orbit.universal import propagate, propagate_rows

__all__ = [
    "CentralBody",
    "EARTH_EGM2008",
    "EARTH_WGS84",
    "MOON",
    "SUN",
    "Zonal",
    "ThirdBody",
    "KeplerOrbit",
    "PerturbedStates",
    "zonal_acceleration",
    "zonal_potential",
    "third_body_acceleration",
    "point_mass_difference",
    "propagate_perturbed",
]


# --------------------------------------------------------------------------- constants


def _j_from_normalized(cbar_n0: float, n: int) -> float:
    """Unnormalized zonal J_n = -sqrt(2n + 1) * C̄_n0 (fully normalized, Kaula)."""
    return -math.sqrt(2.0 * n + 1.0) * cbar_n0


@dataclass(frozen=True)
class CentralBody:
    """Constants of an attracting body: ``mu`` (m^3/s^2), equatorial reference
    radius ``radius`` (m), zonal coefficients ``J = (J2, J3, ...)``
    (unnormalized, dimensionless) and where they come from."""

    name: str
    mu: float
    radius: float
    J: tuple[float, ...] = ()
    source: str = ""

    def zonal(self, degree: int | None = None) -> Zonal:
        """A :class:`Zonal` perturbation with ``J2 .. J_degree`` (all if None).

        ``degree``: an int from 2 to the body's highest (``len(J) + 1``); ``TypeError``
        naming it for a float, a bool or anything else that is not an int, ``ValueError``
        naming it and the range for an int outside it (a body without zonals takes only None)."""
        if degree is None:
            return Zonal(self.mu, self.radius, self.J)
        top = len(self.J) + 1
        allowed = f"an int from 2 to {top} ({self.name} has J2..J{top})" if self.J else \
            f"None ({self.name} has no zonal coefficients)"
        if isinstance(degree, (bool, np.bool_)) or not isinstance(degree, (int, np.integer)):
            raise TypeError(f"zonal: degree: expected {allowed}, got {degree!r}")
        if not 2 <= degree <= top:
            raise ValueError(f"zonal: degree: expected {allowed}, got {int(degree)}")
        return Zonal(self.mu, self.radius, self.J[: int(degree) - 1])


EARTH_EGM2008 = CentralBody(
    "Earth (EGM2008)",
    mu=3.986004415e14,
    radius=6378136.3,
    J=tuple(
        _j_from_normalized(c, n)
        for n, c in (
            (2, -0.484165143790815e-03),
            (3, 0.957161207093473e-06),
            (4, 0.539965866638991e-06),
            (5, 0.686702913736681e-07),
            (6, -0.149953927978527e-06),
        )
    ),
    source=(
        "EGM2008 (Pavlis et al. 2012, JGR 117, B04406), tide-free, NGA coefficient file "
        "EGM2008_to2190_TideFree: GM = 3.986004415e14 m^3/s^2, a = 6378136.3 m, fully normalized "
        "C20..C60 converted by J_n = -sqrt(2n+1) C_n0 (J2 = 1.0826262e-3, tide-free)"
    ),
)

EARTH_WGS84 = CentralBody(
    "Earth (WGS84)",
    mu=3.986004418e14,
    radius=6378137.0,
    J=(_j_from_normalized(-0.484166774985e-03, 2),),
    source="NGA.STND.0036 WGS84 (2014), Table 3.1/3.6: GM = 3.986004418e14 m^3/s^2, a = 6378137 m, C20 = -0.484166774985e-3",
)

MOON = CentralBody(
    "Moon",
    mu=4.9028000661e12,
    radius=1738.0e3,
    J=(2.0322e-4,),
    source=(
        "GM: JPL DE430 (Folkner et al. 2014, IPN PR 42-196, Table 4: 4902.800066 km^3/s^2); "
        "reference radius 1738 km and J2 = 2.0322e-4 (rounded) from GRAIL GL0660B "
        "(Konopliv et al. 2013, JGR Planets 118, 1415)"
    ),
)

SUN = CentralBody(
    "Sun",
    mu=1.32712440041939e20,
    radius=6.957e8,
    J=(),
    source=(
        "GM: JPL DE430 (Folkner et al. 2014, Table 4: 132712440041.9394 km^3/s^2); "
        "radius: IAU 2015 Resolution B3 nominal solar radius; J2 (~2e-7) omitted"
    ),
)


# --------------------------------------------------------------------------- kernels


@jit(inline="always")
def _battin_f(q):
    """Battin's f(q) = (1 + q)^{3/2} - 1 without cancellation for small q."""
    s = 1.0 + q
    return q * (3.0 + 3.0 * q + q * q) / (1.0 + s * math.sqrt(s))


@jit
def _point_mass_difference_kernel(x, dx, mu, sign, out):
    """out += sign * (G(x + dx) - G(x)) with G(y) = -mu y / |y|^3, rows of (N, 3) arrays
    (x may have one row, broadcast).  Battin's form: -(mu/|y|^3)(dx - f(q) x)."""
    n = dx.shape[0]
    one_x = x.shape[0] == 1
    for k in range(n):
        j = 0 if one_x else k
        x0, x1, x2 = x[j, 0], x[j, 1], x[j, 2]
        d0, d1, d2 = dx[k, 0], dx[k, 1], dx[k, 2]
        q = (d0 * (d0 + 2.0 * x0) + d1 * (d1 + 2.0 * x1) + d2 * (d2 + 2.0 * x2)) / (x0 * x0 + x1 * x1 + x2 * x2)
        f = _battin_f(q)
        y0, y1, y2 = x0 + d0, x1 + d1, x2 + d2
        y2n = y0 * y0 + y1 * y1 + y2 * y2
        c = -mu / (y2n * math.sqrt(y2n))
        out[k, 0] += sign * c * (d0 - f * x0)
        out[k, 1] += sign * c * (d1 - f * x1)
        out[k, 2] += sign * c * (d2 - f * x2)


@jit
def _j2_kernel(r, mu, R, J2, out):
    """out += fast path: -(3/2) J2 mu R^2 / r^5 [x (1 - 5 s^2), y (1 - 5 s^2), z (3 - 5 s^2)], s = z/r."""
    k = -1.5 * J2 * mu * R * R
    for i in range(r.shape[0]):
        x, y, z = r[i, 0], r[i, 1], r[i, 2]
        r2 = x * x + y * y + z * z
        c = k / (r2 * r2 * math.sqrt(r2))
        s2 = 5.0 * z * z / r2
        out[i, 0] += c * x * (1.0 - s2)
        out[i, 1] += c * y * (1.0 - s2)
        out[i, 2] += c * z * (3.0 - s2)


@jit
def _zonal_kernel(r, mu, R, J, out):
    """out += general zonal sum J2..J(1+len(J)) by Bonnet's recurrence (module docstring)."""
    nJ = J.shape[0]
    for i in range(r.shape[0]):
        x, y, z = r[i, 0], r[i, 1], r[i, 2]
        r2 = x * x + y * y + z * z
        rn = math.sqrt(r2)
        s = z / rn
        rho = R / rn
        rho_n = rho
        p_prev, p_cur = 1.0, s  # P_0, P_1
        dp_cur = 1.0  # P_1'
        radial = 0.0
        polar = 0.0
        for m in range(nJ):
            n = m + 2
            p_next = ((2.0 * n - 1.0) * s * p_cur - (n - 1.0) * p_prev) / n
            dp_next = n * p_cur + s * dp_cur
            rho_n *= rho
            c = J[m] * rho_n
            radial += c * ((n + 1.0) * p_next + s * dp_next)
            polar += c * dp_next
            p_prev, p_cur, dp_cur = p_cur, p_next, dp_next
        f = mu / r2
        out[i, 0] += f * radial * x / rn
        out[i, 1] += f * radial * y / rn
        out[i, 2] += f * (radial * s - polar)


@jit
def _zonal_potential_kernel(r, mu, R, J, out):
    nJ = J.shape[0]
    for i in range(r.shape[0]):
        x, y, z = r[i, 0], r[i, 1], r[i, 2]
        rn = math.sqrt(x * x + y * y + z * z)
        s = z / rn
        rho = R / rn
        rho_n = rho
        p_prev, p_cur = 1.0, s
        acc = 0.0
        for m in range(nJ):
            n = m + 2
            p_next = ((2.0 * n - 1.0) * s * p_cur - (n - 1.0) * p_prev) / n
            rho_n *= rho
            acc += J[m] * rho_n * p_next
            p_prev, p_cur = p_cur, p_next
        out[i] = -mu / rn * acc


# --------------------------------------------------------------------------- array wrappers


def _rows(x, name, who=""):
    a = real_array(x, name, who)
    if a.ndim == 0 or a.shape[-1] != 3:
        prefix = f"{who}: " if who else ""
        raise ValueError(f"{prefix}{name} must have shape (..., 3) (Cartesian components in m), got shape {a.shape}")
    return a


def point_mass_difference(x, dx, mu):
    """``G(x + dx) - G(x)`` for the point-mass field ``G(y) = -mu y / |y|^3``,
    without the cancellation of the two nearly equal terms (Battin's f(q)).

    ``x``, ``dx`` shape ``(..., 3)`` (broadcast), m; ``mu`` m^3/s^2; returns
    m/s^2 of the broadcast shape.  Encke's deviation acceleration is
    ``point_mass_difference(rho, delta, mu)``; the third-body perturbation is
    ``-point_mass_difference(s, -r, mu3)``."""
    return _point_mass_difference(x, dx, mu, "point_mass_difference", ("x", "dx", "mu"))


def _point_mass_difference(x, dx, mu, who, names):
    x, dx = _rows(x, names[0], who), _rows(dx, names[1], who)
    mu = real_scalar(mu, names[2], who, "m^3/s^2")
    try:
        x, dx = np.broadcast_arrays(x, dx)
    except ValueError:
        broadcast_named(who, (names[0], x, 1), (names[1], dx, 1))
        raise
    shape = dx.shape
    out = np.zeros((int(np.prod(shape[:-1], dtype=np.int64)), 3))
    _point_mass_difference_kernel(
        np.ascontiguousarray(x).reshape(-1, 3), np.ascontiguousarray(dx).reshape(-1, 3), mu, 1.0, out
    )
    return out.reshape(shape)


def third_body_acceleration(r, s, mu3):
    """Perturbing acceleration (m/s^2) on a satellite at ``r`` from a point mass
    ``mu3`` at ``s`` (both relative to the central body, shape ``(..., 3)``,
    broadcast): ``mu3 [(s - r)/|s - r|^3 - s/|s|^3]`` via Battin's f(q)
    (module docstring)."""
    who = "third_body_acceleration"
    r = _rows(r, "r", who)
    s = _rows(s, "s", who)
    broadcast_named(who, ("r", r, 1), ("s", s, 1))
    return -_point_mass_difference(s, -r, mu3, who, ("s", "r", "mu3"))


def _zonal_call(kernel, r, mu, R, J, per_row, who):
    r = _rows(r, "r", who)
    shape = r.shape[:-1] + ((3,) if per_row else ())
    flat = np.ascontiguousarray(r).reshape(-1, 3)
    out = np.zeros((flat.shape[0], 3) if per_row else flat.shape[0])
    kernel(flat, real_scalar(mu, "mu", who), real_scalar(R, "R", who), real_array(J, "J", who).reshape(-1), out)
    return out.reshape(shape)


def zonal_acceleration(r, mu, R, J):
    """Zonal-harmonic acceleration (m/s^2), shape of ``r`` ``(..., 3)`` (m,
    body-fixed axes with z along the pole; for zonals any frame sharing the
    pole works).  ``J = (J2, J3, ...)``, unnormalized.  J2 alone uses the
    fast closed form; otherwise Bonnet's recurrence (module docstring)."""
    who = "zonal_acceleration"
    J = tuple(float(j) for j in np.atleast_1d(real_array(J, "J", who)))
    if len(J) == 1:
        r = _rows(r, "r", who)
        flat = np.ascontiguousarray(r).reshape(-1, 3)
        out = np.zeros_like(flat)
        _j2_kernel(flat, real_scalar(mu, "mu", who), real_scalar(R, "R", who), J[0], out)
        return out.reshape(r.shape)
    return _zonal_call(_zonal_kernel, r, mu, R, J, True, who)


def zonal_potential(r, mu, R, J):
    """The zonal part of the gravitational potential (m^2/s^2),
    ``V_J = -(mu / r) sum_n J_n (R / r)^n P_n(z / r)``, so that
    ``zonal_acceleration = grad V_J`` and the conserved energy of a satellite
    is ``|v|^2 / 2 - mu / |r| - V_J``.  Shape ``r.shape[:-1]``."""
    return _zonal_call(_zonal_potential_kernel, r, mu, R, np.atleast_1d(real_array(J, "J", "zonal_potential")), False,
                       "zonal_potential")


# --------------------------------------------------------------------------- declarative models


@dataclass(frozen=True)
class Zonal:
    """Zonal harmonics of the central body: ``mu`` (m^3/s^2), reference radius
    ``R`` (m), ``J = (J2, J3, ...)`` unnormalized; pole along z.

    ``mu`` and ``R`` finite and > 0, every ``J`` finite (ValueError naming it; TypeError for
    values that are not real numbers), stored as floats."""

    mu: float
    R: float
    J: tuple[float, ...] = ()

    def __post_init__(self):
        mu = real_scalar(self.mu, "mu", "Zonal", "m^3/s^2")
        R = real_scalar(self.R, "R", "Zonal", "m")
        if not (mu > 0 and R > 0 and math.isfinite(mu) and math.isfinite(R)):
            raise ValueError(f"Zonal: mu and R must be finite and > 0, got mu={self.mu!r}, R={self.R!r}")
        J = real_array(self.J, "J", "Zonal")
        if J.ndim != 1:
            raise ValueError(f"Zonal: J must be a sequence (J2, J3, ...), got shape {J.shape}")
        if not np.isfinite(J).all():
            raise ValueError(f"Zonal: J must be finite, got J = {tuple(float(j) for j in J)}")
        object.__setattr__(self, "mu", mu)
        object.__setattr__(self, "R", R)
        object.__setattr__(self, "J", tuple(float(j) for j in J))
        object.__setattr__(self, "_J_array", np.array(self.J, dtype=np.float64))

    @property
    def trivial(self) -> bool:
        return all(j == 0.0 for j in self.J)

    def acceleration(self, t, r, v=None):
        return zonal_acceleration(r, self.mu, self.R, self.J)

    def _add_acceleration(self, t, r, v, out):
        """out += acceleration, r and out contiguous (N, 3) float64 (propagator fast path)."""
        if len(self.J) == 1:
            _j2_kernel(r, self.mu, self.R, self.J[0], out)
        else:
            _zonal_kernel(r, self.mu, self.R, self._J_array, out)

    def potential(self, r):
        return zonal_potential(r, self.mu, self.R, self.J)


@dataclass(frozen=True)
class KeplerOrbit:
    """A body on an exact two-body conic: state ``(r0, v0)`` (m, m/s, shape
    (3,)) at time ``t0`` (s), about a centre of gravitational parameter ``mu``.

    For a third body orbiting the central body (both massive), ``mu`` is
    ``mu_central + mu_third`` (their relative orbit).  Calling it with a scalar ``t``
    returns the position (3,) at ``t`` via ``astrodyn.orbit.propagate`` (an array ``t``
    raises ValueError naming it).  ``r0, v0`` of shape (3,) and ``mu > 0`` are checked
    when it is made."""

    r0: Sequence[float]
    v0: Sequence[float]
    mu: float
    t0: float = 0.0

    def __post_init__(self):
        for name in ("r0", "v0"):
            shape = real_array(getattr(self, name), name, "KeplerOrbit").shape
            if shape != (3,):
                raise ValueError(f"KeplerOrbit: {name} must have shape (3,), got shape {shape}")
        mu = real_scalar(self.mu, "mu", "KeplerOrbit", "m^3/s^2")
        if not mu > 0:
            raise ValueError(f"KeplerOrbit: mu must be > 0 (m^3/s^2), got {self.mu!r}")
        real_scalar(self.t0, "t0", "KeplerOrbit", "s")

    def __call__(self, t):
        t = real_scalar(t, "t", "KeplerOrbit", "s")
        r, _ = propagate(np.asarray(self.r0, float), np.asarray(self.v0, float), t - self.t0, self.mu)
        return r


@dataclass(frozen=True)
class ThirdBody:
    """Point-mass third body ``mu3`` (m^3/s^2) at ``r3_of_t(t)`` (m, relative to
    the central body; a callable such as :class:`KeplerOrbit`, or a constant
    (3,) position).

    ``mu3`` finite and >= 0 (0: a trivial perturbation, skipped), stored as a float; a
    constant position finite of shape (3,), checked here; a callable's result must have
    shape (3,), checked at each call (ValueError naming ``r3_of_t``)."""

    mu3: float
    r3_of_t: Callable | Sequence[float]

    def __post_init__(self):
        mu3 = real_scalar(self.mu3, "mu3", "ThirdBody", "m^3/s^2")
        if not (mu3 >= 0.0 and math.isfinite(mu3)):
            raise ValueError(f"ThirdBody: mu3 must be finite and >= 0 (m^3/s^2), got {self.mu3!r}")
        object.__setattr__(self, "mu3", mu3)
        if not callable(self.r3_of_t):
            s = real_array(self.r3_of_t, "r3_of_t", "ThirdBody")
            if s.shape != (3,) or not np.isfinite(s).all():
                raise ValueError(f"ThirdBody: r3_of_t (a constant position) must be 3 finite numbers in m, "
                                 f"got {'shape ' + str(s.shape) if s.shape != (3,) else s.tolist()}")

    @property
    def trivial(self) -> bool:
        return self.mu3 == 0.0

    def position(self, t):
        if callable(self.r3_of_t):
            s = real_array(self.r3_of_t(t), "r3_of_t(t)", "ThirdBody")
            if s.shape != (3,):
                raise ValueError(f"ThirdBody: r3_of_t(t) must return a position of shape (3,) in m, "
                                 f"got shape {s.shape} at t = {t}")
            return s
        return np.asarray(self.r3_of_t, dtype=np.float64)

    def acceleration(self, t, r, v=None):
        return third_body_acceleration(r, self.position(t), self.mu3)

    def _add_acceleration(self, t, r, v, out):
        """out += acceleration (propagator fast path): -(G(s - r) - G(s))."""
        s = np.ascontiguousarray(self.position(t), dtype=np.float64).reshape(1, 3)
        _point_mass_difference_kernel(s, np.negative(r), self.mu3, -1.0, out)


# --------------------------------------------------------------------------- propagator


@dataclass(frozen=True)
class PerturbedStates:
    """Result of :func:`propagate_perturbed`.

    ``r, v``: states at the requested times, shape ``(..., T, 3)`` (or
    ``(..., 3)`` for a scalar ``t``); ``error_r, error_v``: estimated error
    norms (m, m/s), shape ``(..., T)`` (zeros for the exact Kepler path, NaN
    if ``error_estimate=False``); ``method``: "kepler", "cowell" or "encke";
    ``integrated``: whether anything was integrated; ``nfev``: right-hand-side
    evaluations (tight run); ``rectifications``: Encke reference restarts;
    ``message``: a one-line account of what was done."""

    t: np.ndarray
    r: np.ndarray
    v: np.ndarray
    error_r: np.ndarray
    error_v: np.ndarray
    method: str
    integrated: bool
    nfev: int = 0
    nsteps: int = 0
    rectifications: int = 0
    message: str = ""
    perturbations: tuple = field(default=(), repr=False)


def _describe(p) -> str:
    """A perturbation in one short line (its repr, whitespace collapsed, at most 100 characters)."""
    text = " ".join(repr(p).split())
    return text if len(text) <= 100 else text[:97] + "..."


def _active(perturbations):
    if perturbations is None:
        return ()
    if not isinstance(perturbations, Iterable):
        perturbations = (perturbations,)
    out = []
    for p in perturbations:
        if not callable(getattr(p, "acceleration", None)):
            raise ValueError(f"perturbations: each entry needs an acceleration(t, r, v) method, got {p!r}")
        if not getattr(p, "trivial", False):
            out.append(p)
    return tuple(out)


@jit
def _unpack(y, L, V, r, v):
    """Scaled stacked vector y (6N,) -> r, v (N, 3) (row k scaled by L[k], V[k])."""
    for k in range(L.shape[0]):
        for j in range(3):
            r[k, j] = y[6 * k + j] * L[k]
            v[k, j] = y[6 * k + 3 + j] * V[k]


@jit
def _central_acceleration(r, mu, a):
    """a = -mu r / |r|^3 (overwrites a)."""
    for k in range(r.shape[0]):
        r2 = r[k, 0] * r[k, 0] + r[k, 1] * r[k, 1] + r[k, 2] * r[k, 2]
        c = -mu / (r2 * math.sqrt(r2))
        for j in range(3):
            a[k, j] = c * r[k, j]


@jit
def _pack(dr_dt, a, L, V, out):
    """out = the scaled derivative (dr/dt / L, a / V per body); returns whether all of it is finite."""
    finite = True
    for k in range(L.shape[0]):
        for j in range(3):
            x = dr_dt[k, j] / L[k]
            y = a[k, j] / V[k]
            out[6 * k + j] = x
            out[6 * k + 3 + j] = y
            finite = finite and math.isfinite(x) and math.isfinite(y)
    return finite


class _System:
    """The stacked, scaled ODE of N bodies (Cowell or Encke)."""

    def __init__(self, mu, perturbations, L, V, method):
        self.mu = mu
        self.perturbations = perturbations
        self.L = np.ascontiguousarray(L, dtype=np.float64)
        self.V = np.ascontiguousarray(V, dtype=np.float64)
        self.method = method
        self.n = L.shape[0]
        self.nfev = 0
        self.ref = None  # Encke reference: (r_ref, v_ref, t_ref)
        n = self.n
        self._mu_rows = np.full(n, float(mu))
        self._dt_rows = np.empty(n)
        self._x = np.empty((n, 3))  # r (Cowell) or delta (Encke)
        self._xd = np.empty((n, 3))  # v (Cowell) or delta-dot (Encke)
        self._a = np.empty((n, 3))

    def set_reference(self, r_ref, v_ref, t_ref):
        self.ref = (np.ascontiguousarray(r_ref, dtype=np.float64), np.ascontiguousarray(v_ref, dtype=np.float64), t_ref)

    def _reference(self, t):
        """Kepler reference (rho, rho_dot) at t.  Calls the universal-variable
        kernel of astrodyn.orbit.universal directly: the public ``propagate``
        validates and broadcasts on every call (~75 us), which would dominate
        Encke's right-hand side."""
        r_ref, v_ref, t_ref = self.ref
        rho, rho_dot = np.empty((self.n, 3)), np.empty((self.n, 3))
        self._dt_rows.fill(t - t_ref)
        propagate_rows(r_ref, v_ref, self._dt_rows, self._mu_rows, rho, rho_dot)
        return rho, rho_dot

    def state(self, t, y):
        """Physical (r, v), each (N, 3), from the scaled vector y at time t."""
        r, v = np.empty((self.n, 3)), np.empty((self.n, 3))
        _unpack(y, self.L, self.V, r, v)
        if self.method == "encke":
            rho, rho_dot = self._reference(t)
            return rho + r, rho_dot + v
        return r, v

    def rhs(self, t, y):
        self.nfev += 1
        x, xd, a = self._x, self._xd, self._a
        _unpack(y, self.L, self.V, x, xd)
        if self.method == "encke":
            rho, rho_dot = self._reference(t)
            a[:] = 0.0
            _point_mass_difference_kernel(rho, x, self.mu, 1.0, a)
            r, v = rho + x, rho_dot + xd
        else:
            _central_acceleration(x, self.mu, a)
            r, v = x, xd
        for p in self.perturbations:
            add = getattr(p, "_add_acceleration", None)
            if add is not None:
                add(t, r, v, a)
            else:
                a += np.asarray(p.acceleration(t, r, v), dtype=np.float64)
        out = np.empty(6 * self.n)
        if not _pack(xd, a, self.L, self.V, out):
            raise RuntimeError(self._not_finite(t, r, v))
        return out

    def _not_finite(self, t, r, v) -> str:
        """Why the right-hand side at ``t`` is not finite, naming the culprit (the message of
        the RuntimeError that stops the integration: scipy's DOP853 would otherwise shrink
        its step without end on a NaN derivative, or loop forever on a NaN step size)."""
        where = f"at t = {t:.9g} s" if math.isfinite(t) else f"at t = {t}"
        head = "propagate_perturbed: "
        if not (np.isfinite(r).all() and np.isfinite(v).all()):
            return f"{head}the integrated state is not finite {where} (the step size collapsed?)"
        scratch = np.zeros((self.n, 3))
        if self.method == "encke":
            rho, _ = self._reference(t)
            _point_mass_difference_kernel(rho, r - rho, self.mu, 1.0, scratch)
        else:
            _central_acceleration(r, self.mu, scratch)
        if not np.isfinite(scratch).all():
            return f"{head}the central body's acceleration is not finite {where} (|r| = 0: a collision?)"
        for p in self.perturbations:
            scratch[:] = 0.0
            add = getattr(p, "_add_acceleration", None)
            if add is not None:
                add(t, r, v, scratch)
            else:
                scratch += np.asarray(p.acceleration(t, r, v), dtype=np.float64)
            if not np.isfinite(scratch).all():
                return (f"{head}the acceleration of {_describe(p)} is not finite {where} (a third body at the "
                        "spacecraft's position, a non-finite coefficient or ephemeris?)")
        return f"{head}the equations of motion are not finite {where}"


def shortest_period(r0, v0, mu) -> float:
    """The shortest two-body period (s) of the bound rows of ``r0, v0`` (N, 3) about ``mu``
    (from the osculating semi-major axis), ``inf`` if none is bound."""
    r = np.linalg.norm(r0, axis=-1)
    energy = 0.5 * np.einsum("ij,ij->i", v0, v0) - mu / r
    bound = energy < 0.0
    if not np.any(bound):
        return math.inf
    a = -mu / (2.0 * energy[bound])
    return float(np.min(2.0 * math.pi * np.sqrt(a**3 / mu)))


def _integrate_direction(system, r0, v0, taus, direction, rtol, atol, rectify_ratio, max_steps, period=math.inf):
    """Integrate from t = 0 to each t = direction * tau (taus ascending, > 0).

    ``max_steps`` applies per chunk: between two output times, and within each ``period``
    (s) of integration (the shortest revolution of the bodies), whichever ends first -- it
    catches a step size that collapses, never a long span (the integration itself is one
    run, so the result does not depend on the chunks).

    Returns r, v of shape (len(taus), N, 3), steps, rectifications."""
    from scipy.integrate import DOP853

    n = r0.shape[0]
    T = len(taus)
    r_out = np.empty((T, n, 3))
    v_out = np.empty((T, n, 3))
    if T == 0:
        return r_out, v_out, 0, 0
    t_end = direction * taus[-1]

    def start(t0, r_start, v_start):
        if system.method == "encke":
            system.set_reference(r_start, v_start, t0)
            y0 = np.zeros(6 * n)
        else:
            y0 = np.concatenate([r_start / system.L[:, None], v_start / system.V[:, None]], axis=1).reshape(-1)
        return DOP853(system.rhs, t0, y0, t_end, rtol=rtol, atol=atol)

    solver = start(0.0, r0, v0)
    k = 0
    steps = 0
    rectifications = 0
    chunk_steps = 0  # steps since the last output time or chunk boundary
    chunk = period if period > 0 else math.inf
    chunk_end = chunk  # elapsed |t| at which the chunk's count starts again
    while k < T:
        if chunk_steps >= max_steps:
            where = f"between t = {solver.t:.9g} s and the next output time {direction * taus[k]:.9g} s"
            per = f" and within one revolution ({chunk:.6g} s)" if math.isfinite(chunk) else ""
            raise RuntimeError(f"propagate_perturbed: more than max_steps={max_steps} integrator steps {where}{per}; "
                               "loosen rtol/atol or raise max_steps")
        if not (math.isfinite(solver.t) and math.isfinite(solver.h_abs)):  # DOP853 would never leave its step
            raise RuntimeError(f"propagate_perturbed: the integrator's time or step size is not finite "
                               f"(t = {solver.t}, step = {solver.h_abs})")
        t_prev = solver.t
        msg = solver.step()
        steps += 1
        chunk_steps += 1
        if direction * solver.t >= chunk_end:
            chunk_steps = 0
            chunk_end = direction * solver.t + chunk
        if solver.status == "failed":
            raise RuntimeError(f"propagate_perturbed: DOP853 failed at t = {solver.t} s: {msg}")
        t_new = solver.t
        dense = None
        while k < T and taus[k] <= direction * t_new:
            tk = direction * taus[k]
            if tk == t_new:
                yk = solver.y
            else:
                dense = dense or solver.dense_output()
                yk = dense(tk)
            r_out[k], v_out[k] = system.state(tk, yk)
            k += 1
            chunk_steps = 0
        if system.method == "encke" and k < T and t_new != t_prev:
            Y = solver.y.reshape(n, 6)
            rho, rho_dot = system._reference(t_new)
            ratio = np.sqrt(np.einsum("ij,ij->i", Y[:, :3], Y[:, :3])) * system.L / np.linalg.norm(rho, axis=-1)
            if np.max(ratio) > rectify_ratio:
                r_now, v_now = system.state(t_new, solver.y)
                solver = start(t_new, r_now, v_now)
                rectifications += 1
    return r_out, v_out, steps, rectifications


def _run(system, r0, v0, t_flat, rtol, atol, rectify_ratio, max_steps, period=math.inf):
    n = r0.shape[0]
    T = t_flat.shape[0]
    r_out = np.empty((T, n, 3))
    v_out = np.empty((T, n, 3))
    steps = rect = 0
    zero = t_flat == 0.0
    r_out[zero] = r0
    v_out[zero] = v0
    for direction in (1.0, -1.0):
        idx = np.flatnonzero(direction * t_flat > 0.0)
        if idx.size == 0:
            continue
        order = idx[np.argsort(direction * t_flat[idx], kind="stable")]
        taus = direction * t_flat[order]
        r_d, v_d, s, k = _integrate_direction(system, r0, v0, taus, direction, rtol, atol, rectify_ratio, max_steps,
                                          period)
        r_out[order] = r_d
        v_out[order] = v_d
        steps += s
        rect += k
    return r_out, v_out, steps, rect


def propagate_perturbed(
    r0,
    v0,
    t,
    mu,
    perturbations=(),
    method: str = "cowell",
    rtol: float = 1e-10,
    atol: float = 1e-12,
    *,
    error_estimate: bool = True,
    rectify_ratio: float = 1e-2,
    max_steps: int = 1_000_000,
) -> PerturbedStates:
    """Propagate ``(r0, v0)`` under two-body gravity plus ``perturbations``.

    Parameters
    ----------
    r0, v0 : (..., 3) position (m) and velocity (m/s) at t = 0, relative to the
        central body, inertial frame (z along the pole for zonals).
    t : scalar or 1-D array of times (s since the epoch of r0, v0), any order
        and sign (negative times integrate backward from 0).
    mu : central gravitational parameter (m^3/s^2), scalar.
    perturbations : iterable of :class:`Zonal`, :class:`ThirdBody` or any object
        with ``acceleration(t, r, v)``.  Empty (or only trivial entries):
        exact Kepler propagation, nothing is integrated.
    method : "cowell" or "encke" (module docstring).
    rtol, atol : DOP853 tolerances on the scaled state (dimensionless; atol is
        a fraction of |r0| and sqrt(mu/|r0|)), per body; finite and > 0.
    error_estimate : run a second integration at 10x looser tolerances and
        report the difference (conservative) as ``error_r, error_v``.
    rectify_ratio : Encke rectification threshold on |delta| / |rho|; finite and > 0.
    max_steps : cap on integrator steps between two output times and within one
        revolution of the fastest bound body, whichever ends first (RuntimeError beyond):
        it catches a step size that collapses; a long span with many revolutions is fine.
        An int >= 1.

    Returns a :class:`PerturbedStates`.  Bodies with a non-finite state or
    ``r0 = 0`` get NaN outputs (the others are integrated normally).  Bad arguments raise
    ValueError / TypeError naming them before anything is integrated
    (:func:`checked_propagation_inputs`).  A perturbation whose acceleration is not finite
    during the integration (a third body at the spacecraft's position, a NaN ephemeris)
    stops it with a RuntimeError naming the perturbation and the time.
    """
    r0, v0, mu, t_arr = checked_propagation_inputs(r0, v0, t, mu, method, rtol, atol, rectify_ratio, max_steps)
    active = _active(perturbations)
    if not active:
        return kepler_states(r0, v0, t_arr, mu)
    t_flat = np.atleast_1d(t_arr)
    r_all, v_all, er_all, ev_all, nfev, steps, rect = integrate_finite_bodies(
        r0.reshape(-1, 3), v0.reshape(-1, 3), t_flat, mu, active, method, rtol, atol,
        error_estimate, rectify_ratio, max_steps,
    )
    lead, scalar_t = r0.shape[:-1], t_arr.ndim == 0
    names = ", ".join(type(p).__name__ for p in active)
    return PerturbedStates(
        t_arr,
        states_in_input_shape(r_all, lead, scalar_t),
        states_in_input_shape(v_all, lead, scalar_t),
        errors_in_input_shape(er_all, lead, scalar_t),
        errors_in_input_shape(ev_all, lead, scalar_t),
        method,
        True,
        nfev=nfev,
        nsteps=steps,
        rectifications=rect,
        message=f"{method} (DOP853, rtol={rtol:g}, atol={atol:g}) with {names}; {steps} steps, {rect} rectifications",
        perturbations=active,
    )


def checked_propagation_inputs(r0, v0, t, mu, method, rtol, atol, rectify_ratio=1e-2, max_steps=1_000_000):
    """The arguments of :func:`propagate_perturbed` checked and converted: ``(r0, v0)``
    float64 ``(..., 3)`` rows of one shape (m, m/s), ``mu`` a finite positive float
    (m^3/s^2), ``t`` a finite float64 scalar or 1-D array (s); ValueError naming the
    argument otherwise (also for a ``method`` other than "cowell" / "encke", ``rtol``,
    ``atol`` and ``rectify_ratio`` not finite and > 0, and ``max_steps`` < 1), TypeError
    naming it for values that are not real numbers (:mod:`astrodyn.inputs`) and for a
    ``max_steps`` that is not an int."""
    who = "propagate_perturbed"
    if method not in ("cowell", "encke"):
        raise ValueError(f"{who}: method must be 'cowell' or 'encke', got {method!r}")
    r0 = _rows(r0, "r0", who)
    v0 = _rows(v0, "v0", who)
    if r0.shape != v0.shape:
        raise ValueError(f"{who}: v0 must have the shape of r0 {r0.shape}, got {v0.shape}")
    mu = real_scalar(mu, "mu", who, "m^3/s^2")
    if not (math.isfinite(mu) and mu > 0):
        raise ValueError(f"{who}: mu (central gravitational parameter, m^3/s^2) must be finite and > 0, got {mu!r}")
    for name, value in (("rtol", rtol), ("atol", atol), ("rectify_ratio", rectify_ratio)):
        x = real_scalar(value, name, who)
        if not (math.isfinite(x) and x > 0):
            raise ValueError(f"{who}: {name} must be finite and > 0, got {value!r}")
    if isinstance(max_steps, bool) or not isinstance(max_steps, (int, np.integer)):
        raise TypeError(f"{who}: max_steps: expected an integer >= 1, got {type(max_steps).__name__} {max_steps!r}")
    if max_steps < 1:
        raise ValueError(f"{who}: max_steps must be >= 1, got {max_steps!r}")
    t_arr = real_array(t, "t", who)
    if t_arr.ndim > 1:
        raise ValueError(f"{who}: t must be a scalar or a 1-D array of times in s, got shape {t_arr.shape}")
    if not np.all(np.isfinite(t_arr)):
        raise ValueError(f"{who}: t must be finite (seconds since the epoch of r0, v0)")
    return r0, v0, mu, t_arr


def kepler_states(r0, v0, t_arr, mu) -> PerturbedStates:
    """The result of :func:`propagate_perturbed` with nothing to integrate: exact two-body
    states (:func:`astrodyn.orbit.propagate`) of ``(r0, v0)`` (..., 3) at the times
    ``t_arr`` (s, scalar or 1-D), with zero error estimates."""
    t_flat = np.atleast_1d(t_arr)
    r, v = propagate(r0[..., None, :], v0[..., None, :], t_flat, mu)
    if t_arr.ndim == 0:
        r, v = r[..., 0, :], v[..., 0, :]
    zeros = np.zeros(r.shape[:-1])
    return PerturbedStates(
        t_arr, r, v, zeros, zeros.copy(), "kepler", False,
        message="no perturbations: exact two-body propagation (astrodyn.orbit.propagate), nothing integrated",
    )


def integrate_finite_bodies(R0, V0, t_flat, mu, active, method, rtol, atol, error_estimate, rectify_ratio, max_steps):
    """Integrate the bodies of ``R0, V0`` (N, 3) whose state is finite with ``|r0| > 0``
    (the others stay NaN) to the times ``t_flat`` (T,): returns ``r, v`` (T, N, 3),
    ``error_r, error_v`` (T, N) and ``nfev, steps, rectifications`` of the tight run.

    The tolerances of :func:`propagate_perturbed` are per body: the stacked system of
    ``n`` bodies runs at ``rtol / sqrt(n)`` (not below 100 eps) and ``atol / sqrt(n)``;
    the error estimate is the difference to a run at 10x those tolerances."""
    T, N = t_flat.shape[0], R0.shape[0]
    L = np.linalg.norm(R0, axis=-1)
    ok = np.isfinite(L) & np.all(np.isfinite(V0), axis=-1) & (L > 0)
    r_all = np.full((T, N, 3), np.nan)
    v_all = np.full((T, N, 3), np.nan)
    er_all = np.full((T, N), np.nan)
    ev_all = np.full((T, N), np.nan)
    nfev = steps = rect = 0
    if np.any(ok):
        Lk = L[ok]
        Vk = np.sqrt(mu / Lk)
        n_ok = int(np.count_nonzero(ok))
        floor = 100 * np.finfo(np.float64).eps
        scale = 1.0 / math.sqrt(n_ok)

        period = shortest_period(R0[ok], V0[ok], mu)

        def once(factor):
            system = _System(mu, active, Lk, Vk, method)
            rr, vv, s, k = _run(
                system, R0[ok], V0[ok], t_flat, max(rtol * factor * scale, floor), atol * factor * scale, rectify_ratio,
                max_steps, period,
            )
            return rr, vv, s, k, system.nfev

        r_k, v_k, steps, rect, nfev = once(1.0)
        r_all[:, ok], v_all[:, ok] = r_k, v_k
        if error_estimate:
            r_l, v_l, *_ = once(10.0)
            er_all[:, ok] = np.linalg.norm(r_k - r_l, axis=-1)
            ev_all[:, ok] = np.linalg.norm(v_k - v_l, axis=-1)
    return r_all, v_all, er_all, ev_all, nfev, steps, rect


def states_in_input_shape(x_TN3, lead, scalar_t):
    """``(T, N, 3)`` states -> ``lead + (T, 3)``, or ``lead + (3,)`` for a scalar ``t``."""
    T = x_TN3.shape[0]
    x = np.moveaxis(x_TN3, 0, -2).reshape(lead + (T,) + x_TN3.shape[2:])
    return x[..., 0, :] if scalar_t else x


def errors_in_input_shape(x_TN, lead, scalar_t):
    """``(T, N)`` error norms -> ``lead + (T,)``, or ``lead`` for a scalar ``t``."""
    T = x_TN.shape[0]
    x = np.moveaxis(x_TN, 0, -1).reshape(lead + (T,))
    return x[..., 0] if scalar_t else x
