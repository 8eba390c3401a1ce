"""Live 3D view of a running scene in Foxglove: ``serve CFG --foxglove PORT``, ``replay REC --foxglove PORT``.

A separate process (``python -m astrodyn.service.viewer``) that only subscribes to the
scene's keys and serves a Foxglove WebSocket server (foxglove-sdk) on
``ws://127.0.0.1:PORT``.  Open the Foxglove app, "Open connection", Foxglove WebSocket,
that URL: the 3D panel shows the scene, the Plot panel the raw states.

It never slows the simulation.  Under ``serve`` (``--from-logger``) it does not subscribe
to the state streams at all: at each view frame it asks the logger's ``@latest`` queryable
for the newest sample of every state key (one envelope, signed by the logger), so the bus
carries nothing extra at the simulation's rate (a full-rate subscriber cost
constellation-1000 13 % of its speed: docs/benchmarks.md).  Under ``replay`` it subscribes,
and its Zenoh callback keeps only the newest sample of each key (a dictionary store,
nothing else), so the bus never waits on the viewer.  The viewer
runs at a lower CPU priority (nice 10), so on a busy machine the simulation goes first;
its work per second is bounded (transforms, trail points and raw messages per second); every
``1 / rate`` s of wall time (30 Hz by default) the viewer takes those samples, checks them
(the run's HMAC when it runs under a supervisor, then the message definition) and sends
view frames.  States between two frames are not shown (the recording has them all); a
slow or vanished browser only loses view frames: foxglove-sdk drops what a client cannot
take.

Channels (timestamps: the scenario epoch + t, so Foxglove's clock is simulated time;
the server also broadcasts that time):

``foxglove/tf``       ``foxglove.FrameTransforms`` (at most 2000 body transforms a second:
                      30 frames a second up to 66 bodies, fewer above): per body with an attitude the frame
                      ``<body>`` (rotation from its Euler parameters, at its position, or
                      at the origin without an orbit); per body with only an orbit the
                      frame ``<body>/position`` (axes parallel to the orbit frame).  km.
``foxglove/scene``    ``foxglove.SceneUpdate``, every 5 s, when a client subscribes and when
                      a body or a body's orbit or attitude appears: the central body (sphere of
                      its equatorial radius), each body's trail (its positions at the view
                      frames, at most 2000 points per body and 20,000 in all), each body's
                      axes (x red, y green, z blue).
``astrodyn/<scenario>/<body>/orbit`` ... the raw state channels as recorded (JSON, the
                      message schemas), at most ``--raw-rate`` messages per second in all,
                      shared round-robin between the channels.

Control from the view (``--services VERBS``, given by ``serve`` and ``replay``): each control
verb of the run (``status``, ``pause``, ``resume``, ``rate``, ``stop``; ``seek`` under replay,
``fault`` under a closed-loop serve) is a Foxglove service of that name ("Call Service"
panel, JSON request).  The request carries the run's control token like every other client
(docs/security.md): ``{"token": "...", "factor": 2}`` for ``rate``, ``{"token": "...", "t":
120}`` for ``seek``; the viewer forwards it to the run's ``@control/<verb>`` key with that
token and answers with the run's replies (a JSON list).  The viewer holds no token: a
request without the right one is refused by the run, as on the bus.

The first JSON line on stdout says where it listens:
``{"foxglove": "ws://127.0.0.1:8765", "scenario": ...}``.
"""

from __future__ import annotations

import argparse
import collections
import json
import math
import os
import sys
import threading
import time
from pathlib import Path

import msgspec
import numpy as np

from astrodyn import auth, bus, messages
from astrodyn.recording.foxglove_scene import (
    BODY_COLORS,
    FRAME_TRANSFORMS_SCHEMA,
    MAX_LINE_POINTS,
    SCENE_TOPIC,
    SCENE_UPDATE_SCHEMA,
    axes_entity,
    central_body_entity,
    frame_transform,
    orbit_line_entity,
    stamp,
)
from astrodyn.service.children import share_fate_with_supervisor
from astrodyn.service.signals import StopFlag

__all__ = ["LatestSamples", "LiveScene", "add_foxglove_argument", "viewer_command", "main", "TF_TOPIC", "MAX_LIVE_SCENE_POINTS"]

TF_TOPIC = "foxglove/tf"
#: Most trail points of all bodies together in one scene update (a 1000-body constellation
#: gets 20 per body); the scene is resent every 5 s.
MAX_LIVE_SCENE_POINTS = 20_000
#: Most body transforms per second: the view frame rate drops below ``--rate`` for scenes of
#: more than 66 bodies (1000 bodies: 2 frames a second), so the view's work stays bounded
#: (measured: 6000 a second cost constellation-1000 10 % of its speed on 2 busy cores).
MAX_TRANSFORMS_PER_S = 2000
#: The viewer's CPU priority (``nice``): on a busy machine the simulation goes first.
VIEWER_NICE = 10
SCENE_PERIOD_S = 5.0


def add_foxglove_argument(parser: argparse.ArgumentParser, what: str) -> None:
    """The ``--foxglove PORT`` option of ``serve`` and ``replay`` (a port 0..65535; 0: a free one)."""
    def port(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = -1
        if not 0 <= value <= 65535:
            raise argparse.ArgumentTypeError(f"expected a port 0..65535 (0: a free one), got {text!r}")
        if value and (why := bus.port_taken(value)):  # the view would fail in its own process, unseen
            raise argparse.ArgumentTypeError(f"expected a free port on {bus.DEFAULT_HOST}, got {value} ({why})")
        return value

    parser.add_argument("--foxglove", type=port, default=None, metavar="PORT",
                        help=f"live 3D view of {what}: a Foxglove WebSocket server on ws://127.0.0.1:PORT (0: a free "
                             "port); open it in the Foxglove app (docs/foxglove.md)")


def viewer_command() -> list[str]:
    """argv prefix that starts the viewer process (an installed wheel has it too)."""
    return [sys.executable, "-m", "astrodyn.service.viewer"]


class LatestSamples:
    """A Zenoh subscriber callback that keeps only the newest sample of each key.

    The callback runs on Zenoh's thread: it stores ``(payload, attachment)`` under the key
    and returns (O(1), never blocks on the viewer), so a slow viewer never back-pressures
    the publishers.  :meth:`take` hands over what arrived since the last call."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._latest: dict[str, tuple[bytes, bytes | None]] = {}
        self.received = 0

    def __call__(self, sample) -> None:
        attachment = sample.attachment
        item = (sample.payload.to_bytes(), None if attachment is None else attachment.to_bytes())
        with self._lock:
            self._latest[str(sample.key_expr)] = item
            self.received += 1

    def take(self) -> dict[str, tuple[bytes, bytes | None]]:
        with self._lock:
            out, self._latest = self._latest, {}
        return out


class _Body:
    __slots__ = ("name", "index", "frame", "r_km", "r_time", "xyzw", "q_time", "recent_q", "trail", "samples",
                 "has_orbit")

    def __init__(self, name: str, index: int, has_orbit: bool | None):
        self.name, self.index = name, index
        self.frame = "GCRF"
        self.r_km: tuple | None = None  # newest position, km, and its log time
        self.r_time = 0
        self.xyzw: tuple | None = None  # newest attitude (Foxglove order, scalar last) and its log time
        self.q_time = 0
        self.recent_q: collections.OrderedDict[int, tuple] = collections.OrderedDict()  # log time -> xyzw
        self.trail: collections.deque = collections.deque(maxlen=MAX_LINE_POINTS)
        self.samples = 0
        self.has_orbit = has_orbit  # from the config; None: unknown (then: once an orbit state came)


def _numpy_to_json(obj):
    """msgspec's hook for what it does not encode itself: numpy arrays and scalars."""
    if isinstance(obj, (np.ndarray, np.generic)):
        return obj.tolist()
    raise TypeError(f"cannot encode {type(obj).__name__} as JSON")


#: The view's JSON encoder: about 10x faster than json.dumps on a frame of 1000 transforms
#: (0.34 against 3.2 ms), shortest round-trip floats like json.
_VIEW_JSON = msgspec.json.Encoder(enc_hook=_numpy_to_json)

#: Most state keys whose parse the view keeps (a frame of 10,000 bodies is 20,000 keys).
MAX_KEYS_CACHED = 100_000


class LiveScene:
    """What the view shows, built from the states taken at each view frame.

    ``epoch_ns``: the scenario epoch (ns since the Unix epoch); ``central``: the config's
    ``central_body`` table (``name``, ``radius`` in m).  Payloads are checked against their
    message definitions (:func:`astrodyn.messages.decode`); invalid ones are counted in
    ``invalid`` and not shown."""

    def __init__(self, epoch_ns: int, central: dict, orbit_bodies: set[str] | None = None):
        self.epoch_ns = int(epoch_ns)
        self.orbit_bodies = orbit_bodies  # names of the bodies with an orbit (the config), None: unknown
        self.central_name = str(central.get("name", "central"))
        radius = central.get("radius")
        self.radius_km = float(radius) / 1e3 if isinstance(radius, (int, float)) and math.isfinite(radius) and radius > 0 \
            else 0.0
        self.bodies: dict[str, _Body] = {}
        self.t = 0.0
        self.invalid = 0
        self.changed = False  #: a body, or a body's first orbit or attitude, appeared since the last scene
        self._keys: dict[str, tuple[str, str]] = {}  # key -> (body, kind): parsed once per key

    def log_time(self) -> int:
        """Log time of the newest state shown (ns since the Unix epoch)."""
        return self.epoch_ns + int(round(self.t * 1e9))

    def update(self, key: str, payload: bytes) -> int | None:
        """Take one state message; its log time, or None (counted in ``invalid`` when it is
        not a valid message) for anything that is not an orbit or attitude state."""
        parsed = self._keys.get(key)
        if parsed is None:
            try:
                _, name, kind = messages.parse_key(key)
            except messages.MessageError:
                self.invalid += 1
                return None
            if len(self._keys) >= MAX_KEYS_CACHED:  # a flood of made-up keys: start over
                self._keys.clear()
            parsed = self._keys[key] = (name, kind)
        name, kind = parsed
        if kind not in ("orbit", "attitude"):
            return None
        try:
            msg = messages.decode(payload, kind)
        except messages.MessageError:
            self.invalid += 1
            return None
        body = self.bodies.get(name)
        if body is None:
            has_orbit = None if self.orbit_bodies is None else name in self.orbit_bodies
            body = self.bodies[name] = _Body(name, len(self.bodies), has_orbit)
            self.changed = True
        log_time = self.epoch_ns + int(round(float(msg["t"]) * 1e9))
        if kind == "orbit":  # plain floats: this runs for every body at every view frame
            r = msg["r"]
            r_km = (r[0] / 1e3, r[1] / 1e3, r[2] / 1e3)
            self.changed |= body.r_km is None
            if log_time >= body.r_time:
                body.r_km, body.r_time = r_km, log_time
            body.frame = msg["frame"]
            body.trail.append(r_km)
            body.samples += 1
            body.has_orbit = True if body.has_orbit is None else body.has_orbit
        else:
            q = msg["q"]
            xyzw = (q[1], q[2], q[3], q[0])  # Foxglove order (astrodyn.rotation.quat_to_scalar_last)
            self.changed |= body.xyzw is None
            if log_time >= body.q_time:
                body.xyzw, body.q_time = xyzw, log_time
            body.recent_q[log_time] = xyzw
            while len(body.recent_q) > 64:
                body.recent_q.popitem(last=False)
        self.t = max(self.t, float(msg["t"]))
        return log_time

    def transforms(self) -> dict:
        """The ``foxglove.FrameTransforms`` message of the newest states.  Each transform is
        stamped with the log time of the state it shows: for a body with an orbit, its
        newest position, turned by its attitude at that same instant (or, before that
        attitude arrived, the newest one); a body with an orbit is not shown before its
        first position (never at a made-up origin); an attitude-only body sits at the
        origin of its frame, stamped with its attitude's time."""
        out = []
        for b in self.bodies.values():
            if b.r_km is not None:
                if b.xyzw is not None:
                    q = b.recent_q.get(b.r_time, b.xyzw)
                    out.append(frame_transform(stamp(b.r_time), b.frame, b.name, b.r_km, q))
                else:
                    out.append(frame_transform(stamp(b.r_time), b.frame, f"{b.name}/position", b.r_km,
                                               (0.0, 0.0, 0.0, 1.0)))
            elif b.xyzw is not None and b.has_orbit is False:
                out.append(frame_transform(stamp(b.q_time), b.frame, b.name, (0.0, 0.0, 0.0), b.xyzw))
        return {"transforms": out}

    def scene(self) -> dict:
        """The ``foxglove.SceneUpdate`` message: central body, trails, axes."""
        ts = stamp(self.log_time())
        orbiting = [b for b in self.bodies.values() if b.trail]
        entities = []
        if orbiting and self.radius_km > 0:
            entities.append(central_body_entity(ts, orbiting[0].frame, self.central_name, self.radius_km))
        per_body = max(2, MAX_LIVE_SCENE_POINTS // max(1, len(orbiting)))
        axis_km = 0.1 * self.radius_km if orbiting and self.radius_km > 0 else 1.0
        for b in self.bodies.values():
            if b.trail:
                trail = np.asarray(b.trail)
                keep = np.unique(np.rint(np.linspace(0, len(trail) - 1, min(per_body, len(trail)))).astype(int))
                entities.append(orbit_line_entity(ts, b.frame, b.name, trail[keep], BODY_COLORS[b.index % len(BODY_COLORS)],
                                                  b.samples))
            if b.xyzw is not None:
                entities.append(axes_entity(ts, b.name, axis_km))
        return {"deletions": [], "entities": entities}


def _schema(name: str, schema: dict):
    import foxglove

    return foxglove.Schema(name=name, encoding="jsonschema", data=json.dumps(schema).encode())


class _View:
    """The Foxglove server and its channels; raw state channels made on first use."""

    def __init__(self, host: str, port: int, scenario: str, raw_rate: float, services: bool = False,
                 playback: PlaybackBar | None = None):
        import foxglove

        self.foxglove = foxglove
        self.scene_wanted = threading.Event()  # a client subscribed to the scene: send it at the next frame
        view = self

        class Listener(foxglove.ServerListener):
            def on_subscribe(self, client, channel) -> None:
                if channel.topic == SCENE_TOPIC:
                    view.scene_wanted.set()

            def on_playback_control_request(self, request):
                return playback.handle(request)

        capabilities = [foxglove.Capability.Time, *([foxglove.Capability.Services] if services else []),
                        *([foxglove.Capability.PlaybackControl] if playback is not None else [])]
        self.server = foxglove.start_server(name=f"astrodyn {scenario}", host=host, port=port,
                                            capabilities=capabilities, server_listener=Listener(),
                                            supported_encodings=["json"] if services else None,
                                            playback_time_range=None if playback is None else playback.time_range)
        self.tf = foxglove.Channel(TF_TOPIC, schema=_schema("foxglove.FrameTransforms", FRAME_TRANSFORMS_SCHEMA),
                                   message_encoding="json")
        self.scene = foxglove.Channel(SCENE_TOPIC, schema=_schema("foxglove.SceneUpdate", SCENE_UPDATE_SCHEMA),
                                      message_encoding="json")
        self.raw: dict[str, object] = {}
        self.raw_budget = float(raw_rate)
        self.pending: collections.OrderedDict[str, tuple[bytes, int]] = collections.OrderedDict()

    def raw_channel(self, key: str):
        ch = self.raw.get(key)
        if ch is None:
            found = messages.schema_for_key(key)
            name, schema = found if found is not None else ("", {})
            ch = self.raw[key] = self.foxglove.Channel(key, schema=_schema(name, schema), message_encoding="json")
        return ch

    def forward(self, dt: float) -> int:
        """Send pending raw states, at most ``raw_rate * dt`` of them, oldest keys first
        (round-robin: a key sent goes to the back)."""
        n = int(self.raw_budget * dt) or 1
        sent = 0
        while self.pending and sent < n:
            key, (payload, log_time) = self.pending.popitem(last=False)
            channel = self.raw_channel(key)  # made (advertised) even before anyone subscribes
            if channel.has_sinks():
                channel.log(payload, log_time=log_time)
            sent += 1
        return sent

    def add_control_services(self, session, scenario: str, verbs: list[str]) -> None:
        """One Foxglove service per control verb, forwarding to ``@control/<verb>`` (module docstring)."""
        from foxglove.websocket import MessageSchema, Service, ServiceSchema

        def schema(name: str, body: dict):
            return MessageSchema(encoding="json", schema=_schema(name, body))

        services = []
        for verb in verbs:
            request = schema(f"astrodyn.control.{verb}.Request", control_request_schema(verb))
            response = schema(f"astrodyn.control.{verb}.Response", {"type": "array", "items": {"type": "object"}})
            services.append(Service(name=verb, schema=ServiceSchema(name=f"astrodyn.control.{verb}", request=request,
                                                                    response=response),
                                    handler=lambda req, verb=verb: forward_control(session, scenario, verb, req.payload)))
        self.server.add_services(services)

    def close(self) -> None:
        self.server.stop()


class PlaybackBar:
    """Foxglove's playback bar (play, pause, speed, seek) wired to a replay's control verbs
    (``replay --foxglove PORT --foxglove-playback``): each PlaybackControlRequest becomes
    ``seek`` (when the bar was dragged), ``rate`` (when the speed changed), then ``resume`` or
    ``pause``, sent with the replay's control token, which this viewer holds for it; the
    answer is the replay's state after them.  ``time_range``: the recording's span in ns
    since the Unix epoch; ``epoch_ns`` the scenario epoch (``t`` = (ns - epoch_ns) / 1e9)."""

    def __init__(self, scenario: str, token: str, time_range: tuple[int, int], epoch_ns: int):
        self.scenario, self.token, self.time_range, self.epoch_ns = scenario, token, time_range, epoch_ns
        self.session = None  # set once the bus session is open
        self.speed = 1.0

    def _send(self, verb: str, args: dict | None = None) -> dict:
        replies = bus.send_control(self.session, self.scenario, verb, args, timeout_s=5.0, token=self.token)
        reply = next((r for r in replies if isinstance(r, dict)), {})
        if "error" in reply:
            raise ValueError(str(reply["error"]))
        return reply

    def handle(self, request):
        """The PlaybackState after ``request`` (a foxglove PlaybackControlRequest)."""
        from foxglove.websocket import PlaybackCommand, PlaybackState, PlaybackStatus

        did_seek = request.seek_time is not None
        reply: dict = {}
        try:
            if self.session is None:
                raise ValueError("the viewer's bus session is not open yet")
            if did_seek:
                reply = self._send("seek", {"t": (int(request.seek_time) - self.epoch_ns) / 1e9})
            speed = float(request.playback_speed)
            if math.isfinite(speed) and speed > 0 and speed != self.speed:
                reply = self._send("rate", {"factor": speed})
                self.speed = speed
            verb = "resume" if request.playback_command == PlaybackCommand.Play else "pause"
            reply = self._send(verb)
        except (ValueError, bus.BusError) as exc:  # the bar shows the state it had; the reason goes to stderr
            print(f"astrodyn viewer: playback request refused: {exc}", file=sys.stderr, flush=True)
            did_seek = False
        state = reply.get("state")
        status = {"running": PlaybackStatus.Playing, "paused": PlaybackStatus.Paused,
                  "finished": PlaybackStatus.Ended, "stopped": PlaybackStatus.Ended}.get(state, PlaybackStatus.Paused)
        t = reply.get("t")
        now = self.epoch_ns + int(round(float(t) * 1e9)) if isinstance(t, (int, float)) and math.isfinite(t) \
            else self.time_range[0]
        return PlaybackState(status=status, current_time=max(self.time_range[0], min(self.time_range[1], now)),
                             playback_speed=self.speed, did_seek=did_seek, request_id=request.request_id)


def playback_bar(args, epoch_ns: int) -> PlaybackBar | None:
    """The :class:`PlaybackBar` of ``--playback-token-file`` and ``--playback-range``, or None."""
    if args.playback_token_file is None:
        return None
    token = Path(args.playback_token_file).read_text(encoding="utf-8").strip()
    try:
        lo, hi = (int(x) for x in args.playback_range.split(","))
    except (AttributeError, ValueError):
        raise ValueError(f"--playback-range: expected START_NS,END_NS, got {args.playback_range!r}") from None
    if not 0 <= lo <= hi:
        raise ValueError(f"--playback-range: expected 0 <= START_NS <= END_NS, got {args.playback_range!r}")
    return PlaybackBar(args.scenario, token, (lo, hi), epoch_ns)


#: The arguments each control verb takes besides the token (docs/clients.md).
_CONTROL_ARGS = {
    "rate": {"factor": {"type": "number", "description": "real-time factor (inf: as fast as possible)"}},
    "seek": {"t": {"type": "number", "description": "simulated time to continue from, s since the scenario epoch"}},
}

#: Largest service request accepted, bytes (a control request is a few dozen).
MAX_SERVICE_REQUEST = 65536


def control_request_schema(verb: str) -> dict:
    """JSON Schema of the Foxglove service request for ``verb``: the token and the verb's arguments."""
    props = {"token": {"type": "string", "description": "the run's control token (docs/security.md)"},
             **_CONTROL_ARGS.get(verb, {})}
    return {"type": "object", "properties": props, "additionalProperties": verb == "fault"}


def forward_control(session, scenario: str, verb: str, payload: bytes) -> bytes:
    """Answer a Foxglove service call: ``payload`` (a JSON object, the token in ``"token"``)
    goes to ``@control/<verb>`` with that token; the run's replies come back as a JSON list.
    ValueError (the client sees its text) for a request that is not a JSON object."""
    if len(payload) > MAX_SERVICE_REQUEST:
        raise ValueError(f"{verb}: expected a request of at most {MAX_SERVICE_REQUEST} bytes, got {len(payload)}")
    try:
        args = json.loads(bytes(payload) or b"{}")
    except (ValueError, RecursionError):
        raise ValueError(f'{verb}: expected a JSON object, e.g. {{"token": "...", "factor": 2}}') from None
    if not isinstance(args, dict):
        raise ValueError(f"{verb}: expected a JSON object, got {type(args).__name__}")
    token = args.pop("token", None)
    if token is not None and not isinstance(token, str):
        raise ValueError(f"{verb}.token: expected a string, got {type(token).__name__}")
    replies = bus.send_control(session, scenario, verb, args or None, timeout_s=5.0, token=token)
    if not replies:
        raise ValueError(f"{verb}: no answer from the run within 5 s")
    return json.dumps(replies).encode()


_CLOSED_LOOP_KINDS = frozenset(messages.CONTROL_KINDS + messages.SENSOR_KINDS)


def closed_loop_log_time(key: str, payload: bytes, epoch_ns: int) -> int | None:
    """Log time (ns since the Unix epoch) of a valid command, actuator state or sensor
    sample (docs/control.md), forwarded as a raw channel; None for anything else."""
    try:
        kind = messages.kind_of_key(key)
        if kind not in _CLOSED_LOOP_KINDS:
            return None
        return epoch_ns + int(round(float(messages.decode(payload, kind)["t"]) * 1e9))
    except (messages.MessageError, ValueError, OverflowError):
        return None


def _scenario_metadata(path: str | None) -> tuple[int, dict, set[str] | None]:
    """(epoch_unix_ns, central_body table, names of the bodies with an orbit or None) from
    a scenario metadata JSON file (``Scenario.to_metadata``)."""
    if not path:
        return 0, {}, None
    meta = json.loads(Path(path).read_text())
    try:
        config = json.loads(meta.get("json") or "{}")
        central = config.get("central_body") or {}
        orbiting = {b["name"] for b in config.get("bodies") or [] if isinstance(b, dict) and b.get("orbit")}
    except (ValueError, AttributeError, KeyError, TypeError):
        central, orbiting = {}, None
    return int(meta.get("epoch_unix_ns") or 0), central if isinstance(central, dict) else {}, orbiting


def main(argv: list[str] | None = None) -> int:
    """``python -m astrodyn.service.viewer --scenario NAME ...`` (module docstring): exit 0
    when stopped, 1 when the server or the bus cannot start, 2 for bad arguments."""
    args = parse_viewer_arguments(argv)
    try:
        epoch_ns, central, orbiting, verbs = checked_viewer_arguments(args)
    except (ValueError, OSError, messages.MessageError) as exc:
        print(f"astrodyn viewer: error: {exc}", file=sys.stderr)
        return 2
    share_fate_with_supervisor()
    try:
        os.nice(VIEWER_NICE)
    except OSError:
        pass
    stop = StopFlag()
    secret = auth.secret_from_environment()
    samples = ViewerSamples(args.scenario, args.from_logger, auth.Verifier(secret) if secret is not None else None)
    scene = LiveScene(epoch_ns, central, orbiting)
    try:
        playback = playback_bar(args, epoch_ns)
    except (ValueError, OSError) as exc:
        print(f"astrodyn viewer: error: {exc}", file=sys.stderr)
        return 2
    try:
        view = _View(args.host, args.port, args.scenario, args.raw_rate, services=bool(verbs), playback=playback)
    except Exception as exc:  # foxglove-sdk: port taken, bad host
        print(f"astrodyn viewer: error: cannot start the Foxglove server on {args.host}:{args.port}: {exc}",
              file=sys.stderr)
        return 1
    try:
        with bus.session_from_args(args) as session:
            base = f"{messages.PREFIX}/{args.scenario}"
            subs = [] if args.from_logger else [session.declare_subscriber(key, samples.latest)
                                                for key in (f"{base}/**", f"{base}/@batch/*")]
            if verbs:
                view.add_control_services(session, args.scenario, verbs)
            if playback is not None:
                playback.session = session
            print(json.dumps({"foxglove": f"ws://{args.host}:{view.server.port}", "scenario": args.scenario,
                              "authenticated": samples.verifier is not None}), flush=True)
            run_view_frames(session, 1.0 / args.rate, stop, samples, scene, view)
            for sub in subs:
                sub.undeclare()
    except bus.BusError as exc:
        print(f"astrodyn viewer: error: {exc}", file=sys.stderr)
        return 1
    finally:
        view.close()
    print(json.dumps({"viewer": "stopped", "reason": stop.why, "received": samples.latest.received,
                      "bodies": len(scene.bodies), "invalid": scene.invalid, "rejected": samples.rejected}), flush=True)
    return 0


def parse_viewer_arguments(argv: list[str] | None) -> argparse.Namespace:
    """The viewer's command line (``--scenario``, ``--port``, ``--rate`` ..., and the bus options)."""
    ap = argparse.ArgumentParser(prog="astrodyn.service.viewer", description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", required=True, help="scenario name (the keys astrodyn/<scenario>/...)")
    ap.add_argument("--port", type=int, default=8765, help="Foxglove WebSocket port on 127.0.0.1 (0: a free one)")
    ap.add_argument("--host", default="127.0.0.1", help="address to listen on (default loopback only)")
    ap.add_argument("--metadata", default=None, help="scenario metadata JSON (epoch, central body)")
    ap.add_argument("--rate", type=float, default=30.0, help="view frames per second of wall time (default 30)")
    ap.add_argument("--from-logger", action="store_true",
                    help="take the newest states from the logger's @latest queryable at each view frame instead of "
                         "subscribing to the full-rate streams (what serve does: the bus then carries nothing extra)")
    ap.add_argument("--services", default="", metavar="VERBS",
                    help="comma-separated control verbs to offer as Foxglove services (serve and replay pass theirs)")
    ap.add_argument("--playback-token-file", default=None, metavar="FILE",
                    help="wire Foxglove's playback bar to the replay's control verbs with the token in FILE "
                         "(replay --foxglove-playback passes it)")
    ap.add_argument("--playback-range", default=None, metavar="START_NS,END_NS",
                    help="the recording's span for the playback bar, ns since the Unix epoch")
    ap.add_argument("--raw-rate", type=float, default=1000.0,
                    help="raw state messages per second sent to Foxglove, all channels together (default 1000)")
    bus.add_bus_arguments(ap)
    return ap.parse_args(argv)


def checked_viewer_arguments(args: argparse.Namespace) -> tuple[int, dict, set[str] | None, list[str]]:
    """``(epoch_unix_ns, central_body table, names of the bodies with an orbit or None,
    control verbs)`` of valid arguments; ValueError (or OSError, MessageError) naming the
    option otherwise: ``--rate`` in (0, 1000], ``--raw-rate`` in (0, 100000], ``--port``
    0..65535, ``--services`` verbs of the run."""
    messages.check_name(args.scenario, "--scenario")
    for name in ("rate", "raw_rate"):
        value = getattr(args, name)
        if not (math.isfinite(value) and 0 < value <= 1000 * (100 if name == "raw_rate" else 1)):
            raise ValueError(f"--{name.replace('_', '-')}: expected a number in (0, "
                             f"{1000 * (100 if name == 'raw_rate' else 1)}], got {value}")
    if not 0 <= args.port <= 65535:
        raise ValueError(f"--port: expected 0..65535, got {args.port}")
    epoch_ns, central, orbiting = _scenario_metadata(args.metadata)
    verbs = [v for v in args.services.split(",") if v]
    for verb in verbs:
        if verb not in (*bus.CONTROL_VERBS, "seek", "fault"):
            raise ValueError(f"--services: expected verbs from {', '.join((*bus.CONTROL_VERBS, 'seek', 'fault'))}, "
                             f"got {verb!r}")
    return epoch_ns, central, orbiting, verbs


class ViewerSamples:
    """Where the viewer's samples come from, and their check: the logger's newest
    (``from_logger``: one query per view frame, one envelope checked against the run's
    authenticator) or what the subscription kept (:class:`LatestSamples`: each sample
    checked on its own).  ``rejected`` counts what failed the check."""

    def __init__(self, scenario: str, from_logger: bool, verifier: auth.Verifier | None):
        self.from_logger = from_logger
        self.verifier = verifier
        self.latest = LatestSamples()
        self.latest_key = messages.latest_key(scenario)
        self.rejected = 0

    def newest(self, session) -> dict[str, tuple[bytes, bytes | None]]:
        """key -> (payload, attachment) of the samples to show at this view frame."""
        if not self.from_logger:
            return self.latest.take()
        out: dict[str, tuple[bytes, bytes | None]] = {}
        for reply in session.get(self.latest_key, timeout=2.0):
            if reply.ok is None:
                continue
            payload = reply.ok.payload.to_bytes()
            attachment = reply.ok.attachment
            if self.verifier is not None:
                try:
                    self.verifier.verify(self.latest_key, payload, None if attachment is None else attachment.to_bytes())
                except auth.AuthError:
                    self.rejected += 1
                    continue
            try:
                out.update((k, (p, None)) for k, p in messages.decode_batch(payload))
            except messages.MessageError:
                continue
        self.latest.received += len(out)
        return out

    def accepted(self, key: str, payload: bytes, attachment: bytes | None) -> bool:
        """False (and counted) for a subscribed sample that fails the run's authenticator;
        the logger's samples were checked as one envelope by :meth:`newest`."""
        if self.verifier is not None and not self.from_logger:
            try:
                self.verifier.verify(key, payload, attachment)
            except auth.AuthError:
                self.rejected += 1
                return False
        return True


def run_view_frames(session, period: float, stop: StopFlag, samples: ViewerSamples, scene: LiveScene, view: _View) -> None:
    """Until ``stop``: every ``period`` s of wall time (longer for scenes of more than
    :data:`MAX_TRANSFORMS_PER_S` ``* period`` bodies) take the newest samples into the scene
    and send one view frame."""
    next_frame = next_scene = time.monotonic()
    while stop.why is None:
        now = time.monotonic()
        if now < next_frame:
            time.sleep(min(next_frame - now, 0.05))
            continue
        frame_period = max(period, len(scene.bodies) / MAX_TRANSFORMS_PER_S)
        next_frame = max(next_frame + frame_period, now)
        take_samples(samples.newest(session), samples, scene, view)
        if scene.bodies:  # what no client subscribes to is not built (has_sinks)
            next_scene = send_view_frame(scene, view, frame_period, now, next_scene)


def take_samples(newest: dict[str, tuple[bytes, bytes | None]], samples: ViewerSamples, scene: LiveScene,
                 view: _View) -> None:
    """The accepted, valid states of ``newest`` into ``scene``, and every state or closed-loop
    sample into the raw channels waiting to be sent (``view.pending``, newest last)."""
    for key, (payload, attachment) in newest.items():
        if not samples.accepted(key, payload, attachment):
            continue
        try:
            pairs = bus.state_samples(key, payload)
        except messages.MessageError:
            continue
        for k, p in pairs:
            log_time = scene.update(k, p)
            if log_time is None:  # the closed loop's channels: for the Plot panel only
                log_time = closed_loop_log_time(k, p, scene.epoch_ns)
            if log_time is not None:
                view.pending[k] = (p, log_time)
                view.pending.move_to_end(k)


def send_view_frame(scene: LiveScene, view: _View, frame_period: float, now: float, next_scene: float) -> float:
    """One view frame (the transforms, the time, the raw channels' share of the frame) and,
    when due, wanted or changed, the scene update; returns the time the next scene update
    is due (monotonic s)."""
    lt = scene.log_time()
    if view.tf.has_sinks():
        view.tf.log(_VIEW_JSON.encode(scene.transforms()), log_time=lt)  # 10x json.dumps
    view.server.broadcast_time(lt)
    view.forward(frame_period)
    if view.scene.has_sinks() and (now >= next_scene or view.scene_wanted.is_set() or scene.changed):
        view.scene_wanted.clear()
        scene.changed = False
        view.scene.log(_VIEW_JSON.encode(scene.scene()), log_time=lt)
        next_scene = now + SCENE_PERIOD_S
    return next_scene


if __name__ == "__main__":
    raise SystemExit(main())
