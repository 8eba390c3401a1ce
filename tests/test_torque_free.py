"""Exact torque-free motion against independent references.

References: the 30-digit mpmath Taylor integrator
(:mod:`astrodyn.reference.attitude_mp`, shares no code with the core), scipy
DOP853 at rtol 1e-13, closed forms (axisymmetric body, uniform rotation,
Landau's 4K/wp) and the conservation laws.

Tolerances (conditioning, see each assert):
* rates: a one-ulp change of t or w0 moves w by about eps |w| (1 + wp |t|);
  the elliptic functions add a few ulp.  We allow 100 eps |w0| (1 + wp t).
* attitude: psi(t) is a sum of O(|w| t) and O(K) terms (K the quarter period
  in the elliptic argument, up to 22 near the separatrix), each evaluated to a
  few ulp, so |C - C_ref| <~ eps (|w| t + K); one ulp of t alone moves C by
  eps |w| t.  We allow 100 eps (1 + |w| t + K).
"""

import functools
import math

import mpmath as mp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from astrodyn.attitude import flip_period, herpolhode, polhode, rate_period, torque_free
from astrodyn.reference.attitude_mp import torque_free_reference
from astrodyn.rotation import dcm_from_quat

EPS = np.finfo(float).eps
Q0 = tuple(np.array([0.9, 0.1, -0.3, 0.2]) / np.linalg.norm([0.9, 0.1, -0.3, 0.2]))


@functools.cache
def _mp_reference(inertia, w0, span, npts=5):
    t = np.linspace(0.0, span, npts)
    w, C, q = torque_free_reference(inertia, w0, Q0, t, dps=30, order=28)
    return t, w, C


def _landau_K_wp(inertia, w0):
    """Quarter period K(m) and wp from Landau sec. 37 (mpmath, sorted axes, both families)."""
    with mp.workdps(40):
        I = [mp.mpf(x) for x in inertia]
        w = [mp.mpf(x) for x in w0]
        order = sorted(range(3), key=lambda i: I[i])
        A, B, C = (I[i] for i in order)
        w1, w2, w3 = (w[i] for i in order)
        T2 = A * w1**2 + B * w2**2 + C * w3**2
        H2 = (A * w1) ** 2 + (B * w2) ** 2 + (C * w3) ** 2
        if H2 < T2 * B:  # circulation about the minor axis: swap roles (Landau: "interchange I1 and I3")
            A, C = C, A
        wp = mp.sqrt((C - B) * (H2 - T2 * A) / (A * B * C))
        m = (B - A) * (T2 * C - H2) / ((C - B) * (H2 - T2 * A))
        return mp.ellipk(m), wp, m


# (name, inertia, w0, span in s)
CASES = [
    ("triaxial_major", (1.0, 2.0, 3.0), (0.3, 0.2, 1.0), 4.0),
    ("triaxial_minor_unsorted", (3.0, 1.0, 2.0), (0.2, 1.0, 0.4), 4.0),
    ("axisymmetric", (2.0, 2.0, 3.0), (0.3, 0.2, 1.0), 4.0),
    ("near_axisymmetric", (1.0, 1.0 + 1e-9, 2.0), (0.3, 0.2, 1.0), 4.0),
    ("prolate_axisymmetric", (1.0, 3.0, 3.0), (0.3, 0.2, 1.0), 4.0),
    ("sphere", (1.0, 1.0, 1.0), (0.1, 0.2, 0.3), 4.0),
    ("sphere_plus_ulp", (1.0, 1.0, 1.0 + 2.0**-52), (0.1, 0.2, 0.3), 4.0),
    ("intermediate_flip", (1.0, 2.0, 3.0), (1e-3, 1.0, -1e-3), 4.0),
    ("near_separatrix_1e-9", (1.0, 2.0, 3.0), (1e-9, 1.0, 1e-9), 4.0),
    ("m1_1e-12", (1.0, 2.0, 3.0), (1e-6, 1.0, 0.0), 4.0),
    ("exact_intermediate_spin", (1.0, 2.0, 3.0), (0.0, 1.0, 0.0), 4.0),
    ("fast_spin_300", (1.0, 2.0, 3.0), (3.0, 2.0, 300.0), 0.03),
    # moment gap 1e-9 between the two minor moments, circulating about the minor axis
    # (w3^2 < (B - A) w1^2 / 2): wp = 2.3e-5 rad/s, n = -5.0e8, k = 2.2e4; one ulp of
    # the inputs moves C by < 7e-16 (mpmath), the J - J0 form lost |k| eps ~ 1e-11
    ("near_symmetric_slow_circulation", (1.0, 1.0 + 1e-9, 2.0), (1.0, 0.2, 1e-6), 4.0),
    ("near_prolate_circulation", (1.0, 3.0, 3.0 + 3e-9), (1.0, 0.2, 0.3), 4.0),
]


@pytest.mark.parametrize("name, inertia, w0, span", CASES, ids=[c[0] for c in CASES])
def test_against_mpmath_reference(name, inertia, w0, span):
    t, w_ref, C_ref = _mp_reference(inertia, w0, span)
    w, q = torque_free(inertia, w0, Q0, t)
    wmag = np.linalg.norm(w0)
    K = float(_landau_K_wp(inertia, w0)[0]) if name not in ("sphere", "exact_intermediate_spin") else 0.0
    K = K if math.isfinite(K) else 0.0
    for i, ti in enumerate(t):
        tol_w = 100 * EPS * wmag * (1 + wmag * ti)  # one ulp of t / w0, 100x
        tol_C = 100 * EPS * (1 + wmag * ti + K)  # O(|w| t) and O(K) terms at a few ulp, 100x
        assert np.abs(w[i] - w_ref[i]).max() <= tol_w, (name, ti, np.abs(w[i] - w_ref[i]).max())
        assert np.abs(dcm_from_quat(q[i]) - C_ref[i]).max() <= tol_C, (name, ti)


def test_m1_of_the_near_separatrix_cases():
    """The named cases really are that close to the separatrix (m1 = 1 - m from mpmath)."""
    for w0, lo, hi in [((1e-9, 1.0, 1e-9), 1e-19, 1e-17), ((1e-6, 1.0, 0.0), 1e-13, 1e-11)]:
        _, _, m = _landau_K_wp((1.0, 2.0, 3.0), w0)
        assert lo < float(1 - m) < hi


def test_negative_times_against_reference():
    inertia, w0 = (1.0, 2.0, 3.0), (0.3, 0.2, 1.0)
    t = np.array([0.0, -1.5, -3.0])
    w_ref, C_ref, _ = torque_free_reference(inertia, w0, Q0, t, dps=30, order=28)
    w, q = torque_free(inertia, w0, Q0, t)
    assert np.abs(w - w_ref).max() <= 100 * EPS * 4
    assert np.abs(dcm_from_quat(q) - C_ref).max() <= 100 * EPS * 8


def _dop853(inertia, w0, t):
    I = np.asarray(inertia, float)

    def rhs(_, y):
        w = y[:3]
        Cm = y[3:].reshape(3, 3)
        return np.concatenate([np.cross(I * w, w) / I, (-np.cross(w, Cm.T).T).ravel()])

    y0 = np.concatenate([w0, dcm_from_quat(np.array(Q0)).ravel()])
    s = solve_ivp(rhs, (0, t[-1]), y0, method="DOP853", rtol=1e-13, atol=1e-15, t_eval=t)
    return s.y[:3].T, s.y[3:].T.reshape(-1, 3, 3)


@pytest.mark.parametrize(
    "inertia, w0, tol",
    [
        # DOP853 at rtol 1e-13 accumulates ~1e-13 per unit time here; measured 1e-13..1e-12 over 50 s
        ((1.0, 2.0, 3.0), (0.3, 0.2, 1.0), 1e-10),
        ((5.0, 2.0, 3.0), (0.1, 0.2, -1.0), 1e-10),
        # intermediate axis: the integrator's error grows through each flip (~1e-9 documented)
        ((1.0, 2.0, 3.0), (1e-3, 1.0, 1e-3), 1e-8),
    ],
)
def test_against_dop853_over_50s(inertia, w0, tol):
    t = np.linspace(0, 50, 26)
    w_ref, C_ref = _dop853(inertia, np.array(w0), t)
    w, q = torque_free(inertia, w0, Q0, t)
    assert np.abs(w - w_ref).max() <= tol * np.linalg.norm(w0)
    assert np.abs(dcm_from_quat(q) - C_ref).max() <= tol


def test_flip_period_formula_and_zero_crossings():
    """flip_period = 4 K(m)/wp (Landau 37.10-37.12 in mpmath); w2 reverses every half of it."""
    inertia, w0 = (1.0, 2.0, 3.0), (0.05, 1.0, 0.05)
    K, wp, _ = _landau_K_wp(inertia, w0)
    T = flip_period(inertia, w0)
    assert abs(T / float(4 * K / wp) - 1) <= 16 * EPS  # K and wp each to a few ulp
    # rates return after one period and reverse after half of it
    w, _ = torque_free(inertia, w0, Q0, np.array([0.0, T / 2, T, 7 * T]))
    assert np.abs(w[2] - w[0]).max() <= 1e-13 and np.abs(w[3] - w[0]).max() <= 1e-12
    # DOP853 zero crossings of w2 (independent), good to its ~1e-9
    def ev(t, y):
        return y[1]
    I = np.asarray(inertia)
    sol = solve_ivp(
        lambda t, y: np.cross(I * y, y) / I, (0, 1.6 * T), np.array(w0), method="DOP853",
        rtol=1e-13, atol=1e-15, events=ev,
    )
    crossings = sol.t_events[0]
    assert len(crossings) >= 3
    assert abs((crossings[2] - crossings[0]) / T - 1) <= 1e-9


def test_flip_period_against_mpmath_reference_fast():
    """Half a flip period from the mpmath reference: w at T/2 is w0 with w1, w2 reversed (sn, cn change sign)."""
    inertia, w0 = (1.0, 2.0, 3.0), (0.3, 1.0, 0.3)  # well away from the separatrix: short period
    T = flip_period(inertia, w0)
    w_ref, _, _ = torque_free_reference(inertia, w0, Q0, [T / 2], dps=30, order=28)
    expected = np.array([-w0[0], -w0[1], w0[2]])
    assert np.abs(w_ref[0] - expected).max() <= 1e-14  # reference at 30 digits; T rounded to 1 ulp


def test_axisymmetric_closed_form_rates():
    """I1 = I2 = A: w3 constant, z = w1 + i w2 obeys z' = i lambda z, lambda = (C - A) w3 / A (Baruh ch. 10)."""
    A, C = 2.0, 3.0
    w0 = np.array([0.3, 0.2, 1.0])
    t = np.linspace(0, 1e4, 101)
    w, _ = torque_free((A, A, C), w0, Q0, t)
    lam = (C - A) / A * w0[2]
    z = (w0[0] + 1j * w0[1]) * np.exp(1j * lam * t)
    assert np.abs(w[:, 2] - w0[2]).max() <= 4 * EPS
    tol = 100 * EPS * (1 + lam * t)  # phase lam t carries one ulp of t, 100x
    assert np.all(np.abs(w[:, 0] - z.real) <= tol) and np.all(np.abs(w[:, 1] - z.imag) <= tol)


def test_uniform_rotation_closed_form():
    """Pure spin about any principal axis (the intermediate one included): w constant, C = C_axis(w t) C0."""
    t = np.array([0.0, 0.7, 123.4, -5.0])
    C0 = dcm_from_quat(np.array(Q0))
    for axis in range(3):
        w0 = np.zeros(3)
        w0[axis] = 1.3
        w, q = torque_free((1.0, 2.0, 3.0), w0, Q0, t)
        assert np.all(w == w0)
        for ti, qi in zip(t, q):
            a = 1.3 * ti
            c, s = math.cos(a), math.sin(a)
            j, k = (axis + 1) % 3, (axis + 2) % 3
            R = np.eye(3)
            R[j, j] = R[k, k] = c
            R[j, k], R[k, j] = s, -s
            assert np.abs(dcm_from_quat(qi) - R @ C0).max() <= 100 * EPS * (1 + abs(a))


def test_zero_rates_identity_motion():
    w, q = torque_free((1.0, 2.0, 3.0), (0.0, 0.0, 0.0), Q0, np.array([0.0, 1e6]))
    assert np.all(w == 0) and np.abs(q - np.array(Q0)).max() <= EPS


def test_initial_state_reproduced():
    for _, inertia, w0, _ in CASES:
        w, q = torque_free(inertia, w0, Q0, np.array([0.0]))
        assert np.abs(w[0] - w0).max() <= 8 * EPS * np.linalg.norm(w0)
        assert np.abs(dcm_from_quat(q[0]) - dcm_from_quat(np.array(Q0))).max() <= 8 * EPS


@pytest.mark.parametrize(
    "inertia, w0",
    [((1.0, 2.0, 3.0), (0.3, 0.2, 1.0)), ((1.0, 2.0, 3.0), (1e-9, 1.0, 1e-9)), ((1.0, 1.0 + 1e-9, 2.0), (0.3, 0.2, 1.0)),
     ((3.0, 1.0, 2.0), (0.2, 1.0, 0.4)), ((1.0, 2.0, 3.0), (3.0, 2.0, 300.0)), ((1.0, 1.0 + 1e-9, 2.0), (1.0, 0.2, 1e-6))],
)
def test_long_span_conservation(inertia, w0):
    """Over 1e6 s: |q| - 1 <= 1e-12, energy and inertial momentum C^T I w to 1e-10 relative."""
    t = np.concatenate([np.linspace(0, 1e6, 2001), [1e6 - 0.123, 987654.321]])
    w, q = torque_free(inertia, w0, Q0, t)
    I = np.asarray(inertia)
    assert np.abs(np.linalg.norm(q, axis=1) - 1).max() <= 1e-12
    T = np.einsum("ij,j,ij->i", w, I, w)
    assert np.abs(T / T[0] - 1).max() <= 1e-10
    H = np.einsum("nji,nj->ni", dcm_from_quat(q), I * w)
    assert np.abs(H - H[0]).max() <= 1e-10 * np.linalg.norm(H[0])


@pytest.mark.parametrize(
    "inertia, w0", [((1.0, 2.0, 3.0), (0.3, 0.2, 1.0)), ((1.0, 1.0 + 1e-9, 2.0), (1.0, 0.2, 1e-6))], ids=["triaxial", "slow"]
)
def test_restart_across_half_periods(inertia, w0):
    """Flow property x(t1 + t2) = flow(t2, x(t1)) across several half periods of the rates.

    The restart recomputes the initial phase, J0/G0 and C_B0 from the state at t1
    (a different phase and reduction path; the half-period constants themselves are
    checked against mpmath in test_pi_form_against_mpmath).  The restart state
    carries ~eps |w| rounding, which moves the attitude by ~eps |w| t2; the direct
    path carries eps (|w| t + K) as in the mpmath test: 100x their sum.
    """
    P = rate_period(inertia, w0)  # two half periods
    t1 = np.array([0.0, 1.3 * P, 2.6 * P])
    t2 = 0.37 * P
    w1, q1 = torque_free(inertia, w0, Q0, t1)
    wd, qd = torque_free(inertia, w0, Q0, t1 + t2)
    wmag = np.linalg.norm(w0)
    K = float(_landau_K_wp(inertia, w0)[0])
    for i in range(len(t1)):
        wr, qr = torque_free(inertia, w1[i], q1[i], t2)
        tol = 100 * EPS * (1 + wmag * (t1[i] + t2) + K)
        assert np.abs(wr - wd[i]).max() <= tol * wmag
        assert np.abs(dcm_from_quat(qr) - dcm_from_quat(qd[i])).max() <= tol


@pytest.mark.parametrize("n, m", [(-3.0, 0.3), (-6.7e8, 0.044), (-1.5, 0.999), (-40.0, 1e-6)])
def test_pi_form_against_mpmath(n, m):
    """The n < -1 form of the third-kind integral (reciprocal characteristic, DLMF 19.7.9)
    and its half-period increment 2 Pi(n|m), against mpmath.ellippi at 30 digits.

    Relative accuracy: a few ulp of Pi (no cancellation: both terms positive for
    sn > 0), so 100 eps relative, plus 100 eps absolute on the scale 1/sqrt(-n).
    """
    import importlib

    tf = importlib.import_module("astrodyn.attitude.torque_free")
    from astrodyn.attitude.elliptic import ellipj, ellipk

    m1 = 1.0 - m
    g = math.sqrt(1.0 + m - n - m / n)
    K = float(ellipk(m, m1))
    for r in np.linspace(-K, K, 9):
        sn, cn, dn = (float(x) for x in ellipj(r, m))
        jv, _ = tf._j_g(sn, cn, dn, r, n, math.sqrt(1 - n), m1, m, 1.0, g)
        with mp.workdps(30):
            phi = mp.asin(mp.mpf(sn))  # |r| <= K: amplitude in [-pi/2, pi/2]
            ref = float(mp.ellippi(mp.mpf(n), phi, mp.mpf(m)))
        assert abs(jv - ref) <= 100 * EPS * (abs(ref) + 1 / math.sqrt(-n)), (r, jv, ref)
    # the half-period constant of a body with about this (n, m): A = 1, C = 2, B from
    # n = -C (B - A) / (A (C - B)), w2 = 0 and w3 from m; compared with mpmath at the
    # body's own (n, m) (whatever rounding made of them)
    A, C = 1.0, 2.0
    B = C * A * (1.0 - n) / (C - n * A)
    w3 = math.sqrt((B - A) * A / ((C - B) * C * m))
    body = tf.PreparedBody([A, B, C], [1.0, 0.0, w3], [1.0, 0, 0, 0]).bodies[0]
    assert body["pi_form"] == 1 and 0.0 < body["m"] < 1.0
    with mp.workdps(30):
        ref2 = 2 * mp.ellippi(mp.mpf(body["n"]), mp.mpf(body["m"]))
    assert abs(body["dj"] - float(ref2)) <= 100 * EPS * abs(ref2)


def test_periodicity_cost_independent_of_t():
    """Rates repeat after the rate period also at t ~ 1e9 s (reduction by the period, not by integration)."""
    inertia, w0 = (1.0, 2.0, 3.0), (0.3, 0.2, 1.0)
    P = rate_period(inertia, w0)
    k = np.floor(1e9 / P)
    w, _ = torque_free(inertia, w0, Q0, np.array([0.0, k * P]))
    # k P is known to ulp(1e9) ~ 1.2e-7 s: the rate error is |w'| * 1.2e-7 at most
    assert np.abs(w[1] - w[0]).max() <= 1e-6


def test_batch_over_bodies_matches_loop():
    inertia = np.array([[1.0, 2.0, 3.0], [3.0, 1.0, 2.0], [2.0, 2.0, 3.0]])
    w0 = np.array([[0.3, 0.2, 1.0], [0.2, 1.0, 0.4], [0.0, 1.0, 0.0]])
    t = np.linspace(-5, 5, 7)
    w, q = torque_free(inertia, w0, Q0, t)
    assert w.shape == (3, 7, 3) and q.shape == (3, 7, 4)
    for b in range(3):
        wb, qb = torque_free(inertia[b], w0[b], Q0, t)
        assert np.array_equal(wb, w[b]) and np.array_equal(qb, q[b])
    ws, qs = torque_free(inertia[0], w0[0], Q0, 1.0)
    assert ws.shape == (3,) and qs.shape == (4,)


def test_polhode_and_herpolhode_geometry():
    inertia, w0 = np.array([1.0, 2.0, 3.0]), np.array([0.3, 0.2, 1.0])
    P = polhode(inertia, w0, 64)
    T2, H2 = w0 @ (inertia * w0), np.sum((inertia * w0) ** 2)
    assert np.abs(np.einsum("ij,j,ij->i", P, inertia, P) / T2 - 1).max() <= 1e-14
    assert np.abs(np.sum((inertia * P) ** 2, axis=1) / H2 - 1).max() <= 1e-14
    assert np.abs(P[0] - w0).max() <= 1e-15
    t = np.linspace(0, 100, 50)
    wi = herpolhode(inertia, w0, Q0, t)
    Hi = dcm_from_quat(np.array(Q0)).T @ (inertia * w0)
    # tip on the invariable plane w_i . H_hat = 2T/H
    assert np.abs(wi @ (Hi / np.linalg.norm(Hi)) - T2 / math.sqrt(H2)).max() <= 1e-13


def test_bad_input_and_nan():
    with pytest.raises(ValueError, match="inertia"):
        torque_free((1.0, -2.0, 3.0), (0.1, 0.2, 0.3), Q0, [0.0])
    with pytest.raises(ValueError, match="w0"):
        torque_free((1.0, 2.0, 3.0), (0.1, 0.2), Q0, [0.0])
    with pytest.raises(ValueError, match="q0"):
        torque_free((1.0, 2.0, 3.0), (0.1, 0.2, 0.3), (1.0, 0.0, 0.0), [0.0])
    with pytest.raises(ValueError, match="t:"):
        torque_free((1.0, 2.0, 3.0), (0.1, 0.2, 0.3), Q0, np.zeros((2, 2)))
    w, q = torque_free((1.0, 2.0, 3.0), (np.nan, 0.2, 0.3), Q0, [0.0, 1.0])
    assert np.all(np.isnan(w)) and np.all(np.isnan(q))
    w, q = torque_free((1.0, 2.0, 3.0), (0.1, 0.2, 0.3), Q0, [np.nan, 1.0])
    assert np.all(np.isnan(w[0])) and np.all(np.isfinite(w[1]))
