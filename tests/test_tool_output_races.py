"""Two file tools writing one output at once, and a recorder rolling onto a taken part name.

``merge`` and ``recover`` wrote through one fixed temporary name (``.M.merging``,
``M.recover-tmp``) opened with ``"wb"``: two of them at once wrote into one file, the first
to finish renamed it to ``--out`` while the other went on writing into it (a corrupt hybrid
that ``load`` called complete), and the other then printed a traceback or said "nothing was
written" about bytes that were in ``--out``.  Now each writes a temporary file of its own
(``O_EXCL``) and a new ``--out`` takes its name only while it is free: the final name holds
one tool's complete output, the other says in one line that its result was dropped.

The results are checked with the plain ``mcap`` package's seeking reader (not astrodyn's):
the whole file is read through its summary and the messages equal, as a set, those of the
input of the tool that succeeded.  Real processes; the interleaving that used to corrupt
the file is forced by stopping one tool (SIGSTOP) while it writes.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from _recordings import leo_recording

ASTRODYN = [sys.executable, "-m", "astrodyn"]


@pytest.fixture(scope="module")
def data(tmp_path_factory) -> Path:
    """big.mcap (two bodies, 20 min at 10 Hz: 36,003 messages), small.mcap (1 min at 2 Hz),
    cut.mcap (big.mcap cut at 2/3: a killed logger's file)."""
    d = tmp_path_factory.mktemp("races")
    leo_recording(d / "big.mcap", duration="1200 s", rate="10 Hz")
    leo_recording(d / "small.mcap", duration="60 s", rate="2 Hz")
    whole = (d / "big.mcap").read_bytes()
    (d / "cut.mcap").write_bytes(whole[: len(whole) * 2 // 3])
    return d


def _messages(path: Path) -> list[tuple]:
    """Every message of ``path`` read with the mcap package's seeking reader (summary, chunk
    indexes), sorted: (topic, log time, publish time, sequence, payload).  The count must
    also be the one the file's statistics give."""
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        reader = make_reader(f)
        out = sorted((ch.topic, m.log_time, m.publish_time, m.sequence, bytes(m.data))
                     for _, ch, m in reader.iter_messages())
        assert reader.get_summary().statistics.message_count == len(out), path
    return out


def _start(processes, *argv) -> subprocess.Popen:
    return processes([*ASTRODYN, *map(str, argv)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _temporaries(d: Path) -> list[Path]:
    return sorted(p for p in d.iterdir() if p.name.endswith((".merging", ".recover-tmp")))


def _wait_for(proc: subprocess.Popen, condition, timeout: float = 60.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert proc.poll() is None, f"ended (status {proc.returncode}) before the moment: {proc.stderr.read()[-2000:]}"
        assert time.monotonic() < deadline, "the moment never came"
        time.sleep(0.001)


def _a_new_temporary(d: Path, before: dict[str, tuple]):
    """A temporary file that is not one of ``before`` (name -> (inode, size)) as it was."""
    def found() -> bool:
        for p in _temporaries(d):
            try:
                st = p.stat()
            except FileNotFoundError:
                continue
            if before.get(p.name) != (st.st_ino, st.st_size):
                return True
        return False
    return found


def _snapshot(d: Path) -> dict[str, tuple]:
    return {p.name: (p.stat().st_ino, p.stat().st_size) for p in _temporaries(d)}


def _killed_while_writing(processes, d: Path, *argv) -> None:
    """Run the tool ``argv`` and SIGKILL it once its temporary file exists (what a kill -9
    leaves: that file)."""
    before = _snapshot(d)
    proc = _start(processes, *argv)
    _wait_for(proc, _a_new_temporary(d, before))
    proc.kill()
    proc.communicate(timeout=30)
    assert _temporaries(d), "the killed tool left no temporary file to clean up"


def _stopped_while_writing(processes, d: Path, *argv) -> subprocess.Popen:
    """Start the tool ``argv`` and SIGSTOP it once its temporary file is there (it is
    writing its output)."""
    before = _snapshot(d)
    proc = _start(processes, *argv)
    _wait_for(proc, _a_new_temporary(d, before))
    os.kill(proc.pid, signal.SIGSTOP)
    assert proc.poll() is None
    return proc


def _no_traceback(*errs: str) -> None:
    for err in errs:
        assert "Traceback" not in err, err


# ------------------------------------------------------------------------------- merge


def _race_into_one_out(tool: str, trials: int, tmp_path, data, processes) -> None:
    """``trials`` times, ``astrodyn <tool> big.mcap --out X`` and the same with small.mcap
    started together: exactly one ends 0 and X holds its result, whole; the other ends in
    one true line (its result dropped: exit 1, or X already there: exit 2), never a
    traceback nor "nothing was written"; no temporary file is left."""
    inputs = {"big": _messages(data / "big.mcap"), "small": _messages(data / "small.mcap")}
    for trial in range(trials):
        d = tmp_path / f"t{trial}"
        d.mkdir()
        out = d / "out.mcap"
        procs = {name: _start(processes, tool, data / f"{name}.mcap", "--out", out) for name in ("big", "small")}
        ended = {name: (*p.communicate(timeout=60), p.returncode) for name, p in procs.items()}
        _no_traceback(*(err for _, err, _ in ended.values()))
        winners = [name for name, (_, _, rc) in ended.items() if rc == 0]
        assert len(winners) == 1, ended
        assert _messages(out) == inputs[winners[0]], f"trial {trial}: --out is not {winners[0]}.mcap's {tool}"
        (loser,) = set(ended) - set(winners)
        _, err, rc = ended[loser]
        assert err.count("\n") == 1 and "nothing was written" not in err, err
        assert (rc, "another process wrote this file" in err or "exists already" in err) in ((1, True), (2, True)), err
        assert not _temporaries(d)


def test_two_merges_into_one_out_at_once_leave_one_whole_file(tmp_path, data, processes):
    """Started together, 3 times.  Before: both exited 0 (the second replaced the first
    one's output), or --out was a hybrid of the two."""
    _race_into_one_out("merge", 3, tmp_path, data, processes)


def test_a_merge_overtaken_by_another_keeps_the_other_whole_and_says_so(tmp_path, data, processes):
    """Merge A stopped while it writes; merge B into the same --out runs to its end; A
    continued.  Before: B truncated and rewrote the temporary file A was writing, renamed it
    to --out, and A went on writing into it: a corrupt hybrid, and A's message claimed
    nothing had been written.  Now: --out is B's whole merge, A exits 1 saying its result was
    dropped, and the temporary file a killed merge left is removed by the next merge."""
    out = tmp_path / "m.mcap"
    _killed_while_writing(processes, tmp_path, "merge", data / "big.mcap", "--out", out)
    a = _stopped_while_writing(processes, tmp_path, "merge", data / "big.mcap", "--out", out)
    try:
        b = subprocess.run([*ASTRODYN, "merge", str(data / "small.mcap"), "--out", str(out)],
                           capture_output=True, text=True, timeout=60)
        assert b.returncode == 0, b.stderr
        left_by_b = _temporaries(tmp_path)  # the stopped merge's only: the killed one's removed
    finally:
        os.kill(a.pid, signal.SIGCONT)
    _, a_err = a.communicate(timeout=60)
    _no_traceback(a_err, b.stderr)
    assert _messages(out) == _messages(data / "small.mcap")
    assert len(left_by_b) == 1, left_by_b
    assert a.returncode == 1 and "another process wrote this file" in a_err and "dropped" in a_err, a_err
    assert a_err.count("\n") == 1 and "nothing was written" not in a_err, a_err
    assert not _temporaries(tmp_path)


def test_a_merge_of_a_file_its_writer_did_not_finish_warns_in_one_line(tmp_path, data):
    """Before: only the JSON report said so; export and analyze warn on stderr."""
    proc = subprocess.run([*ASTRODYN, "merge", str(data / "cut.mcap"), "--out", str(tmp_path / "m.mcap")],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"astrodyn merge: warning: {data / 'cut.mcap'}: truncated"), lines
    assert "merged the complete messages it holds" in lines[0]


# ------------------------------------------------------------------------------- recover


def test_two_recovers_into_one_out_at_once_leave_one_whole_file(tmp_path, data, processes):
    """Started together, twice.  Before: the loser printed a traceback (the rename of the
    shared temporary file failed) and --out could be a hybrid."""
    _race_into_one_out("recover", 2, tmp_path, data, processes)


def test_a_recover_overtaken_by_another_recover_of_the_same_partial_file(tmp_path, data, processes):
    """Two ``recover X.partial.mcap``: A stopped while it writes X.mcap, B finishes it and
    removes the partial file, A continued.  Before: A's rename failed with a
    FileNotFoundError traceback.  Now: X.mcap is B's whole recovery, A exits 1 in one line,
    and the temporary files a killed recover (of X) and a killed merge (into another file
    of the directory) left are removed by B."""
    from astrodyn.recording.recover import recover

    reference = tmp_path / "ref" / "x.mcap"
    reference.parent.mkdir()
    shutil.copy(data / "cut.mcap", tmp_path / "ref" / "cut.mcap")
    recover(tmp_path / "ref" / "cut.mcap", reference)
    partial = tmp_path / "x.partial.mcap"
    shutil.copy(data / "cut.mcap", partial)
    _killed_while_writing(processes, tmp_path, "recover", partial)
    _killed_while_writing(processes, tmp_path, "merge", data / "big.mcap", "--out", tmp_path / "m.mcap")
    a = _stopped_while_writing(processes, tmp_path, "recover", partial)
    try:
        b = subprocess.run([*ASTRODYN, "recover", str(partial)], capture_output=True, text=True, timeout=60)
        assert b.returncode == 0 and not partial.exists(), b.stderr
    finally:
        os.kill(a.pid, signal.SIGCONT)
    _, a_err = a.communicate(timeout=60)
    _no_traceback(a_err, b.stderr)
    assert _messages(tmp_path / "x.mcap") == _messages(reference)
    assert a.returncode == 1 and "another process wrote this file" in a_err and a_err.count("\n") == 1, a_err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ref", "x.mcap"]


# ------------------------------------------------------------------------------- the recorder's rolled parts


@pytest.mark.parametrize("atomic", [True, False], ids=["partial-then-rename", "in-place"])
def test_a_rolled_part_never_replaces_an_existing_part(tmp_path, data, atomic):
    """A part of an earlier session (``x-0001.mcap``) is where this recorder's part 1 goes.
    Before: renamed over it (atomic) or truncated by the open (in place), without a word.
    Now it stays byte-identical; the new part is kept, complete, as ``x-0001.clash-1.mcap``
    and the recorder's stats name it (the caller fails loudly with that)."""
    from astrodyn import messages
    from astrodyn.recording import McapRecorder

    earlier = tmp_path / "x-0001.mcap"
    shutil.copy(data / "small.mcap", earlier)
    before = earlier.read_bytes()
    key = messages.orbit_key("rp", "sat")
    with McapRecorder(tmp_path / "x.mcap", {"name": "rp"}, epoch_ns=0, roll_interval_s=1e-9, atomic=atomic) as rec:
        for part in range(3):  # each flush finishes a part (an age of 1 ns) and starts the next
            for seq in range(part * 5, part * 5 + 5):
                rec.write(key, messages.orbit_message(float(seq), seq, "kepler", [7e6, 0, 0], [0, 7.5e3, 0], 3.986e14))
            rec.flush()
    stats = rec.stats()
    kept = tmp_path / "x-0001.clash-1.mcap"
    assert earlier.read_bytes() == before
    assert stats["parts_kept_aside"] == [{"part": str(earlier), "file": str(kept), "why": stats["parts_kept_aside"][0]["why"]}]
    assert str(kept) in stats["paths"] and str(earlier) not in stats["paths"]
    assert [m[3] for m in _messages(kept)] == [5, 6, 7, 8, 9]
    assert [m[3] for m in _messages(tmp_path / "x-0002.mcap")] == [10, 11, 12, 13, 14]
    assert not list(tmp_path.glob("*.partial*"))
