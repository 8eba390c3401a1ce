"""orbit.propagate_scalar (issue 15): one state as six floats in and out.  Against the
50-digit mpmath propagator (100x the one-ulp sensitivity, as tests/test_propagate.py) and
bit for bit against propagate's single-state result; invalid input gives NaN."""

from __future__ import annotations

import math

import numpy as np
import pytest

from astrodyn.orbit import propagate, propagate_scalar
from astrodyn.reference.conditioning import ulp_sensitivity
from astrodyn.reference.orbit_mp import propagate_mp

EPS = np.finfo(float).eps
MU = 3.986004418e14


def _ellipse(a, e, nu, mu=MU):
    p = a * (1 - e * e)
    r = p / (1 + e * math.cos(nu))
    return ([r * math.cos(nu), r * math.sin(nu), 0.0],
            [-math.sqrt(mu / p) * math.sin(nu), math.sqrt(mu / p) * (e + math.cos(nu)), 0.0])


CASES = {
    "LEO, one minute": ([7e6, 1e5, -2e5], [10.0, 7.5e3, 1e3], 60.0),
    "e = 0.9, 10.3 revolutions backward": (*_ellipse(2.6e7, 0.9, 0.3), -10.3 * 2 * math.pi * math.sqrt(2.6e7**3 / MU)),
    "hyperbola e = 1.5 through periapsis": (*_ellipse(-2e7, 1.5, -1.2), 2.0e4),
    "near-parabolic e = 1 - 1e-8": (*_ellipse(7e6 / 1e-8, 1 - 1e-8, -0.4), 3.0e3),
    "inclined circular, dt = 1e-9 s": ([0.0, 7e6 * math.cos(0.9), 7e6 * math.sin(0.9)], [-math.sqrt(MU / 7e6), 0.0, 0.0], 1e-9),
}


@pytest.mark.parametrize("name", list(CASES))
def test_against_mpmath_and_propagate(name):
    r0, v0, dt = CASES[name]
    out = propagate_scalar(*r0, *v0, dt, MU)
    r, v = np.array(out[:3]), np.array(out[3:])
    r_ref, v_ref = propagate_mp(r0, v0, dt, MU, dps=50)
    dr, dv = ulp_sensitivity(r0, v0, dt, MU, dps=30)
    assert np.linalg.norm(r - r_ref) <= 100 * (dr + EPS * np.linalg.norm(r_ref)), name
    assert np.linalg.norm(v - v_ref) <= 100 * (dv + EPS * np.linalg.norm(v_ref)), name
    r_p, v_p = propagate(np.array(r0), np.array(v0), float(dt), MU)
    np.testing.assert_array_equal(r, r_p)
    np.testing.assert_array_equal(v, v_p)


@pytest.mark.parametrize("args", [
    (0.0, 0.0, 0.0, 1.0, 2.0, 3.0, 10.0, MU),  # r0 = 0
    (7e6, 0.0, 0.0, 0.0, 7.5e3, 0.0, 10.0, -MU),  # mu <= 0
    (7e6, 0.0, math.nan, 0.0, 7.5e3, 0.0, 10.0, MU),
    (7e6, 0.0, 0.0, 0.0, 7.5e3, 0.0, math.inf, MU),
])
def test_invalid_input_gives_nan(args):
    assert all(math.isnan(x) for x in propagate_scalar(*args))
