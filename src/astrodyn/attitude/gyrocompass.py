"""The gyrocompass: a gyroscope on the rotating Earth whose spin axis is held horizontal
(H. Baruh, *Analytical Dynamics*, sec. 10.7).

Model.  A rotor (axial moment ``J``, kg m^2) spins at ``s`` rad/s relative to a
gimbal that can turn only about the local vertical (``s`` is the relative spin in the
initial state: the axial momentum ``h`` below is what stays constant, so the relative
spin changes slightly as the axis swings); the gimbal + rotor assembly
has moment ``I`` about that vertical axis (kg m^2).  The Earth turns at
``Omega_E`` rad/s; at geodetic latitude ``lat`` its rate has local components
``Omega_E (0, cos lat, sin lat)`` (east, north, up).  ``alpha`` is the azimuth of
the spin axis, measured from north towards east.  The gimbal frame ``F``
(``f1 = (sin alpha, cos alpha, 0)`` = spin axis, ``f2 = up x f1 = (-cos alpha, sin alpha, 0)``,
``f3`` = up, in east-north-up components) turns relative to the ground at ``-alpha'``
about up (``df1/dt = alpha' (cos alpha, -sin alpha, 0) = -alpha' f2``: a growing azimuth
turns it clockwise seen from above), so in inertial space at ``Omega_E - alpha' f3``,
whose components are ``Omega_E cos(lat) cos(alpha)``, ``Omega_E cos(lat) sin(alpha)``,
``Omega_E sin(lat) - alpha'``.  The kinetic energy

    T = I/2 (alpha' - Omega_E sin lat)^2 + J/2 (phi' + Omega_E cos lat cos alpha)^2
        + dI/2 (Omega_E cos lat)^2 sin^2 alpha

(``phi`` the rotor angle, ``dI = I_2 - I_1`` the difference of the assembly's
non-spinning moments about ``f2`` and ``f1``, default 0) has the cyclic rotor
angle: the absolute axial momentum ``h = J (phi' + Omega_E cos lat cos alpha)`` is
constant (frictionless spin bearing), and Lagrange's equation for ``alpha`` is (the
term of ``T`` linear in ``alpha'``, ``-I alpha' Omega_E sin lat``, has a constant
coefficient and drops out of it, whatever its sign)

    I alpha'' = -h Omega_E cos(lat) sin(alpha) + dI (Omega_E cos lat)^2 sin(alpha) cos(alpha).

The spin axis swings about north like a pendulum; for small swings the period is
Baruh's ``T = 2 pi sqrt(I / (J s Omega_E cos lat))`` (with ``h = J s`` up to the
relative ``Omega_E / s`` and ``dI Omega_E cos(lat) / h`` corrections).
:func:`period` gives the exact large-amplitude period of this equation with the
complete elliptic integral ``K`` (pendulum formula ``T = 4 K(sin^2(alpha_max/2)) / w_n``)
for ``dI = 0``.

Integration reuses the attitude splitting's machinery: ``alpha`` is a
Hamiltonian 1-DOF system ``p^2/(2I) + V(alpha)``, stepped by the symmetric
kick-drift-kick splitting and Suzuki's 4th-order composition
(:data:`astrodyn.attitude.integrators.SPLIT4_WEIGHTS`): symplectic, so the
energy-like integral ``E = I alpha'^2 / 2 + V(alpha)`` stays bounded.
SI units; angles in radians.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from astrodyn.attitude.elliptic import ellipk
from astrodyn.attitude.integrators import (
    MAX_STEPS,
    SPLIT4_WEIGHTS,
    check_step_budget,
    checked_max_steps,
    step_chunks,
    step_plan,
)
from astrodyn.inputs import real_array, real_scalar
from astrodyn.jit import jit

__all__ = ["Gyrocompass", "EARTH_ROTATION_RATE"]

EARTH_ROTATION_RATE = 7.2921150e-5
"""Earth's sidereal rotation rate, rad/s (IERS Conventions 2010, nominal value)."""


@dataclass(frozen=True)
class Gyrocompass:
    """An undamped gyrocompass; symbols as in the module docstring.

    Parameters: ``gimbal_inertia`` ``I`` (kg m^2, about the local vertical),
    ``rotor_inertia`` ``J`` (kg m^2, axial), ``spin`` ``s`` (rad/s, the rotor relative
    to the gimbal at the initial azimuth ``alpha0``: the axial momentum is
    ``h = J (s + Omega_E cos(lat) cos(alpha0))``, :meth:`axial_momentum`, as
    :meth:`simulate` and :meth:`period` take it), ``latitude`` (rad, ``|lat| < pi/2``),
    ``earth_rate`` (rad/s), ``inertia_difference`` ``dI = I_2 - I_1`` (kg m^2).
    """

    gimbal_inertia: float
    rotor_inertia: float
    spin: float
    latitude: float
    earth_rate: float = EARTH_ROTATION_RATE
    inertia_difference: float = 0.0

    def __post_init__(self):
        for name in ("gimbal_inertia", "rotor_inertia", "earth_rate"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name}: expected a finite positive number, got {v!r}")
        if not math.isfinite(self.spin):
            raise ValueError(f"spin: expected a finite rotor rate in rad/s, got {self.spin!r}")
        if not (math.isfinite(self.latitude) and abs(self.latitude) < 0.5 * math.pi):
            raise ValueError(f"latitude: expected |latitude| < pi/2 rad (no north-seeking torque at the poles), got {self.latitude!r}")
        if not math.isfinite(self.inertia_difference):
            raise ValueError(f"inertia_difference: expected a finite number in kg m^2, got {self.inertia_difference!r}")

    @property
    def horizontal_earth_rate(self) -> float:
        """``Omega_E cos(lat)``, rad/s: the north component of the Earth's rate."""
        return self.earth_rate * math.cos(self.latitude)

    def axial_momentum(self, alpha0=0.0) -> float:
        """``h = J (s + Omega_E cos(lat) cos(alpha0))`` (N m s), constant along the motion."""
        return self.rotor_inertia * (self.spin + self.horizontal_earth_rate * math.cos(alpha0))

    def natural_frequency(self, alpha0=0.0) -> float:
        """Small-swing angular frequency ``sqrt((h Omega_E cos lat - dI (Omega_E cos lat)^2) / I)``, rad/s."""
        wh = self.horizontal_earth_rate
        return math.sqrt((self.axial_momentum(alpha0) * wh - self.inertia_difference * wh * wh) / self.gimbal_inertia)

    def baruh_period(self) -> float:
        """Baruh's small-swing period ``2 pi sqrt(I / (J s Omega_E cos lat))``, s (sec. 10.7)."""
        return 2.0 * math.pi * math.sqrt(self.gimbal_inertia / (self.rotor_inertia * self.spin * self.horizontal_earth_rate))

    def period(self, amplitude, alpha0=None) -> float:
        """Exact swing period (s) for the swing amplitude ``amplitude`` (rad, ``< pi``), ``dI = 0``.

        Pendulum: ``T = 4 K(m) / w_n`` with ``m = sin^2(amplitude / 2)``; ``w_n`` uses
        ``h`` at ``alpha0`` (default: the turning point ``alpha0 = amplitude``).
        """
        if self.inertia_difference != 0.0:
            raise ValueError("inertia_difference: the closed-form period needs dI = 0")
        a = float(amplitude)
        if not (0.0 <= a < math.pi):
            raise ValueError(f"amplitude: expected 0 <= amplitude < pi rad, got {amplitude!r}")
        wn = self.natural_frequency(a if alpha0 is None else alpha0)
        return 4.0 * float(ellipk(math.sin(0.5 * a) ** 2, math.cos(0.5 * a) ** 2)) / wn

    def energy(self, alpha, alpha_dot, h):
        """Integral of the swing, J: ``I alpha'^2 / 2 - h W cos(alpha) + dI W^2 sin^2(alpha) / 2``, ``W = Omega_E cos lat``.

        ``h`` from :meth:`axial_momentum`; arrays broadcast.
        """
        wh = self.horizontal_earth_rate
        alpha = np.asarray(alpha, dtype=np.float64)
        return (
            0.5 * self.gimbal_inertia * np.asarray(alpha_dot) ** 2
            - h * wh * np.cos(alpha)
            + 0.5 * self.inertia_difference * wh * wh * np.sin(alpha) ** 2
        )

    def simulate(self, alpha0, alpha_dot0, t, step=None, max_steps=MAX_STEPS):
        """Swing of the spin axis: ``(alpha, alpha_dot)`` (rad, rad/s) at times ``t`` (s, >= 0 ascending).

        ``alpha0`` azimuth of the spin axis from north (rad), ``alpha_dot0`` its rate
        at ``t = 0``.  ``step`` defaults to 1/200 of the small-swing period.  4th-order
        symplectic splitting (module docstring); the rotor's momentum ``h`` is set
        from the initial state.  More than ``max_steps`` steps in total
        (:data:`~astrodyn.attitude.integrators.MAX_STEPS` by default) are refused
        before the run, as by :func:`~astrodyn.attitude.integrators.propagate_attitude`.
        """
        max_steps = checked_max_steps(max_steps)
        t_out = np.atleast_1d(real_array(t, "t", "Gyrocompass.simulate"))
        if t_out.ndim != 1 or not np.all(np.isfinite(t_out)) or np.any(t_out < 0) or np.any(np.diff(t_out) < 0):
            raise ValueError("t: expected a scalar or 1-D array of finite times >= 0 s, ascending")
        h = self.axial_momentum(float(alpha0))
        wh = self.horizontal_earth_rate
        note = ""
        if step is None:
            step = 2.0 * math.pi / self.natural_frequency(float(alpha0)) / 200.0
            note = " (the default: 1/200 of the small-swing period)"
        step = real_scalar(step, "step", "Gyrocompass.simulate")
        if not (step > 0 and math.isfinite(step)):
            raise ValueError(f"step: expected a positive finite step in s, got {step}")
        check_step_budget(t_out, step, False, max_steps, note)
        coef = np.array([h * wh / self.gimbal_inertia, self.inertia_difference * wh * wh / self.gimbal_inertia])
        starts, n, dt = step_plan(t_out, step, False)
        out = np.empty((len(t_out), 2))
        state = np.array([float(alpha0), float(alpha_dot0)])
        for _, sd, rec in step_chunks(starts, n, dt):
            _swing_kernel(state, coef, SPLIT4_WEIGHTS, sd, rec, out)
        for k in range(len(t_out)):
            if n[k] == 0:
                out[k] = (alpha0, alpha_dot0) if k == 0 else out[k - 1]
        if np.ndim(t) == 0:
            return out[0, 0], out[0, 1]
        return out[:, 0], out[:, 1]


@jit
def _swing_kernel(state, coef, weights, step_dt, record, out):
    """Kick-drift-kick stages of ``alpha'' = -c0 sin(alpha) + c1 sin(alpha) cos(alpha)`` composed with ``weights``."""
    a = state[0]
    v = state[1]
    for k in range(step_dt.shape[0]):
        dt = step_dt[k]
        for s in range(weights.shape[0]):
            hs = 0.5 * weights[s] * dt
            sa = math.sin(a)
            v += hs * sa * (coef[1] * math.cos(a) - coef[0])
            a += 2.0 * hs * v
            sa = math.sin(a)
            v += hs * sa * (coef[1] * math.cos(a) - coef[0])
        j = record[k]
        if j >= 0:
            out[j, 0] = a
            out[j, 1] = v
    state[0] = a
    state[1] = v
