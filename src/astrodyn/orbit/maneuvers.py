"""Orbit manoeuvres: impulsive velocity changes, the Hohmann transfer, and finite burns.

SI units (m, m/s, s, kg, N), inertial frame of the central body.

* :func:`hohmann` -- the two-impulse transfer between coplanar circular orbits of radii
  ``r1`` and ``r2`` (Vallado, *Fundamentals of Astrodynamics and Applications*, 4th ed.,
  sec. 6.3.1, Algorithm 36): transfer ellipse ``a_t = (r1 + r2) / 2``,
  ``dv1 = sqrt(mu/r1) (sqrt(2 r2 / (r1 + r2)) - 1)``,
  ``dv2 = sqrt(mu/r2) (1 - sqrt(2 r1 / (r1 + r2)))``, time of flight ``pi sqrt(a_t^3 / mu)``.
  Signed: both negative for a transfer inwards.
* :func:`apply_impulse` -- ``v + dv`` at an instant (an impulsive burn).
* :class:`ConstantThrust` -- a finite burn: thrust ``force`` (N, inertial axes) held
  constant while the mass falls at ``mdot = |force| / (isp g0)`` (kg/s), as a perturbation
  of :func:`astrodyn.orbit.propagate_perturbed` (acceleration ``force / m(t)``).  Integrate
  one burn segment per call (the thrust is continuous inside a segment; a closed loop holds
  it over each control step), with ``t`` measured from the segment's start.
* :class:`RotatingThrust` -- the same burn with a force that turns uniformly about a fixed
  inertial axis (Rodrigues' formula, ``|force|`` constant, the same mass model): a thrust
  fixed in the axes of a body that spins about a fixed axis at a constant rate, e.g. the
  closed-loop plant's body-axis thrust over one control step (:mod:`astrodyn.plant`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["G0", "hohmann", "apply_impulse", "ConstantThrust", "RotatingThrust", "rocket_dv"]

#: Standard gravity (m/s^2), the constant of specific impulse (CGPM 1901).
G0 = 9.80665


def hohmann(r1: float, r2: float, mu: float) -> tuple[float, float, float]:
    """``(dv1, dv2, tof)``: the Hohmann transfer from a circular orbit of radius ``r1`` to
    one of radius ``r2`` (m) about ``mu`` (m^3/s^2): the two tangential speed changes (m/s,
    signed along the velocity) and the time of flight (s) between them."""
    for name, x in (("r1", r1), ("r2", r2), ("mu", mu)):
        if not (isinstance(x, (int, float)) and math.isfinite(x) and x > 0):
            raise ValueError(f"{name}: expected a finite number > 0, got {x!r}")
    s = r1 + r2
    dv1 = math.sqrt(mu / r1) * (math.sqrt(2.0 * r2 / s) - 1.0)
    dv2 = math.sqrt(mu / r2) * (1.0 - math.sqrt(2.0 * r1 / s))
    tof = math.pi * math.sqrt((0.5 * s) ** 3 / mu)
    return dv1, dv2, tof


def apply_impulse(v, dv) -> np.ndarray:
    """``v + dv`` (m/s, inertial): an impulsive burn; shapes broadcast."""
    v = np.asarray(v, dtype=np.float64)
    dv = np.asarray(dv, dtype=np.float64)
    out = v + dv
    if not np.all(np.isfinite(out)):
        raise ValueError("dv: expected finite velocity changes in m/s")
    return out


def rocket_dv(isp: float, m0: float, m1: float) -> float:
    """Tsiolkovsky: the speed change ``isp g0 ln(m0 / m1)`` (m/s) of a burn from mass
    ``m0`` to ``m1`` (kg) with specific impulse ``isp`` (s), free of gravity."""
    return isp * G0 * math.log(m0 / m1)


class _BurnMass:
    """The mass model of a finite burn (``force``, ``mass``, ``isp`` fields): the mass falls
    at ``mdot = |force| / (isp g0)`` from ``mass`` at ``t = 0``."""

    def _check_burn(self) -> np.ndarray:
        """Validate ``force``, ``mass``, ``isp``; the force as a float64 (3,) array."""
        f = np.asarray(self.force, dtype=np.float64).reshape(3)
        if not np.all(np.isfinite(f)):
            raise ValueError(f"force: expected 3 finite numbers in N (inertial axes), got {f.tolist()}")
        if not (math.isfinite(self.mass) and self.mass > 0):
            raise ValueError(f"mass: expected a finite mass > 0 kg, got {self.mass!r}")
        if not self.isp > 0:
            raise ValueError(f"isp: expected a specific impulse > 0 s (inf: no mass loss), got {self.isp!r}")
        return f

    @property
    def mdot(self) -> float:
        """Mass flow (kg/s)."""
        return 0.0 if math.isinf(self.isp) else float(np.linalg.norm(self.force)) / (self.isp * G0)

    def mass_at(self, t: float) -> float:
        """``m(t)`` (kg); ``ValueError`` once the burn would have used up the whole mass."""
        m = self.mass - self.mdot * t
        if not m > 0:
            raise ValueError(f"burn: the mass is used up after {self.mass / self.mdot:.6g} s (asked t = {t:.6g} s)")
        return m


@dataclass(frozen=True)
class ConstantThrust(_BurnMass):
    """A finite burn: ``force`` (3,) N in inertial axes, from mass ``mass`` kg, specific
    impulse ``isp`` s (``inf``: no mass loss).  ``acceleration(t, r, v) = force / m(t)`` with
    ``m(t) = mass - mdot t``; ``t`` from the start of the burn segment (s)."""

    force: tuple
    mass: float
    isp: float = math.inf

    def __post_init__(self):
        object.__setattr__(self, "force", self._check_burn())

    def acceleration(self, t, r, v=None):
        r = np.asarray(r, dtype=np.float64)
        return np.broadcast_to(self.force / self.mass_at(float(t)), r.shape).copy()


@dataclass(frozen=True)
class RotatingThrust(_BurnMass):
    """A finite burn whose force turns uniformly about a fixed inertial axis: ``force``
    (3,) N the thrust at ``t = 0`` (inertial axes), ``axis`` (3,) the axis (inertial,
    nonzero; stored normalized), ``rate`` rad/s (right-handed about ``axis``; any sign),
    ``mass``, ``isp`` as :class:`ConstantThrust` (the same mass model, ``|force|`` constant):

        f(t) = R(axis, rate t) force = force + sin(rate t) axis x force
                                       + (1 - cos(rate t)) axis x (axis x force)

    (Rodrigues' formula, the active rotation), ``acceleration(t, r, v) = f(t) / m(t)``.
    ``rate = 0`` is :class:`ConstantThrust`, bit for bit.  The thrust fixed in the axes of
    a body that turns at the constant rate ``rate`` about the fixed inertial ``axis`` (a
    pure spin about a principal axis, say) is exactly this."""

    force: tuple
    mass: float
    isp: float = math.inf
    axis: tuple = (0.0, 0.0, 1.0)
    rate: float = 0.0

    def __post_init__(self):
        f = self._check_burn()
        a = np.asarray(self.axis, dtype=np.float64).reshape(3)
        n = float(np.linalg.norm(a)) if np.all(np.isfinite(a)) else math.nan
        if not (math.isfinite(n) and n > 0):
            raise ValueError(f"axis: expected 3 finite numbers, not all 0 (inertial axes), got {a.tolist()}")
        if not math.isfinite(self.rate):
            raise ValueError(f"rate: expected a finite turn rate in rad/s, got {self.rate!r}")
        a = a / n
        object.__setattr__(self, "force", f)
        object.__setattr__(self, "axis", a)
        object.__setattr__(self, "rate", float(self.rate))
        object.__setattr__(self, "_cross", np.cross(a, f))  # axis x force
        object.__setattr__(self, "_double", np.cross(a, np.cross(a, f)))  # axis x (axis x force)

    def force_at(self, t: float) -> np.ndarray:
        """``f(t)`` (3,) N, inertial axes (``1 - cos`` as ``2 sin^2(phi / 2)``: no cancellation)."""
        phi = self.rate * float(t)
        if phi == 0.0:
            return self.force
        s = math.sin(0.5 * phi)
        return self.force + math.sin(phi) * self._cross + (2.0 * s * s) * self._double

    def acceleration(self, t, r, v=None):
        r = np.asarray(r, dtype=np.float64)
        return np.broadcast_to(self.force_at(t) / self.mass_at(float(t)), r.shape).copy()
