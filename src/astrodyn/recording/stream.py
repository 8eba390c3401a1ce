"""Raw messages of an MCAP file in log-time order, chunk by chunk, for replay and export.

>>> with open_stream("demo.mcap") as s:                              # doctest: +SKIP
...     for m in s.messages(topics="astrodyn/demo/*/orbit", start_t=60.0):
...         m.topic, m.log_time, m.data      # str, int ns since the Unix epoch, payload bytes

:func:`astrodyn.recording.load` turns a whole file into arrays; this module hands out
the records themselves (payload bytes untouched) in ``log_time`` order, which is what a
replay needs.  It works on complete files and on files whose writer was killed:

1. *Index pass*: the top-level records are walked by their length prefixes, reading only
   the 28-byte head of each Chunk record (start/end log time) and seeking over its data.
   Metadata, Schema and Channel records outside chunks are read.  The walk stops at the
   footer, or at the first record that does not fit in what is left of the file (a cut
   file: ``truncated`` is set and ``truncation`` says where).  A file that does not start
   with the MCAP magic raises :class:`RecordingError`.
2. *Merge*: chunks sorted by their start time are opened lazily (decompressed, CRC
   checked) only when the merge reaches their start time; one head message per open chunk
   sits in a heap.  Memory is the chunks that overlap the current log time, never the
   file.  A chunk that fails to decompress is skipped and counted in ``corrupt_chunks``.

Ties in ``log_time`` keep file order.  A channel record is looked up when its message is
handed out, not when its chunk is opened, so a channel defined in an earlier chunk (the
astrodyn writer puts each definition in the first chunk that needs it) is always known
by then.  Messages on channels never defined are counted in ``orphans``.

Times: ``start_t`` / ``end_t`` are seconds since the scenario epoch (the ``t`` of the
messages), converted with ``epoch_unix_ns`` of the "recording" metadata record
(``log_time = epoch_unix_ns + round(t * 1e9)``); ``start_ns`` / ``end_ns`` are raw
log times.  The end is inclusive.
"""

from __future__ import annotations

import fnmatch
import heapq
import io
import os
import struct
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Message, Metadata, Schema

from astrodyn.recording.reader import chunk_limits, chunk_records, open_recording, scan_records
from astrodyn.recording.writer import RecordingError

__all__ = ["RawMessage", "McapStream", "open_stream", "topic_matcher", "MAX_T_S"]

#: Largest |t| (s from the scenario epoch) a time given to a stream may have: 1e12 s
#: (~31,700 years) is beyond any recording (scenarios are capped at 250 years) and keeps
#: ``t * 1e9`` ns exact enough and finite.
MAX_T_S = 1e12

_CHUNK_HEAD = struct.Struct("<QQ")  # message_start_time, message_end_time
_UNKNOWN = object()


@dataclass(frozen=True)
class RawMessage:
    """One recorded message: topic, schema name, encoding, times (ns), MCAP sequence, payload."""

    topic: str
    schema_name: str
    message_encoding: str
    log_time: int
    publish_time: int
    sequence: int
    data: bytes


@dataclass
class _ChunkRef:
    start: int
    end: int
    offset: int  # of the record's opcode byte
    length: int  # record body length
    single: Message | None = None  # a top-level (unchunked) message


def topic_matcher(topics: str | Sequence[str] | None):
    """A predicate on topics from shell-style globs (``*`` matches across ``/``); None: all."""
    if topics is None:
        return lambda topic: True
    patterns = [topics] if isinstance(topics, str) else list(topics)
    for p in patterns:
        if not isinstance(p, str) or not p:
            raise ValueError(f"topics: expected non-empty glob strings like 'astrodyn/demo/*/orbit', got {p!r}")
    return lambda topic: any(fnmatch.fnmatchcase(topic, p) for p in patterns)


class McapStream:
    """An indexed MCAP file (see the module docstring); use as a context manager."""

    def __init__(self, path: str | os.PathLike):
        self.path = os.fspath(path)
        self._f, self.size = open_recording(self.path)
        self.schemas: dict[int, Schema] = {}
        self.channels: dict[int, Channel] = {}
        #: name -> key/value map of the metadata records outside chunks: the last of each name
        #: (a file that holds two that differ: :meth:`metadata_conflict`)
        self.metadata: dict[str, dict[str, str]] = {}
        self._first_metadata: dict[str, dict[str, str]] = {}  # name -> its first record
        self._differing_metadata: dict[str, dict[str, str]] = {}  # name -> the first record unlike that
        self.chunks: list[_ChunkRef] = []
        self.truncated = True
        self.truncation = ""
        self.corrupt_chunks = 0
        self.orphans = 0
        self.notes: list[str] = []
        self._limits = chunk_limits()
        try:
            self._index()
        except BaseException:
            self._f.close()
            raise

    # ------------------------------------------------------------------ index pass

    def _index(self) -> None:
        """One pass over the top-level records (:func:`astrodyn.recording.reader.scan_records`,
        reading only each chunk's header): schemas, channels, metadata and where each chunk is."""
        state: dict = {}
        for opcode, body, pos, length in scan_records(self._f, self.size, self.path, state,
                                                      heads={Opcode.CHUNK: _CHUNK_HEAD.size}):
            if opcode == Opcode.CHUNK:
                if length < _CHUNK_HEAD.size:
                    self.notes.append(f"chunk record at byte {pos} too short ({length} bytes), skipped")
                    self.corrupt_chunks += 1
                else:
                    start, end = _CHUNK_HEAD.unpack(body)
                    self.chunks.append(_ChunkRef(start, end, pos, length))
            elif opcode in (Opcode.SCHEMA, Opcode.CHANNEL, Opcode.METADATA, Opcode.MESSAGE):
                try:
                    self._top_level(opcode, body, pos, length)
                except Exception as exc:  # damaged record whose framing is intact
                    self.notes.append(f"damaged {Opcode(opcode).name} record at byte {pos}: {exc}")
        self.truncated = not state.get("complete")
        self.truncation = state.get("truncation", "")

    def _top_level(self, opcode: int, body: bytes, pos: int, length: int) -> None:
        stream = ReadDataStream(io.BytesIO(body))
        if opcode == Opcode.SCHEMA:
            rec = Schema.read(stream)
            self.schemas[rec.id] = rec
        elif opcode == Opcode.CHANNEL:
            rec = Channel.read(stream)
            self.channels.setdefault(rec.id, rec)
        elif opcode == Opcode.METADATA:
            rec = Metadata.read(stream)
            data = self.metadata[rec.name] = dict(rec.metadata)
            first = self._first_metadata.setdefault(rec.name, data)
            if data != first:
                self._differing_metadata.setdefault(rec.name, data)
        else:
            rec = Message.read(stream, len(body))
            self.chunks.append(_ChunkRef(rec.log_time, rec.log_time, pos, length, single=rec))

    def metadata_conflict(self, name: str) -> tuple[dict[str, str], dict[str, str]] | None:
        """``(first, other)`` when the file holds more than one metadata record ``name`` that
        differ: its first, and the first that differs from it (:attr:`metadata` holds the
        last); None when it holds at most one, or copies of one.  Which record counts cannot
        be told then: ``run --commands`` and ``run --resume`` refuse a file whose ``scenario``
        records differ, where :func:`astrodyn.recording.reader.recorded_metadata` (serve)
        reads the first and :func:`astrodyn.recording.load` the last."""
        other = self._differing_metadata.get(name)
        return None if other is None else (self._first_metadata[name], other)

    # ------------------------------------------------------------------ properties

    @property
    def epoch_ns(self) -> int | None:
        """``epoch_unix_ns`` of the "recording" (or "scenario") metadata record, if any: the
        first that is an integer within int64 (log times are uint64 ns; anything else, a
        400-digit number included, is not an epoch)."""
        for name in ("recording", "scenario"):
            raw = self.metadata.get(name, {}).get("epoch_unix_ns")
            if raw is not None:
                try:
                    epoch = int(raw)
                except ValueError:
                    continue
                if -(2**63) <= epoch < 2**63:
                    return epoch
        return None

    @property
    def start_ns(self) -> int | None:
        """Smallest chunk start log time (None for a file without messages)."""
        return min((c.start for c in self.chunks), default=None)

    @property
    def end_ns(self) -> int | None:
        """Largest chunk end log time (None for a file without messages)."""
        return max((c.end for c in self.chunks), default=None)

    def t_to_ns(self, t: float, what: str = "t") -> int:
        """Seconds since the scenario epoch -> log time ns (needs the epoch metadata)."""
        epoch = self.epoch_ns
        if epoch is None:
            raise RecordingError(f"{self.path}: {what}: the file has no epoch_unix_ns metadata, give log times in ns instead")
        if type(t) not in (int, float) or not abs(t) <= MAX_T_S:  # (not a bool; NaN fails the comparison)
            shown = repr(t) if len(repr(t)) <= 40 else repr(t)[:37] + "..."
            raise ValueError(f"{what}: expected a number of seconds since the scenario epoch within +-{MAX_T_S:g}, "
                             f"got {shown}")
        return epoch + round(t * 1e9)

    def ns_to_t(self, ns: int) -> float:
        epoch = self.epoch_ns
        return (ns - (epoch or 0)) / 1e9

    # ------------------------------------------------------------------ merge

    def _open_chunk(self, ref: _ChunkRef) -> list:
        if ref.single is not None:
            return [ref.single]
        self._f.seek(ref.offset + 9)
        body = self._f.read(ref.length)
        try:
            chunk = Chunk.read(ReadDataStream(io.BytesIO(body)))
            records = chunk_records(chunk, self._limits)
        except Exception as exc:  # a bomb, zstd error, CRC mismatch, cut inner record
            self.corrupt_chunks += 1
            self.notes.append(f"corrupt chunk at byte {ref.offset} skipped: {type(exc).__name__}: {exc}")
            return []
        out = []
        for rec in records:
            if isinstance(rec, Message):
                out.append(rec)
            elif isinstance(rec, Schema):
                self.schemas.setdefault(rec.id, rec)
            elif isinstance(rec, Channel):
                self.channels.setdefault(rec.id, rec)
        return out

    def messages(
        self,
        topics: str | Sequence[str] | None = None,
        *,
        start_t: float | None = None,
        end_t: float | None = None,
        start_ns: int | None = None,
        end_ns: int | None = None,
    ) -> Iterator[RawMessage]:
        """Messages with ``start <= log_time <= end`` on matching topics, in log-time order."""
        match = topic_matcher(topics)
        lo = self.t_to_ns(start_t, "start") if start_t is not None else start_ns
        hi = self.t_to_ns(end_t, "end") if end_t is not None else end_ns
        lo = -1 if lo is None else lo
        hi = 2**64 if hi is None else hi
        refs = sorted(
            (c for c in self.chunks if c.end >= lo and c.start <= hi),
            key=lambda c: (c.start, c.offset),
        )
        heap: list = []
        nxt = 0
        cache: dict[int, tuple[str, str, str] | None] = {}
        while True:
            while nxt < len(refs) and (not heap or refs[nxt].start <= heap[0][0]):
                msgs = [m for m in self._open_chunk(refs[nxt]) if lo <= m.log_time <= hi]
                msgs.sort(key=lambda m: m.log_time)  # stable: file order within equal times
                if msgs:
                    it = iter(msgs)
                    first = next(it)
                    heapq.heappush(heap, (first.log_time, nxt, 0, first, it))
                nxt += 1
            if not heap:
                return
            log_time, order, pos, msg, it = heap[0]
            follower = next(it, None)
            if follower is None:
                heapq.heappop(heap)
            else:
                heapq.heapreplace(heap, (follower.log_time, order, pos + 1, follower, it))
            info = cache.get(msg.channel_id, _UNKNOWN)
            if info is _UNKNOWN:
                ch = self.channels.get(msg.channel_id)
                if ch is None:
                    self.orphans += 1
                    continue
                schema = self.schemas.get(ch.schema_id)
                info = cache[msg.channel_id] = (
                    (ch.topic, schema.name if schema is not None else "", ch.message_encoding) if match(ch.topic) else None
                )
            if info is None:
                continue
            yield RawMessage(info[0], info[1], info[2], msg.log_time, msg.publish_time, msg.sequence, msg.data)

    def topics(self) -> list[str]:
        """Topics of the channels known so far (all of them after a full pass or a summary)."""
        return sorted({c.topic for c in self.channels.values()})

    def report(self) -> str:
        """One line: complete, or why not (truncation, corrupt chunks, orphans)."""
        parts = []
        if self.truncated:
            parts.append(f"truncated: {self.truncation}")
        parts += self.notes
        if self.orphans:
            parts.append(f"{self.orphans} messages on channels whose definition was lost")
        return "; ".join(parts) if parts else "complete"

    def close(self) -> None:
        self._f.close()

    def __enter__(self) -> McapStream:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def open_stream(path: str | os.PathLike) -> McapStream:
    """Index ``path`` (a complete or cut MCAP file); :class:`RecordingError` if it is not MCAP."""
    return McapStream(path)
