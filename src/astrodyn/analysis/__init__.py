"""``astrodyn analyze FILE.mcap [--out DIR] [--seq 321]``: a report with plots from a recording.

::

    from astrodyn.analysis import analyze
    report = analyze("demo.mcap", "demo-report")
    report["bodies"]["iss"]["orbit"]["energy_drift_max"]  # the numbers of the report

Writes into ``DIR`` (default ``<file>-report``):

* ``report.md``   -- per body a table of numbers and the figures (Markdown);
* ``report.html`` -- the same page for a browser, PNGs embedded by relative path;
* ``report.json`` -- every number of the report (what the tests check);
* ``<body>-<figure>.png`` -- per body with an orbit: ``orbit3d``, ``groundtrack``
  (Earth-centred runs), ``elements``, ``orbit-drift``, ``crosscheck`` (if recorded);
  with an attitude: ``euler``, ``quaternion``, ``rates``, and when the inertia is in the
  scenario metadata ``polhode`` and ``attitude-drift``; for heavy tops ``top-angles``;
  for flexible spacecraft ``appendages`` and ``flexible-drift`` instead of the rigid two,
  for rolling disks ``contact-path`` and ``rolling-angles``; with gyroscopes on board ``gyros``.

Definitions of every number: :mod:`astrodyn.analysis.metrics`.  An orbit that burns moved
(a closed loop's impulses or thrust, read from its ``<body>/actuators`` and applied
``<body>/command`` channels: :class:`astrodyn.analysis.closed_loop.OrbitActuation`) has
its energy and angular momentum judged between burns: drifts over each coast arc
(``energy_coast_drift_max``, the rows ``... between burns``), the burns' changes listed
in its closed-loop section.  A cut or damaged file is
analysed up to what is complete and the report says so at the top (with the first invalid
message and its reason); so does a channel with duplicated or missing sequence numbers
(count, channel, the missing seqs) or whose ``t`` does not increase with seq (the first
place; :func:`sequence_issues`, the check ``export`` makes too), which ``astrodyn analyze``
also prints as a warning.  A file with no valid state of any (chosen) body is nothing to
analyse: :class:`~astrodyn.recording.RecordingError` (:func:`nothing_to_analyse`; exit 1,
as ``export`` of a file with nothing to export), no report written.

What each number is: the orbit table's ``E`` and ``h`` are the two-body ones whatever the
model (the rows say so, and a note when the model does not conserve them, as a J2 orbit);
the quantities the model conserves are the "conserved quantities" rows, and the
``orbit-drift`` figure draws those (``E (with J2)`` and ``h_z`` for a J2 orbit).  The
attitude table's ``T`` and ``H_i`` are the rigid body's, computed as the conserved rows'
(:func:`astrodyn.analysis.metrics.inertial_from_body`).  Recorded values that are finite
but whose squares or products exceed float64 (an ``r`` of 1e308 m) give numbers that are
not: numpy's overflow warnings are silenced and the body's section "non-finite numbers"
names them and the largest recorded value of each of its channels.
"""

from __future__ import annotations

import argparse
import fnmatch
import html
import json
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from astrodyn.analysis.closed_loop import CLOSED_LOOP_FIGURES, OrbitActuation, closed_loop_section
from astrodyn.analysis.pointing import POINTING_FIGURES, pointing_section
from astrodyn.files import output_path_problem, path_argument
from astrodyn.progress import Progress
from astrodyn.recording import RecordingError, Track, load
from astrodyn.recording.outputs import staging_directory, warn_incomplete_input
from astrodyn.recording.reader import SEQ_NOT_COUNTED, sequence_issues, sequence_note
from astrodyn.signals import deferred_interrupts, interruptible_main

__all__ = ["analyze", "main", "FIGURES", "nothing_to_analyse", "orbit_arc_starts", "SEQ_NOT_COUNTED", "sequence_issues", "sequence_note", "check_report_options",
           "ReportOptionError"]

#: figure name -> what it shows (report captions)
FIGURES = {
    "orbit3d": "orbit in 3D (inertial frame, km)",
    "groundtrack": "ground track",
    "elements": "osculating orbital elements",
    "orbit-drift": "drift of the energy and angular momentum its model conserves (E and h two-body, or with J2: E "
                   "with the zonal potential and h_z)",
    "crosscheck": "difference to the REBOUND cross-check",
    "euler": "Euler angles",
    "quaternion": "Euler parameters",
    "rates": "body angular velocity",
    "polhode": "polhode on the momentum sphere",
    "attitude-drift": "rigid-body kinetic energy and inertial angular momentum drift",
    "top-angles": "precession and nutation",
    "appendages": "tip displacement of each flexible appendage",
    "flexible-drift": "energy, angular momentum drift and nutation of a flexible spacecraft",
    "contact-path": "a rolling disk's path on the plane",
    "gyros": "single-axis gyroscopes: indication against the body's motion",
    "rolling-angles": "a rolling disk's lean and heading",
    **CLOSED_LOOP_FIGURES,
    **POINTING_FIGURES,
}

_SEQS = ("121", "123", "131", "132", "212", "213", "231", "232", "312", "313", "321", "323")


def _fmt(x) -> str:
    if isinstance(x, float):
        return f"{x:.6g}"
    return str(x)


#: Bodies whose figures a report draws by default (the first by name); the numbers cover all.
FIGURE_BODIES = 12


#: The ``astrodyn analyze`` flag of each :func:`analyze` argument (:class:`ReportOptionError`).
_FLAGS = {"seq": "--seq", "bodies": "--bodies", "figures_for": "--figures-for"}


class ReportOptionError(ValueError):
    """A bad ``seq``, ``bodies`` or ``figures_for`` of :func:`analyze`.  ``str`` names the
    Python argument (``"seq: expected one of ..."``); :attr:`flag_message` says the same
    naming the ``astrodyn analyze`` flag (``"--seq: expected one of ..."``), which the
    command line prints."""

    def __init__(self, argument: str, reason: str):
        super().__init__(f"{argument}: {reason}")
        self.argument, self.reason = argument, reason

    @property
    def flag_message(self) -> str:
        return f"{_FLAGS[self.argument]}: {self.reason}"


def _cli_message(exc: ValueError) -> str:
    """``exc``'s text for the command line: a :class:`ReportOptionError` names the flag."""
    return exc.flag_message if isinstance(exc, ReportOptionError) else str(exc)


def check_report_options(seq: str, bodies: Sequence[str] | None, figures_for: int) -> None:
    """:class:`ReportOptionError` (a ValueError) naming the argument (``seq``, ``bodies``,
    ``figures_for``; its :attr:`~ReportOptionError.flag_message` the flag ``--seq``,
    ``--bodies``, ``--figures-for``) and what it allows, for a value wrong whatever the
    recording: judged before the file is read (``astrodyn analyze`` exits 2 for these).  A
    ``bodies`` pattern that matches no body of the recording is the recording's matter
    (:func:`select_bodies`, exit 1)."""
    if seq not in _SEQS:
        raise ReportOptionError("seq", f"expected one of {', '.join(_SEQS)} (the Euler angle sequence), got {seq!r}")
    if bodies is not None and (isinstance(bodies, str) or not all(isinstance(p, str) and p.strip() for p in bodies)):
        shown = bodies if isinstance(bodies, str) else ",".join(map(str, bodies))
        raise ReportOptionError("bodies", f"expected comma-separated body names or shell patterns, none empty (e.g. "
                                          f"'sat-00*,leo'), got {shown!r}")
    if type(figures_for) is not int or figures_for < 0:
        raise ReportOptionError("figures_for", f"expected an integer >= 0, got {figures_for!r}")


def select_bodies(names, patterns: Sequence[str] | None) -> list[str]:
    """The body names (sorted) that match any of ``patterns`` (names or shell globs such as
    ``sat-00*``; None: all); :class:`ReportOptionError` (a ValueError) naming ``bodies``
    and a pattern that matches none."""
    names = sorted(names)
    if patterns is None:
        return names
    chosen = set()
    for pattern in patterns:
        found = fnmatch.filter(names, pattern)
        if not found:
            shown = ", ".join(names[:8]) + (", ..." if len(names) > 8 else "")
            raise ReportOptionError("bodies", f"{pattern!r} matches no body of the recording (it has {len(names)}: {shown})")
        chosen.update(found)
    return [n for n in names if n in chosen]


def analyze(path: str | os.PathLike, out: str | os.PathLike | None = None, seq: str = "321",
            bodies: Sequence[str] | None = None, figures_for: int = FIGURE_BODIES,
            progress: Progress | None = None) -> dict:
    """Write the report of ``path`` into ``out``; returns the numbers (as in report.json).

    ``bodies``: names or shell patterns of the bodies to report (default all);
    ``figures_for``: draw the figures of the first this many of them (by name; the numbers
    cover every one): a figure takes ~0.2-1 s to draw, so a scene of 1000 bodies with all of
    them would take about an hour.  ``progress``: where to say how far it is (reading the
    file, then body k of n; ``astrodyn analyze`` passes a :class:`~astrodyn.progress.Progress`
    on stderr), None for nothing.  A bad ``seq``, ``bodies`` or ``figures_for`` raises
    :class:`ReportOptionError` naming the argument (``astrodyn analyze`` prints its flag)."""
    from astrodyn.scenario.planning import counted  # the progress lines' numbers (scenario: not needed before)

    check_report_options(seq, bodies, figures_for)
    started = time.monotonic()
    if progress is not None and os.path.isfile(path):  # (a missing file: load says so, nothing before it)
        progress.done(f"analyze: reading {os.fspath(path)} ({os.path.getsize(path) / 1e6:.1f} MB)")
    run = load(path)
    names = select_bodies(run.bodies, bodies)
    if not any(_has_states(run.bodies[name]) for name in names):
        raise RecordingError(nothing_to_analyse(run, names, bodies is not None))
    if progress is not None:
        progress.done(f"analyze: {run.messages} messages read in {time.monotonic() - started:.1f} s; "
                      f"{counted(len(names), 'body', 'bodies')} to report, figures for {min(figures_for, len(names))}")
    out = Path(out) if out is not None else Path(os.fspath(path)).with_suffix("").with_name(Path(path).stem + "-report")
    # written in a work directory inside out, moved into place once complete (astrodyn.recording.outputs)
    with staging_directory(out, "analyze", cannot=lambda exc: RecordingError(
            f"{out}: cannot create the report directory: {exc.strerror or exc}")) as work:
        report = _write_report(run, names, work, seq, figures_for, progress)
        with deferred_interrupts():  # the whole report or, on a signal before this, nothing of it
            for f in sorted(work.iterdir(), key=lambda f: (f.name.startswith("report."), f.name)):  # pages last
                os.replace(f, out / f.name)
    if progress is not None:
        progress.done(f"analyze: {counted(len(names), 'body', 'bodies')} reported in {time.monotonic() - started:.1f} s")
    return report


def _has_states(body) -> bool:
    """Whether a body of ``load(path).bodies`` holds a state on any of its channels."""
    return any(isinstance(track, Track) and len(track) for track in vars(body).values())


def nothing_to_analyse(run, names: list[str], chosen: bool) -> str:
    """Why ``run`` gives no report (none of the bodies ``names`` holds a state; ``chosen``:
    they are those ``bodies`` selected): which channels it has instead, or that every
    state message was invalid, and the reader's account of the file (the cut, the first
    invalid message and its reason).  The error :func:`analyze` raises (exit 1)."""
    if not run.bodies:
        topics = list(run.channels)
        shown = ", ".join(topics[:5]) + (f", and {len(topics) - 5} more" if len(topics) > 5 else "")
        what = (f"no astrodyn state channel (<scenario>/<body>/orbit, attitude, ...) among its {len(topics)} "
                f"channel{'' if len(topics) == 1 else 's'} ({shown})" if topics else "no channel")
    else:
        shown = ", ".join(names[:5]) + (f", and {len(names) - 5} more" if len(names) > 5 else "")
        what = f"no valid state of {'the bodies chosen by --bodies' if chosen else 'any body'} ({shown})"
    why = run.incomplete_reason
    return f"{run.path}: nothing to analyse: {what}" + (f"; {why}" if why else "")


def _non_finite(numbers: dict, body) -> dict:
    """The section "non-finite numbers" of a body whose numbers include NaN or infinity
    (finite recorded states whose squares or products exceed float64: an |r| of 1e308 m
    makes ``h = r x v`` overflow): which numbers, and the largest recorded value of each of
    the body's state channels with its seq, so the report says why ({} when all are finite)."""
    found = [f"{section}: {label}" for section, values in numbers.items() if isinstance(values, dict)
             for label, value in _rows({k: v for k, v in values.items() if isinstance(v, float) and not np.isfinite(v)})]
    if not found:
        return {}
    largest = []
    for kind, track in vars(body).items():
        if not isinstance(track, Track) or not len(track):
            continue
        fields = {k: np.abs(a).reshape(len(track), -1) for k, a in track.fields.items()
                  if a.dtype.kind == "f" and k != "t"}
        if fields:
            field, a = max(fields.items(), key=lambda kv: float(np.max(kv[1])))
            k = int(np.argmax(np.max(a, axis=1)))
            largest.append((float(np.max(a[k])), f"{kind} {field} = {_fmt(float(np.max(a[k])))} at seq {int(track.seq[k])}"))
    shown = "; ".join(found[:5]) + (f"; and {len(found) - 5} more" if len(found) > 5 else "")
    return {"non-finite numbers": {
        "numbers": shown,
        "why": "the recorded states are finite but their squares or products exceed float64 (about 1.8e308)",
        "largest recorded values": "; ".join(text for _, text in sorted(largest, reverse=True))}}


def _write_report(run, names: list[str], out: Path, seq: str, figures_for: int, progress: Progress | None) -> dict:
    """Write the figures and report.md / .html / .json of ``names`` into ``out``; the numbers."""
    from astrodyn.analysis import figures as fg, metrics as mt

    central = mt.central_body_from_scenario(run.scenario)
    inertias = mt.inertia_from_scenario(run.scenario)
    earth = str(central.get("name", "")).lower() == "earth"
    report: dict = {
        "file": run.path, "scenario": run.scenario.get("name", "?"), "epoch": run.scenario.get("epoch", "?"),
        "messages": run.messages, "complete": run.complete, "file_report": run.incomplete_reason,
        "euler_sequence": seq, "bodies": {}, "figures": {},
        "bodies_in_file": len(run.bodies), "figures_drawn_for": min(figures_for, len(names)),
        "sequence": sequence_issues(run),
    }
    for i, name in enumerate(names):
        if progress is not None:
            progress.show(lambda i=i, name=name: f"analyze: body {i + 1} of {len(names)}: {name}")
        # hostile but finite states (1e308 m) overflow the formulas: numpy's warnings are silenced
        # and the report names the numbers that are not finite and the values behind them
        with fg.drawing(i < figures_for), np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            numbers, report["figures"][name] = _body_report(run, name, run.bodies[name], out / name, seq,
                                                            central, inertias, earth)
        report["bodies"][name] = {**numbers, **_non_finite(numbers, run.bodies[name])}
    _write_markdown(report, out / "report.md")
    _write_html(report, out / "report.html")
    (out / "report.json").write_text(json.dumps(report, indent=1, default=str))
    return report


def _body_report(run, name: str, body, stem: Path, seq: str, central: dict, inertias: dict, earth: bool
                 ) -> tuple[dict, dict[str, str]]:
    """``(numbers, figures)`` of one body: its sections and ``{kind: PNG file name}`` of the
    figures drawn (none outside :func:`astrodyn.analysis.figures.drawing`)."""
    from astrodyn.analysis import figures as fg, metrics as mt

    numbers: dict = {}
    figs: list[tuple[str, Path]] = []
    arc_starts = orbit_arc_starts(run, name, body)
    if body.orbit is not None and len(body.orbit) > 0:
        tr = body.orbit
        mu = float(tr.mu[0])
        om = mt.orbit_metrics(tr.t, tr.r, tr.v, mu, arc_starts)
        numbers["orbit"] = {**om["summary"], "models": sorted(set(tr.model)), "frame": sorted(set(tr.frame))[0]}
        figs.append(("orbit3d", fg.orbit_3d(name, tr.r, central.get("radius"), Path(f"{stem}-orbit3d.png"))))
        if earth:
            lon, lat = mt.ground_track(tr.r, tr.log_time)
            figs.append(("groundtrack", fg.ground_track(name, lon, lat, Path(f"{stem}-groundtrack.png"))))
        figs.append(("elements", fg.elements(name, tr.t, om["elements"], Path(f"{stem}-elements.png"))))
        models = sorted(set(tr.model))
        quantities = _orbit_quantities(run, name, tr)
        two_body = quantities.energy_name == "E (two-body)" if quantities is not None else models == ["kepler"]
        if not two_body:  # the orbit table's E and h are two-body (metrics): say what they are here
            own = (f"{quantities.energy_name} and {quantities.momentum_name}, under \"conserved quantities\""
                   if quantities is not None else "none: a third body moves")
            numbers["orbit"]["two_body_note"] = (f"E and h above are the two-body quantities, which {', '.join(models)} "
                                                 f"does not conserve (their change is the perturbation's effect); the "
                                                 f"ones it conserves: {own}")
        figs.append(("orbit-drift", _orbit_drift_figure(name, tr, om, quantities, arc_starts, two_body, models, stem)))
    if body.crosscheck is not None and len(body.crosscheck) > 0:
        cc = body.crosscheck
        numbers["crosscheck"] = {"dr_max_m": float(np.max(cc.dr_norm)), "dv_max_m_s": float(np.max(cc.dv_norm)),
                                 "reference": sorted(set(cc.reference))[0]}
        figs.append(("crosscheck", fg.crosscheck(name, cc.t, cc.dr_norm, cc.dv_norm, Path(f"{stem}-crosscheck.png"))))
    if body.attitude is not None and len(body.attitude) > 0:
        tr = body.attitude
        # a flexible body's hub alone, a rolling disk (the plane's forces) conserve neither T
        # nor H: their rows are their models' own (below)
        inertia = inertias.get(name) if not set(tr.model) & {"flexible", "rolling_disk"} else None
        am = mt.attitude_metrics(tr.t, tr.q, tr.w, seq, inertia)
        numbers["attitude"] = {**am["summary"], "models": sorted(set(tr.model))}
        figs.append(("euler", fg.euler_angles(name, tr.t, am["euler"], seq, Path(f"{stem}-euler.png"))))
        figs.append(("quaternion", fg.quaternion(name, tr.t, tr.q, Path(f"{stem}-quaternion.png"))))
        figs.append(("rates", fg.body_rates(name, tr.t, tr.w, Path(f"{stem}-rates.png"))))
        if set(tr.model) == {"flexible"}:  # the hub's rigid invariants mean nothing: the whole system's
            section, more = _flexible_section(run, name, body, stem)
            numbers.update(section)
            figs += more
        elif set(tr.model) == {"rolling_disk"}:
            section, more = _rolling_section(body, stem)
            numbers.update(section)
            figs += more
        elif inertia is not None and "actuated" not in set(tr.model):  # commanded torques: no polhode, no drift
            figs.append(("polhode", fg.polhode(name, am["h_body"], inertia.inertia, Path(f"{stem}-polhode.png"))))
            figs.append(("attitude-drift", fg.attitude_drift(name, tr.t, am["energy_drift"], am["h_inertial_drift"],
                                                             Path(f"{stem}-attitude-drift.png"))))
            if inertia.is_top:
                figs.append(("top-angles", fg.top_angles(name, tr.t, am["precession"], am["nutation"], Path(f"{stem}-top-angles.png"))))
    if body.gimbals is not None and len(body.gimbals) and body.attitude is not None and len(body.attitude):
        section, more = _gyro_section(run, name, body, stem)
        numbers.update(section)
        figs += more
    numbers.update(_conserved(run.scenario, name, body, arc_starts))
    section, more = closed_loop_section(run, name, stem)  # commands, actuators, momentum, pointing, dv, burns
    numbers.update(section)
    figs += more
    section, more = pointing_section(run, name, stem)  # against the config's target, if it names one
    numbers.update(section)
    figs += more
    return numbers, {kind: p.name for kind, p in figs if p is not None}


def _orbit_quantities(run, name: str, tr):
    """The energy and momentum body ``name``'s orbit model conserves, per recorded state
    (:func:`astrodyn.analysis.invariants.recorded_orbit_quantities`: those of its
    "conserved quantities" rows), or None (a third body; no constants recorded)."""
    from astrodyn.analysis.invariants import recorded_orbit_quantities

    try:
        return recorded_orbit_quantities(run.scenario, name, str(tr.model[-1]), tr.r, tr.v)
    except ValueError:  # the metadata's constants do not fit the model: its rows are two-body as well
        return None


def _orbit_drift_figure(name: str, tr, om: dict, quantities, arc_starts: np.ndarray | None, two_body: bool,
                        models: list[str], stem: Path) -> Path | None:
    """The orbit-drift figure: the drift of the energy and angular momentum the orbit's
    model conserves (``quantities``, :func:`_orbit_quantities`: E with J2 and h_z for a J2
    orbit), over each coast arc for an orbit that burns moved; for a model that conserves
    none (a third body), the two-body drift, titled so (``two_body`` False)."""
    from astrodyn.analysis import figures as fg, metrics as mt

    path = Path(f"{stem}-orbit-drift.png")
    between_burns = arc_starts is not None
    if quantities is None:
        note = "" if two_body else f"(two-body E and h: {', '.join(models)} conserves neither)"
        return fg.orbit_drift(name, tr.t, om["energy_drift"], om["h_drift"], path, between_burns=between_burns,
                              note=note)
    energy_drift = mt.relative_drift_over_arcs(quantities.energy, arc_starts, quantities.energy_scale)
    momentum_drift = mt.relative_drift_over_arcs(quantities.momentum, arc_starts, quantities.momentum_scale)
    return fg.orbit_drift(name, tr.t, energy_drift, momentum_drift, path, between_burns=between_burns,
                          energy=quantities.energy_name, momentum=quantities.momentum_name)


def _flexible_section(run, name: str, body, stem: Path) -> tuple[dict, list[tuple[str, Path]]]:
    """A flexible spacecraft (hub attitude plus the appendages key): the tip displacements,
    the system's energy and inertial angular momentum, the nutation angle of H from body
    axis 3 (:mod:`astrodyn.analysis.invariants`)."""
    from astrodyn.analysis import figures as fg
    from astrodyn.analysis.invariants import appendage_arrays, flexible_states, recorded_spacecraft
    from astrodyn.attitude import flexible as fx
    from astrodyn.rotation import dcm_from_quat

    tr, app = body.attitude, body.appendages
    arrays = appendage_arrays(app) if app is not None and len(app) else None
    text = run.scenario.get("json")
    sc = recorded_spacecraft(text, name) if isinstance(text, str) else None
    if arrays is None or sc is None:
        return {"appendages": {"note": "no appendages channel or no spacecraft in the metadata: hub attitude only"}}, []
    eta, eta_dot, tip = arrays
    _, ia, ie = np.intersect1d(tr.seq, app.seq, return_indices=True)
    if eta.shape[1] != sc.n_elastic or not ia.size:
        return {"appendages": {"note": "appendage states do not match the recorded spacecraft"}}, []
    t, q, w = tr.t[ia], tr.q[ia], tr.w[ia]
    states = flexible_states(sc, q, w, eta[ie], eta_dot[ie])
    energy = fx.spacecraft_energy(sc, states)
    _, h = fx.spacecraft_momentum(sc, states)
    axis3 = dcm_from_quat(q)[:, 2, :]  # body axis 3 in inertial components: row 3 of C
    hn = np.linalg.norm(h, axis=1)
    nutation = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", axis3, h) / np.where(hn > 0, hn, 1.0), -1.0, 1.0)))
    h_drift = np.linalg.norm(h - h[0], axis=1) / (hn[0] or 1.0)
    section = {"appendages": {
        "appendages": int(tip.shape[1]),
        "tip_max_m": [float(x) for x in np.max(np.linalg.norm(tip, axis=-1), axis=0)],
        "energy_first_J": float(energy[0]), "energy_last_J": float(energy[-1]),
        "nutation_first_deg": float(nutation[0]), "nutation_last_deg": float(nutation[-1]),
        "damped": bool(sc.damped),
    }}
    figs = [("appendages", fg.appendage_tips(name, app.t, tip, Path(f"{stem}-appendages.png"))),
            ("flexible-drift", fg.flexible_drift(name, t, energy / energy[0] if energy[0] else energy, h_drift, nutation,
                                                 sc.damped, Path(f"{stem}-flexible-drift.png")))]
    return section, figs


def _gyro_section(run, name: str, body, stem: Path) -> tuple[dict, list[tuple[str, Path]]]:
    """The body's single-axis gyroscopes (its gimbals key) against its recorded motion: a
    rate gyro's indication against the body rate about its input axis, a rate-integrating
    gyro's against the angle turned about it (trapezoidal integral of that rate from the
    first sample); input axes and types from the recording's config."""
    from astrodyn.analysis import figures as fg

    try:
        meta = json.loads(run.scenario.get("json") or "{}")
        gyros = next(b for b in meta.get("bodies", []) if b.get("name") == name)["gyros"]
        axes = np.array([np.asarray(g["mount"], dtype=np.float64)[0] for g in gyros])
        types = [str(g["type"]) for g in gyros]
        indicated = np.array([np.asarray(row, dtype=np.float64) for row in body.gimbals.indicated])
    except (StopIteration, KeyError, TypeError, ValueError, IndexError, AttributeError, RecursionError):
        return {"gyros": {"note": "gyroscopes not described in the recording's config"}}, []
    _, ia, ig = np.intersect1d(body.attitude.seq, body.gimbals.seq, return_indices=True)
    if indicated.ndim != 2 or indicated.shape[1] != len(types) or axes.shape != (len(types), 3) or ia.size < 2:
        return {"gyros": {"note": "gimbal states do not match the recorded gyroscopes"}}, []
    t = body.attitude.t[ia]
    rate = body.attitude.w[ia] @ axes.T  # (T, n) the body's rate about each input axis
    angle = np.vstack([np.zeros((1, rate.shape[1])), np.cumsum(0.5 * (rate[1:] + rate[:-1]) * np.diff(t)[:, None], axis=0)])
    truth = np.where(np.array(types) == "rate", rate, angle)
    ind = indicated[ig]
    labels = [f"{k}: {ty} ({'rad/s' if ty == 'rate' else 'rad'})" for k, ty in enumerate(types)]
    section = {"gyros": {"types": types,
                         "max_error": [float(x) for x in np.max(np.abs(ind - truth), axis=0)],
                         "max_truth": [float(x) for x in np.max(np.abs(truth), axis=0)]}}
    return section, [("gyros", fg.gyro_indications(name, t, ind, truth, labels, Path(f"{stem}-gyros.png")))]


def _rolling_section(body, stem: Path) -> tuple[dict, list[tuple[str, Path]]]:
    """A rolling disk (its rolling key): lean range, path length, the contact path and the
    angles (:class:`astrodyn.messages.RollingState`)."""
    from astrodyn.analysis import figures as fg

    tr = body.rolling
    if tr is None or not len(tr) or not {"contact", "center", "lean", "heading"} <= set(tr.fields):
        return {"rolling": {"note": "no rolling channel: attitude only"}}, []
    name = stem.name
    steps = np.linalg.norm(np.diff(tr.contact, axis=0), axis=1)
    section = {"rolling": {"lean_min_deg": float(np.degrees(np.min(tr.lean))),
                           "lean_max_deg": float(np.degrees(np.max(tr.lean))),
                           "path_length_m": float(np.sum(steps)),
                           "displacement_m": float(np.linalg.norm(tr.contact[-1] - tr.contact[0]))}}
    figs = [("contact-path", fg.contact_path(name, tr.contact, tr.center, Path(f"{stem}-contact-path.png"))),
            ("rolling-angles", fg.rolling_angles(name, tr.t, tr.lean, tr.heading, Path(f"{stem}-rolling-angles.png")))]
    return section, figs


def orbit_arc_starts(run, name: str, body) -> np.ndarray | None:
    """The coast arcs of body ``name``'s recorded orbit when burns moved it (True at each
    state that begins one: :meth:`astrodyn.analysis.closed_loop.OrbitActuation.arc_starts`,
    from the body's ``actuators`` and applied ``command`` channels); None without an orbit
    or a burn."""
    if body.orbit is None or not len(body.orbit):
        return None
    prefix = f"astrodyn/{run.scenario.get('name', '')}/{name}/"
    actuation = OrbitActuation()
    actuation.add(run.channels.get(prefix + "actuators"), run.channels.get(prefix + "command"))
    return actuation.arc_starts(body.orbit.t) if actuation else None


def _conserved(scenario: dict, name: str, body, orbit_arc_starts: np.ndarray | None = None) -> dict:
    """The section "conserved quantities": each invariant of the body's model
    (:mod:`astrodyn.analysis.invariants`), the same rows as ``astrodyn run``'s summary;
    an orbit that burns moved (``orbit_arc_starts``) judged between its burns."""
    from astrodyn.analysis.invariants import own_state_arrays, recorded_invariants
    from astrodyn.messages import MODEL_STATE_KINDS

    kinds = {}
    if body.orbit is not None and len(body.orbit) > 0:
        kinds["orbit"] = (body.orbit.model[-1], body.orbit.r, body.orbit.v)
    if body.attitude is not None and len(body.attitude) > 0:
        model = body.attitude.model[-1]
        kinds["attitude"] = (model, body.attitude.q, body.attitude.w)
        track = getattr(body, MODEL_STATE_KINDS.get(model, ""), None)
        arrays = own_state_arrays(model, track)
        if arrays is not None:  # a flexible or rolling body: its states on both channels, step by step
            _, ia, ie = np.intersect1d(body.attitude.seq, track.seq, return_indices=True)
            kinds["attitude"] = (model, body.attitude.q[ia], body.attitude.w[ia])
            kinds["own"] = {k: a[ie] for k, a in arrays.items()}
    if not kinds:
        return {}
    rows = recorded_invariants(scenario, name, **kinds, orbit_arc_starts=orbit_arc_starts if "orbit" in kinds else None)
    section = {}
    for kind, invs in rows.items():
        for inv in invs:
            if inv.conserved:
                section[f"{kind}: {inv.name} [{inv.unit}], max drift relative to {inv.scale}"] = inv.drift
            else:
                section[f"{kind}: {inv.name}"] = "-"
    return {"conserved quantities": section} if section else {}


_LABELS = {
    "states": "states", "t_span_s": "time span (s), max t - min t",
    # the orbit table's E and h are the two-body ones whatever the model (metrics.orbit_metrics);
    # the model's own are the "conserved quantities" rows
    "energy_drift_max": "max |E - E0| / |E0|, two-body E = |v|^2/2 - mu/|r|",
    "h_drift_max": "max |h - h0| / |h0|, two-body h = r x v", "two_body_note": "note",
    # an orbit that burns moved: the drift over each coast arc, from its first state (E0, h0)
    "coast_arcs": "coast arcs between burns (2 states or more)",
    "energy_coast_drift_max": "max |E - E0| / |E0| over each coast arc, two-body E (burns change E by design)",
    "h_coast_drift_max": "max |h - h0| / |h0| over each coast arc, two-body h (burns change h by design)",
    "energy_coast_drift_max_abs": "max |E - E0| over each coast arc, two-body E (J/kg; an arc with E0 = 0, so "
                                  "absolute)",
    "h_coast_drift_max_abs": "max |h - h0| over each coast arc, two-body h (m^2/s; an arc with h0 = 0, so absolute)",
    "r_min_m": "min radius (m)", "r_max_m": "max radius (m)",
    "models": "models", "frame": "frame", "dr_max_m": "max |dr| to REBOUND (m)", "dv_max_m_s": "max |dv| to REBOUND (m/s)",
    "reference": "reference", "quat_norm_error_max": "max ||q| - 1|", "rate_max_rad_s": "max |w| (rad/s)",
    # the rigid body's T and H_i (metrics.attitude_metrics; a gyrostat's conserved H_i adds its
    # rotors': the "conserved quantities" rows)
    "kinetic_energy_drift_max": "max |T - T0| / |T0|, rigid-body T = w.Iw/2",
    "h_inertial_drift_max": "max |Hi - Hi0| / |Hi0|, rigid-body Hi = C(q)^T I w",
    "nutation_min_deg": "min nutation (deg)", "nutation_max_deg": "max nutation (deg)",
    # a quantity that starts at 0 (a body at rest, a parabola): its absolute drift, in its unit
    "energy_drift_max_abs": "max |E - E0|, two-body E (J/kg; E0 = 0, so absolute)",
    "h_drift_max_abs": "max |h - h0|, two-body h (m^2/s; h0 = 0, so absolute)",
    "kinetic_energy_drift_max_abs": "max |T - T0|, rigid-body T (J; T0 = 0, so absolute)",
    "h_inertial_drift_max_abs": "max |Hi - Hi0|, rigid-body Hi (N m s; Hi0 = 0, so absolute)",
}


def _rows(section: dict) -> list[tuple[str, str]]:
    return [(_LABELS.get(k, k), ", ".join(_fmt(x) for x in v) if isinstance(v, list) else _fmt(v))
            for k, v in section.items()]


def at_a_glance(report: dict) -> list[str]:
    """One sentence per body for the top of the report: what was recorded, over what span,
    and the worst figure of merit (the largest drift of a conserved quantity of the body's
    model, and the largest difference to the REBOUND cross-check), so a reader sees whether
    the run is trustworthy before any table."""
    lines = []
    for name, numbers in report["bodies"].items():
        parts = []
        for kind in ("orbit", "attitude"):
            sec = numbers.get(kind)
            if sec:
                parts.append(f"{kind} ({', '.join(sec.get('models', []))}): {sec.get('states', '?')} states over "
                             f"{_fmt(float(sec.get('t_span_s', 0.0)))} s")
        conserved = {k: v for k, v in numbers.get("conserved quantities", {}).items() if isinstance(v, float)}
        if conserved:  # a drift that is not finite (NaN, inf: "non-finite numbers") is the worst
            worst = max(conserved, key=lambda k: (not np.isfinite(conserved[k]),
                                                  conserved[k] if np.isfinite(conserved[k]) else 0.0))
            value = conserved[worst]
            parts.append(f"largest drift of a conserved quantity {value:.2g} ({worst.split(',')[0]})" if np.isfinite(value)
                         else f"a conserved quantity's drift is not finite ({worst.split(',')[0]}: see "
                              f"\"non-finite numbers\")")
        cc = numbers.get("crosscheck")
        if cc:
            parts.append(f"differs from {cc.get('reference', 'REBOUND')} by at most {cc['dr_max_m']:.2g} m")
        lines.append(f"{name}: " + ("; ".join(parts) if parts else "no states") + ".")
    return lines


def figures_note(report: dict) -> str:
    """The sentence that says which bodies the report covers and draws, when not all."""
    n, shown, drawn = report["bodies_in_file"], len(report["bodies"]), report["figures_drawn_for"]
    if drawn == shown == n:
        return ""
    which = f"{shown} of the {n} bodies (`--bodies`)" if shown < n else ("the one body" if n == 1 else f"all {n} bodies")
    return (f"Numbers for {which}; figures for the first {drawn} of them by name (`--figures-for N`: a figure "
            f"takes about a second to draw).")


def _write_markdown(report: dict, path: Path) -> None:
    lines = [f"# astrodyn report: {report['scenario']}", "",
             f"File `{report['file']}`, epoch {report['epoch']}, {report['messages']} messages, "
             f"Euler sequence {report['euler_sequence']}.", ""]
    if not report["complete"]:
        lines += [f"**Incomplete file**: {report['file_report'] or 'invalid messages skipped'}.", ""]
    if report["sequence"]:
        lines += [f"**Sequence numbers**: {sequence_note(report['sequence'])}.", ""]
    lines += [f"{figures_note(report)}", ""] if figures_note(report) else []
    lines += ["At a glance:", ""] + [f"- {line}" for line in at_a_glance(report)] + [""]
    for name, numbers in report["bodies"].items():
        lines += [f"## {name}", ""]
        for section, values in numbers.items():
            lines += [f"### {section}", "", "| quantity | value |", "| --- | --- |"]
            lines += [f"| {k.replace('|', chr(92) + '|')} | {v} |" for k, v in _rows(values)] + [""]
        for kind, file in report["figures"][name].items():
            lines += [f"![{name}: {FIGURES[kind]}]({file})", ""]
    path.write_text("\n".join(lines))


def _write_html(report: dict, path: Path) -> None:
    e = html.escape
    parts = ["<!doctype html><html><head><meta charset='utf-8'>",
             f"<title>astrodyn report: {e(report['scenario'])}</title>",
             "<style>body{font-family:sans-serif;max-width:980px;margin:auto}table{border-collapse:collapse}"
             "td,th{border:1px solid #ccc;padding:2px 8px}img{max-width:100%}</style></head><body>",
             f"<h1>astrodyn report: {e(report['scenario'])}</h1>",
             f"<p>File <code>{e(report['file'])}</code>, epoch {e(report['epoch'])}, {report['messages']} messages, "
             f"Euler sequence {e(report['euler_sequence'])}.</p>"]
    if not report["complete"]:
        parts.append(f"<p><b>Incomplete file</b>: {e(report['file_report'] or 'invalid messages skipped')}.</p>")
    if report["sequence"]:
        parts.append(f"<p><b>Sequence numbers</b>: {e(sequence_note(report['sequence']))}.</p>")
    if figures_note(report):
        parts.append(f"<p>{e(figures_note(report))}</p>")
    parts.append("<p>At a glance:</p><ul>" + "".join(f"<li>{e(line)}</li>" for line in at_a_glance(report)) + "</ul>")
    for name, numbers in report["bodies"].items():
        parts.append(f"<h2>{e(name)}</h2>")
        for section, values in numbers.items():
            parts.append(f"<h3>{e(section)}</h3><table><tr><th>quantity</th><th>value</th></tr>")
            parts += [f"<tr><td>{e(k)}</td><td>{e(v)}</td></tr>" for k, v in _rows(values)]
            parts.append("</table>")
        for kind, file in report["figures"][name].items():
            parts.append(f"<figure><img src='{e(file)}' alt='{e(name)}: {e(FIGURES[kind])}'>"
                         f"<figcaption>{e(name)}: {e(FIGURES[kind])}</figcaption></figure>")
    parts.append("</body></html>")
    path.write_text("\n".join(parts))


@interruptible_main("astrodyn analyze")
def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="astrodyn analyze", description="Report (Markdown, HTML, PNG) from an MCAP recording.",
                                 epilog="Exit status: 0 written; 1 the input cannot be analysed or the report not "
                                        "written (a file with nothing to analyse, no valid state of any body, and a "
                                        "--bodies pattern matching no body of this recording included); "
                                        "2 a bad flag value or an --out that is not a directory that can be made; "
                                        "128 + the signal when interrupted.")
    ap.add_argument("file", type=path_argument,
                    help="MCAP file recorded by astrodyn, or a sweep directory (with summary.csv)")
    ap.add_argument("--out", default=None, type=path_argument, help="report directory (default <file>-report)")
    ap.add_argument("--seq", default="321", help="Euler angle sequence for the attitude plots (default 321)")
    ap.add_argument("--bodies", default=None, metavar="NAMES",
                    help="comma-separated body names or shell patterns to report, e.g. 'sat-00*,leo' (default: all)")
    ap.add_argument("--figures-for", type=int, default=FIGURE_BODIES, metavar="N",
                    help=f"draw the figures of the first N reported bodies by name; the numbers cover all "
                         f"(default {FIGURE_BODIES}; 0: none)")
    ap.add_argument("--quiet", action="store_true", help="no progress lines on stderr (warnings and errors stay)")
    args = ap.parse_args(argv)
    bodies = None if args.bodies is None else [p.strip() for p in args.bodies.split(",")]
    try:  # the command line alone: exit 2, before the input is read
        check_report_options(args.seq, bodies, args.figures_for)
        problem = None if args.out is None else output_path_problem(args.out, directory=True)
        if problem is not None:
            raise ValueError(f"--out {args.out}: {problem}")
    except ValueError as exc:
        print(f"astrodyn analyze: error: {_cli_message(exc)}", file=sys.stderr)
        return 2
    if Path(args.file).is_dir():
        if not (Path(args.file) / "summary.csv").is_file():
            print(f"astrodyn analyze: error: {args.file}: expected an MCAP file or a sweep directory with summary.csv",
                  file=sys.stderr)
            return 1
        from astrodyn.analysis.sweep import sweep_report

        out = Path(args.out) if args.out else Path(args.file) / "report"
        try:
            sweep_report(args.file, out)
        except (RecordingError, ValueError) as exc:
            print(f"astrodyn analyze: error: {exc}", file=sys.stderr)
            return 1
        except OSError as exc:
            print(f"astrodyn analyze: error: {args.file}: cannot make the sweep report"
                  f"{' (' + str(exc.filename) + ')' if exc.filename else ''}: {exc.strerror or exc}; nothing in "
                  f"{out} was replaced", file=sys.stderr)
            return 1
        print(out / "report.md")
        return 0
    try:
        report = analyze(args.file, args.out, args.seq, bodies, args.figures_for, Progress(enabled=not args.quiet))
    except (RecordingError, ValueError) as exc:
        print(f"astrodyn analyze: error: {_cli_message(exc)}", file=sys.stderr)
        return 1
    except OSError as exc:  # writing the report: e.g. the disk is full
        print(f"astrodyn analyze: error: cannot write the report{' file ' + str(exc.filename) if exc.filename else ''}: "
              f"{exc.strerror or exc}; nothing in the report directory was replaced", file=sys.stderr)
        return 1
    out = Path(args.out) if args.out else Path(args.file).with_name(Path(args.file).stem + "-report")
    if not report["complete"]:
        warn_incomplete_input("analyze", args.file, report["file_report"], "analysed what is complete")
    if report["sequence"]:
        print(f"astrodyn analyze: warning: {args.file}: {sequence_note(report['sequence'])}", file=sys.stderr)
    overflowed = [name for name, numbers in report["bodies"].items() if "non-finite numbers" in numbers]
    if overflowed:
        first = report["bodies"][overflowed[0]]["non-finite numbers"]
        print(f"astrodyn analyze: warning: {args.file}: numbers not finite for {len(overflowed)} "
              f"bod{'y' if len(overflowed) == 1 else 'ies'} ({overflowed[0]}: {first['numbers']}; largest recorded "
              f"values: {first['largest recorded values']}): see \"non-finite numbers\" in the report", file=sys.stderr)
    print(out / "report.html")
    return 0
