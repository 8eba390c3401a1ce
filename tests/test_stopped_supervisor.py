"""A supervisor that was itself stopped (Ctrl-Z in its terminal, SIGSTOP, a paused VM)
must not take its healthy children for hung.

`run` and `serve` kill a child whose heartbeat has been silent for `--stall-timeout` wall
seconds (docs/reliability.md).  While the supervisor is stopped it hears nothing, so before
the fix, the moment it was continued it found every child "silent" for as long as it had
been stopped and SIGKILLed them all (measured: a 10 s stop with `--stall-timeout 5` killed
and restarted the logger and a propagator of a healthy run).  Silence is now counted on the
supervisor's listening clock (`astrodyn.bus.HeartbeatMonitor.listening_s`).  (A stopped
logger is another matter: past 5 s its links are closed, see test_bus_link_loss.py.)

Real processes, real signals; every process is stopped by its PID, loops are bounded.
"""

from __future__ import annotations

import json
import os
import signal
import sys
import time
from pathlib import Path

import psutil
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _recordings import children_by_kind, one_satellite_scene, run_while

pytestmark = pytest.mark.network

STEPS = 150_001  # 10 Hz over 15000 s: the children run ~10 s more after the stop


@pytest.mark.slow  # CI time and load: its 1.5 s --stall-timeout killed a propagator of a loaded CI box (session 16)
def test_a_stopped_supervisor_does_not_kill_its_healthy_children(tmp_path):
    stopped_s, stall_s = 4.0, 1.5  # stopped well past its --stall-timeout
    config = tmp_path / "stopped.toml"
    config.write_text(one_satellite_scene("stopped", "15000 s", "10 Hz"))
    out, result = tmp_path / "stopped.mcap", tmp_path / "result.json"

    def stop_and_continue(supervisor: int) -> None:
        before = children_by_kind(supervisor)  # the recording is under way: every child beats
        assert sorted(before.values()) == ["attitude", "logger", "orbit"]
        os.kill(supervisor, signal.SIGSTOP)
        time.sleep(stopped_s)
        running = [pid for pid in before if psutil.pid_exists(pid) and psutil.Process(pid).status() != "zombie"]
        os.kill(supervisor, signal.SIGCONT)
        # the test has teeth only if children were there to be judged when it was continued
        # (before the fix they were all killed then; a restart shows in the result below)
        assert running, "every child had ended while the supervisor was stopped"

    rc, err = run_while([str(config), "--out", str(out), "--json", str(result), "--quiet", "--stall-timeout",
                         str(stall_s)], tmp_path / "stopped.partial.mcap", 2_000_000, stop_and_continue)
    assert rc == 0, err
    run = json.loads(result.read_text())
    assert run["restarts"] == [], run["restarts"]
    assert "stalled" not in err, err
    log = run["logger"]
    assert log["missing"] == 0 and log["states"] == 2 * STEPS, log
