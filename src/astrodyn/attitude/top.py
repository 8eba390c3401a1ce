"""The heavy symmetric top about a fixed point (H. Baruh, *Analytical Dynamics*, sec. 10.5).

A rigid body with an axis of symmetry (body axis 3) turns about a fixed point
``O`` on that axis under uniform gravity.  ``transverse_inertia`` ``I`` and
``axial_inertia`` ``J`` are the principal moments **about the fixed point**
(kg m^2), ``mass`` ``m`` (kg), ``cm_distance`` ``l`` (m) the distance from ``O``
to the centre of mass along ``+b3``, ``gravity`` ``g`` (m/s^2) pointing along
inertial ``-Z`` (inertial ``Z`` up).

3-1-3 Euler angles ``(psi, theta, phi)`` (precession, nutation, spin):
``C = C_3(phi) C_1(theta) C_3(psi)`` (design.md sequence ``"313"``), so
``cos(theta) = b3 . Z = C[2, 2]``.  The Lagrangian

    L = I/2 (theta'^2 + psi'^2 sin^2 theta) + J/2 (phi' + psi' cos theta)^2 - m g l cos theta

has three integrals: the axial rate ``w3 = phi' + psi' cos theta`` (``p_phi = J w3``),
the vertical angular momentum ``p_psi = I psi' sin^2 theta + J w3 cos theta`` and the
energy ``E = I/2 (theta'^2 + psi'^2 sin^2 theta) + J/2 w3^2 + m g l cos theta``.

* Steady precession (``theta`` constant, Baruh eq. 10.5x):
  ``I cos(theta) psi'^2 - J w3 psi' + m g l = 0``, two roots (slow and fast).
* Sleeping top (``theta = 0``) is stable when ``J^2 w3^2 > 4 I m g l``.
* Nutation: with ``u = cos theta``, ``u'^2 = f(u) = (1 - u^2) (2/I) (E - J w3^2/2 - m g l u)
  - (p_psi - J w3 u)^2 / I^2``; ``theta`` oscillates between the two roots of the
  cubic ``f`` in ``[-1, 1]`` (the turning points).

Simulation goes through :func:`astrodyn.attitude.integrators.propagate_attitude`:
gravity is a body-fixed force at the centre of mass and enters the splitting as a
torque kick ``r_c x (C m g)`` (:class:`~astrodyn.attitude.torques.UniformGravityTorque`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from astrodyn.attitude.torques import UniformGravityTorque
from astrodyn.rotation import dcm_from_quat, omega_from_euler_rates, quat_from_euler

__all__ = ["HeavyTop"]


@dataclass(frozen=True)
class HeavyTop:
    """A heavy symmetric top; see the module docstring for symbols and frames."""

    mass: float
    cm_distance: float
    transverse_inertia: float
    axial_inertia: float
    gravity: float = 9.80665

    def __post_init__(self):
        for name in ("mass", "cm_distance", "transverse_inertia", "axial_inertia", "gravity"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"{name}: expected a finite non-negative number, got {v!r}")
        if not (self.transverse_inertia > 0 and self.axial_inertia > 0):
            raise ValueError("transverse_inertia, axial_inertia: expected positive moments about the fixed point (kg m^2)")
        if self.axial_inertia > 2.0 * self.transverse_inertia * (1 + 1e-12):
            raise ValueError("axial_inertia: a rigid body needs axial_inertia <= 2 * transverse_inertia")

    # -- parameters -----------------------------------------------------------------
    @property
    def inertia(self) -> np.ndarray:
        """Principal moments about the fixed point, ``(I, I, J)``, kg m^2."""
        return np.array([self.transverse_inertia, self.transverse_inertia, self.axial_inertia])

    @property
    def mgl(self) -> float:
        """Gravity moment coefficient ``m g l``, N m."""
        return self.mass * self.gravity * self.cm_distance

    def gravity_torque(self) -> UniformGravityTorque:
        """The gravity torque model (centre of mass at ``(0, 0, l)`` in body axes, g along -Z)."""
        return UniformGravityTorque(self.mass, (0.0, 0.0, self.cm_distance), (0.0, 0.0, -self.gravity))

    # -- states ---------------------------------------------------------------------
    @staticmethod
    def state_from_euler(psi, theta, phi, psi_dot, theta_dot, phi_dot):
        """``(w, q)`` body rates (rad/s) and Euler parameters from 3-1-3 angles and rates."""
        angles = np.stack(np.broadcast_arrays(psi, theta, phi), -1).astype(np.float64)
        rates = np.stack(np.broadcast_arrays(psi_dot, theta_dot, phi_dot), -1).astype(np.float64)
        return omega_from_euler_rates(angles, rates, "313"), quat_from_euler(angles, "313")

    def integrals(self, w, q):
        """The three integrals ``(E, p_psi, p_phi)``: energy (J), vertical and axial momentum (N m s).

        ``E = 1/2 w.Iw + m g l C[2,2]``, ``p_psi = Z.(C^T I w)`` (inertial vertical
        component of the angular momentum about O), ``p_phi = J w3``.
        """
        w = np.asarray(w, dtype=np.float64)
        C = dcm_from_quat(q)
        H = self.inertia * w
        energy = 0.5 * np.sum(w * H, -1) + self.mgl * C[..., 2, 2]
        p_psi = np.sum(C[..., :, 2] * H, -1)
        return energy, p_psi, H[..., 2]

    # -- Baruh 10.5 closed forms ----------------------------------------------------
    def steady_precession_rates(self, theta, spin):
        """Both steady-precession rates ``psi'`` (rad/s) at nutation angle ``theta`` (rad).

        ``spin`` is the axial rate ``w3 = phi' + psi' cos theta`` (rad/s).  Roots of
        ``I cos(theta) psi'^2 - J w3 psi' + m g l = 0`` (Baruh sec. 10.5), returned
        as ``(slow, fast)`` with ``|slow| <= |fast|``; NaN where no steady precession
        exists (``J^2 w3^2 < 4 I m g l cos theta``).  At ``cos theta = 0`` the single
        root ``m g l / (J w3)`` is the slow one and the fast one is infinite.  The
        slow root is computed as ``2 m g l / (J w3 + sqrt(...))`` (no cancellation).
        """
        theta, spin = np.broadcast_arrays(np.asarray(theta, float), np.asarray(spin, float))
        I, J, mgl = self.transverse_inertia, self.axial_inertia, self.mgl
        a = I * np.cos(theta)
        b = J * spin
        disc = b * b - 4.0 * a * mgl
        with np.errstate(invalid="ignore", divide="ignore"):
            root = np.sqrt(np.where(disc >= 0, disc, np.nan))
            big = b + np.copysign(root, b)  # |big| = |b| + root, no cancellation
            slow = 2.0 * mgl / big
            fast = np.where(a != 0, big / (2.0 * a), np.copysign(np.inf, b))
        return slow, fast

    def sleeping_spin_threshold(self) -> float:
        """Smallest axial rate (rad/s) for which the upright sleeping top is stable: ``2 sqrt(I m g l) / J``."""
        return 2.0 * np.sqrt(self.transverse_inertia * self.mgl) / self.axial_inertia

    def sleeping_is_stable(self, spin):
        """``J^2 w3^2 > 4 I m g l`` (Baruh sec. 10.5): linear stability of the upright spin."""
        return self.axial_inertia**2 * np.asarray(spin, float) ** 2 > 4.0 * self.transverse_inertia * self.mgl

    def nutation_polynomial(self, w, q):
        """Coefficients ``(c3, c2, c1, c0)`` of ``f(u) = u'^2`` (highest first) for the state ``(w, q)``."""
        energy, p_psi, p_phi = self.integrals(w, q)
        I, J, mgl = self.transverse_inertia, self.axial_inertia, self.mgl
        e_red = energy - 0.5 * p_phi**2 / J  # E - J w3^2 / 2
        a = p_phi  # J w3
        return np.array([2 * mgl / I, -2 * e_red / I - a * a / I**2, -2 * mgl / I + 2 * p_psi * a / I**2, 2 * e_red / I - p_psi**2 / I**2])

    def nutation_bounds(self, w, q):
        """Turning points ``(theta_min, theta_max)`` (rad) of the nutation for one state ``(w, q)``.

        The two smallest real roots of the cubic ``f(u)`` bracket the motion
        (``f > 0`` between them; ``f(+-1) <= 0``); ``theta = arccos(u)``.
        """
        c = self.nutation_polynomial(w, q)
        roots = np.roots(c if c[0] != 0 else c[1:])
        r = np.sort(roots.real)
        u_lo, u_hi = np.clip(r[0], -1.0, 1.0), np.clip(r[1], -1.0, 1.0)
        return float(np.arccos(u_hi)), float(np.arccos(u_lo))

    def simulate(self, w0, q0, t, method="split4", step=None, **kwargs):
        """Propagate the top: ``(w, q, info)`` as :func:`~astrodyn.attitude.integrators.propagate_attitude`."""
        from astrodyn.attitude.integrators import propagate_attitude

        return propagate_attitude(self.inertia, w0, q0, t, torque=self.gravity_torque(), method=method, step=step, **kwargs)
