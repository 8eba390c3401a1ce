"""``astrodyn run CONFIG --commands REC.mcap`` against recordings it cannot re-simulate as
they are (docs/control.md, "Re-simulation and determinism").

A recording of another rate or config is refused naming what differs (as ``--resume``
refuses one); one that ends before the config's last step, or goes on past its duration,
is re-simulated to the config's duration and the run says so at the start and at the end,
with counts read here from the recording itself; a file torn inside its data says so and
points to ``astrodyn recover``; the check before the run keeps no decoded command.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tracemalloc
from pathlib import Path

import pytest

from _by_hand_controller import detumble_scene
from _recordings import payloads_by_topic
from _scenes import fault_table
from astrodyn.recording.stream import open_stream

ROOT = Path(__file__).resolve().parents[1]
RUN = [sys.executable, "-m", "astrodyn", "run"]

_GYRO_BIAS = fault_table("1.5 s", "gyro_bias", value=["2e-4 rad/s", 0, 0])
_NOMINAL = {"duration": "3 s", "rate": "10 Hz", "period": "0.1 s", "seed": 42, "torque": "0.05 N m"}


def _config(path: Path, **changes) -> Path:
    path.write_text(detumble_scene(**{**_NOMINAL, **changes}, faults=_GYRO_BIAS))
    return path


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    """A 3 s lockstep run of the scene at 10 Hz (steps 0 .. 30) with examples/detumble.py."""
    work = tmp_path_factory.mktemp("rec")
    out = work / "rec.mcap"
    proc = subprocess.run([*RUN, str(_config(work / "det.toml")), "--out", str(out), "--quiet", "--controller",
                           f"python {ROOT / 'examples' / 'detumble.py'}"], capture_output=True, text=True, timeout=120,
                          cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return out


def _applied_by_step(path: Path) -> dict[int, int]:
    """Output step -> commands applied in it, from the recording's actuator states."""
    with open_stream(path) as s:
        return {json.loads(m.data)["seq"]: len(json.loads(m.data).get("applied", []))
                for m in s.messages() if m.topic == "astrodyn/detumble/sc/actuators"}


def _refused(capsys, argv: list[str]) -> str:
    """Run ``astrodyn run`` in this process (it ends before anything starts); its stderr."""
    from astrodyn.service.runner import main as runner_main

    rc = runner_main(argv)
    err = capsys.readouterr().err
    assert rc == 2, err
    return err


@pytest.mark.network
def test_a_recording_of_another_rate_or_config_is_refused_naming_what_differs(recording, tmp_path, capsys):
    from astrodyn.scenario import load
    from astrodyn.service.runner import check_command_recording

    cases = [({"rate": "5 Hz", "period": "0.2 s"}, ('scenario.rate is "5 Hz" here, "10 Hz" in the recording',
                                                   'control.period is "0.2 s" here, "0.1 s" in the recording')),
             ({"seed": 7}, ("control.seed is 7 here, 42 in the recording",)),
             ({"torque": "0.01 N m"}, ('bodies[0].actuators.torque is "0.01 N m" here, "0.05 N m" in the recording',))]
    for n, (changes, named) in enumerate(cases):
        err = _refused(capsys, [str(_config(tmp_path / f"c{n}.toml", **changes)), "--out", str(tmp_path / "x.mcap"),
                                "--commands", str(recording)])
        assert "--commands" in err and "another config of 'detumble'" in err, err
        for text in named:
            assert text in err, err
    assert not (tmp_path / "x.mcap").exists()
    # the same config read from another file (another path, a copy) is the same config
    (tmp_path / "elsewhere").mkdir()
    same = _config(tmp_path / "elsewhere" / "copy.toml")
    check_command_recording(load(same), recording, tmp_path / "y.mcap")


@pytest.mark.network
def _first_chunk_middle(data: bytes) -> int:
    """The offset of the middle of the first Chunk record of MCAP ``data``, walking its records
    as the MCAP spec lays them out: 8 magic bytes, then opcode (1 byte), length (uint64 LE),
    body; Chunk is opcode 0x06.  (How many chunks the logger wrote depends on its flushes.)"""
    pos = 8
    while pos + 9 <= len(data):
        opcode, length = data[pos], int.from_bytes(data[pos + 1:pos + 9], "little")
        if opcode == 0x06:
            return pos + 9 + length // 2
        pos += 9 + length
    raise AssertionError("no chunk in the recording")


def test_a_recording_torn_inside_its_data_says_so_and_points_to_recover(recording, tmp_path, capsys):
    data = recording.read_bytes()
    torn = tmp_path / "torn.mcap"
    torn.write_bytes(data[:_first_chunk_middle(data)])  # no command readable: cut inside the first data chunk
    err = _refused(capsys, [str(_config(tmp_path / "c.toml")), "--out", str(tmp_path / "x.mcap"), "--commands",
                            str(torn)])
    assert "cut short or damaged" in err and "truncated" in err and f"astrodyn recover {torn}" in err, err


def _resimulate(config: Path, recording: Path, out: Path) -> tuple[subprocess.CompletedProcess, dict]:
    js = out.with_suffix(".json")
    proc = subprocess.run([*RUN, str(config), "--out", str(out), "--quiet", "--json", str(js), "--commands",
                           str(recording)], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return proc, json.loads(js.read_text())


def _end_line(stderr: str) -> str:
    return next(line for line in stderr.splitlines() if line.startswith("astrodyn run: closed loop:"))


@pytest.mark.network
def test_a_recording_that_ends_before_the_configs_end_is_said_and_its_steps_come_out_bit_for_bit(recording, tmp_path):
    steps = _applied_by_step(recording)
    last = max(steps)  # 30: the recording's last step; the config of 4 s goes on to step 40
    out = tmp_path / "longer.mcap"
    proc, result = _resimulate(_config(tmp_path / "c.toml", duration="4 s"), recording, out)
    start = f"the recording ends at step {last} (t = {last / 10:g} s), before this config's last step 40 (t = 4 s)"
    assert start in proc.stderr and "stay held" in proc.stderr, proc.stderr[-3000:]
    assert f"the recording ended at step {last}" in _end_line(proc.stderr), proc.stderr[-3000:]
    assert result["commands_recording"]["last_step"] == last and result["commands_recording"]["held_after"]
    kinds = ("/attitude", "/gyro", "/actuators")
    first, again = payloads_by_topic(recording, kinds), payloads_by_topic(out, kinds)
    for key, payloads in first.items():  # the recorded steps, bit for bit; then the config's remaining ones
        assert again[key][:len(payloads)] == payloads, key
    assert len(again["astrodyn/detumble/sc/attitude"]) == 41


@pytest.mark.network
def test_recorded_commands_past_the_configs_duration_are_counted_as_not_applied(recording, tmp_path):
    steps = _applied_by_step(recording)
    beyond = sum(n for k, n in steps.items() if k > 20)  # the config of 2 s ends at step 20
    assert beyond > 0
    proc, result = _resimulate(_config(tmp_path / "c.toml", duration="2 s"), recording, tmp_path / "shorter.mcap")
    assert f"past this config's duration (2 s): its {beyond} recorded commands after that are not applied" \
        in proc.stderr, proc.stderr[-3000:]
    assert f"{beyond} recorded commands after the config's duration not applied" in _end_line(proc.stderr)
    assert result["commands_recording"]["commands_after_end"] == beyond
    assert f"{sum(n for k, n in steps.items() if k <= 20)} commands applied" in _end_line(proc.stderr)


def test_the_check_before_the_run_keeps_no_decoded_command(tmp_path):
    """F11: ``run`` reads the recording to check it, and the plant reads it again: the check
    holds the commands as their payload bytes while it reads, not decoded (a decoded command,
    a dict of floats and lists, weighs several times its JSON)."""
    from mcap.writer import CompressionType, Writer

    from astrodyn import messages
    from astrodyn.scenario import load
    from astrodyn.service.plant import read_command_recording

    scenario = load(_config(tmp_path / "c.toml"))
    per_step, steps = 300, 31
    path = tmp_path / "many.mcap"
    with open(path, "wb") as f:
        w = Writer(f, compression=CompressionType.ZSTD)
        w.start(profile="", library="test")
        w.add_metadata("scenario", scenario.to_metadata())
        cmd = w.register_channel("astrodyn/detumble/sc/command", "json", w.register_schema("c", "jsonschema", b"{}"))
        act = w.register_channel("astrodyn/detumble/sc/actuators", "json", w.register_schema("a", "jsonschema", b"{}"))
        for k in range(steps):
            ids = []
            for i in range(per_step):
                seq = k * per_step + i
                w.add_message(cmd, log_time=k, publish_time=k, data=messages.encode(
                    {"t": k / 10, "seq": seq, "sender": "detumble", "torque": [1e-3 * i, -2e-3, 3.5e-4 * k]}, "command"))
                ids.append(f"detumble#{seq}")
            w.add_message(act, log_time=k, publish_time=k, data=json.dumps(
                {"t": k / 10, "seq": k, "torque": [0.0, 0.0, 0.0], "applied": ids}).encode())
        w.finish()

    def peak(keep: bool) -> tuple[int, object]:
        tracemalloc.start()
        try:
            found = read_command_recording(path, scenario, keep=keep)
            return tracemalloc.get_traced_memory()[1], found
        finally:
            tracemalloc.stop()

    checked_peak, checked = peak(False)
    kept_peak, kept = peak(True)
    n = per_step * steps
    assert checked.applied == kept.applied == n and not checked.by_step and len(kept.by_step) == steps
    # a decoded command: its dict, its list of 3 floats, the floats (sys.getsizeof, not the code under test)
    one = messages.decode(messages.encode({"t": 1.5, "seq": 12345, "sender": "detumble", "torque": [1e-3, -2e-3, 3e-4]},
                                          "command"), "command")
    decoded = sys.getsizeof(one) + sys.getsizeof(one["torque"]) + 4 * sys.getsizeof(1.5)
    assert kept_peak - checked_peak > 0.5 * n * decoded, (kept_peak, checked_peak, n * decoded)
