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
(``*.<pid>-<random>[.mcap].merging`` / ``.recover-tmp`` whose process is gone).

For any other file, without ``--out`` the file is rewritten in place; either way the new file is first
written beside the target as ``<root>.<pid>-<random><ext>.recover-tmp`` (a name of its own,
created with ``O_EXCL``) and given the final name only once it is finished, so a failure
(disk full, unwritable directory) never leaves a half-written file under the final name.
A new file takes its name only while the name is still free: when another ``recover`` or
``merge`` wrote it meanwhile, that complete file stays and this result is dropped (exit 1,
one line; this run removes no partial file).  The temporary files of the target left by
killed tools are removed by the next recover writing that target.

Exit status: 0 recovered; 1 unreadable input or write failure (or both ``NAME.mcap`` and
``NAME.recovered.mcap`` exist: give ``--out``; or another process wrote the target
meanwhile); 2 bad arguments, judged before any input is read: a ``--chunk-size`` out of
range, an ``--out`` that exists (other than the input itself), is not a file path (a
directory, a FIFO, a device) or is in a missing or unwritable directory.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import re
import shutil
import sys
import time

from mcap.records import Channel, Chunk, Message, Metadata, Schema

from astrodyn import __version__
from astrodyn.files import output_path_problem, path_argument
from astrodyn.recording.chunked_writer import ChunkedWriter
from astrodyn.recording.outputs import OutputTaken, stale_temporaries, write_atomically
from astrodyn.recording.reader import (
    MAX_CHUNK_BYTES,
    MCAP_MAGIC,
    chunk_records,
    open_recording,
    parse_record,
    read_records,
)
from astrodyn.recording.writer import RecordingError, being_written
from astrodyn.signals import interruptible

__all__ = ["recover", "write_atomically", "main", "finished_name", "find_partials", "partials_of", "nothing_to_recover",
           "stale_work_dirs"]


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
    return sorted(os.path.join(folder, f) for f in names
                  if f.startswith(stem) and _PARTIAL.match(f) and finished_name(os.path.join(folder, f)) == recording)


def nothing_to_recover(target: str) -> str:
    """Why ``recover TARGET`` has nothing to do when TARGET does not exist: a partial
    recording's own name is missing (the others of its recording are named, if any); a
    recording's name has no partial recording either (``NAME.partial*.mcap``)."""
    final = finished_name(target)
    if final is None:
        return f"{target}: no such file, and no partial recording of it ({os.path.splitext(target)[0]}.partial*.mcap)"
    others = [p for p in partials_of(final) if p != target]
    return f"{target}: no such file" + (f"; other partial recordings of {final}: {', '.join(others)}" if others else "")


def stale_work_dirs(folder: str) -> list[str]:
    """Work directories (``.astrodyn-run-*``, ``.astrodyn-serve-*``) in ``folder`` whose
    supervisor is gone: a killed supervisor cannot remove its own (children's logs, the
    run secret); ``recover`` removes them."""
    out = []
    try:
        names = os.listdir(folder)
    except OSError:
        return out
    for name in names:
        if not (name.startswith(".astrodyn-run-") or name.startswith(".astrodyn-serve-")):
            continue
        path = os.path.join(folder, name)
        try:
            with open(os.path.join(path, "supervisor.pid")) as f:
                pid = int(f.read().strip())
            os.kill(pid, 0)
            continue  # its supervisor still runs
        except ProcessLookupError:
            pass
        except (OSError, ValueError):  # no readable pid file: a start-up under way (the pid is written just
            try:                       # after the directory is made), or damaged: only an old one is stale
                if time.time() - os.stat(path).st_mtime < STARTING_WORK_DIR_S:
                    continue
            except OSError:
                continue  # (removed meanwhile)
        out.append(path)
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


def main(argv: list[str] | None = None) -> int:
    return interruptible("astrodyn recover", lambda: _main(argv))


def _main(argv: list[str] | None) -> int:
    ap = argparse.ArgumentParser(prog="astrodyn recover",
                                 description="Rewrite a crashed writer's MCAP file with a proper summary and index.")
    ap.add_argument("file", type=path_argument, help="MCAP file (typically cut by a killed logger): a NAME.partial.mcap left by a killed "
                    "run, the --out path of that run or serve (the partial files of its series are found: "
                    "NAME.partial.mcap, NAME-000k.partial.mcap), or a directory (every partial file in it); a "
                    "complete file is left as it is unless --out is given")
    ap.add_argument("--out", default=None, type=path_argument, help="write the recovered file here (default: NAME.mcap for "
                    "NAME.partial.mcap when no NAME.mcap exists, NAME.recovered.mcap when it does; other files "
                    "are rewritten in place)")
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
    if args.out is not None and len(sources) > 1:
        print(f"astrodyn recover: --out: {len(sources)} partial files found ({', '.join(sources)}); recover them one "
              f"at a time to choose each --out", file=sys.stderr)
        return 2
    if args.out is not None and sources and os.path.lexists(args.out) and not _same_file(sources[0], args.out):
        print(f"astrodyn recover: {sources[0]}: --out {args.out} exists already; recover writes a new file (nothing "
              f"is overwritten; only the input itself is rewritten in place)", file=sys.stderr)
        return 2
    status = 0
    for src in sources:
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
    for work in stale_work_dirs(folder):
        shutil.rmtree(work, ignore_errors=True)
        print(json.dumps({"removed_work_directory": work}), flush=True)
    for tmp in stale_temporaries(folder):  # what a killed merge or recover left
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
            print(json.dumps({"removed_temporary_file": tmp}), flush=True)
    return status


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
