"""MCAP recorder: one channel per key, JSON Schema schemas, zstd chunks, crash-safe flushing.

File layout (docs/architecture.md, section 5)::

    topic            the Zenoh key, e.g. astrodyn/<scenario>/<body>/orbit
    message encoding "json"      (the payload exactly as it travelled on the bus)
    schema           encoding "jsonschema", name and data from astrodyn.messages.schema_for_key
    log_time         epoch_ns + round(t * 1e9): integer ns since the Unix epoch, where
                     epoch_ns is the scenario epoch as Unix ns (converted at the config edge)
    publish_time     when the logger received it (Unix ns, wall clock); log_time by default
    sequence         the message's seq modulo 2**32 (MCAP's field is uint32; the payload
                     holds the full seq)
    metadata         "scenario": the config as run (values are strings; non-strings JSON);
                     "recording": epoch_unix_ns, the log_time rule, astrodyn version

Crash safety (measured on mcap 1.6.0): a writer killed without ``flush()`` loses its whole
open chunk.  :class:`McapRecorder` calls ``flush()`` (closes the chunk and hands the bytes
to the OS) at least every ``flush_interval_s`` while messages arrive (and from
:meth:`McapRecorder.maybe_flush` when idle), so a SIGKILL loses at most the messages of
the last ``flush_interval_s`` (and never more than one ``chunk_size`` of data).  The OS
keeps what was flushed even when the process is killed; only a power loss needs ``fsync``,
done at :meth:`McapRecorder.close`.

The file is written in place at ``path`` (no ``.part`` + rename): a crashed writer leaves
a file without summary and footer, which is its own mark of incompleteness -- the seeking
MCAP reader refuses it, :func:`astrodyn.recording.load` reads every complete chunk and
reports ``truncated``, and ``astrodyn recover`` rewrites it with a summary.  Keeping the
requested name means the data is where the user asked for it after any crash.

Seq accounting (:class:`SeqTracker`): per channel, a message whose seq is the next one is
``OK``; a jump ahead opens a gap (``GAP``, recorded); a message filling a gap is ``LATE``
(recorded, counted as out of order); a seq already recorded is a ``DUPLICATE`` (counted,
not recorded: the first message with a seq wins).
"""

from __future__ import annotations

import errno
import fcntl
import json
import operator
import os
import re
import time
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from astrodyn import __version__, messages
from astrodyn.recording import ingest
from astrodyn.recording.chunked_writer import ChunkedWriter

__all__ = ["RecordingError", "McapRecorder", "being_written", "partial_path", "is_partial_path", "part_path", "standby_path", "fsync_directory", "link_new", "clash_name", "BatchLayout", "SeqTracker", "OK", "GAP", "LATE", "DUPLICATE"]

OK, GAP, LATE, DUPLICATE = 0, 1, 2, 3
_STATUS_NAMES = ("ok", "gap", "late", "duplicate")
_U32 = 0xFFFFFFFF
#: Channels one MCAP file can hold (channel ids are uint16; id 0 is never used by the writer).
MAX_CHANNELS = 65535
_U64_END = 2**64
INGEST_GRAMMAR = ingest.grammar_tables(messages.ORBIT_MODELS, messages.ATTITUDE_MODELS)


class RecordingError(Exception):
    """An MCAP file cannot be written or read; the text starts with the path."""


def _tracker_slot(view: str, doc: str) -> property:
    """A read-write property: the element at the channel's ``slot`` of its tracker's
    memoryview named ``view``."""
    get_view = operator.attrgetter(view)

    def fget(self) -> int:
        return get_view(self.tracker)[self.slot]

    def fset(self, value: int) -> None:
        get_view(self.tracker)[self.slot] = value

    return property(fget, fset, doc=doc)


class _ChannelSeq:
    """One channel's seq accounting; ``next`` and ``count`` live in the tracker's arrays
    (slot ``slot``) so the compiled batch ingest (:mod:`astrodyn.recording.ingest`) can
    advance them for in-order messages."""

    __slots__ = ("tracker", "slot", "missing", "duplicates", "out_of_order", "gaps", "gaps_truncated", "seeded_below",
                 "already_recorded", "gaps_expected")

    def __init__(self, tracker: SeqTracker, slot: int) -> None:
        self.tracker = tracker
        self.slot = slot
        self.missing = 0
        self.duplicates = 0
        self.out_of_order = 0
        self.gaps: list[list[int]] = []  # sorted, disjoint inclusive [first, last] missing ranges
        self.gaps_truncated = False
        self.seeded_below = 0  # seqs below this are in an earlier part (seed)
        self.already_recorded = 0  # arrivals below seeded_below: dropped, not duplicates
        self.gaps_expected = False  # its gaps are not losses (SeqTracker.expect_gaps)

    next = _tracker_slot("_next_view", "The next seq expected (int): the tracker's ``next_seq[slot]``.")
    count = _tracker_slot("_count_view", "Messages recorded (int): the tracker's ``counts[slot]``.")


def being_written(path: str | os.PathLike) -> bool:
    """Whether a live process is writing the recording ``path``: a :class:`McapRecorder`
    holds an exclusive ``flock`` on each file it writes until it closes it or ends (killed
    or not: the kernel releases it).  False for a missing or unreadable file; on a file
    system without ``flock`` a recorder's file reads as not being written."""
    try:
        fd = os.open(os.fspath(path), os.O_RDONLY | os.O_NONBLOCK)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    except OSError:
        return False
    finally:
        os.close(fd)  # (closing the descriptor releases a lock taken here)
    return False


class SeqTracker:
    """Per-channel accounting of ``seq``: gaps, duplicates, out-of-order arrivals.

    :meth:`add` returns ``OK``, ``GAP``, ``LATE`` or ``DUPLICATE`` (see the module
    docstring).  Missing ranges are kept for the first ``max_gaps`` gaps per channel; the
    counts are always exact for an arrival order where late messages fill stored gaps.
    Each channel has a slot (:meth:`slot`) in the int64 arrays ``next_seq`` and
    ``counts``; the compiled batch ingest advances those for in-order messages only.
    """

    def __init__(self, max_gaps: int = 1000):
        self.max_gaps = int(max_gaps)
        self.channels: dict[str, _ChannelSeq] = {}
        self._set_arrays(np.zeros(64, dtype=np.int64), np.zeros(64, dtype=np.int64))

    def _set_arrays(self, next_seq: np.ndarray, counts: np.ndarray) -> None:
        self.next_seq, self.counts = next_seq, counts
        # memoryviews: element access from Python at list speed (numpy scalars are ~3x slower)
        self._next_view, self._count_view = memoryview(next_seq), memoryview(counts)

    def _channel(self, channel: str) -> _ChannelSeq:
        c = self.channels.get(channel)
        if c is None:
            slot = len(self.channels)
            if slot == self.next_seq.shape[0]:  # grow both arrays (callers re-read them)
                self._set_arrays(np.concatenate([self.next_seq, np.zeros(slot, dtype=np.int64)]),
                                 np.concatenate([self.counts, np.zeros(slot, dtype=np.int64)]))
            c = self.channels[channel] = _ChannelSeq(self, slot)
        return c

    def slot(self, channel: str) -> int:
        """The channel's index into ``next_seq`` / ``counts`` (created on first use)."""
        return self._channel(channel).slot

    def seed(self, channel: str, next_seq: int) -> None:
        """Start ``channel`` at ``next_seq``: its seqs below are already recorded elsewhere
        (a restarted logger's earlier part).  Arrivals below it are dropped as ``DUPLICATE``
        and counted as ``already_recorded``, not as duplicates; no gap is counted before it."""
        if not (isinstance(next_seq, int) and next_seq >= 0):
            raise ValueError(f"{channel}: expected a seq >= 0 to start from, got {next_seq!r}")
        c = self._channel(channel)
        if c.count or c.missing:
            raise ValueError(f"{channel}: already has messages; seed before recording")
        self._next_view[c.slot] = next_seq
        c.seeded_below = next_seq

    def expect_gaps(self, channel: str) -> None:
        """Gaps on ``channel`` are not losses: it records a selection of a sender's messages
        (the commands the plant applied, each with its sender's seq; refused ones are not
        re-published).  Its gaps stay in :meth:`report`; :meth:`totals` leaves them out of
        ``missing`` and counts them as ``skipped``."""
        self._channel(channel).gaps_expected = True

    def add(self, channel: str, seq: int) -> int:
        c = self.channels.get(channel)
        if c is None:
            c = self._channel(channel)
        slot = c.slot
        nxt = self._next_view[slot]
        if seq == nxt:
            self._next_view[slot] = nxt + 1
            self._count_view[slot] += 1
            return OK
        if seq > nxt:
            c.missing += seq - nxt
            if len(c.gaps) < self.max_gaps:
                c.gaps.append([nxt, seq - 1])
            else:
                c.gaps_truncated = True
            c.next = seq + 1
            c.count += 1
            return GAP
        for i, (first, last) in enumerate(c.gaps):
            if first <= seq <= last:
                if first == last:
                    del c.gaps[i]
                elif seq == first:
                    c.gaps[i][0] = seq + 1
                elif seq == last:
                    c.gaps[i][1] = seq - 1
                else:
                    c.gaps[i : i + 1] = [[first, seq - 1], [seq + 1, last]]
                c.missing -= 1
                c.out_of_order += 1
                c.count += 1
                return LATE
            if first > seq:
                break
        if seq < c.seeded_below:
            c.already_recorded += 1
        else:
            c.duplicates += 1
        return DUPLICATE

    def totals(self) -> dict[str, int]:
        """Sums over channels: count, missing, duplicates, out_of_order, already_recorded;
        ``skipped``: the gaps of channels whose gaps are expected (:meth:`expect_gaps`), not
        in ``missing``."""
        out = {"count": 0, "missing": 0, "duplicates": 0, "out_of_order": 0, "already_recorded": 0, "skipped": 0}
        for c in self.channels.values():
            out["already_recorded"] += c.already_recorded
            out["count"] += c.count
            out["skipped" if c.gaps_expected else "missing"] += c.missing
            out["duplicates"] += c.duplicates
            out["out_of_order"] += c.out_of_order
        return out

    def report(self) -> dict[str, dict]:
        """Per channel: count, next_seq, missing, gaps [[first, last], ...], duplicates, out_of_order."""
        return {
            name: {
                "count": c.count,
                "next_seq": c.next,
                "missing": c.missing,
                "gaps": [list(g) for g in c.gaps],
                "gaps_truncated": c.gaps_truncated,
                "duplicates": c.duplicates,
                "out_of_order": c.out_of_order,
            }
            for name, c in self.channels.items()
        }


def partial_path(path: str | os.PathLike, attempt: int = 0) -> str:
    """Where a recording is written until it is finished: ``NAME.partial.mcap`` for
    ``NAME.mcap`` (``NAME.partial-N.mcap`` for the N-th restarted logger of a run).  A file
    with this name is what a killed run leaves; ``astrodyn recover`` finishes it."""
    root, ext = os.path.splitext(os.fspath(path))
    return f"{root}.partial{'' if attempt == 0 else f'-{attempt}'}{ext or '.mcap'}"


def is_partial_path(path: str | os.PathLike) -> bool:
    """Whether ``path`` is named like an unfinished recording (:func:`partial_path`:
    ``NAME.partial.mcap``, ``NAME.partial-N.mcap``)."""
    root, _ = os.path.splitext(os.path.basename(os.fspath(path)))
    return re.search(r"\.partial(-[1-9][0-9]*)?$", root) is not None


def part_path(path: str | os.PathLike, part: int) -> str:
    """The name of rolled part ``part`` of the recording ``path``: ``path`` itself for 0,
    ``NAME-0001.mcap``, ``NAME-0002.mcap``, ... after it."""
    if part == 0:
        return os.fspath(path)
    root, ext = os.path.splitext(os.fspath(path))
    return f"{root}-{part:04d}{ext or '.mcap'}"


def standby_path(path: str | os.PathLike, k: int) -> str:
    """The recording of standby logger ``k`` (2, 3, ...) of the run recorded at ``path``:
    ``NAME.logger-k.mcap`` beside ``NAME.mcap`` (``--loggers N``)."""
    if not (isinstance(k, int) and k >= 2):
        raise ValueError(f"k: expected a standby number >= 2, got {k!r}")
    root, ext = os.path.splitext(os.fspath(path))
    return f"{root}.logger-{k}{ext or '.mcap'}"


def fsync_directory(path: str | os.PathLike) -> None:
    """fsync the directory holding ``path`` (a rename survives a power cut only then)."""
    try:
        fd = os.open(os.path.dirname(os.path.abspath(path)) or ".", os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


#: errnos of a file system that cannot make hard links (FAT, some network and FUSE ones)
_NO_HARD_LINKS = {errno.EPERM, errno.EOPNOTSUPP, errno.ENOTSUP, errno.ENOSYS, errno.EMLINK, errno.EXDEV}


def link_new(src: str | os.PathLike, dst: str | os.PathLike) -> bool:
    """Give the finished file ``src`` the name ``dst`` unless ``dst`` exists (any file,
    a dangling link included): True when ``src`` now has the name ``dst`` (``src`` itself
    is then gone), False when ``dst`` was taken (both untouched).  Never replaces what is
    at ``dst``: a hard link, which the kernel makes only if the name is free, then the
    unlink of ``src``; the directory is fsynced.  On a file system without hard links
    the name is checked just before a rename (a narrow window remains there).  An
    OSError for anything else (the directory gone, no permission)."""
    src, dst = os.fspath(src), os.fspath(dst)
    try:
        os.link(src, dst)
    except FileExistsError:
        return False
    except OSError as exc:
        if exc.errno not in _NO_HARD_LINKS:
            raise
        if os.path.lexists(dst):
            return False
        os.rename(src, dst)
    else:
        os.unlink(src)
    fsync_directory(dst)
    return True


def clash_name(path: str | os.PathLike, n: int) -> str:
    """Where a finished file goes when its own name ``path`` is taken by a file that must
    not be replaced: ``NAME.clash-<n>.mcap`` beside ``NAME.mcap`` (a name no part,
    partial or standby pattern matches)."""
    root, ext = os.path.splitext(os.fspath(path))
    return f"{root}.clash-{n}{ext or '.mcap'}"


#: how many ``clash_name`` numbers are tried before a part keeps its partial name
MAX_CLASH_NAMES = 100


def _metadata_strings(name: str, data: Mapping[str, Any]) -> dict[str, str]:
    if not isinstance(data, Mapping):
        raise TypeError(f"{name}: expected a dict of metadata, got {type(data).__name__}")
    out = {}
    for key, value in data.items():
        if not isinstance(key, str):
            raise TypeError(f"{name}: expected string keys, got {key!r}")
        out[key] = value if isinstance(value, str) else json.dumps(value, sort_keys=True)
    return out


class BatchLayout:
    """The keys of one publisher's envelopes, resolved to channels once per file.

    ``keys`` in envelope order; ``kinds`` (int8, :data:`astrodyn.recording.ingest.KIND_*`)
    says which entries the compiled path may take (canonical orbit / attitude states on
    known keys); :meth:`resolve` fills ``cids`` (MCAP channel ids of the current file,
    registering them) and ``slots`` (:meth:`SeqTracker.slot`).  ``blob``/``blob_start``/
    ``blob_len`` hold the key bytes, to recognise the next envelope with the same keys
    (:func:`astrodyn.recording.ingest.same_keys`).
    """

    def __init__(self, keys: list[str], kinds: np.ndarray):
        self.keys = keys
        self.kinds = np.ascontiguousarray(kinds, dtype=np.int8)
        raw = [k.encode("utf-8") for k in keys]
        self.blob = np.frombuffer(b"".join(raw), dtype=np.uint8).copy() if raw else np.zeros(0, np.uint8)
        self.blob_len = np.array([len(k) for k in raw], dtype=np.int64)
        self.blob_start = np.concatenate([[0], np.cumsum(self.blob_len)[:-1]]).astype(np.int64) if raw else np.zeros(0, np.int64)
        self.cids = np.zeros(len(keys), dtype=np.int64)
        self.slots = np.zeros(len(keys), dtype=np.int64)
        self.writer = None

    def resolve(self, recorder: McapRecorder) -> None:
        for i, key in enumerate(self.keys):
            if self.kinds[i] == ingest.KIND_OTHER:
                continue
            cid = recorder._channels.get(key)
            if cid is None:
                cid = recorder._channel_for(key)
            self.cids[i] = cid
            self.slots[i] = recorder.seq.slot(key)
        self.writer = recorder._writer


class McapRecorder:
    """Write astrodyn messages to an MCAP file (layout and crash behaviour: module docstring).

    Parameters
    ----------
    path : output file (created or overwritten).
    scenario_metadata : dict written as the "scenario" metadata record (string values kept,
        other values JSON-encoded).
    epoch_ns : the scenario epoch as integer ns since the Unix epoch (``log_time`` origin).
    chunk_size : uncompressed bytes per zstd chunk (1 MiB default).
    flush_interval_s : longest time (s) between flushes while messages arrive; bounds what
        a SIGKILL can lose.
    roll_size, roll_interval_s : for long runs (``astrodyn serve``): finish the file and
        continue in ``<stem>-0001.mcap``, ``<stem>-0002.mcap``, ... once it holds
        ``roll_size`` bytes (checked at each write: a part passes it by less than one
        compressed chunk) or is ``roll_interval_s`` old (checked at each flush).  Every
        finished part is a complete MCAP with both metadata records; seq accounting spans
        all parts; ``paths`` lists them.  A part never replaces a file of its name (an
        earlier session's part): it is kept as ``NAME-000k.clash-1.mcap`` instead
        (:func:`clash_name`; its partial name when 100 such names are taken) and
        :attr:`parts_kept_aside` (``stats()["parts_kept_aside"]``) lists it, so that the
        caller can say so; the earlier file is untouched.
    atomic : write each file as :func:`partial_path` (``NAME.partial.mcap``) and rename it
        to its name only once it is finished, so a failed or killed run never destroys
        the previous recording of that name (the logger of ``run`` / ``serve`` does this).
    first_part, attempt : for a restarted logger (``serve``): number its parts from
        ``first_part`` and name its partial files ``NAME.partial-<attempt>.mcap``.  A rolled
        part (any but the first file of a run: part k >= 1) whose partial name is taken
        (another recorder's live file that happens to have that name, a killed run's) is
        written as the partial file of a :func:`clash_name` instead
        (``NAME-000k.clash-1.partial.mcap``), listed in :attr:`parts_kept_aside`; the file
        in the way is never touched.  The first file of a run is never clash-named: its
        name is the user's ``--out``, and a file in the way of it is an error naming it.
    on_file : ``on_file(path, (st_dev, st_ino))``, called when a file is created (its
        writing path, before anything but its headers is in it) and when a finished part
        takes its name (same identity, new path): how a supervisor knows which files are
        this recorder's own (:class:`astrodyn.service.supervision.LoggerFiles`).

    Errors: :class:`RecordingError` naming the path for an unwritable path, a full disk or
    any other write failure; after such an error the file is left without footer (it does
    not claim to be complete) and further writes raise again.  Use as a context manager:
    the file is finished (summary, indexes, footer) on exit, also on an exception raised
    by the caller.
    """

    def __init__(
        self,
        path: str | os.PathLike,
        scenario_metadata: Mapping[str, Any],
        *,
        epoch_ns: int,
        chunk_size: int = 1 << 20,
        flush_interval_s: float = 1.0,
        roll_size: int | None = None,
        roll_interval_s: float | None = None,
        atomic: bool = False,
        first_part: int = 0,
        attempt: int = 0,
        on_file: Callable[[str, tuple[int, int]], None] | None = None,
    ):
        self.path = os.fspath(path)
        self._on_file = on_file
        self._identity: tuple[int, int] | None = None
        if not (isinstance(first_part, int) and first_part >= 0 and isinstance(attempt, int) and attempt >= 0):
            raise ValueError(f"first_part, attempt: expected integers >= 0, got {first_part!r}, {attempt!r}")
        self.atomic = bool(atomic)
        self.attempt = attempt
        self._base = self.path
        self._first_part = first_part
        if isinstance(epoch_ns, bool) or not isinstance(epoch_ns, int):
            raise TypeError(f"epoch_ns: expected an integer (ns since the Unix epoch), got {epoch_ns!r}")
        if not (isinstance(chunk_size, int) and chunk_size > 0):
            raise ValueError(f"chunk_size: expected a positive integer number of bytes, got {chunk_size!r}")
        if not (flush_interval_s > 0):
            raise ValueError(f"flush_interval_s: expected > 0 s, got {flush_interval_s!r}")
        if roll_size is not None and not (isinstance(roll_size, int) and roll_size > 0):
            raise ValueError(f"roll_size: expected a positive integer number of bytes, got {roll_size!r}")
        if roll_interval_s is not None and not (roll_interval_s > 0):
            raise ValueError(f"roll_interval_s: expected > 0 s, got {roll_interval_s!r}")
        self.epoch_ns = epoch_ns
        self.flush_interval_s = float(flush_interval_s)
        self.chunk_size = chunk_size
        self.roll_size = roll_size
        self.roll_interval_s = roll_interval_s
        self.seq = SeqTracker()
        self.message_count = 0
        self.flushes = 0
        self.closed = False
        self.paths: list[str] = []  # every file written, in order (more than one when rolling)
        #: rolled parts whose own name was taken by an existing file (an earlier session's
        #: part), which was left as it was: [{"part": its name, "file": where it is, "why"}]
        self.parts_kept_aside: list[dict[str, str]] = []
        self._error: RecordingError | None = None
        self._scenario = _metadata_strings("scenario_metadata", scenario_metadata)
        # write_batch's t cache: the text of the last t, its float and its log_time
        self._t_text = np.zeros(0, dtype=np.uint8)
        self._t_value = 0.0
        self._t_log_time = 0
        self._open(self._roll_path(first_part) if first_part else self.path)

    def _open(self, path: str) -> None:
        """Start a new file at ``path`` with both metadata records (channels are re-registered lazily).

        With ``atomic`` the bytes go to :func:`partial_path` of ``path`` and the file takes
        its name only when finished (:meth:`_finish_file`); an existing partial file (a
        killed run's, for ``astrodyn recover``) is never overwritten."""
        self._channels: dict[str, int] = {}
        self._schemas: dict[str, int] = {}
        self.path = path
        self.writing_path = partial_path(path, self.attempt) if self.atomic else path
        try:
            if self.atomic and path != self._base:  # a rolled part: beside a file in the way of its partial name
                self._stream = self._open_new_partial_part(path)
            elif self.atomic:
                self._stream = open(self.writing_path, "xb")
            elif path != self._base:  # a rolled part written in place: never over an existing file
                self._stream = self._open_new_part(path)
            else:
                self._stream = open(self.path, "wb")
        except FileExistsError:
            err = RecordingError(f"{self.writing_path}: exists (a killed run's partial recording?): finish it with "
                                 f"`astrodyn recover {self.writing_path}` or remove it; it is never overwritten")
            err.path = self.writing_path  # the file really in the way (the logger names it)
            raise err from None
        except OSError as exc:
            raise RecordingError(f"{self.writing_path}: cannot open for writing: {exc.strerror or exc}") from None
        # held while this process writes the file (released by the kernel when it ends, even
        # killed): recover and the --out checks leave a file being written alone (being_written)
        try:
            fcntl.flock(self._stream.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            self._stream.close()
            raise RecordingError(f"{self.writing_path}: is being written by another process") from None
        self.paths.append(self.path)
        self._opened_at = time.monotonic()
        st = os.fstat(self._stream.fileno())
        self._identity = (st.st_dev, st.st_ino)
        self._report(self.writing_path)
        try:
            self._writer = ChunkedWriter(self._stream, chunk_size=self.chunk_size, library=f"astrodyn {__version__}")
            self._writer.add_metadata("scenario", self._scenario)
            self._writer.add_metadata(
                "recording",
                {
                    "epoch_unix_ns": str(self.epoch_ns),
                    "log_time": "epoch_unix_ns + round(t * 1e9)",
                    "sequence": "seq mod 2**32",
                    "astrodyn_version": __version__,
                    "part": str(self._first_part + len(self.paths) - 1),
                },
            )
            self._flush()
        except OSError as exc:
            self._fail(exc)
        self._next_flush = time.monotonic() + self.flush_interval_s

    def _roll_path(self, n: int) -> str:
        return part_path(self._base, n)

    def _report(self, path: str) -> None:
        """Tell ``on_file`` that this recorder's current file is now at ``path``."""
        if self._on_file is not None and self._identity is not None:
            self._on_file(path, self._identity)

    def _open_new_partial_part(self, path: str):
        """Create the partial file of rolled part ``path`` (atomic); when its partial name
        is taken (another recorder's live file of that name, a killed run's), the partial
        file of a :func:`clash_name` of ``path`` instead, reported in
        :attr:`parts_kept_aside`: the file in the way is never touched."""
        try:
            return open(self.writing_path, "xb")
        except FileExistsError:
            taken = self.writing_path
        for n in range(1, MAX_CLASH_NAMES + 1):
            name = clash_name(path, n)
            try:
                stream = open(partial_path(name, self.attempt), "xb")
            except FileExistsError:
                continue
            self.path, self.writing_path = name, partial_path(name, self.attempt)
            self.parts_kept_aside.append({"part": path, "file": name,
                                          "why": f"{taken} exists (another recorder's file, or a killed run's); it "
                                                 f"was not touched"})
            return stream
        self.writing_path = taken
        raise FileExistsError(taken)

    def _open_new_part(self, path: str):
        """Open rolled part ``path`` (not atomic) as a new file; when that name is taken (an
        earlier recording's part), a :func:`clash_name` beside it, reported in
        :attr:`parts_kept_aside`."""
        try:
            return open(path, "xb")
        except FileExistsError:
            pass
        for n in range(1, MAX_CLASH_NAMES + 1):
            try:
                stream = open(clash_name(path, n), "xb")
            except FileExistsError:
                continue
            self.path = self.writing_path = clash_name(path, n)
            self.parts_kept_aside.append({"part": path, "file": self.path,
                                          "why": f"{path} exists (another recording's part); it was not replaced"})
            return stream
        raise RecordingError(f"{path}: exists (another recording's part), and so do {clash_name(path, 1)} .. "
                             f"{MAX_CLASH_NAMES}; none is replaced: move them away")

    def _name_finished_part(self) -> None:
        """Give the finished rolled part (``writing_path``, atomic) its name ``path`` without
        ever replacing a file there: an earlier serve session's part of that name stays as
        it was and this one takes a :func:`clash_name`, or when none is free keeps its
        partial name; either way :attr:`parts_kept_aside` says where it is."""
        if link_new(self.writing_path, self.path):
            return
        taken = self.path
        for n in range(1, MAX_CLASH_NAMES + 1):
            if link_new(self.writing_path, clash_name(taken, n)):
                self.path = clash_name(taken, n)
                break
        else:
            self.path = self.writing_path
        self.paths[-1] = self.path
        self.parts_kept_aside.append({"part": taken, "file": self.path,
                                      "why": f"{taken} exists (another recording's part); it was not replaced"})

    def _maybe_roll(self) -> None:
        """Finish this file and start the next one when it is over ``roll_size`` bytes or
        ``roll_interval_s`` old (:meth:`_over_roll_size`; the age at each flush)."""
        if self.closed or (self.roll_size is None and self.roll_interval_s is None):
            return
        big = self._over_roll_size()
        old = self.roll_interval_s is not None and time.monotonic() - self._opened_at >= self.roll_interval_s
        if not (big or old):
            return
        self._finish_file()
        self._open(self._roll_path(self._first_part + len(self.paths)))

    # -- channels ------------------------------------------------------------------------

    def add_channel(self, topic: str, schema_name: str, schema: Mapping | bytes, message_encoding: str = "json") -> int:
        """Register a channel with a JSON Schema (e.g. a ``foxglove.FrameTransform`` extra).

        ``MessageError`` (a ``ValueError``) once the file holds :data:`MAX_CHANNELS`
        channels: MCAP channel ids are 16-bit, and a file must stay readable."""
        if topic not in self._channels and len(self._channels) >= MAX_CHANNELS:
            raise messages.MessageError(f"{topic}: channel limit reached ({MAX_CHANNELS} channels per MCAP file, "
                                        "16-bit channel ids); not recorded")
        sid = self._schemas.get(schema_name)
        try:
            if sid is None:
                data = schema if isinstance(schema, bytes) else json.dumps(schema, separators=(",", ":")).encode()
                sid = self._schemas[schema_name] = self._writer.register_schema(schema_name, "jsonschema", data)
            cid = self._channels[topic] = self._writer.register_channel(topic, message_encoding, sid)
        except OSError as exc:
            self._fail(exc)
        return cid

    def _channel_for(self, key: str) -> int:
        found = messages.schema_for_key(key)  # MessageError for a non-astrodyn key
        if found is None:
            raise messages.MessageError(f"key: expected a key that carries messages, got {key!r}")
        return self.add_channel(key, found[0], found[1])

    # -- writing -------------------------------------------------------------------------

    def log_time(self, t: float) -> int:
        """``epoch_ns + round(t * 1e9)``; ValueError if not a uint64 (MCAP's log_time)."""
        try:
            ns = self.epoch_ns + round(t * 1e9)
        except (ValueError, OverflowError, TypeError):
            raise ValueError(f"t: expected a finite number of seconds, got {t!r}") from None
        if not 0 <= ns < _U64_END:
            raise ValueError(f"t: expected epoch + t within 1970 ... 2554 (MCAP log_time is uint64 ns), got t={t!r}")
        return ns

    def write_encoded(self, key: str, payload: bytes, t: float, seq: int, publish_time: int | None = None,
                      track: str | None = None, log_time: int | None = None) -> int:
        """Fast path: record a payload already encoded (and validated) as it came off the bus.

        ``t`` and ``seq`` are the message's own fields.  Returns the seq status (``OK``,
        ``GAP``, ``LATE`` or ``DUPLICATE``; duplicates are not written).  ``track`` names
        the seq counter when several processes share a channel (events: key + process).
        ``log_time`` (ns since the Unix epoch) overrides ``epoch + round(t * 1e9)``: a copy
        of a recorded message keeps its exact log time (t in float64 s is ns-exact only
        within 104 days of the epoch).
        ValueError if ``t`` gives no valid log_time; RecordingError if the write fails.
        """
        if self._error is not None:
            raise self._error
        log_time = self.log_time(t) if log_time is None else int(log_time)
        cid = self._channels.get(key)
        if cid is None:
            cid = self._channel_for(key)
        status = self.seq.add(key if track is None else track, seq)
        if status == DUPLICATE:
            return status
        try:
            self._writer.add_message(cid, log_time, payload, log_time if publish_time is None else publish_time, seq & _U32)
        except OSError as exc:
            self._fail(exc)
        self.message_count += 1
        if time.monotonic() >= self._next_flush or (self.roll_size is not None and self._over_roll_size()):
            self.flush()  # (the roll_size test inline: this is the per-message path)
        return status

    def _over_roll_size(self) -> bool:
        """Whether the file's written chunks reach ``roll_size``: then the next flush rolls
        (checked at each write, so a part overshoots by less than one chunk, however fast
        messages come between flushes)."""
        return self.roll_size is not None and self._stream.tell() >= self.roll_size

    def write_batch(self, buf: np.ndarray, count: int, pay_start: np.ndarray, pay_len: np.ndarray,
                    layout: BatchLayout, publish_time: int, slow) -> tuple[int, float]:
        """Record the ``count`` entries of a framed envelope, compiled where it can.

        ``buf`` is the envelope as a uint8 array, ``pay_start/pay_len`` the payload spans
        (:func:`astrodyn.recording.ingest.frame_batch`), ``layout`` its keys.  Entries in
        the canonical state layout with the next seq of their channel are checked and
        written by :func:`astrodyn.recording.ingest.ingest_batch`; every other entry
        ``i`` is handed to ``slow(i)`` (the caller's per-message path, which ends in
        :meth:`write_encoded`), in arrival order, so the file is what per-message writes
        would give.  Returns ``(messages written here, largest t among them)``.
        """
        if self._error is not None:
            raise self._error
        lits, lit_start, lit_len, names, name_start, name_len = INGEST_GRAMMAR
        result = np.zeros(4, dtype=np.int64)
        written = 0
        max_t = -np.inf
        i = 0
        while i < count:
            w = self._writer
            if layout.writer is not w:
                layout.resolve(self)
            state = w.chunk_state
            state[2] = 0
            # the roles of ingest_batch's parameters, one a line (fmt: skip)
            ingest.ingest_batch(
                buf, i, count, pay_start, pay_len, layout.kinds, layout.cids, layout.slots,
                lits, lit_start, lit_len, names, name_start, name_len, messages.QUAT_NORM_TOL,
                self._t_text, self._t_log_time, publish_time, self.seq.next_seq, self.seq.counts,
                w.chunk, state, w.chunk_size, w.idx_channel, w.idx_time, w.idx_offset, result,
            )  # fmt: skip
            n = int(state[2])
            if n:
                written += n
                max_t = max(max_t, self._t_value)
            code, i = int(result[0]), int(result[1])
            if code == ingest.DONE:
                break
            if code == ingest.NEED_T:
                text = buf[result[2] : result[3]].tobytes()
                try:
                    t = float(text)
                    log_time = self.log_time(t)
                except ValueError:  # let the per-message path report it
                    slow(i)
                    i += 1
                    continue
                self._t_text = np.frombuffer(text, dtype=np.uint8).copy()  # writable: one kernel signature
                self._t_value, self._t_log_time = t, log_time
            elif code == ingest.CHUNK_FULL and int(state[0]) > 0:
                try:
                    w.finalize_chunk()
                except OSError as exc:
                    self._fail(exc)
            else:  # SLOW, or one record larger than the whole buffer
                slow(i)
                i += 1
        self.message_count += written
        if time.monotonic() >= self._next_flush or self._over_roll_size():
            self.flush()
        return written, max_t

    def add_metadata(self, name: str, data: Mapping[str, Any]) -> None:
        """Write one more metadata record into the current file (e.g. the logger's "end":
        why and where the run stopped).  Values as for ``scenario_metadata``."""
        if self._error is not None:
            raise self._error
        try:
            self._writer.add_metadata(name, _metadata_strings(name, data))
        except OSError as exc:
            self._fail(exc)

    def write(self, key: str, msg: dict, publish_time: int | None = None) -> int:
        """Encode ``msg`` (validated against the key's schema) and record it."""
        payload = messages.encode(msg, key)
        return self.write_encoded(key, payload, msg["t"], msg["seq"], publish_time)

    # -- flushing and closing --------------------------------------------------------------

    def _flush(self) -> None:
        self._writer.flush()
        self.flushes += 1

    def flush(self) -> None:
        """Close the open chunk and hand everything to the OS (survives a SIGKILL)."""
        if self._error is not None:
            raise self._error
        try:
            self._flush()
        except OSError as exc:
            self._fail(exc)
        self._next_flush = time.monotonic() + self.flush_interval_s
        self._maybe_roll()

    def maybe_flush(self) -> None:
        """Flush if ``flush_interval_s`` has passed since the last flush (call when idle)."""
        if not self.closed and time.monotonic() >= self._next_flush:
            self.flush()

    def _fail(self, exc: OSError) -> None:
        reason = exc.strerror or str(exc)
        self._error = RecordingError(
            f"{self.writing_path}: write failed: {reason}; the file has no footer and holds what was "
            "flushed before the failure (astrodyn.recording.load reads it, marked truncated)"
        )
        self._error.errno = exc.errno  # e.g. ENOSPC: the disk is full (the logger's exit status says so)
        try:
            self._stream.close()
        except OSError:
            pass
        self.closed = True
        raise self._error from None

    def _finish_file(self, rename: bool = True) -> None:
        try:
            self._writer.finish()
            self._stream.flush()
            os.fsync(self._stream.fileno())
            self._stream.close()
            if rename and self.writing_path != self.path and self.path == self._base:
                # atomic: the finished file takes its name in one step (replacing an earlier
                # recording of that name: a run's --out)
                os.replace(self.writing_path, self.path)
                fsync_directory(self.path)
                self._report(self.path)
            elif rename and self.writing_path != self.path:  # a rolled part: never over another one
                self._name_finished_part()
                self._report(self.path)
        except OSError as exc:
            self._fail(exc)

    def close(self, rename: bool = True) -> dict:
        """Finish the file (summary, indexes, footer), fsync, close; returns :meth:`stats`.

        With ``atomic``, ``rename=False`` leaves the finished file under its partial name
        (a run that was stopped by a signal or lost a process: it must not replace an
        earlier recording; ``astrodyn recover`` renames it).  ``stats()["file"]`` says
        where the file is."""
        if self._error is not None:
            raise self._error
        if not self.closed:
            self._finish_file(rename=rename)
            self.closed = True
            self.final_file = self.path if (rename or self.writing_path == self.path) else self.writing_path
        return self.stats()

    def stats(self) -> dict:
        """Messages written, flushes, and the seq accounting totals and per-channel report."""
        return {
            "path": self.path,
            "paths": list(self.paths),
            "writing": None if self.closed else self.writing_path,
            "file": getattr(self, "final_file", None),
            "parts_kept_aside": [dict(k) for k in self.parts_kept_aside],
            "messages": self.message_count,
            "channels": len(self._channels),
            "flushes": self.flushes,
            **{k: v for k, v in self.seq.totals().items() if k != "count"},
        }

    def __enter__(self) -> McapRecorder:
        return self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        if self._error is None and not self.closed:
            self.close()
        elif exc_type is None and self._error is not None:
            raise self._error
