""""The same config" for ``run --resume``, ``run --commands`` and serve's restart is the same
simulation (probe A, F8): :func:`astrodyn.scenario.recorded.config_difference` compares
resolved values, so a quantity written another way ("0.01 kHz" for "10 Hz", "10 minutes" for
"600 s", "51.64 degrees" for "51.64 deg") is the same config, and what is not simulated (the
description, ``real_time_factor``) is not compared.  Before, these were refused as "another
config".

The spec: a re-simulation must be bit for bit, so two values are the same only if they
resolve to the same float; the expected equalities are checked on the unit definitions in
plain float arithmetic (0.01 * 1000 == 10.0, 10 * 60 == 600.0), and a pair that differs in
the last bit (0.07 h = 0.07 * 3600 s != 252 s) is another config.  A real difference is
still refused, naming the field with both values as written.
"""

from __future__ import annotations

from astrodyn.scenario import loads
from astrodyn.scenario.recorded import DURATION_PATHS, config_difference

TEMPLATE = """
[scenario]
name = "same"
{description}
epoch = "2026-03-20T12:00:00 UTC"
duration = {duration}
rate = {rate}
{real_time_factor}

[[bodies]]
name = "sat"
[bodies.orbit]
a = "7000 km"
e = 0.001
i = {i}
[bodies.attitude]
w = {w}
inertia = ["100 kg m2", "120 kg m2", "80 kg m2"]
"""

DEFAULTS = {"description": 'description = "a satellite"', "duration": '"600 s"', "rate": '"10 Hz"',
            "real_time_factor": "", "i": '"51.64 deg"', "w": '["0.1 rad/s", "0 rad/s", "0 rad/s"]'}


def _scenario(source: str = "here.toml", **changes):
    return loads(TEMPLATE.format(**(DEFAULTS | changes)), source=source)


def _difference(recorded_changes: dict, here_changes: dict, ignore: tuple = ()) -> str | None:
    """config_difference of the config with ``here_changes`` against a recording of the one
    with ``recorded_changes`` (its scenario metadata record)."""
    recorded = _scenario("recorded.toml", **recorded_changes).to_metadata()
    return config_difference(recorded, _scenario(**here_changes), ignore=ignore)


def test_a_quantity_written_another_way_is_the_same_config():
    assert 0.01 * 1000 == 10.0 and 10 * 60 == 600.0  # kHz and min are exact factors of these values
    pairs = [
        ({"rate": '"10 Hz"'}, {"rate": '"0.01 kHz"'}),
        ({"duration": '"600 s"'}, {"duration": '"10 minutes"'}),
        ({"duration": '"600 s"'}, {"duration": "600"}),  # a bare number is SI
        ({"i": '"51.64 deg"'}, {"i": '"51.64 degrees"'}),
        ({"w": '["0.1 rad/s", "0 rad/s", "0 rad/s"]'}, {"w": '"[0.1, 0, 0] rad/s"'}),  # a vector written two ways
        ({"w": '["0.1 rad/s", "0 rad/s", "0 rad/s"]'}, {"w": "[0.1, 0, 0]"}),
    ]
    for recorded, here in pairs:
        assert _difference(recorded, here) is None, (recorded, here)
        assert _difference(here, recorded) is None, (here, recorded)
    # all of them at once
    everything = {k: v for _, here in pairs for k, v in here.items()}
    assert _difference({}, everything) is None


def test_what_is_not_simulated_is_not_compared():
    assert _difference({}, {"description": 'description = "another text"'}) is None
    assert _difference({}, {"description": ""}) is None  # no description at all
    assert _difference({}, {"real_time_factor": "real_time_factor = 5"}) is None


def test_a_real_difference_is_named_with_both_values_as_written():
    problem = _difference({"rate": '"10 Hz"'}, {"rate": '"20 Hz"'})
    assert problem is not None and 'scenario.rate is "20 Hz" here, "10 Hz" in the recording' in problem, problem
    problem = _difference({"duration": '"600 s"'}, {"duration": '"601 s"'})
    assert problem is not None and 'scenario.duration is "601 s" here, "600 s" in the recording' in problem, problem
    problem = _difference({"duration": '"10 minutes"'}, {"duration": '"601 s"'})
    assert problem is not None and 'scenario.duration is "601 s" here, "10 minutes" in the recording' in problem, problem


def test_only_the_real_difference_is_named_beside_ones_written_differently():
    problem = _difference({"rate": '"10 Hz"', "i": '"51.64 deg"'}, {"rate": '"0.01 kHz"', "i": '"52 deg"'})
    assert problem is not None
    assert "scenario.rate" not in problem and "more)" not in problem, problem
    assert 'bodies[0].orbit.i is "52 deg" here, "51.64 deg" in the recording' in problem, problem


def test_values_are_compared_bit_for_bit_never_with_a_tolerance():
    assert 0.07 * 3600 != 252.0  # 0.07 h is not exactly 252 s in float64 (one ulp off)
    problem = _difference({"duration": '"252 s"'}, {"duration": '"0.07 h"'})
    assert problem is not None and 'scenario.duration is "0.07 h" here, "252 s" in the recording' in problem, problem


def test_commands_may_still_differ_in_duration_only():
    assert _difference({"duration": '"600 s"'}, {"duration": '"601 s"'}, ignore=DURATION_PATHS) is None
    problem = _difference({"rate": '"10 Hz"'}, {"rate": '"20 Hz"', "duration": '"601 s"'}, ignore=DURATION_PATHS)
    assert problem is not None and "scenario.rate" in problem and "duration" not in problem, problem
