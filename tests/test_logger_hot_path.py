"""The logger's hot path: batch handling with the fast check, and the lean MCAP writer's
vectorized message indexes.

References: mcap 1.6's own ``MessageIndex`` record serialiser and its readers (CRC
validated), and the per-message slow path (``messages.decode``) for the verdicts.
"""

from __future__ import annotations

import io

import numpy as np
from mcap.data_stream import RecordBuilder
from mcap.reader import make_reader
from mcap.records import MessageIndex

from astrodyn import messages as m
from astrodyn.recording.chunked_writer import _message_indexes
from astrodyn.recording.writer import McapRecorder
from astrodyn.service.logger import Logger

EPOCH_NS = 1_774_008_000_000_000_000


def test_message_indexes_equal_mcap_records():
    rng = np.random.default_rng(3)
    channels = rng.integers(1, 40, size=500).astype(np.uint16)
    times = rng.integers(0, 2**63, size=500, dtype=np.uint64)
    offsets = np.cumsum(rng.integers(30, 300, size=500)).astype(np.uint64)
    ids, starts, counts, data = _message_indexes(channels, times, offsets)
    expected = b""
    for cid in sorted(set(channels.tolist())):
        sel = channels == cid
        builder = RecordBuilder()
        MessageIndex(channel_id=cid, records=list(zip(times[sel].tolist(), offsets[sel].tolist()))).write(builder)
        assert starts[ids.index(cid)] == len(expected)
        assert counts[ids.index(cid)] == int(sel.sum())
        expected += builder.end()
    assert data == expected
    assert ids == sorted(set(channels.tolist()))


def _logger(path):
    rec = McapRecorder(path, {"name": "c"}, epoch_ns=EPOCH_NS, chunk_size=4096)
    return Logger(None, "c", rec), rec


def test_batch_mixes_fast_slow_and_bad_entries(tmp_path):
    path = str(tmp_path / "x.mcap")
    logger, rec = _logger(path)
    keys = [m.orbit_key("c", f"s{i}") for i in range(3)] + [m.attitude_key("c", f"s{i}") for i in range(3)]
    r = np.array([[7e6, 0.0, 0.0], [0.0, 7e6, 1.0], [1.0, 2.0, 3.0]])
    v = np.array([[0.0, 7.5e3, 0.0], [-7.5e3, 0.0, 0.0], [4.0, 5.0, 6.0]])
    q = np.array([[1.0, 0, 0, 0], [0.5, 0.5, 0.5, 0.5], [0, 0, 0, 1.0]])
    w = np.full((3, 3), 1e-3)
    n_steps = 40
    for k in range(n_steps):
        orbit = m.encode_orbit_batch(k / 10, k, "kepler", r, v, 3.986004418e14)
        att = m.encode_attitude_batch(k / 10, k, "torque_free", q, w)
        orbit[1] = orbit[1].replace(b'{"t"', b'{ "t"')  # valid, not canonical: slow path
        items = list(zip(keys, orbit + att))
        items.append((keys[0], b'{"t":1e999}'))  # bad: counted, not written
        items.append(("astrodyn/other/s0/orbit", orbit[0]))  # another scenario: bad
        logger.handle("astrodyn/c/@batch/orbit", m.encode_batch(items))
    logger.handle("astrodyn/c/@batch/orbit", m.encode_batch([(keys[3], att[0])]))  # duplicate seq
    rec.close()
    assert logger.states == 6 * n_steps
    assert logger.malformed == 2 * n_steps
    assert logger.max_t == (n_steps - 1) / 10
    totals = rec.seq.totals()
    assert totals["missing"] == 0 and totals["duplicates"] == 1
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        got = {}
        for _, channel, message in reader.iter_messages(log_time_order=False):
            got.setdefault(channel.topic, []).append(message)
    assert sorted(got) == sorted(keys)
    for key, msgs in got.items():
        assert [x.sequence for x in msgs] == list(range(n_steps))
        assert [x.log_time for x in msgs] == [EPOCH_NS + round(k / 10 * 1e9) for k in range(n_steps)]
        for x in msgs:
            assert m.decode(x.data, key)["seq"] == x.sequence


def test_file_written_through_many_chunks_reads_back_with_indexes(tmp_path):
    path = str(tmp_path / "y.mcap")
    logger, rec = _logger(path)
    keys = [m.attitude_key("c", f"b{i}") for i in range(50)]
    q = np.tile([0.0, 0.6, 0.0, 0.8], (50, 1))
    w = np.zeros((50, 3))
    for k in range(30):
        logger.handle("astrodyn/c/@batch/attitude", m.encode_batch(zip(keys, m.encode_attitude_batch(k * 0.5, k, "torque_free", q, w))))
    rec.close()
    buf = io.BytesIO(open(path, "rb").read())
    reader = make_reader(buf, validate_crcs=True)
    stats = reader.get_summary().statistics
    assert stats.message_count == 1500 and stats.chunk_count > 5
    assert set(stats.channel_message_counts.values()) == {30}
    # the seeking reader uses the message indexes: every message, time order
    times = [msg.log_time for _, _, msg in reader.iter_messages(topics=[keys[7]])]
    assert times == [EPOCH_NS + k * 500_000_000 for k in range(30)]


def test_chunk_index_record_equals_mcap_serialiser():
    from mcap.records import ChunkIndex

    from astrodyn.recording.chunked_writer import chunk_index_record

    rng = np.random.default_rng(5)
    for n in (0, 1, 7, 300):
        ids = sorted(rng.choice(65535, size=n, replace=False) + 1)
        offs = rng.integers(0, 2**63, size=n).tolist()
        args = [int(x) for x in rng.integers(0, 2**63, size=4)]
        sizes = [int(x) for x in rng.integers(0, 2**40, size=3)]
        builder = RecordBuilder()
        ChunkIndex(
            message_start_time=args[0], message_end_time=args[1], chunk_start_offset=args[2], chunk_length=args[3],
            message_index_offsets=dict(zip(ids, offs)), message_index_length=sizes[0], compression="zstd",
            compressed_size=sizes[1], uncompressed_size=sizes[2],
        ).write(builder)
        assert chunk_index_record(*args, ids, offs, sizes[0], "zstd", sizes[1], sizes[2]) == builder.end()
