"""Driving a running ``astrodyn serve`` from a test: its status over the control channel,
and waiting (wall clock) until it reports what the test needs."""

from __future__ import annotations

import json
import time
from collections.abc import Callable

from astrodyn import bus


def serve_status(session, scenario: str, token: str, timeout_s: float = 5.0) -> Callable[[], dict]:
    """A callable that asks the serve of ``scenario`` for its ``status`` (the reply dict,
    fresh on each call) through the Zenoh ``session``, with the control ``token``, waiting
    at most ``timeout_s`` s for the reply."""

    def status() -> dict:
        return bus.send_control(session, scenario, "status", token=token, timeout_s=timeout_s)[0]

    return status


def wait_until(ready: Callable[[], object], timeout_s: float, what: str | Callable[[], str], poll_s: float = 0.2):
    """Call ``ready()`` every ``poll_s`` s until it returns a true value, and return that
    value; fail with ``what`` (a string, or a callable that gives it then, e.g. from the
    lines read by that time) once ``timeout_s`` s of wall time have passed without it."""
    deadline = time.monotonic() + timeout_s
    while not (value := ready()):
        assert time.monotonic() < deadline, what() if callable(what) else what
        time.sleep(poll_s)
    return value


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


def start_serve(config, out, *flags: str, max_wall_s: float = 120, parse_constant=None, **popen_kw) -> tuple:
    """``astrodyn serve`` of ``config`` into ``out`` with ``--max-wall max_wall_s`` (s of wall
    time) and the further ``flags`` (e.g. ``--rate``), started with ``subprocess.Popen``
    (text pipes; ``popen_kw``: e.g. ``env``, ``cwd``), and its start line (stdout's first,
    JSON: hub, control token, ...), read by ``json.loads`` with ``parse_constant``:
    ``(Popen, dict)``.  One that printed no such line is stopped here (by PID) and the test
    fails with that line, the parser's error and its stderr."""
    import subprocess
    import sys

    from astrodyn.service.children import stop_process

    serve = subprocess.Popen([sys.executable, "-m", "astrodyn", "serve", str(config), "--out", str(out), "--max-wall",
                              f"{max_wall_s:g}", *flags], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             **popen_kw)
    line = serve.stdout.readline()
    try:
        return serve, json.loads(line, parse_constant=parse_constant)
    except ValueError as exc:
        stop_process(serve)
        raise AssertionError(f"start line {line!r}: {exc}\n{serve.stderr.read()[-3000:]}") from None


def serve_demo(out, rate, *flags: str, max_wall_s: float = 120, **popen_kw) -> tuple:
    """:func:`start_serve` of configs/demo.toml at ``--rate rate`` (at most ``max_wall_s`` s
    of wall time, 120 unless given): ``(Popen, start line)``."""
    from pathlib import Path

    config = Path(__file__).resolve().parents[1] / "configs" / "demo.toml"
    return start_serve(config, out, "--rate", str(rate), *flags, max_wall_s=max_wall_s, **popen_kw)
