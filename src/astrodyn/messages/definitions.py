"""The message types, each defined once as a msgspec Struct, and the JSON Schemas that follow
from them (stored with every MCAP channel; docs/architecture.md, section 5)."""

from __future__ import annotations

import math
from typing import Annotated, Any, Literal

import msgspec
import msgspec.inspect
from msgspec import Meta

from astrodyn.messages.keys import (
    ATTITUDE_MODELS,
    CROSSCHECK_REFERENCES,
    MAX_SEQ,
    NAME_PATTERN,
    ORBIT_MODELS,
    QUAT_NORM_TOL,
    STATUS_STATES,
    kind_of_key,
)

# ---------------------------------------------------------------------------------------
# Message types: each defined once, as a msgspec Struct.  Its JSON Schema (stored in the
# MCAP files), its validation and decoding all follow from this definition; encoding keeps
# the field order of the definition and Python's float repr (see :func:`encode`).

_SEQ_DESCRIPTION = "message counter of this channel: 0, 1, 2, ... without gaps"
_T = Annotated[float, Meta(description="time since the scenario epoch, s")]
_Seq = Annotated[int, Meta(ge=0, le=MAX_SEQ, description=_SEQ_DESCRIPTION)]
_NAME_META = dict(pattern=f"^{NAME_PATTERN}$", max_length=128)


def _vec(n: int, description: str) -> Any:
    return Annotated[list[float], Meta(min_length=n, max_length=n, description=description)]


def _enum(values: tuple[str, ...], description: str | None = None) -> Any:
    """One of ``values``; error messages list them in this order (msgspec sorts them)."""
    return Annotated[Literal[values], Meta(description=description, extra={"values": values})]


def _name(description: str, what: str) -> Any:
    return Annotated[str, Meta(**_NAME_META, description=description, extra={"expected": f"{what} matching {NAME_PATTERN}"})]


_DETAIL = Annotated[str, Meta(max_length=4096, description="human-readable detail",
                              extra={"expected": "a string of at most 4096 characters"})]


# Rules the field types cannot state (|q| = 1, equal lengths, ...) are each written once, as
# the message type's static method ``rule``: its parameters are fields of the type, it
# returns the problem (the error text) or None.  ``__post_init__`` raises it (msgspec's
# decoding and construction); the checks generated from the definition
# (:mod:`astrodyn.messages.codec`) call the same function on the values, without building
# the Struct.  A type with ``__post_init__`` but no ``rule`` is checked by building it.


_sqrt = math.sqrt


def _unit_quaternion_problem(q: list[float], field: str) -> str | None:
    """The rule of every quaternion a message carries (Euler parameters, dimensionless):
    None when | |q| - 1 | <= :data:`QUAT_NORM_TOL`, else the error text naming ``field``."""
    q0, q1, q2, q3 = q
    norm = _sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
    if abs(norm - 1.0) <= QUAT_NORM_TOL:
        return None
    return f"{field}: expected a unit quaternion (| |q| - 1 | <= {QUAT_NORM_TOL:g}), got |q| = {norm!r}"


def _enforce(problem: str | None) -> None:
    """``__post_init__``'s half of a ``rule``: raise its problem (msgspec reports a ValueError
    raised in ``__post_init__`` as a ValidationError with this text)."""
    if problem is not None:
        raise ValueError(problem)


def _unequal_lengths(kind: str, per: str, **fields: list) -> str | None:
    """The rule of a message whose list ``fields`` hold one entry per item (an appendage, a
    gyroscope): None when they are all as long, else the error text naming them and ``per``."""
    lengths = [len(x) for x in fields.values()]
    if len(set(lengths)) <= 1:
        return None
    *first, last = fields
    return f"{kind}: expected {', '.join(first)} and {last} for the same {per}, got {', '.join(map(str, lengths))}"


class Stamped(msgspec.Struct, forbid_unknown_fields=True):
    """The fields every message type starts with: ``t`` (s since the scenario epoch) and
    ``seq`` (the message's number on its channel)."""

    t: _T
    seq: _Seq


class OrbitState(Stamped, forbid_unknown_fields=True):
    """Translational state of one body relative to the central body, SI units."""

    model: _enum(ORBIT_MODELS, "model that produced the state")
    r: _vec(3, "position, m, in `frame`")
    v: _vec(3, "velocity, m/s, in `frame`")
    mu: Annotated[float, Meta(gt=0, description="gravitational parameter, m^3/s^2")]
    frame: _name("inertial frame of r and v, e.g. GCRF", "a frame name")


class AttitudeState(Stamped, forbid_unknown_fields=True):
    """Rotational state of one body: Euler parameters q = (e0, e1, e2, e3), scalar first, unit norm, v_body = C(q) v_inertial (Baruh ch. 7); w body angular velocity in body axes."""

    model: _enum(ATTITUDE_MODELS, "model that produced the state")
    q: _vec(4, "Euler parameters, scalar first, |q| = 1")
    w: _vec(3, "angular velocity in body axes, rad/s")

    @staticmethod
    def rule(q: list[float]) -> str | None:
        """|q| = 1: a rule a JSON Schema cannot state (see the note above :class:`Stamped`)."""
        return _unit_quaternion_problem(q, "attitude.q")

    def __post_init__(self) -> None:
        _enforce(self.rule(self.q))


#: Most appendages of one flexible spacecraft, and assumed modes per bending plane.
MAX_APPENDAGES = 32
MAX_MODES = 24
_PerAppendage = Annotated[list[float], Meta(min_length=2, max_length=2 * MAX_MODES)]


class AppendageState(Stamped, forbid_unknown_fields=True):
    """Elastic state of a flexible spacecraft's appendages at t (Baruh ch. 11; the model of
    astrodyn.attitude.flexible): per appendage, in the order of the config, its assumed-mode
    coordinates (the n modes of bending along its normal f, then the n along g = e x f, m),
    their rates (m/s) and the displacement of its tip from the undeformed position (body
    axes, m).  The hub's attitude is on the body's attitude key at the same seq."""

    eta: Annotated[list[_PerAppendage], Meta(min_length=1, max_length=MAX_APPENDAGES, description=(
        "per appendage: modal coordinates, bending along f (n values) then along g (n values), m"))]
    eta_dot: Annotated[list[_PerAppendage], Meta(min_length=1, max_length=MAX_APPENDAGES, description=(
        "per appendage: rates of the modal coordinates, same layout as eta, m/s"))]
    tip: Annotated[list[_vec(3, "tip displacement, body axes, m")], Meta(
        min_length=1, max_length=MAX_APPENDAGES, description="per appendage: tip displacement, body axes, m")]

    @staticmethod
    def rule(eta: list[list[float]], eta_dot: list[list[float]], tip: list[list[float]]) -> str | None:
        """Rules a JSON Schema cannot state (see the note above :class:`Stamped`)."""
        if problem := _unequal_lengths("appendages", "number of appendages", eta=eta, eta_dot=eta_dot, tip=tip):
            return problem
        for k, (eta_k, eta_dot_k) in enumerate(zip(eta, eta_dot)):
            if len(eta_k) % 2 or len(eta_dot_k) != len(eta_k):
                return (f"appendages.eta[{k}]: expected 2 n values (n modes in each bending plane) and as "
                        f"many in eta_dot[{k}], got {len(eta_k)} and {len(eta_dot_k)}")
        return None

    def __post_init__(self) -> None:
        _enforce(self.rule(self.eta, self.eta_dot, self.tip))


class RollingState(Stamped, forbid_unknown_fields=True):
    """State of a disk rolling without slipping on the horizontal plane z = 0 (Baruh 10.6;
    the model of astrodyn.attitude.rolling_disk): the contact point, the centre, the angles
    of the body-axis sequence 312 (heading psi about the vertical, lean theta, spin phi) and
    Kane's generalized speeds u = (theta', psi' sin theta + phi', psi' cos theta).  The
    disk's attitude is on the body's attitude key at the same seq."""

    contact: _vec(2, "contact point (x, y) on the plane, m")
    center: _vec(3, "position of the disk's centre, m")
    heading: Annotated[float, Meta(description="heading psi: direction of the contact point's path from x, rad")]
    lean: Annotated[float, Meta(description="lean theta from the vertical, rad (0 upright)")]
    spin_angle: Annotated[float, Meta(description="spin angle phi about the symmetry axis, rad")]
    u: _vec(3, "generalized speeds (theta', psi' sin theta + phi', psi' cos theta), rad/s")


#: Most single-axis gyroscopes on one body.
MAX_GYROS = 16
_PerGyro = Annotated[list[float], Meta(min_length=1, max_length=MAX_GYROS)]


class GimbalState(Stamped, forbid_unknown_fields=True):
    """The single-axis gyroscopes mounted on a body (Baruh 10.7.3; astrodyn.attitude.gyroscopes),
    in the order of the config: each one's gimbal (output) angle, its rate, and what the
    instrument indicates from it -- a rate gyro the input rate k theta / H (rad/s), a
    rate-integrating gyro the input angle c theta / H (rad)."""

    angle: Annotated[_PerGyro, Meta(description="gimbal (output) angle of each gyroscope, rad")]
    angle_rate: Annotated[_PerGyro, Meta(description="rate of each gimbal angle, rad/s")]
    indicated: Annotated[_PerGyro, Meta(description=(
        "each gyroscope's indication: rate gyro k theta / H (rad/s), rate-integrating gyro c theta / H (rad)"))]

    @staticmethod
    def rule(angle: list[float], angle_rate: list[float], indicated: list[float]) -> str | None:
        """A rule a JSON Schema cannot state (see the note above :class:`Stamped`)."""
        return _unequal_lengths("gimbals", "gyroscopes", angle=angle, angle_rate=angle_rate, indicated=indicated)

    def __post_init__(self) -> None:
        _enforce(self.rule(self.angle, self.angle_rate, self.indicated))


class CrossCheck(Stamped, forbid_unknown_fields=True):
    """astrodyn state minus the reference integrator's state for one body."""

    dr: _vec(3, "position difference, m")
    dv: _vec(3, "velocity difference, m/s")
    dr_norm: Annotated[float, Meta(ge=0, description="|dr|, m")]
    dv_norm: Annotated[float, Meta(ge=0, description="|dv|, m/s")]
    reference: _enum(CROSSCHECK_REFERENCES, "reference integrator")


class Event(Stamped, forbid_unknown_fields=True):
    """Something that happened to a process of the run (start, restart, stop, error, ...)."""

    seq: Annotated[int, Meta(ge=0, le=MAX_SEQ, description=(
        "message counter of the sending process on this channel: 0, 1, 2, ... without gaps for each "
        "process (the event channel carries the events of every process of the run)"))]

    process: _name("process name, e.g. orbit, attitude, logger, runner", "a process name")
    kind: Annotated[str, Meta(pattern="^[a-z][a-z_]{0,31}$", max_length=32,
                              description="start, restart, stop, error, pause, resume, rate, gap, ... (lower case)",
                              extra={"expected": "a lower-case word matching ^[a-z][a-z_]{0,31}$"})]
    detail: _DETAIL


class Status(Stamped, forbid_unknown_fields=True, omit_defaults=True):
    """State of a running `serve` (also the reply of the status queryable); ``t`` is the
    simulation time reached."""

    state: _enum(STATUS_STATES)
    real_time_factor: Annotated[float, Meta(ge=0, description="sim seconds per wall second")]
    rate: Annotated[float, Meta(gt=0, description="output rate, Hz")] | msgspec.UnsetType = msgspec.UNSET
    messages: Annotated[int, Meta(ge=0, le=MAX_SEQ, description="messages published")] | msgspec.UnsetType = msgspec.UNSET
    processes: Annotated[
        dict[Annotated[str, Meta(**_NAME_META)], Annotated[str, Meta(max_length=64)]],
        Meta(description="process name -> its state (e.g. alive, dead, restarting)",
             extra={"expected": "an object name -> state string"}),
    ] | msgspec.UnsetType = msgspec.UNSET
    detail: _DETAIL | msgspec.UnsetType = msgspec.UNSET


# -- the closed loop (docs/control.md) --------------------------------------------------

#: Most reaction wheels (or rotors) of one body.
MAX_WHEELS = 64
#: Commands one actuator state names as applied in its step (the plant applies no more per body per step).
MAX_APPLIED = 4096
_Wheels = Annotated[list[float], Meta(min_length=1, max_length=MAX_WHEELS)]
_Sender = _name("name of the controller that sent the command", "a controller name")
_SENDER_SEQ = Annotated[int, Meta(ge=0, le=MAX_SEQ, description=(
    "the sender's counter of its commands to this body, increasing (0, 1, 2, ...; one counter over all "
    "its commands, every body, increases per body too)"))]


class Command(Stamped, forbid_unknown_fields=True, omit_defaults=True):
    """A controller's command to one body's actuators, applying from sim time t (held until
    the next command: torque, wheel_torque, thrust; applied once at t: dv)."""

    seq: _SENDER_SEQ
    sender: _Sender
    torque: _vec(3, "external torque in body axes, N m, held") | msgspec.UnsetType = msgspec.UNSET
    wheel_torque: Annotated[_Wheels, Meta(description="motor torque of each reaction wheel, N m, held")] | msgspec.UnsetType = msgspec.UNSET
    dv: _vec(3, "impulsive velocity change, inertial axes, m/s, applied at t") | msgspec.UnsetType = msgspec.UNSET
    thrust: _vec(3, "thrust force, N, in `frame`, held") | msgspec.UnsetType = msgspec.UNSET
    frame: _enum(("inertial", "body"), "axes of thrust (default inertial)") | msgspec.UnsetType = msgspec.UNSET


class ActuatorState(Stamped, forbid_unknown_fields=True, omit_defaults=True):
    """What a body's actuators applied over the step that starts at t (after saturation),
    and the state of its wheels at t."""

    torque: _vec(3, "external torque applied, body axes, N m")
    wheel_torque: Annotated[_Wheels, Meta(description="motor torques applied, N m")] | msgspec.UnsetType = msgspec.UNSET
    wheel_speed: Annotated[_Wheels, Meta(description="wheel speeds relative to the body, rad/s")] | msgspec.UnsetType = msgspec.UNSET
    clipped: Annotated[list[int], Meta(max_length=MAX_WHEELS, description="wheels whose command was clipped")] | msgspec.UnsetType = msgspec.UNSET
    dv: _vec(3, "impulse applied in the step, inertial axes, m/s") | msgspec.UnsetType = msgspec.UNSET
    dv_t: Annotated[float, Meta(description=(
        "simulated time the step's impulse was applied (a command due inside the step applies at its own t; "
        "the last one if several), s"))] | msgspec.UnsetType = msgspec.UNSET
    thrust: _vec(3, "thrust applied, inertial axes, N") | msgspec.UnsetType = msgspec.UNSET
    mass: Annotated[float, Meta(gt=0, description="mass at t, kg")] | msgspec.UnsetType = msgspec.UNSET
    dv_total: Annotated[float, Meta(ge=0, description="delta-v spent since the start, m/s")] | msgspec.UnsetType = msgspec.UNSET
    applied: Annotated[list[str], Meta(max_length=MAX_APPLIED, description=(
        "commands first applied at this step, as sender#seq"))] | msgspec.UnsetType = msgspec.UNSET


class GyroSample(Stamped, forbid_unknown_fields=True):
    """A rate gyro's measurement: body angular velocity with bias and noise."""

    w: _vec(3, "measured angular velocity, body axes, rad/s")


class StarTrackerSample(Stamped, forbid_unknown_fields=True):
    """A star tracker's measured attitude: Euler parameters, scalar first, e0 >= 0, unit norm."""

    q: _vec(4, "measured Euler parameters, scalar first, |q| = 1")

    @staticmethod
    def rule(q: list[float]) -> str | None:
        """|q| = 1 within the attitude state's :data:`QUAT_NORM_TOL`: the sensor's noise is a
        rotation composed with the true attitude (``C(q_meas) = C(d) C(q)``,
        :class:`astrodyn.sensors.StarTracker`), never added to the components, so a
        measured quaternion is as unit as the true one (round-off, ~1e-16)."""
        return _unit_quaternion_problem(q, "star_tracker.q")

    def __post_init__(self) -> None:
        _enforce(self.rule(self.q))


class GpsSample(Stamped, forbid_unknown_fields=True):
    """A position/velocity receiver's measurement, inertial frame of the scene."""

    r: _vec(3, "measured position, m")
    v: _vec(3, "measured velocity, m/s")


class TachometerSample(Stamped, forbid_unknown_fields=True):
    """Measured reaction-wheel speeds relative to the body."""

    speeds: Annotated[_Wheels, Meta(description="wheel speeds, rad/s")]


class Tick(Stamped, forbid_unknown_fields=True):
    """The plant's control step seq at time t: the step's states and sensor samples, each
    the message published on its own key, by key relative to the scenario (body/kind)."""

    step: Annotated[int, Meta(ge=0, le=MAX_SEQ, description="output step index of t")]
    samples: Annotated[dict[str, dict], Meta(description=(
        "the messages of this step: key relative to astrodyn/<scenario>/ (e.g. sc/gyro) -> message"),
        extra={"expected": "an object key -> message object"})]


class StepDone(Stamped, forbid_unknown_fields=True):
    """A controller's answer to control step seq (time t): it sent `commands` commands."""

    sender: _Sender
    commands: Annotated[int, Meta(ge=0, le=1_000_000, description="commands sent for this step")]


#: kind -> message type (the one definition of each; docs/architecture.md, section 5)
MESSAGE_TYPES: dict[str, type[msgspec.Struct]] = {
    "orbit": OrbitState,
    "attitude": AttitudeState,
    "crosscheck": CrossCheck,
    "appendages": AppendageState,
    "rolling": RollingState,
    "gimbals": GimbalState,
    "event": Event,
    "status": Status,
    "command": Command,
    "actuators": ActuatorState,
    "gyro": GyroSample,
    "star_tracker": StarTrackerSample,
    "gps": GpsSample,
    "tachometer": TachometerSample,
    "tick": Tick,
    "done": StepDone,
}


def json_schema(message_type: type[msgspec.Struct]) -> dict:
    """The JSON Schema (draft 2020-12) of a message type, as stored with its MCAP channels:
    self-contained (no ``$ref``), titled ``astrodyn.<Name>``, described by the docstring."""
    generated = msgspec.json.schema(message_type)
    body = dict(generated["$defs"][message_type.__name__])
    body.pop("title", None)
    body.pop("description", None)
    name = message_type.__name__
    return {"$schema": _DRAFT, "$id": f"https://astrodyn.invalid/schemas/{name}.json", "title": f"astrodyn.{name}",
            "description": " ".join((message_type.__doc__ or "").split()), **body}


_DRAFT = "https://json-schema.org/draft/2020-12/schema"
ORBIT_SCHEMA: dict = json_schema(OrbitState)
ATTITUDE_SCHEMA: dict = json_schema(AttitudeState)
CROSSCHECK_SCHEMA: dict = json_schema(CrossCheck)
EVENT_SCHEMA: dict = json_schema(Event)
STATUS_SCHEMA: dict = json_schema(Status)

#: schema name -> schema; the names are the schema titles.
SCHEMAS: dict[str, dict] = {
    s["title"]: s for s in (ORBIT_SCHEMA, ATTITUDE_SCHEMA, CROSSCHECK_SCHEMA, EVENT_SCHEMA, STATUS_SCHEMA,
                            *(json_schema(t) for t in MESSAGE_TYPES.values() if t not in
                              (OrbitState, AttitudeState, CrossCheck, Event, Status)))
}
_SCHEMA_OF_KIND = {kind: SCHEMAS[f"astrodyn.{t.__name__}"] for kind, t in MESSAGE_TYPES.items()}
KIND_OF_SCHEMA_TITLE = {f"astrodyn.{t.__name__}": kind for kind, t in MESSAGE_TYPES.items()}


def schema_for_key(key: str) -> tuple[str, dict] | None:
    """``(schema_name, schema_dict)`` of the messages on ``key``, or None (control, alive, batch).

    Raises MessageError if ``key`` is not an astrodyn key at all.
    """
    kind = kind_of_key(key)
    if kind is None:
        return None
    schema = _SCHEMA_OF_KIND[kind]
    return schema["title"], schema
