"""MCAP recorder and reader: layout (docs/architecture.md, section 5), round trips, crashes, bad files.

References are independent of the code under test: the plain ``mcap`` library reads
the files back; log_time is checked with integer arithmetic on times that are exact
binary fractions; what a cut file must still contain comes from the complete file's
own chunk index (written by mcap, read by mcap); seq accounting is checked against a
set-based model.
"""

from __future__ import annotations

import json
import os
import random
import signal
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import zstandard
from mcap.reader import make_reader
from mcap.stream_reader import StreamReader, breakup_chunk

from astrodyn import messages
from astrodyn.recording import DUPLICATE, GAP, LATE, OK, McapRecorder, RecordingError, SeqTracker, gap_report, load

EPOCH_NS = 1_774_008_000_000_000_000  # 2026-03-20T12:00:00 UTC as Unix ns
SCENARIO = "rt"
BODIES = ("sat1", "sat2")
N = 120
DT_S = 0.25  # exact in binary, so t * 1e9 is an exact integer number of ns
CHILD = Path(__file__).with_name("_bus_child.py")


def _orbit(body: int, seq: int) -> dict:
    r = [7.0e6 + 1000.0 * body + 0.1 * seq, -1234.5678901234567 * (seq + 1), 3.0e5 / (seq + 1)]
    v = [1.0 / 3.0 + seq, 7.5e3 - body, -2.0 ** -30 * seq]
    return messages.orbit_message(seq * DT_S, seq, "kepler", r, v, 3.986004418e14)


def _attitude(seq: int) -> dict:
    a = 0.013 * seq
    q = [np.cos(a), np.sin(a) / np.sqrt(3), np.sin(a) / np.sqrt(3), np.sin(a) / np.sqrt(3)]
    return messages.attitude_message(seq * DT_S, seq, "torque_free", q, [0.1, -0.2, 0.3 + seq])


def _expected_messages() -> list[tuple[str, dict]]:
    out = []
    for seq in range(N):
        for i, body in enumerate(BODIES):
            out.append((messages.orbit_key(SCENARIO, body), _orbit(i, seq)))
            out.append((messages.attitude_key(SCENARIO, body), _attitude(seq)))
    out.append((messages.event_key(SCENARIO), messages.event_message(N * DT_S, 0, "orbit", "stop", '{"messages":480}')))
    return out


METADATA = {"name": SCENARIO, "config": "[scenario]\nname = 'rt'\n", "bodies": ["sat1", "sat2"]}


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("rec") / "rt.mcap"
    with McapRecorder(path, METADATA, epoch_ns=EPOCH_NS, chunk_size=4096) as rec:
        for key, msg in _expected_messages():
            assert rec.write(key, dict(msg)) == OK
    return path


def test_layout_read_by_plain_mcap_reader(recorded):
    expected = _expected_messages()
    with open(recorded, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        summary = reader.get_summary()
        assert summary.statistics.message_count == len(expected)
        assert sum(summary.statistics.channel_message_counts.values()) == len(expected)
        got = list(reader.iter_messages(log_time_order=False))
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
        in_time_order = [m.log_time for _, _, m in reader.iter_messages(log_time_order=True)]
        f.seek(0)
        records = list(StreamReader(f, validate_crcs=True).records)  # every CRC, footer and magic
    assert in_time_order == sorted(in_time_order) and len(in_time_order) == len(expected)
    assert type(records[-1]).__name__ == "Footer"
    assert len(got) == len(expected)
    for (schema, channel, message), (key, msg) in zip(got, expected):
        kind = key.rsplit("/", 1)[-1] if "@" not in key else "event"
        assert channel.topic == key
        assert channel.message_encoding == "json"
        assert schema.encoding == "jsonschema"
        name, schema_dict = messages.schema_for_key(key)
        assert schema.name == name == f"astrodyn.{ {'orbit': 'OrbitState', 'attitude': 'AttitudeState', 'event': 'Event'}[kind] }"
        assert json.loads(schema.data) == schema_dict
        # log_time = epoch + t in integer ns: t is a multiple of 0.25 s, so exact
        assert message.log_time == EPOCH_NS + int(msg["t"] * 4) * 250_000_000
        assert message.sequence == msg["seq"]
        assert json.loads(message.data) == msg  # JSON floats round-trip exactly (repr)
    # every chunk is zstd-compressed
    assert summary.chunk_indexes and all(ci.compression == "zstd" for ci in summary.chunk_indexes)
    assert metadata["scenario"] == {"name": "rt", "config": METADATA["config"], "bodies": '["sat1", "sat2"]'}
    assert metadata["recording"]["epoch_unix_ns"] == str(EPOCH_NS)


def test_load_round_trip(recorded):
    run = load(recorded)
    assert not run.truncated and run.complete and run.truncation == ""
    assert run.messages == 4 * N + 1
    assert run.scenario["name"] == "rt" and run.scenario["config"] == METADATA["config"]
    assert sorted(run.bodies) == list(BODIES)
    for i, body in enumerate(BODIES):
        orbit = run.bodies[body].orbit
        ref = [_orbit(i, s) for s in range(N)]
        np.testing.assert_array_equal(orbit.seq, np.arange(N))
        np.testing.assert_array_equal(orbit.t, [m["t"] for m in ref])
        np.testing.assert_array_equal(orbit.r, [m["r"] for m in ref])  # bit-exact: JSON repr round trip
        np.testing.assert_array_equal(orbit.v, [m["v"] for m in ref])
        np.testing.assert_array_equal(orbit.mu, 3.986004418e14)
        assert set(orbit.model) == {"kepler"} and set(orbit.frame) == {"GCRF"}
        np.testing.assert_array_equal(orbit.log_time, EPOCH_NS + np.arange(N) * 250_000_000)
        att = run.bodies[body].attitude
        np.testing.assert_array_equal(att.q, [_attitude(s)["q"] for s in range(N)])
        np.testing.assert_array_equal(att.w, [_attitude(s)["w"] for s in range(N)])
        assert run.bodies[body].crosscheck is None
    assert all(g["missing"] == 0 and g["duplicates"] == 0 for g in run.gaps.values())
    assert [e["kind"] for e in run.events] == ["stop"]


def _chunk_ends_and_counts(path: Path) -> list[tuple[int, int]]:
    """(end offset, messages inside) of each chunk, from mcap's own index of the complete file."""
    out = []
    with open(path, "rb") as f:
        for ci in make_reader(f).get_summary().chunk_indexes:
            f.seek(ci.chunk_start_offset)
            chunk = next(iter(StreamReader(f, skip_magic=True, emit_chunks=True).records))
            count = sum(type(r).__name__ == "Message" for r in breakup_chunk(chunk))
            out.append((ci.chunk_start_offset + ci.chunk_length, count))
    return out


def test_message_indexes_point_at_their_messages(recorded):
    """The per-chunk message indexes (used by seeking readers) are consistent with the chunks."""
    with open(recorded, "rb") as f:
        summary = make_reader(f).get_summary()
        for ci in summary.chunk_indexes:
            f.seek(ci.chunk_start_offset)
            chunk = next(iter(StreamReader(f, skip_magic=True, emit_chunks=True).records))
            data = zstandard.decompress(chunk.data, chunk.uncompressed_size)
            for cid, offset in ci.message_index_offsets.items():
                f.seek(offset)
                index = next(iter(StreamReader(f, skip_magic=True).records))
                assert index.channel_id == cid
                for log_time, at in index.records:
                    opcode, _, channel_id, _, stamped = struct.unpack_from("<BQHIQ", data, at)
                    assert (opcode, channel_id, stamped) == (5, cid, log_time)


def test_truncated_at_random_offsets(recorded, tmp_path):
    data = recorded.read_bytes()
    chunks = _chunk_ends_and_counts(recorded)
    assert sum(c for _, c in chunks) == 4 * N + 1 and len(chunks) > 10
    rng = random.Random(20260320)
    cuts = sorted({1, 7, 8, 9, 40, len(data) - 1, *(rng.randrange(8, len(data)) for _ in range(60))})
    cut_path = tmp_path / "cut.mcap"
    previous = 0
    for cut in cuts:
        cut_path.write_bytes(data[:cut])
        run = load(cut_path)
        assert run.truncated and not run.complete and run.truncation, cut
        must_have = sum(c for end, c in chunks if end <= cut)  # every chunk completely before the cut
        assert run.messages >= must_have, (cut, run.messages, must_have)
        assert run.messages >= previous  # a longer prefix never reads less
        previous = run.messages
        for i, body in enumerate(BODIES):
            orbit = run.bodies[body].orbit if body in run.bodies else None
            if orbit is None:
                continue
            n = len(orbit)  # chunks hold whole steps in order: seqs are a prefix 0..n-1
            np.testing.assert_array_equal(orbit.seq, np.arange(n))
            np.testing.assert_array_equal(orbit.r, np.array([_orbit(i, s)["r"] for s in range(n)]).reshape(n, 3))
        assert run.invalid == 0 and run.corrupt_chunks == 0


def test_corrupt_chunk_is_skipped_and_reported(recorded, tmp_path):
    data = bytearray(recorded.read_bytes())
    chunks = _chunk_ends_and_counts(recorded)
    with open(recorded, "rb") as f:
        ci = make_reader(f).get_summary().chunk_indexes[3]
    middle = ci.chunk_start_offset + ci.chunk_length - 20  # inside the compressed data
    data[middle] ^= 0xFF
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    run = load(bad)
    assert run.corrupt_chunks == 1 and not run.complete
    assert "corrupt chunk" in run.truncation
    assert run.messages == 4 * N + 1 - chunks[3][1]


def test_not_mcap_and_unreadable_files(tmp_path):
    text = tmp_path / "notes.mcap"
    text.write_text("hello, this is not MCAP\n")
    with pytest.raises(RecordingError) as err:
        load(text)
    assert str(err.value) == f"{text}: not an MCAP file (bad magic)"
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    with pytest.raises(RecordingError, match=r"empty\.mcap: not an MCAP file \(empty file\)"):
        load(empty)
    with pytest.raises(RecordingError, match=r"missing\.mcap: cannot open: No such file"):
        load(tmp_path / "missing.mcap")


def test_unwritable_path_and_full_disk(tmp_path):
    target = tmp_path / "no" / "such" / "dir" / "x.mcap"
    with pytest.raises(RecordingError, match=r"x\.mcap: cannot open for writing: No such file or directory"):
        McapRecorder(target, {}, epoch_ns=EPOCH_NS)
    assert not target.exists()
    if not os.path.exists("/dev/full"):
        pytest.skip("no /dev/full on this system")
    with pytest.raises(RecordingError, match=r"/dev/full: write failed: No space left on device"):
        McapRecorder("/dev/full", {}, epoch_ns=EPOCH_NS)


def test_bad_arguments_and_log_time_range(tmp_path):
    with pytest.raises(TypeError, match="epoch_ns: expected an integer"):
        McapRecorder(tmp_path / "a.mcap", {}, epoch_ns=1.5e18)
    with pytest.raises(ValueError, match="flush_interval_s: expected > 0"):
        McapRecorder(tmp_path / "a.mcap", {}, epoch_ns=0, flush_interval_s=0)
    with McapRecorder(tmp_path / "a.mcap", {}, epoch_ns=EPOCH_NS) as rec:
        key = messages.orbit_key("s", "a")
        # t before 1970: log_time would be negative, which MCAP's uint64 cannot hold
        with pytest.raises(ValueError, match=r"t: expected epoch \+ t within"):
            rec.write_encoded(key, b"{}", -EPOCH_NS / 1e9 - 1.0, 0)
        with pytest.raises(ValueError, match="t: expected a finite number"):
            rec.write_encoded(key, b"{}", float("nan"), 0)
        assert rec.message_count == 0 and rec.seq.totals()["count"] == 0  # nothing was consumed
    assert not load(tmp_path / "a.mcap").truncated


def test_sigkilled_writer_keeps_everything_flushed(tmp_path):
    path = tmp_path / "killed.mcap"
    n = 300
    child = subprocess.Popen([sys.executable, str(CHILD), "mcapkill", str(path), str(n)], stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdout.readline().strip() == "flushed"
    finally:
        os.kill(child.pid, signal.SIGKILL)
        child.wait(timeout=10)
    assert child.returncode == -signal.SIGKILL
    # the seeking reader needs the footer that a killed writer never wrote
    with open(path, "rb") as f, pytest.raises(Exception):
        list(make_reader(f).iter_messages())
    run = load(path)
    assert run.truncated and "without data end and footer" in run.truncation
    orbit = run.bodies["a"].orbit
    np.testing.assert_array_equal(orbit.seq, np.arange(n))  # everything flushed, nothing of the open chunk
    assert run.scenario == {"name": "kill"}


def _model_accounting(arrivals: list[int]) -> dict:
    """Reference: a message is recorded iff its seq was not recorded before."""
    seen: set[int] = set()
    dup = late = 0
    top = -1
    for s in arrivals:
        if s in seen:
            dup += 1
            continue
        if s < top:
            late += 1
        seen.add(s)
        top = max(top, s)
    missing = top + 1 - len(seen)
    return {"count": len(seen), "duplicates": dup, "out_of_order": late, "missing": missing}


def test_seq_tracker_against_set_model():
    assert [SeqTracker().add("k", s) for s in [0]] == [OK]
    tr = SeqTracker()
    assert [tr.add("k", s) for s in [0, 1, 4, 2, 2, 3, 5, 0]] == [OK, OK, GAP, LATE, DUPLICATE, LATE, OK, DUPLICATE]
    assert tr.report()["k"]["gaps"] == [] and tr.report()["k"]["missing"] == 0
    rng = random.Random(7)
    for _trial in range(300):
        n = rng.randrange(1, 60)
        arrivals = [s for s in range(n) if rng.random() > 0.2]
        for _ in range(rng.randrange(0, 10)):  # local swaps and duplicates
            i, j = rng.randrange(len(arrivals) or 1), rng.randrange(len(arrivals) or 1)
            if arrivals:
                arrivals[i], arrivals[j] = arrivals[j], arrivals[i]
                arrivals.insert(rng.randrange(len(arrivals) + 1), arrivals[rng.randrange(len(arrivals))])
        tr = SeqTracker()
        for s in arrivals:
            tr.add("k", s)
        ref = _model_accounting(arrivals)
        got = tr.totals() if arrivals else {"count": 0, "duplicates": 0, "out_of_order": 0, "missing": 0, "already_recorded": 0,
                                            "skipped": 0}
        assert got.pop("already_recorded") == 0  # nothing seeded
        assert got.pop("skipped") == 0  # no channel whose gaps are expected
        assert got == ref, (arrivals, got, ref)
        if arrivals:
            gaps = tr.report()["k"]["gaps"]
            absent = sorted(set(range(max(arrivals) + 1)) - set(arrivals))
            assert [s for a, b in gaps for s in range(a, b + 1)] == absent
            assert gap_report(np.array(arrivals))["gaps"] == gaps  # the reader's batch version agrees


def test_load_blocks_is_load_in_pieces_and_the_run_summary_does_not_depend_on_them():
    """load_blocks (bounded memory) against load (whole file) on the pre-refactor fixture:
    the blocks' tracks concatenated are load's, field by field; the end-of-run summary
    computed block by block (first state put in front of each block) equals the one from a
    single block exactly, because every drift is a largest deviation from the first state."""
    from pathlib import Path

    from astrodyn.recording import load_blocks
    from astrodyn.scenario import load as load_scenario
    from astrodyn.service.summary import file_summary

    fixtures = Path(__file__).parent / "fixtures"
    path = fixtures / "legacy-v0.mcap"
    whole = load(path)
    blocks = list(load_blocks(path, 1))
    assert len(blocks) >= 3 and sum(b.messages for b in blocks) == whole.messages
    assert blocks[-1].truncated == whole.truncated and not any(b.truncated for b in blocks[:-1])
    for topic, track in whole.channels.items():
        parts = [b.channels[topic] for b in blocks if topic in b.channels and len(b.channels[topic])]
        assert np.array_equal(np.concatenate([p.seq for p in parts]), track.seq), topic
        for name, col in track.fields.items():
            if col.dtype != object:
                assert np.array_equal(np.concatenate([p.fields[name] for p in parts]), col, equal_nan=True), (topic, name)
    scenario = load_scenario(fixtures / "legacy-v0.toml")
    assert file_summary(path, scenario, block_messages=1) == file_summary(path, scenario, block_messages=10**9)
    with pytest.raises(ValueError, match="block_messages"):
        next(load_blocks(path, 0))


def test_channel_tails_are_the_last_messages_the_plain_reader_sees_also_in_a_cut_file(recorded, tmp_path):
    """channel_tails against the plain mcap reader (complete file) and against what load
    reads of each cut prefix: per channel the last ``keep`` payloads in file order."""
    from astrodyn.recording.tail import channel_tails

    expected: dict[str, list[bytes]] = {}
    with open(recorded, "rb") as f:
        for _, channel, message in make_reader(f).iter_messages(log_time_order=False):
            expected.setdefault(channel.topic, []).append(bytes(message.data))
    wanted = [t for t in expected if t.endswith("/orbit") or t.endswith("/attitude")]
    tails = channel_tails(recorded, lambda topic: topic in wanted, keep=3)
    assert tails == {t: expected[t][-3:] for t in wanted}
    data = recorded.read_bytes()
    rng = random.Random(11)
    for cut in sorted(rng.randrange(8, len(data)) for _ in range(12)):
        (tmp_path / "cut.mcap").write_bytes(data[:cut])
        run = load(tmp_path / "cut.mcap")
        tails = channel_tails(tmp_path / "cut.mcap", lambda topic: topic in wanted, keep=2)
        for topic in wanted:
            track = run.channels.get(topic)
            got = [json.loads(p)["seq"] for p in tails.get(topic, [])]
            assert got == ([] if track is None else [int(s) for s in track.seq[-2:]]), (cut, topic)
    with pytest.raises(RecordingError, match="not an MCAP file"):
        (tmp_path / "text.mcap").write_text("hello")
        channel_tails(tmp_path / "text.mcap", lambda topic: True)


def test_a_seeded_channel_drops_what_an_earlier_part_holds_and_counts_no_gap():
    tr = SeqTracker()
    tr.seed("k", 10)
    assert [tr.add("k", s) for s in [8, 9, 10, 11, 13, 12, 12]] == [DUPLICATE, DUPLICATE, OK, OK, GAP, LATE, DUPLICATE]
    totals = tr.totals()
    assert (totals["count"], totals["missing"], totals["already_recorded"], totals["duplicates"]) == (4, 0, 2, 1)
    with pytest.raises(ValueError, match="seed before recording"):
        tr.seed("k", 20)
    with pytest.raises(ValueError, match="expected a seq >= 0"):
        SeqTracker().seed("k", -1)


def test_validated_channels_give_the_columns_the_checked_path_gives(tmp_path):
    """States on astrodyn keys are validated by messages.decode and appended without a second
    check; the same payloads on a foreign key with the same stored JSON Schema go through the
    field-by-field check.  Both paths must give identical columns, optional fields left out
    included (NaN for a number, -1 for an integer)."""
    from mcap.writer import Writer

    rng = np.random.default_rng(7)
    orbit_name, orbit_schema = messages.schema_for_key(messages.orbit_key("v", "sat"))
    status_name, status_schema = messages.schema_for_key(messages.status_key("v"))
    path = tmp_path / "both.mcap"
    with open(path, "wb") as f:
        w = Writer(f)
        w.start()
        ids = {}
        for name, schema, topics in ((orbit_name, orbit_schema, (messages.orbit_key("v", "sat"), "foreign/sat/orbit")),
                                     (status_name, status_schema, (messages.status_key("v"), "foreign/status"))):
            sid = w.register_schema(name=name, encoding="jsonschema", data=json.dumps(schema).encode())
            for topic in topics:
                ids[topic] = w.register_channel(topic=topic, message_encoding="json", schema_id=sid)
        for i in range(200):
            r, v = rng.normal(size=3) * 7e6, rng.normal(size=3) * 7e3
            orbit = messages.encode(messages.orbit_message(0.5 * i, i, "kepler", r, v, 3.986004418e14), "orbit")
            extra = {"rate": 2.0} if i % 3 else {"messages": i}  # each optional field absent from some
            status = messages.encode(messages.status_message(0.5 * i, i, "running", 1.0 + i, **extra), "status")
            for topic, payload in ((messages.orbit_key("v", "sat"), orbit), ("foreign/sat/orbit", orbit),
                                   (messages.status_key("v"), status), ("foreign/status", status)):
                w.add_message(ids[topic], log_time=i, publish_time=i, data=payload, sequence=i)
        w.finish()
    run = load(path)
    assert run.invalid == 0 and run.messages == 800
    for ours, foreign in ((messages.orbit_key("v", "sat"), "foreign/sat/orbit"), (messages.status_key("v"), "foreign/status")):
        a, b = run.channels[ours], run.channels[foreign]
        assert a.kind is not None and b.kind is None  # one validated, one checked
        assert np.array_equal(a.seq, b.seq) and np.array_equal(a.log_time, b.log_time)
        assert sorted(a.fields) == sorted(b.fields)
        for name, column in a.fields.items():
            assert column.dtype == b.fields[name].dtype, name
            if column.dtype == object:
                assert list(column) == list(b.fields[name]), name
            else:
                assert np.array_equal(column, b.fields[name], equal_nan=column.dtype.kind == "f"), name
    status = run.channels[messages.status_key("v")].fields
    assert np.isnan(status["rate"][0]) and status["rate"][1] == 2.0 and status["messages"][1] == -1


def test_a_part_passes_roll_size_by_less_than_one_chunk_however_fast_messages_come(tmp_path):
    """``roll_size`` was checked at each flush only (every ``flush_interval_s``): a logger fed
    faster than a flush's worth of ``roll_size`` wrote parts many times over it (probe B:
    20-27 MB parts for ``--roll-size "1 MiB"`` at 1000 bodies).  Here no flush is due during
    the writes (a 1 h flush interval), so only the size check can roll; each finished part
    must end within one compressed chunk (at most ``chunk_size`` plus its record header) of
    ``roll_size``, and the parts together hold every message once, in order."""
    roll, chunk = 6000, 2048
    path = tmp_path / "r.mcap"
    with McapRecorder(path, METADATA, epoch_ns=EPOCH_NS, chunk_size=chunk, roll_size=roll,
                      flush_interval_s=3600.0) as rec:
        for key, msg in _expected_messages():
            rec.write(key, msg)
        paths = list(rec.paths)
    assert len(paths) >= 3, paths
    for part in paths[:-1]:
        assert os.path.getsize(part) <= roll + chunk + 4096, (part, os.path.getsize(part))  # + summary and footer
    got = []
    for part in paths:
        with open(part, "rb") as f:
            got += [(c.topic, json.loads(m.data)) for _, c, m in make_reader(f).iter_messages(log_time_order=False)]
    assert got == _expected_messages()
