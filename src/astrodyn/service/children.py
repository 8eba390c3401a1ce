"""Child processes of a supervisor (``astrodyn run``, ``astrodyn serve``): how each is
started, watched and stopped.

Every process of a run is started from the installed package (``python -m ...``), never
from a path in the source tree, so a plain ``pip install .`` runs every command
(docs/architecture.md, "Processes").  Each child gets its own session (a signal to the
supervisor's terminal group does not reach it) and its stdout / stderr go to files in
the supervisor's work directory, each stream kept within :data:`OUTPUT_CAP_BYTES` there
(:class:`CappedOutput`); :meth:`Child.summary` reads the one-line JSON summary a process
prints last.

Fate sharing: no child outlives its supervisor by more than about 2 s, whatever kills the
supervisor and whenever.  :class:`Child` hands every child the supervisor's PID
(:data:`SUPERVISOR_ENV`); the child calls :func:`share_fate_with_supervisor` first thing:
on Linux ``prctl(PR_SET_PDEATHSIG, SIGTERM)`` (the kernel signals it when the supervisor
dies), then a check that its parent is still that PID (the supervisor may have died
between ``fork`` and the ``prctl``), and a watcher thread that polls the parent every
0.2 s (any OS).  Orphaned, a child stops as on SIGTERM (a logger finishes its file) and
is made to exit after :data:`ORPHAN_GRACE_S` at the latest.

The work directory (:func:`work_directory`) lies beside the recording, so what a killed
supervisor leaves there is found and removed by ``astrodyn recover``.
"""

from __future__ import annotations

import argparse
import contextlib
import ctypes
import math
import os
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
import weakref
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

from astrodyn import auth, bus, messages
from astrodyn.signals import STOP_SIGNAL_NAMES, catch_job_control, suspended_s

if TYPE_CHECKING:
    from astrodyn.scenario import Scenario

__all__ = ["Child", "CappedOutput", "OUTPUT_CAP_BYTES", "config_snapshot", "zenoh_config_snapshot", "child_bus_arguments", "ensure_open_file_limit", "MIN_OPEN_FILES", "wait_ready", "children_of", "logger_command", "propagator_command", "plant_command", "controller_argv", "start_controller", "share_fate_with_supervisor",
           "stop_process", "stop_process_group", "work_directory", "SUPERVISOR_ENV", "ORPHAN_GRACE_S", "EXIT_ORPHANED", "LOGGED_WAIT_S",
           "MODEL_ENDED_EXIT", "DISK_FULL_EXIT", "OUT_IN_THE_WAY_EXIT", "StartError", "JobControl", "JOB_STOP_WAIT_S", "catches_signal", "is_stopped"]

#: Environment variable that carries the supervisor's PID to each child.
SUPERVISOR_ENV = "ASTRODYN_SUPERVISOR_PID"
#: Seconds an orphaned child has to stop cleanly after its SIGTERM before it is made to exit.
ORPHAN_GRACE_S = 1.5
#: Exit status of a child that found its supervisor gone.
EXIT_ORPHANED = 70
#: Exit status of a propagator whose model cannot go on (a rolling disk fell flat): every
#: state before that is published and logged; a supervisor (``run``, ``serve``) does not
#: restart it (it would end there again) and the run fails naming the body and the time.
MODEL_ENDED_EXIT = 4
#: Exit status of a logger whose disk is full (ENOSPC, EDQUOT): its file holds what was
#: flushed before (truncated, readable); a supervisor does not restart it (a new logger
#: would fail the same way) and the run fails saying so.
DISK_FULL_EXIT = 5
#: Exit status of a logger that cannot create its file because something is in its place
#: (another run's or serve's live recording, a killed run's partial file, a symbolic
#: link): a supervisor never starts another logger for it (it would take the other
#: recorder's file, or fail the same way) and the run fails with the logger's words.
OUT_IN_THE_WAY_EXIT = 6
#: Seconds a process waits, after its end-of-run event, for the logger's receipt of it
#: (``astrodyn.service.propagator.wait_until_logged``) before it closes its session.
LOGGED_WAIT_S = 60.0
_PR_SET_PDEATHSIG = 1


def share_fate_with_supervisor(poll_s: float = 0.2) -> int | None:
    """Make this process end when the supervisor that started it ends (module docstring).

    Does nothing (returns None) in a process not started by a supervisor; returns the
    supervisor's PID otherwise.  Call it before any long work, in the main thread."""
    text = os.environ.get(SUPERVISOR_ENV)
    if not text or not text.isdigit():
        return None
    supervisor = int(text)
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0)
        except (OSError, AttributeError):
            pass  # the watcher thread below still holds
    if os.getppid() != supervisor:  # it died before the prctl took effect
        os._exit(EXIT_ORPHANED)

    def watch() -> None:
        while os.getppid() == supervisor:
            time.sleep(poll_s)
        try:
            os.kill(os.getpid(), signal.SIGTERM)  # stop as on SIGTERM: a logger finishes its file
        except OSError:
            pass
        time.sleep(ORPHAN_GRACE_S)
        os._exit(EXIT_ORPHANED)

    threading.Thread(target=watch, name="astrodyn-supervisor-watch", daemon=True).start()
    return supervisor


class StartError(Exception):
    """A run or serve cannot start (e.g. its work directory cannot be written: the disk is
    full); the text names the path and why.  Nothing has been started."""


#: Open files a supervisor and its children need at the least (each child: its two log
#: files, pipes, zenoh's sockets; a supervisor with 8 loggers and a live view: ~40).
MIN_OPEN_FILES = 64
#: The soft open-file limit a supervisor raises itself to when the hard limit allows.
WANTED_OPEN_FILES = 1024


def ensure_open_file_limit() -> int:
    """Raise this process's soft open-file limit (``ulimit -n``; children inherit it) to
    :data:`WANTED_OPEN_FILES` when it is lower and the hard limit allows; return the limit.
    StartError naming the limit when even :data:`MIN_OPEN_FILES` cannot be had: with too few
    descriptors a start fails half-way, in a traceback or a panic inside zenoh."""
    import resource

    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if soft != resource.RLIM_INFINITY and soft < WANTED_OPEN_FILES:
        wanted = WANTED_OPEN_FILES if hard == resource.RLIM_INFINITY else min(WANTED_OPEN_FILES, hard)
        if wanted > soft:
            with contextlib.suppress(ValueError, OSError):
                resource.setrlimit(resource.RLIMIT_NOFILE, (wanted, hard))
                soft = wanted
    if soft != resource.RLIM_INFINITY and soft < MIN_OPEN_FILES:
        raise StartError(f"open-file limit: expected at least {MIN_OPEN_FILES} (ulimit -n), got {soft} and the hard "
                         f"limit is {hard}; raise it (ulimit -n {MIN_OPEN_FILES}) and start again")
    return soft


@contextlib.contextmanager
def work_directory(beside: Path, kind: str) -> Iterator[Path]:
    """A private directory ``.astrodyn-<kind>-XXXX`` beside ``beside`` (the recording), with
    the supervisor's PID in ``supervisor.pid``; removed on exit.  A killed supervisor's is
    found by that PID and removed by ``astrodyn recover``.  :class:`StartError` if it
    cannot be made."""
    folder = Path(beside).resolve().parent
    try:
        path = Path(tempfile.mkdtemp(prefix=f".astrodyn-{kind}-", dir=folder))
    except OSError as exc:
        raise StartError(f"{folder}: cannot make the {kind}'s work directory there: {exc.strerror or exc}") from None
    try:
        try:
            (path / "supervisor.pid").write_text(str(os.getpid()))
        except OSError as exc:
            raise StartError(f"{path}: cannot write the {kind}'s work directory: {exc.strerror or exc}") from None
        yield path
    finally:
        shutil.rmtree(path, ignore_errors=True)


def config_snapshot(scenario: Scenario, work: Path) -> Path:
    """Write the TOML text ``scenario`` was loaded from to ``work/config.toml`` (readable by
    the user only) and return its path: the config every process of the run loads.

    The supervisor reads the file the user named once: a process started or restarted later
    (a crash, hours into ``serve``) must not run a file edited since, and a config given as a
    pipe (``astrodyn run <(generate)``) can be read only once.  StartError for a scenario
    without text (built with ``load_dict``) or a work directory that cannot take the file."""
    if scenario.text is None:
        raise StartError(f"scenario {scenario.name!r} ({scenario.source}) has no config text to hand to its "
                         f"processes; load it with astrodyn.scenario.load() or loads()")
    path = Path(work) / "config.toml"
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(scenario.text)
    except OSError as exc:
        raise StartError(f"{path}: cannot write the run's copy of its config: {exc.strerror or exc}") from None
    return path


def zenoh_config_snapshot(zenoh_config: bus.ZenohConfigText | None, work: Path) -> Path | None:
    """Write the ``--zenoh-config`` text the supervisor read and checked at the start
    (:func:`astrodyn.bus.read_zenoh_config`) to ``work/zenoh-config.<ext>`` (readable by the
    user only) and return its path: the Zenoh config of the supervisor's own session and of
    every process it starts or restarts; None without one.

    As for :func:`config_snapshot`: the user's file is read once, so a process restarted
    hours later does not load a file edited, deleted or replaced (by a FIFO, which blocked
    its read for good) since.  StartError if the work directory cannot take the file."""
    if zenoh_config is None:
        return None
    try:
        return zenoh_config.write(work)
    except OSError as exc:
        raise StartError(f"{work}: cannot write the run's copy of {zenoh_config.label}: {exc.strerror or exc}") from None


def child_bus_arguments(hub: str, connect: list[str] | tuple[str, ...], zenoh_config_copy: Path | None) -> list[str]:
    """The bus flags of every process a supervisor starts: ``--connect`` to its ``hub`` and to
    each of ``connect`` (a router), and ``--zenoh-config`` naming the supervisor's copy
    (:func:`zenoh_config_snapshot`), never the user's file."""
    argv = sum((["--connect", e] for e in [hub, *connect]), [])
    return argv + (["--zenoh-config", str(zenoh_config_copy)] if zenoh_config_copy is not None else [])


def children_of(parent: int) -> dict[int, list[str]]:
    """The live child processes of ``parent`` with their command lines (Linux ``/proc``:
    what ``ps`` shows any user); processes that vanish while being read are skipped."""
    found: dict[int, list[str]] = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat", "rb") as f:
                ppid = int(f.read().rsplit(b")", 1)[1].split()[1])
            if ppid != parent:
                continue
            with open(f"/proc/{entry}/cmdline", "rb") as f:
                argv = f.read().split(b"\0")
        except (OSError, ValueError, IndexError):
            continue
        found[int(entry)] = [a.decode(errors="replace") for a in argv if a]
    return found


def stop_process(proc: subprocess.Popen, sig: int = signal.SIGTERM, timeout: float = 10.0) -> int | None:
    """Stop a process this program started, by its PID: ``sig`` (SIGTERM: it finishes what
    it holds), wait up to ``timeout`` s, then SIGKILL.  Returns its exit status."""
    if proc.poll() is None:
        try:
            os.kill(proc.pid, sig)
            proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            os.kill(proc.pid, signal.SIGKILL)
            proc.wait(timeout=5)
        except ProcessLookupError:
            pass
    return proc.returncode


def stop_process_group(proc: subprocess.Popen, sig: int = signal.SIGTERM, timeout: float = 10.0) -> int | None:
    """Stop ``proc``, a process this program started as the leader of a new session
    (``start_new_session=True``: its process group is its PID), and every process of that
    group: ``sig`` to the group, up to ``timeout`` s for the leader, then SIGKILL to what is
    left of the group (a grandchild that ignored ``sig`` or was still ending).  A process
    that left the group (``setsid`` of its own) is out of reach.  Returns the leader's
    exit status."""
    def signal_group(s: int) -> bool:
        try:
            os.killpg(proc.pid, s)  # the group outlives its reaped leader while members are left
        except (ProcessLookupError, PermissionError):
            return False
        return True

    signal_group(sig)
    try:
        proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        pass
    deadline = time.monotonic() + min(timeout, 2.0)
    while signal_group(0) and time.monotonic() < deadline:  # members still ending after the signal
        time.sleep(0.05)
    signal_group(signal.SIGKILL)
    if proc.poll() is None:
        proc.wait(timeout=5)
    return proc.returncode


def logger_command() -> list[str]:
    """The command line that starts a logger process with this interpreter; arguments follow."""
    return [sys.executable, "-m", "astrodyn.service.logger"]


def propagator_command(kind: str) -> list[str]:
    """The command line that starts a ``kind`` (``orbit`` or ``attitude``) propagator process
    with this interpreter; arguments follow."""
    if kind not in ("orbit", "attitude"):
        raise ValueError(f"propagator kind: expected 'orbit' or 'attitude', got {kind!r}")
    return [sys.executable, "-m", "astrodyn.service.propagator", kind]


def plant_command() -> list[str]:
    """The command line that starts the closed loop's plant process; arguments follow."""
    return [sys.executable, "-m", "astrodyn.service.plant"]


def _die_with_parent() -> None:  # pragma: no cover - runs in the child between fork and exec
    """``PR_SET_PDEATHSIG``: the kernel sends SIGTERM to the child when the supervisor dies.
    For programs that are not astrodyn's (controllers), which cannot call
    :func:`share_fate_with_supervisor` themselves."""
    try:
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(_PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0)
    except (OSError, AttributeError):
        pass


def controller_argv(cmd: str) -> list[str]:
    """The argv of ``--controller CMD``: split like a shell line (``shlex``), run without a
    shell; a leading ``python`` / ``python3`` is astrodyn's own interpreter (the one with
    zenoh installed), whatever ``python`` is on the PATH."""
    argv = shlex.split(cmd)
    if argv and argv[0] in ("python", "python3"):
        argv[0] = sys.executable
    return argv


def start_controller(name: str, cmd: str, scenario: str, hub: str, log_dir: Path, child_env: dict | None,
                     token_file: Path | None) -> Child:
    """A closed-loop controller (``run`` / ``serve`` ``--controller CMD``; docs/control.md):
    the user's program, with the run's bus, name and credentials in its environment and
    the kernel's promise to end it with the supervisor."""
    env = {**(child_env or {}), "ASTRODYN_SCENARIO": scenario, "ASTRODYN_CONTROLLER": name, "ASTRODYN_CONNECT": hub}
    if token_file is not None:
        env[auth.TOKEN_ENV] = str(token_file)
    return Child(f"controller-{name}", controller_argv(cmd), log_dir, env=env, foreign=True)


#: A propagator or logger with no heartbeat for this many wall seconds (ten times that, and at
#: least :data:`PREPARE_GRACE_S`, while it starts or prepares) is hung: the supervisor kills it and handles it as a crash (``--stall-timeout``).
STALL_S = 120.0
#: Wall seconds at the least a child is given before it counts as hung while it starts (no
#: heartbeat yet) or says ``preparing``, whatever ``--stall-timeout``: its numeric kernels
#: compile then, on a cold cache (a fresh install) 30-55 s each on this project's 2-core
#: machine and more under load (docs/benchmarks.md).  Ten times ``--stall-timeout`` alone
#: killed them mid-compile under a short limit (2 s: 20 s), and each restart compiled again.
PREPARE_GRACE_S = 300.0


def wall_seconds(text: str, zero: bool = False) -> float:
    """An argparse type: wall seconds, a finite number > 0 (``--timeout``, ``--max-wall``);
    ``zero``: 0 too (meaning never: ``--stall-timeout``)."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (0.0 <= value if zero else 0.0 < value) or not value < math.inf:  # nan fails both
        raise argparse.ArgumentTypeError(f"expected wall seconds, a finite number {'>= 0 (0: never)' if zero else '> 0'}, "
                                         f"got {text!r}")
    return value


def add_stall_argument(ap: argparse.ArgumentParser) -> None:
    """``--stall-timeout S`` (``run`` and ``serve``): :data:`STALL_S` by default."""
    ap.add_argument("--stall-timeout", type=lambda text: wall_seconds(text, zero=True), default=STALL_S, metavar="S",
                    help=f"a propagator or logger with no heartbeat for S wall seconds is hung: killed and restarted "
                         f"like a crashed one (default {STALL_S:g}; 0: never; docs/reliability.md)")


#: Seconds of a child's life (on its supervisor's listening clock) before what the logger
#: says of it is taken into account (:meth:`Child.kill_if_lost_to_logger`).
REACH_GRACE_S = 10.0
#: Seconds a gap in a child's state channels must stay open before it counts as lost (late
#: arrivals fill short ones).
HOLE_GRACE_S = 3.0
#: Seconds within which the supervisor must have heard both the logger and the child.
FRESH_S = 2.0
#: Seconds the supervisor must have heard a child without a break (no silence over
#: :data:`FRESH_S`) before the logger's word that it does not hear the child counts.  A child
#: that was silent for a while (its numeric kernels compiling on a cold cache of a loaded
#: machine: 30-50 s; a stop) and beats again is heard by the logger too within a report or
#: two (every 0.5 s), while its last report still speaks of the silence: without the wait the
#: child was killed and restarted for it, and its states recorded twice.
REACH_STREAK_S = 3.0


def logger_report_on(beats, process: str) -> tuple[float | None, int | None]:
    """What the logger's last heartbeat on ``beats`` (its
    :meth:`~astrodyn.service.logger.Logger.reach_report`) says of ``process``: the seconds
    it has not heard it (``unheard``) and the first step missing in its state channels
    (``holes``), each None when not said or not a finite number / an output step (0 ..
    :data:`astrodyn.messages.MAX_SEQ`)."""
    report = beats.last.get("logger")
    report = report if isinstance(report, dict) else {}
    unheard, holes = report.get("unheard"), report.get("holes")
    silent = unheard.get(process) if isinstance(unheard, dict) else None
    first = holes.get(process) if isinstance(holes, dict) else None
    if isinstance(silent, bool) or not isinstance(silent, (int, float)) or not math.isfinite(silent):
        silent = None
    if isinstance(first, bool) or not isinstance(first, int) or not 0 <= first <= messages.MAX_SEQ:
        first = None
    return silent, first


#: Bytes of one output stream (stdout or stderr) of a child kept on disk, in two files of at
#: most half as much each (:class:`CappedOutput`): its newest output, what a failure quotes.
OUTPUT_CAP_BYTES = 4 * 1024 * 1024
#: Seconds between two looks at the size of the output files astrodyn's own processes write
#: themselves (:class:`CappedOutput`, not piped).
OUTPUT_POLL_S = 0.2
#: Longest wait, once a piped child has ended, for the rest of its output to reach the file
#: (a process it started may hold the pipe open after it).
OUTPUT_SETTLE_S = 1.0


class CappedOutput:
    """One output stream (stdout or stderr) of a child, kept on disk within ``cap`` bytes:
    ``path`` holds the newest output and ``path.1`` (:attr:`older`) the ``cap / 2`` bytes
    before it; whatever came earlier is dropped (:attr:`dropped` bytes).  A chatty controller
    (1 kB a tick at 100 Hz is 8.6 GB a day) thus never fills the disk that holds the
    recording, and its last lines, which a failure quotes, are kept.

    ``piped`` (a program that is not astrodyn's: a controller): the child writes into a pipe
    that a thread of the supervisor drains at once into the files (a child is never held up
    by a full pipe while its supervisor runs), so the cap holds to the byte.  Not piped
    (astrodyn's own processes, which print little): the child writes the file itself,
    appending (``O_APPEND``), so it leaves its last words there even when its supervisor is
    gone; a thread of the supervisor looks at its size every :data:`OUTPUT_POLL_S` and, past
    ``cap / 2``, moves the newest ``cap / 2`` bytes to ``path.1`` (what the child wrote
    during the move included) and empties ``path`` (what the child writes in the few
    microseconds between the last look and the emptying is lost; ``path`` may pass ``cap /
    2`` by what the child writes in :data:`OUTPUT_POLL_S`, ``path.1`` never does).

    Call :meth:`start` with the child's process once it is started, and :meth:`close` when
    done with it."""

    def __init__(self, path: Path, piped: bool, cap: int = OUTPUT_CAP_BYTES):
        if cap < 2:
            raise ValueError(f"cap: expected at least 2 bytes, got {cap}")
        self.path = Path(path)
        self.older = self.path.with_name(self.path.name + ".1")
        self.piped = piped
        self.half = cap // 2
        self.dropped = 0  # bytes of output no longer on disk
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._stopping = threading.Event()
        self._proc: subprocess.Popen | None = None
        if piped:
            self._read_end, self.child_end = os.pipe()
            with contextlib.suppress(OSError, AttributeError):  # Linux: room for 1 MB while the thread is busy
                import fcntl

                fcntl.fcntl(self.child_end, getattr(fcntl, "F_SETPIPE_SZ", 1031), 1 << 20)
            try:
                self._file = open(self.path, "wb", buffering=0)  # the drain thread closes it
            except OSError:
                os.close(self._read_end)
                os.close(self.child_end)
                raise
            self._size = 0
        else:
            self.child_end = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_APPEND | os.O_CLOEXEC, 0o600)

    def start(self, proc: subprocess.Popen) -> None:
        """The child ``proc`` started with :attr:`child_end` as its stream: close this
        process's copy of it and start the thread that keeps the files within the cap."""
        self._proc = proc
        os.close(self.child_end)
        target = self._drain if self.piped else self._watch
        self._thread = threading.Thread(target=target, name=f"astrodyn-output-{self.path.name}", daemon=True)
        self._thread.start()

    def abandon(self) -> None:
        """The child could not be started: release what :meth:`__init__` opened."""
        with contextlib.suppress(OSError):
            os.close(self.child_end)
        if self.piped:
            with contextlib.suppress(OSError):
                os.close(self._read_end)
            self._file.close()

    def _drain(self) -> None:
        try:
            while True:
                try:
                    chunk = os.read(self._read_end, 1 << 16)
                except InterruptedError:
                    continue
                except OSError:
                    break
                if not chunk:
                    break  # every writer has closed it: the child (and what it started) ended
                self._keep(chunk)
        finally:
            with contextlib.suppress(OSError):
                os.close(self._read_end)
            with self._lock:
                with contextlib.suppress(OSError):
                    self._file.close()

    def _keep(self, chunk: bytes) -> None:
        """Append ``chunk`` to the newest file, moving it to :attr:`older` each time it holds
        ``cap / 2`` bytes.  A file that cannot be written (the disk is full, the work directory
        gone) drops what it cannot take: the child must never wait for it."""
        with self._lock:
            while chunk:
                room = self.half - self._size
                part, chunk = chunk[:room], chunk[room:]
                try:
                    if not self._file.closed:
                        self._file.write(part)
                except OSError:
                    self.dropped += len(part)
                self._size += len(part)
                if self._size >= self.half:
                    self._rotate_piped()

    def _rotate_piped(self) -> None:
        if self.older.exists():
            self.dropped += self.half
        try:
            self._file.close()
            os.replace(self.path, self.older)
            self._file = open(self.path, "wb", buffering=0)  # closed by the drain thread
        except OSError:
            pass  # the work directory is gone: the child is being stopped; what follows is dropped
        self._size = 0

    def _watch(self) -> None:
        while not self._stopping.wait(OUTPUT_POLL_S):
            self._trim_file()
            if self._proc is not None and self._proc.poll() is not None:
                self._trim_file()
                return

    def _trim_file(self) -> None:
        """Not piped: past ``cap / 2``, move the newest ``cap / 2`` bytes of the file the
        child appends to into :attr:`older` and empty the file."""
        try:
            if os.stat(self.path).st_size <= self.half:
                return
            with self._lock, open(self.path, "rb+") as f:  # a reader sees both files before or after
                size = os.fstat(f.fileno()).st_size
                f.seek(size - self.half)
                tail = f.read(self.half)
                done = size  # what the child wrote meanwhile follows, up to the moment the file is emptied
                while (end := os.fstat(f.fileno()).st_size) > done:
                    f.seek(done)
                    tail += f.read(end - done)
                    done = end
                f.truncate(0)
                kept = tail[-self.half:]  # the newest cap / 2 bytes, however much came during the move
                tmp = self.older.with_name(self.older.name + ".tmp")
                tmp.write_bytes(kept)
                os.replace(tmp, self.older)
            self.dropped += done - len(kept)
        except OSError:
            pass

    def settle(self, timeout: float = OUTPUT_SETTLE_S) -> None:
        """Piped, once the child has ended: wait (at most ``timeout`` s) until the drain
        thread has written all it will get, so the files end with the child's last words."""
        if self.piped and self._thread is not None and self._proc is not None and self._proc.poll() is not None:
            self._thread.join(timeout)

    def tail(self, max_bytes: int | None = None) -> bytes:
        """The newest output on disk (``older`` then ``path``), its last ``max_bytes`` only
        if given."""
        self.settle()
        with self._lock:
            parts = []
            for path in (self.older, self.path):
                try:
                    parts.append(path.read_bytes())
                except OSError:
                    continue
        data = b"".join(parts)
        return data if max_bytes is None else data[-max_bytes:]

    def close(self) -> None:
        """Stop watching (the files stay): a piped stream's thread ends when every writer has
        closed the pipe; it is waited for a moment only (a process the child started may
        still hold it, and the thread drains it meanwhile)."""
        self._stopping.set()
        if self._thread is not None:
            self._thread.join(OUTPUT_SETTLE_S if self.piped else 1.0)


class Child:
    """One child process: ``argv`` started in its own session, stdout / stderr to
    ``log_dir/<name>.out|.err``, each kept within :data:`OUTPUT_CAP_BYTES` on disk
    (:class:`CappedOutput`); ``env`` adds variables to the supervisor's environment
    (e.g. :data:`astrodyn.auth.SECRET_ENV`, the path of the run secret).  ``foreign``: a
    program that is not astrodyn's (a controller): the kernel ends it with the supervisor,
    and its output goes through a pipe the supervisor drains."""

    def __init__(self, name: str, argv: list[str], log_dir: Path, env: dict[str, str] | None = None,
                 foreign: bool = False):
        self.name = name
        self.foreign = foreign
        self.stdout_path = log_dir / f"{name}.out"
        self.stderr_path = log_dir / f"{name}.err"
        self.stdout = CappedOutput(self.stdout_path, piped=foreign)
        try:
            self.stderr = CappedOutput(self.stderr_path, piped=foreign)
        except BaseException:
            self.stdout.abandon()
            raise
        try:
            self.proc = subprocess.Popen(argv, stdout=self.stdout.child_end, stderr=self.stderr.child_end,
                                         stdin=subprocess.DEVNULL, start_new_session=True,
                                         preexec_fn=_die_with_parent if foreign else None,
                                         env={**os.environ, **(env or {}), SUPERVISOR_ENV: str(os.getpid())})
        except BaseException:
            self.stdout.abandon()
            self.stderr.abandon()
            raise
        self.stdout.start(self.proc)
        self.stderr.start(self.proc)
        _STARTED.add(self)
        self.started = time.monotonic()
        self.started_listening: float | None = None  # the supervisor's listening clock at the start
        self.stalled_s: float | None = None  # set when kill_if_stalled ended it
        self.lost_to_logger: str | None = None  # why kill_if_lost_to_logger ended it
        self._hole: tuple[int, float] | None = None  # (first missing step, listening_s when first reported)
        self._heard_since: float | None = None  # listening_s since which the supervisor hears it without a break
        self.refill_from: int | None = None  # the first step the logger misses, when that is why it was killed
        self.asked_to_stop = False  # set by stop(): its supervisor signalled it (a stop signal's exit is then wanted)
        self._exit_reason: str | None = None  # the reason its summary gives, once it exited 0

    def outside_stop_signal(self, rc: int | None) -> str | None:
        """The stop signal (``"SIGTERM"``, ``"SIGINT"``, ``"SIGHUP"``) a child that exited 0
        says it stopped on (the ``reason`` of its summary line), when its supervisor did not
        ask it to stop (:meth:`stop`): someone else signalled it (``kill PID``, a cgroup or
        OOM manager), so it ended before its work was done and is handled as a crash
        (restarted, or the run fails naming it).  None otherwise: still running, any other
        exit, or its own end (its scenario's end, a ``stop`` from its supervisor, its model
        ended)."""
        if rc != 0 or self.asked_to_stop:
            return None
        if self._exit_reason is None:  # read once: it exited, its summary is written
            self._exit_reason = str((self.summary() or {}).get("reason", ""))
        return self._exit_reason if self._exit_reason in STOP_SIGNAL_NAMES else None

    def how(self, rc: int) -> str:
        """How it ended, for a failure message."""
        if (sig := self.outside_stop_signal(rc)) is not None:
            return f"stopped on a {sig} its supervisor did not send (exit status 0: `kill {self.pid}`?)"
        if self.stalled_s is not None:
            return f"stalled (no heartbeat for {self.stalled_s:.0f} s) and was killed"
        if self.lost_to_logger is not None:
            return f"was cut off from the logger{'' if rc == 0 else ' and killed'}: {self.lost_to_logger}"
        if rc == DISK_FULL_EXIT:
            return f"exited with status {rc} (its disk is full)"
        return f"killed by signal {-rc}" if rc < 0 else f"exited with status {rc}"

    def kill_if_stalled(self, beats, limit_s: float | None, now: float) -> bool:
        """SIGKILL this child (by PID) when it runs but is silent: no heartbeat on
        ``beats`` (an :class:`astrodyn.bus.HeartbeatMonitor`, keyed by :attr:`name`) for
        ``limit_s`` wall seconds since its last one; ten times that, and at least
        :data:`PREPARE_GRACE_S`, before its first one (it starts: imports, its session; on a
        loaded machine a short ``--stall-timeout`` killed healthy children there) and while
        its last one says ``preparing`` (the numeric kernels compile).  A hung
        process (deadlock, SIGSTOP, an endless loop) thus ends like a crash and takes the
        same path: restarted, or the run fails naming it (:meth:`how`).  None or 0: never.

        Silence is counted on the supervisor's listening clock (``beats.listening_s``), not
        on the wall clock: while the supervisor itself was stopped (Ctrl-Z, SIGSTOP, a paused
        VM) it heard nothing, and a healthy child must not be killed for that."""
        if not limit_s or self.stalled_s is not None or self.proc.poll() is not None:
            return False
        self.listened_since_start(beats, now)
        heard_since_start = beats.seen.get(self.name, 0.0) > self.started  # not its predecessor's
        since = beats.heard[self.name] if heard_since_start else self.started_listening
        silent_s = beats.listening_s - since
        starting = not heard_since_start or beats.last.get(self.name, {}).get("preparing")
        if silent_s <= (max(10 * limit_s, PREPARE_GRACE_S) if starting else limit_s):
            return False
        self.stalled_s = silent_s
        self.proc.kill()
        return True

    def listened_since_start(self, beats, now: float) -> float:
        """Seconds of the supervisor's listening clock (``beats.listening_s``) since this child
        started; ``now``: the monotonic time (the first call, one loop after the start, fixes
        the start on that clock)."""
        if self.started_listening is None:
            self.started_listening = beats.listening_s - min(now - self.started, bus.LISTENING_GAP_S)
        return beats.listening_s - self.started_listening

    def kill_if_lost_to_logger(self, beats, holes: bool = True) -> bool:
        """SIGKILL this child (by PID) when it runs and beats but what it publishes no longer
        reaches the logger: the logger's heartbeat (:meth:`astrodyn.service.logger.Logger.reach_report`)
        says it has not heard this child for seconds (``unheard``) or, with ``holes``, that
        its state channels have had a gap for :data:`HOLE_GRACE_S` (``holes``).  The bus
        link between the two was lost while both ran (docs/reliability.md: the logger
        stopped for more than 5 s, the whole run paused for more than 10 s) and Zenoh does
        not always link them again, so the states published meanwhile are gone.  Killed, it
        takes the crash path: restarted from the last step the logger holds without a hole,
        which it publishes again.  Judged only on fresh news from both (heard within
        :data:`FRESH_S` of the supervisor's listening clock), once the supervisor has heard
        this child without a break for :data:`REACH_STREAK_S`, and after :data:`REACH_GRACE_S`
        of this child's life (the logger may still speak of its predecessor)."""
        if self.lost_to_logger is not None or self.stalled_s is not None or self.proc.poll() is not None:
            return False
        now = beats.listening_s
        fresh = [now - beats.heard.get(p, -math.inf) <= FRESH_S and beats.seen.get(p, 0.0) > self.started
                 for p in ("logger", self.name)]
        if not fresh[1]:
            self._heard_since = None  # silent: the logger's word on it waits for a streak of beats again
        elif self._heard_since is None:
            self._heard_since = now
        if self.listened_since_start(beats, time.monotonic()) < REACH_GRACE_S:
            return False
        if not all(fresh) or now - self._heard_since < REACH_STREAK_S:
            return False
        silent, first = logger_report_on(beats, self.name)
        why = None
        if silent is not None:
            why = f"the logger had not heard it for {silent:g} s, so its states were lost (their bus link was lost)"
        first = first if holes else None
        if first is not None:
            if self._hole is None or self._hole[0] != first:
                self._hole = (first, now)
            elif now - self._hole[1] >= HOLE_GRACE_S and why is None:
                why = f"its states from step {first} on never reached the logger (their bus link was lost)"
                self.refill_from = first
        else:
            self._hole = None
        if why is None:
            return False
        self.lost_to_logger = why
        self.proc.kill()
        return True

    def ended_cut_off_from_logger(self, beats) -> bool:
        """This child ended (exit 0) but the logger, still running and heard within
        :data:`FRESH_S`, lists it as ``unheard`` (its end of run never arrived) or reports a
        gap in its state channels: states it published went out over a lost bus link (a
        propagator whose logger does not answer ends without waiting for it).  Marks it
        (:meth:`how`) for a restart by the caller, which publishes them again."""
        if self.proc.poll() != 0 or self.lost_to_logger is not None:
            return False
        if beats.listening_s - beats.heard.get("logger", -math.inf) > FRESH_S:
            return False
        silent, first = logger_report_on(beats, self.name)
        if silent is not None:
            self.lost_to_logger = (f"the logger had not heard it for {silent:g} s when it ended, so its last states "
                                   f"and its end of run never reached the file (their bus link was lost)")
        elif first is not None:
            self.lost_to_logger = f"its states from step {first} on never reached the logger (their bus link was lost)"
            self.refill_from = first
        return self.lost_to_logger is not None

    @property
    def pid(self) -> int:
        return self.proc.pid

    def poll(self):
        return self.proc.poll()

    def stop(self, sig=signal.SIGTERM, timeout: float = 10.0) -> int | None:
        """Signal this child by PID, wait, SIGKILL if it does not go.  A foreign child (a
        controller: a shell line may start more programs) is stopped with everything it
        started in its session (:func:`stop_process_group`), even after it ended itself."""
        self.asked_to_stop = True
        if self.foreign:
            return stop_process_group(self.proc, sig, timeout)
        return stop_process(self.proc, sig, timeout)

    def close(self) -> None:
        self.stdout.close()
        self.stderr.close()

    def stdout_lines(self) -> list[str]:
        """The lines of its stdout still on disk (the newest :data:`OUTPUT_CAP_BYTES`)."""
        return self.stdout.tail().decode(errors="replace").splitlines()

    def summary(self) -> dict | None:
        """The one-line JSON summary the process printed last on stdout, if any."""
        for line in reversed(self.stdout_lines()):
            try:
                obj = messages.parse_json(line)  # a controller's output is anything
            except ValueError:
                continue
            if isinstance(obj, dict):
                return obj
        return None

    def stderr_tail(self, n: int = 5) -> str:
        """The last ``n`` lines of its stderr ("" if none)."""
        text = self.stderr.tail(STDERR_TAIL_BYTES).decode(errors="replace")
        return "\n".join(text.strip().splitlines()[-n:])

    def last_words(self, n: int = 3) -> str:
        """The last ``n`` lines of stderr, for a failure message ("no output on stderr" if none)."""
        return self.stderr_tail(n) or "no output on stderr"


#: Bytes at the end of a child's stderr read for its last lines (:meth:`Child.stderr_tail`).
STDERR_TAIL_BYTES = 64 * 1024


#: Every :class:`Child` this process started (weakly held): :class:`JobControl` stops and
#: continues those still running.
_STARTED: weakref.WeakSet[Child] = weakref.WeakSet()


def catches_signal(pid: int, sig: int) -> bool:
    """Whether process ``pid`` has a handler for ``sig`` installed (Linux: ``SigCgt`` in
    ``/proc/PID/status``); False when that cannot be read."""
    try:
        with open(f"/proc/{pid}/status") as f:
            mask = next((int(line.split()[1], 16) for line in f if line.startswith("SigCgt:")), 0)
    except (OSError, ValueError, IndexError):
        return False
    return bool(mask >> (int(sig) - 1) & 1)


def is_stopped(pid: int) -> bool:
    """Whether process ``pid`` is stopped (state ``T`` or ``t`` in ``/proc/PID/stat``);
    False when that cannot be read (it has gone)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] in ("T", "t")
    except (OSError, IndexError):
        return False


#: Seconds the supervisor waits, on Ctrl-Z, for its children to stop themselves (each at
#: the end of the numeric call it is in) before it stops them with SIGSTOP.
JOB_STOP_WAIT_S = 2.0


def _wait_until_stopped(children: list[Child]) -> None:
    """Wait (at most :data:`JOB_STOP_WAIT_S`) until each of ``children`` is stopped or has ended."""
    deadline = time.monotonic() + JOB_STOP_WAIT_S
    while time.monotonic() < deadline and not all(is_stopped(c.pid) or c.poll() is not None for c in children):
        time.sleep(0.01)


#: The program of a pause guard (:class:`JobControl`): argv ``SUPERVISOR_PID PGID...``.  It
#: waits while its parent is the supervisor; once the supervisor is gone (killed while the run
#: was paused) it continues every stopped child's group, so that each acts on the SIGTERM its
#: supervisor's death sent (``PR_SET_PDEATHSIG``) instead of staying stopped for good.
PAUSE_GUARD_PROGRAM = """
import os, signal, sys, time
for s in (signal.SIGTSTP, signal.SIGINT, signal.SIGHUP, signal.SIGTTOU, signal.SIGTTIN):
    signal.signal(s, signal.SIG_IGN)
supervisor = int(sys.argv[1])
while os.getppid() == supervisor:
    time.sleep(0.1)
for group in sys.argv[2:]:
    try:
        os.killpg(int(group), signal.SIGCONT)
    except OSError:
        pass
"""


class JobControl:
    """Ctrl-Z pauses a whole run (``astrodyn run``, ``astrodyn serve``), not its supervisor alone.

    Each child runs in its own session, so the terminal's SIGTSTP (Ctrl-Z) reaches only the
    supervisor.  Made in the supervisor's main thread, this object handles it
    (:func:`astrodyn.signals.catch_job_control`): it sends SIGTSTP to each child this
    process started that still runs and handles it (the propagators and the plant count the
    time stopped and keep their real-time schedule after it: ``Pacer``), waits for those to
    stop (at most ``JOB_STOP_WAIT_S``), then SIGSTOP to the process group of every other
    (the logger, a controller with the programs it started, one that did not stop in time),
    waits until all are stopped, then stops itself.  SIGCONT (``fg``, ``bg``, ``kill
    -CONT``) continues them.  Deadlines that judge another process are measured on
    listening clocks (:class:`astrodyn.bus.ListeningClock`), so the pause counts against
    none of them; a pause longer than Zenoh's 10 s lease loses bus links, which the
    supervisor heals as for any whole-run pause (docs/reliability.md).

    :attr:`suspended_s` is the time spent stopped so far (wall-clock limits such as ``run
    --timeout`` leave it out); :meth:`take_resumed` gives the length of the last pause once
    after each continue (``serve`` moves its schedule on by as much).  A SIGSTOP, which
    cannot be caught, stops the supervisor alone; its children go on.

    A stopped process does not act on a signal but SIGKILL and SIGCONT, so the SIGTERM a killed
    supervisor's children get (``PR_SET_PDEATHSIG``) would wait for good.  So while the run is
    paused a small guard process (:data:`PAUSE_GUARD_PROGRAM`, in a session of its own, not
    stopped) watches the supervisor and continues every child's group if it dies: a run killed
    while paused (``kill -9`` of a stopped job) ends like one killed while running.
    """

    def __init__(self) -> None:
        self._stopped: list[Child] = []
        self._resumed_s: float | None = None
        self._guard: subprocess.Popen | None = None
        self.restore = catch_job_control(self._stop_children, self._continue_children)

    @property
    def suspended_s(self) -> float:
        return suspended_s()

    def _stop_children(self) -> None:
        self._stopped = [child for child in list(_STARTED) if child.poll() is None]
        self._start_guard()  # before any is stopped: a supervisor killed while it stops them leaves none stopped
        # Those that stop themselves first, then the rest: a logger stopped first fills up and
        # blocks the propagators' puts (congestion control BLOCK), so that they could not run
        # their SIGTSTP handler within the wait.
        catching = [c for c in self._stopped if not c.foreign and catches_signal(c.pid, signal.SIGTSTP)]
        for child in catching:  # unreaped, so the PID is still this child's
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.kill(child.pid, signal.SIGTSTP)
        _wait_until_stopped(catching)
        for child in self._stopped:  # the rest, and any that did not stop in time: their group
            if child.poll() is None and not is_stopped(child.pid):  # (PGID = PID: start_new_session)
                with contextlib.suppress(ProcessLookupError, PermissionError):
                    os.killpg(child.pid, signal.SIGSTOP)
        _wait_until_stopped(self._stopped)

    def _start_guard(self) -> None:
        """Start the pause guard (class docstring) over the groups about to be stopped."""
        if not self._stopped:
            return
        try:
            self._guard = subprocess.Popen(
                [sys.executable, "-I", "-S", "-c", PAUSE_GUARD_PROGRAM, str(os.getpid()),
                 *(str(c.pid) for c in self._stopped)],
                stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                start_new_session=True, close_fds=True)
        except OSError:  # no guard (out of processes): the pause itself still works
            self._guard = None

    def _stop_guard(self) -> None:
        guard, self._guard = self._guard, None
        if guard is not None:
            with contextlib.suppress(OSError):
                guard.kill()
            with contextlib.suppress(subprocess.TimeoutExpired):
                guard.wait(timeout=1.0)

    def _continue_children(self, seconds: float) -> None:
        self._stop_guard()
        stopped, self._stopped = self._stopped, []
        for child in stopped:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(child.pid, signal.SIGCONT)
        self._resumed_s = (self._resumed_s or 0.0) + seconds

    def take_resumed(self) -> float | None:
        """Seconds the run was paused by Ctrl-Z since the last call; None if it was not."""
        resumed, self._resumed_s = self._resumed_s, None
        return resumed


#: Longest wait, once a logger's liveliness token is there, for its ``@latest`` answer signed
#: with the run's secret (:func:`wait_ready`), before the child's exit is looked at again: with
#: 0.5 s, a logger busy with a flood of forged heartbeats never answered in time and the run
#: failed after 60 s ("not ready").
READY_ANSWER_WAIT_S = 5.0


def wait_ready(session, scenario: str, child: Child, timeout_s: float, interrupted: dict,
               verifier=None) -> str | None:
    """Wait for ``child``'s liveliness token; a failure description if it exits first (e.g.
    the logger cannot write its file), is interrupted, or is not ready within ``timeout_s``.

    ``verifier`` (a logger's supervisor, holding the run secret): ready means the logger's
    ``@latest`` reply signed by ``child.name`` with the run's secret
    (:func:`astrodyn.bus.wait_for_logger`), not just a token in its name: on a bus shared
    through a router another run of the same scenario has a logger token too, and taking
    it for this run's logger made a serve whose own logger was refused (its ``--out`` taken)
    carry on as if it recorded (docs/reliability.md)."""
    deadline = time.monotonic() + timeout_s
    while True:
        rc = child.poll()
        if rc is not None:
            time.sleep(0.1)  # let its last words reach the stderr file
            return f"process {child.name} (pid {child.pid}) exited with status {rc} during start-up: {child.last_words(3)}"
        if interrupted["signal"]:
            return f"interrupted by {interrupted['signal']} during start-up"
        try:
            bus.wait_for_process(session, scenario, child.name, timeout_s=0.5)
            if verifier is not None:  # its token is there: its signed answer may take a while (a flooded bus)
                bus.wait_for_logger(session, scenario, child.name, verifier=verifier,
                                    timeout_s=max(0.5, min(READY_ANSWER_WAIT_S, deadline - time.monotonic())))
            return None
        except bus.BusError:
            if time.monotonic() > deadline:
                return f"process {child.name} (pid {child.pid}) not ready after {timeout_s} s: {child.last_words(3)}"
