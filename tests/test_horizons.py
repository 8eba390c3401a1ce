"""Long horizons and extreme legal values (the horizons probe, /work/notes/horizons_report.md).

* F1: a run may record log times up to 2**64 ns (MCAP's uint64); the reader used to count
  every message after 2**63 ns (2262-04-11T23:47:16 UTC) as invalid, so those states
  vanished from ``load`` / ``export`` / the run summary, which said nothing.
* F2: ``merge`` took MCAP's 32-bit ``sequence`` (``seq mod 2**32``) for the step and dropped
  every state after step 2**32 as a "conflict", exit 0.
* F3: orbital elements whose speed is far above 0.1 c (rp = 1e-200 m, e = 1e6) passed
  validation and the propagator emitted NaN.
* F5: an interrupted run's summary gave the real-time factor of the whole scene.

Everything is checked against what was written, read with the ``mcap`` package's own
reader, or against closed forms; the recordings are small and written in-process.
"""

from __future__ import annotations

import csv
import json
import math
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from astrodyn import messages
from astrodyn.recording import McapRecorder, load
from astrodyn.recording.export import export
from astrodyn.recording.merge import merge
from astrodyn.scenario import ScenarioError, loads

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _recordings import LEO_TWO_BODIES, record

INT64_END_NS = 2**63  # 2262-04-11T23:47:16.854775808 UTC


def _raw(path: Path) -> dict[str, list[tuple[int, int, int]]]:
    """topic -> [(log_time, MCAP sequence, payload seq)] in file order, read by the mcap package."""
    out: dict[str, list[tuple[int, int, int]]] = {}
    with open(path, "rb") as f:
        for _, channel, m in make_reader(f).iter_messages(log_time_order=False):
            seq = json.loads(m.data).get("seq") if channel.topic.startswith("astrodyn/") else None
            out.setdefault(channel.topic, []).append((m.log_time, m.sequence, seq))
    return out


@pytest.fixture(scope="module")
def late(tmp_path_factory):
    """The LEO pair, 41 states over 1e7 s from the latest epoch a config allows (2261):
    the last six (from t = 8.75e6 s) lie after 2**63 ns."""
    path = tmp_path_factory.mktemp("late") / "late.mcap"
    text = LEO_TWO_BODIES.format(name="late", duration="1e7 s", rate="4e-6 Hz").replace(
        "2026-03-20T12:00:00 UTC", "2261-12-31T23:59:59 UTC")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # erfa: "dubious year" for dates after ~2200
        sc, _ = record(path, text)
    return path, sc


def test_states_after_2262_are_loaded_and_exported_exactly(late, tmp_path):
    path, sc = late
    raw = _raw(path)
    states = {t: rows for t, rows in raw.items() if t.endswith(("/orbit", "/attitude"))}
    assert len(states) == 3 and all(len(rows) == 41 for rows in states.values())
    assert all(sum(lt >= INT64_END_NS for lt, _, _ in rows) == 6 for rows in states.values())  # the case at hand
    run = load(path)
    assert run.complete and run.invalid == 0, run.incomplete_reason
    for topic, rows in states.items():
        track = run.channels[topic]
        assert track.log_time.dtype == np.uint64
        by_seq = sorted(rows, key=lambda r: r[2])
        assert track.seq.tolist() == [r[2] for r in by_seq]
        assert track.log_time.tolist() == [r[0] for r in by_seq]  # every ns exact, past 2**63 too
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        csv_files = export(path, "csv", tmp_path / "csv")
        (oem,) = [p for p in export(path, "oem", tmp_path / "oem") if p.name.startswith("leo")]
    orbit_csv = next(p for p in csv_files if p.name == "leo.orbit.csv")
    with open(orbit_csv) as f:
        rows = list(csv.DictReader(line for line in f if not line.startswith("#")))
    assert [int(r["log_time_ns"]) for r in rows] == [r[0] for r in sorted(states["astrodyn/late/leo/orbit"],
                                                                           key=lambda r: r[2])]
    data_lines = [ln for ln in oem.read_text().splitlines() if ln[:4].isdigit()]
    assert len(data_lines) == 41 and data_lines[-1].startswith("2262-04-26T17:46:39")  # epoch + 1e7 s
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        (fox,) = export(path, "foxglove", tmp_path / "fox")
    counts = {t: len(rows) for t, rows in _raw(fox).items()}  # copies and transforms agree: one per state
    assert all(counts[t] == 41 for t in (*states, "foxglove/leo/tf", "foxglove/geo/tf")), counts


def test_the_ground_track_runs_on_across_2262(late):
    """Sidereal time from the uint64 log times goes on at the Earth's rate across 2**63 ns
    (an int64 cast wrapped the states after 2262-04-11 to 1677)."""
    from astrodyn.analysis.metrics import gmst_rad

    path, _ = late
    lt = load(path).channels["astrodyn/late/leo/orbit"].log_time
    assert (lt >= INT64_END_NS).sum() == 6
    dt = np.diff(lt).astype(np.float64) / 1e9
    turned = np.mod(np.diff(gmst_rad(lt)), 2 * np.pi)
    expected = np.mod(7.292115855e-5 * dt, 2 * np.pi)  # the Earth's sidereal rate, IAU 1982 (Vallado eq. 3-40)
    assert np.max(np.abs(np.angle(np.exp(1j * (turned - expected))))) < 1e-6


def test_the_run_summary_counts_every_state_and_says_what_the_reader_skipped(late, tmp_path, capsys):
    from astrodyn.service.summary import file_summary, print_summary

    path, sc = late
    rows = file_summary(path, sc, block_messages=17)
    assert {r["body"]: (r.get("orbit_states"), r.get("attitude_states")) for r in rows} == {
        "leo": (41, 41), "geo": (41, None)}
    # a file with one invalid state (not a valid orbit message): the summary must say so
    bad = tmp_path / "bad.mcap"
    with McapRecorder(bad, sc.to_metadata(), epoch_ns=sc.epoch_unix_ns) as rec:
        key = messages.orbit_key(sc.name, "geo")
        for k in range(3):
            msg = messages.orbit_message(float(k), k, "kepler", [4.2e7, 0.0, 0.0], [0.0, 3074.0, 0.0],
                                         sc.central_body.mu, sc.frame)
            payload = messages.encode(msg) if k != 1 else b'{"t":1.0,"seq":1,"r":"nowhere"}'
            rec.write_encoded(key, payload, float(k), k)
    with open(bad, "rb") as f:  # all three are in the file
        assert sum(1 for _ in make_reader(f).iter_messages()) == 3
    rows = file_summary(bad, sc)
    assert {r["body"]: r.get("orbit_states") for r in rows} == {"leo": None, "geo": 2}
    print_summary({"out": str(bad), "wall_s": 1.0, "logger": {"t": 2.0, "reason": "end of run: every expected "
                                                                                   "message recorded"}}, rows, sc)
    out = capsys.readouterr().out
    assert "WARNING: reading the file back skipped 1 invalid messages (1 on astrodyn/late/geo/orbit)" in out, out


def test_an_interrupted_run_gives_the_real_time_factor_of_the_sim_time_reached(capsys):
    from astrodyn.service.summary import print_summary

    sc = loads(LEO_TWO_BODIES.format(name="cut", duration="1e4 s", rate="1 Hz"))
    result = {"out": "cut.partial.mcap", "wall_s": 10.0, "failure": "interrupted by SIGINT at sim t 45 s of 10000 s",
              "interrupted": "SIGINT",
              "logger": {"t": 50.0, "reason": "SIGINT", "stopped_early": {"orbit": {"t": 60.0, "reason": "SIGINT"},
                                                                          "attitude": {"t": 55.0, "reason": "SIGINT"}}}}
    print_summary(result, [], sc)
    out = capsys.readouterr().out
    assert "wall 10.00 s for 50 s of sim time reached (of 10000 s; real-time factor 5.0x)" in out, out  # 50 / 10
    assert "sim t reached 50 s of 10000 s" in out and "orbit stopped early at sim t 60 s" in out, out
    print_summary({**result, "failure": None, "interrupted": None, "logger": {"t": 1e4, "reason": "end of run"}}, [], sc)
    assert "wall 10.00 s for 10000 s of sim time (real-time factor 1000.0x)" in capsys.readouterr().out


# ----------------------------------------------------------------------------- F2: merge


def _write_steps(path: Path, steps, forged: int | None = None) -> None:
    """An orbit channel holding ``steps`` (payload seq = step, t = step / 1000 s), as the
    logger writes it (MCAP sequence = seq mod 2**32); step ``forged`` with other bytes."""
    sc = loads(LEO_TWO_BODIES.format(name="wrap", duration="1e7 s", rate="1000 Hz"))
    key = messages.orbit_key(sc.name, "geo")
    with McapRecorder(path, sc.to_metadata(), epoch_ns=sc.epoch_unix_ns) as rec:
        for k in steps:
            t = k / 1000.0
            r = [4.2e7 + (1.0 if k == forged else 0.0), 0.0, 0.0]
            msg = messages.orbit_message(t, k, "kepler", r, [0.0, 3074.0, 0.0], sc.central_body.mu, sc.frame)
            rec.write_encoded(key, messages.encode(msg), t, k)


def test_merge_keeps_every_state_across_step_2_to_the_32(tmp_path):
    a, b = tmp_path / "a.mcap", tmp_path / "b.mcap"
    _write_steps(a, range(2**32 - 3, 2**32 + 3))
    _write_steps(b, range(2**32, 2**32 + 5))  # a standby's overlapping part
    raw = _raw(a)["astrodyn/wrap/geo/orbit"]
    assert [s for _, s, _ in raw] == [2**32 - 3, 2**32 - 2, 2**32 - 1, 0, 1, 2]  # the writer's uint32 sequence
    out = tmp_path / "m.mcap"
    report = merge([a, b], out)
    got = _raw(out)["astrodyn/wrap/geo/orbit"]
    assert [p for _, _, p in got] == list(range(2**32 - 3, 2**32 + 5))  # each state once, none dropped
    assert (report.messages, report.duplicates, report.conflicts) == (8, 3, 0)


def test_merge_conflicts_are_not_a_silent_success(tmp_path):
    a, b = tmp_path / "a.mcap", tmp_path / "b.mcap"
    _write_steps(a, range(2**32 - 2, 2**32 + 2))
    _write_steps(b, range(2**32 - 2, 2**32 + 2), forged=2**32 + 1)  # another state under seq 2**32 + 1
    out = tmp_path / "m.mcap"
    proc = subprocess.run([sys.executable, "-m", "astrodyn", "merge", str(a), str(b), "--out", str(out)],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 3, proc.stderr
    assert json.loads(proc.stdout)["conflicts"] == 1
    assert "CONFLICTS: 1 states left out (1 on astrodyn/wrap/geo/orbit)" in proc.stderr, proc.stderr
    got = _raw(out)["astrodyn/wrap/geo/orbit"]
    assert [p for _, _, p in got] == list(range(2**32 - 2, 2**32 + 2))  # the first of the two kept, once


# ----------------------------------------------------------------------------- F3: elements


def _elements_scene(size: str, e: float, extra: str = "") -> str:
    return f"""
[scenario]
name = "el"
epoch = "2026-01-01T00:00:00 UTC"
duration = "100 s"
rate = "1 Hz"
[central_body]
name = "earth"
[[bodies]]
name = "b"
[bodies.orbit]
{size}
e = {e}
i = "0 deg"
nu = "0 deg"
{extra}"""


def test_elements_whose_speed_exceeds_a_tenth_of_c_are_refused_naming_body_and_field():
    mu = loads(_elements_scene('a = "7000 km"', 0.0)).central_body.mu
    with pytest.raises(ScenarioError) as info:  # the probe's hype.toml: |v| = sqrt(mu (1 + e) / rp) at nu = 0
        loads(_elements_scene('rp = "1e-200 m"', 1e6))
    speed = math.sqrt(mu * (1 + 1e6)) * 1e100
    msg = str(info.value)
    assert "bodies[0] (b).orbit.rp: expected elements whose speed |v| <= 2.99792e+07 m/s (0.1 c" in msg, msg
    assert f"|v| = {speed / 1e110:.3g}e+110 m/s" in msg, msg
    # a circular orbit's speed is sqrt(mu / a): the limit 0.1 c lies at a = mu / (0.1 c)^2 = 0.4435 m
    a_limit = mu / (0.1 * 299_792_458.0) ** 2
    sc = loads(_elements_scene(f'a = "{a_limit * 1.01!r} m"', 0.0))
    assert np.linalg.norm(sc.bodies[0].orbit.v0) <= 0.1 * 299_792_458.0
    with pytest.raises(ScenarioError, match=r"orbit\.a: expected elements whose speed"):
        loads(_elements_scene(f'a = "{a_limit * 0.99!r} m"', 0.0))


def test_tiny_sizes_are_refused_in_one_line_with_the_right_reason():
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # numpy's overflow RuntimeWarnings used to be printed first
        with pytest.raises(ScenarioError, match=r"orbit\.a: expected elements whose speed"):
            loads(_elements_scene('a = "1e-300 m"', 0.0))
    text = _elements_scene('a = "7000 km"', 0.0).replace('a = "7000 km"\ne = 0.0\ni = "0 deg"\nnu = "0 deg"\n',
                                                          'r = ["1e-300 m", "0 m", "0 m"]\nv = ["0 m/s", "1 m/s", "0 m/s"]\n')
    with pytest.raises(ScenarioError) as info:  # |r| = 1e-300 m is > 0: the message must not say it is not
        loads(text)
    assert "orbit.r: expected |r| >= 1e-100 m" in str(info.value) and "|r| > 0" not in str(info.value)


def test_the_output_step_limit_and_its_message_agree():
    text = _elements_scene('a = "7000 km"', 0.0).replace('duration = "100 s"\nrate = "1 Hz"',
                                                         'duration = "1e7 s"\nrate = "1000 Hz"')
    assert loads(text).n_steps == 10**10 + 1  # duration x rate = 1e10: k = 0 .. 1e10
    with pytest.raises(ScenarioError) as info:
        loads(text.replace('"1e7 s"', '"1.0000001e7 s"'))
    assert "duration x rate <= 1e+10 (at most 10000000001 output steps, t = 0 included)" in str(info.value)
