"""Continue a run from what a recording holds: the resume point and the last states.

Used by ``astrodyn run --resume FILE.mcap`` (continue a stopped or crashed run into a new
file) and by ``astrodyn serve`` (restart a killed propagator from the last state the
logger flushed).  ``seq`` of every state channel is the output step index
(docs/architecture.md, section 5), so "how far a recording got" is a step number:

* :func:`contiguous_steps` -- how many steps from 0 every channel holds without a hole
  (``run --resume`` copies exactly those into the new file and continues after them);
* :func:`last_common_step` -- the latest step present in every channel (``serve``: a
  rolled part does not start at step 0);
* :func:`states_at` -- the recorded states of one process kind at one step, as the
  engines' ``resume`` methods take them (:meth:`astrodyn.simulate.OrbitEngine.resume`,
  :meth:`astrodyn.simulate.AttitudeEngine.resume`);
* :func:`write_state_file` / :func:`read_state_file` -- the JSON handed to a propagator
  with ``--resume-state`` (floats by ``repr``: the states round-trip bit for bit).

Exact models (Kepler orbits, torque-free attitudes) need no state: they are evaluated
from the initial state at each output time, so a resumed run reproduces them bit for bit.
Integrated models (J2, zonal, third body, torqued attitudes, flexible spacecraft) continue
from the recorded state of the step before the resume point; a flexible body's state is its
attitude and its appendages' coordinates (``eta``, ``eta_dot``) at that step, from its two
channels (:func:`state_channels`).
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable
from pathlib import Path

import numpy as np

from astrodyn import messages
from astrodyn.messages import ATTITUDE_PROCESS_KINDS
from astrodyn.scenario import Scenario, ScenarioError, plan as make_plan
from astrodyn.simulate import FlexibleBody, GyroSet, RollingBody

__all__ = ["state_channels", "state_topics", "contiguous_steps", "last_common_step", "states_at", "write_state_file",
           "read_state_file", "propagator_resume_args", "resume_args", "tail_resume_point", "ResumeError"]


class ResumeError(ValueError):
    """A recording cannot be resumed from (the text says which file and why)."""


#: message kind -> the fields of its messages that make a state to continue from
_STATE_FIELDS = {"orbit": ("r", "v"), "attitude": ("q", "w"),
                 **{src.kind: src.resume_fields for src in (FlexibleBody, RollingBody, GyroSet)}}


def state_channels(scenario: Scenario, kind: str) -> list[tuple[str, str, str]]:
    """``(body, message kind, key)`` of every state channel the ``kind`` ("orbit" |
    "attitude") process publishes: each propagated body's orbit or attitude, and the own
    key of a flexible or rolling body (:data:`astrodyn.messages.MODEL_STATE_KINDS`: the
    rest of the state to continue from)."""
    p = make_plan(scenario)
    if kind == "orbit":
        return [(b.name, "orbit", messages.orbit_key(scenario.name, b.name)) for b in p.bodies if b.orbit_model]
    if kind == "attitude":
        out = []
        for b in p.bodies:
            if b.attitude_model:
                out.append((b.name, "attitude", messages.attitude_key(scenario.name, b.name)))
                if b.attitude_model != messages.ACTUATED_MODEL:  # the plant's channels are not resumed
                    out += [(b.name, own, messages.body_key(scenario.name, b.name, own)) for own in b.own_kinds]
        return out
    if kind == "plant":  # a ScenarioError: `run --resume` reports it as it reports a wrong file
        raise ScenarioError(f"scenario {scenario.name!r} is a closed loop: its plant cannot be resumed (the "
                            f"controllers' state lives outside astrodyn; docs/control.md); re-simulate it from "
                            f"its commands with --commands REC.mcap instead")
    raise ValueError(f"kind: expected 'orbit' or 'attitude', got {kind!r}")


def state_topics(scenario: Scenario, kind: str) -> dict[str, str]:
    """``body`` (``body/appendages`` for a flexible body's second channel) -> key of every
    state channel of the ``kind`` process (:func:`state_channels`)."""
    return {body if mk in ("orbit", "attitude") else f"{body}/{mk}": key for body, mk, key in state_channels(scenario, kind)}


def _tracks(run, topics) -> list:
    return [run.channels.get(t) for t in topics]


def contiguous_steps(run, topics) -> int:
    """The number k of steps 0..k-1 that every channel in ``topics`` holds (0 if any is absent)."""
    k = None
    for track in _tracks(run, topics):
        if track is None or len(track) == 0:
            return 0
        seq = np.unique(track.seq)
        n = int(np.searchsorted(seq - np.arange(seq.size), 0, side="right"))  # seq[i] == i prefix
        k = n if k is None else min(k, n)
    return k or 0


def last_common_step(run, topics) -> int | None:
    """The latest step present in every channel of ``topics`` (None if there is none)."""
    tracks = _tracks(run, topics)
    if not tracks or any(t is None or len(t) == 0 for t in tracks):
        return None
    common = np.unique(tracks[0].seq)
    for t in tracks[1:]:
        common = np.intersect1d(common, t.seq, assume_unique=False)
    return int(common[-1]) if common.size else None


def states_at(run, scenario: Scenario, kind: str, step: int) -> tuple[float, dict[str, dict]]:
    """``(t, {body: state})`` of ``kind`` at output step ``step`` from the recording ``run``.

    Orbit states are ``{"r", "v"}`` (m, m/s), attitude states ``{"q", "w"}`` (scalar-first
    Euler parameters, body rates rad/s), a flexible body's also ``{"eta", "eta_dot"}``
    (one list per appendage), all as plain float lists.
    """
    out: dict[str, dict] = {}
    t = None
    for body, mk, topic in state_channels(scenario, kind):
        track = run.channels.get(topic)
        idx = np.flatnonzero(track.seq == step) if track is not None else np.zeros(0, int)
        if idx.size == 0:
            raise ResumeError(f"{run.path}: no {mk} state of body {body!r} at step {step}")
        i = int(idx[0])
        out.setdefault(body, {}).update({f: _plain(getattr(track, f)[i]) for f in _STATE_FIELDS[mk]})
        t = float(track.t[i])
    if t is None:
        t = step / scenario.rate
    return t, out


def _plain(value):
    """A recorded value (a number, a row of floats, or per appendage a list of them) as
    plain Python floats and lists."""
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_plain(x) for x in value]
    return float(value)


def write_state_file(path: str | os.PathLike, kind: str, step: int, t: float, states: dict) -> Path:
    """Write the ``--resume-state`` JSON of a propagator: the states at ``step`` (time ``t``)."""
    path = Path(path)
    path.write_text(json.dumps({"kind": kind, "step": int(step), "t": float(t), "states": states}, allow_nan=False))
    return path


def read_state_file(path: str | os.PathLike, kind: str) -> tuple[int, float, dict]:
    """``(step, t, states)`` from a ``--resume-state`` file; ResumeError naming what is wrong."""
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise ResumeError(f"--resume-state {path}: expected a readable JSON file, got {type(exc).__name__}: {exc}") from None
    if not isinstance(data, dict) or data.get("kind") != kind:
        raise ResumeError(f"--resume-state {path}: expected a JSON object with kind {kind!r}")
    step, t, states = data.get("step"), data.get("t"), data.get("states")
    if not (isinstance(step, int) and step >= 0 and isinstance(t, (int, float)) and math.isfinite(t)
            and isinstance(states, dict)):
        raise ResumeError(f"--resume-state {path}: expected step >= 0, finite t and a states object")
    fields = _STATE_FIELDS[kind] if kind in _STATE_FIELDS else ()

    def number(x) -> bool:
        return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)

    def finite(xs, n=None) -> bool:
        return isinstance(xs, list) and (n is None or len(xs) == n) and all(number(x) for x in xs)

    def finite_tree(x, depth=2) -> bool:  # a number, or (nested) lists of finite numbers
        return number(x) or (depth > 0 and isinstance(x, list) and bool(x)
                             and all(finite_tree(y, depth - 1) for y in x))

    own = sorted({f for k in ATTITUDE_PROCESS_KINDS[1:] for f in _STATE_FIELDS[k]}) if kind == "attitude" else []
    for body, st in states.items():
        ok = isinstance(st, dict) and all(finite(st.get(f), 4 if f == "q" else 3) for f in fields)
        # a flexible or rolling body's own fields: finite numbers, lists of them, lists of those
        ok = ok and set(st) <= {*fields, *own} and all(finite_tree(st[f]) for f in own if f in st)
        if not ok:
            raise ResumeError(f"--resume-state {path}: states.{body}: expected finite {' and '.join(fields)} vectors"
                              + (" (and the finite fields of a flexible or rolling body's own key)"
                                 if kind == "attitude" else ""))
    return step, float(t), states


def propagator_resume_args(run, scenario: Scenario, kind: str, step: int, work: str | os.PathLike) -> dict:
    """The arguments that make a ``kind`` propagator continue after output step ``step``
    of the recording ``run``: ``--start-step step+1`` and, when the process has integrated
    bodies, ``--resume-state`` (a JSON file written in ``work`` with their states at ``step``)."""
    return resume_args(scenario, kind, step, lambda: states_at(run, scenario, kind, step), work)


def resume_args(scenario: Scenario, kind: str, step: int, states: Callable[[], tuple[float, dict]],
                work: str | os.PathLike) -> dict:
    """``--start-step step+1`` and, when the ``kind`` process has integrated bodies,
    ``--resume-state`` with their states at ``step``; ``states()`` gives ``(t, {body:
    state})`` as :func:`states_at` does (called only when some body is integrated)."""
    args: dict = {"--start-step": step + 1}
    p = make_plan(scenario)
    exact = "kepler" if kind == "orbit" else "torque_free"
    integrated = {b.name for b in p.bodies if (b.orbit_model if kind == "orbit" else b.attitude_model) not in (None, exact)
                  or (kind == "attitude" and b.own_kinds and b.attitude_model != messages.ACTUATED_MODEL)}
    if integrated:
        t, all_states = states()
        chosen = {b: st for b, st in all_states.items() if b in integrated}
        args["--resume-state"] = write_state_file(Path(work) / f"{kind}-state-{step}.json", kind, step, t, chosen)
    return args


def tail_resume_point(tails: dict[str, list[bytes]], scenario: Scenario, kind: str) -> tuple[int, float, dict] | None:
    """``(step, t, {body: state})``: the latest step that every ``kind`` state channel
    holds among its last payloads (:func:`astrodyn.recording.tail.channel_tails`), with
    the states at it (as :func:`states_at`); None when a channel has no valid payload
    there or the channels share no step.  Payloads are validated (a hostile file's bytes
    are never a state to continue from)."""
    decoded: list[tuple[str, str, dict[int, dict]]] = []
    for body, mk, topic in state_channels(scenario, kind):
        by_seq: dict[int, dict] = {}
        for data in tails.get(topic, ()):
            try:
                msg = messages.decode(data, mk)
            except messages.MessageError:
                continue
            by_seq[msg["seq"]] = msg
        if not by_seq:
            return None
        decoded.append((body, mk, by_seq))
    if not decoded:
        return None
    common = set.intersection(*(set(s) for _, _, s in decoded))
    if not common:
        return None
    step = max(common)
    t = decoded[0][2][step]["t"]
    states: dict[str, dict] = {}
    for body, mk, by_seq in decoded:
        states.setdefault(body, {}).update({f: list(by_seq[step][f]) for f in _STATE_FIELDS[mk]})
    return step, t, states
