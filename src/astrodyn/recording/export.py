"""``astrodyn export FILE.mcap --format csv|parquet|oem|aem|foxglove --out DIR``.

What each format writes (one file per channel or body, named after the body):

``csv``      ``<body>.<kind>.csv`` per astrodyn channel (``events.csv`` for ``@event``,
             other topics with ``/`` -> ``.``): columns ``t`` (s since the scenario
             epoch), ``seq``, ``log_time_ns``, then the message fields; vectors are split
             into ``r_x r_y r_z`` (3-vectors) and ``q_0 .. q_3`` (``q`` scalar first, as in
             the messages).  Floats are written with ``repr`` (shortest round-trip form),
             so reading the CSV back gives the recorded float64 values exactly.  SI units.
``parquet``  the same columns, one ``.parquet`` file per channel (needs the optional
             ``pyarrow``: ``pip install 'astrodyn[parquet]'``).
``oem``      ``<body>.oem``: a CCSDS Orbit Ephemeris Message, KVN, version 3.0
             (CCSDS 502.0-B-3): header, one segment per body, data lines
             ``epoch X Y Z X_DOT Y_DOT Z_DOT`` in km and km/s.  ``REF_FRAME`` is the
             message's ``frame`` (e.g. GCRF), ``CENTER_NAME`` the scenario's central body.
``aem``      ``<body>.aem``: a CCSDS Attitude Ephemeris Message, KVN, version 2.0
             (CCSDS 504.0-B-2), ``ATTITUDE_TYPE = QUATERNION``.  Conventions, also
             written as COMMENT lines in the file:

             * ``REF_FRAME_A`` = the inertial frame of the orbit messages (GCRF when the
               body has no orbit), ``REF_FRAME_B = SC_BODY_1``;
             * the quaternion rotates frame A into frame B: with astrodyn's Euler
               parameters ``q = (e0, e1, e2, e3)`` and ``v_B = C(q) v_A`` (Baruh ch. 7),
               ``Q1 Q2 Q3 QC = e1 e2 e3 e0`` -- the scalar QC is the **last** column, as
               504.0-B-2 orders the QUATERNION data line.  No sign change: Baruh's C(q)
               and the A-to-B quaternion of 504.0-B-2 are the same rotation.
``foxglove`` ``<file>.foxglove.mcap``: every recorded channel copied unchanged, plus a
             ``foxglove.FrameTransform`` JSON channel per body on ``foxglove/<body>/tf``
             (parent frame = the orbit frame, e.g. ``GCRF``, child = the body name).
             Translation in **km** (Foxglove's 3D panel works in float32 "metres": an
             orbit in metres loses the sub-metre detail and the camera's far plane;
             read 1 grid unit as 1 km); rotation ``(x, y, z, w) = (e1, e2, e3, e0)``,
             which as Foxglove's active child-to-parent rotation is ``C(q).T``
             (:func:`astrodyn.rotation.quat_to_scalar_last`).

Epochs of OEM/AEM: ``TIME_SYSTEM`` is the scale of the scenario epoch (UTC, TAI, TT,
TDB, ...), and each data line's epoch is ``epoch + t`` computed in that scale with
astropy (leap seconds included for UTC), written in calendar form
``YYYY-MM-DDThh:mm:ss.ffffff`` (microseconds).  A file without scenario metadata uses its
``log_time`` (POSIX ns) as UTC.  CCSDS also allows day-of-year dates
(``2026-079T12:00:00``), which astropy's ``isot`` parser rejects:
:func:`parse_ccsds_epoch` converts them.
"""

from __future__ import annotations

import argparse
import csv
import heapq
import json
import os
import re
import sys
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from astrodyn import __version__, messages
from astrodyn.recording.reader import Run, Track, load
from astrodyn.recording.writer import McapRecorder, RecordingError
from astrodyn.rotation import quat_to_scalar_last

__all__ = [
    "FORMATS", "ExportError", "export", "write_csv", "write_parquet", "write_oem", "write_aem",
    "write_foxglove", "ccsds_epochs", "parse_ccsds_epoch", "FRAME_TRANSFORM_SCHEMA", "main",
]

FORMATS = ("csv", "parquet", "oem", "aem", "foxglove")
_CCSDS_SCALES = {"utc": "UTC", "tai": "TAI", "tt": "TT", "tdb": "TDB", "tcb": "TCB", "tcg": "TCG", "ut1": "UT1"}
_XYZ = ("x", "y", "z")

#: foxglove.FrameTransform, JSON Schema as published in foxglove-sdk schemas/jsonschema.
FRAME_TRANSFORM_SCHEMA = {
    "title": "foxglove.FrameTransform",
    "description": "A transform between two reference frames in 3D space",
    "type": "object",
    "properties": {
        "timestamp": {"type": "object", "title": "time", "properties": {
            "sec": {"type": "integer", "minimum": 0},
            "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999}}},
        "parent_frame_id": {"type": "string"},
        "child_frame_id": {"type": "string"},
        "translation": {"title": "foxglove.Vector3", "type": "object", "properties": {
            "x": {"type": "number"}, "y": {"type": "number"}, "z": {"type": "number"}},
            "required": ["x", "y", "z"]},
        "rotation": {"title": "foxglove.Quaternion", "type": "object", "properties": {
            "x": {"type": "number"}, "y": {"type": "number"}, "z": {"type": "number"}, "w": {"type": "number"}},
            "required": ["x", "y", "z", "w"]},
    },
    "required": ["timestamp", "parent_frame_id", "child_frame_id", "translation", "rotation"],
}


class ExportError(RuntimeError):
    """An export cannot be done (missing optional package, nothing to export, bad option)."""


# ------------------------------------------------------------------------------ tables


def channel_file_stem(topic: str) -> str:
    """``astrodyn/s/sat1/orbit`` -> ``sat1.orbit``; ``astrodyn/s/@event`` -> ``events``."""
    try:
        _, body, kind = messages.parse_key(topic)
        if body.startswith("@"):
            return {"event": "events", "status": "status"}.get(kind, f"{body[1:]}.{kind}")
        return f"{body}.{kind}"
    except messages.MessageError:
        return re.sub(r"[^A-Za-z0-9_.-]+", ".", topic).strip(".") or "channel"


def table(track: Track) -> dict[str, np.ndarray]:
    """Columns of one channel: t, seq, log_time_ns, then fields (vectors split, see module doc)."""
    cols: dict[str, np.ndarray] = {}
    if "t" in track.fields:
        cols["t"] = track.fields["t"]
    cols["seq"] = track.seq
    cols["log_time_ns"] = track.log_time
    for name, a in track.fields.items():
        if name == "t":
            continue
        if a.ndim == 2:
            names = [f"{name}_{c}" for c in _XYZ] if a.shape[1] == 3 else [f"{name}_{i}" for i in range(a.shape[1])]
            for i, col in enumerate(names):
                cols[col] = a[:, i]
        else:
            cols[name] = a
    if track.records is not None:
        cols["json"] = np.array([json.dumps(r) if not isinstance(r, bytes) else r.hex() for r in track.records], dtype=object)
    return cols


def _cell(x) -> str:
    if isinstance(x, (float, np.floating)):
        return repr(float(x))
    if x is None:
        return ""
    return str(x)


def write_csv(run: Run, out: Path) -> list[Path]:
    """One CSV per channel (see the module docstring); returns the files written."""
    written = []
    for topic, track in run.channels.items():
        cols = table(track)
        path = out / f"{channel_file_stem(topic)}.csv"
        with open(path, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(cols)
            for row in zip(*cols.values()):
                w.writerow([_cell(x) for x in row])
        written.append(path)
    return written


def write_parquet(run: Run, out: Path) -> list[Path]:
    """One Parquet file per channel (needs pyarrow)."""
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        raise ExportError("--format parquet needs the optional package pyarrow: pip install 'astrodyn[parquet]'") from None
    written = []
    for topic, track in run.channels.items():
        cols = table(track)
        arrays = {k: pa.array(list(v) if v.dtype == object else v) for k, v in cols.items()}
        path = out / f"{channel_file_stem(topic)}.parquet"
        pq.write_table(pa.table(arrays), path)
        written.append(path)
    return written


# ------------------------------------------------------------------------------ CCSDS


def ccsds_epochs(run: Run, t: np.ndarray, log_time: np.ndarray) -> tuple[list[str], str]:
    """Calendar epochs ``YYYY-MM-DDThh:mm:ss.ffffff`` of ``epoch + t`` and the CCSDS TIME_SYSTEM."""
    from astropy.time import Time, TimeDelta
    from astropy.utils import iers

    iers.conf.auto_download = False
    given = run.scenario.get("epoch")
    scale = run.scenario.get("epoch_scale", "utc").lower()
    if given and scale in _CCSDS_SCALES:
        text = given.split()[0]
        base = Time(text, format="isot" if "T" in text else "iso", scale=scale)
        times = base + TimeDelta(np.asarray(t, dtype=np.float64), format="sec")
        system = _CCSDS_SCALES[scale]
    else:  # no scenario metadata: POSIX log times as UTC
        ns = np.asarray(log_time, dtype=np.int64)
        times = Time(ns // 10**9, (ns % 10**9) * 1e-9, format="unix", scale="utc")
        system = "UTC"
    times.precision = 6
    return [s for s in np.atleast_1d(times.isot)], system


def parse_ccsds_epoch(text: str, scale: str = "utc"):
    """astropy ``Time`` of a CCSDS epoch, calendar (``2026-03-20T12:00:00.5``) or
    day-of-year (``2026-079T12:00:00.5``) form; a trailing ``Z`` is allowed.

    astropy's ``isot`` parser rejects the day-of-year form, so it is rewritten as
    astropy's ``yday`` format (``2026:079:12:00:00.5``).
    """
    from astropy.time import Time

    s = text.strip().rstrip("Z")
    m = re.fullmatch(r"(\d{4})-(\d{3})T(\d{2}:\d{2}:\d{2}(?:\.\d*)?)", s)
    if m:
        return Time(f"{m[1]}:{m[2]}:{m[3]}", format="yday", scale=scale.lower())
    if not re.fullmatch(r"\d{4}-\d{2}-\d{2}T\d{2}:\d{2}:\d{2}(\.\d*)?", s):
        raise ValueError(f"epoch: expected a CCSDS date YYYY-MM-DDThh:mm:ss[.f] or YYYY-DDDThh:mm:ss[.f], got {text!r}")
    return Time(s, format="isot", scale=scale.lower())


def _creation_date() -> str:
    return datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%S")


def _kvn(key: str, value) -> str:
    return f"{key:<20} = {value}"


def _central_name(run: Run) -> str:
    try:
        return str(json.loads(run.scenario["json"])["central_body"]["name"]).upper()
    except (KeyError, ValueError, TypeError):
        return "EARTH"


def _f(x: float) -> str:
    return repr(float(x))


def _message_head(version_key: str, version: str, run: Run, tr: Track, comments: list[str], name: str,
                  meta: list[tuple[str, str]], system: str, epochs: list[str]) -> list[str]:
    """Header and metadata block shared by OEM and AEM (KVN)."""
    return [
        _kvn(version_key, version),
        f"COMMENT astrodyn {__version__} export of {os.path.basename(run.path)}, channel {tr.topic}",
        *(f"COMMENT {c}" for c in comments),
        _kvn("CREATION_DATE", _creation_date()),
        _kvn("ORIGINATOR", "ASTRODYN"),
        "",
        "META_START",
        _kvn("OBJECT_NAME", name),
        _kvn("OBJECT_ID", name),
        _kvn("CENTER_NAME", _central_name(run)),
        *(_kvn(k, v) for k, v in meta),
        _kvn("TIME_SYSTEM", system),
        _kvn("START_TIME", epochs[0]),
        _kvn("STOP_TIME", epochs[-1]),
    ]


def write_oem(run: Run, out: Path) -> list[Path]:
    """``<body>.oem`` per body with an orbit channel (CCSDS 502.0-B-3 KVN)."""
    written = []
    for name, body in run.bodies.items():
        tr = body.orbit
        if tr is None or len(tr) == 0:
            continue
        epochs, system = ccsds_epochs(run, tr.t, tr.log_time)
        frames = sorted(set(tr.frame))
        comment = (f"scenario {run.scenario.get('name', '?')}, epoch {run.scenario.get('epoch', '?')}; "
                   f"models {', '.join(sorted(set(tr.model)))}")
        lines = _message_head("CCSDS_OEM_VERS", "3.0", run, tr, [comment], name,
                              [("REF_FRAME", frames[0] if len(frames) == 1 else "GCRF")], system, epochs) + [
            "META_STOP",
            "",
            "COMMENT position km, velocity km/s",
        ]
        r, v = tr.r / 1e3, tr.v / 1e3
        for k, ep in enumerate(epochs):
            lines.append(" ".join([ep, *map(_f, r[k]), *map(_f, v[k])]))
        path = out / f"{name}.oem"
        path.write_text("\n".join(lines) + "\n")
        written.append(path)
    return written


def write_aem(run: Run, out: Path) -> list[Path]:
    """``<body>.aem`` per body with an attitude channel (CCSDS 504.0-B-2 KVN, QUATERNION)."""
    written = []
    for name, body in run.bodies.items():
        tr = body.attitude
        if tr is None or len(tr) == 0:
            continue
        epochs, system = ccsds_epochs(run, tr.t, tr.log_time)
        frame_a = sorted(set(body.orbit.frame))[0] if body.orbit is not None and len(body.orbit) else "GCRF"
        comments = ["Quaternion rotates REF_FRAME_A into REF_FRAME_B: v_B = C(q) v_A (Baruh ch. 7),",
                    "data columns Q1 Q2 Q3 QC with the scalar QC last (astrodyn q = (QC, Q1, Q2, Q3))."]
        lines = _message_head("CCSDS_AEM_VERS", "2.0", run, tr, comments, name,
                              [("REF_FRAME_A", frame_a), ("REF_FRAME_B", "SC_BODY_1")], system, epochs) + [
            _kvn("ATTITUDE_TYPE", "QUATERNION"),
            "META_STOP",
            "",
            "DATA_START",
        ]
        q = tr.q
        for k, ep in enumerate(epochs):
            lines.append(" ".join([ep, _f(q[k, 1]), _f(q[k, 2]), _f(q[k, 3]), _f(q[k, 0])]))
        lines.append("DATA_STOP")
        path = out / f"{name}.aem"
        path.write_text("\n".join(lines) + "\n")
        written.append(path)
    return written


# ------------------------------------------------------------------------------ Foxglove


def frame_transforms(run: Run) -> list[tuple[int, str, bytes]]:
    """``(log_time, topic, payload)`` of the ``foxglove.FrameTransform`` messages, time-sorted.

    One per body per instant at which the body has an orbit or an attitude state; a
    body's missing half is the origin (attitude-only bodies) or the identity rotation.
    """
    out = []
    for name, body in run.bodies.items():
        orbit, att = body.orbit, body.attitude
        if orbit is None and att is None:
            continue
        parent = sorted(set(orbit.frame))[0] if orbit is not None and len(orbit) else "GCRF"
        times = np.union1d(orbit.log_time if orbit is not None else [], att.log_time if att is not None else []).astype(np.int64)
        pos = np.zeros((times.size, 3))
        rot = np.tile([0.0, 0.0, 0.0, 1.0], (times.size, 1))
        for tr, fill in ((orbit, "r"), (att, "q")):
            if tr is None or len(tr) == 0:
                continue
            ix = np.searchsorted(times, tr.log_time)
            if fill == "r":
                pos[ix] = tr.r / 1e3
            else:
                rot[ix] = quat_to_scalar_last(tr.q)
        # a body with both channels at different instants: hold the last known value
        for tr, arr in ((orbit, pos), (att, rot)):
            if tr is not None and 0 < len(tr) < times.size:
                have = np.isin(times, tr.log_time)
                last = np.maximum.accumulate(np.where(have, np.arange(times.size), 0))
                arr[:] = arr[last]
        topic = f"foxglove/{name}/tf"
        for k, lt in enumerate(times.tolist()):
            msg = {"timestamp": {"sec": lt // 10**9, "nsec": lt % 10**9}, "parent_frame_id": parent, "child_frame_id": name,
                   "translation": dict(zip(_XYZ, map(float, pos[k]))),
                   "rotation": dict(zip(("x", "y", "z", "w"), map(float, rot[k])))}
            out.append((lt, topic, json.dumps(msg, separators=(",", ":")).encode()))
    out.sort(key=lambda m: m[0])
    return out


def write_foxglove(run: Run, out: Path) -> list[Path]:
    """A Foxglove-ready copy of the file: every channel unchanged plus FrameTransform channels."""
    from astrodyn.recording.stream import open_stream

    path = out / (Path(run.path).name.removesuffix(".mcap") + ".foxglove.mcap")
    if path.resolve() == Path(run.path).resolve():
        raise ExportError(f"--out: would overwrite the input {run.path}")
    epoch_ns = int(run.metadata.get("recording", {}).get("epoch_unix_ns", run.scenario.get("epoch_unix_ns", 0)))
    tfs = frame_transforms(run)
    with open_stream(run.path) as stream, McapRecorder(path, run.scenario, epoch_ns=epoch_ns) as rec:
        registered: set[str] = set()
        seqs: dict[str, int] = {}
        originals = ((m.log_time, m.topic, m.data, m) for m in stream.messages())
        extras = ((lt, topic, data, None) for lt, topic, data in tfs)
        for lt, topic, data, raw in heapq.merge(originals, extras, key=lambda x: x[0]):
            if topic not in registered:
                if raw is None:
                    rec.add_channel(topic, "foxglove.FrameTransform", FRAME_TRANSFORM_SCHEMA)
                else:
                    ch = next(c for c in stream.channels.values() if c.topic == topic)
                    schema = stream.schemas.get(ch.schema_id)
                    rec.add_channel(topic, schema.name if schema else "", schema.data if schema else b"{}", ch.message_encoding)
                registered.add(topic)
            seq = seqs.get(topic, 0)
            seqs[topic] = seq + 1
            # t from the log time: McapRecorder recomputes epoch_ns + round(t * 1e9), equal to
            # lt while |lt - epoch| < 2**53 ns (104 days); beyond, within a few ns
            rec.write_encoded(topic, data, (lt - epoch_ns) / 1e9, seq, publish_time=raw.publish_time if raw else lt)
    return [path]


# ------------------------------------------------------------------------------ driver

_WRITERS = {"csv": write_csv, "parquet": write_parquet, "oem": write_oem, "aem": write_aem, "foxglove": write_foxglove}


def export(path: str | os.PathLike, fmt: str, out: str | os.PathLike) -> list[Path]:
    """Export ``path`` in format ``fmt`` (one of :data:`FORMATS`) into directory ``out``."""
    if fmt not in _WRITERS:
        raise ExportError(f"format: expected one of {', '.join(FORMATS)}, got {fmt!r}")
    run = load(path)
    if not run.complete:
        print(f"astrodyn export: warning: {run.path}: {run.truncation or 'invalid messages skipped'}; "
              f"exporting the {run.messages} complete, valid messages", file=sys.stderr)
    out = Path(out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ExportError(f"--out: cannot create directory {out}: {exc.strerror or exc}") from None
    files = _WRITERS[fmt](run, out)
    if not files:
        what = {"oem": "orbit", "aem": "attitude"}.get(fmt, "message")
        raise ExportError(f"{run.path}: no {what} channels to export as {fmt}")
    return files


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="astrodyn export", description="Export an MCAP recording to other formats.")
    ap.add_argument("file", help="MCAP file recorded by astrodyn")
    ap.add_argument("--format", required=True, choices=FORMATS, help="csv | parquet | oem | aem | foxglove")
    ap.add_argument("--out", required=True, help="output directory (created if missing)")
    args = ap.parse_args(argv)
    try:
        run_files = export(args.file, args.format, args.out)
    except (RecordingError, ExportError) as exc:
        print(f"astrodyn export: error: {exc}", file=sys.stderr)
        return 1
    for f in run_files:
        print(f)
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
