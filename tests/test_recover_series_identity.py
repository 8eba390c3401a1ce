"""``astrodyn recover NAME.mcap`` of a killed serve's rolled series (session 20 probe D, D5).

- Every ``NAME-00NN.partial.mcap`` was finished as part NN, whatever it held: a cut copy of
  another recording became ``k-0013.mcap``, a cut copy of ``k-0005`` a duplicate part
  ``k-0012.mcap``.  Only a file whose own metadata records say it is that part of that
  series is finished now (its ``recording`` record's part is the one its name says, its
  ``scenario`` record the series'); the others are left as they are and named.
- ``--out`` with a series wrote its partial *part* to ``--out``, while the help reads as
  "the file given is rewritten to --out": refused (exit 2), naming the part and how to write
  it elsewhere.  ``NAME.mcap --out`` of a killed ``run`` (its one partial file) still works.
- The killed serve's control token file ``.NAME.mcap.control-token`` was left while its work
  directory was removed: it is removed when no live serve can own it.

The recordings are written by the recorder a logger uses (:class:`McapRecorder`, with
``first_part`` for a rolled part); a killed logger's file is a complete one cut short.  What
must come out is fixed by that construction: which file holds which part of which scenario.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from _recordings import one_satellite_scene
from astrodyn import messages
from astrodyn.recording import McapRecorder
from astrodyn.recording.recover import is_complete, main as recover_main
from astrodyn.recording.writer import being_written
from astrodyn.scenario import loads

SERIES = loads(one_satellite_scene("series", "100 s", "1 Hz"))
OTHER = loads(one_satellite_scene("other", "100 s", "1 Hz"))


def part_file(base: Path, scenario, part: int, steps: range) -> Path:
    """Part ``part`` of the recording ``base`` of ``scenario``: the orbit states of ``steps``
    (a new chunk every few of them, so a cut keeps some)."""
    rec = McapRecorder(base, scenario.to_metadata(), epoch_ns=scenario.epoch_unix_ns, first_part=part, chunk_size=512)
    with rec:
        for k in steps:
            rec.write(f"astrodyn/{scenario.name}/sat/orbit", messages.orbit_message(
                float(k), k, "kepler", [7e6, 0, 0], [0, 7.5e3, 0], 3.986004418e14))
    return Path(rec.paths[-1])


def elsewhere(folder: Path, name: str) -> Path:
    """``name`` in a directory of its own below ``folder`` (where a file is written before
    its copy is put beside the series)."""
    for n in range(100):
        other = folder / f"elsewhere-{n}"
        if not other.exists():
            other.mkdir()
            return other / name
    raise AssertionError("no free directory name")


def cut_copy(source: Path, partial: Path) -> bytes:
    """What a killed logger leaves of ``source``: its first two thirds, at ``partial``."""
    data = source.read_bytes()[: source.stat().st_size * 2 // 3]
    partial.write_bytes(data)
    return data


def test_only_partial_parts_of_the_series_are_finished_the_others_are_left_and_named(tmp_path, capsys):
    base = tmp_path / "k.mcap"
    first, second = part_file(base, SERIES, 0, range(0, 20)), part_file(base, SERIES, 1, range(20, 40))
    third = part_file(elsewhere(tmp_path, "k.mcap"), SERIES, 2, range(40, 60))
    cut_copy(third, tmp_path / "k-0002.partial.mcap")  # the killed serve's last part
    copy_of_part_1 = cut_copy(second, tmp_path / "k-0003.partial.mcap")  # records part 1
    other = part_file(elsewhere(tmp_path, "o.mcap"), OTHER, 4, range(0, 20))
    copy_of_other = cut_copy(other, tmp_path / "k-0004.partial.mcap")  # part 4, of scenario "other"
    assert (first.name, second.name) == ("k.mcap", "k-0001.mcap")

    assert recover_main([str(base)]) == 0
    captured = capsys.readouterr()
    assert is_complete(str(tmp_path / "k-0002.mcap")) and not (tmp_path / "k-0002.partial.mcap").exists()
    # the strangers: untouched, not finished as parts, each named with why
    assert (tmp_path / "k-0003.partial.mcap").read_bytes() == copy_of_part_1
    assert (tmp_path / "k-0004.partial.mcap").read_bytes() == copy_of_other
    assert not (tmp_path / "k-0003.mcap").exists() and not (tmp_path / "k-0004.mcap").exists()
    assert "k-0003.partial.mcap was left as it is" in captured.err and "says part 1, its name part 3" in captured.err
    assert "k-0004.partial.mcap was left as it is" in captured.err and "scenario 'other', not 'series'" in captured.err
    left = {json.loads(line)["source"] for line in captured.out.splitlines() if "left" in json.loads(line)}
    assert left == {str(tmp_path / "k-0003.partial.mcap"), str(tmp_path / "k-0004.partial.mcap")}

    # named by itself, a stranger is finished as the user asks
    assert recover_main([str(tmp_path / "k-0004.partial.mcap"), "--out", str(tmp_path / "o-4.mcap")]) == 0
    assert is_complete(str(tmp_path / "o-4.mcap"))


def test_out_is_refused_for_a_series_with_a_partial_part_and_taken_for_a_killed_runs_file(tmp_path, capsys):
    base = tmp_path / "k.mcap"
    part_file(base, SERIES, 0, range(0, 20))
    cut = cut_copy(part_file(elsewhere(tmp_path, "k.mcap"), SERIES, 1, range(20, 40)), tmp_path / "k-0001.partial.mcap")
    out = tmp_path / "out.mcap"
    assert recover_main([str(base), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "k-0001.partial.mcap finishes as" in err and f"astrodyn recover {tmp_path / 'k-0001.partial.mcap'}" in err, err
    assert not out.exists() and (tmp_path / "k-0001.partial.mcap").read_bytes() == cut

    # a killed run's one file (NAME.partial.mcap, part 0): --out writes it
    cut_copy(part_file(elsewhere(tmp_path, "run.mcap"), SERIES, 0, range(0, 20)), tmp_path / "run.partial.mcap")
    assert recover_main([str(tmp_path / "run.mcap"), "--out", str(out)]) == 0
    assert is_complete(str(out))


def serve_work_dir(folder: Path, name: str, pid: int, own_files: list[str] | None) -> Path:
    """A serve's work directory as ``serve`` makes it: its pid, and the files its loggers
    created (``own-files.jsonl``; None: none yet, a serve starting)."""
    path = folder / name
    path.mkdir()
    (path / "supervisor.pid").write_text(str(pid))
    if own_files is not None:
        (path / "own-files.jsonl").write_text("".join(json.dumps({"file": str(folder / f), "dev": 1, "ino": n}) + "\n"
                                                      for n, f in enumerate(own_files)))
    return path


def token(folder: Path, recording: str) -> Path:
    path = folder / f".{recording}.control-token"
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    os.write(fd, b"t" * 43)
    os.close(fd)
    return path


def gone_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])  # a PID that was a process and is no more
    proc.wait()
    return proc.pid


def test_a_killed_serves_control_token_is_removed_once_no_live_serve_can_own_it(tmp_path, capsys):
    part_file(tmp_path / "k.mcap", SERIES, 0, range(0, 20))
    serve_work_dir(tmp_path, ".astrodyn-serve-dead", gone_pid(), ["k.partial.mcap", "k.mcap"])
    killed = token(tmp_path, "k.mcap")
    # while a live serve may own it, it stays: one of k.mcap (rolled on since), one starting
    # (no file of its loggers yet)
    for own_files in (["k-0003.partial.mcap"], None):
        live = serve_work_dir(tmp_path, ".astrodyn-serve-live", os.getpid(), own_files)
        assert recover_main([str(tmp_path / "k.mcap")]) == 0
        assert killed.exists() and live.exists(), own_files
        for f in live.iterdir():
            f.unlink()
        live.rmdir()
    capsys.readouterr()
    dead = serve_work_dir(tmp_path, ".astrodyn-serve-dead-2", gone_pid(), ["k.partial.mcap", "k.mcap"])
    # a live serve of another recording in the same directory (serve's default out/ holds all):
    # k.mcap's token is the dead serve's, the other one's is left
    live = serve_work_dir(tmp_path, ".astrodyn-serve-live", os.getpid(), ["o.partial.mcap"])
    running = token(tmp_path, "o.mcap")
    assert recover_main([str(tmp_path / "k.mcap")]) == 0
    out = capsys.readouterr().out
    assert not killed.exists() and not dead.exists() and json.dumps({"removed_control_token": str(killed)}) in out
    assert running.exists() and live.exists()


@pytest.mark.slow  # a real serve (a few seconds): the unit tests above cover each rule
@pytest.mark.network
def test_recover_after_a_killed_serve_removes_its_control_token_and_finishes_its_last_part(tmp_path):
    """The files a real ``serve`` leaves when SIGKILLed (its token file, its work directory
    with ``own-files.jsonl``, its last part partial): ``recover`` of its ``--out`` finishes
    the part and removes the token and the work directory."""
    config = tmp_path / "tiny.toml"
    config.write_text(one_satellite_scene("tiny", "1 day", "10 Hz"))
    out = tmp_path / "k.mcap"
    proc = subprocess.Popen([sys.executable, "-m", "astrodyn", "serve", str(config), f"--out={out}", "--rate", "100",
                             "--max-wall", "60"], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                            start_new_session=True)
    try:
        first = json.loads(proc.stdout.readline())
        token_file = Path(first["control_token_file"])
        deadline = time.monotonic() + 30
        while not (token_file.exists() and list(tmp_path.glob(".astrodyn-serve-*/own-files.jsonl"))):
            assert time.monotonic() < deadline and proc.poll() is None, "serve did not start"
            time.sleep(0.1)
        time.sleep(1.0)  # some states recorded
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
        deadline = time.monotonic() + 30  # its children end once their supervisor is gone
        while any(being_written(p) for p in tmp_path.glob("k*.partial*.mcap")):
            assert time.monotonic() < deadline, "the killed serve's logger still writes"
            time.sleep(0.1)
        assert token_file.exists() and list(tmp_path.glob("k*.partial*.mcap"))
        assert recover_main([str(out)]) == 0
        assert not token_file.exists() and not list(tmp_path.glob(".astrodyn-serve-*"))
        assert not list(tmp_path.glob("k*.partial*.mcap")) and is_complete(str(out))
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)  # (the serve's group: its children, if any are left)
        proc.stdout.close()


def test_partials_of_a_name_without_a_folder_are_found(tmp_path, monkeypatch):
    """``recover x.partial.mcap`` run in x's folder names x's other partial files: "x.mcap"
    and "./x.mcap" are one file (the listing joins "." to the names)."""
    from astrodyn.recording.recover import nothing_to_recover, partials_of

    for name in ("x.partial.mcap", "x.partial-1.mcap", "y.partial.mcap"):
        (tmp_path / name).write_bytes(b"")
    monkeypatch.chdir(tmp_path)
    assert [os.path.basename(p) for p in partials_of("x.mcap")] == ["x.partial-1.mcap", "x.partial.mcap"]
    said = nothing_to_recover("x.partial-2.mcap")
    assert "x.partial.mcap" in said and "x.partial-1.mcap" in said and "y.partial" not in said
