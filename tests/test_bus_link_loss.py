"""States lost on a bus link that broke while every process ran are published again.

Zenoh closes a link whose sending queue stayed blocked for `wait_before_close` (5 s by
default: a logger stopped or stuck that long) and one whose peer sent nothing for the lease
(10 s: a whole run paused -- `docker pause`, SIGSTOP of the group, a paused VM -- expires
every lease when it is continued).  What is published meanwhile is dropped, and the two
processes are not always linked again.  Before, `run` then lost states for good: a logger
stopped 7 s never heard either propagator again and the run failed after 60 s with the
rest of the recording missing; a run paused 14 s lost 218,762 of 1.8 M states.

Now the logger's heartbeat says whom it has not heard and which state channels have a gap
(`Logger.reach_report`); `run` restarts such a propagator from the last step the file holds
without a hole (the crash path), and the recording is complete.  The Zenoh config of the
test shortens the lease to 2 s and the blocked-link wait to 1 s, so short stops suffice.

Real processes, real SIGSTOP / SIGCONT; every process is stopped by its PID, loops are bounded.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader

from astrodyn import bus, messages

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _recordings import assert_one_satellite_payloads, children_by_kind, one_satellite_scene, run_while

pytestmark = pytest.mark.network

ASTRODYN = [sys.executable, "-m", "astrodyn"]
SCENE = one_satellite_scene("linkloss", "3000 s", "10 Hz")
STEPS = 30_001
SHORT_TIMES = "{ transport: { link: { tx: { lease: 2000, queue: { congestion_control: { block: { " \
              "wait_before_close: 1000000 } } } } } } }"  # lease 2 s (ms); blocked-link wait 1 s (us)


def _recorded_by_seq(path: Path) -> dict[str, list[bytes]]:
    """topic -> payloads of each state channel in seq order (a refilled hole is written
    after later steps), each seq exactly once."""
    by_topic: dict[str, dict[int, bytes]] = {}
    with open(path, "rb") as f:
        for _, channel, message in make_reader(f).iter_messages(log_time_order=False):
            if channel.topic.endswith(("/orbit", "/attitude")):
                seq = json.loads(message.data)["seq"]
                assert seq not in by_topic.setdefault(channel.topic, {}), (channel.topic, seq)
                by_topic[channel.topic][seq] = message.data
    return {topic: [seqs[k] for k in sorted(seqs)] for topic, seqs in by_topic.items()}


def _assert_the_numeric_cores(recorded: dict[str, list[bytes]]) -> tuple[int, int]:
    """The payloads of body ``sat`` are the numeric core's (each seq once); their counts."""
    orbit, attitude = recorded[messages.orbit_key("linkloss", "sat")], recorded[messages.attitude_key("linkloss", "sat")]
    assert_one_satellite_payloads("linkloss", orbit, attitude)
    return len(orbit), len(attitude)


@pytest.mark.parametrize("stopped, stopped_s", [
    ("logger", 3.0),  # its propagators' links block past the 1 s wait and are closed
    ("run", 4.0),  # supervisor and children, past the 2 s lease
])
def test_states_lost_on_a_broken_bus_link_are_published_again(tmp_path, stopped, stopped_s):
    config, zenoh_config = tmp_path / "linkloss.toml", tmp_path / "short.json5"
    config.write_text(SCENE)
    zenoh_config.write_text(SHORT_TIMES)
    out, result, partial = tmp_path / "linkloss.mcap", tmp_path / "result.json", tmp_path / "linkloss.partial.mcap"

    def stop_and_continue(supervisor: int) -> None:
        children = children_by_kind(supervisor)
        assert sorted(children.values()) == ["attitude", "logger", "orbit"]
        victims = [p for p, kind in children.items() if kind == "logger"] if stopped == "logger" \
            else [supervisor, *children]
        for pid in victims:
            os.kill(pid, signal.SIGSTOP)
        time.sleep(stopped_s)
        for pid in reversed(victims):  # the children first
            os.kill(pid, signal.SIGCONT)

    rc, err = run_while([str(config), "--out", str(out), "--json", str(result), "--quiet", "--zenoh-config",
                         str(zenoh_config)], partial, 300_000, stop_and_continue)
    assert rc == 0, err
    run = json.loads(result.read_text())
    assert run["logger"]["missing"] == 0, run["logger"]
    assert run["restarts"] and all("cut off from the logger" in r["why"] for r in run["restarts"]), run["restarts"]
    # every step once, and each payload the one the numeric core gives for that step
    assert _assert_the_numeric_cores(_recorded_by_seq(out)) == (STEPS, STEPS)


def test_serve_publishes_again_the_states_a_broken_link_lost(tmp_path):
    """`serve` (real time x100) with its logger stopped 3 s: the gap it leaves in the part
    being written is refilled (the propagator restarted just before the first missing
    step, `Supervisor.refill_args`).  Before: 1,167 states missing and no restart."""
    from _serve_control import serve_status, stop_serve, wait_until

    config, zenoh_config = tmp_path / "linkloss.toml", tmp_path / "short.json5"
    config.write_text(one_satellite_scene("linkloss", "100000 s", "10 Hz"))
    zenoh_config.write_text(SHORT_TIMES)
    out, partial = tmp_path / "linkloss.mcap", tmp_path / "linkloss.partial.mcap"
    serve = subprocess.Popen([*ASTRODYN, "serve", str(config), "--out", str(out), "--rate", "100",
                              "--zenoh-config", str(zenoh_config)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                             text=True)
    try:
        started = json.loads(serve.stdout.readline())
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and not (partial.exists() and partial.stat().st_size > 100_000):
            assert serve.poll() is None, serve.stderr.read()
            time.sleep(0.05)
        logger, = [p for p, kind in children_by_kind(serve.pid).items() if kind == "logger"]
        os.kill(logger, signal.SIGSTOP)
        time.sleep(3.0)
        os.kill(logger, signal.SIGCONT)
        with bus.open_session(connect=started["hub"], config_file=str(zenoh_config)) as session:
            status = serve_status(session, "linkloss", started["control_token"])
            beats = bus.HeartbeatMonitor(session, "linkloss")  # (the logger's report of what it misses)

            def healed() -> bool:
                beats.poll()
                now = status()
                return (bool(now["restarts"]) and all(p["running"] for p in now["processes"].values())
                        and "logger" in beats.last and not ({"holes", "unheard"} & beats.last["logger"].keys()))

            wait_until(healed, 60.0, "a restart, every process running, and the logger missing nothing")
        _, stderr, summary = stop_serve(serve, settle_s=2.0)
    finally:
        if serve.poll() is None:
            serve.kill()
            serve.wait()
    assert serve.returncode == 0, stderr
    assert summary["logger"]["missing"] == 0, summary["logger"]
    assert all("cut off from the logger" in r["why"] for r in summary["restarts"]), summary["restarts"]
    _assert_the_numeric_cores(_recorded_by_seq(out))  # (each seq once)
