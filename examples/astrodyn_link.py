"""A controller's link to an astrodyn closed loop, in plain Python: zenoh, json, hmac.

No astrodyn import: this is the whole client side of docs/control.md, which the example
controllers in this directory share.  Use it as a starting point for your own::

    with Link() as link:               # from the environment `astrodyn run --controller` sets
        while (tick := link.wait_tick()) is not None:
            gyro = link.latest("sc", "gyro")               # the step's sample of a key, a dict
            link.command("sc", tick["t"], wheel_torque=[0.01, 0.0, 0.0])
            link.done(tick)            # answer the control step (lockstep)

Environment (set by ``astrodyn run/serve ... --controller CMD``):
``ASTRODYN_CONNECT`` the run's bus endpoint, ``ASTRODYN_SCENARIO``, ``ASTRODYN_CONTROLLER``
(this controller's name), and ``ASTRODYN_RUN_SECRET_FILE`` (the run secret: commands are
signed with it).  An outside controller started by hand passes ``connect``, ``scenario``
and ``name`` (or sets the same variables) and the run's control token file instead
(``ASTRODYN_CONTROL_TOKEN_FILE``): it presents the token with its commands and checks the
plant's ticks with it.

Started by hand, the link checks what it is given before it waits (a mistyped endpoint made
it wait for ever: Zenoh accepts it and never connects): ``ASTRODYN_CONNECT`` must be a Zenoh
endpoint, ``PROTOCOL/HOST:PORT`` as the run's ``bus`` line prints it (e.g.
``tcp/127.0.0.1:7447``, without the ``:`` that ends that line), and with the control
token only (not under ``--controller``) the first tick must come within
:data:`FIRST_TICK_TIMEOUT_S` of connecting (``ASTRODYN_FIRST_TICK_TIMEOUT``, seconds; 0
waits for ever): a wrong endpoint or scenario, or a run that has ended, is then one line
on stderr and exit status 1 (:class:`LinkError`), not a controller waiting for ever.
Under ``run`` / ``serve --controller`` (the run secret) the link waits as long as the
plant does: the supervisor ends the controller with the run.

What the link believes (docs/control.md, "Trusting what you read"): any local process can
put on the run's keys, so every sample is checked before the controller sees it.  A tick
must be signed by the run's plant, with a counter above the last one seen (no replays) and a
``seq`` above the last tick's; the end of the run is the plant's signed ``stop`` event.  With
the run secret that is the plant's ``ADA1`` authenticator (HMAC-SHA256 of the run secret,
docs/control.md, "Authentication"), and a sample on another key must be signed by one of the
run's processes.  With only the control token it is the plant's ``ADP1`` part (HMAC-SHA256
with a key derived from the token), and the link reads nothing but ticks and the plant's
events: the tick carries the step's states and sensor samples, and samples on other keys
cannot be authenticated with the token.  Either way a sample larger than ``max_payload``
bytes, not JSON, not an object, or whose numbers are not finite, is dropped.  Dropped
samples are counted per reason (``link.dropped``); the first is reported on stderr in one
line and the counts when the link closes, never one line per sample, and the controller
never sees them.  In lockstep the plant puts the current tick again every 0.5 s while it
waits for the answers (for a controller that joined late): a signed tick with the last
tick's ``seq`` is such a copy, ignored without a word (``link.repeats`` counts them).
"""

from __future__ import annotations

import hashlib
import hmac
import json
import os
import queue
import re
import struct
import sys
import threading
import time

import zenoh

#: Largest sample the link reads, bytes (larger ones are dropped unread).  A tick holds every
#: state and sensor sample of its step, ~150-300 bytes each: raise it for scenes of more than
#: ~50,000 of them.
MAX_PAYLOAD = 16 * 1024 * 1024
#: Ticks waiting for the controller before new ones are dropped (the plant sends one per
#: control step; in lockstep it waits for the answer, so one is waiting at a time).
MAX_WAITING_TICKS = 1024
#: The numeric fields a controller reads from the messages of each kind (docs/control.md,
#: "Keys and messages"): each must be a finite number or a non-empty list of them.
NUMERIC_FIELDS = {
    "orbit": ("t", "r", "v", "mu"),
    "attitude": ("t", "q", "w"),
    "gyro": ("t", "w"),
    "star_tracker": ("t", "q"),
    "gps": ("t", "r", "v"),
    "tachometer": ("t", "speeds"),
    "actuators": ("t", "torque"),
}
#: Longest list of numbers a message may hold (wheels, modal coordinates, ...).
MAX_VECTOR = 4096
_MAC_BYTES = 32  # HMAC-SHA256
#: The plant's part for control-token holders: b"ADP1", counter (u64 little-endian), MAC.
_PART_BYTES = 4 + 8 + _MAC_BYTES
#: The plant's key for token holders is HMAC-SHA256(token, this label) (docs/control.md).
_PLANT_KEY_LABEL = b"ADP1 plant tick v1"
#: Wall seconds a controller started by hand (the control token, not ``--controller``) waits
#: for its first tick before it gives up (:class:`LinkError`); ``ASTRODYN_FIRST_TICK_TIMEOUT``
#: overrides it, 0 waits for ever.  In lockstep the plant repeats its tick every 0.5 s, in
#: free mode it ticks every control period of sim time: raise it for a long period at a slow rate.
FIRST_TICK_TIMEOUT_S = 60.0
#: The largest ``seq`` a message may carry (2**53 - 1: exact in every JSON reader's doubles).
MAX_SEQ = 2**53 - 1
#: The protocols of a Zenoh endpoint ``PROTOCOL/HOST:PORT`` (plus ``unixsock-stream/PATH``).
ENDPOINT_PROTOCOLS = ("tcp", "udp", "tls", "quic", "ws")


class LinkError(SystemExit):
    """The link cannot work: a malformed endpoint, no first tick in time (module docstring).
    A :class:`SystemExit` with the reason: uncaught, the process ends with that one line on
    stderr and exit status 1, no traceback."""


def endpoint_problem(endpoint) -> str | None:
    """Why ``endpoint`` is not a Zenoh endpoint -- ``PROTOCOL/HOST:PORT[?metadata][#config]``
    with PROTOCOL one of :data:`ENDPOINT_PROTOCOLS`, HOST an IPv4 address, ``[IPv6]`` or a
    host name, PORT 1..65535, or ``unixsock-stream/PATH`` -- or None when it is (the rules of
    astrodyn's own check, ``astrodyn.bus.endpoint_problem``, which this file does not import)."""
    if not isinstance(endpoint, str) or not endpoint:
        return "empty"
    protocol, slash, rest = endpoint.partition("/")
    if not slash:
        return "no PROTOCOL/ before the address"
    address = re.split(r"[?#]", rest, maxsplit=1)[0]
    if protocol == "unixsock-stream":
        return None if address and "\0" not in address else "no socket path after unixsock-stream/"
    if protocol not in ENDPOINT_PROTOCOLS:
        return f"protocol {protocol[:40]!r} is not one of {', '.join(ENDPOINT_PROTOCOLS)}, unixsock-stream"
    host, colon, port = address.rpartition(":")
    if not colon or not host:
        return "expected HOST:PORT after the protocol"
    if not (port.isascii() and port.isdigit()):
        hint = " (the ':' that ends the run's `bus tcp/...:` line is not part of the endpoint)" if not port else ""
        return f"port {port[:20]!r} is not an integer{hint}"
    if len(port) > 5 or not 1 <= int(port) <= 65535:
        return f"port {port[:20]} is not in 1..65535"
    if ":" in host and not (host.startswith("[") and host.endswith("]")):
        return f"host {host[:60]!r}: an IPv6 address goes in brackets, [::1]"
    return None


def first_tick_timeout(text: str | None) -> float | None:
    """Wall seconds to wait for the first tick from ``ASTRODYN_FIRST_TICK_TIMEOUT`` (None:
    :data:`FIRST_TICK_TIMEOUT_S`); None for 0 (wait for ever); :class:`LinkError` for
    anything but a number >= 0."""
    if text is None or not text.strip():
        return FIRST_TICK_TIMEOUT_S
    try:
        seconds = float(text)
    except ValueError:
        seconds = float("nan")
    if not 0 <= seconds < float("inf"):
        raise LinkError(f"astrodyn_link: ASTRODYN_FIRST_TICK_TIMEOUT: expected wall seconds >= 0 (0: wait for "
                        f"ever), got {text[:40]!r}")
    return seconds or None


def finite_number(x) -> bool:
    """A JSON number that is a finite float64: not a bool, NaN, an infinity, or an integer
    beyond the float range (``json`` reads ``1e999`` as inf and keeps 400-digit integers)."""
    return type(x) in (int, float) and abs(x) <= sys.float_info.max


def numbers_problem(message: dict, kind: str) -> str | None:
    """Why ``message`` (a JSON object on a ``<body>/<kind>`` key) does not hold the numbers
    a controller reads from it (:data:`NUMERIC_FIELDS`; ``t`` for every kind), else None."""
    for field in NUMERIC_FIELDS.get(kind, ("t",)):
        value = message.get(field)
        if isinstance(value, list):
            if not 0 < len(value) <= MAX_VECTOR or not all(finite_number(x) for x in value):
                return f"{kind}.{field}: expected 1..{MAX_VECTOR} finite numbers"
        elif not finite_number(value):
            return f"{kind}.{field}: expected a finite number"
    return None


class Dropped(Exception):
    """A sample the link does not pass on; ``reason`` is the count's name, ``detail`` why."""

    def __init__(self, reason: str, detail: str = ""):
        super().__init__(reason)
        self.reason, self.detail = reason, detail


class Link:
    def __init__(self, connect: str | None = None, scenario: str | None = None, name: str | None = None,
                 max_payload: int = MAX_PAYLOAD):
        env = os.environ
        self.scenario = scenario or env["ASTRODYN_SCENARIO"]
        self.name = name or env["ASTRODYN_CONTROLLER"]
        endpoint = connect or env["ASTRODYN_CONNECT"]
        problem = endpoint_problem(endpoint)
        if problem is not None:  # Zenoh would take it and never connect: the controller would wait for ever
            raise LinkError(f"astrodyn_link: {'connect' if connect else 'ASTRODYN_CONNECT'}: expected a Zenoh "
                            f"endpoint like 'tcp/127.0.0.1:7447', got {endpoint[:200]!r}: {problem}")
        self.endpoint = endpoint
        self.base = f"astrodyn/{self.scenario}"
        self.max_payload = int(max_payload)
        self._secret = None
        self._token = self._plant_key = None
        if env.get("ASTRODYN_RUN_SECRET_FILE"):
            with open(env["ASTRODYN_RUN_SECRET_FILE"], "rb") as fh:
                self._secret = fh.read()
        elif env.get("ASTRODYN_CONTROL_TOKEN_FILE"):
            with open(env["ASTRODYN_CONTROL_TOKEN_FILE"], "rb") as fh:
                self._token = fh.read().strip()
            self._plant_key = hmac.new(self._token, _PLANT_KEY_LABEL, hashlib.sha256).digest()
        else:
            raise ValueError("astrodyn_link: expected ASTRODYN_RUN_SECRET_FILE (started by --controller) or "
                             "ASTRODYN_CONTROL_TOKEN_FILE (an outside controller; docs/control.md)")
        # by hand (the token only), the first tick must come in time; under --controller the supervisor decides
        self.first_tick_timeout = None if self._secret else first_tick_timeout(env.get("ASTRODYN_FIRST_TICK_TIMEOUT"))
        self._instance = os.urandom(8)
        self._counters: dict[str, int] = {}
        self._seq: dict[str, int] = {}  # per body: this controller's next command seq (docs/control.md, Commands)
        self._sent = 0  # commands sent since the last answer
        self._latest: dict[str, dict] = {}
        self._ticks: queue.Queue = queue.Queue()
        self._tick_seq = -1  # seq of the last tick let through (ticks must come in increasing seq)
        self.repeats = 0  # the plant's copies of a tick already let through (it repeats the tick while it waits)
        self._answerable: dict | None = None  # the tick wait_tick returned last, until answered
        self._seen: dict[tuple[bytes, str], int] = {}  # (signer instance, key) -> last counter verified
        self.dropped: dict[str, int] = {}  # reason -> samples dropped
        self._dropped_lock = threading.Lock()
        conf = zenoh.Config()
        conf.insert_json5("mode", '"peer"')  # a peer on loopback: the plant's samples come straight, not via the hub
        conf.insert_json5("listen/endpoints", '["tcp/127.0.0.1:0"]')
        conf.insert_json5("scouting/gossip/enabled", "true")
        conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
        conf.insert_json5("scouting/multicast/enabled", "false")
        self.session = zenoh.open(conf)
        self._first_tick_deadline = None if self.first_tick_timeout is None else \
            time.monotonic() + self.first_tick_timeout
        # with the token only, the ticks (which carry the step's samples) and the plant's events:
        # nothing else can be authenticated with it
        self._subs = [self.session.declare_subscriber(f"{self.base}/**", self._on_sample)] if self._secret else []
        self._subs += [
            self.session.declare_subscriber(f"{self.base}/@tick", self._on_tick),
            self.session.declare_subscriber(f"{self.base}/@event", self._on_event),
        ]

    # -- checking what arrives -------------------------------------------------------
    def _drop(self, key: str, exc: Dropped) -> None:
        with self._dropped_lock:
            first = not self.dropped
            self.dropped[exc.reason] = self.dropped.get(exc.reason, 0) + 1
        if first:  # one line, not one per sample: a flood is counted, reported at close()
            print(f"astrodyn_link: dropped a sample on {key[:200]!r}: {exc.reason}"
                  f"{': ' + exc.detail[:200] if exc.detail else ''} (further ones are counted, reported at the end)",
                  file=sys.stderr, flush=True)

    def _signer(self, key: str, payload: bytes, attachment) -> str:
        """The run process that signed this sample (docs/control.md, "Authentication"): with
        the run secret its ADA1 authenticator, with the token only the plant's ADP1 part;
        :class:`Dropped` if it does not verify or is a replay."""
        a = b"" if attachment is None else attachment.to_bytes()
        if self._secret is None:  # the plant's part for token holders: the attachment's last 44 bytes
            part = a[-_PART_BYTES:]
            if len(part) != _PART_BYTES or part[:4] != b"ADP1":
                raise Dropped("unsigned", "no plant authenticator for the control token")
            header, mac, secret, signer = part[:12], part[12:], self._plant_key, "plant"
        else:
            n = a[4] if a[:4] == b"ADA1" and len(a) > 4 else 0
            end = 5 + n + 8 + 8 + _MAC_BYTES  # the ADA1 authenticator; a plant's tick or event has its ADP1 part after it
            if not n or (len(a) != end and (len(a) != end + _PART_BYTES or a[end:end + 4] != b"ADP1")):
                raise Dropped("unsigned", "no authenticator of the run")
            # magic, name length, name, instance (8), counter (u64 little-endian); then the MAC
            header, mac, secret, signer = a[:end - _MAC_BYTES], a[end - _MAC_BYTES:end], self._secret, None
        expected = hmac.new(secret, header + key.encode() + b"\0" + payload, hashlib.sha256).digest()
        if not hmac.compare_digest(mac, expected):
            raise Dropped("bad-mac", "not signed by the run's processes, or altered")
        (counter,) = struct.unpack("<Q", header[-8:])
        signer_key = (header[:-8], key)
        if counter <= self._seen.get(signer_key, 0):
            raise Dropped("replay", f"counter {counter} after {self._seen[signer_key]}")
        self._seen[signer_key] = counter
        return signer or header[5:-16].decode("utf-8", "replace")

    def _read(self, sample) -> tuple[str, str, dict]:
        """``(key, signer, message)`` of a sample: at most ``max_payload`` bytes, signed by a
        run process (with the token only: by the plant), a JSON object; :class:`Dropped`
        otherwise."""
        key = str(sample.key_expr)
        if len(sample.payload) > self.max_payload:
            raise Dropped("too-large", f"{len(sample.payload)} bytes, more than {self.max_payload}")
        payload = sample.payload.to_bytes()
        signer = self._signer(key, payload, sample.attachment)
        try:
            message = json.loads(payload)
        except (ValueError, RecursionError) as exc:  # not UTF-8, not JSON, nested too deep
            raise Dropped("not-json", type(exc).__name__) from None
        if not isinstance(message, dict):
            raise Dropped("malformed", f"expected a JSON object, got {type(message).__name__}")
        return key, signer, message

    def _checked_tick(self, sample) -> dict | None:
        """The tick of ``sample``, checked; None for the plant's copy of the last tick."""
        key, signer, tick = self._read(sample)
        if signer != "plant":
            raise Dropped("wrong-signer", f"a tick signed by {signer!r}, not by the plant")
        seq, step, samples = tick.get("seq"), tick.get("step"), tick.get("samples")
        if not (finite_number(tick.get("t")) and type(seq) is int and type(step) is int and 0 <= seq <= 2**53
                and isinstance(samples, dict)):
            raise Dropped("malformed", "expected a tick: t, seq, step numbers and samples {body/kind: message}")
        if seq == self._tick_seq:  # the plant's copy of the tick it waits on (signed, fresh counter)
            self.repeats += 1
            return None
        if seq < self._tick_seq:
            raise Dropped("old-tick", f"tick {seq} after tick {self._tick_seq}")
        for name, message in samples.items():
            problem = "not a message object" if not isinstance(message, dict) else \
                numbers_problem(message, name.rsplit("/", 1)[-1])
            if problem:
                raise Dropped("malformed", f"tick sample {name[:100]!r}: {problem}")
        self._tick_seq = seq
        return tick

    # -- receiving ------------------------------------------------------------------
    def _on_sample(self, sample) -> None:  # free mode: the newest sample of each key
        try:
            key, _, message = self._read(sample)
            problem = numbers_problem(message, key.rsplit("/", 1)[-1])
            if problem:
                raise Dropped("malformed", problem)
        except Dropped as exc:
            self._drop(str(sample.key_expr), exc)
            return
        if key not in self._latest or message["t"] >= self._latest[key]["t"]:
            self._latest[key] = message

    def _on_tick(self, sample) -> None:
        try:
            tick = self._checked_tick(sample)
            if tick is None:
                return
            if self._ticks.qsize() >= MAX_WAITING_TICKS:
                raise Dropped("backlog", f"{MAX_WAITING_TICKS} ticks already wait for the controller")
        except Dropped as exc:
            self._drop(str(sample.key_expr), exc)
            return
        self._ticks.put(tick)

    def _take(self, tick: dict | None) -> dict | None:
        # the tick carries the step's states and sensor samples: read them from it, since
        # samples on other keys may still be on their way (each subscriber has its thread)
        if tick is not None:
            for key, message in tick["samples"].items():
                self._latest[f"{self.base}/{key}"] = message
        self._answerable = tick
        return tick

    def _on_event(self, sample) -> None:
        a = sample.attachment
        if self._secret is None and (a is None or a.to_bytes()[-_PART_BYTES:-_MAC_BYTES - 8] != b"ADP1"):
            return  # with the token only: the other processes' events, which it can neither check nor needs
        try:
            _, signer, event = self._read(sample)
        except Dropped as exc:
            self._drop(str(sample.key_expr), exc)
            return
        # the end of the run: the plant's own stop event (other processes' events are theirs)
        if signer == "plant" and event.get("process") == "plant" and event.get("kind") == "stop":
            self._ticks.put(None)

    def wait_tick(self, timeout: float | None = None) -> dict | None:
        """The next control step ``{"t", "seq", "step", "samples"}`` (checked: see the module
        docstring), or None when the run has ended.  ``timeout`` (wall s): :class:`queue.Empty`
        when none came by then.  Without it, a controller started by hand gives up with
        :class:`LinkError` when its first tick has not come within :attr:`first_tick_timeout`
        s of connecting."""
        if timeout is None and self._first_tick_deadline is not None and self._tick_seq < 0:
            try:
                return self._take(self._ticks.get(timeout=max(0.0, self._first_tick_deadline - time.monotonic())))
            except queue.Empty:
                raise LinkError(
                    f"astrodyn_link: no tick from the plant of scenario {self.scenario!r} at {self.endpoint} within "
                    f"{self.first_tick_timeout:g} s of connecting: is that the run's `bus` endpoint and scenario, and "
                    f"is the run still going? (ASTRODYN_FIRST_TICK_TIMEOUT=S to wait longer, 0 for ever)") from None
        return self._take(self._ticks.get(timeout=timeout))

    def latest(self, body: str, kind: str) -> dict | None:
        """The newest message on ``astrodyn/<scenario>/<body>/<kind>`` (e.g. "attitude",
        "orbit", "gyro", "star_tracker", "gps", "tachometer", "actuators"); with the control
        token only, the newest of those the ticks carry (states and sensor samples)."""
        return self._latest.get(f"{self.base}/{body}/{kind}")

    # -- sending --------------------------------------------------------------------
    def _attachment(self, key: str, payload: bytes) -> bytes:
        if self._secret is None:
            return b"ADT1" + self._token  # the run's control token (outside controller)
        n = self._counters.get(key, 0) + 1
        self._counters[key] = n
        name = self.name.encode()
        header = b"ADA1" + bytes([len(name)]) + name + self._instance + struct.pack("<Q", n)
        mac = hmac.new(self._secret, header + key.encode() + b"\0" + payload, hashlib.sha256).digest()
        return header + mac

    def _put(self, key: str, message: dict) -> None:
        payload = json.dumps(message, separators=(",", ":")).encode()
        self.session.put(key, payload, attachment=self._attachment(key, payload),
                         congestion_control=zenoh.CongestionControl.BLOCK)

    def command(self, body: str, t: float, **fields) -> None:
        """Command ``body`` from sim time ``t`` (s): any of torque=[3] N m (body axes),
        wheel_torque=[n] N m, dv=[3] m/s (inertial), thrust=[3] N with frame="inertial"|"body"."""
        seq = self._seq.get(body)
        if seq is None:  # where this sender's commands to the body stopped, if it ran before (a restart)
            seq = self.recorded_next_seq(body)
        self._seq[body] = seq + 1
        self._put(f"{self.base}/{body}/command", {"t": t, "seq": seq, "sender": self.name, **fields})
        self._sent += 1

    def recorded_next_seq(self, body: str, timeout: float = 2.0) -> int:
        """The seq this controller's next command to ``body`` takes: one past the last the
        logger recorded from this sender (``@status`` with ``{"channels": true}``, its
        ``event_next_seq`` table; docs/control.md, Commands), so that a restarted controller
        goes on above the numbers it used (the plant refuses a seq not above the last it took);
        0 when the logger has none (a fresh run) or does not answer within ``timeout`` s."""
        track = f"{self.base}/{body}/command#{self.name}"
        best = 0
        try:
            for reply in self.session.get(f"{self.base}/@status", payload=json.dumps({"channels": True}),
                                          timeout=timeout):
                if reply.ok is None:
                    continue
                try:
                    table = json.loads(reply.ok.payload.to_bytes()).get("event_next_seq")
                    value = table.get(track) if isinstance(table, dict) else None
                except (ValueError, RecursionError, AttributeError):
                    continue
                if type(value) is int and 0 <= value <= MAX_SEQ // 2:  # (a forged answer cannot exhaust the range)
                    best = max(best, value)
        except zenoh.ZError:
            return best
        return best

    def done(self, tick: dict) -> None:
        """Answer control step ``tick`` (the tick :meth:`wait_tick` returned last, once): every
        command for it has been sent."""
        if tick is None or tick is not self._answerable:
            raise ValueError("done: expected the tick wait_tick returned last, not yet answered")
        self._answerable = None
        self._put(f"{self.base}/@done/{self.name}",
                  {"t": tick["t"], "seq": tick["seq"], "sender": self.name, "commands": self._sent})
        self._sent = 0

    def close(self) -> None:
        for s in self._subs:
            s.undeclare()
        self.session.close()
        if self.dropped:
            counts = ", ".join(f"{n} {reason}" for reason, n in sorted(self.dropped.items()))
            print(f"astrodyn_link: dropped {sum(self.dropped.values())} samples that were not the run's or not "
                  f"well-formed ({counts})", file=sys.stderr, flush=True)

    # A process whose Zenoh session is still open when it exits waits for ever on Zenoh's
    # threads: use the link in a `with` block, so an exception or sys.exit closes it.
    def __enter__(self) -> Link:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
