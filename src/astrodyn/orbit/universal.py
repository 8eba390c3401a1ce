"""Exact two-body propagation on every conic: ``propagate(r0, v0, dt, mu) -> (r, v)``.

The state moves along the Kepler conic through the Lagrange coefficients
(Vallado 4th ed. sec. 2.3, alg. 8; Curtis sec. 3.7, eqs. 3.69):

    r = f r0 + g v0,        v = fdot r0 + gdot v0.

Units are SI (m, m/s, s, m^3/s^2); any inertial frame (the result is in the
frame of ``r0, v0``).  Vectorized over leading axes: ``r0, v0`` have shape
``(..., 3)``, ``dt`` and ``mu`` broadcast against the leading shape.

Each state picks the formulation that is best conditioned for it (all are the
same universal-variable equation in different scalings, ``x = sqrt(|alpha|) chi``
with ``alpha = 1 / a = 2 / r0 - v0^2 / mu``):

* **Ellipse** (``r0 alpha > 0`` outside the near-parabolic window): the mean
  anomaly change ``n dt`` is formed as an exact double-double product and
  reduced modulo ``2 pi`` exactly (:func:`astrodyn.orbit.floating.reduce_2pi`),
  then the *difference form* of Kepler's equation in the eccentric-anomaly change
  ``x`` is solved, ``(r0/a) x + C (x - sin x) + S (1 - cos x) = n dt mod 2 pi``
  with ``C = e cos E0 = 1 - r0/a`` and ``S = e sin E0 = r0.v0 / sqrt(mu a)``.
  Any number of revolutions costs the same and loses no accuracy beyond the
  conditioning of ``n``.
* **Hyperbola** (``r0 alpha < 0`` outside the window): Kepler's equation in
  the absolute hyperbolic anomaly ``F1`` (well conditioned for long arcs that
  start far out on the incoming asymptote), polished in the difference form
  when the arc is short (``|F1 - F0| < 1``).  ``g`` is taken from whichever of
  three equivalent expressions has the least cancellation (the plain
  ``dt - (sinh x - x)/n`` loses ~700x on such arcs).
* **Near-parabolic and parabolic** (``|r0 alpha| <= 0.05`` and ``|n dt| <= 1``):
  the universal variable ``chi`` with the Stumpff functions ``c2, c3``
  (Vallado eq. 2-50).  In this window ``|z| = |alpha| chi^2 <= 5.06`` (the square
  of the anomaly change; derivation at ``_Z_WINDOW``), so a fixed 13-term series
  gives ``c2, c3`` to float64 accuracy.  Straight-line solve: the root of the
  parabolic (``z = 0``) cubic by a cancellation-free Cardano form, one
  Laguerre-Conway step (Conway 1986, Celest. Mech. 39, 199), one fifth-order
  step from the inverted Taylor series (the derivatives of the time equation
  are ``r``, ``dr/dchi``, ``1 - alpha r``, ``-alpha dr/dchi``) and the residual
  check, all in float64; then one Newton step and f, g with the time equation in
  double-double (:func:`_uni_fg_dd`: the invariants ``r0.v0``, ``v0^2``, ``|r0|`` and
  the energy from the state's components with exact products, the Sundman variable
  ``s = chi / sqrt(mu)`` so that ``sqrt(mu)`` is not rounded into the result).  Near
  the parabola the float64 invariants and time equation alone lose up to ~10x the
  one-ulp floor of the state (an inbound arc through periapsis: the terms of the time
  equation are several times their sum, and ``h^2 = r0^2 v0^2 - (r0.v0)^2`` a small
  difference); with them the position is within ~1x the floor, the rounding of
  f, g and of ``f r0 + g v0`` (tests/test_propagate_universal.py, issue 15).  Where
  the check fails (none of the benchmark's 118k window states; e.g.
  ``|dt| ~ 1e-100 s``, or ``|tau| > 1e154`` on a parabola) the safeguarded loop
  takes over, in float64: Laguerre-Conway kept in a bracket, general Stumpff
  functions.  ``alpha = 0`` exactly is a parabola.

Speed (``astrodyn bench orbit``, docs/bench-orbit.md): large batches are cut
into blocks of 512 states; in each block the ellipses are gathered and solved
in passes over all of them (setup, own ``atan2`` and starter; own ``sin/cos``,
one fifth-order step, residual check and polish; the safeguarded solver for the
few that fail the check; f, g), straight-line code that LLVM vectorizes four
states wide; the hyperbolas likewise (the straight-line solve with an own
``exp`` vectorized, setup and f, g scalar); the near-parabolic states in five
vectorized loops (starter; Laguerre step; series step; check; double-double polish,
f, g and ``r, v``: short loop bodies, because each state's chain of divisions and
square roots is too long for the core to overlap two states of one long body),
then the safeguarded loop for the rare failures and the scatter.  Each state goes through exactly the
operations of a single call, so a batch gives the same bits as one call per
state, serial or parallel (``prange`` over chunks of eight blocks).

All iterations stop on the residual of the time equation at its rounding-noise
level and are capped, so they never hang.  NaN or infinite input, ``|r0| = 0``
or ``mu <= 0`` inside the kernel give NaN (the Python wrappers raise
``ValueError`` for finite ``mu <= 0`` and for wrong shapes).
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np

from astrodyn.inputs import NonRealInputError, broadcast_named, real_array
from astrodyn.jit import jit, pjit, prange
from astrodyn.orbit.floating import (
    EPS,
    HUGE_ANGLE,
    INV6,
    INV24,
    INV_EVEN_FACT,
    INV_ODD_FACT,
    INV_TWO_PI,
    PI,
    TWO_PI_1,
    atan2_vec,
    cbrt_start,
    dot3_dd,
    fast_two_sum,
    fma,
    one_minus_cos,
    reduce_2pi,
    reduce_2pi_core,
    rotate_sincos,
    sincos_vec,
    sinh_parts,
    two_prod,
    two_prod_fma,
    two_sum,
    x_minus_sin,
)
from astrodyn.orbit.kepler import (
    MAX_ITER,
    hyperbolic_upper_start_vec,
    markley_start,
    solve_kepler_difference,
    solve_kepler_hyperbolic_kernel,
    solve_kepler_hyperbolic_vec,
)

__all__ = ["propagate", "propagate_scalar", "lagrange_coefficients", "stumpff"]

Q_UNIVERSAL = 0.05  # |r0 / a| at or below which near-parabolic arcs use chi
M_UNIVERSAL = 1.0  # ... provided the mean-motion angle |n dt| is at most this

# ---------------------------------------------------------------------------
# Stumpff functions
# ---------------------------------------------------------------------------
@jit
def _stumpff(z):
    """Stumpff functions ``(c2(z), c3(z))`` (Vallado 4th ed. eq. 2-52 / Curtis eqs. 3.52-3.53).

    ``c2 = (1 - cos sqrt z) / z``, ``c3 = (sqrt z - sin sqrt z) / sqrt(z)^3`` for
    ``z > 0``, the hyperbolic forms for ``z < 0``; Taylor series
    ``c2 = sum (-z)^k / (2k+2)!``, ``c3 = sum (-z)^k / (2k+3)!`` for ``|z| < 1``
    (ten terms, truncation below 1e-19 relative).
    """
    if abs(z) < 1.0:
        a = INV_EVEN_FACT
        b = INV_ODD_FACT
        c2 = a[9]
        c3 = b[9]
        for k in range(8, -1, -1):
            c2 = a[k] - z * c2
            c3 = b[k] - z * c3
        return c2, c3
    if z > 0.0:
        s = math.sqrt(z)
        sh = math.sin(0.5 * s)
        return 2.0 * sh * sh / z, x_minus_sin(s, math.sin(s)) / (z * s)
    s = math.sqrt(-z)
    sh, chm1, shmx = sinh_parts(s)
    return chm1 / (-z), shmx / (-z * s)


@jit
def _stumpff_loop(z, c2, c3):
    for i in range(z.shape[0]):
        c2[i], c3[i] = _stumpff(z[i])


def stumpff(z):
    """Stumpff functions ``c2(z), c3(z)`` of the universal variable, vectorized.

    ``z = alpha chi^2`` (dimensionless); ``c2(0) = 1/2``, ``c3(0) = 1/6``.
    Series near ``z = 0``, closed forms elsewhere (Vallado 4th ed. eq. 2-52).
    Returns two arrays of the shape of ``z`` (floats for scalar ``z``); ``TypeError``
    naming ``z`` for values that are not real numbers (:mod:`astrodyn.inputs`).
    """
    z = real_array(z, "z", "stumpff")
    zf = np.ascontiguousarray(z).reshape(-1)
    c2 = np.empty_like(zf)
    c3 = np.empty_like(zf)
    _stumpff_loop(zf, c2, c3)
    if z.ndim == 0:
        return float(c2[0]), float(c3[0])
    return c2.reshape(z.shape), c3.reshape(z.shape)


# ---------------------------------------------------------------------------
# the three formulations
# ---------------------------------------------------------------------------
@jit(inline="always")
def _ell_setup(sig, q, alpha, n, dt, mu):
    """Ellipse, part 1: invariants, exact ``n dt mod 2 pi`` and the Markley starter ``x0``.

    Returns ``(sqa, C, S, mh, ml, e, x0, c0)``: ``sqa = 1 / sqrt(mu a)``,
    ``C = e cos E0``, ``S = e sin E0``, ``mh + ml = n dt mod 2 pi`` (double-double),
    ``c0 = mh - S`` (the root obeys ``|x - c0| <= e``).
    """
    if abs(n * dt) < HUGE_ANGLE:  # exact product (double-double) and exact reduction
        mh, ml = two_prod(n, dt)
        _, mh, ml = reduce_2pi_core(mh, ml)
    else:  # the phase is lost anyway (see reduce_2pi); never taken by the block passes
        _, mh, ml = reduce_2pi(n * dt, 0.0)
    return _ell_setup_core(sig, q, alpha, mu, mh, ml)


@jit(inline="always")
def _ell_setup_core(sig, q, alpha, mu, mh, ml):
    """:func:`_ell_setup` after the reduction (straight-line code: the block passes vectorize it)."""
    sqa = math.sqrt(alpha / mu)  # 1 / sqrt(mu a)
    C = 1.0 - q  # e cos E0
    S = sig * sqa  # e sin E0
    e = math.sqrt(C * C + S * S)
    e = e if e < 1.0 - EPS else 1.0 - EPS
    E0 = atan2_vec(S, C)
    M1 = E0 - S + mh
    M1 = M1 - TWO_PI_1 if M1 > PI else (M1 + TWO_PI_1 if M1 < -PI else M1)
    x0 = markley_start(M1, e) - E0
    c0 = mh - S
    x0 += TWO_PI_1 * np.floor((c0 - x0) * INV_TWO_PI + 0.5)
    return sqa, C, S, mh, ml, e, x0, c0


@jit(inline="always")
def _ell_residual(q, C, S, mh, ml, x, s, c):
    """Difference-form residual (see :func:`astrodyn.orbit.kepler.solve_kepler_difference`), its slope ``r/a`` and noise."""
    omc = one_minus_cos(s, c)
    xms = x_minus_sin(x, s)
    rda = q + C * omc + S * s
    F = (q * x + C * xms + S * omc - mh) - ml
    noise = EPS * (abs(q * x) + abs(C * xms) + abs(S * omc) + abs(mh))
    return omc, rda, F, noise


@jit(inline="always")
def _ell_one_step(q, C, S, mh, ml, x, s, c):
    """Ellipse, part 2 (straight-line fast path): one fifth-order step from the starter, then
    the residual check and Newton polish of :func:`astrodyn.orbit.kepler.solve_kepler_difference`.

    The same arithmetic as that solver's first iteration when it converges there
    (the usual case after Markley's starter); ``ok`` is False when it would not
    (series outside its range, step > 0.05 rad, residual above the noise), and the
    caller then runs the general safeguarded solver from the starter instead.
    No loop and no libm call (own :func:`astrodyn.orbit.floating.sincos_vec` before it), so a loop
    over many states vectorizes (:func:`_ell_passes`).
    Returns ``(ok, x, s, c, 1 - cos x, r / a)``.
    """
    omc, rda, F, noise = _ell_residual(q, C, S, mh, ml, x, s, c)
    F2 = C * s + S * c
    F3 = C * c - S * s
    inv = 1.0 / rda
    u = F * inv
    a2u = 0.5 * F2 * inv * u
    a3u2 = F3 * INV6 * inv * u * u
    a4u3 = -F2 * INV24 * inv * u * u * u
    # inverted Taylor series of the residual (fifth order; see solve_kepler_difference)
    dx = -u * (1.0 + a2u + (2.0 * a2u * a2u - a3u2) + (5.0 * a2u * (a2u * a2u - a3u2) + a4u3))
    ok = abs(a2u) < 0.1 and abs(dx) <= 0.05
    x = x + dx
    s, c = rotate_sincos(s, c, dx)
    omc, rda, F, noise = _ell_residual(q, C, S, mh, ml, x, s, c)
    ok = ok and abs(F) <= 2.0 * noise
    F2 = C * s + S * c
    dx = -F / rda
    x += dx
    s, c = s + c * dx, c - s * dx
    omc += s * dx
    rda += F2 * dx
    return ok, x, s, c, omc, rda


@jit(inline="always")
def _ell_fg(r0, q, alpha, n, sqa, S, s, omc, rda):
    """Ellipse, part 3: Lagrange coefficients from the solved eccentric-anomaly change."""
    f = 1.0 - omc / q
    g = (q * s + S * omc) / n  # from the time equation: no m, no cancellation with dt
    r = rda / alpha
    fdot = -s / (sqa * r * r0)
    gdot = 1.0 - omc / rda
    return f, g, fdot, gdot


@jit(inline="always")
def _ell_fallback(q, C, S, mh, ml, e, x0, c0):
    """The general safeguarded solver from the starter (bracket ``c0 +- e``)."""
    pad = 4.0 * EPS * (abs(c0) + 1.0)
    x, s, c, omc, rda = solve_kepler_difference(q, C, S, mh, ml, x0, c0 - e - pad, c0 + e + pad)
    return x, s, c, omc, rda


@jit
def _fg_elliptic(r0, sig, q, alpha, n, dt, mu):
    """Lagrange coefficients on an ellipse via the exactly reduced difference form."""
    sqa, C, S, mh, ml, e, x0, c0 = _ell_setup(sig, q, alpha, n, dt, mu)
    s0, c0s = sincos_vec(x0)
    ok, x, s, c, omc, rda = _ell_one_step(q, C, S, mh, ml, x0, s0, c0s)
    if not ok:
        x, s, c, omc, rda = _ell_fallback(q, C, S, mh, ml, e, x0, c0)
    return _ell_fg(r0, q, alpha, n, sqa, S, s, omc, rda)


@jit(inline="always")
def _hyp_setup(sig, q, beta, n, dt, mu, h2):
    """Hyperbola, part 1: invariants and the absolute mean anomaly ``M1`` at the end.

    Returns ``(sqb, p, Ch, Sh, e, em1, m, F0, M1)``: ``sqb = 1 / sqrt(mu |a|)``,
    ``p = r0 / |a|``, ``Ch = e cosh F0``, ``Sh = e sinh F0``, ``m = n dt``.
    """
    sqb = math.sqrt(beta / mu)  # 1 / sqrt(mu |a|)
    p = -q  # r0 / |a| = e cosh F0 - 1
    Ch = 1.0 + p  # e cosh F0
    Sh = sig * sqb  # e sinh F0
    e2m1 = beta * h2 / mu  # e^2 - 1 (Vallado eq. 2-67 rearranged), no cancellation
    e = math.sqrt(1.0 + e2m1)
    em1 = e2m1 / (1.0 + e)
    m = n * dt
    F0 = math.asinh(Sh / e)
    M1 = (Sh - F0) + m
    return sqb, p, Ch, Sh, e, em1, m, F0, M1


@jit(inline="always")
def _hyp_solve_fast(M1, e, em1):
    """Hyperbola, part 2: ``(ok, F1, sinh F1, cosh F1 - 1)`` by the straight-line path (own
    starter and exp, :func:`astrodyn.orbit.kepler.solve_kepler_hyperbolic_vec`; vectorizable); ``ok`` is
    False where the safeguarded solver must take over (its check failed, ``|M1| >= 1e100``)."""
    M = abs(M1)
    ok, F1, sh1, chm1_1 = solve_kepler_hyperbolic_vec(M, e, em1, hyperbolic_upper_start_vec(M, e, em1))
    return ok & (M < 1e100), math.copysign(F1, M1), math.copysign(sh1, M1), chm1_1


@jit(inline="always")
def _hyp_solve(M1, e, em1):
    """``(F1, sinh F1, cosh F1 - 1)``: :func:`_hyp_solve_fast`, the safeguarded solver as fallback."""
    ok, F1, sh1, chm1_1 = _hyp_solve_fast(M1, e, em1)
    if ok:
        return F1, sh1, chm1_1
    return solve_kepler_hyperbolic_kernel(M1, e, em1)


@jit(inline="always")
def _hyp_fg(r0, sqb, p, Ch, Sh, e, em1, m, F0, beta, n, F1, sh1, chm1_1):
    """Hyperbola, part 3: Lagrange coefficients from the solved absolute anomaly ``F1``
    (difference-form polish of short arcs, ``g`` from its least-cancelling form).

    Compiled on its own (not inlined): it holds a loop and libm calls, and
    inlining it into the block kernel costs compile time for no speed."""
    x = F1 - F0
    sh, chm1, shmx = sinh_parts(x)
    if abs(x) < 1.0:
        # short arc: the difference form G(x) = p x + Ch (sinh x - x) + Sh (cosh x - 1) = m
        # is better conditioned than F1 - F0 (Newton, stopped on the residual)
        for _ in range(MAX_ITER):
            G = (p * x + Ch * shmx + Sh * chm1) - m
            Gp = p + Ch * chm1 + Sh * sh
            noise = EPS * (abs(p * x) + abs(Ch * shmx) + abs(Sh * chm1) + abs(m))
            dx = -G / Gp
            if not (abs(dx) < 0.5):
                break
            x += dx
            sh, chm1, shmx = sinh_parts(x)
            if abs(G) <= 4.0 * noise:
                break
        rb = p + Ch * chm1 + Sh * sh  # r / |a|
    else:
        rb = em1 + e * chm1_1  # e cosh F1 - 1
    # n g from three equivalent forms; take the one with the smallest terms
    t1 = abs(p * sh) + abs(Sh * chm1)
    t2 = abs(e * sh1) + abs(Sh) + abs(sh)
    t3 = abs(m) + abs(shmx)
    if t1 <= t2 and t1 <= t3:
        ng = p * sh + Sh * chm1
    elif t2 <= t3:
        ng = (e * sh1 - Sh) - sh
    else:
        ng = m - shmx
    r = rb / beta
    f = 1.0 - chm1 / p
    g = ng / n
    fdot = -sh / (sqb * r * r0)
    gdot = 1.0 - chm1 / rb
    return f, g, fdot, gdot


@jit
def _fg_hyperbolic(r0, sig, q, beta, n, dt, mu, h2):
    """Lagrange coefficients on a hyperbola (absolute anomaly, difference-form polish)."""
    sqb, p, Ch, Sh, e, em1, m, F0, M1 = _hyp_setup(sig, q, beta, n, dt, mu, h2)
    F1, sh1, chm1_1 = _hyp_solve(M1, e, em1)
    return _hyp_fg(r0, sqb, p, Ch, Sh, e, em1, m, F0, beta, n, F1, sh1, chm1_1)


# ---------------------------------------------------------------------------
# universal variable (near-parabolic window)
# ---------------------------------------------------------------------------
# Bound on z = alpha chi^2 in the window.  z is the square of the eccentric-anomaly
# change x (ellipse) or minus the square of the hyperbolic-anomaly change (hyperbola),
# and x solves the difference form of Kepler's equation (module doc)
#     q x + C (x - sin x) + S (1 - cos x) = n dt,   C = 1 - q,  S^2 = e^2 - C^2 < 1 - C^2
# (hyperbola: p x + Ch (sinh x - x) + Sh (cosh x - 1) = n dt, p = -q, Sh^2 < Ch^2 - 1).
# With |q| <= Q_UNIVERSAL = 0.05 and |n dt| <= M_UNIVERSAL = 1 the root is largest for
# q = 0.05 and the extreme S against the motion: |x| <= 2.2483 (ellipse; z <= 5.055),
# |x| <= 2.0413 (hyperbola; z >= -4.167) (root-finding over q and S, scipy brentq).
# _Z_WINDOW leaves room for float64 rounding of q and the starter's iterates.
_Z_WINDOW = 6.0
# Number of Taylor terms for |z| <= 6: the first omitted terms are z^13 / 28! = 4.3e-20
# (c2 >= c2(6) = 0.295: 1.5e-19 relative) and z^13 / 29! = 1.5e-21 (c3 >= c3(6) = 0.123:
# 1.2e-20 relative), far below the float64 rounding.  The alternating sum at z = 6 has
# sum |terms| = c2(-6) = 0.80 against c2(6) = 0.295 (c3: 0.24 / 0.123), so Estrin's
# rounding stays within a few ulp.  Coefficients 1 / (2k+2)!, 1 / (2k+3)! correctly
# rounded (int / int true division).
# The Laguerre step from the starter only needs T to ~1e-8 (the series step after it
# starts from the Laguerre iterate's ~1e-4 error anyway): its 8 terms leave
# z^8 / 18! = 2.6e-10 (c2: 9e-10 relative) and z^8 / 19! = 1.4e-11 (c3: 1e-10) at |z| = 6.
_N_STUMPFF = 13
_C2_TAYLOR = tuple(1 / math.factorial(2 * k + 2) for k in range(_N_STUMPFF))
_C3_TAYLOR = tuple(1 / math.factorial(2 * k + 3) for k in range(_N_STUMPFF))
# c4 = (1/2 - c2) / z and c5 = (1/6 - c3) / z (Stumpff's recursion c_k = 1/k! - z c_(k+2)):
# the same series shifted by one term, 12 terms for |z| <= 6 (first omitted terms
# z^12 / 28! = 7e-21 against c4(6) = 0.034, z^12 / 29! = 2.4e-22 against c5(6) = 0.0073).
# The final evaluation (_uni_fg_dd) needs c2 = 1/2 - z c4, c3 = 1/6 - z c5 with the
# constant exact and only the small remainder rounded.
_C4_TAYLOR = _C2_TAYLOR[1:]
_C5_TAYLOR = _C3_TAYLOR[1:]
INV6_LO = float(Fraction(1, 6) - Fraction(INV6))  # 1/6 = INV6 + INV6_LO to 106 bits


@jit(inline="always")
def _estrin13(a, y):
    """``sum_{k=0}^{12} a[k] y^k`` by Estrin's scheme (depth 4 instead of Horner's 12)."""
    y2 = y * y
    y4 = y2 * y2
    y8 = y4 * y4
    b0 = a[0] + a[1] * y
    b1 = a[2] + a[3] * y
    b2 = a[4] + a[5] * y
    b3 = a[6] + a[7] * y
    b4 = a[8] + a[9] * y
    b5 = a[10] + a[11] * y
    d0 = (b0 + b1 * y2) + (b2 + b3 * y2) * y4
    d1 = (b4 + b5 * y2) + a[12] * y4
    return d0 + d1 * y8


@jit(inline="always")
def _estrin12(a, y):
    """``sum_{k=0}^{11} a[k] y^k`` by Estrin's scheme."""
    y2 = y * y
    y4 = y2 * y2
    d0 = ((a[0] + a[1] * y) + (a[2] + a[3] * y) * y2) + ((a[4] + a[5] * y) + (a[6] + a[7] * y) * y2) * y4
    d1 = (a[8] + a[9] * y) + (a[10] + a[11] * y) * y2
    return d0 + d1 * (y4 * y4)


@jit(inline="always")
def _estrin8(a, y):
    """``sum_{k=0}^{7} a[k] y^k`` by Estrin's scheme."""
    y2 = y * y
    return ((a[0] + a[1] * y) + (a[2] + a[3] * y) * y2) + ((a[4] + a[5] * y) + (a[6] + a[7] * y) * y2) * (y2 * y2)


@jit(inline="always")
def _stumpff_window(z):
    """``(c2(z), c3(z))`` by their 13-term Taylor series, for ``|z| <= _Z_WINDOW`` (= 6).

    Straight-line code (vectorizes); accurate to a few ulp there (see the comment
    at ``_Z_WINDOW``).  Outside that range it is not used (the fast path checks).
    """
    return _estrin13(_C2_TAYLOR, -z), _estrin13(_C3_TAYLOR, -z)


@jit(inline="always")
def _uni_start(r0, sg, omq, tau):
    """Starter: the root of the parabolic (``z = 0``) time equation, a cubic in chi.

    ``cc chi^3 / 6 + sg chi^2 / 2 + r0 chi = tau`` with ``cc = max(1 - q, sg^2 / (2 r0))``
    (``1 - q`` is the exact leading coefficient; the max keeps the cubic monotonic,
    ``r0 + sg chi + cc chi^2 / 2 > 0``, so it has one real root).  With
    ``chi = y - s``, ``s = sg / cc`` it reads ``y^3 + P y = R``, ``P >= 0``, and
    Cardano's root ``y = A - B``, ``A^3 = R/2 + sqrt(R^2/4 + P^3/27)``,
    ``B = P / (3 A)``, is formed without cancellation as ``R / (A^2 + A B + B^2)``
    (``A^3 - B^3 = R``; Barker's solution when ``sg = 0``, ``cc = 1``).
    The ``z`` terms left out make it a starter only (Laguerre-Conway then
    converges in one or two steps: the module doc).  Overflow (``|tau| > ~1e154``)
    gives a useless starter and the caller's check sends the state to the safeguarded loop.
    """
    w = sg * sg / (2.0 * r0)
    cc = omq if omq >= w else w
    icc = 1.0 / cc
    s = sg * icc
    P = 6.0 * r0 * icc - 3.0 * s * s
    P = P if P > 0.0 else 0.0
    R = 6.0 * icc * (tau + s * (r0 - cc * s * s * (1.0 / 3.0)))
    u = 0.5 * abs(R)
    A = cbrt_start(u + math.sqrt(u * u + P * P * P * (1.0 / 27.0)))
    B = P / (3.0 * A)
    return math.copysign(2.0 * u / (A * A + A * B + B * B), R) - s


@jit(inline="always")
def _uni_radius(chi, z, c2, c3, r0, sg):
    """``r / sqrt(mu)``-scaled radius ``dT/dchi = chi^2 c2 + sg chi (1 - z c3) + r0 (1 - z c2)`` [m]."""
    return chi * chi * c2 + sg * chi * (1.0 - z * c3) + r0 * (1.0 - z * c2)


@jit(inline="always")
def _uni_time(chi, z, c2, c3, r0, sg, omq, tau):
    """Time-equation residual ``T`` (Vallado eq. 2-50 times sqrt(mu)) [m^(3/2)], its slope
    ``rr = dT/dchi`` (the radius) and the rounding noise of ``T``, at ``chi`` with
    ``z = alpha chi^2`` and ``c2(z), c3(z)`` given."""
    chi2 = chi * chi
    t1 = r0 * chi
    t2 = sg * chi2 * c2
    t3 = omq * chi * chi2 * c3
    T = (t1 + t2 + t3) - tau
    noise = EPS * (abs(t1) + abs(t2) + abs(t3) + abs(tau))
    return T, _uni_radius(chi, z, c2, c3, r0, sg), noise


@jit(inline="always")
def _uni_laguerre(chi, r0, sg, omq, alpha, tau):
    """One Laguerre-Conway step (n = 5; Conway 1986) on the time equation, with the
    8-term series (1e-9 relative: enough for the step from the starter, see ``_N_STUMPFF``)."""
    z = alpha * (chi * chi)
    c2, c3 = _estrin8(_C2_TAYLOR, -z), _estrin8(_C3_TAYLOR, -z)
    T, rr, noise = _uni_time(chi, z, c2, c3, r0, sg, omq, tau)
    drr = sg * (1.0 - z * c2) + omq * chi * (1.0 - z * c3)  # dr/dchi
    return chi - 5.0 * T / (rr + math.sqrt(abs(16.0 * rr * rr - 20.0 * T * drr)))


@jit(inline="always")
def _uni_series_step(chi, r0, sg, omq, alpha, tau):
    """One fifth-order step: the inverted Taylor series of the time equation about ``chi``.

    The derivatives of ``T`` are all at hand: ``T' = r``, ``T'' = dr/dchi``,
    ``T^(3) = 1 - alpha r`` and ``T^(4) = -alpha dr/dchi`` (the universal functions
    obey ``U_k' = U_(k-1)``, ``U0' = -alpha U1`` and ``U0 + alpha U2 = 1``; Battin 1999
    sec. 4.5), so with ``u = T / T'`` and ``a_k = T^(k) / (k! T')`` the root is
    ``chi - u (1 + a2 u + (2 a2^2 - a3) u^2 + (5 a2^3 - 5 a2 a3 + a4) u^3) + O(u^5)``
    (the series of the ellipse's step, :func:`_ell_one_step`).
    """
    z = alpha * (chi * chi)
    c2, c3 = _stumpff_window(z)
    T, rr, noise = _uni_time(chi, z, c2, c3, r0, sg, omq, tau)
    drr = sg * (1.0 - z * c2) + omq * chi * (1.0 - z * c3)  # dr/dchi
    inv = 1.0 / rr
    u = T * inv
    a2u = 0.5 * drr * inv * u
    a3u2 = (1.0 - alpha * rr) * INV6 * inv * u * u
    a4u3 = -alpha * drr * INV24 * inv * u * u * u
    return chi - u * (1.0 + a2u + (2.0 * a2u * a2u - a3u2) + (5.0 * a2u * (a2u * a2u - a3u2) + a4u3))


@jit(inline="always")
def _uni_fast(r0, sg, q, alpha, tau):
    """Straight-line universal-variable solve (no loop, no libm call but sqrt: vectorizes).

    Parabolic-cubic starter (:func:`_uni_start`; relative error up to ~5 % where
    ``|z| ~ 3``), one Laguerre-Conway step (robust from a poor start; ~1e-4 left),
    one fifth-order series step (:func:`_uni_series_step`) and the residual check
    ``|T| <= 4 noise`` of the safeguarded loop (:func:`_uni_check`).  The root is then
    within the rounding noise of the float64 time equation; :func:`_uni_fg_dd` polishes
    it against the time equation in double-double and forms f, g.
    Returns ``(ok, chi)``; ``ok`` is False (the caller then runs
    :func:`_uni_solve_safe`) when the check fails or ``|z| > _Z_WINDOW`` or
    anything is NaN.
    """
    omq = 1.0 - q
    chi = _uni_start(r0, sg, omq, tau)
    chi = _uni_laguerre(chi, r0, sg, omq, alpha, tau)
    chi = _uni_series_step(chi, r0, sg, omq, alpha, tau)
    ok, z, c4, c5 = _uni_check(chi, r0, sg, omq, alpha, tau)
    return ok, chi, z, c4, c5


@jit(inline="always")
def _uni_check(chi, r0, sg, omq, alpha, tau):
    """The end of :func:`_uni_fast`: is ``chi`` a root to the noise of the float64 time equation
    (and inside the window of the series, with a positive radius)?  Returns ``(ok, z, c4, c5)``:
    the Stumpff functions come from ``c4, c5`` (``c2 = 1/2 - z c4``, ``c3 = 1/6 - z c5``),
    which :func:`_uni_fg_dd` reuses."""
    z = alpha * (chi * chi)
    c4 = _estrin12(_C4_TAYLOR, -z)
    c5 = _estrin12(_C5_TAYLOR, -z)
    T, rr, noise = _uni_time(chi, z, 0.5 - z * c4, INV6 - z * c5, r0, sg, omq, tau)
    return (abs(T) <= 4.0 * noise) & (abs(z) <= _Z_WINDOW) & (rr > 0.0), z, c4, c5


@jit(inline="always")
def _uni_invariants_dd(rx, ry, rz, vx, vy, vz, r0, mu):
    """The invariants the final evaluation needs beyond float64, from the state's components.

    Near the parabola the orbit is a small difference of large numbers: the energy
    ``q = r0 / a = 2 - r0 v0^2 / mu`` (``|q|`` down to 1e-4 and below) and the angular
    momentum ``h^2 = r0^2 v0^2 - (r0.v0)^2 ~ (r_p / r0) r0^2 v0^2`` (a fortieth of its
    terms from ``r0 = 40 r_p``).  One rounding of ``r0.v0`` or ``v0^2`` (or of ``|r0|``
    inside ``q``) moves the propagated position by up to several times what a one-ulp
    change of an input does (measured: 2.4x, 1.4x and 0.7x the floor alone), so they
    are formed in double-double (:func:`dot3_dd`, exact products by
    :func:`two_prod_fma`) and ``q`` is rounded once at the end.
    Returns ``(r0_lo, 1 / r0, sig_hi, sig_lo, q)`` with ``|r0| = r0 + r0_lo`` (``r0`` the
    float64 norm :func:`_classify` formed), ``sig_hi + sig_lo = r0.v0``.
    """
    r2h, r2l = dot3_dd(rx, ry, rz, rx, ry, rz)
    inv_r0 = 1.0 / r0
    r0l = (fma(-r0, r0, r2h) + r2l) * (0.5 * inv_r0)  # sqrt(r2) = r0 + (r2 - r0^2) / (2 r0)
    v2h, v2l = dot3_dd(vx, vy, vz, vx, vy, vz)
    sigh, sigl = dot3_dd(rx, ry, rz, vx, vy, vz)
    ph, pl = two_prod_fma(r0, v2h)  # r0 v0^2 (double-double)
    pl += r0 * v2l + r0l * v2h
    inv_mu = 1.0 / mu
    wh = ph * inv_mu  # r0 v0^2 / mu ~ 2: its remainder exactly by fma
    wl = (fma(-wh, mu, ph) + pl) * inv_mu
    q = (2.0 - wh) - wl  # 2 - wh exact (Sterbenz: wh in [1, 4] in the window)
    return r0l, inv_r0, sigh, sigl, q


@jit(inline="always")
def _uni_fg_dd(rx, ry, rz, vx, vy, vz, r0, chi, z0, c4, c5, dt, mu, sqmu):
    """Lagrange coefficients at the root near ``chi`` with the time equation in double-double.

    In the Sundman variable ``s = chi / sqrt(mu)`` with ``G_k = s^k c_k(beta s^2)``,
    ``beta = mu alpha`` (Goodyear 1965; Battin 1999 sec. 4.5), so the rounding of
    ``sqrt(mu)`` (outside the one-ulp floor: mu is not perturbed; it was the larger part
    of the median error) never enters:

        T = r0 G1 + sig G2 + mu G3 - dt,   r = r0 G0 + sig G1 + mu G2,
        f = 1 - mu G2 / r0,  g = r0 G1 + sig G2,  fdot = -mu G1 / (r r0),  gdot = 1 - mu G2 / r.

    On an inbound arc through periapsis the terms of ``T`` and ``g`` are several times
    their sum, so each is formed to about eps^2: ``s^2``, ``s^3`` and the products with
    ``r0, sig, mu`` exactly (:func:`two_prod_fma`), ``c2 = 1/2 - z c4``, ``c3 = 1/6 - z c5``
    with only the ``z`` remainders rounded, and the invariants of
    :func:`_uni_invariants_dd`.  One Newton step ``d = -T / r`` from ``chi`` (a root to
    the float64 noise, :func:`_uni_check`) polishes ``s``; ``G1, G2`` and ``g`` follow to
    first order (``G_k' = G_(k-1)``; the neglected ``d^2`` terms are ~eps^2 relative).
    ``c4, c5`` are those of the check at ``z0 = alpha chi^2`` (float64 ``alpha``), moved to
    first order to this ``z`` (``c4' = -1/720``, ``c5' = -1/5040`` up to O(z); ``z - z0`` is
    a few ulp of ``q`` times ``chi^2 / r0``, so the neglected terms are ~eps^2).

    The time unit is scaled by the power of two ``p <= sqrt(mu) < 2 p`` (exactly: ``v0 / p``,
    ``mu / p^2`` in ``[1, 4)``, ``dt p``; then ``g / p``, ``fdot p``), so ``s`` is within a
    factor 2 of ``chi`` and every intermediate has the range of the chi-form of the check
    for any ``mu`` (unscaled, ``s^3 = chi^3 / mu^1.5`` overflows for ``mu`` ~ 1e-200).
    """
    p = np.int64(np.float64(sqmu).view(np.int64) & 0x7FF0000000000000).view(np.float64)
    ip = 1.0 / p  # exact: sqmu >= sqrt(5e-324) is normal
    vx, vy, vz = vx * ip, vy * ip, vz * ip
    mu = (mu * ip) * ip
    dt = dt * p
    r0l, inv_r0, sigh, sigl, q = _uni_invariants_dd(rx, ry, rz, vx, vy, vz, r0, mu)
    beta = mu * (q * inv_r0)  # 2 mu / r0 - v0^2
    s = chi * (p / sqmu)  # chi / sqrt(mu) to an ulp (the polish below takes any error)
    z = beta * (s * s)
    dz = z - z0
    c4 = c4 - dz * _C4_TAYLOR[1]
    c5 = c5 - dz * _C5_TAYLOR[1]
    s2h, s2l = two_prod_fma(s, s)
    s3h, s3l = two_prod_fma(s2h, s)
    s3l += s2l * s
    g2h, g2l = fast_two_sum(0.5 * s2h, 0.5 * s2l - s2h * (z * c4))  # G2 = s^2 c2 (|z c4| < 1/2)
    g3 = s3h * (INV6 - z * c5)  # G3 = s^3 c3, float: a z/6 part of G1 below
    g1h, g1l = fast_two_sum(s, -beta * g3)  # G1 = s c1 = s - beta G3 (|beta G3| < |s| in the window)
    g0 = 1.0 - beta * g2h
    # T = (r0 G1 + sig G2) + mu G3 - dt, each product exact plus its low-order terms;
    # mu G3 = (mu / 6) s^3 + mu s^3 (c3 - 1/6) with mu / 6 in double-double
    ah, al = two_prod_fma(r0, g1h)
    al += r0 * g1l + r0l * g1h
    bh, bl = two_prod_fma(sigh, g2h)
    bl += sigh * g2l + sigl * g2h
    m6h, m6l = two_prod_fma(mu, INV6)
    m6l += mu * INV6_LO
    ch, cl = two_prod_fma(m6h, s3h)
    cl += (m6h * s3l + m6l * s3h) - (mu * s3h) * (z * c5)
    gh, gl = two_sum(ah, bh)
    gl += al + bl
    th, tl = two_sum(gh, ch)
    T = (th - dt) + (tl + (gl + cl))  # at the root |th - dt| ~ |T| << |dt|: its rounding is eps |T|
    mg2 = mu * g2h
    rr = (r0 * g0 + sigh * g1h) + mg2
    d = -T / rr
    # one Newton step on s, carried to first order
    g = gh + (gl + (rr - mg2) * d)  # d(r0 G1 + sig G2)/ds = r - mu G2
    g2l += g1h * d
    mh, ml = two_prod_fma(mu, g2h)
    ml += mu * g2l
    fq = mh * inv_r0  # mu G2 / r0 (double-double): its remainder exactly by fma
    fql = (fma(-fq, r0, mh) + (ml - fq * r0l)) * inv_r0
    fh, fl = two_sum(1.0, -fq)
    f = fh + (fl - fql)
    g1 = g1h + (g1l + g0 * d)
    rr += (sigh * g0 + (mu - beta * r0) * g1h) * d  # r(s + d): dr/ds = sig G0 + mu (1 - q) G1
    fdot = -mu * g1 * inv_r0 / rr
    gdot = 1.0 - (mh + ml) / rr
    return f, g * ip, fdot * p, gdot


@jit
def _uni_solve_safe(r0, sg, q, alpha, tau):
    """The safeguarded universal-variable solve (reference path, any input of the window).

    Laguerre-Conway iteration kept inside a bracket of the root (Conway 1986,
    Celest. Mech. 39, 199) from a linear/cubic starter, general Stumpff functions
    (:func:`_stumpff`), stopped on the residual at its noise level and capped.
    Returns ``(chi, z, c2, c3, rr)`` at the polished root.
    """
    omq = 1.0 - q
    chi = tau / r0
    cub = cbrt_start(6.0 * abs(tau) / omq)
    if abs(chi) > cub:
        chi = math.copysign(cub, tau)
    if tau > 0.0:
        lo, hi = 0.0, math.inf
    else:
        lo, hi = -math.inf, 0.0
    c2 = 0.5
    c3 = 1.0 / 6.0
    z = 0.0
    rr = r0
    for _ in range(MAX_ITER + 28):
        z = alpha * (chi * chi)
        c2, c3 = _stumpff(z)
        T, rr, noise = _uni_time(chi, z, c2, c3, r0, sg, omq, tau)
        if abs(T) <= 4.0 * noise:
            chi -= T / rr
            z = alpha * (chi * chi)
            c2, c3 = _stumpff(z)
            rr = _uni_radius(chi, z, c2, c3, r0, sg)
            break
        if T > 0.0:
            hi = min(hi, chi)
        else:
            lo = max(lo, chi)
        drr = sg * (1.0 - z * c2) + omq * chi * (1.0 - z * c3)  # dr/dchi
        disc = abs(16.0 * rr * rr - 20.0 * T * drr)
        dchi = -5.0 * T / (rr + math.sqrt(disc))  # Laguerre-Conway, n = 5; rr > 0
        chin = chi + dchi
        if not (lo < chin < hi):
            if math.isinf(hi):
                chin = 2.0 * max(chi, lo) + 1.0
            elif math.isinf(lo):
                chin = 2.0 * min(chi, hi) - 1.0
            else:
                chin = 0.5 * (lo + hi)
        if chin == chi:
            break
        chi = chin
    return chi, z, c2, c3, rr


@jit(inline="always")
def _uni_functions(chi, z, c2, c3):
    """Universal functions ``U1 = chi (1 - z c3)``, ``U2 = chi^2 c2``, ``U3 = chi^3 c3`` [m^(k/2)]."""
    chi2 = chi * chi
    return chi * (1.0 - z * c3), chi2 * c2, chi * chi2 * c3


@jit(inline="always")
def _uni_fg(r0, sg, dt, sqmu, tau, U1, U2, U3, rr):
    """Lagrange coefficients from the universal functions at the root (Vallado eqs. 2-65..2-68):
    ``f = 1 - U2 / r0``, ``fdot = -sqrt(mu) U1 / (r r0)``, ``gdot = 1 - U2 / r`` and
    ``g`` from the time equation, ``(sg U2 + r0 U1) / sqrt(mu)``, or
    ``dt - U3 / sqrt(mu)``, whichever cancels less (both formed, one selected:
    straight-line code).
    """
    ta = abs(sg * U2) + abs(r0 * U1)
    tb = abs(tau) + abs(U3)
    ga = (sg * U2 + r0 * U1) / sqmu
    gb = dt - U3 / sqmu
    g = ga if ta <= tb else gb
    f = 1.0 - U2 / r0
    fdot = -sqmu * U1 / (rr * r0)
    gdot = 1.0 - U2 / rr
    return f, g, fdot, gdot


@jit
def _fg_universal(rx, ry, rz, vx, vy, vz, r0, sg, q, alpha, dt, mu, sqmu):
    """Lagrange coefficients from the universal variable chi (near-parabolic, parabolic).

    Solves ``sqrt(mu) dt = r0 chi + sg chi^2 c2 + (1 - q) chi^3 c3`` (Vallado eq.
    2-50 / Curtis eq. 3.49) with ``sg = r0.v0 / sqrt(mu)``, ``z = alpha chi^2``:
    the straight-line :func:`_uni_fast` and :func:`_uni_fg_dd`, or
    :func:`_uni_solve_safe` where its check fails.
    """
    tau = sqmu * dt
    ok, chi, z0, c4, c5 = _uni_fast(r0, sg, q, alpha, tau)
    if not ok:
        return _fg_universal_safe(r0, sg, q, alpha, dt, sqmu)
    return _uni_fg_dd(rx, ry, rz, vx, vy, vz, r0, chi, z0, c4, c5, dt, mu, sqmu)


@jit
def _fg_universal_safe(r0, sg, q, alpha, dt, sqmu):
    """:func:`_fg_universal` by the safeguarded loop alone (its fallback; the reference path)."""
    tau = sqmu * dt
    chi, z, c2, c3, rr = _uni_solve_safe(r0, sg, q, alpha, tau)
    U1, U2, U3 = _uni_functions(chi, z, c2, c3)
    return _uni_fg(r0, sg, dt, sqmu, tau, U1, U2, U3, rr)


@jit(inline="always")
def _classify(rx, ry, rz, vx, vy, vz, dt, mu):
    """Which formulation a state takes (module doc), with its scalar invariants.

    Returns ``(kind, r0, sig, q, alpha, n)``: kind 0 = NaN result (non-finite
    input, ``r0 = 0``, ``mu <= 0``), 1 = identity (``dt = 0``), 2 = ellipse,
    3 = hyperbola, 4 = universal variable (near-parabolic window).
    ``sig = r0.v0``, ``q = r0 / a``, ``alpha = 1 / a``, ``n`` the mean motion.
    """
    if not (
        math.isfinite(rx)
        and math.isfinite(ry)
        and math.isfinite(rz)
        and math.isfinite(vx)
        and math.isfinite(vy)
        and math.isfinite(vz)
        and math.isfinite(dt)
        and math.isfinite(mu)
        and mu > 0.0
    ):
        return 0, 0.0, 0.0, 0.0, 0.0, 0.0
    r0 = math.sqrt(rx * rx + ry * ry + rz * rz)
    if r0 == 0.0:
        return 0, 0.0, 0.0, 0.0, 0.0, 0.0
    if dt == 0.0:
        return 1, r0, 0.0, 0.0, 0.0, 0.0
    v2 = vx * vx + vy * vy + vz * vz
    sig = rx * vx + ry * vy + rz * vz
    q = 2.0 - r0 * v2 / mu  # r0 / a
    alpha = q / r0
    if q > 0.0:
        n = alpha * math.sqrt(mu * alpha)
    else:
        n = -alpha * math.sqrt(-mu * alpha)
    if abs(q) <= Q_UNIVERSAL and abs(n * dt) <= M_UNIVERSAL:
        return 4, r0, sig, q, alpha, n
    if q > 0.0:
        return 2, r0, sig, q, alpha, n
    return 3, r0, sig, q, alpha, n


@jit(inline="always")
def _dispatch(kind, r0, sig, q, alpha, n, rx, ry, rz, vx, vy, vz, dt, mu):
    """``(f, g, fdot, gdot)`` of a classified state (:func:`_classify`)."""
    if kind == 2:
        return _fg_elliptic(r0, sig, q, alpha, n, dt, mu)
    if kind == 3:
        hx = ry * vz - rz * vy
        hy = rz * vx - rx * vz
        hz = rx * vy - ry * vx
        return _fg_hyperbolic(r0, sig, q, -alpha, n, dt, mu, hx * hx + hy * hy + hz * hz)
    if kind == 4:
        sqmu = math.sqrt(mu)
        return _fg_universal(rx, ry, rz, vx, vy, vz, r0, sig / sqmu, q, alpha, dt, mu, sqmu)
    if kind == 1:
        return 1.0, 0.0, 0.0, 1.0
    nan = math.nan
    return nan, nan, nan, nan


@jit
def lagrange_coefficients_scalar(rx, ry, rz, vx, vy, vz, dt, mu):
    """``(f, g, fdot, gdot)`` for one state; picks the formulation (see module doc)."""
    kind, r0, sig, q, alpha, n = _classify(rx, ry, rz, vx, vy, vz, dt, mu)
    return _dispatch(kind, r0, sig, q, alpha, n, rx, ry, rz, vx, vy, vz, dt, mu)


# ---------------------------------------------------------------------------
# loops (serial for small batches, parallel for large ones)
# ---------------------------------------------------------------------------
_BLOCK = 512  # states per block: ellipses and hyperbolas are gathered per block and solved in pairs


@jit(inline="always")
def _store(r0, v0, r, v, i, f, g, fd, gd):
    for j in range(3):
        r[i, j] = f * r0[i, j] + g * v0[i, j]
        v[i, j] = fd * r0[i, j] + gd * v0[i, j]


# rows of the per-block work array W (columns: gathered states); ellipses fill the
# columns from the front, hyperbolas from the back
_RN, _SIG, _Q, _ALPHA, _N, _H2, _DT, _MU = 0, 1, 2, 3, 4, 5, 5, 6  # inputs (_H2: hyperbolas, _DT: ellipses)
_SQA, _C, _S, _MH, _ML, _E, _X0, _C0 = 7, 8, 9, 10, 11, 12, 13, 14  # ellipse setup
_OK, _SX, _OMC, _RDA = 15, 16, 17, 18  # ellipse solve
# hyperbolas have their own work array WH (columns from 0, so LLVM sees
# non-negative indices and vectorizes): rows _RN.._N, _H2, _MU as in W, then
_HDT, _SQB, _P, _CH, _SH, _HE, _EM1, _M, _F0, _M1 = 7, 8, 9, 10, 11, 12, 13, 14, 15, 16  # setup
_HOK, _F1, _SH1, _CHM1 = 17, 18, 19, 20  # solve
_NW = 19
_NWH = 21
# near-parabolic states: their own work array WU (rows _RN, _SIG, _Q, _ALPHA as in W), then
_UDT, _UMU, _UOK, _UF, _UG, _UFD, _UGD = 4, 5, 6, 7, 8, 9, 10
_USQMU, _USG, _UTAU, _UCHI = 11, 12, 13, 14
_URX, _URY, _URZ, _UVX, _UVY, _UVZ = 15, 16, 17, 18, 19, 20  # the state's components (finish pass)
_UZ, _UC4, _UC5 = 21, 22, 23  # z and the Stumpff c4, c5 of the check
_NWU = 24
# WU's rows are _BLOCK + _WU_PAD long: with exactly 512 doubles (4 KiB) every row of a column
# falls in the same L1 cache set, and the 24 rows a column touches evict each other
# (measured: the gather and the passes 2-3 ns/state slower than with padded rows)
_WU_PAD = 32


@jit
def _ell_passes(W, m, idx, r0, v0, r, v):
    """The ellipses of a block (columns ``0:m`` of ``W``) in passes over all of them.

    Pass 1 (setup, own atan2, starter) and pass 2 (own sin/cos, fifth-order step,
    residual check, polish) are straight-line code over independent columns, so
    LLVM vectorizes them (AVX2: four states per instruction); the few states whose
    check fails take the general safeguarded solver in a scalar pass 3; pass 4
    forms f, g and stores.  Each column goes through exactly the operations of
    :func:`_fg_elliptic`, so the results are bit-identical to a single call.
    """
    for k in range(m):
        mh, ml = two_prod(W[_N, k], W[_DT, k])  # |n dt| < HUGE_ANGLE (see the gather)
        _, mh, ml = reduce_2pi_core(mh, ml)
        sqa, C, S, mh, ml, e, x0, c0 = _ell_setup_core(W[_SIG, k], W[_Q, k], W[_ALPHA, k], W[_MU, k], mh, ml)
        W[_SQA, k] = sqa
        W[_C, k] = C
        W[_S, k] = S
        W[_MH, k] = mh
        W[_ML, k] = ml
        W[_E, k] = e
        W[_X0, k] = x0
        W[_C0, k] = c0
    for k in range(m):
        x0 = W[_X0, k]
        s, c = sincos_vec(x0)
        ok, x, s, c, omc, rda = _ell_one_step(W[_Q, k], W[_C, k], W[_S, k], W[_MH, k], W[_ML, k], x0, s, c)
        W[_OK, k] = 1.0 if ok else 0.0
        W[_SX, k] = s
        W[_OMC, k] = omc
        W[_RDA, k] = rda
    for k in range(m):
        if W[_OK, k] == 0.0:
            x, s, c, omc, rda = _ell_fallback(
                W[_Q, k], W[_C, k], W[_S, k], W[_MH, k], W[_ML, k], W[_E, k], W[_X0, k], W[_C0, k]
            )
            W[_SX, k] = s
            W[_OMC, k] = omc
            W[_RDA, k] = rda
    for k in range(m):
        f, g, fd, gd = _ell_fg(W[_RN, k], W[_Q, k], W[_ALPHA, k], W[_N, k], W[_SQA, k], W[_S, k], W[_SX, k], W[_OMC, k], W[_RDA, k])
        _store(r0, v0, r, v, idx[k], f, g, fd, gd)


@jit
def _uni_fast_pass(W, nu):
    """Pass 1 of :func:`_uni_passes`: :func:`_uni_fast` of every column (the root ``chi``,
    the check and its ``z, c4, c5`` into ``W``), as straight-line loops that LLVM
    vectorizes.  Cut into four loops (starter; Laguerre step; series step; check): each
    state's chain of dependent divisions and square roots is long, and shorter loop
    bodies let the core overlap more states (measured 43 -> 30 ns/state).  The same
    operations as :func:`_uni_fast`."""
    for k in range(nu):
        sqmu = math.sqrt(W[_UMU, k])
        sg = W[_SIG, k] / sqmu
        tau = sqmu * W[_UDT, k]
        W[_USQMU, k] = sqmu
        W[_USG, k] = sg
        W[_UTAU, k] = tau
        W[_UCHI, k] = _uni_start(W[_RN, k], sg, 1.0 - W[_Q, k], tau)
    for k in range(nu):
        W[_UCHI, k] = _uni_laguerre(W[_UCHI, k], W[_RN, k], W[_USG, k], 1.0 - W[_Q, k], W[_ALPHA, k], W[_UTAU, k])
    for k in range(nu):
        W[_UCHI, k] = _uni_series_step(W[_UCHI, k], W[_RN, k], W[_USG, k], 1.0 - W[_Q, k], W[_ALPHA, k], W[_UTAU, k])
    for k in range(nu):
        ok, z, c4, c5 = _uni_check(W[_UCHI, k], W[_RN, k], W[_USG, k], 1.0 - W[_Q, k], W[_ALPHA, k], W[_UTAU, k])
        W[_UOK, k] = 1.0 if ok else 0.0
        W[_UZ, k] = z
        W[_UC4, k] = c4
        W[_UC5, k] = c5


@jit
def _uni_passes(W, nu, idx, r0, v0, r, v):
    """The near-parabolic states of a block (columns ``0:nu`` of their work array ``W``).

    Pass 1 (:func:`_uni_fast_pass`): starter, Laguerre-Conway and series steps and
    check as straight-line code over all columns (vectorized); pass 2
    (:func:`_uni_finish`): the double-double polish and f, g (:func:`_uni_fg_dd`, from
    the components the gather stored) and ``r, v``, vectorized, then the safeguarded
    loop (:func:`_fg_universal_safe`) for the columns whose check failed, and the
    scatter.  Bit-identical to :func:`_fg_universal` on each state.
    """
    _uni_fast_pass(W, nu)
    _uni_finish(W, nu, idx, r0, v0, r, v)


@jit
def _uni_finish_pass(W, nu, idx, r0, v0, r, v):
    """Pass 2 of :func:`_uni_passes` for a work array whose gather did not store the
    components: gathers them into rows ``_URX.._UVZ``, then :func:`_uni_finish`."""
    for k in range(nu):
        i = idx[k]
        W[_URX, k], W[_URY, k], W[_URZ, k] = r0[i, 0], r0[i, 1], r0[i, 2]
        W[_UVX, k], W[_UVY, k], W[_UVZ, k] = v0[i, 0], v0[i, 1], v0[i, 2]
    _uni_finish(W, nu, idx, r0, v0, r, v)


@jit
def _uni_finish(W, nu, idx, r0, v0, r, v):
    """Pass 2 of :func:`_uni_passes` (the components in rows ``_URX.._UVZ``, stored by the
    gather of :func:`_propagate_block`): :func:`_uni_fg_dd` at every column's root and
    ``r = f r0 + g v0``, ``v = fdot r0 + gdot v0`` (straight-line: vectorized; the result
    overwrites the components), then the scatter of every column, through the
    safeguarded loop (:func:`_fg_universal_safe`) for the columns with ``W[_UOK] == 0``."""
    for k in range(nu):
        rx, ry, rz, vx, vy, vz = W[_URX, k], W[_URY, k], W[_URZ, k], W[_UVX, k], W[_UVY, k], W[_UVZ, k]
        f, g, fd, gd = _uni_fg_dd(
            rx, ry, rz, vx, vy, vz,
            W[_RN, k], W[_UCHI, k], W[_UZ, k], W[_UC4, k], W[_UC5, k], W[_UDT, k], W[_UMU, k], W[_USQMU, k],
        )
        W[_URX, k] = f * rx + g * vx  # the arithmetic of _store
        W[_URY, k] = f * ry + g * vy
        W[_URZ, k] = f * rz + g * vz
        W[_UVX, k] = fd * rx + gd * vx
        W[_UVY, k] = fd * ry + gd * vy
        W[_UVZ, k] = fd * rz + gd * vz
    for k in range(nu):
        i = idx[k]
        if W[_UOK, k] == 0.0:
            f, g, fd, gd = _fg_universal_safe(W[_RN, k], W[_USG, k], W[_Q, k], W[_ALPHA, k], W[_UDT, k], W[_USQMU, k])
            _store(r0, v0, r, v, i, f, g, fd, gd)
        else:
            r[i, 0], r[i, 1], r[i, 2] = W[_URX, k], W[_URY, k], W[_URZ, k]
            v[i, 0], v[i, 1], v[i, 2] = W[_UVX, k], W[_UVY, k], W[_UVZ, k]


@jit(inline="always")
def _propagate_block(r0, v0, dt, mu, r, v, lo, hi, idx, W, idxh, WH, idxu, WU):
    """States ``lo:hi``: ellipses (``idx, W``) gathered and solved in vectorized passes
    (:func:`_ell_passes`), hyperbolas (:func:`_hyp_passes`) and near-parabolic states
    (:func:`_uni_passes`) likewise, the rest (identity, NaN; ellipses with a phase
    beyond 2**52 rad) directly."""
    m = 0
    mh = 0
    mu_ = 0
    for i in range(lo, hi):
        rx, ry, rz = r0[i, 0], r0[i, 1], r0[i, 2]
        vx, vy, vz = v0[i, 0], v0[i, 1], v0[i, 2]
        kind, rn, sig, q, alpha, n = _classify(rx, ry, rz, vx, vy, vz, dt[i], mu[i])
        if kind == 2 and abs(n * dt[i]) < HUGE_ANGLE:
            idx[m] = i
            W[_RN, m], W[_SIG, m], W[_Q, m], W[_ALPHA, m], W[_N, m] = rn, sig, q, alpha, n
            W[_DT, m], W[_MU, m] = dt[i], mu[i]
            m += 1
        elif kind == 3:
            hx = ry * vz - rz * vy
            hy = rz * vx - rx * vz
            hz = rx * vy - ry * vx
            idxh[mh] = i
            WH[_RN, mh], WH[_SIG, mh], WH[_Q, mh], WH[_ALPHA, mh], WH[_N, mh] = rn, sig, q, alpha, n
            WH[_H2, mh], WH[_MU, mh], WH[_HDT, mh] = hx * hx + hy * hy + hz * hz, mu[i], dt[i]
            mh += 1
        elif kind == 4:
            idxu[mu_] = i
            WU[_RN, mu_], WU[_SIG, mu_], WU[_Q, mu_], WU[_ALPHA, mu_] = rn, sig, q, alpha
            WU[_UDT, mu_], WU[_UMU, mu_] = dt[i], mu[i]
            WU[_URX, mu_], WU[_URY, mu_], WU[_URZ, mu_] = rx, ry, rz
            WU[_UVX, mu_], WU[_UVY, mu_], WU[_UVZ, mu_] = vx, vy, vz
            mu_ += 1
        else:
            f, g, fd, gd = _dispatch(kind, rn, sig, q, alpha, n, rx, ry, rz, vx, vy, vz, dt[i], mu[i])
            _store(r0, v0, r, v, i, f, g, fd, gd)
    _ell_passes(W, m, idx, r0, v0, r, v)
    _hyp_passes(WH, mh, idxh, r0, v0, r, v)
    _uni_passes(WU, mu_, idxu, r0, v0, r, v)


@jit
def _hyp_fast_pass(W, nh):
    """Pass 2 of :func:`_hyp_passes`: straight-line, LLVM vectorizes it (packed ymm
    arithmetic in ``_hyp_fast_pass.inspect_asm``)."""
    for k in range(nh):
        ok, F1, sh1, chm1_1 = _hyp_solve_fast(W[_M1, k], W[_HE, k], W[_EM1, k])
        W[_HOK, k] = 1.0 if ok else 0.0
        W[_F1, k] = F1
        W[_SH1, k] = sh1
        W[_CHM1, k] = chm1_1


@jit
def _hyp_passes(W, nh, idx, r0, v0, r, v):
    """The hyperbolas of a block (columns ``0:nh`` of their work array ``W``) in passes over all of them.

    Pass 1: invariants and ``F0 = asinh`` (libm: scalar, but independent
    iterations the core overlaps); pass 2: starter and straight-line solve
    (:func:`_hyp_solve_fast`: own log, cube root and exp), which LLVM
    vectorizes; pass 3: the safeguarded solver where its check failed; pass 4:
    f, g and store.  Bit-identical to :func:`_fg_hyperbolic` on each state.
    """
    for k in range(nh):
        sqb, p, Ch, Sh, e, em1, m, F0, M1 = _hyp_setup(W[_SIG, k], W[_Q, k], -W[_ALPHA, k], W[_N, k], W[_HDT, k], W[_MU, k], W[_H2, k])
        W[_SQB, k], W[_P, k], W[_CH, k], W[_SH, k], W[_HE, k] = sqb, p, Ch, Sh, e
        W[_EM1, k], W[_M, k], W[_F0, k], W[_M1, k] = em1, m, F0, M1
    _hyp_fast_pass(W, nh)
    for k in range(nh):
        if W[_HOK, k] == 0.0:
            W[_F1, k], W[_SH1, k], W[_CHM1, k] = solve_kepler_hyperbolic_kernel(W[_M1, k], W[_HE, k], W[_EM1, k])
    for k in range(nh):
        f, g, fd, gd = _hyp_fg(
            W[_RN, k], W[_SQB, k], W[_P, k], W[_CH, k], W[_SH, k], W[_HE, k], W[_EM1, k], W[_M, k], W[_F0, k],
            -W[_ALPHA, k], W[_N, k], W[_F1, k], W[_SH1, k], W[_CHM1, k],
        )
        _store(r0, v0, r, v, idx[k], f, g, fd, gd)


@jit
def _propagate_range(r0, v0, dt, mu, r, v, lo, hi, idx, W, idxh, WH, idxu, WU):
    """States ``lo:hi`` block by block (one compiled body shared by the serial and parallel loops)."""
    for blo in range(lo, hi, _BLOCK):
        _propagate_block(r0, v0, dt, mu, r, v, blo, min(blo + _BLOCK, hi), idx, W, idxh, WH, idxu, WU)


@jit
def _block_workspace():
    """Scratch arrays of one block: ellipse, hyperbola and universal-variable gathers and work rows."""
    return (np.empty(_BLOCK, dtype=np.int64), np.empty((_NW, _BLOCK)), np.empty(_BLOCK, dtype=np.int64),
            np.empty((_NWH, _BLOCK)), np.empty(_BLOCK, dtype=np.int64), np.empty((_NWU, _BLOCK + _WU_PAD)))


@jit
def propagate_rows(r0, v0, dt, mu, r, v):
    idx, W, idxh, WH, idxu, WU = _block_workspace()
    _propagate_range(r0, v0, dt, mu, r, v, 0, r0.shape[0], idx, W, idxh, WH, idxu, WU)


_CHUNK = 8 * _BLOCK  # states per parallel task (one block per task below 16 chunks)
PROPAGATE_PARALLEL_MIN = 4 * _BLOCK  # from 2048 states the two-thread kernel is ~2x faster (measured)


@pjit
def _propagate_loop_par(r0, v0, dt, mu, r, v):
    n = r0.shape[0]
    chunk = _CHUNK if n >= 16 * _CHUNK else _BLOCK  # small batches: one block per task
    nchunks = (n + chunk - 1) // chunk
    for c in prange(nchunks):
        idx, W, idxh, WH, idxu, WU = _block_workspace()
        lo = np.int64(c) * chunk  # prange's index is unsigned: keep one int64 specialization
        _propagate_range(r0, v0, dt, mu, r, v, lo, min(lo + chunk, n), idx, W, idxh, WH, idxu, WU)


@jit
def formulation_rows(r0, v0, dt, mu, out):
    """Formulation of each state (:func:`_classify`'s kind), for benchmarks and tests."""
    for i in range(r0.shape[0]):
        out[i] = _classify(r0[i, 0], r0[i, 1], r0[i, 2], v0[i, 0], v0[i, 1], v0[i, 2], dt[i], mu[i])[0]


@jit
def _propagate_single(r0, v0, dt, mu):
    """One state, no broadcasting: the cheap path for scalar calls."""
    r = np.empty(3)
    v = np.empty(3)
    f, g, fd, gd = lagrange_coefficients_scalar(r0[0], r0[1], r0[2], v0[0], v0[1], v0[2], dt, mu)
    for j in range(3):
        r[j] = f * r0[j] + g * v0[j]
        v[j] = fd * r0[j] + gd * v0[j]
    return r, v


@jit
def propagate_scalar_kernel(rx, ry, rz, vx, vy, vz, dt, mu):
    """The compiled body of :func:`propagate_scalar`, for other numba code (a controller's
    step calls it without any call overhead).  The same arguments and result; once
    :func:`propagate_scalar` has run in the process it holds the float64 specialization only
    and converts other real types to it, which compiled callers should pass anyway."""
    f, g, fd, gd = lagrange_coefficients_scalar(rx, ry, rz, vx, vy, vz, dt, mu)
    return (f * rx + g * vx, f * ry + g * vy, f * rz + g * vz,
            fd * rx + gd * vx, fd * ry + gd * vy, fd * rz + gd * vz)


_SCALAR_ARGS = ("rx", "ry", "rz", "vx", "vy", "vz", "dt", "mu")


def _scalar_kernel_first_call(*args):
    """The first call of :func:`propagate_scalar` in a process: the kernel's float64
    specialization (from numba's cache), then no further compilation, so numba's dispatch
    converts ints, float32 and the like to it instead of compiling a specialization for each
    mix of types (11 s each, and a 60-line TypingError for ints)."""
    global _scalar_kernel
    propagate_scalar_kernel(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0)  # float64 x 8: compiled or loaded
    propagate_scalar_kernel.disable_compile()
    _scalar_kernel = propagate_scalar_kernel
    return propagate_scalar_kernel(*args)


_scalar_kernel = _scalar_kernel_first_call


def _scalar_floats(args) -> list[float]:
    """The arguments numba's dispatch refused, as floats: real numbers it does not convert
    (a 0-d array, a ``Fraction``); :class:`astrodyn.inputs.NonRealInputError` naming the first
    argument that is not one (``TypeError`` for an array of more than one number)."""
    out = []
    for name, x in zip(_SCALAR_ARGS, args):
        if x is None or isinstance(x, (complex, np.complexfloating, str, bytes)):
            got = "None" if x is None else type(x).__name__
            raise NonRealInputError(f"propagate_scalar: {name}: expected a real number, got {got}")
        if np.ndim(x) != 0:
            raise TypeError(f"propagate_scalar: {name}: expected a real number, got {type(x).__name__} "
                            f"of shape {np.shape(x)}")
        try:
            out.append(float(x))
        except (TypeError, ValueError):
            raise NonRealInputError(f"propagate_scalar: {name}: expected a real number, "
                                    f"got {type(x).__name__}") from None
    return out


def propagate_scalar(rx, ry, rz, vx, vy, vz, dt, mu):
    """One state by ``dt`` with scalars in and out: ``(x, y, z, vx, vy, vz)`` [m, m/s].

    The same exact propagation as :func:`propagate` (bit for bit its single-state
    result) without arrays: ``r0 = (rx, ry, rz)`` [m], ``v0 = (vx, vy, vz)`` [m/s],
    ``dt`` [s], ``mu`` [m^3/s^2].  About 0.5 us from Python (a third of a
    :func:`propagate` call, which boxes two arrays); other compiled code (a controller's
    step) calls :func:`propagate_scalar_kernel`, free of call overhead.  Invalid values
    (NaN/inf, ``r0 = 0``, ``mu <= 0``) give NaN; no exception.

    Any real scalars: Python and numpy ints and floats of any width are converted to
    float64 by numba's dispatch (one compiled specialization serves every mix; bools, which
    numba converts too, count as 0 and 1 here, unlike in the array functions); 0-d arrays
    and other real numbers through ``float()``.  ``None``, complex numbers and strings raise
    :class:`astrodyn.inputs.NonRealInputError`, arrays ``TypeError``, naming the argument.
    This is the one exception to the core's input rule (:mod:`astrodyn.inputs`): the
    compiled scalar call converts what numba converts.
    """
    try:
        return _scalar_kernel(rx, ry, rz, vx, vy, vz, dt, mu)
    except TypeError:  # numba's dispatch: "No matching definition for argument type(s) ..."
        pass
    return _scalar_kernel(*_scalar_floats((rx, ry, rz, vx, vy, vz, dt, mu)))


@jit
def _lagrange_loop(r0, v0, dt, mu, out):
    for i in range(r0.shape[0]):
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = lagrange_coefficients_scalar(
            r0[i, 0], r0[i, 1], r0[i, 2], v0[i, 0], v0[i, 1], v0[i, 2], dt[i], mu[i]
        )


# ---------------------------------------------------------------------------
# public API
# ---------------------------------------------------------------------------
def _state_vector(x, name, who, unit):
    """``x`` as float64 ``(..., 3)`` (:func:`astrodyn.inputs.real_array`), else an error naming it."""
    x = real_array(x, name, who)
    if x.ndim == 0 or x.shape[-1] != 3:
        raise ValueError(f"{who}: {name} must have shape (..., 3) [{unit}]; got shape {x.shape}")
    return x


def _prepare(r0, v0, dt, mu, who):
    """Validate and broadcast; returns the leading shape and flat contiguous arrays."""
    r0 = _state_vector(r0, "r0", who, "m")
    v0 = _state_vector(v0, "v0", who, "m/s")
    dt = real_array(dt, "dt", who)
    mu = real_array(mu, "mu", who)
    if np.any(mu <= 0.0):  # NaN mu is let through and gives NaN
        raise ValueError(f"{who}: mu must be > 0 [m^3/s^2]; got {float(mu[mu <= 0.0].ravel()[0])!r}")
    lead = broadcast_named(who, ("r0", r0, 1), ("v0", v0, 1), ("dt", dt, 0), ("mu", mu, 0))
    n = math.prod(lead)
    r0f = np.ascontiguousarray(np.broadcast_to(r0, lead + (3,))).reshape(n, 3)
    v0f = np.ascontiguousarray(np.broadcast_to(v0, lead + (3,))).reshape(n, 3)
    dtf = np.ascontiguousarray(np.broadcast_to(dt, lead)).reshape(n)
    muf = np.ascontiguousarray(np.broadcast_to(mu, lead)).reshape(n)
    return lead, r0f, v0f, dtf, muf


def propagate(r0, v0, dt, mu):
    """Two-body (Kepler) propagation of position and velocity by ``dt``.

    Parameters
    ----------
    r0 : array_like, shape (..., 3)
        Initial position [m] in any inertial frame centred on the primary.
    v0 : array_like, shape (..., 3)
        Initial velocity [m/s], same frame.
    dt : array_like
        Time of flight [s], positive or negative, any number of revolutions;
        scalar or broadcastable to the leading shape.
    mu : array_like
        Gravitational parameter ``G M`` [m^3/s^2] (> 0), scalar or broadcastable.

    Returns
    -------
    r, v : ndarray, shape (lead..., 3)
        Position [m] and velocity [m/s] after ``dt``, same frame; ``(3,)`` for a
        single state.  Accurate to the problem's conditioning on every conic
        (module doc; tests/test_propagate.py checks against a 50-digit mpmath
        reference).  NaN rows where an input of that state is NaN/inf or
        ``r0 = 0``.

    Raises
    ------
    ValueError
        Wrong shapes (names the argument) or a finite ``mu <= 0``.
    TypeError
        An argument that is not real numbers (``None``, complex, str, bool, an object array
        holding anything but ints and floats): :class:`astrodyn.inputs.NonRealInputError`
        naming it.
    """
    if type(dt) is float and type(mu) is float:  # fast path for one state (a few microseconds)
        r0a = real_array(r0, "r0", "propagate")
        v0a = real_array(v0, "v0", "propagate")
        if r0a.shape == (3,) and v0a.shape == (3,) and mu > 0.0:
            return _propagate_single(r0a, v0a, dt, mu)
    lead, r0f, v0f, dtf, muf = _prepare(r0, v0, dt, mu, "propagate")
    r = np.empty_like(r0f)
    v = np.empty_like(v0f)
    (_propagate_loop_par if r0f.shape[0] >= PROPAGATE_PARALLEL_MIN else propagate_rows)(r0f, v0f, dtf, muf, r, v)
    return r.reshape(lead + (3,)), v.reshape(lead + (3,))


def lagrange_coefficients(r0, v0, dt, mu):
    """Lagrange coefficients ``f, g, fdot, gdot`` of the two-body flow.

    ``r = f r0 + g v0`` and ``v = fdot r0 + gdot v0`` (Vallado 4th ed. eqs.
    2-65..2-68, Curtis eqs. 3.69).  ``f, gdot`` dimensionless, ``g`` [s],
    ``fdot`` [1/s].  Inputs as in :func:`propagate`; each output has the
    leading shape (floats for a single state).  ``f gdot - fdot g = 1``.
    """
    lead, r0f, v0f, dtf, muf = _prepare(r0, v0, dt, mu, "lagrange_coefficients")
    out = np.empty((r0f.shape[0], 4))
    _lagrange_loop(r0f, v0f, dtf, muf, out)
    out = out.reshape(lead + (4,))
    f, g, fdot, gdot = (out[..., k] for k in range(4))
    if not lead:
        return float(f), float(g), float(fdot), float(gdot)
    return f, g, fdot, gdot
