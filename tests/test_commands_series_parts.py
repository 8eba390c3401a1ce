"""``astrodyn run CONFIG --commands REC.mcap`` given what is not one whole recording of a
run (docs/control.md, "Re-simulation and determinism").

- A part of a rolled series (``serve``, or a restarted logger: ``NAME-000k.mcap``, its
  ``recording`` metadata record says part k) does not hold the run's start: before, part 5
  of a series (steps 74 ..) was re-simulated from step 0 with no command until its first
  step, exit 0, and the run said only that the steps after its end were not a
  re-simulation.  It is refused, named as part k, pointing to ``astrodyn merge``; the first
  part of a series that goes on (no ``end`` record) is named as such.  The parts merged
  re-simulate bit for bit.
- A FIFO, a device or a directory is named as such (it was "no such file"), in the words of
  ``--resume``.
- What the command reader refuses names ``--commands FILE`` once (it was said twice).
- A file with two ``scenario`` metadata records that differ is refused by ``--commands`` and
  ``--resume`` alike, naming both (``--commands`` took the last, serve the first).

The parts here are written by astrodyn's own recorder (:class:`McapRecorder` with
``first_part``, as a restarted logger writes them), with commands and actuator states made
up here: step k applies one command, ``detumble#k``.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from _by_hand_controller import detumble_scene
from _recordings import payloads_by_topic
from _scenes import fault_table
from astrodyn import messages
from astrodyn.recording import McapRecorder
from astrodyn.recording.merge import merge
from astrodyn.scenario import ScenarioError, loads
from astrodyn.service.runner import check_command_recording, command_recording_notes, resume_plan

ROOT = Path(__file__).resolve().parents[1]

def _scenario(duration: str = "3 s", faults: str = ""):
    return loads(detumble_scene(duration, faults=faults))


def _write_part(base: Path, part: int, steps: range | list[int], *, end: bool, scenario=None, commands: bool = True,
                applied: bool = True, extra_scenario=None) -> Path:
    """Part ``part`` of the recording ``base`` (``base`` itself for 0, ``NAME-000k.mcap``
    after), by the recorder a logger uses: at each output step k of ``steps`` the command
    ``detumble#k`` (t = k / 10 s; left out without ``commands``) and the actuator state
    naming it (naming none without ``applied``); ``end``: the ``end`` record the logger writes into the part it stops in;
    ``extra_scenario``: a second ``scenario`` record, written after the messages."""
    scenario = scenario or _scenario()
    rec = McapRecorder(base, scenario.to_metadata(), epoch_ns=scenario.epoch_unix_ns, first_part=part)
    with rec:
        for k in steps:
            t = k / 10
            if commands:
                rec.write_encoded("astrodyn/detumble/sc/command", messages.encode(
                    {"t": t, "seq": k, "sender": "detumble", "torque": [1e-3, -2e-3, 3e-4]}, "command"),
                    t, k, track="detumble")
            rec.write_encoded("astrodyn/detumble/sc/actuators", json.dumps(
                {"t": t, "seq": k, "torque": [1e-3, -2e-3, 3e-4], "applied": [f"detumble#{k}"] if applied else []}).encode(), t, k)
        if end:
            rec.add_metadata("end", {"reason": "stop requested", "t": str(steps[-1] / 10)})
        if extra_scenario is not None:
            rec.add_metadata("scenario", extra_scenario.to_metadata())
    return Path(rec.paths[-1])


def _refusal(scenario, path: Path, tmp_path: Path) -> str:
    with pytest.raises(ScenarioError) as err:
        check_command_recording(scenario, path, tmp_path / "out.mcap")
    return str(err.value)


def test_a_later_part_of_a_series_is_refused_naming_it_and_merge_and_the_merged_parts_are_taken(tmp_path):
    scenario = _scenario()
    base = tmp_path / "rec.mcap"
    first = _write_part(base, 0, range(0, 10), end=False)
    second = _write_part(base, 1, range(10, 20), end=False)
    last = _write_part(base, 2, range(20, 31), end=True)
    assert (first.name, second.name, last.name) == ("rec.mcap", "rec-0001.mcap", "rec-0002.mcap")
    for k, part in ((1, second), (2, last)):
        err = _refusal(scenario, part, tmp_path)
        assert err.startswith(f"--commands {part}: ") and f"part {k} of a rolled recording" in err, err
        assert "astrodyn merge" in err and f"{base} {tmp_path / 'rec-0001.mcap'}" in err, err

    # the first part holds the start: taken, and named as the first part of a series that goes on
    info = check_command_recording(scenario, first, tmp_path / "out.mcap")
    assert info["applied"] == 10 and info["last_step"] == 9
    notes = " ".join(command_recording_notes(info, scenario))
    assert "part 0 of a rolled recording that goes on in rec-0001.mcap" in notes and "astrodyn merge" in notes, notes

    # the three merged: every step from 0 to 30, one command each, and nothing said of parts
    merged = tmp_path / "merged.mcap"
    merge([first, second, last], merged)
    info = check_command_recording(scenario, merged, tmp_path / "out.mcap")
    assert (info["applied"], info["last_step"], info["series_goes_on"]) == (31, 30, None)
    assert not any("part" in note for note in command_recording_notes(info, scenario))


def test_a_recording_that_does_not_start_at_step_0_is_refused_naming_its_first_step(tmp_path):
    """A file whose ``recording`` record says part 0 (or says nothing) but whose first
    actuator state is at step 10: steps 0 .. 9 would run without their commands."""
    scenario = _scenario()
    cut = _write_part(tmp_path / "cut.mcap", 0, range(10, 31), end=True)
    err = _refusal(scenario, cut, tmp_path)
    assert "first actuator state is at step 10 (t = 1 s)" in err and "astrodyn merge" in err, err


def test_the_first_part_without_commands_says_it_is_the_first_part_of_a_series(tmp_path):
    """serve's first file is often empty of commands (the controller still starting when the
    first second rolled over): before, "found none: nothing to re-simulate", and no word of
    the parts after it."""
    base = tmp_path / "rec.mcap"
    first = _write_part(base, 0, range(0, 3), end=False, commands=False, applied=False)
    (first.parent / "rec-0001.mcap").write_bytes(b"")  # (what follows it; not read)
    err = _refusal(_scenario(), first, tmp_path)
    assert "found none: nothing to re-simulate" in err, err
    assert "part 0 of a rolled recording that goes on in rec-0001.mcap" in err and "astrodyn merge" in err, err


def test_a_fifo_a_device_and_a_directory_are_named_as_such_as_resume_names_them(tmp_path):
    fifo = tmp_path / "fifo.mcap"
    os.mkfifo(fifo)
    scenario = _scenario()
    for path, kind in ((fifo, "a FIFO"), (Path("/dev/null"), "a character device"), (tmp_path, "a directory")):
        err = _refusal(scenario, path, tmp_path)
        assert err == f"--commands {path}: cannot open: expected a regular file, got {kind}", err
        with pytest.raises(ScenarioError) as resumed:  # --resume's words for it
            resume_plan(path, scenario, tmp_path / "out.mcap", tmp_path)
        assert f"cannot open: expected a regular file, got {kind}" in str(resumed.value), resumed.value


def test_what_the_command_reader_refuses_names_the_flag_once(tmp_path):
    """An actuator state naming a command the file does not hold (the reader's own check)."""
    scenario = _scenario()
    path = _write_part(tmp_path / "nocmd.mcap", 0, range(0, 31), end=True, commands=False)
    err = _refusal(scenario, path, tmp_path)
    assert "names command detumble#0, which the recording does not hold" in err, err
    assert err.count("--commands") == 1 and err.count(str(path)) == 1, err


def test_two_scenario_records_that_differ_are_refused_by_commands_and_resume_naming_both(tmp_path):
    """The first record of another config (rate 5 Hz), the last of this one: ``--commands``
    took the last (accepted), serve's check the first (refused)."""
    from astrodyn.service.supervision import holds_config

    this = _scenario()
    other = loads(detumble_scene("3 s", rate="5 Hz", period="0.2 s"))
    path = _write_part(tmp_path / "two.mcap", 0, range(0, 31), end=True, scenario=other, extra_scenario=this)
    err = _refusal(this, path, tmp_path)
    assert "got records that differ" in err and 'scenario.rate is "10 Hz" here, "5 Hz" in the recording' in err, err
    assert "this config" in err, err
    with pytest.raises(ScenarioError) as resumed:
        resume_plan(path, this, tmp_path / "out.mcap", tmp_path)
    assert str(resumed.value).startswith(f"--resume {path}: ") and "got records that differ" in str(resumed.value)
    assert not holds_config(path, this)  # serve does not take it for this config's either
    # copies of one record are one record
    same = _write_part(tmp_path / "same.mcap", 0, range(0, 31), end=True, scenario=this, extra_scenario=this)
    assert check_command_recording(this, same, tmp_path / "out.mcap")["applied"] == 31


_FAULTS = (fault_table("1 s", "gyro_bias", value=["2e-4 rad/s", 0, 0])
           + fault_table("2 s", "sensor_dropout", sensor="gyro", duration="0.5 s"))


@pytest.mark.slow
@pytest.mark.network
def test_a_served_series_parts_are_refused_and_merged_they_re_simulate_bit_for_bit(tmp_path):
    """A real closed-loop ``serve`` with a new file each wall second (about 10 s): every part
    after the first is refused naming its part number (from its file name, NAME-000k.mcap)
    and ``astrodyn merge``; the first is named as the first of a series; ``merge`` of all
    re-simulates every recorded state, sensor sample and actuator state bit for bit."""
    config = tmp_path / "det.toml"
    config.write_text(detumble_scene("30 s", faults=_FAULTS))
    base = tmp_path / "d.mcap"
    proc = subprocess.run([sys.executable, "-m", "astrodyn", "serve", str(config), "--out", str(base), "--controller",
                           f"{sys.executable} {ROOT / 'examples' / 'detumble.py'}", "--roll-interval", "1",
                           "--rate", "5", "--max-wall", "4"], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-3000:]
    parts = sorted(tmp_path.glob("d-[0-9][0-9][0-9][0-9].mcap"))
    assert len(parts) >= 2, sorted(p.name for p in tmp_path.iterdir())
    scenario = _scenario("30 s", _FAULTS)
    for part in parts:
        k = int(part.stem.rsplit("-", 1)[1])
        err = _refusal(scenario, part, tmp_path)
        assert f"part {k} of a rolled recording" in err and "astrodyn merge" in err, err
    try:
        said = " ".join(command_recording_notes(check_command_recording(scenario, base, tmp_path / "o.mcap"), scenario))
    except ScenarioError as exc:  # no command in it yet (the controller was starting)
        said = str(exc)
    assert "part 0 of a rolled recording that goes on in d-0001.mcap" in said and "astrodyn merge" in said, said

    merged = tmp_path / "merged.mcap"
    subprocess.run([sys.executable, "-m", "astrodyn", "merge", "--out", str(merged), str(base), *map(str, parts)],
                   check=True, capture_output=True, timeout=60, cwd=ROOT)
    again = tmp_path / "again.mcap"
    proc = subprocess.run([sys.executable, "-m", "astrodyn", "run", str(config), "--out", str(again), "--quiet",
                           "--commands", str(merged)], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-3000:]
    kinds = ("/attitude", "/gyro", "/actuators")
    recorded, resimulated = payloads_by_topic(merged, kinds), payloads_by_topic(again, kinds)
    assert len(recorded["astrodyn/detumble/sc/actuators"]) > 20
    for key, payloads in recorded.items():
        assert resimulated[key][:len(payloads)] == payloads, key


def test_resume_from_a_later_part_names_it_and_merge(tmp_path):
    """``run --resume PART`` of a later part of a rolled series said only "found none" (its
    states start after step 0): it now names the part and the merge to resume from."""
    from _recordings import one_satellite_scene

    scenario = loads(one_satellite_scene("rp", "10 s", "1 Hz"))
    base = tmp_path / "rp.mcap"
    rec = McapRecorder(base, scenario.to_metadata(), epoch_ns=scenario.epoch_unix_ns, first_part=1)
    with rec:
        for k in range(4, 8):  # part 1 holds steps 4 .. 7: 0 .. 3 are in part 0
            rec.write("astrodyn/rp/sat/orbit", messages.orbit_message(float(k), k, "kepler", [7e6, 0, 0],
                                                                      [0, 7.5e3, 0], 3.986004418e14))
            rec.write("astrodyn/rp/sat/attitude", messages.attitude_message(float(k), k, "torque_free",
                                                                            [1, 0, 0, 0], [0.01, 0.2, 0.01]))
    part = Path(rec.paths[-1])
    assert part.name == "rp-0001.mcap"
    with pytest.raises(ScenarioError) as err:
        resume_plan(part, scenario, tmp_path / "out.mcap", tmp_path)
    said = str(err.value)
    assert "found none" in said and "part 1 of a rolled recording" in said, said
    assert "astrodyn merge" in said and "give --resume the merged file" in said, said


def test_a_recording_with_steps_cut_out_of_its_middle_is_refused_naming_them(tmp_path):
    """Probe D (D2): a merged recording with steps 3000-3499 removed re-simulated them without
    their commands, exit 0; the plant records an actuator state at every step, so a hole in
    them is named."""
    scenario = _scenario()
    holed = _write_part(tmp_path / "holed.mcap", 0, [*range(0, 10), *range(15, 31)], end=True)
    err = _refusal(scenario, holed, tmp_path)
    assert "actuator states of steps 10 .. 14 are missing" in err, err
    whole = _write_part(tmp_path / "whole.mcap", 0, range(0, 31), end=True)
    assert check_command_recording(scenario, whole, tmp_path / "out.mcap")["applied"] == 31
