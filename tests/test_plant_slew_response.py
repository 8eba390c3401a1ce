"""A small-angle PD slew through the plant (astrodyn.plant) against linear theory.

Three reaction wheels along the principal axes, the body turned by theta0 about z, the
controller of examples/slew_pd.py in the test (u = -K e_z - C w_z from the error
quaternion, wheel torque g = -u, held for each control step).  About a principal axis
with w along it, Euler's equations are exactly linear: I_kin theta'' = u (I_kin = I_z - J,
the wheel's axial moment moves with the wheel), so

* with the controller's own law u_k = -K sin(theta_k / 2) - C theta'_k, the exact
  zero-order-hold recursion x_{k+1} = [[1, dt], [0, 1]] x_k + [dt^2 / 2, dt] u_k / I_kin
  is the answer; the plant's splitting integrates a body rate linear in time exactly, so
  they agree to round-off;
* the small-angle law u = -K theta / 2 - C theta' makes a second-order system with
  omega_n = sqrt(K / (2 I_kin)) and zeta = C / (2 sqrt(K I_kin / 2)); its overshoot
  exp(-zeta pi / sqrt(1 - zeta^2)) holds for the sampled loop within the hold's delay of
  dt / 2, which lowers the effective damping by about omega_n dt / 2 (here 0.008, so the
  overshoot moves by about pi dzeta / (1 - zeta^2)^1.5 x overshoot = 0.011).
"""

from __future__ import annotations

import math

import numpy as np

from _scenes import wheel_tables
from astrodyn.plant import Plant
from astrodyn.scenario import loads

K, C, DT, THETA0, I_Z, J = 4.0, 7.59, 0.1, 1e-3, 80.0, 0.05
SCENE = f"""
[scenario]
name = "pd"
epoch = "2026-03-20T12:00:00 UTC"
duration = "60 s"
rate = "10 Hz"
[control]
[[bodies]]
name = "sc"
[bodies.attitude]
q = [{math.cos(THETA0 / 2)!r}, 0, 0, {math.sin(THETA0 / 2)!r}]
inertia = [100, 120, {I_Z}]
[bodies.actuators]
""" + wheel_tables([[1, 0, 0], [0, 1, 0], [0, 0, 1]], J, 10, 1e4)


def _simulate(n: int):
    plant = Plant(loads(SCENE))
    b = plant.bodies["sc"]
    theta, rate = [], []
    for k in range(n):
        q, w = b.q, b.w
        theta.append(2.0 * math.atan2(q[3], q[0]))
        rate.append(w[2])
        u = [-K * q[i + 1] * (1.0 if q[0] >= 0 else -1.0) - C * w[i] for i in range(3)]
        b.begin_step()
        b.apply({"t": k * DT, "seq": k, "sender": "pd", "wheel_torque": [-x for x in u]})
        b.finish_commands()
        b.advance(DT)
    return np.array(theta), np.array(rate)


def _recursion(n: int, law):
    i_kin = I_Z - J
    x = np.array([THETA0, 0.0])
    out = []
    for _ in range(n):
        out.append(x.copy())
        u = law(x)
        x = np.array([x[0] + DT * x[1] + 0.5 * DT * DT * u / i_kin, x[1] + DT * u / i_kin])
    return np.array(out)


def test_the_plant_matches_the_exact_sampled_recursion_to_round_off():
    theta, rate = _simulate(600)
    ref = _recursion(600, lambda x: -K * math.sin(x[0] / 2) - C * x[1])
    # round-off: a few ulps of theta0 per step, 600 steps
    assert np.max(np.abs(theta - ref[:, 0])) < 600 * 10 * np.finfo(float).eps * THETA0
    assert np.max(np.abs(rate - ref[:, 1])) < 600 * 10 * np.finfo(float).eps * THETA0


def test_the_overshoot_is_the_second_order_systems():
    theta, _ = _simulate(600)
    i_kin = I_Z - J
    zeta = C / (2.0 * math.sqrt(K * i_kin / 2.0))
    expected = math.exp(-zeta * math.pi / math.sqrt(1.0 - zeta * zeta))  # 0.37 for zeta 0.30
    overshoot = -np.min(theta) / THETA0
    assert abs(overshoot - expected) < 0.02  # twice the hold's estimated effect (module docstring)
    # and the small-angle linear law's recursion is the same curve to the neglected theta^2 / 24
    linear = _recursion(600, lambda x: -K * x[0] / 2 - C * x[1])
    assert np.max(np.abs(theta - linear[:, 0])) < 10 * THETA0 ** 3 / 24
