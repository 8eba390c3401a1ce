"""Single-axis gyroscopes mounted on a body, in a config: a body's ``gyros`` list
(H. Baruh, *Analytical Dynamics*, 10.7.3; the model is
:class:`astrodyn.attitude.gyroscopes.SingleAxisGyro`).  The body's attitude (any model) is
their base; each gyroscope's gimbal angle, its rate and its indication are published on
``<body>/gimbals`` at every output step::

    [[bodies.gyros]]
    type = "rate"                    # rate (spring and damper) | rate_integrating (damper only)
    input_axis = [1, 0, 0]           # body components: the rate it measures
    output_axis = [0, 1, 0]          # the gimbal axis, perpendicular to input_axis;
                                     # the spin reference axis is input x output
    spin_inertia = "1e-4 kg m2"      # rotor, about its axis (C)
    transverse_inertia = "6e-5 kg m2"  # rotor, about a diameter through the pivot (A; C <= 2 A)
    spin_rate = "24000 rpm"          # rotor relative to the gimbal (held by its motor)
    natural_frequency = "30 Hz"      # rate gyro: sqrt(k / J2), or spring = "... N m/rad"
    damping_ratio = 0.7              # rate gyro: c / (2 sqrt(k J2)), or damping = "... N m s/rad"
    # rate_integrating: damping = "... N m s/rad" or time_constant = "... s" (J2 / c)

Units as everywhere in configs; errors name the field, e.g. ``bodies[0] (sc).gyros[1].
output_axis: expected a direction perpendicular to input_axis, got [1, 0, 0]``.  The base
rate between output samples is a cubic spline of the body's published rates: the output
rate must resolve the body's motion (it does not have to resolve the gimbal's).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from astrodyn.scenario.fields import Ctx, Table, check, choice, quantity, vector

__all__ = ["Gyro", "GYRO_TYPES", "MAX_GYROS", "parse_gyros", "single_axis_gyro", "GimbalBank"]

GYRO_TYPES = ("rate", "rate_integrating")
#: Most gyroscopes on one body (astrodyn.messages.definitions.MAX_GYROS).
MAX_GYROS = 16
_KEYS = ("type", "input_axis", "output_axis", "spin_inertia", "transverse_inertia", "spin_rate", "natural_frequency",
         "damping_ratio", "spring", "damping", "time_constant")


@dataclass(frozen=True, eq=False)
class Gyro:
    """One single-axis gyroscope: ``type``, ``mount`` (3, 3) with rows the input, output and
    spin reference axes in body components (``v_case = mount @ v_body``), rotor ``spin_inertia``
    ``C`` and ``transverse_inertia`` ``A`` (kg m^2), ``spin_rate`` (rad/s), ``spring`` ``k``
    (N m/rad, 0 for rate-integrating) and ``damping`` ``c`` (N m s/rad)."""

    type: str
    mount: np.ndarray
    spin_inertia: float
    transverse_inertia: float
    spin_rate: float
    spring: float
    damping: float


def _unit(ctx: Ctx, value: Any, path: str) -> np.ndarray:
    d = vector(ctx, value, "dimensionless", 3, path)
    n = float(np.linalg.norm(d))
    check(ctx, n > 0, path, "a non-zero direction (body components; normalized on load)", value)
    return d / n


def _positive(ctx: Ctx, tb: Table, key: str, kind: str, path: str) -> float:
    x = quantity(ctx, tb.get(key), kind, f"{path}.{key}")
    check(ctx, x > 0, f"{path}.{key}", f"{key} > 0", tb.get(key))
    return x


def _one_of(ctx: Ctx, tb: Table, path: str, a: str, b: str, what: str) -> str:
    if tb.has(a) and tb.has(b):
        raise ctx.error(f"{path}.{b}", f"either {a} or {b}, not both", tb.get(b))
    if not (tb.has(a) or tb.has(b)):
        raise ctx.error(f"{path}.{a}", f"{a} or {b} ({what})", "nothing", raw=True)
    return a if tb.has(a) else b


def parse_gyros(ctx: Ctx, data: Any, path: str) -> tuple[Gyro, ...]:
    """A body's ``gyros`` list (module docstring)."""
    if not isinstance(data, list) or not 1 <= len(data) <= MAX_GYROS:
        raise ctx.error(path, f"a list of 1 to {MAX_GYROS} gyroscope tables", data)
    out = []
    for k, item in enumerate(data):
        p = f"{path}[{k}]"
        tb = Table(ctx, item, p, _KEYS)
        kind = choice(ctx, tb.get("type", "rate"), GYRO_TYPES, f"{p}.type")
        i_axis = _unit(ctx, tb.get("input_axis"), f"{p}.input_axis")
        o_axis = _unit(ctx, tb.get("output_axis"), f"{p}.output_axis")
        check(ctx, abs(float(i_axis @ o_axis)) <= 1e-9, f"{p}.output_axis", "a direction perpendicular to input_axis",
              tb.get("output_axis"))
        o_axis = o_axis - (o_axis @ i_axis) * i_axis
        o_axis /= np.linalg.norm(o_axis)
        mount = np.array([i_axis, o_axis, np.cross(i_axis, o_axis)])
        C = _positive(ctx, tb, "spin_inertia", "inertia", p)
        A = _positive(ctx, tb, "transverse_inertia", "inertia", p)
        check(ctx, C <= 2 * A * (1 + 1e-12), f"{p}.spin_inertia", "spin_inertia <= 2 transverse_inertia (a rigid rotor)",
              tb.get("spin_inertia"))
        spin = quantity(ctx, tb.get("spin_rate"), "angular_velocity", f"{p}.spin_rate")
        check(ctx, spin != 0, f"{p}.spin_rate", "a non-zero spin rate (the rotor's momentum is the instrument)",
              tb.get("spin_rate"))
        J2 = A  # massless gimbal: gimbal + rotor about the output axis
        if kind == "rate":
            for key in ("time_constant",):
                if tb.has(key):
                    raise ctx.error(f"{p}.{key}", 'no time_constant unless type = "rate_integrating"', tb.get(key))
            if _one_of(ctx, tb, p, "natural_frequency", "spring", "the restraining spring") == "spring":
                k_spring = _positive(ctx, tb, "spring", "rotational_stiffness", p)
            else:
                wn = 2 * math.pi * _positive(ctx, tb, "natural_frequency", "frequency", p)
                k_spring = wn * wn * J2
            if _one_of(ctx, tb, p, "damping_ratio", "damping", "the damper") == "damping":
                c = _positive(ctx, tb, "damping", "rotational_damping", p)
            else:
                zeta = _positive(ctx, tb, "damping_ratio", "dimensionless", p)
                c = 2 * zeta * math.sqrt(k_spring * J2)
        else:
            for key in ("natural_frequency", "damping_ratio", "spring"):
                if tb.has(key):
                    raise ctx.error(f"{p}.{key}", f'no {key} for type = "rate_integrating" (no spring)', tb.get(key))
            k_spring = 0.0
            if _one_of(ctx, tb, p, "damping", "time_constant", "the damper") == "damping":
                c = _positive(ctx, tb, "damping", "rotational_damping", p)
            else:
                c = J2 / _positive(ctx, tb, "time_constant", "time", p)
        check(ctx, math.isfinite(C * spin * spin) and math.isfinite(k_spring) and math.isfinite(c), p,
              "rotor and gimbal values whose products stay finite", "overflowing values")
        out.append(Gyro(type=kind, mount=mount, spin_inertia=C, transverse_inertia=A, spin_rate=spin, spring=k_spring,
                        damping=c))
    return tuple(out)


def single_axis_gyro(g: Gyro):
    """The :class:`astrodyn.attitude.gyroscopes.SingleAxisGyro` of a config's gyroscope
    (massless gimbal, speed-regulated rotor)."""
    from astrodyn.attitude.gyroscopes import SingleAxisGyro

    return SingleAxisGyro(g.spin_inertia, g.transverse_inertia, g.spin_rate, spring=g.spring, damping=g.damping)


class GimbalBank:
    """The gimbals of a body's single-axis gyroscopes (``gyros``, each a :class:`Gyro`): their
    state ``(theta, theta')`` (rad, rad/s) per gyro, advanced over an interval on a base
    rate given per gyro, and their indications.  Rate gyros start at their exact steady
    angle for the body rate ``w0`` (the instrument has been running), rate-integrating gyros
    at zero (they measure the angle turned from the start).  Used by the attitude process
    (``<body>/gimbals``, :class:`astrodyn.simulate.GyroSet`) and by the closed loop's dynamic
    gyro sensor (:mod:`astrodyn.plant`)."""

    RTOL = 1e-10

    def __init__(self, gyros, w0):
        from astrodyn.attitude.gyroscopes import steady_state_angle

        self.models = [single_axis_gyro(g) for g in gyros]
        self.mounts = [np.asarray(g.mount, dtype=np.float64) for g in gyros]
        self.state = np.zeros((len(self.models), 2))
        for i, (m, mount) in enumerate(zip(self.models, self.mounts)):
            if m.spring > 0:
                try:
                    self.state[i, 0] = steady_state_angle(m, mount @ np.asarray(w0, dtype=np.float64))
                except ValueError:  # no stable steady angle at this rate: start at rest
                    pass
        # indication per gimbal angle: a rate gyro k / H (rad/s per rad), a rate-integrating c / H
        self.gain = np.array([(m.spring if m.spring > 0 else m.damping) / m.momentum for m in self.models])

    def advance(self, bases, grid) -> np.ndarray:
        """Integrate every gimbal over ``grid`` (s from the current state, starting at 0) on
        its base ``bases[i](t) -> (w, w')`` (the gyro's case axes); returns the states
        ``(len(grid), n, 2)`` and keeps the last as the current state."""
        from astrodyn.attitude.gyroscopes import propagate_single_axis

        out = np.empty((len(grid), len(self.models), 2))
        for i, m in enumerate(self.models):
            y, _ = propagate_single_axis(m, bases[i], grid, theta0=self.state[i, 0], theta_dot0=self.state[i, 1],
                                         rtol=self.RTOL, atol=1e-3 * self.RTOL)
            out[:, i] = y[:, :2]
        self.state = out[-1].copy()
        return out

    def indicated(self, angles=None) -> np.ndarray:
        """Each gyro's indication (rate gyro k theta / H rad/s, rate-integrating c theta / H
        rad) for gimbal ``angles`` (default the current ones)."""
        return self.gain * (self.state[:, 0] if angles is None else np.asarray(angles))
