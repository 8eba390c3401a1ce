"""docs/clients.md's plain-Zenoh client, run as written against a real ``serve``.

The example block is cut out of the document and run in a separate process (it imports
only zenoh); what it prints is checked: the five schema titles from the ``@schema``
queryable, and ten orbit states whose positions lie on the scene's orbit (|r| within the
periapsis and apoapsis radii of a = 7000 km, e = 0.01: an independent closed form).
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

from astrodyn import bus
from astrodyn.service.children import stop_process

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _recordings import one_satellite_scene

pytestmark = pytest.mark.network
DOC = Path(__file__).resolve().parents[1] / "docs" / "clients.md"


def test_the_documented_plain_zenoh_client_works(tmp_path):
    block = re.search(r"```python\n(.*?)```", DOC.read_text(), re.S).group(1)
    assert "astrodyn" not in re.sub(r'f?"astrodyn/[^"]*"', "", block).replace("# ", "")  # no astrodyn code in it
    script = tmp_path / "tap.py"
    script.write_text(block)
    cfg = tmp_path / "tap.toml"
    cfg.write_text(one_satellite_scene("tap", "100000 s", "10 Hz"))
    serve = subprocess.Popen([sys.executable, "-m", "astrodyn", "serve", str(cfg), "--out", str(tmp_path / "tap.mcap"),
                              "--rate", "20", "--max-wall", "120"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                             text=True)
    try:
        hello = json.loads(serve.stdout.readline())
        tap = subprocess.run([sys.executable, str(script), hello["hub"], "tap"], capture_output=True, text=True,
                             timeout=120)
        with bus.open_session(connect=[hello["hub"]]) as s:
            bus.send_control(s, "tap", "stop", token=hello["control_token"], timeout_s=60)
        serve.communicate(timeout=60)
    finally:
        stop_process(serve)
    assert tap.returncode == 0, tap.stderr[-2000:]
    lines = tap.stdout.splitlines()
    titles = {line.split()[1] for line in lines if "/@schema/" in line}
    assert titles == {"astrodyn.OrbitState", "astrodyn.AttitudeState", "astrodyn.CrossCheck", "astrodyn.Event",
                      "astrodyn.Status",  # and the closed loop's (docs/control.md):
                      "astrodyn.Command", "astrodyn.ActuatorState", "astrodyn.GyroSample", "astrodyn.StarTrackerSample",
                      "astrodyn.GpsSample", "astrodyn.TachometerSample", "astrodyn.Tick", "astrodyn.StepDone",
                      # and the further state channels (flexible, rolling, gyroscopes):
                      "astrodyn.AppendageState", "astrodyn.RollingState", "astrodyn.GimbalState"}
    states = [line for line in lines if line.startswith("astrodyn/tap/sat/orbit")]
    assert len(states) == 10
    for line in states:
        r = json.loads(line.split("r = ")[1].removesuffix(" m"))
        radius = sum(c * c for c in r) ** 0.5
        assert 7.0e6 * (1 - 0.01) * (1 - 1e-12) <= radius <= 7.0e6 * (1 + 0.01) * (1 + 1e-12)
