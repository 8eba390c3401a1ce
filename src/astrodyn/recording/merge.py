"""Merge partial recordings of one run into one file, without duplicates.

Two loggers of one run (a hot standby beside the main one, or the parts a restarted
logger left) each hold some of the run's messages, many of them twice.  :func:`merge`
reads every input with the crash-tolerant stream reader (:func:`astrodyn.recording.
stream.open_stream`: complete files and files cut by a killed writer alike), walks all of
them together in log-time order, and writes each distinct message once, payload and times
unchanged, with the schemas, channels and metadata records of the inputs (the first
input's record wins when two carry the same name) and a ``merged_from`` record naming the
sources.

What counts as the same message: same topic, same log time and same payload bytes (the
loggers record payloads as received, so two copies of one message are identical).  On a
state channel (``<body>/orbit|attitude|crosscheck``) ``seq`` also rises with time: a
message whose ``seq`` is not above the last one written for its topic, with other bytes,
is a *conflict* (two different states claim one seq) -- counted per topic, the first
kept, the other left out of the merged file; ``astrodyn merge`` then ends with exit
status 3 (docs/exports.md).  The step is the payload's ``seq`` (a run has up to 1e10
steps), never MCAP's 32-bit ``sequence`` alone, which the writer stores as ``seq mod
2**32``: a ``sequence`` one to 2**31 - 1 above the last one's (mod 2**32) is that many steps
on, with no payload decoded (the usual case); any other (the same, lower, or a jump of
2**31 or more) is judged by the ``seq`` decoded from the payload.
Inputs of different scenarios are refused (their ``scenario`` records disagree).

Writing uses the ``mcap`` package's own :class:`mcap.writer.Writer` (zstd chunks, full
summary): merging is not a hot path, and a writer this project did not write checks ours.
The file is written as ``.NAME.<pid>-<random>.mcap.merging`` beside ``--out`` and takes
that name only if it is still free once finished (:mod:`astrodyn.recording.outputs`): two
merges (or a merge and a recover) into one ``--out`` at once leave one complete file there,
and the later one ends with exit 1 saying its result was dropped.  An input its writer did
not finish (a live or killed logger's file) is merged up to where it ends, with a warning.
"""

from __future__ import annotations

import heapq
import json
import os
import struct
from dataclasses import dataclass, field
from pathlib import Path

from mcap.writer import CompressionType, Writer

from astrodyn.files import output_path_problem, path_argument
from astrodyn.messages import STATE_KINDS
from astrodyn.recording.outputs import OutputTaken, warn_incomplete_input, write_atomically
from astrodyn.recording.stream import open_stream
from astrodyn.recording.writer import RecordingError
from astrodyn.signals import interruptible

__all__ = ["MergeReport", "merge", "taken_output_problem"]



@dataclass
class MergeReport:
    """What :func:`merge` wrote: messages per topic, duplicates dropped, conflicts kept out,
    and each input's reader report (complete, or where it was cut)."""

    out: str
    messages: int = 0
    duplicates: int = 0
    conflicts: int = 0
    per_topic: dict[str, int] = field(default_factory=dict)
    #: conflicts per topic: states of these channels were left out (two inputs disagree)
    conflicts_per_topic: dict[str, int] = field(default_factory=dict)
    inputs: dict[str, str] = field(default_factory=dict)

    def as_dict(self) -> dict:
        out = {"out": self.out, "messages": self.messages, "duplicates": self.duplicates, "conflicts": self.conflicts,
               "topics": len(self.per_topic), "inputs": self.inputs}
        if self.conflicts_per_topic:
            out["conflicts_per_topic"] = dict(self.conflicts_per_topic)
        return out


_WRAP = 2**32  #: MCAP's ``sequence`` is uint32: the writer stores ``seq mod 2**32``


def _is_state(topic: str) -> bool:
    return topic.rsplit("/", 1)[-1] in STATE_KINDS and "/@" not in topic


def _payload_seq(data: bytes) -> int | None:
    """The ``seq`` of a state payload (a JSON object's non-negative integer ``seq``), or None."""
    try:
        msg = json.loads(data)
    except (ValueError, RecursionError):
        return None
    seq = msg.get("seq") if isinstance(msg, dict) else None
    return seq if isinstance(seq, int) and not isinstance(seq, bool) and seq >= 0 else None


def _step_of(m, last: int | None) -> int | None:
    """The step (``seq``) of the state message ``m`` of a topic whose last written step is
    ``last``: ``last + d`` when MCAP's 32-bit ``sequence`` is ``d`` in 1 .. 2**31 - 1 ahead of
    ``last`` (mod 2**32); else the payload's ``seq`` (None when the payload has none: then
    no seq rule applies to it)."""
    if last is not None:
        d = (m.sequence - last) % _WRAP
        if 0 < d < _WRAP // 2:
            return last + d
    return _payload_seq(m.data)


def taken_output_problem(inputs: list[str | os.PathLike], out: str | os.PathLike) -> str | None:
    """Why ``out`` is no place for a merge: it exists already (a merge writes a new file,
    it never replaces one) or it is one of ``inputs``; None when it is free."""
    out = Path(out)
    if os.path.lexists(out):
        return "exists already; merge writes a new file (nothing is overwritten)"
    if any(Path(p).resolve() == out.resolve() for p in inputs):
        return "is one of the inputs"
    return None


def merge(inputs: list[str | os.PathLike], out: str | os.PathLike, *, chunk_size: int = 1 << 20) -> MergeReport:
    """Merge the recordings ``inputs`` (paths) into ``out`` (a new file; see the module
    docstring).  :class:`RecordingError` for an unreadable input, inputs of different
    scenarios, or an ``out`` that is one of the inputs or exists already;
    :class:`astrodyn.recording.outputs.OutputTaken` (one) when another process wrote
    ``out`` while this merge ran (its file is left as it was, this result dropped)."""
    paths = [Path(p) for p in inputs]
    out = Path(out)
    if len(paths) < 1:
        raise RecordingError("merge: expected at least one input recording")
    if problem := taken_output_problem(paths, out):
        raise RecordingError(f"--out {out}: {problem}")
    streams = [open_stream(p) for p in paths]
    try:
        names = {p: s.metadata.get("scenario", {}).get("name") for p, s in zip(paths, streams)}
        if len(set(names.values()) - {None}) > 1:
            shown = ", ".join(f"{p}: {name}" for p, name in names.items() if name is not None)
            raise RecordingError(f"merge: the inputs record different scenarios ({shown}); expected parts of one run")
        report = MergeReport(str(out))

        def write(f) -> None:
            try:
                write_merged(f)
            except struct.error as exc:  # more channels than MCAP's 65,535 ids
                raise RecordingError(f"--out {out}: cannot write the merged file: {exc}; nothing was written") from None

        def write_merged(f) -> None:
            writer = Writer(f, chunk_size=chunk_size, compression=CompressionType.ZSTD)
            writer.start(profile="", library="astrodyn merge")
            _copy(streams, writer, report)
            seen_meta: set[str] = set()
            for s in streams:
                for name, data in s.metadata.items():
                    if name not in seen_meta:
                        writer.add_metadata(name, {str(k): str(v) for k, v in data.items()})
                        seen_meta.add(name)
            writer.add_metadata("merged_from", {"files": ";".join(str(p) for p in paths),
                                                "duplicates": str(report.duplicates), "conflicts": str(report.conflicts)})
            writer.finish()

        # a temporary file of its own (.NAME.<pid>-<random>.mcap.merging), named --out only while
        # that name is free: a merge never replaces a file, another merge's or recover's included
        try:
            write_atomically(out, write, suffix=".merging", hidden=True, replace=False, cannot=lambda exc: RecordingError(
                f"--out {out}: cannot write the merged file: {exc.strerror or exc}; nothing was written"))
        except OutputTaken:
            raise OutputTaken(f"--out {out}: another process wrote this file while the merge ran; it holds that "
                              f"process's complete output and was left as it was; this merge's result was dropped "
                              f"(merge into a new --out)") from None
        for p, s in zip(paths, streams):
            report.inputs[str(p)] = s.report()
        return report
    finally:
        for s in streams:
            s.close()


def _copy(streams, writer: Writer, report: MergeReport) -> None:
    iters = [s.messages() for s in streams]
    heap = []
    for k, it in enumerate(iters):
        m = next(it, None)
        if m is not None:
            heap.append((m.log_time, k, m))
    heapq.heapify(heap)
    schema_ids: dict[tuple, int] = {}
    channel_ids: dict[str, int] = {}
    last_seq: dict[str, int] = {}
    window_time = None
    window: set[tuple] = set()
    while heap:
        log_time, k, m = heapq.heappop(heap)
        nxt = next(iters[k], None)
        if nxt is not None:
            heapq.heappush(heap, (nxt.log_time, k, nxt))
        if log_time != window_time:
            window_time, window = log_time, set()
        key = (m.topic, m.data)
        if key in window:
            report.duplicates += 1
            continue
        seq = _step_of(m, last_seq.get(m.topic)) if _is_state(m.topic) else None
        if seq is not None and m.topic in last_seq and seq <= last_seq[m.topic]:
            report.conflicts += 1  # same seq again with other bytes (or out of order)
            report.conflicts_per_topic[m.topic] = report.conflicts_per_topic.get(m.topic, 0) + 1
            continue
        window.add(key)
        cid = channel_ids.get(m.topic)
        if cid is None:
            cid = channel_ids[m.topic] = _register(streams[k], writer, m, schema_ids)
        writer.add_message(cid, log_time=m.log_time, data=m.data, publish_time=m.publish_time, sequence=m.sequence)
        if seq is not None:
            last_seq[m.topic] = seq
        report.messages += 1
        report.per_topic[m.topic] = report.per_topic.get(m.topic, 0) + 1


def _register(stream, writer: Writer, m, schema_ids: dict) -> int:
    channel = next((c for c in stream.channels.values() if c.topic == m.topic), None)
    schema = stream.schemas.get(channel.schema_id) if channel is not None else None
    sid = 0
    if schema is not None:
        skey = (schema.name, schema.encoding, schema.data)
        sid = schema_ids.get(skey)
        if sid is None:
            sid = schema_ids[skey] = writer.register_schema(schema.name, schema.encoding, schema.data)
    return writer.register_channel(m.topic, m.message_encoding, sid,
                                   dict(channel.metadata) if channel is not None else {})


def main(argv: list[str] | None = None) -> int:
    return interruptible("astrodyn merge", lambda: _main(argv))


def _main(argv: list[str] | None) -> int:
    import argparse
    import sys

    ap = argparse.ArgumentParser(prog="astrodyn merge",
                                 description="Merge partial recordings of one run (standby loggers, restarted "
                                             "loggers' parts) into one file without duplicates.",
                                 epilog="Exit status: 0 merged; 1 an input cannot be read or the inputs are not of "
                                        "one run, or the file cannot be written (or another process wrote --out meanwhile); 2 a bad flag value or an --out that "
                                        "exists, is an input or is not a file path in a writable directory; 3 merged, "
                                        "but the inputs disagree: states claiming a seq already written, with other "
                                        "bytes (conflicts), were left out; 128 + the signal when interrupted.")
    ap.add_argument("inputs", nargs="+", type=path_argument, help="MCAP recordings of the same run (complete or cut)")
    ap.add_argument("--out", required=True, type=path_argument, help="the merged MCAP file to write (must not exist)")
    args = ap.parse_args(argv)
    # the command line alone, before any input is read: exit 2 (an input that cannot be merged: 1)
    if problem := output_path_problem(args.out) or taken_output_problem(args.inputs, args.out):
        print(f"astrodyn merge: --out {args.out}: {problem}", file=sys.stderr)
        return 2
    try:
        report = merge(args.inputs, args.out)
    except RecordingError as exc:
        print(f"astrodyn merge: {exc}", file=sys.stderr)
        return 1
    for path, state in report.inputs.items():  # a file its writer has not finished (a live or killed logger's)
        if state != "complete":
            warn_incomplete_input("merge", path, state, "merged the complete messages it holds")
    print(json.dumps(report.as_dict()))
    if report.conflicts:  # states were left out: not a silent success
        shown = ", ".join(f"{n} on {t}" for t, n in sorted(report.conflicts_per_topic.items())[:5])
        print(f"astrodyn merge: CONFLICTS: {report.conflicts} states left out ({shown}): the inputs hold different "
              f"states under one seq, the first in log-time order (then input order) was kept; {args.out} holds "
              f"the rest of the merge", file=sys.stderr)
        return 3
    return 0
