"""Numerical attitude propagation for torqued rigid bodies and gyrostats.

One entry point, :func:`propagate_attitude`, with the method stated explicitly:

``method="split2"`` / ``"split4"`` (structure preserving)
    The free rigid body ``H = sum_i (M_i - h_i)^2 / (2 I_i)`` (``M`` total body
    angular momentum, ``h`` rotor momentum, principal moments ``I_i``) is split
    into its three axis terms.  Each term's flow is an *exact rotation* of the
    body about one principal axis by the angle ``(M_i - h_i) dt / I_i``, applied
    both to ``M`` (``M <- C_i(angle) M``) and to the attitude
    (``C <- C_i(angle) C``, i.e. ``q <- q (x) (cos(angle/2), sin(angle/2) e_i)``).
    With external torques as momentum kicks ``K: M <- M + dt tau(t, q)`` at
    fixed attitude, one symmetric (Strang) step is the palindrome
    ``T1(h/2) K(h/2) T2(h/2) T3(h) T2(h/2) K(h/2) T1(h/2)`` (Dullweber,
    Leimkuhler & McLachlan, J. Chem. Phys. 107, 5840 (1997); Touma & Wisdom,
    Astron. J. 107, 1189 (1994)); time is carried by ``T1``, so both kicks see
    the step's midpoint time.  ``T1`` leaves ``M_1`` unchanged, so the ``T1``
    halves that meet across stage and step boundaries are applied as one
    rotation (first-same-as-last): 4 rotations per stage, 1 orbit position per
    stage for gravity gradient.  ``split2`` is that second-order symmetric step;
    ``split4`` is its 4th-order composition with Suzuki's five-stage fractal
    weights ``(p, p, 1 - 4p, p, p)``, ``p = 1 / (4 - 4^(1/3))`` (M. Suzuki,
    Phys. Lett. A 146, 319 (1990)); Yoshida's three-stage triple jump
    (``split4-yoshida``, Phys. Lett. A 150, 262 (1990)) is cheaper per step but
    ~9x less accurate at equal cost, and McLachlan's five-stage
    ``(0.28, 0.6255, ...)`` (SIAM J. Sci. Comput. 16, 151 (1995)) ~2x (measured
    on the benchmark cases), so Suzuki's stays the default.
    Because every sub-step is a rotation, ``|q| = 1`` holds by construction (a
    cheap renormalisation per step removes the round-off random walk) and the
    free part keeps ``|M|`` exactly up to round-off; the method is symplectic and
    time reversible for ``(t, q)``-dependent torques.  A time-varying rotor
    momentum ``h(t)`` is frozen at each stage's midpoint time, which keeps the
    step symmetric.  The error estimate comes from step doubling (Richardson):
    the run is repeated with steps ``2h`` and ``err ~ |y_h - y_2h| / (2^p - 1)``.

    The built-in torque models of :mod:`astrodyn.attitude.torques`
    (gravity gradient, uniform gravity about a fixed point, constant torques and
    their sums) run inside one compiled numba kernel that steps many steps per
    call; for :meth:`GravityGradientTorque.kepler` the kernel also evaluates the
    orbit (exact two-body nodes, quintic Hermite in between).  A step is a
    serial chain (each rotation angle needs the ``M`` the previous one left), so
    the kernel is built for a short chain: the state stays in registers; the
    rotation of ``M`` takes cos and sin of small angles (``|angle| <= 1/8`` rad)
    from Taylor polynomials in Estrin form, and ``q``'s half-angle pair the
    rational form of ``tan(angle/4)`` (unit norm for any ``tan`` value; libm
    ``tan`` above 1/8 rad), all within about 1 ulp; the first kick of a stage
    takes the body copies ``C(q) r`` (and of an inertial torque or gravity
    force) and the inner rotations turn those copies like ``M``, so the second
    kick needs no ``C(q)``.  ``astrodyn bench attitude`` (docs/bench-attitude.md):
    about 65 ns per ``split2`` step torque-free and 120 ns with gravity gradient
    on a Kepler orbit, about 110 ns per ``split4`` stage with gravity gradient.
    Any other ``torque(t, q, w)`` callable runs through the same splitting
    in a Python loop (slower, about 10-30 us per step); a torque that depends on
    ``w`` is applied by an implicit-midpoint kick (fixed-point iteration), which
    keeps the step symmetric.

``method="dop853"`` (classical baseline)
    scipy's adaptive DOP853 on the state ``(q, M)`` (Euler parameters and total
    body momentum; ``M`` rather than ``w`` so a commanded rotor momentum ``h(t)``
    needs no derivative), ``q`` normalised at output.

``method="exact"``
    The exact torque-free solution :func:`astrodyn.attitude.torque_free.torque_free`
    (no integration).  ``method="auto"`` selects it when there is no torque and
    no rotor, and ``split4`` otherwise.

Conventions (docs/architecture.md, section 2): Euler parameters ``q = (e0, e1, e2, e3)`` scalar first,
``v_body = C(q) @ v_inertial``, ``dC/dt = -[w x] C``, ``w`` body rates in rad/s,
SI units throughout (s, kg m^2, N m, N m s).  The initial state is at ``t = 0``.

Building blocks shared with :mod:`astrodyn.attitude.top` and
:mod:`astrodyn.attitude.gyrocompass` (public names, compiled unless noted):
:func:`axis_rotation_trig` and :func:`cos_sinc_minus_one` (cos and sin of a splitting angle,
Taylor below :data:`SMALL_ANGLE`), :func:`turn_body` (one exact principal-axis rotation of
``M`` and ``q``), :func:`renormalized` (``q / |q|``), and in Python :func:`step_plan` /
:func:`step_chunks` (step counts per output interval, and the steps in kernel-sized chunks).
"""

from __future__ import annotations

import math
import time as _time
from collections import namedtuple

import numpy as np

from astrodyn.attitude.euler import inertia_tensor, principal_axes
from astrodyn.attitude.torques import (
    ConstantTorque,
    GravityGradientTorque,
    TorqueSum,
    UniformGravityTorque,
)
from astrodyn.inputs import real_array, real_scalar
from astrodyn.jit import jit
from astrodyn.orbit.universal import lagrange_coefficients_scalar
from astrodyn.rotation import attitude_difference, quat_from_dcm, quat_multiply

__all__ = ["propagate_attitude", "SPLIT2_WEIGHTS", "SPLIT4_WEIGHTS", "YOSHIDA4_WEIGHTS", "free_rigid_body_step",
           "held_torque_step", "HeldInputsBody", "MAX_STEPS", "checked_max_steps", "check_step_budget"]

MAX_STEPS = 1_000_000
"""Default ``max_steps`` of :func:`propagate_attitude` (and of the heavy top's and the
gyrocompass's splitting): the most integration steps one call may take, as
``propagate_perturbed``'s default.  About 0.1-1 s in the compiled kernel (65-850 ns a
step, ``astrodyn bench attitude``), 10-30 s through a Python torque; a call that needs
more is refused before it starts (a step far too small for the span, or rates so high
that the default step -- 1/60 of the fastest natural period -- is tiny), and a caller
that means it passes a larger ``max_steps``."""

SPLIT2_WEIGHTS = np.array([1.0])
"""Stage weights of the 2nd-order Strang step (one stage)."""

_P4 = 1.0 / (4.0 - 4.0 ** (1.0 / 3.0))
SPLIT4_WEIGHTS = np.array([_P4, _P4, 1.0 - 4.0 * _P4, _P4, _P4])
"""Suzuki's 4th-order five-stage composition weights (they sum to 1)."""

_CBRT2 = 2.0 ** (1.0 / 3.0)
YOSHIDA4_WEIGHTS = np.array([1.0 / (2.0 - _CBRT2), -_CBRT2 / (2.0 - _CBRT2), 1.0 / (2.0 - _CBRT2)])
"""Yoshida's 4th-order three-stage "triple jump" (Phys. Lett. A 150, 262 (1990)), for comparison:
3/5 of Suzuki's cost per step but about 9x its error at equal cost on the bench cases
(error constant x stages^4: 0.84 vs 0.091 triaxial, 2.2 vs 0.24 near the separatrix),
i.e. Suzuki needs ~1.7x less work for a given error."""

_ORDER = {"split2": 2, "split4": 4, "split4-yoshida": 4}
_WEIGHTS = {"split2": SPLIT2_WEIGHTS, "split4": SPLIT4_WEIGHTS, "split4-yoshida": YOSHIDA4_WEIGHTS}
_CHUNK = 1 << 15  # steps per kernel call (bounds the size of per-step tables)


# ---------------------------------------------------------------------------
# compiled sub-steps (principal axes)
# ---------------------------------------------------------------------------


# Short odd/even Taylor polynomials for the small angles of a splitting step
# (Abramowitz & Stegun 4.3.65-67), with libm above the range:
#   tan y = y + y^3/3 + 2 y^5/15 + 17 y^7/315 + 62 y^9/2835 + ...   |y| <= 1/32:
#       first omitted term 1382/155925 y^11 <= 8.1e-18 |y| (0.08 ulp);
#   sin x = x - x^3/3! + ... - x^11/11!,  cos x = 1 - x^2/2! + ... - x^10/10!   |x| <= 1/8:
#       first omitted terms x^13/13! <= 1.2e-23 |x| and x^12/12! <= 3e-20.
SMALL_ANGLE = 0.125  # rad: |angle| up to which the polynomials are used (y = angle/4 <= 1/32)
_TAN3, _TAN5, _TAN7, _TAN9 = 1.0 / 3.0, 2.0 / 15.0, 17.0 / 315.0, 62.0 / 2835.0
_SIN1, _SIN2, _SIN3, _SIN4, _SIN5 = -1.0 / 6.0, 1.0 / 120.0, -1.0 / 5040.0, 1.0 / 362880.0, -1.0 / 39916800.0
_COS1, _COS2, _COS3, _COS4, _COS5 = -0.5, 1.0 / 24.0, -1.0 / 720.0, 1.0 / 40320.0, -1.0 / 3628800.0


@jit(inline="always")
def cos_sinc_minus_one(z):
    """``(cos x - 1, sin(x)/x - 1)`` from ``z = x^2`` (rad^2), for ``z <= SMALL_ANGLE^2``.

    Both are even in ``x``, so they need no square root: Taylor polynomials in
    ``z`` (A&S 4.3.65-66, terms to ``x^10`` and ``x^11``) in Estrin's form (a short
    dependency chain).  Returned as the small corrections so the caller adds the
    leading 1 (or ``x``) last, which keeps the result within about 1 ulp.
    """
    z2 = z * z
    z4 = z2 * z2
    cos_m1 = z * ((_COS1 + z * _COS2) + z2 * (_COS3 + z * _COS4) + z4 * _COS5)
    sinc_m1 = z * ((_SIN1 + z * _SIN2) + z2 * (_SIN3 + z * _SIN4) + z4 * _SIN5)
    return cos_m1, sinc_m1


@jit(inline="always")
def axis_rotation_trig(angle):
    """``(c, s, ca, sa)``: cos and sin of ``angle/2`` (for ``q``) and of ``angle`` (for ``M``), rad.

    ``c, s`` come from ``u = tan(angle/4)`` through the rational half-angle forms
    ``c = (1 - u^2)/(1 + u^2)``, ``s = 2u/(1 + u^2)``, so ``c^2 + s^2 = 1`` for any
    ``u``: the Euler parameters keep unit norm up to rounding whatever the accuracy
    of ``u``.  For ``|angle| <= 1/8`` rad, ``u`` is an odd Taylor polynomial and
    ``(ca, sa)`` the Taylor polynomials of ``cos, sin angle`` (Estrin's scheme:
    a short dependency chain, which is what the serial splitting step waits on);
    above, ``u = tan`` (libm) and ``ca = c^2 - s^2``, ``sa = 2 s c``.  Every branch
    is within about 1 ulp of the true values (tested against mpmath); NaN gives
    NaN (it fails the range test).
    """
    if abs(angle) <= SMALL_ANGLE:
        z = angle * angle
        cos_m1, sinc_m1 = cos_sinc_minus_one(z)
        sa = angle + angle * sinc_m1
        ca = 1.0 + cos_m1
        y = 0.25 * angle
        y2 = 0.0625 * z
        u = y + y * (y2 * ((_TAN3 + y2 * _TAN5) + (y2 * y2) * (_TAN7 + y2 * _TAN9)))
        u2 = u * u
        d = 1.0 / (1.0 + u2)
        return (1.0 - u2) * d, 2.0 * u * d, ca, sa
    u = math.tan(0.25 * angle)
    u2 = u * u
    d = 1.0 / (1.0 + u2)
    c = (1.0 - u2) * d
    s = 2.0 * u * d
    return c, s, (c - s) * (c + s), 2.0 * s * c


@jit(inline="always")
def _rot2(ca, sa, x, y):
    """``(x, y)`` components of a body vector after the body turns by ``angle`` about the third axis."""
    return ca * x + sa * y, ca * y - sa * x


@jit(inline="always")
def turn_body(axis, c, s, ca, sa, m0, m1, m2, e0, e1, e2, e3):
    """Exact rotation of the body by ``angle`` about principal axis ``axis`` (0, 1, 2), in scalars.

    ``M <- C_i(angle) M`` and ``q <- q (x) (c, s e_i)`` with ``(c, s, ca, sa)``
    from :func:`axis_rotation_trig`.
    """
    if axis == 0:
        m1, m2 = _rot2(ca, sa, m1, m2)
        e0, e1 = _rot2(c, -s, e0, e1)
        e2, e3 = _rot2(c, s, e2, e3)
    elif axis == 1:
        m2, m0 = _rot2(ca, sa, m2, m0)
        e0, e2 = _rot2(c, -s, e0, e2)
        e3, e1 = _rot2(c, s, e3, e1)
    else:
        m0, m1 = _rot2(ca, sa, m0, m1)
        e0, e3 = _rot2(c, -s, e0, e3)
        e1, e2 = _rot2(c, s, e1, e2)
    return m0, m1, m2, e0, e1, e2, e3


@jit(inline="always")
def _turn_vector(axis, ca, sa, v0, v1, v2):
    """Body components of an inertially fixed vector after the same rotation (like ``M``)."""
    if axis == 0:
        v1, v2 = _rot2(ca, sa, v1, v2)
    elif axis == 1:
        v2, v0 = _rot2(ca, sa, v2, v0)
    else:
        v0, v1 = _rot2(ca, sa, v0, v1)
    return v0, v1, v2


@jit(inline="always")
def _turned(axis, angle, m0, m1, m2, e0, e1, e2, e3):
    """``(M, q)`` after the exact rotation by ``angle`` (rad) about principal axis ``axis``, in scalars."""
    c, s, ca, sa = axis_rotation_trig(angle)
    return turn_body(axis, c, s, ca, sa, m0, m1, m2, e0, e1, e2, e3)


@jit(inline="always")
def renormalized(e0, e1, e2, e3):
    """One Newton step towards ``|q| = 1`` (removes round-off drift only: ``|q|^2 - 1 ~ 1e-16``)."""
    f = 1.5 - 0.5 * (e0 * e0 + e1 * e1 + e2 * e2 + e3 * e3)
    return e0 * f, e1 * f, e2 * f, e3 * f


@jit
def _rotate_about_axis(M, q, axis, angle):
    """In place: ``M <- C_i(angle) M`` and ``q <- q (x) (cos(angle/2), sin(angle/2) e_i)``.

    This is the exact flow of ``H_i = (M_i - h_i)^2 / (2 I_i)`` with
    ``angle = (M_i - h_i) dt / I_i`` (rotation of the body about principal axis i).
    """
    M[0], M[1], M[2], q[0], q[1], q[2], q[3] = _turned(axis, angle, M[0], M[1], M[2], q[0], q[1], q[2], q[3])


@jit
def _free_strang(M, q, inertia, h_rot, dt):
    """Symmetric splitting ``T1(dt/2) T2(dt/2) T3(dt) T2(dt/2) T1(dt/2)`` of the free gyrostat."""
    hd = 0.5 * dt
    _rotate_about_axis(M, q, 0, (M[0] - h_rot[0]) / inertia[0] * hd)
    _rotate_about_axis(M, q, 1, (M[1] - h_rot[1]) / inertia[1] * hd)
    _rotate_about_axis(M, q, 2, (M[2] - h_rot[2]) / inertia[2] * dt)
    _rotate_about_axis(M, q, 1, (M[1] - h_rot[1]) / inertia[1] * hd)
    _rotate_about_axis(M, q, 0, (M[0] - h_rot[0]) / inertia[0] * hd)


@jit
def _inner_rotations(M, q, inertia, h_rot, a):
    """``T2(a/2) T3(a) T2(a/2)``: the inner part of a stage (Python path)."""
    _rotate_about_axis(M, q, 1, (M[1] - h_rot[1]) / inertia[1] * (0.5 * a))
    _rotate_about_axis(M, q, 2, (M[2] - h_rot[2]) / inertia[2] * a)
    _rotate_about_axis(M, q, 1, (M[1] - h_rot[1]) / inertia[1] * (0.5 * a))


@jit
def _renormalize(q):
    """In place: one Newton step towards |q| = 1 (:func:`renormalized`)."""
    q[0], q[1], q[2], q[3] = renormalized(q[0], q[1], q[2], q[3])


KICK_CONSTANT, KICK_FORCE, KICK_GRAVITY_GRADIENT = 1, 2, 4


@jit(inline="always")
def _dcm_apply(e0, e1, e2, e3, v0, v1, v2):
    """``C(q) v`` for an inertial ``v = (v0, v1, v2)``: its body components (``C`` of Baruh eq. 7.x, scalar first)."""
    c00 = e0 * e0 + e1 * e1 - e2 * e2 - e3 * e3
    c11 = e0 * e0 - e1 * e1 + e2 * e2 - e3 * e3
    c22 = e0 * e0 - e1 * e1 - e2 * e2 + e3 * e3
    c01 = 2.0 * (e1 * e2 + e0 * e3)
    c10 = 2.0 * (e1 * e2 - e0 * e3)
    c02 = 2.0 * (e1 * e3 - e0 * e2)
    c20 = 2.0 * (e1 * e3 + e0 * e2)
    c12 = 2.0 * (e2 * e3 + e0 * e1)
    c21 = 2.0 * (e2 * e3 - e0 * e1)
    return (
        c00 * v0 + c01 * v1 + c02 * v2,
        c10 * v0 + c11 * v1 + c12 * v2,
        c20 * v0 + c21 * v1 + c22 * v2,
    )


@jit(inline="always")
def _gg_factor(mu3, x, y, z):
    """``3 mu / |r|^5`` (m^-2 s^-2) of the gravity-gradient torque, from the inertial position ``r = (x, y, z)`` (m)."""
    rr = x * x + y * y + z * z
    return mu3 / (rr * rr * math.sqrt(rr))


#: The kick's fixed parameters (:func:`_kick_constants`), each vector a tuple of scalars so the
#: kernel's loop holds them in registers: ``tau_body`` (3) N m, ``com`` (3) m, ``inertia`` the
#: gravity-gradient tensor ``J`` (3 rows of 3) kg m^2.
KickConstants = namedtuple("KickConstants", ["tau_body", "com", "inertia"])

#: Body components ``C(q) v`` of the inertial vectors the kick needs (:func:`_body_copies`), 3-tuples:
#: ``r`` orbit position (m), ``u`` inertial torque (N m), ``f`` uniform gravity force (N).
BodyVectors = namedtuple("BodyVectors", ["r", "u", "f"])

_ZERO3 = (0.0, 0.0, 0.0)


@jit(inline="always")
def _kick_constants(tau_body, com, gg_inertia):
    """:data:`KickConstants` from ``tau_body`` (3,) N m, ``com`` (3,) m, ``gg_inertia`` (3, 3) kg m^2."""
    J = gg_inertia
    return KickConstants(
        (tau_body[0], tau_body[1], tau_body[2]),
        (com[0], com[1], com[2]),
        ((J[0, 0], J[0, 1], J[0, 2]), (J[1, 0], J[1, 1], J[1, 2]), (J[2, 0], J[2, 1], J[2, 2])),
    )


@jit(inline="always")
def _kicked(dt, m0, m1, m2, parts, kc, kg, v):
    """``M + dt tau`` with the body torque of the kernel's models, from body copies of inertial vectors.

    ``tau = tau_body + u`` (constant torques, ``u`` the inertial one in body axes),
    ``+ r_c x f`` (uniform gravity ``f`` at the centre of mass ``r_c``), ``+ kg
    r_b x (J r_b)`` (gravity gradient, ``kg = 3 mu / |r|^5``; Hughes ch. 8);
    ``kc``: :data:`KickConstants`, ``v``: :data:`BodyVectors`.  ``parts`` selects the terms present.
    """
    t0 = t1 = t2 = 0.0
    if parts & KICK_CONSTANT:
        tb, u = kc.tau_body, v.u
        t0 = tb[0] + u[0]
        t1 = tb[1] + u[1]
        t2 = tb[2] + u[2]
    if parts & KICK_FORCE:
        c, f = kc.com, v.f
        t0 += c[1] * f[2] - c[2] * f[1]
        t1 += c[2] * f[0] - c[0] * f[2]
        t2 += c[0] * f[1] - c[1] * f[0]
    if parts & KICK_GRAVITY_GRADIENT:
        J0, J1, J2 = kc.inertia
        b0, b1, b2 = v.r
        g0 = J0[0] * b0 + J0[1] * b1 + J0[2] * b2
        g1 = J1[0] * b0 + J1[1] * b1 + J1[2] * b2
        g2 = J2[0] * b0 + J2[1] * b1 + J2[2] * b2
        t0 += kg * (b1 * g2 - b2 * g1)
        t1 += kg * (b2 * g0 - b0 * g2)
        t2 += kg * (b0 * g1 - b1 * g0)
    return m0 + dt * t0, m1 + dt * t1, m2 + dt * t2


@jit(inline="always")
def _body_copies(e0, e1, e2, e3, parts, x, y, z, tau_inertial, force):
    """:data:`BodyVectors` ``C(q) v`` of the orbit position ``r = (x, y, z)``, the inertial torque
    and the gravity force (zeros for absent terms)."""
    r = u = f = _ZERO3
    if parts & KICK_GRAVITY_GRADIENT:
        r = _dcm_apply(e0, e1, e2, e3, x, y, z)
    if parts & KICK_CONSTANT:
        u = _dcm_apply(e0, e1, e2, e3, tau_inertial[0], tau_inertial[1], tau_inertial[2])
    if parts & KICK_FORCE:
        f = _dcm_apply(e0, e1, e2, e3, force[0], force[1], force[2])
    return BodyVectors(r, u, f)


@jit
def _kick(M, q, dt, parts, tau_body, tau_inertial, com, force, gg_mu, gg_inertia, r):
    """``M <- M + dt * tau(q)``: constant body + inertial torques, uniform gravity, gravity gradient.

    ``parts`` bitmask of the terms present (``KICK_CONSTANT | KICK_FORCE |
    KICK_GRAVITY_GRADIENT``): absent terms cost nothing.  ``r`` inertial orbit
    position (m), ``gg_mu`` m^3/s^2, ``gg_inertia`` (3, 3) kg m^2.
    """
    kg = _gg_factor(3.0 * gg_mu, r[0], r[1], r[2]) if parts & KICK_GRAVITY_GRADIENT else 0.0
    v = _body_copies(q[0], q[1], q[2], q[3], parts, r[0], r[1], r[2], tau_inertial, force)
    M[0], M[1], M[2] = _kicked(dt, M[0], M[1], M[2], parts, _kick_constants(tau_body, com, gg_inertia), kg, v)


@jit
def _orbit_node(orbit_rv, mu, t, node):
    """``node[:] = (r, v, a)`` of the two-body orbit at time ``t`` (s): exact
    Lagrange coefficients (:func:`astrodyn.orbit.universal.lagrange_coefficients_scalar`),
    ``a = -mu r / |r|^3``."""
    # the r row, the v row, then t and mu, as orbit_rv holds them: fmt: skip
    f, g, fd, gd = lagrange_coefficients_scalar(
        orbit_rv[0, 0], orbit_rv[0, 1], orbit_rv[0, 2], orbit_rv[1, 0], orbit_rv[1, 1], orbit_rv[1, 2],
        t + orbit_rv[2, 0], mu,
    )  # fmt: skip
    for j in range(3):
        node[j] = f * orbit_rv[0, j] + g * orbit_rv[1, j]
        node[3 + j] = fd * orbit_rv[0, j] + gd * orbit_rv[1, j]
    rr = node[0] * node[0] + node[1] * node[1] + node[2] * node[2]
    k = -mu / (rr * math.sqrt(rr))
    for j in range(3):
        node[6 + j] = k * node[j]


@jit
def _hermite_power_coefficients(nodes):
    """Rows ``3 + p`` of ``nodes`` = coefficients of ``x^p`` (p = 0..5) of the quintic Hermite
    interpolant between the node states in rows 0 and 1, ``x = (t - k D) / D`` in [0, 1].

    With ``P, V = D v, A = D^2 a`` at the two ends (Hermite basis
    ``1 - 10x^3 + 15x^4 - 6x^5``, ``x - 6x^3 + 8x^4 - 3x^5``, ``x^2/2 - 3x^3/2 + 3x^4/2 - x^5/2``
    and their mirror images): ``c0 = P0``, ``c1 = V0``, ``c2 = A0/2`` and
    ``c3, c4, c5`` from ``dP = P1 - P0`` (formed once, so the higher coefficients
    carry no cancellation of the large ``|r|``).
    """
    D = nodes[2, 0]
    D2 = D * D
    for j in range(3):
        dP = nodes[1, j] - nodes[0, j]
        V0 = D * nodes[0, 3 + j]
        V1 = D * nodes[1, 3 + j]
        A0 = D2 * nodes[0, 6 + j]
        A1 = D2 * nodes[1, 6 + j]
        nodes[3, j] = nodes[0, j]
        nodes[4, j] = V0
        nodes[5, j] = 0.5 * A0
        nodes[6, j] = 10.0 * dP - 6.0 * V0 - 4.0 * V1 - 1.5 * A0 + 0.5 * A1
        nodes[7, j] = -15.0 * dP + 8.0 * V0 + 7.0 * V1 + 1.5 * A0 - A1
        nodes[8, j] = 6.0 * dP - 3.0 * V0 - 3.0 * V1 - 0.5 * A0 + 0.5 * A1


@jit
def _orbit_nodes_update(orbit_rv, mu, k, nodes):
    """Move the node pair of the interpolation cache ``nodes`` to ``(k D, (k + 1) D)`` (reusing
    a node when ``k`` moves by one) and refresh the power-basis coefficients."""
    D = nodes[2, 0]
    if k == nodes[2, 1] + 1.0:
        nodes[0, :] = nodes[1, :]
    elif k == nodes[2, 1] - 1.0:
        nodes[1, :] = nodes[0, :]
        _orbit_node(orbit_rv, mu, k * D, nodes[0])
    else:
        _orbit_node(orbit_rv, mu, k * D, nodes[0])
    if not k == nodes[2, 1] - 1.0:
        _orbit_node(orbit_rv, mu, (k + 1.0) * D, nodes[1])
    nodes[2, 1] = k
    _hermite_power_coefficients(nodes)


@jit(inline="always")
def _orbit_position(orbit_rv, mu, t, nodes):
    """The two-body orbit position ``(x, y, z)`` (m) at time ``t`` (s).

    ``nodes`` (9, 9) is the interpolation cache.  ``nodes[2, 0] == 0``: exact
    Kepler evaluation at ``t``.  Otherwise quintic Hermite interpolation in
    ``(r, v, a)`` between grid nodes ``k D`` and ``(k + 1) D`` (``D = nodes[2, 0]``
    s, ``k = nodes[2, 1]`` the cached node pair, ``nodes[2, 2] = 1/D``), each node
    exact (rows 0, 1), evaluated by Horner's rule from its power-basis
    coefficients (rows 3-8, :func:`_hermite_power_coefficients`).  The error
    bound ``|r^(6)| D^6 / 46080`` with ``D = 0.005 / w_max`` (``w_max`` the fastest
    angular rate on the orbit, ``|r^(6)| ~ w_max^6 |r|``) is ``3e-19 |r|``: below round-off.
    Inlined into the kernel; only a node move calls out (so the kernel's state
    stays in registers between moves).
    """
    if nodes[2, 0] == 0.0:  # no cache: node 0 is scratch space
        _orbit_node(orbit_rv, mu, t, nodes[0])
        return nodes[0, 0], nodes[0, 1], nodes[0, 2]
    u = t * nodes[2, 2]  # t / D
    k = math.floor(u)
    if not k == nodes[2, 1]:
        _orbit_nodes_update(orbit_rv, mu, k, nodes)
    x = u - k
    return (
        nodes[3, 0] + x * (nodes[4, 0] + x * (nodes[5, 0] + x * (nodes[6, 0] + x * (nodes[7, 0] + x * nodes[8, 0])))),
        nodes[3, 1] + x * (nodes[4, 1] + x * (nodes[5, 1] + x * (nodes[6, 1] + x * (nodes[7, 1] + x * nodes[8, 1])))),
        nodes[3, 2] + x * (nodes[4, 2] + x * (nodes[5, 2] + x * (nodes[6, 2] + x * (nodes[7, 2] + x * nodes[8, 2])))),
    )


@jit
def _stage_midpoints(weights):
    """Fraction of the step at each stage's midpoint: ``sum_{j<s} w_j + w_s / 2``."""
    mids = np.empty(weights.shape[0])
    acc = 0.0
    for s in range(weights.shape[0]):
        mids[s] = acc + 0.5 * weights[s]
        acc += weights[s]
    return mids


@jit(inline="always")
def _turn_carry(axis, angle, parts, m0, m1, m2, e0, e1, e2, e3, v):
    """:func:`_turned` by ``angle`` about ``axis``, also turning the kick's :data:`BodyVectors` ``v``
    (a body copy of a fixed inertial vector obeys ``v <- C_i(angle) v`` like ``M``)."""
    c, s, ca, sa = axis_rotation_trig(angle)
    m0, m1, m2, e0, e1, e2, e3 = turn_body(axis, c, s, ca, sa, m0, m1, m2, e0, e1, e2, e3)
    r, u, f = v
    if parts & KICK_GRAVITY_GRADIENT:
        r = _turn_vector(axis, ca, sa, r[0], r[1], r[2])
    if parts & KICK_CONSTANT:
        u = _turn_vector(axis, ca, sa, u[0], u[1], u[2])
    if parts & KICK_FORCE:
        f = _turn_vector(axis, ca, sa, f[0], f[1], f[2])
    return m0, m1, m2, e0, e1, e2, e3, BodyVectors(r, u, f)


@jit
# parameters one group a line: state and outputs, torques, orbit, rotor (fmt: skip)
def _split_kernel(
    M, q, inertia, weights, step_t, step_dt, record, out_M, out_q,
    parts, tau_body, tau_inertial, com, force, gg_mu, gg_inertia,
    orbit_mode, r_kick, orbit_rv, orbit_nodes, rotor_mode, h_table,
):  # fmt: skip
    """Advance ``(M, q)`` in place over ``len(step_dt)`` composed splitting steps.

    Each stage (weight ``g``, ``a = g dt``) is the palindrome
    ``T1(a/2) K(a/2) T2(a/2) T3(a) T2(a/2) K(a/2) T1(a/2)`` with the kicks at the
    stage's midpoint time (time advances with ``T1``).  ``T1`` does not change
    ``M_1``, so the ``T1`` halves that meet across stage and step boundaries are
    one rotation by the summed angle (FSAL): ``4 ns`` rotations per step
    instead of ``5 ns``; the pending ``T1`` is applied before an output is stored
    and at the end of the call.  Torques depend on ``(t, q)`` only.

    The state lives in scalars between outputs.  The first kick of a stage forms
    the body components of the inertial vectors it needs (orbit position
    ``r_b = C(q) r``, inertial torque, gravity force) once; ``T2 T3 T2`` turns
    those copies exactly as it turns ``M``, so the second kick needs no ``C(q)``
    and is the same kick as with ``C(q') r`` in exact arithmetic.  ``3 mu / |r|^5``
    comes from the inertial ``r``, once per stage.

    ``orbit_mode`` (read with gravity gradient only) 1: two-body orbit through
    ``orbit_rv = (r0, v0)`` at ``t = -orbit_rv[2, 0]`` evaluated here
    (:func:`_orbit_position`, node cache ``orbit_nodes``); 2: positions given
    per stage midpoint ``r_kick[k, s]``; 0: no orbit (no gravity gradient).
    ``rotor_mode`` 0 none, 1 constant ``h_table[0, 0]``, 2 per stage midpoint
    ``h_table[k, s]``.  After step ``k`` the state is stored in
    ``out_*[record[k]]`` when ``record[k] >= 0``.
    """
    ns = weights.shape[0]
    mids = _stage_midpoints(weights)
    h0 = h1 = h2 = 0.0
    if rotor_mode == 1:
        h0, h1, h2 = h_table[0, 0, 0], h_table[0, 0, 1], h_table[0, 0, 2]
    m0, m1, m2 = M[0], M[1], M[2]
    e0, e1, e2, e3 = q[0], q[1], q[2], q[3]
    i0 = 1.0 / inertia[0]
    i1 = 1.0 / inertia[1]
    i2 = 1.0 / inertia[2]
    mu3 = 3.0 * gg_mu
    kc = _kick_constants(tau_body, com, gg_inertia)
    x = y = z = kg = 0.0
    v = BodyVectors(_ZERO3, _ZERO3, _ZERO3)
    pend = 0.0  # angle of the pending T1 rotation (rad)
    for k in range(step_dt.shape[0]):
        dt = step_dt[k]
        for st in range(ns):
            a = weights[st] * dt
            ha = 0.5 * a
            if rotor_mode == 2:
                h0, h1, h2 = h_table[k, st, 0], h_table[k, st, 1], h_table[k, st, 2]
            # rotation angle per unit momentum and the rotor's share, off the serial chain:
            # angle_i = (M_i - h_i) dt_i / I_i = M_i g_i - p_i
            g0, g1, g2 = i0 * ha, i1 * ha, i2 * a
            p0, p1, p2 = h0 * g0, h1 * g1, h2 * g2
            m0, m1, m2, e0, e1, e2, e3 = _turned(0, pend + (m0 * g0 - p0), m0, m1, m2, e0, e1, e2, e3)
            if parts != 0:
                if parts & KICK_GRAVITY_GRADIENT:
                    if orbit_mode == 1:
                        x, y, z = _orbit_position(orbit_rv, gg_mu, step_t[k] + mids[st] * dt, orbit_nodes)
                    else:
                        x, y, z = r_kick[k, st, 0], r_kick[k, st, 1], r_kick[k, st, 2]
                    kg = _gg_factor(mu3, x, y, z)
                v = _body_copies(e0, e1, e2, e3, parts, x, y, z, tau_inertial, force)
                m0, m1, m2 = _kicked(ha, m0, m1, m2, parts, kc, kg, v)
            m0, m1, m2, e0, e1, e2, e3, v = _turn_carry(1, m1 * g1 - p1, parts, m0, m1, m2, e0, e1, e2, e3, v)
            m0, m1, m2, e0, e1, e2, e3, v = _turn_carry(2, m2 * g2 - p2, parts, m0, m1, m2, e0, e1, e2, e3, v)
            m0, m1, m2, e0, e1, e2, e3, v = _turn_carry(1, m1 * g1 - p1, parts, m0, m1, m2, e0, e1, e2, e3, v)
            if parts != 0:
                m0, m1, m2 = _kicked(ha, m0, m1, m2, parts, kc, kg, v)
            pend = m0 * g0 - p0
        e0, e1, e2, e3 = renormalized(e0, e1, e2, e3)
        j = record[k]
        if j >= 0:
            m0, m1, m2, e0, e1, e2, e3 = _turned(0, pend, m0, m1, m2, e0, e1, e2, e3)
            pend = 0.0
            out_M[j, 0], out_M[j, 1], out_M[j, 2] = m0, m1, m2
            out_q[j, 0], out_q[j, 1], out_q[j, 2], out_q[j, 3] = e0, e1, e2, e3
    if pend != 0.0:
        m0, m1, m2, e0, e1, e2, e3 = _turned(0, pend, m0, m1, m2, e0, e1, e2, e3)
    M[0], M[1], M[2] = m0, m1, m2
    q[0], q[1], q[2], q[3] = e0, e1, e2, e3


@jit
def held_torque_step(M, q, moments, weights, dt, n_sub, tau, h0, hdot):
    """One step of ``dt`` s of a gyrostat under held inputs, in place, compiled: ``n_sub``
    equal steps of the composed splitting of :func:`propagate_attitude` (``weights``, e.g.
    :data:`SPLIT4_WEIGHTS`) with a constant body torque ``tau`` (3,) N m and rotor momentum
    ``h(t) = h0 + hdot t`` (3,) N m s relative to the body (``t`` from the step's start).

    Everything in the principal axes of ``moments`` (3,) kg m^2: ``M`` (3,) total angular
    momentum N m s, ``q`` (4,) Euler parameters of those axes.  The same kernel, stages and
    stage-midpoint rotor values as ``propagate_attitude(method="split4", torque=
    ConstantTorque(tau), rotor_momentum=h)`` over one output interval, without its Python
    set-up (about 1.5 us per substep instead of 160 us per call): the closed loop's per-body step.
    """
    ns = weights.shape[0]
    mids = _stage_midpoints(weights)
    h = dt / n_sub
    step_t = np.empty(n_sub)
    step_dt = np.full(n_sub, h)
    record = np.full(n_sub, -1, dtype=np.int64)
    h_table = np.empty((n_sub, ns, 3))
    for k in range(n_sub):
        step_t[k] = k * h
        for st in range(ns):
            tm = step_t[k] + mids[st] * h
            for i in range(3):
                h_table[k, st, i] = h0[i] + hdot[i] * tm
    parts = KICK_CONSTANT if (tau[0] != 0.0 or tau[1] != 0.0 or tau[2] != 0.0) else 0
    zero3 = np.zeros(3)
    out_M = np.empty((1, 3))
    out_q = np.empty((1, 4))
    # the groups of _split_kernel's parameters, one a line (fmt: skip)
    _split_kernel(
        M, q, moments, weights, step_t, step_dt, record, out_M, out_q,
        parts, tau, zero3, zero3, zero3,
        0.0, np.zeros((3, 3)), 0, np.zeros((1, 1, 3)), np.zeros((3, 3)), np.zeros((9, 9)), 2, h_table,
    )  # fmt: skip


class HeldInputsBody:
    """A rigid body (or gyrostat) stepped under held inputs with :func:`held_torque_step`,
    in body axes outside: ``inertia`` (3,) or (3, 3) kg m^2 (for a gyrostat the ``I`` of
    ``H = I w + h``).  The principal frame is set up once (``step_held`` is the per-step call).
    """

    def __init__(self, inertia):
        self.frame = _Frame(inertia)
        self.frame.moments = np.ascontiguousarray(self.frame.moments, dtype=np.float64)
        self._min_moment = float(np.min(self.frame.moments))
        self._zero = np.zeros(3)

    def step_held(self, w, q, dt, tau=None, h0=None, hdot=None, step=None, max_steps=MAX_STEPS):
        """``(w, q)`` after ``dt`` s from body rates ``w`` (3,) rad/s and ``q`` (4,) (scalar
        first) with the body torque ``tau`` (3,) N m and the rotor momentum
        ``h0 + hdot t`` (3,) N m s held (body axes; None: zero).  ``step``: the splitting
        step (default as :func:`propagate_attitude`'s: 1/60 of the fastest natural period).

        ``dt`` and ``step``: finite and > 0 (``ValueError`` naming them).  ``max_steps``: the
        most splitting steps the call may take (as :func:`propagate_attitude`'s): a ``dt``
        that needs more (a ``step`` far too small for it, or rates so high that the default
        step is tiny) is refused before the kernel runs, with a ``ValueError`` naming the step
        and the number of steps it would need."""
        dt = real_scalar(dt, "dt", "step_held")
        if not (dt > 0.0 and math.isfinite(dt)):
            raise ValueError(f"dt: expected a finite step > 0 s, got {dt!r}")
        max_steps = checked_max_steps(max_steps)
        note = ""
        if step is not None:
            step = real_scalar(step, "step", "step_held")
            if not (step > 0.0 and math.isfinite(step)):
                raise ValueError(f"step: expected a finite splitting step > 0 s, got {step!r}")
        f = self.frame
        z = self._zero
        h0p = z if h0 is None else f.vec_to_p(np.asarray(h0, dtype=np.float64))
        hdp = z if hdot is None else f.vec_to_p(np.asarray(hdot, dtype=np.float64))
        taup = z if tau is None else f.vec_to_p(np.asarray(tau, dtype=np.float64))
        wp = f.vec_to_p(np.asarray(w, dtype=np.float64))
        M = f.moments * wp + h0p
        qp = np.array(q if f.identity else f.quat_to_p(np.asarray(q, dtype=np.float64)), dtype=np.float64)
        if step is None:  # as propagate_attitude's default: 1/60 of the fastest natural period
            w0, w1_, w2 = wp
            d0, d1, d2 = M - h0p
            rate = max(abs(w0), abs(w1_), abs(w2), math.sqrt(d0 * d0 + d1 * d1 + d2 * d2) / self._min_moment)
            step = 0.1 if not rate > 0 else 2.0 * math.pi / (60.0 * rate)
            note = " (the default: 1/60 of the fastest natural period)"
        ratio = dt / step if step > 0.0 else math.inf
        if not ratio <= max_steps:  # ceil(ratio) <= max_steps exactly when ratio <= max_steps
            need = float(math.ceil(ratio)) if math.isfinite(ratio) else math.inf
            raise ValueError(
                f"step: {step:.6g} s{note} over dt = {dt:.6g} s needs {need:.6g} steps, more than "
                f"max_steps={max_steps}; pass a larger step, or max_steps={int(min(need, 2.0**63 - 1))} to run it anyway"
            )
        n = max(1, int(math.ceil(ratio)))
        held_torque_step(M, qp, f.moments, SPLIT4_WEIGHTS, dt, n, np.ascontiguousarray(taup, dtype=np.float64),
                         np.ascontiguousarray(h0p, dtype=np.float64), np.ascontiguousarray(hdp, dtype=np.float64))
        w1 = f.vec_from_p((M - (h0p + hdp * dt)) / f.moments)
        return w1, (qp if f.identity else np.asarray(f.quat_from_p(qp)))


def free_rigid_body_step(inertia, M, q, dt, rotor_momentum=(0.0, 0.0, 0.0)):
    """One symmetric splitting step of the free body (or gyrostat) in principal axes.

    ``inertia`` principal moments ``(3,)`` kg m^2, ``M`` total body angular
    momentum ``(3,)`` N m s, ``q`` Euler parameters ``(4,)``, ``dt`` s.  Returns new
    ``(M, q)`` (inputs untouched).  Second order, exact rotations only.
    """
    M = np.array(M, dtype=np.float64)
    q = np.array(q, dtype=np.float64)
    _free_strang(M, q, np.asarray(inertia, dtype=np.float64), np.asarray(rotor_momentum, dtype=np.float64), float(dt))
    return M, q


# ---------------------------------------------------------------------------
# set-up: frames, torques, rotors, step tables
# ---------------------------------------------------------------------------


class _Frame:
    """Body axes <-> principal axes of the kinetic inertia (``v_p = P.T v_b``)."""

    def __init__(self, inertia):
        self.J = inertia_tensor(inertia)
        self.moments, self.P = principal_axes(self.J)
        self.identity = bool(np.array_equal(self.P, np.eye(3)))
        # C(r) = P^T (quat_from_dcm of the identity is exactly (1, 0, 0, 0))
        self.r = np.array([1.0, 0.0, 0.0, 0.0]) if self.identity else quat_from_dcm(self.P.T)
        self.r_inv = self.r * np.array([1.0, -1.0, -1.0, -1.0])

    def vec_to_p(self, v):
        return v if self.identity else v @ self.P

    def vec_from_p(self, v):
        return v if self.identity else v @ self.P.T

    def quat_to_p(self, q):
        return q if self.identity else quat_multiply(self.r, q)

    def quat_from_p(self, q):
        return q if self.identity else quat_multiply(self.r_inv, q)


def _flatten_torque(torque):
    if isinstance(torque, TorqueSum):
        out = []
        for m in torque.models:
            out += _flatten_torque(m)
        return out
    return [torque]


def _kernel_torque(torque, frame):
    """Kernel parameters for built-in (t, q)-only torque models, or None for the Python path."""
    tau_b = np.zeros(3)
    tau_i = np.zeros(3)
    com = np.zeros(3)
    force = np.zeros(3)
    gg = None
    if torque is None:
        return dict(has=False, parts=0, tau_b=tau_b, tau_i=tau_i, com=com, force=force, gg=None)
    for m in _flatten_torque(torque):
        if type(m) is ConstantTorque:
            if m.frame == "body":
                tau_b = tau_b + frame.vec_to_p(m.torque)
            else:
                tau_i = tau_i + m.torque
        elif type(m) is UniformGravityTorque:
            if np.any(force != 0):
                return None
            com = frame.vec_to_p(m.center_of_mass)
            force = m.mass * m.gravity
        elif type(m) is GravityGradientTorque:
            if gg is not None:
                return None
            gg = m
        else:
            return None
    parts = (KICK_CONSTANT if np.any(tau_b != 0) or np.any(tau_i != 0) else 0) | (KICK_FORCE if np.any(force != 0) else 0)
    parts |= KICK_GRAVITY_GRADIENT if gg is not None else 0
    return dict(has=True, parts=parts, tau_b=tau_b, tau_i=tau_i, com=com, force=force, gg=gg)


def _rotor_function(rotor_momentum, frame):
    """``(mode, h_p(t))``: mode 0 none, 1 constant, 2 time-varying; h in principal axes."""
    if rotor_momentum is None:
        return 0, None, np.zeros(3)
    if callable(rotor_momentum):

        def h_p(t):
            h = np.asarray(rotor_momentum(np.asarray(t, dtype=np.float64)), dtype=np.float64)
            if h.shape[-1:] != (3,):
                raise ValueError(f"rotor_momentum: callable must return shape (..., 3) N m s, got {h.shape}")
            return frame.vec_to_p(h)

        return 2, h_p, None
    h = real_array(rotor_momentum, "rotor_momentum", "propagate_attitude")
    if h.shape != (3,):
        raise ValueError(f"rotor_momentum: expected a (3,) body vector in N m s or a callable h(t), got shape {h.shape}")
    hp = frame.vec_to_p(h)
    return 1, (lambda t: np.broadcast_to(hp, np.shape(t) + (3,))), hp


def step_plan(t_out, step, even):
    """Per-interval step counts and sizes: interval k from t_{k-1} (t_{-1}=0) to t_k."""
    starts = np.concatenate([[0.0], t_out[:-1]])
    span = t_out - starts
    n = np.ceil(np.abs(span) / step).astype(np.int64)
    if even:
        n = n + (n % 2)
    dt = np.where(n > 0, span / np.maximum(n, 1), 0.0)
    return starts, n, dt


def checked_max_steps(max_steps):
    """``max_steps`` as a Python int >= 1 (``ValueError`` naming it otherwise; bools refused)."""
    if isinstance(max_steps, (bool, np.bool_)) or not isinstance(max_steps, (int, np.integer)) or max_steps < 1:
        raise ValueError(f"max_steps: expected an int >= 1 (a cap on integration steps), got {max_steps!r}")
    return int(max_steps)


def check_step_budget(t_out, step, even, max_steps, step_note=""):
    """Refuse, before any work, a :func:`step_plan` of more than ``max_steps`` steps in total.

    The count is the one the run would take (``sum ceil(|span_k| / step)``, made even per
    interval when ``even``), computed in floating point so that no span/step ratio can
    overflow.  The ``ValueError`` names the step, the span, the steps needed and
    ``max_steps``, and says how to raise it; ``step_note`` says where the step came from.
    ``t_out`` is monotone away from 0 (as the callers check), so a cheap bound settles
    most calls.
    """
    if len(t_out) == 0:
        return
    # t_out is monotone away from 0, so the count is at most |t_end| / step + 2 per interval
    if abs(float(t_out[-1])) / step + 2.0 * len(t_out) <= max_steps:
        return
    starts = np.concatenate([[0.0], t_out[:-1]])
    with np.errstate(over="ignore"):
        n = np.ceil(np.abs(t_out - starts) / step)
    if even:
        n = n + n % 2.0
    need = float(np.sum(n))
    if not need <= max_steps:
        raise ValueError(
            f"step: {step:.6g} s{step_note} over the {abs(float(t_out[-1])):.6g} s span of t needs {need:.6g} steps, "
            f"more than max_steps={max_steps}; pass a larger step, or max_steps={int(min(need, 2.0**63 - 1))} "
            "to run it anyway"
        )


def step_chunks(starts, n, dt, chunk=_CHUNK):
    """Yield ``(step_t, step_dt, record)`` arrays of at most ``chunk`` steps."""
    bt, bd, br, size = [], [], [], 0
    for k in range(len(n)):
        nk = int(n[k])
        j0 = 0
        while j0 < nk:
            m = min(nk - j0, chunk - size)
            idx = np.arange(j0, j0 + m, dtype=np.float64)
            bt.append(starts[k] + dt[k] * idx)
            bd.append(np.full(m, dt[k]))
            rec = np.full(m, -1, dtype=np.int64)
            if j0 + m == nk:
                rec[-1] = k
            br.append(rec)
            size += m
            j0 += m
            if size == chunk:
                yield np.concatenate(bt), np.concatenate(bd), np.concatenate(br)
                bt, bd, br, size = [], [], [], 0
    if size:
        yield np.concatenate(bt), np.concatenate(bd), np.concatenate(br)


def _hermite_spacing(r0, v0, mu, step):
    """Node spacing (s) of the orbit interpolation in :func:`_orbit_position`, 0 for exact evaluation.

    ``0.005 / w_max`` with ``w_max = h / r_p^2`` the orbit's fastest angular rate
    (periapsis).  0 (exact Kepler at every kick) when the integration step is not
    at least 4x shorter than that (interpolation would not save work) or the
    orbit is degenerate (rectilinear, non-finite).
    """
    h = np.linalg.norm(np.cross(r0, v0))
    rn = np.linalg.norm(r0)
    e_vec = np.cross(v0, np.cross(r0, v0)) / mu - r0 / rn
    rp = h * h / mu / (1.0 + np.linalg.norm(e_vec))
    with np.errstate(divide="ignore", invalid="ignore"):
        D = 0.005 * rp * rp / h
    if not (np.isfinite(D) and D > 0.0 and 4.0 * step <= D):
        return 0.0
    return float(D)


def _run_split(frame, M0, q0, t_out, step, weights, ktorque, rotor, torque, even):
    """Run the splitting over the output times; returns (M_p, q_p, n_steps) at t_out."""
    mode, h_p, h_const = rotor
    ns = len(weights)
    mids = _stage_midpoints(weights)
    starts, n, dt = step_plan(t_out, step, even)
    nout = len(t_out)
    out_M = np.full((nout, 3), np.nan)
    out_q = np.full((nout, 4), np.nan)
    M = np.array(M0, dtype=np.float64)
    q = np.array(q0, dtype=np.float64)
    if ktorque is not None:
        gg = ktorque["gg"]
        gg_mu = 0.0 if gg is None else gg.mu
        gg_I = np.zeros((3, 3)) if gg is None else frame.P.T @ gg.inertia @ frame.P
        h_table1 = np.zeros((1, 1, 3)) if mode != 1 else h_const.reshape(1, 1, 3).copy()
        dummy_r = np.zeros((1, 1, 3))
        orbit_rv = np.zeros((3, 3))
        orbit_nodes = np.zeros((9, 9))
        orbit_mode = 0
        if gg is not None:
            orbit_mode = 2
            if gg.orbit is not None:  # two-body orbit: positions computed inside the kernel
                orbit_mode = 1
                orbit_rv[0], orbit_rv[1], orbit_rv[2, 0] = gg.orbit[0], gg.orbit[1], -gg.orbit[2]
                D = _hermite_spacing(gg.orbit[0], gg.orbit[1], gg.mu, np.max(np.abs(dt)))
                orbit_nodes[2, :3] = D, math.nan, (1.0 / D if D > 0 else 0.0)
        for st, sd, rec in step_chunks(starts, n, dt):
            if orbit_mode == 2:
                tk = st[:, None] + sd[:, None] * mids[None, :]
                r_kick = np.asarray(gg.position(tk.ravel()), dtype=np.float64).reshape(len(st), ns, 3)
            else:
                r_kick = dummy_r
            if mode == 2:
                tm = st[:, None] + sd[:, None] * mids[None, :]
                h_table = np.ascontiguousarray(h_p(tm.ravel()).reshape(len(st), ns, 3))
            else:
                h_table = h_table1
            # the groups of _split_kernel's parameters, one a line (fmt: skip)
            _split_kernel(
                M, q, frame.moments, weights, st, sd, rec, out_M, out_q,
                ktorque["parts"], ktorque["tau_b"], ktorque["tau_i"], ktorque["com"], ktorque["force"],
                gg_mu, gg_I, orbit_mode, r_kick, orbit_rv, orbit_nodes, mode, h_table,
            )  # fmt: skip
    else:
        _run_split_python(frame, M, q, starts, n, dt, weights, mids, torque, h_p, out_M, out_q)
    # outputs reached without any step: copy the previous state (t = 0 or repeated times)
    for k in range(nout):
        if n[k] == 0:
            out_M[k] = M0 if k == 0 else out_M[k - 1]
            out_q[k] = q0 if k == 0 else out_q[k - 1]
    return out_M, out_q, int(n.sum())


def _run_split_python(frame, M, q, starts, n, dt, weights, mids, torque, h_p, out_M, out_q):
    """Same splitting as :func:`_split_kernel` (without the T1 merge), with a general
    Python ``torque(t, q, w)`` applied by implicit-midpoint kicks (symmetric, so a
    ``w``-dependent torque keeps the composition's order)."""
    J_p = frame.moments
    zero = np.zeros(3)

    def hrot(t):
        return zero if h_p is None else np.asarray(h_p(t), dtype=np.float64).reshape(3)

    def tau_p(t, qp, Mp, h):
        w_p = (Mp - h) / J_p
        tau = np.asarray(torque(t, frame.quat_from_p(qp), frame.vec_from_p(w_p)), dtype=np.float64)
        if tau.shape != (3,):
            raise ValueError(f"torque: callable must return a (3,) body torque in N m, got shape {tau.shape}")
        return frame.vec_to_p(tau)

    def kick(t, dtk, h):
        tau0 = tau_p(t, q, M, h)
        M1 = M + dtk * tau0
        for _ in range(20):  # implicit midpoint; one extra evaluation when tau ignores w
            tau1 = tau_p(t, q, 0.5 * (M + M1), h)
            M2 = M + dtk * tau1
            if np.array_equal(M2, M1) or np.max(np.abs(M2 - M1)) <= 4e-16 * np.max(np.abs(M2)):
                M1 = M2
                break
            M1 = M2
        M[:] = M1

    for k in range(len(n)):
        for j in range(int(n[k])):
            t0 = starts[k] + dt[k] * j
            for s, g in enumerate(weights):
                a = g * dt[k]
                tm = t0 + mids[s] * dt[k]
                h = hrot(tm)
                _rotate_about_axis(M, q, 0, (M[0] - h[0]) / J_p[0] * (0.5 * a))
                kick(tm, 0.5 * a, h)
                _inner_rotations(M, q, J_p, h, a)
                kick(tm, 0.5 * a, h)
                _rotate_about_axis(M, q, 0, (M[0] - h[0]) / J_p[0] * (0.5 * a))
            _renormalize(q)
        if n[k] > 0:
            out_M[k] = M
            out_q[k] = q


def _default_step(frame, M0, h0, ktorque, torque, w0):
    """About 1/60 of the fastest natural period (body rates, and the orbit for gravity gradient)."""
    rates = [np.max(np.abs(w0)), np.linalg.norm(M0 - h0) / np.min(frame.moments)]
    if ktorque is not None and ktorque["gg"] is not None:
        r0 = np.asarray(ktorque["gg"].position(np.zeros(1)), dtype=np.float64).reshape(3)
        rates.append(2.0 * math.sqrt(ktorque["gg"].mu / np.dot(r0, r0) ** 1.5))
    rate = max(rates)
    return 0.1 if not rate > 0 else 2.0 * math.pi / (60.0 * rate)


# ---------------------------------------------------------------------------
# public entry point
# ---------------------------------------------------------------------------


# the initial state and times on the first line, the options on the second (fmt: skip)
def _checked_inputs(w0, q0, t, torque, rotor_momentum, method):
    """:func:`propagate_attitude`'s arguments checked (ValueError / TypeError naming the argument):
    ``w0 (3,)``, ``q0 (4,)`` normalised, ``t`` as a 1-D array, and ``auto`` resolved."""
    w0 = real_array(w0, "w0", "propagate_attitude")
    if w0.shape != (3,):
        raise ValueError(f"w0: expected body rates of shape (3,) in rad/s, got shape {w0.shape}")
    q0 = real_array(q0, "q0", "propagate_attitude")
    if q0.shape != (4,):
        raise ValueError(f"q0: expected Euler parameters of shape (4,), scalar first, got shape {q0.shape}")
    nq = np.linalg.norm(q0)
    if not abs(nq - 1.0) <= 1e-6:
        raise ValueError(f"q0: expected unit Euler parameters (|q0| = 1 within 1e-6), got |q0| = {nq}")
    t_out = np.atleast_1d(real_array(t, "t", "propagate_attitude"))
    if t_out.ndim != 1:
        raise ValueError(f"t: expected a scalar or 1-D array of times in s, got shape {t_out.shape}")
    if not np.all(np.isfinite(t_out)):
        raise ValueError("t: times must be finite")
    sgn = 1.0 if np.all(t_out >= 0) else -1.0
    if np.any(sgn * t_out < 0) or np.any(np.diff(sgn * t_out) < 0):
        raise ValueError("t: expected times monotone away from 0 (all >= 0 ascending, or all <= 0 descending)")
    if torque is not None and not callable(torque):
        raise ValueError(f"torque: expected None or a callable torque(t, q, w) -> (3,) N m, got {torque!r}")
    methods = ("auto", "exact", "split2", "split4", "split4-yoshida", "dop853")
    if method not in methods:
        raise ValueError(f"method: expected one of {methods}, got {method!r}")
    if method == "auto":
        method = "exact" if torque is None and rotor_momentum is None else "split4"
    return w0, q0 / nq, t_out, method


def propagate_attitude(
    inertia, w0, q0, t, torque=None, rotor_momentum=None, method="auto", step=None,
    rtol=1e-12, atol=1e-14, error_estimate=True, max_steps=MAX_STEPS,
):  # fmt: skip
    """Propagate a rigid body (or gyrostat) under torques; returns ``(w, q, info)``.

    Parameters
    ----------
    inertia : array_like
        ``(3,)`` principal moments or ``(3, 3)`` tensor in body axes, kg m^2.  For a
        gyrostat it is the inertia ``I`` of ``H = I w + h`` (see
        :mod:`astrodyn.attitude.gyrostat`); for a top, about the fixed point.
    w0 : array_like (3,)
        Initial body angular velocity, rad/s, at ``t = 0``.
    q0 : array_like (4,)
        Initial Euler parameters, scalar first.  Must be a unit quaternion to 1e-6
        (``||q0| - 1| <= 1e-6``, else ``ValueError``); it is then divided by ``|q0|``.
        This is stricter than :func:`~astrodyn.attitude.torque_free.torque_free`,
        which accepts and normalises any nonzero ``q0``: here a ``q0`` that is
        not unit is taken as a caller's mistake (e.g. scalar-last order, a lost
        component), since the integrator's initial state should be an attitude.
        ``method="exact"`` goes through ``torque_free`` with this checked ``q0``.
    t : float or array_like (n,)
        Output times, s, monotone away from 0 (all >= 0 ascending or all <= 0
        descending).
    torque : callable or None
        ``torque(t, q, w) -> (3,)`` body torque, N m; the models of
        :mod:`astrodyn.attitude.torques` (and their :class:`TorqueSum`) run in the
        compiled kernel.
    rotor_momentum : None, array_like (3,) or callable
        Rotor angular momentum relative to the body, body axes, N m s: constant
        or ``h(t)`` (must accept a 1-D array of times and return ``(n, 3)``).
    method : {"auto", "exact", "split2", "split4", "split4-yoshida", "dop853"}
        ``auto`` = ``exact`` without torque and rotors, else ``split4``
        (``split4-yoshida``: the 3-stage composition, for comparison only).
    step : float or None
        Splitting step, s (each output interval uses ``ceil(span / step)`` equal
        steps); default about 1/60 of the fastest natural period.
    rtol, atol : float
        DOP853 tolerances (``atol`` on the scaled state, see below), both > 0.
    error_estimate : bool
        Splitting only: repeat the run with steps ``2 h`` and report a Richardson
        estimate of the error of the returned solution (costs +50 %).
    max_steps : int
        Cap on the integration steps of the call, default :data:`MAX_STEPS`
        (1,000,000).  Splitting: the total number of steps (``info["n_steps"]``, the
        sum of ``ceil(span / step)`` over the output intervals; the error-estimate
        run takes half as many more) is known from ``t`` and ``step`` and checked
        before anything runs: beyond ``max_steps`` a ``ValueError`` names the step,
        the span, the steps needed and how to allow them.  ``dop853``: at most
        ``max_steps`` DOP853 steps (counted as 12 function evaluations each;
        ``RuntimeError`` beyond).  Unused by ``exact`` (its cost does not grow with
        the span).

    Returns
    -------
    w : ndarray ``(n, 3)`` body rates, rad/s (``(3,)`` for a scalar ``t``).
    q : ndarray ``(n, 4)`` Euler parameters, scalar first.
    info : dict
        ``method``, ``order``, ``step`` (s), ``n_steps``, ``seconds`` (wall time),
        ``error_attitude`` (rad) and ``error_rate`` (rad/s) estimates (max over
        outputs; splitting with ``error_estimate``), ``nfev`` (DOP853),
        ``quat_norm_drift`` (DOP853: max ||q| - 1| before normalisation).
    """
    tick = _time.perf_counter()
    frame = _Frame(inertia)
    w0, q0, t_out, method = _checked_inputs(w0, q0, t, torque, rotor_momentum, method)
    max_steps = checked_max_steps(max_steps)
    scalar_t = np.ndim(t) == 0

    def finish(w, q, info):
        info["seconds"] = _time.perf_counter() - tick
        if scalar_t:
            return w[0], q[0], info
        return w, q, info

    if method == "exact":
        if torque is not None or rotor_momentum is not None:
            raise ValueError("method: 'exact' is the torque-free solution; it takes no torque and no rotor_momentum")
        from astrodyn.attitude.torque_free import torque_free

        w_p, q_p = torque_free(frame.moments, frame.vec_to_p(w0), frame.quat_to_p(q0), t_out)
        w_p, q_p = np.asarray(w_p), np.asarray(q_p)
        return finish(frame.vec_from_p(w_p), frame.quat_from_p(q_p), dict(method="exact", order=None))

    rotor = _rotor_function(rotor_momentum, frame)
    mode, h_p, _ = rotor
    h0_p = np.zeros(3) if mode == 0 else np.asarray(h_p(np.zeros(1)), dtype=np.float64).reshape(3)
    w0_p = frame.vec_to_p(w0)
    M0_p = frame.moments * w0_p + h0_p
    if not np.all(np.isfinite(M0_p)) or not np.all(np.isfinite(q0)):
        nan = np.full((len(t_out), 3), np.nan)
        return finish(nan, np.full((len(t_out), 4), np.nan), dict(method=method, order=None))

    if method == "dop853":
        rtol, atol = real_scalar(rtol, "rtol", "propagate_attitude"), real_scalar(atol, "atol", "propagate_attitude")
        if not (0.0 < rtol < math.inf and 0.0 < atol < math.inf):
            raise ValueError(f"rtol and atol: expected finite tolerances > 0, got rtol={rtol!r}, atol={atol!r}")
        if len(t_out) == 0:
            info = dict(method="dop853", order=8, rtol=rtol, atol=atol, nfev=0, quat_norm_drift=0.0)
            return finish(np.empty((0, 3)), np.empty((0, 4)), info)
        return finish(*_run_dop853(frame, w0, q0, t_out, torque, rotor_momentum, rtol, atol, max_steps))

    ktorque = _kernel_torque(torque, frame)
    note = ""
    if step is None:
        step = _default_step(frame, M0_p, h0_p, ktorque, torque, w0)
        note = " (the default: 1/60 of the fastest natural period)"
    step = real_scalar(step, "step", "propagate_attitude")
    if not step > 0 or not math.isfinite(step):
        raise ValueError(f"step: expected a positive finite step in s, got {step}")
    check_step_budget(t_out, step, error_estimate, max_steps, note)
    if len(t_out) == 0:  # nothing to integrate (as the exact path: empty arrays)
        info = dict(method=method, order=_ORDER[method], step=step, n_steps=0, kernel=ktorque is not None)
        if error_estimate:
            info.update(error_attitude=0.0, error_rate=0.0)
        return finish(np.empty((0, 3)), np.empty((0, 4)), info)
    weights = _WEIGHTS[method]
    q0_p = frame.quat_to_p(q0)
    M_p, q_p, nsteps = _run_split(frame, M0_p, q0_p, t_out, step, weights, ktorque, rotor, torque, error_estimate)
    t_h = np.zeros((len(t_out), 3)) if mode == 0 else np.asarray(h_p(t_out), dtype=np.float64).reshape(len(t_out), 3)
    w_p = (M_p - t_h) / frame.moments
    info = dict(method=method, order=_ORDER[method], step=step, n_steps=nsteps, kernel=ktorque is not None)
    if error_estimate:
        M2, q2, _ = _run_split(frame, M0_p, q0_p, t_out, 2.0 * step, weights, ktorque, rotor, torque, False)
        # the coarse plan uses exactly half the (even) step counts of the fine one
        f = 1.0 / (2.0 ** _ORDER[method] - 1.0)
        w2 = (M2 - t_h) / frame.moments
        info["error_attitude"] = float(np.max(attitude_difference(q_p, q2))) * f
        info["error_rate"] = float(np.max(np.linalg.norm(w_p - w2, axis=-1))) * f
    return finish(frame.vec_from_p(w_p), frame.quat_from_p(q_p), info)


def _run_dop853(frame, w0, q0, t_out, torque, rotor_momentum, rtol, atol, max_steps=MAX_STEPS):
    """scipy DOP853 on (q, M) in body axes; M scaled by |M0| (or max I) for the tolerances.
    More than ``max_steps`` steps (12 right-hand sides each) raise RuntimeError."""
    from scipy.integrate import solve_ivp

    J = frame.J
    Jinv = np.linalg.inv(J)
    if callable(rotor_momentum):

        def hfun(t):
            return np.asarray(rotor_momentum(np.asarray([t])), dtype=np.float64).reshape(3)

    else:
        hc = np.zeros(3) if rotor_momentum is None else np.asarray(rotor_momentum, dtype=np.float64)

        def hfun(t):
            return hc

    M0 = J @ w0 + hfun(0.0)
    scale = float(np.linalg.norm(M0)) or float(np.max(frame.moments))
    # The right-hand side in Python floats (scipy calls it once per stage): numpy calls on
    # 3-vectors (cross, matmul, concatenate, zeros) cost 1-10 us each, three times scipy's own
    # work per evaluation (issue 15).  w = J^-1 (M - h), entries of J^-1 as floats.
    (j00, j01, j02), (j10, j11, j12), (j20, j21, j22) = Jinv.tolist()
    h_const = None if callable(rotor_momentum) else hfun(0.0).tolist()

    max_fev = 12 * max_steps
    calls = [0]

    def rhs(t, y):
        calls[0] += 1
        if calls[0] > max_fev:
            raise RuntimeError(f"propagate_attitude: dop853 needs more than max_steps={max_steps} steps "
                               f"({max_fev} right-hand sides) before t = {t:.9g} s; loosen rtol/atol or raise max_steps")
        e0, e1, e2, e3, m0, m1, m2 = y.tolist()
        m0 *= scale
        m1 *= scale
        m2 *= scale
        h0, h1, h2 = h_const if h_const is not None else hfun(t).tolist()
        a0, a1, a2 = m0 - h0, m1 - h1, m2 - h2
        w0_ = j00 * a0 + j01 * a1 + j02 * a2
        w1_ = j10 * a0 + j11 * a1 + j12 * a2
        w2_ = j20 * a0 + j21 * a1 + j22 * a2
        if torque is None:
            t0 = t1 = t2 = 0.0
        else:
            t0, t1, t2 = np.asarray(torque(t, y[:4], np.array([w0_, w1_, w2_])), dtype=np.float64).tolist()
        # dq/dt = Omega(w) q / 2 (Baruh ch. 7; astrodyn.rotation.quat_rate), dM/dt = M x w + tau
        return [
            0.5 * (-e1 * w0_ - e2 * w1_ - e3 * w2_),
            0.5 * (e0 * w0_ + e2 * w2_ - e3 * w1_),
            0.5 * (e0 * w1_ + e3 * w0_ - e1 * w2_),
            0.5 * (e0 * w2_ + e1 * w1_ - e2 * w0_),
            (m1 * w2_ - m2 * w1_ + t0) / scale,
            (m2 * w0_ - m0 * w2_ + t1) / scale,
            (m0 * w1_ - m1 * w0_ + t2) / scale,
        ]

    y0 = np.concatenate([q0, M0 / scale])
    t_end = t_out[-1]
    nout = len(t_out)
    if t_end == 0.0:
        Y = np.tile(y0, (nout, 1))
        nfev = 0
    else:
        sol = solve_ivp(rhs, (0.0, t_end), y0, method="DOP853", t_eval=t_out, rtol=rtol, atol=atol)
        if not sol.success:
            raise RuntimeError(f"DOP853 failed: {sol.message}")
        Y = sol.y.T
        nfev = sol.nfev
    qn = np.linalg.norm(Y[:, :4], axis=-1)
    q = Y[:, :4] / qn[:, None]
    hs = np.array([hfun(tt) for tt in t_out]) if callable(rotor_momentum) else hfun(0.0)
    w = (Y[:, 4:] * scale - hs) @ Jinv.T
    info = dict(method="dop853", order=8, rtol=rtol, atol=atol, nfev=nfev, quat_norm_drift=float(np.max(np.abs(qn - 1))))
    return w, q, info
