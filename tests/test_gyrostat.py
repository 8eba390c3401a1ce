"""Gyrostats (astrodyn.attitude.gyrostat): spin stability with rotor momentum, driven rotors.

Stability is judged from simulated perturbation growth (splitting integrator),
independent of the closed-form condition (h + (I2 - I1) w)(h + (I2 - I3) w) > 0
it is compared with.  Driven rotors are checked against an independent
formulation of the coupled body + rotor equations integrated by scipy DOP853.
"""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from astrodyn.attitude.gyrostat import Gyrostat, spin_stability_product, spin_transverse_rate
from astrodyn.rotation import dcm_from_quat, quat_from_axis_angle, quat_rate

I_P = np.array([1.0, 2.0, 3.0])  # spin about axis 2 (index 1) is the intermediate one
SPIN = 1.0
ROTOR_I = 0.1
EPS = 1e-6


def transverse_history(h, t_end, n):
    body = Gyrostat(I_P, [[0.0, 1.0, 0.0]], [ROTOR_I])
    t = np.linspace(0.0, t_end, n + 1)[1:]
    # transverse perturbation (EPS, 0.3 EPS): generic (w1 = w3 would sit on the stable manifold for h = 0.5)
    w, q, speeds, _ = body.propagate([EPS, SPIN, 0.3 * EPS], [1.0, 0, 0, 0], t, rotor_speed=[h / ROTOR_I], step=0.02, error_estimate=False)
    return t, w


def test_stability_product_matches_rigid_body_rule():
    # h = 0: major and minor axes stable, intermediate unstable
    assert spin_stability_product(I_P, SPIN, 0.0, 0) > 0
    assert spin_stability_product(I_P, SPIN, 0.0, 2) > 0
    assert spin_stability_product(I_P, SPIN, 0.0, 1) < 0
    # threshold for axis 2: |h| > SPIN (I2 - I1 = 1, I3 - I2 = 1)
    assert spin_stability_product(I_P, SPIN, [0.99, 1.01], 1).tolist() == pytest.approx([-0.0199, 0.0201])


@pytest.mark.parametrize("h", [0.0, 0.5, 0.9])
def test_intermediate_axis_unstable_below_threshold(h):
    lam = spin_transverse_rate(I_P, SPIN, h, 1)
    assert spin_stability_product(I_P, SPIN, h, 1) < 0
    t, w = transverse_history(h, 14.0 / lam, 400)
    amp = np.hypot(w[:, 0], w[:, 2])
    # exponential growth at the predicted rate: fitted between 4/lam and 12/lam,
    # where the decaying mode is < e^-8 and the nonlinear terms < 1e-2 relative
    sel = (t > 4.0 / lam) & (t < 12.0 / lam)
    ln = np.log(np.sqrt(I_P[0] * w[sel, 0] ** 2 + I_P[2] * w[sel, 2] ** 2))
    # the transverse motion is elliptic with the growth; the weighted norm removes most of the ripple
    slope = np.polyfit(t[sel], ln, 1)[0]
    assert abs(slope / lam - 1.0) < 0.02
    assert np.max(amp) > 1e3 * EPS


@pytest.mark.parametrize("h", [1.2, 2.0, -1.5])
def test_intermediate_axis_stable_above_threshold(h):
    assert spin_stability_product(I_P, SPIN, h, 1) > 0
    om = spin_transverse_rate(I_P, SPIN, h, 1)
    t, w = transverse_history(h, 20 * 2 * np.pi / om, 4000)
    amp = np.hypot(w[:, 0], w[:, 2])
    # bounded: the linear ellipse's axis ratio is at most sqrt of a moment/product ratio ~ a few
    assert np.max(amp) < 10 * EPS
    # oscillation frequency from zero crossings of w1 (linear interpolation, 2e-3 period sampling)
    s = np.sign(w[:, 0])
    idx = np.nonzero(s[1:] != s[:-1])[0]
    tc = t[idx] - w[idx, 0] * (t[idx + 1] - t[idx]) / (w[idx + 1, 0] - w[idx, 0])
    freq = np.pi * (len(tc) - 1) / (tc[-1] - tc[0])
    assert abs(freq / om - 1.0) < 1e-4


def _coupled_reference(inertia, axis, rotor_i, w0, q0, t, motor_torque=None, rotor_speed0=None, speed_fn=None, speed_rate_fn=None):
    """Independent model: states (q, w, Omega); I w' + I_s a Omega' = -w x (I w + I_s Omega a), I_s (a.w' + Omega') = g."""
    I = np.diag(inertia)
    a = np.asarray(axis, float)

    def rhs(tt, y):
        q, w = y[:4], y[4:7]
        if speed_fn is None:
            om = y[7]
            H = I @ w + rotor_i * om * a
            # [[I, I_s a], [I_s a^T, I_s]] (w', Omega') = (-w x H, g)
            A = np.zeros((4, 4))
            A[:3, :3] = I
            A[:3, 3] = rotor_i * a
            A[3, :3] = rotor_i * a
            A[3, 3] = rotor_i
            sol = np.linalg.solve(A, np.concatenate([-np.cross(w, H), [motor_torque]]))
            return np.concatenate([quat_rate(q, w), sol])
        om, omd = speed_fn(tt), speed_rate_fn(tt)
        H = I @ w + rotor_i * om * a
        wd = np.linalg.solve(I, -np.cross(w, H) - rotor_i * omd * a)
        return np.concatenate([quat_rate(q, w), wd])

    y0 = np.concatenate([q0, w0] + ([[rotor_speed0]] if speed_fn is None else []))
    sol = solve_ivp(rhs, (0, t[-1]), y0, method="DOP853", t_eval=t, rtol=1e-13, atol=1e-15)
    return sol.y.T


def test_motor_torque_spin_up_against_coupled_model():
    body = Gyrostat(I_P, [[0.0, 0.0, 1.0]], [ROTOR_I])
    w0 = np.array([0.1, 0.2, 0.3])
    q0 = quat_from_axis_angle([1.0, 1.0, 0.0], 0.4)
    t = np.array([5.0, 10.0])
    w, q, speeds, info = body.propagate(w0, q0, t, motor_torque=[0.02], rotor_speed0=[3.0], step=0.01)
    ref = _coupled_reference(I_P, [0, 0, 1], ROTOR_I, w0, q0, t, motor_torque=0.02, rotor_speed0=3.0)
    # split4 at 0.01 s on rates ~0.3 rad/s: error ~1e-11 (info), reference ~1e-12
    np.testing.assert_allclose(w, ref[:, 4:7], atol=1e-9)
    np.testing.assert_allclose(speeds[:, 0], ref[:, 7], atol=1e-9)
    # internal torque: the inertial total angular momentum is conserved
    H = I_P * w + ROTOR_I * speeds[:, :1] * np.array([0.0, 0.0, 1.0])
    L = np.einsum("nji,nj->ni", dcm_from_quat(q), H)
    L0 = dcm_from_quat(q0).T @ (I_P * w0 + ROTOR_I * 3.0 * np.array([0.0, 0.0, 1.0]))
    np.testing.assert_allclose(L, np.broadcast_to(L0, L.shape), atol=1e-12)


def test_commanded_speed_profile_against_rate_form():
    axis = np.array([1.0, 1.0, 0.0]) / np.sqrt(2.0)
    body = Gyrostat(I_P, [axis], [ROTOR_I])

    def speed(tt):
        return 2.0 + np.sin(0.7 * np.asarray(tt))

    def speed_rate(tt):
        return 0.7 * np.cos(0.7 * np.asarray(tt))

    w0 = np.array([0.2, -0.1, 0.4])
    q0 = np.array([1.0, 0.0, 0.0, 0.0])
    t = np.array([6.0, 12.0])
    w, q, speeds, _ = body.propagate(w0, q0, t, rotor_speed=lambda tt: speed(tt)[..., None], step=0.01)
    ref = _coupled_reference(I_P, axis, ROTOR_I, w0, q0, t, speed_fn=speed, speed_rate_fn=speed_rate)
    np.testing.assert_allclose(w, ref[:, 4:7], atol=1e-9)
    np.testing.assert_allclose(speeds[:, 0], speed(t))


def test_bad_rotor_arguments():
    body = Gyrostat(I_P, [[0.0, 0.0, 1.0]], [ROTOR_I])
    with pytest.raises(ValueError, match="exactly one"):
        body.propagate([0, 0, 1.0], [1.0, 0, 0, 0], [1.0])
    with pytest.raises(ValueError, match="rotor_speed0"):
        body.propagate([0, 0, 1.0], [1.0, 0, 0, 0], [1.0], motor_torque=[0.1])
    with pytest.raises(ValueError, match="rotor_inertia"):
        Gyrostat(I_P, [[0.0, 0.0, 1.0]], [-1.0])
