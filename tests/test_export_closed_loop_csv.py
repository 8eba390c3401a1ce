"""``astrodyn export --format csv`` (and parquet) of a closed-loop recording, read back
independently (probe B, F6).

Before, the command file said ``# frame: None, body (...)``; ``applied`` was a Python list
repr ``['ctl#0']`` (``json.loads`` fails), ``clipped`` ``[0]``, ``wheel_torque`` /
``wheel_speed`` / ``speeds`` / the gyroscopes' lists quoted list reprs while 3-vectors were
split into columns; a field the message does not carry was ``nan`` in a number column and
an empty cell in a list column; the appendages of unequal mode counts one repr cell; and
docs/exports.md described none of these channels.

The reference here is not the exporter: every message is read with the plain ``mcap``
reader and ``json``; the columns a message field must make are derived from the JSON Schema
stored with its channel in the file, by the rules docs/exports.md states ("How message
fields become columns"); each column's unit is taken from the tables of docs/exports.md
("Every channel's columns").  The recording is made once (a real closed loop: plant,
propagators, logger and a controller that sends commands with different fields left out),
1 s at 10 Hz.
"""

from __future__ import annotations

import csv
import json
import math
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from mcap.reader import make_reader

from _recordings import copy_recording
from _scenes import RATE_GYRO_DYNAMICS, appendage_table, coin_body, gyro_table, wheel_tables
from astrodyn.recording.export import export

pytestmark = pytest.mark.network
ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs" / "exports.md"

#: One body of every closed-loop kind (orbit, a flexible hub with two appendages of 1 and 2
#: modes, three wheels, torque, dv and thrust actuators, all four sensors), a rolling disk
#: and a body with two rate gyros.
SCENE = """
[scenario]
name = "csvloop"
epoch = "2026-03-20T12:00:00 UTC"
duration = "1 s"
rate = "10 Hz"

[control]
mode = "lockstep"
period = "0.1 s"
controllers = ["ctl"]
timeout = "20 s"
seed = 1

[[bodies]]
name = "sc"
[bodies.orbit]
a = "7000 km"
e = 0.001
i = "51 deg"
[bodies.attitude]
model = "flexible"
mass = "400 kg"
inertia = ["300 kg m2", "250 kg m2", "400 kg m2"]
""" + appendage_table(["0 m", "1 m", "0 m"], [1, 0, 0], "5 m", "2 kg/m", "2000 N m2", 1) \
    + appendage_table(["0 m", "-1 m", "0 m"], [1, 0, 0], "5 m", "2 kg/m", "2000 N m2", 2) + """
[bodies.actuators]
torque = "0.05 N m"
dv = "100 m/s"
thrust = "2 N"
isp = "220 s"
mass = "500 kg"
""" + wheel_tables([[1, 0, 0], [0, 1, 0], [0, 0, 1]], "0.1 kg m2", "0.2 N m", "6000 rpm") + """
[bodies.sensors]
gyro = { sigma = "1e-6 rad/s" }
star_tracker = { sigma = "5 arcsec" }
gps = { sigma_r = "5 m", sigma_v = "0.05 m/s" }
tachometer = { sigma = "0.1 rad/s" }

""" + coin_body("coin", 'shape = "disk"\nlean = "20 deg"\nheading_rate = "6 rad/s"\nspin_rate = "steady"\n') + """
[[bodies]]
name = "probe"
[bodies.attitude]
inertia = ["900 kg m2", "1100 kg m2", "1300 kg m2"]
w = ["1.5 deg/s", "-0.8 deg/s", "2.5 deg/s"]
""" + gyro_table("rate", [1, 0, 0], RATE_GYRO_DYNAMICS) \
    + gyro_table("rate", [0, 1, 0], RATE_GYRO_DYNAMICS, output_axis=[0, 0, 1])

#: Step 0: torque only; step 1: wheel torques beyond max_torque (wheel 0 clipped) and a dv;
#: step 2: a body-axes thrust and, separately, wheel torques (two commands applied in one step).
CONTROLLER = """
import sys
sys.path.insert(0, {examples!r})
from astrodyn_link import Link
with Link() as link:
    n = 0
    while (tick := link.wait_tick()) is not None:
        t = tick["t"]
        if n == 0:
            link.command("sc", t, torque=[0.01, 0.0, -0.01])
        elif n == 1:
            link.command("sc", t, wheel_torque=[0.5, -0.01, 0.0], dv=[0.1, 0.0, 0.0])
        elif n == 2:
            link.command("sc", t, thrust=[0.0, 1.0, 0.0], frame="body")
            link.command("sc", t, wheel_torque=[0.0, 0.0, 0.01])
        n += 1
        link.done(tick)
"""


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("closed_loop_csv")
    cfg, ctl, out = d / "csvloop.toml", d / "ctl.py", d / "loop.mcap"
    cfg.write_text(SCENE)
    ctl.write_text(textwrap.dedent(CONTROLLER.format(examples=str(ROOT / "examples"))))
    proc = subprocess.run([sys.executable, "-m", "astrodyn", "run", str(cfg), "--out", str(out),
                           "--controller", f"python {ctl}", "--quiet"],
                          capture_output=True, text=True, timeout=240, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    return out


@pytest.fixture(scope="module")
def exported(recording, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("csv")
    export(recording, "csv", out)
    return out


# ------------------------------------------------------------------ the independent reading


def recorded_channels(path: Path) -> dict[str, tuple[dict, list[tuple[int, dict]]]]:
    """topic -> (the JSON Schema stored with it, [(log_time, message)] in the file's order)."""
    out: dict[str, tuple[dict, list]] = {}
    with open(path, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages(log_time_order=False):
            entry = out.setdefault(channel.topic, (json.loads(schema.data), []))
            entry[1].append((message.log_time, json.loads(message.data)))
    return out


def file_name(topic: str) -> str:
    """docs/exports.md: ``astrodyn/<scenario>/<body>/<kind>`` -> ``<body>.<kind>.csv``, ``@event`` -> ``events.csv``."""
    parts = topic.split("/")
    return "events.csv" if parts[-1] == "@event" else f"{parts[-2]}.{parts[-1]}.csv"


def documented_columns(schema: dict, msgs: list[dict]) -> list[tuple[str, str, object]]:
    """``(column, how, getter)`` for every message field, by the rules of docs/exports.md:
    how is ``number``, ``integer``, ``text`` or ``json``; ``getter(message)`` is the value
    the cell holds, or ``ABSENT`` when the message does not carry it."""
    cols = []
    for name, prop in schema["properties"].items():
        if name in ("t", "seq"):
            continue
        kind, items = prop.get("type"), prop.get("items") or {}
        element = lambda *path, name=name: field_getter(name, *path)  # noqa: E731
        if kind in ("number", "integer"):
            cols.append((name, kind, element()))
        elif kind == "array" and items.get("type") == "number":
            fixed = prop.get("minItems") == prop.get("maxItems")
            n = prop["minItems"] if fixed else max((len(m[name]) for m in msgs if name in m), default=0)
            suffixes = "xyz" if fixed and n == 3 else [str(i) for i in range(n)]
            cols += [(f"{name}_{s}", "number", element(i)) for i, s in enumerate(suffixes)]
        elif kind == "array" and items.get("type") == "array" and items["items"].get("type") == "number":
            per = max((len(m[name]) for m in msgs if name in m), default=0)
            for k in range(per):
                inner_fixed = items.get("minItems") == items.get("maxItems")
                n = max((len(m[name][k]) for m in msgs if name in m and k < len(m[name])), default=0)
                suffixes = "xyz" if inner_fixed and n == 3 else [str(i) for i in range(n)]
                cols += [(f"{name}_{k}_{s}", "number", element(k, i)) for i, s in enumerate(suffixes)]
        elif kind == "string" or "enum" in prop:
            cols.append((name, "text", element()))
        else:
            cols.append((name, "json", element()))
    return cols


ABSENT = object()


def field_getter(name: str, *path: int):
    """``get(message)``: the message's field ``name`` (its element ``path``), or ``ABSENT``."""
    def get(message: dict):
        value = message.get(name, ABSENT)
        for i in path:
            if value is ABSENT or i >= len(value):
                return ABSENT
            value = value[i]
        return value
    return get


def read_csv(path: Path) -> tuple[dict[str, str], list[str], list[dict[str, str]], list[str]]:
    """(header entries, column names, rows, the ``#`` lines) of an exported CSV."""
    lines = path.read_text().splitlines()
    comments = [line for line in lines if line.startswith("#")]
    head = dict(line[2:].split(": ", 1) for line in comments)
    reader = csv.reader(line for line in lines if not line.startswith("#"))
    names = next(reader)
    rows = [dict(zip(names, row, strict=True)) for row in reader]
    return head, names, rows, comments


def documented_units() -> dict[str, dict[str, str]]:
    """file pattern (``<body>.command.csv``) -> column regex -> documented unit, from the
    tables of docs/exports.md, section "Every channel's columns"."""
    text = DOCS.read_text().split("### Every channel's columns", 1)[1].split("\n## ", 1)[0]
    out: dict[str, dict[str, str]] = {}
    current = None
    for line in text.splitlines():
        if m := re.match(r"\*\*`([^`]+\.csv)`\*\*", line):
            current = out.setdefault(m[1], {})
        elif current is not None and line.startswith("| `"):
            columns, unit = [c.strip() for c in line.strip("|").split("|")[:2]]
            for group in re.findall(r"`([^`]+)`", columns):
                for col in group.split():
                    current[re.escape(col).replace("<i>", r"\d+").replace("<k>", r"\d+")] = unit
    return out


def doc_section(name: str, docs: dict[str, dict[str, str]]) -> dict[str, str]:
    body_kind = re.fullmatch(r"[^.]+\.(.+\.csv)", name)
    key = name if name in docs else f"<body>.{body_kind[1]}" if body_kind else name
    assert key in docs, f"docs/exports.md documents no {key}"
    return docs[key]


def assert_cells_are_the_messages(csv_path: Path, schema: dict, msgs: list[tuple[int, dict]]) -> None:
    head, names, rows, comments = read_csv(csv_path)
    expected = documented_columns(schema, [m for _, m in msgs])
    assert names == ["t", "seq", "log_time_ns", *(c for c, _, _ in expected)], csv_path.name
    # each row is one message: (seq, process / sender) names it on every channel
    key = lambda m: (int(m["seq"]), m.get("process"), m.get("sender"))  # noqa: E731
    by_key = {key(m): (lt, m) for lt, m in msgs}
    assert len(by_key) == len(msgs) == len(rows), csv_path.name
    assert [int(r["seq"]) for r in rows] == sorted(int(r["seq"]) for r in rows), csv_path.name
    json_columns = []
    for row in rows:
        log_time, msg = by_key[key(row)]
        assert float(row["t"]) == msg["t"] and int(row["log_time_ns"]) == log_time
        for col, how, get in expected:
            value, cell = get(msg), row[col]
            where = f"{csv_path.name} seq {msg['seq']} {col}: {cell!r}"
            if value is ABSENT:
                assert cell == "", where  # a field (or element) the message does not carry: an empty cell
            elif how == "number":
                assert float(cell) == value and math.isfinite(float(cell)), where
            elif how == "integer":
                assert int(cell) == value, where
            elif how == "text":
                assert cell == value, where
            else:
                assert json.loads(cell) == value, where
            if how == "json":
                json_columns.append(col)
            if col != "detail":  # an event's free text may quote anything
                assert "'" not in cell and "None" not in cell and "nan" not in cell.lower(), where
    # the header: no Python None, the JSON columns named, every column's documented unit
    assert not any("None" in line for line in comments), comments
    if json_columns:
        assert head["json"].split(": ")[0].split(", ") == sorted(set(json_columns), key=names.index)
    if any(get(m) is ABSENT for _, m in msgs for _, _, get in expected):
        assert "empty cell" in head["empty"]
    units = dict(u.split("=", 1) for u in head["units"].split(", "))
    documented = doc_section(csv_path.name, documented_units())
    for col in names[3:]:
        matches = [unit for pattern, unit in documented.items() if re.fullmatch(pattern, col)]
        assert len(matches) == 1, f"{csv_path.name}: column {col} documented {len(matches)} times"
        unit = matches[0]
        if unit in ("text", "JSON"):
            assert col not in units, (csv_path.name, col)
        else:
            assert units.get(col) in unit.split(" or "), (csv_path.name, col, units.get(col), unit)
    for pattern in documented:  # and nothing documented is missing
        assert any(re.fullmatch(pattern, col) for col in names), f"{csv_path.name}: no column {pattern}"


# ------------------------------------------------------------------ tests


def test_every_csv_of_a_closed_loop_recording_holds_its_messages_as_documented(recording, exported):
    channels = recorded_channels(recording)
    kinds = {topic.rsplit("/", 1)[1] for topic in channels}
    # the recording has every closed-loop kind (the test's premise)
    assert {"command", "actuators", "gyro", "star_tracker", "gps", "tachometer", "appendages", "rolling",
            "gimbals", "orbit", "attitude", "@event"} <= kinds
    assert sorted(p.name for p in exported.iterdir()) == sorted(file_name(t) for t in channels)
    for topic, (schema, msgs) in channels.items():
        assert_cells_are_the_messages(exported / file_name(topic), schema, msgs)


def test_closed_loop_specifics_read_back(exported):
    """What the probe saw, stated directly: fields left out are empty cells, lists of names
    and indices are JSON, wheels are indexed (three of them, not x y z), the command's
    ``frame`` is a column and not a header, the orbit's header names its frame."""
    head, names, rows, _ = read_csv(exported / "sc.command.csv")
    assert "frame" not in head and "sender" in names
    assert [c for c in names if c.startswith("wheel_torque")] == ["wheel_torque_0", "wheel_torque_1", "wheel_torque_2"]
    first = rows[0]  # torque only
    assert [first[f"dv_{c}"] for c in "xyz"] == ["", "", ""] and first["frame"] == "" and first["wheel_torque_0"] == ""
    thrust = next(r for r in rows if r["frame"] == "body")
    assert [float(thrust[f"thrust_{c}"]) for c in "xyz"] == [0.0, 1.0, 0.0]
    _, names, rows, _ = read_csv(exported / "sc.actuators.csv")
    applied = [json.loads(r["applied"]) if r["applied"] else [] for r in rows]
    assert applied[:3] == [["ctl#0"], ["ctl#1"], ["ctl#2", "ctl#3"]] and not any(applied[3:])
    assert json.loads(rows[1]["clipped"]) == [0] and float(rows[1]["wheel_torque_0"]) == 0.2  # max_torque
    assert rows[0]["clipped"] == "" and rows[0]["dv_t"] == "" and float(rows[1]["dv_t"]) == 0.1
    head, _, _, _ = read_csv(exported / "sc.orbit.csv")
    assert head["frame"] == "GCRF (inertial, origin at the central body)"
    _, names, _, _ = read_csv(exported / "sc.appendages.csv")  # 1 and 2 modes: 2 and 4 coordinates
    assert [c for c in names if c.startswith("eta_") and not c.startswith("eta_dot")] == \
        ["eta_0_0", "eta_0_1", "eta_1_0", "eta_1_1", "eta_1_2", "eta_1_3"]


def test_lists_shorter_in_some_messages_leave_empty_cells(recording, tmp_path):
    """A file whose layout changes (valid messages: one appendage and two wheel speeds in
    every third message) makes the columns of the longest list; the shorter ones leave the
    cells they have no element for empty."""
    def fewer_elements(channel, message) -> bytes:
        msg = json.loads(message.data)
        if msg["seq"] % 3 == 1 and channel.topic.endswith("/appendages"):
            msg["eta"], msg["eta_dot"], msg["tip"] = msg["eta"][:1], msg["eta_dot"][:1], msg["tip"][:1]
            return json.dumps(msg).encode()
        if msg["seq"] % 3 == 1 and channel.topic.endswith("/tachometer"):
            msg["speeds"] = msg["speeds"][:2]
            return json.dumps(msg).encode()
        return message.data

    changed = tmp_path / "changed.mcap"
    copy_recording(recording, changed, edit_message=fewer_elements)
    out = tmp_path / "csv"
    export(changed, "csv", out)
    channels = recorded_channels(changed)
    for topic in ("astrodyn/csvloop/sc/appendages", "astrodyn/csvloop/sc/tachometer"):
        schema, msgs = channels[topic]
        assert_cells_are_the_messages(out / file_name(topic), schema, msgs)
    _, _, rows, _ = read_csv(out / "sc.tachometer.csv")
    assert rows[1]["speeds_2"] == "" and rows[2]["speeds_2"] != ""


def test_parquet_has_the_csv_columns_with_null_for_an_absent_field(recording, exported, tmp_path):
    pq = pytest.importorskip("pyarrow.parquet")
    export(recording, "parquet", tmp_path)
    for name in ("sc.command", "sc.actuators", "sc.appendages", "probe.gimbals", "sc.tachometer"):
        head, names, rows, _ = read_csv(exported / f"{name}.csv")
        table = pq.read_table(tmp_path / f"{name}.parquet")
        assert table.column_names == names
        meta = {k.decode(): v.decode() for k, v in table.schema.metadata.items()}
        assert {k.removeprefix("astrodyn."): v for k, v in meta.items()} == head
        values = table.to_pydict()
        for col in names:
            for cell, value in zip((r[col] for r in rows), values[col], strict=True):
                if cell == "":
                    assert value is None, (name, col)
                elif isinstance(value, str):
                    assert value == cell, (name, col)
                else:
                    assert value == float(cell), (name, col)
