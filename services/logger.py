"""Logger process: record one scenario from the Zenoh bus into an MCAP file.

    python services/logger.py --scenario demo --out demo.mcap --epoch-ns 1774008000000000000 \
        --connect tcp/127.0.0.1:7447 --expect orbit --expect attitude --config configs/demo.toml

Prints a one-line JSON summary on stdout when it finishes (end of run, ``stop`` control
verb, SIGTERM or Ctrl-C).  Exit status: 0 file finished, 1 recording or bus error,
2 bad arguments.  Behaviour and the end-of-run protocol: astrodyn.recording.logger.
"""

from __future__ import annotations

import argparse
import json
import os
import sys

from astrodyn import bus
from astrodyn.recording.logger import Logger
from astrodyn.recording.writer import McapRecorder, RecordingError


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="services/logger.py", description=__doc__.split("\n\n")[0])
    p.add_argument("--scenario", required=True, help="scenario name (the <scenario> in astrodyn/<scenario>/**)")
    p.add_argument("--out", required=True, help="MCAP file to write")
    p.add_argument("--epoch-ns", type=int, required=True, help="scenario epoch as integer ns since the Unix epoch")
    p.add_argument("--config", help="scenario config file; its text is stored in the 'scenario' metadata record")
    p.add_argument("--metadata", help="JSON file with extra 'scenario' metadata (an object)")
    p.add_argument("--expect", action="append", default=[], metavar="PROCESS",
                   help="process whose end-of-run event ends the recording (repeatable)")
    p.add_argument("--chunk-size", type=int, default=1 << 20, help="uncompressed bytes per zstd chunk")
    p.add_argument("--flush-interval", type=float, default=1.0, help="max seconds between flushes (crash-loss bound)")
    p.add_argument("--queue", type=int, default=256, help="bounded receive queue per subscription (samples; a full queue blocks the publishers, so memory stays bounded and nothing is lost)")
    p.add_argument("--no-control", action="store_true",
                   help="do not answer the stop verb (a supervisor such as `astrodyn serve` ends the run)")
    p.add_argument("--roll-size", type=int, default=None, help="start a new file after this many bytes")
    p.add_argument("--roll-interval", type=float, default=None, help="start a new file after this many wall seconds")
    p.add_argument("--max-seconds", type=float, default=None, help="stop after this many wall seconds")
    p.add_argument("--prefill", default=None, metavar="MCAP",
                   help="first copy the state messages with seq < --prefill-steps from this recording (run --resume)")
    p.add_argument("--prefill-steps", type=int, default=0, help="steps (seq 0 .. N-1) to copy from --prefill")
    bus.add_bus_arguments(p)
    return p.parse_args(argv)


def scenario_metadata(args: argparse.Namespace) -> dict:
    meta: dict = {"name": args.scenario}
    if args.metadata:
        with open(args.metadata, encoding="utf-8") as f:
            extra = json.load(f)
        if not isinstance(extra, dict):
            raise ValueError(f"--metadata {args.metadata}: expected a JSON object, got {type(extra).__name__}")
        meta.update(extra)
    if args.config:
        with open(args.config, encoding="utf-8") as f:
            meta["config"] = f.read()
        meta["config_path"] = args.config
    return meta


def prefill(recorder: McapRecorder, path: str, scenario: str, steps: int) -> int:
    """Copy the state messages (orbit, attitude, crosscheck) with ``seq < steps`` of
    ``scenario`` from the recording ``path`` into ``recorder``, payloads unchanged; this
    also seeds the seq accounting, so the continuation counts no gap.  Returns the number
    of messages copied.  Events of the old run are not copied (the new processes number
    their own); the "resumed_from" metadata record says where the copy came from."""
    from astrodyn import messages
    from astrodyn.recording.stream import open_stream

    n = 0
    with open_stream(path) as stream:
        for m in stream.messages(f"{messages.PREFIX}/{scenario}/*"):
            try:
                kind = messages.kind_of_key(m.topic)
            except messages.MessageError:
                continue
            if kind not in ("orbit", "attitude", "crosscheck"):
                continue
            try:
                msg = messages.decode(m.data, kind)
            except messages.MessageError:
                continue  # load() reports these; they are not states to continue from
            if msg["seq"] < steps:
                recorder.write_encoded(m.topic, m.data, msg["t"], msg["seq"], m.publish_time)
                n += 1
    recorder.add_metadata("resumed_from", {"path": os.path.abspath(path), "steps": str(steps), "messages": str(n)})
    return n


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        meta = scenario_metadata(args)
    except (OSError, ValueError) as exc:
        print(f"logger: {exc}", file=sys.stderr)
        return 2
    try:
        with bus.session_from_args(args) as session:
            recorder = McapRecorder(args.out, meta, epoch_ns=args.epoch_ns,
                                    chunk_size=args.chunk_size, flush_interval_s=args.flush_interval,
                                    roll_size=args.roll_size, roll_interval_s=args.roll_interval)
            copied = prefill(recorder, args.prefill, args.scenario, args.prefill_steps) if args.prefill else 0
            logger = Logger(session, args.scenario, recorder, expect=args.expect, queue_capacity=args.queue,
                            control=not args.no_control)
            summary = logger.run(max_seconds=args.max_seconds)
            if args.prefill:
                summary["prefilled"] = copied
    except (RecordingError, bus.BusError) as exc:
        print(f"logger: {exc}", file=sys.stderr)
        return 1
    print(json.dumps(summary, separators=(",", ":")), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
