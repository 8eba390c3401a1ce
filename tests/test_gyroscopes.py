"""Gyroscopes as instruments (astrodyn.attitude.gyroscopes; Baruh 10.7.1 and 10.7.3).

Every expected value comes from something independent of the module's equations:

* closed forms derived by hand here (ideal rate / rate-integrating gyro, the linear error
  terms, the linearized nutation, the exact torque-free symmetric rotor);
* conservation laws (energy, momentum about the outer axis, rotor axial momentum, the
  Jacobi integral of a uniformly turning case);
* an independent Newton-Euler integration (:class:`_Chain`): every body has its own
  Euler equation in its own (spinning, for the rotor) frame, the joint torques are
  unknowns solved for at each step, the kinematics is built from this file's own elementary
  rotations.  It shares no code and no algebra with the module's Lagrange / gimbal-frame
  equations.
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.interpolate import CubicHermiteSpline, CubicSpline
from scipy.optimize import least_squares

from astrodyn.attitude.gyroscopes import (
    FreeGyroscope,
    SingleAxisGyro,
    constant_base_rate,
    error_torques,
    fast_rotor_nutation_frequency,
    free_gyro_integrals,
    free_gyro_linear,
    free_gyro_momentum,
    free_gyro_rates,
    free_gyro_state,
    nutation_frequency,
    propagate_free_gyro,
    propagate_single_axis,
    sampled_base_rate,
    single_axis_energy,
    single_axis_jacobi_integral,
    single_axis_momentum,
    single_axis_rates,
    steady_state_angle,
)

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _hostile_calls import assert_refused_quickly

# a small instrument: rotor 1e-4 kg m^2 at 2000 rad/s (H = 0.2 N m s), float + rotor J2 = 9e-5 kg m^2
C_ROT, A_ROT, SPIN = 1e-4, 6e-5, 2000.0
GIMBAL = (2e-5, 3e-5, 2e-5)
H = C_ROT * SPIN
J1, J2, J3 = GIMBAL[0] + A_ROT, GIMBAL[1] + A_ROT, GIMBAL[2] + C_ROT
DJ = J3 - J1  # anisoinertia coefficient, 4e-5 kg m^2


# --------------------------------------------------------------------------- independent Newton-Euler


def _elem(axis, a):
    """Frame rotation about ``axis`` (1, 2, 3) by ``a`` and its derivative with respect to ``a``."""
    c, s = math.cos(a), math.sin(a)
    i = axis - 1
    j, k = (i + 1) % 3, (i + 2) % 3
    R, dR = np.zeros((3, 3)), np.zeros((3, 3))
    R[i, i] = 1.0
    R[j, j] = R[k, k] = c
    R[j, k], R[k, j] = s, -s
    dR[j, j] = dR[k, k] = -s
    dR[j, k], dR[k, j] = c, -c
    return R, dR


def _cross(a, b):
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


class _Chain:
    """Bodies 1..N about one fixed point (all mass centres there); body k turns relative to
    body k-1 (body 0: the base, turning at ``base(t) -> (w, w')``) about its own axis
    ``axes[k]`` by ``q_k`` (frame ``F_k = C_axis(q_k) F_{k-1}``), principal inertias
    ``inertias[k]`` in ``F_k``.  ``joint(t, q, qd)`` gives the torque about each joint axis
    that body k-1 exerts on body k; a joint in ``locked`` has a prescribed constant rate
    (its motor torque is an unknown).  Newton-Euler: for every body
    ``I_k w_k' + w_k x I_k w_k = tau_k - R_{k+1}^T tau_{k+1}`` with the joint torques
    ``tau_k`` (3 unknowns each) and ``e_k . tau_k`` given (or ``q_k'' = 0``)."""

    def __init__(self, axes, inertias, base, joint, locked=()):
        self.axes, self.I = list(axes), [np.diag(np.asarray(m, dtype=float)) for m in inertias]
        self.base, self.joint, self.locked = base, joint, set(locked)

    def kinematics(self, t, q, qd):
        n = len(self.axes)
        w, wd = self.base(t)
        w, a, B = np.asarray(w, float), np.asarray(wd, float), np.zeros((3, n))
        out = []
        for k, ax in enumerate(self.axes):
            R, dR = _elem(ax, q[k])
            e = np.eye(3)[ax - 1]
            a = R @ a + (dR * qd[k]) @ w
            B = R @ B
            B[:, k] += e
            w = R @ w + qd[k] * e
            out.append((R, e, w.copy(), a.copy(), B.copy()))
        return out

    def accel(self, t, q, qd):
        n = len(self.axes)
        kin = self.kinematics(t, q, qd)
        Q = self.joint(t, q, qd)
        M, rhs = np.zeros((4 * n, 4 * n)), np.zeros(4 * n)
        for k, (_, e, w, a, B) in enumerate(kin):
            I = self.I[k]
            r = slice(3 * k, 3 * k + 3)
            M[r, :n] = I @ B
            M[r, n + 3 * k : n + 3 * k + 3] = -np.eye(3)
            if k + 1 < n:
                M[r, n + 3 * (k + 1) : n + 3 * (k + 2)] = kin[k + 1][0].T
            rhs[r] = -I @ a - _cross(w, I @ w)
            row = 3 * n + k
            if k in self.locked:
                M[row, k] = 1.0
            else:
                M[row, n + 3 * k : n + 3 * k + 3] = e
                rhs[row] = Q[k]
        x = np.linalg.solve(M, rhs)
        return x[:n]

    def energy(self, t, q, qd):
        return sum(0.5 * w @ self.I[k] @ w for k, (_, _, w, _, _) in enumerate(self.kinematics(t, q, qd)))

    def integrate(self, q0, qd0, t, rtol=1e-12, atol=1e-14):
        n = len(self.axes)

        def f(time_, y):
            return np.concatenate([y[n:], self.accel(time_, y[:n], y[n:])])

        sol = solve_ivp(
            f, (0.0, float(t[-1])), np.concatenate([q0, qd0]), method="DOP853", t_eval=t, rtol=rtol, atol=atol
        )
        assert sol.success
        return sol.y.T


def _gyro_chain(gyro, base, regulated):
    k, c = gyro.spring, gyro.damping
    return _Chain(
        [2, 3],
        [gyro.gimbal_inertia, (gyro.transverse_inertia,) * 2 + (gyro.spin_inertia,)],
        base,
        lambda t, q, qd: (-k * q[0] - c * qd[0], 0.0),
        locked=(1,) if regulated else (),
    )


def _rich_base(t):
    """A base turning about all three axes at once, w and w' in closed form (rad/s, rad/s^2)."""
    w = np.array(
        [0.3 * math.sin(7.0 * t) + 0.1, 0.5 * math.cos(11.0 * t) - 0.2 * t, 0.4 * math.sin(5.0 * t + 0.3) + 0.2]
    )
    wd = np.array([2.1 * math.cos(7.0 * t), -5.5 * math.sin(11.0 * t) - 0.2, 2.0 * math.cos(5.0 * t + 0.3)])
    return w, wd


def _gyro(k=0.9, c=1.8e-3, free_rotor=False, gimbal=GIMBAL):
    return SingleAxisGyro(C_ROT, A_ROT, SPIN, gimbal, k, c, free_rotor)


def _extrema(t, x, xd):
    """Times and values of the extrema of a sampled smooth signal ``x`` with derivative ``xd``:
    roots of a cubic spline through ``xd``, values from the cubic Hermite interpolant."""
    roots = CubicSpline(t, xd).roots(extrapolate=False)
    roots = roots[(roots > t[0]) & (roots < t[-1])]
    return roots, CubicHermiteSpline(t, x, xd)(roots)


# --------------------------------------------------------------------------- 1. rate gyro


@pytest.mark.parametrize("w1", [1e-3, 1e-2, 0.1, 0.4])
def test_rate_gyro_steady_state_is_H_w1_over_k(w1):
    """Constant input rate: theta_ss = H w1 / k for small angles.  From the exact balance
    k theta = H w1 cos(theta) + (J3 - J1) w1^2 sin(theta) cos(theta) the small-angle result
    is off by theta0 (-theta0^2 / 2 + (J3 - J1) w1^2 / k) + O(theta0^5): the test checks both
    that the ideal value holds to that bound and that the derived cubic correction is what
    the simulation shows (to 2 % of it, or 1e-12 rad)."""
    gyro = _gyro(c=2 * 0.7 * math.sqrt(0.9 * J2))  # zeta = 0.7: settled to 1e-12 well within 0.6 s
    t = np.array([0.0, 0.6])
    theta = propagate_single_axis(gyro, constant_base_rate([w1, 0.0, 0.0]), t)[0][-1, 0]
    theta0 = H * w1 / 0.9
    correction = theta0 * (-(theta0**2) / 2 + DJ * w1**2 / 0.9)
    assert abs(theta - theta0) <= 1.05 * abs(correction) + 1e-12
    assert abs(theta - theta0 - correction) <= 0.02 * abs(correction) + abs(theta0) ** 5 + 1e-12


def _fit_step(t, theta):
    """Least-squares fit of theta_ss + exp(-a t) (P cos(wd t) + Q sin(wd t))."""

    def resid(p):
        ss, a, wd, P, Q = p
        return ss + np.exp(-a * t) * (P * np.cos(wd * t) + Q * np.sin(wd * t)) - theta

    guess = [theta[-1], 10.0, 99.0, -theta[-1], -0.1 * theta[-1]]
    fit = least_squares(resid, guess, xtol=1e-15, ftol=1e-15, gtol=1e-15)
    return fit.x


def test_rate_gyro_natural_frequency_and_damping_from_step_response():
    """Step in w1 from rest: fitted omega_n = sqrt(a^2 + wd^2) and zeta = a / omega_n against
    sqrt(k / J2) = 100 rad/s and c / (2 sqrt(k J2)) = 0.1; separately, the log decrement of
    successive extrema of theta' (spaced pi / wd: ratio exp(-a pi / wd)) and the period from
    the zero crossings of theta'.  Small-angle bound: linearized about theta_ss the
    stiffness is k (1 + theta_ss^2) - (J3 - J1) w1^2 (to leading order), so with
    w1 = 0.005 rad/s (theta_ss = 1.1e-3 rad) omega_n and zeta are off by < 2e-6; the fit's
    own error is far below."""
    w1 = 0.005
    gyro = _gyro()
    t = np.linspace(0.0, 0.5, 8001)  # 8 periods, ~1000 samples each
    s = propagate_single_axis(gyro, constant_base_rate([w1, 0.0, 0.0]), t)[0]
    theta_ss = H * w1 / 0.9
    bound = 2.0 * (theta_ss**2 + abs(DJ) * w1**2 / 0.9) + 1e-9
    ss, a, wd, _, _ = _fit_step(t, s[:, 0])
    wn = math.hypot(a, wd)
    assert abs(wn / math.sqrt(0.9 / J2) - 1) < bound
    assert abs((a / wn) / (1.8e-3 / (2 * math.sqrt(0.9 * J2))) - 1) < bound
    assert abs(ss / theta_ss - 1) < bound
    # sharper: the leading small-angle shifts themselves, +theta^2/2 in omega_n, -theta^2/2 in
    # zeta and in theta_ss (cos theta), seen to 20 % of theta^2
    shift = 0.5 * theta_ss**2
    assert abs(wn / 100.0 - 1 - shift) < 0.2 * theta_ss**2
    assert abs((a / wn) / 0.1 - 1 + shift) < 0.2 * theta_ss**2
    assert abs(ss / theta_ss - 1 + shift) < 0.2 * theta_ss**2
    # log decrement and zero crossings of theta' (its own extrema need theta'': from theta' samples)
    thd = s[:, 1]
    zeros = CubicSpline(t, thd).roots(extrapolate=False)
    zeros = zeros[(zeros > 1e-6) & (zeros < t[-1])]
    half_period = np.mean(np.diff(zeros))
    wd_cross = math.pi / half_period
    dt = CubicSpline(t, thd).derivative()
    tpk = dt.roots(extrapolate=False)
    tpk = tpk[(tpk > 0) & (tpk < t[-1])]
    peaks = np.abs(CubicSpline(t, thd)(tpk))
    decrement = np.mean(np.log(peaks[:-1] / peaks[1:]))  # = a pi / wd per half period
    zeta = decrement / math.hypot(math.pi, decrement)
    wn_cross = wd_cross / math.sqrt(1 - zeta**2)
    assert abs(wn_cross / 100.0 - 1) < bound + 1e-7
    assert abs(zeta / 0.1 - 1) < bound + 1e-6


# --------------------------------------------------------------------------- 2. rate-integrating gyro


def test_rate_integrating_output_is_H_over_c_times_the_integral_of_the_input():
    """k = 0: integrating J2 theta'' + c theta' = H w1 from rest gives the exact identity
    c theta + J2 theta' = H int w1 dt (checked to the small-angle bound H |w1| theta^2 / 2
    integrated, and the anisoinertia term, here zero: w3 = 0).  The output itself follows
    (H / c) int w1 dt to within the lag (J2 / c) |theta'|, and exactly the closed-form
    solution of the ideal equation for w1 = W sin(nu t)."""
    c, W, nu = 9e-3, 1e-4, 5.0  # time constant J2 / c = 0.01 s
    gyro = SingleAxisGyro.rate_integrating(C_ROT, A_ROT, SPIN, c, GIMBAL)

    def base(t):
        return np.array([W * math.sin(nu * t), 0.0, 0.0]), np.array([W * nu * math.cos(nu * t), 0.0, 0.0])

    t = np.linspace(0.0, 2.0, 401)
    s = propagate_single_axis(gyro, base, t)[0]
    theta, thd = s[:, 0], s[:, 1]
    integral = W * (1 - np.cos(nu * t)) / nu
    small = H * W * np.max(theta**2) / 2 * t[-1] / c  # bound on the dropped H w1 (cos theta - 1), integrated
    assert np.max(np.abs(c * theta + J2 * thd - H * integral)) / c <= small + 1e-13
    assert np.max(np.abs(theta - H / c * integral)) <= np.max(J2 / c * np.abs(thd)) + small + 1e-13
    assert np.max(np.abs(theta - H / c * integral)) > 1e-3 * np.max(np.abs(theta))  # the lag is real
    # closed form of J2 x' + c x = H W sin(nu t), x = theta', x(0) = 0, theta = int x
    den = c * c + (J2 * nu) ** 2
    K = H * W * J2 * nu / den
    tau = J2 / c
    theta_exact = (H * W / den) * (c * (1 - np.cos(nu * t)) / nu - J2 * np.sin(nu * t)) + K * tau * (
        1 - np.exp(-t / tau)
    )
    assert np.max(np.abs(theta - theta_exact)) <= small + 1e-12


def test_rate_integrating_output_axis_acceleration_error():
    """A constant output-axis rate does nothing (only w2' enters); a varying one makes a
    rate-integrating gyro read c theta + J2 theta' = -J2 (w2(t) - w2(0)): with w2 = V (1 -
    cos(nu t)) the output is -(J2 / c) (w2 - ...) to the ideal equation's exactness (no
    other rate, so the remaining terms vanish identically)."""
    c, V, nu = 9e-3, 0.3, 4.0
    gyro = SingleAxisGyro.rate_integrating(C_ROT, A_ROT, SPIN, c, GIMBAL)
    t = np.linspace(0.0, 1.5, 301)
    s0 = propagate_single_axis(gyro, constant_base_rate([0.0, 0.7, 0.0]), t)[0]
    assert np.max(np.abs(s0[:, :2])) == 0.0

    def base(t):
        return np.array([0.0, V * (1 - math.cos(nu * t)), 0.0]), np.array([0.0, V * nu * math.sin(nu * t), 0.0])

    s = propagate_single_axis(gyro, base, t)[0]
    w2 = V * (1 - np.cos(nu * t))
    assert np.max(np.abs(c * s[:, 0] + J2 * s[:, 1] + J2 * w2)) < 1e-12
    assert np.max(np.abs(s[:, 0])) > 1e-3  # 3e-3 rad: the error term is large for this instrument


# --------------------------------------------------------------------------- 3. cross-coupling, full equations


@pytest.mark.parametrize("w3", [0.5, -0.3])
def test_rate_gyro_cross_coupling_and_anisoinertia_error(w3):
    """Input rate w1 with a spin-axis rate w3: linearizing k theta = wg1 (H + (J3 - J1) wg3),
    wg1 = w1 cos - w3 sin, wg3 = w1 sin + w3 cos, gives
    theta_ss = (H w1 + (J3 - J1) w1 w3) / (k + H w3 + (J3 - J1) (w3^2 - w1^2)): the spin-axis
    rate changes the scale factor (cross-coupling, -H w3 theta) and the anisoinertia adds
    (J3 - J1) w1 w3.  The simulated error against H w1 / k matches this to the neglected
    O(theta^3) (bounded here by theta^3), and each term is far above that bound."""
    w1, k = 0.01, 0.9
    gyro = _gyro(c=2 * 0.7 * math.sqrt(k * J2))
    theta = propagate_single_axis(gyro, constant_base_rate([w1, 0.0, w3]), np.array([0.0, 0.6]))[0][-1, 0]
    predicted = (H * w1 + DJ * w1 * w3) / (k + H * w3 + DJ * (w3**2 - w1**2))
    ideal = H * w1 / k
    assert abs(theta - predicted) <= abs(ideal) ** 3
    cross = H * w1 / (k + H * w3) - ideal
    aniso = predicted - H * w1 / (k + H * w3)
    assert abs(cross) > 1e3 * abs(ideal) ** 3 and abs(aniso) > 10 * abs(ideal) ** 3
    assert abs(steady_state_angle(gyro, [w1, 0.0, w3]) - theta) < 1e-13  # the exact balance, solved


@pytest.mark.parametrize("free_rotor", [False, True])
def test_single_axis_matches_independent_newton_euler(free_rotor):
    """Large base rates about all three axes at once (theta up to ~0.2 rad): the gimbal
    angle, its rate and the rotor's spin agree with the Newton-Euler chain (gimbal about b2,
    rotor about g3 in its own spinning frame) to 1e-9 -- so every cross-coupling term of the
    module's equation is right, not only the textbook ones.  Also: the error torques it names
    are exactly the terms the ideal equation drops (theta'' from the chain)."""
    gyro = _gyro(free_rotor=free_rotor)
    t = np.linspace(0.0, 0.8, 161)
    s = propagate_single_axis(gyro, _rich_base, t, theta0=0.05, theta_dot0=-0.3, rtol=1e-12, atol=1e-14)[0]
    chain = _gyro_chain(gyro, _rich_base, regulated=not free_rotor)
    ref = chain.integrate(np.array([0.05, 0.0]), np.array([-0.3, SPIN]), t)
    assert np.max(np.abs(s[:, 0])) > 0.05
    np.testing.assert_allclose(s[:, 0], ref[:, 0], rtol=0, atol=1e-9)
    np.testing.assert_allclose(s[:, 1], ref[:, 2], rtol=0, atol=1e-8)
    np.testing.assert_allclose(s[:, 2], ref[:, 3], rtol=1e-12, atol=1e-8)
    if free_rotor:
        assert np.ptp(s[:, 2]) > 0.1  # the free rotor's spin really changes
    # the named error torques close the ideal equation exactly
    W = np.array([_rich_base(x)[0] for x in t])
    Wd = np.array([_rich_base(x)[1] for x in t])
    thdd = np.array([chain.accel(x, r[:2], r[2:])[0] for x, r in zip(t, ref)])
    err = error_torques(gyro, s, W, Wd)
    lhs = J2 * thdd + gyro.damping * s[:, 1] + gyro.spring * s[:, 0] - H * W[:, 0]
    np.testing.assert_allclose(lhs, sum(err.values()), rtol=0, atol=1e-9 * np.max(np.abs(lhs)))
    for name in ("cross_coupling", "output_acceleration", "anisoinertia"):
        assert np.max(np.abs(err[name])) > 1e-4 * np.max(np.abs(lhs)), name


def test_single_axis_rates_function_matches_chain_pointwise():
    """single_axis_rates (the public right-hand side) against the chain's acceleration at
    scattered states and times, both rotor modes."""
    rng = np.random.default_rng(7)
    for free_rotor in (False, True):
        gyro = _gyro(free_rotor=free_rotor)
        chain = _gyro_chain(gyro, _rich_base, regulated=not free_rotor)
        for _ in range(20):
            th, thd, spin, tt = rng.uniform(-1.2, 1.2), rng.uniform(-3, 3), rng.uniform(500, 3000), rng.uniform(0, 2)
            d = single_axis_rates(gyro, tt, [th, thd, spin], _rich_base)
            qdd = chain.accel(tt, np.array([th, 0.4]), np.array([thd, spin]))
            assert d[0] == thd
            assert abs(d[1] - qdd[0]) <= 1e-9 * max(1.0, abs(qdd[0]))
            assert abs(d[2] - qdd[1]) <= 1e-9 * max(1.0, abs(qdd[1]))


def test_conservation_base_at_rest_and_jacobi_integral_of_a_turning_base():
    """No damper, free rotor.  Base at rest (no spring either): the energy, the momentum
    about the output axis (the bearings take the rest) and |H| are conserved; H itself turns
    with the gimbal.  Base turning at a constant rate about all three axes, with the spring:
    the energy is not conserved but the Jacobi integral is (the Lagrangian in the case's
    coordinates is time-independent), to the integrator's tolerance."""
    gyro = SingleAxisGyro(C_ROT, A_ROT, SPIN, GIMBAL, 0.0, 0.0, free_rotor=True)
    t = np.linspace(0.0, 1.0, 101)
    zero = np.zeros(3)
    s = propagate_single_axis(gyro, constant_base_rate(zero), t, theta_dot0=2.0)[0]
    e = single_axis_energy(gyro, s, zero)
    Hb = single_axis_momentum(gyro, s, zero)
    assert np.max(np.abs(e / e[0] - 1)) < 1e-12
    assert np.max(np.abs(Hb[:, 1] - J2 * 2.0)) < 1e-12 * H
    assert np.max(np.abs(np.linalg.norm(Hb, axis=1) / math.hypot(J2 * 2.0, H) - 1)) < 1e-12
    assert np.ptp(Hb[:, 0]) > 0.1 * H  # the rotor's momentum turns with the gimbal
    # turning base: Jacobi integral
    w = np.array([0.4, -0.7, 0.9])
    gyro_k = SingleAxisGyro(C_ROT, A_ROT, SPIN, GIMBAL, 0.9, 0.0, free_rotor=True)
    s = propagate_single_axis(gyro_k, constant_base_rate(w), t, theta0=0.1, theta_dot0=1.0, rtol=1e-12, atol=1e-14)[0]
    jac = single_axis_jacobi_integral(gyro_k, s, w)
    e = single_axis_energy(gyro_k, s, w)
    assert np.max(np.abs(jac - jac[0])) < 1e-11 * abs(e[0])
    assert np.ptp(e) > 1e-6 * abs(e[0])  # the energy really changes: the test is not vacuous
    # and the chain's energy agrees with the module's energy on the same states
    chain = _gyro_chain(gyro_k, constant_base_rate(w), regulated=False)
    for x, r in zip(t[::25], s[::25]):
        ec = chain.energy(x, np.array([r[0], 0.0]), np.array([r[1], r[2]])) + 0.5 * 0.9 * r[0] ** 2
        assert abs(ec - single_axis_energy(gyro_k, r, w)) < 1e-13 * abs(ec)


def test_sampled_base_rate_from_an_attitude_model():
    """Driving the gyro with an astrodyn attitude model's output: the exact torque-free
    rates of an asymmetric body (astrodyn.attitude.torque_free), sampled and splined, with
    the case mounted so its input axis is the body's axis 2.  Reference: the same gyro
    driven by the exact rates and Euler's-equation rates w' = f(w), through the mounting
    permutation.  Agreement to the spline's accuracy."""
    from astrodyn.attitude import torque_free

    Ib = np.array([1.0, 2.0, 2.5])
    w0 = np.array([0.3, 0.8, 0.2])
    ts = np.linspace(0.0, 1.0, 401)
    wb = torque_free(Ib, w0, [1.0, 0, 0, 0], ts)[0]
    mount = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])  # case (I, O, S) = body (2, 3, 1)
    base = sampled_base_rate(ts, wb, mount)

    def exact(t):
        w = torque_free(Ib, w0, [1.0, 0, 0, 0], float(t))[0]
        wd = np.array(
            [
                (Ib[1] - Ib[2]) * w[1] * w[2] / Ib[0],
                (Ib[2] - Ib[0]) * w[2] * w[0] / Ib[1],
                (Ib[0] - Ib[1]) * w[0] * w[1] / Ib[2],
            ]
        )
        return mount @ w, mount @ wd

    for x in (0.1234, 0.5, 0.987):
        np.testing.assert_allclose(base(x)[0], exact(x)[0], atol=1e-9)
        np.testing.assert_allclose(base(x)[1], exact(x)[1], atol=1e-6)
    gyro = SingleAxisGyro.rate_integrating(C_ROT, A_ROT, SPIN, 9e-3, GIMBAL)
    t = np.linspace(0.0, 1.0, 21)
    a = propagate_single_axis(gyro, base, t)[0]
    b = propagate_single_axis(gyro, exact, t)[0]
    assert np.max(np.abs(a[:, 0])) > 1e-2
    np.testing.assert_allclose(a[:, 0], b[:, 0], atol=1e-8)


# --------------------------------------------------------------------------- 4. free gyroscope


FREE = FreeGyroscope(C_ROT, A_ROT, inner_gimbal=(2e-5, 3e-5, 2e-5), outer_gimbal=1e-5)
A_I, A_O = A_ROT + 2e-5, 1e-5 + A_ROT + 3e-5  # 8e-5, 1e-4 kg m^2


def _nutation(gyro, spin, u, theta0=0.5 * math.pi, periods=8, per=200):
    """Simulated nutation after an inner-gimbal rate u: frequency from the spacing of the
    extrema of theta (zeros of theta'), the theta amplitude and the psi half-swing."""
    h = gyro.rotor_axial * spin
    wlin = nutation_frequency(gyro, h, theta0)
    t = np.linspace(0.0, periods * 2 * math.pi / wlin, periods * per + 1)
    s, info = propagate_free_gyro(
        gyro, free_gyro_state(gyro, spin, theta=theta0, theta_dot=u), t, rtol=1e-12, atol=1e-15
    )
    tx, th = _extrema(t, s[:, 1], s[:, 4])
    _, ps = _extrema(t, s[:, 0], s[:, 3])
    freq = math.pi / np.mean(np.diff(tx))
    return freq, 0.5 * np.mean(np.abs(np.diff(th))), 0.5 * np.mean(np.abs(np.diff(ps))), info


def test_free_gyro_nutation_frequency_and_amplitude_converge_to_fast_rotor_closed_form():
    """Inner gimbal struck (theta'(0) = u) at the working attitude theta = pi/2: nutation
    frequency C n / sqrt(A_i A_o), theta amplitude u / omega_n, psi half-swing A_i u / (C n)
    (module docstring derivation; A_i, A_o from the inertias by hand here).  The neglected
    terms are cubic, so each relative error must fall ~4x per doubling of the spin and stay
    below a few times the squared amplitude."""
    u = 1.0
    errs = []
    for n in (100.0, 200.0, 400.0, 800.0):
        h = C_ROT * n
        w_fast = h / math.sqrt(A_I * A_O)
        freq, amp_th, amp_psi, info = _nutation(FREE, n, u)
        amp = u / w_fast
        e = (abs(freq / w_fast - 1), abs(amp_th / amp - 1), abs(amp_psi / (A_I * u / h) - 1))
        assert max(e) < 2.0 * amp**2, (n, e, amp)
        assert info["energy_drift"] < 1e-11 and info["h_drift"] < 1e-11 and info["p_psi_drift"] < 1e-11
        errs.append(e)
    errs = np.array(errs)
    for j in range(3):
        ratios = errs[:-1, j] / errs[1:, j]
        assert np.all((ratios > 3.0) & (ratios < 5.0)), (j, ratios)
    assert fast_rotor_nutation_frequency(FREE, 100.0) == pytest.approx(C_ROT * 100.0 / math.sqrt(A_I * A_O), rel=1e-15)


def test_free_gyro_nutation_off_the_working_attitude_follows_exact_linearization():
    """At theta0 = pi/6 the fast-rotor formula is wrong by sin(theta0) sqrt(A_o / M(theta0))
    (here 0.73: 27 %); the simulation follows the exact linearized h sin(theta0) / sqrt(A_i
    M(theta0)), M(theta0) = I_o + (A + B2) sin^2 + B3 cos^2 written out here, converging as
    the spin grows (error O(amplitude) there: M is not even about theta0)."""
    th0 = math.pi / 6
    M0 = 1e-5 + (A_ROT + 3e-5) * math.sin(th0) ** 2 + 2e-5 * math.cos(th0) ** 2
    errs = []
    for n in (200.0, 800.0):
        h = C_ROT * n
        w_exact = h * math.sin(th0) / math.sqrt(A_I * M0)
        assert nutation_frequency(FREE, h, th0) == pytest.approx(w_exact, rel=1e-14)
        freq, _, _, _ = _nutation(FREE, n, 0.5, theta0=th0)
        errs.append(abs(freq / w_exact - 1))
        factor = math.sin(th0) * math.sqrt(A_O / M0)
        assert abs(freq / fast_rotor_nutation_frequency(FREE, n) / factor - 1) < 1e-3
        assert factor < 0.75
    assert errs[1] < errs[0] / 3 and errs[1] < 1e-5


def test_massless_gimbals_exact_free_symmetric_rotor():
    """Massless gimbals: the rotor is a free symmetric body, its spin axis cones about the
    constant H at |H| / A for any amplitude.  A large nutation (cone half-angle
    atan(A u / (C n)) = 17 deg): the gimbal-angle period is 2 pi A / |H| to 1e-9 and the
    whole angular momentum vector is constant, although the gimbal angles swing widely."""
    gyro = FreeGyroscope(C_ROT, A_ROT)
    n, u = 300.0, 150.0
    Hmag = math.hypot(A_ROT * u, C_ROT * n)
    period = 2 * math.pi * A_ROT / Hmag
    t = np.linspace(0.0, 6 * period, 6 * 400 + 1)
    s, info = propagate_free_gyro(gyro, free_gyro_state(gyro, n, theta_dot=u), t, rtol=1e-12, atol=1e-15)
    tx, th = _extrema(t, s[:, 1], s[:, 4])
    assert abs(2 * np.mean(np.diff(tx)) / period - 1) < 1e-9
    assert np.ptp(s[:, 1]) > 0.5
    Hn = free_gyro_momentum(gyro, s)
    assert np.max(np.abs(Hn - Hn[0])) < 1e-11 * Hmag
    assert abs(np.linalg.norm(Hn[0]) / Hmag - 1) < 1e-14
    # the ideal C n / A is off by the second-order factor |H| / (C n)
    assert abs(fast_rotor_nutation_frequency(gyro, n) / (Hmag / A_ROT) - 1) > 1e-2


def test_free_gyro_constant_torque_precession_matches_closed_form():
    """A constant torque Q about the inner axis: the gyro precesses about the outer axis at
    the mean rate Q / h while the inner angle dips by Q A_o / h^2 (1 - cos omega_n t), both
    to a relative error falling with the spin; and the whole trajectory follows
    free_gyro_linear's formulas, which are checked against hand-derived special cases."""
    Q = 2e-3
    rel = []
    for n in (200.0, 800.0):
        h = C_ROT * n
        wn = h / math.sqrt(A_I * A_O)
        T = 2 * math.pi / wn
        t = np.linspace(0.0, 10 * T, 2001)
        s, _ = propagate_free_gyro(
            FREE, free_gyro_state(FREE, n), t, torques=lambda _t, _y: (0.0, Q, 0.0), rtol=1e-12, atol=1e-15
        )
        mean_rate = s[-1, 0] / t[-1]  # whole periods: the oscillating part of psi is back to 0
        rel.append(abs(mean_rate / (Q / h) - 1))
        hand = Q * A_O / h**2 * (1 - np.cos(wn * t))
        dpsi, delta = free_gyro_linear(FREE, h, t, inner_torque=Q)
        np.testing.assert_allclose(delta, hand, atol=1e-12 * Q * A_O / h**2)
        np.testing.assert_allclose(dpsi, Q / h * (t - np.sin(wn * t) / wn), atol=1e-9 * Q / h * t[-1])
        scale = Q * A_O / h**2
        assert np.max(np.abs(s[:, 1] - 0.5 * math.pi - delta)) < 50 * scale**2 + 1e-12
    assert rel[1] < rel[0] / 10 and rel[1] < 1e-5


def test_free_gyro_linear_general_case_against_integration_of_linear_equations():
    """free_gyro_linear with every input at once (rates, both torques, theta0 != pi/2)
    against a direct integration of the linearized equations M0 psi'' = g delta' + Q_psi,
    A_i delta'' = -g psi' + Q_theta (written here)."""
    h, th0, u, v, qt, qp = 0.05, 1.1, 0.3, -0.2, 1e-3, -2e-3
    M0 = 1e-5 + (A_ROT + 3e-5) * math.sin(th0) ** 2 + 2e-5 * math.cos(th0) ** 2
    g = h * math.sin(th0)
    t = np.linspace(0.0, 0.05, 51)
    sol = solve_ivp(
        lambda _t, y: [y[2], y[3], (g * y[3] + qp) / M0, (-g * y[2] + qt) / A_I],
        (0, t[-1]),
        [0.0, 0.0, v, u],
        method="DOP853",
        t_eval=t,
        rtol=1e-13,
        atol=1e-16,
    )
    dpsi, delta = free_gyro_linear(FREE, h, t, theta0=th0, inner_rate=u, outer_rate=v, inner_torque=qt, outer_torque=qp)
    np.testing.assert_allclose(dpsi, sol.y[0], atol=1e-11)
    np.testing.assert_allclose(delta, sol.y[1], atol=1e-11)


def test_free_gyro_matches_independent_newton_euler_chain():
    """Massive gimbals, large motion with all three torques (spring-like outer torque,
    inner damping, a spin motor), against the three-body Newton-Euler chain (outer gimbal
    about n3, inner about o1, rotor about i3 in its own spinning frame).  The free case also
    conserves energy, p_psi and h to the integrator's tolerance."""

    def torques(_t, y):
        return (-0.02 * y[0], -1e-4 * y[4], 1e-4 * math.cos(3.0 * _t))

    t = np.linspace(0.0, 0.3, 61)
    y0 = free_gyro_state(FREE, 100.0, theta=1.2, psi=0.1, psi_dot=10.0, theta_dot=-15.0)
    s, _ = propagate_free_gyro(FREE, y0, t, torques=torques, rtol=1e-12, atol=1e-14)
    zero = (np.zeros(3), np.zeros(3))
    chain = _Chain(
        [3, 1, 3],
        [(0.7e-5, 0.6e-5, 1e-5), (2e-5, 3e-5, 2e-5), (A_ROT, A_ROT, C_ROT)],
        lambda _t: zero,
        lambda tt, q, qd: torques(tt, [q[0], q[1], q[2], qd[0], qd[1], qd[2]]),
    )
    ref = chain.integrate(y0[:3], y0[3:], t)
    assert np.ptp(s[:, 1]) > 0.2 and np.ptp(s[:, 0]) > 0.2
    np.testing.assert_allclose(s[:, :2], ref[:, :2], atol=1e-9)
    np.testing.assert_allclose(s[:, 3:5], ref[:, 3:5], atol=1e-7)
    np.testing.assert_allclose(s[:, 5], ref[:, 5], rtol=1e-11)
    # torque-free: conservation, and the energy equals the chain's
    s, info = propagate_free_gyro(FREE, y0, t, rtol=1e-12, atol=1e-14)
    E, p, hh = free_gyro_integrals(FREE, s)
    assert np.max(np.abs(E / E[0] - 1)) < 1e-11
    assert np.max(np.abs(p - p[0])) < 1e-11 * abs(hh[0]) and np.max(np.abs(hh / hh[0] - 1)) < 1e-12
    assert info["energy_drift"] < 1e-11
    for y in s[::20]:
        assert abs(chain.energy(0.0, y[:3], y[3:]) / free_gyro_energy_scalar(y) - 1) < 1e-13
    np.testing.assert_allclose(free_gyro_momentum(FREE, s)[:, 2], p, rtol=1e-13)


def test_free_gyro_rates_function_matches_chain_pointwise():
    """free_gyro_rates (the public right-hand side) against the three-body chain's
    accelerations at scattered states, torques included, away from gimbal lock."""
    rng = np.random.default_rng(11)
    for _ in range(30):
        y = np.array(
            [
                rng.uniform(-3, 3),
                rng.uniform(0.3, 2.8),
                rng.uniform(-3, 3),
                rng.uniform(-20, 20),
                rng.uniform(-20, 20),
                rng.uniform(-500, 500),
            ]
        )
        q = tuple(rng.uniform(-1e-3, 1e-3, 3))
        chain = _Chain(
            [3, 1, 3],
            [(0.7e-5, 0.6e-5, 1e-5), (2e-5, 3e-5, 2e-5), (A_ROT, A_ROT, C_ROT)],
            lambda _t: (np.zeros(3), np.zeros(3)),
            lambda _t, _q, _qd, q=q: q,
        )
        d = free_gyro_rates(FREE, 0.0, y, torques=lambda _t, _y, q=q: q)
        np.testing.assert_array_equal(d[:3], y[3:])
        ref = chain.accel(0.0, y[:3], y[3:])
        np.testing.assert_allclose(d[3:], ref, rtol=1e-9, atol=1e-9 * np.max(np.abs(ref)))


def free_gyro_energy_scalar(y):
    return float(free_gyro_integrals(FREE, y)[0])


# --------------------------------------------------------------------------- 5. hostile inputs


def _bad_base(t):
    return np.zeros(2), np.zeros(3)


def _nan_later(t):
    return (np.array([math.nan if t > 0.01 else 0.0, 0.0, 0.0]), np.zeros(3))


_G = SingleAxisGyro(C_ROT, A_ROT, SPIN, GIMBAL, 0.9, 1e-3)
_B = constant_base_rate([0.01, 0, 0])
_T = np.linspace(0, 0.1, 5)

HOSTILE = [
    ("spin_inertia", lambda: SingleAxisGyro(math.nan, A_ROT, SPIN)),
    ("spin_inertia", lambda: SingleAxisGyro(-1e-4, A_ROT, SPIN)),
    ("spin_inertia", lambda: SingleAxisGyro(math.inf, A_ROT, SPIN)),
    ("spin_inertia", lambda: SingleAxisGyro("1e-4", A_ROT, SPIN)),  # strings are not numbers here
    ("spin_inertia", lambda: SingleAxisGyro(None, A_ROT, SPIN)),
    ("spin_inertia", lambda: SingleAxisGyro(3e-4, 1e-4, SPIN)),  # C > 2 A
    ("transverse_inertia", lambda: SingleAxisGyro(C_ROT, 0.0, SPIN)),
    ("transverse_inertia", lambda: SingleAxisGyro(C_ROT, [1e-4, 2e-4], SPIN)),
    ("spin_rate", lambda: SingleAxisGyro(C_ROT, A_ROT, math.nan)),
    ("spin_rate", lambda: SingleAxisGyro(C_ROT, A_ROT, -math.inf)),
    ("spin_rate", lambda: SingleAxisGyro(C_ROT, A_ROT, 1e200)),  # C Omega^2 overflows
    ("gimbal_inertia", lambda: SingleAxisGyro(C_ROT, A_ROT, SPIN, (1e-5, 1e-5))),
    ("gimbal_inertia", lambda: SingleAxisGyro(C_ROT, A_ROT, SPIN, (1e-5, -1e-5, 1e-5))),
    ("gimbal_inertia", lambda: SingleAxisGyro(C_ROT, A_ROT, SPIN, (1e-5, math.nan, 1e-5))),
    ("gimbal_inertia", lambda: SingleAxisGyro(C_ROT, A_ROT, SPIN, (1e-5, 1e-5, 5e-5))),  # triangle
    ("gimbal_inertia", lambda: SingleAxisGyro(C_ROT, A_ROT, SPIN, "abc")),
    ("gimbal_inertia", lambda: SingleAxisGyro(C_ROT, A_ROT, SPIN, ["1e-5", "1e-5", "1e-5"])),
    ("state0", lambda: propagate_free_gyro(FREE, [True] * 6, _T)),
    ("spring", lambda: SingleAxisGyro(C_ROT, A_ROT, SPIN, spring=-1.0)),
    ("spring", lambda: SingleAxisGyro(C_ROT, A_ROT, SPIN, spring=math.nan)),
    ("damping", lambda: SingleAxisGyro(C_ROT, A_ROT, SPIN, damping=-1e-3)),
    ("damping", lambda: SingleAxisGyro(C_ROT, A_ROT, SPIN, damping=math.inf)),
    ("free_rotor", lambda: SingleAxisGyro(C_ROT, A_ROT, SPIN, free_rotor="yes")),
    ("spring", lambda: SingleAxisGyro.rate_gyro(C_ROT, A_ROT, SPIN, 0.0, 1e-3)),
    ("damping", lambda: SingleAxisGyro.rate_integrating(C_ROT, A_ROT, SPIN, 0.0)),
    ("spring", lambda: SingleAxisGyro(C_ROT, A_ROT, SPIN).rate_sensitivity),
    ("base", lambda: propagate_single_axis(_G, "not callable", _T)),
    ("base", lambda: propagate_single_axis(_G, _bad_base, _T)),
    ("base", lambda: propagate_single_axis(_G, lambda t: None, _T)),
    ("base", lambda: propagate_single_axis(_G, _nan_later, _T)),
    ("t", lambda: propagate_single_axis(_G, _B, [])),
    ("t", lambda: propagate_single_axis(_G, _B, [0.1, 0.2])),
    ("t", lambda: propagate_single_axis(_G, _B, [0.0, 0.2, 0.1])),
    ("t", lambda: propagate_single_axis(_G, _B, [0.0, math.nan])),
    ("t", lambda: propagate_single_axis(_G, _B, [0.0, math.inf])),
    ("theta0", lambda: propagate_single_axis(_G, _B, _T, theta0=math.nan)),
    ("theta_dot0", lambda: propagate_single_axis(_G, _B, _T, theta_dot0="1")),
    ("spin0", lambda: propagate_single_axis(_G, _B, _T, spin0=math.inf)),
    ("rtol", lambda: propagate_single_axis(_G, _B, _T, rtol=0.0)),
    ("rtol", lambda: propagate_single_axis(_G, _B, _T, rtol=1e-20)),
    ("atol", lambda: propagate_single_axis(_G, _B, _T, atol=-1.0)),
    ("max_nfev", lambda: propagate_single_axis(_G, _B, _T, max_nfev=0)),
    ("max_nfev", lambda: propagate_single_axis(_G, _B, _T, max_nfev=1.5)),
    ("gyro", lambda: propagate_single_axis(FREE, _B, _T)),
    ("torquer", lambda: propagate_single_axis(_G, _B, _T, torquer=lambda t, y: math.nan)),
    ("torquer", lambda: propagate_single_axis(_G, _B, _T, torquer=3.0)),
    ("state", lambda: single_axis_rates(_G, 0.0, [0.0, 0.0], _B)),
    ("state", lambda: single_axis_rates(_G, 0.0, [0.0, math.nan, SPIN], _B)),
    ("w", lambda: constant_base_rate([0.0, 0.0])),
    ("w", lambda: constant_base_rate([0.0, math.nan, 0.0])),
    ("w", lambda: steady_state_angle(_G, [0.0, 0.0, math.inf])),
    ("states", lambda: single_axis_energy(_G, np.zeros((4, 2)), np.zeros(3))),
    ("w", lambda: steady_state_angle(_G, [0.01, 0.0, -10.0])),  # H w3 = -2 < -k: no stable root
    ("w", lambda: error_torques(_G, np.zeros((4, 3)), np.zeros((4, 2)), np.zeros((4, 3)))),
    ("times", lambda: sampled_base_rate([0.0, 1.0, 2.0], np.zeros((3, 3)))),
    ("times", lambda: sampled_base_rate([0.0, 1.0, 1.0, 2.0], np.zeros((4, 3)))),
    ("rates", lambda: sampled_base_rate([0.0, 1.0, 2.0, 3.0], np.zeros((4, 2)))),
    ("rates", lambda: sampled_base_rate([0.0, 1.0, 2.0, 3.0], np.full((4, 3), math.nan))),
    ("mount", lambda: sampled_base_rate([0.0, 1.0, 2.0, 3.0], np.zeros((4, 3)), 2.0 * np.eye(3))),
    ("mount", lambda: sampled_base_rate([0.0, 1.0, 2.0, 3.0], np.zeros((4, 3)), -np.eye(3))),
    ("rotor_axial", lambda: FreeGyroscope(0.0, A_ROT)),
    ("rotor_axial", lambda: FreeGyroscope(math.nan, A_ROT)),
    ("rotor_transverse", lambda: FreeGyroscope(C_ROT, -A_ROT)),
    ("inner_gimbal", lambda: FreeGyroscope(C_ROT, A_ROT, (1e-5, 1e-5, 1e-5, 1e-5))),
    ("inner_gimbal", lambda: FreeGyroscope(C_ROT, A_ROT, (1e-5, -1e-5, 1e-5))),
    ("outer_gimbal", lambda: FreeGyroscope(C_ROT, A_ROT, outer_gimbal=-1.0)),
    ("outer_gimbal", lambda: FreeGyroscope(C_ROT, A_ROT, outer_gimbal=math.inf)),
    ("state0", lambda: propagate_free_gyro(FREE, np.zeros(5), _T)),
    ("state0", lambda: propagate_free_gyro(FREE, [0, 1.5, 0, 0, math.nan, 100], _T)),
    ("state0", lambda: propagate_free_gyro(FreeGyroscope(C_ROT, A_ROT), [0, 0.0, 0, 0, 0, 100], _T)),  # lock
    ("torques", lambda: propagate_free_gyro(FREE, free_gyro_state(FREE, 100.0), _T, torques=lambda t, y: (1, 2))),
    ("torques", lambda: propagate_free_gyro(FREE, free_gyro_state(FREE, 100.0), _T, torques="x")),
    ("t", lambda: propagate_free_gyro(FREE, free_gyro_state(FREE, 100.0), [1.0])),
    ("gyro", lambda: propagate_free_gyro(_G, free_gyro_state(FREE, 100.0), _T)),
    ("spin", lambda: free_gyro_state(FREE, math.nan)),
    ("theta", lambda: free_gyro_state(FREE, 100.0, theta=math.inf)),
    ("h", lambda: free_gyro_linear(FREE, 0.0, _T)),
    ("h", lambda: nutation_frequency(FREE, math.nan)),
    ("theta0", lambda: nutation_frequency(FreeGyroscope(C_ROT, A_ROT), 1.0, 0.0)),
    ("inner_torque", lambda: free_gyro_linear(FREE, 1.0, _T, inner_torque=math.nan)),
    ("states", lambda: free_gyro_integrals(FREE, np.zeros((3, 5)))),
]


@pytest.mark.parametrize("field, call", HOSTILE, ids=[f"{i}-{f}" for i, (f, _) in enumerate(HOSTILE)])
def test_hostile_inputs_raise_value_error_naming_the_field(field, call):
    assert_refused_quickly(call, rf"\b{field}\b")


def test_bounded_time_on_an_endless_span():
    """A span of 1e12 s stops after max_nfev evaluations with a RuntimeError, quickly."""
    start = time.perf_counter()
    with pytest.raises(RuntimeError, match="max_nfev"):
        propagate_single_axis(_G, _B, [0.0, 1e12], max_nfev=2000)
    with pytest.raises(RuntimeError, match="max_nfev"):
        propagate_free_gyro(FREE, free_gyro_state(FREE, 100.0, theta_dot=1.0), [0.0, 1e12], max_nfev=2000)
    assert time.perf_counter() - start < 5.0
