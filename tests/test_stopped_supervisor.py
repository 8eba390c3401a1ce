"""A supervisor that was itself stopped (Ctrl-Z in its terminal, SIGSTOP, a paused VM)
must not take its healthy children for hung.

`run` and `serve` kill a child whose heartbeat has been silent for `--stall-timeout` wall
seconds (docs/reliability.md).  While the supervisor is stopped it hears nothing, so before
the fix, the moment it was continued it found every child "silent" for as long as it had
been stopped and SIGKILLed them all (measured: a 10 s stop with `--stall-timeout 5` killed
and restarted the logger and a propagator of a healthy run).  Silence is now counted on the
supervisor's listening clock (`astrodyn.bus.HeartbeatMonitor.listening_s`).

Real processes, real signals; every process is stopped by its PID, loops are bounded.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _recordings import one_satellite_scene

pytestmark = pytest.mark.network

ASTRODYN = [sys.executable, "-m", "astrodyn"]
STALL_S = 1.5  # --stall-timeout of the run
STOPPED_S = 4.0  # how long the supervisor stays stopped: well past the stall timeout
STEPS = 150_001  # 10 Hz over 15000 s: the children run ~10 s more after the stop


def _children(pid: int) -> dict[int, str]:
    """PID -> process kind (logger, orbit, attitude) of the astrodyn children of ``pid``."""
    out = {}
    for child in psutil.Process(pid).children():
        try:
            cmd = child.cmdline()
        except psutil.NoSuchProcess:
            continue
        module = next((c for c in cmd if c.startswith("astrodyn.service.")), "")
        kind = "logger" if module.endswith("logger") else cmd[cmd.index(module) + 1] if module else None
        if kind:
            out[child.pid] = kind
    return out


def test_a_stopped_supervisor_does_not_kill_its_healthy_children(tmp_path):
    config = tmp_path / "stopped.toml"
    config.write_text(one_satellite_scene("stopped", "15000 s", "10 Hz"))
    out, result = tmp_path / "stopped.mcap", tmp_path / "result.json"
    partial = tmp_path / "stopped.partial.mcap"
    proc = subprocess.Popen([*ASTRODYN, "run", str(config), "--out", str(out), "--json", str(result), "--quiet",
                             "--stall-timeout", str(STALL_S)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and not (partial.exists() and partial.stat().st_size > 2_000_000):
            assert proc.poll() is None, proc.stderr.read().decode()
            time.sleep(0.05)  # the recording is under way: every child beats
        before = _children(proc.pid)
        assert sorted(before.values()) == ["attitude", "logger", "orbit"]
        os.kill(proc.pid, signal.SIGSTOP)
        time.sleep(STOPPED_S)
        os.kill(proc.pid, signal.SIGCONT)
        time.sleep(2 * STALL_S)  # long enough for the supervisor to judge (and, before, to kill)
        still = [pid for pid in before if psutil.pid_exists(pid) and psutil.Process(pid).status() != "zombie"]
        assert still == list(before), "the children were still running after the stop"
        _, err = proc.communicate(timeout=180)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    err = err.decode()
    assert proc.returncode == 0, err
    run = json.loads(result.read_text())
    assert run["restarts"] == [], run["restarts"]
    assert "stalled" not in err, err
    log = run["logger"]
    assert log["missing"] == 0 and log["states"] == 2 * STEPS, log
