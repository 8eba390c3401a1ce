"""The last few messages of each channel of a recording, in one pass, without decoding JSON.

``astrodyn serve`` restarts a dead logger from this (:mod:`astrodyn.service.supervision`):
where the dead logger's file ends for each state channel, and the last states, are all it
needs, so it reads no more than that.  The walk is the readers' one crash-tolerant walk
(:func:`astrodyn.recording.reader.scan_records`, a file cut anywhere is fine) and the
same untrusting chunk opener (:func:`astrodyn.recording.reader.chunk_records`: size and
ratio limits before decompression, CRC checked); records are cut at their length
prefixes and no payload is parsed, so a pass costs about 1 us per message and memory is
``keep`` payloads per channel, whatever the file's size.  A damaged chunk is skipped (its
messages are not the tail's), a file that is not MCAP raises
:class:`~astrodyn.recording.reader.RecordingError`.
"""

from __future__ import annotations

import os
from collections import deque
from collections.abc import Callable

from mcap.records import Channel, Chunk, Message

from astrodyn.recording.reader import chunk_limits, chunk_records, open_recording, parse_record, scan_records

__all__ = ["channel_tails"]


def channel_tails(path: str | os.PathLike, wanted: Callable[[str], bool], keep: int = 4) -> dict[str, list[bytes]]:
    """topic -> the payloads of its last ``keep`` messages (oldest first), for every
    channel of the file whose topic ``wanted(topic)`` accepts; channels without a message
    are absent.  "Last" is file order, which is arrival order for astrodyn's logger."""
    if keep < 1:
        raise ValueError(f"keep: expected >= 1, got {keep}")
    path = os.fspath(path)
    f, size = open_recording(path)
    topics: dict[int, str | None] = {}  # channel id -> topic (None: not wanted)
    tails: dict[str, deque[bytes]] = {}
    limits = chunk_limits()

    def take(rec: object) -> None:
        if isinstance(rec, Message):
            topic = topics.get(rec.channel_id)
            if topic is not None:
                tail = tails.get(topic)
                if tail is None:
                    tail = tails[topic] = deque(maxlen=keep)
                tail.append(rec.data)
        elif isinstance(rec, Channel) and rec.id not in topics:
            topics[rec.id] = rec.topic if wanted(rec.topic) else None

    with f:
        for opcode, body, _offset, _length in scan_records(f, size, path, {}):
            try:
                rec = parse_record(opcode, body)
                inner = chunk_records(rec, limits) if isinstance(rec, Chunk) else [rec]
            except Exception:  # a damaged record or chunk: not part of any channel's tail
                continue
            for r in inner:
                take(r)
    return {topic: list(tail) for topic, tail in tails.items()}
