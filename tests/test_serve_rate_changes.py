"""Rate changes, the start line and restarts while paused of a real ``astrodyn serve``
(session 20 probe A, F1, F5, F11).

* F1: after ``rate 1e6`` (a light scene reaches about x1500, flat out) then ``rate 10``,
  serve anchored every process to a schedule it extrapolated from a heartbeat at the stated
  1e6: up to 500,000 sim s ahead of any process, which then raced to it for minutes while
  ``status`` said 10.  Checked against the wall clock of the test: after ``rate 10`` the sim
  time goes on at x10 (within what the heartbeats' age and the output step allow), and
  orbit and attitude stay together.
* F5: with ``--rate inf`` the first stdout line said ``"real_time_factor": Infinity``, not
  JSON (jq read 1.8e308, JSON.parse refused it).  Both lines are read by a strict parser.
* F11: a propagator restarted while serve is paused ran on (about 3 s of sim time at x10)
  until the pause was sent again.  Checked on the states it publishes: none past where it
  was paused, then it goes on after ``resume``.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time
from pathlib import Path

import pytest

from _serve_control import start_serve, wait_until
from astrodyn import bus, messages

pytestmark = pytest.mark.network

SCENARIO = "ratechg"
OUTPUT_HZ = 10.0  # the config's rate: one output step is 0.1 s of sim time
CONFIG = f"""\
[scenario]
name = "{SCENARIO}"
epoch = "2026-03-20T12:00:00 TDB"
duration = "100000 s"
rate = "{OUTPUT_HZ:g} Hz"
real_time_factor = 10.0
[[bodies]]
name = "sat1"
[bodies.orbit]
a = "7000 km"
e = 0.001
i = "51.64 deg"
[bodies.attitude]
w = ["0.01 rad/s", "0.02 rad/s", "0.1 rad/s"]
inertia = ["10 kg m2", "20 kg m2", "30 kg m2"]
"""
#: Wall seconds a heartbeat may take, beyond its period, to be sent and heard on a loaded
#: 2-core machine (scheduling, the bus): added to the age of what ``status`` reports.
DELIVERY_S = 0.25


def _start_serve(tmp_path: Path, *flags: str, parse_constant=None) -> tuple[subprocess.Popen, dict]:
    """:func:`start_serve` of the one-body config above (at most 90 s of wall time: a first
    run compiles the kernels) in ``tmp_path``: ``(Popen, its start line)``, read by
    ``json.loads`` with ``parse_constant``."""
    config = tmp_path / "ratechg.toml"
    config.write_text(CONFIG)
    return start_serve(config, tmp_path / "r.mcap", *flags, max_wall_s=90, parse_constant=parse_constant, cwd=tmp_path)


def _stop(serve: subprocess.Popen) -> None:
    """Stop the serve this test started, by its PID (its children share its fate)."""
    if serve.poll() is None:
        os.kill(serve.pid, signal.SIGKILL)
        serve.communicate(timeout=30)


def _status(s, token: str) -> dict:
    return bus.send_control(s, SCENARIO, "status", token=token, timeout_s=10, require_reply=True)[0]


def _times(s, token: str) -> dict[str, float | None]:
    procs = _status(s, token)["processes"]
    return {k: procs[k]["t"] for k in ("orbit", "attitude")}


def _reject_constant(name: str):
    raise ValueError(f"not JSON: {name}")


@pytest.mark.slow  # CI time (8-11 s): test_serve_rate_sync keeps rate inf then a finite rate in make test
def test_serve_from_rate_inf_then_1e6_then_10_prints_strict_json_and_goes_on_at_x10_with_orbit_and_attitude_together(
        tmp_path):
    """One serve for F5, F1 and D1 (CI time): started at ``--rate inf``, its first and last
    lines are strict JSON; pause, resume and at once ``rate 10``: together; ``rate 1e6``,
    then ``rate 10``: x10 from then on."""
    rate = 10.0
    serve, hello = _start_serve(tmp_path, "--rate", "inf", parse_constant=_reject_constant)  # Infinity / NaN refused
    try:
        assert hello["real_time_factor"] == "inf", hello  # as the status reply says
        token = hello["control_token"]
        with bus.open_session(connect=[hello["hub"]]) as s:
            assert _status(s, token)["real_time_factor"] == "inf"
            wait_until(lambda: all((t or 0) > 1.0 for t in _times(s, token).values()), 60, "the propagators never ran",
                       poll_s=0.1)
            together = rate * (bus.HEARTBEAT_PERIOD_S + DELIVERY_S) + 1.0 / OUTPUT_HZ
            # probe D, D1: a rate change within half a second of a resume (the heartbeats still
            # say paused) anchored to those stale times and left the two on two schedules
            bus.send_control(s, SCENARIO, "pause", token=token, timeout_s=10, require_reply=True)
            time.sleep(2 * bus.HEARTBEAT_PERIOD_S)  # their heartbeats say paused
            bus.send_control(s, SCENARIO, "resume", token=token, timeout_s=10, require_reply=True)  # at inf again
            time.sleep(0.3)  # within a heartbeat period: the last heartbeats still say paused
            bus.send_control(s, SCENARIO, "rate", {"factor": rate}, token=token, timeout_s=10, require_reply=True)
            wait_until(lambda: abs((t := _times(s, token))["orbit"] - t["attitude"]) <= together, 30,
                       "orbit and attitude did not come together after resume, rate 10", poll_s=0.1)
            bus.send_control(s, SCENARIO, "rate", {"factor": 1e6}, token=token, timeout_s=10, require_reply=True)
            # more than a heartbeat period: each propagator has beaten at 1e6 (what the old
            # estimate advanced by its age times 1e6)
            time.sleep(bus.HEARTBEAT_PERIOD_S + 0.1)
            bus.send_control(s, SCENARIO, "rate", {"factor": rate}, token=token, timeout_s=10, require_reply=True)
            wall0, t0 = time.monotonic(), _times(s, token)
            # the one behind (1e6 drove them apart) catches up as fast as it can, then stays with
            # the other: the two agree to what the age of two heartbeats allows
            wait_until(lambda: abs((t := _times(s, token))["orbit"] - t["attitude"]) <= together, 30,
                       "orbit and attitude did not come together", poll_s=0.1)
            time.sleep(max(0.0, wall0 + 3.0 - time.monotonic()))
            reply = _status(s, token)
            wall1 = time.monotonic()
            t1 = {k: reply["processes"][k]["t"] for k in ("orbit", "attitude")}
            bus.send_control(s, SCENARIO, "stop", token=token, timeout_s=60)
        out, err = serve.communicate(timeout=60)
    finally:
        _stop(serve)
    assert serve.returncode == 0, err[-3000:]
    json.loads(out.strip().splitlines()[-1], parse_constant=_reject_constant)
    assert reply["real_time_factor"] == rate, reply
    # each t in a status reply is a heartbeat's: sent at most a period (+ delivery) before the
    # query, and the last step published, which pacing holds at most one output step behind
    # the schedule: a difference of two is off the true one by at most this much
    tolerance = rate * (bus.HEARTBEAT_PERIOD_S + DELIVERY_S) + 2.0 / OUTPUT_HZ
    lead0, lead1 = max(t0.values()), max(t1.values())
    assert abs((lead1 - lead0) - rate * (wall1 - wall0)) <= tolerance, (t0, t1, wall1 - wall0)
    assert abs(t1["orbit"] - t1["attitude"]) <= together, t1  # and stayed together, paced


@pytest.mark.slow  # CI time (14 s: a serve, a pause, the logger's flush, a restart and its start-up)
def test_a_propagator_restarted_while_serve_is_paused_publishes_nothing_until_resume(tmp_path):
    serve, hello = _start_serve(tmp_path, "--rate", "100")  # one output step per 1 ms of wall time
    orbit_seqs: list[int] = []
    starts: list[str] = []
    try:
        token = hello["control_token"]
        with bus.open_session(connect=[hello["hub"]]) as s:
            s.declare_subscriber(messages.orbit_key(SCENARIO, "sat1"),
                                 lambda sample: orbit_seqs.append(json.loads(sample.payload.to_bytes())["seq"]))
            s.declare_subscriber(messages.event_key(SCENARIO), lambda sample: starts.extend(
                [e["process"]] if (e := json.loads(sample.payload.to_bytes()))["kind"] == "start" else []))
            wait_until(lambda: all((t or 0) > 5.0 for t in _times(s, token).values()), 60, "the propagators never ran",
                       poll_s=0.1)
            bus.send_control(s, SCENARIO, "pause", token=token, timeout_s=10, require_reply=True)
            # both stand still (two status replies a heartbeat period apart agree), and the
            # logger has flushed (every 1 s) up to there: the restart continues from that step
            held = [_times(s, token)]
            wait_until(lambda: (time.sleep(bus.HEARTBEAT_PERIOD_S + 0.1) or held.append(_times(s, token))
                                or held[-1] == held[-2]), 10, "the propagators did not pause", poll_s=0.1)
            time.sleep(1.5)
            paused_seq, orbit_starts = max(orbit_seqs), starts.count("orbit")
            os.kill(_status(s, token)["processes"]["orbit"]["pid"], signal.SIGKILL)  # a child of our serve
            wait_until(lambda: starts.count("orbit") > orbit_starts, 30, "orbit was not restarted", poll_s=0.1)
            # the old code published at once and ran until serve's pause, re-sent at most once a
            # second, reached it: two heartbeat periods plus that second cover it
            time.sleep(1.0 + 2 * bus.HEARTBEAT_PERIOD_S)
            after_restart = max(orbit_seqs)
            restarts = _status(s, token)["restarts"]
            bus.send_control(s, SCENARIO, "resume", token=token, timeout_s=10, require_reply=True)
            wait_until(lambda: max(orbit_seqs) > paused_seq + 10, 20, "the restarted orbit did not go on after resume",
                       poll_s=0.1)
            bus.send_control(s, SCENARIO, "stop", token=token, timeout_s=60)
        serve.communicate(timeout=60)
    finally:
        _stop(serve)
    assert [r["process"] for r in restarts] == ["orbit"], restarts
    assert after_restart <= paused_seq + 1, (paused_seq, after_restart, restarts)
