"""Driving a running ``astrodyn serve`` from a test: its status over the control channel,
and waiting (wall clock) until it reports what the test needs."""

from __future__ import annotations

import json
import time
from collections.abc import Callable

from astrodyn import bus


def serve_status(session, scenario: str, token: str) -> Callable[[], dict]:
    """A callable that asks the serve of ``scenario`` for its ``status`` (the reply dict,
    fresh on each call) through the Zenoh ``session``, with the control ``token``."""

    def status() -> dict:
        return bus.send_control(session, scenario, "status", token=token)[0]

    return status


def wait_until(ready: Callable[[], object], timeout_s: float, what: str, poll_s: float = 0.2) -> None:
    """Call ``ready()`` every ``poll_s`` s until it returns a true value; fail with ``what``
    once ``timeout_s`` s of wall time have passed without it."""
    deadline = time.monotonic() + timeout_s
    while not ready():
        assert time.monotonic() < deadline, what
        time.sleep(poll_s)


def read_run_start(stderr, timeout_s: float = 120.0) -> dict:
    """What the start lines of ``astrodyn run`` (without ``--quiet`` on stderr, read from the
    text stream ``stderr`` line by line) say: ``{"hub": endpoint, "token": control token
    file, "lines": the text read}``, read until both are seen; AssertionError with the lines
    read if the run ends or ``timeout_s`` passes first."""
    found: dict = {}
    lines = []
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and not ("hub" in found and "token" in found):
        line = stderr.readline()
        if not line:
            break
        lines.append(line)
        if line.startswith("  bus "):
            found["hub"] = line.split()[1].rstrip(":")
        if line.startswith("  control token "):
            found["token"] = line.split()[2].rstrip(":")
    assert "hub" in found and "token" in found, "".join(lines)
    found["lines"] = "".join(lines)
    return found


def stop_serve(proc, settle_s: float = 1.0, timeout_s: float = 90.0) -> tuple[str, str, dict]:
    """End a ``serve`` the test started (``subprocess.Popen`` with text pipes) as a user does:
    after ``settle_s``, SIGTERM; returns ``(stdout, stderr, its final JSON summary)``.  It
    is SIGKILLed (by PID) if it does not end within ``timeout_s``, and the test fails."""
    import signal

    time.sleep(settle_s)
    proc.send_signal(signal.SIGTERM)
    try:
        stdout, stderr = proc.communicate(timeout=timeout_s)
    except Exception:
        proc.kill()
        proc.communicate()
        raise
    return stdout, stderr, json.loads(stdout.strip().splitlines()[-1])


def serve_demo(out, rate: str) -> tuple:
    """``astrodyn serve`` of configs/demo.toml at ``rate`` into ``out`` (at most 120 s of
    wall time) and the start line it printed (hub, control token): ``(Popen, dict)``.  One
    that did not start is stopped here (by PID) and the test fails with its stderr."""
    import subprocess
    import sys
    from pathlib import Path

    from astrodyn.service.children import stop_process

    config = Path(__file__).resolve().parents[1] / "configs" / "demo.toml"
    serve = subprocess.Popen([sys.executable, "-m", "astrodyn", "serve", str(config), "--out", str(out), "--rate",
                              str(rate), "--max-wall", "120"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        return serve, json.loads(serve.stdout.readline())
    except ValueError:
        stop_process(serve)
        raise AssertionError(serve.stderr.read()[-3000:]) from None
