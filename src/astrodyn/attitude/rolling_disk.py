"""A disk rolling without slipping on a horizontal plane (Baruh, *Analytical Dynamics*, 10.6),
in generalized speeds by Kane's method (Baruh ch. 9).

Frames and angles
-----------------
Inertial N: ``n1, n2`` horizontal, ``n3`` up; the plane is z = 0.  The disk's orientation is
given by three angles, body-axis sequence "312" (:func:`astrodyn.rotation.quat_from_euler`):

* heading ``psi`` about ``n3``: ``a1 = cos psi n1 + sin psi n2`` is the direction the contact
  point moves in (the tangent of its path), ``a2 = n3 x a1``;
* lean ``theta`` about ``a1``: the non-spinning frame B, ``b1 = a1``,
  ``b2 = cos theta a2 + sin theta a3`` (the disk's symmetry axis), ``b3 = -sin theta a2 + cos theta a3``
  (in the disk's plane, from the contact point up to the centre G); ``theta = 0`` is upright,
  ``theta = +-pi/2`` flat on the plane;
* spin ``phi`` about ``b2``.

The disk: radius ``R`` (m, the contact radius), mass ``m`` (kg), moments of inertia about
its centre ``A`` (any diameter) and ``C`` (the symmetry axis), kg m^2: a thin uniform disk
has ``A = m R^2 / 4, C = m R^2 / 2``, a hoop ``A = m R^2 / 2, C = m R^2``.  Gravity ``g``
(m/s^2) along ``-n3``.

Generalized speeds and equations (Kane)
---------------------------------------
The components of the disk's angular velocity in B are the generalized speeds::

    u1 = theta',  u2 = psi' sin theta + phi' (the spin),  u3 = psi' cos theta

so ``theta' = u1, psi' = u3 / cos theta, phi' = u2 - u3 tan theta``.  Rolling makes the
contact material point's velocity zero, so the centre moves at ``v_G = R (u2 b1 - u1 b2)``
and the contact point's path at ``x' = R phi' cos psi, y' = R phi' sin psi``.  The contact
force does no work and drops out of Kane's equations; gravity's generalized forces are
``(m g R sin theta, 0, 0)``.  With ``v_G``'s partial velocities ``(-R b2, R b1, 0)`` and the
angular momentum ``(A u1, C u2, A u3)`` in B (which turns with ``psi' a3 + theta' b1``)::

    (A + m R^2) u1' = m g R sin theta + (C + m R^2) u2 u3 - A u3^2 tan theta
    (C + m R^2) u2' = -m R^2 u1 u3
             A u3' = -C u1 u2 + A u1 u3 tan theta

Energy ``E = m/2 R^2 (u1^2 + u2^2) + (A u1^2 + C u2^2 + A u3^2) / 2 + m g R cos theta`` is
conserved (the rolling constraint does no work).  Upright straight rolling at spin
``Omega`` is stable when ``C (C + m R^2) Omega^2 > A m g R`` (linearize the first and last
equations about ``theta = u3 = 0``): ``Omega^2 > g / (3 R)`` for the thin disk (forward
speed ``R Omega > sqrt(g R / 3)``, Routh's result), ``g / (4 R)`` for the hoop.  Steady
rolling on a circle (``theta`` constant, ``u1 = 0``) needs
``m g R sin theta + (C + m R^2) u2 u3 = A u3^2 tan theta`` (:func:`steady_spin`).

The state vector, shape ``(..., 8)``: ``(x, y, psi, theta, phi, u1, u2, u3)`` in m, rad and
rad/s.  The equations are singular when the disk lies flat (``cos theta = 0``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from astrodyn.attitude.output_times import check_output_times, integrate_dop853

__all__ = ["FLAT_COS", "RollingDisk", "rolling_disk_rates", "propagate_rolling_disk", "energy", "upright_critical_spin",
           "steady_spin", "disk_quaternion", "disk_body_rates", "center_position", "STATE_FIELDS"]

#: Names of the state vector's components, in order (m, rad, rad/s).
STATE_FIELDS = ("x", "y", "psi", "theta", "phi", "u1", "u2", "u3")


@dataclass(frozen=True)
class RollingDisk:
    """An axisymmetric wheel rolling on a plane: radius ``R`` m, mass ``m`` kg, moments of
    inertia about its centre ``A`` (diameter) and ``C`` (axis) in kg m^2 (default: a thin
    uniform disk, ``m R^2 / 4`` and ``m R^2 / 2``), gravity ``g`` m/s^2."""

    radius: float
    mass: float
    A: float | None = None
    C: float | None = None
    g: float = 9.80665

    def __post_init__(self) -> None:
        for name in ("radius", "mass", "g"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name}: expected a finite number > 0, got {value!r}")
        if self.A is None:
            object.__setattr__(self, "A", self.mass * self.radius**2 / 4)
        if self.C is None:
            object.__setattr__(self, "C", self.mass * self.radius**2 / 2)
        for name in ("A", "C"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name}: expected a moment of inertia > 0 (kg m^2), got {value!r}")

    @classmethod
    def hoop(cls, radius: float, mass: float, g: float = 9.80665) -> RollingDisk:
        """A thin ring: ``A = m R^2 / 2``, ``C = m R^2``."""
        return cls(radius, mass, mass * radius**2 / 2, mass * radius**2, g)


def rolling_disk_rates(disk: RollingDisk, state: np.ndarray) -> np.ndarray:
    """Time derivative of ``state`` (..., 8) (module docstring; Kane's equations)."""
    s = np.asarray(state, dtype=np.float64)
    if s.shape[-1] != 8:
        raise ValueError(f"state: expected shape (..., 8) = {STATE_FIELDS}, got {s.shape}")
    psi, theta, phi, u1, u2, u3 = (s[..., k] for k in range(2, 8))
    R, m, A, C, g = disk.radius, disk.mass, disk.A, disk.C, disk.g
    c, sn = np.cos(theta), np.sin(theta)
    tan = sn / c
    phi_dot = u2 - u3 * tan
    out = np.empty_like(s)
    out[..., 0] = R * phi_dot * np.cos(psi)
    out[..., 1] = R * phi_dot * np.sin(psi)
    out[..., 2] = u3 / c
    out[..., 3] = u1
    out[..., 4] = phi_dot
    out[..., 5] = (m * g * R * sn + (C + m * R * R) * u2 * u3 - A * u3 * u3 * tan) / (A + m * R * R)
    out[..., 6] = -m * R * R * u1 * u3 / (C + m * R * R)
    out[..., 7] = (-C * u1 * u2 + A * u1 * u3 * tan) / A
    return out


def energy(disk: RollingDisk, state: np.ndarray) -> np.ndarray:
    """Total energy (J): translation of the centre, rotation, and gravity (zero with the
    centre at the plane's height)."""
    s = np.asarray(state, dtype=np.float64)
    theta, u1, u2, u3 = s[..., 3], s[..., 5], s[..., 6], s[..., 7]
    R, m = disk.radius, disk.mass
    return (0.5 * m * R * R * (u1 * u1 + u2 * u2) + 0.5 * (disk.A * u1 * u1 + disk.C * u2 * u2 + disk.A * u3 * u3)
            + m * disk.g * R * np.cos(theta))


def upright_critical_spin(disk: RollingDisk) -> float:
    """Spin (rad/s) above which upright straight rolling is stable:
    ``sqrt(A m g R / (C (C + m R^2)))`` (module docstring)."""
    R, m = disk.radius, disk.mass
    return math.sqrt(disk.A * m * disk.g * R / (disk.C * (disk.C + m * R * R)))


def steady_spin(disk: RollingDisk, theta: float, psi_dot: float) -> float:
    """The spin rate ``phi'`` (rad/s) of steady rolling on a circle at lean ``theta`` (rad)
    and heading rate ``psi'`` (rad/s): solves ``m g R sin theta + (C + m R^2) u2 u3 =
    A u3^2 tan theta`` with ``u3 = psi' cos theta``, ``u2 = psi' sin theta + phi'``."""
    R, m = disk.radius, disk.mass
    u3 = psi_dot * math.cos(theta)
    if u3 == 0.0:
        raise ValueError("psi_dot: steady circular rolling needs psi' cos theta != 0")
    u2 = (disk.A * u3 * u3 * math.tan(theta) - m * disk.g * R * math.sin(theta)) / ((disk.C + m * R * R) * u3)
    return u2 - psi_dot * math.sin(theta)


#: The disk "lies flat" when cos(lean) falls to this (lean within 0.06 deg of 90 deg): the
#: equations are singular there and the model (no impact with the plane) ends.
FLAT_COS = 1e-3


def propagate_rolling_disk(disk: RollingDisk, state0, t, rtol: float = 1e-12, atol: float = 1e-14):
    """States (len(t), 8) at the times ``t`` (s, increasing from 0) from ``state0`` (8,),
    integrated with DOP853 (scipy) on Kane's equations; returns ``(states, info)`` with the
    number of right-hand-side evaluations and the largest relative energy drift.  A disk
    that falls flat (``cos theta`` reaches :data:`FLAT_COS`) ends the integration there:
    ``states`` then holds only the times before it and ``info["flat_at"]`` is the time (s)."""
    y0 = np.asarray(state0, dtype=np.float64).reshape(8)
    t = check_output_times(t)
    if not np.all(np.isfinite(y0)):
        raise ValueError(f"state0: expected 8 finite numbers {STATE_FIELDS}, got {y0.tolist()}")
    if abs(math.cos(y0[3])) < 1e-9:
        raise ValueError(f"state0: theta = {y0[3]!r} rad: the disk lies flat (cos theta = 0), where the "
                         "equations are singular")
    R, m, A, C, g = disk.radius, disk.mass, disk.A, disk.C, disk.g
    mR2 = m * R * R
    k1, k2 = 1.0 / (A + mR2), 1.0 / (C + mR2)
    mgR = m * g * R

    def rhs(_, y):  # Python floats: numpy calls on 8 numbers cost more than the arithmetic
        _, _, psi, theta, _, u1, u2, u3 = y.tolist()
        c, sn = math.cos(theta), math.sin(theta)
        tan = sn / c
        phi_dot = u2 - u3 * tan
        return [R * phi_dot * math.cos(psi), R * phi_dot * math.sin(psi), u3 / c, u1, phi_dot,
                (mgR * sn + (C + mR2) * u2 * u3 - A * u3 * u3 * tan) * k1,
                -mR2 * u1 * u3 * k2,
                (-C * u1 * u2 + A * u1 * u3 * tan) / A]

    def flat(_, y):  # cos(theta) - FLAT_COS: zero when the disk is about to lie flat
        return math.cos(y[3]) - FLAT_COS

    flat.terminal, flat.direction = True, -1
    states, nfev, events = integrate_dop853(rhs, y0, t, rtol, atol, "rolling disk", events=[flat])
    info = {"method": "dop853", "rtol": rtol, "atol": atol, "nfev": nfev}
    if events[0].size:
        info["flat_at"] = float(events[0][0])
    e = energy(disk, states)
    info["energy_drift"] = float(np.max(np.abs(e - e[0])) / abs(e[0])) if e[0] else float(np.max(np.abs(e - e[0])))
    return states, info


def disk_quaternion(state: np.ndarray) -> np.ndarray:
    """Euler parameters (..., 4), scalar first, of the disk's body axes (b1 turned by the
    spin, the symmetry axis b2, b3 turned by the spin): sequence "312" of (psi, theta, phi),
    ``v_body = C(q) v_inertial``."""
    from astrodyn.rotation import quat_from_euler

    s = np.asarray(state, dtype=np.float64)
    return quat_from_euler(np.stack([s[..., 2], s[..., 3], s[..., 4]], axis=-1), "312")


def disk_body_rates(state: np.ndarray) -> np.ndarray:
    """The disk's angular velocity (..., 3, rad/s) in its body axes (those of
    :func:`disk_quaternion`): the B-frame components ``(u1, u2, u3)`` turned by the spin
    ``phi`` about b2, ``w = C_2(phi) (u1, u2, u3) = (u1 cos phi - u3 sin phi, u2,
    u1 sin phi + u3 cos phi)``."""
    s = np.asarray(state, dtype=np.float64)
    phi, u1, u2, u3 = s[..., 4], s[..., 5], s[..., 6], s[..., 7]
    c, sn = np.cos(phi), np.sin(phi)
    return np.stack([c * u1 - sn * u3, u2, sn * u1 + c * u3], axis=-1)


def center_position(disk: RollingDisk, state: np.ndarray) -> np.ndarray:
    """Position (..., 3) of the disk's centre: the contact point plus ``R b3``."""
    s = np.asarray(state, dtype=np.float64)
    psi, theta = s[..., 2], s[..., 3]
    R = disk.radius
    b3 = np.stack([np.sin(theta) * np.sin(psi), -np.sin(theta) * np.cos(psi), np.cos(theta)], axis=-1)
    contact = np.stack([s[..., 0], s[..., 1], np.zeros_like(psi)], axis=-1)
    return contact + R * b3
