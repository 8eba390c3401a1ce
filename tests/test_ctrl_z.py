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

import json
import os
import signal
import sys
import time
from pathlib import Path

import psutil
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _recordings import children_by_kind, one_satellite_scene, run_while
from _serve_control import serve_demo, stop_serve, wait_until
from astrodyn import bus
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
