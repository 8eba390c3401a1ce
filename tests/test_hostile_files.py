"""A corpus of hostile MCAP files through every reading tool (issue 13 items 7 and 8).

Each file is made here, from the MCAP specification, with the plain ``mcap`` writer or
record by record: decompression bombs (a 6 KB chunk that inflates to 200 MiB, with a true
and with a lying declared size), a chunk declaring 4 GiB, foreign JSON whose payloads
violate the JSON Schema stored with them (on astrodyn keys and on foreign topics), deeply
nested JSON, numbers that overflow float64, invalid UTF-8.

The contract (docs/reliability.md): ``load``, ``replay``, ``analyze``, ``export`` and
``recover`` give data or a clear one-line error, never a traceback; a bomb is refused
before it is decompressed (bounded time and memory); invalid messages are counted per
channel and never returned as states.
"""

from __future__ import annotations

import io
import json
import subprocess
import sys
import time
import zlib
from pathlib import Path

import pytest
import zstandard
from mcap.data_stream import RecordBuilder
from mcap.records import Chunk, DataEnd, Footer, Header
from mcap.writer import CompressionType, Writer

from astrodyn.recording import load
from astrodyn.recording.reader import MAX_CHUNK_BYTES, MAX_CHUNK_RATIO

ASTRODYN = [sys.executable, "-m", "astrodyn"]
MAGIC = b"\x89MCAP0\r\n"
ORBIT_OK = {"t": 0.0, "seq": 0, "model": "kepler", "r": [7.0e6, 0.0, 0.0], "v": [0.0, 7.5e3, 0.0], "mu": 3.986004418e14,
            "frame": "GCRF"}


def _raw_file(path: Path, chunk: Chunk) -> None:
    """magic, Header, one Chunk, DataEnd, Footer, magic: the smallest complete file."""
    b = RecordBuilder()
    Header(profile="", library="hostile").write(b)
    chunk.write(b)
    DataEnd(data_section_crc=0).write(b)
    Footer(summary_start=0, summary_offset_start=0, summary_crc=0).write(b)
    path.write_bytes(MAGIC + b.end() + MAGIC)


def _bomb(path: Path, inflated: int, declared: int) -> None:
    packed = zstandard.ZstdCompressor(level=19).compress(b"\0" * inflated)
    _raw_file(path, Chunk(message_start_time=0, message_end_time=0, uncompressed_size=declared,
                          uncompressed_crc=0, compression="zstd", data=packed))


def _foreign(path: Path) -> dict[str, int]:
    """Messages that violate their stored schema; returns the invalid count per topic."""
    with open(path, "wb") as f:
        w = Writer(f, compression=CompressionType.ZSTD)
        w.start(profile="", library="hostile")
        lying = w.register_schema("astrodyn.OrbitState", "jsonschema", json.dumps({"type": "object"}).encode())
        orbit = w.register_channel("astrodyn/demo/sat/orbit", "json", lying)
        numeric = w.register_schema("other.Reading", "jsonschema", json.dumps({
            "type": "object", "properties": {"x": {"type": "number"}, "v": {"type": "array", "items": {"type": "number"},
                                                                          "minItems": 3, "maxItems": 3},
                                             "n": {"type": "integer"}, "s": {"type": "string"}}}).encode())
        other = w.register_channel("other/reading", "json", numeric)
        good = [ORBIT_OK | {"seq": k, "t": float(k)} for k in range(3)]
        bad_orbit = [json.dumps(ORBIT_OK | {"t": "soon", "seq": 3}).encode(),
                     json.dumps(ORBIT_OK | {"seq": 4, "r": [1e999, 0, 0]}).replace("Infinity", "1e999").encode(),
                     b"[" * 100_000 + b"]" * 100_000, b"\xff\xfe not utf-8", b"null",
                     json.dumps(ORBIT_OK | {"seq": 10**30}).encode()]
        bad_other = [b'{"x": "three"}', b'{"v": 5}', b'{"v": [1, 2]}', b'{"n": 1.5}', b'{"s": [1]}', b"[]",
                     b'{"x": ' + b"[" * 50_000 + b"]" * 50_000 + b"}", b'{"n": 1' + b"0" * 5000 + b"}"]
        t = 0
        for payload in [json.dumps(m).encode() for m in good] + bad_orbit:
            w.add_message(orbit, log_time=t, data=payload, publish_time=t)
            t += 1
        for payload in [b'{"x": 1.5, "v": [1, 2, 3], "n": 2, "s": "ok"}', *bad_other]:
            w.add_message(other, log_time=t, data=payload, publish_time=t)
            t += 1
        w.finish()
    return {"astrodyn/demo/sat/orbit": len(bad_orbit), "other/reading": len(bad_other)}


@pytest.fixture(scope="module")
def corpus(tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("hostile")
    files = {name: d / f"{name}.mcap" for name in ("bomb", "bomb-lying", "huge-declared", "foreign")}
    _bomb(files["bomb"], 200 * 2**20, 200 * 2**20)  # true size: the ratio gives it away
    _bomb(files["bomb-lying"], 200 * 2**20, 4096)  # declares 4 KiB: decompression stops there
    _raw_file(files["huge-declared"], Chunk(message_start_time=0, message_end_time=0, uncompressed_size=2**32,
                                            uncompressed_crc=0, compression="", data=b"\0" * 64))
    _foreign(files["foreign"])
    return files


def test_the_bombs_are_what_they_claim(corpus):
    """Independent of astrodyn: the file is small and its chunk really inflates that far."""
    data = corpus["bomb"].read_bytes()
    assert len(data) < 20_000
    with zstandard.ZstdDecompressor().stream_reader(io.BytesIO(data[data.index(b"zstd") + 12:])) as z:
        assert len(z.read(250 * 2**20)) == 200 * 2**20
    assert 200 * 2**20 > MAX_CHUNK_RATIO * len(data) and 2**32 > MAX_CHUNK_BYTES


@pytest.mark.parametrize("name", ["bomb", "bomb-lying", "huge-declared"])
def test_load_refuses_a_bomb_fast(corpus, name):
    t0 = time.perf_counter()
    run = load(corpus[name])
    elapsed = time.perf_counter() - t0
    assert elapsed < 0.5, f"{name}: {elapsed:.2f} s"
    assert run.corrupt_chunks == 1 and run.messages == 0
    assert ("bomb" in run.truncation) if name == "bomb" else True
    assert "declared" in run.truncation or "declares" in run.truncation, run.truncation


def test_foreign_payloads_are_counted_per_channel_never_states(corpus):
    path = corpus["foreign"]
    expected = _foreign(path)
    run = load(path)
    assert run.invalid_by_channel == expected
    assert run.invalid == sum(expected.values())
    sat = run.bodies["sat"].orbit
    assert list(sat.seq) == [0, 1, 2] and sat.r.shape == (3, 3)  # only the valid states
    other = run.channels["other/reading"]
    assert len(other) == 1 and other.fields["x"][0] == 1.5
    assert not run.complete


def _cli_bounded(*argv: str, timeout: float = 60) -> tuple[subprocess.CompletedProcess, float, int]:
    """Run an astrodyn command; return it, its wall time and its peak RSS in MiB."""
    wrapper = ("import resource, subprocess, sys, json\n"
               "p = subprocess.run(sys.argv[1:], capture_output=True, text=True)\n"
               "print(json.dumps([p.returncode, p.stdout[-3000:], p.stderr[-3000:], "
               "resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss]))")
    t0 = time.monotonic()
    proc = subprocess.run([sys.executable, "-c", wrapper, *ASTRODYN, *argv], capture_output=True, text=True,
                          timeout=timeout)
    rc, out, err, rss = json.loads(proc.stdout.splitlines()[-1])
    return subprocess.CompletedProcess(argv, rc, out, err), time.monotonic() - t0, rss // 1024


@pytest.mark.parametrize("name", ["bomb", "bomb-lying", "huge-declared", "foreign"])
def test_every_tool_on_every_hostile_file(corpus, name, tmp_path):
    path = corpus[name]
    commands = {
        "recover": ["recover", str(path), "--out", str(tmp_path / "recovered.mcap")],
        "analyze": ["analyze", str(path), "--out", str(tmp_path / "report")],
        "export": ["export", str(path), "--format", "csv", "--out", str(tmp_path / "csv")],
        "replay": ["replay", str(path), "--rate", "inf", "--wait", "0", "--quiet"],
    }
    for what, argv in commands.items():
        proc, wall, rss = _cli_bounded(*argv)
        where = f"{what} on {name}: rc={proc.returncode} wall={wall:.1f} s rss={rss} MiB\n{proc.stderr[-1500:]}"
        assert "Traceback" not in proc.stderr, where
        assert proc.returncode in (0, 1, 2), where
        assert proc.returncode == 0 or proc.stderr.strip(), where
        assert wall < 30, where  # python start + imports are most of it
        assert rss < 700, where  # a decompressed bomb alone would be 200+ MiB on top of ~250 MiB of imports


def test_chunk_limits_can_be_raised_by_the_environment(corpus, monkeypatch):
    monkeypatch.setenv("ASTRODYN_MAX_CHUNK_RATIO", "1e9")
    monkeypatch.setenv("ASTRODYN_MAX_CHUNK_BYTES", str(300 * 2**20))
    run = load(corpus["bomb"])  # now decompressed: 200 MiB of zeros is opcode 0, not a record: corrupt, fast
    assert run.corrupt_chunks == 1 and "only Schema, Channel and Message" in run.truncation
    monkeypatch.setenv("ASTRODYN_MAX_CHUNK_RATIO", "lots")
    proc = subprocess.run([*ASTRODYN, "analyze", str(corpus["foreign"])], capture_output=True, text=True, timeout=60)
    assert proc.returncode != 0 and "ASTRODYN_MAX_CHUNK_RATIO" in proc.stderr and "Traceback" not in proc.stderr


def test_crc_of_a_real_chunk_still_checked(tmp_path):
    """A chunk inside the limits whose bytes do not match its CRC is skipped as corrupt."""
    packed = zstandard.ZstdCompressor().compress(b"\x01" * 100)
    path = tmp_path / "crc.mcap"
    _raw_file(path, Chunk(message_start_time=0, message_end_time=0, uncompressed_size=100,
                          uncompressed_crc=zlib.crc32(b"\x02" * 100), compression="zstd", data=packed))
    run = load(path)
    assert run.corrupt_chunks == 1 and "CRC" in run.truncation



def test_analyze_warning_always_says_why(corpus, tmp_path):
    """An incomplete file's warning names the reason (it was empty for files whose only
    fault was invalid messages)."""
    proc = subprocess.run([*ASTRODYN, "analyze", str(corpus["foreign"]), "--out", str(tmp_path / "r")],
                          capture_output=True, text=True, timeout=120)
    warning = [line for line in proc.stderr.splitlines() if "warning" in line]
    assert warning and "invalid messages skipped" in warning[0] and "astrodyn/demo/sat/orbit" in warning[0], proc.stderr
    run = load(corpus["foreign"])
    assert "14 invalid messages skipped" in run.incomplete_reason and "incomplete: 14 invalid" in repr(run)
