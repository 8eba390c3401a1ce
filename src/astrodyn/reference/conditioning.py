"""How much a two-body propagation can be trusted in float64: one-ulp sensitivities.

A float64 state is only known to half an ulp per component, and a float64 time
likewise.  The change of the propagated state that such a perturbation causes is
the best any float64 method can promise; tests and benchmarks state their
tolerances as a multiple (about 100x) of it.

* :func:`ulp_sensitivity` perturbs each of the seven inputs (three position and
  three velocity components and the time) by one ulp-sized step, propagates with
  the high-precision reference, and returns the largest change of the final
  position [m] and velocity [m/s].

* :func:`path_sensitivity` is the floor for a *step-by-step* integrator
  (REBOUND, DOP853): it re-rounds the state at every step, so the float64
  representation of the most sensitive state on the path matters, not only the
  initial one.  On a Kepler arc that is the periapsis passage: at e -> 1 the
  energy v^2/2 - mu/r is a difference of two numbers 2/(1 - e) times larger than
  itself, so rounding the periapsis state perturbs the semi-major axis by about
  eps * 4/(1 - e) relative, and the final along-track position accordingly.
  The floor is the larger of the sensitivity from the initial state and from
  the first periapsis passage inside the arc.

One-ulp step: ``eps * |r|`` for position components, ``eps * |v|`` for velocity
components (an upper bound of the ulp of any component), ``ulp(dt)`` for time.
With the mpmath reference the responses are differenced in mpmath, so the step
is exactly one ulp.  With a float64 ``propagate`` the step is 64 ulp and the
response is divided by 64, so that it stands above the rounding of the
outputs; the map is linear at that scale except where the sensitivity is of
the order of the orbit itself, where any float64 answer is equally
(un)informative.

These functions use :func:`astrodyn.reference.orbit_mp.propagate_mp` (50-digit
universal-variable propagation, independent of :mod:`astrodyn.orbit`) unless
another propagator is passed.  Slow by design (seven reference propagations
per state): use on samples.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import mpmath as mp
import numpy as np

__all__ = ["ulp_sensitivity", "path_sensitivity", "time_to_periapsis"]

_EPS = float(np.finfo(np.float64).eps)
_FLOAT_STEP_SCALE = 64.0  # float64 propagators: measure with 64 ulp and divide (module docstring)


def _reference_propagator(dps: int) -> Callable:
    """The mpmath reference, returning mpf results (differences taken in mpmath)."""
    from astrodyn.reference.orbit_mp import propagate_mp

    def prop(r0, v0, dt, mu):
        return propagate_mp(r0, v0, dt, mu, dps=dps, as_float=False)

    prop.dps = dps
    return prop


def _as_float_state(rv):
    return np.array([float(x) for x in rv], dtype=np.float64)


def _broadcast(r0, v0, dt):
    r0 = np.asarray(r0, dtype=np.float64)
    v0 = np.asarray(v0, dtype=np.float64)
    lead = np.broadcast_shapes(r0.shape[:-1], v0.shape[:-1], np.shape(dt))
    dt = np.broadcast_to(np.asarray(dt, dtype=np.float64), lead)
    return np.broadcast_to(r0, (*lead, 3)), np.broadcast_to(v0, (*lead, 3)), dt, lead


def _one_state(r0, v0, dt, mu, prop):
    """(max |dr|, max |dv|) over the seven one-ulp input perturbations of one state."""
    dps = getattr(prop, "dps", None)
    scale = 1.0 if dps else _FLOAT_STEP_SCALE
    r0 = np.asarray(r0, dtype=np.float64)
    v0 = np.asarray(v0, dtype=np.float64)
    dt = float(dt)
    r_base, v_base = prop(r0, v0, dt, mu)
    step_r = scale * _EPS * float(np.linalg.norm(r0))
    step_v = scale * _EPS * float(np.linalg.norm(v0))
    step_t = scale * float(np.spacing(abs(dt))) if dt != 0.0 else 0.0

    def dist(a, b):
        if dps:
            with mp.workdps(dps + 20):
                return float(mp.sqrt(sum((x - y) ** 2 for x, y in zip(a, b))))
        return float(np.linalg.norm(np.asarray(a) - np.asarray(b)))

    dr = dv = 0.0
    for j in range(7):
        r1, v1, t1 = r0.copy(), v0.copy(), dt
        if j < 3:
            r1[j] += step_r
        elif j < 6:
            v1[j - 3] += step_v
        elif step_t:
            t1 = dt + step_t
        else:
            continue
        r2, v2 = prop(r1, v1, t1, mu)
        dr = max(dr, dist(r2, r_base))
        dv = max(dv, dist(v2, v_base))
    if not (np.isfinite(dr) and np.isfinite(dv)):
        raise FloatingPointError(
            f"the reference propagation of r0={r0.tolist()}, v0={v0.tolist()}, dt={dt!r} is not finite; "
            "no sensitivity (and no tolerance) can be derived from it"
        )
    return dr / scale, dv / scale


def ulp_sensitivity(r0, v0, dt, mu: float, *, propagate: Callable | None = None, dps: int = 50):
    """Largest change of the propagated (r, v) caused by a one-ulp change of one input.

    Parameters
    ----------
    r0, v0 : array_like (..., 3)
        Initial position [m] and velocity [m/s].
    dt : float or array_like (...)
        Propagation time [s], broadcast against the leading shape.
    mu : float
        Gravitational parameter [m^3/s^2] (not perturbed: both sides use the same value).
    propagate : callable(r0, v0, dt, mu) -> (r, v) for one state, optional
        Defaults to the ``dps``-digit mpmath reference.

    Returns
    -------
    (dr, dv) : arrays of the leading shape, in m and m/s.
    """
    prop = propagate if propagate is not None else _reference_propagator(dps)
    r0, v0, dt, lead = _broadcast(r0, v0, dt)
    dr = np.empty(lead)
    dv = np.empty(lead)
    for idx in np.ndindex(*lead):
        dr[idx], dv[idx] = _one_state(r0[idx], v0[idx], dt[idx], mu, prop)
    return dr, dv


def time_to_periapsis(r0, v0, mu: float, dt: float) -> float | None:
    """Time [s] from the initial state to its first periapsis passage inside the arc [0, dt].

    Returns ``None`` when the arc (forward for dt > 0, backward for dt < 0) does
    not pass periapsis (strictly inside).  Closed forms, float64 (only needed to
    a fraction of the passage time): the eccentric anomaly for ellipses
    (Vallado 4th ed. eq. 2-50), the hyperbolic anomaly for hyperbolas (eq. 2-53),
    Barker's equation when r / |a| < 1e-6 (eq. 2-36): t - t_p = (p D + D^3/3) /
    (2 sqrt(mu)) with D = r.v / sqrt(mu).
    """
    r0 = np.asarray(r0, dtype=np.float64)
    v0 = np.asarray(v0, dtype=np.float64)
    rn = float(np.linalg.norm(r0))
    rv = float(r0 @ v0)
    energy = float(v0 @ v0) / 2.0 - mu / rn
    h = float(np.linalg.norm(np.cross(r0, v0)))
    e = math.sqrt(max(0.0, 1.0 + 2.0 * energy * h * h / (mu * mu)))
    period = None
    # Branch on the energy, not on e: a nearly radial ellipse has e ~ 1 but a finite a.
    if abs(2.0 * energy * rn / mu) < 1e-6:  # r / |a| < 1e-6: parabolic to float64 working accuracy
        d = rv / math.sqrt(mu)
        since = (h * h / mu * d + d**3 / 3.0) / (2.0 * math.sqrt(mu))
    elif e < 1.0:
        a = -mu / (2.0 * energy)
        ecc_anom = math.atan2(rv / math.sqrt(mu * a), 1.0 - rn / a)
        n = math.sqrt(mu / a**3)
        since = (ecc_anom - rv / math.sqrt(mu * a)) / n  # M = E - e sin E, e sin E = r.v / sqrt(mu a)
        period = 2.0 * math.pi / n
    else:
        a = mu / (2.0 * energy)
        hyp_anom = math.asinh(rv / (e * math.sqrt(mu * a)))
        since = (e * math.sinh(hyp_anom) - hyp_anom) / math.sqrt(mu / a**3)
    if period is not None:
        tp = (-since) % period if dt > 0 else -(since % period)
    else:
        tp = -since
    if (dt > 0 and 0.0 < tp < dt) or (dt < 0 and dt < tp < 0.0):
        return tp
    return None


def path_sensitivity(r0, v0, dt, mu: float, *, propagate: Callable | None = None, dps: int = 50):
    """One-ulp floor of a step-by-step integrator over the arc: max over the initial
    state and the first periapsis passage inside the arc of :func:`ulp_sensitivity`.

    Same arguments and returns as :func:`ulp_sensitivity`.
    """
    prop = propagate if propagate is not None else _reference_propagator(dps)
    r0, v0, dt, lead = _broadcast(r0, v0, dt)
    dr, dv = ulp_sensitivity(r0, v0, dt, mu, propagate=prop)
    dr, dv = np.array(dr, ndmin=0), np.array(dv, ndmin=0)
    for idx in np.ndindex(*lead):
        tp = time_to_periapsis(r0[idx], v0[idx], mu, float(dt[idx]))
        if tp is None:
            continue
        rp, vp = prop(r0[idx], v0[idx], tp, mu)  # the integrator holds this state rounded to float64
        sr, sv = _one_state(_as_float_state(rp), _as_float_state(vp), float(dt[idx]) - tp, mu, prop)
        dr[idx] = max(dr[idx], sr)
        dv[idx] = max(dv[idx], sv)
    return dr, dv
