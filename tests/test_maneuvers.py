"""Orbit manoeuvres (astrodyn.orbit.maneuvers) against published values and closed forms.

* Hohmann LEO -> GEO: Vallado 4th ed. Example 6-1 (r_i = 191.34411 km altitude,
  r_f = 35,781.34857 km altitude, R_E = 6378.137 km, mu = 398,600.4418 km^3/s^2):
  dv_a = 2.457038 km/s, dv_b = 1.478187 km/s, tof = 5.256713 h.
* Flown with the exact two-body propagator and two impulses, the transfer arrives on the
  target circle: the radius stays r2 to 1e-9 relative over a whole target orbit.
* A finite burn in (almost) free space gives Tsiolkovsky's speed change.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from astrodyn.orbit import propagate, propagate_perturbed
from astrodyn.orbit.maneuvers import G0, ConstantThrust, apply_impulse, hohmann, rocket_dv

MU_KM = 398600.4418
R_E = 6378.137


def test_hohmann_matches_vallado_example_6_1():
    r1, r2 = R_E + 191.34411, R_E + 35781.34857
    dv1, dv2, tof = hohmann(r1 * 1e3, r2 * 1e3, MU_KM * 1e9)
    # the example prints 7 significant digits
    assert dv1 == pytest.approx(2457.038, abs=5e-4)
    assert dv2 == pytest.approx(1478.187, abs=5e-4)
    assert tof / 3600.0 == pytest.approx(5.256713, abs=5e-7)
    down = hohmann(r2 * 1e3, r1 * 1e3, MU_KM * 1e9)  # the way back: same magnitudes, negative
    assert down[0] == pytest.approx(-dv2, rel=1e-14) and down[1] == pytest.approx(-dv1, rel=1e-14)


def test_hohmann_flown_with_two_impulses_arrives_on_the_target_circle():
    mu = MU_KM * 1e9
    r1, r2 = (R_E + 191.34411) * 1e3, (R_E + 35781.34857) * 1e3
    dv1, dv2, tof = hohmann(r1, r2, mu)
    r0 = np.array([r1, 0.0, 0.0])
    v0 = np.array([0.0, math.sqrt(mu / r1), 0.0])
    v_burn = apply_impulse(v0, dv1 * v0 / np.linalg.norm(v0))
    ra, va = propagate(r0, v_burn, tof, mu)
    assert np.linalg.norm(ra) == pytest.approx(r2, rel=1e-12)  # apoapsis reached at tof
    vb = apply_impulse(va, dv2 * va / np.linalg.norm(va))
    period = 2 * math.pi * math.sqrt(r2**3 / mu)
    t = np.linspace(0.0, period, 500)
    r, _ = propagate(np.broadcast_to(ra, (t.size, 3)), np.broadcast_to(vb, (t.size, 3)), t, mu)
    assert np.max(np.abs(np.linalg.norm(r, axis=1) / r2 - 1.0)) < 1e-9


def test_finite_burn_follows_the_rocket_equation():
    thrust = ConstantThrust((10.0, 0.0, 0.0), mass=1000.0, isp=300.0)
    r0, v0 = np.array([1e9, 0.0, 0.0]), np.zeros(3)  # mu = 1 m^3/s^2 at 1e6 km: 1e-18 m/s^2 of gravity
    burn = 200.0
    st = propagate_perturbed(r0, v0, np.array([burn]), 1.0, perturbations=[thrust], rtol=1e-12, atol=1e-14)
    dv = st.v[-1] - v0
    m1 = thrust.mass_at(burn)
    assert m1 == pytest.approx(1000.0 - 10.0 / (300.0 * G0) * burn, rel=1e-15)
    assert dv[0] == pytest.approx(rocket_dv(300.0, 1000.0, m1), rel=1e-10)
    assert abs(dv[1]) < 1e-12 and abs(dv[2]) < 1e-12
    with pytest.raises(ValueError, match="mass is used up"):
        thrust.mass_at(1e9)


def test_bad_inputs_name_the_field():
    with pytest.raises(ValueError, match="r2"):
        hohmann(7e6, -1.0, 3.986e14)
    with pytest.raises(ValueError, match="force"):
        ConstantThrust((np.inf, 0, 0), 100.0)
    with pytest.raises(ValueError, match="mass"):
        ConstantThrust((1.0, 0, 0), 0.0)
    with pytest.raises(ValueError, match="dv"):
        apply_impulse([0.0, 0.0, 0.0], [np.nan, 0.0, 0.0])
