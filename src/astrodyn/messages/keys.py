"""Names and keys of the astrodyn bus and logs (the table in :mod:`astrodyn.messages`), and the
model names a state message may carry."""

from __future__ import annotations

import re
from typing import Any

from astrodyn.messages.errors import MessageError

# ---------------------------------------------------------------------------------------
# Names and keys

#: Models a state message may name.  The scenario loader accepts the same names (plus
#: "none" for attitude, which publishes nothing).
ORBIT_MODELS: tuple[str, ...] = ("kepler", "j2", "zonal", "third_body", "actuated")
ATTITUDE_MODELS: tuple[str, ...] = ("torque_free", "gravity_gradient", "gyrostat", "heavy_top", "user", "flexible",
                                    "rolling_disk", "actuated")
#: The model name of a body moved by a closed loop (its actuators, commanded by controllers;
#: docs/control.md).  A state message may name it; a config may not (the plan picks it).
ACTUATED_MODEL = "actuated"
CROSSCHECK_REFERENCES: tuple[str, ...] = ("rebound-ias15",)
#: Orbit models the REBOUND cross-check can run (astrodyn.crosscheck's twin: point mass, point
#: mass + J2); a body of another model asked to be cross-checked is planned as not checked.
CROSSCHECK_MODELS: tuple[str, ...] = ("kepler", "j2")
STATUS_STATES: tuple[str, ...] = ("starting", "running", "paused", "stopping", "stopped", "error")

PREFIX = "astrodyn"
NAME_PATTERN = r"[A-Za-z0-9_.-]{1,128}"
#: a whole name (use ``.search``): ``^NAME_PATTERN$``
NAME_FULL_RE = re.compile(f"^{NAME_PATTERN}$")
#: Per-body kinds: states (one message per output step, ``seq`` = the step: orbit, attitude,
#: the REBOUND cross-check, a flexible spacecraft's appendages, a rolling disk's contact
#: state), then the closed loop's (docs/control.md): commands from controllers, actuator
#: states and sensor samples from the plant.
STATE_KINDS = ("orbit", "attitude", "crosscheck", "appendages", "rolling", "gimbals")
#: Attitude models whose state does not fit the attitude message alone: the kind of the
#: second state channel they publish, at the same seq (the rest of the state to resume from).
MODEL_STATE_KINDS = {"flexible": "appendages", "rolling_disk": "rolling"}
#: The kind of the channel of a body's single-axis gyroscopes (its ``gyros`` tables).
GIMBALS_KIND = "gimbals"
#: Per-body state kinds the attitude process publishes.
ATTITUDE_PROCESS_KINDS = ("attitude", *MODEL_STATE_KINDS.values(), GIMBALS_KIND)
CONTROL_KINDS = ("command", "actuators")
SENSOR_KINDS = ("gyro", "star_tracker", "gps", "tachometer")
_BODY_KINDS = STATE_KINDS + CONTROL_KINDS + SENSOR_KINDS
#: Every message kind, one per message type (:data:`astrodyn.messages.MESSAGE_TYPES` has these keys).
MESSAGE_KINDS = ("orbit", "attitude", "crosscheck", "appendages", "rolling", "gimbals", "event", "status",
                 "command", "actuators", "gyro", "star_tracker", "gps", "tachometer", "tick", "done")
_SPECIAL_WITH_NAME = ("@control", "@alive", "@batch", "@schema", "@done")
_SPECIAL_PLAIN = {"@status": "status", "@event": "event", "@latest": "latest", "@tick": "tick"}

#: The names a run's own processes publish and sign as (docs/security.md): the plant's
#: and the propagators' ``@batch/<process>`` envelopes carry states, never commands, and the
#: plant drops what is signed with its own name.  Standby loggers are ``logger-2``, ...
#: A controller may not take one of these names (:func:`is_run_process_name`).
RUN_PROCESS_NAMES = frozenset(("plant", "orbit", "attitude", "logger", "serve", "run"))


def is_run_process_name(name: str) -> bool:
    """True if ``name`` is one of :data:`RUN_PROCESS_NAMES` or a standby logger's (``logger-N``)."""
    return name in RUN_PROCESS_NAMES or re.fullmatch(r"logger-[0-9]+", name) is not None


#: |q| may differ from 1 by at most this much in a message (integrators keep |q| at
#: round-off, ~1e-15; JSON repr round-trips floats exactly, so 1e-9 only rejects garbage).
QUAT_NORM_TOL = 1e-9

#: Largest seq / integer accepted: 2**53 - 1, exact in every JSON reader (doubles).
MAX_SEQ = 2**53 - 1


def check_name(name: Any, what: str = "name") -> str:
    """Return ``name`` if it is a valid scenario/body/process name, else raise MessageError.

    Valid: 1-128 characters from ``[A-Za-z0-9_.-]``, not ``.`` or ``..``.
    """
    if not isinstance(name, str) or not NAME_FULL_RE.search(name) or name in (".", ".."):
        raise MessageError(f"{what}: expected a name matching {NAME_PATTERN} (not '.' or '..'), got {name!r}")
    return name


def orbit_key(scenario: str, body: str) -> str:
    """``astrodyn/<scenario>/<body>/orbit``."""
    return f"{PREFIX}/{check_name(scenario, 'scenario')}/{check_name(body, 'body')}/orbit"


def attitude_key(scenario: str, body: str) -> str:
    """``astrodyn/<scenario>/<body>/attitude``."""
    return f"{PREFIX}/{check_name(scenario, 'scenario')}/{check_name(body, 'body')}/attitude"


def crosscheck_key(scenario: str, body: str) -> str:
    """``astrodyn/<scenario>/<body>/crosscheck``."""
    return f"{PREFIX}/{check_name(scenario, 'scenario')}/{check_name(body, 'body')}/crosscheck"


def latest_key(scenario: str) -> str:
    """``astrodyn/<scenario>/@latest``: the logger's queryable answering with the newest
    authenticated state sample of every state key it received (one batch envelope of
    ``(key, payload)`` pairs, see :func:`encode_batch`), for views that must not take the
    full-rate streams."""
    return f"{PREFIX}/{check_name(scenario, 'scenario')}/@latest"


def schema_key(scenario: str, kind: str) -> str:
    """``astrodyn/<scenario>/@schema/<kind>``: a queryable answering with the JSON Schema of
    the messages of ``kind`` (orbit, attitude, crosscheck, event, status)."""
    if kind not in MESSAGE_KINDS:
        raise MessageError(f"kind: expected one of {', '.join(MESSAGE_KINDS)}, got {kind!r}")
    return f"{PREFIX}/{check_name(scenario, 'scenario')}/@schema/{kind}"


def control_key(scenario: str, verb: str) -> str:
    """``astrodyn/<scenario>/@control/<verb>`` (verbs: status, pause, resume, rate, stop)."""
    return f"{PREFIX}/{check_name(scenario, 'scenario')}/@control/{check_name(verb, 'verb')}"


def status_key(scenario: str) -> str:
    """``astrodyn/<scenario>/@status``."""
    return f"{PREFIX}/{check_name(scenario, 'scenario')}/@status"


def alive_key(scenario: str, process: str) -> str:
    """``astrodyn/<scenario>/@alive/<process>`` (liveliness token of one process)."""
    return f"{PREFIX}/{check_name(scenario, 'scenario')}/@alive/{check_name(process, 'process')}"


def event_key(scenario: str) -> str:
    """``astrodyn/<scenario>/@event``."""
    return f"{PREFIX}/{check_name(scenario, 'scenario')}/@event"


def batch_key(scenario: str, process: str) -> str:
    """``astrodyn/<scenario>/@batch/<process>`` (carries :func:`encode_batch` envelopes)."""
    return f"{PREFIX}/{check_name(scenario, 'scenario')}/@batch/{check_name(process, 'process')}"


def parse_key(key: Any) -> tuple[str, str, str]:
    """Split a key into ``(scenario, body_or_special, kind)``; see the module docstring.

    Raises MessageError for anything that is not an astrodyn key.
    """
    if not isinstance(key, str):
        raise MessageError(f"key: expected a string, got {type(key).__name__}")
    parts = key.split("/")
    bad = f"key: expected astrodyn/<scenario>/<body>/(orbit|attitude|crosscheck) or a special key, got {key!r}"
    if len(parts) < 3 or parts[0] != PREFIX:
        raise MessageError(bad)
    scenario = parts[1]
    check_name(scenario, "key scenario")
    second = parts[2]
    if len(parts) == 3 and second in _SPECIAL_PLAIN:
        return scenario, second, _SPECIAL_PLAIN[second]
    if len(parts) == 4 and second in _SPECIAL_WITH_NAME:
        return scenario, second, check_name(parts[3], f"key {second[1:]} name")
    if len(parts) == 4 and parts[3] in _BODY_KINDS:
        return scenario, check_name(second, "key body"), parts[3]
    raise MessageError(bad)


def kind_of_key(key: str) -> str | None:
    """Message kind for a key ("orbit", "attitude", "crosscheck", "event", "status", the
    closed loop's "command", "actuators", sensor kinds, "tick", "done"), else None."""
    _, who, kind = parse_key(key)
    if who == "@done":
        return "done"
    return None if who in _SPECIAL_WITH_NAME or who == "@latest" else kind


def body_key(scenario: str, body: str, kind: str) -> str:
    """``astrodyn/<scenario>/<body>/<kind>`` for any per-body kind (states, ``command``,
    ``actuators``, sensors: :data:`STATE_KINDS`, :data:`CONTROL_KINDS`, :data:`SENSOR_KINDS`)."""
    if kind not in _BODY_KINDS:
        raise MessageError(f"kind: expected one of {', '.join(_BODY_KINDS)}, got {kind!r}")
    return f"{PREFIX}/{check_name(scenario, 'scenario')}/{check_name(body, 'body')}/{kind}"


def tick_key(scenario: str) -> str:
    """``astrodyn/<scenario>/@tick``: the plant's "step k is out" (closed loop, docs/control.md)."""
    return f"{PREFIX}/{check_name(scenario, 'scenario')}/@tick"


def done_key(scenario: str, controller: str) -> str:
    """``astrodyn/<scenario>/@done/<controller>``: a controller's answer to a control step."""
    return f"{PREFIX}/{check_name(scenario, 'scenario')}/@done/{check_name(controller, 'controller')}"
