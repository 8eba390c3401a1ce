"""The console streams of the ``astrodyn`` commands: output nobody reads any more is dropped,
the work goes on.

A command's stdout and stderr carry progress and reports, never its results: those are
files (the MCAP recording, exports, figures).  So when the reader of a pipe goes away
(``astrodyn run big.toml | head``, a ``grep`` or a log shipper that ends, a terminal that
closes), a write raises :class:`BrokenPipeError`; :func:`keep_working_when_output_closes`
makes that stream quietly discard whatever follows (its descriptor now points at
``/dev/null``), and the run goes on to finish its recording, with the exit status it would
have had.  Python ignores SIGPIPE, so without this the first progress line after the
reader left ended the run with a traceback nobody saw and a partial recording.

::

    keep_working_when_output_closes()   # astrodyn.cli.main does it
"""

from __future__ import annotations

import os
import sys
from typing import Any, TextIO

__all__ = ["DropWhenClosed", "keep_working_when_output_closes"]


class DropWhenClosed:
    """A text stream (``sys.stdout`` / ``sys.stderr``) whose writes and flushes, once its
    reader has gone (:class:`BrokenPipeError`), go to ``/dev/null`` instead; ``closed_pipe``
    tells whether that happened.  Every other attribute is the wrapped stream's."""

    def __init__(self, stream: TextIO):
        self._stream = stream
        self.closed_pipe = False

    def _drop(self) -> None:
        self.closed_pipe = True
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            try:
                os.dup2(devnull, self._stream.fileno())  # the buffered text then flushes into /dev/null
            finally:
                os.close(devnull)
        except (OSError, ValueError):  # no descriptor (a StringIO in a test): drop in Python
            self._stream = open(os.devnull, "w")  # lives as long as the process

    def write(self, text: str) -> int:
        try:
            return self._stream.write(text)
        except BrokenPipeError:
            self._drop()
            return len(text)

    def flush(self) -> None:
        try:
            self._stream.flush()
        except BrokenPipeError:
            self._drop()
            try:
                self._stream.flush()
            except OSError:
                pass

    def __getattr__(self, name: str) -> Any:
        return getattr(self._stream, name)


def keep_working_when_output_closes() -> None:
    """Wrap ``sys.stdout`` and ``sys.stderr`` in :class:`DropWhenClosed` (once)."""
    for name in ("stdout", "stderr"):
        stream = getattr(sys, name)
        if stream is not None and not isinstance(stream, DropWhenClosed):
            setattr(sys, name, DropWhenClosed(stream))
