"""Exports (CSV, Parquet, CCSDS OEM / AEM, Foxglove copy) read back independently.

The OEM and AEM files are read with a small KVN parser written here (not the exporter's
code), their epochs with ``datetime`` (UTC epoch without leap second in the span, so
calendar arithmetic is exact), and compared with the states the core produced before
they were recorded.  The attitude direction is checked physically: for torque-free
motion the angular momentum ``I w`` (body) mapped to frame A must stay constant, which
holds only if the quaternion is applied in the documented direction.
"""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from datetime import datetime
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from astrodyn.recording import load
from astrodyn.recording.export import ExportError, export, parse_ccsds_epoch, write_aem

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _recordings import LEO_TWO_BODIES, leo_recording, record


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    path = tmp_path_factory.mktemp("export") / "ex.mcap"
    sc, res = leo_recording(path, name="ex", duration="600 s", rate="0.5 Hz")
    return path, sc, res


def parse_kvn(text: str) -> tuple[dict, dict, list[list[str]]]:
    """(header, metadata, data rows) of a one-segment CCSDS KVN ephemeris message."""
    header, meta, rows = {}, {}, []
    section = "header"
    for raw in text.splitlines():
        line = raw.strip()
        if not line or line.startswith("COMMENT"):
            continue
        if line in ("META_START", "META_STOP", "DATA_START", "DATA_STOP"):
            section = {"META_START": "meta", "META_STOP": "data", "DATA_START": "data", "DATA_STOP": "end"}[line]
            continue
        if section in ("header", "meta"):
            key, _, value = line.partition("=")
            (header if section == "header" else meta)[key.strip()] = value.strip()
        elif section == "data":
            rows.append(line.split())
    return header, meta, rows


def _seconds_from(epoch: str, start: datetime) -> float:
    return (datetime.strptime(epoch, "%Y-%m-%dT%H:%M:%S.%f") - start).total_seconds()


def test_oem_parses_back_to_the_recorded_states(recording, tmp_path):
    path, sc, res = recording
    files = export(path, "oem", tmp_path)
    assert sorted(f.name for f in files) == ["geo.oem", "leo.oem"]
    for i, name in enumerate(res.orbit_names):
        header, meta, rows = parse_kvn((tmp_path / f"{name}.oem").read_text())
        assert header["CCSDS_OEM_VERS"] == "3.0" and header["ORIGINATOR"]
        assert meta["OBJECT_NAME"] == name and meta["CENTER_NAME"] == "EARTH"
        assert meta["REF_FRAME"] == "GCRF" and meta["TIME_SYSTEM"] == "UTC"
        assert meta["START_TIME"] == "2026-03-20T12:00:00.000000" and len(rows) == res.t.size
        start = datetime(2026, 3, 20, 12)
        t = np.array([_seconds_from(row[0], start) for row in rows])
        np.testing.assert_array_equal(t, res.t)  # whole seconds: exact in the 1 us format
        state = np.array([[float(x) for x in row[1:]] for row in rows]) * 1e3  # km -> m
        # km written with repr of r/1e3: the round trip r -> r/1e3 -> *1e3 costs <= 2 ulp
        np.testing.assert_allclose(state[:, :3], res.r[:, i], rtol=5e-16, atol=0)
        np.testing.assert_allclose(state[:, 3:], res.v[:, i], rtol=5e-16, atol=1e-18)
    assert meta["STOP_TIME"] == "2026-03-20T12:10:00.000000"


def test_oem_time_system_follows_the_epoch_scale(tmp_path):
    path = tmp_path / "tdb.mcap"
    record(path, LEO_TWO_BODIES.format(name="tdb", duration="10 s", rate="1 Hz").replace(":00 UTC", ":00 TDB"))
    export(path, "oem", tmp_path)
    _, meta, rows = parse_kvn((tmp_path / "leo.oem").read_text())
    # epoch + t stays in the epoch's own scale: TDB 12:00:00 + 10 s = TDB 12:00:10
    assert meta["TIME_SYSTEM"] == "TDB" and rows[0][0] == "2026-03-20T12:00:00.000000" and rows[-1][0] == "2026-03-20T12:00:10.000000"


def _ccsds_dcm_a_to_b(q1, q2, q3, qc):
    """CCSDS 504.0-B-2 quaternion (vector part q1..q3, scalar qc) -> matrix M with v_B = M v_A."""
    return np.array([
        [qc * qc + q1 * q1 - q2 * q2 - q3 * q3, 2 * (q1 * q2 + q3 * qc), 2 * (q1 * q3 - q2 * qc)],
        [2 * (q1 * q2 - q3 * qc), qc * qc - q1 * q1 + q2 * q2 - q3 * q3, 2 * (q2 * q3 + q1 * qc)],
        [2 * (q1 * q3 + q2 * qc), 2 * (q2 * q3 - q1 * qc), qc * qc - q1 * q1 - q2 * q2 + q3 * q3],
    ])


def test_aem_parses_back_with_documented_order_and_direction(recording, tmp_path):
    path, sc, res = recording
    files = export(path, "aem", tmp_path)
    assert [f.name for f in files] == ["leo.aem"]
    text = files[0].read_text()
    header, meta, rows = parse_kvn(text)
    assert header["CCSDS_AEM_VERS"] == "2.0"
    assert meta["ATTITUDE_TYPE"] == "QUATERNION/ANGVEL" and meta["REF_FRAME_A"] == "GCRF" and meta["REF_FRAME_B"] == "SC_BODY_1"
    assert "scalar QC last" in text and len(rows) == res.t.size
    quat = np.array([[float(x) for x in row[1:5]] for row in rows])
    # Q1 Q2 Q3 QC = e1 e2 e3 e0, values unchanged (repr round trip: exact)
    np.testing.assert_array_equal(quat, np.concatenate([res.q[:, 0, 1:], res.q[:, 0, :1]], axis=1))
    # direction: torque-free => H_A = M^T (I w) constant.  |I w| ~ 1e-2; M is built from
    # the file's values to ~1 ulp, so H_A is constant to ~1e-15 relative; 1e-12 leaves room
    # for the exact torque-free solution's own error (elliptic functions, ~1e-14).
    inertia = np.diag([0.03, 0.035, 0.01])
    h_a = np.array([_ccsds_dcm_a_to_b(*qk).T @ (inertia @ wk) for qk, wk in zip(quat, res.w[:, 0])])
    scale = np.linalg.norm(h_a[0])
    assert np.max(np.abs(h_a - h_a[0])) < 1e-12 * scale
    # ... and the other direction would not be constant (the check can fail)
    h_wrong = np.array([_ccsds_dcm_a_to_b(*qk) @ (inertia @ wk) for qk, wk in zip(quat, res.w[:, 0])])
    assert np.max(np.abs(h_wrong - h_wrong[0])) > 1e-3 * scale


def test_aem_rates_parse_back_in_deg_per_s_in_body_axes(recording, tmp_path):
    path, _, res = recording
    (aem,) = export(path, "aem", tmp_path)
    text = aem.read_text()
    _, meta, rows = parse_kvn(text)
    # CCSDS 504.0-B-2 table 4-4: QUATERNION/ANGVEL = epoch Q1 Q2 Q3 QC ANGVEL_X ANGVEL_Y ANGVEL_Z,
    # ANGVEL_FRAME (sec. 4.2.3) names the frame of the rate components
    assert meta["ATTITUDE_TYPE"] == "QUATERNION/ANGVEL" and meta["ANGVEL_FRAME"] == meta["REF_FRAME_B"] == "SC_BODY_1"
    assert {len(row) for row in rows} == {8} and "deg/s" in text
    rates = np.array([[float(x) for x in row[5:8]] for row in rows])
    # deg/s -> rad/s here with pi/180: two roundings (w * 180/pi written with repr, read
    # back * pi/180) of <= 1 ulp each, relative whatever the magnitude: 1e-15 ~ 4.5 ulp
    np.testing.assert_allclose(rates * (np.pi / 180.0), res.w[:, 0], rtol=1e-15, atol=0)
    # units: 0.3 rad/s about y is 17.19 deg/s (not 0.3 rad/s, not 0.3/2pi rev/s)
    assert abs(rates[0, 1] - 17.188733853924696) < 1e-12


def _skew(w):
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def _euler_step_errors(quat, rates_deg, dt, stride):
    """max over k of |M(t + stride dt) - (I - [w x] stride dt) M(t)| for the CCSDS matrices
    M (v_B = M v_A) and w of B relative to A in B axes (dM/dt = -[w x] M), and the same
    with the sign of w flipped."""
    right, wrong = 0.0, 0.0
    for k in range(len(quat) - stride):
        m0, m1 = _ccsds_dcm_a_to_b(*quat[k]), _ccsds_dcm_a_to_b(*quat[k + stride])
        w = rates_deg[k] * (np.pi / 180.0)
        h = stride * dt
        right = max(right, np.max(np.abs(m1 - (np.eye(3) - _skew(w) * h) @ m0)))
        wrong = max(wrong, np.max(np.abs(m1 - (np.eye(3) + _skew(w) * h) @ m0)))
    return right, wrong


SPIN_Z = LEO_TWO_BODIES.split("[[bodies]]")[0] + """
[[bodies]]
name = "spin-z"
[bodies.attitude]
q = [1, 0, 0, 0]
w = ["0 rad/s", "0 rad/s", "0.2 rad/s"]
inertia = ["0.03 kg m2", "0.035 kg m2", "0.01 kg m2"]
"""


@pytest.mark.parametrize("body", ["spin-z", "tumbler"])
def test_aem_rates_propagate_the_written_quaternion(tmp_path, body):
    """Integrating the written quaternion with the written rates over one sample gives the
    next written quaternion to O(dt^2): the rates are in the right frame, sign and unit."""
    path = tmp_path / "spin.mcap"
    toml = SPIN_Z.format(name="spin", duration="20 s", rate="1 Hz")
    if body == "tumbler":
        toml = toml.replace('"0 rad/s", "0 rad/s", "0.2 rad/s"', '"0.05 rad/s", "0.02 rad/s", "0.2 rad/s"')
    record(path, toml)
    (aem,) = export(path, "aem", tmp_path)
    _, meta, rows = parse_kvn(aem.read_text())
    assert meta["ATTITUDE_TYPE"] == "QUATERNION/ANGVEL"
    quat = np.array([[float(x) for x in row[1:5]] for row in rows])
    rates = np.array([[float(x) for x in row[5:8]] for row in rows])
    dt = 1.0
    spin = np.max(np.linalg.norm(rates, axis=1)) * np.pi / 180.0  # rad/s
    if body == "spin-z":
        # pure spin about z: Q3 = sin(w t / 2), QC = cos(w t / 2) with w = +0.2 rad/s (A -> B rotation)
        t = np.arange(len(rows)) * dt
        np.testing.assert_allclose(quat, np.stack([0 * t, 0 * t, np.sin(0.1 * t), np.cos(0.1 * t)], axis=1), atol=1e-14)
        np.testing.assert_allclose(rates, np.tile([0.0, 0.0, 0.2 * 180 / np.pi], (len(rows), 1)), rtol=1e-15, atol=0)
    err1, wrong1 = _euler_step_errors(quat, rates, dt, 1)
    err2, _ = _euler_step_errors(quat, rates, dt, 2)
    # an Euler step of dM/dt = -[w x] M errs by about (w dt)^2 / 2 (plus dw/dt dt^2 / 2, small
    # here); the wrong sign errs by about 2 w dt
    assert err1 < (spin * dt) ** 2
    assert wrong1 > spin * dt
    # ... and the error is second order: doubling the step multiplies it by ~4
    assert 3.0 < err2 / err1 < 5.0


def test_aem_without_rates_writes_plain_quaternions(recording, tmp_path):
    path, _, res = recording
    for case in ("missing", "nan"):
        run = load(path)
        fields = run.bodies["leo"].attitude.fields
        if case == "missing":
            del fields["w"]
        else:
            fields["w"][3, 1] = np.nan  # one message without a usable rate
        out = tmp_path / case
        out.mkdir()
        (aem,) = write_aem(run, out)
        text = aem.read_text()
        _, meta, rows = parse_kvn(text)
        assert meta["ATTITUDE_TYPE"] == "QUATERNION" and "ANGVEL_FRAME" not in meta and "ANGVEL" not in text
        assert {len(row) for row in rows} == {5}
        np.testing.assert_array_equal([[float(x) for x in row[1:]] for row in rows],
                                      np.concatenate([res.q[:, 0, 1:], res.q[:, 0, :1]], axis=1))


def test_csv_round_trip_is_exact(recording, tmp_path):
    path, sc, res = recording
    files = export(path, "csv", tmp_path)
    assert sorted(f.name for f in files) == ["geo.orbit.csv", "leo.attitude.csv", "leo.orbit.csv"]
    with open(tmp_path / "leo.orbit.csv") as f:
        lines = f.read().splitlines()
    head = dict(line[2:].split(": ", 1) for line in lines if line.startswith("# "))
    rows = list(csv.DictReader(line for line in lines if not line.startswith("#")))
    assert head["epoch"] == sc.epoch and head["time_scale"] == sc.epoch_scale.upper()
    assert head["frame"].startswith("GCRF") and "r_x=m" in head["units"] and "v_z=m/s" in head["units"]
    assert len(rows) == res.t.size
    assert [int(r["seq"]) for r in rows] == list(range(res.t.size))
    np.testing.assert_array_equal([float(r["t"]) for r in rows], res.t)
    r = np.array([[float(row[f"r_{c}"]) for c in "xyz"] for row in rows])
    v = np.array([[float(row[f"v_{c}"]) for c in "xyz"] for row in rows])
    np.testing.assert_array_equal(r, res.r[:, 0])
    np.testing.assert_array_equal(v, res.v[:, 0])
    assert {row["model"] for row in rows} == {"kepler"} and {row["frame"] for row in rows} == {"GCRF"}
    epoch_ns = sc.epoch_unix_ns
    assert [int(row["log_time_ns"]) for row in rows] == [epoch_ns + round(t * 1e9) for t in res.t]
    with open(tmp_path / "leo.attitude.csv") as f:
        lines = f.read().splitlines()
    assert any(line.startswith("# quaternion: q_0 q_1 q_2 q_3 = Euler parameters (e0, e1, e2, e3), scalar FIRST")
               for line in lines)
    rows = list(csv.DictReader(line for line in lines if not line.startswith("#")))
    q = np.array([[float(row[f"q_{i}"]) for i in range(4)] for row in rows])
    np.testing.assert_array_equal(q, res.q[:, 0])


def sc_epoch(path) -> str:
    """The scenario epoch string as stored in the file's metadata (read with the plain mcap reader)."""
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        for meta in make_reader(f).iter_metadata():
            if meta.name == "scenario":
                return meta.metadata["epoch"]
    raise AssertionError("no scenario metadata")


def test_parquet_round_trip_or_clear_error(recording, tmp_path, monkeypatch):
    path, _, res = recording
    try:
        import pyarrow.parquet as pq
    except ImportError:
        with pytest.raises(ExportError, match=r"needs the optional package pyarrow: pip install 'astrodyn\[parquet\]'"):
            export(path, "parquet", tmp_path)
        return
    export(path, "parquet", tmp_path)
    table = pq.read_table(tmp_path / "leo.orbit.parquet")
    tab = table.to_pydict()
    np.testing.assert_array_equal(np.array([tab[f"r_{c}"] for c in "xyz"]).T, res.r[:, 0])
    meta = {k.decode(): v.decode() for k, v in table.schema.metadata.items()}
    assert meta["astrodyn.epoch"] == sc_epoch(path) and meta["astrodyn.frame"].startswith("GCRF")
    assert table.schema.field("r_x").metadata == {b"unit": b"m"}
    assert table.schema.field("v_y").metadata == {b"unit": b"m/s"}
    assert table.schema.field("t").metadata == {b"unit": b"s"}


def test_parquet_without_pyarrow_names_the_extra(recording, tmp_path, monkeypatch):
    path, _, _ = recording
    monkeypatch.setitem(sys.modules, "pyarrow", None)  # import pyarrow -> ImportError
    with pytest.raises(ExportError, match="pyarrow"):
        export(path, "parquet", tmp_path)


def test_ccsds_day_of_year_epochs_are_converted():
    doy = parse_ccsds_epoch("2026-079T12:00:00.5")
    cal = parse_ccsds_epoch("2026-03-20T12:00:00.5")
    assert datetime.strptime("2026-079", "%Y-%j").date().isoformat() == "2026-03-20"  # independent
    assert abs((doy - cal).sec) < 1e-9 and doy.isot == "2026-03-20T12:00:00.500"
    assert parse_ccsds_epoch("2026-001T00:00:00Z", "tdb").scale == "tdb"
    with pytest.raises(ValueError, match="epoch: expected a CCSDS date"):
        parse_ccsds_epoch("20 March 2026")


def _rotate_active(xyzw, v):
    """Hamilton active rotation of v by the unit quaternion (x, y, z, w) (written here)."""
    x, y, z, w = xyzw
    u = np.array([x, y, z])
    return v + 2 * w * np.cross(u, v) + 2 * np.cross(u, np.cross(u, v))


def test_foxglove_copy_has_frame_transforms_in_km_and_body_to_inertial(recording, tmp_path):
    path, _, res = recording
    (out,) = export(path, "foxglove", tmp_path)
    with open(out, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        names = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
        counts = {c.topic: summary.statistics.channel_message_counts[c.id] for c in summary.channels.values()}
        tf = [json.loads(m.data) for _, _, m in reader.iter_messages(topics=["foxglove/leo/tf"], log_time_order=True)]
    assert names["foxglove/leo/tf"] == "foxglove.FrameTransform" and names["foxglove/geo/tf"] == "foxglove.FrameTransform"
    assert names["astrodyn/ex/leo/orbit"] == "astrodyn.OrbitState" and counts["astrodyn/ex/leo/orbit"] == res.t.size
    assert len(tf) == res.t.size and tf[0]["parent_frame_id"] == "GCRF" and tf[0]["child_frame_id"] == "leo"
    trans = np.array([[m["translation"][c] for c in "xyz"] for m in tf])
    np.testing.assert_allclose(trans * 1e3, res.r[:, 0], rtol=5e-16)
    # rotation maps body components to inertial ones: H_inertial = R (I w) is constant
    inertia = np.diag([0.03, 0.035, 0.01])
    h = np.array([_rotate_active([m["rotation"][c] for c in "xyzw"], inertia @ w) for m, w in zip(tf, res.w[:, 0])])
    assert np.max(np.abs(h - h[0])) < 1e-12 * np.linalg.norm(h[0])  # same reasoning as the AEM test


def test_export_errors_are_clear(tmp_path, recording):
    bad = tmp_path / "bad.mcap"
    bad.write_text("not mcap")
    proc = subprocess.run([sys.executable, "-m", "astrodyn.recording.export", str(bad), "--format", "csv", "--out", str(tmp_path)],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 1 and "not an MCAP file" in proc.stderr and "Traceback" not in proc.stderr
    only_orbits = tmp_path / "orb.mcap"
    record(only_orbits, LEO_TWO_BODIES.format(name="orb", duration="4 s", rate="1 Hz").split("[bodies.attitude]")[0]
           + LEO_TWO_BODIES.split('inertia = ["0.03 kg m2", "0.035 kg m2", "0.01 kg m2"]')[1])
    with pytest.raises(ExportError, match="no attitude channels to export as aem"):
        export(only_orbits, "aem", tmp_path / "aem")
    with pytest.raises(ExportError, match="format: expected one of"):
        export(recording[0], "xlsx", tmp_path)


def _recording_with_one_time(path: Path, step: int, t_at_step: float) -> None:
    """The LEO pair of LEO_TWO_BODIES for 20 s at 1 Hz, written as the logger would, except
    that the states of ``step`` say ``t = t_at_step`` (a hostile or corrupt file: the
    payloads are valid messages, the log times those of the real steps)."""
    from astrodyn import messages
    from astrodyn.recording import McapRecorder
    from astrodyn.scenario import loads
    from astrodyn.simulate import simulate

    sc = loads(LEO_TWO_BODIES.format(name="ht", duration="20 s", rate="1 Hz"))
    res = simulate(sc)
    with McapRecorder(path, sc.to_metadata(), epoch_ns=sc.epoch_unix_ns) as rec:
        for k, t in enumerate(res.t):
            t = float(t)
            said = t_at_step if k == step else t
            for i, name in enumerate(res.orbit_names):
                msg = messages.orbit_message(said, k, "kepler", res.r[k, i], res.v[k, i], sc.central_body.mu, sc.frame)
                rec.write_encoded(messages.orbit_key(sc.name, name), messages.encode(msg), t, k, log_time=rec.log_time(t))
            for i, name in enumerate(res.attitude_names):
                msg = messages.attitude_message(said, k, "torque_free", res.q[k, i], res.w[k, i])
                rec.write_encoded(messages.attitude_key(sc.name, name), messages.encode(msg), t, k,
                                  log_time=rec.log_time(t))


@pytest.mark.parametrize("fmt", ["oem", "aem"])
@pytest.mark.parametrize("t_at_step,says", [
    (1e13, "seq 10: t = 1e+13 s is 318913-08-08T05:46:40.000000: expected a date of the years 0001-9999"),
    (-7e10, "seq 10: t = -7e+10 s is "),  # before year 1
    (5.0, "seq 10: t = 5 s after t = 9 s (seq 9): expected times that increase with seq"),
])
def test_ccsds_export_refuses_times_no_ccsds_file_can_hold(tmp_path, fmt, t_at_step, says):
    """One state of a (hostile) recording at t = 1e13 s was written as the epoch
    318913-08-08T05:46:40 (CCSDS epochs have four-digit years), and one at t = 5 s between
    9 and 11 s as an out-of-order data line; a CCSDS reader rejects both files.  Now the
    export fails naming the channel, the seq and the time, and writes nothing."""
    src = tmp_path / "odd.mcap"
    _recording_with_one_time(src, 10, t_at_step)
    out = tmp_path / fmt
    with pytest.raises(ExportError) as info:
        export(src, fmt, out)
    message = str(info.value)
    kind = "orbit" if fmt == "oem" else "attitude"
    assert f"astrodyn/ht/leo/{kind}: {says}" in message, message
    assert not out.exists() or not any(out.iterdir())
