"""A child's stdout / stderr files in the supervisor's work directory stay within a cap
(closedloop F16: a chatty controller wrote 375 MB/s there, on the disk of the recording, for
as long as serve ran), the child is never held up by it, and its last words are kept."""

from __future__ import annotations

import contextlib
import sys
import textwrap
import time

import pytest

from astrodyn.service.children import OUTPUT_CAP_BYTES, Child, start_controller

MIB = 1024 * 1024
#: What the chatty child writes to each stream: many times the cap.
WRITTEN_MIB = 50

CHATTY = textwrap.dedent(f"""
    import sys
    block = (b"x" * 1023 + b"\\n") * 1024  # 1 MiB of 1 kB lines
    for _ in range({WRITTEN_MIB}):
        sys.stdout.buffer.write(block)
        sys.stderr.buffer.write(block)
    sys.stdout.buffer.flush()
    sys.stderr.buffer.write(b"the final line of stderr\\n")
    sys.stdout.buffer.write(b'{{"summary": "the final line of stdout"}}\\n')
""")


def _on_disk(folder, name: str) -> int:
    """Bytes of the output files of child ``name`` in ``folder`` (every file it may use)."""
    total = 0
    for path in folder.iterdir():
        if path.name.startswith(f"{name}."):
            with contextlib.suppress(FileNotFoundError):  # moved aside meanwhile
                total += path.stat().st_size
    return total


def test_a_chatty_controller_keeps_its_output_files_within_the_cap(tmp_path):
    script = tmp_path / "chatty.py"
    script.write_text(CHATTY)
    work = tmp_path / "work"
    work.mkdir()
    child = start_controller("chatty", f"python {script}", "nothing", "tcp/127.0.0.1:9", work, None, None)
    try:
        largest = 0
        deadline = time.monotonic() + 30
        while child.poll() is None and time.monotonic() < deadline:  # watched while it writes
            largest = max(largest, _on_disk(work, "controller-chatty"))
            time.sleep(0.002)
        assert child.poll() == 0, child.last_words()  # finished: never held up by its output
        assert largest <= 2 * OUTPUT_CAP_BYTES  # two streams, each within the cap
        assert child.last_words(1) == "the final line of stderr"
        assert child.summary() == {"summary": "the final line of stdout"}
        child.close()
        for stream in ("out", "err"):
            size = sum(p.stat().st_size for p in work.glob(f"controller-chatty.{stream}*"))
            assert 0 < size <= OUTPUT_CAP_BYTES, stream
        assert OUTPUT_CAP_BYTES < WRITTEN_MIB * MIB  # the test wrote more than the cap
    finally:
        child.stop(timeout=5)
        child.close()


def test_astrodyns_own_processes_write_their_files_and_are_cut_back_to_the_cap(tmp_path):
    """A child that is not foreign writes its files itself (its last words survive its
    supervisor); once it has ended the files are back within the cap, the last lines kept."""
    script = tmp_path / "chatty.py"
    script.write_text(CHATTY)
    child = Child("own", [sys.executable, str(script)], tmp_path)
    try:
        assert child.proc.wait(timeout=30) == 0
        deadline = time.monotonic() + 5
        while _on_disk(tmp_path, "own") > 2 * OUTPUT_CAP_BYTES and time.monotonic() < deadline:
            time.sleep(0.05)
        assert _on_disk(tmp_path, "own") <= 2 * OUTPUT_CAP_BYTES
        assert child.last_words(1) == "the final line of stderr"
        assert child.summary() == {"summary": "the final line of stdout"}
    finally:
        child.stop(timeout=5)
        child.close()


@pytest.mark.parametrize("foreign", [True, False])
def test_a_quiet_child_keeps_all_it_wrote(tmp_path, foreign):
    lines = [f"line {k}" for k in range(100)]
    child = Child("quiet", [sys.executable, "-c", f"import sys; sys.stderr.write({chr(10).join(lines)!r} + '\\n')"],
                  tmp_path, foreign=foreign)
    try:
        assert child.proc.wait(timeout=30) == 0
        assert child.stderr_tail(100).splitlines() == lines
        child.close()
        assert (tmp_path / "quiet.err").read_text().splitlines() == lines
        assert not (tmp_path / "quiet.err.1").exists()
    finally:
        child.stop(timeout=5)
        child.close()
