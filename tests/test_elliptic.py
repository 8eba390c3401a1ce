"""astrodyn.attitude.elliptic against mpmath at 40-60 digits (independent reference).

Tolerances: the functions are evaluated from float64 inputs that are exact in
mpmath, so the only error is ours.  For sn, cn the conditioning with respect
to u is |d sn/du| = |cn dn| <= 1, so one ulp of u moves them by <= ulp(u);
we allow 40 ulp of max(1, |u|) (absolute), i.e. well inside the 100x-ulp rule.
dn is checked *relatively* because near the separatrix dn(K) = sqrt(m1) is the
physics; its conditioning is |d ln dn/du| = m |sn cn| / dn^2.
"""

import math

import mpmath as mp
import numpy as np
import pytest
from hypothesis import given, strategies as st

from astrodyn.attitude.elliptic import ellipf, ellipj, ellipk, ellippi, elliprd, elliprf, elliprj

EPS = np.finfo(float).eps
M1_GRID = [1.0, 0.9, 0.5, 0.4999, 0.3, 0.1, 1e-2, 1e-4, 1e-8, 2e-12, 1e-15, 1e-18, 1e-30]


def _mp_sncndn(u, m1):
    m = 1 - mp.mpf(m1)
    u = mp.mpf(u)
    if m == 0:  # mpmath's ellipfun is slow at m = 0; the functions are sin, cos, 1
        return mp.sin(u), mp.cos(u), mp.mpf(1)
    return (mp.ellipfun("sn", u, m=m), mp.ellipfun("cn", u, m=m), mp.ellipfun("dn", u, m=m))


@pytest.mark.parametrize("m1", M1_GRID)
def test_sncndn_against_mpmath(m1):
    rng = np.random.default_rng(int(-math.log10(m1) * 7) + 1)
    with mp.workdps(60):  # 1 - 1e-30 needs > 30 digits to be represented
        K = float(mp.ellipk(1 - mp.mpf(m1)))
        u = np.concatenate([rng.uniform(-3 * K, 3 * K, 24), [0.0, K, -K, 0.5 * K, 2 * K, 1e-7]])
        sn, cn, dn = ellipj(u, 1.0 - m1, m1)
        for ui, s, c, d in zip(u, sn, cn, dn):
            S, C, D = _mp_sncndn(ui, m1)
            tol = 40 * EPS * max(1.0, abs(ui))  # ulp(u) conditioning, 40x
            assert abs(s - S) <= tol, (ui, s, S)
            assert abs(c - C) <= tol, (ui, c, C)
            # relative dn: conditioning m |sn cn| / dn^2 per unit of u
            tol_d = 40 * EPS * (1.0 + max(1.0, abs(ui)) * float(abs(S * C) / (D * D)))
            assert abs(d / D - 1) <= tol_d, (ui, d, D)


def test_dn_at_quarter_period_near_separatrix():
    """dn(K) = sqrt(m1), sn(K) = 1, cn(K) = 0 exactly; scipy.special.ellipj cannot do this at m1 = 2e-12."""
    for m1 in [1e-8, 2e-12, 1e-15, 1e-18]:
        K = ellipk(1.0 - m1, m1)
        sn, cn, dn = ellipj(K, 1.0 - m1, m1)
        assert abs(sn - 1) <= 4 * EPS
        # cn(K - du) = k' du: the rounding of K (<= ulp(K)) gives cn <= sqrt(m1) ulp(K)
        assert abs(cn) <= 4 * math.sqrt(m1) * K * EPS + 4 * EPS * math.sqrt(m1)
        assert abs(dn / math.sqrt(m1) - 1) <= 16 * EPS


@pytest.mark.parametrize("m1", M1_GRID)
def test_ellipk_against_mpmath(m1):
    with mp.workdps(60):
        ref = mp.ellipk(1 - mp.mpf(m1))
        # dK/dm1 * m1 / K = O(1 / ln(1/m1)): relative conditioning <= 1 ulp
        assert abs(ellipk(1.0 - m1, m1) / ref - 1) <= 8 * EPS


def test_ellipk_endpoints():
    assert ellipk(1.0, 0.0) == math.inf
    assert abs(ellipk(0.0, 1.0) - math.pi / 2) <= 2 * EPS


def _rand_args(rng, k, n=30):
    return [tuple(rng.uniform(0.0, 3.0, k) ** 3) for _ in range(n)]


def test_carlson_against_mpmath():
    """R_F, R_D, R_J relative error; the integrals are O(1)-conditioned in their arguments."""
    rng = np.random.default_rng(7)
    with mp.workdps(40):
        for x, y, z in _rand_args(rng, 3):
            assert abs(elliprf(x, y, z) / mp.elliprf(x, y, z) - 1) <= 40 * EPS
            assert abs(elliprd(x, y, z) / mp.elliprd(x, y, z) - 1) <= 40 * EPS
        for x, y, z, p in _rand_args(rng, 4):
            # p below min(x, y, z) makes Carlson's R_C terms hyperbolic (atanh near 1); documented
            # limit: p >= 1e-3 max(x, y, z) keeps them at the 100x-ulp level (torque_free uses p >= 1)
            p = max(p, 1e-3 * max(x, y, z))
            tol = 40 * EPS if p >= min(x, y, z) else 100 * EPS
            assert abs(elliprj(x, y, z, p) / mp.elliprj(x, y, z, p) - 1) <= tol, (x, y, z, p)


def test_carlson_edge_arguments():
    with mp.workdps(40):
        for args in [(0.0, 1e-18, 1.0), (1e-30, 2e-30, 1.0), (0.0, 1.0, 1.0), (1.0, 1.0, 1.0), (0.0, 0.5, 1.0)]:
            assert abs(elliprf(*args) / mp.elliprf(*args) - 1) <= 8 * EPS
            assert abs(elliprd(*args) / mp.elliprd(*args) - 1) <= 8 * EPS
            for p in (1.0, 3.0, 1e6):  # p >= 1: the case the torque-free attitude uses
                assert abs(elliprj(*args, p) / mp.elliprj(*args, p) - 1) <= 16 * EPS


def test_incomplete_integrals_against_mpmath():
    rng = np.random.default_rng(11)
    with mp.workdps(40):
        for _ in range(40):
            phi = rng.uniform(-10, 10)
            m1 = rng.uniform() ** 6
            n = -rng.uniform(0, 10) ** 2 if rng.uniform() < 0.7 else rng.uniform(0, 0.99)
            m = 1 - mp.mpf(m1)
            # conditioning in phi: dF/dphi = 1/dn <= 1/sqrt(m1); reduction by pi costs ulp(phi)
            F = mp.ellipf(phi, m)
            cond = 1.0 + abs(phi) / math.sqrt(m1) / float(abs(F))
            assert abs(ellipf(phi, 1.0 - m1, m1) / F - 1) <= 40 * EPS * cond
            P = mp.ellippi(n, phi, m)
            condp = 1.0 + abs(phi) / (math.sqrt(m1) * min(1.0, 1.0 - n)) / float(abs(P))
            assert abs(ellippi(n, phi, 1.0 - m1, m1) / P - 1) <= 40 * EPS * condp


@given(
    u=st.floats(-50, 50, allow_nan=False),
    m1=st.floats(0.0, 1.0, allow_nan=False),
)
def test_identities(u, m1):
    """sn^2 + cn^2 = 1 and dn^2 = m1 + m cn^2 (DLMF 22.6.1) for any u, m1."""
    sn, cn, dn = ellipj(u, 1.0 - m1, m1)
    assert abs(sn * sn + cn * cn - 1) <= 16 * EPS
    assert abs(dn * dn - (m1 + (1.0 - m1) * cn * cn)) <= 16 * EPS
    assert -1 <= sn <= 1 and -1 <= cn <= 1 and 0 <= dn <= 1 + 4 * EPS


def test_arrays_broadcast_and_scalars():
    u = np.linspace(0, 3, 6).reshape(2, 3)
    sn, cn, dn = ellipj(u, 0.7, 0.3)
    assert sn.shape == (2, 3)
    s0, _, _ = ellipj(1.0, 0.7, 0.3)
    assert isinstance(s0, float)
    assert ellipk(np.array([0.1, 0.2])).shape == (2,)


def test_nan_in_nan_out_and_errors():
    sn, cn, dn = ellipj(np.nan, 0.5, 0.5)
    assert math.isnan(sn) and math.isnan(cn) and math.isnan(dn)
    assert math.isnan(elliprf(np.nan, 1.0, 1.0))
    with pytest.raises(ValueError, match="m, m1"):
        ellipj(1.0, 1.5, -0.5)
    with pytest.raises(ValueError, match="m, m1"):
        ellipj(1.0, 0.5, 0.4)  # inconsistent complement
    with pytest.raises(ValueError, match="x, y, z"):
        elliprf(-1.0, 1.0, 1.0)
    with pytest.raises(ValueError, match="n:"):
        ellippi(1.5, 0.3, 0.5)
