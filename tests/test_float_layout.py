"""The compiled layout pass (astrodyn.messages.floatlayout) against Python's own ``repr``.

msgspec writes each float with the shortest round-trip digits but lays some out unlike
``repr`` (``0.00001``, ``1e-7``, ``1e16``); ``as_repr_layout`` rewrites its JSON so that
every float reads as ``json.dumps`` (which writes floats by ``float.__repr__``) would
write it.  The references here are ``json.dumps`` and ``json.loads``, not the module's
own rules.  The module is built by setup.py (``make install``); the Python path the codec
takes without it is checked against the same reference at the end.
"""

from __future__ import annotations

import json
import random

import msgspec
import numpy as np
import pytest

from astrodyn import messages as m
from astrodyn.messages import codec
from astrodyn.messages.floatlayout import as_repr_layout
from test_encode_single import hard_floats


def _reference(values) -> bytes:
    return json.dumps(values, separators=(",", ":"), ensure_ascii=False).encode()


def test_every_finite_float_reads_as_repr_writes_it():
    """Random bit patterns (every exponent), subnormals, the extremes and the neighbours of
    each power of ten, both signs: one document of about 600,000 floats (the heap buffer),
    and each float alone (the stack buffer)."""
    x = hard_floats(600_000, 7)
    values = x[np.isfinite(x)].tolist()
    assert as_repr_layout(msgspec.json.encode(values)) == _reference(values)
    for v in values[::97]:
        assert as_repr_layout(msgspec.json.encode(v)) == repr(v).encode()


def test_strings_integers_and_literals_are_left_as_they_are():
    tricky = ['1e5', '0.00001', 'null', 'x"1e-7"', 'back\\slash 1e16\\', '\\"0.00001', 'é 1e-7 ☃', '']
    doc = {"s": tricky, "k": {"1e16": 1e16, "0.00001": 1e-5}, "i": [0, -1, 12345678901234567890, 10**30],
           "b": [True, False], "f": [1e-7, 1e16, 0.5]}
    assert as_repr_layout(msgspec.json.encode(doc)) == _reference(doc)
    plain = msgspec.json.encode({"s": tricky, "i": [0, -7, 10**20], "f": [0.5, 1e-4, 123.25]})
    assert as_repr_layout(plain) is plain  # nothing to change: the same object back


@pytest.mark.parametrize("values", [[1.0, float("nan")], [float("inf")], {"a": [0.5, float("-inf")]}, [None]])
def test_a_null_gives_none(values):
    """msgspec writes NaN and infinities as null; the messages handed over hold no None."""
    assert as_repr_layout(msgspec.json.encode(values)) is None


def test_hostile_documents_keep_their_values_and_never_crash():
    """Whatever the bytes, the pass returns bytes or None in bounded time; a valid JSON
    document reads back (``json.loads``) to the same values."""
    rng = random.Random(11)
    alphabet = b'0123456789-+.eE"\\,[]{}: nulltrfa'
    pieces = [b"1e", b"-", b"1e+", b"0.0000", b"1" * 40 + b".5", b"1e99999", b"-0.00000", b"1.e5", b"\"", b"e-7"]
    for _ in range(20_000):
        if rng.random() < 0.5:
            data = bytes(rng.choice(alphabet) for _ in range(rng.randint(0, 40)))
        else:
            data = b",".join(rng.choice(pieces) for _ in range(rng.randint(1, 6)))
        out = as_repr_layout(data)
        assert out is None or type(out) is bytes
        try:
            before = json.loads(data)
        except ValueError:
            continue
        assert out is not None or b"null" in data
        if out is not None:
            assert json.loads(out) == before and type(json.loads(out)) is type(before)
    with pytest.raises(TypeError, match="takes bytes"):
        as_repr_layout("1e-7")


def test_the_python_path_without_the_compiled_module_writes_the_same_bytes(monkeypatch):
    """Where setup.py could not compile the module, the generated checks hand floats outside
    the range where msgspec and ``repr`` agree to msgspec as raw ``repr`` text."""
    monkeypatch.setattr(codec, "_LAYOUT", None)
    x = hard_floats(2000, 3)
    x = x[np.isfinite(x)]
    for kind in ("orbit", "attitude"):
        for mode in (codec._TEXT, codec._TEXT | codec._VALID):
            template = (m.orbit_message(1.5, 1, "kepler", [7e6, 0.0, 0.0], [0.0, 7.5e3, 0.0], 3.986004418e14)
                        if kind == "orbit" else m.attitude_message(1.5, 1, "torque_free", [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0]))
            check = codec._generated_check.__wrapped__(kind, tuple(template), mode)
            assert "_layout" not in check.source and "_Raw" in check.source
            for k in range(0, len(x) - 3, 3):
                msg = dict(template, t=float(x[k]), **({"v": x[k:k + 3].tolist()} if kind == "orbit" else {"w": x[k:k + 3].tolist()}))
                try:
                    expected = codec._encode_reference(msg, kind if mode & codec._VALID else None)
                except m.MessageError:
                    expected = None
                assert check(msg) == expected  # None: refused, as the reference refuses
