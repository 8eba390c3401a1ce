"""Config texts for tests: edit one and check the one-line error a hostile edit gives."""

from __future__ import annotations

import pytest

from astrodyn.scenario import ScenarioError, loads


def edited(text: str, **replace: str) -> str:
    """``text`` with each ``old`` replaced once by ``new`` (``old`` must be there)."""
    for old, new in replace.items():
        assert old in text, old
        text = text.replace(old, new, 1)
    return text


def assert_config_error(text: str, where: str, says: str) -> str:
    """Loading ``text`` fails with one line that names ``where`` and says ``says``."""
    with pytest.raises(ScenarioError) as info:
        loads(text, source="x.toml")
    message = str(info.value)
    assert where in message and says in message, message
    assert "\n" not in message
    return message
