"""``astrodyn recover FILE.mcap [--out FIXED.mcap]``: give a crashed writer's file a summary.

A logger killed with SIGKILL (or a machine that lost power) leaves an MCAP file without
data-end record, summary and footer.  Every chunk it flushed is intact (the recorder
flushes at least every ``flush_interval_s``, 1 s by default: that is the loss bound, see
:mod:`astrodyn.recording.writer`), so the file is readable by the streaming ``mcap``
reader and by :func:`astrodyn.recording.load`, but the seeking reader (``make_reader``,
Foxglove, the ``mcap`` CLI's ``info``) refuses it.

This command reads the file record by record (the same length-checked walk as
:func:`astrodyn.recording.load`: one chunk in memory at a time), keeps every complete
record -- schemas, channels, messages (payload, log time, publish time and sequence
unchanged, in file order) and metadata -- and writes a complete MCAP with chunk indexes,
statistics and footer.  A chunk whose data is damaged (zstd or CRC failure) is skipped
and counted; messages on channels whose definition was lost are counted as orphans.
A metadata record ``recovery`` says what was done: the source file, the messages kept,
the last log time (how far the run got), why the source ended, chunks skipped.

A killed ``astrodyn run`` / ``serve`` leaves ``NAME.partial.mcap`` (the logger writes there
and renames the finished file to ``NAME.mcap``): ``astrodyn recover NAME.partial.mcap``,
``astrodyn recover NAME.mcap`` (the run's ``--out``: its partial file is found) or
``astrodyn recover DIR`` (every partial file in the directory) finishes it as ``NAME.mcap``
(``NAME.recovered.mcap`` if a ``NAME.mcap`` exists: an earlier recording is never
replaced) and removes the partial file.  The work directories a killed supervisor left
in that directory (``.astrodyn-run-*``: its children's logs and the run secret) are
removed too, and so are the temporary files of killed ``merge`` / ``recover`` runs there
(``*.<pid>-<random>[.mcap].merging`` / ``.recover-tmp`` whose process is gone), and the
control token files of killed serves (``.NAME.mcap.control-token``) that no live serve can
own (:func:`stale_control_tokens`).

Given a recording's name (``NAME.mcap``), the partial files of its rolled series are
finished only when they are of that series (:func:`series_strangers`): each one's
``recording`` metadata record gives the part its name says (``NAME-0012.partial.mcap``:
part 12) and its ``scenario`` record is the series' (that of its first complete part).
Any other file named like one of its partial parts (a cut copy of another recording, or of
one of its own parts) is left as it is and named; ``recover`` of that file by its own name
finishes it.  ``--out`` is refused for a series with a rolled partial part
(``NAME-000k.partial.mcap``): it would write that one part under another name.

For any other file, without ``--out`` the file is rewritten in place; either way the new file is first
written beside the target as ``<root>.<pid>-<random><ext>.recover-tmp`` (a name of its own,
created with ``O_EXCL``) and given the final name only once it is finished, so a failure
(disk full, unwritable directory) never leaves a half-written file under the final name.
A new file takes its name only while the name is still free: when another ``recover`` or
``merge`` wrote it meanwhile, that complete file stays and this result is dropped (exit 1,
one line; this run removes no partial file).  The temporary files of the target left by
killed tools are removed by the next recover writing that target.

Exit status: 0 recovered (files left as not of the series are named on stderr, and do not
change it); 1 unreadable input or write failure (or both ``NAME.mcap`` and
``NAME.recovered.mcap`` exist: give ``--out``; or another process wrote the target
meanwhile); 2 bad arguments, judged before any input is read: a ``--chunk-size`` out of
range, an ``--out`` that exists (other than the input itself), is not a file path (a
directory, a FIFO, a device) or is in a missing or unwritable directory, or ``--out`` with
more than one partial file or with a series' rolled partial part.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import re
import shutil
import stat
import sys
import time

from mcap.records import Channel, Chunk, Message, Metadata, Schema

from astrodyn import __version__
from astrodyn.files import output_path_problem, path_argument
from astrodyn.messages import json_field
from astrodyn.recording.chunked_writer import ChunkedWriter
from astrodyn.recording.merge import recorded_parts
from astrodyn.recording.outputs import OutputTaken, process_may_run, stale_temporaries, write_atomically
from astrodyn.recording.reader import (
    MAX_CHUNK_BYTES,
    MCAP_MAGIC,
    chunk_records,
    open_recording,
    parse_record,
    read_records,
    recorded_metadata,
)
from astrodyn.recording.writer import RecordingError, being_written, part_path
from astrodyn.signals import interruptible_main

__all__ = ["recover", "write_atomically", "main", "finished_name", "find_partials", "partials_of", "nothing_to_recover",
           "stale_work_dirs", "series_part_number", "series_strangers", "stale_control_tokens"]


class _Copier:
    """Copies schemas, channels and messages into ``writer``, renumbering ids on first use."""

    def __init__(self, writer: ChunkedWriter):
        self.writer = writer
        self.schemas: dict[int, Schema] = {}  # source id -> record
        self.channels: dict[int, Channel] = {}
        self.new_schema: dict[int, int] = {}  # source id -> id in the new file
        self.new_channel: dict[int, int] = {}
        self.messages = 0
        self.orphans = 0
        self.first_log_time: int | None = None
        self.last_log_time: int | None = None

    def record(self, rec) -> None:
        if isinstance(rec, Schema):
            self.schemas.setdefault(rec.id, rec)
        elif isinstance(rec, Channel):
            self.channels.setdefault(rec.id, rec)
        elif isinstance(rec, Message):
            self.message(rec)

    def _channel_id(self, source_id: int) -> int | None:
        cid = self.new_channel.get(source_id)
        if cid is not None:
            return cid
        ch = self.channels.get(source_id)
        if ch is None:
            return None
        sid = 0  # MCAP: schema id 0 = no schema
        if ch.schema_id:
            sid = self.new_schema.get(ch.schema_id, 0)
            sc = self.schemas.get(ch.schema_id)
            if not sid and sc is not None:
                sid = self.new_schema[ch.schema_id] = self.writer.register_schema(sc.name, sc.encoding, sc.data)
        cid = self.new_channel[source_id] = self.writer.register_channel(ch.topic, ch.message_encoding, sid)
        return cid

    def message(self, msg: Message) -> None:
        cid = self._channel_id(msg.channel_id)
        if cid is None:
            self.orphans += 1
            return
        self.writer.add_message(cid, msg.log_time, msg.data, msg.publish_time, msg.sequence)
        self.messages += 1
        if self.first_log_time is None or msg.log_time < self.first_log_time:
            self.first_log_time = msg.log_time
        if self.last_log_time is None or msg.log_time > self.last_log_time:
            self.last_log_time = msg.log_time


def recover(path: str | os.PathLike, out: str | os.PathLike | None = None, *, chunk_size: int = 1 << 20) -> dict:
    """Rewrite the MCAP file ``path`` (complete or cut) as a complete file at ``out``
    (default: in place).  Returns a summary dict (see the module docstring).

    Raises :class:`RecordingError` naming the file for a non-MCAP or unreadable input, an
    ``out`` that exists (other than the input itself: nothing is overwritten) and for a
    failed write (the temporary file is removed; the target is untouched);
    :class:`astrodyn.recording.outputs.OutputTaken` (one) when another process wrote ``out``
    while this ran (its file is left as it was; this result is dropped).
    """
    src = os.fspath(path)
    dst = os.fspath(out) if out is not None else src
    t0 = time.monotonic()
    if being_written(src):  # a live logger's file: recovering it would take it from under the logger
        raise RecordingError(f"{src}: is being written by a running process (a logger of a run or serve that has "
                             f"not ended); it is finished by that process when it ends: stop the run, or recover the "
                             f"file once the process is gone")
    f, size = open_recording(src)
    with f:
        if os.path.exists(dst) and not os.path.isfile(dst):  # never rename over a device, fifo or directory
            raise RecordingError(f"{dst}: expected a regular file to write, got a special file or directory")
        in_place = dst == src or _same_file(src, dst)
        if not in_place and os.path.lexists(dst):
            raise RecordingError(f"{dst}: exists already; recover writes a new file (nothing is overwritten; only "
                                 f"the input itself is rewritten in place)")

        def write(stream) -> dict:
            summary = _rewrite(f, size, src, dst, stream, chunk_size)
            summary["output_bytes"] = stream.tell()
            return summary

        # a temporary file of its own (NAME.<pid>-<random>.mcap.recover-tmp); a new file takes
        # its name only while that name is free, the input itself is replaced in one step
        try:
            summary = write_atomically(dst, write, replace=in_place)
        except OutputTaken:
            raise OutputTaken(f"{dst}: another process wrote this file while the recovery ran; it holds that "
                              f"process's complete output and was left as it was; this recovery's result was "
                              f"dropped") from None
    summary["input_bytes"] = size
    summary["seconds"] = round(time.monotonic() - t0, 3)
    return summary


def _rewrite(f, size: int, src: str, dst: str, stream, chunk_size: int) -> dict:
    """Copy every readable record of ``f`` into a new file on ``stream``; the summary."""
    state: dict = {}
    notes: list[str] = []
    corrupt = 0
    metadata: list[Metadata] = []
    writer = ChunkedWriter(stream, chunk_size=chunk_size, library=f"astrodyn {__version__} (recover)")
    copier = _Copier(writer)
    for opcode, body, offset in read_records(f, size, src, state):
        try:
            rec = parse_record(opcode, body)
        except Exception as exc:  # framing intact, content damaged
            corrupt += 1
            notes.append(f"damaged record at byte {offset} skipped: {exc}")
            continue
        if isinstance(rec, Chunk):
            try:
                inner = chunk_records(rec)
            except Exception as exc:  # a bomb, zstd error, CRC mismatch, cut inner record
                corrupt += 1
                notes.append(f"corrupt chunk at byte {offset} skipped: {type(exc).__name__}: {exc}")
                continue
            for r in inner:
                copier.record(r)
        elif isinstance(rec, Metadata):
            if rec.name != "recovery":
                metadata.append(rec)
        elif rec is not None:
            copier.record(rec)
    for m in metadata:
        writer.add_metadata(m.name, dict(m.metadata))
    summary = {
        "source": src,
        "out": dst,
        "source_complete": bool(state.get("complete")),
        "source_end": state.get("truncation", "footer found (the file was already complete)"),
        "messages": copier.messages,
        "channels": len(copier.new_channel),
        "orphans": copier.orphans,
        "corrupt_chunks": corrupt,
        "first_log_time": copier.first_log_time,
        "last_log_time": copier.last_log_time,
        "notes": notes[:20],
    }
    writer.add_metadata("recovery", {
        **{k: v if isinstance(v, str) else json.dumps(v) for k, v in summary.items() if k != "out"},
        "astrodyn_version": __version__,
    })
    writer.finish()
    return summary


_PARTIAL = re.compile(r"^(?P<root>.+)\.partial(?:-(?P<attempt>\d+))?(?P<ext>\.[^.]+)$")


def finished_name(partial: str) -> str | None:
    """``NAME.mcap`` for a partial recording ``NAME.partial.mcap`` / ``NAME.partial-N.mcap``
    (:func:`astrodyn.recording.writer.partial_path`), None for any other name."""
    m = _PARTIAL.match(os.fspath(partial))
    return f"{m['root']}{m['ext']}" if m else None


def find_partials(target: str) -> list[str]:
    """The partial recordings ``recover TARGET`` finishes: for a directory, every partial
    file in it; for a recording name (``NAME.mcap``), the partial files of its series
    (:func:`series_partials`: a killed ``serve`` leaves its last part, ``NAME-000k.partial.mcap``,
    beside its finished ones), and TARGET itself when it exists and is not complete (a file
    cut by another writer); for any other existing file (a ``.partial`` one), TARGET."""
    if os.path.isdir(target):
        return sorted(os.path.join(target, f) for f in os.listdir(target) if _PARTIAL.match(f) and f.endswith(".mcap"))
    if not os.path.exists(target):
        return series_partials(target)
    if finished_name(target) is not None:
        return [target]
    series = series_partials(target)
    return series if series and is_complete(target) else [target, *series]


def series_partials(recording: str) -> list[str]:
    """The partial recordings beside ``recording`` (``NAME.mcap``) that finish as it or as
    one of its rolled parts (``NAME-000k.mcap``, :func:`astrodyn.recording.writer.part_path`),
    sorted."""
    root, ext = os.path.splitext(recording)
    folder = os.path.dirname(recording) or "."
    part = re.compile(re.escape(os.path.basename(root)) + r"(?:-\d{4,})?" + re.escape(ext or ".mcap") + "$")
    try:
        names = os.listdir(folder)
    except OSError:
        return []
    return sorted(os.path.join(folder, f) for f in names
                  if _PARTIAL.match(f) and part.match(os.path.basename(finished_name(f) or "")))


def names_series(target: str) -> bool:
    """Whether ``recover TARGET`` takes TARGET as a recording's name whose rolled series'
    partial files it finishes (:func:`find_partials`): not a directory, not a partial file's name."""
    return not os.path.isdir(target) and finished_name(target) is None


def series_part_number(recording: str, path: str) -> int | None:
    """The part of the rolled series of ``recording`` (``NAME.mcap``) that the file name of
    ``path`` is (:func:`astrodyn.recording.writer.part_path`): 0 for ``NAME.mcap``, k for
    ``NAME-000k.mcap``; None for any other name (only the base names are compared)."""
    root, ext = os.path.splitext(os.path.basename(recording))
    m = re.fullmatch(re.escape(root) + r"(?:-(\d{4,}))?" + re.escape(ext or ".mcap"), os.path.basename(path))
    if m is None:
        return None
    k = int(m[1]) if m[1] else 0
    return k if os.path.basename(part_path(os.path.basename(recording), k)) == os.path.basename(path) else None


def _recorded_part_and_scenario(path: str) -> tuple[int | None, dict | None]:
    """``(part, scenario record)`` of the file ``path``: its ``recording`` record's part
    number and its ``scenario`` record, each None when absent or when the file cannot be
    read (read from its head: a cut file has them there)."""
    try:
        meta = recorded_metadata(path, ("scenario", "recording"))
    except (RecordingError, OSError):
        return None, None
    parts = recorded_parts({"recording": meta.get("recording", {})})
    return (parts[0][0] if parts else None), meta.get("scenario")


def series_strangers(recording: str, partials: list[str]) -> dict[str, str]:
    """The files among ``partials`` (partial files named as parts of the rolled series of
    ``recording``, :func:`series_partials`) that their own metadata records show not to be
    of that series, each with why: one whose ``recording`` record gives another part than
    its name says (``NAME-0012.partial.mcap`` holding part 5: a copy of another part, or of
    another recording's), or whose ``scenario`` record is not the series' (that of its
    lowest complete part whose ``recording`` record gives its name's part; without one, of
    its lowest such partial file).  A file that does not say (no such record, or not
    readable: ``recover`` names what is wrong with it) is not listed.  Only the files'
    heads are read (:func:`astrodyn.recording.reader.recorded_metadata`)."""
    strangers: dict[str, str] = {}
    members: list[tuple[int, str, dict | None, bool]] = []  # (its name's part, path, scenario, says that part)
    for path in partials:
        named = series_part_number(recording, finished_name(path) or path)
        part, scenario = _recorded_part_and_scenario(path)
        if named is not None and part is not None and part != named:
            strangers[path] = (f"its `recording` metadata record says part {part}, its name part {named}: it is not "
                               f"that part of the series (a copy of another file?)")
        else:
            members.append((named if named is not None else -1, path, scenario, part is not None))
    folder = os.path.dirname(recording) or "."
    try:
        names = os.listdir(folder)
    except OSError:
        names = []
    complete = sorted((k, os.path.join(folder, f)) for f in names
                      if (k := series_part_number(recording, f)) is not None and is_complete(os.path.join(folder, f)))
    reference = next(((path, scenario) for k, path in complete
                      for part, scenario in [_recorded_part_and_scenario(path)] if part == k and scenario is not None),
                     None)
    if reference is None:
        reference = next(((path, scenario) for k, path, scenario, says in sorted(members, key=lambda x: x[0])
                          if k >= 0 and says and scenario is not None), None)
    for _, path, scenario, _ in members:
        if reference is not None and scenario is not None and scenario != reference[1]:
            name, ref_name = scenario.get("name"), reference[1].get("name")
            what = (f"scenario {name!r}, not {ref_name!r} as" if name != ref_name
                    else f"another config of scenario {name!r} than")
            strangers[path] = (f"its `scenario` metadata record is of {what} in {os.path.basename(reference[0])}, "
                               f"a part of this series: it is not of this series")
    return strangers


def is_complete(path: str) -> bool:
    """Whether the file at ``path`` ends as a finished MCAP file does: a footer record
    followed by the closing magic (what a writer that finished leaves; ``recover`` of it has
    nothing to do)."""
    footer = 9 + 20  # opcode, length, summary_start, summary_offset_start, summary_crc
    try:
        with open(path, "rb") as f:
            size = os.fstat(f.fileno()).st_size
            if size < 2 * len(MCAP_MAGIC) + footer:
                return False
            f.seek(size - len(MCAP_MAGIC) - footer)
            tail = f.read(footer + len(MCAP_MAGIC))
    except OSError:
        return False
    return tail[0] == 0x02 and int.from_bytes(tail[1:9], "little") == 20 and tail[footer:] == MCAP_MAGIC


def partials_of(recording: str) -> list[str]:
    """The partial recordings (``NAME.partial.mcap``, ``NAME.partial-N.mcap``) beside
    ``recording`` (``NAME.mcap``) that finish as it, sorted."""
    root, _ = os.path.splitext(recording)
    folder = os.path.dirname(recording) or "."
    stem = os.path.basename(root) + ".partial"
    try:
        names = os.listdir(folder)
    except OSError:
        return []
    target = os.path.normpath(recording)  # "x.mcap" and "./x.mcap" name one file
    return sorted(os.path.join(folder, f) for f in names
                  if f.startswith(stem) and _PARTIAL.match(f)
                  and os.path.normpath(finished_name(os.path.join(folder, f)) or "") == target)


def nothing_to_recover(target: str) -> str:
    """Why ``recover TARGET`` has nothing to do when TARGET does not exist: a partial
    recording's own name is missing (the others of its recording are named, if any); a
    recording's name has no partial recording either (``NAME.partial*.mcap``)."""
    final = finished_name(target)
    if final is None:
        return f"{target}: no such file, and no partial recording of it ({os.path.splitext(target)[0]}.partial*.mcap)"
    others = [p for p in partials_of(final) if os.path.normpath(p) != os.path.normpath(target)]
    return f"{target}: no such file" + (f"; other partial recordings of {final}: {', '.join(others)}" if others else "")


def stale_work_dirs(folder: str) -> list[str]:
    """Work directories (``.astrodyn-run-*``, ``.astrodyn-serve-*``) in ``folder`` whose
    supervisor is gone: a killed supervisor cannot remove its own (children's logs, the
    run secret); ``recover`` removes them."""
    return [path for path in _work_dirs(folder, (".astrodyn-run-", ".astrodyn-serve-")) if _supervisor_gone(path)]


def _work_dirs(folder: str, prefixes: tuple[str, ...]) -> list[str]:
    try:
        names = os.listdir(folder)
    except OSError:
        return []
    return sorted(os.path.join(folder, name) for name in names if name.startswith(prefixes))


def _supervisor_gone(work: str) -> bool:
    """Whether the supervisor of the work directory ``work`` is gone: its ``supervisor.pid``
    names no running process; without a pid file (a start-up under way: the pid is written
    just after the directory is made) or with a damaged one, when the directory is older
    than :data:`STARTING_WORK_DIR_S`.  A pid file that cannot be read for want of permission
    (another user's directory), or a process of another user's under that pid, is not gone."""
    try:
        with open(os.path.join(work, "supervisor.pid")) as f:
            pid = int(f.read().strip())
        if not 0 < pid < 2**31:  # (0 or -N would ask about a process group)
            raise ValueError(pid)
    except PermissionError:
        return False
    except (OSError, ValueError):
        try:
            return time.time() - os.stat(work).st_mtime >= STARTING_WORK_DIR_S
        except OSError:
            return False  # (removed meanwhile)
    return not process_may_run(pid)


#: ``serve``'s control token file for its recording ``NAME``: ``.NAME.control-token`` beside it
#: (:func:`astrodyn.service.serve.control_token_path`); group ``recording`` the recording's file name.
_CONTROL_TOKEN = re.compile(r"^\.(?P<recording>.+)\.control-token$")
#: The report of the files a serve's loggers created, in its work directory (one JSON line
#: ``{"file", "dev", "ino"}`` each: the logger's ``--own-files``, ``astrodyn.service.supervision.LoggerFiles``).
_OWN_FILES = "own-files.jsonl"


def _serve_recordings(work: str) -> list[str] | None:
    """The base names of the files the loggers of the serve whose work directory is ``work``
    created (its ``own-files.jsonl``); None when it names none (a serve starting: its logger
    has not created its first file yet) or cannot be read."""
    try:
        with open(os.path.join(work, _OWN_FILES), "rb") as f:
            data = f.read(1 << 24)
    except OSError:
        return None
    names = []
    for line in data.splitlines():
        if isinstance(file := json_field(line, "file"), str):
            names.append(os.path.basename(file))
    return names or None


def stale_control_tokens(folder: str) -> list[tuple[str, os.stat_result]]:
    """Control token files in ``folder`` (``.NAME.control-token``, this user's regular files)
    whose serve is gone, for ``recover`` to remove (a killed serve cannot), each with its
    ``lstat`` taken before the serves were looked at (remove it only while it is still that
    file: a serve started meanwhile writes a new one).  A serve writes its
    token only while its work directory (``.astrodyn-serve-*``, beside its recording, with its
    pid) exists, so the token of ``NAME`` is the dead serve's when no serve whose supervisor
    runs (:func:`stale_work_dirs`' rule) may record ``NAME``: every live serve's loggers
    created files of another recording (its ``own-files.jsonl``; one that names none yet may
    be ``NAME``'s), and no partial file of ``NAME``'s series is being written.  A token whose
    ``NAME`` is a symbolic link is left (its serve's work directory may be elsewhere)."""
    try:
        names = os.listdir(folder)
    except OSError:
        return []
    tokens = []
    for name in sorted(names):
        if (m := _CONTROL_TOKEN.match(name)) is None:
            continue
        path = os.path.join(folder, name)
        try:
            st = os.lstat(path)
        except OSError:
            continue
        if stat.S_ISREG(st.st_mode) and st.st_uid == os.getuid():
            tokens.append((path, os.path.join(folder, m["recording"]), st))
    if not tokens:
        return []
    # (after the lstat: a serve that starts later and writes its token makes another file)
    live = [_serve_recordings(work) for work in _work_dirs(folder, (".astrodyn-serve-",)) if not _supervisor_gone(work)]
    out = []
    for path, recording, st in tokens:
        if os.path.islink(recording):
            continue
        if any(names_of is None or any(series_part_number(recording, finished_name(f) or f) is not None
                                       for f in names_of) for names_of in live):
            continue  # a live serve records it, or may (it has created no file yet)
        if any(being_written(p) for p in series_partials(recording)):
            continue
        out.append((path, st))
    return out


#: A work directory without a readable ``supervisor.pid`` younger than this (seconds) is a
#: supervisor's start under way, not a killed one's: ``recover`` leaves it.
STARTING_WORK_DIR_S = 60.0


def _still(path: str, read: os.stat_result) -> bool:
    """Whether ``path`` is still the file that was read (``read``: its stat then) and no
    process writes it: only then may it be removed (a new run may have started a new
    partial file of that name meanwhile)."""
    try:
        now = os.stat(path)
    except OSError:
        return False
    return (now.st_dev, now.st_ino) == (read.st_dev, read.st_ino) and not being_written(path)


def _same_file(a: str, b: str) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


#: Largest ``--chunk-size`` (bytes): the writer holds a chunk in one buffer of that size, and
#: astrodyn's reader decompresses no larger chunk (:data:`astrodyn.recording.reader.MAX_CHUNK_BYTES`).
MAX_CHUNK_SIZE = MAX_CHUNK_BYTES


@interruptible_main("astrodyn recover")
def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="astrodyn recover",
                                 description="Rewrite a crashed writer's MCAP file with a proper summary and index.")
    ap.add_argument("file", type=path_argument, help="MCAP file (typically cut by a killed logger): a NAME.partial.mcap left by a killed "
                    "run, the --out path of that run or serve (the partial files of its series are found: "
                    "NAME.partial.mcap, NAME-000k.partial.mcap; one whose metadata says it is another part or "
                    "another scenario is left and named), or a directory (every partial file in it); a "
                    "complete file is left as it is unless --out is given")
    ap.add_argument("--out", default=None, type=path_argument, help="write the recovered file here (default: NAME.mcap for "
                    "NAME.partial.mcap when no NAME.mcap exists, NAME.recovered.mcap when it does; other files "
                    "are rewritten in place); one file only: refused for several partial files and for a rolled "
                    "series' partial part NAME-000k.partial.mcap found from NAME.mcap (give that file itself)")
    ap.add_argument("--chunk-size", type=int, default=1 << 20,
                    help=f"uncompressed bytes per zstd chunk of the new file (1 .. {MAX_CHUNK_SIZE}, default 1 MiB)")
    args = ap.parse_args(argv)
    if not 0 < args.chunk_size <= MAX_CHUNK_SIZE:  # the chunk is a buffer of this size: 1e11 asked for 93 GiB
        print(f"astrodyn recover: --chunk-size: expected bytes 1 <= N <= {MAX_CHUNK_SIZE} (64 MiB), got "
              f"{args.chunk_size}", file=sys.stderr)
        return 2
    if args.out is not None and (problem := output_path_problem(args.out)):  # a directory, a FIFO, no such folder
        print(f"astrodyn recover: --out {args.out}: {problem}", file=sys.stderr)
        return 2
    sources = find_partials(args.file)
    if not sources and os.path.isdir(args.file):
        print(json.dumps({"partial_recordings": 0, "directory": args.file}), flush=True)
    elif not sources:
        print(f"astrodyn recover: error: {nothing_to_recover(args.file)}", file=sys.stderr)
        return 1
    rolled = [src for src in sources if src != args.file and series_part_number(args.file, finished_name(src) or src)
              != 0] if names_series(args.file) else []
    if args.out is not None and rolled:  # judged by name alone, before any input is read
        print(f"astrodyn recover: --out: {args.file} is a rolled recording whose partial part {rolled[0]} finishes as "
              f"{finished_name(rolled[0])}, beside its other parts; --out would write that one part under another "
              f"name: give no --out to finish every partial part of the series under its part's name, or name the "
              f"partial file to write it elsewhere (`astrodyn recover {rolled[0]} --out {args.out}`)", file=sys.stderr)
        return 2
    if args.out is not None and len(sources) > 1:
        print(f"astrodyn recover: --out: {len(sources)} partial files found ({', '.join(sources)}); recover them one "
              f"at a time to choose each --out", file=sys.stderr)
        return 2
    if args.out is not None and sources and os.path.lexists(args.out) and not _same_file(sources[0], args.out):
        print(f"astrodyn recover: {sources[0]}: --out {args.out} exists already; recover writes a new file (nothing "
              f"is overwritten; only the input itself is rewritten in place)", file=sys.stderr)
        return 2
    status = 0
    strangers = series_strangers(args.file, [src for src in sources if src != args.file]) \
        if names_series(args.file) else {}
    for src, why in strangers.items():  # named like a part of the series, but not one: left as it is
        print(json.dumps({"source": src, "left": why}), flush=True)
        print(f"astrodyn recover: warning: {src} was left as it is: {why}; it is not finished as a part of "
              f"{args.file} (`astrodyn recover {src} --out FILE.mcap` finishes it by itself)", file=sys.stderr)
    for src in sources:
        if src in strangers:
            continue
        dst, remove_source = args.out, False
        final = finished_name(src)
        if dst is None and final is None and is_complete(src):  # in place, and nothing to finish
            print(json.dumps({"source": src, "source_complete": True, "nothing_done": "the file is complete (footer "
                              "found); give --out to rewrite it anyway"}), flush=True)
            continue
        if dst is None and final is not None:
            root, ext = os.path.splitext(final)
            dst = final if not os.path.exists(final) else f"{root}.recovered{ext}"
            if os.path.exists(dst):
                print(f"astrodyn recover: error: {src}: both {final} and {dst} exist; give --out", file=sys.stderr)
                status = 1
                continue
            remove_source = True
        try:
            read = os.stat(src)
            summary = recover(src, dst, chunk_size=args.chunk_size)
        except OSError as exc:  # gone meanwhile (another recover of it finished)
            print(f"astrodyn recover: error: {src}: {exc.strerror or exc}", file=sys.stderr)
            status = 1
            continue
        except RecordingError as exc:
            print(f"astrodyn recover: error: {exc}", file=sys.stderr)
            status = 1
            continue
        if remove_source and os.path.abspath(src) != os.path.abspath(summary["out"]) and _still(src, read):
            with contextlib.suppress(FileNotFoundError):  # (another recover of it may have removed it)
                os.unlink(src)  # everything it held is in the finished file
                summary["removed"] = src
        print(json.dumps(summary, separators=(",", ":")), flush=True)
    folder = args.file if os.path.isdir(args.file) else (os.path.dirname(args.file) or ".")
    tokens = stale_control_tokens(folder)  # (judged before the work directories go)
    for work in stale_work_dirs(folder):
        shutil.rmtree(work, ignore_errors=True)
        print(json.dumps({"removed_work_directory": work}), flush=True)
    for path, read in tokens:  # a killed serve's: no live serve can own it (its owner's work directory is gone)
        with contextlib.suppress(OSError):
            now = os.lstat(path)
            if (now.st_dev, now.st_ino) == (read.st_dev, read.st_ino):  # not a new serve's, written meanwhile
                os.unlink(path)
                print(json.dumps({"removed_control_token": path}), flush=True)
    for tmp in stale_temporaries(folder):  # what a killed merge or recover left
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
            print(json.dumps({"removed_temporary_file": tmp}), flush=True)
    return status


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
