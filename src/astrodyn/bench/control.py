"""Closed-loop lockstep: control steps per second and the round trip tick -> answer.

``astrodyn bench control [--bodies 1,100,1000] [--steps N]``: for each size, a scene of N
rigid bodies with a torque actuator and a rate gyro at a 10 Hz control rate, run by
``astrodyn run`` with one controller process (:mod:`astrodyn.bench.controller`) that
commands every body at every step (``u = -K w_gyro``).  Reported: lockstep control steps
per wall second (the plant's steps over its wall time), the round trip as the plant sees
it (tick published -> every answer and command in: bus both ways, the controller's work,
the plant's intake), p50 / p99, and the real-time factor.  Goals (issue 16): >= 5,000
steps/s for one body (round trip <= 200 us); 1000 bodies at 10 Hz faster than real time.

Two peers in the same run, with no astrodyn code: the bare zenoh-python round trip between
two processes (the floor of any step), and a lockstep *skeleton* (that round trip plus the
other puts of a one-body step, with a third process reading them, as the logger does): the
most steps per second that Python processes exchanging these messages reach on this machine.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

from astrodyn.bench import cpu_model, print_table
from astrodyn.bench.flags import int_in, int_list_in

__all__ = ["main", "scene", "DEFAULT_STEPS", "few_steps_note"]

DEFAULT_STEPS = 2000  #: --steps of the documented runs (docs/benchmarks.md)


def few_steps_note(steps: int) -> str | None:
    """The line that says figures of fewer than :data:`DEFAULT_STEPS` steps are not the
    documented ones (None for a full run): steps/s is the plant's steps over its whole wall
    time, start-up included, so 50 steps (``bench all --quick``) gave ~150 steps/s against
    the documented 1,200-1,500 and read as a tenfold regression."""
    if steps >= DEFAULT_STEPS:
        return None
    return (f"note: {steps} control steps per run, fewer than the {DEFAULT_STEPS} of the documented runs: start-up "
            f"weighs in, so steps/s and the round trip are not comparable with docs/benchmarks.md (a smoke run; "
            f"measure with --steps {DEFAULT_STEPS} or more)")


def scene(n_bodies: int, steps: int, rate_hz: float = 10.0, wheels: bool = False) -> str:
    """A closed-loop scene of ``n_bodies`` (TOML text) running ``steps`` control steps."""
    lines = ['[scenario]', 'name = "bench-control"', 'epoch = "2026-03-20T12:00:00 UTC"',
             f'duration = "{(steps - 1) / rate_hz!r} s"', f'rate = "{rate_hz!r} Hz"', '',
             '[control]', 'controllers = ["bench"]', 'timeout = "30 s"', '']
    for k in range(n_bodies):
        lines += ['[[bodies]]', f'name = "b{k:04d}"', '[bodies.attitude]',
                  'w = [0.01, -0.02, 0.015]', 'inertia = [100, 120, 80]', '[bodies.actuators]', 'torque = "0.05 N m"']
        if wheels:
            for axis in ("[1, 0, 0]", "[0, 1, 0]", "[0, 0, 1]"):
                lines += ['[[bodies.actuators.wheels]]', f'axis = {axis}', 'inertia = 0.05', 'max_torque = 0.2',
                          'max_speed = 600']
        lines += ['[bodies.sensors]', 'gyro = { sigma = 1e-6 }', '']
    return "\n".join(lines)


def one(n_bodies: int, steps: int, work: Path, wheels: bool) -> dict:
    from astrodyn.scenario import load
    from astrodyn.service.runner import run_scenario

    cfg = work / f"c{n_bodies}{'w' if wheels else ''}.toml"
    cfg.write_text(scene(n_bodies, steps, wheels=wheels))
    out = work / f"c{n_bodies}{'w' if wheels else ''}.mcap"
    result = run_scenario(load(cfg), out, progress=False, timeout_s=1800,
                          controllers=[f"{sys.executable} -m astrodyn.bench.controller"])
    plant = (result["processes"].get("plant") or {}).get("summary") or {}
    if not result.get("ok") or not plant:
        raise RuntimeError(f"bench control: the run of {n_bodies} bodies failed: {result.get('failure')}")
    rt = plant.get("round_trip_us", {})
    sim = plant["t"]
    return {"bodies": n_bodies, "wheels": wheels, "steps": plant["steps"], "wall_s": plant["wall_s"],
            "steps_per_s": plant["steps"] / plant["wall_s"], "p50_us": rt.get("p50"), "p99_us": rt.get("p99"),
            "rtf": sim / plant["wall_s"], "applied": plant["applied"]}


#: The start of the peer scripts below: a zenoh-python peer on the endpoint ``sys.argv[1]``,
#: listening on it or connecting to it (``role``), no scouting.
_PEER = """
import json, sys, zenoh
conf = zenoh.Config()
conf.insert_json5("mode", '"peer"')
conf.insert_json5("{role}/endpoints", json.dumps([sys.argv[1]]))
conf.insert_json5("scouting/multicast/enabled", "false")
"""

_PONG = _PEER.format(role="listen") + """
with zenoh.open(conf) as s:
    pub = s.declare_publisher("bench/pong")
    sub = s.declare_subscriber("bench/ping", zenoh.handlers.FifoChannel(16))  # held: a dropped one is undeclared
    for sample in sub:
        pub.put(sample.payload.to_bytes())
"""

_LISTENER = _PEER.format(role="connect") + """
with zenoh.open(conf) as s:
    sub = s.declare_subscriber("bench/**", zenoh.handlers.FifoChannel(4096))
    for sample in sub:
        sample.payload.to_bytes()
"""

#: The puts a one-body step of this benchmark's scene makes besides its tick (states, sensor
#: samples, actuator states; counted in docs/benchmarks.md, "Lockstep, one body: where a
#: step's time goes").
SKELETON_SAMPLES = 4


def zenoh_floor(n: int = 2000, samples: int = 0, listener: bool = False) -> dict:
    """The bare round trip of zenoh-python on this machine: a 200-byte sample to another
    Python process (a peer on loopback) and back, no astrodyn code on either side; the
    floor under any lockstep step of a controller in Python.

    ``samples`` > 0 and ``listener``: the *skeleton* of a lockstep step instead: after each
    ping, ``samples`` more 200-byte puts on keys of their own, with a third Python process
    subscribed to all of them (a logger that only reads), as a plant with no work of its own
    would publish a one-body step.  Returns the round trip's p50 / p99 (us) and the steps
    per wall second."""
    import subprocess
    import time

    import zenoh

    from astrodyn import bus

    endpoint = bus.loopback_endpoint(bus.free_port())
    procs = [subprocess.Popen([sys.executable, "-c", _PONG, endpoint])]
    if listener:
        procs.append(subprocess.Popen([sys.executable, "-c", _LISTENER, endpoint]))
    try:
        with bus.open_session(connect=endpoint) as s:
            sub = s.declare_subscriber("bench/pong", zenoh.handlers.FifoChannel(16))
            pub = s.declare_publisher("bench/ping")
            others = [s.declare_publisher(f"bench/sample/{k}") for k in range(samples)]
            times = []
            deadline = time.monotonic() + 30
            while sub.try_recv() is None:  # until the route is up
                if time.monotonic() > deadline:
                    raise RuntimeError("bench control: the ping-pong peer did not answer within 30 s")
                pub.put(b"x")
                time.sleep(0.05)
            time.sleep(0.5 if listener else 0.0)  # the listener's routes too
            while sub.try_recv() is not None:
                pass
            body = b"x" * 200
            began = time.perf_counter()
            for _ in range(n):
                t0 = time.perf_counter()
                pub.put(body)
                for other in others:
                    other.put(body)
                sub.recv()
                times.append(time.perf_counter() - t0)
            wall = time.perf_counter() - began
    finally:
        for proc in procs:
            proc.terminate()
            proc.wait(timeout=10)
    times.sort()
    return {"p50_us": 1e6 * times[n // 2], "p99_us": 1e6 * times[int(0.99 * (n - 1))], "steps_per_s": n / wall}


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """The options of ``astrodyn bench control``, checked (argparse's usage error, exit 2)."""
    ap = argparse.ArgumentParser(prog="astrodyn bench control", description=__doc__.splitlines()[0])
    ap.add_argument("--bodies", type=int_list_in(1, 10_000, most=10), default="1,100,1000",
                    help="comma-separated scene sizes, each 1..10000, at most 10 (default 1,100,1000)")
    ap.add_argument("--steps", type=int_in(50, 1_000_000), default=DEFAULT_STEPS,
                    help="control steps per run, 50..1000000 (default 2000; fewer for big scenes: "
                         "at most 200000 / bodies, at least 50)")
    ap.add_argument("--wheels", action="store_true", help="three reaction wheels per body as well")
    return ap.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    sizes = args.bodies
    rows = []
    with tempfile.TemporaryDirectory(prefix="astrodyn-bench-control-") as work:
        for n in sizes:
            steps = max(50, min(args.steps, 200_000 // n))
            for wheels in ((False, True) if args.wheels else (False,)):
                r = one(n, steps, Path(work), wheels)
                rows.append(r)
                print(f"{n} bodies{' + wheels' if wheels else ''}: {r['steps_per_s']:.0f} steps/s, round trip p50 "
                      f"{r['p50_us']:.0f} us", file=sys.stderr, flush=True)
    floor = zenoh_floor()
    skeleton = zenoh_floor(4000, samples=SKELETON_SAMPLES, listener=True)
    print(f"# closed-loop lockstep on {cpu_model()}: one controller commanding every body each step, 10 Hz\n")
    print(f"floor: bare zenoh-python round trip between two processes (peers, loopback), same run: p50 "
          f"{floor['p50_us']:.0f} us, p99 {floor['p99_us']:.0f} us\n")
    print(f"skeleton: the same round trip plus {SKELETON_SAMPLES} more puts per step and a third process reading "
          f"them all (a one-body step with no work of its own, no astrodyn code), same run: "
          f"{skeleton['steps_per_s']:.0f} steps/s, p50 {skeleton['p50_us']:.0f} us, p99 {skeleton['p99_us']:.0f} us\n")
    print_table(["bodies", "wheels", "steps", "control steps/s", "round trip p50 (us)", "p99 (us)", "p50 / zenoh floor",
                 "real-time factor"],
                ([r["bodies"], "3" if r["wheels"] else "-", r["steps"], f"{r['steps_per_s']:.0f}", f"{r['p50_us']:.0f}",
                  f"{r['p99_us']:.0f}", f"{r['p50_us'] / floor['p50_us']:.1f}x", f"{r['rtf']:.1f}"] for r in rows),
                align="rlrrrrrr")
    if note := few_steps_note(args.steps):
        print(f"\n{note}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
