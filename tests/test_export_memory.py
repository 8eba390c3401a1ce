"""What ``export`` holds beyond the loaded arrays does not grow with the number of states.

Each OEM / AEM file was built as one list of line strings (and all its epochs as one list
of strings) before a byte was written: about 1.3 kB per state, ten times the loaded
arrays (docs/exports.md, "Memory").  The writers now format and write a chunk of states
at a time.  Measured here in-process with ``tracemalloc`` on a recording of 24,000 states
(one body, orbit and attitude, built directly as a ``Run``: no file to write or read;
tracemalloc makes the writers about 7 times slower, so more would not fit the test's few
seconds), with chunks of 256 rows instead of 16,384: the peak allocated while a writer
runs must stay below the size of the loaded arrays plus a generous cost of one chunk of
rows (2.7 MB here; the whole-file lists took 8 MB, the chunks take 0.3 MB).  CSV was
written row by row before too: its test keeps it so.  The data lines are compared with a
formatting of the states written here (``datetime`` epochs: a UTC span without leap
second, times that are whole microseconds; ``repr`` of the numbers), so every chunk
boundary is crossed.  And the checks of the times still come before the first byte: a
bad time in any chunk refuses the export with nothing written.
"""

from __future__ import annotations

import csv
import io
import math
import tracemalloc
from datetime import datetime, timedelta

import numpy as np
import pytest

from astrodyn.recording import export as ex
from astrodyn.recording.reader import BodyTracks, Run, Track

N = 12_000  #: states per track: 24,000 in all
CHUNK = 256  #: rows per chunk while measured
ROW_BUDGET = 2048  #: bytes one row of a chunk may take while it is formatted (a data line is < 200 characters)
EPOCH = datetime(2026, 3, 20, 12, 0, 0)  # UTC; no leap second within the 25 min below
EPOCH_NS = 1_774_008_000 * 10**9  # 2026-03-20T12:00:00 UTC as POSIX ns


def _run(n: int, name: str = "mem") -> Run:
    """One body ``sat`` with an orbit and an attitude track of ``n`` states each, every
    0.125 s (exact binary fractions: whole microseconds)."""
    rng = np.random.default_rng(1)
    t = np.arange(n) * 0.125
    seq = np.arange(n, dtype=np.int64)
    log_time = (EPOCH_NS + np.arange(n, dtype=np.uint64) * np.uint64(125_000_000)).astype(np.uint64)
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1)[:, None]

    def strings(s: str) -> np.ndarray:
        a = np.empty(n, dtype=object)
        a[:] = s
        return a

    orbit = Track(f"astrodyn/{name}/sat/orbit", "orbit", "astrodyn.Orbit", seq, log_time, {
        "t": t, "model": strings("kepler"), "r": rng.normal(scale=7e6, size=(n, 3)),
        "v": rng.normal(scale=7e3, size=(n, 3)), "mu": np.full(n, 3.986004418e14), "frame": strings("GCRF")})
    attitude = Track(f"astrodyn/{name}/sat/attitude", "attitude", "astrodyn.Attitude", seq.copy(), log_time.copy(),
                     {"t": t.copy(), "model": strings("torque_free"), "q": q, "w": rng.normal(scale=0.1, size=(n, 3))})
    scenario = {"name": name, "epoch": "2026-03-20T12:00:00 UTC", "epoch_scale": "utc"}
    return Run(path=f"{name}.mcap", scenario=scenario, metadata={"scenario": scenario},
               bodies={"sat": BodyTracks("sat", orbit=orbit, attitude=attitude)},
               channels={orbit.topic: orbit, attitude.topic: attitude}, events=[], gaps={}, messages=2 * n,
               truncated=False)


def _array_bytes(run: Run) -> int:
    return sum(a.nbytes for tr in run.channels.values() for a in (tr.seq, tr.log_time, *tr.fields.values()))


def _epoch(t: float) -> str:
    return (EPOCH + timedelta(seconds=t)).strftime("%Y-%m-%dT%H:%M:%S.%f")


@pytest.fixture(scope="module")
def big(tmp_path_factory):
    ex.write_oem(_run(3, "warm"), tmp_path_factory.mktemp("warm"))  # astropy imported, its tables read: not measured
    return _run(N)


@pytest.fixture
def measured(monkeypatch, tmp_path):
    """``call(writer, run)``: the files it wrote (name -> text) and the peak of memory
    allocated while it ran (tracemalloc), with chunks of ``CHUNK`` rows."""
    monkeypatch.setattr(ex, "_CHUNK_ROWS", CHUNK, raising=False)

    def call(writer, run):
        out = tmp_path / writer.__name__
        out.mkdir()
        tracemalloc.start()
        try:
            tracemalloc.reset_peak()
            paths = writer(run, out)
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        return {p.name: p.read_text() for p in paths}, peak

    return call


def _budget(run: Run) -> int:
    """The loaded arrays once over (numbers an export may copy) plus one chunk of rows."""
    return _array_bytes(run) + CHUNK * ROW_BUDGET


def test_oem_memory_is_one_chunk_and_its_lines_are_the_states(big, measured):
    files, peak = measured(ex.write_oem, big)
    assert peak < _budget(big), f"write_oem allocated {peak / 1e6:.1f} MB for {N} states (arrays " \
                                f"{_array_bytes(big) / 1e6:.1f} MB, budget {_budget(big) / 1e6:.1f} MB)"
    text = files["sat.oem"]
    data = text.split("COMMENT position km, velocity km/s\n", 1)[1]
    orbit = big.bodies["sat"].orbit
    r, v = orbit.r / 1000.0, orbit.v / 1000.0
    expected = "".join(f"{_epoch(t)} {' '.join(map(repr, rk))} {' '.join(map(repr, vk))}\n"
                       for t, rk, vk in zip(orbit.t.tolist(), r.tolist(), v.tolist()))
    assert data == expected
    assert f"START_TIME           = {_epoch(0.0)}\nSTOP_TIME            = {_epoch((N - 1) * 0.125)}\n" in text


def test_aem_memory_is_one_chunk_and_its_lines_are_the_states(big, measured):
    files, peak = measured(ex.write_aem, big)
    assert peak < _budget(big), f"write_aem allocated {peak / 1e6:.1f} MB for {N} states (arrays " \
                                f"{_array_bytes(big) / 1e6:.1f} MB, budget {_budget(big) / 1e6:.1f} MB)"
    text = files["sat.aem"]
    assert "ATTITUDE_TYPE        = QUATERNION/ANGVEL\n" in text
    data = text.split("DATA_START\n", 1)[1]
    att = big.bodies["sat"].attitude
    deg = 180.0 / math.pi
    expected = "".join(f"{_epoch(t)} {q[1]!r} {q[2]!r} {q[3]!r} {q[0]!r} {w[0] * deg!r} {w[1] * deg!r} {w[2] * deg!r}\n"
                       for t, q, w in zip(att.t.tolist(), att.q.tolist(), att.w.tolist()))
    assert data == expected + "DATA_STOP\n"


def test_csv_memory_is_one_chunk_and_its_rows_are_the_states(big, measured):
    files, peak = measured(ex.write_csv, big)
    assert peak < _budget(big), f"write_csv allocated {peak / 1e6:.1f} MB for {N} states (arrays " \
                                f"{_array_bytes(big) / 1e6:.1f} MB, budget {_budget(big) / 1e6:.1f} MB)"
    att = big.bodies["sat"].attitude
    rows = list(csv.reader(io.StringIO(files["sat.attitude.csv"])))
    rows = [row for row in rows if not row[0].startswith("#")]
    assert rows[0] == ["t", "seq", "log_time_ns", "model", "q_0", "q_1", "q_2", "q_3", "w_x", "w_y", "w_z"]
    expected = [[repr(t), str(k), str(lt), "torque_free", *map(repr, q), *map(repr, w)]
                for k, (t, lt, q, w) in enumerate(zip(att.t.tolist(), att.log_time.tolist(), att.q.tolist(),
                                                      att.w.tolist()))]
    assert rows[1:] == expected


@pytest.mark.parametrize("times,says", [
    ({700: 1e13}, "seq 700: t = 1e+13 s is 318913-08-08T05:46:40.000000: expected a date of the years 0001-9999"),
    ({300: 1e13, 900: 1e300}, "t from 0 to 1e+300 s: expected times a calendar date can show"),  # wherever it is
    ({900: 112.25}, "seq 900: t = 112.25 s after t = 112.375 s (seq 899): expected times that increase with seq"),
    ({300: -7e10, 900: 5.0}, "seq 300: t = -7e+10 s is -192-01-03T07:33:57.000000: expected a date"),  # before order
])
@pytest.mark.parametrize("writer", [ex.write_oem, ex.write_aem])
@pytest.mark.filterwarnings("ignore:ERFA function")  # erfa's "dubious year" of the bad times
def test_a_bad_time_in_any_chunk_refuses_the_export_before_a_byte_is_written(monkeypatch, tmp_path, writer, times,
                                                                               says):
    monkeypatch.setattr(ex, "_CHUNK_ROWS", CHUNK, raising=False)
    run = _run(1000, "ht")
    for tr in run.channels.values():
        for k, t in times.items():
            tr.fields["t"][k] = t
    with pytest.raises(ex.ExportError) as info:
        writer(run, tmp_path)
    kind = "orbit" if writer is ex.write_oem else "attitude"
    assert f"ht.mcap: astrodyn/ht/sat/{kind}: {says}" in str(info.value)
    assert list(tmp_path.iterdir()) == []
