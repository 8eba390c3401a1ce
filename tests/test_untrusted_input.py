"""Untrusted files: cut, corrupted and non-MCAP recordings into ``load``, ``recover``,
``astrodyn replay`` and ``astrodyn analyze``; configs that try to run code or point at
URLs; recordings whose payloads are pickles (issue 6, docs/reliability.md, docs/security.md).

The commands run as subprocesses with a time bound (a hang fails the test) and their exit
status and stderr are checked: a clear one-line error, never a traceback.
"""

from __future__ import annotations

import ast
import json
import os
import pickle
import random
import subprocess
import sys
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.writer import Writer

from astrodyn.recording import RecordingError, load
from astrodyn.recording.recover import recover
from astrodyn.scenario import ScenarioError, load as load_scenario, loads

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _recordings import leo_recording

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src" / "astrodyn"
ASTRODYN = [sys.executable, "-m", "astrodyn"]


@pytest.fixture(scope="module")
def good(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("good") / "good.mcap"
    leo_recording(path, duration="60 s", rate="2 Hz")
    return path


def _bad_files(good: Path, d: Path) -> dict[str, Path]:
    data = good.read_bytes()
    files = {}

    def put(name: str, content: bytes) -> None:
        files[name] = d / f"{name}.mcap"
        files[name].write_bytes(content)

    put("empty", b"")
    put("text", b"hello, not an MCAP file\n" * 10)
    put("magic-only", data[:8])
    put("half-magic", data[:4])
    put("cut-half", data[: len(data) // 2])
    put("cut-header", data[:40])
    flipped = bytearray(data)
    for i in range(len(data) // 3, len(data) // 3 + 64):  # inside a compressed chunk
        flipped[i] ^= 0xFF
    put("corrupt-chunk", bytes(flipped))
    lying = bytearray(data)
    lying[9:17] = (2**62).to_bytes(8, "little")  # the header record claims an absurd length
    put("absurd-length", bytes(lying))
    put("random", random.Random(6).randbytes(5000))
    return files


def test_load_and_recover_give_data_or_a_clear_error(good, tmp_path):
    files = _bad_files(good, tmp_path)
    complete = load(good)
    for name, path in files.items():
        try:
            run = load(path)
        except RecordingError as exc:
            assert str(exc).startswith(str(path)) and "not an MCAP file" in str(exc), name
            with pytest.raises(RecordingError, match="not an MCAP file"):
                recover(path, tmp_path / f"{name}-fixed.mcap")
            continue
        assert not run.complete and run.truncation, name  # never passes for a complete file
        assert run.messages <= complete.messages
        summary = recover(path, tmp_path / f"{name}-fixed.mcap")
        fixed = load(tmp_path / f"{name}-fixed.mcap")
        assert fixed.complete and fixed.messages == run.messages == summary["messages"], name
        with open(tmp_path / f"{name}-fixed.mcap", "rb") as f:
            assert make_reader(f).get_summary().statistics.message_count == run.messages
    assert not list(tmp_path.glob("*.recover-tmp"))


def test_random_damage_never_escapes_as_another_exception(good, tmp_path):
    data = good.read_bytes()
    rng = random.Random(2026)
    path = tmp_path / "damaged.mcap"
    for _ in range(60):  # bounded fuzz: flips, cuts and splices anywhere in the file
        buf = bytearray(data)
        for _ in range(rng.randint(1, 8)):
            i = rng.randrange(len(buf))
            buf[i] = rng.randrange(256)
        if rng.random() < 0.5:
            buf = buf[: rng.randrange(len(buf))]
        path.write_bytes(bytes(buf))
        try:
            run = load(path)
        except RecordingError:
            continue
        assert run.messages <= 400


def test_recover_into_a_full_disk_leaves_nothing_behind(good, tmp_path):
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(good.read_bytes()[:-300])
    before = cut.read_bytes()
    with pytest.raises(RecordingError, match="cannot write"):
        recover(cut, tmp_path / "no" / "such" / "dir.mcap")
    with pytest.raises(RecordingError, match="expected a regular file"):
        recover(cut, "/dev/null")  # never renamed over a device
    assert os.path.exists("/dev/null") and not os.path.isfile("/dev/null")
    # a disk that fills up mid-write (RLIMIT_FSIZE: writes past it fail with EFBIG)
    out = tmp_path / "small.mcap"
    proc = subprocess.run(["prlimit", "--fsize=4000", *ASTRODYN, "recover", str(cut), "--out", str(out)],
                          capture_output=True, text=True, timeout=90)
    assert proc.returncode == 1 and "File too large" in proc.stderr and "Traceback" not in proc.stderr
    assert not out.exists() and not list(tmp_path.glob("*.recover-tmp"))
    assert cut.read_bytes() == before  # the source is untouched by a failed recovery


def _cli(*argv: str, timeout: float = 90) -> subprocess.CompletedProcess:
    return subprocess.run([*ASTRODYN, *argv], capture_output=True, text=True, timeout=timeout, cwd=ROOT)


@pytest.mark.network
def test_replay_analyze_recover_cli_on_bad_files(good, tmp_path):
    files = _bad_files(good, tmp_path)
    # one process per command over all files would hide which file hung; a few representative ones
    for name in ("text", "cut-half", "corrupt-chunk"):  # load() itself sees all of them above
        path = files[name]
        for argv in (["replay", str(path), "--rate", "inf", "--wait", "0", "--quiet"],
                     ["analyze", str(path), "--out", str(tmp_path / f"{name}-report")],
                     ["recover", str(path), "--out", str(tmp_path / f"{name}-rec.mcap")]):
            proc = _cli(*argv)
            where = f"{argv[0]} {name}: rc={proc.returncode} stderr={proc.stderr[-600:]}"
            assert "Traceback" not in proc.stderr, where
            if name == "text":
                assert proc.returncode == 1 and "not an MCAP file" in proc.stderr, where
            else:  # readable up to the damage: done, with a warning where the command has one
                assert proc.returncode in (0, 1), where
                assert proc.returncode == 0 or "error:" in proc.stderr, where
    missing = _cli("analyze", str(tmp_path / "missing.mcap"))
    assert missing.returncode == 1 and "cannot open" in missing.stderr and "Traceback" not in missing.stderr


# ----------------------------------------------------------------------------- configs never run code

BASE = (ROOT / "configs" / "demo.toml").read_text()


@pytest.mark.parametrize("payload", [
    "!!python/object/apply:os.system ['touch {marker}']",  # YAML's code tag: not TOML
    "{{ __import__('os').system('touch {marker}') }}",
    "__import__('os').system('touch {marker}')",
])
def test_config_with_code_is_rejected_and_not_run(tmp_path, payload):
    marker = tmp_path / "pwned"
    for text in (f"{payload.format(marker=marker)}\n" + BASE,
                 BASE.replace('description = "', f'description = "{payload.format(marker=marker)}" #')):
        cfg = tmp_path / "evil.toml"
        cfg.write_text(text)
        try:
            scn = load_scenario(cfg)  # a string value is only ever a string
            assert payload.format(marker=marker) in scn.to_metadata()["json"]
        except ScenarioError as exc:
            assert str(exc).startswith(str(cfg))
        assert not marker.exists()


def _evil_pickle(marker: Path) -> bytes:
    """A pickle that would create ``marker`` if anything ever unpickled it."""

    class Evil:
        def __reduce__(self):
            return (os.system, (f"touch {marker}",))

    return pickle.dumps(Evil())


def test_pickle_config_is_rejected(tmp_path):
    marker = tmp_path / "pwned"

    cfg = tmp_path / "evil.toml"
    cfg.write_bytes(_evil_pickle(marker))
    with pytest.raises(ScenarioError, match=str(cfg)):
        load_scenario(cfg)
    assert not marker.exists()


@pytest.mark.parametrize("path", ["http://example.com/x.mcap", "https://example.com/x.mcap", "file:///etc/x.mcap",
                                  "s3://bucket/x.mcap", "ftp://host/x.mcap"])
def test_output_path_that_is_a_url_is_rejected(path):
    with pytest.raises(ScenarioError, match="output.path: expected a file path"):
        loads(BASE + f'\n[output]\npath = "{path}"\n')


def test_relative_output_path_is_resolved_against_the_config(tmp_path):
    (tmp_path / "sub").mkdir()
    cfg = tmp_path / "sub" / "c.toml"
    cfg.write_text(BASE + '\n[output]\npath = "runs/x.mcap"\n')
    assert load_scenario(cfg).output_path == tmp_path / "sub" / "runs" / "x.mcap"


# ----------------------------------------------------------------------------- no unpickling, no eval


def test_recordings_with_pickle_payloads_are_never_unpickled(tmp_path):
    marker = tmp_path / "pwned"

    path = tmp_path / "pickle.mcap"
    with open(path, "wb") as f:
        w = Writer(f)
        w.start()
        sid = w.register_schema("Evil", "pickle", _evil_pickle(marker))
        cid = w.register_channel("astrodyn/x/evil/orbit", "pickle", sid)
        cid2 = w.register_channel("other/topic", "pickle", sid)
        for i in range(3):
            w.add_message(cid, i, _evil_pickle(marker), i, i)
            w.add_message(cid2, i, _evil_pickle(marker), i, i)
        w.finish()
    run = load(path)
    assert run.messages == 6 and not run.bodies  # not JSON: opaque bytes, never a body's states
    for topic in ("astrodyn/x/evil/orbit", "other/topic"):
        assert all(isinstance(r, bytes) for r in run.channels[topic].records)
    from astrodyn.recording.stream import open_stream

    with open_stream(path) as s:
        assert all(isinstance(m.data, bytes) for m in s.messages())
    proc = _cli("analyze", str(path), "--out", str(tmp_path / "rep"))
    assert "Traceback" not in proc.stderr
    recover(path, tmp_path / "rec.mcap")
    assert not marker.exists()


#: The one place that compiles code: astrodyn.messages.codec generates a check function per
#: message type and key tuple from the msgspec definitions ("Plain messages"); its source is
#: built from the definitions' field names and constants only, never from message data
#: (test_generated_checks_never_see_message_data below).
_COMPILES_FROM_DEFINITIONS = {("messages/codec.py", "exec"), ("messages/codec.py", "compile")}


def test_no_module_can_execute_data():
    """No eval/exec, no pickle/marshal/shelve/yaml loaders anywhere in the package (apart
    from the code generated from the message definitions, above)."""
    banned_calls = {"eval", "exec", "compile", "__import__"}
    banned_modules = {"pickle", "cPickle", "dill", "marshal", "shelve", "yaml", "cloudpickle", "joblib"}
    found = []
    for py in SRC.rglob("*.py"):
        tree = ast.parse(py.read_text(), filename=str(py))
        rel = py.relative_to(SRC).as_posix()
        for node in ast.walk(tree):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in banned_calls:
                if (rel, node.func.id) not in _COMPILES_FROM_DEFINITIONS:
                    found.append(f"{py}:{node.lineno} {node.func.id}()")
            elif isinstance(node, ast.Import):
                found += [f"{py}:{node.lineno} import {a.name}" for a in node.names if a.name.split(".")[0] in banned_modules]
            elif isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] in banned_modules:
                found.append(f"{py}:{node.lineno} from {node.module}")
    assert not found, found


@pytest.mark.parametrize("key", ["__import__('os').system('true')", "t\nimport os", "seq'): pass\n#", "r" * 5000])
def test_generated_checks_never_see_message_data(key):
    """A message whose keys are code, or anything but the definition's field names in
    order, gets no generated check: it takes the reference path (json + msgspec), which
    refuses it naming the field, or encodes it as data."""
    from astrodyn import messages
    from astrodyn.messages import codec

    msg = {"t": 0.0, "seq": 0, "model": "kepler", "r": [1.0, 2.0, 3.0], "v": [0.0, 1.0, 0.0], "mu": 1.0, "frame": "GCRF",
           key: 1.0}
    for kind in (None, "orbit"):
        for mode in (1, 2, 3):
            assert codec._plain_check(tuple(msg), kind, mode) is None
    with pytest.raises(messages.MessageError):
        messages.encode(msg, "orbit")
    assert json.loads(messages.encode(msg))[key] == 1.0  # no kind: plain JSON data, never code
