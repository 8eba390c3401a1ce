"""A rolling disk in a config (``model = "rolling_disk"``): a wheel rolling without
slipping on the horizontal plane z = 0 under gravity (H. Baruh, *Analytical Dynamics*,
10.6; the model is :mod:`astrodyn.attitude.rolling_disk`, Kane's equations in generalized
speeds).  The attitude table gives the wheel and its initial state by the angles and
rates of that module (body-axis sequence 312: heading psi, lean theta, spin phi)::

    [bodies.attitude]
    model = "rolling_disk"
    radius = "1.2 cm"
    mass = "7.5 g"
    shape = "disk"               # disk (A = m R^2/4, C = m R^2/2) | hoop (m R^2/2, m R^2)
    # moments = ["2.7e-7 kg m2", "5.4e-7 kg m2"]   # or A (any diameter) and C (the axis)
    g = "9.80665 m/s2"           # default standard gravity
    position = ["0 m", "0 m"]    # contact point (x, y)
    heading = "0 deg"            # direction the contact point moves in, from x
    lean = "20 deg"              # from the vertical; |lean| < 90 deg
    spin_angle = "0 deg"
    lean_rate = "0 rad/s"
    heading_rate = "2 rad/s"     # psi'
    spin_rate = "steady"         # phi' (rad/s), or "steady": steady rolling on a circle
                                 # at this lean and heading rate (Baruh 10.6)
    tolerance = 1e-10            # relative tolerance of the DOP853 integration (default 1e-10)

The disk's attitude (``q``, ``w`` of its body axes: b1, b3 in its plane turned by the
spin, b2 the symmetry axis) is published on ``<body>/attitude``, the contact point, the
centre, the angles and the generalized speeds on ``<body>/rolling``.  A disk that falls
flat (|lean| -> 90 deg, where the equations are singular) ends the run with an error
naming the body; the recording up to there stays valid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from astrodyn.scenario.fields import Ctx, Table, check, choice, quantity, vector

__all__ = ["RollingSpec", "ROLLING_KEYS", "ROLLING_SHAPES", "parse_rolling", "rolling_disk", "rolling_state0"]

ROLLING_SHAPES = ("disk", "hoop")
#: Keys of the attitude table that belong to the rolling disk.
ROLLING_KEYS = ("radius", "shape", "moments", "position", "heading", "lean", "spin_angle", "lean_rate",
                "heading_rate", "spin_rate")
#: Largest |lean| of an initial state: the equations are singular at 90 deg.
MAX_LEAN_DEG = 89.0


@dataclass(frozen=True, eq=False)
class RollingSpec:
    """A rolling disk: ``radius`` m, ``mass`` kg, moments ``A`` (diameter) and ``C``
    (axis) kg m^2, gravity ``g`` m/s^2, and the initial state (m, rad, rad/s):
    ``position`` (x, y), ``heading``, ``lean``, ``spin_angle``, ``lean_rate``,
    ``heading_rate``, ``spin_rate`` (phi')."""

    radius: float
    mass: float
    A: float
    C: float
    g: float
    position: np.ndarray
    heading: float
    lean: float
    spin_angle: float
    lean_rate: float
    heading_rate: float
    spin_rate: float


def parse_rolling(ctx: Ctx, tb: Table, path: str, mass: float, g: float) -> RollingSpec:
    """The rolling disk of an attitude table ``tb`` (module docstring); ``mass`` and ``g``
    are read by the caller (shared keys of the attitude table)."""
    radius = quantity(ctx, tb.get("radius"), "length", f"{path}.radius")
    check(ctx, radius > 0, f"{path}.radius", "radius > 0", tb.get("radius"))
    shape = choice(ctx, tb.get("shape", "disk"), ROLLING_SHAPES, f"{path}.shape")
    if tb.has("moments"):
        if tb.has("shape"):
            raise ctx.error(f"{path}.moments", "either shape or moments, not both", tb.get("moments"))
        A, C = vector(ctx, tb.get("moments"), "inertia", 2, f"{path}.moments")
        check(ctx, A > 0 and C > 0, f"{path}.moments", "two positive moments [A (a diameter), C (the axis)]",
              tb.get("moments"))
        # an axisymmetric body's principal moments (A, A, C) obey C <= 2 A
        check(ctx, C <= 2 * A * (1 + 1e-12), f"{path}.moments", "C <= 2 A (the triangle inequality of (A, A, C))",
              tb.get("moments"))
    else:
        A, C = (mass * radius**2 / 4, mass * radius**2 / 2) if shape == "disk" else (mass * radius**2 / 2, mass * radius**2)
    position = vector(ctx, tb.get("position", [0.0, 0.0]), "length", 2, f"{path}.position")
    heading = quantity(ctx, tb.get("heading", 0.0), "angle", f"{path}.heading")
    raw_lean = tb.get("lean", 0.0)
    lean = quantity(ctx, raw_lean, "angle", f"{path}.lean")
    check(ctx, abs(lean) <= math.radians(MAX_LEAN_DEG), f"{path}.lean",
          f"|lean| <= {MAX_LEAN_DEG:g} deg (at 90 deg the disk lies flat: the equations are singular)", raw_lean)
    spin_angle = quantity(ctx, tb.get("spin_angle", 0.0), "angle", f"{path}.spin_angle")
    lean_rate = quantity(ctx, tb.get("lean_rate", 0.0), "angular_velocity", f"{path}.lean_rate")
    heading_rate = quantity(ctx, tb.get("heading_rate", 0.0), "angular_velocity", f"{path}.heading_rate")
    raw_spin = tb.get("spin_rate", 0.0)
    if raw_spin == "steady":
        from astrodyn.attitude.rolling_disk import RollingDisk, steady_spin

        check(ctx, heading_rate * math.cos(lean) != 0 and lean_rate == 0, f"{path}.spin_rate",
              'a number, or "steady" with heading_rate != 0 and lean_rate = 0 (steady rolling on a circle)', raw_spin)
        spin_rate = steady_spin(RollingDisk(radius, mass, A, C, g), lean, heading_rate)
        check(ctx, math.isfinite(spin_rate) and abs(spin_rate) <= 1e5, f"{path}.spin_rate",
              "a steady spin |phi'| <= 1e5 rad/s for this lean and heading rate", raw_spin)
    else:
        spin_rate = quantity(ctx, raw_spin, "angular_velocity", f"{path}.spin_rate")
    return RollingSpec(radius=radius, mass=mass, A=A, C=C, g=g, position=position, heading=heading, lean=lean,
                       spin_angle=spin_angle, lean_rate=lean_rate, heading_rate=heading_rate, spin_rate=spin_rate)


def rolling_disk(spec: RollingSpec):
    """The :class:`astrodyn.attitude.rolling_disk.RollingDisk` of a config's rolling body."""
    from astrodyn.attitude.rolling_disk import RollingDisk

    return RollingDisk(spec.radius, spec.mass, spec.A, spec.C, spec.g)


def rolling_state0(spec: RollingSpec) -> np.ndarray:
    """The initial state vector ``(x, y, psi, theta, phi, u1, u2, u3)`` (m, rad, rad/s) of
    :mod:`astrodyn.attitude.rolling_disk`: ``u1 = theta'``, ``u2 = psi' sin theta + phi'``,
    ``u3 = psi' cos theta``."""
    th = spec.lean
    return np.array([spec.position[0], spec.position[1], spec.heading, th, spec.spin_angle, spec.lean_rate,
                     spec.heading_rate * math.sin(th) + spec.spin_rate, spec.heading_rate * math.cos(th)])
