"""Lightly flexible spacecraft: a rigid hub with cantilevered Euler-Bernoulli appendages,
by the assumed-modes method (H. Baruh, *Analytical Dynamics*, ch. 11), with the geometric
(centrifugal) stiffening of T. R. Kane, R. R. Ryan and A. K. Banerjee, "Dynamics of a
cantilever beam attached to a moving base", J. Guidance 10(2), 139-151 (1987).

Large rigid-body motion of the hub, small elastic motion of the appendages: the equations
are exact in the hub's attitude and rates and linear in the elastic coordinates, except
for the one second-order effect a linear deformation field loses -- the foreshortening of
a bent beam, which is where the centrifugal stiffening comes from (KRB 1987).  The
classical linear formulation (no foreshortening, no stiffening; KRB's "conventional"
approach) is kept as an option (``stiffening=False``) for comparison.

Beam and assumed modes
----------------------
A uniform beam of length ``L`` (m), mass per length ``rho`` (kg/m) and bending stiffness
``EI`` (N m^2) is clamped at ``x = 0`` to the hub, ``x`` along its undeformed axis; rotary
inertia and shear are neglected (Euler-Bernoulli) and it is inextensible.  Its transverse
deflection in one bending plane is ``w(x, t) = sum_j phi_j(x) q_j(t)`` (``q_j`` in m, the
``phi_j`` dimensionless) with admissible functions spanning the polynomials
``(x/L)^2, ..., (x/L)^(n+1)`` (``phi(0) = phi'(0) = 0``).  ``basis="monomial"`` uses them as
they are; ``basis="modal"`` (the default) the Rayleigh-Ritz modes of the non-spinning beam
in that span, mass-normalised (``M = rho L I``, ``K = rho L diag(omega_j^2)``) with a positive
tip value: the same span, so the same Rayleigh-Ritz results, but well conditioned and with
coordinates that are (nearly) modal amplitudes.  The matrices, all by exact Gauss-Legendre
quadrature of the polynomials (:func:`beam_matrices`)::

    M_ij  = rho int phi_i phi_j dx                          mass, kg
    K_ij  = EI  int phi_i'' phi_j'' dx                      stiffness, N/m
    Sa_ij = rho int (L - x) phi_i' phi_j' dx                axial-load stiffness per unit root acceleration, kg/m
    Sb_ij = rho int (L^2 - x^2)/2 phi_i' phi_j' dx          centrifugal stiffness of a beam at r = 0, kg
    S     = r Sa + Sb                                       geometric stiffness per Omega^2 (N/m per (rad/s)^2)
    beta_j = rho int phi_j dx,  gamma_j = rho int x phi_j dx

``S`` is the work of the tension ``P(x) = rho Omega^2 (r (L - x) + (L^2 - x^2)/2)`` of a beam
spinning at ``Omega`` about an axis normal to it, with its root at the distance ``r`` (m,
the hub radius) from the axis.  A spinning beam's frequencies (:func:`natural_frequencies`)
solve ``(K + Omega^2 S) = omega^2 M`` for bending out of the plane of rotation (flapping)
and ``(K + Omega^2 (S - M)) = omega^2 M`` in it (lead-lag: the centrifugal force's
transverse component softens it by ``Omega^2``); to first order in ``Omega^2``,
``omega^2 = omega_0^2 + lambda Omega^2`` with the Southwell coefficient ``lambda``
(``lambda - 1`` in plane).  Damping, when asked for, is modal on the non-spinning
Rayleigh-Ritz modes: ``C = M V diag(2 zeta omega_j) V^T M`` (``V`` the M-orthonormal
eigenvectors), N s/m.

Kinematics and the kinetic energy (the derivation)
--------------------------------------------------
Body frame B fixed in the hub with origin O at the hub's mass centre.  Appendage ``k`` is
clamped at the root ``a`` (m, body components) with axis ``e`` and bending directions
``f`` and ``g = e x f`` (unit vectors in B); ``eta = (eta_f, eta_g)`` are its elastic
coordinates in the two planes.  A point at ``x`` is at (body components, from O)::

    p = a + (x + u) e + d,   d = f phi.eta_f + g phi.eta_g,   u(x) = -1/2 int_0^x (w_f'^2 + w_g'^2) dxi

``u`` is the foreshortening of the inextensible bent beam (KRB 1987), second order in
``eta``; with ``stiffening=False`` it is left out.  With ``v`` and ``w`` the velocity of
O and the hub's angular velocity (body components), a point's inertial velocity is
``v + w x p + dp/dt``.  The kinetic energy ``T = 1/2 m_h v.v + 1/2 w.J_h w +
sum_k 1/2 int rho |v + w x p + dp/dt|^2 dx`` is kept to second order in the elastic
coordinates and their rates (all orders in ``v, w``); that gives exactly::

    T = 1/2 m v.v + v.(w x s) + 1/2 w.I w + v.sdot + w.h + sum_k 1/2 etadot.Mq etadot

with the total mass ``m``, the first moment ``s = sum_k (s0 + c1 + U0 e)`` (``s0`` of the
undeformed beam, ``c1 = int rho d``, ``U0 = int rho u = -1/2 eta.Sa eta``), the inertia
about O ``I = J_h + sum_k (I0 + dI1 + dI2 + dI4)`` -- the undeformed beams, the first-order
change ``int rho (2 p0.d 1 - p0 d^T - d p0^T)``, ``int rho (d.d 1 - d d^T)`` and the
foreshortening's ``int rho u (2 p0.e 1 - p0 e^T - e p0^T)`` (``U1 = int rho x u = -1/2
eta.Sb eta``) -- the first moment's rate ``sdot = ds/dt`` and the relative angular
momentum ``h = sum_k (R etadot + e (eta_f.M etadot_g - eta_g.M etadot_f) + (a x e) dU0/dt)``,
``R = int rho p0 x Phi``.  The strain energy is ``V = sum_k 1/2 eta.Kq eta`` (``Mq, Kq, Cq``
block-diagonal with ``M, K, C`` for the two planes).

Equations of motion (Lagrange in quasi-coordinates)
---------------------------------------------------
For the body-frame velocities, Lagrange's equations in quasi-coordinates (Boltzmann-Hamel;
Baruh's treatment of Lagrange's equations for a body frame), and Lagrange's equations for
the elastic coordinates::

    d/dt dT/dv + w x dT/dv = F               (F = 0: no external force)
    d/dt dT/dw + w x dT/dw + v x dT/dv = tau (the external torque on the hub, body components, N m)
    d/dt dT/detadot - dT/deta + Kq eta + Cq etadot = 0

``dT/dv = P`` is the linear momentum and ``dT/dw = H`` the angular momentum about O.
Written out, the elastic equations of one appendage are::

    (D1^T - Sa eta e^T) vdot + (R^T + J2 eta e^T - Sa eta (a x e)^T) wdot + Mq etaddot
      + 2 (w.e) J2 etadot + Kq eta + Cq etadot
      = D1^T (v x w - w x (w x a)) - D2^T (w x (w x e)) + (Q (x) M) eta
        - (axial acceleration of the root and centrifugal load) Sa eta - (|w|^2 - (w.e)^2) Sb eta

(``D1 = int rho Phi``, ``D2 = int rho x Phi``, ``J2 eta = (-M eta_g, M eta_f)``, ``Q_{fg} =
f.(|w|^2 1 - w w^T).g``, the root load term ``((vdot + w x v + wdot x a).e - (w x a).(w x e))
Sa eta`` split between the two sides as the mass matrix shows): the base excitation, the
Coriolis coupling, the centrifugal softening ``Q`` and the stiffening.  For a beam spinning
at ``Omega`` about a normal axis the stiffening term is ``Omega^2 (r Sa + Sb) = Omega^2 S``.
The generalized mass matrix ``d^2 T / d(v, w, etadot)^2`` is assembled and solved by its
Schur complement on the 6 rigid-body rows (the elastic block is constant).

The truncated ``T`` is an exact Lagrangian, so the equations conserve ``E = T + V`` (when
undamped and torque-free), the inertial linear momentum ``C^T P`` and the angular momentum
about the inertial origin ``r_O x C^T P + C^T H`` exactly: to the integrator's tolerance.
Damping dissipates at ``dE/dt = -sum etadot.Cq etadot``.

The planar model (:func:`planar_free_rates`, :func:`planar_prescribed_rates`) is the same
theory restricted to one beam bending in the plane of the hub's rotation ``theta`` about a
fixed axis through O (the hub pinned at O, or a symmetric pair of beams bending
antisymmetrically), with ``a = r e``::

    T = 1/2 (J + q.D q) theta'^2 + theta' b.q' + 1/2 q'.M q',   V = 1/2 q.K q
    J = J_hub + rho ((r + L)^3 - r^3) / 3,  b = r beta + gamma,  D = M - S  (M with stiffening=False)

    M q'' + b theta'' + C q' + (K - theta'^2 D) q = 0
    (J + q.D q) theta'' + b.q'' + 2 theta' q.D q' = tau

so a beam spinning at ``theta' = Omega`` has the stiffness ``K + Omega^2 (S - M)`` -- and,
without stiffening, ``K - Omega^2 M``, which loses its positive definiteness above the
first bending frequency: the classical formulation's spurious divergence (KRB 1987).

Frames, units and the state vectors
-----------------------------------
SI throughout: m, kg, s, rad, N, N m.  Euler parameters ``q = (e0, e1, e2, e3)`` scalar
first with ``v_body = C(q) v_inertial`` and ``dq/dt = 1/2 Omega(w) q`` (:mod:`astrodyn.rotation`).
The state of :class:`FlexibleSpacecraft` (:func:`state_layout`), shape ``(13 + 2 n_el,)``::

    q (4), w (3, rad/s, body), r_O (3, m, inertial), v (3, m/s, body), eta (n_el, m), etadot (n_el, m/s)

with ``eta`` the appendages' coordinates in order, each ``(eta_f (n_modes), eta_g (n_modes))``.
The planar free-hub state is ``(theta, theta', q (n), q' (n))``, the prescribed-motion
state ``(q (n), q' (n))``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.polynomial import legendre as _leg

from astrodyn.attitude.output_times import check_output_times, integrate_dop853
from astrodyn.inputs import NonRealInputError, real_array, real_scalar
from astrodyn.jit import jit

__all__ = [
    "BeamModes", "beam_matrices", "shape_functions", "natural_frequencies",
    "krb_spinup", "tip_deflection",
    "planar_prescribed_rates", "propagate_planar_prescribed",
    "planar_free_rates", "propagate_planar_free", "planar_energy", "planar_angular_momentum",
    "Appendage", "FlexibleSpacecraft", "state_layout", "make_state", "spacecraft_rates", "spacecraft_rates_reference",
    "propagate_spacecraft",
    "spacecraft_energy", "spacecraft_momentum", "spacecraft_energy_reference", "spacecraft_momentum_reference",
    "tip_deflections",
]


# --------------------------------------------------------------------------- the beam


@dataclass(frozen=True, eq=False)
class BeamModes:
    """Assumed modes of a uniform clamped-free beam (:func:`beam_matrices`).

    ``coef`` (n, n + 2): ``phi_j(x) = sum_k coef[j, k] P_k(2 x / L - 1)`` (Legendre
    polynomials ``P_k``).  Matrices as in the module docstring: ``M`` kg, ``K`` N/m,
    ``C`` N s/m, ``Sa`` kg/m, ``Sb`` kg, ``S = r Sa + Sb`` kg; ``beta`` kg, ``gamma``
    kg m; ``tip = phi(L)``; ``G_tip_ij = int_0^L phi_i' phi_j' dx`` (1/m), so the tip's
    foreshortening is ``-1/2 q.G_tip q``; ``omega0`` the non-spinning Rayleigh-Ritz
    frequencies (rad/s)."""

    EI: float
    rho: float
    L: float
    r: float
    basis: str
    coef: np.ndarray
    M: np.ndarray
    K: np.ndarray
    C: np.ndarray
    Sa: np.ndarray
    Sb: np.ndarray
    S: np.ndarray
    beta: np.ndarray
    gamma: np.ndarray
    tip: np.ndarray
    G_tip: np.ndarray
    omega0: np.ndarray

    @property
    def n_modes(self) -> int:
        return self.M.shape[0]

    @property
    def mass(self) -> float:
        """The beam's mass ``rho L`` (kg)."""
        return self.rho * self.L


def _real(name, value, who):
    """``value`` as a float: real numbers only (:func:`astrodyn.inputs.real_scalar`:
    ``NonRealInputError`` naming ``who: name`` for None, strings, bools, complex...)."""
    return real_scalar(value, name, who)


def _state_vector(name, value, size, who, finite=True):
    """``value`` as a float64 vector of ``size`` (``finite``) real numbers
    (:func:`astrodyn.inputs.real_array`), or an error naming it."""
    y = real_array(value, name, who)
    if y.shape != (size,) or (finite and not np.all(np.isfinite(y))):
        raise ValueError(f"{name}: expected {size} {'finite ' if finite else ''}numbers, got shape {y.shape}")
    return y


def _positive(name, value, who):
    value = _real(name, value, who)
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"{name}: expected a finite number > 0, got {value!r}")
    return value


def _series_values(coef, xi, derivative):
    """Values (n, len(xi)) of the Legendre series ``coef`` (n, m) in ``t = 2 xi - 1``, or of
    their ``derivative``-th derivative with respect to ``xi``."""
    c = coef.T
    if derivative:
        c = _leg.legder(c, derivative, scl=2.0, axis=0)
    return _leg.legval(2.0 * xi - 1.0, c).reshape(coef.shape[0], -1)


def _matrices(coef, EI, rho, L):
    """Every beam integral of the module docstring for the series ``coef``, by
    Gauss-Legendre quadrature exact for their degree."""
    n_pts = coef.shape[1] + 3
    t, wq = _leg.leggauss(n_pts)
    xi, wq = 0.5 * (t + 1.0), 0.5 * wq  # nodes and weights on [0, 1]
    p0 = _series_values(coef, xi, 0)
    p1 = _series_values(coef, xi, 1)  # d/dxi
    p2 = _series_values(coef, xi, 2)
    M = rho * L * (p0 * wq) @ p0.T
    K = EI / L**3 * (p2 * wq) @ p2.T
    Sa = rho * (p1 * (wq * (1.0 - xi))) @ p1.T
    Sb = 0.5 * rho * L * (p1 * (wq * (1.0 - xi * xi))) @ p1.T
    G_tip = (p1 * wq) @ p1.T / L
    beta = rho * L * p0 @ wq
    gamma = rho * L * L * p0 @ (wq * xi)
    tip = _series_values(coef, np.array([1.0]), 0)[:, 0]
    sym = lambda A: 0.5 * (A + A.T)  # noqa: E731 -- quadrature round-off only
    return sym(M), sym(K), sym(Sa), sym(Sb), sym(G_tip), beta, gamma, tip


def beam_matrices(n_modes: int, EI: float, rho: float, L: float, r: float = 0.0, *, basis: str = "modal",
                  damping_ratio: float = 0.0) -> BeamModes:
    """Assumed-modes matrices of a uniform clamped-free beam: ``n_modes`` shape functions
    spanning ``(x/L)^2 .. (x/L)^(n_modes+1)``, bending stiffness ``EI`` (N m^2), mass per
    length ``rho`` (kg/m), length ``L`` (m), root at the distance ``r`` (m) from the spin
    axis (the hub radius).  ``basis``: ``"modal"`` (mass-normalised Rayleigh-Ritz modes of
    the non-spinning beam; ``n_modes`` 1 to 24) or ``"monomial"`` (1 to 8: ill-conditioned
    beyond); ``damping_ratio`` ``zeta`` of every
    non-spinning mode (module docstring).  Returns a :class:`BeamModes`."""
    if not isinstance(basis, str) or basis not in ("modal", "monomial"):
        raise ValueError(f"basis: expected 'modal' or 'monomial', got {basis!r}")
    # the monomials' mass matrix is Hilbert-like (condition ~ 2e12 at n = 8, ~1e17 at 12):
    # past 8 their frequencies lose all accuracy and the Cholesky of M fails (n >= 12)
    n_max = 8 if basis == "monomial" else 24
    if isinstance(n_modes, (bool, np.bool_)):
        raise NonRealInputError(f"beam_matrices: n_modes: expected an integer from 1 to {n_max}, got {n_modes!r}")
    try:
        n = int(n_modes)
        ok = n == n_modes and 1 <= n <= n_max
    except (TypeError, ValueError, OverflowError):  # None, "3", nan, inf
        ok = False
    if not ok:
        raise ValueError(f"n_modes: expected an integer from 1 to {n_max} (basis {basis!r}), got {n_modes!r}")
    who = "beam_matrices"
    EI, rho, L = _positive("EI", EI, who), _positive("rho", rho, who), _positive("L", L, who)
    r = _real("r", r, who)
    if not (math.isfinite(r) and r >= 0):
        raise ValueError(f"r: expected a finite number >= 0 (m), got {r!r}")
    zeta = _real("damping_ratio", damping_ratio, who)
    if not (math.isfinite(zeta) and zeta >= 0):
        raise ValueError(f"damping_ratio: expected a finite number >= 0, got {damping_ratio!r}")
    # xi^2 P_k(2 xi - 1), k < n: the span of xi^2 .. xi^(n+1), well conditioned
    xi2 = _leg.poly2leg([0.25, 0.5, 0.25])  # xi^2 = ((t + 1)/2)^2 in t = 2 xi - 1
    base = np.zeros((n, n + 2))
    for k in range(n):
        ck = _leg.legmul(xi2, np.eye(k + 1)[k])
        base[k, : ck.size] = ck
    M, K = _matrices(base, EI, rho, L)[:2]
    from scipy.linalg import eigh

    lam, V = eigh(K, M)  # V^T M V = I
    if basis == "modal":
        V = V * math.sqrt(rho * L)  # M = rho L I
        coef = V.T @ base
        tips = _series_values(coef, np.array([1.0]), 0)[:, 0]
        coef = coef * np.where(tips < 0, -1.0, 1.0)[:, None]
    else:
        coef = np.zeros((n, n + 2))
        for j in range(n):  # xi^(j+2) as a Legendre series in t
            cj = _leg.poly2leg(np.polynomial.polynomial.polypow([0.5, 0.5], j + 2))
            coef[j, : cj.size] = cj
    M, K, Sa, Sb, G_tip, beta, gamma, tip = _matrices(coef, EI, rho, L)
    lam, Vb = eigh(K, M)
    omega0 = np.sqrt(np.maximum(lam, 0.0))
    MV = M @ Vb
    C = (MV * (2.0 * zeta * omega0)) @ MV.T
    return BeamModes(EI, rho, L, r, basis, coef, M, K, 0.5 * (C + C.T), Sa, Sb, r * Sa + Sb, beta, gamma, tip,
                     G_tip, omega0)


def shape_functions(beam: BeamModes, x, derivative: int = 0) -> np.ndarray:
    """The shape functions ``phi_j(x)`` (dimensionless), or their ``derivative``-th
    derivative (1/m^k), at ``x`` (m, 0 at the root), shape ``(n_modes,) + x.shape``."""
    x = real_array(x, "x", "shape_functions")
    if isinstance(derivative, (bool, np.bool_)):
        raise NonRealInputError(f"shape_functions: derivative: expected an integer >= 0, got {derivative!r}")
    try:
        ok = int(derivative) == derivative and derivative >= 0
    except (TypeError, ValueError, OverflowError):  # None, "1", nan, inf
        ok = False
    if not ok:
        raise ValueError(f"derivative: expected an integer >= 0, got {derivative!r}")
    values = _series_values(beam.coef, x.reshape(-1) / beam.L, int(derivative)) / beam.L ** int(derivative)
    return values.reshape((beam.n_modes,) + x.shape)


def natural_frequencies(beam: BeamModes, spin: float = 0.0, plane: str = "out", stiffening: bool = True) -> np.ndarray:
    """Bending frequencies (rad/s, ascending) of the beam spinning at ``spin`` (rad/s)
    about an axis normal to it, at its root's distance ``beam.r``: bending out of the
    plane of rotation (``plane="out"``, flapping) solves ``(K + spin^2 S) = omega^2 M``,
    in it (``"in"``, lead-lag) ``(K + spin^2 (S - M)) = omega^2 M``; ``stiffening=False``
    drops ``S`` (the classical linear formulation).  A negative ``omega^2`` (divergence)
    is returned as ``-sqrt(-omega^2)``."""
    from scipy.linalg import eigh

    if plane not in ("out", "in"):
        raise ValueError(f"plane: expected 'out' or 'in', got {plane!r}")
    spin = _real("spin", spin, "natural_frequencies")
    if not math.isfinite(spin):
        raise ValueError(f"spin: expected a finite number (rad/s), got {spin!r}")
    W2 = spin**2
    Keff = beam.K + (W2 * beam.S if stiffening else 0.0) - (W2 * beam.M if plane == "in" else 0.0)
    lam = eigh(Keff, beam.M, eigvals_only=True)
    return np.sign(lam) * np.sqrt(np.abs(lam))


def tip_deflection(beam: BeamModes, q) -> np.ndarray:
    """Transverse tip deflection ``w(L) = sum_j phi_j(L) q_j`` (m) of coordinates
    ``q`` (..., n_modes)."""
    return real_array(q, "q", "tip_deflection") @ beam.tip


# --------------------------------------------------------------------------- planar model


def krb_spinup(t, omega_s: float = 6.0, T: float = 15.0):
    """The spin-up of Kane, Ryan & Banerjee (1987): ``theta(t) = (omega_s / T) (t^2 / 2 +
    (T / 2 pi)^2 (cos(2 pi t / T) - 1))`` for ``t < T``, then the constant rate
    ``omega_s`` (rad/s): ``theta = omega_s (t - T / 2)``.  Returns ``(theta, theta',
    theta'')`` in rad, rad/s, rad/s^2 (floats, or arrays like ``t``)."""
    omega_s, T = _real("omega_s", omega_s, "krb_spinup"), _positive("T", T, "krb_spinup")
    if not math.isfinite(omega_s):
        raise ValueError(f"omega_s: expected a finite number (rad/s), got {omega_s!r}")
    t = real_array(t, "t", "krb_spinup")
    k = 2.0 * math.pi / T
    up = t < T
    th = np.where(up, omega_s / T * (t * t / 2 + (np.cos(k * t) - 1.0) / (k * k)), omega_s * (t - T / 2))
    thd = np.where(up, omega_s / T * (t - np.sin(k * t) / k), omega_s)
    thdd = np.where(up, omega_s / T * (1.0 - np.cos(k * t)), 0.0)
    if t.ndim == 0:
        return float(th), float(thd), float(thdd)
    return th, thd, thdd


def _planar_D(beam, stiffening):
    return beam.M - beam.S if stiffening else beam.M


def _planar_J_b(beam):
    """Rigid inertia about O (kg m^2) and coupling ``b = r beta + gamma`` (kg m)."""
    return beam.rho * ((beam.r + beam.L) ** 3 - beam.r**3) / 3.0, beam.r * beam.beta + beam.gamma


def planar_prescribed_rates(beam: BeamModes, t: float, state, hub_motion: Callable, stiffening: bool = True):
    """Rates of the state ``(q, q')`` (2 n) of a beam on a hub turning as prescribed,
    ``hub_motion(t) -> (theta, theta', theta'')`` (rad, rad/s, rad/s^2):
    ``M q'' = -b theta'' - C q' - (K - theta'^2 D) q`` (module docstring)."""
    n = beam.n_modes
    t = _real("t", t, "planar_prescribed_rates")
    s = _state_vector("state", state, 2 * n, "planar_prescribed_rates", finite=False)
    q, qd = s[:n], s[n:]
    _, thd, thdd = hub_motion(t)
    _, b = _planar_J_b(beam)
    f = -b * thdd - beam.C @ qd - (beam.K - thd * thd * _planar_D(beam, stiffening)) @ q
    return np.concatenate([qd, np.linalg.solve(beam.M, f)])


def propagate_planar_prescribed(beam: BeamModes, hub_motion: Callable, state0, t, stiffening: bool = True,
                                rtol: float = 1e-10, atol: float = 1e-12):
    """States ``(len(t), 2 n)`` = ``(q, q')`` (m, m/s) at the times ``t`` (s, from 0) of a
    beam on a hub turning as ``hub_motion(t) -> (theta, theta', theta'')`` (e.g.
    :func:`krb_spinup`); DOP853.  Returns ``(states, info)``."""
    n = beam.n_modes
    who = "propagate_planar_prescribed"
    y0 = _state_vector("state0", state0, 2 * n, who)
    t = check_output_times(real_array(t, "t", who))
    rtol, atol = _real("rtol", rtol, who), _real("atol", atol, who)
    _, b = _planar_J_b(beam)
    D = _planar_D(beam, stiffening)
    Minv = np.linalg.inv(beam.M)
    K, C = beam.K, beam.C

    def rhs(time, y):
        q, qd = y[:n], y[n:]
        _, thd, thdd = hub_motion(time)
        return np.concatenate([qd, Minv @ (-b * thdd - C @ qd - (K - thd * thd * D) @ q)])

    states, nfev = integrate_dop853(rhs, y0, t, rtol, atol, "planar beam")
    return states, {"method": "dop853", "rtol": rtol, "atol": atol, "nfev": nfev}


def planar_free_rates(beam: BeamModes, hub_inertia: float, state, torque: float = 0.0, stiffening: bool = True):
    """Rates of the state ``(theta, theta', q, q')`` of a hub of moment of inertia
    ``hub_inertia`` (kg m^2, about its fixed axis through O) carrying the beam, under the
    hub torque ``torque`` (N m); module docstring's two equations, solved together."""
    n = beam.n_modes
    who = "planar_free_rates"
    hub_inertia, torque = _real("hub_inertia", hub_inertia, who), _real("torque", torque, who)
    s = _state_vector("state", state, 2 + 2 * n, who, finite=False)
    thd, q, qd = s[1], s[2 : 2 + n], s[2 + n :]
    Jb, b = _planar_J_b(beam)
    D = _planar_D(beam, stiffening)
    Dq = D @ q
    A = np.empty((n + 1, n + 1))
    A[0, 0] = hub_inertia + Jb + q @ Dq
    A[0, 1:] = A[1:, 0] = b
    A[1:, 1:] = beam.M
    f = np.concatenate([[torque - 2.0 * thd * (Dq @ qd)], thd * thd * Dq - beam.K @ q - beam.C @ qd])
    acc = np.linalg.solve(A, f)  # (theta'', q'')
    return np.concatenate([[thd, acc[0]], qd, acc[1:]])  # same order as the state


def propagate_planar_free(beam: BeamModes, hub_inertia: float, state0, t, torque: Callable | None = None,
                          stiffening: bool = True, rtol: float = 1e-11, atol: float = 1e-13):
    """States ``(len(t), 2 + 2 n)`` = ``(theta, theta', q, q')`` at the times ``t`` (s,
    from 0) of the free hub (``hub_inertia`` kg m^2) with one beam, under
    ``torque(t, state)`` (N m, or none); DOP853.  Returns ``(states, info)`` with the
    largest relative drift of the energy and of the angular momentum (meaningful when
    undamped and torque-free)."""
    n = beam.n_modes
    who = "propagate_planar_free"
    J = _positive("hub_inertia", hub_inertia, who)
    y0 = _state_vector("state0", state0, 2 + 2 * n, who)
    t = check_output_times(real_array(t, "t", who))
    rtol, atol = _real("rtol", rtol, who), _real("atol", atol, who)

    def rhs(time, y):
        return planar_free_rates(beam, J, y, 0.0 if torque is None else float(torque(time, y)), stiffening)

    states, nfev = integrate_dop853(rhs, y0, t, rtol, atol, "planar hub")
    e = planar_energy(beam, J, states, stiffening)
    h = planar_angular_momentum(beam, J, states, stiffening)
    return states, {"method": "dop853", "rtol": rtol, "atol": atol, "nfev": nfev,
                    "energy_drift": float(np.max(np.abs(e - e[0])) / max(abs(e[0]), 1e-300)),
                    "momentum_drift": float(np.max(np.abs(h - h[0])) / max(abs(h[0]), 1e-300))}


def _planar_parts(beam, hub_inertia, state, stiffening, who):
    hub_inertia = _real("hub_inertia", hub_inertia, who)
    s = real_array(state, "state", who)
    n = beam.n_modes
    thd, q, qd = s[..., 1], s[..., 2 : 2 + n], s[..., 2 + n :]
    Jb, b = _planar_J_b(beam)
    J = hub_inertia + Jb + np.einsum("...i,ij,...j->...", q, _planar_D(beam, stiffening), q)
    return thd, q, qd, J, b


def planar_energy(beam: BeamModes, hub_inertia: float, state, stiffening: bool = True) -> np.ndarray:
    """``T + V`` (J) of the planar free-hub states ``(..., 2 + 2 n)``."""
    thd, q, qd, J, b = _planar_parts(beam, hub_inertia, state, stiffening, "planar_energy")
    T = 0.5 * J * thd * thd + thd * (qd @ b) + 0.5 * np.einsum("...i,ij,...j->...", qd, beam.M, qd)
    return T + 0.5 * np.einsum("...i,ij,...j->...", q, beam.K, q)


def planar_angular_momentum(beam: BeamModes, hub_inertia: float, state, stiffening: bool = True) -> np.ndarray:
    """Angular momentum about the axis (kg m^2/s), ``(J + q.D q) theta' + b.q'``."""
    thd, q, qd, J, b = _planar_parts(beam, hub_inertia, state, stiffening, "planar_angular_momentum")
    return J * thd + qd @ b


# --------------------------------------------------------------------------- the spacecraft


def _cross(a, b):
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def _skew(a):
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


@dataclass(frozen=True, eq=False)
class Appendage:
    """A beam (:class:`BeamModes`) clamped to the hub at ``root`` (m, body components;
    default ``beam.r * axis``), along the unit ``axis`` ``e``, bending along ``normal``
    ``f`` (perpendicular to ``e``) and ``g = e x f``."""

    beam: BeamModes
    axis: np.ndarray
    normal: np.ndarray
    root: np.ndarray | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.beam, BeamModes):
            raise ValueError(f"beam: expected a BeamModes (beam_matrices), got {type(self.beam).__name__}")
        e, f = _state_vector("axis", self.axis, 3, "Appendage"), _state_vector("normal", self.normal, 3, "Appendage")
        if np.linalg.norm(e) == 0 or np.linalg.norm(f) == 0:
            raise ValueError("axis, normal: expected finite nonzero 3-vectors")
        e, f = e / np.linalg.norm(e), f / np.linalg.norm(f)
        if abs(e @ f) > 1e-9:
            raise ValueError(f"normal: expected perpendicular to axis, got cos = {e @ f!r}")
        a = self.beam.r * e if self.root is None else _state_vector("root", self.root, 3, "Appendage")
        object.__setattr__(self, "axis", e)
        object.__setattr__(self, "normal", f)
        object.__setattr__(self, "root", a)


@dataclass(frozen=True, eq=False)
class _AppendageData:
    """Constant arrays of one appendage (module docstring's notation)."""

    n: int
    a: np.ndarray
    e: np.ndarray
    f: np.ndarray
    g: np.ndarray
    axe: np.ndarray  # a x e
    m: float
    s0: np.ndarray
    I0: np.ndarray
    M: np.ndarray
    Sa: np.ndarray
    Sb: np.ndarray
    Kq: np.ndarray
    Cq: np.ndarray
    Mq_inv: np.ndarray
    D1: np.ndarray  # (3, 2n) int rho Phi
    D2: np.ndarray  # (3, 2n) int rho x Phi
    R: np.ndarray  # (3, 2n) int rho p0 x Phi
    tip: np.ndarray
    G_tip: np.ndarray


def _appendage_data(app: Appendage, stiffening: bool) -> _AppendageData:
    bm = app.beam
    n = bm.n_modes
    a, e, f = app.root, app.axis, app.normal
    g = _cross(e, f)
    rho, L = bm.rho, bm.L
    m = rho * L
    s0 = m * a + rho * L * L / 2 * e
    pp = m * np.outer(a, a) + rho * L * L / 2 * (np.outer(a, e) + np.outer(e, a)) + rho * L**3 / 3 * np.outer(e, e)
    I0 = np.trace(pp) * np.eye(3) - pp
    Z = np.zeros((n, n))
    blk = lambda A: np.block([[A, Z], [Z, A]])  # noqa: E731
    Sa, Sb = (bm.Sa, bm.Sb) if stiffening else (Z, Z)
    D1 = np.hstack([np.outer(f, bm.beta), np.outer(g, bm.beta)])
    D2 = np.hstack([np.outer(f, bm.gamma), np.outer(g, bm.gamma)])
    R = np.hstack([np.outer(_cross(a, f), bm.beta) + np.outer(_cross(e, f), bm.gamma),
                   np.outer(_cross(a, g), bm.beta) + np.outer(_cross(e, g), bm.gamma)])
    return _AppendageData(n, a, e, f, g, _cross(a, e), m, s0, I0, bm.M, Sa, Sb, blk(bm.K), blk(bm.C),
                          blk(np.linalg.inv(bm.M)), D1, D2, R, bm.tip, bm.G_tip)


@dataclass(frozen=True, eq=False)
class FlexibleSpacecraft:
    """A rigid hub (mass ``hub_mass`` kg, inertia tensor ``hub_inertia`` (3, 3) kg m^2
    about its mass centre O, body axes) with the cantilevered ``appendages``;
    ``stiffening=False`` is the classical linear formulation (module docstring)."""

    hub_mass: float
    hub_inertia: np.ndarray
    appendages: tuple
    stiffening: bool = True
    _data: tuple = field(default=(), repr=False)
    _packed: tuple = field(default=(), repr=False)

    def __post_init__(self) -> None:
        _positive("hub_mass", self.hub_mass, "FlexibleSpacecraft")
        J = real_array(self.hub_inertia, "hub_inertia", "FlexibleSpacecraft")
        if J.shape == (3,):
            J = np.diag(J)
        if J.shape != (3, 3) or not np.all(np.isfinite(J)) or not np.allclose(J, J.T, rtol=0, atol=1e-12 * np.abs(J).max()):
            raise ValueError("hub_inertia: expected a symmetric (3, 3) tensor or 3 principal moments (kg m^2)")
        if np.min(np.linalg.eigvalsh(J)) <= 0:
            raise ValueError("hub_inertia: expected a positive definite tensor")
        apps = tuple(self.appendages)
        if not all(isinstance(a, Appendage) for a in apps):
            raise ValueError("appendages: expected Appendage instances")
        object.__setattr__(self, "hub_inertia", J)
        object.__setattr__(self, "appendages", apps)
        object.__setattr__(self, "_data", tuple(_appendage_data(a, self.stiffening) for a in apps))
        object.__setattr__(self, "_packed", _pack(self))

    @property
    def n_elastic(self) -> int:
        """Number of elastic coordinates, ``sum 2 n_modes``."""
        return sum(2 * d.n for d in self._data)

    @property
    def mass(self) -> float:
        """Total mass (kg)."""
        return self.hub_mass + sum(d.m for d in self._data)

    @property
    def damped(self) -> bool:
        """Any appendage has structural damping (then the energy falls; else it is conserved)."""
        return any(bool(np.any(a.beam.C)) for a in self.appendages)


def state_layout(sc: FlexibleSpacecraft) -> dict:
    """Slices of the state vector: ``q`` (Euler parameters), ``w`` (rad/s, body), ``r``
    (position of O, m, inertial), ``v`` (velocity of O, m/s, body), ``eta`` (m),
    ``eta_dot`` (m/s), and per appendage ``eta_k`` / ``eta_dot_k`` slices into the full
    state (each ``(eta_f, eta_g)``)."""
    ne = sc.n_elastic
    out = {"q": slice(0, 4), "w": slice(4, 7), "r": slice(7, 10), "v": slice(10, 13),
           "eta": slice(13, 13 + ne), "eta_dot": slice(13 + ne, 13 + 2 * ne), "size": 13 + 2 * ne}
    k0 = 13
    out["eta_k"], out["eta_dot_k"] = [], []
    for d in sc._data:
        out["eta_k"].append(slice(k0, k0 + 2 * d.n))
        out["eta_dot_k"].append(slice(k0 + ne, k0 + ne + 2 * d.n))
        k0 += 2 * d.n
    return out


def make_state(sc: FlexibleSpacecraft, q=(1.0, 0.0, 0.0, 0.0), w=(0.0, 0.0, 0.0), r=(0.0, 0.0, 0.0),
               v=None, eta=None, eta_dot=None) -> np.ndarray:
    """A state vector from its parts (units as in :func:`state_layout`).  ``v=None`` sets
    the velocity of O that makes the total linear momentum zero (the mass centre at rest)."""
    lay = state_layout(sc)
    ne = sc.n_elastic
    y = np.zeros(lay["size"])
    who = "make_state"
    q = _state_vector("q", q, 4, who)
    if np.linalg.norm(q) == 0:
        raise ValueError("q: expected nonzero Euler parameters")
    y[lay["q"]] = q / np.linalg.norm(q)
    y[lay["w"]] = _state_vector("w", w, 3, who)
    y[lay["r"]] = _state_vector("r", r, 3, who)
    if eta is not None:
        y[lay["eta"]] = _state_vector("eta", eta, ne, who)
    if eta_dot is not None:
        y[lay["eta_dot"]] = _state_vector("eta_dot", eta_dot, ne, who)
    if v is None:  # P = m v + (w x s + sdot + sum B_v etadot) = 0, P linear in v
        y[lay["v"]] = 0.0
        P0 = _assemble(sc, y)["P"]
        y[lay["v"]] = -P0 / sc.mass
    else:
        y[lay["v"]] = _state_vector("v", v, 3, who)
    return y


def _dcm(q):
    e0, e1, e2, e3 = q / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (e2 * e2 + e3 * e3), 2 * (e1 * e2 + e0 * e3), 2 * (e1 * e3 - e0 * e2)],
        [2 * (e1 * e2 - e0 * e3), 1 - 2 * (e1 * e1 + e3 * e3), 2 * (e2 * e3 + e0 * e1)],
        [2 * (e1 * e3 + e0 * e2), 2 * (e2 * e3 - e0 * e1), 1 - 2 * (e1 * e1 + e2 * e2)],
    ])


def _I1(a, e, c1, c2):
    """``int rho ((p0.d) 1 - (p0 d^T + d p0^T)/2)`` from ``c1 = int rho d``, ``c2 = int rho x d``."""
    P = np.outer(a, c1) + np.outer(e, c2)
    return np.trace(P) * np.eye(3) - 0.5 * (P + P.T)


def _I4(a, e, U0, U1):
    """``int rho u ((p0.e) 1 - (p0 e^T + e p0^T)/2)`` from ``U0 = int rho u``, ``U1 = int rho x u``."""
    P = U0 * np.outer(a, e) + U1 * np.outer(e, e)
    return np.trace(P) * np.eye(3) - 0.5 * (P + P.T)


def _assemble(sc: FlexibleSpacecraft, y):
    """Momenta, mass-matrix blocks and the velocity terms of the equations at state ``y``."""
    w, v = y[4:7], y[10:13]
    ne = sc.n_elastic
    eta_all, etad_all = y[13 : 13 + ne], y[13 + ne : 13 + 2 * ne]
    s_tot = np.zeros(3)
    sd_tot = np.zeros(3)
    I_tot = sc.hub_inertia.copy()
    Id_tot = np.zeros((3, 3))
    h_tot = np.zeros(3)
    fv_extra = np.zeros(3)
    fw_extra = np.zeros(3)
    ww = w @ w
    per = []
    k0 = 0
    for d in sc._data:
        n = d.n
        eta, etad = eta_all[k0 : k0 + 2 * n], etad_all[k0 : k0 + 2 * n]
        k0 += 2 * n
        ef, eg, edf, edg = eta[:n], eta[n:], etad[:n], etad[n:]
        Mef, Meg = d.M @ ef, d.M @ eg
        Sae = np.concatenate([d.Sa @ ef, d.Sa @ eg])
        Sbe = np.concatenate([d.Sb @ ef, d.Sb @ eg])
        U0, U1 = -0.5 * (eta @ Sae), -0.5 * (eta @ Sbe)
        U0d, U1d = -(Sae @ etad), -(Sbe @ etad)
        sdd = etad @ np.concatenate([d.Sa @ edf, d.Sa @ edg])
        c1, c2 = d.D1 @ eta, d.D2 @ eta
        c1d, c2d = d.D1 @ etad, d.D2 @ etad
        Eff, Egg, Efg = ef @ Mef, eg @ Meg, ef @ Meg
        fg = np.outer(d.f, d.g)
        E = Eff * np.outer(d.f, d.f) + Egg * np.outer(d.g, d.g) + Efg * (fg + fg.T)
        Edff, Edgg, Edfg = 2 * (edf @ Mef), 2 * (edg @ Meg), edf @ Meg + edg @ Mef
        Ed = Edff * np.outer(d.f, d.f) + Edgg * np.outer(d.g, d.g) + Edfg * (fg + fg.T)
        s_tot += d.s0 + c1 + U0 * d.e
        sd_tot += c1d + U0d * d.e
        I_tot += d.I0 + 2 * _I1(d.a, d.e, c1, c2) + (Eff + Egg) * np.eye(3) - E + 2 * _I4(d.a, d.e, U0, U1)
        Id_tot += 2 * _I1(d.a, d.e, c1d, c2d) + (Edff + Edgg) * np.eye(3) - Ed + 2 * _I4(d.a, d.e, U0d, U1d)
        J2e = np.concatenate([-Meg, Mef])
        h_tot += d.R @ etad + d.e * (J2e @ etad) + d.axe * U0d
        fv_extra += d.e * sdd
        fw_extra += d.axe * sdd
        Bv = d.D1 - np.outer(d.e, Sae)
        Bw = d.R + np.outer(d.e, J2e) - np.outer(d.axe, Sae)
        # elastic generalized forces except the mass-matrix terms
        we = w @ d.e
        J2ed = np.concatenate([-(d.M @ edg), d.M @ edf])
        wf, wg = w @ d.f, w @ d.g
        Qff, Qgg, Qfg = ww - wf * wf, ww - wg * wg, -wf * wg
        Qeta = np.concatenate([Qff * Mef + Qfg * Meg, Qfg * Mef + Qgg * Meg])
        vxw = _cross(v, w)
        wxa, wxe = _cross(w, d.a), _cross(w, d.e)
        f_eta = (-d.Kq @ eta - d.Cq @ etad - 2.0 * we * J2ed
                 + d.D1.T @ (vxw + ww * d.a - (w @ d.a) * w) + d.D2.T @ (ww * d.e - we * w) + Qeta
                 - ((vxw @ d.e) + wxa @ wxe) * Sae - (ww - we * we) * Sbe)
        per.append((Bv, Bw, f_eta, d.Mq_inv, eta, etad, d))
    m = sc.mass
    P = m * v + _cross(w, s_tot) + sd_tot
    H = _cross(s_tot, v) + I_tot @ w + h_tot
    return {"P": P, "H": H, "s": s_tot, "sd": sd_tot, "I": I_tot, "Id": Id_tot, "fv_extra": fv_extra,
            "fw_extra": fw_extra, "per": per, "m": m}


# --------------------------------------------------------------------------- compiled rates
#
# The same equations as spacecraft_rates_reference (below, in numpy: the reference the
# tests hold this kernel to), in one compiled pass: the per-appendage constants stacked
# and zero-padded to the largest mode count (_pack), loops instead of small numpy calls.


def _pack(sc) -> tuple:
    """The constants of every appendage stacked for :func:`_rates_kernel`: mode counts
    ``(N,)``, vectors ``(N, 6, 3)`` (a, e, f, g, a x e, s0), ``I0 (N, 3, 3)``, ``M, Sa, Sb
    (N, n, n)``, ``Kq, Cq, Mq_inv (N, 2n, 2n)``, ``D1, D2, R (N, 3, 2n)`` (n the largest
    mode count; each appendage's own block in the leading rows and columns)."""
    N = len(sc._data)
    n = max((d.n for d in sc._data), default=1)
    nn = np.array([d.n for d in sc._data], dtype=np.int64)
    vec, I0 = np.zeros((N, 6, 3)), np.zeros((N, 3, 3))
    M, Sa, Sb = np.zeros((N, n, n)), np.zeros((N, n, n)), np.zeros((N, n, n))
    Kq, Cq, Mi = np.zeros((N, 2 * n, 2 * n)), np.zeros((N, 2 * n, 2 * n)), np.zeros((N, 2 * n, 2 * n))
    D1, D2, R = np.zeros((N, 3, 2 * n)), np.zeros((N, 3, 2 * n)), np.zeros((N, 3, 2 * n))
    for k, d in enumerate(sc._data):
        m = d.n
        vec[k] = (d.a, d.e, d.f, d.g, d.axe, d.s0)
        I0[k] = d.I0
        M[k, :m, :m], Sa[k, :m, :m], Sb[k, :m, :m] = d.M, d.Sa, d.Sb
        Kq[k, : 2 * m, : 2 * m], Cq[k, : 2 * m, : 2 * m], Mi[k, : 2 * m, : 2 * m] = d.Kq, d.Cq, d.Mq_inv
        D1[k, :, : 2 * m], D2[k, :, : 2 * m], R[k, :, : 2 * m] = d.D1, d.D2, d.R
    return (np.ascontiguousarray(sc.hub_inertia, dtype=np.float64), float(sc.mass), nn, vec, I0, M, Sa, Sb, Kq, Cq,
            Mi, D1, D2, R)


@jit
def _cross3(a, b):
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


@jit
def _add_inertia_terms(out, a, e, c1, c2, U0, U1, E2, f, g, Eff, Egg, Efg):
    """``out += 2 I1(a, e, c1, c2) + (Eff + Egg) 1 - E + 2 I4(a, e, U0, U1)`` (module
    docstring), with ``E = Eff f f^T + Egg g g^T + Efg (f g^T + g f^T)``; ``E2`` scratch."""
    for i in range(3):
        for j in range(3):
            E2[i, j] = a[i] * c1[j] + e[i] * c2[j] + U0 * a[i] * e[j] + U1 * e[i] * e[j]
    tr = E2[0, 0] + E2[1, 1] + E2[2, 2]
    for i in range(3):
        for j in range(3):
            v = -(E2[i, j] + E2[j, i])  # 2 * (-(P + P^T) / 2)
            if i == j:
                v += 2.0 * tr + Eff + Egg
            v -= Eff * f[i] * f[j] + Egg * g[i] * g[j] + Efg * (f[i] * g[j] + g[i] * f[j])
            out[i, j] += v


@jit
def _assemble_kernel(y, J, mass, nn, vec, I0, M, Sa, Sb, Kq, Cq, Mi, D1, D2, R):
    """The blocks of :func:`_assemble` at state ``y``, compiled: ``(P, H, s, sd, I, Id, fv,
    fw, B, feta, T_el, V)`` with ``B`` the stacked ``[Bv; Bw]`` and ``feta`` the elastic
    forces per appendage, ``T_el = sum etadot.Mq etadot`` and ``V`` the strain energy."""
    N = nn.shape[0]
    ne = 0
    for k in range(N):
        ne += 2 * nn[k]
    w, v = y[4:7], y[10:13]
    ww = w[0] * w[0] + w[1] * w[1] + w[2] * w[2]
    s = np.zeros(3)
    sd = np.zeros(3)
    It = J.copy()
    Id = np.zeros((3, 3))
    h = np.zeros(3)
    fv = np.zeros(3)
    fw = np.zeros(3)
    E2 = np.zeros((3, 3))
    vxw = _cross3(v, w)
    nmax2 = M.shape[1] * 2
    B = np.zeros((N, 6, nmax2))  # [Bv; Bw] per appendage
    feta = np.zeros((N, nmax2))
    T_el = V = 0.0
    k0 = 0
    for k in range(N):
        n = nn[k]
        a, e, f, g, axe, s0 = vec[k, 0], vec[k, 1], vec[k, 2], vec[k, 3], vec[k, 4], vec[k, 5]
        eta = y[13 + k0 : 13 + k0 + 2 * n]
        etad = y[13 + ne + k0 : 13 + ne + k0 + 2 * n]
        k0 += 2 * n
        Mef, Meg, Medf, Medg = np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(n)
        Sae, Sbe, Saed = np.zeros(2 * n), np.zeros(2 * n), np.zeros(2 * n)
        for i in range(n):
            for j in range(n):
                Mef[i] += M[k, i, j] * eta[j]
                Meg[i] += M[k, i, j] * eta[n + j]
                Medf[i] += M[k, i, j] * etad[j]
                Medg[i] += M[k, i, j] * etad[n + j]
                Sae[i] += Sa[k, i, j] * eta[j]
                Sae[n + i] += Sa[k, i, j] * eta[n + j]
                Sbe[i] += Sb[k, i, j] * eta[j]
                Sbe[n + i] += Sb[k, i, j] * eta[n + j]
                Saed[i] += Sa[k, i, j] * etad[j]
                Saed[n + i] += Sa[k, i, j] * etad[n + j]
        U0 = U1 = U0d = U1d = sdd = 0.0
        for i in range(2 * n):
            U0 -= 0.5 * eta[i] * Sae[i]
            U1 -= 0.5 * eta[i] * Sbe[i]
            U0d -= Sae[i] * etad[i]
            U1d -= Sbe[i] * etad[i]
            sdd += etad[i] * Saed[i]
        c1, c2, c1d, c2d = np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3)
        Reta = np.zeros(3)
        for i in range(3):
            for j in range(2 * n):
                c1[i] += D1[k, i, j] * eta[j]
                c2[i] += D2[k, i, j] * eta[j]
                c1d[i] += D1[k, i, j] * etad[j]
                c2d[i] += D2[k, i, j] * etad[j]
                Reta[i] += R[k, i, j] * etad[j]
        Eff = Egg = Efg = Edff = Edgg = Edfg = 0.0
        for i in range(n):
            Eff += eta[i] * Mef[i]
            Egg += eta[n + i] * Meg[i]
            Efg += eta[i] * Meg[i]
            Edff += 2.0 * etad[i] * Mef[i]
            Edgg += 2.0 * etad[n + i] * Meg[i]
            Edfg += etad[i] * Meg[i] + etad[n + i] * Mef[i]
        J2e_etad = 0.0  # J2e = [-Meg; Mef]
        for i in range(n):
            J2e_etad += -Meg[i] * etad[i] + Mef[i] * etad[n + i]
        for i in range(3):
            s[i] += s0[i] + c1[i] + U0 * e[i]
            sd[i] += c1d[i] + U0d * e[i]
            h[i] += Reta[i] + e[i] * J2e_etad + axe[i] * U0d
            fv[i] += e[i] * sdd
            fw[i] += axe[i] * sdd
            for j in range(3):
                It[i, j] += I0[k, i, j]
        _add_inertia_terms(It, a, e, c1, c2, U0, U1, E2, f, g, Eff, Egg, Efg)
        _add_inertia_terms(Id, a, e, c1d, c2d, U0d, U1d, E2, f, g, Edff, Edgg, Edfg)
        for j in range(2 * n):
            J2ej = -Meg[j] if j < n else Mef[j - n]
            for i in range(3):
                B[k, i, j] = D1[k, i, j] - e[i] * Sae[j]
                B[k, 3 + i, j] = R[k, i, j] + e[i] * J2ej - axe[i] * Sae[j]
        we = w[0] * e[0] + w[1] * e[1] + w[2] * e[2]
        wf = w[0] * f[0] + w[1] * f[1] + w[2] * f[2]
        wg = w[0] * g[0] + w[1] * g[1] + w[2] * g[2]
        wa = w[0] * a[0] + w[1] * a[1] + w[2] * a[2]
        Qff, Qgg, Qfg = ww - wf * wf, ww - wg * wg, -wf * wg
        wxa, wxe = _cross3(w, a), _cross3(w, e)
        u1 = np.zeros(3)  # vxw + ww a - (w.a) w
        u2 = np.zeros(3)  # ww e - we w
        for i in range(3):
            u1[i] = vxw[i] + ww * a[i] - wa * w[i]
            u2[i] = ww * e[i] - we * w[i]
        geo = (vxw[0] * e[0] + vxw[1] * e[1] + vxw[2] * e[2]) + (wxa[0] * wxe[0] + wxa[1] * wxe[1] + wxa[2] * wxe[2])
        cen = ww - we * we
        for i in range(n):
            T_el += etad[i] * Medf[i] + etad[n + i] * Medg[i]
        for i in range(2 * n):
            acc = 0.0
            for j in range(2 * n):
                V += 0.5 * eta[i] * Kq[k, i, j] * eta[j]
                acc -= Kq[k, i, j] * eta[j] + Cq[k, i, j] * etad[j]
            J2edi = -Medg[i] if i < n else Medf[i - n]
            acc -= 2.0 * we * J2edi
            for j in range(3):
                acc += D1[k, j, i] * u1[j] + D2[k, j, i] * u2[j]
            acc += (Qff * Mef[i] + Qfg * Meg[i]) if i < n else (Qfg * Mef[i - n] + Qgg * Meg[i - n])
            acc -= geo * Sae[i] + cen * Sbe[i]
            feta[k, i] = acc
    P = mass * v + _cross3(w, s) + sd
    H = _cross3(s, v) + It @ w + h
    return P, H, s, sd, It, Id, fv, fw, B, feta, T_el, V


@jit
def _energy_momentum_kernel(y, J, mass, nn, vec, I0, M, Sa, Sb, Kq, Cq, Mi, D1, D2, R):
    """``(E, P_i, H_i)`` of state ``y``: the energy ``T + V`` (J), the linear momentum (kg
    m/s) and the angular momentum about the inertial origin (kg m^2/s), inertial components
    (:func:`spacecraft_energy`, :func:`spacecraft_momentum`)."""
    P, H, s, sd, It, Id, fv, fw, B, feta, T_el, V = _assemble_kernel(y, J, mass, nn, vec, I0, M, Sa, Sb, Kq, Cq, Mi,
                                                                      D1, D2, R)
    w, v = y[4:7], y[10:13]
    ne = 0
    for k in range(nn.shape[0]):
        ne += 2 * nn[k]
    T2 = v @ P + w @ H + T_el
    k0 = 0
    for k in range(nn.shape[0]):
        for i in range(2 * nn[k]):
            bvw = 0.0
            for r in range(3):
                bvw += B[k, r, i] * v[r] + B[k, 3 + r, i] * w[r]
            T2 += y[13 + ne + k0 + i] * bvw
        k0 += 2 * nn[k]
    C = _dcm_kernel(y[0:4])
    Pi = C.T @ P
    Hi = _cross3(y[7:10], Pi) + C.T @ H
    return 0.5 * T2 + V, Pi, Hi


@jit
def _dcm_kernel(q):
    """``C(q)`` (``v_body = C v_inertial``) of the normalised Euler parameters ``q``."""
    nq = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    q0, q1, q2, q3 = q[0] / nq, q[1] / nq, q[2] / nq, q[3] / nq
    return np.array([
        [1 - 2 * (q2 * q2 + q3 * q3), 2 * (q1 * q2 + q0 * q3), 2 * (q1 * q3 - q0 * q2)],
        [2 * (q1 * q2 - q0 * q3), 1 - 2 * (q1 * q1 + q3 * q3), 2 * (q2 * q3 + q0 * q1)],
        [2 * (q1 * q3 + q0 * q2), 2 * (q2 * q3 - q0 * q1), 1 - 2 * (q1 * q1 + q2 * q2)],
    ])


@jit
def _rates_kernel(y, tau, J, mass, nn, vec, I0, M, Sa, Sb, Kq, Cq, Mi, D1, D2, R):
    """``dy/dt`` of a flexible spacecraft (the state of :func:`state_layout`) under the hub
    torque ``tau`` (N m, body): Lagrange's equations in quasi-coordinates with the elastic
    coordinates eliminated by the Schur complement (module docstring)."""
    P, H, s, sd, It, Id, fv, fw, B, feta, _, _ = _assemble_kernel(y, J, mass, nn, vec, I0, M, Sa, Sb, Kq, Cq, Mi,
                                                                   D1, D2, R)
    N = nn.shape[0]
    ne = 0
    for k in range(N):
        ne += 2 * nn[k]
    w, v = y[4:7], y[10:13]
    nmax2 = M.shape[1] * 2
    rhs = np.zeros(6)
    rhs[:3] = -_cross3(w, P) - _cross3(w, sd) + fv
    rhs[3:] = tau - _cross3(w, H) - _cross3(v, P) - _cross3(sd, v) - Id @ w + fw
    A = np.zeros((6, 6))
    for i in range(3):
        A[i, i] = mass
        for j in range(3):
            A[3 + i, 3 + j] = It[i, j]
    A[0, 4], A[0, 5], A[1, 3], A[1, 5], A[2, 3], A[2, 4] = s[2], -s[1], -s[2], s[0], s[1], -s[0]  # -[s x]
    A[3, 1], A[3, 2], A[4, 0], A[4, 2], A[5, 0], A[5, 1] = -s[2], s[1], s[2], -s[0], -s[1], s[0]  # [s x]
    X = np.zeros((N, nmax2, 6))
    yk = np.zeros((N, nmax2))
    for k in range(N):
        m2 = 2 * nn[k]
        for i in range(m2):  # X = Minv B^T, yk = Minv f_eta
            for j in range(m2):
                mij = Mi[k, i, j]
                yk[k, i] += mij * feta[k, j]
                for c in range(6):
                    X[k, i, c] += mij * B[k, c, j]
        for r in range(6):  # A -= B X, rhs -= B yk
            for i in range(m2):
                b = B[k, r, i]
                rhs[r] -= b * yk[k, i]
                for c in range(6):
                    A[r, c] -= b * X[k, i, c]
    if np.all(np.isfinite(A)) and np.all(np.isfinite(rhs)):
        acc = np.linalg.solve(A, rhs)
    else:  # a non-finite state: non-finite rates (numba's solve would raise on NaN)
        acc = np.full(6, np.nan)
    out = np.empty_like(y)
    e0, e1, e2, e3 = y[0], y[1], y[2], y[3]
    out[0] = -0.5 * (e1 * w[0] + e2 * w[1] + e3 * w[2])
    ev = y[1:4]
    exw = _cross3(ev, w)
    for i in range(3):
        out[1 + i] = 0.5 * (e0 * w[i] + exw[i])
    out[4:7] = acc[3:]
    C = _dcm_kernel(y[0:4])  # C^T v with the normalised q
    for i in range(3):
        out[7 + i] = C[0, i] * v[0] + C[1, i] * v[1] + C[2, i] * v[2]
    out[10:13] = acc[:3]
    out[13 : 13 + ne] = y[13 + ne : 13 + 2 * ne]
    k0 = 0
    for k in range(N):
        m2 = 2 * nn[k]
        for i in range(m2):
            val = yk[k, i]
            for c in range(6):
                val -= X[k, i, c] * acc[c]
            out[13 + ne + k0 + i] = val
        k0 += m2
    return out


def spacecraft_rates(sc: FlexibleSpacecraft, t: float, state, torque: Callable | None = None) -> np.ndarray:
    """Time derivative of the state (module docstring), with the hub torque
    ``torque(t, state)`` (N m, body components) or none: one compiled pass
    (``_rates_kernel``; :func:`spacecraft_rates_reference` is the same in numpy)."""
    t = _real("t", t, "spacecraft_rates")
    y = _state_vector("state", state, 13 + 2 * sc.n_elastic, "spacecraft_rates", finite=False)
    tau = np.zeros(3) if torque is None else np.asarray(torque(t, y), dtype=np.float64).reshape(3)
    return _rates_kernel(y, tau, *sc._packed)


def spacecraft_rates_reference(sc: FlexibleSpacecraft, t: float, state, torque: Callable | None = None) -> np.ndarray:
    """:func:`spacecraft_rates` written with numpy calls on the assembled blocks
    (:func:`_assemble`): the readable form, and the reference the compiled kernel is
    tested against."""
    ne = sc.n_elastic
    t = _real("t", t, "spacecraft_rates_reference")
    y = _state_vector("state", state, 13 + 2 * ne, "spacecraft_rates_reference", finite=False)
    q, w, v = y[0:4], y[4:7], y[10:13]
    A = _assemble(sc, y)
    P, H, s, sd = A["P"], A["H"], A["s"], A["sd"]
    tau = np.zeros(3) if torque is None else np.asarray(torque(t, y), dtype=np.float64).reshape(3)
    f_rb = np.concatenate([-_cross(w, P) - _cross(w, sd) + A["fv_extra"],
                           tau - _cross(w, H) - _cross(v, P) - _cross(sd, v) - A["Id"] @ w + A["fw_extra"]])
    Arb = np.zeros((6, 6))
    Arb[:3, :3] = A["m"] * np.eye(3)
    Arb[:3, 3:] = -_skew(s)
    Arb[3:, :3] = _skew(s)
    Arb[3:, 3:] = A["I"]
    Ared, rhs = Arb.copy(), f_rb.copy()
    parts = []
    for Bv, Bw, f_eta, Minv, *_ in A["per"]:
        B = np.vstack([Bv, Bw])  # (6, 2n)
        X = Minv @ B.T
        yk = Minv @ f_eta
        Ared -= B @ X
        rhs -= B @ yk
        parts.append((X, yk))
    acc_rb = np.linalg.solve(Ared, rhs)
    etadd = np.concatenate([yk - X @ acc_rb for X, yk in parts]) if parts else np.zeros(0)
    e0, e = q[0], q[1:]
    qdot = np.concatenate([[-0.5 * (e @ w)], 0.5 * (e0 * w + _cross(e, w))])
    rdot = _dcm(q).T @ v
    return np.concatenate([qdot, acc_rb[3:], rdot, acc_rb[:3], y[13 + ne : 13 + 2 * ne], etadd])


def _each(sc, state, fn, who):
    """``fn`` over the last axis of ``state`` (one state or a stack of them)."""
    s = real_array(state, "state", who)
    size = 13 + 2 * sc.n_elastic
    if s.ndim == 0 or s.shape[-1] != size:
        raise ValueError(f"state: expected shape (..., {size}) (state_layout), got {s.shape}")
    rows = [np.asarray(fn(row)) for row in s.reshape(-1, s.shape[-1])]
    return np.stack(rows).reshape(s.shape[:-1] + rows[0].shape)


def spacecraft_energy(sc: FlexibleSpacecraft, state) -> np.ndarray:
    """Kinetic plus strain energy ``T + V`` (J) of states ``(..., 13 + 2 n_el)``;
    ``T = 1/2 (v.P + w.H + etadot.p_eta)`` (compiled; :func:`spacecraft_energy_reference`
    is the same in numpy)."""
    packed = sc._packed
    return _each(sc, state, lambda y: _energy_momentum_kernel(np.ascontiguousarray(y), *packed)[0], "spacecraft_energy")


def spacecraft_momentum(sc: FlexibleSpacecraft, state):
    """``(P, H)``: the linear momentum (kg m/s) and the angular momentum about the inertial
    origin (kg m^2/s), inertial components, of states ``(..., 13 + 2 n_el)`` (compiled;
    :func:`spacecraft_momentum_reference` is the same in numpy)."""
    packed = sc._packed

    def one(y):
        _, p, h = _energy_momentum_kernel(np.ascontiguousarray(y), *packed)
        return np.concatenate([p, h])

    out = _each(sc, state, one, "spacecraft_momentum")
    return out[..., :3], out[..., 3:]


def spacecraft_energy_reference(sc: FlexibleSpacecraft, state) -> np.ndarray:
    """:func:`spacecraft_energy` from the numpy blocks (:func:`_assemble`): the reference."""

    def one(y):
        A = _assemble(sc, y)
        w, v = y[4:7], y[10:13]
        T2 = v @ A["P"] + w @ A["H"]
        V = 0.0
        for Bv, Bw, _, _, eta, etad, d in A["per"]:
            T2 += etad @ (Bv.T @ v + Bw.T @ w) + etad @ np.concatenate([d.M @ etad[: d.n], d.M @ etad[d.n :]])
            V += 0.5 * eta @ d.Kq @ eta
        return 0.5 * T2 + V

    return _each(sc, state, one, "spacecraft_energy_reference")


def spacecraft_momentum_reference(sc: FlexibleSpacecraft, state):
    """:func:`spacecraft_momentum` from the numpy blocks (:func:`_assemble`): the reference."""

    def one(y):
        A = _assemble(sc, y)
        Ct = _dcm(y[0:4]).T
        P = Ct @ A["P"]
        return np.concatenate([P, _cross(y[7:10], P) + Ct @ A["H"]])

    out = _each(sc, state, one, "spacecraft_momentum_reference")
    return out[..., :3], out[..., 3:]


def tip_deflections(sc: FlexibleSpacecraft, state) -> np.ndarray:
    """Tip displacements ``(..., N, 3)`` (m, body components) of the appendages from
    their undeformed positions: ``f w_f(L) + g w_g(L) + u(L) e`` (``u`` zero without
    stiffening)."""

    def one(y):
        out = []
        k0 = 13
        for d in sc._data:
            n = d.n
            ef, eg = y[k0 : k0 + n], y[k0 + n : k0 + 2 * n]
            k0 += 2 * n
            u = -0.5 * (ef @ d.G_tip @ ef + eg @ d.G_tip @ eg) if sc.stiffening else 0.0
            out.append(d.f * (d.tip @ ef) + d.g * (d.tip @ eg) + u * d.e)
        return np.array(out).reshape(-1, 3)

    return _each(sc, state, one, "tip_deflections")


def propagate_spacecraft(sc: FlexibleSpacecraft, state0, t, torque: Callable | None = None, rtol: float = 1e-10,
                         atol: float = 1e-12):
    """States ``(len(t), 13 + 2 n_el)`` at the times ``t`` (s, from 0) from ``state0``
    under the hub torque ``torque(t, state)`` (N m, body) or none; DOP853 (scipy), the
    Euler parameters renormalised at the output times.  Returns ``(states, info)`` with
    the number of right-hand-side evaluations and, when torque-free, the largest relative
    drift of the angular momentum (``momentum_drift``: an error) and of the energy: its
    drift ``energy_drift`` (an error) when no appendage is damped, else ``energy_change``,
    the largest relative loss ``max |E - E0| / |E0|``, which is the physical dissipation
    ``int eta'^T C eta' dt``, not an error."""
    lay = state_layout(sc)
    who = "propagate_spacecraft"
    y0 = real_array(state0, "state0", who).reshape(-1)
    if y0.size != lay["size"] or not np.all(np.isfinite(y0)):
        raise ValueError(f"state0: expected {lay['size']} finite numbers (state_layout), got shape {y0.shape}")
    t = check_output_times(real_array(t, "t", who))
    rtol, atol = _real("rtol", rtol, who), _real("atol", atol, who)

    packed, zero = sc._packed, np.zeros(3)

    def rhs(time, y):  # the compiled kernel straight, without spacecraft_rates' checks
        tau = zero if torque is None else np.asarray(torque(time, y), dtype=np.float64).reshape(3)
        return _rates_kernel(y, tau, *packed)

    states, nfev = integrate_dop853(rhs, y0, t, rtol, atol, "flexible spacecraft")
    states[:, 0:4] /= np.linalg.norm(states[:, 0:4], axis=1, keepdims=True)
    info = {"method": "dop853", "rtol": rtol, "atol": atol, "nfev": nfev}
    if torque is None:
        e = spacecraft_energy(sc, states)
        _, h = spacecraft_momentum(sc, states)
        info["energy_change" if sc.damped else "energy_drift"] = float(np.max(np.abs(e - e[0])) / max(abs(e[0]), 1e-300))
        info["momentum_drift"] = float(np.max(np.linalg.norm(h - h[0], axis=1)) / max(np.linalg.norm(h[0]), 1e-300))
    return states, info
