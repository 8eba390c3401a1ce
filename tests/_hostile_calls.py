"""Hostile arguments to library calls: each call must be refused quickly, with an error
whose text names the offending argument (the tests' tables of ``(field, call)``)."""

from __future__ import annotations

import time

import pytest


def assert_refused_quickly(call, match: str, error: type[Exception] = ValueError, seconds: float = 2.0) -> None:
    """``call()`` raises ``error`` whose text matches the regex ``match`` (``re.search``),
    within ``seconds`` of wall time."""
    start = time.perf_counter()
    with pytest.raises(error, match=match):
        call()
    assert time.perf_counter() - start < seconds
