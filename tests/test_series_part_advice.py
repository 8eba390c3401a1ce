"""What ``run --commands``, ``run --resume`` and ``merge`` say of files that are not a whole
rolled series from its part 0 (session 20 probe D, D3).

- ``merge d-0002.mcap d-0003.mcap`` then ``--commands`` of it was refused with the command
  reader's "actuator state of sc at step 20 names command detumble#19, which the recording
  does not hold" (the command was recorded in part 1), never with the part and merge advice
  a later part gets: a recording that does not start at step 0 is now named as such first,
  and a merge of later parts names its parts and the merge from part 0.
- ``--resume`` of such a merge, and of a part 0 that holds no complete step while its series
  goes on (at ``--rate inf`` one process's first states come parts after another's), said
  only "found none"; they now name the parts / the series and the merge to make.
- ``merge d.mcap d-0001.mcap d-0003.mcap`` merged without a word about part 2; it is
  refused naming it (exit 1), unless ``--allow-missing-parts`` (then a warning names it).

The parts are written by the recorder a logger uses (:class:`McapRecorder` with
``first_part``, as serve's rolled parts and a restarted logger's are), with made-up
states, commands and actuator states: at step k the plant applies the command sent at step
k - 1 (``detumble#k-1``), so the first actuator state of part 2 names a command of part 1.
What is expected is fixed by that construction (which steps each part holds), not by the
code's output.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from _by_hand_controller import detumble_scene
from _recordings import one_satellite_scene
from astrodyn import messages
from astrodyn.recording import McapRecorder
from astrodyn.recording.merge import main as merge_main, merge
from astrodyn.recording.writer import RecordingError
from astrodyn.scenario import ScenarioError, loads
from astrodyn.service.runner import check_command_recording, resume_plan

DETUMBLE = loads(detumble_scene("4 s"))

#: the steps each part of the closed-loop series holds (part k: 10 k .. 10 k + 9; the last ends)
PARTS = {0: range(0, 10), 1: range(10, 20), 2: range(20, 30), 3: range(30, 41)}


def closed_loop_part(base: Path, part: int) -> Path:
    """Part ``part`` of the closed-loop recording ``base``: steps :data:`PARTS` ``[part]``,
    at each the command ``detumble#k`` and the actuator state applying ``detumble#k-1``."""
    rec = McapRecorder(base, DETUMBLE.to_metadata(), epoch_ns=DETUMBLE.epoch_unix_ns, first_part=part)
    with rec:
        for k in PARTS[part]:
            t = k / 10
            rec.write_encoded("astrodyn/detumble/sc/command", messages.encode(
                {"t": t, "seq": k, "sender": "detumble", "torque": [1e-3, -2e-3, 3e-4]}, "command"),
                t, k, track="detumble")
            rec.write_encoded("astrodyn/detumble/sc/actuators", json.dumps(
                {"t": t, "seq": k, "torque": [1e-3, -2e-3, 3e-4],
                 "applied": [f"detumble#{k - 1}"] if k else []}).encode(), t, k)
        if part == max(PARTS):
            rec.add_metadata("end", {"reason": "stop requested", "t": str(PARTS[part][-1] / 10)})
    return Path(rec.paths[-1])


def commands_refusal(path: Path, tmp_path: Path) -> str:
    with pytest.raises(ScenarioError) as err:
        check_command_recording(DETUMBLE, path, tmp_path / "out.mcap")
    return str(err.value)


def test_commands_of_a_merge_of_later_parts_names_its_parts_and_the_merge_from_part_0(tmp_path):
    base = tmp_path / "d.mcap"
    parts = [closed_loop_part(base, k) for k in PARTS]
    assert [p.name for p in parts] == ["d.mcap", "d-0001.mcap", "d-0002.mcap", "d-0003.mcap"]
    late = tmp_path / "m_late.mcap"
    merge(parts[2:], late)
    err = commands_refusal(late, tmp_path)
    assert "does not hold" not in err, err  # (the reader's words for detumble#19, which part 1 holds)
    assert f"first actuator state is at step {PARTS[2][0]}" in err, err
    assert "a merge of parts 2-3 of a rolled recording" in err and "d-0002.mcap, is part 2" in err, err
    assert "the steps from 0 are in parts 0 .. 1" in err, err
    assert f"astrodyn merge --out MERGED.mcap {base} {tmp_path / 'd-0001.mcap'}" in err, err
    assert "give --commands the merged file" in err, err

    # every part from the first, merged: taken, each step from 1 applying one command
    whole = tmp_path / "m_all.mcap"
    merge(parts, whole)
    info = check_command_recording(DETUMBLE, whole, tmp_path / "out.mcap")
    assert (info["applied"], info["last_step"]) == (PARTS[3][-1], PARTS[3][-1])


def open_loop_part(base: Path, scenario, part: int, orbit: range, attitude: range, end: bool = False) -> Path:
    """Part ``part`` of an open-loop recording ``base`` of ``scenario`` (body ``sat``),
    holding the orbit states of the steps ``orbit`` and the attitude states of ``attitude``."""
    rec = McapRecorder(base, scenario.to_metadata(), epoch_ns=scenario.epoch_unix_ns, first_part=part)
    name = scenario.name
    with rec:
        for k in sorted({*orbit, *attitude}):
            if k in orbit:
                rec.write(f"astrodyn/{name}/sat/orbit", messages.orbit_message(
                    float(k), k, "kepler", [7e6, 0, 0], [0, 7.5e3, 0], 3.986004418e14))
            if k in attitude:
                rec.write(f"astrodyn/{name}/sat/attitude", messages.attitude_message(
                    float(k), k, "torque_free", [1, 0, 0, 0], [0.01, 0.2, 0.01]))
        if end:
            rec.add_metadata("end", {"reason": "stop requested", "t": str(float(max(orbit)))})
    return Path(rec.paths[-1])


def resume_refusal(path: Path, scenario, tmp_path: Path) -> str:
    with pytest.raises(ScenarioError) as err:
        resume_plan(path, scenario, tmp_path / "out.mcap", tmp_path)
    return str(err.value)


def test_resume_of_a_merge_of_later_parts_names_its_parts_and_the_merge(tmp_path):
    scenario = loads(one_satellite_scene("rp", "20 s", "1 Hz"))
    base = tmp_path / "rp.mcap"
    parts = [open_loop_part(base, scenario, k, range(4 * k, 4 * k + 4), range(4 * k, 4 * k + 4)) for k in range(4)]
    late = tmp_path / "late.mcap"
    merge(parts[2:], late)  # steps 8 .. 15: none from step 0
    said = resume_refusal(late, scenario, tmp_path)
    assert "found none" in said and "a merge of parts 2-3 of a rolled recording" in said, said
    assert f"astrodyn merge --out MERGED.mcap {base} {tmp_path / 'rp-0001.mcap'}" in said, said
    assert "give --resume the merged file" in said, said
    whole = tmp_path / "whole.mcap"
    merge(parts, whole)
    assert resume_plan(whole, scenario, tmp_path / "out.mcap", tmp_path)["step"] == 16  # steps 0 .. 15 held


def test_resume_of_a_first_part_without_a_complete_step_names_the_series_that_goes_on(tmp_path):
    """Part 0 holds orbit states 0 .. 3 and no attitude state: the attitude's first states
    came in part 1 (as at ``serve --rate inf``)."""
    scenario = loads(one_satellite_scene("rq", "20 s", "1 Hz"))
    base = tmp_path / "rq.mcap"
    first = open_loop_part(base, scenario, 0, range(0, 4), range(0))
    second = open_loop_part(base, scenario, 1, range(4, 8), range(0, 8), end=True)
    said = resume_refusal(first, scenario, tmp_path)
    assert "found none" in said and "part 0 of a rolled recording that goes on in rq-0001.mcap" in said, said
    assert "astrodyn merge" in said and "give --resume the merged file" in said, said
    whole = tmp_path / "whole.mcap"
    merge([first, second], whole)
    assert resume_plan(whole, scenario, tmp_path / "out.mcap", tmp_path)["step"] == 8  # both from 0 to 7


def test_merge_refuses_parts_that_leave_one_out_naming_it_unless_allowed(tmp_path, capsys):
    base = tmp_path / "d.mcap"
    parts = [closed_loop_part(base, k) for k in PARTS]
    skipped = [parts[0], parts[1], parts[3]]
    with pytest.raises(RecordingError) as err:
        merge(skipped, tmp_path / "m.mcap")
    assert "without part 2 (d-0002.mcap)" in str(err.value) and "--allow-missing-parts" in str(err.value), err.value
    assert not (tmp_path / "m.mcap").exists()

    # the command line: exit 1, one line naming the part; with the flag, merged with a warning
    out = tmp_path / "m_cli.mcap"
    assert merge_main(["--out", str(out), *map(str, skipped)]) == 1
    assert "without part 2 (d-0002.mcap)" in capsys.readouterr().err and not out.exists()
    assert merge_main(["--out", str(out), "--allow-missing-parts", *map(str, skipped)]) == 0
    captured = capsys.readouterr()
    assert "warning: part 2 is missing" in captured.err, captured.err
    assert json.loads(captured.out)["missing_parts"] == "2"
    with pytest.raises(ScenarioError) as refused:  # what it lacks is still named when re-simulated
        check_command_recording(DETUMBLE, out, tmp_path / "out.mcap")
    assert "without part 2 " in str(refused.value) and "does not hold" not in str(refused.value), refused.value

    # consecutive later parts are one stretch of the run: merged; a merge of merges lists every part
    late = tmp_path / "late.mcap"
    assert merge(parts[2:], late).parts == "2-3"
    first_two = tmp_path / "first_two.mcap"
    merge(parts[:2], first_two)
    with pytest.raises(RecordingError) as err:
        merge([first_two, parts[3]], tmp_path / "m2.mcap")
    assert "without part 2" in str(err.value), err.value
    assert merge([first_two, late], tmp_path / "m3.mcap").parts == "0-3"
