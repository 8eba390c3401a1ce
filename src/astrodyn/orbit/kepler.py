"""Kepler's equation, elliptic and hyperbolic, solved to the float64 floor.

Elliptic (``0 <= e < 1``): given the mean anomaly ``M`` [rad], find the
eccentric anomaly ``E`` [rad] with ``M = E - e sin E`` (Vallado 4th ed.
eq. 2-4 / Curtis eq. 3.14).  Hyperbolic (``e > 1``): find ``F`` with
``M = e sinh F - F`` (Vallado eq. 2-5 / Curtis eq. 3.40).

How the accuracy is obtained (every piece is exercised by ``tests/test_kepler.py``):

* **Range reduction.** ``M`` is reduced to ``[-pi, pi]`` by Cody-Waite
  reduction with ``2 pi`` split into three float64 parts and exact
  (Dekker/Veltkamp) products, so the remainder carries a double-double low
  word.  The reduction itself adds no error beyond one rounding of the
  remainder for ``|M| < 2**52``; plain ``fmod(M, float(2 pi))`` would drift by
  ``N x 2.4e-16`` after ``N`` revolutions.  The returned ``E`` keeps the
  revolution: ``E = M + (E_red - M_red)``, so ``E - e sin E = M``.
* **Starter.** Markley (1995), "Kepler equation solver", Celest. Mech. Dyn.
  Astr. 63, 101-111: a cubic starter followed by a fifth-order correction
  (about 1e-15 relative already; the inverted Taylor series, of the same
  order as his eqs. 29-31 with one division instead of three), here applied to the cancellation-free
  residual; sine and cosine at the corrected point come from a Taylor
  rotation, so a typical solve makes one sin/cos evaluation (libm in
  ``solve_kepler``; the propagator's vectorized path uses the own straight-line
  kernels ``_sincos`` and ``_atan2`` of this module, tested against mpmath).  For the hyperbola, an upper bound from the
  cubic ``(e - 1) F + e F^3 / 6 = M`` or ``asinh(M / (e - 1))``, tightened by
  one fixed-point step ``F = asinh((M + F) / e)`` (asinh as a widened log + sqrt
  bound, :func:`_asinh_upper`), so Newton/Halley converge monotonically from above;
  two Halley steps and a residual check usually suffice (:func:`_kepler_hyp_fast`).
* **Residual without cancellation.** ``(1 - e) E + e (E - sin E) - M`` with a
  series for ``E - sin E`` when ``|E| < 1`` (and ``(e - 1) F + e (sinh F - F) -
  M`` for the hyperbola); ``1 - e cos E = (1 - e) + e (1 - cos E)``.  The naive
  ``E - e sin E - M`` loses about three digits near ``e -> 1, M -> 0``.
* **Stopping.** Safeguarded (bracketed) Halley/Newton iterations stop when the
  residual is at its own rounding-noise level, not on a step size; at most
  ``MAX_ITER`` iterations, so NaN or pathological inputs never hang.

NaN in ``M`` or ``e`` gives NaN; ``M = +-inf`` gives NaN.  ``e`` outside the
allowed range (finite) raises ``ValueError``.

The scalar kernels (``_reduce_2pi``, ``_solve_diff_ell``, ``_kepler_start``,
``_kepler_hyp_scalar``, ``_x_minus_sin``, ``_sinh_minus_x`` ...) are shared
with :mod:`astrodyn.orbit.universal`.
"""

from __future__ import annotations

import math

import numpy as np

from astrodyn.jit import jit, pjit, prange

__all__ = ["solve_kepler", "solve_kepler_hyperbolic"]

EPS = 2.220446049250313e-16
MAX_ITER = 12
PARALLEL_MIN = 4096  # below this many elements the serial kernel is faster

# 2*pi = TWO_PI_1 + TWO_PI_2 + TWO_PI_3 to about 160 bits (mpmath, 60 digits).
TWO_PI_1 = 6.283185307179586
TWO_PI_2 = 2.4492935982947064e-16
TWO_PI_3 = -5.989539619436679e-33
PI = math.pi
_SPLIT = 134217729.0  # 2**27 + 1, Veltkamp splitter
# reciprocals of constants: without fast-math, x / 6.0 stays a (slow) division
_INV6 = 1.0 / 6.0
_INV24 = 1.0 / 24.0
_INV_PI2_M6 = 1.0 / (PI * PI - 6.0)
_INV_TWO_PI = 1.0 / TWO_PI_1
_LN2 = math.log(2.0)
_CBRT_B1 = 715094163  # fdlibm s_cbrt.c: high word of x / 3 + B1 ~ high word of cbrt x
HUGE_ANGLE = 2.0**52  # [rad] above this the float64 phase is not resolved (see _reduce_2pi)

# Taylor coefficients 1/(2k+1)! for k = 1..10: x - sin x = sum (-1)^(k+1) x^(2k+1)/(2k+1)!
_INV_ODD_FACT = (
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
_INV_EVEN_FACT = (
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
def _two_sum(a, b):
    """Knuth's TwoSum: ``s + t == a + b`` exactly."""
    s = a + b
    bb = s - a
    t = (a - (s - bb)) + (b - bb)
    return s, t


@jit(inline="always")
def _two_prod(a, b):
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
def _reduce_2pi_core(hi, lo):
    """:func:`_reduce_2pi` for ``|hi| < HUGE_ANGLE``: straight-line code (selects), vectorizable.

    For ``|hi| <= pi`` (``k = 0``) it returns ``two_sum(hi, lo)``.
    """
    k = np.floor(hi * _INV_TWO_PI + 0.5)
    p1, e1 = _two_prod(k, TWO_PI_1)
    s = hi - p1  # exact (Sterbenz): p1 is within a factor 2 of hi
    p2, e2 = _two_prod(k, TWO_PI_2)
    s, t = _two_sum(s, -p2)
    t = t + (lo - e1 - e2 - k * TWO_PI_3)
    s, t = _two_sum(s, t)
    # one more wrap if the floor landed on the wrong side (rounding of hi / 2 pi)
    up = s > PI
    down = s < -PI
    w1 = -TWO_PI_1 if up else TWO_PI_1
    w2 = -TWO_PI_2 if up else TWO_PI_2
    sw, u = _two_sum(s, w1)
    sw, tw = _two_sum(sw, t + u + w2)
    wrap = up | down
    k = k + 1.0 if up else (k - 1.0 if down else k)
    return k, (sw if wrap else s), (tw if wrap else t)


@jit
def _reduce_2pi(hi, lo):
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
        return (hi - s) * _INV_TWO_PI, s, 0.0
    return _reduce_2pi_core(hi, lo)


# ---------------------------------------------------------------------------
# cancellation-free pieces
# ---------------------------------------------------------------------------
@jit(inline="always")
def _odd_series(x, sign):
    """``sum_{k>=1} sign^(k+1) x^(2k+1) / (2k+1)!`` through ``x^21``, for ``|x| < 1``.

    ``sign = -1``: ``x - sin x``; ``sign = +1``: ``sinh x - x``.  Estrin's scheme
    in ``y = sign x^2`` (short dependency chain; the terms fall fast enough that
    its rounding stays within an ulp or two of the Horner form).
    """
    c = _INV_ODD_FACT
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
def _x_minus_sin(x, s):
    """``x - sin x`` without cancellation; ``s = sin x`` already known (used for |x| >= 1).

    Series through x^21 for |x| < 1 (truncation < 1e-19 relative).
    """
    if abs(x) < 1.0:
        return _odd_series(x, -1.0)
    return x - s


@jit(inline="always")
def _one_minus_cos(s, c):
    """``1 - cos x`` from ``s = sin x`` and ``c = cos x`` without cancellation."""
    if c > 0.0:
        return s * s / (1.0 + c)
    return 1.0 - c


@jit(inline="always")
def _sinh_parts(x):
    """Return ``(sinh x, cosh x - 1, sinh x - x)`` accurate to a few ulp each."""
    if abs(x) < 1.0:
        shmx = _odd_series(x, 1.0)
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
def _sinh_parts_fast(x):
    """:func:`_sinh_parts` for ``|x| <= 700`` as straight-line code with the own :func:`_exp`.

    Both forms are evaluated and one is selected (the series below 1, the
    exponentials above), so loops of it vectorize.  Beyond 700 the caller must
    not use it (it returns finite garbage there).
    """
    shmx_s = _odd_series(x, 1.0)
    sh_s = x + shmx_s
    chm1_s = sh_s * sh_s / (1.0 + math.sqrt(1.0 + sh_s * sh_s))
    ex = _exp(x if abs(x) <= 700.0 else 0.0)
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
def _sincos(x):
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
def _atan2(y, x):
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
def _exp(x):
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
def _log(y):
    """``log y`` for finite normal ``y > 0`` within 2 eps (1 + |log y|) (tests vs mpmath).

    ``y = 2^k m`` with ``m`` in ``[sqrt(1/2), sqrt 2)`` from the bit pattern (the
    exponent read as a float without an int-to-float conversion),
    ``log m = 2 atanh((m - 1)/(m + 1))`` by its series, ``k ln 2`` with ``ln 2``
    in two parts.  No branch and no libm call: loops of it vectorize.  Only the
    Kepler starters use it (through :func:`_asinh_upper_own`, which widens it).
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
def _cbrt_start(x):
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


# ---------------------------------------------------------------------------
# elliptic
# ---------------------------------------------------------------------------
@jit(inline="always")
def _kepler_start(M, e):
    """Markley (1995) cubic starter for ``M`` in ``[-pi, pi]``, ``0 <= e < 1`` (his eqs. 20-21).

    Relative error below about 1e-3; :func:`_solve_diff_ell` then applies
    a fifth-order correction (the order of his eqs. 29-31) to the cancellation-free
    residual and polishes.
    """
    sgn = -1.0 if M < 0.0 else 1.0
    M = abs(M)
    ome = 1.0 - e
    alpha = (3.0 * PI * PI + 1.6 * PI * (PI - M) / (1.0 + e)) * _INV_PI2_M6
    d = 3.0 * ome + alpha * e
    q = 2.0 * alpha * d * ome - M * M
    r = 3.0 * alpha * d * (d - 1.0 + e) * M + M * M * M
    disc = q * q * q + r * r
    disc = disc if disc > 0.0 else 0.0
    w = _cbrt_start(abs(r) + math.sqrt(disc))
    w = w * w  # (|r| + sqrt(disc))^(2/3)
    den = w * w + w * q + q * q
    E = (2.0 * r * w + M * den) / (d * den) if den > 0.0 else M / d
    return sgn * E


@jit(inline="always")
def _rotate(s, c, d):
    """``(sin(x + d), cos(x + d))`` from ``s = sin x``, ``c = cos x`` for ``|d| <= 0.05``.

    Taylor series of ``sin d`` and ``1 - cos d`` (truncation below 1e-19), so
    a small correction needs no further libm call.
    """
    d2 = d * d
    fo = _INV_ODD_FACT
    fe = _INV_EVEN_FACT
    sd = d - d * d2 * (fo[0] - d2 * (fo[1] - d2 * (fo[2] - d2 * fo[3])))
    omcd = d2 * (fe[0] - d2 * (fe[1] - d2 * (fe[2] - d2 * fe[3])))
    return s + (c * sd - s * omcd), c - (s * sd + c * omcd)


@jit
def _solve_diff_ell(q, C, S, mh, ml, x, lo, hi):
    """Solve the difference form of Kepler's equation for ``x`` [rad].

        q x + C (x - sin x) + S (1 - cos x) = mh + ml

    with ``q = r0 / a = 1 - e cos E0``, ``C = e cos E0``, ``S = e sin E0``
    (``E = E0 + x``; Vallado 4th ed. alg. 8 / Battin sec. 4.5 in terms of the
    eccentric-anomaly change).  ``E0 = 0, q = 1 - e, C = e, S = 0`` is the
    classical equation.  The left side is increasing (derivative ``r / a > 0``);
    ``[lo, hi]`` must bracket the root, ``x`` is the starter.

    Steps: a fifth-order correction (inverted Taylor series of this
    residual, the order of Markley's eqs. 29-31), Newton or bisection when
    that leaves the bracket;
    stop when the residual is at its rounding-noise level.  After a step of at
    most 0.05 rad the new sine and cosine come from :func:`_rotate`.

    Returns ``(x, sin x, cos x, 1 - cos x, r / a)`` consistent to first order.
    """
    s = math.sin(x)
    c = math.cos(x)
    for _ in range(MAX_ITER):
        omc = _one_minus_cos(s, c)
        xms = _x_minus_sin(x, s)
        Fp = q + C * omc + S * s  # r / a
        F = (q * x + C * xms + S * omc - mh) - ml
        noise = EPS * (abs(q * x) + abs(C * xms) + abs(S * omc) + abs(mh))
        F2 = C * s + S * c
        if abs(F) <= 2.0 * noise:
            dx = -F / Fp
            x += dx
            s, c = s + c * dx, c - s * dx
            omc += s * dx
            Fp += F2 * dx
            return x, s, c, omc, Fp
        if F > 0.0:
            hi = min(hi, x)
        else:
            lo = max(lo, x)
        # derivatives: F' = Fp, F'' = F2, F''' = F3, F'''' = -F2
        # Fifth-order step as the inverted Taylor series of F(x + dx) = 0 in
        # u = F / F' (one division instead of Markley's three nested ones, same order):
        #   dx = -u - a2 u^2 - (2 a2^2 - a3) u^3 - (5 a2^3 - 5 a2 a3 + a4) u^4,
        # a_k = F^(k) / (k! F'); Newton when the series would not converge (|a2 u| >= 0.1)
        F3 = C * c - S * s
        inv = 1.0 / Fp
        u = F * inv
        a2u = 0.5 * F2 * inv * u
        if abs(a2u) < 0.1:
            a3u2 = F3 * _INV6 * inv * u * u
            a4u3 = -F2 * _INV24 * inv * u * u * u
            dx = -u * (1.0 + a2u + (2.0 * a2u * a2u - a3u2) + (5.0 * a2u * (a2u * a2u - a3u2) + a4u3))
        else:
            dx = -u
        xn = x + dx
        if not (lo <= xn <= hi):
            xn = x - F / Fp  # Newton, then bisection if even that leaves the bracket
            if not (lo <= xn <= hi):
                xn = 0.5 * (lo + hi)
        if xn == x:
            break
        d = xn - x
        if abs(d) <= 0.05:
            s, c = _rotate(s, c, d)
        else:
            s = math.sin(xn)
            c = math.cos(xn)
        x = xn
    s = math.sin(x)
    c = math.cos(x)
    omc = _one_minus_cos(s, c)
    return x, s, c, omc, q + C * omc + S * s


@jit
def _kepler_ell_scalar(M, e):
    """Eccentric anomaly ``E`` [rad] for any finite ``M`` [rad] and ``0 <= e < 1``."""
    if not (math.isfinite(M) and e >= 0.0 and e < 1.0):
        return math.nan
    k, mh, ml = _reduce_2pi(M, 0.0)
    x0 = _kepler_start(mh, e)
    if mh >= 0.0:
        lo, hi = mh, mh + e
    else:
        lo, hi = mh - e, mh
    x = _solve_diff_ell(1.0 - e, e, 0.0, mh, ml, x0, lo, hi)[0]
    if k == 0.0:
        return x
    return M + ((x - mh) - ml)


@jit
def _kepler_ell_loop(M, e, out):
    for i in range(M.shape[0]):
        out[i] = _kepler_ell_scalar(M[i], e[i])


@pjit
def _kepler_ell_loop_par(M, e, out):
    for i in prange(M.shape[0]):
        out[i] = _kepler_ell_scalar(M[i], e[i])


# ---------------------------------------------------------------------------
# hyperbolic
# ---------------------------------------------------------------------------
@jit(inline="always")
def _asinh_upper(y):
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
def _asinh_upper_own(y):
    """:func:`_asinh_upper` with the own :func:`_log` (straight-line; finite ``y >= 0``).

    The own log is within 2 eps (1 + |L|) (tests/test_kepler.py), so the bound
    adds ``8 eps (1 + L)``; above 1e150 ``log y + log 2 + 8 eps (1 + L)`` (a
    valid, slightly loose bound: its callers exclude the overflow edge).
    """
    big = y >= 1e150
    L = _log(y * 0.5 if big else y + math.sqrt(1.0 + y * y)) + (2.0 * _LN2 if big else 0.0)
    b = L + 8.0 * EPS * (1.0 + L)
    return y if y < b else b


@jit(inline="always")
def _hyp_cubic_bound(M, e, em1):
    """The cubic bound ``(e - 1) F + e F^3 / 6 = M`` of :func:`_hyp_upper_start` (``M < 1e100``)."""
    p3 = 2.0 * em1 / e  # p/3 with p = 6 (e - 1)/e
    qh = 3.0 * M / e  # qq/2 with qq = 6 M / e
    u = _cbrt_start(qh + math.sqrt(qh * qh + p3 * p3 * p3))
    v = p3 / u
    return 2.0 * qh / (u * u + u * v + v * v) * (1.0 + 1e-10)


@jit(inline="always")
def _hyp_upper_start(M, e, em1):
    """An upper bound of the root ``F > 0`` of ``e sinh F - F = M`` (``M > 0``), typically 1e-2 relative.

    The cubic ``(e - 1) F + e F^3 / 6 = M`` (``sinh F - F >= F^3 / 6``; Cardano
    in the cancellation-free form ``2 (q/2) / (u^2 + u v + v^2)``) and, when
    ``e - 1`` is large, ``(e - 1) sinh F <= M``; then one fixed-point step
    ``F = asinh((M + F) / e)``, which maps upper bounds to upper bounds and
    contracts by ``1 / (e cosh F)``.  Cube root and asinh come from
    :func:`_cbrt_start` (relative error below 1e-14; the bound is widened by 1e-10,
    since the Cardano form decreases with u at most twice as fast) and
    :func:`_asinh_upper`.
    """
    if M < 1e100:
        Fu = _hyp_cubic_bound(M, e, em1)
    else:
        Fu = math.inf
    if em1 > 0.0:
        Fu = min(Fu, _asinh_upper(M / em1))
    if not math.isfinite(Fu):  # e -> 1 and huge M (M / (e - 1) overflows): log bound, in logs so
        Fu = _LN2 + math.log1p(M) + math.log1p(M) + 1.0  # that M ~ 1e308 does not overflow
    return _asinh_upper((M + Fu) / e)  # still an upper bound, much tighter


@jit(inline="always")
def _hyp_upper_start_own(M, e, em1):
    """:func:`_hyp_upper_start` for ``0 <= M < 1e100`` as straight-line code (own log): vectorizable.

    Outside that range it returns garbage; :func:`_kepler_hyp_fast` then fails
    its check and the caller takes :func:`_kepler_hyp_solve`.
    """
    Fc = _hyp_cubic_bound(M, e, em1)
    y = M / em1 if em1 > 0.0 else 0.0
    Fa = _asinh_upper_own(y) if (em1 > 0.0) & (y < 1e300) else Fc
    return _asinh_upper_own((M + (Fa if Fa < Fc else Fc)) / e)


@jit(inline="always")
def _hyp_residual(F, e, em1, M, sh, chm1, shmx):
    """``(e - 1) F + e (sinh F - F) - M``, its slope ``e cosh F - 1``, ``sinh F``, ``cosh F - 1``, noise
    (``sh, chm1, shmx``: :func:`_sinh_parts` of ``F``)."""
    R = (em1 * F + e * shmx) - M
    noise = EPS * (abs(em1 * F) + abs(e * shmx) + abs(M))
    return R, em1 + e * chm1, sh, chm1, noise


@jit(inline="always")
def _hyp_halley(R, Rp, e, sh):
    """Halley's step for the hyperbolic residual (second derivative ``e sinh F``); Newton's if
    Halley's denominator drops below half the slope."""
    dF = -R / Rp
    den = Rp + 0.5 * dF * (e * sh)
    if den > 0.5 * Rp:
        dF = -R / den
    return dF


@jit(inline="always")
def _kepler_hyp_fast(M, e, em1, F):
    """Straight-line solve for ``M > 0`` from the upper bound ``F``: two Halley steps, then the
    residual check and a Newton correction (no loop, no bracket, no libm call: a loop over
    many states vectorizes).

    From the starter's ~2e-2 relative error Halley's cubic convergence reaches the
    noise level in two steps for almost every input; ``ok`` is False otherwise and
    the caller runs the safeguarded :func:`_kepler_hyp_solve`.  Returns
    ``(ok, F, sinh F, cosh F - 1)`` (sinh, cosh carried to first order through the
    final correction, as in :func:`_kepler_hyp_solve`).
    """
    sh, chm1, shmx = _sinh_parts_fast(F)
    R, Rp, sh, chm1, noise = _hyp_residual(F, e, em1, M, sh, chm1, shmx)
    F = F + _hyp_halley(R, Rp, e, sh)
    sh, chm1, shmx = _sinh_parts_fast(F)
    R, Rp, sh, chm1, noise = _hyp_residual(F, e, em1, M, sh, chm1, shmx)
    F = F + _hyp_halley(R, Rp, e, sh)
    sh, chm1, shmx = _sinh_parts_fast(F)
    R, Rp, sh, chm1, noise = _hyp_residual(F, e, em1, M, sh, chm1, shmx)
    # |F| <= 700: _sinh_parts_fast's range (F is near there only when M is near 1e300)
    ok = (abs(R) <= 4.0 * noise) & (Rp > 0.0) & (abs(F) <= 700.0)
    d = -R / Rp
    return ok, F + d, sh + (1.0 + chm1) * d, chm1 + sh * d


@jit
def _kepler_hyp_solve(M, e, em1):
    """Hyperbolic anomaly with its sinh: ``(F, sinh F, cosh F - 1)``, ``e sinh F - F = M``.

    ``em1 = e - 1`` given accurately.  Converges monotonically from an upper
    bound (:func:`_hyp_upper_start`; the residual is convex for ``F > 0``) by
    Halley steps on the cancellation-free residual, stopped at its rounding
    noise and safeguarded by a bracket; odd symmetry handles ``M < 0``.  The
    returned sinh and cosh - 1 are the last residual's, carried through the
    final Newton correction ``d`` to first order (``|d|`` is at the noise
    level, so ``d^2`` is far below an ulp).
    """
    if not (math.isfinite(M) and e >= 1.0 and em1 >= 0.0):
        return math.nan, math.nan, math.nan
    sgn = 1.0
    if M < 0.0:
        M = -M
        sgn = -1.0
    if M == 0.0:
        return 0.0, 0.0, 0.0
    lo = 0.0  # F > 0 for M > 0 (bracket for the bisection fallback only)
    F = _hyp_upper_start(M, e, em1)
    hi = F
    for _ in range(MAX_ITER + 8):
        sh, chm1, shmx = _sinh_parts(F)
        R, Rp, sh, chm1, noise = _hyp_residual(F, e, em1, M, sh, chm1, shmx)
        if abs(R) <= 4.0 * noise:
            d = -R / Rp
            return sgn * (F + d), sgn * (sh + (1.0 + chm1) * d), chm1 + sh * d
        if R > 0.0:
            hi = min(hi, F)
        else:
            lo = max(lo, F)
        Fn = F + _hyp_halley(R, Rp, e, sh)
        if not (lo <= Fn <= hi):
            Fn = 0.5 * (lo + hi)
        if Fn == F:
            break
        F = Fn
    sh, chm1, _ = _sinh_parts(F)
    return sgn * F, sgn * sh, chm1


@jit
def _kepler_hyp_scalar(M, e, em1):
    """Hyperbolic anomaly ``F`` [rad] with ``e sinh F - F = M``; ``em1 = e - 1`` given accurately."""
    return _kepler_hyp_solve(M, e, em1)[0]


@jit
def _kepler_hyp_loop(M, e, out):
    for i in range(M.shape[0]):
        out[i] = _kepler_hyp_scalar(M[i], e[i], e[i] - 1.0)


@pjit
def _kepler_hyp_loop_par(M, e, out):
    for i in prange(M.shape[0]):
        out[i] = _kepler_hyp_scalar(M[i], e[i], e[i] - 1.0)


# ---------------------------------------------------------------------------
# public, vectorized
# ---------------------------------------------------------------------------
def _broadcast_flat(M, e):
    M = np.asarray(M, dtype=np.float64)
    e = np.asarray(e, dtype=np.float64)
    shape = np.broadcast_shapes(M.shape, e.shape)
    Mf = np.ascontiguousarray(np.broadcast_to(M, shape)).reshape(-1)
    ef = np.ascontiguousarray(np.broadcast_to(e, shape)).reshape(-1)
    return shape, Mf, ef


def _run(serial, parallel, Mf, ef, shape):
    out = np.empty(Mf.shape[0])
    (parallel if Mf.shape[0] >= PARALLEL_MIN else serial)(Mf, ef, out)
    out = out.reshape(shape)
    return out[()] if out.ndim == 0 else out


def solve_kepler(M, e):
    """Eccentric anomaly ``E`` [rad] solving ``M = E - e sin E`` (elliptic orbits).

    Parameters
    ----------
    M : array_like
        Mean anomaly [rad], any finite real value (the revolution count is kept:
        ``solve_kepler(M + 2 pi k, e) = solve_kepler(M, e) + 2 pi k``).
    e : array_like
        Eccentricity, ``0 <= e < 1``; broadcast against ``M``.

    Returns
    -------
    E : ndarray or float
        Same broadcast shape; a Python-float-like 0-d result for scalar input.
        Accurate to the conditioning limit ``eps (|M| + e) / (1 - e cos E)``
        (Markley 1995 starter, residual-stopped Halley polish; see module doc).
        NaN where ``M`` or ``e`` is NaN or ``M`` is infinite.

    Raises
    ------
    ValueError
        If a finite ``e`` is outside ``[0, 1)``.
    """
    if type(M) is float and type(e) is float and 0.0 <= e < 1.0:  # fast path for one value
        return _kepler_ell_scalar(M, e)
    shape, Mf, ef = _broadcast_flat(M, e)
    bad = np.isfinite(ef) & ~((ef >= 0.0) & (ef < 1.0))
    if bad.any():
        raise ValueError(f"solve_kepler: e must satisfy 0 <= e < 1 (elliptic); got e = {ef[bad][0]!r}")
    return _run(_kepler_ell_loop, _kepler_ell_loop_par, Mf, ef, shape)


def solve_kepler_hyperbolic(M, e):
    """Hyperbolic anomaly ``F`` [rad] solving ``M = e sinh F - F`` (hyperbolic orbits).

    Parameters
    ----------
    M : array_like
        Hyperbolic mean anomaly [rad], any finite real value.
    e : array_like
        Eccentricity, ``e > 1``; broadcast against ``M``.

    Returns
    -------
    F : ndarray or float
        Accurate to the conditioning limit ``eps |M| / (e cosh F - 1)``
        (cancellation-free residual ``(e - 1) F + e (sinh F - F) - M``,
        monotone Halley/Newton from an upper bound).  NaN where ``M`` or ``e``
        is NaN or ``M`` is infinite.

    Raises
    ------
    ValueError
        If a finite ``e`` is not ``> 1``.
    """
    if type(M) is float and type(e) is float and e > 1.0:  # fast path for one value
        return _kepler_hyp_scalar(M, e, e - 1.0)
    shape, Mf, ef = _broadcast_flat(M, e)
    bad = np.isfinite(ef) & ~(ef > 1.0)
    if bad.any():
        raise ValueError(f"solve_kepler_hyperbolic: e must satisfy e > 1 (hyperbolic); got e = {ef[bad][0]!r}")
    return _run(_kepler_hyp_loop, _kepler_hyp_loop_par, Mf, ef, shape)
