"""``astrodyn bench all`` and ``astrodyn bench soak`` as a user meets them (walk report F12, F19).

No benchmark body runs here: ``bench all`` is checked through its help and its argument
handling (each suite's ``main`` replaced), the soak through its verdict function on synthetic
samples, judged against the rule its docstring and ``--help`` state:

* the samples taken during start-up (the one at wall time 0 and any before sim time first
  advances) are left out;
* of the rest at least ``MIN_VERDICT_SAMPLES`` are needed (else: no verdict, exit 3, and how
  long a run must be);
* memory is flat when the last quarter's mean RSS is within 10 % of the second quarter's;
  the lag may grow by at most ``MAX_LAG_GROWTH_S``.
"""

from __future__ import annotations

import importlib
import math
import subprocess
import sys
from pathlib import Path

import pytest

from astrodyn.bench import SUITES, main as bench_main

ROOT = Path(__file__).resolve().parents[1]


def _bench(*argv: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "astrodyn", "bench", *argv], capture_output=True, text=True,
                          timeout=60, stdin=subprocess.DEVNULL, cwd=ROOT)


# --------------------------------------------------------------------------- bench all (F12)


def test_bench_all_help_describes_all():
    done = _bench("all", "--help")
    assert done.returncode == 0, done.stderr
    text = " ".join(done.stdout.split())
    assert text.startswith("usage: astrodyn bench all"), text  # not one suite's usage
    assert "astrodyn bench orbit" not in text
    for suite in SUITES:  # every suite named: the ones it runs, and the soak it leaves out
        assert suite in text, (suite, text)
    assert "Left out: soak" in text and "--quick" in text, text


@pytest.fixture
def ran(monkeypatch):
    """Every suite's ``main`` replaced by a recorder: the options it got (nothing runs)."""
    calls: dict[str, list[str]] = {}
    for name, module in SUITES.items():
        mod = importlib.import_module(module)

        def fake(argv=None, name=name, mod=mod):
            mod.parse_args(argv)  # the suite's own check of what it got
            calls[name] = list(argv)
            return 0

        monkeypatch.setattr(mod, "main", fake)
    return calls


def test_bench_all_quick_gives_every_suite_a_small_form_it_accepts(ran):
    assert bench_main(["all", "--quick"]) == 0
    assert set(ran) == set(SUITES) - {"soak"}  # every suite but the hour-long soak
    for name, argv in ran.items():
        assert argv, name  # each got a smaller form than its default
        args = importlib.import_module(SUITES[name]).parse_args(argv)
        default = importlib.import_module(SUITES[name]).parse_args([])
        assert vars(args) != vars(default), name


def test_bench_all_passes_other_options_after_the_quick_ones(ran):
    from astrodyn.bench import suite_args

    for name, argv in suite_args(["--repeats", "3"], quick=True).items():
        assert argv[-2:] == ["--repeats", "3"], (name, argv)  # last: argparse lets the given option win
    with pytest.raises(SystemExit) as exc:  # an option not every suite takes: refused before any suite runs
        bench_main(["all", "--quick", "--repeats", "3"])
    assert exc.value.code == 2 and ran == {}


def test_bench_attitude_does_not_write_into_the_repositorys_docs_by_default():
    """``make bench`` (``astrodyn bench all``, run in the checkout) rewrote the tracked
    docs/bench-attitude.md and .png: the attitude suite's default --out was ``docs``."""
    from astrodyn.bench import attitude

    out = Path(attitude.parse_args([]).out)
    assert not (ROOT / out).resolve().is_relative_to((ROOT / "docs").resolve()), out
    recipe = (ROOT / "Makefile").read_text().split("\nbench:", 1)[1].split("\n\n", 1)[0]
    assert "astrodyn bench all" in recipe and "docs" not in recipe.split("astrodyn bench all", 1)[1], recipe


# --------------------------------------------------------------------------- soak verdict (F19)


def _samples(n: int, rss=lambda k: 300.0, lag=lambda k: 1.0, start_rss: float = 9.0, sim_t0: float = 0.0) -> list[dict]:
    """``n`` soak samples every 10 s: sample 0 at start-up (small RSS, sim t ``sim_t0``),
    then RSS ``rss(k)`` MiB and lag ``lag(k)`` s for every process."""
    rows = []
    for k in range(n):
        row = {"wall_s": 10.0 * k, "status_rtt_ms": 1.0, "sim_t": sim_t0 if k == 0 else 10.0 * k - 1, "lag_s": lag(k)}
        for p in ("serve", "logger", "orbit", "attitude"):
            row[f"{p}_rss_mb"] = start_rss if k == 0 else rss(k)
        rows.append(row)
    return rows


def test_too_few_samples_is_no_verdict_and_says_how_long_to_run():
    from astrodyn.bench.soak import MIN_VERDICT_SAMPLES, verdict

    # the walk's run: --minutes 0.5 --sample 10 is 3 samples, the first at start-up (9 -> 296 MB)
    got = verdict(_samples(3, rss=lambda k: 296.0), sample_s=10.0)
    assert got["outcome"] == "NO VERDICT" and not got["failures"], got
    note = got["note"]
    assert f"too few samples for a verdict: need {MIN_VERDICT_SAMPLES}" in note and "got 2" in note, note
    minutes = float(note.split("--minutes >= ")[1].split()[0])
    # a run of that length takes enough samples (every 10 s from wall 0) after the one start-up sample,
    # with at most one sample interval to spare (rounded up to 0.1 min)
    assert math.ceil(minutes * 60 / 10.0) - 1 >= MIN_VERDICT_SAMPLES, minutes
    assert minutes <= (MIN_VERDICT_SAMPLES + 2) * 10.0 / 60 + 0.1, minutes


def test_no_verdict_still_fails_a_gap_or_a_logger_not_restarted():
    from astrodyn.bench.soak import verdict

    assert verdict(_samples(3), sample_s=10.0, gaps=1)["outcome"] == "FAILED"
    kills = [{"restart_delay_s": None}]
    assert verdict(_samples(3), sample_s=10.0, kills=kills)["outcome"] == "FAILED"
    assert verdict(_samples(3), sample_s=10.0, ended_early=True)["outcome"] == "FAILED"


def test_the_start_up_memory_rise_is_not_growth():
    from astrodyn.bench.soak import MIN_VERDICT_SAMPLES, verdict

    for n in (MIN_VERDICT_SAMPLES + 1, 12, 61):  # the shortest run with a verdict, and longer ones
        got = verdict(_samples(n, rss=lambda k: 296.0 + (k % 3)), sample_s=10.0)  # 9 -> 296 MB at start-up
        assert got["outcome"] == "OK", (n, got)
        assert all(got["flat"].values()) and got["lag_growth_s"] == pytest.approx(0.0), got
    # samples before sim time advances (kernels still loading) are start-up too
    rows = _samples(14, rss=lambda k: 40.0 if k < 3 else 296.0)
    for row in rows[:3]:
        row["sim_t"] = 0.0
    got = verdict(rows, sample_s=10.0)
    assert got["start_up"] == 3 and got["steady"] == 11 and got["outcome"] == "OK", got


def test_real_growth_fails():
    from astrodyn.bench.soak import verdict

    # 1 % per sample over 40 samples: the last quarter's mean is ~20 % above the second's
    got = verdict(_samples(41, rss=lambda k: 300.0 * (1 + 0.01 * k)), sample_s=10.0)
    assert got["outcome"] == "FAILED" and got["flat"]["orbit"] is False, got
    # 5 % growth stays within the 10 % band
    got = verdict(_samples(41, rss=lambda k: 300.0 * (1 + 0.05 * k / 40)), sample_s=10.0)
    assert got["outcome"] == "OK", got
    # the lag growing by 0.5 s a sample: ~10 s from the second quarter to the last, over 5 s
    got = verdict(_samples(41, lag=lambda k: 0.5 * k), sample_s=10.0)
    assert got["outcome"] == "FAILED" and got["lag_growth_s"] == pytest.approx(0.5 * (35 - 15), abs=1.0), got


def test_soak_help_documents_the_no_verdict_exit_status_and_minutes_bounds():
    done = _bench("soak", "--help")
    assert done.returncode == 0
    text = " ".join(done.stdout.split())
    assert "3 too few samples for a verdict" in text and "0.5..1440" in text, text
    done = _bench("soak", "--minutes", "0.1")
    assert done.returncode == 2 and "argument --minutes: expected a number 0.5 <= X <= 1440, got '0.1'" in done.stderr
