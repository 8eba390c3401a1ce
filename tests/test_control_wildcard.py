"""A control query whose key expression is not exactly one verb's key does nothing (svc probe F4).

``serve`` prints its control key as ``astrodyn/<scenario>/@control/*``.  A ``session.get``
of exactly that expression, with the run's token, reached every per-verb queryable: serve
answered ``resume``, ``pause``, ``stop``, ``status`` and ``rate`` at once and ended.  The spec
(``bus.ControlServer``, docs/reliability.md): a verb acts only on a query of its own key;
any other expression gets one error naming the verbs and saying to query one verb's key,
and nothing is done.  ``replay`` uses the same server (its ``seek`` included).
"""

from __future__ import annotations

import re
import threading
import time

import pytest

from _serve_control import serve_demo
from astrodyn import bus

TOKEN = "t" * 43  # the token the test's server asks for: any string works for ControlServer
REPLAY_VERBS = (*bus.CONTROL_VERBS, "seek")

#: Key expressions of scenario "cw" that name no single verb, each intersecting every verb key
#: (so each verb's queryable receives the query): the advertised key, ``**`` forms, a
#: wildcard scenario, a sub-chunk wildcard.  (``astrodyn/cw/**`` reaches no verb: Zenoh's
#: wildcards never match a chunk that begins with ``@``.)
NOT_ONE_VERB = ["astrodyn/cw/@control/*", "astrodyn/cw/@control/**", "astrodyn/*/@control/*",
                "astrodyn/**/@control/*", "astrodyn/cw/@control/st$*"]


def _handle(server: bus.ControlServer, handled: list[str], stop: threading.Event) -> None:
    """A server's owner loop: every request that reaches ``poll()`` is an action, recorded."""
    while not stop.is_set():
        for request in server.poll():
            handled.append(request.verb)
            request.reply({"verb": request.verb})
        time.sleep(0.005)


def _get(session, key: str) -> list[dict]:
    return bus.query_json(session, key, timeout_s=3.0, token=TOKEN)


@pytest.mark.parametrize("verbs", [bus.CONTROL_VERBS, REPLAY_VERBS], ids=["serve", "replay"])
def test_a_query_that_names_no_single_verb_gets_one_error_naming_the_verbs_and_nothing_is_done(hub, verbs):
    session, endpoint = hub
    handled: list[str] = []
    helper_handled: list[str] = []
    with bus.ControlServer(session, "cw", verbs, token=TOKEN) as front, \
            bus.ControlServer(session, "cw", ("stop",), token=TOKEN) as helper, \
            bus.open_session(connect=[endpoint]) as client:
        stop = threading.Event()
        threads = [threading.Thread(target=_handle, args=(srv, out, stop), daemon=True)
                   for srv, out in ((front, handled), (helper, helper_handled))]
        for thread in threads:
            thread.start()
        try:
            deadline = time.monotonic() + 10
            while not _get(client, "astrodyn/cw/@control/status") and time.monotonic() < deadline:
                pass  # until the queryables reach the client
            handled.clear()
            for key in NOT_ONE_VERB:
                replies = _get(client, key)
                assert len(replies) == 1, (key, replies)  # one answer, not one per verb
                error = replies[0].get("error", "")
                assert "nothing was done" in error and "query one verb's key" in error, (key, error)
                assert re.findall(r"\w+", error.split("one of", 1)[1]) == list(verbs), (key, error)
            assert handled == [] and helper_handled == []  # no verb acted, the helper's stop included
            # each verb's own key still acts, once
            assert _get(client, "astrodyn/cw/@control/pause") == [{"verb": "pause"}]
            assert handled == ["pause"] and helper_handled == []
        finally:
            stop.set()
            for thread in threads:
                thread.join(timeout=5)


def test_serve_answers_its_advertised_control_key_with_an_error_and_keeps_running(tmp_path):
    """A real serve: ``@control/*`` (the key its first line gave as ``control`` before), queried with its token, gets one error
    naming its verbs; serve is still running, not paused, and stops on ``stop`` (exit 0)."""
    serve, hello = serve_demo(tmp_path / "demo.mcap", "10", max_wall_s=60)
    try:
        token = hello["control_token"]
        with bus.open_session(connect=[hello["hub"]]) as s:
            # the first line names the verbs and the key of each (a template, not a key expression to query)
            assert hello["control"] == "astrodyn/demo/@control/<verb>" and hello["verbs"] == list(bus.CONTROL_VERBS)
            replies = bus.query_json(s, "astrodyn/demo/@control/*", timeout_s=5.0, token=token)
            assert len(replies) == 1 and "nothing was done" in replies[0].get("error", ""), replies
            assert re.findall(r"\w+", replies[0]["error"].split("one of", 1)[1]) == list(bus.CONTROL_VERBS)
            time.sleep(0.5)  # a stop or pause, had one been done, has taken effect
            assert serve.poll() is None
            (status,) = bus.send_control(s, "demo", "status", token=token, timeout_s=5)
            assert status["state"] == "running" and not status["failures"], status
            (final,) = bus.send_control(s, "demo", "stop", token=token, timeout_s=60)
            assert final["state"] == "stopped", final
        _, err = serve.communicate(timeout=60)
        assert serve.returncode == 0, err[-2000:]
    finally:
        if serve.poll() is None:  # only the serve this test started, by its PID
            serve.kill()
            serve.communicate(timeout=30)
