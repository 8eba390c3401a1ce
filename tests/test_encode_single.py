"""Single-message encoding, validation and the builders: the fast path (msgspec's encoder
and the checks generated from the definitions, astrodyn.messages.codec "Plain messages")
gives exactly the bytes, dicts and MessageError texts of the reference path (``json`` with
floats by ``repr``, msgspec's validation, the converting builders) -- over hard floats
(random bit patterns across all exponents, subnormals, +-0.0, the neighbours of 1e-4 and
1e16 where ``repr`` changes notation, NaN and infinities), every message kind, the
constraints of each field and inputs of every odd type.
"""

from __future__ import annotations

import copy
import dataclasses
import decimal
import enum
import json
import re

import msgspec
import numpy as np
import pytest

from astrodyn import messages as m
from astrodyn.messages import codec
from test_message_definitions import _example


def outcome(fn, *args, **kwargs):
    """What ``fn`` returns, or the type and text of what it raises (object addresses left out)."""
    try:
        return fn(*args, **kwargs)
    except Exception as exc:  # the reference raises MessageError, TypeError, OverflowError, ...
        return (type(exc).__name__, re.sub(r" at 0x[0-9a-f]+", "", str(exc)))


def _shown(msg):
    return re.sub(r" at 0x[0-9a-f]+", "", repr(msg))


def assert_encodes_like_reference(msg, kind=None):
    reference = outcome(codec._encode_reference, copy.deepcopy(msg), kind)
    before = _shown(msg)
    assert outcome(m.encode, msg, kind) == reference
    assert _shown(msg) == before  # not changed
    return reference


def assert_validates_like_reference(msg, kind):
    reference = outcome(codec._validate_reference, copy.deepcopy(msg), kind)
    assert outcome(m.validate, copy.deepcopy(msg), kind) == reference
    return reference


def hard_floats(n: int, seed: int) -> np.ndarray:
    """``n`` random float64 bit patterns (every exponent equally likely, NaN and infinities
    included) followed by the hard cases: zeros, subnormals, the extremes, and 40 neighbours
    (both signs) of each power of ten from 1e-11 to 1e22 -- 1e-4 and 1e16 are where ``repr``
    switches notation, 1e-9 and 1e-6 where msgspec's text changes."""
    rng = np.random.default_rng(seed)
    random = rng.integers(0, 2**64, size=n, dtype=np.uint64).view(np.float64)
    subnormal = (rng.integers(1, 2**52, size=200, dtype=np.uint64)).view(np.float64)
    special = [0.0, -0.0, 5e-324, 2.225073858507201e-308, 2.2250738585072014e-308, 1.7976931348623157e308,
               1e-4, 1e16, 9999999999999998.0, 1.0000000000000002e16, 0.00010000000000000002, 9.999999999999999e-05,
               2.5e-05, 1e-07, 1e15, 123456789012345680.0, 0.1, 1.0, 3.0, 1e22, 1e23]
    near = []
    for k in range(-11, 23):
        x = np.float64(10.0**k)
        up, down = x, x
        for _ in range(20):
            near += [up, down]
            up, down = np.nextafter(up, np.inf), np.nextafter(down, 0.0)
    hard = np.concatenate([subnormal, special, near, [10.0**k for k in range(-323, 309)]])
    return np.concatenate([random, hard, -hard])


def test_msgspec_writes_repr_text_exactly_in_the_text_range():
    """The premise of the plain path: msgspec's text of a float is ``repr``'s if and only if
    |x| < 1e-9 or 1e-4 <= |x| < 1e16 (codec._TEXT_RANGE)."""
    x = hard_floats(300_000, 1)
    near = [np.float64(b) for b in (1e-9, -1e-9)]
    for _ in range(200):
        near += [np.nextafter(near[-2], 0.0), np.nextafter(near[-1], 0.0)]
    x = np.concatenate([x, near, -np.array(near)])
    x = x[np.isfinite(x)].tolist()
    texts = msgspec.json.encode(x)[1:-1].split(b",")
    tiny, lo, hi = codec._TEXT_RANGE
    inside = 0
    for v, text in zip(x, texts):
        in_range = abs(v) < tiny or lo <= abs(v) < hi
        assert (text == repr(v).encode()) == in_range, v
        inside += in_range
    assert 100_000 < inside < len(x) - 100_000


@pytest.mark.parametrize("seed", [1, 2])
def test_orbit_messages_of_hard_floats_encode_like_the_reference(seed):
    x = hard_floats(40_000, seed)
    x = x[: x.size // 8 * 8].reshape(-1, 8)
    fast = 0
    for row in x.tolist():
        msg = {"t": row[0], "seq": 7, "model": "kepler", "r": row[1:4], "v": row[4:7], "mu": row[7], "frame": "GCRF"}
        expected = assert_encodes_like_reference(msg)
        assert_encodes_like_reference(msg, "orbit")
        if not isinstance(expected, tuple):
            independent = (f'{{"t":{row[0]!r},"seq":7,"model":"kepler","r":[{row[1]!r},{row[2]!r},{row[3]!r}],'
                           f'"v":[{row[4]!r},{row[5]!r},{row[6]!r}],"mu":{row[7]!r},"frame":"GCRF"}}').encode()
            assert expected == independent
            assert codec._plain_check(tuple(msg), None, codec._TEXT)(msg) == expected  # by the fast path
            fast += 1
        else:
            assert expected == ("MessageError", expected[1]) and "NaN or infinity" in expected[1]
    assert fast > 1000


def test_state_messages_equal_the_compiled_batch_payloads_over_hard_floats():
    x = hard_floats(30_000, 3)
    x = x[np.isfinite(x)]
    x = x[: x.size // 7 * 7].reshape(-1, 7)
    r, v, w = x[:, 0:3], x[:, 3:6], x[:, 4:7]
    rng = np.random.default_rng(4)
    q = rng.normal(size=(x.shape[0], 4)) * 10.0 ** rng.integers(-20, 1, size=(x.shape[0], 1))
    q[:, 0] = 1.0
    q[:, 1:] *= rng.choice([0.0, 1e-30, 1e-9, 1e-5], size=(x.shape[0], 1))
    q /= np.linalg.norm(q, axis=1)[:, None]
    for t, mu in ((1234.5, 3.986004418e14), (2.5e-05, 1.32712440018e20), (0.0, 1e16)):
        orbit = m.encode_orbit_batch(t, 3, "kepler", r, v, mu)
        attitude = m.encode_attitude_batch(t, 3, "torque_free", q, w)
        for i in range(x.shape[0]):
            assert m.encode(m.orbit_message(t, 3, "kepler", r[i], v[i], mu), "orbit") == orbit[i]
            assert m.encode(m.attitude_message(t, 3, "torque_free", q[i], w[i]), "attitude") == attitude[i]


def test_a_few_bodies_encoded_one_by_one_give_the_compiled_pass_bytes_and_errors():
    """Fewer than FEW_BODIES bodies go through the builder and encode; more through the
    compiled pass.  The first k < FEW_BODIES rows give the first k payloads of a large
    batch, over hard floats; a bad row gives the compiled pass's error."""
    x = hard_floats(3000, 5)
    x = x[np.isfinite(x)]
    x = x[: x.size // 7 * 7].reshape(-1, 7)
    rng = np.random.default_rng(6)
    q = rng.normal(size=(x.shape[0], 4))
    q /= np.linalg.norm(q, axis=1)[:, None]
    seqs = rng.integers(0, 2**53, size=x.shape[0])
    orbit = m.encode_orbit_batch(2.5e-05, seqs, "kepler", x[:, :3], x[:, 3:6], 3.986004418e14)
    attitude = m.encode_attitude_batch(1e16, 7, "torque_free", q, x[:, 4:7])
    assert x.shape[0] > m.FEW_BODIES
    for start in range(0, x.shape[0] - m.FEW_BODIES, m.FEW_BODIES):
        for k in range(1, m.FEW_BODIES):
            rows = slice(start, start + k)
            assert m.encode_orbit_batch(2.5e-05, seqs[rows], "kepler", x[rows, :3], x[rows, 3:6],
                                        3.986004418e14) == orbit[rows]
            assert m.encode_attitude_batch(1e16, 7, "torque_free", q[rows], x[rows, 4:7].tolist()) == attitude[rows]
    bad_q = np.array([[1.0, 0.0, 0.0, 0.0]] * m.FEW_BODIES)
    bad_q[1, 0] = 1.1
    errors = []
    for n in (2, m.FEW_BODIES):
        with pytest.raises(m.MessageError) as exc:
            m.encode_attitude_batch(1.0, 1, "torque_free", bad_q[:n], np.zeros((n, 3)))
        errors.append(str(exc.value))
    assert errors[0] == errors[1] and "attitude.q[1]" in errors[0]
    with pytest.raises(m.MessageError, match="same N"):
        m.encode_orbit_batch(1.0, 1, "kepler", np.ones((2, 3)), np.ones((3, 3)), 1.0)
    with pytest.raises(m.MessageError, match="orbit.model"):
        m.encode_orbit_batch(1.0, 1, "nope", np.ones((1, 3)), np.ones((1, 3)), 1.0)


@pytest.mark.parametrize("where", ["t", "r", "v", "mu", "q", "w"])
@pytest.mark.parametrize("bad", [float("nan"), float("inf"), float("-inf")])
def test_nan_and_infinity_are_refused_with_the_same_text(where, bad):
    kind = "attitude" if where in ("q", "w") else "orbit"
    msg = _example(kind)
    if isinstance(msg[where], list):
        msg[where][1] = bad
    else:
        msg[where] = bad
    for k in (None, kind):
        got = assert_encodes_like_reference(msg, k)
        assert got[0] == "MessageError" and "expected a finite number, got a NaN or infinity" in got[1]
    assert assert_validates_like_reference(msg, kind)[0] == "MessageError"


@pytest.mark.parametrize("kind", list(m.MESSAGE_TYPES))
def test_every_kind_encodes_and_validates_like_the_reference(kind):
    msg = _example(kind)
    data = assert_encodes_like_reference(msg)
    assert assert_encodes_like_reference(msg, kind) == data
    assert assert_validates_like_reference(msg, kind) == msg
    assert m.decode(data, kind) == json.loads(data)
    for value in (1e-05, 3e-07, 1e-09, 9.999999999999999e-10, 1.5e16, -3e-300, 5e-324, 0.0001, 9999999999999998.0, -0.0):
        for name, field in msg.items():
            changed = copy.deepcopy(msg)
            if type(field) is float:
                changed[name] = value
            elif type(field) is list and field and type(field[0]) is float:
                changed[name] = [value] + field[1:]
            else:
                continue
            assert_encodes_like_reference(changed)
            assert_encodes_like_reference(changed, kind)
            assert_validates_like_reference(changed, kind)


def test_the_plain_path_covers_the_state_messages():
    """Orbit and attitude states (and the other kinds without nested objects) take the
    generated path; the generated source names every field of the definition."""
    for kind in ("orbit", "attitude", "crosscheck", "event", "gyro", "star_tracker", "gps", "tachometer", "done",
                 "command", "actuators"):
        msg = _example(kind)
        for mode in (codec._TEXT, codec._VALID, codec._TEXT | codec._VALID):
            check = codec._plain_check(tuple(msg), kind, mode)
            assert check is not None, (kind, mode)
            assert check(msg) is not None, (kind, mode)
            assert check.source.count("type(v") >= len(msg)  # a test per field
    assert codec._plain_check(tuple(_example("tick")), "tick", codec._TEXT) is None  # nested messages: json


# -- the constraints of the definitions ------------------------------------------------------

NAMES = ["", "GCRF", "GCRF\n", "\nGCRF", "GC RF", "GCRF/x", "a" * 128, "a" * 129, ".", "..", "é", "x" * 127 + "é",
         "GCRF\ud800"]
CONSTRAINED = [
    ("orbit", "seq", [-1, 0, 2**53 - 1, 2**53, 10**400, True, 3.0]),
    ("orbit", "model", ["kepler", "Kepler", "", "kepler\n", 5]),
    ("orbit", "frame", NAMES),
    ("orbit", "mu", [0.0, -0.0, -1.0, 5e-324, 1e-300, 1e300, 3]),
    ("orbit", "r", [[1.0, 2.0], [1.0, 2.0, 3.0, 4.0], [1.0, 2.0, 3], [1.0, 2.0, True], (1.0, 2.0, 3.0), [[1.0], 2.0, 3.0],
                    np.array([1.0, 2.0, 3.0]), [1.0, 2.0, np.float64(3.0)], [1.0, 2.0, "3"], {1.0, 2.0, 3.0}]),
    ("attitude", "q", [[1.0, 0.0, 0.0, 0.0], [1.0 + 1e-9, 0.0, 0.0, 0.0], [1.0 + 1.1e-9, 0.0, 0.0, 0.0],
                       [1.0 - 1e-9, 1e-5, 0.0, 0.0], [0.5, 0.5, 0.5, 0.5], [0.5, 0.5, 0.5, 0.5000000001],
                       [0.0, 0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]),
    ("attitude", "model", ["torque_free", "nope"]),
    ("crosscheck", "dr_norm", [0.0, -0.0, -1e-300, 1e-5, 1e20]),
    ("crosscheck", "reference", ["rebound-ias15", "x"]),
    ("event", "kind", ["restart", "a", "Restart", "a" * 32, "a" * 33, "a_b", "a-b", "restart\n", ""]),
    ("event", "process", NAMES),
    ("event", "detail", ["", "a" * 4096, "a" * 4097, "é" * 4096, "é" * 4097, "\U0001f600" * 4096, "\U0001f600" * 4097,
                         'quote " backslash \\ newline \n tab \t nul \x00 del \x7f', "\u2028\u2029"]),
    ("status", "real_time_factor", [0.0, -1e-300, 2.5]),
    ("status", "rate", [0.0, 1e-5, -1.0]),
    ("status", "messages", [0, -1, 2**53]),
    ("tachometer", "speeds", [[], [1.0], [1.0] * 64, [1.0] * 65, [1.0, 2]]),
    ("actuators", "clipped", [[], [1, 2], [1.0], list(range(64)), list(range(65))]),
    ("actuators", "applied", [[], ["pd#7"], [1], ["x"] * 4097]),
    ("command", "frame", ["inertial", "body", "x"]),
    ("done", "commands", [0, 1_000_000, 1_000_001, -1]),
]


@pytest.mark.parametrize(("kind", "field", "values"), CONSTRAINED, ids=[f"{k}.{f}" for k, f, _ in CONSTRAINED])
def test_constraints_give_the_reference_verdict_and_text(kind, field, values):
    for value in values:
        msg = _example(kind)
        msg[field] = value
        for k in (None, kind):
            assert_encodes_like_reference(msg, k)
        assert_validates_like_reference(msg, kind)


class FloatEnum(float, enum.Enum):
    A = 2.5
    B = 1e-05


class PlainEnum(enum.Enum):
    A = 2.5


class IntEnum(enum.IntEnum):
    A = 3


class StrEnum(enum.StrEnum):
    A = "kepler"


class SubFloat(float):
    pass


class SubStr(str):
    pass


@dataclasses.dataclass
class Point:
    x: float = 1.0


ODD = [decimal.Decimal("1.5"), {1.5}, frozenset([1.5]), b"GCRF", bytearray(b"GCRF"), np.float64(1.5), np.float32(1.5),
       np.int64(3), np.bool_(True), SubFloat(1.5), SubFloat(1e-5), FloatEnum.A, FloatEnum.B, PlainEnum.A, IntEnum.A,
       StrEnum.A, SubStr("GCRF"), True, None, 3, 10**400, "x", "\ud800", [1.5], (1.5,), {"a": 1.5}, Point(),
       msgspec.Raw(b"1.5"), 1j, msgspec.UNSET]


@pytest.mark.parametrize("value", ODD, ids=[type(v).__name__ + str(i) for i, v in enumerate(ODD)])
@pytest.mark.parametrize(("kind", "field"), [("orbit", "t"), ("orbit", "seq"), ("orbit", "model"), ("orbit", "frame"),
                                             ("orbit", "r[0]"), ("attitude", "w[2]"), ("event", "detail"),
                                             ("tachometer", "speeds[0]"), ("actuators", "applied[0]")])
def test_values_of_odd_types_give_the_reference_result(kind, field, value):
    msg = _example(kind)
    if field.endswith("]"):
        name, index = field[:-1].split("[")
        msg[name][int(index)] = value
    else:
        msg[field] = value
    for k in (None, kind):
        assert_encodes_like_reference(msg, k)
    assert_validates_like_reference(msg, kind)


def test_keys_in_another_order_missing_extra_or_odd_give_the_reference_result():
    msg = _example("orbit")
    variants = [dict(reversed(list(msg.items()))), {k: v for k, v in msg.items() if k != "frame"},
                {**msg, "extra": 1.0}, {SubStr(k): v for k, v in msg.items()}, {**msg, 1e-05: 1.0},
                {**msg, True: 1}, {**msg, None: 1}, {"t": 1e-05}, {}]
    for variant in variants:
        for k in (None, "orbit", "astrodyn/s/sat1/orbit", "astrodyn.OrbitState", "astrodyn/s/sat1/attitude", "nope", 5):
            assert_encodes_like_reference(variant, k)
    for k in ("orbit", "astrodyn/s/sat1/orbit", "astrodyn.OrbitState", "astrodyn/s/sat1/attitude", "nope", 5):
        assert_validates_like_reference(msg, k)
    for not_a_dict in ([1.5], "x", None, 1e-05, msgspec.structs.replace(m.OrbitState(**msg))):
        assert_encodes_like_reference(not_a_dict)
        assert_encodes_like_reference(not_a_dict, "orbit")


# -- the builders -------------------------------------------------------------------------------


def _float_types(msg):
    return {k: [type(e) for e in v] if isinstance(v, list) else type(v) for k, v in msg.items()}


BUILDER_INPUTS = {
    "orbit": (codec._orbit_checked, [
        (1234.5, 3, "kepler", [7e6, 1.0, -2.5e-5], [1.0, 7.5e3, 0.0], 3.986004418e14, "GCRF"),
        (1234.5, 3, "kepler", np.array([7e6, 1.0, -2.5e-5]), (1.0, 7.5e3, 0.0), 3.986004418e14, "GCRF"),
        (np.float64(1.5), np.int64(3), "kepler", np.array([7e6, 1.0, 2.0]), [1.0, 7.5e3, 0.0], 4e14, "GCRF"),
        (0, 3.0, "kepler", [7e6, 1, 2], [1.0, 7.5e3, 0.0], 4e14, "GCRF"),
        ("1.5", 3, "kepler", np.array([7e6, 1.0, 2.0], dtype=np.float32), [1.0, 7.5e3, 0.0], 4e14, "GCRF"),
        (1.5, 3, "kepler", np.array([7e6, 1.0, 2.0], dtype=object), [1.0, 7.5e3, 0.0], 4e14, "GCRF"),
        (1.5, 3, "kepler", [7e6, 1.0, float("nan")], [1.0, 7.5e3, 0.0], 4e14, "GCRF"),
        (1.5, 3, "kepler", [7e6, 1.0], [1.0, 7.5e3, 0.0], 4e14, "GCRF"),
        (1.5, 3, "kepler", np.zeros((3, 1)), [1.0, 7.5e3, 0.0], 4e14, "GCRF"),
        (1.5, -1, "kepler", [7e6, 1.0, 2.0], [1.0, 7.5e3, 0.0], 4e14, "GCRF"),
        (1.5, 3, "nope", [7e6, 1.0, 2.0], [1.0, 7.5e3, 0.0], 4e14, "GCRF"),
        (1.5, 3, "kepler", [7e6, 1.0, 2.0], [1.0, 7.5e3, 0.0], -4e14, "GCRF"),
        (1.5, 3, "kepler", [7e6, 1.0, 2.0], [1.0, 7.5e3, 0.0], 4e14, "GC RF"),
        (float("inf"), 3, "kepler", [7e6, 1.0, 2.0], [1.0, 7.5e3, 0.0], 4e14, "GCRF"),
        (True, True, "kepler", [7e6, 1.0, 2.0], [1.0, 7.5e3, 0.0], 4e14, "GCRF"),
        (10**400, 3, "kepler", [7e6, 1.0, 2.0], [1.0, 7.5e3, 0.0], 4e14, "GCRF"),
    ]),
    "attitude": (codec._attitude_checked, [
        (1.5, 3, "torque_free", [1.0, 0.0, 0.0, 0.0], [0.1, -0.02, 3e-5]),
        (1.5, 3, "torque_free", np.array([0.5, 0.5, 0.5, 0.5]), np.array([1e-300, 0.0, -0.0])),
        (1.5, 3, "torque_free", [1.0, 0.0, 0.0, 1e-4], [0.1, -0.02, 3e-5]),
        (1.5, 3, "torque_free", [1, 0, 0, 0], [0, 0, 0]),
        (1.5, 3, "torque_free", [1.0, 0.0, 0.0], [0.1, -0.02, 3e-5]),
    ]),
    "crosscheck": (codec._crosscheck_checked, [
        (1.5, 3, [1e-3, -2e-3, 0.0], [1e-6, 0.0, 0.0], "rebound-ias15"),
        (1.5, 3, np.array([1e-3, -2e-3, 0.0]), np.array([1e-6, 0.0, 0.0]), "rebound-ias15"),
        (1.5, 3, np.array([1e308, 1e308, 0.0]), np.array([1e-6, 0.0, 0.0]), "rebound-ias15"),
        (1.5, 3, ["a", 1.0, 2.0], [1e-6, 0.0, 0.0], "rebound-ias15"),
        (1.5, 3, [[1.0], 1.0, 2.0], [1e-6, 0.0, 0.0], "rebound-ias15"),
        (1.5, 3, [1.0, 2.0], [1e-6, 0.0, 0.0], "rebound-ias15"),
        (1.5, 3, [1.0, 2.0, 3.0], [1e-6, 0.0, 0.0], "nope"),
    ]),
    "event": (codec._event_checked, [
        (1.5, 3, "orbit", "restart", "restarted"),
        (1.5, 3, "orbit", "Restart", "restarted"),
        (1.5, 3, "or bit", "restart", "restarted"),
        (1.5, 3, "orbit", "restart", "x" * 5000),
        (np.float64(1.5), 3, "orbit", "restart", ""),
    ]),
}


@pytest.mark.parametrize("kind", list(BUILDER_INPUTS))
def test_builders_return_the_reference_dict_or_error(kind):
    reference, cases = BUILDER_INPUTS[kind]
    builder = getattr(m, f"{kind}_message")
    for args in cases:
        expected = outcome(reference, *copy.deepcopy(args))
        got = outcome(builder, *args)
        assert got == expected, args
        if isinstance(got, dict):
            assert _float_types(got) == _float_types(expected), args  # Python floats and ints, as before


def test_builders_copy_their_vectors():
    r = [7e6, 1.0, 2.0]
    msg = m.orbit_message(1.5, 3, "kepler", r, r, 4e14)
    r[0] = 0.0
    assert msg["r"] == msg["v"] == [7e6, 1.0, 2.0] and msg["r"] is not msg["v"]


def test_floats_outside_the_text_range_encode_as_repr_writes_them():
    """The floats msgspec writes unlike ``repr`` (1e-9 <= |x| < 1e-4 and |x| >= 1e16:
    random values across those decades, their boundaries, random bit patterns), in a
    scalar and in list fields of a message, through :func:`encode` (the generated check's
    raw text), against ``json`` (``repr``)."""
    rng = np.random.default_rng(7)
    x = np.concatenate([10.0 ** rng.uniform(-9, -4, 50_000), 10.0 ** rng.uniform(16, 308, 10_000),
                        rng.integers(0, 2**64, size=50_000, dtype=np.uint64).view(np.float64),
                        hard_floats(0, 7), [1e-9, 1e-6, 1e-5, 9.999999999999999e-05, 1e16, 1.7976931348623157e308]])
    x = np.concatenate([x, -x])
    tiny, lo, hi = codec._TEXT_RANGE
    n = 0
    for v in x[np.isfinite(x)].tolist():
        if tiny <= abs(v) < lo or abs(v) >= hi:
            msg = {"t": v, "seq": 1, "model": "kepler", "r": [v, 7e6, 1.0], "v": [0.5, 2.0, v], "mu": 4e14,
                   "frame": "GCRF"}
            assert m.encode(msg) == json.dumps(msg, separators=(",", ":")).encode(), v
            n += 1
    assert n > 100_000


def test_strings_of_every_code_point_encode_like_the_reference():
    """msgspec and json (``ensure_ascii=False``) escape alike: every code point but the
    lone surrogates (which both refuse), in the text fields of an event."""
    every = "".join(map(chr, [*range(0xD800), *range(0xE000, 0x110000)]))
    msg = m.event_message(1.5, 3, "orbit", "restart", "")
    for detail, process in ((every, "orbit"), (every[:300], every[:300]), ("\ud800", "orbit"), ("x", "\udfff")):
        msg["detail"], msg["process"] = detail, process
        expected = outcome(codec._encode_reference, msg)
        assert outcome(m.encode, msg) == expected
        assert codec._plain_check(tuple(msg), None, codec._TEXT)(msg) == (None if isinstance(expected, tuple) else expected)
