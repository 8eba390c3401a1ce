"""How the file tools (``recover``, ``merge``, ``export``, ``analyze``, ``sweep``) write their
outputs.

A file is written under a temporary name of its own beside its final one and given the
final name only once complete (:func:`written_atomically`, :func:`write_atomically`); a
set of files (an export, a report) is written in a work directory inside the output
directory and moved into place only once every file is complete
(:func:`staging_directory`; the move runs under :func:`astrodyn.signals.deferred_interrupts`).
So a failure or an interrupt (:func:`astrodyn.signals.interruptible`) never leaves a
half-written file under a final name, and an earlier output there is replaced by a complete
one or not at all.

Every temporary name is unique: it holds the writer's pid and a random part
(``NAME.<pid>-<8 chars>.mcap.recover-tmp``, ``.NAME.<pid>-<8 chars>.mcap.merging``,
``case-K.<pid>-<8 chars>.mcap.tmp``, ``.export-<pid>-*/``) and is created with ``O_EXCL``,
so two tools writing one output at once never write into one file.  A new file (``merge
--out``, ``recover --out``) takes its name only if the name is still free when it is
finished (:func:`astrodyn.recording.writer.link_new`): when another process wrote that
output meanwhile, the final name keeps that process's complete file and this one's result
is dropped with :class:`OutputTaken` (one line, never a mix of the two).  An output that is
meant to be replaced (``recover X`` rewriting X, a sweep case rerun) is renamed over it in
one step: the last one finished is there, whole.

A SIGKILL cannot be caught: it leaves the temporary name, never the final one; the next
run writing the same output removes the temporary files of that output whose process is
gone (:func:`written_atomically`), as the next export or analyze into a directory removes
the work directories of dead processes (:func:`staging_directory`); ``astrodyn recover``
removes those of ``merge`` and ``recover`` in its directory (:func:`stale_temporaries`).
A process is taken for gone when its pid is not running here: a temporary file of a tool
in another PID namespace (another container) sharing the directory could be taken for a
dead one's.
"""

from __future__ import annotations

import contextlib
import errno
import os
import re
import secrets
import shutil
import sys
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

from astrodyn.recording.writer import RecordingError, fsync_directory, link_new
from astrodyn.signals import deferred_interrupts

__all__ = ["written_atomically", "write_atomically", "staging_directory", "OutputTaken", "temporary_name",
           "stale_temporaries", "warn_incomplete_input", "process_may_run"]


class OutputTaken(RecordingError):
    """A new output file was finished, but another process had written a file under its
    name meanwhile: that file is left as it was and this result was dropped."""


def temporary_name(dst: str | os.PathLike, suffix: str, *, hidden: bool = False, token: str | None = None,
                   pid: int | None = None) -> str:
    """The temporary name this process writes ``dst`` through: ``<dir>/[.]<root>.<pid>-<token><ext><suffix>``
    (``token``: 8 random characters unless given; the ``.`` in front when ``hidden``).
    ``<ext><suffix>`` stays at the end, so globs such as ``case-*.mcap.tmp`` or
    ``*.recover-tmp`` find it, and it never ends with ``.mcap``."""
    folder, name = os.path.split(os.fspath(dst))
    root, ext = os.path.splitext(name)
    token = secrets.token_hex(4) if token is None else token
    pid = os.getpid() if pid is None else pid
    return os.path.join(folder, f"{'.' if hidden else ''}{root}.{pid}-{token}{ext}{suffix}")


def _temporary_pattern(dst: str, suffix: str, hidden: bool) -> re.Pattern:
    root, ext = os.path.splitext(os.path.basename(dst))
    return re.compile(rf"^{re.escape('.' if hidden else '')}{re.escape(root)}\.(\d+)-[0-9a-f]{{8}}"
                      rf"{re.escape(ext + suffix)}$")


#: the temporary files of ``merge`` and ``recover`` (any output): :func:`stale_temporaries`
_TOOL_TEMPORARY = re.compile(r"^.+\.(\d+)-[0-9a-f]{8}(?:\.[^.]+)?(?:\.merging|\.recover-tmp)$")


def stale_temporaries(folder: str | os.PathLike, pattern: re.Pattern = _TOOL_TEMPORARY) -> list[str]:
    """Temporary files in ``folder`` (names matching ``pattern``, group 1 the writer's pid;
    by default those of ``merge`` and ``recover`` for any output) whose process is gone:
    what a SIGKILLed tool left.  A live process's (or another user's) is never listed."""
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return []
    out = []
    for entry in entries:
        m = pattern.match(entry.name)
        try:
            if m and entry.is_file(follow_symlinks=False) and not process_may_run(int(m.group(1))):
                out.append(entry.path)
        except OSError:
            continue
    return sorted(out)


def _remove_stale_temporaries(dst: str, suffix: str, hidden: bool) -> None:
    """Remove the temporary files of ``dst`` (:func:`temporary_name`) whose process is gone."""
    for path in stale_temporaries(os.path.dirname(dst) or ".", _temporary_pattern(dst, suffix, hidden)):
        with contextlib.suppress(OSError):
            os.unlink(path)


def process_may_run(pid: int) -> bool:
    """Whether process ``pid`` may still run: True unless ``kill(pid, 0)`` says there is no
    such process (another user's process, or a number this system has no pid for: True, so
    that what it may own is left alone)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (OSError, OverflowError):
        return True  # another user's, or not a pid this system has: leave its files alone
    return True


def _create_temporary(dst: str, suffix: str, hidden: bool) -> str:
    """Create an empty, new temporary file for ``dst`` (``O_EXCL``, mode 0666 less the
    umask, as ``open(..., "wb")`` makes it) and return its name."""
    for _ in range(100):
        tmp = temporary_name(dst, suffix, hidden=hidden)
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0), 0o666)
        except FileExistsError:
            continue
        os.close(fd)
        return tmp
    raise FileExistsError(errno.EEXIST, "no free temporary name", tmp)


@contextlib.contextmanager
def written_atomically(dst: str | os.PathLike, suffix: str = ".tmp", *, replace: bool = True,
                       hidden: bool = False) -> Iterator[str]:
    """Yield a new, empty temporary file (:func:`temporary_name` of ``dst``, created with
    ``O_EXCL``; the caller opens it to write) that takes the name ``dst`` when the block
    ends normally; removed on any exception (an interrupt included), ``dst`` then untouched.

    ``replace``: rename it over ``dst`` (whatever is there is replaced in one step).
    Otherwise ``dst`` is a new file: it takes the name only while the name is free
    (:func:`astrodyn.recording.writer.link_new`), else :class:`OutputTaken` and ``dst``
    keeps what another process put there.  Temporary files of ``dst`` left by dead
    processes are removed first.  An OSError creating the file or naming it propagates."""
    dst = os.fspath(dst)
    tmp: str | None = None
    try:
        _remove_stale_temporaries(dst, suffix, hidden)
        with deferred_interrupts():  # created and its name kept, so that the finally below removes it
            tmp = _create_temporary(dst, suffix, hidden)
        yield tmp
        with deferred_interrupts():  # named, or not at all: no second name left by a signal
            if replace:
                os.replace(tmp, dst)
                fsync_directory(dst)
            elif link_new(tmp, dst):
                tmp = None
            else:
                raise OutputTaken(f"{dst}: another process wrote this file while this one worked; it holds that "
                                  f"process's complete output and was left as it was; this result was dropped")
        tmp = None
    finally:
        if tmp is not None:
            with contextlib.suppress(OSError):
                os.unlink(tmp)


def write_atomically(dst: str, write, *, suffix: str = ".recover-tmp", replace: bool = True, hidden: bool = False,
                     cannot: Callable[[OSError], Exception] | None = None):
    """Call ``write(stream)`` on a new temporary file of ``dst`` (:func:`written_atomically`
    with ``suffix``, ``replace``, ``hidden``), make it durable (fsync) and give it the name
    ``dst``; returns what ``write`` returned.  On any failure the temporary file is removed
    and ``dst`` is untouched: ``cannot(exc)`` for an OSError (default: a RecordingError
    naming ``dst``), :class:`OutputTaken` when ``replace`` is false and another process
    wrote ``dst`` meanwhile."""
    def failed(exc: OSError, default: str) -> Exception:
        return cannot(exc) if cannot is not None else RecordingError(default)

    try:
        with written_atomically(dst, suffix, replace=replace, hidden=hidden) as tmp:
            try:
                stream = open(tmp, "wb")
            except OSError as exc:
                raise failed(exc, f"{dst}: cannot write: {exc.strerror or exc}") from None
            try:
                with stream:
                    result = write(stream)
                    stream.flush()
                    os.fsync(stream.fileno())
            except OSError as exc:
                raise failed(exc, f"{dst}: write failed: {exc.strerror or exc}; nothing was replaced") from None
    except OSError as exc:  # creating the temporary file, or naming the finished one
        raise failed(exc, f"{dst}: cannot write: {exc.strerror or exc}; nothing was replaced") from None
    return result


def warn_incomplete_input(tool: str, path: str | os.PathLike, why: str, going_on: str) -> None:
    """The one line a file tool prints on stderr when an input is cut (its writer did not
    finish: a live or killed logger's file) or damaged, and it goes on with what is whole:
    ``astrodyn <tool>: warning: <path>: <why>; <going_on>``."""
    print(f"astrodyn {tool}: warning: {path}: {why}; {going_on}", file=sys.stderr)


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
            # the directory and its name together: a signal while mkdtemp makes it (after its
            # mkdir, before ``path`` is set) left it behind, with nothing to remove it
            with deferred_interrupts():
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
        if m and entry.is_dir(follow_symlinks=False) and not process_may_run(int(m.group(1))):
            shutil.rmtree(entry.path, ignore_errors=True)
