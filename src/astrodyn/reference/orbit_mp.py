"""Independent 50-digit two-body propagator (mpmath), the reference for tests and benchmarks.

Universal-variable formulation (Vallado 4th ed. alg. 8, Curtis sec. 3.7):
solve ``sqrt(mu) dt = sigma chi^2 C(z) + (1 - alpha r0) chi^3 S(z) + r0 chi``
(``z = alpha chi^2``, ``sigma = r0.v0 / sqrt(mu)``) for chi.  The left side
is strictly increasing in chi (its derivative is r > 0), so the root is
bracketed by expanding (x2 / /2) from a starting value (Vallado 4th ed. alg. 8:
``tau alpha`` on ellipses, the asymptotic logarithm on hyperbolas, Barker near
the parabola), then refined by Newton's method safeguarded with bisection
(Numerical Recipes 3rd ed. sec. 9.4, ``rtsafe``: bisect whenever a Newton step
leaves the bracket or is not at least twice shorter than the step before).
A good start converges in ~10 iterations; bisection alone needs ~250.  An
iteration cap raises :class:`ReferenceNotConverged` instead of returning an
unconverged answer.  Then
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

__all__ = ["propagate_mp", "stumpff_mp", "ReferenceNotConverged"]


class ReferenceNotConverged(RuntimeError):
    """The reference iteration hit its cap (the result would not be a reference)."""


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


def _initial_guess(rn, sigma, alpha, tau, sqmu, h2):
    """Starting value of chi (Vallado 4th ed. alg. 8, p. 93), same sign as tau.

    Ellipse (alpha rn > 1e-6): chi = tau alpha (one mean motion times dt in
    sqrt(a) units).  Hyperbola (alpha rn < -1e-6): the asymptotic form
    chi = s sqrt(-a) ln(-2 mu alpha dt / (r.v + s sqrt(-mu a) (1 - rn alpha)))
    with s = sign(dt), which is exact up to O(1) in the hyperbolic anomaly for
    long arcs.  Near-parabolic: Barker's equation through the semi-latus rectum.
    Anything not finite or of the wrong sign falls back to the short-arc value
    tau / rn (which :func:`propagate_mp` also tries); its bracket search
    repairs any guess.
    """
    sgn = 1 if tau > 0 else -1
    short = tau / rn
    guess = None
    try:
        if alpha * rn > mp.mpf("1e-6"):
            guess = tau * alpha
        elif alpha * rn < -mp.mpf("1e-6"):
            a = 1 / alpha
            # sqmu * sigma = r.v; sqmu * dt = tau
            den = sqmu * sigma + sgn * mp.sqrt(-sqmu**2 * a) * (1 - rn * alpha)
            arg = -2 * sqmu * alpha * tau / den
            if arg > 1:
                guess = sgn * mp.sqrt(-a) * mp.log(arg)
        elif h2 > 0:
            p = h2 / sqmu**2
            s = mp.acot(3 * mp.sqrt(sqmu**2 / p**3) * (tau / sqmu)) / 2
            w = mp.atan(mp.cbrt(mp.tan(s))) if mp.tan(s) >= 0 else -mp.atan(mp.cbrt(-mp.tan(s)))
            guess = mp.sqrt(p) * 2 * mp.cot(2 * w)
    except (ZeroDivisionError, ValueError):
        guess = None
    if guess is None or not mp.isfinite(guess) or guess * sgn <= 0:
        guess = short
    return guess


def propagate_mp(r0, v0, dt, mu, dps=50, as_float=True, max_iter=400):
    """Propagate one state ``(3,)`` by ``dt`` [s] at ``dps`` decimal digits.

    Returns ``(r, v)`` as float64 arrays (``as_float``) or lists of mpf.
    Raises ``ValueError`` for non-finite inputs or ``mu <= 0`` and
    :class:`ReferenceNotConverged` when the root of the time equation is not
    found to ``dps + 10`` digits within ``max_iter`` function evaluations.
    """
    r0 = np.asarray(r0, dtype=float)
    v0 = np.asarray(v0, dtype=float)
    if r0.shape != (3,) or v0.shape != (3,):
        raise ValueError(f"propagate_mp: r0 and v0 must have shape (3,), got {r0.shape} and {v0.shape}")
    for name, val in (("r0", r0), ("v0", v0), ("dt", dt), ("mu", mu)):
        if not np.all(np.isfinite(val)):
            raise ValueError(f"propagate_mp: {name} must be finite, got {val!r}")
    if not float(mu) > 0:
        raise ValueError(f"propagate_mp: mu must be > 0, got {mu!r}")
    if not np.any(r0):
        raise ValueError("propagate_mp: r0 must not be the centre (|r0| = 0)")
    with mp.workdps(dps + 20):
        r0 = [mp.mpf(float(x)) for x in r0]
        v0 = [mp.mpf(float(x)) for x in v0]
        dt, mu = mp.mpf(float(dt)), mp.mpf(float(mu))
        rn = mp.sqrt(sum(x * x for x in r0))
        v2 = sum(x * x for x in v0)
        sqmu = mp.sqrt(mu)
        sigma = sum(a * b for a, b in zip(r0, v0)) / sqmu
        alpha = 2 / rn - v2 / mu
        tau = sqmu * dt
        h2 = rn**2 * v2 - (sqmu * sigma) ** 2  # |r x v|^2 (Lagrange's identity)

        def T(chi):
            z = alpha * chi * chi
            C, S = stumpff_mp(z)
            t = sigma * chi**2 * C + (1 - alpha * rn) * chi**3 * S + rn * chi - tau
            r = chi**2 * C + sigma * chi * (1 - z * S) + rn * (1 - z * C)
            return t, r

        tol = mp.mpf(10) ** (-(dps + 10))
        evals = 0
        chi = mp.mpf(0)
        if tau != 0:
            sgn = 1 if tau > 0 else -1
            # the conic's starting value or the short-arc one (tau / rn), whichever has the smaller residual
            guess = _initial_guess(rn, sigma, alpha, tau, sqmu, h2)
            t, r = T(guess)
            short = tau / rn
            t_short, r_short = T(short)
            evals += 2
            if abs(t_short) < abs(t):
                guess, t, r = short, t_short, r_short
            # bracket [lo, hi] with T(lo) < 0 < T(hi), expanding geometrically from the guess;
            # chi = 0 always has T = -tau, so the inner side ends there at the latest
            if sgn * t < 0:
                inner, outer = guess, 2 * guess
                while sgn * T(outer)[0] < 0:
                    evals += 1
                    if evals > max_iter:
                        break
                    inner, outer = outer, 2 * outer
                evals += 1
            else:
                outer, inner = guess, guess / 2
                while sgn * T(inner)[0] > 0:
                    evals += 1
                    if evals > max_iter:
                        break
                    outer, inner = inner, inner / 2
                evals += 1
            lo, hi = (inner, outer) if sgn > 0 else (outer, inner)
            chi = guess
            step_old = step = hi - lo
            converged = t == 0
            while not converged and evals < max_iter:
                newton = chi - t / r
                if abs(t / r) <= tol * abs(chi):  # the Newton correction is below the target: done
                    chi, converged = newton, True
                    break
                if not (lo < newton < hi) or abs(2 * t) > abs(step_old * r):
                    step_old, step = step, (hi - lo) / 2
                    chi = lo + step
                else:
                    step_old, step = step, chi - newton
                    chi = newton
                t, r = T(chi)
                evals += 1
                if t < 0:
                    lo = chi
                elif t > 0:
                    hi = chi
                converged = t == 0 or hi - lo <= tol * abs(chi)
            if not converged:
                raise ReferenceNotConverged(
                    f"propagate_mp: no convergence in {max_iter} evaluations for r0={[float(x) for x in r0]}, "
                    f"v0={[float(x) for x in v0]}, dt={float(dt)!r} (bracket [{mp.nstr(lo, 20)}, {mp.nstr(hi, 20)}])"
                )
        z = alpha * chi * chi
        C, S = stumpff_mp(z)
        r = chi**2 * C + sigma * chi * (1 - z * S) + rn * (1 - z * C)
        f = 1 - chi**2 * C / rn
        g = dt - chi**3 * S / sqmu
        fdot = sqmu * chi * (z * S - 1) / (r * rn)
        gdot = 1 - chi**2 * C / r
        rv = [f * a + g * b for a, b in zip(r0, v0)]
        vv = [fdot * a + gdot * b for a, b in zip(r0, v0)]
        propagate_mp.last_evaluations = evals
        if as_float:
            return np.array([float(x) for x in rv]), np.array([float(x) for x in vv])
        return rv, vv


propagate_mp.last_evaluations = 0
