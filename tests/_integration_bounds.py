"""Error bounds of an adaptive integrator, shared by the tests of the scipy-integrated models.

scipy's DOP853 accepts a step when ``RMS_i(err_i / (atol + rtol |y_i|)) <= 1``, so every
component's local error obeys ``|err_i| <= sqrt(N) (atol + rtol |y_i|)``.  An invariant of
the exact flow (energy, momentum) is conserved from wherever a step lands, so one step can
move it by at most ``sum_i |d invariant / d y_i| |err_i|`` (first order); a run of ``n``
steps by ``n`` times that.  Gradients by central differences at a few of the states.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["dop853_step_bound", "dop853_drift_bound"]


def dop853_step_bound(invariant, states, rtol: float, atol: float) -> float:
    """Largest change of ``invariant`` one accepted DOP853 step can make (first order),
    worst over about six of ``states``."""
    worst = 0.0
    for y in states[:: max(1, len(states) // 6)]:
        g = []
        for i in range(y.size):
            h = 1e-6 * max(1.0, abs(y[i]))
            yp, ym = y.copy(), y.copy()
            yp[i] += h
            ym[i] -= h
            g.append(np.linalg.norm(np.atleast_1d(invariant(yp) - invariant(ym))) / (2 * h))
        worst = max(worst, math.sqrt(y.size) * float(np.sum(np.array(g) * (atol + rtol * np.abs(y)))))
    return worst


def dop853_drift_bound(invariant, states, nfev: int, rtol: float, atol: float) -> float:
    """Bound on the drift of ``invariant`` over a run of ``nfev`` evaluations: at most
    ``nfev / 12`` steps (12 evaluations per DOP853 step) of :func:`dop853_step_bound`."""
    return nfev / 12.0 * dop853_step_bound(invariant, states, rtol, atol)
