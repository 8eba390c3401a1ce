"""Jacobi elliptic functions and Carlson's symmetric elliptic integrals, compiled.

Every routine takes the parameter ``m = k^2`` *and* its complement
``m1 = 1 - m`` as two separate arguments.  Near the separatrix of a rigid body
``m1`` is the small quantity that carries the physics (it can be 1e-18 while
``m`` rounds to exactly 1.0), so it is never recomputed as ``1 - m``; callers
form it from differences that do not cancel.  ``scipy.special.ellipj`` takes
``m`` only and loses about 5e-9 at ``m1 = 1e-8`` (and is wrong at 2e-12); the
functions here stay at a few ulp for every ``m1`` in ``[0, 1]``.

Definitions (DLMF ch. 19 and 22; Abramowitz & Stegun ch. 16, 17):

* ``sn(u|m), cn(u|m), dn(u|m)``: Jacobi elliptic functions, ``sn = sin(am u)``,
  ``cn = cos(am u)``, ``dn = sqrt(1 - m sn^2)``.
* ``K(m) = F(pi/2|m)``, complete integral of the first kind.
* ``F(phi|m) = int_0^phi dth / sqrt(1 - m sin^2 th)``.
* ``Pi(n; phi|m) = int_0^phi dth / ((1 - n sin^2 th) sqrt(1 - m sin^2 th))``
  (the characteristic ``n`` as in A&S 17.2.15; DLMF writes it alpha^2).
* ``R_F, R_D, R_J``: Carlson's symmetric integrals (DLMF 19.16).

Algorithms:

* ``sn, cn, dn`` (:func:`ellipj`): argument reduced to ``[0, K]`` by the
  half-period ``2K`` (``sn, cn`` change sign, ``dn`` does not) and parity; then
  for ``m <= 1/2`` descending Landen (Gauss) transformations (A&S 16.12) until
  ``m < 1e-9`` and the expansion about ``m = 0`` (A&S 16.13), and for
  ``m > 1/2`` ascending Landen
  transformations (A&S 16.14) driven by the complementary modulus
  ``k'_{j+1} = m1_j / (1 + k_j)^2`` until ``m1 < 1e-17``, where the first-order
  expansion about ``m = 1`` (A&S 16.15) is exact to rounding.  ``dn`` keeps its
  relative accuracy down to ``dn(K) = sqrt(m1)``.
* ``K`` (:func:`ellipk`): ``pi / (2 AGM(1, sqrt(m1)))`` (A&S 17.6).
* ``R_F, R_D, R_J``: B. C. Carlson, "Numerical computation of real or complex
  elliptic integrals", Numer. Algorithms 10 (1995) 13-26, duplication
  algorithms with the paper's stopping rule ``4^-n Q < |A_n|`` for a relative
  error ``r = 1e-16`` and the paper's fifth-order series.  ``R_J`` here takes
  ``p > 0`` (no Cauchy principal value); it is at a few ulp for
  ``p >= min(x, y, z)`` (the torque-free attitude has ``p >= 1 >= x, y, z``)
  and loses up to about 1e-13 relative when ``p`` is below ``1e-6 min(x, y, z)``
  (its ``R_C(1, 1 + e)`` terms then have ``e`` near -1).
* ``F`` and ``Pi`` (:func:`ellipf`, :func:`ellippi`): DLMF 19.25.5 and
  19.25.14 for ``|phi| <= pi/2``, extended by ``F(phi + j pi) = F(phi) + 2 j K``
  (likewise with the complete ``Pi``); ``Pi`` for ``n < 1``.

Scalar kernels (``_sncndn``, ``elliprf_scalar``, ``elliprj_scalar``, ...) are compiled with
:func:`astrodyn.jit.jit` and used directly by
:mod:`astrodyn.attitude.torque_free`; the public functions broadcast arrays and
loop in compiled code.  NaN inputs give NaN outputs; loops have iteration caps.

Example::

    >>> from astrodyn.attitude.elliptic import ellipj, ellipk
    >>> m1 = 2e-12                      # 1 - m, given directly
    >>> K = ellipk(1 - m1, m1)
    >>> sn, cn, dn = ellipj(K, 1 - m1, m1)
    >>> round(float(dn) / m1 ** 0.5, 14)  # dn(K) = sqrt(m1), to the last digits
    1.0
"""

from __future__ import annotations

import math

import numpy as np

from astrodyn.jit import jit, parallel_kernel, prange

__all__ = ["ellipj", "ellipk", "elliprf", "elliprd", "elliprj", "ellipf", "ellippi"]

_R_TOL = 1e-16  # Carlson's r: relative error target of the duplication loops
_Q_RF = (3.0 * _R_TOL) ** (-1.0 / 6.0)
_Q_RJ = (_R_TOL / 4.0) ** (-1.0 / 6.0)
_MAX_IT = 64  # duplication halves |A - x| by 4 each step: 30 steps reach 1e-18 from 1e0
_GAUSS_BASE_M = 1e-9  # below this m the first-order expansion about m = 0 is exact to rounding
_LANDEN_BASE_M1 = 1e-17  # below this m1 the first-order expansion about m = 1 is exact to rounding


# ---------------------------------------------------------------------------
# complete integral of the first kind


@jit
def ellipk_scalar(m1):
    """K from the complementary parameter only: ``pi / (2 AGM(1, sqrt(m1)))``."""
    if not (m1 >= 0.0):  # NaN or negative
        return math.nan
    if m1 == 0.0:
        return math.inf
    a = 1.0
    b = math.sqrt(m1)
    for _ in range(_MAX_IT):
        if abs(a - b) <= 4e-16 * a:
            break
        a, b = 0.5 * (a + b), math.sqrt(a * b)
    return math.pi / (a + b)


# ---------------------------------------------------------------------------
# Jacobi elliptic functions


@jit
def _sncndn_near0(v, m):
    """First-order expansion about m = 0 (A&S 16.13.1-3), for m < 1e-9 and |v| <= K."""
    s = math.sin(v)
    c = math.cos(v)
    g = 0.25 * m * (v - s * c)
    return s - g * c, c + g * s, 1.0 - 0.5 * m * s * s


@jit
def _gauss_step(mm, mc):
    """One descending Landen step: (m, m1) -> (r = sqrt(mu), mu, mu1); r = m/(1 + k')^2 (no cancellation)."""
    kc = math.sqrt(mc)
    opk2 = (1.0 + kc) * (1.0 + kc)
    r = mm / opk2
    return r, r * r, 4.0 * kc / opk2


@jit
def _gauss_back(s, c, d, r):
    """Back from parameter mu to m (A&S 16.12.2-4), r = sqrt(mu); denominators >= 1."""
    den = 1.0 + r * s * s
    return (1.0 + r) * s / den, c * d / den, (1.0 - r * s * s) / den


@jit
def _sncndn_m_small(u, m, m1):
    """sn, cn, dn for 0 <= u <= K and 0 <= m <= 1/2: descending Landen (A&S 16.12).

    Step j maps m_j to mu = ((1 - k')/(1 + k'))^2, argument v = u/(1 + sqrt(mu));
    mu falls quadratically (1/2 -> 0.029 -> 5.6e-5 -> 1.9e-10 -> 2e-21), and
    below 1e-9 the first-order expansion about m = 0 is exact to rounding
    (error O(mu^2)).  At most four steps; unrolled (no scratch arrays).
    """
    if m < _GAUSS_BASE_M:
        return _sncndn_near0(u, m)
    r1, mu1, mc1 = _gauss_step(m, m1)
    v = u / (1.0 + r1)
    if mu1 < _GAUSS_BASE_M:
        s, c, d = _sncndn_near0(v, mu1)
        return _gauss_back(s, c, d, r1)
    r2, mu2, mc2 = _gauss_step(mu1, mc1)
    v = v / (1.0 + r2)
    if mu2 < _GAUSS_BASE_M:
        s, c, d = _sncndn_near0(v, mu2)
        s, c, d = _gauss_back(s, c, d, r2)
        return _gauss_back(s, c, d, r1)
    r3, mu3, mc3 = _gauss_step(mu2, mc2)
    v = v / (1.0 + r3)
    if mu3 < _GAUSS_BASE_M:
        s, c, d = _sncndn_near0(v, mu3)
        s, c, d = _gauss_back(s, c, d, r3)
        s, c, d = _gauss_back(s, c, d, r2)
        return _gauss_back(s, c, d, r1)
    r4, mu4, mc4 = _gauss_step(mu3, mc3)
    v = v / (1.0 + r4)
    s, c, d = _sncndn_near0(v, mu4)
    s, c, d = _gauss_back(s, c, d, r4)
    s, c, d = _gauss_back(s, c, d, r3)
    s, c, d = _gauss_back(s, c, d, r2)
    return _gauss_back(s, c, d, r1)


@jit
def _sncndn_near1(v, m1):
    """First-order expansion about m = 1 (A&S 16.15.1-3), for tiny m1 and moderate v."""
    e = math.exp(-v)
    ch = 0.5 * (1.0 / e + e)
    th = math.tanh(v)
    sech = 1.0 / ch
    sh = th * ch
    g = 0.25 * m1 * (sh * ch - v)
    s = th + g * sech * sech
    c = sech - g * th * sech
    d = sech + 0.25 * m1 * (sh * ch + v) * th * sech
    return s, c, d


@jit
def _ascend(mm, mc):
    """One ascending Landen step: (m, m1) -> (r = sqrt(mu1), mu, mu1); r = m1/(1 + k)^2 (no cancellation)."""
    k = math.sqrt(mm)
    opk2 = (1.0 + k) * (1.0 + k)
    r = mc / opk2
    return r, 4.0 * k / opk2, r * r


@jit
def _descend(s, c, d, r, mu):
    """Back from parameter mu to m (A&S 16.14.1-3), r = sqrt(mu1)."""
    return (
        (1.0 + r) * s * c / d,
        (1.0 + r) / mu * (d * d - r) / d,
        (1.0 - r) / mu * (d * d + r) / d,
    )


@jit
def _sncndn_m_large(u, m, m1):
    """sn, cn, dn for 0 <= u <= K and m > 1/2: ascending Landen (A&S 16.14).

    Step j maps parameter m_j to mu = 4 k/(1 + k)^2 with complementary modulus
    r_j = sqrt(mu1) = m1_j / (1 + k_j)^2 and argument v = u / (1 + r_j); since
    u <= K(m_j) maps to v <= K(mu)/2, after j steps v <= K/2^j of its level.
    Steps continue until mu1 < 1e-17 (at most four from m1 = 1/2), where the
    first-order expansion about m = 1 is exact to rounding (its error is
    O(mu1^2 cosh^4 v) <= O(mu1)); at least one step is always taken.
    """
    r1, mu1, mc1 = _ascend(m, m1)
    v = u / (1.0 + r1)
    if mc1 < _LANDEN_BASE_M1:
        s, c, d = _sncndn_near1(v, mc1)
        return _descend(s, c, d, r1, mu1)
    r2, mu2, mc2 = _ascend(mu1, mc1)
    v = v / (1.0 + r2)
    if mc2 < _LANDEN_BASE_M1:
        s, c, d = _sncndn_near1(v, mc2)
        s, c, d = _descend(s, c, d, r2, mu2)
        return _descend(s, c, d, r1, mu1)
    r3, mu3, mc3 = _ascend(mu2, mc2)
    v = v / (1.0 + r3)
    if mc3 < _LANDEN_BASE_M1:
        s, c, d = _sncndn_near1(v, mc3)
        s, c, d = _descend(s, c, d, r3, mu3)
        s, c, d = _descend(s, c, d, r2, mu2)
        return _descend(s, c, d, r1, mu1)
    r4, mu4, mc4 = _ascend(mu3, mc3)
    v = v / (1.0 + r4)
    s, c, d = _sncndn_near1(v, mc4)
    s, c, d = _descend(s, c, d, r4, mu4)
    s, c, d = _descend(s, c, d, r3, mu3)
    s, c, d = _descend(s, c, d, r2, mu2)
    return _descend(s, c, d, r1, mu1)


@jit
def _sncndn_reduced(u, m, m1):
    """sn, cn, dn for 0 <= u <= K (K finite)."""
    if m <= 0.5:
        return _sncndn_m_small(u, m, m1)
    return _sncndn_m_large(u, m, m1)


@jit
def sncndn_half(r, m, m1):
    """sn, cn, dn for |r| <= K (K finite): parity (sn odd, cn and dn even)."""
    s, c, d = _sncndn_reduced(abs(r), m, m1)
    # rounding can leave |sn|, |cn|, dn one ulp above 1 (e.g. cn(0) from the Landen steps)
    s = min(s, 1.0)
    c = min(max(c, -1.0), 1.0)
    d = min(d, 1.0)
    if r < 0.0:
        s = -s
    return s, c, d


@jit
def reduce_half_period(u, K):
    """u = j 2K + r with |r| <= K (K finite); returns (j as float, r)."""
    twoK = 2.0 * K
    j = math.floor(u / twoK + 0.5)
    r = u - j * twoK
    if r > K:  # rounding at the half-period boundary
        r -= twoK
        j += 1.0
    elif r < -K:
        r += twoK
        j -= 1.0
    return j, r


@jit
def _sncndn(u, m, m1, K):
    """sn, cn, dn for any real u; ``K = K(m)`` supplied (``inf`` when m1 == 0)."""
    if not (u == u and m == m and m1 == m1):
        return math.nan, math.nan, math.nan
    if m1 == 0.0:  # m = 1: sn = tanh, cn = dn = sech
        th = math.tanh(u)
        sech = 1.0 / math.cosh(u) if abs(u) < 710.0 else 0.0
        return th, sech, sech
    if m == 0.0:
        return math.sin(u), math.cos(u), 1.0
    j, r = reduce_half_period(u, K)
    s, c, d = sncndn_half(r, m, m1)
    if j % 2.0 != 0.0:
        s = -s
        c = -c
    return s, c, d


# ---------------------------------------------------------------------------
# Carlson symmetric integrals


@jit(inline="always")
def carlson_roots(x, y, z):
    """``(sqrt x, sqrt y, sqrt z, lam)`` of one duplication step of Carlson's algorithms,
    ``lam = sqrt(x) sqrt(y) + sqrt(x) sqrt(z) + sqrt(y) sqrt(z)`` (Carlson 1995, sec. 2)."""
    sx = math.sqrt(x)
    sy = math.sqrt(y)
    sz = math.sqrt(z)
    return sx, sy, sz, sx * sy + sx * sz + sy * sz


@jit(inline="always")
def carlson_duplicate(lam, a, x, y, z):
    """The duplication step of Carlson's algorithms: ``(a, x, y, z) -> ((a + lam) / 4, (x + lam) / 4, ...)``."""
    return 0.25 * (a + lam), 0.25 * (x + lam), 0.25 * (y + lam), 0.25 * (z + lam)


@jit
def elliprf_scalar(x, y, z):
    """Carlson R_F(x, y, z), x, y, z >= 0, at most one zero (Carlson 1995, sec. 2)."""
    a0 = (x + y + z) / 3.0
    q = _Q_RF * max(abs(a0 - x), abs(a0 - y), abs(a0 - z))
    a = a0
    fac = 1.0
    xn, yn, zn = x, y, z
    for _ in range(_MAX_IT):
        if fac * q < abs(a):
            break
        _, _, _, lam = carlson_roots(xn, yn, zn)
        a, xn, yn, zn = carlson_duplicate(lam, a, xn, yn, zn)
        fac *= 0.25
    X = fac * (a0 - x) / a
    Y = fac * (a0 - y) / a
    Z = -X - Y
    e2 = X * Y - Z * Z
    e3 = X * Y * Z
    return (1.0 - e2 / 10.0 + e3 / 14.0 + e2 * e2 / 24.0 - 3.0 * e2 * e3 / 44.0) / math.sqrt(a)


@jit
def _rc1(e):
    """R_C(1, 1 + e) for e > -1: atan(sqrt e)/sqrt e, atanh(sqrt -e)/sqrt -e; series for small |e|."""
    if abs(e) < 1e-3:
        # R_C(1, 1+e) = sum (-e)^k / (2k + 1); terms to e^6 leave < 1e-21
        return 1.0 + e * (-1.0 / 3.0 + e * (1.0 / 5.0 + e * (-1.0 / 7.0 + e * (1.0 / 9.0 + e * (-1.0 / 11.0 + e / 13.0)))))
    if e > 0.0:
        s = math.sqrt(e)
        return math.atan(s) / s
    s = math.sqrt(-e)
    return math.atanh(s) / s


@jit
def _rj_series(e2, e3, e4, e5):
    """The fifth-order series that closes Carlson's R_J and R_D duplication algorithms (Carlson 1995, Numer. Algorithms 10)."""
    return (
        1.0
        - 3.0 * e2 / 14.0
        + e3 / 6.0
        + 9.0 * e2 * e2 / 88.0
        - 3.0 * e4 / 22.0
        - 9.0 * e2 * e3 / 52.0
        + 3.0 * e5 / 26.0
    )


@jit
def elliprj_scalar(x, y, z, p):
    """Carlson R_J(x, y, z, p), x, y, z >= 0 (at most one zero), p > 0 (Carlson 1995, sec. 2)."""
    a0 = (x + y + z + 2.0 * p) / 5.0
    delta = (p - x) * (p - y) * (p - z)
    q = _Q_RJ * max(abs(a0 - x), abs(a0 - y), abs(a0 - z), abs(a0 - p))
    a = a0
    fac = 1.0
    xn, yn, zn, pn = x, y, z, p
    s = 0.0
    for _ in range(_MAX_IT):
        if fac * q < abs(a):
            break
        sx, sy, sz, lam = carlson_roots(xn, yn, zn)
        sp = math.sqrt(pn)
        d = (sp + sx) * (sp + sy) * (sp + sz)
        e = fac * fac * fac * delta / (d * d)
        s += fac * _rc1(e) / d
        a, xn, yn, zn = carlson_duplicate(lam, a, xn, yn, zn)
        pn = 0.25 * (pn + lam)
        fac *= 0.25
    X = fac * (a0 - x) / a
    Y = fac * (a0 - y) / a
    Z = fac * (a0 - z) / a
    P = -0.5 * (X + Y + Z)
    e2 = X * Y + X * Z + Y * Z - 3.0 * P * P
    e3 = X * Y * Z + 2.0 * e2 * P + 4.0 * P * P * P
    e4 = (2.0 * X * Y * Z + e2 * P + 3.0 * P * P * P) * P
    e5 = X * Y * Z * P * P
    series = _rj_series(e2, e3, e4, e5)
    return fac * series / (a * math.sqrt(a)) + 6.0 * s


@jit
def _rd(x, y, z):
    """Carlson R_D(x, y, z) = R_J(x, y, z, z), x, y >= 0 (at most one zero), z > 0."""
    a0 = (x + y + 3.0 * z) / 5.0
    q = _Q_RJ * max(abs(a0 - x), abs(a0 - y), abs(a0 - z))
    a = a0
    fac = 1.0
    xn, yn, zn = x, y, z
    s = 0.0
    for _ in range(_MAX_IT):
        if fac * q < abs(a):
            break
        _, _, sz, lam = carlson_roots(xn, yn, zn)
        s += fac / (sz * (zn + lam))
        a, xn, yn, zn = carlson_duplicate(lam, a, xn, yn, zn)
        fac *= 0.25
    X = fac * (a0 - x) / a
    Y = fac * (a0 - y) / a
    Z = -(X + Y) / 3.0
    e2 = X * Y - 6.0 * Z * Z
    e3 = (3.0 * X * Y - 8.0 * Z * Z) * Z
    e4 = 3.0 * (X * Y - Z * Z) * Z * Z
    e5 = X * Y * Z * Z * Z
    series = _rj_series(e2, e3, e4, e5)
    return fac * series / (a * math.sqrt(a)) + 3.0 * s


# ---------------------------------------------------------------------------
# incomplete integrals


@jit
def _reduce_amplitude(phi):
    """phi = j pi + r with |r| <= pi/2; returns (j, sin r, cos r >= 0)."""
    j = math.floor(phi / math.pi + 0.5)
    r = phi - j * math.pi
    return j, math.sin(r), abs(math.cos(r))


@jit
def _ellipf(phi, m, m1):
    j, s, c = _reduce_amplitude(phi)
    f = s * elliprf_scalar(c * c, m1 + m * c * c, 1.0)  # 1 - m s^2 = m1 + m c^2: no cancellation
    if j != 0.0:
        f += 2.0 * j * ellipk_scalar(m1)
    return f


@jit
def _ellippi(n, phi, m, m1):
    j, s, c = _reduce_amplitude(phi)
    d2 = m1 + m * c * c
    p = 1.0 - n * s * s
    val = s * elliprf_scalar(c * c, d2, 1.0) + n / 3.0 * s * s * s * elliprj_scalar(c * c, d2, 1.0, p)
    if j != 0.0:
        complete = elliprf_scalar(0.0, m1, 1.0) + n / 3.0 * elliprj_scalar(0.0, m1, 1.0, 1.0 - n)
        val += 2.0 * j * complete
    return val


# ---------------------------------------------------------------------------
# array wrappers


@parallel_kernel("elliptic")
def ellipj_loop(u, m, m1, sn, cn, dn):
    """``(sn, cn, dn)`` of ``u[i]`` at parameter ``m[i]`` (complement ``m1[i]``) into the
    output arrays; call as ``ellipj_loop(n, ...)`` (:mod:`astrodyn.jit` thread policy)."""
    for i in prange(u.shape[0]):
        K = ellipk_scalar(m1[i])
        sn[i], cn[i], dn[i] = _sncndn(u[i], m[i], m1[i], K)


@parallel_kernel("elliptic")
def _ellipk_loop(m1, out):
    for i in prange(m1.shape[0]):
        out[i] = ellipk_scalar(m1[i])


@parallel_kernel("elliptic")
def _rf_loop(x, y, z, out):
    for i in prange(x.shape[0]):
        out[i] = elliprf_scalar(x[i], y[i], z[i])


@parallel_kernel("elliptic")
def _rd_loop(x, y, z, out):
    for i in prange(x.shape[0]):
        out[i] = _rd(x[i], y[i], z[i])


@parallel_kernel("elliptic")
def elliprj_loop(x, y, z, p, out):
    """Carlson ``R_J(x[i], y[i], z[i], p[i])`` into ``out``; call as ``elliprj_loop(n, ...)``."""
    for i in prange(x.shape[0]):
        out[i] = elliprj_scalar(x[i], y[i], z[i], p[i])


@parallel_kernel("elliptic")
def _ellipf_loop(phi, m, m1, out):
    for i in prange(phi.shape[0]):
        out[i] = _ellipf(phi[i], m[i], m1[i])


@parallel_kernel("elliptic")
def _ellippi_loop(n, phi, m, m1, out):
    for i in prange(phi.shape[0]):
        out[i] = _ellippi(n[i], phi[i], m[i], m1[i])


def _flat(*args):
    arrs = np.broadcast_arrays(*[np.asarray(a, dtype=np.float64) for a in args])
    shape = arrs[0].shape
    return shape, [np.ascontiguousarray(a).reshape(-1) for a in arrs]


def _out(x, shape):
    return x.reshape(shape) if shape else x.reshape(())[()]


def _check_m(m, m1):
    """m and m1 in [0, 1] and consistent: |m + m1 - 1| <= 1e-12 (NaN passes through)."""
    bad = (m < 0) | (m > 1) | (m1 < 0) | (m1 > 1) | (np.abs(m + m1 - 1.0) > 1e-12)
    if np.any(bad):
        i = np.flatnonzero(bad)[0]
        raise ValueError(
            f"m, m1: expected 0 <= m <= 1 and m1 = 1 - m >= 0 (given separately), "
            f"got m = {m[i]!r}, m1 = {m1[i]!r}"
        )


def ellipj(u, m, m1=None):
    """Jacobi elliptic functions ``(sn, cn, dn)`` of ``u`` for parameter ``m``.

    ``m1 = 1 - m`` should be given separately when ``m`` is near 1 (it is
    computed as ``1 - m`` if omitted).  Arrays broadcast; scalars give scalars.
    Accuracy: a few ulp absolute (``dn`` relative) for ``|u|`` up to about
    ``1e3 K``; range reduction by ``2K`` costs ``|u| eps`` beyond that.
    """
    if m1 is None:
        m1 = 1.0 - np.asarray(m, dtype=np.float64)
    shape, (u_, m_, m1_) = _flat(u, m, m1)
    _check_m(m_, m1_)
    sn, cn, dn = (np.empty_like(u_) for _ in range(3))
    ellipj_loop(u_.shape[0], u_, m_, m1_, sn, cn, dn)
    return _out(sn, shape), _out(cn, shape), _out(dn, shape)


def ellipk(m, m1=None):
    """Complete elliptic integral of the first kind ``K(m)``; ``inf`` at ``m1 = 0``."""
    if m1 is None:
        m1 = 1.0 - np.asarray(m, dtype=np.float64)
    shape, (m_, m1_) = _flat(m, m1)
    _check_m(m_, m1_)
    out = np.empty_like(m_)
    _ellipk_loop(m1_.shape[0], m1_, out)
    return _out(out, shape)


def elliprf(x, y, z):
    """Carlson ``R_F(x, y, z)`` for ``x, y, z >= 0`` with at most one zero."""
    shape, (x_, y_, z_) = _flat(x, y, z)
    if np.any((x_ < 0) | (y_ < 0) | (z_ < 0)):
        raise ValueError("x, y, z: expected non-negative arguments of R_F")
    out = np.empty_like(x_)
    _rf_loop(x_.shape[0], x_, y_, z_, out)
    return _out(out, shape)


def elliprd(x, y, z):
    """Carlson ``R_D(x, y, z)`` for ``x, y >= 0`` (at most one zero) and ``z > 0``."""
    shape, (x_, y_, z_) = _flat(x, y, z)
    if np.any((x_ < 0) | (y_ < 0) | (z_ <= 0)):
        raise ValueError("x, y, z: expected x, y >= 0 and z > 0 for R_D")
    out = np.empty_like(x_)
    _rd_loop(x_.shape[0], x_, y_, z_, out)
    return _out(out, shape)


def elliprj(x, y, z, p):
    """Carlson ``R_J(x, y, z, p)`` for ``x, y, z >= 0`` (at most one zero) and ``p > 0``."""
    shape, (x_, y_, z_, p_) = _flat(x, y, z, p)
    if np.any((x_ < 0) | (y_ < 0) | (z_ < 0) | (p_ <= 0)):
        raise ValueError("x, y, z, p: expected x, y, z >= 0 and p > 0 for R_J (no principal value)")
    out = np.empty_like(x_)
    elliprj_loop(x_.shape[0], x_, y_, z_, p_, out)
    return _out(out, shape)


def ellipf(phi, m, m1=None):
    """Incomplete integral of the first kind ``F(phi|m)`` for any real ``phi`` (rad)."""
    if m1 is None:
        m1 = 1.0 - np.asarray(m, dtype=np.float64)
    shape, (phi_, m_, m1_) = _flat(phi, m, m1)
    _check_m(m_, m1_)
    out = np.empty_like(phi_)
    _ellipf_loop(phi_.shape[0], phi_, m_, m1_, out)
    return _out(out, shape)


def ellippi(n, phi, m, m1=None):
    """Incomplete integral of the third kind ``Pi(n; phi|m)`` for ``n < 1`` and any real ``phi``."""
    if m1 is None:
        m1 = 1.0 - np.asarray(m, dtype=np.float64)
    shape, (n_, phi_, m_, m1_) = _flat(n, phi, m, m1)
    _check_m(m_, m1_)
    if np.any(n_ >= 1):
        raise ValueError("n: expected characteristic n < 1 (no principal value)")
    out = np.empty_like(phi_)
    _ellippi_loop(n_.shape[0], n_, phi_, m_, m1_, out)
    return _out(out, shape)
