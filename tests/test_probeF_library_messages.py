"""Library results and messages a user met in probe F (notes: probeF_report.md F1.1-F1.3, F2.3,
F4.1-F4.3).

References independent of the code under test: the vis-viva energy ``a = -mu / (2 E)`` of a
radial orbit, worked in exact rational arithmetic (``fractions.Fraction``); Kepler's
definition that a radial orbit is the degenerate conic of ``e = 1``, ``p = h^2 / mu = 0``;
the SI units of the scenario's quantities (``e`` dimensionless, ``a`` in m, ``w`` in rad/s);
the benchmark's own stated target (ns per step) divided by hand.
"""

from __future__ import annotations

import csv
import json
import math
import re
import warnings
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from _recordings import one_satellite_scene
from astrodyn.attitude import torque_free
from astrodyn.orbit import elements_from_state

MU = 3.986004418e14
README = Path(__file__).resolve().parents[1] / "README.md"


def _energy_a(r, v, mu) -> float:
    """``-mu / (2 E)``, ``E = |v|^2 / 2 - mu / |r|``, from the exact values of the float inputs
    (``|r|`` is the one irrational: taken as the float, correctly rounded, of its square)."""
    rnorm = Fraction(math.sqrt(sum(Fraction(x) ** 2 for x in r)))
    energy = sum(Fraction(x) ** 2 for x in v) / 2 - Fraction(mu) / rnorm
    return math.inf if energy == 0 else float(-Fraction(mu) / (2 * energy))


# --------------------------------------------------------------------------- F1.1 radial states


@pytest.mark.parametrize("escaping", [False, True], ids=["bound", "escaping"])
def test_a_radial_state_is_e_1_p_0_and_a_from_its_energy(escaping):
    """r and v parallel as floating point makes them (v = s r / |r|), in random directions:
    before, h of rounding size gave p ~ 1e-30 m and a = p / (1 - e^2), noise (1e-14 m, or inf
    when e came out exactly 1); a radial orbit has e = 1, p = 0, a = -mu / (2 E)."""
    rng = np.random.default_rng(5)
    r = rng.normal(size=(200, 3)) * 7e6
    rnorm = np.linalg.norm(r, axis=1)
    escape = np.sqrt(2 * MU / rnorm)
    # |E| at least 0.3 mu / |r|: a well conditioned; bound below escape speed, escaping above
    speed = escape * (rng.uniform(0.0, 0.8, 200) if not escaping else rng.uniform(1.2, 3.0, 200))
    speed *= rng.choice([-1.0, 1.0], 200)  # falling in or flying out
    v = r / rnorm[:, None] * speed[:, None]
    el = elements_from_state(r, v, MU)
    assert np.all(el.e == 1.0) and np.all(el.p == 0.0)
    expected = np.array([_energy_a(r[k], v[k], MU) for k in range(len(r))])
    assert np.all(np.sign(el.a) == (-1.0 if escaping else 1.0))
    np.testing.assert_allclose(el.a, expected, rtol=1e-13)


def test_radial_falls_from_rest_and_the_radial_parabola():
    """From rest at r: E = -mu / r, a = r / 2 (the fall is half of a degenerate ellipse of
    major axis r); the radial parabola (E = 0 exactly: r = 2, v = 1, mu = 1) alone has a = inf."""
    el = elements_from_state([7e6, 0.0, 0.0], [0.0, 0.0, 0.0], MU)
    assert el.e == 1.0 and el.p == 0.0 and el.a == pytest.approx(3.5e6, rel=1e-15)
    el = elements_from_state([0.0, 2.0, 0.0], [0.0, 1.0, 0.0], 1.0)
    assert el.e == 1.0 and el.p == 0.0 and el.a == math.inf


def test_the_readme_states_what_a_radial_state_gives():
    """The README's elements row said only "a = inf when the computed e is exactly 1", which a
    radial state (e = 1, finite a) contradicts."""
    row = next(line for line in README.read_text().splitlines() if line.startswith("| elements |"))
    assert "radial" in row and "-mu / (2 E)" in row and "r = 0" in row, row


# --------------------------------------------------------------------------- F1.2 r = 0


def test_a_state_at_the_centre_of_attraction_gives_nan_elements_and_no_warning():
    """r = 0 has no conic: every element NaN, as for NaN input (docs/architecture.md, "Bad
    numbers"); before, numpy printed "RuntimeWarning: invalid value encountered in divide"
    (an error under warnings-as-errors) and a came out 0.  The other rows of a batch are
    unaffected."""
    good_r, good_v = np.array([7e6, 1e5, -2e5]), np.array([10.0, 7.5e3, 1e3])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        el = elements_from_state([0.0, 0.0, 0.0], [0.0, 7.5e3, 0.0], MU)
        batch = elements_from_state(np.stack([np.zeros(3), good_r]), np.stack([good_v, good_v]), MU)
        for bad in (np.inf, np.nan):  # NaN in, NaN out: silent as well
            elements_from_state([bad, 0.0, 0.0], good_v, MU)
    one = elements_from_state(good_r, good_v, MU)
    for name in ("p", "a", "e", "i", "raan", "argp", "nu"):
        assert np.isnan(getattr(el, name)), name
        assert np.isnan(getattr(batch, name)[0]) and getattr(batch, name)[1] == getattr(one, name), name


# --------------------------------------------------------------------------- F1.3 torque_free's inertia


def test_an_inertia_tensor_given_to_torque_free_is_named_as_read_as_three_bodies():
    """A (3, 3) array is three bodies' principal moments (propagate_attitude takes a tensor):
    before, diag(1, 2, 3) was refused as "got [1.0, 0.0, 0.0] (not positive)" alone."""
    with pytest.raises(ValueError) as info:
        torque_free(np.diag([1.0, 2.0, 3.0]), [0.1, 0.2, 0.3], [1.0, 0.0, 0.0, 0.0], 1.0)
    message = str(info.value)
    assert "inertia" in message and "3 bodies" in message and "tensor" in message and "principal_axes" in message
    with pytest.raises(ValueError, match=r"inertia: .*not an inertia tensor.*got shape \(3, 2\)"):
        torque_free(np.ones((3, 2)), [0.1, 0.2, 0.3], [1.0, 0.0, 0.0, 0.0], 1.0)
    assert "three bodies" in torque_free.__doc__ and "(3, 3)" in torque_free.__doc__


def test_a_three_by_three_inertia_is_three_bodies_each_as_alone():
    """What the docstring says the shape means: row k of a (3, 3) inertia is body k."""
    moments = np.array([[1.0, 2.0, 2.5], [2.0, 2.0, 3.0], [1.5, 1.0, 2.0]])
    w0, q0 = np.array([0.1, 0.2, 0.3]), np.array([1.0, 0.0, 0.0, 0.0])
    w, q = torque_free(moments, w0, q0, 2.0)
    for k in range(3):
        wk, qk = torque_free(moments[k], w0, q0, 2.0)
        np.testing.assert_array_equal(w[k], wk)
        np.testing.assert_array_equal(q[k], qk)


# --------------------------------------------------------------------------- F2.3 a sweep's units

SWEEP_CONFIG = one_satellite_scene("units", "60 s", "0.1 Hz")  # orbit a, e; attitude w, inertia


def test_a_sweeps_draw_columns_say_their_si_unit(tmp_path, capsys):
    """A draw without a unit is in SI, like a bare number in the config (docs/sweeps.md): e is
    dimensionless ("1", as the metric e_final), a in m, w in rad/s; a unit given stays.  Before,
    each said "SI", and a vector element drawn alone (w[0]) had no unit and was missing from
    failures.csv."""
    from astrodyn import sweep

    config = tmp_path / "units.toml"
    config.write_text(SWEEP_CONFIG)
    out = tmp_path / "out"
    rc = sweep.main([str(config), "--workers", "0", "-n", "2", "--out", str(out), "--quiet",
                     "--vary", "bodies.sat.orbit.e=uniform(0.001, 0.02)",
                     "--vary", "bodies.sat.orbit.a=uniform(6.9e6, 7.1e6)",
                     "--vary", "bodies.sat.attitude.w[0]=uniform(0.01, 0.02)",
                     "--vary", "bodies.sat.orbit.i=uniform(50, 52) deg"])
    assert rc == 0, capsys.readouterr().err
    units = json.loads((out / "sweep.json").read_text())["columns"]
    assert units["bodies.sat.orbit.e"] == units["sat.e_final"] == "1"
    assert units["bodies.sat.orbit.a"] == "m"
    assert units["bodies.sat.attitude.w[0]"] == "rad/s"
    assert units["bodies.sat.orbit.i [deg]"] == "deg"
    assert "SI" not in units.values()
    with open(out / "failures.csv", newline="") as f:  # the header lists the draws (no case failed)
        header = next(csv.reader(f))
    assert {"bodies.sat.orbit.e", "bodies.sat.orbit.a", "bodies.sat.attitude.w[0]", "bodies.sat.orbit.i [deg]"} <= set(header)


# --------------------------------------------------------------------------- F4 bench wording


def test_an_error_not_measured_is_a_dash_with_the_reason_not_nan():
    from astrodyn.bench.attitude import NOT_CHECKED_COSTLY, NOT_CHECKED_QUICK, table_line

    for ref in (NOT_CHECKED_QUICK, NOT_CHECKED_COSTLY):
        line = table_line(dict(method="exact", param="-", seconds=1.7e-6, per=174.0, per_unit="ns/(body,time)",
                               err_a=math.nan, err_w=math.nan, ref=ref, ratio=1.3e-6))
        cells = [c.strip() for c in line.strip("|").split("|")]
        assert "nan" not in line.lower() and cells[4] == cells[5] == "-", line
        assert "not checked" in cells[6] and "mpmath" in cells[6], line
    line = table_line(dict(method="split2", param="h=0.01 s", seconds=0.01, per=70.0, per_unit="ns/step",
                           err_a=1.44e-4, err_w=2.32e-4, ref="exact", ratio=0.001))
    assert "| 1.44e-04 | 2.32e-04 |" in line


def test_the_design_target_sentence_compares_ns_per_step_with_the_per_step_target():
    """Before: "split4 + gravity gradient: 550 ns/step = 110 ns per stage (5 stages; 0.55 x the
    target per stage)", which read as met; the target is per step, and 550 ns is 2.75 x 200."""
    from astrodyn.bench.attitude import TARGET_NS_PER_STEP, target_sentence

    assert TARGET_NS_PER_STEP == 200.0  # docs/architecture.md, section 7
    text = target_sentence(121.0, 550.0, 106.0)
    assert "per stage" not in text and "x the target per" not in text
    assert f"split4 + gravity gradient: 550 ns/step = {550 / 200:.2f} x the target (NOT met)" in text
    assert f"121 ns/step = {121 / 200:.2f} x the target (met)" in text
    assert f"106 ns/step = {106 / 200:.2f} x the target (met)" in text
    assert "NOT met" not in target_sentence(121.0, 190.0, 106.0)


def test_quick_figures_say_they_are_not_comparable(capsys, monkeypatch):
    """`bench all --quick` gave control 146 steps/s (documented 1,160-1,491) and "the view costs
    -8.6 %" with nothing saying the smoke run's figures are no measurement."""
    import astrodyn.bench as bench
    from astrodyn.bench import QUICK_ARGS, control, view

    quick_control = control.parse_args(QUICK_ARGS["control"])
    quick_view = view.parse_args(QUICK_ARGS["view"])
    for note in (control.few_steps_note(quick_control.steps), view.short_run_note(quick_view.wall, quick_view.rounds)):
        assert note is not None and "not comparable" in note and "docs/benchmarks.md" in note
    full_control, full_view = control.parse_args([]), view.parse_args([])  # the documented runs' defaults
    assert control.few_steps_note(full_control.steps) is None
    assert view.short_run_note(full_view.wall, full_view.rounds) is None

    monkeypatch.setattr(bench, "suite_args", lambda rest, quick: {})  # no suite run: the frame alone
    assert bench.main(["all", "--quick"]) == 0
    lines = [line for line in capsys.readouterr().out.splitlines() if line.strip()]
    assert lines[0] == lines[-1] == bench.QUICK_NOTE and "not comparable" in bench.QUICK_NOTE
    assert bench.main(["all"]) == 0 and bench.QUICK_NOTE not in capsys.readouterr().out
    text = (README.parent / "docs" / "benchmarks.md").read_text()
    assert re.search(r"smoke\s+form checks that every suite runs; its figures are not comparable", text)
