"""One stop-signal helper and one progress printer for every process (issue 12): a real
SIGTERM delivered to this process is recorded, the previous handler comes back; the
printer rewrites in place on a terminal and prints a line per period into a file."""

from __future__ import annotations

import io
import os
import signal

from astrodyn.progress import Progress
from astrodyn.signals import StopFlag, catch_stop_signals


def test_a_real_sigterm_is_recorded_and_the_old_handler_restored():
    before = signal.getsignal(signal.SIGTERM)
    stop = StopFlag()
    try:
        assert stop.why is None
        os.kill(os.getpid(), signal.SIGTERM)
        assert stop.why == "SIGTERM"
        os.kill(os.getpid(), signal.SIGINT)
        assert stop.why == "SIGINT"
    finally:
        stop.restore()
    assert signal.getsignal(signal.SIGTERM) is before
    got = []
    restore = catch_stop_signals(got.append)
    try:
        os.kill(os.getpid(), signal.SIGTERM)
    finally:
        restore()
    assert got == ["SIGTERM"]


class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_on_a_terminal_and_into_a_file():
    tty, log = _Tty(), io.StringIO()
    a, b = Progress(tty), Progress(log)
    built = []

    def line() -> str:
        built.append(1)
        return "sim t 1.0"

    assert a.show(line, now=100.0) and not a.show(line, now=100.2) and a.show(line, now=100.6)
    assert b.show(line, now=100.0) and not b.show(line, now=104.0) and b.show(line, now=105.1)
    assert len(built) == 4  # the text is built only when it is printed
    a.done("end")
    assert tty.getvalue() == "\rsim t 1.0\rsim t 1.0\rend\n"
    assert log.getvalue() == "sim t 1.0\nsim t 1.0\n"
    quiet = io.StringIO()
    assert not Progress(quiet, enabled=False).show(line) and quiet.getvalue() == ""
