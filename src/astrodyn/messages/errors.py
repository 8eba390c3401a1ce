"""The one exception of :mod:`astrodyn.messages` (its text names the field), and how a bad value is shown in it."""

from __future__ import annotations

import json
from typing import Any


class MessageError(ValueError):
    """A key or payload that does not match its message type; ``str`` names the field."""


def show_value(value: Any) -> str:
    """Short JSON-ish rendering of a bad value for error messages."""
    try:
        text = json.dumps(value, allow_nan=True, default=repr)
    except Exception:  # pragma: no cover - default=repr handles anything
        text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."
