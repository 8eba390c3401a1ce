"""``astrodyn replay FILE.mcap``: republish a recorded run on Zenoh, paced like the original.

Every recorded message is put on its own key (the MCAP topic *is* the Zenoh key,
docs/architecture.md, section 5) with its payload bytes unchanged, in ``log_time`` order, at ``--rate`` times
real time (``--rate inf``: as fast as the bus takes them).  State keys use the same
publisher settings as the live service (reliable, ``CongestionControl.BLOCK``, JSON
encoding), so a consumer subscribed to ``astrodyn/<scenario>/**`` (and ``@event``) sees
the same keys, payloads, order and pacing it would see from the live service.
``--batch`` additionally mimics the propagators' transport: the state messages of one
instant are sent as one batch envelope on ``astrodyn/<scenario>/@batch/orbit`` (orbit and
crosscheck keys) or ``.../@batch/attitude`` (:func:`astrodyn.messages.encode_batch`)
instead of one put per key.

Options: ``--start T`` / ``--end T`` (s since the scenario epoch, inclusive), ``--topics
GLOB`` (repeatable, shell-style, ``*`` crosses ``/``), ``--wait S`` (default 5: wait up
to S wall s, before the clock starts, for a subscriber to any key the replay puts on;
``status`` says ``"state": "waiting"`` meanwhile, with the keys and the seconds left),
``--hold`` (after the end, keep answering control queries until ``stop``; a ``seek``
replays again), ``--listen`` / ``--connect`` / ``--mode`` / ``--port`` (Zenoh endpoints;
default one loopback endpoint, multicast scouting off, as every astrodyn process).

Control, mirroring ``astrodyn serve`` (:mod:`astrodyn.service.serve`), as Zenoh queryables on
``astrodyn/<scenario>/@control/<verb>`` (``--control-scenario`` to use another name):

=========  ==================================  =========================================
verb       arguments (JSON payload)            reply
=========  ==================================  =========================================
status     --                                  state (running, waiting, paused, finished),
                                               rate, t, messages published, progress
pause      --                                  the new status (nothing is sent while paused)
resume     --                                  the new status (pacing re-anchored at t)
rate       ``{"factor": x}`` (1e-3..1e6, "inf")  the new status
seek       ``{"t": T}`` (s since the epoch,    the new status; replay continues from T
           within ``t_start`` .. ``t_end``)
stop       --                                  the final summary
=========  ==================================  =========================================

Pacing: the message with log time ``L`` goes out at wall time ``w0 + (L - L0) / rate``
where ``(w0, L0)`` is the anchor set at start, resume, rate change and seek; messages
with the same log time go out together.  The clock starts with playback (the first
:meth:`Replayer.step`, after the ``--wait`` for a subscriber), not at launch: until then
``t`` stays at the start time (``--start``, or the point of a ``seek``), whatever
``status``, ``pause`` or ``rate`` is asked meanwhile.  A seek back in time republishes earlier seqs
(a consumer sees them again, as it would from a new run).

Bad files: a file that is not MCAP is an error (exit 1, nothing published); a cut file
(writer killed) is replayed up to its last complete chunk and the summary says so
(``"complete": false`` and the reason; exit 0).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from astrodyn import auth, bus, messages
from astrodyn.progress import Progress
from astrodyn.recording.stream import McapStream, RawMessage, topic_matcher
from astrodyn.recording.writer import RecordingError
from astrodyn.service.children import Child, JobControl, StartError, zenoh_config_snapshot
from astrodyn.service.supervision import RestartBudget
from astrodyn.service.viewer import add_foxglove_argument, viewer_command
from astrodyn.signals import StopFlag, suspended_s

__all__ = ["Replayer", "main", "build_parser", "open_recording", "start_viewer", "play", "LiveView", "REPLAY_VERBS",
           "check_control_scenario", "data_scenario_of"]

REPLAY_VERBS = (*bus.CONTROL_VERBS, "seek")
_BATCH_PROCESS = {"orbit": "orbit", "crosscheck": "orbit", "attitude": "attitude"}
_POLL_S = 0.02  # control queries are answered within about this long
#: Per 10 ms round of the wait for a first subscriber: publishers declared (~30 us each) and
#: matching statuses read (~1 us each), so that a recording of many keys holds up the
#: control verbs for no more than ~10 ms a round.
WAIT_DECLARES_PER_ROUND = 256
WAIT_READS_PER_ROUND = 4096
#: Keys named in the ``waiting`` entry of the status (the rest are counted).
WAITING_KEYS_SHOWN = 8


def parse_rate(raw: Any, what: str = "rate") -> float:
    """A real-time factor within :data:`astrodyn.bus.RATE_BOUNDS`, or "inf" (as fast as
    possible); ``ValueError`` naming ``what`` and the allowed range otherwise."""
    try:
        return bus.parse_rate_factor(raw)
    except ValueError:
        lo, hi = bus.RATE_BOUNDS
        shown = repr(raw) if len(repr(raw)) <= 40 else repr(raw)[:37] + "..."
        raise ValueError(f'{what}: expected a real-time factor with {lo:g} <= x <= {hi:g} or "inf", got {shown}') from None


def scenario_of(stream: McapStream) -> str:
    """The scenario name: the "scenario" metadata ``name``, else the first astrodyn topic's."""
    name = stream.metadata.get("scenario", {}).get("name")
    if name:
        return name
    for topic in stream.topics():
        try:
            return messages.parse_key(topic)[0]
        except messages.MessageError:
            continue
    # channels inside chunks are only known once read: peek at the first message
    for msg in stream.messages():
        try:
            return messages.parse_key(msg.topic)[0]
        except messages.MessageError:
            continue
    raise RecordingError(f"{stream.path}: no astrodyn topic and no scenario metadata; give --control-scenario")


def data_scenario_of(stream: McapStream, fallback: str) -> str:
    """The scenario of the recording's data keys (``astrodyn/<scenario>/...``, what the live
    view subscribes to): its first astrodyn topic's, ``fallback`` when none parses (the
    metadata's name can differ from the topics', and ``--control-scenario`` changes only the
    control keys)."""
    for topic in stream.topics():
        try:
            return messages.parse_key(topic)[0]
        except messages.MessageError:
            continue
    return fallback


def check_control_scenario(name, path: str, given: bool) -> str:
    """``name`` if it can be the scenario of the control keys, else MessageError naming where
    it came from: ``--control-scenario`` when ``given``, else the recording ``path``'s
    scenario name (its metadata or its first topic), with the way out (``--control-scenario``).
    The bad value is shown shortened (a 10 kB name stays a one-line error)."""
    try:
        return messages.check_name(name, "--control-scenario")
    except messages.MessageError:
        expected = f"expected a name matching {messages.NAME_PATTERN} (not '.' or '..')"
        shown = f"{messages.show_value(name)} ({len(name)} characters)" if isinstance(name, str) else messages.show_value(name)
        if given:
            raise messages.MessageError(f"--control-scenario: {expected}, got {shown}") from None
        raise messages.MessageError(f"{path}: the recorded scenario name: {expected}, got {shown}; give "
                                    f"--control-scenario NAME to replay it under another name") from None


class Replayer:
    """Publishes the messages of one :class:`McapStream` on a Zenoh session (module docstring).

    Drive it with :meth:`step` from a loop (it returns False once finished), answer
    :class:`astrodyn.bus.ControlRequest` objects with :meth:`handle`.
    """

    def __init__(self, session, stream: McapStream, *, rate: float = 1.0, start_t: float | None = None,
                 end_t: float | None = None, topics=None, batch: bool = False, signer: auth.Signer | None = None):
        self.session = session
        self.signer = signer  # signs each put for the live view (--foxglove), which drops what it did not sign
        self.stream = stream
        self.rate = parse_rate(rate)
        self.topics = topics
        self.batch = batch
        self.lo = stream.t_to_ns(start_t, "start") if start_t is not None else stream.start_ns
        self.hi = stream.t_to_ns(end_t, "end") if end_t is not None else stream.end_ns
        if start_t is not None and end_t is not None and end_t < start_t:
            raise ValueError(f"end: expected end >= start, got start={start_t:g}, end={end_t:g}")
        if self.lo is not None and None not in (stream.start_ns, stream.end_ns) and self.lo > stream.end_ns:
            raise ValueError(f"start: t = {start_t:g} s is after the recording's end (it covers t = "
                             f"{stream.ns_to_t(stream.start_ns):g} .. {stream.ns_to_t(stream.end_ns):g} s)")
        if self.hi is not None and stream.end_ns is not None:
            self.hi = min(self.hi, stream.end_ns)
        if self.lo is not None and self.hi is not None and self.hi < self.lo:  # an end before the recording's start
            raise ValueError(f"end: t = {end_t:g} s is before the recording's start (it covers t = "
                             f"{stream.ns_to_t(stream.start_ns):g} .. {stream.ns_to_t(stream.end_ns):g} s)")
        self.state = "running"
        self.published = 0
        self.skipped: dict[str, str] = {}
        self.last_ns: int | None = None
        self._publishers: dict[str, Any] = {}
        self._pending: dict[str, list[tuple[str, bytes]]] = {}
        self._pending_ns: int | None = None
        # the pacing clock runs from the first step() (playback), not from here: a replay
        # waiting for its first subscriber stays at its start time (module docstring, Pacing)
        self.clock_started = False
        # while wait_for_subscriber() runs: the monotonic time it ends at, the keys, the --wait
        self.waiting_until: float | None = None
        self.waiting_keys: list[str] = []
        self.waiting_s = 0.0
        self._seek(self.lo)
        self.started = time.monotonic()

    # ------------------------------------------------------------------ clock

    def _seek(self, ns: int | None) -> None:
        self._flush_batches()
        self._iter = self.stream.messages(self.topics, start_ns=ns, end_ns=self.hi)
        self._next: RawMessage | None = next(self._iter, None)
        base = ns if ns is not None else (self._next.log_time if self._next else 0)
        self._anchor(base)

    def _anchor(self, ns: int) -> None:
        self._anchor_ns = ns
        self._anchor_wall = time.monotonic()
        self._suspended_at_anchor = suspended_s()

    def _playing_s(self, now: float) -> float:
        """Wall seconds of playback since the anchor at monotonic time ``now``: time the
        replay spent stopped by Ctrl-Z is left out, so after ``fg`` it goes on from where it
        was instead of racing through what the pause would have covered."""
        return now - self._anchor_wall - (suspended_s() - self._suspended_at_anchor)

    def virtual_ns(self, now: float | None = None) -> float:
        """The replay clock: log time (ns) that corresponds to the wall time ``now``
        (the anchor's log time while paused, or before playback has begun)."""
        if self.state != "running" or not self.clock_started:
            return float(self._anchor_ns)
        if math.isinf(self.rate):
            return math.inf
        now = time.monotonic() if now is None else now
        return self._anchor_ns + self._playing_s(now) * self.rate * 1e9

    def wait_time(self) -> float:
        """Seconds until the next message is due (0 when due, inf when paused or done)."""
        if self._next is None or self.state != "running":
            return math.inf
        if math.isinf(self.rate):
            return 0.0
        return max(0.0, (self._next.log_time - self._anchor_ns) / (self.rate * 1e9) - self._playing_s(time.monotonic()))

    # ------------------------------------------------------------------ publishing

    def _publisher(self, key: str):
        pub = self._publishers.get(key)
        if pub is None and key not in self.skipped:
            try:
                pub = self._publishers[key] = bus.declare_state_publisher(self.session, key)
            except Exception as exc:  # not a valid Zenoh key expression (e.g. "/tf")
                self.skipped[key] = f"not a Zenoh key: {exc}"
        return pub

    def _batch_key(self, topic: str) -> str | None:
        if not self.batch:
            return None
        try:
            scenario, body, kind = messages.parse_key(topic)
        except messages.MessageError:
            return None
        process = _BATCH_PROCESS.get(kind)
        return None if process is None or body.startswith("@") else messages.batch_key(scenario, process)

    def _flush_batches(self) -> None:
        for key, items in self._pending.items():
            if items:
                bus.signed_put(self._publisher(key), key, messages.encode_batch(items), self.signer)
        self._pending.clear()
        self._pending_ns = None

    def _publish(self, msg: RawMessage) -> None:
        bkey = self._batch_key(msg.topic)
        if bkey is not None:
            if self._pending_ns is not None and msg.log_time != self._pending_ns:
                self._flush_batches()
            self._pending.setdefault(bkey, []).append((msg.topic, msg.data))
            self._pending_ns = msg.log_time
        else:
            if self._pending:
                self._flush_batches()
            pub = self._publisher(msg.topic)
            if pub is None:
                return
            bus.signed_put(pub, msg.topic, msg.data, self.signer)
        self.published += 1
        self.last_ns = msg.log_time

    def replayed_keys(self) -> list[str]:
        """The Zenoh keys this replay puts on, sorted: the recording's topics that ``--topics``
        selects (the channels known so far: all of them in a complete file, those of the
        chunks read in a cut one, the first message's at least), each replaced by its batch
        envelope's key under ``--batch``."""
        wanted = topic_matcher(self.topics)
        topics = [topic for topic in self.stream.topics() if wanted(topic)]
        if self._next is not None:
            topics.append(self._next.topic)
        return sorted({self._batch_key(topic) or topic for topic in topics})

    def wait_for_subscriber(self, timeout_s: float, keep_waiting: Callable[[], bool] = lambda: True) -> bool:
        """Wait up to ``timeout_s`` wall seconds until a subscriber matches any key the replay
        puts on (:meth:`replayed_keys`: a subscriber on ``astrodyn/<scenario>/<body>/orbit``,
        ``.../*/orbit``, ``.../**`` or ``.../@event`` alike); returns whether one came.  Each
        10 ms round declares the next :data:`WAIT_DECLARES_PER_ROUND` publishers (kept for
        the playback), reads up to :data:`WAIT_READS_PER_ROUND` matching statuses, round
        robin, then calls
        ``keep_waiting()`` (the owner's control verbs, signals and live view: a ``stop`` or
        SIGTERM must not wait for ``--wait``), which ends the wait when it returns False.
        Meanwhile :meth:`status` says ``"state": "waiting"`` (unless paused) and what for."""
        if self._next is None or timeout_s <= 0:
            return False
        keys = self.replayed_keys()
        self.waiting_keys = keys
        self.waiting_s = timeout_s
        self.waiting_until = deadline = time.monotonic() + timeout_s
        publishers: list = []
        declared = cursor = 0
        try:
            while time.monotonic() < deadline:
                for key in keys[declared:declared + WAIT_DECLARES_PER_ROUND]:
                    if (pub := self._publisher(key)) is not None:  # None: not a Zenoh key (skipped_topics)
                        publishers.append(pub)
                declared += WAIT_DECLARES_PER_ROUND
                for _ in range(min(WAIT_READS_PER_ROUND, len(publishers))):
                    if publishers[cursor].matching_status.matching:
                        return True
                    cursor = (cursor + 1) % len(publishers)
                if not keep_waiting():
                    return False
                time.sleep(0.01)
            return False
        finally:
            self.waiting_until = None
            self._anchor(self._anchor_ns)

    def step(self, budget_s: float = _POLL_S) -> bool:
        """Publish what is due within the next ``budget_s`` of wall time; False when done."""
        if self.state in ("stopped",):
            return False
        if not self.clock_started:  # playback begins: the clock runs from the anchor's log time, now
            self.clock_started = True
            self._anchor(self._anchor_ns)
        deadline = time.monotonic() + budget_s
        while self.state == "running" and self._next is not None:
            wait = self.wait_time()
            if wait > 0:
                remaining = deadline - time.monotonic()
                if wait > remaining:
                    time.sleep(max(0.0, remaining))
                    return True
                time.sleep(wait)
            msg = self._next
            self._publish(msg)
            self._next = next(self._iter, None)
            if self._next is None or self._next.log_time != msg.log_time:
                self._flush_batches()
            if time.monotonic() >= deadline:
                return True
        if self._next is None and self.state == "running":
            self._flush_batches()
            self.state = "finished"
        return self.state != "finished"

    # ------------------------------------------------------------------ control

    def status(self) -> dict:
        lo, hi = self.lo or 0, self.hi or 0
        # the last message published; right after a seek (nothing published yet) the seek's point
        now_ns = self.last_ns if self.last_ns is not None else getattr(self, "_anchor_ns", lo)
        span = max(hi - lo, 1)
        waiting = None
        if self.waiting_until is not None:
            shown = self.waiting_keys[:WAITING_KEYS_SHOWN]
            waiting = {"for": f"a subscriber to any of the {len(self.waiting_keys)} keys this replay puts on",
                       "keys": shown + ([f"... {len(self.waiting_keys) - len(shown)} more"]
                                        if len(self.waiting_keys) > len(shown) else []),
                       "wait_s": self.waiting_s,
                       "left_s": round(max(0.0, self.waiting_until - time.monotonic()), 3)}
        return {
            "file": self.stream.path,
            # "waiting": for a first subscriber (--wait; a pause asked meanwhile says "paused")
            "state": "waiting" if waiting is not None and self.state == "running" else self.state,
            "waiting": waiting,
            "real_time_factor": "inf" if math.isinf(self.rate) else self.rate,
            "t": self.stream.ns_to_t(now_ns),
            "t_start": self.stream.ns_to_t(lo),
            "t_end": self.stream.ns_to_t(hi),
            "progress": round(min(1.0, max(0.0, (now_ns - lo) / span)), 6),
            "messages": self.published,
            "wall_s": round(time.monotonic() - self.started, 3),
            "complete": not self.stream.truncated and not self.stream.corrupt_chunks,
            "file_report": self.stream.report(),
            "skipped_topics": dict(self.skipped),
        }

    def pause(self) -> None:
        if self.state == "running":
            v = self.virtual_ns()
            self._flush_batches()
            self.state = "paused"
            self._anchor(int(v) if math.isfinite(v) else (self.last_ns or self._anchor_ns))

    def resume(self) -> None:
        if self.state == "paused":
            self.state = "running"
            self._anchor(self._anchor_ns)

    def set_rate(self, factor: float) -> None:
        v = self.virtual_ns()
        self.rate = parse_rate(factor)
        self._anchor(int(v) if math.isfinite(v) else (self.last_ns or self._anchor_ns))

    def seek(self, t: Any) -> None:
        """Go on from ``t`` (s since the scenario epoch) within the replayed range, ``t_start``
        <= t <= ``t_end`` of :meth:`status` (the recording's, or narrowed by ``--start`` /
        ``--end``); ValueError naming the verb, the value and the range otherwise (a seek
        before the start used to be moved to the start without a word).  A ``t`` within the
        range is taken to the nanosecond, kept inside it (a ``t_end`` sent back as the status
        gave it can be a nanosecond past the last log time once rounded)."""
        ns = self.stream.t_to_ns(t, "seek.t")
        if self.lo is not None and self.hi is not None:
            t_lo, t_hi = self.stream.ns_to_t(self.lo), self.stream.ns_to_t(self.hi)
            if not t_lo <= t <= t_hi:
                raise ValueError(f"seek.t: expected a time within the replayed range, {t_lo} <= t <= {t_hi} s since "
                                 f"the scenario epoch (the recording's, or --start/--end), got {t!r}")
            ns = min(max(ns, self.lo), self.hi)
        paused = self.state == "paused"
        self.state = "running"
        self.last_ns = None
        self._seek(ns)
        if paused:
            self.state = "paused"

    def handle(self, request: bus.ControlRequest) -> bool:
        """Answer one control request; True when it was ``stop`` (answered by the caller)."""
        verb = request.verb
        try:
            if verb == "status":
                pass
            elif verb == "pause":
                self.pause()
            elif verb == "resume":
                self.resume()
            elif verb == "rate":
                self.set_rate(parse_rate(request.args.get("factor"), 'rate: {"factor": x}'))
            elif verb == "seek":
                if "t" not in request.args:
                    raise ValueError('seek: expected {"t": T} with T in s since the scenario epoch')
                self.seek(request.args["t"])
            elif verb == "stop":
                self._flush_batches()
                self.state = "stopped"
                return True
            else:
                raise ValueError(f"{verb}: expected one of {', '.join(REPLAY_VERBS)}")
        except (ValueError, TypeError, RecordingError) as exc:
            request.error(str(exc))
            return False
        request.reply(self.status())
        return False

    def close(self) -> None:
        for pub in self._publishers.values():
            pub.undeclare()
        self._publishers.clear()


def _progress_line(rep: Replayer) -> str:
    s = rep.status()
    return (f"replay t {s['t']:10.1f} / {s['t_end']:.1f} s ({100 * s['progress']:5.1f} %)  "
            f"{s['messages']} messages  {s['state']}  x{s['real_time_factor']}")


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="astrodyn replay", description="Republish a recorded MCAP file on Zenoh.")
    ap.add_argument("file", help="MCAP file recorded by astrodyn (or any MCAP whose topics are Zenoh keys)")
    ap.add_argument("--rate", type=bus.rate_argument, default=1.0,
                    help='real-time factor (default 1; "inf" = as fast as possible)')
    ap.add_argument("--start", type=float, default=None, help="start at this t (s since the scenario epoch)")
    ap.add_argument("--end", type=float, default=None, help="end at this t (s since the scenario epoch, inclusive)")
    ap.add_argument("--topics", action="append", default=None, metavar="GLOB", help="only topics matching (repeatable)")
    ap.add_argument("--batch", action="store_true", help="send states as batch envelopes on @batch/<process> like the propagators")
    ap.add_argument("--wait", type=float, default=5.0,
                    help="wait up to this many wall s (at most a day) for a subscriber to any key the replay "
                         "publishes before starting (default 5)")
    ap.add_argument("--hold", action="store_true", help="after the end, keep answering control queries until stop")
    ap.add_argument("--control-scenario", default=None, help="scenario name of the control keys (default: the recorded one)")
    ap.add_argument("--port", type=int, default=None, help="loopback port to listen on (default: a free one)")
    ap.add_argument("--quiet", action="store_true", help="no progress line")
    ap.add_argument("--open-control", action="store_true",
                    help="answer control verbs from anyone who reaches the bus (default: only with the control token "
                         "printed at start and stored in a 0600 file; docs/security.md)")
    add_foxglove_argument(ap, "the replay")
    ap.add_argument("--foxglove-playback", action="store_true",
                    help="with --foxglove: wire Foxglove's playback bar (play, pause, speed, seek) to this replay; "
                         "the viewer then holds the control token, so any local process that reaches the WebSocket "
                         "port can steer the replay (never the recording; docs/foxglove.md)")
    bus.add_bus_arguments(ap)
    return ap


def open_recording(args: argparse.Namespace) -> tuple[float, McapStream]:
    """The replay rate and the stream of ``args.file``; ValueError for a bad flag,
    RecordingError for a file with nothing to replay."""
    rate = args.rate
    if not 0 <= args.wait <= MAX_WAIT_S:  # nan fails too
        raise ValueError(f"--wait: expected wall seconds 0 <= S <= {MAX_WAIT_S:g} (a day), got {args.wait}")
    if args.control_scenario is not None:
        try:
            check_control_scenario(args.control_scenario, args.file, given=True)
        except messages.MessageError as exc:
            raise ValueError(str(exc)) from None
    if args.port is not None and (problem := bus.local_port_problem(args.port)):
        raise ValueError(f"--port: {problem}")
    for name in ("start", "end"):
        value = getattr(args, name)
        if value is not None and not math.isfinite(value):
            raise ValueError(f"--{name}: expected a finite number of seconds, got {value}")
    stream = McapStream(args.file)
    if not stream.chunks:
        stream.close()
        raise RecordingError(f"{stream.path}: nothing to replay ({stream.truncation if stream.truncated else 'no messages'})")
    if args.topics is not None:
        try:
            wanted = topic_matcher(args.topics)
        except ValueError as exc:
            stream.close()
            raise ValueError(f"--{exc}") from None
        if not any(wanted(topic) for topic in stream.topics()):
            stream.close()
            raise ValueError(f"--topics {' '.join(args.topics)[:200]!r}: matches no topic of {stream.path} (shell-style "
                             f"globs, * matches across /, e.g. 'astrodyn/demo/*/orbit')")
    return rate, stream


#: Longest ``--wait`` for a first subscriber, wall seconds (a day).
MAX_WAIT_S = 86400.0


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.foxglove_playback and args.foxglove is None:
        print("astrodyn replay: error: --foxglove-playback: expected --foxglove PORT as well (the bar is the "
              "view's)", file=sys.stderr)
        return 2
    try:  # read once: the session and the live view (restarts too) get the replay's private copy
        zenoh_config = None if args.zenoh_config is None else \
            bus.read_zenoh_config(args.zenoh_config, shared=args.foxglove is not None)
        rate, stream = open_recording(args)
    except (ValueError, RecordingError, bus.BusError) as exc:
        print(f"astrodyn replay: error: {exc}", file=sys.stderr)
        return 1 if isinstance(exc, RecordingError) else 2
    if zenoh_config is not None and (warning := zenoh_config.warning()):
        print(f"astrodyn replay: warning: {warning}", file=sys.stderr)
    listen = args.listen
    if listen is None and args.mode != "client":
        listen = [bus.loopback_endpoint(args.port or None)]  # 0: a free one, named in the hello line
    stop_signal = StopFlag()
    JobControl()  # Ctrl-Z stops the replay with its viewer; the pacing leaves the pause out
    printer = Progress(enabled=not args.quiet)
    with stream, tempfile.TemporaryDirectory(prefix="astrodyn-replay-") as work:  # private: the token, the copies
        token_dir = Path(work)
        try:
            scenario = args.control_scenario or scenario_of(stream)
            check_control_scenario(scenario, stream.path, given=args.control_scenario is not None)
            zenoh_config_copy = zenoh_config_snapshot(zenoh_config, token_dir)
            session = bus.open_session(listen=listen, connect=args.connect, mode=args.mode,
                                       config_file=zenoh_config_copy)
        except (RecordingError, messages.MessageError, bus.BusError, StartError) as exc:
            print(f"astrodyn replay: error: {exc}", file=sys.stderr)
            return 1
        # the live view trusts only what this replay signed (a local process can put on its bus):
        # a secret of this replay, handed to the view the way serve hands the run secret
        view_secret = None if args.foxglove is None else auth.RunSecret.generate()
        with session:
            try:
                rep = Replayer(session, stream, rate=rate, start_t=args.start, end_t=args.end,
                               topics=args.topics, batch=args.batch,
                               signer=None if view_secret is None else auth.Signer(view_secret, "replay"))
            except (ValueError, RecordingError) as exc:
                print(f"astrodyn replay: error: {exc}", file=sys.stderr)
                return 2
            if stream.truncated or stream.corrupt_chunks:
                print(f"astrodyn replay: warning: {stream.path}: {stream.report()}", file=sys.stderr, flush=True)
            token, viewer = None, None
            try:
                if not args.open_control:
                    token = auth.new_token()
                    auth.write_private_file(token_dir / "control-token", token.encode())
                viewer_url = None
                if args.foxglove is not None:  # the live view: a child process that subscribes to what we publish
                    port = args.foxglove or bus.free_port()
                    playback = None
                    if args.foxglove_playback:
                        if token is None:  # --open-control: the verbs need no token; the viewer sends an empty one
                            auth.write_private_file(token_dir / "control-token", b"")
                        playback = (token_dir / "control-token", rep.lo, rep.hi)
                    endpoints = listen or args.connect or []
                    data_scenario = data_scenario_of(stream, scenario_of(stream))
                    secret_file = view_secret.save(token_dir, "view.secret")
                    viewer = LiveView(lambda: start_viewer(stream, data_scenario, port, endpoints, token_dir, playback,
                                                           zenoh_config_copy, control_scenario=scenario,
                                                           secret_file=secret_file))
                    viewer_url = f"ws://127.0.0.1:{port}"
                # the verbs are answered from the first line on: a client that reads it and asks
                # for status at once gets an answer (before: the queryable came after the line)
                with bus.ControlServer(session, scenario, verbs=REPLAY_VERBS, token=token) as control:
                    print(json.dumps({"replaying": stream.path, "scenario": scenario, "listen": listen,
                                      "connect": args.connect, "foxglove": viewer_url,
                                      "control": f"astrodyn/{scenario}/@control/<verb>", "verbs": list(REPLAY_VERBS),
                                      "real_time_factor": "inf" if math.isinf(rate) else rate,  # as status says it
                                      "control_token": token,
                                      "control_token_file": None if token is None else str(token_dir / "control-token")}),
                          flush=True)
                    summary = play(rep, control, args, printer, stop_signal, viewer)
            finally:
                rep.close()
                if viewer is not None:
                    viewer.close()
    printer.done(_progress_line(rep))
    if not args.quiet and not summary["complete"]:
        print(f"astrodyn replay: {stream.path} is incomplete ({summary['file_report']}); "
              f"replayed the {rep.published} complete messages", file=sys.stderr)
    print(json.dumps(summary), flush=True)
    return 0


def start_viewer(stream: McapStream, scenario: str, port: int, endpoints: list[str], work: Path,
                 playback: tuple[Path, int, int] | None = None, zenoh_config: Path | None = None,
                 control_scenario: str | None = None, secret_file: Path | None = None) -> Child:
    """The live view (``--foxglove``): a child process subscribing to what the replay publishes
    on the data keys of ``scenario`` (the recorded one, :func:`data_scenario_of`), its
    services and playback bar on the control keys of ``control_scenario`` (default
    ``scenario``); ``playback`` = (token file, first ns, last ns) wires Foxglove's playback
    bar to the replay; ``zenoh_config``: the replay's copy of its ``--zenoh-config`` (TLS,
    access control), the viewer's too (a restarted viewer loads that copy, not the user's
    file as it is by then); ``secret_file``: the replay's secret (0600) the view checks
    every sample against (:data:`astrodyn.auth.SECRET_ENV`), so it drops what another
    process put on the replay's bus."""
    meta = work / "scenario.json"
    meta.write_text(json.dumps(stream.metadata.get("scenario", {})))
    bar = [] if playback is None else ["--playback-token-file", str(playback[0]),
                                       "--playback-range", f"{playback[1]},{playback[2]}"]
    return Child("viewer", [*viewer_command(), "--scenario", scenario, "--port", str(port), "--metadata", str(meta),
                            *(["--control-scenario", control_scenario] if control_scenario else []),
                            "--services", ",".join(REPLAY_VERBS), *bar, *sum((["--connect", e] for e in endpoints), []),
                            *(["--zenoh-config", str(zenoh_config)] if zenoh_config else [])],
                 work, env=None if secret_file is None else {auth.SECRET_ENV: str(secret_file)})


class LiveView:
    """The replay's live view (``--foxglove``): the viewer child started by ``start`` (a
    callable returning a :class:`Child`), watched by :meth:`check` and started again on
    its port when it dies, within a :class:`RestartBudget` (as ``serve`` does); past the
    budget the replay goes on without it and says so once.  The recording is never at
    stake: the view only reads what the replay publishes."""

    def __init__(self, start):
        self.start = start
        self.child: Child | None = start()
        self.budget = RestartBudget("viewer")
        self._next_check = 0.0

    def check(self, now: float | None = None) -> None:
        """Every half second at most: restart a dead viewer (or give up on it, once)."""
        now = time.monotonic() if now is None else now
        if self.child is None or now < self._next_check:
            return
        self._next_check = now + 0.5
        rc = self.child.poll()
        if rc is None:
            return
        old = self.child
        why = f"the live view (pid {old.pid}) {old.how(rc)}: {old.last_words(2)}"
        old.close()
        if self.budget.allow(now):
            self.child = self.start()
            print(f"astrodyn replay: {why}; restarted it (pid {self.child.pid})", file=sys.stderr, flush=True)
        else:
            self.child = None
            print(f"astrodyn replay: warning: {why}; {self.budget.refusal(recording=False)}; the replay goes on without it",
                  file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.child is not None:
            self.child.stop()
            self.child.close()
            self.child = None


def play(rep: Replayer, control: bus.ControlServer, args: argparse.Namespace,
         printer: Progress, stop_signal: StopFlag, view: LiveView | None = None) -> dict:
    """Publish until the end (or ``stop``, or a signal), answering the verbs that come to
    ``control`` on the way (and keeping the live ``view`` up); the final status, also the
    reply to each ``stop``."""
    stop_requests: list[bus.ControlRequest] = []

    def keep_up() -> bool:
        """Answer the control verbs and keep the live view up; False once told to stop."""
        for req in control.poll():
            if req.handled_by(rep.handle):
                stop_requests.append(req)
        if view is not None:
            view.check()
        return rep.state != "stopped" and not stop_signal.why

    def keep_waiting() -> bool:
        """keep_up, and the progress line (which says "waiting") while no one subscribes."""
        printer.show(lambda: _progress_line(rep))
        return keep_up()

    rep.wait_for_subscriber(args.wait, keep_waiting)
    while True:
        if not keep_up():
            break
        more = rep.step()
        if not more and rep.state == "finished" and not args.hold:
            break
        if rep.state != "running":
            time.sleep(_POLL_S)
        printer.show(lambda: _progress_line(rep))
    rep._flush_batches()
    if stop_signal.why:
        rep.state = "stopped"
    summary = rep.status()
    if not rep.stream.truncated and not rep.stream.corrupt_chunks:
        summary["file_report"] = "complete"
    for req in stop_requests:
        req.reply(summary)
    time.sleep(0.05)  # let the last puts and replies leave before the session closes
    return summary
