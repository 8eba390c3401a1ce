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
nothing else), so the bus never waits on the viewer; ``replay`` signs what it puts with a
secret of its own, handed to the viewer as ``serve`` hands the run secret, so a state
another process puts on the replay's bus is dropped.  A state of a key earlier than the
one shown (a replay's seek back) is shown: the view follows its source back.  The viewer
runs at a lower CPU priority (nice 10), so on a busy machine the simulation goes first;
its work per second is bounded (transforms, trail points and raw messages per second); every
``1 / rate`` s of wall time (30 Hz by default) the viewer takes those samples, checks them
(the run's HMAC when it runs under a supervisor, then the message definition) and sends
view frames.  States between two frames are not shown (the recording has them all); a
slow or vanished browser only loses view frames: foxglove-sdk drops the oldest of what a
client cannot take.

Clients that misbehave (docs/foxglove.md): what foxglove-sdk 0.30 does not bound, the
viewer does from outside it (:class:`ConnectionGuard`, every second, from the process's own
sockets): a client that reads nothing for 15 s while data waits for it, a connection
without a WebSocket handshake after 10 s, one that sends more than 4 MiB a second are
cut, and beyond 16 connections those still in their handshake, then idle ones (sent less
than 1 kB/s: subscribed to nothing), then the newest (:meth:`ConnectionGuard.cut_order`;
``--client-stall-timeout``, ``--handshake-timeout``,
``--max-clients``, or ``ASTRODYN_VIEWER_STALL_S`` / ``_HANDSHAKE_S`` / ``_MAX_CLIENTS``); a
server whose accept loop died (out of descriptors) is restarted on the same port; the
SDK's log lines about clients (one per bad message) are limited to 20 a minute; a client's
subscription to the scene makes it sent at most once a second; the stop waits at most 2 s
for the server.  The viewer asks the kernel to end it first under memory pressure
(``oom_score_adj``): the logger holds the record, ``serve`` restarts the view.

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
                      message schemas): the newest state of each key at each view frame,
                      each state once, at most ``--raw-rate`` messages per second in all,
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
import array
import collections
import errno
import fcntl
import json
import logging
import math
import os
import resource
import socket
import struct
import sys
import termios
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
from astrodyn.recording.stream import MAX_T_S
from astrodyn.service.children import share_fate_with_supervisor
from astrodyn.signals import StopFlag

__all__ = ["LatestSamples", "LiveScene", "add_foxglove_argument", "viewer_command", "main", "TF_TOPIC", "MAX_LIVE_SCENE_POINTS",
           "ConnectionGuard", "LineBudget", "route_sdk_log", "raise_descriptor_limit", "MAX_CLIENTS", "CLIENT_STALL_S",
           "HANDSHAKE_S", "TrailRing", "RecentAttitudes"]

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
#: A client's subscription to the scene makes the next frame send it, at most this often
#: (a client that subscribed and unsubscribed in a loop had the view build and send its
#: largest message, 1.8 MB for 200 bodies, at every frame, to every client).
SCENE_REQUEST_MIN_S = 1.0

# What the view allows a WebSocket client (:class:`ConnectionGuard`, docs/foxglove.md,
# "Clients that misbehave"); the first three can be changed with the viewer's options or
# the environment variables named there.
#: Most connections at a time (a live view has a few clients); beyond, connections are cut
#: in the order of :meth:`ConnectionGuard.cut_order`: those still in their handshake, then the
#: idle ones, then the newest.
MAX_CLIENTS = 16
#: A connection younger than this is not cut as idle: time to subscribe after its handshake, s
#: (the Foxglove app subscribes within a second).
NEWCOMER_GRACE_S = 5.0
#: A connection sent less than this many bytes a second by the view is idle: one subscribed
#: to nothing gets only the time (about 11 bytes 30 times a second, 330 B/s); one subscribed
#: to the transforms of even one body gets about 6 kB/s.
IDLE_BYTES_PER_S = 1024.0
#: A client that reads nothing for this long while data waits for it is cut, s.
CLIENT_STALL_S = 15.0
#: A connection that has not completed its WebSocket handshake after this long is cut, s.
HANDSHAKE_S = 10.0
#: A client that sends more than this many bytes a second is cut (requests are a few hundred bytes).
MAX_CLIENT_INPUT_PER_S = 4 * 2**20
#: How often the connections are looked at, s.
GUARD_PERIOD_S = 1.0
#: How long closing the server may take before the viewer exits without it, s.
CLOSE_TIMEOUT_S = 2.0
#: Most lines of foxglove-sdk's log (and of the guard's) per window; the rest are counted.
LOG_LINES_PER_WINDOW = 20
LOG_WINDOW_S = 60.0
#: The soft limit of open descriptors the viewer raises itself to (at most its hard limit).
MAX_DESCRIPTORS = 65536
#: Restarts of a server that stopped accepting connections within a minute, before the
#: viewer exits (status 1) and leaves it to ``serve``'s restart budget.
MAX_SERVER_RESTARTS = 5


def add_foxglove_argument(parser: argparse.ArgumentParser, what: str) -> None:
    """The ``--foxglove PORT`` option of ``serve`` and ``replay`` (a port 0..65535; 0: a free one)."""
    parser.add_argument("--foxglove", type=bus.local_port, default=None, metavar="PORT",
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


#: Rows a trail first allocates; it doubles up to its capacity as points come.
TRAIL_FIRST_ROWS = 32
#: Distinct log times of a body's newest attitudes kept, so that a position is shown turned
#: by the attitude of its own instant (orbit and attitude states arrive separately).
RECENT_ATTITUDES = 64


class TrailRing:
    """One body's orbit trail: its newest ``capacity`` positions in a float64 ring buffer.

    A point is a position ``(x, y, z)`` in km in the inertial frame of the body's orbit
    states (the view draws the whole trail in the body's newest ``frame``); one is appended
    per orbit state the view takes, and the points are kept in the order they were appended
    (time order for a stream of states).  Once ``capacity`` points are held, each new one
    replaces the oldest.  :meth:`points` and :meth:`take` give them oldest first, as the
    ``deque(maxlen=capacity)`` of tuples this replaces did.

    Storage: ``capacity * 3`` float64, :attr:`nbytes` = 24 bytes a point, once full (a deque
    of tuples took about 150: a tuple, three float objects and its slot); until then it
    grows by doubling from :data:`TRAIL_FIRST_ROWS` rows, so a short trail holds little.
    """

    __slots__ = ("capacity", "_flat", "_rows", "_writer", "_count", "_next")

    def __init__(self, capacity: int = MAX_LINE_POINTS):
        if not (isinstance(capacity, (int, np.integer)) and not isinstance(capacity, bool) and capacity >= 1):
            raise ValueError(f"capacity: expected an integer >= 1, got {capacity!r}")
        self.capacity = int(capacity)
        self._count = 0  # points held
        self._next = 0  # row the next point goes to; once full, the row of the oldest point
        self._allocate(min(self.capacity, TRAIL_FIRST_ROWS))

    def _allocate(self, rows: int) -> None:
        """Storage for ``rows`` points, the points held copied into it (rows 0 .. count-1)."""
        flat = np.empty(3 * rows, dtype=np.float64)
        if self._count:
            flat[:3 * self._count] = self._flat[:3 * self._count]
        self._flat = flat  # x0, y0, z0, x1, ...
        self._rows = flat.reshape(rows, 3)  # the same memory, one row a point
        self._writer = memoryview(flat)  # item assignment: 4x faster than a numpy row assignment

    def __len__(self) -> int:
        return self._count

    @property
    def nbytes(self) -> int:
        """Bytes of the point storage (24 a row allocated; ``capacity * 24`` once full)."""
        return self._flat.nbytes

    def append(self, point_km) -> None:
        """Add the newest point ``(x, y, z)``, km; the oldest goes once ``capacity`` are held."""
        x, y, z = map(float, point_km)  # TypeError/ValueError before anything changes
        row = self._next
        if row == len(self._rows):  # only while filling: the storage is full, not the ring
            self._allocate(min(2 * row, self.capacity))
        k = 3 * row
        writer = self._writer
        writer[k] = x
        writer[k + 1] = y
        writer[k + 2] = z
        if self._count < self.capacity:
            self._count += 1
        self._next = row + 1 if row + 1 < self.capacity else 0

    def take(self, indices) -> np.ndarray:
        """The points at ``indices`` in time order (0: the oldest held, ``len - 1``: the
        newest), shape ``(len(indices), 3)``, km, a copy; IndexError outside ``0 .. len - 1``."""
        indices = np.asarray(indices, dtype=np.intp)
        if indices.size and (int(indices.min()) < 0 or int(indices.max()) >= self._count):
            raise IndexError(f"trail indices: expected 0 .. {self._count - 1}, got {indices.min()} .. {indices.max()}")
        if self._count < self.capacity:  # not wrapped: row i holds point i
            return self._rows[indices]
        return self._rows[(indices + self._next) % self.capacity]

    def points(self) -> np.ndarray:
        """All points held, oldest first, shape ``(len, 3)``, km, a copy."""
        return self.take(np.arange(self._count))


class RecentAttitudes:
    """One body's attitudes at its newest ``capacity`` distinct log times.

    A log time is in ns since the Unix epoch (an int of any size); an attitude is a unit
    quaternion in Foxglove order ``(x, y, z, w)``, scalar last.  :meth:`put` of a time
    already held replaces its attitude in place; of a new time, once ``capacity`` are held,
    drops the time that was put first: the same as the ``OrderedDict`` (log time -> tuple)
    capped at ``capacity`` it replaces, in a list of the times and ``4 * capacity`` float64
    (about 4.6 KB for 64 instead of about 24 KB).
    """

    __slots__ = ("capacity", "_times", "_xyzw", "_next", "_latest")

    def __init__(self, capacity: int = RECENT_ATTITUDES):
        if not (isinstance(capacity, int) and not isinstance(capacity, bool) and capacity >= 1):
            raise ValueError(f"capacity: expected an integer >= 1, got {capacity!r}")
        self.capacity = capacity
        self._times: list[int] = []  # slot -> log time, slots in the order they were first put
        self._xyzw = array.array("d", bytes(8 * 4 * capacity))  # slot i: x, y, z, w at 4 i
        self._next = 0  # once full: the slot of the time put first, replaced by the next new time
        self._latest = 0  # no time held is later (when any is held): a later one needs no search

    def __len__(self) -> int:
        return len(self._times)

    def _slot(self, log_time: int) -> int:
        """The slot holding ``log_time``, or -1."""
        times = self._times
        if not times or log_time > self._latest:  # the usual case for a new state: no search
            return -1
        newest = self._next - 1  # the slot of the time put last (-1: the last slot)
        if times[newest] == log_time:
            return newest % len(times)
        return times.index(log_time) if log_time in times else -1

    def put(self, log_time: int, xyzw) -> None:
        """The attitude ``xyzw`` (x, y, z, w) at ``log_time`` (ns since the Unix epoch)."""
        x, y, z, w = map(float, xyzw)  # TypeError/ValueError before anything changes
        times, stored = self._times, self._xyzw
        slot = self._slot(log_time)
        if slot >= 0:  # a time held: its newer attitude, in place
            k = 4 * slot
            stored[k], stored[k + 1], stored[k + 2], stored[k + 3] = x, y, z, w
            return
        if not times or log_time > self._latest:
            self._latest = log_time  # an upper bound: it may stay when its time is dropped
        if len(times) < self.capacity:
            slot = len(times)
            times.append(log_time)
        else:
            slot = self._next
            times[slot] = log_time
            self._next = slot + 1 if slot + 1 < self.capacity else 0
        k = 4 * slot
        stored[k], stored[k + 1], stored[k + 2], stored[k + 3] = x, y, z, w

    def get(self, log_time: int, default=None):
        """The attitude ``(x, y, z, w)`` at ``log_time``, or ``default`` when it is not held."""
        slot = self._slot(log_time)
        if slot < 0:
            return default
        return tuple(self._xyzw[4 * slot:4 * slot + 4])


class _Body:
    __slots__ = ("name", "index", "frame", "r_km", "r_time", "xyzw", "q_time", "recent_attitudes", "trail",
                 "samples", "has_orbit")

    def __init__(self, name: str, index: int, has_orbit: bool | None):
        self.name, self.index = name, index
        self.frame = "GCRF"
        self.r_km: tuple | None = None  # newest position, km, and its log time
        self.r_time = 0
        self.xyzw: tuple | None = None  # newest attitude (Foxglove order, scalar last) and its log time
        self.q_time = 0
        self.recent_attitudes = RecentAttitudes()  # log time -> xyzw, the newest RECENT_ATTITUDES times
        self.trail = TrailRing(MAX_LINE_POINTS)  # positions at the view frames, km, oldest first
        self.samples = 0  # orbit states taken (the trail's metadata)
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
        t = float(msg["t"])
        log_time = self.epoch_ns + int(round(t * 1e9)) if -MAX_T_S <= t <= MAX_T_S else -1
        if not 0 <= log_time < 2**64:  # a valid message, but no time the view (or Foxglove) can show
            self.invalid += 1
            return None
        body = self.bodies.get(name)
        if body is None:
            has_orbit = None if self.orbit_bodies is None else name in self.orbit_bodies
            body = self.bodies[name] = _Body(name, len(self.bodies), has_orbit)
            self.changed = True
        # The newest state taken for a key is what its source shows now, in either direction:
        # one earlier than the state shown means the source went back in time (a replay's
        # seek, from the bus, a Foxglove service or the playback bar), so that body's trail
        # (or recent attitudes) starts over and the view's time follows it back.
        went_back = False
        if kind == "orbit":  # plain floats: this runs for every body at every view frame
            r = msg["r"]
            r_km = (r[0] / 1e3, r[1] / 1e3, r[2] / 1e3)
            self.changed |= body.r_km is None
            if body.r_km is not None and log_time < body.r_time:
                went_back = True
                body.trail = TrailRing(MAX_LINE_POINTS)
                body.samples = 0
                self.changed = True  # the scene's trail of that body is redrawn at the next frame
            body.r_km, body.r_time = r_km, log_time
            body.frame = msg["frame"]
            body.trail.append(r_km)
            body.samples += 1
            body.has_orbit = True if body.has_orbit is None else body.has_orbit
        else:
            q = msg["q"]
            xyzw = (q[1], q[2], q[3], q[0])  # Foxglove order (astrodyn.rotation.quat_to_scalar_last)
            self.changed |= body.xyzw is None
            if body.xyzw is not None and log_time < body.q_time:
                went_back = True
                body.recent_attitudes = RecentAttitudes()
            body.xyzw, body.q_time = xyzw, log_time
            body.recent_attitudes.put(log_time, xyzw)
        self.t = t if went_back else max(self.t, t)
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
                    # the attitude at the position's instant; the newest is it when their times agree
                    q = b.xyzw if b.q_time == b.r_time else b.recent_attitudes.get(b.r_time, b.xyzw)
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
        orbiting = [b for b in self.bodies.values() if len(b.trail)]
        entities = []
        if orbiting and self.radius_km > 0:
            entities.append(central_body_entity(ts, orbiting[0].frame, self.central_name, self.radius_km))
        per_body = max(2, MAX_LIVE_SCENE_POINTS // max(1, len(orbiting)))
        axis_km = 0.1 * self.radius_km if orbiting and self.radius_km > 0 else 1.0
        for b in self.bodies.values():
            if n := len(b.trail):  # evenly spread over the trail, oldest first, the first and newest kept
                keep = np.unique(np.rint(np.linspace(0, n - 1, min(per_body, n))).astype(int))
                entities.append(orbit_line_entity(ts, b.frame, b.name, b.trail.take(keep),
                                                  BODY_COLORS[b.index % len(BODY_COLORS)], b.samples))
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
        self.scene_request_ok = 0.0  # monotonic s from which a subscription's scene request is served again
        view = self

        class Listener(foxglove.ServerListener):
            def on_subscribe(self, client, channel) -> None:
                if channel.topic == SCENE_TOPIC:
                    view.scene_wanted.set()

            def on_playback_control_request(self, request):
                return playback.handle(request)

        capabilities = [foxglove.Capability.Time, *([foxglove.Capability.Services] if services else []),
                        *([foxglove.Capability.PlaybackControl] if playback is not None else [])]
        self._server_args = dict(name=f"astrodyn {scenario}", host=host, capabilities=capabilities,
                                 server_listener=Listener(), supported_encodings=["json"] if services else None,
                                 playback_time_range=None if playback is None else playback.time_range)
        self.server = foxglove.start_server(port=port, **self._server_args)
        self.port = self.server.port  # the one bound (port 0: a free one), kept by a restart
        self.restarts = 0
        self.restarted_at: collections.deque[float] = collections.deque(maxlen=MAX_SERVER_RESTARTS)  # monotonic s
        self._services: list = []
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
        """Send pending raw states, at most ``raw_rate * dt`` of them, the keys that have
        waited longest first (round robin: a key sent leaves the queue and goes to the back
        with its next new state), each state once."""
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
        self._services = services
        self.server.add_services(services)

    def restart(self, guard: ConnectionGuard) -> None:
        """A new server on the same port, for one that stopped accepting connections
        (foxglove-sdk ends its accept loop at the first failed accept, e.g. out of file
        descriptors): every connection of the old one is cut first, so their descriptors
        are released, and the old one is stopped without waiting for it (:meth:`close`).
        Raises what ``start_server`` raises (the port taken meanwhile, still no descriptor)."""
        guard.disconnect_all("restart")
        old, self.server = self.server, None
        _stop_server(old, wait_s=0.0)
        time.sleep(0.2)  # the old server's tasks end and close their sockets
        self.server = self.foxglove.start_server(port=self.port, **self._server_args)
        if self._services:
            self.server.add_services(self._services)
        self.restarts += 1
        self.restarted_at.append(time.monotonic())

    def close(self) -> str | None:
        """Stop the server; at most :data:`CLOSE_TIMEOUT_S`: foxglove-sdk's stop waits for every
        connection, and one that never finished its WebSocket handshake (a half-open TCP
        connection) would hold it forever (SIGTERM then took ``serve`` 13 s: its 10 s wait,
        then SIGKILL).  Returns what went wrong, or None."""
        if self.server is None:
            return None
        server, self.server = self.server, None
        if not _stop_server(server, CLOSE_TIMEOUT_S):
            return (f"the Foxglove server did not stop within {CLOSE_TIMEOUT_S:g} s (a connection that never finished "
                    f"its handshake?); exiting without it")
        return None


def _stop_server(server, wait_s: float) -> bool:
    """``server.stop()`` in a daemon thread, waited for at most ``wait_s`` s; True if it returned."""
    done = threading.Thread(target=server.stop, name="foxglove-stop", daemon=True)
    done.start()
    done.join(wait_s)
    return not done.is_alive()


class LineBudget:
    """At most ``per_window`` lines to stderr per ``window_s`` s; the others are counted and
    said in one line once the window is over (:meth:`flush`).  Thread-safe.  A client that
    sends garbage makes foxglove-sdk log one line per message (measured: 5 MB/s of
    ``Invalid message`` into the viewer's log, beside the recording); this bounds it."""

    def __init__(self, per_window: int = LOG_LINES_PER_WINDOW, window_s: float = LOG_WINDOW_S,
                 prefix: str = "astrodyn viewer: "):
        self.per_window, self.window_s, self.prefix = per_window, window_s, prefix
        self._lock = threading.Lock()
        self._start = -math.inf
        self._used = 0
        self._held = 0  # lines suppressed in the current window
        self.suppressed = 0  # in all

    def say(self, line: str, now: float | None = None) -> bool:
        """Print ``line`` if the budget allows; False if it was suppressed."""
        now = time.monotonic() if now is None else now
        with self._lock:
            self._roll(now)
            if self._used >= self.per_window:
                self._held += 1
                self.suppressed += 1
                return False
            self._used += 1
        print(self.prefix + line, file=sys.stderr, flush=True)
        return True

    def flush(self, now: float | None = None, force: bool = False) -> None:
        """Say how many lines were suppressed, once their window is over (or now: ``force``)."""
        with self._lock:
            if force:
                self._start = -math.inf
            self._roll(time.monotonic() if now is None else now)

    def _roll(self, now: float) -> None:
        if now - self._start < self.window_s:
            return
        if self._held:
            print(f"{self.prefix}{self._held} more lines suppressed in the last {self.window_s:g} s (at most "
                  f"{self.per_window} per {self.window_s:g} s)", file=sys.stderr, flush=True)
        self._start, self._used, self._held = now, 0, 0


class _SdkLogHandler(logging.Handler):
    """foxglove-sdk's log records (Rust ``tracing`` through Python ``logging``) into a :class:`LineBudget`."""

    def __init__(self, budget: LineBudget):
        super().__init__(logging.WARNING)
        self.budget = budget

    def emit(self, record: logging.LogRecord) -> None:
        try:
            self.budget.say(f"foxglove: {record.getMessage()}")
        except Exception:  # a log line must never take the view down
            pass


def route_sdk_log(budget: LineBudget) -> logging.Handler:
    """Send foxglove-sdk's (and its WebSocket library's) warnings and errors through
    ``budget`` instead of Python's last-resort handler (one stderr line per record)."""
    handler = _SdkLogHandler(budget)
    for name in ("foxglove", "tungstenite", "tokio_tungstenite"):
        logger = logging.getLogger(name)
        logger.addHandler(handler)
        logger.setLevel(logging.WARNING)
        logger.propagate = False
    return handler


class _Conn:
    __slots__ = ("first", "acked", "progress", "received", "checked", "peer", "cut", "sent_rate")

    def __init__(self, now: float, acked: int, received: int, peer: str):
        self.first = self.progress = self.checked = now
        self.acked, self.received, self.peer = acked, received, peer
        self.cut = False
        self.sent_rate = 0.0  # bytes a second the client acknowledged over the last check (what the view sent it)


def _tcp_counters(sk: socket.socket) -> tuple[int, int, int, int]:
    """(TCP state, bytes acked by the peer, bytes received from it, bytes waiting in the send
    queue) of a connected TCP socket (Linux ``TCP_INFO``: ``tcpi_bytes_acked`` and
    ``tcpi_bytes_received`` at offsets 120 and 128 since Linux 4.1; ``SIOCOUTQ``)."""
    info = sk.getsockopt(socket.IPPROTO_TCP, socket.TCP_INFO, 256)
    if len(info) < 136:
        raise OSError("TCP_INFO without byte counters (Linux < 4.1)")
    acked, received = struct.unpack_from("<QQ", info, 120)
    outq = array.array("i", [0])
    fcntl.ioctl(sk.fileno(), termios.TIOCOUTQ, outq)
    return info[0], acked, received, outq[0]


class ConnectionGuard:
    """The limits foxglove-sdk (0.30) does not keep, kept from outside it: every
    :data:`GUARD_PERIOD_S` the viewer looks at the TCP connections of its own WebSocket port
    (its descriptors in ``/proc/self/fd``, each one's ``TCP_INFO``) and cuts
    (``shutdown``, so the SDK ends that client and frees its queues):

    - a connection that has not completed its WebSocket handshake within ``handshake_s``
      (nothing sent to it yet): the SDK has no handshake timeout, so a half-open
      connection held a task and a descriptor forever and made the server's stop hang;
    - a client that reads nothing for ``stall_s`` while data waits for it: the SDK drops
      the oldest of at most 1024 queued messages per client but never lets go of the
      client, so each one that stopped reading pinned up to 1024 of the view's largest
      messages (a 200-body scene: 60 KB transforms, 1.8 MB scenes);
    - a client that sends more than ``max_input_per_s`` bytes a second (the SDK buffers
      up to 64 MiB of one message before refusing it);
    - beyond ``max_clients`` connections, the first of :meth:`cut_order` (in their
      handshake, then idle, then the newest).

    It also watches the listening socket: the SDK ends its accept loop at the first failed
    ``accept`` (e.g. out of file descriptors), after which the port refused every client
    while the viewer ran on; :attr:`listener_lost` then says why (the frame loop restarts
    the server).  Linux only (``/proc``); elsewhere :attr:`available` is False and it does
    nothing."""

    def __init__(self, port: int, max_clients: int = MAX_CLIENTS, stall_s: float = CLIENT_STALL_S,
                 handshake_s: float = HANDSHAKE_S, max_input_per_s: float = MAX_CLIENT_INPUT_PER_S,
                 budget: LineBudget | None = None):
        self.port = port
        self.max_clients, self.stall_s, self.handshake_s = max_clients, stall_s, handshake_s
        self.max_input_per_s = max_input_per_s
        self.budget = budget or LineBudget()
        self.flush_also: list[LineBudget] = []  # other budgets whose suppressed counts each check says when due
        self.available = sys.platform.startswith("linux") and os.path.isdir("/proc/self/fd")
        self.conns: dict[int, _Conn] = {}  # socket inode -> what was seen of that connection
        self._other: set[int] = set()  # inodes of sockets that are not the view's port (Zenoh's, ...)
        self.listener: int | None = None  # inode of the listening socket, once seen
        self.listener_lost: str | None = None
        self.cut = collections.Counter()  # reason -> connections cut
        self._said: dict[str, list[str]] = {}  # what this check cut: why -> peers
        self._lock = threading.Lock()
        self._reserve: int | None = None  # a descriptor held back, to look at sockets when none is left
        self._take_reserve()

    def _take_reserve(self) -> None:
        if self._reserve is None:
            try:
                self._reserve = os.open(os.devnull, os.O_RDONLY | os.O_CLOEXEC)
            except OSError:
                pass

    def _spare(self, make):
        """``make()``, and when the process is out of descriptors, ``make()`` again after
        giving back the one held back for this (every use here closes its descriptor at
        once, so that one slot serves them all in turn)."""
        try:
            return make()
        except OSError as exc:
            if exc.errno not in (errno.EMFILE, errno.ENFILE) or self._reserve is None:
                raise
            os.close(self._reserve)
            self._reserve = None
            return make()

    def _sockets(self) -> list[tuple[int, int]]:
        """(descriptor, inode) of every socket this process holds."""
        out = []
        for name in self._spare(lambda: os.listdir("/proc/self/fd")):
            try:
                link = os.readlink(f"/proc/self/fd/{name}")
            except OSError:  # closed meanwhile
                continue
            if link.startswith("socket:["):
                out.append((int(name), int(link[8:-1])))
        return out

    def _open(self, fd: int, inode: int) -> socket.socket | None:
        """A duplicate of descriptor ``fd`` as a socket object, if it is still socket ``inode``."""
        try:
            dup = self._spare(lambda: os.dup(fd))
        except OSError:
            return None
        try:
            if os.fstat(dup).st_ino == inode:
                return socket.socket(fileno=dup)
        except OSError:
            pass
        os.close(dup)
        return None

    def _cut(self, fd: int, inode: int, conn: _Conn, reason: str, why: str) -> None:
        sk = self._open(fd, inode)
        if sk is None:  # gone meanwhile, or no descriptor to look at it: the next check tries again
            return
        with sk:
            try:
                sk.shutdown(socket.SHUT_RDWR)  # the SDK's reads end, its writes fail: it drops the client
            except OSError:
                pass
        conn.cut = True
        self.cut[reason] += 1
        self._said.setdefault(why, []).append(conn.peer)

    def check(self, now: float | None = None) -> None:
        """One look at the connections (see the class)."""
        if not self.available:
            return
        now = time.monotonic() if now is None else now
        with self._lock:
            self._said = {}
            self._check(now)
            self._take_reserve()
            said, self._said = self._said, {}
        for why, peers in said.items():  # one line per reason and check, however many were cut
            more = f" and {len(peers) - 3} more" if len(peers) > 3 else ""
            self.budget.say(f"disconnected WebSocket client{'s' if len(peers) > 1 else ''} {', '.join(peers[:3])}{more}: "
                            f"{why}")
        for budget in (self.budget, *self.flush_also):
            budget.flush(now)

    def _check(self, now: float) -> None:
        present, live, listener_seen = set(), [], False
        for fd, inode in self._sockets():
            present.add(inode)
            if inode == self.listener:
                listener_seen = True
                continue
            if inode in self._other:
                continue
            looked = self._look(fd, inode, now)
            if looked == "listener":
                listener_seen = True
            elif looked is not None:
                live.append(looked)
        self._other &= present
        for inode in [i for i in self.conns if i not in present]:
            del self.conns[inode]
        if self.listener is not None and not listener_seen:
            self.listener_lost = (f"the Foxglove server stopped accepting connections on port {self.port} "
                                  f"({len(present)} sockets open, descriptor limit {_nofile_limit()})")
        if len(live) > self.max_clients:
            order = self.cut_order([conn for _, _, conn in live], now)
            rank = {id(conn): k for k, conn in enumerate(order)}
            over = sorted(live, key=lambda item: rank[id(item[2])])[:len(live) - self.max_clients]
            for fd, inode, conn in over:
                self._cut(fd, inode, conn, "too_many", f"more than {self.max_clients} connections (cut: "
                                                        f"{self.kind_of(conn, now)})")

    @staticmethod
    def kind_of(conn: _Conn, now: float) -> str:
        """Why a connection goes where it goes in :meth:`cut_order`."""
        if conn.acked == 0:
            return "in its handshake"
        if now - conn.first < NEWCOMER_GRACE_S:
            return "the newest"
        return "idle" if conn.sent_rate < IDLE_BYTES_PER_S else "the newest"

    @staticmethod
    def cut_order(conns: list[_Conn], now: float) -> list[_Conn]:
        """The connections in the order they are cut when more than ``max_clients`` are
        open, first cut first: those that have not completed their WebSocket handshake
        (oldest first); those past :data:`NEWCOMER_GRACE_S` the view sent less than
        :data:`IDLE_BYTES_PER_S` over the last check (subscribed to nothing: oldest
        first); then all others, newest first.  So connections that only hold a place
        (half-open, or reading nothing but the time) never keep a newcomer out, and a
        client that receives the view keeps its place against newcomers (it was the
        oldest 16 kept, whatever they did: 16 idle connections kept every later client out).
        A process that opens connections which subscribe and read the view still takes
        places like any client (docs/foxglove.md)."""
        def key(conn: _Conn):
            if conn.acked == 0:
                return (0, conn.first)
            if now - conn.first >= NEWCOMER_GRACE_S and conn.sent_rate < IDLE_BYTES_PER_S:
                return (1, conn.first)
            return (2, -conn.first)
        return sorted(conns, key=key)

    def _look(self, fd: int, inode: int, now: float):
        """None (not the view's port, or gone), "listener", or (fd, inode, conn) of a live
        connection, after cutting it if it broke a limit."""
        sk = self._open(fd, inode)
        if sk is None:
            return None
        with sk:
            try:
                if sk.family not in (socket.AF_INET, socket.AF_INET6) or sk.type != socket.SOCK_STREAM \
                        or sk.getsockname()[1] != self.port:
                    self._other.add(inode)
                    return None
                if sk.getsockopt(socket.SOL_SOCKET, socket.SO_ACCEPTCONN):
                    self.listener = inode
                    return "listener"
                state, acked, received, outq = _tcp_counters(sk)
                host, port = sk.getpeername()[:2]
                peer = f"{host}:{port}"
            except OSError:  # closing, or not a TCP socket after all
                return None
        conn = self.conns.get(inode)
        if conn is None:  # new since the last check: what it sent, it sent since then
            conn = self.conns[inode] = _Conn(now, acked, 0, peer)
            conn.checked = now - GUARD_PERIOD_S
        if conn.cut or state != 1:  # cut already, or closing (not ESTABLISHED)
            return None
        if outq == 0 or acked > conn.acked:
            conn.progress = now
        elapsed = max(now - conn.checked, GUARD_PERIOD_S)
        rate = (received - conn.received) / elapsed
        conn.sent_rate = (acked - conn.acked) / elapsed
        conn.acked, conn.received, conn.checked = acked, received, now
        if acked == 0 and now - conn.first >= self.handshake_s:
            self._cut(fd, inode, conn, "no_handshake", f"no WebSocket handshake within {self.handshake_s:g} s")
        elif now - conn.progress >= self.stall_s:
            self._cut(fd, inode, conn, "not_reading", f"read nothing for {self.stall_s:g} s ({outq} bytes waiting)")
        elif rate > self.max_input_per_s:
            self._cut(fd, inode, conn, "too_much_input",
                      f"sent {rate / 2**20:.1f} MiB/s (at most {self.max_input_per_s / 2**20:g} MiB/s)")
        else:
            return fd, inode, conn
        return None

    def disconnect_all(self, reason: str, stuck_only: bool = False) -> int:
        """Cut every connection of the view's port (before a restart of the server), or only
        the stuck ones (before a stop): those still in their handshake and those with data
        waiting that they do not read.  foxglove-sdk's stop waits for each client's last
        message, so for those it would wait forever; it closes the others properly.  How
        many were cut, counted under ``reason``."""
        if not self.available:
            return 0
        n = 0
        with self._lock:
            for fd, inode in self._sockets():
                if inode in self._other or inode == self.listener:
                    continue
                sk = self._open(fd, inode)
                if sk is None:
                    continue
                with sk:
                    try:
                        if sk.family not in (socket.AF_INET, socket.AF_INET6) or sk.getsockname()[1] != self.port \
                                or sk.getsockopt(socket.SOL_SOCKET, socket.SO_ACCEPTCONN):
                            continue
                        if stuck_only:
                            _, acked, _, outq = _tcp_counters(sk)
                            if acked > 0 and outq == 0:  # handshake done, nothing waiting: the SDK closes it
                                continue
                        sk.shutdown(socket.SHUT_RDWR)
                        n += 1
                    except OSError:
                        continue
                if inode in self.conns:
                    self.conns[inode].cut = True
            if not stuck_only:
                self.listener, self.listener_lost = None, None
            self._take_reserve()
        if n:
            self.cut[reason] += n
        return n

    def run(self, stop: StopFlag) -> None:
        """Check every :data:`GUARD_PERIOD_S` until ``stop`` (the body of a daemon thread)."""
        while stop.why is None:
            time.sleep(GUARD_PERIOD_S)
            try:
                self.check()
            except Exception as exc:  # the guard must never take the view down
                self.budget.say(f"connection guard: {type(exc).__name__}: {exc}")


def _nofile_limit() -> int:
    return resource.getrlimit(resource.RLIMIT_NOFILE)[0]


def raise_descriptor_limit(cap: int = MAX_DESCRIPTORS) -> int:
    """Raise this process's soft limit of open descriptors to its hard limit (at most
    ``cap``): each WebSocket connection takes one, and foxglove-sdk stops accepting for
    good at the first ``accept`` that fails (a typical soft limit is 1024).  The new limit."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    want = cap if hard == resource.RLIM_INFINITY else min(hard, cap)
    if want > soft:
        try:
            resource.setrlimit(resource.RLIMIT_NOFILE, (want, hard))
            soft = want
        except (ValueError, OSError):
            pass
    return soft


def expendable_under_memory_pressure() -> None:
    """Ask the kernel to end this process first when the machine runs out of memory
    (``oom_score_adj`` 1000): the view is restarted by ``serve`` and holds nothing that is
    not in the recording, the logger does."""
    try:
        Path("/proc/self/oom_score_adj").write_text("1000")
    except OSError:
        pass


class PlaybackBar:
    """Foxglove's playback bar (play, pause, speed, seek) wired to a replay's control verbs
    (``replay --foxglove PORT --foxglove-playback``): a PlaybackControlRequest becomes
    ``seek`` (when the bar was dragged), ``rate`` (when the speed changed), then ``resume`` or
    ``pause``, sent with the replay's control token, which this viewer holds for it; the
    replay's state after them is broadcast to the clients (a PlaybackState with the
    request's id).  ``time_range``: the recording's span in ns since the Unix epoch;
    ``epoch_ns`` the scenario epoch (``t`` = (ns - epoch_ns) / 1e9); ``scenario``: the
    replay's control scenario.

    The SDK's callback (:meth:`handle`) never waits: it leaves the request for the bar's own
    thread and returns.  That thread sends one request's verbs at a time (each a bus round
    trip of tens of ms); requests that come meanwhile replace each other, so only the newest
    is sent next and the others, superseded, get no answer of their own (the newest's answer
    is the state).  A burst of requests from one client (a dragged bar sends a stream of
    seeks) therefore costs the replay a few round trips and never holds up the view's frames
    for the other clients (it stopped them for 4.75 s per 100 requests when the callback
    sent the verbs itself).  A refused request (a speed out of the replay's range) is
    answered with the replay's state as ``status`` then gives it, or the last state known;
    the reason goes to stderr through ``log`` (a :class:`LineBudget`)."""

    def __init__(self, scenario: str, token: str, time_range: tuple[int, int], epoch_ns: int,
                 log: LineBudget | None = None):
        self.scenario, self.token, self.time_range, self.epoch_ns = scenario, token, time_range, epoch_ns
        self.log = log or LineBudget()
        self.session = None  # set once the bus session is open (open_on)
        self.publish = None  # broadcasts a PlaybackState to every client (open_on)
        self.speed = 1.0
        self.last_reply: dict = {}  # the replay's newest status reply seen
        self.superseded = 0  # requests replaced by a newer one before they were sent
        self.handled = 0
        self._wake = threading.Condition()
        self._newest: tuple | None = None  # (play, speed, seek ns or None, request id) not yet sent

    def open_on(self, session, publish) -> None:
        """Start sending requests on the bus ``session``; ``publish(state)`` broadcasts each
        answer.  The WebSocket server starts first: a request that came before is kept (the
        newest) and sent now."""
        self.session, self.publish = session, publish
        threading.Thread(target=self._run, name="view-playback", daemon=True).start()

    def handle(self, request) -> None:
        """The SDK's callback for a PlaybackControlRequest: keep it as the newest and return
        at once (no answer now: the bar's thread broadcasts it)."""
        from foxglove.websocket import PlaybackCommand

        seek = request.seek_time
        item = (request.playback_command == PlaybackCommand.Play, float(request.playback_speed),
                None if seek is None else int(seek), str(request.request_id))
        with self._wake:
            if self._newest is not None:
                self.superseded += 1
            self._newest = item
            self._wake.notify()
        return None

    def _run(self) -> None:
        while True:
            with self._wake:
                while self._newest is None:
                    self._wake.wait()
                item, self._newest = self._newest, None
            try:
                state = self.apply(*item)
                self.publish(state)
            except Exception as exc:  # the bar must never take the view down
                self.log.say(f"playback request failed: {type(exc).__name__}: {exc}")
            self.handled += 1

    def _send(self, verb: str, args: dict | None = None) -> dict:
        # require_reply: a replay that has ended answers nothing, which is not a success
        replies = bus.send_control(self.session, self.scenario, verb, args, timeout_s=5.0, token=self.token,
                                   require_reply=True)
        reply = next((r for r in replies if isinstance(r, dict)), {})
        if "error" in reply:
            raise ValueError(str(reply["error"]))
        self.last_reply = reply
        return reply

    def apply(self, play: bool, speed: float, seek_ns: int | None, request_id: str):
        """Send one request's verbs; the PlaybackState after them (module docstring)."""
        from foxglove.websocket import PlaybackState, PlaybackStatus

        steps = [("seek", {"t": (seek_ns - self.epoch_ns) / 1e9})] if seek_ns is not None else []
        if math.isfinite(speed) and speed > 0 and speed != self.speed:
            steps.append(("rate", {"factor": speed}))
        steps.append(("resume" if play else "pause", None))
        did_seek = refused = False
        for verb, args in steps:  # each part on its own: a refused speed still plays or pauses
            try:
                self._send(verb, args)
            except (ValueError, bus.BusError) as exc:  # the bar shows the replay's state; the reason goes to stderr
                self.log.say(f"playback request refused: {exc}")
                refused = True
                continue
            did_seek |= verb == "seek"
        if refused:  # the state after what went through (the last reply may predate a refused step)
            try:
                self._send("status")
            except (ValueError, bus.BusError):
                pass  # the last state known
        reply = self.last_reply
        status = {"running": PlaybackStatus.Playing, "waiting": PlaybackStatus.Playing, "paused": PlaybackStatus.Paused,
                  "finished": PlaybackStatus.Ended, "stopped": PlaybackStatus.Ended}.get(reply.get("state"),
                                                                                         PlaybackStatus.Paused)
        factor = reply.get("real_time_factor")
        if isinstance(factor, (int, float)) and math.isfinite(factor) and factor > 0:
            self.speed = float(factor)
        t = reply.get("t")
        now = self.epoch_ns + int(round(float(t) * 1e9)) if isinstance(t, (int, float)) and math.isfinite(t) \
            else self.time_range[0]
        return PlaybackState(status=status, current_time=max(self.time_range[0], min(self.time_range[1], now)),
                             playback_speed=self.speed, did_seek=did_seek, request_id=request_id)


def playback_bar(args, epoch_ns: int, log: LineBudget | None = None) -> PlaybackBar | None:
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
    return PlaybackBar(control_scenario(args), token, (lo, hi), epoch_ns, log)


def control_scenario(args: argparse.Namespace) -> str:
    """The scenario of the control keys the services and the playback bar use (``--control-scenario``,
    by default ``--scenario``: a replay under ``--control-scenario`` keeps its recorded data keys)."""
    return args.control_scenario or args.scenario


#: The arguments each control verb takes besides the token (docs/clients.md).
_CONTROL_ARGS = {
    "rate": {"factor": {"type": ["number", "string"],
                        "description": 'real-time factor, or "inf": as fast as possible'}},
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
    when stopped, 1 when the server or the bus cannot start (or the server cannot be
    restarted), 2 for bad arguments."""
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
    expendable_under_memory_pressure()
    raise_descriptor_limit()
    sdk_log = LineBudget()  # its own budget: the guard's lines are not crowded out by the SDK's
    route_sdk_log(sdk_log)
    budget = LineBudget()
    stop = StopFlag()
    secret = auth.secret_from_environment()
    samples = ViewerSamples(args.scenario, args.from_logger, auth.Verifier(secret) if secret is not None else None)
    scene = LiveScene(epoch_ns, central, orbiting)
    try:
        playback = playback_bar(args, epoch_ns, budget)
    except (ValueError, OSError) as exc:
        print(f"astrodyn viewer: error: {exc}", file=sys.stderr)
        return 2
    try:
        view = _View(args.host, args.port, args.scenario, args.raw_rate, services=bool(verbs), playback=playback)
    except Exception as exc:  # foxglove-sdk: port taken, bad host
        print(f"astrodyn viewer: error: cannot start the Foxglove server on {args.host}:{args.port}: {exc}",
              file=sys.stderr)
        return 1
    guard = ConnectionGuard(view.port, args.max_clients, args.client_stall_timeout, args.handshake_timeout,
                            budget=budget)
    guard.flush_also.append(sdk_log)
    guard.check()  # finds the listening socket while descriptors are plenty
    threading.Thread(target=guard.run, args=(stop,), name="view-guard", daemon=True).start()
    failure = None
    try:
        with bus.session_from_args(args) as session:
            base = f"{messages.PREFIX}/{args.scenario}"
            subs = [] if args.from_logger else [session.declare_subscriber(key, samples.latest)
                                                for key in (f"{base}/**", f"{base}/@batch/*")]
            if verbs:
                view.add_control_services(session, control_scenario(args), verbs)
            if playback is not None:
                playback.open_on(session, lambda state: view.server.broadcast_playback_state(state))
            print(json.dumps({"foxglove": f"ws://{args.host}:{view.port}", "scenario": args.scenario,
                              "control_scenario": control_scenario(args),
                              "authenticated": samples.verifier is not None}), flush=True)
            failure = run_view_frames(session, 1.0 / args.rate, stop, samples, scene, view, guard)
            for sub in subs:
                sub.undeclare()
    except bus.BusError as exc:
        print(f"astrodyn viewer: error: {exc}", file=sys.stderr)
        return 1
    finally:
        guard.disconnect_all("stop", stuck_only=True)  # the SDK's stop would wait for them forever
        stuck = view.close()
        if stuck:
            print(f"astrodyn viewer: warning: {stuck}", file=sys.stderr, flush=True)
        budget.flush(force=True)
        sdk_log.flush(force=True)
    if failure:
        print(f"astrodyn viewer: error: {failure}", file=sys.stderr, flush=True)
    print(json.dumps({"viewer": "stopped", "reason": stop.why or failure, "received": samples.latest.received,
                      "bodies": len(scene.bodies), "invalid": scene.invalid, "rejected": samples.rejected,
                      "disconnected": dict(guard.cut), "log_lines_suppressed": budget.suppressed + sdk_log.suppressed,
                      "server_restarts": view.restarts}), flush=True)
    return 1 if failure else 0


def _env_default(name: str, fallback: float) -> str:
    return os.environ.get(name) or repr(fallback)


def parse_viewer_arguments(argv: list[str] | None) -> argparse.Namespace:
    """The viewer's command line (``--scenario``, ``--port``, ``--rate`` ..., and the bus options)."""
    ap = argparse.ArgumentParser(prog="astrodyn.service.viewer", description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", required=True, help="scenario name of the data keys (astrodyn/<scenario>/...)")
    ap.add_argument("--control-scenario", default=None,
                    help="scenario name of the control keys the services and the playback bar use (default: --scenario)")
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
    ap.add_argument("--max-clients", type=int, default=_env_default("ASTRODYN_VIEWER_MAX_CLIENTS", MAX_CLIENTS),
                    help=f"most WebSocket connections at a time; the newest beyond are cut (default {MAX_CLIENTS}, "
                         "or $ASTRODYN_VIEWER_MAX_CLIENTS)")
    ap.add_argument("--client-stall-timeout", type=float, metavar="S",
                    default=_env_default("ASTRODYN_VIEWER_STALL_S", CLIENT_STALL_S),
                    help=f"cut a client that reads nothing for S s while data waits for it (default {CLIENT_STALL_S:g}, "
                         "or $ASTRODYN_VIEWER_STALL_S)")
    ap.add_argument("--handshake-timeout", type=float, metavar="S",
                    default=_env_default("ASTRODYN_VIEWER_HANDSHAKE_S", HANDSHAKE_S),
                    help=f"cut a connection that has not completed its WebSocket handshake after S s (default "
                         f"{HANDSHAKE_S:g}, or $ASTRODYN_VIEWER_HANDSHAKE_S)")
    bus.add_bus_arguments(ap)
    return ap.parse_args(argv)


def checked_viewer_arguments(args: argparse.Namespace) -> tuple[int, dict, set[str] | None, list[str]]:
    """``(epoch_unix_ns, central_body table, names of the bodies with an orbit or None,
    control verbs)`` of valid arguments; ValueError (or OSError, MessageError) naming the
    option otherwise: ``--rate`` in (0, 1000], ``--raw-rate`` in (0, 100000], ``--port``
    0..65535, ``--services`` verbs of the run."""
    messages.check_name(args.scenario, "--scenario")
    if args.control_scenario is not None:
        messages.check_name(args.control_scenario, "--control-scenario")
    for name in ("rate", "raw_rate"):
        value = getattr(args, name)
        if not (math.isfinite(value) and 0 < value <= 1000 * (100 if name == "raw_rate" else 1)):
            raise ValueError(f"--{name.replace('_', '-')}: expected a number in (0, "
                             f"{1000 * (100 if name == 'raw_rate' else 1)}], got {value}")
    if not 0 <= args.port <= 65535:
        raise ValueError(f"--port: expected 0..65535, got {args.port}")
    if not 1 <= args.max_clients <= 10_000:
        raise ValueError(f"--max-clients ($ASTRODYN_VIEWER_MAX_CLIENTS): expected 1..10000, got {args.max_clients}")
    for name, env in (("client_stall_timeout", "ASTRODYN_VIEWER_STALL_S"), ("handshake_timeout", "ASTRODYN_VIEWER_HANDSHAKE_S")):
        value = getattr(args, name)
        if not (math.isfinite(value) and 1.0 <= value <= 86400.0):
            raise ValueError(f"--{name.replace('_', '-')} (${env}): expected seconds in [1, 86400], got {value}")
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
        self._shown: dict[str, bytes] = {}  # from_logger: key -> the payload taken last (the logger's keys)

    def newest(self, session) -> dict[str, tuple[bytes, bytes | None]]:
        """key -> (payload, attachment) of the samples to show at this view frame: those
        new since the last frame (the logger answers every key's newest at each query;
        one it already answered is not taken again, so each state is sent once)."""
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
        shown = self._shown
        out = {k: item for k, item in out.items() if shown.get(k) != item[0]}
        if len(shown) + len(out) > MAX_KEYS_CACHED:  # a logger of more keys than any scene: start over
            shown.clear()
        shown.update((k, item[0]) for k, item in out.items())
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


def run_view_frames(session, period: float, stop: StopFlag, samples: ViewerSamples, scene: LiveScene, view: _View,
                    guard: ConnectionGuard | None = None) -> str | None:
    """Until ``stop``: every ``period`` s of wall time (longer for scenes of more than
    :data:`MAX_TRANSFORMS_PER_S` ``* period`` bodies) take the newest samples into the scene
    and send one view frame.  When ``guard`` says the server stopped accepting connections,
    restart it; returns why the view had to end (the restart failed), or None."""
    next_frame = next_scene = time.monotonic()
    while stop.why is None:
        if guard is not None and guard.listener_lost:
            lost = guard.listener_lost
            if len(view.restarted_at) == MAX_SERVER_RESTARTS and time.monotonic() - view.restarted_at[0] < 60.0:
                return f"{lost} again, after {MAX_SERVER_RESTARTS} restarts within a minute"  # serve restarts the process
            try:
                view.restart(guard)
            except Exception as exc:  # the port taken meanwhile, still no descriptor: serve restarts the process
                return f"{lost}; restarting it failed: {exc}"
            print(f"astrodyn viewer: warning: {lost}; restarted it on the same port", file=sys.stderr, flush=True)
        now = time.monotonic()
        if now < next_frame:
            time.sleep(min(next_frame - now, 0.05))
            continue
        frame_period = max(period, len(scene.bodies) / MAX_TRANSFORMS_PER_S)
        next_frame = max(next_frame + frame_period, now)
        take_samples(samples.newest(session), samples, scene, view)
        if scene.bodies:  # what no client subscribes to is not built (has_sinks)
            next_scene = send_view_frame(scene, view, frame_period, now, next_scene)
    return None


def take_samples(newest: dict[str, tuple[bytes, bytes | None]], samples: ViewerSamples, scene: LiveScene,
                 view: _View) -> None:
    """The accepted, valid states of ``newest`` into ``scene``, and every state or closed-loop
    sample into the raw channels waiting to be sent (``view.pending``: the newest unsent
    state of each key, in the order the keys first waited, so :meth:`_View.forward` serves
    them round robin; a new state of a waiting key replaces its older one in place)."""
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
            if log_time is not None:  # a key already waiting keeps its place in the round robin
                view.pending[k] = (p, log_time)


def send_view_frame(scene: LiveScene, view: _View, frame_period: float, now: float, next_scene: float) -> float:
    """One view frame (the transforms, the time, the raw channels' share of the frame) and,
    when due, wanted or changed, the scene update; returns the time the next scene update
    is due (monotonic s)."""
    lt = scene.log_time()
    if view.tf.has_sinks():
        view.tf.log(_VIEW_JSON.encode(scene.transforms()), log_time=lt)  # 10x json.dumps
    view.server.broadcast_time(lt)
    view.forward(frame_period)
    wanted = view.scene_wanted.is_set() and now >= view.scene_request_ok  # at most once a SCENE_REQUEST_MIN_S
    if view.scene.has_sinks() and (now >= next_scene or wanted or scene.changed):
        view.scene_wanted.clear()
        scene.changed = False
        view.scene.log(_VIEW_JSON.encode(scene.scene()), log_time=lt)
        next_scene = now + SCENE_PERIOD_S
        view.scene_request_ok = now + SCENE_REQUEST_MIN_S
    return next_scene


if __name__ == "__main__":
    raise SystemExit(main())
