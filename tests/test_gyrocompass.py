"""Gyrocompass (astrodyn.attitude.gyrocompass) against Baruh sec. 10.7's period.

The simulated swing of the spin axis (symplectic 4th-order splitting of the
reduced equation) is checked against closed forms that share no code with the
integrator: Baruh's small-swing period 2 pi sqrt(I / (J s Omega_E cos lat)), its
latitude dependence, the exact large-swing pendulum period 4 K(m) / w_n, and the
conservation of the swing's energy integral.
"""

import math

import numpy as np
import pytest

from astrodyn.attitude.gyrocompass import Gyrocompass

# a marine-gyrocompass-like toy: rotor 0.02 kg m^2 at 2000 rad/s, gimbal 0.05 kg m^2
GYRO = dict(gimbal_inertia=0.05, rotor_inertia=0.02, spin=2000.0)


def measured_period(gc, alpha0, periods, step_fraction=200, samples=400):
    """Mean period from the zero crossings of alpha (linear interpolation between samples)."""
    T0 = gc.baruh_period()
    t = np.arange(1, int(periods * samples) + 1) * (T0 / samples)
    alpha, _ = gc.simulate(alpha0, 0.0, t, step=T0 / step_fraction)
    idx = np.nonzero(np.sign(alpha[1:]) != np.sign(alpha[:-1]))[0]
    tc = t[idx] - alpha[idx] * (t[idx + 1] - t[idx]) / (alpha[idx + 1] - alpha[idx])
    return 2.0 * (tc[-1] - tc[0]) / (len(tc) - 1)


@pytest.mark.parametrize("lat_deg", [0.0, 45.0, 70.0])
def test_small_swing_period_matches_baruh(lat_deg):
    gc = Gyrocompass(latitude=math.radians(lat_deg), **GYRO)
    T = measured_period(gc, 1e-3, periods=6)
    # differences from Baruh's formula: amplitude (alpha0^2/16 = 6e-8), h = J (s + Omega_E
    # cos lat) instead of J s (Omega_E / s = 4e-8); integration at T/200 (4th order,
    # phase error ~ (2 pi / 200)^4 / 100 ~ 1e-8 per period); linear interpolation of
    # crossings sampled at T/400 where alpha'' = 0: < 1e-9.  The first two add up to
    # +6.3e-8 - 1.8e-8 (lat 0); measured 4.4e-8 .. 5.6e-8.  Bound 3e-7.
    assert abs(T / gc.baruh_period() - 1.0) < 3e-7


def test_period_latitude_dependence():
    # T ~ 1 / sqrt(cos lat): at 60 deg the simulated swing is sqrt(2) slower than at
    # the equator (Baruh 10.7); each measured period is within ~1e-7 of its formula
    # (see above), the ratio within 2x that plus the h = J (s + Omega_E cos lat) term
    T0 = measured_period(Gyrocompass(latitude=0.0, **GYRO), 1e-3, periods=4)
    T60 = measured_period(Gyrocompass(latitude=math.radians(60.0), **GYRO), 1e-3, periods=4)
    assert abs(T60 / T0 - math.sqrt(2.0)) < 1e-6
    # about 31 s at 45 deg for this toy (north-seeking is slow next to the 3 ms spin period)
    assert 25 < Gyrocompass(latitude=math.radians(45.0), **GYRO).baruh_period() < 40


@pytest.mark.parametrize("amplitude", [0.5, 2.0, 3.0])
def test_large_swing_period_matches_elliptic_closed_form(amplitude):
    gc = Gyrocompass(latitude=math.radians(30.0), **GYRO)
    T_exact = gc.period(amplitude)
    T = measured_period(gc, amplitude, periods=4, step_fraction=2000, samples=4000)
    # step T0/2000: phase error ~ (2 pi / 2000)^4 ~ 1e-10 per period (larger near the
    # separatrix at 3 rad, where the motion lingers at the top); crossings at the
    # steepest point of the swing, interpolation error ~ (dt)^2 alpha''' / alpha' ~ 1e-12;
    # measured <= 8e-13
    assert abs(T / T_exact - 1.0) < 1e-10
    assert T_exact > gc.period(1e-3)  # longer than the small-swing period (pendulum)


def test_energy_integral_bounded():
    gc = Gyrocompass(latitude=math.radians(45.0), inertia_difference=0.01, **GYRO)
    T0 = gc.baruh_period()
    t = np.linspace(0.0, 20 * T0, 2001)[1:]
    alpha, alpha_dot = gc.simulate(1.0, 0.0, t)
    h = gc.axial_momentum(1.0)
    e0 = gc.energy(1.0, 0.0, h)
    e = gc.energy(alpha, alpha_dot, h)
    scale = h * gc.horizontal_earth_rate  # size of the potential term
    # symplectic 4th order at T/200: bounded energy error ~ (2 pi/200)^4 ~ 1e-6 x scale
    # at most (measured 8.6e-9); no secular drift over 20 periods (second half no worse
    # than 2x the first)
    de = np.abs(e - e0) / scale
    assert np.max(de) < 1e-7
    assert np.max(de[1000:]) < 2 * np.max(de[:1000]) + 1e-15


@pytest.mark.parametrize(
    "kwargs, msg",
    [
        (dict(latitude=math.pi / 2), "latitude"),
        (dict(latitude=0.1, gimbal_inertia=-1.0), "gimbal_inertia"),
        (dict(latitude=0.1, spin=math.nan), "spin"),
    ],
)
def test_bad_parameters(kwargs, msg):
    args = dict(GYRO)
    args.update(kwargs)
    with pytest.raises(ValueError, match=msg):
        Gyrocompass(**args)
    gc = Gyrocompass(latitude=0.1, **GYRO)
    with pytest.raises(ValueError, match="t:"):
        gc.simulate(0.1, 0.0, [2.0, 1.0])
