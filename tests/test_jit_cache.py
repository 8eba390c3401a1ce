"""Kernels where numba can cache nothing: a read-only install run with a read-only home.

numba stores compiled kernels beside their sources, else in its user cache directory
(``$NUMBA_CACHE_DIR``, else ``~/.cache``); where neither is writable, ``cache=True`` raises
"no locator available" when the module is imported.  astrodyn then compiles without a cache
and says so once (astrodyn.jit.compile_kernel).  Before, ``astrodyn run`` ended at import with
that RuntimeError.  The read-only places are real read-only bind mounts (the test needs root
to make them and is skipped where it cannot).
"""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

KERNEL = '''
from astrodyn.jit import jit, kernels_uncached


@jit
def hypot3(x, y, z):
    return (x * x + y * y + z * z) ** 0.5
'''


@pytest.fixture
def read_only(tmp_path):
    """``(package_dir, home)``: two read-only bind mounts; the first holds a module ``kernels``."""
    pkg, home = tmp_path / "pkg", tmp_path / "home"
    pkg.mkdir()
    home.mkdir()
    (pkg / "kernels.py").write_text(KERNEL)
    mounted = []
    try:
        for d in (pkg, home):
            for cmd in (["mount", "--bind", str(d), str(d)], ["mount", "-o", "remount,bind,ro", str(d)]):
                done = subprocess.run(cmd, capture_output=True)
                if done.returncode != 0:
                    pytest.skip(f"cannot make a read-only bind mount here: {done.stderr.decode(errors='replace').strip()}")
                if cmd[1] == "--bind":
                    mounted.append(d)
        assert not os.access(pkg, os.W_OK) or _write_fails(pkg)
        yield pkg, home
    finally:
        for d in reversed(mounted):
            subprocess.run(["umount", "-l", str(d)], capture_output=True)


def _write_fails(folder) -> bool:
    try:
        (folder / "probe").write_text("x")
    except OSError:
        return True
    return False


def test_kernels_compile_and_run_without_a_writable_cache(read_only):
    pkg, home = read_only
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "XDG_CACHE_HOME", "NUMBA_DISABLE_JIT")}
    env.update(HOME=str(home), XDG_CACHE_HOME=str(home / ".cache"))
    code = ("import sys; sys.path.insert(0, sys.argv[1]); import kernels; "
            "print(kernels.hypot3(3.0, 4.0, 12.0), kernels.hypot3(1.0, 2.0, 2.0), kernels.kernels_uncached())")
    done = subprocess.run([sys.executable, "-c", code, str(pkg)], capture_output=True, text=True, env=env, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.split() == ["13.0", "3.0", "True"]  # 3-4-12-13 and 1-2-2-3: exact in float64
    notices = [line for line in done.stderr.splitlines() if "numba cannot cache compiled kernels" in line]
    assert len(notices) == 1 and "NUMBA_CACHE_DIR" in notices[0], done.stderr
    assert "Traceback" not in done.stderr
    assert not list(pkg.rglob("*.nbi")) and not list(home.rglob("*.nbi"))
