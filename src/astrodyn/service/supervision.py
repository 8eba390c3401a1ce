"""Restarting a dead logger without losing a state (``astrodyn run`` and ``astrodyn serve``).

A logger that dies (SIGKILL, crash, OOM) leaves its file as ``NAME.partial.mcap`` (or
``NAME.partial-<n>.mcap`` for the n-th restarted logger), holding every chunk it flushed
(at most ``--flush-interval``, 1 s, of states are only in its memory).  The supervisor
then, within about a second:

1. stops the propagators (what they publish now has no recorder);
2. reads the dead logger's file up to its last flushed chunk and finds ``k``, the number
   of steps every state channel holds from the file's first step without a hole
   (:func:`astrodyn.service.resume.contiguous_steps` for a file that starts at step 0);
3. starts a new logger (``--attempt n``) that first copies those states into its own
   file (``--prefill``, payloads unchanged, the seq accounting seeded), then records;
4. restarts every propagator at step ``k`` (exact models re-evaluated, integrated ones
   continued from the recorded state of step ``k-1``:
   :func:`astrodyn.service.resume.propagator_resume_args`).

The steps the dead logger had not flushed are published again, so the new file holds
every state exactly once: a logger restart costs wall-clock time, not states.  The dead
logger's partial file is removed once the new one has copied it.  A logger that dies
:data:`RESTART_LIMIT` times within :data:`RESTART_WINDOW_S` ends the run with an error
naming it (the file so far stays valid and recoverable).

That is ``astrodyn run``'s restart (one output file).  ``astrodyn serve``, which records
in parts anyway (``--roll-interval``), restarts without copying anything, so the restart
costs the same after a minute or a day (:func:`plan_part_restart`):

1. reads only where each state channel of the dead logger's file ends
   (:func:`astrodyn.recording.tail.channel_tails`: a header walk, about 1 us per message,
   no JSON, memory per channel) and, per propagator, the latest step all its channels
   hold there with the states at it (:func:`astrodyn.service.resume.tail_resume_point`);
2. starts a new logger on the next part (``--first-part p+1``) with every channel's
   next seq (``--resume-seqs``): a step published again is dropped as already recorded,
   no gap is counted before it;
3. restarts each propagator after its step, and finishes the dead file as part ``p`` in
   the background (:func:`astrodyn.recording.recover.recover`), so the parts hold every
   state exactly once.
"""

from __future__ import annotations

import json
import os
import re
import stat
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from astrodyn.recording.writer import being_written, partial_path
from astrodyn.service.output import identity_at

__all__ = ["wait_until_gone", "contiguous_end", "RESTART_LIMIT", "RESTART_WINDOW_S", "RestartBudget", "LoggerRestart", "plan_logger_restart",
           "PartRestart", "plan_part_restart", "part_number", "resume_from_parts", "LoggerFile", "LoggerFiles", "holds_config",
           "restarts_after_start_up_death"]

def restarts_after_start_up_death(rc: int | None) -> bool:
    """Whether a logger that ended with status ``rc`` before it was ready is replaced: only
    one ended by a signal (SIGKILL, a crash: SIGSEGV, SIGABRT, the OOM killer).  One that
    exits on its own said why (its file is in the way or cannot be written, its disk is
    full, a bad argument) and another would fail the same way, or worse, record beside a
    run that holds the file (docs/reliability.md)."""
    return rc is not None and rc < 0


def _identity(st: os.stat_result) -> tuple[int, int]:
    return st.st_dev, st.st_ino


class LoggerFile:
    """A file one of this run's loggers created (``NAME.partial[-n].mcap``), known by its
    identity ``(st_dev, st_ino)``: the supervisor removes or renames a path only while it
    still names that file, never one another run (or the user) put there.  A read
    descriptor is kept on the file until :meth:`close` (its inode number is not reused
    meanwhile), which also tells where it went (its directory renamed, the file moved) at
    the end (:meth:`where`, Linux).

    :meth:`of_ready_logger`: the file of a logger that is ready (it created it with
    ``O_EXCL`` and holds its ``flock``); :meth:`of_dead_logger`: the file a logger that died while starting may have
    created: taken as its own only if there was nothing at ``path`` before it started, and
    it is a regular file no live recorder holds."""

    def __init__(self, path: str, identity: tuple[int, int], fd: int | None = None):
        self.path, self.identity, self._fd = os.fspath(path), identity, fd
        self.names = [self.path]  # every name it was known by, oldest first (:meth:`renamed_to`)

    @classmethod
    def _held(cls, path: str) -> LoggerFile | None:
        """The regular file at ``path`` with a descriptor held on it (so its inode number
        cannot be given to another file while the run goes on); None for anything else."""
        try:
            # O_PATH (Linux): no read permission needed, nothing is read; fstat and /proc/self/fd work on it
            fd = os.open(path, getattr(os, "O_PATH", os.O_RDONLY | os.O_NONBLOCK) | os.O_NOFOLLOW | os.O_CLOEXEC)
        except OSError:
            return None
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            os.close(fd)
            return None
        return cls(path, _identity(st), fd)

    @classmethod
    def reported(cls, path: str | os.PathLike, identity: tuple[int, int]) -> LoggerFile | None:
        """The file at ``path`` if it is the one a logger reported as created by it
        (``identity``: ``--own-files``, :class:`LoggerFiles`); None for any other."""
        held = cls._held(os.fspath(path))
        if held is not None and held.identity != tuple(identity):
            held.close()
            return None
        return held

    @classmethod
    def of_ready_logger(cls, path: str | os.PathLike) -> LoggerFile | None:
        return cls._held(os.fspath(path))  # created with O_EXCL by the logger, which holds it

    @classmethod
    def of_dead_logger(cls, path: str | os.PathLike, existed_before: bool) -> LoggerFile | None:
        path = os.fspath(path)
        if existed_before or being_written(path):
            return None
        return cls._held(path)

    def here(self) -> bool:
        """Whether :attr:`path` still names this file."""
        return identity_at(self.path) == self.identity

    def renamed_to(self, path: str | os.PathLike) -> None:
        """Its logger reported that the file took the name ``path`` (a finished part: the
        partial name linked to ``NAME-000k.mcap`` and unlinked, :func:`~astrodyn.recording.writer.link_new`,
        or renamed to ``NAME.mcap``): :attr:`path` becomes ``path`` if that names the file."""
        path = os.fspath(path)
        if path not in self.names:
            self.names.append(path)
        if identity_at(path) == self.identity:
            self.path = path

    def where(self) -> str | None:
        """Where the file is now: :attr:`path` if it still names it, else the newest of
        the names it was reported under that does, else where it was moved (its directory
        renamed, the file renamed) as the descriptor kept on it tells (``/proc/self/fd``),
        its finished name (``NAME-000k.mcap`` for ``NAME-000k.partial.mcap``) looked for
        too: a part named by a hard link and an unlink of its partial name, which
        ``/proc`` shows as deleted (:func:`astrodyn.service.output.held_path`); None when
        it was removed or that cannot be told."""
        from astrodyn.recording.recover import finished_name
        from astrodyn.service.output import held_path

        if self.here():
            return self.path
        names = [*reversed(self.names)]
        for name in names:
            if identity_at(name) == self.identity:
                return name
        names += [final for name in self.names if (final := finished_name(name)) is not None]
        return held_path(self._fd, self.identity, names)

    def unlink_if_here(self) -> bool:
        """Remove :attr:`path` if it still names this file (a dead logger's, copied); True
        if removed."""
        if not self.here():
            return False
        try:
            os.unlink(self.path)
        except OSError:
            return False
        return True

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None


class LoggerFiles:
    """Every file this run's loggers created, as :class:`LoggerFile` (by identity), oldest
    first: ``serve``'s record of its own parts.  Its loggers report each file they create
    and each name a finished part takes (``--own-files REPORT``, a file in the supervisor's
    private work directory: ``{file, dev, ino}`` lines); :meth:`sync` takes the new lines.
    A file is taken only while the reported path still names the reported ``(st_dev,
    st_ino)``, and then held (:class:`LoggerFile`: its later names are followed, its inode
    number is not reused).  A file another recorder (another user's serve, a run) wrote is
    never among them, whatever its name: only these are read for a resume, finished as a
    dead logger's part, counted as parts, or renamed."""

    def __init__(self, report: Path):
        self.report = Path(report)
        self.files: list[LoggerFile] = []
        self._offset = 0
        self._pending: dict[tuple[int, int], str] = {}  # reported, not yet held: identity -> latest name

    def sync(self) -> None:
        try:
            with open(self.report, "rb") as f:
                f.seek(self._offset)
                data = f.read()
        except OSError:
            return
        end = data.rfind(b"\n") + 1  # whole lines only (a line is one O_APPEND write)
        self._offset += end
        held = {lf.identity: lf for lf in self.files}
        for line in data[:end].splitlines():
            try:
                rec = json.loads(line)
                identity = (int(rec["dev"]), int(rec["ino"]))
                path = str(rec["file"])
            except (ValueError, KeyError, TypeError):
                continue
            if identity in held:  # the name a finished part took (before: ignored, and a part seen
                held[identity].renamed_to(path)  # while partial was lost once link_new named it)
            else:
                self._pending[identity] = path  # kept in creation order, with the latest name
        for identity, path in list(self._pending.items()):
            lf = LoggerFile.reported(path, identity)
            if lf is not None:
                self.files.append(lf)
                del self._pending[identity]

    def add(self, lf: LoggerFile, instead_of: LoggerFile | None = None) -> None:
        """Take ``lf`` (a file this run made otherwise: a dead part finished by its own
        ``astrodyn recover``), in the place of ``instead_of`` when given."""
        if instead_of is not None and instead_of in self.files:
            self.files[self.files.index(instead_of)] = lf
        else:
            self.files.append(lf)

    def newest_first(self) -> list[tuple[LoggerFile, str]]:
        """``(file, where it is now)`` of every own file that still exists, newest first."""
        self.sync()
        out = []
        for lf in reversed(self.files):
            where = lf.where()
            if where is not None:
                out.append((lf, where))
        return out

    def owns(self, path: str | os.PathLike) -> LoggerFile | None:
        """The own file ``path`` names now, if any."""
        self.sync()
        try:
            identity = _identity(os.lstat(path))
        except OSError:
            return None
        return next((lf for lf in self.files if lf.identity == identity), None)

    def close(self) -> None:
        for lf in self.files:
            lf.close()


def holds_config(path: str | os.PathLike, scenario) -> bool:
    """Whether the recording ``path`` (finished or cut) holds ``scenario``'s config: its
    ``scenario`` metadata record, wherever the file keeps it (the logger writes it first;
    a part ``astrodyn recover`` finished, a dead logger's, has it after the messages, found
    through its summary's metadata index: :func:`astrodyn.recording.reader.recorded_metadata`,
    a bounded read whatever the file's size), names the same scenario and config as ``run
    --resume`` and ``run --commands`` judge it
    (:func:`astrodyn.scenario.recorded.config_difference`: where the config file was read
    from does not count).  False for anything else, and for a file that cannot be read: a
    resume never starts from another config's states."""
    from astrodyn.recording.reader import RecordingError, recorded_metadata
    from astrodyn.scenario.recorded import config_difference

    try:
        found = recorded_metadata(path, ("scenario",))
    except (RecordingError, OSError, ValueError):
        return False
    return "scenario" in found and config_difference(found["scenario"], scenario) is None


#: A process that dies this many times ...
RESTART_LIMIT = 5
#: ... within this many seconds is not restarted again: the run stops with an error naming it.
RESTART_WINDOW_S = 60.0


def wait_until_gone(session, scenario: str, process: str, timeout_s: float = 5.0) -> bool:
    """Wait until ``process``'s liveliness token has left the bus (a dead process's goes
    when its links close), so that the token seen next is its successor's; True if gone."""
    from astrodyn.messages import alive_key

    key = alive_key(scenario, process)
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if not any(r.ok is not None for r in session.liveliness().get(key, timeout=0.5)):
            return True
        time.sleep(0.02)
    return False


def next_event_seq(session, scenario: str, process: str, fallback: int) -> int:
    """The seq a restarted ``process`` must give its first event: the next one the logger
    expects on the event channel from that process (it saw all the dead instance sent,
    which may be none: a process killed before its start event).  ``fallback`` when the
    logger does not answer (its restart is then recorded with a gap)."""
    from astrodyn.bus import query_json
    from astrodyn.messages import event_key, status_key

    for reply in query_json(session, status_key(scenario), {"channels": True}, timeout_s=5.0):
        table = reply.get("event_next_seq")
        if isinstance(table, dict):
            value = table.get(f"{event_key(scenario)}#{process}", 0)
            return int(value) if isinstance(value, int) and value >= 0 else fallback
    return fallback


@dataclass
class RestartBudget:
    """Deaths of one process: :meth:`allow` says whether one more restart is within the
    limit (:data:`RESTART_LIMIT` deaths in :data:`RESTART_WINDOW_S`)."""

    name: str
    limit: int = RESTART_LIMIT
    window_s: float = RESTART_WINDOW_S
    deaths: list[float] = field(default_factory=list)

    def allow(self, now: float | None = None) -> bool:
        now = time.monotonic() if now is None else now
        self.deaths = [t for t in self.deaths if now - t < self.window_s] + [now]
        return len(self.deaths) < self.limit

    def refusal(self, recording: bool = True) -> str:
        """Why it is not restarted; ``recording``: the process is one of a run that records
        (not ``replay``'s live view), so the message says the recording so far is kept."""
        return (f"process {self.name} died {len(self.deaths)} times within {self.window_s:g} s; not restarted again"
                + (" (the recording so far is kept)" if recording else ""))


@dataclass
class LoggerRestart:
    """What to start after a logger death: the new logger's extra arguments, each
    propagator's resume arguments, and where the copied states came from."""

    attempt: int
    steps: int
    source: str | None
    logger_args: list[str]
    propagator_args: dict[str, dict]


def plan_logger_restart(scenario, out: Path, attempt: int, kinds: list[str], work: Path,
                        first_logger_args: list[str] | None = None,
                        first_propagator_args: dict | None = None) -> LoggerRestart:
    """How to restart the logger of ``scenario`` recording to ``out`` after its logger
    number ``attempt - 1`` died (module docstring).  ``first_*`` are the arguments the run
    started with (a ``run --resume``), used when the dead logger's file holds no step."""
    from astrodyn.recording import RecordingError, load as load_run
    from astrodyn.service.resume import contiguous_steps, propagator_resume_args, state_topics

    dead = partial_path(out, attempt - 1)
    steps, run = 0, None
    if os.path.exists(dead):
        try:
            run = load_run(dead)  # up to the last flushed chunk
            topics = [t for kind in kinds for t in state_topics(scenario, kind).values()]
            steps = contiguous_steps(run, topics)
        except (RecordingError, OSError):
            steps, run = 0, None
    if steps == 0 or run is None:
        return LoggerRestart(attempt, 0, None, list(first_logger_args or []), dict(first_propagator_args or {}))
    logger_args = [f"--prefill={dead}", "--prefill-steps", str(steps)]  # "=": a path may start with "-"
    props = {kind: propagator_resume_args(run, scenario, kind, steps - 1, work) for kind in kinds}
    return LoggerRestart(attempt, steps, dead, logger_args, props)


def contiguous_end(run, topics) -> int | None:
    """One past the last step that every channel of ``topics`` holds without a hole from
    the channel's first step in ``run`` (a rolled part starts after step 0); None if a
    channel is missing or empty."""
    import numpy as np

    end = None
    for topic in topics:
        track = run.channels.get(topic)
        if track is None or len(track) == 0:
            return None
        seq = np.unique(track.seq)
        n = int(np.searchsorted(seq - seq[0] - np.arange(seq.size), 0, side="right"))
        e = int(seq[0]) + n
        end = e if end is None else min(end, e)
    return end


def part_number(path: str, out: str | os.PathLike) -> int:
    """The part a (finished or partial) file of the recording ``out`` is: 0 for ``out``
    itself, k for ``NAME-000k.mcap`` (:func:`astrodyn.recording.writer.part_path`)."""
    from astrodyn.recording.recover import finished_name

    final = finished_name(path) or path
    if final == os.fspath(out):
        return 0
    m = re.search(r"-(\d{4,})(?:\.clash-\d+)*\.[^.]+$", final)  # NAME-000k[.clash-n].mcap
    return int(m.group(1)) if m else 0


def _state_channel_of(scenario_name: str):
    from astrodyn.messages import PREFIX, STATE_KINDS, MessageError, kind_of_key

    prefix = f"{PREFIX}/{scenario_name}/"

    def wanted(topic: str) -> bool:
        if not topic.startswith(prefix):
            return False
        try:
            return kind_of_key(topic) in STATE_KINDS
        except MessageError:
            return False
    return wanted


def resume_from_parts(scenario, kind: str, parts: list[str], work: Path,
                      tails_of: dict[str, dict[str, list[bytes]]] | None = None) -> tuple[dict, str | None]:
    """The resume arguments of the ``kind`` propagator from the newest of ``parts`` (files,
    newest first) whose last messages hold a step common to all its channels, and that
    file; ``({"--start-step": 0}, None)`` when none does.  ``tails_of`` caches each file's
    :func:`~astrodyn.recording.tail.channel_tails`."""
    from astrodyn.recording.reader import RecordingError
    from astrodyn.recording.tail import channel_tails
    from astrodyn.service.resume import resume_args, tail_resume_point

    tails_of = {} if tails_of is None else tails_of
    for part in parts:
        if part not in tails_of:
            try:  # never another config's states (same scenario name, other orbits: holds_config)
                tails_of[part] = channel_tails(part, _state_channel_of(scenario.name)) \
                    if holds_config(part, scenario) else {}
            except (RecordingError, OSError):
                tails_of[part] = {}
        point = tail_resume_point(tails_of[part], scenario, kind)
        if point is not None:
            step, t, states = point
            return resume_args(scenario, kind, step, lambda t=t, states=states: (t, states), work), part
    return {"--start-step": 0}, None


@dataclass
class PartRestart:
    """What ``serve`` starts after a logger death (:func:`plan_part_restart`)."""

    part: int                       # the new logger's first part
    source: str | None              # the dead logger's partial file
    final: str | None               # the name it is finished under
    logger_args: list[str]
    propagator_args: dict[str, dict]

    def finish_in_background(self, log_dir: Path):
        """Finish the dead logger's file as its part in a separate process (``astrodyn
        recover``: the finished file, then the partial one removed), so serve's own loop
        and its heartbeats are not slowed by it; the :class:`~astrodyn.service.children.Child`
        (ended with serve: ``PR_SET_PDEATHSIG``), or None when there is no file.  A failure
        leaves the partial file for ``astrodyn recover`` (serve's summary says so)."""
        if self.source is None:
            return None
        from astrodyn.service.children import Child

        name = f"finish-part-{self.part - 1}"
        # absolute: a relative path that starts with "-" would read as an option
        return Child(name, [sys.executable, "-m", "astrodyn", "recover", os.path.abspath(self.source)], Path(log_dir),
                     foreign=True)


def plan_part_restart(scenario, out: Path, dead: str | None, finished: list[str], kinds: list[str],
                      attempt: int, work: Path, event_seqs: dict[str, int] | None = None) -> PartRestart:
    """How ``serve`` restarts its logger number ``attempt`` after a death (module
    docstring): ``dead`` is the dead logger's partial file (None if it left none),
    ``finished`` the run's finished parts, newest first; ``event_seqs``: process -> the
    seq of its next event (what serve heard: :class:`astrodyn.bus.EventSeqWatcher`), where
    the new part's event channel of each process starts (its earlier events are not missing
    from the new part: they are in the earlier ones)."""
    from astrodyn.messages import decode, event_key, kind_of_key
    from astrodyn.recording.recover import finished_name

    numbers = [part_number(p, out) for p in ([dead] if dead else []) + finished]
    part = max(numbers) + 1 if numbers else 0
    files = ([dead] if dead else []) + finished
    tails_of: dict[str, dict[str, list[bytes]]] = {}
    props = {}
    for kind in kinds:
        props[kind], _ = resume_from_parts(scenario, kind, files, work, tails_of) if kind != "plant" else ({}, None)
    seeds: dict[str, int] = {}
    for file in files:  # newest first: a channel's next seq is one past its last recorded one
        for topic, payloads in tails_of.get(file, {}).items():
            if topic in seeds:
                continue
            seqs = []
            for data in payloads:
                try:
                    seqs.append(decode(data, kind_of_key(topic))["seq"])
                except ValueError:
                    continue
            if seqs:
                seeds[topic] = max(seqs) + 1
    for process, next_seq in (event_seqs or {}).items():
        seeds[f"{event_key(scenario.name)}#{process}"] = next_seq
    seeds_file = Path(work) / f"resume-seqs-{attempt}.json"
    seeds_file.write_text(json.dumps(seeds))
    logger_args = ["--first-part", str(part), "--resume-seqs", str(seeds_file)]
    return PartRestart(part, dead, finished_name(dead) if dead else None, logger_args, props)
