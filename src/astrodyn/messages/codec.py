"""Validation, decoding and encoding of single messages, from the definitions in
:mod:`astrodyn.messages.definitions`; the fast check of the canonical state layout (the
logger's hot path); the message builders."""

from __future__ import annotations

import functools
import inspect
import json
import math
import operator
import re
import sys
import types
import typing
from collections.abc import Callable, Sequence
from typing import Any

import msgspec
import msgspec.inspect
import numpy as np

from astrodyn.messages.definitions import KIND_OF_SCHEMA_TITLE, MESSAGE_TYPES
from astrodyn.messages.errors import MessageError, show_value
from astrodyn.messages.keys import ATTITUDE_MODELS, MAX_SEQ, ORBIT_MODELS, kind_of_key

# ---------------------------------------------------------------------------------------
# Validation and decoding: msgspec, from the definitions above.  When msgspec refuses a
# message, :func:`_explain` reads the same definition to say which field is wrong, what it
# expected and what it got, e.g. ``orbit.r: expected array of 3 finite numbers, got [1.0, "x"]``.


def _is_number(x: Any) -> bool:
    """A finite JSON number that fits a float64 (an integer of 400 digits does not)."""
    if type(x) is int:
        return -_FLOAT64_MAX <= x <= _FLOAT64_MAX
    return type(x) is float and math.isfinite(x)


_FLOAT64_MAX = int(sys.float_info.max)


@functools.cache
def _fields(message_type: type[msgspec.Struct]) -> tuple[tuple[str, Any, bool], ...]:
    """(name, msgspec.inspect type, required) of each field, in definition order."""
    info = msgspec.inspect.type_info(message_type)
    out = []
    for f in info.fields:
        t = f.type
        if isinstance(t, msgspec.inspect.UnionType):  # X | UNSET: the optional field's own type
            t = next(a for a in t.types if not isinstance(a, msgspec.inspect.UnsetType))
        out.append((f.name, t, f.required))
    return tuple(out)


def _field_problem(kind: str, name: str, t: Any, x: Any) -> str | None:
    """What is wrong with value ``x`` of field ``name`` of type ``t``, or None."""
    ins = msgspec.inspect
    extra = {}
    if isinstance(t, ins.Metadata):
        extra, t = t.extra or {}, t.type
    where = f"{kind}.{name}"
    if isinstance(t, ins.FloatType):
        if not _is_number(x):
            return f"{where}: expected a finite number, got {show_value(x)}"
        if t.gt is not None and not x > t.gt:
            return f"{where}: expected > {float(t.gt)}, got {show_value(x)}"
        if t.ge is not None and not x >= t.ge:
            return f"{where}: expected >= {float(t.ge)}, got {show_value(x)}"
        return None
    if isinstance(t, ins.IntType):
        if type(x) is not int or (t.ge is not None and x < t.ge) or (t.le is not None and x > t.le):
            return f"{where}: expected an integer 0 <= {name} <= 2**53-1, got {show_value(x)}"
        return None
    if isinstance(t, ins.LiteralType):
        values = extra.get("values", t.values)
        if type(x) is not str or x not in values:
            return f"{where}: expected one of {', '.join(values)}, got {show_value(x)}"
        return None
    if isinstance(t, ins.ListType):
        lo, hi = t.min_length or 0, t.max_length
        n = str(lo) if lo == hi else f"{lo}..{hi}"
        if isinstance(t.item_type, ins.StrType):
            if type(x) is not list or not lo <= len(x) <= (hi or len(x)) or not all(type(c) is str for c in x):
                return f"{where}: expected array of {n} strings, got {show_value(x)}"
            return None
        if type(x) is not list or not lo <= len(x) <= (hi or len(x)) or not all(_is_number(c) for c in x):
            return f"{where}: expected array of {n} finite numbers, got {show_value(x)}"
        return None
    if isinstance(t, ins.StrType):
        if type(x) is not str or (t.max_length is not None and len(x) > t.max_length) or (
                t.pattern is not None and not re.search(t.pattern, x)):
            return f"{where}: expected {extra.get('expected', 'a string')}, got {show_value(x)}"
        return None
    if isinstance(t, ins.DictType):
        key_t, value_t = t.key_type, t.value_type
        if type(x) is not dict or not all(
                _field_problem(kind, name, key_t, k) is None and _field_problem(kind, name, value_t, v) is None
                for k, v in x.items()):
            return f"{where}: expected {extra.get('expected', 'an object')}, got {show_value(x)}"
        return None
    return None  # pragma: no cover - every field type of the definitions is handled above


def _explain(kind: str, msg: Any, fallback: str) -> MessageError:
    """The first problem of decoded JSON ``msg`` against message type ``kind``, read off its
    definition; ``fallback`` (msgspec's own text) if none is found."""
    if type(msg) is not dict:
        return MessageError(f"{kind}: expected a JSON object, got {show_value(msg)}")
    fields = _fields(MESSAGE_TYPES[kind])
    for name, _, required in fields:
        if required and name not in msg:
            return MessageError(f"{kind}.{name}: expected a value (required field), got nothing")
    known = [name for name, _, _ in fields]
    extra = sorted(str(k) for k in msg if k not in known)
    if extra:
        return MessageError(f"{kind}: expected only fields {', '.join(known)}, got extra {', '.join(extra)}")
    for name, t, _ in fields:
        if name in msg:
            problem = _field_problem(kind, name, t, msg[name])
            if problem:
                return MessageError(problem)
    fallback = re.sub(r" - at `\$[^`]*`$", "", fallback)
    return MessageError(fallback if fallback.startswith(f"{kind}.") else f"{kind}: {fallback}")


@functools.cache
def _decoder(kind: str) -> msgspec.json.Decoder:
    return msgspec.json.Decoder(MESSAGE_TYPES[kind])


_OPTIONAL_FIELDS = frozenset(t for t in MESSAGE_TYPES.values() if t.__struct_config__.omit_defaults)


def _as_dict(obj: msgspec.Struct) -> dict:
    return msgspec.to_builtins(obj) if type(obj) in _OPTIONAL_FIELDS else msgspec.structs.asdict(obj)


def _kind(key_or_kind: str) -> str:
    if not isinstance(key_or_kind, str):
        raise MessageError(f"key: expected a key or message kind string, got {type(key_or_kind).__name__}")
    return _kind_of_str(key_or_kind)


@functools.lru_cache(maxsize=65536)
def _kind_of_str(key_or_kind: str) -> str:
    if key_or_kind in MESSAGE_TYPES:
        return key_or_kind
    if key_or_kind in KIND_OF_SCHEMA_TITLE:  # a schema name works too
        return KIND_OF_SCHEMA_TITLE[key_or_kind]
    kind = kind_of_key(key_or_kind)
    if kind is None:
        raise MessageError(f"key: expected a key that carries messages (orbit, attitude, crosscheck, @event, @status), got {key_or_kind!r}")
    return kind


def validate(msg: Any, key_or_kind: str) -> dict:
    """Check a decoded message (a dict) against its type; return it or raise MessageError.

    ``key_or_kind``: a key (``astrodyn/s/sat1/orbit``), a kind (``"orbit"``, ``"attitude"``,
    ``"crosscheck"``, ``"event"``, ``"status"``) or a schema name (``"astrodyn.OrbitState"``).
    """
    if type(msg) is dict and type(key_or_kind) is str:
        keys = tuple(msg)
        by_keys = _VALID_ONLY.get(key_or_kind)
        if ((by_keys is not None and by_keys.get(keys)) or _check_for(keys, key_or_kind, _VALID))(msg):
            return msg
    return _validate_reference(msg, key_or_kind)


def _validate_reference(msg: Any, key_or_kind: str) -> dict:
    """:func:`validate` by msgspec's own validation (the reference of the plain check)."""
    kind = _kind(key_or_kind)
    if type(msg) is dict and "seq" in msg and type(msg["seq"]) is float and msg["seq"].is_integer():
        msg["seq"] = int(msg["seq"])  # JSON Schema's "integer" admits 3.0
    try:
        if type(msg) is not dict or _find_nonfinite(msg, "") is not None:  # msgspec.convert admits inf
            raise msgspec.ValidationError("not a dict of finite values")
        msgspec.convert(msg, MESSAGE_TYPES[kind], strict=True)
    except msgspec.ValidationError as exc:
        raise _explain(kind, msg, str(exc)) from None
    return msg


_DECODE_JSON = msgspec.json.Decoder().decode
_CONSTRAINTS = ("gt", "ge", "lt", "le", "multiple_of", "min_length", "max_length", "tz")


def _unpatterned(tp: Any, name: str, patterns: dict[str, str]) -> Any:
    """Annotation ``tp`` of field ``name`` without the pattern of its string (entered in
    ``patterns``); an optional field's ``X | UnsetType`` keeps its union."""
    if typing.get_origin(tp) in (typing.Union, types.UnionType):
        return functools.reduce(operator.or_, (_unpatterned(a, name, patterns) for a in typing.get_args(tp)))
    if typing.get_origin(tp) is not typing.Annotated:
        return tp
    base, *metas = typing.get_args(tp)
    kept = []
    for meta in metas:
        if isinstance(meta, msgspec.Meta) and meta.pattern is not None:
            patterns[name] = meta.pattern
            meta = msgspec.Meta(**{k: getattr(meta, k) for k in _CONSTRAINTS if getattr(meta, k) is not None})
        kept.append(meta)
    return typing.Annotated[(base, *kept)]


def _has_pattern(schema: Any) -> bool:
    """True if a JSON Schema (nested dicts and lists) still states a string pattern."""
    if isinstance(schema, dict):
        return isinstance(schema.get("pattern"), str) or any(_has_pattern(v) for v in schema.values())
    if isinstance(schema, list):
        return any(_has_pattern(v) for v in schema)
    return False


@functools.cache
def _loose_decoding(kind: str) -> tuple[Any, tuple, Any]:
    """``(decode, tests, as_dict)`` for ``kind``: msgspec's decoder of the message type as
    defined but without the patterns of its top-level string fields (the same fields, order,
    constraints, config and ``__post_init__``: a type derived from the definition, not a
    second one), ``(field, known, test)`` of each pattern (:func:`_pattern_test`, as the
    generated checks test them), and the conversion to a dict.  A type with patterns
    elsewhere (dict keys, list items) keeps its own decoder and no tests."""
    message_type = MESSAGE_TYPES[kind]
    as_dict = msgspec.to_builtins if message_type.__struct_config__.omit_defaults else msgspec.structs.asdict
    patterns: dict[str, str] = {}
    hints = typing.get_type_hints(message_type, include_extras=True)
    fields = [(name, _unpatterned(hints[name], name, patterns), default)
              for name, default in zip(message_type.__struct_fields__,
                                       (msgspec.NODEFAULT,) * (len(message_type.__struct_fields__)
                                                               - len(message_type.__struct_defaults__))
                                       + message_type.__struct_defaults__)]
    config = message_type.__struct_config__
    namespace = {"__post_init__": message_type.__post_init__} if hasattr(message_type, "__post_init__") else {}
    loose = msgspec.defstruct(message_type.__name__, fields, namespace=namespace, omit_defaults=config.omit_defaults,
                              forbid_unknown_fields=config.forbid_unknown_fields)
    if not patterns or _has_pattern(msgspec.json.schema(loose)):
        return _decoder(kind).decode, (), as_dict
    tests = tuple((name, *_pattern_test(pattern)) for name, pattern in patterns.items())
    return msgspec.json.Decoder(loose).decode, tests, as_dict


#: key, kind or schema name -> :func:`_loose_decoding` of its kind (bounded, as ``_TABLES``)
_LOOSE: dict[str, tuple[Any, tuple, Any]] = {}


def _loose_for(key_or_kind: str) -> tuple[Any, tuple, Any] | None:
    try:
        kind = _kind_of_str(key_or_kind)
    except MessageError:
        return None
    if len(_LOOSE) >= 65536:
        _LOOSE.clear()
    found = _LOOSE[key_or_kind] = _loose_decoding(kind)
    return found


def _reject_constant(name: str) -> Any:
    raise MessageError(f"payload: expected JSON numbers, got {name}")


def _finite_float(text: str) -> float:
    x = float(text)
    if not math.isfinite(x):
        raise ValueError(f"expected finite numbers, got {text[:40]} (beyond float64)")
    return x


def _no_constant(name: str) -> Any:
    raise ValueError(f"expected finite numbers, got {name} (not JSON)")


def parse_json(data: bytes | bytearray | str, finite: bool = False) -> Any:
    """``json.loads`` of text from outside (a bus payload, a child's output line, a file),
    with one error for every way it can fail: ``ValueError`` also for JSON nested past the
    parser's depth (``"[" * 100000`` raised RecursionError, which the callers' ``except
    ValueError`` let through: one such query ended the logger or ``serve``) and for bad UTF-8.
    ``finite``: numbers that are not finite floats (``NaN``, ``Infinity``, which JSON does
    not have, and ``1e999``, which overflows) are a ``ValueError`` too."""
    try:
        if finite:
            return json.loads(data, parse_float=_finite_float, parse_constant=_no_constant)
        return json.loads(data)
    except RecursionError:
        raise ValueError("expected JSON, got values nested past the parser's depth") from None
    except TypeError as exc:  # not text at all
        raise ValueError(f"expected JSON text, got {type(data).__name__}") from exc


def json_field(data: bytes | bytearray | str, name: str) -> Any:
    """The value of field ``name`` of the JSON object ``data`` from outside (a payload, a
    line of a file), or None when ``data`` is not JSON (by :func:`parse_json`'s rules), not
    an object, or has no such field.  For reading one field of something that may be
    hostile, where any of these just means "not given"; the caller checks the value."""
    try:
        obj = parse_json(data)
    except ValueError:
        return None
    return obj.get(name) if isinstance(obj, dict) else None


def decode(data: bytes | bytearray | memoryview, key_or_kind: str) -> dict:
    """Parse a payload and validate it against its message type; return it as a dict (fields
    in definition order; optional fields of a Status only when present).

    Raises MessageError naming the field for anything that is not the message type of
    ``key_or_kind``: invalid UTF-8, invalid JSON, NaN / Infinity literals, numbers beyond
    float64, missing or extra fields, a wrong type or range.

    The payload is first decoded by :func:`_loose_decoding`'s decoder (the definition without
    its string patterns, which msgspec tests by calling ``re``), the patterns then tested on
    the decoded strings; whatever that refuses, the decoder of the definition decides.
    """
    loose = _LOOSE.get(key_or_kind) if type(key_or_kind) is str else None
    if loose is None and type(key_or_kind) is str:
        loose = _loose_for(key_or_kind)
    if loose is not None:
        loose_decode, tests, as_dict = loose
        try:
            obj = loose_decode(data)
        except Exception:  # whatever it is, the decoder of the definition below says it
            obj = None
        if obj is not None:
            for name, known, test in tests:
                x = getattr(obj, name)
                if type(x) is str and not (x in known or test(x)):
                    break
            else:
                return as_dict(obj)
    kind = _kind(key_or_kind)
    try:
        return _as_dict(_decoder(kind).decode(data))
    except (msgspec.DecodeError, ValueError) as exc:  # ValidationError; UnicodeDecodeError in a key
        fallback = str(exc)
    try:  # the slow path: say what is wrong, in terms of the definition
        msg = json.loads(bytes(data), parse_constant=_reject_constant)
    except MessageError:
        raise
    except (ValueError, TypeError, RecursionError) as exc:  # JSONDecodeError, UnicodeDecodeError
        raise MessageError(f"payload: expected UTF-8 JSON, got {show_value(bytes(data[:40]).decode('utf-8', 'replace'))} ({exc})") from None
    if type(msg) is dict and type(msg.get("seq")) is float and msg["seq"].is_integer():
        msg["seq"] = int(msg["seq"])  # JSON Schema's "integer" admits 3.0: valid, normalized
        return validate(msg, kind)
    raise _explain(kind, msg, fallback)


def is_valid(data: bytes | dict, key_or_kind: str) -> bool:
    """True if ``data`` (payload bytes, or an already decoded dict) is a valid message."""
    try:
        if isinstance(data, dict):
            validate(data, key_or_kind)
        else:
            decode(data, key_or_kind)
    except MessageError:
        return False
    return True


# ---------------------------------------------------------------------------------------
# Fast check of the canonical layout (the logger's hot path)
#
# The batch encoders write every state in one fixed layout: keys in schema order, no
# spaces, floats by repr.  A state in that layout is judged by one precompiled regex
# instead of json.loads + the validator (about 10x cheaper); anything else -- another
# key order, spaces, integers where floats are usual, escapes, garbage -- falls back to
# :func:`decode`, so the hand-written validator and its error messages judge it.
#
# Finite by construction: a fixed-notation number has at most 17 integer digits and an
# exponent-notation number one mantissa digit and an exponent <= +307 (or any negative
# exponent, which underflows to 0 or a subnormal at worst), so every number the pattern
# admits parses to a finite float64.  Every string the pattern admits is also valid JSON
# (no leading zeros: RFC 8259 section 6) that json.loads + the validator accept with the
# same t and seq: tests/test_messages_fast.py checks both directions with hypothesis.

_FAST_NUM = (
    rb"-?(?:(?:0|[1-9][0-9]{0,16})\.[0-9]{1,24}"
    rb"|[0-9](?:\.[0-9]{1,24})?[eE](?:-[0-9]{1,3}|\+?(?:[0-9]{1,2}|[12][0-9]{2}|30[0-7])))"
)
_FAST_SEQ = rb"(0|[1-9][0-9]{0,15})"


def _fast_enum(names: Sequence[str]) -> bytes:
    return b"(?:" + b"|".join(re.escape(n.encode()) for n in names) + b")"


_FAST_ORBIT = re.compile(
    rb'\{"t":(' + _FAST_NUM + rb'),"seq":' + _FAST_SEQ + rb',"model":"' + _fast_enum(ORBIT_MODELS)
    + rb'","r":\[' + _FAST_NUM + rb"," + _FAST_NUM + rb"," + _FAST_NUM
    + rb'\],"v":\[' + _FAST_NUM + rb"," + _FAST_NUM + rb"," + _FAST_NUM
    + rb'\],"mu":(' + _FAST_NUM + rb'),"frame":"[A-Za-z0-9_.\-]{1,128}"\}'
)
_FAST_ATTITUDE = re.compile(
    rb'\{"t":(' + _FAST_NUM + rb'),"seq":' + _FAST_SEQ + rb',"model":"' + _fast_enum(ATTITUDE_MODELS)
    + rb'","q":(\[' + _FAST_NUM + rb"," + _FAST_NUM + rb"," + _FAST_NUM + rb"," + _FAST_NUM
    + rb'\]),"w":\[' + _FAST_NUM + rb"," + _FAST_NUM + rb"," + _FAST_NUM + rb"\]\}"
)
_attitude_rule = MESSAGE_TYPES["attitude"].rule


def _fast_check(pattern: re.Pattern, rule: Callable[[bytes], bool]) -> Callable[[bytes], tuple[float, int] | None]:
    """The fast checker of one state kind: ``(t, seq)`` of a payload that ``pattern`` (its
    canonical layout, groups t, seq and one more) matches whole, with ``seq <= MAX_SEQ`` and
    ``rule`` true of the third group; None for anything else (:func:`decode` judges it)."""
    fullmatch = pattern.fullmatch

    def check(data: bytes) -> tuple[float, int] | None:
        m = fullmatch(data)
        if m is None:
            return None
        t, seq, more = m.groups()
        seq = int(seq)
        if seq > MAX_SEQ or not rule(more):
            return None
        return float(t), seq

    return check


def _positive_mu(mu: bytes) -> bool:
    return float(mu) > 0.0


def _unit_q(q: bytes) -> bool:
    # q: four floats (every number of the grammar has a fraction or an exponent), parsed in
    # one call; |q| = 1 by AttitudeState's own rule, so both paths agree to the last bit
    return _attitude_rule(_DECODE_JSON(q)) is None


#: kind -> fast checker; kinds without one always take the :func:`decode` path.
FAST_CHECKS = {"orbit": _fast_check(_FAST_ORBIT, _positive_mu), "attitude": _fast_check(_FAST_ATTITUDE, _unit_q)}


def check_state(data: bytes, kind: str) -> tuple[float, int]:
    """``(t, seq)`` of a valid message of ``kind`` ("orbit", "attitude", ...); MessageError if not.

    Same verdict as :func:`decode` (same error text for a bad payload), but payloads in the
    batch encoders' canonical layout (see :func:`encode_orbit_batch`) are checked by a
    precompiled regex plus the numeric rules it cannot state (``mu > 0``, ``|q| = 1``,
    ``seq <= 2**53-1``) instead of a full parse: 1-4 us instead of 10-30 us per state
    (shared, loaded 2-core machine).  ``data`` must be ``bytes``.
    """
    fast = FAST_CHECKS.get(kind)
    if fast is not None and type(data) is bytes:
        found = fast(data)
        if found is not None:
            return found
    msg = decode(data, kind)
    return msg["t"], msg["seq"]


# ---------------------------------------------------------------------------------------
# Plain messages: checks generated from the definitions (the fast paths of encode,
# validate and the builders)
#
# The wire text is what ``json.JSONEncoder`` writes (compact, ``ensure_ascii=False``, dict
# order, floats by ``repr``).  msgspec's C encoder writes the same bytes about ten times
# faster for a *plain* message -- a dict whose values have exactly the Python types of
# their fields (float, int, str, lists of them) -- except for the layout of some floats:
# the digits are the same shortest round-trip digits, but msgspec writes ``1e-05`` as
# ``0.00001``, ``1e-07`` as ``1e-7`` and ``1e+16`` as ``1e16``.  Both write a float x
# alike if and only if |x| < 1e-9 (exponents of two or three digits, e.g. ``1e-10``, and
# 0.0) or 1e-4 <= |x| < 1e16 (tests/test_encode_single.py: random bit patterns, the
# boundaries; string escapes agree for every code point).  A message with a float outside
# that range is written by msgspec and then laid out as ``repr`` by the compiled
# :func:`astrodyn.messages.floatlayout.as_repr_layout` (about 0.05 us); where the package
# was built without a C compiler, each such float is handed to msgspec as raw text instead,
# ``repr``'s (:func:`_repr_text`; about 0.7 us more per message).  For each message type
# and tuple of keys a check is generated from the definition -- one straight-line function,
# a type test and a few comparisons per value, instead of a walk over the message.  By ``mode``:
#
# * ``_TEXT``: the message is plain with finite floats; returns msgspec's bytes of it
#   (laid out as ``repr``, or of a copy with ``Raw`` text for the floats outside the range,
#   if any), else None;
# * ``_VALID``: every float is finite and every constraint of the definition holds (bounds,
#   literal values, lengths, patterns, ``__post_init__``), so msgspec's validation (of
#   the dict, or of its bytes) accepts it; returns True, else None;
# * ``_TEXT | _VALID``: both; returns the bytes, else None.
#
# What a check refuses takes the reference path (json, msgspec's validation, the error
# messages of before), so a refusal costs time, never a difference.

_TEXT = 1
_VALID = 2
_LAID_OUT = 4  # (of a value test) the text goes through the layout pass, which refuses NaN and inf
#: the floats whose ``repr`` and msgspec's text agree: |x| < tiny or lo <= |x| < hi
_TEXT_RANGE = (1e-9, 1e-4, 1e16)
_MSGSPEC_ENCODE = msgspec.json.Encoder().encode
_UNROLL = 8  # fixed-length lists up to this length are tested item by item, without a loop
#: the largest finite float: ``-MAX <= x <= MAX`` is the finite test (NaN fails it), with
#: constants, about 3x cheaper than ``-_inf < x < _inf`` on global names
_MAX_FLOAT = sys.float_info.max


def _in_text_range(x: str) -> str:
    """Source of the test that float ``x`` (a name) is written alike by msgspec and ``repr``."""
    tiny, lo, hi = _TEXT_RANGE
    return f"({lo!r} <= {x} < {hi!r} or {-hi!r} < {x} <= {-lo!r} or {-tiny!r} < {x} < {tiny!r})"


_Raw = msgspec.Raw

try:  # the compiled layout pass (setup.py builds it; optional)
    from astrodyn.messages.floatlayout import as_repr_layout as _LAYOUT
except ImportError:  # built without a C compiler: raw ``repr`` text instead, same bytes
    _LAYOUT = None

#: Whether the compiled layout pass is in use (False where the package was built without a
#: C compiler: the same bytes, about 0.6 us more per message with a float outside the range).
LAYOUT_COMPILED = _LAYOUT is not None


def _as_text(x: str) -> str:
    """Source of float ``x`` as msgspec is to write it: itself in the text range, else
    ``repr``'s text as raw JSON."""
    return f"({x} if {_in_text_range(x)} else {_repr_text(x)})"


def _repr_text(x: str) -> str:
    """Source of ``repr``'s text of float ``x`` (a name) as raw JSON: ``_Raw(f"{x!r}")``."""
    return f'_Raw(f"{{{x}!r}}")'



def _bound_terms(x: str, t: Any) -> list[str]:
    return [f"{x} {op} {bound!r}" for op, bound in ((">", t.gt), (">=", t.ge), ("<", t.lt), ("<=", t.le))
            if bound is not None]


def _length_terms(x: str, t: Any) -> list[str]:
    return [f"len({x}) {op} {n!r}" for op, n in ((">=", t.min_length), ("<=", t.max_length)) if n is not None]


@functools.lru_cache(maxsize=64)
def _pattern_test(pattern: str) -> tuple[set, Any]:
    """``(known, test)``: ``test(s)`` is whether ``re.search(pattern, s)`` finds a match (as
    msgspec tests a pattern); the strings that matched, up to 4096, are added to ``known``
    (names repeat: frames, processes), which the generated checks look up first."""
    search = re.compile(pattern).search
    known: set[str] = set()

    def test(s: str) -> bool:
        if search(s) is None:
            return False
        if len(known) < 4096:
            known.add(s)
        return True

    return known, test


def _value_test(x: str, t: Any, mode: int, consts: dict, indent: str, rebind: bool = True,
                flag: int = 1) -> list[str] | None:
    """Source lines that return None unless the value named ``x`` passes field type ``t``
    (msgspec.inspect) for ``mode``; with ``_TEXT``, a float outside the text range sets
    bit ``flag`` of ``fix`` (its field is to be replaced) and (``rebind``) is replaced by
    its ``repr`` as raw text; with ``_LAID_OUT``, a float is not tested finite (the layout
    pass refuses msgspec's ``null`` for NaN and inf).  None for a type or constraint the
    generator does not cover."""
    ins = msgspec.inspect
    extra = {}
    if isinstance(t, ins.Metadata):
        extra, t = t.extra or {}, t.type
    fail = [f"{indent}    return None"]
    if isinstance(t, (ins.FloatType, ins.IntType)):
        if t.multiple_of is not None:
            return None
        bounds = " and ".join([""] + _bound_terms(x, t)) if mode & _VALID else ""
        if isinstance(t, ins.IntType):
            return [f"{indent}if not (type({x}) is int{bounds}):", *fail]
        finite_term = "" if mode & _LAID_OUT else f" and {-_MAX_FLOAT!r} <= {x} <= {_MAX_FLOAT!r}"
        finite = [f"{indent}if not (type({x}) is float{finite_term}{bounds}):", *fail]
        if not mode & _TEXT:
            return finite
        return [f"{indent}if not (type({x}) is float and {_in_text_range(x)}{bounds}):",
                *("    " + line for line in finite), *([f"{indent}    {x} = {_repr_text(x)}"] if rebind else []),
                f"{indent}    fix |= {flag}"]
    if isinstance(t, ins.LiteralType) and all(type(v) is str for v in t.values):
        if not mode & _VALID:
            return [f"{indent}if type({x}) is not str:", *fail]
        name = f"_values{len(consts)}"
        consts[name] = frozenset(extra.get("values", t.values))
        return [f"{indent}if not (type({x}) is str and {x} in {name}):", *fail]
    if isinstance(t, ins.StrType):
        terms = [f"type({x}) is str"]
        if mode & _VALID:
            terms += _length_terms(x, t)
            if t.pattern is not None:
                known, test = f"_known{len(consts)}", f"_pattern{len(consts)}"
                consts[known], consts[test] = _pattern_test(t.pattern)
                terms.append(f"({x} in {known} or {test}({x}))")
        return [f"{indent}if not ({' and '.join(terms)}):", *fail]
    return None


def _is_float(t: Any) -> bool:
    ins = msgspec.inspect
    return isinstance(t.type if isinstance(t, ins.Metadata) else t, ins.FloatType)


def _rule_call(message_type: type[msgspec.Struct], given: dict[str, str]) -> str | None:
    """Source of the call of ``message_type.rule`` (the rules its field types cannot state,
    :mod:`astrodyn.messages.definitions`) on the values named in ``given`` (field -> name),
    or None if it has no ``rule`` or the rule needs a field that is not given."""
    rule = message_type.__dict__.get("rule")
    if not isinstance(rule, staticmethod):
        return None
    params = inspect.signature(rule.__func__).parameters
    if any(name not in given for name in params):
        return None
    return f"_rule({', '.join(given[name] for name in params)})"


def _check_source(message_type: type[msgspec.Struct], keys: tuple[str, ...], mode: int) -> tuple[str, dict] | None:
    """``(source, globals)`` of ``plain(msg)`` (see above) for dicts of ``message_type`` with
    exactly the fields ``keys`` in this order, or None if the generator does not cover one."""
    ins = msgspec.inspect
    fields = _fields(message_type)
    types = {name: t for name, t, _ in fields}
    named = tuple(name for name, _, _ in fields if name in keys)  # the keys, as the definition spells them
    if named != keys or any(required and name not in keys for name, _, required in fields):
        return None  # unknown, missing or reordered fields: the reference path says what
    consts: dict[str, Any] = {"_Raw": _Raw, "_encode": _MSGSPEC_ENCODE, "_layout": _LAYOUT}
    # With the compiled layout pass, floats are only checked finite and every message with a
    # float field goes through the pass; without it, floats outside the text range set ``fix``.
    value_mode = mode & ~_TEXT | _LAID_OUT if _LAYOUT is not None and mode & _TEXT else mode
    names = [f"v{i}" for i in range(len(keys))]
    body = [f"    {', '.join(names)}, = msg.values()", *(["    fix = 0"] if value_mode & _TEXT else [])]
    as_text = []  # (bit of fix, key, value of the copy with raw text for floats outside the range)
    for i, (x, key) in enumerate(zip(names, keys)):
        t = types[key]
        inner = t.type if isinstance(t, ins.Metadata) else t
        flag = 1 << i
        if not isinstance(inner, ins.ListType):
            lines = _value_test(x, t, value_mode, consts, "    ", flag=flag)
            if _is_float(t):
                as_text.append((flag, key, x))
        elif inner.min_length is not None and inner.min_length == inner.max_length <= _UNROLL:  # r, q: unrolled
            items = [f"{x}_{k}" for k in range(inner.min_length)]
            tests = [_value_test(e, inner.item_type, value_mode, consts, "    ", flag=flag) for e in items]
            lines = None if None in tests else [
                f"    if type({x}) is not list or len({x}) != {len(items)}:", "        return None",
                f"    {', '.join(items)}, = {x}", *(line for test in tests for line in test)]
            if _is_float(inner.item_type):
                as_text.append((flag, key, f"[{', '.join(items)}]"))
        else:
            test = _value_test("e", inner.item_type, value_mode, consts, "        ", rebind=False, flag=flag)  # copied below
            lengths = "".join(f" or not {term}" for term in _length_terms(x, inner)) if mode & _VALID else ""
            lines = None if test is None else [f"    if type({x}) is not list{lengths}:", "        return None",
                                               f"    for e in {x}:", *test]
            if _is_float(inner.item_type):
                as_text.append((flag, key, f"[{_as_text('e')} for e in {x}]"))
        if lines is None or isinstance(inner, ins.ListType) and isinstance(inner.item_type, ins.Metadata):
            return None
        body += lines
    if mode & _VALID and hasattr(message_type, "__post_init__"):  # a rule the field types cannot state
        given = {k: f"msg[{k!r}]" if mode & _TEXT and _is_float(types[k]) else x for k, x in zip(named, names)}  # not Raw
        call = _rule_call(message_type, given)
        if call is not None:  # the rule itself, on the values
            consts["_rule"] = message_type.__dict__["rule"].__func__
            body += ["    try:", f"        if {call} is not None:", "            return None",
                     "    except Exception:", "        return None"]
        else:  # a __post_init__ without a rule function: build the Struct to run it
            consts["_struct"] = message_type
            args = ", ".join(f"{k}={x}" for k, x in given.items())
            body += ["    try:", f"        _struct({args})", "    except Exception:", "        return None"]
    if not mode & _TEXT:
        return "def plain(msg):\n" + "\n".join([*body, "    return True"]) + "\n", consts
    encode = "_encode(msg)"
    if as_text and _LAYOUT is not None:  # msgspec's text laid out as repr
        encode = "_layout(_encode(msg))"
    elif as_text:  # a copy with the raw text of the floats outside the range, in the fields that have one
        body += ["    if fix:", "        msg = msg.copy()",
                 *(f"        if fix & {flag}:\n            msg[{key!r}] = {text}" for flag, key, text in as_text)]
    body += ["    try:", f"        return {encode}",
             "    except ValueError:  # a lone surrogate (UnicodeEncodeError): the reference path says so",
             "        return None"]
    return "def plain(msg):\n" + "\n".join(body) + "\n", consts


@functools.lru_cache(maxsize=1024)
def _generated_check(kind: str, keys: tuple[str, ...], mode: int) -> Any:
    found = _check_source(MESSAGE_TYPES[kind], keys, mode)
    if found is None:
        return None
    source, namespace = found
    exec(compile(source, f"<plain check of {kind}, mode {mode}>", "exec"), namespace)
    plain = namespace["plain"]
    plain.source = source  # for the curious reader (and the tests)
    return plain


@functools.lru_cache(maxsize=65536)
def _plain_check(keys: tuple, key_or_kind: str | None, mode: int) -> Any:
    """The generated ``plain(msg)`` for dicts with the keys ``keys`` (in this order) on
    ``key_or_kind`` (a key, kind or schema name; None: the first message type whose fields
    they are), for ``mode`` (``_TEXT``, ``_VALID`` or both); None if there is none."""
    if key_or_kind is None:
        kinds = [kind for kind, t in MESSAGE_TYPES.items() if set(keys) <= set(t.__struct_fields__)]
    else:
        try:
            kinds = [_kind_of_str(key_or_kind)]
        except MessageError:
            return None
    for kind in kinds:
        plain = _generated_check(kind, keys, mode)
        if plain is not None:
            return plain
    return None


def _refuse(msg: dict) -> None:
    """The check of a key layout that has no generated one: the reference path decides."""
    return None


#: The per-call lookup of the generated checks: mode -> key, kind or schema name (None: any
#: kind, for :func:`encode` without one) -> tuple of keys -> check (or :func:`_refuse`): two
#: dict lookups on the caller's strings (their hashes are cached) instead of resolving the
#: key and hashing an lru_cache key.  Every key or name of one kind shares the kind's table
#: (``_BY_KIND``); both are bounded (cleared when full: unusual layouts only cost time).
_TABLES: dict[int, dict[str | None, dict[tuple, Any]]] = {_TEXT: {}, _VALID: {}, _TEXT | _VALID: {}}
_BY_KIND: dict[int, dict[str | None, dict[tuple, Any]]] = {mode: {None: {}} for mode in _TABLES}
for _mode in _TABLES:
    _TABLES[_mode][None] = _BY_KIND[_mode][None]
_ANY_TEXT = _TABLES[_TEXT][None]
_TEXT_VALID = _TABLES[_TEXT | _VALID]
_VALID_ONLY = _TABLES[_VALID]


def _check_for(keys: tuple, key_or_kind: str | None, mode: int) -> Any:
    """The check of ``keys`` on ``key_or_kind`` for ``mode`` (:func:`_plain_check`, or
    :func:`_refuse`), entered in ``_TABLES``."""
    if key_or_kind is None:
        kind = None
    else:
        try:
            kind = _kind_of_str(key_or_kind)
        except MessageError:
            return _refuse
    by_kind = _BY_KIND[mode]
    by_keys = by_kind.get(kind)
    if by_keys is None:
        by_keys = by_kind[kind] = {}
    if len(by_keys) >= 4096:
        by_keys.clear()  # in place: the tables refer to it
    plain = by_keys[keys] = _plain_check(keys, kind, mode) or _refuse
    tables = _TABLES[mode]
    if len(tables) >= 65536:
        tables.clear()
        tables[None] = by_kind[None]
    tables[key_or_kind] = by_keys
    return plain


# ---------------------------------------------------------------------------------------
# Encoding


def _to_json_default(x: Any) -> Any:
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.floating):
        return float(x)
    if isinstance(x, np.bool_):
        return bool(x)
    raise TypeError(f"expected JSON-serializable values, got {type(x).__name__}")


def _find_nonfinite(obj: Any, path: str) -> str | None:
    if isinstance(obj, float) or isinstance(obj, np.floating):
        return None if math.isfinite(obj) else path
    if isinstance(obj, dict):
        for k, v in obj.items():
            found = _find_nonfinite(v, f"{path}.{k}" if path else str(k))
            if found:
                return found
    if isinstance(obj, (list, tuple, np.ndarray)):
        for i, v in enumerate(obj.tolist() if isinstance(obj, np.ndarray) else obj):
            found = _find_nonfinite(v, f"{path}[{i}]")
            if found:
                return found
    return None


_ENCODER = json.JSONEncoder(separators=(",", ":"), allow_nan=False, ensure_ascii=False, default=_to_json_default)


def encode(msg: dict, kind: str | None = None) -> bytes:
    """Compact UTF-8 JSON of ``msg``; floats by ``repr`` (exact round trip).

    numpy arrays and scalars are accepted. NaN/inf anywhere raise MessageError naming the
    field. With ``kind`` (a kind, key or schema name) the encoded bytes are also validated.

    A plain message (see "Plain messages" above: exact types, floats in the range where
    msgspec's text is ``repr``'s) is written by msgspec, validated on the values (what
    :func:`decode` of the bytes would check, generated from the definition); anything
    else by ``json`` and validated by :func:`decode` -- the same bytes and errors.
    """
    if type(msg) is dict:
        keys = tuple(msg)
        if kind is None:
            data = (_ANY_TEXT.get(keys) or _check_for(keys, None, _TEXT))(msg)
        elif type(kind) is str:
            by_keys = _TEXT_VALID.get(kind)
            data = ((by_keys is not None and by_keys.get(keys)) or _check_for(keys, kind, _TEXT | _VALID))(msg)
        else:
            data = None
        if data is not None:
            return data
    return _encode_reference(msg, kind)


def _encode_reference(msg: Any, kind: str | None = None) -> bytes:
    """:func:`encode` by ``json`` and :func:`decode` (the reference of the plain path)."""
    try:
        data = _ENCODER.encode(msg).encode("utf-8")
    except ValueError:
        where = _find_nonfinite(msg, kind or "message") or kind or "message"
        raise MessageError(f"{where}: expected a finite number, got a NaN or infinity") from None
    except TypeError as exc:
        raise MessageError(f"{kind or 'message'}: {exc}") from None
    if kind is not None:
        decode(data, kind)  # validates exactly what goes out (numpy values included)
    return data


def checked_floats(x: Any, n: int, kind: str, field: str) -> list[float]:
    try:
        a = np.asarray(x, dtype=float)
    except (TypeError, ValueError, OverflowError):  # not numbers; an integer beyond float64
        a = np.full(max(n, 1) + 1, np.nan)  # refused below
    if a.shape != (n,) or not np.all(np.isfinite(a)):
        raise MessageError(f"{kind}.{field}: expected array of {n} finite numbers, got {show_value(np.asarray(x).tolist() if np.ndim(x) else x)}")
    return a.tolist()


def checked_float(x: Any, kind: str, field: str) -> float:
    try:
        f = float(x)
    except (TypeError, ValueError, OverflowError):
        raise MessageError(f"{kind}.{field}: expected a finite number, got {show_value(x)}") from None
    if not math.isfinite(f):
        raise MessageError(f"{kind}.{field}: expected a finite number, got {f!r}")
    return f


def checked_int(x: Any, kind: str, field: str) -> int:
    expected = f"{kind}.{field}: expected an integer 0 <= {field} <= 2**53-1, got "
    if isinstance(x, (bool, np.bool_)):
        raise MessageError(expected + show_value(x))
    if isinstance(x, (float, np.floating)):
        if not (math.isfinite(x) and float(x).is_integer()):
            raise MessageError(expected + show_value(float(x)))
    elif not isinstance(x, (int, np.integer)):
        raise MessageError(expected + show_value(x))
    i = int(x)
    if not 0 <= i <= MAX_SEQ:
        raise MessageError(expected + show_value(i))
    return i


def _listed(x: Any) -> Any:
    """A new list of the items of a list, tuple or numpy array (for the builders' fast
    path, which then tests every item); anything else as it is (the slow path judges it)."""
    t = type(x)
    if t is list:
        return x.copy()
    if t is np.ndarray:
        return x.tolist()
    if t is tuple:
        return list(x)
    return x


def _built(msg: dict, kind: str) -> bool:
    """True if ``msg`` (a builder's dict, fields in definition order) is plain and valid as
    it is: the builder returns it without converting anything."""
    keys = tuple(msg)
    by_keys = _VALID_ONLY.get(kind)
    return ((by_keys is not None and by_keys.get(keys)) or _check_for(keys, kind, _VALID))(msg) is True


def orbit_message(t: float, seq: int, model: str, r: Any, v: Any, mu: float, frame: str = "GCRF") -> dict:
    """An ``astrodyn.OrbitState`` dict (validated): r in m, v in m/s, mu in m^3/s^2."""
    msg = {"t": t, "seq": seq, "model": model, "r": _listed(r), "v": _listed(v), "mu": mu, "frame": frame}
    if _built(msg, "orbit"):
        return msg
    return _orbit_checked(t, seq, model, r, v, mu, frame)


def _orbit_checked(t: float, seq: int, model: str, r: Any, v: Any, mu: float, frame: str = "GCRF") -> dict:
    """orbit_message by conversion and msgspec's validation (the reference of the fast path)."""
    msg = {
        "t": checked_float(t, "orbit", "t"),
        "seq": checked_int(seq, "orbit", "seq"),
        "model": model,
        "r": checked_floats(r, 3, "orbit", "r"),
        "v": checked_floats(v, 3, "orbit", "v"),
        "mu": checked_float(mu, "orbit", "mu"),
        "frame": frame,
    }
    _validate_reference(msg, "orbit")
    return msg


def attitude_message(t: float, seq: int, model: str, q: Any, w: Any) -> dict:
    """An ``astrodyn.AttitudeState`` dict (validated): q scalar first, unit; w body rad/s."""
    msg = {"t": t, "seq": seq, "model": model, "q": _listed(q), "w": _listed(w)}
    if _built(msg, "attitude"):
        return msg
    return _attitude_checked(t, seq, model, q, w)


def _attitude_checked(t: float, seq: int, model: str, q: Any, w: Any) -> dict:
    """attitude_message by conversion and msgspec's validation (the reference of the fast path)."""
    msg = {
        "t": checked_float(t, "attitude", "t"),
        "seq": checked_int(seq, "attitude", "seq"),
        "model": model,
        "q": checked_floats(q, 4, "attitude", "q"),
        "w": checked_floats(w, 3, "attitude", "w"),
    }
    _validate_reference(msg, "attitude")
    return msg


def crosscheck_message(t: float, seq: int, dr: Any, dv: Any, reference: str = "rebound-ias15") -> dict:
    """An ``astrodyn.CrossCheck`` dict: dr = r_astrodyn - r_reference (m), dv likewise (m/s)."""
    dr_list, dv_list = _listed(dr), _listed(dv)
    if type(dr_list) is list and type(dv_list) is list and len(dr_list) == len(dv_list) == 3:
        try:
            msg = {"t": t, "seq": seq, "dr": dr_list, "dv": dv_list, "dr_norm": math.hypot(*dr_list),
                   "dv_norm": math.hypot(*dv_list), "reference": reference}
        except (TypeError, ValueError):  # not numbers: the checks below say which
            msg = None
        if msg is not None and _built(msg, "crosscheck"):
            return msg
    return _crosscheck_checked(t, seq, dr, dv, reference)


def _crosscheck_checked(t: float, seq: int, dr: Any, dv: Any, reference: str = "rebound-ias15") -> dict:
    """crosscheck_message by conversion and msgspec's validation (the reference of the fast path)."""
    dr_list = checked_floats(dr, 3, "crosscheck", "dr")
    dv_list = checked_floats(dv, 3, "crosscheck", "dv")
    msg = {
        "t": checked_float(t, "crosscheck", "t"),
        "seq": checked_int(seq, "crosscheck", "seq"),
        "dr": dr_list,
        "dv": dv_list,
        "dr_norm": math.hypot(*dr_list),
        "dv_norm": math.hypot(*dv_list),
        "reference": reference,
    }
    _validate_reference(msg, "crosscheck")
    return msg


def event_message(t: float, seq: int, process: str, kind: str, detail: str = "") -> dict:
    """An ``astrodyn.Event`` dict, e.g. ``event_message(12.5, 3, "orbit", "restart", "...")``."""
    msg = {"t": t, "seq": seq, "process": process, "kind": kind, "detail": detail}
    if _built(msg, "event"):
        return msg
    return _event_checked(t, seq, process, kind, detail)


def _event_checked(t: float, seq: int, process: str, kind: str, detail: str = "") -> dict:
    """event_message by conversion and msgspec's validation (the reference of the fast path)."""
    msg = {"t": checked_float(t, "event", "t"), "seq": checked_int(seq, "event", "seq"), "process": process, "kind": kind, "detail": detail}
    _validate_reference(msg, "event")
    return msg


def status_message(t: float, seq: int, state: str, real_time_factor: float, **optional: Any) -> dict:
    """An ``astrodyn.Status`` dict; optional fields: rate (Hz), messages, processes, detail."""
    msg = {
        "t": checked_float(t, "status", "t"),
        "seq": checked_int(seq, "status", "seq"),
        "state": state,
        "real_time_factor": checked_float(real_time_factor, "status", "real_time_factor"),
    }
    msg.update(optional)
    validate(msg, "status")
    return msg
