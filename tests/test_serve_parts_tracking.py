"""serve keeps track of its own parts across rolls (service probe F3).

serve restarts a killed propagator after the last step its channels hold in the newest of
its own parts (``supervision.LoggerFiles``, ``supervision.resume_from_parts``).  Two
things lost parts: a part serve had seen while it was partial vanished once the logger
named it (``writer.link_new``: a hard link to ``NAME-000k.mcap``, then an unlink of the
partial name), and a dead logger's part finished by ``astrodyn recover`` (its metadata
after the messages) was never taken as holding the run's config.  A propagator was then
restarted thousands of steps back, or from step 0.

The parts here are written as the logger writes them: a rolling, atomic
:class:`~astrodyn.recording.McapRecorder` reporting its files with the logger's own
``--own-files`` reporter; the states are those the numeric core computes
(:func:`astrodyn.simulate.simulate`), and the expected resume step is one past the last
step the test put into the part (the propagator continues after it).
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

from mcap.reader import make_reader
from mcap.stream_reader import StreamReader

from _recordings import one_satellite_scene
from astrodyn import messages
from astrodyn.recording import McapRecorder
from astrodyn.recording.recover import recover
from astrodyn.scenario import loads
from astrodyn.service.logger import own_files_reporter
from astrodyn.service.supervision import LoggerFiles, holds_config, resume_from_parts
from astrodyn.simulate import simulate

NAME = "pt"


def _scene(name: str = NAME, rate: str = "10 Hz"):
    sc = loads(one_satellite_scene(name, "3 s", rate))
    return sc, simulate(sc)


def _write_steps(rec: McapRecorder, sc, res, steps: range) -> None:
    """The orbit and attitude states of body ``sat`` at ``steps``, as the propagators publish them."""
    (orbit_model, attitude_model), = [(bp.orbit_model, bp.attitude_model) for bp in res.plan.bodies]
    for k in steps:
        t = float(res.t[k])
        rec.write(messages.orbit_key(sc.name, "sat"),
                  messages.orbit_message(t, k, orbit_model, res.r[k, 0], res.v[k, 0], sc.central_body.mu, sc.frame))
        rec.write(messages.attitude_key(sc.name, "sat"),
                  messages.attitude_message(t, k, attitude_model, res.q[k, 0], res.w[k, 0]))


def _rolling_recorder(out: Path, report: Path, sc) -> McapRecorder:
    """The logger's recorder of ``serve``: atomic (partial names until finished), reporting
    each file to ``report``; every flush rolls (``roll_interval_s`` 1 ns: the age is checked
    at each flush; a size is checked at each write), and only the test flushes (one flush an
    hour otherwise)."""
    return McapRecorder(out, sc.to_metadata(), epoch_ns=sc.epoch_unix_ns, atomic=True, roll_interval_s=1e-9,
                        flush_interval_s=3600.0, on_file=own_files_reporter(str(report)))


def test_a_part_seen_while_partial_is_still_found_after_it_rolled(tmp_path):
    """Part 1 is seen by serve while partial, then finished by the roll (link_new): it stays
    among serve's parts under its finished name, and a propagator killed right after the next
    roll (the new part holds none of its states yet) continues after the last step of part 1,
    not of part 0 (before: part 1 vanished from the list and the restart went back to step 10)."""
    sc, res = _scene()
    out, report = tmp_path / "served.mcap", tmp_path / "own-files.jsonl"
    own = LoggerFiles(report)
    rec = _rolling_recorder(out, report, sc)
    try:
        _write_steps(rec, sc, res, range(0, 10))
        assert [w for _, w in own.newest_first()] == [str(tmp_path / "served.partial.mcap")]
        rec.flush()  # part 0 finished as served.mcap, part 1 begins
        _write_steps(rec, sc, res, range(10, 20))
        first_part = tmp_path / "served-0001.partial.mcap"
        assert [w for _, w in own.newest_first()] == [str(first_part), str(out)]  # part 1 seen while partial
        rec.flush()  # part 1 named by a hard link and an unlink of its partial name; part 2 begins, empty
        assert not first_part.exists() and (tmp_path / "served-0001.mcap").exists()
        parts = [w for _, w in own.newest_first()]
        assert parts == [str(tmp_path / "served-0002.partial.mcap"), str(tmp_path / "served-0001.mcap"), str(out)]
        for kind in ("orbit", "attitude"):
            args, source = resume_from_parts(sc, kind, parts, tmp_path)
            assert (args["--start-step"], source) == (20, str(tmp_path / "served-0001.mcap")), kind
    finally:
        rec.close()
        own.close()


def test_a_finished_part_is_found_when_its_logger_reported_only_the_partial_name(tmp_path):
    """A logger killed between naming a part and reporting the name (or a serve that reads the
    report before that line): the part is found under its finished name all the same, also
    after the directory was renamed (the descriptor serve holds shows the unlinked partial
    name; the finished name is looked for beside it)."""
    sc, res = _scene()
    folder = tmp_path / "d"
    folder.mkdir()
    out, report = folder / "served.mcap", tmp_path / "own-files.jsonl"
    own = LoggerFiles(report)
    rec = _rolling_recorder(out, report, sc)
    try:
        _write_steps(rec, sc, res, range(0, 5))
        rec.flush()
        _write_steps(rec, sc, res, range(5, 10))
        own.sync()  # part 1 held while partial
        lines = report.read_bytes()
        rec.flush()  # part 1 takes its name ...
        report.write_bytes(lines)  # ... but the line saying so never came
        parts = [w for _, w in own.newest_first()]
        assert str(folder / "served-0001.mcap") in parts, parts
        rec.close(rename=False)  # (part 2 keeps its partial name)
        os.rename(folder, tmp_path / "moved")
        parts = [w for _, w in own.newest_first()]
        assert str(tmp_path / "moved" / "served-0001.mcap") in parts, parts
    finally:
        if not rec.closed:
            rec.close()
        own.close()


def _metadata_after_first_chunk(path: Path) -> bool:
    """Whether the file's "scenario" metadata record comes after its first chunk (read with
    the mcap library's own stream reader)."""
    seen_chunk = False
    with open(path, "rb") as f:
        for record in StreamReader(f, skip_magic=False, emit_chunks=True).records:
            kind = type(record).__name__
            if kind == "Chunk":
                seen_chunk = True
            elif kind == "Metadata" and record.name == "scenario":
                return seen_chunk
    raise AssertionError(f"{path}: no scenario metadata record")


def test_a_dead_loggers_part_finished_by_recover_is_a_resume_source(tmp_path):
    """A dead logger's part (cut after its last flush) finished by ``astrodyn recover`` holds
    its metadata after the messages: it is taken as holding the run's config (never another
    config's), and a restart continues after its last step (before: holds_config read only
    the records before the first chunk, so the part was refused and the restart went back
    to the previous part)."""
    sc, res = _scene()
    out, report = tmp_path / "served.mcap", tmp_path / "own-files.jsonl"
    with _rolling_recorder(out, report, sc) as rec:
        _write_steps(rec, sc, res, range(0, 10))  # part 0: steps 0 .. 9, finished as served.mcap
    cut = tmp_path / "served-0001.partial-1.mcap"
    with McapRecorder(tmp_path / "writing.mcap", sc.to_metadata(), epoch_ns=sc.epoch_unix_ns,
                      flush_interval_s=3600.0) as live:
        _write_steps(live, sc, res, range(10, 25))
        live.flush()
        shutil.copyfile(tmp_path / "writing.mcap", cut)  # what a SIGKILLed logger leaves: flushed chunks, no footer
    finished = tmp_path / "served-0001.mcap"
    recover(cut, finished, chunk_size=1024)  # small chunks: as a part of many MiB, its chunks come before the metadata
    with open(finished, "rb") as f:  # a complete file, by the mcap library's seeking reader
        assert make_reader(f).get_summary() is not None
    assert _metadata_after_first_chunk(finished)  # the case at hand
    assert holds_config(finished, sc)
    other, _ = _scene(rate="5 Hz")
    assert not holds_config(finished, other)  # another config's states are never a resume source
    assert not holds_config(finished, loads(one_satellite_scene("another", "3 s", "10 Hz")))
    for kind in ("orbit", "attitude"):
        args, source = resume_from_parts(sc, kind, [str(finished), str(out)], tmp_path)
        assert (args["--start-step"], source) == (25, str(finished)), kind


def test_holds_config_reads_no_chunk_of_a_large_part(tmp_path):
    """The metadata of a finished part is found through its summary's metadata index, not by
    reading the messages: with every chunk's bytes after the first one zeroed (a read of any
    of them would fail its CRC), the record is still found."""
    sc, res = _scene(rate="100 Hz")
    cut = tmp_path / "cut.mcap"
    with McapRecorder(tmp_path / "writing.mcap", sc.to_metadata(), epoch_ns=sc.epoch_unix_ns, chunk_size=4096,
                      flush_interval_s=3600.0) as live:
        _write_steps(live, sc, res, range(0, 300))
        live.flush()
        shutil.copyfile(tmp_path / "writing.mcap", cut)
    finished = tmp_path / "finished.mcap"
    recover(cut, finished, chunk_size=4096)
    with open(finished, "rb") as f:
        summary = make_reader(f).get_summary()
    chunks = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
    assert len(chunks) > 10
    with open(finished, "r+b") as f:
        for c in chunks:  # the chunk bodies (after their 9-byte record headers), zeroed
            f.seek(c.chunk_start_offset + 9)
            f.write(bytes(c.chunk_length - 9))
    assert holds_config(finished, sc)
