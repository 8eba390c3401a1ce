"""Per-model invariants (astrodyn.analysis.invariants) against the physics they claim.

Each model's rows are computed on states from an independent propagation of that
model (the exact Kepler solution, DOP853 on the J2 / J2..J6 equations at rtol 1e-12,
the splitting integrator for tops and gyrostats): the quantities the row calls conserved
stay at the propagation's error, and the quantity a model does *not* conserve (the
two-body energy of a J2 orbit, |h| under zonals, T of a heavy top) is shown to move by
orders of magnitude more, so a row with the wrong potential or sign cannot pass.
"""

from __future__ import annotations

import numpy as np
import pytest

from astrodyn.analysis.invariants import attitude_invariants, orbit_invariants
from astrodyn.attitude import UniformGravityTorque, propagate_attitude, torque_free
from astrodyn.orbit import EARTH_EGM2008, propagate, propagate_perturbed
from astrodyn.rotation import quat_from_euler

MU = EARTH_EGM2008.mu
R_E = EARTH_EGM2008.radius


def _rows(rows):
    return {r.name: r for r in rows}


def _molniya():
    from astrodyn.orbit import state_from_elements

    a, e = 26600e3, 0.74
    return state_from_elements(a * (1 - e * e), e, np.radians(50.0), 0.3, np.radians(270.0), 0.1, MU)


def test_kepler_rows_hold_to_round_off():
    r0, v0 = _molniya()
    t = np.linspace(0.0, 3 * 43200.0, 400)
    r, v = propagate(np.broadcast_to(r0, (t.size, 3)), np.broadcast_to(v0, (t.size, 3)), t, MU)
    rows = _rows(orbit_invariants("kepler", r, v, MU))
    assert rows["E (two-body)"].drift < 1e-14 and rows["E (two-body)"].scale == "|E0|"
    assert rows["h"].drift < 1e-14 and rows["h"].unit == "m^2/s"


@pytest.mark.parametrize("degree", [2, 6])
def test_zonal_rows_hold_where_the_two_body_ones_do_not(degree):
    r0, v0 = _molniya()
    t = np.linspace(0.0, 2 * 43200.0, 300)
    zonal = EARTH_EGM2008.zonal(degree)
    states = propagate_perturbed(r0, v0, t, MU, perturbations=[zonal], rtol=1e-12, atol=1e-14)
    r, v = states.r, states.v
    rows = _rows(orbit_invariants("j2" if degree == 2 else "zonal", r, v, MU, radius=R_E, j=EARTH_EGM2008.J,
                                  degree=degree))
    energy = next(k for k in rows if k.startswith("E (with J2"))
    assert rows[energy].drift < 1e-10, rows[energy]
    assert rows["h_z"].drift < 1e-10, rows["h_z"]
    two_body = _rows(orbit_invariants("kepler", r, v, MU))
    # what J2 really changes: 1e-5 .. 1e-3 for a Molniya perigee at ~600 km
    assert two_body["E (two-body)"].drift > 1e4 * rows[energy].drift
    assert two_body["h"].drift > 1e4 * rows["h_z"].drift


def test_third_body_has_no_orbit_invariant():
    r0, v0 = _molniya()
    (row,) = orbit_invariants("third_body", np.array([r0]), np.array([v0]), MU, third_body=True)
    assert not row.conserved and "none" in row.name


def test_torque_free_rows():
    inertia = np.array([1.0, 2.0, 3.0])
    t = np.linspace(0.0, 300.0, 301)
    w, q = torque_free(inertia, [1e-3, 1.0, 1e-3], quat_from_euler([0.1, 0.2, 0.3], "321"), t)
    rows = _rows(attitude_invariants("torque_free", q, w, np.diag(inertia)))
    assert rows["T"].drift < 1e-13 and rows["H_i"].drift < 1e-13 and rows["|q| - 1"].drift < 1e-14


def test_gyrostat_rows_include_the_rotor_momentum():
    inertia = np.diag([10.0, 12.0, 8.0])
    h = np.array([0.0, 0.0, 3.0])
    t = np.linspace(0.0, 200.0, 201)
    drifts = []
    for step in (0.2, 0.1):  # the splitting keeps H exactly; T only to its 4th-order error
        w, q, _ = propagate_attitude(inertia, [0.05, 0.3, 0.2], [1.0, 0.0, 0.0, 0.0], t, rotor_momentum=h,
                                     method="split4", step=step, error_estimate=False)
        rows = _rows(attitude_invariants("gyrostat", q, w, inertia, rotor_momentum=h))
        assert rows["H_i"].drift < 1e-13, rows["H_i"]
        drifts.append(rows["T"].drift)
    # halving the step divides the energy error by ~2^4: it is the integrator's, the invariant is right
    assert drifts[1] < drifts[0] / 10, drifts
    without = _rows(attitude_invariants("torque_free", q, w, inertia))  # forgetting the rotors breaks H_i
    assert without["H_i"].drift > 1e6 * rows["H_i"].drift


def test_heavy_top_rows():
    inertia = np.diag([0.6, 0.6, 0.2])  # about the fixed point, symmetric
    m, l, g = 1.5, 0.1, 9.80665
    q0 = quat_from_euler([0.0, 0.4, 0.0], "313")
    t = np.linspace(0.0, 5.0, 501)
    w, q, _ = propagate_attitude(inertia, [0.0, 0.0, 40.0], q0, t, torque=UniformGravityTorque(m, [0.0, 0.0, l], (0, 0, -g)),
                                 method="split4", error_estimate=False)
    rows = _rows(attitude_invariants("heavy_top", q, w, inertia, mass=m, cm=l, g=g))
    energy = rows["E = T + m g cm cos(theta)"]
    assert energy.drift < 1e-8 and rows["L_z"].drift < 1e-8 and rows["H_3 (spin)"].drift < 1e-10, rows
    # the kinetic energy alone is not conserved (nutation trades it with the potential)
    t_alone = _rows(attitude_invariants("torque_free", q, w, inertia))["T"]
    assert t_alone.drift > 1e3 * energy.drift


def test_bad_shapes_name_the_arrays():
    with pytest.raises(ValueError, match="r, v"):
        orbit_invariants("kepler", np.zeros((3,)), np.zeros((3,)), MU)
    with pytest.raises(ValueError, match="q, w"):
        attitude_invariants("torque_free", np.zeros((2, 3)), np.zeros((2, 3)), np.eye(3))


def test_rows_from_a_recording_and_in_the_analysis_report(tmp_path):
    """The recording made before the refactor (tests/fixtures): models and constants come
    from its scenario metadata; the J2 body is judged by the energy with J2."""
    from pathlib import Path

    from astrodyn.analysis import analyze
    from astrodyn.analysis.invariants import recorded_invariants
    from astrodyn.recording import load

    path = Path(__file__).parent / "fixtures" / "legacy-v0.mcap"
    run = load(path)
    m = run.bodies["molniya"].orbit
    rows = _rows(recorded_invariants(run.scenario, "molniya", orbit=("j2", m.r, m.v))["orbit"])
    assert set(rows) == {"E (with J2)", "h_z"}
    assert rows["E (with J2)"].drift < 1e-9  # the recorded J2 run, DOP853 at the service's tolerance
    assert _rows(orbit_invariants("kepler", m.r, m.v, MU))["E (two-body)"].drift > 1e-6  # J2 moves it
    c = run.bodies["cubesat"].attitude
    assert _rows(recorded_invariants(run.scenario, "cubesat", attitude=("torque_free", c.q, c.w))["attitude"])["T"].drift < 1e-13
    report = analyze(path, tmp_path / "report")
    section = report["bodies"]["molniya"]["conserved quantities"]
    assert any(k.startswith("orbit: E (with J2) [J/kg]") for k in section)
    assert "E (with J2)" in (tmp_path / "report" / "report.md").read_text()
    # a recording without metadata constants still gets the rows that need none
    bare = recorded_invariants({}, "molniya", orbit=("j2", m.r, m.v), attitude=("torque_free", c.q, c.w))
    assert "orbit" not in bare and [i.name for i in bare["attitude"]] == ["|q| - 1"]
