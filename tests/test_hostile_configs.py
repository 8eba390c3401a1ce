"""Configs that parse and look valid but would overflow, exceed a file-format limit or
not fit on disk (issue 13 items 3 and 4; docs/architecture.md, section 6).

The contract: refused by ``astrodyn validate`` and ``astrodyn run`` before any process
starts, exit 2, one line naming the field (body index and name), the value and the
allowed range; nothing written.  The limits are independent of the code: the float64
range (products such as r^3 or I w^2 must stay below 1.8e308), MCAP's 16-bit channel
ids (the MCAP specification), and the free space the operating system reports.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from astrodyn.scenario import BYTES_PER_STATE, MAX_CHANNELS, ScenarioError, loads, plan

CONFIGS = Path(__file__).resolve().parent.parent / "configs"
ASTRODYN = [sys.executable, "-m", "astrodyn"]
DEMO = (CONFIGS / "demo.toml").read_text()


def _run_cli(*argv: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([*ASTRODYN, *argv], capture_output=True, text=True, timeout=timeout)


# (description, replacement in demo.toml, field path expected in the message)
OVERFLOWING = [
    ("semi-major axis 1e308 m", ('a = "6795 km"', 'a = "1e308 m"'), "bodies[0] (iss).orbit.a"),
    ("semi-major axis that overflows in km", ('a = "6795 km"', 'a = "1e306 km"'), "bodies[0] (iss).orbit.a"),
    ("angular velocity 1e308 rad/s", ('w = ["0.3 rad/s"', 'w = ["1e308 rad/s"'), "bodies[1] (cubesat).attitude.w[0]"),
    ("position 1e300 km", ('r = ["6878 km"', 'r = ["1e300 km"'), "bodies[1] (cubesat).orbit.r[0]"),
    ("speed faster than light", ('v = ["0 km/s", "4.8 km/s"', 'v = ["0 km/s", "4.8e6 km/s"'),
     "bodies[1] (cubesat).orbit.v[1]"),
    ("subnormal inertia", ('"0.03 kg m2", "0.035 kg m2"', '"1e-320 kg m2", "0.035 kg m2"'),
     "bodies[1] (cubesat).attitude.inertia[0]"),
    ("inertia 1e300 kg m2", ('"1.2e8 kg m2"', '"1e300 kg m2"'), "bodies[0] (iss).attitude.inertia[0]"),
]


@pytest.mark.parametrize("what,replace,field", OVERFLOWING, ids=[c[0] for c in OVERFLOWING])
def test_overflowing_values_are_refused_naming_the_field(what, replace, field, tmp_path):
    old, new = replace
    assert old in DEMO
    cfg = tmp_path / "hostile.toml"
    cfg.write_text(DEMO.replace(old, new, 1))
    with pytest.raises(ScenarioError) as info:
        loads(cfg.read_text(), source=str(cfg))
    msg = str(info.value)
    assert field in msg, msg
    assert "<=" in msg or ">=" in msg or "finite" in msg, f"the allowed range is not stated: {msg}"
    # the same through the command line: exit 2, one line, no traceback, nothing written
    out = tmp_path / "hostile.mcap"
    for argv in (("validate", str(cfg)), ("run", str(cfg), "--out", str(out))):
        proc = _run_cli(*argv)
        assert proc.returncode == 2, proc.stderr
        assert "Traceback" not in proc.stderr
        assert field in proc.stderr, proc.stderr
    assert list(tmp_path.iterdir()) == [cfg], "a refused run wrote something"


def test_values_inside_the_ranges_still_load():
    """The limits are not tighter than real use: a body at 1 au, a 10 kHz spin, a
    space-station inertia of 1e10 kg m2, a hyperbolic flyby at 50 km/s."""
    text = (DEMO.replace('a = "6795 km"', 'a = "1.496e8 km"')
            .replace('w = ["0.3 rad/s"', 'w = ["6.3e4 rad/s"')
            .replace('["1.2e8 kg m2", "1.0e8 kg m2", "2.0e8 kg m2"]', '["1.2e10 kg m2", "1.0e10 kg m2", "2.0e10 kg m2"]')
            .replace('v = ["0 km/s", "4.8 km/s", "5.9 km/s"]', 'v = ["0 km/s", "50 km/s", "5.9 km/s"]'))
    scn = loads(text)
    assert scn.body("iss").orbit.elements["a"] == pytest.approx(1.496e11)


def test_periapsis_below_the_surface_is_a_warning_naming_the_body(tmp_path):
    cfg = tmp_path / "low.toml"
    cfg.write_text(DEMO.replace('a = "26600 km"\ne = 0.74', 'a = "26600 km"\ne = 0.8'))
    # independent: rp = a (1 - e) = 5320 km < 6378.1366 km (Earth's equatorial radius)
    proc = _run_cli("validate", str(cfg))
    assert proc.returncode == 0, proc.stderr
    warning = [line for line in proc.stderr.splitlines() if "warning" in line]
    assert len(warning) == 1, proc.stderr
    assert "bodies[2] (molniya).orbit: periapsis" in warning[0] and "5320" in warning[0], warning[0]
    # a plain config gets no warning
    assert "warning" not in _run_cli("validate", str(CONFIGS / "demo.toml")).stderr


def test_more_channels_than_mcap_allows_is_refused_at_validation(tmp_path):
    """MCAP channel ids are uint16 (the MCAP specification, Channel record): 33,000 bodies
    with an orbit and an attitude need 66,000 state channels."""
    text = (
        '[scenario]\nname = "big"\nepoch = "2026-01-01T00:00:00 UTC"\nduration = "10 s"\nrate = "1 Hz"\n'
        '[central_body]\nname = "earth"\n'
        '[walker]\ni = "53 deg"\nt = 33000\np = 50\naltitude = "550 km"\n'
        '[walker.attitude]\nq = [1, 0, 0, 0]\nw = ["0.01 rad/s", "0 rad/s", "0 rad/s"]\n'
        'inertia = ["1 kg m2", "2 kg m2", "3 kg m2"]\n'
    )
    cfg = tmp_path / "big.toml"
    cfg.write_text(text)
    t0 = time.monotonic()
    proc = _run_cli("validate", str(cfg))
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    assert "66000 channels" in proc.stderr and str(MAX_CHANNELS - 2) in proc.stderr, proc.stderr
    assert time.monotonic() - t0 < 60
    # the same scene at the limit's side that fits: 32,000 bodies, 64,000 channels
    ok = loads(text.replace("t = 33000", "t = 32000"))
    assert len(ok.bodies) == 32000


def test_run_refuses_a_recording_that_cannot_fit_on_the_disk(tmp_path):
    """115 days at 1000 Hz of the demo's five state channels: 5e10 messages, about 4.5 TB;
    compared with the free space the operating system reports for the test's disk."""
    text = DEMO.replace('duration = "93 min"', 'duration = "115 d"').replace('rate = "1 Hz"', 'rate = "1000 Hz"')
    cfg = tmp_path / "huge.toml"
    cfg.write_text(text)
    p = plan(loads(text))
    assert p.messages == p.n_steps * 5  # iss and cubesat: orbit and attitude; molniya: orbit
    need = p.messages * BYTES_PER_STATE
    free = shutil.disk_usage(tmp_path).free
    if need <= free:
        pytest.skip(f"this disk has {free / 1e12:.1f} TB free, more than the {need / 1e12:.1f} TB the scene needs")
    out = tmp_path / "huge.mcap"
    proc = _run_cli("run", str(cfg), "--out", str(out))
    assert proc.returncode == 2, proc.stderr
    assert "--force" in proc.stderr and "free" in proc.stderr, proc.stderr
    assert sorted(tmp_path.iterdir()) == [cfg], "a refused run wrote something"
    # validate states the size it expects
    shown = _run_cli("validate", str(cfg)).stdout
    assert "expected recording: about" in shown and "TB" in shown, shown
