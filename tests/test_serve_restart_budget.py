"""serve restarts a dying propagator within a rate budget, not a count over its life (svc probe F1).

The spec (docs/reliability.md, ``astrodyn.service.serve``): a process is restarted unless
its death is its 5th within the budget's window (``RestartBudget``: 5 deaths in 60 s, as
``run``); one that is not restarted is said on stderr at once, ``status`` says
``degraded`` and why under that process, the others go on, and ``stop`` ends serve with
exit 1.  Before, serve counted every restart since it started: the 6th death, however far
apart from the others, left the process down while ``status`` said ``running``.

The window is shrunk to :data:`WINDOW_S` (serve's hidden ``--restart-window``) so the test
takes seconds: deaths :data:`SPACING_S` apart (never 5 within a window) are each restarted,
6 of them (one more than the old lifetime limit); then a burst (a kill as soon as each
restart is seen) is refused at the death that makes 5 within the window.
"""

from __future__ import annotations

import os
import signal
import threading
import time
from pathlib import Path

import pytest

from _serve_control import serve_demo, serve_status, wait_until
from astrodyn import bus

LIMIT = 5  # deaths within the window: the one that makes this many is not restarted (the spec)
WINDOW_S = 3.0  # the test's budget window, wall seconds
SPACING_S = 1.05  # > WINDOW_S / (LIMIT - 1): at most LIMIT - 1 deaths in any window, with 1.2 s to spare
VICTIM = "attitude"


def _restarts_of(status: dict) -> list[dict]:
    return [r for r in status["restarts"] if r["process"] == VICTIM]


def _serve_reading_stderr(out: Path, *flags: str, **popen_kw) -> tuple:
    """:func:`serve_demo` at rate 10 (at most 90 s of wall time) with ``flags``; its start
    line, and the list of its stderr lines, filled by a daemon thread as they come (and
    that thread): ``(Popen, start line, lines, thread)``."""
    serve, hello = serve_demo(out, "10", *flags, max_wall_s=90, **popen_kw)
    err_lines: list[str] = []
    reader = threading.Thread(target=lambda: err_lines.extend(iter(serve.stderr.readline, "")), daemon=True)
    reader.start()
    return serve, hello, err_lines, reader


def _wait(ready, timeout_s: float, what):
    """:func:`wait_until`, polling every 0.03 s (a restart is seen as soon as it is reported)."""
    return wait_until(ready, timeout_s, what, poll_s=0.03)


def test_deaths_spread_wider_than_the_budget_are_each_restarted_and_a_burst_is_refused_and_reported(tmp_path):
    serve, hello, err_lines, reader = _serve_reading_stderr(tmp_path / "demo.mcap", "--restart-window", str(WINDOW_S))
    try:
        token = hello["control_token"]
        kills: list[float] = []  # monotonic time of each SIGKILL this test sent
        with bus.open_session(connect=[hello["hub"]]) as s:
            status = serve_status(s, "demo", token, timeout_s=10)

            def kill_current() -> None:
                pid = status()["processes"][VICTIM]["pid"]
                os.kill(pid, signal.SIGKILL)  # a process of the serve this test started, named by its status
                kills.append(time.monotonic())

            def restarted(n: int):
                st = status()
                return st if len(_restarts_of(st)) >= n and st["processes"][VICTIM]["running"] else None

            _wait(lambda: status()["processes"][VICTIM]["running"], 30, "the victim never ran")
            # deaths never LIMIT within a window: each is restarted, the 6th too (the old lifetime limit was 5)
            for k in range(LIMIT + 1):
                if kills:
                    time.sleep(max(0.0, kills[-1] + SPACING_S - time.monotonic()))
                kill_current()
                st = _wait(lambda k=k: restarted(k + 1), 20,
                           lambda k=k: f"kill {k + 1} (spaced {SPACING_S} s) was not restarted: {err_lines[-3:]}")
                assert st["state"] == "running" and not st["failures"], st
            assert all(b - a >= SPACING_S for a, b in zip(kills, kills[1:], strict=False))
            # a burst: each restarted process killed at once, until serve refuses one
            burst = 0
            while not any("not restarted" in line for line in err_lines):
                assert burst < LIMIT, f"{burst} quick kills and still restarted: {err_lines[-5:]}"
                n = len(_restarts_of(status()))
                kill_current()
                burst += 1
                _wait(lambda n=n: any("not restarted" in line for line in err_lines) or restarted(n + 1), 20,
                      "neither restarted nor refused")
            # refused only at the death that made LIMIT within the window (kill times, 0.3 s for detection)
            assert sum(1 for t in kills if kills[-1] - t < WINDOW_S - 0.3) >= LIMIT, kills
            (said,) = [line for line in err_lines if "not restarted" in line]
            assert f"process {VICTIM} died {LIMIT} times within {WINDOW_S:g} s" in said, said
            st = status()
            assert st["state"] == "degraded", st
            assert "not restarted" in st["processes"][VICTIM]["not_restarted"] and not st["processes"][VICTIM]["running"]
            assert any("not restarted" in f for f in st["failures"]), st["failures"]
            t_orbit = st["processes"]["orbit"]["t"]  # the others go on
            _wait(lambda: (status()["processes"]["orbit"]["t"] or 0) > (t_orbit or 0), 10, "orbit stopped too")
            (final,) = bus.send_control(s, "demo", "stop", token=token, timeout_s=60)
        serve.communicate(timeout=60)
        reader.join(timeout=10)
        assert serve.returncode == 1, err_lines[-10:]  # a process left down: serve failed (the documented status)
        assert any("not restarted" in f for f in final["failures"]) and Path(final["file"]).exists(), final
    finally:
        if serve.poll() is None:  # only the serve this test started, by its PID (its children share its fate)
            serve.kill()
            serve.communicate(timeout=30)


@pytest.mark.slow  # CI time (10 s; run's same-error test (test_service.py) covers the rule serve takes from runner)
def test_a_propagator_that_fails_the_same_way_at_the_same_step_is_not_restarted_for_ever(tmp_path):
    """With the rate budget alone, a deterministic failure slower than 5 deaths a minute would be
    restarted for ever (the lifetime limit used to end it).  As in ``run``: the same error 3
    times in a row, each time restarted at the same step and recording none, is not restarted
    again.  The budget's window is shrunk to 0.1 s here, so only that rule can stop it."""
    from test_service import BOOM_SITECUSTOMIZE  # the orbit engine raises the same error at every step

    site = tmp_path / "site"
    site.mkdir()
    (site / "sitecustomize.py").write_text(BOOM_SITECUSTOMIZE)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")])}
    serve, hello, err_lines, reader = _serve_reading_stderr(tmp_path / "boom.mcap", "--restart-window", "0.1", env=env)
    try:
        token = hello["control_token"]
        with bus.open_session(connect=[hello["hub"]]) as s:
            status = serve_status(s, "demo", token, timeout_s=10)
            _wait(lambda: any("not restarted" in line for line in err_lines), 60,
                  lambda: f"never refused: {err_lines[-5:]}")
            st = status()
            assert st["state"] == "degraded" and not st["processes"]["orbit"]["running"], st
            why = st["processes"]["orbit"]["not_restarted"]
            assert "same error 3 times in a row" in why and "a deterministic failure of this model" in why, why
            assert len([r for r in st["restarts"] if r["process"] == "orbit"]) == 2, st["restarts"]
            (final,) = bus.send_control(s, "demo", "stop", token=token, timeout_s=60)
        serve.communicate(timeout=60)
        reader.join(timeout=10)
        assert serve.returncode == 1 and any("same error" in f for f in final["failures"]), err_lines[-10:]
    finally:
        if serve.poll() is None:  # only the serve this test started, by its PID (its children share its fate)
            serve.kill()
            serve.communicate(timeout=30)
