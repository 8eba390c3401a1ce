"""Issue 12, "each message type defined once": the rules a field type cannot state are one
function per message type (``rule``), called by ``__post_init__`` and by the generated
checks; :func:`decode` first decodes with the definition minus its string patterns; the
per-call tables of the generated checks; several floats outside msgspec's text range in one
message.  Each is checked against an independent reference (``repr``, ``json.loads``,
msgspec's own decoder of the definition, the reference paths) over random and hostile input.
"""

from __future__ import annotations

import copy
import json
import math
import random
import re

import msgspec
import numpy as np
import pytest

from astrodyn import messages as m
from astrodyn.messages import codec
from astrodyn.messages.definitions import MESSAGE_TYPES
from test_encode_single import assert_encodes_like_reference, assert_validates_like_reference, hard_floats, outcome
from test_message_definitions import _example

# -- one rule, two callers -----------------------------------------------------------------


def test_every_post_init_is_a_rule():
    """Every message type whose __post_init__ states a rule has it as ``rule`` (one place);
    the generated checks call it instead of building the Struct."""
    for kind, t in MESSAGE_TYPES.items():
        if hasattr(t, "__post_init__"):
            assert isinstance(t.__dict__.get("rule"), staticmethod), kind
    for kind in ("attitude", "gimbals"):
        source = codec._plain_check(tuple(_example(kind)), kind, codec._VALID).source
        assert "_rule(" in source and "_struct(" not in source


def _quaternion(rng: np.random.Generator, scale: float) -> list[float]:
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    return (q * (1.0 + scale * rng.uniform(-2, 2))).tolist()


@pytest.mark.parametrize("seed", range(4))
def test_quaternion_rule_same_verdict_everywhere(seed):
    """|q| near the tolerance (1e-9), exactly 1, far off, zero: validate, encode with kind,
    the builder and decode agree with msgspec's validation (the Struct's __post_init__) and
    with the rule evaluated independently here."""
    rng = np.random.default_rng(seed)
    for k in range(300):
        scale = [0.0, 1e-10, 5e-10, 1e-9, 2e-9, 1e-3, 1.0][k % 7]
        q = _quaternion(rng, scale) if k % 50 else [0.0, 0.0, 0.0, 0.0]
        msg = {"t": 1.5, "seq": 3, "model": "torque_free", "q": q, "w": [1e-3, 3e-5, -2.0]}
        norm = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
        unit = abs(norm - 1.0) <= m.QUAT_NORM_TOL
        reference = assert_validates_like_reference(msg, "attitude")
        assert (reference == msg) is unit
        expected = assert_encodes_like_reference(msg, "attitude")
        assert isinstance(expected, bytes) is unit
        data = m.encode(msg)
        assert outcome(m.decode, data, "attitude") == (msg if unit else outcome(codec._validate_reference, msg, "attitude"))
        assert outcome(m.attitude_message, 1.5, 3, "torque_free", q, msg["w"]) == outcome(
            codec._attitude_checked, 1.5, 3, "torque_free", q, msg["w"])


def test_gimbal_and_appendage_rules_keep_their_texts():
    base = _example("gimbals")
    for n in range(1, 4):
        msg = dict(base, angle=[0.1] * n, angle_rate=[0.2] * 2, indicated=[0.3] * 2)
        assert_validates_like_reference(msg, "gimbals")
        assert_encodes_like_reference(msg, "gimbals")
    with pytest.raises(m.MessageError, match=r"gimbals: expected angle, angle_rate and indicated"):
        m.validate(dict(base, angle=[0.1], angle_rate=[0.2, 0.3], indicated=[0.1]), "gimbals")
    app = dict(_example("appendages"), eta=[[0.1, 0.2, 0.3]], eta_dot=[[0.1, 0.2, 0.3]])
    text = "appendages.eta[0]: expected 2 n values (n modes in each bending plane) and as many in eta_dot[0], got 3 and 3"
    assert MESSAGE_TYPES["appendages"].rule(app["eta"], app["eta_dot"], app["tip"]) == text
    with pytest.raises(ValueError, match=re.escape(text)):
        MESSAGE_TYPES["appendages"](**app)
    assert_validates_like_reference(app, "appendages")


# -- several floats outside the text range in one message ----------------------------------


def test_many_fixed_floats_in_one_message_match_repr():
    """Floats whose msgspec text differs from repr's in any combination of fields (t, the
    vectors, mu, variable-length lists): bytes == the reference (json with repr) and == an
    independent f-string of reprs; the caller's dict is left unchanged."""
    values = hard_floats(2000, 11)
    values = values[np.isfinite(values)].tolist()
    rng = random.Random(5)
    for _ in range(1500):
        pick = [rng.choice(values) for _ in range(8)]
        orbit = {"t": pick[0], "seq": 7, "model": "kepler", "r": pick[1:4], "v": pick[4:7], "mu": abs(pick[7]) or 1.0,
                 "frame": "GCRF"}
        before = copy.deepcopy(orbit)
        text = (f'{{"t":{pick[0]!r},"seq":7,"model":"kepler","r":[{",".join(map(repr, pick[1:4]))}],'
                f'"v":[{",".join(map(repr, pick[4:7]))}],"mu":{orbit["mu"]!r},"frame":"GCRF"}}').encode()
        assert m.encode(orbit) == text == assert_encodes_like_reference(orbit)
        assert m.encode(orbit, "orbit") == text
        assert orbit == before and type(orbit["r"]) is list
        speeds = [rng.choice(values) for _ in range(rng.randint(1, 6))]
        tach = {"t": pick[0], "seq": 1, "speeds": speeds}
        assert m.encode(tach, "tachometer") == (
            f'{{"t":{pick[0]!r},"seq":1,"speeds":[{",".join(map(repr, speeds))}]}}').encode()
        assert tach["speeds"] == speeds


# -- decode: the definition without its patterns, then the patterns -------------------------

NAMES = ["GCRF", "GCRF\n", "\nGCRF", "", "a" * 128, "a" * 129, "GC RF", "é", "x.y-z_1", "\u2028", "restart", "Restart",
         "a" * 32, "a" * 33, "orbit", "orbit\n", "_x", "x_"]


def _decode_reference(data: bytes, kind: str):
    """msgspec's decoder of the definition itself (patterns included), as a dict; or json.loads
    + the reference validation for what it refuses (the old decode)."""
    try:
        obj = msgspec.json.decode(data, type=MESSAGE_TYPES[kind])
        return msgspec.to_builtins(obj)
    except (msgspec.DecodeError, ValueError):
        pass
    try:
        msg = json.loads(data)
    except ValueError:
        return "bad"
    return outcome(codec._validate_reference, msg, kind) if type(msg) is dict else "bad"


@pytest.mark.parametrize("kind", ["orbit", "event", "command", "done", "status", "attitude"])
def test_decode_same_as_the_definitions_decoder(kind):
    """Names of every kind in the pattern fields (valid, a newline at either end, too long,
    non-ASCII), and random byte edits of valid payloads: the same dict (same types, same
    order) as msgspec's decoder of the definition, or an error."""
    base = _example(kind)
    rng = random.Random(kind)
    payloads = []
    for field in [k for k, v in base.items() if type(v) is str]:
        for name in NAMES:
            payloads.append(m.encode(dict(base, **{field: name})))
    data = m.encode(base)
    for _ in range(400):
        i = rng.randrange(len(data))
        payloads.append(data[:i] + bytes([rng.randrange(256)]) + data[i + 1:])
        payloads.append(data[:i] + data[i + 1:])
    payloads += [data.replace(b'"seq":', b'"seq":1.0,"x":'), data + b" ", b" " + data, data[:-1] + b',"t":2.5}']
    for p in payloads:
        reference = _decode_reference(p, kind)
        got = outcome(m.decode, p, kind)
        if type(reference) is dict:
            assert got == reference and list(got) == list(reference), p
            assert [type(v) for v in got.values()] == [type(v) for v in reference.values()], p
        else:
            assert type(got) is tuple and got[0] == "MessageError", (p, got)


def test_decode_errors_name_the_field():
    bad = m.encode(dict(_example("orbit"), frame="GC RF"))
    with pytest.raises(m.MessageError, match=r"^orbit\.frame: expected a frame name matching"):
        m.decode(bad, "orbit")
    bad = m.encode(dict(_example("event"), kind="Restart"))
    with pytest.raises(m.MessageError, match=r"^event\.kind: expected a lower-case word"):
        m.decode(bad, "event")


# -- the per-call tables -----------------------------------------------------------------


def test_tables_stay_right_when_full():
    """More key layouts than a table holds (each a message with an extra field): every one
    still gets the reference's verdict; keys, kinds and schema names all resolve."""
    msg = _example("orbit")
    for i in range(4200):
        odd = dict(msg, **{f"x{i}": 1.0})
        if i % 300 == 0:
            assert_encodes_like_reference(odd)
            assert_encodes_like_reference(odd, "orbit")
            assert_validates_like_reference(odd, "orbit")
        else:
            m.is_valid(odd, "orbit")
    for key_or_kind in ("orbit", "astrodyn.OrbitState", m.orbit_key("s", "sat1"), m.orbit_key("s", "sat2")):
        assert m.validate(dict(msg), key_or_kind) == msg
        assert m.encode(msg, key_or_kind) == codec._encode_reference(msg, "orbit")
        assert m.decode(m.encode(msg), key_or_kind) == msg
    for wrong in ("nope", "astrodyn/s/sat1/nope", "", "attitude"):
        assert isinstance(outcome(m.encode, msg, wrong), tuple)
        assert isinstance(outcome(m.decode, m.encode(msg), wrong), tuple)
