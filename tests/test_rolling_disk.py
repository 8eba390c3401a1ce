"""The rolling disk (Baruh 10.6) in generalized speeds, against what does not come from it.

* Energy is conserved: the rolling constraint does no work (to the integrator's tolerance).
* Upright straight rolling is stable above the spin ``sqrt(g / (3 R))`` for a thin disk and
  ``sqrt(g / (4 R))`` for a hoop (Routh; the classical forward speed ``sqrt(g R / 3)`` of a
  rolling coin): 20 % above stays up, 20 % below falls.
* Steady rolling on a circle: started on the relation, the lean stays constant and the
  contact point runs on a circle of radius ``R phi' / psi'``.
* A different formulation of the same physics -- Newton-Euler for the centre of mass and
  Euler's equations in body axes, with the contact force solved at every instant from the
  differentiated rolling constraint, quaternion attitude, integrated by scipy's DOP853 --
  gives the same motion on a general, far-from-steady case.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from astrodyn.attitude.rolling_disk import (
    RollingDisk,
    center_position,
    disk_quaternion,
    energy,
    propagate_rolling_disk,
    rolling_disk_rates,
    steady_spin,
    upright_critical_spin,
)
from astrodyn.rotation import dcm_from_quat, euler_from_quat

DISK = RollingDisk(radius=0.1, mass=0.5)
G = 9.80665


def test_energy_is_conserved_on_a_general_motion():
    state0 = [0.0, 0.0, 0.3, 0.4, 0.0, 0.5, 12.0, -2.0]
    t = np.linspace(0.0, 60.0, 601)
    states, info = propagate_rolling_disk(DISK, state0, t)
    assert np.all(np.abs(np.cos(states[:, 3])) > 0.05)  # it never lies flat: the equations hold throughout
    e = energy(DISK, states)
    # DOP853 at rtol 1e-12 over ~10^4 steps: the energy error is a few 1e-12 relative
    assert np.max(np.abs(e - e[0])) / abs(e[0]) < 1e-9
    assert info["energy_drift"] < 1e-9 and info["nfev"] > 0


@pytest.mark.parametrize("disk,omega_c", [
    (DISK, math.sqrt(G / (3 * 0.1))),                             # thin disk: Omega^2 > g / (3 R)
    (RollingDisk.hoop(radius=0.2, mass=1.0), math.sqrt(G / (4 * 0.2))),  # hoop: Omega^2 > g / (4 R)
])
def test_upright_rolling_is_stable_above_the_classical_spin(disk, omega_c):
    assert upright_critical_spin(disk) == pytest.approx(omega_c, rel=1e-14)
    t = np.linspace(0.0, 20.0, 2001)
    for factor, stays_up in ((1.2, True), (0.8, False)):
        state0 = [0.0, 0.0, 0.0, 0.0, 0.0, 0.02, factor * omega_c, 0.0]  # a small push sideways
        states, _ = propagate_rolling_disk(disk, state0, t, rtol=1e-10, atol=1e-12)
        lean = np.max(np.abs(states[:, 3]))
        if stays_up:
            assert lean < 0.05, f"{factor} x critical spin: leaned to {lean:.3f} rad"
        else:
            assert lean > 0.5, f"{factor} x critical spin: only leaned to {lean:.3f} rad"


def test_steady_circular_rolling_keeps_its_lean_and_its_circle():
    theta0, psi_dot = 0.3, 2.0
    phi_dot = steady_spin(DISK, theta0, psi_dot)
    u2, u3 = psi_dot * math.sin(theta0) + phi_dot, psi_dot * math.cos(theta0)
    t = np.linspace(0.0, 30.0, 3001)  # about 10 laps
    states, _ = propagate_rolling_disk(DISK, [0.0, 0.0, 0.0, theta0, 0.0, 0.0, u2, u3], t)
    assert np.max(np.abs(states[:, 3] - theta0)) < 1e-9  # the lean does not move
    # the contact point's path: a circle of radius R phi' / psi' about (0, R phi'/psi')
    rho = DISK.radius * phi_dot / psi_dot
    centre = np.array([0.0, rho])
    radius = np.linalg.norm(states[:, :2] - centre, axis=1)
    assert np.max(np.abs(radius - abs(rho))) < 1e-9 * max(1.0, abs(rho))
    assert states[-1, 2] == pytest.approx(psi_dot * t[-1], rel=1e-10)


def _newton_euler(disk: RollingDisk, y0: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The disk as a free rigid body plus a contact force solved each instant from
    d/dt (v_G + w x rho) = 0, rho = the vector from G to the contact point.  State:
    r_G (3), v_G (3), q (4, scalar first, v_body = C(q) v_inertial), w in body axes (3);
    the symmetry axis is body y.  Written here, independently of the module."""
    m, R, A, C, g = disk.mass, disk.radius, disk.A, disk.C, disk.g
    inertia = np.diag([A, C, A])
    inv = np.diag([1 / A, 1 / C, 1 / A])
    n3 = np.array([0.0, 0.0, 1.0])

    def rhs(_, y):
        v, q, wb = y[3:6], y[6:10], y[10:13]
        q = q / np.linalg.norm(q)
        c = dcm_from_quat(q)
        n = c[1]  # the symmetry axis in inertial components (row 2 of C)
        w = c.T @ wb
        s = n3 - (n3 @ n) * n
        b3 = s / np.linalg.norm(s)
        rho = -R * b3
        n_dot = np.cross(w, n)
        s_dot = -(n3 @ n_dot) * n - (n3 @ n) * n_dot
        b3_dot = s_dot / np.linalg.norm(s) - s * (s @ s_dot) / np.linalg.norm(s) ** 3
        rho_dot = -R * b3_dot

        def cross_matrix(a):
            return np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])

        J = c.T @ inv @ c
        h = c.T @ inv @ np.cross(wb, inertia @ wb)
        Px = cross_matrix(rho)
        M = np.eye(3) / m - Px @ J @ Px
        F = np.linalg.solve(M, g * n3 + np.cross(h, rho) - np.cross(w, rho_dot))
        a = F / m - g * n3
        wb_dot = inv @ (c @ np.cross(rho, F) - np.cross(wb, inertia @ wb))
        e0, e1, e2, e3 = q
        w0, w1, w2 = wb
        q_dot = 0.5 * np.array([-e1 * w0 - e2 * w1 - e3 * w2, e0 * w0 + e2 * w2 - e3 * w1,
                                e0 * w1 + e3 * w0 - e1 * w2, e0 * w2 + e1 * w1 - e2 * w0])
        return np.concatenate([v, a, q_dot, wb_dot])

    sol = solve_ivp(rhs, (0.0, t[-1]), y0, method="DOP853", t_eval=t, rtol=1e-12, atol=1e-14)
    assert sol.success
    return sol.y.T


def test_newton_euler_with_the_constraint_force_gives_the_same_motion():
    state0 = np.array([0.2, -0.1, 0.7, 0.35, 0.4, -0.8, 15.0, 3.0])
    t = np.linspace(0.0, 3.0, 301)
    kane, _ = propagate_rolling_disk(DISK, state0, t)
    # the same initial state in the Newton-Euler variables
    psi, theta, phi, u1, u2, u3 = state0[2:]
    b1 = np.array([math.cos(psi), math.sin(psi), 0.0])
    b2 = np.array([-math.cos(theta) * math.sin(psi), math.cos(theta) * math.cos(psi), math.sin(theta)])
    v_g = DISK.radius * (u2 * b1 - u1 * b2)
    w_body = np.array([u1 * math.cos(phi) - u3 * math.sin(phi), u2, u1 * math.sin(phi) + u3 * math.cos(phi)])
    y0 = np.concatenate([center_position(DISK, state0), v_g, disk_quaternion(state0), w_body])
    ne = _newton_euler(DISK, y0, t)
    # the two attitudes, the centres and the contact points agree
    q_kane = disk_quaternion(kane)
    q_ne = ne[:, 6:10] / np.linalg.norm(ne[:, 6:10], axis=1, keepdims=True)
    # rotation angle between them: 4 asin(|qa -+ qb| / 2) (well conditioned near 0, unlike acos of the dot)
    chord = np.minimum(np.linalg.norm(q_kane - q_ne, axis=1), np.linalg.norm(q_kane + q_ne, axis=1))
    assert np.max(4 * np.arcsin(chord / 2)) < 1e-9  # rad
    assert np.max(np.linalg.norm(center_position(DISK, kane) - ne[:, :3], axis=1)) < 1e-9  # m (measured 2e-12; a 0.1 % error in C gives 3e-3)
    angles = euler_from_quat(q_ne, "312")
    assert np.max(np.abs(angles[:, 1] - kane[:, 3])) < 1e-7  # the lean
    assert np.max(np.abs(kane[:, 3] - state0[3])) > 0.05  # and the motion was far from steady
    # the Kane rates are the time derivatives of the Newton-Euler motion (central differences)
    rates = rolling_disk_rates(DISK, kane)
    dt = t[1] - t[0]
    theta_dot_fd = (kane[2:, 3] - kane[:-2, 3]) / (2 * dt)
    assert np.max(np.abs(theta_dot_fd - rates[1:-1, 3])) < 1e-2 * np.max(np.abs(rates[:, 3]))


def test_bad_parameters_and_states_are_refused():
    with pytest.raises(ValueError, match="radius"):
        RollingDisk(radius=-1.0, mass=1.0)
    with pytest.raises(ValueError, match="A: expected"):
        RollingDisk(radius=1.0, mass=1.0, A=float("nan"))
    with pytest.raises(ValueError, match="flat"):
        propagate_rolling_disk(DISK, [0, 0, 0, math.pi / 2, 0, 0, 1, 0], [0.0, 1.0])
    with pytest.raises(ValueError, match="state0"):
        propagate_rolling_disk(DISK, [0, 0, 0, float("inf"), 0, 0, 1, 0], [0.0, 1.0])
    with pytest.raises(ValueError, match="t: expected"):
        propagate_rolling_disk(DISK, [0, 0, 0, 0.1, 0, 0, 1, 0], [1.0, 2.0])
