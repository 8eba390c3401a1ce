"""The 50-digit reference propagator itself (astrodyn.reference.orbit_mp), on long hyperbolic arcs.

Every other orbit test trusts :func:`propagate_mp`, so it is checked here
against a formulation it shares nothing with: the hyperbolic Kepler equation
``e sinh F - F = M`` (Vallado 4th ed. eq. 2-53; Curtis eq. 3.40) solved with
its own Newton loop, the radius ``r = |a| (e cosh F - 1)`` (Vallado eq. 2-56),
the true anomaly ``tan(nu/2) = sqrt((e + 1)/(e - 1)) tanh(F/2)`` (Curtis eq.
3.44b) and the perifocal position ``r (cos nu P + sin nu Q)`` with P along the
eccentricity vector and Q = h x P / |h| (Vallado alg. 10).  Both sides run in
mpmath on the exact float64 inputs, so they agree to the working precision,
not to a float64 conditioning: the tolerance is 1e-40 relative for a 50-digit
run (the root is found to 60 digits at 70 working digits; 1e-40 leaves ten
orders of margin for the growth of rounding through cosh/sinh of F ~ 40).

The arcs are the hard ones for the universal-variable iteration: the nearly
radial hyperbola (e - 1 ~ 5e-13, r_p ~ 6e-6 m) out to 1e9 s, through its
near-collision periapsis backwards, and e = 1.5 / 100 hyperbolas through
periapsis out to 1e9 s.  Each must converge in a few iterations (max_iter = 30
raises otherwise; plain bisection would need ~250).
"""

import math

import mpmath as mp
import numpy as np
import pytest

from astrodyn.reference.orbit_mp import ReferenceNotConverged, propagate_mp

MU_E = 3.986004418e14  # m^3/s^2
RP = 7.0e6  # m
DPS = 50
REL_TOL = mp.mpf("1e-40")  # module docstring


def periapsis_state(e, rp=RP, mu=MU_E):
    v = math.sqrt(mu * (1.0 + e) / rp)
    return np.array([rp, 0.0, 0.0]), np.array([0.0, v, 0.0])


def hyperbolic_kepler_position(r0, v0, dt, mu):
    """Position and speed after dt on a hyperbola, by the hyperbolic anomaly (module docstring)."""
    r0 = [mp.mpf(float(x)) for x in r0]
    v0 = [mp.mpf(float(x)) for x in v0]
    dt, mu = mp.mpf(float(dt)), mp.mpf(float(mu))
    def dot(a, b):
        return sum(x * y for x, y in zip(a, b))
    def cross(a, b):
        return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    rn = mp.sqrt(dot(r0, r0))
    h = cross(r0, v0)
    hn = mp.sqrt(dot(h, h))
    energy = dot(v0, v0) / 2 - mu / rn
    a = mu / (2 * energy)  # |a| of the hyperbola
    ecc_vec = [x / mu - y / rn for x, y in zip(cross(v0, h), r0)]
    e = mp.sqrt(dot(ecc_vec, ecc_vec))
    n = mp.sqrt(mu / a**3)
    F0 = mp.asinh(dot(r0, v0) / (e * mp.sqrt(mu * a)))  # e sinh F = r.v / sqrt(mu |a|)
    M = e * mp.sinh(F0) - F0 + n * dt
    F = mp.asinh(M / e)  # |F| >= |asinh(M / e)|; Newton from there (convex on the far side)
    for _ in range(200):
        step = (e * mp.sinh(F) - F - M) / (e * mp.cosh(F) - 1)
        F -= step
        if abs(step) <= mp.mpf(10) ** (-(mp.mp.dps - 5)) * (1 + abs(F)):
            break
    else:
        raise AssertionError("test-side hyperbolic Kepler solve did not converge")
    r = a * (e * mp.cosh(F) - 1)
    nu = 2 * mp.atan(mp.sqrt((e + 1) / (e - 1)) * mp.tanh(F / 2))
    P = [x / e for x in ecc_vec]
    Q = [x / hn for x in cross(h, P)]
    pos = [r * (mp.cos(nu) * p + mp.sin(nu) * q) for p, q in zip(P, Q)]
    speed = mp.sqrt(mu * (2 / r + 1 / a))
    return pos, speed


RADIAL = (np.array([RP, 0.0, 0.0]), np.array([12000.0, 0.01, 0.0]))
CASES = [("nearly-radial", *RADIAL, dt) for dt in (1e7, 1e8, 1e9, -1e7, -1e9)]
for _e in (1.5, 100.0):
    _r, _v = periapsis_state(_e)
    CASES += [(f"e={_e}", _r, _v, dt) for dt in (1e9, -1e9, 3.3e7)]


@pytest.mark.parametrize("name, r0, v0, dt", CASES, ids=[f"{c[0]}-dt{c[3]:g}" for c in CASES])
def test_long_hyperbolic_arcs_against_the_hyperbolic_anomaly(name, r0, v0, dt):
    with mp.workdps(DPS + 20):
        r, v = propagate_mp(r0, v0, dt, MU_E, dps=DPS, as_float=False, max_iter=30)
        pos, speed = hyperbolic_kepler_position(r0, v0, dt, MU_E)
        rn = mp.sqrt(sum(x * x for x in pos))
        assert mp.sqrt(sum((x - y) ** 2 for x, y in zip(r, pos))) <= REL_TOL * rn
        assert abs(mp.sqrt(sum(x * x for x in v)) - speed) <= REL_TOL * speed


def test_the_reported_radial_case_converges_fast():
    """r0 = (7e6, 0, 0) m, v0 = (12000, 0.01, 0) m/s, dt = 1e7 s used to come back as ~ -1e841 m;
    now a handful of evaluations, and the answer is a hyperbola's: |r| ~ v_inf dt."""
    r, v = propagate_mp(*RADIAL, 1e7, MU_E, max_iter=30)
    assert propagate_mp.last_evaluations <= 15
    v_inf = math.sqrt(12000.0**2 + 0.01**2 - 2 * MU_E / RP)
    # r(t) = v_inf t + (mu / v_inf^2) ln(t) + O(1) far out: within 1 % of v_inf t at 1e7 s
    assert abs(np.linalg.norm(r) / (v_inf * 1e7) - 1) < 0.01
    assert abs(np.linalg.norm(v) / v_inf - 1) < 0.01


def test_not_converged_raises_instead_of_returning():
    with pytest.raises(ReferenceNotConverged, match="no convergence"):
        propagate_mp(*RADIAL, 1e7, MU_E, max_iter=3)


@pytest.mark.parametrize(
    "args, match",
    [
        ((np.array([np.nan, 0, 0]), RADIAL[1], 1.0, MU_E), "r0 must be finite"),
        ((RADIAL[0], RADIAL[1], math.inf, MU_E), "dt must be finite"),
        ((RADIAL[0], RADIAL[1], 1.0, -1.0), "mu must be > 0"),
        ((np.zeros(3), RADIAL[1], 1.0, MU_E), "centre"),
        ((np.zeros(2), RADIAL[1], 1.0, MU_E), "shape"),
    ],
)
def test_bad_input_raises(args, match):
    with pytest.raises(ValueError, match=match):
        propagate_mp(*args)
