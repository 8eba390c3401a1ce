"""Reaction wheels (astrodyn.attitude.wheels) against conservation laws and closed forms.

* Internal motor torques, changed every step at random, conserve the inertial angular
  momentum of body plus wheels (``C^T (I_kin w + sum h_k a_k)``) to round-off over 2000
  steps: the wheels only move momentum between body and rotors.
* A constant body-axis torque on a spherical body (no wheels' momentum, ``w x I w = 0``)
  gives ``w(t) = w0 + tau t / I`` (Euler's equations are linear there), to round-off once
  the splitting step makes its 4th-order error smaller than that.
* A constant inertial torque changes the inertial momentum by its integral ``tau T``.
* Saturation: commands beyond the torque limit are clipped to it; a wheel driven into its
  speed limit stops there (and can be driven back).  Saturation only ever reduces a
  command: the applied torque has the command's sign (or is 0) and at most its magnitude,
  also for a wheel already beyond its speed limit, in the one-body and the batch paths
  alike, and the plant reports as clipped exactly the wheels whose command was changed.
"""

from __future__ import annotations

import numpy as np
import pytest

from _recordings import scenario_head
from _scenes import tumbling_sc, wheel_tables
from astrodyn.attitude import ConstantTorque
from astrodyn.attitude.wheels import HeldInputsBatch, ReactionWheels, step_with_wheels
from astrodyn.rotation import dcm_from_quat, quat_from_euler

PYRAMID = np.array([[1.0, 0.0, 1.0], [0.0, 1.0, 1.0], [-1.0, 0.0, 1.0], [0.0, -1.0, 1.0]]) / np.sqrt(2.0)


def _wheels(max_torque=0.2, max_speed=600.0):
    return ReactionWheels(PYRAMID, rotor_inertia=0.02, max_torque=max_torque, max_speed=max_speed)


def _inertial_momentum(inertia, wheels, w, q, h):
    return dcm_from_quat(q).T @ (wheels.kinematic_inertia(inertia) @ w + wheels.momentum(h))


def test_internal_wheel_torques_conserve_total_momentum():
    inertia = np.array([[120.0, 2.0, -1.0], [2.0, 100.0, 0.5], [-1.0, 0.5, 80.0]])
    wheels = _wheels()
    rng = np.random.default_rng(3)
    w, q = np.array([0.02, -0.01, 0.03]), quat_from_euler([0.3, -0.2, 1.0], "321")
    h = wheels.absolute_momentum(rng.uniform(-100, 100, 4), w)
    H0 = _inertial_momentum(inertia, wheels, w, q, h)
    worst = 0.0
    for _ in range(2000):
        s = step_with_wheels(inertia, wheels, w, q, h, rng.uniform(-0.3, 0.3, 4), 0.1)
        w, q, h = s.w, s.q, s.h
        worst = max(worst, np.linalg.norm(_inertial_momentum(inertia, wheels, w, q, h) - H0) / np.linalg.norm(H0))
    # round-off only: each step rebuilds w from H - h through I_kin (a few roundings of |H|);
    # bound: linear accumulation of 10 eps per step over the 2000 steps (random-walk ~5e-14)
    assert worst < 2000 * 10 * np.finfo(float).eps, worst
    assert abs(np.linalg.norm(q) - 1.0) < 1e-14
    # and momentum did move between body and wheels
    assert np.linalg.norm(w - np.array([0.02, -0.01, 0.03])) > 1e-3


def test_constant_body_torque_on_a_sphere_is_linear_in_time():
    wheels = ReactionWheels([[1.0, 0.0, 0.0]], rotor_inertia=1e-3, max_torque=1.0, max_speed=np.inf)
    inertia = np.eye(3) * 50.0 + np.diag([1e-3, 0.0, 0.0])  # the wheel's J taken back out: I_kin = 50 I
    tau = np.array([0.3, -0.2, 0.1])
    w0 = np.array([0.1, 0.2, -0.05])
    w, q, h = w0, np.array([1.0, 0.0, 0.0, 0.0]), np.zeros(1)
    t = 0.0
    for k in range(1, 51):
        s = step_with_wheels(inertia, wheels, w, q, h, [0.0], 0.2, external_torque=ConstantTorque(tau, "body"), step=0.01)
        w, q, h = s.w, s.q, s.h
        t += 0.2
        expected = w0 + tau * t / 50.0
        # the idle wheel (h = 0) keeps the body spherical: w x I w = 0, so w' = tau / I.  The
        # splitting kicks the inertial momentum, so a body-fixed torque is exact only up to its
        # 4th-order error, ~(|w| h)^4 ~ 1e-12 for h = 0.2 s; at h = 0.01 s that is below round-off
        # round-off: a few roundings of |w| per substep (20 per control step), accumulated
        assert np.max(np.abs(w - expected)) < 20 * k * 4 * np.finfo(float).eps * np.max(np.abs(expected)), (t, w - expected)


def test_inertial_torque_changes_momentum_by_its_integral():
    inertia = np.diag([10.0, 20.0, 30.0])
    wheels = _wheels()
    tau = np.array([0.05, 0.0, -0.02])  # inertial axes
    w, q = np.array([0.01, 0.2, 0.01]), quat_from_euler([0.1, 0.2, 0.3], "321")
    h = wheels.absolute_momentum(np.full(4, 50.0), w)
    H0 = _inertial_momentum(inertia, wheels, w, q, h)
    T = 0.0
    for k in range(200):
        s = step_with_wheels(inertia, wheels, w, q, h, np.sin(k + np.arange(4)) * 0.05, 0.05,
                             external_torque=ConstantTorque(tau, "inertial"), step=0.005)
        w, q, h = s.w, s.q, s.h
        T += 0.05
    dH = _inertial_momentum(inertia, wheels, w, q, h) - H0
    # the splitting applies the torque in kicks: 4th-order error in the step, here ~1e-10 of |tau T|
    assert np.linalg.norm(dH - tau * T) < 1e-8 * np.linalg.norm(tau * T), dH - tau * T


def test_saturation_clips_torque_and_speed():
    wheels = _wheels(max_torque=0.1, max_speed=100.0)
    w = np.zeros(3)
    h = wheels.absolute_momentum([0.0, 99.9, -100.0, 10.0], w)
    g, clipped = wheels.saturate([0.5, 0.05, -0.05, -0.5], h, w, 0.1)
    assert g[0] == pytest.approx(0.1) and clipped[0]                        # torque limit
    assert wheels.speeds(h + g * 0.1, w)[1] == pytest.approx(100.0)         # stops at the speed limit
    assert g[2] == 0.0 and clipped[2]                                       # at -100: no further
    assert g[3] == pytest.approx(-0.1) and clipped[3]
    g2, c2 = wheels.saturate([0.0, -0.05, 0.05, 0.0], h, w, 0.1)           # back towards zero is allowed
    assert g2[1] == pytest.approx(-0.05) and g2[2] == pytest.approx(0.05) and not c2.any()
    inertia = np.diag([5.0, 5.0, 5.0])
    q = np.array([1.0, 0.0, 0.0, 0.0])
    drift = np.zeros(4)
    for _ in range(100):  # driven hard for 10 s: speeds stay within the limit, but for the body's turn
        s = step_with_wheels(inertia, wheels, w, q, h, [1.0, 1.0, -1.0, 1.0], 0.1)
        # the limit holds for the speed predicted with the body rate held; the actual one
        # differs by -a_k . dw (the wheel's absolute momentum is what the motor set)
        dw = np.abs(PYRAMID @ (s.w - w))
        before = np.abs(wheels.speeds(h, w))
        assert np.all(np.abs(wheels.speeds(s.h, s.w)) <= np.maximum(before, 100.0) + dw + 1e-12)
        drift += dw
        w, q, h = s.w, s.q, s.h
    assert np.all(np.abs(wheels.speeds(h, w)) <= 100.0 + drift + 1e-12)
    assert np.all(drift < 0.3)  # small body rates: within 0.3 % of the limit


def test_bad_wheels_and_commands_name_the_field():
    with pytest.raises(ValueError, match="axes"):
        ReactionWheels([[1.0, 1.0, 0.0]], 0.01, 0.1, 100.0)
    with pytest.raises(ValueError, match="max_torque"):
        ReactionWheels([[1.0, 0.0, 0.0]], 0.01, -0.1, 100.0)
    with pytest.raises(ValueError, match="wheel torque"):
        _wheels().saturate([np.nan, 0, 0, 0], np.zeros(4), np.zeros(3), 0.1)
    with pytest.raises(ValueError, match="dt"):
        step_with_wheels(np.eye(3), _wheels(), np.zeros(3), np.array([1.0, 0, 0, 0]), np.zeros(4), np.zeros(4), 0.0)


def _only_reduced(g, cmd):
    """Saturation's promise, whatever the wheel's state: the applied torque ``g`` has the
    sign of the command or is 0, and is no larger."""
    g, cmd = np.asarray(g), np.asarray(cmd)
    return bool(np.all(((g == 0.0) | (np.sign(g) == np.sign(cmd))) & (np.abs(g) <= np.abs(cmd))))


def _batch_saturate(wheels, h, w, cmd, dt):
    """The applied torques and clipped flags of HeldInputsBatch.step (the plant's compiled path), one body."""
    batch = HeldInputsBatch([np.diag([5.0, 6.0, 7.0])], [wheels])
    g, clipped = batch.step([0], np.array([w], dtype=float), np.array([[1.0, 0.0, 0.0, 0.0]]), np.array([h], dtype=float),
                            np.array([cmd], dtype=float), np.zeros((1, 3)), dt)
    return g[0], clipped[0]


@pytest.mark.parametrize("sign", [1.0, -1.0])
@pytest.mark.parametrize("path", ["numpy", "batch"])
def test_a_wheel_beyond_its_speed_limit_gets_no_torque_it_was_not_commanded(path, sign):
    """A wheel can end a step beyond max_speed (the prediction holds the body rate); from
    there a command of 0 stays 0, one that would speed it up further becomes 0, and one that
    slows it down is applied (clipped only to max_torque)."""
    wheels = ReactionWheels([[1.0, 0.0, 0.0]] * 4, rotor_inertia=0.05, max_torque=0.2, max_speed=100.0)
    w = np.array([0.01, -0.02, 0.03])
    h = wheels.absolute_momentum(sign * np.full(4, 101.0), w)  # 1 rad/s over the limit
    cmd = sign * np.array([0.0, 0.001, -0.001, -0.5])  # none, small same-sign, small opposite, large opposite
    if path == "numpy":
        g, clipped = wheels.saturate(cmd, h, w, 0.1)
    else:
        g, clipped = _batch_saturate(wheels, h, w, cmd, 0.1)
    assert _only_reduced(g, cmd), g
    np.testing.assert_array_equal(clipped, g != cmd)
    np.testing.assert_array_equal(g, sign * np.array([0.0, 0.0, -0.001, -0.2]))
    np.testing.assert_array_equal(clipped, [False, True, False, True])


def test_saturation_only_ever_reduces_a_command_and_keeps_a_wheel_within_its_limit():
    """Random wheel speeds (within, at and beyond the limit), commands (0, small, beyond the
    torque limit, exactly at the speed bound), limits and steps: in both paths the applied
    torque has the command's sign or is 0, is no larger, is clipped exactly where it differs
    from the command, and a wheel within its limit is predicted (body rate held) to end
    within it, one beyond it to end no farther out."""
    rng = np.random.default_rng(11)
    eps = np.finfo(float).eps
    for _ in range(40):
        n = 6
        axes = rng.normal(size=(n, 3))
        axes /= np.linalg.norm(axes, axis=1, keepdims=True)
        J = 10.0 ** rng.uniform(-3, 0, n)
        mt = 10.0 ** rng.uniform(-3, 0, n)
        ms = 10.0 ** rng.uniform(0, 3, n)
        wheels = ReactionWheels(axes, J, mt, ms)
        w = rng.normal(size=3) * 10.0 ** rng.uniform(-3, 0)
        dt = 10.0 ** rng.uniform(-2, 1)
        u = rng.random(n)
        side = np.where(rng.random(n) < 0.5, -1.0, 1.0)
        speeds = np.where(u < 0.5, rng.uniform(-1, 1, n) * ms, side * ms * np.where(u < 0.7, 1.0, rng.uniform(1.0, 1.2, n)))
        h = wheels.absolute_momentum(speeds, w)
        omega = wheels.speeds(h, w)
        c = rng.random(n)
        cmd = np.where(c < 0.15, 0.0, np.where(c < 0.3, (side * ms - omega) * J / dt,
                                                rng.normal(size=n) * mt * 10.0 ** rng.uniform(-2, 1, n)))
        for g, clipped in (wheels.saturate(cmd, h, w, dt), _batch_saturate(wheels, h, w, cmd, dt)):
            assert _only_reduced(g, cmd), (omega, cmd, g)
            np.testing.assert_array_equal(clipped, g != cmd)
            assert np.all(np.abs(g) <= mt)
            end = np.abs(omega + g * dt / J)
            slack = 8 * eps * (np.abs(omega) + ms)  # the roundings of the bound and of the prediction
            assert np.all(end <= np.maximum(np.abs(omega), ms) + slack), (omega, ms, g)
            inside = np.abs(omega) <= ms
            assert np.all(end[inside] <= ms[inside] + slack[inside])


WHEELED = scenario_head("overspeed", "10 s", "10 Hz") + "[control]\n" + tumbling_sc(
    wheel_tables([[1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0.6, 0.8]], 0.05, 0.2, 100))


@pytest.mark.parametrize("batched", [False, True])
def test_the_plant_reports_as_clipped_exactly_the_wheels_whose_command_it_changed(batched):
    """Wheels beyond their speed limit (as one may end a step) in the plant, one path or the
    other (Plant.advance's compiled batch, PlantBody.advance): the zero command is applied
    as 0 and not reported, the one that would speed its wheel up is zeroed and reported, the
    braking ones are applied as commanded (within max_torque) or clipped to it and reported."""
    from astrodyn.plant import Plant
    from astrodyn.scenario import loads

    plant = Plant(loads(WHEELED))
    b = plant.bodies["sc"]
    b.h = b.wheels.absolute_momentum([101.0, -101.0, 101.0, 101.0], b.w)
    cmd = [0.0, -0.001, -0.05, -0.5]
    b.begin_step()
    b.apply({"t": 0.0, "seq": 0, "sender": "c", "wheel_torque": cmd})
    b.finish_commands()
    if batched:
        assert b.batched()
        plant.advance([b], 0.1)
    else:
        b.advance(0.1)
    np.testing.assert_array_equal(b.applied_wheel, [0.0, 0.0, -0.05, -0.2])
    assert b.clipped == [1, 3]
    assert b.actuator_state()["clipped"] == [1, 3]
