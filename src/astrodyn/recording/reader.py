"""Read an astrodyn MCAP file into numpy arrays, including files whose writer crashed.

>>> run = load("demo.mcap")                                       # doctest: +SKIP
>>> run.bodies["sat1"].orbit.r.shape        # (n, 3) metres, frame in .frame
>>> run.bodies["sat1"].attitude.q           # (n, 4) Euler parameters, scalar first
>>> run.scenario                            # the "scenario" metadata record (str -> str)
>>> run.truncated, run.truncation           # True and why, for a file without footer
>>> run.gaps["astrodyn/demo/sat1/orbit"]    # count, missing, gaps, duplicates

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
import struct
import sys
from array import array
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any, BinaryIO

import numpy as np
from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Message, Metadata, Schema
from mcap.stream_reader import breakup_chunk

from astrodyn import messages
from astrodyn.recording.writer import RecordingError

__all__ = ["load", "Run", "BodyTracks", "Body", "Track", "gap_report", "MCAP_MAGIC"]

MCAP_MAGIC = b"\x89MCAP0\r\n"
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


class Track:
    """The messages of one channel as arrays, sorted by seq.

    Always: ``topic``, ``kind``, ``schema_name``, ``seq`` (int64), ``log_time`` (int64 ns
    since the Unix epoch) and, for astrodyn kinds, ``t`` (s since the scenario epoch).
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
    """The tracks of one body: ``orbit``, ``attitude``, ``crosscheck`` (None if absent)."""

    name: str
    orbit: Track | None = None
    attitude: Track | None = None
    crosscheck: Track | None = None


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

    @property
    def complete(self) -> bool:
        """True for a finished file with every record intact and every message valid."""
        return not self.truncated and self.corrupt_chunks == 0 and self.invalid == 0

    def __repr__(self) -> str:
        """One line: file, scenario, bodies, channels, span of t, messages, state.  The
        config as run is one attribute away (``run.scenario``), not printed."""
        ts = [tr.fields["t"] for tr in self.channels.values() if "t" in tr.fields and len(tr)]
        span = f", t {min(float(t.min()) for t in ts):.6g}..{max(float(t.max()) for t in ts):.6g} s" if ts else ""
        names = list(self.bodies)
        shown = ", ".join(names[:5]) + (f", ... ({len(names)} in all)" if len(names) > 5 else "")
        state = "complete" if self.complete else f"incomplete: {self.truncation or f'{self.invalid} invalid messages'}"
        return (f"Run({os.path.basename(self.path)!r}, scenario {self.scenario.get('name', '?')!r}, bodies [{shown}], "
                f"{len(self.channels)} channels{span}, {self.messages} messages, {state})")


# ------------------------------------------------------------------------------- scanning


class _Truncated(Exception):
    pass


def read_records(f: BinaryIO, size: int, path: str, state: dict) -> Iterator[tuple[int, bytes, int]]:
    """Yield (opcode, body, offset) of each complete top-level record up to the footer."""
    head = f.read(8)
    if head != MCAP_MAGIC:
        if size == 0:
            raise RecordingError(f"{path}: not an MCAP file (empty file)")
        if len(head) < 8 and MCAP_MAGIC.startswith(head):
            state["truncation"] = f"file ends inside the opening magic ({size} bytes)"
            return
        raise RecordingError(f"{path}: not an MCAP file (bad magic)")
    pos = 8
    while True:
        if pos == size:
            state["truncation"] = f"file ends at byte {pos} without data end and footer (writer did not finish)"
            return
        if size - pos < 9:
            state["truncation"] = f"file ends inside a record header at byte {pos}"
            return
        opcode, length = _HEADER.unpack(f.read(9))
        if length > size - pos - 9:
            name = Opcode(opcode).name if opcode in Opcode._value2member_map_ else f"opcode {opcode:#x}"
            state["truncation"] = (
                f"{name} record at byte {pos} needs {length} bytes, only {size - pos - 9} left (cut or corrupt)"
            )
            return
        body = f.read(length)
        yield opcode, body, pos
        pos += 9 + length
        if opcode == Opcode.FOOTER:
            if f.read(8) != MCAP_MAGIC:
                state["truncation"] = "footer not followed by the closing magic"
            else:
                state["complete"] = True
            return


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


def _columns_for(schema: dict | None) -> dict[str, tuple[str, int]] | None:
    """field -> (kind, width) from a JSON Schema: ("f", 1) float, ("i", 1) int, ("f", k) vector, ("s", 0) string."""
    if not schema or "properties" not in schema:
        return None
    out = {}
    for name, prop in schema["properties"].items():
        typ = prop.get("type")
        if typ == "number":
            out[name] = ("f", 1)
        elif typ == "integer":
            out[name] = ("i", 1)
        elif typ == "array" and prop.get("minItems") == prop.get("maxItems") and prop.get("items", {}).get("type") == "number":
            out[name] = ("f", int(prop["minItems"]))
        elif typ == "string" or "enum" in prop:
            out[name] = ("s", 0)
        else:
            out[name] = ("o", 0)
    return out


class _Builder:
    __slots__ = ("topic", "kind", "schema_name", "columns", "seq", "log_time", "data", "records", "strings")

    def __init__(self, topic: str, kind: str | None, schema_name: str, columns: dict | None):
        self.topic, self.kind, self.schema_name, self.columns = topic, kind, schema_name, columns
        self.seq, self.log_time = array("q"), array("q")
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

    def add(self, msg: dict, seq: int, log_time: int) -> None:
        self.log_time.append(log_time)
        if self.columns is None:
            self.seq.append(int(msg["seq"]) if isinstance(msg, dict) and isinstance(msg.get("seq"), int) else seq)
            self.records.append(msg)
            return
        self.seq.append(msg["seq"] if "seq" in msg else seq)
        strings = self.strings
        for name, (k, width) in self.columns.items():
            value = msg.get(name)
            col = self.data[name]
            if k == "f":
                if width == 1:
                    col.append(float("nan") if value is None else value)
                else:
                    col.extend(value if value is not None else [float("nan")] * width)
            elif k == "i":
                col.append(-1 if value is None else value)
            elif k == "s":
                col.append(None if value is None else strings.setdefault(value, value))
            else:
                col.append(value)

    def build(self) -> Track:
        seq = np.frombuffer(self.seq, dtype=np.int64).copy() if len(self.seq) else np.zeros(0, np.int64)
        log_time = np.frombuffer(self.log_time, dtype=np.int64).copy() if len(self.log_time) else np.zeros(0, np.int64)
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
    path = os.fspath(path)
    try:
        f = open(path, "rb")
        size = os.fstat(f.fileno()).st_size
    except OSError as exc:
        raise RecordingError(f"{path}: cannot open: {exc.strerror or exc}") from None
    state: dict[str, Any] = {}
    schemas: dict[int, tuple[str, dict | None]] = {}
    channel_info: dict[int, tuple[str, str | None, _Builder]] = {}
    builders: dict[str, _Builder] = {}
    metadata: dict[str, dict[str, str]] = {}
    events: list[dict] = []
    notes: list[str] = []
    counters = {"messages": 0, "invalid": 0, "corrupt": 0, "orphans": 0}
    examples: list[str] = []

    def on_schema(rec: Schema) -> None:
        try:
            data = json.loads(rec.data) if rec.encoding == "jsonschema" and rec.data else None
        except ValueError:
            data = None
        schemas[rec.id] = (rec.name, data if isinstance(data, dict) else None)

    def on_channel(rec: Channel) -> None:
        if rec.id in channel_info:
            return
        name, schema = schemas.get(rec.schema_id, ("", None))
        try:
            kind = messages.kind_of_key(rec.topic) if rec.message_encoding == "json" else None
        except messages.MessageError:
            kind = None  # not JSON (e.g. a pickle someone recorded): opaque bytes, never a body's states
        b = builders.get(rec.topic)
        if b is None:
            b = builders[rec.topic] = _Builder(rec.topic, kind, name, _columns_for(schema) if rec.message_encoding == "json" else None)
        channel_info[rec.id] = (rec.topic, kind if rec.message_encoding == "json" else None, b)

    def on_message(rec: Message) -> None:
        info = channel_info.get(rec.channel_id)
        if info is None:
            counters["orphans"] += 1
            return
        topic, kind, b = info
        if kind is not None:
            try:
                msg = messages.decode(rec.data, kind)
            except messages.MessageError as exc:
                counters["invalid"] += 1
                if len(examples) < _MAX_EXAMPLES:
                    examples.append(f"{topic} seq {rec.sequence}: {exc}")
                return
            if kind == "event":
                events.append(msg)
        else:
            try:
                msg = json.loads(rec.data) if b.columns is not None or b.records is not None else rec.data
            except ValueError:
                msg = rec.data
        counters["messages"] += 1
        b.add(msg, rec.sequence, rec.log_time)

    handlers = {Schema: on_schema, Channel: on_channel, Message: on_message}
    with f:
        for opcode, body, offset in read_records(f, size, path, state):
            try:
                rec = parse_record(opcode, body)
            except Exception as exc:  # a damaged record whose framing is intact
                counters["corrupt"] += 1
                notes.append(f"damaged {Opcode(opcode).name if opcode in Opcode._value2member_map_ else opcode} record at byte {offset}: {exc}")
                continue
            if rec is None:
                continue
            if isinstance(rec, Chunk):
                try:
                    inner = breakup_chunk(rec, validate_crc=True)
                except Exception as exc:  # zstd error, CRC mismatch, cut inner record
                    counters["corrupt"] += 1
                    notes.append(f"corrupt chunk at byte {offset} skipped: {type(exc).__name__}: {exc}")
                    continue
                for r in inner:
                    handlers[type(r)](r)
            elif isinstance(rec, Metadata):
                metadata[rec.name] = dict(rec.metadata)
            else:
                handlers[type(rec)](rec)

    channels = {topic: b.build() for topic, b in builders.items()}
    bodies: dict[str, BodyTracks] = {}
    gaps: dict[str, dict] = {}
    for topic, track in channels.items():
        if track.kind in ("orbit", "attitude", "crosscheck"):
            _, body, kind = messages.parse_key(topic)
            setattr(bodies.setdefault(body, BodyTracks(body)), kind, track)
        if track.kind == "event":
            for process in sorted(set(track.fields["process"])):
                gaps[f"{topic}#{process}"] = gap_report(track.seq[track.fields["process"] == process])
        else:
            gaps[topic] = gap_report(track.seq)
    events.sort(key=lambda e: (e["t"], e["process"], e["seq"]))
    if counters["orphans"]:
        notes.append(f"{counters['orphans']} messages on channels whose definition was lost")
    truncated = not state.get("complete", False)
    if "truncation" in state:
        notes.insert(0, state["truncation"])
    return Run(
        path=path,
        scenario=metadata.get("scenario", {}),
        metadata=metadata,
        bodies=bodies,
        channels=channels,
        events=events,
        gaps=gaps,
        messages=counters["messages"],
        truncated=truncated,
        truncation="; ".join(notes),
        corrupt_chunks=counters["corrupt"],
        invalid=counters["invalid"],
        invalid_examples=examples,
    )


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
