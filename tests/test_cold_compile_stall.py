"""A fresh install compiles its numeric kernels on the first run (30-55 s each on this
project's 2-core machine; numba caches them).  A child says ``preparing`` meanwhile, and the
supervisor gives it at least ``PREPARE_GRACE_S`` whatever ``--stall-timeout`` says
(docs/reliability.md, hung processes).  Before, it gave ten times the limit only: with
``--stall-timeout 2`` the orbit propagator was killed as hung after 20 s of compiling, and
each restart compiled again from nothing.

A real `astrodyn run` with an empty numba cache of its own (NUMBA_CACHE_DIR), so the
children really compile."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _recordings import one_satellite_scene

pytestmark = pytest.mark.network


@pytest.mark.slow  # two cold compiles: one to two minutes on 2 cores
def test_a_cold_compile_under_a_short_stall_timeout_is_not_taken_for_a_hang(tmp_path):
    config, out, result = tmp_path / "cold.toml", tmp_path / "cold.mcap", tmp_path / "result.json"
    config.write_text(one_satellite_scene("cold", "5 s", "10 Hz"))
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba-cache")}  # empty: every kernel compiles
    done = subprocess.run([sys.executable, "-m", "astrodyn", "run", str(config), "--out", str(out), "--json",
                           str(result), "--quiet", "--stall-timeout", "2"],
                          env=env, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "hung" not in done.stderr and "restarted" not in done.stderr, done.stderr[-3000:]
    summary = json.loads(result.read_text())
    assert summary["restarts"] == [], summary["restarts"]
    assert any(Path(tmp_path / "numba-cache").rglob("*.nbi")), "nothing was compiled: the test did not test a cold start"
