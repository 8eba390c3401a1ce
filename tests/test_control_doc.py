"""docs/control.md's self-contained controller, run as written as the controller of a real
``astrodyn run`` (``--controller``).

The block is cut out of the document and run as its own process (it imports only zenoh
and the standard library).  Check, independent of astrodyn's code: with u = -K w_gyro the
rotational energy T = 1/2 sum I_i w_i^2 may only fall (dT/dt = w . u <= 0 while the gyro's
noise is far below the rates; the gyroscopic terms do no work), and it falls far: each axis
is driven at the actuator's limit of 0.05 N m until K |w_i| < 0.05 N m (at most
I_max |w|_0 / 0.05 N m ~ 130 s), then decays with time constants I_i / K <= 24 s, so by
300 s the energy is below 1e-3 of its start with a wide margin (the gyro noise floor,
~I sigma^2, is ~1e-8 J).
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from astrodyn.recording import load

pytestmark = pytest.mark.network
ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "control.md"


def test_the_documented_controller_damps_the_rates(tmp_path):
    text = DOC.read_text()
    block = re.search(r"## A complete controller.*?```python\n(.*?)```", text, re.S).group(1)
    assert "astrodyn" not in re.sub(r'f?"astrodyn/[^"]*"', "", block).replace("ASTRODYN_", "")  # no astrodyn code
    script = tmp_path / "ctl.py"
    script.write_text(block)
    cfg = (ROOT / "configs" / "detumble.toml").read_text().replace('duration = "900 s"', 'duration = "300 s"')
    cfg = cfg[:cfg.index("[[control.faults]]")] + cfg[cfg.index("[[bodies]]"):]  # no faults: the plain law
    (tmp_path / "d.toml").write_text(cfg)
    out = tmp_path / "d.mcap"
    proc = subprocess.run([sys.executable, "-m", "astrodyn", "run", str(tmp_path / "d.toml"), "--out", str(out),
                           "--controller", f"python {script}", "--quiet"], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "3001 commands applied, 0 refused, 0 late" in proc.stderr  # one per control step, 0 .. 300 s
    run = load(out)
    w = run.channels["astrodyn/detumble/sc/attitude"].w
    energy = 0.5 * np.sum(np.array([100.0, 120.0, 80.0]) * w * w, axis=1)
    # monotone: each step's rise bounded by the noise's work, |K sigma w| dt ~ 5e-5 * 0.05 * 0.1 J
    assert np.all(np.diff(energy) <= 1e-6), np.max(np.diff(energy))
    assert energy[-1] < 1e-3 * energy[0]


def test_the_documented_controller_started_by_hand_gives_up_without_a_run(tmp_path):
    """Started by hand (the control token) at an endpoint where no run is (a wrong port, a
    run that has ended), it says so in one line and exits 1 after ASTRODYN_FIRST_TICK_TIMEOUT,
    instead of waiting for ever."""
    import os
    import time

    from astrodyn import bus

    text = DOC.read_text()
    script = tmp_path / "ctl.py"
    script.write_text(re.search(r"## A complete controller.*?```python\n(.*?)```", text, re.S).group(1))
    token = tmp_path / "token"
    token.write_text("0" * 64)
    endpoint = bus.loopback_endpoint(bus.free_port())  # nothing listens there
    env = {**os.environ, "ASTRODYN_CONTROL_TOKEN_FILE": str(token), "ASTRODYN_CONNECT": endpoint,
           "ASTRODYN_SCENARIO": "detumble", "ASTRODYN_CONTROLLER": "pd", "ASTRODYN_FIRST_TICK_TIMEOUT": "2"}
    env.pop("ASTRODYN_RUN_SECRET_FILE", None)
    started = time.monotonic()
    proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=60, env=env)
    assert proc.returncode == 1, proc.stderr
    assert f"no tick from astrodyn/detumble at {endpoint} within 2 s" in proc.stderr, proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1, proc.stderr  # one line, no traceback
    assert time.monotonic() - started < 30
