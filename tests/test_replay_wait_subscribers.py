"""``astrodyn replay --wait S``: the wait ends when a subscriber matches any replayed key,
``status`` says "waiting" meanwhile, and ``seek`` refuses a time outside the replayed range.

Before (probe B, F1): the wait watched the first recorded topic only (``@event`` in an
astrodyn recording, which ``**`` does not match), so a client of a per-body state key got
its first sample only when the whole wait had run out, while ``status`` said "running".
Before (probe B, F8): ``seek`` to ``t = -5`` went to the start without a word.
"""

from __future__ import annotations

import json
import select
import subprocess
import sys
import time
from pathlib import Path

import pytest
import zenoh

from astrodyn import bus
from astrodyn.recording.stream import McapStream
from astrodyn.service.replay import Replayer

#: A recording made by the service (scenario "legacy", tests/fixtures/legacy-v0.toml: t = 0
#: .. 120 s at 1 Hz, bodies iss, cubesat, molniya): like every astrodyn recording its first
#: topic is ``@event``, the one key the old wait watched.
FIXTURE = Path(__file__).parent / "fixtures" / "legacy-v0.mcap"
DURATION_S = 120.0
#: How long a subscriber may wait for its first sample once it is declared.  The subscriber's
#: declaration reaches the replay over the already open loopback TCP link in milliseconds
#: (one Zenoh declaration message), the replay reads the matching statuses every 10 ms, and
#: the first message is due at once: 2 s is ~100x that, for a loaded 2-core machine, and 10x
#: below the 20 s ``--wait`` that the old code sat out.
FIRST_SAMPLE_BOUND_S = 2.0
WAIT_S = 20.0


def _first_line(proc: subprocess.Popen, timeout_s: float) -> dict:
    """The replay's first JSON line on stdout, read within ``timeout_s``."""
    ready, _, _ = select.select([proc.stdout], [], [], timeout_s)
    assert ready, f"no first line from replay within {timeout_s} s"
    return json.loads(proc.stdout.readline())


def _plain_client(endpoint: str) -> zenoh.Session:
    """A client session as docs/clients.md opens it (no astrodyn helpers)."""
    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(conf)


def _status(session, token: str) -> dict:
    replies = bus.send_control(session, "legacy", "status", timeout_s=5.0, token=token)
    assert len(replies) == 1, replies
    return replies[0]


@pytest.mark.network
def test_a_subscriber_to_a_body_state_key_ends_the_wait_at_once(processes):
    proc = processes([sys.executable, "-m", "astrodyn", "replay", FIXTURE, "--rate", "10", "--wait", str(WAIT_S),
                      "--quiet"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    hello = _first_line(proc, 15.0)
    with _plain_client(hello["listen"][0]) as session:
        status = _status(session, hello["control_token"])
        assert status["state"] == "waiting" and status["messages"] == 0, status
        assert 0 < status["waiting"]["left_s"] <= WAIT_S and "astrodyn/legacy/iss/orbit" in status["waiting"]["keys"]
        subscriber = session.declare_subscriber("astrodyn/legacy/iss/orbit", zenoh.handlers.FifoChannel(1024))
        declared = time.monotonic()
        first = None
        while first is None and time.monotonic() - declared < FIRST_SAMPLE_BOUND_S:
            first = subscriber.try_recv()
            time.sleep(0.005)
        assert first is not None, f"no sample within {FIRST_SAMPLE_BOUND_S} s of subscribing (--wait {WAIT_S:g})"
        state = json.loads(first.payload.to_bytes())
        assert state["t"] == 0.0 and state["seq"] == 0  # the recording's first state: nothing went out before
        status = _status(session, hello["control_token"])
        assert status["state"] in ("running", "finished") and status["waiting"] is None, status
        assert bus.send_control(session, "legacy", "stop", timeout_s=5.0, token=hello["control_token"])
    proc.wait(timeout=10)
    assert proc.returncode == 0, proc.stderr.read()


@pytest.mark.network
@pytest.mark.parametrize("subscribed, options, ends_wait", [
    ("astrodyn/legacy/*/orbit", {}, True),
    ("astrodyn/legacy/**", {}, True),
    ("astrodyn/legacy/@event", {}, True),
    ("astrodyn/legacy/@batch/*", {"batch": True}, True),  # --batch puts the states on the envelope keys
    ("astrodyn/legacy/iss/orbit", {"batch": True}, False),  # ... and not on the per-body keys
    ("astrodyn/legacy/iss/orbit", {"topics": ["astrodyn/legacy/molniya/*"]}, False),  # --topics: no iss
    ("astrodyn/other/**", {}, False),
])
def test_the_wait_ends_for_a_subscriber_of_any_replayed_key_only(subscribed, options, ends_wait):
    endpoint = bus.loopback_endpoint()
    with bus.open_session(listen=endpoint) as replay_session, McapStream(FIXTURE) as stream, \
            bus.open_session(connect=endpoint, mode="client") as client:
        rep = Replayer(replay_session, stream, **options)
        subscriber = client.declare_subscriber(subscribed)
        asked = time.monotonic()
        came = rep.wait_for_subscriber(FIRST_SAMPLE_BOUND_S if ends_wait else 0.5)
        assert came is ends_wait and rep.status()["state"] == "running"
        if ends_wait:
            assert time.monotonic() - asked < FIRST_SAMPLE_BOUND_S
        subscriber.undeclare()
        rep.close()


def test_seek_outside_the_replayed_range_is_refused_with_the_range():
    with McapStream(FIXTURE) as stream:
        rep = Replayer(None, stream)  # seek publishes nothing: no bus needed
        for t in (-5, -1e-6, DURATION_S + 0.5):
            with pytest.raises(ValueError) as err:
                rep.seek(t)
            assert f"got {t!r}" in str(err.value) and "seek" in str(err.value)
            assert f"0.0 <= t <= {DURATION_S}" in str(err.value), err.value
        for t in (0, 0.0, 20.5, DURATION_S):  # the ends are inside
            rep.seek(t)
            assert rep.status()["t"] == t
        narrowed = Replayer(None, stream, start_t=10.0, end_t=30.0)  # --start / --end narrow the range
        with pytest.raises(ValueError, match=r"10\.0 <= t <= 30\.0 s .*got 5"):
            narrowed.seek(5)
        with pytest.raises(ValueError, match=r"10\.0 <= t <= 30\.0 s .*got 31"):
            narrowed.seek(31)
