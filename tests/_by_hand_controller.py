"""What the closed-loop tests with a plain-zenoh controller share: the detumble body and the
first part of a controller written from docs/control.md alone (json, hmac, zenoh).

``DETUMBLE_BODY``: TOML of body ``sc`` (a torque actuator, a rate gyro), appended to a
scene's ``[scenario]`` and ``[control]`` tables; :func:`detumble_scene`: a whole scene of it.

``CONTROLLER_PRELUDE``: Python source a test's controller starts with.  It defines
``scenario``, ``name`` (the controller's name, ``ASTRODYN_CONTROLLER``), ``base``, the
zenoh config ``conf``; ``put(s, key, msg=None, raw=None, signer=name, sign=True)``, which
signs with the run secret as docs/control.md says (``ADA1``, a per-key counter, HMAC-SHA256)
unless ``sign`` is false; a queue ``ticks`` fed by ``on_tick`` (each tick once, in seq
order) and closed with None by ``on_event`` at the plant's ``end`` or ``stop`` event;
``subscribed_session()``, a zenoh session of ``conf`` with ``on_tick`` and ``on_event``
subscribed to the run's ticks and events; and ``command_key``, the key of body ``sc``'s
commands."""

DETUMBLE_BODY = """
[[bodies]]
name = "sc"
[bodies.attitude]
w = ["3 deg/s", "-2 deg/s", "2.5 deg/s"]
inertia = ["100 kg m2", "120 kg m2", "80 kg m2"]
[bodies.actuators]
torque = "{torque}"
[bodies.sensors]
gyro = {{ sigma = "1e-5 rad/s" }}
"""


def detumble_scene(duration: str, *, rate: str = "10 Hz", period: str | None = "0.1 s",
                   controllers: str = '["detumble"]', timeout: str | None = None, seed: int | None = 42,
                   faults: str = "", torque: str = "0.05 N m", name: str = "detumble") -> str:
    """TOML of a closed-loop scene of :data:`DETUMBLE_BODY`: scenario ``name`` from
    2026-03-20T12:00:00 UTC for ``duration`` at the output ``rate``; its ``[control]`` table
    with the loop ``period``, the ``controllers`` (TOML array text), the ``timeout`` and the
    noise ``seed`` (each left out when None), then ``faults`` (TOML ``[[control.faults]]``
    tables); then body ``sc`` with its torque actuator's ``torque`` (quantity texts)."""
    from _recordings import scenario_head

    keys = {"period": None if period is None else f'"{period}"', "controllers": controllers,
            "timeout": None if timeout is None else f'"{timeout}"', "seed": seed}
    control = "".join(f"{key} = {value}\n" for key, value in keys.items() if value is not None)
    return (scenario_head(name, duration, rate) + "\n[control]\n" + control + faults + "\n"
            + DETUMBLE_BODY.format(torque=torque))


CONTROLLER_PRELUDE = r'''
import hashlib, hmac, json, os, queue, struct, sys, time
import zenoh

scenario = os.environ["ASTRODYN_SCENARIO"]; name = os.environ["ASTRODYN_CONTROLLER"]
secret = open(os.environ["ASTRODYN_RUN_SECRET_FILE"], "rb").read()
instance, counters = os.urandom(8), {}
base = f"astrodyn/{scenario}"

def put(s, key, msg=None, raw=None, signer=name, sign=True):
    payload = raw if raw is not None else json.dumps(msg, separators=(",", ":")).encode()
    att = None
    if sign:
        counters[signer, key] = counters.get((signer, key), 0) + 1
        h = b"ADA1" + bytes([len(signer)]) + signer.encode() + instance + struct.pack("<Q", counters[signer, key])
        att = h + hmac.new(secret, h + key.encode() + b"\0" + payload, hashlib.sha256).digest()
    s.put(key, payload, attachment=att, congestion_control=zenoh.CongestionControl.BLOCK)

ticks, last = queue.Queue(), [-1]
def on_tick(sample):
    tk = json.loads(sample.payload.to_bytes())
    if tk["seq"] > last[0]:
        last[0] = tk["seq"]; ticks.put(tk)
def on_event(sample):
    ev = json.loads(sample.payload.to_bytes())
    if ev.get("process") == "plant" and ev.get("kind") in ("end", "stop"):
        ticks.put(None)

conf = zenoh.Config()
conf.insert_json5("mode", '"peer"')
conf.insert_json5("connect/endpoints", json.dumps([os.environ["ASTRODYN_CONNECT"]]))
conf.insert_json5("scouting/multicast/enabled", "false")
command_key = f"{base}/sc/command"

def subscribed_session():
    s = zenoh.open(conf)
    s.declare_subscriber(f"{base}/@tick", on_tick)
    s.declare_subscriber(f"{base}/@event", on_event)
    return s
'''
