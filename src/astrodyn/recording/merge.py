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

Parts of a rolled series (``serve``'s ``NAME.mcap``, ``NAME-0001.mcap``, ...: each one's
``recording`` record gives its part number) are merged only when their part numbers leave
none out between the lowest and the highest (:func:`missing_parts`): ``merge d.mcap
d-0001.mcap d-0003.mcap`` is refused naming part 2 (``d-0002.mcap``), since the merged file
would hold no state, command or event of that part's steps and look whole (before, it was
merged with exit 0 and no word).  ``allow_missing_parts`` (``--allow-missing-parts``) merges
them anyway, with a warning naming the missing parts.  A merge that starts at a later part
(``d-0002.mcap d-0003.mcap``) is a merge of consecutive parts, taken; ``run --commands`` and
``--resume`` refuse it naming its first part and the merge from part 0.  The merged file's
``merged_from`` record lists the parts it holds (``parts``: ``"2-3"``, ``"0-1,3"``), and
never copies an input's own ``merged_from`` (a merge of merges lists every part once).

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
from astrodyn.messages import STATE_KINDS, json_field
from astrodyn.recording.outputs import OutputTaken, warn_incomplete_input, write_atomically
from astrodyn.recording.stream import open_stream
from astrodyn.recording.writer import RecordingError, part_path
from astrodyn.signals import interruptible_main

__all__ = ["MergeReport", "merge", "taken_output_problem", "recorded_parts", "missing_parts", "format_parts",
           "parts_named", "series_first_file"]


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
    #: the parts of a rolled series the inputs hold (:func:`format_parts`; "" when none says)
    parts: str = ""
    #: parts between the lowest and the highest that no input holds (merged only when allowed)
    missing_parts: str = ""

    def as_dict(self) -> dict:
        out = {"out": self.out, "messages": self.messages, "duplicates": self.duplicates, "conflicts": self.conflicts,
               "topics": len(self.per_topic), "inputs": self.inputs}
        if self.conflicts_per_topic:
            out["conflicts_per_topic"] = dict(self.conflicts_per_topic)
        if self.parts:
            out["parts"] = self.parts
        if self.missing_parts:
            out["missing_parts"] = self.missing_parts
        return out


#: Most digits of a part number read from a file (a series has at most 10**9 parts).
_PART_DIGITS = 9


def _part_number(text: str) -> int | None:
    text = text.strip()
    return int(text) if text.isascii() and text.isdigit() and len(text) <= _PART_DIGITS else None


def recorded_parts(metadata: dict) -> list[tuple[int, int]]:
    """The parts of its rolled series a recording holds, as ranges ``(first, last)`` of part
    numbers, sorted and joined: a logger's file ``[(k, k)]`` from its ``recording`` record's
    ``part`` (0 for a run's first or only file, k for ``NAME-000k.mcap``); a merge those its
    ``merged_from`` record lists (``parts``, :func:`format_parts`).  ``metadata``: the file's
    metadata records, name -> key/value map.  ``[]`` when the file says nothing readable (not
    a logger's file, a merge made before merges listed parts, a damaged value)."""
    merged = metadata.get("merged_from")
    if merged is not None:
        text = merged.get("parts", "")
        ranges = []
        for item in text.split(",") if text else ():
            first, _, last = item.partition("-")
            a, b = _part_number(first), _part_number(last) if last else _part_number(first)
            if a is None or b is None or b < a:
                return []
            ranges.append((a, b))
        return _joined(ranges)
    k = _part_number(str(metadata.get("recording", {}).get("part", "")))
    return [] if k is None else [(k, k)]


def _joined(ranges) -> list[tuple[int, int]]:
    out: list[tuple[int, int]] = []
    for a, b in sorted(ranges):
        if out and a <= out[-1][1] + 1:
            out[-1] = (out[-1][0], max(out[-1][1], b))
        else:
            out.append((a, b))
    return out


def missing_parts(ranges) -> list[tuple[int, int]]:
    """The ranges ``(first, last)`` of part numbers between the lowest and the highest of
    ``ranges`` (as :func:`recorded_parts` gives them, of any number of files) that none of
    them holds; ``[]`` when they leave none out."""
    joined = _joined(ranges)
    return [(a[1] + 1, b[0] - 1) for a, b in zip(joined, joined[1:])]


def format_parts(ranges) -> str:
    """``"0-1,3"``: part-number ranges as the ``parts`` of a ``merged_from`` record."""
    return ",".join(str(a) if a == b else f"{a}-{b}" for a, b in _joined(ranges))


def parts_named(parts: str) -> str:
    """``part 2`` or ``parts 2-4,6`` for part numbers as :func:`format_parts` writes them."""
    return f"part {parts}" if parts.isdigit() else f"parts {parts}"


def series_first_file(path: str | os.PathLike, part: int | None) -> str | None:
    """The first file of the rolled series whose part ``part`` (its ``recording`` record)
    is ``path``: ``NAME.mcap`` for ``NAME-000k.mcap`` (:func:`astrodyn.recording.writer.part_path`),
    ``path`` itself for part 0; None when the part or the name does not tell it."""
    if part is None:
        return None
    root, ext = os.path.splitext(os.fspath(path))
    tail = f"-{part:04d}" if part else ""
    return root.removesuffix(tail) + (ext or ".mcap") if root.endswith(tail) else None


def _named_missing(missing: list[tuple[int, int]], first_file: str | None) -> str:
    """``part 2 (d-0002.mcap)``, ``parts 2 .. 4 (d-0002.mcap .. d-0004.mcap)``, joined."""
    said = []
    for a, b in missing[:10]:
        files = "" if first_file is None else (
            f" ({Path(part_path(first_file, a)).name[:200]}" + (
                "" if a == b else f" .. {Path(part_path(first_file, b)).name[:200]}") + ")")
        said.append((f"part {a}" if a == b else f"parts {a} .. {b}") + files)
    return ", ".join(said) + (f" and {len(missing) - 10} more ranges" if len(missing) > 10 else "")


_WRAP = 2**32  #: MCAP's ``sequence`` is uint32: the writer stores ``seq mod 2**32``


def _is_state(topic: str) -> bool:
    return topic.rsplit("/", 1)[-1] in STATE_KINDS and "/@" not in topic


def _payload_seq(data: bytes) -> int | None:
    """The ``seq`` of a state payload (a JSON object's non-negative integer ``seq``), or None."""
    seq = json_field(data, "seq")
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


def merge(inputs: list[str | os.PathLike], out: str | os.PathLike, *, chunk_size: int = 1 << 20,
          allow_missing_parts: bool = False) -> MergeReport:
    """Merge the recordings ``inputs`` (paths) into ``out`` (a new file; see the module
    docstring).  :class:`RecordingError` for an unreadable input, inputs of different
    scenarios, parts of a rolled series that leave a part out (unless ``allow_missing_parts``:
    then merged, the report's ``missing_parts`` names them), or an ``out`` that is one of
    the inputs or exists already;
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
        held = {p: recorded_parts(s.metadata) for p, s in zip(paths, streams)}
        parts = [r for ranges in held.values() for r in ranges]
        report.parts = format_parts(parts)
        if missing := missing_parts(parts):
            report.missing_parts = format_parts(missing)
            # a file of a part its `recording` record names (NAME-000k.mcap) tells the series' names
            first_file = next((f for p, ranges in held.items() if len(ranges) == 1 and ranges[0][0] == ranges[0][1]
                               and (f := series_first_file(p, ranges[0][0])) is not None), None)
            if not allow_missing_parts:
                raise RecordingError(
                    f"merge: the inputs are parts {report.parts} of a rolled recording (their `recording` metadata "
                    f"records), without {_named_missing(missing, first_file)}: the merged file would hold none of "
                    f"the states, commands and events of those steps; add the missing part (every part from the "
                    f"first to the last), or give --allow-missing-parts to merge them without it")

        def write(f) -> None:
            try:
                write_merged(f)
            except struct.error as exc:  # more channels than MCAP's 65,535 ids
                raise RecordingError(f"--out {out}: cannot write the merged file: {exc}; nothing was written") from None

        def write_merged(f) -> None:
            writer = Writer(f, chunk_size=chunk_size, compression=CompressionType.ZSTD)
            writer.start(profile="", library="astrodyn merge")
            _copy(streams, writer, report)
            seen_meta: set[str] = {"merged_from"}  # its own, below: an input's lists only that input's parts
            for s in streams:
                for name, data in s.metadata.items():
                    if name not in seen_meta:
                        writer.add_metadata(name, {str(k): str(v) for k, v in data.items()})
                        seen_meta.add(name)
            merged_from = {"files": ";".join(str(p) for p in paths), "duplicates": str(report.duplicates),
                           "conflicts": str(report.conflicts)}
            if report.parts:
                merged_from["parts"] = report.parts
            writer.add_metadata("merged_from", merged_from)
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


@interruptible_main("astrodyn merge")
def main(argv: list[str] | None = None) -> int:
    import argparse
    import sys

    ap = argparse.ArgumentParser(prog="astrodyn merge",
                                 description="Merge partial recordings of one run (standby loggers, restarted "
                                             "loggers' parts) into one file without duplicates.",
                                 epilog="Exit status: 0 merged; 1 an input cannot be read or the inputs are not of "
                                        "one run (parts of a rolled recording that leave a part out, without "
                                        "--allow-missing-parts), or the file cannot be written (or another process wrote --out meanwhile); 2 a bad flag value or an --out that "
                                        "exists, is an input or is not a file path in a writable directory; 3 merged, "
                                        "but the inputs disagree: states claiming a seq already written, with other "
                                        "bytes (conflicts), were left out; 128 + the signal when interrupted.")
    ap.add_argument("inputs", nargs="+", type=path_argument, help="MCAP recordings of the same run (complete or cut)")
    ap.add_argument("--out", required=True, type=path_argument, help="the merged MCAP file to write (must not exist)")
    ap.add_argument("--allow-missing-parts", action="store_true",
                    help="merge parts of a rolled recording (NAME.mcap, NAME-0001.mcap, ...) even when a part between "
                         "the first and the last given is missing (refused by default, naming it: the merged file "
                         "would lack its steps); a warning names the missing parts")
    args = ap.parse_args(argv)
    # the command line alone, before any input is read: exit 2 (an input that cannot be merged: 1)
    if problem := output_path_problem(args.out) or taken_output_problem(args.inputs, args.out):
        print(f"astrodyn merge: --out {args.out}: {problem}", file=sys.stderr)
        return 2
    try:
        report = merge(args.inputs, args.out, allow_missing_parts=args.allow_missing_parts)
    except RecordingError as exc:
        print(f"astrodyn merge: {exc}", file=sys.stderr)
        return 1
    if report.missing_parts:  # (--allow-missing-parts)
        verb = "is" if report.missing_parts.isdigit() else "are"
        print(f"astrodyn merge: warning: {parts_named(report.missing_parts)} {verb} missing from the inputs (parts "
              f"{report.parts} of a rolled recording, --allow-missing-parts): {args.out} holds none of the steps "
              f"recorded there", file=sys.stderr)
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
