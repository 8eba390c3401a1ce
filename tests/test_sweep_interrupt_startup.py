"""A Dask sweep stopped at chosen moments of its start-up by a real signal (docs/sweeps.md,
"Interrupted"): the promise is one line, exit 128 + the signal, nothing written when no
case had finished, no process of the sweep left.

The sweep runs as its own process group, SIGINT at its default (as a terminal's foreground
job; a test run in the background inherits it ignored), and Ctrl-C is SIGINT to the whole
group.  The moment that printed a 15-line Dask traceback ("Task exception was never
retrieved ... KeyError: 'tcp://...'") is the spec's scatter to the workers: the interrupt
closes the cluster while the scheduler (in the sweep's process) replicates the spec to the
workers the close removes.  That moment lasts milliseconds, so the child widens it: its
scheduler's ``replicate`` marks a file and waits (bounded) until a worker is gone before it
goes on, which is what happens when the signal arrives at that instant.  The other moments
are read from outside: the ``--out`` directory appears, the cluster's first process
appears, and fixed delays after it.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from _recordings import one_satellite_scene
from test_tool_interrupts import _group, _wait_for  # a process group's PIDs (/proc); wait for a moment, bounded

CONFIG = one_satellite_scene("interrupt-startup", "600 s", "0.1 Hz")

#: The sweep's command in a child whose SIGINT is at its default (or ignored: ``SIGINT_IGNORED``
#: set, as a background job of a non-interactive shell has it), optionally with the scatter
#: moment widened (``SCATTER_MARK``: the scheduler's ``replicate`` creates that file, then
#: waits up to 5 s until a worker is gone, then does its work).
CHILD = r"""
import asyncio, os, signal, sys
signal.signal(signal.SIGINT, signal.SIG_IGN if os.environ.get("SIGINT_IGNORED") else signal.SIG_DFL)
mark = os.environ.get("SCATTER_MARK")
if mark:
    from distributed.scheduler import Scheduler

    replicate = Scheduler.replicate

    async def replicate_when_a_worker_is_gone(self, *args, **kwargs):
        workers = len(self.workers)
        open(mark, "w").close()
        for _ in range(500):
            if len(self.workers) < workers:
                break
            await asyncio.sleep(0.01)
        return await replicate(self, *args, **kwargs)

    Scheduler.replicate = replicate_when_a_worker_is_gone
from astrodyn.cli import main
sys.exit(main(sys.argv[1:]))
"""

CASES = 2000  #: more than can finish within any of the moments below


@pytest.fixture(scope="module")
def config(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("interrupt-startup") / "orbit.toml"
    path.write_text(CONFIG)
    return path


def _start(processes, config: Path, out: Path, **env: str) -> subprocess.Popen:
    argv = [sys.executable, "-c", CHILD, "sweep", config, "--vary", "bodies.sat.orbit.e=uniform(0.001, 0.02)",
            "-n", str(CASES), "--workers", "2", "--out", out, "--quiet"]
    return processes(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
                     env=os.environ | env)


def _stop(proc: subprocess.Popen, sig: int) -> str:
    """``sig`` as a user sends it (Ctrl-C: SIGINT to the process group; SIGTERM: ``kill PID``);
    the sweep's stderr once it ended (bounded)."""
    if sig == signal.SIGINT:
        os.killpg(proc.pid, sig)
    else:
        os.kill(proc.pid, sig)
    return proc.communicate(timeout=60)[1]


def _ended_cleanly(proc: subprocess.Popen, sig: int, err: str, out: Path) -> None:
    """Exit 128 + signal, one last line saying so and nothing else from Python or Dask, nothing
    written when no case had finished, no process of the sweep's group left."""
    assert "Traceback" not in err and "exception" not in err.lower(), err
    assert proc.returncode == 128 + sig, (proc.returncode, err)
    lines = [line for line in err.splitlines() if line.strip()]
    assert lines and f"interrupted by {signal.Signals(sig).name}" in lines[-1], err
    assert len(lines) == 1, err  # --quiet: the interrupt's line alone
    if "no case had finished" in lines[-1]:
        assert not out.exists(), sorted(p.name for p in out.iterdir())
    deadline = time.monotonic() + 10
    while True:
        try:
            os.killpg(proc.pid, 0)  # the sweep's group: its workers, the resource tracker
        except ProcessLookupError:
            break
        assert time.monotonic() < deadline, f"a process of the sweep outlived it: {_group(proc.pid)}"
        time.sleep(0.05)


def test_ctrl_c_while_the_spec_is_scattered_to_the_workers_is_one_line(config, tmp_path, processes):
    """Before: the scheduler's replicate to a worker the close had removed failed with a
    KeyError, and asyncio printed it (15 lines) when the task was collected."""
    out, mark = tmp_path / "sweep", tmp_path / "scattering"
    proc = _start(processes, config, out, SCATTER_MARK=str(mark))
    _wait_for(proc, mark.exists)
    err = _stop(proc, signal.SIGINT)
    _ended_cleanly(proc, signal.SIGINT, err, out)
    assert "no case had finished" in err  # the scatter precedes every case


@pytest.mark.slow
def test_sigterm_while_the_spec_is_scattered_is_one_line(config, tmp_path, processes):
    out, mark = tmp_path / "sweep", tmp_path / "scattering"
    proc = _start(processes, config, out, SCATTER_MARK=str(mark))
    _wait_for(proc, mark.exists)
    err = _stop(proc, signal.SIGTERM)
    _ended_cleanly(proc, signal.SIGTERM, err, out)


#: moments of the start-up: (what is awaited, seconds after it)
MOMENTS = {
    "out-directory-created": ("out", 0.0),
    "cluster-first-process": ("cluster", 0.0),
    "cluster-plus-0.3s": ("cluster", 0.3),
    "cluster-plus-0.7s": ("cluster", 0.7),
    "cluster-plus-1.2s": ("cluster", 1.2),
    "cluster-plus-2s": ("cluster", 2.0),
}


@pytest.mark.slow
@pytest.mark.parametrize("moment", list(MOMENTS))
def test_ctrl_c_at_moments_of_the_start_up_is_one_line(config, tmp_path, processes, moment):
    out = tmp_path / "sweep"
    proc = _start(processes, config, out)
    awaited, delay = MOMENTS[moment]
    _wait_for(proc, out.exists if awaited == "out" else lambda: bool(_group(proc.pid)))
    time.sleep(delay)
    err = _stop(proc, signal.SIGINT)
    _ended_cleanly(proc, signal.SIGINT, err, out)


@pytest.mark.slow
def test_a_background_sweep_with_sigint_ignored_is_stopped_by_sigterm(config, tmp_path, processes):
    """docs/sweeps.md: a background job of a non-interactive shell inherits SIGINT ignored
    (POSIX), which the sweep keeps; SIGTERM stops it the same way Ctrl-C would."""
    out = tmp_path / "sweep"
    proc = _start(processes, config, out, SIGINT_IGNORED="1")
    _wait_for(proc, lambda: bool(_group(proc.pid)))
    os.killpg(proc.pid, signal.SIGINT)
    time.sleep(1.0)
    assert proc.poll() is None, "a sweep whose parent made it ignore SIGINT was stopped by it"
    err = _stop(proc, signal.SIGTERM)
    _ended_cleanly(proc, signal.SIGTERM, err, out)
