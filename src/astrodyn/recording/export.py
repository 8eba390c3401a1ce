"""``astrodyn export FILE.mcap --format csv|parquet|oem|aem|foxglove --out DIR``.

What each format writes (one file per channel or body, named after the body):

``csv``      ``<body>.<kind>.csv`` per astrodyn channel (``events.csv`` for ``@event``,
             other topics with ``/`` -> ``.``): columns ``t`` (s since the scenario
             epoch), ``seq``, ``log_time_ns``, then the message fields (:func:`_groups`):
             fixed-length vectors split into ``r_x r_y r_z`` (3 numbers) or ``q_0 .. q_3``
             (other lengths; ``q`` scalar first, as in the messages); one number per wheel
             or gyroscope into ``wheel_torque_0 ..`` (config order, also for 3); one list
             per appendage into ``eta_<k>_<i>`` / ``tip_<k>_x``; lists of names or indices
             and objects as JSON text (``json.loads`` reads it).  A field the message does
             not carry is an empty cell in every column it makes.  Floats are written with
             ``repr`` (shortest round-trip form), so reading the CSV back gives the recorded
             float64 values exactly.  SI units.  The file opens with ``# key: value``
             lines: epoch, time scale, frame, quaternion order, empty cells, JSON columns
             and every column's unit (:func:`channel_header`).  docs/exports.md lists every
             channel's columns.
``parquet``  the same columns, one ``.parquet`` file per channel (needs the optional
             ``pyarrow``: ``pip install 'astrodyn[parquet]'``), an absent field null; the
             header entries are the file's key-value metadata (``astrodyn.epoch``, ...),
             each column's unit its field metadata ``unit``.
``oem``      ``<body>.oem``: a CCSDS Orbit Ephemeris Message, KVN, version 3.0
             (CCSDS 502.0-B-3): header, one segment per body, data lines
             ``epoch X Y Z X_DOT Y_DOT Z_DOT`` in km and km/s.  ``REF_FRAME`` is the
             message's ``frame`` (e.g. GCRF), ``CENTER_NAME`` the scenario's central body.
``aem``      ``<body>.aem``: a CCSDS Attitude Ephemeris Message, KVN, version 2.0
             (CCSDS 504.0-B-2).  ``ATTITUDE_TYPE = QUATERNION/ANGVEL`` with
             ``ANGVEL_FRAME = SC_BODY_1`` when every attitude message carries finite body
             rates ``w`` (the astrodyn schema requires them), plain ``QUATERNION``
             otherwise (files from other writers, a NaN rate).  Conventions, also written
             as COMMENT lines in the file:

             * ``REF_FRAME_A`` = the inertial frame of the orbit messages (GCRF when the
               body has no orbit), ``REF_FRAME_B = SC_BODY_1``;
             * the quaternion rotates frame A into frame B: with astrodyn's Euler
               parameters ``q = (e0, e1, e2, e3)`` and ``v_B = C(q) v_A`` (Baruh ch. 7),
               ``Q1 Q2 Q3 QC = e1 e2 e3 e0`` -- the scalar QC is the **last** column, as
               504.0-B-2 orders the QUATERNION data line.  No sign change: Baruh's C(q)
               and the A-to-B quaternion of 504.0-B-2 are the same rotation.
             * ``ANGVEL_X ANGVEL_Y ANGVEL_Z`` (504.0-B-2 table 4-4: after ``QC`` on the
               same line) are the angular velocity of frame B relative to frame A, in
               frame-B (body) components, in **deg/s**: ``w * 180/pi`` of the recorded
               ``w`` (rad/s), so ``dC/dt = -[w x] C``.
``aem1``     the same attitude ephemeris as ADM version 1.0 (CCSDS 504.0-B-1) for readers
             that know only version 1: ``ATTITUDE_DIR = A2B``, ``QUATERNION_TYPE = LAST``,
             plain QUATERNION lines (no rates: see :func:`write_aem`).
``foxglove`` ``<file>.foxglove.mcap``: every recorded channel copied unchanged (but the
             ``foxglove/*`` channels of an input that is itself such an export: they
             are made anew), plus a
             ``foxglove.FrameTransform`` JSON channel per body on ``foxglove/<body>/tf``
             (parent frame = the orbit frame, e.g. ``GCRF``, child = the body name).
             Translation in **km** (Foxglove's 3D panel works in float32 "metres": an
             orbit in metres loses the sub-metre detail and the camera's far plane;
             read 1 grid unit as 1 km); rotation ``(x, y, z, w) = (e1, e2, e3, e0)``,
             which as Foxglove's active child-to-parent rotation is ``C(q).T``
             (:func:`astrodyn.rotation.quat_to_scalar_last`).
             And one ``foxglove.SceneUpdate`` JSON channel, ``foxglove/scene``, written
             once at the first log time, entities that never expire (km as well):
             the central body as a sphere of the metadata's equatorial radius at the
             origin of the orbit frame (only when some body has an orbit); per body with
             an orbit its recorded positions as a LINE_STRIP in its colour, at most
             2000 points per body and 200,000 in all, evenly spread over the samples,
             first and last kept (:func:`line_indices`); per body with an attitude
             three arrows along its x, y, z axes (red, green, blue) in its own frame.
             See :func:`scene_updates`.

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
import hashlib
import heapq
import json
import os
import re
import sys
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from astrodyn import __version__, messages
from astrodyn.files import output_path_problem, path_argument
from astrodyn.recording.foxglove_scene import (
    BODY_COLORS,
    FRAME_TRANSFORM_SCHEMA,
    MAX_LINE_POINTS,
    MAX_SCENE_POINTS,
    SCENE_TOPIC,
    SCENE_UPDATE_SCHEMA,
    XYZ,
    axes_entity,
    central_body_entity,
    frame_transform,
    line_indices,
    orbit_line_entity,
    stamp,
)
from astrodyn.recording.outputs import staging_directory, warn_incomplete_input
from astrodyn.recording.reader import Run, Track, load, sequence_issues, sequence_note, time_order
from astrodyn.recording.writer import McapRecorder, RecordingError
from astrodyn.rotation import quat_to_scalar_last
from astrodyn.signals import deferred_interrupts, interruptible_main

__all__ = [
    "FORMATS", "FIELD_UNITS", "INDICATED_UNITS", "channel_file_stems", "column_units", "channel_units", "channel_header", "ExportError", "export", "write_csv", "write_parquet", "write_oem", "write_aem", "write_aem_v1",
    "write_foxglove", "ccsds_epochs", "parse_ccsds_epoch", "FRAME_TRANSFORM_SCHEMA", "SCENE_UPDATE_SCHEMA",
    "SCENE_TOPIC", "FOXGLOVE_TOPICS", "MAX_LINE_POINTS", "MAX_SCENE_POINTS", "scene_updates", "line_indices", "main",
    "rejected_channels",
]

FORMATS = ("csv", "parquet", "oem", "aem", "aem1", "foxglove")
_CCSDS_SCALES = {"utc": "UTC", "tai": "TAI", "tt": "TT", "tdb": "TDB", "tcb": "TCB", "tcg": "TCG", "ut1": "UT1"}
_XYZ = XYZ

#: States (rows) formatted and written at a time by the CSV, OEM and AEM writers: beyond the
#: loaded arrays, an export holds the text of one chunk, whatever the number of states.
_CHUNK_ROWS = 16_384


class ExportError(RuntimeError):
    """An export cannot be done (missing optional package, nothing to export, bad option)."""


def _chunks(start: int, stop: int):
    """``(a, b)`` row ranges of at most :data:`_CHUNK_ROWS` rows covering ``start`` to ``stop``."""
    size = _CHUNK_ROWS
    return ((a, min(stop, a + size)) for a in range(start, stop, size))


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


def channel_file_stems(topics) -> dict[str, str]:
    """``topic -> file stem`` (:func:`channel_file_stem`) made unique and short enough for
    any file system: a stem already taken by an earlier topic gets ``-2``, ``-3``, ... (two
    foreign topics ``a/b`` and ``a.b``, or ``events``, would otherwise write one file and
    lose a channel), one longer than 150 characters is cut and given a hash of its topic."""
    out: dict[str, str] = {}
    taken: set[str] = set()
    for topic in topics:
        stem = channel_file_stem(topic)
        if len(stem) > 150:
            stem = f"{stem[:140]}.{hashlib.sha256(topic.encode('utf-8', 'surrogatepass')).hexdigest()[:8]}"
        unique, n = stem, 1
        while unique.lower() in taken:
            n += 1
            unique = f"{stem}-{n}"
        taken.add(unique.lower())
        out[topic] = unique
    return out


class _Group(NamedTuple):
    """The columns one message field (or the channel's records) makes, and how their cells
    are made (:func:`_group_values`).  ``how``: ``numbers`` (a float column, or a 2-D one,
    one column per array column), ``integers`` (``absent``: the value that marks a field
    the message does not carry, or None), ``lists`` (an object column of lists of numbers,
    flattened by :func:`_flat_lists` with ``widths`` and ``nested``), ``values`` (text as
    it is, any other value as JSON text; ``json``: the field's values are not text, so its
    column holds JSON text), ``records`` (the decoded messages of a channel without a
    schema, as JSON text)."""

    how: str
    names: list[str]
    data: Any
    absent: int | None = None
    widths: tuple[int, ...] = ()
    nested: bool = False
    json: bool = False
    short: bool = False  # lists: some row has no list or a shorter one than ``widths`` (empty cells)


def _definition(track: Track) -> dict | None:
    """The JSON Schema of the astrodyn message type the channel's messages were decoded
    and checked with (:data:`astrodyn.messages.MESSAGE_TYPES`), or None for a foreign channel."""
    if track.kind is None:
        return None
    try:
        found = messages.schema_for_key(track.topic)
    except messages.MessageError:
        return None
    return found[1] if found else None


def _suffixes(width: int) -> list[str]:
    """Column suffixes of a fixed-length vector: ``x y z`` for 3 numbers, ``0 .. n-1`` otherwise."""
    return list(_XYZ) if width == 3 else [str(i) for i in range(width)]


def _number_lists(prop: dict) -> tuple[bool, bool] | None:
    """``(nested, fixed)`` when a field's definition is a list of numbers of varying length
    (one per wheel or gyro: not nested) or a list of lists of numbers (one per appendage:
    nested; ``fixed`` when each inner list has one length, as the tip's 3-vector); else None."""
    items = prop.get("items") if prop.get("type") == "array" else None
    if not isinstance(items, dict):
        return None
    if items.get("type") == "number":
        return False, False
    inner = items.get("items")
    if items.get("type") == "array" and isinstance(inner, dict) and inner.get("type") == "number":
        return True, items.get("minItems") is not None and items.get("minItems") == items.get("maxItems")
    return None


def _list_widths(column: np.ndarray, nested: bool) -> tuple[tuple[int, ...], bool]:
    """The longest list of an object column (``nested``: per position of the outer list,
    its longest inner list; messages without the field, None, count nothing), and whether
    some row has no list or a shorter one (its cells of the missing elements are empty)."""
    shapes = set()
    for x in column:
        if not isinstance(x, list):
            shapes.add(None)
        else:
            shapes.add(tuple(len(inner) if isinstance(inner, list) else 0 for inner in x) if nested else (len(x),))
    lists = [shape for shape in shapes if shape is not None]
    widths = tuple(max((shape[k] for shape in lists if k < len(shape)), default=0)
                   for k in range(max(map(len, lists), default=0)))
    return widths, bool(shapes - {widths})


def _groups(track: Track) -> list[_Group]:
    """The column groups of one channel: ``t`` (s since the scenario epoch), ``seq``,
    ``log_time_ns``, then each field in the order of the message definition (see the
    module docstring and docs/exports.md, "CSV and Parquet columns")."""
    definition = _definition(track)
    properties = definition.get("properties", {}) if definition else {}
    required = set(definition.get("required", ())) if definition else set()
    groups = []
    if "t" in track.fields:
        groups.append(_Group("numbers", ["t"], track.fields["t"]))
    groups += [_Group("integers", ["seq"], track.seq), _Group("integers", ["log_time_ns"], track.log_time)]
    for name, a in track.fields.items():
        if name == "t":
            continue
        prop = properties.get(name) or {}
        if a.dtype.kind == "f":
            names = [name] if a.ndim == 1 else [f"{name}_{c}" for c in _suffixes(a.shape[1])]
            groups.append(_Group("numbers", names, a))
        elif a.dtype.kind in "iub":
            # an astrodyn field the message may leave out is read as -1, never one of its values (>= 0)
            absent = -1 if definition and name not in required and prop.get("minimum", -1) >= 0 else None
            groups.append(_Group("integers", [name], a, absent))
        elif (layout := _number_lists(prop)) is not None:
            nested, fixed = layout
            widths, short = _list_widths(a, nested)
            if nested:  # per appendage a list: name_<k>_<i>, or name_<k>_x .. _z for its fixed 3-vector
                names = [f"{name}_{k}_{c}" for k, n in enumerate(widths)
                         for c in (_suffixes(n) if fixed else map(str, range(n)))]
            else:  # one number per wheel, gyro, ...: indexed, even when there are 3
                names = [f"{name}_{i}" for i in range(widths[0] if widths else 0)]
            groups.append(_Group("lists", names, a, widths=widths, nested=nested, short=short))
        else:  # text; JSON text of a list of names or wheel indices, an object, a foreign field's values
            json_text = prop.get("type") in ("array", "object") if definition else \
                any(x is not None and not isinstance(x, str) for x in a)
            groups.append(_Group("values", [name], a, json=json_text))
    if track.records is not None:
        groups.append(_Group("records", ["json"], track.records, json=True))
    return groups


def _flat_lists(part: np.ndarray, widths: tuple[int, ...], nested: bool) -> np.ndarray:
    """The lists of an object column's rows as a float64 array of ``sum(widths)`` columns:
    element ``i`` of a row's list (``nested``: element ``i`` of its list ``k``) in column
    ``i`` (``offset(k) + i``); NaN where a row has no such element or no list."""
    total = int(sum(widths))
    rows = len(part)
    try:  # every row a list of the full widths: one conversion
        flat = np.array(list(part), dtype=np.float64)
        if flat.shape[:2] == (rows, len(widths) if nested else total) and flat.size == rows * total:
            return flat.reshape(rows, total)
    except (TypeError, ValueError):  # a row without the field, lists of other lengths
        pass
    out = np.full((rows, total), np.nan)
    offsets = np.concatenate([[0], np.cumsum(widths)]).astype(int).tolist()
    for r, x in enumerate(part):
        if not isinstance(x, list):
            continue
        if not nested:
            out[r, :len(x)] = x
            continue
        for k, inner in enumerate(x):
            if isinstance(inner, list):
                out[r, offsets[k]:offsets[k] + len(inner)] = inner
    return out


def _json_default(x: Any) -> Any:
    if hasattr(x, "tolist"):  # a numpy scalar or array in a run built by hand
        return x.tolist()
    raise TypeError(f"{type(x).__name__} is not JSON")


def _value_text(x: Any) -> str | None:
    """The text of one ``values`` cell: None (absent) stays None, text is itself, any other
    value (a list of names, of wheel indices, an object) its JSON text."""
    if x is None or isinstance(x, str):
        return x
    return json.dumps(x, default=_json_default)


def _group_values(group: _Group, a: int, b: int) -> list[tuple[Any, np.ndarray | None]]:
    """``(values, absent)`` of each column of ``group`` for the rows ``a`` to ``b``: values a
    float64 array, an int64 / uint64 array, or a list of str and None (None: absent); absent a
    bool array marking the cells of a field the message does not carry (NaN of a number, the
    group's ``absent`` integer), or None when there is none."""
    part = group.data[a:b]
    if group.how == "records":
        return [([r.hex() if isinstance(r, bytes) else json.dumps(r, default=_json_default) for r in part], None)]
    if group.how == "values":
        return [([_value_text(x) for x in part], None)]
    if group.how == "integers":
        return [(part, None if group.absent is None else part == group.absent)]
    if group.how == "lists":
        part = _flat_lists(part, group.widths, group.nested)
    columns = [part] if part.ndim == 1 else [part[:, i] for i in range(part.shape[1])]
    return [(c, np.isnan(c) if np.isnan(c).any() else None) for c in columns]


def _columns(track: Track) -> tuple[list[str], list[_Group], list[int]]:
    """The column names of a channel, its groups (:func:`_groups`) and which of the columns
    are kept: a name made twice (a foreign field ``seq``) keeps its first place and its last
    column."""
    groups = _groups(track)
    names = [name for g in groups for name in g.names]
    kept: dict[str, int] = {}
    for i, name in enumerate(names):
        kept[name] = i
    return list(kept), groups, list(kept.values())


def _column_values(groups: list[_Group], kept: list[int], a: int, b: int) -> list[tuple[Any, np.ndarray | None]]:
    """:func:`_group_values` of every kept column (:func:`_columns`) for the rows ``a`` to ``b``."""
    columns = [c for g in groups for c in _group_values(g, a, b)]
    return columns if len(kept) == len(columns) else [columns[i] for i in kept]


#: Unit of each message field as exported (SI; "1" for dimensionless, "" for text), keyed
#: by the field's name in its message definition (:data:`astrodyn.messages.MESSAGE_TYPES`);
#: a field missing here is shown as ``?``, the mark of a foreign channel's field.
FIELD_UNITS = {
    "t": "s", "seq": "1", "log_time_ns": "ns", "r": "m", "v": "m/s", "mu": "m^3/s^2", "q": "1", "w": "rad/s",
    "dr": "m", "dv": "m/s", "dr_norm": "m", "dv_norm": "m/s", "model": "", "frame": "", "reference": "",
    # events (astrodyn.Event): which process, what happened, why
    "process": "", "kind": "", "detail": "", "json": "",
    # the closed loop's (docs/control.md): commands, actuator states, sensor samples
    "torque": "N m", "wheel_torque": "N m", "wheel_speed": "rad/s", "clipped": "", "thrust": "N", "mass": "kg",
    "dv_total": "m/s", "dv_t": "s", "applied": "", "sender": "", "speeds": "rad/s", "step": "1", "commands": "1",
    # a flexible spacecraft's appendages: modal coordinates, their rates, tip displacements
    "eta": "m", "eta_dot": "m/s", "tip": "m",
    # a rolling disk (astrodyn.RollingState): contact point, centre, angles, generalized speeds
    "contact": "m", "center": "m", "heading": "rad", "lean": "rad", "spin_angle": "rad", "u": "rad/s",
    # single-axis gyroscopes (astrodyn.GimbalState); "indicated" is rad/s or rad by gyro type
    # (:data:`INDICATED_UNITS`, per column by :func:`channel_units`)
    "angle": "rad", "angle_rate": "rad/s",
    # a serve's status (astrodyn.Status)
    "state": "", "real_time_factor": "1", "rate": "Hz", "messages": "1", "processes": "",
}

#: Unit of a single-axis gyroscope's indication by its config ``type``: a rate gyro
#: indicates the input rate, a rate-integrating gyro the input angle.
INDICATED_UNITS = {"rate": "rad/s", "rate_integrating": "rad"}


def column_units(columns) -> dict[str, str]:
    """Unit of each exported column (``r_x`` -> ``m``, ``q_0`` -> ``1``); ``?`` for fields
    of foreign channels that astrodyn does not define."""
    out = {}
    for col in columns:
        field = col
        while field not in FIELD_UNITS and "_" in field:  # tip_0_x -> tip_0 -> tip
            field = field.rsplit("_", 1)[0]
        out[col] = FIELD_UNITS.get(field, "?")
    return out


def _gyro_types(run: Run, body: str) -> list:
    """The config ``type`` of each single-axis gyroscope of ``body``, in config order, from
    the scenario metadata (any JSON: [] when it does not say)."""
    try:
        bodies = json.loads(run.scenario["json"])["bodies"]
        config = next(b for b in bodies if isinstance(b, dict) and b.get("name") == body)
        return [g.get("type") if isinstance(g, dict) else None for g in config["gyros"]]
    except (KeyError, ValueError, TypeError, StopIteration, RecursionError):
        return []


def channel_units(run: Run, topic: str, columns) -> dict[str, str]:
    """:func:`column_units` of one channel's columns, with each gyroscope's indication
    ``indicated_<k>`` in the unit of the k-th gyroscope's type (:data:`INDICATED_UNITS`;
    ``?`` when the metadata do not say)."""
    units = column_units(columns)
    track = run.channels[topic]
    if track.kind == "gimbals":
        types = _gyro_types(run, messages.parse_key(topic)[1])
        for col in columns:
            if (m := re.fullmatch(r"indicated_(\d+)", col)) and int(m[1]) < len(types):
                units[col] = INDICATED_UNITS.get(types[int(m[1])], "?")
    return units


def channel_header(run: Run, topic: str, columns) -> dict[str, str]:
    """What a reader of one exported channel needs besides the numbers: the channel, the
    scenario epoch and its time scale (``t`` counts SI seconds from it in that scale), the
    frame of the vectors, the quaternion order, whether cells may be empty, which columns
    hold JSON text, and every column's unit.  Written as the ``# key: value`` lines at the
    top of a CSV and as the Parquet key-value metadata."""
    track = run.channels[topic]
    definition = _definition(track)
    groups = _groups(track)
    head = {
        "astrodyn_export": f"astrodyn {__version__}, file {os.path.basename(run.path)}, channel {topic}",
        "epoch": str(run.scenario.get("epoch", "none (t is absent; log_time_ns is POSIX time, UTC)")),
        "time_scale": str(run.scenario.get("epoch_scale", "utc")).upper(),
        "t": "SI seconds since the epoch, in the epoch's time scale",
        "log_time_ns": "MCAP log time, POSIX ns (epoch + t, leap seconds ignored)",
    }
    # the inertial frame a state's frame field names (a command's frame names the axes of its
    # thrust, per message: its column says it)
    if "frame" in track.fields and track.kind in (None, "orbit"):
        frames = sorted({str(f) for f in track.fields["frame"] if f is not None})
        if frames:
            head["frame"] = ", ".join(frames) + " (inertial, origin at the central body)"
    if "q" in track.fields:
        head["quaternion"] = "q_0 q_1 q_2 q_3 = Euler parameters (e0, e1, e2, e3), scalar FIRST; v_body = C(q) v_inertial"
    if "w" in track.fields:
        head["w"] = "body angular velocity, body-axis components"
    optional = definition is None or set(definition.get("properties", ())) - set(definition.get("required", ()))
    if optional or any(g.short for g in groups):
        head["empty"] = ("an empty cell (Parquet: null) is a field the message does not carry, or an element "
                         "its list does not have" + ("" if definition else " (in a channel astrodyn does not "
                                                                            "define, also a NaN)"))
    json_columns = [name for g in groups if g.json for name in g.names if name in columns]
    if json_columns:
        head["json"] = f"{', '.join(json_columns)}: JSON text (json.loads reads it)"
    head["units"] = ", ".join(f"{c}={u}" for c, u in channel_units(run, topic, columns).items() if u)
    return head


def _cells(values: Any, absent: np.ndarray | None) -> list[str]:
    """The CSV cells of one column of :func:`_column_values`: floats with ``repr`` (the
    shortest text that reads back to the same float64), integers as they are, text as it
    is; a field the message does not carry is an empty cell."""
    if isinstance(values, list):
        return ["" if v is None else v for v in values]
    cells = list(map(repr if values.dtype.kind == "f" else str, values.tolist()))
    if absent is not None:
        cells = ["" if gone else c for c, gone in zip(cells, absent.tolist())]
    return cells


def rejected_channels(run: Run) -> list[str]:
    """The topics of ``run`` whose every message was rejected as invalid (none valid, some
    invalid): nothing of them to export, so the CSV and Parquet exports write no file for
    them (a header without rows would read as a channel recorded empty) and say so."""
    return [topic for topic, track in run.channels.items() if not len(track) and run.invalid_by_channel.get(topic)]


def _exported_channels(run: Run) -> dict[str, Track]:
    """The channels the CSV and Parquet exports write a file for: all but :func:`rejected_channels`."""
    rejected = set(rejected_channels(run))
    return {topic: track for topic, track in run.channels.items() if topic not in rejected}


def write_csv(run: Run, out: Path) -> list[Path]:
    """One CSV per channel (see the module docstring); returns the files written.

    Each file starts with ``# key: value`` comment lines (:func:`channel_header`: epoch,
    time scale, frame, quaternion order, empty cells, JSON columns, units), then the column
    names, then one row per message.  ``pandas.read_csv(path, comment="#")`` reads it; so
    does any CSV reader told to skip lines starting with ``#``.  The columns are those of
    :func:`_columns`, formatted and written :data:`_CHUNK_ROWS` rows at a time.  A channel
    whose every message was rejected gets no file (:func:`rejected_channels`)."""
    written = []
    stems = channel_file_stems(run.channels)
    for topic, track in _exported_channels(run).items():
        names, groups, kept = _columns(track)
        path = out / f"{stems[topic]}.csv"
        with open(path, "w", newline="") as f:
            for key, value in channel_header(run, topic, names).items():
                f.write(f"# {key}: {value}\n")
            w = csv.writer(f)
            w.writerow(names)
            for a, b in _chunks(0, len(track)):
                w.writerows(zip(*(_cells(v, gone) for v, gone in _column_values(groups, kept, a, b))))
        written.append(path)
    return written


def write_parquet(run: Run, out: Path) -> list[Path]:
    """One Parquet file per channel (needs pyarrow), the CSV's columns: floats float64,
    integers int64 / uint64, text and JSON text strings, a field the message does not carry
    null.  The :func:`channel_header` entries are the file's key-value metadata (keys
    prefixed ``astrodyn.``) and each column's unit is its field metadata ``unit``.  A channel
    whose every message was rejected gets no file (:func:`rejected_channels`)."""
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        raise ExportError("--format parquet needs the optional package pyarrow: pip install 'astrodyn[parquet]'") from None
    written = []
    stems = channel_file_stems(run.channels)
    for topic, track in _exported_channels(run).items():
        names, groups, kept = _columns(track)
        units = channel_units(run, topic, names)
        fields, arrays = [], []
        for name, (values, absent) in zip(names, _column_values(groups, kept, 0, len(track))):
            arr = pa.array(values, type=pa.string()) if isinstance(values, list) else pa.array(values, mask=absent)
            fields.append(pa.field(name, arr.type, metadata={"unit": units[name]}))
            arrays.append(arr)
        meta = {f"astrodyn.{k}": v for k, v in channel_header(run, topic, names).items()}
        path = out / f"{stems[topic]}.parquet"
        pq.write_table(pa.Table.from_arrays(arrays, schema=pa.schema(fields, metadata=meta)), path)
        written.append(path)
    return written


# ------------------------------------------------------------------------------ CCSDS


#: A CCSDS calendar epoch as :func:`ccsds_epochs` writes it: four-digit year 0001-9999.
_CCSDS_EPOCH = re.compile(r"(?!0000)\d{4}-\d{2}-\d{2}T\d{2}:\d{2}:\d{2}(\.\d+)?$")


#: Julian dates, in the time's own scale, well inside the years 1000-9999 (1000-01-02T12:00
#: to 9999-12-30T12:00), which astropy writes with the four digits of a CCSDS year (it
#: writes 0999 as ``999``): epochs between them need no check of their text.
_PLAIN_JD = (2086304.0, 5373482.0)


def _epoch_times(run: Run):
    """``(times, time_system)``: ``times(t, log_time)`` is the astropy ``Time`` of
    ``epoch + t`` in the scale of the scenario epoch, or of the POSIX log times as UTC in a
    file without scenario metadata; the same element by element for any slice of the
    states, so epochs can be made a chunk at a time (:func:`ccsds_epochs`)."""
    from astropy.time import Time, TimeDelta
    from astropy.utils import iers

    iers.conf.auto_download = False
    given = run.scenario.get("epoch")
    scale = run.scenario.get("epoch_scale", "utc").lower()
    if given and scale in _CCSDS_SCALES:
        text = given.split()[0]
        try:
            base = Time(text, format="isot" if "T" in text else "iso", scale=scale)
        except ValueError:
            raise ExportError(f"{run.path}: scenario metadata epoch {given[:80]!r}: expected an ISO date and time "
                              f"(e.g. 2026-03-20T12:00:00 UTC)") from None
        return (lambda t, log_time: base + TimeDelta(np.asarray(t, dtype=np.float64), format="sec")), _CCSDS_SCALES[scale]

    def posix(t, log_time):  # no scenario metadata: POSIX log times as UTC
        ns = np.asarray(log_time, dtype=np.uint64)  # MCAP's uint64 ns: 1970 to 2554, none wrapped to 1677
        return Time((ns // np.uint64(10**9)).astype(np.float64), (ns % np.uint64(10**9)) * 1e-9, format="unix", scale="utc")

    return posix, "UTC"


def _isot(times) -> list[str]:
    """The calendar epochs ``YYYY-MM-DDThh:mm:ss.ffffff`` of astropy ``times``."""
    times.precision = 6
    return np.atleast_1d(times.isot).tolist()


def ccsds_epochs(run: Run, t: np.ndarray, log_time: np.ndarray) -> tuple[list[str], str]:
    """Calendar epochs ``YYYY-MM-DDThh:mm:ss.ffffff`` of ``epoch + t`` and the CCSDS TIME_SYSTEM."""
    times, system = _epoch_times(run)
    return _isot(times(t, log_time)), system


class _Epochs:
    """The CCSDS epochs of one track's states (:func:`ccsds_epochs`), made when asked, a
    slice at a time: :meth:`at` one, :meth:`of` rows ``a`` to ``b``."""

    def __init__(self, track: Track, times) -> None:
        self.t, self.log_time, self.times = track.t, track.log_time, times

    def of(self, a: int, b: int) -> list[str]:
        return _isot(self.times(self.t[a:b], self.log_time[a:b]))

    def at(self, k: int) -> str:
        return self.of(k, k + 1)[0]


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
    return datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%S")


def _kvn(key: str, value) -> str:
    return f"{key:<20} = {value}"


def _central_body(run: Run) -> dict:
    """The scenario metadata's ``central_body`` table (name, mu, radius m, frame), or {}."""
    try:
        cb = json.loads(run.scenario["json"])["central_body"]
        return cb if isinstance(cb, dict) else {}
    except (KeyError, ValueError, TypeError, RecursionError):  # any text, nested past the parser's depth
        return {}


def _central_name(run: Run) -> str:
    return str(_central_body(run).get("name", "earth")).upper()


def _orbit_frame(body) -> str:
    """The inertial frame of a body's orbit messages (GCRF when it has no orbit)."""
    orbit = body.orbit
    return sorted(set(orbit.frame))[0] if orbit is not None and len(orbit) else "GCRF"


def _message_head(version_key: str, version: str, run: Run, tr: Track, comments: list[str], name: str,
                  meta: list[tuple[str, str]], system: str, start: str, stop: str) -> list[str]:
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
        _kvn("START_TIME", start),
        _kvn("STOP_TIME", stop),
    ]


def _ccsds_tracks(run: Run, kind: str) -> list[tuple[str, object, Track, _Epochs, str]]:
    """``(name, body, track, epochs, time_system)`` for each body whose ``kind`` track
    ("orbit" or "attitude") has samples; ``epochs`` (:class:`_Epochs`), ``time_system``:
    :func:`ccsds_epochs`.  Every track is checked before this returns, so a refused export
    has written nothing: epochs a CCSDS file can hold (:func:`_check_epochs`) and times that
    increase with seq."""
    tracks = []
    for name, body in run.bodies.items():
        tr = getattr(body, kind)
        if tr is None or len(tr) == 0:
            continue
        times, system = _epoch_times(run)
        epochs = _Epochs(tr, times)
        _check_epochs(run, tr, epochs)
        _check_time_order(run, tr)
        tracks.append((name, body, tr, epochs, system))
    return tracks


def _check_time_order(run: Run, tr: Track) -> None:
    """ExportError unless ``tr`` holds one state per seq and its ``t`` increases with seq
    (the recording's contract, checked by :func:`astrodyn.recording.reader.time_order`, the
    check every reader makes): a CCSDS ephemeris has one data line per epoch, in time order.
    A duplicated seq is named as such, with the ``merge`` that keeps the first of each."""
    order = time_order(tr)
    if order["first_duplicate"] is not None:
        n = order["duplicates"]
        raise ExportError(f"{run.path}: {tr.topic}: seq {order['first_duplicate']}: a duplicated sequence number (a "
                          f"message repeating a seq already recorded; {n} in the channel): expected one state per seq "
                          f"(CCSDS data lines are one per epoch); `astrodyn merge {run.path} --out NEW.mcap` keeps the "
                          f"first of each")
    if order["first_not_increasing"] is not None:
        seq, t, before, t_before = order["first_not_increasing"]
        n = order["not_increasing"]
        raise ExportError(f"{run.path}: {tr.topic}: seq {seq}: t = {t:g} s after t = {t_before:g} s (seq {before}): "
                          f"expected times that increase with seq (CCSDS data lines are in time order)"
                          + (f"; {n} such steps in the channel" if n > 1 else ""))


def _check_epochs(run: Run, tr: Track, epochs: _Epochs) -> None:
    """ExportError unless every state's epoch is a date of a CCSDS file (a four-digit year),
    checked a chunk at a time without keeping any text: a chunk whose Julian dates lie in
    :data:`_PLAIN_JD` passes as it is, any other has its epochs made and matched.  A time
    no calendar date can show fails before an ill-written one anywhere in the track."""
    bad = None  # (k, epoch) of the first epoch that is no CCSDS epoch
    for a, b in _chunks(0, len(tr)):
        try:
            times = epochs.times(epochs.t[a:b], epochs.log_time[a:b])
            jd = times.jd1 + times.jd2
            if np.all((jd > _PLAIN_JD[0]) & (jd < _PLAIN_JD[1])):
                continue
            text = _isot(times)
        except ValueError as exc:  # erfa's "unacceptable date": a hostile t (1e300 s) beyond any calendar
            raise ExportError(f"{run.path}: {tr.topic}: t from {float(np.min(tr.t)):g} to {float(np.max(tr.t)):g} s: "
                              f"expected times a calendar date can show ({type(exc).__name__}: {exc})") from None
        if bad is None:  # CCSDS ASCII time: a four-digit year, 0001 to 9999
            bad = next(((a + k, e) for k, e in enumerate(text) if not _CCSDS_EPOCH.match(e)), None)
    if bad is not None:
        k, epoch = bad
        raise ExportError(f"{run.path}: {tr.topic}: seq {int(tr.seq[k])}: t = {float(tr.t[k]):g} s is "
                          f"{epoch}: expected a date of the years 0001-9999 (a CCSDS epoch)")


def _write_lines(f, lines: list[str]) -> None:
    """Write ``lines`` to the open text file ``f``, each ended by a newline (a KVN message)."""
    if lines:
        f.write("\n".join(lines) + "\n")


def _impulse_cuts(tr: Track, impulses: dict[float, float]) -> list[int]:
    """The rows that start a new OEM segment: each ``k + 1`` whose ``t[k]`` is the step of
    an impulsive burn (:func:`_impulse_steps`), ``k + 1`` still a row of ``tr``."""
    if not impulses:
        return []
    t, steps = np.asarray(tr.t), np.fromiter(impulses, dtype=np.float64, count=len(impulses))
    hits = [a + k for a, b in _chunks(0, len(tr)) for k in np.flatnonzero(np.isin(t[a:b], steps)).tolist()]
    return [k + 1 for k in hits if k + 1 < len(tr)]


def _impulse_steps(run: Run, name: str) -> dict[float, float]:
    """``{t_k: |dv| m/s}`` of the closed loop's impulsive burns of body ``name``: applied
    in the step that starts at ``t_k`` (its actuator state's ``dv``; docs/control.md)."""
    act = run.channels.get(f"astrodyn/{run.scenario.get('name', '')}/{name}/actuators")
    dv = None if act is None else act.fields.get("dv")
    if dv is None or np.ndim(dv) != 2 or np.shape(dv)[1:] != (3,):
        return {}
    hit = np.isfinite(dv[:, 0])
    return {float(t): float(np.linalg.norm(d)) for t, d in zip(np.asarray(act.t)[hit], dv[hit])}


def write_oem(run: Run, out: Path) -> list[Path]:
    """``<body>.oem`` per body with an orbit channel (CCSDS 502.0-B-3 KVN).  An impulsive
    burn of the closed loop ends a segment: the ephemeris is cut between the step it was
    applied in and the next (a new META block), so that no reader interpolates across the
    velocity jump."""
    written = []
    for name, _, tr, epochs, system in _ccsds_tracks(run, "orbit"):
        frames = sorted(set(tr.frame))
        comment = (f"scenario {run.scenario.get('name', '?')}, epoch {run.scenario.get('epoch', '?')}; "
                   f"models {', '.join(sorted(set(tr.model)))}")
        impulses = _impulse_steps(run, name)
        bounds = [0, *_impulse_cuts(tr, impulses), len(tr)]
        frame = frames[0] if len(frames) == 1 else "GCRF"
        path = out / f"{name}.oem"
        with open(path, "w") as f:
            for j in range(len(bounds) - 1):
                a, b = bounds[j], bounds[j + 1]
                head = _message_head("CCSDS_OEM_VERS", "3.0", run, tr, [comment], name, [("REF_FRAME", frame)],
                                     system, epochs.at(a), epochs.at(b - 1))
                lines = []
                if j > 0:  # later segments: only the metadata block (the header is the file's)
                    head = head[head.index("META_START"):]
                    lines.append("")
                lines += head + ["META_STOP", ""]
                if j > 0:
                    dt = float(tr.t[a - 1])
                    lines.append(f"COMMENT after an impulsive burn of {impulses[dt]!r} m/s applied between "
                                 f"{epochs.at(a - 1)} and {epochs.at(a)} (a new segment: do not interpolate across it)")
                lines.append("COMMENT position km, velocity km/s")
                _write_lines(f, lines)
                for c, d in _chunks(a, b):  # the data lines a chunk at a time: r and v in km, km/s
                    r, v = (tr.r[c:d] / 1e3).tolist(), (tr.v[c:d] / 1e3).tolist()
                    _write_lines(f, [" ".join([ep, *map(repr, rk), *map(repr, vk)])
                                     for ep, rk, vk in zip(epochs.of(c, d), r, v)])
        written.append(path)
    return written


def _body_rates(tr: Track) -> np.ndarray | None:
    """The attitude track's body rates ``w`` (rad/s, ``(n, 3)``) if every message carries them."""
    w = tr.fields.get("w")
    if w is None or w.ndim != 2 or w.shape != (len(tr), 3) or not all(np.all(np.isfinite(w[a:b]))
                                                                       for a, b in _chunks(0, len(tr))):
        return None
    return w


def write_aem(run: Run, out: Path, version: str = "2.0") -> list[Path]:
    """``<body>.aem`` per body with an attitude channel, CCSDS KVN.

    ``version="2.0"`` (504.0-B-2, the default): QUATERNION/ANGVEL when every attitude
    message carries finite body rates ``w``, plain QUATERNION otherwise (see the module
    docstring).  ``version="1.0"`` (504.0-B-1, ``--format aem1``) for readers that know
    only ADM version 1 (e.g. the ``ccsds-ndm`` package): ``ATTITUDE_DIR = A2B``,
    ``QUATERNION_TYPE = LAST`` and plain QUATERNION data lines; the rates are left out,
    because version 1's QUATERNION/RATE gives its rates in the order of an
    ``EULER_ROT_SEQ`` and readers differ on what they mean (version 2's ANGVEL is exact).
    """
    if version not in ("1.0", "2.0"):
        raise ExportError(f"AEM version: expected 1.0 or 2.0, got {version!r}")
    written = []
    for name, body, tr, epochs, system in _ccsds_tracks(run, "attitude"):
        frame_a = _orbit_frame(body)
        w = _body_rates(tr) if version == "2.0" else None
        comments = ["Quaternion rotates REF_FRAME_A into REF_FRAME_B: v_B = C(q) v_A (Baruh ch. 7),",
                    "data columns Q1 Q2 Q3 QC with the scalar QC last (astrodyn q = (QC, Q1, Q2, Q3))."]
        frames = [("REF_FRAME_A", frame_a), ("REF_FRAME_B", "SC_BODY_1")]
        meta_tail = [_kvn("ATTITUDE_TYPE", "QUATERNION")]
        if version == "1.0":
            comments.append("ADM version 1 output: body rates are in the version 2.0 export (QUATERNION/ANGVEL).")
            frames.append(("ATTITUDE_DIR", "A2B"))
            meta_tail.append(_kvn("QUATERNION_TYPE", "LAST"))
        elif w is not None:
            comments += ["ANGVEL_X ANGVEL_Y ANGVEL_Z: angular velocity of REF_FRAME_B relative to REF_FRAME_A,",
                         "components in ANGVEL_FRAME = SC_BODY_1 (body axes), deg/s: the recorded w (rad/s) * 180/pi;",
                         "dC/dt = -[w x] C."]
            meta_tail = [_kvn("ATTITUDE_TYPE", "QUATERNION/ANGVEL"), _kvn("ANGVEL_FRAME", "SC_BODY_1")]
        head = _message_head("CCSDS_AEM_VERS", version, run, tr, comments, name, frames, system, epochs.at(0),
                             epochs.at(len(tr) - 1))
        path = out / f"{name}.aem"
        with open(path, "w") as f:
            _write_lines(f, [*head, *meta_tail, "META_STOP", "", "DATA_START"])
            for a, b in _chunks(0, len(tr)):  # the data lines a chunk at a time: Q1 Q2 Q3 QC [ANGVEL deg/s]
                q = np.asarray(tr.q[a:b], dtype=np.float64).tolist()
                if w is None:
                    lines = [f"{ep} {qk[1]!r} {qk[2]!r} {qk[3]!r} {qk[0]!r}" for ep, qk in zip(epochs.of(a, b), q)]
                else:
                    lines = [f"{ep} {qk[1]!r} {qk[2]!r} {qk[3]!r} {qk[0]!r} {wk[0]!r} {wk[1]!r} {wk[2]!r}"
                             for ep, qk, wk in zip(epochs.of(a, b), q, np.degrees(w[a:b]).tolist())]
                _write_lines(f, lines)
            _write_lines(f, ["DATA_STOP"])
        written.append(path)
    return written


def write_aem_v1(run: Run, out: Path) -> list[Path]:
    """``--format aem1``: :func:`write_aem` with ``version="1.0"``."""
    return write_aem(run, out, version="1.0")


# ------------------------------------------------------------------------------ Foxglove


#: Topics an export to Foxglove writes (:func:`write_foxglove`): ``foxglove/<body>/tf`` and
#: :data:`SCENE_TOPIC`.  An input's channels under it (a ``.foxglove.mcap`` exported again)
#: are not copied: they are made anew from its states.
FOXGLOVE_TOPICS = "foxglove/"


def frame_transforms(run: Run) -> list[tuple[int, str, bytes]]:
    """``(log_time, topic, payload)`` of the ``foxglove.FrameTransform`` messages, time-sorted.

    One per body per instant at which the body has an orbit or an attitude state, stamped
    with exactly that state's log time.  A body with an attitude is the frame ``<body>``:
    its recorded rotation, at its recorded position (the origin of the parent frame when
    it has no orbit; between the instants of one kind the last value of the other is
    held).  A body with an orbit and no attitude is the frame ``<body>/position``: its
    position only, axes parallel to the parent frame (no attitude is made up for it).
    """
    out = [m for frame in _body_frames(run) for m in _transform_messages(*frame)]
    out.sort(key=lambda m: m[0])
    return out


def _body_frames(run: Run) -> list[tuple[str, str, str, np.ndarray, np.ndarray, np.ndarray]]:
    """``(topic, parent, child, times, position_km, rotation_xyzw)`` of each body's
    FrameTransforms (:func:`frame_transforms`) as arrays, one row per instant in time order."""
    out = []
    for name, body in run.bodies.items():
        orbit, att = body.orbit, body.attitude
        orbit = orbit if orbit is not None and len(orbit) else None
        att = att if att is not None and len(att) else None
        if orbit is None and att is None:
            continue
        parent = _orbit_frame(body)
        child = name if att is not None else f"{name}/position"
        none = np.zeros(0, dtype=np.uint64)  # Track.log_time's dtype: another one's union is float64, rounding ns
        times = np.union1d(orbit.log_time if orbit is not None else none, att.log_time if att is not None else none)
        pos = np.zeros((times.size, 3))
        rot = np.tile([0.0, 0.0, 0.0, 1.0], (times.size, 1))  # the parent's axes: only for position-only frames
        for tr, arr in ((orbit, pos), (att, rot)):
            if tr is None:
                continue
            arr[np.searchsorted(times, tr.log_time)] = tr.r / 1e3 if arr is pos else quat_to_scalar_last(tr.q)
            if len(tr) < times.size:  # both kinds at different instants: hold the last known value
                have = np.isin(times, tr.log_time)
                last = np.maximum.accumulate(np.where(have, np.arange(times.size), 0))
                arr[:] = arr[last]
        out.append((f"{FOXGLOVE_TOPICS}{name}/tf", parent, child, times, pos, rot))
    return out


def _transform_messages(topic: str, parent: str, child: str, times: np.ndarray, pos: np.ndarray, rot: np.ndarray):
    """The ``(log_time, topic, payload)`` of one body's FrameTransforms (:func:`_body_frames`)
    in time order, made :data:`_CHUNK_ROWS` at a time."""
    encode = json.JSONEncoder(separators=(",", ":")).encode  # json.dumps(..., separators=...), one encoder for all
    for a, b in _chunks(0, times.size):
        for lt, p, r in zip(times[a:b].tolist(), pos[a:b].tolist(), rot[a:b].tolist()):
            yield lt, topic, encode(frame_transform(stamp(lt), parent, child, p, r)).encode()


def scene_updates(run: Run, max_line_points: int = MAX_LINE_POINTS,
                  max_scene_points: int = MAX_SCENE_POINTS) -> list[tuple[int, str, bytes]]:
    """``(log_time, topic, payload)`` of the ``foxglove.SceneUpdate`` messages on :data:`SCENE_TOPIC`.

    All are stamped with the first log time of the recording and never expire
    (``lifetime`` 0); distances in km like the FrameTransforms.  One message per entity
    group, so none grows with the number of bodies:

    * ``central_body/<name>``: the central body as a sphere of the metadata's equatorial
      radius (diameter ``2 R / 1000`` on each axis), centred on the origin of the orbit
      frame.  Written only when some body has an orbit (in an attitude-only scene the
      bodies sit at the origin, inside the sphere) and the metadata give a radius.
    * ``orbit/<body>``: per body with an orbit, its recorded positions ``r / 1000`` as a
      LINE_STRIP in the orbit frame, 2 px wide, in the body's colour
      (:data:`BODY_COLORS`).  At most ``max_line_points`` points per body and
      ``max_scene_points`` for all bodies together (a 1000-body constellation gets 200
      per body), chosen by :func:`line_indices`.
    * ``axes/<body>``: per body with an attitude, three arrows along its x (red), y
      (green) and z (blue) axes in the body's own frame (``frame_id`` = body name,
      ``frame_locked``), so they turn with the FrameTransform; length a tenth of the
      central body's radius in an orbit scene, 1 km otherwise.
    """
    if not (isinstance(max_scene_points, (int, np.integer)) and max_scene_points >= 2):
        raise ValueError(f"max_scene_points: expected an integer >= 2, got {max_scene_points!r}")
    bodies = [(name, b) for name, b in run.bodies.items()
              if (b.orbit is not None and len(b.orbit)) or (b.attitude is not None and len(b.attitude))]
    if not bodies:
        return []
    t0 = int(min(int(tr.log_time.min()) for tr in run.channels.values() if len(tr)))
    ts = stamp(t0)
    orbiting = [b for _, b in bodies if b.orbit is not None and len(b.orbit)]
    central = _central_body(run)
    try:
        radius_km = float(central.get("radius", 0.0)) / 1e3
    except (TypeError, ValueError):
        radius_km = 0.0
    radius_km = radius_km if np.isfinite(radius_km) and radius_km > 0 else 0.0
    updates = []
    if orbiting and radius_km > 0:
        updates.append([central_body_entity(ts, _orbit_frame(orbiting[0]), str(central.get("name", "central")),
                                            radius_km)])
    per_body = max(2, min(int(max_line_points), int(max_scene_points) // max(1, len(orbiting))))
    axis_km = 0.1 * radius_km if orbiting and radius_km > 0 else 1.0
    for k, (name, body) in enumerate(bodies):
        rgb = BODY_COLORS[k % len(BODY_COLORS)]
        entities = []
        if body.orbit is not None and len(body.orbit):
            idx = line_indices(len(body.orbit), per_body)
            entities.append(orbit_line_entity(ts, _orbit_frame(body), name, body.orbit.r[idx] / 1e3, rgb,
                                              len(body.orbit)))
        if body.attitude is not None and len(body.attitude):
            entities.append(axes_entity(ts, name, axis_km))
        updates.append(entities)
    return [(t0, SCENE_TOPIC, json.dumps({"deletions": [], "entities": ents}, separators=(",", ":")).encode())
            for ents in updates]


def write_foxglove(run: Run, out: Path, max_line_points: int = MAX_LINE_POINTS) -> list[Path]:
    """A Foxglove-ready copy of the file: every channel unchanged plus FrameTransform
    channels and the SceneUpdate channel (see the module docstring).  The input's own
    channels under :data:`FOXGLOVE_TOPICS` (it is an earlier export's output) are left out,
    so each instant has one transform per body and the scene is written once, not again
    beside the earlier export's."""
    from astrodyn.recording.stream import open_stream

    path = out / (Path(run.path).name.removesuffix(".mcap") + ".foxglove.mcap")
    if path.resolve() == Path(run.path).resolve():
        raise ExportError(f"--out: would overwrite the input {run.path}")
    raw = run.metadata.get("recording", {}).get("epoch_unix_ns", run.scenario.get("epoch_unix_ns", "0"))
    try:
        epoch_ns = int(raw)
        if not -(2**63) <= epoch_ns < 2**63:  # log times are uint64 ns: a 400-digit epoch overflowed t's float
            raise ValueError(raw)
    except (TypeError, ValueError):
        raise ExportError(f"{run.path}: metadata epoch_unix_ns {str(raw)[:40]!r}: expected an integer number of ns "
                          f"(int64)") from None
    # the scene first: at the first instant it is there before the first transform; then the
    # bodies' transforms in time order (at one instant in body order), each made when written
    frames = [_transform_messages(*frame) for frame in _body_frames(run)]
    tfs = heapq.merge(scene_updates(run, max_line_points), *frames, key=lambda m: m[0])
    with open_stream(run.path) as stream, McapRecorder(path, run.scenario, epoch_ns=epoch_ns) as rec:
        registered: set[str] = set()
        seqs: dict[str, int] = {}
        originals = ((m.log_time, m.topic, m.data, m) for m in stream.messages()
                     if not m.topic.startswith(FOXGLOVE_TOPICS))  # made anew below
        extras = ((lt, topic, data, None) for lt, topic, data in tfs)
        for lt, topic, data, raw in heapq.merge(originals, extras, key=lambda x: x[0]):
            if topic not in registered:
                if raw is None and topic == SCENE_TOPIC:
                    rec.add_channel(topic, "foxglove.SceneUpdate", SCENE_UPDATE_SCHEMA)
                elif raw is None:
                    rec.add_channel(topic, "foxglove.FrameTransform", FRAME_TRANSFORM_SCHEMA)
                else:
                    ch = next(c for c in stream.channels.values() if c.topic == topic)
                    schema = stream.schemas.get(ch.schema_id)
                    rec.add_channel(topic, schema.name if schema else "", schema.data if schema else b"{}", ch.message_encoding)
                registered.add(topic)
            seq = seqs.get(topic, 0)
            seqs[topic] = seq + 1
            # the exact log time of each message (t alone is ns-exact only within 104 days of the epoch)
            rec.write_encoded(topic, data, (lt - epoch_ns) / 1e9, seq, publish_time=raw.publish_time if raw else lt,
                              log_time=lt)
    return [path]


# ------------------------------------------------------------------------------ driver

_WRITERS = {"csv": write_csv, "parquet": write_parquet, "oem": write_oem, "aem": write_aem, "aem1": write_aem_v1,
            "foxglove": write_foxglove}


def export(path: str | os.PathLike, fmt: str, out: str | os.PathLike) -> list[Path]:
    """Export ``path`` in format ``fmt`` (one of :data:`FORMATS`) into directory ``out``."""
    if fmt not in _WRITERS:
        raise ExportError(f"format: expected one of {', '.join(FORMATS)}, got {fmt!r}")
    run = load(path)
    if run.messages == 0:  # an empty file, a cut one, one whose every message was rejected: nothing to export
        why = run.incomplete_reason or (f"its {len(run.channels)} channel{'' if len(run.channels) == 1 else 's'} "
                                        f"hold no message" if run.channels else "it holds no channel")
        raise ExportError(f"{run.path}: nothing to export as {fmt}: no valid message; {why}")
    if not run.complete:
        rejected = rejected_channels(run) if fmt in ("csv", "parquet") else []
        left_out = (f" (no file for the {len(rejected)} channel{'' if len(rejected) == 1 else 's'} whose every message "
                    f"was rejected: {', '.join(rejected[:5])}{', ...' if len(rejected) > 5 else ''})" if rejected else "")
        warn_incomplete_input("export", run.path, run.incomplete_reason,
                              f"exporting the {run.messages} complete, valid messages{left_out}")
    # the seq account analyze gives, as a warning, for the channels the format exports; a CCSDS
    # file's channel with a duplicated seq or a time that goes back is refused instead
    # (_check_time_order), not warned about
    ccsds_kind = {"oem": "orbit", "aem": "attitude", "aem1": "attitude"}.get(fmt)
    issues = {key: issue for key, issue in sequence_issues(run).items()
              if ccsds_kind is None or (run.channels[key.split("#", 1)[0]].kind == ccsds_kind
                                        and not (issue["duplicates"] or issue.get("t_not_increasing")))}
    if issues:
        print(f"astrodyn export: warning: {run.path}: {sequence_note(issues)}; exported as recorded, in seq order",
              file=sys.stderr)
    out = Path(out)
    # every file is written in a work directory inside --out and moved into place only when
    # all of them are complete: a failed or interrupted export leaves the files already in
    # --out as they were (astrodyn.recording.outputs)
    with staging_directory(out, "export", cannot=lambda exc: ExportError(
            f"--out: cannot create directory {out}: {exc.strerror or exc}")) as work:
        try:
            files = _WRITERS[fmt](run, work)
        except OSError as exc:
            written = f" {Path(exc.filename).name}" if exc.filename else ""
            raise ExportError(f"{run.path}: --out {out}: cannot write{written}: {exc.strerror or exc}; "
                              f"nothing in {out} was replaced") from None
        if not files:
            what = {"oem": "orbit", "aem": "attitude", "aem1": "attitude"}.get(fmt, "message")
            raise ExportError(f"{run.path}: no {what} channels to export as {fmt}")
        placed = []
        for f in files:
            target = out / f.name
            if target.resolve() == Path(run.path).resolve() or target.is_dir():
                raise ExportError(f"{run.path}: --out {out}: {target} is {'the input' if target.is_file() else 'a directory'}; "
                                  f"it is never replaced (nothing was written)")
            placed.append(target)
        try:
            with deferred_interrupts():  # all of them or, on a signal before this, none
                for f, target in zip(files, placed):
                    os.replace(f, target)
        except OSError as exc:
            raise ExportError(f"{run.path}: --out {out}: cannot write {target}: {exc.strerror or exc}") from None
        return placed


@interruptible_main("astrodyn export")
def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="astrodyn export", description="Export an MCAP recording to other formats.",
                                 epilog="Exit status: 0 exported; 1 the input cannot be read or has nothing to export, "
                                        "or the files cannot be written; 2 a bad flag value or an --out that is not a "
                                        "directory that can be made; 128 + the signal when interrupted.")
    ap.add_argument("file", type=path_argument, help="MCAP file recorded by astrodyn")
    ap.add_argument("--format", required=True, choices=FORMATS, help="csv | parquet | oem | aem | aem1 (CCSDS ADM version 1) | foxglove")
    ap.add_argument("--out", required=True, type=path_argument, help="output directory (created if missing)")
    args = ap.parse_args(argv)
    if problem := output_path_problem(args.out, directory=True):  # the command line alone: before the input is read
        print(f"astrodyn export: error: --out {args.out}: {problem}", file=sys.stderr)
        return 2
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
