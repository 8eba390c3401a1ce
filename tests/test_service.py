"""The service end to end: real processes, real Zenoh on loopback, MCAP read back.

Every process a test starts is stopped by its PID (``_stop``); loops are bounded in count
and time.  The references are independent of the service path: the plain ``mcap`` reader
for the file, and the numeric core run directly from the first recorded state.
"""

from __future__ import annotations

import json
import os
import re
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from astrodyn import bus
from astrodyn.attitude import torque_free
from astrodyn.orbit import propagate
from astrodyn.scenario import load
from astrodyn.service.children import stop_process

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _serve_control import serve_demo

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = ROOT / "configs"
ASTRODYN = [sys.executable, "-m", "astrodyn"]

pytestmark = pytest.mark.network


def _stop(proc: subprocess.Popen) -> None:
    stop_process(proc, timeout=20)


def _read_plain(path: Path):
    """Channels and messages with the plain mcap reader (seeking: needs a finished file)."""
    channels: dict[str, list] = {}
    schemas = {}
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            schemas[channel.topic] = (schema.name, schema.encoding, channel.message_encoding)
            channels.setdefault(channel.topic, []).append((message.log_time, message.sequence, json.loads(message.data)))
    return channels, schemas, meta, summary


@pytest.fixture(scope="module")
def demo_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo") / "demo.mcap"
    res = tmp_path_factory.mktemp("demo") / "result.json"
    proc = subprocess.run([*ASTRODYN, "run", str(CONFIGS / "demo.toml"), "--out", str(out), "--cross-check",
                           "--json", str(res), "--timeout", "400"],
                          capture_output=True, text=True, timeout=500, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return out, json.loads(res.read_text()), proc


def test_demo_run_records_every_channel_contiguously(demo_run):
    out, result, _ = demo_run
    scn = load(CONFIGS / "demo.toml")
    channels, schemas, meta, _ = _read_plain(out)
    n = scn.n_steps
    expected = set()
    for b in scn.bodies:
        if b.orbit is not None:
            expected |= {f"astrodyn/demo/{b.name}/orbit", f"astrodyn/demo/{b.name}/crosscheck"}
        if b.attitude is not None:
            expected.add(f"astrodyn/demo/{b.name}/attitude")
    got = {k for k in channels if not k.endswith("@event")}
    # --cross-check: every orbit (kepler and j2 both have a REBOUND twin) has a crosscheck channel
    assert got == expected
    assert "scenario" in meta and json.loads(meta["scenario"]["json"])["name"] == "demo"
    for topic in expected:
        msgs = channels[topic]
        assert schemas[topic][1:] == ("jsonschema", "json")
        seq = [m[2]["seq"] for m in msgs]
        assert seq == list(range(n)), topic  # contiguous from 0, no gaps, no duplicates
        t = np.array([m[2]["t"] for m in msgs])
        assert np.all(np.diff(t) > 0)
        log_time = np.array([m[0] for m in msgs], dtype=np.int64)
        assert np.array_equal(log_time, scn.epoch_unix_ns + np.round(t * 1e9).astype(np.int64))
    assert result["logger"]["missing"] == 0 and result["logger"]["malformed"] == 0


def _ulp_sensitivity(f, x0):
    """Largest change of f's output when x0 is perturbed by one ulp (relative 2.2e-16)."""
    base = f(x0)
    return max(np.max(np.abs(f(x0 * (1 + s * 2.2e-16)) - base)) for s in (1, -1))


def test_demo_states_equal_the_core_from_the_first_state(demo_run):
    """Kepler orbits and torque-free attitudes equal the core run from the first recorded
    state (both are exact solutions evaluated from the initial state at each t).  The
    tolerance is 100x the change a one-ulp perturbation of the first state causes
    (docs/architecture.md, section 6): the service's first state is itself the result of one
    evaluation, so the two runs start an ulp or so apart."""
    out, _, _ = demo_run
    scn = load(CONFIGS / "demo.toml")
    channels, _, _, _ = _read_plain(out)
    mu = scn.central_body.mu
    for b in scn.bodies:
        if b.orbit is not None and b.orbit.model == "kepler":
            msgs = [m[2] for m in channels[f"astrodyn/demo/{b.name}/orbit"]]
            t = np.array([m["t"] for m in msgs])
            r = np.array([m["r"] for m in msgs])
            v = np.array([m["v"] for m in msgs])
            rr, vv = propagate(r[0], v[0], t, mu)
            tol = 100 * _ulp_sensitivity(lambda x: propagate(x, v[0], t, mu)[0], r[0]) + 1e-15 * np.max(np.abs(r))
            assert np.max(np.abs(rr - r)) <= tol
            assert np.max(np.abs(rr - r) / np.linalg.norm(r, axis=1)[:, None]) < 1e-12
        if b.attitude is not None and b.attitude.model == "torque_free":
            msgs = [m[2] for m in channels[f"astrodyn/demo/{b.name}/attitude"]]
            t = np.array([m["t"] for m in msgs])
            q = np.array([m["q"] for m in msgs])
            w = np.array([m["w"] for m in msgs])
            inertia = b.attitude.principal_moments
            ww, qq = torque_free(inertia, w[0], q[0], t)
            sign = np.sign(np.sum(qq * q, axis=1))[:, None]
            tol = 100 * _ulp_sensitivity(lambda x: torque_free(inertia, x, q[0], t)[1], w[0]) + 1e-15
            assert np.max(np.abs(qq * sign - q)) <= tol, b.name
            assert np.max(np.abs(ww - w)) <= 100 * _ulp_sensitivity(lambda x: torque_free(inertia, x, q[0], t)[0], w[0]) + 1e-15 * np.max(np.abs(w))


def test_demo_summary_reports_models_and_crosscheck(demo_run):
    _, result, proc = demo_run
    rows = {r["body"]: r for r in result["bodies"]}
    assert rows["iss"]["orbit_model"] == "kepler" and rows["iss"]["attitude_model"] == "torque_free"
    assert rows["molniya"]["orbit_model"] == "j2"
    # REBOUND IAS15 vs the exact solution over one ISS orbit: IAS15 keeps ~1e-15 relative
    # per orbit (Rein & Spiegel 2015); 1e-6 m on 6.8e6 m (1.5e-13) leaves 100x for its
    # step-size control and the time-accumulation rounding of sim.t.
    assert rows["iss"]["crosscheck_max_dr"] < 1e-6
    assert "real-time factor" in proc.stdout and "iss" in proc.stdout


def test_demo_summary_matches_the_file(demo_run):
    """The drifts the propagators measured on what they published equal those measured on
    what the file holds (read back independently)."""
    from astrodyn.service.summary import file_summary

    out, result, _ = demo_run
    from_file = {r["body"]: r for r in file_summary(out, load(CONFIGS / "demo.toml"))}
    assert result["bodies"] == list(from_file.values())  # the printed summary is the file's
    for row in result["propagator_bodies"]:
        ref = from_file[row["body"]]
        for key in ("orbit_states", "attitude_states"):
            assert row.get(key) == ref.get(key)
        for key in ("energy_drift", "momentum_drift", "two_body_energy_change", "two_body_momentum_change",
                    "quat_norm_error", "rot_energy_drift", "crosscheck_max_dr"):
            if key in ref:
                assert abs(row[key] - ref[key]) <= 1e-15 + 1e-12 * abs(ref[key]), (row["body"], key)
        # two-body E and |h| are a "drift" only where the model conserves them (multihost walk:
        # the J2 Molniya's orbit process said "energy_drift": 7.7e-4, its conserved E with J2 1.6e-11)
        conserving = row["orbit_model"] in ("kepler", "actuated")
        if row.get("orbit_states"):
            assert ("energy_drift" in row) == conserving and ("two_body_energy_change" in row) != conserving, row
    assert {r["orbit_model"] for r in result["propagator_bodies"] if r.get("orbit_states")} >= {"kepler", "j2"}


def test_bad_config_exits_2_and_writes_nothing(tmp_path):
    cfg = tmp_path / "bad.toml"
    cfg.write_text((CONFIGS / "demo.toml").read_text().replace("e = 0.0005", "e = -0.1"))
    out = tmp_path / "x.mcap"
    proc = subprocess.run([*ASTRODYN, "run", str(cfg), "--out", str(out)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert "bodies[0] (iss).orbit.e" in proc.stderr and "-0.1" in proc.stderr
    assert not out.exists()


def test_unwritable_output_is_a_clear_error(tmp_path):
    proc = subprocess.run([*ASTRODYN, "run", str(CONFIGS / "demo.toml"), "--out", str(tmp_path / "no" / "such" / "x.mcap")],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "--out" in proc.stderr and "directory" in proc.stderr


def test_a_config_read_from_a_pipe_runs(tmp_path):
    """``astrodyn run <(generate-config)``: the config is a pipe, readable once.  The run reads
    it once and hands its processes a copy (before: each process opened the pipe again, the
    logger died 5 times and the run failed)."""
    import threading

    fifo = tmp_path / "generated.toml"
    os.mkfifo(fifo)
    text = (CONFIGS / "demo.toml").read_text().replace('duration = "93 min"', 'duration = "10 min"')

    def generate() -> None:
        with open(fifo, "w") as f:  # waits for the run to open it (the test's wait below bounds it)
            f.write(text)

    writer = threading.Thread(target=generate, daemon=True)
    writer.start()
    out = tmp_path / "piped.mcap"
    proc = subprocess.run([*ASTRODYN, "run", str(fifo), "--out", str(out), "--quiet"], capture_output=True, text=True,
                          timeout=300)
    writer.join(timeout=5)
    assert proc.returncode == 0, proc.stderr
    scenario = load(CONFIGS / "demo.toml")
    steps = int(10 * 60 * scenario.rate) + 1
    channels, _, _, _ = _read_plain(out)
    states = {topic: msgs for topic, msgs in channels.items() if topic.endswith(("/orbit", "/attitude"))}
    assert len(states) == 5  # iss, cubesat: orbit + attitude; molniya: orbit
    for topic, msgs in states.items():
        assert [payload["seq"] for _, _, payload in msgs] == list(range(steps)), topic


@pytest.mark.parametrize("command", ["run", "serve"])
def test_a_fifo_out_is_refused_at_once(tmp_path, command):
    fifo = tmp_path / "x.mcap"
    os.mkfifo(fifo)  # nobody writes it: reading it blocks (the check used to, forever)
    proc = subprocess.run([*ASTRODYN, command, str(CONFIGS / "demo.toml"), "--out", str(fifo)], capture_output=True,
                          text=True, timeout=60)
    assert proc.returncode == 2
    assert f"--out {fifo}: exists and is not an MCAP recording (expected a regular file, got a FIFO)" in proc.stderr
    assert stat.S_ISFIFO(os.stat(fifo).st_mode)


def test_too_low_an_open_file_limit_is_raised_or_refused_by_name(tmp_path):
    """``ulimit -n 20``: run raises its soft limit to what the hard limit allows and runs; with
    the hard limit at 20 too it refuses in one line, exit 1, nothing left behind (before: an
    OSError traceback from os.pipe, or a panic inside zenoh, and a stale work directory)."""
    import resource

    cfg = tmp_path / "fd.toml"
    cfg.write_text((CONFIGS / "demo.toml").read_text().replace('duration = "93 min"', 'duration = "5 min"'))
    _, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if hard != resource.RLIM_INFINITY and hard < 1024:
        pytest.skip(f"the hard open-file limit here is {hard}")
    for case, (limits, rc) in enumerate((((20, hard), 0), ((20, 20), 1))):
        out = tmp_path / f"fd{case}.mcap"
        proc = subprocess.run([*ASTRODYN, "run", str(cfg), "--out", str(out), "--quiet"], capture_output=True, text=True,
                              timeout=300, preexec_fn=lambda limits=limits: resource.setrlimit(resource.RLIMIT_NOFILE, limits))
        assert proc.returncode == rc, proc.stderr[-2000:]
        assert "Traceback" not in proc.stderr and "panicked" not in proc.stderr
        if rc:
            assert "open-file limit: expected at least 64 (ulimit -n), got 20" in proc.stderr
        assert out.exists() == (rc == 0) and not list(tmp_path.glob(f"fd{case}.partial*"))
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".astrodyn-")]


def _long_config(tmp_path: Path, duration: str = "30 d") -> Path:
    text = (CONFIGS / "demo.toml").read_text().replace('duration = "93 min"', f'duration = "{duration}"')
    cfg = tmp_path / "long.toml"
    cfg.write_text(text)
    return cfg


# Both in make test-all only (CI time): a propagator SIGKILLed under `run` and restarted with no
# hole is also test_zenoh_config_flag.py::test_run_restarts_a_killed_propagator_from_its_own_copy_when_the_file_was_deleted
# (every seq of both channels) and the random faults of test_supervision.py; a hung (SIGSTOPped) one is
# killed and restarted by the same Child.kill_if_stalled under serve in
# test_reliability.py::test_serve_restarts_a_killed_or_hung_propagator_from_the_last_state[SIGSTOP]
@pytest.mark.parametrize("fault", [pytest.param("SIGKILL", marks=pytest.mark.slow),
                                   pytest.param("SIGSTOP", marks=pytest.mark.slow)])
def test_killed_or_hung_propagator_is_restarted_and_the_file_has_no_hole(tmp_path, fault):
    """SIGKILL of the orbit propagator during `astrodyn run`, or SIGSTOP (hung: no heartbeat,
    so killed after ``--stall-timeout``, 3 s here): the runner restarts it after the
    last step the logger flushed; the run goes on (stopped here by Ctrl-C after the restart)
    and every orbit channel in the file is 0, 1, 2, ... without a hole or a duplicate,
    reaching past the step where the process was killed."""
    from astrodyn.recording import load as load_run

    cfg = _long_config(tmp_path)
    out = tmp_path / "killed.mcap"
    partial = tmp_path / "killed.partial.mcap"
    proc = subprocess.Popen([*ASTRODYN, "run", str(cfg), "--out", str(out), "--stall-timeout", "3"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    pid = None
    try:
        deadline = time.monotonic() + 120
        while pid is None and time.monotonic() < deadline:
            line = proc.stderr.readline()
            m = re.search(r"orbit \(pid (\d+)\)", line)
            if m:
                pid = int(m.group(1))
        assert pid is not None, "runner never reported the orbit process's pid"
        # let it publish for a while (orbit states flushed to the file), then kill it
        before = 0
        deadline = time.monotonic() + 90
        while time.monotonic() < deadline:
            time.sleep(0.5)
            if partial.exists():
                run = load_run(partial)  # reads a file still being written, up to its last chunk
                before = max((len(b.orbit) for b in run.bodies.values() if b.orbit is not None), default=0)
                if before > 1000:
                    break
        os.kill(pid, getattr(signal, fault))
        how = "killed by signal 9" if fault == "SIGKILL" else "stalled (no heartbeat for"
        restarted, lines = False, []
        deadline = time.monotonic() + 60
        while not restarted and time.monotonic() < deadline:
            line = proc.stderr.readline()
            lines.append(line)
            restarted = f"orbit (pid {pid}) {how}" in line and "restarted" in line
        assert restarted, "".join(lines[-20:])
        assert not Path(f"/proc/{pid}").exists()  # the hung one was killed (and reaped) before its restart
        time.sleep(3.0)  # the new process publishes past the point of the kill
        os.kill(proc.pid, signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=120)
    finally:
        _stop(proc)
        if pid is not None and Path(f"/proc/{pid}").exists():  # only the process this test stopped
            os.kill(pid, signal.SIGKILL)
    assert proc.returncode == 128 + signal.SIGINT
    assert not out.exists()  # an interrupted run does not claim the final name
    run = load_run(partial)
    assert not run.truncated  # the logger finished the file at the interrupt
    orbit_tracks = [b.orbit for b in run.bodies.values() if b.orbit is not None]
    assert orbit_tracks and all(len(t) > before for t in orbit_tracks)
    for track in orbit_tracks:  # the restart left no hole and no duplicate
        assert np.array_equal(track.seq, np.arange(len(track)))


def test_gravity_gradient_attitude_uses_the_published_orbit():
    """The attitude engine's orbit positions are the orbit engine's, bit for bit."""
    from astrodyn.simulate import AttitudeEngine, OrbitEngine

    scn = load(CONFIGS / "leo-gravity-gradient.toml")
    orbits = OrbitEngine(scn)
    att = AttitudeEngine(scn)
    t = np.linspace(0.0, 3000.0, 31)
    r_pub, _ = orbits.states(t)
    k = att.names.index("gg-boom")
    r_att = att.bodies[k].torque.position(t)
    assert np.array_equal(r_att, r_pub[:, orbits.names.index("gg-boom")])


@pytest.mark.slow  # CI time (13 s; serve's verbs stay covered by test_serve_rate_sync, test_control_wildcard, test_send_control_errors, test_clients_doc)
def test_serve_control_over_zenoh(tmp_path):
    port = bus.free_port()
    out = tmp_path / "serve.mcap"
    proc = subprocess.Popen([*ASTRODYN, "serve", str(_long_config(tmp_path)), "--out", str(out), "--rate", "50",
                             "--port", str(port), "--max-wall", "120"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        hello = json.loads(proc.stdout.readline())
        assert hello["serving"] == "demo"
        token = hello["control_token"]
        token_file = Path(hello["control_token_file"])
        assert token_file.read_text() == token and stat.S_IMODE(token_file.stat().st_mode) == 0o600
        with bus.open_session(connect=[bus.loopback_endpoint(port)]) as s:
            def status():
                (reply,) = bus.send_control(s, "demo", "status", token=token)
                return reply

            deadline = time.monotonic() + 60
            while status()["t"] < 20 and time.monotonic() < deadline:
                time.sleep(0.2)
            st = status()
            # without the token (or with another) nothing is obeyed
            for bad in (None, token[::-1]):
                (refused,) = bus.send_control(s, "demo", "pause", token=bad)
                assert "unauthorised" in refused["error"]
            for factor in (1e-300, 1e7, "nan", -1, True, 10**400, "5", [2]):  # 10**400 once crashed serve
                (refused,) = bus.send_control(s, "demo", "rate", {"factor": factor}, token=token)
                assert "1e+06" in refused["error"] and "0.001" in refused["error"], refused
            assert status()["state"] == "running" and status()["real_time_factor"] == 50.0
            assert st["state"] == "running" and st["real_time_factor"] == 50.0
            assert bus.send_control(s, "demo", "pause", token=token)[0]["state"] == "paused"
            time.sleep(1.5)  # heartbeats (0.5 s period) settle
            t1 = status()["t"]
            time.sleep(1.5)
            assert status()["t"] == t1  # nothing advances while paused
            bus.send_control(s, "demo", "resume", token=token)
            bus.send_control(s, "demo", "rate", {"factor": 200}, token=token)
            time.sleep(1.0)
            t1, w1 = status()["t"], time.monotonic()
            time.sleep(3.0)
            t2, w2 = status()["t"], time.monotonic()
            # 200 sim s per wall s; heartbeat granularity 0.5 s and 1 s output steps
            assert 100 < (t2 - t1) / (w2 - w1) < 300
            err = bus.send_control(s, "demo", "rate", {"factor": -1}, token=token)
            assert "error" in err[0] and "factor" in err[0]["error"]
            (final,) = bus.send_control(s, "demo", "stop", timeout_s=60, token=token)
            assert final["state"] == "stopped" and final["logger"]["missing"] == 0
        proc.communicate(timeout=60)
        assert proc.returncode == 0
    finally:
        _stop(proc)
    assert not token_file.exists()  # the token is never valid again: its file goes with serve
    channels, _, _, _ = _read_plain(out)
    for topic, msgs in channels.items():
        if topic.endswith(("/orbit", "/attitude")):
            seq = [m[2]["seq"] for m in msgs]
            assert seq == list(range(len(seq)))


def test_zenoh_config_file_reaches_every_process(tmp_path):
    """--zenoh-config (TLS / access control in real use) is loaded by the runner and every
    child; a file Zenoh cannot read is refused up front (exit 2, nothing written)."""
    cfg = tmp_path / "zenoh.json5"
    cfg.write_text("{\n  // extra settings only; astrodyn sets mode, endpoints, scouting\n"
                   "  transport: { unicast: { max_sessions: 64 } },\n}\n")
    out = tmp_path / "dz.mcap"
    ok = subprocess.run([*ASTRODYN, "run", str(CONFIGS / "dzhanibekov.toml"), "--out", str(out), "--quiet",
                         "--zenoh-config", str(cfg)], capture_output=True, text=True, timeout=300)
    assert ok.returncode == 0, ok.stderr[-2000:]
    bad_out = tmp_path / "bad.mcap"
    bad = subprocess.run([*ASTRODYN, "run", str(CONFIGS / "dzhanibekov.toml"), "--out", str(bad_out), "--quiet",
                          "--zenoh-config", str(tmp_path / "missing.json5")], capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and "--zenoh-config" in bad.stderr and not bad_out.exists()


def test_a_restarted_propagator_catches_up_with_the_schedule():
    """Pacer(anchor=...): a process started 2 s late on a 10x schedule publishes at once
    until it is back on it, then waits as the schedule says (wall clock arithmetic)."""
    import time as _time

    from astrodyn.service.propagator import Pacer

    now = _time.monotonic()
    late = Pacer(10.0, anchor=(now - 2.0, 0.0))  # t = 0 was due 2 s ago: t = 20 s is due now
    assert late.wait_time(5.0) == 0.0 and late.wait_time(19.9) == 0.0
    assert 0.9 < late.wait_time(30.0) <= 1.0  # 10 s of sim ahead of the schedule: 1 s of wall
    fresh = Pacer(10.0)  # no anchor: the first instant starts the schedule
    assert fresh.wait_time(100.0) == 0.0 and 0.09 < fresh.wait_time(101.0) <= 0.1


@pytest.mark.slow  # CI time (10 s; an edge of the restart path that test_reliability covers in make test)
def test_a_restarted_propagator_with_no_step_left_ends_when_the_logger_has_finished():
    """Found by the random-fault series: a propagator killed after its last step was recorded
    (while it waited for the logger's receipt) was restarted at step N = n_steps, the logger
    finished the file meanwhile, and the new process waited 30 s for a logger that was gone:
    the run failed.  With nothing left to publish it now ends at once, exit 0; with steps left
    it still refuses to publish into the void (exit 1, naming the logger)."""
    from astrodyn.scenario import load as load_scenario

    n = load_scenario(CONFIGS / "demo.toml").n_steps
    started = time.monotonic()
    done = subprocess.run([sys.executable, "-m", "astrodyn.service.propagator", "orbit", str(CONFIGS / "demo.toml"),
                           "--start-step", str(n), "--wait-logger", "30"], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert time.monotonic() - started < 25  # the 5 s of NOTHING_LEFT_WAIT_S, not the 30 s of --wait-logger
    left = subprocess.run([sys.executable, "-m", "astrodyn.service.propagator", "orbit", str(CONFIGS / "demo.toml"),
                           "--start-step", str(n - 10), "--wait-logger", "2"], capture_output=True, text=True, timeout=120)
    assert left.returncode != 0 and "logger" in left.stderr, left.stderr[-2000:]


def _assert_the_propagators_stay_paused(session, token: str, timeout_s: float = 60.0) -> None:
    """Once the demo's orbit and attitude propagators have each sent a heartbeat with a sim
    time (serve's status through ``session``, with the control ``token``) and a re-sent
    pause has had time to land (~1.5 s), neither one's sim time moves for 2 s (40 s of sim
    time at x20, thousands at rate inf, if they ran)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        procs = bus.send_control(session, "demo", "status", token=token)[0]["processes"]
        if all(procs[k]["t"] is not None for k in ("orbit", "attitude")):
            break
        time.sleep(0.2)
    time.sleep(2.5)
    before = bus.send_control(session, "demo", "status", token=token)[0]["processes"]
    time.sleep(2.0)
    after = bus.send_control(session, "demo", "status", token=token)[0]["processes"]
    assert [after[k]["t"] for k in ("orbit", "attitude")] == [before[k]["t"] for k in ("orbit", "attitude")]


@pytest.mark.slow  # CI time (9 s; pause and resume stay covered by test_serve_rate_sync and test_ctrl_z)
def test_a_pause_sent_while_the_propagators_start_holds_at_rate_inf(tmp_path):
    """At ``--rate inf`` a propagator never waits, so it sent no heartbeat saying its pause
    state and serve never saw that a propagator had missed its early ``pause``: serve said
    ``paused`` while the propagators ran on (55,000 s of sim time in 9 s).  Every heartbeat
    now says it."""
    out = tmp_path / "inf.mcap"
    serve, hello = serve_demo(out, "inf")
    try:
        token = hello["control_token"]
        with bus.open_session(connect=[hello["hub"]]) as s:
            assert bus.send_control(s, "demo", "pause", token=token)[0]["state"] == "paused"  # before they listen
            _assert_the_propagators_stay_paused(s, token)
            (stopped,) = bus.send_control(s, "demo", "stop", token=token, timeout_s=60)
            assert stopped["state"] == "stopped"
        serve.wait(timeout=60)
    finally:
        stop_process(serve)
    assert serve.returncode == 0, serve.stderr.read()[-3000:]


@pytest.mark.slow  # CI time: ::test_a_pause_sent_while_the_propagators_start_holds_at_rate_inf stays in make test
def test_a_pause_and_a_stop_sent_while_the_propagators_start_still_reach_them(tmp_path):
    """Serve's commands are plain puts: a propagator that subscribes after one was sent (it
    is still loading its kernels or waiting for the logger) missed it, and ran on while
    serve said ``paused``, or never heard ``stop`` (serve then waited its 60 s).  Serve now
    sends pause / resume again while a propagator's heartbeat disagrees, and stop until each
    propagator has ended; the rate likewise.  Checked against serve's own status: paused
    means no propagator's sim time moves, then each moves at the rate set; stop is answered
    within seconds."""
    out = tmp_path / "early.mcap"
    serve, hello = serve_demo(out, "20")
    try:
        token = hello["control_token"]
        with bus.open_session(connect=[hello["hub"]]) as s:
            assert bus.send_control(s, "demo", "pause", token=token)[0]["state"] == "paused"  # at once: before they listen
            assert bus.send_control(s, "demo", "rate", {"factor": 5}, token=token)[0]["real_time_factor"] == 5
            _assert_the_propagators_stay_paused(s, token)
            assert bus.send_control(s, "demo", "resume", token=token)[0]["state"] == "running"
            time.sleep(1.5)  # re-anchored at the resume, then paced at x5 (x20 if the rate had been missed)
            first = bus.send_control(s, "demo", "status", token=token)[0]["processes"]
            time.sleep(4.0)
            last = bus.send_control(s, "demo", "status", token=token)[0]["processes"]
            for k in ("orbit", "attitude"):  # 20 s of sim time at x5 (+- heartbeat periods); x20 would give ~80 s
                assert 10 <= last[k]["t"] - first[k]["t"] <= 40, (k, first[k]["t"], last[k]["t"])
            started = time.monotonic()
            (stopped,) = bus.send_control(s, "demo", "stop", token=token, timeout_s=60)
            assert stopped["state"] == "stopped" and time.monotonic() - started < 15, stopped
        serve.wait(timeout=60)
    finally:
        stop_process(serve)
    assert serve.returncode == 0, serve.stderr.read()[-3000:]


BOOM_SITECUSTOMIZE = '''
import os
if b"astrodyn.service.propagator" in open("/proc/self/cmdline", "rb").read().split(b"\\0"):
    from astrodyn import simulate

    def _states(self, times):  # the same input, the same failure: a deterministic fault of the model
        raise RuntimeError("a deterministic failure of this model")

    simulate.OrbitEngine.states = _states
'''


def test_a_propagator_that_fails_the_same_way_at_the_same_step_is_not_restarted_for_ever(tmp_path):
    """A propagator that ends with its own error, restarted at the same step and failing again
    there with the same error, is deterministic: after 3 such deaths the run fails naming the
    error (restart lines carry it too).  Before, each restart said only "exited with status 1"
    and the run went on restarting until 5 deaths fell within 60 s; deaths further apart (a J2
    block of 60 s at a long output spacing, horizons probe F7) restarted it for ever."""
    site = tmp_path / "site"
    site.mkdir()
    (site / "sitecustomize.py").write_text(BOOM_SITECUSTOMIZE)
    cfg = tmp_path / "boom.toml"
    cfg.write_text((Path(__file__).resolve().parents[1] / "configs" / "demo.toml").read_text())
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run([*ASTRODYN, "run", cfg, "--out", tmp_path / "boom.mcap"], capture_output=True, text=True,
                          timeout=300, env=env)
    assert done.returncode == 1, done.stderr[-3000:]
    said = "exited with status 1: orbit: failed: RuntimeError: a deterministic failure of this model"
    assert done.stderr.count(f"{said}: restarted") == 2, done.stderr[-3000:]
    assert f"{said}, again: 3 times in a row at step 0 without recording a step; not restarted again" in done.stderr, \
        done.stderr[-3000:]
    assert "died 5 times" not in done.stderr
