"""A controller may not take the name of one of the run's own processes.

The plant drops commands signed with its own name (its copies of applied commands) and
``@batch/<process>`` envelopes of the run's processes (states, never commands).  A config
with ``controllers = ["plant"]`` was accepted; the controller's answers were then dropped
uncounted and the run failed after its timeout with "controller 'plant' did not answer"
(closed-loop probe, session 18).  The config now refuses such names, naming the field.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from astrodyn.messages import RUN_PROCESS_NAMES
from astrodyn.scenario import ScenarioError, load

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "detumble.toml"


def _config_with(tmp_path: Path, name: str) -> Path:
    text = CONFIG.read_text()
    new, n = re.subn(r"controllers = \[[^\]]*\]", f'controllers = ["{name}"]', text)
    assert n == 1
    path = tmp_path / f"c-{name}.toml"
    path.write_text(new)
    return path


@pytest.mark.parametrize("name", [*sorted(RUN_PROCESS_NAMES), "logger-2", "logger-17"])
def test_a_run_process_name_is_refused_naming_the_field(tmp_path, name):
    with pytest.raises(ScenarioError) as err:
        load(_config_with(tmp_path, name))
    text = str(err.value)
    assert "control.controllers[0]" in text and f'"{name}"' in text and "plant" in text


@pytest.mark.parametrize("name", ["pd", "loggerx", "logger-", "plant2", "my-orbit"])
def test_other_names_are_taken(tmp_path, name):
    assert load(_config_with(tmp_path, name)).control.controllers == (name,)


def test_run_refuses_it_in_one_line_before_starting_anything(tmp_path):
    out = tmp_path / "x.mcap"
    proc = subprocess.run([sys.executable, "-m", "astrodyn", "run", str(_config_with(tmp_path, "plant")), "--out", str(out)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, proc.stderr
    assert "control.controllers[0]" in proc.stderr and "Traceback" not in proc.stderr
    assert not out.exists() and not list(tmp_path.glob("*.mcap"))
