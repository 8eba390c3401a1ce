"""The live view's per-body stores: trails in float64 rings, recent attitudes (session 13).

``TrailRing`` replaced a ``deque(maxlen=MAX_LINE_POINTS)`` of ``(x, y, z)`` tuples (about
150 bytes a point, 290 MB for a 1000-body scene once full) and ``RecentAttitudes`` an
``OrderedDict`` of log time -> quaternion capped at 64 (about 24 KB a body).  Each is
checked here against a plain Python reference written from its definition: the last N
points appended, a dict of the last N distinct times first put.  The scene's trail points
are checked against the selection the deque-based view made (``round(linspace(0, n - 1,
min(per_body, n)))``, duplicates dropped, over the last ``MAX_LINE_POINTS`` positions in km),
computed here from the positions sent.
"""

from __future__ import annotations

import collections
import random
import tracemalloc

import numpy as np
import pytest

from astrodyn import messages
from astrodyn.recording.foxglove_scene import MAX_LINE_POINTS
from astrodyn.service import viewer
from astrodyn.service.viewer import MAX_LIVE_SCENE_POINTS, RecentAttitudes, TrailRing

BYTES_PER_POINT = 3 * 8  # x, y, z as float64

SCENARIO = "trails"
EPOCH_NS = 1_774_008_000 * 10**9


def _random_points(rng: random.Random, n: int) -> list[tuple[float, float, float]]:
    return [(rng.uniform(-5e4, 5e4), rng.uniform(-5e4, 5e4), rng.uniform(-5e4, 5e4)) for _ in range(n)]


def _append_counts(capacity: int, rng: random.Random) -> list[int]:
    """Below, at and far beyond capacity, exactly N and N + 1 among them."""
    return sorted({0, 1, max(0, capacity - 1), capacity, capacity + 1, 2 * capacity, 2 * capacity + 1,
                   7 * capacity + 3, rng.randrange(0, capacity + 1), rng.randrange(capacity, 10 * capacity + 2)})


@pytest.mark.parametrize("capacity", [1, 2, 3, 31, 32, 33, 100, 257])
def test_ring_holds_exactly_the_last_capacity_points_in_append_order(capacity):
    rng = random.Random(capacity)
    for count in _append_counts(capacity, rng):
        points = _random_points(rng, count)
        ring = TrailRing(capacity)
        for p in points:
            ring.append(p)
        expected = points[-capacity:] if count else []  # the reference: the newest N, oldest first
        assert len(ring) == len(expected) == min(count, capacity)
        got = ring.points()
        assert got.shape == (len(expected), 3) and got.dtype == np.float64
        assert got.tolist() == [list(p) for p in expected]  # exact: a float64 holds a Python float
        if expected:
            indices = [rng.randrange(len(expected)) for _ in range(20)] + [0, len(expected) - 1]
            assert ring.take(indices).tolist() == [list(expected[i]) for i in indices]


def test_ring_matches_a_bounded_deque_after_every_append():
    rng = random.Random(7)
    capacity = 40
    ring, reference = TrailRing(capacity), collections.deque(maxlen=capacity)
    for p in _random_points(rng, 5 * capacity + 11):
        ring.append(p)
        reference.append(p)
        assert ring.points().tolist() == [list(q) for q in reference]


def test_time_order_is_kept_across_the_wrap():
    capacity = 50
    ring = TrailRing(capacity)
    for count in range(1, 4 * capacity + 2):
        ring.append((float(count), 0.0, -float(count)))  # x: the order of arrival
        x = ring.points()[:, 0]
        assert x[-1] == count and x[0] == max(1, count - capacity + 1)
        assert np.all(np.diff(x) == 1.0)


def test_take_refuses_indices_outside_the_points_held():
    ring = TrailRing(10)
    for i in range(4):  # storage for more rows than points held: those rows are not points
        ring.append((i, i, i))
    for bad in ([4], [-1], [0, 9]):
        with pytest.raises(IndexError):
            ring.take(bad)
    assert ring.take([]).shape == (0, 3)
    for bad in (0, -3, 2.5, True):
        with pytest.raises(ValueError):
            TrailRing(bad)
    with pytest.raises((TypeError, ValueError)):
        ring.append((1.0, "x", 2.0))
    assert ring.points().tolist() == [[float(i)] * 3 for i in range(4)]  # a bad point changes nothing


def test_ring_memory_is_capacity_times_three_float64():
    """Bounded by the data: capacity x 3 x 8 bytes a body once full (a deque of tuples of
    Python floats needs over 100 bytes a point), never more before."""
    ring = TrailRing(MAX_LINE_POINTS)
    for i in range(3 * MAX_LINE_POINTS + 1):
        ring.append((i, 2.0 * i, 3.0 * i))
        assert ring.nbytes <= MAX_LINE_POINTS * BYTES_PER_POINT
    assert ring.nbytes == MAX_LINE_POINTS * BYTES_PER_POINT

    # What the allocator was asked for, per full ring (tracemalloc sees numpy's data):
    # the points plus a small constant for the objects (ring, arrays, memoryview).
    rings, n_rings = [], 20
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        for _ring in range(n_rings):
            r = TrailRing(MAX_LINE_POINTS)
            for _point in range(MAX_LINE_POINTS + 5):
                r.append((1.0, 2.0, 3.0))
            rings.append(r)
        per_ring = (tracemalloc.get_traced_memory()[0] - before) / n_rings
    finally:
        tracemalloc.stop()
    data = MAX_LINE_POINTS * BYTES_PER_POINT
    assert data <= per_ring <= data + 1024, per_ring


# --------------------------------------------------------------------------- the scene's trails


def _orbit_payload(t: float, seq: int, r_m: tuple[float, float, float]) -> bytes:
    return messages.encode({"t": t, "seq": seq, "model": "kepler", "r": list(r_m), "v": [0.0, 7.5e3, 0.0],
                            "mu": 3.986004418e14, "frame": "GCRF"}, "orbit")


def _attitude_payload(t: float, seq: int, q: tuple[float, float, float, float]) -> bytes:
    return messages.encode({"t": t, "seq": seq, "model": "torque_free", "q": list(q), "w": [0.0, 0.0, 0.001]},
                           "attitude")


def _reference_selection(positions_km: list[tuple], capacity: int, per_body: int) -> list[dict]:
    """The deque-based view's line points, from its definition: the newest ``capacity``
    positions, then the indices round(linspace(0, n - 1, min(per_body, n))) without repeats."""
    trail = collections.deque(positions_km, maxlen=capacity)
    n = len(trail)
    keep = sorted({int(round(float(x))) for x in np.linspace(0, n - 1, min(per_body, n))})
    return [dict(zip("xyz", trail[i])) for i in keep]


def _feed_and_compare(counts: dict[str, int], capacity: int, rng: random.Random) -> None:
    scene = viewer.LiveScene(EPOCH_NS, {"name": "earth", "radius": 6_378_137.0}, set(counts))
    sent: dict[str, list[tuple]] = {name: [] for name in counts}
    for name, count in counts.items():
        key = messages.orbit_key(SCENARIO, name)
        for seq in range(count):
            r_m = (rng.uniform(-7e6, 7e6), rng.uniform(-7e6, 7e6), rng.uniform(-7e6, 7e6))
            assert scene.update(key, _orbit_payload(0.5 * seq, seq, r_m)) is not None
            sent[name].append((r_m[0] / 1e3, r_m[1] / 1e3, r_m[2] / 1e3))
    built = scene.scene()
    lines = {e["id"].removeprefix("orbit/"): e["lines"][0] for e in built["entities"] if e["lines"]}
    orbiting = [name for name, count in counts.items() if count]
    assert sorted(lines) == sorted(orbiting)
    per_body = max(2, viewer.MAX_LIVE_SCENE_POINTS // len(orbiting))
    for name in orbiting:
        assert lines[name]["points"] == _reference_selection(sent[name], capacity, per_body), name


def test_scene_points_equal_the_deque_selection_at_the_real_limits():
    """11 bodies: 20,000 // 11 = 1818 points each at most, over trails of 2000 (full,
    wrapped or not) and shorter ones."""
    n = MAX_LINE_POINTS
    counts = {"a": 1, "b": 2, "c": 1817, "d": n - 1, "e": n, "f": n + 1, "g": n + 2, "h": 2 * n + 7,
              "i": 1818, "j": 1819, "k": 3 * n - 1}
    assert MAX_LIVE_SCENE_POINTS // len(counts) < n  # the selection does spread the points
    _feed_and_compare(counts, n, random.Random(11))


@pytest.mark.parametrize("seed", range(4))
def test_scene_points_equal_the_deque_selection_for_random_counts(monkeypatch, seed):
    """Small limits (capacity 50, 150 points in all) so that many shapes run fast."""
    rng = random.Random(seed)
    capacity = 50
    monkeypatch.setattr(viewer, "MAX_LINE_POINTS", capacity)  # read when a body is made
    monkeypatch.setattr(viewer, "MAX_LIVE_SCENE_POINTS", 150)
    choices = [0, 1, 2, 3, capacity - 1, capacity, capacity + 1, 2 * capacity, 2 * capacity + 1]
    counts = {f"sat-{i}": rng.choice(choices + [rng.randrange(0, 6 * capacity)]) for i in range(rng.randrange(1, 9))}
    counts["sat-x"] = capacity + 1
    _feed_and_compare(counts, capacity, rng)


# --------------------------------------------------------------------------- recent attitudes


class _ReferenceRecent:
    """The OrderedDict the view used: log time -> xyzw, at most ``capacity``, first put first out."""

    def __init__(self, capacity: int):
        self.capacity, self.d = capacity, collections.OrderedDict()

    def put(self, log_time, xyzw):
        self.d[log_time] = tuple(map(float, xyzw))
        while len(self.d) > self.capacity:
            self.d.popitem(last=False)


@pytest.mark.parametrize("capacity", [1, 2, 5, 64])
def test_recent_attitudes_match_a_capped_ordered_dict(capacity):
    rng = random.Random(capacity)
    recent, reference = RecentAttitudes(capacity), _ReferenceRecent(capacity)
    base = EPOCH_NS
    times = [base + rng.randrange(0, 3 * capacity + 3) for _ in range(8 * capacity + 40)]
    times += [base + 10**9 + i for i in range(2 * capacity)]  # in order, as a stream gives them
    times += [2**70, -5, 2**70, base]  # any int: far beyond int64, negative, a time again
    probes = sorted(set(times)) + [base - 1, 2**71]
    for log_time in times:
        xyzw = (rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-1, 1))
        recent.put(log_time, xyzw)
        reference.put(log_time, xyzw)
        assert len(recent) == len(reference.d)
        for probe in (log_time, *rng.sample(probes, min(len(probes), 12))):
            assert recent.get(probe, "none") == reference.d.get(probe, "none"), probe
    assert all(recent.get(t) == q for t, q in reference.d.items())


def test_a_position_is_turned_by_the_attitude_of_its_own_instant():
    scene = viewer.LiveScene(EPOCH_NS, {"name": "earth", "radius": 6_378_137.0}, {"sat"})
    at_1 = (0.6, 0.8, 0.0, 0.0)  # scalar first, as the messages carry them
    at_2 = (0.0, 0.0, 0.6, 0.8)
    scene.update(messages.attitude_key(SCENARIO, "sat"), _attitude_payload(1.0, 0, at_1))
    scene.update(messages.attitude_key(SCENARIO, "sat"), _attitude_payload(2.0, 1, at_2))
    scene.update(messages.orbit_key(SCENARIO, "sat"), _orbit_payload(1.0, 0, (7e6, 0.0, 0.0)))
    (tf,) = scene.transforms()["transforms"]
    assert tf["rotation"] == {"x": 0.8, "y": 0.0, "z": 0.0, "w": 0.6}  # the attitude at t = 1, not the newest
    assert tf["translation"] == {"x": 7000.0, "y": 0.0, "z": 0.0}
    scene.update(messages.orbit_key(SCENARIO, "sat"), _orbit_payload(3.0, 1, (7e6, 1e3, 0.0)))
    (tf,) = scene.transforms()["transforms"]
    assert tf["rotation"] == {"x": 0.0, "y": 0.6, "z": 0.8, "w": 0.0}  # none at t = 3: the newest
