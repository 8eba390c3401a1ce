"""What a control client learns when its verb finds no answer (walk F5), and when serve says
a fault was requested (closedloop F13).

Walk F5: ``bus.send_control`` returned ``[]`` alike for a dead hub, a wrong scenario name and
a verb the process does not have (``seek`` to ``serve``): the verb found no queryable, so
nothing answered.  Now serve and replay answer any other verb of their scenario with an
error naming the verbs they have, and ``require_reply=True`` turns ``[]`` into an error.

Closedloop F13: serve stamped its ``fault_requested`` event with the sim time of the last
heartbeat it had heard (sent every 0.5 s: up to 5 s of sim time old at ``--rate 10``), so
the recording showed seconds between a request and the plant's ``fault`` event that began
at its next step.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader

from astrodyn import bus
from astrodyn.service.children import stop_process

ROOT = Path(__file__).resolve().parents[1]
RATE = 10.0  # serve's --rate: 1 wall second is 10 s of sim time
STEP_S = 0.1  # detumble.toml's output step (10 Hz) and control period
TRAVEL_S = 0.1  # wall seconds allowed for a fault request to go from serve to the plant, on a loaded machine


def test_nothing_answering_is_an_empty_list_or_with_require_reply_an_error_naming_the_scenario():
    dead = bus.loopback_endpoint()  # a free port: nothing listens there
    with bus.open_session(connect=[dead]) as s:
        assert bus.send_control(s, "nobody", "status", timeout_s=0.3) == []
        with pytest.raises(bus.BusError, match=r"control verb 'status': no process of scenario 'nobody' answered"):
            bus.send_control(s, "nobody", "status", timeout_s=0.3, require_reply=True)


def _serve_verbs(server: bus.ControlServer, stop: threading.Event) -> None:
    while not stop.is_set():
        for request in server.poll():
            request.reply({"verb": request.verb})
        time.sleep(0.01)


REPLAY_VERBS = (*bus.CONTROL_VERBS, "seek")


def test_a_scenario_server_answers_a_verb_it_lacks_with_the_verbs_it_has_and_a_helper_stays_silent(hub):
    """A server of every control verb (serve, replay) answers an unknown one; a process
    that serves a verb or two beside it (the logger's ``stop``) does not add a second reply."""
    session, endpoint = hub
    with bus.ControlServer(session, "cv", REPLAY_VERBS) as front, bus.ControlServer(session, "cv", ("stop",)) as helper, \
            bus.open_session(connect=[endpoint]) as client:
        stop = threading.Event()
        threads = [threading.Thread(target=_serve_verbs, args=(srv, stop), daemon=True) for srv in (front, helper)]
        for thread in threads:
            thread.start()
        try:
            deadline = time.monotonic() + 10
            while not bus.send_control(client, "cv", "status", timeout_s=1) and time.monotonic() < deadline:
                pass  # until the queryables reach the client
            assert bus.send_control(client, "cv", "status", timeout_s=3) == [{"verb": "status"}]  # once, not twice
            assert bus.send_control(client, "cv", "seek", timeout_s=3) == [{"verb": "seek"}]
            (reply,) = bus.send_control(client, "cv", "fast-forward", timeout_s=3, require_reply=True)
            assert reply["error"].startswith("fast-forward: unknown control verb")
            assert re.findall(r"\w+", reply["error"].split("answers", 1)[1]) == list(REPLAY_VERBS)
            assert sorted(r.get("verb") for r in bus.send_control(client, "cv", "stop", timeout_s=3)) == ["stop", "stop"]
        finally:
            stop.set()
            for thread in threads:
                thread.join(timeout=5)


@pytest.fixture(scope="module")
def closed_loop_serve(tmp_path_factory):
    """A closed-loop ``serve`` (detumble, free mode, no controller) at ``--rate 10``: its
    start line, the token, its Popen and its recording's path."""
    tmp = tmp_path_factory.mktemp("serve")
    text = (ROOT / "configs" / "detumble.toml").read_text()
    text = text.replace('controllers = ["detumble"]', 'controllers = []\nmode = "free"')
    cfg = tmp / "detumble.toml"
    cfg.write_text(text)
    out = tmp / "served.mcap"
    serve = subprocess.Popen([sys.executable, "-m", "astrodyn", "serve", str(cfg), "--out", str(out), "--rate", str(RATE),
                              "--max-wall", "120"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        hello = json.loads(serve.stdout.readline())
        token = Path(hello["control_token_file"]).read_text().strip()
        yield serve, hello, token
    finally:
        stop_process(serve, timeout=60)


def test_serve_answers_a_verb_it_lacks_naming_its_verbs(closed_loop_serve):
    serve, hello, token = closed_loop_serve
    with bus.open_session(connect=[hello["hub"]]) as s:
        (reply,) = bus.send_control(s, "detumble", "seek", {"t": 5}, token=token, timeout_s=10)
    assert reply["error"] == "seek: unknown control verb; this process answers status, pause, resume, rate, stop, fault"


def test_serve_stamps_fault_requested_with_the_sim_time_of_the_request(closed_loop_serve):
    """Each ``fault_requested`` is before the plant's ``fault`` event, which begins it at the
    plant's next step (docs/control.md), by at most two steps and the request's travel from
    serve to the plant (:data:`TRAVEL_S` of wall time, measured: 0.05-0.19 s of sim time in
    all), and never after it by more than a step.  Four requests at wall times unrelated to
    the heartbeats' 0.5 s period: before, each lagged by its heartbeat's age (0 .. 5 s of sim
    time at x10), so all four within 1.2 s happened about once in 400 runs."""
    serve, hello, token = closed_loop_serve
    with bus.open_session(connect=[hello["hub"]]) as s:
        deadline = time.monotonic() + 90
        while time.monotonic() < deadline:  # the plant runs at pace
            replies = bus.send_control(s, "detumble", "status", token=token, timeout_s=10)
            if replies and (replies[0].get("processes", {}).get("plant", {}).get("t") or 0) > 5:
                break
            time.sleep(0.2)
        for k in range(4):
            time.sleep(0.37)  # not a multiple of the heartbeat period
            (ok,) = bus.send_control(s, "detumble", "fault", {"body": "sc", "fault": "gyro_bias", "value": [k * 1e-4, 0, 0]},
                                     token=token, timeout_s=10)
            assert "error" not in ok, ok
        time.sleep(0.5)
        (final,) = bus.send_control(s, "detumble", "stop", token=token, timeout_s=60)
    serve.communicate(timeout=60)
    requested, began = [], []  # (seq, t) of each event, in the order sent
    with open(final["file"], "rb") as f:
        for _, channel, message in make_reader(f).iter_messages():
            if channel.topic.endswith("/@event"):
                event = json.loads(message.data)
                if event["kind"] == "fault_requested" and event["process"] == "serve":
                    requested.append((event["seq"], event["t"]))
                elif event["kind"] == "fault" and event["process"] == "plant" and event["t"] < 300:  # not the config's
                    began.append((event["seq"], event["t"]))
    assert len(requested) == len(began) == 4, (requested, began)
    for (_, asked), (_, t) in zip(sorted(requested), sorted(began), strict=True):
        assert -STEP_S - 1e-9 <= t - asked <= 2 * STEP_S + TRAVEL_S * RATE, (requested, began)
