"""Finite burns and impulses through the plant's command path (astrodyn.plant), against
Tsiolkovsky's rocket equation and the frame convention v_body = C(q) v_inertial.

Free space: a central body of the smallest allowed mu (1e-3 m^3/s^2) and the spacecraft
1e15 m away, so gravity changes v by ~1e-36 m/s over the burn, far below the checks."""

from __future__ import annotations

import math

import numpy as np
import pytest

from astrodyn.orbit.maneuvers import G0
from astrodyn.plant import Plant
from astrodyn.scenario import loads

SCENE = """
[scenario]
name = "burn"
epoch = "2026-03-20T12:00:00 UTC"
duration = "100 s"
rate = "1 Hz"
[central_body]
name = "point"
mu = 1e-3
radius = 1
[control]
[[bodies]]
name = "sc"
[bodies.orbit]
r = [1e15, 0, 0]
v = [0, 0, 0]
[bodies.attitude]
euler = ["90 deg", 0, 0]
seq = "321"
inertia = [10, 10, 10]
[bodies.actuators]
thrust = "20 N"
isp = "300 s"
mass = "500 kg"
dv = "10 m/s"
"""


def _plant():
    plant = Plant(loads(SCENE))
    return plant, plant.bodies["sc"]


@pytest.mark.parametrize("frame, axis", [("inertial", 0), ("body", 1)])
def test_a_constant_thrust_gives_tsiolkovskys_dv_along_the_commanded_axis(frame, axis):
    plant, b = _plant()
    b.apply({"t": 0.0, "seq": 0, "sender": "c", "thrust": [20.0, 0.0, 0.0], "frame": frame})
    for _ in range(60):
        b.begin_step()
        b.finish_commands()
        b.advance(1.0)
    mdot = 20.0 / (300.0 * G0)
    m1 = 500.0 - 60.0 * mdot
    dv = 300.0 * G0 * math.log(500.0 / m1)  # Tsiolkovsky
    # body frame: q is 90 deg about z (3-2-1 yaw), so body x is inertial +y (C^T e_x = e_y)
    expected = np.zeros(3)
    expected[axis] = dv
    assert b.mass == pytest.approx(m1, rel=1e-14)
    # DOP853 at rtol 1e-13 on a 60 s arc: the integration error is ~1e-13 relative
    np.testing.assert_allclose(b.v, expected, rtol=0, atol=1e-10 * dv)
    assert b.dv_total == pytest.approx(dv, rel=1e-13)  # 60 steps of log1p at round-off (a log of m0/m1 lost 1e-12)


def test_thrust_and_dv_are_limited_and_the_efficiency_fault_scales_them():
    plant, b = _plant()
    b.apply({"t": 0.0, "seq": 0, "sender": "c", "dv": [30.0, 40.0, 0.0]})  # |dv| 50 > 10: scaled to the limit
    np.testing.assert_allclose(b.v, [6.0, 8.0, 0.0], rtol=1e-15)
    b.apply({"t": 0.0, "seq": 1, "sender": "c", "thrust": [0.0, 0.0, 40.0]})  # 40 N > 20 N: scaled
    assert np.linalg.norm(b.thrust) == pytest.approx(20.0, rel=1e-15)
    b.faults.efficiency = 0.5  # what the thruster_efficiency fault sets
    v0 = b.v.copy()
    b.apply({"t": 1.0, "seq": 2, "sender": "c", "dv": [0.0, 0.0, 4.0]})
    np.testing.assert_allclose(b.v - v0, [0.0, 0.0, 2.0], rtol=1e-15)


def _wheel(axis: str, speed: str) -> str:
    """A ``[[bodies.actuators.wheels]]`` entry: ``axis`` in body components, rotor 0.05 kg m^2, 0.2 N m and
    600 rad/s at most, the initial ``speed`` (a quantity)."""
    return f"""[[bodies.actuators.wheels]]
axis = {axis}
inertia = 0.05
max_torque = 0.2
max_speed = 600
speed = "{speed}"
"""


WHEELED = """
[scenario]
name = "seize"
epoch = "2026-03-20T12:00:00 UTC"
duration = "100 s"
rate = "10 Hz"
[control]
[[control.faults]]
t = "2 s"
body = "sc"
fault = "wheel_stuck"
wheel = 1
[[bodies]]
name = "sc"
[bodies.attitude]
w = [0.01, -0.02, 0.03]
inertia = [[120, 2, -1], [2, 100, 0.5], [-1, 0.5, 80]]
[bodies.actuators]
""" + _wheel("[1, 0, 0]", "300 rpm") + _wheel("[0, 0.6, 0.8]", "-2000 rpm")


def test_a_seized_wheel_hands_its_momentum_to_the_body_and_the_total_is_kept():
    """The rotor seizes at 2 s: an internal event, so the inertial angular momentum of body
    plus wheels, C^T (I_kin w + sum h_k a_k), stays what it was, to round-off, across the
    seizure and after it while the other wheel keeps being torqued; the seized wheel's
    speed relative to the body is 0 from then on."""
    from astrodyn.rotation import dcm_from_quat

    plant = Plant(loads(WHEELED))
    b = plant.bodies["sc"]
    i_kin = b.wheels.kinematic_inertia(b.inertia)

    def total():
        return dcm_from_quat(b.q).T @ (i_kin @ b.w + b.h @ b.wheels.axes)

    H0 = total()
    w_before = None
    for k in range(300):
        plant.faults_at(k * 0.1)
        if k == 19:
            w_before = b.w.copy()
        b.begin_step()
        b.apply({"t": k * 0.1, "seq": k, "sender": "c", "wheel_torque": [0.05 * math.sin(0.3 * k), 0.1]})
        b.finish_commands()
        b.advance(0.1)
        # the momentum is ~0.3 N m s here; 300 steps of a few roundings each
        assert np.linalg.norm(total() - H0) < 300 * 10 * np.finfo(float).eps * np.linalg.norm(H0), k
    assert abs(b.wheel_speeds()[1]) < 1e-12 * 2000 * 2 * math.pi / 60  # locked: no relative speed
    assert np.linalg.norm(b.w - w_before) > 1e-3  # the seizure moved the wheel's momentum into the body
    assert b.applied_wheel[1] == 0.0 and b.applied_wheel[0] != 0.0


def test_commands_for_actuators_a_body_lacks_are_refused_with_the_reason():
    from astrodyn.plant import CommandRefused

    plant, b = _plant()  # thrust and dv, no torque, no wheels
    with pytest.raises(CommandRefused, match="has no torque actuator"):
        b.apply({"t": 0.0, "seq": 0, "sender": "c", "torque": [0.1, 0.0, 0.0]})
    with pytest.raises(CommandRefused, match="has no reaction wheels"):
        b.apply({"t": 0.0, "seq": 1, "sender": "c", "wheel_torque": [0.1]})
    wheeled = Plant(loads(WHEELED)).bodies["sc"]
    with pytest.raises(CommandRefused, match=r"wheel_torque: expected 2 values \(one per wheel\), got 3"):
        wheeled.apply({"t": 0.0, "seq": 0, "sender": "c", "wheel_torque": [0.1, 0.0, 0.0]})
    with pytest.raises(CommandRefused, match="no impulsive dv capability"):
        wheeled.apply({"t": 0.0, "seq": 1, "sender": "c", "dv": [1.0, 0.0, 0.0]})
    assert np.all(wheeled.wheel_command == 0.0)  # nothing of a refused command was applied


def test_overflowing_command_values_leave_a_finite_state():
    """A controller of the run may still send nonsense: values near the float64 limit are
    clipped or scaled to the actuators' limits, and nothing becomes inf or NaN."""
    plant, b = _plant()
    big = 1.7e308
    b.apply({"t": 0.0, "seq": 0, "sender": "c", "dv": [big, big, -big]})  # |dv| overflows to inf
    b.apply({"t": 0.0, "seq": 1, "sender": "c", "thrust": [big, 0.0, big], "frame": "body"})
    for _ in range(3):
        b.begin_step()
        b.finish_commands()
        b.advance(1.0)
    assert np.all(np.isfinite(b.v)) and np.all(np.isfinite(b.r)) and np.isfinite(b.mass)
    assert np.linalg.norm(b.thrust) == pytest.approx(20.0, rel=1e-15)
    # the impulse was scaled to the 10 m/s limit along its own direction, not to nothing
    assert b.dv_total >= 10.0 * (1 - 1e-15)
    wheeled = Plant(loads(WHEELED)).bodies["sc"]
    wheeled.apply({"t": 0.0, "seq": 0, "sender": "c", "wheel_torque": [big, -big]})
    wheeled.begin_step()
    wheeled.finish_commands()
    wheeled.advance(0.1)
    assert np.all(np.abs(wheeled.applied_wheel) <= 0.2) and np.all(np.isfinite(wheeled.w))
