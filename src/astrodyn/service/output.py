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

from astrodyn.recording.reader import MCAP_MAGIC, RecordingError, open_recording, recorded_metadata
from astrodyn.recording.writer import being_written, is_partial_path, part_path, partial_path
from astrodyn.scenario import ScenarioError

__all__ = ["check_output_path", "OutputDirectory", "series_parts_problem", "series_start_problem", "held_path",
           "identity_at"]


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
