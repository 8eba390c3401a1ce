"""serve: the output directory renamed and a child dead at about the same moment.

A death may be the directory's move (a process writing into it, or reading its recording
back to restart), so serve checks the directory at once on any death, before a restart.
Before, the check ran at most once a second: a propagator killed just after the rename was
restarted from the old path first, and that restart failed with "No such file or
directory", a message that hid the cause (docs/reliability.md, the row on `--out` renamed)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from _recordings import children_by_kind, one_satellite_scene

pytestmark = pytest.mark.network

ASTRODYN = [sys.executable, "-m", "astrodyn"]


def test_a_death_right_after_the_directory_moved_is_the_move_not_a_failed_restart(tmp_path: Path):
    config = tmp_path / "movedk.toml"
    config.write_text(one_satellite_scene("movedk", "20000 s", "10 Hz"))
    folder = tmp_path / "d"
    folder.mkdir()
    proc = subprocess.Popen([*ASTRODYN, "serve", str(config), "--out", str(folder / "x.mcap"), "--rate", "100",
                             "--max-wall", "60"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert json.loads(proc.stdout.readline())["serving"] == "movedk"
        partial, deadline = folder / "x.partial.mcap", time.monotonic() + 120
        while time.monotonic() < deadline and not (partial.exists() and partial.stat().st_size > 60_000):
            assert proc.poll() is None, proc.stderr.read()[-2000:]
            time.sleep(0.05)
        orbit = [pid for pid, kind in children_by_kind(proc.pid).items() if kind == "orbit"]
        assert len(orbit) == 1, children_by_kind(proc.pid)
        folder.rename(tmp_path / "d2")
        os.kill(orbit[0], signal.SIGKILL)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 1, err[-2000:]
    assert f"was moved to {tmp_path / 'd2'}" in err, err[-2000:]
    assert "No such file or directory" not in err, err[-2000:]
    assert "restarted orbit" not in err and "restart failed" not in err, err[-2000:]
    assert (tmp_path / "d2" / "x.partial.mcap").exists()
