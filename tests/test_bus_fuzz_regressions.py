"""Regressions found by fuzzing running services with hostile local processes on the bus.

Each test runs a real ``astrodyn run`` and a real attacker process that imports only zenoh
(what any local user has; it finds the hub in the children's command lines), and checks
the documented behaviour (docs/security.md) against an unattacked run of the same scene.

* A flood of forged heartbeats on ``@heartbeat/<anything>`` parked the logger for ever:
  its own heartbeat was delivered to its own subscription's FIFO, full of the flood, which
  only the logger's (blocked) main loop drains.  The run failed after a minute with an
  unfinished file.  Heartbeats now go to remote subscribers only.
* Liveliness tokens forged in the processes' names: one in the logger's name, declared
  before the real logger was ready, let the propagators publish before it subscribed (a
  lost start event: the run failed, "1 messages missing"); one in a propagator's name,
  undeclared while the real one ran, and a crowd of ghost names, wrote "process ... died"
  error events into the recording (one per name: unbounded).  Propagators now wait for a
  reply signed by the run's logger; the logger reports deaths only of the processes it
  expects or heard from, after checking that no token of that name is left.
* Forged supervisor commands were refused by the propagators but counted nowhere: the run
  exited 0.  The propagators' end events carry their refusals; the logger counts them.
"""

from __future__ import annotations

import json
import sys
import textwrap
from pathlib import Path

import pytest
from mcap.reader import make_reader

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_bus_trust import SCENE as TRUST_SCENE, _channels, run_attacked

pytestmark = pytest.mark.network

# the trust scene (two satellites, one with an attitude), long enough for the attacks to land
SCENE = TRUST_SCENE.replace('duration = "3000 s"', 'duration = "9000 s"')
assert SCENE != TRUST_SCENE

# argv: endpoint, attack, report file (tests/test_bus_trust.py: run_attacked).  Every loop is bounded; the report says what was sent.
ATTACKER = textwrap.dedent(r'''
    import json, struct, sys, time, zenoh
    endpoint, attack, out = sys.argv[1], sys.argv[2], sys.argv[3]
    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    base = "astrodyn/trust"
    sent = {}
    with zenoh.open(conf) as s:
        if attack == "heartbeats":
            pub = s.declare_publisher(base + "/@heartbeat/x", congestion_control=zenoh.CongestionControl.BLOCK)
            deadline = time.monotonic() + 4.0
            n = 0
            while time.monotonic() < deadline and n < 2_000_000:
                for _ in range(1000):
                    pub.put(b"x")
                n += 1000
            sent["heartbeats"] = n
        elif attack == "tokens-and-commands":
            # as early as possible: tokens in the names of the run's processes, before they are ready
            own = [s.liveliness().declare_token(f"{base}/@alive/{p}") for p in ("logger", "orbit", "attitude")]
            ghosts = [s.liveliness().declare_token(f"{base}/@alive/ghost{i}") for i in range(200)]
            # wait until both propagators publish (their command subscriptions are declared by then)
            seen = set()
            sub = s.declare_subscriber(base + "/sat/*", zenoh.handlers.FifoChannel(64))
            deadline = time.monotonic() + 60
            while len(seen) < 2 and time.monotonic() < deadline:
                smp = sub.recv()
                seen.add(str(smp.key_expr).rsplit("/", 1)[-1])
            sub.undeclare()
            for t in own + ghosts:  # the run's processes go on: none of them died
                t.undeclare()
            pub = s.declare_publisher(base + "/@command", congestion_control=zenoh.CongestionControl.BLOCK)
            forged = b"ADA1" + bytes([5]) + b"serve" + bytes(8)
            for i in range(300):
                pub.put(b'{"verb":"stop"}')
                pub.put(b'{"verb":"stop"}', attachment=forged + struct.pack("<Q", i + 1) + bytes(32))
            sent = {"unsigned": 300, "bad-mac": 300, "seen": sorted(seen)}
            time.sleep(0.5)
    open(out, "w").write(json.dumps(sent))
''')


def _run(tmp: Path, attack: str | None) -> tuple[int, str, dict, dict]:
    """``astrodyn run`` of SCENE in ``tmp`` (with ``attack`` by a separate attacker
    process): exit status, stderr, the attacker's report, the run's --json result."""
    config = tmp / "trust.toml"
    config.write_text(SCENE)
    cmd = [sys.executable, "-m", "astrodyn", "run", str(config), "--out", str(tmp / "run.mcap"), "--quiet",
           "--timeout", "120", "--json", str(tmp / "result.json")]
    rc, stderr, sent = run_attacked(cmd, tmp, None if attack is None else ATTACKER, (attack,) if attack else (), 150)
    result = json.loads((tmp / "result.json").read_text()) if (tmp / "result.json").exists() else {}
    return rc, stderr, sent, result


def _states(path: Path) -> dict[str, list[bytes]]:
    return {k: [d for _, d in v] for k, v in _channels(path).items() if "/@" not in k}


def _metadata(path: Path) -> dict:
    with open(path, "rb") as f:
        return {m.name: m.metadata for m in make_reader(f).iter_metadata()}


@pytest.fixture(scope="module")
def clean(tmp_path_factory) -> dict[str, list[bytes]]:
    tmp = tmp_path_factory.mktemp("clean")
    rc, err, _, _ = _run(tmp, None)
    assert rc == 0, err[-3000:]
    return _states(tmp / "run.mcap")


def test_a_flood_of_forged_heartbeats_does_not_hang_the_logger(tmp_path, clean):
    rc, err, sent, _ = _run(tmp_path, "heartbeats")
    assert sent["heartbeats"] > 0
    assert rc == 3, err[-3000:]  # before the fix: 1, "logger did not finish within 60 s", no footer
    assert _states(tmp_path / "run.mcap") == clean
    by_reason = json.loads(_metadata(tmp_path / "run.mcap")["rejected"]["by_reason"])
    assert set(by_reason) == {"unsigned"} and by_reason["unsigned"] > 0, by_reason


def test_forged_liveliness_tokens_and_supervisor_commands(tmp_path, clean):
    rc, err, sent, result = _run(tmp_path, "tokens-and-commands")
    assert sent["seen"] == ["attitude", "orbit"], sent
    # nothing entered the record: same states, no death reported, no error event
    assert rc == 3, err[-3000:]
    path = tmp_path / "run.mcap"
    assert _states(path) == clean
    meta = _metadata(path)
    assert json.loads(meta["end"]["died"]) == {} and meta["end"]["complete"] == "true", meta["end"]
    events = [json.loads(d) for _, d in _channels(path)["astrodyn/trust/@event"]]
    assert [e for e in events if e["kind"] == "error"] == []
    assert result["logger"]["liveliness_ignored"] >= 200
    # the forged stop commands were refused (the run went to its end) and counted with their
    # reason: in the file, what each propagator says it refused (one that had already ended
    # when they came got none)
    by_reason = json.loads(meta["rejected"]["by_reason"])
    refused = {}
    for kind in ("orbit", "attitude"):
        for reason, n in result["processes"][kind]["summary"]["rejected"].items():
            refused[f"command {reason}"] = refused.get(f"command {reason}", 0) + n
    assert by_reason == refused, (by_reason, refused)
    assert set(by_reason) == {"command unsigned", "command bad-mac"}, by_reason
    assert 0 < by_reason["command unsigned"] <= 2 * sent["unsigned"] and 0 < by_reason["command bad-mac"] <= 2 * sent["bad-mac"]
    assert "ATTACKED" in err
