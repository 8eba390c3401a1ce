"""After ``rate inf``, every propagator of a served scene is paced to one sim time again
(svc probe F5).  At ``inf`` each runs as fast as it can, so orbit and attitude drift apart
(thousands of sim seconds in a few wall seconds); when the rate became finite again each
paced from its own time, and the bus carried a scene whose channels stayed hours apart for
good.  The rule (docs/reliability.md): a rate change or a resume gives every process one
schedule, the sim time of the one furthest on; those behind catch up.  Checked from the
status of a real serve: the propagators' sim times agree to what their heartbeats' age
allows (half a second of wall time at the rate, twice)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from astrodyn import bus

pytestmark = pytest.mark.network
ROOT = Path(__file__).resolve().parents[1]


def _times(s, token) -> dict[str, float]:
    reply = bus.send_control(s, "demo", "status", token=token, timeout_s=10, require_reply=True)[0]
    return {k: reply["processes"][k]["t"] for k in ("orbit", "attitude")}


def test_after_rate_inf_orbit_and_attitude_are_paced_to_one_sim_time(tmp_path):
    serve = subprocess.Popen([sys.executable, "-m", "astrodyn", "serve", str(ROOT / "configs" / "demo.toml"), "--out",
                              str(tmp_path / "d.mcap"), "--rate", "10", "--max-wall", "90"],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path)
    try:
        hello = json.loads(serve.stdout.readline())
        token = hello["control_token"]
        with bus.open_session(connect=[hello["hub"]]) as s:
            deadline = time.monotonic() + 60
            while time.monotonic() < deadline and None in _times(s, token).values():  # both beating
                time.sleep(0.2)
            bus.send_control(s, "demo", "rate", {"factor": "inf"}, token=token, timeout_s=10, require_reply=True)
            time.sleep(2.0)
            apart = _times(s, token)
            bus.send_control(s, "demo", "rate", {"factor": 10}, token=token, timeout_s=10, require_reply=True)
            deadline = time.monotonic() + 30  # the one behind catches up as fast as it can
            times = _times(s, token)
            while time.monotonic() < deadline and abs(times["orbit"] - times["attitude"]) > 10.0:
                time.sleep(0.5)
                times = _times(s, token)
            time.sleep(1.5)  # and stays with the other, paced
            times = _times(s, token)
            bus.send_control(s, "demo", "stop", token=token, timeout_s=60)
        serve.communicate(timeout=60)
    finally:
        if serve.poll() is None:
            os.kill(serve.pid, signal.SIGKILL)
    assert abs(apart["orbit"] - apart["attitude"]) > 100.0, apart  # inf drove them apart (else nothing is tested)
    # heartbeats are up to 0.5 s of wall time old: 5 s of sim time at x10 each way
    assert abs(times["orbit"] - times["attitude"]) <= 10.0, (apart, times)
