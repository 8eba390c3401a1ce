"""Kepler's equation, elliptic and hyperbolic, solved to the float64 floor.

Elliptic (``0 <= e < 1``): given the mean anomaly ``M`` [rad], find the
eccentric anomaly ``E`` [rad] with ``M = E - e sin E`` (Vallado 4th ed.
eq. 2-4 / Curtis eq. 3.14).  Hyperbolic (``e > 1``): find ``F`` with
``M = e sinh F - F`` (Vallado eq. 2-5 / Curtis eq. 3.40).

How the accuracy is obtained (every piece is exercised by ``tests/test_kepler.py``):

* **Range reduction.** ``M`` is reduced to ``[-pi, pi]`` by
  :func:`astrodyn.orbit.floating.reduce_2pi` (Cody-Waite with ``2 pi`` in three
  parts and exact products: the remainder carries a double-double low word and no
  error beyond one rounding for ``|M| < 2**52``).  The returned ``E`` keeps the
  revolution: ``E = M + (E_red - M_red)``, so ``E - e sin E = M``.
* **Starter.** Markley (1995), "Kepler equation solver", Celest. Mech. Dyn.
  Astr. 63, 101-111: a cubic starter followed by a fifth-order correction
  (about 1e-15 relative already; the inverted Taylor series, of the same
  order as his eqs. 29-31 with one division instead of three), here applied to the cancellation-free
  residual; sine and cosine at the corrected point come from a Taylor
  rotation, so a typical solve makes one sin/cos evaluation (libm in
  ``solve_kepler``; the propagator's vectorized path uses the straight-line
  kernels ``sincos_vec`` and ``atan2_vec`` of :mod:`astrodyn.orbit.floating`).  For the hyperbola, an upper bound from the
  cubic ``(e - 1) F + e F^3 / 6 = M`` or ``asinh(M / (e - 1))``, tightened by
  one fixed-point step ``F = asinh((M + F) / e)`` (asinh as a widened log + sqrt
  bound, :func:`asinh_upper`), so Newton/Halley converge monotonically from above;
  two Halley steps and a residual check usually suffice (:func:`solve_kepler_hyperbolic_vec`).
* **Residual without cancellation.** ``(1 - e) E + e (E - sin E) - M`` with a
  series for ``E - sin E`` when ``|E| < 1`` (and ``(e - 1) F + e (sinh F - F) -
  M`` for the hyperbola); ``1 - e cos E = (1 - e) + e (1 - cos E)``.  The naive
  ``E - e sin E - M`` loses about three digits near ``e -> 1, M -> 0``.
* **Stopping.** Safeguarded (bracketed) Halley/Newton iterations stop when the
  residual is at its own rounding-noise level, not on a step size; at most
  ``MAX_ITER`` iterations, so NaN or pathological inputs never hang.

NaN in ``M`` or ``e`` gives NaN; ``M = +-inf`` gives NaN.  ``e`` outside the
allowed range (finite) raises ``ValueError``; so do shapes that do not broadcast (naming
``M`` and ``e`` with their shapes).  Arguments that are not real numbers (``None``,
complex, strings, bools, object arrays holding anything but ints and floats) raise
:class:`astrodyn.inputs.NonRealInputError` (a ``TypeError``) naming them.

Compiled kernels shared with :mod:`astrodyn.orbit.universal` (public names, callable
from other numba code; the floating-point pieces they use live in
:mod:`astrodyn.orbit.floating`):

* :func:`markley_start` -- Markley's cubic starter of the elliptic equation;
* :func:`solve_kepler_difference` -- the difference form ``q x + C (x - sin x) + S (1 - cos x) = M``;
* :func:`hyperbolic_upper_start_vec` -- a straight-line upper bound of the hyperbolic root;
* :func:`solve_kepler_hyperbolic_vec` -- two Halley steps from that bound with an ``ok`` flag;
* :func:`solve_kepler_hyperbolic_kernel` -- the safeguarded hyperbolic solve
  ``(F, sinh F, cosh F - 1)``.
"""

from __future__ import annotations

import math

import numpy as np

from astrodyn.inputs import broadcast_named, real_array
from astrodyn.jit import jit, pjit, prange
from astrodyn.orbit.floating import (
    EPS,
    INV6,
    INV24,
    LN2,
    PI,
    asinh_upper,
    asinh_upper_vec,
    cbrt_start,
    one_minus_cos,
    reduce_2pi,
    rotate_sincos,
    sinh_parts,
    sinh_parts_vec,
    x_minus_sin,
)

__all__ = ["solve_kepler", "solve_kepler_hyperbolic"]

MAX_ITER = 12
PARALLEL_MIN = 4096  # below this many elements the serial kernel is faster
_INV_PI2_M6 = 1.0 / (PI * PI - 6.0)


# ---------------------------------------------------------------------------
# elliptic
# ---------------------------------------------------------------------------
@jit(inline="always")
def markley_start(M, e):
    """Markley (1995) cubic starter for ``M`` in ``[-pi, pi]``, ``0 <= e < 1`` (his eqs. 20-21).

    Relative error below about 1e-3; :func:`solve_kepler_difference` then applies
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
    w = cbrt_start(abs(r) + math.sqrt(disc))
    w = w * w  # (|r| + sqrt(disc))^(2/3)
    den = w * w + w * q + q * q
    E = (2.0 * r * w + M * den) / (d * den) if den > 0.0 else M / d
    return sgn * E


@jit
def solve_kepler_difference(q, C, S, mh, ml, x, lo, hi):
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
    most 0.05 rad the new sine and cosine come from :func:`rotate_sincos`.

    Returns ``(x, sin x, cos x, 1 - cos x, r / a)`` consistent to first order.
    """
    s = math.sin(x)
    c = math.cos(x)
    for _ in range(MAX_ITER):
        omc = one_minus_cos(s, c)
        xms = x_minus_sin(x, s)
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
            a3u2 = F3 * INV6 * inv * u * u
            a4u3 = -F2 * INV24 * inv * u * u * u
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
            s, c = rotate_sincos(s, c, d)
        else:
            s = math.sin(xn)
            c = math.cos(xn)
        x = xn
    s = math.sin(x)
    c = math.cos(x)
    omc = one_minus_cos(s, c)
    return x, s, c, omc, q + C * omc + S * s


@jit
def _kepler_ell_scalar(M, e):
    """Eccentric anomaly ``E`` [rad] for any finite ``M`` [rad] and ``0 <= e < 1``."""
    if not (math.isfinite(M) and e >= 0.0 and e < 1.0):
        return math.nan
    k, mh, ml = reduce_2pi(M, 0.0)
    x0 = markley_start(mh, e)
    if mh >= 0.0:
        lo, hi = mh, mh + e
    else:
        lo, hi = mh - e, mh
    x = solve_kepler_difference(1.0 - e, e, 0.0, mh, ml, x0, lo, hi)[0]
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
def _hyp_cubic_bound(M, e, em1):
    """The cubic bound ``(e - 1) F + e F^3 / 6 = M`` of :func:`_hyp_upper_start` (``M < 1e100``)."""
    p3 = 2.0 * em1 / e  # p/3 with p = 6 (e - 1)/e
    qh = 3.0 * M / e  # qq/2 with qq = 6 M / e
    u = cbrt_start(qh + math.sqrt(qh * qh + p3 * p3 * p3))
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
    :func:`cbrt_start` (relative error below 1e-14; the bound is widened by 1e-10,
    since the Cardano form decreases with u at most twice as fast) and
    :func:`asinh_upper`.
    """
    if M < 1e100:
        Fu = _hyp_cubic_bound(M, e, em1)
    else:
        Fu = math.inf
    if em1 > 0.0:
        Fu = min(Fu, asinh_upper(M / em1))
    if not math.isfinite(Fu):  # e -> 1 and huge M (M / (e - 1) overflows): log bound, in logs so
        Fu = LN2 + math.log1p(M) + math.log1p(M) + 1.0  # that M ~ 1e308 does not overflow
    return asinh_upper((M + Fu) / e)  # still an upper bound, much tighter


@jit(inline="always")
def hyperbolic_upper_start_vec(M, e, em1):
    """:func:`_hyp_upper_start` for ``0 <= M < 1e100`` as straight-line code (own log): vectorizable.

    Outside that range it returns garbage; :func:`solve_kepler_hyperbolic_vec` then fails
    its check and the caller takes :func:`solve_kepler_hyperbolic_kernel`.
    """
    Fc = _hyp_cubic_bound(M, e, em1)
    y = M / em1 if em1 > 0.0 else 0.0
    Fa = asinh_upper_vec(y) if (em1 > 0.0) & (y < 1e300) else Fc
    return asinh_upper_vec((M + (Fa if Fa < Fc else Fc)) / e)


@jit(inline="always")
def _hyp_residual(F, e, em1, M, sh, chm1, shmx):
    """``(e - 1) F + e (sinh F - F) - M``, its slope ``e cosh F - 1``, ``sinh F``, ``cosh F - 1``, noise
    (``sh, chm1, shmx``: :func:`sinh_parts` of ``F``)."""
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
def solve_kepler_hyperbolic_vec(M, e, em1, F):
    """Straight-line solve for ``M > 0`` from the upper bound ``F``: two Halley steps, then the
    residual check and a Newton correction (no loop, no bracket, no libm call: a loop over
    many states vectorizes).

    From the starter's ~2e-2 relative error Halley's cubic convergence reaches the
    noise level in two steps for almost every input; ``ok`` is False otherwise and
    the caller runs the safeguarded :func:`solve_kepler_hyperbolic_kernel`.  Returns
    ``(ok, F, sinh F, cosh F - 1)`` (sinh, cosh carried to first order through the
    final correction, as in :func:`solve_kepler_hyperbolic_kernel`).
    """
    sh, chm1, shmx = sinh_parts_vec(F)
    R, Rp, sh, chm1, noise = _hyp_residual(F, e, em1, M, sh, chm1, shmx)
    F = F + _hyp_halley(R, Rp, e, sh)
    sh, chm1, shmx = sinh_parts_vec(F)
    R, Rp, sh, chm1, noise = _hyp_residual(F, e, em1, M, sh, chm1, shmx)
    F = F + _hyp_halley(R, Rp, e, sh)
    sh, chm1, shmx = sinh_parts_vec(F)
    R, Rp, sh, chm1, noise = _hyp_residual(F, e, em1, M, sh, chm1, shmx)
    # |F| <= 700: sinh_parts_vec's range (F is near there only when M is near 1e300)
    ok = (abs(R) <= 4.0 * noise) & (Rp > 0.0) & (abs(F) <= 700.0)
    d = -R / Rp
    return ok, F + d, sh + (1.0 + chm1) * d, chm1 + sh * d


@jit
def solve_kepler_hyperbolic_kernel(M, e, em1):
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
        sh, chm1, shmx = sinh_parts(F)
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
    sh, chm1, _ = sinh_parts(F)
    return sgn * F, sgn * sh, chm1


@jit
def _kepler_hyp_scalar(M, e, em1):
    """Hyperbolic anomaly ``F`` [rad] with ``e sinh F - F = M``; ``em1 = e - 1`` given accurately."""
    return solve_kepler_hyperbolic_kernel(M, e, em1)[0]


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
def _broadcast_flat(M, e, who):
    M = real_array(M, "M", who)
    e = real_array(e, "e", who)
    shape = broadcast_named(who, ("M", M, 0), ("e", e, 0))
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
        If a finite ``e`` is outside ``[0, 1)``, or the shapes of ``M`` and ``e`` do not
        broadcast (names both with their shapes).
    TypeError
        ``M`` or ``e`` not real numbers (``None``, complex, str, bool; names it:
        :class:`astrodyn.inputs.NonRealInputError`).
    """
    if type(M) is float and type(e) is float and 0.0 <= e < 1.0:  # fast path for one value
        return _kepler_ell_scalar(M, e)
    shape, Mf, ef = _broadcast_flat(M, e, "solve_kepler")
    bad = np.isfinite(ef) & ~((ef >= 0.0) & (ef < 1.0))
    if bad.any():
        raise ValueError(f"solve_kepler: e must satisfy 0 <= e < 1 (elliptic); got e = {float(ef[bad][0])!r}")
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
    ValueError, TypeError
        If a finite ``e`` is not ``> 1``; otherwise as :func:`solve_kepler`.
    """
    if type(M) is float and type(e) is float and e > 1.0:  # fast path for one value
        return _kepler_hyp_scalar(M, e, e - 1.0)
    shape, Mf, ef = _broadcast_flat(M, e, "solve_kepler_hyperbolic")
    bad = np.isfinite(ef) & ~(ef > 1.0)
    if bad.any():
        raise ValueError(f"solve_kepler_hyperbolic: e must satisfy e > 1 (hyperbolic); got e = {float(ef[bad][0])!r}")
    return _run(_kepler_hyp_loop, _kepler_hyp_loop_par, Mf, ef, shape)
