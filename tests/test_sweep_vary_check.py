"""A ``--vary`` (or ``--cases`` column) that would fail every case is refused before any case
runs, exit 2, nothing created (walk report F7; docs/sweeps.md: exit 2 for a bad spec).

The refusal's text is compared with the scenario validator's own answer for the same edit of
the config made by hand (:func:`astrodyn.scenario.load_dict`), so the message names the field
and what it accepts.  Dispersions only some of whose values are invalid still run (those
cases fail one by one), as does one that is valid only together with another.
"""

from __future__ import annotations

import copy
import subprocess
import sys
import time
from pathlib import Path

import pytest

from _recordings import orbiter, scenario_head
from astrodyn.scenario import ScenarioError, load, load_dict
from astrodyn.sweep import SweepError, make_spec

ROOT = Path(__file__).resolve().parents[1]
DEMO = ROOT / "configs" / "demo.toml"


def _validator_says(edit) -> str:
    """The scenario loader's message (after the ``<source>: ``) for demo.toml edited by ``edit``."""
    config = copy.deepcopy(load(DEMO).config)
    edit(config)
    with pytest.raises(ScenarioError) as info:
        load_dict(config, source="SRC", base_dir=str(DEMO.parent))
    return str(info.value).removeprefix("SRC: ")


def _checked(*args, **kwargs):
    """:func:`make_spec`, then the check ``astrodyn sweep`` applies before any case runs."""
    from astrodyn.sweep import check_values_against_config

    spec = make_spec(*args, **kwargs)
    check_values_against_config(spec)
    return spec


def _sweep(tmp_path: Path, vary: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "astrodyn", "sweep", str(DEMO), "--vary", vary, "-n", "4",
                           "--workers", "0", "--out", str(tmp_path / "sw"), "--quiet"],
                          capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL)


def _iss(config: dict) -> dict:
    return next(b for b in config["bodies"] if b["name"] == "iss")


@pytest.mark.parametrize(("vary", "edit"), [
    ("bodies.iss.orbit.ecc=uniform(0.0001, 0.01)", lambda c: _iss(c)["orbit"].update(ecc="0.0001")),
    ("bodies.iss.orbit.a=uniform(6800, 7200) deg", lambda c: _iss(c)["orbit"].update(a="6800.0 deg")),
], ids=["misspelled key", "unit of the wrong kind"])
def test_a_vary_that_fails_every_case_is_refused_up_front(tmp_path, vary, edit):
    t0 = time.monotonic()
    done = _sweep(tmp_path, vary)
    assert done.returncode == 2, (done.returncode, done.stderr)
    err = done.stderr.strip()
    assert err.count("\n") == 0 and "Traceback" not in err, err
    assert err.startswith(f"astrodyn sweep: --vary {vary!r}: "), err
    expected = _validator_says(edit)
    field, rest = expected.split(": expected ", 1)
    assert f"{field}: expected {rest.rsplit(', got ', 1)[0]}" in err, (err, expected)  # the field and what it accepts
    assert not (tmp_path / "sw").exists()  # nothing created, no case run
    assert time.monotonic() - t0 < 60


def test_a_misspelled_cases_column_is_refused_up_front(tmp_path):
    cases = tmp_path / "cases.csv"
    cases.write_text("bodies.iss.orbit.ecc\n0.001\n0.002\n")
    with pytest.raises(SweepError) as info:
        _checked(DEMO, [], cases_csv=cases)
    assert "--cases column 'bodies.iss.orbit.ecc'" in str(info.value)
    assert 'got unknown key "ecc"' in str(info.value)


ORBIT = scenario_head("check", "60 s", "0.1 Hz", "TDB") + "\n" + orbiter("sat1", "7000 km", 0.01, "51.6 deg")


@pytest.fixture
def orbit(tmp_path) -> Path:
    path = tmp_path / "orbit.toml"
    path.write_text(ORBIT)
    return path


def test_a_dispersion_with_some_invalid_values_still_runs(orbit):
    """e < 0 is invalid, but most draws of uniform(-0.05, 0.2) are not: the cases fail one by one."""
    for vary in ("bodies.sat1.orbit.e=uniform(-0.05, 0.2)", "bodies.sat1.orbit.e=normal(0, 0.01)",
                 "bodies.sat1.orbit.e=choice(-1, 0.1)"):
        _checked(orbit, [vary], n=4)


def test_values_valid_only_together_are_accepted(orbit):
    """A hyperbola needs e > 1 and a < 0: each alone contradicts the config, together they do not."""
    e, a = "bodies.sat1.orbit.e=uniform(1.5, 2)", "bodies.sat1.orbit.a=uniform(-9000, -8000) km"
    for alone in (e, a):
        with pytest.raises(SweepError, match="no case was run"):
            _checked(orbit, [alone], n=4)
    _checked(orbit, [e, a], n=4)
