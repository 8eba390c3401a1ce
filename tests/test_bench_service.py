"""astrodyn bench service: a tiny end-to-end run (real processes, loopback Zenoh, MCAP read
back) with zero loss and the table printed; the read-back check itself catches a lost, a
reordered and a duplicated message in a hand-made file."""

from __future__ import annotations

import numpy as np

from astrodyn import messages as m
from astrodyn.bench import service
from astrodyn.recording.writer import McapRecorder

EPOCH_NS = 1_774_008_000_000_000_000


def test_tiny_constellation_runs_without_loss(tmp_path, capsys):
    md = tmp_path / "bench.md"
    rc = service.main(["--bodies", "50", "--duration", "2", "--md", str(md)])
    out = capsys.readouterr().out
    assert rc == 0, out
    assert "| constellation-50 | 50 | 2 | max |" in out
    row = next(line for line in out.splitlines() if line.startswith("| constellation-50"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert cells[7:11] == ["2,100", "0", "0", "yes"]  # expected = 2 kinds x 50 bodies x 21 steps
    text = md.read_text()
    assert text.startswith("# Service benchmark") and "| constellation-50 |" in text


def _write(path, seqs_of_channel):
    with McapRecorder(path, {"name": "c"}, epoch_ns=EPOCH_NS) as rec:
        for key, seqs in seqs_of_channel.items():
            for k in seqs:
                if key.endswith("/orbit"):
                    payload = m.encode_orbit_batch(k / 10, k, "kepler", [[7e6, 0, 0]], [[0, 7.5e3, 0]], 3.986e14)[0]
                else:
                    payload = m.encode_attitude_batch(k / 10, k, "torque_free", [[1.0, 0, 0, 0]], np.zeros((1, 3)))[0]
                rec.write_encoded(key, payload, k / 10, k)


def test_check_recording_counts_loss_and_disorder(tmp_path):
    a, b = m.orbit_key("c", "s0"), m.attitude_key("c", "s0")
    good = tmp_path / "good.mcap"
    _write(good, {a: range(10), b: range(10)})
    assert service.check_recording(good, 2, 10) == {
        "messages": 20, "channels": 2, "lost": 0, "reordered": 0, "extra": 0, "seq_mismatch": 0}
    bad = tmp_path / "bad.mcap"
    _write(bad, {a: [0, 1, 2, 4, 3, 5, 6, 7, 8], b: [0, 1, 2, 3, 4, 5, 6, 7, 8]})  # a: 9 lost, 3/4 swapped
    got = service.check_recording(bad, 2, 10)
    assert got["lost"] == 2 and got["reordered"] == 3 and got["channels"] == 2  # jumps at 4, 3, 5
    missing_channel = service.check_recording(good, 3, 10)
    assert missing_channel["lost"] == 10


def test_scene_config_replaces_size_and_duration():
    from astrodyn.scenario import loads
    from astrodyn.scenario.catalogue import config_path

    template = config_path("constellation-1000").read_text()
    text = service.scene_config(service.Scene("tiny", 6, 3, 1.5), template)
    sc = loads(text)
    assert sc.name == "tiny" and len(sc.bodies) == 6 and sc.n_steps == 16


def test_flood_into_a_small_logger_queue_loses_nothing(tmp_path):
    # 4 samples of queue: the publisher is blocked (BLOCK congestion control) most of the
    # time instead of dropping; the read-back finds every message in order.
    row = service.run_flood(40, 50, 4, tmp_path)
    assert row["ok"], row.get("failure")
    assert row["check"] == {"messages": 4000, "channels": 100, "lost": 0, "reordered": 0, "extra": 0, "seq_mismatch": 0}
    assert row["zero_loss"] and row["logger_missing"] == 0
