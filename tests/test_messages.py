"""astrodyn.messages: keys, schemas, encode/decode, batch encoders and batch framing.

The independent references are the JSON text itself (json.loads of the bytes), the
``jsonschema`` package's draft 2020-12 implementation (metaschema check, and the verdict
on generated messages compared with the hand-written validator), and the documented
binary layout of the batch envelope re-implemented here with ``struct``.
"""

from __future__ import annotations

import json
import math
import struct

import jsonschema
import numpy as np
import pytest
from hypothesis import given, strategies as st

from astrodyn import messages as m

MU_EARTH = 3.986004418e14

finite = st.floats(allow_nan=False, allow_infinity=False)
vec3 = st.lists(finite, min_size=3, max_size=3)
NAME_CHARS = "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_.-"
names = st.text(alphabet=NAME_CHARS, min_size=1, max_size=20).filter(lambda s: s not in (".", ".."))


def unit_quat(draw_floats):
    q = np.asarray(draw_floats, dtype=float)
    n = np.linalg.norm(q)
    return (q / n).tolist() if n > 1e-3 else [1.0, 0.0, 0.0, 0.0]


quats = st.lists(st.floats(-1, 1), min_size=4, max_size=4).map(unit_quat)


# ------------------------------------------------------------------------- keys


def test_key_builders_and_parse_round_trip():
    assert m.orbit_key("demo", "sat-1") == "astrodyn/demo/sat-1/orbit"
    assert m.attitude_key("demo", "sat.1") == "astrodyn/demo/sat.1/attitude"
    assert m.crosscheck_key("demo", "s_1") == "astrodyn/demo/s_1/crosscheck"
    assert m.control_key("demo", "pause") == "astrodyn/demo/@control/pause"
    assert m.status_key("demo") == "astrodyn/demo/@status"
    assert m.alive_key("demo", "orbit") == "astrodyn/demo/@alive/orbit"
    assert m.event_key("demo") == "astrodyn/demo/@event"
    assert m.batch_key("demo", "orbit") == "astrodyn/demo/@batch/orbit"
    assert m.parse_key("astrodyn/demo/sat-1/orbit") == ("demo", "sat-1", "orbit")
    assert m.parse_key("astrodyn/demo/sat-1/attitude") == ("demo", "sat-1", "attitude")
    assert m.parse_key("astrodyn/demo/sat-1/crosscheck") == ("demo", "sat-1", "crosscheck")
    assert m.parse_key("astrodyn/demo/@status") == ("demo", "@status", "status")
    assert m.parse_key("astrodyn/demo/@event") == ("demo", "@event", "event")
    assert m.parse_key("astrodyn/demo/@control/rate") == ("demo", "@control", "rate")
    assert m.parse_key("astrodyn/demo/@alive/logger") == ("demo", "@alive", "logger")
    assert m.parse_key("astrodyn/demo/@batch/orbit") == ("demo", "@batch", "orbit")


@given(names, names)
def test_parse_key_inverts_builders(scenario, body):
    for build, kind in ((m.orbit_key, "orbit"), (m.attitude_key, "attitude"), (m.crosscheck_key, "crosscheck")):
        assert m.parse_key(build(scenario, body)) == (scenario, body, kind)


@pytest.mark.parametrize("bad", ["", "a/b", "*", "**", "$*", "@x", "a b", ".", "..", "x" * 129, "é", None, 3])
def test_bad_names_rejected(bad):
    with pytest.raises(m.MessageError, match=r"^body: expected a name matching"):
        m.orbit_key("demo", bad)
    with pytest.raises(m.MessageError, match=r"^scenario: expected a name matching"):
        m.status_key(bad)


@pytest.mark.parametrize(
    "key",
    [
        "astrodyn/demo",
        "astrodyn/demo/sat/velocity",
        "other/demo/sat/orbit",
        "astrodyn/demo/sat/orbit/extra",
        "astrodyn/demo/@status/x",
        "astrodyn/demo/@control",
        "astrodyn/demo/@nope/x",
        "astrodyn/*/sat/orbit",
        "astrodyn/demo/**/orbit",
        "astrodyn//sat/orbit",
    ],
)
def test_parse_key_rejects(key):
    with pytest.raises(m.MessageError, match=r"^key"):
        m.parse_key(key)


def test_schema_for_key():
    assert m.schema_for_key("astrodyn/s/b/orbit") == ("astrodyn.OrbitState", m.ORBIT_SCHEMA)
    assert m.schema_for_key("astrodyn/s/b/attitude") == ("astrodyn.AttitudeState", m.ATTITUDE_SCHEMA)
    assert m.schema_for_key("astrodyn/s/b/crosscheck") == ("astrodyn.CrossCheck", m.CROSSCHECK_SCHEMA)
    assert m.schema_for_key("astrodyn/s/@event") == ("astrodyn.Event", m.EVENT_SCHEMA)
    assert m.schema_for_key("astrodyn/s/@status") == ("astrodyn.Status", m.STATUS_SCHEMA)
    assert m.schema_for_key("astrodyn/s/@control/stop") is None
    assert m.schema_for_key("astrodyn/s/@alive/orbit") is None
    assert m.schema_for_key("astrodyn/s/@batch/orbit") is None


# ------------------------------------------------------------------------- round trips


@given(finite, st.integers(0, 2**53 - 1), st.sampled_from(m.ORBIT_MODELS), vec3, vec3, st.floats(1e-10, 1e30))
def test_orbit_round_trip_exact(t, seq, model, r, v, mu):
    msg = m.orbit_message(t, seq, model, r, v, mu)
    data = m.encode(msg)
    assert b" " not in data  # compact
    back = m.decode(data, "astrodyn/s/b/orbit")
    assert back == msg  # float equality: repr round-trips exactly
    assert [math.copysign(1, x) for x in back["r"]] == [math.copysign(1, x) for x in r]  # -0.0 kept
    assert json.loads(data) == msg  # plain JSON, readable by anyone


@given(finite, st.integers(0, 2**53 - 1), st.sampled_from(m.ATTITUDE_MODELS), quats, vec3)
def test_attitude_round_trip_exact(t, seq, model, q, w):
    msg = m.attitude_message(t, seq, model, q, w)
    assert m.decode(m.encode(msg), "attitude") == msg


def test_crosscheck_event_status_round_trip():
    cc = m.crosscheck_message(10.0, 1, [3.0, 4.0, 0.0], [0.0, 0.0, -2.0])
    assert cc["dr_norm"] == 5.0 and cc["dv_norm"] == 2.0 and cc["reference"] == "rebound-ias15"
    assert m.decode(m.encode(cc), "astrodyn/s/b/crosscheck") == cc
    ev = m.event_message(0.0, 0, "orbit", "restart", "restarted from t = 12 s (ünïcode ok)")
    assert m.decode(m.encode(ev), "astrodyn/s/@event") == ev
    stt = m.status_message(5.0, 2, "running", 5.0, rate=10.0, messages=12, processes={"orbit": "alive"})
    assert m.decode(m.encode(stt), "astrodyn/s/@status") == stt
    assert m.decode(m.encode(stt), "astrodyn.Status") == stt  # a schema name works as the kind


def test_builders_accept_numpy():
    msg = m.orbit_message(np.float64(1.0), np.int64(3), "j2", np.array([7e6, 0, 0]), np.array([0, 7.5e3, 0]), np.float64(MU_EARTH))
    assert type(msg["seq"]) is int and type(msg["r"][0]) is float
    raw = {"t": 1.0, "seq": 3, "model": "j2", "r": np.array([7e6, 0.0, 0.0]), "v": [0.0, 7.5e3, np.float64(0.0)], "mu": MU_EARTH, "frame": "GCRF"}
    assert m.encode(raw, "orbit") == m.encode(msg)


def test_seq_float_integer_normalized_like_json_schema_integer():
    # JSON Schema 2020-12: "integer" is any number with zero fractional part, so 3.0 is valid
    data = b'{"t":0,"seq":3.0,"model":"kepler","r":[1,0,0],"v":[0,1,0],"mu":1,"frame":"GCRF"}'
    assert m.decode(data, "orbit")["seq"] == 3 and type(m.decode(data, "orbit")["seq"]) is int


# ------------------------------------------------------------------------- every validation error

GOOD = {
    "orbit": {"t": 1.0, "seq": 0, "model": "kepler", "r": [7e6, 0.0, 0.0], "v": [0.0, 7.5e3, 0.0], "mu": MU_EARTH, "frame": "GCRF"},
    "attitude": {"t": 1.0, "seq": 0, "model": "torque_free", "q": [1.0, 0.0, 0.0, 0.0], "w": [0.1, 0.0, 0.0]},
    "crosscheck": {"t": 1.0, "seq": 0, "dr": [0.0, 0.0, 0.0], "dv": [0.0, 0.0, 0.0], "dr_norm": 0.0, "dv_norm": 0.0, "reference": "rebound-ias15"},
    "event": {"t": 1.0, "seq": 0, "process": "orbit", "kind": "start", "detail": ""},
    "status": {"t": 1.0, "seq": 0, "state": "running", "real_time_factor": 1.0},
}

# (kind, field, bad value, exact expected message)
ERRORS = [
    ("orbit", "t", "1", 'orbit.t: expected a finite number, got "1"'),
    ("orbit", "t", True, "orbit.t: expected a finite number, got true"),
    ("orbit", "t", None, "orbit.t: expected a finite number, got null"),
    ("orbit", "seq", -1, "orbit.seq: expected an integer 0 <= seq <= 2**53-1, got -1"),
    ("orbit", "seq", 1.5, "orbit.seq: expected an integer 0 <= seq <= 2**53-1, got 1.5"),
    ("orbit", "seq", 2**53, "orbit.seq: expected an integer 0 <= seq <= 2**53-1, got 9007199254740992"),
    ("orbit", "seq", False, "orbit.seq: expected an integer 0 <= seq <= 2**53-1, got false"),
    ("orbit", "model", "rk4", 'orbit.model: expected one of kepler, j2, zonal, third_body, actuated, got "rk4"'),
    ("orbit", "model", "torque_free", 'orbit.model: expected one of kepler, j2, zonal, third_body, actuated, got "torque_free"'),
    ("orbit", "r", [1.0, "x"], 'orbit.r: expected array of 3 finite numbers, got [1.0, "x"]'),
    ("orbit", "r", [1.0, 2.0, 3.0, 4.0], "orbit.r: expected array of 3 finite numbers, got [1.0, 2.0, 3.0, 4.0]"),
    ("orbit", "r", {"x": 1}, 'orbit.r: expected array of 3 finite numbers, got {"x": 1}'),
    ("orbit", "v", [0.0, float("nan"), 0.0], "orbit.v: expected array of 3 finite numbers, got [0.0, NaN, 0.0]"),
    ("orbit", "v", [0.0, True, 0.0], "orbit.v: expected array of 3 finite numbers, got [0.0, true, 0.0]"),
    ("orbit", "mu", 0.0, "orbit.mu: expected > 0.0, got 0.0"),
    ("orbit", "mu", -1.0, "orbit.mu: expected > 0.0, got -1.0"),
    ("orbit", "mu", float("inf"), "orbit.mu: expected a finite number, got Infinity"),
    ("orbit", "frame", "G/CRF", 'orbit.frame: expected a frame name matching [A-Za-z0-9_.-]{1,128}, got "G/CRF"'),
    ("orbit", "frame", 7, "orbit.frame: expected a frame name matching [A-Za-z0-9_.-]{1,128}, got 7"),
    ("attitude", "q", [1.0, 0.0, 0.0], "attitude.q: expected array of 4 finite numbers, got [1.0, 0.0, 0.0]"),
    ("attitude", "q", [2.0, 0.0, 0.0, 0.0], "attitude.q: expected a unit quaternion (| |q| - 1 | <= 1e-09), got |q| = 2.0"),
    ("attitude", "w", [0.0, 0.0], "attitude.w: expected array of 3 finite numbers, got [0.0, 0.0]"),
    ("attitude", "model", "none", 'attitude.model: expected one of torque_free, gravity_gradient, gyrostat, heavy_top, user, flexible, rolling_disk, actuated, got "none"'),
    ("crosscheck", "dr_norm", -1.0, "crosscheck.dr_norm: expected >= 0.0, got -1.0"),
    ("crosscheck", "dv_norm", "0", 'crosscheck.dv_norm: expected a finite number, got "0"'),
    ("crosscheck", "dv", [0, 0], "crosscheck.dv: expected array of 3 finite numbers, got [0, 0]"),
    ("crosscheck", "reference", "scipy", 'crosscheck.reference: expected one of rebound-ias15, got "scipy"'),
    ("event", "process", "@x", 'event.process: expected a process name matching [A-Za-z0-9_.-]{1,128}, got "@x"'),
    ("event", "kind", "Start", 'event.kind: expected a lower-case word matching ^[a-z][a-z_]{0,31}$, got "Start"'),
    ("event", "detail", 5, "event.detail: expected a string of at most 4096 characters, got 5"),
    ("event", "detail", "x" * 4097, 'event.detail: expected a string of at most 4096 characters, got "' + "x" * 76 + "..."),
    ("status", "state", "walking", 'status.state: expected one of starting, running, paused, stopping, stopped, error, got "walking"'),
    ("status", "real_time_factor", -1, "status.real_time_factor: expected >= 0.0, got -1"),
    ("status", "rate", 0.0, "status.rate: expected > 0.0, got 0.0"),
    ("status", "messages", -5, "status.messages: expected an integer 0 <= messages <= 2**53-1, got -5"),
    ("status", "processes", {"orbit": 1}, 'status.processes: expected an object name -> state string, got {"orbit": 1}'),
    ("status", "detail", [], "status.detail: expected a string of at most 4096 characters, got []"),
]


@pytest.mark.parametrize("kind,field,value,expected", ERRORS, ids=[f"{k}.{f}-{i}" for i, (k, f, _, _) in enumerate(ERRORS)])
def test_every_validation_error_message(kind, field, value, expected):
    msg = dict(GOOD[kind], **{field: value})
    with pytest.raises(m.MessageError) as info:
        m.validate(msg, kind)
    assert str(info.value) == expected
    assert not m.is_valid(msg, kind)


@pytest.mark.parametrize("kind", list(GOOD))
def test_missing_extra_and_non_object(kind):
    assert m.is_valid(dict(GOOD[kind]), kind)
    for field in GOOD[kind]:
        msg = {k: v for k, v in GOOD[kind].items() if k != field}
        with pytest.raises(m.MessageError, match=rf"^{kind}\.{field}: expected a value \(required field\), got nothing$"):
            m.validate(msg, kind)
    with pytest.raises(m.MessageError, match=rf"^{kind}: expected only fields .*, got extra zzz$"):
        m.validate(dict(GOOD[kind], zzz=1), kind)
    with pytest.raises(m.MessageError, match=rf"^{kind}: expected a JSON object, got \[1, 2\]$"):
        m.validate([1, 2], kind)


@pytest.mark.parametrize(
    "data,expected",
    [
        (b"\xff\xfe", r"^payload: expected UTF-8 JSON"),
        (b"{not json", r"^payload: expected UTF-8 JSON"),
        (b"", r"^payload: expected UTF-8 JSON"),
        (b"[" * 100000, r"^payload: expected UTF-8 JSON"),  # deep nesting: RecursionError caught
        (b'{"t":NaN,"seq":0,"model":"kepler","r":[1,0,0],"v":[0,1,0],"mu":1,"frame":"GCRF"}', r"^payload: expected JSON numbers, got NaN$"),
        (b'{"t":0,"seq":0,"model":"kepler","r":[Infinity,0,0],"v":[0,1,0],"mu":1,"frame":"GCRF"}', r"^payload: expected JSON numbers, got Infinity$"),
        (b'{"t":0,"seq":0,"model":"kepler","r":[1e999,0,0],"v":[0,1,0],"mu":1,"frame":"GCRF"}', r"^orbit\.r: expected array of 3 finite numbers, got \[Infinity, 0, 0\]$"),
        (b'"just a string"', r'^orbit: expected a JSON object, got "just a string"$'),
    ],
)
def test_decode_rejects_garbage(data, expected):
    with pytest.raises(m.MessageError, match=expected):
        m.decode(data, "astrodyn/s/b/orbit")


def test_decode_bad_key_or_kind():
    for bad in ("astrodyn/s/@control/stop", "velocity", "astrodyn/s/b/velocity", None, ["orbit"]):
        with pytest.raises(m.MessageError, match=r"^key"):
            m.decode(b"{}", bad)


@given(st.binary(max_size=300))
def test_decode_random_bytes_never_raises_anything_else(data):
    for kind in ("orbit", "attitude", "crosscheck", "event", "status"):
        try:
            m.decode(data, kind)
        except m.MessageError:
            pass


# ------------------------------------------------------------------------- NaN / inf rejection on encode


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), -float("inf")])
def test_nan_rejected_everywhere(bad):
    with pytest.raises(m.MessageError, match=r"^orbit\.r: expected array of 3 finite numbers"):
        m.orbit_message(0.0, 0, "kepler", [bad, 0, 0], [0, 1, 0], 1.0)
    with pytest.raises(m.MessageError, match=r"^orbit\.t: expected a finite number"):
        m.orbit_message(bad, 0, "kepler", [1, 0, 0], [0, 1, 0], 1.0)
    with pytest.raises(m.MessageError, match=r"^attitude\.w: expected array of 3 finite numbers"):
        m.attitude_message(0.0, 0, "torque_free", [1, 0, 0, 0], [0, bad, 0])
    # plain encode without a kind still refuses and names the field
    with pytest.raises(m.MessageError, match=r"^message\.v\[1\]: expected a finite number, got a NaN or infinity$"):
        m.encode({"t": 0.0, "v": [0.0, bad]})
    with pytest.raises(m.MessageError, match=r"^message\.x: expected a finite number"):
        m.encode({"x": np.float64(bad)})
    r = np.zeros((5, 3))
    r[3, 2] = bad
    with pytest.raises(m.MessageError, match=r"^orbit\.r\[3\]: expected array of 3 finite numbers"):
        m.encode_orbit_batch(0.0, 0, "kepler", r, np.ones((5, 3)), 1.0)
    with pytest.raises(m.MessageError, match=r"^orbit\.mu: expected a finite number"):
        m.encode_orbit_batch(0.0, 0, "kepler", np.ones((5, 3)), np.ones((5, 3)), bad)


def test_encode_rejects_unserializable():
    with pytest.raises(m.MessageError, match=r"^message: expected JSON-serializable values, got object"):
        m.encode({"x": object()})


# ------------------------------------------------------------------------- batch encoders


def _rand_states(n, seed):
    rng = np.random.default_rng(seed)
    r = rng.normal(size=(n, 3)) * 10.0 ** rng.integers(-3, 12, size=(n, 1))
    v = rng.normal(size=(n, 3)) * 10.0 ** rng.integers(-3, 5, size=(n, 1))
    r[0] = [-0.0, 0.0, 1e-300]  # signed zero and a subnormal-range exponent survive
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return r, v, q


def test_orbit_batch_equals_single_encoder():
    r, v, _ = _rand_states(200, 1)
    seqs = np.arange(200) + 7
    out = m.encode_orbit_batch(123.456, seqs, "j2", r, v, MU_EARTH, "GCRF")
    assert len(out) == 200
    for i in range(200):
        assert out[i] == m.encode(m.orbit_message(123.456, int(seqs[i]), "j2", r[i], v[i], MU_EARTH))
        back = m.decode(out[i], "orbit")
        assert back["r"] == r[i].tolist() and back["v"] == v[i].tolist()  # bit-exact


def test_attitude_batch_equals_single_encoder():
    _, w, q = _rand_states(200, 2)
    out = m.encode_attitude_batch(0.1, 5, "gyrostat", q, w)
    for i in range(200):
        assert out[i] == m.encode(m.attitude_message(0.1, 5, "gyrostat", q[i], w[i]))
        assert m.decode(out[i], "attitude")["q"] == q[i].tolist()


def test_batch_encoder_errors():
    ones = np.ones((4, 3))
    with pytest.raises(m.MessageError, match=r"^orbit\.v: expected an array of shape \(N, 3\) with the same N for every field, got shape \(3, 3\)$"):
        m.encode_orbit_batch(0.0, 0, "kepler", ones, np.ones((3, 3)), 1.0)
    with pytest.raises(m.MessageError, match=r"^orbit\.seq: expected an integer or an array of 4 integers"):
        m.encode_orbit_batch(0.0, [0, 1], "kepler", ones, ones, 1.0)
    with pytest.raises(m.MessageError, match=r"^orbit\.seq: expected integers 0 <= seq <= 2\*\*53-1, got range \[-1, -1\]$"):
        m.encode_orbit_batch(0.0, -1, "kepler", ones, ones, 1.0)
    with pytest.raises(m.MessageError, match=r"^orbit\.model: expected one of kepler"):
        m.encode_orbit_batch(0.0, 0, "rk4", ones, ones, 1.0)
    with pytest.raises(m.MessageError, match=r"^orbit\.frame: expected a frame name"):
        m.encode_orbit_batch(0.0, 0, "kepler", ones, ones, 1.0, frame='a"b')
    with pytest.raises(m.MessageError, match=r"^orbit\.mu: expected > 0"):
        m.encode_orbit_batch(0.0, 0, "kepler", ones, ones, -1.0)
    q = np.tile([1.0, 0, 0, 0], (4, 1))
    q[2] = [1.0, 1e-4, 0, 0]
    with pytest.raises(m.MessageError, match=r"^attitude\.q\[2\]: expected a unit quaternion"):
        m.encode_attitude_batch(0.0, 0, "torque_free", q, ones)
    assert m.encode_orbit_batch(0.0, 0, "kepler", np.zeros((0, 3)), np.zeros((0, 3)), 1.0) == []


# ------------------------------------------------------------------------- batch envelope framing


def _reference_frame(items):
    """The documented layout, written independently with struct."""
    out = b"ADB1" + struct.pack("<I", len(items))
    for key, payload in items:
        kb = key.encode()
        out += struct.pack("<H", len(kb)) + kb + struct.pack("<I", len(payload)) + payload
    return out


@given(st.lists(st.tuples(names.map(lambda b: f"astrodyn/s/{b}/orbit"), st.binary(max_size=200)), max_size=20))
def test_batch_round_trip_and_layout(items):
    env = m.encode_batch(items)
    assert env == _reference_frame(items)
    assert m.decode_batch(env) == items


def test_batch_of_real_payloads_splits_back_without_reencoding():
    r, v, q = _rand_states(50, 3)
    orbit = m.encode_orbit_batch(1.0, 0, "kepler", r, v, MU_EARTH)
    att = m.encode_attitude_batch(1.0, 0, "torque_free", q, v)
    items = [(m.orbit_key("demo", f"sat{i}"), p) for i, p in enumerate(orbit)]
    items += [(m.attitude_key("demo", f"sat{i}"), p) for i, p in enumerate(att)]
    back = m.decode_batch(m.encode_batch(items))
    assert back == items
    for key, payload in back:
        m.decode(payload, key)


def test_batch_truncation_at_every_byte_is_a_clear_error():
    items = [("astrodyn/s/a/orbit", b'{"x":1}'), ("astrodyn/s/b/orbit", b"")]
    env = m.encode_batch(items)
    for cut in range(len(env)):
        with pytest.raises(m.MessageError, match=r"^batch(\[\d\]\.\w+)?: expected .*(truncated|entries)"):
            m.decode_batch(env[:cut])
    assert m.decode_batch(env) == items


def test_batch_framing_errors():
    env = m.encode_batch([("astrodyn/s/a/orbit", b"abc")])
    with pytest.raises(m.MessageError, match=r"^batch: expected magic b'ADB1', got b'XDB1'$"):
        m.decode_batch(b"X" + env[1:])
    with pytest.raises(m.MessageError, match=r"^batch: expected 1 entries ending at byte 35, got 2 trailing bytes$"):
        m.decode_batch(env + b"zz")
    with pytest.raises(m.MessageError, match=r"^batch: expected at least 8 header bytes, got 3 \(truncated\)$"):
        m.decode_batch(b"ADB")
    huge = b"ADB1" + struct.pack("<I", 2**32 - 1) + b"\x00" * 12  # count far beyond the data: no allocation
    with pytest.raises(m.MessageError, match=r"^batch: expected at most 2 entries in 20 bytes, header says 4294967295"):
        m.decode_batch(huge)
    bad_utf8 = b"ADB1" + struct.pack("<I", 1) + struct.pack("<H", 2) + b"\xff\xfe" + struct.pack("<I", 0)
    with pytest.raises(m.MessageError, match=r"^batch\[0\]\.key: expected UTF-8"):
        m.decode_batch(bad_utf8)
    with pytest.raises(m.MessageError, match=r"^batch\[0\]\.payload: expected bytes, got str$"):
        m.encode_batch([("k", "not bytes")])
    with pytest.raises(m.MessageError, match=r"^batch\[0\]: expected a \(key, payload\) pair"):
        m.encode_batch([("k",)])
    with pytest.raises(m.MessageError, match=r"^batch\[0\]\.key: expected a string"):
        m.encode_batch([(b"k", b"")])


@given(st.binary(max_size=200))
def test_decode_batch_random_bytes(data):
    try:
        m.decode_batch(data)
    except m.MessageError:
        pass
    try:
        m.decode_batch(b"ADB1" + data)
    except m.MessageError:
        pass


# ------------------------------------------------------------------------- schemas vs jsonschema

SCHEMA_OF = {"orbit": m.ORBIT_SCHEMA, "attitude": m.ATTITUDE_SCHEMA, "crosscheck": m.CROSSCHECK_SCHEMA, "event": m.EVENT_SCHEMA, "status": m.STATUS_SCHEMA}


@pytest.mark.parametrize("kind", list(SCHEMA_OF))
def test_schemas_are_valid_draft_2020_12(kind):
    schema = SCHEMA_OF[kind]
    assert schema["$schema"] == "https://json-schema.org/draft/2020-12/schema"
    jsonschema.Draft202012Validator.check_schema(schema)
    assert m.SCHEMAS[schema["title"]] is schema
    json.dumps(schema)  # serializable as the MCAP schema data
    jsonschema.Draft202012Validator(schema).validate(GOOD[kind])


# Values that probe each rule: numbers, bools, strings, lists of the wrong length/contents.
any_value = st.one_of(
    st.none(), st.booleans(), st.integers(-5, 5), st.integers(2**53 - 2, 2**53 + 1),
    st.floats(allow_nan=False, allow_infinity=False), st.just(3.0), st.just(-0.0),
    st.text(max_size=6), st.sampled_from(["kepler", "torque_free", "GCRF", "start", "running", "rebound-ias15", "a/b", "@x"]),
    st.lists(finite, min_size=2, max_size=5), st.lists(st.one_of(finite, st.text(max_size=2), st.booleans()), min_size=3, max_size=4),
    st.dictionaries(st.sampled_from(["orbit", "@bad", "x y"]), st.one_of(st.text(max_size=3), st.integers()), max_size=2),
)


@st.composite
def mutated(draw):
    kind = draw(st.sampled_from(list(GOOD)))
    msg = dict(GOOD[kind])
    for _ in range(draw(st.integers(0, 3))):
        action = draw(st.sampled_from(["set", "drop", "add"]))
        if action == "set":
            msg[draw(st.sampled_from(sorted(msg) + ["rate", "messages", "detail", "processes"]))] = draw(any_value)
        elif action == "drop" and msg:
            msg.pop(draw(st.sampled_from(sorted(msg))))
        else:
            msg[draw(st.sampled_from(["extra", "rate", "detail"]))] = draw(any_value)
    return kind, msg


@given(mutated())
def test_hand_validator_agrees_with_jsonschema(case):
    kind, msg = case
    reference_ok = jsonschema.Draft202012Validator(SCHEMA_OF[kind]).is_valid(msg)
    ours_ok = m.is_valid(json.loads(json.dumps(msg)), kind)
    if kind == "attitude" and reference_ok and not ours_ok:
        # the only rule beyond the schema: unit quaternion
        q = msg["q"]
        assert abs(math.sqrt(sum(c * c for c in q)) - 1) > m.QUAT_NORM_TOL
        return
    assert ours_ok == reference_ok, (kind, msg)


@given(st.sampled_from(list(GOOD)), finite, st.integers(0, 2**53 - 1), vec3, quats)
def test_generated_valid_messages_pass_both(kind, t, seq, vec, q):
    msg = dict(GOOD[kind], t=t, seq=seq)
    for field in ("r", "v", "w", "dr", "dv"):
        if field in msg:
            msg[field] = vec
    if "q" in msg:
        msg["q"] = q
    assert jsonschema.Draft202012Validator(SCHEMA_OF[kind]).is_valid(msg)
    assert m.is_valid(m.encode(msg), kind)


def test_an_integer_beyond_float64_is_a_message_error_never_an_overflow():
    """A JSON integer of 400 digits fits no float64: decode and the builders say which field
    (the contract: MessageError for numbers beyond float64), instead of the OverflowError
    that math.isfinite / float() raise on it."""
    huge = "1" + "0" * 399
    good = {"t": 1.0, "seq": 0, "model": "kepler", "r": [7e6, 0.0, 0.0], "v": [0.0, 7.5e3, 0.0], "mu": 3.986004418e14,
            "frame": "GCRF"}
    for field, text in [("t", huge), ("mu", "-" + huge), ("r", f"[{huge},0,0]"), ("seq", huge)]:
        payload = json.dumps({**good, field: "@"}).replace('"@"', text).encode()
        with pytest.raises(m.MessageError, match=rf"orbit\.{field}: expected"):
            m.decode(payload, "orbit")
    for args, field in [((10**400, 0), "t"), ((1.0, 10**400), "seq")]:
        with pytest.raises(m.MessageError, match=rf"orbit\.{field}: expected"):
            m.orbit_message(*args, "kepler", [7e6, 0, 0], [0, 7.5e3, 0], 3.986004418e14)
    with pytest.raises(m.MessageError, match=r"orbit\.r: expected array of 3 finite numbers"):
        m.orbit_message(1.0, 0, "kepler", [10**400, 0, 0], [0, 7.5e3, 0], 3.986004418e14)
