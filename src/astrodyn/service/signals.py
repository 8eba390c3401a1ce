"""How every astrodyn process stops: SIGTERM, SIGINT (Ctrl-C) and SIGHUP (the terminal or
SSH session closed) become a request to stop.

One helper for all of them (logger, propagators, viewer, run, serve, replay, router): the
handler only records the signal's name; the process's own loop sees it and stops cleanly
(a logger finishes its file, a propagator sends its end-of-run event).

>>> stop = StopFlag()                    # doctest: +SKIP
>>> while not stop.why: ...              # "SIGTERM" / "SIGINT" / "SIGHUP" once one arrived
>>> stop.restore()                       # the previous handlers back (tests, in-process runs)
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable

__all__ = ["STOP_SIGNALS", "STOP_SIGNAL_NAMES", "catch_stop_signals", "StopFlag"]

#: SIGHUP too: without a handler it ended ``serve`` at once, in the middle of a recording
#: (a partial file, its work directory left), when the terminal that started it closed.
STOP_SIGNALS = (signal.SIGTERM, signal.SIGINT, signal.SIGHUP)
STOP_SIGNAL_NAMES = tuple(sig.name for sig in STOP_SIGNALS)


def catch_stop_signals(callback: Callable[[str], None]) -> Callable[[], None]:
    """Call ``callback(name)`` ("SIGTERM", "SIGINT" or "SIGHUP") when one of :data:`STOP_SIGNALS`
    arrives; return a function that puts the previous handlers back.  Python handles
    signals in the main thread only: elsewhere nothing is installed and the returned
    function does nothing."""
    if threading.current_thread() is not threading.main_thread():
        return lambda: None
    previous = {sig: signal.signal(sig, lambda s, f: callback(signal.Signals(s).name)) for sig in STOP_SIGNALS}

    def restore() -> None:
        for sig, handler in previous.items():
            signal.signal(sig, handler)

    return restore


class StopFlag:
    """The common case of :func:`catch_stop_signals`: ``why`` holds the name of the last
    stop signal received (None before any); :meth:`restore` uninstalls."""

    def __init__(self) -> None:
        self.why: str | None = None
        self.restore = catch_stop_signals(self.set)

    def set(self, why: str) -> None:
        self.why = why
