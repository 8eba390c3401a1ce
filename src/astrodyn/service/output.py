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

from astrodyn.recording.reader import MCAP_MAGIC, RecordingError, open_recording
from astrodyn.recording.writer import being_written, is_partial_path, part_path, partial_path
from astrodyn.scenario import ScenarioError

__all__ = ["check_output_path", "OutputDirectory", "series_parts_problem", "held_path"]


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
    """What is in the way of ``serve`` rolling the recording ``path`` into parts
    (``NAME-0001.mcap``, ... :func:`astrodyn.recording.writer.part_path`): the parts of an
    earlier series (finished or partial) that its new parts would be written over, one
    line naming the first of them; None when there are none.  Judged with ``os.lstat``
    only (a FIFO never blocks)."""
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
            found.append((k, os.path.join(os.path.dirname(finished), name)))
    if not found:
        return None
    found.sort()
    first = ", ".join(p for _, p in found[:3]) + (f" and {len(found) - 3} more" if len(found) > 3 else "")
    many = len(found) > 1
    return (f"{first}: {'parts' if many else 'a part'} of an earlier recording's series {'exist' if many else 'exists'}; "
            f"serve's own parts would take {'their names' if many else 'its name'}, and it never writes over a "
            f"recording: move {'them' if many else 'it'} elsewhere or choose another --out")


def held_path(fd: int | None, identity: tuple[int, int]) -> str | None:
    """Where the file or directory held open by descriptor ``fd`` is now (``/proc/self/fd``,
    Linux), if a path there still names it (``(st_dev, st_ino)`` = ``identity``); None when
    it was removed or that cannot be told.  How a run finds its recording after its
    directory was renamed (:class:`OutputDirectory`, ``supervision.LoggerFile``)."""
    if fd is None:
        return None
    try:
        now = os.readlink(f"/proc/self/fd/{fd}")
        st = os.lstat(now)
    except OSError:
        return None
    return now if (st.st_dev, st.st_ino) == identity and not now.endswith(" (deleted)") else None


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
