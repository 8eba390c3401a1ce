"""An outside controller started by hand, with only the run's control token (docs/control.md,
"Authentication"): it may join after the run's first tick, and it checks the plant's ticks
with the token.

Real processes: ``astrodyn run`` of a 3 s lockstep slew (``control.timeout`` 10 s) and
examples/slew_pd.py on examples/astrodyn_link.py, started by hand with the token file the
run prints (no run secret in its environment).  The reference is the same run with the
controller started at once: a lockstep run is deterministic, so the states, sensor samples,
actuator states and commands of the late start must equal it byte for byte.  This test also
watches the ticks from the run's hub, as a third party: while the plant waits for the late
controller it must put the same tick again (every 0.5 s), each copy with the plant's ``ADA1``
authenticator first and an ``ADP1`` part last whose counter is the next one and whose MAC is
the HMAC-SHA256 computed here with hmac from the token file (the key derivation of the
docs, independent of astrodyn.auth).
"""

from __future__ import annotations

import hashlib
import hmac
import json
import os
import struct
import subprocess
import sys
import time
from pathlib import Path

import pytest
import zenoh

from _serve_control import read_run_start
from astrodyn.recording.stream import open_stream

pytestmark = pytest.mark.network
ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
KINDS = ("/attitude", "/gyro", "/star_tracker", "/tachometer", "/actuators", "/command")
LATE_S = 2.5  # the controller starts this long after the run's first tick


def _slew(tmp: Path) -> Path:
    path = tmp / "slew.toml"
    text = (ROOT / "configs" / "slew.toml").read_text()
    assert 'duration = "180 s"' in text and 'timeout = "10 s"' in text
    path.write_text(text.replace('duration = "180 s"', 'duration = "3 s"'))
    return path


def _start_run(processes, tmp: Path, out: Path) -> tuple[subprocess.Popen, dict]:
    run = processes([sys.executable, "-m", "astrodyn", "run", _slew(tmp), "--out", out, "--quiet"],
                    stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True, cwd=ROOT)
    return run, read_run_start(run.stderr)


def _start_controller(processes, found: dict, err: Path) -> subprocess.Popen:
    """examples/slew_pd.py as an outside controller: the control token, no run secret."""
    env = {k: v for k, v in os.environ.items() if k != "ASTRODYN_RUN_SECRET_FILE"}
    env.update(ASTRODYN_CONNECT=found["hub"], ASTRODYN_CONTROL_TOKEN_FILE=found["token"], ASTRODYN_SCENARIO="slew",
               ASTRODYN_CONTROLLER="pd")
    with err.open("w") as fh:
        return processes([sys.executable, EXAMPLES / "slew_pd.py"], env=env, cwd=ROOT, stderr=fh)


def _finish(run: subprocess.Popen, ctl: subprocess.Popen, found: dict) -> str:
    _, err = run.communicate(timeout=60)
    ctl.wait(timeout=30)
    return found["lines"] + err


def _payloads(path: Path) -> dict[str, list[bytes]]:
    out: dict[str, list[bytes]] = {}
    with open_stream(path) as s:
        for m in s.messages():
            out.setdefault(m.topic, []).append(bytes(m.data))
    return out


@pytest.fixture(scope="module")
def started_at_once(tmp_path_factory, processes_module):
    """The recorded payloads of the run with the outside controller started at once."""
    tmp = tmp_path_factory.mktemp("at-once")
    run, found = _start_run(processes_module, tmp, tmp / "ref.mcap")
    ctl = _start_controller(processes_module, found, tmp / "ctl.err")
    err = _finish(run, ctl, found)
    assert run.returncode == 0 and ctl.returncode == 0, err
    assert (tmp / "ctl.err").read_text() == ""  # nothing dropped, nothing said
    payloads = _payloads(tmp / "ref.mcap")
    assert len(payloads["astrodyn/slew/sc/attitude"]) == 31 and len(payloads["astrodyn/slew/sc/command"]) == 31
    return payloads


@pytest.fixture(scope="module")
def processes_module():
    """The conftest's ``processes`` for a module-scoped fixture: killed by PID at the end."""
    children: list[subprocess.Popen] = []

    def start(argv, **kw) -> subprocess.Popen:
        children.append(subprocess.Popen([str(a) for a in argv], **kw))
        return children[-1]

    yield start
    for proc in children:
        if proc.poll() is None:
            proc.kill()
        proc.wait(timeout=10)
        if proc.stderr is not None:
            proc.stderr.close()


def test_a_controller_started_after_the_first_tick_completes_the_run_with_the_same_states(
        tmp_path, processes, started_at_once):
    out = tmp_path / "late.mcap"
    run, found = _start_run(processes, tmp_path, out)
    token = Path(found["token"]).read_bytes().strip()
    plant_key = hmac.new(token, b"ADP1 plant tick v1", hashlib.sha256).digest()
    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", json.dumps([found["hub"]]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    seen = []  # (wall time of arrival, payload, attachment) of every tick put, in order

    def on_tick(sample) -> None:  # zenoh's thread, one sample at a time
        seen.append((time.monotonic(), sample.payload.to_bytes(), sample.attachment.to_bytes()))

    with zenoh.open(conf) as session:
        ticks = session.declare_subscriber("astrodyn/slew/@tick", on_tick)
        deadline = time.monotonic() + 60
        while not seen and time.monotonic() < deadline and run.poll() is None:
            time.sleep(0.001)
        assert seen, "no tick from the plant"
        time.sleep(max(0.0, seen[0][0] + LATE_S - time.monotonic()))
        ctl = _start_controller(processes, found, tmp_path / "ctl.err")
        err = _finish(run, ctl, found)
        ticks.undeclare()
    # the run completed, and as if the controller had been there from the start
    assert run.returncode == 0 and ctl.returncode == 0, err
    assert (tmp_path / "ctl.err").read_text() == ""  # the copies of a tick are not drops
    late = _payloads(out)
    assert {k: v for k, v in late.items() if k.endswith(KINDS)} == \
           {k: v for k, v in started_at_once.items() if k.endswith(KINDS)}
    assert not any("@tick" in topic for topic in late)  # ticks are not recorded, copies or not
    # the plant put tick 0 again while it waited: the same payload, every ~0.5 s
    first = [(t, payload) for t, payload, _ in seen if json.loads(payload)["seq"] == 0]
    assert len(first) >= int(LATE_S / 0.5) - 1 and len({payload for _, payload in first}) == 1, len(first)
    gaps = [b[0] - a[0] for a, b in zip(first, first[1:])]
    assert all(0.3 < g < 3.0 for g in gaps), gaps  # every 0.5 s at the plant, give or take a loaded machine
    assert sorted({json.loads(payload)["seq"] for _, payload, _ in seen}) == list(range(31))
    # every put: ADA1 of the plant (its own length) first, then ADP1 with the next counter and the token's MAC
    counters = []
    for _, payload, a in seen:
        assert a[:10] == b"ADA1\x05plant" and len(a) == 5 + 5 + 8 + 8 + 32 + 44, a[:12]
        part = a[-44:]
        assert part[:4] == b"ADP1"
        mac = hmac.new(plant_key, part[:12] + b"astrodyn/slew/@tick\0" + payload, hashlib.sha256).digest()
        assert hmac.compare_digest(part[12:], mac)
        counters.append(struct.unpack("<Q", part[4:12])[0])
    assert counters == list(range(counters[0], counters[0] + len(counters))), counters
