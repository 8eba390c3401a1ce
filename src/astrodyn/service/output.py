"""Output paths of a run: checked before anything starts.

A recording never overwrites an input or anything that is not a recording: ``--out`` that
names the config, another input file of the run, or an existing file that is not an MCAP
file is refused (exit 2, nothing written).  The logger writes ``NAME.partial.mcap`` and
renames it over ``NAME.mcap`` only when the file is finished, so a failed or killed run
leaves the previous recording intact and its own partial file for ``astrodyn recover``.
"""

from __future__ import annotations

import os
from pathlib import Path

from mcap.opcode import Opcode

from astrodyn.recording.reader import MCAP_MAGIC, RecordingError, open_recording
from astrodyn.recording.writer import being_written, is_partial_path, part_path, partial_path
from astrodyn.scenario import ScenarioError

__all__ = ["check_output_path", "OutputDirectory", "series_parts_problem", "series_start_problem", "held_path",
           "identity_at", "recorded_metadata", "MAX_METADATA_RECORD_BYTES"]


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return False


def check_output_path(path: Path, inputs: tuple = ()) -> None:
    """Raise :class:`~astrodyn.scenario.ScenarioError` naming ``--out`` unless ``path`` is a
    file path in an existing, writable directory that is none of ``inputs`` (the config and
    any other file the run reads), is not an existing file other than an MCAP recording,
    and has no partial recording of a killed run beside it."""
    path = Path(path)
    parent = path.resolve().parent
    if not parent.is_dir():
        raise ScenarioError(f"--out {path}: expected a file in an existing directory, got missing directory {parent}")
    if not os.access(parent, os.W_OK):
        raise ScenarioError(f"--out {path}: expected a writable directory, {parent} is not writable")
    if path.is_dir():
        raise ScenarioError(f"--out {path}: expected a file path, got a directory")
    for given in inputs:
        if given is not None and (_same_file(path, Path(given)) or path.resolve() == Path(given).resolve()):
            raise ScenarioError(f"--out {path}: names an input of the run ({given}); expected a new .mcap path")
    if path.exists():
        try:  # non-blocking (a FIFO would hang the read), regular files only (a device is never a recording)
            f, _ = open_recording(str(path))
        except RecordingError as exc:  # "<path>: cannot open: <why>"
            why = str(exc).rpartition(": cannot open: ")[2]
            raise ScenarioError(f"--out {path}: exists and is not an MCAP recording ({why}); it is never written "
                                f"to (expected a new path or an earlier recording to replace)") from None
        with f:
            head = f.read(len(MCAP_MAGIC))
        if head != MCAP_MAGIC:
            raise ScenarioError(f"--out {path}: exists and is not an MCAP recording; it is never overwritten "
                                f"(expected a new path or an earlier recording to replace)")
        if is_partial_path(path):  # a finished recording may be replaced; an unfinished one only recovered
            raise ScenarioError(f"--out {path}: exists and is the partial recording of a killed or failed run; it is "
                                f"never replaced: finish it with `astrodyn recover {path}`, or choose another --out")
    partial = Path(partial_path(path))
    if partial.is_symlink():  # a dangling one too (exists() says False): the logger's O_EXCL would fail on it
        raise ScenarioError(f"--out {path}: {partial} is a symbolic link, in the way of the recording (it is written "
                            f"as {partial} first); it is never written through or removed: remove it or choose "
                            f"another --out")
    if being_written(partial):
        raise ScenarioError(f"--out {path}: {partial} is being recorded right now by another run or serve (its "
                            f"logger holds it); choose another --out, or stop that one first")
    if partial.exists():
        raise ScenarioError(f"--out {path}: {partial} exists, the partial recording of a killed run; finish it with "
                            f"`astrodyn recover {partial}` (or remove it) before recording to {path} again")


def series_parts_problem(path: Path) -> str | None:
    """What is in the way of ``serve`` recording to ``path`` and rolling it into parts
    (``NAME-0001.mcap``, ... :func:`astrodyn.recording.writer.part_path`), one line; None
    when nothing is.  Two things are:

    - the parts of an earlier series (finished or partial), which serve's new parts would
      be written over: the line names every file of that series, ``NAME.mcap`` (its first
      part) included, so that moving what it names moves the whole series (before, it named
      the parts only, and a serve started after they were moved replaced ``NAME.mcap`` at
      its stop); a partial part (``NAME-000k.partial.mcap``, a killed serve's) is named with
      ``astrodyn recover``, which finishes it;
    - ``NAME.mcap`` alone when it is the start of a recording that went on elsewhere
      (:func:`series_start_problem`): serve replaces a finished recording at its stop, but
      never the first part of an earlier series whose later parts were moved away.

    The names are judged with ``os.lstat`` only (a FIFO never blocks); only a regular
    ``NAME.mcap`` is read (its head and summary: :func:`recorded_metadata`)."""
    import re

    root, ext = os.path.splitext(os.fspath(path))
    ext = ext or ".mcap"
    folder = os.path.dirname(root) or "."
    head = os.path.basename(root)
    pattern = re.compile(re.escape(head) + r"-(\d{4,})(\.partial(-\d+)?)?" + re.escape(ext) + "$")
    try:
        names = os.listdir(folder)
    except OSError:
        return None
    found = []
    for name in names:
        m = pattern.match(name)
        if m is None:
            continue
        k = int(m.group(1))
        finished = part_path(path, k)  # NAME-000k.mcap; its partial names start with NAME-000k.partial
        if k >= 1 and (name == os.path.basename(finished) or name.startswith(os.path.basename(root) + f"-{k:04d}.")):
            found.append((k, name, os.path.join(os.path.dirname(finished), name)))
    if not found:
        return series_start_problem(path)
    found.sort()
    files = ([os.fspath(path)] if os.path.lexists(path) else []) + [p for _, _, p in found]
    named = ", ".join(files) if len(files) <= 8 else f"{', '.join(files[:4])}, ..., {files[-1]} ({len(files)} files)"
    every = f"{os.fspath(path)} and every {os.path.join(os.path.dirname(os.fspath(path)), head)}-NNNN*{ext}"
    partials = [p for _, name, p in found if is_partial_path(name)]
    first = f" ({os.fspath(path)} is its first part)" if os.path.lexists(path) else ""
    problem = (f"{named}: an earlier recording's series is there{first}; serve's own parts would take the names of "
               f"its parts, and it never writes over a recording")
    move = f"move all of it elsewhere ({every}) or choose another --out"
    if not partials:
        return f"{problem}: {move}"
    which = partials[0] if len(partials) == 1 else (os.path.dirname(os.fspath(path)) or ".")
    listed = ", ".join(partials[:3]) + (", ..." if len(partials) > 3 else "")
    return (f"{problem}; {listed} {'is an unfinished part' if len(partials) == 1 else 'are unfinished parts'} of a "
            f"killed serve: finish {'it' if len(partials) == 1 else 'them'} with `astrodyn recover {which}`, then "
            f"{move}")


def series_start_problem(path: Path, who: str = "serve") -> str | None:
    """One line when the existing recording ``path`` (``NAME.mcap``) must not be replaced
    by ``who`` (``serve``, ``run``) because its recording does not end in it: an astrodyn logger's file (it has
    the ``recording`` metadata record) without the ``end`` record the logger writes into
    the file it stops in.  That is the first part of an earlier series that rolled on into
    ``NAME-0001.mcap``, ... (moved away since), or a killed serve's file finished by
    ``astrodyn recover`` (which may be one too, and holds a session nothing else holds).
    None for anything else: no file, a finished recording of a run or serve that ended in
    it (replaced at serve's stop, as the README says), a file that is not an astrodyn
    recording or cannot be read (:func:`check_output_path` judges those)."""
    import stat

    try:
        if not stat.S_ISREG(os.lstat(path).st_mode):
            return None
        found = recorded_metadata(path, ("recording", "end"))
    except (OSError, RecordingError):
        return None
    if "recording" not in found or "end" in found:
        return None
    root, ext = os.path.splitext(os.fspath(path))
    first = f"{os.path.basename(root)}-0001{ext or '.mcap'}"
    return (f"{os.fspath(path)}: is the start of an earlier recording that does not end in it (it has no `end` "
            f"record: the first part of an earlier serve's series, which went on in {first}, ..., or a killed "
            f"serve's file finished by `astrodyn recover`); {who} never writes over it: move it elsewhere (with the "
            f"rest of its series) or choose another --out")


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
    opcode is in ``stop`` and at one that does not fit."""
    import struct

    pos = begin
    for _ in range(limit):
        if end - pos < _RECORD_HEAD:
            return
        f.seek(pos)
        head = f.read(_RECORD_HEAD)
        if len(head) != _RECORD_HEAD:
            return
        opcode, length = struct.unpack("<BQ", head)
        if opcode in stop or length > end - pos - _RECORD_HEAD:
            return
        if opcode in wanted and length <= wanted[opcode]:
            yield opcode, f.read(length)
        pos += _RECORD_HEAD + length


def held_path(fd: int | None, identity: tuple[int, int], names=()) -> str | None:
    """Where the file or directory held open by descriptor ``fd`` is now (``/proc/self/fd``,
    Linux), if a path there still names it (``(st_dev, st_ino)`` = ``identity``); None when
    it was removed or that cannot be told.  How a run finds its recording after its
    directory was renamed (:class:`OutputDirectory`, ``supervision.LoggerFile``).

    A file whose name the descriptor was opened by is gone but which still has a link
    (``st_nlink`` > 0) was given another name by a hard link and an unlink
    (:func:`astrodyn.recording.writer.link_new`: how a finished part is named; ``/proc``
    then reads ``<old path> (deleted)``): it is looked for under ``names`` (paths it may
    have taken, e.g. the finished names its logger reported), each as given and in the
    directory ``/proc`` shows (where that directory is now)."""
    if fd is None:
        return None
    try:
        now: str | None = os.readlink(f"/proc/self/fd/{fd}")
    except OSError:
        now = None
    if now is not None and not now.endswith(" (deleted)") and identity_at(now) == identity:
        return now
    if not names:
        return None
    try:
        if os.fstat(fd).st_nlink == 0:  # removed, not renamed
            return None
    except OSError:
        return None
    folders = [os.path.dirname(now.removesuffix(" (deleted)"))] if now is not None and now.startswith("/") else []
    for name in names:
        name = os.fspath(name)
        for candidate in (name, *(os.path.join(d, os.path.basename(name)) for d in folders)):
            if identity_at(candidate) == identity:
                return candidate
    return None


def identity_at(path: str | os.PathLike) -> tuple[int, int] | None:
    """``(st_dev, st_ino)`` of what ``path`` names (a symbolic link itself, not followed),
    None when nothing is there: the identity by which a run knows its own files."""
    try:
        st = os.lstat(path)
    except OSError:
        return None
    return st.st_dev, st.st_ino


class OutputDirectory:
    """The directory a recording is written in, held open (a descriptor on it) from the
    start: :meth:`problem` tells when it was renamed or removed while the run recorded
    (the recording then is not at ``--out``), and where it went if that can be told
    (``/proc/self/fd``, Linux)."""

    def __init__(self, out: Path):
        self.path = os.path.dirname(os.path.abspath(out))
        try:  # O_PATH (Linux): no read permission needed on the directory
            self._fd: int | None = os.open(self.path, getattr(os, "O_PATH", os.O_RDONLY) | os.O_DIRECTORY | os.O_CLOEXEC)
            st = os.fstat(self._fd)
        except OSError:  # then a move is still noticed, but where it went cannot be told
            self._fd = None
            st = os.stat(self.path)
        self.identity = (st.st_dev, st.st_ino)

    def where(self) -> str | None:
        """Where the directory is now (None: removed, or not known)."""
        return held_path(self._fd, self.identity)

    def problem(self) -> str | None:
        """None while the directory is still at :attr:`path`; else one line saying it was
        moved (and where to) or removed."""
        try:
            st = os.stat(self.path)
            if (st.st_dev, st.st_ino) == self.identity:
                return None
        except OSError:
            pass
        where = self.where()
        if where is not None:
            return f"the output directory {self.path} was moved to {where} while recording: the recording is there"
        return f"the output directory {self.path} was removed (or moved where it cannot be told) while recording"

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None
