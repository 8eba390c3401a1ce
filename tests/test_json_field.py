"""messages.json_field: one field of JSON text from outside, or None for anything else.

The reference is the standard library's json module: for text json.loads reads as an object,
the field must be exactly what json.loads gives; for every other input (not JSON, bad UTF-8,
not an object, nested past the parser's depth) the answer is None, never an exception.
"""

import json

import pytest

from astrodyn.messages import json_field

OBJECTS = [
    b'{"seq": 3, "t": 0.1}',
    b'{"seq": -1}',
    b'{"seq": true}',
    b'{"seq": null}',
    b'{"seq": [1, 2]}',
    b'{"seq": {"inner": 1}}',
    b'{"sender": "pd#0", "seq": 18446744073709551616}',
    '{"file": "out/demo-0001.mcap"}',
    b'{}',
    b'{"seq": 1, "seq": 2}',  # a repeated key: json keeps the last
]


@pytest.mark.parametrize("text", OBJECTS)
@pytest.mark.parametrize("name", ["seq", "sender", "file", "missing"])
def test_field_of_an_object_is_what_json_reads(text, name):
    assert json_field(text, name) == json.loads(text).get(name)


HOSTILE = [
    b"",
    b"{",
    b"[1, 2, 3]",
    b'"seq"',
    b"3",
    b"null",
    b"\xff\xfe{}",
    b'{"seq": 1',
    b"[" * 100_000,
    "{" * 50_000,
    b'{"a": ' * 30_000 + b"1" + b"}" * 30_000,
]


@pytest.mark.parametrize("text", HOSTILE, ids=range(len(HOSTILE)))
def test_anything_else_is_none(text):
    assert json_field(text, "seq") is None
    assert json_field(text, "a") is None
