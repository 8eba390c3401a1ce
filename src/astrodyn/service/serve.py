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
rate       ``{"factor": x}`` (1e-3..1e6, "inf")  the new status
stop       --                                  the final summary once the file is finished
fault      ``{"body", "fault", ...}``          closed loop only: a fault from the plant's next step
                                               (the keys of ``[[control.faults]]`` without ``t``;
                                               docs/control.md); recorded as events: serve's
                                               ``fault_requested`` (t: :meth:`Supervisor.sim_time_now`
                                               of the plant) and the plant's ``fault`` (t: the step
                                               it began)
=========  ==================================  =============================================

Any other verb of the scenario is answered with an error naming these
(``{"error": "seek: unknown control verb; this process answers status, ..."}``).

From Python::

    from pathlib import Path
    from astrodyn import bus
    TOKEN = Path("out/.demo.mcap.control-token").read_text()  # serve's "control_token_file"
    with bus.open_session(connect=["tcp/127.0.0.1:7447"]) as s:  # serve's "hub"
        bus.send_control(s, "demo", "rate", {"factor": 50}, token=TOKEN, require_reply=True)  # BusError if none answers

The supervisor forwards pause / resume / rate / stop to its propagators on the private key
``astrodyn/<scenario>/@command``; on ``stop`` the propagators end with their end-of-run
events and the logger finishes the file once it holds every message (nothing published
is lost).  SIGTERM / Ctrl-C to the supervisor is a ``stop``.

A propagator that dies (SIGKILL, crash) is noticed from its exit status and its Zenoh
liveliness token (measured: well under a second, docs/reliability.md), reported on stderr
and in the ``status`` reply (``restarts``), and restarted from the last state the logger
flushed to the file (:mod:`astrodyn.service.resume`: the latest step every one of its channels
holds; exact models are re-evaluated from the initial state, integrated ones continue from
that state with ``--resume-state``).  A ``restart`` event (process ``serve``) is recorded
in the MCAP with the step it restarted from.  Steps the dead process published after the
last flush are published again; the logger keeps the first copy of each seq, so the file
has no gap and no duplicate.

Restarts are limited by rate, not over the service's life: a process that dies for the
:data:`~astrodyn.service.supervision.RESTART_LIMIT`-th time within
:data:`~astrodyn.service.supervision.RESTART_WINDOW_S` seconds
(:class:`~astrodyn.service.supervision.RestartBudget`, as ``run``), or that ended with the
same error :data:`~astrodyn.service.runner.SAME_ERROR_RESTARTS` times in a row at the
step it was restarted at (deterministic: a restart only repeats it), or whose model ended,
is not restarted: serve says so on stderr at once (``process orbit died 5 times within 60
s; not restarted again ...``), ``status`` says ``"state": "degraded"`` and gives the
reason under that process (``not_restarted``) and in ``failures``, the other processes go
on, and ``stop`` ends serve with exit 1.  Rare deaths spread over weeks are each
restarted (before, the 6th death in the service's life was final and silent).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

from astrodyn import auth, bus
from astrodyn.recording.recover import finished_name
from astrodyn.recording.writer import standby_path
from astrodyn.scenario import ScenarioError, load, plan as make_plan, resolved_epoch_environment
from astrodyn.scenario.fields import flag_quantity, jsonable
from astrodyn.service.children import (
    DISK_FULL_EXIT,
    MODEL_ENDED_EXIT,
    STALL_S,
    Child,
    JobControl,
    StartError,
    add_stall_argument,
    child_bus_arguments,
    config_snapshot,
    ensure_open_file_limit,
    start_controller,
    wait_ready,
    wall_seconds,
    work_directory,
    zenoh_config_snapshot,
)
from astrodyn.service.output import OutputDirectory, series_parts_problem
from astrodyn.service.propagator import command_key
from astrodyn.service.runner import (
    EXIT_REJECTED,
    MAX_LOGGERS,
    SAME_ERROR_RESTARTS,
    attack_report,
    check_bus_flags,
    check_closed_loop_arguments,
    check_scenario_free,
    checked_output_path,
    closed_loop_line,
    logger_base_argv,
    propagator_argv,
)
from astrodyn.service.supervision import (
    RESTART_WINDOW_S,
    LoggerFile,
    LoggerFiles,
    RestartBudget,
    holds_config,
    next_event_seq,
    plan_part_restart,
    resume_from_parts,
    wait_until_gone,
)
from astrodyn.service.viewer import add_foxglove_argument, viewer_command
from astrodyn.signals import StopFlag

__all__ = ["main", "Supervisor", "roll_settings", "check_serve_flags", "ROLL_INTERVAL_DEFAULT_S"]


#: Wall seconds serve waits for its propagators to say they paused, when a rate change from
#: ``inf``, or from a rate they did not keep, brings them to one schedule (their heartbeats
#: come every 0.5 s).
PAUSE_HEARD_S = 2.0
#: Wall seconds a propagator's heartbeat may show it behind serve's schedule and still count
#: as keeping it (:meth:`Supervisor.keeps_schedule`): a pacing process publishes each step
#: when it is due (sleeping at most 50 ms at a time), so only scheduling delays of a loaded
#: machine lag it; one judged wrongly off the schedule costs a pause of half a second.
SCHEDULE_LAG_S = 0.1
#: Wall seconds after serve set a schedule before a heartbeat can show a process keeping it:
#: one heartbeat period, five times :data:`SCHEDULE_LAG_S`, so one that reaches less than
#: 80 % of the rate (at ``rate 1e6`` a light scene reaches about x1500) is off it by then.
SCHEDULE_JUDGED_AFTER_S = bus.HEARTBEAT_PERIOD_S


class Supervisor:
    """Starts the processes of one scenario and answers the control verbs (module docstring).

    ``zenoh_config``: serve's copy of its ``--zenoh-config`` in the work directory ``tmp``
    (:func:`~astrodyn.service.children.zenoh_config_snapshot`), which every process it starts
    or restarts is given, never the user's file.

    ``own_output()`` is called once its loggers are ready, i.e. once this serve holds its
    output (another run or serve recording to it would have made the first logger fail):
    what may only be done then (the control token file, :func:`control_token`).

    ``restart_window_s``: the window of each process's restart budget (:class:`RestartBudget`:
    the death that makes its ``limit``-th within this many seconds is not restarted); the
    default is run's; tests shrink it (serve's hidden ``--restart-window``)."""

    def __init__(self, scenario, out: Path, session, hub: str, *, rate: float,
                 roll_size: int | None = None, roll_interval: float | None = None, connect=(), tmp: Path,
                 restart_window_s: float = RESTART_WINDOW_S, zenoh_config: Path | None = None,
                 foxglove_port: int | None = None,
                 controllers: list[str] | None = None, token_file: Path | None = None, loggers: int = 1,
                 stall_s: float | None = STALL_S, own_output=None):
        self.scenario = scenario
        self.session = session
        self.out = Path(out)
        self.tmp = tmp
        self.restart_window_s = float(restart_window_s)
        self.stall_s = stall_s  # a propagator or logger silent this long is killed, then restarted
        self.restarts: list[dict] = []
        self.finishing: list[Child] = []  # `recover` of dead loggers' parts (restart_logger)
        self.rate = float(rate)
        self.state = "starting"
        self.started = time.monotonic()
        self.failures: list[str] = []
        self.not_restarted: dict[str, str] = {}  # process -> why it stays down (status: "degraded")
        p = make_plan(scenario)
        self.propagators = [k for k in p.processes if k != "logger"]
        self.budgets = {k: RestartBudget(k, window_s=self.restart_window_s) for k in p.processes}
        connect_args = child_bus_arguments(hub, connect, zenoh_config)
        meta = tmp / "scenario.json"
        meta.write_text(json.dumps(scenario.to_metadata()))
        # every process, restarted ones too, runs the text checked at the start, not the file as it is now
        config_path = config_snapshot(scenario, tmp)
        # the run's identity: children sign what they publish, commands are signed by us
        secret = auth.RunSecret.generate()
        self.child_env = {auth.SECRET_ENV: str(secret.save(tmp)), **resolved_epoch_environment(scenario)}
        self.signer = auth.Signer(secret, "serve")
        # a logger is ready when it answers signed with the run's secret: a liveliness token in its
        # name is no proof (another run's logger on a shared router has one: docs/reliability.md)
        self.verifier = auth.Verifier(secret)
        # the files this serve's (main) loggers created, by identity (--own-files): the only ones it
        # reads for a resume, finishes, counts as parts or renames, whatever else is named like them
        self.own = LoggerFiles(tmp / "own-files.jsonl")
        self.finishing_sources: dict[int, LoggerFile | None] = {}  # id(finish child) -> the dead part it finishes
        common = logger_base_argv(scenario, meta, config_path, self.propagators, connect_args)
        if roll_size:
            common += ["--roll-size", str(roll_size)]
        if roll_interval:
            common += ["--roll-interval", str(roll_interval)]
        # "--out=": a path that starts with "-" is not taken for an option
        self._logger_argv = [*common, f"--out={out}", "--leave-partial", f"--own-files={self.own.report}"]
        self.logger_attempt = 0
        self.children: dict[str, Child] = {}
        self.outdir = OutputDirectory(self.out)  # a rename or removal of it while recording fails serve
        self.outdir_checked = time.monotonic()
        self.outdir_failed = False  # its move or removal is among the failures
        self.start_first_logger()
        self.standbys: dict[str, Child] = {}  # hot standby loggers (--loggers N): not restarted
        for k in range(2, int(loggers) + 1):
            name = f"logger-{k}"
            child = self.standbys[name] = Child(name, [*common, "--name", name, f"--out={standby_path(out, k)}"], tmp,
                                                env=self.child_env)
            failure = wait_ready(session, scenario.name, child, 30.0, {"signal": None}, verifier=self.verifier)
            if failure is not None:  # nothing else has started: stop the loggers, say why
                self.stop_loggers()
                raise bus.BusError(failure)
        if own_output is not None:
            try:
                own_output()
            except Exception:
                self.stop_loggers()
                raise
        # the propagators' event numbering, heard from their first event on: a logger restart
        # continues it (the new logger has seen none of it: restart_logger)
        self.event_seqs = bus.EventSeqWatcher(session, scenario.name, verifier=auth.Verifier(secret))
        self._argv = {kind: propagator_argv(kind, config_path, connect_args, "--endless") for kind in self.propagators}
        if "plant" in self._argv and token_file is not None:  # outside controllers present serve's token
            self._argv["plant"].append(f"--control-token-file={token_file}")  # "=": beside --out, may start with "-"
        self.schedule: tuple[float, float] | None = None  # (wall, t): sim t due at that monotonic wall time
        self.pause_reasserted = 0.0  # monotonic time pause / resume was last sent again (reassert_pause)
        for kind in self.propagators:
            self.children[kind] = Child(kind, [*self._argv[kind], "--real-time-factor", str(self.rate)], tmp, env=self.child_env)
        self.verbs = (*bus.CONTROL_VERBS, "fault") if "plant" in self.propagators else bus.CONTROL_VERBS
        self.viewer_url = None
        if foxglove_port is not None:  # the live view: a separate process that only subscribes
            self._argv["viewer"] = [*viewer_command(), "--scenario", scenario.name, "--port", str(foxglove_port),
                                    "--metadata", str(meta), "--from-logger", "--services", ",".join(self.verbs),
                                    *connect_args]
            self.budgets["viewer"] = RestartBudget("viewer", window_s=self.restart_window_s)
            self.children["viewer"] = Child("viewer", self._argv["viewer"], tmp, env=self.child_env)
            self.viewer_url = f"ws://127.0.0.1:{foxglove_port}"
        self.controllers: dict[str, Child] = {}
        names = scenario.control.controllers if scenario.control is not None else ()
        for n, cmd in enumerate(controllers or []):  # closed loop: the user's programs, ended with us
            self.controllers[names[n]] = start_controller(names[n], cmd, scenario.name, hub, tmp, self.child_env,
                                                          token_file)
        self.commands = session.declare_publisher(command_key(scenario.name))
        self.beats = bus.HeartbeatMonitor(session, scenario.name, verifier=auth.Verifier(secret))
        # each propagator's last two heartbeats heard (poll_beats): the pace it showed between them
        self.beat_pairs: dict[str, tuple[dict | None, dict]] = {}
        self.alive = bus.AliveWatcher(session, scenario.name)
        self.events = bus.EventPublisher(session, scenario.name, "serve", signer=self.signer)
        self.state = "running"

    # ------------------------------------------------------------------ commands

    def command(self, verb: str, **args) -> None:
        bus.signed_put(self.commands, command_key(self.scenario.name), json.dumps({"verb": verb, **args}).encode(),
                       self.signer)

    def reassert_pause(self, now: float) -> None:
        """Send ``pause`` / ``resume`` and ``rate`` again, at most once a second, while a
        propagator's heartbeat (each says its pacer's state, paced or not) says otherwise than
        serve's state: one that subscribed to the commands after they were sent (still
        starting) would otherwise run while serve is paused, or at the old rate (at
        ``--rate inf`` it ran on: only the heartbeats sent while pacing said their state)."""
        if self.state not in ("running", "paused") or now - self.pause_reasserted < 1.0:
            return
        paused = self.state == "paused"
        rate = "inf" if math.isinf(self.rate) else self.rate
        beats = [self.beats.last.get(k, {}) for k in self.propagators]
        if any(hb.get("paused", paused) != paused for hb in beats):
            self.pause_reasserted = now
            if paused:
                self.command("pause")
            else:
                self.command("resume", **({"anchor": list(self.schedule)} if self.schedule else {}))
        if any(hb.get("rate", rate) != rate for hb in beats):
            self.pause_reasserted = now
            self.command("rate", factor=self.rate, **({"anchor": list(self.schedule)} if self.schedule else {}))

    def resume_schedule(self, paused_s: float) -> None:
        """After a Ctrl-Z of ``paused_s`` seconds (:class:`~astrodyn.service.children.JobControl`):
        the schedule moves on by as much, as the propagators' own do (``Pacer``), so a
        process restarted later keeps pace with them instead of racing through the sim time
        the pause would have covered."""
        if self.schedule is not None:
            self.schedule = (self.schedule[0] + paused_s, self.schedule[1])

    def status(self) -> dict:
        """The ``status`` reply.  ``state``: serve's (``running``, ``paused``, ...), except
        ``degraded`` while it runs with a process that died and is not restarted: that
        process's entry gives why (``not_restarted``), as ``failures`` does."""
        self.poll_beats()
        procs = {}
        for name, ch in self.children.items():
            hb = self.beats.last.get(name, {})
            procs[name] = {"pid": ch.pid, "running": ch.poll() is None, "exit": ch.poll(),
                           "t": hb.get("t"), "messages": hb.get("messages")}
            if name in self.not_restarted:
                procs[name]["not_restarted"] = self.not_restarted[name]
        ts = [procs[k]["t"] for k in self.propagators if procs[k]["t"] is not None]
        for name, ch in self.controllers.items():
            procs[f"controller {name}"] = {"pid": ch.pid, "running": ch.poll() is None, "exit": ch.poll()}
        state = "degraded" if self.state == "running" and self.not_restarted else self.state
        return {"scenario": self.scenario.name, "state": state,
                "real_time_factor": "inf" if math.isinf(self.rate) else self.rate,
                "t": min(ts) if ts else 0.0, "wall_s": round(time.monotonic() - self.started, 3),
                "processes": procs, "failures": list(self.failures), "restarts": list(self.restarts)}

    def poll_beats(self) -> None:
        """Take the heartbeats that arrived, keeping each propagator's last two
        (``beat_pairs``, :meth:`measured_pace`)."""
        self.beats.poll()
        for k in self.propagators:
            hb = self.beats.last.get(k)
            if hb is not None and (pair := self.beat_pairs.get(k)) is not None and pair[1] is hb:
                continue
            if hb is not None:
                self.beat_pairs[k] = (pair[1] if pair is not None else None, hb)

    def measured_pace(self, name: str) -> float:
        """Sim seconds per wall second process ``name`` advanced between its last two
        heartbeats heard (at most two heartbeat periods apart, both publishing at one stated
        rate, from one process: a restarted one counts its heartbeats from 1 again); 0.0 when
        they show none (too far apart, paused, a rate change or a restart between them)."""
        a, b = self.beat_pairs.get(name, (None, None))
        if a is None or b is None:
            return 0.0
        try:
            dt_s = (b["time_ns"] - a["time_ns"]) / 1e9
            if not (0.0 < dt_s <= 2 * bus.HEARTBEAT_PERIOD_S and b["n"] > a["n"] and a.get("rate") == b.get("rate")
                    and all(hb.get("paused") is False and not hb.get("waiting") and not hb.get("preparing")
                            and not hb.get("done") for hb in (a, b))):
                return 0.0
            pace = (float(b["t"]) - float(a["t"])) / dt_s
        except (KeyError, TypeError, ValueError, OverflowError):  # a field missing or of another type
            return 0.0
        return pace if math.isfinite(pace) and pace > 0 else 0.0

    @staticmethod
    def heartbeat_age_s(hb: dict) -> float | None:
        """Wall seconds since heartbeat ``hb`` was sent (its ``time_ns``: serve's children run
        on its host), or None when it has no valid ``time_ns``."""
        sent_ns = hb.get("time_ns")
        if isinstance(sent_ns, bool) or not isinstance(sent_ns, int):
            return None
        return (time.time_ns() - sent_ns) / 1e9

    def keeps_schedule(self, hb: dict) -> bool:
        """Whether heartbeat ``hb`` shows its process pacing on serve's schedule
        (``self.schedule``, at ``self.rate``, finite): it publishes (not paused, waiting for a
        controller, preparing or done), states serve's rate, was sent at least
        :data:`SCHEDULE_JUDGED_AFTER_S` after the schedule was set and at most two heartbeat
        periods ago, and its ``t`` is at most one output step plus :data:`SCHEDULE_LAG_S` of
        wall time at the rate behind the sim time the schedule had due when it was sent.
        False for one that runs as fast as it can (``inf``, or a rate it cannot keep), one
        that has not heard serve's last rate, and one not heard since the schedule was set."""
        t, rate, age_s = hb.get("t"), hb.get("rate"), self.heartbeat_age_s(hb)
        if (self.schedule is None or not math.isfinite(self.rate) or age_s is None
                or not -0.1 <= age_s <= 2 * bus.HEARTBEAT_PERIOD_S
                or hb.get("paused") is not False or hb.get("waiting") or hb.get("preparing") or hb.get("done")
                or isinstance(t, bool) or not isinstance(t, (int, float)) or not math.isfinite(t)
                or isinstance(rate, bool) or rate != self.rate):
            return False
        sent = time.monotonic() - max(0.0, age_s)
        wall0, t0 = self.schedule
        if sent - wall0 < SCHEDULE_JUDGED_AFTER_S:  # too early to tell (or of an earlier schedule)
            return False
        due = t0 + (sent - wall0) * self.rate
        return t >= due - (1.0 / self.scenario.rate + SCHEDULE_LAG_S * self.rate)

    def runs_off_schedule(self) -> list[str]:
        """The running propagators whose last heartbeat shows them publishing but not on
        serve's schedule (:meth:`keeps_schedule`): where they are now is known only once they
        stand still.  One waiting, preparing, done or not heard yet is not among them: it is
        where its heartbeat says; nor one paused while serve is paused.  One whose heartbeat
        says paused while serve runs is: that heartbeat predates a ``resume`` (a rate change
        within half a second of a resume anchored to such stale times and left orbit and
        attitude on two schedules, hundreds of sim seconds apart: session 20 probe D, D1)."""
        self.poll_beats()
        off = []
        for k in self.propagators:
            hb = self.beats.last.get(k)
            if self.children[k].poll() is not None or not hb or hb.get("t") is None:
                continue
            if hb.get("paused") is True and self.state == "running":
                off.append(k)
            elif (hb.get("paused") is False and not hb.get("waiting") and not hb.get("preparing")
                    and not hb.get("done") and not self.keeps_schedule(hb)):
                off.append(k)
        return off

    def sim_time_now(self, name: str) -> float:
        """Serve's best estimate of the sim time process ``name`` is at now, s, never beyond
        what was measured: the ``t`` of its last heartbeat, advanced for the wall time since it
        was sent (at most one heartbeat period, :data:`astrodyn.bus.HEARTBEAT_PERIOD_S`: it
        beats that often while it publishes) at the rate that heartbeat states or the pace it
        showed since the one before (:meth:`measured_pace`), whichever is lower.  Not advanced
        when it shows none: paused, waiting for a controller (a lockstep plant), preparing,
        done, or a rate change or restart just before.  It used to be advanced at the stated
        rate alone: after ``rate 1e6``, which a light scene runs at about x1500, up to 500,000
        sim s that no process reached, and ``rate 10`` then anchored every process there
        (session 20 probe A, F1).  0.0 before its first heartbeat.  Heartbeats are up to a
        period old, so at ``--rate 10`` the last one's ``t`` alone lags by up to 5 s of sim time
        (closedloop probe F13)."""
        hb = self.beats.last.get(name, {})
        t = hb.get("t")
        if isinstance(t, bool) or not isinstance(t, (int, float)) or not math.isfinite(t):
            return 0.0
        rate, age_s = hb.get("rate"), self.heartbeat_age_s(hb)
        if isinstance(rate, bool) or not isinstance(rate, (int, float)) or not math.isfinite(rate) or age_s is None:
            rate = 0.0  # "inf" (as before: not advanced), or not a number
        pace = min(float(rate), self.measured_pace(name))
        return float(t) + min(max(0.0, age_s or 0.0), bus.HEARTBEAT_PERIOD_S) * pace

    def wait_paused(self, timeout_s: float, since_ns: int | None = None) -> None:
        """Wait (at most ``timeout_s``) until every running propagator's heartbeat says it is
        paused: its ``t`` is then where it stopped, not where it was up to half a second ago.
        ``since_ns`` (``time.time_ns()`` of the pause command): only a heartbeat sent after it
        counts (one that said "paused" before a resume is stale: session 20 probe D, D1)."""
        deadline = time.monotonic() + timeout_s

        def paused(k: str) -> bool:
            hb = self.beats.last.get(k, {})
            sent = hb.get("time_ns")
            return hb.get("paused") is True and (since_ns is None or (isinstance(sent, int) and sent >= since_ns))

        while time.monotonic() < deadline:
            self.poll_beats()
            if all(paused(k) or self.children[k].poll() is not None for k in self.propagators):
                return
            time.sleep(0.02)

    def lead_schedule(self) -> tuple[float, float]:
        """``(monotonic wall now, sim t)`` for a rate change or a resume: the sim time of the
        propagator furthest on (:meth:`sim_time_now`), the one schedule every process paces to
        from now on (``Pacer``'s anchor); never ahead of where that propagator is (a schedule
        ahead of every process made them race to it: session 20 probe A, F1).  At ``rate inf``
        each ran as fast as it could, so orbit and attitude drifted apart (hours of sim time in
        seconds); paced each from its own time, they stayed apart for good (svc probe F5): now
        those behind catch up."""
        self.poll_beats()
        ts = [self.sim_time_now(k) for k in self.propagators if self.beats.last.get(k, {}).get("t") is not None]
        return time.monotonic(), max(ts, default=0.0)

    def handle(self, request: bus.ControlRequest) -> bool:
        """Answer one control request; True when it was ``stop``."""
        verb = request.verb
        if verb == "status":
            request.reply(self.status())
        elif verb == "pause":
            self.command("pause")
            self.state = "paused"
            self.schedule = None  # paused: no schedule; resume starts a new one
            request.reply(self.status())
        elif verb == "resume":
            self.schedule = self.lead_schedule()
            self.command("resume", anchor=list(self.schedule))
            self.state = "running"
            request.reply(self.status())
        elif verb == "rate":
            try:
                factor = bus.parse_rate_factor(request.args.get("factor"))
            except ValueError as exc:
                request.error(str(exc))
                return False
            # from inf, or from a rate they did not keep (each ran as fast as it could, so they ran
            # apart and no estimate from their heartbeats is sure), or not yet on the last
            # schedule: hold them where they are, so the schedule starts from the one furthest on
            # as it really is (session 20 probe A, F1: `rate 1e6`, then `rate 10`, raced for a minute)
            hold = self.state == "running" and not math.isinf(factor) and bool(self.runs_off_schedule())
            if hold:
                paused_at_ns = time.time_ns()
                self.command("pause")
                self.wait_paused(PAUSE_HEARD_S, since_ns=paused_at_ns)
            self.schedule = self.lead_schedule()  # judged at the rate they kept until now
            self.rate = factor
            self.command("rate", factor=factor, anchor=list(self.schedule))
            if hold:
                self.command("resume", anchor=list(self.schedule))
            request.reply(self.status())
        elif verb == "fault" and "plant" in self.propagators:
            from astrodyn.scenario.control import parse_fault, plant_bodies
            from astrodyn.scenario.fields import Ctx

            try:  # checked here, so the caller learns what is wrong; the plant applies it at its next step
                f = parse_fault(Ctx("fault"), request.args, "fault", math.inf, plant_bodies(self.scenario), t=0.0)
            except ScenarioError as exc:
                request.error(str(exc).removeprefix("fault: "))
                return False
            self.command("fault", fault=request.args)
            self.poll_beats()
            heard = self.beats.last.get("plant", {}).get("t")
            self.events.emit("fault_requested", self.sim_time_now("plant"), json.dumps(
                {"body": f.body, "fault": f.fault, "plant_t_heard": heard if isinstance(heard, (int, float)) else None,
                 "begins": "at the plant's next step: its fault event gives the time"}, separators=(",", ":")))
            request.reply(self.status())
        elif verb == "stop":
            return True
        else:
            request.error(f"{verb}: expected one of {', '.join(self.verbs)}")
        return False

    def stop_loggers(self) -> None:
        """Stop the loggers started so far (start-up failed: nothing else has started)."""
        for ch in [*self.standbys.values(), self.children["logger"]]:
            ch.stop()
            ch.close()
        self.outdir.close()
        self.own.close()

    def check_output_directory(self, now: float, at_once: bool = False) -> None:
        """At most once a second (``at_once``: now): the directory of ``--out`` still where it
        was?  Renamed or removed, the recording is not at ``--out`` any more: serve fails
        (nothing renamed or removed), saying where it is when that can be told."""
        if not at_once and now - self.outdir_checked < 1.0 or self.state not in ("running", "paused"):
            return
        self.outdir_checked = now
        if (problem := self.outdir.problem()) is not None:
            msg = f"{problem}; the recording is not at --out {self.out} (nothing was renamed or removed)"
            print(f"astrodyn serve: {msg}", file=sys.stderr, flush=True)
            self.failures.append(msg)
            self.outdir_failed = True
            self.state = "failed"

    def check_children(self) -> None:
        """Notice dead processes (exit status or lost liveliness token); restart propagators."""
        self.poll_beats()  # the sim times a failure message names are the latest
        now = time.monotonic()
        self.check_output_directory(now)
        for name in (*self.propagators, "logger"):
            ch = self.children[name]
            if self.state in ("running", "paused") and ch.kill_if_stalled(self.beats, self.stall_s, now):
                print(f"astrodyn serve: process {name} (pid {ch.pid}) has sent no heartbeat for {ch.stalled_s:.0f} s: "
                      f"killed as hung", file=sys.stderr, flush=True)
            # a propagator whose states no longer reach the logger (its bus link lost): restarted
            # from the file's tail (the logger no longer hears it) or from just before the first
            # step the logger misses (a gap: refilled, Supervisor.restart)
            elif (self.state in ("running", "paused") and name not in ("logger", "plant")
                    and ch.kill_if_lost_to_logger(self.beats)):
                print(f"astrodyn serve: process {name} (pid {ch.pid}) {ch.how(-9)}", file=sys.stderr, flush=True)
        self.reassert_pause(now)
        if self.schedule is None and self.state == "running":  # the pace the propagators keep, once they do
            ts = [self.beats.last.get(k, {}).get("t") for k in self.propagators]
            if ts and all(t is not None and t > 0 for t in ts):
                self.schedule = (time.monotonic(), min(ts))
        lost = {p for p, is_alive in self.alive.poll() if not is_alive}
        for name, ch in list(self.children.items()):
            rc = ch.poll()
            if rc is None and name in lost and self.state in ("running", "paused"):
                try:  # the token went first: the process is likely on its way out
                    rc = ch.proc.wait(timeout=0.05)
                except subprocess.TimeoutExpired:
                    # still running: a network blip, or a token forged in its name and withdrawn
                    # (never wait long on that: anyone can toggle one); its exit or its silence
                    # (kill_if_stalled) tells on a later check
                    continue
            # exit 0 is an end serve asked for, unless it was a stop signal from elsewhere (a crash)
            if rc is None or rc == 0 and ch.outside_stop_signal(rc) is None or getattr(ch, "reported", False):
                continue
            ch.reported = True
            hb = self.beats.last.get(name, {})
            msg = f"process {name} (pid {ch.pid}) {ch.how(rc)} at {sim_time(hb.get('t'))}: {ch.last_words(3)}"
            print(f"astrodyn serve: {msg}", file=sys.stderr, flush=True)
            # a death may be the output directory's move (a process writing into it or reading
            # its recording back): that is serve's failure, said as such, before any restart
            # tries the old path and fails with "No such file or directory"
            self.check_output_directory(now, at_once=True)
            if self.outdir_failed:
                self.failures.append(msg)
                continue
            n = sum(1 for r in self.restarts if r["process"] == name)
            if name == "viewer":  # the view is not the record: restart it, never fail the run for it
                if self.state in ("running", "paused") and self.budgets["viewer"].allow():
                    old = self.children["viewer"]
                    old.close()
                    self.children["viewer"] = Child(f"viewer-r{n + 1}", self._argv["viewer"], self.tmp, env=self.child_env)
                    self.children["viewer"].name = "viewer"
                    self.restarts.append({"process": "viewer", "old_pid": old.pid, "new_pid": self.children["viewer"].pid,
                                          "why": msg, "from_step": None, "state_from": None, "time": time.time()})
                    print(f"astrodyn serve: restarted viewer (pid {self.children['viewer'].pid})", file=sys.stderr,
                          flush=True)
                else:
                    print(f"astrodyn serve: warning: the live view is gone ({self.budgets['viewer'].refusal()}); "
                          f"the simulation and the recording go on", file=sys.stderr, flush=True)
                continue
            if name in ("plant", "logger") and "plant" in self.propagators:
                # a closed loop is not restarted: its controllers' state lives outside astrodyn,
                # and a plant cannot resume mid-run (docs/control.md, docs/reliability.md)
                self.failures.append(msg + f" (the {name} of a closed-loop run is not restarted; docs/control.md)")
                self.state = "failed"
                continue
            if name == "logger" and rc == DISK_FULL_EXIT:  # a new logger would fail the same way
                why = f"not restarted: free space beside {self.out}, then `astrodyn recover`"
                print(f"astrodyn serve: the logger's disk is full: {why}; serve stops", file=sys.stderr, flush=True)
                self.failures.append(msg + f" ({why})")
                self.state = "failed"
                continue
            if name == "logger" and self.state in ("running", "paused"):
                if self.budgets["logger"].allow():
                    try:
                        self.restart_logger(msg)
                        continue
                    except Exception as exc:
                        msg += f"; restart failed: {exc}"
                        print(f"astrodyn serve: the logger could not be restarted: {exc}; serve stops", file=sys.stderr,
                              flush=True)
                else:
                    msg = f"{self.budgets['logger'].refusal()}; last: {msg}"
                    print(f"astrodyn serve: {self.budgets['logger'].refusal()}: serve stops", file=sys.stderr, flush=True)
                self.failures.append(msg)
                self.state = "failed"
                continue
            if name in self.propagators and rc == MODEL_ENDED_EXIT:  # it would end there again
                self.leave_down(name, msg, f"process {name} not restarted: its model ended (it would end there again)")
                continue
            if name in self.propagators and self.state in ("running", "paused"):
                if not self.budgets[name].allow():  # a rate, not a count over the service's life
                    self.leave_down(name, msg, self.budgets[name].refusal())
                    continue
                said = ch.stderr_tail(1) if rc > 0 and ch.stalled_s is None and ch.lost_to_logger is None else ""
                try:
                    refused = self.restart(name, msg, n, said)
                except Exception as exc:  # keep serving the others; the failure is final for this one
                    refused = f"process {name} not restarted: the restart failed: {exc}"
                if refused is not None:
                    self.leave_down(name, msg, refused)
                continue
            self.failures.append(msg)
        self.check_controllers()

    def leave_down(self, name: str, death: str, why: str) -> None:
        """Process ``name`` died (``death``: what serve said of it) and is not restarted
        (``why``, a sentence that says so): said on stderr at once, in ``status`` (state
        ``degraded``, the process's ``not_restarted``) and in ``failures`` (``stop`` ends
        serve with exit 1); the other processes go on."""
        self.not_restarted[name] = why
        self.failures.append(f"{death}; {why}")
        print(f"astrodyn serve: {why}; the other processes go on (status: degraded), and `stop` ends serve with exit 1",
              file=sys.stderr, flush=True)

    def check_controllers(self) -> None:
        """A ``--controller`` that ended is not restarted (its state is its own): in lockstep
        the plant cannot go on without its answers, so serve fails now, naming it, instead of
        after ``control.timeout``; in free mode the plant goes on, and serve says so once."""
        plant_ending = self.beats.last.get("plant", {}).get("done")  # its last heartbeat: it is on its way out
        for name, ch in self.controllers.items():
            rc = ch.poll()
            if rc is None or getattr(ch, "reported", False) or self.state not in ("running", "paused"):
                continue
            if self.scenario.control.mode == "lockstep" and plant_ending:
                continue  # a controller leaves when the plant stops: the plant's exit says why (check_children)
            ch.reported = True
            msg = f"controller {name} (pid {ch.pid}) {ch.how(rc)} at {sim_time(self.beats.last.get('plant', {}).get('t'))}: " \
                  f"{ch.last_words(3)}"
            if self.scenario.control.mode == "lockstep":
                self.failures.append(msg + " (a lockstep plant cannot go on without it; a controller is not "
                                           "restarted: docs/control.md)")
                self.state = "failed"
            print(f"astrodyn serve: {msg}" + ("" if self.state == "failed" else
                                              "; the plant goes on without its commands (free mode)"),
                  file=sys.stderr, flush=True)

    def start_first_logger(self, timeout_s: float = 30.0) -> None:
        """Start the logger and wait until it is ready.  One killed by a signal before it is
        ready (nothing is recorded yet: no propagator has started) is replaced, within its
        restart budget, and the file it had opened (headers only) removed; one that exits on
        its own (it cannot write its file, a partial recording is in the way, ...) ends serve
        with its words (:class:`astrodyn.bus.BusError`)."""
        from astrodyn.recording.writer import partial_path

        while True:
            attempt = self.logger_attempt
            own_file = Path(partial_path(self.out, attempt))
            existed = os.path.lexists(own_file)
            argv = [*self._logger_argv, *(["--attempt", str(attempt)] if attempt else [])]
            child = self.children["logger"] = Child("logger" if attempt == 0 else f"logger-r{attempt}", argv,
                                                    self.tmp, env=self.child_env)
            child.name = "logger"
            failure = wait_ready(self.session, self.scenario.name, child, timeout_s, {"signal": None},
                                 verifier=self.verifier)
            if failure is None:
                return
            rc = child.poll()
            if rc is None or rc >= 0 or not self.budgets["logger"].allow():
                child.stop(signal.SIGKILL, timeout=5)
                child.close()
                raise bus.BusError(failure if rc is None or rc >= 0 else f"{self.budgets['logger'].refusal()}; last: {failure}")
            child.close()
            wait_until_gone(self.session, self.scenario.name, "logger")
            if (dead_file := LoggerFile.of_dead_logger(own_file, existed)) is not None:  # headers only, and its own
                dead_file.unlink_if_here()
            self.logger_attempt += 1
            self.restarts.append({"process": "logger", "old_pid": child.pid, "new_pid": None, "why": f"killed by signal {-rc} while starting",
                                  "from_step": 0, "state_from": None, "time": time.time()})
            print(f"astrodyn serve: logger (pid {child.pid}) killed by signal {-rc} while starting: starting another",
                  file=sys.stderr, flush=True)

    def refill_args(self, kind: str, first_missing: int) -> tuple[dict | None, str | None]:
        """The arguments that restart ``kind`` just before ``first_missing``, the first step
        the logger misses in its channels (states lost on a broken bus link,
        :meth:`~astrodyn.service.children.Child.kill_if_lost_to_logger`), from the part being
        written (read up to its last flushed chunk), and that part's name; ``(None, None)``
        when the step before it is not in that part (the gap began with the part: the
        parts' tails decide then)."""
        from astrodyn.recording import RecordingError, load as load_run
        from astrodyn.service.resume import ResumeError, propagator_resume_args

        parts = self._parts()
        if not parts or not holds_config(parts[0], self.scenario):  # never another config's states
            return None, None
        part = parts[0]
        try:
            return propagator_resume_args(load_run(part), self.scenario, kind, first_missing - 1, self.tmp), part
        except (RecordingError, ResumeError, OSError):
            return None, None

    def _parts(self) -> list[str]:
        """The files the (main) loggers of this serve have written so far, newest first, where
        they are now: the part being written (``NAME[-000k].partial[-n].mcap``), then the
        finished parts (a dead logger's part finished by its ``recover`` in its place).  Only
        files this serve's loggers created (:class:`~astrodyn.service.supervision.LoggerFiles`,
        by identity): never another recorder's file, whatever its name (another user's serve
        recording ``NAME-0002.mcap`` in the same directory), nor a standby logger's."""
        self._take_finished_parts()
        return [where for _, where in self.own.newest_first()]

    def _take_finished_parts(self, wait_s: float = 10.0) -> None:
        """Take the files the ``recover`` of dead loggers' parts made (restart_logger) as this
        serve's own, each in the place of the part it finished.  One still running whose
        source is gone already (it is about to end) is waited for, at most ``wait_s``."""
        for child in self.finishing:
            if id(child) not in self.finishing_sources:
                continue
            source = self.finishing_sources[id(child)]
            if child.poll() is None and source is not None and not source.here():
                with contextlib.suppress(subprocess.TimeoutExpired):
                    child.proc.wait(timeout=wait_s)
            if child.poll() is None:
                continue
            del self.finishing_sources[id(child)]
            if child.poll() != 0:
                continue
            for line in child.stdout_lines():
                with contextlib.suppress(ValueError, TypeError, AttributeError):
                    out = json.loads(line).get("out")
                    if isinstance(out, str) and (lf := LoggerFile.of_ready_logger(out)) is not None:
                        self.own.add(lf, instead_of=source)

    def restart_logger(self, why: str) -> None:
        """The logger died: a new one records the next part while the dead one's file is
        finished as its own part, and the propagators continue after the last step that
        file holds (:func:`astrodyn.service.supervision.plan_part_restart`).  Nothing is
        copied, so the restart costs about a second whatever the size of the part: wall
        time, not states."""


        for kind in self.propagators:
            self.children[kind].reported = True  # stopped here, not a death to restart
            self.children[kind].stop(signal.SIGKILL, timeout=5)
        dead = self.children["logger"]
        dead.close()
        wait_until_gone(self.session, self.scenario.name, "logger")
        self.logger_attempt += 1
        parts = self._parts()  # this serve's own files only (by identity), newest first
        partials = [p for p in parts if finished_name(p)]
        self.event_seqs.poll()  # every process's events, the dead logger's own included, continue their numbering
        plan = plan_part_restart(self.scenario, self.out, partials[0] if partials else None,
                                 [p for p in parts if not finished_name(p)], self.propagators,
                                 self.logger_attempt, self.tmp, self.event_seqs.next_seqs())
        argv = [*self._logger_argv, "--attempt", str(self.logger_attempt), *plan.logger_args]
        self.children["logger"] = Child(f"logger-r{self.logger_attempt}", argv, self.tmp, env=self.child_env)
        self.children["logger"].name = "logger"
        # its own signed answer, not a token in its name (another run's logger on a shared router)
        failure = wait_ready(self.session, self.scenario.name, self.children["logger"], 30.0, {"signal": None},
                             verifier=self.verifier)
        if failure is not None:
            raise bus.BusError(failure)
        # each propagator's events continue its numbering (the new logger has seen none of them,
        # so next_event_seq cannot tell: what serve heard does): a merged series has each seq once
        self.event_seqs.poll()
        for kind in self.propagators:
            if kind in self.not_restarted:  # left down (leave_down): a logger restart does not revive it
                continue
            argv = [*self._argv[kind], "--real-time-factor", str(self.rate), "--first-event-seq",
                    str(self.event_seqs.next_seq(kind)), *self.pace_args()]
            for k, v in plan.propagator_args[kind].items():
                argv += [k, str(v)]
            self.children[kind].close()
            self.children[kind] = Child(f"{kind}-l{self.logger_attempt}", argv, self.tmp, env=self.child_env)
            self.children[kind].name = kind
        dead_file = self.own.owns(plan.source) if plan.source else None
        finishing = plan.finish_in_background(self.tmp)
        if finishing is not None:
            self.finishing.append(finishing)
            self.finishing_sources[id(finishing)] = dead_file
        steps = {kind: args.get("--start-step", 0) for kind, args in plan.propagator_args.items()
                 if kind not in self.not_restarted}
        record = {"process": "logger", "old_pid": dead.pid, "new_pid": self.children["logger"].pid, "why": why,
                  "from_step": min(steps.values(), default=0), "state_from": plan.final or plan.source,  # its name once finished
                  "time": time.time()}
        self.restarts.append(record)
        self.emit_restart(record, record["from_step"] - 1 if record["from_step"] > 0 else None)
        print(f"astrodyn serve: restarted logger (pid {record['new_pid']}) on part {plan.part}; the dead logger's "
              f"{plan.source or 'file'} is finished as part {plan.part - 1}; propagators continue at "
              + ", ".join(f"{k} step {v}" for k, v in steps.items()), file=sys.stderr, flush=True)

    def pace_args(self) -> list[str]:
        """How a restarted propagator paces: ``--paused`` while serve is paused (it holds
        before its first step until ``resume``; it used to run on until the pause was sent
        again, about 3 s of sim time at x10 past where the others stood: session 20 probe A,
        F11); else ``--pace-anchor``, the run's schedule, so the new process catches
        up with it instead of starting a new one behind (none at rate inf)."""
        if self.state == "paused":
            return ["--paused"]
        if self.schedule is None or math.isinf(self.rate):
            return []
        return ["--pace-anchor", repr(self.schedule[0]), repr(self.schedule[1])]

    def restart(self, kind: str, why: str, n: int, said: str = "") -> str | None:
        """Start ``kind`` again after the last step every one of its channels has in the
        newest part that holds one (read from the parts' tails: a cost independent of their size).
        ``said``: the last line of its stderr when it exited with an error of its own ("" for
        a signal, a stall, a cut bus link).  Returns None once restarted, or why it is not: it
        ended with the same error :data:`SAME_ERROR_RESTARTS` times in a row, each time
        restarted at this step (deterministic: a restart only repeats it, however far apart
        the deaths are; the rate budget would restart it for ever)."""
        old = self.children[kind]
        args, source = self.refill_args(kind, old.refill_from) if old.refill_from else (None, None)
        if args is None:
            args, source = resume_from_parts(self.scenario, kind, self._parts(), self.tmp)
        same = 0  # the restarts just before this one, at this step, that ended with this error
        for r in reversed([r for r in self.restarts if r["process"] == kind]):
            if not said or r.get("from_step") != args["--start-step"] or r.get("said") != said:
                break
            same += 1
        if same >= SAME_ERROR_RESTARTS:
            return (f"process {kind} not restarted: it ended with the same error {same + 1} times in a row, each time "
                    f"restarted at step {args['--start-step']} without recording a step: {said}")
        step = args["--start-step"] - 1 if source is not None else None
        old.close()
        wait_until_gone(self.session, self.scenario.name, kind)
        self.event_seqs.poll()  # the logger's count, or what serve heard when the logger does not answer
        event_seq = max(next_event_seq(self.session, self.scenario.name, kind, 0), self.event_seqs.next_seq(kind))
        argv = [*self._argv[kind], "--real-time-factor", str(self.rate), "--first-event-seq", str(event_seq),
                *self.pace_args()]
        for k, v in args.items():
            argv += [k, str(v)]
        self.children[kind] = Child(f"{kind}-r{n + 1}", argv, self.tmp, env=self.child_env)
        self.children[kind].name = kind
        record = {"process": kind, "old_pid": old.pid, "new_pid": self.children[kind].pid, "why": why,
                  "from_step": args["--start-step"], "state_from": source and (finished_name(source) or source),
                  "time": time.time(),
                  **({"said": said} if said else {})}
        self.restarts.append(record)
        self.emit_restart(record, step)
        print(f"astrodyn serve: restarted {kind} (pid {record['new_pid']}) from step {record['from_step']}"
              f"{' (state from ' + source + ')' if source else ''}", file=sys.stderr, flush=True)
        return None

    def emit_restart(self, record: dict, step: int | None) -> None:
        """The ``restart`` event (process ``serve``) of a restart ``record``: its ``t`` is that
        of ``step``, the step whose state the restarted process continued from (0 when it
        started from the beginning); its detail the record's process, pids, ``from_step``
        and ``state_from``."""
        t = step / self.scenario.rate if step is not None else 0.0
        self.events.emit("restart", max(0.0, t), json.dumps({k: record[k] for k in ("process", "old_pid", "new_pid",
                                                                                      "from_step", "state_from")}))

    def stop(self, timeout_s: float = 60.0) -> dict:
        """Stop the propagators, let the logger finish the file, return the final summary."""
        self.state = "stopping"
        self.command("stop")
        deadline = time.monotonic() + timeout_s
        for kind in self.propagators:
            ch = self.children[kind]
            while ch.proc.poll() is None and time.monotonic() < deadline:
                try:
                    ch.proc.wait(timeout=min(0.5, max(0.01, deadline - time.monotonic())))
                except subprocess.TimeoutExpired:  # one that subscribed to the commands after the first stop
                    self.command("stop")  # (still starting: compiling, waiting for the logger) missed it
            if ch.proc.poll() is None:
                ch.stop()
        logger = self.children["logger"]
        moved = self.outdir.problem()  # checked before the end, which would fail on it in other ways
        if any(self.children[kind].poll() != 0 for kind in self.propagators):
            # one ended without its last states (dead, not restarted, or stopped above): the
            # logger would wait for them until the deadline; it records what is queued and
            # finishes the file now
            deadline = min(deadline, time.monotonic() + 1.0)
        try:
            logger.proc.wait(timeout=max(1.0, deadline - time.monotonic()))
        except Exception:
            logger.stop(signal.SIGTERM, timeout=30)
        for child in self.finishing:  # dead loggers' parts: finished before we say we are done
            try:
                child.proc.wait(timeout=max(1.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                child.stop()
            if child.poll() != 0:
                self.failures.append(f"{child.name} (pid {child.pid}) {child.stderr_tail(2) or 'did not finish'}: "
                                     f"finish the dead logger's file with `astrodyn recover`")
            child.close()
        standbys = {}
        for name, child in self.standbys.items():  # they end by themselves once every state is recorded
            try:
                child.proc.wait(timeout=max(1.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                child.stop(signal.SIGTERM, timeout=30)
            log = child.summary() or {}
            standbys[name] = {"pid": child.pid, "exit": child.poll(), "file": log.get("file"), "summary": log}
            if child.poll() != 0:
                self.failures.append(f"standby {name} (pid {child.pid}) exited with status {child.poll()}: its "
                                     f"recording stays partial (`astrodyn recover`, or `astrodyn merge` with the main one)")
        self.state = "stopped"
        summary = self.status()
        summary["standbys"] = standbys
        summary["logger"] = log = logger.summary()
        for kept in (log or {}).get("parts_kept_aside") or []:  # a part's name was taken by a file not ours
            print(f"astrodyn serve: warning: {kept.get('why')}: that part of this serve's recording is "
                  f"{kept.get('file')} instead", file=sys.stderr, flush=True)
        if "plant" in self.propagators:  # its rejected commands and answers (the ATTACKED line)
            summary["plant"] = self.children["plant"].summary()
        rc = logger.poll()
        if moved is not None and not self.outdir_failed:
            self.failures.append(f"{moved}; the recording is not at --out {self.out} (nothing was renamed or removed)")
        if rc not in (0, None) and not getattr(logger, "reported", False):  # it died at the end (its summary, ...)
            self.failures.append(f"process logger (pid {logger.pid}) {logger.how(rc)} while finishing: "
                                 f"{logger.last_words(2)}")
        elif not log and not self.failures:
            self.failures.append(f"the logger ended without its summary (its output in {self.tmp} is gone); its "
                                 f"recording is not known to be at --out {self.out}")
        written = (log or {}).get("file")
        if written is not None and self.own.owns(written) is None and os.path.exists(written):
            self.failures.append(f"the logger says its recording is {written}, which is not a file this serve's "
                                 f"loggers created; nothing was renamed")
        summary["file"] = self.name_the_recording(written, bool(self.failures))
        if summary["file"] is None:  # the logger died, not restarted: its part stays partial
            summary["file"] = next((p for p in self._parts() if ".partial" in os.path.basename(p)), None)
        if moved is not None:  # its files are where the directory went (the failure says where), not at --out
            summary["file"] = None
        if isinstance(summary.get("logger"), dict):
            # one path for one recording: the top-level "file" (the logger's own names the file
            # under its partial name, which is gone once serve has named it)
            summary["logger"].pop("file", None)
        summary["failures"] = list(self.failures)
        self.outdir.close()
        self.own.close()
        if self.failures and summary["file"] and ".partial" in os.path.basename(summary["file"]):
            print(f"astrodyn serve: the recording stays at {summary['file']} (serve failed, so it keeps its partial "
                  f"name); `astrodyn recover {summary['file']}` finishes it and gives it its name",
                  file=sys.stderr, flush=True)
        return summary

    def name_the_recording(self, written: str | None, failed: bool) -> str | None:
        """The logger leaves its last file as ``NAME.partial.mcap`` (or ``NAME-000k.partial.mcap``
        when rolling); a stop that ends a healthy service renames it to its name, a failed
        one leaves it for ``astrodyn recover`` (docs/reliability.md)."""

        from astrodyn.recording.writer import fsync_directory

        final = finished_name(written) if written else None
        if written is None or final is None or failed:
            return written
        if not os.path.exists(written):  # removed or moved while serve recorded: never "done" (exit 1)
            self.failures.append(f"the recording {written} is gone (removed or moved while serve recorded); "
                                 f"nothing was renamed")
            return None
        try:
            os.replace(written, final)
        except OSError as exc:
            self.failures.append(f"cannot name the recording {final}: {exc.strerror or exc}; it stays at {written}")
            return written
        fsync_directory(final)
        return final

    def close(self) -> None:
        for ch in self.controllers.values():
            ch.stop(signal.SIGTERM, timeout=5)
            ch.close()
        for ch in [*self.children.values(), *self.standbys.values()]:
            ch.stop()
            ch.close()
        self.beats.close()
        self.alive.close()
        self.events.close()
        self.event_seqs.close()
        self.commands.undeclare()


def sim_time(t) -> str:
    """``sim t 5.6 s`` for a failure message (``sim t unknown`` before the first heartbeat)."""
    return f"sim t {t:.6g} s" if isinstance(t, (int, float)) else "sim t unknown"


def control_token_path(out: Path) -> Path:
    """Where ``serve`` stores the control token of the run recording ``out`` (mode 0600):
    ``.<file name>.control-token`` beside it (``.x.mcap.control-token`` for ``x.mcap``): one
    file per recording path, so serves of ``x.mcap`` and ``x.MCAP`` / ``x.rec`` in one
    directory never share (and replace, and remove) one token file."""
    return out.parent / f".{out.name}.control-token"


#: ``--roll-size`` bytes and ``--roll-interval`` wall seconds: the ranges of a config's
#: ``output.roll_size`` and ``output.roll_interval`` (astrodyn.scenario).
ROLL_SIZE_BOUNDS = (2**20, 2**50)
ROLL_INTERVAL_BOUNDS = (1.0, 250 * 365.25 * 86400.0)
#: ``--restart-window`` wall seconds (a hidden flag, for tests: the restart budget's window).
RESTART_WINDOW_BOUNDS = (0.1, 86400.0)
#: Wall seconds between rolled files when neither ``--roll-interval`` nor the config's
#: ``output.roll_interval`` says: hourly files keep each file's chunk index (held in the
#: logger's memory for its summary) small (docs/soak.md).
ROLL_INTERVAL_DEFAULT_S = 3600.0


def roll_settings(args: argparse.Namespace, scenario) -> tuple[int | None, float]:
    """``(bytes, wall seconds)`` after which serve's logger starts a new file: each flag
    (``--roll-size``, ``--roll-interval``) when given, else the config's ``[output]``
    ``roll_size`` / ``roll_interval``, else no size limit and :data:`ROLL_INTERVAL_DEFAULT_S`."""
    size = args.roll_size if args.roll_size is not None else scenario.roll_size
    interval = args.roll_interval if args.roll_interval is not None else scenario.roll_interval
    return size, (interval if interval is not None else ROLL_INTERVAL_DEFAULT_S)


@contextlib.contextmanager
def control_token(out: Path, open_control: bool) -> Iterator[tuple[str | None, Path | None, Callable[[], None]]]:
    """``(token, file, write)``: serve's control token (docs/security.md), its 0600 file
    ``.<file name>.control-token`` beside ``out`` (:func:`control_token_path`), and ``write()``, which writes that file
    (replacing a previous serve's, whose token is never valid again).  ``write`` is to be
    called only once this serve owns ``out`` (its logger is ready,
    :class:`Supervisor`'s ``own_output``): a serve refused because another one records to
    ``out`` must not take the token file of the one that runs.  The file is removed when
    serve ends, only if it is still the one this serve wrote.  ``(None, None, no-op)`` with
    ``--open-control``.  StartError if the file cannot be written."""
    if open_control:
        yield None, None, lambda: None
        return
    token, path = auth.new_token(), control_token_path(out)
    written: list[tuple[int, int]] = []

    def write() -> None:
        path.unlink(missing_ok=True)  # a previous run's token: never valid again
        try:
            auth.write_private_file(path, token.encode())
            st = os.lstat(path)
        except OSError as exc:
            raise StartError(f"{path}: cannot write the control token: {exc.strerror or exc}") from None
        written.append((st.st_dev, st.st_ino))

    try:
        yield token, path, write
    finally:
        with contextlib.suppress(OSError):
            st = os.lstat(path)
            if written and (st.st_dev, st.st_ino) == written[0]:  # ours: never another serve's
                path.unlink()


def check_serve_flags(args: argparse.Namespace) -> bus.ZenohConfigText | None:
    """The numeric flags of ``serve`` argparse does not bound, and the bus flags
    (:func:`~astrodyn.service.runner.check_bus_flags`); ScenarioError naming the flag.
    Returns the ``--zenoh-config`` text as read, once, and checked (None without one)."""
    lo, hi = ROLL_SIZE_BOUNDS
    if args.roll_size is not None and not lo <= args.roll_size <= hi:
        raise ScenarioError(f"--roll-size: expected bytes {lo} (1 MiB) <= N <= {hi} (1 PiB), got {args.roll_size}")
    lo, hi = ROLL_INTERVAL_BOUNDS
    if args.roll_interval is not None and not lo <= args.roll_interval <= hi:  # nan fails too
        raise ScenarioError(f"--roll-interval: expected wall seconds {lo:g} <= S <= {hi:g}, got {args.roll_interval}")
    lo, hi = RESTART_WINDOW_BOUNDS
    if not lo <= args.restart_window <= hi:  # nan fails too
        raise ScenarioError(f"--restart-window: expected wall seconds {lo:g} <= S <= {hi:g}, got {args.restart_window}")
    if args.port is not None and (problem := bus.local_port_problem(args.port)):
        raise ScenarioError(f"--port: {problem}")
    return check_bus_flags(args.connect, args.zenoh_config)


def make_parents(out: Path) -> list[Path]:
    """Create the missing directories above ``out`` (serve's default is ``out/NAME.mcap``);
    returns those it created, top first.  ScenarioError naming ``--out`` when it cannot."""
    missing = [d for d in reversed(out.parent.parents) if not d.exists()] + ([out.parent] if not out.parent.exists() else [])
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ScenarioError(f"--out {str(out)[:200]}: expected a file path in a directory that can be created, got "
                            f"{exc.strerror or exc}: {str(exc.filename)[:200]}") from None
    return missing


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="astrodyn serve", description="Long-running real-time service controlled over Zenoh.")
    ap.add_argument("config", help="scenario TOML file")
    ap.add_argument("--out", help="MCAP file (default out/<scenario>.mcap; rolled files get -0001, -0002, ...)")
    ap.add_argument("--rate", type=bus.rate_argument, default=None,
                    help='real-time factor, or "inf" (default: the scenario\'s real_time_factor)')
    ap.add_argument("--roll-size", type=flag_quantity("bytes", "bytes"), default=None,
                    help='start a new MCAP file after this many bytes ("256 MB", "1 GiB" or a number of bytes; '
                         "default: the config's [output] roll_size, else no size limit)")
    ap.add_argument("--roll-interval", type=flag_quantity("time", "seconds"), default=None,
                    help="start a new MCAP file after this much wall time (\"1 h\", \"90 min\" or seconds; default: "
                         "the config's [output] roll_interval, else 3600: hourly files keep each file's chunk index, "
                         "held in memory for its summary, small)")
    ap.add_argument("--max-wall", type=wall_seconds, default=None, help="stop by itself after this many wall seconds")
    ap.add_argument("--port", type=int, default=None, help="loopback port of the control hub (default: a free one)")
    ap.add_argument("--connect", action="append", default=[], metavar="ENDPOINT", help="also connect to this endpoint (router)")
    ap.add_argument("--zenoh-config", metavar="FILE", help="Zenoh JSON5 config every process starts from (TLS, access control)")
    ap.add_argument("--open-control", action="store_true",
                    help="answer control verbs from anyone who reaches the bus (default: only with this run's control "
                         "token, printed at start and stored in a 0600 file beside --out; docs/security.md)")
    add_foxglove_argument(ap, "the running scene")
    ap.add_argument("--loggers", type=int, default=1, metavar="N",
                    help="loggers recording the run (default 1, at most 8): the 2nd ... Nth are hot standbys, each "
                         "writing a complete file of its own, NAME.logger-2.mcap, ... (docs/reliability.md)")
    ap.add_argument("--controller", action="append", default=None, metavar="CMD",
                    help="closed loop: start this controller program under serve (as with run; docs/control.md)")
    add_stall_argument(ap)
    # for tests only (hidden): the window of each process's restart budget, wall seconds (default
    # RESTART_WINDOW_S, 60); a test shrinks it to check in seconds that deaths spread wider than
    # the window are each restarted and a burst within it is not (Supervisor's restart_window_s)
    ap.add_argument("--restart-window", type=float, default=RESTART_WINDOW_S, help=argparse.SUPPRESS)
    ap.add_argument("--tolerate-rejected", action="store_true",
                    help="exit 0 even when the logger or the plant rejected messages that were not this run's own "
                         "(default: exit 3, the record was attacked; docs/security.md)")
    args = ap.parse_args(argv)
    created: list[Path] = []
    try:
        if args.out == "":
            raise ScenarioError("--out: expected a file path, got an empty string")
        scenario = load(args.config)
        out = Path(args.out) if args.out else (scenario.output_path or Path("out") / f"{scenario.name}.mcap")
        if not 1 <= args.loggers <= MAX_LOGGERS:
            raise ScenarioError(f"--loggers: expected 1 <= N <= {MAX_LOGGERS}, got {args.loggers}")
        zenoh_config = check_serve_flags(args)
        roll_size, roll_interval = roll_settings(args, scenario)
        check_closed_loop_arguments(scenario, args.controller or [], None, out)
        created = make_parents(out)  # the last step before the output checks: nothing is created for a refused flag
        for path in [out, *(Path(standby_path(out, k)) for k in range(2, args.loggers + 1))]:
            checked_output_path(path, (args.config, args.zenoh_config))
            if problem := series_parts_problem(path):  # an earlier serve's rolled parts: never written over
                raise ScenarioError(f"--out {str(path)[:200]}: {problem}")
        rate = args.rate if args.rate is not None else scenario.real_time_factor
        try:
            rate = bus.parse_rate_factor(rate)
        except ValueError:
            raise ScenarioError(f"--rate: expected a real-time factor with {bus.RATE_BOUNDS[0]:g} <= x <= "
                                f"{bus.RATE_BOUNDS[1]:g} (or inf), got {rate}") from None
        check_scenario_free(scenario.name, args.connect, zenoh_config)
    except ScenarioError as exc:
        for d in reversed(created):  # the directories made for --out, left as they were
            with contextlib.suppress(OSError):
                d.rmdir()
        print(f"astrodyn serve: {exc}", file=sys.stderr)
        return 2
    if zenoh_config is not None and (warning := zenoh_config.warning()):
        print(f"astrodyn serve: warning: {warning}", file=sys.stderr)
    hub = bus.loopback_endpoint(args.port or bus.free_port())
    stop_signal = StopFlag()
    job = JobControl()  # Ctrl-Z pauses every process of the service
    try:
        ensure_open_file_limit()
        with work_directory(out, "serve") as tmp, \
                bus.open_session(listen=[hub], config_file=(zenoh_config_copy := zenoh_config_snapshot(zenoh_config, tmp))) \
                as session, \
                control_token(out, args.open_control) as (token, token_file, write_token):
            try:
                sup = Supervisor(scenario, out, session, hub, rate=rate, roll_size=roll_size,
                                 roll_interval=roll_interval, connect=args.connect, tmp=Path(tmp),
                                 zenoh_config=zenoh_config_copy,
                                 foxglove_port=None if args.foxglove is None else (args.foxglove or bus.free_port()),
                                 controllers=args.controller, token_file=token_file, loggers=args.loggers,
                                 stall_s=args.stall_timeout or None, own_output=write_token,
                                 restart_window_s=args.restart_window)
            except (bus.BusError, OSError) as exc:  # the logger could not start: nothing else was started
                print(f"astrodyn serve: {exc}", file=sys.stderr)
                return 1
            stop_requests: list[bus.ControlRequest] = []
            try:
                with bus.ControlServer(session, scenario.name, sup.verbs, token=token) as control:
                    # the first line once the verbs are answered: a client that reads it and asks
                    # for status at once gets an answer (before: the queryable came after the line).
                    # Strict JSON, as the status reply: a float that is not finite is its word
                    # ("inf", as status says), never the Infinity / NaN jq and JSON.parse refuse
                    print(json.dumps(jsonable({"serving": scenario.name, "hub": hub,
                                               "control": f"astrodyn/{scenario.name}/@control/<verb>",
                                               "verbs": list(sup.verbs), "out": str(out), "real_time_factor": rate,
                                               "roll_size": roll_size, "roll_interval_s": roll_interval,
                                               "foxglove": sup.viewer_url, "control_token": token,
                                               "control_token_file": None if token_file is None else str(token_file)})),
                          flush=True)
                    t_end = None if args.max_wall is None else time.monotonic() + args.max_wall
                    while True:
                        stopping = False
                        for req in control.poll():
                            if req.handled_by(sup.handle):
                                stop_requests.append(req)
                                stopping = True
                        if (paused_s := job.take_resumed()) is not None:
                            sup.resume_schedule(paused_s)
                        sup.check_children()
                        if stop_signal.why or stopping or sup.state == "failed" or \
                                (t_end is not None and time.monotonic() - job.suspended_s > t_end):
                            break
                        if all(sup.children[k].poll() is not None for k in sup.propagators):
                            break
                        time.sleep(0.02)
                    summary = sup.stop()
                    for req in stop_requests:
                        req.reply(summary)
            finally:
                sup.close()
    except (StartError, bus.BusError) as exc:  # nothing was started (the hub's session did not open)
        print(f"astrodyn serve: error: {exc}", file=sys.stderr)
        return 1
    print(json.dumps(jsonable(summary), default=str), flush=True)  # strict JSON, as the first line
    if summary.get("plant"):  # as run's end line: applied, refused, late, waiting, controllers' errors
        print(f"astrodyn serve: {closed_loop_line(summary['plant'])}", file=sys.stderr, flush=True)
    if summary["failures"]:
        return 1
    attack = attack_report(summary.get("logger"), summary.get("plant"))
    if attack:
        print(f"astrodyn serve: ATTACKED: {attack}", file=sys.stderr, flush=True)
        if not args.tolerate_rejected:
            return EXIT_REJECTED
    return 0
