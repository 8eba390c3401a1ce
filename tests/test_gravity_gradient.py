"""Gravity-gradient torque (astrodyn.attitude.torques) and its coupling to an orbit.

* The torque formula 3 mu / r^5 (r_b x I r_b) against a direct sum of the point
  gravity forces on a body made of point masses (independent physics).
* The classic small pitch libration in a circular orbit: frequency
  sqrt(3 (Ix - Iz) / Iy) n (Hughes, *Spacecraft Attitude Dynamics*, sec. 9.x;
  Baruh ch. 8), measured from the simulated motion by zero crossings.
"""

import numpy as np
import pytest

from astrodyn.attitude.integrators import propagate_attitude
from astrodyn.attitude.torques import GravityGradientTorque, gravity_gradient_torque
from astrodyn.rotation import dcm_from_quat, quat_from_axis_angle, quat_from_dcm, quat_rotate

MU = 3.986004418e14
A = 7.0e6
N = np.sqrt(MU / A**3)


def circular_orbit(t):
    """Circular orbit in the inertial XY plane (orbit normal +Z), radius A."""
    t = np.asarray(t, dtype=np.float64)
    return A * np.stack([np.cos(N * t), np.sin(N * t), np.zeros_like(t)], -1)


def test_torque_matches_point_mass_sum():
    # six point masses at +-d on the body axes (centre of mass at the origin)
    d = np.array([3.0, 5.0, 2.0])
    m = np.array([10.0, 4.0, 7.0])
    pts, ms = [], []
    for k in range(3):
        for sgn in (1.0, -1.0):
            p = np.zeros(3)
            p[k] = sgn * d[k]
            pts.append(p)
            ms.append(m[k])
    pts, ms = np.array(pts), np.array(ms)
    inertia = np.einsum("i,ij->ij", ms, np.sum(pts**2, 1)[:, None] * np.eye(3)[None, :, :].reshape(1, 9)).reshape(-1, 3, 3).sum(0) - np.einsum("i,ij,ik->jk", ms, pts, pts)
    rng = np.random.default_rng(3)
    for _ in range(5):
        r_b = rng.normal(size=3)
        r_b *= A / np.linalg.norm(r_b)
        rho = r_b + pts
        forces = -MU * ms[:, None] * rho / np.linalg.norm(rho, axis=1)[:, None] ** 3
        exact = np.sum(np.cross(pts, forces), axis=0)
        gg = gravity_gradient_torque(r_b, inertia, MU)
        # symmetric pairs cancel the odd terms: the next term is O((d/r)^2) ~ 1e-12;
        # the direct sum cancels to ~eps / (d/r) ~ 2e-10 relative
        np.testing.assert_allclose(exact, gg, rtol=0, atol=1e-8 * np.linalg.norm(gg))
    # the object form: C(q) turns the inertial position into body axes
    q = quat_from_axis_angle([1.0, 2.0, 0.5], 0.8)
    r_in = np.array([A, 0.0, 0.0])
    model = GravityGradientTorque(MU, lambda t: r_in, inertia)
    np.testing.assert_allclose(model(0.0, q), gravity_gradient_torque(quat_rotate(q, r_in), inertia, MU), rtol=1e-15, atol=0)


def lvlh_dcm(t):
    """C_LVLH(t): rows x = along-track, y = -orbit normal, z = nadir (inertial components)."""
    c, s = np.cos(N * t), np.sin(N * t)
    z = np.zeros_like(t)
    return np.stack([np.stack([-s, c, z], -1), np.stack([z, z, -np.ones_like(t)], -1), np.stack([-c, -s, z], -1)], -2)


@pytest.mark.parametrize("inertia", [(80.0, 100.0, 40.0), (60.0, 45.0, 20.0)])
def test_pitch_libration_frequency(inertia):
    # body x = roll (along-track), y = pitch (orbit normal, negative), z = yaw (nadir):
    # inertia = (Ix, Iy, Iz); pitch is stable for Ix > Iz with frequency sqrt(3 (Ix - Iz)/Iy) n
    Ix, Iy, Iz = inertia
    om = np.sqrt(3.0 * (Ix - Iz) / Iy) * N
    theta0 = 1e-3
    C0 = np.array([[np.cos(theta0), 0, -np.sin(theta0)], [0, 1, 0], [np.sin(theta0), 0, np.cos(theta0)]]) @ lvlh_dcm(np.array(0.0))
    w0 = np.array([0.0, -N, 0.0])  # LVLH turns at n about +Z = -y_body
    periods = 8
    t = np.arange(1, int(periods * 2 * np.pi / om / 10.0)) * 10.0
    gg = GravityGradientTorque(MU, circular_orbit, inertia)
    w, q, info = propagate_attitude(inertia, w0, quat_from_dcm(C0), t, torque=gg, method="split4", step=20.0)
    rel = dcm_from_quat(q) @ np.swapaxes(lvlh_dcm(t), -1, -2)  # = C_2(pitch)
    pitch = np.arctan2(-rel[:, 0, 2], rel[:, 0, 0])
    # planar motion: roll and yaw stay at round-off
    assert np.max(np.abs(rel[:, 1, [0, 2]])) < 1e-12
    s = np.sign(pitch)
    idx = np.nonzero(s[1:] != s[:-1])[0]
    tc = t[idx] - pitch[idx] * (t[idx + 1] - t[idx]) / (pitch[idx + 1] - pitch[idx])
    freq = np.pi * (len(tc) - 1) / (tc[-1] - tc[0])
    # amplitude correction ~ theta0^2 / 4 ~ 3e-7; linear interpolation of a sine sampled
    # at om * 10 s ~ 0.01 rad: crossing error ~1e-7 s; split4 at 20 s: error ~info
    assert abs(freq / om - 1.0) < 1e-5
    assert info["error_attitude"] < 1e-9


def test_gravity_gradient_kernel_matches_dop853_and_python_path():
    inertia = np.array([[80.0, 3.0, -2.0], [3.0, 100.0, 1.0], [-2.0, 1.0, 40.0]])
    gg = GravityGradientTorque(MU, circular_orbit, inertia)
    w0 = np.array([1e-3, -2e-3, 5e-4])
    q0 = quat_from_axis_angle([0.2, 1.0, -0.3], 0.5)
    t = np.array([1000.0, 2000.0])
    wr, qr, _ = propagate_attitude(inertia, w0, q0, t, torque=gg, method="dop853", rtol=1e-13, atol=1e-16)
    w1, q1, info1 = propagate_attitude(inertia, w0, q0, t, torque=gg, method="split4", step=5.0)
    w2, q2, info2 = propagate_attitude(inertia, w0, q0, t, torque=lambda tt, q, w: gg(tt, q, w), method="split4", step=5.0)
    assert info1["kernel"] and not info2["kernel"]
    np.testing.assert_allclose(w1, w2, rtol=0, atol=1e-15)  # same arithmetic up to merged kicks
    # rates ~1e-3 rad/s, step 5 s: split4 error ~1e-12 rad/s; DOP853 ~1e-13 relative
    np.testing.assert_allclose(w1, wr, rtol=0, atol=1e-11)
    np.testing.assert_allclose(q1 * np.sign(q1[:, :1] * qr[:, :1]), qr, rtol=0, atol=1e-9)


@pytest.mark.parametrize("ecc, step", [(0.0, 0.5), (0.6, 0.5), (0.6, 200.0)])
def test_kepler_orbit_in_kernel_matches_numpy_positions(ecc, step):
    # GravityGradientTorque.kepler evaluates r(t) inside the compiled kernel (exact
    # Lagrange coefficients at nodes + quintic Hermite, or exact at every kick when
    # the step is long); the reference run takes r(t) from astrodyn.orbit.propagate
    # through the Python-callable path (positions tabulated per chunk).
    from astrodyn.orbit import propagate

    inertia = np.array([80.0, 100.0, 40.0])
    rp = 7.0e6
    r0 = np.array([rp, 0.0, 0.0])
    v0 = np.array([0.0, np.sqrt(MU * (1 + ecc) / rp) * np.cos(0.3), np.sqrt(MU * (1 + ecc) / rp) * np.sin(0.3)])
    t0 = 123.0  # orbit state given at t = 123 s on the integrator's clock
    kep = GravityGradientTorque.kepler(MU, r0, v0, inertia, t0=t0)
    tab = GravityGradientTorque(MU, lambda t: propagate(r0, v0, np.asarray(t) - t0, MU)[0], inertia)
    w0 = np.array([1e-3, -2e-3, 5e-4])
    q0 = quat_from_axis_angle([0.2, 1.0, -0.3], 0.5)
    t = np.array([1000.0, 4000.0])
    w1, q1, i1 = propagate_attitude(inertia, w0, q0, t, torque=kep, method="split4", step=step, error_estimate=False)
    w2, q2, i2 = propagate_attitude(inertia, w0, q0, t, torque=tab, method="split4", step=step, error_estimate=False)
    assert i1["kernel"] and i2["kernel"]
    # positions agree to ~1e-15 relative (Kepler solves at the noise level, Hermite
    # truncation < 3e-19 |r|); over 8000 steps of rates ~1e-3 rad/s that moves w by
    # ~ 1e-15 * |tau| t / I ~ 1e-18 rad/s and the attitude by round-off (~1e-13)
    np.testing.assert_allclose(w1, w2, rtol=0, atol=1e-15)
    np.testing.assert_allclose(q1, q2, rtol=0, atol=1e-12)
    # the shifted model: the same torque on a clock starting 500 s later
    np.testing.assert_allclose(kep.shifted(500.0).position(np.array([100.0])), kep.position(np.array([600.0])), rtol=1e-15)


@pytest.mark.parametrize("ecc", [0.0, 0.6, 0.99])
def test_kernel_orbit_interpolation_against_propagate(ecc):
    # the kernel's orbit positions (exact Kepler nodes, quintic Hermite in power form
    # between them) against astrodyn.orbit.propagate at random times, both directions
    import math

    from astrodyn.attitude.integrators import _hermite_spacing, _orbit_position
    from astrodyn.jit import jit
    from astrodyn.orbit import propagate

    @jit
    def positions(orbit_rv, mu, t, nodes):
        out = np.empty((t.shape[0], 3))
        for i in range(t.shape[0]):
            out[i, 0], out[i, 1], out[i, 2] = _orbit_position(orbit_rv, mu, t[i], nodes)
        return out

    rp = 7.0e6
    vp = np.sqrt(MU * (1 + ecc) / rp)
    r0, v0, t0 = np.array([rp, 0.0, 0.0]), np.array([0.0, vp * np.cos(0.3), vp * np.sin(0.3)]), 50.0
    orbit_rv = np.zeros((3, 3))
    orbit_rv[0], orbit_rv[1], orbit_rv[2, 0] = r0, v0, -t0
    D = _hermite_spacing(r0, v0, MU, 0.01)
    nodes = np.zeros((9, 9))
    nodes[2, :3] = D, math.nan, 1.0 / D
    t = np.random.default_rng(5).uniform(-3000.0, 3000.0, 4000)
    t = np.concatenate([np.sort(t), np.sort(t)[::-1]])  # node pair moving forward, then backward
    got = positions(orbit_rv, MU, t, nodes)
    ref = propagate(r0, v0, t - t0, MU)[0]
    # nodes are exact Kepler states (each a few eps, as is the reference), Hermite
    # truncation < 3e-19 |r|, Horner rounding ~1 eps: measured <= 5.5 eps
    assert np.max(np.linalg.norm(got - ref, axis=1) / np.linalg.norm(ref, axis=1)) < 20 * 2.2e-16


@pytest.mark.parametrize("rotor", ["none", "constant", "varying"])
def test_kernel_with_every_torque_term_matches_python_path(rotor):
    # gravity gradient + body and inertial constant torques + uniform gravity on a
    # full inertia tensor, with rotors: the compiled kernel (body copies of r, the
    # inertial torque and the force formed once per stage and turned with M) against
    # the Python path (C(q) r rebuilt at every kick, numpy torque formulas)
    from astrodyn.attitude.torques import ConstantTorque, TorqueSum, UniformGravityTorque

    inertia = np.array([[80.0, 3.0, -2.0], [3.0, 100.0, 1.0], [-2.0, 1.0, 40.0]])
    tq = TorqueSum(
        GravityGradientTorque(MU, circular_orbit, inertia), ConstantTorque([1e-4, 0.0, -2e-4]),
        ConstantTorque([0.0, 3e-4, 1e-4], frame="inertial"), UniformGravityTorque(2.0, [0.0, 1e-3, 2e-3]),
    )
    h = {
        "none": None,
        "constant": np.array([0.1, -0.2, 0.3]),
        "varying": lambda t: np.stack([0.1 * np.sin(0.01 * np.asarray(t)), 0.2 + 0 * np.asarray(t), 1e-3 * np.asarray(t)], -1),
    }[rotor]
    w0 = np.array([1e-2, -2e-2, 5e-3])
    q0 = quat_from_axis_angle([0.2, 1.0, -0.3], 0.5)
    t = np.array([40.0, 80.0])
    w1, q1, i1 = propagate_attitude(inertia, w0, q0, t, torque=tq, rotor_momentum=h, method="split4", step=0.5, error_estimate=False)
    w2, q2, i2 = propagate_attitude(inertia, w0, q0, t, torque=lambda tt, q, w: tq(tt, q, w), rotor_momentum=h, method="split4", step=0.5, error_estimate=False)
    assert i1["kernel"] and not i2["kernel"]
    # same scheme, different rounding: 160 steps x 5 stages x ~6 rotations/kicks,
    # a random walk of ~1e-16 each -> ~5e-15 in q, ~2e-16 in w (|w| ~ 0.03 rad/s),
    # measured 3.1e-15 and 1.7e-16; the bounds allow ~100x
    np.testing.assert_allclose(q1, q2, rtol=0, atol=3e-13)
    np.testing.assert_allclose(w1, w2, rtol=0, atol=2e-14)


def test_a_position_following_the_documented_contract_works_with_every_method():
    """``position`` as the class docstring asks for it (a 1-D array of times in, ``(len(t), 3)``
    out; here it refuses anything else): the compiled splitting evaluates it at arrays of kick
    times, DOP853 and the Python torque path at one time (as a 1-element array).  All agree
    within the error they claim: split4's Richardson estimate, DOP853's tolerance."""
    from astrodyn.orbit import propagate

    r0, v0 = np.array([A, 0.0, 0.0]), np.array([0.0, 8.4e3, 1.0e3])  # an eccentric, inclined orbit

    def position(t):
        assert np.ndim(t) == 1, "the contract: a 1-D array of times"
        return propagate(r0, v0, t, MU)[0]

    inertia = np.array([[80.0, 3.0, -2.0], [3.0, 100.0, 1.0], [-2.0, 1.0, 40.0]])
    gg = GravityGradientTorque(MU, position, inertia)
    w0 = np.array([1e-3, -2e-3, 5e-4])
    q0 = quat_from_axis_angle([0.2, 1.0, -0.3], 0.5)
    t = np.array([100.0, 200.0])
    rtol = 1e-12
    wr, qr, _ = propagate_attitude(inertia, w0, q0, t, torque=gg, method="dop853", rtol=rtol, atol=1e-15)
    w1, q1, info = propagate_attitude(inertia, w0, q0, t, torque=gg, method="split4", step=5.0)
    w2, q2, info2 = propagate_attitude(inertia, w0, q0, t, torque=lambda tt, q, w: gg(tt, q, w), method="split4", step=5.0)
    assert info["kernel"] and not info2["kernel"]
    assert np.shape(gg(0.0, q0)) == (3,) and np.shape(gg(t, q0)) == (2, 3)
    # DOP853's global error: its tolerance per unit of the state (|w| ~ 2e-3 rad/s, |q| = 1), times a few
    tol_w = info["error_rate"] + 10 * rtol * np.linalg.norm(w0)
    tol_q = info["error_attitude"] + 10 * rtol
    np.testing.assert_allclose(w1, wr, rtol=0, atol=tol_w)
    np.testing.assert_allclose(q1 * np.sign(q1[:, :1] * qr[:, :1]), qr, rtol=0, atol=tol_q)
    np.testing.assert_allclose(w2, w1, rtol=0, atol=tol_w)
    np.testing.assert_allclose(q2, q1, rtol=0, atol=tol_q)
