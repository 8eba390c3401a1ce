"""A closed-loop ``serve`` whose plant or logger is killed (docs/reliability.md, docs/control.md).

Neither is restarted: the controllers' state lives outside astrodyn and a plant cannot
resume mid-run.  The contract: serve ends at once (not after the logger's 60 s wait for
states that will never come), exit 1, the failure naming the process; nothing is restarted
with arguments meant for a propagator; every state the file holds is a gap-free prefix
of the run; no process serve started outlives it.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from _recordings import wait_for_recording
from astrodyn.recording import load

pytestmark = pytest.mark.network
ROOT = Path(__file__).resolve().parents[1]


def _children(pid: int) -> dict[int, str]:
    """PID -> command line of the direct children of ``pid`` (from /proc)."""
    out = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as f:
                ppid = int(f.read().rsplit(")", 1)[1].split()[1])
            if ppid == pid:
                with open(f"/proc/{entry}/cmdline", "rb") as f:
                    out[int(entry)] = f.read().replace(b"\0", b" ").decode()
        except (OSError, IndexError, ValueError):
            continue
    return out


def _gone(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] == "Z"
    except OSError:
        return True


@pytest.mark.parametrize("victim, sig", [("logger", signal.SIGKILL), ("plant", signal.SIGKILL),
                                         ("plant", signal.SIGTERM)])  # SIGTERM: kill PID by someone else than serve
def test_a_killed_plant_or_logger_ends_a_closed_loop_serve_at_once_naming_it(tmp_path, processes, victim, sig):
    """The plant or logger of a closed loop dies: serve ends at once (exit 1) naming it.  A
    SIGTERM from someone else stops the plant cleanly with exit 0, its controller leaving
    after it: serve names the plant (before: it blamed the controller, probe E, E5)."""
    text = (ROOT / "configs" / "slew.toml").read_text().replace('duration = "180 s"', 'duration = "100000 s"')
    cfg = tmp_path / "slew.toml"
    cfg.write_text(text)
    out = tmp_path / "served.mcap"
    serve = processes([sys.executable, "-m", "astrodyn", "serve", str(cfg), "--out", str(out), "--rate", "20",
                       "--max-wall", "120", "--controller", f"python {ROOT / 'examples' / 'slew_pd.py'}"],
                      stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    partial = tmp_path / "served.partial.mcap"
    wait_for_recording(serve, partial, 30_000, timeout_s=90, poll_s=0.2)
    children = _children(serve.pid)
    marker = "astrodyn.service.logger" if victim == "logger" else "astrodyn.service.plant"
    [target] = [pid for pid, cmd in children.items() if marker in cmd]
    killed_at = time.monotonic()
    os.kill(target, sig)
    stdout, stderr = serve.communicate(timeout=60)
    ended_after = time.monotonic() - killed_at
    assert serve.returncode == 1, stderr
    assert ended_after < 15, (ended_after, stderr)  # before: the logger waited 60 s for the plant's last states
    summary = json.loads(stdout.strip().splitlines()[-1])
    assert summary["restarts"] == [], summary
    assert summary["failures"] == [summary["failures"][0]] and \
        summary["failures"][0].startswith(f"process {victim} (pid {target}) " + (
            "killed by signal 9" if sig == signal.SIGKILL else "stopped on a SIGTERM its supervisor did not send")), summary
    assert "not restarted" in summary["failures"][0], summary
    assert "unrecognized arguments" not in stderr, stderr  # nothing restarted with a propagator's flags
    assert summary["file"] == str(partial) and f"the recording stays at {partial}" in stderr, stderr
    time.sleep(0.5)
    left = [(pid, cmd) for pid, cmd in children.items() if not _gone(pid)]
    assert not left, left
    recovered = tmp_path / "recovered.mcap"
    subprocess.run([sys.executable, "-m", "astrodyn", "recover", str(partial), "--out", str(recovered)],
                   check=True, capture_output=True, cwd=ROOT, timeout=60)
    run = load(recovered)
    att = run.channels["astrodyn/slew/sc/attitude"]
    assert len(att) >= 10 and np.array_equal(att.seq, np.arange(len(att)))  # a gap-free prefix of the run
    assert not run.truncated and run.invalid == 0
