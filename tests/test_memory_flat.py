"""Peak memory of a run does not grow with its duration (issue 13 item 5).

The same scene is run for T and for 10 T; the peak resident set of every process of
the run (runner, propagators, logger: the largest of them, as the kernel reports it for
waited-for descendants, getrusage(RUSAGE_CHILDREN).ru_maxrss) must agree within 10 %.
A runner that allocated every output time up front, or a logger that kept every state,
would grow by the 9 T extra steps: 45,000 extra steps x 5 channels of ~200 B payloads
is ~45 MB, far above the 10 % bound on a ~200 MB process.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

CONFIGS = Path(__file__).resolve().parent.parent / "configs"

_MEASURE = """
import resource, subprocess, sys
rc = subprocess.run([sys.executable, "-m", "astrodyn", "run", sys.argv[1], "--out", sys.argv[2], "--quiet"]).returncode
print(rc, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)
"""


def _peak_rss_kib(tmp_path: Path, duration_s: int) -> int:
    cfg = tmp_path / f"demo-{duration_s}.toml"
    text = (CONFIGS / "demo.toml").read_text()
    cfg.write_text(text.replace('duration = "93 min"', f'duration = "{duration_s} s"').replace('rate = "1 Hz"', 'rate = "10 Hz"'))
    out = tmp_path / f"demo-{duration_s}.mcap"
    proc = subprocess.run([sys.executable, "-c", _MEASURE, str(cfg), str(out)], capture_output=True, text=True, timeout=600)
    rc, rss = proc.stdout.split()[-2:]  # after what the run itself prints
    assert rc == "0", proc.stderr[-2000:]
    return int(rss)


@pytest.mark.slow  # CI time (15 s): the bounded memory of hostile files, exports and sweep cases stays in make test
def test_peak_rss_is_flat_in_duration(tmp_path):
    short = _peak_rss_kib(tmp_path, 500)  # 5,001 steps
    long = _peak_rss_kib(tmp_path, 5000)  # 50,001 steps
    assert long <= 1.10 * short, f"peak RSS {short / 1024:.0f} MiB for T, {long / 1024:.0f} MiB for 10 T"
