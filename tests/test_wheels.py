"""Reaction wheels (astrodyn.attitude.wheels) against conservation laws and closed forms.

* Internal motor torques, changed every step at random, conserve the inertial angular
  momentum of body plus wheels (``C^T (I_kin w + sum h_k a_k)``) to round-off over 2000
  steps: the wheels only move momentum between body and rotors.
* A constant body-axis torque on a spherical body (no wheels' momentum, ``w x I w = 0``)
  gives ``w(t) = w0 + tau t / I`` (Euler's equations are linear there), to round-off once
  the splitting step makes its 4th-order error smaller than that.
* A constant inertial torque changes the inertial momentum by its integral ``tau T``.
* Saturation: commands beyond the torque limit are clipped to it; a wheel driven into its
  speed limit stops there (and can be driven back).
"""

from __future__ import annotations

import numpy as np
import pytest

from astrodyn.attitude import ConstantTorque
from astrodyn.attitude.wheels import ReactionWheels, step_with_wheels
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
    for _ in range(100):  # driven hard for 10 s: speeds stay within the limit
        s = step_with_wheels(inertia, wheels, w, q, h, [1.0, 1.0, -1.0, 1.0], 0.1)
        w, q, h = s.w, s.q, s.h
    assert np.all(np.abs(wheels.speeds(h, w)) <= 100.0 * (1 + 1e-3))


def test_bad_wheels_and_commands_name_the_field():
    with pytest.raises(ValueError, match="axes"):
        ReactionWheels([[1.0, 1.0, 0.0]], 0.01, 0.1, 100.0)
    with pytest.raises(ValueError, match="max_torque"):
        ReactionWheels([[1.0, 0.0, 0.0]], 0.01, -0.1, 100.0)
    with pytest.raises(ValueError, match="wheel torque"):
        _wheels().saturate([np.nan, 0, 0, 0], np.zeros(4), np.zeros(3), 0.1)
    with pytest.raises(ValueError, match="dt"):
        step_with_wheels(np.eye(3), _wheels(), np.zeros(3), np.array([1.0, 0, 0, 0]), np.zeros(4), np.zeros(4), 0.0)
