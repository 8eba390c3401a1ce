"""The benchmark's controller (``python -m astrodyn.bench.controller``): at every tick,
``u = -K w_gyro`` for every body of the tick, one command each, then the answer.  Signs
with the run secret through :mod:`astrodyn.auth` (the protocol of docs/control.md).

It parses with msgspec (the tick's samples left raw but the gyros'), as a controller in a
hurry would: the plain-json controller of docs/control.md works the same, slower."""

from __future__ import annotations

import gc
import json
import os

import msgspec
import zenoh

from astrodyn import auth, bus, messages

GAIN = 2.0


class _Tick(msgspec.Struct):
    t: float
    seq: int
    samples: dict[str, msgspec.Raw]


class _Gyro(msgspec.Struct):
    w: tuple[float, float, float]


_TICK = msgspec.json.Decoder(_Tick)
_GYRO = msgspec.json.Decoder(_Gyro)
_encode = msgspec.json.Encoder().encode


def answer(raw: bytes | _Tick, base: str, name: str, seqs: dict[str, int]) -> tuple[list[tuple[str, bytes]], bytes]:
    """The commands ``(key, payload)`` for the tick ``raw`` (its payload, or already
    decoded; one command per body with a gyro sample; ``seqs`` the per-body command
    counters, updated) and the answer's payload."""
    tick = raw if isinstance(raw, _Tick) else _TICK.decode(raw)
    commands = []
    for key, msg in tick.samples.items():
        body, _, kind = key.partition("/")
        if kind != "gyro":
            continue
        seq = seqs.get(body, 0)
        seqs[body] = seq + 1
        w = _GYRO.decode(msg).w
        cmd = {"t": tick.t, "seq": seq, "sender": name, "torque": [-GAIN * w[0], -GAIN * w[1], -GAIN * w[2]]}
        commands.append((f"{base}/{body}/command", _encode(cmd)))
    return commands, _encode({"t": tick.t, "seq": tick.seq, "sender": name, "commands": len(commands)})


def main() -> int:
    scenario, name = os.environ["ASTRODYN_SCENARIO"], os.environ["ASTRODYN_CONTROLLER"]
    signer = auth.Signer(auth.secret_from_environment(), name)
    base = f"astrodyn/{scenario}"

    # a loopback peer with gossip (astrodyn.bus defaults): straight to the plant, not via the hub
    with bus.open_session(connect=os.environ["ASTRODYN_CONNECT"]) as session:
        tick_key = f"{base}/@tick"

        def on_event(sample) -> None:  # the plant's stop wakes the loop: an empty tick, to this session only
            event = json.loads(sample.payload.to_bytes())
            if event["process"] == "plant" and event["kind"] == "stop":
                session.put(tick_key, b"", allowed_destination=zenoh.Locality.SESSION_LOCAL)

        ticks = session.declare_subscriber(tick_key, zenoh.handlers.FifoChannel(1024))  # read here, no thread hand-off
        events = session.declare_subscriber(f"{base}/@event", on_event)  # noqa: F841 (held for the session's life)
        done_key = f"{base}/@done/{name}"
        seqs: dict[str, int] = {}
        pubs: dict[str, zenoh.Publisher] = {}

        def put(key: str, payload: bytes) -> None:
            pub = pubs.get(key)
            if pub is None:
                pub = pubs[key] = session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)
            pub.put(payload, attachment=signer.attachment(key, payload))

        batch_key = f"{base}/@batch/{name}"
        gc.freeze()  # what is loaded now stays: out of the cyclic collector's scans
        last_tick = -1
        while raw := ticks.recv().payload.to_bytes():
            tick = _TICK.decode(raw)  # once: the seq check and the answer share it
            if tick.seq <= last_tick:  # the plant's repeat of a tick already answered (late joiners' copy)
                continue
            last_tick = tick.seq
            commands, done = answer(tick, base, name, seqs)
            if commands:  # one envelope: the commands and the answer (docs/control.md)
                put(batch_key, messages.encode_batch([*commands, (done_key, done)]))
            else:
                put(done_key, done)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
