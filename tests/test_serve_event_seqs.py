"""A logger restart under serve continues each process's event numbering and is recorded (svc probe F6).

Each process numbers its own events 0, 1, ... over the whole run (``bus.EventPublisher``;
a restarted process continues its predecessor's numbering: ``--first-event-seq``).  After a
logger restart serve started the propagators without it, so their events began at 0 again in
the new part: ``merge`` of the parts then held seqs 0, 1 twice with other content, which
``analyze`` reported as duplicated.  And a logger restart left no ``restart`` event (process
``serve``) in the recording, as a propagator restart does.

The new logger's own accounting began every event channel at seq 0 as well: its part's
``end`` record counted the earlier parts' events as missing (``complete: false``), and the
logger's own events (a death it saw) began at 0 again.  The restarted logger now starts each
process's event channel, its own included, where the run's numbering stands.

Checked with the plain ``mcap`` reader on ``astrodyn merge`` of the parts: every process's
events -- the logger's own, from a propagator death before and one after its restart --
have the seqs 0 .. N-1, each once, and ``restart`` events of serve name the processes; and
the new part's ``end`` record counts no message missing.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

from mcap.reader import make_reader

from _serve_control import serve_demo, serve_status, wait_until
from astrodyn import bus

EVENT_TOPIC = "astrodyn/demo/@event"


def _kill_and_wait_restart(status, process: str, restarts_before: int, starts: list[str]) -> dict:
    """Kill ``process`` and wait until serve (asked with ``status``) has restarted it and
    every propagator it restarted has started again (its ``start`` event heard: ``starts``)."""
    restarted = ("orbit", "attitude") if process == "logger" else (process,)
    before = {p: starts.count(p) for p in restarted}
    os.kill(status()["processes"][process]["pid"], signal.SIGKILL)  # a child of the serve this test started
    # 60 s: a logger's restart restarts both propagators (kernels loaded again); on a loaded CI
    # machine (two xdist workers and more) that took over 30 s once
    wait_until(lambda: all(starts.count(p) > before[p] for p in restarted), 60, f"{process} was not restarted",
               poll_s=0.05)
    return wait_until(lambda: len((st := status())["restarts"]) > restarts_before and st, 60,
                      f"{process} was not restarted", poll_s=0.05)


def test_after_a_logger_restart_the_merged_parts_hold_each_event_seq_once_and_the_restart_event(tmp_path):
    out = tmp_path / "demo.mcap"
    serve, hello = serve_demo(out, "20", max_wall_s=240)
    try:
        token = hello["control_token"]
        partial = tmp_path / "demo.partial.mcap"
        with bus.open_session(connect=[hello["hub"]]) as s:
            status = serve_status(s, "demo", token, timeout_s=10)
            starts: list[str] = []  # the process of each start event heard
            s.declare_subscriber(EVENT_TOPIC, lambda sample: starts.extend(
                [e["process"]] if (e := json.loads(sample.payload.to_bytes()))["kind"] == "start" else []))
            # both propagators have published (their start events are out) and the logger has flushed some
            wait_until(lambda: all((status()["processes"][k]["t"] or 0) > 20 for k in ("orbit", "attitude")), 30,
                       "the propagators never ran", poll_s=0.05)
            wait_until(lambda: partial.exists() and partial.stat().st_size > 20_000, 30, "the logger flushed nothing",
                       poll_s=0.05)
            _kill_and_wait_restart(status, "orbit", 0, starts)  # the logger records the death: an event of its own
            time.sleep(1.5)  # flushed (--flush-interval 1 s): a killed logger loses what it had not written
            _kill_and_wait_restart(status, "logger", 1, starts)
            # the new logger's own event continues its numbering
            st = _kill_and_wait_restart(status, "orbit", 2, starts)
            assert [r["process"] for r in st["restarts"]] == ["orbit", "logger", "orbit"], st["restarts"]
            time.sleep(1.0)  # the new part records the restarted propagators' events and states
            (final,) = bus.send_control(s, "demo", "stop", token=token, timeout_s=60)
        _, err = serve.communicate(timeout=60)
        assert serve.returncode == 0, err[-3000:]
    finally:
        if serve.poll() is None:  # only the serve this test started, by its PID (its children share its fate)
            serve.kill()
            serve.communicate(timeout=30)
    parts = [out, tmp_path / "demo-0001.mcap"]
    assert final["file"] == str(parts[-1]) and all(p.exists() for p in parts), sorted(tmp_path.iterdir())
    assert "file" not in final["logger"], final["logger"]  # one path for the recording: its name (probe B, F8)
    assert not any(isinstance(v, str) and ".partial" in v for v in final["logger"].values()), final["logger"]
    merged = tmp_path / "all.mcap"
    done = subprocess.run([sys.executable, "-m", "astrodyn", "merge", *map(str, parts), "--out", str(merged)],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    seqs: dict[str, list[int]] = {}
    restarts = []
    with open(merged, "rb") as f:
        for _, channel, message in make_reader(f).iter_messages():
            if channel.topic == EVENT_TOPIC:
                event = json.loads(message.data)
                seqs.setdefault(event["process"], []).append(event["seq"])
                if event["process"] == "serve" and event["kind"] == "restart":
                    restarts.append(json.loads(event["detail"]))
    assert {"orbit", "attitude", "serve", "logger"} <= set(seqs), seqs
    assert len(seqs["logger"]) >= 2, seqs["logger"]  # a death seen by each logger
    for process, got in seqs.items():
        assert sorted(got) == list(range(len(got))), (process, sorted(got))  # 0 .. N-1, each once
    assert [r["process"] for r in restarts] == ["orbit", "logger", "orbit"], restarts
    # each names the file the state came from by the name it has once finished (not a partial name that is gone)
    assert {r["state_from"] for r in restarts} <= {str(p) for p in parts}, restarts
    with open(parts[-1], "rb") as f:  # the new part's own account: no earlier event counted as missing
        (end,) = [dict(m.metadata) for m in make_reader(f).iter_metadata() if m.name == "end"]
    assert end["missing"] == "0", end
