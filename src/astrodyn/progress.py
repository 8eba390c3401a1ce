"""The one progress printer of the long commands (``run``, ``replay``, ``sweep``, ``analyze``): a
line on stderr (stdlib only: every layer above the scene may use it).

On a terminal the line is rewritten in place twice a second (``\\r``); into a file or a
pipe (CI logs) a new line every 5 s, so logs stay short and readable.

::

    progress = Progress()
    while working:
        progress.show(lambda: f"sim t {t:.1f} s")  # the text is only built when it is printed
    progress.done(f"sim t {t:.1f} s")              # the last line, always printed
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import TextIO

__all__ = ["Progress"]


class Progress:
    """See the module docstring.  ``enabled=False`` prints nothing (``--quiet``)."""

    def __init__(self, stream: TextIO | None = None, enabled: bool = True):
        self.stream = sys.stderr if stream is None else stream
        self.enabled = enabled
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.period_s = 0.5 if self.tty else 5.0
        self._last = -float("inf")

    def due(self, now: float | None = None) -> bool:
        """Whether the next :meth:`show` prints."""
        return self.enabled and (time.monotonic() if now is None else now) - self._last >= self.period_s

    def show(self, line: Callable[[], str], now: float | None = None) -> bool:
        """Print ``line()`` if a period has passed since the last print; returns whether it did."""
        now = time.monotonic() if now is None else now
        if not self.due(now):
            return False
        self._last = now
        print(("\r" if self.tty else "") + line(), end="" if self.tty else "\n", file=self.stream, flush=True)
        return True

    def done(self, line: str) -> None:
        """Print the final line (ending the in-place line on a terminal)."""
        if self.enabled:
            print(("\r" if self.tty else "") + line, file=self.stream, flush=True)
