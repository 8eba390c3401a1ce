"""Regressions found by fuzzing the *payloads* of MCAP recordings (valid files whose
messages or metadata are hostile) through every command that reads them.

Each test builds its hostile file here with the plain ``mcap`` writer and checks the
contract of docs/reliability.md / docs/control.md against an expectation written here: the
hostile message is counted invalid on its channel, or the command refuses the file naming
the channel and log time that were corrupted.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from mcap.writer import CompressionType, Writer

from astrodyn.recording import load
from astrodyn.scenario import ScenarioError, loads

EPOCH_NS = 1_774_008_000_000_000_000
ORBIT = {"t": 0.0, "seq": 0, "model": "kepler", "r": [7.0e6, 0.0, 0.0], "v": [0.0, 7.5e3, 0.0], "mu": 3.986004418e14,
         "frame": "GCRF"}
#: a closed-loop scene: one body "sc" with a torque actuator, 10 steps of 0.1 s
DET = loads('[scenario]\nname = "det"\nepoch = "2026-03-20T12:00:00 UTC"\nduration = "1 s"\nrate = "10 Hz"\n'
            '[control]\ncontrollers = ["c"]\n[[bodies]]\nname = "sc"\n[bodies.attitude]\n'
            'inertia = ["1 kg m2", "2 kg m2", "3 kg m2"]\n[bodies.actuators]\ntorque = "0.1 N m"\n')


def _write(path: Path, channels: dict[str, list[tuple[int, bytes]]], metadata: dict | None = None) -> Path:
    """An MCAP file of JSON channels: topic -> [(log_time, payload), ...]."""
    with open(path, "wb") as f:
        w = Writer(f, compression=CompressionType.ZSTD)
        w.start(profile="", library="payload-fuzz-regression")
        for topic, msgs in channels.items():
            cid = w.register_channel(topic, "json", w.register_schema(topic + ".schema", "jsonschema", b"{}"))
            for k, (log_time, data) in enumerate(msgs):
                w.add_message(cid, log_time=log_time, data=data, publish_time=log_time, sequence=k)
        for name, record in (metadata or {}).items():
            w.add_metadata(name, record)
        w.finish()
    return path


def _at(k: int) -> int:
    """The log time of step k of DET (0.1 s steps)."""
    return EPOCH_NS + k * 100_000_000


def _command(k: int, seq: int, **fields) -> tuple[int, bytes]:
    return _at(k), json.dumps({"t": k / 10, "seq": seq, "sender": "c", "torque": [0.01, 0.0, 0.0]} | fields).encode()


def _actuators(k: int, applied: list[str], body: str = "sc") -> tuple[int, bytes]:
    return _at(k), json.dumps({"t": k / 10, "seq": k, "torque": [0.01, 0.0, 0.0], "applied": applied}).encode()


def _commands_file(path: Path, commands: list, actuators: list, body: str = "sc", extra: dict | None = None) -> Path:
    return _write(path, {f"astrodyn/det/{body}/command": commands, f"astrodyn/det/{body}/actuators": actuators,
                         **(extra or {})})


def test_an_integer_past_float64_in_a_state_is_counted_invalid(tmp_path):
    """A 400-digit integer where astrodyn expects a number made the message decoder raise
    OverflowError (``math.isfinite`` of a huge int), so ``load``, analyze, export, replay's
    index, recover, merge, ``--resume`` and ``--commands`` all crashed with a traceback.  It is
    an invalid message on its channel, like 1e999."""
    big = "9" * 400
    good = [(EPOCH_NS + k, json.dumps(ORBIT | {"seq": k, "t": float(k)}).encode()) for k in range(3)]
    bad = (EPOCH_NS + 1, json.dumps(ORBIT | {"seq": 1}).replace('"t": 0.0', f'"t": {big}').encode())
    run = load(_write(tmp_path / "bigint.mcap", {"astrodyn/demo/sat/orbit": [good[0], bad, good[2]],
                                                  "astrodyn/demo/sat/attitude": [
        (EPOCH_NS, b'{"t":0.0,"seq":0,"model":"torque_free","q":[' + big.encode() + b',0,0,0],"w":[0,0,0]}')]}))
    assert run.invalid_by_channel == {"astrodyn/demo/sat/orbit": 1, "astrodyn/demo/sat/attitude": 1}
    assert run.channels["astrodyn/demo/sat/orbit"].seq.tolist() == [0, 2]
    # the reason is the decoder's ("orbit.t: expected a finite number") or the reader's ("... beyond float64")
    assert any(e.startswith("astrodyn/demo/sat/orbit seq 1: orbit") for e in run.invalid_examples), run.invalid_examples


def test_commands_with_an_integer_past_float64_name_the_channel_and_time(tmp_path):
    from astrodyn.service.plant import recorded_commands

    path = _commands_file(tmp_path / "c.mcap", [(_at(3), b'{"t":' + b"9" * 400 + b',"seq":0,"sender":"c"}')],
                          [_actuators(3, ["c#0"])])
    with pytest.raises(ValueError, match=f"astrodyn/det/sc/command at log time {_at(3)} ns: command.*(finite|float64)"):
        recorded_commands(path, "det")


def test_a_genuine_command_file_is_re_simulated(tmp_path):
    """The expectation the checks below must not break: each command applied once, at the
    step that holds its t (t inside the step, after the step's start, too)."""
    from astrodyn.service.plant import recorded_commands, recorded_faults

    path = _commands_file(tmp_path / "ok.mcap", [_command(2, 0), _command(4, 1, t=0.45)],
                          [_actuators(2, ["c#0"]), _actuators(3, []), _actuators(4, ["c#1"])])
    assert recorded_faults(path, DET) == []
    assert {k: [(b, c["seq"]) for b, c in v] for k, v in recorded_commands(path, DET).items()} == \
        {2: [("sc", 0)], 4: [("sc", 1)]}


def test_commands_for_a_body_not_in_the_scene_are_refused(tmp_path):
    """They were dropped without a word (0 refused), so a recording of another scene was
    "re-simulated" without its commands and the run exited 0."""
    from astrodyn.service.plant import recorded_commands

    ghost = _commands_file(tmp_path / "ghost.mcap", [_command(5, 0)], [_actuators(5, ["c#0"])], body="ghost",
                           extra={"astrodyn/det/sc/command": [_command(2, 0)],
                                  "astrodyn/det/sc/actuators": [_actuators(2, ["c#0"])]})
    with pytest.raises(ValueError, match=f"astrodyn/det/ghost/(command|actuators) at log time {_at(5)} ns: "
                                         "body 'ghost' is not an actuated body of scenario 'det' \\(sc\\)"):
        recorded_commands(ghost, DET)


def test_a_command_applied_at_two_steps_is_refused(tmp_path):
    """An actuator state naming a command already applied made ``--commands`` apply it
    again (552 commands applied from a recording of 551)."""
    from astrodyn.service.plant import recorded_commands

    path = _commands_file(tmp_path / "twice.mcap", [_command(2, 0)], [_actuators(2, ["c#0"]), _actuators(6, ["c#0"])])
    with pytest.raises(ValueError, match=f"astrodyn/det/sc/actuators at log time {_at(6)} ns: actuator state of sc "
                                         "at step 6 names command c#0, already applied at step 2"):
        recorded_commands(path, "det")


def test_one_command_id_with_two_contents_is_refused(tmp_path):
    """The last copy silently won; the plant records each command once."""
    from astrodyn.service.plant import recorded_commands

    path = _commands_file(tmp_path / "two.mcap", [_command(2, 0), _command(3, 0, torque=[0.1, 0.1, 0.1])],
                          [_actuators(2, ["c#0"])])
    with pytest.raises(ValueError, match=f"astrodyn/det/sc/command at log time {_at(3)} ns: command sc/c#0 is "
                                         f"recorded twice with different contents \\(first at .* {_at(2)} ns\\)"):
        recorded_commands(path, "det")
    same = _commands_file(tmp_path / "same.mcap", [_command(2, 0), _command(2, 0)], [_actuators(2, ["c#0"])])
    assert len(recorded_commands(same, "det")[2]) == 1  # an identical copy is the same command


def test_a_command_whose_t_is_after_its_step_is_refused(tmp_path):
    """A command with t = 1e9 s applied at step 5 made the re-simulating plant advance the
    body 1e9 s inside the step: the run hung until killed."""
    from astrodyn.service.plant import recorded_commands

    path = _commands_file(tmp_path / "late.mcap", [_command(5, 0, t=1e9)], [_actuators(5, ["c#0"])])
    with pytest.raises(ValueError, match=f"astrodyn/det/sc/command at log time {_at(5)} ns: command c#0 has "
                                         "t = 1000000000.0 s, after the end of step 5"):
        recorded_commands(path, DET)


def test_resume_of_a_closed_loop_scene_is_a_clear_error(tmp_path):
    """``run CLOSED_LOOP.toml --resume REC.mcap`` crashed with ``ValueError: kind: expected
    'orbit' or 'attitude', got 'plant'`` (a traceback) even on a genuine recording."""
    from astrodyn.service.runner import resume_plan

    meta = DET.to_metadata()
    rec = _write(tmp_path / "rec.mcap", {"astrodyn/det/sc/attitude": [(_at(0), json.dumps(
        {"t": 0.0, "seq": 0, "model": "actuated", "q": [1.0, 0, 0, 0], "w": [0, 0, 0]}).encode())]}, {"scenario": meta})
    with pytest.raises(ScenarioError, match="scenario 'det' is a closed loop: its plant cannot be resumed.*--commands"):
        resume_plan(rec, DET, tmp_path / "out.mcap", tmp_path)


def test_an_epoch_of_400_digits_is_no_epoch(tmp_path):
    """``epoch_unix_ns`` = 10**400 - 1 in the "recording" record passed int() and then
    overflowed float: an OverflowError traceback from ``replay`` (its status ``t``) and
    ``export --format foxglove``.  The stream skips it for the scenario record's epoch;
    export refuses it naming the value."""
    from astrodyn.recording.export import ExportError, export
    from astrodyn.recording.stream import open_stream

    big = "9" * 400
    path = _write(tmp_path / "epoch.mcap", {"astrodyn/demo/sat/orbit": [(EPOCH_NS + 10**9, json.dumps(ORBIT | {"t": 1.0}).encode())]},
                  {"scenario": {"name": "demo", "epoch_unix_ns": str(EPOCH_NS)}, "recording": {"epoch_unix_ns": big}})
    with open_stream(path) as s:
        assert s.epoch_ns == EPOCH_NS
        assert [s.ns_to_t(m.log_time) for m in s.messages()] == [1.0]
    with pytest.raises(ExportError, match=f"{path}: metadata epoch_unix_ns '9{{40}}': expected an integer number of ns"):
        export(path, "foxglove", tmp_path / "out")


@pytest.mark.parametrize("config", ["[" * 100_000 + "]" * 100_000, '{"bodies": [{"name": "sat", "attitude": [1]}], '
                                    '"central_body": [1]}', '{"bodies": [{"attitude": {"inertia": [1, 0, 0, 0, 1, 0, 0, 0, 1]}}]}'])
def test_a_hostile_scenario_json_is_no_config_not_a_crash(tmp_path, config):
    """The scenario record's ``json`` nested 100k deep raised RecursionError (a traceback
    from analyze and from export oem / aem / aem1 / foxglove); a body whose ``attitude`` is
    not an object, AttributeError, and one without a name KeyError.  Such a record describes no central body and no inertia."""
    from astrodyn.analysis.metrics import central_body_from_scenario, inertia_from_scenario
    from astrodyn.recording.export import export

    scenario = {"name": "demo", "epoch_unix_ns": str(EPOCH_NS), "epoch": "2026-03-20T12:00:00 UTC", "json": config}
    path = _write(tmp_path / "deep.mcap", {"astrodyn/demo/sat/orbit": [(EPOCH_NS, json.dumps(ORBIT).encode())]},
                  {"scenario": scenario})
    assert central_body_from_scenario(scenario) == {} and inertia_from_scenario(scenario) == {}
    [oem] = export(path, "oem", tmp_path / "out")
    assert "CENTER_NAME          = EARTH" in Path(oem).read_text()  # the default, as for a foreign file


def test_a_stored_schema_nested_100k_deep_is_no_schema(tmp_path):
    """``read_schema`` caught ValueError only: a foreign channel's JSON Schema nested 100k
    deep raised RecursionError out of ``load``."""
    path = tmp_path / "schema.mcap"
    with open(path, "wb") as f:
        w = Writer(f, compression=CompressionType.NONE)  # zstd would make it a refused bomb (ratio 1700)
        w.start(profile="", library="payload-fuzz-regression")
        cid = w.register_channel("other/x", "json", w.register_schema("x", "jsonschema", b"[" * 100_000 + b"]" * 100_000))
        w.add_message(cid, log_time=1, data=b'{"a": 1}', publish_time=1, sequence=0)
        w.finish()
    run = load(path)
    assert run.channels["other/x"].records == [{"a": 1}] and run.invalid == 0


@pytest.mark.parametrize("fmt", ["oem", "aem"])
def test_a_state_at_t_1e300_is_a_clear_export_error(tmp_path, fmt):
    """A valid state whose t is 1e300 s (a finite number, so the message is valid) made
    astropy / erfa raise ``ErfaError: unacceptable date``: a traceback from ``export
    --format oem|aem|aem1``.  The error names the channel and its span of t."""
    from astrodyn.recording.export import ExportError, export

    scenario = {"name": "demo", "epoch_unix_ns": str(EPOCH_NS), "epoch": "2026-03-20T12:00:00 UTC", "epoch_scale": "utc"}
    att = {"t": 0.0, "seq": 0, "model": "torque_free", "q": [1.0, 0.0, 0.0, 0.0], "w": [0.0, 0.0, 0.1]}
    kind, first = ("orbit", ORBIT) if fmt == "oem" else ("attitude", att)
    path = _write(tmp_path / "late.mcap", {f"astrodyn/demo/sat/{kind}": [
        (EPOCH_NS, json.dumps(first).encode()), (EPOCH_NS + 1, json.dumps(first | {"seq": 1, "t": 1e300}).encode())]},
        {"scenario": scenario})
    with pytest.raises(ExportError, match=f"{path}: astrodyn/demo/sat/{kind}: t from 0 to 1e\\+300 s: expected times a "
                                          "calendar date can show"):
        export(path, fmt, tmp_path / "out")
    assert not (tmp_path / "out").exists() or not any(p.suffix in (".oem", ".aem") for p in (tmp_path / "out").iterdir())
