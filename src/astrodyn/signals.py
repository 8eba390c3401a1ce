"""How every astrodyn process stops: SIGTERM, SIGINT (Ctrl-C) and SIGHUP (the terminal or
SSH session closed), :data:`STOP_SIGNALS`, each a request to stop cleanly.  Two ways, one
per kind of program:

* **Services** (logger, propagators, plant, viewer, run, serve, replay, router) run a loop:
  :func:`catch_stop_signals` / :class:`StopFlag` only record the signal's name, and the
  loop sees it and stops cleanly (a logger finishes its file, a propagator sends its
  end-of-run event).
* **File tools** (``recover``, ``merge``, ``export``, ``analyze``, ``sweep``) run straight
  through: :func:`interruptible` turns the signal into :class:`Interrupted` (a
  :class:`KeyboardInterrupt`), so their ``finally`` / ``except BaseException`` cleanups run
  (Python's default for SIGTERM and SIGHUP is to die at once, which left temporary files
  behind); the command ends with one line and exit 128 + the signal (130, 143, 129).  A
  :class:`MemoryError` (a memory limit) likewise ends it with one line and exit 1.
  :func:`deferred_interrupts` holds a signal back over steps that must not be cut (moving
  a set of finished files into place).

A third kind of signal is Ctrl-Z (SIGTSTP): :func:`catch_job_control` makes a process take
part in it (a supervisor stops its children first; a paced propagator counts the time
stopped, :func:`suspended_s`, and keeps its real-time schedule after ``fg``).

::

    stop = StopFlag()
    while not stop.why: ...              # "SIGTERM" / "SIGINT" / "SIGHUP" once one arrived
    stop.restore()                       # the previous handlers back (tests, in-process runs)

    @interruptible_main("astrodyn export")    # Ctrl-C, SIGTERM: one line, exit 128 + the signal
    def main(argv=None) -> int: ...
"""

from __future__ import annotations

import contextlib
import functools
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator

__all__ = ["STOP_SIGNALS", "STOP_SIGNAL_NAMES", "catch_stop_signals", "StopFlag", "Interrupted", "interruptible",
           "interruptible_main", "deferred_interrupts", "interrupt_received", "catch_job_control", "suspended_s"]

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


# --------------------------------------------------------------------------- file tools


class Interrupted(KeyboardInterrupt):
    """One of :data:`STOP_SIGNALS` received under :func:`interruptible`; ``signum`` says which."""

    def __init__(self, signum: int):
        self.signum = int(signum)
        super().__init__(signal.Signals(self.signum).name)


class _State:
    raised = False  # an Interrupted is on its way: later signals are ignored
    deferring = 0  # inside deferred_interrupts
    pending: int | None = None  # a signal that arrived while deferring
    received: int | None = None  # the first stop signal received under interruptible


def _on_signal(signum: int, frame) -> None:
    _State.received = _State.received or signum
    if _State.raised:
        return
    if _State.deferring:
        _State.pending = _State.pending or signum
        return
    _State.raised = True
    raise Interrupted(signum)


def interrupt_received() -> int | None:
    """The stop signal received under :func:`interruptible` (None before any): a loop that
    must stop can check it itself, as the :class:`Interrupted` raised for it can be lost
    (raised inside a garbage-collector callback or a ``__del__``, where Python prints and
    drops exceptions)."""
    return _State.received


def _on_unraisable(previous: Callable) -> Callable:
    """``sys.unraisablehook``: an :class:`Interrupted` Python dropped (a gc callback such as
    Dask's ``GCDiagnosis``, a ``__del__``) is as if never raised: the next stop signal raises
    again instead of being ignored for good (only SIGKILL then stopped the process)."""
    def hook(unraisable) -> None:
        if isinstance(unraisable.exc_value, Interrupted):
            _State.raised = False
            return
        previous(unraisable)

    return hook


def interruptible_main(prog: str) -> Callable[[Callable[..., int]], Callable[..., int]]:
    """Decorator for a command's ``main(argv=None) -> int``: each call runs it under
    :func:`interruptible` with the command's name ``prog`` (``"astrodyn export"``)."""

    def decorate(main: Callable[..., int]) -> Callable[..., int]:
        @functools.wraps(main)
        def run(argv: list[str] | None = None) -> int:
            return interruptible(prog, lambda: main(argv))

        return run

    return decorate


def interruptible(prog: str, run: Callable[[], int]) -> int:
    """``run()`` with :data:`STOP_SIGNALS` raising :class:`Interrupted`; its exit status, or
    128 + the signal after one line on stderr naming it.  A signal the parent made this
    process ignore (``nohup``, a background job) stays ignored.  Outside the main thread
    (where Python cannot handle signals) ``run()`` alone."""
    if threading.current_thread() is not threading.main_thread():
        return run()
    _State.raised, _State.deferring, _State.pending, _State.received = False, 0, None, None
    previous = {sig: signal.getsignal(sig) for sig in STOP_SIGNALS}
    previous_hook = sys.unraisablehook
    sys.unraisablehook = _on_unraisable(previous_hook)
    for sig, handler in previous.items():
        if handler is not signal.SIG_IGN:
            signal.signal(sig, _on_signal)
    try:
        return run()
    except KeyboardInterrupt as exc:  # Interrupted, or a Ctrl-C that came before the handler
        signum = getattr(exc, "signum", signal.SIGINT)
        print(f"{prog}: interrupted by {signal.Signals(signum).name}; no output was left half-written",
              file=sys.stderr)
        return 128 + signum
    except MemoryError as exc:  # a memory limit (ulimit -v, a container's): one line, not a traceback
        detail = " ".join(str(exc).split())
        print(f"{prog}: out of memory{f' ({detail})' if detail else ''}; no output was left half-written",
              file=sys.stderr)
        # the command's cleanups ran as the error unwound; what an allocation failure inside a C++
        # extension left behind may not be freed safely (matplotlib's Agg renderer: SIGSEGV at
        # exit under a 700 MB limit), so the process ends here, without the interpreter's teardown
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(1)
    finally:
        sys.unraisablehook = previous_hook
        _State.received = None
        for sig, handler in previous.items():
            signal.signal(sig, handler)


@contextlib.contextmanager
def deferred_interrupts() -> Iterator[None]:
    """A stop signal arriving inside the block raises :class:`Interrupted` only once
    the block is done (under :func:`interruptible`; elsewhere nothing changes)."""
    _State.deferring += 1
    try:
        yield
    finally:
        _State.deferring -= 1
    if not _State.deferring and _State.pending is not None and not _State.raised:
        signum, _State.pending = _State.pending, None
        _State.raised = True
        raise Interrupted(signum)


# --------------------------------------------------------------------------- Ctrl-Z


class _Suspension:
    total_s = 0.0  # time spent stopped by handled SIGTSTPs, s
    since: float | None = None  # monotonic time of the current stop
    continued_from_outside_at: float | None = None  # monotonic time of the last SIGCONT of a stop not ours


#: A SIGTSTP whose handler runs within this many seconds after that of a SIGCONT ending a stop
#: this process did not make is stale, and is dropped (:func:`catch_job_control`).
STALE_STOP_S = 0.05


def suspended_s() -> float:
    """Seconds this process has spent stopped by the SIGTSTPs it handled
    (:func:`catch_job_control`): a real-time schedule moves on by as much
    (:class:`astrodyn.service.propagator.Pacer`)."""
    return _Suspension.total_s


def catch_job_control(before_stop: Callable[[], None] | None = None,
                      after_continue: Callable[[float], None] | None = None) -> Callable[[], None]:
    """Take part in Ctrl-Z: on SIGTSTP call ``before_stop()``, then stop this process
    (SIGSTOP: a supervisor's children run in process groups with no parent in their session,
    where the kernel discards SIGTSTP's own stop); on the SIGCONT that continues it add the
    time stopped to :func:`suspended_s` and call ``after_continue(seconds)``.  Returns a
    function that puts the previous handlers back.  Main thread only (elsewhere nothing is
    installed); a SIGTSTP this process was made to ignore stays ignored.

    Python runs a handler only when the main thread is back in Python code, pending ones in
    increasing signal number (SIGCONT, 18, before SIGTSTP, 20).  A process whose main thread
    was held in a compiled call or a blocked ``put`` past its supervisor's wait is stopped
    by the supervisor with SIGSTOP (:class:`astrodyn.service.children.JobControl`); once
    continued, its SIGTSTP handler, pending all along, would stop it again, with no one left
    to continue it.  So a SIGTSTP handled right after (:data:`STALE_STOP_S`) a SIGCONT that
    ended a stop not of its own is dropped: that pause is over."""
    if threading.current_thread() is not threading.main_thread() or \
            signal.getsignal(signal.SIGTSTP) is signal.SIG_IGN:
        return lambda: None

    def on_stop(signum, frame) -> None:
        outside = _Suspension.continued_from_outside_at
        if outside is not None and time.monotonic() - outside < STALE_STOP_S:
            return  # pending since before a SIGSTOP from outside, which the SIGCONT just ended
        if before_stop is not None:
            before_stop()
        _Suspension.since = time.monotonic()
        os.kill(os.getpid(), signal.SIGSTOP)  # the SIGCONT handler runs once continued

    def on_continue(signum, frame) -> None:
        if _Suspension.since is None:  # not a stop of ours (a SIGSTOP from outside): nothing to count
            _Suspension.continued_from_outside_at = time.monotonic()
            return
        seconds = time.monotonic() - _Suspension.since
        _Suspension.total_s += seconds
        _Suspension.since = None
        if after_continue is not None:
            after_continue(seconds)

    previous = {signal.SIGCONT: signal.signal(signal.SIGCONT, on_continue),
                signal.SIGTSTP: signal.signal(signal.SIGTSTP, on_stop)}

    def restore() -> None:
        for sig, handler in previous.items():
            signal.signal(sig, handler)

    return restore
