"""An interrupted `run` says how far it got, not how far the fastest process got.

Found walking the README as a new user: `astrodyn run` stopped by SIGTERM printed
`sim t reached 10800 s of 10800 s; logger stopped: end of run: every expected message
recorded` although its attitude propagator had recorded none of its states (its end event
said `last_step -1`): the line showed the largest sim time of any channel, and nothing said
that a process had stopped before the end of the scene.  The logger now keeps the end
reasons (`stopped_early` in its summary and the file's `end` record) and the line gives the
sim time every process reached.

Real processes, a real SIGTERM; the run is stopped by its PID.
"""

from __future__ import annotations

import json
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _recordings import one_satellite_scene

pytestmark = pytest.mark.network


def test_an_interrupted_run_says_which_process_stopped_early_and_the_sim_time_all_reached(tmp_path):
    config, out, result = tmp_path / "cut.toml", tmp_path / "cut.mcap", tmp_path / "cut.json"
    config.write_text(one_satellite_scene("cut", "100000 s", "10 Hz"))
    partial = tmp_path / "cut.partial.mcap"
    proc = subprocess.Popen([sys.executable, "-m", "astrodyn", "run", str(config), "--out", str(out), "--json",
                             str(result), "--quiet"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and not (partial.exists() and partial.stat().st_size > 300_000):
            assert proc.poll() is None, proc.stderr.read()
            time.sleep(0.05)
        proc.send_signal(signal.SIGTERM)
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 128 + signal.SIGTERM, stderr
    logger = json.loads(result.read_text())["logger"]
    assert set(logger["stopped_early"]) == {"orbit", "attitude"}, logger["stopped_early"]
    assert all(e["reason"] == "SIGTERM" for e in logger["stopped_early"].values()), logger["stopped_early"]
    # the time every channel of the file reaches, read independently with the plain mcap reader
    last_t: dict[str, float] = {}
    with open(partial, "rb") as f:
        for _, channel, message in make_reader(f).iter_messages(log_time_order=False):
            if channel.topic.endswith(("/orbit", "/attitude")):
                last_t[channel.topic] = max(last_t.get(channel.topic, 0.0), json.loads(message.data)["t"])
    reached = re.search(r"sim t reached (\S+) s of 100000 s", stdout)
    assert reached, stdout
    # every state channel of the scene counts: one with no state yet (its propagator was still loading its
    # kernels on a busy machine when the signal came) has reached nothing
    all_reached = min(last_t.get(f"astrodyn/cut/sat/{kind}", 0.0) for kind in ("orbit", "attitude"))
    assert float(reached.group(1)) == pytest.approx(all_reached, abs=1e-6 * all_reached), (stdout, last_t)
    assert "attitude stopped early at sim t" in stdout and "(SIGTERM)" in stdout, stdout
    with open(partial, "rb") as f:  # the file's own end record says it too
        end = next(m for m in make_reader(f).iter_metadata() if m.name == "end")
    assert set(json.loads(end.metadata["stopped_early"])) == {"orbit", "attitude"}, end.metadata
