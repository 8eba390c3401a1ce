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
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from pathlib import Path

from astrodyn.recording.writer import partial_path

__all__ = ["wait_until_gone", "contiguous_end", "RESTART_LIMIT", "RESTART_WINDOW_S", "RestartBudget", "LoggerRestart", "plan_logger_restart"]

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

    def refusal(self) -> str:
        return (f"process {self.name} died {len(self.deaths)} times within {self.window_s:g} s; not restarted again "
                f"(the recording so far is kept)")


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
    logger_args = ["--prefill", dead, "--prefill-steps", str(steps)]
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
