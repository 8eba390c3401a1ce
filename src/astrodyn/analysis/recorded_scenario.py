"""The scenario a recording was made from, read back from its ``scenario`` metadata record.

The analysis sections that need a body's config (wheel geometry, pointing target) ask this
module: the config is parsed once per recording, not once per body and section (a
1000-body scene's config parsed 1000 times was quadratic).  A foreign or damaged record
gives None: those sections are then left out, never a traceback.
"""

from __future__ import annotations

import functools
import json

__all__ = ["recorded_scenario", "recorded_body"]


@functools.lru_cache(maxsize=4)
def _parsed(text: str):
    from astrodyn.scenario import load_dict

    try:
        return load_dict(json.loads(text)["config"], source="recording")
    except Exception:  # a foreign or damaged scenario record
        return None


def recorded_scenario(scenario_meta: dict):
    """The :class:`astrodyn.scenario.Scenario` of a recording's ``scenario`` metadata
    (``run.scenario``), or None when it holds none that validates."""
    text = scenario_meta.get("json") if isinstance(scenario_meta, dict) else None
    return _parsed(text) if isinstance(text, str) else None


def recorded_body(scenario_meta: dict, name: str):
    """The config of body ``name`` (:class:`astrodyn.scenario.Body`), or None."""
    scenario = recorded_scenario(scenario_meta)
    if scenario is None:
        return None
    try:
        return scenario.body(name)
    except Exception:  # no such body in the record
        return None
