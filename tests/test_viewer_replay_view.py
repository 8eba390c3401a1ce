"""The live view of a replay (``replay --foxglove``) against what probe C found
(/work/notes/probeC_report.md): a burst of playback-bar requests, a seek backwards,
states forged by another process on the replay's bus, ``--control-scenario``, a refused
playback request.

Every client is a real WebSocket client of a real ``replay`` process (``RawClient`` and
``Reader`` of ``test_live_view_hostile``); a forger is a real process on the replay's
Zenoh endpoint.  What the view sends is checked against the replay's own ``status`` (read
on the bus with its control token), the recorded states, and the frame period of the view
(30 frames a second, the viewer's default ``--rate``).  Processes are started here and
stopped by their PIDs.
"""

from __future__ import annotations

import json
import struct
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from astrodyn import bus, messages
from astrodyn.recording import load
from astrodyn.service.children import stop_process

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _recordings import copy_recording, leo_recording
from test_live_view_hostile import RawClient, Reader

pytestmark = pytest.mark.network

ASTRODYN = [sys.executable, "-m", "astrodyn"]
#: The view's frame period: the viewer's default ``--rate`` of 30 frames a second, s.
FRAME_PERIOD_S = 1.0 / 30
#: Largest gap between two transforms messages a reading client may see: a few frame
#: periods (the view runs at nice 10 on a machine other tests load too).
MAX_FRAME_GAP_S = 10 * FRAME_PERIOD_S


def _replay(rec: Path, *extra: str) -> tuple[subprocess.Popen, dict]:
    replay = subprocess.Popen([*ASTRODYN, "replay", str(rec), "--foxglove", "0", "--wait", "30", "--quiet", *extra],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    return replay, json.loads(replay.stdout.readline())


def _status(session, hello: dict) -> dict:
    return bus.send_control(session, hello["scenario"], "status", token=hello["control_token"], timeout_s=5)[0]


def _stamp_ns(tr: dict) -> int:
    return tr["timestamp"]["sec"] * 10**9 + tr["timestamp"]["nsec"]


def _wait_for(what, timeout_s: float, why: str):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if (got := what()):
            return got
        time.sleep(0.05)
    raise AssertionError(why)


def _transforms_of(reader: Reader, body: str, since: float = 0.0) -> list[tuple[float, int, dict]]:
    """(arrival, message log time, transform) of ``body``'s transforms the reader got after ``since``."""
    out = []
    for arrived, ts, payload in list(reader.got.get("foxglove/tf", [])):
        if arrived >= since:
            out.extend((arrived, ts, tr) for tr in json.loads(payload)["transforms"] if tr["child_frame_id"] == body)
    return out


def _bar_client(url: str, timeout_s: float = 60.0) -> RawClient:
    """A :class:`RawClient` of ``url``, retried while the view's server starts."""
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            return RawClient(url)
        except OSError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.2)


def _playback_request(command: int, speed: float, seek_ns: int | None, request_id: str) -> bytes:
    """A PlaybackControlRequest (binary opcode 3: command u8, speed f32, had_seek u8, seek_time
    u64, request id length u32, request id; Foxglove WebSocket protocol, foxglove.sdk.v1)."""
    rid = request_id.encode()
    return struct.pack("<BBfBQI", 3, command, speed, seek_ns is not None, seek_ns or 0, len(rid)) + rid


class PlaybackStates(threading.Thread):
    """Reads everything a :class:`RawClient` gets and keeps its PlaybackState frames (binary
    opcode 5: status u8, current time u64, speed f32, did_seek u8, request id) by request id."""

    def __init__(self, client: RawClient):
        super().__init__(daemon=True)
        self.client = client
        self.states: dict[str, tuple[int, int, float, int]] = {}

    def run(self) -> None:
        try:
            while True:
                op, payload = self.client.recv()
                if op == 2 and payload[:1] == b"\x05":
                    status, now, speed, did_seek, k = struct.unpack_from("<BQfBI", payload, 1)
                    self.states[payload[19:19 + k].decode()] = (status, now, speed, did_seek)
        except OSError:
            pass


def test_a_burst_of_playback_requests_never_stops_the_view_of_other_clients(tmp_path):
    """F1: 100 playback requests at once from one client stopped every client's frames for
    4.75 s (each request's bus round trips ran in the SDK's callback).  Now the other
    client's transforms keep coming, no gap longer than a few frame periods; the requests
    coalesce into the newest, which the replay follows (its status read on the bus).
    F7: a request whose speed the replay refuses still plays, and its answer is the
    replay's real state (it was "Paused at the recording's start")."""
    rec = tmp_path / "rec.mcap"
    leo_recording(rec, name="pbf", duration="3000 s", rate="2 Hz")
    epoch_ns = int(load(rec).scenario["epoch_unix_ns"])
    replay, hello = _replay(rec, "--rate", "2", "--foxglove-playback")
    reader = Reader(hello["foxglove"], {"foxglove/tf"})
    reader.start()
    try:
        reader.wait_subscribed()
        _wait_for(lambda: len(reader.got.get("foxglove/tf", [])) >= 10, 30, "no transforms before the burst")
        bar = _bar_client(hello["foxglove"])
        answers = PlaybackStates(bar)
        answers.start()
        burst_at = time.monotonic()
        final_t = 1000.0
        for n in range(100):  # pause, each dragged somewhere else; the newest: pause at final_t
            t = final_t if n == 99 else 200.0 + 20 * n
            bar.send(_playback_request(1, 2.0, epoch_ns + int(t * 1e9), f"r{n}"), opcode=2)
        _wait_for(lambda: "r99" in answers.states, 30, "the newest request of the burst was never answered")
        time.sleep(max(0.0, burst_at + 3.0 - time.monotonic()))  # the other client keeps reading meanwhile
        arrivals = [a for a, _, _ in reader.got["foxglove/tf"] if a >= burst_at - 1.0]
        with bus.open_session(connect=hello["listen"]) as s:
            after_burst = _status(s, hello)
        bar.close()
    finally:
        reader.stop()
        stop_process(replay)
    gaps = np.diff(arrivals)
    assert len(arrivals) > 60 and gaps.max() <= MAX_FRAME_GAP_S, \
        f"largest gap {gaps.max():.3f} s between transforms, at most {MAX_FRAME_GAP_S:.3f} s (a few frames)"
    status, now, _, did_seek = answers.states["r99"]
    assert after_burst["state"] == "paused" and after_burst["t"] == pytest.approx(final_t, abs=0.5)
    assert status == 1 and did_seek == 1 and now == pytest.approx(epoch_ns + final_t * 1e9, abs=0.5e9)
    assert len(answers.states) < 100  # superseded requests coalesced into the newest


def test_a_refused_playback_request_is_answered_with_the_replays_real_state(tmp_path):
    """F7: a request whose speed the replay refuses (3e38, out of its rate range) was
    answered "Paused at the recording's start" while the replay ran, and its play was
    skipped.  Now the play still goes through and the answer is the replay's state, as its
    own status gives it on the bus."""
    rec = tmp_path / "rec.mcap"
    leo_recording(rec, name="pbr", duration="3000 s", rate="2 Hz")
    epoch_ns = int(load(rec).scenario["epoch_unix_ns"])
    replay, hello = _replay(rec, "--rate", "2", "--foxglove-playback")
    try:
        bar = _bar_client(hello["foxglove"])
        answers = PlaybackStates(bar)
        answers.start()
        with bus.open_session(connect=hello["listen"]) as s:
            bus.send_control(s, "pbr", "seek", {"t": 1000.0}, token=hello["control_token"], timeout_s=5)
            bus.send_control(s, "pbr", "pause", token=hello["control_token"], timeout_s=5)
            bar.send(_playback_request(0, 3e38, None, "refused-speed"), opcode=2)  # play, at a speed refused
            _wait_for(lambda: "refused-speed" in answers.states, 30, "the refused request was never answered")
            status = _status(s, hello)
        bar.close()
    finally:
        stop_process(replay)
    shown, now, speed, _ = answers.states["refused-speed"]
    assert status["state"] == "running" and shown == 0  # Playing, as the replay is
    assert 1000.0 <= (now - epoch_ns) / 1e9 <= status["t"]
    assert speed == pytest.approx(status["real_time_factor"])


def test_after_a_seek_back_the_view_follows_the_replay_back(tmp_path):
    """F2: after a seek backwards the view kept sending the later time's transforms and
    clock (until the replay passed it again, 48 min of wall time in the probe).  Now, within
    a second, every transform of the body is a recorded state no later than the replay's
    own status t, and the view's clock (the messages' log time) follows it back."""
    rec = tmp_path / "rec.mcap"
    leo_recording(rec, name="sb", duration="3000 s", rate="2 Hz")
    orbit = load(rec).bodies["leo"].orbit
    epoch_ns = int(load(rec).scenario["epoch_unix_ns"])
    by_time = dict(zip(orbit.log_time.tolist(), orbit.r / 1e3))
    replay, hello = _replay(rec, "--rate", "2")
    reader = Reader(hello["foxglove"], {"foxglove/tf"})
    reader.start()
    try:
        reader.wait_subscribed()
        with bus.open_session(connect=hello["listen"]) as s:
            bus.send_control(s, "sb", "seek", {"t": 2500.0}, token=hello["control_token"], timeout_s=5)
            _wait_for(lambda: any(_stamp_ns(tr) >= epoch_ns + 2500 * 10**9 for _, _, tr in _transforms_of(reader, "leo")),
                      30, "the view never showed the seek forward")
            bus.send_control(s, "sb", "seek", {"t": 100.0}, token=hello["control_token"], timeout_s=5)
            settled = time.monotonic() + 1.0
            time.sleep(2.0)
            status = _status(s, hello)
    finally:
        reader.stop()
        stop_process(replay)
    shown = _transforms_of(reader, "leo", since=settled)
    assert len(shown) >= 10
    for _, ts, tr in shown:
        t_shown = (_stamp_ns(tr) - epoch_ns) / 1e9
        assert 100.0 <= t_shown <= status["t"], f"transform at t = {t_shown} s; the replay is at {status['t']} s"
        assert 100.0 <= (ts - epoch_ns) / 1e9 <= status["t"]  # the view's clock
        np.testing.assert_array_equal([tr["translation"][c] for c in "xyz"], by_time[_stamp_ns(tr)])


FORGER = textwrap.dedent('''
    import sys, time
    from astrodyn import bus, messages
    endpoint, scenario, seconds = sys.argv[1], sys.argv[2], float(sys.argv[3])
    def orbit(t, x):
        return messages.encode(messages.orbit_message(t, 1, "kepler", [x, 0.0, 0.0], [0.0, 7.5e3, 0.0], 3.986e14), "orbit")
    with bus.open_session(connect=[endpoint]) as s:
        end = time.monotonic() + seconds
        n = 0
        while time.monotonic() < end:
            s.put(messages.orbit_key(scenario, "leo"), orbit(1e7 + n, 1e9))  # the real body, 1,000,000 km away
            for k in range(50):  # bodies the recording never had
                s.put(messages.orbit_key(scenario, f"ghost-{(50 * n + k) % 2000:04d}"), orbit(10.0 + n, 7e6))
            n += 1
            time.sleep(0.02)
    print(n)
''')


def test_states_forged_by_another_process_never_reach_the_replays_view(tmp_path):
    """F3: one well-formed state of a real body put by any local process pinned that body at
    1,000,000 km (and the view's clock in year 2343), and invented bodies became frames and
    channels without bound.  Now the replay signs what it puts with a secret of its own,
    handed to its view, which drops the rest: a forger on the replay's endpoint changes
    nothing the client sees; the body's transforms are the recorded states."""
    rec = tmp_path / "rec.mcap"
    leo_recording(rec, name="fg", duration="600 s", rate="2 Hz")
    orbit = load(rec).bodies["leo"].orbit
    by_time = dict(zip(orbit.log_time.tolist(), orbit.r / 1e3))
    replay, hello = _replay(rec, "--rate", "5")
    reader = Reader(hello["foxglove"], {"foxglove/tf", messages.orbit_key("fg", "leo")})
    reader.start()
    script = tmp_path / "forger.py"
    script.write_text(FORGER)
    try:
        reader.wait_subscribed()
        forger = subprocess.run([sys.executable, str(script), hello["listen"][0], "fg", "3"], capture_output=True,
                                text=True, timeout=60)
        assert forger.returncode == 0 and int(forger.stdout) > 10, forger.stderr[-2000:]
        time.sleep(0.5)
    finally:
        reader.stop()
        stop_process(replay)
    assert not [t for t in reader.channels if "ghost" in t], "invented bodies became channels"
    frames = {tr["child_frame_id"] for _, _, p in reader.got["foxglove/tf"] for tr in json.loads(p)["transforms"]}
    assert not [f for f in frames if "ghost" in f], "invented bodies became frames"
    epoch_ns = int(load(rec).scenario["epoch_unix_ns"])
    assert max(ts for _, ts, _ in reader.got["foxglove/tf"]) <= epoch_ns + 600 * 10**9  # the view's clock
    shown = _transforms_of(reader, "leo")
    assert len(shown) >= 10
    for _, _, tr in shown:
        np.testing.assert_array_equal([tr["translation"][c] for c in "xyz"], by_time[_stamp_ns(tr)])
    for _, _, payload in reader.got[messages.orbit_key("fg", "leo")]:
        assert messages.decode(payload, "orbit")["t"] <= 600.0


def _renamed_in_metadata(src: Path, dst: Path, name: str) -> None:
    """A copy of recording ``src`` whose scenario metadata names scenario ``name``, topics unchanged."""
    copy_recording(src, dst, edit_metadata=lambda record, metadata: {
        **metadata, **({"name": name} if record == "scenario" else {})})


@pytest.mark.parametrize("renamed", ["control-scenario", "metadata"])
def test_a_replay_under_another_scenario_name_still_shows_the_recording(tmp_path, renamed):
    """F5: ``replay --control-scenario NAME --foxglove`` showed an empty view (the view
    subscribed to the control name), and so did a recording whose metadata names another
    scenario than its topics.  The README: --control-scenario changes only the control
    keys, the data keys stay the recorded ones; the view shows the recorded keys."""
    rec = tmp_path / "rec.mcap"
    leo_recording(rec, name="cs", duration="600 s", rate="2 Hz")
    orbit = load(rec).bodies["leo"].orbit
    by_time = dict(zip(orbit.log_time.tolist(), orbit.r / 1e3))
    raw = messages.orbit_key("cs", "leo")
    if renamed == "metadata":
        _renamed_in_metadata(rec, tmp_path / "other.mcap", "elsewhere")
        replay, hello = _replay(tmp_path / "other.mcap", "--rate", "5")
    else:
        replay, hello = _replay(rec, "--rate", "5", "--control-scenario", "elsewhere")
    reader = Reader(hello["foxglove"], {"foxglove/tf", raw})
    reader.start()
    try:
        reader.wait_subscribed(timeout=30)
        _wait_for(lambda: len(_transforms_of(reader, "leo")) >= 10 and reader.got.get(raw), 30,
                  "no transforms or raw states of the recording")
    finally:
        reader.stop()
        stop_process(replay)
    assert hello["control"] == "astrodyn/elsewhere/@control/<verb>"
    for _, _, tr in _transforms_of(reader, "leo"):
        np.testing.assert_array_equal([tr["translation"][c] for c in "xyz"], by_time[_stamp_ns(tr)])
