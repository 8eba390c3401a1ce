"""Exit codes and messages of the file tools for hostile flag values, through the real CLI.

The rule (docs/exports.md, "Exit status"): **2** when the command line is wrong and that
can be judged before the input is read -- a bad flag value, an empty path, an ``--out`` of
the wrong kind (a regular file, a FIFO or a device where a directory goes, a directory or
a device where a file goes), in a missing directory or under a file, or one that exists
where a new file goes (``merge``, ``recover --out``); **1** when the input or the run
fails, including what only the input can tell (``analyze --bodies`` matching no body of
that recording, an export with nothing to export).  Each case: the exit code, one line
naming the flag and what it allows, no traceback, nothing written.

Every command is its own process (``python -m astrodyn``), all started at once (at most
:data:`AT_ONCE` running) with a time bound, so the module takes a few seconds.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

AT_ONCE = 4  #: commands running together (2 cores, shared)
TIMEOUT_S = 60.0

#: (command line with {rec} the recording and {toml} a sweep config, exit code, what stderr says)
CASES = {
    # analyze: flag values wrong whatever the recording (all exit 1 before)
    "analyze-figures-for-negative": ("analyze {rec} --figures-for -1", 2, "--figures-for: expected an integer >= 0"),
    "analyze-seq-999": ("analyze {rec} --seq 999", 2, "--seq: expected one of 121, 123, 131, 132, 212, 213"),
    "analyze-seq-empty": ("analyze {rec} --seq ''", 2, "--seq: expected one of 121"),
    "analyze-bodies-empty": ("analyze {rec} --bodies ''", 2, "--bodies: expected comma-separated body names"),
    "analyze-bodies-empty-item": ("analyze {rec} --bodies 'leo,,geo'", 2, "--bodies: expected comma-separated"),
    "analyze-out-file": ("analyze {rec} --out afile", 2, "--out afile: expected a directory, got a regular file"),
    "analyze-out-fifo": ("analyze {rec} --out fifo", 2, "--out fifo: expected a directory, got a FIFO"),
    "analyze-out-device": ("analyze {rec} --out /dev/null", 2, "expected a directory, got a character device"),
    "analyze-out-under-file": ("analyze {rec} --out afile/sub", 2,
                               "expected a directory that can be created, got a path inside a regular file"),
    "analyze-input-empty": ("analyze ''", 2, "argument file: expected a path, got an empty string"),
    # export
    "export-out-file": ("export {rec} --format csv --out afile", 2, "--out afile: expected a directory, got a regular file"),
    "export-out-fifo": ("export {rec} --format oem --out fifo", 2, "--out fifo: expected a directory, got a FIFO"),
    "export-out-under-file": ("export {rec} --format csv --out afile/sub", 2, "got a path inside a regular file"),
    "export-input-empty": ("export '' --format csv --out new", 2, "argument file: expected a path, got an empty string"),
    # merge: --out must be a new file path in an existing, writable directory
    "merge-out-dir": ("merge {rec} --out adir", 2, "--out adir: expected a file path, got a directory"),
    "merge-out-fifo": ("merge {rec} --out fifo", 2, "--out fifo: expected a file path, got a FIFO"),
    "merge-out-device": ("merge {rec} --out /dev/null", 2, "expected a file path, got a character device"),
    "merge-out-exists": ("merge {rec} --out afile", 2, "--out afile: exists already"),
    "merge-out-missing-dir": ("merge {rec} --out nodir/m.mcap", 2, "expected a file path in an existing directory"),
    "merge-input-empty": ("merge '' --out m.mcap", 2, "argument inputs: expected a path, got an empty string"),
    # recover
    "recover-out-exists": ("recover {rec} --out afile", 2, "--out afile exists already"),
    "recover-out-fifo": ("recover {rec} --out fifo", 2, "--out fifo: expected a file path, got a FIFO"),
    "recover-out-missing-dir": ("recover {rec} --out nodir/r.mcap", 2, "expected a file path in an existing directory"),
    "recover-input-empty": ("recover ''", 2, "argument file: expected a path, got an empty string"),
    # sweep (exit 2 before as well, with a misleading message)
    "sweep-out-fifo": ("sweep {toml} --vary 'bodies.sat.orbit.e=uniform(0, 0.1)' -n 1 --workers 0 --out fifo", 2,
                       "--out fifo: expected a directory, got a FIFO"),
    "sweep-config-empty": ("sweep '' --vary 'bodies.sat.orbit.e=uniform(0, 0.1)' -n 1 --workers 0 --out new", 2,
                           "argument config: expected a path, got an empty string"),
}

SWEEP_CONFIG = """
[scenario]
name = "flags"
epoch = "2026-03-20T12:00:00 TDB"
duration = "10 s"
rate = "1 Hz"

[[bodies]]
name = "sat"
[bodies.orbit]
a = "7000 km"
e = 0.01
"""


def _tree(d: Path) -> dict[str, tuple]:
    return {str(p.relative_to(d)): (p.stat().st_size, p.stat().st_mtime_ns) if p.is_file() else "dir"
            for p in sorted(d.rglob("*")) if not p.is_fifo()}


@pytest.fixture(scope="module")
def results(tmp_path_factory) -> dict[str, tuple[int, str]]:
    """Every case run in one directory holding the recording, a sweep config, a regular
    file ``afile``, a directory ``adir`` and a FIFO ``fifo``: case -> (exit code, stderr).
    The directory must be as it was afterwards (checked here: nothing written)."""
    import shlex

    from _recordings import leo_recording

    d = tmp_path_factory.mktemp("flags")
    leo_recording(d / "rec.mcap", duration="10 s", rate="1 Hz")
    (d / "s.toml").write_text(SWEEP_CONFIG)
    (d / "afile").write_text("not an output\n")
    (d / "adir").mkdir()
    os.mkfifo(d / "fifo")
    before = _tree(d)
    pending = list(CASES.items())
    running: dict[str, subprocess.Popen] = {}
    out: dict[str, tuple[int, str]] = {}
    deadline = time.monotonic() + TIMEOUT_S
    try:
        while pending or running:
            while pending and len(running) < AT_ONCE:
                name, (line, _, _) = pending.pop(0)
                argv = shlex.split(line.format(rec="rec.mcap", toml="s.toml"))
                running[name] = subprocess.Popen([sys.executable, "-m", "astrodyn", *argv], cwd=d, text=True,
                                                 stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                                 stderr=subprocess.PIPE)
            for name, proc in list(running.items()):
                if proc.poll() is not None:
                    out[name] = (proc.returncode, proc.stderr.read())
                    proc.stderr.close()
                    del running[name]
            assert time.monotonic() < deadline, f"still running after {TIMEOUT_S} s: {sorted(running)}"
            time.sleep(0.01)
    finally:
        for proc in running.values():
            proc.kill()
            proc.wait()
            proc.stderr.close()
    assert _tree(d) == before, "a refused command wrote something"
    return out


@pytest.mark.parametrize("case", list(CASES))
def test_a_hostile_flag_value_gets_its_exit_code_and_one_line_naming_the_flag(results, case):
    code, says = CASES[case][1:]
    status, err = results[case]
    assert "Traceback" not in err, err
    assert status == code, (status, err)
    assert says in err.strip().splitlines()[-1], err
