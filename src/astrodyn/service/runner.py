"""``astrodyn run CONFIG --out FILE.mcap``: a scenario headless, as fast as the machine allows.

What happens, in order:

1. The config is loaded and validated (:func:`astrodyn.scenario.load`); a bad config or an
   unwritable output path exits 2 before anything is started or written.
2. The runner opens a Zenoh session on a free loopback port (the hub, multicast scouting
   off) and starts, as separate OS processes (``subprocess``, never ``fork``):
   ``services/logger.py`` first, then only the propagators the plan needs
   (``services/orbit.py``, ``services/attitude.py``).  Children connect to the hub and
   meet each other through gossip.
3. While they run it prints progress on stderr (sim time reached, messages/s) from the
   processes' heartbeats, and watches their liveliness tokens and exit codes: a
   propagator that dies is reported (which process, which bodies, how far it got), the
   logger is told to finish the file (everything logged so far stays readable) and the
   run exits 1.
4. The logger ends by itself once it holds every message the propagators announced
   (end-of-run protocol of :mod:`astrodyn.service.logger`); the runner then reads the
   file back and prints a summary per body: model, steps, states logged, and the drift of
   the conserved quantities (orbit: specific energy and angular momentum, exact for
   two-body models; attitude: |q| - 1, and for torque-free bodies rotational energy and
   inertial angular momentum).

Exit status: 0 complete, 1 a process failed or messages were lost, 2 bad config/arguments, 3 complete
but the logger rejected messages that were not the run's own (``--tolerate-rejected`` makes that 0).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from astrodyn import auth, bus
from astrodyn.files import regular_file_problem
from astrodyn.jit import kernels_uncached
from astrodyn.progress import Progress
from astrodyn.recording.writer import part_path, partial_path, standby_path
from astrodyn.scenario import Scenario, ScenarioError, load, plan as make_plan, resolved_epoch_environment
from astrodyn.scenario.recorded import DURATION_PATHS, config_difference
from astrodyn.service.children import (
    DISK_FULL_EXIT,
    LOGGED_WAIT_S,
    MODEL_ENDED_EXIT,
    STALL_S,
    Child,
    JobControl,
    StartError,
    add_stall_argument,
    child_bus_arguments,
    config_snapshot,
    ensure_open_file_limit,
    logger_command,
    plant_command,
    propagator_command,
    start_controller,
    wait_ready,
    wall_seconds,
    work_directory,
    zenoh_config_snapshot,
)
from astrodyn.service.output import check_output_path, series_start_problem
from astrodyn.service.summary import file_summary, print_summary, propagator_rows, sim_time_reached
from astrodyn.service.supervision import (
    LoggerFile,
    RestartBudget,
    next_event_seq,
    plan_logger_restart,
    restarts_after_start_up_death,
    wait_until_gone,
)
from astrodyn.signals import catch_stop_signals

__all__ = ["main", "run_scenario", "ScenarioRun", "EXIT_REJECTED", "attack_report", "closed_loop_line",
           "check_command_recording", "logger_base_argv", "propagator_argv"]

#: Most loggers of one run (``--loggers``): the main one and its hot standbys.
MAX_LOGGERS = 8

#: Exit status of ``astrodyn run`` when the run completed but the logger rejected messages
#: that were not the run's own (forged, replayed, ghost bodies): the record was attacked.
EXIT_REJECTED = 3


def logger_base_argv(scenario: Scenario, metadata: Path, config_path: Path, expect: list[str],
                     connect_args: list[str]) -> list[str]:
    """The command line every logger of a run starts from (``run`` and ``serve``: the main
    logger, its restarts and the hot standbys add ``--out`` and the rest): the scenario's
    name and epoch (Unix time in ns), its ``metadata`` file (JSON), the config, no
    control channel of its own, the processes it expects (``--expect``) and the bus
    arguments ``connect_args``."""
    return [*logger_command(), "--scenario", scenario.name, "--epoch-ns", str(scenario.epoch_unix_ns),
            "--metadata", str(metadata), "--config", str(config_path), "--no-control",
            *sum((["--expect", k] for k in expect), []), *connect_args]


def propagator_argv(kind: str, config_path: Path, connect_args: list[str], *options: str) -> list[str]:
    """The command line of the process ``kind`` of a run (a propagator, or ``"plant"``, the
    closed loop's plant): the config, ``options``, then the bus arguments ``connect_args``."""
    return [*(plant_command() if kind == "plant" else propagator_command(kind)), str(config_path), *options,
            *connect_args]


def run_scenario(scenario: Scenario, out: Path, *, cross_check: bool = False,
                 real_time_factor: float = math.inf, connect: list[str] | None = None,
                 progress: bool = True, timeout_s: float | None = None, extra_args: dict | None = None,
                 logger_args: list[str] | None = None, zenoh_config: bus.ZenohConfigText | str | None = None,
                 authenticate: bool = True, controllers: list[str] | None = None,
                 commands: Path | None = None, loggers: int = 1, stall_s: float | None = STALL_S) -> dict:
    """Run ``scenario`` with real processes; return the result dict (see :func:`main`).

    The processes load the config text ``scenario`` was loaded from (``scenario.text``),
    copied into the run's work directory (:func:`~astrodyn.service.children.config_snapshot`),
    never the file the user named: an edit made while the run goes on changes nothing.

    ``zenoh_config``: a Zenoh JSON5 file (TLS, access control) every process starts from: the
    text :func:`astrodyn.bus.read_zenoh_config` read and checked (a path is read here), copied
    into the work directory like the scene config
    (:func:`~astrodyn.service.children.zenoh_config_snapshot`): a restarted process loads
    that copy, never the user's file as it is by then.
    ``controllers``: command lines of the closed loop's controllers (``--controller``),
    started once the plant is up, named after ``control.controllers`` in order, with the
    run's bus and secret in their environment (docs/control.md); ``commands``: a recording
    whose commands the plant re-applies instead (``--commands``).
    ``loggers``: how many loggers record the run; the second and later are hot standbys,
    each recording a complete file of its own (:func:`astrodyn.recording.writer.standby_path`).
    ``stall_s``: a propagator or logger silent (no heartbeat) this many wall seconds is
    killed and handled as a crash (:meth:`astrodyn.service.children.Child.kill_if_stalled`);
    None: never.
    ``authenticate=False`` runs without the run secret (children neither sign nor verify):
    only for measuring what authentication costs (``astrodyn bench service``).

    SIGTERM / SIGINT (Ctrl-C) while it runs: the propagators are stopped first (each sends
    its end-of-run event saying how far it got), then the logger finishes the file
    (summary, indexes, footer, and an "end" metadata record with the sim time reached);
    ``result["interrupted"]`` names the signal.
    """
    return ScenarioRun(scenario, out, cross_check=cross_check, real_time_factor=real_time_factor,
                       connect=connect, progress=progress, timeout_s=timeout_s, extra_args=extra_args,
                       logger_args=logger_args, zenoh_config=zenoh_config, authenticate=authenticate,
                       controllers=controllers, commands=commands, loggers=loggers, stall_s=stall_s).run()


#: Wall seconds an interrupted run waits for the logger to end by itself, once the
#: propagators are stopped (it ends once it holds their end-of-run events); then, or at a
#: second stop signal, it is told to finish the file with what it holds (SIGTERM).
INTERRUPTED_LOGGER_WAIT_S = 10.0
#: Wall seconds the logger of an interrupted run is given, once every propagator has exited,
#: to take what they published last (already on its way: a drain of the logger's queues is
#: milliseconds) before it is told to finish: a propagator stopped while it loaded its
#: kernels sends no end-of-run event, and the logger would wait for it the whole
#: :data:`INTERRUPTED_LOGGER_WAIT_S`.
INTERRUPTED_DRAIN_S = 1.0


#: A propagator that ends with the same error this many times in a row, each time restarted at
#: the same step and recording none (a deterministic failure), is not restarted again, however
#: far apart the deaths (the RestartBudget counts deaths within 60 s only).
SAME_ERROR_RESTARTS = 2


class ScenarioRun:
    """One ``astrodyn run``: the module docstring's steps, one method each (start the
    logger, the propagators and the controllers, watch, restart what dies, finish)."""

    def __init__(self, scenario: Scenario, out: Path, *, cross_check: bool,
                 real_time_factor: float, connect: list[str] | None, progress: bool, timeout_s: float | None,
                 extra_args: dict | None, logger_args: list[str] | None,
                 zenoh_config: bus.ZenohConfigText | str | None,
                 authenticate: bool, controllers: list[str] | None, commands: Path | None, loggers: int = 1,
                 stall_s: float | None = STALL_S):
        self.scenario, self.out = scenario, out
        self.config_path: Path | None = None  # the run's copy of the config (run())
        self.stall_s = stall_s
        self.cross_check, self.real_time_factor = cross_check, real_time_factor
        self.progress, self.timeout_s = progress, timeout_s
        self.extra_args, self.logger_args = extra_args or {}, logger_args or []
        if zenoh_config is not None and not isinstance(zenoh_config, bus.ZenohConfigText):
            zenoh_config = bus.read_zenoh_config(zenoh_config, shared=True)
        self.zenoh_config, self.authenticate = zenoh_config, authenticate
        self.controller_commands, self.commands = controllers or [], commands
        self.plan = make_plan(scenario)
        self.propagators = [k for k in self.plan.processes if k != "logger"]
        self.hub = bus.loopback_endpoint(bus.free_port())
        self.connect = list(connect or [])
        self.connect_args: list[str] = []  # every child's bus flags (bus_config_copy)
        self.result: dict = {"scenario": scenario.name, "out": str(out), "processes": {}, "ok": False}
        self.restarts: list[dict] = self.result.setdefault("restarts", [])
        self.interrupted: dict = {"signal": None, "count": 0}  # the last stop signal, how many came
        self.children: dict[str, Child] = {}
        self.controllers: dict[str, Child] = {}
        self.logger_budget = RestartBudget("logger")
        self.budgets = {kind: RestartBudget(kind) for kind in self.propagators}
        self.token_file: Path | None = None
        self.loggers = int(loggers)
        self.standbys: dict[str, Child] = {}  # hot standby loggers: logger-2, ... (not restarted)
        self.logger_files: dict[int, LoggerFile] = {}  # attempt -> the file that logger created (LoggerFile)
        self.logger_attempt = 0  # the attempt number of the logger running now
        self.verifier: auth.Verifier | None = None  # a logger is ready when it answers signed (wait_ready)

    def start_logger(self, attempt: int, extra: list[str], announce=None) -> str | None:
        """Start logger number ``attempt`` (0: the first; ``--attempt N`` writes
        ``NAME.partial-N.mcap``) and wait until it is ready; the failure text if it is not.
        The file it created is recorded as this run's (:class:`LoggerFile`): only such a file
        is ever renamed or removed by the run, never one another run or the user put at
        that path.  ``announce(child)`` is called once it is started."""
        path = partial_path(self.out, attempt)
        existed_before = os.path.lexists(path)
        argv = [*self.logger_argv, *(["--attempt", str(attempt)] if attempt else []), *extra]
        child = self.children["logger"] = Child("logger" if not attempt else f"logger-r{attempt}", argv, self.tmpd,
                                                env=self.child_env)
        child.name = "logger"
        self.logger_attempt = attempt
        if announce is not None:
            announce(child)
        failure = wait_ready(self.session, self.scenario.name, child, 60.0, self.interrupted, verifier=self.verifier)
        if failure is None:
            owned = LoggerFile.of_ready_logger(path)
        else:  # one that died may have created its file (headers only) before it was killed
            owned = LoggerFile.of_dead_logger(path, existed_before) if child.poll() is not None else None
        if owned is not None:
            self.logger_files[attempt] = owned
        return failure

    def bus_config_copy(self, work: Path) -> Path | None:
        """Write the run's copy of its ``--zenoh-config`` into the work directory ``work`` and
        set the bus flags of every child to name it; return its path (None without one), the
        config of the hub's session too."""
        copy = zenoh_config_snapshot(self.zenoh_config, work)
        self.connect_args = child_bus_arguments(self.hub, self.connect, copy)
        return copy

    def on_stop_signal(self, why: str) -> None:
        """SIGINT (Ctrl-C), SIGTERM, SIGHUP: the run stops (:meth:`finish`); a second one
        makes the logger finish its file at once."""
        self.interrupted["signal"] = why
        self.interrupted["count"] += 1

    def say(self, text: str) -> None:
        if self.progress:
            print(text, file=sys.stderr, flush=True)

    def run(self) -> dict:
        scenario, result = self.scenario, self.result
        ensure_open_file_limit()
        started = time.monotonic()
        restore_signals = catch_stop_signals(self.on_stop_signal)
        self.job = JobControl()  # Ctrl-Z pauses every process of the run
        secret = auth.RunSecret.generate() if self.authenticate else None
        with work_directory(self.out, "run") as tmp, \
                bus.open_session(listen=[self.hub], config_file=self.bus_config_copy(Path(tmp))) as session, \
                bus.HeartbeatMonitor(session, scenario.name, verifier=secret and auth.Verifier(secret)) as beats, \
                bus.AliveWatcher(session, scenario.name) as alive:
            self.session, self.tmpd = session, Path(tmp)
            # not for run: a logger flooded from its first moment (2 M forged heartbeats in 4 s,
            # test_bus_fuzz_regressions) answers @latest only after the flood's callbacks, past the 60 s
            # start-up wait.  serve does verify (children.wait_ready): two serves on one --out behind a shared
            # router; two runs there still end right, the loser with a less exact message (crossing probe F5)
            self.verifier = None
            self.config_path = config_snapshot(scenario, self.tmpd)
            # the run's identity: children sign what they publish (docs/security.md)
            self.child_env = {**resolved_epoch_environment(scenario),
                              **({auth.SECRET_ENV: str(secret.save(self.tmpd))} if secret is not None else {})}
            if "plant" in self.propagators and secret is not None:  # outside controllers join with this token
                self.token_file = auth.write_private_file(self.tmpd / "control.token", auth.new_token().encode())
                result["control_token_file"] = str(self.token_file)
            meta_path = self.tmpd / "scenario.json"
            meta_path.write_text(json.dumps(scenario.to_metadata()))
            try:
                common = logger_base_argv(scenario, meta_path, self.config_path, self.propagators, self.connect_args)
                # "--out=": a path that starts with "-" is not taken for an option
                self.logger_argv = [*common, f"--out={self.out}", "--leave-partial"]
                failure = self.start_logger(0, self.logger_args)
                failure = self.replace_logger_dead_while_starting(failure)
                if failure is None:
                    failure = self.start_standbys(common)
                if failure is None:
                    failure = self.start_and_watch(beats, alive)
                result["failure"] = self.finish(failure)
            finally:
                for ch in self.controllers.values():
                    ch.stop(signal.SIGTERM, timeout=5)
                    ch.close()
                for name in [*(k for k in self.children if k != "logger"), "logger"]:  # propagators first
                    if name in self.children:
                        self.children[name].stop()
                        self.children[name].close()
                for standby in self.standbys.values():
                    standby.stop()
                    standby.close()
                restore_signals()
                self.job.restore()
        result["interrupted"] = self.interrupted["signal"]
        result["wall_s"] = time.monotonic() - started
        log = (result["processes"].get("logger") or {}).get("summary") or {}
        if not isinstance(log, dict):
            log = {}
        result["logger"] = log
        why = self.interrupted["signal"]
        reached = sim_time_reached(log)
        if why and reached is not None and (result.get("failure") or "").startswith(f"interrupted by {why} at sim t"):
            # how far the recording got (the heartbeats the watch saw may be seconds old, or from start-up)
            result["failure"] = f"interrupted by {why} at sim t {reached:.6g} s of {self.scenario.duration:.6g} s"
            if recorded_to_the_end(log):  # the signal came while the logger took the last states: nothing is missing
                del result["failure"]
                result["complete_before_signal"] = True
        lost = log.get("missing", 0)
        if not result.get("failure") and lost:
            result["failure"] = f"{lost} messages missing in the recording"
        try:
            result["file"] = _name_the_recording(log.get("file"), self.out, result, self.logger_files,
                                                 self.logger_attempt)
        finally:
            for owned in self.logger_files.values():
                owned.close()
        if not result.get("failure") and not log:  # its summary (in the work directory) is gone: say so
            result["failure"] = (f"the logger ended without its summary (its output in {self.tmpd} is gone); the "
                                 f"recording is {result['file'] or 'not found'}")
        result["ok"] = not result.get("failure") and bool(log) and not lost
        return result

    # ------------------------------------------------------------------ starting

    def start_propagator(self, kind: str, resume_args: dict, n: int = 0, event_seq: int = 0) -> None:
        children = self.children
        if kind == "plant":
            argv = propagator_argv(kind, self.config_path, self.connect_args)
            if self.token_file is not None:
                argv += ["--control-token-file", str(self.token_file)]
            if self.commands is not None:
                argv.append(f"--commands={self.commands}")  # "=": a path may start with "-"
            children[kind] = Child(kind, argv, self.tmpd, env=self.child_env)
            return
        argv = propagator_argv(kind, self.config_path, self.connect_args)
        if event_seq:
            argv += ["--first-event-seq", str(event_seq)]
        if not math.isinf(self.real_time_factor):
            argv += ["--real-time-factor", str(self.real_time_factor)]
        if self.cross_check and kind == "orbit":
            argv.append("--cross-check")
        for k, v in resume_args.items():
            argv += [k, str(v)]
        children[kind] = Child(kind if not n else f"{kind}-r{n}", argv, self.tmpd, env=self.child_env)
        children[kind].name = kind

    def absent_controllers(self) -> list[str]:
        """The controllers a lockstep run waits for that it did not start (``--controller``
        gives fewer than ``control.controllers`` names): outside ones, started by hand; none
        when the commands come from a recording (``--commands``)."""
        control = self.scenario.control
        if control is None or control.mode != "lockstep" or self.commands is not None:
            return []
        return [name for name in control.controllers if name not in self.controllers]

    def start_controllers(self) -> str | None:
        scenario = self.scenario
        names = scenario.control.controllers if scenario.control is not None else ()
        for n, cmd in enumerate(self.controller_commands):
            cname = names[n]
            try:
                self.controllers[cname] = start_controller(cname, cmd, scenario.name, self.hub, self.tmpd,
                                                           self.child_env, self.token_file)
            except OSError as exc:
                return f"controller {cname}: cannot start {cmd!r}: {exc}"
        return None

    def replace_logger_dead_while_starting(self, failure: str | None) -> str | None:
        """The logger was killed by a signal while starting (a kill at a random moment can
        land there, a crash): nothing is recorded yet, so a new one starts afresh (its
        predecessor's partial is removed at the end like every dead logger's), within the
        restart budget.  One that exited on its own (its file is in the way: another run
        records to it, a killed run left it; it cannot be written; its disk is full; a bad
        argument) is not replaced: the run fails at once with its words
        (:func:`~astrodyn.service.supervision.restarts_after_start_up_death`)."""
        children, scenario = self.children, self.scenario
        while failure is not None and restarts_after_start_up_death(children["logger"].poll()) \
                and not self.interrupted["signal"]:
            dead, rc = children["logger"], children["logger"].poll()
            if not self.logger_budget.allow():
                return f"{self.logger_budget.refusal()}; last: {failure}"
            dead.close()
            wait_until_gone(self.session, scenario.name, "logger")
            attempt = len(self.restarts_of("logger")) + 1
            how = dead.how(rc)
            record = {"process": "logger", "old_pid": dead.pid, "new_pid": None, "why": f"{how} while starting",
                      "from_step": 0, "state_from": None}
            self.restarts.append(record)

            def announce(child, dead=dead, how=how, record=record):
                record["new_pid"] = child.pid
                self.say(f"  logger (pid {dead.pid}) {how} while starting: restarted (pid {child.pid})")
            failure = self.start_logger(attempt, self.logger_args, announce)
        return failure

    def start_standbys(self, common: list[str]) -> str | None:
        """Start the hot standby loggers (``--loggers N``): ``logger-2`` ... ``logger-N``, each
        recording everything into its own file (:func:`standby_path`) and naming it itself
        when the run ends.  A standby is not restarted: one that dies leaves its partial file
        (for ``recover`` or ``merge``) and a warning; the run goes on with the others."""
        for k in range(2, self.loggers + 1):
            name = f"logger-{k}"
            child = self.standbys[name] = Child(name, [*common, "--name", name, f"--out={standby_path(self.out, k)}"],
                                                self.tmpd, env=self.child_env)
            failure = wait_ready(self.session, self.scenario.name, child, 60.0, self.interrupted,
                                 verifier=self.verifier)
            if failure is not None:
                return failure
        if self.standbys:
            self.say("  standby loggers " + ", ".join(f"{n} (pid {c.pid})" for n, c in self.standbys.items()))
        return None

    def finish_standbys(self, failure: str | None) -> None:
        """Let each standby finish its file (they end, as the logger does, once every state
        is recorded); ``result["standbys"]`` says how each ended and where its file is."""
        out = self.result.setdefault("standbys", {})
        for k, (name, child) in enumerate(self.standbys.items(), start=2):
            if failure:
                child.stop(signal.SIGTERM, timeout=30)
            else:
                try:
                    child.proc.wait(timeout=60)
                except subprocess.TimeoutExpired:
                    child.stop(signal.SIGTERM, timeout=30)
            summary = child.summary()
            final = standby_path(self.out, k)
            file = (summary or {}).get("file") or partial_path(final)
            out[name] = {"pid": child.pid, "exit": child.poll(), "file": file, "summary": summary,
                         "stderr": child.stderr_tail()}
            if child.poll() != 0 or file != final:
                self.result.setdefault("warnings", []).append(
                    f"standby {name} (pid {child.pid}) {child.how(child.poll()) if child.poll() else 'did not finish'}: "
                    f"its recording stays at {file} (`astrodyn recover`, or `astrodyn merge` with the main file)")

    def start_and_watch(self, beats, alive) -> str | None:
        """Start the propagators and the controllers; watch them until the run ends."""
        scenario = self.scenario
        self.result["hub"] = self.hub
        print(f"  bus {self.hub}: any Zenoh client can subscribe to astrodyn/{scenario.name}/** there "
              f"(docs/clients.md)", file=sys.stderr, flush=True)
        if self.token_file is not None:
            print(f"  control token {self.token_file}: outside controllers present it (docs/control.md)",
                  file=sys.stderr, flush=True)
        for kind in self.propagators:
            self.start_propagator(kind, self.extra_args.get(kind, {}))
        failure = self.start_controllers()
        if self.controllers:
            self.say("  controllers " + ", ".join(f"{n} (pid {c.pid})" for n, c in self.controllers.items()))
        if (absent := self.absent_controllers()):
            control = scenario.control
            self.say(f"  waiting for controller{'s' if len(absent) > 1 else ''} {', '.join(map(repr, absent))} "
                     f"(control.controllers; none started with --controller): start "
                     f"{'each' if len(absent) > 1 else 'it'} by hand with the control token, or give "
                     f"--controller CMD; without an answer the run stops after control.timeout = "
                     f"{control.timeout:g} s (docs/control.md)")
        self.say("  started " + ", ".join(f"{n} (pid {c.pid})" for n, c in self.children.items()))
        return failure or _watch(scenario, self.plan, self.children, beats, alive, self.progress, self.timeout_s,
                                 self.interrupted, on_death=self.restart, controllers=self.controllers,
                                 stall_s=self.stall_s, job=self.job)

    # ------------------------------------------------------------------ restarts

    def restarts_of(self, name: str) -> list[dict]:
        return [r for r in self.restarts if r["process"] == name]

    def restart(self, name: str, rc: int) -> str | None:
        if "plant" in self.propagators and name in ("plant", "logger"):
            dead = self.children[name]
            if name == "logger":  # its file ends where it was killed: no index, no footer
                partial = partial_path(self.out, self.logger_attempt)
                what = (f"its file {partial} holds what it wrote before, without the index and footer that make it "
                        f"readable as is: `astrodyn recover {partial}` finishes it")
            else:  # the logger finishes the file with what it got
                what = "the recording holds everything up to here"
            return (f"{name} (pid {dead.pid}) {dead.how(rc)}: a closed-loop run is not restarted (its controllers' "
                    f"state lives outside astrodyn); {what}: {dead.last_words(3)}")
        if name == "logger" and rc == DISK_FULL_EXIT:  # a new logger would fail the same way
            dead = self.children[name]
            return (f"logger (pid {dead.pid}) {dead.how(rc)}: not restarted; the recording holds what was written "
                    f"before (free space beside {self.out}, then `astrodyn recover`): {dead.last_words(2)}")
        try:
            return self.restart_logger(rc) if name == "logger" else self.restart_propagator(name, rc)
        except OSError as exc:  # the restart's own files (state, seqs) beside --out: e.g. the disk is full
            dead = self.children[name]
            return (f"{name} (pid {dead.pid}) {dead.how(rc)}: {dead.last_words(2)}; restarting it failed: "
                    f"{exc.strerror or exc}{': ' + str(exc.filename) if exc.filename else ''}")

    def restart_logger(self, rc: int) -> str | None:
        """The logger died mid-run: a new one continues the file (astrodyn.service.supervision).
        A new logger that dies while starting is replaced again, within the restart budget."""
        children, scenario, budget = self.children, self.scenario, self.logger_budget
        for kind in self.propagators:
            children[kind].stop(signal.SIGKILL, timeout=5)
            children[kind].close()
        while True:
            dead = children["logger"]
            how = dead.how(rc)
            if not budget.allow():
                return f"{budget.refusal()}; last: logger (pid {dead.pid}) {how}: {dead.last_words(3)}"
            dead.close()
            wait_until_gone(self.session, scenario.name, "logger")
            attempt = len(self.restarts_of("logger")) + 1
            plan = plan_logger_restart(scenario, self.out, attempt, self.propagators, self.tmpd, self.logger_args,
                                       self.extra_args)
            record = {"process": "logger", "old_pid": dead.pid, "new_pid": None, "why": how, "from_step": plan.steps,
                      "state_from": plan.source}
            self.restarts.append(record)

            def announce(child, dead=dead, how=how, record=record, plan=plan):
                record["new_pid"] = child.pid
                self.say(f"\n  logger (pid {dead.pid}) {how}: restarted (pid {child.pid}), {plan.steps} steps copied "
                         f"from {plan.source or '-'}")
            why = self.start_logger(attempt, plan.logger_args, announce)
            if why is None:
                break
            rc = children["logger"].poll()
            # only a new logger killed by a signal while starting is replaced again; one that exits on its own
            # (its disk is full, its file is in the way) would fail the same way
            if not restarts_after_start_up_death(rc) or self.interrupted["signal"]:
                return f"logger (pid {dead.pid}) {how}; its restart failed: {why}"
        for kind in self.propagators:  # a new file: their events number from 0 again
            self.start_propagator(kind, plan.propagator_args.get(kind, {}), attempt)
        return None

    def restart_propagator(self, kind: str, rc: int) -> str | None:
        """A propagator died: start it again after the last step of its own that the
        logger's file holds; steps it publishes twice are recorded once (first copy)."""
        from astrodyn.recording import RecordingError, load as load_run
        from astrodyn.service.resume import contiguous_steps, propagator_resume_args, state_topics

        scenario = self.scenario
        dead = self.children[kind]
        how = dead.how(rc)
        said = dead.stderr_tail(1) if rc > 0 and dead.stalled_s is None and dead.lost_to_logger is None else ""
        if said:  # it ended with an error of its own: say it with the restart (it was lost before)
            how = f"{how}: {said}"
        if not self.budgets[kind].allow():
            return f"{self.budgets[kind].refusal()}; last: {kind} (pid {dead.pid}) {how}: {dead.last_words(3)}"
        dead.close()
        wait_until_gone(self.session, scenario.name, kind)
        args, step = dict(self.extra_args.get(kind, {})), None
        try:
            run = load_run(partial_path(self.out, self.logger_attempt))  # up to its last flushed chunk
            # the last step before the first hole of any of its channels: its last common step
            # after a crash, and the refill of states lost on the bus (kill_if_lost_to_logger)
            held = contiguous_steps(run, list(state_topics(scenario, kind).values()))
            step = held - 1 if held else None
            if step is not None:
                args = propagator_resume_args(run, scenario, kind, step, self.tmpd)
        except (RecordingError, OSError):
            pass  # nothing flushed yet: start again from the beginning
        earlier = self.restarts_of(kind)
        same = 0  # the restarts just before this one at this step that ended with this error
        for r in reversed(earlier):
            if not said or r.get("from_step") != args.get("--start-step", 0) or r.get("said") != said:
                break
            same += 1
        if same >= SAME_ERROR_RESTARTS:
            # restarted at this step, it ended with the same error each time before recording one more
            # step: deterministic (the same input gives the same failure), a restart only repeats it
            # (deaths further apart than the RestartBudget's 60 s repeated it for ever)
            return (f"{kind} (pid {dead.pid}) {how}, again: {same + 1} times in a row at step "
                    f"{args.get('--start-step', 0)} without recording a step; not restarted again")
        n = len(earlier) + 1
        self.start_propagator(kind, args, n, event_seq=next_event_seq(self.session, scenario.name, kind, n))
        self.restarts.append({"process": kind, "old_pid": dead.pid, "new_pid": self.children[kind].pid, "why": how,
                              "from_step": args.get("--start-step", 0), **({"said": said} if said else {})})
        self.say(f"\n  {kind} (pid {dead.pid}) {how}: restarted (pid {self.children[kind].pid}) at step "
                 f"{args.get('--start-step', 0)}")
        return None

    # ------------------------------------------------------------------ the end

    def finish(self, failure: str | None) -> str | None:
        """Let the logger finish the file (stop it when the run failed); collect every
        process's exit and summary into the result; returns the run's failure, if any."""
        children = self.children
        logger = children["logger"]
        if self.interrupted["signal"] and any(kind in children for kind in self.propagators):
            # at once: the stop can take seconds, and a silent wait invites a kill
            print(f"\nastrodyn run: stopping ({self.interrupted['signal']}): the processes end, then the logger "
                  f"finishes the file (waiting up to {INTERRUPTED_LOGGER_WAIT_S:g} s for their last messages; "
                  f"a second Ctrl-C or SIGTERM finishes it at once)", file=sys.stderr, flush=True)
        if failure:
            for kind in self.propagators:
                if kind in children:
                    children[kind].stop()
            if self.interrupted["signal"] and any(kind in children for kind in self.propagators):
                # clean stops: the logger ends once it holds their last states (none to wait for
                # when the run was stopped before it started them)
                count = self.interrupted["count"]
                deadline = time.monotonic() + INTERRUPTED_LOGGER_WAIT_S
                while logger.poll() is None and time.monotonic() < deadline and self.interrupted["count"] == count:
                    if all(children[k].poll() is not None for k in self.propagators if k in children):
                        deadline = min(deadline, time.monotonic() + INTERRUPTED_DRAIN_S)  # all gone: drain, finish
                    time.sleep(0.05)
            logger.stop(signal.SIGTERM, timeout=30)  # it finishes the file with what it holds
        else:
            try:
                logger.proc.wait(timeout=60)
            except subprocess.TimeoutExpired:
                failure = "logger did not finish within 60 s of the end of the run; stopped it (file finished)"
                logger.stop(signal.SIGTERM, timeout=30)
        self.finish_standbys(failure)
        for ch in self.controllers.values():  # the run is over: controllers go (by PID)
            ch.stop(signal.SIGTERM, timeout=5)
        for name, ch in [*children.items(), *((c.name, c) for c in self.controllers.values())]:
            self.result["processes"][name] = {"pid": ch.pid, "exit": ch.poll(), "summary": ch.summary(),
                                              "stderr": ch.stderr_tail()}
        if logger.poll() not in (0, None) and not failure:
            failure = f"logger exited with status {logger.poll()}: {logger.last_words(5)}"
        return failure


def recorded_to_the_end(log: dict) -> bool:
    """Whether the logger's summary ``log`` says the run is recorded to its end: every
    expected state is in the file (``complete``) and every process ended at the end of the
    scene, none stopped early (an interrupted run whose propagators had finished)."""
    return log.get("complete") is True and not log.get("stopped_early") and bool(log.get("ended"))


def _fail(result: dict, why: str) -> None:
    """Add ``why`` to the run's failure (the run fails: exit 1)."""
    result["failure"] = f"{result['failure']}; {why}" if result.get("failure") else why


def _name_the_recording(written: str | None, out: Path, result: dict, files: dict[int, LoggerFile],
                        attempt: int) -> str | None:
    """Give the finished file its name: the logger left it as ``NAME.partial.mcap``; a run
    that succeeded renames it over ``out`` (an earlier recording of that name is replaced
    only now), a failed or interrupted one leaves it there for ``astrodyn recover``
    (docs/reliability.md).  Returns the path that holds the recording (None: not known).

    ``files`` are the files this run's loggers created, by attempt (``attempt``: the
    logger that ran last): a path is renamed or removed only while it still names such a
    file, never a file another run (or the user) put there.  A recording no longer where
    its logger wrote it (its directory renamed or removed, the file moved) fails the run,
    saying where it is when that can be told; nothing is renamed or removed then."""
    from astrodyn.recording.writer import fsync_directory

    mine = files.get(attempt)
    if mine is None and written is not None and Path(written) == Path(partial_path(out, attempt)):
        # the logger's own summary names the file it created (O_EXCL): its file was not there yet
        # when its readiness was seen (a liveliness token forged in its name came first)
        mine = files[attempt] = LoggerFile.of_ready_logger(written)
        if mine is None:
            del files[attempt]
    if mine is not None and not mine.here():
        where = mine.where()
        _fail(result, f"the recording is not at {mine.path} (nor at {out}): " + (
            f"it was moved while the run recorded and is now {where}; nothing was renamed or removed "
            f"(`astrodyn recover {where}` finishes it)" if where else
            "it was moved or removed while the run recorded (its directory renamed or deleted?) and cannot be found"))
        return where
    if written is None:  # the logger died: its partial file (no footer) is all there is
        return mine.path if mine is not None else None
    if result.get("failure") or Path(written) == Path(out):
        return written
    if mine is None or Path(mine.path) != Path(written):
        _fail(result, f"the logger says its recording is {written}, which is not the file this run's logger created; "
                      f"{out} is not replaced")
        return written if os.path.exists(written) else None
    try:
        os.replace(written, out)
    except OSError as exc:
        _fail(result, f"cannot name the recording {out}: {exc.strerror or exc}; it stays at {written}")
        return written if mine.here() else None
    fsync_directory(out)
    for n, dead in files.items():  # dead loggers' files (copied by their successors): only if still theirs
        if n != attempt:
            dead.unlink_if_here()
    return str(out)


def progress_line(last: dict, propagators: list[str], duration: float, dt: float, last_msgs: int) -> str:
    """The progress line of ``run``: the simulated time every propagator has passed (the
    slowest one's, from their heartbeats ``last``), the messages the logger holds and its
    rate over the last ``dt`` s; a propagator that has not sent its first state yet is
    named as compiling (a first run compiles the numeric kernels; numba caches them)."""
    busy = {k: last[k]["busy"] for k in propagators if isinstance(last.get(k, {}).get("busy"), dict)}
    preparing = [k for k in propagators if k not in busy and (last.get(k, {}).get("preparing") or k not in last)]
    ts = [float(last[k].get("t", 0.0)) for k in propagators if k in last]
    t_min = min(ts) if ts else 0.0
    msgs = last.get("logger", {}).get("messages", 0)
    rate = (msgs - last_msgs) / max(1e-9, dt)
    line = (f"  sim t {t_min:10.1f} / {duration:.1f} s  ({100 * t_min / max(duration, 1e-300):5.1f} %)"
            f"  logged {msgs:>9d}  {rate:9.0f} msg/s")
    if preparing:
        how = "compiled in every run: no writable cache" if kernels_uncached() else \
            "compiled on the first run only, cached afterwards"
        line += f"  [{', '.join(preparing)}: loading numeric kernels ({how})]"
    for kind, b in busy.items():  # a long engine call, beating in parts: what it does and how far it got
        with contextlib.suppress(TypeError, ValueError):
            what = str(b.get("what", "computing")).removeprefix(f"{kind}: ")[:80]
            line += f"  [{kind}: {what}: sim t {float(b['t']):.6g} of {float(b['to']):.6g} s]"
    return line


#: Wall seconds ``run`` keeps watching after every propagator exited 0 while the logger
#: runs: long enough for the logger to say one of them never reached it (it lists a
#: process it has not heard for its 5 s stall time), so that one is restarted
#: (:meth:`astrodyn.service.children.Child.ended_cut_off_from_logger`).  A logger that
#: finishes ends the wait at once.
END_REACH_S = 8.0


def _watch(scenario: Scenario, p, children: dict, beats, alive, progress: bool, timeout_s: float | None,
           interrupted: dict | None = None, on_death=None, controllers: dict | None = None,
           stall_s: float | None = None, job: JobControl | None = None) -> str | None:
    """Wait for the propagators to finish; return a failure description or None.

    ``on_death(name, rc)``: called when a child dies before the end; it restarts it (and
    for the logger the propagators too) in ``children`` (:mod:`astrodyn.service.supervision`)
    and returns None, or a failure description when it cannot.  ``controllers``: the closed
    loop's controller processes; in lockstep one that exits before the plant is a failure
    named after it (it would never answer again).  ``stall_s``: a child silent that long
    is killed first, so that it takes the same path (:meth:`Child.kill_if_stalled`).
    ``job``: the run's :class:`JobControl`; time spent suspended (Ctrl-Z) is not counted
    against ``timeout_s``."""
    lockstep = scenario.control is not None and scenario.control.mode == "lockstep"
    propagators = [k for k in children if k != "logger"]
    duration = (scenario.n_steps - 1) / scenario.rate if scenario.n_steps else 0.0  # last output instant, no array
    printer = Progress(enabled=progress)
    t0 = time.monotonic()
    last_msgs, last_time = 0, t0
    ended_at = None  # when every propagator had exited 0
    while True:
        now = time.monotonic()
        beats.poll()
        alive.poll()
        for name, ch in children.items():
            ch.kill_if_stalled(beats, stall_s, now)
            if name in propagators and name != "plant":  # (a plant is not restarted: docs/control.md)
                ch.kill_if_lost_to_logger(beats)
        for name, ch in list(children.items()):
            rc = ch.poll()
            ended = name in propagators and rc == MODEL_ENDED_EXIT  # not restarted: it would end there again
            # exit 0 on a stop signal the run did not send (kill PID: the process stopped cleanly before
            # the end) fails the run, which keeps its partial file (--resume goes on); not a logger
            # that held every expected message by then (it finished its file whole)
            if (ch.outside_stop_signal(rc) is not None and not (interrupted and interrupted["signal"])
                    and not (name == "logger" and (ch.summary() or {}).get("complete") is True)):
                how_far = beats.last.get(name, {}).get("t")
                where = f" at sim t {how_far:.6g} s of {duration:.6g} s" if how_far is not None else ""
                return (f"process {name} (pid {ch.pid}) {ch.how(rc)}{where}: a process stopped before the end of the "
                        f"run stops the run (`astrodyn run --resume` goes on from the recording)")
            died = rc not in (None, 0)
            if died and on_death is not None and not ended and not (interrupted and interrupted["signal"]):
                failure = on_death(name, rc)
                if failure:
                    return failure
                break  # children were replaced: look again
            if rc is not None and (name == "logger" or died):
                if name == "logger" and not died:
                    # the logger ends by itself once it holds everything: give the
                    # propagators time to exit after their end-of-run event (a propagator
                    # waits up to LOGGED_WAIT_S for the logger's receipt; on loaded cores
                    # its exit can take seconds)
                    deadline = time.monotonic() + LOGGED_WAIT_S + 5.0
                    while time.monotonic() < deadline and any(children[k].poll() is None for k in propagators):
                        time.sleep(0.05)
                    if all(children[k].poll() == 0 for k in propagators):
                        return None
                    failed = [k for k in propagators if children[k].poll() not in (0, None)]
                    if not failed:
                        late = [k for k in propagators if children[k].poll() is None]
                        return (f"process {late[0]} (pid {children[late[0]].pid}) did not exit within "
                                f"{LOGGED_WAIT_S + 5.0:g} s after the logger finished the recording")
                    name, ch = failed[0], children[failed[0]]  # the logger finished the file after it failed
                    rc = ch.poll()
                how_far = beats.last.get(name, {}).get("t")
                where = f", sim t reached {how_far:.6g} s of {duration:.6g} s" if how_far is not None else ""
                bodies = [b.name for b in p.bodies if (b.orbit_model if name == "orbit" else b.attitude_model)]
                who = f" (bodies: {', '.join(bodies[:5])}{', ...' if len(bodies) > 5 else ''})" if name != "logger" else ""
                return f"process {name} (pid {ch.pid}) {ch.how(rc)}{who}{where}: {ch.last_words(3)}"
        if all(children[k].poll() == 0 for k in propagators):
            cut_off = [k for k in propagators if k != "plant" and children["logger"].poll() is None
                       and on_death is not None and children[k].ended_cut_off_from_logger(beats)]
            for name in cut_off:  # restarted: each publishes its lost states again
                failure = on_death(name, 0)
                if failure:
                    return failure
            if cut_off:
                continue
            if children["logger"].poll() is not None or ended_at is not None and now - ended_at > END_REACH_S:
                return None
            ended_at = now if ended_at is None else ended_at
        for cname, ch in (controllers or {}).items():
            rc = ch.poll()
            if rc is not None and lockstep and "plant" in children and children["plant"].poll() is None:
                deadline = time.monotonic() + 3.0  # the plant may be ending with its own reason (a timeout)
                while time.monotonic() < deadline and children["plant"].poll() is None:
                    time.sleep(0.05)
                beats.poll()
                if children["plant"].poll() is not None or beats.last.get("plant", {}).get("done"):
                    break  # look again: the plant's exit says what happened (it may first wait for the logger)
                how = ch.how(rc)
                t = beats.last.get("plant", {}).get("t")
                return (f"controller {cname} (pid {ch.pid}) {how} before the end of the run"
                        f"{f' (sim t {t:.6g} s)' if t is not None else ''}: {ch.last_words(3)}")
        if printer.show(lambda dt=now - last_time, n=last_msgs: progress_line(beats.last, propagators, duration, dt, n),
                        now):
            last_msgs, last_time = beats.last.get("logger", {}).get("messages", 0), now
        if interrupted is not None and interrupted["signal"]:
            ts = [t for k in propagators if (t := beats.last.get(k, {}).get("t")) is not None]  # those heard from
            ts = ts or [beats.last.get("logger", {}).get("t", 0.0)]  # (a propagator that has ended beats no more)
            return f"interrupted by {interrupted['signal']} at sim t {min(ts):.6g} s of {duration:.6g} s"
        if timeout_s is not None and now - t0 - (job.suspended_s if job is not None else 0.0) > timeout_s:
            return f"timeout: the run took longer than {timeout_s} s"
        time.sleep(0.05)


def main(argv: list[str] | None = None, prog: str = "astrodyn run") -> int:
    """``astrodyn run`` (``prog``: the command the user typed, in its messages: ``astrodyn demo`` runs through here)."""
    ap = argparse.ArgumentParser(prog=prog, description="Run a scenario headless into an MCAP file.")
    ap.add_argument("config", help="scenario TOML file (see configs/)")
    ap.add_argument("--out", help="MCAP file to write (default: the config's [output] path, else <scenario>.mcap)")
    ap.add_argument("--cross-check", action="store_true", help="run REBOUND IAS15 alongside every orbit; report the difference")
    ap.add_argument("--connect", action="append", metavar="ENDPOINT", help="also connect to this Zenoh endpoint (router)")
    ap.add_argument("--zenoh-config", metavar="FILE", help="Zenoh JSON5 config every process starts from (TLS, "
                    "access control; docs/security.md)")
    ap.add_argument("--timeout", type=wall_seconds, default=None, help="fail if the run takes longer than this many wall seconds")
    ap.add_argument("--quiet", action="store_true", help="no progress line")
    ap.add_argument("--json", metavar="FILE", help="write the full result (per-body summary included) as JSON")
    ap.add_argument("--resume", metavar="MCAP", help="continue the scenario from the last complete step recorded in "
                    "this file: its states are copied into --out (which must differ) and the run goes on from there")
    ap.add_argument("--force", action="store_true",
                    help="start even when the expected recording does not fit on the output disk")
    ap.add_argument("--controller", action="append", default=None, metavar="CMD",
                    help="closed loop: start this controller program (split like a shell command line, run without "
                         "a shell) under the run, named after control.controllers in order; repeatable; docs/control.md")
    ap.add_argument("--commands", metavar="REC.mcap", default=None,
                    help="closed loop: re-simulate from the commands recorded in REC (no controllers): the states "
                         "come out bit for bit as recorded")
    ap.add_argument("--loggers", type=int, default=1, metavar="N",
                    help="loggers recording the run (default 1, at most 8): the 2nd ... Nth are hot standbys, each "
                         "writing a complete file of its own, NAME.logger-2.mcap, ... (docs/reliability.md)")
    add_stall_argument(ap)
    ap.add_argument("--tolerate-rejected", action="store_true",
                    help="exit 0 even when the logger rejected messages that did not come from this run's own "
                         "processes (default: exit 3, the record was attacked; docs/security.md)")
    args = ap.parse_args(argv)
    # the resume work directory exists only for --resume: a run killed by SIGKILL leaves nothing in /tmp
    work_dir = tempfile.TemporaryDirectory(prefix="astrodyn-resume-") if args.resume else contextlib.nullcontext("")
    with work_dir as work:
        try:
            if args.out == "":
                raise ScenarioError("--out: expected a file path, got an empty string")
            if args.resume == "":  # not "no --resume": a path that came out empty (a shell variable)
                raise ScenarioError("--resume: expected the MCAP recording to continue, got an empty string")
            scenario = load(args.config)
            out = Path(args.out) if args.out else (scenario.output_path or Path(f"{scenario.name}.mcap"))
            if not 1 <= args.loggers <= MAX_LOGGERS:
                raise ScenarioError(f"--loggers: expected 1 <= N <= {MAX_LOGGERS}, got {args.loggers}")
            inputs = (args.config, args.resume, args.zenoh_config, args.json, args.commands)
            outputs = [out, *(Path(standby_path(out, k)) for k in range(2, args.loggers + 1))]
            for path in outputs:
                checked_output_path(path, inputs)
                if problem := series_start_problem(path, "run"):  # the only file of a session, or a series' first part
                    raise ScenarioError(f"--out {str(path)[:200]}: {problem}")
            if args.json is not None:
                check_json_path(Path(args.json), (args.config, args.resume, args.zenoh_config, args.commands, *outputs))
            zenoh_config = check_bus_flags(args.connect, args.zenoh_config)
            resume = resume_plan(Path(args.resume), scenario, out, Path(work)) if args.resume else {}
            replayed = check_closed_loop_arguments(scenario, args.controller or [], args.commands, out)
            check_scenario_free(scenario.name, args.connect, zenoh_config)
        except ScenarioError as exc:
            print(f"{prog}: {exc}", file=sys.stderr)
            return 2
        the_plan = make_plan(scenario, cross_check_all=args.cross_check)
        for w in filter(None, [*the_plan.warnings, zenoh_config and zenoh_config.warning()]):
            print(f"{prog}: warning: {w}", file=sys.stderr)
        free = shutil.disk_usage(out.resolve().parent).free
        if the_plan.estimated_file_bytes > free and not args.force:
            print(f"{prog}: the recording needs about {the_plan.estimated_file_bytes / 1e6:.4g} MB and "
                  f"{out.resolve().parent} has {free / 1e6:.4g} MB free; shorten the run, lower the rate, choose "
                  f"another --out, or pass --force", file=sys.stderr)
            return 2
        print(the_plan.text(), file=sys.stderr)
        for note in command_recording_notes(replayed, scenario) if replayed else ():
            print(f"{prog}: {note}", file=sys.stderr)
        if resume:
            print(f"  resuming from {args.resume} at step {resume['step']} (t = {resume['t']:.6g} s)", file=sys.stderr)
        try:
            result = run_scenario(scenario, out, cross_check=args.cross_check, connect=args.connect,
                                  progress=not args.quiet, timeout_s=args.timeout, extra_args=resume.get("extra_args"),
                                  logger_args=resume.get("logger_args"), zenoh_config=zenoh_config,
                                  controllers=args.controller, commands=Path(args.commands) if args.commands else None,
                                  loggers=args.loggers, stall_s=args.stall_timeout or None)
        except (StartError, bus.BusError) as exc:  # nothing was started (the hub's session did not open)
            print(f"{prog}: error: {exc}", file=sys.stderr)
            return 1
    print("", file=sys.stderr)
    rows = None
    recording = result.get("file")
    if recording and Path(recording).exists():  # the summary measures what the file holds, not what was sent
        if Path(recording) != out:
            print(f"{prog}: the recording stays at {recording} (the run did not succeed, so {out} is not "
                  f"replaced); `astrodyn recover {recording}` gives it its name", file=sys.stderr)
        try:
            rows = file_summary(Path(recording), scenario)
        except Exception as exc:  # the file is still there; say why the summary is missing
            print(f"{prog}: could not read back {recording} for the summary: {exc}", file=sys.stderr)
    if rows is None:
        rows = propagator_rows(result, scenario)
    rows = rows or []
    result["bodies"] = rows
    result["propagator_bodies"] = propagator_rows(result, scenario)
    if replayed:  # what of the --commands recording was re-simulated (command_recording_notes)
        result["commands_recording"] = replayed
    # the summary's header names the file that holds the recording (NAME.partial.mcap of a failed run), not --out
    print_summary({**result, "out": recording} if recording and Path(recording).exists() else result, rows, scenario)
    for warning in result.get("warnings", []):
        print(f"{prog}: warning: {warning}", file=sys.stderr)
    for name, standby in (result.get("standbys") or {}).items():
        if standby.get("exit") == 0:
            print(f"  standby {name}: {standby['file']}", file=sys.stderr)
    if args.json:
        try:
            Path(args.json).write_text(json.dumps(result, indent=1, default=str))
        except OSError as exc:
            with contextlib.suppress(OSError):  # not a cut JSON file
                Path(args.json).unlink()
            print(f"{prog}: --json {args.json}: cannot write: {exc.strerror or exc} (the run's recording: "
                  f"{result.get('file')})", file=sys.stderr)
            return 1
    plant = (result.get("processes", {}).get("plant") or {}).get("summary") or {}
    if plant:  # also when the run failed: a refused command may be why
        print(f"{prog}: {closed_loop_line(plant, replayed)}", file=sys.stderr)
    if result.get("failure"):
        print(f"{prog}: FAILED: {result['failure']}", file=sys.stderr)
        if result.get("interrupted"):  # shell convention: 128 + signal number
            return 128 + int(signal.Signals[result["interrupted"]])
        return 1
    attack = attack_report(result.get("logger"), plant)
    if attack:
        print(f"{prog}: ATTACKED: {attack}", file=sys.stderr)
        if not args.tolerate_rejected:
            return EXIT_REJECTED
    if result.get("complete_before_signal"):  # finished as a run that succeeded; the exit still says the signal
        print(f"{prog}: {result['interrupted']} came after every state was recorded: the recording is complete "
              f"({result.get('file')})", file=sys.stderr)
        return 128 + int(signal.Signals[result["interrupted"]])
    return 0


#: Controllers named with their errors in the end line of a closed-loop run (the rest are counted).
MAX_AUTHORS_NAMED = 3


def closed_loop_line(plant: dict, replayed: dict | None = None) -> str:
    """The end line of a closed-loop run from the plant's summary ``plant``: commands applied,
    refused, late, still waiting for their time when the run ended, the controllers'
    malformed messages (their errors, not an attack: :func:`attack_report`), with the first
    refusals and controller errors; and for a ``--commands`` re-simulation (``replayed``,
    :func:`check_command_recording`) what of the recording it did not re-simulate."""
    line = (f"closed loop: {plant.get('applied', 0)} commands applied, {plant.get('refused', 0)} refused, "
            f"{plant.get('late', 0)} late")
    if plant.get("pending"):
        line += f", {plant['pending']} still waiting for their time at the end (never applied)"
    errors = plant.get("controller_errors_by_author") or {}
    if errors:
        named = sorted(errors.items())[:MAX_AUTHORS_NAMED]
        line += ", " + ", ".join(f"{sum(counts.values())} rejected from controller {name} ("
                                 + ", ".join(f"{n} {reason}" for reason, n in sorted(counts.items())) + ")"
                                 for name, counts in named)
        if len(errors) > len(named):
            rest = sum(sum(counts.values()) for _, counts in sorted(errors.items())[MAX_AUTHORS_NAMED:])
            line += f", {rest} from {len(errors) - len(named)} other senders"
    if replayed and replayed.get("held_after"):
        line += (f"; the recording ended at step {replayed['last_step']}: the commands last applied were held "
                 f"from there to step {replayed['config_last_step']}")
    if replayed and replayed.get("commands_after_end"):
        line += f"; {replayed['commands_after_end']} recorded commands after the config's duration not applied"
    line += "".join(f"\n  refused: {r}" for r in plant.get("refusals", [])[:5])
    if errors:
        line += "".join(f"\n  controller error: {e}" for e in plant.get("controller_error_examples", [])[:5])
    return line


def attack_report(logger: dict | None, plant: dict | None) -> str | None:
    """What the logger's and the plant's summaries say was rejected as not the run's own
    (forged, unsigned or replayed samples; forged commands and answers), for the
    ``ATTACKED`` line of ``run`` and ``serve`` (docs/security.md); None when nothing was.
    The line names only the processes whose summary counts a rejection: a scene without
    ``[control]`` has no plant (``plant`` None or empty), and then the line is the logger's
    alone (before, it said "the logger and the plant" in every scene)."""
    by_logger = {reason: n for reason, n in ((logger or {}).get("rejected") or {}).items() if n}
    by_plant = {f"command {reason}": n  # forged commands and answers, dropped by the plant
                for reason, n in ((plant or {}).get("rejected") or {}).items() if n}
    rejected = dict(by_logger)
    for reason, n in by_plant.items():
        rejected[reason] = rejected.get(reason, 0) + n
    if not rejected:
        return None
    who = " and ".join(name for name, counts in (("the logger", by_logger), ("the plant", by_plant)) if counts)
    total = sum(rejected.values())
    why = ", ".join(f"{n} {reason}" for reason, n in sorted(rejected.items()))
    senders = (logger or {}).get("rejected_by_sender") or {}
    from_whom = f"; senders: {', '.join(f'{s} x{n}' for s, n in senders.items())}" if senders else ""
    return (f"{who} rejected {total} messages that were not this run's own ({why}{from_whom}); the recording "
            f"holds only the run's authenticated states (counts in its 'rejected' metadata record)")


def check_bus_flags(connect: list[str] | None, zenoh_config: str | None) -> bus.ZenohConfigText | None:
    """``--connect`` endpoints (:func:`astrodyn.bus.check_endpoint`: protocol, host, port
    1..65535) and the ``--zenoh-config`` file, checked before anything starts (a bad endpoint
    made every child fail at start-up, or was accepted and never connected); ScenarioError
    naming the flag.  Returns the Zenoh config as read, once, and checked
    (:func:`astrodyn.bus.read_zenoh_config`: a regular file of at most
    :data:`astrodyn.bus.ZENOH_CONFIG_MAX_BYTES` that Zenoh parses, without an ``id`` every
    process would share): the text every process of the run is given a copy of (None
    without the flag); its :meth:`~astrodyn.bus.ZenohConfigText.warning` is for the caller
    to print."""
    text = None
    if zenoh_config is not None:
        try:
            text = bus.read_zenoh_config(zenoh_config, shared=True)
        except bus.BusError as exc:
            raise ScenarioError(str(exc)) from None
    if connect:
        try:
            bus.make_config(mode="peer", connect=connect)
        except bus.BusError as exc:  # "connect: expected Zenoh endpoints like ..."
            raise ScenarioError(f"--{exc}") from None
    return text


#: Seconds ``run`` / ``serve`` wait for the routers of ``--connect`` to list the processes of
#: their scenario name (:func:`check_scenario_free`).
SCENARIO_CHECK_WAIT_S = 2.0


def check_scenario_free(scenario: str, connect: list[str] | None, zenoh_config: bus.ZenohConfigText | None) -> None:
    """Refuse to start a run of ``scenario`` on a bus where one is running (ScenarioError).

    Only with ``--connect``: without it the run's bus is its own hub, on a port just picked.
    Every key of a run is ``astrodyn/<scenario>/...``, so two runs of one scenario name on
    one router share them; each signs with its own secret, so each logger rejects the
    other's samples and both runs end ATTACKED, exit 3 (docs/multihost.md).  A short client
    session through the ``--connect`` endpoints (with the run's ``--zenoh-config``: TLS,
    access control) lists the liveliness tokens ``astrodyn/<scenario>/@alive/*`` there.  An
    endpoint that does not answer now is left to the run's own processes (they keep
    trying); two runs started in the same second may both pass (each still ends
    ATTACKED)."""
    if not connect:
        return
    with tempfile.TemporaryDirectory(prefix="astrodyn-check-") as work:
        try:
            config = zenoh_config.write(work) if zenoh_config is not None else None
            with bus.open_session(connect=connect, mode="client", config_file=config) as session:
                others = bus.alive_processes(session, scenario, timeout_s=SCENARIO_CHECK_WAIT_S)
        except (bus.BusError, OSError):
            return
    if others:
        raise ScenarioError(
            f"scenario {scenario!r} is already running on the bus of --connect {' '.join(connect)}: its processes "
            f"{', '.join(sorted(others))} are alive there (astrodyn/{scenario}/@alive/*); two runs of one scenario "
            f"name on one bus share every key and both end ATTACKED (docs/multihost.md): give this run its own "
            f"[scenario] name, or stop the other one first")


def checked_output_path(path: Path, inputs: tuple) -> None:
    """:func:`check_output_path`, with the operating system's refusals (a name too long, a
    file where a directory should be) as a ScenarioError naming ``--out``."""
    try:
        check_output_path(path, inputs=inputs)
    except OSError as exc:
        raise ScenarioError(f"--out {str(path)[:200]}: expected a usable file path, got {exc.strerror or exc}") from None


def check_json_path(path: Path, inputs: tuple) -> None:
    """``--json FILE``: written when the run ends, so checked before it starts: a file in an
    existing, writable directory, none of the run's inputs or outputs, and never an existing
    file other than an earlier result (a JSON object); ScenarioError naming ``--json``."""
    shown = str(path)[:200]
    try:
        parent = path.resolve().parent
        for given in inputs:
            if given is not None and path.resolve() == Path(given).resolve():
                raise ScenarioError(f"--json {shown}: names a file of the run ({given}); expected a new .json path")
        if not parent.is_dir() or not os.access(parent, os.W_OK):
            raise ScenarioError(f"--json {shown}: expected a file in an existing, writable directory, got {parent}")
        if path.is_dir():
            raise ScenarioError(f"--json {shown}: expected a file path, got a directory")
        if problem := regular_file_problem(path, missing_ok=True):  # a FIFO would block the read below
            raise ScenarioError(f"--json {shown}: {problem}; it is never written to")
        if path.exists():
            with open(path, "rb") as f:
                head = f.read(64).lstrip()
            if not head.startswith(b"{"):
                raise ScenarioError(f"--json {shown}: exists and is not an earlier JSON result; it is never "
                                    f"overwritten (expected a new path or an earlier result to replace)")
    except OSError as exc:
        raise ScenarioError(f"--json {shown}: expected a usable file path, got {exc.strerror or exc}") from None


def check_closed_loop_arguments(scenario: Scenario, controllers: list[str], commands: str | None,
                                out: Path) -> dict | None:
    """``--controller`` / ``--commands`` against the scene; ScenarioError naming the option.
    Returns what :func:`check_command_recording` says of the ``--commands`` recording (None without)."""
    control = scenario.control
    if (controllers or commands) and control is None:
        opt = "--controller" if controllers else "--commands"
        raise ScenarioError(f"{opt}: expected a closed-loop scene (a [control] table; docs/control.md), "
                            f"{scenario.source} has none")
    if controllers and commands:
        raise ScenarioError("--commands: expected either --commands (re-simulate) or --controller, not both")
    if controllers and len(controllers) > len(control.controllers):
        raise ScenarioError(f"--controller: expected at most {len(control.controllers)} (one per name in "
                            f"control.controllers = {list(control.controllers)}), got {len(controllers)}")
    for cmd in controllers:
        try:
            argv = shlex.split(cmd)
        except ValueError as exc:
            raise ScenarioError(f"--controller {cmd!r}: {exc}") from None
        if not argv:
            raise ScenarioError("--controller: expected a command line, got an empty string")
    if commands is not None:
        return check_command_recording(scenario, Path(commands), out)
    return None


def check_command_recording(scenario: Scenario, path: Path, out: Path) -> dict:
    """``--commands REC``: refuse (ScenarioError naming the flag and what is wrong) a file
    that is not a regular file (a FIFO, a device, a directory: as ``--resume`` says it), not
    a recording of this scenario and config
    (:func:`astrodyn.scenario.recorded.config_difference`; the duration may differ), one
    whose ``scenario`` metadata records differ (:func:`recorded_config_conflict`), a later
    part of a rolled series (part k >= 1 of its ``recording`` record, even one whose first
    step is 0: the part before may hold commands and fault events of that step; the
    refusal names the part and points to ``astrodyn merge``), a merge that leaves a part
    out (:func:`merged_missing_parts`), one that does not start at
    step 0 (its first actuator state is at a later step: a merge of later parts, which
    names them, :func:`merged_later_parts`; this is judged before the commands are, so such
    a file is refused for what it is, not for a command of the part before it, which an
    actuator state names), one that holds no applied command
    (saying when the file is cut short or damaged, or is the first part of a series that
    goes on: :func:`series_goes_on`), or one the plant could not re-simulate
    (:func:`read_command_recording`'s checks).  Returns what the run says about it
    (:func:`command_recording_notes`): where the recording ends against the config's last
    step, and what it holds past the config's duration.  The commands are checked without
    being kept (the plant reads them again)."""
    from astrodyn.recording import RecordingError
    from astrodyn.recording.stream import open_stream
    from astrodyn.service.plant import read_command_recording, recorded_faults

    shown = str(path)[:200]
    if path.resolve() == out.resolve():
        raise ScenarioError(f"--commands {shown}: expected a recording other than --out")
    if problem := regular_file_problem(path):  # (open_stream reads a regular file only, and says so too)
        raise ScenarioError(f"--commands {shown}: cannot open: {problem}")

    def refused(exc: Exception) -> ScenarioError:  # the reader's words, without the path they start with
        why = str(exc).removeprefix(f"{path}: ")
        return ScenarioError(f"--commands {shown}: expected an MCAP recording of scenario {scenario.name!r}: {why}")

    def late_start(step: int) -> ScenarioError:  # steps 0 .. step - 1 would run without their commands
        merged = merged_later_parts(path, metadata)
        what = (f"{merged}" if merged else "a later part of a rolled recording, or a file that lost its start")
        return ScenarioError(f"--commands {shown}: expected a recording from the run's start (step 0, where the "
                             f"re-simulation starts), got one whose first actuator state is at step {step} "
                             f"(t = {step / scenario.rate:.6g} s): {what}; {series_merge_advice(path, metadata)}")

    try:  # read here, so a foreign, damaged or empty file is refused before anything starts
        with open_stream(path) as stream:  # (its index: the metadata records come first)
            recorded, metadata, cut = stream.metadata.get("scenario"), dict(stream.metadata), stream.truncated
            conflict = recorded_config_conflict(stream, scenario)
        if conflict is not None:
            raise ScenarioError(f"--commands {shown}: {conflict}")
        problem = config_difference(recorded, scenario, ignore=DURATION_PATHS)
        if problem is not None and recorded is not None:  # another config's commands would not fit this one
            raise ScenarioError(f"--commands {shown}: expected a recording of this scenario and config "
                                f"({scenario.name!r}; its duration may differ), got {problem}")
        part = recorded_part(metadata)
        if part:  # the part before holds its run's start: its first steps, or commands and faults before them
            raise ScenarioError(f"--commands {shown}: expected a recording from the run's start (step 0, where the "
                                f"re-simulation starts), got part {part} of a rolled recording (its `recording` "
                                f"metadata record): the run's start is in the earlier parts; {merge_advice(path, part)}")
        # a later start first: the reader would name an actuator state of it whose command is
        # in the part before
        if (first := first_actuator_step(path, scenario)) is not None and first > 0:
            raise late_start(first)
        if gap := merged_missing_parts(metadata):  # (merge --allow-missing-parts): the same, within
            raise ScenarioError(f"--commands {shown}: expected a whole recording of the run, got {gap}: the steps "
                                f"recorded there would be re-simulated without their commands; "
                                f"{series_merge_advice(path, metadata)}")
        found = read_command_recording(path, scenario, keep=False)
        faults = recorded_faults(path, scenario)
    except (RecordingError, OSError) as exc:
        raise refused(exc) from None
    except ValueError as exc:
        if isinstance(exc, ScenarioError):
            raise
        raise refused(exc) from None
    if found.first_step > 0:  # steps 0 .. first_step - 1 would run without their commands
        raise late_start(found.first_step)
    series = series_goes_on(path, metadata, cut)
    if not found.applied:
        damaged = (f"; the file is cut short or damaged ({found.damage[:300]}): what it holds past that cannot be "
                   f"read (`astrodyn recover {shown}` saves what can be)") if found.damage else ""
        rest = f"; {series}: {merge_advice(path, part)}" if series else ""
        raise ScenarioError(f"--commands {shown}: expected applied commands of scenario {scenario.name!r} "
                            f"(actuator states naming them), found none: nothing to re-simulate{damaged}{rest}")
    if problem is not None:  # commands, but no scenario metadata to check them against
        raise ScenarioError(f"--commands {shown}: expected a recording of this scenario and config "
                            f"({scenario.name!r}), got {problem}")
    end = scenario.n_steps - 1
    return {"file": str(path), "applied": found.applied, "last_step": found.last_step,
            "t_last": found.last_step / scenario.rate, "config_last_step": end,
            "held_after": found.last_step < end, "commands_after_end": found.after_end,
            "faults_after_end": sum(1 for f in faults if f.t > end / scenario.rate * (1 + 1e-12)),
            "damage": found.damage, "series_goes_on": series,
            "series_advice": merge_advice(path, part) if series else None}


def recorded_config_conflict(stream, scenario: Scenario) -> str | None:
    """What to say (after the flag and the file) of a recording (an open
    :class:`astrodyn.recording.stream.McapStream`) whose ``scenario`` metadata records
    differ, naming both, each against ``scenario``; None when it holds at most one (or
    copies of one).  ``--commands`` and ``--resume`` refuse such a file: which record tells
    the config it was made with cannot be told (readers differ: serve's
    :func:`astrodyn.recording.reader.recorded_metadata` takes the first,
    :func:`astrodyn.recording.load` the last), and astrodyn writes one per file."""
    both = stream.metadata_conflict("scenario")
    if both is None:
        return None
    named = [config_difference(record, scenario) or "this config" for record in both]
    return (f"expected one `scenario` metadata record (the config the recording was made with), got records that "
            f"differ: the first is ({named[0]}), another is ({named[1]}); which one the recording was made with "
            f"cannot be told")


def recorded_part(metadata: dict) -> int | None:
    """The part number a file's ``recording`` metadata record gives (0 for a run's first or
    only file, k for ``NAME-000k.mcap`` of a rolled series), None when it has none, or is a
    merge of several files (``merged_from``: its ``recording`` record is one input's; the
    parts it holds: :func:`merged_later_parts`)."""
    from astrodyn.recording.merge import recorded_parts

    parts = [] if "merged_from" in metadata else recorded_parts(metadata)
    return parts[0][0] if parts else None


def merged_later_parts(path: Path, metadata: dict) -> str | None:
    """What the merged recording ``path`` (its metadata records) is when it does not start
    at part 0 of its rolled series: ``a merge of parts 2-3 of a rolled recording (its
    `merged_from` metadata record; its first input, d-0002.mcap, is part 2): the steps from 0
    are in parts 0 .. 1``; None for any other file (not a merge, a merge from part 0, or one
    that does not say: made before merges listed their parts)."""
    from astrodyn.recording.merge import recorded_parts

    if "merged_from" not in metadata:
        return None
    parts = recorded_parts(metadata)
    if not parts or parts[0][0] == 0:
        return None
    source = merged_first_input(metadata)
    first = f"; its first input, {Path(source[0]).name[:200]}, is part {source[1]}" if source else ""
    listed = metadata["merged_from"].get("parts", "")
    return (f"a merge of parts {listed[:200]} of a rolled recording (its `merged_from` metadata record{first}): the "
            f"steps from 0 are in parts 0 .. {parts[0][0] - 1}")


def merged_missing_parts(metadata: dict) -> str | None:
    """What a merged recording (its metadata records) is when its ``merged_from`` record
    lists parts with some left out (``merge --allow-missing-parts``): ``a merge of parts
    0-1,3 of a rolled recording, without part 2 ...``; None for any other file."""
    from astrodyn.recording.merge import format_parts, missing_parts, parts_named, recorded_parts

    if "merged_from" not in metadata or not (missing := missing_parts(recorded_parts(metadata))):
        return None
    listed = metadata["merged_from"].get("parts", "")
    return (f"a merge of parts {listed[:200]} of a rolled recording, without {parts_named(format_parts(missing))[:200]} "
            f"(its `merged_from` metadata record)")


def merged_first_input(metadata: dict) -> tuple[str, int] | None:
    """``(file, part)``: the first input of a merged recording (its ``merged_from`` record's
    ``files``) and that input's part number, from the ``recording`` record the merge took from
    it (the first input's record is the one a merge keeps); None when either is unknown."""
    from astrodyn.recording.merge import recorded_parts

    files = metadata.get("merged_from", {}).get("files", "")
    parts = recorded_parts({"recording": metadata.get("recording", {})})
    if not files or not parts:
        return None
    return files.split(";", 1)[0], parts[0][0]


def series_merge_advice(path: Path, metadata: dict, flag: str = "--commands") -> str:
    """:func:`merge_advice` for the recording ``path`` (its metadata records): its own part, or
    for a merge, its first input's (which names the series' files)."""
    if "merged_from" in metadata and (source := merged_first_input(metadata)) is not None:
        return merge_advice(Path(source[0]), source[1], flag)
    return merge_advice(path, recorded_part(metadata), flag)


def series_position(path: Path, metadata: dict, cut: bool, flag: str) -> str | None:
    """Why the recording ``path`` (its metadata records; ``cut``: it has no footer) may lack
    steps its rolled series holds in other files, with the merge to make, for a refusal that
    found nothing to start from: a later part (:func:`recorded_part`), a merge of later parts
    (:func:`merged_later_parts`) or the first part of a series that goes on
    (:func:`series_goes_on`); None for any other file."""
    part = recorded_part(metadata)
    if part:
        return (f"it is part {part} of a rolled recording (its `recording` metadata record): the steps from 0 are in "
                f"the earlier parts; {merge_advice(path, part, flag)}")
    if merged := merged_later_parts(path, metadata):
        return f"it is {merged}; {series_merge_advice(path, metadata, flag)}"
    if series := series_goes_on(path, metadata, cut):
        return f"{series}: {merge_advice(path, part, flag)}"
    return None


def first_actuator_step(path: Path, scenario: Scenario) -> int | None:
    """The step (``seq``) of the first actuator state of ``scenario``'s plant bodies in the
    recording ``path``, in log-time order; None when it holds none or its payload is not one
    (:func:`astrodyn.service.plant.read_command_recording` names that).  Reads up to that
    message (a recording of the run's start has it in its first chunk)."""
    from astrodyn import messages
    from astrodyn.recording.stream import open_stream
    from astrodyn.scenario.control import plant_bodies

    topics = [messages.body_key(scenario.name, body, "actuators") for body in plant_bodies(scenario)]
    if not topics:
        return None
    with open_stream(path) as stream:
        for m in stream.messages(topics):
            try:
                return messages.decode(m.data, "actuators")["seq"]
            except messages.MessageError:
                return None
    return None


def series_goes_on(path: Path, metadata: dict, cut: bool) -> str | None:
    """Why the recording ``path`` (its metadata records, ``cut``: it has no footer) is a part
    of a rolled series that goes on in another file, or None: a finished logger's file
    (``recording`` record) without the ``end`` record the logger writes into the part it
    stops in, and neither a merge's nor ``astrodyn recover``'s output (a killed run's file
    also lacks ``end``)."""
    from astrodyn.recording.merge import series_first_file

    part = recorded_part(metadata)
    if part is None or cut or "end" in metadata or "recovery" in metadata:
        return None
    first = series_first_file(path, part)
    following = f" in {Path(part_path(first, part + 1)).name[:200]}" if first is not None else ""
    return (f"it is part {part} of a rolled recording that goes on{following} (it has no `end` record, which the "
            f"logger writes into the part it stops in)")


def merge_advice(path: Path, part: int | None, flag: str = "--commands") -> str:
    """How to re-simulate (or, ``flag`` ``--resume``, continue) the whole rolled series of
    which ``path`` is part ``part`` (None: not known): ``astrodyn merge`` of its parts, then
    ``flag`` the merged file."""
    from astrodyn.recording.merge import series_first_file

    first = series_first_file(path, part)
    files = ("NAME.mcap NAME-0001.mcap ..." if first is None else
             f"{shlex.quote(first[:200])} {shlex.quote(part_path(first, 1)[:200])} ...")
    return (f"merge all the parts (`astrodyn merge --out MERGED.mcap {files}`, every part from the first) and give "
            f"{flag} the merged file")


def command_recording_notes(info: dict, scenario: Scenario) -> list[str]:
    """The lines ``run`` prints at the start about its ``--commands`` recording ``info``
    (:func:`check_command_recording`): a recording that ends before the config's last step
    (a killed or stopped run, or the first part of a rolled series that goes on: from there
    on the re-simulation holds the commands last applied), and recorded commands and faults
    past the config's duration (a served run goes past it), which are not applied."""
    rate, shown = scenario.rate, info["file"][:200]
    end_t = info["config_last_step"] / rate
    notes = []
    if info["held_after"]:
        cut = f" (the file is cut short: {info['damage'][:200]})" if info["damage"] else ""
        series = (f"; {info['series_goes_on']}: {info['series_advice']} to re-simulate all of it"
                  if info.get("series_goes_on") else "")
        notes.append(f"--commands {shown}: the recording ends at step {info['last_step']} (t = {info['t_last']:.6g} s), "
                     f"before this config's last step {info['config_last_step']} (t = {end_t:.6g} s){cut}: after it "
                     f"the commands last applied stay held; the states from step {info['last_step'] + 1} on are not "
                     f"a re-simulation of the recording{series}")
    if info["commands_after_end"] or info["faults_after_end"]:
        what = " and ".join(f"{n} {kind}{'s' if n != 1 else ''}" for n, kind in
                            ((info["commands_after_end"], "recorded command"), (info["faults_after_end"], "fault"))
                            if n)
        notes.append(f"--commands {shown}: the recording goes on to step {info['last_step']} (t = "
                     f"{info['t_last']:.6g} s), past this config's duration ({end_t:.6g} s): its {what} after that "
                     f"are not applied")
    return notes


def resume_plan(path: Path, scenario: Scenario, out: Path, work: Path) -> dict:
    """How to continue ``scenario`` from the recording ``path``: the step k to start at (every
    state channel holds steps 0 .. k-1), the logger's prefill arguments and each
    propagator's ``--start-step`` / ``--resume-state``.  ScenarioError naming the file for
    anything that cannot be resumed (not MCAP, another scenario or config, nothing or
    everything recorded, ``--out`` the same file, ``scenario`` metadata records that differ:
    :func:`recorded_config_conflict`)."""
    from astrodyn.recording import RecordingError, load as load_run
    from astrodyn.recording.stream import open_stream
    from astrodyn.service.resume import contiguous_steps, propagator_resume_args, state_topics

    if path.resolve() == out.resolve():
        raise ScenarioError(f"--out {out}: expected a new file, not the --resume file itself")
    try:
        run = load_run(path)
        with open_stream(path) as stream:  # (its index only)
            conflict, metadata, cut = recorded_config_conflict(stream, scenario), dict(stream.metadata), stream.truncated
    except (RecordingError, OSError) as exc:
        raise ScenarioError(f"--resume {exc}") from None
    if conflict is not None:
        raise ScenarioError(f"--resume {path}: {conflict}")
    problem = config_difference(run.scenario, scenario)
    if problem:
        raise ScenarioError(f"--resume {path}: expected a recording of this scenario and config ({scenario.name!r}), "
                            f"got {problem}")
    p = make_plan(scenario)
    kinds = [k for k in p.processes if k != "logger"]
    topics = [t for kind in kinds for t in state_topics(scenario, kind).values()]
    k = contiguous_steps(run, topics)
    if k == 0:  # a later part, a merge of later parts, the first part of a series that goes on: say so
        later = f"; {where}" if (where := series_position(path, metadata, cut, "--resume")) else ""
        raise ScenarioError(f"--resume {path}: expected at least one complete step (every body's states, from step "
                            f"0), found none{later}")
    if k >= scenario.n_steps:
        raise ScenarioError(f"--resume {path}: the recording already holds all {scenario.n_steps} steps; nothing to resume")
    extra = {kind: propagator_resume_args(run, scenario, kind, k - 1, work) for kind in kinds}
    return {"step": k, "t": k / scenario.rate, "extra_args": extra,
            "logger_args": [f"--prefill={path}", "--prefill-steps", str(k)]}
