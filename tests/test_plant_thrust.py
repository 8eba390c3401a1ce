"""Finite burns and impulses through the plant's command path (astrodyn.plant), against
Tsiolkovsky's rocket equation and the frame convention v_body = C(q) v_inertial.

Free space: a central body of the smallest allowed mu (1e-3 m^3/s^2) and the spacecraft
1e15 m away, so gravity changes v by ~1e-36 m/s over the burn, far below the checks.

A body-axis thrust on a spinning body turns with it through each step: for a pure spin
``w = (0, 0, wz)`` about a principal axis, body x is ``(cos wz t, sin wz t, 0)`` in
inertial axes, so ``dv = integral F / m(t) (cos wz t, sin wz t, 0) dt``: ``(F/m) (sin wz T,
1 - cos wz T, 0) / wz`` at constant mass; with the mass falling at ``mdot`` (``m(t) = mdot
(tb - t)``, ``tb = m0 / mdot``) ``dv_x + i dv_y = (F/mdot) e^(i wz tb) [(Ci(x0) - Ci(x1)) -
i (Si(x0) - Si(x1))]``, ``x0 = wz tb``, ``x1 = wz (tb - T)`` (substitute ``s = tb - t``:
``integral e^(-i wz s) / s ds = Ci(wz s) - i Si(wz s)``)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from _recordings import scenario_head
from _scenes import fault_table, tumbling_sc, wheel_tables
from astrodyn.orbit.maneuvers import G0, ConstantThrust, RotatingThrust
from astrodyn.plant import Plant
from astrodyn.rotation import dcm_from_quat
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


def test_an_impulsive_dv_spends_propellant_by_the_rocket_equation_and_later_burns_feel_it():
    """An impulse is a burn too short to resolve: with ``mass`` and ``isp`` it spends
    m0 (1 - exp(-|dv| / (isp g0))) of propellant (Tsiolkovsky).  Before, the mass stayed at
    500 kg after dv, so every later finite burn accelerated at F / m0 (closed-loop probe)."""
    plant, b = _plant()
    b.apply({"t": 0.0, "seq": 0, "sender": "c", "dv": [6.0, 8.0, 0.0]})  # |dv| = 10 m/s
    m1 = 500.0 * math.exp(-10.0 / (300.0 * G0))
    assert b.mass == pytest.approx(m1, rel=1e-15)
    b.apply({"t": 0.0, "seq": 1, "sender": "c", "dv": [0.0, 0.0, 10.0]})
    assert b.mass == pytest.approx(500.0 * math.exp(-20.0 / (300.0 * G0)), rel=1e-15)  # dv adds: exp multiplies
    m2 = b.mass
    v0 = b.v.copy()
    b.apply({"t": 0.0, "seq": 2, "sender": "c", "thrust": [20.0, 0.0, 0.0]})
    for _ in range(10):
        b.begin_step()
        b.finish_commands()
        b.advance(1.0)
    mdot = 20.0 / (300.0 * G0)
    assert b.mass == pytest.approx(m2 - 10.0 * mdot, rel=1e-14)
    assert b.v[0] - v0[0] == pytest.approx(300.0 * G0 * math.log(m2 / (m2 - 10.0 * mdot)), rel=1e-10)
    assert b.dv_total == pytest.approx(20.0 + 300.0 * G0 * math.log(m2 / (m2 - 10.0 * mdot)), rel=1e-13)


def test_an_impulsive_dv_without_isp_keeps_the_mass():
    plant = Plant(loads(SCENE.replace('isp = "300 s"\n', "")))
    b = plant.bodies["sc"]
    b.apply({"t": 0.0, "seq": 0, "sender": "c", "dv": [6.0, 8.0, 0.0]})
    assert b.mass == 500.0 and b.dv_total == pytest.approx(10.0, rel=1e-15)


#: Two wheels (rotor 0.05 kg m^2, 0.2 N m and 600 rad/s at most) turning at 300 and -2000 rpm;
#: the second seizes at 2 s.
WHEELED = scenario_head("seize", "100 s", "10 Hz") + "[control]\n" + fault_table("2 s", "wheel_stuck", wheel=1) \
    + tumbling_sc(wheel_tables([[1, 0, 0], [0, 0.6, 0.8]], 0.05, 0.2, 600, speeds=["300 rpm", "-2000 rpm"]))


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


RTOL = 1e-13  # the plant's DOP853 tolerance per step (PlantBody.advance_orbit)


def _spinner(wz: float, thrust: str = "20 N", mass: str = "500 kg", isp: str | None = None, wheel: bool = False):
    """The free-space body spinning at ``wz`` rad/s about its principal z axis (inertia 10,
    20, 30: the major axis), body axes = inertial at t = 0; a thruster, optionally a
    specific impulse and a reaction wheel about z (then Plant.advance steps its attitude in
    the compiled batch)."""
    scene = SCENE.split("[bodies.attitude]")[0] + f"""[bodies.attitude]
inertia = [10, 20, 30]
w = [0, 0, {wz!r}]
[bodies.actuators]
thrust = "{thrust}"
mass = "{mass}"
""" + (f'isp = "{isp}"\n' if isp else "") + (wheel_tables([[0, 0, 1]], 0.05, 0.2, 600) if wheel else "")
    plant = Plant(loads(scene))
    b = plant.bodies["sc"]
    b.apply({"t": 0.0, "seq": 0, "sender": "c", "thrust": [float(thrust.split()[0]), 0.0, 0.0], "frame": "body"})
    return plant, b


# (wz rad/s, step s, steps): a slow and a fast spin at 1 s steps; turns of 5 rad (more than
# pi: the whole turns counted the other way), 10 rad and exactly 2 pi per step
SPINS = [(0.05, 1.0, 30), (0.2, 1.0, 30), (1.0, 5.0, 6), (2.0, 5.0, 6), (2 * math.pi / 5, 5.0, 6)]


@pytest.mark.parametrize("wz, dt, n", SPINS)
def test_a_body_axis_thrust_turns_with_a_spinning_body(wz, dt, n):
    plant, b = _spinner(wz)
    for _ in range(n):
        b.begin_step()
        b.finish_commands()
        b.advance(dt)
    T, a = n * dt, 20.0 / 500.0
    exact = a * np.array([math.sin(wz * T) / wz, (1.0 - math.cos(wz * T)) / wz, 0.0])
    np.testing.assert_allclose(b.w, [0.0, 0.0, wz], rtol=0, atol=1e-15 * wz)  # the spin stays pure
    # each step's DOP853 is good to its rtol of the state, |v| <= a T: n of them
    np.testing.assert_allclose(b.v, exact, rtol=0, atol=n * RTOL * a * T)
    assert b.mass == 500.0 and b.dv_total == pytest.approx(a * T, rel=1e-14)


@pytest.mark.parametrize("wz, dt, n", [(0.2, 1.0, 30), (1.0, 5.0, 6)])
def test_a_turning_thrust_with_mass_loss_follows_the_closed_form(wz, dt, n):
    """2000 N from 100 kg at isp 100 s: 61 % of the mass burnt in 30 s (the closed form of
    the module docstring; Si, Ci at arguments ~10, well conditioned)."""
    from scipy.special import sici

    plant, b = _spinner(wz, thrust="2000 N", mass="100 kg", isp="100 s")
    for _ in range(n):
        b.begin_step()
        b.finish_commands()
        b.advance(dt)
    T, F, m0, isp = n * dt, 2000.0, 100.0, 100.0
    mdot = F / (isp * G0)
    m1 = m0 - mdot * T
    tb = m0 / mdot
    (si0, ci0), (si1, ci1) = sici(wz * tb), sici(wz * (tb - T))
    z = F / mdot * complex(math.cos(wz * tb), math.sin(wz * tb)) * complex(ci0 - ci1, -(si0 - si1))
    rocket = isp * G0 * math.log(m0 / m1)  # Tsiolkovsky: the speed gained along the thrust
    assert b.mass == pytest.approx(m1, rel=1e-14)
    assert b.dv_total == pytest.approx(rocket, rel=1e-13)
    # |v| <= rocket at all times; n steps at RTOL, and Si, Ci (~1) to a few eps times F/mdot
    np.testing.assert_allclose(b.v, [z.real, z.imag, 0.0], rtol=0, atol=n * RTOL * rocket + 8 * np.finfo(float).eps * F / mdot)
    assert np.linalg.norm(b.v) <= rocket


@pytest.mark.parametrize("wheel", [True, False])
def test_the_recorded_thrust_is_the_one_applied_at_its_time(wheel):
    """Through Plant.advance (with a wheel the compiled batch steps the attitude, without one
    the torque-free solution): the actuator state's thrust of each step is C(q(t))^T f_body
    with q the attitude of the same t, and the step's velocity change is that thrust turning
    with the spin (about z at wz) through the step: dv_k = (sin(wz dt) f_k + (1 - cos(wz dt))
    z x f_k) / (m wz)."""
    wz, dt, m = 0.3, 1.0, 500.0
    plant, b = _spinner(wz, wheel=wheel)
    assert b.batched() == wheel
    f_body = np.array([20.0, 0.0, 0.0])
    eps = np.finfo(float).eps
    for _ in range(10):
        b.begin_step()
        b.finish_commands()
        q, v = b.q.copy(), b.v.copy()
        plant.advance([b], dt)
        f = b.actuator_state()["thrust"]
        np.testing.assert_allclose(f, dcm_from_quat(q).T @ f_body, rtol=0, atol=4 * eps * 20.0)
        phi = wz * dt
        dv = (math.sin(phi) * f + (1.0 - math.cos(phi)) * np.cross([0.0, 0.0, 1.0], f)) / (m * wz)
        # the step's DOP853 to RTOL of |v| <= 20 / m * 10 s; the rotation of q to round-off
        np.testing.assert_allclose(b.v - v, dv, rtol=0, atol=RTOL * 20.0 / m * 10 + 1e-14 * np.linalg.norm(dv))
    np.testing.assert_allclose(b.w, [0.0, 0.0, wz], rtol=0, atol=1e-14 * wz)


def test_a_rotating_thrust_turns_right_handed_and_is_a_constant_thrust_at_rate_0():
    f0 = np.array([3.0, -4.0, 12.0])
    rot = RotatingThrust(f0, 100.0, 300.0, axis=(0.0, 0.0, 2.0), rate=0.1)
    const = ConstantThrust(f0, 100.0, 300.0)
    assert rot.mdot == const.mdot and rot.mass_at(7.0) == const.mass_at(7.0)
    c, s = math.cos(0.7), math.sin(0.7)  # 0.7 rad about +z: x -> (c, s), y -> (-s, c)
    np.testing.assert_allclose(rot.force_at(7.0), [3.0 * c + 4.0 * s, 3.0 * s - 4.0 * c, 12.0], rtol=0, atol=1e-14)
    assert np.linalg.norm(rot.force_at(123.0)) == pytest.approx(13.0, rel=1e-15)
    r = np.array([[7e6, 0.0, 0.0], [0.0, 7e6, 0.0]])
    still = RotatingThrust(f0, 100.0, 300.0, axis=(1.0, 1.0, 0.0), rate=0.0)
    for t in (0.0, 3.0, 50.0):
        assert np.array_equal(still.acceleration(t, r), const.acceleration(t, r))
    with pytest.raises(ValueError, match="axis"):
        RotatingThrust(f0, 100.0, axis=(0.0, 0.0, 0.0), rate=0.1)
    with pytest.raises(ValueError, match="rate"):
        RotatingThrust(f0, 100.0, axis=(0.0, 0.0, 1.0), rate=math.inf)
    with pytest.raises(ValueError, match="mass"):
        RotatingThrust(f0, -1.0)
