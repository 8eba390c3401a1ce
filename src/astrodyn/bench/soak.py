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
writes ``soak.json`` and ``soak.md`` (table + verdict, :func:`verdict`).

Verdict: the samples taken while the service starts (the one at wall time 0, and any before
sim time first advances: imports and numeric kernels loading, hundreds of MB that are not a
leak) are left out; of the rest (at least :data:`MIN_VERDICT_SAMPLES`), memory is flat when
each process's mean RSS over the last quarter is within 10 % of its mean over the second
quarter, and the lag of sim time behind wall time must not grow by more than
:data:`MAX_LAG_GROWTH_S` from the second quarter to the last.  Exit status: 0 OK; 1 FAILED
(memory grew, the lag grew, a channel has a gap, a killed logger was not restarted, or
serve exited before the end); 2 a bad option; 3 too few samples for a verdict on memory and
lag (a run too short for its ``--sample``; nothing else failed) -- the report says how long
a run needs.
"""

from __future__ import annotations

import argparse
import json
import math
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

MIN_VERDICT_SAMPLES = 8  #: samples after start-up a verdict on memory and lag needs (2 per quarter)
MAX_LAG_GROWTH_S = 5.0  #: most the lag of sim time behind wall time may grow, second quarter to last (s)
PROCESSES = ("serve", "logger", "orbit", "attitude")  #: the processes sampled
EXIT_NO_VERDICT = 3  #: exit status of a run with too few samples for a verdict (and nothing failed)


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
    ap = argparse.ArgumentParser(
        prog="astrodyn bench soak", description=__doc__.split("\n\n")[0],
        epilog=f"Exit status: 0 OK; 1 FAILED (memory or lag grew, a gap in the recording, a killed logger not "
               f"restarted, serve exited early); 2 a bad option; {EXIT_NO_VERDICT} too few samples for a verdict: "
               f"memory and lag need {MIN_VERDICT_SAMPLES} samples after start-up, i.e. --minutes >= about "
               f"{MIN_VERDICT_SAMPLES + 1} x --sample / 60 plus the start-up (a kernel load of up to a minute on "
               f"a first run).")
    ap.add_argument("--minutes", type=float_in(0.5, 1440.0), default=60.0,
                    help="length of the soak, 0.5..1440 (a day; MCAP on disk: about 330 MB an hour per 100 satellites; "
                         f"default 60; a verdict needs {MIN_VERDICT_SAMPLES} samples after start-up)")
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
    planned = math.ceil(args.minutes * 60 / args.sample)  # samples at wall 0, S, 2 S, ... before the end
    if planned - 1 < MIN_VERDICT_SAMPLES:
        print(f"[soak] note: --minutes {args.minutes:g} --sample {args.sample:g} takes {planned} samples; a verdict on "
              f"memory and lag needs {MIN_VERDICT_SAMPLES} after the start-up one: this run will end with no verdict "
              f"(exit {EXIT_NO_VERDICT}) unless something fails; use --minutes >= "
              f"{minutes_for_verdict(args.sample, 1):g}", file=sys.stderr)
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
    ended_early = False
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
            ended_early = serve.poll() is not None
            replies = bus.send_control(s, "soak", "stop", timeout_s=120, token=hello["control_token"])
            final = replies[0] if replies else {}
        serve.wait(timeout=120)
    finally:
        stop_process(serve, timeout=60)
    result = report(samples, final, out, args, kills, ended_early=ended_early)
    (out / "soak.json").write_text(json.dumps({"samples": samples, "kills": kills, "final": final, "report": result},
                                              indent=1, default=str))
    print(result["markdown"])
    return {"OK": 0, "FAILED": 1}.get(result["outcome"], EXIT_NO_VERDICT)


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


def start_up_samples(samples: list[dict]) -> int:
    """How many of the first ``samples`` were taken while the service started: the one at
    wall time 0 and every one before sim time first advanced (``sim_t`` missing or 0), when
    the processes import and load their numeric kernels (memory rises by hundreds of MB)."""
    k = 1
    while k < len(samples) and not (samples[k].get("sim_t") or 0) > 0:
        k += 1
    return min(k, len(samples))


def minutes_for_verdict(sample_s: float, start_up: int) -> float:
    """The ``--minutes`` (rounded up to 0.1) that take :data:`MIN_VERDICT_SAMPLES` samples
    every ``sample_s`` seconds after ``start_up`` start-up samples."""
    return math.ceil((MIN_VERDICT_SAMPLES + start_up) * sample_s / 6) / 10


def verdict(samples: list[dict], sample_s: float, gaps: int = 0, kills: list[dict] | None = None,
            ended_early: bool = False) -> dict:
    """The soak's verdict on its ``samples`` (rows with ``sim_t``, ``lag_s`` in s and
    ``<process>_rss_mb`` in MiB, taken every ``sample_s`` s), the recording's ``gaps`` (channels
    with a gap) and the logger ``kills`` (module docstring).

    Returns ``outcome`` (``"OK"``, ``"FAILED"`` or ``"NO VERDICT"``: too few samples after
    start-up for memory and lag, nothing else failed), ``flat`` (process -> bool, None without
    a verdict), ``lag_growth_s`` (nan without one), ``start_up`` and ``steady`` (sample counts),
    ``failures`` (one phrase each) and ``note`` (why there is no verdict and what run would
    give one)."""
    kills = kills or []
    start_up = start_up_samples(samples)
    steady = samples[start_up:]
    n = len(steady)
    failures = []
    if gaps:
        failures.append(f"{gaps} channel(s) with a gap")
    restarted = sum(1 for k in kills if k.get("restart_delay_s") is not None)
    if restarted != len(kills):
        failures.append(f"the logger was not restarted after {len(kills) - restarted} of {len(kills)} kills")
    if ended_early:
        failures.append("serve exited before the end of the soak")
    flat: dict[str, bool | None] = dict.fromkeys(PROCESSES)
    lag_growth = float("nan")
    note = ""
    if n < MIN_VERDICT_SAMPLES:
        note = (f"too few samples for a verdict: need {MIN_VERDICT_SAMPLES} after start-up, got {n} (of {len(samples)}, "
                f"{start_up} taken during start-up); use --minutes >= {minutes_for_verdict(sample_s, start_up):g} "
                f"with --sample {sample_s:g}")
    else:
        q2, q4 = steady[n // 4: n // 2], steady[3 * n // 4:]

        def mean(rows, key):
            vals = [r[key] for r in rows if isinstance(r.get(key), (int, float)) and r[key] == r[key]]
            return sum(vals) / len(vals) if vals else float("nan")

        for p in PROCESSES:
            before, after = mean(q2, f"{p}_rss_mb"), mean(q4, f"{p}_rss_mb")
            flat[p] = abs(after - before) <= 0.10 * before  # nan (process not sampled): not flat
        grown = [p for p, ok in flat.items() if not ok]
        if grown:
            failures.append(f"memory not flat: {', '.join(grown)}")
        lag_growth = mean(q4, "lag_s") - mean(q2, "lag_s")
        if not lag_growth <= MAX_LAG_GROWTH_S:
            failures.append(f"lag growth {lag_growth:.2f} s (at most {MAX_LAG_GROWTH_S:g} s)" if lag_growth == lag_growth
                            else "no lag measured in the second or last quarter (status unanswered)")
    outcome = "FAILED" if failures else ("NO VERDICT" if note else "OK")
    return {"outcome": outcome, "flat": flat, "lag_growth_s": lag_growth, "start_up": start_up, "steady": n,
            "failures": failures, "note": note}


def report(samples: list[dict], final: dict, out: Path, args, kills: list[dict] | None = None,
           ended_early: bool = False) -> dict:
    """Check the recording in ``out``, judge the run (:func:`verdict`), write ``soak.md``;
    the verdict's fields plus ``ok``, ``gaps``, ``messages``, ``files`` and ``markdown``."""
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
    kills = kills or []
    judged = verdict(samples, args.sample, gaps, kills, ended_early)
    delays = [k["restart_delay_s"] for k in kills if k["restart_delay_s"] is not None]
    states = sum(len(s) for s in seqs.values())
    lines = [f"# Soak: `astrodyn serve` at real time for {args.minutes:g} min",
             "", f"Scene: {args.satellites}-satellite Walker, orbit + torque-free attitude at 10 Hz "
             f"({2 * 10 * args.satellites} messages/s); samples every {args.sample:g} s; "
             f"{len(files)} MCAP file(s), {messages} messages, channels with a gap: {gaps}.", "",
             "| wall s | sim t s | lag s | status RTT ms | " + " | ".join(f"{p} RSS MB | {p} CPU s" for p in PROCESSES) + " |",
             "|" + "---|" * (4 + 2 * len(PROCESSES))]
    for r in samples:
        lines.append(f"| {r['wall_s']} | {r.get('sim_t')} | {r.get('lag_s')} | {r['status_rtt_ms']} | "
                     + " | ".join(f"{r.get(p + '_rss_mb')} | {r.get(p + '_cpu_s')}" for p in PROCESSES) + " |")
    lines.append("")
    if judged["note"]:
        lines.append(f"Memory and lag: {judged['note']}.")
    else:
        lines += [f"Memory flat (last-quarter mean RSS within 10 % of the second quarter's, the {judged['start_up']} "
                  "start-up sample(s) left out): " + ", ".join(f"{p} {'yes' if v else 'NO'}" for p, v in judged["flat"].items()),
                  f"Lag growth (last quarter minus second quarter): {judged['lag_growth_s']:.2f} s."]
    lines.append(f"Verdict: {judged['outcome']}" + (f" ({'; '.join(judged['failures'])})" if judged["failures"] else "") + ".")
    if kills:
        lines += ["", f"Logger SIGKILLed {len(kills)} times (every {args.kill_logger_every:g} s): restarted "
                  f"{len(delays)} times; restart delay (kill to the new logger in `status`) median "
                  f"{sorted(delays)[len(delays) // 2] if delays else float('nan'):.2f} s, worst "
                  f"{max(delays) if delays else float('nan'):.2f} s; {states} states in {len(seqs)} channels, "
                  f"channels with a gap or a lost state: {gaps}."]
    md = "\n".join(lines)
    (out / "soak.md").write_text(md + "\n")
    return {**judged, "ok": judged["outcome"] == "OK", "gaps": gaps, "messages": messages, "kills": len(kills),
            "restart_delays_s": delays, "files": [str(f) for f in files], "markdown": md}
