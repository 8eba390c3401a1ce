"""Foxglove export: the ``foxglove.SceneUpdate`` channel (central body, orbit lines, body axes).

The exported file is read back with the plain ``mcap`` reader (not astrodyn's), every
SceneUpdate message is checked against the JSON Schema *declared in the file* by a small
validator written here (jsonschema is not installed), and the declared schema's
``required`` lists are compared with the ones published by Foxglove
(foxglove-sdk ``schemas/jsonschema/SceneUpdate.json``), copied below by hand.  Line
points are compared with the simulated positions ``/ 1000`` (the same float64 division,
so exactly), the sphere with the radius in the file's own scenario metadata record.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from astrodyn.recording import load
from astrodyn.recording.export import export, line_indices, scene_updates

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _recordings import LEO_TWO_BODIES, record, scenario_head
from test_export import _rotate_active  # written independently of the exporter

# foxglove-sdk schemas/jsonschema/SceneUpdate.json: the "required" list of each object
# astrodyn writes (SceneUpdate, SceneEntity, and the primitives it fills).
PUBLISHED_REQUIRED = {
    "foxglove.SceneUpdate": ["deletions", "entities"],
    "foxglove.SceneEntityDeletion": ["timestamp", "type", "id"],
    "foxglove.SceneEntity": ["timestamp", "frame_id", "id", "lifetime", "frame_locked", "metadata", "arrows", "cubes",
                             "spheres", "cylinders", "lines", "triangles", "texts", "models"],
    "foxglove.SpherePrimitive": ["pose", "size", "color"],
    "foxglove.CubePrimitive": ["pose", "size", "color"],
    "foxglove.ArrowPrimitive": ["pose", "shaft_length", "shaft_diameter", "head_length", "head_diameter", "color"],
    "foxglove.LinePrimitive": ["type", "pose", "thickness", "scale_invariant", "points", "color", "colors", "indices"],
    "foxglove.Pose": ["position", "orientation"],
    "foxglove.Vector3": ["x", "y", "z"],
    "foxglove.Point3": ["x", "y", "z"],
    "foxglove.Quaternion": ["x", "y", "z", "w"],
    "foxglove.Color": ["r", "g", "b", "a"],
    "foxglove.KeyValuePair": ["key", "value"],
}

_TYPES = {
    "object": lambda x: isinstance(x, dict),
    "array": lambda x: isinstance(x, list),
    "string": lambda x: isinstance(x, str),
    "boolean": lambda x: isinstance(x, bool),
    "integer": lambda x: isinstance(x, int) and not isinstance(x, bool),
    "number": lambda x: isinstance(x, (int, float)) and not isinstance(x, bool),
}


def validate(value, schema: dict, where: str = "$") -> None:
    """Check ``value`` against the JSON Schema keywords used by Foxglove's schemas
    (type, required, properties, items, enum, oneOf of consts, minimum, maximum)."""
    typ = schema.get("type")
    if typ is not None:
        assert _TYPES[typ](value), f"{where}: expected {typ}, got {value!r:.60}"
    if "enum" in schema:
        assert value in schema["enum"], f"{where}: {value!r} not in {schema['enum']}"
    if "oneOf" in schema:
        assert value in [alt["const"] for alt in schema["oneOf"]], f"{where}: {value!r} matches no const"
    if "minimum" in schema:
        assert value >= schema["minimum"], f"{where}: {value} < {schema['minimum']}"
    if "maximum" in schema:
        assert value <= schema["maximum"], f"{where}: {value} > {schema['maximum']}"
    if typ == "object":
        for key in schema.get("required", []):
            assert key in value, f"{where}: missing required {key!r}"
        for key, sub in schema.get("properties", {}).items():
            if key in value:
                validate(value[key], sub, f"{where}.{key}")
    if typ == "array" and "items" in schema:
        for i, item in enumerate(value):
            validate(item, schema["items"], f"{where}[{i}]")


def titled(schema, out=None) -> dict:
    """Every sub-schema with a title, by title."""
    out = {} if out is None else out
    if isinstance(schema, dict):
        if "title" in schema:
            out.setdefault(schema["title"], schema)
        for v in schema.values():
            titled(v, out)
    elif isinstance(schema, list):
        for v in schema:
            titled(v, out)
    return out


def read_back(path: Path) -> dict:
    """Schemas, scene messages, transforms, metadata and first log time, via the mcap reader."""
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        names = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
        scene_schema = [json.loads(s.data) for s in summary.schemas.values() if s.name == "foxglove.SceneUpdate"]
        meta = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        scene, tfs, first = [], {}, None
        for _, channel, msg in reader.iter_messages(log_time_order=True):
            first = msg.log_time if first is None else min(first, msg.log_time)
            if channel.topic == "foxglove/scene":
                scene.append((msg.log_time, json.loads(msg.data)))
            elif channel.topic.endswith("/tf"):
                tfs.setdefault(channel.topic, []).append(json.loads(msg.data))
    return {"names": names, "schema": scene_schema, "scene": scene, "tfs": tfs, "meta": meta, "first": first}


def entities(back: dict) -> dict:
    ents = {}
    for _, upd in back["scene"]:
        for e in upd["entities"]:
            assert e["id"] not in ents, f"entity {e['id']} written twice"
            ents[e["id"]] = e
    return ents


@pytest.fixture(scope="module")
def long_recording(tmp_path_factory):
    """2501 samples per body: more than the 2000-point line limit."""
    path = tmp_path_factory.mktemp("scene") / "sc.mcap"
    sc, res = record(path, LEO_TWO_BODIES.format(name="sc", duration="2500 s", rate="1 Hz"), chunk_size=1 << 20)
    (out,) = export(path, "foxglove", path.parent / "out")
    return read_back(out), sc, res


def test_scene_messages_validate_against_the_declared_schema(long_recording):
    back, _, _ = long_recording
    assert back["names"]["foxglove/scene"] == "foxglove.SceneUpdate"
    (schema,) = back["schema"]
    # the declared schema requires what Foxglove's published schema requires
    declared = titled(schema)
    for title, required in PUBLISHED_REQUIRED.items():
        assert declared[title]["required"] == required, title
    assert back["scene"], "no SceneUpdate message"
    for log_time, upd in back["scene"]:
        validate(upd, schema)
        # written once, at the start, never expiring
        assert log_time == back["first"]
        for e in upd["entities"]:
            assert e["lifetime"] == {"sec": 0, "nsec": 0}
            assert e["timestamp"]["sec"] * 10**9 + e["timestamp"]["nsec"] == back["first"]
    # the validator itself rejects a message missing a required field
    broken = json.loads(json.dumps(back["scene"][0][1]))
    del broken["entities"][0]["frame_locked"]
    with pytest.raises(AssertionError, match="missing required 'frame_locked'"):
        validate(broken, schema)


def test_central_body_sphere_has_the_metadata_radius_in_km(long_recording):
    back, _, _ = long_recording
    central = json.loads(back["meta"]["scenario"]["json"])["central_body"]
    (sphere_entity,) = [e for e in entities(back).values() if e["spheres"]]
    assert sphere_entity["id"] == "central_body/earth" and sphere_entity["frame_id"] == "GCRF"
    (sphere,) = sphere_entity["spheres"]
    # size = diameter in km: 2 * 6378136.3 m / 1000, the same float64 operations -> exact
    assert central["radius"] == 6378136.3
    assert sphere["size"] == {"x": 2 * (central["radius"] / 1e3), "y": 2 * (central["radius"] / 1e3), "z": 2 * (central["radius"] / 1e3)}
    assert sphere["pose"]["position"] == {"x": 0.0, "y": 0.0, "z": 0.0}


def test_orbit_lines_are_the_recorded_positions_in_km(long_recording):
    back, _, res = long_recording
    ents = entities(back)
    n = res.t.size
    assert n == 2501
    colors = []
    for i, name in enumerate(res.orbit_names):
        ent = ents[f"orbit/{name}"]
        assert ent["frame_id"] == "GCRF" and not ent["frame_locked"]
        (line,) = ent["lines"]
        assert line["type"] == 0  # LINE_STRIP
        km = res.r[:, i] / 1e3
        where = {tuple(p): k for k, p in enumerate(km.tolist())}
        kept = [where[(p["x"], p["y"], p["z"])] for p in line["points"]]  # KeyError if a point is not a recorded one
        assert 2 <= len(kept) <= 2000
        assert kept[0] == 0 and kept[-1] == n - 1 and np.all(np.diff(kept) > 0)
        # evenly spread: no gap wider than the ceiling of the mean spacing
        assert np.max(np.diff(kept)) <= int(np.ceil((n - 1) / (len(kept) - 1)))
        np.testing.assert_array_equal([[p[c] for c in "xyz"] for p in line["points"]], km[kept])
        colors.append(tuple(line["color"][c] for c in "rgba"))
    assert len(set(colors)) == len(colors), "each body has its own colour"
    assert all(0.0 <= c <= 1.0 for col in colors for c in col)


def test_attitude_body_gets_axes_in_its_own_frame(long_recording):
    back, _, res = long_recording
    ents = entities(back)
    assert set(ents) == {"central_body/earth", "orbit/leo", "orbit/geo", "axes/leo"}
    axes = ents["axes/leo"]
    assert axes["frame_id"] == "leo" and axes["frame_locked"] is True
    dirs = [_rotate_active([a["pose"]["orientation"][c] for c in "xyzw"], np.array([1.0, 0.0, 0.0])) for a in axes["arrows"]]
    # arrows point along +x, +y, +z of the body frame; 1e-15: the 45 deg quaternion components are rounded (~1 ulp)
    np.testing.assert_allclose(dirs, np.eye(3), atol=1e-15)
    assert [a["color"]["r"] > 0.5 for a in axes["arrows"]] == [True, False, False]  # x red


def test_line_decimation_limits():
    np.testing.assert_array_equal(line_indices(5, 2000), np.arange(5))
    idx = line_indices(10_001, 2000)
    assert idx.size == 2000 and idx[0] == 0 and idx[-1] == 10_000 and np.all(np.diff(idx) > 0)
    assert set(np.diff(idx)) <= {5, 6}  # 10000 / 1999 = 5.0025
    with pytest.raises(ValueError, match="max_points: expected an integer >= 2"):
        line_indices(10, 1)


def test_total_point_budget_is_shared_between_bodies(tmp_path):
    path = tmp_path / "budget.mcap"
    record(path, LEO_TWO_BODIES.format(name="bud", duration="100 s", rate="1 Hz"))
    run = load(path)
    lines = {e["id"]: len(e["lines"][0]["points"])
             for _, _, data in scene_updates(run, max_line_points=80, max_scene_points=100)
             for e in json.loads(data)["entities"] if e["lines"]}
    assert lines == {"orbit/leo": 50, "orbit/geo": 50}  # 100 points shared by two bodies, under the 80 per body
    with pytest.raises(ValueError, match="max_scene_points"):
        scene_updates(run, max_scene_points=0)


ATTITUDE_ONLY = scenario_head("lab", "2 s", "5 Hz") + """
[[bodies]]
name = "spinner"
[bodies.attitude]
inertia = ["4.0e-4 kg m2", "2.5e-4 kg m2", "1.6e-4 kg m2"]
w = ["0.01 rad/s", "10 rad/s", "0 rad/s"]

[[bodies]]
name = "still"
[bodies.attitude]
inertia = ["1 kg m2", "2 kg m2", "3 kg m2"]
w = ["0 rad/s", "0 rad/s", "0 rad/s"]
"""


def test_scene_without_orbits_has_no_lines_but_every_body_frame(tmp_path):
    path = tmp_path / "lab.mcap"
    _, res = record(path, ATTITUDE_ONLY)
    (out,) = export(path, "foxglove", tmp_path / "out")
    back = read_back(out)
    (schema,) = back["schema"]
    for _, upd in back["scene"]:
        validate(upd, schema)
    ents = entities(back)
    assert not any(e["lines"] for e in ents.values())
    assert not any(e["spheres"] for e in ents.values())  # the bodies sit at the origin: no sphere over them
    assert set(ents) == {"axes/spinner", "axes/still"}
    for name in ("spinner", "still"):
        tf = back["tfs"][f"foxglove/{name}/tf"]
        assert len(tf) == res.t.size and {m["child_frame_id"] for m in tf} == {name}
        assert {(m["translation"]["x"], m["translation"]["y"], m["translation"]["z"]) for m in tf} == {(0.0, 0.0, 0.0)}
        assert ents[f"axes/{name}"]["frame_id"] == name


def test_transforms_carry_exactly_the_states_log_times_and_no_made_up_attitude(tmp_path):
    """Far from the epoch (t > 2**53 ns, 104 days) a log time rebuilt from t in float64 s
    can be off by tens of ns: the transforms are stamped, in the file and in the message,
    with exactly the log times of the body's states.  The orbit-only body (geo) gets a
    position-only frame, ``geo/position``, whose axes are the parent's -- never an
    attitude it does not have; the body with an attitude (leo) is the frame ``leo``."""
    path = tmp_path / "far.mcap"
    record(path, LEO_TWO_BODIES.format(name="far", duration="300 d", rate="0.7e-5 Hz"))
    run = load(path)
    (out,) = export(path, "foxglove", tmp_path / "out")
    back = read_back(out)
    with open(out, "rb") as f:
        logged = {}
        for _, channel, msg in make_reader(f).iter_messages():
            if channel.topic.endswith("/tf"):
                logged.setdefault(channel.topic, []).append(msg.log_time)
    for body in ("leo", "geo"):
        att = run.bodies[body].attitude
        states = np.union1d(run.bodies[body].orbit.log_time, att.log_time if att is not None else np.zeros(0, np.uint64))  # Track.log_time: uint64
        assert states.max() - states.min() > 2**53  # the far part is covered
        assert sorted(logged[f"foxglove/{body}/tf"]) == states.tolist(), body
        stamps = [m["timestamp"]["sec"] * 10**9 + m["timestamp"]["nsec"] for m in back["tfs"][f"foxglove/{body}/tf"]]
        assert sorted(stamps) == states.tolist(), body
    assert {m["child_frame_id"] for m in back["tfs"]["foxglove/geo/tf"]} == {"geo/position"}
    assert {m["child_frame_id"] for m in back["tfs"]["foxglove/leo/tf"]} == {"leo"}
