"""A recording being written is never taken from under its logger (docs/reliability.md).

Found by hand: `astrodyn recover NAME.partial.mcap` while serve was still recording it
rewrote the partial file as NAME.mcap and unlinked it; the logger went on writing into
the unlinked file and its later states were lost (1,405 recorded, 294 kept).  A recorder
now holds an exclusive flock on the file it writes (released by the kernel when the
process ends, killed or not); recover and the --out checks of run / serve refuse a file
that is held.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from _serve_control import stop_serve
from astrodyn.recording import McapRecorder, load
from astrodyn.recording.writer import being_written

ROOT = Path(__file__).resolve().parents[1]
EPOCH_NS = 1_774_008_000_000_000_000


def test_a_recorder_holds_its_file_until_it_closes_or_its_process_dies(tmp_path):
    path = tmp_path / "r.mcap"
    rec = McapRecorder(path, {}, epoch_ns=EPOCH_NS)
    assert being_written(rec.writing_path) and not being_written(tmp_path / "missing.mcap")
    rec.close()
    assert not being_written(path)
    # another process's recorder, SIGKILLed: the kernel releases its lock, the file is recoverable
    script = textwrap.dedent(f"""
        import sys, time
        from astrodyn.recording import McapRecorder
        rec = McapRecorder({str(tmp_path / 'k.mcap')!r}, {{}}, epoch_ns={EPOCH_NS})
        print(rec.writing_path, flush=True)
        time.sleep(60)
    """)
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    try:
        partial = proc.stdout.readline().strip()
        assert being_written(partial)
        with pytest.raises(Exception, match="is being written by another process"):
            McapRecorder(Path(partial).with_name("k.mcap"), {}, epoch_ns=EPOCH_NS, attempt=0)
    finally:
        proc.kill()
        proc.wait()
    assert not being_written(partial)


@pytest.mark.slow  # CI time (10 s; the live-recording refusals stay covered by the other tests of this file)
@pytest.mark.network
def test_recover_and_a_second_run_leave_a_live_recording_alone(tmp_path):
    cfg = tmp_path / "demo.toml"
    cfg.write_text((ROOT / "configs" / "demo.toml").read_text())
    out = tmp_path / "live.mcap"
    partial = tmp_path / "live.partial.mcap"
    serve = subprocess.Popen([sys.executable, "-m", "astrodyn", "serve", str(cfg), "--out", str(out), "--rate", "50",
                              "--max-wall", "120"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    try:
        deadline = time.monotonic() + 90
        while time.monotonic() < deadline and not (partial.exists() and partial.stat().st_size > 20_000):
            assert serve.poll() is None, serve.communicate()
            time.sleep(0.2)
        recover = subprocess.run([sys.executable, "-m", "astrodyn", "recover", str(partial)], capture_output=True,
                                 text=True, timeout=60, cwd=ROOT)
        assert recover.returncode == 1 and "is being written by a running process" in recover.stderr, recover.stderr
        assert partial.exists() and not out.exists()  # untouched
        for command in ("run", "serve"):
            again = subprocess.run([sys.executable, "-m", "astrodyn", command, str(cfg), "--out", str(out), "--quiet"]
                                   if command == "run" else
                                   [sys.executable, "-m", "astrodyn", command, str(cfg), "--out", str(out)],
                                   capture_output=True, text=True, timeout=60, cwd=ROOT)
            assert again.returncode == 2 and "is being recorded right now" in again.stderr, again.stderr
    finally:
        stdout, stderr, summary = stop_serve(serve)
    assert serve.returncode == 0, stderr
    assert summary["file"] == str(out) and not summary["failures"], summary
    run = load(out)
    assert not run.truncated and run.invalid == 0
    for c in run.channels.values():
        if c.kind in ("orbit", "attitude"):
            assert np.array_equal(c.seq, np.arange(len(c)))  # the whole run, no state lost
    assert not partial.exists() and os.path.exists(out)
