"""``astrodyn sweep``: dispersion parser, per-case reproducibility, Dask = serial, failures, reruns.

References independent of the code under test: numpy's documented generator
(``default_rng([seed, k])`` drawn by hand), ``itertools.product`` for grid order, the
values a case was given (a Kepler orbit's final osculating a and e equal the drawn ones:
two-body invariants), the conic's bounds a(1 - e) <= r <= a(1 + e), and a serial run for
the distributed one.
"""

from __future__ import annotations

import csv
import itertools
import json
import math
from pathlib import Path

import numpy as np
import pytest

from _recordings import orbiter, scenario_head
from astrodyn import sweep
from astrodyn.sweep import SweepError, make_spec, parse_path, parse_value, parse_vary

CONFIG = scenario_head("sweep-test", "600 s", "0.1 Hz", "TDB") + "\n" + orbiter("sat1", "7000 km", 0.01, "51.6 deg") \
    + "\n" + orbiter("sat2", "7000 km", 0.01, "51.6 deg", nu="1 deg")

# e drawn from [-0.05, 0.2): draws below 0 are invalid (the loader wants 0 <= e), so
# those cases fail with the ScenarioError text and the others run.
VARIES = ["bodies.sat1.orbit.e=uniform(-0.05, 0.2)", "bodies[1].orbit.a=normal(7000, 10) km"]
N = 20
SEED = 11


@pytest.fixture(scope="module")
def config(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("sweep") / "orbit2.toml"
    path.write_text(CONFIG)
    return path


def _argv(config: Path, out: Path, *extra: str) -> list[str]:
    return [str(config), *sum((["--vary", v] for v in VARIES), []), "-n", str(N), "--seed", str(SEED),
            "--out", str(out), "--quiet", *extra]


def _read(path: Path) -> list[dict]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def _no_wall(row: dict) -> dict:
    return {k: v for k, v in row.items() if k != "wall_s"}


@pytest.fixture(scope="module")
def serial_run(config, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("serial")
    rc = sweep.main(_argv(config, out, "--workers", "0"))
    assert rc == 1  # some draws are invalid by construction (see VARIES)
    return out


def _expected_failed() -> set[int]:
    # independent of the sweep code: the first draw of case k from numpy's generator
    return {k for k in range(N) if np.random.default_rng([SEED, k]).uniform(-0.05, 0.2) < 0}


# --------------------------------------------------------------------------- parser


def test_parse_value_and_path():
    assert parse_value("[0, 0, 0.1]") == [0, 0, 0.1]
    assert parse_value("-2.5e3") == -2500.0 and parse_value("7") == 7
    assert parse_value('"6800 km"') == "6800 km" and parse_value("j2") == "j2"
    assert parse_path("bodies[2].orbit.e") == ("bodies", 2, "orbit", "e")
    assert parse_path("bodies[sat.1].attitude.w[2]") == ("bodies", "sat.1", "attitude", "w", 2)
    assert parse_path("bodies.sat1.orbit.e") == ("bodies", "sat1", "orbit", "e")


@pytest.mark.parametrize("text, words", [
    ("bodies.sat1.orbit.e", ["PATH=DISTRIBUTION"]),
    ("bodies.sat1.orbit.e=gauss(0, 1)", ["unknown distribution", "'gauss'", "uniform, normal, choice, grid"]),
    ("bodies.sat1.orbit.e=uniform(0.1)", ["uniform", "expected 2 arguments", "got 1"]),
    ("bodies.sat1.orbit.e=uniform(0.9, 0.1)", ["low <= high"]),
    ("bodies.sat1.orbit.e=normal(0.1, -1)", ["sigma >= 0"]),
    ("bodies.sat1.orbit.e=normal([0, 0], [1, 1, 1])", ["shape of mean"]),
    ("bodies.sat1.orbit.e=uniform(0.1, 0.2) furlongs/fortnite", ["unit", "furlongs/fortnite"]),
    ("bodies.sat1.orbit.model=choice(kepler, j2) km", ["unit applies to numbers only"]),
    ("bodies.sat1.orbit.e=grid(0, 1, 2.5)", ["point count"]),
    ("bodies.sat1.orbit.e=uniform(0.1, __import__('os'))", ["expected", "character"]),
    ("bodies..orbit.e=uniform(0, 1)", ["key path", "character"]),
    ("bodies.sat1.orbit.e=uniform(0.1, 0.2", ["')'", "the end"]),
])
def test_parse_errors_are_clear(text, words):
    with pytest.raises(SweepError) as info:
        parse_vary(text)
    msg = str(info.value)
    assert msg.startswith("--vary"), msg
    for w in words:
        assert w in msg, (w, msg)


def test_paths_are_checked_against_the_config(config):
    with pytest.raises(SweepError, match=r"no entry named 'sat9'.*names: sat1, sat2"):
        make_spec(config, ["bodies.sat9.orbit.e=uniform(0, 0.1)"], n=2)
    with pytest.raises(SweepError, match=r"bodies has 2 entries; expected an index 0..1"):
        make_spec(config, ["bodies[5].orbit.e=uniform(0, 0.1)"], n=2)
    with pytest.raises(SweepError, match=r"bodies\[0\].orbitx is not in the config"):
        make_spec(config, ["bodies.sat1.orbitx.e=uniform(0, 0.1)"], n=2)
    with pytest.raises(SweepError, match=r"-n: expected the number of cases"):
        make_spec(config, ["bodies.sat1.orbit.e=uniform(0, 0.1)"])
    with pytest.raises(SweepError, match=r"at most once"):
        make_spec(config, ["bodies.sat1.orbit.e=uniform(0, 0.1)", "bodies[0].orbit.e=0.2".replace("bodies[0]", "bodies.sat1")], n=2)


def test_draws_are_numpy_default_rng_seed_case_in_order(config):
    spec = make_spec(config, ["bodies.sat1.orbit.e=uniform(0.1, 0.9)", "bodies.sat2.orbit.i=normal([1, 2], 0.5)",
                              "bodies.sat2.orbit.model=choice(kepler, j2)"], n=50, seed=3)
    for k in (0, 1, 17, 49):
        rng = np.random.default_rng([3, k])
        e = rng.uniform(0.1, 0.9)
        i = rng.normal([1.0, 2.0], 0.5)
        m = ["kepler", "j2"][int(rng.integers(2))]
        d = spec.draws(k)
        assert d["bodies.sat1.orbit.e"] == e
        assert d["bodies.sat2.orbit.i"] == list(i)
        assert d["bodies.sat2.orbit.model"] == m


def test_grids_form_the_product_first_slowest(config):
    spec = make_spec(config, ["bodies.sat1.orbit.e=grid(0, 0.2, 3)", "bodies.sat2.orbit.e=grid([0.01, 0.02])",
                              "scenario.rate=0.5"])
    assert spec.n == 6
    expected = list(itertools.product(np.linspace(0, 0.2, 3), [0.01, 0.02]))
    got = [(spec.draws(k)["bodies.sat1.orbit.e"], spec.draws(k)["bodies.sat2.orbit.e"]) for k in range(6)]
    assert got == [(float(a), b) for a, b in expected]
    assert all(spec.draws(k)["scenario.rate"] == 0.5 for k in range(6))


def test_cases_csv(config, tmp_path):
    path = tmp_path / "cases.csv"
    path.write_text('bodies.sat1.orbit.e,bodies[1].orbit.a\n0.1,"""7100 km"""\n0.2,\n')
    spec = make_spec(config, ["bodies.sat2.orbit.e=uniform(0, 0.01)"], cases_csv=path)
    assert spec.n == 2
    assert spec.draws(0)["bodies[1].orbit.a"] == "7100 km" and spec.draws(0)["bodies.sat1.orbit.e"] == 0.1
    assert "bodies[1].orbit.a" not in spec.draws(1)
    bad = tmp_path / "bad.csv"
    bad.write_text("bodies.sat1.orbit.e\nexec(1)\n")
    with pytest.raises(SweepError, match=r"line 2, column 'bodies.sat1.orbit.e'"):
        make_spec(config, [], cases_csv=bad)


# --------------------------------------------------------------------------- runs


def test_serial_run_reports_failures_and_completes_the_rest(serial_run):
    rows = _read(serial_run / "summary.csv")
    assert [int(r["case"]) for r in rows] == list(range(N))
    failed = {int(r["case"]) for r in rows if r["status"] != "ok"}
    assert failed == _expected_failed() and 0 < len(failed) < N
    fails = _read(serial_run / "failures.csv")
    assert {int(r["case"]) for r in fails} == failed
    for r in fails:
        assert "bodies[0] (sat1).orbit.e: expected 0 <= e" in r["error"], r["error"]
        assert f"case {r['case']}:" in r["error"]
    spec = json.loads((serial_run / "sweep.json").read_text())
    assert spec["seed"] == SEED and spec["n"] == N and spec["failed"] == len(failed)
    assert spec["columns"]["sat1.a_final"] == "m" and spec["columns"]["bodies[1].orbit.a [km]"] == "km"


def test_metrics_match_the_drawn_orbit(serial_run):
    """Kepler orbits keep a and e: the final osculating elements equal the drawn ones."""
    for r in _read(serial_run / "summary.csv"):
        if r["status"] != "ok":
            continue
        e = float(r["bodies.sat1.orbit.e"])
        a2 = float(r["bodies[1].orbit.a [km]"]) * 1e3
        # elements -> state -> exact propagation -> elements: each step is accurate to a few
        # tens of ulp of its inputs (a ~ 7e6 m: 1 ulp ~ 1e-9 m); 1e-12 relative is ~100x that
        assert float(r["sat1.a_final"]) == pytest.approx(7.0e6, rel=1e-12)
        assert float(r["sat2.a_final"]) == pytest.approx(a2, rel=1e-12)
        assert float(r["sat1.e_final"]) == pytest.approx(e, rel=1e-11, abs=1e-14)
        assert float(r["sat2.e_final"]) == pytest.approx(0.01, rel=1e-11)
        # sampled radii lie on the conic: a(1 - e) <= r <= a(1 + e) (100 ulp slack)
        assert 7.0e6 * (1 - e) * (1 - 1e-13) <= float(r["sat1.r_min"]) <= float(r["sat1.r_max"]) <= 7.0e6 * (1 + e) * (1 + 1e-13)
        # exact two-body motion: energy and h are constants up to round-off (~1e-15)
        assert float(r["sat1.energy_drift"]) < 1e-13 and float(r["sat1.h_drift"]) < 1e-13
        assert r["min_separation_pair"] == "sat1|sat2" and float(r["min_separation"]) > 0
        assert int(r["n_steps"]) == 61  # 600 s at 0.1 Hz, t = 0 included


def test_dask_local_cluster_gives_the_serial_table(config, serial_run, tmp_path):
    pytest.importorskip("distributed")
    rc = sweep.main(_argv(config, tmp_path, "--workers", "2", "--chunk", "3"))  # 7 tasks of <= 3 cases
    assert rc == 1
    dask_rows = _read(tmp_path / "summary.csv")
    serial_rows = _read(serial_run / "summary.csv")
    assert list(dask_rows[0]) == list(serial_rows[0])
    # exact: the same draws and the same float64 code; only wall time differs
    assert [_no_wall(r) for r in dask_rows] == [_no_wall(r) for r in serial_rows]
    assert _read(tmp_path / "failures.csv") == _read(serial_run / "failures.csv")
    assert json.loads((tmp_path / "sweep.json").read_text())["workers"] == 2


def test_rerun_one_case_gives_the_same_row(config, serial_run, tmp_path, capsys):
    import shutil

    out = tmp_path / "copy"
    shutil.copytree(serial_run, out)
    before = _read(out / "summary.csv")
    ok = next(k for k in range(N) if k not in _expected_failed())
    bad = min(_expected_failed())
    rc = sweep.main(_argv(config, out, "--case", str(ok), "--case", str(bad)))
    assert rc == 1
    printed = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert [p["case"] for p in sorted(printed, key=lambda p: p["case"])] == sorted([ok, bad])
    after = _read(out / "summary.csv")
    assert [_no_wall(r) for r in after] == [_no_wall(r) for r in before]
    assert _read(out / "failures.csv") == _read(serial_run / "failures.csv")
    assert json.loads((out / "sweep.json").read_text())["reruns"] == [sorted([ok, bad])]


def test_unexpected_exception_fails_only_that_case(config, tmp_path, monkeypatch):
    import astrodyn.simulate as sim

    real = sim.simulate

    def flaky(scenario, *a, **kw):
        if scenario.source.endswith("case 2"):
            raise RuntimeError("boom in case 2")
        return real(scenario, *a, **kw)

    monkeypatch.setattr(sim, "simulate", flaky)
    rc = sweep.main([str(config), "--vary", "bodies.sat1.orbit.e=uniform(0, 0.1)", "-n", "4", "--workers", "0",
                     "--out", str(tmp_path), "--quiet"])
    assert rc == 1
    rows = _read(tmp_path / "summary.csv")
    assert [r["status"] for r in rows] == ["ok", "ok", "failed", "ok"]
    assert _read(tmp_path / "failures.csv")[0]["error"] == "RuntimeError: boom in case 2"
    assert "boom in case 2" in (tmp_path / "failures" / "case-000002.txt").read_text()


def test_case_mcap_is_complete(config, tmp_path):
    from mcap.reader import make_reader

    rc = sweep.main([str(config), "--vary", "bodies.sat1.orbit.e=uniform(0, 0.1)", "-n", "1", "--workers", "0",
                     "--mcap", "--out", str(tmp_path), "--quiet"])
    assert rc == 0
    seqs: dict[str, list[int]] = {}
    ecc: dict[str, list[float]] = {}
    with open(tmp_path / "mcap" / "case-000000.mcap", "rb") as f:
        reader = make_reader(f)
        for _, channel, message in reader.iter_messages():
            msg = json.loads(message.data)
            seqs.setdefault(channel.topic, []).append(msg["seq"])
            # eccentricity vector from the recorded state (two-body, independent of the sweep code)
            r, v, mu = np.array(msg["r"]), np.array(msg["v"]), msg["mu"]
            e_vec = ((v @ v - mu / np.linalg.norm(r)) * r - (r @ v) * v) / mu
            ecc.setdefault(channel.topic, []).append(float(np.linalg.norm(e_vec)))
        f.seek(0)
        meta = {m.name: m.metadata for m in make_reader(f).iter_metadata()}
    assert set(seqs) == {"astrodyn/sweep-test/sat1/orbit", "astrodyn/sweep-test/sat2/orbit"}
    assert all(s == list(range(61)) for s in seqs.values())
    # each channel carries its own body's states: sat1 has the drawn e, sat2 the config's
    drawn = json.loads(meta["scenario"]["sweep_draws"])["bodies.sat1.orbit.e"]
    # 1e-9: e from a state has ~1e-16 / e relative round-off, far below this
    np.testing.assert_allclose(ecc["astrodyn/sweep-test/sat1/orbit"], drawn, atol=1e-9)
    np.testing.assert_allclose(ecc["astrodyn/sweep-test/sat2/orbit"], 0.01, atol=1e-9)


def test_cli_errors_exit_2(config, tmp_path, capsys):
    assert sweep.main([str(config), "--vary", "bodies.sat1.orbit.e=uniform(0.1)", "-n", "2", "--out", str(tmp_path)]) == 2
    assert "uniform: expected 2 arguments" in capsys.readouterr().err
    assert sweep.main([str(config), "--vary", "bodies.sat1.orbit.e=uniform(0, 0.1)", "-n", "2", "--case", "5",
                       "--out", str(tmp_path)]) == 2
    assert "--case: expected 0 <= K < 2" in capsys.readouterr().err
    assert sweep.main([str(tmp_path / "missing.toml"), "--vary", "scenario.rate=1", "-n", "1", "--out", str(tmp_path)]) == 2


def test_parquet_equals_csv(serial_run):
    pq = pytest.importorskip("pyarrow.parquet")
    table = pq.read_table(serial_run / "summary.parquet").to_pylist()
    rows = _read(serial_run / "summary.csv")
    assert len(table) == len(rows)
    for t, r in zip(table, rows):
        for key, text in r.items():
            v = t[key]
            if isinstance(v, float):
                assert v == float(text) or (math.isnan(v) and text == "nan")
            else:
                assert ("" if v is None else str(v)) == text


def test_sweep_report(serial_run, tmp_path):
    pytest.importorskip("matplotlib")
    from astrodyn.analysis.sweep import is_sweep_dir, sweep_report

    assert is_sweep_dir(serial_run) and not is_sweep_dir(tmp_path)
    rep = sweep_report(serial_run, tmp_path / "rep")
    rows = [r for r in _read(serial_run / "summary.csv") if r["status"] == "ok"]
    e = np.array([float(r["sat1.e_final"]) for r in rows])
    assert rep["ok"] == len(rows) and rep["failed"] == N - len(rows)
    assert rep["stats"]["sat1.e_final"]["mean"] == pytest.approx(e.mean(), rel=1e-15)  # same sum, maybe reordered
    assert "sat1.a_final" in rep["constant"]  # Kepler: a is kept to round-off
    # e_final follows the drawn e exactly, so its rank correlation with it is 1
    assert rep["correlations"]["bodies.sat1.orbit.e"]["sat1.e_final"] == 1.0
    for f in rep["figures"]:
        assert Path(f).stat().st_size > 10_000
    text = Path(rep["report"]).read_text()
    assert "| sat1.r_min | m |" in text and "## Failures" in text
    with pytest.raises(ValueError, match="summary.csv"):
        sweep_report(tmp_path)


def test_existing_scheduler_gives_the_serial_table(config, serial_run, tmp_path):
    distributed = pytest.importorskip("distributed")
    # a scheduler started elsewhere (here: in this process, one in-process worker thread)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cluster:
        address = cluster.scheduler_address
        rc = sweep.main(_argv(config, tmp_path, "--scheduler", address, "--chunk", "5"))
    assert rc == 1
    assert [_no_wall(r) for r in _read(tmp_path / "summary.csv")] == [_no_wall(r) for r in _read(serial_run / "summary.csv")]
    assert json.loads((tmp_path / "sweep.json").read_text())["scheduler"] == address


def test_unreachable_scheduler_is_a_clear_error(config, tmp_path, capsys, monkeypatch):
    pytest.importorskip("distributed")
    monkeypatch.setattr(sweep, "SCHEDULER_TIMEOUT_S", 2.0)
    from astrodyn.bus import free_port

    rc = sweep.main(_argv(config, tmp_path, "--scheduler", f"tcp://127.0.0.1:{free_port()}"))
    assert rc == 2
    assert "cannot reach a Dask scheduler" in capsys.readouterr().err
