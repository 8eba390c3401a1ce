"""A run whose disk fills up (ENOSPC): the logger stops writing, says so by its exit status,
and is not restarted (a new logger would fail the same way); the run fails naming the
cause, without a traceback, and what was written before stays readable
(docs/reliability.md).  The disk is a real 2 MB tmpfs (the test needs root to mount one
and is skipped where it cannot)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from astrodyn.recording import load

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def small_disk(tmp_path):
    mount = tmp_path / "small"
    mount.mkdir()
    made = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=2M", "tmpfs", str(mount)], capture_output=True)
    if made.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {made.stderr.decode(errors='replace').strip()}")
    try:
        yield mount
    finally:
        subprocess.run(["umount", "-l", str(mount)], capture_output=True)


@pytest.mark.network
def test_a_full_disk_fails_the_run_naming_it_and_keeps_what_was_written(small_disk):
    out = small_disk / "demo.mcap"  # the demo's recording needs ~2.5 MB; --force skips the free-space check
    proc = subprocess.run([sys.executable, "-m", "astrodyn", "run", str(ROOT / "configs" / "demo.toml"), "--out", str(out),
                           "--force", "--quiet"], capture_output=True, text=True, timeout=180, cwd=ROOT)
    assert proc.returncode == 1, proc.stderr[-3000:]
    assert "Traceback" not in proc.stderr, proc.stderr[-3000:]
    assert "(its disk is full): not restarted" in proc.stderr, proc.stderr[-3000:]
    partial = small_disk / "demo.partial.mcap"
    assert not out.exists() and partial.exists()
    run = load(partial)
    assert run.truncated and run.invalid == 0
    states = [c for c in run.channels.values() if c.kind in ("orbit", "attitude")]
    assert states and sum(len(c) for c in states) > 1000  # ~2 MB of states were flushed before the disk filled
    assert all(np.array_equal(c.seq, np.arange(len(c))) for c in states)  # each a gap-free prefix


def _fill(disk: Path) -> None:
    """Write zeros into ``disk`` until it is full (ENOSPC)."""
    with open(disk / "fill", "wb") as f:
        try:
            while True:
                f.write(b"\0" * 65536)
                f.flush()
        except OSError:
            pass


def test_the_file_tools_on_a_full_disk_say_so_and_leave_nothing_half_written(small_disk, tmp_path):
    from _recordings import leo_recording

    rec = tmp_path / "in.mcap"
    leo_recording(rec, name="full", duration="120 s", rate="2 Hz")
    _fill(small_disk)
    commands = {
        "recover": (["recover", str(rec), "--out", str(small_disk / "r.mcap")], small_disk / "r.mcap"),
        "merge": (["merge", str(rec), str(rec), "--out", str(small_disk / "m.mcap")], small_disk / "m.mcap"),
        "export": (["export", str(rec), "--format", "csv", "--out", str(small_disk / "csv")], small_disk / "csv"),
        "analyze": (["analyze", str(rec), "--out", str(small_disk / "rep"), "--quiet", "--figures-for", "1"], None),
    }
    for name, (argv, target) in commands.items():
        proc = subprocess.run([sys.executable, "-m", "astrodyn", *argv], capture_output=True, text=True, timeout=120,
                              cwd=ROOT)
        assert proc.returncode == 1, (name, proc.stderr[-2000:])
        assert "Traceback" not in proc.stderr and "No space left on device" in proc.stderr, (name, proc.stderr[-2000:])
        assert len(proc.stderr.strip().splitlines()) == 1, (name, proc.stderr)  # one line that says it
        if target is not None:
            assert not target.exists(), name  # nothing half-written under the name asked for
    # nothing left behind: the report directory analyze made (its work directory inside) is removed
    assert sorted(p.name for p in small_disk.iterdir()) == ["fill"]


@pytest.mark.network
def test_run_and_serve_on_a_full_disk_refuse_to_start_in_one_line(small_disk, tmp_path):
    _fill(small_disk)
    demo = str(ROOT / "configs" / "demo.toml")
    for argv in (["run", demo, "--out", str(small_disk / "d.mcap"), "--force", "--quiet"],
                 ["serve", demo, "--out", str(small_disk / "s.mcap"), "--max-wall", "5"]):
        proc = subprocess.run([sys.executable, "-m", "astrodyn", *argv], capture_output=True, text=True, timeout=120,
                              cwd=ROOT)
        assert proc.returncode == 1 and "Traceback" not in proc.stderr, proc.stderr[-2000:]
        assert "work directory: No space left on device" in proc.stderr.strip().splitlines()[-1], proc.stderr[-2000:]
    assert sorted(p.name for p in small_disk.iterdir()) == ["fill"]  # no work directory, no token, no recording left
    # the run itself on another disk, only its --json result on the full one
    proc = subprocess.run([sys.executable, "-m", "astrodyn", "run", str(ROOT / "configs" / "hohmann.toml"),
                           "--out", str(tmp_path / "h.mcap"), "--json", str(small_disk / "r.json"), "--quiet",
                           "--controller", f"python {ROOT / 'examples' / 'hohmann.py'}"],
                          capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert proc.returncode == 1 and "Traceback" not in proc.stderr, proc.stderr[-2000:]
    assert f"--json {small_disk / 'r.json'}: cannot write: No space left on device" in proc.stderr, proc.stderr[-2000:]
    assert (tmp_path / "h.mcap").exists() and not (small_disk / "r.json").exists()


@pytest.mark.network
def test_serve_says_on_stderr_why_a_killed_logger_was_not_restarted_on_a_full_disk(small_disk):
    """The disk fills while serve records, then its logger is killed: the restart fails for
    want of space.  serve says so on stderr when it happens, with the reason; before, stderr
    said only that the logger was killed and where the recording stays, and the reason
    (``No space left on device``) was in the final JSON alone (probe E, E8)."""
    import json
    import os
    import signal

    from _recordings import children_by_kind

    out = small_disk / "s.mcap"
    proc = subprocess.Popen([sys.executable, "-m", "astrodyn", "serve", str(ROOT / "configs" / "demo.toml"), "--out",
                             str(out), "--rate", "50", "--max-wall", "120"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    try:
        assert json.loads(proc.stdout.readline() or "{}").get("serving") == "demo"
        logger = next(pid for pid, kind in children_by_kind(proc.pid).items() if kind == "logger")
        _fill(small_disk)
        os.kill(logger, signal.SIGKILL)  # this test's serve's logger, by its PID
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 1 and "Traceback" not in err, err[-3000:]
    said = [line for line in err.splitlines() if "No space left on device" in line]
    assert said and "logger" in said[0], err[-3000:]
