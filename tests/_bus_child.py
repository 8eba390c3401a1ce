"""Child processes for tests/test_bus.py and tests/test_recording.py (started with subprocess).

    python tests/_bus_child.py alive     CONNECT SCENARIO PROCESS        token, then sleep until killed
    python tests/_bus_child.py rogue     CONNECT SCENARIO N              valid + bad traffic, then end event
    python tests/_bus_child.py ordered   CONNECT SCENARIO N              N orbit messages of body "a", BLOCK
    python tests/_bus_child.py flood     CONNECT SCENARIO STEPS          1000 bodies x 2 kinds per step, batched
    python tests/_bus_child.py mcapkill  PATH N                          write N messages, flush, print, sleep

Every session is closed (context managers); the process never forks.
"""

from __future__ import annotations

import sys
import time

import numpy as np

from astrodyn import bus, messages
from astrodyn.recording.writer import McapRecorder

EPOCH_NS = 1_774_008_000_000_000_000  # 2026-03-20T12:00:00 UTC


def orbit(seq: int, t: float | None = None) -> dict:
    t = 0.5 * seq if t is None else t
    return messages.orbit_message(t, seq, "kepler", [7.0e6 + seq, 1.0, 2.0], [0.0, 7.5e3, 1.0], 3.986004418e14)


def attitude(seq: int) -> dict:
    c, s = np.cos(0.01 * seq), np.sin(0.01 * seq)
    return messages.attitude_message(0.5 * seq, seq, "torque_free", [c, 0.0, 0.0, s], [0.0, 0.0, 0.02])


def cmd_alive(connect: str, scenario: str, process: str) -> None:
    with bus.open_session(connect=connect) as session, bus.declare_alive(session, scenario, process):
        print("ready", flush=True)
        time.sleep(60)


def cmd_ordered(connect: str, scenario: str, n: int) -> None:
    with bus.open_session(connect=connect) as session:
        bus.wait_for_process(session, scenario, "listener", timeout_s=10)
        with bus.Publisher(session, messages.orbit_key(scenario, "a")) as pub:
            for i in range(n):
                pub.publish(orbit(i))
        time.sleep(0.2)


def cmd_rogue(connect: str, scenario: str, n: int) -> None:
    """Valid orbit/attitude channels for bodies a and b (n each; b sent in batches), plus
    malformed, duplicate and out-of-order traffic; ends with the end-of-run event."""
    with bus.open_session(connect=connect) as session:
        bus.wait_for_process(session, scenario, "logger", timeout_s=10)
        ka, kb = messages.orbit_key(scenario, "a"), messages.orbit_key(scenario, "b")
        kq = messages.attitude_key(scenario, "a")
        raw = bus.declare_state_publisher
        pa, pb, pq = raw(session, ka), raw(session, kb), raw(session, kq)
        batch = bus.BatchPublisher(session, scenario, "rogue")
        events = bus.EventPublisher(session, scenario, "rogue")
        events.emit("start", 0.0)
        valid = 0
        # body a: seq 0..n-1 but 5 and 6 swapped (out of order), 3 sent twice (duplicate)
        order = list(range(n))
        order[5], order[6] = order[6], order[5]
        for seq in order:
            pa.put(messages.encode(orbit(seq)))
            valid += 1
            if seq == 3:
                pa.put(messages.encode(orbit(3, t=99.0)))  # duplicate seq, different content
        # attitude of a, plain
        for seq in range(n):
            pq.put(messages.encode(attitude(seq)))
            valid += 1
        # body b: in batch envelopes of 4
        items = []
        for seq in range(n):
            items.append((kb, messages.encode(orbit(seq))))
            valid += 1
            if len(items) == 4:
                batch.publish(items)
                items = []
        if items:
            batch.publish(items)
        # malformed traffic: 6 samples
        pb.put(b"\xff\xfe not json")                                     # garbage bytes
        pb.put(b'{"t": 1.0, "seq": 1}')                                  # wrong schema
        pb.put(b'{"t":NaN,"seq":0,"model":"kepler","r":[1,2,3],"v":[1,2,3],"mu":1.0,"frame":"GCRF"}')
        pq.put(messages.encode(orbit(0)))                                # orbit on an attitude key
        batch._entity.put(b"ADB1\x05\x00\x00\x00truncated")              # broken batch envelope
        session.put(f"astrodyn/{scenario}/a/velocity", b"{}")           # unknown kind
        events.end(0.5 * n, valid)
        time.sleep(0.3)
        for p in (pa, pb, pq):
            p.undeclare()
        batch.close()
        events.close()


def cmd_flood(connect: str, scenario: str, steps: int) -> None:
    """1000 bodies x (orbit + attitude) per step in batch envelopes, as fast as possible."""
    nb = 1000
    rng = np.random.default_rng(1)
    r, v, w = rng.normal(size=(nb, 3)) * 7e6, rng.normal(size=(nb, 3)) * 7e3, rng.normal(size=(nb, 3))
    q = rng.normal(size=(nb, 4))
    q /= np.linalg.norm(q, axis=1)[:, None]
    okeys = [messages.orbit_key(scenario, f"s{i}") for i in range(nb)]
    akeys = [messages.attitude_key(scenario, f"s{i}") for i in range(nb)]
    with bus.open_session(connect=connect) as session:
        bus.wait_for_process(session, scenario, "logger", timeout_s=20)
        with bus.BatchPublisher(session, scenario, "orbit") as batch, bus.EventPublisher(session, scenario, "orbit") as ev:
            for k in range(steps):
                orbit = messages.encode_orbit_batch(0.1 * k, k, "kepler", r, v, 3.986004418e14)
                att = messages.encode_attitude_batch(0.1 * k, k, "torque_free", q, w)
                batch.publish(list(zip(okeys, orbit)) + list(zip(akeys, att)))
            ev.end(0.1 * steps, 2 * nb * steps)
            time.sleep(0.5)


def cmd_mcapkill(path: str, n: int) -> None:
    with McapRecorder(path, {"name": "kill"}, epoch_ns=EPOCH_NS, flush_interval_s=3600) as rec:
        for seq in range(n):
            rec.write(messages.orbit_key("kill", "a"), orbit(seq))
        rec.flush()
        print("flushed", flush=True)
        for seq in range(n, n + 50):  # in the open chunk: lost by the kill
            rec.write(messages.orbit_key("kill", "a"), orbit(seq))
        time.sleep(60)


if __name__ == "__main__":
    cmd, *rest = sys.argv[1:]
    if cmd == "alive":
        cmd_alive(rest[0], rest[1], rest[2])
    elif cmd == "ordered":
        cmd_ordered(rest[0], rest[1], int(rest[2]))
    elif cmd == "rogue":
        cmd_rogue(rest[0], rest[1], int(rest[2]))
    elif cmd == "flood":
        cmd_flood(rest[0], rest[1], int(rest[2]))
    elif cmd == "mcapkill":
        cmd_mcapkill(rest[0], int(rest[1]))
    else:
        raise SystemExit(f"unknown command {cmd!r}")
