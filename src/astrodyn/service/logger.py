"""The logger process: everything published under ``astrodyn/<scenario>/**`` into one MCAP.

What it does with each sample (keys in :mod:`astrodyn.bus`):

* ``<body>/orbit|attitude|crosscheck``, ``@event``, ``@status``: decoded and validated with
  :func:`astrodyn.messages.decode` (orbit and attitude payloads in the batch encoders'
  canonical layout by the equivalent, faster :data:`astrodyn.messages.FAST_CHECKS`); valid messages are written as received (no re-encoding)
  by :class:`~astrodyn.recording.writer.McapRecorder`, which accounts ``seq`` per channel
  (gaps, late arrivals, duplicates -- duplicates are not written).  Event seqs are
  accounted per (channel, process), since every process numbers its own events.
* ``@batch/<process>``: each entry is handled as if it had arrived on its own key.  The
  common entries (canonical orbit / attitude states with the next seq of their channel)
  are checked and written by one compiled pass over the envelope
  (:mod:`astrodyn.recording.ingest`, :meth:`McapRecorder.write_batch`: about 1.7 us per
  message with compression, against 7.7 us per message in Python); every other entry goes
  through the per-message path above, in arrival order, so the file is the same.
* ``@heartbeat/<process>``: not recorded; a process whose heartbeat stops while its
  liveliness token stays is reported as ``stalled`` (an ``error`` event in the file).
* anything else, and any payload that fails validation: counted as malformed with the
  reason (the first 20 kept as examples), never written, never fatal.

A process that loses its liveliness token before its end-of-run event is reported as
``died``; the logger writes an ``error`` event (process "logger") saying so and keeps
recording the others.

**How the runner knows the logger has every message.**  Each publishing process ends with
an ``@event`` of kind ``stop`` whose detail is JSON ``{"messages": M}``: the number of state
messages it published (:meth:`astrodyn.bus.EventPublisher.end`).  Started with
``expect=("orbit", "attitude")``, the logger finishes on its own once every expected
process has ended (or died) and it holds at least the sum of the announced counts with no
open gap, or, failing that, once the bus has been quiet for ``drain_idle_s`` (bounded by
``drain_timeout_s``).  The runner can also watch progress with a query on
``astrodyn/<scenario>/@status`` (the logger's counts as JSON; add ``?channels=1`` for
per-channel detail) and stop the logger with the ``stop`` control verb; the reply to
``stop`` is the final summary, sent after the file is finished.

SIGTERM / SIGINT / ``stop``: the logger drains what is already queued, finishes the file
(summary, indexes, footer) and prints its one-line JSON summary on stdout.
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import json
import os
import sys
import time
from collections.abc import Iterable
from typing import Any

import numpy as np
import zenoh

from astrodyn import auth, bus, messages
from astrodyn.jit import service_threads, set_threads
from astrodyn.recording import ingest
from astrodyn.recording.writer import (
    DUPLICATE,
    INGEST_GRAMMAR,
    BatchLayout,
    McapRecorder,
    RecordingError,
    being_written,
    part_path,
    partial_path,
)
from astrodyn.service.children import DISK_FULL_EXIT, OUT_IN_THE_WAY_EXIT, share_fate_with_supervisor
from astrodyn.signals import STOP_SIGNAL_NAMES, catch_stop_signals

__all__ = ["Logger", "main"]

_STATE_KINDS = frozenset(messages.STATE_KINDS)
#: per-body kinds the attitude process publishes: attitude, and the flexible / rolling bodies' own
_ATTITUDE_PROCESS_KINDS = frozenset(messages.ATTITUDE_PROCESS_KINDS)
_SCENE_KINDS = frozenset(messages.STATE_KINDS + messages.CONTROL_KINDS + messages.SENSOR_KINDS)
#: keys whose newest sample @latest serves (the live view): states and the closed loop's
_LATEST_SUFFIXES = tuple(f"/{k}" for k in ("orbit", "attitude", *messages.CONTROL_KINDS, *messages.SENSOR_KINDS))
_MAX_EXAMPLES = 20
_MAX_KEY_CACHE = 100_000
_MAX_LAYOUTS = 64  #: envelope layouts remembered in all (memory: each holds its envelope's keys)
#: Envelope layouts remembered per batch key, the most recent first: one publisher may put
#: several kinds of envelope on one key in turn (the plant's states and sensor samples, then
#: its actuator states; a user's own publisher), and with one remembered layout each envelope
#: took the slow path (Python decode and channel resolution: 2.5x the logger's CPU in
#: ``bench service``'s flood, whose orbit and attitude envelopes alternate on one key).
_LAYOUTS_PER_KEY = 4
_FAST_KIND = {"orbit": ingest.KIND_ORBIT, "attitude": ingest.KIND_ATTITUDE}


def publisher_of(rest: str) -> str | None:
    """The process entitled to publish on ``astrodyn/<scenario>/<rest>``: ``orbit`` for
    ``<body>/orbit`` and ``<body>/crosscheck``, ``attitude`` for ``<body>/attitude``, the
    named process for ``@batch/<p>`` and ``@heartbeat/<p>``; None for keys any of the
    run's processes may use (``@event``: there the event's own ``process`` field must
    match its signer)."""
    head, _, tail = rest.rpartition("/")
    if head in ("@batch", "@heartbeat"):
        return tail
    if tail in ("orbit", "crosscheck") and head and not head.startswith("@"):
        return "orbit"
    if tail in _ATTITUDE_PROCESS_KINDS and head and not head.startswith("@"):
        return "attitude"
    return None


def scene_state_keys(scenario) -> set[str]:
    """Every per-body key a run of ``scenario`` (an :class:`astrodyn.scenario.Scenario`) may
    publish: orbit and cross-check keys of the bodies with an orbit model, attitude keys
    of the bodies with an attitude model, and for the closed loop's bodies their
    ``command``, ``actuators`` and sensor keys (:func:`scene_publishers`)."""
    from astrodyn.scenario import plan as make_plan

    keys = set(scene_publishers(scenario))
    for bp in make_plan(scenario).bodies:
        if bp.orbit_model:
            keys.add(messages.orbit_key(scenario.name, bp.name))
            keys.add(messages.crosscheck_key(scenario.name, bp.name))
        if bp.attitude_model:
            keys.add(messages.attitude_key(scenario.name, bp.name))
        for kind in bp.own_kinds if bp.attitude_model != messages.ACTUATED_MODEL else ():  # the plant's: above
            keys.add(messages.body_key(scenario.name, bp.name, kind))
    return keys


def scene_publishers(scenario) -> dict[str, str]:
    """The keys of the closed loop's bodies and the process entitled to each: the plant
    (states, actuator states, sensor samples, and the copies of applied commands it
    re-publishes on ``<body>/command``; docs/control.md).  Empty for an open-loop scene."""
    out: dict[str, str] = {}
    for b in scenario.bodies:
        if not b.in_plant:
            continue
        kinds = ["actuators", "command"] if b.actuators is not None else []
        if b.orbit is not None:
            kinds.append("orbit")
        if b.attitude is not None and b.attitude.model != "none":
            kinds.append("attitude")
        if b.attitude is not None and b.attitude.model in messages.MODEL_STATE_KINDS:  # a flexible body's appendages
            kinds.append(messages.MODEL_STATE_KINDS[b.attitude.model])
        kinds += [s.kind for s in (b.sensors.present() if b.sensors is not None else ())]
        for kind in kinds:
            out[messages.body_key(scenario.name, b.name, kind)] = "plant"
    return out


def _claimed_process(attachment: bytes | None) -> str:
    """The process name an unverified authenticator claims (for counting only), else
    "unsigned" / "malformed"."""
    if not attachment:
        return "unsigned"
    if attachment[:4] == auth.MAGIC and len(attachment) > 5:
        name = attachment[5:5 + attachment[4]]
        return "claims " + name.decode("utf-8", "replace")[:64]
    return "malformed"


#: How an end event's ``reason`` begins when its process went to the end of the scene (or
#: as far as its model goes): any other reason (a signal name, "stop requested") is a
#: process stopped early (``Logger.stopped_early``).
FULL_RUN_END_REASONS = ("end of scenario", "model ended", "every step already recorded")

#: Seconds between two refreshes of the logger's :meth:`Logger.reach_report` (sent with its
#: heartbeat).
REACH_REPORT_S = 0.5

class Logger:
    """Subscribe to one scenario and record it with ``recorder`` (see the module docstring).

    Parameters
    ----------
    session : an open Zenoh session (the caller owns and closes it).
    scenario : scenario name.
    recorder : an open :class:`McapRecorder`; :meth:`run` closes it.
    expect : processes whose end-of-run events end the recording.
    queue_capacity : bound of the subscriber's FIFO; when full, Zenoh blocks the publishers
        (they use ``CongestionControl.BLOCK``), so memory stays bounded and nothing is lost.
    stall_timeout_s : a heartbeat older than this marks a live process as stalled.
    verifier : the run's :class:`astrodyn.auth.Verifier`; when given, every sample must carry
        a valid authenticator of the run (docs/security.md) from the process entitled to its
        key (:func:`publisher_of`), anything else is rejected, counted per reason and never
        written.
    scene_keys : the per-body keys of the scene (:func:`scene_state_keys`); when given, a
        message of a per-body kind on any other key is rejected (no channel is created for it).
    publishers : key -> the process entitled to it where :func:`publisher_of`'s rule does not
        say (the closed loop's bodies: :func:`scene_publishers`).  With a verifier, samples on
        ``<body>/command`` that the plant did not sign are controllers' inputs to the plant:
        not recorded, not counted as rejected (the plant judges them; its copy is recorded).
    """

    def __init__(
        self,
        session: zenoh.Session,
        scenario: str,
        recorder: McapRecorder,
        *,
        expect: Iterable[str] = (),
        queue_capacity: int = 256,
        drain_idle_s: float = 0.3,
        drain_timeout_s: float = 10.0,
        stall_timeout_s: float = 5.0,
        name: str = "logger",
        control: bool = True,
        verifier: auth.Verifier | None = None,
        scene_keys: Iterable[str] | None = None,
        signer: auth.Signer | None = None,
        publishers: dict[str, str] | None = None,
        first_event_seq: int = 0,
    ):
        self.session = session
        self.scenario = messages.check_name(scenario, "scenario")
        self.recorder = recorder
        self.expect = tuple(messages.check_name(p, "expect process") for p in expect)
        self.queue_capacity = int(queue_capacity)
        self.drain_idle_s = float(drain_idle_s)
        self.drain_timeout_s = float(drain_timeout_s)
        self.stall_timeout_s = float(stall_timeout_s)
        self.name = messages.check_name(name, "name")
        self.control = bool(control)  # False under a supervisor (serve): it ends the run, not us
        self._lost: dict[str, float] = {}  # liveliness lost, death not yet confirmed
        self.prefix = f"{messages.PREFIX}/{self.scenario}/"
        self.event_key = messages.event_key(self.scenario)
        # counters
        self.received = 0  # samples off the bus
        self.states = 0  # valid, non-duplicate state messages written
        self.malformed = 0
        self.malformed_examples: list[str] = []
        self.heartbeats: dict[str, float] = {}  # process -> self.clock.s at its last heartbeat
        # the logger's listening clock (bus.LISTENING_GAP_S): time the logger was stopped
        # itself (SIGSTOP, a paused container) is not silence of the processes it watches
        self.clock = bus.ListeningClock()
        self._reach: dict[str, dict] = {}  # reach_report(), refreshed every REACH_REPORT_S
        self._next_reach_report = 0.0
        #: newest authenticated sample of each state key (per-body keys and @batch envelopes),
        #: served on @latest to views that must not take the full-rate streams
        self.latest: dict[str, bytes] = {}
        self.ended: dict[str, int | None] = {}
        #: processes whose end event says they stopped before the end of the scene (a signal,
        #: a stop): reason, sim t and last step; a recording can be complete (every state they
        #: published is in it) and still end early (status "stopped_early")
        self.stopped_early: dict[str, dict] = {}
        #: the last output step each ended process announced (its end event's ``last_step``)
        self.last_step: dict[str, int] = {}
        self._channel_process: dict[str, str | None] = {}  # state channel -> its publisher (cache)
        self.died: dict[str, str] = {}
        self.stalled: set[str] = set()
        self.max_t = 0.0
        #: the seq of the logger's next own event (a restarted logger's continues its
        #: predecessor's: ``--resume-seqs``), and its publisher on the event key (in :meth:`run`)
        self._own_event_seq = int(first_event_seq)
        self._own_event_publisher: Any = None
        self._key_kind: dict[str, str | None] = {}
        self._layouts: dict[str, list[BatchLayout]] = {}  # batch key -> its recent envelopes' layouts
        self._spans = tuple(np.empty(4096, dtype=np.int64) for _ in range(4))  # frame_batch output
        self._stop_reason: str | None = None
        self._stop_requested_at: float | None = None
        self._stop_requests: list[bus.ControlRequest] = []
        self._all_ended_at: float | None = None
        self._last_sample_at = time.monotonic()
        self._drained_at = 0.0  # last time a receive pass found every queue empty
        self._started = time.monotonic()
        self.reason = ""
        self.rename_at_end = True  # False: the file keeps its partial name (the supervisor renames it)
        self.verifier = verifier
        self.signer = signer
        self.scene_keys = None if scene_keys is None else frozenset(scene_keys)
        self.publishers = dict(publishers or {})  # key -> entitled process, beyond publisher_of's rule
        self.inputs = 0  # controllers' commands seen (recorded through the plant's copies)
        self.rejected: dict[str, int] = {}  # reason -> samples rejected (trust, scene)
        self.rejected_by_sender: dict[str, int] = {}  # claimed process / Zenoh id -> samples
        self.rejected_examples: list[str] = []
        #: processes whose authenticated samples reached us: liveliness is watched for these
        #: and the expected ones only (a token carries no authenticator)
        self.signers: set[str] = set()
        self.liveliness_ignored = 0  # token changes of processes we do not watch (counted, never recorded)

    # ------------------------------------------------------------------ control

    def request_stop(self, reason: str) -> None:
        """Ask the loop to drain and finish (safe from a signal handler)."""
        if self._stop_reason is None:
            self._stop_reason = reason

    # ------------------------------------------------------------------ message handling

    def _bad(self, key: str, why: str) -> None:
        self.malformed += 1
        if len(self.malformed_examples) < _MAX_EXAMPLES:
            self.malformed_examples.append(f"{key}: {why}")

    def _reject(self, key: str, reason: str, sender: str, detail: str = "") -> None:
        """Count a sample refused for trust or scene reasons (never written)."""
        self.rejected[reason] = self.rejected.get(reason, 0) + 1
        if sender in self.rejected_by_sender or len(self.rejected_by_sender) < _MAX_EXAMPLES:
            self.rejected_by_sender[sender] = self.rejected_by_sender.get(sender, 0) + 1
        else:
            self.rejected_by_sender["(others)"] = self.rejected_by_sender.get("(others)", 0) + 1
        if len(self.rejected_examples) < _MAX_EXAMPLES:
            self.rejected_examples.append(f"{key[:200]}: {reason}{': ' + detail[:200] if detail else ''}")

    def _kind(self, key: str) -> str | None:
        """Message kind of a key of this scenario ("orbit", ..., "event", "status"), else None."""
        kind = self._key_kind.get(key, "")
        if kind != "":
            return kind
        kind = None
        if key.startswith(self.prefix):
            try:
                kind = messages.kind_of_key(key)
            except messages.MessageError:
                kind = None
        if len(self._key_kind) < _MAX_KEY_CACHE:
            self._key_kind[key] = kind
        return kind

    def _record(self, key: str, payload: bytes, now_ns: int, sender: str | None = None) -> None:
        kind = self._kind(key)
        if kind is None:
            self._bad(key, "not a message key of this scenario")
            return
        if self.scene_keys is not None and kind in _SCENE_KINDS and key not in self.scene_keys:
            self._reject(key, "not-in-scene", sender or "unauthenticated")
            return
        fast = messages.FAST_CHECKS.get(kind)
        found = fast(payload) if fast is not None and type(payload) is bytes else None
        msg = None
        if found is None:
            try:
                msg = messages.decode(payload, kind)
            except messages.MessageError as exc:
                self._bad(key, str(exc))
                return
            found = msg["t"], msg["seq"]
        t, seq = found
        track = None
        if kind == "event":
            if sender is not None and msg["process"] != sender:
                self._reject(key, "impersonation", sender, f"event of process {msg['process']!r} signed by {sender!r}")
                return
            if msg["process"] == self.name:  # its own event, recorded when it happened (_own_event): the echo
                return
            track = f"{key}#{msg['process']}"
        elif kind == "command":  # seq counts each sender's commands to this body; the plant
            track = f"{key}#{msg['sender']}"  # re-publishes those it applied: a refused one is a gap, not a loss
            if track not in self.recorder.seq.channels:
                self.recorder.seq.expect_gaps(track)
        try:
            status = self.recorder.write_encoded(key, payload, t, seq, now_ns, track)
        except ValueError as exc:  # t outside MCAP's log_time range
            self._bad(key, str(exc))
            return
        if status == DUPLICATE:
            return
        if t > self.max_t:
            self.max_t = t
        if kind in _STATE_KINDS:
            self.states += 1
        elif kind == "event":
            self._on_event(msg)

    def _layout_of(self, batch_key: str, payload: bytes, buf: np.ndarray, count: int) -> BatchLayout | None:
        """The :class:`BatchLayout` of this envelope's keys (cached per batch key); None
        (and reported as malformed) when the envelope cannot be split."""
        spans = self._spans
        known = self._layouts.get(batch_key)
        for i, layout in enumerate(known or ()):
            if ingest.same_keys(buf, spans[0], spans[1], count, layout.blob, layout.blob_start, layout.blob_len):
                if i:
                    known.insert(0, known.pop(i))
                return layout
        try:
            items = messages.decode_batch(payload)
        except messages.MessageError as exc:
            self._bad(batch_key, str(exc))
            return None
        keys = [key for key, _ in items]
        # keys outside the scene take the per-message path, which rejects them
        kinds = np.array([_FAST_KIND.get(self._kind(key), ingest.KIND_OTHER)
                          if self.scene_keys is None or key in self.scene_keys else ingest.KIND_OTHER
                          for key in keys], dtype=np.int8)
        layout = BatchLayout(keys, kinds)
        # at most _LAYOUTS_PER_KEY per key and _MAX_LAYOUTS in all (a publisher that sends a
        # new layout each time only replaces its own oldest one)
        cached = sum(map(len, self._layouts.values()))
        if known is not None:
            known.insert(0, layout)
            if len(known) > _LAYOUTS_PER_KEY or cached >= _MAX_LAYOUTS:
                known.pop()
        elif cached < _MAX_LAYOUTS:
            self._layouts[batch_key] = [layout]
        return layout

    def _record_batch(self, batch_key: str, payload: bytes, now_ns: int, sender: str | None = None) -> None:
        """Every entry of an envelope, as if each had arrived on its own key: canonical
        states in one compiled pass (:meth:`McapRecorder.write_batch`), the rest through
        :meth:`_record`, in arrival order."""
        buf = np.frombuffer(payload, dtype=np.uint8)
        spans = self._spans
        count = ingest.frame_batch(buf, *spans)
        if count < 0 and len(payload) >= 8:  # too many entries for the span arrays, or damage
            need = int.from_bytes(payload[4:8], "little")
            if need > spans[0].shape[0] and need <= len(payload) // 6:
                self._spans = spans = tuple(np.empty(need, dtype=np.int64) for _ in range(4))
                count = ingest.frame_batch(buf, *spans)
        if count < 0:
            try:
                messages.decode_batch(payload)
            except messages.MessageError as exc:
                self._bad(batch_key, str(exc))
            return
        layout = self._layout_of(batch_key, payload, buf, count)
        if layout is None:
            return
        keys, starts, lens = layout.keys, spans[2], spans[3]

        def slow(i: int) -> None:
            a = int(starts[i])
            self._record(keys[i], payload[a : a + int(lens[i])], now_ns, sender)

        try:
            written, max_t = self.recorder.write_batch(buf, count, starts, lens, layout, now_ns, slow)
        except messages.MessageError as exc:  # a key the recorder cannot register
            self._bad(batch_key, str(exc))
            return
        self.states += written
        if max_t > self.max_t:
            self.max_t = max_t

    def _on_event(self, msg: dict) -> None:
        process = msg["process"]
        if msg["kind"] == bus.END_EVENT:
            count = None
            try:
                detail = messages.parse_json(msg["detail"]) if msg["detail"] else {}
            except ValueError:
                detail = None
            if isinstance(detail, dict):
                if isinstance(detail.get("messages"), int):
                    count = detail["messages"]
                last = detail.get("last_step")
                if isinstance(last, int) and not isinstance(last, bool) and 0 <= last <= messages.MAX_SEQ:
                    self.last_step[process] = last
                self._fold_refusals(process, detail.get("rejected"))
                reason = detail.get("reason")
                if isinstance(reason, str) and not reason.startswith(FULL_RUN_END_REASONS):
                    self.stopped_early[process] = {"reason": reason[:200], "t": msg["t"], "last_step": last}
                else:
                    self.stopped_early.pop(process, None)  # (a restarted process that went on to the end)
            self.ended[process] = count

    def _fold_refusals(self, process: str, rejected: Any) -> None:
        """Count the supervisor commands a propagator refused (its end event's ``rejected``,
        reason -> n) among this logger's rejections, as ``command <reason>``: they were sent
        to the run by someone else (docs/security.md).  Only from an authenticated event, and
        not the plant's (``run`` adds those from the plant's own summary)."""
        if self.verifier is None or process in ("plant", self.name) or not isinstance(rejected, dict):
            return
        for reason, n in list(rejected.items())[:len(auth.REJECT_REASONS) + 1]:
            if isinstance(n, int) and not isinstance(n, bool) and 0 < n <= messages.MAX_SEQ and isinstance(reason, str):
                why = f"command {reason[:40]}"
                self.rejected[why] = self.rejected.get(why, 0) + n
                sender = f"(commands to {process})"
                self.rejected_by_sender[sender] = self.rejected_by_sender.get(sender, 0) + n

    def handle(self, key: str, payload: bytes, attachment: bytes | None = None) -> None:
        """Handle one sample (exposed for tests and for replaying captured traffic);
        ``attachment`` is the sample's Zenoh attachment (its authenticator)."""
        self.received += 1
        now_ns = time.time_ns()
        rest = key[len(self.prefix):] if key.startswith(self.prefix) else None
        sender = None
        if rest is not None and rest.startswith("@batch/") and "plant" in self.expect and rest[7:] not in self.expect:
            self.inputs += 1  # a controller's envelope of commands, addressed to the plant (docs/control.md)
            return
        if self.verifier is not None:
            if key.endswith("/command") and "plant" in self.expect and _claimed_process(attachment) != "claims plant":
                self.inputs += 1  # a controller's command, addressed to the plant: it judges and re-publishes it
                return
            try:
                sender = self.verifier.verify(key, payload, attachment)
            except auth.AuthError as exc:
                self._reject(key, exc.reason, _claimed_process(attachment))
                return
            entitled = self.publishers.get(key) or (publisher_of(rest) if rest is not None else None)
            if entitled is not None and entitled != sender:
                self._reject(key, "wrong-publisher", sender, f"{key} belongs to process {entitled!r}")
                return
            self.signers.add(sender)  # one of the run's processes (bounded: only they can sign)
        if rest is not None and rest.startswith("@batch/"):
            self.latest[key] = payload
            self._record_batch(key, payload, now_ns, sender)
        elif rest is not None and rest.startswith("@heartbeat/"):
            self.heartbeats[rest[len("@heartbeat/"):]] = self.clock.s
        else:
            if key.endswith(_LATEST_SUFFIXES):
                self.latest[key] = payload
            self._record(key, payload, now_ns, sender)

    def answer_latest(self, query) -> None:
        """The ``@latest`` queryable (on Zenoh's thread): one batch envelope of the newest
        sample of every state key, signed by this logger when it has the run's secret."""
        try:
            items = list(self.latest.items())  # one C-level copy under the GIL
            payload = messages.encode_batch(items)
            key = messages.latest_key(self.scenario)
            attachment = self.signer.attachment(key, payload) if self.signer is not None else None
            query.reply(key, payload, attachment=attachment)
        except Exception as exc:  # never let a query disturb the logger
            query.reply_err(json.dumps({"error": f"latest: {exc}"}))

    def _own_event(self, kind: str, detail: str) -> None:
        """Record an event of the logger itself (a death or a stall it saw) and publish it,
        signed, as every process publishes its events: a live client sees it, and a
        supervisor counts the logger's event seqs (``serve`` continues them in a restarted
        logger's part: :class:`astrodyn.bus.EventSeqWatcher`).  Its echo is not recorded twice."""
        msg = messages.event_message(self.max_t, self._own_event_seq, self.name, kind, detail[:4096])
        self._own_event_seq += 1
        payload = messages.encode(msg)
        self.recorder.write_encoded(self.event_key, payload, msg["t"], msg["seq"], time.time_ns(), f"{self.event_key}#{self.name}")
        if self._own_event_publisher is not None:
            with contextlib.suppress(Exception):  # the file holds it; the bus copy is for live clients
                bus.signed_put(self._own_event_publisher, self.event_key, payload, self.signer)
        print(f"logger: {detail}", file=sys.stderr, flush=True)

    # ------------------------------------------------------------------ status

    def status(self, channels: bool = False) -> dict:
        """Counts so far (the reply of the ``@status`` query and the basis of the summary)."""
        totals = self.recorder.seq.totals()
        expected = self.expected_messages()
        elapsed = time.monotonic() - self._started
        out: dict[str, Any] = {
            "process": self.name,
            "scenario": self.scenario,
            "out": self.recorder.path,
            "received": self.received,
            "messages": self.recorder.message_count,
            "states": self.states,
            "missing": totals["missing"],
            "duplicates": totals["duplicates"],
            "already_recorded": totals["already_recorded"],
            "out_of_order": totals["out_of_order"],
            "malformed": self.malformed,
            "malformed_examples": list(self.malformed_examples),
            "rejected": dict(self.rejected),
            "rejected_by_sender": dict(self.rejected_by_sender),
            "rejected_examples": list(self.rejected_examples),
            "ended": dict(self.ended),
            "died": dict(self.died),
            "stalled": sorted(self.stalled),
            "liveliness_ignored": self.liveliness_ignored,
            "expected_states": expected,
            "complete": self.is_complete(),
            "stopped_early": dict(self.stopped_early),
            "t": self.max_t,
            "elapsed_s": round(elapsed, 3),
            "rate_msg_s": round(self.received / elapsed, 1) if elapsed > 0 else 0.0,
        }
        if channels:
            report = self.recorder.seq.report()
            out["channels"] = {k: r["count"] for k, r in report.items()}
            # per process on the event channel: the seq a restarted process must continue from
            out["event_next_seq"] = {k: r["next_seq"] for k, r in report.items() if "#" in k}
            out["gaps"] = {k: r["gaps"] for k, r in report.items() if r["gaps"]}
        return out

    def expected_messages(self) -> int | None:
        """Sum of the end-of-run counts of the expected processes, once all have ended."""
        if not self.expect or any(self.ended.get(p) is None for p in self.expect):
            return None
        return sum(self.ended[p] for p in self.expect)  # type: ignore[misc]

    def reach_report(self) -> dict[str, dict]:
        """What the logger misses of processes that have not ended, for its supervisor's
        heartbeat watch (:meth:`astrodyn.service.children.Child.kill_if_lost_to_logger`):

        * ``unheard``: ``{process: seconds}``, processes whose heartbeat the logger has not
          heard for more than ``stall_timeout_s`` of its listening clock;
        * ``holes``: ``{process: step}``, the first output step missing in the state channels
          of each process whose channels have a gap (ended processes too).

        Both happen when the bus link between a process and the logger was lost while both
        ran (the logger stopped longer than Zenoh waits on a blocked link, 5 s; the whole run
        paused longer than the 10 s lease): Zenoh drops what is published meanwhile and does
        not always link the two again.  The supervisor, which still hears the process,
        restarts it from the last step the logger holds (docs/reliability.md)."""
        unheard = {p: round(self.clock.s - heard, 1) for p, heard in self.heartbeats.items()
                   if p != self.name and p not in self.ended and self.clock.s - heard > self.stall_timeout_s}
        holes: dict[str, int] = {}
        seq = self.recorder.seq
        if seq.totals()["missing"]:
            for channel, c in seq.channels.items():
                if c.missing and c.gaps and not c.gaps_expected:
                    process = self._publisher_of_state(channel)
                    if process is not None:
                        holes[process] = min(holes.get(process, c.gaps[0][0]), c.gaps[0][0])
        return {k: v for k, v in (("unheard", unheard), ("holes", holes)) if v}

    def is_complete(self) -> bool:
        """Every expected process ended and every state it announced is recorded, no gaps.

        Two tests, both needed.  The count: at least the sum of the end events' counts.  And
        the steps: every state channel of an ended process that announced its ``last_step``
        holds that step (``seq`` is the output step, docs/architecture.md section 5).  The
        count alone is not enough after a restart: the states of the killed process are
        recorded but counted in no end event, so the new process's last states could still
        be on their way when the count was already reached (an end event and the states
        before it arrive on different subscribers, in any order)."""
        expected = self.expected_messages()
        totals = self.recorder.seq.totals()
        # states a restarted process published again and an earlier part holds count too
        if expected is None or self.states + totals["already_recorded"] < expected or totals["missing"] != 0:
            return False
        return self.steps_recorded()

    def steps_recorded(self) -> bool:
        """Every orbit / attitude / crosscheck channel seen holds the ``last_step`` its
        publishing process announced in its end event (True for processes that did not)."""
        if not self.last_step:
            return True
        seq = self.recorder.seq
        for channel, c in seq.channels.items():
            process = self._channel_process.get(channel, "")
            if process == "":
                process = self._channel_process[channel] = self._publisher_of_state(channel)
            last = self.last_step.get(process) if process is not None else None
            if last is not None and seq.next_seq[c.slot] <= last:
                return False
        return True

    def _publisher_of_state(self, channel: str) -> str | None:
        """The process publishing the state channel (seq = output step), else None."""
        if not channel.startswith(self.prefix):
            return None
        rest = channel[len(self.prefix):]
        if rest.rpartition("/")[2] not in _STATE_KINDS:
            return None
        return self.publishers.get(channel) or publisher_of(rest)

    # ------------------------------------------------------------------ housekeeping

    def _housekeeping(self, control: bus.ControlServer, alive: bus.AliveWatcher, heartbeat: bus.Heartbeat) -> bool:
        """Queries, liveliness, heartbeats, flushing; returns True when the loop should end."""
        now = time.monotonic()
        for request in control.poll():
            if request.verb == "stop":
                self.request_stop("stop requested")
                self._stop_requests.append(request)
            else:
                request.reply(self.status(channels=bool(request.args.get("channels"))))
        for process, is_alive in alive.poll():
            if not self._watched(process):
                self.liveliness_ignored += 1
            elif not is_alive and process not in self.ended:
                self._lost.setdefault(process, now)
            elif is_alive:
                self._lost.pop(process, None)
        # A token can vanish while the process's last samples (its end-of-run event among
        # them) still wait in our queue: confirm a death only once the queue was drained
        # after the loss (or 5 s later if it never drains).
        for process, lost_at in list(self._lost.items()):
            if process in self.ended:
                del self._lost[process]
            elif self._drained_at >= lost_at or now - lost_at > 5.0:
                del self._lost[process]
                if self._token_present(process):
                    # another token of that name is still there: the one that went was not
                    # the process's own (anyone can declare one; docs/security.md)
                    self.liveliness_ignored += 1
                    continue
                self.died[process] = f"liveliness lost at sim t = {self.max_t!r} s"
                self._own_event("error", f"process {process} died (liveliness token lost) before its end-of-run event; "
                                f"{self.states} states recorded so far, sim t reached {self.max_t!r} s")
        for process, heard in self.heartbeats.items():
            silent_s = self.clock.s - heard
            if (silent_s > self.stall_timeout_s and process in alive.alive and process not in self.ended
                    and process not in self.stalled and process != self.name):
                self.stalled.add(process)
                self._own_event("error", f"process {process} stalled: alive but no heartbeat for {silent_s:.1f} s")
        if now >= self._next_reach_report:
            self._next_reach_report = now + REACH_REPORT_S
            self._reach = self.reach_report()
        heartbeat.beat(messages=self.recorder.message_count, t=self.max_t, **self._reach)
        self.recorder.maybe_flush()

        idle = now - self._last_sample_at
        if self._stop_reason is not None:
            if self._stop_requested_at is None:
                self._stop_requested_at = now
            if self.is_complete() or idle >= min(self.drain_idle_s, 0.1) or now - self._stop_requested_at > self.drain_timeout_s:
                self.reason = self._stop_reason
                return True
            return False
        # under a supervisor (control off) a death does not end the run: it restarts the process
        if self.expect and all(p in self.ended or (p in self.died and self.control) for p in self.expect):
            if self._all_ended_at is None:
                self._all_ended_at = now
            if self.is_complete():
                self.reason = "end of run: every expected message recorded"
                return True
            # under a supervisor a gap in a state channel (states lost on the bus) is refilled by
            # restarting its process (Child.ended_cut_off_from_logger): wait for that, bounded
            refill = not self.control and bool(self._reach.get("holes"))
            if (idle >= self.drain_idle_s and not refill) or now - self._all_ended_at > self.drain_timeout_s:
                self.reason = "end of run: expected processes ended or died; bus quiet"
                return True
        return False

    def _watched(self, process: str) -> bool:
        """Whether a liveliness change of ``process`` may be reported (a death is written to
        the file as an ``error`` event): an expected process or one whose authenticated
        samples we received; under no secret (a logger run by hand) any, up to a bound."""
        if process == self.name:
            return False
        if process in self.expect or process in self.signers or process in self.died or process in self._lost:
            return True
        return self.verifier is None and len(self.died) + len(self._lost) < _MAX_EXAMPLES

    def _token_present(self, process: str) -> bool:
        """A liveliness query for ``process``'s token (bounded wait)."""
        try:
            for reply in self.session.liveliness().get(messages.alive_key(self.scenario, process), timeout=0.5):
                if reply.ok is not None:
                    return True
        except zenoh.ZError:  # a failed query confirms nothing: report the loss
            return False
        return False

    # ------------------------------------------------------------------ main loop

    def run(self, max_seconds: float | None = None, install_signal_handlers: bool = True) -> dict:
        """Record until the run ends or a stop; finish the file; return the summary dict."""
        if install_signal_handlers:
            catch_stop_signals(self.request_stop)
        deadline = None if max_seconds is None else time.monotonic() + max_seconds
        with contextlib.ExitStack() as stack:
            subs = [
                stack.enter_context(self.session.declare_subscriber(key, zenoh.handlers.FifoChannel(self.queue_capacity)))
                for key in bus.scenario_keys(self.scenario)
            ]
            control = stack.enter_context(bus.ControlServer(
                self.session, self.scenario, verbs=("stop",) if self.control else (),
                extra_keys={messages.status_key(self.scenario): "status"}))
            stack.enter_context(bus.SchemaServer(self.session, self.scenario))  # the message layouts, for any client
            latest = self.session.declare_queryable(messages.latest_key(self.scenario), self.answer_latest)
            stack.callback(latest.undeclare)
            alive = stack.enter_context(bus.AliveWatcher(self.session, self.scenario))
            heartbeat = stack.enter_context(bus.Heartbeat(self.session, self.scenario, self.name, signer=self.signer))
            self._own_event_publisher = bus.declare_state_publisher(self.session, self.event_key)
            stack.callback(self._own_event_publisher.undeclare)
            ingest.warm_up(INGEST_GRAMMAR)  # compile / load the batch kernels before we say ready
            stack.enter_context(bus.declare_alive(self.session, self.scenario, self.name))  # last: ready
            receivers = [sub.try_recv for sub in subs]
            handle = self.handle
            next_housekeeping = 0.0
            while True:
                n = 0
                for try_recv in receivers:  # a budget per subscription: none starves the others
                    for _ in range(2048):
                        sample = try_recv()
                        if sample is None:
                            break
                        attachment = sample.attachment
                        handle(str(sample.key_expr), sample.payload.to_bytes(),
                               None if attachment is None else attachment.to_bytes())
                        n += 1
                now = time.monotonic()
                self.clock.tick(now)
                if n:
                    self._last_sample_at = now
                else:
                    self._drained_at = now
                if n == 0 or now >= next_housekeeping:
                    next_housekeeping = now + 0.05
                    if self._housekeeping(control, alive, heartbeat):
                        break
                    if deadline is not None and now > deadline:
                        self.reason = f"max_seconds={max_seconds} reached"
                        break
                if n == 0:
                    time.sleep(0.002)
            summary = self.status(channels=True)
            summary["reason"] = self.reason
            # how far the run got, in the file itself (read back by load().metadata["end"])
            self.recorder.add_metadata("end", {k: summary[k] for k in (
                "reason", "t", "states", "missing", "duplicates", "malformed", "ended", "died", "stalled", "complete", "stopped_early")})
            if self.verifier is not None or self.scene_keys is not None:
                # what was refused, in the file itself (read back by load().metadata["rejected"])
                self.recorder.add_metadata("rejected", {
                    "authenticated": self.verifier is not None, "scene_only": self.scene_keys is not None,
                    "total": sum(self.rejected.values()), "by_reason": self.rejected,
                    "by_sender": self.rejected_by_sender, "examples": self.rejected_examples})
            # the file takes its name when it was stopped as it should: the end of the run, a
            # stop request, or SIGTERM / SIGINT / SIGHUP to a logger run by hand (docs/reliability.md);
            # a supervisor's logger leaves that to the supervisor, who knows how the run ended
            finished = self.rename_at_end and (
                self.reason in ("end of run: every expected message recorded", "stop requested", *STOP_SIGNAL_NAMES)
                or self.reason.startswith("max_seconds"))
            stats = self.recorder.close(rename=finished)
            summary["file_complete"] = True
            summary["file"] = stats.get("file") or self.recorder.path
            if stats.get("parts_kept_aside"):  # a rolled part's name was taken: where that part is instead
                summary["parts_kept_aside"] = stats["parts_kept_aside"]
            for request in self._stop_requests:
                request.reply(summary)
        return summary


# --------------------------------------------------------------------------- process entry


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="python -m astrodyn.service.logger", description="Logger process: record one scenario from the Zenoh bus into an MCAP file.")
    p.add_argument("--scenario", required=True, help="scenario name (the <scenario> in astrodyn/<scenario>/**)")
    p.add_argument("--out", required=True, help="MCAP file to write")
    p.add_argument("--epoch-ns", type=int, required=True, help="scenario epoch as integer ns since the Unix epoch")
    p.add_argument("--config", help="scenario config file; its text is stored in the 'scenario' metadata record")
    p.add_argument("--metadata", help="JSON file with extra 'scenario' metadata (an object)")
    p.add_argument("--expect", action="append", default=[], metavar="PROCESS",
                   help="process whose end-of-run event ends the recording (repeatable)")
    p.add_argument("--chunk-size", type=int, default=1 << 20, help="uncompressed bytes per zstd chunk")
    p.add_argument("--flush-interval", type=float, default=1.0, help="max seconds between flushes (crash-loss bound)")
    p.add_argument("--queue", type=int, default=256, help="bounded receive queue per subscription (samples; a full queue blocks the publishers, so memory stays bounded and nothing is lost)")
    p.add_argument("--no-control", action="store_true",
                   help="do not answer the stop verb (a supervisor such as `astrodyn serve` ends the run)")
    p.add_argument("--roll-size", type=int, default=None, help="start a new file after this many bytes")
    p.add_argument("--roll-interval", type=float, default=None, help="start a new file after this many wall seconds")
    p.add_argument("--max-seconds", type=float, default=None, help="stop after this many wall seconds")
    p.add_argument("--prefill", default=None, metavar="MCAP",
                   help="first copy the state messages with seq < --prefill-steps from this recording (run --resume)")
    p.add_argument("--prefill-steps", type=int, default=0, help="steps (seq 0 .. N-1) to copy from --prefill")
    p.add_argument("--in-place", action="store_true",
                   help="write --out directly (default: write NAME.partial.mcap and rename it to --out once finished)")
    p.add_argument("--leave-partial", action="store_true",
                   help="finish the last file under its partial name; the supervisor renames it once the run succeeded")
    p.add_argument("--name", default="logger",
                   help="process name on the bus (default logger; a standby beside it: logger-2, ...); it signs as this name")
    p.add_argument("--first-part", type=int, default=0, help="number of the first rolled part (a restarted logger)")
    p.add_argument("--resume-seqs", default=None, metavar="JSON",
                   help="a JSON file {key: next seq}: each channel starts there, lower seqs are in an earlier part "
                        "(serve's logger restart) and are dropped as already recorded")
    p.add_argument("--attempt", type=int, default=0,
                   help="restart count of this logger in its run: its partial files are NAME.partial-<attempt>.mcap")
    p.add_argument("--own-files", default=None, metavar="FILE",
                   help="append a JSON line {file, dev, ino} to FILE for every file this logger creates or names "
                        "(a supervisor's record of which files are its own: docs/reliability.md)")
    bus.add_bus_arguments(p)
    return p.parse_args(argv)


def own_files_reporter(path: str | None):
    """The recorder's ``on_file`` for ``--own-files``: one JSON line per file created or
    named, appended (``O_APPEND``: one write, whole lines) to the supervisor's private
    file; None without the flag.  A line that cannot be written is said on stderr (the
    supervisor then does not take the file for its own: it is never read, renamed or
    removed by it)."""
    if not path:
        return None

    def report(file: str, identity: tuple[int, int]) -> None:
        line = json.dumps({"file": os.path.abspath(file), "dev": identity[0], "ino": identity[1]}) + "\n"
        try:
            fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_CLOEXEC, 0o600)
            try:
                os.write(fd, line.encode())
            finally:
                os.close(fd)
        except OSError as exc:
            with contextlib.suppress(OSError):
                print(f"logger: warning: --own-files {path}: {exc.strerror or exc}", file=sys.stderr, flush=True)
    return report


def scenario_metadata(args: argparse.Namespace) -> dict:
    meta: dict = {"name": args.scenario}
    if args.metadata:
        with open(args.metadata, encoding="utf-8") as f:
            extra = json.load(f)
        if not isinstance(extra, dict):
            raise ValueError(f"--metadata {args.metadata}: expected a JSON object, got {type(extra).__name__}")
        meta.update(extra)
    if args.config:
        with open(args.config, encoding="utf-8") as f:
            meta["config"] = f.read()
        meta["config_path"] = meta.get("source", args.config)  # the file the user named (--config is the run's copy)
    return meta


def prefill(recorder: McapRecorder, path: str, scenario: str, steps: int) -> int:
    """Copy the state messages (orbit, attitude, crosscheck) with ``seq < steps`` of
    ``scenario`` from the recording ``path`` into ``recorder``, payloads unchanged; this
    also seeds the seq accounting, so the continuation counts no gap.  Returns the number
    of messages copied.  Events of the old run are not copied (the new processes number
    their own); the "resumed_from" metadata record says where the copy came from."""
    from astrodyn.recording.stream import open_stream

    n = 0
    with open_stream(path) as stream:
        for m in stream.messages(f"{messages.PREFIX}/{scenario}/*"):
            try:
                kind = messages.kind_of_key(m.topic)
            except messages.MessageError:
                continue
            if kind not in _STATE_KINDS:
                continue
            try:
                msg = messages.decode(m.data, kind)
            except messages.MessageError:
                continue  # load() reports these; they are not states to continue from
            if msg["seq"] < steps:
                recorder.write_encoded(m.topic, m.data, msg["t"], msg["seq"], m.publish_time)
                n += 1
    recorder.add_metadata("resumed_from", {"path": os.path.abspath(path), "steps": str(steps), "messages": str(n)})
    return n


def read_seed_table(path: str) -> dict[str, int]:
    """The ``--resume-seqs`` file: ``{channel: next seq}`` (written by serve when it restarts
    a dead logger: :mod:`astrodyn.service.supervision`), each channel a key astrodyn records
    or an event key and a process, ``KEY#PROCESS`` (each process numbers its own events);
    ValueError naming the file and the entry for anything else.  Read before the recording
    is opened, so a bad file leaves nothing behind."""
    try:
        with open(path, encoding="utf-8") as f:
            table = json.load(f)
    except (OSError, ValueError, RecursionError) as exc:
        raise ValueError(f"--resume-seqs {path}: expected a readable JSON file, got {type(exc).__name__}: {exc}") from None
    if not isinstance(table, dict):
        raise ValueError(f"--resume-seqs {path}: expected a JSON object key -> next seq")
    for key, next_seq in table.items():
        if not (isinstance(next_seq, int) and not isinstance(next_seq, bool) and 0 <= next_seq <= messages.MAX_SEQ):
            raise ValueError(f"--resume-seqs {path}: {key}: expected an integer seq 0 ... 2**53-1, got {next_seq!r}")
        key_part, hash_sign, process = key.partition("#")
        try:
            kind = messages.kind_of_key(key_part)
            if hash_sign:
                if kind != "event":
                    raise messages.MessageError(f"{key}: only an event key takes a #process, {key_part!r} is a {kind} key")
                messages.check_name(process, f"{key}: the process")
        except messages.MessageError as exc:
            raise ValueError(f"--resume-seqs {path}: {exc}") from None
    return table


def trust_from_environment(args: argparse.Namespace) -> dict:
    """The Logger's trust arguments for this process: a verifier and a signer from the run
    secret a supervisor handed down (:data:`astrodyn.auth.SECRET_ENV`; none for a logger
    started by hand), and the scene's state keys from ``--config`` (scene-only recording)."""
    out: dict = {}
    signer = bus.process_signer(args.name)
    if signer is not None:
        out["signer"] = signer
        out["verifier"] = auth.Verifier(auth.secret_from_environment())
    if args.config:
        from astrodyn.scenario import ScenarioError, load

        try:
            scenario = load(args.config)
        except ScenarioError as exc:
            raise ValueError(f"--config: {exc}") from None
        if scenario.name != args.scenario:
            raise ValueError(f"--config: expected scenario {args.scenario!r}, the file names {scenario.name!r}")
        out["scene_keys"] = scene_state_keys(scenario)
        out["publishers"] = scene_publishers(scenario)
    return out


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    share_fate_with_supervisor()  # never outlive the run / serve that started us
    try:
        set_threads(service_threads())  # thread policy (astrodyn.jit): 1 numba thread unless $ASTRODYN_THREADS
        messages.check_name(args.name, "--name")
        seeds = read_seed_table(args.resume_seqs) if args.resume_seqs else {}
        meta = scenario_metadata(args)
    except (OSError, ValueError) as exc:
        print(f"logger: {exc}", file=sys.stderr)
        return 2
    try:
        trust = trust_from_environment(args)
    except (OSError, ValueError, auth.AuthError, bus.BusError) as exc:
        print(f"logger: {exc}", file=sys.stderr)
        return 2
    try:
        with bus.session_from_args(args) as session:
            recorder = McapRecorder(args.out, meta, epoch_ns=args.epoch_ns,
                                    chunk_size=args.chunk_size, flush_interval_s=args.flush_interval,
                                    roll_size=args.roll_size, roll_interval_s=args.roll_interval,
                                    atomic=not args.in_place, first_part=args.first_part, attempt=args.attempt,
                                    on_file=own_files_reporter(args.own_files))
            copied = prefill(recorder, args.prefill, args.scenario, args.prefill_steps) if args.prefill else 0
            for key, next_seq in seeds.items():  # each channel starts where an earlier part ended
                recorder.seq.seed(key, next_seq)
            own_events = f"{messages.event_key(args.scenario)}#{args.name}"  # its own events continue too
            logger = Logger(session, args.scenario, recorder, name=args.name, expect=args.expect, queue_capacity=args.queue,
                            control=not args.no_control, first_event_seq=seeds.get(own_events, 0), **trust)
            logger.rename_at_end = not args.leave_partial
            summary = logger.run(max_seconds=args.max_seconds)
            if args.prefill:
                summary["prefilled"] = copied
    except (RecordingError, bus.BusError) as exc:
        # the file really in the way: the first one, or a later rolled part's (the writer names it)
        writing = None if args.in_place else (getattr(exc, "path", None) or writing_path(args))
        if writing is not None and isinstance(exc.__context__, FileExistsError):  # O_EXCL: something is there
            with contextlib.suppress(OSError):
                print(f"logger: {in_the_way(writing)}", file=sys.stderr, flush=True)
            return OUT_IN_THE_WAY_EXIT
        disk_full = getattr(exc, "errno", None) in DISK_FULL_ERRNOS
        with contextlib.suppress(OSError):  # stderr may be a file on the disk that is full
            print(f"logger: {exc}", file=sys.stderr, flush=True)
        return DISK_FULL_EXIT if disk_full else 1
    return print_summary_line(summary)


#: errno values of a write that failed because the logger's disk, or its share of it, is
#: full: ENOSPC, EDQUOT (quota), EFBIG (``File too large``: RLIMIT_FSIZE, or the largest
#: file the file system takes).  A logger that meets one exits :data:`DISK_FULL_EXIT` and
#: is not restarted (a new one would fail the same way).
DISK_FULL_ERRNOS = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG)


def writing_path(args: argparse.Namespace) -> str:
    """The file the logger of ``args`` creates first (``NAME[-000k].partial[-n].mcap``)."""
    first = part_path(args.out, args.first_part) if args.first_part else args.out
    return partial_path(first, args.attempt)


def in_the_way(path: str) -> str:
    """Why the logger could not create ``path`` (``O_EXCL``: something is there), in one
    line for the supervisor to pass on: another recorder's live file (it holds its
    ``flock``), a symbolic link, or a file left there (a killed run's partial recording)."""
    if os.path.islink(path):
        return (f"{path}: is a symbolic link, in the way of the recording; it is never written through, replaced or "
                f"removed: remove it or choose another --out")
    for _ in range(5):  # a recorder that won a race for the name takes its lock right after creating the file
        if being_written(path):
            return (f"{path}: is being recorded right now by another run or serve (its logger holds it); it is never "
                    f"touched: choose another --out, or stop that one first")
        time.sleep(0.05)
    return (f"{path}: is in the way (another run or serve started recording to the same --out, or a killed run left "
            f"its partial recording there): finish it with `astrodyn recover {path}` or remove it; it is never "
            f"overwritten")


def print_summary_line(summary: dict) -> int:
    """Print the one-line JSON summary on stdout (a file in the supervisor's work directory);
    the logger's exit status: 0, or :data:`DISK_FULL_EXIT` / 1 when the line cannot be
    written (its disk is full: the recording itself is finished)."""
    try:
        print(json.dumps(summary, separators=(",", ":")), flush=True)
    except OSError as exc:
        with contextlib.suppress(OSError):  # what is left in stdout's buffer goes nowhere, not into a failed exit
            fd = os.open(os.devnull, os.O_WRONLY)
            os.dup2(fd, sys.stdout.fileno())
            os.close(fd)
        with contextlib.suppress(OSError):
            print(f"logger: the recording is finished ({summary.get('file')}), but its summary could not be "
                  f"written: {exc.strerror or exc}", file=sys.stderr, flush=True)
        return DISK_FULL_EXIT if exc.errno in DISK_FULL_ERRNOS else 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
