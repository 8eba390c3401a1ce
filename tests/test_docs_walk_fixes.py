"""Code problems a new user found walking the docs (docs walk of 2026-11-26, "Code problems").

Each test fails on the code before its fix:

* (3) the ``ATTACKED`` line of ``serve`` named "the logger and the plant" in a scene without a
  plant: :func:`test_the_attacked_line_names_only_the_processes_that_rejected` checks
  ``astrodyn.service.runner.attack_report``, whose fix is a patch to runner.py given in
  /work/notes/docs_walk_fixes.md: THIS TEST FAILS UNTIL THAT PATCH IS APPLIED
  (``pytest tests/test_docs_walk_fixes.py -k attacked``);
* (4) ``events.csv`` / ``events.parquet`` marked the Event field ``kind`` as foreign (``kind=?``);
* (5) an orbit moved by burns reported their changes of E and h as the drift of a
  conserved quantity (0.84 and 1.5 for configs/hohmann.toml);
* (6) ``validate`` and ``run`` said "1 bodies";
* (7) a controller started by hand on examples/astrodyn_link.py with a malformed
  ``ASTRODYN_CONNECT`` (the ``:`` of the ``bus tcp/...:`` line) or at a hub without its run
  waited for ever.

(2), the replay clock while it waits for a subscriber, is tested in tests/test_replay.py
(``test_a_waiting_replay_stays_at_its_start_time_until_playback``).
"""

from __future__ import annotations

import csv
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from astrodyn import messages
from astrodyn.recording import McapRecorder

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _recordings import one_satellite_scene

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"


# --------------------------------------------------------------------------- (3) the ATTACKED line


def test_the_attacked_line_names_only_the_processes_that_rejected():
    """FAILS UNTIL the attack_report patch of /work/notes/docs_walk_fixes.md is applied to
    src/astrodyn/service/runner.py.  ``serve configs/demo.toml`` (no ``[control]``: no plant)
    fed a replay printed "ATTACKED: the logger and the plant rejected 44652 messages"."""
    from astrodyn.service.runner import attack_report

    logger = {"rejected": {"unsigned": 44652}, "rejected_by_sender": {"(unsigned)": 44652}}
    for plant in (None, {}, {"rejected": {}}, {"applied": 3, "rejected": {"bad-token": 0}}):  # no plant, or none refused
        line = attack_report(logger, plant)
        assert line.startswith("the logger rejected 44652 messages that were not this run's own (44652 unsigned; "
                               "senders: (unsigned) x44652)"), (plant, line)
        assert "plant" not in line, line
    line = attack_report({"rejected": {}}, {"rejected": {"unsigned": 2, "bad-token": 1}})  # the plant alone
    assert line.startswith("the plant rejected 3 messages that were not this run's own (1 command bad-token, "
                           "2 command unsigned)"), line
    assert "logger" not in line and "senders" not in line, line
    line = attack_report(logger, {"rejected": {"unsigned": 2}})  # both
    assert line.startswith("the logger and the plant rejected 44654 messages"), line
    assert "2 command unsigned" in line and "44652 unsigned" in line, line
    assert attack_report({"rejected": {}}, None) is None and attack_report(None, {"rejected": {"x": 0}}) is None


# --------------------------------------------------------------------------- (4) export units


def _events_recording(path: Path) -> None:
    """A small recording: 11 orbit states of one body and three events of two processes."""
    from astrodyn.scenario import loads

    sc = loads(one_satellite_scene("ev", "10 s", "1 Hz"))
    with McapRecorder(path, sc.to_metadata(), epoch_ns=sc.epoch_unix_ns) as rec:
        for k in range(11):
            rec.write(messages.orbit_key("ev", "sat"),
                      messages.orbit_message(float(k), k, "kepler", [7.0e6, 7.5e3 * k, 0.0], [0.0, 7.5e3, 0.0], 3.986e14))
        for t, seq, process, kind, detail in ((0.0, 0, "orbit", "start", ""), (0.0, 0, "logger", "start", ""),
                                              (10.0, 1, "orbit", "stop", '{"messages": 11}')):
            key = messages.event_key("ev")  # seq counted per process, as the logger does (track)
            rec.write_encoded(key, messages.encode(messages.event_message(t, seq, process, kind, detail), key), t, seq,
                              track=f"{key}:{process}")


def test_events_export_gives_kind_the_unit_of_text_like_process_and_detail(tmp_path):
    """events.csv said ``# units: t=s, seq=1, log_time_ns=ns, kind=?``: ``?`` marks the fields
    of foreign channels, but ``kind`` is the Event's own (FIELD_UNITS had the key ``event``)."""
    from astrodyn.recording.export import FIELD_UNITS, column_units, export

    _events_recording(tmp_path / "events.mcap")
    out = tmp_path / "csv"
    out.mkdir()
    export(tmp_path / "events.mcap", "csv", out)
    lines = (out / "events.csv").read_text().splitlines()
    head = dict(line[2:].split(": ", 1) for line in lines if line.startswith("# "))
    assert head["units"] == "t=s, seq=1, log_time_ns=ns", head  # text columns (process, kind, detail) have no unit
    rows = list(csv.DictReader(line for line in lines if not line.startswith("#")))
    assert [r["kind"] for r in rows] == ["start", "start", "stop"]
    # every field astrodyn defines has a unit (or "" for text), never the foreign mark; but the
    # gyroscopes' "indicated" (rad/s or rad by gyro type) and the objects of status and tick
    undefined = {"indicated", "state", "real_time_factor", "rate", "messages", "processes", "samples"}
    import msgspec

    for kind, message_type in messages.MESSAGE_TYPES.items():
        for field in msgspec.structs.fields(message_type):
            if field.name not in undefined:
                assert field.name in FIELD_UNITS, (kind, field.name)
    assert column_units(["kind", "process", "detail", "dv_t", "dv_x", "u_0", "contact_x"]) == {
        "kind": "", "process": "", "detail": "", "dv_t": "s", "dv_x": "m/s", "u_0": "rad/s", "contact_x": "m"}
    pq = pytest.importorskip("pyarrow.parquet")
    export(tmp_path / "events.mcap", "parquet", out)
    schema = pq.read_table(out / "events.parquet").schema
    assert schema.field("kind").metadata == schema.field("process").metadata == {b"unit": b""}


# --------------------------------------------------------------------------- (5) orbits moved by burns

BURNS_SCENE = """
[scenario]
name = "burns"
epoch = "2026-03-20T12:00:00 UTC"
duration = "3000 s"
rate = "0.1 Hz"

[central_body]
name = "earth"

[control]
period = "10 s"
controllers = ["plan"]

[[bodies]]
name = "sat"
[bodies.orbit]
a = "7000 km"
e = 0
i = "0 deg"
[bodies.actuators]
dv = "1 km/s"
thrust = "50 N"
mass = "500 kg"
"""

#: The burns of the test's orbit: impulses (t s, dv m/s inertial) and one thrust arc.
IMPULSES = ((1234.5, (20.0, 100.0, 0.0)), (2000.0, (0.0, -50.0, 10.0)))  # inside a step; on a step
THRUST = (2505.0, 2600.0, (0.0, 40.0, 5.0))  # from, to (s), force (N): starts inside a step


def _burns_recording(path: Path):
    """A closed loop as the plant records it (docs/control.md): per output step k (10 s) the
    orbit state at t_k, the commands applied in the step (copies), the actuator state of the
    step.  Coasts by the exact two-body propagation, thrust by the plant's own integration;
    a command at t_k applies after the state at t_k is read off, one inside the step at its
    own t.  Returns (scenario, t, r, v, the velocity just before each impulse)."""
    from astrodyn.orbit import propagate
    from astrodyn.orbit.maneuvers import ConstantThrust
    from astrodyn.orbit.perturbations import propagate_perturbed
    from astrodyn.scenario import loads

    sc = loads(BURNS_SCENE)
    mu = sc.central_body.mu
    mass = 500.0
    r, v = np.array([7.0e6, 0.0, 0.0]), np.array([0.0, np.sqrt(mu / 7.0e6), 0.0])
    force = np.zeros(3)
    now = 0.0
    before_impulse = {}
    commands = sorted([(t, {"dv": list(dv)}) for t, dv in IMPULSES]
                      + [(THRUST[0], {"thrust": list(THRUST[2])}), (THRUST[1], {"thrust": [0.0, 0.0, 0.0]})],
                      key=lambda c: c[0])

    def advance(to: float):
        nonlocal r, v, now
        if to > now:
            if np.any(force):
                out = propagate_perturbed(r, v, to - now, mu, [ConstantThrust(force, mass)], rtol=1e-13, atol=1e-15,
                                          error_estimate=False)
                r, v = np.asarray(out.r).reshape(3), np.asarray(out.v).reshape(3)
            else:
                r1, v1 = propagate(r, v, to - now, mu)
                r, v = np.asarray(r1), np.asarray(v1)
            now = to

    def apply(t: float, cmd: dict) -> dict:
        nonlocal v, force
        if "dv" in cmd:
            before_impulse[t] = v.copy()
            v = v + np.asarray(cmd["dv"])
        if "thrust" in cmd:
            force = np.asarray(cmd["thrust"], dtype=np.float64)
        return {"t": t, "seq": commands.index((t, cmd)), "sender": "plan", **cmd}

    times = np.arange(301) * 10.0
    rs, vs = [], []
    with McapRecorder(path, sc.to_metadata(), epoch_ns=sc.epoch_unix_ns) as rec:
        for k, tk in enumerate(times):
            advance(tk)
            rs.append(r.copy())
            vs.append(v.copy())
            rec.write(messages.orbit_key("burns", "sat"), messages.orbit_message(tk, k, "actuated", r, v, mu))
            step_dv, dv_t, applied = None, None, []
            due = [c for c in commands if tk - 1e-9 <= c[0] < tk + 10.0 - 1e-9]
            for t, cmd in due:
                if t > tk + 1e-9:
                    continue  # inside the step: below
                applied.append(apply(t, cmd))
            thrust_at_start = force.copy()
            for t, cmd in due:
                if t > tk + 1e-9:
                    advance(t)
                    applied.append(apply(t, cmd))
            for c in applied:
                rec.write(messages.body_key("burns", "sat", "command"), c)
                if "dv" in c:
                    step_dv, dv_t = (np.zeros(3) if step_dv is None else step_dv) + np.asarray(c["dv"]), c["t"]
            state = {"t": tk, "seq": k, "torque": [0.0, 0.0, 0.0], "thrust": thrust_at_start.tolist(), "mass": mass}
            if step_dv is not None:
                state.update(dv=step_dv.tolist(), dv_t=dv_t)
            rec.write(messages.body_key("burns", "sat", "actuators"), state)
    return sc, times, np.array(rs), np.array(vs), before_impulse


@pytest.fixture(scope="module")
def burns(tmp_path_factory):
    path = tmp_path_factory.mktemp("burns") / "burns.mcap"
    return (path, *_burns_recording(path))


def _energy(r, v, mu):
    return 0.5 * np.einsum("ij,ij->i", v, v) - mu / np.linalg.norm(r, axis=1)


def test_the_test_orbit_is_conserved_on_its_coasts_and_changed_by_its_burns(burns):
    """The recording itself, independent of the analysis code: on each coast arc of a Kepler
    orbit E and h are constant to round-off; across an impulse E changes by v.dv + |dv|^2/2
    (vis-viva) and by far more than round-off."""
    path, sc, t, r, v, before = burns
    mu = sc.central_body.mu
    energy, h = _energy(r, v, mu), np.cross(r, v)
    for lo, hi in ((0.0, 1230.0), (1240.0, 2000.0), (2010.0, 2500.0), (2600.0, 3000.0)):
        arc = (t >= lo) & (t <= hi)
        assert np.max(np.abs(energy[arc] - energy[arc][0])) < 1e-12 * abs(energy[arc][0])
        assert np.max(np.linalg.norm(h[arc] - h[arc][0], axis=1)) < 1e-12 * np.linalg.norm(h[arc][0])
    k = np.searchsorted(t, 1234.5)
    dv = np.array(IMPULSES[0][1])
    assert energy[k] - energy[k - 1] == pytest.approx(before[1234.5] @ dv + dv @ dv / 2, rel=1e-9)
    assert abs(energy[-1] - energy[0]) > 1e-3 * abs(energy[0])


def test_analyze_judges_an_actuated_orbit_between_its_burns(burns, tmp_path):
    """``analyze`` of configs/hohmann.toml said "largest drift of a conserved quantity 1.5":
    the burns' changes of E and h.  Now the rows are "... between burns", each drift over a
    coast arc from its first state (round-off here), and the closed-loop section lists what
    each burn changed: an impulse by v.dv + |dv|^2/2."""
    from astrodyn.analysis import analyze, at_a_glance

    path, sc, t, r, v, before = burns
    report = analyze(path, tmp_path / "report", figures_for=0)
    body = report["bodies"]["sat"]
    conserved = body["conserved quantities"]
    assert set(conserved) == {"orbit: E (two-body) between burns [J/kg], max drift relative to |E0| of its coast arc",
                              "orbit: h between burns [m^2/s], max drift relative to |h0| of its coast arc"}, conserved
    assert max(conserved.values()) < 1e-12, conserved
    assert body["orbit"]["energy_coast_drift_max"] < 1e-12 and body["orbit"]["h_coast_drift_max"] < 1e-12, body["orbit"]
    assert body["orbit"]["coast_arcs"] == 4 and "energy_drift_max" not in body["orbit"]
    changes = body["closed loop"]["orbit change across each burn"]
    assert [(c["from t (s)"], c["to t (s)"]) for c in changes] == [(1230.0, 1240.0), (1990.0, 2010.0), (2500.0, 2600.0)]
    for change, (tau, dv) in zip(changes, IMPULSES):
        dv = np.array(dv)
        assert change["E change (J/kg)"] == pytest.approx(before[tau] @ dv + dv @ dv / 2, rel=1e-9), tau
    assert "largest drift of a conserved quantity" in at_a_glance(report)[0]
    assert float(at_a_glance(report)[0].split("conserved quantity ")[1].split()[0]) < 1e-12


def test_the_run_summary_judges_an_actuated_orbit_between_its_burns_block_by_block(burns, capsys):
    """The end of ``run`` (astrodyn.service.summary) showed E and h "max drift" 8.4e-01 and
    1.5e+00 for configs/hohmann.toml.  Read in blocks of any size (memory flat), the rows are
    "... between burns" at round-off, the same as in one block."""
    from astrodyn.service.summary import file_summary, print_summary

    path, sc, *_ = burns
    results = []
    for block_messages in (50_000, 97, 13):  # one block; blocks that split arcs and burns
        (row,) = file_summary(path, sc, block_messages=block_messages)
        rows = {i["name"]: i for i in row["orbit_invariants"]}
        assert set(rows) == {"E (two-body) between burns", "h between burns"}, rows
        assert all(i["drift"] < 1e-12 and i["scale"].endswith("of its coast arc") for i in rows.values()), rows
        assert row["energy_drift"] < 1e-12 and row["momentum_drift"] < 1e-12, row
        assert rows["E (two-body) between burns"]["initial"] == pytest.approx(-sc.central_body.mu / 2 / 7.0e6, rel=1e-12)
        results.append(row)
    assert results[1]["orbit_invariants"] == results[0]["orbit_invariants"]
    print_summary({"out": str(path), "wall_s": 1.0, "logger": {}}, [results[0]], sc)
    table = capsys.readouterr().out
    assert "E (two-body) between burns" in table and "h between burns" in table, table


def test_coast_arcs_break_at_impulses_and_thrust_from_either_channel():
    """:class:`OrbitActuation`: an impulse at tau separates the states at a <= tau <= b (the
    state at tau alone), thrust over [s, e) separates the states whose interval it overlaps;
    thrust known from a command inside a step (the actuator state shows it a step later)."""
    from types import SimpleNamespace

    from astrodyn.analysis.closed_loop import OrbitActuation

    class Track(SimpleNamespace):  # a recorded track: its fields as arrays, and their names in .fields
        def __len__(self):
            return len(self.t)

    nan3 = [np.nan] * 3
    actuators = Track(t=np.array([0.0, 10.0, 20.0, 30.0]), dv=np.array([nan3, [1.0, 0, 0], nan3, nan3]),
                      dv_t=np.array([np.nan, 15.0, np.nan, np.nan]),
                      thrust=np.array([[0.0, 0, 0], [0, 0, 0], [0, 0, 0], [1.0, 0, 0]]))
    actuators.fields = {"t": 0, "dv": 0, "dv_t": 0, "thrust": 0}
    commands = Track(t=np.array([15.0, 27.0]), dv=np.array([[1.0, 0, 0], nan3]), thrust=np.array([nan3, [1.0, 0, 0]]))
    commands.fields = {"t": 0, "dv": 0, "thrust": 0}
    act = OrbitActuation()
    assert not act
    act.add(actuators, commands)
    assert act.impulses == [15.0] and act.thrust == [[30.0, np.inf], [27.0, np.inf]]
    t = np.arange(0.0, 60.0, 5.0)  # 0 5 10 15 20 25 30 ...
    starts = act.arc_starts(t)
    assert t[starts].tolist() == [0.0, 15.0, 20.0, 30.0, 35.0, 40.0, 45.0, 50.0, 55.0]
    # the same, fed in two blocks, the second block's first state against the first's last
    a2 = OrbitActuation()
    a2.add(Track(**{k: getattr(actuators, k)[:2] for k in ("t", "dv", "dv_t", "thrust")},
                 fields=actuators.fields), Track(t=commands.t[:1], dv=commands.dv[:1], thrust=commands.thrust[:1],
                                                 fields=commands.fields))
    first = a2.arc_starts(t[:4])
    a2.add(Track(**{k: getattr(actuators, k)[2:] for k in ("t", "dv", "dv_t", "thrust")}, fields=actuators.fields),
           Track(t=commands.t[1:], dv=commands.dv[1:], thrust=commands.thrust[1:], fields=commands.fields))
    assert np.concatenate([first, a2.arc_starts(t[4:], t_before=t[3])]).tolist() == starts.tolist()


# --------------------------------------------------------------------------- (6) "1 bodies"


def test_the_plan_says_1_body_not_1_bodies():
    """``validate`` and ``run`` print the plan: "scenario slew: 1 bodies, ..." (configs/slew.toml,
    hohmann, detumble, gyro-instruments, flexible-slew)."""
    from astrodyn.scenario import load, plan

    text = plan(load(ROOT / "configs" / "slew.toml")).text()
    assert text.startswith("scenario slew: 1 body, 1801 output steps, 1801 state messages (attitude)"), text
    assert plan(load(ROOT / "configs" / "demo.toml")).text().startswith("scenario demo: 3 bodies, "), text


# --------------------------------------------------------------------------- (7) a controller started by hand


def _controller_by_hand(tmp_path: Path, endpoint: str, **env) -> subprocess.Popen:
    """examples/detumble.py started by hand with the control token (a token file of its own:
    nothing checks it before a tick comes), as docs/control.md says, its stderr piped."""
    token = tmp_path / "control.token"
    token.write_text("0" * 64)
    base = {k: v for k, v in os.environ.items() if k != "ASTRODYN_RUN_SECRET_FILE"}
    return subprocess.Popen([sys.executable, str(EXAMPLES / "detumble.py")], stderr=subprocess.PIPE, text=True,
                            env={**base, "ASTRODYN_CONNECT": endpoint, "ASTRODYN_CONTROL_TOKEN_FILE": str(token),
                                 "ASTRODYN_SCENARIO": "detumble", "ASTRODYN_CONTROLLER": "detumble", **env})


def _ended_within(proc: subprocess.Popen, seconds: float) -> tuple[int, str, float]:
    """(exit status, stderr, wall s) of ``proc``; killed by its PID and failed past ``seconds``."""
    started = time.monotonic()
    try:
        _, err = proc.communicate(timeout=seconds)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate()
        raise AssertionError(f"the controller still waited after {seconds} s") from None
    return proc.returncode, err, time.monotonic() - started


@pytest.mark.parametrize("endpoint, says", [
    ("tcp/127.0.0.1:37811:", "port '' is not an integer (the ':' that ends the run's `bus tcp/...:` line"),
    ("127.0.0.1:37811", "no PROTOCOL/ before the address"),
    ("tcp/127.0.0.1:99999", "port 99999 is not in 1..65535"),
])
def test_a_controller_given_a_malformed_endpoint_says_so_at_once(tmp_path, endpoint, says):
    proc = _controller_by_hand(tmp_path, endpoint)
    rc, err, _ = _ended_within(proc, 20)
    assert rc == 1 and err.count("\n") == 1 and "Traceback" not in err, err
    assert err.startswith(f"astrodyn_link: ASTRODYN_CONNECT: expected a Zenoh endpoint like 'tcp/127.0.0.1:7447', "
                          f"got {endpoint!r}: {says}"), err


@pytest.mark.network
def test_a_controller_started_by_hand_gives_up_when_no_tick_comes(tmp_path, hub):
    """A well-formed endpoint where no run ticks (the test's own hub: a wrong scenario, a run
    that has ended): before, the controller waited for ever; now it gives up after
    ASTRODYN_FIRST_TICK_TIMEOUT s, in one line."""
    _, endpoint = hub
    proc = _controller_by_hand(tmp_path, endpoint, ASTRODYN_FIRST_TICK_TIMEOUT="1.5")
    rc, err, wall = _ended_within(proc, 30)
    assert rc == 1 and err.count("\n") == 1, err
    assert err.startswith(f"astrodyn_link: no tick from the plant of scenario 'detumble' at {endpoint} within 1.5 s "
                          f"of connecting"), err
    assert wall >= 1.5, wall
    proc = _controller_by_hand(tmp_path, endpoint, ASTRODYN_FIRST_TICK_TIMEOUT="soon")
    rc, err, _ = _ended_within(proc, 20)
    assert rc == 1 and "ASTRODYN_FIRST_TICK_TIMEOUT: expected wall seconds >= 0 (0: wait for ever), got 'soon'" in err


def test_analyze_of_a_missing_file_says_only_that_it_is_missing(tmp_path, capsys):
    """Probe B (session 20): ``analyze nope.mcap`` printed ``reading nope.mcap (0.0 MB)`` before
    saying the file does not exist."""
    from astrodyn.cli import main

    assert main(["analyze", str(tmp_path / "nope.mcap")]) == 1
    err = capsys.readouterr().err
    assert "No such file" in err and "reading" not in err and "MB" not in err, err


def test_a_lockstep_run_names_the_controllers_it_waits_for_that_it_did_not_start():
    """Probe B (session 20): ``astrodyn demo --config configs/hohmann.toml`` (no --controller)
    waited 10 s and failed without saying a controller was expected; the run now says whom it
    waits for, and how long."""
    from types import SimpleNamespace

    from astrodyn.scenario import load
    from astrodyn.service.runner import ScenarioRun

    scenario = load(str(Path(__file__).resolve().parents[1] / "configs" / "hohmann.toml"))
    expected = list(scenario.control.controllers)
    waits = ScenarioRun.absent_controllers
    assert waits(SimpleNamespace(scenario=scenario, commands=None, controllers={})) == expected
    assert waits(SimpleNamespace(scenario=scenario, commands=None, controllers=dict.fromkeys(expected))) == []
    assert waits(SimpleNamespace(scenario=scenario, commands="rec.mcap", controllers={})) == []  # re-simulation


def test_demo_names_itself_in_its_messages(tmp_path, capsys):
    """Probe B (session 20): two demos at once, the second said ``astrodyn run: ...``."""
    from astrodyn.service import runner

    assert runner.main([str(tmp_path / "missing.toml")], prog="astrodyn demo") == 2
    err = capsys.readouterr().err
    assert err.startswith("astrodyn demo: ") and "astrodyn run" not in err, err


@pytest.mark.parametrize("complete, stopped_early, ended, to_the_end", [
    (True, {}, {"attitude": 11162, "orbit": 16743}, True),  # every process ended at the end, every state in the file
    (True, {"orbit": {"last_step": -1, "reason": "SIGTERM", "t": 0.0}}, {"attitude": 11162, "orbit": 0}, False),
    (False, {}, {"attitude": 11162, "orbit": 16743}, False),  # a state missing
    (True, {}, {}, False),  # no process ended: nothing says the run reached its end
])
def test_an_interrupted_run_counts_as_complete_only_when_recorded_to_its_end(complete, stopped_early, ended, to_the_end):
    """Probe B (session 20): a Ctrl-C while the logger took a finished run's last states said
    ``FAILED: interrupted ... at sim t 120 s of 120 s`` and left ``NAME.partial.mcap``,
    although every state was in the file.  The logger's summary (the shape of its ``end``
    record: ``complete``, ``stopped_early``, ``ended``) decides."""
    from astrodyn.service.runner import recorded_to_the_end

    log = {"complete": complete, "stopped_early": stopped_early, "ended": ended}
    assert recorded_to_the_end(log) is to_the_end


def test_a_replays_live_view_given_up_does_not_speak_of_a_recording(capsys):
    """Probe C (session 20, F8): replay's view, dead 5 times (its port taken by another
    replay), was given up with serve's words "the recording so far is kept"."""
    from types import SimpleNamespace

    from astrodyn.service.replay import LiveView

    def dead_view():
        return SimpleNamespace(pid=4242, poll=lambda: 1, how=lambda rc: f"exited with status {rc}",
                               last_words=lambda n: "viewer: port 8765 is in use", close=lambda: None)

    view = LiveView(dead_view)
    for k in range(6):
        view.check(now=1000.0 + k)
    err = capsys.readouterr().err
    assert view.child is None and "the replay goes on without it" in err, err
    assert "recording" not in err, err
