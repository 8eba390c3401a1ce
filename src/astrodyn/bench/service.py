"""``astrodyn bench service``: the whole service, propagators -> Zenoh -> logger -> MCAP.

What is measured (docs/architecture.md, "Performance targets"), each scene run headless through
the machinery of ``astrodyn run`` (:func:`astrodyn.service.runner.run_scenario`: real OS
processes, loopback Zenoh, the end-of-run protocol):

* ``constellation-1000`` (``configs/constellation-1000.toml``: 1000 Walker satellites,
  Kepler orbit + exact torque-free attitude, 10 Hz, i.e. 20 000 state messages per
  simulated second) and a smaller scene of the same shape (100 satellites), as fast as the
  machine allows.  Target: >= 5x real time (100 000 messages/s) with no lost or
  reordered message.
* The load case of issue 6: the propagators paced at 10x the nominal rate of
  ``constellation-1000`` (``--real-time-factor 10``: 200 000 messages/s offered), so the
  publishers outrun the logger.  Zenoh's reliable delivery with blocking congestion
  control must slow the publishers down instead of dropping: the row reports the rate
  actually sustained, any gap (must be none) and the logger's peak memory (bounded).

Per scene: wall time of the run (process start-up included), real-time factor = simulated
seconds / wall seconds, messages per wall second, and per process (logger, orbit,
attitude) CPU seconds and peak resident memory (VmHWM), sampled from ``/proc`` every
50 ms while the process lives (CPU of the last < 50 ms of a process can be missed; the
exact sum over all children from ``getrusage(RUSAGE_CHILDREN)`` is printed beside).

Loss and order are checked independently of the logger's own accounting: the MCAP is
read back with the plain ``mcap`` streaming reader (CRCs validated) and every channel
must hold exactly ``n_steps`` messages whose ``sequence`` is 0, 1, 2, ... in file order,
with ``log_time`` increasing; one payload in 997 is also JSON-decoded and its ``seq``
compared with the record's ``sequence``.

Results go to stdout as a table and, with ``--md``, to a Markdown file (machine, date,
load average before and after: the machine is shared, so the numbers are a snapshot).
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import math
import os
import platform
import re
import resource
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

from astrodyn.bench import walker_planes
from astrodyn.bench.flags import float_in, int_in, int_list_in, output_dir, output_file

__all__ = ["Scene", "main", "run_scene", "check_recording", "ProcSampler"]

_CLK_TCK = os.sysconf("SC_CLK_TCK")
_PROCESSES = ("logger", "orbit", "attitude")


@dataclass
class Scene:
    """One benchmark row: a Walker constellation of ``bodies`` satellites."""

    name: str
    bodies: int
    planes: int
    duration_s: float
    real_time_factor: float = math.inf  # inf: as fast as possible; finite: paced (load test)
    rate_hz: float = 10.0
    authenticate: bool = True  # False: no run secret (what authentication costs, same run)

    @property
    def n_steps(self) -> int:
        return int(round(self.duration_s * self.rate_hz)) + 1

    @property
    def expected_messages(self) -> int:
        return 2 * self.bodies * self.n_steps


def scene_config(scene: Scene, template: str) -> str:
    """The TOML of ``scene``: ``configs/constellation-1000.toml`` with its name, size and
    duration replaced (everything else -- orbit, attitude, rate -- as shipped; the phasing
    ``f`` 0 in a single plane, where the Walker pattern has no other)."""
    out = template
    for key, value in (("name", f'"{scene.name}"'), ("duration", f'"{scene.duration_s:g} s"'),
                       ("rate", f'"{scene.rate_hz:g} Hz"'), ("t", str(scene.bodies)), ("p", str(scene.planes)),
                       *((("f", "0"),) if scene.planes == 1 else ())):
        out, n = re.subn(rf"(?m)^{key} = .*$", f"{key} = {value}", out, count=1)
        if n != 1:
            raise ValueError(f"constellation template: expected one '{key} = ...' line")
    return out


# --------------------------------------------------------------------------- /proc sampling


def _proc_cpu_s(pid: int) -> float | None:
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            fields = f.read().rsplit(b")", 1)[1].split()
    except (OSError, IndexError):
        return None
    return (int(fields[11]) + int(fields[12])) / _CLK_TCK  # utime, stime (fields 14, 15)


def _proc_hwm_mb(pid: int) -> float | None:
    try:
        with open(f"/proc/{pid}/status", "rb") as f:
            for line in f:
                if line.startswith(b"VmHWM:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        return None
    return None


def _children_by_name(parent: int) -> dict[str, int]:
    """pid of each logger / propagator child of ``parent`` (by its ``python -m`` command line in /proc)."""
    from astrodyn.service.children import children_of

    found = {}
    for pid, argv in children_of(parent).items():
        words = argv[1:4]
        if words[:2] == ["-m", "astrodyn.service.logger"]:
            name = "logger"
        elif words[:2] == ["-m", "astrodyn.service.propagator"] and len(words) > 2:
            name = words[2]
        else:
            continue
        if name in _PROCESSES:
            found[name] = pid
    return found


@dataclass
class ProcSampler:
    """Samples CPU time and VmHWM of this process's service children every ``period_s``."""

    period_s: float = 0.05
    cpu_s: dict[str, float] = field(default_factory=dict)
    hwm_mb: dict[str, float] = field(default_factory=dict)
    pids: dict[str, int] = field(default_factory=dict)

    def __post_init__(self):
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, daemon=True)

    def _loop(self) -> None:
        me = os.getpid()
        while not self._stop.is_set():
            for name, pid in _children_by_name(me).items():
                self.pids[name] = pid
            for name, pid in list(self.pids.items()):
                cpu = _proc_cpu_s(pid)
                if cpu is not None:
                    self.cpu_s[name] = max(cpu, self.cpu_s.get(name, 0.0))
                hwm = _proc_hwm_mb(pid)
                if hwm is not None:
                    self.hwm_mb[name] = max(hwm, self.hwm_mb.get(name, 0.0))
            self._stop.wait(self.period_s)

    def __enter__(self) -> ProcSampler:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()


# --------------------------------------------------------------------------- read-back check


def check_recording(path: str | os.PathLike, n_channels: int, n_steps: int) -> dict:
    """Read the MCAP back with mcap's streaming reader; count loss and disorder per channel.

    Returns ``{"messages", "channels", "lost", "reordered", "extra", "seq_mismatch"}``:
    ``lost`` = expected messages (``n_channels * n_steps``) not found, ``reordered`` =
    messages whose ``sequence`` is not the previous one + 1 in file order or whose
    ``log_time`` does not increase, ``extra`` = messages beyond ``n_steps`` on a channel,
    ``channels`` = state channels found (must equal ``n_channels``), ``seq_mismatch`` = sampled payloads whose JSON
    ``seq`` differs from the record's ``sequence``.
    """
    from mcap.reader import make_reader

    counts: dict[int, int] = {}
    last_seq: dict[int, int] = {}
    last_time: dict[int, int] = {}
    topics: dict[int, str] = {}
    reordered = seq_mismatch = n = 0
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        for _schema, channel, message in reader.iter_messages(log_time_order=False):
            cid = channel.id
            if cid not in topics:
                topics[cid] = channel.topic
            if (message.sequence != last_seq.get(cid, -1) + 1 or message.log_time <= last_time.get(cid, -1)) \
                    and channel.topic.endswith(("/orbit", "/attitude")):  # @event: one seq per process
                reordered += 1
            last_seq[cid] = message.sequence
            last_time[cid] = message.log_time
            counts[cid] = counts.get(cid, 0) + 1
            if n % 997 == 0 and json.loads(message.data)["seq"] != message.sequence:
                seq_mismatch += 1
            n += 1
    state = {cid: c for cid, c in counts.items() if topics[cid].endswith(("/orbit", "/attitude"))}
    found = sum(min(c, n_steps) for c in state.values())
    extra = sum(max(0, c - n_steps) for c in state.values())
    return {"messages": sum(state.values()), "channels": len(state), "lost": n_channels * n_steps - found,
            "reordered": reordered, "extra": extra, "seq_mismatch": seq_mismatch}


# --------------------------------------------------------------------------- one scene


def run_scene(scene: Scene, workdir: Path, template: str, keep: bool = False) -> dict:
    """Run ``scene`` through :func:`astrodyn.service.runner.run_scenario`; measure and check it."""
    from astrodyn.scenario import load
    from astrodyn.service.runner import run_scenario

    config = workdir / f"{scene.name}.toml"
    config.write_text(scene_config(scene, template))
    out = workdir / f"{scene.name}.mcap"
    scenario = load(config)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.monotonic()
    with ProcSampler() as sampler:
        result = run_scenario(scenario, out, real_time_factor=scene.real_time_factor, progress=False,
                              authenticate=scene.authenticate)
    wall = time.monotonic() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    row: dict = {
        "scene": scene.name, "bodies": scene.bodies, "sim_s": scene.duration_s,
        "paced_rtf": scene.real_time_factor, "expected": scene.expected_messages,
        "wall_s": wall, "rtf": scene.duration_s / wall, "ok": bool(result.get("ok")),
        "failure": result.get("failure"),
        "cpu_s": {k: round(v, 2) for k, v in sampler.cpu_s.items()},
        "peak_rss_mb": {k: round(v, 1) for k, v in sampler.hwm_mb.items()},
        "children_cpu_s": round((after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime), 2),
    }
    procs = result.get("processes", {})
    prop_walls = [((procs.get(k) or {}).get("summary") or {}).get("wall_s") for k in ("orbit", "attitude")]
    prop_walls = [w for w in prop_walls if w]
    row["propagate_wall_s"] = max(prop_walls) if prop_walls else None
    log = result.get("logger") or {}
    row["logger_missing"] = log.get("missing")
    row["logger_malformed"] = log.get("malformed")
    if out.exists():
        row["check"] = check_recording(out, 2 * scene.bodies, scene.n_steps)
        row["msg_per_s"] = row["check"]["messages"] / wall
        row["file_mb"] = round(out.stat().st_size / 2**20, 1)
        if not keep:
            out.unlink()
    else:
        row["check"] = None
        row["msg_per_s"] = 0.0
    c = row["check"] or {}
    row["lost"] = c.get("lost", scene.expected_messages)
    row["reordered"] = c.get("reordered", 0)
    row["zero_loss"] = bool(c) and c["channels"] == 2 * scene.bodies and c["lost"] == 0 and c["reordered"] == 0 and c["extra"] == 0 and c["seq_mismatch"] == 0
    return row


# --------------------------------------------------------------------------- flood (issue 6)


def flood_publisher(connect: str, scenario: str, steps: int, bodies: int) -> None:
    """Child process of :func:`run_flood`: pre-encode ``steps`` instants of orbit + attitude
    envelopes for ``bodies`` bodies (as the propagators frame them), then put them all as
    fast as Zenoh takes them; prints ``{"first_put_unix": ..., "publish_s": ...}``."""
    import numpy as np

    from astrodyn import bus, messages

    rng = np.random.default_rng(1)
    okeys = [messages.orbit_key(scenario, f"s{i}") for i in range(bodies)]
    akeys = [messages.attitude_key(scenario, f"s{i}") for i in range(bodies)]
    envelopes = []
    for k in range(steps):
        r, v = rng.normal(size=(bodies, 3)) * 7e6, rng.normal(size=(bodies, 3)) * 7.5e3
        q = rng.normal(size=(bodies, 4))
        q /= np.linalg.norm(q, axis=1)[:, None]
        w = rng.normal(size=(bodies, 3)) * 1e-3
        envelopes.append(messages.encode_batch(zip(okeys, messages.encode_orbit_batch(k / 10, k, "kepler", r, v, 3.986004418e14))))
        envelopes.append(messages.encode_batch(zip(akeys, messages.encode_attitude_batch(k / 10, k, "torque_free", q, w))))
    with bus.open_session(connect=[connect]) as session:
        bus.wait_for_process(session, scenario, "logger", timeout_s=30)
        with bus.EventPublisher(session, scenario, "flood") as events:
            publisher = session.declare_publisher(
                messages.batch_key(scenario, "flood"), congestion_control=zenoh_block(), reliability=zenoh_reliable())
            first = time.time()
            t0 = time.monotonic()
            for env in envelopes:
                publisher.put(env)
            publish_s = time.monotonic() - t0
            events.end(steps / 10, 2 * bodies * steps)
            # put() returns once a sample is queued on our side; closing the session drops
            # what is still queued, so stay until the logger has everything (it exits).
            deadline = time.monotonic() + 300
            while "logger" in bus.alive_processes(session, scenario) and time.monotonic() < deadline:
                time.sleep(0.05)
            publisher.undeclare()
    print(json.dumps({"first_put_unix": first, "publish_s": publish_s}), flush=True)


def zenoh_block():
    import zenoh

    return zenoh.CongestionControl.BLOCK


def zenoh_reliable():
    import zenoh

    return zenoh.Reliability.RELIABLE


def run_flood(steps: int, bodies: int, queue: int, workdir: Path) -> dict:
    """Issue 6 load case: one publisher putting pre-encoded envelopes as fast as Zenoh takes
    them (far above 10x the nominal rate) into ``services/logger.py --queue queue``."""
    import subprocess

    from astrodyn import bus
    from astrodyn.service.children import logger_command

    name = f"flood-q{queue}"
    out = workdir / f"{name}.mcap"
    port = bus.free_port()
    hub = bus.loopback_endpoint(port)
    py = sys.executable
    row: dict = {"scene": name, "bodies": bodies, "sim_s": steps / 10, "paced_rtf": math.inf,
                 "expected": 2 * bodies * steps, "queue": queue}
    t0 = time.monotonic()
    with bus.open_session(listen=[hub]), ProcSampler() as sampler:
        logger = subprocess.Popen([*logger_command(), "--scenario", name, "--out", str(out),
                                   "--epoch-ns", "1774008000000000000", "--expect", "flood", "--queue", str(queue),
                                   "--connect", hub], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        pub = subprocess.Popen([py, "-m", "astrodyn.bench.service", "--flood-publisher", hub, name, str(steps), str(bodies)],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        sampler.pids.update(logger=logger.pid, flood=pub.pid)
        pub_out, pub_err = pub.communicate(timeout=600)
        log_out, log_err = logger.communicate(timeout=600)
        end_unix = time.time()
    row["wall_s"] = time.monotonic() - t0
    row["cpu_s"] = {k: round(v, 2) for k, v in sampler.cpu_s.items()}
    row["peak_rss_mb"] = {k: round(v, 1) for k, v in sampler.hwm_mb.items()}
    try:
        pinfo = json.loads(pub_out.decode().strip().splitlines()[-1])
        summary = json.loads(log_out.decode().strip().splitlines()[-1])
    except (ValueError, IndexError):
        row.update(ok=False, failure=f"flood: publisher rc {pub.returncode}: {pub_err.decode()[-300:]}; "
                                     f"logger rc {logger.returncode}: {log_err.decode()[-300:]}")
        return row
    row["offered_msg_s"] = row["expected"] / max(pinfo["publish_s"], 1e-9)
    row["sustained_msg_s"] = row["expected"] / max(end_unix - pinfo["first_put_unix"], 1e-9)
    row["logger_missing"] = summary.get("missing")
    row["check"] = check_recording(out, 2 * bodies, steps) if out.exists() else None
    c = row["check"] or {}
    row["zero_loss"] = bool(c) and c["channels"] == 2 * bodies and c["lost"] == 0 and c["reordered"] == 0 \
        and c["extra"] == 0 and c["seq_mismatch"] == 0
    row["ok"] = logger.returncode == 0 and pub.returncode == 0
    row["failure"] = None if row["ok"] else f"exit codes logger {logger.returncode}, publisher {pub.returncode}"
    out.unlink(missing_ok=True)
    return row


def flood_table(rows: list[dict]) -> list[str]:
    head = ("| scene | logger queue (samples) | messages | publish phase msg/s | sustained msg/s into MCAP | lost |"
            " reordered | zero loss | peak RSS MB logger / publisher | CPU s logger |")
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for r in rows:
        c = r.get("check") or {}
        lines.append(f"| {r['scene']} | {r['queue']} | {r['expected']:,} | {r.get('offered_msg_s', 0):,.0f} |"
                     f" {r.get('sustained_msg_s', 0):,.0f} | {c.get('lost', '?')} | {c.get('reordered', '?')} |"
                     f" {'yes' if r.get('zero_loss') else 'NO'} | {r['peak_rss_mb'].get('logger', float('nan')):.0f} /"
                     f" {r['peak_rss_mb'].get('flood', float('nan')):.0f} | {r['cpu_s'].get('logger', float('nan')):.1f} |")
    return lines


# --------------------------------------------------------------------------- report


def machine() -> dict:
    from astrodyn.bench import cpu_model

    return {"cpu": cpu_model(), "cores": os.cpu_count(), "python": platform.python_version(),
            "platform": platform.platform(), "load": os.getloadavg()}


def table(rows: list[dict]) -> list[str]:
    """Markdown table, one line per scene (also printed to stdout)."""
    head = ("| scene | bodies | sim s | pacing | wall s | real-time factor | msg/s | expected | lost | reordered |"
            " zero loss | CPU s logger / orbit / attitude | peak RSS MB logger / orbit / attitude |")
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for r in rows:
        cpu = " / ".join(f"{r['cpu_s'].get(k, float('nan')):.1f}" for k in _PROCESSES)
        rss = " / ".join(f"{r['peak_rss_mb'].get(k, float('nan')):.0f}" for k in _PROCESSES)
        pacing = "max" if math.isinf(r["paced_rtf"]) else f"{r['paced_rtf']:g}x"
        lines.append(f"| {r['scene']} | {r['bodies']} | {r['sim_s']:g} | {pacing} | {r['wall_s']:.1f} | {r['rtf']:.2f} |"
                     f" {r['msg_per_s']:,.0f} | {r['expected']:,} | {r['lost']} | {r['reordered']} |"
                     f" {'yes' if r['zero_loss'] else 'NO'} | {cpu} | {rss} |")
    return lines


def default_scenes(duration: float | None, load_duration: float, small: int) -> list[Scene]:
    return [
        Scene(f"constellation-{small}", small, walker_planes(small, small), duration or 120.0),
        Scene("constellation-1000", 1000, 20, duration or 120.0),
        Scene("constellation-1000-unauthenticated", 1000, 20, duration or 120.0, authenticate=False),
        Scene("load-10x", 1000, 20, load_duration, real_time_factor=10.0),
    ]


FLOOD_STEPS_MAX = 1000
"""Largest ``--flood-steps``: the publisher holds every envelope in memory before it puts
them (about 0.47 MB per instant of 1000 bodies x 2 kinds), and so may a logger with a big
queue: 470 MB each here."""


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """The options of ``astrodyn bench service``, checked (argparse's usage error, exit 2)."""
    ap = argparse.ArgumentParser(prog="astrodyn bench service", description=__doc__.split("\n\n")[0])
    ap.add_argument("--duration", type=float_in(1.0, 3600.0), default=None,
                    help="simulated seconds of the as-fast-as-possible scenes, 1..3600 (20000 messages per simulated "
                         "second for 1000 bodies; default 120, as in the config)")
    ap.add_argument("--load-duration", type=float_in(1.0, 3600.0), default=20.0,
                    help="simulated seconds of the 10x load case, 1..3600 (default 20)")
    ap.add_argument("--small", type=int_in(1, 1000), default=100, help="satellites of the small scene, 1..1000 (default 100)")
    ap.add_argument("--bodies", type=int_in(1, 10_000), default=None,
                    help="run one scene of this many satellites only, 1..10000 (smoke runs)")
    ap.add_argument("--no-load", action="store_true", help="skip the 10x load case")
    ap.add_argument("--flood-steps", type=int_in(0, FLOOD_STEPS_MAX), default=200,
                    help=f"instants of the flood case (1000 bodies x 2 kinds each), 0..{FLOOD_STEPS_MAX} (held in "
                         "memory, about 0.47 MB each; default 200 = 400k messages; 0 skips it)")
    ap.add_argument("--flood-queues", type=int_list_in(1, 65_536, most=10), default="65536,64",
                    help="logger --queue values (samples) to run the flood case with, each 1..65536, at most 10 "
                         "(default 65536,64)")
    ap.add_argument("--md", metavar="FILE", type=output_file, help="write the results as Markdown (e.g. docs/bench-service.md)")
    ap.add_argument("--json", metavar="FILE", type=output_file, help="write the results as JSON")
    ap.add_argument("--keep", metavar="DIR", type=output_dir, help="keep configs and MCAP files in DIR (created if missing)")
    return ap.parse_args(argv)


def _flood_publisher_main(argv: list[str]) -> int:
    """``--flood-publisher HUB SCENARIO STEPS BODIES``: the child process of :func:`run_flood`."""
    from astrodyn.bus import endpoint_argument

    ap = argparse.ArgumentParser(prog="astrodyn bench service --flood-publisher")
    ap.add_argument("connect", type=endpoint_argument)
    ap.add_argument("scenario")
    ap.add_argument("steps", type=int_in(1, FLOOD_STEPS_MAX))
    ap.add_argument("bodies", type=int_in(1, 10_000))
    args = ap.parse_args(argv)
    flood_publisher(args.connect, args.scenario, args.steps, args.bodies)
    return 0


def main(argv: list[str] | None = None) -> int:
    if argv and argv[0] == "--flood-publisher" or argv is None and sys.argv[1:2] == ["--flood-publisher"]:
        return _flood_publisher_main((argv if argv is not None else sys.argv[1:])[1:])
    args = parse_args(argv)
    from astrodyn.scenario.catalogue import config_path

    template = config_path("constellation-1000").read_text()
    if args.bodies:
        scenes = [Scene(f"constellation-{args.bodies}", args.bodies, walker_planes(args.bodies, 20), args.duration or 2.0)]
    else:
        scenes = default_scenes(args.duration, args.load_duration, args.small)
        if args.no_load:
            scenes = [s for s in scenes if math.isinf(s.real_time_factor)]
    info = machine()
    rows = []
    with tempfile.TemporaryDirectory(prefix="astrodyn-bench-") as tmp:
        workdir = Path(args.keep) if args.keep else Path(tmp)
        workdir.mkdir(parents=True, exist_ok=True)
        for scene in scenes:
            print(f"[bench service] {scene.name}: {scene.bodies} bodies, {scene.duration_s:g} s sim, "
                  f"{scene.expected_messages:,} messages ...", file=sys.stderr, flush=True)
            rows.append(run_scene(scene, workdir, template, keep=bool(args.keep)))
        floods = []
        if args.flood_steps and not args.bodies and not args.no_load:
            for queue in args.flood_queues:
                print(f"[bench service] flood: {args.flood_steps} instants x 2000 messages, logger queue {queue} ...",
                      file=sys.stderr, flush=True)
                floods.append(run_flood(args.flood_steps, 1000, queue, workdir))
    info["load_after"] = os.getloadavg()
    lines = table(rows)
    if floods:
        lines += ["", *flood_table(floods)]
    print("\n".join(lines))
    for r in rows:
        if r["failure"]:
            print(f"  {r['scene']}: run failure: {r['failure']}")
        print(f"  {r['scene']}: children CPU total {r['children_cpu_s']} s (getrusage), propagate wall "
              f"{r['propagate_wall_s'] or float('nan'):.1f} s, file {r.get('file_mb', 0)} MB, check {r['check']}")
    if args.md:
        Path(args.md).write_text("\n".join(markdown(rows, floods, info, argv)) + "\n")
    if args.json:
        Path(args.json).write_text(json.dumps({"machine": info, "rows": rows, "flood": floods}, indent=1, default=str))
    return 0 if all(r.get("zero_loss") and r.get("ok") for r in rows + floods) else 1


def budget(rows: list[dict]) -> list[str]:
    """CPU per message of each process and the real-time factor that CPU allows on dedicated cores.

    Projection for ``cores`` dedicated cores: the run cannot be shorter than the busiest
    single process (each is one Python thread) nor than the total CPU / cores.
    """
    lines = ["| scene | logger us/msg | orbit us/msg | attitude us/msg | share of the machine used |"
             " RTF possible on 2 dedicated cores |", "|---|---|---|---|---|---|"]
    for r in rows:
        cpu = r.get("cpu_s") or {}
        n = r["expected"]
        if n == 0 or not all(k in cpu for k in _PROCESSES):
            continue
        per = [cpu["logger"] / n * 1e6, cpu["orbit"] / (n / 2) * 1e6, cpu["attitude"] / (n / 2) * 1e6]
        floor_s = max(max(cpu[k] for k in _PROCESSES), sum(cpu[k] for k in _PROCESSES) / 2)
        share = sum(cpu[k] for k in _PROCESSES) / r["wall_s"]
        lines.append(f"| {r['scene']} | {per[0]:.1f} | {per[1]:.1f} | {per[2]:.1f} | {share:.2f} cores |"
                     f" {r['sim_s'] / floor_s:.1f}x |")
    lines += ["", "CPU seconds include each process's start-up (imports, numba cache load, Zenoh session: about"
              " 1-2 s), which weighs on the short rows. 'Possible' assumes nothing else runs on the two cores."]
    return lines


def markdown(rows: list[dict], floods: list[dict], info: dict, argv: list[str] | None) -> list[str]:
    cmd = " ".join(["astrodyn bench service", *(argv if argv is not None else sys.argv[1:])]).strip()
    load0, load1 = info["load"], info["load_after"]
    out = [
        "# Service benchmark: propagators -> Zenoh -> logger -> MCAP",
        "",
        f"Generated by `{cmd}` on {_dt.datetime.now().strftime('%Y-%m-%d %H:%M')}: {info['cpu']}, {info['cores']} cores,"
        f" Python {info['python']}. The machine is shared: load average {load0[0]:.1f} before and {load1[0]:.1f} after"
        " the run, so every number is a snapshot of a loaded machine, not a best case.",
        "",
        "Each row is one `astrodyn run` (real processes, loopback Zenoh, end-of-run protocol); wall time includes",
        "process start-up. Loss and order are checked by reading the MCAP back with the plain `mcap` reader: every",
        "channel must hold exactly n_steps messages, sequence 0, 1, 2, ... in file order. CPU seconds and peak RSS",
        "(VmHWM) per process are sampled from /proc. Target (docs/architecture.md, section 7): constellation-1000 at >= 5x",
        "real time, i.e. 100 000 msg/s, zero loss. The load row paces the propagators at 10x real time",
        "(200 000 msg/s offered): blocking congestion control must slow them instead of dropping.",
        "",
        *table(rows),
        "",
    ]
    for r in rows:
        out.append(f"- {r['scene']}: children CPU total {r['children_cpu_s']} s (getrusage), propagators' own wall"
                   f" {r['propagate_wall_s'] or float('nan'):.1f} s, file {r.get('file_mb', 0)} MB"
                   + (f", FAILURE: {r['failure']}" if r["failure"] else ""))
    out += ["", "## Where the CPU goes", "", *budget(rows)]
    if floods:
        out += ["", "## Flood: publisher far faster than the logger (issue 6)", "",
                "One process puts pre-encoded envelopes (1000 bodies x orbit + attitude per instant) as fast as Zenoh",
                "takes them into `services/logger.py --queue N`. 'Publish phase' is the rate of the puts (blocking",
                "congestion control slows them once the logger's queue is full); 'sustained' counts from the first put",
                "to the logger's exit with the file finished. The logger's peak RSS shows what its queue holds.", "",
                *flood_table(floods)]
    return out


if __name__ == "__main__":
    sys.exit(main())
