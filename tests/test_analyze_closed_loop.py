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
@pytest.mark.slow  # CI time: the hostile-channels case below runs the closed-loop section in make test
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
    for kind in ("wheel-torque", "wheel-speed", "momentum", "pointing", "pointing-error"):
        assert (tmp_path / "report" / report["figures"]["sc"][kind]).stat().st_size > 1000
    # the config's target: 90 deg about z from the initial identity attitude (exact), and
    # the final error is the rotation angle scipy finds between the recorded q and it
    from scipy.spatial.transform import Rotation

    from astrodyn.recording import load

    pointing = report["bodies"]["sc"]["pointing"]
    assert pointing["error at start (deg)"] == pytest.approx(90.0, abs=1e-9)
    q_end = load(out).bodies["sc"].attitude.q[-1]
    target = np.array(pointing["target (e0, e1, e2, e3)"])
    as_scipy = [1, 2, 3, 0]  # scipy's quaternions are scalar last
    angle = (Rotation.from_quat(target[as_scipy]).inv() * Rotation.from_quat(q_end[as_scipy])).magnitude()
    assert pointing["error at end (deg)"] == pytest.approx(np.degrees(angle), abs=1e-9)
    assert pointing["error at end (deg)"] < pointing["error at start (deg)"]


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


def test_pointing_error_is_the_rotation_angle_and_settling_is_the_last_entry_into_the_tolerance():
    """pointing_errors against scipy's rotation magnitude on random attitudes (q and -q alike);
    settling_time on a series built to enter, leave and re-enter the tolerance."""
    from scipy.spatial.transform import Rotation

    from astrodyn.analysis.pointing import pointing_errors, settling_time

    rng = np.random.default_rng(3)
    q = rng.normal(size=(200, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q[::2] *= -1.0
    target = q[7].copy()
    expected = (Rotation.from_quat(target[[1, 2, 3, 0]]).inv() * Rotation.from_quat(q[:, [1, 2, 3, 0]])).magnitude()
    # acos near 1 loses half the digits: sqrt(eps) ~ 1.5e-8 rad is the conditioning at small angles
    np.testing.assert_allclose(pointing_errors(q, target), expected, atol=3e-8)
    t = np.arange(10.0)
    err = np.array([5, 4, 0.5, 0.2, 2, 0.9, 0.5, 0.1, 0.3, 0.2])
    assert settling_time(t, err, 1.0) == 5.0
    assert settling_time(t, err, 10.0) == 0.0
    assert settling_time(t, np.append(err[:-1], 3.0), 1.0) is None


@pytest.mark.parametrize("table, says", [
    ("target = [nan, 0, 0, 1]", "pointing.target[0]"), ("target = [1e308, 1e308, 0, 0]", "pointing.target[0]"),
    ("target = [1, 1, 0, 0]", "a unit quaternion"), ('target = "x"', "pointing.target"),
    ('target = [1, 0, 0, 0]\ntolerance = "1e400 deg"', "pointing.tolerance"),
    ('target = [1, 0, 0, 0]\ntolerance = "-1 deg"', "(0, 180 deg]"), ("tolerance = \"1 deg\"", "pointing.target"),
    ("target = [1, 0, 0, 0]\nextra = 1", "pointing.extra"),
])
def test_a_hostile_pointing_table_is_a_config_error_naming_the_field(table, says):
    from astrodyn.scenario import ScenarioError, loads

    text = (ROOT / "configs" / "slew.toml").read_text().split("[bodies.pointing]")[0]
    with pytest.raises(ScenarioError) as err:
        loads(text + "[bodies.pointing]\n" + table + "\n")
    assert "bodies[0] (sc).pointing" in str(err.value) and says in str(err.value)


def test_a_hostile_foxglove_service_request_is_refused_before_the_bus():
    """What a WebSocket client sends a control service: oversized, not JSON, nested past the
    parser, not an object, a token that is not a string; each refused naming the verb, and
    the bus is never asked (the session here is not a session)."""
    from astrodyn.service.viewer import MAX_SERVICE_REQUEST, forward_control

    for payload, says in [(b"{" + b" " * MAX_SERVICE_REQUEST + b"}", "at most"), (b"\xff\xfe", "JSON object"),
                          (b"[" * 30_000, "JSON object"), (b"[1, 2]", "JSON object, got list"),
                          (b'{"token": 5}', "rate.token: expected a string")]:
        with pytest.raises(ValueError, match="rate") as err:
            forward_control(object(), "x", "rate", payload)
        assert says in str(err.value), (payload[:20], str(err.value))
