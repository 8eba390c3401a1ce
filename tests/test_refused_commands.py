"""A refused command is reported, never fatal, and is not a lost message (docs/control.md).

The plant re-publishes on ``<body>/command`` only the commands it applied, each with its
sender's seq, so a refused one leaves a gap in that sender's seq.  The logger must not
count that gap as missing (before: the run failed with "1 messages missing" and the
refusal reason was never shown).  The seq accounting is checked against counting by hand.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from astrodyn.recording import GAP, OK, SeqTracker
from astrodyn.recording.stream import open_stream

ROOT = Path(__file__).resolve().parents[1]


def test_expected_gaps_are_reported_but_not_counted_missing():
    seq = SeqTracker()
    seq.expect_gaps("cmd#pd")
    assert [seq.add("cmd#pd", s) for s in (0, 1, 3, 4, 7)] == [OK, OK, GAP, OK, GAP]
    assert [seq.add("state", s) for s in (0, 2)] == [OK, GAP]
    totals = seq.totals()
    assert totals["missing"] == 1 and totals["skipped"] == 3 and totals["count"] == 7  # 2 | 5, 6 | 1
    assert seq.report()["cmd#pd"]["gaps"] == [[2, 2], [5, 6]]  # still in the per-channel report


def _slew_run(tmp_path: Path, each_tick: str, out: Path) -> subprocess.CompletedProcess:
    """``astrodyn run`` of configs/slew.toml cut to 2 s (21 steps, lockstep) into ``out``,
    with a controller on examples/astrodyn_link.py that runs ``each_tick`` at each tick
    (``n``: 1, 2, ...; it sends the step's commands), then answers the tick."""
    cfg = tmp_path / "slew.toml"
    cfg.write_text((ROOT / "configs" / "slew.toml").read_text().replace('duration = "180 s"', 'duration = "2 s"'))
    ctl = tmp_path / "ctl.py"
    ctl.write_text(textwrap.dedent(f"""
        import sys, time
        sys.path.insert(0, {str(ROOT / 'examples')!r})
        from astrodyn_link import Link
        with Link() as link:
            n = 0
            while (tick := link.wait_tick()) is not None:
                n += 1
    """) + textwrap.indent(textwrap.dedent(each_tick).strip("\n"), " " * 8) + "\n        link.done(tick)\n")
    return subprocess.run([sys.executable, "-m", "astrodyn", "run", str(cfg), "--out", str(out), "--quiet",
                           "--controller", f"python {ctl}"], capture_output=True, text=True, timeout=180, cwd=ROOT)


@pytest.mark.network
def test_a_refused_dv_between_applied_commands_does_not_fail_the_run(tmp_path):
    out = tmp_path / "r.mcap"
    proc = _slew_run(tmp_path, """
        if n == 3:  # the body has three wheels and no dv capability: refused
            link.command("sc", tick["t"], dv=[1.0, 0.0, 0.0])
        else:
            link.command("sc", tick["t"], wheel_torque=[0.001, 0.0, 0.0])
    """, out)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "body sc has no impulsive dv capability" in proc.stderr, proc.stderr[-3000:]
    with open_stream(out) as s:
        seqs = [json.loads(m.data)["seq"] for m in s.messages() if m.topic == "astrodyn/slew/sc/command"]
    steps = 21  # 2 s at the 0.1 s control period, t = 0 .. 2 s
    assert seqs == [s for s in range(steps) if s != 2], seqs  # every applied command once; the refused one absent


@pytest.mark.slow  # CI time (9 s; the seq rules stay covered by test_closed_loop_intake_hostile)
@pytest.mark.network
def test_a_restarted_controller_goes_on_above_its_numbers_and_a_reused_seq_is_refused(tmp_path):
    """Found by the churn probe: an outside controller restarted (its link numbering from 0
    again) had its commands applied by the plant but dropped by the logger as duplicates of
    the earlier instance's: 214,000 applied commands missing from a recording that said
    nothing was missing, and `--commands` re-simulation refused it.  Now the link goes on from
    the logger's next seq for its track, and the plant refuses a seq not above the last it
    took from that sender (the logger could not record it).  What is recorded is then what
    was applied: the re-simulation reproduces every state."""
    out, again = tmp_path / "r.mcap", tmp_path / "again.mcap"
    proc = _slew_run(tmp_path, """
        if n == 8:  # as a restarted controller starts: no numbers of its own yet
            time.sleep(0.5)
            link._seq.clear()
        if n == 14:  # three numbers used again
            link._seq["sc"] -= 3
        link.command("sc", tick["t"], wheel_torque=[0.001 * n, 0.0, 0.0])
    """, out)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "18 commands applied, 3 refused" in proc.stderr, proc.stderr[-3000:]  # 21 steps
    assert proc.stderr.count("is not above pd's last command to sc") >= 1, proc.stderr[-3000:]
    with open_stream(out) as s:
        seqs = [json.loads(m.data)["seq"] for m in s.messages() if m.topic == "astrodyn/slew/sc/command"]
    assert seqs == sorted(set(seqs)) and len(seqs) == 18, seqs  # every applied command, once
    proc = subprocess.run([sys.executable, "-m", "astrodyn", "run", str(tmp_path / "slew.toml"), "--quiet", "--out",
                           str(again), "--commands", str(out)], capture_output=True, text=True, timeout=180, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-3000:]
    with open_stream(out) as a, open_stream(again) as b:
        first, second = ([m.data for m in s.messages() if m.topic == "astrodyn/slew/sc/attitude"] for s in (a, b))
    assert len(first) == 21 and first == second
