"""Scenario files: load and validate a TOML scene, and plan what it needs to run.

A scenario is a TOML file (parsed with :mod:`tomllib`: data only, nothing in it is ever
executed). This module is the *edge* of astrodyn: it is the one place where astropy
turns epochs and quantities with units into the plain SI numbers the numeric core
takes. The result is a :class:`Scenario` of frozen dataclasses with numpy arrays ready
for the core (``r0, v0`` in m, m/s; ``q0`` scalar first; ``w0`` rad/s; inertia kg m^2).

A small example (``configs/demo.toml`` is a complete one)::

    [scenario]
    name = "demo"
    epoch = "2026-03-20T12:00:00 TDB"   # any astropy scale: UTC (default), TAI, TT, TDB, ...
    duration = "90 min"
    rate = "10 Hz"                      # output rate: one state per body per 0.1 s
    real_time_factor = 1.0              # pacing of `astrodyn serve` (sim s per wall s)

    [central_body]
    name = "earth"                      # mu, radius, J2..J6 from the built-in table

    [[bodies]]
    name = "iss"
    [bodies.orbit]                      # state vector (r, v) or elements
    a = "6790 km"                       # a | p | rp  (size), e, i, raan, argp, nu | M
    e = 0.0005
    i = "51.6 deg"
    model = "kepler"                    # kepler | j2 | zonal | third_body
    [bodies.attitude]
    q = [1, 0, 0, 0]                    # Euler parameters, scalar first (or euler + seq)
    w = ["0.1 deg/s", "0 deg/s", "0.5 deg/s"]
    inertia = ["1.2e8 kg m2", "1.0e8 kg m2", "2.0e8 kg m2"]   # principal moments, or 3x3
    model = "torque_free"               # none | torque_free | gravity_gradient | gyrostat | heavy_top | user
                                        # | flexible | rolling_disk

Quantities are strings with a unit (``"7000 km"``, ``"51.6 deg"``, ``"0.1 rad/s"``,
``"10 Hz"``, ``"90 min"``, ``"3.986e14 m3/s2"``, ``"60 rpm"``) parsed by astropy and
converted to SI; a bare number is taken to be in SI units already (m, s, rad, Hz, ...).
A vector is a list of such values or one string ``"[7000, 0, 0] km"``.

Sections and keys (every other key is an error, with a "did you mean" suggestion):

``[scenario]``
    ``name`` (``[A-Za-z0-9_.-]+``), ``epoch`` (string ``"<ISO time> [SCALE]"`` or a TOML
    date-time, taken as UTC), ``duration`` (> 0, at most 250 years), ``rate`` (output
    rate, :data:`MIN_RATE_HZ` to :data:`MAX_RATE_HZ`), ``real_time_factor`` (default 1,
    up to 1e6), ``frame`` (default "GCRF" around the Earth, else "ICRF"),
    ``description``.
``[central_body]``
    ``name`` (a key of :data:`CENTRAL_BODIES`, or any name if ``mu`` and ``radius`` are
    given), optional overrides ``mu``, ``radius``, ``j2`` ... ``j6``.
``[[bodies]]``
    ``name``, ``cross_check`` (bool: also run REBOUND and publish the difference),
    ``[bodies.orbit]`` and/or ``[bodies.attitude]``, ``[[bodies.gyros]]`` (single-axis
    gyroscopes mounted on the body, :mod:`~astrodyn.scenario.gyros`).
``orbit``
    ``r`` and ``v``, or elements: one of ``a`` (negative for a hyperbola), ``p``, ``rp``
    (periapsis radius; works for every conic), ``e`` (default 0), ``i``, ``raan``,
    ``argp`` (default 0), ``nu`` or ``M`` (default nu = 0); ``model`` (default kepler),
    ``degree`` (zonal: 2..6, default 6), ``perturbers`` (third_body: names from the table).
``attitude``
    ``q`` (unit, scalar first) or ``euler`` + ``seq`` (e.g. ``"321"``), ``w`` (body rad/s),
    ``inertia`` (3 principal moments or a symmetric 3x3 tensor, positive, obeying the
    triangle inequality), ``rotors`` (list of ``{axis, h}`` or ``{axis, speed, inertia}``),
    ``model`` (default torque_free, or gyrostat when rotors are given), ``mass``, ``cm``
    (distance fixed point to centre of mass along body axis 3) and ``g`` (default
    9.80665 m/s^2) for heavy_top, ``torque`` (constant body-axis torque, N m) for user;
    for flexible (a hub with cantilevered beams) ``inertia`` and ``mass`` of the hub,
    ``appendages`` (a list of beam tables), ``stiffening``, ``tolerance``
    (:mod:`~astrodyn.scenario.appendages`); for rolling_disk (a wheel rolling on the
    plane z = 0) ``radius``, ``mass``, ``shape`` or ``moments``, ``g`` and the initial
    angles and rates (:mod:`~astrodyn.scenario.rolling`).
``[walker]``
    Walker delta constellation ``i: t/p/f`` (Walker 1984, J. Br. Interplanet. Soc. 37,
    559): ``i``, ``t`` satellites in ``p`` equally spaced planes, phasing ``f`` (0..p-1),
    ``altitude`` or ``a``, ``raan0``, ``prefix``, ``model``, ``cross_check`` and an
    ``[walker.attitude]`` table shared by every satellite. Satellite ``k`` of plane ``j``
    has ``raan = raan0 + 2 pi j / p`` and argument of latitude ``u = 2 pi k / s + 2 pi f j / t``
    (``s = t / p``); circular orbits (e = 0, argp = 0, nu = u).
``[output]``
    ``path`` (the MCAP file; resolved relative to the config file, never a URL),
    ``roll_size`` (e.g. ``"256 MB"``), ``roll_interval`` (e.g. ``"1 h"``).

Errors are :class:`ScenarioError` with the text ``<file>: <key path>: expected <...>,
got <...>``, for example ``configs/x.toml: bodies[2].orbit.e: expected 0 <= e, got
-0.1``. Loading never raises anything else, never touches the network (astropy's IERS
auto-download is switched off; bundled tables only), and rejects oversized input.

:func:`plan` decides what a run needs ("model only what a scene needs"): per body the
cheapest exact model (analytic Kepler unless a perturbation is listed and non-zero;
exact torque-free unless a torque model is listed and the torque is not identically
zero) and which processes to start. ``astrodyn validate CONFIG`` prints it.

Modules: this one reads the scene's sections into the :class:`Scenario` dataclasses;
:mod:`~astrodyn.scenario.fields` reads single values (quantities with units, vectors,
choices; errors naming the field), :mod:`~astrodyn.scenario.control` the closed loop's
tables, :mod:`~astrodyn.scenario.appendages` a flexible spacecraft's beams,
:mod:`~astrodyn.scenario.rolling` a rolling disk,
:mod:`~astrodyn.scenario.planning` the plan; each re-exported here.

The built-in central-body table takes the Earth, Moon and Sun from
``astrodyn.orbit.perturbations`` and adds Mars, Venus and Jupiter.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime as _dt
import json
import math
import os
import re
import sys
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from astrodyn.files import MAX_TEXT_INPUT_BYTES
from astrodyn.messages import ACTUATED_MODEL, ATTITUDE_MODELS, ORBIT_MODELS
from astrodyn.orbit.perturbations import (
    EARTH_EGM2008 as _EARTH,
    MOON as _MOON,
    SUN as _SUN,
    CentralBody as GravityCentralBody,
)
from astrodyn.scenario.appendages import (
    DEFAULT_TOLERANCE,
    Appendage,
    parse_appendages,
    parse_tolerance,
)
from astrodyn.scenario.control import (
    Actuators,
    Control,
    Pointing,
    Sensors,
    parse_actuators,
    parse_control,
    parse_pointing,
    parse_sensors,
    steps_per,
)
from astrodyn.scenario.fields import (
    MAGNITUDE_MAX,
    MAGNITUDE_MIN,
    MAX_STRING,
    Ctx,
    ScenarioError,
    Table,
    boolean,
    check,
    choice,
    did_you_mean,
    field_name,
    integer,
    jsonable,
    quantity,
    show,
    string,
    unit_quaternion,
    vector,
)
from astrodyn.scenario.gyros import Gyro, parse_gyros
from astrodyn.scenario.planning import BYTES_PER_STATE, BodyPlan, Plan, plan
from astrodyn.scenario.rolling import ROLLING_KEYS, RollingSpec, parse_rolling, rolling_state0

__all__ = [
    "ScenarioError",
    "RESOLVED_EPOCH_ENV",
    "resolved_epoch_environment",
    "CentralBody",
    "OrbitSpec",
    "Rotor",
    "AttitudeSpec",
    "Body",
    "Scenario",
    "BodyPlan",
    "Plan",
    "CENTRAL_BODIES",
    "load",
    "loads",
    "load_dict",
    "plan",
    "main",
    "MAGNITUDE_MAX",
    "MAGNITUDE_MIN",
    "MAX_STRING",
    "MAX_CHANNELS",
    "BYTES_PER_STATE",
]

# --------------------------------------------------------------------------- limits

MIN_RATE_HZ = 1e-6  #: slowest output rate (one state every ~11.6 days)
MAX_RATE_HZ = 1000.0  #: fastest output rate; above this the bus, not physics, is the limit
MAX_DURATION_S = 250 * 365.25 * 86400.0  #: 250 Julian years (MCAP log_time, uint64 ns, ends in 2554)
MAX_OUTPUT_STEPS = 10**10  #: duration * rate (so at most 1e10 + 1 output instants, t = 0 included)
#: Largest log time of a recording, exclusive: MCAP's ``log_time`` is uint64 ns since 1970
#: (2**64 ns is 2554-07-21T23:34:33 UTC); every tool reads that whole range (``Track.log_time`` is uint64)
LOG_TIME_END_NS = 2**64
#: Smallest |r| of an initial state (m): |r|^3, which the kernels form, stays a normal float64 above it
MIN_RADIUS_M = 1e-100
MAX_REAL_TIME_FACTOR = 1e6
MAX_BODIES = 100_000
#: Largest config file, bytes (4 MiB): checked before the TOML is parsed, whose time grows
#: with the size (about 0.8 s per MiB for an array of small numbers on this machine; a
#: 16 MiB array took 12-33 s).  The largest legitimate config, constellation-1000 written
#: out body by body (1000 [[bodies]] tables with r, v, q, w, inertia: 346 kB), fits 12
#: times; a [walker] table describes 100,000 bodies in a few lines.  The cap of every text
#: file a command reads whole (:data:`astrodyn.files.MAX_TEXT_INPUT_BYTES`).
MAX_FILE_BYTES = MAX_TEXT_INPUT_BYTES
TRIANGLE_RTOL = 1e-12  #: I3 <= I1 + I2 (1 + rtol): a flat plate (equality) is allowed
SYMMETRY_RTOL = 1e-12  #: |I - I^T| <= rtol max|I| for a full tensor
#: MCAP channel ids are 16-bit: channels of one recording, all bodies and kinds together.
MAX_CHANNELS = 65_535
#: Channels a run records besides the bodies' (events, status).
EXTRA_CHANNELS = 2
#: Model names a config may choose ("actuated" is the plan's, for closed-loop bodies).
CONFIG_ORBIT_MODELS = tuple(m for m in ORBIT_MODELS if m != ACTUATED_MODEL)
ATTITUDE_MODELS_ALL = ("none",) + tuple(m for m in ATTITUDE_MODELS if m != ACTUATED_MODEL)
G0 = 9.80665  #: standard gravity, m/s^2 (default g of a heavy top)

_ORBIT_ANALYTIC = "kepler"
_ATTITUDE_EXACT = "torque_free"


# --------------------------------------------------------------------------- central bodies


@dataclass(frozen=True)
class CentralBody(GravityCentralBody):
    """The scene's gravitating body at the origin: the constants of
    :class:`astrodyn.orbit.perturbations.CentralBody` (``mu`` m^3/s^2, equatorial
    ``radius`` m, zonal coefficients ``J = (J2, J3, J4, J5, J6)``, unnormalized, always
    five, zeros where unknown) and the scene's inertial ``frame`` name."""

    frame: str = "GCRF"

    @property
    def j(self) -> tuple[float, ...]:
        """Deprecated old name of :attr:`J` (the same tuple ``(J2, ..., J6)``)."""
        return self.J

    def to_dict(self) -> dict[str, Any]:
        """The ``central_body`` table of the recorded scenario metadata: keys ``name, mu,
        radius, j, frame`` in that order (the names recordings have always carried;
        docs/architecture.md, section 5)."""
        return {"name": self.name, "mu": self.mu, "radius": self.radius, "j": tuple(self.J), "frame": self.frame}


def _j5(J: tuple[float, ...]) -> tuple[float, float, float, float, float]:
    J = tuple(float(x) for x in J[:5])
    return J + (0.0,) * (5 - len(J))  # type: ignore[return-value]


# name -> (mu m^3/s^2, equatorial radius m, (J2..J6) unnormalized).
# Earth, Moon, Sun: the constants of astrodyn.orbit.perturbations (one source; their
#   citations are there): Earth is the self-consistent EGM2008 tide-free set (GM, a, J2..J6).
# Mars: GM JPL DE440 (Park et al. 2021, AJ 161, 105; system), R = 3396.19 km (IAU 2015),
#   J2 = 1.96045e-3 (Vallado, Fundamentals of Astrodynamics, 4th ed., Table D-4).
# Venus: GM DE440, R = 6051.8 km, J2 = 4.458e-6 (Vallado Table D-4).
# Jupiter: GM DE440 (system), R = 71 492 km, J2 = 1.4736e-2 (Vallado Table D-4).
CENTRAL_BODIES: dict[str, tuple[float, float, tuple[float, float, float, float, float]]] = {
    "earth": (_EARTH.mu, _EARTH.radius, _j5(_EARTH.J)),
    "moon": (_MOON.mu, _MOON.radius, _j5(_MOON.J)),
    "sun": (_SUN.mu, _SUN.radius, _j5(_SUN.J)),
    "mars": (4.282837362e13, 3396190.0, (1.96045e-3, 0.0, 0.0, 0.0, 0.0)),
    "venus": (3.2485859200e14, 6051800.0, (4.458e-6, 0.0, 0.0, 0.0, 0.0)),
    "jupiter": (1.26712764100e17, 71492000.0, (1.4736e-2, 0.0, 0.0, 0.0, 0.0)),
}

# --------------------------------------------------------------------------- validated result


@dataclass(frozen=True, eq=False)
class OrbitSpec:
    """Initial translational state and the requested orbit model.

    ``r0`` (m) and ``v0`` (m/s) relative to the central body in the scenario frame;
    ``elements`` holds the elements as given (SI, radians) when the orbit was specified by
    elements, else None. ``degree`` is the zonal degree (2 for j2), ``perturbers`` the
    third bodies.
    """

    model: str
    r0: np.ndarray
    v0: np.ndarray
    elements: dict[str, float] | None = None
    degree: int = 0
    perturbers: tuple[str, ...] = ()


@dataclass(frozen=True, eq=False)
class Rotor:
    """A symmetric rotor (flywheel) of a gyrostat: unit ``axis`` in body axes, axial
    angular momentum ``h`` relative to the body (N m s) = ``inertia`` (kg m^2) x
    ``speed`` (rad/s) when those were given."""

    axis: np.ndarray
    h: float
    speed: float | None = None
    inertia: float | None = None


@dataclass(frozen=True, eq=False)
class AttitudeSpec:
    """Initial rotational state, mass properties and the requested attitude model.

    ``q0`` Euler parameters (scalar first, unit; ``v_body = C(q0) v_inertial``), ``w0``
    body angular velocity (rad/s, body axes), ``inertia`` the 3x3 tensor in body axes
    (kg m^2), ``principal_moments`` its eigenvalues and ``principal_axes`` the matrix whose
    columns are the principal axes in body components (identity when the inertia was
    given as principal moments or a diagonal tensor; then the moments keep the given
    order). Heavy top: ``mass`` kg, ``cm`` m along body axis 3 from the fixed point,
    ``g`` m/s^2. User torque: ``torque`` N m, body axes.  Flexible spacecraft
    (:mod:`astrodyn.scenario.appendages`): ``inertia`` and ``mass`` are the hub's,
    ``appendages`` its beams, ``stiffening`` and ``tolerance`` the model's options.
    """

    model: str
    q0: np.ndarray
    w0: np.ndarray
    inertia: np.ndarray
    principal_moments: np.ndarray
    principal_axes: np.ndarray
    rotors: tuple[Rotor, ...] = ()
    mass: float | None = None
    cm: float | None = None
    g: float | None = None
    torque: np.ndarray | None = None
    appendages: tuple[Appendage, ...] = ()
    stiffening: bool = True
    tolerance: float | None = None
    rolling: RollingSpec | None = None


@dataclass(frozen=True, eq=False)
class Body:
    """One body of the scene: a name, an orbit and/or an attitude, options."""

    name: str
    orbit: OrbitSpec | None
    attitude: AttitudeSpec | None
    cross_check: bool = False
    actuators: Actuators | None = None  #: closed loop (astrodyn.scenario.control)
    sensors: Sensors | None = None
    pointing: Pointing | None = None  #: the attitude it should hold (analyze reports the error)
    gyros: tuple[Gyro, ...] = ()  #: single-axis gyroscopes mounted on it (astrodyn.scenario.gyros)

    @property
    def in_plant(self) -> bool:
        """Moved by the closed loop's plant process (it has actuators or sensors)."""
        return self.actuators is not None or self.sensors is not None


@dataclass(frozen=True, eq=False)
class Scenario:
    """A validated scenario, SI units throughout.

    ``epoch`` is the string as given, ``epoch_scale`` its astropy time scale,
    ``epoch_unix_ns`` the same instant as integer ns since 1970-01-01T00:00:00 UTC
    (POSIX, leap seconds not counted; MCAP ``log_time = epoch_unix_ns + round(t * 1e9)``).
    ``duration`` s, ``rate`` Hz (outputs at ``t = k / rate``, k = 0 .. ``n_steps - 1``).
    ``config`` is the parsed TOML (JSON-safe) as given, ``source`` the file it came from,
    ``text`` the TOML text itself when it was loaded from text (:func:`load`, :func:`loads`;
    None from :func:`load_dict`): what a run hands its processes, so that every process
    runs the scene its supervisor checked (:func:`astrodyn.service.children.config_snapshot`).
    """

    name: str
    epoch: str
    epoch_scale: str
    epoch_unix_ns: int
    duration: float
    rate: float
    real_time_factor: float
    frame: str
    central_body: CentralBody
    bodies: tuple[Body, ...]
    description: str = ""
    output_path: Path | None = None
    roll_size: int | None = None
    roll_interval: float | None = None
    walker: dict[str, Any] | None = None
    control: Control | None = None  #: the closed loop's [control] table (docs/control.md)
    source: str = "<string>"
    config: dict[str, Any] = field(default_factory=dict)
    text: str | None = field(default=None, repr=False)

    @property
    def n_steps(self) -> int:
        """Number of output instants ``t = k / rate`` with ``t <= duration`` (k from 0)."""
        return int(math.floor(self.duration * self.rate * (1 + 4 * 2.2e-16))) + 1

    def output_times(self) -> np.ndarray:
        """The output instants ``k / rate`` (s since the epoch), shape ``(n_steps,)``."""
        return np.arange(self.n_steps, dtype=np.float64) / self.rate

    def body(self, name: str) -> Body:
        """The body called ``name`` (KeyError if none)."""
        for b in self.bodies:
            if b.name == name:
                return b
        raise KeyError(name)

    def orbit_arrays(self, model: str | None = None) -> tuple[list[str], np.ndarray, np.ndarray]:
        """``(names, r0 (N, 3), v0 (N, 3))`` of the bodies with an orbit (optionally one model)."""
        sel = [b for b in self.bodies if b.orbit is not None and (model is None or b.orbit.model == model)]
        r0 = np.array([b.orbit.r0 for b in sel], dtype=np.float64).reshape(-1, 3)
        v0 = np.array([b.orbit.v0 for b in sel], dtype=np.float64).reshape(-1, 3)
        return [b.name for b in sel], r0, v0

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe dict of the scenario as run (for the MCAP metadata record "scenario").

        ``config`` is the file as given; the other keys are the resolved SI values, the
        initial states, and the plan (model actually used per body).
        """
        p = plan(self)
        return {
            "format": "astrodyn.scenario/1",
            "source": self.source,
            "name": self.name,
            "description": self.description,
            "epoch": self.epoch,
            "epoch_scale": self.epoch_scale,
            "epoch_unix_ns": self.epoch_unix_ns,
            "duration": self.duration,
            "rate": self.rate,
            "n_steps": self.n_steps,
            "real_time_factor": self.real_time_factor,
            "frame": self.frame,
            "central_body": self.central_body.to_dict(),
            "bodies": [_body_dict(b, bp) for b, bp in zip(self.bodies, p.bodies)],
            "processes": list(p.processes),
            "walker": self.walker,
            "output": {
                "path": None if self.output_path is None else str(self.output_path),
                "roll_size": self.roll_size,
                "roll_interval": self.roll_interval,
            },
            "config": self.config,
        }

    def to_metadata(self) -> dict[str, str]:
        """String-to-string map for an MCAP Metadata record (whose values must be strings)."""
        d = self.to_dict()
        return {
            "name": self.name,
            "epoch": self.epoch,
            "epoch_scale": self.epoch_scale,
            "epoch_unix_ns": str(self.epoch_unix_ns),
            "source": self.source,
            "json": json.dumps(d, separators=(",", ":"), allow_nan=False),
        }


def _body_dict(b: Body, bp: BodyPlan) -> dict[str, Any]:
    out: dict[str, Any] = {"name": b.name, "cross_check": b.cross_check}
    if b.orbit is not None:
        out["orbit"] = jsonable(dataclasses.asdict(b.orbit)) | {"model_used": bp.orbit_model}
    if b.gyros:
        out["gyros"] = [jsonable(dataclasses.asdict(g)) for g in b.gyros]
    if b.attitude is not None:
        a = b.attitude
        out["attitude"] = jsonable(
            {f.name: getattr(a, f.name) for f in dataclasses.fields(a) if f.name not in ("rotors", "appendages", "rolling")}
            | {"rotors": [dataclasses.asdict(r) for r in a.rotors], "model_used": bp.attitude_model}
            | ({"appendages": [dataclasses.asdict(x) for x in a.appendages]} if a.appendages else {})
            | ({"rolling": dataclasses.asdict(a.rolling)} if a.rolling is not None else {})
        )
    return out


# --------------------------------------------------------------------------- epoch

_SCALES = ("utc", "tai", "tt", "tdb", "tcg", "tcb", "ut1")

#: Environment variable by which a supervisor hands the processes it starts the epoch it
#: converted (:func:`resolved_epoch_environment`): JSON ``[epoch as given, scale, unix ns]``.
RESOLVED_EPOCH_ENV = "ASTRODYN_RESOLVED_EPOCH"


def resolved_epoch_environment(scenario: Scenario) -> dict[str, str]:
    """The environment entry that lets a process started by this one load ``scenario``'s
    config without converting its epoch again: astropy's import and first conversion cost
    each process about 0.4 s of CPU at start-up, 1.2 s for a run's three children
    (docs/architecture.md, "Processes").  A process whose config names another epoch, or
    whose entry is not this shape, converts as usual."""
    return {RESOLVED_EPOCH_ENV: json.dumps([scenario.epoch, scenario.epoch_scale, scenario.epoch_unix_ns])}


def _epoch_resolved_by_supervisor(given: str, scale: str) -> int | None:
    """The unix ns of epoch ``given`` in ``scale`` from :data:`RESOLVED_EPOCH_ENV`, when the
    entry is well formed and names this very epoch; None otherwise."""
    text = os.environ.get(RESOLVED_EPOCH_ENV)
    if not text or len(text) > 256:
        return None
    try:
        entry = json.loads(text)
    except ValueError:
        return None
    if not (isinstance(entry, list) and len(entry) == 3 and entry[0] == given and entry[1] == scale
            and type(entry[2]) is int and 0 <= entry[2] < 2**63):
        return None
    return entry[2]


def _epoch(ctx: Ctx, value: Any, path: str) -> tuple[str, str, int]:
    """(epoch string as given, scale, unix ns) from ``"<ISO> [SCALE]"`` or a TOML datetime."""
    expected = 'an epoch like "2026-03-20T12:00:00 TDB" (scales: ' + ", ".join(s.upper() for s in _SCALES) + ")"
    if isinstance(value, _dt.datetime):
        if value.tzinfo is not None:
            value = value.astimezone(_dt.UTC).replace(tzinfo=None)
        text, scale = value.isoformat(), "utc"
        given = text + " UTC"
    elif isinstance(value, str) and 0 < len(value) <= 64:
        given = value.strip()
        parts = given.split()
        scale = "utc"
        if len(parts) == 2 and parts[1].lower() in _SCALES:
            text, scale = parts[0], parts[1].lower()
        elif len(parts) == 1:
            text = parts[0]
        else:
            raise ctx.error(path, expected, value)
        if not re.fullmatch(r"[0-9]{4}-[0-9]{2}-[0-9]{2}([T ][0-9]{2}:[0-9]{2}(:[0-9]{2}(\.[0-9]{1,12})?)?)?", text):
            raise ctx.error(path, expected, value)
    else:
        raise ctx.error(path, expected, value)
    year = int(text[:4])
    if not 1970 <= year <= 2261:
        raise ctx.error(path, "an epoch after 1970-01-01 and before 2262 (ns since 1970 must fit an int64)", value)
    known = _epoch_resolved_by_supervisor(given, scale)
    if known is not None:
        return given, scale, known
    from astropy.time import Time
    from astropy.utils import iers

    iers.conf.auto_download = False  # bundled tables only: never the network
    try:
        t = Time(text, format="isot" if "T" in text else "iso", scale=scale)
        ymdhms = t.utc.ymdhms
        y, mo, d, h, mi = (int(ymdhms[k]) for k in ("year", "month", "day", "hour", "minute"))
        sec = float(ymdhms["second"])
    except Exception as exc:  # astropy: bad dates, UT1 outside the bundled IERS table, ...
        raise ctx.error(path, f"{expected} that astropy can convert offline", f"{show(value)} ({type(exc).__name__}: {str(exc)[:120]})", raw=True) from None
    if not math.isfinite(sec):  # pragma: no cover - the regex makes it finite
        raise ctx.error(path, expected, value)
    # POSIX time from the UTC calendar fields (ERFA's quasi-JD stretches leap-second days,
    # so jd1/jd2 or astropy's "unix" would be off by up to 1 s on such a day); a leap
    # second 23:59:60 maps onto the next day's 00:00:00, as POSIX clocks do. Resolution:
    # astropy's two-double time, a few ns.
    days = _dt.date(y, mo, d).toordinal() - _dt.date(1970, 1, 1).toordinal()
    unix_ns = (days * 86400 + h * 3600 + mi * 60) * 10**9 + int(round(sec * 1e9))
    if not 0 <= unix_ns < 2**63:
        raise ctx.error(path, "an epoch after 1970-01-01 and before 2262 (ns since 1970 must fit an int64)", value)
    return given, scale, unix_ns


# --------------------------------------------------------------------------- sections


def _central_body(ctx: Ctx, data: Any) -> CentralBody:
    tb = Table(ctx, data, "central_body", ("name", "mu", "radius", "j2", "j3", "j4", "j5", "j6", "frame"))
    name = tb.get("name")
    if not isinstance(name, str):
        raise ctx.error("central_body.name", f"one of {', '.join(CENTRAL_BODIES)} or a name with mu and radius", name)
    key = name.lower()
    if key in CENTRAL_BODIES:
        mu, radius, j = CENTRAL_BODIES[key]
        j = list(j)
    else:
        if not (tb.has("mu") and tb.has("radius")):
            hint = did_you_mean(key, tuple(CENTRAL_BODIES))
            raise ctx.error("central_body.name", f"one of {', '.join(CENTRAL_BODIES)}{hint}, or mu and radius given explicitly", name)
        field_name(ctx, name, "central_body.name")
        mu, radius, j = 0.0, 0.0, [0.0] * 5
    if tb.has("mu"):
        mu = quantity(ctx, tb.get("mu"), "gm", "central_body.mu")
        check(ctx, mu > 0, "central_body.mu", "mu > 0", tb.get("mu"))
    if tb.has("radius"):
        radius = quantity(ctx, tb.get("radius"), "length", "central_body.radius")
        check(ctx, radius > 0, "central_body.radius", "radius > 0", tb.get("radius"))
    for n in range(2, 7):
        if tb.has(f"j{n}"):
            jn = quantity(ctx, tb.get(f"j{n}"), "dimensionless", f"central_body.j{n}")
            check(ctx, abs(jn) < 1.0, f"central_body.j{n}", f"|j{n}| < 1 (an unnormalized zonal coefficient)", tb.get(f"j{n}"))
            j[n - 2] = jn
    frame = field_name(ctx, tb.get("frame", "GCRF" if key == "earth" else "ICRF"), "central_body.frame")
    return CentralBody(name=key if key in CENTRAL_BODIES else name, mu=mu, radius=radius, J=tuple(j), frame=frame)


_ORBIT_KEYS = ("model", "r", "v", "a", "p", "rp", "e", "i", "raan", "argp", "nu", "M", "degree", "perturbers")
_ELEMENT_KEYS = ("a", "p", "rp", "e", "i", "raan", "argp", "nu", "M")


def _orbit(ctx: Ctx, data: Any, path: str, cb: CentralBody) -> OrbitSpec:
    tb = Table(ctx, data, path, _ORBIT_KEYS)
    model = choice(ctx, tb.get("model", _ORBIT_ANALYTIC), CONFIG_ORBIT_MODELS, f"{path}.model")
    has_state = tb.has("r") or tb.has("v")
    has_elements = any(tb.has(k) for k in _ELEMENT_KEYS)
    if has_state and has_elements:
        first = next(k for k in _ELEMENT_KEYS if tb.has(k))
        raise ctx.error(f"{path}.{first}", "either a state vector (r, v) or elements, not both", tb.get(first))
    if has_state:
        r0 = vector(ctx, tb.get("r"), "length", 3, f"{path}.r")
        v0 = vector(ctx, tb.get("v"), "speed", 3, f"{path}.v")
        check(ctx, bool(np.any(r0 != 0)), f"{path}.r", "|r| > 0 (not at the centre of the central body)", tb.get("r"))
        check(ctx, math.hypot(*r0) >= MIN_RADIUS_M, f"{path}.r",  # hypot: no underflow at 1e-300 m
              f"|r| >= {MIN_RADIUS_M:g} m (|r|^3 must stay a normal float64)", tb.get("r"))
        elements = None
    elif has_elements:
        r0, v0, elements = _elements(ctx, tb, path, cb.mu)
    else:
        raise ctx.error(path, "a state vector (r, v) or elements (a | p | rp, e, i, raan, argp, nu | M)", "neither", raw=True)
    degree, perturbers = 0, ()
    if tb.has("degree"):
        check(ctx, model == "zonal", f"{path}.degree", 'no degree unless model = "zonal"', tb.get("degree"))
        degree = integer(ctx, tb.get("degree"), f"{path}.degree", 2, 6)
    elif model == "zonal":
        degree = 6
    elif model == "j2":
        degree = 2
    if tb.has("perturbers"):
        check(ctx, model == "third_body", f"{path}.perturbers", 'no perturbers unless model = "third_body"', tb.get("perturbers"))
        raw = tb.get("perturbers")
        if not isinstance(raw, list) or not raw:
            raise ctx.error(f"{path}.perturbers", f"a non-empty list of names from {', '.join(CENTRAL_BODIES)}", raw)
        perturbers = tuple(choice(ctx, p, tuple(CENTRAL_BODIES), f"{path}.perturbers[{k}]") for k, p in enumerate(raw))
    elif model == "third_body":
        perturbers = ("moon", "sun") if cb.name == "earth" else ()
        if not perturbers:
            raise ctx.error(f"{path}.perturbers", "a list of third bodies for model third_body (the default moon, sun is for the Earth only)", "nothing", raw=True)
    for k, pb in enumerate(perturbers):
        check(ctx, pb != cb.name, f"{path}.perturbers[{k}]", "a body other than the central body", pb)
        check(ctx, pb not in perturbers[:k], f"{path}.perturbers[{k}]", "each perturber once", pb)
    return OrbitSpec(model=model, r0=r0, v0=v0, elements=elements, degree=degree, perturbers=perturbers)


def _elements(ctx: Ctx, tb: Table, path: str, mu: float) -> tuple[np.ndarray, np.ndarray, dict[str, float]]:
    """Classical elements -> (r0, v0, elements as SI dict) via astrodyn.orbit.state_from_elements."""
    sizes = [k for k in ("a", "p", "rp") if tb.has(k)]
    if len(sizes) != 1:
        raise ctx.error(path, "exactly one of a, p, rp (the size of the conic)", "none" if not sizes else ", ".join(sizes), raw=True)
    if tb.has("nu") and tb.has("M"):
        raise ctx.error(f"{path}.M", "either nu or M, not both", tb.get("M"))
    e = quantity(ctx, tb.get("e", 0.0), "dimensionless", f"{path}.e")
    check(ctx, e >= 0, f"{path}.e", "0 <= e", tb.get("e", 0.0))
    check(ctx, e <= 1e6, f"{path}.e", "e <= 1e6", tb.get("e", 0.0))
    size_key = sizes[0]
    size = quantity(ctx, tb.get(size_key), "length", f"{path}.{size_key}")
    spath = f"{path}.{size_key}"
    if size_key == "a":
        check(ctx, e != 1.0, spath, "p or rp for a parabola (e = 1: a is infinite)", tb.get("a"))
        if e < 1:
            check(ctx, size > 0, spath, "a > 0 for an ellipse (e < 1)", tb.get("a"))
        else:
            check(ctx, size < 0, spath, "a < 0 for a hyperbola (e > 1)", tb.get("a"))
        p = size * (1.0 - e) * (1.0 + e)
    elif size_key == "p":
        check(ctx, size > 0, spath, "p > 0", tb.get("p"))
        p = size
    else:
        check(ctx, size > 0, spath, "rp > 0", tb.get("rp"))
        p = size * (1.0 + e)
    check(ctx, math.isfinite(p) and p > 0, spath, "a conic of finite positive size", tb.get(size_key))
    i = _angle(ctx, tb, "i", path)
    check(ctx, 0.0 <= i <= math.pi, f"{path}.i", "0 <= i <= 180 deg", tb.get("i", 0.0))
    raan = _angle(ctx, tb, "raan", path)
    argp = _angle(ctx, tb, "argp", path)
    if tb.has("M"):
        M = _angle(ctx, tb, "M", path)
        from astrodyn.orbit.elements import true_from_mean

        try:
            nu = float(true_from_mean(M, e))
        except (ValueError, ArithmeticError) as exc:
            raise ctx.error(f"{path}.M", "a mean anomaly the Kepler solver converts", f"{show(tb.get('M'))} ({exc})", raw=True) from None
        check(ctx, math.isfinite(nu), f"{path}.M", "a mean anomaly the Kepler solver converts", tb.get("M"))
    else:
        nu = _angle(ctx, tb, "nu", path)
    if e > 1:
        limit = math.acos(-1.0 / e)
        nu_red = math.remainder(nu, 2 * math.pi)
        check(ctx, 1.0 + e * math.cos(nu) > 0 and abs(nu_red) < limit, f"{path}.nu",
               f"|nu| < {math.degrees(limit):.6g} deg (between the asymptotes of e = {e!r})", tb.get("nu", nu))
    from astrodyn.orbit.elements import state_from_elements

    # |r| = p / (1 + e cos nu) and |v| = sqrt(mu / p) sqrt(1 + 2 e cos nu + e^2), in logarithms (no overflow):
    # the limits of a given v (a speed) and r (MIN_RADIUS_M), checked before the state is formed
    q = 1.0 + e * math.cos(nu)
    given = ", ".join(f"{k} = {show(tb.get(k))}" for k in (size_key, "e", "nu", "M") if tb.has(k))
    log_r = math.log10(p) - math.log10(q) if q > 0 else math.inf
    log_v = 0.5 * ((math.log10(mu) if mu > 0 else -math.inf) - math.log10(p)) + 0.5 * math.log10(max(1.0 + 2.0 * e * math.cos(nu) + e * e, 1e-300))
    max_v = MAGNITUDE_MAX["speed"]
    if not log_v <= math.log10(max_v):
        raise ctx.error(f"{path}.{size_key}", f"elements whose speed |v| <= {max_v:g} m/s (0.1 c, the range of a "
                        f"speed; |v| = sqrt(mu / p) sqrt(1 + 2 e cos nu + e^2))", f"{given}: |v| = {_power(log_v)} m/s",
                        raw=True)
    if not log_r >= math.log10(MIN_RADIUS_M):
        raise ctx.error(f"{path}.{size_key}", f"elements whose position |r| >= {MIN_RADIUS_M:g} m (|r|^3 must stay "
                        f"a normal float64)", f"{given}: |r| = {_power(log_r)} m", raw=True)
    try:
        with np.errstate(all="ignore"):  # a non-finite result is refused below, in one line
            r0, v0 = state_from_elements(p, e, i, raan, argp, nu, mu)
    except ValueError as exc:  # pragma: no cover - every precondition is checked above
        raise ctx.error(path, "elements that define a state", str(exc), raw=True) from None
    r0, v0 = np.asarray(r0, dtype=np.float64).reshape(3), np.asarray(v0, dtype=np.float64).reshape(3)
    if not (np.all(np.isfinite(r0)) and np.all(np.isfinite(v0))):
        raise ctx.error(path, "elements that give a finite state", f"r = {r0.tolist()}, v = {v0.tolist()}", raw=True)
    elements = {"p": p, "e": e, "i": i, "raan": raan, "argp": argp, "nu": nu}
    if size_key == "a":
        elements["a"] = size
    if tb.has("M"):
        elements["M"] = M
    return r0, v0, elements


def _power(log10_x: float) -> str:
    """A positive number given by its log10, shown like ``2e+110`` also beyond float64."""
    if not math.isfinite(log10_x):
        return "inf" if log10_x > 0 else "0"
    exp = math.floor(log10_x)
    mant = 10 ** (log10_x - exp)
    return f"{mant:.3g}e{exp:+d}"


def _angle(ctx: Ctx, tb: Table, key: str, path: str) -> float:
    raw = tb.get(key, 0.0)
    x = quantity(ctx, raw, "angle", f"{path}.{key}")
    if not isinstance(raw, str) and abs(x) > 2 * math.pi * (1 + 1e-12) and key != "M":
        raise ctx.error(f"{path}.{key}", f'an angle in rad (bare numbers are SI) or with a unit like "{raw} deg"', raw)
    return x


_ATT_KEYS = ("model", "q", "euler", "seq", "w", "inertia", "rotors", "mass", "cm", "g", "torque", "appendages",
             "stiffening", "tolerance", *ROLLING_KEYS)


def _attitude(ctx: Ctx, data: Any, path: str) -> AttitudeSpec:
    tb = Table(ctx, data, path, _ATT_KEYS)
    rotors = _rotors(ctx, tb.get("rotors", []), f"{path}.rotors")
    default_model = "gyrostat" if rotors else _ATTITUDE_EXACT
    model = choice(ctx, tb.get("model", default_model), ATTITUDE_MODELS_ALL, f"{path}.model")
    if rotors and model != "gyrostat":
        raise ctx.error(f"{path}.rotors", 'no rotors unless model = "gyrostat"', f'{len(rotors)} rotor(s) with model = "{model}"', raw=True)
    if model == "gyrostat" and not rotors:
        raise ctx.error(f"{path}.rotors", "at least one rotor for model gyrostat", "none", raw=True)
    if model == "rolling_disk":
        return _rolling_attitude(ctx, tb, path)
    for key in ROLLING_KEYS:
        if tb.has(key):
            raise ctx.error(f"{path}.{key}", f'no {key} unless model = "rolling_disk"', tb.get(key))
    # orientation
    if tb.has("q") and tb.has("euler"):
        raise ctx.error(f"{path}.euler", "either q or euler (+ seq), not both", tb.get("euler"))
    if tb.has("seq") and not tb.has("euler"):
        raise ctx.error(f"{path}.seq", "seq only together with euler", tb.get("seq"))
    if tb.has("euler"):
        from astrodyn.rotation import EULER_SEQUENCES, quat_from_euler

        angles = vector(ctx, tb.get("euler"), "angle", 3, f"{path}.euler")
        seq = tb.get("seq", None)
        if seq is None:
            raise ctx.error(f"{path}.seq", f"a rotation sequence with euler, one of {', '.join(EULER_SEQUENCES)}", "nothing", raw=True)
        if isinstance(seq, int) and not isinstance(seq, bool):
            seq = str(seq)
        choice(ctx, seq, EULER_SEQUENCES, f"{path}.seq")
        q0 = np.asarray(quat_from_euler(angles, seq), dtype=np.float64)
        q0 = q0 / np.linalg.norm(q0)
    elif tb.has("q"):
        q0 = unit_quaternion(ctx, tb.get("q"), f"{path}.q")
    else:
        q0 = np.array([1.0, 0.0, 0.0, 0.0])
    w0 = vector(ctx, tb.get("w", [0.0, 0.0, 0.0]), "angular_velocity", 3, f"{path}.w")
    if model != "none" and not tb.has("inertia"):
        raise ctx.error(f"{path}.inertia", f"the inertia (3 principal moments or a 3x3 tensor) for model {model}", "nothing", raw=True)
    inertia, moments, axes = _inertia(ctx, tb.get("inertia", [1.0, 1.0, 1.0]), f"{path}.inertia")
    # model-specific parameters
    mass = cm = g = torque = tolerance = None
    appendages: tuple[Appendage, ...] = ()
    stiffening = True
    for key, needs in (("mass", ("heavy_top", "flexible")), ("cm", ("heavy_top",)), ("g", ("heavy_top",)),
                       ("torque", ("user",)), ("appendages", ("flexible",)), ("stiffening", ("flexible",)),
                       ("tolerance", ("flexible",))):
        if tb.has(key) and model not in needs:
            models = " or ".join(f'"{m}"' for m in needs)
            raise ctx.error(f"{path}.{key}", f"no {key} unless model = {models}", tb.get(key))
    if model == "flexible":
        if not tb.has("mass"):
            raise ctx.error(f"{path}.mass", "the hub's mass for model flexible", "nothing", raw=True)
        mass = quantity(ctx, tb.get("mass"), "mass", f"{path}.mass")
        check(ctx, mass > 0, f"{path}.mass", "mass > 0 (the hub's)", tb.get("mass"))
        if not tb.has("appendages"):
            raise ctx.error(f"{path}.appendages", "at least one [[...appendages]] table for model flexible "
                            "(a hub without appendages is torque_free)", "none", raw=True)
        appendages = parse_appendages(ctx, tb.get("appendages"), f"{path}.appendages")
        stiffening = boolean(ctx, tb.get("stiffening", True), f"{path}.stiffening")
        tolerance = parse_tolerance(ctx, tb.get("tolerance", DEFAULT_TOLERANCE), f"{path}.tolerance")
    if model == "heavy_top":
        mass = quantity(ctx, tb.get("mass"), "mass", f"{path}.mass")
        check(ctx, mass > 0, f"{path}.mass", "mass > 0", tb.get("mass"))
        cm = quantity(ctx, tb.get("cm"), "length", f"{path}.cm")
        check(ctx, cm >= 0, f"{path}.cm", "cm >= 0 (distance from the fixed point along body axis 3)", tb.get("cm"))
        g = quantity(ctx, tb.get("g", G0), "acceleration", f"{path}.g")
        check(ctx, g >= 0, f"{path}.g", "g >= 0", tb.get("g", G0))
    if model == "user":
        torque = vector(ctx, tb.get("torque"), "torque", 3, f"{path}.torque")
    return AttitudeSpec(model=model, q0=q0, w0=w0, inertia=inertia, principal_moments=moments, principal_axes=axes,
                        rotors=rotors, mass=mass, cm=cm, g=g, torque=torque, appendages=appendages,
                        stiffening=stiffening, tolerance=tolerance)


def _rolling_attitude(ctx: Ctx, tb: Table, path: str) -> AttitudeSpec:
    """A rolling disk (:mod:`astrodyn.scenario.rolling`): its state is given by angles and
    rates, so q, w and inertia are derived, never given."""
    from astrodyn.attitude.rolling_disk import disk_body_rates, disk_quaternion

    allowed = ("model", "mass", "g", "tolerance", *ROLLING_KEYS)
    for key in _ATT_KEYS:
        if key not in allowed and tb.has(key):
            raise ctx.error(f"{path}.{key}", f"no {key} for model rolling_disk (its state is given by "
                            "position, heading, lean, spin_angle and their rates; mass and radius make its inertia)",
                            tb.get(key))
    if not tb.has("mass"):
        raise ctx.error(f"{path}.mass", "the disk's mass for model rolling_disk", "nothing", raw=True)
    mass = quantity(ctx, tb.get("mass"), "mass", f"{path}.mass")
    check(ctx, mass > 0, f"{path}.mass", "mass > 0", tb.get("mass"))
    g = quantity(ctx, tb.get("g", G0), "acceleration", f"{path}.g")
    check(ctx, g > 0, f"{path}.g", "g > 0 (gravity along -z holds the disk on the plane)", tb.get("g", G0))
    spec = parse_rolling(ctx, tb, path, mass, g)
    state0 = rolling_state0(spec)
    inertia = np.diag([spec.A, spec.C, spec.A])  # body axes b1, b2 (the symmetry axis), b3
    return AttitudeSpec(model="rolling_disk", q0=disk_quaternion(state0), w0=disk_body_rates(state0), inertia=inertia,
                        principal_moments=np.diag(inertia).copy(), principal_axes=np.eye(3), mass=mass, g=g,
                        tolerance=parse_tolerance(ctx, tb.get("tolerance", DEFAULT_TOLERANCE), f"{path}.tolerance"),
                        rolling=spec)


def _inertia(ctx: Ctx, value: Any, path: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    desc = "3 principal moments or a 3x3 symmetric tensor"
    if isinstance(value, list) and len(value) == 3 and all(isinstance(row, list) for row in value):
        tensor = np.array([vector(ctx, row, "inertia", 3, f"{path}[{k}]") for k, row in enumerate(value)])
        scale = float(np.max(np.abs(tensor)))
        check(ctx, scale > 0, path, "a non-zero inertia tensor", value)
        check(ctx, bool(np.all(np.abs(tensor - tensor.T) <= SYMMETRY_RTOL * scale)), path, "a symmetric tensor (I[i][j] = I[j][i])", value)
        tensor = 0.5 * (tensor + tensor.T)
        if np.count_nonzero(tensor - np.diag(np.diag(tensor))) == 0:
            moments, axes = np.diag(tensor).copy(), np.eye(3)
        else:
            moments, axes = np.linalg.eigh(tensor)
            if np.linalg.det(axes) < 0:
                axes[:, 2] = -axes[:, 2]
    elif isinstance(value, (list, str)):
        moments = vector(ctx, value, "inertia", 3, path)
        tensor, axes = np.diag(moments), np.eye(3)
    else:
        raise ctx.error(path, desc, value)
    for k in range(3):
        check(ctx, moments[k] > 0, path, "positive principal moments (a singular or negative inertia is not a rigid body)", moments.tolist())
    total = float(np.sum(moments))
    for k in range(3):
        check(ctx, moments[k] <= (total - moments[k]) * (1 + TRIANGLE_RTOL), path,
               "principal moments obeying the triangle inequality (each <= the sum of the other two)", moments.tolist())
    return tensor, moments, axes


def _rotors(ctx: Ctx, value: Any, path: str) -> tuple[Rotor, ...]:
    if not isinstance(value, list) or len(value) > 64:
        raise ctx.error(path, "a list of at most 64 rotor tables {axis, h} or {axis, speed, inertia}", value)
    out = []
    for k, item in enumerate(value):
        p = f"{path}[{k}]"
        tb = Table(ctx, item, p, ("axis", "h", "speed", "inertia"))
        axis = vector(ctx, tb.get("axis"), "dimensionless", 3, f"{p}.axis")
        n = float(np.linalg.norm(axis))
        check(ctx, n > 0, f"{p}.axis", "a non-zero axis (body components; normalized on load)", tb.get("axis"))
        if tb.has("h"):
            if tb.has("speed") or tb.has("inertia"):
                raise ctx.error(f"{p}.h", "either h or speed + inertia, not both", tb.get("h"))
            out.append(Rotor(axis=axis / n, h=quantity(ctx, tb.get("h"), "angular_momentum", f"{p}.h")))
        else:
            speed = quantity(ctx, tb.get("speed"), "angular_velocity", f"{p}.speed")
            j = quantity(ctx, tb.get("inertia"), "inertia", f"{p}.inertia")
            check(ctx, j > 0, f"{p}.inertia", "inertia > 0 (axial moment of the rotor)", tb.get("inertia"))
            out.append(Rotor(axis=axis / n, h=j * speed, speed=speed, inertia=j))
    return tuple(out)


def _body(ctx: Ctx, data: Any, path: str, cb: CentralBody, rate: float = 1.0, control_every: int | None = None) -> Body:
    tb = Table(ctx, data, path, ("name", "orbit", "attitude", "cross_check", "actuators", "sensors", "pointing", "gyros"))
    name = field_name(ctx, tb.get("name"), f"{path}.name")
    path = f"{path} ({name})"  # errors name the body by index and name: bodies[0] (iss).orbit.a
    orbit = _orbit(ctx, tb.get("orbit"), f"{path}.orbit", cb) if tb.has("orbit") else None
    attitude = _attitude(ctx, tb.get("attitude"), f"{path}.attitude") if tb.has("attitude") else None
    if orbit is None and attitude is None:
        raise ctx.error(path, "an orbit table, an attitude table or both", f'body "{name}" with neither', raw=True)
    if attitude is not None and attitude.model == "heavy_top" and orbit is not None:
        raise ctx.error(f"{path}.orbit", "no orbit for a heavy_top body (a top spins about a fixed point in uniform gravity)", "an orbit table", raw=True)
    if attitude is not None and attitude.model == "rolling_disk" and orbit is not None:
        raise ctx.error(f"{path}.orbit", "no orbit for a rolling_disk body (it rolls on the plane z = 0)", "an orbit table", raw=True)
    if attitude is not None and attitude.model == "gravity_gradient" and orbit is None:
        raise ctx.error(f"{path}.attitude.model", "an orbit table with gravity_gradient (the torque depends on the position)", '"gravity_gradient" without an orbit', raw=True)
    cross = boolean(ctx, tb.get("cross_check", False), f"{path}.cross_check")
    if cross and orbit is None:
        raise ctx.error(f"{path}.cross_check", "an orbit to cross-check", "true without an orbit", raw=True)
    actuators = sensors = None
    if tb.has("actuators") or tb.has("sensors"):
        which = "actuators" if tb.has("actuators") else "sensors"
        if control_every is None:
            raise ctx.error(f"{path}.{which}", "a [control] table in the config (a closed-loop scene; docs/control.md)",
                            f"{which} without [control]", raw=True)
        if orbit is not None and orbit.model != "kepler":
            raise ctx.error(f"{path}.orbit.model", "kepler for a body with actuators or sensors (the closed loop flies "
                            "two-body orbits with their burns)", orbit.model)
        if attitude is not None and attitude.model not in ("torque_free", "flexible", "none"):
            raise ctx.error(f"{path}.attitude.model", "torque_free or flexible for a body with actuators or sensors "
                            "(torques come from the commands)", attitude.model)
        has_att = attitude is not None and attitude.model != "none"
        if tb.has("actuators"):
            actuators = parse_actuators(ctx, tb.get("actuators"), f"{path}.actuators", orbit is not None, has_att)
        if tb.has("sensors"):
            sensors = parse_sensors(ctx, tb.get("sensors"), f"{path}.sensors", rate, control_every, orbit is not None,
                                    has_att, bool(actuators is not None and actuators.wheels))
    pointing = parse_pointing(ctx, tb.get("pointing"), f"{path}.pointing", attitude is not None) if tb.has("pointing") else None
    gyros: tuple[Gyro, ...] = ()
    if tb.has("gyros"):
        if attitude is None or attitude.model == "none":
            raise ctx.error(f"{path}.gyros", "an attitude for the gyroscopes to sense (their base)",
                            "gyros on a body without a propagated attitude", raw=True)
        if actuators is not None or sensors is not None:
            raise ctx.error(f"{path}.gyros", "no gyros on a closed-loop body (its sensors table has the gyro)",
                            "gyros with actuators or sensors", raw=True)
        gyros = parse_gyros(ctx, tb.get("gyros"), f"{path}.gyros")
    return Body(name=name, orbit=orbit, attitude=attitude, cross_check=cross, actuators=actuators, sensors=sensors,
                pointing=pointing, gyros=gyros)


_WALKER_KEYS = ("prefix", "i", "t", "p", "f", "altitude", "a", "raan0", "model", "cross_check", "attitude")


def _walker(ctx: Ctx, data: Any, cb: CentralBody) -> tuple[list[Body], dict[str, Any]]:
    tb = Table(ctx, data, "walker", _WALKER_KEYS)
    prefix = field_name(ctx, tb.get("prefix", "sat"), "walker.prefix")
    i = _angle(ctx, tb, "i", "walker")
    check(ctx, 0.0 <= i <= math.pi, "walker.i", "0 <= i <= 180 deg", tb.get("i"))
    t = integer(ctx, tb.get("t"), "walker.t", 1, MAX_BODIES)
    p = integer(ctx, tb.get("p"), "walker.p", 1, t)
    check(ctx, t % p == 0, "walker.p", f"a divisor of t = {t} (equal planes)", tb.get("p"))
    f = integer(ctx, tb.get("f", 0), "walker.f", 0, p - 1)
    if tb.has("altitude") == tb.has("a"):
        raise ctx.error("walker", "exactly one of altitude, a", "both" if tb.has("a") else "neither", raw=True)
    if tb.has("a"):
        a = quantity(ctx, tb.get("a"), "length", "walker.a")
    else:
        a = cb.radius + quantity(ctx, tb.get("altitude"), "length", "walker.altitude")
    check(ctx, a > 0, "walker.a" if tb.has("a") else "walker.altitude", "an orbit radius a > 0", tb.get("a", tb.get("altitude", None)))
    raan0 = _angle(ctx, tb, "raan0", "walker")
    model = choice(ctx, tb.get("model", _ORBIT_ANALYTIC), CONFIG_ORBIT_MODELS, "walker.model")
    cross = boolean(ctx, tb.get("cross_check", False), "walker.cross_check")
    attitude = _attitude(ctx, tb.get("attitude"), "walker.attitude") if tb.has("attitude") else None
    if attitude is not None and attitude.model in ("heavy_top", "rolling_disk"):
        raise ctx.error("walker.attitude.model", "an orbiting model (not heavy_top or rolling_disk)", attitude.model)
    from astrodyn.orbit.elements import state_from_elements

    s = t // p
    j_idx, k_idx = np.divmod(np.arange(t), s)
    raan = raan0 + 2 * np.pi * j_idx / p
    u = 2 * np.pi * k_idx / s + 2 * np.pi * f * j_idx / t
    r0, v0 = state_from_elements(np.full(t, a), np.zeros(t), np.full(t, i), raan, np.zeros(t), u, cb.mu)
    r0, v0 = np.asarray(r0).reshape(t, 3), np.asarray(v0).reshape(t, 3)
    wp, ws = len(str(p - 1)), len(str(s - 1))
    degree = {"j2": 2, "zonal": 6}.get(model, 0)
    perturbers = ("moon", "sun") if model == "third_body" and cb.name == "earth" else ()
    if model == "third_body" and not perturbers:
        raise ctx.error("walker.model", "third_body only around the Earth (default perturbers moon, sun)", model)
    bodies = []
    for n in range(t):
        name = f"{prefix}-{j_idx[n]:0{wp}d}-{k_idx[n]:0{ws}d}"
        elements = {"p": a, "a": a, "e": 0.0, "i": i, "raan": float(raan[n]), "argp": 0.0, "nu": float(u[n])}
        orbit = OrbitSpec(model=model, r0=r0[n].copy(), v0=v0[n].copy(), elements=elements, degree=degree, perturbers=perturbers)
        bodies.append(Body(name=name, orbit=orbit, attitude=attitude, cross_check=cross))
    summary = {"prefix": prefix, "i": i, "t": t, "p": p, "f": f, "a": a, "raan0": raan0, "model": model}
    return bodies, summary


def _output(ctx: Ctx, data: Any, base: Path | None) -> tuple[Path | None, int | None, float | None]:
    tb = Table(ctx, data, "output", ("path", "roll_size", "roll_interval"))
    path = None
    if tb.has("path"):
        raw = string(ctx, tb.get("path"), "output.path", 1024)
        if re.match(r"^[A-Za-z][A-Za-z0-9+.-]*:", raw) and not re.match(r"^[A-Za-z]:[\\/]", raw):
            raise ctx.error("output.path", "a file path (resolved relative to the config file), not a URL", raw)
        check(ctx, bool(raw.strip()) and "\x00" not in raw, "output.path", "a non-empty file path", raw)
        path = Path(raw)
        if not path.is_absolute() and base is not None:
            path = base / path
    roll_size = roll_interval = None
    if tb.has("roll_size"):
        size = quantity(ctx, tb.get("roll_size"), "bytes", "output.roll_size")
        check(ctx, 2**20 <= size <= 2**50, "output.roll_size", "1 MiB <= roll_size <= 1 PiB", tb.get("roll_size"))
        roll_size = int(size)
    if tb.has("roll_interval"):
        roll_interval = quantity(ctx, tb.get("roll_interval"), "time", "output.roll_interval")
        check(ctx, 1.0 <= roll_interval <= MAX_DURATION_S, "output.roll_interval", "1 s <= roll_interval", tb.get("roll_interval"))
    return path, roll_size, roll_interval


def _channels(b: Body) -> int:
    """State channels body ``b`` records: orbit, attitude, cross-check, gimbals, appendages or rolling."""
    return ((b.orbit is not None) + (b.attitude is not None) + bool(b.cross_check) + bool(b.gyros)
            + bool(b.attitude is not None and (b.attitude.appendages or b.attitude.rolling)))


def _too_many_channels(ctx: Ctx, got: str) -> ScenarioError:
    return ctx.error("bodies", f"at most {MAX_CHANNELS - EXTRA_CHANNELS} state channels in one recording (MCAP "
                     f"channel ids are 16-bit; each body has one per orbit, attitude, cross-check and appendages)",
                     got, raw=True)


# --------------------------------------------------------------------------- loading


def load(path: str | Path) -> Scenario:
    """Load and validate a scenario file; raise :class:`ScenarioError` on any problem."""
    source = str(path)
    ctx = Ctx(source)
    try:
        p = Path(path)
        with open(p, "rb") as fh:
            raw = fh.read(MAX_FILE_BYTES + 1)
            size = os.fstat(fh.fileno()).st_size if len(raw) > MAX_FILE_BYTES else len(raw)
    except OSError as exc:
        raise ctx.error("file", "a readable TOML file", f"{type(exc).__name__}: {exc.strerror or exc}", raw=True) from None
    if len(raw) > MAX_FILE_BYTES:  # a pipe or device reports no size: "more than" the cap
        got = f"{size} bytes" if size > MAX_FILE_BYTES else f"more than {MAX_FILE_BYTES} bytes"
        raise ctx.error("file", f"a config of at most {MAX_FILE_BYTES // 2**20} MiB ({MAX_FILE_BYTES} bytes; the size "
                        f"cap, MAX_FILE_BYTES: a [walker] table describes a large constellation in a few lines)",
                        got, raw=True)
    try:  # "utf-8-sig": a byte order mark, which some Windows editors write first, is dropped
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ctx.error("file", "UTF-8 text", f"invalid byte at offset {exc.start}", raw=True) from None
    return loads(text, source=source, base_dir=p.resolve().parent)


def loads(text: str, source: str = "<string>", base_dir: str | Path | None = None) -> Scenario:
    """Load a scenario from TOML text; ``source`` names it in errors, ``base_dir`` anchors
    relative file paths (default: the current directory)."""
    ctx = Ctx(source)
    if not isinstance(text, str):
        raise ctx.error("file", "TOML text", type(text).__name__, raw=True)
    if len(text) > MAX_FILE_BYTES:
        raise ctx.error("file", f"a config of at most {MAX_FILE_BYTES // 2**20} MiB ({MAX_FILE_BYTES} characters; the "
                        f"size cap, MAX_FILE_BYTES)", f"{len(text)} characters", raw=True)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ctx.error("toml", "valid TOML", str(exc), raw=True) from None
    except RecursionError:
        raise ctx.error("toml", "valid TOML", "nesting too deep", raw=True) from None
    return dataclasses.replace(load_dict(data, source=source, base_dir=base_dir), text=text)


def load_dict(data: dict[str, Any], source: str = "<dict>", base_dir: str | Path | None = None) -> Scenario:
    """Validate an already parsed config (e.g. the ``config`` of :meth:`Scenario.to_dict`)."""
    ctx = Ctx(source)
    top = Table(ctx, data, "", ("scenario", "central_body", "bodies", "walker", "output", "control"))
    sc = Table(ctx, top.get("scenario"), "scenario", ("name", "description", "epoch", "duration", "rate", "real_time_factor", "frame"))
    name = field_name(ctx, sc.get("name"), "scenario.name")
    description = string(ctx, sc.get("description", ""), "scenario.description")
    epoch, scale, epoch_ns = _epoch(ctx, sc.get("epoch"), "scenario.epoch")
    duration = quantity(ctx, sc.get("duration"), "time", "scenario.duration")
    check(ctx, duration > 0, "scenario.duration", "duration > 0", sc.get("duration"))
    check(ctx, duration <= MAX_DURATION_S, "scenario.duration", "duration <= 250 years", sc.get("duration"))
    check(ctx, epoch_ns + round(duration * 1e9) < LOG_TIME_END_NS, "scenario.duration",
          "an end (scenario.epoch + duration) before 2554-07-21T23:34:33 UTC (2**64 ns since 1970: MCAP's uint64 log_time)",
          sc.get("duration"))
    rate = quantity(ctx, sc.get("rate"), "frequency", "scenario.rate")
    check(ctx, MIN_RATE_HZ <= rate <= MAX_RATE_HZ, "scenario.rate", f"{MIN_RATE_HZ:g} Hz <= rate <= {MAX_RATE_HZ:g} Hz", sc.get("rate"))
    check(ctx, duration * rate <= MAX_OUTPUT_STEPS, "scenario.rate",
          f"duration x rate <= {MAX_OUTPUT_STEPS:.0e} (at most {MAX_OUTPUT_STEPS + 1} output steps, t = 0 included)", sc.get("rate"))
    rtf = quantity(ctx, sc.get("real_time_factor", 1.0), "dimensionless", "scenario.real_time_factor")
    check(ctx, 0 < rtf <= MAX_REAL_TIME_FACTOR, "scenario.real_time_factor", f"0 < real_time_factor <= {MAX_REAL_TIME_FACTOR:g}", sc.get("real_time_factor", 1.0))
    cb = _central_body(ctx, top.get("central_body", {"name": "earth"}))
    frame = field_name(ctx, sc.get("frame", cb.frame), "scenario.frame")

    bodies: list[Body] = []
    raw_bodies = top.get("bodies", [])
    if not isinstance(raw_bodies, list):
        raise ctx.error("bodies", "an array of tables [[bodies]]", raw_bodies)
    if len(raw_bodies) > MAX_BODIES:
        raise ctx.error("bodies", f"at most {MAX_BODIES} bodies", f"{len(raw_bodies)} bodies", raw=True)
    max_state_channels = MAX_CHANNELS - EXTRA_CHANNELS
    if len(raw_bodies) > max_state_channels:  # refused before reading them: each body records at least one channel
        raise ctx.error("bodies", f"at most {max_state_channels} bodies (each records at least one state channel in "
                        f"the recording; MCAP channel ids are 16-bit)", f"{len(raw_bodies)} bodies", raw=True)
    control_every = None
    if top.has("control"):
        ct = top.get("control")
        control_every = 1
        if isinstance(ct, dict) and "period" in ct:  # the sensors' default rate (validated again below)
            period = quantity(ctx, ct["period"], "time", "control.period")
            check(ctx, period > 0, "control.period", "period > 0", ct["period"])
            control_every = steps_per(ctx, period, rate, "control.period", ct["period"])
    seen: dict[str, int] = {}
    channels = 0
    for k, item in enumerate(raw_bodies):
        b = _body(ctx, item, f"bodies[{k}]", cb, rate, control_every)
        if b.name in seen:  # at once: a file of 60,000 copies of one body is refused without reading them all
            raise ctx.error(f"bodies[{k}].name", f"a unique body name (also bodies[{seen[b.name]}])", b.name)
        if b.name == frame:  # the views draw each body as a frame whose parent is the scene's frame
            raise ctx.error(f"bodies[{k}].name", f"a body name other than the scene's frame {frame!r} (a body's frame "
                            f"in the live view and the Foxglove export would be its own parent)", b.name)
        seen[b.name] = k
        channels += _channels(b)
        if channels > max_state_channels:
            raise _too_many_channels(ctx, f"more than that from the first {k + 1} bodies")
        bodies.append(b)
    walker = None
    if top.has("walker"):
        generated, walker = _walker(ctx, top.get("walker"), cb)
        bodies += generated
    if not bodies:
        raise ctx.error("bodies", "at least one body ([[bodies]] or [walker])", "none", raw=True)
    if len(bodies) > MAX_BODIES:
        raise ctx.error("bodies", f"at most {MAX_BODIES} bodies", f"{len(bodies)} bodies", raw=True)
    channels = sum(_channels(b) for b in bodies)
    if channels + EXTRA_CHANNELS > MAX_CHANNELS:
        raise _too_many_channels(ctx, f"{channels} channels from {len(bodies)} bodies")
    for k, b in enumerate(bodies[len(raw_bodies):], start=len(raw_bodies)):  # the walker's, against all
        where = "walker.prefix"
        if b.name in seen:
            raise ctx.error(where, f"a unique body name (also bodies[{seen[b.name]}])", b.name)
        if b.name == frame:
            raise ctx.error(where, f"body names other than the scene's frame {frame!r}", b.name)
        seen[b.name] = k
    control = None
    if top.has("control"):
        plant = {b.name: (b.actuators, b.sensors) for b in bodies if b.in_plant}
        control = parse_control(ctx, top.get("control"), rate, duration, plant)
        if not plant:
            raise ctx.error("control", "at least one body with an actuators or sensors table (a closed-loop scene)",
                            "a [control] table and no such body", raw=True)
    out_path = roll_size = roll_interval = None
    if top.has("output"):
        out_path, roll_size, roll_interval = _output(ctx, top.get("output"), Path(base_dir) if base_dir is not None else Path.cwd())
    return Scenario(
        name=name, epoch=epoch, epoch_scale=scale, epoch_unix_ns=epoch_ns, duration=duration, rate=rate,
        real_time_factor=rtf, frame=frame, central_body=cb, bodies=tuple(bodies), description=description,
        output_path=out_path, roll_size=roll_size, roll_interval=roll_interval, walker=walker, control=control,
        source=source, config=jsonable(data),
    )


# --------------------------------------------------------------------------- CLI


def main(argv: list[str] | None = None) -> int:
    """``astrodyn validate CONFIG [--json]``: print the plan; exit 2 on a bad config."""
    parser = argparse.ArgumentParser(prog="astrodyn validate", description="Check a scenario config and print what it would run.")
    parser.add_argument("config", help="scenario TOML file")
    parser.add_argument("--json", action="store_true", help="print the scenario as run (JSON) instead of the plan")
    parser.add_argument("--all", action="store_true", help="list every body in the plan")
    args = parser.parse_args(argv)
    try:
        scn = load(args.config)
        if args.json:
            print(json.dumps(scn.to_dict(), indent=1))
        else:
            p = plan(scn)
            for w in p.warnings:
                print(f"astrodyn validate: warning: {w}", file=sys.stderr)
            print(f"{args.config}: ok")
            print(p.text(max_bodies=10**9 if args.all else 20))
    except ScenarioError as exc:
        print(f"astrodyn validate: {exc}", file=sys.stderr)
        return 2
    except Exception as exc:  # pragma: no cover - a bug: report it without a traceback wall
        print(f"astrodyn validate: internal error ({type(exc).__name__}: {exc}); please report it", file=sys.stderr)
        return 3
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
