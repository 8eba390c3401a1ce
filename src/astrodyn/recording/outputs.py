"""How the file tools (``recover``, ``merge``, ``export``, ``analyze``, ``sweep``) write their
outputs.

A file is written under a temporary name beside its final one and renamed over it only once
complete (:func:`written_atomically`, :func:`write_atomically`); a set of files (an export,
a report) is written in a work directory inside the output directory and moved into place
only once every file is complete (:func:`staging_directory`; the move runs under
:func:`astrodyn.signals.deferred_interrupts`).  So a failure or an interrupt
(:func:`astrodyn.signals.interruptible`) never leaves a half-written file under a final
name, and an earlier output there is replaced by a complete one or not at all.  A SIGKILL
cannot be caught: it leaves the temporary name (``<name>.tmp``, ``<name>.recover-tmp``,
``.export-<pid>-*/``), never the final one; the next run writing the same output removes it.
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

from astrodyn.recording.writer import RecordingError

__all__ = ["written_atomically", "write_atomically", "staging_directory"]


@contextlib.contextmanager
def written_atomically(dst: str | os.PathLike, suffix: str = ".tmp") -> Iterator[str]:
    """Yield the temporary path ``dst + suffix`` to write ``dst`` through: renamed over
    ``dst`` when the block ends normally, removed on any exception (an interrupt included),
    ``dst`` then untouched."""
    dst = os.fspath(dst)
    tmp = dst + suffix
    try:
        yield tmp
        os.replace(tmp, dst)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def write_atomically(dst: str, write):
    """Call ``write(stream)`` on ``dst + ".recover-tmp"``, make it durable (fsync) and
    rename it over ``dst``; returns what ``write`` returned.  On any failure the temporary
    file is removed and ``dst`` is untouched (RecordingError for an OSError)."""
    with written_atomically(dst, ".recover-tmp") as tmp:
        try:
            stream = open(tmp, "wb")
        except OSError as exc:
            raise RecordingError(f"{dst}: cannot write: {exc.strerror or exc}") from None
        try:
            with stream:
                result = write(stream)
                stream.flush()
                os.fsync(stream.fileno())
        except OSError as exc:
            raise RecordingError(f"{dst}: write failed: {exc.strerror or exc}; nothing was replaced") from None
    return result


@contextlib.contextmanager
def staging_directory(out: str | os.PathLike, prefix: str,
                      cannot: Callable[[OSError], Exception] | None = None) -> Iterator[Path]:
    """A new directory ``out/.<prefix>-<pid>-XXXXXXXX`` to write a set of output files in
    before they are moved into ``out`` (created if missing); removed at the end, whatever
    happens.  When the block fails or is interrupted, ``out`` is removed too if this made it
    and it is still empty.  Work directories of ``prefix`` whose process is gone (killed)
    are removed first.  ``cannot(exc)``: the exception to raise when the directories cannot
    be made (default: the OSError itself).

    A generator: the directories are made inside it, so an interrupt that lands while they
    are made, or before the caller's ``with`` has taken them, still removes them (the
    generator's ``finally``, at the latest when it is collected)."""
    out = Path(out)
    created = not out.exists()
    path: Path | None = None
    failed = True
    try:
        try:
            out.mkdir(parents=True, exist_ok=True)
            _remove_stale(out, prefix)
            path = Path(tempfile.mkdtemp(prefix=f".{prefix}-{os.getpid()}-", dir=out))
        except OSError as exc:
            if cannot is None:
                raise
            raise cannot(exc) from None
        yield path
        failed = False
    finally:
        if path is not None:
            shutil.rmtree(path, ignore_errors=True)
        if failed and created:
            with contextlib.suppress(OSError):  # only when empty
                out.rmdir()


def _remove_stale(out: Path, prefix: str) -> None:
    pattern = re.compile(rf"^\.{re.escape(prefix)}-(\d+)-")
    for entry in os.scandir(out):
        m = pattern.match(entry.name)
        if not m or not entry.is_dir(follow_symlinks=False):
            continue
        try:
            os.kill(int(m.group(1)), 0)
            continue  # its process runs (or is another user's)
        except ProcessLookupError:
            shutil.rmtree(entry.path, ignore_errors=True)
        except (OSError, OverflowError):
            continue
