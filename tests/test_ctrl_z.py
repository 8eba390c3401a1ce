"""Ctrl-Z (SIGTSTP) on `astrodyn run` or `astrodyn serve` pauses the whole run, and `fg`
(SIGCONT) continues it with nothing lost (docs/reliability.md, "Ctrl-Z").

Every child runs in its own session, so the terminal's SIGTSTP reaches the supervisor
alone: before, Ctrl-Z stopped the supervisor while its children ran on in the background.
Now the supervisor stops every child's process group, then itself, and continues them on
SIGCONT (`astrodyn.service.children.JobControl`).  Paced (`serve`), the propagators go on
in real time from where they were, not racing through the sim time the pause covered.

A lockstep plant waits `control.timeout` for its controllers: that wait is measured on the
plant's listening clock (`astrodyn.bus.ListeningClock`), so a pause of the whole run that
stops a controller before it answers (a paused container stops processes in any order) is
not taken for a controller that fails to answer.

Real processes and real signals; every process is signalled by its PID, loops are bounded.
"""

from __future__ import annotations

import contextlib
import json
import os
import queue
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import psutil
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _recordings import children_by_kind, one_satellite_scene, run_while
from _serve_control import serve_demo, stop_serve, wait_until
from astrodyn import bus
from astrodyn.recording import load
from astrodyn.service.children import stop_process

pytestmark = pytest.mark.network

ROOT = Path(__file__).resolve().parent.parent
STEPS = 60_001  # 10 Hz over 6000 s: the children run for seconds after the pause


def _states(pids) -> list[str]:
    out = []
    for pid in pids:
        try:
            out.append(psutil.Process(pid).status())
        except psutil.NoSuchProcess:
            out.append("gone")
    return out


def test_ctrl_z_pauses_every_process_of_a_run_and_fg_continues_it(tmp_path):
    config = tmp_path / "ctrlz.toml"
    config.write_text(one_satellite_scene("ctrlz", "6000 s", "10 Hz"))
    out, result = tmp_path / "ctrlz.mcap", tmp_path / "result.json"
    partial = tmp_path / "ctrlz.partial.mcap"
    seen = {}

    def ctrl_z_then_fg(supervisor: int) -> None:
        children = children_by_kind(supervisor)
        assert sorted(children.values()) == ["attitude", "logger", "orbit"]
        os.kill(supervisor, signal.SIGTSTP)  # what the terminal sends on Ctrl-Z
        wait_until(lambda: set(_states([supervisor, *children])) == {psutil.STATUS_STOPPED}, 10,
                   f"not every process stopped: {_states([supervisor, *children])}", poll_s=0.05)
        size = partial.stat().st_size
        time.sleep(2.0)
        seen["grew"] = partial.stat().st_size - size  # nothing recorded while paused
        os.kill(supervisor, signal.SIGCONT)  # what the shell sends on fg
        wait_until(lambda: psutil.STATUS_STOPPED not in _states([supervisor, *children]), 10,
                   f"still stopped after SIGCONT: {_states([supervisor, *children])}", poll_s=0.05)

    rc, err = run_while([str(config), "--out", str(out), "--json", str(result), "--quiet"], partial, 1_000_000,
                        ctrl_z_then_fg)
    assert rc == 0, err
    assert seen["grew"] == 0
    run = json.loads(result.read_text())
    assert run["restarts"] == [], run["restarts"]
    log = run["logger"]
    assert log["missing"] == 0 and log["duplicates"] == 0 and log["states"] == 2 * STEPS, log


def test_a_run_killed_while_paused_leaves_no_stopped_child_behind(tmp_path):
    """``kill -9`` of a run stopped by Ctrl-Z: its children, stopped too, got the supervisor's
    death signal (``PR_SET_PDEATHSIG`` SIGTERM) but a stopped process does not act on it,
    so before they stayed stopped for good (two propagators of a test run were found stopped,
    parent PID 1, 78 min later).  Now the pause guard continues them and they end as if the
    supervisor had been killed while running; the logger's file keeps what it holds."""
    config = tmp_path / "killed.toml"
    config.write_text(one_satellite_scene("killed", "6000 s", "10 Hz"))
    out, partial = tmp_path / "killed.mcap", tmp_path / "killed.partial.mcap"
    children: dict[int, str] = {}

    def ctrl_z_then_kill(supervisor: int) -> None:
        children.update(children_by_kind(supervisor))
        os.kill(supervisor, signal.SIGTSTP)
        wait_until(lambda: set(_states([supervisor, *children])) == {psutil.STATUS_STOPPED}, 10,
                   f"not every process stopped: {_states([supervisor, *children])}", poll_s=0.05)
        os.kill(supervisor, signal.SIGKILL)

    rc, _ = run_while([str(config), "--out", str(out), "--quiet"], partial, 1_000_000, ctrl_z_then_kill)
    assert rc == -signal.SIGKILL
    try:
        wait_until(lambda: set(_states(children)) == {"gone"} or
                   set(_states(children)) <= {"gone", psutil.STATUS_ZOMBIE}, 15,
                   f"children left behind: {dict(zip(children.values(), _states(children)))}", poll_s=0.1)
    finally:
        for pid in children:  # only the processes this run started
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
    run = load(partial)  # the logger finished its file (it stopped as on SIGTERM): what it holds is whole
    states = [c for c in run.channels.values() if c.kind in ("orbit", "attitude")]
    # (not both kinds: with a cold kernel cache one propagator may still compile when the other has sent 1 MB)
    assert states and all(np.array_equal(c.seq, np.arange(len(c))) for c in states)


# slow (13 s; CI time): Ctrl-Z of a run above covers the job control serve shares
@pytest.mark.slow
def test_serve_resumes_in_real_time_from_where_ctrl_z_paused_it(tmp_path):
    """At x20 a 5 s pause would be 100 s of sim time; after fg the propagators go on from
    where they were at x20, instead of running flat out until they are back on the old schedule."""
    rate, paused_s = 20.0, 5.0
    serve, hello = serve_demo(tmp_path / "serve.mcap", rate)
    try:
        with bus.open_session(connect=[hello["hub"]]) as s:
            def t_sim() -> float | None:
                procs = bus.send_control(s, "demo", "status", token=hello["control_token"])[0]["processes"]
                ts = [procs[k]["t"] for k in ("orbit", "attitude")]
                return None if None in ts else min(ts)

            wait_until(lambda: (t_sim() or 0.0) > 2 * rate, 90, "serve did not reach 2 s of real time")
            before = t_sim()
            os.kill(serve.pid, signal.SIGTSTP)
            time.sleep(paused_s)
            os.kill(serve.pid, signal.SIGCONT)
            time.sleep(1.0)
            wait_until(lambda: t_sim() is not None, 30, "serve did not answer after SIGCONT")
            after = t_sim()
        # ~1 s of real time since the continue (plus the query's own latency) at x20; the
        # race through the pause would add 100 s of sim time
        assert after - before < rate * (1.0 + paused_s / 2), (before, after)
        _, err, summary = stop_serve(serve, settle_s=0.0)
        assert serve.returncode == 0, err[-3000:]
        assert summary["restarts"] == [] and summary["failures"] == [], summary
    finally:
        stop_process(serve)


@pytest.mark.slow  # CI time: the run and serve cases above pause whole runs in make test
def test_a_lockstep_plant_does_not_time_out_a_controller_paused_with_it(tmp_path):
    """The whole run paused in the worst order: the controller before it answers, then the
    plant waiting for that answer, for longer than control.timeout.  Before the fix the
    plant's deadline had passed when it was continued, and the run failed naming the
    controller; the plant now counts the pause as 1 s at most."""
    config = tmp_path / "slew.toml"
    text = (ROOT / "configs" / "slew.toml").read_text()
    config.write_text(text.replace('duration = "180 s"', 'duration = "600 s"').replace('timeout = "10 s"',
                                                                                        'timeout = "2.5 s"'))
    out, result = tmp_path / "slew.mcap", tmp_path / "result.json"

    def pause_controller_then_plant(supervisor: int) -> None:
        children = {c.pid: " ".join(c.cmdline()) for c in psutil.Process(supervisor).children()}
        plant = next(pid for pid, cmd in children.items() if "astrodyn.service.plant" in cmd)
        controller = next(pid for pid, cmd in children.items() if "slew_pd.py" in cmd)
        os.killpg(controller, signal.SIGSTOP)  # its group: the controller started by a shell line
        time.sleep(0.3)  # the plant sends its next tick and waits for the answer
        os.kill(plant, signal.SIGSTOP)
        time.sleep(5.0)
        os.kill(plant, signal.SIGCONT)
        time.sleep(0.2)
        os.killpg(controller, signal.SIGCONT)

    rc, err = run_while([str(config), "--out", str(out), "--json", str(result), "--quiet", "--controller",
                         f"{sys.executable} {ROOT / 'examples' / 'slew_pd.py'}"], tmp_path / "slew.partial.mcap",
                        300_000, pause_controller_then_plant)
    assert rc == 0, err
    run = json.loads(result.read_text())
    assert run["logger"]["missing"] == 0, run["logger"]


def _line(lines: queue.Queue, timeout_s: float) -> str:
    try:
        return lines.get(timeout=timeout_s)
    except queue.Empty:
        raise AssertionError(f"no line from the child in {timeout_s} s (is it stopped?)") from None


_HELD_CHILD = """
import hashlib, sys, threading, time
from astrodyn.signals import catch_job_control, suspended_s
catch_job_control()
main = threading.main_thread().ident

def say_ready():  # once the main thread is in the call (which lets other threads run meanwhile)
    while sys._current_frames()[main].f_lineno != CALL_LINE:
        time.sleep(0.001)
    print("ready", flush=True)

CALL_LINE = sys._getframe().f_lineno + 2
threading.Thread(target=say_ready, daemon=True).start()
hashlib.pbkdf2_hmac("sha256", b"x", b"y", 8_000_000)  # ~1.6 s in one compiled call: no handler runs in it
print("back", flush=True)
for _ in range(30):  # then Python code, where a pending handler runs
    time.sleep(0.01)
print(f"done {suspended_s()}", flush=True)
"""


def test_a_sigtstp_pending_across_a_sigstop_and_sigcont_does_not_stop_the_process_again(tmp_path):
    """A child whose main thread is held in a compiled call (a numeric kernel, a ``put``
    blocked by a full queue) cannot run its SIGTSTP handler; after ``JOB_STOP_WAIT_S`` the
    supervisor stops it with SIGSTOP, and on ``fg`` continues it with SIGCONT.  The handler,
    pending all along, then ran and stopped the process again, this time with no one to
    continue it: a CI run's propagator stayed stopped until serve killed it as stalled, and
    one whose supervisor was gone stayed stopped for good.  Now a SIGTSTP handled right after
    the SIGCONT that ended an outside stop is dropped (``astrodyn.signals.catch_job_control``)."""
    child = psutil.Popen([sys.executable, "-c", _HELD_CHILD], stdout=subprocess.PIPE, text=True, cwd=tmp_path)
    try:
        lines: queue.Queue[str] = queue.Queue()
        threading.Thread(target=lambda: [lines.put(line.strip()) for line in child.stdout], daemon=True).start()
        assert _line(lines, 60) == "ready"
        os.kill(child.pid, signal.SIGTSTP)  # pending: the main thread is in the compiled call
        time.sleep(0.2)
        assert child.status() != psutil.STATUS_STOPPED
        os.kill(child.pid, signal.SIGSTOP)  # the supervisor's fallback
        wait_until(lambda: child.status() == psutil.STATUS_STOPPED, 10, "SIGSTOP did not stop it", poll_s=0.01)
        os.kill(child.pid, signal.SIGCONT)  # fg
        assert _line(lines, 30) == "back"
        deadline, stopped_since = time.monotonic() + 30, None
        while child.poll() is None:
            now = time.monotonic()
            with contextlib.suppress(psutil.NoSuchProcess):
                stopped_since = (stopped_since or now) if child.status() == psutil.STATUS_STOPPED else None
            assert stopped_since is None or now - stopped_since < 2.0, "it stopped itself again after fg"
            assert now < deadline, "it did not end"
            time.sleep(0.05)
        assert child.returncode == 0
        assert _line(lines, 5).startswith("done ")
    finally:
        if child.poll() is None:  # only the process this test started
            child.kill()
            child.wait()
