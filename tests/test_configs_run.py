"""Every scenario in configs/ runs headless through the real service with nothing lost.

(demo.toml has its own, deeper end-to-end test in test_service.py; constellation-1000
moves 2.4 million messages and is marked slow: `make test-all`, and `astrodyn bench service`.)
"""

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

from astrodyn.scenario import load

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = sorted(p for p in (ROOT / "configs").glob("*.toml") if p.stem != "demo")
#: run in `make test-all` only: constellation-1000 (minutes); explorer-1 (15 s) is also run
#: by test_flexible_service.py::test_explorer_1_run_drifts_to_a_flat_spin_and_the_oblate_twin_stays_put,
#: flexible-slew (12 s) as it is, with its controller, by test_plant_flexible.py's `slew` fixture
# detumble: its controller on this config (cut to 30 s) runs in test_closed_loop, test_docs_walk_fixes and
# test_live_view (CI time)
SLOW_CONFIGS = ("constellation-1000", "explorer-1", "flexible-slew", "detumble",  # CI time; the others run
                "hyperbolic-flyby")  # (8 s; the hyperbolic Kepler path is in the orbit tests and hard cases)

pytestmark = pytest.mark.network


@pytest.mark.parametrize(
    "config",
    [pytest.param(p, id=p.stem, marks=[pytest.mark.slow] if p.stem in SLOW_CONFIGS else []) for p in CONFIGS],
)
def test_config_runs_with_nothing_lost(config, tmp_path):
    out, res = tmp_path / "run.mcap", tmp_path / "result.json"
    # a closed-loop scene runs with the controller its header comment names (docs/control.md)
    found = re.search(r'--controller "python (examples/[\w.]+\.py)"', config.read_text())
    controller = ["--controller", f"python {ROOT / found.group(1)}"] if found else []
    assert bool(found) == ("[control]" in config.read_text()), "a closed-loop config names its controller"
    proc = subprocess.run([sys.executable, "-m", "astrodyn", "run", str(config), "--out", str(out), "--quiet",
                           "--json", str(res), "--timeout", "600", *controller], capture_output=True, text=True,
                          timeout=900)
    assert proc.returncode == 0, proc.stderr[-2000:]
    result = json.loads(res.read_text())
    scn = load(config)
    logger = result["logger"]
    # every state of every body, and only those: the plan's message count
    from astrodyn.scenario import plan

    assert logger["states"] == plan(scn).messages
    assert logger["missing"] == 0 and logger["malformed"] == 0 and logger["duplicates"] == 0
    assert len(result["bodies"]) == len(scn.bodies)
