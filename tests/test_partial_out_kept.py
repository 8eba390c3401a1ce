"""An unfinished recording is never replaced by a new run's ``--out``.

Newcomer walk (session 18): after a Ctrl-C'd run, ``run`` / ``serve`` refuse to start until
``out/demo.partial.mcap`` is recovered; but ``astrodyn run configs/demo.toml --out
out/demo.partial.mcap`` exited 0 and put the new recording in its place: the killed run's
steps were gone.  A finished recording may still be replaced (documented); a file named as
a partial recording (``NAME.partial.mcap``, ``NAME.partial-N.mcap``) is refused, exit 2,
byte for byte as it was.
"""

from __future__ import annotations

import hashlib
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from astrodyn.recording.writer import is_partial_path, partial_path

ROOT = Path(__file__).resolve().parents[1]
FIXTURE = ROOT / "tests" / "fixtures" / "legacy-v0.mcap"  # an MCAP recording (any will do)


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.mark.parametrize("name", ["demo.partial.mcap", "demo.partial-3.mcap"])
@pytest.mark.parametrize("command", ["run", "serve"])
def test_a_partial_recording_named_as_out_is_refused_and_kept(tmp_path, name, command):
    target = tmp_path / name
    shutil.copyfile(FIXTURE, target)
    before = _digest(target)
    proc = subprocess.run([sys.executable, "-m", "astrodyn", command, str(ROOT / "configs" / "demo.toml"),
                           "--out", str(target)], capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    assert "partial recording" in proc.stderr and "astrodyn recover" in proc.stderr and "Traceback" not in proc.stderr
    assert _digest(target) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == [name]


def test_partial_names_are_what_partial_path_makes():
    for out in ("a.mcap", "dir/b.c.mcap", "x"):
        for attempt in (0, 1, 12):
            assert is_partial_path(partial_path(out, attempt))
        assert not is_partial_path(out)
    assert not is_partial_path("partial.mcap") and not is_partial_path("a.partial-0.mcap")
    assert not is_partial_path("a.partial.x/b.mcap")
