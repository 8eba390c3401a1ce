"""A controller's link to an astrodyn closed loop, in plain Python: zenoh, json, hmac.

No astrodyn import: this is the whole client side of docs/control.md, which the example
controllers in this directory share.  Use it as a starting point for your own::

    with Link() as link:               # from the environment `astrodyn run --controller` sets
        while (tick := link.wait_tick()) is not None:
            gyro = link.latest("sc", "gyro")               # the step's sample of a key, a dict
            link.command("sc", tick["t"], wheel_torque=[0.01, 0.0, 0.0])
            link.done(tick)            # answer the control step (lockstep)

Environment (set by ``astrodyn run/serve ... --controller CMD``):
``ASTRODYN_CONNECT`` the run's bus endpoint, ``ASTRODYN_SCENARIO``, ``ASTRODYN_CONTROLLER``
(this controller's name), and ``ASTRODYN_RUN_SECRET_FILE`` (the run secret: commands are
signed with it).  An outside controller started by hand passes ``connect``, ``scenario``
and ``name`` and the run's control token file instead (``ASTRODYN_CONTROL_TOKEN_FILE``).
"""

from __future__ import annotations

import hashlib
import hmac
import json
import os
import queue
import struct

import zenoh


class Link:
    def __init__(self, connect: str | None = None, scenario: str | None = None, name: str | None = None):
        env = os.environ
        self.scenario = scenario or env["ASTRODYN_SCENARIO"]
        self.name = name or env["ASTRODYN_CONTROLLER"]
        endpoint = connect or env["ASTRODYN_CONNECT"]
        self.base = f"astrodyn/{self.scenario}"
        self._secret = None
        self._token = None
        if env.get("ASTRODYN_RUN_SECRET_FILE"):
            with open(env["ASTRODYN_RUN_SECRET_FILE"], "rb") as fh:
                self._secret = fh.read()
        elif env.get("ASTRODYN_CONTROL_TOKEN_FILE"):
            with open(env["ASTRODYN_CONTROL_TOKEN_FILE"], "rb") as fh:
                self._token = fh.read().strip()
        self._instance = os.urandom(8)
        self._counters: dict[str, int] = {}
        self._seq: dict[str, int] = {}  # per body: this controller's command counter
        self._sent = 0  # commands sent since the last answer
        self._latest: dict[str, dict] = {}
        self._ticks: queue.Queue = queue.Queue()
        conf = zenoh.Config()
        conf.insert_json5("mode", '"peer"')  # a peer on loopback: the plant's samples come straight, not via the hub
        conf.insert_json5("listen/endpoints", '["tcp/127.0.0.1:0"]')
        conf.insert_json5("scouting/gossip/enabled", "true")
        conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
        conf.insert_json5("scouting/multicast/enabled", "false")
        self.session = zenoh.open(conf)
        self._subs = [
            self.session.declare_subscriber(f"{self.base}/**", self._on_sample),
            self.session.declare_subscriber(f"{self.base}/@tick", self._on_tick),
            self.session.declare_subscriber(f"{self.base}/@event", self._on_event),
        ]

    # -- receiving ------------------------------------------------------------------
    def _on_sample(self, sample) -> None:  # free mode: the newest sample of each key
        message = json.loads(sample.payload.to_bytes())
        key = str(sample.key_expr)
        if key not in self._latest or message.get("t", 0) >= self._latest[key].get("t", 0):
            self._latest[key] = message

    def _on_tick(self, sample) -> None:
        self._ticks.put(json.loads(sample.payload.to_bytes()))

    def _take(self, tick: dict | None) -> dict | None:
        # the tick carries the step's states and sensor samples: read them from it, since
        # samples on other keys may still be on their way (each subscriber has its thread)
        if tick is not None:
            for key, message in tick["samples"].items():
                self._latest[f"{self.base}/{key}"] = message
        return tick

    def _on_event(self, sample) -> None:
        event = json.loads(sample.payload.to_bytes())
        if event["process"] == "plant" and event["kind"] == "stop":
            self._ticks.put(None)  # the run is over

    def wait_tick(self, timeout: float | None = None) -> dict | None:
        """The next control step ``{"t", "seq", "step"}``, or None when the run has ended."""
        return self._take(self._ticks.get(timeout=timeout))

    def latest(self, body: str, kind: str) -> dict | None:
        """The newest message on ``astrodyn/<scenario>/<body>/<kind>`` (e.g. "attitude",
        "orbit", "gyro", "star_tracker", "gps", "tachometer", "actuators")."""
        return self._latest.get(f"{self.base}/{body}/{kind}")

    # -- sending --------------------------------------------------------------------
    def _attachment(self, key: str, payload: bytes) -> bytes:
        if self._secret is None:
            return b"ADT1" + self._token  # the run's control token (outside controller)
        n = self._counters.get(key, 0) + 1
        self._counters[key] = n
        name = self.name.encode()
        header = b"ADA1" + bytes([len(name)]) + name + self._instance + struct.pack("<Q", n)
        mac = hmac.new(self._secret, header + key.encode() + b"\0" + payload, hashlib.sha256).digest()
        return header + mac

    def _put(self, key: str, message: dict) -> None:
        payload = json.dumps(message, separators=(",", ":")).encode()
        self.session.put(key, payload, attachment=self._attachment(key, payload),
                         congestion_control=zenoh.CongestionControl.BLOCK)

    def command(self, body: str, t: float, **fields) -> None:
        """Command ``body`` from sim time ``t`` (s): any of torque=[3] N m (body axes),
        wheel_torque=[n] N m, dv=[3] m/s (inertial), thrust=[3] N with frame="inertial"|"body"."""
        seq = self._seq.get(body, 0)
        self._seq[body] = seq + 1
        self._put(f"{self.base}/{body}/command", {"t": t, "seq": seq, "sender": self.name, **fields})
        self._sent += 1

    def done(self, tick: dict) -> None:
        """Answer control step ``tick``: every command for it has been sent."""
        self._put(f"{self.base}/@done/{self.name}",
                  {"t": tick["t"], "seq": tick["seq"], "sender": self.name, "commands": self._sent})
        self._sent = 0

    def close(self) -> None:
        for s in self._subs:
            s.undeclare()
        self.session.close()

    # A process whose Zenoh session is still open when it exits waits for ever on Zenoh's
    # threads: use the link in a `with` block, so an exception or sys.exit closes it.
    def __enter__(self) -> Link:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
