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

__all__ = ["file_kind", "regular_file_problem", "path_argument", "MAX_TEXT_INPUT_BYTES"]

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
