"""A sweep case whose whole-run arrays would not fit in memory fails by itself, before it
makes them; a sweep no case of which fits is refused up front (probe report F6).  A ``--vary``
unit with a number in front (``5 km``, a scaled unit) is refused (probe report F4).

References independent of the code under test: the layout of the run's arrays (float64 ``t``
and ``r, v`` per orbit: 56 bytes per step at least, a lower bound of any estimate), Python's
own allocation tracer (tracemalloc: numpy reports its buffers to it) for what a case really
takes, the two-body invariants of a Kepler orbit (final a and e equal the initial ones), the
same case simulated directly, and the unit conversions of the config loader written by hand.
No test allocates more than a few MB: budgets are set small (``--case-memory``) or the
machine's memory is replaced by a small number.
"""

from __future__ import annotations

import argparse
import csv
import math
import os
import re
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from astrodyn import sweep
from astrodyn.scenario import load_dict
from astrodyn.simulate import simulate
from astrodyn.sweep import SweepError, make_spec, parse_vary, run_case

A_M, E = 7_000_000.0, 0.01

TINY = f"""
[scenario]
name = "tiny"
epoch = "2026-01-01T00:00:00 UTC"
duration = "60 s"
rate = "1 Hz"

[central_body]
name = "earth"

[[bodies]]
name = "sat1"
[bodies.orbit]
a = "{A_M / 1e3} km"
e = {E}
i = "50 deg"
model = "kepler"

[[bodies]]
name = "sat2"
[bodies.orbit]
r = ["7000 km", "0 km", "0 km"]
v = ["0 km/s", "7.5 km/s", "0 km/s"]
"""

#: 60 s and 1e5 s at 1 Hz: 61 and 100001 output steps; the long one's arrays take at least
#: 100001 x (8 + 2 x 48) bytes = 10.4 MB (t, r and v of two orbits), over a budget of 1 MiB.
LONG_STEPS = 100_001
BUDGET = "1 MiB"
GRID = "scenario.duration=grid(60, 1e5, 2) s"


@pytest.fixture()
def tiny(tmp_path) -> Path:
    path = tmp_path / "tiny.toml"
    path.write_text(TINY)
    return path


def _read(path: Path) -> list[dict]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def _size_bytes(text: str) -> float:
    """The first ``about X UNIT`` size of a message, in bytes."""
    m = re.search(r"about ([0-9.e+]+) (bytes|KiB|MiB|GiB|TiB)", text)
    assert m, text
    return float(m.group(1)) * 1024 ** ("bytes", "KiB", "MiB", "GiB", "TiB").index(m.group(2))


def test_an_oversized_case_fails_alone_and_the_others_complete(tiny, tmp_path, capsys):
    out = tmp_path / "sw"
    rc = sweep.main([str(tiny), "--vary", GRID, "--workers", "0", "--case-memory", BUDGET, "--out", str(out),
                     "--quiet"])
    assert rc == 1  # some cases failed (docs/sweeps.md, exit status)
    err = capsys.readouterr().err
    # told up front, before any case ran: the dispersion, the estimate and the budget
    assert f"--vary {GRID!r}: a case at 100000.0 s needs about" in err, err
    assert "over the memory budget of a case of 1 MiB" in err, err

    (failure,) = _read(out / "failures.csv")
    assert failure["case"] == "1"
    message = failure["error"]
    assert message.startswith(f"{tiny} case 1: needs about "), message
    assert f"({LONG_STEPS} output steps of 2 orbit(s) and 0 attitude(s))" in message, message
    assert _size_bytes(message) >= LONG_STEPS * (8 + 2 * 48)  # at least the arrays a run holds
    for words in ("memory budget of a case of 1 MiB", "shorten scenario.duration", "lower scenario.rate",
                  "fewer bodies", "--case-memory"):
        assert words in message, (words, message)
    assert not (out / "failures").exists()  # a clean refusal: no traceback file

    rows = {r["case"]: r for r in _read(out / "summary.csv")}
    assert rows["1"]["status"] == "failed"
    ok = rows["0"]
    assert ok["status"] == "ok"
    assert int(ok["n_steps"]) == 61  # 60 s at 1 Hz, t = 0 included
    # the two-body invariants: a Kepler orbit keeps its a and e
    assert float(ok["sat1.a_final"]) == pytest.approx(A_M, rel=1e-12)
    assert float(ok["sat1.e_final"]) == pytest.approx(E, abs=1e-12)
    assert float(ok["sat1.energy_drift"]) < 1e-13
    # and the same case simulated directly gives the same metrics, bit for bit
    spec = make_spec(tiny, [GRID])
    scenario = load_dict(spec.case_config(0)[0], source="x", base_dir=str(tiny.parent))
    direct = sweep.case_metrics(scenario, simulate(scenario))
    for key, value in direct.items():
        assert (float(ok[key]) == value) if isinstance(value, float) else (ok[key] == str(value)), key


def _traced_peak(call):
    """``(call(), peak bytes tracemalloc saw while it ran)``."""
    tracemalloc.start()
    try:
        result = call()
        return result, tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_the_oversized_case_is_refused_before_it_allocates(tiny):
    spec = make_spec(tiny, [GRID])
    spec.case_memory = 2**20
    assert run_case(0, spec)["status"] == "ok"  # warm up: numba kernels, astropy units
    row, peak = _traced_peak(lambda: run_case(1, spec))
    assert row["status"] == "failed" and "needs about" in row["error"], row
    assert "traceback" not in row
    assert peak < 2**20, peak  # far below the 10.4 MB the run's arrays would take


def test_a_sweep_no_case_of_which_fits_is_refused_up_front(tiny, tmp_path, capsys):
    out = tmp_path / "sw"
    vary = "scenario.duration=grid(1e5, 2e5, 3) s"
    rc = sweep.main([str(tiny), "--vary", vary, "--workers", "0", "--case-memory", BUDGET, "--out", str(out)])
    assert rc == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0, err
    assert err.startswith("astrodyn sweep: no case fits in the memory budget of a case"), err
    assert "no case was run" in err and "case 0 needs about" in err and "of 1 MiB" in err, err
    assert _size_bytes(err) >= LONG_STEPS * (8 + 2 * 48)
    assert not out.exists()  # nothing created


def test_the_default_budget_is_half_the_machine_memory_over_the_cases_at_once(tiny, tmp_path, capsys,
                                                                                monkeypatch):
    phys = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    assert 0 < sweep.machine_memory() <= phys
    small = 16 * 2**20  # stands for the machine's memory: no test allocates gigabytes
    monkeypatch.setattr(sweep, "machine_memory", lambda: small)
    assert sweep.default_case_memory(0) == sweep.default_case_memory(1) == small // 2
    assert sweep.default_case_memory(2) == small // 4
    assert sweep.case_memory_here() == small // 2  # not in a Dask worker: this machine's
    rc = sweep.main([str(tiny), "--vary", GRID, "--workers", "0", "--out", str(tmp_path / "sw"), "--quiet"])
    assert rc == 1
    (failure,) = _read(tmp_path / "sw" / "failures.csv")
    assert failure["case"] == "1" and "over the memory budget of a case of 8 MiB" in failure["error"], failure


def test_the_estimate_bounds_what_a_case_takes(tmp_path):
    config = tmp_path / "mixed.toml"
    config.write_text(TINY.replace('duration = "60 s"', 'duration = "10000 s"') + """
[bodies.attitude]
w = ["0.01 rad/s", "0.2 rad/s", "0.001 rad/s"]
inertia = ["1 kg m2", "2 kg m2", "3 kg m2"]

[[bodies]]
name = "sat3"
[bodies.orbit]
a = "7000 km"
e = 0.001
model = "j2"
""")
    spec = make_spec(config, ["scenario.rate=1 Hz"], n=1)
    spec.case_memory = 2**40
    # warm up with the case itself: a shorter one takes other kernels (the parallel variants,
    # for as many steps), whose compile the tracer then counted when no earlier test of the
    # session had compiled them (seen with the tests spread over two workers: 23 MB)
    assert run_case(0, spec)["status"] == "ok"
    row, peak = _traced_peak(lambda: run_case(0, spec))
    assert row["status"] == "ok", row
    scenario = load_dict(spec.case_config(0)[0], source="x", base_dir=str(tmp_path))
    need = sweep.case_memory_need(scenario)
    held = scenario.n_steps * (8 + 3 * 48 + 1 * 56)  # t, r, v of 3 orbits, q, w of 1 attitude
    assert peak <= need, (peak, need)
    assert need <= 3 * peak, (peak, need)  # an estimate, not a wild guess
    assert peak >= held  # what the tracer saw includes the run's arrays


@pytest.mark.parametrize("unit", ["5 km", "2 deg", "10/s", "1e3 m", ".5 km"])
def test_a_vary_unit_with_a_number_is_refused(tiny, tmp_path, capsys, unit):
    vary = f"bodies.sat1.orbit.a=uniform(6800, 7200) {unit}"
    with pytest.raises(SweepError) as info:
        parse_vary(vary)
    assert str(info.value).startswith(f"--vary {vary!r}: expected a unit without a number"), info.value
    assert f"got {unit!r}" in str(info.value)
    out = tmp_path / "sw"
    assert sweep.main([str(tiny), "--vary", vary, "-n", "2", "--workers", "0", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and f"--vary {vary!r}" in err, err
    assert not out.exists()


@pytest.mark.parametrize(("vary", "read", "expected"), [
    ("bodies.sat1.orbit.a=grid(6800, 7200, 2) km", lambda s: s.body("sat1").orbit.elements["a"], [6.8e6, 7.2e6]),
    ("bodies.sat2.orbit.v[1]=grid(7, 8, 2) km/s", lambda s: s.body("sat2").orbit.v0[1], [7000.0, 8000.0]),
    ("bodies.sat1.orbit.i=grid(30, 60, 2) deg", lambda s: s.body("sat1").orbit.elements["i"],
     [math.pi / 6, math.pi / 3]),
    ("scenario.rate=grid(1, 2, 2) 1/s", lambda s: s.rate, [1.0, 2.0]),
], ids=["km", "km/s", "deg", "1/s"])
def test_units_without_a_number_still_work(tiny, vary, read, expected):
    spec = make_spec(tiny, [vary])
    got = [read(load_dict(spec.case_config(k)[0], source="x", base_dir=str(tiny.parent))) for k in range(2)]
    np.testing.assert_allclose(got, expected, rtol=1e-14)


@pytest.mark.parametrize("text", ["0", "-1 GB", "1e30 B", "2 mb", "4 kg"])
def test_a_case_memory_that_is_no_budget_is_refused_naming_the_flag(text):
    """``--case-memory "1e30 B"`` was taken and turned the guard off (probe D, D6); a size in
    bits, of another kind or below 1 byte is refused too."""
    with pytest.raises(argparse.ArgumentTypeError):
        sweep.case_memory_argument(text)
    assert sweep.case_memory_argument("4 GiB") == 4 * 2**30
