"""Classical and modified equinoctial orbital elements, and anomaly conversions.

Everything here is a pure function of numpy arrays, SI units (m, m/s,
m^3/s^2), angles in radians, vectorized over leading axes: ``r`` and ``v`` have
shape ``(..., 3)``, every element has the leading shape, and a scalar call
(``r`` of shape ``(3,)``) returns 0-d values.

Classical elements
------------------
:func:`elements_from_state` returns an :class:`Elements` with
``p`` (semi-latus rectum, m), ``a`` (semi-major axis, m; negative for a
hyperbola; for a state with angular momentum, ``inf`` only when the computed ``e``
is exactly 1: a parabolic state usually comes out with ``e`` a few ulps off 1, and
then a huge finite ``a`` of either sign, as the conditioning of ``p / (1 - e^2)``
there allows; a radial state: below), ``e``, ``i`` in [0, pi],
``raan``, ``argp`` and ``nu`` in [0, 2 pi).  :func:`state_from_elements`
is the inverse, from ``(p, e, i, raan, argp, nu)`` (``p`` rather than ``a`` so
that the parabola is an ordinary case).

The angles use atan2 of a sine-like and a cosine-like projection (never the
arccos of a dot product near 1), after Vallado, *Fundamentals of
Astrodynamics and Applications*, 4th ed., sec. 2.5 (RV2COE / COE2RV) and
Curtis, *Orbital Mechanics for Engineering Students*, 3rd ed., Algorithms 4.2
and 4.5.

Singular cases (docs/architecture.md, section 2) are defined, finite and round-trip:

* **circular** (``e <= SINGULAR_TOLERANCE``): ``e`` is reported as 0,
  ``argp = 0`` and ``nu`` is the argument of latitude (angle from the
  ascending node to ``r``);
* **equatorial** (``sin i <= SINGULAR_TOLERANCE``): ``i`` is reported as
  exactly 0 (prograde) or pi (retrograde), ``raan = 0`` and ``argp`` is
  measured from the +x axis to periapsis;
* **circular equatorial**: ``nu`` is the true longitude (angle from +x to
  ``r``).

All in-plane angles (``argp``, ``nu`` and the longitudes above) are measured
in the direction of motion, i.e. positive about the angular momentum ``h``.
For a retrograde equatorial orbit (``h`` along -z) that is clockwise seen from
+z: ``argp = atan2(-e_y, e_x)``, which is what ``state_from_elements`` with
``i = pi, raan = 0`` inverts.

The threshold ``SINGULAR_TOLERANCE = 64 * eps = 1.42e-14`` comes from float64
precision: for a state that is exactly circular (or equatorial), the computed
``|e_vec|`` (or ``|h_xy| / |h|``) is rounding noise of a few ``eps`` (each
component of ``h = r x v`` carries an absolute error of about ``eps |r||v|``,
and ``e_vec = v x h / mu - r/|r|`` subtracts two unit-size vectors), so 64 eps
sits well above that noise; conversely, snapping ``e`` or ``sin i`` below the
threshold to 0 moves the reconstructed state by at most ``64 eps |r|``, inside
the conditioning-limited round-trip tolerance (about 100 ulp).

Degenerate input: **rectilinear (radial) motion**, ``h = 0`` or ``|h| <=
SINGULAR_TOLERANCE |r| |v|`` (``r`` and ``v`` parallel to rounding, as ``v = s r / |r|``
computed in floating point gives), is the degenerate conic of ``e = 1``: ``p = 0``,
``e = 1`` exactly and ``a = -mu / (2 E)`` from the energy ``E = |v|^2 / 2 - mu / |r|``
(vis-viva), finite: ``a > 0`` for a bound radial orbit (a fall from rest at ``r`` has
``a = |r| / 2``), ``a < 0`` for an escaping one, ``inf`` only at ``E = 0`` exactly (the
radial parabola); the orientation angles of a straight line are not defined (they come
out finite: ``i``, ``raan`` from the rounding-size ``h``, or the equatorial convention
when ``h = 0``).  It cannot be inverted by ``state_from_elements`` (which needs
``p > 0``).  ``r = 0`` (a body at the centre of attraction: no conic) gives every
element NaN, like NaN or infinite inputs (NaN in, NaN out, no numpy warning;
docs/architecture.md, "Bad numbers").

Modified equinoctial elements
-----------------------------
:func:`equinoctial_from_state` / :func:`state_from_equinoctial` use the set of
Walker, Ireland & Owens, "A set of modified equinoctial orbit elements",
Celestial Mechanics 36, 409-419 (1985), eqs. (1)-(3)::

    p,  f = e cos(argp + I raan),  g = e sin(argp + I raan),
    h = tan(i/2)**I cos(raan),  k = tan(i/2)**I sin(raan),
    L = raan*I + argp + nu      (true longitude)

with the **retrograde factor** ``I = +1`` (default, singular only at
``i = pi``) or ``I = -1`` (``retrograde=True``, singular only at ``i = 0``),
following Broucke & Cefola, Celestial Mechanics 5, 303-310 (1972).  The
equinoctial basis is (with ``s2 = 1 + h**2 + k**2``)::

    f_hat = [1 - k**2 + h**2, 2 h k, -2 I k] / s2
    g_hat = [2 I h k, I (1 + k**2 - h**2), 2 h] / s2
    w_hat = [2 k, -2 h, I (1 - h**2 - k**2)] / s2   (= h_vec / |h_vec|)

so ``r = p / (1 + f cos L + g sin L) (cos L f_hat + sin L g_hat)`` and
``v = sqrt(mu/p) (-(g + sin L) f_hat + (f + cos L) g_hat)``.

Anomalies
---------
:func:`mean_from_true` and :func:`true_from_mean` convert on every conic,
chosen per element by ``e``: eccentric anomaly ``E`` (``e < 1``, solved with
:func:`astrodyn.orbit.kepler.solve_kepler`), hyperbolic anomaly ``F``
(``e > 1``, :func:`astrodyn.orbit.kepler.solve_kepler_hyperbolic``) and, for
``e == 1``, Barker's equation ``M = D + D**3 / 3`` with ``D = tan(nu/2)``
(Vallado 4th ed. sec. 2.2, Algorithm 3 KEPEQTP; mean motion
``n_p = 2 sqrt(mu / p**3)``).
Each conic uses its own mean anomaly: ``M = n (t - t_p)`` with
``n = sqrt(mu / |a|**3)`` for the ellipse and hyperbola.  The conversions keep
the revolution count: ``nu = 2 pi k + nu0`` maps to ``M = 2 pi k + M0`` on an
ellipse.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from astrodyn.inputs import broadcast_named, real_array
from astrodyn.jit import jit
from astrodyn.orbit.floating import sinh_parts, x_minus_sin
from astrodyn.orbit.kepler import solve_kepler, solve_kepler_hyperbolic

__all__ = [
    "SINGULAR_TOLERANCE",
    "Elements",
    "ModifiedEquinoctial",
    "elements_from_state",
    "state_from_elements",
    "equinoctial_from_state",
    "state_from_equinoctial",
    "eccentric_from_true",
    "true_from_eccentric",
    "hyperbolic_from_true",
    "true_from_hyperbolic",
    "mean_from_eccentric",
    "mean_from_hyperbolic",
    "mean_from_true",
    "true_from_mean",
]

SINGULAR_TOLERANCE = 64.0 * np.finfo(np.float64).eps
"""``e`` (circular) and ``sin i`` (equatorial) at or below this are treated as
exactly 0 (see the module docstring for the derivation)."""

_TWO_PI = 2.0 * np.pi


# ---------------------------------------------------------------- helpers


def _vector(x, name, who):
    a = real_array(x, name, who)
    if a.ndim == 0 or a.shape[-1] != 3:
        raise ValueError(f"{who}: {name} must have shape (..., 3) (Cartesian components), got shape {a.shape}")
    return a


def _positive_mu(mu, who):
    mu = real_array(mu, "mu", who)
    if np.any(mu <= 0):  # NaN compares False: NaN mu propagates to NaN elements
        raise ValueError(f"{who}: mu (gravitational parameter, m^3/s^2) must be > 0")
    return mu


def _state_lead(r, v, mu, who):
    """The broadcast leading shape of ``r, v`` (..., 3) and ``mu``; ValueError naming the three
    shapes when they do not broadcast (:func:`astrodyn.inputs.broadcast_named`)."""
    return broadcast_named(who, ("r", r, 1), ("v", v, 1), ("mu", mu, 0))


def _reals(who, **args):
    """Each keyword argument as float64 (:func:`astrodyn.inputs.real_array`), in order."""
    return [real_array(x, name, who) for name, x in args.items()]


def _broadcast(who, names, arrays):
    """``np.broadcast_arrays(*arrays)``; ValueError naming each argument and its shape."""
    try:
        return np.broadcast_arrays(*arrays)
    except ValueError:
        broadcast_named(who, *((n, a, 0) for n, a in zip(names, arrays)))
        raise


def _dot(a, b):
    return np.einsum("...i,...i->...", a, b)


def _norm(a):
    return np.sqrt(_dot(a, a))


def _wrap_2pi(x):
    """Map an angle from atan2 (in [-pi, pi]) to [0, 2 pi).

    A tiny negative angle would become exactly 2 pi after adding 2 pi; it is
    mapped to 0 instead so the range is half-open."""
    y = np.where(x < 0.0, x + _TWO_PI, x)
    return np.where(y >= _TWO_PI, 0.0, y)


def _angle_about(a, b, h, hnorm):
    """Angle from vector ``a`` to vector ``b`` measured positively about ``h``
    (both in the plane normal to ``h``), in [-pi, pi].  Scale-free atan2 of
    ``(a x b) . h_hat`` and ``a . b``."""
    return np.arctan2(_dot(np.cross(a, b), h), _dot(a, b) * hnorm)


def _out(x):
    """0-d arrays become numpy scalars (a scalar call returns scalars)."""
    x = np.asarray(x, dtype=np.float64)
    return x[()] if x.ndim == 0 else x


# ---------------------------------------------------------------- classical


@dataclass(frozen=True)
class Elements:
    """Classical orbital elements (SI units, radians), arrays of the leading shape.

    ``p`` semi-latus rectum (m); ``a`` semi-major axis (m; negative for a
    hyperbola, ``inf`` when the computed ``e`` of a state with angular momentum is exactly
    1, a huge finite value of either sign for a parabolic state whose ``e`` comes out a few
    ulps off 1; a radial state, ``p = 0`` and ``e = 1``, has ``a = -mu / (2 E)``, finite
    unless its energy ``E`` is exactly 0); ``e`` eccentricity; ``i``
    inclination in [0, pi]; ``raan`` right ascension of the ascending node,
    ``argp`` argument of periapsis, ``nu`` true anomaly, each in [0, 2 pi).
    See the module docstring for the circular/equatorial conventions."""

    p: np.ndarray
    a: np.ndarray
    e: np.ndarray
    i: np.ndarray
    raan: np.ndarray
    argp: np.ndarray
    nu: np.ndarray


def elements_from_state(r, v, mu) -> Elements:
    """Classical elements of the osculating conic through the state ``(r, v)``.

    Parameters: ``r`` position (m) and ``v`` velocity (m/s), shape ``(..., 3)``,
    in any inertial frame whose xy plane is the reference plane; ``mu``
    gravitational parameter (m^3/s^2), scalar or broadcastable to the leading
    shape.  Returns :class:`Elements`.  A radial state (``r`` parallel to ``v``, or
    ``v = 0``) gives ``p = 0``, ``e = 1`` and ``a = -mu / (2 E)``; ``r = 0`` gives NaN
    elements (see the module docstring, "Degenerate input").

    Algorithm: Vallado (4th ed.) Algorithm 9 RV2COE, with every angle from
    atan2 and the singular cases of the module docstring.
    """
    r = _vector(r, "r", "elements_from_state")
    v = _vector(v, "v", "elements_from_state")
    mu = _positive_mu(mu, "elements_from_state")
    _state_lead(r, v, mu, "elements_from_state")
    # NaN / inf in, NaN out without numpy's warnings (docs/architecture.md, "Bad numbers")
    with np.errstate(divide="ignore", invalid="ignore"):
        return _classical_elements(r, v, mu)


def _classical_elements(r, v, mu) -> Elements:
    """The body of :func:`elements_from_state`, on checked arrays."""
    h = np.cross(r, v)
    hnorm = _norm(h)
    rnorm = _norm(r)
    at_centre = rnorm == 0.0  # no conic: every element NaN (below)
    # Rectilinear (radial) motion: h = 0, or h of rounding size (r and v parallel to within
    # SINGULAR_TOLERANCE rad, e.g. v = s * r / |r| computed in floating point).
    rectilinear = hnorm <= SINGULAR_TOLERANCE * rnorm * _norm(v)
    p = np.where(rectilinear, 0.0, hnorm * hnorm / mu)

    e_vec = np.cross(v, h) / mu[..., None] - r / rnorm[..., None]
    e = np.where(rectilinear, 1.0, _norm(e_vec))

    h_xy = np.hypot(h[..., 0], h[..., 1])
    equatorial = h_xy <= SINGULAR_TOLERANCE * hnorm
    circular = e <= SINGULAR_TOLERANCE

    i = np.where(equatorial, np.where(h[..., 2] >= 0.0, 0.0, np.pi), np.arctan2(h_xy, h[..., 2]))
    e = np.where(circular, 0.0, e)

    # Ascending node direction n = z x h = (-h_y, h_x, 0); the +x axis when equatorial.
    zeros = np.zeros_like(h[..., 0])
    node = np.stack([-h[..., 1], h[..., 0], zeros], axis=-1)
    x_axis = np.stack([np.ones_like(zeros), zeros, zeros], axis=-1)
    node = np.where(equatorial[..., None], x_axis, node)

    raan = np.where(equatorial, 0.0, _wrap_2pi(np.arctan2(h[..., 0], -h[..., 1])))
    argp = np.where(circular, 0.0, _wrap_2pi(_angle_about(node, e_vec, h, hnorm)))
    # nu from periapsis; for a circular orbit from the node (argument of latitude,
    # or true longitude when also equatorial, node = +x).
    origin = np.where(circular[..., None], node, e_vec)
    nu = _wrap_2pi(_angle_about(origin, r, h, hnorm))

    # a = p / (1 - e^2), factored to avoid forming e^2; inf for e == 1.
    # Rectilinear motion (p == 0, e == 1) has a = -mu / (2 energy) (vis-viva): finite unless
    # the energy is exactly 0 (p / (1 - e^2) is 0 / 0 there, or rounding noise).
    one_minus_e2 = (1.0 - e) * (1.0 + e)
    a = np.where(one_minus_e2 == 0.0, np.inf, p / one_minus_e2)
    energy_a = 1.0 / (2.0 / rnorm - _dot(v, v) / mu)
    a = np.where(rectilinear, energy_a, a)

    elements = (p, a, e, i, raan, argp, nu)
    if np.any(at_centre):
        elements = tuple(np.where(at_centre, np.nan, x) for x in elements)
    return Elements(*(_out(x) for x in elements))


def _perifocal_basis(i, raan, argp):
    """Unit vectors P (to periapsis) and Q (90 deg ahead in the direction of
    motion): the columns of the rotation R3(-raan) R1(-i) R3(-argp) of
    Vallado 4th ed. Algorithm 10 (COE2RV)."""
    ci, si = np.cos(i), np.sin(i)
    cO, sO = np.cos(raan), np.sin(raan)
    cw, sw = np.cos(argp), np.sin(argp)
    P = np.stack([cO * cw - sO * sw * ci, sO * cw + cO * sw * ci, sw * si], axis=-1)
    Q = np.stack([-cO * sw - sO * cw * ci, -sO * sw + cO * cw * ci, cw * si], axis=-1)
    return P, Q


def state_from_elements(p, e, i, raan, argp, nu, mu):
    """Position (m) and velocity (m/s), each shape ``(..., 3)``, from classical elements.

    ``p`` semi-latus rectum (m, > 0), ``e`` >= 0, angles in radians (any
    real value), ``mu`` (m^3/s^2, > 0); all broadcast together.  Every conic
    works; on a hyperbola ``nu`` must lie strictly between the asymptotes
    (``1 + e cos nu > 0``), otherwise ``ValueError``.  NaN in, NaN out.
    Singular cases need no special handling here: ``e = 0, argp = 0`` puts
    ``nu`` from the node, ``i = 0, raan = 0`` puts ``argp`` from +x.

    Reference: Vallado (4th ed.) Algorithm 10 COE2RV; Curtis Algorithm 4.5.
    """
    who = "state_from_elements"
    p, e, i, raan, argp, nu = _reals(who, p=p, e=e, i=i, raan=raan, argp=argp, nu=nu)
    mu = _positive_mu(mu, who)
    if np.any(p <= 0):
        raise ValueError(f"{who}: p (semi-latus rectum, m) must be > 0")
    if np.any(e < 0):
        raise ValueError(f"{who}: e (eccentricity) must be >= 0")
    p, e, i, raan, argp, nu, mu = _broadcast(who, ("p", "e", "i", "raan", "argp", "nu", "mu"),
                                             (p, e, i, raan, argp, nu, mu))
    cnu, snu = np.cos(nu), np.sin(nu)
    denom = 1.0 + e * cnu
    if np.any(denom <= 0):
        raise ValueError("nu (true anomaly) lies outside the hyperbola's asymptotes: need 1 + e cos(nu) > 0")
    rnorm = p / denom
    vscale = np.sqrt(mu / p)
    P, Q = _perifocal_basis(i, raan, argp)
    r = (rnorm * cnu)[..., None] * P + (rnorm * snu)[..., None] * Q
    v = (-vscale * snu)[..., None] * P + (vscale * (e + cnu))[..., None] * Q
    return r, v


# ---------------------------------------------------------------- equinoctial


@dataclass(frozen=True)
class ModifiedEquinoctial:
    """Modified equinoctial elements (Walker, Ireland & Owens 1985).

    ``p`` semi-latus rectum (m); ``f, g`` eccentricity vector components in
    the equinoctial frame; ``h, k`` node-and-inclination components
    (``tan(i/2)**I`` times cos/sin raan); ``L`` true longitude in [0, 2 pi);
    ``retrograde`` records the retrograde factor (``I = -1`` if True)."""

    p: np.ndarray
    f: np.ndarray
    g: np.ndarray
    h: np.ndarray
    k: np.ndarray
    L: np.ndarray
    retrograde: bool = False


def _equinoctial_basis(h, k, I):
    s2 = 1.0 + h * h + k * k
    f_hat = np.stack([1.0 - k * k + h * h, 2.0 * h * k, -2.0 * I * k], axis=-1) / s2[..., None]
    g_hat = np.stack([2.0 * I * h * k, I * (1.0 + k * k - h * h), 2.0 * h], axis=-1) / s2[..., None]
    return f_hat, g_hat


def equinoctial_from_state(r, v, mu, retrograde=False) -> ModifiedEquinoctial:
    """Modified equinoctial elements of the state ``(r, v)`` (shape ``(..., 3)``, SI).

    Nonsingular for every orbit with ``h != 0`` except ``i = pi`` (or, with
    ``retrograde=True``, ``i = 0``), circular and equatorial included.
    ``h, k`` come from the orbit normal ``w_hat`` as ``k = w_x / (1 + I w_z)``,
    ``h = -w_y / (1 + I w_z)``; ``f, g`` are the eccentricity vector's
    components on ``f_hat, g_hat``; ``L = atan2(r . g_hat, r . f_hat)``.
    """
    r = _vector(r, "r", "equinoctial_from_state")
    v = _vector(v, "v", "equinoctial_from_state")
    mu = _positive_mu(mu, "equinoctial_from_state")
    _state_lead(r, v, mu, "equinoctial_from_state")
    I = -1.0 if retrograde else 1.0
    hv = np.cross(r, v)
    hnorm = _norm(hv)
    w = hv / hnorm[..., None]
    denom = 1.0 + I * w[..., 2]
    k = w[..., 0] / denom
    h = -w[..., 1] / denom
    f_hat, g_hat = _equinoctial_basis(h, k, I)
    e_vec = np.cross(v, hv) / mu[..., None] - r / _norm(r)[..., None]
    p = hnorm * hnorm / mu
    L = _wrap_2pi(np.arctan2(_dot(r, g_hat), _dot(r, f_hat)))
    return ModifiedEquinoctial(
        *(_out(x) for x in (p, _dot(e_vec, f_hat), _dot(e_vec, g_hat), h, k, L)), retrograde=bool(retrograde)
    )


def state_from_equinoctial(p, f, g, h, k, L, mu, retrograde=False):
    """Position (m) and velocity (m/s), shape ``(..., 3)``, from modified
    equinoctial elements (Walker, Ireland & Owens 1985, eqs. 3-4, written with
    the equinoctial basis of the module docstring).  ``p > 0``; on a
    hyperbola ``1 + f cos L + g sin L`` must be > 0."""
    who = "state_from_equinoctial"
    p, f, g, h, k, L = _reals(who, p=p, f=f, g=g, h=h, k=k, L=L)
    mu = _positive_mu(mu, who)
    if np.any(p <= 0):
        raise ValueError(f"{who}: p (semi-latus rectum, m) must be > 0")
    p, f, g, h, k, L, mu = _broadcast(who, ("p", "f", "g", "h", "k", "L", "mu"), (p, f, g, h, k, L, mu))
    I = -1.0 if retrograde else 1.0
    cL, sL = np.cos(L), np.sin(L)
    w = 1.0 + f * cL + g * sL
    if np.any(w <= 0):
        raise ValueError("L (true longitude) lies outside the hyperbola's asymptotes: need 1 + f cos L + g sin L > 0")
    f_hat, g_hat = _equinoctial_basis(h, k, I)
    rnorm = p / w
    vscale = np.sqrt(mu / p)
    r = (rnorm * cL)[..., None] * f_hat + (rnorm * sL)[..., None] * g_hat
    v = (-vscale * (g + sL))[..., None] * f_hat + (vscale * (f + cL))[..., None] * g_hat
    return r, v


# ---------------------------------------------------------------- anomalies


def _unwrap_like(angle, reference):
    """Add the multiple of 2 pi that brings ``angle`` within pi of ``reference``."""
    return angle + _TWO_PI * np.round((reference - angle) / _TWO_PI)


_ELLIPTIC = "0 <= e < 1 (elliptic)"
_HYPERBOLIC = "e > 1 (hyperbolic)"


def _anomaly_args(who, name, x, e, hyperbolic):
    """The arguments of an anomaly helper checked: ``x`` (named ``name``) and ``e`` float64
    (TypeError naming one that is not real numbers), their shapes broadcast (ValueError
    naming both), and every finite ``e`` inside the helper's domain -- ``0 <= e < 1``, or
    ``e > 1`` when ``hyperbolic`` -- else ValueError in :func:`solve_kepler`'s words.  NaN
    and infinite ``e`` pass (their elements come out NaN or infinite, as in solve_kepler).
    No Python loop over the elements: the domain test is ``e.min()`` / ``e.max()``, and the
    full element-wise test only when those are out of the domain or NaN."""
    if type(x) is float and type(e) is float and _in_domain(e, hyperbolic):  # one value: the cheap path
        return np.asarray(x), np.asarray(e)
    x = real_array(x, name, who)
    e = real_array(e, "e", who)
    if x.shape != e.shape:
        broadcast_named(who, (name, x, 0), ("e", e, 0))
    if e.ndim == 0 or e.size == 0:
        inside = e.size == 0 or _in_domain(float(e), hyperbolic)
    elif hyperbolic:
        inside = e.min() > 1.0  # NaN anywhere: False, and the test below looks closer
    else:
        inside = e.min() >= 0.0 and e.max() < 1.0
    if not inside:
        outside = (e <= 1.0) if hyperbolic else ((e < 0.0) | (e >= 1.0))  # NaN compares False
        bad = (outside & np.isfinite(e)).ravel()
        if bad.any():
            ev = float(e.ravel()[bad][0])
            raise ValueError(f"{who}: e must satisfy {_HYPERBOLIC if hyperbolic else _ELLIPTIC}; got e = {ev!r}")
    return x, e


def _in_domain(ev, hyperbolic):
    """Whether one eccentricity passes :func:`_anomaly_args` (NaN and +-inf do)."""
    return not math.isfinite(ev) or (ev > 1.0 if hyperbolic else 0.0 <= ev < 1.0)


# Kepler's equation residual pieces: the series kernels of astrodyn.orbit.kepler
# (``x_minus_sin``: E - sin E; ``sinh_parts``: sinh F - F) keep every digit
# near e -> 1, M -> 0.


@jit
def _mean_from_eccentric_flat(E, e, out):
    for j in range(E.size):
        x = E[j]
        out[j] = (1.0 - e[j]) * x + e[j] * x_minus_sin(x, math.sin(x))


@jit
def _mean_from_hyperbolic_flat(F, e, out):
    for j in range(F.size):
        sh, _, sh_minus_x = sinh_parts(F[j])
        out[j] = (e[j] - 1.0) * sh + sh_minus_x


def _flat_kernel(kernel, x, e):
    """Run a compiled per-element kernel over broadcast float64 ``(x, e)``."""
    x, e = np.broadcast_arrays(x, e)
    out = np.empty(x.shape)
    kernel(np.ascontiguousarray(x).ravel(), np.ascontiguousarray(e).ravel(), out.reshape(-1))
    return _out(out)


# The unchecked bodies (float64 arrays in): the public helpers check their arguments first;
# mean_from_true / true_from_mean call these on the elements of each conic.


def _eccentric_from_true(nu, e):
    E = np.arctan2(np.sqrt((1.0 - e) * (1.0 + e)) * np.sin(nu), e + np.cos(nu))
    return _out(_unwrap_like(E, nu))


def _true_from_eccentric(E, e):
    nu = 2.0 * np.arctan2(np.sqrt(1.0 + e) * np.sin(0.5 * E), np.sqrt(1.0 - e) * np.cos(0.5 * E))
    return _out(_unwrap_like(nu, E))


def _hyperbolic_from_true(nu, e):
    denom = 1.0 + e * np.cos(nu)
    with np.errstate(invalid="ignore", divide="ignore"):
        F = np.arcsinh(np.sqrt((e - 1.0) * (e + 1.0)) * np.sin(nu) / denom)
    return _out(np.where(denom > 0.0, F, np.nan))


def _true_from_hyperbolic(F, e):
    return _out(2.0 * np.arctan2(np.sqrt(e + 1.0) * np.sinh(0.5 * F), np.sqrt(e - 1.0) * np.cosh(0.5 * F)))


def eccentric_from_true(nu, e):
    """Eccentric anomaly ``E`` (rad) from true anomaly ``nu`` on an ellipse
    (0 <= e < 1): ``E = atan2(sqrt(1 - e^2) sin nu, e + cos nu)`` (Vallado
    sec. 2.2, in the atan2 form valid in every quadrant), in the same
    revolution as ``nu``.

    Like every anomaly helper here: vectorized (``nu`` and ``e`` broadcast; ValueError
    naming both shapes if they do not); a finite ``e`` outside the helper's domain anywhere
    in the array raises ValueError (here ``0 <= e < 1``, as :func:`solve_kepler`); NaN or
    infinite ``e`` gives NaN (or infinite) elements and no error, as in solve_kepler;
    arguments that are not real numbers raise TypeError naming them."""
    nu, e = _anomaly_args("eccentric_from_true", "nu", nu, e, False)
    return _eccentric_from_true(nu, e)


def true_from_eccentric(E, e):
    """True anomaly ``nu`` (rad) from eccentric anomaly on an ellipse (0 <= e < 1):
    ``nu = 2 atan2(sqrt(1 + e) sin(E/2), sqrt(1 - e) cos(E/2))`` (half-angle
    form, accurate as e -> 1), in the same revolution as ``E``.  Arguments and
    errors as :func:`eccentric_from_true`."""
    E, e = _anomaly_args("true_from_eccentric", "E", E, e, False)
    return _true_from_eccentric(E, e)


def hyperbolic_from_true(nu, e):
    """Hyperbolic anomaly ``F`` from true anomaly on a hyperbola (e > 1):
    ``sinh F = sqrt(e^2 - 1) sin nu / (1 + e cos nu)`` (Vallado sec. 2.2), so
    ``F = asinh(...)`` with no loss near ``nu = 0``.  ``nu`` is taken modulo
    2 pi into (-pi, pi] and must lie between the asymptotes (else NaN).
    Arguments and errors as :func:`eccentric_from_true`, with the domain ``e > 1``
    (as :func:`solve_kepler_hyperbolic`)."""
    nu, e = _anomaly_args("hyperbolic_from_true", "nu", nu, e, True)
    return _hyperbolic_from_true(nu, e)


def true_from_hyperbolic(F, e):
    """True anomaly in (-pi, pi) from hyperbolic anomaly (e > 1):
    ``nu = 2 atan2(sqrt(e + 1) sinh(F/2), sqrt(e - 1) cosh(F/2))``.  Arguments and
    errors as :func:`hyperbolic_from_true`."""
    F, e = _anomaly_args("true_from_hyperbolic", "F", F, e, True)
    return _true_from_hyperbolic(F, e)


def mean_from_eccentric(E, e):
    """Kepler's equation ``M = E - e sin E``, written as
    ``(1 - e) E + e (E - sin E)`` so that near e -> 1, E -> 0 no digits are
    lost (the naive form loses about 3 there).  0 <= e < 1; arguments and errors as
    :func:`eccentric_from_true`."""
    E, e = _anomaly_args("mean_from_eccentric", "E", E, e, False)
    return _flat_kernel(_mean_from_eccentric_flat, E, e)


def mean_from_hyperbolic(F, e):
    """Hyperbolic Kepler equation ``M = e sinh F - F``, written as
    ``(e - 1) sinh F + (sinh F - F)`` (no cancellation near e -> 1, F -> 0).
    e > 1; arguments and errors as :func:`hyperbolic_from_true`."""
    F, e = _anomaly_args("mean_from_hyperbolic", "F", F, e, True)
    return _flat_kernel(_mean_from_hyperbolic_flat, F, e)


def _per_conic(who, name, x, e, ellipse, parabola, hyperbola):
    """Apply ``ellipse(x, e)``, ``parabola(x)`` or ``hyperbola(x, e)`` per
    element according to ``e < 1``, ``e == 1``, ``e > 1`` (NaN e gives NaN)."""
    x = real_array(x, name, who)
    e = real_array(e, "e", who)
    x, e = _broadcast(who, (name, "e"), (x, e))
    if np.any(e < 0):
        raise ValueError(f"{who}: e (eccentricity) must be >= 0; got e = {float(e[e < 0].ravel()[0])!r}")
    out = np.full(x.shape, np.nan)
    for mask, fn in ((e < 1.0, ellipse), (e > 1.0, hyperbola)):
        if np.any(mask):
            out[mask] = fn(x[mask], e[mask])
    par = e == 1.0
    if np.any(par):
        out[par] = parabola(x[par])
    return _out(out)


def _barker_mean(nu):
    """Barker's equation ``M = D + D^3/3``, ``D = tan(nu/2)``, nu reduced to
    (-pi, pi] only when outside it (``nu + pi - pi`` would wipe out tiny nu)."""
    nu = np.where(np.abs(nu) <= np.pi, nu, np.remainder(nu + np.pi, _TWO_PI) - np.pi)
    D = np.tan(0.5 * nu)
    return D + D**3 / 3.0


def _barker_true(M):
    """Root of Barker's cubic, ``D = 2 sinh(asinh(3 M / 2) / 3)``, as ``nu = 2 atan D``."""
    return 2.0 * np.arctan(2.0 * np.sinh(np.arcsinh(1.5 * M) / 3.0))


def mean_from_true(nu, e):
    """Mean anomaly from true anomaly on every conic, chosen per element:
    ellipse ``M = E - e sin E``; parabola (e == 1) Barker ``M = D + D^3/3``,
    ``D = tan(nu/2)``; hyperbola ``M = e sinh F - F``.  On the ellipse the
    revolution count of ``nu`` is kept; on the parabola ``nu`` is reduced to
    (-pi, pi] first; on the hyperbola ``nu`` must lie between the asymptotes
    (else NaN).  ``e >= 0`` (ValueError otherwise), NaN ``e`` gives NaN; shapes and
    types as :func:`eccentric_from_true`."""
    return _per_conic(
        "mean_from_true",
        "nu",
        nu,
        e,
        lambda nu, e: _flat_kernel(_mean_from_eccentric_flat, _eccentric_from_true(nu, e), e),
        _barker_mean,
        lambda nu, e: _flat_kernel(_mean_from_hyperbolic_flat, _hyperbolic_from_true(nu, e), e),
    )


def true_from_mean(M, e):
    """True anomaly from mean anomaly on every conic, chosen per element
    (inverse of :func:`mean_from_true`): ellipse via ``solve_kepler``
    (revolution kept), hyperbola via ``solve_kepler_hyperbolic`` (nu in
    (-pi, pi)), parabola via the closed-form root of Barker's cubic
    ``D = 2 sinh(asinh(3 M / 2) / 3)`` (Cardano's hyperbolic form; no
    cancellation for small or large M).  Arguments and errors as :func:`mean_from_true`."""
    return _per_conic(
        "true_from_mean",
        "M",
        M,
        e,
        lambda M, e: _true_from_eccentric(solve_kepler(M, e), e),
        _barker_true,
        lambda M, e: _true_from_hyperbolic(solve_kepler_hyperbolic(M, e), e),
    )
