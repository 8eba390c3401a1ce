"""The end-of-run summary of ``astrodyn run``: what the file holds, body by body.

Everything here is read back from the recording (:func:`astrodyn.recording.load_blocks`), not
taken from what the propagators say they published, so anything in the file that did
not come from the run would show (docs/security.md).  Per body and kind: the model, the
states recorded, and the drift of each quantity the model conserves
(:mod:`astrodyn.analysis.invariants`: two-body energy and h for Kepler orbits, energy
with the zonal potential and h_z for J2 / zonal orbits, T and H_i for torque-free
bodies, ...), with its unit and what the drift is relative to; the REBOUND cross-check
difference in metres.  An orbit that burns moved (a closed loop's impulses or thrust,
docs/control.md) is judged between its burns: its rows are ``... between burns``, their
drift taken over each coast arc from that arc's first state
(:class:`astrodyn.analysis.closed_loop.OrbitActuation`), not across a burn, which changes
the energy and angular momentum by design.  :func:`propagator_rows` gives what the propagators measured on
what they published, for comparison.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from astrodyn.analysis.closed_loop import OrbitActuation
from astrodyn.analysis.invariants import own_state_arrays, recorded_invariants
from astrodyn.analysis.metrics import coast_arc_first
from astrodyn.messages import ACTUATED_MODEL, ATTITUDE_PROCESS_KINDS, MODEL_STATE_KINDS
from astrodyn.scenario import Scenario, plan as make_plan
from astrodyn.scenario.planning import counted, state_kinds_text

__all__ = ["file_summary", "propagator_rows", "print_summary", "sim_time_reached", "table_lines", "FileRows", "TWO_BODY_KEYS"]

#: The names of the two-body energy and |h| deviations (relative to mu/|r0| and |h0|) of an
#: orbit: ``TWO_BODY_KEYS[True]`` for a model that conserves them (Kepler; an actuated orbit
#: between its burns), a drift; ``TWO_BODY_KEYS[False]`` for one that does not (J2, zonals,
#: third bodies), the physical change.  Used by the propagators' end-of-run lines too.
TWO_BODY_KEYS = {True: ("energy_drift", "momentum_drift"),
                 False: ("two_body_energy_change", "two_body_momentum_change")}


class FileRows(list):
    """The rows of :func:`file_summary` (a list of dicts, one per body) and what reading
    the file back skipped, in ``read_back``: ``invalid`` messages (with ``invalid_by_channel``
    and the first ``examples``) and ``corrupt_chunks``.  :func:`print_summary` says so when
    either is not 0: the table counts only the states the reader returned."""

    def __init__(self, rows=(), read_back: dict | None = None):
        super().__init__(rows)
        self.read_back = read_back or {"invalid": 0, "invalid_by_channel": {}, "examples": [], "corrupt_chunks": 0}


def propagator_rows(result: dict, scenario: Scenario) -> list[dict] | None:
    """Per body: models, states logged (the logger's per-channel counts) and the drifts the
    propagators measured on what they published (two-body energy relative to mu/|r0| and
    |h|; |q| - 1, and for torque-free bodies T and H_i); None when a propagator left no
    summary (killed)."""
    procs = result.get("processes", {})
    per_kind = {}
    for kind in ("orbit", "attitude"):
        if kind in procs:
            summary = procs[kind].get("summary") or {}
            if "per_body" not in summary:
                return None
            per_kind[kind] = summary["per_body"]
    channels = (result.get("logger") or {}).get("channels") or {}
    rows = []
    for bp in make_plan(scenario).bodies:
        row = {"body": bp.name, "orbit_model": bp.orbit_model, "attitude_model": bp.attitude_model}
        for kind in ("orbit", "attitude"):
            stats = per_kind.get(kind, {}).get(bp.name)
            if stats is not None:
                row[f"{kind}_states"] = int(channels.get(f"astrodyn/{scenario.name}/{bp.name}/{kind}", 0))
                row.update(stats)
        rows.append(row)
    return rows


def file_summary(path: Path, scenario: Scenario, block_messages: int = 50_000) -> FileRows:
    """Per body, from the file: models, states recorded per kind, the invariant rows
    (``orbit_invariants`` / ``attitude_invariants``: lists of :class:`Invariant` dicts),
    the cross-check difference, and the legacy drift keys (``energy_drift`` and
    ``momentum_drift`` relative to mu/|r0| and |h0|, ``quat_norm_error``,
    ``rot_energy_drift``, ``inertial_momentum_drift``, ``crosscheck_max_dr``) that
    :func:`propagator_rows` also reports.

    The file is read in blocks of ``block_messages`` (:func:`astrodyn.recording.load_blocks`),
    so memory does not grow with the recording: every drift is a largest deviation from the
    first recorded state, so each block is evaluated with that state put in front of it and
    the blocks' maxima combined (a NaN anywhere stays NaN).  An orbit that burns moved:
    from the first state of its current coast arc, the arcs found from the burns recorded
    so far (:class:`~astrodyn.analysis.closed_loop.OrbitActuation`, fed each block's
    actuator states and applied commands before its states).  The messages the reader
    skipped (invalid, in corrupt chunks) are counted in the result's ``read_back``
    (:class:`FileRows`)."""
    from astrodyn.recording import load_blocks

    plan = {bp.name: bp for bp in make_plan(scenario).bodies}
    rows = {b.name: {"body": b.name, "orbit_model": plan[b.name].orbit_model,
                     "attitude_model": plan[b.name].attitude_model} for b in scenario.bodies}
    first: dict[tuple[str, str], tuple] = {}
    actuations = {b.name: OrbitActuation() for b in scenario.bodies if b.actuators is not None and b.orbit is not None}
    read_back = {"invalid": 0, "invalid_by_channel": {}, "examples": [], "corrupt_chunks": 0}
    for run in load_blocks(path, block_messages):
        read_back["invalid"] += run.invalid
        read_back["corrupt_chunks"] += run.corrupt_chunks
        for topic, n in run.invalid_by_channel.items():
            read_back["invalid_by_channel"][topic] = read_back["invalid_by_channel"].get(topic, 0) + n
        read_back["examples"] += run.invalid_examples[: max(0, 5 - len(read_back["examples"]))]
        for b in scenario.bodies:
            if b.name in actuations:
                prefix = f"astrodyn/{scenario.name}/{b.name}/"
                actuations[b.name].add(run.channels.get(prefix + "actuators"), run.channels.get(prefix + "command"))
            rec = run.bodies.get(b.name)
            if rec is None:
                continue
            _add_block(rows[b.name], rec, run.scenario, plan[b.name], scenario.central_body.mu, first,
                       actuations.get(b.name))
    return FileRows(rows.values(), read_back)


def _max_nan(a: float | None, b: float) -> float:
    if a is None:
        return b
    return float("nan") if math.isnan(a) or math.isnan(b) else max(a, b)


def _merge_invariants(old: list[dict] | None, new: list[dict]) -> list[dict]:
    """The rows of the blocks so far and of one more: the larger drift, the first block's
    ``initial`` (the first recorded state's), the newest name and scale (an orbit's rows
    become ``... between burns`` from the block of its first burn on)."""
    if old is None:
        return new
    return [{**n, "initial": o["initial"], "drift": _max_nan(o["drift"], n["drift"])}
            for o, n in zip(old, new, strict=True)]


def _add_orbit_block(row: dict, orbit, recorded_scenario: dict, bp, mu: float, first: dict,
                     actuation: OrbitActuation | None) -> None:
    """Fold one block of a body's orbit track into its summary row, led by the first state
    of the coast arc the block starts in (the body's first state unless a burn moved the
    orbit: :class:`~astrodyn.analysis.closed_loop.OrbitActuation`); what is carried to the
    next block, in ``first``, is the time of the block's last state and the first state of
    its arc."""
    t = np.asarray(orbit.t, dtype=np.float64)
    t_last, r0, v0 = first.get((bp.name, "orbit"), (None, orbit.r[:1].copy(), orbit.v[:1].copy()))
    r, v = np.concatenate([r0, orbit.r]), np.concatenate([v0, orbit.v])
    arc_starts = np.concatenate([[True], actuation.arc_starts(t, t_last)]) if actuation else None
    inv = recorded_invariants(recorded_scenario, bp.name, orbit=(bp.orbit_model, r, v),
                              orbit_arc_starts=arc_starts)["orbit"]
    arc_first = coast_arc_first(arc_starts) if arc_starts is not None else np.zeros(len(r), dtype=int)
    first[(bp.name, "orbit")] = (float(t[-1]), r[arc_first[-1:]].copy(), v[arc_first[-1:]].copy())
    rn = np.linalg.norm(r, axis=1)
    energy = 0.5 * np.einsum("ij,ij->i", v, v) - mu / rn
    h = np.linalg.norm(np.cross(r, v), axis=1)
    h_first = h[arc_first]
    row["orbit_states"] = row.get("orbit_states", 0) + len(orbit)
    row["orbit_last_seq"] = max(row.get("orbit_last_seq", -1), int(orbit.seq[-1]))
    row["orbit_invariants"] = _merge_invariants(row.get("orbit_invariants"), [i.as_dict() for i in inv])
    # two-body E and |h|: a drift for a Kepler (or actuated, between burns) body, a physical
    # change of quantities its model does not conserve for a perturbed one
    e_key, h_key = TWO_BODY_KEYS[bp.orbit_model in ("kepler", ACTUATED_MODEL)]
    row[e_key] = _max_nan(row.get(e_key), float(np.max(np.abs(energy - energy[arc_first]) * rn[arc_first] / mu)))
    with np.errstate(divide="ignore", invalid="ignore"):
        h_drift = np.where(h_first != 0, np.abs(h - h_first) / np.where(h_first != 0, h_first, 1.0), 0.0)
    row[h_key] = _max_nan(row.get(h_key), float(np.max(h_drift)))


def _attitude_block(rec, bp, first: dict) -> tuple[np.ndarray, np.ndarray, dict | None]:
    """``(q, w, own)`` of one block, led by the body's first recorded state (drifts are
    from it).  A flexible or rolling body's states are its steps on both the attitude and
    its own channel, ``own`` the arrays of that channel (:func:`own_state_arrays`); a block
    with none of those is empty."""
    att = rec.attitude
    kind = MODEL_STATE_KINDS.get(bp.attitude_model)
    empty = np.zeros((0, 4)), np.zeros((0, 3)), None
    if kind is None:
        q0, w0 = first.setdefault((bp.name, "attitude"), (att.q[:1].copy(), att.w[:1].copy()))
        return np.concatenate([q0, att.q]), np.concatenate([w0, att.w]), None
    track = getattr(rec, kind, None)
    arrays = own_state_arrays(bp.attitude_model, track)
    if arrays is None:
        return empty
    _, ia, ie = np.intersect1d(att.seq, track.seq, return_indices=True)
    if not ia.size:
        return empty
    q0, w0, own0 = first.setdefault((bp.name, "attitude"), (att.q[ia[:1]], att.w[ia[:1]],
                                                            {k: a[ie[:1]] for k, a in arrays.items()}))
    if any(own0[k].shape[1:] != a.shape[1:] for k, a in arrays.items()):
        return empty
    return (np.concatenate([q0, att.q[ia]]), np.concatenate([w0, att.w[ia]]),
            {k: np.concatenate([own0[k], a[ie]]) for k, a in arrays.items()})


def _add_block(row: dict, rec, recorded_scenario: dict, bp, mu: float, first: dict,
               actuation: OrbitActuation | None = None) -> None:
    """Fold one block of a body's tracks into its summary row (see :func:`file_summary`);
    ``actuation``: the burns recorded so far of a body with actuators."""
    if rec.orbit is not None and len(rec.orbit):
        _add_orbit_block(row, rec.orbit, recorded_scenario, bp, mu, first, actuation)
    if rec.attitude is not None and len(rec.attitude):
        row["attitude_states"] = row.get("attitude_states", 0) + len(rec.attitude)
        q, w, own = _attitude_block(rec, bp, first)
        if q.shape[0]:
            inv = recorded_invariants(recorded_scenario, bp.name, attitude=(bp.attitude_model, q, w),
                                      own=own)["attitude"]
            row["attitude_invariants"] = _merge_invariants(row.get("attitude_invariants"), [i.as_dict() for i in inv])
            row["quat_norm_error"] = _max_nan(row.get("quat_norm_error"),
                                              float(np.max(np.abs(np.linalg.norm(q, axis=1) - 1.0))))
        named = {i["name"]: i for i in row.get("attitude_invariants") or ()}
        if bp.attitude_model == "torque_free" and "T" in named:
            row.update(rot_energy_drift=named["T"]["drift"], inertial_momentum_drift=named["H_i"]["drift"])
    for kind in ATTITUDE_PROCESS_KINDS[1:]:  # a flexible or rolling body's own key, gyroscopes' gimbals
        track = getattr(rec, kind, None)
        if track is not None and len(track):
            row["own_states"] = row.get("own_states", 0) + len(track)
    if rec.crosscheck is not None and len(rec.crosscheck):
        row["crosscheck_states"] = row.get("crosscheck_states", 0) + len(rec.crosscheck)
        row["crosscheck_max_dr"] = _max_nan(row.get("crosscheck_max_dr"), float(np.max(rec.crosscheck.dr_norm)))


def _fmt(x: float, spec: str = ".1e") -> str:
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else format(x, spec)


def sim_time_reached(log: dict) -> float | None:
    """The sim time (s) every process of a run got to, from the logger's summary ``log``: the
    least of the last state it recorded (``t``) and of where each process that stopped early
    said it stopped (``stopped_early``: process -> ``{"t", "reason"}``); None when the summary
    holds no ``t`` (no summary, or a logger that recorded nothing)."""
    if not isinstance(log.get("t"), (int, float)):
        return None
    early = [e["t"] for e in (log.get("stopped_early") or {}).values()
             if isinstance(e, dict) and isinstance(e.get("t"), (int, float))]
    return min([log["t"], *early])


def print_summary(result: dict, rows: list[dict], scenario: Scenario, max_bodies: int = 25) -> None:
    """The end-of-run table on stdout: one line per conserved quantity of each body."""
    log = result.get("logger") or {}
    states = sum(r.get("orbit_states", 0) + r.get("attitude_states", 0) for r in rows)
    xchecks = sum(r.get("crosscheck_states", 0) for r in rows)
    own = sum(r.get("own_states", 0) for r in rows)
    print(f"\nscenario {scenario.name}: {result['out']}")
    early = {p: e for p, e in (log.get("stopped_early") or {}).items() if isinstance(e, dict)}
    reached = sim_time_reached(log)
    stopped = bool(result.get("failure") or result.get("interrupted") or early)
    wall = max(result["wall_s"], 1e-9)
    if not stopped:
        print(f"  wall {result['wall_s']:.2f} s for {scenario.duration:.6g} s of sim time "
              f"(real-time factor {scenario.duration / wall:.1f}x)")
    elif reached is not None:  # the run stopped early: the factor of the sim time it reached, not of the scene's
        print(f"  wall {result['wall_s']:.2f} s for {reached:.6g} s of sim time reached (of {scenario.duration:.6g} s; "
              f"real-time factor {reached / wall:.1f}x)")
    else:
        print(f"  wall {result['wall_s']:.2f} s; the run stopped before the end of its {scenario.duration:.6g} s of sim "
              f"time (the logger left no summary of how far it got)")
    kinds = state_kinds_text(sum(r.get("orbit_states", 0) for r in rows), sum(r.get("attitude_states", 0) for r in rows))
    print(f"  in the file: {states} state messages ({kinds})"
          + (f" + {xchecks} cross-check messages" if xchecks else "")
          + (f" + {own} appendage / rolling / gimbal states" if own else "")
          + f"; logger: missing {log.get('missing', '?')}, malformed {log.get('malformed', '?')}, "
          f"rejected {sum((log.get('rejected') or {}).values())}")
    if reached is not None and log.get("reason"):
        print(f"  sim t reached {reached:.6g} s of {scenario.duration:.6g} s (recorded, and published by every process)"
              f"; logger stopped: {log['reason']}"
              + "".join(f"; {p} stopped early at sim t {e.get('t', 0):.6g} s ({e.get('reason')})"
                        for p, e in sorted(early.items()))
              + (" (the sim t of the last state each of them published)" if early else ""))
    read_back = getattr(rows, "read_back", None) or {}
    skipped = read_back.get("invalid", 0) + read_back.get("corrupt_chunks", 0)
    if skipped:  # whatever the logger said: the table counts only what the reader returned
        result["read_back"] = read_back
        per = ", ".join(f"{n} on {t}" for t, n in sorted(read_back.get("invalid_by_channel", {}).items())[:5])
        print(f"  WARNING: reading the file back skipped {read_back.get('invalid', 0)} invalid messages"
              + (f" ({per})" if per else "")
              + (f" and {read_back['corrupt_chunks']} corrupt chunks" if read_back.get("corrupt_chunks") else "")
              + "; the states counted here and what load / analyze / export give leave them out"
              + (f"; e.g. {read_back['examples'][0]}" if read_back.get("examples") else ""))
    table = [_TABLE_HEADER]
    shown = rows if len(rows) <= max_bodies else rows[: max_bodies - 5]
    for r in shown:
        first = True
        for kind in ("orbit", "attitude"):
            invs = r.get(f"{kind}_invariants")
            if not invs:
                continue
            model = r.get(f"{kind}_model") or "-"
            for k, inv in enumerate(invs):
                drift = _fmt(inv["drift"]) if inv["conserved"] else "-"
                table.append((r["body"] if first else "", kind if k == 0 else "", model if k == 0 else "",
                              r.get(f"{kind}_states", 0) if k == 0 else "", inv["name"], inv["unit"], drift,
                              inv["scale"] if inv["conserved"] else ""))
                first = False
        if r.get("crosscheck_max_dr") is not None:
            table.append(("", "x-check", "rebound-ias15", r.get("crosscheck_states", 0), "max |r - r_REBOUND|", "m",
                          _fmt(r["crosscheck_max_dr"], ".2e"), "absolute"))
    worst: dict[tuple, float] = {}
    if len(rows) > len(shown):
        for r in rows:
            for kind in ("orbit", "attitude"):
                for inv in r.get(f"{kind}_invariants") or []:
                    if inv["conserved"]:
                        key = (kind, r.get(f"{kind}_model"), inv["name"], inv["unit"], inv["scale"])
                        worst[key] = max(worst.get(key, 0.0), inv["drift"])
    tail = [("(all)", kind, model or "-", "", name, unit, _fmt(d), scale)
            for (kind, model, name, unit, scale), d in worst.items()]
    lines = table_lines([*table, *tail])
    print("\n".join(lines[:len(table)]))
    if len(rows) > len(shown):
        print(f"  ... {counted(len(rows) - len(shown), 'more body', 'more bodies')} (all in the --json summary); "
              f"worst drift per quantity:")
        print("\n".join(lines[len(table):]))


#: The columns of the run summary table: (header, least width, alignment) and the gap before
#: each; a longer cell (a body name of 15+ characters, a long quantity name) widens its column.
_TABLE_COLUMNS = (("body", 14, "<", "  "), ("kind", 9, "<", " "), ("model", 17, "<", " "), ("states", 7, ">", " "),
                  ("conserved quantity", 26, "<", "  "), ("unit", 6, "<", " "), ("max drift", 9, ">", " "),
                  ("relative to", 0, "<", "  "))
_TABLE_HEADER = tuple(c[0] for c in _TABLE_COLUMNS)


def table_lines(cells: list[tuple]) -> list[str]:
    """The lines of the run summary table of ``cells`` (one tuple of 8 cells per line, the
    header first): each column as wide as its widest cell (at least its least width), so
    every line's columns start at the same offset; no trailing blanks."""
    texts = [[str(c) for c in row] for row in cells]
    widths = [max([least, *(len(t[j]) for t in texts)]) for j, (_, least, _, _) in enumerate(_TABLE_COLUMNS)]
    out = []
    for t in texts:
        line = "".join(f"{gap}{cell:{align}{width}}" for cell, width, (_, _, align, gap) in zip(t, widths, _TABLE_COLUMNS))
        out.append(line.rstrip())
    return out
