"""Independent 50-digit two-body propagator (mpmath), the reference for tests and benchmarks.

Universal-variable formulation (Vallado 4th ed. alg. 8, Curtis sec. 3.7):
solve ``sqrt(mu) dt = sigma chi^2 C(z) + (1 - alpha r0) chi^3 S(z) + r0 chi``
(``z = alpha chi^2``, ``sigma = r0.v0 / sqrt(mu)``) by Newton's method
safeguarded with bisection (whenever a step leaves the bracket or the
bracket fails to halve) on a bracket found by doubling, then
``r = f r0 + g v0``, ``v = fdot r0 + gdot v0`` with
``f = 1 - chi^2 C / r0``, ``g = dt - chi^3 S / sqrt(mu)``,
``fdot = sqrt(mu) chi (z S - 1) / (r r0)``, ``gdot = 1 - chi^2 C / r``.

Stumpff functions: Taylor series for ``|z| < 1``, closed forms otherwise, all
in mpmath at the working precision plus 20 guard digits.  The float64 inputs
are taken exactly (every float is a rational number).  This module shares no
code with :mod:`astrodyn.orbit`; it is slow (milliseconds per state) by design.
"""

from __future__ import annotations

import mpmath as mp
import numpy as np

__all__ = ["propagate_mp", "stumpff_mp"]


def stumpff_mp(z):
    """``(C(z), S(z))`` = ``(c2, c3)`` at the current mpmath precision."""
    z = mp.mpf(z)
    if abs(z) < 1:
        C = S = mp.mpf(0)
        term_c, term_s, k = mp.mpf(1) / 2, mp.mpf(1) / 6, 0
        while abs(term_c) > mp.eps * 1e-3 or k < 3:
            C += term_c
            S += term_s
            k += 1
            term_c *= -z / ((2 * k + 1) * (2 * k + 2))
            term_s *= -z / ((2 * k + 2) * (2 * k + 3))
        return C, S
    if z > 0:
        s = mp.sqrt(z)
        return (1 - mp.cos(s)) / z, (s - mp.sin(s)) / s**3
    s = mp.sqrt(-z)
    return (mp.cosh(s) - 1) / (-z), (mp.sinh(s) - s) / s**3


def propagate_mp(r0, v0, dt, mu, dps=50, as_float=True):
    """Propagate one state ``(3,)`` by ``dt`` [s] at ``dps`` decimal digits.

    Returns ``(r, v)`` as float64 arrays (``as_float``) or lists of mpf.
    """
    with mp.workdps(dps + 20):
        r0 = [mp.mpf(float(x)) for x in np.asarray(r0, dtype=float)]
        v0 = [mp.mpf(float(x)) for x in np.asarray(v0, dtype=float)]
        dt, mu = mp.mpf(float(dt)), mp.mpf(float(mu))
        rn = mp.sqrt(sum(x * x for x in r0))
        v2 = sum(x * x for x in v0)
        sqmu = mp.sqrt(mu)
        sigma = sum(a * b for a, b in zip(r0, v0)) / sqmu
        alpha = 2 / rn - v2 / mu
        tau = sqmu * dt

        def T(chi):
            z = alpha * chi * chi
            C, S = stumpff_mp(z)
            t = sigma * chi**2 * C + (1 - alpha * rn) * chi**3 * S + rn * chi - tau
            r = chi**2 * C + sigma * chi * (1 - z * S) + rn * (1 - z * C)
            return t, r, C, S, z

        # bracket (T is increasing in chi, T(0) = -tau): double from a small
        # step so that the bracket [lo, hi] is tight (hi = 2 lo) from the start
        lo = hi = mp.mpf(0)
        if tau != 0:
            sgn = 1 if tau > 0 else -1
            step = mp.mpf(2) ** -20 * mp.sqrt(rn)
            while sgn * T(sgn * step)[0] < 0:
                step *= 2
            lo, hi = sorted([sgn * step / 2, sgn * step])
            if sgn * T(sgn * step / 2)[0] > 0:  # tiny |tau|: root below the first step
                lo, hi = sorted([mp.mpf(0), sgn * step])
        chi = (lo + hi) / 2
        tol = mp.mpf(10) ** (-(dps + 10))
        width = hi - lo
        for _ in range(3000):
            t, r, C, S, z = T(chi)
            if t == 0:
                break
            if t > 0:
                hi = chi
            else:
                lo = chi
            new = chi - t / r
            # Newton inside the bracket; bisection if it leaves it or stalls
            if not (lo < new < hi) or (hi - lo) > 0.5 * width:
                new = (lo + hi) / 2
            width = hi - lo
            if abs(new - chi) <= tol * (1 + abs(chi)) or hi - lo <= tol * (1 + abs(chi)):
                chi = new
                break
            chi = new
        t, r, C, S, z = T(chi)
        f = 1 - chi**2 * C / rn
        g = dt - chi**3 * S / sqmu
        fdot = sqmu * chi * (z * S - 1) / (r * rn)
        gdot = 1 - chi**2 * C / r
        rv = [f * a + g * b for a, b in zip(r0, v0)]
        vv = [fdot * a + gdot * b for a, b in zip(r0, v0)]
        if as_float:
            return np.array([float(x) for x in rv]), np.array([float(x) for x in vv])
        return rv, vv
