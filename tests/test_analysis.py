"""``astrodyn analyze``: every figure is written, and the report's numbers match the arrays.

The recording is made from the core's states (tests/_recordings.py); the numbers are
recomputed here from those states with the textbook formulas written out (energy
v^2/2 - mu/r, h = r x v, T = w.Iw/2, H_i = C^T I w with C built by hand from Baruh's
Euler-parameter DCM), independent of astrodyn.analysis.metrics.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from astrodyn.analysis import FIGURES, analyze
from astrodyn.analysis.metrics import gmst_rad

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _recordings import LEO_TWO_BODIES, leo_recording, record

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    base = tmp_path_factory.mktemp("analysis")
    path = base / "an.mcap"
    sc, res = leo_recording(path, name="an", duration="1200 s", rate="0.5 Hz")
    rep = analyze(path, base / "rep", seq="313")
    return base / "rep", rep, sc, res


def _dcm(q):
    """Baruh (7.x) DCM of Euler parameters, v_body = C v_inertial (written out here)."""
    e0, e1, e2, e3 = q
    return np.array([
        [e0**2 + e1**2 - e2**2 - e3**2, 2 * (e1 * e2 + e0 * e3), 2 * (e1 * e3 - e0 * e2)],
        [2 * (e1 * e2 - e0 * e3), e0**2 - e1**2 + e2**2 - e3**2, 2 * (e2 * e3 + e0 * e1)],
        [2 * (e1 * e3 + e0 * e2), 2 * (e2 * e3 - e0 * e1), e0**2 - e1**2 - e2**2 + e3**2],
    ])


def test_every_figure_is_written_and_linked(report):
    out, rep, _, _ = report
    expected = {"leo": ["orbit3d", "groundtrack", "elements", "orbit-drift", "euler", "quaternion", "rates",
                        "polhode", "attitude-drift"],
                "geo": ["orbit3d", "groundtrack", "elements", "orbit-drift"]}
    md = (out / "report.md").read_text()
    page = (out / "report.html").read_text()
    for body, kinds in expected.items():
        assert list(rep["figures"][body]) == kinds
        for kind in kinds:
            png = out / f"{body}-{kind}.png"
            assert png.stat().st_size > 10_000 and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
            assert f"({png.name})" in md and f"src='{png.name}'" in page
            assert FIGURES[kind] in md
    assert json.loads((out / "report.json").read_text())["bodies"] == json.loads(json.dumps(rep["bodies"]))


def test_report_numbers_match_the_arrays(report):
    out, rep, sc, res = report
    mu = sc.central_body.mu
    for i, name in enumerate(res.orbit_names):
        r, v = res.r[:, i], res.v[:, i]
        energy = np.array([vk @ vk / 2 - mu / np.sqrt(rk @ rk) for rk, vk in zip(r, v)])
        h = np.cross(r, v)
        num = rep["bodies"][name]["orbit"]
        # same formula, different evaluation order: agree to a few ulp of the drift's
        # terms (|E| ~ 3e7 J/kg, drift ~1e-15): 1e-15 absolute on a relative quantity
        assert abs(num["energy_drift_max"] - np.max(np.abs(energy - energy[0])) / abs(energy[0])) < 1e-15
        assert abs(num["h_drift_max"] - np.max(np.linalg.norm(h - h[0], axis=1)) / np.linalg.norm(h[0])) < 1e-15
        assert num["states"] == res.t.size and num["t_span_s"] == 1200.0
        radius = np.linalg.norm(r, axis=1)
        assert num["r_min_m"] == pytest.approx(radius.min(), rel=1e-15)
        # Kepler orbits: invariants at round-off (the check has teeth: 1e-12 would flag a bug)
        assert num["energy_drift_max"] < 1e-13 and num["h_drift_max"] < 1e-13
    inertia = np.diag([0.03, 0.035, 0.01])
    q, w = res.q[:, 0], res.w[:, 0]
    t_kin = np.array([wk @ inertia @ wk / 2 for wk in w])
    h_i = np.array([_dcm(qk).T @ inertia @ wk for qk, wk in zip(q, w)])
    att = rep["bodies"]["leo"]["attitude"]
    assert abs(att["kinetic_energy_drift_max"] - np.max(np.abs(t_kin - t_kin[0])) / t_kin[0]) < 1e-15
    assert abs(att["h_inertial_drift_max"] - np.max(np.linalg.norm(h_i - h_i[0], axis=1)) / np.linalg.norm(h_i[0])) < 1e-15
    assert att["quat_norm_error_max"] == np.max(np.abs(np.linalg.norm(q, axis=1) - 1))
    assert att["rate_max_rad_s"] == pytest.approx(np.max(np.linalg.norm(w, axis=1)), rel=1e-15)
    md = (out / "report.md").read_text()
    assert f"{att['h_inertial_drift_max']:.6g}" in md and f"{rep['bodies']['geo']['orbit']['energy_drift_max']:.6g}" in md


def test_gmst_matches_astropy():
    """IAU 1982 GMST vs astropy's IAU 2006 GMST (UT1 = UTC): the models differ by < 0.1 s
    of time over these decades (~1e-5 rad); 2e-5 rad is far below a map's resolution."""
    from astropy.time import Time

    ns = np.array([946_728_000_000_000_000, 1_774_008_000_000_000_000, 1_790_000_000_123_456_789])
    ref = Time(ns // 10**9, (ns % 10**9) * 1e-9, format="unix", scale="utc")
    ref.delta_ut1_utc = 0.0  # UT1 = UTC, as gmst_rad assumes (no IERS table needed)
    ref = ref.sidereal_time("mean", "greenwich", model="IAU2006").rad
    d = np.angle(np.exp(1j * (gmst_rad(ns) - ref)))
    assert np.max(np.abs(d)) < 2e-5


def test_heavy_top_gets_precession_and_nutation(tmp_path):
    path = tmp_path / "top.mcap"
    text = (ROOT / "configs" / "spinning-top.toml").read_text().replace('duration = "20 s"', 'duration = "1 s"').replace('rate = "200 Hz"', 'rate = "100 Hz"')
    record(path, text)
    rep = analyze(path, tmp_path / "rep")
    assert "top-angles" in rep["figures"]["precessing"]
    # started on steady precession at theta = 30 deg: nutation stays at 30 deg (config comment, Baruh ch. 10)
    num = rep["bodies"]["precessing"]["attitude"]
    assert abs(num["nutation_min_deg"] - 30) < 1e-3 and abs(num["nutation_max_deg"] - 30) < 1e-3


def test_analyze_bad_files_and_options_are_clear(tmp_path):
    bad = tmp_path / "x.mcap"
    bad.write_bytes(b"\x00" * 100)
    # a bad input: exit 1; a bad flag value (judged before the input is read): exit 2
    for args, needle, code in [([str(bad)], "not an MCAP file", 1), ([str(bad), "--seq", "345"], "seq: expected one of", 2)]:
        proc = subprocess.run([sys.executable, "-m", "astrodyn", "analyze", *args, "--out", str(tmp_path / "r")],
                              capture_output=True, text=True, timeout=120)
        assert proc.returncode == code and needle in proc.stderr and "Traceback" not in proc.stderr
    # a cut file: analysed up to the cut, said so in the report
    good = tmp_path / "g.mcap"
    record(good, LEO_TWO_BODIES.format(name="cut", duration="100 s", rate="1 Hz"), chunk_size=4096)
    data = good.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    rep = analyze(cut, tmp_path / "cutrep")
    assert rep["complete"] is False and "Incomplete file" in (tmp_path / "cutrep" / "report.md").read_text()
    assert 0 < rep["bodies"]["leo"]["orbit"]["states"] < 101


@pytest.mark.slow
def test_analyze_the_real_demo_run(tmp_path):
    out = tmp_path / "demo.mcap"
    subprocess.run([sys.executable, "-m", "astrodyn", "run", str(ROOT / "configs" / "demo.toml"), "--out", str(out), "--quiet"],
                   check=True, timeout=300, cwd=ROOT)
    rep = analyze(out, tmp_path / "rep")
    assert set(rep["bodies"]) == {"iss", "cubesat", "molniya"}
    for figs in rep["figures"].values():
        for file in figs.values():
            assert (tmp_path / "rep" / file).stat().st_size > 10_000
    assert rep["bodies"]["iss"]["orbit"]["energy_drift_max"] < 1e-13  # Kepler body


def test_report_opens_with_one_line_per_body_from_the_file(report):
    """The "At a glance" lines come before any table and state, per body, the number of
    states actually in the file (counted here with the plain ``mcap`` reader) and the worst
    drift among the conserved quantities listed further down."""
    from mcap.reader import make_reader

    out, rep, _, _ = report
    counts: dict[str, int] = {}
    with open(rep["file"], "rb") as f:
        for _, channel, _ in make_reader(f).iter_messages():
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
    md = (out / "report.md").read_text()
    page = (out / "report.html").read_text()
    glance = md.split("At a glance:", 1)[1].split("## ", 1)[0]
    assert md.index("At a glance:") < md.index("| quantity |") and "At a glance:" in page
    for body in ("leo", "geo"):
        line = next(x for x in glance.splitlines() if x.startswith(f"- {body}:"))
        n_orbit = next(n for topic, n in counts.items() if topic.endswith(f"/{body}/orbit"))
        assert f"orbit (kepler): {n_orbit} states" in line
        drifts = [v for v in rep["bodies"][body]["conserved quantities"].values() if isinstance(v, float)]
        assert f"largest drift of a conserved quantity {max(drifts):.2g}" in line


def test_repr_of_a_loaded_run_is_one_short_line(report):
    """``repr(load(...))`` names the file, scenario, bodies, channels and span, and does not
    dump the config as run (which stays in ``run.scenario``)."""
    from astrodyn.recording import load

    _, rep, sc, res = report
    run = load(rep["file"])
    text = repr(run)
    assert "\n" not in text and len(text) < 300
    assert "'an'" in text and "leo" in text and "geo" in text and f"{run.messages} messages" in text
    assert f"t 0..{res.t[-1]:.6g} s" in text
    assert run.scenario["epoch"] not in text  # the config is one attribute away, not printed


def test_many_bodies_numbers_for_all_figures_for_the_first_few(tmp_path):
    """A report draws the figures of the first ``figures_for`` bodies by name (a 1000-body
    scene would otherwise take an hour) and the numbers of every selected body: the PNG
    files on disk are those of "geo" only (sorted before "leo"), the numbers of both agree
    with a full report's; ``bodies`` picks by name or shell pattern, and a pattern that
    matches nothing is an error naming it."""
    path = tmp_path / "two.mcap"
    record(path, LEO_TWO_BODIES.format(name="two", duration="200 s", rate="0.5 Hz"))
    full = analyze(path, tmp_path / "full")
    one = analyze(path, tmp_path / "one", figures_for=1)
    assert one["bodies"] == full["bodies"] and set(one["bodies"]) == {"geo", "leo"}
    assert one["figures"]["leo"] == {} and one["figures"]["geo"] == full["figures"]["geo"]
    assert sorted(p.name.split("-")[0] for p in (tmp_path / "one").glob("*.png")) == ["geo"] * len(full["figures"]["geo"])
    md = (tmp_path / "one" / "report.md").read_text()
    assert "Numbers for all 2 bodies; figures for the first 1 of them by name" in md
    picked = analyze(path, tmp_path / "picked", bodies=["l*"])
    assert set(picked["bodies"]) == {"leo"} and picked["bodies"]["leo"] == full["bodies"]["leo"]
    assert "Numbers for 1 of the 2 bodies" in (tmp_path / "picked" / "report.md").read_text()
    # called from Python the error names the argument (the command line prints its flag, --bodies)
    with pytest.raises(ValueError, match=r"^bodies: 'sat\*' matches no body of the recording \(it has 2: geo, leo\)"):
        analyze(path, tmp_path / "none", bodies=["sat*"])
    proc = subprocess.run([sys.executable, "-m", "astrodyn", "analyze", str(path), "--out", str(tmp_path / "cli"),
                           "--figures-for", "0", "--bodies", "geo,leo"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0 and not list((tmp_path / "cli").glob("*.png")), proc.stderr


def test_analyze_says_how_far_it_is_and_quiet_says_nothing(tmp_path):
    """Long work shows progress (stderr): the file and its size, the messages read (as load
    counts them) and the bodies to report, then the end; ``--quiet`` prints none of it."""
    from astrodyn.recording import load

    path = tmp_path / "p.mcap"
    leo_recording(path, name="pg", duration="60 s", rate="1 Hz")
    run = load(path)
    proc = subprocess.run([sys.executable, "-m", "astrodyn", "analyze", str(path), "--out", str(tmp_path / "r"),
                           "--figures-for", "0"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stderr.splitlines()
    assert lines[0] == f"analyze: reading {path} ({path.stat().st_size / 1e6:.1f} MB)", lines
    assert lines[1].startswith(f"analyze: {run.messages} messages read in "), lines
    assert lines[1].endswith(f"; {len(run.bodies)} bodies to report, figures for 0"), lines
    assert lines[-1].startswith(f"analyze: {len(run.bodies)} bodies reported in "), lines
    quiet = subprocess.run([sys.executable, "-m", "astrodyn", "analyze", str(path), "--out", str(tmp_path / "q"),
                            "--figures-for", "0", "--quiet"], capture_output=True, text=True, timeout=120)
    assert quiet.returncode == 0 and quiet.stderr == "", quiet.stderr
    assert quiet.stdout.strip() == str(tmp_path / "q" / "report.html")


@pytest.mark.parametrize("kwargs, argument, flag, reason", [
    ({"seq": "123x"}, "seq", "--seq", "expected one of 121, 123, 131, 132, 212, 213, 231, 232, 312, 313, 321, 323 "
                                      "(the Euler angle sequence), got '123x'"),
    ({"figures_for": -1}, "figures_for", "--figures-for", "expected an integer >= 0, got -1"),
    ({"bodies": ["leo", ""]}, "bodies", "--bodies", "expected comma-separated body names or shell patterns, none empty "
                                                    "(e.g. 'sat-00*,leo'), got 'leo,'"),
])
def test_analyze_from_python_names_the_argument_and_the_cli_the_flag(tmp_path, capsys, kwargs, argument, flag, reason):
    """analyze() called from Python names its own argument (``seq``), not a command-line
    flag; ``astrodyn analyze`` prints the flag (``--seq``), word for word as before."""
    from astrodyn import analysis

    missing = tmp_path / "never-read.mcap"  # judged before the input is read
    with pytest.raises(ValueError) as info:
        analyze(missing, tmp_path / "rep", **kwargs)
    assert str(info.value) == f"{argument}: {reason}"
    assert type(info.value).__name__ == "ReportOptionError" and info.value.flag_message == f"{flag}: {reason}"
    value = {"seq": "123x", "figures_for": "-1", "bodies": "leo,"}[argument]
    assert analysis.main([str(missing), "--out", str(tmp_path / "rep"), flag, value]) == 2
    assert capsys.readouterr().err.strip().splitlines()[-1] == f"astrodyn analyze: error: {flag}: {reason}"
    assert not (tmp_path / "rep").exists()
