"""The closed loop's dynamic gyro sensor: ``gyro = { ..., dynamics = {...} }`` in a body's
sensors makes the gyro three single-axis rate gyros (Baruh 10.7.3) along the body axes,
their gimbals driven by the body's rate step by step, the sample their indications.

References, independent of the plant: a spherical body under a constant torque turns at
exactly w(t) = w0 + alpha t (alpha = tau / I); a damped second-order instrument on a ramp
input lags it by 2 zeta alpha / omega_n once its transient has died (linear theory), and a
gyro whose output axis accelerates at alpha reads -J2 alpha / H (the output-axis term of the
instrument equation); and one DOP853 integration of each gimbal over the whole span on the
exact w(t), not step by step.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

from astrodyn.attitude import gyroscopes as gy
from astrodyn.plant import Plant
from astrodyn.scenario import loads

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _config_text import assert_config_error, edited

C, A, SPIN = 1e-4, 6e-5, 24000 * 2 * math.pi / 60
H = C * SPIN
WN, ZETA = 2 * math.pi * 30, 0.7
K = WN * WN * A
I_BODY, TAU = 100.0, 0.2  # kg m^2 (spherical), N m about body x: alpha = 2e-3 rad/s^2

SCENE = f"""
[scenario]
name = "gyro-dyn"
epoch = "2026-01-01T00:00:00 UTC"
duration = "4 s"
rate = "10 Hz"

[control]
mode = "lockstep"
period = "0.1 s"
controllers = []
seed = 3

[[bodies]]
name = "sc"
[bodies.attitude]
inertia = [{I_BODY}, {I_BODY}, {I_BODY}]
w = ["0.01 rad/s", "0 rad/s", "0 rad/s"]
[bodies.actuators]
torque = "1 N m"
[bodies.sensors]
gyro = {{ sigma = "0 rad/s", dynamics = {{ natural_frequency = "30 Hz", damping_ratio = 0.7, spin_rate = "24000 rpm", spin_inertia = "1e-4 kg m2", transverse_inertia = "6e-5 kg m2" }} }}
"""


def _samples():
    plant = Plant(loads(SCENE))
    b = plant.bodies["sc"]
    out, ts = [], []
    for k in range(40):
        t = 0.1 * k
        (kind, names, fields), = plant.sensor_samples(k, t)
        out.append(fields["w"][0].copy())
        ts.append(t)
        plant.begin_step()
        b.apply({"t": t, "seq": k, "sender": "x", "torque": [TAU, 0.0, 0.0]})
        b.finish_commands()
        plant.advance([b], 0.1)
    return np.array(ts), np.array(out), b


def test_the_gimbals_follow_a_ramp_as_the_instrument_equation_says():
    t, w_meas, b = _samples()
    alpha = TAU / I_BODY
    w_true = 0.01 + alpha * t
    settled = t >= 0.3  # the transient decays as exp(-zeta omega_n t): e^-40 by 0.3 s
    # gyro x: the ramp, lagged by 2 zeta alpha / omega_n (linear theory); what linear theory
    # leaves out is the gimbal's tilt of the input axis, w (1 - cos theta) ~ w theta^2 / 2 with
    # theta ~ H w / k ~ 2e-3 rad (4e-8 rad/s here)
    lag = 2 * ZETA * alpha / WN
    theta_max = H * np.max(w_true) / K
    assert np.max(np.abs(w_meas[settled, 0] - (w_true[settled] - lag))) <= 1e-3 * lag + np.max(w_true) * theta_max**2
    # gyro y (no input, spin reference axis x): nothing; gyro z (input z, output x accelerating
    # at alpha): k theta = -J2 alpha, so it reads -J2 alpha / H
    assert np.max(np.abs(w_meas[:, 1])) <= 1e-12
    assert np.max(np.abs(w_meas[settled, 2] - (-A * alpha / H))) <= 1e-3 * A * alpha / H
    # the true rate is the exact ramp (spherical body, constant torque)
    assert abs(b.w[0] - (0.01 + alpha * 4.0)) <= 1e-12


def test_step_by_step_equals_one_integration_on_the_exact_rate():
    t, w_meas, _ = _samples()
    alpha = TAU / I_BODY
    rate = gy.SingleAxisGyro.rate_gyro(C, A, SPIN, K, 2 * ZETA * math.sqrt(K * A))

    def base(s):  # gyro x: case axes = body axes
        return np.array([0.01 + alpha * s, 0.0, 0.0]), np.array([alpha, 0.0, 0.0])

    theta0 = gy.steady_state_angle(rate, [0.01, 0.0, 0.0])
    ref, _ = gy.propagate_single_axis(rate, base, t, theta0=theta0, rtol=1e-12, atol=1e-15)
    assert np.max(np.abs(w_meas[:, 0] - K * ref[:, 0] / H)) <= 1e-8 * np.max(np.abs(w_meas[:, 0]))


def test_dynamics_tables_are_checked_naming_the_field():
    assert_config_error(edited(SCENE, **{'natural_frequency = "30 Hz"': 'natural_frequency = "-1 Hz"'}),
                        "sensors.gyro.dynamics[0].natural_frequency", "> 0")
    assert_config_error(edited(SCENE, **{'dynamics = {': 'dynamics = { type = "rate", '}),
                        "sensors.gyro.dynamics.type", "no type (three rate gyros along the body axes)")
    assert_config_error(edited(SCENE, **{'spin_rate = "24000 rpm", ': ''}), "sensors.gyro.dynamics[0].spin_rate",
                        "a value")
    bad = SCENE.replace('dynamics = { natural_frequency = "30 Hz", damping_ratio = 0.7, spin_rate = "24000 rpm", '
                        'spin_inertia = "1e-4 kg m2", transverse_inertia = "6e-5 kg m2" }', 'dynamics = 3')
    assert_config_error(bad, "sensors.gyro.dynamics", "a table of the rate gyros' rotor and gimbal")


def test_an_ideal_gyro_still_reads_the_true_rate():
    ideal = SCENE.replace(', dynamics = { natural_frequency = "30 Hz", damping_ratio = 0.7, spin_rate = "24000 rpm", '
                          'spin_inertia = "1e-4 kg m2", transverse_inertia = "6e-5 kg m2" }', "")
    plant = Plant(loads(ideal))
    (_, _, fields), = plant.sensor_samples(0, 0.0)
    assert fields["w"][0].tolist() == [0.01, 0.0, 0.0]
