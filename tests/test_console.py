"""A command whose stdout / stderr reader goes away (``astrodyn run X | head``) keeps working.

Python ignores SIGPIPE, so a write into a pipe with no reader raises BrokenPipeError; before
astrodyn.console, the first progress line after ``head`` had exited ended ``run`` with exit 1,
a traceback nobody saw and a partial recording.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

from _recordings import one_satellite_scene, payloads_by_topic
from astrodyn.console import DropWhenClosed


def test_a_stream_whose_reader_has_gone_drops_what_follows():
    read_end, write_end = os.pipe()
    stream = DropWhenClosed(os.fdopen(write_end, "w"))
    os.close(read_end)  # the reader goes (the kernel answers EPIPE from now on)
    stream.write("a progress line\n")
    stream.flush()  # raises BrokenPipeError on the bare stream
    assert stream.closed_pipe
    stream.write("and more\n")
    stream.flush()
    assert stream.isatty() is False  # the rest is the wrapped stream's


def test_a_run_piped_into_a_reader_that_exits_finishes_its_recording(tmp_path):
    config = tmp_path / "piped.toml"
    config.write_text(one_satellite_scene("piped", "300 s", "10 Hz"))
    out = tmp_path / "piped.mcap"
    proc = subprocess.Popen([sys.executable, "-m", "astrodyn", "run", str(config), "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
    try:
        first = proc.stdout.readline()  # as `astrodyn run ... 2>&1 | head -1`
        proc.stdout.close()
        rc = proc.wait(timeout=300)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert first.startswith(b"scenario piped"), first
    assert rc == 0
    assert out.exists() and not (tmp_path / "piped.partial.mcap").exists()
    payloads = payloads_by_topic(out, ("/orbit", "/attitude"))
    assert sorted(payloads) == ["astrodyn/piped/sat/attitude", "astrodyn/piped/sat/orbit"]
    steps = 300 * 10 + 1  # 0 .. 300 s at 10 Hz, both ends included
    for topic, datas in payloads.items():
        assert [json.loads(d)["seq"] for d in datas] == list(range(steps)), topic
