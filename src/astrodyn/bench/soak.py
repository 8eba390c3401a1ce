"""``astrodyn bench soak``: a long ``astrodyn serve`` run at real time, sampled every minute.

    astrodyn bench soak --minutes 60 --out soak/          # the issue-6 soak (one hour)
    astrodyn bench soak --minutes 2 --sample 10 --out /tmp/s   # a quick look

What it does: writes a 100-satellite Walker scene (orbit + torque-free attitude at 10 Hz:
2000 messages/s), starts ``astrodyn serve`` on it at real-time factor 1 with rolling MCAP
files, and every ``--sample`` seconds records, per process (supervisor, logger, orbit,
attitude): resident memory (VmRSS) and CPU time (utime + stime) from ``/proc``; plus the
round-trip time of a ``status`` query over Zenoh and the lag of sim time behind wall time
(a service falling behind shows a growing lag).  At the end it stops the service with the
``stop`` verb, checks the recording (every channel contiguous across the rolled files) and
writes ``soak.json`` and ``soak.md`` (table + verdict: memory flat = the last quarter's
mean RSS within 10 % of the second quarter's; no growing lag).
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from astrodyn import bus
from astrodyn.bench import walker_planes
from astrodyn.bench.flags import float_in, int_in, output_dir
from astrodyn.scenario.catalogue import config_path
from astrodyn.service.children import stop_process

_TICK = os.sysconf("SC_CLK_TCK")


def _proc(pid: int) -> tuple[float, float]:
    """(RSS MiB, CPU seconds) of a live process, from /proc; (nan, nan) if gone."""
    try:
        with open(f"/proc/{pid}/status") as f:
            rss = next(int(line.split()[1]) for line in f if line.startswith("VmRSS:")) / 1024
        with open(f"/proc/{pid}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
        cpu = (int(fields[11]) + int(fields[12])) / _TICK
        return rss, cpu
    except (OSError, StopIteration, IndexError, ValueError):
        return float("nan"), float("nan")


def _scene(out: Path, satellites: int) -> Path:
    text = config_path("constellation-1000").read_text()
    text = text.replace('name = "constellation-1000"', 'name = "soak"').replace("t = 1000", f"t = {satellites}")
    planes = walker_planes(satellites, 10)
    text = text.replace("p = 20", f"p = {planes}")
    if planes == 1:  # a single plane has no phasing but 0 (the template's f = 1 needs two planes)
        text = text.replace("\nf = 1\n", "\nf = 0\n")
    path = out / "soak.toml"
    path.write_text(text)
    return path


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """The options of ``astrodyn bench soak``, checked (argparse's usage error, exit 2)."""
    ap = argparse.ArgumentParser(prog="astrodyn bench soak", description=__doc__.split("\n\n")[0])
    ap.add_argument("--minutes", type=float_in(0.5, 1440.0), default=60.0,
                    help="length of the soak, 0.5..1440 (a day; MCAP on disk: about 330 MB an hour per 100 satellites; "
                         "default 60)")
    ap.add_argument("--sample", type=float_in(1.0, 3600.0), default=60.0,
                    help="seconds between samples, 1..3600 (default 60)")
    ap.add_argument("--satellites", type=int_in(1, 2000), default=100,
                    help="Walker satellites (10 Hz, orbit + attitude), 1..2000 (real time on a laptop; default 100)")
    ap.add_argument("--out", type=output_dir, default="soak",
                    help="directory for the config, MCAP files and the report, created if missing (default soak)")
    ap.add_argument("--kill-logger-every", type=float_in(5.0, 86_400.0), default=None, metavar="S",
                    help="SIGKILL the logger every S seconds, 5..86400 (issue 13's fault soak): serve must restart it "
                         "with no state lost; the restart delay of each kill is measured")
    return ap.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    config = _scene(out, args.satellites)
    port = bus.free_port()
    serve = subprocess.Popen([sys.executable, "-m", "astrodyn", "serve", str(config), "--out", str(out / "soak.mcap"),
                              "--rate", "1", "--port", str(port), "--roll-size", str(256 << 20),
                              "--max-wall", str(args.minutes * 60 + 600)],
                             stdout=subprocess.PIPE, stderr=open(out / "serve.err", "wb"), text=True)
    samples: list[dict] = []
    kills: list[dict] = []
    final: dict = {}
    try:
        hello = json.loads(serve.stdout.readline())
        print(f"[soak] serving {hello['serving']} on {hello['hub']} for {args.minutes} min", file=sys.stderr)
        with bus.open_session(connect=[bus.loopback_endpoint(port)]) as s:
            t_start = time.monotonic()
            end = t_start + args.minutes * 60
            next_sample = t_start
            next_kill = t_start + (args.kill_logger_every or float("inf"))
            while time.monotonic() < end and serve.poll() is None:
                if time.monotonic() >= next_kill:
                    kills.append(_kill_logger(s, hello, t_start))
                    print(f"[soak] {json.dumps(kills[-1])}", file=sys.stderr, flush=True)
                    next_kill += args.kill_logger_every
                if time.monotonic() >= next_sample:
                    q0 = time.perf_counter()
                    replies = bus.send_control(s, "soak", "status", timeout_s=10, token=hello["control_token"])
                    rtt = time.perf_counter() - q0
                    st = replies[0] if replies else {}
                    row = {"wall_s": round(time.monotonic() - t_start, 1), "status_rtt_ms": round(rtt * 1e3, 2),
                           "sim_t": st.get("t"), "lag_s": None}
                    if st.get("t") is not None:
                        row["lag_s"] = round(st.get("wall_s", 0.0) - st["t"], 2)
                    pids = {"serve": serve.pid, **{k: v["pid"] for k, v in st.get("processes", {}).items()}}
                    for name, pid in pids.items():
                        rss, cpu = _proc(pid)
                        row[f"{name}_rss_mb"], row[f"{name}_cpu_s"] = round(rss, 1), round(cpu, 2)
                    samples.append(row)
                    print(f"[soak] {json.dumps(row)}", file=sys.stderr, flush=True)
                    next_sample += args.sample
                time.sleep(0.5)
            replies = bus.send_control(s, "soak", "stop", timeout_s=120, token=hello["control_token"])
            final = replies[0] if replies else {}
        serve.wait(timeout=120)
    finally:
        stop_process(serve, timeout=60)
    report = _report(samples, final, out, args, kills)
    (out / "soak.json").write_text(json.dumps({"samples": samples, "kills": kills, "final": final, "report": report},
                                              indent=1, default=str))
    print(report["markdown"])
    return 0 if report["ok"] else 1


def _kill_logger(session, hello: dict, t_start: float) -> dict:
    """SIGKILL serve's logger; wait until serve reports a new logger running; return the
    kill's record with the restart delay (kill to a new logger pid in ``status``)."""
    def logger_pid() -> tuple[int | None, bool]:
        replies = bus.send_control(session, hello["serving"], "status", timeout_s=10, token=hello["control_token"])
        proc = (replies[0] if replies else {}).get("processes", {}).get("logger", {})
        return proc.get("pid"), bool(proc.get("running"))

    pid, _ = logger_pid()
    killed_at = time.monotonic()
    os.kill(pid, signal.SIGKILL)
    while time.monotonic() - killed_at < 120:
        new, running = logger_pid()
        if new is not None and new != pid and running:
            return {"wall_s": round(killed_at - t_start, 1), "killed_pid": pid, "new_pid": new,
                    "restart_delay_s": round(time.monotonic() - killed_at, 3)}
        time.sleep(0.05)
    return {"wall_s": round(killed_at - t_start, 1), "killed_pid": pid, "new_pid": None, "restart_delay_s": None}


def _report(samples: list[dict], final: dict, out: Path, args, kills: list[dict] | None = None) -> dict:
    from astrodyn.recording import load

    files = sorted(out.glob("soak*.mcap"))
    seqs: dict[str, list] = {}
    messages = 0
    for f in files:
        run = load(f)
        messages += run.messages
        for topic, track in run.channels.items():
            if topic.endswith(("/orbit", "/attitude")):
                seqs.setdefault(topic, []).extend(track.seq.tolist())
    gaps = sum(1 for s in seqs.values() if sorted(s) != list(range(len(s))))
    procs = ["serve", "logger", "orbit", "attitude"]
    n = len(samples)
    q2 = samples[n // 4: n // 2] or samples
    q4 = samples[3 * n // 4:] or samples

    def mean(rows, key):
        vals = [r[key] for r in rows if r.get(key) == r.get(key) and r.get(key) is not None]
        return sum(vals) / len(vals) if vals else float("nan")

    flat = {p: abs(mean(q4, f"{p}_rss_mb") - mean(q2, f"{p}_rss_mb")) <= 0.10 * mean(q2, f"{p}_rss_mb") for p in procs}
    lag_growth = (mean(q4, "lag_s") - mean(q2, "lag_s")) if n >= 4 else float("nan")
    kills = kills or []
    delays = [k["restart_delay_s"] for k in kills if k["restart_delay_s"] is not None]
    states = sum(len(s) for s in seqs.values())
    ok = all(flat.values()) and gaps == 0 and not (lag_growth > 5.0) and len(delays) == len(kills)
    lines = [f"# Soak: `astrodyn serve` at real time for {args.minutes:g} min",
             "", f"Scene: {args.satellites}-satellite Walker, orbit + torque-free attitude at 10 Hz "
             f"({2 * 10 * args.satellites} messages/s); samples every {args.sample:g} s; "
             f"{len(files)} MCAP file(s), {messages} messages, channels with a gap: {gaps}.", "",
             "| wall s | sim t s | lag s | status RTT ms | " + " | ".join(f"{p} RSS MB | {p} CPU s" for p in procs) + " |",
             "|" + "---|" * (4 + 2 * len(procs))]
    for r in samples:
        lines.append(f"| {r['wall_s']} | {r.get('sim_t')} | {r.get('lag_s')} | {r['status_rtt_ms']} | "
                     + " | ".join(f"{r.get(p + '_rss_mb')} | {r.get(p + '_cpu_s')}" for p in procs) + " |")
    lines += ["", "Memory flat (last-quarter mean RSS within 10 % of the second quarter's): "
              + ", ".join(f"{p} {'yes' if v else 'NO'}" for p, v in flat.items()),
              f"Lag growth (last quarter minus second quarter): {lag_growth:.2f} s; verdict: {'OK' if ok else 'FAILED'}."]
    if kills:
        lines += ["", f"Logger SIGKILLed {len(kills)} times (every {args.kill_logger_every:g} s): restarted "
                  f"{len(delays)} times; restart delay (kill to the new logger in `status`) median "
                  f"{sorted(delays)[len(delays) // 2] if delays else float('nan'):.2f} s, worst "
                  f"{max(delays) if delays else float('nan'):.2f} s; {states} states in {len(seqs)} channels, "
                  f"channels with a gap or a lost state: {gaps}."]
    md = "\n".join(lines)
    (out / "soak.md").write_text(md + "\n")
    return {"ok": ok, "gaps": gaps, "messages": messages, "kills": len(kills), "restart_delays_s": delays, "files": [str(f) for f in files], "flat": flat,
            "lag_growth_s": lag_growth, "markdown": md}
