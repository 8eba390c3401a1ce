"""Integrating a model's equations with scipy's DOP853 to given output times.

The models whose equations are not (yet) compiled kernels -- the rolling disk
(:mod:`astrodyn.attitude.rolling_disk`), the flexible spacecraft
(:mod:`astrodyn.attitude.flexible`) and the gyroscopes (:mod:`astrodyn.attitude.gyroscopes`)
-- integrate with scipy's DOP853 (Hairer-Norsett-Wanner's 8(5,3) pair) and sample the
solution at the caller's times: the same checks and the same call, here once.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

__all__ = ["check_output_times", "integrate_dop853"]


def check_output_times(t) -> np.ndarray:
    """``t`` as a 1-D float64 array of finite, non-decreasing times starting at 0 (s);
    ValueError naming ``t`` otherwise."""
    try:
        t = np.asarray(t, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise ValueError("t: expected finite, non-decreasing times starting at 0 (s)") from None
    if t.size == 0 or t[0] != 0.0 or np.any(np.diff(t) < 0) or not np.all(np.isfinite(t)):
        raise ValueError("t: expected finite, non-decreasing times starting at 0 (s)")
    return t


def integrate_dop853(rhs: Callable, y0: np.ndarray, t: np.ndarray, rtol: float, atol: float,
                     what: str, events: list | None = None):
    """``(states (len(t), len(y0)), nfev)``: ``dy/dt = rhs(t, y)`` from ``y0`` at ``t = 0``,
    sampled at the times ``t`` (:func:`check_output_times`) by scipy's DOP853 with the
    tolerances ``rtol``, ``atol``.  RuntimeError naming ``what`` when the integrator fails
    (a step size below round-off: a singular or diverging motion).  With ``events``
    (scipy's event functions; a terminal one ends the integration) the result is
    ``(states, nfev, t_events)`` and ``states`` holds the times before a terminal event."""
    from scipy.integrate import solve_ivp

    if t[-1] == 0.0:
        states = np.tile(y0, (t.size, 1))
        return (states, 0) if events is None else (states, 0, [np.zeros(0) for _ in events])
    sol = solve_ivp(rhs, (0.0, float(t[-1])), y0, method="DOP853", t_eval=t, rtol=rtol, atol=atol, events=events)
    if not sol.success:
        raise RuntimeError(f"{what}: DOP853 failed: {sol.message}")
    return (sol.y.T, sol.nfev) if events is None else (sol.y.T, sol.nfev, sol.t_events)
