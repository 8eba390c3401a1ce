"""Child processes of a supervisor (``astrodyn run``, ``astrodyn serve``): how each is
started, watched and stopped.

Every process of a run is started from the installed package (``python -m ...``), never
from a path in the source tree, so a plain ``pip install .`` runs every command
(docs/architecture.md, "Processes").  Each child gets its own session (a signal to the
supervisor's terminal group does not reach it) and its stdout / stderr go to files in
the supervisor's working directory; :meth:`Child.summary` reads the one-line JSON summary
a process prints last.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

__all__ = ["Child", "children_of", "logger_command", "propagator_command"]


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


def logger_command() -> list[str]:
    """The command line that starts a logger process with this interpreter; arguments follow."""
    return [sys.executable, "-m", "astrodyn.service.logger"]


def propagator_command(kind: str) -> list[str]:
    """The command line that starts a ``kind`` (``orbit`` or ``attitude``) propagator process
    with this interpreter; arguments follow."""
    if kind not in ("orbit", "attitude"):
        raise ValueError(f"propagator kind: expected 'orbit' or 'attitude', got {kind!r}")
    return [sys.executable, "-m", "astrodyn.service.propagator", kind]


class Child:
    """One child process: ``argv`` started in its own session, stdout / stderr to
    ``log_dir/<name>.out|.err``; ``env`` adds variables to the supervisor's environment
    (e.g. :data:`astrodyn.auth.SECRET_ENV`, the path of the run secret)."""

    def __init__(self, name: str, argv: list[str], log_dir: Path, env: dict[str, str] | None = None):
        self.name = name
        self.stdout_path = log_dir / f"{name}.out"
        self.stderr_path = log_dir / f"{name}.err"
        self._out = open(self.stdout_path, "wb")
        self._err = open(self.stderr_path, "wb")
        self.proc = subprocess.Popen(argv, stdout=self._out, stderr=self._err, stdin=subprocess.DEVNULL,
                                     start_new_session=True, env={**os.environ, **env} if env else None)

    @property
    def pid(self) -> int:
        return self.proc.pid

    def poll(self):
        return self.proc.poll()

    def stop(self, sig=signal.SIGTERM, timeout: float = 10.0) -> int | None:
        """Signal this child by PID, wait, SIGKILL if it does not go."""
        if self.proc.poll() is None:
            try:
                os.kill(self.proc.pid, sig)
                self.proc.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                os.kill(self.proc.pid, signal.SIGKILL)
                self.proc.wait(timeout=5)
            except ProcessLookupError:
                pass
        return self.proc.returncode

    def close(self) -> None:
        self._out.close()
        self._err.close()

    def summary(self) -> dict | None:
        """The one-line JSON summary the process printed last on stdout, if any."""
        try:
            lines = self.stdout_path.read_text(errors="replace").strip().splitlines()
        except OSError:
            return None
        for line in reversed(lines):
            try:
                obj = json.loads(line)
            except ValueError:
                continue
            if isinstance(obj, dict):
                return obj
        return None

    def stderr_tail(self, n: int = 5) -> str:
        try:
            return "\n".join(self.stderr_path.read_text(errors="replace").strip().splitlines()[-n:])
        except OSError:
            return ""


