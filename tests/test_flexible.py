"""Lightly flexible spacecraft (astrodyn.attitude.flexible) against independent references.

* Non-spinning cantilever: the exact frequencies ``(beta_j L)^2 sqrt(EI / (rho L^4))`` with
  ``cos x cosh x = -1`` solved here by mpmath, and the exact Rayleigh-Ritz values of the
  same polynomial span from rational matrices in 50-digit arithmetic (upper bounds,
  monotone in ``n``, converging super-geometrically).
* Spinning beam: Southwell coefficient 1.1933 (Wright, Smith, Thresher & Wang, J. Appl.
  Mech. 49, 1982; Hodges & Rutkowski, AIAA J. 19, 1981), their tabulated first flapping
  frequencies, and frequencies from shooting on the beam's ODE (scipy) here.
* Kane, Ryan & Banerjee (J. Guidance 10(2), 1987) spin-up: against the quasi-static
  deflection from the static beam ODE (shooting), and the classical model's divergence.
* 3D spacecraft: kinetic energy and momenta against direct quadrature over the beams of
  the exact velocity field of the model's kinematics (agreement to second order in the
  elastic coordinates), linearised frequencies against the spinning-beam frequencies and
  the ``omega_k +- Omega`` of a beam spinning about its own axis, the symmetric pair
  against the independently coded planar model, conservation laws with bounds from the
  integrator's error control, and the rigid limit against the exact torque-free solution.
* Hostile input: ValueError naming the field.
"""

import math
import sys
from pathlib import Path

import mpmath as mp
import numpy as np
import pytest
from scipy.integrate import quad, solve_ivp
from scipy.linalg import eigh
from scipy.optimize import brentq

from astrodyn.attitude import flexible as fx, torque_free

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _hostile_calls import assert_refused_quickly
from _integration_bounds import dop853_drift_bound

EPS = np.finfo(float).eps
# the KRB (1987) beam: L = 10 m, A = 4e-4 m^2, density 3000 kg/m^3, E = 7e10 Pa, I = 2e-7 m^4
KRB = {"EI": 14000.0, "rho": 1.2, "L": 10.0}


def _unit(v):
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


# --------------------------------------------------------------------------- independent references


_MP_DPS = 50


def _beta_L():
    """First three roots of cos x cosh x = -1, 50 digits (mpmath)."""
    with mp.workdps(_MP_DPS):
        return [mp.findroot(lambda x: mp.cos(x) * mp.cosh(x) + 1, x0) for x0 in (1.9, 4.7, 7.85)]


_RITZ_CACHE = {}


def _exact_ritz(n):
    """Exact Rayleigh-Ritz frequencies (units sqrt(EI / (rho L^4))) of the span of
    xi^2 .. xi^(n+1), from the rational matrices M_ab = 1/(a+b+1), K_ab = a(a-1)b(b-1)/(a+b-3)
    (phi_a = xi^a), in 50-digit arithmetic: the monomial Gram matrix's condition (~1e18 at
    n = 24) leaves > 30 digits."""
    if n not in _RITZ_CACHE:
        with mp.workdps(_MP_DPS):
            M, K = mp.matrix(n, n), mp.matrix(n, n)
            for i in range(n):
                for j in range(n):
                    a, b = i + 2, j + 2
                    M[i, j] = mp.mpf(1) / (a + b + 1)
                    K[i, j] = mp.mpf(a * (a - 1) * b * (b - 1)) / (a + b - 3)
            Li = mp.inverse(mp.cholesky(M))
            A = Li * K * Li.T
            ev = mp.eigsy((A + A.T) / 2, eigvals_only=True)
            _RITZ_CACHE[n] = sorted(mp.sqrt(ev[i]) for i in range(n))
    return _RITZ_CACHE[n]


def _shoot_det(om2, lam, r):
    """Clamped-free beam spinning about a normal axis (flapping), units L = EI = rho = 1:
    w'''' - (P w')' = om2 w, P = lam^2 (r (1 - x) + (1 - x^2)/2).  Determinant of the
    free-end conditions (w''(1), w'''(1) - P(1) w'(1) = s(1)) over the two solutions with
    w(0) = w'(0) = 0."""

    def f(x, y):
        P = lam * lam * (r * (1 - x) + (1 - x * x) / 2)
        out = np.empty(8)
        for k in (0, 4):
            w, wp, wpp, s = y[k : k + 4]
            out[k : k + 4] = wp, wpp, s + P * wp, om2 * w
        return out

    sol = solve_ivp(f, (0.0, 1.0), [0, 0, 1, 0, 0, 0, 0, 1.0], method="DOP853", rtol=1e-13, atol=1e-15)
    y = sol.y[:, -1]
    return y[2] * y[7] - y[3] * y[6]


def _shooting_flap(lam, r, guess):
    """Flapping frequency (units sqrt(EI/(rho L^4))) near ``guess`` (bracketed +-4%)."""
    om2 = brentq(_shoot_det, (0.96 * guess) ** 2, (1.04 * guess) ** 2, args=(lam, r), xtol=1e-13, rtol=4 * EPS)
    return math.sqrt(om2)


def _quasi_static_tip(EI, rho, L, spin, accel):
    """Tip of the static in-plane deflection of a cantilever (root on the axis) spinning at
    ``spin`` with angular acceleration ``accel``:  EI w'''' - (P w')' - rho spin^2 w =
    -rho accel x,  P = rho spin^2 (L^2 - x^2)/2, clamped-free; by superposition shooting."""

    def f(x, y):
        P = rho * spin * spin * (L * L - x * x) / 2
        out = np.empty(12)
        for k, load in ((0, 1.0), (4, 0.0), (8, 0.0)):
            w, wp, wpp, s = y[k : k + 4]
            out[k : k + 4] = wp, wpp, (s + P * wp) / EI, rho * spin * spin * w - load * rho * accel * x
        return out

    y0 = np.zeros(12)
    y0[6] = y0[11] = 1.0  # homogeneous solutions: w''(0) = 1, s(0) = 1
    y = solve_ivp(f, (0.0, L), y0, method="DOP853", rtol=1e-12, atol=1e-15).y[:, -1]
    A = np.array([[y[6], y[10]], [y[7], y[11]]])
    c = np.linalg.solve(A, -y[2:4])
    return y[0] + c[0] * y[4] + c[1] * y[8]


# --------------------------------------------------------------------------- 1. non-spinning cantilever


def test_characteristic_roots_match_published():
    bl = _beta_L()
    assert [float(b) for b in bl] == pytest.approx([1.8751040687, 4.6940911330, 7.8547574382], abs=6e-11)


def _roundoff_tol(omega):
    """Rounding allowance of computed Ritz frequencies: eigh's backward error perturbs every
    eigenvalue of the pencil by ~ p(n) eps lambda_max, i.e. omega_j relatively by
    ~ p(n) eps (omega_n / omega_j)^2; p(n) = 2 n^2 covers the two eigen-solutions of the
    construction (the modal basis, then the matrices' own)."""
    n = omega.size
    return 2.0 * n * n * EPS * (omega[-1] / omega) ** 2


@pytest.mark.parametrize("n", [1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 16, 20, 24])
def test_frequencies_are_the_exact_rayleigh_ritz_values(n):
    beam = fx.beam_matrices(n, **KRB)
    scale = math.sqrt(KRB["EI"] / (KRB["rho"] * KRB["L"] ** 4))
    ritz = np.array([float(x) for x in _exact_ritz(n)]) * scale
    np.testing.assert_array_less(np.abs(beam.omega0 / ritz - 1.0), _roundoff_tol(ritz))


def test_rayleigh_ritz_upper_bounds_monotone_and_converging():
    exact = _beta_L()
    with mp.workdps(_MP_DPS):
        err = {n: [(_exact_ritz(n)[j] - exact[j] ** 2) / exact[j] ** 2 for j in range(min(3, n))] for n in range(1, 13)}
        for n in range(1, 13):  # upper bounds (Rayleigh), non-increasing in n (nested spans)
            assert all(e > 0 for e in err[n])
            if n > 1:
                assert all(_exact_ritz(n)[j] <= _exact_ritz(n - 1)[j] for j in range(min(3, n - 1)))
    err = {n: [float(e) for e in v] for n, v in err.items()}
    # super-geometric convergence of the first frequency: the error's reduction per two
    # added functions (odd/even steps alternate) grows with n
    ratios = [err[n][0] / err[n + 2][0] for n in range(1, 11)]
    assert all(b > a for a, b in zip(ratios[:-1], ratios[1:], strict=True))
    assert err[6][0] < 1e-9 and err[10][0] < 1e-18 and max(err[12]) < 2e-12

    # the module: upper bounds to its rounding allowance, converged at n = 10 / 12
    scale = math.sqrt(KRB["EI"] / (KRB["rho"] * KRB["L"] ** 4))
    w_exact = np.array([float(b) ** 2 for b in exact]) * scale
    for n in range(1, 25):
        om = fx.beam_matrices(n, **KRB).omega0
        k = min(3, n)
        tol = _roundoff_tol(om)[:k]
        assert np.all(om[:k] >= w_exact[:k] * (1 - tol))
    # n = 10: Ritz error 7e-21, so the first frequency is right to its rounding allowance
    # (worst case 1.1e-7; measured ~1e-16: the lowest eigenvalue is far better than the bound)
    om10 = fx.beam_matrices(10, **KRB).omega0
    assert abs(om10[0] / w_exact[0] - 1) <= err[10][0] + _roundoff_tol(om10)[0]
    om12 = fx.beam_matrices(12, **KRB).omega0
    np.testing.assert_array_less(np.abs(om12[:3] / w_exact - 1), np.array(err[12]) + _roundoff_tol(om12)[:3])


def test_monomial_matrices_closed_form():
    """phi_a = (x/L)^a, a = 2 .. n+1: every matrix in closed form."""
    EI, rho, L, r, n = 700.0, 1.7, 3.0, 0.4, 6
    beam = fx.beam_matrices(n, EI, rho, L, r, basis="monomial")
    a = np.arange(n)[:, None] + 2.0
    b = a.T
    ref = {
        "M": rho * L / (a + b + 1),
        "K": EI / L**3 * a * (a - 1) * b * (b - 1) / (a + b - 3),
        "Sa": rho * a * b * (1 / (a + b - 1) - 1 / (a + b)),
        "Sb": rho * L * a * b / 2 * (1 / (a + b - 1) - 1 / (a + b + 1)),
        "G_tip": a * b / (L * (a + b - 1)),
    }
    ref["S"] = r * ref["Sa"] + ref["Sb"]
    for name, R in ref.items():  # quadrature of degree-exact Gauss rules: rounding only
        np.testing.assert_allclose(getattr(beam, name), R, rtol=1e-12, atol=0, err_msg=name)
    np.testing.assert_allclose(beam.beta, rho * L / (a[:, 0] + 1), rtol=1e-13)
    np.testing.assert_allclose(beam.gamma, rho * L * L / (a[:, 0] + 2), rtol=1e-13)
    np.testing.assert_allclose(beam.tip, 1.0, rtol=1e-13)
    x = np.array([0.0, 0.3 * L, L])
    np.testing.assert_allclose(fx.shape_functions(beam, x), (x / L) ** a, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(fx.shape_functions(beam, x, 1), a * x ** (a - 1) / L**a, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("n", [1, 3, 6, 8])
def test_modal_basis_spans_the_monomials(n):
    """Same span: the pencils (K, M) and (S, M) have the same eigenvalues in both bases, to
    the monomial Gram matrix's conditioning (eps cond(M) bounds its eigenvalue errors)."""
    EI, rho, L, r = 900.0, 1.3, 4.0, 0.7
    mod = fx.beam_matrices(n, EI, rho, L, r)
    mono = fx.beam_matrices(n, EI, rho, L, r, basis="monomial")
    tol = 10 * EPS * np.linalg.cond(mono.M)
    np.testing.assert_allclose(mono.omega0, mod.omega0, rtol=tol)
    np.testing.assert_allclose(eigh(mono.S, mono.M, eigvals_only=True), eigh(mod.S, mod.M, eigvals_only=True), rtol=tol)
    # M-orthonormality of computed eigenvectors: the same rounding allowance as the frequencies
    rt = _roundoff_tol(mod.omega0)[0]
    np.testing.assert_allclose(mod.M, rho * L * np.eye(n), rtol=0, atol=rt * rho * L)
    np.testing.assert_allclose(mod.K, rho * L * np.diag(mod.omega0**2), rtol=0, atol=rt * rho * L * mod.omega0[-1] ** 2)
    assert np.all(mod.tip > 0)
    phi = fx.shape_functions(mod, np.array([0.0]), 0)[:, 0]
    dphi = fx.shape_functions(mod, np.array([0.0]), 1)[:, 0]
    assert np.abs(phi).max() < 1e-12 and np.abs(dphi).max() < 1e-12 / L


def test_modal_damping_matrix():
    zeta = 0.03
    beam = fx.beam_matrices(5, 2000.0, 0.9, 6.0, damping_ratio=zeta)
    lam, V = eigh(beam.K, beam.M)
    np.testing.assert_allclose(V.T @ beam.C @ V, np.diag(2 * zeta * np.sqrt(lam)), atol=1e-11 * np.sqrt(lam[-1]))


# --------------------------------------------------------------------------- 2. spinning beam


def test_southwell_coefficient():
    """First flapping mode, r = 0: lambda_1 = d omega^2 / d Omega^2 at Omega = 0."""
    b1 = float(_beta_L()[0])
    s1 = (math.cosh(b1) + math.cos(b1)) / (math.sinh(b1) + math.sin(b1))

    def phi(x):
        return math.cosh(b1 * x) - math.cos(b1 * x) - s1 * (math.sinh(b1 * x) - math.sin(b1 * x))

    def dphi(x):
        return b1 * (math.sinh(b1 * x) + math.sin(b1 * x) - s1 * (math.cosh(b1 * x) - math.cos(b1 * x)))

    num = quad(lambda x: (1 - x * x) / 2 * dphi(x) ** 2, 0, 1, epsabs=0, epsrel=1e-13)[0]
    den = quad(lambda x: phi(x) ** 2, 0, 1, epsabs=0, epsrel=1e-13)[0]
    lam_exact = num / den  # Rayleigh quotient of the exact mode: first-order perturbation
    assert lam_exact == pytest.approx(1.1933, abs=5e-5)  # Wright et al. 1982
    for EI, rho, L in ((1.0, 1.0, 1.0), tuple(KRB.values())):
        beam = fx.beam_matrices(10, EI, rho, L)
        lam_code = beam.S[0, 0] / beam.M[0, 0]  # modal basis: first-order eigenvalue perturbation
        # eigenvector error ~ sqrt of the eigenvalue error (7e-21 at n = 10): 1e-10
        assert lam_code == pytest.approx(lam_exact, rel=1e-9)
        # and natural_frequencies at a small spin: O(dOmega^2) curvature, eps w0^2/dOmega^2 rounding
        dW = 1e-3 * beam.omega0[0]
        w2 = fx.natural_frequencies(beam, spin=dW)[0] ** 2
        assert (w2 - beam.omega0[0] ** 2) / dW**2 == pytest.approx(lam_exact, rel=1e-5)


# Wright et al. (1982) / Hodges & Rutkowski (1981): first flapping frequency, r = 0, at the
# nondimensional spin lam = Omega sqrt(rho L^4 / EI), 4 decimals
_WRIGHT_FIRST = {1: 3.6816, 2: 4.1373, 5: 6.4495, 10: 11.2023, 12: 13.1702}


@pytest.mark.parametrize("lam", sorted(_WRIGHT_FIRST))
def test_spinning_flap_frequency_published_and_shooting(lam):
    EI, rho, L = KRB.values()
    unit = math.sqrt(EI / (rho * L**4))
    beam = fx.beam_matrices(10, EI, rho, L)
    out = fx.natural_frequencies(beam, spin=lam * unit, plane="out") / unit
    assert out[0] == pytest.approx(_WRIGHT_FIRST[lam], abs=5e-5)
    # shooting (rtol 1e-13 on the ODE: roots to ~1e-11); Ritz error at n = 10 ~ 1e-10
    assert out[0] == pytest.approx(_shooting_flap(lam, 0.0, out[0]), rel=1e-8)
    if lam in (2, 10):
        assert out[1] == pytest.approx(_shooting_flap(lam, 0.0, out[1]), rel=1e-8)


@pytest.mark.parametrize("r", [0.5, 2.0])
def test_spinning_flap_frequency_with_hub_radius(r):
    """S = r Sa + Sb against shooting with the tension of a root at r (units of L)."""
    EI, rho, L, lam = 3.0, 2.0, 1.5, 4.0
    unit = math.sqrt(EI / (rho * L**4))
    beam = fx.beam_matrices(10, EI, rho, L, r=r * L)
    out = fx.natural_frequencies(beam, spin=lam * unit) / unit
    for j in (0, 1):
        assert out[j] == pytest.approx(_shooting_flap(lam, r, out[j]), rel=1e-8)


@pytest.mark.parametrize("spin", [0.5, 3.0, 10.0])
def test_lead_lag_is_flap_minus_spin_squared(spin):
    beam = fx.beam_matrices(8, 14000.0, 1.2, 10.0, r=1.5)
    out = fx.natural_frequencies(beam, spin=spin, plane="out")
    inn = fx.natural_frequencies(beam, spin=spin, plane="in")
    tol = 2 * 64 * EPS * out[-1] ** 2  # eigh: absolute error ~ p(n) eps lambda_max on omega^2
    np.testing.assert_allclose(np.sign(inn) * inn**2, out**2 - spin**2, rtol=0, atol=tol)


def test_classical_model_loses_stiffness_above_first_frequency():
    beam = fx.beam_matrices(6, **KRB)
    w1 = beam.omega0[0]
    assert fx.natural_frequencies(beam, spin=0.9 * w1, plane="in", stiffening=False)[0] > 0
    assert fx.natural_frequencies(beam, spin=1.1 * w1, plane="in", stiffening=False)[0] < 0
    assert fx.natural_frequencies(beam, spin=3.0 * w1, plane="in", stiffening=True)[0] > 0


# --------------------------------------------------------------------------- 3. Kane-Ryan-Banerjee spin-up


def test_krb_spinup_profile():
    t = np.linspace(0, 20, 2001)
    th, thd, thdd = fx.krb_spinup(t)
    assert thd[-1] == 6.0 and np.all(thdd[t >= 15] == 0.0)
    assert thd[0] == 0.0 and thdd[0] == 0.0
    # theta' = int theta'', theta = int theta' (trapezoid: h^2 error)
    h = t[1] - t[0]
    np.testing.assert_allclose(thd[1:], np.cumsum(0.5 * h * (thdd[1:] + thdd[:-1])), atol=1e-4)
    np.testing.assert_allclose(th[1:], np.cumsum(0.5 * h * (thd[1:] + thd[:-1])), atol=1e-3)


def test_krb_spinup_stiffened_bounded_and_quasi_static():
    """Stiffened: the tip follows the quasi-static deflection under the spin-up's inertial
    load (the load varies at 2 pi / 15 = 0.42 rad/s against a first frequency >= 3.8 rad/s,
    so the dynamic correction is ~(0.42/3.8)^2 = 1.2%, and the smooth start excites a
    residual oscillation of the same order): within 5% of the peak; the peak is ~0.57 m,
    lagging (negative), and after the spin-up the tip returns to near zero."""
    EI, rho, L = KRB.values()
    beam = fx.beam_matrices(4, EI, rho, L)
    t = np.linspace(0.0, 20.0, 81)
    y, _ = fx.propagate_planar_prescribed(beam, fx.krb_spinup, np.zeros(8), t, stiffening=True)
    tip = fx.tip_deflection(beam, y[:, :4])
    _, thd, thdd = fx.krb_spinup(t)
    qs = np.array([_quasi_static_tip(EI, rho, L, s, a) for s, a in zip(thd, thdd, strict=True)])
    peak = np.abs(qs).max()
    assert 0.3 < peak < 1.0 and qs.min() == -peak  # lags the rotation
    assert np.abs(tip - qs).max() < 0.05 * peak
    assert np.abs(tip[t >= 15.0]).max() < 0.05 * peak  # back near zero at constant spin


def test_krb_spinup_classical_diverges():
    """Conventional linear model (no stiffening): K - Omega^2 M is indefinite once the spin
    passes the first frequency (3.80 rad/s), so the tip diverges (KRB 1987)."""
    EI, rho, L = KRB.values()
    beam = fx.beam_matrices(4, EI, rho, L)
    t = np.linspace(0.0, 15.0, 61)
    y, _ = fx.propagate_planar_prescribed(beam, fx.krb_spinup, np.zeros(8), t, stiffening=False)
    tip = np.abs(fx.tip_deflection(beam, y[:, :4]))
    w1 = (float(_beta_L()[0]) ** 2) * math.sqrt(EI / (rho * L**4))
    t_crit = brentq(lambda s: fx.krb_spinup(s)[1] - w1, 0.0, 15.0)
    assert tip[-1] > 1.0 and tip.max() > 1.0
    assert tip[-1] > 100.0 * tip[np.searchsorted(t, t_crit + 1.0)]  # exponential growth


# --------------------------------------------------------------------------- 4. planar free hub


def _planar_run(zeta, stiffening, t, torque=None, rtol=1e-10, atol=1e-12):
    """The free hub (500 kg m^2, a 3-mode beam with damping ratio ``zeta``) propagated over
    ``t`` s by DOP853 at ``rtol``, ``atol``: ``(beam, y, info, E, H, bounds)`` with the
    energy E (J) and angular momentum H (kg m^2/s) along the states y, and
    ``bounds(states, tau=0)`` -> DOP853's drift bounds on ``(E - tau theta, H)`` from ``states``."""
    beam = fx.beam_matrices(3, 14000.0, 1.2, 10.0, r=1.0, damping_ratio=zeta)
    J, y0 = 500.0, np.array([0.1, 2.0, 0.05, 0.0, -0.01, 0.0, 0.3, 0.0])
    y, info = fx.propagate_planar_free(beam, J, y0, t, torque=torque, stiffening=stiffening, rtol=rtol, atol=atol)

    def energy(s):
        return fx.planar_energy(beam, J, s, stiffening)

    def momentum(s):
        return fx.planar_angular_momentum(beam, J, s, stiffening)

    def bounds(states, tau=0.0):
        return (dop853_drift_bound(lambda s: energy(s) - tau * s[0], states, info["nfev"], rtol, atol),
                dop853_drift_bound(momentum, states, info["nfev"], rtol, atol))

    return beam, y, info, energy(y), momentum(y), bounds


@pytest.mark.parametrize("stiffening", [True, False])
def test_planar_free_conserves_energy_and_momentum(stiffening):
    t = np.linspace(0.0, 8.0, 81)
    _, y, info, E, H, bounds = _planar_run(0.0, stiffening, t)
    bE, bH = bounds(y)
    assert np.abs(E - E[0]).max() <= bE
    assert np.abs(H - H[0]).max() <= bH
    assert info["energy_drift"] * abs(E[0]) <= bE and info["momentum_drift"] * abs(H[0]) <= bH
    assert np.abs(y[:, 2:5]).max() > 0.01  # it did vibrate
    # sharper: the drift is integration error, so it falls with the tolerance (DOP853's
    # error per unit time ~ tol^(8/9): 1000x tighter -> ~460x smaller); a modelling
    # inconsistency between the rates and E or H would not.  Ask for 30x.
    _, _, _, E7, H7, _ = _planar_run(0.0, stiffening, t, rtol=1e-7, atol=1e-9)
    assert np.abs(E - E[0]).max() < np.abs(E7 - E7[0]).max() / 30
    assert np.abs(H - H[0]).max() < np.abs(H7 - H7[0]).max() / 30


def test_planar_free_damped_dissipation():
    """zeta > 0: E decreases at dE/dt = -q'.C q' (Simpson over the samples), momentum kept."""
    t = np.linspace(0.0, 4.0, 4001)
    beam, y, info, E, H, bounds = _planar_run(0.02, True, t)
    bE, bH = bounds(y[::50])
    assert np.abs(H - H[0]).max() <= bH
    qd = y[:, 5:]
    p = np.einsum("ki,ij,kj->k", qd, beam.C, qd)
    assert np.all(np.diff(E) <= bE)  # monotone (to the integration's error)
    h = t[1] - t[0]
    dissipated = h / 3 * (p[0] + p[-1] + 4 * p[1:-1:2].sum() + 2 * p[2:-1:2].sum())
    # Simpson: h^4 max|p''''|/180 with p oscillating at 2 omega_3 <= 2 * 130 rad/s: (0.26)^4/180 ~ 3e-5
    assert E[0] - E[-1] == pytest.approx(dissipated, rel=1e-4)
    assert E[0] - E[-1] > 1e-3 * E[0]


def test_planar_linearised_in_plane_frequencies():
    """A huge hub spinning steadily: the linearised beam frequencies are the in-plane
    (lead-lag) frequencies K + Omega^2 (S - M) of natural_frequencies (finite hub: 1e-9)."""
    n, Om = 4, 2.5
    beam = fx.beam_matrices(n, 14000.0, 1.2, 10.0, r=1.0)
    y = np.zeros(2 + 2 * n)
    y[1] = Om
    J = 1e12  # against the beam's b^2 / M ~ 1e3 kg m^2: 1e-9
    idx = np.r_[1, 2 : 2 + 2 * n]
    A = np.empty((idx.size, idx.size))
    for k, i in enumerate(idx):
        h = 1e-6
        yp, ym = y.copy(), y.copy()
        yp[i] += h
        ym[i] -= h
        A[:, k] = (fx.planar_free_rates(beam, J, yp)[idx] - fx.planar_free_rates(beam, J, ym)[idx]) / (2 * h)
    im = np.sort(np.abs(np.linalg.eigvals(A).imag))[1::2]
    np.testing.assert_allclose(im, fx.natural_frequencies(beam, Om, "in"), rtol=1e-6)


# --------------------------------------------------------------------------- 3D spacecraft: kinematics and T


def _direct_invariants(sc, y):
    """E = T + V, P (inertial) and H (about the inertial origin) by Gauss quadrature over the
    beams of the exact velocity v + w x p + dp/dt of p = a + (x + u) e + f w_f + g w_g,
    u = -1/2 int (w_f'^2 + w_g'^2) (nested quadrature); monomial basis phi_a = (x/L)^a."""
    w, v = y[4:7], y[10:13]
    ne = sc.n_elastic
    eta_all, etad_all = y[13 : 13 + ne], y[13 + ne :]
    T = 0.5 * sc.hub_mass * v @ v + 0.5 * w @ sc.hub_inertia @ w
    P, H, Vs = sc.hub_mass * v, sc.hub_inertia @ w, 0.0
    tips = []
    k0 = 0
    for app in sc.appendages:
        bm = app.beam
        n, L, rho, EI = bm.n_modes, bm.L, bm.rho, bm.EI
        e, f, a = app.axis, app.normal, app.root
        g = np.cross(e, f)
        ef, eg = eta_all[k0 : k0 + n], eta_all[k0 + n : k0 + 2 * n]
        edf, edg = etad_all[k0 : k0 + n], etad_all[k0 + n : k0 + 2 * n]
        k0 += 2 * n
        pw = np.arange(n) + 2.0

        def phi(x, pw=pw, L=L):
            return (x[..., None] / L) ** pw

        def dphi(x, pw=pw, L=L):
            return pw * (x[..., None] / L) ** (pw - 1) / L

        def ddphi(x, pw=pw, L=L):
            return pw * (pw - 1) * (x[..., None] / L) ** (pw - 2) / L**2

        tg, wg = np.polynomial.legendre.leggauss(n + 6)
        x, wx = 0.5 * L * (tg + 1), 0.5 * L * wg
        ti, wi = np.polynomial.legendre.leggauss(n + 2)  # exact for w'^2 (degree 2n)
        xi, wxi = 0.5 * x[:, None] * (ti + 1), 0.5 * x[:, None] * wi
        D = dphi(xi)
        u = -0.5 * np.sum(wxi * ((D @ ef) ** 2 + (D @ eg) ** 2), axis=1)
        ud = -np.sum(wxi * ((D @ ef) * (D @ edf) + (D @ eg) * (D @ edg)), axis=1)
        Ph = phi(x)
        p = a + (x + u)[:, None] * e + (Ph @ ef)[:, None] * f + (Ph @ eg)[:, None] * g
        pd = ud[:, None] * e + (Ph @ edf)[:, None] * f + (Ph @ edg)[:, None] * g
        V = v + np.cross(w, p) + pd
        T += 0.5 * rho * np.sum(wx * np.sum(V * V, axis=1))
        P = P + rho * (wx @ V)
        H = H + rho * (wx @ np.cross(p, V))
        D2 = ddphi(x)
        Vs += 0.5 * EI * np.sum(wx * ((D2 @ ef) ** 2 + (D2 @ eg) ** 2))
        DL = dphi(0.5 * L * (ti + 1))
        uL = -0.25 * L * np.sum(wi * ((DL @ ef) ** 2 + (DL @ eg) ** 2))
        tips.append(f * ef.sum() + g * eg.sum() + uL * e)
    e0, e1, e2, e3 = y[:4] / np.linalg.norm(y[:4])
    # v_body = C v_inertial (Euler parameters, scalar first), C^T here
    Ct = np.array([
        [1 - 2 * (e2 * e2 + e3 * e3), 2 * (e1 * e2 - e0 * e3), 2 * (e1 * e3 + e0 * e2)],
        [2 * (e1 * e2 + e0 * e3), 1 - 2 * (e1 * e1 + e3 * e3), 2 * (e2 * e3 - e0 * e1)],
        [2 * (e1 * e3 - e0 * e2), 2 * (e2 * e3 + e0 * e1), 1 - 2 * (e1 * e1 + e2 * e2)],
    ])  # fmt: skip
    Pi = Ct @ P
    return T + Vs, Pi, np.cross(y[7:10], Pi) + Ct @ H, np.array(tips)


def _general_spacecraft(stiffening=True):
    b1 = fx.beam_matrices(3, 900.0, 1.3, 4.0, r=0.7, basis="monomial")
    b2 = fx.beam_matrices(2, 500.0, 0.9, 3.0, r=0.5, basis="monomial")
    e1 = _unit([1, 0.3, -0.2])
    e2 = _unit([-0.4, 1, 0.5])
    apps = (fx.Appendage(b1, e1, _unit(np.cross(e1, [0.2, 0.1, 1.0])), root=[0.6, 0.2, -0.3]),
            fx.Appendage(b2, e2, _unit(np.cross(e2, [1.0, -0.3, 0.2]))))  # fmt: skip
    J = np.array([[50.0, 3.0, -2.0], [3.0, 70.0, 1.0], [-2.0, 1.0, 90.0]])
    return fx.FlexibleSpacecraft(80.0, J, apps, stiffening=stiffening)


def test_energy_and_momenta_match_direct_quadrature_to_second_order():
    """The module keeps T to second order in the elastic coordinates: E_module - E_direct
    and H_module - H_direct are O(eps^3) (halving eps divides them by 8: a wrong
    second-order term would divide by 4); P is exact (linear in p); tips exact."""
    sc = _general_spacecraft()
    rng = np.random.default_rng(7)
    eta, etad = rng.standard_normal(sc.n_elastic), rng.standard_normal(sc.n_elastic)
    kw = {"q": _unit([0.8, 0.3, -0.4, 0.2]), "w": [0.4, -0.7, 0.5], "r": [3.0, -1.0, 2.0], "v": [0.3, 0.2, -0.5]}
    diffs = []
    for eps in (2e-2, 1e-2, 5e-3):
        y = fx.make_state(sc, eta=eps * eta, eta_dot=eps * etad, **kw)
        E, (P, H) = fx.spacecraft_energy(sc, y), fx.spacecraft_momentum(sc, y)
        Ed, Pd, Hd, tips = _direct_invariants(sc, y)
        assert np.abs(P - Pd).max() < 1e-12 * np.abs(Pd).max()
        np.testing.assert_allclose(fx.tip_deflections(sc, y), tips, rtol=0, atol=1e-15)
        diffs.append((abs(E - Ed), np.linalg.norm(H - Hd), abs(Ed), np.linalg.norm(Hd)))
    for (dE1, dH1, _, _), (dE2, dH2, _, _) in zip(diffs[:-1], diffs[1:], strict=True):
        assert 7.0 < dE1 / dE2 < 9.0 and 7.0 < dH1 / dH2 < 9.0
    assert diffs[0][0] < 1e-4 * diffs[0][2] and diffs[0][1] < 1e-4 * diffs[0][3]


def test_make_state_zero_linear_momentum():
    sc = _general_spacecraft()
    y = fx.make_state(sc, w=[0.1, 0.2, -0.3], eta=0.01 * np.ones(sc.n_elastic), eta_dot=0.02 * np.ones(sc.n_elastic))
    P, _ = fx.spacecraft_momentum(sc, y)
    assert np.abs(P).max() < 1e-13
    assert np.abs(_direct_invariants(sc, y)[1]).max() < 1e-13


# --------------------------------------------------------------------------- 3D: linearised frequencies


def _linearised_frequencies(sc, y, h=1e-6):
    ne = sc.n_elastic
    idx = np.r_[4:7, 10:13, 13 : 13 + 2 * ne]  # (w, v, eta, eta') do not depend on q, r
    A = np.empty((idx.size, idx.size))
    for k, i in enumerate(idx):
        yp, ym = y.copy(), y.copy()
        yp[i] += h
        ym[i] -= h
        A[:, k] = (fx.spacecraft_rates(sc, 0.0, yp)[idx] - fx.spacecraft_rates(sc, 0.0, ym)[idx]) / (2 * h)
    lam = np.linalg.eigvals(A)
    assert np.abs(lam.real).max() < 1e-6 * np.abs(lam).max()  # undamped, stable: centre
    return np.abs(lam.imag)


# finite hub (1e9 kg, kg m^2 against ~1 kg beams): 1e-9; central differences h = 1e-6 on
# rates with entries up to omega_max^2 ~ 2e4: eps omega_max^2 / h ~ 4e-6 absolute, ~1e-7
# relative on the frequencies; tolerance 1e-6
_LIN_RTOL = 1e-6
_BIG = 1e9


@pytest.mark.parametrize("r", [0.0, 0.5])
def test_3d_linearised_spin_normal_to_beam(r):
    """Beam along x on a huge hub spinning about z: in-plane (f = y) lead-lag and
    out-of-plane (g = z) flapping frequencies of natural_frequencies."""
    n, lam = 4, 3.0
    beam = fx.beam_matrices(n, 1.0, 1.0, 1.0, r=r)
    sc = fx.FlexibleSpacecraft(_BIG, [_BIG, 1.1 * _BIG, 1.2 * _BIG], (fx.Appendage(beam, [1, 0, 0], [0, 1, 0]),))
    im = _linearised_frequencies(sc, fx.make_state(sc, w=[0, 0, lam]))
    # natural_frequencies is checked against shooting and the literature above
    for ref in np.r_[fx.natural_frequencies(beam, lam, "out"), fx.natural_frequencies(beam, lam, "in")]:
        assert np.min(np.abs(im / ref - 1)) < _LIN_RTOL


def test_3d_linearised_spin_about_beam_axis():
    """A beam spinning about its own axis (no rotary inertia): bending at omega_k in inertial
    space is seen at omega_k +- Omega in the body frame (Coriolis 2 Omega, softening Omega^2)."""
    n, Om = 4, 3.0
    beam = fx.beam_matrices(n, 1.0, 1.0, 1.0, r=0.5)
    sc = fx.FlexibleSpacecraft(_BIG, [_BIG, 1.1 * _BIG, 1.2 * _BIG], (fx.Appendage(beam, [0, 0, 1], [1, 0, 0]),))
    im = _linearised_frequencies(sc, fx.make_state(sc, w=[0, 0, Om]))
    for ref in np.r_[beam.omega0 + Om, np.abs(beam.omega0 - Om)]:
        assert np.min(np.abs(im / ref - 1)) < _LIN_RTOL


# --------------------------------------------------------------------------- 3D vs planar


@pytest.mark.parametrize("stiffening", [True, False])
def test_symmetric_pair_matches_planar_model(stiffening):
    """Two beams along +-x bending in the plane of the hub's spin, antisymmetrically (each
    deflected along the direction of rotation): the mass centre stays at O and the 3D
    equations reduce to the planar ones with half the hub's J_z per beam."""
    n = 3
    beam = fx.beam_matrices(n, 14000.0, 1.2, 10.0, r=1.0)
    Jz = 800.0
    apps = (fx.Appendage(beam, [1, 0, 0], [0, 1, 0]), fx.Appendage(beam, [-1, 0, 0], [0, -1, 0]))
    sc = fx.FlexibleSpacecraft(300.0, [500.0, 600.0, Jz], apps, stiffening=stiffening)
    lay = fx.state_layout(sc)
    rng = np.random.default_rng(11)
    for _ in range(3):
        q, qd, th, thd = 0.3 * rng.standard_normal(n), rng.standard_normal(n), rng.uniform(0, 6), rng.uniform(-3, 3)
        eta = np.concatenate([q, np.zeros(n), q, np.zeros(n)])
        etad = np.concatenate([qd, np.zeros(n), qd, np.zeros(n)])
        y3 = fx.make_state(sc, q=[math.cos(th / 2), 0, 0, math.sin(th / 2)], w=[0, 0, thd], eta=eta, eta_dot=etad)
        assert np.abs(y3[lay["v"]]).max() < 1e-14
        yp = np.concatenate([[th, thd], q, qd])
        d3 = fx.spacecraft_rates(sc, 0.0, y3)
        dp = fx.planar_free_rates(beam, Jz / 2, yp, stiffening=stiffening)
        scale = np.abs(dp).max()
        assert abs(d3[6] - dp[1]) < 1e-12 * scale  # theta''
        np.testing.assert_allclose(d3[lay["eta_dot"]][:n], dp[2 + n :], rtol=0, atol=1e-12 * scale)
        np.testing.assert_allclose(d3[lay["eta_dot"]][2 * n : 3 * n], dp[2 + n :], rtol=0, atol=1e-12 * scale)
        assert np.abs(d3[lay["eta_dot"]][n : 2 * n]).max() < 1e-12 * scale  # no flapping excited
        assert np.abs(d3[np.r_[4, 5, 10, 11, 12]]).max() < 1e-12 * scale
        Ep = fx.planar_energy(beam, Jz / 2, yp, stiffening)
        assert fx.spacecraft_energy(sc, y3) == pytest.approx(2 * Ep, rel=1e-13)
        Hz = fx.spacecraft_momentum(sc, y3)[1][2]
        assert Hz == pytest.approx(2 * fx.planar_angular_momentum(beam, Jz / 2, yp, stiffening), rel=1e-13)


# --------------------------------------------------------------------------- 4. 3D conservation


def _tumbling_spacecraft(zeta):
    b1 = fx.beam_matrices(2, 40.0, 0.8, 3.0, r=0.6, damping_ratio=zeta)
    b2 = fx.beam_matrices(2, 20.0, 0.5, 2.0, r=0.5, damping_ratio=zeta)
    e2 = _unit([0.3, -1, 0.4])
    # the second root off its axis line (a x e != 0: the root's transport terms)
    apps = (fx.Appendage(b1, [1, 0, 0], [0, 1, 0]),
            fx.Appendage(b2, e2, _unit(np.cross(e2, [0, 0, 1.0])), root=[0.3, -0.4, 0.5]))  # fmt: skip
    sc = fx.FlexibleSpacecraft(40.0, [20.0, 25.0, 30.0], apps)
    rng = np.random.default_rng(3)
    y0 = fx.make_state(sc, q=_unit([1, 0.2, -0.1, 0.3]), w=[0.3, -0.4, 0.6], r=[0.5, -0.2, 0.1], v=[0.2, -0.1, 0.3],
                       eta=0.05 * rng.standard_normal(8), eta_dot=0.1 * rng.standard_normal(8))  # fmt: skip
    return sc, y0


def _mass_centre(sc, y):
    """Inertial position of the mass centre: r_O + C^T s / m, s = sum (m_b a + rho L^2/2 e
    + f beta.eta_f + g beta.eta_g - 1/2 eta.Sa eta e) (stiffened), C^T from the Euler parameters."""
    s = np.zeros(3)
    k0 = 13
    for app in sc.appendages:
        bm, e, f = app.beam, app.axis, app.normal
        n = bm.n_modes
        ef, eg = y[k0 : k0 + n], y[k0 + n : k0 + 2 * n]
        k0 += 2 * n
        U0 = -0.5 * (ef @ bm.Sa @ ef + eg @ bm.Sa @ eg)
        s += (
            bm.mass * app.root
            + bm.rho * bm.L**2 / 2 * e
            + f * (bm.beta @ ef)
            + np.cross(e, f) * (bm.beta @ eg)
            + U0 * e
        )
    e0, e1, e2, e3 = y[:4] / np.linalg.norm(y[:4])
    s_inertial = np.array([
        (1 - 2 * (e2 * e2 + e3 * e3)) * s[0] + 2 * (e1 * e2 - e0 * e3) * s[1] + 2 * (e1 * e3 + e0 * e2) * s[2],
        2 * (e1 * e2 + e0 * e3) * s[0] + (1 - 2 * (e1 * e1 + e3 * e3)) * s[1] + 2 * (e2 * e3 - e0 * e1) * s[2],
        2 * (e1 * e3 - e0 * e2) * s[0] + 2 * (e2 * e3 + e0 * e1) * s[1] + (1 - 2 * (e1 * e1 + e2 * e2)) * s[2],
    ])  # fmt: skip
    return y[7:10] + s_inertial / sc.mass


@pytest.mark.parametrize("zeta", [0.0, 0.05])
def test_3d_conservation(zeta):
    """Undamped: E, P, H conserved within the integrator-error bound.  Damped: E decreasing
    monotonically (to that bound), P and H still conserved.  Either way the mass centre
    moves uniformly: r_cm(t) = r_cm(0) + P t / m."""
    sc, y0 = _tumbling_spacecraft(zeta)
    t = np.linspace(0.0, 3.0, 31)
    rtol, atol = 1e-9, 1e-12
    y, info = fx.propagate_spacecraft(sc, y0, t, rtol=rtol, atol=atol)
    E = fx.spacecraft_energy(sc, y)
    P, H = fx.spacecraft_momentum(sc, y)

    def mom(s):
        p, h = fx.spacecraft_momentum(sc, s)
        return np.concatenate([p, h])

    bE = dop853_drift_bound(lambda s: fx.spacecraft_energy(sc, s), y, info["nfev"], rtol, atol)
    bM = dop853_drift_bound(mom, y, info["nfev"], rtol, atol)
    assert np.linalg.norm(np.hstack([P - P[0], H - H[0]]), axis=1).max() <= bM
    assert np.linalg.norm(P[0]) > 0.1  # moving
    m, T_end = sc.mass, t[-1]
    cm = np.array([_mass_centre(sc, s) for s in y])
    bC = dop853_drift_bound(
        lambda s: _mass_centre(sc, s) - fx.spacecraft_momentum(sc, s)[0] * T_end / m, y, info["nfev"], rtol, atol
    )
    assert np.linalg.norm(cm - cm[0] - np.outer(t, P[0] / m), axis=1).max() <= bC
    if zeta == 0.0:
        assert np.abs(E - E[0]).max() <= bE
        # and it falls with the tolerance (see the planar test): integration error, not model
        y6, _ = fx.propagate_spacecraft(sc, y0, t, rtol=1e-6, atol=1e-9)
        E6 = fx.spacecraft_energy(sc, y6)
        H6 = fx.spacecraft_momentum(sc, y6)[1]
        assert np.abs(E - E[0]).max() < np.abs(E6 - E6[0]).max() / 30
        assert np.abs(H - H[0]).max() < np.abs(H6 - H6[0]).max() / 30
    else:
        assert np.all(np.diff(E) <= bE)
        assert E[-1] < 0.99 * E[0]  # and it does dissipate
    assert np.abs(np.linalg.norm(y[:, :4], axis=1) - 1).max() < 1e-14
    assert np.abs(y[:, 13:]).max() > 0.01  # it did vibrate


def test_planar_hub_torque():
    """Constant hub torque: H(t) = H(0) + tau t exactly, E(t) = E(0) + tau (theta(t) - theta(0))."""
    tau = 150.0
    t = np.linspace(0.0, 4.0, 41)
    _, y, _, E, H, bounds = _planar_run(0.0, True, t, torque=lambda time, s: tau)
    bE, bH = bounds(y, tau)
    assert np.abs(H - H[0] - tau * t).max() <= bH
    assert np.abs(E - E[0] - tau * (y[:, 0] - y[0, 0])).max() <= bE
    assert H[-1] - H[0] == pytest.approx(tau * t[-1], rel=1e-6)


def test_3d_hub_torque():
    """A torque fixed in inertial space (body components C tau_in) on the hub: the angular
    momentum about the inertial origin grows as H(0) + tau_in t (the torque is a couple),
    P stays constant."""
    sc, y0 = _tumbling_spacecraft(0.0)
    tau_in = np.array([0.4, -0.3, 0.5])

    def torque(time, s):
        e0, e1, e2, e3 = s[:4] / np.linalg.norm(s[:4])
        C = np.array([
            [1 - 2 * (e2 * e2 + e3 * e3), 2 * (e1 * e2 + e0 * e3), 2 * (e1 * e3 - e0 * e2)],
            [2 * (e1 * e2 - e0 * e3), 1 - 2 * (e1 * e1 + e3 * e3), 2 * (e2 * e3 + e0 * e1)],
            [2 * (e1 * e3 + e0 * e2), 2 * (e2 * e3 - e0 * e1), 1 - 2 * (e1 * e1 + e2 * e2)],
        ])  # fmt: skip
        return C @ tau_in

    rtol, atol = 1e-9, 1e-12
    t = np.linspace(0.0, 2.0, 11)
    y, info = fx.propagate_spacecraft(sc, y0, t, torque=torque, rtol=rtol, atol=atol)
    P, H = fx.spacecraft_momentum(sc, y)

    def mom(s):
        p, h = fx.spacecraft_momentum(sc, s)
        return np.concatenate([p, h])

    bM = dop853_drift_bound(mom, y, info["nfev"], rtol, atol)
    assert np.linalg.norm(np.hstack([P - P[0], H - H[0] - np.outer(t, tau_in)]), axis=1).max() <= bM
    assert "energy_drift" not in info


# --------------------------------------------------------------------------- 5. rigid limit


def test_rigid_limit_matches_torque_free():
    """Stiff beams (omega_1 >> |w|), starting undeformed and at rest relative to the hub:
    the hub follows the rigid composite body's exact torque-free motion, the deviation
    vanishing with the beams' compliance: the quasi-static deflection and the attitude
    error scale as 1/EI, and the rate error (through the relative angular momentum of the
    residual vibration, eta' ~ omega eta) as 1/sqrt(EI).  Composite inertia by hand: two
    thin rods along +-x from r to r + L.  The errors are RMS over 801 samples (the max of a
    sampled vibration depends on where the samples fall); the scaling laws are the leading
    terms of an expansion in |w| / omega_1 (2.3 % at the softer beam), so the ratios of
    the two runs must be 4 and 2 to within that: 3 %."""
    rho, L, r = 0.5, 4.0, 0.5
    Jh = np.array([30.0, 45.0, 60.0])
    Irod = rho * ((r + L) ** 3 - r**3) / 3.0
    inertia = Jh + np.array([0.0, 2 * Irod, 2 * Irod])
    w0, q0 = np.array([0.25, 0.1, 0.3]), _unit([0.9, 0.1, -0.3, 0.2])
    t = np.linspace(0.0, 10.0, 801)
    w_ref, q_ref = torque_free(inertia, w0, q0, t)
    errs = []
    for EI in (2e3, 8e3):
        beam = fx.beam_matrices(1, EI, rho, L, r=r)
        sc = fx.FlexibleSpacecraft(50.0, Jh, (fx.Appendage(beam, [1, 0, 0], [0, 1, 0]),
                                              fx.Appendage(beam, [-1, 0, 0], [0, 1, 0])))  # fmt: skip
        y, _ = fx.propagate_spacecraft(sc, fx.make_state(sc, q=q0, w=w0), t, rtol=1e-10, atol=1e-12)
        angle = 2 * np.arccos(np.clip(np.abs(np.sum(y[:, :4] * q_ref, axis=1)), 0, 1))
        dw = np.linalg.norm(y[:, 4:7] - w_ref, axis=1)
        ratio = (np.linalg.norm(w0) / beam.omega0[0]) ** 2  # (|w| / omega_1)^2: 5e-4 and 1.3e-4
        assert angle.max() < ratio and dw.max() < np.linalg.norm(w0) * math.sqrt(ratio)
        assert np.abs(y[:, 7:10]).max() < 1e-12  # mass centre (= O by symmetry) at rest
        errs.append((np.sqrt(np.mean(angle**2)), np.sqrt(np.mean(dw**2))))
    assert errs[0][0] / errs[1][0] == pytest.approx(4.0, rel=0.03)  # 1/EI
    assert errs[0][1] / errs[1][1] == pytest.approx(2.0, rel=0.03)  # 1/sqrt(EI)


# --------------------------------------------------------------------------- 6. hostile input


def _sc1():
    beam = fx.beam_matrices(2, 100.0, 1.0, 2.0)
    return fx.FlexibleSpacecraft(10.0, [1.0, 2.0, 3.0], (fx.Appendage(beam, [1, 0, 0], [0, 1, 0]),))


_BEAM = dict(n_modes=2, EI=100.0, rho=1.0, L=2.0)
_HOSTILE = [
    *[("n_modes", lambda v=v: fx.beam_matrices(**{**_BEAM, "n_modes": v}))
      for v in (0, -1, 25, 10**9, 1e300, 2.5, float("nan"), float("inf"), None, "3")],
    ("n_modes", lambda: fx.beam_matrices(**{**_BEAM, "n_modes": 9}, basis="monomial")),
    *[(k, lambda k=k, v=v: fx.beam_matrices(**{**_BEAM, k: v}))
      for k in ("EI", "rho", "L") for v in (-1.0, 0.0, float("nan"), float("inf"), -float("inf"), None, "abc")],
    *[("r", lambda v=v: fx.beam_matrices(**_BEAM, r=v)) for v in (-0.1, float("nan"), float("inf"), "x")],
    *[("damping_ratio", lambda v=v: fx.beam_matrices(**_BEAM, damping_ratio=v)) for v in (-0.1, float("nan"))],
    ("basis", lambda: fx.beam_matrices(**_BEAM, basis="chebyshev")),
    ("spin", lambda: fx.natural_frequencies(fx.beam_matrices(**_BEAM), spin=float("nan"))),
    ("plane", lambda: fx.natural_frequencies(fx.beam_matrices(**_BEAM), plane="sideways")),
    ("T", lambda: fx.krb_spinup(1.0, T=0.0)),
    ("omega_s", lambda: fx.krb_spinup(1.0, omega_s=float("inf"))),
    ("state0", lambda: fx.propagate_planar_prescribed(fx.beam_matrices(**_BEAM), fx.krb_spinup, np.zeros(3), [0, 1])),
    ("state0", lambda: fx.propagate_planar_prescribed(fx.beam_matrices(**_BEAM), fx.krb_spinup, [np.nan, 0, 0, 0], [0, 1])),
    ("state0", lambda: fx.propagate_planar_free(fx.beam_matrices(**_BEAM), 1.0, np.zeros(5), [0, 1])),
    ("state0", lambda: fx.propagate_planar_free(fx.beam_matrices(**_BEAM), 1.0, [0, np.inf, 0, 0, 0, 0], [0, 1])),
    ("state", lambda: fx.planar_free_rates(fx.beam_matrices(**_BEAM), 1.0, np.zeros(7))),
    ("state", lambda: fx.planar_prescribed_rates(fx.beam_matrices(**_BEAM), 0.0, np.zeros(5), fx.krb_spinup)),
    ("hub_inertia", lambda: fx.propagate_planar_free(fx.beam_matrices(**_BEAM), -1.0, np.zeros(6), [0, 1])),
    ("hub_inertia", lambda: fx.propagate_planar_free(fx.beam_matrices(**_BEAM), float("nan"), np.zeros(6), [0, 1])),
    ("t", lambda: fx.propagate_planar_free(fx.beam_matrices(**_BEAM), 1.0, np.zeros(6), [0, np.nan])),
    ("t", lambda: fx.propagate_planar_free(fx.beam_matrices(**_BEAM), 1.0, np.zeros(6), [1.0, 2.0])),
    ("t", lambda: fx.propagate_spacecraft(_sc1(), fx.make_state(_sc1()), [0.0, 2.0, 1.0])),
    ("hub_mass", lambda: fx.FlexibleSpacecraft(-1.0, [1, 2, 3], ())),
    ("hub_mass", lambda: fx.FlexibleSpacecraft(float("nan"), [1, 2, 3], ())),
    ("hub_inertia", lambda: fx.FlexibleSpacecraft(1.0, [1, -2, 3], ())),
    ("hub_inertia", lambda: fx.FlexibleSpacecraft(1.0, [1, np.inf, 3], ())),
    ("hub_inertia", lambda: fx.FlexibleSpacecraft(1.0, [[1, 2, 0], [0, 1, 0], [0, 0, 1]], ())),
    ("appendages", lambda: fx.FlexibleSpacecraft(1.0, [1, 2, 3], ("boom",))),
    ("beam", lambda: fx.Appendage("beam", [1, 0, 0], [0, 1, 0])),
    ("axis", lambda: fx.Appendage(fx.beam_matrices(**_BEAM), [0, 0, 0], [0, 1, 0])),
    ("axis", lambda: fx.Appendage(fx.beam_matrices(**_BEAM), [np.nan, 0, 0], [0, 1, 0])),
    ("normal", lambda: fx.Appendage(fx.beam_matrices(**_BEAM), [1, 0, 0], [1, 1, 0])),
    ("axis", lambda: fx.Appendage(fx.beam_matrices(**_BEAM), [1, 0], [0, 1, 0])),
    ("normal", lambda: fx.Appendage(fx.beam_matrices(**_BEAM), [1, 0, 0], "y")),
    ("root", lambda: fx.Appendage(fx.beam_matrices(**_BEAM), [1, 0, 0], [0, 1, 0], root=[0, 0, 0, 0])),
    ("hub_inertia", lambda: fx.FlexibleSpacecraft(1.0, ["a", "b", "c"], ())),
    ("root", lambda: fx.Appendage(fx.beam_matrices(**_BEAM), [1, 0, 0], [0, 1, 0], root=[0, np.inf, 0])),
    ("state0", lambda: fx.propagate_spacecraft(_sc1(), np.zeros(5), [0, 1])),
    ("state0", lambda: fx.propagate_spacecraft(_sc1(), np.full(17, np.nan), [0, 1])),
    ("state", lambda: fx.spacecraft_rates(_sc1(), 0.0, np.zeros(16))),
    ("state", lambda: fx.spacecraft_energy(_sc1(), np.zeros((3, 18)))),
    ("state", lambda: fx.spacecraft_momentum(_sc1(), np.zeros(5))),
    ("state", lambda: fx.tip_deflections(_sc1(), 1.0)),
    ("eta", lambda: fx.make_state(_sc1(), eta=np.zeros(3))),
    ("eta_dot", lambda: fx.make_state(_sc1(), eta_dot=[np.nan, 0, 0, 0])),
    ("q", lambda: fx.make_state(_sc1(), q=[0, 0, 0, 0])),
    ("q", lambda: fx.make_state(_sc1(), q=[1, 0, 0])),
    ("w", lambda: fx.make_state(_sc1(), w=[0, np.inf, 0])),
    ("v", lambda: fx.make_state(_sc1(), v=[0, 0])),
]  # fmt: skip


@pytest.mark.parametrize(("field", "call"), _HOSTILE, ids=[f"{f}-{i}" for i, (f, _) in enumerate(_HOSTILE)])
def test_hostile_input_names_the_field(field, call):
    # a value that is not real numbers names the function first (astrodyn.inputs: "beam_matrices: EI: ...")
    assert_refused_quickly(call, rf"^(\w+: )?{field}\b")


def test_monomial_basis_limit_is_where_conditioning_fails():
    """The monomial cap (n <= 8) is the conditioning limit: at 8 every frequency is within
    eps cond(M) of the exact Ritz value; the Gram matrix's condition grows ~ e^(3.5 n)."""
    beam = fx.beam_matrices(8, 1.0, 1.0, 1.0, basis="monomial")
    ritz = np.array([float(x) for x in _exact_ritz(8)])
    np.testing.assert_array_less(np.abs(beam.omega0 / ritz - 1), EPS * np.linalg.cond(beam.M))
    a = np.arange(13)[:, None] + 2.0
    assert EPS * np.linalg.cond(1.0 / (a + a.T + 1)) > 1e-2  # n = 13: no accuracy left
