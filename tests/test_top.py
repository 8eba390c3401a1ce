"""Heavy symmetric top (astrodyn.attitude.top) against Baruh sec. 10.5.

The closed forms (steady precession rates, sleeping-top threshold, nutation
turning points from the cubic in u = cos theta) are checked against the
*simulated* motion (the top's own splitting with the exact free symmetric-top
flow, ``top4``, and the generic rigid-body splitting), which shares no code with
them; the three integrals of the top are checked along the simulation.
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
    from astrodyn.attitude.integrators import _attitude_difference

    gap = np.max(_attitude_difference(q, q2))
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
