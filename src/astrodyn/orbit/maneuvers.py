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
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["G0", "hohmann", "apply_impulse", "ConstantThrust", "rocket_dv"]

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


@dataclass(frozen=True)
class ConstantThrust:
    """A finite burn: ``force`` (3,) N in inertial axes, from mass ``mass`` kg, specific
    impulse ``isp`` s (``inf``: no mass loss).  ``acceleration(t, r, v) = force / m(t)`` with
    ``m(t) = mass - mdot t``; ``t`` from the start of the burn segment (s)."""

    force: tuple
    mass: float
    isp: float = math.inf

    def __post_init__(self):
        f = np.asarray(self.force, dtype=np.float64).reshape(3)
        if not np.all(np.isfinite(f)):
            raise ValueError(f"force: expected 3 finite numbers in N (inertial axes), got {f.tolist()}")
        if not (math.isfinite(self.mass) and self.mass > 0):
            raise ValueError(f"mass: expected a finite mass > 0 kg, got {self.mass!r}")
        if not self.isp > 0:
            raise ValueError(f"isp: expected a specific impulse > 0 s (inf: no mass loss), got {self.isp!r}")
        object.__setattr__(self, "force", f)

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

    def acceleration(self, t, r, v=None):
        r = np.asarray(r, dtype=np.float64)
        return np.broadcast_to(self.force / self.mass_at(float(t)), r.shape).copy()
