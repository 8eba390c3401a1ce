"""A flexible spacecraft (``model = "flexible"``, Baruh ch. 11) as a model of the service:
config, plan, the attitude process, the appendages key, the recording, the summary's
invariants, resume, and configs/explorer-1.toml.

The physics of the model itself is tested in tests/test_flexible.py and
tests/test_flexible_energy_sink.py; here the references are the laws the service must not
break: a torque-free hub with undamped beams conserves its inertial angular momentum and
its energy (to the integration tolerance, whatever the block boundaries of the
propagator), the tip deflection of each beam is its shape functions' tip values times the
recorded modal coordinates (evaluated independently with
:func:`astrodyn.attitude.flexible.shape_functions`), and every recorded message follows
the JSON Schema stored with its channel (checked by the third-party ``jsonschema`` and
``mcap`` packages).
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from astrodyn.analysis.invariants import appendage_arrays, flexible_invariants
from astrodyn.attitude import flexible as fx
from astrodyn.recording import load
from astrodyn.scenario import ScenarioError, load as load_config, loads, plan
from astrodyn.scenario.appendages import flexible_spacecraft
from astrodyn.service.resume import read_state_file, state_channels, states_at, tail_resume_point, write_state_file
from astrodyn.simulate import AttitudeEngine

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _config_text import assert_config_error, edited
from _recordings import copy_recording, run_to_end
from _scenes import appendage_table

ROOT = Path(__file__).resolve().parents[1]
ASTRODYN = [sys.executable, "-m", "astrodyn"]

# A hub with two undamped beams, two modes per plane, tumbling: torque-free, so H_i and
# T + V are invariants.  3 s at 20 Hz keeps the run short.
SCENE = """
[scenario]
name = "flexsc"
epoch = "2026-01-01T00:00:00 UTC"
duration = "3 s"
rate = "20 Hz"
real_time_factor = 1000

[[bodies]]
name = "sc"
[bodies.attitude]
model = "flexible"
mass = "40 kg"
inertia = [[8.0, 0.2, 0.0], [0.2, 6.0, 0.1], [0.0, 0.1, 5.0]]
w = ["0.3 rad/s", "-0.2 rad/s", "2.0 rad/s"]
q = [0.9, 0.3, 0.3, 0.1]
""" + appendage_table(["0.5 m", "0 m", "0.1 m"], [0, 1, 0], "3 m", "0.4 kg/m", "120 N m2", 2, axis=[1, 0, 0]) \
    + appendage_table(["-0.5 m", "0 m", "0 m"], [0, 0, 1], "2 m", "0.2 kg/m", "60 N m2", 2)
# with q given as not quite unit, normalised on load: |(0.9, 0.3, 0.3, 0.1)| = 1.0
assert abs(math.sqrt(0.81 + 0.09 + 0.09 + 0.01) - 1.0) < 1e-12


# --------------------------------------------------------------------------- config


HOSTILE = [
    # (old, new, field path in the error, what the error must say)
    ('mass = "40 kg"\n', "", "attitude.mass", "hub's mass"),
    ('model = "flexible"', 'model = "torque_free"', "attitude.mass", 'unless model = "heavy_top" or "flexible"'),
    ('length = "3 m"', 'length = "-3 m"', "appendages[0].length", "length > 0"),
    ('length = "3 m"', 'length = "1e400 m"', "appendages[0].length", "finite"),
    ('length = "3 m"', 'lenght = "3 m"', "appendages[0]", 'did you mean "length"'),
    ('mass_per_length = "0.4 kg/m"', 'mass_per_length = "0 kg/m"', "appendages[0].mass_per_length", "> 0"),
    ('mass_per_length = "0.4 kg/m"', 'mass_per_length = "0.4 kg"', "appendages[0].mass_per_length", "mass per length"),
    ('bending_stiffness = "120 N m2"', 'bending_stiffness = "nan N m2"', "appendages[0].bending_stiffness", "finite"),
    ('bending_stiffness = "120 N m2"', 'bending_stiffness = "1e300 N m2"', "appendages[0].bending_stiffness", "<="),
    ("modes = 2\n", "modes = 0\n", "appendages[0].modes", "1 <= n <= 8"),
    ("modes = 2\n", "modes = 9\n", "appendages[0].modes", "1 <= n <= 8"),
    ("modes = 2\n", 'modes = "2"\n', "appendages[0].modes", "integer"),
    ("modes = 2\n", "modes = true\n", "appendages[0].modes", "integer"),
    ("normal = [0, 1, 0]", "normal = [1, 0, 0]", "appendages[0].normal", "perpendicular to axis"),
    ("normal = [0, 1, 0]", "normal = [0, 0, 0]", "appendages[0].normal", "non-zero"),
    ("axis = [1, 0, 0]", 'axis = ["x", 0, 0]', "appendages[0].axis[0]", "a number"),
    ('root = ["0.5 m", "0 m", "0.1 m"]', 'root = ["0.5 m", "0 m"]', "appendages[0].root", "3 values"),
    ('[[bodies.attitude.appendages]]\nroot = ["-0.5 m", "0 m", "0 m"]',
     '[[bodies.attitude.appendages]]\nroot = ["0 m", "0 m", "0 m"]', "appendages[1].axis", "defaults to the root"),
    ("modes = 2\n", "modes = 2\ndamping_ratio = -0.1\n", "appendages[0].damping_ratio", "0 <= damping_ratio"),
    ('mass = "40 kg"', 'mass = "40 kg"\ntolerance = 1e-20', "attitude.tolerance", "1e-13 <= tolerance"),
    ('mass = "40 kg"', 'mass = "40 kg"\nstiffening = "yes"', "attitude.stiffening", "true or false"),
]


@pytest.mark.parametrize("old,new,field,says", HOSTILE, ids=[f"{h[2]}:{h[1][:24]}" for h in HOSTILE])
def test_hostile_flexible_configs_name_the_field(old, new, field, says):
    path = field if field.startswith("attitude.") else f"attitude.{field}"
    assert_config_error(edited(SCENE, **{old: new}), f"bodies[0] (sc).{path}", says)


def test_appendages_only_for_the_flexible_model_and_at_least_one():
    no_apps = SCENE.split("[[bodies.attitude.appendages]]")[0]
    with pytest.raises(ScenarioError, match=r"bodies\[0\] \(sc\)\.attitude\.appendages: expected at least one"):
        loads(no_apps)
    rigid = edited(SCENE, **{'model = "flexible"\nmass = "40 kg"\n': 'model = "torque_free"\n'})
    with pytest.raises(ScenarioError, match=r'attitude\.appendages: expected no appendages unless model = "flexible"'):
        loads(rigid)
    too_many = no_apps + "".join(f'[[bodies.attitude.appendages]]\nroot = ["{1 + k} m", 0, 0]\nnormal = [0, 1, 0]\n'
                                 'length = "1 m"\nmass_per_length = "1 kg/m"\nbending_stiffness = "1 N m2"\n'
                                 for k in range(33))
    with pytest.raises(ScenarioError, match=r"appendages: expected a list of 1 to 32 appendage tables"):
        loads(too_many)


def test_the_plan_counts_an_appendages_message_per_step():
    scn = loads(SCENE)
    p = plan(scn)
    assert [bp.attitude_model for bp in p.bodies] == ["flexible"]
    assert p.processes == ("attitude", "logger")
    assert p.n_steps == 61 and p.messages == 2 * 61 and p.model_state_messages == 61 and p.state_messages == 61
    assert "61 appendage / rolling / gimbal states" in p.text()


# --------------------------------------------------------------------------- the engine


def _spacecraft_of(body):
    """The flexible spacecraft model of a loaded config's ``body``."""
    a = body.attitude
    return flexible_spacecraft(a.mass, a.inertia, a.appendages, a.stiffening)


def _engine_run(scn, blocks):
    """Hub states and the appendages' states of the engine, called block by block."""
    eng = AttitudeEngine(scn)
    t = scn.output_times()
    qs, ws, etas, etads = [], [], [], []
    for tb in np.array_split(t, blocks):
        q, w = eng.states(tb)
        body = eng.own_channels()[0][1]
        lay = body.layout
        qs.append(q[:, 0]), ws.append(w[:, 0]), etas.append(body.last[:, lay["eta"]])
        etads.append(body.last[:, lay["eta_dot"]])
    return t, np.concatenate(qs), np.concatenate(ws), np.concatenate(etas), np.concatenate(etads)


def test_engine_blocks_conserve_momentum_and_energy_and_agree_with_one_tight_integration():
    scn = loads(SCENE)
    sc = _spacecraft_of(scn.bodies[0])
    t, q, w, eta, eta_dot = _engine_run(scn, blocks=7)
    rows = {r.name: r for r in flexible_invariants(sc, q, w, eta, eta_dot)}
    # rtol 1e-10 per step, ~100s of steps: the invariants hold to a few 1e-9 at worst
    assert rows["H_i (hub + appendages)"].drift < 1e-8
    assert rows["E = T + V"].drift < 1e-8
    # the same motion in one call at rtol 1e-13: block restarts change nothing beyond tolerance
    a = scn.bodies[0].attitude
    ref, _ = fx.propagate_spacecraft(sc, fx.make_state(sc, q=a.q0, w=a.w0), t, rtol=1e-13, atol=1e-16)
    lay = fx.state_layout(sc)
    assert np.max(np.abs(q - ref[:, lay["q"]])) < 1e-7
    assert np.max(np.abs(eta - ref[:, lay["eta"]])) < 1e-7 * max(1.0, np.max(np.abs(ref[:, lay["eta"]])))
    # the beams do move: a rigid body would make this test vacuous
    assert np.max(np.abs(eta)) > 1e-4


def test_engine_resumes_from_a_recorded_state():
    scn = loads(SCENE)
    t, q, w, eta, eta_dot = _engine_run(scn, blocks=1)
    k = 30
    sc_eng = AttitudeEngine(scn)
    assert sc_eng.own_channels()[0][1].last is None
    layout = fx.state_layout(_spacecraft_of(scn.bodies[0]))
    columns = [slice(s.start - layout["eta"].start, s.stop - layout["eta"].start) for s in layout["eta_k"]]
    per, per_dot = [eta[k][c].tolist() for c in columns], [eta_dot[k][c].tolist() for c in columns]
    taken = sc_eng.resume(float(t[k]), {"sc": {"q": q[k].tolist(), "w": w[k].tolist(), "eta": per, "eta_dot": per_dot}})
    assert taken == ["sc"]
    q2, w2 = sc_eng.states(t[k + 1:])
    assert np.max(np.abs(q2[:, 0] - q[k + 1:])) < 1e-8
    lay = sc_eng.own_channels()[0][1].layout
    assert np.max(np.abs(sc_eng.own_channels()[0][1].last[:, lay["eta"]] - eta[k + 1:])) < 1e-8
    with pytest.raises(ValueError, match=r"gyroscopes\) of the integrated bodies \['sc'\]"):
        AttitudeEngine(scn).resume(1.0, {"sc": {"q": q[k].tolist(), "w": w[k].tolist()}})


# --------------------------------------------------------------------------- the service


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """``astrodyn run`` of SCENE: (scenario, recording path, --json result)."""
    out, result, stdout = run_to_end(tmp_path_factory.mktemp("flex"), "flexsc", SCENE, "--timeout", "300")
    return loads(SCENE), out, result, stdout


@pytest.mark.network
def test_run_records_the_hub_and_the_appendages_of_every_step(recorded):
    scn, out, result, stdout = recorded
    log = result["logger"]
    assert log["states"] == plan(scn).messages == 122
    assert log["missing"] == 0 and log["malformed"] == 0 and log["duplicates"] == 0
    run = load(out)
    body = run.bodies["sc"]
    assert list(body.attitude.seq) == list(range(61)) == list(body.appendages.seq)
    assert np.array_equal(body.attitude.t, body.appendages.t)
    eta, eta_dot, tip = appendage_arrays(body.appendages)
    assert eta.shape == (61, 8) and eta_dot.shape == (61, 8) and tip.shape == (61, 2, 3)
    # tips from the shape functions' values at x = L (an independent evaluation) and the
    # recorded coordinates, plus the foreshortening along the axis (second order)
    sc = _spacecraft_of(scn.bodies[0])
    k0 = 0
    for j, app in enumerate(sc.appendages):
        n = app.beam.n_modes
        phi_tip = fx.shape_functions(app.beam, np.array([app.beam.L]))[:, 0]
        ef, eg = eta[:, k0:k0 + n], eta[:, k0 + n:k0 + 2 * n]
        k0 += 2 * n
        g = np.cross(app.axis, app.normal)
        lateral = np.outer(ef @ phi_tip, app.normal) + np.outer(eg @ phi_tip, g)
        assert np.allclose(tip[:, j] - np.outer(tip[:, j] @ app.axis, app.axis), lateral, rtol=1e-12, atol=1e-15)
        assert np.all(tip[:, j] @ app.axis <= 1e-15)  # a bent inextensible beam is shorter
    # the summary's invariants come from the recording: H_i and T + V conserved
    rows = {r["name"]: r for r in result["bodies"][0]["attitude_invariants"]}
    assert rows["H_i (hub + appendages)"]["drift"] < 1e-8 and rows["E = T + V"]["drift"] < 1e-8
    assert "+ 61 appendage / rolling / gimbal states" in stdout and "H_i (hub + appendages)" in stdout


@pytest.mark.network
def test_a_third_party_reader_validates_every_appendages_message_against_its_stored_schema(recorded):
    jsonschema = pytest.importorskip("jsonschema")
    from mcap.reader import make_reader

    _, out, _, _ = recorded
    seen = 0
    with open(out, "rb") as f:
        for schema, _channel, message in make_reader(f).iter_messages(topics=["astrodyn/flexsc/sc/appendages"]):
            assert schema.name == "astrodyn.AppendageState" and schema.encoding == "jsonschema"
            jsonschema.validate(json.loads(message.data), json.loads(schema.data))
            seen += 1
    assert seen == 61


@pytest.mark.network
def test_analyze_reports_the_system_invariants_and_the_appendages(recorded, tmp_path):
    from astrodyn.analysis import analyze

    _, out, _, _ = recorded
    report = analyze(out, tmp_path / "report")
    body = report["bodies"]["sc"]
    conserved = body["conserved quantities"]
    assert conserved["attitude: H_i (hub + appendages) [N m s], max drift relative to |H0|"] < 1e-8
    assert conserved["attitude: E = T + V [J], max drift relative to |E0|"] < 1e-8
    assert body["appendages"]["appendages"] == 2 and not body["appendages"]["damped"]
    # the hub's rigid rows (T, H of the hub alone: not conserved) are not reported
    assert "kinetic_energy_drift_max" not in body["attitude"]
    figures = report["figures"]["sc"]
    assert {"appendages", "flexible-drift"} <= set(figures) and "polhode" not in figures
    assert all((tmp_path / "report" / f).stat().st_size > 10_000 for f in figures.values())


@pytest.mark.network
def test_resume_point_and_state_file_carry_the_elastic_state(recorded, tmp_path):
    scn, out, _, _ = recorded
    run = load(out)
    assert [c[1] for c in state_channels(scn, "attitude")] == ["attitude", "appendages"]
    t, states = states_at(run, scn, "attitude", 40)
    assert set(states["sc"]) == {"q", "w", "eta", "eta_dot"} and len(states["sc"]["eta"]) == 2
    # the tail of each channel gives the same state (serve's O(1) restart reads only tails)
    from mcap.reader import make_reader

    tails: dict[str, list[bytes]] = {key: [] for _, _, key in state_channels(scn, "attitude")}
    with open(out, "rb") as f:
        for _, channel, message in make_reader(f).iter_messages():
            if channel.topic in tails:
                tails[channel.topic].append(message.data)
    step, t_tail, tail_states = tail_resume_point(tails, scn, "attitude")
    assert step == 60
    t60, states60 = states_at(run, scn, "attitude", 60)
    assert t_tail == t60 and tail_states == states60
    # a state file round-trips; a hostile one is refused naming the body
    path = write_state_file(tmp_path / "s.json", "attitude", 40, t, states)
    assert read_state_file(path, "attitude") == (40, t, states)
    bad = json.loads(path.read_text())
    bad["states"]["sc"]["eta"][1] = [1.0, "x", 0.0, 0.0]
    path.write_text(json.dumps(bad))
    with pytest.raises(ValueError, match=r"states\.sc: expected finite q and w vectors \(and the finite fields"):
        read_state_file(path, "attitude")


# --------------------------------------------------------------------------- explorer-1


def test_explorer_1_config_is_the_energy_sink_pair():
    scn = load_config(ROOT / "configs" / "explorer-1.toml")
    assert [b.attitude.model for b in scn.bodies] == ["flexible", "flexible"]
    for b, composite in zip(scn.bodies, ([12.0, 12.0, 8.0], [8.0, 8.0, 12.0])):
        sc = _spacecraft_of(b)
        # the composite inertia of hub plus undeformed antennas, about the mass centre:
        # the prolate (minor-axis) and oblate (major-axis) spinners of the energy-sink test
        state = fx.make_state(sc, w=[0.0, 0.0, 1.0])
        _, h = fx.spacecraft_momentum(sc, state)
        assert h[2] == pytest.approx(composite[2], rel=1e-4)
        state = fx.make_state(sc, w=[1.0, 0.0, 0.0])
        _, h = fx.spacecraft_momentum(sc, state)
        assert h[0] == pytest.approx(composite[0], rel=1e-4)
        # H at 10 deg from the spin axis
        w = b.attitude.w0
        assert math.degrees(math.atan2(composite[0] * w[0], composite[2] * w[2])) == pytest.approx(10.0, abs=1e-3)


def _nutation(sc, q, w, eta, eta_dot):
    states = np.stack([fx.make_state(sc, q=q[k], w=w[k], eta=eta[k], eta_dot=eta_dot[k]) for k in range(len(q))])
    _, h = fx.spacecraft_momentum(sc, states)
    e0, e1, e2, e3 = q.T
    z = np.stack([2 * (e1 * e3 + e0 * e2), 2 * (e2 * e3 - e0 * e1), 1 - 2 * (e1 * e1 + e2 * e2)], axis=1)
    return np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", z, h) / np.linalg.norm(h, axis=1), -1, 1))), h, states


@pytest.mark.network
@pytest.mark.slow  # CI time (10 s): the energy sink's physics (engine tests above) and a flexible run stay in make test
def test_explorer_1_run_drifts_to_a_flat_spin_and_the_oblate_twin_stays_put(tmp_path):
    out, res = tmp_path / "explorer.mcap", tmp_path / "result.json"
    proc = subprocess.run([*ASTRODYN, "run", str(ROOT / "configs" / "explorer-1.toml"), "--out", str(out), "--json",
                           str(res), "--quiet", "--timeout", "1200"], capture_output=True, text=True, timeout=1500)
    assert proc.returncode == 0, proc.stderr[-2000:]
    scn = load_config(ROOT / "configs" / "explorer-1.toml")
    run = load(out)
    for b in scn.bodies:
        sc = _spacecraft_of(b)
        rec = run.bodies[b.name]
        eta, eta_dot, _ = appendage_arrays(rec.appendages)
        theta, h, states = _nutation(sc, rec.attitude.q, rec.attitude.w, eta, eta_dot)
        energy = fx.spacecraft_energy(sc, states)
        hn = np.linalg.norm(h, axis=1)
        assert np.max(np.abs(hn - hn[0])) / hn[0] < 1e-6  # |H| conserved: only internal forces
        assert np.max(np.diff(energy)) <= 1e-7 * energy[0]  # the dampers only take energy
        if b.name == "prolate":  # minor axis: to a flat spin about a transverse (major) axis
            last = theta[-400:]  # the last 40 s: the spin axis turns about H's normal plane
            assert theta[0] == pytest.approx(10.0, abs=0.01)
            assert 70.0 < np.min(last) and np.max(last) < 110.0 and abs(np.mean(last) - 90.0) < 5.0
            # at fixed |H| a rigid axisymmetric body has E = H^2/2 (sin^2 th / I_t + cos^2 th / I_s):
            # from th = 10 deg about the minor axis to the flat spin (th = 90 deg) energy falls by
            # the factor (1 / I_t) / (sin^2 10 / I_t + cos^2 10 / I_s) = 0.6734 (I_t = 12, I_s = 8);
            # the antennas' deflection and the residual +-8 deg wobble stay within 2 %
            s2 = math.sin(math.radians(10.0)) ** 2
            assert energy[-1] / energy[0] == pytest.approx((1 / 12.0) / (s2 / 12.0 + (1 - s2) / 8.0), rel=0.02)
        else:  # major axis: the nutation decays
            assert theta[-1] < 1.0


@pytest.mark.network
def test_csv_export_flattens_the_appendages_into_numeric_columns_with_units(recorded, tmp_path):
    import csv

    _, out, _, _ = recorded
    proc = subprocess.run([*ASTRODYN, "export", str(out), "--format", "csv", "--out", str(tmp_path)],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    lines = (tmp_path / "sc.appendages.csv").read_text().splitlines()
    units = next(x for x in lines if x.startswith("# units:"))
    assert "eta_1_3=m," in units and "eta_dot_0_0=m/s" in units and "tip_1_z=m" in units and "?" not in units
    rows = list(csv.DictReader(x for x in lines if not x.startswith("#")))
    eta, eta_dot, tip = appendage_arrays(load(out).bodies["sc"].appendages)
    assert len(rows) == 61
    # shortest round-trip text: reading the CSV back gives the recorded float64 values exactly
    assert [float(r["eta_1_3"]) for r in rows] == eta[:, 7].tolist()
    assert [float(r["eta_dot_0_2"]) for r in rows] == eta_dot[:, 2].tolist()
    assert [float(r["tip_1_y"]) for r in rows] == tip[:, 1, 1].tolist()


@pytest.mark.network
def test_hostile_appendage_channels_and_metadata_end_in_notes_not_tracebacks(recorded, tmp_path):
    """A file whose appendages change layout mid-run (valid messages, inconsistent with the
    config), or whose config metadata does not describe a spacecraft: load, the run summary,
    analyze and export read what they can, say what they could not, and never raise."""
    from astrodyn.analysis import analyze
    from astrodyn.recording import export
    from astrodyn.service.summary import file_summary

    _, out, _, _ = recorded

    def no_spacecraft(name, meta):
        meta["json"] = json.dumps({"bodies": [{"name": "sc", "attitude": {"appendages": [{"modes": "x"}] * 99}}]})
        return meta

    def one_appendage_fewer(channel, message):
        if not (channel.topic.endswith("/appendages") and message.sequence % 7 == 3):
            return message.data
        msg = json.loads(message.data)  # one appendage fewer, still a valid AppendageState
        msg["eta"], msg["eta_dot"], msg["tip"] = msg["eta"][:1], msg["eta_dot"][:1], msg["tip"][:1]
        return json.dumps(msg, separators=(",", ":")).encode()

    for case in ("layout", "metadata"):
        bad = tmp_path / f"{case}.mcap"
        if case == "metadata":
            copy_recording(out, bad, edit_metadata=no_spacecraft)
        else:
            copy_recording(out, bad, edit_message=one_appendage_fewer)
        run = load(bad)
        assert len(run.bodies["sc"].appendages) == 61  # valid messages: all kept
        rows = file_summary(bad, loads(SCENE))
        assert rows and rows[0]["attitude_states"] == 61
        report = analyze(bad, tmp_path / f"{case}-report")
        assert "note" in report["bodies"]["sc"]["appendages"]
        written = export.export(str(bad), "csv", str(tmp_path / f"{case}-csv"))
        assert any("appendages" in str(p) for p in written)


@pytest.mark.network
@pytest.mark.slow  # CI time: test_reliability's serve case resumes killed propagators in make test
def test_serve_restarts_a_killed_attitude_propagator_from_the_recorded_elastic_state(tmp_path):
    """serve with a flexible body: SIGKILL the attitude propagator; serve restarts it from
    the last step both of the body's channels hold (hub attitude and appendages), and the
    recording has every step once on both, with the invariants of the undamped, torque-free
    system continuous across the restart (the restarted integration starts from the recorded
    state: a wrong or missing elastic state would jump the energy by O(1))."""
    import os
    import signal
    import time

    from _serve_control import serve_status, start_serve, wait_until
    from astrodyn import bus
    from astrodyn.service.children import stop_process

    cfg, out = tmp_path / "flexsc.toml", tmp_path / "serve.mcap"
    cfg.write_text(edited(SCENE, **{'duration = "3 s"': 'duration = "100000 s"'}))
    proc, hello = start_serve(cfg, out, "--rate", "5")
    try:
        token = hello["control_token"]
        with bus.open_session(connect=[hello["hub"]]) as s:
            status = serve_status(s, "flexsc", token)
            wait_until(lambda: status()["t"] >= 10, 60, "serve never reached t = 10 s")
            time.sleep(2.0)  # the logger flushes what it holds
            old = status()["processes"]["attitude"]["pid"]
            os.kill(old, signal.SIGKILL)
            wait_until(lambda: status()["restarts"], 60, "no restart reported", poll_s=0.1)
            restart = status()["restarts"][0]
            assert restart["process"] == "attitude" and restart["old_pid"] == old
            wait_until(lambda: status()["t"] >= restart["from_step"] / 20 + 10, 60,  # the new process publishes
                       "the restarted propagator does not advance")
            (final,) = bus.send_control(s, "flexsc", "stop", timeout_s=120, token=token)
            assert final.get("state") == "stopped", final
        proc.communicate(timeout=60)
    finally:
        stop_process(proc)
    run = load(out)
    body = run.bodies["sc"]
    n = len(body.attitude)
    assert n > restart["from_step"] + 100
    np.testing.assert_array_equal(body.attitude.seq, np.arange(n))  # no gap, no duplicate across the restart
    np.testing.assert_array_equal(body.appendages.seq, np.arange(len(body.appendages)))
    m = min(n, len(body.appendages))
    eta, eta_dot, _ = appendage_arrays(body.appendages)
    rows = {r.name: r for r in flexible_invariants(_spacecraft_of(loads(SCENE).bodies[0]), body.attitude.q[:m],
                                                   body.attitude.w[:m], eta[:m], eta_dot[:m])}
    assert rows["H_i (hub + appendages)"].drift < 1e-8 and rows["E = T + V"].drift < 1e-8
