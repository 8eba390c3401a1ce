"""MCAP recording: write (:class:`McapRecorder`), read (:func:`load`), and the logger process.

* :mod:`astrodyn.recording.writer`  -- :class:`McapRecorder`, :class:`SeqTracker`, :class:`RecordingError`
* :mod:`astrodyn.recording.reader`  -- :func:`load` -> :class:`Run` (numpy arrays per body, metadata,
  gap report; reads files cut by a crash up to the last complete record)
* :mod:`astrodyn.service.logger`  -- the logger process (Zenoh -> MCAP), ``services/logger.py``

File layout and crash behaviour: :mod:`astrodyn.recording.writer`.
"""

from astrodyn.recording.reader import Body, BodyTracks, Run, Track, gap_report, load, load_blocks
from astrodyn.recording.writer import DUPLICATE, GAP, LATE, OK, McapRecorder, RecordingError, SeqTracker

__all__ = [
    "McapRecorder", "RecordingError", "SeqTracker", "OK", "GAP", "LATE", "DUPLICATE",
    "load", "load_blocks", "Run", "BodyTracks", "Body", "Track", "gap_report",
]
