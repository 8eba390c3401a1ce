"""When a fault begins and how long a sensor dropout lasts (docs/control.md, faults).

Closed-loop probe (session 18): a config fault began at the *nearest* output step, so a
gyro bias at t = 10.04 s began at 10.0 s, before its time; a dropout's end was computed
from the stated t (10.04 + 5 = 15.04 s: silent to 15.1 s) while a re-simulation took the
start from the recorded ``fault`` event (10.0 s: silent to 15.0 s), so ``--commands``
re-simulation published one more gyro sample and every later gyro payload differed; serve's
``fault`` verb stamped a fault at ``t_k + dt`` (38.800000000000004), which made a 1 s dropout
silence 11 steps.  And a short dropout ended a permanent one of the same sensor.

The rule now: a fault begins at the first output step at or after its t; a dropout of
``duration`` silences the ceil(duration * rate) steps from there; a dropout never shortens
one already on.  Checked against the output grid t_k = k / rate, computed here.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

from mcap.reader import make_reader

from astrodyn.plant import Plant
from astrodyn.scenario import load
from astrodyn.scenario.control import Fault

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "detumble.toml"
RATE = 10  # Hz, detumble.toml's


def _scene(tmp_path: Path, faults: str) -> Path:
    text = CONFIG.read_text().replace('duration = "900 s"', 'duration = "6 s"').replace(
        'controllers = ["detumble"]', "controllers = []")
    text, n = re.subn(r"\[\[control.faults\]\].*?(?=\[\[bodies\]\])", faults, text, flags=re.S)
    assert n == 1
    path = tmp_path / "faults.toml"
    path.write_text(text)
    return path


def _dropout(t: str, duration: str | None) -> str:
    return (f'[[control.faults]]\nt = "{t}"\nbody = "sc"\nfault = "sensor_dropout"\nsensor = "gyro"\n'
            + (f'duration = "{duration}"\n' if duration else "") + "\n")


def test_off_grid_dropout_begins_at_the_next_step_and_a_short_one_does_not_end_a_permanent_one(tmp_path):
    cfg = _scene(tmp_path, _dropout("1.04 s", "0.25 s") + _dropout("3 s", None) + _dropout("4 s", "1 s"))
    out = tmp_path / "f.mcap"
    proc = subprocess.run([sys.executable, "-m", "astrodyn", "run", str(cfg), "--out", str(out), "--quiet"],
                          capture_output=True, text=True, timeout=180)
    assert proc.returncode == 0, proc.stderr
    gyro, faults = [], []
    with open(out, "rb") as f:
        for _, channel, message in make_reader(f).iter_messages():
            if channel.topic.endswith("/sc/gyro"):
                gyro.append(json.loads(message.data)["t"])
            elif channel.topic.endswith("/@event") and json.loads(message.data).get("kind") == "fault":
                faults.append(json.loads(message.data)["t"])
    # first step at or after 1.04 s is k = 11; 0.25 s at 10 Hz silences ceil(2.5) = 3 steps
    # (k = 11, 12, 13); from k = 30 the permanent dropout, which the 1 s one at 4 s must not end
    silent = set(range(11, 14)) | set(range(30, 61))
    assert gyro == [k / RATE for k in range(0, 61) if k not in silent]
    assert faults == [11 / RATE, 30 / RATE, 40 / RATE]


def test_a_fault_stamped_t_k_plus_dt_begins_at_t_k_and_lasts_its_whole_steps():
    """serve's fault verb asks for the next step as t_reached + dt: 38.7 + 0.1 =
    38.800000000000004, a hair after the step t = 388 / 10.  It must begin at that step
    and a 1 s dropout silence exactly 10 steps, as a re-simulation from the event's t does."""
    for t_reached_k in (387, 9, 12_345, 99_999):
        plant = Plant(load(CONFIG))
        plant.set_faults([])
        asked = t_reached_k / RATE + 1 / RATE
        plant.inject(Fault(t=asked, body="sc", fault="sensor_dropout", sensor="gyro", duration=1.0))
        k0 = t_reached_k + 1
        assert plant.faults_at((k0 - 1) / RATE) == []
        assert len(plant.faults_at(k0 / RATE)) == 1  # begins at step k0, although asked > k0 / RATE
        sc = plant.bodies["sc"]
        (gyro,) = [s for s in sc.sensors if s.kind == "gyro"]
        due = [k for k in range(k0, k0 + 14) if sc.due(gyro, k, k / RATE)]
        assert due == list(range(k0 + 10, k0 + 14)), (t_reached_k, due)
        # the re-simulation takes the fault at the recorded step time
        replay = Plant(load(CONFIG))
        replay.set_faults([Fault(t=k0 / RATE, body="sc", fault="sensor_dropout", sensor="gyro", duration=1.0)])
        assert replay.faults_at(k0 / RATE)
        rsc = replay.bodies["sc"]
        assert [k for k in range(k0, k0 + 14) if rsc.due(gyro, k, k / RATE)] == due
