"""Hostile query payloads sent to a running `astrodyn serve` by a plain zenoh client.

Found by the churn probe: one query whose payload was JSON nested 100,000 deep (`"[" *
100000`) raised RecursionError in the parser, which the query handlers' `except ValueError`
let through.  On the logger's `@status` (open to anyone: no token) it killed the logger;
five of them within a minute made serve give up and fail, so any local process could end
a serve.  With the control token, the same payload on `rate` killed serve itself.  Every
payload from outside is now parsed by `astrodyn.messages.parse_json`, one error for every
way parsing can fail.  `rate` with `{"factor": 1e999}` (an overflow, read as inf) set the
rate to "inf"; control payloads now take finite numbers only.

A real serve, a real zenoh session; serve is stopped by its PID at the end.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _serve_control import serve_demo, stop_serve, wait_until
from astrodyn import auth, bus, messages
from astrodyn.service.children import stop_process

pytestmark = pytest.mark.network
ROOT = Path(__file__).resolve().parent.parent
DEEP = b"[" * 100_000


def _ask(session, key: str, payload: bytes, token: str | None = None) -> list[dict]:
    """The replies to one query with a raw ``payload`` (as any zenoh client can send it)."""
    replies = []
    for reply in session.get(key, payload=payload, timeout=5.0,
                             attachment=None if token is None else auth.token_attachment(token)):
        raw = reply.ok.payload.to_bytes() if reply.ok is not None else reply.err.payload.to_bytes()
        replies.append(json.loads(raw))
    return replies


def test_deep_json_queries_answer_with_an_error_and_kill_nothing(tmp_path):
    serve, hello = serve_demo(tmp_path / "q.mcap", "20")
    try:
        token = hello["control_token"]
        with bus.open_session(connect=[hello["hub"]]) as s:
            def status() -> dict:
                return bus.send_control(s, "demo", "status", token=token)[0]

            wait_until(lambda: status()["processes"]["logger"]["running"], 60, "serve's logger did not start")
            logger_pid = status()["processes"]["logger"]["pid"]
            for _ in range(6):  # past the restart budget (5 deaths in 60 s)
                replies = _ask(s, messages.status_key("demo"), DEEP)  # the logger's: no token needed
                assert replies and all("nested past the parser's depth" in r.get("error", "") for r in replies), replies
            replies = _ask(s, messages.control_key("demo", "rate"), DEEP, token)
            assert len(replies) == 1 and "nested past the parser's depth" in replies[0]["error"], replies
            replies = _ask(s, messages.control_key("demo", "rate"), b'{"factor": 1e999}', token)
            assert len(replies) == 1 and "expected finite numbers" in replies[0]["error"], replies
            now = status()
            assert now["state"] == "running" and now["real_time_factor"] == 20.0, now
            assert now["processes"]["logger"]["pid"] == logger_pid and now["restarts"] == [], now
        _, err, summary = stop_serve(serve, settle_s=0.0)
        assert serve.returncode == 0, err[-3000:]
        assert summary["failures"] == [] and summary["restarts"] == [], summary
    finally:
        stop_process(serve)


def test_parse_json_has_one_error_for_every_failure():
    for bad in (DEEP, b"\xff", b"{", "[" * 100_000 + "]" * 100_000):
        with pytest.raises(ValueError):
            messages.parse_json(bad)
    for not_finite in (b'{"f": 1e999}', b'{"f": -1e999}', b'[NaN]', b'[Infinity]'):
        with pytest.raises(ValueError, match="expected finite numbers"):
            messages.parse_json(not_finite, finite=True)
    assert messages.parse_json(b'{"f": 1e308}', finite=True) == {"f": 1e308}
