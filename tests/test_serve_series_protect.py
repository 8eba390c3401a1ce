"""serve never writes over an earlier recording's series (service probe F2, F7).

An earlier serve that rolled left ``NAME.mcap`` (part 0) and ``NAME-0001.mcap``, ...  A new
serve on ``--out NAME.mcap`` refused naming only the ``NAME-000k`` parts ("move it
elsewhere"); once they were moved it started, and at its stop replaced ``NAME.mcap``, the
first part of the earlier series.  Now the refusal names every file of the series,
``NAME.mcap`` included, and a ``NAME.mcap`` whose recording does not end in it (no ``end``
record: it rolled on, or is a killed serve's file finished by ``astrodyn recover``) is
refused on its own; a finished recording that ended in it (the logger's ``end`` record) is
replaced as before (README: serve replaces ``out/demo.mcap``).  A leftover partial part
(``NAME-0001.partial.mcap``) is named with ``astrodyn recover``, as ``NAME.partial.mcap`` is.

The series are written as serve's logger writes them (a rolling, atomic
:class:`~astrodyn.recording.McapRecorder`, its ``end`` record added where the logger adds
it); serve itself runs only up to its refusal (exit 2, before anything starts).
"""

from __future__ import annotations

import hashlib
import shutil
import subprocess
import sys
from pathlib import Path

from mcap.writer import Writer

from _recordings import one_satellite_scene
from astrodyn.recording import McapRecorder
from astrodyn.recording.recover import recover
from astrodyn.scenario import loads
from astrodyn.service.output import series_parts_problem

ASTRODYN = [sys.executable, "-m", "astrodyn"]
SCENE = one_satellite_scene("sp", "2 s", "10 Hz")


def _sha1(path: Path) -> str:
    return hashlib.sha1(path.read_bytes()).hexdigest()


def _served(out: Path, rolls: int, ended: bool = True) -> list[Path]:
    """The files of a serve session recorded to ``out`` that rolled ``rolls`` times: ``out``
    and its parts, each finished (summary, footer); the last holds the logger's ``end``
    record when ``ended`` (the logger writes it into the file it stops in)."""
    sc = loads(SCENE)
    rec = McapRecorder(out, sc.to_metadata(), epoch_ns=sc.epoch_unix_ns, atomic=True, roll_interval_s=1e-9,
                       flush_interval_s=3600.0)
    for k in range(rolls + 1):
        rec.write_encoded(f"astrodyn/{sc.name}/sat/orbit", b"{}", float(k), k)
        if k < rolls:
            rec.flush()  # every flush rolls (an age of 1 ns; a size is checked at each write)
    if ended:
        rec.add_metadata("end", {"reason": "stop requested"})
    rec.close()
    return [Path(p) for p in rec.paths]


def _serve(tmp_path: Path, out: Path) -> subprocess.CompletedProcess:
    config = tmp_path / "sp.toml"
    config.write_text(SCENE)
    return subprocess.run([*ASTRODYN, "serve", str(config), "--out", str(out), "--max-wall", "2", "--rate", "50"],
                          capture_output=True, text=True, timeout=120)


def test_the_refusal_names_every_file_of_the_earlier_series_first_part_included(tmp_path):
    out = tmp_path / "demo.mcap"
    files = _served(out, rolls=3)
    assert [f.name for f in files] == ["demo.mcap", "demo-0001.mcap", "demo-0002.mcap", "demo-0003.mcap"]
    problem = series_parts_problem(out)
    assert problem is not None and "move" in problem
    for f in files:
        assert str(f) in problem, (f, problem)


def test_serve_refuses_the_first_part_of_a_series_whose_parts_were_moved_and_keeps_it(tmp_path):
    """The probe's steps: parts moved away as the refusal said; the next serve must not
    replace demo.mcap (before: it started, and replaced it at its stop)."""
    out = tmp_path / "demo.mcap"
    files = _served(out, rolls=2)
    (tmp_path / "moved").mkdir()
    for f in files[1:]:
        shutil.move(f, tmp_path / "moved" / f.name)
    before = _sha1(out)
    proc = _serve(tmp_path, out)
    assert proc.returncode == 2, proc.stderr[-2000:]
    assert len(proc.stderr.strip().splitlines()) == 1 and str(out) in proc.stderr and "move" in proc.stderr, proc.stderr
    assert _sha1(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["demo.mcap", "moved", "sp.toml"]  # nothing else made


def test_a_killed_serves_recovered_file_is_not_replaced_a_finished_recording_is(tmp_path):
    """``recover`` of a killed serve's file gives a NAME.mcap without an ``end`` record (its
    recording may have gone on in parts; it holds the only copy of its session either way):
    refused.  A recording that ended in its file (an earlier run's or serve's that did not
    roll) may be replaced, and so may an MCAP file that is not an astrodyn recording."""
    out = tmp_path / "demo.mcap"
    sc = loads(SCENE)
    with McapRecorder(tmp_path / "w.mcap", sc.to_metadata(), epoch_ns=sc.epoch_unix_ns, flush_interval_s=3600.0) as rec:
        rec.write_encoded(f"astrodyn/{sc.name}/sat/orbit", b"{}", 0.0, 0)
        rec.flush()
        shutil.copyfile(tmp_path / "w.mcap", tmp_path / "demo.partial.mcap")  # a SIGKILLed logger's file
    (tmp_path / "w.mcap").unlink()
    recover(tmp_path / "demo.partial.mcap", out)
    (tmp_path / "demo.partial.mcap").unlink()
    problem = series_parts_problem(out)
    assert problem is not None and str(out) in problem and "move" in problem, problem

    out.unlink()
    _served(out, rolls=0, ended=True)  # a session that ended in its only file
    assert series_parts_problem(out) is None

    out.unlink()
    with open(out, "wb") as f:  # an MCAP file of another tool: no astrodyn metadata
        w = Writer(f)
        w.start()
        w.finish()
    assert series_parts_problem(out) is None


def test_a_first_part_is_told_from_the_summary_not_the_head(tmp_path):
    """The ``end`` record comes after the messages: it is found through the summary's
    metadata index, many chunks in (a long first part without it is refused, a long
    recording with it may be replaced)."""
    sc = loads(SCENE)
    for ended in (False, True):
        out = tmp_path / f"long-{ended}.mcap"
        with McapRecorder(out, sc.to_metadata(), epoch_ns=sc.epoch_unix_ns, chunk_size=1024,
                          flush_interval_s=3600.0) as rec:
            for k in range(2000):
                rec.write_encoded(f"astrodyn/{sc.name}/sat/orbit", b"{}", float(k), k)
            if ended:
                rec.add_metadata("end", {"reason": "stop requested"})
        problem = series_parts_problem(out)
        assert (problem is None) == ended, problem


def test_a_leftover_partial_part_is_named_with_recover(tmp_path):
    """F7: ``NAME-0001.partial.mcap`` (a killed serve's part) is refused with the command that
    finishes it, as ``NAME.partial.mcap`` is."""
    out = tmp_path / "demo.mcap"
    files = _served(out, rolls=1)
    files[1].rename(tmp_path / "demo-0001.partial.mcap")
    problem = series_parts_problem(out)
    assert problem is not None, problem
    assert f"astrodyn recover {tmp_path / 'demo-0001.partial.mcap'}" in problem, problem
    assert str(out) in problem and "move" in problem, problem


def test_run_does_not_write_over_the_first_part_of_a_series_either(tmp_path):
    """``astrodyn run --out demo.mcap`` replaced a demo.mcap that was the first part of a
    serve's series (or a recovered session's only file); a finished one it still replaces."""
    out = tmp_path / "demo.mcap"
    files = _served(out, rolls=1)
    files[1].unlink()  # demo-0001.mcap moved away: demo.mcap is the series' first part
    before = _sha1(out)
    config = tmp_path / "sp.toml"
    config.write_text(SCENE)
    proc = subprocess.run([*ASTRODYN, "run", str(config), "--out", str(out), "--quiet"], capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 2 and "run never writes over it" in proc.stderr, proc.stderr[-2000:]
    assert _sha1(out) == before
    out.unlink()
    _served(out, rolls=0, ended=True)
    proc = subprocess.run([*ASTRODYN, "run", str(config), "--out", str(out), "--quiet"], capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
