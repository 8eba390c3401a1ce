"""What analyze draws of a long series, and how a file tool ends when memory runs out.

`astrodyn.analysis.figures.envelope` reduces a long time series to the least and greatest
sample of each run of consecutive samples before matplotlib draws it (a 345,600-state
recording took ~700 MB to draw before, ~500 MB after, with the same pixels: see the commit).
Checked against a brute-force reduction of the same runs, with NaN, spikes and (for log
axes) values <= 0 that are not drawn.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from astrodyn.analysis.figures import envelope


@pytest.mark.parametrize("n", [10, 8193, 100_003])
@pytest.mark.parametrize("log", [False, True])
def test_envelope_keeps_every_runs_extremes_in_order(n, log):
    rng = np.random.default_rng(n)
    x = np.cumsum(rng.uniform(0.5, 1.5, n))
    y = rng.normal(size=n) ** 2 * (1 - 2 * (rng.uniform(size=n) < 0.1))  # some negative
    y[rng.integers(0, n, 5)] = np.nan
    y[rng.integers(0, n, 3)] = 1e6  # spikes
    runs = 4096
    xd, yd = envelope(x, y, runs, log=log)
    if n <= 2 * runs:
        assert xd is x and yd is y
        return
    assert xd.size <= 2 * runs + 2 and np.all(np.diff(xd) > 0)  # a subset, in order
    assert xd[0] == x[0] and xd[-1] == x[-1]
    kept = np.isin(x, xd)
    assert np.array_equal(y[kept], yd, equal_nan=True)  # the samples themselves, not made-up values
    size = -(-n // runs)
    for start in range(0, n, size):
        run, drawn = y[start:start + size], y[start:start + size][kept[start:start + size]]
        shown = run[np.isfinite(run) & (run > 0)] if log else run[np.isfinite(run)]
        if shown.size:
            assert np.nanmax(drawn) == shown.max()
            mins = drawn[np.isfinite(drawn) & (drawn > 0)] if log else drawn[np.isfinite(drawn)]
            assert mins.min() == shown.min()


def test_a_file_tool_out_of_memory_ends_with_one_line_and_exit_1():
    """A MemoryError (from a memory limit: `ulimit -v`, a container) ends a file tool with
    one line, not a traceback, and exit 1 (measured on `analyze` of a 35 MB recording
    under a 600 MB / 700 MB address-space limit: a traceback, then SIGABRT / SIGSEGV)."""
    code = ("from astrodyn.signals import interruptible\n"
            "def run():\n    raise MemoryError('std::bad_alloc')\n"
            "raise SystemExit(interruptible('astrodyn analyze', run))\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 1, proc.stderr
    assert proc.stderr.strip() == "astrodyn analyze: out of memory (std::bad_alloc); no output was left half-written"
