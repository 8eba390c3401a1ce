"""Message types of the astrodyn bus and logs: keys, JSON Schemas, encode/decode.

One source for the Zenoh bus and the MCAP files (docs/architecture.md, sections 3 and 5). Pure Python
and numpy; no zenoh or mcap import, so every layer can use it.

Keys
----
Every message lives under ``astrodyn/<scenario>/``::

    astrodyn/<scenario>/<body>/orbit        OrbitState      (one channel per body)
    astrodyn/<scenario>/<body>/attitude     AttitudeState
    astrodyn/<scenario>/<body>/crosscheck   CrossCheck      (``--cross-check`` mode)
    astrodyn/<scenario>/<body>/appendages   AppendageState  (flexible spacecraft)
    astrodyn/<scenario>/<body>/rolling      RollingState    (rolling disk)
    astrodyn/<scenario>/<body>/gimbals      GimbalState     (single-axis gyroscopes on the body)
    astrodyn/<scenario>/@status             Status          (``serve``)
    astrodyn/<scenario>/@event              Event           (start, stop, restart, error ...)
    astrodyn/<scenario>/@control/<verb>     queryables      (status, pause, resume, rate, stop)
    astrodyn/<scenario>/@alive/<process>    liveliness tokens
    astrodyn/<scenario>/@batch/<process>    batch envelope  (see :func:`encode_batch`)
    astrodyn/<scenario>/@schema/<kind>      queryable: the JSON Schema of a message kind
    astrodyn/<scenario>/@latest             queryable: the newest state samples (envelope)

Scenario, body, process and verb names match ``[A-Za-z0-9_.-]{1,128}`` and are not
``.`` or ``..``: no ``/``, no Zenoh wildcards ``*``, ``**``, ``$*``, and never a leading
``@`` (which marks the special keys above). :func:`parse_key` returns
``(scenario, body_or_special, kind)``:

====================================  ===============================================
``astrodyn/s/sat1/orbit``             ``("s", "sat1", "orbit")``
``astrodyn/s/@status``                ``("s", "@status", "status")``
``astrodyn/s/@event``                 ``("s", "@event", "event")``
``astrodyn/s/@control/pause``         ``("s", "@control", "pause")``
``astrodyn/s/@alive/orbit``           ``("s", "@alive", "orbit")``
``astrodyn/s/@batch/orbit``           ``("s", "@batch", "orbit")``
``astrodyn/s/@schema/orbit``          ``("s", "@schema", "orbit")``
====================================  ===============================================

Payloads
--------
State messages are compact UTF-8 JSON objects (no spaces, keys in a fixed order), floats
written with Python's ``repr`` (the shortest string that round-trips to the same float64),
NaN and infinities rejected. Every object is described by a JSON Schema (draft 2020-12)
that the MCAP logger stores with the channel. Times ``t`` are seconds since the scenario
epoch, ``seq`` counts the messages of one channel from 0 without gaps. SI units: r in m,
v in m/s, mu in m^3/s^2, w in rad/s (body components), q = (e0, e1, e2, e3) scalar first
(Baruh ch. 7 Euler parameters, ``v_body = C(q) @ v_inertial``).

Each message type is one msgspec Struct (:data:`MESSAGE_TYPES`: :class:`OrbitState`,
:class:`AttitudeState`, :class:`CrossCheck`, :class:`Event`, :class:`Status`); its JSON
Schema (:func:`json_schema`, stored with every MCAP channel), :func:`validate` and
:func:`decode` (msgspec's typed decoder of the definition, its string patterns tested after
the decode: under 1 us per state message, docs/benchmarks.md) follow from it, plus the rules
a JSON Schema cannot state, each written once as the type's ``rule`` (e.g. ``|q| = 1``
within :data:`QUAT_NORM_TOL`, ``AttitudeState.rule``), which ``__post_init__`` and the
generated checks both call.  :func:`encode` writes the fields
in definition order with Python's float ``repr``, byte for byte what the compiled batch
encoders write: msgspec's encoder writes plain messages (its float text is ``repr``'s for
|x| < 1e-9 and 1e-4 <= |x| < 1e16; other floats are laid out as ``repr`` does), after a
check generated from the definition (:mod:`astrodyn.messages.codec`, "Plain messages");
anything else goes through ``json``, with the same bytes and errors.  :func:`check_state` reaches
the same verdict as :func:`decode` on the batch encoders' canonical layout with one
precompiled regex (the logger's hot path); it and the compiled formatter and ingest are
tested field by field against the definitions (tests/test_message_definitions.py).
Errors are :class:`MessageError` whose text names the field and what was expected, e.g.
``orbit.r: expected array of 3 finite numbers, got [1.0, "x"]``.

Modules
-------
:mod:`~astrodyn.messages.errors` (``MessageError``), :mod:`~astrodyn.messages.keys` (names,
kinds, keys), :mod:`~astrodyn.messages.definitions` (the Structs and their schemas),
:mod:`~astrodyn.messages.codec` (validate, decode, encode, builders),
:mod:`~astrodyn.messages.batch` (batch encoders and envelope),
:mod:`~astrodyn.messages.shortest` (the compiled float formatter); this package re-exports
every public name of them (docs/architecture.md, section 5).

Batch envelope
--------------
A publisher may send many per-body payloads in one Zenoh sample on
``astrodyn/<scenario>/@batch/<process>``; the receiver splits it back into
``(key, payload)`` pairs with :func:`decode_batch` and can write each payload to its own
MCAP channel without re-encoding. Binary layout, all integers little-endian unsigned::

    magic    4 bytes  b"ADB1"
    count    u32      number of entries
    entries  count x  { key_len u16, key (UTF-8, key_len bytes),
                        payload_len u32, payload (payload_len bytes) }

Nothing may follow the last entry. A publisher of many bodies can write the entries
directly: :func:`frame_orbit_batch` / :func:`frame_attitude_batch` (payloads and framing
in one compiled pass), :func:`frame_entries` for other pairs, :func:`batch_envelope` to
join them; the bytes equal :func:`encode_batch` of the same pairs.
"""

from __future__ import annotations

from astrodyn.messages.batch import (
    BATCH_MAGIC,
    FEW_BODIES,
    BatchKeys,
    batch_envelope,
    decode_batch,
    encode_attitude_batch,
    encode_batch,
    encode_orbit_batch,
    frame_attitude_batch,
    frame_entries,
    frame_orbit_batch,
)
from astrodyn.messages.codec import (
    FAST_CHECKS,
    attitude_message,
    check_state,
    checked_float,
    checked_floats,
    checked_int,
    crosscheck_message,
    decode,
    encode,
    event_message,
    is_valid,
    json_field,
    orbit_message,
    parse_json,
    status_message,
    validate,
)
from astrodyn.messages.definitions import (
    ATTITUDE_SCHEMA,
    CROSSCHECK_SCHEMA,
    EVENT_SCHEMA,
    KIND_OF_SCHEMA_TITLE,
    MAX_WHEELS,
    MESSAGE_TYPES,
    ORBIT_SCHEMA,
    SCHEMAS,
    STATUS_SCHEMA,
    ActuatorState,
    AppendageState,
    AttitudeState,
    Command,
    CrossCheck,
    Event,
    GimbalState,
    GpsSample,
    GyroSample,
    OrbitState,
    RollingState,
    Stamped,
    StarTrackerSample,
    Status,
    StepDone,
    TachometerSample,
    Tick,
    json_schema,
    schema_for_key,
)
from astrodyn.messages.errors import (
    MessageError,
    show_value,
)
from astrodyn.messages.keys import (
    ACTUATED_MODEL,
    ATTITUDE_MODELS,
    ATTITUDE_PROCESS_KINDS,
    CONTROL_KINDS,
    CROSSCHECK_MODELS,
    CROSSCHECK_REFERENCES,
    GIMBALS_KIND,
    MAX_SEQ,
    MESSAGE_KINDS,
    MODEL_STATE_KINDS,
    NAME_FULL_RE,
    NAME_PATTERN,
    ORBIT_MODELS,
    PREFIX,
    QUAT_NORM_TOL,
    RUN_PROCESS_NAMES,
    SENSOR_KINDS,
    STATE_KINDS,
    STATUS_STATES,
    alive_key,
    attitude_key,
    batch_key,
    body_key,
    check_name,
    control_key,
    crosscheck_key,
    done_key,
    event_key,
    is_run_process_name,
    kind_of_key,
    latest_key,
    orbit_key,
    parse_key,
    schema_key,
    status_key,
    tick_key,
)

__all__ = [
    "MessageError",
    "OrbitState",
    "AttitudeState",
    "AppendageState",
    "RollingState",
    "GimbalState",
    "CrossCheck",
    "Event",
    "Status",
    "MESSAGE_TYPES",
    "json_schema",
    "ORBIT_MODELS",
    "ATTITUDE_MODELS",
    "ORBIT_SCHEMA",
    "ATTITUDE_SCHEMA",
    "CROSSCHECK_SCHEMA",
    "EVENT_SCHEMA",
    "STATUS_SCHEMA",
    "SCHEMAS",
    "QUAT_NORM_TOL",
    "NAME_PATTERN",
    "check_name",
    "orbit_key",
    "attitude_key",
    "body_key",
    "tick_key",
    "done_key",
    "STATE_KINDS",
    "MODEL_STATE_KINDS",
    "GIMBALS_KIND",
    "ATTITUDE_PROCESS_KINDS",
    "CONTROL_KINDS",
    "SENSOR_KINDS",
    "ACTUATED_MODEL",
    "RUN_PROCESS_NAMES",
    "is_run_process_name",
    "Command",
    "ActuatorState",
    "GyroSample",
    "StarTrackerSample",
    "GpsSample",
    "TachometerSample",
    "Tick",
    "StepDone",
    "crosscheck_key",
    "control_key",
    "schema_key",
    "latest_key",
    "status_key",
    "alive_key",
    "event_key",
    "batch_key",
    "parse_key",
    "schema_for_key",
    "kind_of_key",
    "encode",
    "decode",
    "check_state",
    "FAST_CHECKS",
    "validate",
    "parse_json",
    "json_field",
    "is_valid",
    "orbit_message",
    "attitude_message",
    "crosscheck_message",
    "event_message",
    "status_message",
    "encode_orbit_batch",
    "encode_attitude_batch",
    "FEW_BODIES",
    "BatchKeys",
    "frame_orbit_batch",
    "frame_attitude_batch",
    "encode_batch",
    "frame_entries",
    "batch_envelope",
    "decode_batch",
    # shared by the modules of this package and by its users
    "BATCH_MAGIC",
    "checked_float",
    "checked_floats",
    "checked_int",
    "KIND_OF_SCHEMA_TITLE",
    "MAX_WHEELS",
    "Stamped",
    "show_value",
    "CROSSCHECK_MODELS",
    "CROSSCHECK_REFERENCES",
    "MAX_SEQ",
    "MESSAGE_KINDS",
    "NAME_FULL_RE",
    "PREFIX",
    "STATUS_STATES",
]
