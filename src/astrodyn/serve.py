"""``astrodyn serve CONFIG``: the long-running service, paced in real time, controlled over Zenoh.

The supervisor starts the logger and the propagators the scene needs (as ``astrodyn run``
does) with ``--endless`` (they keep going past the scenario's duration) at the scenario's
``real_time_factor`` (or ``--rate``), then answers control queries on
``astrodyn/<scenario>/@control/<verb>``:

=========  ==================================  =============================================
verb       arguments (JSON payload)            reply
=========  ==================================  =============================================
status     --                                  state, rate, sim t per process, pids, logger counts
pause      --                                  the new status (propagators hold their next step)
resume     --                                  the new status (pacing re-anchored at the current t)
rate       ``{"factor": x}`` (x > 0 or "inf")  the new status
stop       --                                  the final summary once the file is finished
=========  ==================================  =============================================

From Python::

    from astrodyn import bus
    with bus.open_session(connect=["tcp/127.0.0.1:7447"]) as s:
        bus.send_control(s, "demo", "rate", {"factor": 50})

The supervisor forwards pause / resume / rate / stop to its propagators on the private key
``astrodyn/<scenario>/@command``; on ``stop`` the propagators end with their end-of-run
events and the logger finishes the file once it holds every message (nothing published
is lost).  SIGTERM / Ctrl-C to the supervisor is a ``stop``.  A propagator that dies is
reported on stderr and in the ``status`` reply.
"""

from __future__ import annotations

import argparse
import json
import math
import signal
import sys
import tempfile
import time
from pathlib import Path

from astrodyn import bus
from astrodyn.propagator import command_key
from astrodyn.runner import _check_output, _Child, services_dir
from astrodyn.scenario import ScenarioError, load, plan as make_plan

__all__ = ["main", "Supervisor"]


class Supervisor:
    """Starts the processes of one scenario and answers the control verbs (module docstring)."""

    def __init__(self, scenario, config_path: Path, out: Path, session, hub: str, *, rate: float,
                 roll_size: int | None = None, roll_interval: float | None = None, connect=(), tmp: Path):
        self.scenario = scenario
        self.session = session
        self.rate = float(rate)
        self.state = "starting"
        self.started = time.monotonic()
        self.failures: list[str] = []
        p = make_plan(scenario)
        self.propagators = [k for k in p.processes if k != "logger"]
        services = services_dir()
        connect_args = sum((["--connect", e] for e in [hub, *connect]), [])
        meta = tmp / "scenario.json"
        meta.write_text(json.dumps(scenario.to_metadata()))
        logger_argv = [sys.executable, str(services / "logger.py"), "--scenario", scenario.name, "--out", str(out),
                       "--epoch-ns", str(scenario.epoch_unix_ns), "--metadata", str(meta), "--config", str(config_path),
                       "--no-control", *sum((["--expect", k] for k in self.propagators), []), *connect_args]
        if roll_size:
            logger_argv += ["--roll-size", str(roll_size)]
        if roll_interval:
            logger_argv += ["--roll-interval", str(roll_interval)]
        self.children: dict[str, _Child] = {"logger": _Child("logger", logger_argv, tmp)}
        bus.wait_for_process(session, scenario.name, "logger", timeout_s=30.0)
        for kind in self.propagators:
            argv = [sys.executable, str(services / f"{kind}.py"), str(config_path), "--endless",
                    "--real-time-factor", str(self.rate), *connect_args]
            self.children[kind] = _Child(kind, argv, tmp)
        self.commands = session.declare_publisher(command_key(scenario.name))
        self.beats = bus.HeartbeatMonitor(session, scenario.name)
        self.state = "running"

    # ------------------------------------------------------------------ commands

    def command(self, verb: str, **args) -> None:
        self.commands.put(json.dumps({"verb": verb, **args}))

    def status(self) -> dict:
        self.beats.poll()
        procs = {}
        for name, ch in self.children.items():
            hb = self.beats.last.get(name, {})
            procs[name] = {"pid": ch.pid, "running": ch.poll() is None, "exit": ch.poll(),
                           "t": hb.get("t"), "messages": hb.get("messages")}
        ts = [procs[k]["t"] for k in self.propagators if procs[k]["t"] is not None]
        return {"scenario": self.scenario.name, "state": self.state,
                "real_time_factor": "inf" if math.isinf(self.rate) else self.rate,
                "t": min(ts) if ts else 0.0, "wall_s": round(time.monotonic() - self.started, 3),
                "processes": procs, "failures": list(self.failures)}

    def handle(self, request: bus.ControlRequest) -> bool:
        """Answer one control request; True when it was ``stop``."""
        verb = request.verb
        if verb == "status":
            request.reply(self.status())
        elif verb == "pause":
            self.command("pause")
            self.state = "paused"
            request.reply(self.status())
        elif verb == "resume":
            self.command("resume")
            self.state = "running"
            request.reply(self.status())
        elif verb == "rate":
            raw = request.args.get("factor")
            try:
                factor = float(raw)
                if not factor > 0:
                    raise ValueError
            except (TypeError, ValueError):
                request.error(f'rate: expected {{"factor": x}} with x > 0 (or "inf"), got {raw!r}')
                return False
            self.rate = factor
            self.command("rate", factor=factor)
            request.reply(self.status())
        elif verb == "stop":
            return True
        else:
            request.error(f"{verb}: expected one of {', '.join(bus.CONTROL_VERBS)}")
        return False

    def check_children(self) -> None:
        for name, ch in self.children.items():
            rc = ch.poll()
            if rc is not None and rc != 0 and not any(f.startswith(f"process {name} ") for f in self.failures):
                hb = self.beats.last.get(name, {})
                msg = (f"process {name} (pid {ch.pid}) "
                       f"{'killed by signal ' + str(-rc) if rc < 0 else 'exited with status ' + str(rc)}"
                       f" at sim t {hb.get('t')}: {ch.stderr_tail(3)}")
                self.failures.append(msg)
                print(f"astrodyn serve: {msg}", file=sys.stderr, flush=True)

    def stop(self, timeout_s: float = 60.0) -> dict:
        """Stop the propagators, let the logger finish the file, return the final summary."""
        self.state = "stopping"
        self.command("stop")
        deadline = time.monotonic() + timeout_s
        for kind in self.propagators:
            ch = self.children[kind]
            try:
                ch.proc.wait(timeout=max(0.1, deadline - time.monotonic()))
            except Exception:
                ch.stop()
        logger = self.children["logger"]
        try:
            logger.proc.wait(timeout=max(1.0, deadline - time.monotonic()))
        except Exception:
            logger.stop(signal.SIGTERM, timeout=30)
        self.state = "stopped"
        summary = self.status()
        summary["logger"] = logger.summary()
        return summary

    def close(self) -> None:
        for ch in self.children.values():
            ch.stop()
            ch.close()
        self.beats.close()
        self.commands.undeclare()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="astrodyn serve", description="Long-running real-time service controlled over Zenoh.")
    ap.add_argument("config", help="scenario TOML file")
    ap.add_argument("--out", help="MCAP file (default out/<scenario>.mcap; rolled files get -0001, -0002, ...)")
    ap.add_argument("--rate", type=float, default=None, help="real-time factor (default: the scenario's real_time_factor)")
    ap.add_argument("--roll-size", type=int, default=None, help="start a new MCAP file after this many bytes")
    ap.add_argument("--roll-interval", type=float, default=None, help="start a new MCAP file after this many wall seconds")
    ap.add_argument("--max-wall", type=float, default=None, help="stop by itself after this many wall seconds")
    ap.add_argument("--port", type=int, default=None, help="loopback port of the control hub (default: a free one)")
    ap.add_argument("--connect", action="append", default=[], metavar="ENDPOINT", help="also connect to this endpoint (router)")
    args = ap.parse_args(argv)
    try:
        scenario = load(args.config)
        out = Path(args.out) if args.out else (scenario.output_path or Path("out") / f"{scenario.name}.mcap")
        out.parent.mkdir(parents=True, exist_ok=True)
        _check_output(out)
        rate = args.rate if args.rate is not None else scenario.real_time_factor
        if not rate > 0:
            raise ScenarioError(f"--rate: expected a real-time factor > 0, got {rate}")
    except ScenarioError as exc:
        print(f"astrodyn serve: {exc}", file=sys.stderr)
        return 2
    hub = bus.loopback_endpoint(args.port or bus.free_port())
    stop_signal = {"why": None}
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda s, f: stop_signal.update(why=signal.Signals(s).name))
    with tempfile.TemporaryDirectory(prefix="astrodyn-serve-") as tmp, bus.open_session(listen=[hub]) as session:
        sup = Supervisor(scenario, Path(args.config), out, session, hub, rate=rate, roll_size=args.roll_size,
                         roll_interval=args.roll_interval, connect=args.connect, tmp=Path(tmp))
        print(json.dumps({"serving": scenario.name, "hub": hub, "control": f"astrodyn/{scenario.name}/@control/*",
                          "out": str(out), "real_time_factor": rate}), flush=True)
        stop_requests: list[bus.ControlRequest] = []
        try:
            with bus.ControlServer(session, scenario.name) as control:
                t_end = None if args.max_wall is None else time.monotonic() + args.max_wall
                while True:
                    stopping = False
                    for req in control.poll():
                        if sup.handle(req):
                            stop_requests.append(req)
                            stopping = True
                    sup.check_children()
                    if stop_signal["why"] or stopping or (t_end is not None and time.monotonic() > t_end):
                        break
                    if all(sup.children[k].poll() is not None for k in sup.propagators):
                        break
                    time.sleep(0.02)
                summary = sup.stop()
                for req in stop_requests:
                    req.reply(summary)
        finally:
            sup.close()
    print(json.dumps(summary, default=str), flush=True)
    return 1 if summary["failures"] else 0
