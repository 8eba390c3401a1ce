"""Euler's equations (astrodyn.attitude.euler): component form, full tensor, gyrostat form.

References are independent of the code under test: the component form of Euler's
equations written out by hand (Baruh eq. 8.5x), a rotation of the whole problem
(the tensor form must be covariant), and finite differences of the DCM.
"""

import numpy as np
import pytest

from astrodyn.attitude.euler import (
    angular_acceleration,
    attitude_state_rates,
    body_momentum_rates,
    inertia_tensor,
    principal_axes,
)
from astrodyn.rotation import dcm_from_quat, quat_from_axis_angle

RNG = np.random.default_rng(7)
I_P = np.array([1.2, 2.3, 3.1])


def _rotation(axis, angle):
    return dcm_from_quat(quat_from_axis_angle(axis, angle))


def test_principal_form_matches_component_equations():
    w = RNG.normal(size=(50, 3))
    tau = RNG.normal(size=(50, 3))
    I1, I2, I3 = I_P
    wd = angular_acceleration(I_P, w, tau)
    ref = np.stack(
        [
            ((I2 - I3) * w[:, 1] * w[:, 2] + tau[:, 0]) / I1,
            ((I3 - I1) * w[:, 2] * w[:, 0] + tau[:, 1]) / I2,
            ((I1 - I2) * w[:, 0] * w[:, 1] + tau[:, 2]) / I3,
        ],
        -1,
    )
    # a few flops of O(1) numbers: 1e-14 is ~100 ulp
    np.testing.assert_allclose(wd, ref, rtol=0, atol=1e-14)


def test_full_tensor_is_covariant_under_rotation():
    R = _rotation([0.3, -1.0, 0.4], 0.9)  # v_principal = R v_body
    J = R.T @ np.diag(I_P) @ R
    w_p = RNG.normal(size=(20, 3))
    tau_p = RNG.normal(size=(20, 3))
    h_p = RNG.normal(size=(20, 3))
    wd_body = angular_acceleration(J, w_p @ R, tau_p @ R, h_p @ R)
    wd_p = angular_acceleration(I_P, w_p, tau_p, h_p)
    # R has ~1 ulp errors; the inverse of J has condition number I3/I1 ~ 2.6
    np.testing.assert_allclose(wd_body @ R.T, wd_p, rtol=0, atol=1e-13)
    m, P = principal_axes(J)
    assert np.linalg.det(P) > 0
    np.testing.assert_allclose(P @ np.diag(m) @ P.T, J, atol=1e-14)
    np.testing.assert_allclose(np.sort(m), I_P, atol=1e-14)


def test_gyrostat_rate_form_agrees_with_momentum_form():
    # d/dt (I w + h) = H'  (Euler's equations of the gyrostat, both forms)
    w = RNG.normal(size=(10, 3))
    h = RNG.normal(size=(10, 3))
    hd = RNG.normal(size=(10, 3))
    tau = RNG.normal(size=(10, 3))
    wd = angular_acceleration(I_P, w, tau, h, hd)
    Hd, w_back = body_momentum_rates(I_P, I_P * w + h, tau, h)
    np.testing.assert_allclose(w_back, w, atol=1e-14)
    np.testing.assert_allclose(I_P * wd + hd, Hd, atol=1e-13)


def test_state_form_quaternion_rates_match_dcm_kinematics():
    # dC/dt = -[w x] C (docs/architecture.md) checked by a central difference of C(q(t))
    q = quat_from_axis_angle([1.0, 2.0, -0.5], 1.3)
    w = np.array([0.4, -0.2, 0.9])
    x = np.concatenate([q, w])
    d = attitude_state_rates(0.0, x, I_P)
    eps = 1e-6
    Cp = dcm_from_quat(q + eps * d[:4])
    Cm = dcm_from_quat(q - eps * d[:4])
    Cdot = (Cp - Cm) / (2 * eps)
    wx = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
    # central difference error ~ eps^2 |q'''| ~ 1e-12, round-off ~ 1e-16/eps = 1e-10
    np.testing.assert_allclose(Cdot, -wx @ dcm_from_quat(q), atol=1e-9)
    np.testing.assert_allclose(d[4:], angular_acceleration(I_P, w), atol=1e-15)


@pytest.mark.parametrize(
    "bad, msg",
    [
        ([1.0, 2.0], "inertia"),
        ([1.0, 1.0, 3.0], "triangle"),
        ([1.0, -1.0, 1.0], "positive"),
        ([[1.0, 0.1, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], "symmetric"),
        ([1.0, np.nan, 1.0], "finite"),
    ],
)
def test_bad_inertia_is_rejected(bad, msg):
    with pytest.raises(ValueError, match=msg):
        inertia_tensor(bad)


def test_nan_rates_give_nan():
    # w1 = NaN reaches w2' and w3' (w1' = (I2 - I3) w2 w3 / I1 does not involve w1)
    wd = angular_acceleration(I_P, [np.nan, 0.0, 1.0])
    assert np.isnan(wd[1]) and np.isnan(wd[2]) and wd[0] == 0.0
