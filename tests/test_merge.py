"""Merging partial recordings of one run (astrodyn.recording.merge, `astrodyn merge`).

The reference is the recording made by the pre-refactor code (tests/fixtures/legacy-v0.mcap),
read by the `mcap` package.  Its messages are split into two overlapping parts, as two
loggers of one run would hold them (one stopped at 70 % of the run, one started at 40 %),
written by the `mcap` package's writer; one part is then cut mid-file as a killed writer
leaves it.  The merge must give back every message of the original exactly once, payload
and times unchanged, in log-time order.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.writer import Writer

from astrodyn.recording import load
from astrodyn.recording.merge import merge
from astrodyn.recording.writer import RecordingError

FIXTURE = Path(__file__).parent / "fixtures" / "legacy-v0.mcap"


def _messages(path: Path):
    with open(path, "rb") as f:
        return [(ch.topic, m.log_time, m.publish_time, m.sequence, m.data, sc.name if sc else "")
                for sc, ch, m in make_reader(f).iter_messages(log_time_order=True)]


def _metadata(path: Path) -> dict:
    with open(path, "rb") as f:
        return {m.name: dict(m.metadata) for m in make_reader(f).iter_metadata()}


def _write_part(path: Path, msgs, meta: dict, chunk_size: int = 4096) -> None:
    with open(FIXTURE, "rb") as f:
        summary = make_reader(f).get_summary()
    with open(path, "wb") as f:
        w = Writer(f, chunk_size=chunk_size)
        w.start()
        sids, cids = {}, {}
        for topic, log_time, publish_time, seq, data, _ in msgs:
            if topic not in cids:
                ch = next(c for c in summary.channels.values() if c.topic == topic)
                sc = summary.schemas[ch.schema_id]
                if sc.id not in sids:
                    sids[sc.id] = w.register_schema(sc.name, sc.encoding, sc.data)
                cids[topic] = w.register_channel(topic, ch.message_encoding, sids[sc.id])
            w.add_message(cids[topic], log_time=log_time, data=data, publish_time=publish_time, sequence=seq)
        for name, data in meta.items():
            w.add_metadata(name, data)
        w.finish()


@pytest.fixture
def parts(tmp_path):
    msgs = _messages(FIXTURE)
    meta = _metadata(FIXTURE)
    t0, t1 = msgs[0][1], msgs[-1][1]
    cut_a, cut_b = t0 + 0.7 * (t1 - t0), t0 + 0.4 * (t1 - t0)
    a, b = tmp_path / "main.mcap", tmp_path / "standby.mcap"
    _write_part(a, [m for m in msgs if m[1] <= cut_a], meta)
    _write_part(b, [m for m in msgs if m[1] >= cut_b], {"scenario": meta["scenario"]})
    return msgs, meta, a, b


def test_two_overlapping_parts_merge_into_the_original(parts, tmp_path):
    msgs, meta, a, b = parts
    out = tmp_path / "merged.mcap"
    report = merge([a, b], out)
    merged = _messages(out)
    assert sorted(merged) == sorted(msgs)  # every message once, bytes and times unchanged
    assert [m[1] for m in merged] == sorted(m[1] for m in merged)
    assert report.messages == len(msgs) and report.duplicates > 0 and report.conflicts == 0
    got = _metadata(out)
    assert got["scenario"] == meta["scenario"] and got["merged_from"]["duplicates"] == str(report.duplicates)
    run = load(out)  # astrodyn's own reader: no gap, no duplicate in any channel
    assert run.gaps and all(g["missing"] == 0 and g["duplicates"] == 0 for g in run.gaps.values()), run.gaps
    assert len(run.bodies["molniya"].orbit) == 121


def test_a_part_cut_by_a_killed_writer_still_merges(parts, tmp_path):
    msgs, _, a, b = parts
    data = b.read_bytes()
    cut = tmp_path / "standby-cut.mcap"
    cut.write_bytes(data[: int(len(data) * 0.8)])  # no summary, no footer, a chunk cut in two
    out = tmp_path / "merged.mcap"
    report = merge([a, cut], out)
    merged = set(_messages(out))
    assert merged <= set(msgs) and len(merged) == report.messages
    assert {m for m in msgs if m[1] <= msgs[0][1] + 0.7 * (msgs[-1][1] - msgs[0][1])} <= merged  # all of main
    assert "truncated" in report.inputs[str(cut)]


def test_conflicting_states_are_counted_not_written(parts, tmp_path):
    msgs, meta, a, b = parts
    forged = [(t, lt, pt, s, d.replace(b'"t":', b'"t": '), sn) if t.endswith("/iss/orbit") else (t, lt, pt, s, d, sn)
              for (t, lt, pt, s, d, sn) in _messages(b)]
    c = tmp_path / "other.mcap"
    _write_part(c, forged, {"scenario": meta["scenario"]})
    report = merge([a, c], tmp_path / "merged.mcap")
    n_overlap = sum(1 for m in _messages(a) if m[0].endswith("/iss/orbit") and m[1] >= _messages(b)[0][1])
    assert report.conflicts == n_overlap > 0


def test_refusals_are_clear(parts, tmp_path):
    msgs, meta, a, b = parts
    with pytest.raises(RecordingError, match="exists already"):
        merge([a, b], a)
    other = tmp_path / "other-run.mcap"
    _write_part(other, msgs[:10], {"scenario": {**meta["scenario"], "name": "another"}})
    with pytest.raises(RecordingError, match="different scenarios"):
        merge([a, other], tmp_path / "x.mcap")
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not an mcap file")
    proc = subprocess.run([sys.executable, "-m", "astrodyn", "merge", str(a), str(junk), "--out", str(tmp_path / "y.mcap")],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 1 and "Traceback" not in proc.stderr and "astrodyn merge:" in proc.stderr
    assert not (tmp_path / "y.mcap").exists()
    ok = subprocess.run([sys.executable, "-m", "astrodyn", "merge", str(a), str(b), "--out", str(tmp_path / "z.mcap")],
                        capture_output=True, text=True, timeout=60)
    assert ok.returncode == 0 and json.loads(ok.stdout)["messages"] == len(msgs)
