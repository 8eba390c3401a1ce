"""A ``sensor_dropout``'s ``duration`` is bounded (docs/control.md, the fault table): at
most 250 yr, the longest scenario.  Before, ``duration = "1e308 s"`` passed ``astrodyn
validate`` and serve's ``fault`` verb, and the plant then died computing the dropout's
length in output steps (``ceil(duration * rate)``: ``OverflowError``), which ended a
closed-loop serve from one control query.  The bound keeps that count an exact integer at
the fastest rate (250 yr x 1 kHz = 7.8894e12 steps < 2**53).
"""

from __future__ import annotations

import math

import pytest

from _by_hand_controller import detumble_scene
from _scenes import fault_table
from astrodyn.scenario import ScenarioError, loads
from astrodyn.scenario.control import parse_fault, plant_bodies
from astrodyn.scenario.fields import Ctx

#: 250 Julian years in s (365.25 days of 86,400 s): the bound as docs/control.md states it
YEARS_250_S = 250 * 365.25 * 86400

def _config(duration: str) -> str:
    """The scene's TOML with the dropout's ``duration`` (quantity text)."""
    dropout = fault_table("0.5 s", "sensor_dropout", sensor="gyro", duration=duration)
    return detumble_scene("2 s", rate="1 kHz", period=None, controllers="[]", seed=None, faults=dropout, name="dropout")


def test_validate_refuses_a_dropout_longer_than_250_years_naming_the_field_and_the_range(tmp_path, capsys):
    from astrodyn.scenario import main as validate_main

    for duration in ("1e308 s", "251 yr", "-1 s", "0 s"):
        with pytest.raises(ScenarioError) as err:
            loads(_config(duration))
        assert "control.faults[0].duration: expected 0 < duration <= 250 yr" in str(err.value), err.value
    config = tmp_path / "dropout.toml"
    config.write_text(_config("1e308 s"))
    assert validate_main([str(config)]) == 2
    said = capsys.readouterr().err
    assert "control.faults[0].duration: expected 0 < duration <= 250 yr" in said and '"1e308 s"' in said, said


def test_serves_fault_verb_arguments_are_refused_by_the_same_parser():
    """serve's ``fault`` verb (and the plant's, which parses it again) read the arguments
    with ``parse_fault(Ctx("fault"), args, "fault", math.inf, plant_bodies(scenario), t=...)``."""
    scenario = loads(_config("1 s"))
    args = {"body": "sc", "fault": "sensor_dropout", "sensor": "gyro", "duration": "1e308 s"}
    with pytest.raises(ScenarioError) as err:
        parse_fault(Ctx("fault"), args, "fault", math.inf, plant_bodies(scenario), t=0.0)
    assert str(err.value).startswith("fault: fault.duration: expected 0 < duration <= 250 yr"), err.value
    args["duration"] = 1e308  # a bare number is seconds
    with pytest.raises(ScenarioError):
        parse_fault(Ctx("fault"), args, "fault", math.inf, plant_bodies(scenario), t=0.0)


def test_the_longest_allowed_dropout_at_the_fastest_rate_silences_the_sensor_for_that_many_steps():
    """250 yr at 1 kHz: the plant counts ceil(duration * rate) = 7,889,400,000,000 steps
    (exact in a float and an int) from the step it begins; the gyro is silent from there."""
    from astrodyn.plant import Plant

    scenario = loads(_config("250 yr"))
    assert scenario.control.faults[0].duration == YEARS_250_S
    fault = parse_fault(Ctx("fault"), {"body": "sc", "fault": "sensor_dropout", "sensor": "gyro",
                                       "duration": "250 yr"}, "fault", math.inf, plant_bodies(scenario), t=0.5)
    assert fault.duration == YEARS_250_S
    plant = Plant(scenario)
    sampled = []
    for k in range(0, 1000, 50):  # steps 0 .. 950 (t 0 .. 0.95 s); the dropout begins at step 500
        t = k / 1000
        plant.faults_at(t)
        sampled.append(any(kind == "gyro" for kind, _, _ in plant.sensor_samples(k, t)))
    assert sampled == [k < 500 for k in range(0, 1000, 50)]
    assert plant.bodies["sc"].faults.dropouts["gyro"] == 500 + 250 * 36525 * 86400 * 1000 // 100
