"""Config fields: the typed readers every scenario section uses, and their error messages.

Each reader takes a :class:`Ctx` (the file name, for errors), the raw TOML value and its
key path, and returns a plain SI value or raises :class:`ScenarioError` with the text
``<file>: <key path>: expected <...>, got <...>``.  Quantities are strings with a unit
parsed by astropy (``"7000 km"``) or bare numbers taken as SI; each kind has a magnitude
range (:data:`MAGNITUDE_MAX`, :data:`MAGNITUDE_MIN`) so that no product the kernels form
overflows float64 (docs/architecture.md, section 5).
"""

from __future__ import annotations

import argparse
import contextlib
import contextvars
import datetime as _dt
import difflib
import functools
import json
import math
import re
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np

from astrodyn.messages import NAME_PATTERN

__all__ = ["QUAT_TOL", "unit_quaternion", "ScenarioError", "Ctx", "Table", "MISSING", "MAX_STRING", "MAGNITUDE_MAX", "MAGNITUDE_MIN", "QUANTITY_KINDS",
           "jsonable", "show", "short_key", "MAX_SHOWN_DEPTH", "did_you_mean", "units", "KIND_UNITS", "UNIT_WORDS", "unit_text", "unknown_unit",
           "scaled_unit_number", "parse_quantity_string", "flag_quantity", "quantity", "quantities_read", "vector", "check",
           "field_name", "choice", "boolean", "integer", "string"]

MAX_STRING = 256  #: longest accepted quantity / epoch string

#: Largest magnitude of each kind of config value (SI, after unit conversion): the ranges
#: where astrodyn's Newtonian models are meant to be used and where the products the
#: kernels form (r^3, |h|^2, I w^2, ...) stay far from float64 overflow.  A value outside
#: is refused naming the field, the value and the range (docs/architecture.md, section 6).
MAGNITUDE_MAX = {
    "length": 1e16,  # m: about 67,000 au
    "speed": 299_792_458.0 * 0.1,  # m/s: a tenth of c (Newtonian mechanics)
    "angular_velocity": 1e5,  # rad/s: about 1 million rpm
    "gm": 1e22,  # m^3/s^2: 75 solar masses
    "inertia": 1e20,  # kg m^2
    "angular_momentum": 1e25,  # kg m^2/s
    "mass": 1e30,  # kg
    "acceleration": 1e7,  # m/s^2
    "torque": 1e15,  # N m
    "force": 1e12,  # N
    "linear_density": 1e9,  # kg/m
    "bending_stiffness": 1e15,  # N m^2: a 10 m steel tube 1 m across is ~1e10
    "rotational_stiffness": 1e15,  # N m/rad
    "rotational_damping": 1e15,  # N m s/rad
    "angle": 1e9,  # rad (mean anomalies of many revolutions included)
    "dimensionless": 1e6,
}
#: Smallest non-zero magnitude of some kinds (below: a typo or a unit slip, and the
#: dynamics lose their meaning in float64, e.g. an inertia of 1e-320 kg m^2 is subnormal).
MAGNITUDE_MIN = {"inertia": 1e-15, "mass": 1e-15, "gm": 1e-3, "linear_density": 1e-9, "bending_stiffness": 1e-9}

class ScenarioError(ValueError):
    """A scenario that cannot be loaded; ``str`` is ``<file>: <key path>: expected ..., got ...``."""



def jsonable(x: Any) -> Any:
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    if isinstance(x, dict):
        return {k: jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if isinstance(x, (_dt.datetime, _dt.date, _dt.time)):
        return x.isoformat()
    if isinstance(x, float) and not math.isfinite(x):  # pragma: no cover - validated away
        return repr(x)
    return x



# --------------------------------------------------------------------------- error helpers


def show(value: Any) -> str:
    """The offending value as the user wrote it (JSON-like, shortened)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else {True: "inf", False: "-inf"}.get(value > 0, "nan") if not math.isnan(value) else "nan"
    if isinstance(value, int):
        text = str(value) if abs(value) < 10**30 else f"an integer of {len(str(abs(value)))} digits"
        return text
    if isinstance(value, dict):
        return "a table"
    if isinstance(value, (_dt.datetime, _dt.date, _dt.time)):
        return value.isoformat()
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if _depth(value) > MAX_SHOWN_DEPTH:  # a hostile nesting: json / jsonable would exhaust the stack
        return f"a value nested more than {MAX_SHOWN_DEPTH} levels deep"
    try:
        text = json.dumps(jsonable(value), ensure_ascii=False)
    except (TypeError, ValueError):  # pragma: no cover - TOML values are always JSON-able
        text = repr(value)
    return text if len(text) <= 100 else text[:97] + "..."


MAX_SHOWN_DEPTH = 32  #: deeper lists / tables are described, not printed, in error messages


def _depth(value: Any) -> int:
    """Nesting depth of lists and tables, counted without recursion (stops past the limit)."""
    depth, level = 0, [value]
    while level and depth <= MAX_SHOWN_DEPTH:
        level = [x for v in level for x in (v.values() if isinstance(v, dict) else v if isinstance(v, list) else ())]
        depth += 1 if level else 0
    return depth


def short_key(key: Any) -> str:
    """A config key as it goes into a key path: on one line (control characters escaped as in
    JSON) and shortened (a hostile key may be megabytes long)."""
    text = str(key)[:64]
    if not text.isprintable():
        text = json.dumps(text, ensure_ascii=False)[1:-1]
    return text if len(str(key)) <= 64 else f"{text[:61]}..."


class Ctx:
    """Carries the file name for error messages."""

    def __init__(self, source: str):
        self.source = source

    def error(self, path: str, expected: str, got: Any, raw: bool = False) -> ScenarioError:
        shown = got if raw else show(got)
        return ScenarioError(f"{self.source}: {path}: expected {expected}, got {shown}")


MISSING = object()


def did_you_mean(word: str, options: tuple[str, ...]) -> str:
    """' (did you mean "x"?)' for the closest option (difflib, or a prefix), else ''."""
    close = difflib.get_close_matches(word, options, n=1, cutoff=0.6)
    if not close:
        close = [o for o in options if word.lower().startswith(o.lower()) or o.lower().startswith(word.lower())][:1] if word else []
    return f' (did you mean "{close[0]}"?)' if close else ""


class Table:
    """A TOML table being read: remembers which keys were used, rejects the rest."""

    def __init__(self, ctx: Ctx, data: Any, path: str, allowed: tuple[str, ...]):
        if not isinstance(data, dict):
            raise ctx.error(path, "a table", data)
        self.ctx, self.data, self.path, self.allowed = ctx, data, path, allowed
        for key in data:
            if key not in allowed:
                hint = did_you_mean(str(key)[:256], allowed)
                raise ctx.error(self.sub(short_key(key)), f"one of the keys {', '.join(allowed)}{hint}",
                                f'unknown key "{short_key(key)}"', raw=True)

    def sub(self, key: str) -> str:
        return f"{self.path}.{key}" if self.path else str(key)

    def has(self, key: str) -> bool:
        return key in self.data

    def get(self, key: str, default: Any = MISSING) -> Any:
        if key in self.data:
            return self.data[key]
        if default is MISSING:
            raise self.ctx.error(self.sub(key), "a value (required)", "nothing", raw=True)
        return default


# --------------------------------------------------------------------------- quantities

_RPM = None


def units():
    """astropy.units with network access off and ``rpm`` defined (imported lazily)."""
    global _RPM
    import astropy.units as u

    if _RPM is None:
        _RPM = u.def_unit("rpm", u.cycle / u.min)
        u.add_enabled_units([_RPM])
    return u


# kind -> (SI unit string, description for errors)
QUANTITY_KINDS: dict[str, tuple[str, str]] = {
    "length": ("m", 'a length, e.g. "7000 km"'),
    "angle": ("rad", 'an angle, e.g. "51.6 deg"'),
    "time": ("s", 'a time, e.g. "90 min"'),
    "frequency": ("Hz", 'a rate, e.g. "10 Hz"'),
    "speed": ("m / s", 'a speed, e.g. "7.5 km/s"'),
    "angular_velocity": ("rad / s", 'an angular velocity, e.g. "0.1 rad/s"'),
    "gm": ("m3 / s2", 'a gravitational parameter, e.g. "3.986004418e14 m3/s2"'),
    "inertia": ("kg m2", 'a moment of inertia, e.g. "100 kg m2"'),
    "angular_momentum": ("kg m2 / s", 'an angular momentum, e.g. "10 N m s"'),
    "mass": ("kg", 'a mass, e.g. "500 kg"'),
    "acceleration": ("m / s2", 'an acceleration, e.g. "9.81 m/s2"'),
    "torque": ("N m", 'a torque, e.g. "0.01 N m"'),
    "force": ("N", 'a force, e.g. "2 N"'),
    "linear_density": ("kg / m", 'a mass per length, e.g. "0.3 kg/m"'),
    "bending_stiffness": ("N m2", 'a bending stiffness EI, e.g. "34 N m2"'),
    "rotational_stiffness": ("N m / rad", 'a torsional spring constant, e.g. "0.5 N m/rad"'),
    "rotational_damping": ("N m s / rad", 'a rotational damping constant, e.g. "0.01 N m s/rad"'),
    "bytes": ("byte", 'a size, e.g. "256 MB"'),
    "dimensionless": ("", "a number"),
}


#: Common unit symbols of each kind, shown when a unit is not known (every one parses with
#: astropy to that kind; any other astropy unit of the kind is accepted too).
KIND_UNITS: dict[str, tuple[str, ...]] = {
    "length": ("m", "km", "mm", "au"),
    "angle": ("rad", "deg", "arcmin", "arcsec", "°"),
    "time": ("s", "ms", "min", "h", "d", "yr"),
    "frequency": ("Hz", "kHz", "1/s"),
    "speed": ("m/s", "km/s", "km/h"),
    "angular_velocity": ("rad/s", "deg/s", "rpm"),
    "gm": ("m3/s2", "km3/s2"),
    "inertia": ("kg m2", "g cm2"),
    "angular_momentum": ("kg m2/s", "N m s"),
    "mass": ("kg", "g"),
    "acceleration": ("m/s2", "km/s2"),
    "torque": ("N m", "mN m"),
    "force": ("N", "mN", "kN"),
    "linear_density": ("kg/m", "g/m"),
    "bending_stiffness": ("N m2",),
    "rotational_stiffness": ("N m/rad", "N m/deg"),
    "rotational_damping": ("N m s/rad",),
    "bytes": ("byte", "kB", "MB", "GB", "KiB", "MiB", "GiB"),
    "dimensionless": (),
}

#: English unit words astropy does not take, each replaced by the unit it names before a
#: quantity string is parsed: ``"93 minutes"``, ``"5580 sec"``, ``"51.64 degrees"``,
#: ``"0.06 deg/sec"``, ``"7.5 km per s"``.  Whole words only, in any letter case (``Minutes``);
#: only words with one meaning are here (the singular long names, ``minute``, ``degree``, are
#: astropy's own).  Unit *symbols* keep astropy's case-sensitive SI meaning (``mm`` millimetre,
#: ``Mm`` megametre, ``MB`` megabyte, ``mb`` millibit): ``"6795 KM"`` is refused with the hint
#: ``did you mean "km"?``, never guessed.
UNIT_WORDS: dict[str, str] = {
    "sec": "s", "secs": "s", "second": "s", "seconds": "s",
    "mins": "min", "minute": "min", "minutes": "min",
    "hrs": "h", "hour": "h", "hours": "h",
    "day": "d", "days": "d",
    "degs": "deg", "degree": "deg", "degrees": "deg",
    "radian": "rad", "radians": "rad",
    "meter": "m", "meters": "m", "metre": "m", "metres": "m",
    "kilometer": "km", "kilometers": "km", "kilometre": "km", "kilometres": "km",
    "kilogram": "kg", "kilograms": "kg", "gram": "g", "grams": "g",
    "newton": "N", "newtons": "N",
    "byte": "byte", "bytes": "byte",
    "per": "/",
}

_WORD = re.compile(r"[A-Za-z]+")
_LEADING_NUMBER = re.compile(r"^\s*[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?\s*")


def unit_text(text: str) -> str:
    """``text`` with the English unit words of :data:`UNIT_WORDS` replaced by astropy's units
    (``"0.06 deg/sec"`` -> ``"0.06 deg/s"``, ``"7 km per s"`` -> ``"7 km / s"``)."""
    return _WORD.sub(lambda m: f" {UNIT_WORDS[m.group().lower()]} " if m.group().lower() in UNIT_WORDS else m.group(), text)


def unknown_unit(text: str, kind: str) -> str:
    """Why the unit of the quantity string ``text`` is not one: the unknown word, a hint when it
    differs from a unit of ``kind`` only in letter case, and the units of ``kind`` to use."""
    u = units()
    rest = _LEADING_NUMBER.sub("", text, count=1)
    bad = []
    for word in _WORD.findall(unit_text(rest)):
        try:
            u.Unit(word, parse_strict="raise")
        except Exception:  # astropy raises ValueError (and others) for an unknown name
            bad.append(word)
    shown = f"unknown unit {json.dumps(bad[0] if bad else rest.strip(), ensure_ascii=False)}"
    names = KIND_UNITS[kind]
    same = [n for n in names if bad and n.lower() == bad[0].lower()]
    if same:
        shown += f' (did you mean "{same[0]}"? unit symbols are case-sensitive)'
    if not names:
        return f"{shown}; expected a plain number"
    si = u.Unit(QUANTITY_KINDS[kind][0])
    words = [w for w, to in UNIT_WORDS.items() if to != "/" and u.Unit(to).is_equivalent(si)]
    return (f"{shown}; accepted: {', '.join(names)}" + (f"; the words {', '.join(words)}" if words else "")
            + "; or any other astropy unit of that kind")


_NUMBER_FIRST = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")
_ONE_OVER = re.compile(r"1\s*/")
_DIGIT_GROUP = re.compile(r"\d+(?:\.\d*)?")
#: A number standing alone inside a unit (``60`` of ``1/60 s``), not an exponent (``m3``,
#: ``s-1``, ``s^2``, ``s**2``).
_NUMBER_IN_UNIT = re.compile(r"(?<![A-Za-z0-9.\-^*])\d+(?:\.\d+)?(?![A-Za-z0-9.])")


def scaled_unit_number(unit: str) -> str | None:
    """The number the unit part ``unit`` of a quantity string starts with (``"400"`` for the
    unit part ``"400 s"`` of ``"5 400 s"``), or None when it starts with none.  astropy takes
    such a unit as a scaled unit (``"5 400 s"`` is 5 x a unit 400 s long, 2000 s), so a
    number written in digit groups would silently multiply: a unit part starting with a
    number is refused.  ``1`` over a unit (``"1/s"``, ``"1 / s"``) is a unit, not a scale: None."""
    text = unit.lstrip()
    if _ONE_OVER.match(text):
        return None
    m = _NUMBER_FIRST.match(text)
    return m.group() if m else None


def _divided_unit(unit: str) -> Any:
    """The unit ``a / b / c`` = a / (b c) written with English words (``"per minutes per sec"``,
    which astropy's grammar does not parse: it starts with "/"), or None if a part is not a
    unit or the result is scaled (a number in it)."""
    u = units()
    parts = unit_text(unit).split("/")
    try:
        first = parts[0].strip()
        result = u.dimensionless_unscaled if first in ("", "1") else u.Unit(first, parse_strict="raise")
        for part in parts[1:]:
            if not part.strip():
                return None
            result = result / u.Unit(part.strip(), parse_strict="raise")
    except Exception:  # astropy raises ValueError (and others) for a part that is not a unit
        return None
    return result if result.scale == 1 else None


def _si_dimension(unit: Any) -> str:
    """``unit`` in SI base units without its scale (``1 / (min s)`` -> ``"1 / s2"``)."""
    u = units()
    base = unit.decompose()
    return u.CompositeUnit(1, base.bases, base.powers).to_string() or "no unit"


@functools.lru_cache(maxsize=4096)
def parse_quantity_string(text: str, kind: str) -> float | str:
    """SI value of a quantity string (an astropy quantity, English unit words of
    :data:`UNIT_WORDS` allowed), or an error description (str): ``"unparsable"``, an unknown
    unit (``"unknown unit ..."``, :func:`unknown_unit`), a number after the value (``"5 400
    s"``: a scaled unit, :func:`scaled_unit_number`; ``"a number after the value ..."``), a
    unit of another kind (``"a quantity in kg"``, ``"a quantity in 1 / s2"`` for ``"1 per
    minute per sec"``), no unit where one is needed (``"a number without a unit"``) or ``"not
    a scalar"``."""
    u = units()
    unit = u.Unit(QUANTITY_KINDS[kind][0]) if QUANTITY_KINDS[kind][0] else u.dimensionless_unscaled
    lead = _LEADING_NUMBER.match(text)
    rest = text[lead.end():] if lead else ""
    if lead and (number := scaled_unit_number(rest)) is not None:
        value = lead.group().strip()
        why = f'a number after the value ("{number}" after "{value}") would scale the unit'
        if _DIGIT_GROUP.fullmatch(number) and _NUMBER_FIRST.fullmatch(value + number) and "e" not in value.lower():
            return (f'{why}; write numbers without spaces between digit groups, e.g. '
                    f'"{value}{number}{rest.lstrip()[len(number):]}"')
        return f"{why}; write the value as one number, then the unit"
    try:
        q = u.Quantity(unit_text(text))
    except Exception:  # astropy raises ValueError, TypeError, UnitsError... on garbage
        if not lead:
            return "unparsable"
        divided = _divided_unit(rest)
        if divided is not None and not divided.is_equivalent(unit):  # every word known: the wrong kind
            return f"a quantity in {_si_dimension(divided)}"
        inside = [m for m in _NUMBER_IN_UNIT.finditer(rest) if not _ONE_OVER.match(rest, m.start())]
        if inside:  # "10 1/60 s", "5 m / 2 s": a scale inside the unit, which astropy's grammar does not take
            return (f'a number inside the unit ("{inside[0].group()}" in "{rest.strip()}"); write the value as one '
                    f'number, then the unit alone')
        return unknown_unit(text, kind)
    try:
        with np.errstate(over="ignore", invalid="ignore"):  # an overflow is reported as "not finite" by the caller
            value = q.to_value(unit)
    except Exception:
        return f"a quantity in {q.unit.to_string()}" if q.unit.to_string() else "a number without a unit"
    if np.ndim(value) != 0:
        return "not a scalar"
    if kind == "bytes" and (problem := _not_bytes(q.unit)):
        return problem
    return float(value)


def _not_bytes(unit: Any) -> str | None:
    """Why a size in ``unit`` is refused: bits (``"256 Mb"`` is 32 MB, ``"256 mb"`` a
    thirty-second of a byte: almost surely meant as MB), or a fraction of a byte; None for
    a unit of whole bytes."""
    name = unit.to_string()
    if "bit" in name:
        return (f"unit {name} counts bits, not bytes: b is bit, B is byte, and unit symbols are case-sensitive; "
                f"accepted: {', '.join(KIND_UNITS['bytes'])}")
    if unit.to(units().byte) < 1:
        return f"unit {name} is a fraction of a byte; accepted: {', '.join(KIND_UNITS['bytes'])}"
    return None


def flag_quantity(kind: str, plain: str) -> Callable[[str], float]:
    """An argparse ``type`` for a command-line flag that takes what the config's field of that
    ``kind`` takes: a quantity string (``"1 h"``, ``"256 MB"``; :func:`parse_quantity_string`)
    or a plain number of ``plain`` (SI: ``"seconds"``, ``"bytes"``); bytes come out as an int
    (rounded).  Ranges are the caller's to judge (``serve --roll-size``, ``sweep
    --case-memory``)."""
    example = QUANTITY_KINDS[kind][1]

    def parse(text: str) -> float:
        try:
            x = float(text)
        except ValueError:
            x = parse_quantity_string(text.strip(), kind)
        if isinstance(x, str):  # the reason it is not one
            raise argparse.ArgumentTypeError(f"expected {example}, or a number of {plain}; got {text!r} ({x})")
        return round(x) if kind == "bytes" and math.isfinite(x) else x

    return parse


def quantity(ctx: Ctx, value: Any, kind: str, path: str) -> float:
    """A finite SI float from a bare number (already SI) or a quantity string."""
    desc = QUANTITY_KINDS[kind][1]
    if isinstance(value, bool):
        raise ctx.error(path, desc, value)
    if isinstance(value, (int, float)):
        try:
            x = float(value)
        except OverflowError:
            raise ctx.error(path, f"{desc} (finite)", value) from None
    elif isinstance(value, str):
        if len(value) > MAX_STRING:
            raise ctx.error(path, f"{desc} (at most {MAX_STRING} characters)", value)
        parsed = parse_quantity_string(value.strip(), kind)
        if isinstance(parsed, str):  # why not: the wrong kind of unit, an unknown one, a digit group, ...
            if parsed in ("unparsable", "not a scalar"):
                why = ""
            elif parsed.startswith(("a quantity in ", "a number without")):  # the wrong kind: what it is
                why = f" (got {parsed})"
            else:  # an unknown unit, bits for bytes, a number after the value (digit groups)
                why = f" ({parsed})"
            raise ctx.error(path, f"{desc}{why}", value)
        x = parsed
    else:
        raise ctx.error(path, desc, value)
    if not math.isfinite(x):
        raise ctx.error(path, f"{desc} (finite)", value)
    hi, lo = MAGNITUDE_MAX.get(kind), MAGNITUDE_MIN.get(kind)
    unit = QUANTITY_KINDS[kind][0]
    if hi is not None and abs(x) > hi:
        raise ctx.error(path, f"|{path.rsplit('.', 1)[-1]}| <= {hi:g} {unit} (after unit conversion; the range of "
                        f"astrodyn's models)".replace("  ", " "), value)
    if lo is not None and x != 0 and abs(x) < lo:
        raise ctx.error(path, f"|{path.rsplit('.', 1)[-1]}| >= {lo:g} {unit} or 0 (after unit conversion)", value)
    if (read := _QUANTITIES_READ.get()) is not None:
        read.setdefault(path, []).append((kind, x))
    return x


_QUANTITIES_READ: contextvars.ContextVar[dict[str, list[tuple[str, float]]] | None] = contextvars.ContextVar(
    "astrodyn_quantities_read", default=None)


@contextlib.contextmanager
def quantities_read() -> Iterator[dict[str, list[tuple[str, float]]]]:
    """While the block runs (in this thread or task), every quantity :func:`quantity` reads is
    noted in the dict it yields: key path as errors name it (``"scenario.rate"``,
    ``"bodies[0] (iss).orbit.a"``, ``"bodies[0] (iss).orbit.r[1]"`` for an element of a
    vector) -> ``[(kind, SI value), ...]`` in the order read.  The scenario loader reads every quantity of a config through
    :func:`quantity` at the key path of its TOML, so this is what two configs written
    differently resolve to (:func:`astrodyn.scenario.recorded.config_difference`)."""
    read: dict[str, list[tuple[str, float]]] = {}
    token = _QUANTITIES_READ.set(read)
    try:
        yield read
    finally:
        _QUANTITIES_READ.reset(token)


VECTOR_STRING = re.compile(r"^\s*[\[(]([^\])]*)[\])]\s*(.*?)\s*$")


def vector(ctx: Ctx, value: Any, kind: str, n: int, path: str) -> np.ndarray:
    """n SI floats from a list of quantities or one string ``"[a, b, c] unit"``."""
    desc = f"a list of {n} values, each {QUANTITY_KINDS[kind][1]}"
    if isinstance(value, str) and len(value) <= MAX_STRING:
        m = VECTOR_STRING.match(value)
        if m:
            parts = [p.strip() for p in m.group(1).split(",")]
            if len(parts) == n and all(parts):
                unit = m.group(2)
                return np.array([quantity(ctx, f"{p} {unit}" if unit else number_or_str(p), kind, f"{path}[{i}]") for i, p in enumerate(parts)])
        raise ctx.error(path, f'{desc}, or a string like "[7000, 0, 0] km"', value)
    if not isinstance(value, list) or len(value) != n:
        raise ctx.error(path, desc, value)
    return np.array([quantity(ctx, v, kind, f"{path}[{i}]") for i, v in enumerate(value)], dtype=np.float64)


def number_or_str(text: str) -> float | str:
    try:
        return float(text)
    except ValueError:
        return text


def check(ctx: Ctx, ok: bool, path: str, expected: str, got: Any) -> None:
    if not ok:
        raise ctx.error(path, expected, got)


def field_name(ctx: Ctx, value: Any, path: str) -> str:
    if not isinstance(value, str) or not re.fullmatch(NAME_PATTERN, value) or value in (".", ".."):
        raise ctx.error(path, f"a name matching {NAME_PATTERN}", value)
    return value


def choice(ctx: Ctx, value: Any, allowed: tuple[str, ...], path: str) -> str:
    if not isinstance(value, str) or value not in allowed:
        hint = did_you_mean(value, allowed) if isinstance(value, str) else ""
        raise ctx.error(path, f"one of {', '.join(allowed)}{hint}", value)
    return value


def boolean(ctx: Ctx, value: Any, path: str) -> bool:
    if not isinstance(value, bool):
        raise ctx.error(path, "true or false", value)
    return value


def integer(ctx: Ctx, value: Any, path: str, lo: int, hi: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise ctx.error(path, f"an integer {lo} <= n <= {hi}", value)
    return value


def string(ctx: Ctx, value: Any, path: str, max_len: int = 4096) -> str:
    if not isinstance(value, str) or len(value) > max_len:
        raise ctx.error(path, f"a string of at most {max_len} characters", value)
    return value


QUAT_TOL = 1e-6  #: a given q must have | |q| - 1 | <= this; it is then normalized


def unit_quaternion(ctx: Ctx, value: Any, path: str) -> np.ndarray:
    """Euler parameters ``(e0, e1, e2, e3)``, scalar first, with ``| |q| - 1 | <=``
    :data:`QUAT_TOL`, returned normalized; the error names ``path`` and the norm."""
    q = vector(ctx, value, "dimensionless", 4, path)
    norm = float(np.linalg.norm(q))
    check(ctx, abs(norm - 1.0) <= QUAT_TOL, path,
          f"a unit quaternion, scalar first (| |q| - 1 | <= {QUAT_TOL:g}; |q| = {norm:.9g})", value)
    return q / norm
