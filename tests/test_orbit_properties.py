"""Properties of the two-body flow (hypothesis): group law, time reversal, first integrals.

The properties are exact for the true Kepler flow, so they test
:func:`astrodyn.orbit.propagate` against physics rather than against itself:

* ``propagate(dt1)`` then ``propagate(dt2)`` equals ``propagate(dt1 + dt2)``;
* ``propagate(dt)`` then ``propagate(-dt)`` returns to the start;
* energy, angular momentum and the eccentricity (Laplace) vector are conserved.

Tolerances from conditioning.  For a state ``x`` and time ``dt``,
``amp(x, dt)`` is the amplification of a one-ulp input error: the largest
response of the output to a one-ulp change of one of the seven inputs
(:func:`astrodyn.reference.conditioning.ulp_sensitivity` with the float64
propagator: 64-ulp steps, response divided by 64), divided by ``eps`` times
the output size, plus one (it grows like 3 pi N over N revolutions).  A
composed propagation can amplify the first leg's error by the second leg's
``amp``; each bound below is 100 x that worst case, stated where it is used.
"""

import math

import numpy as np
from hypothesis import assume, given, strategies as st

from astrodyn.orbit import propagate
from astrodyn.orbit.elements import state_from_elements
from astrodyn.reference.conditioning import ulp_sensitivity

EPS = np.finfo(float).eps
MU = 3.986004418e14


def state(rp, e, i, raan, argp, nu_frac):
    """Initial state from periapsis radius and angles (``state_from_elements``); nu kept inside the conic."""
    nu_max = math.pi if e < 1 else 0.9 * math.acos(-1 / e)
    r, v = state_from_elements(rp * (1 + e), e, i, raan, argp, nu_frac * nu_max, MU)
    return np.asarray(r, dtype=float), np.asarray(v, dtype=float)


def amplification(r0, v0, dt):
    """Dimensionless one-ulp error amplification of propagate at (r0, v0, dt) (module doc)."""
    dr, dv = ulp_sensitivity(r0, v0, dt, MU, propagate=propagate)
    r1, v1 = propagate(r0, v0, dt, MU)
    return 1.0 + max(dr / (EPS * np.linalg.norm(r1)), dv / (EPS * np.linalg.norm(v1)))


conic_e = st.one_of(
    st.floats(0.0, 0.95),  # ellipses
    st.floats(1.05, 20.0),  # hyperbolas
    st.floats(-12, -3).map(lambda k: 1 - 10.0**k),  # near-parabolic ellipse
    st.floats(-12, -3).map(lambda k: 1 + 10.0**k),  # near-parabolic hyperbola
)
orbits = st.tuples(
    st.floats(6.6e6, 1e8),  # periapsis radius [m]
    conic_e,
    st.floats(0.0, math.pi),
    st.floats(0.0, 2 * math.pi),
    st.floats(0.0, 2 * math.pi),
    st.floats(-1.0, 1.0),
)
# times in units of the periapsis time scale sqrt(rp^3 / mu); up to ~8 revolutions of a circle
times = st.floats(-50.0, 50.0)


def time_scale(rp):
    return math.sqrt(rp**3 / MU)


@given(orbits, times, times)
def test_composition(orbit, t1, t2):
    r0, v0 = state(*orbit)
    T = time_scale(orbit[0])
    dt1, dt2 = t1 * T, t2 * T
    r1, v1 = propagate(r0, v0, dt1, MU)
    rA, vA = propagate(r1, v1, dt2, MU)
    rB, vB = propagate(r0, v0, dt1 + dt2, MU)
    assume(np.all(np.isfinite(rB)) and np.linalg.norm(rB) < 1e15)
    # leg-1 error (amp1 eps) is amplified by leg 2 (amp2), plus each path's own error
    amp = amplification(r0, v0, dt1) * amplification(r1, v1, dt2) + amplification(r0, v0, dt1 + dt2)
    assert np.linalg.norm(rA - rB) <= 100 * amp * EPS * np.linalg.norm(rB)
    assert np.linalg.norm(vA - vB) <= 100 * amp * EPS * np.linalg.norm(vB)


def _one_leg(orbit, t):
    """Initial state of ``orbit``, dt = t x its time scale, and the state after dt (a
    hypothesis example whose end state leaves 1e15 m is discarded)."""
    r0, v0 = state(*orbit)
    dt = t * time_scale(orbit[0])
    r1, v1 = propagate(r0, v0, dt, MU)
    assume(np.linalg.norm(r1) < 1e15)
    return r0, v0, dt, r1, v1


@given(orbits, times)
def test_time_reversal(orbit, t):
    r0, v0, dt, r1, v1 = _one_leg(orbit, t)
    r2, v2 = propagate(r1, v1, -dt, MU)
    # forward error (amp_f eps) amplified by the backward leg (amp_b), plus its own
    amp = amplification(r0, v0, dt) * amplification(r1, v1, -dt) + 1
    assert np.linalg.norm(r2 - r0) <= 100 * amp * EPS * np.linalg.norm(r0)
    assert np.linalg.norm(v2 - v0) <= 100 * amp * EPS * np.linalg.norm(v0)


@given(orbits, times)
def test_first_integrals_conserved(orbit, t):
    r0, v0, dt, r1, v1 = _one_leg(orbit, t)
    amp = amplification(r0, v0, dt)
    # state error bounds at the end: 100 x conditioning (module doc)
    dr = 100 * amp * EPS * np.linalg.norm(r1)
    dv = 100 * amp * EPS * np.linalg.norm(v1)

    def integrals(r, v):
        rn, vn = np.linalg.norm(r), np.linalg.norm(v)
        h = np.cross(r, v)
        ecc = np.cross(v, h) / MU - r / rn
        return vn * vn / 2 - MU / rn, h, ecc

    E0, h0, e0 = integrals(r0, v0)
    E1, h1, e1 = integrals(r1, v1)
    R0, V0 = np.linalg.norm(r0), np.linalg.norm(v0)
    R1, V1 = np.linalg.norm(r1), np.linalg.norm(v1)
    # first-order propagation of (dr, dv) into each integral, plus 10 eps of its terms
    # evaluated at both ends (the integrals are computed in float64 here too)
    tol_E = V1 * dv + MU / R1**2 * dr + 10 * EPS * (V0**2 + MU / R0 + V1**2 + MU / R1)
    tol_h = R1 * dv + V1 * dr + 10 * EPS * (R0 * V0 + R1 * V1)
    tol_e = (dv * np.linalg.norm(h1) + V1 * tol_h) / MU + 2 * dr / R1 + 10 * EPS * (
        V0 * R0 * V0 / MU + V1 * R1 * V1 / MU + 2
    )
    assert abs(E1 - E0) <= tol_E
    assert np.linalg.norm(h1 - h0) <= tol_h
    assert np.linalg.norm(e1 - e0) <= tol_e
