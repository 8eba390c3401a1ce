"""The raw state channels of ``serve --foxglove`` (probe B F4, probe C F4) and the limit
on connections (probe C F6), against docs/foxglove.md.

docs/foxglove.md: the raw channels carry "the raw states for the Plot panel, at most 1000
messages a second in all (round-robin between channels)".  Under ``serve`` the view asked
the logger for every key's newest state at each frame and queued every key again, in the
same order, so past 33 keys (1000 / 30 frames a second) the same keys won every frame and
the others never appeared, and each state went out about 3 times (10 states a second, 30
frames).  The serve test is a real ``serve`` and a real WebSocket client (``Reader`` of
``test_live_view_hostile``); the guard test drives :class:`ConnectionGuard` on real TCP
connections of this process.
"""

from __future__ import annotations

import collections
import json
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from astrodyn import messages
from astrodyn.service.children import stop_process
from astrodyn.service.viewer import NEWCOMER_GRACE_S, ConnectionGuard, LineBudget

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _recordings import orbiter, scenario_head
from test_live_view_hostile import Reader

ASTRODYN = [sys.executable, "-m", "astrodyn"]
#: The view's raw budget per frame at its defaults (``--raw-rate`` 1000 a second, 30 frames a second).
PER_FRAME = 1000 // 30
BODIES = 24  # 48 state keys: more than one frame's budget


# make test-all only: in one fresh-clone make test on two workers (session 23) the b00/orbit
# channel was advertised and then carried nothing for 3 s, as the actuator channel did in
# test_live_view: an intermittent fault of the live view under load, not yet found
@pytest.mark.slow
@pytest.mark.network
def test_every_raw_channel_is_served_and_each_state_sent_once_under_serve(tmp_path):
    """48 state keys (24 bodies with orbit and attitude) at 10 states a second each, 480 a
    second in all, under the cap: every key's channel appears within a few frames of the
    first of its propagator (round robin over ceil(48 / 33) = 2 frames), and no (channel,
    seq) comes twice."""
    name = "rr"
    cfg = tmp_path / f"{name}.toml"
    cfg.write_text(scenario_head(name, "100000 s", "10 Hz", central_body="earth") + "\n" + "\n".join(
        orbiter(f"b{k:02d}", f"{7000 + 10 * k} km", 0.001, "51.6 deg", w=["0.01 rad/s", "0.1 rad/s", "0.01 rad/s"])
        for k in range(BODIES)))
    keys = {messages.orbit_key(name, f"b{k:02d}") for k in range(BODIES)} | \
        {messages.attitude_key(name, f"b{k:02d}") for k in range(BODIES)}
    serve = subprocess.Popen([*ASTRODYN, "serve", str(cfg), "--out", str(tmp_path / "rr.mcap"), "--rate", "1",
                              "--foxglove", "0", "--max-wall", "120"], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
    try:
        hello = json.loads(serve.stdout.readline())
        reader = Reader(hello["foxglove"], keys)
        reader.start()
        try:
            deadline = time.monotonic() + 60
            while time.monotonic() < deadline and not keys & set(reader.channels):
                time.sleep(0.01)
            first = time.monotonic()
            while time.monotonic() < first + 5 and not keys <= set(reader.channels):
                time.sleep(0.01)
            time.sleep(3.0)
        finally:
            reader.stop()
    finally:
        stop_process(serve)
    missing = keys - set(reader.channels)
    assert not missing, f"{len(missing)} of {len(keys)} raw channels never appeared, e.g. {sorted(missing)[:3]}"
    # the view's frames between the first and the last advertisement of one propagator's
    # channels (its bodies' states arrive together, in one envelope a step), counted by the
    # time message the server sends with each frame: not wall time (on a loaded machine late
    # frames read as 14-17 for the same 2), and not across the two propagators, whose first
    # states can come half a second apart on a loaded machine (16 frames, all round robin)
    for kind in ("orbit", "attitude"):
        came = [reader.advertised_at[k][0] for k in keys if k.endswith("/" + kind)]
        frames = sum(1 for t in reader.time_frames if min(came) < t < max(came))
        assert frames <= -(-len(keys) // PER_FRAME) + 10, f"the last {kind} channel came {frames} frames after the first"
    sent = collections.Counter((topic, messages.decode(payload, topic)["seq"])
                               for topic, got in reader.got.items() for _, _, payload in got)
    assert sum(sent.values()) > 2 * len(keys)
    repeated = {k: n for k, n in sent.items() if n > 1}
    assert not repeated, f"{len(repeated)} states sent more than once, e.g. {sorted(repeated.items())[:3]}"
    silent = keys - {topic for topic, _ in sent}  # every channel carried states
    assert not silent, {k: {"advertised": len(reader.advertised_at[k]), "messages": len(reader.got.get(k, ()))}
                        for k in sorted(silent)}


def _pair(listener: socket.socket) -> tuple[socket.socket, socket.socket]:
    """(client end, server end) of a new TCP connection to ``listener``."""
    client = socket.create_connection(listener.getsockname())
    server, _ = listener.accept()
    return client, server


def _closed_by_peer(sock: socket.socket) -> bool:
    """Whether the other end shut the connection down (what was sent before is read and dropped)."""
    sock.settimeout(0.2)
    try:
        while True:
            if not sock.recv(1 << 16):
                return True
    except TimeoutError:
        return False
    except OSError:
        return True


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the guard reads /proc and TCP_INFO")
def test_idle_and_half_open_connections_never_keep_a_newcomer_out():
    """F6: with 4 places, 4 connections that completed their handshake and read nothing more
    (no subscription) kept every later client out: the guard kept the oldest and cut the
    newcomer, and half-open connections did the same until their handshake timeout.  Now,
    when more connections are open than places, those still in their handshake go first,
    then the idle ones; a newcomer keeps its place, and a client the view is sending data
    to keeps its place against a later newcomer (docs/foxglove.md)."""
    listener = socket.create_server(("127.0.0.1", 0))
    port = listener.getsockname()[1]
    guard = ConnectionGuard(port, max_clients=4, stall_s=1e6, handshake_s=1e6, budget=LineBudget(prefix="guard: "))
    assert guard.available
    opened: list[socket.socket] = [listener]
    try:
        squatters = []
        for _ in range(4):  # handshake answered (bytes sent to them), then nothing: subscribed to nothing
            client, server = _pair(listener)
            server.sendall(b"x" * 300)
            squatters.append(client)
            opened += [client, server]
        time.sleep(0.1)  # their ACKs
        guard.check(now=0.0)
        assert not any(_closed_by_peer(c) for c in squatters)
        half_open = []
        for _ in range(2):  # connected, never answered (no handshake)
            client, server = _pair(listener)
            half_open.append(client)
            opened += [client, server]
        newcomer, newcomer_server = _pair(listener)
        opened += [newcomer, newcomer_server]
        newcomer_server.sendall(b"x" * 300)
        time.sleep(0.1)
        later = 2 * NEWCOMER_GRACE_S
        guard.check(now=later)  # 7 connections, 4 places
        assert not _closed_by_peer(newcomer), "the newcomer was cut"
        assert all(_closed_by_peer(c) for c in half_open), "a half-open connection kept its place"
        cut = [c for c in squatters if _closed_by_peer(c)]
        assert len(cut) == 1 and cut[0] is squatters[0]  # the oldest idle one
        newcomer_server.sendall(b"y" * 200_000)  # the view sends it data (it subscribed): busy
        assert not _closed_by_peer(newcomer)  # read
        second, second_server = _pair(listener)
        opened += [second, second_server]
        second_server.sendall(b"x" * 300)
        time.sleep(0.1)
        guard.check(now=later + NEWCOMER_GRACE_S + 1.0)  # 5 connections, 4 places: an idle one goes
        assert not _closed_by_peer(newcomer) and not _closed_by_peer(second)
        assert sum(_closed_by_peer(c) for c in squatters) == 2
        assert guard.cut["too_many"] == 4
    finally:
        for sk in opened:
            sk.close()
