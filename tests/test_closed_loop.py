"""The closed loop with real processes (docs/control.md): ``astrodyn run --controller``, the
plant, lockstep, ``--commands`` re-simulation, and faults of controllers and of the bus.

References are independent of the code: the Hohmann transfer against Vallado's Example 6-1
(printed digits) and the circular-orbit condition; determinism and re-simulation against
the first run's own bytes (bit-for-bit is the claim); the rate damping against the energy
law dT/dt = w . u <= 0; controller faults against the contract's error texts.
"""

from __future__ import annotations

import json
import os
import re
import shlex
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
import zenoh

from _recordings import payloads_by_topic
from _serve_control import read_run_start
from astrodyn.recording import load

pytestmark = pytest.mark.network
ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
RUN = [sys.executable, "-m", "astrodyn", "run"]


def _config(name: str, tmp_path: Path, **replace: str) -> Path:
    text = (ROOT / "configs" / f"{name}.toml").read_text()
    for old, new in replace.items():
        assert old in text, old
        text = text.replace(old, new)
    path = tmp_path / f"{name}.toml"
    path.write_text(text)
    return path


def _run(args: list, timeout: float = 240) -> subprocess.CompletedProcess:
    return subprocess.run([*RUN, *map(str, args), "--quiet"], capture_output=True, text=True, timeout=timeout, cwd=ROOT)


def test_hohmann_example_reaches_the_circular_target_orbit_with_vallados_delta_v(tmp_path):
    out = tmp_path / "h.mcap"
    cfg = _config("hohmann", tmp_path, **{'duration = "8 h"': 'duration = "7 h"'})
    proc = _run([cfg, "--out", out, "--controller", f"python {EXAMPLES / 'hohmann.py'}"])
    assert proc.returncode == 0, proc.stderr
    run = load(out)
    orbit = run.channels["astrodyn/hohmann/sat/orbit"]
    act = run.channels["astrodyn/hohmann/sat/actuators"]
    r2 = 6378.137e3 + 35781.34857e3  # Vallado 4th ed., Example 6-1
    tof = np.pi * np.sqrt((0.5 * (6378.137e3 + 191.34411e3 + r2)) ** 3 / 3.986004418e14)
    after = orbit.t > tof + 1.0
    radius = np.linalg.norm(orbit.r[after], axis=1)
    # exact two-body propagation and impulses at their exact times: circular at r2 to the
    # propagation's round-off (~1e-15 per step), far inside the contract's 1e-9
    assert np.max(np.abs(radius - r2)) / r2 < 1e-9
    speed = np.linalg.norm(orbit.v[after], axis=1)
    assert np.max(np.abs(speed - np.sqrt(3.986004418e14 / r2))) / speed[0] < 1e-9
    dv = act.dv[~np.isnan(act.dv[:, 0])]
    assert dv.shape == (2, 3)
    assert np.linalg.norm(dv[0]) == pytest.approx(2457.038, abs=5e-4)  # printed: 2.457038 km/s
    assert np.linalg.norm(dv[1]) == pytest.approx(1478.187, abs=5e-4)  # printed: 1.478187 km/s
    assert act.dv_total[-1] == pytest.approx(3935.225, abs=1e-3)
    # each impulse's own time: the first at its step's start, the second half an orbit of the
    # transfer ellipse later, inside its step (not at the step's start)
    hit = ~np.isnan(act.dv[:, 0])
    applied, steps = act.dv_t[hit], act.t[hit]
    commanded = sorted(run.channels["astrodyn/hohmann/sat/command"].t)
    assert list(applied) == commanded  # exactly when the controller asked
    # half the transfer orbit's period after the first: the controller derives r1 and r2 from
    # the simulated state, this test from Vallado's printed radii (they agree to ~1e-9)
    assert applied[0] == steps[0] and applied[1] == pytest.approx(applied[0] + tof, rel=1e-9)
    assert steps[1] < applied[1] < steps[1] + 10.0 and applied[1] - steps[1] > 1.0
    assert "2 commands applied, 0 refused, 0 late" in proc.stderr
    # the CCSDS OEM export cuts its segments at the burns, read by an independent reader
    ndm = pytest.importorskip("ccsds_ndm.ndm_io")
    from astrodyn.recording.export import export

    (oem_path,) = export(out, "oem", tmp_path / "oem")
    segments = ndm.NdmIo().from_path(oem_path).body.segment
    assert len(segments) == 3 and sum(len(s.data.state_vector) for s in segments) == len(orbit)
    burn_steps = np.flatnonzero(~np.isnan(act.dv[:, 0]))
    assert [len(s.data.state_vector) for s in segments[:2]] == [burn_steps[0] + 1, burn_steps[1] - burn_steps[0]]


def test_lockstep_is_deterministic_and_commands_resimulate_bit_for_bit(tmp_path):
    cfg = _config("slew", tmp_path, **{'duration = "180 s"': 'duration = "20 s"'})
    ctl = f"python {EXAMPLES / 'slew_pd.py'}"
    a, b, c = tmp_path / "a.mcap", tmp_path / "b.mcap", tmp_path / "c.mcap"
    for out in (a, b):
        proc = _run([cfg, "--out", out, "--controller", ctl])
        assert proc.returncode == 0, proc.stderr
    proc = _run([cfg, "--out", c, "--commands", a])
    assert proc.returncode == 0, proc.stderr
    kinds = ("/attitude", "/gyro", "/star_tracker", "/tachometer", "/actuators", "/command")
    pa, pb, pc = (payloads_by_topic(p, kinds) for p in (a, b, c))
    assert set(pa) == {f"astrodyn/slew/sc{k}" for k in kinds}
    assert len(pa["astrodyn/slew/sc/attitude"]) == 201
    assert pa == pb  # two lockstep runs, same deterministic controller: identical payloads
    assert pa == pc  # re-simulated from a's commands, no controller: identical payloads
    # every message of step k is stamped t = k / rate, as the propagators stamp theirs
    # (docs/architecture.md): the plant stamped k * (1 / rate), 3 * 0.1 = 0.30000000000000004
    run = load(a)
    for kind in ("/attitude", "/gyro", "/actuators"):
        track = run.channels[f"astrodyn/slew/sc{kind}"]
        assert np.array_equal(track.t, np.asarray(track.seq) / 10.0), kind
    # and the loop did something: the wheels were commanded and clipped at their limit
    act = run.channels["astrodyn/slew/sc/actuators"]
    assert np.max(np.abs(np.stack(act.wheel_torque))) == pytest.approx(0.2, rel=1e-12)


def _controller(tmp_path: Path, body: str) -> str:
    path = tmp_path / "ctl.py"
    path.write_text(textwrap.dedent(f"""
        import sys
        sys.path.insert(0, {str(EXAMPLES)!r})
        from astrodyn_link import Link
        with Link() as link:
            n = 0
            while (tick := link.wait_tick()) is not None:
                n += 1
                {body}
                link.done(tick)
    """))
    return f"python {path}"


def test_a_controller_that_dies_ends_the_run_naming_it_and_the_recording_stays_valid(tmp_path):
    cfg = _config("slew", tmp_path, **{'duration = "180 s"': 'duration = "20 s"'})
    out = tmp_path / "dies.mcap"
    ctl = _controller(tmp_path, "if n == 30: sys.exit(7)")
    proc = _run([cfg, "--out", out, "--controller", ctl])
    assert proc.returncode == 1, proc.stderr
    assert "controller pd" in proc.stderr and "exited with status 7" in proc.stderr, proc.stderr
    rec = out.with_name("dies.partial.mcap")
    run = load(rec)
    att = run.channels["astrodyn/slew/sc/attitude"]
    assert 25 <= len(att) < 201 and np.array_equal(att.seq, np.arange(len(att)))
    assert not run.truncated  # the logger finished the file


def test_a_controller_that_dies_under_serve_ends_it_at_once_naming_it(tmp_path):
    """In lockstep, ``serve`` does not wait out ``control.timeout`` (here 100 s) for a
    controller that is gone: it stops, exit 1, naming it; the recording stays valid."""
    cfg = _config("slew", tmp_path, **{'duration = "180 s"': 'duration = "100000 s"', 'timeout = "10 s"': 'timeout = "100 s"'})
    out = tmp_path / "served.mcap"
    ctl = _controller(tmp_path, "if n == 30: sys.exit(7)")
    started = time.monotonic()
    proc = subprocess.run([*RUN[:-1], "serve", str(cfg), "--out", str(out), "--rate", "50", "--max-wall", "90",
                           "--controller", ctl], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert time.monotonic() - started < 60, proc.stderr
    assert proc.returncode == 1, proc.stderr
    summary = json.loads(proc.stdout.strip().splitlines()[-1])
    assert len(summary["failures"]) == 1 and summary["failures"][0].startswith("controller pd (pid "), summary
    assert "exited with status 7" in summary["failures"][0], summary
    att = load(summary["file"]).channels["astrodyn/slew/sc/attitude"]
    assert 25 <= len(att) and np.array_equal(att.seq, np.arange(len(att)))  # every step up to the stop


def test_a_controller_that_stalls_times_out_with_the_named_error(tmp_path):
    cfg = _config("slew", tmp_path, **{'duration = "180 s"': 'duration = "20 s"', 'timeout = "10 s"': 'timeout = "1 s"'})
    out = tmp_path / "stall.mcap"
    ctl = _controller(tmp_path, "import time\n                if n == 20: time.sleep(600)")
    started = time.monotonic()
    proc = _run([cfg, "--out", out, "--controller", ctl], timeout=120)
    assert time.monotonic() - started < 60
    assert proc.returncode == 1, proc.stderr
    assert "controller 'pd' did not answer control step 19 (t = 1.9 s) within 1 s" in proc.stderr, proc.stderr
    run = load(out.with_name("stall.partial.mcap"))
    assert len(run.channels["astrodyn/slew/sc/attitude"]) == 20
    assert any(e["kind"] == "error" and "did not answer" in e["detail"] for e in run.events)


def _start_run(args: list) -> tuple[subprocess.Popen, dict]:
    """A run in the background; returns it and what its start lines say (bus, token file)."""
    proc = subprocess.Popen([*RUN, *map(str, args)], stderr=subprocess.PIPE, stdout=subprocess.DEVNULL,
                            text=True, cwd=ROOT)
    return proc, read_run_start(proc.stderr)


def _finish(proc: subprocess.Popen) -> str:
    try:
        _, err = proc.communicate(timeout=180)
    except subprocess.TimeoutExpired:
        os.kill(proc.pid, signal.SIGKILL)
        raise
    return err


def _detumble_with_outside_controller(tmp_path: Path, out: Path):
    """configs/detumble.toml cut to 30 s, run in the background into ``out``, and its
    controller (examples/detumble.py) started by hand with the run's control token.
    Returns the run, the controller and a zenoh client config for a third party on the
    run's hub."""
    cfg = _config("detumble", tmp_path, **{'duration = "900 s"': 'duration = "30 s"', 't = "300 s"': 't = "10 s"',
                                            't = "500 s"': 't = "20 s"'})
    proc, found = _start_run([cfg, "--out", out, "--quiet"])
    env = {**os.environ, "ASTRODYN_CONTROL_TOKEN_FILE": found["token"]}
    env.pop("ASTRODYN_RUN_SECRET_FILE", None)
    ctl = subprocess.Popen([sys.executable, str(EXAMPLES / "detumble.py")], cwd=ROOT, stderr=subprocess.PIPE,
                           env={**env, "ASTRODYN_CONNECT": found["hub"], "ASTRODYN_SCENARIO": "detumble",
                                "ASTRODYN_CONTROLLER": "detumble"})
    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", json.dumps([found["hub"]]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    return proc, ctl, conf


def _wait_for_tick(session, seq: int, timeout_s: float = 60.0) -> None:
    """Until the plant's tick number ``seq`` (the lockstep loop is running)."""
    ticks = session.declare_subscriber("astrodyn/detumble/@tick", zenoh.handlers.FifoChannel(1024))
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        tick = ticks.try_recv()
        if tick is not None and json.loads(tick.payload.to_bytes())["seq"] >= seq:
            break
        time.sleep(0.001)
    ticks.undeclare()


def test_an_outside_controller_joins_with_the_token_and_forgers_are_rejected(tmp_path):
    """An outside controller (started by hand, not by the run) commands with the control
    token; a forger on the same bus (no token, a wrong token, a stolen name) is dropped by
    the plant, counted, and the run exits 3 (the record was attacked; docs/security.md)."""
    out = tmp_path / "out.mcap"
    proc, ctl, conf = _detumble_with_outside_controller(tmp_path, out)
    forged = {"t": 1.0, "seq": 0, "sender": "detumble", "torque": [1.0, 1.0, 1.0]}
    with zenoh.open(conf) as session:
        _wait_for_tick(session, 5)  # forge while the loop runs (not before it, not after it)
        session.put("astrodyn/detumble/sc/command", json.dumps(forged))  # no authenticator
        session.put("astrodyn/detumble/sc/command", json.dumps(forged), attachment=b"ADT1" + b"x" * 43)  # wrong token
        session.put("astrodyn/detumble/ghost/command", json.dumps(forged), attachment=b"ADT1" + b"y" * 43)
        err = _finish(proc)
    ctl.wait(timeout=30)
    assert proc.returncode == 3, err
    assert "ATTACKED" in err and "command unsigned" in err and "command bad-token" in err, err
    run = load(out)  # the attacked run completed; its recording was renamed
    commands = run.channels["astrodyn/detumble/sc/command"]
    assert len(commands) > 100 and set(commands.sender) == {"detumble"}
    assert not np.any(np.all(np.stack(commands.torque) == 1.0, axis=1))  # no forged command was applied
    w = run.channels["astrodyn/detumble/sc/attitude"].w
    inertia = np.array([100.0, 120.0, 80.0])
    energy = 0.5 * np.sum(inertia * w * w, axis=1)
    assert energy[-1] < 0.5 * energy[0]  # the token controller's damping acted


def test_a_flood_of_forged_commands_does_not_starve_the_controllers_answers(tmp_path):
    """A forger floods the body's command key and the controller's answer key with unsigned
    messages, as fast as one Python process can put (~900,000 a second), for 3 s of a
    lockstep run.  The controller's commands and answers still reach the plant: the run
    completes (no controller timeout), no forged command is applied, the attack is
    reported (exit 3).  (An intake read from a zenoh FIFO channel deadlocked here, one
    read from a ring channel lost the controller's commands: astrodyn.service.plant.)"""
    out = tmp_path / "out.mcap"
    proc, ctl, conf = _detumble_with_outside_controller(tmp_path, out)
    forged = json.dumps({"t": 1.0, "seq": 0, "sender": "detumble", "torque": [1.0, 1.0, 1.0]}).encode()
    answer = json.dumps({"t": 1.0, "seq": 10, "sender": "detumble", "commands": 0}).encode()
    sent = 0
    with zenoh.open(conf) as session:
        _wait_for_tick(session, 5)  # flood while the loop runs
        commands = session.declare_publisher("astrodyn/detumble/sc/command")
        answers = session.declare_publisher("astrodyn/detumble/@done/detumble")
        stop = time.monotonic() + 3.0
        while time.monotonic() < stop:
            for _ in range(100):
                commands.put(forged)
            answers.put(answer)
            sent += 101
        err = _finish(proc)
    ctl.wait(timeout=30)
    assert sent > 10_000, sent  # a flood, not a trickle
    assert proc.returncode == 3, err
    assert "did not answer" not in err and "ATTACKED" in err and "command unsigned" in err, err
    run = load(out)
    commands = run.channels["astrodyn/detumble/sc/command"]
    assert len(commands) > 100 and set(commands.sender) == {"detumble"}
    assert not np.any(np.all(np.stack(commands.torque) == 1.0, axis=1))  # no forged command was applied
    assert run.channels["astrodyn/detumble/sc/attitude"].t[-1] == pytest.approx(30.0)  # the whole run


def test_commands_on_a_scene_without_control_and_bad_closed_loop_arguments_are_refused(tmp_path):
    proc = _run([ROOT / "configs" / "demo.toml", "--out", tmp_path / "x.mcap", "--controller", "python x.py"])
    assert proc.returncode == 2 and "--controller: expected a closed-loop scene" in proc.stderr, proc.stderr
    cfg = _config("slew", tmp_path)
    proc = _run([cfg, "--out", tmp_path / "x.mcap", "--controller", "a", "--controller", "b"])
    assert proc.returncode == 2 and "--controller: expected at most 1" in proc.stderr, proc.stderr
    proc = _run([cfg, "--out", tmp_path / "x.mcap", "--commands", tmp_path / "none.mcap"])
    assert proc.returncode == 2 and "no such file" in proc.stderr, proc.stderr
    # hostile recordings for --commands: foreign bytes, and a recording cut before its first command
    (tmp_path / "foreign.mcap").write_bytes(b"not an mcap at all" * 100)
    proc = _run([cfg, "--out", tmp_path / "x.mcap", "--commands", tmp_path / "foreign.mcap"])
    assert proc.returncode == 2 and "not an MCAP file" in proc.stderr and "Traceback" not in proc.stderr, proc.stderr
    short = _config("slew", tmp_path, **{'duration = "180 s"': 'duration = "5 s"'})
    rec = tmp_path / "rec.mcap"
    assert _run([short, "--out", rec, "--controller", f"python {EXAMPLES / 'slew_pd.py'}"]).returncode == 0
    (tmp_path / "cut.mcap").write_bytes(rec.read_bytes()[:3000])
    proc = _run([cfg, "--out", tmp_path / "x.mcap", "--commands", tmp_path / "cut.mcap"])
    assert proc.returncode == 2 and "found none: nothing to re-simulate" in proc.stderr, proc.stderr
    assert not (tmp_path / "x.mcap").exists()


def test_serve_runs_a_free_closed_loop_with_its_controller_and_stops_cleanly(tmp_path):
    """``serve --controller`` in free mode: real-time pacing (x20), the controller's commands
    applied as they come (late ones counted), and the stop verb ends plant, controller and
    logger with everything recorded."""
    from astrodyn import bus

    cfg = _config("detumble", tmp_path, **{'period = "0.1 s"': 'period = "0.1 s"\nmode = "free"'})
    out = tmp_path / "serve.mcap"
    serve = subprocess.Popen([*RUN[:-1], "serve", str(cfg), "--out", str(out), "--rate", "20", "--max-wall", "120",
                              "--controller", f"python {EXAMPLES / 'detumble.py'}"],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    try:
        hello = json.loads(serve.stdout.readline())
        with bus.open_session(connect=[hello["hub"]]) as s:
            deadline = time.monotonic() + 90
            status = {}
            while time.monotonic() < deadline:  # until the loop has run 40 sim seconds
                replies = bus.send_control(s, "detumble", "status", token=hello["control_token"], timeout_s=10)
                status = replies[0] if replies else {}
                if (status.get("processes", {}).get("plant", {}).get("t") or 0) > 40:
                    break
                time.sleep(0.5)
            assert status["processes"]["plant"]["running"] and status["state"] == "running", status
            # a fault on demand through the control verb; a bad one is refused naming the field
            bad = bus.send_control(s, "detumble", "fault", {"body": "ghost", "fault": "gyro_bias", "value": [1, 0, 0]},
                                   token=hello["control_token"], timeout_s=10)
            assert "body: expected a body with actuators or sensors (sc), got \"ghost\"" in bad[0]["error"], bad
            ok = bus.send_control(s, "detumble", "fault", {"body": "sc", "fault": "gyro_bias", "value": [1e-3, 0, 0]},
                                  token=hello["control_token"], timeout_s=10)
            assert "error" not in ok[0], ok
            time.sleep(0.5)
            bus.send_control(s, "detumble", "stop", token=hello["control_token"], timeout_s=60)
        stdout, stderr = serve.communicate(timeout=90)
    finally:
        if serve.poll() is None:
            os.kill(serve.pid, signal.SIGKILL)
    assert serve.returncode == 0, stderr[-2000:]
    summary = json.loads(stdout.strip().splitlines()[-1])
    assert summary["failures"] == [] and Path(summary["file"]).exists()
    run = load(summary["file"])
    commands = run.channels["astrodyn/detumble/sc/command"]
    # the end line says what became of the commands, as run's does, counted by the plant
    line = re.search(r"astrodyn serve: closed loop: (\d+) commands applied, (\d+) refused, (\d+) late", stderr)
    assert line and int(line.group(1)) == len(commands), stderr[-2000:]
    att = run.channels["astrodyn/detumble/sc/attitude"]
    assert len(commands) > 100 and set(att.model) == {"actuated"}
    assert np.array_equal(att.seq, np.arange(len(att)))  # no gap
    energy = 0.5 * np.sum(np.array([100.0, 120.0, 80.0]) * att.w * att.w, axis=1)
    assert energy[-1] < energy[0]  # the commands acted
    injected = [e for e in run.events if e["process"] == "plant" and e["kind"] == "fault"
                and json.loads(e["detail"]) == {"body": "sc", "fault": "gyro_bias", "value": [1e-3, 0.0, 0.0]}]
    assert len(injected) == 1, run.events
    gyro = run.channels["astrodyn/detumble/sc/gyro"]
    after = gyro.t >= injected[0]["t"]  # from the step the fault began: gyro - truth has the new bias
    w_true = att.w[np.searchsorted(att.t, gyro.t[after])]
    assert abs(np.mean(gyro.w[after, 0] - w_true[:, 0]) - 1e-3) < 5 * 1e-5 / np.sqrt(after.sum())  # the new bias
    stop = [e for e in run.events if e["process"] == "plant" and e["kind"] == "stop"]
    assert stop and json.loads(stop[0]["detail"])["reason"] == "stop requested"
    # re-simulated from the served recording: late commands at the steps they were applied,
    # the injected fault when it began: states and sensor samples bit for bit
    again = tmp_path / "again.mcap"
    proc = _run([cfg, "--out", again, "--commands", summary["file"]])
    assert proc.returncode == 0, proc.stderr
    kinds = ("/attitude", "/gyro", "/actuators", "/command")
    first, second = payloads_by_topic(Path(summary["file"]), kinds), payloads_by_topic(again, kinds)
    for key, payloads in first.items():
        assert second[key][:len(payloads)] == payloads, key


def test_what_a_controller_started_ends_with_the_run(tmp_path):
    """``--controller "sh -c '...'"`` may start more programs (a helper, a logger of its
    own): when the run ends, its whole session is stopped, not only the shell's PID (before:
    the background process outlived the run).  Checked by the PID it wrote."""
    cfg = _config("slew", tmp_path, **{'duration = "180 s"': 'duration = "20 s"'})
    pid_file = tmp_path / "helper.pid"
    line = f"sleep 600 & echo $! > {pid_file}; exec {sys.executable} {EXAMPLES / 'slew_pd.py'}"
    done = subprocess.run([*RUN, str(cfg), "--out", str(tmp_path / "h.mcap"), "--quiet", "--controller",
                           f"sh -c {shlex.quote(line)}"], capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert done.returncode == 0, done.stderr[-2000:]
    helper = int(pid_file.read_text())
    gone = not Path(f"/proc/{helper}").exists() or Path(f"/proc/{helper}/stat").read_text().split()[2] == "Z"
    if not gone:
        os.kill(helper, signal.SIGKILL)  # the process this test started, by the PID it wrote
    assert gone, f"the controller's background process {helper} outlived the run"


def test_no_controller_outlives_a_killed_run_supervisor(tmp_path):
    """A controller is the user's program: it cannot call astrodyn's fate-sharing itself.
    ``--controller`` children get PR_SET_PDEATHSIG before exec, so when the supervisor is
    SIGKILLed the kernel ends them; checked by PID, with a controller that would run on."""
    from astrodyn.service.children import children_of

    cfg = _config("slew", tmp_path, **{'duration = "180 s"': 'duration = "100000 s"'})
    deaf = tmp_path / "deaf_slew_pd.py"  # hears nothing, not even the plant's end: only the kernel ends it
    deaf.write_text("import time\ntime.sleep(600)\n")
    sup = subprocess.Popen([*RUN, str(cfg), "--out", str(tmp_path / "k.mcap"), "--quiet", "--controller",
                            f"python {deaf}"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=ROOT)
    try:
        deadline = time.monotonic() + 120
        controller = None
        while controller is None and time.monotonic() < deadline:
            controller = next((pid for pid, argv in children_of(sup.pid).items()
                               if any(a.endswith("deaf_slew_pd.py") for a in argv)), None)
            time.sleep(0.1)
        assert controller is not None, "the controller never started"
        time.sleep(1.0)  # the plant is waiting for its answer
        os.kill(sup.pid, signal.SIGKILL)
        sup.wait(timeout=10)
        deadline = time.monotonic() + 5.0
        while time.monotonic() < deadline and Path(f"/proc/{controller}").exists():
            time.sleep(0.05)
        state = Path(f"/proc/{controller}/stat").read_text().split()[2] if Path(f"/proc/{controller}").exists() else "gone"
        assert state in ("gone", "Z"), f"controller {controller} still running ({state})"
    finally:
        if sup.poll() is None:
            os.kill(sup.pid, signal.SIGKILL)
