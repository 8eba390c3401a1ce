"""Hostile arguments to library calls: each call must be refused quickly, with an error
whose text names the offending argument (the tests' tables of ``(field, call)``), and a
time bound for calls that used to run without one."""

from __future__ import annotations

import signal
import time
from contextlib import contextmanager

import pytest


@contextmanager
def time_bound(seconds: float = 20.0):
    """Raise ``TimeoutError`` (not the error the test expects) in the main thread if the body
    runs longer than ``seconds`` (``SIGALRM``): a bound on calls that used to hang or run for
    hours, so a regression fails instead of hanging.  The alarm lands in Python code (scipy's
    loops, the splitting kernel's returns between chunks of steps)."""

    def expired(signum, frame):
        raise TimeoutError(f"no answer within {seconds} s: the call is not bounded")

    previous = signal.signal(signal.SIGALRM, expired)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0.0)
        signal.signal(signal.SIGALRM, previous)


def assert_refused_quickly(call, match: str, error: type[Exception] = ValueError, seconds: float = 2.0) -> None:
    """``call()`` raises ``error`` whose text matches the regex ``match`` (``re.search``),
    within ``seconds`` of wall time."""
    start = time.perf_counter()
    with pytest.raises(error, match=match):
        call()
    assert time.perf_counter() - start < seconds
