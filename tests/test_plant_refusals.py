"""What the plant refuses, rejects and leaves waiting, and how ``astrodyn run`` reports it.

Each run is ``astrodyn run`` of a 3 s detumble scene (10 Hz, 31 control steps, lockstep) with
a plain zenoh controller written from docs/control.md (``_CONTROLLER``, signing with the run
secret it is given by ``--controller``).  The facts checked are the contract's
(docs/control.md, docs/security.md), not the code's numbers: a command the body can never
apply is refused for that reason whenever it comes; a malformed message signed by the run's
own controller is that controller's error, not an attack (exit 0), while one that fails
authentication is (exit 3); a sender's flood of far-future commands does not lock out the
configured controller, and commands still waiting at the end are counted; a killed logger's
file needs ``astrodyn recover``.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from _by_hand_controller import CONTROLLER_PRELUDE, detumble_scene
from _recordings import children_by_kind, run_while, wait_for_recording
from astrodyn.recording.stream import open_stream

pytestmark = pytest.mark.network

#: A plain controller (docs/control.md): each tick it commands sc with -5 w as "detumble" and
#: answers; MODE adds what a test needs.  It writes the ids of its valid, announced
#: "detumble" commands to the file SENT.
_CONTROLLER = CONTROLLER_PRELUDE + r'''
MODE = os.environ["MODE"]
sent = open(os.environ["SENT"], "w")
n = 0
with subscribed_session() as s:
    while (tk := ticks.get(timeout=30)) is not None:
        j, t = tk["seq"], tk["t"]
        w = tk["samples"].get("sc/gyro", {}).get("w", [0.0, 0.0, 0.0])
        flood = 10_001 if MODE == "flood" and j == 0 else 0  # a second sender: far-future commands, one more than it may
        for i in range(flood):
            put(s, command_key, {"t": 1e9 + i, "seq": i, "sender": "flooder", "torque": [0.0, 0.0, 0.0]},
                signer="flooder")
        put(s, command_key, {"t": t, "seq": n, "sender": "detumble", "torque": [-5.0 * x for x in w]})
        sent.write(f"detumble#{n}\n"); sent.flush()
        n, count = n + 1, 1
        if MODE in ("errors", "errors+unsigned") and j == 3:  # a malformed command, announced
            put(s, command_key, raw=b'{"t":%r,"seq":%d,"sender":"detumble","torque":[NaN,0,0]}' % (t, n))
            n, count = n + 1, 2
        if MODE == "errors+unsigned" and j == 4:  # what did not come from the run: no authenticator
            put(s, command_key, {"t": t, "seq": 10**6, "sender": "detumble", "torque": [0.0, 0.0, 0.0]}, sign=False)
        put(s, f"{base}/@done/detumble", {"t": t, "seq": j, "sender": "detumble", "commands": count})
        if MODE.startswith("errors") and j == 5:  # after the answer, for the step before: late, and for wheels sc lacks
            put(s, command_key, {"t": t - 0.1, "seq": n, "sender": "detumble", "wheel_torque": [0.01]})
            n += 1
        if MODE == "flood":
            put(s, f"{base}/@done/flooder", {"t": t, "seq": j, "sender": "flooder", "commands": flood},
                signer="flooder")
'''


def _run(tmp_path: Path, mode: str, controllers: tuple[str, ...] = ("detumble",)) -> tuple[subprocess.CompletedProcess,
                                                                                          dict, Path, list[str]]:
    """``astrodyn run`` of the scene with ``_CONTROLLER`` in ``mode``; (the process, the
    plant's summary, the recording, the ids of the valid commands the controller announced)."""
    cfg = tmp_path / "det.toml"
    cfg.write_text(detumble_scene("3 s", controllers=json.dumps(list(controllers)), timeout="5 s"))
    ctl = tmp_path / "ctl.py"
    ctl.write_text(_CONTROLLER)
    out, js, sent = tmp_path / "out.mcap", tmp_path / "out.json", tmp_path / "sent.txt"
    proc = subprocess.run([sys.executable, "-m", "astrodyn", "run", str(cfg), "--out", str(out), "--quiet", "--json",
                           str(js), "--controller", f"{sys.executable} {ctl}"], capture_output=True, text=True,
                          timeout=90, cwd=tmp_path, env={**os.environ, "MODE": mode, "SENT": str(sent)})
    summary = json.loads(js.read_text())["processes"]["plant"]["summary"] if js.exists() else {}
    return proc, summary, out, sent.read_text().split() if sent.exists() else []


def _applied(path: Path) -> list[str]:
    """The ``sender#seq`` ids the recording's actuator states of sc say were applied."""
    with open_stream(path) as s:
        return [cid for m in s.messages() if m.topic == "astrodyn/detumble/sc/actuators"
                for cid in json.loads(m.data).get("applied", [])]


def _end_line(stderr: str) -> str:
    return next(line for line in stderr.splitlines() if line.startswith("astrodyn run: closed loop:"))


def test_a_controllers_malformed_command_is_its_error_and_a_content_refusal_beats_late(tmp_path):
    proc, summary, out, sent = _run(tmp_path, "errors")
    # signed with the run secret by the run's own controller: a controller error, not an attack (exit 0)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "ATTACKED" not in proc.stderr, proc.stderr[-3000:]
    assert "1 rejected from controller detumble (1 malformed)" in _end_line(proc.stderr), proc.stderr[-3000:]
    assert summary["controller_errors_by_author"] == {"detumble": {"malformed": 1}}
    assert not summary["rejected"], summary["rejected"]
    # wheel_torque for a body without wheels, also for a time already past: refused for the wheels
    refusal = next(r for r in summary["refusals"] if "wheel" in r or "in the past" in r)
    assert "no reaction wheels" in refusal and "in the past" not in refusal, summary["refusals"]
    assert summary["refused"] == 1
    assert sorted(_applied(out)) == sorted(sent) and len(sent) == 31  # every valid announced command, once


def test_a_message_that_fails_authentication_is_still_an_attack(tmp_path):
    proc, summary, out, sent = _run(tmp_path, "errors+unsigned")
    assert proc.returncode == 3, proc.stderr[-3000:]
    attacked = next(line for line in proc.stderr.splitlines() if "ATTACKED" in line)
    assert "1 command unsigned" in attacked and "malformed" not in attacked, attacked
    assert "1 rejected from controller detumble (1 malformed)" in _end_line(proc.stderr), proc.stderr[-3000:]


def test_a_senders_far_future_flood_does_not_lock_out_the_controller_and_waiting_commands_are_counted(tmp_path):
    from astrodyn.service.plant import MAX_PENDING

    proc, summary, out, sent = _run(tmp_path, "flood", ("detumble", "flooder"))
    assert proc.returncode == 0, proc.stderr[-3000:]
    applied = _applied(out)
    assert sorted(applied) == sorted(sent) and len(sent) == 31, (len(applied), summary["refusals"][:3])
    # the flooder got its own allowance and no more; what waits for t = 1e9 s is reported at the end
    assert summary["refused"] == 10_001 - MAX_PENDING
    assert all("flooder" in r for r in summary["refusals"]), summary["refusals"][:3]
    assert summary["pending"] == MAX_PENDING
    assert f"{MAX_PENDING} still waiting for their time at the end" in _end_line(proc.stderr), proc.stderr[-3000:]


def _long_run(tmp_path: Path, monkeypatch) -> tuple[list[str], Path]:
    """The ``astrodyn run`` arguments of a 600 s scene with ``_CONTROLLER`` in mode plain (the
    config and the controller written to ``tmp_path``, its environment set with
    ``monkeypatch``: the run passes its environment on to the controller), and the partial
    recording it makes."""
    cfg = tmp_path / "det.toml"
    cfg.write_text(detumble_scene("600 s", timeout="5 s"))
    ctl = tmp_path / "ctl.py"
    ctl.write_text(_CONTROLLER)
    monkeypatch.setenv("MODE", "plain")
    monkeypatch.setenv("SENT", str(tmp_path / "sent.txt"))
    argv = [str(cfg), "--out", str(tmp_path / "out.mcap"), "--quiet", "--controller", f"{sys.executable} {ctl}"]
    return argv, tmp_path / "out.partial.mcap"


def test_a_killed_logger_of_a_closed_loop_run_says_its_file_needs_recover(tmp_path, monkeypatch):
    argv, partial = _long_run(tmp_path, monkeypatch)

    def kill_logger(pid: int) -> None:
        (logger,) = [p for p, kind in children_by_kind(pid).items() if kind == "logger"]
        os.kill(logger, signal.SIGKILL)

    rc, err = run_while(argv, partial, 8000, kill_logger, timeout_s=60)
    assert rc == 1, err[-3000:]
    failed = next(line for line in err.splitlines() if "FAILED" in line)
    with open_stream(partial) as s:
        assert s.truncated  # no footer: not readable as a finished recording
    assert f"astrodyn recover {partial}" in failed and "holds everything" not in failed, failed


def test_an_interrupted_run_says_at_once_it_is_stopping_and_where_the_recording_got(tmp_path, monkeypatch, processes):
    """Ctrl-C (SIGINT to ``run``): one line at once that it is stopping; the FAILED line's sim
    time is the recording's (it was the last heartbeat's, seconds old or from start-up),
    and the summary names the file that holds the recording, NAME.partial.mcap."""
    import re

    argv, partial = _long_run(tmp_path, monkeypatch)
    proc = processes([sys.executable, "-m", "astrodyn", "run", *argv], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                     text=True)
    wait_for_recording(proc, partial, 8000, timeout_s=60)
    os.kill(proc.pid, signal.SIGINT)
    stdout, err = proc.communicate(timeout=60)
    assert proc.returncode == 128 + signal.SIGINT, err[-3000:]
    assert "astrodyn run: stopping (SIGINT)" in err, err[-3000:]
    with open_stream(partial) as s:
        last_t = max(json.loads(m.data)["t"] for m in s.messages() if m.topic == "astrodyn/detumble/sc/attitude")
    failed = next(line for line in err.splitlines() if "FAILED" in line)
    said = re.search(r"interrupted by SIGINT at sim t (\S+) s of 600 s", failed)
    summary = re.search(r"sim t reached (\S+) s of 600 s", stdout)
    assert said and summary and said.group(1) == summary.group(1), (failed, summary)  # one answer, not two
    # where the plant got: its last recorded state, or the step before it (published, not yet advanced from)
    assert last_t - 0.1 - 1e-9 <= float(said.group(1)) <= last_t, (failed, last_t)
    assert f"scenario detumble: {partial}" in stdout, stdout[:3000]
