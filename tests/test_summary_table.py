"""The end-of-run summary table of ``astrodyn run`` keeps its columns aligned whatever the
length of a body name (walk report F17: "comet-parabolic", 15 characters, ran into the kind
column) or of a quantity name.

The check is on the printed text only: in every line, each cell starts (left-aligned columns)
or ends (right-aligned: states, max drift) at the offset where the header's column does.
"""

from __future__ import annotations

import pytest

from astrodyn.scenario import loads
from astrodyn.service.summary import print_summary

SCENE = """
[scenario]
name = "names"
epoch = "2026-03-20T12:00:00 TDB"
duration = "10 s"
rate = "1 Hz"

[[bodies]]
name = "iss"
[bodies.orbit]
a = "7000 km"
"""

LEFT = ("body", "kind", "model", "conserved quantity", "unit", "relative to")
RIGHT = ("states", "max drift")


def _row(body: str, quantity: str = "E (two-body)", unit: str = "J/kg") -> dict:
    inv = [{"name": quantity, "unit": unit, "drift": 1.5e-15, "conserved": True, "scale": "|E0|", "initial": -1.0},
           {"name": "h", "unit": "m^2/s", "drift": 2.5e-16, "conserved": True, "scale": "|h0|", "initial": 1.0}]
    return {"body": body, "orbit_model": "kepler", "attitude_model": None, "orbit_states": 123456,
            "orbit_invariants": inv, "crosscheck_max_dr": 1.25e-3, "crosscheck_states": 11}


def _table(capsys, rows: list[dict], max_bodies: int = 25) -> tuple[str, list[str]]:
    print_summary({"out": "x.mcap", "wall_s": 1.0, "logger": {}}, rows, loads(SCENE), max_bodies=max_bodies)
    lines = capsys.readouterr().out.splitlines()
    k = next(i for i, line in enumerate(lines) if line.lstrip().startswith("body "))
    return lines[k], [ln for ln in lines[k + 1:] if not ln.lstrip().startswith("...")]


@pytest.mark.parametrize("name", ["iss", "comet-parabolic", "a-body-with-a-name-of-forty-characters-x", "b" * 128])
def test_every_column_starts_where_the_header_says(capsys, name):
    rows = [_row("iss"), _row(name), _row("x", quantity="none (a third body moves: no orbit invariant)", unit="-")]
    header, lines = _table(capsys, rows)
    starts = {col: header.index(col) for col in LEFT}
    ends = {col: header.index(col) + len(col) for col in RIGHT}
    seen = 0
    for line in lines:
        if line.startswith(" " * 2 + name) or line.startswith("  iss") or line.startswith("  x "):
            body = line.split()[0]
            assert line.index(body) == starts["body"], (line, header)
        for cell in ("orbit", "x-check"):
            if f" {cell} " in line:
                assert line.index(f" {cell} ") + 1 == starts["kind"], (line, header)
                seen += 1
        for cell, col in (("kepler", "model"), ("rebound-ias15", "model"), ("E (two-body)", "conserved quantity"),
                          ("none (a third body", "conserved quantity"), ("max |r - r_REBOUND|", "conserved quantity"),
                          ("J/kg", "unit"), ("m^2/s", "unit"), ("|E0|", "relative to"), ("absolute", "relative to")):
            if cell in line:
                assert line.index(cell) == starts[col], (cell, line, header)
        for cell, col in (("123456", "states"), ("1.5e-15", "max drift"), ("2.5e-16", "max drift"),
                          ("1.25e-03", "max drift")):
            if cell in line:
                assert line.index(cell) + len(cell) == ends[col], (cell, line, header)
    assert seen == 6  # an orbit and an x-check line per body


def test_the_worst_drift_lines_of_many_bodies_align_too(capsys):
    rows = [_row(f"comet-parabolic-{k:02d}") for k in range(30)]
    header, lines = _table(capsys, rows, max_bodies=25)
    all_lines = [ln for ln in lines if ln.lstrip().startswith("(all)")]
    assert all_lines
    for line in lines:  # the 20 bodies shown (18-character names), then the worst drift of the others
        if " orbit " not in line:
            continue
        assert line.index(" orbit ") + 1 == header.index("kind"), (line, header)
        drift = next(c for c in ("1.5e-15", "2.5e-16") if c in line)
        assert line.index(drift) + len(drift) == header.index("max drift") + len("max drift"), (line, header)
