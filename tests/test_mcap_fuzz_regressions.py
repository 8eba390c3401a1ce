"""Regressions found by fuzzing the MCAP readers (hostile files the corpus of
``test_hostile_files.py`` and ``test_untrusted_input.py`` did not hold).

Each test builds its hostile file here, with the plain ``mcap`` writer, and checks the
contract of docs/reliability.md: a clear error naming the file, or a documented partial
result, in bounded time and memory; nothing already on disk replaced by a failed command.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from mcap.writer import CompressionType, Writer

from astrodyn.recording import RecordingError, load
from astrodyn.recording.export import ExportError, export
from astrodyn.recording.merge import merge
from astrodyn.recording.stream import open_stream

ASTRODYN = [sys.executable, "-m", "astrodyn"]
ORBIT = {"t": 0.0, "seq": 0, "model": "kepler", "r": [7.0e6, 0.0, 0.0], "v": [0.0, 7.5e3, 0.0], "mu": 3.986004418e14,
         "frame": "GCRF"}


def _write(path: Path, channels: list[tuple[str, bytes, list[tuple[int, bytes]]]]) -> Path:
    """An MCAP file of JSON channels: (topic, JSON Schema bytes, [(log_time, payload), ...])."""
    with open(path, "wb") as f:
        w = Writer(f, compression=CompressionType.ZSTD)
        w.start(profile="", library="fuzz-regression")
        for topic, schema, msgs in channels:
            cid = w.register_channel(topic, "json", w.register_schema(topic + ".schema", "jsonschema", schema))
            for k, (log_time, data) in enumerate(msgs):
                w.add_message(cid, log_time=log_time, data=data, publish_time=0, sequence=k)
        w.finish()
    return path


def _orbit_file(path: Path) -> Path:
    return _write(path, [("astrodyn/demo/sat/orbit", b"{}", [(k, json.dumps(ORBIT | {"seq": k, "t": float(k)}).encode())
                                                             for k in range(3)])])


def _cli(*argv: str, timeout: float = 60) -> subprocess.CompletedProcess:
    return subprocess.run([*ASTRODYN, *argv], capture_output=True, text=True, timeout=timeout)


@pytest.mark.parametrize("schema", [
    {"properties": {"a": 1, "b": "x"}},                               # a property that is not an object
    {"properties": ["a", "b"]},                                        # properties not an object
    {"properties": None},
    {"properties": {"a": {"type": "array", "minItems": 3, "maxItems": 3, "items": None}}},
    {"properties": {"a": {"type": "array", "minItems": 1.5, "maxItems": 1.5, "items": {"type": "number"}}}},
])
def test_a_foreign_schema_of_any_shape_is_read(tmp_path, schema):
    """The schema stored with a foreign channel is untrusted JSON: any shape gives the
    messages (as records or checked columns), never AttributeError / TypeError."""
    path = _write(tmp_path / "schema.mcap", [("other/s", json.dumps(schema).encode(), [(1, b'{"a": [1, 2, 3]}')])])
    run = load(path)
    assert run.messages + run.invalid == 1 and "other/s" in run.channels


def test_a_schema_claiming_a_billion_numbers_stays_in_bounded_memory(tmp_path):
    """``minItems = maxItems = 10**9`` made every message without the field a row of 10**9
    NaN (8 GB each); under a 1 GiB address-space limit the load must finish."""
    schema = {"type": "object", "properties": {"v": {"type": "array", "minItems": 10**9, "maxItems": 10**9,
                                                     "items": {"type": "number"}}}}
    path = _write(tmp_path / "billion.mcap", [("other/v", json.dumps(schema).encode(), [(1, b"{}"), (2, b'{"v": [1]}')])])
    code = ("import resource, sys\n"
            "resource.setrlimit(resource.RLIMIT_AS, (2**30, 2**30))\n"
            "from astrodyn.recording import load\n"
            "run = load(sys.argv[1])\n"
            "print(run.messages, run.invalid)\n")
    proc = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0 and "MemoryError" not in proc.stderr, proc.stderr[-2000:]
    assert proc.stdout.split() == ["2", "0"]


def test_a_log_time_past_int64_is_read_exactly_not_an_overflow(tmp_path):
    """MCAP log times are uint64 and so is a Track's ``log_time``: 2**64 - 1 and 2**63 (after
    2262-04-11, which a config may reach) are read exactly, not counted invalid (they used
    to be: every state after 2262 vanished from load / analyze / export), nor OverflowError."""
    good = json.dumps(ORBIT).encode()
    path = _write(tmp_path / "late.mcap", [("astrodyn/demo/sat/orbit", b"{}", [(2**64 - 1, good), (5, good.replace(
        b'"seq":0', b'"seq":1'))]), ("other/x", b'{"type":"object"}', [(2**63, b"{}")])])
    run = load(path)
    assert run.messages == 3 and run.invalid == 0 and run.complete, run
    orbit = run.channels["astrodyn/demo/sat/orbit"]
    assert orbit.log_time.dtype == np.uint64 and orbit.log_time.tolist() == [2**64 - 1, 5]  # sorted by seq
    assert run.channels["other/x"].log_time.tolist() == [2**63]


def test_a_fifo_is_refused_at_once_not_waited_on(tmp_path):
    """A FIFO named like a recording: opening it used to wait for a writer for ever."""
    fifo = tmp_path / "pipe.mcap"
    os.mkfifo(fifo)
    result: dict = {}

    def read() -> None:
        for name, reader in (("load", load), ("stream", open_stream)):
            try:
                reader(fifo)
            except RecordingError as exc:
                result[name] = str(exc)

    worker = threading.Thread(target=read, daemon=True)
    worker.start()
    worker.join(5)
    if worker.is_alive():  # unblock the thread (open for writing releases the reader's open)
        with open(fifo, "wb"):
            pass
        pytest.fail("reading a FIFO blocked")
    for name in ("load", "stream"):
        assert result[name].startswith(str(fifo)) and "expected a regular file, got a FIFO" in result[name], result
    proc = _cli("analyze", str(fifo), "--out", str(tmp_path / "report"), timeout=60)
    assert proc.returncode == 1 and str(fifo) in proc.stderr and "Traceback" not in proc.stderr, proc.stderr


def test_export_channels_whose_file_names_collide_are_all_written(tmp_path):
    """``other/a.b`` and ``other/a/b`` both became ``other.a.b.csv`` (one channel lost); a
    topic of 5000 characters was a file name too long (OSError traceback)."""
    long_topic = "x" + "/y" * 2500
    path = _write(tmp_path / "names.mcap", [("other/a.b", b'{"type":"object"}', [(1, b'{"x": 1}')]),
                                            ("other/a/b", b'{"type":"object"}', [(1, b'{"x": 2}')]),
                                            (long_topic, b'{"type":"object"}', [(1, b'{"x": 3}')])])
    files = export(path, "csv", tmp_path / "csv")
    assert len(files) == 3 and len({f.name for f in files}) == 3
    assert all(len(f.name) < 200 and f.is_file() for f in files)
    last_rows = [f.read_text().splitlines()[-1] for f in files]
    for k in (1, 2, 3):  # every channel's message, in a file of its own
        assert sum(f'""x"": {k}' in row for row in last_rows) == 1, last_rows


def test_a_failed_export_replaces_nothing_already_in_out(tmp_path):
    """A directory where one output file goes: a one-line error naming it, and the files
    already in --out (an earlier export) are left as they were, not half replaced."""
    path = _orbit_file(tmp_path / "rec.mcap")
    out = tmp_path / "out"
    out.mkdir()
    (out / "sat.orbit.csv").mkdir()  # in the way of the channel's file
    earlier = out / "events.csv"
    earlier.write_text("an earlier export\n")
    with pytest.raises(ExportError, match="sat.orbit.csv is a directory") as err:
        export(path, "csv", out)
    assert str(path) in str(err.value)
    assert earlier.read_text() == "an earlier export\n"
    assert sorted(p.name for p in out.iterdir()) == ["events.csv", "sat.orbit.csv"]  # no work directory left
    proc = _cli("export", str(path), "--format", "oem", "--out", str(tmp_path / "rec.mcap" / "sub"))
    # an --out that cannot be a directory is the command line's fault: exit 2 (docs/exports.md, exit status)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    assert "expected a directory that can be created" in proc.stderr


def test_recover_never_writes_over_an_existing_out(tmp_path):
    """``recover X --out Y`` with Y an existing file (another recording, a config) used to
    replace Y; it is refused now, and the input is untouched."""
    path = _orbit_file(tmp_path / "rec.mcap")
    before = path.read_bytes()
    precious = tmp_path / "other-run.mcap"
    precious.write_bytes(b"someone else's recording")
    proc = _cli("recover", str(path), "--out", str(precious))  # the command line's fault: exit 2
    assert proc.returncode == 2 and "exists already" in proc.stderr and str(path) in proc.stderr, proc.stderr
    assert precious.read_bytes() == b"someone else's recording" and path.read_bytes() == before
    assert not list(tmp_path.glob("*.recover-tmp"))


def test_merge_into_an_unwritable_place_is_a_clear_error(tmp_path):
    """--out in a directory that does not exist: RecordingError naming --out, not an
    OSError traceback; inputs of different scenarios are named with their files."""
    path = _orbit_file(tmp_path / "rec.mcap")
    with pytest.raises(RecordingError, match="cannot write the merged file"):
        merge([path], tmp_path / "no" / "such" / "dir.mcap")
    proc = _cli("merge", str(path), "--out", str(tmp_path / "missing" / "m.mcap"))  # the command line's fault: exit 2
    assert proc.returncode == 2 and "Traceback" not in proc.stderr and "--out" in proc.stderr, proc.stderr
    assert not list(tmp_path.rglob("*.merging"))


@pytest.fixture(autouse=True)
def _fast():
    t0 = time.monotonic()
    yield
    assert time.monotonic() - t0 < 10  # each test is a few process starts at most



def _with_scenario_metadata(path: Path, scenario: dict[str, str], recording: dict[str, str]) -> Path:
    with open(path, "wb") as f:
        w = Writer(f, compression=CompressionType.ZSTD)
        w.start(profile="", library="fuzz-regression")
        w.add_metadata("scenario", scenario)
        w.add_metadata("recording", recording)
        cid = w.register_channel("astrodyn/demo/sat/orbit", "json", w.register_schema("s", "jsonschema", b"{}"))
        w.add_message(cid, log_time=5, data=json.dumps(ORBIT).encode(), publish_time=5)
        w.finish()
    return path


@pytest.mark.parametrize(("fmt", "scenario", "recording", "error"), [
    ("oem", {"name": "demo", "epoch": "garbage", "epoch_scale": "utc"}, {}, "epoch 'garbage'"),
    ("foxglove", {"name": "demo"}, {"epoch_unix_ns": "abc"}, "epoch_unix_ns 'abc'"),
])
def test_export_of_a_file_with_hostile_epoch_metadata_is_a_clear_error(tmp_path, fmt, scenario, recording, error):
    """The epoch in the file's metadata reached astropy / int() unchecked: a ValueError
    traceback from ``export --format oem|aem|aem1|foxglove``."""
    path = _with_scenario_metadata(tmp_path / "meta.mcap", scenario, recording)
    with pytest.raises(ExportError, match=error) as err:
        export(path, fmt, tmp_path / "out")
    assert str(err.value).startswith(str(path))


def test_commands_from_a_damaged_recording_name_the_channel_and_time(tmp_path):
    """``run --commands``: a payload that fails its definition, or a fault event whose
    detail is not JSON, is refused naming the channel and the log time, not just the field."""
    from astrodyn.scenario import loads
    from astrodyn.service.plant import recorded_commands, recorded_faults

    event = json.dumps({"t": 0.5, "seq": 0, "process": "plant", "kind": "fault", "detail": "not json"}).encode()
    path = _write(tmp_path / "cmds.mcap", [
        ("astrodyn/det/sc/actuators", b"{}", [(77, b'{"t":0.0,"seq":-5,"torque":[0,0,0],"applied":["c#0"]}')]),
        ("astrodyn/det/@event", b"{}", [(88, event)])])
    with pytest.raises(ValueError, match="astrodyn/det/sc/actuators at log time 77 ns: actuators.seq"):
        recorded_commands(path, "det")
    scenario = loads('[scenario]\nname = "det"\nepoch = "2026-03-20T12:00:00 UTC"\nduration = "1 s"\nrate = "10 Hz"\n'
                     '[control]\ncontrollers = ["c"]\n[[bodies]]\nname = "sc"\n[bodies.attitude]\n'
                     'inertia = ["1 kg m2", "2 kg m2", "3 kg m2"]\n[bodies.actuators]\ntorque = "0.1 N m"\n')
    with pytest.raises(ValueError, match="astrodyn/det/@event at log time 88 ns: fault event detail: expected JSON"):
        recorded_faults(path, scenario)
