"""A number written in digit groups ("5 400 s", SI style) is refused, never multiplied
(probe A, F4), and a unit of the wrong kind is named in the error (F12).

astropy reads "5 400 s" as 5 x (a unit 400 s long) = 2000 s, "6 378.137 km" as 2268.822 km
and "90 2 min" as 10800 s: every such value was silently wrong.  A unit part that starts with
a number is now refused with the reason and the number written without spaces.  Units that
contain digits (exponents: "m3/s2", "rad s-1"; 1 over a unit: "1/s") keep working.

Expected values are the physical definitions (1 km = 1000 m, 1 min = 60 s, 1 deg = pi/180
rad), not outputs of the parser.
"""

from __future__ import annotations

import math

import pytest

from astrodyn.scenario import ScenarioError, loads
from astrodyn.scenario.fields import Ctx, parse_quantity_string, quantity, scaled_unit_number

DEG = math.pi / 180

# text, kind, the number after the value, the value written without spaces and its SI value by hand
DIGIT_GROUPS = [
    ("5 400 s", "time", "400", "5400 s", 5400.0),
    ("6 378.137 km", "length", "378.137", "6378.137 km", 6378.137 * 1000),
    ("90 2 min", "time", "2", "902 min", 902 * 60.0),
    ("7 000 km", "length", "000", "7000 km", 7.0e6),
    ("1 2 s", "time", "2", "12 s", 12.0),
    ("3.141 592 rad", "angle", "592", "3.141592 rad", 3.141592),
    ("7 500 m/s", "speed", "500", "7500 m/s", 7500.0),
]


@pytest.mark.parametrize(("text", "kind", "number", "joined", "si"), DIGIT_GROUPS)
def test_digit_groups_are_refused_with_the_number_written_without_spaces(text, kind, number, joined, si):
    reason = parse_quantity_string(text, kind)
    assert isinstance(reason, str), f"{text!r} was read as {reason!r}"
    value = text.split()[0]
    assert reason.startswith(f'a number after the value ("{number}" after "{value}")'), reason
    assert f'write numbers without spaces between digit groups, e.g. "{joined}"' in reason, reason
    assert parse_quantity_string(joined, kind) == pytest.approx(si, rel=1e-15)  # the hint is the meant value


@pytest.mark.parametrize(("text", "kind", "number"), [
    ("5 -3 s", "time", "-3"), ("5 +400 s", "time", "+400"), ("5 .4 s", "time", ".4"), ("5 1e3 s", "time", "1e3"),
    ("1e3 400 s", "time", "400"), ("5 1", "dimensionless", "1"),
])
def test_any_number_after_the_value_is_refused(text, kind, number):
    """A sign, an exponent or a second decimal point: no digit-group hint that would be wrong."""
    reason = parse_quantity_string(text, kind)
    assert isinstance(reason, str), f"{text!r} was read as {reason!r}"
    assert f'a number after the value ("{number}" after ' in reason, reason


@pytest.mark.parametrize(("text", "kind", "si"), [
    ("3 m3/s2", "gm", 3.0),
    ("398600.4418 km3 / s2", "gm", 398600.4418e9),
    ("10 1/s", "frequency", 10.0),
    ("10 1 / s", "frequency", 10.0),
    ("1/s", "frequency", 1.0),
    ("1/min", "frequency", 1 / 60),
    ("2 rad s-1", "angular_velocity", 2.0),
    ("5 deg/s", "angular_velocity", 5 * DEG),
    ("3 degrees per second", "angular_velocity", 3 * DEG),
    ("7.5 km per s", "speed", 7500.0),
    ("1e3 km", "length", 1.0e6),
    ("2.5E-3 km", "length", 2.5),
    ("100 kg m2", "inertia", 100.0),
    ("9.81 m/s2", "acceleration", 9.81),
    ("5400s", "time", 5400.0),
])
def test_units_with_digits_still_parse(text, kind, si):
    assert parse_quantity_string(text, kind) == pytest.approx(si, rel=1e-15)


@pytest.mark.parametrize(("unit", "number"), [
    ("400 s", "400"), ("  378.137 km", "378.137"), ("000 km", "000"), ("-3 s", "-3"), ("1e3 s", "1e3"), ("1 s", "1"),
    ("1/s", None), ("1 / s", None), ("m3/s2", None), ("km", None), ("", None), ("rad s-1", None),
])
def test_scaled_unit_number(unit, number):
    assert scaled_unit_number(unit) == number


CONFIG = """
[scenario]
name = "groups"
epoch = "2026-03-20T12:00:00 UTC"
duration = {duration}
rate = "1 Hz"

[[bodies]]
name = "sat"
[bodies.orbit]
a = {a}
e = 0.001
"""


@pytest.mark.parametrize(("duration", "a", "field", "shown"), [
    ('"5 400 s"', '"7000 km"', "scenario.duration", '"5 400 s"'),
    ('"90 2 min"', '"7000 km"', "scenario.duration", '"90 2 min"'),
    ('"60 s"', '"7 000 km"', "bodies[0] (sat).orbit.a", '"7 000 km"'),
    ('"60 s"', '"6 978.137 km"', "bodies[0] (sat).orbit.a", '"6 978.137 km"'),
])
def test_a_config_with_digit_groups_is_refused_naming_the_field(duration, a, field, shown):
    with pytest.raises(ScenarioError) as info:
        loads(CONFIG.format(duration=duration, a=a), source="groups.toml")
    msg = str(info.value)
    assert msg.startswith(f"groups.toml: {field}: expected "), msg
    assert "a number after the value" in msg and "without spaces between digit groups" in msg, msg
    assert msg.endswith(f"got {shown}"), msg


def test_the_same_config_without_spaces_loads_at_the_value_meant():
    sc = loads(CONFIG.format(duration='"5400 s"', a='"6978.137 km"'), source="groups.toml")
    assert sc.duration == 5400.0
    assert sc.bodies[0].orbit.elements["a"] == pytest.approx(6978.137e3, rel=1e-15)


@pytest.mark.parametrize(("text", "kind", "got"), [
    ("90 kg", "time", "a quantity in kg"),
    ("1 per minutes per sec", "frequency", "a quantity in 1 / s2"),  # 1 / (60 s * s): per second squared
    ("5 per s per s", "frequency", "a quantity in 1 / s2"),
    ("7000", "length", "a number without a unit"),
])
def test_the_wrong_kind_is_named(text, kind, got):
    assert parse_quantity_string(text, kind) == got
    with pytest.raises(ScenarioError) as info:
        quantity(Ctx("f.toml"), text, kind, "scenario.x")
    assert f"(got {got}), got {text!r}".replace("'", '"') in str(info.value), str(info.value)


def test_an_unknown_word_among_known_ones_is_still_an_unknown_unit():
    reason = parse_quantity_string("1 per minutes per secx", "frequency")
    assert reason.startswith('unknown unit "secx"'), reason


@pytest.mark.parametrize("text, kind, number", [("10 1/60 s", "frequency", "60"), ("5 m / 2 s", "speed", "2")])
def test_a_number_inside_the_unit_is_named_not_called_an_unknown_unit(text, kind, number):
    """Probe D (D7): ``"10 1/60 s"`` was refused as 'unknown unit "1/60 s"', though every word
    of it is a unit: the number inside is what astropy's grammar does not take."""
    from astrodyn.scenario.fields import parse_quantity_string

    why = parse_quantity_string(text, kind)
    assert isinstance(why, str) and why.startswith(f'a number inside the unit ("{number}"'), why
