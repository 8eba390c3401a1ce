"""Gyroscopes as instruments: the free gyroscope in two gimbals and the single-axis (rate
and rate-integrating) gyroscope on a rotating base (H. Baruh, *Analytical Dynamics*,
sec. 10.7.1 and 10.7.3).

Every body here turns about one fixed point, the intersection of the gimbal axes, which is
also every body's mass centre (a balanced instrument: no pendulosity, so translation of the
base exerts no moment).  Rotors are axisymmetric: spin (axial) moment ``C``, transverse
moment ``A`` about the fixed point (kg m^2), ``C <= 2 A`` (a rigid body).  Gimbal moments
are principal moments about the gimbal's own axes (kg m^2, zero for a massless gimbal; when
not all zero they must satisfy the triangle inequality of a rigid body).  Bearings are
frictionless; the torques named below are the only ones about the joint axes.  SI units:
kg m^2, N m, N m s, rad, rad/s, s.  Elementary frame rotations ``C_1, C_2, C_3`` as in
:mod:`astrodyn.rotation` (``v_turned = C_n(a) v``).

1. Free gyroscope in gimbals (Baruh 10.7.1)
-------------------------------------------
The base (frame N, ``n3`` the outer gimbal axis) is inertial.  The outer gimbal O turns about
``n3`` by ``psi``; the inner gimbal I about the outer gimbal's axis ``o1`` by ``theta``; the
rotor about the inner gimbal's axis ``i3`` (the spin axis) by ``phi``: ``C_O = C_3(psi)``,
``C_I = C_1(theta) C_O``, ``C_R = C_3(phi) C_I`` -- the 3-1-3 Euler angles of the rotor
(:mod:`astrodyn.attitude.top`).  The spin axis is perpendicular to the outer axis at
``theta = pi/2`` (the working attitude); ``theta = 0, pi`` is gimbal lock.  Inertias: the
outer gimbal ``I_o`` about ``n3``; the inner gimbal ``(B1, B2, B3)`` about ``i1, i2, i3``;
the rotor ``A, C``.  The inner gimbal turns at ``(theta', psi' sin theta, psi' cos theta)``
(I components), the rotor at that plus ``phi' i3``, so::

    T = 1/2 A_i theta'^2 + 1/2 M(theta) psi'^2 + 1/2 C (phi' + psi' cos theta)^2
    A_i = A + B1                                   (about the inner gimbal axis)
    M(theta) = I_o + (A + B2) sin^2 theta + B3 cos^2 theta   (about the outer gimbal axis)

With the generalized forces ``Q_psi`` (torque on the outer gimbal about ``n3``),
``Q_theta`` (on the inner gimbal about ``o1``) and ``Q_phi`` (spin motor torque on the rotor
about ``i3``), Lagrange's equations are, with ``h = C (phi' + psi' cos theta)`` the rotor's
axial angular momentum (``C n``, ``n`` its absolute axial rate) and ``M' = dM/dtheta =
2 (A + B2 - B3) sin theta cos theta``::

    h' = Q_phi
    d/dt [M psi' + h cos theta] = Q_psi:  M psi'' = Q_psi - M' theta' psi' + h sin theta theta' - Q_phi cos theta
    A_i theta'' = Q_theta + 1/2 M' psi'^2 - h psi' sin theta

(:func:`free_gyro_rates`).  Torque-free, ``h``, ``p_psi = M psi' + h cos theta`` (the
angular momentum about the outer axis) and ``T`` are constants; with massless gimbals the
rotor is a free symmetric body and its whole angular momentum vector is constant
(:func:`free_gyro_momentum`).

Nutation (the derivation).  Linearize about ``theta = theta0``, ``psi' = 0`` (every such
state is an equilibrium), ``theta = theta0 + delta``: ``h`` is constant, the ``psi'^2`` term
is second order and ``h cos theta = h cos theta0 - g delta`` with ``g = h sin theta0``, so::

    M0 psi'' = g delta' + Q_psi,    A_i delta'' = -g psi' + Q_theta      (M0 = M(theta0))

Eliminating ``psi'`` (``M0 psi' = M0 v + g delta + Q_psi t``, ``v = psi'(0)``, ``delta(0) = 0``)
gives ``delta'' + omega_n^2 delta = (Q_theta - g v) / A_i - g Q_psi t / (A_i M0)`` with the
exact linearized nutation frequency

    omega_n = |h sin theta0| / sqrt(A_i M(theta0))          (:func:`nutation_frequency`)

At the working attitude ``theta0 = pi/2`` this is Baruh's fast-rotor result
``omega_n = C n / A_eff``, ``A_eff = sqrt(A_i A_o)``, ``A_o = I_o + A + B2``
(:func:`fast_rotor_nutation_frequency`); with massless gimbals ``A_eff = A``.  ("Fast":
the linearization needs the nutation amplitudes below, which fall as ``1/n``, to be small.)
Away from ``pi/2`` the ideal formula is wrong by the factor ``sin theta0 sqrt(A_o / M(theta0))``
(the gyroscope goes soft towards gimbal lock).  Amplitudes: an inner-gimbal rate ``u`` (an
impulse ``A_i u`` about the inner axis) gives ``delta = (u / omega_n) sin omega_n t`` and
``psi - psi0 = (A_i u / g) (1 - cos omega_n t)``: nutation amplitudes ``u / omega_n =
u sqrt(A_i M0) / g`` and ``A_i u / g``, both ``~ 1/n`` -- the gyroscope's rigidity.  A
constant torque ``Q_theta`` makes it precess about the outer axis at the mean rate
``Q_theta / g`` (``psi' = (Q_theta / g)(1 - cos omega_n t)``) while ``delta = (Q_theta M0 /
g^2)(1 - cos omega_n t)``; a constant ``Q_psi`` makes it precess about the inner axis,
``delta' -> -Q_psi / g`` (:func:`free_gyro_linear`).  The neglected terms are cubic in the
nutation amplitudes (``M(theta)`` and ``h sin theta`` are even about ``pi/2``), so the
closed forms' relative error falls as ``1/n^2``.  With massless gimbals the rotor is a free
symmetric body: the spin axis cones about the constant ``H`` at ``|H| / A`` exactly, for any
amplitude.

State (:data:`FREE_STATE_FIELDS`): ``(psi, theta, phi, psi', theta', phi')`` in rad and rad/s;
``phi'`` is the rotor's rate relative to the inner gimbal.

2. Single-axis gyroscope on a rotating base (Baruh 10.7.3)
----------------------------------------------------------
The case (the base, frame B) is fixed in the vehicle: ``b1`` the input axis I, ``b2`` the
output (gimbal) axis O, ``b3 = b1 x b2`` the spin reference axis S.  The base turns at
``w = (w1, w2, w3)`` (B components, rad/s) with rate ``w' = dw/dt`` (rad/s^2; the same in B
and inertial components), both given as a function of time (:func:`constant_base_rate`,
:func:`sampled_base_rate` for any astrodyn attitude model's output).  The gimbal G turns
about ``b2`` by the output angle ``theta`` (``C_G = C_2(theta) C_B``): ``g2 = b2``, the spin
axis ``g3``, ``g1 = g2 x g3`` (the input axis when ``theta = 0``).  The rotor spins about
``g3`` at ``Omega`` relative to the gimbal.  The gimbal's principal moments ``(Ig1, Ig2,
Ig3)``; gimbal + rotor: ``J1 = Ig1 + A``, ``J2 = Ig2 + A`` (the output axis), ``J3 = Ig3 + C``.
The gimbal turns at, in G components,

    wg1 = w1 cos theta - w3 sin theta,   wg2 = w2 + theta',   wg3 = w1 sin theta + w3 cos theta,

and gimbal + rotor have the angular momentum ``(J1 wg1, J2 wg2, J3 wg3 + C Omega)`` about the
pivot (the rotor's moments in G are constant because it is symmetric).  The ``g2`` component of
Euler's law ``dH/dt|_G + wG x H = M`` for gimbal + rotor (the bearings take every other
component), with the spring ``-k theta``, the damper ``-c theta'`` and a torquer ``tau``::

    J2 (theta'' + w2') = C Omega wg1 + (J3 - J1) wg1 wg3 - k theta - c theta' + tau

and the rotor alone about ``g3``: ``C (wg3 + Omega)' = Q_spin``.  Spin motor modes: ``free_rotor
= False`` (default) holds ``Omega`` constant (an ideal speed-regulated motor, ``Omega' = 0``);
``free_rotor = True`` has no motor torque, so the rotor's absolute axial momentum
``C (wg3 + Omega)`` is constant and ``Omega' = -wg3' = -(w1' sin theta + w3' cos theta +
theta' wg1)``.  (:func:`single_axis_rates`; the state, :data:`SINGLE_STATE_FIELDS`, is
``(theta, theta', Omega)``.)

The ideal instrument equation (Baruh), with ``H = C Omega``::

    J2 theta'' + c theta' + k theta = H w1

keeps only the input-rate term.  It drops (:func:`error_torques`, all exact):

* cross-coupling: ``H (wg1 - w1) = H (w1 (cos theta - 1) - w3 sin theta) ~ -H w3 theta``: the
  gyro senses the rate about the displaced input axis ``g1``; a spin-axis rate ``w3``
  stiffens a rate gyro (``k -> k + H w3``; ``H w3 < -k`` destabilizes it) and turns a
  rate-integrating gyro into a leaky integrator (time constant ``c / (H w3)``; unstable for
  ``H w3 < 0``);
* output-axis angular acceleration: ``-J2 w2'`` (a constant ``w2`` does nothing; a
  rate-integrating gyro reads ``-J2 (w2(t) - w2(0)) / c`` of it);
* anisoinertia: ``(J3 - J1) wg1 wg3 ~ (J3 - J1) w1 w3``;
* with a free rotor, the spin change ``Omega - Omega0 = -(wg3 - wg3(0))``.

Rate gyro (``k > 0``): for a constant ``w1`` the output settles at ``theta_ss = H w1 / k``
(small angle; exact: ``k theta = wg1 (H + (J3 - J1) wg3)``), natural frequency
``sqrt(k / J2)`` and damping ratio ``c / (2 sqrt(k J2))``.  Rate-integrating gyro (``k = 0``,
``c > 0``): integrating the ideal equation from rest, ``c theta + J2 theta' = H int w1 dt``,
so ``theta ~ (H / c) int w1 dt`` once the time constant ``J2 / c`` has passed.

All propagators integrate with scipy's DOP853 and stop with ``RuntimeError`` after
``max_nfev`` right-hand-side evaluations (bounded time).  Bad inputs raise ``ValueError``
naming the field; numeric arguments take real numbers only (:mod:`astrodyn.inputs`: None,
strings, bools, complex numbers raise ``NonRealInputError``, a ``TypeError`` and a
``ValueError``, naming the function and the field).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from astrodyn.attitude.output_times import check_output_times, integrate_dop853
from astrodyn.inputs import real_array, real_scalar

__all__ = [
    "FREE_STATE_FIELDS", "SINGLE_STATE_FIELDS",
    "FreeGyroscope", "free_gyro_state", "free_gyro_rates", "propagate_free_gyro", "free_gyro_energy",
    "free_gyro_momentum", "free_gyro_integrals", "nutation_frequency", "fast_rotor_nutation_frequency",
    "free_gyro_linear",
    "SingleAxisGyro", "constant_base_rate", "sampled_base_rate", "single_axis_rates", "propagate_single_axis",
    "error_torques", "steady_state_angle", "single_axis_energy", "single_axis_jacobi_integral",
    "single_axis_momentum",
]

#: Free gyroscope state: outer, inner gimbal and rotor angles (rad) and their rates (rad/s).
FREE_STATE_FIELDS = ("psi", "theta", "phi", "psi_dot", "theta_dot", "phi_dot")
#: Single-axis gyroscope state: output angle (rad), its rate (rad/s), rotor spin relative to the gimbal (rad/s).
SINGLE_STATE_FIELDS = ("theta", "theta_dot", "spin")

DEFAULT_MAX_NFEV = 2_000_000


# --------------------------------------------------------------------------- validation


def _real(name, value, who):
    """``value`` as a float (:func:`astrodyn.inputs.real_scalar`: ``NonRealInputError``
    naming ``who: name`` for None, strings, bools, complex...; ValueError for an array)."""
    return real_scalar(value, name, who)


def _finite(name, value, who, unit=""):
    v = _real(name, value, who)
    if not math.isfinite(v):
        raise ValueError(f"{name}: expected a finite number{unit}, got {value!r}")
    return v


def _nonneg(name, value, who, unit=""):
    v = _finite(name, value, who, unit)
    if v < 0:
        raise ValueError(f"{name}: expected a finite number >= 0{unit}, got {value!r}")
    return v


def _positive(name, value, who, unit=""):
    v = _finite(name, value, who, unit)
    if not v > 0:
        raise ValueError(f"{name}: expected a finite number > 0{unit}, got {value!r}")
    return v


def _vector(name, value, size, who, unit=""):
    """A new float64 array of ``size`` finite numbers (real numbers only:
    :func:`astrodyn.inputs.real_array`), or an error naming ``name``."""
    y = np.array(real_array(value, name, who), dtype=np.float64)
    if y.shape != (size,) or not np.all(np.isfinite(y)):
        raise ValueError(f"{name}: expected {size} finite numbers{unit}, got shape {y.shape}"
                         + ("" if y.shape != (size,) else f" with values {y.tolist()}"))
    return y


def _gimbal_moments(name, value, who):
    """Three principal moments >= 0 (kg m^2) obeying the triangle inequality unless all zero."""
    m = _vector(name, value, 3, who, " (kg m^2)")
    if np.any(m < 0):
        raise ValueError(f"{name}: moments of inertia must be >= 0 (kg m^2), got {m.tolist()}")
    total = float(m.sum())
    if total > 0 and np.any(2.0 * m > total * (1.0 + 1e-12)):
        raise ValueError(f"{name}: principal moments {m.tolist()} violate the triangle inequality of a rigid "
                         "body (each must be <= the sum of the other two)")
    return m


def _rotor(C, A, c_name, a_name, who):
    C = _positive(c_name, C, who, " (kg m^2)")
    A = _positive(a_name, A, who, " (kg m^2)")
    if C > 2.0 * A * (1.0 + 1e-12):
        raise ValueError(f"{c_name}: an axisymmetric rigid rotor needs C <= 2 A, got C = {C!r}, A = {A!r}")
    return C, A


def _tolerances(rtol, atol, max_nfev, who):
    rtol = _positive("rtol", rtol, who)
    atol = _positive("atol", atol, who)
    if rtol < 1e-14:
        raise ValueError(f"rtol: expected >= 1e-14 (DOP853 cannot meet less), got {rtol!r}")
    if isinstance(max_nfev, (bool, np.bool_)) or not isinstance(max_nfev, (int, np.integer)) or max_nfev < 1:
        raise ValueError(f"max_nfev: expected a positive integer, got {max_nfev!r}")
    return rtol, atol, int(max_nfev)


class _Budget:
    """Counts right-hand-side evaluations and stops the integration past ``limit``."""

    def __init__(self, limit, what):
        self.n, self.limit, self.what = 0, limit, what

    def tick(self):
        self.n += 1
        if self.n > self.limit:
            raise RuntimeError(f"{self.what}: more than max_nfev = {self.limit} right-hand-side evaluations "
                               "(a very long span or a stiff configuration); shorten t or raise max_nfev")


# --------------------------------------------------------------------------- 1. free gyroscope


@dataclass(frozen=True)
class FreeGyroscope:
    """A rotor in two gimbals on an inertial base (module docstring, section 1).

    ``rotor_axial`` ``C`` and ``rotor_transverse`` ``A`` (kg m^2, about the pivot),
    ``inner_gimbal`` ``(B1, B2, B3)`` principal moments about the inner gimbal's axes
    ``i1`` (the inner gimbal axis), ``i2``, ``i3`` (the spin axis), ``outer_gimbal`` ``I_o``
    the outer gimbal's moment about the outer axis ``n3`` (kg m^2; default massless)."""

    rotor_axial: float
    rotor_transverse: float
    inner_gimbal: tuple = (0.0, 0.0, 0.0)
    outer_gimbal: float = 0.0

    def __post_init__(self):
        C, A = _rotor(self.rotor_axial, self.rotor_transverse, "rotor_axial", "rotor_transverse", "FreeGyroscope")
        object.__setattr__(self, "rotor_axial", C)
        object.__setattr__(self, "rotor_transverse", A)
        object.__setattr__(self, "inner_gimbal", tuple(_gimbal_moments("inner_gimbal", self.inner_gimbal,
                                                                           "FreeGyroscope").tolist()))
        object.__setattr__(self, "outer_gimbal", _nonneg("outer_gimbal", self.outer_gimbal, "FreeGyroscope", " (kg m^2)"))

    @property
    def inner_axis_inertia(self) -> float:
        """``A_i = A + B1`` (kg m^2): moment of inner gimbal + rotor about the inner gimbal axis."""
        return self.rotor_transverse + self.inner_gimbal[0]

    @property
    def outer_axis_inertia(self) -> float:
        """``A_o = I_o + A + B2`` (kg m^2): moment about the outer axis at ``theta = pi/2``."""
        return self.outer_gimbal + self.rotor_transverse + self.inner_gimbal[1]

    def outer_inertia(self, theta):
        """``M(theta) = I_o + (A + B2) sin^2 theta + B3 cos^2 theta`` (kg m^2)."""
        theta = real_array(theta, "theta", "FreeGyroscope.outer_inertia")
        s, c = np.sin(theta), np.cos(theta)
        return self.outer_gimbal + (self.rotor_transverse + self.inner_gimbal[1]) * s * s + self.inner_gimbal[2] * c * c


def _free_state(name, value, who):
    return _vector(name, value, 6, who, " (psi, theta, phi in rad, their rates in rad/s)")


def free_gyro_state(gyro: FreeGyroscope, spin: float, theta: float = 0.5 * math.pi, psi: float = 0.0,
                    psi_dot: float = 0.0, theta_dot: float = 0.0, phi: float = 0.0) -> np.ndarray:
    """A state (6,) with the rotor's absolute axial rate ``spin`` ``n`` (rad/s):
    ``phi' = n - psi' cos theta`` (so ``h = C n``)."""
    spin = _finite("spin", spin, "free_gyro_state", " (rad/s)")
    vals = {k: _finite(k, v, "free_gyro_state") for k, v in (("theta", theta), ("psi", psi), ("psi_dot", psi_dot),
                                          ("theta_dot", theta_dot), ("phi", phi))}
    return np.array([vals["psi"], vals["theta"], vals["phi"], vals["psi_dot"], vals["theta_dot"],
                     spin - vals["psi_dot"] * math.cos(vals["theta"])])


def _check_lock(gyro, theta, name):
    m = float(gyro.outer_inertia(theta))
    scale = gyro.outer_gimbal + gyro.rotor_transverse + sum(gyro.inner_gimbal)
    if not m > 1e-12 * scale:
        raise ValueError(f"{name}: theta = {theta!r} rad is at gimbal lock (the moment about the outer axis, "
                         f"{m!r} kg m^2, vanishes: massless outer gimbal and B3 = 0)")


def _free_accel(C, A_i, Io, AB2, B3, psi_d, th, th_d, phi_d, q_psi, q_th, q_phi):
    s, c = math.sin(th), math.cos(th)
    M = Io + AB2 * s * s + B3 * c * c
    Mp = 2.0 * (AB2 - B3) * s * c
    h = C * (phi_d + psi_d * c)
    psi_dd = (q_psi - Mp * th_d * psi_d + h * s * th_d - q_phi * c) / M
    th_dd = (q_th + 0.5 * Mp * psi_d * psi_d - h * psi_d * s) / A_i
    phi_dd = q_phi / C - psi_dd * c + psi_d * s * th_d
    return psi_dd, th_dd, phi_dd


def _free_torques(torques, t, y):
    if torques is None:
        return 0.0, 0.0, 0.0
    try:
        q = np.asarray(torques(t, y), dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError("torques: must return three numbers (Q_psi, Q_theta, Q_phi) in N m") from None
    if q.shape != (3,) or not np.all(np.isfinite(q)):
        raise ValueError(f"torques: expected three finite numbers (Q_psi, Q_theta, Q_phi) in N m, got {q!r}")
    return float(q[0]), float(q[1]), float(q[2])


def free_gyro_rates(gyro: FreeGyroscope, t: float, state, torques: Callable | None = None) -> np.ndarray:
    """Time derivative (6,) of the free gyroscope's ``state`` (Lagrange's equations of the
    module docstring, section 1).  ``torques(t, state) -> (Q_psi, Q_theta, Q_phi)`` (N m):
    about the outer axis on the outer gimbal, about the inner axis on the inner gimbal, and
    the spin motor's torque on the rotor; ``None`` for none."""
    t = _real("t", t, "free_gyro_rates")
    y = _vector("state", state, 6, "free_gyro_rates")
    q = _free_torques(torques, t, y)
    B1, B2, B3 = gyro.inner_gimbal
    A, C = gyro.rotor_transverse, gyro.rotor_axial
    acc = _free_accel(C, A + B1, gyro.outer_gimbal, A + B2, B3, y[3], y[1], y[4], y[5], *q)
    return np.array([y[3], y[4], y[5], *acc])


def propagate_free_gyro(gyro: FreeGyroscope, state0, t, torques: Callable | None = None, rtol: float = 1e-11,
                        atol: float = 1e-12, max_nfev: int = DEFAULT_MAX_NFEV):
    """States ``(len(t), 6)`` of the free gyroscope at the times ``t`` (s, from 0), DOP853.

    Returns ``(states, info)``; ``info`` has ``nfev`` and, torque-free, the largest relative
    drifts of the energy, ``p_psi`` and ``h`` (:func:`free_gyro_integrals`; the momenta
    relative to ``max(|p_psi|, |h|)``)."""
    if not isinstance(gyro, FreeGyroscope):
        raise ValueError(f"gyro: expected a FreeGyroscope, got {type(gyro).__name__}")
    y0 = _free_state("state0", state0, "propagate_free_gyro")
    t = check_output_times(real_array(t, "t", "propagate_free_gyro"))
    rtol, atol, max_nfev = _tolerances(rtol, atol, max_nfev, "propagate_free_gyro")
    if torques is not None and not callable(torques):
        raise ValueError("torques: expected a callable (t, state) -> (Q_psi, Q_theta, Q_phi) or None")
    _check_lock(gyro, y0[1], "state0")
    _free_torques(torques, 0.0, y0)
    B1, B2, B3 = gyro.inner_gimbal
    A, C = gyro.rotor_transverse, gyro.rotor_axial
    A_i, Io, AB2 = A + B1, gyro.outer_gimbal, A + B2
    budget = _Budget(max_nfev, "free gyroscope")

    def rhs(time, y):
        budget.tick()
        _, th, _, psi_d, th_d, phi_d = y.tolist()
        q = _free_torques(torques, time, y)
        return [psi_d, th_d, phi_d, *_free_accel(C, A_i, Io, AB2, B3, psi_d, th, th_d, phi_d, *q)]

    states, nfev = integrate_dop853(rhs, y0, t, rtol, atol, budget.what)
    info = {"method": "dop853", "rtol": rtol, "atol": atol, "nfev": nfev}
    if torques is None:
        e, p, h = free_gyro_integrals(gyro, states)
        # momenta relative to the largest of |p_psi| and |h| (p_psi is often 0)
        hscale = max(abs(float(p[0])), abs(float(h[0])), 1e-300)
        for key, v, scale in (("energy_drift", e, max(abs(float(e[0])), 1e-300)), ("p_psi_drift", p, hscale),
                              ("h_drift", h, hscale)):
            info[key] = float(np.max(np.abs(v - v[0])) / scale)
    return states, info


def _free_states(states, who):
    s = real_array(states, "states", who)
    if s.ndim < 1 or s.shape[-1] != 6:
        raise ValueError(f"states: expected shape (..., 6) = {FREE_STATE_FIELDS}, got {s.shape}")
    return s


def free_gyro_energy(gyro: FreeGyroscope, states) -> np.ndarray:
    """Kinetic energy (J) ``1/2 A_i theta'^2 + 1/2 M(theta) psi'^2 + h^2 / (2 C)``."""
    s = _free_states(states, "free_gyro_energy")
    th, psi_d, th_d, phi_d = s[..., 1], s[..., 3], s[..., 4], s[..., 5]
    h = gyro.rotor_axial * (phi_d + psi_d * np.cos(th))
    return (0.5 * gyro.inner_axis_inertia * th_d**2 + 0.5 * gyro.outer_inertia(th) * psi_d**2
            + 0.5 * h * h / gyro.rotor_axial)


def free_gyro_integrals(gyro: FreeGyroscope, states):
    """``(T, p_psi, h)``: energy (J), angular momentum about the outer axis ``M psi' + h cos
    theta`` and the rotor's axial momentum ``C (phi' + psi' cos theta)`` (N m s); constant
    when torque-free."""
    s = _free_states(states, "free_gyro_integrals")
    th, psi_d, phi_d = s[..., 1], s[..., 3], s[..., 5]
    h = gyro.rotor_axial * (phi_d + psi_d * np.cos(th))
    return free_gyro_energy(gyro, s), gyro.outer_inertia(th) * psi_d + h * np.cos(th), h


def free_gyro_momentum(gyro: FreeGyroscope, states) -> np.ndarray:
    """Angular momentum (..., 3) of outer gimbal + inner gimbal + rotor about the pivot,
    inertial (N) components, N m s.  Its ``n3`` component is ``p_psi``; the whole vector is
    constant only with massless gimbals (the bearings take the rest)."""
    s = _free_states(states, "free_gyro_momentum")
    psi, th, psi_d, th_d, phi_d = s[..., 0], s[..., 1], s[..., 3], s[..., 4], s[..., 5]
    B1, B2, B3 = gyro.inner_gimbal
    A, C = gyro.rotor_transverse, gyro.rotor_axial
    st, ct, sp, cp = np.sin(th), np.cos(th), np.sin(psi), np.cos(psi)
    h1 = (A + B1) * th_d  # inner gimbal + rotor, I components
    h2 = (A + B2) * psi_d * st
    h3 = B3 * psi_d * ct + C * (phi_d + psi_d * ct)
    # I -> O: v_O = C_1(theta)^T v_I;  O -> N: v_N = C_3(psi)^T v_O
    o1, o2, o3 = h1, ct * h2 - st * h3, st * h2 + ct * h3
    o3 = o3 + gyro.outer_gimbal * psi_d
    return np.stack([cp * o1 - sp * o2, sp * o1 + cp * o2, o3], axis=-1)


def nutation_frequency(gyro: FreeGyroscope, h: float, theta0: float = 0.5 * math.pi) -> float:
    """Exact linearized nutation frequency (rad/s) about the inner gimbal angle ``theta0``
    (rad) for the rotor's axial momentum ``h`` (N m s): ``|h sin theta0| / sqrt(A_i M(theta0))``."""
    h = _finite("h", h, "nutation_frequency", " (N m s)")
    theta0 = _finite("theta0", theta0, "nutation_frequency", " (rad)")
    _check_lock(gyro, theta0, "theta0")
    return abs(h * math.sin(theta0)) / math.sqrt(gyro.inner_axis_inertia * float(gyro.outer_inertia(theta0)))


def fast_rotor_nutation_frequency(gyro: FreeGyroscope, spin: float) -> float:
    """Baruh's fast-rotor nutation frequency ``C n / sqrt(A_i A_o)`` (rad/s; ``C n / A``
    with massless gimbals) for the rotor's axial rate ``spin`` ``n`` (rad/s)."""
    spin = _finite("spin", spin, "fast_rotor_nutation_frequency", " (rad/s)")
    return abs(gyro.rotor_axial * spin) / math.sqrt(gyro.inner_axis_inertia * gyro.outer_axis_inertia)


def free_gyro_linear(gyro: FreeGyroscope, h: float, t, theta0: float = 0.5 * math.pi, inner_rate: float = 0.0,
                     outer_rate: float = 0.0, inner_torque: float = 0.0, outer_torque: float = 0.0):
    """Closed-form linearized motion about ``(theta0, psi' = 0)`` (module docstring, section
    1): ``(psi - psi0, theta - theta0)`` (rad, arrays like ``t``) from ``theta = theta0``
    with the rates ``outer_rate`` ``v = psi'(0)``, ``inner_rate`` ``u = theta'(0)`` (rad/s)
    under the constant torques ``outer_torque`` ``Q_psi`` and ``inner_torque`` ``Q_theta``
    (N m), for the axial momentum ``h`` (N m s, ``h sin theta0 != 0``)::

        delta = a + b t - a cos(w t) + (u - b) / w sin(w t),  a = (Q_theta - g v) M0 / g^2,  b = -Q_psi / g
        psi - psi0 = v t + (g / M0) (a t + b t^2 / 2 - a sin(w t) / w + (u - b) (1 - cos(w t)) / w^2) + Q_psi t^2 / (2 M0)

    with ``g = h sin theta0``, ``M0 = M(theta0)``, ``w`` = :func:`nutation_frequency`."""
    who = "free_gyro_linear"
    h = _finite("h", h, who, " (N m s)")
    theta0 = _finite("theta0", theta0, who, " (rad)")
    u, v = _finite("inner_rate", inner_rate, who, " (rad/s)"), _finite("outer_rate", outer_rate, who, " (rad/s)")
    qt, qp = _finite("inner_torque", inner_torque, who, " (N m)"), _finite("outer_torque", outer_torque, who, " (N m)")
    t = real_array(t, "t", who)
    if not np.all(np.isfinite(t)):
        raise ValueError("t: expected finite times (s)")
    g = h * math.sin(theta0)
    if g == 0.0:
        raise ValueError("h: the linearized gyroscope needs h sin(theta0) != 0")
    M0 = float(gyro.outer_inertia(theta0))
    w = nutation_frequency(gyro, h, theta0)
    a, b = (qt - g * v) * M0 / (g * g), -qp / g
    cw, sw = np.cos(w * t), np.sin(w * t)
    delta = a + b * t - a * cw + (u - b) / w * sw
    dpsi = v * t + (g / M0) * (a * t + 0.5 * b * t * t - a * sw / w + (u - b) * (1.0 - cw) / (w * w)) \
        + 0.5 * qp * t * t / M0
    return dpsi, delta


# --------------------------------------------------------------------------- 2. single-axis gyroscope


@dataclass(frozen=True)
class SingleAxisGyro:
    """A single-degree-of-freedom gyroscope (module docstring, section 2).

    ``spin_inertia`` ``C`` and ``transverse_inertia`` ``A`` of the rotor (kg m^2),
    ``spin_rate`` ``Omega`` (rad/s, the rotor relative to the gimbal: the nominal and default
    initial spin), ``gimbal_inertia`` ``(Ig1, Ig2, Ig3)`` principal moments of the gimbal
    (float) about the input, output and spin axes (kg m^2, default massless), ``spring``
    ``k`` (N m/rad; 0 for a rate-integrating gyro), ``damping`` ``c`` (N m s/rad),
    ``free_rotor``: False holds ``Omega`` constant (speed-regulated motor), True leaves the
    rotor torque-free about its axis."""

    spin_inertia: float
    transverse_inertia: float
    spin_rate: float
    gimbal_inertia: tuple = (0.0, 0.0, 0.0)
    spring: float = 0.0
    damping: float = 0.0
    free_rotor: bool = False

    def __post_init__(self):
        who = "SingleAxisGyro"
        C, A = _rotor(self.spin_inertia, self.transverse_inertia, "spin_inertia", "transverse_inertia", who)
        object.__setattr__(self, "spin_inertia", C)
        object.__setattr__(self, "transverse_inertia", A)
        object.__setattr__(self, "spin_rate", _finite("spin_rate", self.spin_rate, who, " (rad/s)"))
        object.__setattr__(self, "gimbal_inertia", tuple(_gimbal_moments("gimbal_inertia", self.gimbal_inertia,
                                                                         who).tolist()))
        object.__setattr__(self, "spring", _nonneg("spring", self.spring, who, " (N m/rad)"))
        object.__setattr__(self, "damping", _nonneg("damping", self.damping, who, " (N m s/rad)"))
        if not isinstance(self.free_rotor, (bool, np.bool_)):
            raise ValueError(f"free_rotor: expected True or False, got {self.free_rotor!r}")
        if not math.isfinite(self.momentum * self.spin_rate):
            raise ValueError(f"spin_rate: C Omega^2 = {self.momentum * self.spin_rate!r} overflows")

    @classmethod
    def rate_gyro(cls, spin_inertia, transverse_inertia, spin_rate, spring, damping, gimbal_inertia=(0.0, 0.0, 0.0),
                  free_rotor=False) -> SingleAxisGyro:
        """A rate gyro: restraining spring ``k > 0`` (N m/rad) and damper ``c`` (N m s/rad)."""
        if not (_finite("spring", spring, "SingleAxisGyro.rate_gyro") > 0):
            raise ValueError(f"spring: a rate gyro needs k > 0 (N m/rad), got {spring!r}")
        return cls(spin_inertia, transverse_inertia, spin_rate, gimbal_inertia, spring, damping, free_rotor)

    @classmethod
    def rate_integrating(cls, spin_inertia, transverse_inertia, spin_rate, damping, gimbal_inertia=(0.0, 0.0, 0.0),
                         free_rotor=False) -> SingleAxisGyro:
        """A rate-integrating gyro: no spring, damper ``c > 0`` (N m s/rad)."""
        if not (_finite("damping", damping, "SingleAxisGyro.rate_integrating") > 0):
            raise ValueError(f"damping: a rate-integrating gyro needs c > 0 (N m s/rad), got {damping!r}")
        return cls(spin_inertia, transverse_inertia, spin_rate, gimbal_inertia, 0.0, damping, free_rotor)

    @property
    def momentum(self) -> float:
        """``H = C Omega`` (N m s), the rotor's momentum relative to the gimbal at the nominal spin."""
        return self.spin_inertia * self.spin_rate

    @property
    def output_inertia(self) -> float:
        """``J2 = Ig2 + A`` (kg m^2): gimbal + rotor about the output axis."""
        return self.gimbal_inertia[1] + self.transverse_inertia

    @property
    def input_inertia(self) -> float:
        """``J1 = Ig1 + A`` (kg m^2)."""
        return self.gimbal_inertia[0] + self.transverse_inertia

    @property
    def spin_axis_inertia(self) -> float:
        """``J3 = Ig3 + C`` (kg m^2)."""
        return self.gimbal_inertia[2] + self.spin_inertia

    @property
    def natural_frequency(self) -> float:
        """``sqrt(k / J2)`` (rad/s) of the ideal rate gyro."""
        return math.sqrt(self.spring / self.output_inertia)

    @property
    def damping_ratio(self) -> float:
        """``c / (2 sqrt(k J2))`` of the ideal rate gyro (inf without a spring)."""
        return self.damping / (2.0 * math.sqrt(self.spring * self.output_inertia)) if self.spring > 0 else math.inf

    @property
    def rate_sensitivity(self) -> float:
        """Ideal rate gyro output per input rate ``H / k`` (rad per rad/s)."""
        if self.spring <= 0:
            raise ValueError("spring: the rate sensitivity H / k needs k > 0")
        return self.momentum / self.spring

    @property
    def integrating_gain(self) -> float:
        """Ideal rate-integrating gyro output per input angle ``H / c`` (rad/rad)."""
        if self.damping <= 0:
            raise ValueError("damping: the integrating gain H / c needs c > 0")
        return self.momentum / self.damping

    @property
    def time_constant(self) -> float:
        """``J2 / c`` (s) of the rate-integrating gyro."""
        if self.damping <= 0:
            raise ValueError("damping: the time constant J2 / c needs c > 0")
        return self.output_inertia / self.damping


def constant_base_rate(w) -> Callable:
    """A base turning at the constant ``w`` (3,) (rad/s, case components): ``t -> (w, 0)``."""
    w = _vector("w", w, 3, "constant_base_rate", " (rad/s)")
    zero = np.zeros(3)

    def base(_t):
        return w, zero

    return base


def sampled_base_rate(times, rates, mount=None) -> Callable:
    """A base rate callable from samples of an attitude model's output: ``rates`` (N, 3)
    body angular velocity (rad/s, body components) at ``times`` (N,) (s, increasing, N >= 4),
    e.g. :func:`astrodyn.attitude.propagate_attitude`'s; a cubic spline gives ``w`` and
    ``w'`` (its derivative: pass the exact ``w'`` instead when the model has it).
    ``mount`` (3, 3): the direction cosine matrix ``v_case = mount @ v_body`` of the
    instrument's case in the body (rows: the input, output and spin reference axes in body
    components); identity by default."""
    from scipy.interpolate import CubicSpline

    tt = real_array(times, "times", "sampled_base_rate")
    ww = real_array(rates, "rates", "sampled_base_rate")
    if tt.ndim != 1 or tt.size < 4 or not np.all(np.isfinite(tt)) or np.any(np.diff(tt) <= 0):
        raise ValueError(f"times: expected >= 4 finite, strictly increasing times (s), got shape {tt.shape}")
    if ww.shape != (tt.size, 3) or not np.all(np.isfinite(ww)):
        raise ValueError(f"rates: expected shape ({tt.size}, 3) of finite rates (rad/s), got {ww.shape}")
    if mount is not None:
        R = real_array(mount, "mount", "sampled_base_rate")
        if R.shape != (3, 3) or not np.all(np.isfinite(R)) or not np.allclose(R @ R.T, np.eye(3), atol=1e-9) \
                or np.linalg.det(R) < 0:
            raise ValueError("mount: expected a proper orthogonal 3x3 matrix (v_case = mount @ v_body)")
        ww = ww @ R.T
    spline = CubicSpline(tt, ww, axis=0)
    deriv = spline.derivative()

    def base(t):
        return spline(t), deriv(t)

    return base


def _base_values(base, t):
    try:
        out = base(t)
        w, wd = out
        w = np.asarray(w, dtype=np.float64)
        wd = np.asarray(wd, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError("base: expected a callable t -> (w, w_dot), two arrays of 3 numbers (rad/s, rad/s^2)") \
            from None
    if w.shape != (3,) or wd.shape != (3,) or not (np.all(np.isfinite(w)) and np.all(np.isfinite(wd))):
        raise ValueError(f"base: at t = {t!r} s expected (w, w_dot) of 3 finite numbers each, got shapes "
                         f"{w.shape}, {wd.shape}")
    return w, wd


def _single_accel(C, J1, J2, J3, k, c, free, th, th_d, spin, w1, w2, w3, wd1, wd2, wd3, tau):
    s, co = math.sin(th), math.cos(th)
    wg1 = w1 * co - w3 * s
    wg3 = w1 * s + w3 * co
    th_dd = (C * spin * wg1 + (J3 - J1) * wg1 * wg3 - k * th - c * th_d + tau) / J2 - wd2
    spin_d = -(wd1 * s + wd3 * co + th_d * wg1) if free else 0.0
    return th_dd, spin_d


def _single_state(name, value, who):
    return _vector(name, value, 3, who, " (theta rad, theta_dot rad/s, spin rad/s)")


def single_axis_rates(gyro: SingleAxisGyro, t: float, state, base: Callable, torquer: Callable | None = None):
    """Time derivative (3,) of ``state = (theta, theta', Omega)`` (module docstring, section
    2) with ``base(t) -> (w, w')`` (case components, rad/s and rad/s^2) and the optional
    torquer ``torquer(t, state) -> tau`` (N m about the output axis)."""
    t = _real("t", t, "single_axis_rates")
    y = _single_state("state", state, "single_axis_rates")
    w, wd = _base_values(base, t)
    tau = _torquer_value(torquer, t, y)
    acc = _single_accel(gyro.spin_inertia, gyro.input_inertia, gyro.output_inertia, gyro.spin_axis_inertia,
                        gyro.spring, gyro.damping, gyro.free_rotor, y[0], y[1], y[2], *w, *wd, tau)
    return np.array([y[1], *acc])


def _torquer_value(torquer, t, y):
    if torquer is None:
        return 0.0
    try:
        tau = float(torquer(t, y))
    except (TypeError, ValueError):
        raise ValueError("torquer: expected a callable (t, state) -> torque (N m)") from None
    if not math.isfinite(tau):
        raise ValueError(f"torquer: returned a non-finite torque {tau!r} at t = {t!r} s")
    return tau


def propagate_single_axis(gyro: SingleAxisGyro, base: Callable, t, theta0: float = 0.0, theta_dot0: float = 0.0,
                          spin0: float | None = None, torquer: Callable | None = None, rtol: float = 1e-11,
                          atol: float = 1e-13, max_nfev: int = DEFAULT_MAX_NFEV):
    """States ``(len(t), 3)`` = ``(theta, theta', Omega)`` at the times ``t`` (s, from 0) of a
    single-axis gyroscope on a base turning as ``base(t) -> (w, w')`` (case components:
    input, output, spin reference axes; rad/s, rad/s^2), from ``theta0`` (rad),
    ``theta_dot0`` (rad/s) and the rotor spin ``spin0`` (rad/s relative to the gimbal;
    default ``gyro.spin_rate``); DOP853.  Returns ``(states, info)`` with ``nfev``."""
    if not isinstance(gyro, SingleAxisGyro):
        raise ValueError(f"gyro: expected a SingleAxisGyro, got {type(gyro).__name__}")
    if not callable(base):
        raise ValueError("base: expected a callable t -> (w, w_dot) (rad/s, rad/s^2, case components)")
    if torquer is not None and not callable(torquer):
        raise ValueError("torquer: expected a callable (t, state) -> torque (N m) or None")
    who = "propagate_single_axis"
    theta0 = _finite("theta0", theta0, who, " (rad)")
    theta_dot0 = _finite("theta_dot0", theta_dot0, who, " (rad/s)")
    spin0 = gyro.spin_rate if spin0 is None else _finite("spin0", spin0, who, " (rad/s)")
    t = check_output_times(real_array(t, "t", who))
    rtol, atol, max_nfev = _tolerances(rtol, atol, max_nfev, who)
    y0 = np.array([theta0, theta_dot0, spin0])
    _base_values(base, 0.0)
    _torquer_value(torquer, 0.0, y0)
    C, J1, J2, J3 = gyro.spin_inertia, gyro.input_inertia, gyro.output_inertia, gyro.spin_axis_inertia
    k, c, free = gyro.spring, gyro.damping, gyro.free_rotor
    budget = _Budget(max_nfev, "single-axis gyroscope")

    def rhs(time, y):
        budget.tick()
        th, th_d, spin = y.tolist()
        w, wd = _base_values(base, time)
        tau = _torquer_value(torquer, time, y)
        w1, w2, w3 = w.tolist()
        wd1, wd2, wd3 = wd.tolist()
        return [th_d, *_single_accel(C, J1, J2, J3, k, c, free, th, th_d, spin, w1, w2, w3, wd1, wd2, wd3, tau)]

    states, nfev = integrate_dop853(rhs, y0, t, rtol, atol, budget.what)
    return states, {"method": "dop853", "rtol": rtol, "atol": atol, "nfev": nfev}


def _single_states(states, who):
    s = real_array(states, "states", who)
    if s.ndim < 1 or s.shape[-1] != 3:
        raise ValueError(f"states: expected shape (..., 3) = {SINGLE_STATE_FIELDS}, got {s.shape}")
    return s


def _rates_array(name, w, shape, who):
    w = real_array(w, name, who)
    if w.shape[-1:] != (3,):
        raise ValueError(f"{name}: expected (..., 3) rates, got shape {w.shape}")
    return np.broadcast_to(w, shape + (3,)) if w.ndim == 1 else w


def error_torques(gyro: SingleAxisGyro, states, w, w_dot) -> dict:
    """The torques about the output axis (N m, arrays like ``states[..., 0]``) that the ideal
    equation ``J2 theta'' + c theta' + k theta = H w1`` drops, for the states (..., 3) and the
    base rates ``w``, ``w_dot`` (..., 3) (case components): ``"cross_coupling"`` ``C Omega
    (wg1 - w1)``, ``"output_acceleration"`` ``-J2 w2'``, ``"anisoinertia"`` ``(J3 - J1) wg1
    wg3`` and ``"spin_change"`` ``C (Omega - Omega_nominal) w1``; with them the ideal
    equation is exact: ``J2 theta'' + c theta' + k theta = H w1 + sum``."""
    s = _single_states(states, "error_torques")
    th, spin = s[..., 0], s[..., 2]
    w = _rates_array("w", w, th.shape, "error_torques")
    wd = _rates_array("w_dot", w_dot, th.shape, "error_torques")
    w1, w3 = w[..., 0], w[..., 2]
    wg1 = w1 * np.cos(th) - w3 * np.sin(th)
    wg3 = w1 * np.sin(th) + w3 * np.cos(th)
    C = gyro.spin_inertia
    return {
        "cross_coupling": C * spin * (wg1 - w1),
        "output_acceleration": -gyro.output_inertia * wd[..., 1],
        "anisoinertia": (gyro.spin_axis_inertia - gyro.input_inertia) * wg1 * wg3,
        "spin_change": C * (spin - gyro.spin_rate) * w1,
    }


def steady_state_angle(gyro: SingleAxisGyro, w) -> float:
    """The rate gyro's exact steady output angle (rad) for a constant base rate ``w`` (3,)
    (rad/s) and a regulated rotor: the root near ``H w1 / (k + H w3)`` of ``k theta = wg1 (H +
    (J3 - J1) wg3)`` (module docstring), by Newton's method from the small-angle estimate; a
    ValueError naming ``w`` when there is no stable root there (``k + H w3 <~ 0``)."""
    w1, w2, w3 = _vector("w", w, 3, "steady_state_angle", " (rad/s)").tolist()
    if gyro.spring <= 0:
        raise ValueError("spring: a steady output angle needs k > 0")
    H, k, dJ = gyro.momentum, gyro.spring, gyro.spin_axis_inertia - gyro.input_inertia
    den = k + H * w3 + dJ * (w3 * w3 - w1 * w1)
    th = (H * w1 + dJ * w1 * w3) / den if den > 0 else 0.0
    for _ in range(60):
        s, c = math.sin(th), math.cos(th)
        wg1, wg3 = w1 * c - w3 * s, w1 * s + w3 * c
        f = k * th - wg1 * (H + dJ * wg3)
        fp = k + wg3 * (H + dJ * wg3) - dJ * wg1 * wg1  # d/dtheta: the stiffness about the root
        step = f / fp if fp != 0 else math.inf
        th -= step
        if not math.isfinite(th):
            break
        if abs(step) <= 1e-15 * max(1e-300, abs(th)) or abs(step) < 1e-300:
            s, c = math.sin(th), math.cos(th)
            wg1, wg3 = w1 * c - w3 * s, w1 * s + w3 * c
            if k + wg3 * (H + dJ * wg3) - dJ * wg1 * wg1 > 0:
                return th
            break
    raise ValueError(f"w: no stable steady output angle near H w1 / (k + H w3) for w = {[w1, w2, w3]} rad/s "
                     "(a spin-axis rate with H w3 < -k destabilizes the rate gyro)")


def single_axis_energy(gyro: SingleAxisGyro, states, w) -> np.ndarray:
    """Kinetic + spring energy (J) of gimbal + rotor with the base rate ``w`` (..., 3):
    ``1/2 (J1 wg1^2 + J2 wg2^2 + Ig3 wg3^2 + C (wg3 + Omega)^2 + k theta^2)``."""
    s = _single_states(states, "single_axis_energy")
    th, th_d, spin = s[..., 0], s[..., 1], s[..., 2]
    w = _rates_array("w", w, th.shape, "single_axis_energy")
    wg1 = w[..., 0] * np.cos(th) - w[..., 2] * np.sin(th)
    wg2 = w[..., 1] + th_d
    wg3 = w[..., 0] * np.sin(th) + w[..., 2] * np.cos(th)
    C = gyro.spin_inertia
    return 0.5 * (gyro.input_inertia * wg1**2 + gyro.output_inertia * wg2**2 + gyro.gimbal_inertia[2] * wg3**2
                  + C * (wg3 + spin) ** 2 + gyro.spring * th * th)


def single_axis_jacobi_integral(gyro: SingleAxisGyro, states, w) -> np.ndarray:
    """Jacobi integral (J) for a base turning at a constant ``w`` (3,): ``theta' dT/dtheta' +
    Omega dT/dOmega - T + k theta^2 / 2``, with ``dT/dtheta' = J2 wg2`` and ``dT/dOmega = C (wg3
    + Omega)``.  Constant for a free rotor without damper or torquer (the Lagrangian in the
    case's coordinates does not depend on time); the energy alone is not."""
    s = _single_states(states, "single_axis_jacobi_integral")
    th, th_d, spin = s[..., 0], s[..., 1], s[..., 2]
    w = _rates_array("w", w, th.shape, "single_axis_jacobi_integral")
    wg2 = w[..., 1] + th_d
    wg3 = w[..., 0] * np.sin(th) + w[..., 2] * np.cos(th)
    e = single_axis_energy(gyro, s, w)
    T = e - 0.5 * gyro.spring * th * th
    return th_d * gyro.output_inertia * wg2 + spin * gyro.spin_inertia * (wg3 + spin) - T + 0.5 * gyro.spring * th * th


def single_axis_momentum(gyro: SingleAxisGyro, states, w) -> np.ndarray:
    """Angular momentum (..., 3) of gimbal + rotor about the pivot in case (B) components (N m s):
    ``C_2(theta)^T (J1 wg1, J2 wg2, J3 wg3 + C Omega)``."""
    s = _single_states(states, "single_axis_momentum")
    th, th_d, spin = s[..., 0], s[..., 1], s[..., 2]
    w = _rates_array("w", w, th.shape, "single_axis_momentum")
    st, ct = np.sin(th), np.cos(th)
    wg1 = w[..., 0] * ct - w[..., 2] * st
    wg2 = w[..., 1] + th_d
    wg3 = w[..., 0] * st + w[..., 2] * ct
    h1, h2, h3 = gyro.input_inertia * wg1, gyro.output_inertia * wg2, gyro.spin_axis_inertia * wg3 + gyro.spin_inertia * spin
    # v_B = C_2(theta)^T v_G,  C_2 = [[c, 0, -s], [0, 1, 0], [s, 0, c]]
    return np.stack([ct * h1 + st * h3, h2, -st * h1 + ct * h3], axis=-1)
