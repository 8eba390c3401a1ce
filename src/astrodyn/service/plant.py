"""The plant process: the closed loop's bodies, stepped with the controllers' commands.

``python -m astrodyn.service.plant CONFIG`` (started by ``astrodyn run`` / ``serve`` when
the scene has a ``[control]`` table; docs/control.md is the contract for controllers).

Every output step ``k`` (``t = k / rate``), for the scene's actuated bodies
(:class:`astrodyn.plant.Plant`):

1. faults that begin now take effect and are recorded as ``fault`` events;
2. states (``<body>/orbit``, ``<body>/attitude``, model ``actuated``; a flexible body's
   ``<body>/appendages`` too, at its attitude's seq) and the sensor samples due
   (``<body>/gyro|star_tracker|gps|tachometer``) are published;
3. on a control step (every ``control.period``) the plant publishes ``@tick`` (which
   carries the step's states and samples too: Zenoh orders samples per subscriber, not
   across a client's subscribers, so a controller reads one consistent step from it) and, in
   lockstep mode, waits until every controller of ``control.controllers`` has answered
   the tick on ``@done/<controller>`` (with the number of commands it sent) and those
   commands have arrived, putting the same tick again every :data:`TICK_REPEAT_S` s of
   wall time while it waits (a controller started late, or whose subscriber was not yet
   matched when the tick went out, gets it then; one that has it already drops the copy, its
   ``seq`` not above the last tick's); a controller that does not answer within
   ``control.timeout`` of the first put ends the run with an error naming it (exit 1; the
   recording stays valid);
4. commands with ``t <= t_k`` are applied at ``t_k``, in arrival order; commands with
   ``t_k < t < t_k+1`` (already received) at their own ``t``, inside the step (the body
   is advanced to it first): an impulse lands exactly when commanded.  Each applied
   command is re-published, signed by the plant, on its ``<body>/command`` key (that copy
   is what the logger records); ``<body>/actuators`` then says what the step applied;
5. the bodies advance to ``t + 1 / rate`` with the held commands.

The plant signs what it publishes with the run secret (``ADA1``, :mod:`astrodyn.auth`);
given the control token it also appends to its ticks and events the ``ADP1`` part that an
outside controller, holding only the token, checks (docs/control.md, "Authentication").

Trust (docs/security.md): a command or an answer is taken only from a process of the run
(authenticator of the run secret, signed by the process named in its ``sender``) or from
an outside controller that presents the run's control token (``--control-token-file``).
An answer is taken only from a controller of ``control.controllers``, for a tick the
plant has published (its ``seq`` at most the last tick's), and once per controller and tick
(above that controller's last answer): in lockstep that is the current control step.  An
answer to a tick the plant never sent (``unsent-tick``, e.g. a controller fooled by a forged
``@tick``), a second answer (``repeated-answer``) or one from another name
(``unknown-controller``) is rejected.  Everything else is counted per reason (``rejected``
in the end event and the summary, with examples), never applied, never fatal.  A sample
that authenticates but is malformed, or commands a body that is not the plant's, is counted
apart as its author's error (``controller_errors``: by author and reason in the summary),
not among the rejected: what the run reports as an attack is what did not authenticate.

Free mode (``control.mode = "free"``): nothing waits; the plant paces sim time at the
scenario's real-time factor and applies what has arrived; commands whose time has passed
are applied at once and counted as ``late``.

``--commands REC.mcap``: no controllers; the commands recorded in REC are applied at the
steps where REC's actuator states say they were, and the faults at the times REC's
``fault`` events say they began (the config's and those of serve's ``fault`` verb), which
reproduces REC's states and sensor samples bit for bit, to the config's duration (past
REC's last step the commands last applied stay held; ``astrodyn run`` checks REC first and
says so, :func:`astrodyn.service.runner.check_command_recording`).
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import gc
import json
import math
import queue
import re
import sys
import time
from pathlib import Path

import numpy as np
import zenoh

from astrodyn import auth, bus, messages
from astrodyn.messages.definitions import MAX_APPLIED
from astrodyn.messages.keys import NAME_FULL_RE
from astrodyn.plant import CommandRefused, FlexiblePlantBody, Plant, command_id
from astrodyn.recording import RecordingError
from astrodyn.service.children import share_fate_with_supervisor
from astrodyn.service.propagator import (
    BATCH_THRESHOLD,
    CommandVerifier,
    Pacer,
    command_key,
    obey_commands,
    pace_to,
    wait_until_logged,
)
from astrodyn.signals import catch_job_control, catch_stop_signals

__all__ = ["main", "run_plant", "PlantLoop", "recorded_commands", "read_command_recording", "CommandRecording",
           "recorded_faults", "tick_payload", "encode_stamped",
           "ControllerTimeout", "PROCESS"]

PROCESS = "plant"
#: Samples waiting in the plant's intake before it drops new ones (a flood from a hostile
#: process must not grow memory without bound; a controller sends a few per step).  The
#: intake is a callback into a queue.Queue, not a zenoh FIFO or ring channel read by the
#: plant's thread (measured faster by 50-70 us a round trip): a FIFO channel that fills
#: blocks zenoh's threads and deadlocked a lockstep run under a flood of forged commands,
#: a ring channel drops the controller's commands under the same flood, while a callback
#: slows zenoh's receiving enough that the hub drops the flood, not the controller's
#: messages (tests/test_closed_loop.py).
INTAKE_CAPACITY = 100_000
MAX_EXAMPLES = 20
#: Commands one sender may have waiting for their time, per body (more are refused): a
#: sender's flood of far-future commands fills its own allowance, not the others'.
MAX_PENDING = 10_000
#: Commands waiting for their time from all senders not in ``control.controllers`` together
#: (free mode: token holders may command under any name); the controllers of
#: ``control.controllers`` are held to MAX_PENDING alone, so that nobody else can lock them out.
MAX_PENDING_UNLISTED = 100_000
#: Lockstep round trips kept for the summary's percentiles.
MAX_ROUND_TRIPS = 1_000_000
#: Lockstep: wall seconds between puts of the current tick while the plant waits for answers.
TICK_REPEAT_S = 0.5


def _largest_command() -> int:
    """Bytes of the largest valid command (every actuator field, ``MAX_WHEELS`` wheels, the
    longest sender and seq, floats of the longest repr), canonical JSON."""
    from astrodyn.messages.definitions import MAX_WHEELS
    from astrodyn.messages.keys import MAX_SEQ

    x = -1.2345678901234567e-300  # the longest repr of a float
    return len(messages.encode({"t": x, "seq": MAX_SEQ, "sender": "s" * 128, "torque": [x] * 3,
                                "wheel_torque": [x] * MAX_WHEELS, "dv": [x] * 3, "thrust": [x] * 3, "frame": "inertial"},
                               "command"))


#: Commands one body applies in one step (the most an ActuatorState's ``applied`` names); more are refused.
MAX_APPLIED_PER_STEP = MAX_APPLIED
#: Payload of a command or an answer on its own key: larger ones are rejected (``oversized``)
#: before they are queued.  Twice the largest valid command (a non-canonical encoder's
#: spaces and indentation), plus 1 kB.
MAX_COMMAND_BYTES = 2 * _largest_command() + 1024
#: A controller's ``@batch`` envelope: at most this many commands' worth (keys included) per
#: actuated body, ``MAX_BATCH_MIN_ENTRIES`` at least.
MAX_BATCH_ENTRIES_PER_BODY = 4
MAX_BATCH_MIN_ENTRIES = 1024
#: Bytes the intake may hold waiting (samples beyond are dropped, as beyond INTAKE_CAPACITY).
INTAKE_BYTES = 256 * 2**20
#: Command senders the plant keeps track of (seq, counts); commands of further senders are
#: refused (free mode; in lockstep only ``control.controllers`` may command).
MAX_SENDERS = 1024


class ControllerTimeout(RuntimeError):
    """A controller did not answer a control step in time (lockstep)."""


class Intake:
    """Commands and step answers off the bus, authenticated, decoded, counted."""

    def __init__(self, scenario: str, bodies, verifier: auth.Verifier | None, token: str | None):
        self.scenario = scenario
        self.bodies = set(bodies)
        # the command keys of the plant's bodies, known valid: judged without parsing the key
        self.command_keys = {messages.body_key(scenario, b, "command"): b for b in self.bodies}
        self.verifier = verifier
        self.token = token
        self.queue: queue.Queue = queue.Queue(INTAKE_CAPACITY)
        self.rejected: dict[str, int] = {}
        self.examples: list[str] = []
        self.dropped = 0
        self.max_batch = max(MAX_BATCH_MIN_ENTRIES, MAX_BATCH_ENTRIES_PER_BODY * len(self.bodies)) * (MAX_COMMAND_BYTES + 512)
        self.oversized = self.oversized_counted = 0  # counted by Zenoh's thread, folded into rejected by the plant's
        self.oversized_examples: list[str] = []
        self.bytes_in = self.bytes_out = 0  # queued / taken payload bytes (INTAKE_BYTES)
        #: commands rejected here, by the sender they name (or the controller whose envelope
        #: held them): they arrived, and count toward what that sender announced (lockstep)
        self.rejected_from: list[str] = []
        #: authenticated samples rejected for what they say, by their author and reason (:meth:`reject`)
        self.controller_errors: dict[str, dict[str, int]] = {}
        self.controller_error_examples: list[str] = []

    def callback(self, sample) -> None:  # Zenoh's thread: copy out, never block
        key = str(sample.key_expr)
        size = len(sample.payload)
        if size > (self.max_batch if "/@batch/" in key else MAX_COMMAND_BYTES):  # before a copy is made
            self.oversized += 1
            if len(self.oversized_examples) < MAX_EXAMPLES:
                self.oversized_examples.append(f"oversized: {key[:100]}: {size} bytes")
            return
        if self.bytes_in - self.bytes_out + size > INTAKE_BYTES:
            self.dropped += 1
            return
        a = sample.attachment
        try:
            self.queue.put_nowait((key, sample.payload.to_bytes(), None if a is None else a.to_bytes()))
            self.bytes_in += size
        except queue.Full:
            self.dropped += 1

    def fold_oversized(self) -> None:
        """Count the oversized samples the callback refused among the rejected (the plant's thread)."""
        n = self.oversized
        if n != self.oversized_counted:
            self.rejected["oversized"] = self.rejected.get("oversized", 0) + n - self.oversized_counted
            self.oversized_counted = n
            while self.oversized_examples and len(self.examples) < MAX_EXAMPLES:
                self.examples.append(self.oversized_examples.pop(0))

    def reject(self, reason: str, detail: str, sender: str | None = None, author: str | None = None) -> None:
        """Count a rejected sample under ``reason``.  ``sender``: the controller a rejected
        command counts toward (lockstep).  ``author``: for a sample that authenticated (the
        run secret, signed by ``author``, or the control token, ``author`` then the sender it
        names), rejected for what it says: a controller's error, counted in
        ``controller_errors`` (not among the rejected, which are what did not come from the
        run: an attack)."""
        if author is not None:
            if author not in self.controller_errors and len(self.controller_errors) >= MAX_SENDERS:
                author = "(more controllers)"
            counts = self.controller_errors.setdefault(author, {})
            counts[reason] = counts.get(reason, 0) + 1
            if len(self.controller_error_examples) < MAX_EXAMPLES:
                self.controller_error_examples.append(f"{author}: {reason}: {detail[:200]}")
        else:
            self.rejected[reason] = self.rejected.get(reason, 0) + 1
            if len(self.examples) < MAX_EXAMPLES:
                self.examples.append(f"{reason}: {detail[:200]}")
        if sender is not None:
            self.rejected_from.append(sender)

    def judge_batch(self, key: str, payload: bytes, attachment: bytes | None) -> list[tuple[str, str, dict]]:
        """The commands of a controller's envelope on ``@batch/<controller>`` (one
        authenticator for all; each entry a ``<body>/command`` of that controller)."""
        controller = key.rsplit("/", 1)[-1]
        if messages.is_run_process_name(controller):  # (a config refuses these as controller names)
            return []  # the run's own state envelopes: not for the plant
        signer = self._authenticate(key, payload, attachment)
        if signer is None:
            return []
        try:
            items = messages.decode_batch(payload)
        except messages.MessageError as exc:
            self.reject("malformed", f"{key}: {exc}", author=signer if signer is not True else controller)
            return []
        out = []
        for entry_key, entry in items:
            judged = self._judge_entry(entry_key, entry, signer if signer is not True else None, controller)
            if judged is not None:
                if judged[2]["sender"] != controller:
                    self.reject("impersonation", f"{key}: entry {entry_key[:100]} is not {controller!r}'s",
                                controller if judged[0] == "command" else None)
                    continue
                out.append(judged)  # commands, and the answer to the tick, which may close the envelope
        return out

    def _authenticate(self, key: str, payload: bytes, attachment: bytes | None):
        """The verified signer's name, True for a valid control token (or no verifier), None (counted) otherwise."""
        if self.verifier is None:
            return True
        presented = auth.token_from_attachment(attachment)
        if self.token is not None and presented is not None:
            if not auth.token_matches(self.token, presented):
                self.reject("bad-token", key)
                return None
            return True
        try:
            return self.verifier.verify(key, payload, attachment)
        except auth.AuthError as exc:
            self.reject(exc.reason, key)
            return None

    def judge(self, key: str, payload: bytes, attachment: bytes | None) -> tuple[str, str, dict] | None:
        """``(kind, body_or_controller, message)`` of a sample the plant may act on, else None
        (counted).  The plant's own re-published commands are skipped silently."""
        signer = self._authenticate(key, payload, attachment)
        if signer is None or signer == PROCESS:
            return None  # refused (counted), or our own copy of an applied command
        return self._judge_entry(key, payload, signer if signer is not True else None)

    def _judge_entry(self, key: str, payload: bytes, signer: str | None,
                     envelope_of: str | None = None) -> tuple[str, str, dict] | None:
        """``envelope_of``: the controller whose ``@batch`` envelope held the entry."""
        who = self.command_keys.get(key)
        try:
            if who is not None:  # the common case: a command for one of the plant's bodies
                return self._judged("command", who, key, messages.decode(payload, "command"), signer)
            _, who, kind = messages.parse_key(key)  # ("s", body, "command") or ("s", "@done", controller)
            if who == "@done":
                who = kind
            kind = messages.kind_of_key(key)
            if kind not in ("command", "done") or not key.startswith(f"{messages.PREFIX}/{self.scenario}/"):
                raise messages.MessageError(f"key: expected a command or an answer of scenario {self.scenario!r}")
            msg = messages.decode(payload, kind)
        except messages.MessageError as exc:
            is_command = who is not None or key.endswith("/command")
            author = envelope_of or signer or _named_sender(payload)
            self.reject("malformed", f"{key}: {exc}", author if is_command else None,
                        author=author or "(a control-token holder, no sender named)")
            return None
        return self._judged(kind, who, key, msg, signer)

    def _judged(self, kind: str, who: str, key: str, msg: dict, signer: str | None) -> tuple[str, str, dict] | None:
        if signer is not None and signer != msg["sender"]:
            self.reject("impersonation", f"{key}: sender {msg['sender']!r} signed by {signer!r}",
                        signer if kind == "command" else None)
            return None
        if kind == "command" and who not in self.bodies:
            self.reject("not-actuated", f"{key}: body {who!r} is not one of the plant's bodies", msg["sender"],
                        author=signer or msg["sender"])
            return None
        if kind == "done" and who != msg["sender"]:
            self.reject("impersonation", f"{key}: answer of {msg['sender']!r} on {who!r}'s key")
            return None
        return kind, who, msg


def _named_sender(payload: bytes) -> str | None:
    """The ``sender`` a rejected command payload names, if it is JSON naming a valid one."""
    sender = messages.json_field(payload, "sender")
    return sender if isinstance(sender, str) and NAME_FULL_RE.fullmatch(sender) else None


@dataclasses.dataclass
class CommandRecording:
    """What a recording holds for ``--commands`` re-simulation (:func:`read_command_recording`)."""

    #: step -> ``(body, command)`` in the order the plant applied them (empty when read to check only)
    by_step: dict[int, list[tuple[str, dict]]]
    #: commands its actuator states name as applied (each once)
    applied: int
    #: the last output step with an actuator state (the recording's last step of the loop; -1: none)
    last_step: int
    #: the first output step with an actuator state (-1: none): 0 for a recording of a run from
    #: its start; more for a later part of a rolled series, whose steps before are in the
    #: earlier parts (``astrodyn run`` refuses it: :func:`astrodyn.service.runner.check_command_recording`)
    first_step: int
    #: of ``applied``, those applied at a step at or after the scenario's ``n_steps`` (a served
    #: run goes past the config's duration): a re-simulation of the config never reaches them
    after_end: int
    #: "" for a complete file, else why not (:meth:`astrodyn.recording.stream.McapStream.report`:
    #: cut short, corrupt chunks), e.g. a run whose logger was killed
    damage: str


def recorded_commands(path: str | Path, scenario) -> dict[int, list[tuple[str, dict]]]:
    """The commands of recording ``path``, by the output step at which they were applied:
    ``{k: [(body, command), ...]}`` in the order the plant applied them (its actuator states'
    ``applied`` lists); :func:`read_command_recording`, whose checks it makes."""
    return read_command_recording(path, scenario).by_step


def read_command_recording(path: str | Path, scenario, keep: bool = True) -> CommandRecording:
    """Read recording ``path`` for a re-simulation of ``scenario`` (the
    :class:`astrodyn.scenario.Scenario` re-simulated, or only its name).

    ValueError naming the channel and log time for what the plant never records: one
    command id recorded twice with different contents, a command applied at two steps, and
    (given the Scenario) a command or actuator state of a body that is not the scene's plant
    body, or a command applied in a step that ends before its ``t`` (it would move the body
    to that ``t`` inside the step).  ``keep=False`` makes the same checks but keeps no
    command (``by_step`` empty; each command is held as its payload bytes while the file is
    read, not decoded): the check ``astrodyn run`` makes before it starts the plant, which
    reads the file again."""
    from astrodyn.recording.stream import open_stream

    name = scenario if isinstance(scenario, str) else scenario.name
    bodies = rate = None
    n_steps = math.inf
    if not isinstance(scenario, str):
        from astrodyn.scenario.control import plant_bodies

        bodies, rate, n_steps = plant_bodies(scenario), scenario.rate, scenario.n_steps
    # body/id -> (the command, or its payload when not kept; its t; channel; log time ns)
    commands: dict[str, tuple[dict | bytes, float, str, int]] = {}
    applied: list[tuple[int, str, list[str], str, int]] = []
    last_step = -1
    first_state_step = -1  # the first output step with an actuator state
    # the plant records every actuated body's actuator state at every output step: per
    # channel, the last seq read and the first hole (a file with steps cut out of its middle
    # would re-simulate them without their commands: session 20 probe D, D2)
    previous: dict[str, int] = {}
    hole: tuple[str, int, int, int] | None = None
    prefix = f"{messages.PREFIX}/{name}/"
    with open_stream(path) as s:
        for m in s.messages():
            try:
                _, body, kind = messages.parse_key(m.topic)
            except messages.MessageError:
                continue
            if not m.topic.startswith(prefix) or kind not in ("command", "actuators"):
                continue
            if bodies is not None and body not in bodies:
                raise ValueError(f"{m.topic} at log time {m.log_time} ns: body {body!r} is not an actuated body of "
                                 f"scenario {name!r} ({', '.join(bodies) or 'none'})")
            msg = _decode_recorded(m, kind)
            if kind == "command":
                cid = f"{body}/{command_id(msg['sender'], msg['seq'])}"
                first = commands.get(cid)
                if first is None:
                    commands[cid] = (msg if keep else bytes(m.data), msg["t"], m.topic, m.log_time)
                elif first[0] != (msg if keep else m.data) and \
                        (keep or messages.decode(first[0], "command") != msg):  # (a copy need not be canonical)
                    raise ValueError(f"{m.topic} at log time {m.log_time} ns: command {cid} is recorded twice with "
                                     f"different contents (first at {first[2]} at log time {first[3]} ns)")
            else:
                last_step = max(last_step, msg["seq"])
                first_state_step = msg["seq"] if first_state_step < 0 else min(first_state_step, msg["seq"])
                before = previous.get(m.topic)
                if before is not None and msg["seq"] > before + 1 and hole is None:
                    hole = (m.topic, before + 1, msg["seq"] - 1, m.log_time)
                if before is None or msg["seq"] > before:
                    previous[m.topic] = msg["seq"]
                if msg.get("applied"):
                    applied.append((msg["seq"], body, msg["applied"], m.topic, m.log_time))
        damage = "" if not s.truncated and not s.corrupt_chunks else s.report()
    out: dict[int, list[tuple[str, dict]]] = {}
    first_step: dict[str, tuple[int, str, int]] = {}
    count = after_end = 0
    for k, body, ids, topic, log_time in sorted(applied, key=lambda x: x[0]):
        where = f"{topic} at log time {log_time} ns"
        for cid in ids:
            key = f"{body}/{cid}"
            if key in first_step and first_step[key][0] != k:
                earlier = first_step[key]
                raise ValueError(f"{where}: actuator state of {body} at step {k} names command {cid}, already "
                                 f"applied at step {earlier[0]} ({earlier[1]} at log time {earlier[2]} ns): the plant "
                                 f"applies a command once")
            first_step.setdefault(key, (k, topic, log_time))
            cmd = commands.get(key)
            if cmd is None:
                raise ValueError(f"{where}: actuator state of {body} at step {k} names command {cid}, which the "
                                 f"recording does not hold")
            if rate is not None and cmd[1] > (k + 1) / rate * (1 + 1e-12):
                raise ValueError(f"{cmd[2]} at log time {cmd[3]} ns: command {cid} has t = {cmd[1]!r} s, after the end "
                                 f"of step {k} (t = {k / rate:g} s) where {where} says it was applied")
            count += 1
            after_end += k >= n_steps
            if keep:
                out.setdefault(k, []).append((body, cmd[0]))
    if hole is not None:  # (after the checks above: what they name is the more specific error)
        topic, a, b, log_time = hole
        raise ValueError(f"{topic} at log time {log_time} ns: the actuator states of steps {a} .. {b} are missing (the "
                         f"plant records one at every step): those steps would be re-simulated without their "
                         f"commands")
    return CommandRecording(out, count, last_step, first_state_step, after_end, damage)


def recorded_faults(path: str | Path, scenario) -> list:
    """The faults that began in recording ``path`` (the plant's ``fault`` events: those of
    the config and those injected by serve's ``fault`` verb), each at the time it began."""
    from astrodyn.recording.stream import open_stream
    from astrodyn.scenario.control import parse_fault, plant_bodies
    from astrodyn.scenario.fields import Ctx

    out = []
    key = messages.event_key(scenario.name)
    with open_stream(path) as s:
        for m in s.messages():
            if m.topic != key:
                continue
            event = _decode_recorded(m, "event")
            if event["process"] == PROCESS and event["kind"] == "fault":
                try:
                    detail = json.loads(event["detail"])
                except (ValueError, RecursionError) as exc:
                    raise ValueError(f"{m.topic} at log time {m.log_time} ns: fault event detail: expected JSON, "
                                     f"got {type(exc).__name__}: {exc}") from None
                out.append(parse_fault(Ctx(f"--commands {path}"), detail, "fault event",
                                       math.inf, plant_bodies(scenario), t=event["t"]))
    return out


def _decode_recorded(m, kind: str) -> dict:
    """A recorded message of ``kind`` decoded; MessageError naming its channel and log time."""
    try:
        return messages.decode(m.data, kind)
    except messages.MessageError as exc:
        raise messages.MessageError(f"{m.topic} at log time {m.log_time} ns: {exc}") from None


def run_plant(scenario, session, *, token: str | None = None, replay: dict | None = None,
              max_steps: int | None = None, first_event_seq: int = 0, wait_logger_s: float = 30.0,
              real_time_factor: float | None = None, endless: bool = False, replay_faults: list | None = None,
              log=print) -> dict:
    """Run the closed loop of ``scenario`` (module docstring); returns a summary dict.

    ``real_time_factor``: pace sim time at this many sim seconds per wall second (``serve``
    passes its rate); default: the scenario's for free mode, none (as fast as the
    controllers answer) for lockstep and re-simulation.  ``endless``: keep going past the
    scenario's duration until stopped (``serve``).  Supervisor commands on ``@command``
    (pause, resume, rate, stop) are obeyed, as by the propagators."""
    loop = PlantLoop(scenario, session, token=token, replay=replay, max_steps=max_steps, endless=endless,
                     real_time_factor=real_time_factor, replay_faults=replay_faults)
    return loop.run(first_event_seq=first_event_seq, wait_logger_s=wait_logger_s)


class PlantLoop:
    """One run of the plant process: the steps of the module docstring, one method each
    (:meth:`publish_step` 1-2, :meth:`exchange` 3, :meth:`apply_commands` 4-5)."""

    def __init__(self, scenario, session, *, token: str | None, replay: dict | None, max_steps: int | None,
                 endless: bool, real_time_factor: float | None, replay_faults: list | None):
        self.scenario = scenario
        self.session = session
        self.plant = plant = Plant(scenario)
        if replay_faults is not None:  # re-simulation: the faults as they happened (config and control verb alike)
            plant.set_faults(replay_faults)
        self.control = control = scenario.control
        self.name = scenario.name
        self.rate = scenario.rate
        self.dt = 1.0 / scenario.rate
        self.n_steps = (2**53 if endless else scenario.n_steps) if max_steps is None else min(scenario.n_steps, int(max_steps))
        self.replay = replay
        self.lockstep = control.mode == "lockstep" and replay is None
        self.expected = control.controllers if self.lockstep else ()
        self.signer = bus.process_signer(PROCESS)
        # ticks and events: with the control token, also the part its holders check (astrodyn.auth)
        self.tick_signer = self.signer if token is None else auth.WithPlantPart(self.signer, auth.PlantSigner(token))
        self.tick_repeats = 0  # lockstep: ticks put again while waiting for answers
        secret = auth.secret_from_environment()
        self.intake = Intake(self.name, plant.bodies, None if secret is None else auth.Verifier(secret), token)
        self.stopping: dict = {"why": None}
        catch_stop_signals(lambda why: self.stopping.update(why=why))
        catch_job_control()  # Ctrl-Z of a paced run: the pacer keeps its schedule after it
        self.pubs: dict[str, object] = {}
        # the step's messages go out together: per key for small scenes, one envelope on
        # @batch/plant above BATCH_THRESHOLD bodies (as the propagators do; docs/clients.md)
        self.outbox: list[tuple[str, bytes]] = []
        # lockstep: the applied commands and actuator states of a step, put after the next
        # step's tick (while the controller thinks, not before it can start)
        self.held: list[tuple[str, bytes]] = []
        self.batched = len(plant.bodies) > BATCH_THRESHOLD
        self.att_bodies = [(bname, b) for bname, b in plant.bodies.items() if b.has_attitude]
        self.orb_bodies = [(bname, b) for bname, b in plant.bodies.items() if b.has_orbit]
        self.flex_bodies = [(bname, b) for bname, b in plant.bodies.items() if isinstance(b, FlexiblePlantBody)]
        self.att_keys = [messages.attitude_key(self.name, bname) for bname, _ in self.att_bodies]
        self.orb_keys = [messages.orbit_key(self.name, bname) for bname, _ in self.orb_bodies]
        self.seqs: dict[str, int] = {}  # sensor key -> next seq
        self.keys: dict[tuple[str, str], str] = {}  # (body, kind) -> its key
        self.pending: dict[str, list[tuple[dict, bytes | None]]] = {b: [] for b in plant.bodies}
        self.pending_count: dict[tuple[str, str], int] = {}  # (sender, body) -> its commands in pending
        self.pending_unlisted = 0  # commands in pending from senders not in control.controllers
        # lockstep, per controller, for the current tick only (docs/control.md, "Lockstep"):
        # the commands that count toward its answer (arrived while the tick is current, t not
        # before the tick's, not a copy of the last one taken; rejected ones too) and the
        # number its answer announced.  Nothing carries over to the next tick.
        self.received: dict[str, int] = {}
        self.promised: dict[str, int] = {}
        self.tick_t = 0.0  # t of the current tick
        self.last_command_seq: dict[tuple[str, str], int] = {}  # (sender, body) -> seq of its last command taken
        self.last_command: dict[tuple[str, str], dict] = {}  # (sender, body) -> its last command taken (a retransmission is a copy)
        self.senders: set[str] = set()  # senders whose commands were taken (at most MAX_SENDERS)
        self.answered: dict[str, int] = {}  # last control step each controller answered
        self.controllers = frozenset(control.controllers)  # who may answer a tick
        self.tick_seq = -1  # seq of the last tick published (the current control step)
        self.late = self.refused = self.applied = self.published = 0
        self.round_trips: list[float] = []  # lockstep: wall s from a tick to the last answer (the first MAX_ROUND_TRIPS)
        self.refusals: list[str] = []
        self.t_reached = 0.0
        if real_time_factor is None:
            real_time_factor = scenario.real_time_factor if control.mode == "free" and replay is None else math.inf
        self.pacer = Pacer(real_time_factor)
        self.commands_from = CommandVerifier()
        self.replay_by_body: dict[int, dict[str, list[dict]]] = {}  # --commands: step -> body -> commands, in order
        for k_step, items in (replay or {}).items():
            for body_name, cmd in items:
                self.replay_by_body.setdefault(k_step, {}).setdefault(body_name, []).append(cmd)
        self.verbs = {"fault": self.inject_fault}
        self.eps = 1e-9 * self.dt  # "at t": within round-off of the step's time

    # ------------------------------------------------------------------ output

    def put(self, key: str, payload: bytes, signer=None) -> None:
        pub = self.pubs.get(key)
        if pub is None:
            pub = self.pubs[key] = bus.declare_state_publisher(self.session, key)
        bus.signed_put(pub, key, payload, signer or self.signer)

    def flush(self, batch) -> None:
        for box in (self.held, self.outbox):  # the step before's actuator states first
            if box and self.batched:
                batch.publish(box)
            elif box:
                for key, payload in box:
                    self.put(key, payload)
            box.clear()

    # ------------------------------------------------------------------ input

    def inject_fault(self, cmd: dict) -> None:
        """serve's ``fault`` verb (validated by serve): begins at the next step."""
        from astrodyn.scenario.control import parse_fault, plant_bodies
        from astrodyn.scenario.fields import Ctx

        self.plant.inject(parse_fault(Ctx("fault"), cmd["fault"], "fault", math.inf, plant_bodies(self.scenario),
                                      t=self.t_reached + self.dt))

    def refuse(self, bname: str, cmd: dict, why: str) -> None:
        self.refused += 1
        if len(self.refusals) < MAX_EXAMPLES:
            self.refusals.append(f"{bname} {command_id(cmd['sender'], cmd['seq'])}: {why}")

    def refusal(self, b, bname: str, cmd: dict, t: float, applied_in_step: int) -> str | None:
        """Why body ``b`` (``bname``) does not apply ``cmd`` in the step at ``t`` (s), having
        applied ``applied_in_step`` commands in it already; None if it does.  What the command
        asks for comes first: a command the body can never apply is refused for that, even when
        it is also late (in lockstep, in the past)."""
        if applied_in_step >= MAX_APPLIED_PER_STEP:
            return (f"more than {MAX_APPLIED_PER_STEP} commands for {bname} in one step (the most one actuator "
                    f"state records)")
        why = b.refusal(cmd)
        if why is not None:
            return why
        if self.lockstep and cmd["t"] < t - self.eps:
            return f"t = {cmd['t']:g} s is in the past (now {t:g} s)"
        return None

    def apply_command(self, b, bname: str, cmd: dict, raw: bytes | None, at: float) -> None:
        """Apply now (simulated time ``at``, s); re-publish the command as applied (the copy the logger records)."""
        try:
            b.apply(cmd, at)
        except CommandRefused as exc:
            self.refuse(bname, cmd, str(exc))
            return
        self.applied += 1
        self.applied_now.append((self.key(bname, "command"), cmd, raw))  # re-published by apply_commands

    def drain(self, block_s: float | None) -> bool:
        """Take what the intake holds (waiting up to ``block_s`` for the first); False if nothing came."""
        intake = self.intake
        try:
            item = intake.queue.get(timeout=block_s) if block_s else intake.queue.get_nowait()
        except queue.Empty:
            intake.fold_oversized()
            return False
        while True:
            intake.bytes_out += len(item[1])
            for kind, who, msg in (intake.judge_batch(*item) if "/@batch/" in item[0] else
                                   [j for j in (intake.judge(*item),) if j is not None]):
                if kind == "command":
                    sender = msg["sender"]
                    if self.lockstep and sender not in self.controllers:
                        self.refuse(who, msg, f"sender {sender!r} is not one of control.controllers "
                                              f"({', '.join(sorted(self.controllers)) or 'none'}): in lockstep only they command")
                        continue
                    if sender not in self.senders:
                        if len(self.senders) >= MAX_SENDERS:
                            self.refuse(who, msg, f"more than {MAX_SENDERS} senders have commanded the plant")
                            continue
                        self.senders.add(sender)
                    last = self.last_command_seq.get((sender, who), -1)
                    if self.lockstep and msg["t"] >= self.tick_t - self.eps and msg != self.last_command.get((sender, who)):
                        self.received[sender] = self.received.get(sender, 0) + 1  # counts toward its answer
                    if msg["seq"] <= last:  # its copy would be recorded as a duplicate, not as applied
                        self.refuse(who, msg, f"seq {msg['seq']} is not above {sender}'s last command to "
                                              f"{who} (seq {last}): a sender numbers its commands to a body upward, "
                                              f"across its restarts too (docs/control.md)")
                        continue
                    self.last_command_seq[sender, who] = msg["seq"]
                    self.last_command[sender, who] = msg
                    listed = sender in self.controllers
                    if self.pending_count.get((sender, who), 0) >= MAX_PENDING:
                        self.refuse(who, msg, f"more than {MAX_PENDING} commands of {sender} for {who} waiting for "
                                              f"their time")
                    elif not listed and self.pending_unlisted >= MAX_PENDING_UNLISTED:
                        self.refuse(who, msg, f"more than {MAX_PENDING_UNLISTED} commands of senders not in "
                                              f"control.controllers waiting for their time")
                    else:
                        self.pending[who].append((msg, None))  # applied: re-encoded (the same bytes for a canonical one)
                        self.pending_count[sender, who] = self.pending_count.get((sender, who), 0) + 1
                        self.pending_unlisted += not listed
                elif kind == "done":
                    problem = self.answer_problem(who, int(msg["seq"]))
                    if problem is not None:
                        intake.reject(*problem)
                        continue
                    if int(msg["seq"]) == self.tick_seq:  # the announcement of the current tick (lockstep waits for it)
                        self.promised[who] = int(msg["commands"])
                    self.answered[who] = max(self.answered.get(who, -1), int(msg["seq"]))
            if intake.rejected_from:  # rejected commands arrived: they count toward what their sender announced
                for sender in intake.rejected_from:
                    if self.lockstep and sender in self.controllers:
                        self.received[sender] = self.received.get(sender, 0) + 1
                intake.rejected_from.clear()
            try:
                item = intake.queue.get_nowait()
            except queue.Empty:
                intake.fold_oversized()
                return True

    def answer_problem(self, who: str, seq: int) -> tuple[str, str] | None:
        """``(reason, detail)`` if the authenticated answer of controller ``who`` to control
        step ``seq`` is not taken (module docstring, "Trust"), else None."""
        if who not in self.controllers:
            return "unknown-controller", (f"answer of {who!r} to control step {seq}: not one of control.controllers "
                                          f"({', '.join(sorted(self.controllers)) or 'none'})")
        if seq > self.tick_seq:
            return "unsent-tick", (f"answer of {who!r} to control step {seq}: the plant's last tick is control step "
                                   f"{self.tick_seq}")
        last = self.answered.get(who, -1)
        if seq <= last:
            return "repeated-answer", f"answer of {who!r} to control step {seq}: it already answered control step {last}"
        return None

    # ------------------------------------------------------------------ one step

    def wait_for_time(self, t: float, supervisor, heartbeat) -> None:
        """Obey the supervisor (pause, rate, stop, fault) and pace to ``t``; free mode takes
        commands while it waits."""
        pace_to(t, self.pacer, supervisor, self.stopping, heartbeat, self.commands_from, self.t_reached,
                self.verbs, while_waiting=lambda: self.drain(None))

    def publish_step(self, k: int, t: float, events) -> list[tuple[str, bytes]]:
        """Faults that begin now, then the step's states and sensor samples into the outbox;
        returns them as ``(body/kind, payload)`` for the tick."""
        plant = self.plant
        for f in plant.faults_at(t):
            events.emit("fault", t, Plant.fault_detail(f))
        plant.begin_step()
        samples: list[tuple[str, bytes]] = []
        if self.orb_bodies:  # states: the compiled encoders (canonical layout, validated there)
            payloads = messages.encode_orbit_batch(
                t, k, messages.ACTUATED_MODEL, np.array([b.r for _, b in self.orb_bodies]),
                np.array([b.v for _, b in self.orb_bodies]), self.scenario.central_body.mu, self.scenario.frame)
            self.outbox.extend(zip(self.orb_keys, payloads))
            samples.extend((f"{bname}/orbit", p) for (bname, _), p in zip(self.orb_bodies, payloads))
        if self.att_bodies:
            payloads = messages.encode_attitude_batch(t, k, messages.ACTUATED_MODEL, np.array([b.q for _, b in self.att_bodies]),
                                                      np.array([b.w for _, b in self.att_bodies]))
            self.outbox.extend(zip(self.att_keys, payloads))
            samples.extend((f"{bname}/attitude", p) for (bname, _), p in zip(self.att_bodies, payloads))
        for bname, b in self.flex_bodies:  # a flexible body's appendages, at its attitude's seq
            payload = messages.encode(b.appendage_state(t, k), "appendages")
            self.outbox.append((self.key(bname, "appendages"), payload))
            samples.append((f"{bname}/appendages", payload))
        self.published += len(self.orb_bodies) + len(self.att_bodies) + len(self.flex_bodies)
        for kind, bnames, fields in plant.sensor_samples(k, t):  # every body's samples of a kind at once
            keys = [self.key(bname, kind) for bname in bnames]
            seqs = [self.seqs.get(key, 0) for key in keys]
            payloads = encode_stamped(t, seqs, fields)  # NaN refused; fields are the plant's
            self.outbox.extend(zip(keys, payloads))
            samples.extend((f"{bname}/{kind}", p) for bname, p in zip(bnames, payloads))
            for key, seq in zip(keys, seqs):
                self.seqs[key] = seq + 1
        return samples

    def key(self, bname: str, kind: str) -> str:
        key = self.keys.get((bname, kind))
        if key is None:
            key = self.keys[bname, kind] = messages.body_key(self.name, bname, kind)
        return key

    def exchange(self, k: int, t: float, samples, supervisor, heartbeat, batch) -> None:
        """A control step: publish the tick, then the outbox; in lockstep, wait for every
        controller's answer and the commands it announced (ControllerTimeout after
        ``control.timeout``, on the plant's listening clock: a pause of the whole run, which
        stops the controllers too, is not counted against them)."""
        j = k // self.control.every
        self.drain(None)  # what came for the last tick counts toward it, not toward this one
        self.tick_seq, self.tick_t = j, t  # before the put: an answer can only come after it
        self.received.clear()
        self.promised.clear()
        key, payload = messages.tick_key(self.name), tick_payload(t, j, k, samples)
        self.put(key, payload, self.tick_signer)
        sent_at = put_at = time.monotonic()
        self.flush(batch)  # the step's states and samples (in the tick already), while the controller works
        waited = bus.ListeningClock()
        while True:
            self.drain(None)
            waiting = [c for c in self.expected
                       if self.answered.get(c, -1) < j or self.received.get(c, 0) < self.promised.get(c, 0)]
            if not waiting or self.stopping["why"]:
                if self.expected and len(self.round_trips) < MAX_ROUND_TRIPS:
                    self.round_trips.append(time.monotonic() - sent_at)
                return
            now = time.monotonic()
            left = self.control.timeout - waited.tick(now)
            if left <= 0:
                raise ControllerTimeout(self.timeout_message(waiting, j, t))
            if now - put_at >= TICK_REPEAT_S:  # the same tick again (fresh authenticators): for a late subscriber
                self.put(key, payload, self.tick_signer)
                self.tick_repeats += 1
                put_at = now
            self.drain(min(left, put_at + TICK_REPEAT_S - now))
            heartbeat.beat(t=t, step=k, waiting=waiting)
            obey_commands(supervisor, self.pacer, t, self.stopping, heartbeat, self.commands_from, self.verbs)

    def timeout_message(self, waiting: list[str], j: int, t: float) -> str:
        """Why the plant gave up on control step ``j``: who did not answer, or whose announced commands did not all arrive."""
        def why(c: str) -> str:
            if self.answered.get(c, -1) < j:
                return f"controller {c!r} did not answer control step {j} (t = {t:g} s)"
            return (f"controller {c!r} answered control step {j} (t = {t:g} s) announcing {self.promised.get(c, 0)} "
                    f"commands, of which {self.received.get(c, 0)} arrived (counted: commands for t >= {t:g} s, "
                    f"rejected ones included, a repeat of the last one taken not)")
        return (f"{why(waiting[0])} within {self.control.timeout:g} s"
                + (f" (also {'; '.join(why(c) for c in waiting[1:])})" if waiting[1:] else ""))

    def commands_due(self, k: int, t: float, bname: str) -> list[tuple[dict, bytes | None]]:
        """The commands ``bname`` applies in step ``k``: due in [t, t + dt) in arrival order
        (re-simulation: those recorded as applied in this step)."""
        if self.replay is not None:
            return [(c, None) for c in self.replay_by_body.get(k, {}).get(bname, ())]
        due = t + self.eps if k == self.n_steps - 1 else t + self.dt - self.eps
        pending = self.pending[bname]
        mine = [e for e in pending if e[0]["t"] <= due]
        if mine:
            self.pending[bname] = [e for e in pending if e[0]["t"] > due]
            for cmd, _ in mine:
                sender = cmd["sender"]
                left = self.pending_count[sender, bname] - 1
                if left:
                    self.pending_count[sender, bname] = left
                else:
                    del self.pending_count[sender, bname]
                self.pending_unlisted -= sender not in self.controllers
        return mine

    def apply_commands(self, k: int, t: float) -> None:
        """Apply each body's due commands (those inside the step at their own time), advance
        it to the next step, and put its actuator state in the outbox.  The bodies advanced by
        a whole step go together (:meth:`astrodyn.plant.Plant.advance`)."""
        last = k == self.n_steps - 1
        eps, dt = self.eps, self.dt
        whole = []
        self.applied_now: list[tuple[str, dict, bytes | None]] = []
        for bname, b in self.plant.bodies.items():
            inside = []
            before = self.applied
            for cmd, raw in self.commands_due(k, t, bname):
                if cmd["t"] > t + eps:
                    inside.append((cmd, raw))
                    continue
                why = self.refusal(b, bname, cmd, t, self.applied - before)
                if why is not None:
                    self.refuse(bname, cmd, why)
                    continue
                if self.replay is None and cmd["t"] < t - eps:
                    self.late += 1  # (free mode: in lockstep it was refused)
                self.apply_command(b, bname, cmd, raw, t)
            b.finish_commands()
            done_s = 0.0  # commands inside the step: advance to their t, apply, go on
            for cmd, raw in sorted(inside, key=lambda e: e[0]["t"]):
                why = self.refusal(b, bname, cmd, t, self.applied - before)
                if why is not None:
                    self.refuse(bname, cmd, why)
                    continue
                if cmd["t"] - t > done_s:
                    b.advance(cmd["t"] - t - done_s)
                    done_s = cmd["t"] - t
                self.apply_command(b, bname, cmd, raw, cmd["t"])
            if not last and done_s == 0.0:
                whole.append(b)
            elif not last and dt > done_s:
                b.advance(dt - done_s)
        self.plant.advance(whole, dt)
        # the applied commands, decoded and validated on arrival: encoded again (canonical) without a second validation
        payloads = encode_commands([cmd for _, cmd, raw in self.applied_now if raw is None])[::-1]
        self.outbox.extend((key, raw if raw is not None else payloads.pop()) for key, _, raw in self.applied_now)
        self.outbox.extend(self.actuator_states(k, t))

    def actuator_states(self, k: int, t: float) -> list[tuple[str, bytes]]:
        """``(key, payload)`` of every actuated body's actuator state of step ``k``: the
        bodies with the same float fields encoded together (:func:`encode_stamped`)."""
        groups: dict[int, list] = {}  # wheels -> [(body, state)]
        for bname, b in self.plant.bodies.items():
            if b.limits is not None:
                groups.setdefault(0 if b.wheels is None else b.wheels.n, []).append((bname, b.actuator_state()))
        out = []
        for wheels, items in groups.items():
            lead = _ACTUATOR_ARRAYS if wheels else _ACTUATOR_ARRAYS[:1]  # always there, first, in this order
            fields = {f: np.array([state[f] for _, state in items], dtype=np.float64) for f in lead}
            rest = [{f: state[f] for f in state if f not in lead} for _, state in items]
            out.extend(zip([self.key(bname, "actuators") for bname, _ in items], encode_stamped(t, k, fields, rest)))
        return out

    # ------------------------------------------------------------------ the run

    def run(self, first_event_seq: int = 0, wait_logger_s: float = 30.0) -> dict:
        name, session = self.name, self.session
        wall0 = time.monotonic()
        with bus.declare_alive(session, name, PROCESS), \
                bus.Heartbeat(session, name, PROCESS, signer=self.signer) as heartbeat, \
                bus.EventPublisher(session, name, PROCESS, signer=self.tick_signer) as events, \
                session.declare_subscriber(f"{messages.PREFIX}/{name}/*/command", self.intake.callback), \
                session.declare_subscriber(f"{messages.PREFIX}/{name}/@done/*", self.intake.callback), \
                session.declare_subscriber(f"{messages.PREFIX}/{name}/@batch/*", self.intake.callback), \
                bus.BatchPublisher(session, name, PROCESS, signer=self.signer) as batch, \
                session.declare_subscriber(command_key(name), zenoh.handlers.FifoChannel(256)) as supervisor:
            bus.wait_for_logger(session, name, timeout_s=wait_logger_s)
            events.next_seq = int(first_event_seq)
            events.emit("start", 0.0, json.dumps({"bodies": len(self.plant.bodies), "mode": self.control.mode,
                                                  "controllers": list(self.expected), "steps": self.n_steps,
                                                  "replay": self.replay is not None}))
            heartbeat.beat(force=True, t=0.0, step=0, preparing=True)
            failure = None
            k = 0
            # the scene, the plant and the modules stay for the whole run: out of the cyclic
            # collector's scans (a full scan of a 1000-body plant cost ~10 ms every few steps)
            gc.collect()
            gc.freeze()
            try:
                while k < self.n_steps:
                    t = k / self.rate  # the time of step k of every process (docs/architecture.md), not k * dt
                    self.wait_for_time(t, supervisor, heartbeat)
                    if self.stopping["why"]:
                        break
                    samples = self.publish_step(k, t, events)
                    if k % self.control.every == 0:
                        self.exchange(k, t, samples, supervisor, heartbeat, batch)
                    else:
                        self.flush(batch)
                        self.drain(None)
                    if self.stopping["why"]:
                        break
                    self.apply_commands(k, t)
                    if self.lockstep:
                        self.held, self.outbox = self.outbox, self.held  # put after the next tick
                    else:
                        self.flush(batch)
                    self.t_reached = t
                    k += 1
                    heartbeat.beat(t=t, step=k, **self.pacer.state())
            except ControllerTimeout as exc:
                failure = str(exc)
                events.emit("error", self.t_reached, failure)
            self.flush(batch)  # what the last step held back
            wall = time.monotonic() - wall0
            extra = {"last_step": k - 1, "t_reached": self.t_reached, "reason": failure or self.stopping["why"] or "end of scenario",
                     "applied": self.applied, "refused": self.refused, "late": self.late,
                     # taken, for a time the run never reached: neither applied nor refused
                     "pending": sum(len(waiting) for waiting in self.pending.values()),
                     "rejected": {**self.intake.rejected,  # forged supervisor commands (@command) too
                                  **{f"supervisor {r}": n for r, n in self.commands_from.rejected.items()}},
                     # authenticated samples rejected for what they say (by author in the summary)
                     "controller_errors": sum(sum(c.values()) for c in self.intake.controller_errors.values()),
                     "dropped": self.intake.dropped}
            events.end(self.t_reached, self.published, **extra)
            heartbeat.beat(force=True, t=self.t_reached, step=k, done=True)
            wait_until_logged(session, name, PROCESS)
        return self.summary(k, wall, extra, failure)

    def summary(self, k: int, wall: float, extra: dict, failure: str | None) -> dict:
        summary = {"process": PROCESS, "bodies": len(self.plant.bodies), "steps": k, "messages": self.published,
                   "t": self.t_reached, "wall_s": wall, **extra, "tick_repeats": self.tick_repeats,
                   "refusals": self.refusals, "rejected_examples": self.intake.examples,
                   "controller_errors_by_author": self.intake.controller_errors,
                   "controller_error_examples": self.intake.controller_error_examples}
        if self.round_trips:
            rt = sorted(self.round_trips)
            summary["round_trip_us"] = {"n": len(rt), "p50": 1e6 * rt[len(rt) // 2],
                                        "p99": 1e6 * rt[int(0.99 * (len(rt) - 1))], "max": 1e6 * rt[-1]}
        if failure:
            summary["error"] = failure
        return summary


#: Fewer messages than this are encoded one by one (:func:`encode_stamped`, :func:`encode_commands`).
FEW = 4
#: The leading fields of an ActuatorState that are float arrays of one width per body (in order).
_ACTUATOR_ARRAYS = ("torque", "wheel_torque", "wheel_speed")


def encode_stamped(t: float, seqs, fields: dict[str, np.ndarray], rest: list[dict] | None = None) -> list[bytes]:
    """Payloads ``{"t": t, "seq": seqs[i], <field>: row i of fields[field], ..., **rest[i]}``
    of ``n`` messages, byte for byte what :func:`astrodyn.messages.encode` gives each (floats
    as ``repr``, compact): the float arrays of all of them written in one compiled pass
    (:func:`astrodyn.messages.shortest.format_records`), ``rest`` (other fields, after them)
    by the encoder.  ``seqs``: one int or ``n``; ``fields`` (n, width) float arrays.
    MessageError for a NaN or an infinity, as :func:`astrodyn.messages.encode`."""
    from astrodyn.messages import shortest

    names = list(fields)
    n = len(fields[names[0]])
    if n < FEW:  # the encoder, message by message, costs less than the set-up of one pass
        seq_list = [int(seqs)] * n if np.ndim(seqs) == 0 else [int(x) for x in seqs]
        rows = {f: np.asarray(fields[f], dtype=np.float64).tolist() for f in names}  # plain floats: msgspec's path
        return [messages.encode({"t": t, "seq": seq_list[i], **{f: rows[f][i] for f in names}, **(rest[i] if rest else {})})
                for i in range(n)]
    values = np.concatenate([np.asarray(fields[f], dtype=np.float64) for f in names], axis=1)
    seq_arr = np.broadcast_to(np.asarray(seqs, dtype=np.int64), (n,))
    if not np.all(np.isfinite(values)):  # the encoder names the field
        for i in range(n):
            messages.encode({"t": t, "seq": int(seq_arr[i]), **{f: fields[f][i] for f in names}})
    data, offsets = shortest.format_records(_template(True, None, tuple((f, fields[f].shape[1]) for f in names)),
                                            seq_arr, values, (float(t),))
    out = [data[offsets[i]:offsets[i + 1]] for i in range(n)]
    if rest is not None:
        out = [p if not r else p[:-1] + _tail(r) for p, r in zip(out, rest)]
    return out


_PLAIN_STRING = re.compile(r"[A-Za-z0-9_.#-]*")


def _tail(fields: dict) -> bytes:
    """``,"<field>":value,...}``: what :func:`astrodyn.messages.encode` writes for ``fields``
    after a message's first ones.  Alone, the usual ``applied`` list of ``sender#seq`` (names
    need no escape in JSON) is written directly."""
    applied = fields.get("applied")
    if len(fields) == 1 and applied is not None and all(_PLAIN_STRING.fullmatch(a) for a in applied):
        return b',"applied":["' + '","'.join(applied).encode() + b'"]}'
    return b"," + messages.encode(fields)[1:]


#: Command fields that are float arrays, in the order of the message type.
_COMMAND_ARRAYS = ("torque", "wheel_torque", "dv", "thrust")


def encode_commands(commands: list[dict]) -> list[bytes]:
    """:func:`astrodyn.messages.encode` of each of ``commands`` (decoded, valid), byte for
    byte; those of one sender and one layout written together, in one compiled pass."""
    if len(commands) < FEW:
        return [messages.encode(cmd) for cmd in commands]
    groups: dict[tuple, list[int]] = {}
    out: list[bytes | None] = [None] * len(commands)
    for i, cmd in enumerate(commands):
        arrays = tuple((f, len(cmd[f])) for f in _COMMAND_ARRAYS if f in cmd)
        if len(cmd) == 3 + len(arrays):  # t, seq, sender and float arrays only (no frame)
            groups.setdefault((cmd["sender"], arrays), []).append(i)
        else:
            out[i] = messages.encode(cmd)
    from astrodyn.messages import shortest

    for (sender, arrays), rows in groups.items():
        values = np.array([[commands[i]["t"], *(x for f, _ in arrays for x in commands[i][f])] for i in rows], dtype=np.float64)
        data, offsets = shortest.format_records(_template(False, sender, arrays), [commands[i]["seq"] for i in rows], values)
        for j, i in enumerate(rows):
            out[i] = data[offsets[j]:offsets[j + 1]]
    return out


@functools.lru_cache(maxsize=256)
def _template(t_shared: bool, sender: str | None, layout: tuple[tuple[str, int], ...]):
    """``{"t":T,"seq":S[,"sender":"<sender>"],"<name>":[c, ...], ...}`` for ``layout`` ((name,
    width), ...): ``T`` the shared float 0 or the first column, then the arrays' columns."""
    from astrodyn.messages.shortest import SEQ, RecordTemplate, shared

    pieces, slots, column = [b'{"t":', b',"seq":', b""], [shared(0) if t_shared else 0, SEQ], 0 if t_shared else 1
    if sender is not None:
        pieces[-1] += b',"sender":' + json.dumps(sender, ensure_ascii=False).encode()
    for name, width in layout:
        pieces[-1] += b"," + json.dumps(name, ensure_ascii=False).encode() + b":["
        if width == 0:
            pieces[-1] += b"]"
            continue
        for j in range(width):
            slots.append(column)
            pieces.append(b"," if j < width - 1 else b"]")
            column += 1
    pieces[-1] += b"}"
    return RecordTemplate(pieces, slots)


def tick_payload(t: float, seq: int, step: int, samples: list[tuple[str, bytes]]) -> bytes:
    """The :class:`astrodyn.messages.Tick` of a control step, with the step's messages
    spliced in as published (no re-encoding: the bytes a controller reads in the tick are
    those on the keys and in the recording)."""
    head = messages.encode({"t": t, "seq": seq, "step": step, "samples": {}}, "tick")[:-3]  # ...,"samples":
    body = b",".join(json.dumps(key).encode() + b":" + payload for key, payload in samples)
    return head + b"{" + body + b"}}"


def main(argv: list[str] | None = None) -> int:
    """Exit status: 0 done, 1 a controller timed out or a bus error, 2 bad arguments or config."""
    from astrodyn.scenario import ScenarioError, load

    ap = argparse.ArgumentParser(prog="python -m astrodyn.service.plant",
                                 description="astrodyn plant: the closed loop's bodies, stepped with controllers' commands")
    ap.add_argument("config", help="scenario TOML file with a [control] table")
    ap.add_argument("--control-token-file", default=None, metavar="FILE",
                    help="the run's control token (0600 file): outside controllers that present it are obeyed")
    ap.add_argument("--commands", default=None, metavar="REC.mcap",
                    help="re-simulate: apply the commands recorded in REC where they were applied (no controllers)")
    ap.add_argument("--max-steps", type=int, default=None, help="stop after this many output steps")
    ap.add_argument("--real-time-factor", type=float, default=None,
                    help="sim seconds per wall second (default: the scenario's in free mode, inf in lockstep)")
    ap.add_argument("--endless", action="store_true", help="keep going past the scenario's duration until stopped (serve)")
    ap.add_argument("--first-event-seq", type=int, default=0, help="seq of this process's first event")
    ap.add_argument("--wait-logger", type=float, default=30.0, help="seconds to wait for the logger")
    bus.add_bus_arguments(ap)
    args = ap.parse_args(argv)
    share_fate_with_supervisor()
    try:
        scenario = load(args.config)
    except ScenarioError as exc:
        print(f"plant: {exc}", file=sys.stderr)
        return 2
    if scenario.control is None:
        print(f"plant: {args.config}: expected a [control] table (a closed-loop scene; docs/control.md)", file=sys.stderr)
        return 2
    token = None
    if args.control_token_file:
        try:
            token = auth.read_token_file(args.control_token_file)
        except auth.AuthError as exc:
            print(f"plant: --control-token-file: {exc}", file=sys.stderr)
            return 2
    replay = faults = None
    if args.commands:
        try:
            replay = recorded_commands(args.commands, scenario)
            faults = recorded_faults(args.commands, scenario)
        except (OSError, ValueError, RecordingError) as exc:
            print(f"plant: --commands: {exc}", file=sys.stderr)
            return 2
    try:
        with bus.session_from_args(args) as session:
            summary = run_plant(scenario, session, token=token, replay=replay, max_steps=args.max_steps,
                                first_event_seq=args.first_event_seq, wait_logger_s=args.wait_logger,
                                real_time_factor=args.real_time_factor, endless=args.endless, replay_faults=faults)
    except bus.BusError as exc:
        print(f"plant: {exc}", file=sys.stderr)
        return 1
    print(json.dumps(summary, separators=(",", ":")), flush=True)
    if "error" in summary:
        print(f"plant: {summary['error']}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
