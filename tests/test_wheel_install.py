"""A plain (non-editable) install runs every command: the wheel in a fresh venv.

The wheel is built from a copy of the sources (pyproject.toml, setup.py, README.md, src/;
setup.py compiles the one C module, ``astrodyn.messages.floatlayout``) and
installed with ``pip install --no-deps`` into a new virtual environment, whose only other
path is the test venv's site-packages for the dependencies (a ``.pth`` line: that folder's
own ``.pth`` files, the editable install's among them, are not processed, so the package
can only come from the wheel).  From a folder outside the repository, ``astrodyn run`` and
``astrodyn serve`` then start their processes with ``python -m`` from the installed
package.  ``NUMBA_DISABLE_JIT=1`` keeps the test fast: the installed package has no numba
cache, and a cold compile is a minute; the kernels run as Python on a three-step scene.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest
from mcap.reader import make_reader

pytestmark = pytest.mark.network

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _recordings import one_satellite_scene  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]

SCENE = one_satellite_scene("wheel", "3 s", "1 Hz")


@pytest.fixture(scope="module")
def wheel_venv(tmp_path_factory) -> Path:
    tmp = tmp_path_factory.mktemp("wheel")
    src = tmp / "src-copy"
    src.mkdir()
    for name in ("pyproject.toml", "setup.py", "README.md"):
        shutil.copy2(ROOT / name, src / name)
    shutil.copytree(ROOT / "src", src / "src", ignore=shutil.ignore_patterns("__pycache__", "*.egg-info", "*.nbi", "*.nbc", "*.so"))
    build = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
                            "-w", str(tmp / "dist"), str(src)], capture_output=True, text=True, timeout=300)
    assert build.returncode == 0, build.stderr[-3000:]
    (wheel,) = (tmp / "dist").glob("astrodyn-*.whl")
    venv = tmp / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=120)
    py = venv / "bin" / "python"
    new_site = subprocess.run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                              capture_output=True, text=True, check=True).stdout.strip()
    Path(new_site, "astrodyn-test-deps.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    inst = subprocess.run([str(py), "-m", "pip", "install", "-q", "--no-deps", "--no-index", str(wheel)],
                          capture_output=True, text=True, timeout=300)
    assert inst.returncode == 0, inst.stderr[-3000:]
    return venv


def _env() -> dict:
    return {**os.environ, "NUMBA_DISABLE_JIT": "1"}


def test_the_installed_package_and_its_compiled_module_are_the_wheels(wheel_venv, tmp_path):
    code = "import astrodyn, astrodyn.messages.floatlayout as c; print(astrodyn.__file__); print(c.__file__)"
    out = subprocess.run([str(wheel_venv / "bin" / "python"), "-c", code],
                         capture_output=True, text=True, cwd=tmp_path, check=True).stdout.split()
    assert all(path.startswith(str(wheel_venv)) and not path.startswith(str(ROOT)) for path in out)


def test_run_from_the_wheel(wheel_venv, tmp_path):
    config = tmp_path / "wheel.toml"
    config.write_text(SCENE)
    out = tmp_path / "w.mcap"
    proc = subprocess.run([str(wheel_venv / "bin" / "astrodyn"), "run", str(config), "--out", str(out), "--quiet"],
                          capture_output=True, text=True, cwd=tmp_path, env=_env(), timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    with open(out, "rb") as f:
        topics = sorted({ch.topic for _, ch, _ in make_reader(f).iter_messages()})
    assert topics == ["astrodyn/wheel/@event", "astrodyn/wheel/sat/attitude", "astrodyn/wheel/sat/orbit"]


@pytest.mark.slow  # CI time (8 s): run from the wheel, which starts its processes the same way, stays in make test
def test_serve_from_the_wheel(wheel_venv, tmp_path):
    config = tmp_path / "wheel.toml"
    config.write_text(SCENE)
    out = tmp_path / "serve.mcap"
    proc = subprocess.Popen([str(wheel_venv / "bin" / "astrodyn"), "serve", str(config), "--out", str(out),
                             "--rate", "20", "--max-wall", "6"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path, env=_env())
    try:
        stdout, stderr = proc.communicate(timeout=180)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, stderr[-3000:]
    hello = json.loads(stdout.splitlines()[0])
    assert hello["serving"] == "wheel" and hello["hub"].startswith("tcp/127.0.0.1:")
    final = json.loads(stdout.strip().splitlines()[-1])
    assert final["state"] == "stopped" and final["logger"]["missing"] == 0
    assert final["logger"]["states"] > 0
