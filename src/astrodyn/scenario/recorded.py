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

"The same config" is the same simulation: what is not simulated (:data:`NOT_SIMULATED`: where
the config was read from, where it records, its description, the pacing of serve) is not
compared, and a quantity written another way (``"0.01 kHz"`` for ``"10 Hz"``, ``"10 minutes"``
for ``"600 s"``, ``"51.64 degrees"`` for ``"51.64 deg"``) is the same where it resolves to the
same float, bit for bit (a re-simulation must be bit for bit).
"""

from __future__ import annotations

import functools
import json
import re
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from astrodyn.scenario import Scenario

__all__ = ["config_difference", "recorded_scenario", "recorded_body", "NOT_SIMULATED", "DURATION_PATHS",
           "MAX_DIFFERENCES_NAMED"]

#: Parts of a recording's "scenario" metadata (paths into its JSON) that do not describe what
#: is simulated: where the config file was read from (the same file named another way, or a
#: copy, is the same config), where and in what parts it is recorded (the ``[output]``
#: table as written, and resolved: a relative path resolves against the config's directory),
#: the scenario's description and ``real_time_factor`` (how fast ``astrodyn serve`` paces the
#: run, not what it computes), as written and resolved.
NOT_SIMULATED = (("source",), ("output",), ("config", "output"), ("description",), ("config", "scenario", "description"),
                 ("real_time_factor",), ("config", "scenario", "real_time_factor"))
#: ``--commands``: the duration, too, may differ: it says how far the re-simulation goes (the
#: run says where the recording ends, and counts what it holds past the config's duration).
DURATION_PATHS = (("duration",), ("n_steps",), ("config", "scenario", "duration"))
#: Differences named in a refusal (the rest are counted).
MAX_DIFFERENCES_NAMED = 3


def config_difference(recorded: dict | None, scenario: Scenario, ignore: tuple = ()) -> str | None:
    """None when the "scenario" metadata record ``recorded`` of a recording (str -> str, as the
    logger writes it) is ``scenario``'s: the same name and the same simulation (its ``json``,
    but for the paths of :data:`NOT_SIMULATED` and ``ignore``, tuples of keys into that JSON);
    else what differs, for a refusal: ``one of scenario 'x'``, or ``one of another config of
    'x': scenario.rate is "5 Hz" here, "10 Hz" in the recording; ...`` (the config's own keys
    with both values as written in its TOML first, the values resolved from them otherwise; at
    most :data:`MAX_DIFFERENCES_NAMED` named, the rest counted).  A record without ``json`` is
    compared by name only (as ``--resume`` always did).

    The configs are compared as written; where they differ only in how quantities are
    written, both are resolved (:func:`astrodyn.scenario.load_dict`, with
    :func:`~astrodyn.scenario.fields.quantities_read`) and such a quantity is the same when it
    resolves to the same SI float, bit for bit: ``"10 minutes"`` is ``"600 s"`` and ``"0.01
    kHz"`` is ``"10 Hz"`` (both give exactly 600.0 and 10.0), while ``"0.1 min"`` and ``"6 s"``
    are the same only if 0.1 * 60 gives the float 6.0 (floats are compared exactly, never
    with a tolerance: a re-simulation must be bit for bit).  Then what both resolve to (the
    recorded resolved values: an included file, a newer astrodyn) is compared the same way."""
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
    their_config = theirs.get("config") if isinstance(theirs, dict) else None
    _differences(ours.get("config"), their_config, ("config",), skip, found)
    if found:
        found = _not_written_differently(found, ours.get("config"), their_config)
    if not found:  # the same simulation as written: what it resolves to (an included file, a newer astrodyn)
        mine = {k: v for k, v in ours.items() if k != "config"}
        other = {k: v for k, v in theirs.items() if k != "config"} if isinstance(theirs, dict) else theirs
        _differences(mine, other, (), skip, found)
    if not found:
        return None

    def shown(value) -> str:
        text = "nothing" if value is _ABSENT else json.dumps(value, default=str)
        return text if len(text) <= 60 else text[:57] + "..."

    def where(path: tuple) -> str:
        return _key_path(path[1:]) if path[:1] == ("config",) else f"{_key_path(path) or 'the scenario'} (resolved)"

    named = "; ".join(f"{where(path)} is {shown(here)} here, {shown(there)} in the recording"
                      for path, here, there in found[:MAX_DIFFERENCES_NAMED])
    more = f" (and {len(found) - MAX_DIFFERENCES_NAMED} more)" if len(found) > MAX_DIFFERENCES_NAMED else ""
    return f"one of another config of {scenario.name!r}: {named}{more}"


_ABSENT = object()
#: Depth of the metadata JSON compared key by key (deeper: compared whole).
_MAX_DEPTH = 32
#: Deepest list a quantity is written as (an inertia tensor: a list of rows).
_QUANTITY_LIST_DEPTH = 2


def _key_path(path: tuple) -> str:
    """A path of keys as the loader names it in errors: ``("bodies", 0, "orbit", "a")`` ->
    ``"bodies[0].orbit.a"``."""
    return "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in path).lstrip(".")


def _same_number(a, b) -> bool:
    """``a == b`` for two JSON leaves, but numbers bit for bit: ``0.0`` and ``-0.0`` differ
    (600 and 600.0 are the same number)."""
    if a != b or isinstance(a, bool) != isinstance(b, bool):
        return False
    if isinstance(a, float) or isinstance(b, float):
        return isinstance(a, (int, float)) and isinstance(b, (int, float)) and float(a).hex() == float(b).hex()
    return True


def _same_json(a, b) -> bool:
    """``a`` and ``b`` equal as JSON, numbers bit for bit (a fast path: False may still be equal)."""
    try:
        return a == b and json.dumps(a) == json.dumps(b)
    except (TypeError, ValueError, RecursionError):
        return False


def _differences(ours, theirs, path: tuple, skip: set, found: list) -> None:
    """Append ``(path, ours, theirs)`` for each leaf where ``theirs`` differs from ``ours``
    (dicts by key, lists of one length by index; a missing key is :data:`_ABSENT`; numbers
    bit for bit, :func:`_same_number`); ``skip``: paths not compared."""
    if path in skip or _same_json(ours, theirs):
        return
    if len(path) < _MAX_DEPTH and isinstance(ours, dict) and isinstance(theirs, dict):
        for key in [*ours, *(k for k in theirs if k not in ours)]:
            _differences(ours.get(key, _ABSENT), theirs.get(key, _ABSENT), (*path, key), skip, found)
    elif len(path) < _MAX_DEPTH and isinstance(ours, list) and isinstance(theirs, list) and len(ours) == len(theirs):
        for i, (a, b) in enumerate(zip(ours, theirs)):
            _differences(a, b, (*path, i), skip, found)
    elif isinstance(ours, (dict, list)) or isinstance(theirs, (dict, list)) or not _same_number(ours, theirs):
        found.append((path, ours, theirs))


def _quantity_shaped(value, depth: int = 0) -> bool:
    """A config value a quantity may be written as: a number or a string, or a list of those
    (a vector, ``_QUANTITY_LIST_DEPTH`` deep at most)."""
    if isinstance(value, list):
        return depth < _QUANTITY_LIST_DEPTH and all(_quantity_shaped(v, depth + 1) for v in value)
    return isinstance(value, (str, int, float)) and not isinstance(value, bool)


_ELEMENT = re.compile(r"\[\d+\]$")
#: The body's name the loader adds to a key path in its errors (``bodies[0] (iss).orbit.a``).
_NAMED = re.compile(r"\] \([^)]*\)")


def _reads_by_key(config) -> dict[str, dict[str, list[tuple[str, float]]]] | None:
    """The quantities the loader reads from ``config`` (:func:`~astrodyn.scenario.fields.quantities_read`),
    by key path as the config writes it (``bodies[0].orbit.a``, without the body's name the
    loader adds for errors), indexed by each key path that holds them: ``"bodies[0].orbit.r"`` holds
    ``"bodies[0].orbit.r[0]"`` ... as well as ``"bodies[0].orbit.r"`` itself; None when the
    config does not load (a config of an older astrodyn: then compared as written)."""
    from astrodyn.scenario import load_dict
    from astrodyn.scenario.fields import quantities_read

    with quantities_read() as read:
        try:
            load_dict(config, source="recording")
        except Exception:  # any config the loader refuses, or a damaged record
            return None
    held: dict[str, dict[str, list[tuple[str, float]]]] = {}
    for named, values in read.items():
        key = holder = _NAMED.sub("]", named)
        while True:
            held.setdefault(holder, {})[key] = values
            shorter = _ELEMENT.sub("", holder)
            if shorter == holder:
                break
            holder = shorter
    return held


def _same_reads(mine: dict[str, list[tuple[str, float]]], theirs: dict[str, list[tuple[str, float]]]) -> bool:
    """The same quantities read, each of the same kind and bit for bit the same SI float."""
    return bool(mine) and mine.keys() == theirs.keys() and all(
        len(mine[k]) == len(theirs[k]) and all(ka == kb and float(a).hex() == float(b).hex()
                                               for (ka, a), (kb, b) in zip(mine[k], theirs[k]))
        for k in mine)


def _not_written_differently(found: list, ours_config, their_config) -> list:
    """The differences of ``found`` (:func:`_differences` of two configs as written) that are
    not one quantity written two ways: a difference is dropped when both sides are written
    (neither absent), are quantity-shaped, and the loader read from them, at that key path,
    the same quantities resolving to the same floats."""
    if not any(here is not _ABSENT and there is not _ABSENT and _quantity_shaped(here) and _quantity_shaped(there)
               for _, here, there in found):
        return found
    mine, theirs = _reads_by_key(ours_config), _reads_by_key(their_config)
    if mine is None or theirs is None:
        return found
    return [(path, here, there) for path, here, there in found
            if here is _ABSENT or there is _ABSENT or not (_quantity_shaped(here) and _quantity_shaped(there))
            or not _same_reads(mine.get(_key_path(path[1:]), {}), theirs.get(_key_path(path[1:]), {}))]


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
