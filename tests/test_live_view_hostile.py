"""The live view (``serve --foxglove``, ``replay --foxglove``) under hostile and careless
WebSocket clients (docs/foxglove.md, "Clients that misbehave"; docs/reliability.md).

Every client here is a real TCP client of a real ``serve`` / ``replay`` / viewer process:
raw sockets speaking RFC 6455 by hand where the attack needs bytes no library would send
(garbage, a half-open connection, a client that never reads, fragments past the server's
message limit), the ``websockets`` package for the well-behaved client that follows
docs/foxglove.md.  What is asserted are facts found outside the viewer: the TCP connection
closed by the server, the viewer's RSS and stderr read from ``/proc``, the recording
compared payload for payload with the states the numeric core computes for the same
config, the time ``serve`` takes to exit after SIGTERM.  Processes are started here and
stopped by their PIDs.
"""

from __future__ import annotations

import base64
import json
import os
import resource
import signal
import socket
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

import psutil
import pytest
from mcap.reader import make_reader

from astrodyn import messages
from astrodyn.service.children import stop_process

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _recordings import assert_one_satellite_payloads, leo_recording, one_satellite_scene, record, scenario_head

pytestmark = pytest.mark.network

ASTRODYN = [sys.executable, "-m", "astrodyn"]
SUBPROTOCOL = "foxglove.sdk.v1"  # what foxglove-sdk 0.30 accepts (docs/foxglove.md)


# ----------------------------------------------------------------------------- a raw client


class RawClient:
    """A WebSocket client on a plain socket: the handshake and frames of RFC 6455, nothing else."""

    def __init__(self, url: str, subprotocol: str | None = SUBPROTOCOL, rcvbuf: int | None = None):
        host, port = url.removeprefix("ws://").rsplit(":", 1)
        self.sock = socket.socket()
        if rcvbuf:  # a small receive buffer: a client that stops reading stalls the server sooner
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
        self.sock.settimeout(10)
        self.sock.connect((host, int(port)))
        key = base64.b64encode(os.urandom(16)).decode()
        head = (f"GET / HTTP/1.1\r\nHost: {host}:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n")
        if subprotocol:
            head += f"Sec-WebSocket-Protocol: {subprotocol}\r\n"
        self.sock.sendall((head + "\r\n").encode())
        buf = b""
        while b"\r\n\r\n" not in buf:
            chunk = self.sock.recv(4096)
            if not chunk:
                break
            buf += chunk
        response, _, self.buf = buf.partition(b"\r\n\r\n")
        self.status = response.split(b"\r\n", 1)[0].decode(errors="replace")

    def send(self, payload: bytes, opcode: int = 1, fin: bool = True) -> None:
        """One frame, masked with a zero key (masking is required; the key's value is not)."""
        n = len(payload)
        size = struct.pack("!B", 0x80 | n) if n < 126 else struct.pack("!BH", 0x80 | 126, n) if n < 65536 \
            else struct.pack("!BQ", 0x80 | 127, n)
        self.sock.sendall(struct.pack("!B", (0x80 if fin else 0) | opcode) + size + b"\0\0\0\0" + payload)

    def _need(self, n: int) -> None:
        while len(self.buf) < n:
            chunk = self.sock.recv(1 << 16)
            if not chunk:
                raise ConnectionError("closed by the server")
            self.buf += chunk

    def recv(self) -> tuple[int, bytes]:
        """(opcode, payload) of the next frame."""
        self._need(2)
        n, off = self.buf[1] & 0x7F, 2
        if n == 126:
            self._need(4)
            n, off = struct.unpack_from("!H", self.buf, 2)[0], 4
        elif n == 127:
            self._need(10)
            n, off = struct.unpack_from("!Q", self.buf, 2)[0], 10
        self._need(off + n)
        op, payload, self.buf = self.buf[0] & 0x0F, self.buf[off:off + n], self.buf[off + n:]
        return op, payload

    def channels(self, want: set[str], timeout: float = 30.0) -> dict[str, int]:
        """topic -> channel id of the advertised channels, read until every topic of ``want`` came."""
        found: dict[str, int] = {}
        deadline = time.monotonic() + timeout
        while not want <= set(found) and time.monotonic() < deadline:
            op, payload = self.recv()
            if op == 1 and json.loads(payload).get("op") == "advertise":
                found.update((ch["topic"], ch["id"]) for ch in json.loads(payload)["channels"])
        assert want <= set(found), f"never advertised: {want - set(found)}"
        return found

    def subscribe(self, ids: list[int]) -> None:
        self.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": k, "channelId": c}
                                                                   for k, c in enumerate(ids)]}).encode())

    def closed_by_server(self, timeout: float) -> bool:
        """Read (and drop) everything until the server closes the connection; False if it
        is still open after ``timeout`` s."""
        return _server_closes(self.sock, timeout)

    def close(self) -> None:
        self.sock.close()


def _server_closes(sock: socket.socket, timeout: float) -> bool:
    """Whether the server closes ``sock`` within ``timeout`` s (what it sends is dropped)."""
    deadline = time.monotonic() + timeout
    sock.settimeout(0.5)
    while time.monotonic() < deadline:
        try:
            if not sock.recv(1 << 20):
                return True
        except TimeoutError:
            continue
        except OSError:  # reset
            return True
    return False


def _toggle_scene_subscription(url: str, seconds: float) -> tuple[float, float]:
    """A client that reads everything and subscribes to and unsubscribes from the scene
    every 5 ms for ``seconds``; the monotonic times it started and ended."""
    c = _connect(url)
    scene = c.channels({"foxglove/scene"})["foxglove/scene"]

    def drain() -> None:
        try:
            while True:
                c.recv()
        except OSError:
            pass

    threading.Thread(target=drain, daemon=True).start()
    t0 = time.monotonic()
    k = 0
    while time.monotonic() < t0 + seconds:
        c.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": k, "channelId": scene}]}).encode())
        c.send(json.dumps({"op": "unsubscribe", "subscriptionIds": [k]}).encode())
        k += 1
        time.sleep(0.005)
    t1 = time.monotonic()
    c.close()
    return t0, t1


def _connect(url: str, timeout: float = 60.0, **kw) -> RawClient:
    """A RawClient, retrying while the view's server starts."""
    deadline = time.monotonic() + timeout
    while True:
        try:
            return RawClient(url, **kw)
        except OSError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.2)


class Reader(threading.Thread):
    """A well-behaved client (the ``websockets`` package, as docs/foxglove.md's "Checked how"):
    subscribes to ``topics`` and reads everything until told to stop, counting bytes and
    keeping the messages of each topic."""

    def __init__(self, url: str, topics: set[str]):
        super().__init__(daemon=True)
        self.url, self.topics = url, topics
        self.channels: dict[str, dict] = {}
        self.advertised_at: dict[str, list[float]] = {}  # topic -> when each advertisement of it came (monotonic s)
        self.time_frames: list[float] = []  # when each of the server's time messages (one a view frame) came
        self.got: dict[str, list] = {}
        self.server: dict = {}
        self.bytes = 0
        self.started_at = self.error = None
        self.done = threading.Event()
        self.halt = threading.Event()

    def run(self) -> None:
        from websockets.sync.client import connect

        try:
            deadline = time.monotonic() + 60
            while True:
                try:
                    ws = connect(self.url, subprotocols=[SUBPROTOCOL], max_size=None, open_timeout=5)
                    break
                except OSError:
                    if time.monotonic() > deadline:
                        raise
                    time.sleep(0.2)
            self.subprotocol = ws.subprotocol
            sub_topic: dict[int, str] = {}
            with ws:
                while not self.halt.is_set():
                    try:
                        frame = ws.recv(timeout=0.5)
                    except TimeoutError:
                        continue
                    self.bytes += len(frame)
                    if isinstance(frame, str):
                        msg = json.loads(frame)
                        if msg["op"] == "serverInfo":
                            self.server = msg
                        elif msg["op"] == "advertise":
                            new = [ch for ch in msg["channels"] if ch["topic"] in self.topics]
                            self.channels.update((ch["topic"], ch) for ch in msg["channels"])
                            for ch in msg["channels"]:
                                self.advertised_at.setdefault(ch["topic"], []).append(time.monotonic())
                            subs = [{"id": len(sub_topic) + i, "channelId": ch["id"]} for i, ch in enumerate(new)]
                            sub_topic.update((s["id"], ch["topic"]) for s, ch in zip(subs, new))
                            if subs:
                                ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
                            if self.started_at is None and self.topics <= set(sub_topic.values()):
                                self.started_at = time.monotonic()
                    elif frame[0] == 1:
                        sub_id, ts = struct.unpack_from("<IQ", frame, 1)
                        self.got.setdefault(sub_topic[sub_id], []).append((time.monotonic(), ts, frame[13:]))
                    elif frame[0] == 2:  # time (ws-protocol server binary opcode 2)
                        self.time_frames.append(time.monotonic())
        except Exception as exc:  # reported by the test
            self.error = exc
        finally:
            self.done.set()

    def stop(self) -> None:
        self.halt.set()
        self.done.wait(10)

    def wait_subscribed(self, timeout: float = 60.0) -> None:
        deadline = time.monotonic() + timeout
        while self.started_at is None and self.error is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert self.started_at is not None, f"the reader never subscribed: {self.error!r}"


def _viewer_of(parent: subprocess.Popen, timeout: float = 30.0) -> psutil.Process:
    """The viewer process started by ``parent`` (serve or replay)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for child in psutil.Process(parent.pid).children(recursive=True):
            try:
                if "astrodyn.service.viewer" in " ".join(child.cmdline()):
                    return child
            except psutil.NoSuchProcess:
                continue
        time.sleep(0.1)
    raise AssertionError("no viewer process")


def _stderr_path(proc: psutil.Process) -> Path:
    return Path(os.readlink(f"/proc/{proc.pid}/fd/2"))


def _replay(rec: Path, rate: float, env: dict | None = None) -> tuple[subprocess.Popen, str]:
    replay = subprocess.Popen([*ASTRODYN, "replay", str(rec), "--rate", str(rate), "--foxglove", "0", "--wait", "30",
                               "--quiet"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                              env={**os.environ, **(env or {})})
    return replay, json.loads(replay.stdout.readline())["foxglove"]


# ----------------------------------------------------------------------------- the tests

STALL_S = 3.0  # the viewer's --client-stall-timeout in these tests (default 15 s)
SCENE_REQUEST_MIN_S = 1.0  # astrodyn.service.viewer.SCENE_REQUEST_MIN_S: a subscription's scene, at most this often


def test_clients_that_stop_reading_are_cut_and_the_view_memory_stays_bounded(tmp_path):
    """Six clients subscribe to the transforms and the scene of a 200-body replay and never
    read again (a frozen browser tab, or an attacker).  Before: foxglove-sdk kept each one
    forever with up to 1024 of the view's largest messages queued (measured: +80 MB of
    viewer RSS per such client on a 200-body scene, growing about 1 MB/s each).  Now the
    server closes each connection once it has read nothing for the stall timeout; the
    viewer's RSS grows by at most what the view sent each of them until then (the byte rate
    a reading client measures, times the stall timeout plus the guard's period and a
    second), plus 40 MB for the allocator; a well-behaved client reads on throughout."""
    rec = tmp_path / "many.mcap"
    record(rec, scenario_head("many", "100 s", "2 Hz", central_body="earth") + WALKER_200)
    replay, url = _replay(rec, 6, {"ASTRODYN_VIEWER_STALL_S": str(STALL_S)})
    stalled: list[RawClient] = []
    reader = Reader(url, {"foxglove/tf", "foxglove/scene"})
    try:
        viewer = _viewer_of(replay)
        reader.start()
        reader.wait_subscribed()
        time.sleep(1.0)
        rss0 = viewer.memory_info().rss
        t0, bytes0 = time.monotonic(), reader.bytes
        for _ in range(6):
            c = _connect(url, rcvbuf=4096)
            ids = c.channels({"foxglove/tf", "foxglove/scene"})
            c.subscribe([ids["foxglove/tf"], ids["foxglove/scene"]])
            stalled.append(c)
        rss_max, window_end = rss0, time.monotonic() + STALL_S + 4.0
        while time.monotonic() < window_end:
            rss_max = max(rss_max, viewer.memory_info().rss)
            time.sleep(0.1)
        rate = (reader.bytes - bytes0) / (time.monotonic() - t0)  # what the view sends one client, B/s
        cut = [c.closed_by_server(timeout=2.0) for c in stalled]
        late = [t for t, _, _ in reader.got.get("foxglove/tf", []) if t > window_end - 1.0]
        alive = viewer.is_running()
        reader.stop()
    finally:
        for c in stalled:
            c.close()
        stop_process(replay)
    assert all(cut), f"connections left open by the server: {cut.count(False)} of {len(cut)}"
    assert alive and reader.error is None and late, (alive, reader.error)
    bound = len(stalled) * rate * (STALL_S + 2.0) + 40 * 2**20
    assert rss_max - rss0 <= bound, f"viewer RSS +{(rss_max - rss0) / 2**20:.0f} MB > {bound / 2**20:.0f} MB"


WALKER_200 = """
[walker]
prefix = "sat"
i = "53 deg"
t = 200
p = 10
f = 1
altitude = "550 km"
model = "kepler"
"""


def test_garbage_from_clients_never_crashes_the_view_nor_floods_its_log(tmp_path):
    """Against a replay's view: an HTTP request that is no upgrade, random bytes, a wrong or
    missing subprotocol, invalid JSON and unknown ops, subscriptions to channels that do not
    exist and 10,000 times to the same one, a 80 MiB text message in 1 MiB fragments,
    3 s of invalid frames as fast as the socket takes them and 100 connections opened and
    dropped (half of them reset).  The view stays up and listens on loopback only; the
    malformed requests get error statuses, the oversized message and the flood a closed
    connection; the viewer's stderr (beside the recording under serve) holds a few dozen
    lines, not one per bad frame (before: 5 MB a second); and a client that follows
    docs/foxglove.md still gets the channels, schemas, transforms and scene it describes."""
    rec = tmp_path / "rec.mcap"
    leo_recording(rec, name="hv", duration="600 s", rate="2 Hz")
    replay, url = _replay(rec, 5, {"ASTRODYN_VIEWER_HANDSHAKE_S": "2"})
    host, port = url.removeprefix("ws://").rsplit(":", 1)
    try:
        viewer = _viewer_of(replay)
        raw = messages.orbit_key("hv", "leo")
        probe = _connect(url)
        ids = probe.channels({"foxglove/tf", raw})
        probe.close()
        half_open = socket.create_connection((host, int(port)), timeout=5)  # never sends its handshake

        s = socket.create_connection((host, int(port)), timeout=5)  # no upgrade
        s.sendall(b"GET / HTTP/1.1\r\nHost: x\r\n\r\n")
        assert not s.recv(1024).startswith(b"HTTP/1.1 101")
        s.close()
        s = socket.create_connection((host, int(port)), timeout=5)  # garbage
        try:
            s.sendall(os.urandom(65536))
        except OSError:
            pass
        assert _server_closes(s, 5)
        s.close()
        for proto in ("foxglove.websocket.v1", None):
            assert " 400 " in RawClient(url, subprotocol=proto).status

        bad = RawClient(url)
        for text in (b"{", b"[]", b"null", b'{"op": 5}', b'{"op": "nope"}', b'{"op": "subscribe"}',
                     b'{"op":"subscribe","subscriptions":[{"id":-1,"channelId":1e99}]}', b"\x00"):
            bad.send(text)
        bad.send(b"\x99garbage", opcode=2)
        bad.subscribe([10**6 + i for i in range(100)])
        statuses = []
        while len(statuses) < 10:
            op, payload = bad.recv()
            if op == 1 and json.loads(payload)["op"] == "status":
                statuses.append(json.loads(payload)["message"])
        assert any("Invalid message" in m for m in statuses) and any("Unknown channel" in m for m in statuses)
        bad.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": i, "channelId": ids["foxglove/tf"]}
                                                                  for i in range(10_000)]}).encode())
        bad.close()

        big = RawClient(url)  # 80 MiB: past the SDK's 64 MiB message limit
        try:
            big.send(b"a" * 2**20, fin=False)
            for _ in range(79):
                big.send(b"a" * 2**20, opcode=0)
        except OSError:
            pass
        assert _server_closes(big.sock, 5)
        big.close()
        utf = RawClient(url)  # a text frame that is not UTF-8
        utf.send(b"\xff\xfe")
        assert _server_closes(utf.sock, 5)
        utf.close()

        flood = RawClient(url)
        flood.sock.settimeout(0.5)
        frames, t_end = b"\x81\x81\0\0\0\0{" * 2000, time.monotonic() + 3.0
        try:
            while time.monotonic() < t_end:
                flood.sock.sendall(frames)
        except OSError:  # cut, or the server stopped reading it
            pass
        flood.close()

        for k in range(100):
            c = socket.create_connection((host, int(port)), timeout=5)
            if k % 2:
                c.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
            c.close()

        reader = Reader(url, {"foxglove/tf", "foxglove/scene", raw})
        reader.start()
        reader.wait_subscribed()
        time.sleep(0.5)
        toggles = _toggle_scene_subscription(url, seconds=2.0)  # each subscription asks for the scene
        time.sleep(0.5)
        reader.stop()
        half_open_cut = _server_closes(half_open, 1.0)
        half_open.close()
        alive = viewer.is_running()
        listening = [c.laddr for c in viewer.net_connections(kind="inet") if c.status == psutil.CONN_LISTEN
                     and c.laddr.port == int(port)]
        log = _stderr_path(viewer).read_text(errors="replace")
    finally:
        stop_process(replay)
    assert alive and reader.error is None, reader.error
    assert half_open_cut, "a connection without a handshake was kept past --handshake-timeout"
    assert listening and all(a.ip == "127.0.0.1" for a in listening), listening
    t0, t1 = toggles
    scenes = [t for t, _, _ in reader.got["foxglove/scene"] if t0 <= t <= t1]
    assert len(scenes) <= (t1 - t0) / SCENE_REQUEST_MIN_S + 2, f"{len(scenes)} scenes in {t1 - t0:.1f} s of toggling"
    lines = log.splitlines()
    assert len(lines) <= 60 and len(log) < 20_000, f"{len(lines)} lines, {len(log)} bytes: {lines[:5]} ..."
    assert reader.subprotocol == SUBPROTOCOL and "time" in reader.server["capabilities"]
    assert reader.channels["foxglove/tf"]["schemaName"] == "foxglove.FrameTransforms"
    assert reader.channels["foxglove/scene"]["schemaName"] == "foxglove.SceneUpdate"
    assert reader.channels[raw]["schemaName"] == "astrodyn.OrbitState"
    assert len(reader.got["foxglove/tf"]) >= 5 and reader.got[raw]
    for _, _, payload in reader.got[raw]:
        messages.decode(payload, "orbit")
    children = {tr["child_frame_id"] for _, _, p in reader.got["foxglove/tf"] for tr in json.loads(p)["transforms"]}
    assert "leo" in children
    ids = {e["id"] for e in json.loads(reader.got["foxglove/scene"][-1][2])["entities"]}
    assert {"central_body/earth", "orbit/leo", "axes/leo"} <= ids


@pytest.mark.slow  # CI time (9 s; the stalled-clients memory test stays in make test)
def test_sigterm_with_stalled_and_half_open_connections_ends_serve_promptly_with_the_recording_intact(tmp_path):
    """``serve --foxglove`` with a client reading everything, one subscribed that never reads,
    a TCP connection that never sends its WebSocket handshake and a second of garbage
    frames: SIGTERM ends serve in a few seconds (before: 13 s, as foxglove-sdk's stop waited
    forever for the half-open connection and serve SIGKILLed the viewer after 10 s), exit 0,
    and the recording holds every state from step 0 without a gap, each payload byte for
    byte the message of the state the numeric core computes for the same config."""
    cfg = tmp_path / "hs.toml"
    text = one_satellite_scene("hs", "100000 s", "10 Hz")
    cfg.write_text(text)
    out = tmp_path / "hs.mcap"
    serve = subprocess.Popen([*ASTRODYN, "serve", str(cfg), "--out", str(out), "--rate", "100", "--foxglove", "0",
                              "--max-wall", "120"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    held: list = []
    try:
        hello = json.loads(serve.stdout.readline())
        url = hello["foxglove"]
        reader = Reader(url, {"foxglove/tf", "foxglove/scene", messages.orbit_key("hs", "sat")})
        reader.start()
        reader.wait_subscribed()
        stalled = _connect(url, rcvbuf=4096)
        stalled.subscribe(list(stalled.channels({"foxglove/tf", "foxglove/scene"}).values()))
        held.append(stalled)
        host, port = url.removeprefix("ws://").rsplit(":", 1)
        held.append(socket.create_connection((host, int(port))))  # half-open: no handshake, ever
        junk = _connect(url)
        held.append(junk)
        t_end = time.monotonic() + 1.0
        while time.monotonic() < t_end:
            try:
                junk.send(b"not json")
            except ConnectionError:  # the view cut it: more than MAX_CLIENT_INPUT_PER_S (a fast machine sends that)
                break
        time.sleep(2.0)
        t0 = time.monotonic()
        serve.send_signal(signal.SIGTERM)
        serve.wait(timeout=60)
        took = time.monotonic() - t0
        reader.stop()
    finally:
        for h in held:
            h.close()
        stop_process(serve)
    assert serve.returncode == 0, serve.stderr.read()[-2000:]
    assert took < 6.0, f"serve took {took:.1f} s to exit after SIGTERM"
    written = json.loads(serve.stdout.read().strip().splitlines()[-1])["file"]
    recorded: dict[str, list[bytes]] = {}
    with open(written, "rb") as f:
        for _, channel, message in make_reader(f).iter_messages(log_time_order=False):
            recorded.setdefault(channel.topic, []).append(message.data)
    orbit, attitude = recorded[messages.orbit_key("hs", "sat")], recorded[messages.attitude_key("hs", "sat")]
    assert len(orbit) > 200 and len(attitude) > 200
    assert_one_satellite_payloads("hs", orbit, attitude)


def _low_descriptor_limit() -> None:  # in the viewer's child, before exec
    resource.setrlimit(resource.RLIMIT_NOFILE, (128, 128))


def test_a_view_whose_listener_died_of_descriptor_exhaustion_is_restarted(tmp_path):
    """The viewer with 128 descriptors (soft and hard: it cannot raise them), flooded with
    connections that never finish their handshake.  foxglove-sdk ends its accept loop at the
    first failed accept, so before the port refused every client from then on while the
    viewer ran on.  Now the surplus connections are cut, the dead listener is seen and the
    server restarted on the same port: once the flood lets go, a client gets its serverInfo."""
    viewer = subprocess.Popen([sys.executable, "-m", "astrodyn.service.viewer", "--scenario", "fd", "--port", "0"],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                              preexec_fn=_low_descriptor_limit)
    flood: list[socket.socket] = []
    try:
        url = json.loads(viewer.stdout.readline())["foxglove"]
        host, port = url.removeprefix("ws://").rsplit(":", 1)
        for _ in range(300):
            try:
                flood.append(socket.create_connection((host, int(port)), timeout=2))
            except OSError:
                break
        time.sleep(2.0)
        for s in flood:
            s.close()
        status, deadline = None, time.monotonic() + 8
        while status is None and time.monotonic() < deadline:
            try:
                c = RawClient(url)
                c.sock.settimeout(3)
                status = json.loads(c.recv()[1])["op"]
                c.close()
            except OSError:
                time.sleep(0.2)
        alive = viewer.poll() is None
    finally:
        for s in flood:
            s.close()
        stop_process(viewer)
    err = viewer.stderr.read()
    assert alive and status == "serverInfo", err[-2000:]
    assert "stopped accepting connections" in err and "restarted it on the same port" in err, err[-2000:]
    assert json.loads(viewer.stdout.read().strip().splitlines()[-1])["server_restarts"] >= 1


def test_valid_states_at_times_no_view_can_show_are_counted_not_fatal():
    """An orbit or attitude state is valid at any finite t, but the view stamps it at
    epoch + t (ns, an unsigned 64-bit time for Foxglove): t = 1e300 raised OverflowError in
    the viewer's loop (from a hostile recording under ``replay --foxglove``, each restart
    died the same way); t before 1970 gave a negative stamp.  They are counted as invalid,
    the good states around them still shown."""
    from astrodyn.service.viewer import LiveScene

    epoch_ns = 1_774_008_000_000_000_000  # 2026-03-20T12:00:00 UTC
    scene = LiveScene(epoch_ns, {"name": "earth", "radius": 6378137.0})

    def orbit(t: float) -> bytes:
        return messages.encode(messages.orbit_message(t, 0, "kepler", [7e6, 0.0, 0.0], [0.0, 7.5e3, 0.0], 3.986e14), "orbit")

    def attitude(t: float) -> bytes:
        return messages.encode(messages.attitude_message(t, 0, "torque_free", [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.1]),
                               "attitude")

    hostile = [1e300, -1e300, 1.7976931348623157e308, 1e13, -epoch_ns / 1e9 - 1.0, 2**64 / 1e9]
    for t in hostile:
        assert scene.update("astrodyn/x/sat/orbit", orbit(t)) is None
        assert scene.update("astrodyn/x/sat/attitude", attitude(t)) is None
    assert scene.invalid == 2 * len(hostile)
    assert scene.update("astrodyn/x/sat/orbit", orbit(2.5)) == epoch_ns + 2_500_000_000
    assert scene.update("astrodyn/x/sat/attitude", attitude(2.5)) == epoch_ns + 2_500_000_000
    (tf,) = scene.transforms()["transforms"]
    assert tf["timestamp"] == {"sec": epoch_ns // 10**9 + 2, "nsec": 500_000_000}
    json.dumps(scene.scene(), allow_nan=False)
