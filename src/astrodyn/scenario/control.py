"""The closed loop in a config: ``[control]``, a body's ``actuators`` and ``sensors``, faults.

A scene is closed-loop when it has a ``[control]`` table and at least one body with an
``actuators`` or ``sensors`` table; those bodies are moved by the plant process, step by
step, with the commands of outside controllers (docs/control.md has the contract and
examples)::

    [control]
    mode = "lockstep"            # lockstep (default): every control step waits for the controllers
                                 # free: real time, commands apply at the first step at or after their t
    period = "0.1 s"             # control step: a whole number of output steps (default 1 / rate)
    controllers = ["pd"]         # who answers every control step (lockstep; [] for none)
    timeout = "10 s"             # wall time one controller may take for one step (lockstep)
    seed = 7                     # sensor noise: sample k of a sensor draws from (seed, body, sensor, k)

    [[control.faults]]           # faults on demand, each recorded as an event when it begins
    t = "60 s"
    body = "sc"
    fault = "gyro_bias"          # gyro_bias (value = [3] rad/s) | sensor_dropout (sensor, duration)
                                 # | wheel_failed (wheel = index: no torque from then on)
                                 # | wheel_stuck (wheel = index: the rotor seizes, locked to the body)
                                 # | thruster_efficiency (value in [0, 1]: dv and thrust scaled)

    [bodies.actuators]
    torque = "0.05 N m"          # external torque commands, at most this per body axis
    dv = "100 m/s"               # impulsive burns, at most this |dv| per command
    thrust = "2 N"               # finite burns up to this |thrust| (needs mass; isp default inf)
    isp = "220 s"
    mass = "500 kg"
    [[bodies.actuators.wheels]]  # reaction wheels (astrodyn.attitude.wheels)
    axis = [1, 0, 0]             # spin axis, body components (normalized)
    inertia = "0.05 kg m2"       # rotor's axial moment
    max_torque = "0.1 N m"
    max_speed = "6000 rpm"
    speed = "0 rpm"              # initial speed relative to the body

    [bodies.sensors]             # rate default: the control rate; a whole number of output steps
    gyro = { sigma = "1e-5 rad/s", bias = [0, 0, 0], rate = "10 Hz" }
                                 # + dynamics = { natural_frequency = "30 Hz", damping_ratio = 0.7,
                                 #   spin_rate = "24000 rpm", spin_inertia = "1e-4 kg m2",
                                 #   transverse_inertia = "6e-5 kg m2" }: three rate gyros' gimbals
    star_tracker = { sigma = "20 arcsec", rate = "1 Hz" }
    gps = { sigma_r = "5 m", sigma_v = "0.05 m/s", rate = "1 Hz" }
    tachometer = { sigma = "0.1 rad/s" }

Units as everywhere in configs (:mod:`astrodyn.scenario.fields`); errors name the field,
e.g. ``bodies[0] (sc).actuators.wheels[1].max_speed: expected max_speed > 0, got -1``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from astrodyn.messages import RUN_PROCESS_NAMES, is_run_process_name
from astrodyn.scenario.fields import Ctx, Table, check, choice, field_name, integer, quantity, unit_quaternion, vector

__all__ = ["Pointing", "parse_pointing", "Wheel", "Actuators", "Sensor", "Sensors", "Fault", "Control", "CONTROL_MODES", "FAULTS",
           "parse_actuators", "parse_sensors", "parse_control", "parse_fault", "plant_bodies", "steps_per",
           "parse_gyro_dynamics", "GYRO_TRIAD_AXES"]

CONTROL_MODES = ("lockstep", "free")
FAULTS = ("gyro_bias", "sensor_dropout", "wheel_failed", "wheel_stuck", "thruster_efficiency")
SENSOR_NAMES = ("gyro", "star_tracker", "gps", "tachometer")
MAX_CONTROLLERS = 64
MAX_FAULTS = 1000
MAX_TIMEOUT_S = 3600.0
_RATIO_TOL = 1e-9


@dataclass(frozen=True, eq=False)
class Wheel:
    """A reaction wheel: unit ``axis`` (body), rotor ``inertia`` kg m^2, ``max_torque`` N m,
    ``max_speed`` rad/s, initial ``speed`` rad/s relative to the body."""

    axis: np.ndarray
    inertia: float
    max_torque: float
    max_speed: float
    speed: float = 0.0


@dataclass(frozen=True, eq=False)
class Actuators:
    """What a body can be commanded to do; None: that command is refused."""

    torque: float | None = None  #: max |torque| per body axis, N m
    dv: float | None = None  #: max |dv| per impulsive command, m/s
    thrust: float | None = None  #: max |thrust|, N
    isp: float = math.inf  #: specific impulse of the thrusters, s
    mass: float | None = None  #: initial mass, kg
    wheels: tuple[Wheel, ...] = ()


@dataclass(frozen=True, eq=False)
class Sensor:
    """One sensor: its ``kind`` (gyro, star_tracker, gps, tachometer), noise (``sigma`` in
    the sensor's unit; ``sigma_v`` for gps velocity), ``bias`` (gyro, rad/s) and sampling
    ``every`` output steps."""

    kind: str
    sigma: float
    every: int
    sigma_v: float = 0.0
    bias: tuple[float, float, float] = (0.0, 0.0, 0.0)
    #: gyro only: three single-axis rate gyros (input axes body x, y, z; astrodyn.scenario.gyros.Gyro)
    #: whose indications replace the true rates before bias and noise; None: ideal (the true rates)
    dynamics: tuple | None = None


@dataclass(frozen=True, eq=False)
class Sensors:
    """A body's sensors by kind (absent ones are None)."""

    gyro: Sensor | None = None
    star_tracker: Sensor | None = None
    gps: Sensor | None = None
    tachometer: Sensor | None = None

    def present(self) -> tuple[Sensor, ...]:
        return tuple(s for s in (self.gyro, self.star_tracker, self.gps, self.tachometer) if s is not None)


@dataclass(frozen=True, eq=False)
class Fault:
    """A fault from sim time ``t`` (s) on ``body``: see the module docstring."""

    t: float
    body: str
    fault: str
    value: Any = None
    sensor: str | None = None
    wheel: int | None = None
    duration: float = math.inf


@dataclass(frozen=True, eq=False)
class Control:
    """The ``[control]`` table: ``mode``, control ``period`` s = ``every`` output steps,
    the ``controllers`` expected each step, their ``timeout`` (wall s), the sensor ``seed``."""

    mode: str
    period: float
    every: int
    controllers: tuple[str, ...]
    timeout: float
    seed: int
    faults: tuple[Fault, ...] = ()


@dataclass(frozen=True, eq=False)
class Pointing:
    """The attitude a body should hold (``[bodies.pointing]``): ``target`` Euler parameters,
    scalar first, ``v_body = C(target) v_inertial``; ``tolerance`` rad, the error within
    which it counts as settled.  ``astrodyn analyze`` reports the pointing error
    ``2 acos |target . q|`` over the run, when it settled and the error after."""

    target: np.ndarray
    tolerance: float


#: Default settling tolerance of a pointing target, rad (0.1 deg).
POINTING_TOLERANCE = math.radians(0.1)


def parse_pointing(ctx: Ctx, data: Any, path: str, has_attitude: bool) -> Pointing:
    """``[bodies.pointing]``: ``target = [e0, e1, e2, e3]`` and an optional ``tolerance``
    (an angle, default 0.1 deg)."""
    tb = Table(ctx, data, path, ("target", "tolerance"))
    if not has_attitude:
        raise ctx.error(path, "a pointing target only for a body with an attitude", "a body without one", raw=True)
    if not tb.has("target"):
        raise ctx.error(f"{path}.target", "the attitude to hold: Euler parameters [e0, e1, e2, e3], scalar first",
                        "nothing", raw=True)
    target = unit_quaternion(ctx, tb.get("target"), f"{path}.target")
    tolerance = POINTING_TOLERANCE
    if tb.has("tolerance"):
        tolerance = quantity(ctx, tb.get("tolerance"), "angle", f"{path}.tolerance")
        check(ctx, 0 < tolerance <= math.pi, f"{path}.tolerance", "an angle in (0, 180 deg]", tb.get("tolerance"))
    return Pointing(target=target, tolerance=tolerance)


def steps_per(ctx: Ctx, seconds: float, rate: float, path: str, raw: Any) -> int:
    """The whole number of output steps (of ``1 / rate`` s) in ``seconds``; refused otherwise."""
    n = seconds * rate
    k = round(n)
    check(ctx, k >= 1 and abs(n - k) <= _RATIO_TOL * max(1.0, n), path,
          f"a whole number (>= 1) of output steps of {1.0 / rate:g} s (the scenario rate)", raw)
    return int(k)


def _positive(ctx: Ctx, tb: Table, key: str, kind: str, path: str) -> float:
    x = quantity(ctx, tb.get(key), kind, f"{path}.{key}")
    check(ctx, x > 0, f"{path}.{key}", f"{key} > 0", tb.get(key))
    return x


def parse_actuators(ctx: Ctx, data: Any, path: str, has_orbit: bool, has_attitude: bool) -> Actuators:
    tb = Table(ctx, data, path, ("torque", "dv", "thrust", "isp", "mass", "wheels"))
    torque = _positive(ctx, tb, "torque", "torque", path) if tb.has("torque") else None
    dv = _positive(ctx, tb, "dv", "speed", path) if tb.has("dv") else None
    thrust = _positive(ctx, tb, "thrust", "force", path) if tb.has("thrust") else None
    isp = _positive(ctx, tb, "isp", "time", path) if tb.has("isp") else math.inf
    mass = _positive(ctx, tb, "mass", "mass", path) if tb.has("mass") else None
    if tb.has("isp") and thrust is None:
        raise ctx.error(f"{path}.isp", "isp only with thrust", tb.get("isp"))
    if thrust is not None and mass is None:
        raise ctx.error(f"{path}.mass", "a mass for thrust (acceleration = thrust / mass)", "nothing", raw=True)
    for key, value, needs, ok in (("torque", torque, "an attitude", has_attitude), ("dv", dv, "an orbit", has_orbit),
                                  ("thrust", thrust, "an orbit", has_orbit)):
        if value is not None and not ok:
            raise ctx.error(f"{path}.{key}", f"{key} commands only for a body with {needs}", tb.get(key))
    raw = tb.get("wheels", [])
    if not isinstance(raw, list) or len(raw) > 64:
        raise ctx.error(f"{path}.wheels", "a list of at most 64 wheel tables [[...wheels]]", raw)
    if raw and not has_attitude:
        raise ctx.error(f"{path}.wheels", "reaction wheels only for a body with an attitude", f"{len(raw)} wheel(s)", raw=True)
    wheels = []
    for k, item in enumerate(raw):
        p = f"{path}.wheels[{k}]"
        w = Table(ctx, item, p, ("axis", "inertia", "max_torque", "max_speed", "speed"))
        axis = vector(ctx, w.get("axis"), "dimensionless", 3, f"{p}.axis")
        n = float(np.linalg.norm(axis))
        check(ctx, n > 0, f"{p}.axis", "a non-zero axis (body components; normalized on load)", w.get("axis"))
        max_speed = _positive(ctx, w, "max_speed", "angular_velocity", p)
        speed = quantity(ctx, w.get("speed", 0.0), "angular_velocity", f"{p}.speed")
        check(ctx, abs(speed) <= max_speed, f"{p}.speed", f"|speed| <= max_speed = {max_speed:g} rad/s", w.get("speed", 0.0))
        wheels.append(Wheel(axis=axis / n, inertia=_positive(ctx, w, "inertia", "inertia", p),
                            max_torque=_positive(ctx, w, "max_torque", "torque", p), max_speed=max_speed, speed=speed))
    if torque is None and dv is None and thrust is None and not wheels:
        raise ctx.error(path, "at least one of torque, dv, thrust, wheels", "an actuators table with none", raw=True)
    return Actuators(torque=torque, dv=dv, thrust=thrust, isp=isp, mass=mass, wheels=tuple(wheels))


_SENSOR_KEYS = {
    "gyro": ("sigma", "bias", "rate", "dynamics"),
    "star_tracker": ("sigma", "rate"),
    "gps": ("sigma_r", "sigma_v", "rate"),
    "tachometer": ("sigma", "rate"),
}
_SENSOR_NEEDS = {"gyro": "an attitude", "star_tracker": "an attitude", "gps": "an orbit", "tachometer": "reaction wheels"}


def parse_sensors(ctx: Ctx, data: Any, path: str, rate: float, control_every: int, has_orbit: bool,
                  has_attitude: bool, has_wheels: bool) -> Sensors:
    tb = Table(ctx, data, path, SENSOR_NAMES)
    found = {}
    have = {"gyro": has_attitude, "star_tracker": has_attitude, "gps": has_orbit, "tachometer": has_wheels}
    for kind in SENSOR_NAMES:
        if not tb.has(kind):
            continue
        p = f"{path}.{kind}"
        if not have[kind]:
            raise ctx.error(p, f"a {kind} only on a body with {_SENSOR_NEEDS[kind]}", "a sensor table", raw=True)
        s = Table(ctx, tb.get(kind), p, _SENSOR_KEYS[kind])
        unit = {"gyro": "angular_velocity", "star_tracker": "angle", "gps": "length", "tachometer": "angular_velocity"}[kind]
        first = "sigma_r" if kind == "gps" else "sigma"
        sigma = quantity(ctx, s.get(first), unit, f"{p}.{first}")
        check(ctx, sigma >= 0, f"{p}.{first}", f"{first} >= 0 (a standard deviation)", s.get(first))
        sigma_v = 0.0
        if kind == "gps":
            sigma_v = quantity(ctx, s.get("sigma_v"), "speed", f"{p}.sigma_v")
            check(ctx, sigma_v >= 0, f"{p}.sigma_v", "sigma_v >= 0 (a standard deviation)", s.get("sigma_v"))
        bias = (0.0, 0.0, 0.0)
        if kind == "gyro" and s.has("bias"):
            bias = tuple(float(x) for x in vector(ctx, s.get("bias"), "angular_velocity", 3, f"{p}.bias"))
        dynamics = None
        if kind == "gyro" and s.has("dynamics"):
            dynamics = parse_gyro_dynamics(ctx, s.get("dynamics"), f"{p}.dynamics")
        if s.has("rate"):
            hz = quantity(ctx, s.get("rate"), "frequency", f"{p}.rate")
            check(ctx, hz > 0, f"{p}.rate", "rate > 0", s.get("rate"))
            every = steps_per(ctx, 1.0 / hz, rate, f"{p}.rate", s.get("rate"))
        else:
            every = control_every
        found[kind] = Sensor(kind=kind, sigma=sigma, every=every, sigma_v=sigma_v, bias=bias,  # type: ignore[arg-type]
                             dynamics=dynamics)
    return Sensors(**found)


#: The three rate gyros of a dynamic gyro sensor: (input, output) axes in body components.
GYRO_TRIAD_AXES = (([1, 0, 0], [0, 1, 0]), ([0, 1, 0], [0, 0, 1]), ([0, 0, 1], [1, 0, 0]))


def parse_gyro_dynamics(ctx: Ctx, data: Any, path: str) -> tuple:
    """A gyro sensor's ``dynamics`` table: the rotor and gimbal of three single-axis rate
    gyros along the body axes (Baruh 10.7.3; keys of :mod:`astrodyn.scenario.gyros` without
    type and axes), e.g. ``{ natural_frequency = "30 Hz", damping_ratio = 0.7, spin_rate =
    "24000 rpm", spin_inertia = "1e-4 kg m2", transverse_inertia = "6e-5 kg m2" }``."""
    from astrodyn.scenario.gyros import parse_gyros

    if not isinstance(data, dict):
        raise ctx.error(path, "a table of the rate gyros' rotor and gimbal (natural_frequency, damping_ratio, "
                        "spin_rate, spin_inertia, transverse_inertia)", data)
    for key in ("type", "input_axis", "output_axis"):
        if key in data:
            raise ctx.error(f"{path}.{key}", f"no {key} (three rate gyros along the body axes)", data[key])
    gyros = parse_gyros(ctx, [{**data, "type": "rate", "input_axis": i, "output_axis": o} for i, o in GYRO_TRIAD_AXES],
                        path)
    return gyros


def parse_fault(ctx: Ctx, data: Any, path: str, duration: float,
                plant_bodies: dict[str, tuple[Actuators | None, Sensors | None]], t: float | None = None) -> Fault:
    """One fault table (``[[control.faults]]``, or the ``fault`` control verb's arguments,
    which carry no ``t``: pass the time it begins as ``t``).  A ``sensor_dropout``'s
    ``duration`` (s) is at most :data:`astrodyn.scenario.MAX_DURATION_S` (250 years, the
    longest scenario; the plant counts it in output steps, at most 1 kHz, so that count
    stays an exact integer); without one the dropout lasts to the end (``math.inf``)."""
    tb = Table(ctx, data, path, ("body", "fault", "value", "sensor", "wheel", "duration") if t is not None else
               ("t", "body", "fault", "value", "sensor", "wheel", "duration"))
    if t is None:
        t = quantity(ctx, tb.get("t"), "time", f"{path}.t")
        check(ctx, 0 <= t <= duration, f"{path}.t", f"0 <= t <= the scenario's duration ({duration:g} s)", tb.get("t"))
    body = field_name(ctx, tb.get("body"), f"{path}.body")
    if body not in plant_bodies:
        names = ", ".join(sorted(plant_bodies)) or "none"
        raise ctx.error(f"{path}.body", f"a body with actuators or sensors ({names})", body)
    act, sens = plant_bodies[body]
    fault = choice(ctx, tb.get("fault"), FAULTS, f"{path}.fault")
    allowed = {"gyro_bias": ("value",), "sensor_dropout": ("sensor", "duration"), "wheel_failed": ("wheel",),
               "wheel_stuck": ("wheel",), "thruster_efficiency": ("value",)}[fault]
    for key in ("value", "sensor", "wheel", "duration"):
        if tb.has(key) and key not in allowed:
            raise ctx.error(f"{path}.{key}", f"no {key} for fault {fault} (its keys: {', '.join(allowed)})", tb.get(key))
    value = sensor = wheel = None
    length = math.inf
    if fault == "gyro_bias":
        if sens is None or sens.gyro is None:
            raise ctx.error(f"{path}.fault", f"a gyro on body {body} for gyro_bias", fault)
        value = tuple(float(x) for x in vector(ctx, tb.get("value"), "angular_velocity", 3, f"{path}.value"))
    elif fault == "sensor_dropout":
        present = [s.kind for s in sens.present()] if sens is not None else []
        sensor = choice(ctx, tb.get("sensor"), tuple(present) or ("(no sensors on this body)",), f"{path}.sensor")
        if tb.has("duration"):  # bounded: the plant counts it in output steps (<= 250 years x 1 kHz < 2**53)
            from astrodyn.scenario import MAX_DURATION_S  # (the package imports this module)

            length = quantity(ctx, tb.get("duration"), "time", f"{path}.duration")
            check(ctx, 0 < length <= MAX_DURATION_S, f"{path}.duration",
                  f"0 < duration <= 250 yr ({MAX_DURATION_S:g} s; omit it for a dropout to the end)",
                  tb.get("duration"))
    elif fault in ("wheel_failed", "wheel_stuck"):
        n = len(act.wheels) if act is not None else 0
        if n == 0:
            raise ctx.error(f"{path}.fault", f"reaction wheels on body {body} for {fault}", fault)
        wheel = integer(ctx, tb.get("wheel"), f"{path}.wheel", 0, n - 1)
    else:
        if act is None or (act.dv is None and act.thrust is None):
            raise ctx.error(f"{path}.fault", f"dv or thrust actuators on body {body} for thruster_efficiency", fault)
        value = quantity(ctx, tb.get("value"), "dimensionless", f"{path}.value")
        check(ctx, 0.0 <= value <= 1.0, f"{path}.value", "0 <= value <= 1 (fraction of the commanded dv / thrust)", tb.get("value"))
    return Fault(t=t, body=body, fault=fault, value=value, sensor=sensor, wheel=wheel, duration=length)


def parse_control(ctx: Ctx, data: Any, rate: float, duration: float,
                  plant_bodies: dict[str, tuple[Actuators | None, Sensors | None]]) -> Control:
    """The ``[control]`` table; ``plant_bodies`` maps each body with actuators or sensors to them."""
    tb = Table(ctx, data, "control", ("mode", "period", "controllers", "timeout", "seed", "faults"))
    mode = choice(ctx, tb.get("mode", "lockstep"), CONTROL_MODES, "control.mode")
    if tb.has("period"):
        period = quantity(ctx, tb.get("period"), "time", "control.period")
        check(ctx, period > 0, "control.period", "period > 0", tb.get("period"))
        every = steps_per(ctx, period, rate, "control.period", tb.get("period"))
    else:
        every = 1
    raw = tb.get("controllers", [])
    if not isinstance(raw, list) or len(raw) > MAX_CONTROLLERS:
        raise ctx.error("control.controllers", f"a list of at most {MAX_CONTROLLERS} controller names", raw)
    controllers = tuple(field_name(ctx, c, f"control.controllers[{k}]") for k, c in enumerate(raw))
    check(ctx, len(set(controllers)) == len(controllers), "control.controllers", "unique controller names", raw)
    for k, c in enumerate(controllers):  # the plant takes what these sign for the run's own messages
        check(ctx, not is_run_process_name(c), f"control.controllers[{k}]",
              f"a name other than the run's own processes ({', '.join(sorted(RUN_PROCESS_NAMES))}, logger-N)", c)
    timeout = quantity(ctx, tb.get("timeout", 10.0), "time", "control.timeout")
    check(ctx, 0 < timeout <= MAX_TIMEOUT_S, "control.timeout", f"0 < timeout <= {MAX_TIMEOUT_S:g} s (wall time per step)",
          tb.get("timeout", 10.0))
    seed = integer(ctx, tb.get("seed", 0), "control.seed", 0, 2**63 - 1)
    faults_raw = tb.get("faults", [])
    if not isinstance(faults_raw, list) or len(faults_raw) > MAX_FAULTS:
        raise ctx.error("control.faults", f"a list of at most {MAX_FAULTS} fault tables [[control.faults]]", faults_raw)
    faults = tuple(parse_fault(ctx, f, f"control.faults[{k}]", duration, plant_bodies) for k, f in enumerate(faults_raw))
    return Control(mode=mode, period=every / rate, every=every, controllers=controllers, timeout=timeout, seed=seed,
                   faults=tuple(sorted(faults, key=lambda f: f.t)))


def plant_bodies(scenario) -> dict[str, tuple[Actuators | None, Sensors | None]]:
    """The scene's bodies with actuators or sensors, and those (what faults may name)."""
    return {b.name: (b.actuators, b.sensors) for b in scenario.bodies if b.in_plant}
