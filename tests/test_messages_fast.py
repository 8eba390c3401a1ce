"""astrodyn.messages.check_state: the logger's fast check of canonical state payloads.

The reference is the slow path itself, which tests/test_messages.py checks against the
``jsonschema`` package: ``json.loads`` of the bytes plus the hand-written validator
(:func:`astrodyn.messages.decode`).  The fast path must never accept what the slow path
rejects, must return the same ``(t, seq)`` when it accepts, and must accept the
canonical bytes the batch encoders write for ordinary values (otherwise it is useless).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, strategies as st

from astrodyn import messages as m

MU_EARTH = 3.986004418e14

finite = st.floats(allow_nan=False, allow_infinity=False)
# Values repr writes in the layouts the fast pattern admits: |x| < 1e308 (repr of larger
# finite values has exponent +308, which the pattern leaves to the slow path on purpose).
ordinary = st.floats(min_value=-1e307, max_value=1e307, allow_nan=False)
NAME_CHARS = "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_.-"
frames = st.text(alphabet=NAME_CHARS, min_size=1, max_size=12)
seqs = st.integers(0, 2**53 - 1)


def unit_quat(c):
    q = np.asarray(c, dtype=float)
    n = np.linalg.norm(q)
    return q / n if n > 1e-3 else np.array([1.0, 0.0, 0.0, 0.0])


quats = st.lists(st.floats(-1, 1), min_size=4, max_size=4).map(unit_quat)


def slow(data: bytes, kind: str):
    """Verdict of the full path: ("ok", t, seq) or ("bad", error text)."""
    try:
        msg = m.decode(data, kind)
    except m.MessageError as exc:
        return ("bad", str(exc))
    return ("ok", msg["t"], msg["seq"])


def verdict(data: bytes, kind: str):
    try:
        t, seq = m.check_state(data, kind)
    except m.MessageError as exc:
        return ("bad", str(exc))
    return ("ok", t, seq)


def same(a, b) -> bool:
    """Equal verdicts; t compared bit for bit (-0.0 is not 0.0)."""
    if a[0] != b[0]:
        return False
    if a[0] == "bad":
        return a == b
    return math.copysign(1.0, a[1]) == math.copysign(1.0, b[1]) and a[1:] == b[1:] and type(a[2]) is type(b[2]) is int


def orbit_payload(t, seq, model, r, v, mu, frame):
    return m.encode_orbit_batch(t, seq, model, np.reshape(r, (1, 3)), np.reshape(v, (1, 3)), mu, frame)[0]


def attitude_payload(t, seq, model, q, w):
    return m.encode_attitude_batch(t, seq, model, np.reshape(q, (1, 4)), np.reshape(w, (1, 3)))[0]


@st.composite
def canonical(draw, values=finite):
    kind = draw(st.sampled_from(["orbit", "attitude"]))
    t, seq = draw(values), draw(seqs)
    if kind == "orbit":
        r = draw(st.lists(values, min_size=3, max_size=3))
        v = draw(st.lists(values, min_size=3, max_size=3))
        mu = draw(st.floats(min_value=5e-324, max_value=1e300))
        data = orbit_payload(t, seq, draw(st.sampled_from(m.ORBIT_MODELS)), r, v, mu, draw(frames))
    else:
        w = draw(st.lists(values, min_size=3, max_size=3))
        data = attitude_payload(t, seq, draw(st.sampled_from(m.ATTITUDE_MODELS)), draw(quats), w)
    return kind, data


# ------------------------------------------------------------------------- valid messages


@given(canonical(ordinary))
def test_fast_path_takes_canonical_payloads_of_ordinary_values(case):
    kind, data = case
    found = m.FAST_CHECKS[kind](data)
    assert found is not None, data
    ref = slow(data, kind)
    assert same(("ok", *found), ref), (data, found, ref)


@given(canonical())
def test_any_finite_values_same_verdict_as_decode(case):
    kind, data = case  # includes |x| >= 1e307, subnormals, -0.0: fast or fallback, same answer
    assert slow(data, kind)[0] == "ok"
    assert same(verdict(data, kind), slow(data, kind))


def test_representative_constellation_payloads_hit_the_fast_path():
    rng = np.random.default_rng(7)
    r, v = rng.normal(size=(500, 3)) * 7e6, rng.normal(size=(500, 3)) * 7.5e3
    q = rng.normal(size=(500, 4))
    q /= np.linalg.norm(q, axis=1)[:, None]
    w = rng.normal(size=(500, 3)) * 1e-3
    for kind, payloads in (("orbit", m.encode_orbit_batch(12.3, 123, "kepler", r, v, MU_EARTH)),
                           ("attitude", m.encode_attitude_batch(12.3, 123, "torque_free", q, w))):
        for p in payloads:
            assert m.FAST_CHECKS[kind](p) == (12.3, 123)
            assert json.loads(p)["t"] == 12.3


# ------------------------------------------------------------------------- rejected input

BASE = {
    "orbit": orbit_payload(1.5, 7, "kepler", [7e6, 1.25, -3e-5], [0.0, 7.5e3, -0.0], MU_EARTH, "GCRF"),
    "attitude": attitude_payload(1.5, 7, "torque_free", [0.5, 0.5, 0.5, 0.5], [1e-3, 0.0, -2.0]),
}


def test_base_payloads_are_canonical():
    assert BASE["orbit"] == (b'{"t":1.5,"seq":7,"model":"kepler","r":[7000000.0,1.25,-3e-05],'
                             b'"v":[0.0,7500.0,-0.0],"mu":398600441800000.0,"frame":"GCRF"}')
    for kind, data in BASE.items():
        assert m.FAST_CHECKS[kind](data) == (1.5, 7)


# Each replaces one substring of a canonical payload with something the slow path rejects
# (or, for the last seven, accepts through json.loads only); the fast path must not accept
# any of the rejected ones and check_state must give decode's error text word for word.
EDITS = [
    ("orbit", b"7000000.0", b"1e309"),  # overflows to inf in json.loads
    ("orbit", b"7000000.0", b"2e308"),
    ("orbit", b"7000000.0", b"1.8e+308"),
    ("orbit", b"7000000.0", b"NaN"),
    ("orbit", b"7000000.0", b"Infinity"),
    ("orbit", b"7000000.0", b"-Infinity"),
    ("orbit", b"7000000.0", b"07.0"),  # leading zero: invalid JSON
    ("orbit", b"7000000.0", b"7."),
    ("orbit", b"7000000.0", b".5"),
    ("orbit", b"7000000.0", b"+7.0"),
    ("orbit", b"7000000.0", b'"7.0"'),
    ("orbit", b"7000000.0", b"true"),
    ("orbit", b"7000000.0", b"1" * 400 + b".0"),  # finite? no: 1e400 -> inf
    ("orbit", b"398600441800000.0", b"0.0"),  # mu > 0
    ("orbit", b"398600441800000.0", b"-1.0"),
    ("orbit", b'"seq":7', b'"seq":9007199254740992'),  # > 2**53 - 1
    ("orbit", b'"seq":7', b'"seq":-1'),
    ("orbit", b'"seq":7', b'"seq":07'),
    ("orbit", b'"seq":7', b'"seq":7.5'),
    ("orbit", b"kepler", b"keplerx"),
    ("orbit", b"kepler", b"Kepler"),
    ("orbit", b"GCRF", b"GC/RF"),
    ("orbit", b"GCRF", b""),
    ("orbit", b"GCRF", b"G" * 129),
    ("orbit", b"[7000000.0,", b"[7000000.0,1.0,"),  # 4 components
    ("orbit", b",1.25,", b","),  # 2 components
    ("orbit", b'"frame":"GCRF"}', b'"frame":"GCRF","extra":1}'),
    ("orbit", b'"frame":"GCRF"}', b'"frame":"GCRF"}x'),
    ("orbit", b'{"t":1.5,', b"{"),
    ("attitude", b"[0.5,0.5,0.5,0.5]", b"[0.5,0.5,0.5,0.6]"),  # |q| != 1
    ("attitude", b"[0.5,0.5,0.5,0.5]", b"[0.0,0.0,0.0,0.0]"),
    ("attitude", b"[0.5,0.5,0.5,0.5]", b"[1e300,1e300,0.0,0.0]"),  # |q|^2 overflows
    ("attitude", b"torque_free", b"torque-free"),
    ("attitude", b"-2.0", b"NaN"),
    ("attitude", b"-2.0", b"-2e999"),
    ("attitude", b'"w":[', b'"W":['),
    ("attitude", b"]}", b"]} "),  # trailing space: valid JSON, same state, slow path only
    ("attitude", b"]}", b"]}\n"),
    ("orbit", b'{"t":1.5,', b'{ "t":1.5,'),
    ("orbit", b'{"t":1.5,', b'{"t":1.5,"t":1.5,'),  # json.loads keeps the last duplicate
    ("orbit", b"1.25", b"1.25E0"),
    ("orbit", b"1.25", b"125e-2"),
    ("orbit", b"1.25", b"1"),  # integer components are valid, fallback
]


@pytest.mark.parametrize("kind,old,new", EDITS)
def test_edits_take_the_slow_path_or_agree(kind, old, new):
    data = BASE[kind].replace(old, new, 1)
    assert data != BASE[kind]
    ref = slow(data, kind)
    fast = m.FAST_CHECKS[kind](data)
    if fast is not None:
        assert ref[0] == "ok" and same(("ok", *fast), ref), (data, fast, ref)
    assert same(verdict(data, kind), ref), (data, verdict(data, kind), ref)


def test_rejected_edits_are_rejected():
    rejected = [e for e in EDITS if slow(BASE[e[0]].replace(e[1], e[2], 1), e[0])[0] == "bad"]
    # all but the last seven (valid JSON in another layout) are invalid messages
    assert len(rejected) == len(EDITS) - 7
    for kind, old, new in rejected:
        with pytest.raises(m.MessageError):
            m.check_state(BASE[kind].replace(old, new, 1), kind)


@st.composite
def byte_mutants(draw):
    kind, data = draw(canonical(ordinary))
    data = bytearray(data)
    for _ in range(draw(st.integers(1, 3))):
        pos = draw(st.integers(0, len(data) - 1))
        action = draw(st.sampled_from(["replace", "insert", "delete"]))
        byte = draw(st.sampled_from(list(b'0123456789.eE+-,[]{}":aZ \\/\x00\xff')))
        if action == "replace":
            data[pos] = byte
        elif action == "insert":
            data.insert(pos, byte)
        else:
            del data[pos]
    return kind, bytes(data)


@given(byte_mutants())
def test_mutated_payloads_never_accepted_by_the_fast_path_alone(case):
    kind, data = case
    ref = slow(data, kind)
    fast = m.FAST_CHECKS[kind](data)
    if fast is not None:
        assert ref[0] == "ok" and same(("ok", *fast), ref), (data, fast, ref)
    assert same(verdict(data, kind), ref), (data, verdict(data, kind), ref)


@given(st.binary(max_size=300))
def test_random_bytes(data):
    for kind in ("orbit", "attitude"):
        fast = m.FAST_CHECKS[kind](data)
        assert fast is None or slow(data, kind)[0] == "ok"


def test_check_state_other_kinds_and_types():
    ev = m.encode(m.event_message(2.0, 3, "orbit", "start", "x"))
    assert m.check_state(ev, "event") == (2.0, 3)
    assert m.check_state(bytearray(BASE["orbit"]), "orbit") == (1.5, 7)  # not bytes: slow path
    with pytest.raises(m.MessageError, match=r"^payload: expected UTF-8 JSON"):
        m.check_state(b"\xff", "attitude")
