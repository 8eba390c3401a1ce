"""``astrodyn analyze`` and ``astrodyn export`` on hostile recordings (probe F, findings F3.1-F3.8).

Each recording is written here with the plain ``mcap`` writer (a few dozen states, closed
forms: a circular Kepler orbit, a spin about a principal axis), so the tests check the
tools against the recording's contract (docs/architecture.md, "Messages and MCAP": ``seq``
is the output step index, one message per seq, ``t`` increasing with it), the exit-status
table of docs/exports.md, and physics computed here (an energy with the J2 potential, a
constant inertial angular momentum), never against the tools' own output.
"""

from __future__ import annotations

import csv
import json
import math
import warnings
from pathlib import Path

import numpy as np
import pytest
from mcap.writer import Writer
from scipy.integrate import solve_ivp

from astrodyn.analysis import analyze, figures as report_figures, main as analyze_main
from astrodyn.recording import RecordingError, load
from astrodyn.recording.export import main as export_main

MU = 3.986004418e14  # m^3/s^2
R_E = 6378136.3  # m, the J2 reference radius
J2 = 1.0826261738522227e-3
EPOCH_NS = 1_774_008_000 * 10**9  # 2026-03-20T12:00:00 UTC, POSIX ns
NAME = "hz"
INERTIA = [[3.0, 0.0, 0.0], [0.0, 4.0, 0.0], [0.0, 0.0, 5.0]]  # kg m^2


def _scenario(orbit_model: str = "kepler", degree: int = 0) -> dict:
    """The ``scenario`` metadata record: what analyze reads the central body and the inertia from."""
    config = {"name": NAME, "epoch": "2026-03-20T12:00:00 UTC", "epoch_scale": "utc",
              "central_body": {"name": "earth", "mu": MU, "radius": R_E, "j": [J2], "frame": "GCRF"},
              "bodies": [{"name": "sat", "orbit": {"model": orbit_model, "degree": degree, "perturbers": []},
                          "attitude": {"model": "torque_free", "inertia": INERTIA}}]}
    return {"name": NAME, "epoch": "2026-03-20T12:00:00 UTC", "epoch_scale": "utc", "json": json.dumps(config)}


def _write(path: Path, channels: dict[str, list], scenario: dict | None = None) -> Path:
    """An MCAP file of ``channels`` (topic -> payloads, each a dict written as JSON or raw
    bytes), message k of each channel logged k seconds after the epoch."""
    with open(path, "wb") as f:
        w = Writer(f)
        w.start(profile="", library="hostile-test")
        if scenario is not None:
            w.add_metadata("scenario", scenario)
        schema = w.register_schema(name="any", encoding="jsonschema", data=b"{}")
        for topic, payloads in channels.items():
            channel = w.register_channel(topic=topic, message_encoding="json", schema_id=schema)
            for k, payload in enumerate(payloads):
                data = payload if isinstance(payload, bytes) else json.dumps(payload).encode()
                w.add_message(channel, log_time=EPOCH_NS + k * 10**9, publish_time=EPOCH_NS + k * 10**9, data=data,
                              sequence=k)
        w.finish()
    return path


def _circular(n: int, radius: float = 7.0e6) -> list[dict]:
    """Orbit messages of a circular Kepler orbit, one per second (closed form)."""
    rate = math.sqrt(MU / radius**3)
    out = []
    for k in range(n):
        c, s = math.cos(rate * k), math.sin(rate * k)
        out.append({"t": float(k), "seq": k, "model": "kepler", "r": [radius * c, radius * s, 0.0],
                    "v": [-radius * rate * s, radius * rate * c, 0.0], "mu": MU, "frame": "GCRF"})
    return out


def _quaternion(c: np.ndarray) -> list[float]:
    """Euler parameters (e0, e1, e2, e3) of a rotation matrix ``c`` (v_body = c v_inertial,
    c = (e0^2 - e.e) I + 2 e e^T - 2 e0 [e x], Baruh ch. 7), by Shepperd's method."""
    tr = np.trace(c)
    k = int(np.argmax([tr, c[0, 0], c[1, 1], c[2, 2]]))
    if k == 0:
        e0 = math.sqrt(1 + tr) / 2
        e = [(c[1, 2] - c[2, 1]) / (4 * e0), (c[2, 0] - c[0, 2]) / (4 * e0), (c[0, 1] - c[1, 0]) / (4 * e0)]
        return [e0, *e]
    i, j, m = k - 1, k % 3, (k + 1) % 3
    e = [0.0, 0.0, 0.0]
    e[i] = math.sqrt(1 + 2 * c[i, i] - tr) / 2
    e0 = (c[j, m] - c[m, j]) / (4 * e[i])
    e[j] = (c[i, j] + c[j, i]) / (4 * e[i])
    e[m] = (c[i, m] + c[m, i]) / (4 * e[i])
    return [e0, *e] if e0 >= 0 else [-e0, *(-x for x in e)]


def _spin(n: int, rate: float = 0.2, tilt: float = 0.7, norms=None) -> list[dict]:
    """Attitude messages of a torque-free spin about principal axis 3 tilted by ``tilt`` rad
    about inertial axis 1: C(t) = R3(w t) R1(tilt), w = (0, 0, rate) rad/s constant, so T
    and H_i = C^T I w = R1(tilt)^T (0, 0, I3 rate) are constant; ``norms``: |q| of each."""
    ca, sa = math.cos(tilt), math.sin(tilt)
    r1 = np.array([[1.0, 0.0, 0.0], [0.0, ca, sa], [0.0, -sa, ca]])
    out = []
    for k in range(n):
        c, s = math.cos(rate * k), math.sin(rate * k)
        q = np.array(_quaternion(np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]]) @ r1))
        q *= 1.0 if norms is None else norms[k] / np.linalg.norm(q)
        out.append({"t": float(k), "seq": k, "model": "torque_free", "q": q.tolist(), "w": [0.0, 0.0, rate]})
    return out


def _topic(body: str, kind: str) -> str:
    return f"astrodyn/{NAME}/{body}/{kind}"


def _csv_rows(path: Path) -> list[dict]:
    with open(path, newline="") as f:
        return list(csv.DictReader(line for line in f if not line.startswith("#")))


# ------------------------------------------------------------------ F3.1: t that jumps within a channel


def test_a_time_that_goes_back_is_named_by_analyze_and_csv_and_refused_by_oem(tmp_path, capsys):
    """The contract: t increases with seq.  seq 5 says t = 1e6 s, seq 6 t = -5 s (log times
    normal).  analyze warns naming seq 6 and its report's time span is the extent of t (the
    figures' axis), CSV export warns and keeps the rows as recorded, OEM refuses naming it."""
    orbit = _circular(12)
    orbit[5]["t"], orbit[6]["t"] = 1.0e6, -5.0
    path = _write(tmp_path / "tjump.mcap", {_topic("sat", "orbit"): orbit}, _scenario())
    said_t = [m["t"] for m in orbit]

    assert analyze_main([str(path), "--out", str(tmp_path / "report"), "--figures-for", "0", "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "t does not increase with seq" in err and "seq 6: t = -5 s after t = 1e+06 s (seq 5)" in err, err
    report = json.loads((tmp_path / "report" / "report.json").read_text())
    assert report["bodies"]["sat"]["orbit"]["t_span_s"] == max(said_t) - min(said_t)
    assert report["sequence"][_topic("sat", "orbit")]["t_not_increasing"] == 1
    assert "t does not increase with seq" in (tmp_path / "report" / "report.md").read_text()

    assert export_main([str(path), "--format", "csv", "--out", str(tmp_path / "csv")]) == 0
    err = capsys.readouterr().err
    assert "t does not increase with seq" in err and "seq 6" in err and "exported as recorded" in err, err
    rows = _csv_rows(tmp_path / "csv" / "sat.orbit.csv")
    assert [float(r["t"]) for r in rows] == said_t and [int(r["seq"]) for r in rows] == list(range(12))

    assert export_main([str(path), "--format", "oem", "--out", str(tmp_path / "oem")]) == 1
    err = capsys.readouterr().err
    assert "seq 6: t = -5 s after t = 1e+06 s (seq 5): expected times that increase with seq" in err, err


# ------------------------------------------------------------------ F3.2 / F3.3: nothing to analyse or export


def test_a_file_with_nothing_to_analyse_is_exit_1_like_export(tmp_path, capsys):
    """docs/exports.md, exit status 1: an input with nothing to analyse or export.  A file of
    the MCAP magic alone, and one of another tool's channels only: analyze says so and exits
    1, as export does; no report directory is left behind."""
    magic = tmp_path / "magic.mcap"
    magic.write_bytes(b"\x89MCAP0\r\n")
    foreign = _write(tmp_path / "foreign.mcap", {"/robot/odom": [{"x": 1.5}, {"x": 2.5}]})
    for path in (magic, foreign):
        out = tmp_path / f"{path.stem}-report"
        assert analyze_main([str(path), "--out", str(out), "--quiet"]) == 1
        err = capsys.readouterr().err
        assert "error" in err and "nothing to analyse" in err, err
        assert not out.exists()
        with pytest.raises(RecordingError, match="nothing to analyse"):
            analyze(path, out)
    assert "/robot/odom" in str(pytest.raises(RecordingError, analyze, foreign, tmp_path / "r").value)
    assert export_main([str(magic), "--format", "csv", "--out", str(tmp_path / "csv")]) == 1


def test_every_message_rejected_says_why_and_is_exit_1(tmp_path, capsys):
    """Every payload carries one field more than its message definition: nothing is valid.
    Both tools name the first rejection (the extra field) and how many messages it hit, and
    exit 1; export writes no header-only CSVs."""
    orbit = [m | {"extra_field": "hello"} for m in _circular(6)]
    spin = [m | {"extra_field": "hello"} for m in _spin(4)]
    path = _write(tmp_path / "extra.mcap", {_topic("sat", "orbit"): orbit, _topic("sat", "attitude"): spin},
                  _scenario())
    out = tmp_path / "csv"
    assert export_main([str(path), "--format", "csv", "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert "nothing to export" in err and "extra_field" in err, err
    assert "10 invalid messages skipped" in err and "(6 messages rejected for this reason)" in err, err
    assert not out.exists() or not list(out.glob("*.csv"))
    assert analyze_main([str(path), "--out", str(tmp_path / "report"), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert "nothing to analyse" in err and "extra_field" in err, err


def test_a_channel_whose_every_message_was_rejected_gets_no_csv(tmp_path, capsys):
    """The orbit is valid, every attitude message has an extra field: the CSV export writes
    the orbit's file, none for the attitude (a header without rows would read as a channel
    recorded empty), and its warning names the channel left out and why."""
    spin = [m | {"extra_field": 1} for m in _spin(4)]
    path = _write(tmp_path / "half.mcap", {_topic("sat", "orbit"): _circular(5), _topic("sat", "attitude"): spin},
                  _scenario())
    assert export_main([str(path), "--format", "csv", "--out", str(tmp_path / "csv")]) == 0
    err = capsys.readouterr().err
    assert sorted(p.name for p in (tmp_path / "csv").glob("*.csv")) == ["sat.orbit.csv"]
    assert f"no file for the 1 channel whose every message was rejected: {_topic('sat', 'attitude')}" in err, err
    assert "extra_field" in err, err
    assert len(_csv_rows(tmp_path / "csv" / "sat.orbit.csv")) == 5


# ------------------------------------------------------------------ F3.4: the list of channels is not cut silently


def test_invalid_messages_on_many_channels_say_how_many_more(tmp_path):
    """Seven channels each with one invalid message (a string t): the line names five and
    says "and 2 more channels"; the counts it gives plus the rest add up to the total."""
    channels = {}
    for b in range(7):
        good = _circular(2)
        channels[_topic(f"b{b}", "orbit")] = good + [good[1] | {"seq": 2, "t": "soon"}]
    run = load(_write(tmp_path / "many.mcap", channels, _scenario()))
    assert run.invalid == 7
    reason = run.incomplete_reason
    assert "7 invalid messages skipped" in reason and "and 2 more channels" in reason, reason
    assert reason.count(" on astrodyn/") == 5


# ------------------------------------------------------------------ F3.5: duplicated seqs


def test_a_duplicated_seq_is_warned_by_csv_and_named_by_oem(tmp_path, capsys):
    """seq 3 recorded twice (the second with another position).  The contract: one message
    per seq.  CSV export warns naming the duplicate and writes both rows as recorded; OEM,
    which holds one state per epoch, refuses and says it is a duplicated sequence number."""
    orbit = _circular(8)
    copy = dict(orbit[3])
    copy["r"] = [x + 1000.0 for x in copy["r"]]
    path = _write(tmp_path / "dup.mcap", {_topic("sat", "orbit"): orbit[:4] + [copy] + orbit[4:]}, _scenario())
    assert export_main([str(path), "--format", "csv", "--out", str(tmp_path / "csv")]) == 0
    err = capsys.readouterr().err
    assert f"{_topic('sat', 'orbit')}: 1 duplicated sequence number" in err and "exported as recorded" in err, err
    assert [int(r["seq"]) for r in _csv_rows(tmp_path / "csv" / "sat.orbit.csv")] == [0, 1, 2, 3, 3, 4, 5, 6, 7]
    assert export_main([str(path), "--format", "oem", "--out", str(tmp_path / "oem")]) == 1
    err = capsys.readouterr().err
    assert "seq 3: a duplicated sequence number" in err and "astrodyn merge" in err, err
    assert not (tmp_path / "oem").exists() or not list((tmp_path / "oem").iterdir())


# ------------------------------------------------------------------ F3.6: finite values whose squares overflow


def test_a_value_of_1e308_gives_no_numpy_warning_and_is_reported(tmp_path):
    """r = (1e308, 1e308, 1e308) m at seq 4 is a finite number; its radius is sqrt(3) 1e308
    m (finite), h = r x v is not (beyond float64).  No RuntimeWarning escapes; the report
    gives the radius and names the number that is not finite and the value behind it."""
    orbit = _circular(8)
    orbit[4]["r"] = [1e308, 1e308, 1e308]
    path = _write(tmp_path / "giant.mcap", {_topic("sat", "orbit"): orbit}, _scenario())
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        report = analyze(path, tmp_path / "report", figures_for=0)
    sat = report["bodies"]["sat"]
    assert sat["orbit"]["r_max_m"] == pytest.approx(math.sqrt(3.0) * 1e308, rel=1e-15)
    note = sat["non-finite numbers"]
    assert "h = r x v" in note["numbers"] and "orbit r = 1e+308 at seq 4" in note["largest recorded values"], note
    assert "non-finite numbers" in (tmp_path / "report" / "report.md").read_text()


# ------------------------------------------------------------------ F3.7: a J2 orbit's figure and labels


def _j2_orbit(n: int, step: float = 60.0) -> tuple[np.ndarray, np.ndarray]:
    """States of an inclined LEO under two-body + J2 gravity, integrated here (DOP853, rtol
    1e-12): the acceleration is the gradient of U = mu/r (1 - J2 (R/r)^2 (3 z^2/r^2 - 1)/2)."""
    def rhs(_, y):
        x, yy, z = y[:3]
        r2 = x * x + yy * yy + z * z
        r = math.sqrt(r2)
        k = 1.5 * J2 * MU * R_E**2 / r**5
        zz = 5.0 * z * z / r2
        a = -MU / r**3 * y[:3] + k * np.array([x * (zz - 1.0), yy * (zz - 1.0), z * (zz - 3.0)])
        return np.concatenate([y[3:], a])

    r0 = 7.0e6
    speed = math.sqrt(MU / r0)
    y0 = [r0, 0.0, 0.0, 0.0, speed * math.cos(1.0), speed * math.sin(1.0)]
    times = np.arange(n) * step
    sol = solve_ivp(rhs, (0.0, times[-1]), y0, method="DOP853", rtol=1e-12, atol=1e-6, t_eval=times)
    return sol.y[:3].T, sol.y[3:].T


def test_a_j2_orbit_drift_figure_draws_the_energy_with_j2_and_its_two_body_rows_say_so(tmp_path, monkeypatch):
    """README: J2 orbits are judged by the energy with the J2 potential and h_z (their
    two-body E and h change by ~1e-3: J2's effect, not an error).  The orbit-drift figure
    draws those two, matching the drift computed here; the orbit table's E and h say they
    are two-body, and a note says the model does not conserve them."""
    r, v = _j2_orbit(61)
    orbit = [{"t": 60.0 * k, "seq": k, "model": "j2", "r": list(map(float, r[k])), "v": list(map(float, v[k])),
              "mu": MU, "frame": "GCRF"} for k in range(len(r))]
    path = _write(tmp_path / "j2.mcap", {_topic("sat", "orbit"): orbit}, _scenario("j2", 2))
    rn = np.linalg.norm(r, axis=1)
    energy_j2 = 0.5 * np.sum(v * v, axis=1) - MU / rn * (1 - J2 * (R_E / rn) ** 2 * (3 * (r[:, 2] / rn) ** 2 - 1) / 2)
    h = np.cross(r, v)
    expected_e = np.abs(energy_j2 - energy_j2[0]) / abs(energy_j2[0])
    expected_hz = np.abs(h[:, 2] - h[0, 2]) / np.linalg.norm(h[0])
    two_body = 0.5 * np.sum(v * v, axis=1) - MU / rn
    assert np.max(np.abs(two_body - two_body[0])) / abs(two_body[0]) > 1e-5  # the check has teeth
    assert np.max(expected_e) < 1e-9 and np.max(expected_hz) < 1e-9  # the integration holds them

    drawn = {}
    monkeypatch.setattr(report_figures, "orbit_drift", lambda name, t, e, hz, path, **kw: drawn.update(
        e=np.asarray(e), h=np.asarray(hz), **kw))
    report = analyze(path, tmp_path / "report", figures_for=0)
    assert drawn["energy"] == "E (with J2)" and drawn["momentum"] == "h_z"
    np.testing.assert_allclose(drawn["e"], expected_e, rtol=0, atol=1e-14)
    np.testing.assert_allclose(drawn["h"], expected_hz, rtol=0, atol=1e-14)
    orbit_numbers = report["bodies"]["sat"]["orbit"]
    assert "does not conserve" in orbit_numbers["two_body_note"] and "E (with J2)" in orbit_numbers["two_body_note"]
    md = (tmp_path / "report" / "report.md").read_text()
    assert "max \\|E - E0\\| / \\|E0\\|, two-body E" in md


# ------------------------------------------------------------------ F3.8: one value for one quantity


def test_inertial_angular_momentum_drift_is_one_number_and_the_physical_one(tmp_path):
    """A spin about a tilted principal axis keeps H_i constant (closed form), here with
    recorded |q| = 1 +- 4e-10 (within the message definition's 1e-9).  The report gave
    two values for its drift (2.5e-16 in the attitude table, 3.2e-16 in the conserved
    quantities: two evaluations of C(q)^T I w); one quantity now has one value, at
    round-off, and the table's label says which H_i it is."""
    norms = [1.0 + (4e-10 if k % 2 else -4e-10) for k in range(20)]
    spin = _spin(20, norms=norms)
    q = np.array([m["q"] for m in spin])
    assert np.all(np.abs(np.linalg.norm(q, axis=1) - 1) > 3e-10)  # as recorded
    path = _write(tmp_path / "spin.mcap", {_topic("sat", "orbit"): _circular(20), _topic("sat", "attitude"): spin},
                  _scenario())
    report = analyze(path, tmp_path / "report", figures_for=0)
    sat = report["bodies"]["sat"]
    table = sat["attitude"]["h_inertial_drift_max"]
    conserved = sat["conserved quantities"]["attitude: H_i [N m s], max drift relative to |H0|"]
    assert table == conserved
    assert table < 1e-14
    md = (tmp_path / "report" / "report.md").read_text()
    assert "rigid-body Hi = C(q)^T I w" in md
