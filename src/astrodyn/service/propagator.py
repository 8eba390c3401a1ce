"""The propagator process loop shared by ``services/orbit.py`` and ``services/attitude.py``.

One loop, two kinds: it asks an engine of :mod:`astrodyn.simulate` for the states of a
block of output instants, encodes one JSON payload per body per instant
(:func:`astrodyn.messages.encode_orbit_batch` / ``encode_attitude_batch``), and publishes
them on the per-body keys of docs/architecture.md, section 3.  Large scenes (more than
:data:`BATCH_THRESHOLD` bodies, or ``--batch always``) instead publish each instant's
payloads as one batch envelope on ``astrodyn/<scenario>/@batch/<kind>``
(the logger splits it back into the per-body channels of docs/architecture.md, section 3; ``seq`` of
every channel is the output step index ``k``, so 0, 1, 2, ... with no gaps).

Around the loop:

* a liveliness token ``@alive/<kind>`` and an application heartbeat with the sim time
  reached (a hung loop stops beating although the token stays);
* ``start`` and end-of-run (``stop`` with ``{"messages": M}``) events, so the logger knows
  when it holds everything;
* pacing: ``real_time_factor = inf`` runs as fast as the bus lets it (``astrodyn run``);
  a finite factor paces sim time against the wall clock (``astrodyn serve``);
* commands (``serve`` only): JSON puts on ``astrodyn/<scenario>/@command`` from the
  supervisor -- ``{"verb": "pause" | "resume" | "stop"}`` or ``{"verb": "rate",
  "factor": x}`` -- applied between instants;
* cross-check (orbit only): REBOUND IAS15 runs the same bodies alongside and the
  difference is published on ``<body>/crosscheck``.
"""

from __future__ import annotations

import json
import math
import sys
import time
from dataclasses import dataclass

import numpy as np

from astrodyn import bus, messages
from astrodyn.jit import service_threads, set_threads
from astrodyn.scenario import Scenario, plan as make_plan
from astrodyn.service.children import LOGGED_WAIT_S, MODEL_ENDED_EXIT, share_fate_with_supervisor
from astrodyn.service.summary import TWO_BODY_KEYS
from astrodyn.signals import catch_job_control, catch_stop_signals, suspended_s
from astrodyn.simulate import AttitudeEngine, ModelEnded, OrbitEngine

__all__ = ["Pacer", "PropagatorOptions", "run_propagator", "command_key", "CommandVerifier", "command_anchor", "obey_commands", "pace_to",
           "wait_until_logged"]

KINDS = ("orbit", "attitude")

#: Scenes with more bodies than this publish one batch envelope per instant instead of
#: one sample per body (``--batch auto``); consumers use :func:`astrodyn.bus.state_samples`
#: to read both forms alike.
BATCH_THRESHOLD = 64


def command_key(scenario: str) -> str:
    """``astrodyn/<scenario>/@command``: the supervisor's commands to its propagators."""
    return messages.event_key(scenario).rsplit("/", 1)[0] + "/@command"


class Pacer:
    """Paces sim time against the wall clock at ``factor`` sim seconds per wall second.

    ``factor = inf``: never waits.  :meth:`set_factor` and :meth:`pause` / :meth:`resume`
    re-anchor the clock, so a rate change applies from the current instant on.  Time this
    process spent stopped by Ctrl-Z (:func:`astrodyn.signals.suspended_s`) moves the
    schedule on by as much: after ``fg`` it goes on from where it was, not racing through the
    sim time the pause would have covered.
    """

    def __init__(self, factor: float = math.inf, anchor: tuple[float, float] | None = None, paused: bool = False):
        """``anchor = (wall, t_sim)``: the schedule to keep, ``t_sim`` due at ``wall``
        (``time.monotonic()``, which is system-wide on Linux, so a supervisor can hand it to
        a restarted process: the new process runs as fast as it can until it is back on the
        schedule, then paces).  Default: anchored at the first instant published.
        ``paused``: start paused (a process restarted while its supervisor is paused): no
        instant is due until :meth:`resume`."""
        self.factor = float(factor)
        self.paused = bool(paused)
        self._anchor_wall = time.monotonic() if anchor is None else float(anchor[0])
        self._anchor_sim: float | None = None if anchor is None else float(anchor[1])
        self._suspended_at_anchor = suspended_s()

    def _reanchor(self, t_sim: float | None, anchor: tuple[float, float] | None = None) -> None:
        now = time.monotonic()
        if anchor is not None and t_sim is not None and math.isfinite(self.factor) \
                and t_sim > anchor[1] + (now - anchor[0]) * self.factor:
            anchor = None  # ahead of the schedule (it ran on past what its supervisor heard): no wait, go on from here
        self._anchor_wall, self._anchor_sim = (now, t_sim) if anchor is None else anchor
        self._suspended_at_anchor = suspended_s()

    def set_factor(self, factor: float, t_sim: float | None, anchor: tuple[float, float] | None = None) -> None:
        """Pace at ``factor`` from now on: from this process's ``t_sim``, or on the schedule
        ``anchor = (wall, t_sim)`` its supervisor gives every process (as ``__init__``'s), so
        that processes that drifted apart (each ran as fast as it could at ``inf``) are paced
        to one sim time again: one behind the schedule runs as fast as it can until it is on
        it; one ahead of it (the supervisor's ``t_sim`` is from heartbeats, up to half a second
        old) goes on from its own ``t_sim`` without waiting."""
        if not (factor > 0):
            raise ValueError(f"rate factor: expected a number > 0 (or inf), got {factor!r}")
        self.factor = float(factor)
        self._reanchor(t_sim, anchor)

    def pause(self) -> None:
        self.paused = True

    def resume(self, t_sim: float | None, anchor: tuple[float, float] | None = None) -> None:
        """Go on from a pause: from ``t_sim`` now, or on the schedule ``anchor`` (:meth:`set_factor`)."""
        self.paused = False
        self._reanchor(t_sim, anchor)

    def state(self) -> dict:
        """``{"paused": bool, "rate": factor or "inf"}``: what every heartbeat says, so that a
        supervisor sees a process that missed its ``pause`` or ``rate`` (it subscribed late)
        and sends it again, whether the process paces or runs as fast as it can."""
        return {"paused": self.paused, "rate": self.factor if math.isfinite(self.factor) else "inf"}

    def wait_time(self, t_sim: float) -> float:
        """Wall seconds to wait before publishing the instant ``t_sim`` (0 if due)."""
        if math.isinf(self.factor):
            return 0.0
        if self._anchor_sim is None:
            self._reanchor(t_sim)
        due = self._anchor_wall + (suspended_s() - self._suspended_at_anchor) + (t_sim - self._anchor_sim) / self.factor
        return max(0.0, due - time.monotonic())


@dataclass
class PropagatorOptions:
    """How one propagator process runs (see the module docstring)."""

    kind: str
    real_time_factor: float = math.inf
    block: int = 0  # output instants per engine call; 0 = automatic
    cross_check: bool = False
    wait_logger_s: float = 30.0
    start_step: int = 0
    max_steps: int | None = None  # stop after this many instants (tests)
    endless: bool = False  # serve: keep going past the scenario's duration until stopped
    batch: str = "auto"  # "auto" (envelopes above BATCH_THRESHOLD bodies) | "always" | "never"
    resume_state: tuple[int, float, dict] | None = None  # (step, t, states) the integrated bodies continue from
    first_event_seq: int = 0  # a restarted process continues its predecessor's event numbering
    pace_anchor: tuple[float, float] | None = None  # (monotonic wall, t_sim) of the run's schedule (serve restarts)
    start_paused: bool = False  # publish nothing until a resume command (serve restarts it while paused)


class _Stop(Exception):
    pass


#: wall s a restarted propagator with no step left to publish waits for the logger (it may
#: have finished the file already: then the propagator ends at once, exit 0)
NOTHING_LEFT_WAIT_S = 5.0


def _auto_block(n_bodies: int) -> int:
    """About 2e5 states per engine call (memory ~ 10 MB), at least 1, at most 1000 instants."""
    return int(max(1, min(1000, 200_000 // max(1, n_bodies))))


#: Work limits of one uninterruptible computation, so that the heartbeat goes out between
#: them however far apart the output instants are (docs/reliability.md, hung processes):
#: an orbit engine call spans at most this many revolutions of its fastest integrated body
#: (DOP853: ~50 steps per revolution, ~0.3 ms each), ...
ORBIT_REVOLUTIONS_PER_CALL = 5.0
#: ... REBOUND advances at most this many revolutions of its fastest body between two
#: heartbeats (IAS15: ~0.2 ms per LEO revolution and body) ...
CROSSCHECK_REVOLUTIONS_PER_CALL = 200.0
#: ... and an attitude engine call at most about this many splitting steps of its fastest
#: integrated body (step ~ 1/60 of its fastest natural period, as the integrator's default).
ATTITUDE_STEPS_PER_CALL = 10_000.0


def _natural_period(r0: np.ndarray, v0: np.ndarray, mu: float) -> float:
    """The time scale (s) of an orbit's work: its period if bound, else the time to cross
    its initial radius at its initial speed (x 2 pi); inf for a state that cannot move."""
    r, v = float(np.linalg.norm(r0)), float(np.linalg.norm(v0))
    energy = 0.5 * v * v - mu / r if r > 0 else math.nan
    if energy < 0:
        return 2.0 * math.pi * math.sqrt((-mu / (2.0 * energy)) ** 3 / mu)
    return 2.0 * math.pi * r / v if v > 0 else math.inf


def _work_spans(kind: str, scenario: Scenario, engine, cross) -> tuple[float, float]:
    """``(engine span, cross-check span)``: the sim seconds one engine call, and one REBOUND
    advance, may cover (inf: its cost does not grow with the span -- exact models)."""
    span, cross_span = math.inf, math.inf
    if kind == "orbit":
        mu = engine.mu
        integrated = [int(i) for g in engine.groups for i in g.index]
        if integrated:
            span = ORBIT_REVOLUTIONS_PER_CALL * min(_natural_period(engine.r0[i], engine.v0[i], mu) for i in integrated)
        checked = [int(i) for idx, _, _ in (cross.scenes if cross is not None else []) for i in idx]
        if checked:
            cross_span = CROSSCHECK_REVOLUTIONS_PER_CALL * min(
                _natural_period(engine.r0[i], engine.v0[i], mu) for i in checked)
        return span, cross_span
    mu = scenario.central_body.mu
    for b in engine.bodies:
        if b.model == "torque_free" and b.gyros is None:
            continue  # exact from the initial state at any t
        rates = [float(np.max(np.abs(b.w0)))]
        if b.rotor_momentum is not None:
            rates.append(float(np.linalg.norm(b.rotor_momentum)) / float(np.min(b.inertia)))
        body = scenario.body(b.name)
        if b.model == "gravity_gradient" and body.orbit is not None:
            rates.append(2.0 * 2.0 * math.pi / _natural_period(np.asarray(body.orbit.r0, dtype=np.float64),
                                                            np.asarray(body.orbit.v0, dtype=np.float64), mu))
        rate = max(rates)
        step = 0.1 if not rate > 0 else 2.0 * math.pi / (60.0 * rate)
        span = min(span, ATTITUDE_STEPS_PER_CALL * step)
    return span, cross_span


def _waypoints(t_from: float, t_to: float, span: float) -> np.ndarray:
    """Times strictly between ``t_from`` and ``t_to`` (s), ``span`` apart from ``t_from``:
    where a computation longer than ``span`` stops for a heartbeat (empty if none)."""
    if not (span < t_to - t_from):
        return np.zeros(0)
    n = int(math.ceil((t_to - t_from) / span)) - 1
    w = t_from + span * np.arange(1, n + 1, dtype=np.float64)
    return w[w < t_to]


def run_propagator(scenario: Scenario, session, opts: PropagatorOptions, log=print) -> dict:
    """Publish the states of ``opts.kind`` for the whole scenario; returns a summary dict."""
    if opts.kind not in KINDS:
        raise ValueError(f"kind: expected one of {KINDS}, got {opts.kind!r}")
    p = make_plan(scenario)
    if opts.kind == "orbit":
        engine = OrbitEngine(scenario, p)
        key_of = messages.orbit_key
    else:
        engine = AttitudeEngine(scenario, p)
        key_of = messages.attitude_key
    names, models = engine.names, engine.models
    if opts.resume_state is not None:
        step, t_state, states = opts.resume_state
        if opts.start_step != step + 1:
            raise ValueError(f"--start-step: expected {step + 1} (the step after the resume state's {step}), "
                             f"got {opts.start_step}")
        engine.resume(t_state, states)
    keys = [key_of(scenario.name, n) for n in names]
    # flexible and rolling bodies, gyroscopes: the rest of their state on their own keys, same seq
    own_channels = engine.own_channels() if opts.kind == "attitude" else []
    model_keys = {(k, src.kind): messages.body_key(scenario.name, names[k], src.kind) for k, src in own_channels}
    groups: dict[str, np.ndarray] = {}
    for i, m in enumerate(models):
        groups.setdefault(m, []).append(i)  # type: ignore[arg-type]
    groups = {m: np.asarray(ix) for m, ix in groups.items()}
    n_total = scenario.n_steps if not opts.endless else 2**53
    start = int(opts.start_step)
    stop_at = n_total if opts.max_steps is None else min(n_total, start + int(opts.max_steps))
    rate = scenario.rate
    block = opts.block or _auto_block(len(names))

    cross = None
    if opts.kind == "orbit" and (opts.cross_check or any(scenario.body(n).cross_check for n in names)):
        cross = _CrossCheck(scenario, engine, all_bodies=opts.cross_check)
    # one engine call never spans more than `span` s of sim time past the engine's state (an
    # output spacing longer than that is integrated through unpublished waypoints), and the
    # cross-check stops every `cross.span` s: a heartbeat goes out between them however long
    # a block of output instants takes
    span, cross_span = _work_spans(opts.kind, scenario, engine, cross)
    if cross is not None:
        cross.span = cross_span
    engine_t = float(opts.resume_state[1]) if opts.resume_state is not None else 0.0
    cross_t = 0.0  # REBOUND's time (a restarted process integrates it again from 0)

    pacer = Pacer(opts.real_time_factor, opts.pace_anchor, paused=opts.start_paused)
    stopping = {"why": None}
    conservation = _Conservation(opts.kind, scenario, engine)
    catch_stop_signals(lambda why: stopping.update(why=why))
    catch_job_control()  # Ctrl-Z of a paced run: the pacer keeps its schedule after it

    published = 0
    t_reached = start / rate
    wall0 = time.monotonic()
    signer = bus.process_signer(opts.kind)  # the run's identity (docs/security.md); None outside a run
    commands_from = CommandVerifier()
    with bus.declare_alive(session, scenario.name, opts.kind), \
            bus.Heartbeat(session, scenario.name, opts.kind, signer=signer) as heartbeat, \
            bus.BatchPublisher(session, scenario.name, opts.kind, signer=signer) as batch, \
            bus.EventPublisher(session, scenario.name, opts.kind, signer=signer) as events, \
            session.declare_subscriber(command_key(scenario.name), _fifo()) as commands:
        batched = opts.batch == "always" or (opts.batch == "auto" and len(names) > BATCH_THRESHOLD)
        extra_keys = [key for _, xkeys, _ in cross.scenes for key in xkeys] if cross is not None else []
        out = _StepOutput(opts.kind, engine, keys, groups, session, batch, signer, batched,
                          extra_keys + list(model_keys.values()))
        # a restart after its last step was recorded (killed while it waited for the logger's
        # receipt) has only its end event left; if the logger has finished the file meanwhile,
        # there is nothing to do (waiting the full wait_logger_s would fail the run instead)
        nothing_left = start >= stop_at
        logger_gone = False
        try:
            bus.wait_for_logger(session, scenario.name,
                                timeout_s=min(opts.wait_logger_s, NOTHING_LEFT_WAIT_S) if nothing_left else opts.wait_logger_s)
        except bus.BusError:
            if not nothing_left:
                raise
            logger_gone = True
            stopping["why"] = "every step already recorded; the logger has finished"
        events.next_seq = int(opts.first_event_seq)
        events.emit("start", float(t_reached), json.dumps({"bodies": len(names), "first_step": start,
                                                           "steps": stop_at - start}))
        k = start
        # until the first block is out the numeric kernels are being compiled (a first run on
        # this install: tens of seconds; numba caches them) or loaded from numba's cache
        heartbeat.beat(force=True, t=t_reached, step=k, preparing=True)
        kernels = {"loaded": False}
        a = b = None
        rows_done = 0

        def working(what: str, t_now: float, t_to: float) -> None:
            """Between two parts of a long computation: beat (saying what it does and how
            far it got: ``busy``; ``preparing`` until the first engine call has returned)
            and stop at a stop signal."""
            if stopping["why"]:
                raise _Stop
            more = {} if kernels["loaded"] else {"preparing": True}
            heartbeat.beat(t=t_reached, step=k, busy={"what": what, "t": float(t_now), "to": float(t_to)},
                           **more, **pacer.state())

        if cross is not None and start > 0:
            cross.restart_t = start / rate  # REBOUND integrates again from t = 0 up to here
        try:
            while k < stop_at:
                tb = np.arange(k, min(stop_at, k + block), dtype=np.float64) / rate
                model_ended = None
                rows_done = 0  # of this block's rows (a stop inside the block counts only those)
                if math.isfinite(span) or math.isfinite(cross_span):
                    # at most `span` s past the engine's state per call (an output instant further
                    # ahead than that is reached through waypoints: computed, not published), and a
                    # block of at most `cross_span` s of REBOUND, so its states go out as it goes
                    limit = min(engine_t + span, cross_t + cross_span)
                    fit = max(1, int(np.searchsorted(tb, limit, side="right")))
                    if engine_t + span < float(tb[0]):
                        what = (f"{opts.kind}: catching up to the restart step" if engine_t < (k - 1) / rate
                                else f"{opts.kind}: integrating to the next output step")
                        try:
                            for tw in _waypoints(engine_t, float(tb[0]), span):
                                engine.states(np.array([tw]))
                                kernels["loaded"] = True
                                engine_t = float(tw)
                                working(what, engine_t, float(tb[0]))
                        except ModelEnded as end:  # between two output steps: nothing more to publish
                            model_ended = str(end)
                    tb = tb[:fit]
                if model_ended is not None:
                    tb, a, b = tb[:0], np.zeros((0, len(names), 4 if opts.kind == "attitude" else 3)), np.zeros((0, len(names), 3))
                else:
                    try:
                        a, b = engine.states(tb)
                    except ModelEnded as end:  # publish what was computed, then end the run with the reason
                        a, b, tb, model_ended = end.q, end.w, tb[: end.rows], str(end)
                kernels["loaded"] = True
                engine_t = cross_t = float(tb[-1]) if tb.shape[0] else engine_t
                xc = cross.block(tb, a, b, working) if cross is not None else None
                for j in range(tb.shape[0]):
                    t = float(tb[j])
                    pace_to(t, pacer, commands, stopping, heartbeat, commands_from, t_reached)
                    if stopping["why"]:
                        raise _Stop
                    step_extra = None if xc is None else xc(j, k, t)
                    if own_channels:  # each body's further state messages, at the same seq
                        step_extra = (step_extra or []) + [
                            (model_keys[(i, src.kind)], messages.encode(src.message(j, t, k), src.kind))
                            for i, src in own_channels]
                    published += out.publish(t, k, a[j], b[j], step_extra)
                    rows_done = j + 1
                    t_reached = t
                    k += 1
                    heartbeat.beat(t=t_reached, step=k, **pacer.state())
                conservation.update(a, b)
                if model_ended is not None:
                    events.emit("error", float(t_reached), f"model ended: {model_ended}")
                    stopping["why"] = f"model ended: {model_ended}"
                    break
        except _Stop:
            if a is not None:
                conservation.update(a[:rows_done], b[:rows_done])
        wall = time.monotonic() - wall0
        extra = {"last_step": k - 1, "t_reached": float(t_reached), "reason": stopping["why"] or "end of scenario"}
        if cross is not None:
            extra["crosscheck_max_dr"] = cross.max_dr
        if commands_from.rejected:  # forged supervisor commands: counted by the logger from this event
            extra["rejected"] = dict(commands_from.rejected)
        events.end(float(t_reached), published, **extra)
        heartbeat.beat(force=True, t=t_reached, step=k, done=True)
        if not logger_gone:
            wait_until_logged(session, scenario.name, opts.kind)
    summary = {"process": opts.kind, "bodies": len(names), "steps": k - start, "messages": published,
               "t": float(t_reached), "wall_s": wall, "reason": extra["reason"], "rejected": extra.get("rejected", {})}
    per_body = conservation.report()
    if cross is not None:
        summary["crosscheck_max_dr"] = cross.max_dr
        for name, dr in cross.max_dr_by_body.items():
            per_body[name]["crosscheck_max_dr"] = dr
    summary["per_body"] = per_body
    return summary


class _StepOutput:
    """Publishes one output step: every body's payload (and the cross-check's), as one
    batch envelope (``batched``) or one signed put per key."""

    def __init__(self, kind: str, engine, keys: list[str], groups: dict[str, np.ndarray], session, batch,
                 signer, batched: bool, extra_keys: list[str]):
        self.kind, self.engine, self.keys, self.groups = kind, engine, keys, groups
        self.batch, self.signer = batch, signer
        self.group_keys = {m: messages.BatchKeys([keys[i] for i in ix]) for m, ix in groups.items()} if batched else None
        self.per_body = None if batched else {key: bus.declare_state_publisher(session, key)
                                              for key in [*keys, *extra_keys]}

    def publish(self, t: float, k: int, a: np.ndarray, b: np.ndarray, extra: list | None) -> int:
        """Step ``k`` at ``t`` with states ``a, b`` (rows per body) and the ``extra``
        ``(key, payload)`` pairs of the step (cross-checks, appendage states); returns the
        messages sent."""
        if self.per_body is None:  # payloads written as envelope entries in the same compiled pass
            runs = [(_encode_group(self.kind, self.engine, t, k, model, a[ix], b[ix], self.group_keys[model]), len(ix))
                    for model, ix in self.groups.items()]
            if extra is not None:
                runs.append(messages.frame_entries(extra))
            self.batch.publish_envelope(messages.batch_envelope(runs))
            return sum(count for _, count in runs)
        items = []
        for model, ix in self.groups.items():
            payloads = _encode_group(self.kind, self.engine, t, k, model, a[ix], b[ix])
            items.extend(zip((self.keys[i] for i in ix), payloads))
        if extra is not None:
            items.extend(extra)
        for key, payload in items:
            bus.signed_put(self.per_body[key], key, payload, self.signer)
        return len(items)


def _encode_group(kind: str, engine, t: float, k: int, model: str, a, b, keys=None):
    """One model group's payloads (list of bytes), or with ``keys`` their envelope entries (bytes)."""
    if kind == "orbit":
        if keys is None:
            return messages.encode_orbit_batch(t, k, model, a, b, engine.mu, engine.frame)
        return messages.frame_orbit_batch(keys, t, k, model, a, b, engine.mu, engine.frame)
    if keys is None:
        return messages.encode_attitude_batch(t, k, model, a, b)
    return messages.frame_attitude_batch(keys, t, k, model, a, b)


class _Conservation:
    """Drift of the conserved quantities over the states a propagator published.

    Orbit: specific energy (relative to mu/|r0|, the size of its terms, not to the energy
    itself, which is ~0 near parabolic orbits) and |r x v| (relative): ``energy_drift``
    and ``momentum_drift`` for a Kepler body, which conserves both; for a perturbed one
    (J2, zonals, third bodies) ``two_body_energy_change`` and ``two_body_momentum_change``,
    the physical change of quantities its model does not conserve (``astrodyn run``'s
    summary gives the conserved ones, e.g. E with J2).  Attitude: max
    ||q| - 1|; for torque-free bodies also rotational energy and inertial angular
    momentum C^T (J w) (relative).  Reported per body, from the first state published.
    """

    def __init__(self, kind: str, scenario: Scenario, engine):
        self.kind = kind
        self.names = list(engine.names)
        self.first = None
        self.dev = np.zeros((len(self.names), 2))
        self.qnorm = np.zeros(len(self.names))
        if kind == "orbit":
            self.mu = engine.mu
            self.two_body = np.array([m == "kepler" for m in engine.models], dtype=bool)
        else:
            self.J = np.array([scenario.body(n).attitude.inertia for n in self.names]).reshape(-1, 3, 3)
            self.free = np.array([m == "torque_free" for m in engine.models], dtype=bool)

    def _values(self, a, b):
        if self.kind == "orbit":
            rn = np.linalg.norm(a, axis=-1)
            energy = 0.5 * np.einsum("...i,...i->...", b, b) - self.mu / rn
            h = np.linalg.norm(np.cross(a, b), axis=-1)
            return energy, h, rn
        from astrodyn.rotation import quat_conjugate, quat_rotate

        Hb = np.einsum("nij,tnj->tni", self.J, b)
        T = 0.5 * np.einsum("tni,tni->tn", b, Hb)
        Hi = quat_rotate(quat_conjugate(a), Hb)  # C^T H_body: inertial components
        return T, Hi, np.abs(np.linalg.norm(a, axis=-1) - 1.0)

    def update(self, a, b) -> None:
        if a.shape[0] == 0 or not self.names:
            return
        x, y, z = self._values(a, b)
        if self.first is None:
            self.first = (x[0].copy(), y[0].copy(), z[0].copy())
        x0, y0, z0 = self.first
        if self.kind == "orbit":
            self.dev[:, 0] = np.maximum(self.dev[:, 0], np.max(np.abs(x - x0), axis=0) * z0 / self.mu)
            self.dev[:, 1] = np.maximum(self.dev[:, 1], np.max(np.abs(y - y0), axis=0) / np.where(y0 > 0, y0, 1.0))
        else:
            self.qnorm = np.maximum(self.qnorm, np.max(z, axis=0))
            scale_t = np.where(x0 > 0, x0, 1.0)
            h0 = np.linalg.norm(y0, axis=-1)
            self.dev[:, 0] = np.maximum(self.dev[:, 0], np.max(np.abs(x - x0), axis=0) / scale_t)
            self.dev[:, 1] = np.maximum(self.dev[:, 1],
                                        np.max(np.linalg.norm(y - y0, axis=-1), axis=0) / np.where(h0 > 0, h0, 1.0))

    def report(self) -> dict[str, dict]:
        out = {}
        for i, name in enumerate(self.names):
            if self.kind == "orbit":
                e, h = float(self.dev[i, 0]), float(self.dev[i, 1])
                out[name] = dict(zip(TWO_BODY_KEYS[bool(self.two_body[i])], (e, h)))
            else:
                row = {"quat_norm_error": float(self.qnorm[i])}
                if self.free[i]:
                    row.update(rot_energy_drift=float(self.dev[i, 0]), inertial_momentum_drift=float(self.dev[i, 1]))
                out[name] = row
        return out


def wait_until_logged(session, scenario: str, kind: str, timeout_s: float = LOGGED_WAIT_S) -> None:
    """Keep the session open until the logger has our end-of-run event (so every sample
    before it too: puts return once queued locally, and closing the session drops what is
    still queued -- measured: 7000 of 600k samples lost without this wait).  Gives up when
    the logger is gone or after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    status_key = messages.status_key(scenario)
    while time.monotonic() < deadline:
        replies = bus.query_json(session, status_key, timeout_s=2.0)
        if not replies:  # no logger answering: nothing to wait for
            return
        if any(kind in (r.get("ended") or {}) for r in replies):
            return
        time.sleep(0.05)


def _fifo():
    import zenoh

    return zenoh.handlers.FifoChannel(256)


class CommandVerifier:
    """Accepts a supervisor command only when it carries a valid authenticator of the run
    signed by the supervisor (``serve``) -- when this process runs under a supervisor (the
    run secret is in its environment); outside a run every command is accepted.  Refused
    commands are counted in ``refused`` and noted on stderr (at most 20 notes)."""

    SUPERVISORS = ("serve", "run")

    def __init__(self):
        from astrodyn import auth

        secret = auth.secret_from_environment()
        self._verifier = None if secret is None else auth.Verifier(secret)
        self.refused = 0
        #: refusals per reason (the end-of-run event carries them: the logger counts them)
        self.rejected: dict[str, int] = {}

    def accepts(self, sample) -> bool:
        if self._verifier is None:
            return True
        from astrodyn import auth

        attachment = sample.attachment
        try:
            sender = self._verifier.verify(str(sample.key_expr), sample.payload.to_bytes(),
                                           None if attachment is None else attachment.to_bytes())
            if sender in self.SUPERVISORS:
                return True
            why, reason = f"signed by {sender!r}, not the supervisor", "wrong-publisher"
        except auth.AuthError as exc:
            why = reason = exc.reason
        self.refused += 1
        self.rejected[reason] = self.rejected.get(reason, 0) + 1
        if self.refused <= 20:
            print(f"propagator: refused a command ({why})", file=sys.stderr)
        return False


def command_anchor(cmd: dict) -> tuple[float, float] | None:
    """The schedule ``(wall, t_sim)`` a supervisor's ``rate`` or ``resume`` command gives
    (``"anchor": [monotonic wall s, sim t s]``, the same for every process), or None: the
    process paces from its own sim time.  ValueError for one that is not two finite numbers."""
    anchor = cmd.get("anchor")
    if anchor is None:
        return None
    if (not isinstance(anchor, list) or len(anchor) != 2
            or not all(type(x) in (int, float) and math.isfinite(x) for x in anchor)):
        raise ValueError(f"anchor: expected [wall s, sim t s], two finite numbers, got {str(anchor)[:80]}")
    return float(anchor[0]), float(anchor[1])


def obey_commands(commands, pacer: Pacer, t: float, stopping: dict, heartbeat, commands_from: CommandVerifier,
                  more_verbs: dict | None = None) -> None:
    """Apply pending supervisor commands (malformed ones are ignored with a note on stderr,
    unauthenticated ones refused, see :class:`CommandVerifier`); ``more_verbs``: verb ->
    handler of the command dict, for a process's own verbs (the plant's ``fault``)."""
    while (sample := commands.try_recv()) is not None:
        if not commands_from.accepts(sample):
            continue
        try:
            cmd = json.loads(sample.payload.to_bytes())
            verb = cmd["verb"]
            if verb == "pause":
                pacer.pause()
            elif verb == "resume":
                pacer.resume(t, command_anchor(cmd))
            elif verb == "rate":
                pacer.set_factor(float(cmd["factor"]), t, command_anchor(cmd))
            elif verb == "stop":
                stopping["why"] = "stop requested"
                pacer.resume(t)
            elif more_verbs and verb in more_verbs:
                more_verbs[verb](cmd)
            else:
                raise ValueError(f"verb: expected pause | resume | rate | stop, got {verb!r}")
        except (ValueError, KeyError, TypeError) as exc:
            print(f"propagator: ignored a malformed command: {exc}", file=sys.stderr)


def pace_to(t: float, pacer: Pacer, supervisor, stopping: dict, heartbeat, commands_from: CommandVerifier,
            t_reached: float, more_verbs: dict | None = None, while_waiting=None) -> None:
    """Obey the supervisor's commands, then wait until sim time ``t`` is due at the pacer's
    rate (or while paused), beating and obeying every 50 ms; ``while_waiting()`` is called
    on each of those turns (the plant takes commands then).  Returns at once on a stop."""
    obey_commands(supervisor, pacer, t, stopping, heartbeat, commands_from, more_verbs)
    wait = pacer.wait_time(t)
    while (wait > 0 or pacer.paused) and not stopping["why"]:
        time.sleep(min(wait, 0.05) if wait > 0 else 0.05)
        if while_waiting is not None:
            while_waiting()
        heartbeat.beat(t=t_reached, **pacer.state())
        obey_commands(supervisor, pacer, t, stopping, heartbeat, commands_from, more_verbs)
        wait = pacer.wait_time(t)


class _CrossCheck:
    """REBOUND IAS15 alongside the orbit engine; differences per body as crosscheck messages.

    Bodies flagged ``cross_check`` in the config (every orbit with ``all_bodies``) whose
    model REBOUND can run here: ``kepler`` (point mass) and ``j2`` (REBOUND with the J2
    force of :mod:`astrodyn.crosscheck`).  Others are listed in ``skipped``.
    """

    def __init__(self, scenario: Scenario, engine: OrbitEngine, all_bodies: bool = False):
        from astrodyn.crosscheck import ReboundScene

        cb = scenario.central_body
        self.scenes = []  # (indices into engine bodies, keys, ReboundScene)
        self.skipped = []
        self.max_dr = 0.0
        self.max_dr_by_body: dict[str, float] = {}
        chosen = [i for i, b in enumerate(engine.names) if all_bodies or scenario.body(b).cross_check]
        for model in ("kepler", "j2"):
            idx = [i for i in chosen if engine.models[i] == model]
            if not idx:
                continue
            kw = dict(model="j2", j2=cb.J[0], body_radius=cb.radius) if model == "j2" else {}
            scene = ReboundScene(engine.r0[idx], engine.v0[idx], engine.mu, **kw)
            keys = [messages.crosscheck_key(scenario.name, engine.names[i]) for i in idx]
            self.scenes.append((np.asarray(idx), keys, scene))
        self.skipped = [engine.names[i] for i in chosen if engine.models[i] not in ("kepler", "j2")]

    #: sim s REBOUND advances between two calls of ``working`` (set by the propagator)
    span = math.inf
    #: a restarted process's first output time: REBOUND catches up from t = 0 to it
    restart_t = -math.inf

    def _reach(self, scene, t: float, working):
        """REBOUND's states at ``t``, advanced in parts of at most :attr:`span` s with a
        ``working(what, t_now, t_to)`` call between them (the heartbeat).  A restarted
        process integrates again from t = 0 (the reference never takes a state from
        astrodyn's output), so its first block can take as long as the run so far."""
        what = ("orbit: cross-check: REBOUND integrates again from t = 0 to the restart step" if t <= self.restart_t
                else "orbit: cross-check (REBOUND)")
        while working is not None and t - scene.t > self.span:
            scene.advance_to(scene.t + self.span)
            working(what, scene.t, t)
        r, v = scene.advance_to(t)
        # REBOUND's state belongs to scene.t (the compensated sum of its steps), which rounding
        # leaves ~1e-9 s off t after 1e6 s: carried to t to first order (two-body acceleration;
        # the neglected terms are ~|a| dt^2, 1e-17 m), as astrodyn.crosscheck evaluates at it
        dt = t - scene.t
        if dt != 0.0:
            rn = np.linalg.norm(r, axis=-1, keepdims=True)
            r, v = r + v * dt, v - scene.mu * r / rn**3 * dt
        return r, v

    def block(self, tb, r, v, working=None):
        if not self.scenes:
            return None
        parts = []
        for idx, keys, scene in self.scenes:
            refs = []
            for t in tb:
                refs.append(self._reach(scene, float(t), working))
                if working is not None:  # the heartbeat (at most every 0.5 s) between instants too
                    working("orbit: cross-check (REBOUND)", scene.t, float(tb[-1]))
            dr = np.stack([r[j, idx] - refs[j][0] for j in range(len(tb))])
            dv = np.stack([v[j, idx] - refs[j][1] for j in range(len(tb))])
            norms = np.max(np.linalg.norm(dr, axis=-1), axis=0)
            self.max_dr = max(self.max_dr, float(np.max(norms)))
            for key, value in zip(keys, norms):
                body = key.rsplit("/", 2)[-2]
                self.max_dr_by_body[body] = max(self.max_dr_by_body.get(body, 0.0), float(value))
            parts.append((keys, dr, dv))

        def items(j, k, t):
            return [(key, messages.encode(messages.crosscheck_message(t, k, dr[j, n], dv[j, n])))
                    for keys, dr, dv in parts for n, key in enumerate(keys)]

        return items


# --------------------------------------------------------------------------- process entry


def service_main(kind: str, argv: list[str] | None = None) -> int:
    """Entry point of a propagator process (``python -m astrodyn.service.propagator KIND``,
    ``services/<kind>.py``): parse, load the scenario, wire, run.

    Exit status: 0 done (or stopped cleanly), 1 runtime/bus error, 2 bad arguments or config.
    Prints a one-line JSON summary on stdout.
    """
    import argparse

    from astrodyn.scenario import ScenarioError, load

    ap = argparse.ArgumentParser(prog=f"python -m astrodyn.service.propagator {kind}",
                                 description=f"astrodyn {kind} propagator: publish the scenario's {kind} states on Zenoh")
    ap.add_argument("config", help="scenario TOML file")
    ap.add_argument("--real-time-factor", type=float, default=math.inf,
                    help="sim seconds per wall second (default inf: as fast as possible)")
    ap.add_argument("--cross-check", action="store_true", help="orbit: run REBOUND IAS15 alongside for every body")
    ap.add_argument("--start-step", type=int, default=0, help="first output step to publish (resume)")
    ap.add_argument("--resume-state", default=None, metavar="JSON",
                    help="states at step START_STEP-1 for the integrated bodies (astrodyn.service.resume.write_state_file)")
    ap.add_argument("--first-event-seq", type=int, default=0, help="seq of this process's first event (a restart)")
    ap.add_argument("--pace-anchor", type=float, nargs=2, default=None, metavar=("WALL", "T"),
                    help="keep the schedule on which sim time T was due at monotonic wall time WALL (a restarted "
                         "process catches up with the run instead of starting a new schedule)")
    ap.add_argument("--paused", action="store_true",
                    help="start paused: publish nothing until the supervisor's resume (serve restarts a process "
                         "while it is paused)")
    ap.add_argument("--max-steps", type=int, default=None, help="publish at most this many steps")
    ap.add_argument("--batch", choices=("auto", "always", "never"), default="auto",
                    help=f"publish one envelope per step instead of per-body samples (auto: above {BATCH_THRESHOLD} bodies)")
    ap.add_argument("--endless", action="store_true", help="keep going past the scenario's duration until stopped (serve)")
    ap.add_argument("--block", type=int, default=0, help="output steps per engine call (default automatic)")
    ap.add_argument("--wait-logger", type=float, default=30.0, help="seconds to wait for the logger's liveliness token")
    ap.add_argument("--threads", default=None, help="numba threads (default $ASTRODYN_THREADS, else 1; 'all': every core)")
    bus.add_bus_arguments(ap)
    args = ap.parse_args(argv)
    share_fate_with_supervisor()  # never outlive the run / serve that started us
    try:  # thread policy: one numba thread per service process unless asked (astrodyn.jit)
        set_threads(service_threads(args.threads))
    except ValueError as exc:
        print(f"{kind}: {exc}", file=sys.stderr)
        return 2
    try:
        scenario = load(args.config)
    except ScenarioError as exc:
        print(f"{kind}: {exc}", file=sys.stderr)
        return 2
    resume_state = None
    if args.resume_state is not None:
        from astrodyn.service.resume import ResumeError, read_state_file

        try:
            resume_state = read_state_file(args.resume_state, kind)
        except ResumeError as exc:
            print(f"{kind}: {exc}", file=sys.stderr)
            return 2
    if args.start_step < 0 or args.first_event_seq < 0:
        print(f"{kind}: --start-step and --first-event-seq: expected integers >= 0", file=sys.stderr)
        return 2
    if not (args.real_time_factor > 0):
        print(f"{kind}: --real-time-factor: expected a number > 0, got {args.real_time_factor}", file=sys.stderr)
        return 2
    opts = PropagatorOptions(kind=kind, real_time_factor=args.real_time_factor, block=args.block,
                             cross_check=args.cross_check, wait_logger_s=args.wait_logger,
                             start_step=args.start_step, max_steps=args.max_steps, endless=args.endless,
                             resume_state=resume_state, first_event_seq=args.first_event_seq,
                             pace_anchor=None if args.pace_anchor is None else tuple(args.pace_anchor),
                             start_paused=args.paused)
    try:
        with bus.session_from_args(args) as session:
            summary = run_propagator(scenario, session, opts)
    except bus.BusError as exc:
        print(f"{kind}: {exc}", file=sys.stderr)
        return 1
    except ValueError as exc:  # a resume state that does not fit the scenario
        print(f"{kind}: {exc}", file=sys.stderr)
        return 2
    except Exception as exc:  # a numeric failure: the traceback, then its one line last (the supervisor's tail)
        import traceback

        traceback.print_exc(file=sys.stderr)
        print(f"{kind}: failed: {type(exc).__name__}: {exc}", file=sys.stderr, flush=True)
        return 1
    print(json.dumps(summary, separators=(",", ":")), flush=True)
    if str(summary.get("reason", "")).startswith("model ended"):  # states up to there are published and logged
        print(f"{kind}: {summary['reason']}", file=sys.stderr, flush=True)
        return MODEL_ENDED_EXIT
    return 0


if __name__ == "__main__":
    if len(sys.argv) < 2 or sys.argv[1] not in ("orbit", "attitude"):
        print("usage: python -m astrodyn.service.propagator {orbit,attitude} CONFIG [options]", file=sys.stderr)
        sys.exit(2)
    sys.exit(service_main(sys.argv[1], sys.argv[2:]))
