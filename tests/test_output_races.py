"""Races and surprises around ``--out`` (docs/reliability.md): another recorder taking the
file between the checks and the logger's start, a dangling symlink in the partial file's
place, the output directory renamed while recording, a disk (RLIMIT_FSIZE) that fills, an
``--out`` that starts with "-", an earlier serve's rolled parts.  Nothing already recorded
is lost or overwritten, and each failure is one line with exit 1 (2: refused before the
start).  Real processes, small scenes; each case fails on the code before its fix."""

from __future__ import annotations

import errno
import fcntl
import glob
import io
import json
import os
import resource
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from types import SimpleNamespace

import pytest

from _recordings import one_satellite_scene, run_while, wait_for_recording

pytestmark = pytest.mark.network

ASTRODYN = [sys.executable, "-m", "astrodyn"]


def _scene(tmp_path: Path, name: str, duration: str = "20 s", rate: str = "10 Hz") -> Path:
    config = tmp_path / f"{name}.toml"
    config.write_text(one_satellite_scene(name, duration, rate))
    return config


class _Squatter:
    """Another recorder that wins the race for ``partial``: once the supervisor's work
    directory (``.astrodyn-<kind>-*``, made after the ``--out`` checks) appears, it creates
    the partial file with O_EXCL and holds its flock, as a logger does."""

    def __init__(self, folder: Path, kind: str, partial: Path):
        self.folder, self.kind, self.partial = folder, kind, partial
        self.fd: int | None = None
        self.content = b"\x89MCAP0\r\n another recorder's live bytes"
        self.thread = threading.Thread(target=self._take, daemon=True)
        self.thread.start()

    def _take(self) -> None:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not glob.glob(str(self.folder / f".astrodyn-{self.kind}-*")):
            time.sleep(0.002)
        self.fd = os.open(self.partial, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        fcntl.flock(self.fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        os.write(self.fd, self.content)

    def close(self) -> None:
        self.thread.join(timeout=5)
        if self.fd is not None:
            os.close(self.fd)


def test_a_run_whose_partial_file_another_recorder_took_fails_at_once_and_leaves_that_file(tmp_path):
    """F1: the race loser's logger finds NAME.partial.mcap taken (O_EXCL): the run fails at
    once, exit 1, saying the file is being recorded by another run; it is not restarted as
    --attempt 1, and the other recorder's file is neither unlinked nor touched (before: the
    run recorded beside it as NAME.partial-1.mcap, exit 0, then unlinked the other's file)."""
    config, out = _scene(tmp_path, "race"), tmp_path / "x.mcap"
    squatter = _Squatter(tmp_path, "run", tmp_path / "x.partial.mcap")
    try:
        proc = subprocess.run([*ASTRODYN, "run", str(config), "--out", str(out), "--quiet"], capture_output=True,
                              text=True, timeout=120)
    finally:
        squatter.close()
    assert proc.returncode == 1, proc.stderr[-2000:]
    assert "being recorded right now by another run or serve" in proc.stderr, proc.stderr[-2000:]
    assert "restarted" not in proc.stderr and "Traceback" not in proc.stderr, proc.stderr[-2000:]
    assert (tmp_path / "x.partial.mcap").read_bytes() == squatter.content
    assert not out.exists() and not (tmp_path / "x.partial-1.mcap").exists()
    assert "stays at" not in proc.stderr  # not named as this run's recording


def test_a_refused_serve_says_why_and_leaves_the_running_ones_file_and_control_token(tmp_path):
    """F1 (serve's words) and F7: a serve whose logger finds the partial file taken by a live
    recorder says so (not "a killed run's partial recording?"), exit 1, and the running
    serve's control-token file is left as it is (before: unlinked and replaced at start)."""
    config, out = _scene(tmp_path, "race2"), tmp_path / "x.mcap"
    token = tmp_path / ".x.mcap.control-token"
    token.write_text("the running serve's token")
    squatter = _Squatter(tmp_path, "serve", tmp_path / "x.partial.mcap")
    try:
        proc = subprocess.run([*ASTRODYN, "serve", str(config), "--out", str(out), "--max-wall", "3"],
                              capture_output=True, text=True, timeout=120)
    finally:
        squatter.close()
    assert proc.returncode == 1, proc.stderr[-2000:]
    assert "being recorded right now by another run or serve" in proc.stderr, proc.stderr[-2000:]
    assert "a killed run's" not in proc.stderr, proc.stderr[-2000:]
    assert token.read_text() == "the running serve's token"
    assert (tmp_path / "x.partial.mcap").read_bytes() == squatter.content


def test_serve_refuses_an_out_whose_rolled_parts_exist(tmp_path):
    """F2: parts NAME-0001.mcap ... of an earlier serve's series are never written over: serve
    refuses at the start, exit 2, naming the first part (before: it started and its parts
    replaced the earlier ones silently)."""
    config, out = _scene(tmp_path, "parts"), tmp_path / "x.mcap"
    earlier = tmp_path / "x-0001.mcap"
    earlier.write_bytes(b"\x89MCAP0\r\n an earlier session's part")
    proc = subprocess.run([*ASTRODYN, "serve", str(config), "--out", str(out), "--max-wall", "2",
                           "--roll-interval", "1"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, proc.stderr[-2000:]
    assert str(earlier) in proc.stderr and "move" in proc.stderr, proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    assert earlier.read_bytes() == b"\x89MCAP0\r\n an earlier session's part"
    assert not out.exists() and not glob.glob(str(tmp_path / ".astrodyn-*"))


def test_a_dangling_symlink_in_the_partial_files_place_is_refused_and_kept(tmp_path):
    """F1: NAME.partial.mcap a dangling symlink: refused before the start, exit 2, the link
    kept (before: the logger was restarted as --attempt 1 and the run deleted the link)."""
    config, out = _scene(tmp_path, "link"), tmp_path / "z.mcap"
    link = tmp_path / "z.partial.mcap"
    link.symlink_to("missing")
    proc = subprocess.run([*ASTRODYN, "run", str(config), "--out", str(out), "--quiet"], capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 2, proc.stderr[-2000:]
    assert "symbolic link" in proc.stderr, proc.stderr
    assert link.is_symlink() and os.readlink(link) == "missing"


def test_naming_the_recording_touches_only_this_runs_files_and_a_vanished_one_is_a_failure(tmp_path):
    """F1 (b), (c): the run renames and removes only paths that still name its own loggers'
    files; a recording gone at rename time is a failure (run: no FileNotFoundError; serve: not
    exit 0)."""
    from astrodyn.service.runner import _name_the_recording
    from astrodyn.service.serve import Supervisor
    from astrodyn.service.supervision import LoggerFile

    out = tmp_path / "x.mcap"
    dead, live = tmp_path / "x.partial.mcap", tmp_path / "x.partial-1.mcap"
    dead.write_bytes(b"dead logger's file")
    live.write_bytes(b"finished recording")
    files = {0: LoggerFile.of_dead_logger(dead, existed_before=False), 1: LoggerFile.of_ready_logger(live)}
    dead.unlink()
    dead.write_bytes(b"another run's file, made after ours went")  # the same path, another file
    result = {"restarts": [{"process": "logger"}]}
    assert _name_the_recording(str(live), out, result, files, 1) == str(out)
    assert not result.get("failure") and out.read_bytes() == b"finished recording"
    assert dead.read_bytes() == b"another run's file, made after ours went"

    gone = tmp_path / "y.partial.mcap"
    gone.write_bytes(b"recording")
    files = {0: LoggerFile.of_ready_logger(gone)}
    gone.unlink()
    result = {}
    assert _name_the_recording(str(gone), tmp_path / "y.mcap", result, files, 0) is None
    assert "removed" in result["failure"] and not (tmp_path / "y.mcap").exists()

    sup = SimpleNamespace(failures=[])
    assert Supervisor.name_the_recording(sup, str(tmp_path / "s.partial.mcap"), False) is None
    assert sup.failures and "gone" in sup.failures[0]


def test_a_run_whose_output_directory_is_renamed_fails_and_says_where_the_recording_is(tmp_path):
    """F4: the directory of --out renamed while the run records: exit 1, a line saying the
    recording is not at --out and where it is now; nothing renamed or removed there (before:
    exit 0 and no file at --out)."""
    config = _scene(tmp_path, "moved", "2000 s", "10 Hz")
    folder = tmp_path / "d"
    folder.mkdir()

    def rename_while_the_supervisor_is_stopped(pid: int) -> None:  # it cannot name the file meanwhile
        os.kill(pid, signal.SIGSTOP)
        try:
            folder.rename(tmp_path / "d2")
        finally:
            os.kill(pid, signal.SIGCONT)

    rc, err = run_while([str(config), "--out", str(folder / "x.mcap"), "--quiet"], folder / "x.partial.mcap",
                        60_000, rename_while_the_supervisor_is_stopped, timeout_s=120)
    assert rc == 1, err[-2000:]
    assert "the recording is not at" in err and str(tmp_path / "d2" / "x.partial.mcap") in err, err[-2000:]
    assert "Traceback" not in err
    assert not folder.exists() and (tmp_path / "d2" / "x.partial.mcap").exists()
    assert not (tmp_path / "d2" / "x.mcap").exists()


def test_a_serve_whose_output_directory_is_renamed_fails(tmp_path, processes):
    """F4, serve: the directory renamed while serving: serve fails within about a second,
    exit 1, naming where the directory went (before: exit 0, nothing on stderr)."""
    config = _scene(tmp_path, "moved2", "20000 s", "10 Hz")
    folder = tmp_path / "d"
    folder.mkdir()
    proc = processes([*ASTRODYN, "serve", str(config), "--out", str(folder / "x.mcap"), "--rate", "100",
                      "--max-wall", "60"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    first = json.loads(proc.stdout.readline())
    assert first["serving"] == "moved2"
    # renamed while serve records (its propagators past their start-up, states in the
    # file), as run_while does for run; not after a fixed second, which on a loaded
    # machine (three xdist workers on two cores) fell within the propagators' start-up
    wait_for_recording(proc, folder / "x.partial.mcap", 60_000)
    folder.rename(tmp_path / "d2")
    moved_at = time.monotonic()
    _, err = proc.communicate(timeout=60)
    took = time.monotonic() - moved_at
    assert proc.returncode == 1, err[-2000:]
    assert f"was moved to {tmp_path / 'd2'}" in err, err[-2000:]
    assert took < 15, took  # not --max-wall
    assert (tmp_path / "d2" / "x.partial.mcap").exists()


def _file_size_limit(n: int):
    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (n, n))
    return limit


def test_a_logger_that_hits_the_file_size_limit_is_not_restarted(tmp_path):
    """F5: RLIMIT_FSIZE (EFBIG, "File too large") is a full disk: the logger exits
    DISK_FULL_EXIT and is not restarted; run exits 1 saying so, leaving no empty
    NAME.partial-N.mcap (before: restarted 4 times, four empty partial-N files)."""
    config, out = _scene(tmp_path, "fsize", "200 s", "10 Hz"), tmp_path / "o.mcap"
    proc = subprocess.run([*ASTRODYN, "run", str(config), "--out", str(out), "--quiet", "--force"],
                          capture_output=True, text=True, timeout=120, preexec_fn=_file_size_limit(20_000))
    assert proc.returncode == 1, proc.stderr[-2000:]
    assert "(its disk is full): not restarted" in proc.stderr, proc.stderr[-2000:]
    assert "Traceback" not in proc.stderr
    assert (tmp_path / "o.partial.mcap").exists() and not glob.glob(str(tmp_path / "o.partial-*"))


def test_a_serve_whose_logger_hits_the_file_size_limit_fails(tmp_path):
    """F5, serve: the same under serve: exit 1 naming the full disk (before: the logger was
    restarted onto new parts and serve ended 0 with no state recorded)."""
    config, out = _scene(tmp_path, "fsize2", "2000 s", "10 Hz"), tmp_path / "x.mcap"
    proc = subprocess.run([*ASTRODYN, "serve", str(config), "--out", str(out), "--rate", "inf", "--max-wall", "8"],
                          capture_output=True, text=True, timeout=120, preexec_fn=_file_size_limit(20_000))
    assert proc.returncode == 1, proc.stderr[-2000:]
    assert "its disk is full" in proc.stderr, proc.stderr[-2000:]
    assert "restarted logger" not in proc.stderr


def test_an_out_that_starts_with_a_dash_is_recorded(tmp_path):
    """F6: ``--out=-x.mcap`` (also ``./-x.mcap``) reaches the logger as a path, not an option
    (before: its argparse refused it, the logger was restarted 4 times and the run failed)."""
    config = _scene(tmp_path, "dash", "5 s")
    proc = subprocess.run([*ASTRODYN, "run", str(config), "--out", "./-x.mcap", "--quiet"], capture_output=True,
                          text=True, timeout=120, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert (tmp_path / "-x.mcap").exists() and not glob.glob(str(tmp_path / "-x.partial*"))


def test_a_logger_whose_summary_cannot_be_written_says_its_disk_is_full(monkeypatch):
    """F5: the logger's last act, its one-line summary on stdout (a file on the same disk),
    failing with ENOSPC / EFBIG is a full disk (exit DISK_FULL_EXIT), not status 1."""
    from astrodyn.service import logger
    from astrodyn.service.children import DISK_FULL_EXIT

    class Full(io.StringIO):
        def write(self, text):
            raise OSError(errno.EFBIG, "File too large")

        def fileno(self):
            raise OSError(errno.EBADF, "no descriptor")

    monkeypatch.setattr(sys, "stdout", Full())
    assert logger.print_summary_line({"file": "x.partial.mcap"}) == DISK_FULL_EXIT
