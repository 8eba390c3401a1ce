"""A rolling disk (``model = "rolling_disk"``, Baruh 10.6) as a model of the service: config,
the attitude process, the ``<body>/rolling`` key, the recording, the summary's energy,
the end of the model when a disk falls flat, resume, analyze, configs/rolling-disk.toml.

The model's physics is tested in tests/test_rolling_disk.py.  The references here are
independent of the service's code: Baruh's condition of steady circular rolling written
out in the test, the geometry of a circle, the kinematics of the published attitude
against :func:`astrodyn.rotation.dcm_from_euler` differentiated numerically, and the
energy, which the rolling constraint does not change.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from astrodyn.recording import load
from astrodyn.rotation import dcm_from_euler, dcm_from_quat
from astrodyn.scenario import ScenarioError, load as load_config, loads, plan
from astrodyn.service.resume import state_channels, states_at
from astrodyn.simulate import AttitudeEngine, ModelEnded

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _config_text import assert_config_error, edited
from _recordings import run_to_end
from _scenes import coin_body

ROOT = Path(__file__).resolve().parents[1]
ASTRODYN = [sys.executable, "-m", "astrodyn"]
R, M, G = 0.0129, 0.0085, 9.80665  # a 2-euro coin, m and kg; standard gravity
A, C = M * R * R / 4, M * R * R / 2  # thin disk

SCENE = """
[scenario]
name = "coins"
epoch = "2026-01-01T00:00:00 UTC"
duration = "4 s"
rate = "25 Hz"
real_time_factor = 1000

""" + coin_body("circle", 'lean = "25 deg"\nheading = "30 deg"\nheading_rate = "5 rad/s"\n'
                         'spin_rate = "steady"\n') + "\n" \
    + coin_body("wobble", 'position = ["0.2 m", "-0.1 m"]\nlean = "10 deg"\nlean_rate = "1 rad/s"\n'
                          'heading_rate = "2 rad/s"\nspin_rate = "25 rad/s"\n')

FALLS = """
[scenario]
name = "falls"
epoch = "2026-01-01T00:00:00 UTC"
duration = "5 s"
rate = "50 Hz"
real_time_factor = 1000

""" + coin_body("coin", 'lean = "60 deg"\n')


HOSTILE = [
    ('lean = "25 deg"', 'lean = "90 deg"', "circle).attitude.lean", "|lean| <= 89 deg"),
    ('lean = "25 deg"', 'lean = "nan deg"', "circle).attitude.lean", "finite"),
    ('radius = "12.9 mm"', 'radius = "-1 mm"', "circle).attitude.radius", "radius > 0"),
    ('radius = "12.9 mm"', 'radius = "12.9 kg"', "circle).attitude.radius", "a length"),
    ('mass = "8.5 g"\nlean = "25', 'lean = "25', "circle).attitude.mass", "the disk's mass"),
    ('radius = "12.9 mm"', 'radius = "12.9 mm"\nshape = "square"', "circle).attitude.shape", "one of disk, hoop"),
    ('radius = "12.9 mm"', 'radius = "12.9 mm"\nmoments = ["1 kg m2", "3 kg m2"]', "circle).attitude.moments",
     "C <= 2 A"),
    ('radius = "12.9 mm"', 'radius = "12.9 mm"\nshape = "hoop"\nmoments = ["1 kg m2", "1 kg m2"]',
     "circle).attitude.moments", "either shape or moments"),
    ('heading_rate = "5 rad/s"', 'heading_rate = "0 rad/s"', "circle).attitude.spin_rate", '"steady" with heading_rate != 0'),
    ('spin_rate = "steady"', 'spin_rate = "fast"', "circle).attitude.spin_rate", "an angular velocity"),
    ('spin_rate = "steady"', 'spin_rate = "1e300 rad/s"', "circle).attitude.spin_rate", "<="),
    ('lean = "25 deg"', 'lean = "25 deg"\nq = [1, 0, 0, 0]', "circle).attitude.q", "no q for model rolling_disk"),
    ('lean = "25 deg"', 'lean = "25 deg"\ninertia = [1, 1, 1]', "circle).attitude.inertia", "no inertia for model"),
    ('lean = "25 deg"', 'lean = "25 deg"\nlaen = 1', "circle).attitude", 'did you mean "lean"'),
    ('lean = "25 deg"', 'lean = "25 deg"\ng = "0 m/s2"', "circle).attitude.g", "g > 0"),
    ('position = ["0.2 m", "-0.1 m"]', 'position = ["0.2 m"]', "wobble).attitude.position", "2 values"),
]


@pytest.mark.parametrize("old,new,field,says", HOSTILE, ids=[f"{h[2]}:{h[1][-20:]}" for h in HOSTILE])
def test_hostile_rolling_configs_name_the_field(old, new, field, says):
    assert_config_error(edited(SCENE, **{old: new}), field, says)


def test_rolling_keys_belong_to_the_rolling_disk_and_it_has_no_orbit():
    with pytest.raises(ScenarioError, match=r'attitude\.radius: expected no radius unless model = "rolling_disk"'):
        loads(edited(SCENE, **{'model = "rolling_disk"': 'model = "torque_free"\ninertia = [1, 1, 1]'}))
    orbiting = edited(SCENE, **{
        '[bodies.attitude]\nmodel = "rolling_disk"\nradius = "12.9 mm"\nmass = "8.5 g"\nlean = "25 deg"':
        '[bodies.orbit]\na = "7000 km"\n[bodies.attitude]\nmodel = "rolling_disk"\nradius = "12.9 mm"\n'
        'mass = "8.5 g"\nlean = "25 deg"'})
    with pytest.raises(ScenarioError, match=r"circle\)\.orbit: expected no orbit for a rolling_disk body"):
        loads(orbiting)


def test_steady_spin_solves_baruhs_condition_of_circular_rolling():
    """m g R sin th + (C + m R^2) u2 u3 = A u3^2 tan th with u3 = psi' cos th (Baruh 10.6),
    written out here: the config's "steady" spin satisfies it to round-off."""
    a = loads(SCENE).bodies[0].attitude.rolling
    th, psi_dot = math.radians(25.0), 5.0
    u3 = psi_dot * math.cos(th)
    u2 = psi_dot * math.sin(th) + a.spin_rate
    residual = M * G * R * math.sin(th) + (C + M * R * R) * u2 * u3 - A * u3 * u3 * math.tan(th)
    assert abs(residual) <= 1e-14 * (M * G * R)


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    out, result, _ = run_to_end(tmp_path_factory.mktemp("coins"), "coins", SCENE, "--timeout", "300")
    return loads(SCENE), out, result


@pytest.mark.network
def test_run_records_attitude_and_rolling_state_and_conserves_energy(recorded):
    scn, out, result = recorded
    log = result["logger"]
    assert log["states"] == plan(scn).messages == 4 * 101
    assert log["missing"] == 0 and log["malformed"] == 0
    run = load(out)
    for row in result["bodies"]:
        inv = {r["name"]: r for r in row["attitude_invariants"]}
        assert inv["E = T + m g R cos(theta)"]["drift"] < 1e-9  # rtol 1e-10, a few hundred steps
    circle = run.bodies["circle"].rolling
    assert list(circle.seq) == list(range(101)) == list(run.bodies["circle"].attitude.seq)
    # steady circular rolling: the lean stays, the contact point runs on a circle of radius
    # |R phi' / psi'| (its speed R phi', its heading turning at psi')
    assert np.max(np.abs(circle.lean - math.radians(25.0))) < 1e-9
    phi_dot = scn.bodies[0].attitude.rolling.spin_rate
    rho = abs(R * phi_dot / 5.0)
    heading0 = math.radians(30.0)
    # the circle's centre is rho to the side of the start, normal to the heading
    side = np.sign(phi_dot * 5.0)
    centre = circle.contact[0] + side * rho * np.array([-math.sin(heading0), math.cos(heading0)])
    assert np.max(np.abs(np.linalg.norm(circle.contact - centre, axis=1) - rho)) < 1e-9 * max(rho, 1.0)
    # the centre of the disk is R above the contact point along b3 (|centre - contact| = R)
    cpos = np.column_stack([circle.contact, np.zeros(len(circle))])
    assert np.allclose(np.linalg.norm(circle.center - cpos, axis=1), R, rtol=1e-12)
    assert np.allclose(circle.center[:, 2], R * np.cos(circle.lean), rtol=1e-12)


@pytest.mark.network
def test_published_attitude_and_rates_follow_the_angles(recorded):
    """q is C = C_2(phi) C_1(theta) C_3(psi) (sequence 312), and w = vee(-dC/dt C^T), with
    dC/dt by central differences of dcm_from_euler along the recorded angle rates."""
    _, out, _ = recorded
    run = load(out)
    for name in ("circle", "wobble"):
        att, rol = run.bodies[name].attitude, run.bodies[name].rolling
        for k in (0, 37, 100):
            angles = np.array([rol.heading[k], rol.lean[k], rol.spin_angle[k]])
            c = dcm_from_euler(angles, "312")
            assert np.allclose(dcm_from_quat(att.q[k]), c, atol=1e-14)
            u1, u2, u3 = rol.u[k]
            th = rol.lean[k]
            rates = np.array([u3 / math.cos(th), u1, u2 - u3 * math.tan(th)])  # psi', theta', phi'
            h = 1e-6
            cdot = (dcm_from_euler(angles + h * rates, "312") - dcm_from_euler(angles - h * rates, "312")) / (2 * h)
            wx = -cdot @ c.T
            w = np.array([wx[2, 1], wx[0, 2], wx[1, 0]])
            assert np.allclose(att.w[k], w, rtol=1e-7, atol=1e-7 * np.linalg.norm(w))


@pytest.mark.network
def test_a_disk_that_falls_flat_ends_the_run_with_its_name_and_time(tmp_path):
    cfg, out = tmp_path / "falls.toml", tmp_path / "falls.mcap"
    cfg.write_text(FALLS)
    proc = subprocess.run([*ASTRODYN, "run", str(cfg), "--out", str(out), "--timeout", "300", "--quiet"],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 1
    assert "coin: the rolling disk lies flat (|lean| = 90 deg) at t = " in proc.stderr, proc.stderr
    t_flat = float(proc.stderr.split("at t = ")[1].split(" s")[0])
    # what was computed before is recorded, in a readable file, and the disk never passed flat
    partial = tmp_path / "falls.partial.mcap"
    assert partial.exists() and not out.exists()
    run = load(partial)
    rol = run.bodies["coin"].rolling
    assert len(rol) >= 1 and np.all(np.cos(rol.lean) > 0)
    assert rol.t[-1] <= t_flat < rol.t[-1] + 1 / 50 + 1e-12
    # from rest at 60 deg the disk falls under gravity alone: energy conservation gives the
    # lean rate at 90 deg, sqrt(2 m g R cos 60 / (A + m R^2)) (pure rotation about the contact
    # line: u2 = u3 = 0 all along)
    assert np.all(rol.u[:, 1:] == 0.0)
    e0 = M * G * R * math.cos(math.radians(60.0))
    u1_last = rol.u[-1, 0]
    e_last = 0.5 * (A + M * R * R) * u1_last**2 + M * G * R * math.cos(rol.lean[-1])
    assert e_last == pytest.approx(e0, rel=1e-9)


def test_engine_resumes_a_rolling_disk_and_ends_it_at_the_flat_event():
    scn = loads(SCENE)
    t = scn.output_times()
    eng = AttitudeEngine(scn)
    q, w = eng.states(t)
    ext = dict(eng.own_channels())
    k = 40
    states = {b.name: {"q": q[k, i].tolist(), "w": w[k, i].tolist(),
                       **{f: v for f, v in ext[i].message(k, float(t[k]), k).items() if f not in ("t", "seq")}}
              for i, b in enumerate(eng.bodies)}
    again = AttitudeEngine(scn)
    assert sorted(again.resume(float(t[k]), states)) == ["circle", "wobble"]
    q2, w2 = again.states(t[k + 1:])
    assert np.max(np.abs(q2 - q[k + 1:])) < 1e-8 and np.max(np.abs(w2 - w[k + 1:])) < 1e-6
    falls = loads(FALLS)
    with pytest.raises(ModelEnded, match=r"coin: the rolling disk lies flat") as info:
        AttitudeEngine(falls).states(falls.output_times())
    assert 0 < info.value.rows < 250 and info.value.q.shape == (info.value.rows, 1, 4)


@pytest.mark.network
def test_resume_reads_both_channels_and_analyze_shows_the_path(recorded, tmp_path):
    from astrodyn.analysis import analyze

    scn, out, _ = recorded
    assert [c[1] for c in state_channels(scn, "attitude")] == ["attitude", "rolling", "attitude", "rolling"]
    run = load(out)
    _, states = states_at(run, scn, "attitude", 60)
    assert set(states["wobble"]) == {"q", "w", "contact", "center", "heading", "lean", "spin_angle", "u"} - {"center"}
    report = analyze(out, tmp_path / "report")
    circle = report["bodies"]["circle"]
    assert circle["rolling"]["lean_max_deg"] == pytest.approx(25.0, abs=1e-6)
    assert circle["conserved quantities"]["attitude: E = T + m g R cos(theta) [J], max drift relative to |E0|"] < 1e-9
    assert {"contact-path", "rolling-angles"} <= set(report["figures"]["circle"])
    assert "polhode" not in report["figures"]["circle"]


def test_rolling_disk_config_shows_routh_stability():
    """configs/rolling-disk.toml: the two upright coins spin at 1.3 and 0.8 x the critical
    spin sqrt(A m g R / (C (C + m R^2))) (= sqrt(g / (3 R)) for a thin disk): the fast one
    stays within a small lean, the slow one leans far (10 s in the engine)."""
    scn = load_config(ROOT / "configs" / "rolling-disk.toml")
    crit = math.sqrt(G / (3 * R))
    spins = {b.name: b.attitude.rolling.spin_rate for b in scn.bodies}
    assert spins["upright-fast"] / crit == pytest.approx(1.3, abs=1e-3)
    assert spins["upright-slow"] / crit == pytest.approx(0.8, abs=1e-3)
    eng = AttitudeEngine(scn)
    eng.states(scn.output_times())
    lean = {b.name: np.degrees(np.abs(b.extended.last[:, 3])) for b in eng.bodies}
    assert np.max(lean["upright-fast"]) < 15.0 and np.max(lean["upright-slow"]) > 40.0
    assert np.max(np.abs(lean["circle"] - 20.0)) < 1e-8


@pytest.mark.network
def test_serve_does_not_restart_a_model_that_ended(tmp_path):
    """A propagator that exits because its model ended (status 4) would end there again:
    serve reports it as a failure, restarts nothing, keeps the file."""
    cfg, out = tmp_path / "falls.toml", tmp_path / "falls.mcap"
    cfg.write_text(FALLS)
    proc = subprocess.run([*ASTRODYN, "serve", str(cfg), "--out", str(out)], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 1, proc.stderr[-2000:]
    final = json.loads(proc.stdout.strip().splitlines()[-1])
    assert final["restarts"] == [] and final["processes"]["attitude"]["exit"] == 4
    assert any("coin: the rolling disk lies flat" in f and "not restarted" in f for f in final["failures"])
    rol = load(final["file"]).bodies["coin"].rolling
    assert len(rol) >= 1 and np.all(np.cos(rol.lean) > 0)
