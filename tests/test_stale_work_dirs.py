"""Which work directories ``astrodyn recover`` removes (``recording.recover.stale_work_dirs``).

A supervisor (``run``, ``serve``) makes ``.astrodyn-<kind>-XXXX`` beside its recording and
writes its PID in ``supervisor.pid`` just after; it removes the directory when it ends.  A
killed one cannot, so ``recover`` removes those whose supervisor is gone.  A directory
without a readable PID file is a start under way (between the ``mkdir`` and the write) unless
it is old: ``recover`` run at that moment must not take the new run's directory (its run
secret, its children's logs) from under it.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time

from astrodyn.recording.recover import STARTING_WORK_DIR_S, main as recover_main, stale_work_dirs


def _work_dir(folder, name: str, pid: int | str | None, age_s: float = 0.0):
    path = folder / name
    path.mkdir()
    if pid is not None:
        (path / "supervisor.pid").write_text(str(pid))
    if age_s:
        then = time.time() - age_s
        os.utime(path, (then, then))
    return str(path)


def test_recover_removes_the_work_directories_of_gone_supervisors_only(tmp_path, capsys):
    gone = subprocess.Popen([sys.executable, "-c", "pass"])  # a PID that was a process and is no more
    gone.wait()
    dead = _work_dir(tmp_path, ".astrodyn-run-dead", gone.pid)
    alive = _work_dir(tmp_path, ".astrodyn-serve-alive", os.getpid())
    starting = _work_dir(tmp_path, ".astrodyn-run-starting", None)
    abandoned = _work_dir(tmp_path, ".astrodyn-serve-abandoned", None, age_s=2 * STARTING_WORK_DIR_S)
    garbled = _work_dir(tmp_path, ".astrodyn-run-garbled", "not a pid", age_s=2 * STARTING_WORK_DIR_S)
    other = _work_dir(tmp_path, ".someone-else", None, age_s=2 * STARTING_WORK_DIR_S)
    assert sorted(stale_work_dirs(str(tmp_path))) == sorted([dead, abandoned, garbled])
    recover_main([str(tmp_path)])
    assert sorted(os.listdir(tmp_path)) == sorted(os.path.basename(p) for p in (alive, starting, other))
    assert capsys.readouterr().out.count("removed_work_directory") == 3
