"""Read an astrodyn MCAP file into numpy arrays, including files whose writer crashed.

::

    run = load("demo.mcap")
    run.bodies["sat1"].orbit.r.shape        # (n, 3) metres, frame in .frame
    run.bodies["sat1"].attitude.q           # (n, 4) Euler parameters, scalar first
    run.scenario                            # the "scenario" metadata record (str -> str)
    run.complete, run.incomplete_reason     # False and why for a cut file, damaged chunks
                                            # or invalid messages (True, "" otherwise)
    run.truncated, run.truncation           # the cut alone: no footer, and why
    run.gaps["astrodyn/demo/sat1/orbit"]    # count, missing, gaps, duplicates

The file is read record by record from the start (never through the summary), one chunk
at a time, so a 1 GB file never sits in memory and a file without summary or footer (a
killed writer) reads up to its last complete record.  Every record's length is checked
against the bytes left before it is parsed: a cut record ends the read and sets
``truncated``; a chunk whose data is damaged (decompression or CRC failure) is skipped,
counted in ``corrupt_chunks`` and noted in ``truncation``.  Payloads on astrodyn keys
are validated with :func:`astrodyn.messages.decode`; invalid ones are counted in
``invalid`` (with examples), never returned as states.  Within a channel, tracks are
sorted by ``seq``.
"""

from __future__ import annotations

import io
import json
import os
import stat
import struct
import sys
import zlib
from array import array
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any, BinaryIO

import numpy as np
from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Message, Metadata, Schema

from astrodyn import messages
from astrodyn.files import file_kind
from astrodyn.recording.chunked_writer import MAGIC
from astrodyn.recording.writer import RecordingError

__all__ = ["recorded_metadata", "load", "load_blocks", "chunk_records", "chunk_limits", "parse_chunk_data", "ChunkError",
           "MAX_CHUNK_BYTES", "MAX_CHUNK_RATIO", "Run", "BodyTracks", "Body", "Track", "gap_report", "time_order", "SEQ_NOT_COUNTED",
           "sequence_issues", "sequence_note", "MCAP_MAGIC", "read_records", "scan_records", "open_recording"]

MCAP_MAGIC = MAGIC  #: the 8 bytes that open (and end) every MCAP file
_HEADER = struct.Struct("<BQ")
_MAX_EXAMPLES = 20


def gap_report(seqs: np.ndarray) -> dict:
    """Seq accounting of one channel from the seqs it holds: count, missing, gaps, duplicates.

    ``gaps`` lists inclusive ``[first, last]`` ranges of seqs absent between 0 and the
    largest seq present.
    """
    s = np.sort(np.asarray(seqs, dtype=np.int64))
    if s.size == 0:
        return {"count": 0, "missing": 0, "gaps": [], "duplicates": 0, "last_seq": None}
    u = np.unique(s)
    starts = np.concatenate(([-1], u))
    jumps = np.flatnonzero(np.diff(starts) > 1)
    gaps = [[int(starts[i] + 1), int(starts[i + 1] - 1)] for i in jumps]
    missing = int(u[-1] + 1 - u.size)
    return {"count": int(s.size), "missing": missing, "gaps": gaps, "duplicates": int(s.size - u.size), "last_seq": int(u[-1])}


#: Rows :func:`time_order` compares at a time: its temporaries stay small whatever the length of the channel.
_ORDER_ROWS = 65_536


def time_order(track: Track) -> dict:
    """How a state channel keeps the recording's contract (docs/architecture.md, "Messages
    and MCAP"): ``seq`` is the output step index, so one message per seq, and ``t`` (s since
    the epoch) increases with it.  The one check of this for every reader: ``analyze``
    reports it (:func:`sequence_issues`), the CSV / Parquet / Foxglove exports warn and
    write the rows as recorded, the OEM / AEM exports refuse the channel (a CCSDS ephemeris
    holds one state per epoch, in time order).

    ``track`` sorted by seq (as :func:`load` gives it); returns ``{"duplicates": rows
    repeating the seq of the row before (gap_report's count), "first_duplicate": the first
    such seq or None, "not_increasing": steps from one seq to the next whose t does not
    increase (a NaN t included), "first_not_increasing": [seq, t, previous seq, previous t]
    of the first or None}``.  Channels other than the state kinds
    (:data:`astrodyn.messages.STATE_KINDS`: a command's seq counts its sender's commands,
    an event's its process's) and channels without ``t`` give zeros."""
    out: dict[str, Any] = {"duplicates": 0, "first_duplicate": None, "not_increasing": 0, "first_not_increasing": None}
    t = track.fields.get("t") if track.kind in messages.STATE_KINDS else None
    n = len(track)
    if t is None or n < 2:
        return out
    for a in range(0, n - 1, _ORDER_ROWS):
        b = min(n, a + _ORDER_ROWS + 1)  # one row of overlap: the step from the chunk before
        seq, times = track.seq[a:b], np.asarray(t[a:b], dtype=np.float64)
        same = seq[1:] == seq[:-1]
        back = ~same & ~(times[1:] > times[:-1])
        if same.any():
            out["duplicates"] += int(np.count_nonzero(same))
            if out["first_duplicate"] is None:
                out["first_duplicate"] = int(seq[1 + int(np.argmax(same))])
        if back.any():
            out["not_increasing"] += int(np.count_nonzero(back))
            if out["first_not_increasing"] is None:
                k = int(np.argmax(back))
                out["first_not_increasing"] = [int(seq[k + 1]), float(times[k + 1]), int(seq[k]), float(times[k])]
    return out


#: Kinds whose seq is not a count of their channel's messages: a command channel's seq counts
#: each sender's commands over every body (docs/control.md), so repeats and jumps are normal.
SEQ_NOT_COUNTED = ("command",)


def sequence_issues(run: Run) -> dict[str, dict]:
    """The seq accounting of ``run`` (``load(path)``) for every channel that breaks it: per
    channel whose seq counts its messages (per process on the event channel,
    ``<topic>#<process>``; its :func:`gap_report`) with duplicated or missing seqs, and per
    state channel whose ``t`` does not increase with seq (:func:`time_order`).  ``{key:
    {"duplicates": messages repeating a seq already present, "missing": seqs absent below
    the largest, "gap_count", "gaps": the first 5 [first, last] ranges}}``, and where t does
    not increase ``"t_not_increasing"``: the steps, ``"t_first_not_increasing"``: [seq, t,
    previous seq, previous t] of the first.  The one account ``analyze`` and ``export``
    print (:func:`sequence_note`)."""
    issues = {}
    for key, report in run.gaps.items():
        track = run.channels.get(key.split("#", 1)[0])
        if track is not None and track.kind in SEQ_NOT_COUNTED:
            continue
        order = time_order(track) if track is not None else {}  # zeros but on a state channel
        if report.get("duplicates") or report.get("missing") or order.get("not_increasing"):
            gaps = report.get("gaps", [])
            issues[key] = {"duplicates": int(report.get("duplicates", 0)), "missing": int(report.get("missing", 0)),
                           "gap_count": len(gaps), "gaps": [list(g) for g in gaps[:5]]}
            if order.get("not_increasing"):
                issues[key].update(t_not_increasing=order["not_increasing"],
                                   t_first_not_increasing=order["first_not_increasing"])
    return issues


def sequence_note(issues: dict[str, dict], channels: int = 5) -> str:
    """One line for a report and a warning: per channel of :func:`sequence_issues` (the
    first ``channels``, then how many more) its duplicated and missing seqs and where its
    ``t`` does not increase with seq."""
    parts = []
    for key, issue in list(issues.items())[:channels]:
        said = []
        n = issue["duplicates"]
        if n:
            said.append(f"{n} duplicated sequence number{'' if n == 1 else 's'} (a message repeating a seq already "
                        f"recorded)")
        n = issue["missing"]
        if n:
            ranges = ", ".join(f"{a}" if a == b else f"{a}-{b}" for a, b in issue["gaps"])
            ranges += ", ..." if issue["gap_count"] > len(issue["gaps"]) else ""
            said.append(f"{n} missing sequence number{'' if n == 1 else 's'} (seq {ranges})")
        n = issue.get("t_not_increasing", 0)
        if n:
            seq, t, before, t_before = issue["t_first_not_increasing"]
            said.append(f"t does not increase with seq at {n} step{'' if n == 1 else 's'} (the first: seq {seq}: "
                        f"t = {t:g} s after t = {t_before:g} s (seq {before}))")
        parts.append(f"{key}: {' and '.join(said)}")
    more = len(issues) - channels
    return "; ".join(parts) + (f"; and {more} more channel{'' if more == 1 else 's'}" if more > 0 else "")


class Track:
    """The messages of one channel as arrays, sorted by seq.

    Always: ``topic``, ``kind``, ``schema_name``, ``seq`` (int64), ``log_time`` (uint64 ns
    since the Unix epoch: MCAP's whole range, 1970 to 2554, so a state after 2262-04-11,
    2**63 ns, reads like any other) and, for astrodyn kinds, ``t`` (s since the scenario
    epoch).
    Schema fields become attributes: numbers -> ``(n,)`` float64, integers -> ``(n,)``
    int64, fixed-length number arrays -> ``(n, k)`` float64 (``r``, ``v``, ``q``, ``w``,
    ``dr``, ``dv``), strings -> ``(n,)`` object arrays (``model``, ``frame``).  Channels
    without a known schema keep the decoded JSON objects in ``records``.
    """

    def __init__(self, topic: str, kind: str | None, schema_name: str, seq, log_time, fields: dict, records: list | None = None):
        self.topic = topic
        self.kind = kind
        self.schema_name = schema_name
        self.seq = seq
        self.log_time = log_time
        self.fields = fields
        self.records = records

    def __getattr__(self, name: str) -> Any:
        fields = self.__dict__.get("fields", {})
        if name in fields:
            return fields[name]
        raise AttributeError(f"{type(self).__name__} {self.__dict__.get('topic')!r} has no field {name!r}; fields: {', '.join(fields)}")

    def __len__(self) -> int:
        return int(self.seq.size)

    def __repr__(self) -> str:
        return f"Track({self.topic!r}, n={len(self)}, fields={list(self.fields)})"


@dataclass
class BodyTracks:
    """The tracks of one body: ``orbit``, ``attitude``, ``crosscheck``, ``appendages`` (a
    flexible spacecraft's elastic state), ``rolling`` (a rolling disk's contact state),
    ``gimbals`` (its single-axis gyroscopes); None if absent."""

    name: str
    orbit: Track | None = None
    attitude: Track | None = None
    crosscheck: Track | None = None
    appendages: Track | None = None
    rolling: Track | None = None
    gimbals: Track | None = None


Body = BodyTracks
"""Deprecated old name of :class:`BodyTracks` (the scene's body is :class:`astrodyn.scenario.Body`)."""


@dataclass
class Run:
    """Everything read from one file (see the module docstring)."""

    path: str
    scenario: dict[str, str]
    metadata: dict[str, dict[str, str]]
    bodies: dict[str, BodyTracks]
    channels: dict[str, Track]
    events: list[dict]
    gaps: dict[str, dict]
    messages: int
    truncated: bool
    truncation: str = ""
    corrupt_chunks: int = 0
    invalid: int = 0
    invalid_examples: list[str] = field(default_factory=list)
    #: invalid messages per channel topic (not JSON, or violating astrodyn's message
    #: definition on astrodyn keys, or the stored JSON Schema's field types elsewhere)
    invalid_by_channel: dict[str, int] = field(default_factory=dict)
    #: invalid messages rejected for the reason of the first one (``invalid_examples[0]``)
    invalid_first_reason_count: int = 0

    @property
    def complete(self) -> bool:
        """True for a finished file with every record intact and every message valid."""
        return not self.truncated and self.corrupt_chunks == 0 and self.invalid == 0

    @property
    def incomplete_reason(self) -> str:
        """Why the file is not :attr:`complete`, in one line ("" when it is): the cut or
        damage (``truncation``) and the invalid messages per channel."""
        parts = [self.truncation] if self.truncation else []
        if self.truncated and not self.truncation:
            parts.append("the file has no footer (its writer did not finish)")
        if self.invalid:
            parts.append(self.invalid_note())
        return "; ".join(parts)

    def invalid_note(self, channels: int = 5) -> str:
        """The invalid messages in one line: how many, on which channels (the first
        ``channels`` by name, then how many more), and why the first was rejected, with the
        number of messages rejected for that same reason ("" when there is none)."""
        if not self.invalid:
            return ""
        counts = sorted(self.invalid_by_channel.items())
        shown = ", ".join(f"{n} on {topic}" for topic, n in counts[:channels])
        more = len(counts) - channels
        shown += f", and {more} more channel{'' if more == 1 else 's'}" if more > 0 else ""
        text = f"{self.invalid} invalid messages skipped" + (f" ({shown})" if shown else "")
        if self.invalid_examples:
            first = self.invalid_examples[0]
            first = first if len(first) <= 300 else first[:297] + "..."
            n = self.invalid_first_reason_count
            text += f"; the first: {first}" + (f" ({n} messages rejected for this reason)" if n > 1 else "")
        return text

    def __repr__(self) -> str:
        """One line: file, scenario, bodies, channels, span of t, messages, state.  The
        config as run is one attribute away (``run.scenario``), not printed."""
        ts = [tr.fields["t"] for tr in self.channels.values() if "t" in tr.fields and len(tr)]
        span = f", t {min(float(t.min()) for t in ts):.6g}..{max(float(t.max()) for t in ts):.6g} s" if ts else ""
        names = list(self.bodies)
        shown = ", ".join(names[:5]) + (f", ... ({len(names)} in all)" if len(names) > 5 else "")
        state = "complete" if self.complete else f"incomplete: {self.incomplete_reason}"
        return (f"Run({os.path.basename(self.path)!r}, scenario {self.scenario.get('name', '?')!r}, bodies [{shown}], "
                f"{len(self.channels)} channels{span}, {self.messages} messages, {state})")


# ------------------------------------------------------------------------------- scanning


class _Truncated(Exception):
    pass


def open_recording(path: str) -> tuple[BinaryIO, int]:
    """``(file, size)`` of the recording ``path`` opened for reading;
    :class:`RecordingError` ``<path>: cannot open: ...`` when it cannot be."""
    try:  # O_NONBLOCK: opening a FIFO must not wait for a writer; only regular files are read
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except OSError as exc:
        raise RecordingError(f"{path}: cannot open: {exc.strerror or exc}") from None
    st = os.fstat(fd)
    if not stat.S_ISREG(st.st_mode):
        os.close(fd)
        raise RecordingError(f"{path}: cannot open: expected a regular file, got {file_kind(st.st_mode)}")
    return os.fdopen(fd, "rb"), st.st_size


def read_records(f: BinaryIO, size: int, path: str, state: dict) -> Iterator[tuple[int, bytes, int]]:
    """Yield (opcode, body, offset) of each complete top-level record up to the footer
    (:func:`scan_records` with whole bodies)."""
    for opcode, body, pos, _ in scan_records(f, size, path, state):
        yield opcode, body, pos


def scan_records(f: BinaryIO, size: int, path: str, state: dict,
                 heads: dict[int, int] | None = None) -> Iterator[tuple[int, bytes, int, int]]:
    """The one crash-tolerant walk over an MCAP file's top-level records: yield
    ``(opcode, body, offset, length)`` of each complete record up to the footer.

    ``heads``: opcode -> bytes; records of those opcodes yield only the first bytes of
    their body (the rest is skipped with a seek: an index pass reads a chunk's header,
    not its data).  Where the file ends early, ``state["truncation"]`` says how; a file
    whose footer is followed by the closing magic sets ``state["complete"]``.
    RecordingError for a file that is not MCAP at all."""
    f.seek(0)
    head = f.read(8)
    if head != MCAP_MAGIC:
        if size == 0:
            raise RecordingError(f"{path}: not an MCAP file (empty file)")
        if len(head) < 8 and MCAP_MAGIC.startswith(head):
            state["truncation"] = f"file ends inside the opening magic ({size} bytes)"
            return
        raise RecordingError(f"{path}: not an MCAP file (bad magic)")
    heads = heads or {}
    for opcode, pos, length in record_headers(f, 8, size, state):
        body = f.read(min(length, heads[opcode]) if opcode in heads else length)
        yield opcode, body, pos, length
        if opcode == Opcode.FOOTER:
            f.seek(pos + 9 + length)
            if f.read(8) != MCAP_MAGIC:
                state["truncation"] = "footer not followed by the closing magic"
            else:
                state["complete"] = True
            return


def record_headers(f: BinaryIO, begin: int, end: int, state: dict | None = None,
                   limit: int | None = None) -> Iterator[tuple[int, int, int]]:
    """``(opcode, offset, body length)`` of each MCAP record from byte ``begin`` on, each
    whole before byte ``end`` (the end of the file or of a section); over at most ``limit``
    records.  After each yield ``f`` is at the record's body.  The walk ends at ``end`` and
    at a record that does not fit before it; ``state["truncation"]`` (when ``state`` is
    given) then says where the bytes ran out, for a walk up to the end of the file.  The one
    record walk of the readers: :func:`scan_records` (a whole file, crash-tolerant) and the
    bounded walks of a summary section (:func:`recorded_metadata`)."""
    pos = begin
    count = 0
    while limit is None or count < limit:
        count += 1
        reason = None
        if pos == end:
            reason = f"file ends at byte {pos} without data end and footer (writer did not finish)"
        elif end - pos < 9:
            reason = f"file ends inside a record header at byte {pos}"
        else:
            f.seek(pos)
            head = f.read(9)
            if len(head) != 9:
                reason = f"file ends inside a record header at byte {pos}"
            else:
                opcode, length = _HEADER.unpack(head)
                if length > end - pos - 9:
                    name = Opcode(opcode).name if opcode in Opcode._value2member_map_ else f"opcode {opcode:#x}"
                    reason = f"{name} record at byte {pos} needs {length} bytes, only {end - pos - 9} left (cut or corrupt)"
        if reason is not None:
            if state is not None:
                state["truncation"] = reason
            return
        yield opcode, pos, length
        pos += 9 + length


#: Largest declared uncompressed size of one chunk that is decompressed (bytes).  astrodyn
#: writes 1 MiB chunks and other tools a few MiB; more is refused before decompression.
#: Override with the environment variable ``ASTRODYN_MAX_CHUNK_BYTES``.
MAX_CHUNK_BYTES = 64 * 2**20
#: Largest uncompressed / compressed size ratio of a chunk.  JSON states compress 3-10x
#: and very repetitive data a few hundred times; a decompression bomb (zeros, or one
#: record repeated) goes far beyond.  Override with ``ASTRODYN_MAX_CHUNK_RATIO``.
MAX_CHUNK_RATIO = 1000
_MESSAGE_HEAD = struct.Struct("<HIQQ")  # channel_id, sequence, log_time, publish_time
_CHUNK_COMPRESSIONS = ("", "zstd", "lz4")


class ChunkError(ValueError):
    """A chunk refused before or while it is opened: too large, a likely bomb, damaged."""


def chunk_limits() -> tuple[int, float]:
    """(:data:`MAX_CHUNK_BYTES`, :data:`MAX_CHUNK_RATIO`) or their environment overrides."""
    def env(name: str, default: float, kind: type) -> float:
        text = os.environ.get(name)
        if not text:
            return default
        try:
            value = kind(text)
        except ValueError:
            raise RecordingError(f"{name}={text!r}: expected a positive number") from None
        if not value > 0:
            raise RecordingError(f"{name}={text!r}: expected a positive number")
        return value

    return int(env("ASTRODYN_MAX_CHUNK_BYTES", MAX_CHUNK_BYTES, int)), env("ASTRODYN_MAX_CHUNK_RATIO", MAX_CHUNK_RATIO, float)


def chunk_records(chunk: Chunk, limits: tuple[int, float] | None = None) -> list[Schema | Channel | Message]:
    """The Schema, Channel and Message records inside one MCAP chunk, read without trusting it.

    Before anything is decompressed, the declared uncompressed size is checked against
    ``limits`` (:func:`chunk_limits`: at most :data:`MAX_CHUNK_BYTES`, and at most
    :data:`MAX_CHUNK_RATIO` times the compressed size); decompression then stops at the
    declared size whatever the compressed frame says, and the CRC is checked.  Records are
    cut out with ``struct`` at their length prefixes (each Message is one unpack and one
    slice: 0.87 us per record against 2.1 us for ``mcap.stream_reader.breakup_chunk``, same records);
    a record that does not fit, or an opcode that may not appear in a chunk, ends it with
    :class:`ChunkError` (user opcodes >= 0x80 are skipped, as the MCAP specification asks).
    Time and memory are bounded by the limits, so a 6 KB file that inflates to 200 MiB is
    refused in microseconds.
    """
    max_bytes, max_ratio = limits or chunk_limits()
    declared, packed = chunk.uncompressed_size, len(chunk.data)
    if chunk.compression not in _CHUNK_COMPRESSIONS:
        raise ChunkError(f"compression {chunk.compression!r}: expected one of zstd, lz4 or none")
    if chunk.compression and declared > max_ratio * max(packed, 1):
        raise ChunkError(f"declares {declared} bytes from {packed} compressed (ratio {declared / max(packed, 1):.0f}, "
                         f"limit {max_ratio:g}, ASTRODYN_MAX_CHUNK_RATIO): a decompression bomb")
    if declared > max_bytes:
        raise ChunkError(f"declares {declared} uncompressed bytes, more than the limit {max_bytes} "
                         f"(ASTRODYN_MAX_CHUNK_BYTES)")
    if chunk.compression == "zstd":
        import zstandard

        with zstandard.ZstdDecompressor().stream_reader(chunk.data, read_across_frames=True) as z:
            data = z.read(declared + 1)  # never more than declared + 1 bytes, whatever the frame claims
    elif chunk.compression == "lz4":
        import lz4.frame

        d = lz4.frame.LZ4FrameDecompressor()
        data = d.decompress(chunk.data, max_length=declared + 1)
    else:
        data = chunk.data
    if len(data) != declared:
        raise ChunkError(f"holds {'more' if len(data) > declared else len(data)} bytes, declared {declared}")
    if chunk.uncompressed_crc != 0 and zlib.crc32(data) != chunk.uncompressed_crc:
        raise ChunkError("CRC mismatch")
    return parse_chunk_data(data)


def parse_chunk_data(data: bytes) -> list[Schema | Channel | Message]:
    """Records of a chunk's decompressed bytes (see :func:`chunk_records`)."""
    out: list[Schema | Channel | Message] = []
    pos, n = 0, len(data)
    unpack_head, unpack_message = _HEADER.unpack_from, _MESSAGE_HEAD.unpack_from
    message_op, channel_op, schema_op = int(Opcode.MESSAGE), int(Opcode.CHANNEL), int(Opcode.SCHEMA)
    while pos < n:
        if n - pos < 9:
            raise ChunkError(f"record header cut at byte {pos} of the chunk")
        opcode, length = unpack_head(data, pos)
        start, end = pos + 9, pos + 9 + length
        if end > n:
            raise ChunkError(f"record at byte {pos} of the chunk needs {length} bytes, {n - start} left")
        if opcode == message_op:
            if length < 22:
                raise ChunkError(f"message record at byte {pos} of the chunk: {length} bytes, less than its 22-byte head")
            channel_id, sequence, log_time, publish_time = unpack_message(data, start)
            out.append(Message(channel_id=channel_id, sequence=sequence, log_time=log_time,
                               publish_time=publish_time, data=data[start + 22:end]))
        elif opcode in (channel_op, schema_op):
            stream = ReadDataStream(io.BytesIO(data[start:end]))
            out.append(Channel.read(stream) if opcode == channel_op else Schema.read(stream))
        elif opcode < 0x80:
            name = Opcode(opcode).name if opcode in Opcode._value2member_map_ else f"{opcode:#04x}"
            raise ChunkError(f"record {name} at byte {pos} of the chunk: only Schema, Channel and Message may be in a chunk")
        pos = end
    return out


def parse_record(opcode: int, body: bytes) -> Any:
    stream = ReadDataStream(io.BytesIO(body))
    if opcode == Opcode.MESSAGE:
        return Message.read(stream, len(body))
    if opcode == Opcode.CHUNK:
        return Chunk.read(stream)
    if opcode == Opcode.SCHEMA:
        return Schema.read(stream)
    if opcode == Opcode.CHANNEL:
        return Channel.read(stream)
    if opcode == Opcode.METADATA:
        return Metadata.read(stream)
    return None  # header, indexes, summary: not needed


# ------------------------------------------------------------------------------- columns


_INT64_MIN, _INT64_MAX = -(2**63), 2**63 - 1
#: Longest fixed-length number array of a foreign schema read as a (n, k) column; longer
#: ones (a schema may claim 10**9 items, which a missing field would fill with NaN) stay objects.
_MAX_VECTOR = 4096


def _columns_for(schema: dict | None) -> dict[str, tuple[str, int]] | None:
    """field -> (kind, width) from a JSON Schema: ("f", 1) float, ("i", 1) int, ("f", k) vector, ("s", 0) string."""
    properties = schema.get("properties") if isinstance(schema, dict) else None
    if not isinstance(properties, dict):
        return None
    out = {}
    for name, prop in properties.items():  # the file's schema: any JSON, never trusted
        prop = prop if isinstance(prop, dict) else {}
        typ, items, width = prop.get("type"), prop.get("items"), prop.get("minItems")
        if typ == "number":
            out[name] = ("f", 1)
        elif typ == "integer":
            out[name] = ("i", 1)
        elif (typ == "array" and _is_int64(width) and 1 <= width <= _MAX_VECTOR and prop.get("maxItems") == width
              and isinstance(items, dict) and items.get("type") == "number"):
            out[name] = ("f", width)
        elif typ == "string" or "enum" in prop:
            out[name] = ("s", 0)
        else:
            out[name] = ("o", 0)
    return out




_NAN = float("nan")


def _is_number(x: Any) -> bool:
    """A JSON number that fits a float64 (bool is not a number; 10**400 does not fit)."""
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        return False
    if isinstance(x, int):
        return abs(x) < 1.8e308
    return True


def _is_int64(x: Any) -> bool:
    return isinstance(x, int) and not isinstance(x, bool) and _INT64_MIN <= x <= _INT64_MAX


def _short(x: Any) -> str:
    text = repr(x)
    return text if len(text) <= 40 else text[:37] + "..."


class _Builder:
    __slots__ = ("topic", "kind", "schema_name", "columns", "seq", "log_time", "data", "records", "strings", "validated", "plan")

    def __init__(self, topic: str, kind: str | None, schema_name: str, columns: dict | None, validated: bool = False):
        """``validated``: every message given to :meth:`add_validated` was decoded by
        :func:`astrodyn.messages.decode` against the definition the columns come from, so
        its fields are known to be of their columns' types and are not checked again."""
        self.topic, self.kind, self.schema_name, self.columns = topic, kind, schema_name, columns
        self.validated = validated and columns is not None
        self.seq, self.log_time = array("q"), array("Q")  # log_time: MCAP's uint64 ns, all of it
        self.strings: dict[str, str] = {}
        self.records: list | None = None
        if columns is None:
            self.data = {}
            self.records = []
        else:
            self.data = {
                name: (array("d") if k == "f" else array("q") if k == "i" else [])
                for name, (k, _) in columns.items()
            }
        self.plan = tuple((name, k, width, self.data[name]) for name, (k, width) in (columns or {}).items())

    def add(self, msg: Any, seq: int, log_time: int) -> None:
        """Append one decoded message.  On a channel with columns (a JSON Schema was stored
        with it) the message is checked against them first -- an object, each present field
        of its column's type, numbers within float64 / int64 -- and :class:`ValueError`
        names the first field that is not; nothing is appended then (the file's schema is
        not trusted: a foreign writer may not follow it)."""
        if self.columns is None:
            self.log_time.append(log_time)
            self.seq.append(int(msg["seq"]) if isinstance(msg, dict) and isinstance(msg.get("seq"), int)
                            and _INT64_MIN <= msg["seq"] <= _INT64_MAX else seq)
            self.records.append(msg)
            return
        if not isinstance(msg, dict):
            raise ValueError(f"expected a JSON object, got {type(msg).__name__}")
        row_seq = msg.get("seq", seq)
        if not _is_int64(row_seq):
            raise ValueError(f"seq: expected an integer in int64, got {_short(row_seq)}")
        row = []
        for name, (k, width) in self.columns.items():
            value = msg.get(name)
            if k == "f":
                if width == 1:
                    if value is not None and not _is_number(value):
                        raise ValueError(f"{name}: expected a number, got {_short(value)}")
                    value = float("nan") if value is None else float(value)
                else:
                    if value is not None and not (isinstance(value, list) and len(value) == width
                                                  and all(_is_number(x) for x in value)):
                        raise ValueError(f"{name}: expected {width} numbers, got {_short(value)}")
                    value = [float("nan")] * width if value is None else [float(x) for x in value]
            elif k == "i":
                if value is not None and not _is_int64(value):
                    raise ValueError(f"{name}: expected an integer in int64, got {_short(value)}")
                value = -1 if value is None else value
            elif k == "s":
                if value is not None and not isinstance(value, str):
                    raise ValueError(f"{name}: expected a string, got {_short(value)}")
                value = None if value is None else self.strings.setdefault(value, value)
            row.append(value)
        self.log_time.append(log_time)
        self.seq.append(row_seq)
        for (name, (k, width)), value in zip(self.columns.items(), row):
            if k == "f" and width > 1:
                self.data[name].extend(value)
            else:
                self.data[name].append(value)

    def add_validated(self, msg: dict, seq: int, log_time: int) -> None:
        """Append one message already validated against this channel's definition (see
        ``validated``): absent optional fields as NaN / -1 / None, as :meth:`add` does."""
        for name, k, width, column in self.plan:
            value = msg.get(name)
            if k == "f":
                if width == 1:
                    column.append(_NAN if value is None else value)
                else:
                    column.extend((_NAN,) * width if value is None else value)
            elif k == "i":
                column.append(-1 if value is None else value)
            elif k == "s":
                column.append(None if value is None else self.strings.setdefault(value, value))
            else:
                column.append(value)
        self.log_time.append(log_time)
        self.seq.append(msg.get("seq", seq))

    def build(self) -> Track:
        seq = np.frombuffer(self.seq, dtype=np.int64).copy() if len(self.seq) else np.zeros(0, np.int64)
        log_time = np.frombuffer(self.log_time, dtype=np.uint64).copy() if len(self.log_time) else np.zeros(0, np.uint64)
        order = np.argsort(seq, kind="stable")
        fields: dict[str, np.ndarray] = {}
        records = None
        if self.columns is None:
            records = [self.records[i] for i in order]
        else:
            n = seq.size
            for name, (k, width) in self.columns.items():
                if name == "seq":
                    continue
                col = self.data[name]
                if k == "f":
                    a = np.frombuffer(col, dtype=np.float64).copy() if len(col) else np.zeros(0)
                    a = a.reshape(n, width) if width > 1 else a
                elif k == "i":
                    a = np.frombuffer(col, dtype=np.int64).copy() if len(col) else np.zeros(0, np.int64)
                else:
                    a = np.empty(n, dtype=object)
                    a[:] = col
                fields[name] = a[order]
        return Track(self.topic, self.kind, self.schema_name, seq[order], log_time[order], fields, records)


# ------------------------------------------------------------------------------- load


def load(path: str | os.PathLike) -> Run:
    """Read an MCAP file (complete or cut) into a :class:`Run`.

    Raises :class:`RecordingError` ``<path>: not an MCAP file (bad magic)`` for anything
    else, or ``<path>: cannot open: ...`` when it cannot be read.
    """
    for run in _scan(path, None):
        return run
    raise AssertionError("unreachable: _scan yields once without a block size")  # pragma: no cover


def load_blocks(path: str | os.PathLike, block_messages: int = 200_000) -> Iterator[Run]:
    """Read an MCAP file as consecutive :class:`Run` blocks of about ``block_messages``
    messages each (a block ends at a chunk boundary), for work whose memory must not grow
    with the file: a running maximum over a recording, a count.  Each block holds only its
    own messages (tracks sorted by ``seq`` within the block; ``gaps`` of the block alone);
    ``messages``, ``invalid`` and ``corrupt_chunks`` are the block's; ``truncated`` and
    ``truncation`` are filled in on the last block.  Concatenating the blocks' tracks gives
    what :func:`load` gives when the file's chunks are in time order (astrodyn's writer).
    """
    if block_messages < 1:
        raise ValueError(f"block_messages: expected >= 1, got {block_messages}")
    yield from _scan(path, block_messages)


def _scan(path: str | os.PathLike, block_messages: int | None) -> Iterator[Run]:
    """The reader behind :func:`load` (one Run) and :func:`load_blocks` (Runs of about
    ``block_messages`` messages): one walk over the top-level records
    (:func:`read_records`), each handed to a :class:`RecordingScan`; a block ends after
    the chunk that brings it to ``block_messages`` messages."""
    path = os.fspath(path)
    f, size = open_recording(path)
    scan = RecordingScan(path)
    with f:
        for opcode, body, offset in read_records(f, size, path, scan.state):
            chunk_read = scan.read_record(opcode, body, offset)
            if chunk_read and block_messages is not None and scan.counters["messages"] >= block_messages:
                yield scan.run(last=False)
                scan.start_next_block()
    yield scan.run(last=True)


class RecordingScan:
    """What one pass over a recording has gathered so far, and the steps that add to it.

    Schema and Channel records define channels (:meth:`read_schema`, :meth:`read_channel`);
    each Message is decoded and appended to its channel's builder (:meth:`read_message`);
    :meth:`run` turns the builders into a :class:`Run` and :meth:`start_next_block` empties
    them for the next block of :func:`load_blocks`.  Damage is counted, never raised:
    ``counters`` holds ``messages`` (valid ones appended), ``invalid`` (``first_reason``: of
    them, those rejected for the first one's reason), ``corrupt`` (damaged records and
    chunks) and ``orphans`` (messages on a channel never defined); ``notes``
    the lines that become :attr:`Run.truncation`; ``state`` is filled by
    :func:`scan_records` (``truncation``, ``complete``)."""

    __slots__ = ("path", "state", "schemas", "channel_info", "builders", "metadata", "events", "notes",
                 "counters", "examples", "first_reason", "invalid_by_channel", "handlers", "limits")

    def __init__(self, path: str):
        self.path = path
        self.state: dict[str, Any] = {}
        self.schemas: dict[int, tuple[str, dict | None]] = {}
        self.channel_info: dict[int, tuple[str, str | None, _Builder]] = {}
        self.builders: dict[str, _Builder] = {}
        self.metadata: dict[str, dict[str, str]] = {}
        self.events: list[dict] = []
        self.notes: list[str] = []
        self.counters = {"messages": 0, "invalid": 0, "corrupt": 0, "orphans": 0, "first_reason": 0}
        self.examples: list[str] = []
        self.first_reason = ""  # why the first invalid message of the block was rejected
        self.invalid_by_channel: dict[str, int] = {}
        self.handlers = {Schema: self.read_schema, Channel: self.read_channel, Message: self.read_message}
        self.limits = chunk_limits()

    def read_record(self, opcode: int, body: bytes, offset: int) -> bool:
        """Take one top-level record (``offset``: its byte in the file); True when it was a
        chunk whose records were read (the one place a block may end)."""
        try:
            rec = parse_record(opcode, body)
        except Exception as exc:  # a damaged record whose framing is intact
            self.counters["corrupt"] += 1
            self.notes.append(f"damaged {Opcode(opcode).name if opcode in Opcode._value2member_map_ else opcode} record at byte {offset}: {exc}")
            return False
        if rec is None:
            return False
        if isinstance(rec, Chunk):
            return self.read_chunk(rec, offset)
        if isinstance(rec, Metadata):
            self.metadata[rec.name] = dict(rec.metadata)
        else:
            self.handlers[type(rec)](rec)
        return False

    def read_chunk(self, chunk: Chunk, offset: int) -> bool:
        """The records of one chunk (:func:`chunk_records`, within ``limits``); a chunk that
        cannot be opened is counted as corrupt and skipped (False)."""
        try:
            inner = chunk_records(chunk, self.limits)
        except Exception as exc:  # a bomb, zstd error, CRC mismatch, cut inner record
            self.counters["corrupt"] += 1
            self.notes.append(f"corrupt chunk at byte {offset} skipped: {type(exc).__name__}: {exc}")
            return False
        handlers = self.handlers
        for r in inner:
            handlers[type(r)](r)
        return True

    def read_schema(self, rec: Schema) -> None:
        """Keep a schema's name and its JSON Schema (None unless a ``jsonschema`` object)."""
        try:
            data = json.loads(rec.data) if rec.encoding == "jsonschema" and rec.data else None
        except (ValueError, RecursionError):  # not JSON, or nested past the parser's depth
            data = None
        self.schemas[rec.id] = (rec.name, data if isinstance(data, dict) else None)

    def read_channel(self, rec: Channel) -> None:
        """Define a channel (the first definition of an id wins): its astrodyn kind from
        the key (JSON channels only), its columns from astrodyn's own definition on astrodyn
        keys, else from the schema stored in the file; channels of one topic share a builder."""
        if rec.id in self.channel_info:
            return
        name, schema = self.schemas.get(rec.schema_id, ("", None))
        try:
            kind = messages.kind_of_key(rec.topic) if rec.message_encoding == "json" else None
        except messages.MessageError:
            kind = None  # not JSON (e.g. a pickle someone recorded): opaque bytes, never a body's states
        own = messages.schema_for_key(rec.topic) if kind is not None else None
        if own is not None:  # astrodyn's own definition, never the one stored in the file
            name, schema = own
        b = self.builders.get(rec.topic)
        if b is None:
            b = self.builders[rec.topic] = _Builder(rec.topic, kind, name, _columns_for(schema) if rec.message_encoding == "json" else None,
                                                    validated=own is not None)
        self.channel_info[rec.id] = (rec.topic, kind if rec.message_encoding == "json" else None, b)

    def count_invalid(self, topic: str, sequence: int, why: str) -> None:
        """Count one invalid message of ``topic`` (the first :data:`_MAX_EXAMPLES` kept as
        examples; those rejected for the first one's reason counted)."""
        self.counters["invalid"] += 1
        self.invalid_by_channel[topic] = self.invalid_by_channel.get(topic, 0) + 1
        if not self.examples:
            self.first_reason = why
        if why == self.first_reason:
            self.counters["first_reason"] += 1
        if len(self.examples) < _MAX_EXAMPLES:
            self.examples.append(f"{topic} seq {sequence}: {why}")

    def read_message(self, rec: Message) -> None:
        """Decode one message and append it to its channel: astrodyn kinds through
        :func:`astrodyn.messages.decode` (events also to ``events``), other JSON channels
        through ``json``, anything else as bytes; invalid ones are counted, not appended."""
        info = self.channel_info.get(rec.channel_id)
        if info is None:
            self.counters["orphans"] += 1
            return
        topic, kind, b = info
        if kind is not None:
            try:
                msg = messages.decode(rec.data, kind)
            except messages.MessageError as exc:
                self.count_invalid(topic, rec.sequence, str(exc))
                return
            if kind == "event":
                self.events.append(msg)
        else:
            try:
                msg = json.loads(rec.data) if b.columns is not None or b.records is not None else rec.data
            except (ValueError, RecursionError) as exc:  # not JSON, bad UTF-8, nested past the parser's depth
                if b.columns is not None:
                    self.count_invalid(topic, rec.sequence, f"not JSON: {type(exc).__name__}")
                    return
                msg = rec.data
        try:
            if kind is not None and b.validated:
                b.add_validated(msg, rec.sequence, rec.log_time)
            else:
                b.add(msg, rec.sequence, rec.log_time)
        except ValueError as exc:  # violates the schema stored in the file
            self.count_invalid(topic, rec.sequence, str(exc))
            return
        self.counters["messages"] += 1

    def run(self, last: bool) -> Run:
        """The :class:`Run` of what was read since the last block (all of it for
        :func:`load`); ``last``: the file is done, so channels without messages are kept
        and ``truncated`` / ``truncation`` are filled in."""
        counters, notes = self.counters, self.notes
        channels = {topic: b.build() for topic, b in self.builders.items() if last or len(b.seq)}
        bodies, gaps = bodies_and_gaps(channels)
        self.events.sort(key=lambda e: (e["t"], e["process"], e["seq"]))
        if last and counters["orphans"]:
            notes.append(f"{counters['orphans']} messages on channels whose definition was lost")
        if last and "truncation" in self.state:
            notes.insert(0, self.state["truncation"])
        return Run(
            path=self.path,
            scenario=self.metadata.get("scenario", {}),
            metadata=dict(self.metadata),
            bodies=bodies,
            channels=channels,
            events=list(self.events),
            gaps=gaps,
            messages=counters["messages"],
            truncated=not self.state.get("complete", False) if last else False,
            truncation="; ".join(notes) if last else "",
            corrupt_chunks=counters["corrupt"],
            invalid=counters["invalid"],
            invalid_examples=list(self.examples),
            invalid_by_channel=dict(self.invalid_by_channel),
            invalid_first_reason_count=counters["first_reason"],
        )

    def start_next_block(self) -> None:
        """Fresh builders (same channels, no messages) and zeroed block counters, in one
        pass over the channels (not channels^2); ``orphans`` and ``notes`` run on."""
        fresh = {id(b): _Builder(b.topic, b.kind, b.schema_name, b.columns, b.validated) for b in self.builders.values()}
        for topic, b in self.builders.items():
            self.builders[topic] = fresh[id(b)]
        for cid, (t, k, old) in self.channel_info.items():
            self.channel_info[cid] = (t, k, fresh[id(old)])
        self.events.clear()
        self.counters.update(messages=0, invalid=0, corrupt=0, first_reason=0)
        self.examples.clear()
        self.invalid_by_channel.clear()


def bodies_and_gaps(channels: dict[str, Track]) -> tuple[dict[str, BodyTracks], dict[str, dict]]:
    """The state tracks grouped per body (``<scenario>/<body>/<kind>`` keys), and the
    :func:`gap_report` of every channel (of every process on an event channel:
    ``<topic>#<process>``)."""
    bodies: dict[str, BodyTracks] = {}
    gaps: dict[str, dict] = {}
    for topic, track in channels.items():
        if track.kind in messages.STATE_KINDS:
            _, body, kind = messages.parse_key(topic)
            setattr(bodies.setdefault(body, BodyTracks(body)), kind, track)
        if track.kind == "event":
            for process in sorted(set(track.fields["process"])):
                gaps[f"{topic}#{process}"] = gap_report(track.seq[track.fields["process"] == process])
        else:
            gaps[topic] = gap_report(track.seq)
    return bodies, gaps


def main(argv: list[str] | None = None) -> int:  # pragma: no cover - small inspection helper
    """``python -m astrodyn.recording.reader FILE.mcap``: print a one-line JSON summary."""
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 1:
        print("usage: python -m astrodyn.recording.reader FILE.mcap", file=sys.stderr)
        return 2
    try:
        run = load(args[0])
    except RecordingError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    summary = {
        "path": run.path, "messages": run.messages, "truncated": run.truncated, "truncation": run.truncation,
        "channels": {t: len(tr) for t, tr in run.channels.items()},
        "missing": sum(g["missing"] for g in run.gaps.values()), "invalid": run.invalid,
    }
    print(json.dumps(summary))
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())


# --------------------------------------------------------------------------- metadata records, by index


#: Largest metadata record :func:`recorded_metadata` reads (bytes): astrodyn's records hold a
#: config's text and a few numbers; a longer one is not read (treated as absent).
MAX_METADATA_RECORD_BYTES = 16 * 2**20
#: Most summary records :func:`recorded_metadata` walks to find the metadata index of a file
#: whose summary has no offsets section (one per chunk: a file of 10^6 chunks).
MAX_SUMMARY_RECORDS = 2_000_000
#: Most records before the first chunk :func:`recorded_metadata` reads (the logger writes its
#: header, two metadata records and a few schemas and channels there).
MAX_HEAD_RECORDS = 10_000


def recorded_metadata(path: str | os.PathLike, names) -> dict[str, dict[str, str]]:
    """The metadata records of the recording ``path`` named in ``names``: name -> its
    key/value map (the first record of that name), wherever the file keeps them.  Read are
    the records before the first chunk (where astrodyn's logger writes ``scenario`` and
    ``recording``) and, in a file with a footer, the records its summary's metadata index
    points at (every metadata record of a finished file: the logger's ``end``, written
    after the messages, and all of a file ``astrodyn recover`` or ``merge`` wrote, which put
    theirs after the messages).  A cut file (no footer) is read from its head only.

    Bounded whatever the file's size: no chunk is read or decompressed, at most
    :data:`MAX_HEAD_RECORDS` head records and :data:`MAX_SUMMARY_RECORDS` summary records
    are walked, and a record longer than :data:`MAX_METADATA_RECORD_BYTES` is not read.
    Offsets and lengths from the file are checked before use, and a damaged record is
    taken as absent.  :class:`~astrodyn.recording.reader.RecordingError` for a file that
    cannot be opened or is not MCAP."""
    wanted = set(names)
    found: dict[str, dict[str, str]] = {}
    path = os.fspath(path)
    f, size = open_recording(path)
    with f:
        if f.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
            raise RecordingError(f"{path}: not an MCAP file (bad magic)")
        # the records before the first chunk: only metadata bodies are read (a header, schema
        # or channel of any claimed length is skipped with a seek)
        head = _walk(f, len(MCAP_MAGIC), size, {Opcode.METADATA: MAX_METADATA_RECORD_BYTES},
                     stop={Opcode.CHUNK, Opcode.MESSAGE, Opcode.DATA_END, Opcode.FOOTER}, limit=MAX_HEAD_RECORDS)
        for _, body in head:
            rec = _metadata_record(body)
            if rec is not None and rec.name in wanted and rec.name not in found:
                found[rec.name] = dict(rec.metadata)
        if not wanted <= found.keys():
            for name, (offset, length) in _metadata_index(f, size, wanted - found.keys()).items():
                rec = _read_metadata_at(f, offset, length)
                if rec is not None and rec.name == name:
                    found[name] = dict(rec.metadata)
    return found


_RECORD_HEAD = 9  # opcode u8, length u64
_FOOTER_BYTES = _RECORD_HEAD + 20  # summary_start u64, summary_offset_start u64, summary_crc u32


def _metadata_record(body: bytes):
    """The Metadata record of ``body``, None when it does not parse."""
    import io

    from mcap.data_stream import ReadDataStream
    from mcap.records import Metadata

    try:
        return Metadata.read(ReadDataStream(io.BytesIO(body)))
    except Exception:  # damaged content: lengths past the end, invalid UTF-8
        return None


def _read_metadata_at(f, offset: int, length: int):
    """The Metadata record at byte ``offset`` (``length`` bytes with its header), None when
    there is none."""
    import struct

    if length < _RECORD_HEAD or length - _RECORD_HEAD > MAX_METADATA_RECORD_BYTES:
        return None
    f.seek(offset)
    data = f.read(length)
    if len(data) != length:
        return None
    opcode, body_length = struct.unpack_from("<BQ", data)
    if opcode != Opcode.METADATA or body_length != length - _RECORD_HEAD:
        return None
    return _metadata_record(data[_RECORD_HEAD:])


def _metadata_index(f, size: int, names: set[str]) -> dict[str, tuple[int, int]]:
    """name -> ``(offset, length)`` of the first metadata record of each of ``names`` that the
    summary of the file ``f`` (``size`` bytes) indexes; empty for a file without footer or
    summary.  Every offset is checked to lie in the file's data section."""
    import io
    import struct

    from mcap.data_stream import ReadDataStream
    from mcap.records import MetadataIndex

    footer_at = size - len(MCAP_MAGIC) - _FOOTER_BYTES
    if footer_at < len(MCAP_MAGIC):
        return {}
    f.seek(footer_at)
    tail = f.read(_FOOTER_BYTES + len(MCAP_MAGIC))
    if len(tail) != _FOOTER_BYTES + len(MCAP_MAGIC) or tail[_FOOTER_BYTES:] != MCAP_MAGIC:
        return {}
    opcode, length, summary_start, offsets_start = struct.unpack_from("<BQQQ", tail)
    if opcode != Opcode.FOOTER or length != 20 or not len(MCAP_MAGIC) <= summary_start <= footer_at:
        return {}
    summary_end = footer_at
    if offsets_start:
        if not summary_start <= offsets_start <= footer_at:
            return {}
        summary_end = offsets_start
        groups = _walk(f, offsets_start, footer_at, {Opcode.SUMMARY_OFFSET: 64})
        spans = [struct.unpack_from("<BQQ", body) for _, body in groups if len(body) == 17]
        span = next(((start, start + n) for op, start, n in spans if op == Opcode.METADATA_INDEX),
                    (summary_start, summary_end))  # (no offset for that group: the whole summary is walked)
        if not summary_start <= span[0] <= span[1] <= summary_end:
            return {}  # an offset that lies
        begin, end = span
    else:
        begin, end = summary_start, summary_end
    out: dict[str, tuple[int, int]] = {}
    for _, body in _walk(f, begin, end, {Opcode.METADATA_INDEX: 1 << 16}):
        try:
            index = MetadataIndex.read(ReadDataStream(io.BytesIO(body)))
        except Exception:  # a damaged index record: as if absent
            continue
        if index.name in names and index.name not in out and len(MCAP_MAGIC) <= index.offset \
                and index.offset + index.length <= summary_start:
            out[index.name] = (index.offset, index.length)
    return out


def _walk(f, begin: int, end: int, wanted: dict[int, int], stop=frozenset(), limit: int = MAX_SUMMARY_RECORDS):
    """``(opcode, body)`` of each record between bytes ``begin`` and ``end`` whose opcode is
    in ``wanted`` (opcode -> largest body read; longer ones are skipped, and so is every
    other record: a seek past it), over at most ``limit`` records; ends at a record whose
    opcode is in ``stop`` and at one that does not fit (:func:`record_headers`)."""
    for opcode, _, length in record_headers(f, begin, end, limit=limit):
        if opcode in stop:
            return
        if opcode in wanted and length <= wanted[opcode]:
            yield opcode, f.read(length)
