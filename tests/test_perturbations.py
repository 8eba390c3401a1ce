"""Tests for astrodyn.orbit.perturbations: zonal and third-body accelerations, the
Cowell / Encke propagator, and the unperturbed delegation.

Independent references:
* the zonal potential written here with mpmath's Legendre polynomials, and its
  gradient by 30-digit numerical differentiation (mpmath.diff);
* the third-body acceleration by the naive direct-minus-indirect formula at 40
  digits (no cancellation at that precision);
* energy conservation with the zonal potential;
* the secular J2 rates of RAAN and argument of perigee (Vallado 4th ed.
  eqs. 9-41, 9-42; Curtis eqs. 4.52, 4.53);
* REBOUND IAS15: the J2 twin of astrodyn.crosscheck and a restricted three-body
  system (central mass + massive perturber + test particle) built here;
* Cowell against Encke (different formulations of the same physics).
"""

from __future__ import annotations

import math

import mpmath as mp
import numpy as np
import pytest

from astrodyn.orbit import propagate
from astrodyn.orbit.elements import elements_from_state, state_from_elements
from astrodyn.orbit.perturbations import (
    EARTH_EGM2008,
    EARTH_WGS84,
    MOON,
    KeplerOrbit,
    ThirdBody,
    Zonal,
    point_mass_difference,
    propagate_perturbed,
    third_body_acceleration,
    zonal_acceleration,
    zonal_potential,
)

EPS = np.finfo(np.float64).eps
EARTH = EARTH_EGM2008
MU, RE = EARTH.mu, EARTH.radius
J2 = EARTH.J[0]


def period(a, mu=MU):
    return 2 * math.pi * math.sqrt(a**3 / mu)


# --------------------------------------------------------------------------- constants


def test_earth_constants_match_published_values():
    # Earth's J2 as commonly published, 1.0826267e-3 (zero-tide, e.g. Vallado
    # 4th ed. Table D-3); EGM2008 tide-free differs by the permanent-tide term,
    # about 5e-7 relative, hence rel=1e-6.  J3..J6 to the 5 figures quoted in
    # Vallado Table D-3 / Montenbruck & Gill Table 3.2.  WGS84 J2 from
    # NGA.STND.0036 (1.08262982e-3).
    assert EARTH_EGM2008.J[0] == pytest.approx(1.0826267e-3, rel=1e-6)
    assert EARTH_EGM2008.J[1] == pytest.approx(-2.5324e-6, rel=1e-4)
    assert EARTH_EGM2008.J[2] == pytest.approx(-1.6199e-6, rel=1e-4)
    assert EARTH_EGM2008.J[3] == pytest.approx(-2.2775e-7, rel=1e-4)
    assert EARTH_EGM2008.J[4] == pytest.approx(5.4068e-7, rel=1e-4)
    assert EARTH_WGS84.J[0] == pytest.approx(1.08262982e-3, rel=1e-8)
    assert EARTH.zonal(2).J == (EARTH.J[0],)
    with pytest.raises(ValueError, match="degree"):
        EARTH.zonal(9)


# --------------------------------------------------------------------------- zonal field


def mp_zonal_potential(x, y, z, mu, R, J):
    r = mp.sqrt(x * x + y * y + z * z)
    return -mu / r * mp.fsum(Jn * (R / r) ** n * mp.legendre(n, z / r) for n, Jn in enumerate(J, start=2))


@pytest.mark.parametrize("degree", [2, 3, 6])
def test_zonal_acceleration_is_gradient_of_potential(degree):
    # a = grad V_J, V_J from mpmath's Legendre polynomials, gradient by
    # 30-digit numerical differentiation.  Tolerance: each term carries a few
    # eps relative rounding and the terms add with factors up to (2n + 2), so
    # 100 eps * mu/r^2 * sum |J_n| (R/r)^n (2n + 2).
    J = EARTH.J[: degree - 1]
    rng = np.random.default_rng(degree)
    pts = rng.normal(size=(25, 3))
    pts /= np.linalg.norm(pts, axis=1)[:, None]
    pts *= rng.uniform(RE, 8 * RE, 25)[:, None]
    pts[0] = [0.0, 0.0, 1.1 * RE]  # over the pole
    pts[1] = [1.05 * RE, 0.0, 0.0]  # equator
    got = zonal_acceleration(pts, MU, RE, J)
    gotV = zonal_potential(pts, MU, RE, J)
    with mp.workdps(30):
        Jm = [mp.mpf(j) for j in J]
        for p, a, V in zip(pts, got, gotV):
            x, y, z = (mp.mpf(float(c)) for c in p)
            def f(X, Y, Z):
                return mp_zonal_potential(X, Y, Z, mp.mpf(MU), mp.mpf(RE), Jm)
            ref = [mp.diff(f, (x, y, z), (1, 0, 0)), mp.diff(f, (x, y, z), (0, 1, 0)), mp.diff(f, (x, y, z), (0, 0, 1))]
            r = float(mp.sqrt(x * x + y * y + z * z))
            scale = MU / r**2 * sum(abs(j) * (RE / r) ** n * (2 * n + 2) for n, j in enumerate(J, start=2))
            assert np.max(np.abs(a - np.array([float(c) for c in ref]))) <= 100 * EPS * scale
            Vref = float(f(x, y, z))
            assert abs(V - Vref) <= 100 * EPS * MU / r * sum(abs(j) * (RE / r) ** n for n, j in enumerate(J, start=2))


def test_j2_fast_path_matches_general_recurrence():
    rng = np.random.default_rng(1)
    r = rng.normal(size=(100, 3)) * 7e6
    fast = zonal_acceleration(r, MU, RE, (J2,))
    general = zonal_acceleration(r, MU, RE, (J2, 0.0))
    scale = MU / np.sum(r * r, axis=1) * J2 * (RE**2 / np.sum(r * r, axis=1)) * 6
    assert np.all(np.abs(fast - general).max(axis=1) <= 100 * EPS * scale)
    # shape contract: scalar call and leading axes
    assert zonal_acceleration(r[0], MU, RE, (J2,)).shape == (3,)
    assert zonal_acceleration(r.reshape(10, 10, 3), MU, RE, EARTH.J).shape == (10, 10, 3)


# --------------------------------------------------------------------------- third body


def mp_third_body(r, s, mu3):
    with mp.workdps(40):
        r = [mp.mpf(float(c)) for c in r]
        s = [mp.mpf(float(c)) for c in s]
        d = [si - ri for si, ri in zip(s, r)]
        dn3 = mp.sqrt(sum(c * c for c in d)) ** 3
        sn3 = mp.sqrt(sum(c * c for c in s)) ** 3
        return np.array([float(mp.mpf(mu3) * (di / dn3 - si / sn3)) for di, si in zip(d, s)])


@pytest.mark.parametrize("ratio", [1e-8, 1e-4, 1e-2, 0.5, 3.0])
def test_third_body_against_direct_formula_at_40_digits(ratio):
    # |r| / |s| = ratio: at 1e-8 the direct and indirect terms agree to 8
    # digits, so the naive float64 difference would keep only ~8 digits;
    # Battin's f(q) form must keep all of them.  Tolerance 100 eps relative to
    # the perturbing acceleration itself (the one-ulp sensitivity of the
    # tidal term is a few eps).
    rng = np.random.default_rng(int(-math.log10(ratio) * 10) + 7)
    for _ in range(20):
        s = rng.normal(size=3)
        s *= 3.84e8 / np.linalg.norm(s)
        r = rng.normal(size=3)
        r *= ratio * 3.84e8 / np.linalg.norm(r)
        got = third_body_acceleration(r, s, MOON.mu)
        ref = mp_third_body(r, s, MOON.mu)
        assert np.linalg.norm(got - ref) <= 100 * EPS * np.linalg.norm(ref)
    naive = MOON.mu * ((s - r) / np.linalg.norm(s - r) ** 3 - s / np.linalg.norm(s) ** 3)
    if ratio == 1e-8:  # demonstrate the cancellation the formulation avoids
        assert np.linalg.norm(naive - ref) > 1e4 * EPS * np.linalg.norm(ref)


def test_point_mass_difference_small_offsets():
    # Encke's deviation term G(rho + delta) - G(rho) for |delta| / |rho| from
    # 1e-12 to 1e-1 against 40 digits.  Tolerance 100 eps relative.
    rng = np.random.default_rng(3)
    for k in range(-12, 0):
        rho = rng.normal(size=3) * 7e6
        delta = rng.normal(size=3) * 7e6 * 10.0**k
        got = point_mass_difference(rho, delta, MU)
        with mp.workdps(40):
            x = [mp.mpf(float(c)) for c in rho]
            y = [mp.mpf(float(a)) + mp.mpf(float(b)) for a, b in zip(rho, delta)]
            def g(u):
                return [-mp.mpf(MU) * c / mp.sqrt(sum(w * w for w in u)) ** 3 for c in u]
            ref = np.array([float(a - b) for a, b in zip(g(y), g(x))])
        assert np.linalg.norm(got - ref) <= 100 * EPS * np.linalg.norm(ref)


# --------------------------------------------------------------------------- delegation


def test_no_perturbation_delegates_to_exact_kepler(monkeypatch):
    # An unperturbed scene must never integrate: make the integrator explode
    # if touched, and compare with the exact propagator bit for bit.
    import scipy.integrate

    def boom(*a, **k):
        raise AssertionError("the integrator was called for an unperturbed scene")

    monkeypatch.setattr(scipy.integrate, "DOP853", boom)
    r0, v0 = state_from_elements(8e6, 0.3, 0.5, 0.1, 0.2, 0.3, MU)
    t = np.array([0.0, 100.0, -50.0, 1e5])
    for perts in ([], (), None, [Zonal(MU, RE, (0.0, 0.0))], [ThirdBody(0.0, [1e9, 0, 0])]):
        out = propagate_perturbed(r0, v0, t, MU, perts)
        assert out.method == "kepler" and out.integrated is False
        assert "nothing integrated" in out.message
        r, v = propagate(r0[None, :], v0[None, :], t, MU)
        np.testing.assert_array_equal(out.r, r)
        np.testing.assert_array_equal(out.v, v)
        assert out.r.shape == (4, 3)
    out = propagate_perturbed(r0, v0, 100.0, MU)
    assert out.r.shape == (3,)


# --------------------------------------------------------------------------- conservation, Encke vs Cowell


def energy(r, v, zonal):
    return 0.5 * np.sum(v * v, -1) - MU / np.linalg.norm(r, axis=-1) - zonal.potential(r)


@pytest.mark.parametrize("method", ["cowell", "encke"])
def test_energy_with_zonal_potential_is_conserved(method):
    # J2..J6 is conservative and time-independent: v^2/2 - mu/r - V_J is an
    # integral.  Its drift must be covered by the propagator's own error
    # estimate (dE <= |dE/dr| err_r + |dE/dv| err_v, with dE/dr ~ mu/r^2 and
    # dE/dv = v; factor 3 for the estimate's own uncertainty) and sit at the
    # requested tolerance level (rtol 1e-11 -> < 1e-10 relative over 10 orbits).
    zonal = EARTH.zonal(6)
    a, e = 8e6, 0.2
    r0, v0 = state_from_elements(a * (1 - e * e), e, 1.1, 0.3, 0.4, 0.0, MU)
    t = np.linspace(0, 10 * period(a), 41)
    out = propagate_perturbed(r0, v0, t, MU, [zonal], method=method, rtol=1e-11, atol=1e-13)
    E = energy(out.r, out.v, zonal)
    dE = np.abs(E - E[0])
    rn = np.linalg.norm(out.r, axis=-1)
    bound = 3 * (MU / rn**2 * out.error_r + np.linalg.norm(out.v, axis=-1) * out.error_v) + 10 * EPS * abs(E[0])
    assert np.all(dE <= bound)
    assert dE.max() < 1e-10 * abs(E[0])
    assert out.integrated and out.method == method


def test_encke_agrees_with_cowell():
    # Same physics, two formulations: they must agree within the sum of their
    # error estimates (x3 for the estimates' own uncertainty).
    a, e = 7.5e6, 0.05
    r0, v0 = state_from_elements(a * (1 - e * e), e, 0.9, 0.3, 0.4, 0.0, MU)
    moon = ThirdBody(MOON.mu, KeplerOrbit([3.84e8, 0, 0], [0, 1022.0, 0], MU + MOON.mu))
    t = np.linspace(0, 4 * period(a), 9)
    perts = [EARTH.zonal(4), moon]
    c = propagate_perturbed(r0, v0, t, MU, perts, method="cowell", rtol=1e-11, atol=1e-13)
    k = propagate_perturbed(r0, v0, t, MU, perts, method="encke", rtol=1e-11, atol=1e-13)
    assert k.rectifications > 0
    diff = np.linalg.norm(c.r - k.r, axis=-1)
    assert np.all(diff <= 3 * (c.error_r + k.error_r) + 100 * EPS * np.linalg.norm(c.r, axis=-1))
    # and the perturbation is really there (kilometres after 4 orbits)
    kep = propagate_perturbed(r0, v0, t, MU, [])
    assert np.linalg.norm(kep.r[-1] - c.r[-1]) > 1e3


def test_encke_without_rectification_matches_cowell_weak_perturbation():
    # A weak perturbation (distant third body only) keeps |delta|/|rho| small:
    # Encke integrates only the tiny deviation and needs no rectification.
    a = 7e6
    r0, v0 = state_from_elements(a, 0.0, 0.5, 0.0, 0.0, 0.0, MU)
    moon = ThirdBody(MOON.mu, [3.84e8, 0.0, 0.0])
    t = np.linspace(0, 3 * period(a), 7)
    c = propagate_perturbed(r0, v0, t, MU, [moon], method="cowell", rtol=1e-12, atol=1e-14)
    k = propagate_perturbed(r0, v0, t, MU, [moon], method="encke", rtol=1e-12, atol=1e-14)
    assert k.rectifications == 0
    diff = np.linalg.norm(c.r - k.r, axis=-1)
    assert np.all(diff <= 3 * (c.error_r + k.error_r) + 100 * EPS * a)
    assert k.nsteps < c.nsteps  # the point of Encke: the smooth deviation takes longer steps


@pytest.mark.parametrize("method", ["cowell", "encke"])
def test_error_estimate_bounds_the_true_error(method):
    # Loose run (rtol 1e-9) against a reference 10^4 times tighter: the
    # reported error_r must cover the actual error at every output time
    # (measured margin 3-8x).
    a, e = 7.5e6, 0.1
    r0, v0 = state_from_elements(a * (1 - e * e), e, 0.9, 0.3, 0.4, 0.0, MU)
    t = np.linspace(0, 6 * period(a), 7)
    perts = [EARTH.zonal(6)]
    ref = propagate_perturbed(r0, v0, t, MU, perts, rtol=1e-13, atol=1e-15, error_estimate=False)
    out = propagate_perturbed(r0, v0, t, MU, perts, method=method, rtol=1e-9, atol=1e-11)
    true = np.linalg.norm(out.r - ref.r, axis=-1)
    assert np.all(true[1:] <= out.error_r[1:])
    assert np.all(out.error_r[1:] <= 100 * true[1:] + 1e-3)  # and not uselessly loose


# --------------------------------------------------------------------------- J2 secular rates


def fitted_rates(a, e, i, argp, n_orbits=30, per_orbit=16):
    """Propagate with J2 only and fit straight lines to the osculating RAAN and
    argument of perigee (sampled at whole-orbit multiples so short-periodic
    terms average out).  Returns (measured dO, dw, predicted dO, dw, scale)
    where the prediction uses the time-averaged osculating a, e, i."""
    p = a * (1 - e * e)
    r0, v0 = state_from_elements(p, e, i, 0.3, argp, 0.0, MU)
    t = np.linspace(0, n_orbits * period(a), n_orbits * per_orbit + 1)
    out = propagate_perturbed(r0, v0, t, MU, [EARTH.zonal(2)], rtol=1e-10, atol=1e-12, error_estimate=False)
    el = elements_from_state(out.r, out.v, MU)
    dO = np.polyfit(t, np.unwrap(el.raan), 1)[0]
    dw = np.polyfit(t, np.unwrap(el.argp), 1)[0]
    am, em, im = np.mean(el.a), np.mean(el.e), np.mean(el.i)
    pm = am * (1 - em * em)
    k = math.sqrt(MU / am**3) * J2 * (RE / pm) ** 2
    return dO, dw, -1.5 * k * math.cos(im), 0.75 * k * (5 * math.cos(im) ** 2 - 1), 3 * k, J2 * (RE / pm) ** 2


# Tolerance for all J2 rate checks: the first-order secular rates neglect
# (a) O(J2^2) secular terms (Brouwer 1959), relative size ~ J2 (R/p)^2, and
# (b) the difference between osculating and mean elements (short-period terms
# of relative size ~ J2 (R/p)^2 in a, e, i, entering the rate formula through
# n (R/p)^2 with factor ~3.5).  Sampling 30 whole orbits removes most of the
# short-period signal from the fitted slope.  Measured: ~1e-3 relative on a LEO
# (J2 (R/p)^2 = 9e-4), 8e-5 on the Molniya orbit.  Allowed: 5 J2 (R/p)^2.


def test_j2_secular_rates_leo():
    dO, dw, dO_th, dw_th, scale, small = fitted_rates(7.0e6, 0.05, math.radians(50.0), 0.5)
    assert abs(dO / dO_th - 1) <= 5 * small
    assert abs(dw - dw_th) <= 5 * small * scale
    assert dw > 0 and dO < 0  # below the critical inclination perigee advances, node regresses


def test_frozen_perigee_at_critical_inclination_molniya():
    # Molniya-like orbit: a = 26,600 km, e = 0.74, i = 63.4349 deg
    # (cos^2 i = 1/5): argp drift ~ 0, RAAN still regresses at the formula rate.
    i_crit = math.acos(math.sqrt(0.2))
    dO, dw, dO_th, dw_th, scale, small = fitted_rates(26.6e6, 0.74, i_crit, math.radians(270.0))
    assert abs(dw_th) < small * scale  # the prediction is ~0 here (mean i is within ~J2 of critical)
    assert abs(dw) <= 5 * small * scale
    assert abs(dO / dO_th - 1) <= 5 * small
    # contrast: 10 degrees away the perigee drifts by far more than the tolerance
    dO2, dw2, _, dw2_th, scale2, small2 = fitted_rates(26.6e6, 0.74, i_crit - math.radians(10), math.radians(270.0))
    assert abs(dw2) > 20 * 5 * small2 * scale2
    assert abs(dw2 / dw2_th - 1) <= 5 * small2


def test_sun_synchronous_inclination():
    # Choose i so that the first-order nodal rate equals the mean motion of the
    # Sun, 2 pi / 365.2422 days (Vallado sec. 11.4.4); the integrated orbit must
    # precess at that rate.  a = R + 700 km, e = 0.001 -> i = 98.19 deg.
    a, e = RE + 700e3, 0.001
    p = a * (1 - e * e)
    target = 2 * math.pi / (365.2422 * 86400.0)
    ci = -target / (1.5 * math.sqrt(MU / a**3) * J2 * (RE / p) ** 2)
    i = math.acos(ci)
    assert math.degrees(i) == pytest.approx(98.19, abs=0.01)
    dO, _, dO_th, _, _, small = fitted_rates(a, e, i, 0.5)
    assert abs(dO / target - 1) <= 5 * small
    assert abs(dO / dO_th - 1) <= 5 * small


# --------------------------------------------------------------------------- REBOUND


def test_j2_against_rebound_ias15():
    from astrodyn.crosscheck import ReboundScene

    a, e = 7.2e6, 0.1
    r0, v0 = state_from_elements(a * (1 - e * e), e, 0.8, 0.2, 0.3, 0.0, MU)
    scene = ReboundScene(r0, v0, MU, model="j2", j2=J2, body_radius=RE)
    times = [1.3 * period(a), 5.7 * period(a)]
    rb, el = [], []
    for t in times:
        r, _ = scene.advance_to(t)
        rb.append(r[0])
        el.append(scene.elapsed)
    out = propagate_perturbed(r0, v0, np.array(el), MU, [EARTH.zonal(2)], rtol=1e-12, atol=1e-14)
    diff = np.linalg.norm(out.r - np.array(rb), axis=-1)
    # IAS15 works at round-off per step; its global error after ~2e3 steps is
    # ~1e-12 relative; ours is estimated by error_r.  Tolerance: 3 x our
    # estimate + 1e-11 relative for REBOUND.
    assert np.all(diff <= 3 * out.error_r + 1e-11 * a)
    kep = propagate(r0, v0, el[-1], MU)[0]
    assert np.linalg.norm(kep - rb[-1]) > 1e4  # J2 moved it by > 10 km: the test can fail


def rebound_restricted_three_body(mu_c, mu3, s0, s_dot0, r0, v0, times):
    """Central mass + massive perturber + test particle in REBOUND IAS15
    (G = 1, masses = mu), stepped by hand to land exactly on each time, with
    the elapsed time summed exactly (math.fsum of the steps).  Returns the test
    particle's and the perturber's positions relative to the central body and
    the exact elapsed times."""
    import rebound

    sim = rebound.Simulation()
    sim.G = 1.0
    sim.integrator = "ias15"
    sim.add(m=mu_c)
    sim.add(m=mu3, x=s0[0], y=s0[1], z=s0[2], vx=s_dot0[0], vy=s_dot0[1], vz=s_dot0[2])
    sim.add(m=0.0, x=r0[0], y=r0[1], z=r0[2], vx=v0[0], vy=v0[1], vz=v0[2])
    sim.N_active = 2
    sim.testparticle_type = 0
    steps = []
    out_r, out_s, out_t = [], [], []
    for target in times:
        while True:
            remaining = target - math.fsum(steps)
            if remaining <= 0:
                break
            proposal = sim.dt
            last = proposal >= remaining
            if last:
                sim.dt = remaining
            sim.steps(1)
            steps.append(sim.dt_last_done)
            if last:
                sim.dt = proposal
                break
        c, p, q = sim.particles[0], sim.particles[1], sim.particles[2]
        out_r.append(np.array(q.xyz) - np.array(c.xyz))
        out_s.append(np.array(p.xyz) - np.array(c.xyz))
        out_t.append(math.fsum(steps))
    return np.array(out_r), np.array(out_s), np.array(out_t)


def test_third_body_against_rebound_restricted_three_body():
    # Earth + a 10x Moon on a circular orbit (closed form, independent of the
    # Kepler propagator) + a satellite at 100,000 km: the perturbation is
    # strong (hundreds of km over 10 days).  REBOUND integrates the full
    # three-body problem (the Earth reacts to the perturber), which in
    # Earth-centred coordinates is exactly our model: central mu_c, third body
    # mu3 on its relative orbit about mu_c + mu3.
    mu_c, mu3 = MU, 10 * MOON.mu
    d = 3.84e8
    n3 = math.sqrt((mu_c + mu3) / d**3)
    s0 = np.array([d, 0.0, 0.0])
    s_dot0 = np.array([0.0, n3 * d, 0.0])

    def moon_pos(t):
        return np.array([d * math.cos(n3 * t), d * math.sin(n3 * t), 0.0])

    a = 1.0e8
    r0, v0 = state_from_elements(a * (1 - 0.2**2), 0.2, 0.4, 0.5, 0.6, 0.0, mu_c)
    times = np.array([0.37, 2.1, 5.0, 10.0]) * 86400.0
    r_rb, s_rb, elapsed = rebound_restricted_three_body(mu_c, mu3, s0, s_dot0, r0, v0, times)
    # the perturber really moves on the closed-form circle in REBOUND too
    for t, s in zip(elapsed, s_rb):
        assert np.linalg.norm(s - moon_pos(t)) <= 1e-9 * d
    out = propagate_perturbed(r0, v0, elapsed, mu_c, [ThirdBody(mu3, moon_pos)], rtol=1e-12, atol=1e-14)
    diff = np.linalg.norm(out.r - r_rb, axis=-1)
    # Tolerance: 3 x our error estimate + REBOUND's (IAS15 at round-off per
    # step, ~1e-11 relative after ~1e3 steps) + the closed-form perturber's
    # 1e-9-relative position mismatch propagated through the tidal term (tiny).
    assert np.all(diff <= 3 * out.error_r + 1e-11 * a)
    kep = propagate_perturbed(r0, v0, elapsed, mu_c, [])
    assert np.linalg.norm(kep.r[-1] - r_rb[-1]) > 1e5  # the third body matters (>100 km)
    # the same with the perturber as a KeplerOrbit (through astrodyn.orbit.propagate)
    out2 = propagate_perturbed(r0, v0, elapsed, mu_c, [ThirdBody(mu3, KeplerOrbit(s0, s_dot0, mu_c + mu3))], rtol=1e-12, atol=1e-14)
    assert np.all(np.linalg.norm(out2.r - r_rb, axis=-1) <= 3 * out2.error_r + 1e-11 * a)


# --------------------------------------------------------------------------- vectorization, time axis, errors


def test_stacked_bodies_match_single_runs_and_shapes():
    rng = np.random.default_rng(4)
    n = 4
    p = rng.uniform(7e6, 9e6, n)
    e = rng.uniform(0, 0.3, n)
    i, raan, argp, nu = rng.uniform(0, 3, (4, n))
    r0, v0 = state_from_elements(p, e, i, raan, argp, nu, MU)
    t = np.array([3000.0, 0.0, 20000.0, 7000.0])
    perts = [EARTH.zonal(3)]
    out = propagate_perturbed(r0.reshape(2, 2, 3), v0.reshape(2, 2, 3), t, MU, perts, rtol=1e-11, atol=1e-13)
    assert out.r.shape == (2, 2, 4, 3) and out.error_r.shape == (2, 2, 4)
    flat = out.r.reshape(n, 4, 3)
    for k in range(n):
        single = propagate_perturbed(r0[k], v0[k], t, MU, perts, rtol=1e-11, atol=1e-13)
        assert single.r.shape == (4, 3)
        tol = 3 * (single.error_r + out.error_r.reshape(n, 4)[k]) + 100 * EPS * p[k]
        assert np.all(np.linalg.norm(flat[k] - single.r, axis=-1) <= tol)
        np.testing.assert_array_equal(flat[k, 1], r0[k])  # t = 0 is the initial state
    one = propagate_perturbed(r0[0], v0[0], 5000.0, MU, perts)
    assert one.r.shape == (3,) and np.ndim(one.error_r) == 0


def test_backward_and_unsorted_times_return_to_start():
    a = 7e6
    r0, v0 = state_from_elements(a, 0.01, 1.0, 0.0, 0.0, 0.0, MU)
    perts = [EARTH.zonal(2)]
    T = 2 * period(a)
    out = propagate_perturbed(r0, v0, np.array([T, -T, 0.5 * T, -0.5 * T]), MU, perts, rtol=1e-12, atol=1e-14)
    # forward then back from the forward end state returns to r0
    back = propagate_perturbed(out.r[0], out.v[0], -T, MU, perts, rtol=1e-12, atol=1e-14)
    assert np.linalg.norm(back.r - r0) <= 3 * (out.error_r[0] + back.error_r) + 100 * EPS * a
    # backward in time is the time-reverse: propagating the reversed velocity forward
    rev = propagate_perturbed(r0, -v0, T, MU, perts, rtol=1e-12, atol=1e-14)
    assert np.linalg.norm(rev.r - out.r[1]) <= 3 * (out.error_r[1] + rev.error_r) + 100 * EPS * a


def test_bad_inputs_and_nan_bodies():
    r0, v0 = state_from_elements(7e6, 0.0, 1.0, 0.0, 0.0, 0.0, MU)
    z = [EARTH.zonal(2)]
    with pytest.raises(ValueError, match="method"):
        propagate_perturbed(r0, v0, 10.0, MU, z, method="rk4")
    with pytest.raises(ValueError, match="r0 must have shape"):
        propagate_perturbed(r0[:2], v0, 10.0, MU, z)
    with pytest.raises(ValueError, match="v0 must have the shape"):
        propagate_perturbed(r0, np.stack([v0, v0]), 10.0, MU, z)
    with pytest.raises(ValueError, match="mu"):
        propagate_perturbed(r0, v0, 10.0, -1.0, z)
    with pytest.raises(ValueError, match="t must be finite"):
        propagate_perturbed(r0, v0, [0.0, np.nan], MU, z)
    with pytest.raises(ValueError, match="acceleration"):
        propagate_perturbed(r0, v0, 10.0, MU, [object()])
    with pytest.raises(ValueError, match="Zonal"):
        Zonal(-1.0, RE, (J2,))
    r2 = np.stack([r0, [np.nan, 0, 0]])
    v2 = np.stack([v0, v0])
    out = propagate_perturbed(r2, v2, [100.0, 200.0], MU, z)
    assert np.all(np.isnan(out.r[1])) and np.all(np.isfinite(out.r[0]))
    with pytest.raises(RuntimeError, match="max_steps"):
        propagate_perturbed(r0, v0, 1e6, MU, z, max_steps=5)
