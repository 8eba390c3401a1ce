"""Single-axis gyroscopes mounted on a body (``[[bodies.gyros]]``, Baruh 10.7.3) as part of
the service: config, the attitude process, the ``<body>/gimbals`` key, resume.

References independent of the service's plumbing (the spline through the published rates,
the blocks, the messages): the exact steady gimbal angle of a rate gyro on a steadily
turning base (:func:`steady_state_angle`, a root of k theta = w_g1 (H + (J3 - J1) w_g3)),
the rate-integrating gyro's small-angle solution c theta + J2 theta' = H int w1 dt written
out here, and a direct integration of the gimbal on the torque-free body's exact rates and
their exact derivative (Euler's equations), without the service.
"""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from astrodyn.attitude import gyroscopes as gy
from astrodyn.attitude.torque_free import torque_free
from astrodyn.recording import load
from astrodyn.scenario import loads, plan
from astrodyn.service.resume import state_channels
from astrodyn.simulate import AttitudeEngine

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _config_text import assert_config_error, edited
from _scenes import RATE_GYRO_DYNAMICS, gyro_table

ASTRODYN = [sys.executable, "-m", "astrodyn"]
C, A, SPIN = 1e-4, 6e-5, 24000 * 2 * math.pi / 60  # rotor kg m^2, kg m^2, rad/s
H = C * SPIN


#: ``[[bodies.gyros]]`` entries: the rotor of gyro_table is the one of C, A and SPIN above (output axis y)
RATE_GYRO = gyro_table("rate", [1, 0, 0], RATE_GYRO_DYNAMICS)
INTEGRATING = gyro_table("rate_integrating", [0, 0, 1], 'damping = "0.25 N m s/rad"\n')


def _scene(inertia: str, w: str, duration: str = "2 s", rate: str = "50 Hz", gyros: str = RATE_GYRO + INTEGRATING) -> str:
    return f"""
[scenario]
name = "gyros"
epoch = "2026-01-01T00:00:00 UTC"
duration = "{duration}"
rate = "{rate}"
real_time_factor = 1000

[[bodies]]
name = "sc"
[bodies.attitude]
inertia = {inertia}
w = {w}
""" + gyros


TUMBLING = _scene("[900, 1100, 1300]", '["1.5 deg/s", "-0.8 deg/s", "2.5 deg/s"]', duration="6 s")


HOSTILE = [
    ('type = "rate"\n', 'type = "rated"\n', "gyros[0].type", 'did you mean "rate"'),
    ("output_axis = [0, 1, 0]\nspin_inertia", "output_axis = [1, 0, 0]\nspin_inertia", "gyros[0].output_axis",
     "perpendicular to input_axis"),
    ("input_axis = [1, 0, 0]", "input_axis = [0, 0, 0]", "gyros[0].input_axis", "non-zero"),
    ('spin_inertia = "1e-4 kg m2"', 'spin_inertia = "2e-4 kg m2"', "gyros[0].spin_inertia", "<= 2 transverse_inertia"),
    ('spin_rate = "24000 rpm"', 'spin_rate = "0 rpm"', "gyros[0].spin_rate", "non-zero spin rate"),
    ('natural_frequency = "30 Hz"', 'natural_frequency = "-30 Hz"', "gyros[0].natural_frequency", "> 0"),
    ('natural_frequency = "30 Hz"', 'natural_frequency = "30 Hz"\nspring = "1 N m/rad"', "gyros[0].spring",
     "either natural_frequency or spring"),
    ('natural_frequency = "30 Hz"\n', "", "gyros[0].natural_frequency", "natural_frequency or spring"),
    ('damping = "0.25 N m s/rad"', 'damping = "0.25 N m s"', "gyros[1].damping", "rotational damping"),
    ('damping = "0.25 N m s/rad"', 'damping = "0.25 N m s/rad"\nnatural_frequency = "3 Hz"',
     "gyros[1].natural_frequency", 'no natural_frequency for type = "rate_integrating"'),
    ("damping_ratio = 0.7", "damping_ratio = 0.7\nspinrate = 1", "gyros[0]", 'did you mean "spin_rate"'),
]


@pytest.mark.parametrize("old,new,field,says", HOSTILE, ids=[h[2] + ":" + h[1][-18:] for h in HOSTILE])
def test_hostile_gyro_configs_name_the_field(old, new, field, says):
    assert_config_error(edited(TUMBLING, **{old: new}), f"bodies[0] (sc).{field}", says)


def test_gyros_need_a_propagated_attitude_and_count_in_the_plan():
    no_att = TUMBLING.replace('[bodies.attitude]\ninertia = [900, 1100, 1300]\nw = ["1.5 deg/s", "-0.8 deg/s", '
                              '"2.5 deg/s"]', '[bodies.orbit]\na = "7000 km"')
    assert_config_error(no_att, "bodies[0] (sc).gyros", "an attitude for the gyroscopes to sense")
    too_many = edited(TUMBLING, **{INTEGRATING: RATE_GYRO * 16})
    assert_config_error(too_many, "bodies[0] (sc).gyros", "a list of 1 to 16 gyroscope tables")
    p = plan(loads(TUMBLING))
    assert p.bodies[0].own_kinds == ("gimbals",) and p.model_state_messages == p.n_steps == 301
    assert p.messages == 2 * 301


def _run(tmp_path, text: str):
    cfg, out = tmp_path / "gyros.toml", tmp_path / "gyros.mcap"
    cfg.write_text(text)
    proc = subprocess.run([*ASTRODYN, "run", str(cfg), "--out", str(out), "--quiet", "--timeout", "300"],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return load(out)


@pytest.mark.network
def test_on_a_steadily_turning_body_the_rate_gyro_reads_the_exact_steady_state(tmp_path):
    """A spherical body turns at a constant rate: the rate gyro sits at its exact steady
    angle (the cross-coupling included), the rate-integrating gyro (w3 = 0 about its spin
    reference axis) follows the small-angle solution of c theta + J2 theta' = H w1 t."""
    w = np.radians([1.0, -0.5, 0.8])
    # the rate-integrating gyro's spin reference axis z x (1, -0.5, 0) is perpendicular to w:
    # no cross-coupling, and the constant output-axis rate does nothing (Baruh 10.7.3)
    integrating = INTEGRATING.replace("output_axis = [0, 1, 0]", "output_axis = [1, -0.5, 0]")
    run = _run(tmp_path, _scene("[1000, 1000, 1000]", f"[{w[0]}, {w[1]}, {w[2]}]", gyros=RATE_GYRO + integrating))
    g = run.bodies["sc"].gimbals
    angle = np.array(list(g.angle))
    indicated = np.array(list(g.indicated))
    rate = gy.SingleAxisGyro.rate_gyro(C, A, SPIN, (2 * math.pi * 30) ** 2 * A,
                                       2 * 0.7 * math.sqrt((2 * math.pi * 30) ** 2 * A * A))
    theta_ss = gy.steady_state_angle(rate, w)  # case axes = body axes for input x, output y
    assert np.max(np.abs(angle[:, 0] - theta_ss)) <= 1e-9 * abs(theta_ss)
    assert indicated[0, 0] == pytest.approx(rate.spring * theta_ss / H, rel=1e-12)
    # its error against the true rate is Baruh's cross-coupling: k theta = H (w1 - w3 theta) to first order
    assert indicated[0, 0] / w[0] - 1 == pytest.approx(-H * w[2] / rate.spring, rel=0.05)
    # rate-integrating about z, from rest: the small-angle solution (cos theta = 1 - 4e-4 here)
    w1, c, J2 = w[2], 0.25, A
    tau = J2 / c
    t = g.t
    theta = (H * w1 / c) * (t - tau * (1 - np.exp(-t / tau)))
    assert np.max(np.abs(angle[:, 1] - theta)) <= 2e-3 * np.max(np.abs(theta))


def _exact_base(inertia, w0, mount):
    """The torque-free body's exact rates and their derivative (Euler's equations) in the
    gyro's case axes."""
    inertia = np.asarray(inertia, dtype=np.float64)
    q0 = np.array([1.0, 0.0, 0.0, 0.0])

    def base(t):
        w, _ = torque_free(inertia, w0, q0, np.array([t]))
        w = w[0]
        wdot = np.cross(inertia * w, w) / inertia
        return mount @ w, mount @ wdot

    return base


@pytest.mark.network
def test_on_a_tumbling_body_the_gimbals_match_a_direct_integration_on_the_exact_rates(tmp_path):
    run = _run(tmp_path, TUMBLING)
    g = run.bodies["sc"].gimbals
    angle = np.array(list(g.angle))
    w0 = np.radians([1.5, -0.8, 2.5])
    inertia = [900.0, 1100.0, 1300.0]
    k = (2 * math.pi * 30) ** 2 * A
    rate = gy.SingleAxisGyro.rate_gyro(C, A, SPIN, k, 2 * 0.7 * math.sqrt(k * A))
    mount = np.eye(3)
    theta0 = gy.steady_state_angle(rate, w0)
    ref, _ = gy.propagate_single_axis(rate, _exact_base(inertia, w0, mount), g.t, theta0=theta0, rtol=1e-12,
                                      atol=1e-15)
    assert np.max(np.abs(angle[:, 0] - ref[:, 0])) <= 1e-6 * np.max(np.abs(ref[:, 0]))
    integ = gy.SingleAxisGyro.rate_integrating(C, A, SPIN, 0.25)
    mount = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
    ref, _ = gy.propagate_single_axis(integ, _exact_base(inertia, w0, mount), g.t, rtol=1e-12, atol=1e-15)
    assert np.max(np.abs(angle[:, 1] - ref[:, 0])) <= 1e-6 * np.max(np.abs(ref[:, 0]))
    # the published rates are the body's: every sample on both channels
    assert list(g.seq) == list(run.bodies["sc"].attitude.seq) == list(range(301))
    # analyze compares each indication with the body's motion about its input axis
    from astrodyn.analysis import analyze

    report = analyze(run.path, tmp_path / "report")
    section = report["bodies"]["sc"]["gyros"]
    assert section["types"] == ["rate", "rate_integrating"]
    w = run.bodies["sc"].attitude.w
    assert section["max_truth"][0] == pytest.approx(np.max(np.abs(w[:, 0])), rel=1e-12)
    # rate gyro: within its cross-coupling H |w3| / k of the truth.  The rate-integrating gyro's
    # spin reference axis (z x y = -x) turns at |w_x| ~ 0.026 rad/s: the cross-coupling makes the
    # integrator leak by ~ |w_x| t / 2 of the angle over t = 6 s (Baruh 10.7.3), ~8 %
    assert section["max_error"][0] <= 2 * H * np.max(np.abs(w[:, 2])) / k * section["max_truth"][0] + 1e-9
    leak = np.max(np.abs(w[:, 0])) * 6.0 / 2
    assert 0.2 * leak * section["max_truth"][1] <= section["max_error"][1] <= 1.5 * leak * section["max_truth"][1]
    assert (tmp_path / "report" / report["figures"]["sc"]["gyros"]).stat().st_size > 10_000


def test_engine_resumes_the_gimbals_from_a_recorded_state():
    scn = loads(TUMBLING)
    t = scn.output_times()
    eng = AttitudeEngine(scn)
    eng.states(t)
    (k_body, src), = eng.own_channels()
    full = src.last.copy()
    k = 150
    msg = src.message(k, float(t[k]), k)
    again = AttitudeEngine(scn)
    q, w = AttitudeEngine(scn).states(t[: k + 1])
    assert again.resume(float(t[k]), {"sc": {"q": q[k, 0].tolist(), "w": w[k, 0].tolist(), "angle": msg["angle"],
                                             "angle_rate": msg["angle_rate"]}}) == ["sc"]
    again.states(t[k + 1:])
    (_, src2), = again.own_channels()
    assert np.max(np.abs(src2.last[:, :, 0] - full[k + 1:, :, 0])) <= 1e-7 * np.max(np.abs(full[:, :, 0]))
    assert [c[1] for c in state_channels(scn, "attitude")] == ["attitude", "gimbals"]
