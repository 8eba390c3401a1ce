"""Smoke test of ``astrodyn bench orbit --quick``: the table prints, every method has a row,
and astrodyn's error on the sample is within the stated floor (100 x the one-ulp sensitivity
of each state, against the 50-digit mpmath reference).  Timings are not asserted (the
machine is shared); the benchmark itself is a script, its numbers live in docs/bench-orbit.md."""

from __future__ import annotations

import re

from astrodyn.bench import main as bench_main
from astrodyn.bench.orbit import ACCURACY_TARGET


def test_bench_orbit_quick_prints_the_table_within_the_floor(capsys, tmp_path):
    md = tmp_path / "bench.md"
    rc = bench_main(["orbit", "--quick", "--markdown", str(md)])
    out = capsys.readouterr().out
    for row in ("astrodyn propagate", "astrodyn solve_kepler", "REBOUND IAS15", "REBOUND WHFast", "scipy DOP853"):
        assert row in out, f"missing row {row!r}"
    m = re.search(r"astrodyn max err/floor ([0-9.eE+-]+|nan|inf)", out)
    assert m, out
    assert float(m.group(1)) <= ACCURACY_TARGET
    assert rc == 0
    text = md.read_text()
    assert "| method |" in text and "Machine:" in text
