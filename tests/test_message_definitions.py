"""Each message type is defined once (issue 12 section 1; docs/architecture.md, section 5).

``astrodyn.messages.MESSAGE_TYPES`` holds one msgspec Struct per kind; the JSON Schema
stored with the MCAP channels, validation and decoding follow from it.  The hand-written
fast paths that remain (the logger's regex check, the compiled batch formatter, the
compiled MCAP ingest grammar) are checked here field by field against that definition, so
a field added to a Struct and forgotten in one of them fails a test.  The wire format is
checked against a recording made before the refactor (tests/fixtures/legacy-v0.mcap):
every payload in it decodes to the values ``json.loads`` reads, and encodes back to the
same bytes.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import jsonschema
import msgspec
import msgspec.inspect as ins
import numpy as np
import pytest

from astrodyn import messages as m
from astrodyn.recording import ingest
from astrodyn.recording.stream import open_stream

FIXTURE = Path(__file__).parent / "fixtures" / "legacy-v0.mcap"


def _example(kind: str) -> dict:
    """A valid message of ``kind`` with every field of its definition (optional ones
    included), values chosen from each field's type and constraints alone."""
    out = {}
    for f in ins.type_info(m.MESSAGE_TYPES[kind]).fields:
        t = f.type
        if isinstance(t, ins.UnionType):
            t = next(a for a in t.types if not isinstance(a, ins.UnsetType))
        extra = {}
        if isinstance(t, ins.Metadata):
            extra, t = t.extra or {}, t.type
        if isinstance(t, ins.FloatType):
            out[f.name] = 3.986004418e14 if t.gt is not None else 1234.5
        elif isinstance(t, ins.IntType):
            out[f.name] = 12345
        elif isinstance(t, ins.LiteralType):
            out[f.name] = extra.get("values", t.values)[0]
        elif isinstance(t, ins.ListType):
            n = t.min_length or 1
            if isinstance(t.item_type, ins.StrType):
                out[f.name] = ["pd#7"]
            elif isinstance(t.item_type, ins.IntType):
                out[f.name] = [2]
            elif isinstance(t.item_type, (ins.ListType, ins.Metadata)):  # per item a list of numbers
                inner = t.item_type.type if isinstance(t.item_type, ins.Metadata) else t.item_type
                k = inner.min_length or 1
                out[f.name] = [[6878137.123456789, -1.25e-3, 7612.5, 0.25][:k] for _ in range(n)]
            else:
                out[f.name] = [0.5] * n if n == 4 else [6878137.123456789, -1.25e-3, 7612.5][:n]  # 4: a unit quaternion
        elif isinstance(t, ins.StrType):
            out[f.name] = "GCRF" if t.pattern and "A-Z" in t.pattern else ("restart" if t.pattern else "a detail")
        elif isinstance(t, ins.DictType):
            out[f.name] = {"sc/gyro": {"t": 0.5, "w": [0.0, 1.0, 2.0]}} if isinstance(t.value_type, ins.DictType) \
                else {"orbit": "alive"}
        else:  # pragma: no cover - a new field type needs a value here
            raise AssertionError(f"{kind}.{f.name}: no example for {t}")
    return out


@pytest.mark.parametrize("kind", list(m.MESSAGE_TYPES))
def test_schema_validation_and_decoding_come_from_the_definition(kind):
    struct = m.MESSAGE_TYPES[kind]
    schema = m.json_schema(struct)
    assert m.SCHEMAS[f"astrodyn.{struct.__name__}"] == schema
    jsonschema.Draft202012Validator.check_schema(schema)
    assert list(schema["properties"]) == list(struct.__struct_fields__)
    example = _example(kind)
    jsonschema.Draft202012Validator(schema).validate(example)
    data = m.encode(example, kind)
    assert list(json.loads(data)) == list(struct.__struct_fields__)  # encoded in definition order
    assert m.decode(data, kind) == example
    assert msgspec.json.decode(data, type=struct) == msgspec.convert(example, struct)


@pytest.mark.parametrize("kind", sorted(m.FAST_CHECKS))
def test_fast_check_accepts_every_field_of_the_definition(kind):
    """The logger's regex path judges a canonical payload holding every field; a field added
    to the Struct and not to the regex makes it return None (the slow path), failing here."""
    data = m.encode(_example(kind), kind)
    assert m.FAST_CHECKS[kind](data) == (1234.5, 12345)


@pytest.mark.parametrize("kind", ["orbit", "attitude"])
def test_compiled_batch_formatter_writes_every_field_in_definition_order(kind):
    ex = _example(kind)
    if kind == "orbit":
        payloads = m.encode_orbit_batch(ex["t"], ex["seq"], ex["model"], np.array([ex["r"]]), np.array([ex["v"]]),
                                        ex["mu"], ex["frame"])
    else:
        payloads = m.encode_attitude_batch(ex["t"], ex["seq"], ex["model"], np.array([ex["q"]]), np.array([ex["w"]]))
    assert payloads == [m.encode(ex, kind)]  # byte for byte the single-message encoding
    assert list(json.loads(payloads[0])) == list(m.MESSAGE_TYPES[kind].__struct_fields__)


def test_compiled_ingest_grammar_names_every_field_in_definition_order():
    lits = ingest._LITERALS
    orbit = b"".join(lits[0:8])
    attitude = b"".join(lits[0:3] + lits[8:11])
    for kind, text in (("orbit", orbit), ("attitude", attitude)):
        names = [n.decode() for n in re.findall(rb'"(\w+)":', text)]
        assert names == list(m.MESSAGE_TYPES[kind].__struct_fields__), kind


def test_a_recording_made_before_the_refactor_reads_and_reencodes_bit_for_bit():
    n = 0
    with open_stream(FIXTURE) as s:
        for msg in s.messages():
            kind = m.kind_of_key(msg.topic)
            if kind is None:
                continue
            decoded = m.decode(msg.data, kind)
            assert decoded == json.loads(msg.data)  # the same values, float for float
            assert m.encode(decoded, kind) == msg.data  # and the same bytes back
            n += 1
    assert n > 900


@pytest.mark.parametrize("data", [
    b'{"\xff":0.0,"seq":0,"model":"torque_free","q":[1.0,0.0,0.0,0.0],"w":[0.0,0.0,0.0]}',  # found by hypothesis
    b'{"t":0.0,"seq":0,"model":"torque_free","q":[1.0,0.0,0.0,0.0],"w":[0.0,0.0,0.0],"\xc3":1}',
])
def test_invalid_utf8_anywhere_is_a_message_error(data):
    with pytest.raises(m.MessageError, match=r"^payload: expected UTF-8 JSON"):
        m.decode(data, "attitude")


def test_every_message_kind_has_its_one_definition():
    """The key rules (astrodyn.messages.keys) list the message kinds without importing the
    definitions; the two lists are the same, in the same order."""
    from astrodyn.messages import definitions, keys

    assert tuple(definitions.MESSAGE_TYPES) == keys.MESSAGE_KINDS
    for kind in keys.MESSAGE_KINDS:
        assert keys.schema_key("s", kind).endswith(f"/@schema/{kind}")
