"""Paths the user gives (a config, ``--json``, ``--zenoh-config``, a recording): what they
name, judged before they are opened.

Opening a FIFO that no process writes blocks until one does, and a process blocked there
does not even stop for SIGTERM (Python retries the interrupted ``open``): ``--out``,
``--json`` or ``--zenoh-config`` naming a FIFO hung ``run``, ``serve``, ``replay`` and
``router`` for good.  So a file astrodyn reads or replaces must be a regular file, and
:func:`regular_file_problem` says in words what else it is, from ``os.stat`` (which never
blocks).  A scenario config is the exception: read once, it may be a pipe
(``astrodyn run <(generate)``).

>>> regular_file_problem("configs/demo.toml")               # doctest: +SKIP
>>> regular_file_problem("/dev/null")                       # doctest: +SKIP
'expected a regular file, got a character device'
"""

from __future__ import annotations

import argparse
import os
import stat

__all__ = ["file_kind", "regular_file_problem", "path_argument", "output_path_problem", "MAX_TEXT_INPUT_BYTES"]

#: Largest text file a command reads whole (a sweep's ``--cases`` CSV): 4 MiB, as for a
#: scenario config; ``/dev/zero`` or a huge file is refused instead of filling the memory.
MAX_TEXT_INPUT_BYTES = 4 * 2**20

_KINDS = ((stat.S_ISREG, "a regular file"), (stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO"),
          (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))


def file_kind(mode: int) -> str:
    """What an ``st_mode`` is, in words: "a regular file", "a directory", "a FIFO", ..."""
    for test, kind in _KINDS:
        if test(mode):
            return kind
    return "a special file"


def regular_file_problem(path: str | os.PathLike, missing_ok: bool = False) -> str | None:
    """None when ``path`` (symlinks followed) is a regular file, or does not exist and
    ``missing_ok``; else what is wrong, as "expected a regular file, got ..." (a FIFO, a
    directory, a device, no such file)."""
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        return None if missing_ok else "expected a regular file, got no such file"
    except OSError as exc:
        return f"expected a regular file, got an unreadable path ({exc.strerror or exc})"
    return None if stat.S_ISREG(mode) else f"expected a regular file, got {file_kind(mode)}"


def path_argument(text: str) -> str:
    """argparse ``type`` of a path option (``--out``): any path but the empty string, which
    a shell variable that came out empty gives, and which meant "the current directory" to
    some commands (an export or a sweep written there) and a traceback to others."""
    if text == "":
        raise argparse.ArgumentTypeError("expected a path, got an empty string")
    return text


def output_path_problem(path: str | os.PathLike, directory: bool = False) -> str | None:
    """None when ``path`` can be an output: with ``directory``, an existing directory or one
    that can be made (its nearest existing ancestor a writable directory); else a file path
    (a regular file, or nothing yet) in an existing, writable directory.  Otherwise what is
    wrong, "expected a directory, got a regular file", "expected a file path, got a FIFO",
    ...: judged from ``os.stat`` before anything is read or written, so a command refuses an
    output of the wrong kind at once rather than after reading its input."""
    want = "a directory" if directory else "a file path"
    path = os.path.abspath(os.fspath(path))
    mode = _mode(path)
    if mode is not None and (stat.S_ISDIR(mode) != directory or not (directory or stat.S_ISREG(mode))):
        return f"expected {want}, got {file_kind(mode)}"
    if mode is not None and directory:
        place = path
    else:
        place = os.path.dirname(path)
        while directory and _mode(place) is None and os.path.dirname(place) != place:  # made with its parents
            place = os.path.dirname(place)
    place_mode = _mode(place)
    if place_mode is None:
        return f"expected {want} in an existing directory, got the missing directory {place}"
    if not stat.S_ISDIR(place_mode):
        return f"expected {want} {'that can be created' if directory else 'in a directory'}, got a path inside " \
               f"{file_kind(place_mode)} ({place})"
    if not os.access(place, os.W_OK | os.X_OK):
        return f"expected {want} {'that can be created' if directory else 'in a writable directory'}, got a path " \
               f"in {place}, which is not writable"
    return None


def _mode(path: str) -> int | None:
    """``st_mode`` of ``path`` (symlinks followed), None when nothing can be found there."""
    try:
        return os.stat(path).st_mode
    except (OSError, ValueError):  # missing, a file on the way (ENOTDIR), unreachable; a NUL byte
        return None
