"""Foxglove scene pieces shared by the export (``astrodyn export --format foxglove``) and the
live view (:mod:`astrodyn.service.viewer`): the JSON Schemas of the well-known Foxglove
message types astrodyn writes, and builders of their messages.

Distances are in **km** (Foxglove's 3D panel works in float32 "metres": an orbit in metres
loses the sub-metre detail and the camera's far plane; read 1 grid unit as 1 km).
Rotations are Foxglove's ``(x, y, z, w)``; astrodyn's Euler parameters ``(e0, e1, e2, e3)``
(scalar first, ``v_body = C(q) v_inertial``) become ``(e1, e2, e3, e0)``, which as
Foxglove's active child-to-parent rotation is ``C(q).T``
(:func:`astrodyn.rotation.quat_to_scalar_last`).  Timestamps are ``{"sec", "nsec"}`` of
the message's log time (ns since the Unix epoch).
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "FRAME_TRANSFORM_SCHEMA", "FRAME_TRANSFORMS_SCHEMA", "SCENE_UPDATE_SCHEMA", "SCENE_TOPIC", "MAX_LINE_POINTS",
    "MAX_SCENE_POINTS", "BODY_COLORS", "line_indices", "color", "entity", "stamp", "frame_transform",
    "central_body_entity", "orbit_line_entity", "axes_entity", "XYZ",
]

XYZ = ("x", "y", "z")
_XYZ = XYZ

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


def _obj(title: str, props: dict, required: list[str] | None = None) -> dict:
    """A JSON Schema object with ``title``, ``properties`` and (default: all) ``required``."""
    return {"title": title, "type": "object", "properties": props,
            "required": list(props) if required is None else required}


_NUM = {"type": "number"}
_VECTOR3 = _obj("foxglove.Vector3", {c: _NUM for c in _XYZ})
_POINT3 = _obj("foxglove.Point3", {c: _NUM for c in _XYZ})
_QUATERNION = _obj("foxglove.Quaternion", {c: _NUM for c in ("x", "y", "z", "w")})
_POSE = _obj("foxglove.Pose", {"position": _VECTOR3, "orientation": _QUATERNION})
_COLOR = _obj("foxglove.Color", {c: _NUM for c in "rgba"})
_TIME = FRAME_TRANSFORM_SCHEMA["properties"]["timestamp"]
_DURATION = {"type": "object", "title": "duration", "properties": {
    "sec": {"type": "integer"}, "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999}}}


def _array(items: dict | None = None) -> dict:
    return {"type": "array", "items": items} if items is not None else {"type": "array"}


#: foxglove.SceneUpdate, JSON Schema: the part of the published schema (foxglove-sdk
#: schemas/jsonschema/SceneUpdate.json) that astrodyn writes, with the same field names,
#: types and ``required`` lists.  The primitives astrodyn never fills (cylinders,
#: triangles, texts, models) are declared as (always empty) arrays; Foxglove picks the
#: decoder by the schema *name*, so this subset is read like the full schema.
SCENE_UPDATE_SCHEMA = _obj("foxglove.SceneUpdate", {
    "deletions": _array(_obj("foxglove.SceneEntityDeletion", {
        "timestamp": _TIME, "type": {"title": "foxglove.SceneEntityDeletionType", "enum": [0, 1]},
        "id": {"type": "string"}})),
    "entities": _array(_obj("foxglove.SceneEntity", {
        "timestamp": _TIME,
        "frame_id": {"type": "string"},
        "id": {"type": "string"},
        "lifetime": _DURATION,
        "frame_locked": {"type": "boolean"},
        "metadata": _array(_obj("foxglove.KeyValuePair", {"key": {"type": "string"}, "value": {"type": "string"}})),
        "arrows": _array(_obj("foxglove.ArrowPrimitive", {
            "pose": _POSE, "shaft_length": _NUM, "shaft_diameter": _NUM, "head_length": _NUM,
            "head_diameter": _NUM, "color": _COLOR})),
        "cubes": _array(_obj("foxglove.CubePrimitive", {"pose": _POSE, "size": _VECTOR3, "color": _COLOR})),
        "spheres": _array(_obj("foxglove.SpherePrimitive", {"pose": _POSE, "size": _VECTOR3, "color": _COLOR})),
        "cylinders": _array(),
        "lines": _array(_obj("foxglove.LinePrimitive", {
            "type": {"title": "foxglove.LineType", "enum": [0, 1, 2],
                     "description": "0 LINE_STRIP, 1 LINE_LOOP, 2 LINE_LIST"},
            "pose": _POSE, "thickness": _NUM, "scale_invariant": {"type": "boolean"},
            "points": _array(_POINT3), "color": _COLOR, "colors": _array(_COLOR),
            "indices": _array({"type": "integer", "minimum": 0})})),
        "triangles": _array(),
        "texts": _array(),
        "models": _array(),
    })),
})



#: foxglove.FrameTransforms: several FrameTransform in one message (the live view's ``foxglove/tf``).
FRAME_TRANSFORMS_SCHEMA = _obj("foxglove.FrameTransforms", {"transforms": _array(FRAME_TRANSFORM_SCHEMA)})

SCENE_TOPIC = "foxglove/scene"
#: Most points of one orbit line, and of all orbit lines together (see :func:`scene_updates`).
MAX_LINE_POINTS = 2000
MAX_SCENE_POINTS = 200_000
#: Body colours (r, g, b), cycled in the order of the bodies: matplotlib's "tab10".
BODY_COLORS = ((0.122, 0.467, 0.706), (1.0, 0.498, 0.055), (0.173, 0.627, 0.173), (0.839, 0.153, 0.157),
               (0.580, 0.404, 0.741), (0.549, 0.337, 0.294), (0.890, 0.467, 0.761), (0.498, 0.498, 0.498),
               (0.737, 0.741, 0.133), (0.090, 0.745, 0.812))
_CENTRAL_COLOR = {"r": 0.20, "g": 0.42, "b": 0.80, "a": 0.55}
_IDENTITY_POSE = {"position": {"x": 0.0, "y": 0.0, "z": 0.0}, "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}}
# Arrow orientations (x, y, z, w) turning the arrow's +x onto the body's x, y, z axis:
# identity, +90 deg about z, -90 deg about y.
_AXIS_ORIENTATIONS = ((0.0, 0.0, 0.0, 1.0), (0.0, 0.0, 0.5 ** 0.5, 0.5 ** 0.5), (0.0, -(0.5 ** 0.5), 0.0, 0.5 ** 0.5))
_AXIS_COLORS = ((0.9, 0.1, 0.1), (0.1, 0.75, 0.1), (0.15, 0.3, 0.95))


def line_indices(n: int, max_points: int = MAX_LINE_POINTS) -> np.ndarray:
    """Sample indices kept for an orbit line of ``n`` recorded positions.

    All of them when ``n <= max_points``; otherwise exactly ``max_points`` indices spread
    evenly over ``0 .. n-1`` (``round(linspace(0, n-1, max_points))``), the first and the
    last sample always kept.
    """
    if not (isinstance(max_points, (int, np.integer)) and max_points >= 2):
        raise ValueError(f"max_points: expected an integer >= 2, got {max_points!r}")
    if n <= max_points:
        return np.arange(n)
    return np.rint(np.linspace(0.0, n - 1.0, int(max_points))).astype(np.int64)


def color(rgb, a: float = 1.0) -> dict:
    return {"r": float(rgb[0]), "g": float(rgb[1]), "b": float(rgb[2]), "a": float(a)}


def entity(stamp: dict, frame_id: str, entity_id: str, frame_locked: bool = False, metadata: dict | None = None,
            **primitives) -> dict:
    """A ``foxglove.SceneEntity`` with every required field; lifetime 0 = never expires."""
    ent = {"timestamp": stamp, "frame_id": frame_id, "id": entity_id, "lifetime": {"sec": 0, "nsec": 0},
           "frame_locked": frame_locked,
           "metadata": [{"key": k, "value": str(v)} for k, v in (metadata or {}).items()]}
    for kind in ("arrows", "cubes", "spheres", "cylinders", "lines", "triangles", "texts", "models"):
        ent[kind] = primitives.pop(kind, [])
    if primitives:  # pragma: no cover - programming error
        raise TypeError(f"unknown primitives {sorted(primitives)}")
    return ent



def stamp(log_time: int) -> dict:
    """Foxglove time ``{"sec", "nsec"}`` of a log time in ns since the Unix epoch."""
    return {"sec": int(log_time) // 10**9, "nsec": int(log_time) % 10**9}


def frame_transform(ts: dict, parent: str, child: str, position_km, rotation_xyzw) -> dict:
    """A ``foxglove.FrameTransform``: the child frame at ``position_km`` in ``parent``,
    turned by ``rotation_xyzw`` (Foxglove order, scalar last)."""
    return {"timestamp": ts, "parent_frame_id": parent, "child_frame_id": child,
            "translation": dict(zip(XYZ, map(float, position_km))),
            "rotation": dict(zip(("x", "y", "z", "w"), map(float, rotation_xyzw)))}


def central_body_entity(ts: dict, frame: str, name: str, radius_km: float) -> dict:
    """The central body as a sphere of radius ``radius_km`` at the origin of ``frame``."""
    size = {"x": 2 * radius_km, "y": 2 * radius_km, "z": 2 * radius_km}
    sphere = {"pose": _IDENTITY_POSE, "size": size, "color": _CENTRAL_COLOR}
    return entity(ts, frame, f"central_body/{name}", metadata={"name": name, "radius_km": repr(radius_km)},
                  spheres=[sphere])


def orbit_line_entity(ts: dict, frame: str, body: str, points_km, rgb, samples: int) -> dict:
    """A body's positions (km, shape (n, 3)) as a 2 px LINE_STRIP in ``frame``; ``samples``
    is how many states the points were chosen from (metadata)."""
    points = [dict(zip(XYZ, map(float, p))) for p in np.asarray(points_km, dtype=float)]
    line = {"type": 0, "pose": _IDENTITY_POSE, "thickness": 2.0, "scale_invariant": True, "points": points,
            "color": color(rgb), "colors": [], "indices": []}
    return entity(ts, frame, f"orbit/{body}", metadata={"body": body, "samples": samples, "points": len(points)},
                  lines=[line])


def axes_entity(ts: dict, body: str, axis_km: float) -> dict:
    """Three arrows of length ``axis_km`` along the x (red), y (green) and z (blue) axes of
    the body's own frame (``frame_id`` = body name, ``frame_locked``): they turn with the
    body's FrameTransform."""
    arrows = [{"pose": {"position": {"x": 0.0, "y": 0.0, "z": 0.0},
                        "orientation": dict(zip(("x", "y", "z", "w"), orient))},
               "shaft_length": 0.8 * axis_km, "shaft_diameter": 0.04 * axis_km,
               "head_length": 0.2 * axis_km, "head_diameter": 0.1 * axis_km, "color": color(c)}
              for orient, c in zip(_AXIS_ORIENTATIONS, _AXIS_COLORS)]
    return entity(ts, body, f"axes/{body}", frame_locked=True, metadata={"body": body, "axes": "x red, y green, z blue"},
                  arrows=arrows)
