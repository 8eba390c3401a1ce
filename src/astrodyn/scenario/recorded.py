"""The scenario a recording was made from, as its ``scenario`` metadata record holds it:
whether that is a given config (:func:`config_difference`), and the config read back
(:func:`recorded_scenario`, :func:`recorded_body`).

The logger writes :meth:`astrodyn.scenario.Scenario.to_metadata` as the first metadata
record of every file it makes (``name``, ``json`` and a few strings; docs/architecture.md,
section 5).  Every place that asks "is this a recording of this config?" asks
:func:`config_difference`, so they agree on what "the same config" is:

- ``astrodyn run --resume REC`` (:func:`astrodyn.service.runner.resume_plan`),
- ``astrodyn run --commands REC`` (:func:`astrodyn.service.runner.check_command_recording`,
  which lets the duration differ: :data:`DURATION_PATHS`),
- ``astrodyn serve`` restarting a propagator from its rolled parts
  (:func:`astrodyn.service.supervision.holds_config`).

The same config read from another path (a copy, the file named another way) is the same
config: where it was read from and where it records (:data:`NOT_SIMULATED`) are not compared.
"""

from __future__ import annotations

import functools
import json
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from astrodyn.scenario import Scenario

__all__ = ["config_difference", "recorded_scenario", "recorded_body", "NOT_SIMULATED", "DURATION_PATHS",
           "MAX_DIFFERENCES_NAMED"]

#: Parts of a recording's "scenario" metadata (paths into its JSON) that do not describe what
#: is simulated: where the config file was read from (the same file named another way, or a
#: copy, is the same config) and where and in what parts it is recorded (the ``[output]``
#: table as written, and resolved: a relative path resolves against the config's directory).
NOT_SIMULATED = (("source",), ("output",), ("config", "output"))
#: ``--commands``: the duration, too, may differ: it says how far the re-simulation goes (the
#: run says where the recording ends, and counts what it holds past the config's duration).
DURATION_PATHS = (("duration",), ("n_steps",), ("config", "scenario", "duration"))
#: Differences named in a refusal (the rest are counted).
MAX_DIFFERENCES_NAMED = 3


def config_difference(recorded: dict | None, scenario: Scenario, ignore: tuple = ()) -> str | None:
    """None when the "scenario" metadata record ``recorded`` of a recording (str -> str, as the
    logger writes it) is ``scenario``'s: the same name and config (its ``json``, but for the
    paths of :data:`NOT_SIMULATED` and ``ignore``, tuples of keys into that JSON); else what
    differs, for a refusal: ``one of scenario 'x'``, or ``one of another config of 'x':
    scenario.rate is "5 Hz" here, "10 Hz" in the recording; ...`` (the config's own keys as
    written in its TOML first, the values resolved from them otherwise; at most
    :data:`MAX_DIFFERENCES_NAMED` named, the rest counted).  A record without ``json`` is
    compared by name only (as ``--resume`` always did)."""
    if not isinstance(recorded, dict) or recorded.get("name") is None:
        return "a file without the scenario metadata record (the config it ran)"
    if recorded.get("name") != scenario.name:
        return f"one of scenario {str(recorded.get('name'))[:100]!r}"
    text = recorded.get("json")
    if not text:
        return None
    try:
        theirs = json.loads(text)
    except (ValueError, TypeError, RecursionError) as exc:
        return f"one whose scenario metadata is not JSON ({type(exc).__name__})"
    ours = json.loads(scenario.to_metadata()["json"])
    skip = {*NOT_SIMULATED, *ignore}
    found: list[tuple[tuple, object, object]] = []
    _differences(ours.get("config"), theirs.get("config") if isinstance(theirs, dict) else None, ("config",), skip, found)
    if not found:  # the config as written is the same: what it resolves to (an included file, a newer astrodyn)
        mine = {k: v for k, v in ours.items() if k != "config"}
        other = {k: v for k, v in theirs.items() if k != "config"} if isinstance(theirs, dict) else theirs
        _differences(mine, other, (), skip, found)
    if not found:
        return None

    def shown(value) -> str:
        text = "nothing" if value is _ABSENT else json.dumps(value, default=str)
        return text if len(text) <= 60 else text[:57] + "..."

    def where(path: tuple) -> str:
        name = "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in path).lstrip(".")
        return name.removeprefix("config.") if path[:1] == ("config",) else f"{name or 'the scenario'} (resolved)"

    named = "; ".join(f"{where(path)} is {shown(here)} here, {shown(there)} in the recording"
                      for path, here, there in found[:MAX_DIFFERENCES_NAMED])
    more = f" (and {len(found) - MAX_DIFFERENCES_NAMED} more)" if len(found) > MAX_DIFFERENCES_NAMED else ""
    return f"one of another config of {scenario.name!r}: {named}{more}"


_ABSENT = object()
#: Depth of the metadata JSON compared key by key (deeper: compared whole).
_MAX_DEPTH = 32


def _differences(ours, theirs, path: tuple, skip: set, found: list) -> None:
    """Append ``(path, ours, theirs)`` for each leaf where ``theirs`` differs from ``ours``
    (dicts by key, lists of one length by index; a missing key is :data:`_ABSENT`);
    ``skip``: paths not compared."""
    if path in skip or ours == theirs:
        return
    if len(path) < _MAX_DEPTH and isinstance(ours, dict) and isinstance(theirs, dict):
        for key in [*ours, *(k for k in theirs if k not in ours)]:
            _differences(ours.get(key, _ABSENT), theirs.get(key, _ABSENT), (*path, key), skip, found)
    elif len(path) < _MAX_DEPTH and isinstance(ours, list) and isinstance(theirs, list) and len(ours) == len(theirs):
        for i, (a, b) in enumerate(zip(ours, theirs)):
            _differences(a, b, (*path, i), skip, found)
    else:
        found.append((path, ours, theirs))


# --------------------------------------------------------------------------- reading it back
# The analysis sections that need a body's config (wheel geometry, pointing target) ask
# here: the config is parsed once per recording, not once per body and section (a 1000-body
# scene's config parsed 1000 times was quadratic).  A foreign or damaged record gives None:
# those sections are then left out, never a traceback.


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
