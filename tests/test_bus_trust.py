"""Trust on the bus with real processes: a hostile local client attacks a running `astrodyn run`.

The attacker is a separate process that imports only zenoh (what any local user has). It
finds the run's hub port in the children's command lines (as anyone can in the process
list) and, while the run is going: forges states on real keys (the next seqs and seq
2**53 - 1), creates ghost bodies, sends end-of-run ``stop`` events in the propagators'
names, an envelope of 70,000 keys, supervisor commands (``stop``), and replays genuine
signed samples it captured.  The recording must equal an unattacked run of the same
scenario, payload for payload; the attack must be reported (exit 3, a 'rejected' metadata
record with counts per reason).
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader

from astrodyn.service.children import children_of

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _recordings import orbiter, scenario_head

pytestmark = pytest.mark.network

SCENE = scenario_head("trust", "3000 s", "1 Hz", "TDB", central_body="earth") + "\n" + orbiter(
    "sat", "7000 km", 0.01, "51 deg", w=["0.3 rad/s", "0.001 rad/s", "0.002 rad/s"]
) + textwrap.dedent("""
    [[bodies]]
    name = "sat2"
    [bodies.orbit]
    r = ["6878 km", "0 km", "0 km"]
    v = ["0 km/s", "4.8 km/s", "5.9 km/s"]
""")

ATTACKER = textwrap.dedent(r'''
    import json, struct, sys, time, zenoh
    endpoint, out = sys.argv[1], sys.argv[2]
    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    sent = {}
    def count(what, n=1):
        sent[what] = sent.get(what, 0) + n
    def orbit(seq, t):
        return json.dumps({"t": t, "seq": seq, "model": "kepler", "r": [7.0e6, 0.0, 0.0],
                           "v": [0.0, 7.5e3, 0.0], "mu": 3.986004418e14, "frame": "GCRF"},
                          separators=(",", ":")).encode()
    with zenoh.open(conf) as s:
        captured = []
        sub = s.declare_subscriber("astrodyn/trust/**", zenoh.handlers.FifoChannel(4096))
        pubs = {}
        def put(key, payload, attachment=None):
            if key not in pubs:
                pubs[key] = s.declare_publisher(key)
            pubs[key].put(payload, attachment=attachment)
        deadline = time.monotonic() + 20
        rounds = 0
        while time.monotonic() < deadline and rounds < 40:
            rounds += 1
            while (smp := sub.try_recv()) is not None:
                att = smp.attachment.to_bytes() if smp.attachment is not None else b""
                # genuine signed samples only (our own forged ones, delivered locally, have a zero instance)
                if att[:4] == b"ADA1" and att[10:18] != bytes(8) and len(captured) < 200:
                    captured.append((str(smp.key_expr), smp.payload.to_bytes(), att))
            for seq in range(rounds * 5, rounds * 5 + 5):  # forged states on a real key
                put("astrodyn/trust/sat/orbit", orbit(seq, float(seq))); count("forged-state")
            put("astrodyn/trust/sat/orbit", orbit(2**53 - 1, 1.0)); count("huge-seq")
            for i in range(50):  # ghost bodies
                put(f"astrodyn/trust/ghost{rounds}_{i}/orbit", orbit(0, 0.0)); count("ghost")
            for proc in ("orbit", "attitude"):  # forged end-of-run events
                ev = {"t": 0.0, "seq": rounds, "process": proc, "kind": "stop", "detail": json.dumps({"messages": 0})}
                put("astrodyn/trust/@event", json.dumps(ev, separators=(",", ":")).encode()); count("event")
            put("astrodyn/trust/@command", b'{"verb":"stop"}'); count("command")
            # valid messages of the further state kinds, on the scene's body and on a ghost
            own = {"appendages": {"t": 0.0, "seq": rounds, "eta": [[0.1, 0.2]], "eta_dot": [[0.0, 0.0]],
                                  "tip": [[0.0, 0.0, 0.1]]},
                   "rolling": {"t": 0.0, "seq": rounds, "contact": [0.0, 0.0], "center": [0.0, 0.0, 0.01],
                               "heading": 0.0, "lean": 0.1, "spin_angle": 0.0, "u": [0.0, 1.0, 0.0]},
                   "gimbals": {"t": 0.0, "seq": rounds, "angle": [0.01], "angle_rate": [0.0], "indicated": [0.1]}}
            for kind, msg in own.items():
                for body in ("sat", f"ghost{rounds}"):
                    put(f"astrodyn/trust/{body}/{kind}", json.dumps(msg, separators=(",", ":")).encode())
                    count("forged-own")
            # a forged authenticator claiming to be the orbit process
            put("astrodyn/trust/sat/orbit", orbit(rounds, float(rounds)),
                b"ADA1" + bytes([5]) + b"orbit" + bytes(8) + struct.pack("<Q", rounds) + bytes(32)); count("bad-mac")
            for key, payload, att in captured[:20]:  # replayed genuine samples
                put(key, payload, att); count("replay")
            if rounds == 3:  # one envelope of 70,000 keys
                entries = []
                for i in range(70000):
                    k = f"astrodyn/trust/g{i}/orbit".encode()
                    p = orbit(0, 0.0)
                    entries.append(struct.pack("<H", len(k)) + k + struct.pack("<I", len(p)) + p)
                put("astrodyn/trust/@batch/orbit", b"ADB1" + struct.pack("<I", 70000) + b"".join(entries)); count("huge-batch")
            time.sleep(0.1)
    open(out, "w").write(json.dumps(sent))
''')


def _channels(path: Path) -> dict[str, list[tuple[int, bytes]]]:
    """Every message of every channel (topic -> [(log_time, payload)]), read by the mcap package."""
    out: dict[str, list[tuple[int, bytes]]] = {}
    with open(path, "rb") as f:
        for _schema, channel, message in make_reader(f).iter_messages():
            out.setdefault(channel.topic, []).append((message.log_time, message.data))
    return out


def _child_endpoint(pid: int, timeout_s: float = 60.0) -> str | None:
    """The hub endpoint in the command line of a child of ``pid`` (what `ps` shows anyone)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        for argv in children_of(pid).values():
            for i, a in enumerate(argv[:-1]):
                if a == "--connect":
                    return argv[i + 1]
        time.sleep(0.02)
    return None


def run_attacked(cmd: list[str], cwd: Path, attacker: str | None, args: tuple[str, ...] = (),
                 timeout_s: float = 300) -> tuple[int, str, dict]:
    """Run ``cmd`` (an ``astrodyn run``) in ``cwd``; with ``attacker`` (a script's text),
    start it as a separate process with the hub endpoint found in the children's command
    lines, ``args`` and a report file whose JSON it writes.  Exit status, stderr, report."""
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=cwd)
    sent: dict = {}
    attacking = None
    try:
        if attacker is not None:
            endpoint = _child_endpoint(proc.pid)
            assert endpoint is not None, "no child with --connect found"
            script = cwd / "attacker.py"
            script.write_text(attacker)
            attacking = subprocess.Popen([sys.executable, str(script), endpoint, *args, str(cwd / "sent.json")],
                                         stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        _, stderr = proc.communicate(timeout=timeout_s)
        if attacking is not None:
            _, a_err = attacking.communicate(timeout=60)
            assert attacking.returncode == 0, a_err.decode()[-2000:]
            sent = json.loads((cwd / "sent.json").read_text())
    finally:
        for p in (proc, attacking):
            if p is not None and p.poll() is None:
                p.kill()
                p.wait()
    return proc.returncode, stderr.decode(), sent


def _run(config: Path, out: Path, tmp: Path, attack: bool) -> tuple[int, str, dict]:
    cmd = [sys.executable, "-m", "astrodyn", "run", str(config), "--out", str(out), "--quiet", "--timeout", "240"]
    return run_attacked(cmd, tmp, ATTACKER if attack else None)


def test_a_hostile_local_client_cannot_change_the_record(tmp_path):
    config = tmp_path / "trust.toml"
    config.write_text(SCENE)
    clean_dir, attacked_dir = tmp_path / "clean", tmp_path / "attacked"
    clean_dir.mkdir()
    attacked_dir.mkdir()
    rc, err, _ = _run(config, clean_dir / "run.mcap", clean_dir, attack=False)
    assert rc == 0, err[-3000:]
    rc, err, sent = _run(config, attacked_dir / "run.mcap", attacked_dir, attack=True)
    assert sent.get("forged-state", 0) > 0 and sent.get("ghost", 0) > 0 and sent.get("forged-own", 0) > 0, sent

    clean, attacked = _channels(clean_dir / "run.mcap"), _channels(attacked_dir / "run.mcap")
    state_topics = sorted(k for k in clean if not k.split("/")[-1].startswith("@") and "/@" not in k)
    assert state_topics == ["astrodyn/trust/sat/attitude", "astrodyn/trust/sat/orbit", "astrodyn/trust/sat2/orbit"]
    # same channels (no ghost channel created), and every state payload identical, in order
    assert sorted(k for k in attacked if "/@" not in k) == state_topics
    for topic in state_topics:
        assert [d for _, d in attacked[topic]] == [d for _, d in clean[topic]], topic
        assert len(clean[topic]) == 3001
    # events: only the run's own processes (no forged stop of 'messages': 0)
    for _, data in attacked.get("astrodyn/trust/@event", []):
        ev = json.loads(data)
        if ev["kind"] == "stop":
            assert json.loads(ev["detail"])["messages"] > 0

    # the attack is reported: exit 3, a line on stderr, counts in the file
    assert rc == 3, err[-3000:]
    assert "ATTACKED" in err
    with open(attacked_dir / "run.mcap", "rb") as f:
        meta = {m.name: m.metadata for m in make_reader(f).iter_metadata()}
    rejected = meta["rejected"]
    assert rejected["authenticated"] == "true" and int(rejected["total"]) > 0
    by_reason = json.loads(rejected["by_reason"])
    assert by_reason.get("unsigned", 0) > 0 and by_reason.get("bad-mac", 0) > 0, by_reason
    if sent.get("replay"):
        assert by_reason.get("replay", 0) > 0, by_reason


@pytest.mark.parametrize("scene_only", [False, True])
def test_a_70000_key_envelope_never_crashes_a_logger_and_the_file_stays_valid(tmp_path, scene_only):
    """A logger without a run secret (started by hand) gets an envelope of 70,000 keys:
    more channels than an MCAP file can hold (16-bit ids).  It neither crashes nor writes
    an unreadable file; with the scene's keys (``--config``) no ghost channel is created."""
    from astrodyn import messages
    from astrodyn.recording.writer import McapRecorder
    from astrodyn.service.logger import Logger

    def orbit(seq):
        return messages.encode(messages.orbit_message(float(seq), seq, "kepler", [7.0e6, 0.0, 0.0], [0.0, 7.5e3, 0.0],
                                                      3.986004418e14))

    out = tmp_path / "flood.mcap"
    recorder = McapRecorder(str(out), {"name": "s"}, epoch_ns=1_774_008_000_000_000_000)
    real = messages.orbit_key("s", "sat")
    logger = Logger(None, "s", recorder, scene_keys={real} if scene_only else None)
    logger.handle(real, orbit(0))
    envelope = messages.encode_batch([(messages.orbit_key("s", f"g{i}"), orbit(0)) for i in range(70_000)])
    logger.handle(messages.batch_key("s", "orbit"), envelope)
    logger.handle(real, orbit(1))
    recorder.close()
    with open(out, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        on_real = [m.data for _, ch, m in reader.iter_messages(topics=[real])]
    assert on_real == [orbit(0), orbit(1)]
    assert len(summary.channels) <= 65535
    if scene_only:
        assert len(summary.channels) == 1 and logger.rejected == {"not-in-scene": 70_000}
    else:
        assert logger.malformed >= 1  # the overflow is counted, with its reason
        assert any("channel limit" in e for e in logger.malformed_examples), logger.malformed_examples


def test_a_replay_into_a_live_serve_is_rejected_and_serve_says_it_was_attacked(tmp_path):
    """``astrodyn replay REC --connect <serve's hub>`` of a recording of the same scenario name:
    every replayed state reaches serve's logger unsigned by the run's secret.  The file must
    hold only serve's own states (each channel 0 .. N-1 once, as serve's summary counts them),
    and serve, like run, must end with exit 3 and an ATTACKED line counting them (before:
    exit 0 and nothing said; the counts were only in the JSON summary)."""
    from _recordings import leo_recording, one_satellite_scene
    from _serve_control import stop_serve

    rec = tmp_path / "other.mcap"
    leo_recording(rec, name="tw", duration="120 s", rate="2 Hz")
    cfg = tmp_path / "tw.toml"
    cfg.write_text(one_satellite_scene("tw", "100000 s", "2 Hz"))
    out = tmp_path / "served.mcap"
    serve = subprocess.Popen([sys.executable, "-m", "astrodyn", "serve", str(cfg), "--out", str(out), "--rate", "20",
                              "--max-wall", "60"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        hub = json.loads(serve.stdout.readline())["hub"]
        replay = subprocess.run([sys.executable, "-m", "astrodyn", "replay", str(rec), "--connect", hub, "--rate", "inf",
                                 "--quiet"], capture_output=True, text=True, timeout=60)
        assert replay.returncode == 0, replay.stderr
        replayed = json.loads(replay.stdout.strip().splitlines()[-1])
    finally:
        stdout, stderr, summary = stop_serve(serve)
    assert serve.returncode == 3, stderr
    unsigned = summary["logger"]["rejected"].get("unsigned", 0)
    states = sum(len(v) for k, v in _channels(rec).items() if k.endswith(("/orbit", "/attitude")))
    assert unsigned >= states > 0 and replayed["messages"] >= states, (summary["logger"]["rejected"], replayed)
    assert f"astrodyn serve: ATTACKED: the logger rejected {sum(summary['logger']['rejected'].values())}" \
        in stderr, stderr
    for key, items in _channels(out).items():
        if key.endswith(("/orbit", "/attitude")):
            assert [json.loads(data)["seq"] for _, data in items] == list(range(len(items))), key  # serve's own, once each
