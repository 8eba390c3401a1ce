"""Common English unit spellings in a config (walk report F21): "93 minutes", "5580 sec",
"51.64 degrees", "0.06 deg/sec" are taken at their physical value; a unit symbol in the wrong
letter case ("6795 KM") is refused (SI symbols are case-sensitive: mm and Mm differ by 10^9),
with a hint and the accepted units of the field's kind.

Expected values are the physical definitions (1 min = 60 s, 1 deg = pi/180 rad, ...), not
outputs of the parser.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from astrodyn.scenario import ScenarioError, load, load_dict
from astrodyn.scenario.fields import QUANTITY_KINDS, Ctx, parse_quantity_string, quantity

ROOT = Path(__file__).resolve().parents[1]
DEG = math.pi / 180


@pytest.mark.parametrize(("text", "kind", "si"), [
    ("93 minutes", "time", 93 * 60.0),
    ("5580 sec", "time", 5580.0),
    ("5580 secs", "time", 5580.0),
    ("5580 seconds", "time", 5580.0),
    ("1.55 hours", "time", 1.55 * 3600),
    ("2 HOURS", "time", 7200.0),
    ("3 days", "time", 3 * 86400.0),
    ("93 Minutes", "time", 93 * 60.0),
    ("51.64 degrees", "angle", 51.64 * DEG),
    ("2 radians", "angle", 2.0),
    ("0.06 deg/sec", "angular_velocity", 0.06 * DEG),
    ("3 degrees per second", "angular_velocity", 3 * DEG),
    ("7.5 km per s", "speed", 7500.0),
    ("7.5 kilometers/sec", "speed", 7500.0),
    ("6795 kilometres", "length", 6.795e6),
    ("12 meters", "length", 12.0),
    ("12 metres", "length", 12.0),
])
def test_english_spellings_are_taken_at_their_physical_value(text, kind, si):
    assert quantity(Ctx("t"), text, kind, "x") == pytest.approx(si, rel=1e-15)


def test_a_vector_string_takes_the_words_too():
    from astrodyn.scenario.fields import vector

    assert list(vector(Ctx("t"), "[7000, 0, 0] kilometers", "length", 3, "r")) == [7.0e6, 0.0, 0.0]


def test_symbols_keep_their_case_sensitive_si_meaning():
    assert parse_quantity_string("1 mm", "length") == pytest.approx(1e-3)
    assert parse_quantity_string("1 Mm", "length") == pytest.approx(1e6)
    assert parse_quantity_string("1 ms", "time") == pytest.approx(1e-3)
    assert parse_quantity_string("1 Ms", "time") == pytest.approx(1e6)
    assert parse_quantity_string("51.64 seconds", "angle") == "a quantity in s"  # a time is not an angle


@pytest.mark.parametrize(("text", "kind", "hint"), [("6795 KM", "length", "km"), ("10 HZ", "frequency", "Hz"),
                                                     ("10 hz", "frequency", "Hz")])
def test_a_symbol_in_the_wrong_case_is_refused_with_a_hint(text, kind, hint):
    from astrodyn.scenario.fields import KIND_UNITS

    with pytest.raises(ScenarioError) as info:
        quantity(Ctx("demo.toml"), text, kind, "bodies[0].orbit.a")
    msg = str(info.value)
    assert msg.startswith(f"demo.toml: bodies[0].orbit.a: expected {QUANTITY_KINDS[kind][1]} (unknown unit "), msg
    assert f'did you mean "{hint}"?' in msg and msg.endswith(f'got "{text}"'), msg
    assert "accepted: " + ", ".join(KIND_UNITS[kind]) in msg, msg


def test_an_unknown_unit_lists_the_accepted_units_of_the_kind():
    with pytest.raises(ScenarioError) as info:
        quantity(Ctx("demo.toml"), "93 fortnights", "time", "scenario.duration")
    msg = str(info.value)
    assert 'unknown unit "fortnights"' in msg and "accepted: s, ms, min, h, d, yr" in msg, msg
    assert "minutes" in msg and "seconds" in msg and "hours" in msg, msg  # the words too
    assert "\n" not in msg


@pytest.mark.parametrize("kind", [k for k in QUANTITY_KINDS if k != "dimensionless"])
def test_every_listed_unit_is_one_of_its_kind(kind):
    from astrodyn.scenario.fields import KIND_UNITS, units

    assert KIND_UNITS[kind]

    u = units()
    si = u.Unit(QUANTITY_KINDS[kind][0])
    for name in KIND_UNITS[kind]:
        assert isinstance(parse_quantity_string(f"1 {name}", kind), float), (kind, name)
        assert u.Unit(name).is_equivalent(si), (kind, name)


def _demo_with(duration, a, i) -> dict:
    """configs/demo.toml's config with the scenario duration and the ISS's a and i replaced."""
    base = load(ROOT / "configs" / "demo.toml").config
    bodies = [dict(b) for b in base["bodies"]]
    iss = next(b for b in bodies if b["name"] == "iss")
    iss["orbit"] = {**iss["orbit"], "a": a, "i": i}
    return {**base, "scenario": {**base["scenario"], "duration": duration}, "bodies": bodies}


def _iss_state(sc):
    orbit = next(b for b in sc.bodies if b.name == "iss").orbit
    return [*orbit.r0, *orbit.v0]


def test_the_walk_report_edits_of_demo_toml_load():
    """The walk's edits of configs/demo.toml validate as a whole config, at the values the same
    config gives in bare SI numbers (5580 s, 6.795e6 m, 51.64 pi/180 rad)."""
    words = load_dict(_demo_with("93 minutes", "6795 kilometers", "51.64 degrees"), source="w",
                      base_dir=str(ROOT / "configs"))
    si = load_dict(_demo_with(5580.0, 6.795e6, 51.64 * DEG), source="si", base_dir=str(ROOT / "configs"))
    assert words.duration == si.duration == 5580.0
    assert _iss_state(words) == pytest.approx(_iss_state(si), rel=1e-14, abs=1e-6)


def test_a_sweep_unit_may_be_a_word():
    """``--vary ... degrees``: the sweep's unit check takes the words the loader takes."""
    from astrodyn.sweep import make_spec

    spec = make_spec(ROOT / "configs" / "demo.toml", ["bodies.iss.orbit.i=51.64 degrees"], n=1)
    config, _ = spec.case_config(0)
    case = load_dict(config, source="case", base_dir=str(ROOT / "configs"))
    si = load_dict(_demo_with("93 min", 6.795e6, 51.64 * DEG), source="si", base_dir=str(ROOT / "configs"))
    assert _iss_state(case) == pytest.approx(_iss_state(si), rel=1e-14, abs=1e-6)
