"""Several ``astrodyn serve`` of one scenario name side by side (docs/reliability.md, "serves
sharing a directory or a router"): a serve reads, finishes, counts and renames only files
its own loggers created (by ``(st_dev, st_ino)``, reported by each logger), never a file of
another recorder that merely has the name of one of its parts; a rolled part whose name is
taken is written beside it; a serve is ready only on its own logger's signed answer; each
``--out`` has its own control token file.

The other serve records another config under the same scenario name (the Molniya orbit with
e = 0.70 instead of 0.74): a state of it in this serve's recording shows in the osculating
eccentricity of the integrated (J2) body, an independent fact of the config.
"""

from __future__ import annotations

import contextlib
import json
import os
import selectors
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from _serve_control import stop_serve, wait_until
from astrodyn import bus
from astrodyn.recording import load
from astrodyn.service.children import stop_process

ROOT = Path(__file__).resolve().parents[1]
MU_EARTH = 3.986004418e14
MOLNIYA = "astrodyn/demo/molniya/orbit"


def configs(tmp_path: Path) -> tuple[Path, Path]:
    """demo.toml (scenario "demo"), and another config of the same scenario name."""
    text = (ROOT / "configs" / "demo.toml").read_text()
    mine, other = tmp_path / "mine.toml", tmp_path / "other.toml"
    mine.write_text(text)
    assert 'e = 0.74' in text and 'a = "6795 km"' in text
    other.write_text(text.replace("e = 0.74", "e = 0.70").replace('a = "6795 km"', 'a = "7100 km"'))
    return mine, other


@contextlib.contextmanager
def serves(*runs: tuple) -> Iterator[list[tuple[subprocess.Popen, dict | None]]]:
    """``astrodyn serve CONFIG --out OUT EXTRA...`` for each ``(config, out, *extra)``, started
    together (at most 60 s of wall time each), with the first JSON line of each (None if it
    ended without one within 60 s); each still running at the end is stopped by its PID."""
    procs = [subprocess.Popen([sys.executable, "-m", "astrodyn", "serve", str(config), f"--out={out}", "--rate", "50",
                               "--max-wall", "60", *extra], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for config, out, *extra in runs]
    try:
        yield [(p, first_line(p)) for p in procs]
    finally:
        for p in procs:
            if p.poll() is None:
                stop_process(p)


def first_line(proc: subprocess.Popen, timeout_s: float = 60.0) -> dict | None:
    sel = selectors.DefaultSelector()
    sel.register(proc.stdout, selectors.EVENT_READ)
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if sel.select(timeout=0.2):
            line = proc.stdout.readline()
            sel.close()
            return json.loads(line) if line.strip() else None
        if proc.poll() is not None:
            break
    sel.close()
    return None


def end(proc: subprocess.Popen) -> tuple[str, str, dict]:
    """Stop a serve the test started (SIGTERM, then SIGKILL by PID); its stdout, stderr, summary."""
    if proc.poll() is None:
        return stop_serve(proc, settle_s=0.0, timeout_s=60)
    stdout, stderr = proc.communicate(timeout=30)
    lines = stdout.strip().splitlines()
    return stdout, stderr, json.loads(lines[-1]) if lines else {}


def eccentricity(track) -> np.ndarray:
    r, v = np.asarray(track.r, float), np.asarray(track.v, float)
    rn = np.linalg.norm(r, axis=1)
    ev = ((np.sum(v * v, axis=1) - MU_EARTH / rn)[:, None] * r - np.sum(r * v, axis=1)[:, None] * v) / MU_EARTH
    return np.linalg.norm(ev, axis=1)


def molniya_seqs_and_e(files: list[Path]) -> tuple[list[int], np.ndarray]:
    seqs, es = [], []
    for f in files:
        track = load(f).channels.get(MOLNIYA)
        if track is not None and len(track):
            seqs += [int(s) for s in track.seq]
            es.append(eccentricity(track))
    return seqs, np.concatenate(es) if es else np.zeros(0)


def status_of(hello: dict):
    session = bus.open_session(connect=[hello["hub"]])

    def status() -> dict:
        return bus.send_control(session, "demo", "status", token=hello["control_token"])[0]
    return session, status


def kill_child(status, name: str) -> int:
    pid = status()["processes"][name]["pid"]
    os.kill(pid, signal.SIGKILL)
    return pid


# slow (15 s; CI time): the other crossing-serves tests run in make test
@pytest.mark.slow
def test_a_killed_propagator_and_logger_never_resume_from_another_serves_file(tmp_path):
    """F7 / F4 of the crossing probe: user 2's serve records ``x-0002.mcap`` (same scenario
    name, another config) beside user 1's ``x.mcap``.  User 1's orbit propagator, then its
    logger, are SIGKILLed while user 1 is paused (user 2's file is then the newest file named
    like one of user 1's parts).  Before: both restarts took user 2's live
    ``x-0002.partial.mcap`` for user 1's own (resumed from its states, finished it as user 1's
    part, numbered the parts after it): user 1's recording held user 2's Molniya orbit."""
    mine, other = configs(tmp_path)
    d = tmp_path / "d"
    d.mkdir()
    with serves((mine, d / "x.mcap"), (other, d / "x-0002.mcap")) as ((a, hello_a), (b, hello_b)):
        assert hello_a and hello_b, (a.stderr.read() if a.poll() is not None else "", b.poll())
        session, status = status_of(hello_a)
        with session:
            wait_until(lambda: status()["t"] > 60, 40, "user 1's serve does not advance")
            bus.send_control(session, "demo", "pause", token=hello_a["control_token"])
            time.sleep(2.0)  # user 2 goes on writing: its file is the newest
            kill_child(status, "orbit")
            wait_until(lambda: any(r["process"] == "orbit" for r in status()["restarts"]), 20,
                       "the orbit propagator is not restarted")
            kill_child(status, "logger")
            wait_until(lambda: any(r["process"] == "logger" for r in status()["restarts"]), 30,
                       "the logger is not restarted")
            bus.send_control(session, "demo", "resume", token=hello_a["control_token"])
            time.sleep(2.0)
        _, err_a, sum_a = end(a)
        _, err_b, sum_b = end(b)
    theirs = {str(d / "x-0002.partial.mcap"), str(d / "x-0002.mcap")}
    sources = [r["state_from"] for r in sum_a["restarts"]]
    assert not theirs & set(sources), (sources, err_a[-3000:])
    assert sum_a["failures"] == [], err_a[-3000:]
    assert sum_b["failures"] == [] and sum_b["file"] == str(d / "x-0002.mcap"), err_b[-2000:]
    # user 2's recording is its own, whole: its config, untouched by user 1
    _, e_b = molniya_seqs_and_e([d / "x-0002.mcap"])
    assert len(e_b) and np.all(np.abs(e_b - 0.70) < 0.01)
    # user 1's parts: every Molniya state of its own config, each step once, none missing
    parts = sorted(p for p in d.glob("x*.mcap") if p.name != "x-0002.mcap")
    seqs, e_a = molniya_seqs_and_e(parts)
    assert len(e_a) and np.all(np.abs(e_a - 0.74) < 0.01), [p.name for p in parts]
    assert sorted(seqs) == list(range(len(seqs))), [p.name for p in parts]


@pytest.mark.slow  # CI time: the killed propagator and logger case stays in make test
def test_a_rolled_part_whose_name_another_serve_took_is_written_beside_it(tmp_path):
    """F1 of the crossing probe: user 2 serves ``--out x-0001.mcap`` (another config, same
    scenario name) before user 1's serve of ``x.mcap`` rolls into its part 1.  Now user 1's
    part 1 is ``x-0001.clash-1.mcap``, nothing restarts, user 2's file is left as it is.
    Before: user 1's logger exited 6 naming the wrong file (its first one), serve restarted
    it from user 2's live file (its states, its step) and ended exit 1."""
    mine, other = configs(tmp_path)
    d = tmp_path / "d"
    d.mkdir()
    with serves((mine, d / "x.mcap", "--roll-interval", "5"),
                (other, d / "x-0001.mcap")) as ((a, hello_a), (b, hello_b)):
        assert hello_a and hello_b, (a.poll(), b.poll())
        session, status = status_of(hello_a)
        with session:
            # past user 1's first roll (5 s after its logger opened x.partial.mcap), then one more part
            wait_until(lambda: (d / "x-0002.partial.mcap").exists() or (d / "x-0002.partial-1.mcap").exists()
                       or status()["restarts"], 25, "user 1's serve does not roll")
            time.sleep(1.0)
        _, err_a, sum_a = end(a)
        _, err_b, sum_b = end(b)
    assert sum_a["restarts"] == [] and sum_a["failures"] == [], err_a[-3000:]
    assert "x-0001.clash-1.mcap" in err_a, err_a[-2000:]  # said at the end: where part 1 is
    assert sum_b["failures"] == [] and sum_b["file"] == str(d / "x-0001.mcap"), err_b[-2000:]
    _, e_b = molniya_seqs_and_e([d / "x-0001.mcap"])
    assert len(e_b) and np.all(np.abs(e_b - 0.70) < 0.01)
    parts = [d / "x.mcap", d / "x-0001.clash-1.mcap", d / "x-0002.mcap"]
    assert all(p.exists() for p in parts), sorted(os.listdir(d))
    seqs, e_a = molniya_seqs_and_e(parts)
    assert np.all(np.abs(e_a - 0.74) < 0.01)
    assert seqs == list(range(len(seqs)))


def test_serves_of_x_mcap_and_x_MCAP_each_keep_their_own_control_token_file(tmp_path):
    """F3 of the crossing probe: the token file is named after the whole file name of
    ``--out`` (``.x.mcap.control-token``).  Before, both serves used ``.x.control-token``: the
    second replaced the first's token (the first's owner was refused by its own serve) and
    removed the file when it ended."""
    mine, _ = configs(tmp_path)
    with serves((mine, tmp_path / "x.mcap"), (mine, tmp_path / "x.MCAP")) as ((a, hello_a), (b, hello_b)):
        assert hello_a and hello_b
        assert hello_a["control_token_file"] != hello_b["control_token_file"]
        end(b)
        token_a = Path(hello_a["control_token_file"])
        assert token_a.read_text() == hello_a["control_token"]
        with bus.open_session(connect=[hello_a["hub"]]) as s:
            reply = bus.send_control(s, "demo", "status", token=token_a.read_text())[0]
        assert reply.get("state") == "running", reply
        _, err_a, sum_a = end(a)
    assert sum_a["failures"] == [], err_a[-2000:]
    assert not token_a.exists()  # removed by its own serve at its end


@pytest.mark.slow
def test_of_two_serves_on_one_out_behind_a_router_the_loser_fails_at_once(tmp_path):
    """F5 of the crossing probe: two serves of one config on the same ``--out``, joined to one
    router, started together.  The loser's logger finds the output taken and exits 6; the
    loser must fail at once (exit 1), not take the winner's logger token for its own
    logger's readiness, and leave the winner's token file and files alone.  Before: the
    loser "started", wrote its token over the winner's, and recorded a fake part 1 resumed
    from the winner's live file."""
    mine, _ = configs(tmp_path)
    port = bus.free_port()
    router = subprocess.Popen([sys.executable, "-m", "astrodyn", "router", "--listen", f"tcp/127.0.0.1:{port}"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    procs = []
    try:
        time.sleep(1.0)
        argv = [sys.executable, "-m", "astrodyn", "serve", str(mine), f"--out={tmp_path / 'x.mcap'}", "--rate", "50",
                "--max-wall", "60", "--connect", f"tcp/127.0.0.1:{port}"]
        procs = [subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for _ in range(2)]
        hellos = [first_line(p) for p in procs]
        winners = [i for i, h in enumerate(hellos) if h is not None]
        assert len(winners) == 1, hellos
        w, lo = winners[0], 1 - winners[0]
        rc = procs[lo].wait(timeout=30)
        loser_err = procs[lo].stderr.read()
        # 2: the loser found the winner's processes on the router first (runner.check_scenario_free)
        assert (rc == 1 and "x.partial.mcap" in loser_err) or (rc == 2 and "is already running on the bus" in loser_err), \
            loser_err[-2000:]
        token = Path(hellos[w]["control_token_file"])
        assert token.read_text() == hellos[w]["control_token"]
        time.sleep(1.0)
        _, err_w, sum_w = end(procs[w])
        assert sum_w["failures"] == [] and sum_w["restarts"] == [], err_w[-2000:]
        assert sorted(os.listdir(tmp_path)) == sorted(["mine.toml", "other.toml", "x.mcap"]), os.listdir(tmp_path)
    finally:
        for p in procs:
            if p.poll() is None:
                stop_process(p)
        stop_process(router)
