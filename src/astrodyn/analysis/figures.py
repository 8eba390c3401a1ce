"""Figures of the analysis report (matplotlib, Agg backend), one PNG per function.

Every function takes the arrays of :mod:`astrodyn.analysis.metrics`, writes one PNG and
returns its path.  Axes carry units; the time axis is in s, min, h or days, chosen from
the span (:func:`time_axis`) so tick labels stay short.
"""

from __future__ import annotations

import contextlib
import contextvars
import functools
from collections.abc import Iterator
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

__all__ = ["envelope", "ENVELOPE_RUNS", "drawing", "time_axis", "stacked_pairs", "orbit_3d", "ground_track", "elements", "orbit_drift", "crosscheck",
           "euler_angles", "quaternion", "body_rates", "polhode", "attitude_drift", "top_angles", "appendage_tips",
           "flexible_drift", "contact_path", "rolling_angles", "gyro_indications"]

_DPI = 110
plt.rcParams.update({"font.size": 9, "axes.grid": True, "grid.alpha": 0.3, "axes.formatter.useoffset": False})


def time_axis(t: np.ndarray) -> tuple[np.ndarray, str]:
    """(t scaled, label) in s, min, h or days depending on the span."""
    span = float(t[-1] - t[0]) if t.size > 1 else 0.0
    for limit, factor, unit in ((600, 1.0, "s"), (3 * 3600, 60.0, "min"), (3 * 86400, 3600.0, "h")):
        if span <= limit:
            return t / factor, f"t ({unit} since epoch)"
    return t / 86400.0, "t (days since epoch)"


#: A time series longer than twice this is drawn through the smallest and largest value of
#: each of this many runs of consecutive samples (:func:`envelope`): at the figures' width
#: (825 px) that is several runs per pixel column, so the drawing shows every extreme (a
#: drift's peaks, a spike) as the full series would, with bounded memory and time (a
#: 345,600-state day at 4 Hz drew ~700 MB of Agg paths before).
ENVELOPE_RUNS = 4096
def envelope(x: np.ndarray, y: np.ndarray, runs: int = ENVELOPE_RUNS, log: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """``(x, y)`` of a line as drawn: for more than ``2 runs`` samples, the samples holding the
    least and the greatest ``y`` of each of ``runs`` runs of consecutive samples (NaN are
    neither; with ``log``, for a log axis, values <= 0 neither: they are not drawn), and the
    first and last, in their order; else ``(x, y)`` as they are.  ``y`` is (n,).  Not for
    points drawn as dots, whose cloud it would thin to its edges."""
    y = np.asarray(y)
    n = y.shape[0]
    if n <= 2 * runs:
        return x, y
    size = -(-n // runs)
    values = np.asarray(y, dtype=np.float64)
    nan = np.isnan(values) | (values <= 0) if log else np.isnan(values)
    low = np.full(runs * size, np.inf)
    high = np.full(runs * size, -np.inf)
    low[:n] = np.where(nan, np.inf, values)
    high[:n] = np.where(nan, -np.inf, values)
    start = np.arange(runs) * size
    index = np.concatenate([start + low.reshape(runs, size).argmin(axis=1),
                            start + high.reshape(runs, size).argmax(axis=1), [0, n - 1]])
    index = np.unique(index[index < n])
    return np.asarray(x)[index], y[index]


def _save(fig, path: Path) -> Path:
    fig.savefig(path, dpi=_DPI)
    plt.close(fig)
    return path


def _stacked(t, series, labels, title, path, dots=(), log=False):
    """One panel per series over a shared time axis; series indices in ``dots`` are drawn
    as points (angles that wrap at +-180 deg would otherwise draw vertical lines).  With
    ``log`` the y axes are logarithmic (errors and drifts span decades; exact zeros, such as
    the drift at the first instant, are left out of the plot, not clipped to a made-up floor)."""
    ts, tl = time_axis(t)
    fig, axes = plt.subplots(len(series), 1, figsize=(7.5, 1.6 + 1.45 * len(series)), sharex=True,
                             constrained_layout=True)
    axes = np.atleast_1d(axes)
    for k, (ax, y, label) in enumerate(zip(axes, series, labels)):
        if k in dots:
            ax.plot(ts, y, ".", ms=1.5)
        else:
            ax.plot(*envelope(ts, y, log=log), lw=1.0)
        if log and np.any(np.asarray(y) > 0):
            ax.set_yscale("log", nonpositive="mask")
        ax.set_ylabel(label)
    axes[-1].set_xlabel(tl)
    fig.suptitle(title)
    return _save(fig, path)


def stacked_pairs(t, a, b, label_a: str, label_b: str, ylabel: str, title: str, path: Path) -> Path:
    """One panel per column of ``a`` (m, n) against ``t`` (m,), with the same column of ``b``
    (or None) dashed in the same panel: commanded vs applied, speed vs limit."""
    a = np.asarray(a, dtype=np.float64)
    ts, tl = time_axis(np.asarray(t, dtype=np.float64))
    n = a.shape[1]
    fig, axes = plt.subplots(n, 1, figsize=(7.5, 1.6 + 1.45 * n), sharex=True, constrained_layout=True)
    axes = np.atleast_1d(axes)
    for k, ax in enumerate(axes):
        ax.plot(*envelope(ts, a[:, k]), lw=1.0, label=label_a)
        if b is not None:
            ax.plot(*envelope(ts, np.asarray(b, dtype=np.float64)[:, k]), "--", lw=1.0, label=label_b)
        ax.set_ylabel(f"{ylabel} [{k}]" if n > 1 else ylabel)
    if b is not None:
        axes[0].legend(loc="best", fontsize=7)
    axes[-1].set_xlabel(tl)
    fig.suptitle(title)
    return _save(fig, path)


def orbit_3d(name: str, r: np.ndarray, radius: float | None, path: Path) -> Path:
    """Trajectory in the inertial frame (km) with the central body as a wire sphere."""
    fig = plt.figure(figsize=(6.5, 6.0), constrained_layout=True)
    ax = fig.add_subplot(projection="3d")
    km = r / 1e3
    ax.plot(km[:, 0], km[:, 1], km[:, 2], lw=1.0, label=name)
    ax.scatter(*km[0], s=14, color="green", label="start")
    ax.scatter(*km[-1], s=14, color="red", label="end")
    extent = np.max(np.abs(km))
    if radius:
        u, v = np.mgrid[0:2 * np.pi:24j, 0:np.pi:12j]
        rk = radius / 1e3
        ax.plot_wireframe(rk * np.cos(u) * np.sin(v), rk * np.sin(u) * np.sin(v), rk * np.cos(v), color="0.6", lw=0.4)
        extent = max(extent, rk)
    for set_lim in (ax.set_xlim, ax.set_ylim, ax.set_zlim):
        set_lim(-extent, extent)
    ax.set_box_aspect((1, 1, 1))
    ax.set_xlabel("x (km)")
    ax.set_ylabel("y (km)")
    ax.set_zlabel("z (km)")
    ax.legend(loc="upper left", fontsize=8)
    ax.set_title(f"{name}: orbit, inertial frame")
    return _save(fig, path)


def ground_track(name: str, lon: np.ndarray, lat: np.ndarray, path: Path) -> Path:
    """Longitude / latitude (deg) with breaks where the track wraps at +-180 deg."""
    fig, ax = plt.subplots(figsize=(8.0, 4.2), constrained_layout=True)
    lo, la = np.degrees(lon), np.degrees(lat)
    breaks = np.flatnonzero(np.abs(np.diff(lo)) > 180.0) + 1
    for seg_lo, seg_la in zip(np.split(lo, breaks), np.split(la, breaks)):
        ax.plot(seg_lo, seg_la, lw=1.0, color="C0")
    ax.scatter(lo[0], la[0], s=16, color="green", label="start", zorder=3)
    ax.scatter(lo[-1], la[-1], s=16, color="red", label="end", zorder=3)
    ax.set_xlim(-180, 180)
    ax.set_ylim(-90, 90)
    ax.set_xticks(range(-180, 181, 60))
    ax.set_yticks(range(-90, 91, 30))
    ax.set_xlabel("longitude (deg)")
    ax.set_ylabel("geocentric latitude (deg)")
    ax.legend(loc="lower left", fontsize=8)
    ax.set_title(f"{name}: ground track (GMST IAU 1982, UT1 = UTC)")
    return _save(fig, path)


def elements(name: str, t: np.ndarray, el, path: Path) -> Path:
    """a (km), e, i, RAAN, argument of periapsis (unwrapped), true anomaly (deg, points)."""
    deg = np.degrees
    series = [el.a / 1e3, el.e, deg(el.i), deg(np.unwrap(el.raan)), deg(np.unwrap(el.argp)), deg(np.mod(el.nu, 2 * np.pi))]
    labels = ["a (km)", "e (-)", "i (deg)", "RAAN (deg)", "arg. periapsis (deg)", "true anomaly (deg)"]
    return _stacked(t, series, labels, f"{name}: osculating elements", path, dots=(5,))


def orbit_drift(name: str, t: np.ndarray, energy_drift, h_drift, path: Path, between_burns: bool = False,
                energy: str = "E (two-body)", momentum: str = "h", note: str = "") -> Path:
    """Relative drift (dimensionless) of an orbit's energy and angular momentum: those its
    model conserves (``energy`` and ``momentum`` name them, as the report's "conserved
    quantities" rows: ``E (two-body)`` and ``h``, or ``E (with J2)`` and ``h_z``, which
    drifts relative to ``|h0|``), or, for a model that conserves none, the two-body ones
    with a ``note`` that says so.  ``between_burns``: the drifts were taken over each coast
    arc from its own first state (E0, h0), as for an orbit that burns moved, and the
    labels say so."""
    arcs = "; {} at each coast arc's start" if between_burns else ""
    m = momentum.split()[0]
    return _stacked(t, [energy_drift, h_drift],
                    [f"{energy}:\n|E - E0| / |E0| (-{arcs.format('E0')})",
                     f"{momentum}:\n|{m} - {m}0| / |h0| (-{arcs.format('h0')})"],
                    f"{name}: drift of {energy} and {momentum}{' between burns' if between_burns else ''} "
                    f"(log scale){chr(10) + note if note else ''}", path, log=True)


def crosscheck(name: str, t: np.ndarray, dr_norm, dv_norm, path: Path) -> Path:
    """Difference to the REBOUND cross-check (m, m/s)."""
    return _stacked(t, [dr_norm, dv_norm], ["|dr| (m)", "|dv| (m/s)"], f"{name}: difference to REBOUND (log scale)", path, log=True)


def euler_angles(name: str, t: np.ndarray, angles, seq: str, path: Path) -> Path:
    deg = np.degrees(angles)
    labels = [f"angle {i + 1}, axis {seq[i]} (deg)" for i in range(3)]
    return _stacked(t, [deg[:, 0], deg[:, 1], deg[:, 2]], labels, f"{name}: Euler angles, body sequence {seq}", path,
                    dots=(0, 1, 2))


def quaternion(name: str, t: np.ndarray, q, path: Path) -> Path:
    ts, tl = time_axis(t)
    fig, ax = plt.subplots(figsize=(7.5, 3.6), constrained_layout=True)
    for i in range(4):
        ax.plot(*envelope(ts, q[:, i]), lw=1.0, label=f"e{i}")
    ax.set_xlabel(tl)
    ax.set_ylabel("Euler parameter (-)")
    ax.set_ylim(-1.05, 1.05)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    ax.set_title(f"{name}: Euler parameters (scalar e0 first)")
    return _save(fig, path)


def body_rates(name: str, t: np.ndarray, w, path: Path) -> Path:
    return _stacked(t, [w[:, 0], w[:, 1], w[:, 2]], ["w1 (rad/s)", "w2 (rad/s)", "w3 (rad/s)"],
                    f"{name}: body angular velocity", path)


def polhode(name: str, h_body: np.ndarray, inertia: np.ndarray, path: Path) -> Path:
    """The polhode: the body-frame angular momentum on the momentum sphere |H| = const.

    It is the intersection of that sphere with the energy ellipsoid H . I^-1 H = 2T.
    Left: the sphere (wire frame) and the path; right: the path seen along the body
    axis it stays closest to (equal scales), where a small polhode is readable.
    """
    hn = np.linalg.norm(h_body[0])
    hh = h_body / hn
    fig = plt.figure(figsize=(10.0, 4.8), constrained_layout=True)
    ax = fig.add_subplot(1, 2, 1, projection="3d")
    u, v = np.mgrid[0:2 * np.pi:28j, 0:np.pi:14j]
    ax.plot_wireframe(np.cos(u) * np.sin(v), np.sin(u) * np.sin(v), np.cos(v), color="0.8", lw=0.3)
    ax.plot(hh[:, 0], hh[:, 1], hh[:, 2], lw=1.6, color="C3", label="polhode", zorder=5)
    ax.scatter(*hh[0], s=14, color="green", label="start", zorder=6)
    moments = np.diag(inertia)
    for i in range(3):
        ax.text(*(1.3 * np.eye(3)[i]), f"b{i + 1}", fontsize=8)
    ax.set_box_aspect((1, 1, 1))
    for set_ticks in (ax.set_xticks, ax.set_yticks, ax.set_zticks):
        set_ticks([-1, 0, 1])
    ax.set_xlabel("H1 / |H| (-)")
    ax.set_ylabel("H2 / |H| (-)")
    ax.set_zlabel("H3 / |H| (-)")
    ax.legend(loc="upper left", fontsize=8)
    ax.set_title("on the momentum sphere")
    k = int(np.argmax(np.abs(hh.mean(axis=0))))
    i, j = [a for a in range(3) if a != k]
    ax2 = fig.add_subplot(1, 2, 2)
    ax2.plot(hh[:, i], hh[:, j], lw=1.2, color="C3")
    ax2.plot(hh[0, i], hh[0, j], "o", color="green", ms=4)
    ax2.set_aspect("equal", adjustable="datalim")
    ax2.set_xlabel(f"H{i + 1} / |H| (-)")
    ax2.set_ylabel(f"H{j + 1} / |H| (-)")
    ax2.set_title(f"seen along body axis b{k + 1}")
    fig.suptitle(f"{name}: polhode, |H| = {hn:.4g} kg m²/s, I = ({', '.join(f'{m:.3g}' for m in moments)}) kg m²")
    return _save(fig, path)


def attitude_drift(name: str, t: np.ndarray, energy_drift, h_drift, path: Path) -> Path:
    return _stacked(t, [energy_drift, h_drift], ["|T - T0| / |T0| (-)", "|Hi - Hi0| / |Hi0| (-)"],
                    f"{name}: kinetic energy and inertial angular momentum drift (log scale)", path, log=True)


def top_angles(name: str, t: np.ndarray, precession, nutation, path: Path) -> Path:
    return _stacked(t, [np.degrees(precession), np.degrees(nutation)], ["precession phi (deg)", "nutation theta (deg)"],
                    f"{name}: precession and nutation (3-1-3 angles, gravity along -Z)", path)


def appendage_tips(name: str, t: np.ndarray, tip: np.ndarray, path: Path) -> Path:
    """Each appendage's tip displacement from its undeformed position, |tip| in m (``tip``
    ``(T, N, 3)``, body axes), one line per appendage in config order."""
    ts, tl = time_axis(t)
    fig, ax = plt.subplots(figsize=(7.5, 3.2), constrained_layout=True)
    mags = np.linalg.norm(tip, axis=-1)
    for k in range(mags.shape[1]):
        ax.plot(*envelope(ts, mags[:, k]), lw=1.0, label=f"appendage {k}")
    ax.set_ylabel("|tip displacement| (m)")
    ax.set_xlabel(tl)
    if mags.shape[1] <= 12:
        ax.legend(fontsize=7, ncol=min(4, mags.shape[1]))
    fig.suptitle(f"{name}: appendage tip displacements (body axes)")
    return _save(fig, path)


def flexible_drift(name: str, t: np.ndarray, energy_ratio, h_drift, nutation_deg, damped: bool, path: Path) -> Path:
    """A flexible spacecraft's energy ``E / E0`` (falls when damped), its inertial angular
    momentum drift ``|Hi - Hi0| / |Hi0|`` (log scale) and the angle between H and body axis
    3 (deg: an energy sink turns a minor-axis spinner towards 90 deg, a flat spin)."""
    ts, tl = time_axis(t)
    fig, axes = plt.subplots(3, 1, figsize=(7.5, 6.0), sharex=True, constrained_layout=True)
    axes[0].plot(*envelope(ts, energy_ratio), lw=1.0)
    axes[0].set_ylabel("E / E0, E = T + V (-)")
    axes[1].plot(*envelope(ts, h_drift, log=True), lw=1.0)
    if np.any(np.asarray(h_drift) > 0):
        axes[1].set_yscale("log", nonpositive="mask")
    axes[1].set_ylabel("|Hi - Hi0| / |Hi0| (-)")
    axes[2].plot(*envelope(ts, nutation_deg), lw=1.0)
    axes[2].set_ylabel("angle H to body axis 3 (deg)")
    axes[-1].set_xlabel(tl)
    fig.suptitle(f"{name}: energy ({'damped appendages' if damped else 'undamped: conserved'}), momentum, nutation")
    return _save(fig, path)


def contact_path(name: str, contact: np.ndarray, center: np.ndarray, path: Path) -> Path:
    """A rolling disk's contact point and centre seen from above (x, y on the plane, m),
    equal axes, the start marked."""
    fig, ax = plt.subplots(figsize=(5.5, 5.0), constrained_layout=True)
    ax.plot(contact[:, 0], contact[:, 1], lw=1.0, label="contact point")
    ax.plot(center[:, 0], center[:, 1], lw=0.8, ls="--", label="centre (projected)")
    ax.plot(contact[:1, 0], contact[:1, 1], "o", ms=4, label="start")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.legend(fontsize=7)
    fig.suptitle(f"{name}: path on the plane (from above)")
    return _save(fig, path)


def rolling_angles(name: str, t: np.ndarray, lean, heading, path: Path) -> Path:
    return _stacked(t, [np.degrees(lean), np.degrees(heading)], ["lean theta (deg)", "heading psi (deg)"],
                    f"{name}: lean from the vertical and heading of the rolling disk", path)


def gyro_indications(name: str, t: np.ndarray, indicated: np.ndarray, truth: np.ndarray, labels: list[str],
                     path: Path) -> Path:
    """Each gyroscope's indication against the truth it measures (``indicated``, ``truth``
    (T, n); a rate gyro's input rate in rad/s, a rate-integrating gyro's input angle in rad),
    one panel per gyroscope: the two curves, and their difference on a second axis."""
    ts, tl = time_axis(t)
    n = indicated.shape[1]
    fig, axes = plt.subplots(n, 1, figsize=(7.5, 1.6 + 1.6 * n), sharex=True, constrained_layout=True)
    axes = np.atleast_1d(axes)
    for k, ax in enumerate(axes):
        ax.plot(*envelope(ts, truth[:, k]), lw=1.2, label="truth (from the attitude)")
        ax.plot(*envelope(ts, indicated[:, k]), lw=0.8, ls="--", label="indicated")
        ax.set_ylabel(labels[k])
        err = ax.twinx()
        err.plot(*envelope(ts, indicated[:, k] - truth[:, k]), lw=0.6, color="tab:red")
        err.set_ylabel("indicated - truth", color="tab:red", fontsize=7)
        if k == 0:
            ax.legend(fontsize=7, loc="upper left")
    axes[-1].set_xlabel(tl)
    fig.suptitle(f"{name}: single-axis gyroscopes, indication against the body's motion")
    return _save(fig, path)


# ---------------------------------------------------------------------------------------
# Figures on or off: a report of many bodies draws those of the first few only (drawing one
# body's figures takes ~1-5 s; 1000 bodies' would take an hour), with the numbers of all.

_DRAW = contextvars.ContextVar("astrodyn_analysis_draw", default=True)


@contextlib.contextmanager
def drawing(on: bool) -> Iterator[None]:
    """Within this block every figure function of this module draws (``on``) or returns
    None at once, without touching matplotlib."""
    token = _DRAW.set(bool(on))
    try:
        yield
    finally:
        _DRAW.reset(token)


def _when_drawing(f):
    @functools.wraps(f)
    def figure_or_none(*args, **kwargs):
        return f(*args, **kwargs) if _DRAW.get() else None
    return figure_or_none


for _name in __all__:
    if _name not in ("drawing", "time_axis"):
        globals()[_name] = _when_drawing(globals()[_name])
