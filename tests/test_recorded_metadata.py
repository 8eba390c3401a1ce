"""``recorded_metadata`` against hostile files: cut anywhere, a summary and footer that lie.

``astrodyn.recording.reader.recorded_metadata`` is what ``run --resume``, ``run --commands``
and ``serve`` read first of a recording the user names (its ``scenario`` record, written at
the head, and its ``end`` record, which a finished file's summary indexes after the
messages).  Its offsets and lengths come from the file, so they are hostile: whatever the
summary section and footer say, the call must end quickly with what the file really holds
or less -- never another record's content under a name, never an exception other than
``RecordingError`` for a file that is not MCAP.

The files are written with the ``mcap`` package's own writer (one chunk per message, so the
``end`` record lies after the messages, where astrodyn's logger writes it), and the truth
is what the test wrote.  The head (magic, header, the ``scenario`` record) is never damaged
below, so ``scenario`` must always be found, byte for byte.
"""

from __future__ import annotations

import io
import random
import struct

import pytest
from mcap.writer import Writer

from astrodyn.recording.reader import RecordingError, recorded_metadata

TRUTH = {"scenario": {"name": "demo", "config": "[orbit]\nbodies = 3\n" * 20},
         "end": {"complete": "true", "states": "40", "reason": "end of run"}}
FOOTER = struct.Struct("<BQQQI")  # opcode, length (20), summary_start, summary_offset_start, summary_crc
MAGIC = 8


def _recording() -> bytes:
    buf = io.BytesIO()
    w = Writer(buf, chunk_size=1)  # every message its own chunk: "end" comes after them all
    w.start("x", "test")
    w.add_metadata("scenario", TRUTH["scenario"])
    schema = w.register_schema("s", "jsonschema", b"{}")
    channel = w.register_channel("astrodyn/demo/a/orbit", "json", schema)
    for i in range(40):
        w.add_message(channel, i, b'{"t":%d.0,"seq":%d}' % (i, i), i)
    w.add_metadata("end", TRUTH["end"])
    w.add_metadata("other", {"k": "v"})
    w.finish()
    return buf.getvalue()


DATA = _recording()
FOOTER_AT = len(DATA) - MAGIC - FOOTER.size
SUMMARY_START = FOOTER.unpack_from(DATA, FOOTER_AT)[2]


def _read(tmp_path, data: bytes) -> dict:
    path = tmp_path / "r.mcap"
    path.write_bytes(data)
    return recorded_metadata(path, ("scenario", "end"))


def _held(found: dict, head_intact: bool = True) -> None:
    """What was found is what the file holds, or less; ``scenario`` (in the head) always."""
    assert set(found) <= set(TRUTH), found
    for name, meta in found.items():
        assert meta == TRUTH[name], (name, meta)
    if head_intact:
        assert "scenario" in found


def test_an_intact_file_gives_both_records_the_head_one_and_the_indexed_one(tmp_path):
    assert SUMMARY_START > DATA.index(b"end of run")  # the end record lies after the messages
    assert _read(tmp_path, DATA) == TRUTH


def test_a_file_cut_anywhere_gives_what_its_head_holds(tmp_path):
    head_end = DATA.index(TRUTH["scenario"]["config"].encode()) + len(TRUTH["scenario"]["config"])
    for cut in list(range(0, 40)) + list(range(40, len(DATA), 13)):
        if cut < MAGIC:
            with pytest.raises(RecordingError, match="not an MCAP file"):
                _read(tmp_path, DATA[:cut])
            continue
        found = _read(tmp_path, DATA[:cut])
        _held(found, head_intact=cut > head_end)
        assert "end" not in found  # no footer: the end record is only ever found through the summary


def _with_footer(summary_start: int, offsets_start: int) -> bytes:
    return DATA[:FOOTER_AT] + FOOTER.pack(0x02, 20, summary_start, offsets_start, 0) + DATA[FOOTER_AT + FOOTER.size:]


@pytest.mark.parametrize("summary_start", [0, 1, MAGIC, SUMMARY_START - 1, SUMMARY_START + 1, FOOTER_AT, FOOTER_AT + 1,
                                           len(DATA), 2**63, 2**64 - 1])
@pytest.mark.parametrize("offsets_start", [0, 1, SUMMARY_START, FOOTER_AT, len(DATA), 2**64 - 1])
def test_a_footer_whose_offsets_lie_gives_what_the_file_holds_or_less(tmp_path, summary_start, offsets_start):
    _held(_read(tmp_path, _with_footer(summary_start, offsets_start)))


def test_a_damaged_summary_section_never_gives_another_records_content(tmp_path):
    rng = random.Random(20261127)
    for trial in range(300):
        data = bytearray(DATA)
        for _ in range(rng.choice((1, 2, 4))):
            at = rng.randrange(SUMMARY_START, FOOTER_AT + FOOTER.size)
            if rng.random() < 0.5:  # one byte
                data[at] = rng.randrange(256)
            else:  # an offset or length: a u64 of a telling kind
                value = rng.choice((0, 1, MAGIC, rng.randrange(len(DATA)), len(DATA), 2**63, 2**64 - 1))
                at = min(at, len(data) - MAGIC - 8)
                data[at:at + 8] = struct.pack("<Q", value)
        found = _read(tmp_path, bytes(data))
        _held(found), trial


def _record_at(data: bytes, pos: int) -> tuple[int, int]:
    """(opcode, whole length with the 9-byte header) of the record at ``pos``."""
    opcode, length = struct.unpack_from("<BQ", data, pos)
    return opcode, 9 + length


HEADER_LENGTH = _record_at(DATA, MAGIC)[1]
SCENARIO_AT = MAGIC + HEADER_LENGTH  # the head's first metadata record
FIRST_CHUNK_AT = DATA.index(b"\x06", SCENARIO_AT + _record_at(DATA, SCENARIO_AT)[1])


@pytest.mark.parametrize("offset, length", [
    (SCENARIO_AT, _record_at(DATA, SCENARIO_AT)[1]),  # a well-formed metadata record of another name
    (FIRST_CHUNK_AT, _record_at(DATA, FIRST_CHUNK_AT)[1]),  # a record of another kind
    (SCENARIO_AT + 1, 100), (0, 29), (SUMMARY_START, 50), (FOOTER_AT, 29),
    (SCENARIO_AT, 2**63), (2**64 - 1, 2**64 - 1), (len(DATA), 9),
])
def test_a_metadata_index_that_points_elsewhere_gives_no_end_record(tmp_path, offset, length):
    at = DATA.index(struct.pack("<I", 3) + b"end", SUMMARY_START)  # the index of "end": offset u64, length u64, name
    assert _record_at(DATA, SCENARIO_AT)[0] == 0x0C and _record_at(DATA, FIRST_CHUNK_AT)[0] == 0x06
    data = DATA[:at - 16] + struct.pack("<QQ", offset, length) + DATA[at:]
    found = _read(tmp_path, data)
    _held(found)
    assert "end" not in found
