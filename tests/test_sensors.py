"""Sensor models (astrodyn.sensors): statistics against their distributions, reproducibility.

The bounds are confidence intervals of the sample statistics (N samples): a mean within
5 standard errors ``5 sigma / sqrt(N)``, a standard deviation within 5 ``sigma /
sqrt(2 N)`` -- a false failure about once in 10^6 runs, and fixed seeds make each run the
same anyway.  The star tracker's error angle is checked against the chi distribution of
3 degrees of freedom (mean ``2 sigma sqrt(2/pi)``, variance ``sigma^2 (3 - 8/pi)``).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from astrodyn.rotation import quat_conjugate, quat_from_euler, quat_multiply, rotvec_from_quat
from astrodyn.sensors import PositionReceiver, RateGyro, StarTracker, WheelTachometer

N = 20_000


def test_rate_gyro_bias_and_noise():
    gyro = RateGyro(sigma=1e-4, bias=(2e-4, -1e-4, 0.0), seed=11)
    w = np.array([0.1, -0.2, 0.3])
    err = np.array([gyro.sample(w, k) for k in range(N)]) - w
    assert np.all(np.abs(err.mean(axis=0) - gyro.bias) < 5 * 1e-4 / math.sqrt(N))
    assert np.all(np.abs(err.std(axis=0) - 1e-4) < 5 * 1e-4 / math.sqrt(2 * N))
    # independent axes
    c = np.corrcoef(err.T)
    assert np.all(np.abs(c[np.triu_indices(3, 1)]) < 5 / math.sqrt(N))


def test_samples_are_reproducible_and_order_free():
    gyro = RateGyro(sigma=1e-3, seed=5)
    forward = [gyro.sample(np.zeros(3), k) for k in range(50)]
    backward = [gyro.sample(np.zeros(3), k) for k in reversed(range(50))][::-1]
    assert all(np.array_equal(a, b) for a, b in zip(forward, backward))
    assert not np.array_equal(RateGyro(sigma=1e-3, seed=6).sample(np.zeros(3), 0), forward[0])
    # another sensor with the same seed draws another stream
    assert not np.array_equal(WheelTachometer(sigma=1e-3, seed=5).sample(np.zeros(3), 0), forward[0])


def test_star_tracker_error_angle_follows_chi_3():
    sigma = 1e-4
    st = StarTracker(sigma=sigma, seed=3)
    q = quat_from_euler([0.4, -0.3, 2.0], "321")
    meas = np.array([st.sample(q, k) for k in range(N)])
    assert np.all(meas[:, 0] >= 0) and np.all(np.abs(np.linalg.norm(meas, axis=1) - 1) < 1e-15)
    d = rotvec_from_quat(quat_multiply(meas, quat_conjugate(q)))  # C(d) = C(meas) C(q)^T
    angle = np.linalg.norm(d, axis=1)
    mean, var = 2 * sigma * math.sqrt(2 / math.pi), sigma**2 * (3 - 8 / math.pi)
    assert abs(angle.mean() - mean) < 5 * math.sqrt(var / N)
    # the body-axis components are N(0, sigma^2) each
    assert np.all(np.abs(d.std(axis=0) - sigma) < 5 * sigma / math.sqrt(2 * N))


def test_position_receiver_and_dropout():
    rx = PositionReceiver(sigma_r=5.0, sigma_v=0.05, seed=1)
    r, v = np.array([7e6, 0, 0]), np.array([0, 7.5e3, 0])
    samples = [rx.sample(r, v, k) for k in range(N)]
    er = np.array([s[0] for s in samples]) - r
    ev = np.array([s[1] for s in samples]) - v
    assert np.all(np.abs(er.std(axis=0) - 5.0) < 5 * 5.0 / math.sqrt(2 * N))
    assert np.all(np.abs(ev.std(axis=0) - 0.05) < 5 * 0.05 / math.sqrt(2 * N))
    assert PositionReceiver(5.0, 0.05, dropout=True).sample(r, v, 0) is None


def test_bad_parameters_name_the_field():
    with pytest.raises(ValueError, match="sigma"):
        RateGyro(sigma=-1.0)
    with pytest.raises(ValueError, match="bias"):
        RateGyro(sigma=1.0, bias=(np.nan, 0, 0))
    with pytest.raises(ValueError, match="step"):
        StarTracker(1e-4).sample([1.0, 0, 0, 0], -1)
