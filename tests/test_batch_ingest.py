"""The compiled batch ingest (astrodyn.recording.ingest) against the logger's Python path.

References, both independent of the compiled code:

* the slow path's verdict on each payload (``messages.decode``: json.loads + the
  hand-written validator, itself checked against the ``jsonschema`` package in
  tests/test_messages.py): the compiled check must never accept what it rejects, and must
  give the same ``t`` (bit for bit) and ``seq`` when it accepts;
* the file the per-message path writes: the same entries handed to
  ``Logger.handle(key, payload)`` one by one (never compiled) must give the same messages
  (topic, seq, log_time, bytes, in file order), the same malformed count and the same seq
  accounting as the envelopes through the compiled path -- with gaps, duplicates, late
  messages, bad payloads, foreign keys, new times mid-envelope, chunk boundaries and file
  rolls in between.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from mcap.records import Channel, Message
from mcap.stream_reader import StreamReader

from astrodyn import messages as m
from astrodyn.recording import ingest
from astrodyn.recording.writer import INGEST_GRAMMAR, McapRecorder
from astrodyn.service.logger import Logger
from test_messages_fast import BASE, EDITS, byte_mutants, canonical, ordinary, slow

EPOCH_NS = 1_774_008_000_000_000_000


def compiled(data: bytes, kind: str):
    """The compiled check of one payload: None (not taken) or (t text, seq)."""
    buf = np.frombuffer(data, dtype=np.uint8)
    out = np.zeros(3, dtype=np.int64)
    code = ingest.KIND_ORBIT if kind == "orbit" else ingest.KIND_ATTITUDE
    ok = ingest._check_entry(buf, 0, buf.shape[0], code, *INGEST_GRAMMAR, m.QUAT_NORM_TOL, out)
    return (data[out[0] : out[1]], int(out[2])) if ok else None


def agrees(data: bytes, kind: str) -> bool:
    found = compiled(data, kind)
    if found is None:
        return True
    ref = slow(data, kind)
    t = float(found[0])
    return ref[0] == "ok" and math.copysign(1.0, t) == math.copysign(1.0, ref[1]) and t == ref[1] and found[1] == ref[2]


@settings(max_examples=300)
@given(canonical(ordinary))
def test_canonical_payloads_are_taken_and_agree(case):
    kind, data = case
    assert agrees(data, kind), data
    # the regex takes it; so must the compiled check, except the margin cases it leaves
    # to the exact check (mu below 1e-300; |q| - 1 within 0.1 % of the tolerance)
    if m.FAST_CHECKS[kind](data) is not None:
        msg = m.decode(data, kind)
        margin = (kind == "orbit" and msg["mu"] <= 1e-300) or (
            kind == "attitude" and abs(math.sqrt(sum(x * x for x in msg["q"])) - 1.0) > 0.999 * m.QUAT_NORM_TOL)
        assert margin or compiled(data, kind) is not None, data


@settings(max_examples=500)
@given(byte_mutants())
def test_mutated_payloads_never_accepted_wrongly(case):
    kind, data = case
    assert agrees(data, kind), data


@given(st.binary(max_size=300))
def test_random_bytes_never_accepted_wrongly(data):
    for kind in ("orbit", "attitude"):
        assert agrees(data, kind)


@pytest.mark.parametrize("kind,old,new", EDITS)
def test_edits(kind, old, new):
    data = BASE[kind].replace(old, new, 1)
    assert agrees(data, kind), data
    if slow(data, kind)[0] == "bad":
        assert compiled(data, kind) is None


@pytest.mark.parametrize("text", [b"1e307", b"9.999999999999999e+307", b"1e-300", b"1e-301", b"5e-324", b"1e-400",
                                  b"0.000000000000000000000001", b"12345678901234567.0", b"123456789012345678.0"])
def test_mu_edges(text):
    data = BASE["orbit"].replace(b"398600441800000.0", text, 1)
    assert agrees(data, "orbit")
    slow(data, "orbit")  # the reference path decides without raising
    if m.FAST_CHECKS["orbit"](data) is not None and float(text) > 1e-300 * (1 + 1e-12):
        assert compiled(data, "orbit") is not None, text
    if m.FAST_CHECKS["orbit"](data) is None:  # 18 integer digits: outside the canonical grammar
        assert compiled(data, "orbit") is None, text


def test_quaternion_norm_margin():
    # |q| - 1 just inside and just outside the tolerance: the exact check decides
    for eps, taken in ((0.5e-9, True), (0.9985e-9, True), (0.9995e-9, False), (1.0005e-9, False), (2e-9, False)):
        q = (1.0 + eps) * np.array([0.5, 0.5, 0.5, 0.5])
        data = (b'{"t":1.5,"seq":7,"model":"torque_free","q":[' + b",".join(repr(float(x)).encode() for x in q)
                + b'],"w":[0.1,0.2,-2.0]}')
        assert agrees(data, "attitude")
        assert (compiled(data, "attitude") is not None) == taken, eps


# ------------------------------------------------------------------ whole logger, both paths


def _read(paths):
    out = []
    for path in paths:
        topics = {}
        with open(path, "rb") as f:
            for rec in StreamReader(f, skip_magic=False).records:
                if isinstance(rec, Channel):
                    topics[rec.id] = rec.topic
                elif isinstance(rec, Message):
                    out.append((topics[rec.channel_id], rec.sequence, rec.log_time, rec.publish_time, rec.data))
    return out


def _logger(path, **kw):
    rec = McapRecorder(path, {"name": "c"}, epoch_ns=EPOCH_NS, **kw)
    return Logger(None, "c", rec), rec


def _entries(rng, n_bodies, k, chaos):
    """One envelope's entries at step k: orbit + attitude per body, with mischief."""
    t = k / 10
    okeys = [m.orbit_key("c", f"s{i}") for i in range(n_bodies)]
    akeys = [m.attitude_key("c", f"s{i}") for i in range(n_bodies)]
    r = rng.normal(size=(n_bodies, 3)) * 7e6
    v = rng.normal(size=(n_bodies, 3)) * 7e3
    q = rng.normal(size=(n_bodies, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    w = rng.normal(size=(n_bodies, 3))
    seqs = np.full(n_bodies, k)
    if chaos:
        seqs[rng.integers(n_bodies)] = max(k - 1, 0)  # duplicate or late
        seqs[rng.integers(n_bodies)] = k + 2  # gap
    items = list(zip(okeys, m.encode_orbit_batch(t, seqs, "kepler", r, v, 3.986004418e14)))
    items += list(zip(akeys, m.encode_attitude_batch(t, seqs, "torque_free", q, w)))
    if chaos:
        j = rng.integers(len(items))
        key, payload = items[j]
        kind = m.kind_of_key(key)
        edit = EDITS[rng.integers(len(EDITS))]
        if edit[0] == kind and edit[1] in payload:
            items[j] = (key, payload.replace(edit[1], edit[2], 1))
        j = rng.integers(len(items))  # another time mid-envelope
        items[j] = (items[j][0], items[j][1].replace(repr(float(t)).encode(), repr(float(t) + 0.05).encode(), 1))
        items.insert(rng.integers(len(items)), ("astrodyn/other/s0/orbit", items[0][1]))  # foreign key
        items.insert(rng.integers(len(items)), (m.event_key("c"), m.encode(m.event_message(t, k, "orbit", "info", "x"))))
        if rng.random() < 0.3:  # a new body joins: the layout changes
            items.append((m.orbit_key("c", f"late{k}"), items[0][1]))
    return items


@pytest.mark.parametrize("chaos,chunk_size,roll_size", [(False, 1 << 20, None), (True, 1 << 20, None),
                                                        (True, 3000, None), (True, 5000, 40_000)])
def test_compiled_and_python_paths_write_the_same_file(tmp_path, chaos, chunk_size, roll_size):
    rng = np.random.default_rng(11)
    batches = [_entries(rng, 40, k, chaos) for k in range(30)]
    kw = dict(chunk_size=chunk_size, roll_size=roll_size, flush_interval_s=1e-6 if roll_size else 1.0)
    fast_logger, fast_rec = _logger(str(tmp_path / "fast.mcap"), **kw)
    ref_logger, ref_rec = _logger(str(tmp_path / "ref.mcap"), **kw)
    slow_calls = []
    python_path = fast_logger._record
    fast_logger._record = lambda key, payload, now_ns, *sender: (slow_calls.append(key), python_path(key, payload, now_ns, *sender))
    for k, items in enumerate(batches):
        now_ns = EPOCH_NS + 10**9 * k  # the receive time, recorded as publish_time
        fast_logger._record_batch(m.batch_key("c", "orbit"), m.encode_batch(items), now_ns)
        for key, payload in items:
            ref_logger._record(key, payload, now_ns)
    # the compiled path really took most entries (otherwise this test proves nothing)
    n_entries = sum(len(items) for items in batches)
    assert len(slow_calls) <= (0.2 * n_entries if chaos else 0), (len(slow_calls), n_entries)
    for logger in (fast_logger, ref_logger):
        logger.recorder.close()
    fast, ref = _read(fast_rec.paths), _read(ref_rec.paths)
    assert len(fast) == len(ref) > 0
    assert fast == ref
    assert fast_logger.malformed == ref_logger.malformed
    assert fast_logger.states == ref_logger.states
    assert fast_logger.max_t == ref_logger.max_t
    assert fast_rec.seq.report() == ref_rec.seq.report()
    if chaos:
        totals = fast_rec.seq.totals()
        assert totals["missing"] > 0 and totals["duplicates"] > 0 and fast_logger.malformed > 0
    if roll_size:
        assert len(fast_rec.paths) > 2


def test_damaged_envelopes_are_reported_not_recorded(tmp_path):
    logger, rec = _logger(str(tmp_path / "x.mcap"))
    items = list(zip([m.orbit_key("c", "a"), m.orbit_key("c", "b")],
                     m.encode_orbit_batch(0.0, 0, "kepler", np.ones((2, 3)), np.ones((2, 3)), 1.0)))
    good = m.encode_batch(items)
    for bad in (good[:-1], good + b"x", b"ADB1", b"XXXX" + good[4:], good[:4] + b"\xff\xff\xff\x7f" + good[8:]):
        logger.handle(m.batch_key("c", "orbit"), bad)
    assert logger.malformed == 5 and rec.message_count == 0
    logger.handle(m.batch_key("c", "orbit"), good)
    assert rec.message_count == 2 and logger.states == 2
    # more entries than the logger's preallocated span arrays
    many = m.encode_batch([(m.orbit_key("c", f"b{i}"), items[0][1]) for i in range(5000)])
    logger.handle(m.batch_key("c", "orbit"), many)
    assert logger.states == 5002
    rec.close()


def test_envelopes_of_several_layouts_on_one_key_take_the_compiled_path(tmp_path, monkeypatch):
    """One publisher may put envelopes of different keys on one batch key in turn (the plant's
    states and sensor samples, then its actuator states; bench service's flood: orbit, then
    attitude).  The logger remembers a few layouts per key, so the slow path (decoding the
    envelope in Python to learn its keys) runs once per distinct layout, not once per
    envelope (before: every envelope, 2.5x the logger's CPU in the flood); the file is the
    same as recording each entry on its own key."""
    from astrodyn.service import logger as logger_module

    rng = np.random.default_rng(5)
    layouts = [["a", "b"], ["c"], ["a", "b", "c"]]  # three kinds of envelope, in turn on one key
    decodes = []
    real_decode = logger_module.messages.decode_batch
    monkeypatch.setattr(logger_module.messages, "decode_batch", lambda payload: (decodes.append(1), real_decode(payload))[1])
    fast_logger, fast_rec = _logger(str(tmp_path / "fast.mcap"))
    ref_logger, ref_rec = _logger(str(tmp_path / "ref.mcap"))
    n_envelopes = 0
    for k in range(20):
        for names in layouts:
            okeys = [m.orbit_key("c", f"s{name}{len(names)}") for name in names]
            r, v = rng.normal(size=(len(names), 3)) * 7e6, rng.normal(size=(len(names), 3)) * 7e3
            items = list(zip(okeys, m.encode_orbit_batch(k / 10, k, "kepler", r, v, 3.986004418e14)))
            now_ns = EPOCH_NS + 10**9 * k
            fast_logger._record_batch(m.batch_key("c", "plant"), m.encode_batch(items), now_ns)
            for key, payload in items:
                ref_logger._record(key, payload, now_ns)
            n_envelopes += 1
    assert len(decodes) == len(layouts) < n_envelopes, (len(decodes), n_envelopes)
    for logger in (fast_logger, ref_logger):
        logger.recorder.close()
    fast, ref = _read(fast_rec.paths), _read(ref_rec.paths)
    assert fast == ref and len(fast) == 20 * sum(len(names) for names in layouts)
    assert fast_logger.states == ref_logger.states == len(fast)


def test_a_new_layout_in_every_envelope_keeps_the_layout_cache_bounded(tmp_path):
    """Hostile: a publisher that sends envelopes with new keys every time, on one batch key
    and on many.  The logger's remembered layouts stay within their bounds (4 per key, 64 in
    all) and every entry is still recorded as on its own key."""
    from astrodyn.service import logger as logger_module

    rng = np.random.default_rng(9)
    fast_logger, fast_rec = _logger(str(tmp_path / "fast.mcap"))
    ref_logger, ref_rec = _logger(str(tmp_path / "ref.mcap"))
    for k in range(300):
        batch_key = m.batch_key("c", "p" if k < 150 else f"p{k}")  # one key, then a new key each time
        okeys = [m.orbit_key("c", f"b{k}-{i}") for i in range(3)]
        r, v = rng.normal(size=(3, 3)) * 7e6, rng.normal(size=(3, 3)) * 7e3
        items = list(zip(okeys, m.encode_orbit_batch(k / 10, 0, "kepler", r, v, 3.986004418e14)))
        fast_logger._record_batch(batch_key, m.encode_batch(items), EPOCH_NS + k)
        for key, payload in items:
            ref_logger._record(key, payload, EPOCH_NS + k)
        cached = fast_logger._layouts
        assert all(len(v) <= logger_module._LAYOUTS_PER_KEY for v in cached.values())
        assert sum(map(len, cached.values())) <= logger_module._MAX_LAYOUTS
    for logger in (fast_logger, ref_logger):
        logger.recorder.close()
    fast, ref = _read(fast_rec.paths), _read(ref_rec.paths)
    assert fast == ref and len(fast) == 900
