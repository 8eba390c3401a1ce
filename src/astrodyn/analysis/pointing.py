"""The section "pointing" of ``astrodyn analyze``: how well a body held the attitude its
config asks for (``[bodies.pointing] target``, :class:`astrodyn.scenario.control.Pointing`).

The pointing error at each recorded state is the rotation angle between the attitude
``q`` and the target, ``2 acos |target . q|`` (Euler parameters scalar first; the absolute
value because ``q`` and ``-q`` are one attitude).  It settles at the first time after
which it stays within the target's tolerance to the end; the section gives the error at
the start and at the end, when it settled, and the largest error after that.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from astrodyn.scenario.recorded import recorded_body

__all__ = ["pointing_errors", "settling_time", "pointing_section", "POINTING_FIGURES"]

POINTING_FIGURES = {"pointing-error": "pointing error against the config's target, and its tolerance"}


def pointing_errors(q: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Rotation angle (rad) between each attitude ``q`` ``(n, 4)`` and ``target`` ``(4,)``,
    both unit Euler parameters, scalar first."""
    dot = np.abs(np.asarray(q, dtype=np.float64) @ np.asarray(target, dtype=np.float64))
    return 2.0 * np.arccos(np.clip(dot, 0.0, 1.0))


def settling_time(t: np.ndarray, error: np.ndarray, tolerance: float) -> float | None:
    """The first time after which ``error`` stays ``<= tolerance`` to the end; None if the
    last sample is outside it."""
    outside = np.flatnonzero(np.asarray(error) > tolerance)
    if outside.size == 0:
        return float(t[0])
    k = int(outside[-1]) + 1
    return float(t[k]) if k < len(t) else None


def pointing_section(run, name: str, stem: Path) -> tuple[dict, list[tuple[str, Path]]]:
    """``({"pointing": numbers}, figures)`` for body ``name`` of ``run`` when its config
    names a pointing target and it has attitude states; ``({}, [])`` otherwise."""
    config = recorded_body(run.scenario, name)
    pointing = None if config is None else config.pointing
    body = run.bodies.get(name)
    track = None if body is None else body.attitude
    if pointing is None or track is None or len(track) == 0:
        return {}, []
    from astrodyn.analysis import figures as fg  # matplotlib: only when a report is drawn

    t = np.asarray(track.t, dtype=np.float64)
    error = pointing_errors(np.asarray(track.q), pointing.target)
    settled = settling_time(t, error, pointing.tolerance)
    after = error[t >= settled] if settled is not None else np.empty(0)
    numbers = {
        "target (e0, e1, e2, e3)": [float(x) for x in pointing.target],
        "tolerance (deg)": float(np.degrees(pointing.tolerance)),
        "error at start (deg)": float(np.degrees(error[0])),
        "error at end (deg)": float(np.degrees(error[-1])),
        "settled at t (s)": settled,
        "max error after settling (deg)": float(np.degrees(np.max(after))) if after.size else None,
    }
    deg = np.degrees(error)[:, None]
    fig = fg.stacked_pairs(t, deg, np.full_like(deg, np.degrees(pointing.tolerance)), "error", "tolerance",
                           "angle (deg)", f"{name}: pointing error against the target", Path(f"{stem}-pointing-error.png"))
    return {"pointing": numbers}, [("pointing-error", fig)]
