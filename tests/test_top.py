"""Heavy symmetric top (astrodyn.attitude.top) against Baruh sec. 10.5.

The closed forms (steady precession rates, sleeping-top threshold, nutation
turning points from the cubic in u = cos theta) are checked against the
*simulated* motion (the top's own splitting with the exact free symmetric-top
flow, ``top4``, and the generic rigid-body splitting), which shares no code with
them; the three integrals of the top are checked along the simulation.  The
compiled top kernel is also checked against the same splitting written with
direction cosine matrices and libm (no quaternions, no polynomials), against the
exact torque-free solution with gravity off, and its trigonometry against mpmath.
"""

import numpy as np
import pytest

from astrodyn.attitude.top import HeavyTop
from astrodyn.rotation import dcm_from_quat, euler_from_quat

# a toy top: 0.5 kg, centre of mass 4 cm above the tip; moments about the tip
TOP = HeavyTop(mass=0.5, cm_distance=0.04, transverse_inertia=2e-3, axial_inertia=1e-3, gravity=9.81)


def nutation_angle(q):
    return np.arccos(np.clip(dcm_from_quat(q)[..., 2, 2], -1.0, 1.0))


def start(theta, spin, psi_dot=0.0, theta_dot=0.0):
    """State with 3-1-3 angles (0, theta, 0), axial rate spin = phi' + psi' cos theta."""
    return TOP.state_from_euler(0.0, theta, 0.0, psi_dot, theta_dot, spin - psi_dot * np.cos(theta))


@pytest.mark.parametrize("root", [0, 1])
def test_steady_precession_rates_hold_theta_constant(root):
    theta0, spin = 0.5, 100.0
    rates = TOP.steady_precession_rates(theta0, spin)
    psi_dot = float(rates[root])
    # slow ~ m g l / (J w3) ~ 2 rad/s, fast ~ J w3 / (I cos theta) ~ 57 rad/s
    assert (1.5 < psi_dot < 2.5) if root == 0 else (50 < psi_dot < 65)
    w0, q0 = start(theta0, spin, psi_dot)
    t = np.linspace(0.0, 1.0, 201)[1:]
    w, q, info = TOP.simulate(w0, q0, t, step=2e-4)
    # a 1e-6 relative error in psi' would nutate theta by ~1e-7 rad; split4 error ~info
    assert np.max(np.abs(nutation_angle(q) - theta0)) < 1e-8 + 10 * info["error_attitude"]
    psi = np.unwrap(euler_from_quat(q, "313")[:, 0])
    np.testing.assert_allclose(psi, psi_dot * t, rtol=1e-8, atol=1e-8)


def test_steady_precession_absent_when_spin_too_small():
    theta0 = 0.3
    spin_min = 2 * np.sqrt(TOP.transverse_inertia * TOP.mgl * np.cos(theta0)) / TOP.axial_inertia
    slow, fast = TOP.steady_precession_rates(theta0, [0.99 * spin_min, 1.01 * spin_min])
    assert np.isnan(slow[0]) and np.isnan(fast[0])
    assert np.isfinite(slow[1]) and np.isfinite(fast[1])


@pytest.mark.parametrize("method", ["top4", "split4"])
def test_integrals_conserved(method):
    w0, q0 = start(0.5, 60.0)
    t = np.linspace(0.0, 5.0, 51)[1:]
    e0, pz0, pa0 = TOP.integrals(w0, q0)
    errs = []
    for h in (2e-3, 1e-3):
        w, q, _ = TOP.simulate(w0, q0, t, method=method, step=h, error_estimate=False)
        e, pz, pa = TOP.integrals(w, q)
        # vertical momentum: gravity's torque is horizontal and every sub-step is an
        # exact rotation, so p_psi is kept to round-off: at most ~N eps with
        # N = 5000 steps x 25 rotations ~ 1.3e5 -> 1.4e-11 (measured < 5e-12)
        assert np.max(np.abs(pz - pz0)) / abs(pa0) < 1e-10
        if method == "top4":
            # no sub-step writes M3 (the kick has no b3 component, the free flow is
            # exact): J w3 = M3 comes back up to the 1-ulp rounding of w3 = M3 / J
            assert np.max(np.abs(pa - pa0)) <= 2 * np.finfo(float).eps * abs(pa0)
            errs.append(np.max(np.abs(e - e0)) / abs(e0))
        else:
            errs.append(max(np.max(np.abs(e - e0)) / abs(e0), np.max(np.abs(pa - pa0)) / abs(pa0)))
    # energy (and, for split4, axial momentum): truncation error of a 4th-order scheme, ratio 16
    assert errs[1] < 1e-9  # measured 1.1e-10 (split4), 1.3e-12 (top4) at h = 1e-3 s
    assert 0.7 * 16 < errs[0] / errs[1] < 1.3 * 16


def test_top_splitting_long_run():
    # 100 s = 1e5 steps of 1 ms, 1700 spin turns.  top4: J w3 exact, p_psi at the
    # round-off random walk (5e5 rotations x 1e-16 -> ~1e-13 typical; bound 100x that),
    # energy bounded at its truncation level (symplectic: no secular drift), and a
    # 4th-order accuracy about 50x better than the generic split4 at the same step
    # (its free flow is itself split into 3 axis rotations).
    w0, q0 = start(0.5, 60.0)
    t = np.linspace(0.0, 100.0, 21)[1:]
    e0, pz0, pa0 = TOP.integrals(w0, q0)
    w, q, info = TOP.simulate(w0, q0, t, method="top4", step=1e-3)
    e, pz, pa = TOP.integrals(w, q)
    assert np.max(np.abs(pa - pa0)) <= 2 * np.finfo(float).eps * abs(pa0)
    assert np.max(np.abs(pz - pz0)) / abs(pa0) < 1e-11  # measured 1e-12
    de = np.abs(e - e0) / abs(e0)
    assert np.max(de) < 1e-11  # measured 1.1e-12
    assert np.max(de[10:]) < 3 * np.max(de[:10]) + 1e-13  # second half no worse than the first: no drift
    w2, q2, info2 = TOP.simulate(w0, q0, t, method="split4", step=1e-3)
    e2, _, pa2 = TOP.integrals(w2, q2)
    assert np.max(np.abs(pa2 - pa0)) / abs(pa0) > 1e-12  # the generic splitting does not keep J w3
    assert info["error_attitude"] < info2["error_attitude"] / 10
    # the step-doubling estimates are honest: the two runs differ by about split4's error
    from astrodyn.rotation import attitude_difference

    gap = np.max(attitude_difference(q, q2))
    assert info2["error_attitude"] / 3 < gap < 3 * info2["error_attitude"]


@pytest.mark.parametrize("factor, stable", [(1.2, True), (0.8, False)])
def test_sleeping_top_threshold(factor, stable):
    spin = factor * TOP.sleeping_spin_threshold()
    assert TOP.sleeping_is_stable(spin) == stable
    tilt = 1e-3
    w0, q0 = start(tilt, spin)
    t = np.linspace(0.0, 3.0, 301)[1:]
    w, q, _ = TOP.simulate(w0, q0, t, step=5e-4, error_estimate=False)
    th = nutation_angle(q)
    if stable:
        # bounded by the nutation turning points (a few times the initial tilt)
        lo, hi = TOP.nutation_bounds(w0, q0)
        assert np.max(th) < 1.01 * hi < 20 * tilt
    else:
        # growth rate sqrt(4 I m g l - J^2 w3^2) / (2 I) ~ 5.9 /s: the top falls within 3 s
        assert np.max(th) > 0.5


@pytest.mark.parametrize("spin", [60.0, 200.0])
def test_nutation_bounds_match_simulation(spin):
    theta0 = 0.5
    w0, q0 = start(theta0, spin)  # theta' = 0: the start is a turning point
    lo, hi = TOP.nutation_bounds(w0, q0)
    assert abs(lo - theta0) < 1e-9  # root of the cubic at u0 = cos(theta0), conditioning ~1e-15 / f'(u0)
    h = 2e-4
    t = np.arange(1, 10001) * h
    w, q, _ = TOP.simulate(w0, q0, t, step=h, error_estimate=False)
    th = nutation_angle(q)
    # sampling every h: extremes missed by at most (omega_nut h)^2 / 8 * amplitude,
    # omega_nut ~ J w3 / I <= 100 rad/s: < 5e-5 relative of the amplitude
    amp = hi - lo
    assert np.max(th) <= hi + 1e-9 and np.min(th) >= lo - 1e-9
    assert abs(np.max(th) - hi) < 5e-5 * amp + 1e-9


def test_bad_parameters():
    with pytest.raises(ValueError, match="axial_inertia"):
        HeavyTop(1.0, 0.1, 1.0, 3.0)
    with pytest.raises(ValueError, match="mass"):
        HeavyTop(-1.0, 0.1, 1.0, 1.0)


# ---------------------------------------------------------------------------
# the compiled top kernel against independent formulations
# ---------------------------------------------------------------------------


def _rodrigues_dcm(n, angle):
    """``exp(-angle [n x])`` for a unit vector n: the DCM change when the body turns by +angle about n."""
    K = np.array([[0.0, -n[2], n[1]], [n[2], 0.0, -n[0]], [-n[1], n[0], 0.0]])
    return np.eye(3) - np.sin(angle) * K + (1.0 - np.cos(angle)) * (K @ K)


def reference_top(top, w0, q0, t_out, step, weights):
    """The top's splitting written out with direction cosine matrices and libm trig.

    Per stage (weight g, a = g dt): half kick ``M += a/2 r_c x (C F)``; the exact
    free symmetric top ``C <- C_3(b) exp(-|M| a / I [n x]) C``, ``M <- C_3(b) M``
    (``n = M/|M|``, ``b = (1/J - 1/I) M3 a``); half kick.  No merged kicks, no
    quaternions, no polynomials: shares no code with the kernel.
    """
    I, J = top.transverse_inertia, top.axial_inertia
    r_c = np.array([0.0, 0.0, top.cm_distance])
    force = np.array([0.0, 0.0, -top.mass * top.gravity])
    M = top.inertia * np.asarray(w0, float)
    C = dcm_from_quat(q0)
    out_w, out_C, t_prev = [], [], 0.0
    for t_k in t_out:
        n_steps = int(np.ceil(abs(t_k - t_prev) / step))
        for _ in range(n_steps):
            dt = (t_k - t_prev) / n_steps
            for g in weights:
                a = g * dt
                M = M + 0.5 * a * np.cross(r_c, C @ force)
                m = np.linalg.norm(M)
                b = (1.0 / J - 1.0 / I) * M[2] * a
                C3 = np.array([[np.cos(b), np.sin(b), 0.0], [-np.sin(b), np.cos(b), 0.0], [0.0, 0.0, 1.0]])
                C = C3 @ _rodrigues_dcm(M / m, m * a / I) @ C
                M = C3 @ M
                M = M + 0.5 * a * np.cross(r_c, C @ force)
        out_w.append(M / top.inertia)
        out_C.append(C)
        t_prev = t_k
    return np.array(out_w), np.array(out_C)


@pytest.mark.parametrize("method", ["top2", "top4"])
@pytest.mark.parametrize("step", [2e-3, 4e-2])  # turn half-angles <= 0.04 rad (polynomials) / up to 0.4 rad (libm)
@pytest.mark.parametrize("sign", [1.0, -1.0])  # forward and backward in time
def test_kernel_matches_matrix_reference(method, step, sign):
    from astrodyn.attitude.integrators import SPLIT2_WEIGHTS, SPLIT4_WEIGHTS

    weights = SPLIT4_WEIGHTS if method == "top4" else SPLIT2_WEIGHTS
    w0, q0 = TOP.state_from_euler(0.3, 0.7, -0.2, 3.0, 1.5, 55.0)  # tilted, nutating and precessing
    t = sign * np.array([0.13, 0.4, 0.4, 0.8])  # unequal intervals (the kernel's per-dt tables), a repeat
    w, q, _ = TOP.simulate(w0, q0, t, method=method, step=step, error_estimate=False)
    w_ref, C_ref = reference_top(TOP, w0, q0, t, step, weights)
    # the same map evaluated two ways: they differ by rounding only.  Over 400 steps
    # x 5 stages x ~5 rounded operations on unit-size quantities, a worst-case
    # linear build-up is 1e4 eps ~ 2e-12 (measured: <= 3.2e-14 for C, 1.4e-15
    # relative for w).  The map is stable here (nutation of a fast top), so no
    # amplification; a wrong kick sign fails every case (checked).
    np.testing.assert_allclose(dcm_from_quat(q), C_ref, rtol=0, atol=2e-12)
    np.testing.assert_allclose(w, w_ref, rtol=0, atol=2e-12 * np.linalg.norm(w0))
    np.testing.assert_array_equal(w[2], w[1])  # repeated time: no steps, same state
    np.testing.assert_array_equal(TOP.inertia[2] * w[:, 2], TOP.inertia[2] * w0[2])  # J w3 untouched


@pytest.mark.parametrize("step", [1e-3, 5e-2])  # polynomial branch / libm branch (half-angles up to 0.5 rad)
def test_gravity_free_top_is_exact(step):
    # with g = 0 the kicks vanish and top4 is the exact free symmetric-top flow for
    # any step: compare with the exact torque-free solution (Jacobi elliptic
    # functions, astrodyn.attitude.torque_free: independent code)
    from astrodyn.attitude import torque_free
    from astrodyn.rotation import attitude_difference

    free = HeavyTop(mass=0.5, cm_distance=0.04, transverse_inertia=2e-3, axial_inertia=1e-3, gravity=0.0)
    w0, q0 = free.state_from_euler(0.3, 0.7, -0.2, 3.0, 1.5, 55.0)
    t = np.linspace(0.0, 5.0, 6)[1:]
    w, q, info = free.simulate(w0, q0, t, step=step, error_estimate=True)
    w_ex, q_ex = torque_free(free.inertia, w0, q0, t)
    # rounding only: N = 5000 (or 100) steps x 10 turns, each rounding the attitude
    # by ~1 eps: worst-case linear build-up 5e4 x 2.2e-16 ~ 1.1e-11 rad, the bound.
    # Measured 4.0e-13 / 6.7e-14 rad (the previous libm kernel: 3.7e-13 / 5.9e-14);
    # a 1e-6 relative error in the turn rate |M| / I (~29 rad/s) would give 1.4e-4 rad.
    assert np.max(attitude_difference(q, q_ex)) < 1e-11
    np.testing.assert_allclose(w, w_ex, rtol=0, atol=1e-11 * np.linalg.norm(w0))
    assert info["error_attitude"] < 1e-11  # no truncation error: step doubling sees only rounding


def test_momentum_turn_against_mpmath():
    # (c, s) of the turn about M: c = cos x, s = sin(x)/|M|, x = |M| k, from x^2 only
    # (polynomials for |x| <= 1/8, libm above), against 40-digit mpmath
    import mpmath as mp

    from astrodyn.attitude.integrators import SMALL_ANGLE
    from astrodyn.attitude.top import _momentum_turn

    rng = np.random.default_rng(5)
    eps = 2.0**-52
    edge = SMALL_ANGLE * np.array([1.0, 1 - 2**-50, 1 + 2**-50, 0.999, 1.001])
    xs = np.concatenate([rng.uniform(0, SMALL_ANGLE, 300), 10.0 ** rng.uniform(-200, -1, 50), [0.0], edge, rng.uniform(SMALL_ANGLE, 3.0, 100)])
    for x in xs:
        m = float(10.0 ** rng.uniform(-3, 3))  # |M|, N m s
        for k in (x / m, -x / m):  # dt / (2 I): both signs (negative stage weights, backward time)
            mm = m * m
            c, s = _momentum_turn(mm, k)
            with mp.workdps(40):
                xr = mp.sqrt(mp.mpf(mm)) * mp.mpf(k)
                c_ref, s_ref = mp.cos(xr), mp.sin(xr) / mp.sqrt(mp.mpf(mm))
                err_c = float(abs(mp.mpf(c) - c_ref))
                err_s = float(abs(mp.mpf(s) - s_ref) / abs(s_ref)) if s_ref != 0 else abs(s)
            # x itself is known only to ~1 rounding (mm = m*m, k = x/m, z = mm k^2): a 1-ulp
            # change of x moves cos by |x sin x| eps <= |x| eps and sin(x)/|M| by
            # |x cot x| eps relative; polynomials (|x| <= 1/8): truncation < 0.01 ulp,
            # so cos within 2 eps absolute and s within 3 eps relative (measured <= 1.1
            # eps and 1.6 eps); libm branch (x up to 3): cos within (2 + |x|) eps,
            # s within (3 + |x cot x|) eps relative.
            tol_c = 2 * eps if x <= SMALL_ANGLE else (2 + x) * eps
            tol_s = 3 * eps if x <= SMALL_ANGLE else (3 + abs(x / np.tan(x))) * eps
            assert err_c <= tol_c, (x, k, err_c / eps)
            assert err_s <= tol_s, (x, k, err_s / eps)
    assert all(np.isnan(_momentum_turn(np.nan, 0.01)))
    assert _momentum_turn(0.0, 0.01) == (1.0, 0.01)  # zero momentum: no turn
