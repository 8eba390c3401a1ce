"""``astrodyn analyze`` on a closed-loop recording (astrodyn.analysis.closed_loop).

A real slew run (three orthogonal reaction wheels, no external torque): the wheels only
move angular momentum between body and rotors, so the inertial momentum of body plus
wheels that the report computes from the recorded states and wheel speeds must be
constant to round-off (an independent conservation law: the report reconstructs it from
q, w, the wheel speeds and the config's geometry, none of which the plant reports as a
momentum).  Also: peak speeds within the limits, one command per control step, the
figures written, and hostile channels (missing fields, wrong lengths) without a traceback.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from astrodyn.analysis import analyze
from astrodyn.analysis.closed_loop import closed_loop_section
from astrodyn.recording.reader import Track

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.network
def test_the_report_of_a_slew_shows_momentum_conserved_and_the_wheels(tmp_path):
    cfg = tmp_path / "slew.toml"
    cfg.write_text((ROOT / "configs" / "slew.toml").read_text().replace('duration = "180 s"', 'duration = "30 s"'))
    out = tmp_path / "slew.mcap"
    proc = subprocess.run([sys.executable, "-m", "astrodyn", "run", str(cfg), "--out", str(out), "--quiet",
                           "--controller", f"python {ROOT / 'examples' / 'slew_pd.py'}"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    report = analyze(out, tmp_path / "report")
    section = report["bodies"]["sc"]["closed loop"]
    assert section["commands"] == 301 and section["senders"] == ["pd"]
    assert section["external torque applied"] is False
    # ~10 roundings of |H| per step over 300 steps, random walk: far below 1e-13
    assert section["relative to the largest |H_body|, |H_wheels|"] < 1e-13
    assert all(p <= lim for p, lim in zip(section["peak wheel speed (rad/s)"], section["wheel speed limit (rad/s)"]))
    assert section["steps clipped per wheel"][2] > 0  # the 90 deg slew about z saturates wheel 3 at first
    assert 0 < section["pointing knowledge error, median (deg)"] < 1e-2  # 5 arcsec per axis
    for kind in ("wheel-torque", "wheel-speed", "momentum", "pointing"):
        assert (tmp_path / "report" / report["figures"]["sc"][kind]).stat().st_size > 1000


class _Run:
    def __init__(self, channels, scenario):
        self.channels, self.scenario = channels, scenario


def _track(topic, n, **fields):
    return Track(topic, topic.rsplit("/", 1)[-1], "x", np.arange(n), np.arange(n), {"t": np.arange(n, dtype=float), **fields})


def test_hostile_closed_loop_channels_give_a_partial_section_not_a_traceback(tmp_path):
    p = "astrodyn/x/sc/"
    channels = {
        p + "actuators": _track(p + "actuators", 3, wheel_torque=np.array([[1.0], "junk", [1.0, 2.0]], dtype=object),
                                wheel_speed=np.array([None, [1.0], [2.0, 3.0, 4.0]], dtype=object),
                                clipped=np.array([[0], ["a"], [99]], dtype=object)),
        p + "command": _track(p + "command", 2, sender=np.array(["a", "b"], dtype=object)),
    }
    section, figs = closed_loop_section(_Run(channels, {"name": "x", "json": "{not json"}), "sc", tmp_path / "sc")
    assert section["closed loop"]["commands"] == 2
    assert section["closed loop"]["steps clipped per wheel"] == [1, 0]  # 2 wheels (widest row); only index 0 is valid
    assert all(path.exists() for _, path in figs)
