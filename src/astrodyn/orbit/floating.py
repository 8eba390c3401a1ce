"""Floating-point toolkit of the orbit kernels: exact transformations, range reduction,
cancellation-free series and straight-line elementary functions, all float64, no fast-math.

Shared by :mod:`astrodyn.orbit.kepler` (Kepler's equation), :mod:`astrodyn.orbit.universal`
(propagation on every conic) and :mod:`astrodyn.orbit.elements`.  Every function here is a
numba kernel (``inline="always"`` unless noted) callable from other compiled code; every
one is tested against mpmath in ``tests/test_kepler.py`` (directly or through the solvers).

* **Error-free transformations.**  :func:`two_sum` (Knuth) and :func:`two_prod` (Dekker
  with Veltkamp splitting, no FMA needed): ``s + t`` equals the exact sum / product.
  :func:`fma` is LLVM's fused multiply-add (one rounding; exact either in hardware or
  in the C library, never fast-math), :func:`two_prod_fma` the exact product by it in
  two operations, :func:`fast_two_sum` Dekker's sum for ordered operands and
  :func:`dot3_dd` a three-term dot product in double-double (Ogita-Rump-Oishi Dot2).
* **Range reduction.**  :func:`reduce_2pi` reduces a double-double angle to ``[-pi, pi]``
  by Cody-Waite reduction with ``2 pi = TWO_PI_1 + TWO_PI_2 + TWO_PI_3`` (about 160 bits)
  and exact products, so the remainder carries a low word; it adds no error beyond one
  rounding for ``|M| < HUGE_ANGLE = 2**52`` (plain ``fmod(M, float(2 pi))`` drifts by
  ``N x 2.4e-16`` after ``N`` revolutions).  :func:`reduce_2pi_core` is its straight-line
  (vectorizable) body.
* **Cancellation-free pieces.**  :func:`x_minus_sin` (``x - sin x``), :func:`one_minus_cos`,
  :func:`sinh_parts` (``sinh x, cosh x - 1, sinh x - x``) by series below ``|x| = 1``;
  :func:`rotate_sincos` moves a known sine and cosine by a small angle without libm.
* **Straight-line elementary functions** (``*_vec``: selects instead of branches, no libm
  call, so LLVM vectorizes loops over many states; the scalar path uses the same code, so
  vectorized and scalar results are bit-identical): :func:`sincos_vec` (fdlibm kernels,
  one ulp for ``|x| < 1e5``), :func:`atan2_vec` (two ulp), :func:`exp_vec` (fdlibm e_exp,
  one ulp for ``|x| <= 708``), :func:`log_vec`, :func:`sinh_parts_vec`,
  :func:`asinh_upper_vec`; :func:`cbrt_start` is a cube-root starter (1e-14 relative).
* :func:`asinh_upper` / :func:`asinh_upper_vec` are upper bounds of ``asinh`` (the
  hyperbolic Kepler starters need bounds from above).
"""

from __future__ import annotations

import math

import numpy as np
from numba import types
from numba.extending import intrinsic

from astrodyn.jit import jit

EPS = 2.220446049250313e-16

# 2*pi = TWO_PI_1 + TWO_PI_2 + TWO_PI_3 to about 160 bits (mpmath, 60 digits).
TWO_PI_1 = 6.283185307179586
TWO_PI_2 = 2.4492935982947064e-16
TWO_PI_3 = -5.989539619436679e-33
PI = math.pi
_SPLIT = 134217729.0  # 2**27 + 1, Veltkamp splitter
# reciprocals of constants: without fast-math, x / 6.0 stays a (slow) division
INV6 = 1.0 / 6.0
INV24 = 1.0 / 24.0
INV_TWO_PI = 1.0 / TWO_PI_1
LN2 = math.log(2.0)
_CBRT_B1 = 715094163  # fdlibm s_cbrt.c: high word of x / 3 + B1 ~ high word of cbrt x
HUGE_ANGLE = 2.0**52  # [rad] above this the float64 phase is not resolved (see reduce_2pi)

# Taylor coefficients 1/(2k+1)! for k = 1..10: x - sin x = sum (-1)^(k+1) x^(2k+1)/(2k+1)!
INV_ODD_FACT = (
    1.0 / 6.0,
    1.0 / 120.0,
    1.0 / 5040.0,
    1.0 / 362880.0,
    1.0 / 39916800.0,
    1.0 / 6227020800.0,
    1.0 / 1307674368000.0,
    1.0 / 355687428096000.0,
    1.0 / 121645100408832000.0,
    1.0 / 51090942171709440000.0,
)
# 1/(2k+2)! for k = 0..9: 1 - cos x = sum (-1)^k x^(2k+2)/(2k+2)!
INV_EVEN_FACT = (
    1.0 / 2.0,
    1.0 / 24.0,
    1.0 / 720.0,
    1.0 / 40320.0,
    1.0 / 3628800.0,
    1.0 / 479001600.0,
    1.0 / 87178291200.0,
    1.0 / 20922789888000.0,
    1.0 / 6402373705728000.0,
    1.0 / 2432902008176640000.0,
)




# ---------------------------------------------------------------------------
# error-free transformations and range reduction
# ---------------------------------------------------------------------------
@jit(inline="always")
def two_sum(a, b):
    """Knuth's TwoSum: ``s + t == a + b`` exactly."""
    s = a + b
    bb = s - a
    t = (a - (s - bb)) + (b - bb)
    return s, t


@intrinsic
def _fma_intrinsic(typingctx, a, b, c):
    """LLVM's ``llvm.fma.f64``: ``a * b + c`` with one rounding (a hardware FMA where the CPU has one,
    else the C library's correctly rounded ``fma``).  Not fast-math: the result is the exactly
    rounded value either way, so vectorized and scalar code give the same bits."""
    if not (a == types.float64 and b == types.float64 and c == types.float64):
        return None
    sig = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        return builder.fma(*args)

    return sig, codegen


@jit(inline="always")
def fma(a, b, c):
    """``a * b + c`` rounded once (float64 arguments)."""
    return _fma_intrinsic(a, b, c)


@jit(inline="always")
def two_prod_fma(a, b):
    """``p + t == a * b`` exactly by one multiplication and one :func:`fma` (same result as
    :func:`two_prod` while ``a * b`` neither overflows nor underflows)."""
    p = a * b
    return p, fma(a, b, -p)


@jit(inline="always")
def fast_two_sum(a, b):
    """``s + t == a + b`` exactly, for ``|a| >= |b|`` (or ``a = 0``) (Dekker)."""
    s = a + b
    return s, b - (s - a)


@jit(inline="always")
def dot3_dd(ax, ay, az, bx, by, bz):
    """``ax bx + ay by + az bz`` as an unnormalized double-double ``hi + lo`` (Ogita-Rump-Oishi
    Dot2: as accurate as the sum in twice the working precision; ``hi`` is the float64 sum of
    the rounded products, ``lo`` the sum of all the rounding errors, so ``|lo| <= ~2 eps |hi|``
    unless the sum cancels)."""
    p1, e1 = two_prod_fma(ax, bx)
    p2, e2 = two_prod_fma(ay, by)
    p3, e3 = two_prod_fma(az, bz)
    s, t1 = two_sum(p1, p2)
    s, t2 = two_sum(s, p3)
    return s, (e1 + e2 + e3) + (t1 + t2)


@jit(inline="always")
def two_prod(a, b):
    """Dekker's product with Veltkamp splitting: ``p + t == a * b`` exactly (no FMA needed).

    Valid while ``|a|, |b| < 1e290`` (the splitter must not overflow).
    """
    p = a * b
    ca = _SPLIT * a
    ah = ca - (ca - a)
    al = a - ah
    cb = _SPLIT * b
    bh = cb - (cb - b)
    bl = b - bh
    t = ((ah * bh - p) + ah * bl + al * bh) + al * bl
    return p, t


@jit(inline="always")
def reduce_2pi_core(hi, lo):
    """:func:`reduce_2pi` for ``|hi| < HUGE_ANGLE``: straight-line code (selects), vectorizable.

    For ``|hi| <= pi`` (``k = 0``) it returns ``two_sum(hi, lo)``.
    """
    k = np.floor(hi * INV_TWO_PI + 0.5)
    p1, e1 = two_prod(k, TWO_PI_1)
    s = hi - p1  # exact (Sterbenz): p1 is within a factor 2 of hi
    p2, e2 = two_prod(k, TWO_PI_2)
    s, t = two_sum(s, -p2)
    t = t + (lo - e1 - e2 - k * TWO_PI_3)
    s, t = two_sum(s, t)
    # one more wrap if the floor landed on the wrong side (rounding of hi / 2 pi)
    up = s > PI
    down = s < -PI
    w1 = -TWO_PI_1 if up else TWO_PI_1
    w2 = -TWO_PI_2 if up else TWO_PI_2
    sw, u = two_sum(s, w1)
    sw, tw = two_sum(sw, t + u + w2)
    wrap = up | down
    k = k + 1.0 if up else (k - 1.0 if down else k)
    return k, (sw if wrap else s), (tw if wrap else t)


@jit
def reduce_2pi(hi, lo):
    """Reduce the double-double angle ``hi + lo`` [rad] to ``[-pi, pi]``.

    Cody-Waite reduction with ``2 pi`` in three parts and exact products.
    Returns ``(k, rh, rl)`` with ``hi + lo = k 2 pi + rh + rl`` (``rh + rl``
    normalized, ``|rh| <= pi`` up to rounding).  Exact to about 1e-32
    absolute for ``|hi| < 2**52``.  Beyond that one ulp of the angle exceeds
    half a radian, the phase carries no information, and the remainder is
    ``fmod(hi, float(2 pi))`` (still a point on the orbit, never NaN).
    """
    if not (abs(hi) < HUGE_ANGLE):
        s = np.fmod(hi, TWO_PI_1)  # exact remainder; NaN for inf/NaN input
        if s > PI:
            s -= TWO_PI_1
        elif s < -PI:
            s += TWO_PI_1
        return (hi - s) * INV_TWO_PI, s, 0.0
    return reduce_2pi_core(hi, lo)


# ---------------------------------------------------------------------------
# cancellation-free pieces
# ---------------------------------------------------------------------------
@jit(inline="always")
def odd_series(x, sign):
    """``sum_{k>=1} sign^(k+1) x^(2k+1) / (2k+1)!`` through ``x^21``, for ``|x| < 1``.

    ``sign = -1``: ``x - sin x``; ``sign = +1``: ``sinh x - x``.  Estrin's scheme
    in ``y = sign x^2`` (short dependency chain; the terms fall fast enough that
    its rounding stays within an ulp or two of the Horner form).
    """
    c = INV_ODD_FACT
    x2 = x * x
    y = sign * x2
    y2 = y * y
    y4 = y2 * y2
    p01 = c[0] + c[1] * y
    p23 = c[2] + c[3] * y
    p45 = c[4] + c[5] * y
    p67 = c[6] + c[7] * y
    p89 = c[8] + c[9] * y
    acc = (p01 + p23 * y2) + (p45 + p67 * y2) * y4 + p89 * (y4 * y4)
    return x * x2 * acc


@jit(inline="always")
def x_minus_sin(x, s):
    """``x - sin x`` without cancellation; ``s = sin x`` already known (used for |x| >= 1).

    Series through x^21 for |x| < 1 (truncation < 1e-19 relative).
    """
    if abs(x) < 1.0:
        return odd_series(x, -1.0)
    return x - s


@jit(inline="always")
def one_minus_cos(s, c):
    """``1 - cos x`` from ``s = sin x`` and ``c = cos x`` without cancellation."""
    if c > 0.0:
        return s * s / (1.0 + c)
    return 1.0 - c


@jit(inline="always")
def sinh_parts(x):
    """Return ``(sinh x, cosh x - 1, sinh x - x)`` accurate to a few ulp each."""
    if abs(x) < 1.0:
        shmx = odd_series(x, 1.0)
        sh = x + shmx
        chm1 = sh * sh / (1.0 + math.sqrt(1.0 + sh * sh))
        return sh, chm1, shmx
    if abs(x) > 700.0:
        # exp(x) overflows above 709.78 while sinh x stays finite up to 710.47:
        # sinh x = (exp(x/2) / 2) exp(x/2) (x/2 exact; exp(-x) is below 1e-304 relative)
        h = math.exp(0.5 * abs(x))
        ch = (0.5 * h) * h
        sh = math.copysign(ch, x)
        return sh, ch, sh - x
    ex = math.exp(x)
    iex = 1.0 / ex
    sh = 0.5 * (ex - iex)
    return sh, 0.5 * (ex + iex) - 1.0, sh - x


@jit(inline="always")
def sinh_parts_vec(x):
    """:func:`sinh_parts` for ``|x| <= 700`` as straight-line code with the own :func:`exp_vec`.

    Both forms are evaluated and one is selected (the series below 1, the
    exponentials above), so loops of it vectorize.  Beyond 700 the caller must
    not use it (it returns finite garbage there).
    """
    shmx_s = odd_series(x, 1.0)
    sh_s = x + shmx_s
    chm1_s = sh_s * sh_s / (1.0 + math.sqrt(1.0 + sh_s * sh_s))
    ex = exp_vec(x if abs(x) <= 700.0 else 0.0)
    iex = 1.0 / ex
    sh_e = 0.5 * (ex - iex)
    small = abs(x) < 1.0
    sh = sh_s if small else sh_e
    chm1 = chm1_s if small else 0.5 * (ex + iex) - 1.0
    shmx = shmx_s if small else sh_e - x
    return sh, chm1, shmx


# ---------------------------------------------------------------------------
# own sin/cos and atan2 kernels: straight-line code (selects, no libm call) so
# that LLVM can vectorize loops over many states; the same functions serve the
# scalar path, so vectorized and scalar results are bit-identical
# ---------------------------------------------------------------------------
# pi/2 = _PIO2_1 + _PIO2_2 + _PIO2_3: 33 + 33 bits and the rest (mpmath, 60 digits), so
# k * _PIO2_1 and k * _PIO2_2 are exact for |k| < 2**20 (Cody-Waite)
_PIO2_1 = 1.5707963267341256
_PIO2_2 = 6.077100506303966e-11
_PIO2_3 = 2.0222662487959506e-21
_TWO_OVER_PI = 2.0 / PI
# sin r = r + r^3 (S1 + r^2 (S2 + ...)) and cos r = 1 - r^2/2 + r^4 (C1 + ...) on
# |r| <= pi/4: the minimax coefficients of fdlibm's k_sin.c / k_cos.c (Sun
# Microsystems 1993; error below one ulp there), evaluated as in those kernels
# with the low word of the reduced argument
_S1 = -1.66666666666666324348e-01
_S2 = 8.33333333332248946124e-03
_S3 = -1.98412698298579493134e-04
_S4 = 2.75573137070700676789e-06
_S5 = -2.50507602534068634195e-08
_S6 = 1.58969099521155010221e-10
_C1 = 4.16666666666666019037e-02
_C2 = -1.38888888888741095749e-03
_C3 = 2.48015872894767294178e-05
_C4 = -2.75573143513906633035e-07
_C5 = 2.08757232129817482790e-09
_C6 = -1.13596475577881948265e-11
# atan u = u + u z P(z), z = u^2 <= tan(pi/8)^2: least-squares fit at 60 Chebyshev
# nodes in 60-digit mpmath (relative error 2.2e-16 over the range, incl. evaluation)
_ATAN_P = (
    -0.3333333333333333,
    0.19999999999995646,
    -0.1428571428469054,
    0.11111111017032477,
    -0.09090904644927628,
    0.0769218463484144,
    -0.06664530458067883,
    0.05858303869105912,
    -0.05086213230646851,
    0.03925249039424092,
    -0.01920104962575966,
)
_TAN_PI8 = 0.41421356237309503  # tan(pi/8)
_PIO4 = PI / 4.0
_PIO2 = PI / 2.0


@jit(inline="always")
def sincos_vec(x):
    """``(sin x, cos x)`` for ``|x| < 1e5`` [rad], within one ulp (tests/test_kepler.py vs mpmath).

    Cody-Waite reduction ``x = k pi/2 + r`` with ``pi/2`` in three parts (the
    reduced argument carried as ``rh + rl``, exact to ~1e-32), fdlibm's kernels on
    ``|r| <= pi/4``, the quadrant ``k mod 4`` by selects.  No branch and no libm
    call: loops of it vectorize.  Beyond 1e5 it still returns a point on the unit
    circle but the reduction loses digits (the propagator never calls it there).
    """
    k = np.floor(x * _TWO_OVER_PI + 0.5)  # np.floor stays float (math.floor goes through int64)
    t = x - k * _PIO2_1  # exact
    w = k * _PIO2_2  # exact
    rh = t - w
    rl = ((t - rh) - w) - k * _PIO2_3
    z = rh * rh
    # sin(rh + rl) (k_sin.c with the tail)
    rs = _S2 + z * (_S3 + z * (_S4 + z * (_S5 + z * _S6)))
    v = z * rh
    sn = rh - ((z * (0.5 * rl - v * rs) - rl) - v * _S1)
    # cos(rh + rl) (k_cos.c, 2004 form)
    rc = z * (_C1 + z * (_C2 + z * (_C3 + z * (_C4 + z * (_C5 + z * _C6)))))
    hz = 0.5 * z
    w1 = 1.0 - hz
    cs = w1 + (((1.0 - w1) - hz) + (z * rc - rh * rl))
    q = k - 4.0 * np.floor(0.25 * k)  # quadrant 0..3, in floating point (vectorizes on AVX2)
    odd = (q == 1.0) | (q == 3.0)
    s_out = cs if odd else sn
    c_out = sn if odd else cs
    s_out = -s_out if q >= 2.0 else s_out
    c_out = -c_out if (q == 1.0) | (q == 2.0) else c_out
    return s_out, c_out


@jit(inline="always")
def atan2_vec(y, x):
    """``atan2(y, x)`` [rad] in ``[-pi, pi]`` within about two ulp for finite input (0 at the origin).

    Octant reduction to ``u = min/max`` in ``[0, 1]``, ``atan u = pi/4 + atan((u - 1)/(u + 1))``
    above ``tan(pi/8)``, a degree-23 odd polynomial there; quadrant by selects, no
    branch and no libm call (vectorizable).
    """
    ax = abs(x)
    ay = abs(y)
    mx = ax if ax > ay else ay
    mn = ay if ax > ay else ax
    u = mn / mx if mx > 0.0 else 0.0
    big = u > _TAN_PI8
    u = (u - 1.0) / (u + 1.0) if big else u
    z = u * u
    c = _ATAN_P
    p = c[0] + z * (c[1] + z * (c[2] + z * (c[3] + z * (c[4] + z * (c[5] + z * (c[6] + z * (c[7] + z * (c[8] + z * (c[9] + z * c[10])))))))))
    a = u + u * (z * p)
    a = _PIO4 + a if big else a
    a = _PIO2 - a if ay > ax else a
    a = PI - a if x < 0.0 else a
    return -a if y < 0.0 else a


# exp: fdlibm e_exp.c (Sun Microsystems 1993): ln 2 split so that k * _LN2_HI is exact
# for |k| < 2**20, the Remez polynomial P1..P5 of r (e^r + 1)/(e^r - 1) on |r| <= ln2/2
_LN2_HI = 6.93147180369123816490e-01
_LN2_LO = 1.90821492927058770002e-10
_INV_LN2 = 1.44269504088896338700e00
_EXP_P1 = 1.66666666666666019037e-01
_EXP_P2 = -2.77777777770155933842e-03
_EXP_P3 = 6.61375632143793436117e-05
_EXP_P4 = -1.65339022054652515390e-06
_EXP_P5 = 4.13813679705723846039e-08
_ROUND_MAGIC = 6755399441055744.0  # 1.5 * 2**52: k + magic holds the integer k in its low bits


@jit(inline="always")
def exp_vec(x):
    """``exp x`` for ``|x| <= 708`` within one ulp (tests/test_kepler.py vs mpmath).

    fdlibm's method: ``x = k ln 2 + r`` (Cody-Waite, ``|r| <= ln2 / 2``),
    ``exp r = 1 + 2 r / (R(r) - r)`` with its degree-10 rational form, then
    ``2^k`` built in the exponent bits (``k`` read from ``k + 1.5 * 2^52``: no
    float-to-int conversion, which AVX2 lacks).  No branch and no libm call:
    loops of it vectorize.  Outside the range the result is garbage (callers select).
    """
    k = np.floor(x * _INV_LN2 + 0.5)
    hi = x - k * _LN2_HI  # exact
    lo = k * _LN2_LO
    r = hi - lo
    t = r * r
    c = r - t * (_EXP_P1 + t * (_EXP_P2 + t * (_EXP_P3 + t * (_EXP_P4 + t * _EXP_P5))))
    y = 1.0 - ((lo - (r * c) / (2.0 - c)) - hi)
    kb = np.float64(k + _ROUND_MAGIC).view(np.int64)  # low 52 bits: 2**51 + k
    two_k = np.int64((kb + 1023) << 52).view(np.float64)  # the shift drops the 2**51
    return y * two_k


_SQRT2 = math.sqrt(2.0)
_TWO52 = 4503599627370496.0  # 2**52
# log m = 2 atanh s = 2 (s + s^3/3 + s^5/5 + ...), s = (m - 1)/(m + 1), |s| <= 0.1716:
# 1/(2j+1) through j = 11 (truncation below 1e-18 relative)
_LOG_C = tuple(1.0 / (2 * j + 1) for j in range(1, 12))


@jit(inline="always")
def log_vec(y):
    """``log y`` for finite normal ``y > 0`` within 2 eps (1 + |log y|) (tests vs mpmath).

    ``y = 2^k m`` with ``m`` in ``[sqrt(1/2), sqrt 2)`` from the bit pattern (the
    exponent read as a float without an int-to-float conversion),
    ``log m = 2 atanh((m - 1)/(m + 1))`` by its series, ``k ln 2`` with ``ln 2``
    in two parts.  No branch and no libm call: loops of it vectorize.  Only the
    Kepler starters use it (through :func:`asinh_upper_vec`, which widens it).
    """
    bits = np.float64(y).view(np.int64)
    ef = np.int64(((bits >> 52) & 0x7FF) | 0x4330000000000000).view(np.float64) - _TWO52  # biased exponent
    m = np.int64((bits & 0x000FFFFFFFFFFFFF) | 0x3FF0000000000000).view(np.float64)  # [1, 2)
    big = m > _SQRT2
    m = 0.5 * m if big else m
    k = ef - (1022.0 if big else 1023.0)
    s = (m - 1.0) / (m + 1.0)
    z = s * s
    c = _LOG_C
    p = c[0] + z * (c[1] + z * (c[2] + z * (c[3] + z * (c[4] + z * (c[5] + z * (c[6] + z * (c[7] + z * (c[8] + z * (c[9] + z * c[10])))))))))
    return (k * _LN2_HI + (2.0 * s + 2.0 * s * (z * p))) + k * _LN2_LO


@jit(inline="always")
def cbrt_start(x):
    """Cube root of ``x >= 0`` to about 1e-9 relative, for starters only (no bound property).

    Exponent/3 from the high word of the bit pattern (Kahan's trick as in fdlibm's
    s_cbrt.c, ~5 % error), then two
    Halley steps ``y (y^3 + 2x) / (2 y^3 + x)`` (cubic convergence; measured
    relative error below 1e-14 over 1e-99..1e99).  Straight-line code.  Shorter
    latency than ``x ** (1/3)`` (libm pow), which sits on the critical path of
    every solve; the iteration after the starter removes the 1e-9 anyway.
    """
    # y^3 must neither underflow nor overflow: scale tiny and huge x by 2^-+300
    # (exact) and the root by 2^+-100; 0, inf and NaN return x itself (no branch)
    small = x < 1e-100
    large = x > 1e100
    xs = x * 2.0**300 if small else (x * 2.0**-300 if large else x)
    hi = (np.float64(xs).view(np.int64) >> 32) & 0xFFFFFFFF  # high word (sign, exponent, 20 bits)
    # hi // 3 as a multiply-shift (exact for 32-bit hi; vectorizes, an int64 division does not)
    y = np.int64((((hi * 0xAAAAAAAB) >> 33) + _CBRT_B1) << 32).view(np.float64)
    y3 = y * y * y
    y = y * (y3 + 2.0 * xs) / (2.0 * y3 + xs)
    y3 = y * y * y
    y = y * (y3 + 2.0 * xs) / (2.0 * y3 + xs)
    y = y * 2.0**-100 if small else (y * 2.0**100 if large else y)
    return y if (x > 0.0) & (x < math.inf) else x


@jit(inline="always")
def rotate_sincos(s, c, d):
    """``(sin(x + d), cos(x + d))`` from ``s = sin x``, ``c = cos x`` for ``|d| <= 0.05``.

    Taylor series of ``sin d`` and ``1 - cos d`` (truncation below 1e-19), so
    a small correction needs no further libm call.
    """
    d2 = d * d
    fo = INV_ODD_FACT
    fe = INV_EVEN_FACT
    sd = d - d * d2 * (fo[0] - d2 * (fo[1] - d2 * (fo[2] - d2 * fo[3])))
    omcd = d2 * (fe[0] - d2 * (fe[1] - d2 * (fe[2] - d2 * fe[3])))
    return s + (c * sd - s * omcd), c - (s * sd + c * omcd)



@jit(inline="always")
def asinh_upper(y):
    """An upper bound of ``asinh y`` for ``y >= 0``, within a few ulp (plus 1e-15 absolute).

    ``log(y + sqrt(1 + y^2))`` (one log and one sqrt, about half the latency of
    libm's ``asinh``, which goes through ``log1p``): its absolute error is at most
    about 2 eps from the argument's rounding plus one ulp of the result, so adding
    ``4 eps (1 + L)`` makes it a bound; ``asinh y <= y`` keeps small ``y`` tight.
    Above 1e150 (rare: ``y^2`` would overflow, and ``F`` may sit at the overflow edge
    ``e sinh F ~ 1.8e308`` where a widened bound would overflow the residual) libm's
    ``asinh`` itself, a bound up to its sub-ulp rounding, as before.
    """
    if y >= 1e150:
        return math.asinh(y)
    L = math.log(y + math.sqrt(1.0 + y * y))
    return min(y, L + 4.0 * EPS * (1.0 + L))


@jit(inline="always")
def asinh_upper_vec(y):
    """:func:`asinh_upper` with the own :func:`log_vec` (straight-line; finite ``y >= 0``).

    The own log is within 2 eps (1 + |L|) (tests/test_kepler.py), so the bound
    adds ``8 eps (1 + L)``; above 1e150 ``log y + log 2 + 8 eps (1 + L)`` (a
    valid, slightly loose bound: its callers exclude the overflow edge).
    """
    big = y >= 1e150
    L = log_vec(y * 0.5 if big else y + math.sqrt(1.0 + y * y)) + (2.0 * LN2 if big else 0.0)
    b = L + 8.0 * EPS * (1.0 + L)
    return y if y < b else b


