"""Exporting a Foxglove export to Foxglove again (walk F16): the input's ``foxglove/*``
channels were copied and then made again, so the second file held two transforms per body
per instant and the scene twice.  Counted against the source recording's own states."""

from __future__ import annotations

from collections import Counter

from mcap.reader import make_reader

from _recordings import leo_recording
from astrodyn.recording.export import export


def _messages(path) -> list[tuple[str, int, bytes]]:
    """``(topic, log_time, payload)`` of every message of the MCAP file ``path``."""
    with open(path, "rb") as f:
        return [(channel.topic, message.log_time, bytes(message.data))
                for _, channel, message in make_reader(f).iter_messages()]


def test_a_foxglove_export_exported_again_has_one_transform_per_body_per_instant_and_one_scene(tmp_path):
    source = tmp_path / "rx.mcap"
    leo_recording(source, name="rx", duration="30 s", rate="2 Hz")
    (first,) = export(source, "foxglove", tmp_path / "once")
    (second,) = export(first, "foxglove", tmp_path / "twice")

    # each body's instants: the log times of its orbit and attitude states in the source
    instants: dict[str, set[int]] = {}
    for topic, log_time, _ in _messages(source):
        body = topic.split("/")[2]  # astrodyn/<scenario>/<body>/<kind>
        instants.setdefault(body, set()).add(log_time)
    assert sorted(instants) == ["geo", "leo"] and all(len(v) == 61 for v in instants.values())

    once, twice = _messages(first), _messages(second)
    for body, times in instants.items():
        topic = f"foxglove/{body}/tf"
        per_instant = Counter(lt for t, lt, _ in twice if t == topic)
        assert set(per_instant) == times and set(per_instant.values()) == {1}, body
    scene = [m for m in twice if m[0] == "foxglove/scene"]
    assert scene == [m for m in once if m[0] == "foxglove/scene"] and scene
    # the recorded states themselves are copied once, unchanged
    states = sorted(m for m in _messages(source))
    assert sorted(m for m in twice if m[0].startswith("astrodyn/")) == states
    assert Counter(t for t, _, _ in twice) == Counter(t for t, _, _ in once)
