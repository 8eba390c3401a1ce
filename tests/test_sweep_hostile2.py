"""``astrodyn sweep`` / ``analyze SWEEP_DIR`` against hostile uses (probe report F1-F12).

Each test reproduces a fault the probe found and checks the result against facts outside
the code under test: the draws a case's MCAP metadata holds, the rows of an uninterrupted
run of the same spec, the scenario validator's own error, the files in the directory.
Tiny serial sweeps (``--workers 0``) of a 1-minute scenario keep this file fast.
"""

from __future__ import annotations

import csv
import errno
import fcntl
import gc
import json
import os
import shutil
import signal
import socket
import threading
import time
from pathlib import Path

import pytest

from _recordings import orbiter, scenario_head
from astrodyn import sweep

CONFIG = scenario_head("hostile2", "60 s", "0.1 Hz", "TDB") + "\n" + orbiter("sat1", "7000 km", 0.01, "51.6 deg") + """\
[bodies.attitude]
q = [1, 0, 0, 0]
w = [0.01, 0.001, 0.002]
inertia = [1, 2, 3]
"""

VARY = "bodies.sat1.orbit.e=uniform(0, 0.05)"


@pytest.fixture(scope="module")
def config(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("hostile2") / "short.toml"
    path.write_text(CONFIG)
    return path


def _argv(config: Path, out: Path, *extra: str, n: int = 3) -> list[str]:
    return [str(config), "--vary", VARY, "-n", str(n), "--workers", "0", "--out", str(out), "--quiet", *extra]


def _rows(path: Path) -> list[dict]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def _no_wall(rows: list[dict]) -> list[dict]:
    return [{k: v for k, v in r.items() if k != "wall_s"} for r in rows]


@pytest.fixture(scope="module")
def reference(config, tmp_path_factory) -> Path:
    """An uninterrupted 3-case sweep: the rows every completed sweep of this spec must have."""
    out = tmp_path_factory.mktemp("ref") / "ref"
    assert sweep.main(_argv(config, out)) == 0
    return out


# --------------------------------------------------------------------------- F1, F15: wrong results


@pytest.mark.parametrize("varies, where", [
    (["bodies.sat1.orbit.e=uniform(0, 0.05)", "bodies[0].orbit.e=uniform(0.5, 0.6)"], "bodies[0].orbit.e"),
    (["bodies[sat1].orbit.e=0.1", "bodies.sat1.orbit.e=0.2"], "bodies[0].orbit.e"),
    (["bodies.sat1.attitude.w[0]=uniform(0.5, 0.6)", "bodies.sat1.attitude.w=[0.01, 0.001, 0.002]"],
     "bodies[0].attitude.w"),
], ids=["name-and-index", "bracket-and-dot", "element-and-vector"])
def test_one_config_value_varied_under_two_spellings_is_refused(config, tmp_path, capsys, varies, where):
    """Both draws were tabled, only the last assigned reached the simulation (exit 0)."""
    out = tmp_path / "out"
    rc = sweep.main([str(config), *sum((["--vary", v] for v in varies), []), "-n", "2", "--workers", "0",
                     "--out", str(out), "--quiet"])
    err = capsys.readouterr().err
    assert rc == 2, err
    first, second = (v.split("=", 1)[0] for v in varies)
    assert first in err and second in err and where in err and len(err.strip().splitlines()) == 1, err
    assert not out.exists()


def test_a_cases_column_and_a_vary_of_the_same_value_are_refused(config, tmp_path, capsys):
    cases = tmp_path / "c.csv"
    cases.write_text("bodies.sat1.orbit.e\n0.3\n0.4\n")
    out = tmp_path / "out"
    rc = sweep.main([str(config), "--cases", str(cases), "--vary", "bodies[0].orbit.e=0.1", "--workers", "0",
                     "--out", str(out), "--quiet"])
    err = capsys.readouterr().err
    assert rc == 2 and "bodies.sat1.orbit.e" in err and "bodies[0].orbit.e" in err, err
    assert not out.exists()


def test_a_case_rerun_with_another_cases_csv_of_the_same_shape_is_refused(config, tmp_path, capsys):
    cases = tmp_path / "c.csv"
    cases.write_text("bodies.sat1.orbit.e\n0.1\n0.2\n")
    out = tmp_path / "out"
    assert sweep.main([str(config), "--cases", str(cases), "--workers", "0", "--out", str(out), "--quiet"]) == 0
    before = (out / "summary.csv").read_bytes()
    cases.write_text("bodies.sat1.orbit.e\n0.5\n0.6\n")  # same header, same row count
    capsys.readouterr()
    rc = sweep.main([str(config), "--cases", str(cases), "--out", str(out), "--quiet", "--case", "1"])
    err = capsys.readouterr().err
    assert rc == 2 and "another spec" in err and "cases_csv_sha256" in err, err
    assert (out / "summary.csv").read_bytes() == before
    cases.write_text("bodies.sat1.orbit.e\n0.1\n0.2\n")  # the sweep's own CSV: accepted
    assert sweep.main([str(config), "--cases", str(cases), "--out", str(out), "--quiet", "--case", "1"]) == 0
    capsys.readouterr()


# --------------------------------------------------------------------------- F4: one sweep per --out


def test_a_second_sweep_into_a_directory_in_use_is_refused(config, tmp_path, capsys):
    """Two sweeps into one --out both ran and exit 0: one's tables, the other's case files."""
    out = tmp_path / "out"
    out.mkdir()
    fd = os.open(out / sweep.LOCK_NAME, os.O_RDWR | os.O_CREAT)  # another sweep holds it
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        rc = sweep.main(_argv(config, out))
    finally:
        os.close(fd)
    err = capsys.readouterr().err
    assert rc == 2 and "another astrodyn sweep" in err and len(err.strip().splitlines()) == 1, err
    assert sorted(p.name for p in out.iterdir()) == [sweep.LOCK_NAME]  # nothing written
    assert sweep.main(_argv(config, out)) == 0  # free again: runs, and leaves no lock file
    assert not (out / sweep.LOCK_NAME).exists()


# --------------------------------------------------------------------------- F2: always stoppable


def test_a_stop_signal_lost_in_a_gc_callback_still_stops_the_sweep(config, tmp_path, monkeypatch, capsys):
    """The Interrupted raised in Dask's gc callback was printed and dropped, and every later
    signal ignored: only SIGKILL stopped the sweep.  Here the first case ends with a SIGTERM
    delivered inside a gc callback; the sweep must stop before the next case, write the
    finished row and exit 143."""
    ran = []
    original = sweep.run_case

    def run_case(k, spec):
        row = original(k, spec)
        ran.append(k)
        if k == 0:
            def callback(phase, info):
                if phase == "start":
                    gc.callbacks.remove(callback)
                    signal.raise_signal(signal.SIGTERM)  # the handler runs, and raises, in here

            gc.callbacks.append(callback)
            gc.collect()
        return row

    monkeypatch.setattr(sweep, "run_case", run_case)
    out = tmp_path / "out"
    rc = sweep.main(_argv(config, out, n=4))
    assert rc == 143, capsys.readouterr().err
    assert ran == [0]
    assert [r["case"] for r in _rows(out / "summary.csv")] == ["0"]
    assert json.loads((out / "sweep.json").read_text())["interrupted"] is True


# --------------------------------------------------------------------------- F5, F6, F7, F12: results survive


class Killed(BaseException):
    """What SIGKILL does to the sweep, in-process: it ends where it is, no cleanup of its own."""


def test_a_killed_sweep_keeps_its_finished_rows_and_resume_completes_it(config, reference, tmp_path, monkeypatch):
    original = sweep.run_case
    ran = []

    def dies_at_case_2(k, spec):
        if k == 2:
            raise Killed
        ran.append(k)
        return original(k, spec)

    monkeypatch.setattr(sweep, "run_case", dies_at_case_2)
    out = tmp_path / "out"
    with pytest.raises(Killed):
        sweep.main(_argv(config, out, "--mcap"))
    assert not (out / "summary.csv").exists()
    journal = [json.loads(line) for line in (out / sweep.JOURNAL).read_text().splitlines()]
    assert [r["case"] for r in journal] == [0, 1]
    (out / "mcap" / "case-000002.99999999-0123abcd.mcap.tmp").write_bytes(b"x" * 1000)  # a cut case file
    monkeypatch.setattr(sweep, "run_case", lambda k, spec: (ran.append(k), original(k, spec))[1])
    assert sweep.main(_argv(config, out, "--mcap", "--resume")) == 0
    assert ran == [0, 1, 2]  # only case 2 was run again
    assert _no_wall(_rows(out / "summary.csv")) == _no_wall(_rows(reference / "summary.csv"))
    assert sorted(p.name for p in (out / "mcap").iterdir()) == [f"case-00000{k}.mcap" for k in range(3)]
    assert not (out / sweep.JOURNAL).exists()
    from mcap.reader import make_reader

    for row in _rows(out / "summary.csv"):  # each case file holds the draws its row says
        with open(out / "mcap" / f"case-00000{row['case']}.mcap", "rb") as f:
            meta = {m.name: m.metadata for m in make_reader(f).iter_metadata()}
        drawn = json.loads(meta["scenario"]["sweep_draws"])["bodies.sat1.orbit.e"]
        assert drawn == float(row["bodies.sat1.orbit.e"])


def test_a_full_disk_when_the_tables_are_written_is_one_line_and_resumable(config, reference, tmp_path, monkeypatch,
                                                                            capsys):
    real_replace = os.replace

    def full(src, dst, *a, **kw):
        if str(dst).endswith("sweep.json") and "summary.csv" in os.listdir(os.path.dirname(dst)):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(dst))
        return real_replace(src, dst, *a, **kw)

    monkeypatch.setattr(os, "replace", full)
    out = tmp_path / "out"
    rc = sweep.main(_argv(config, out))
    err = capsys.readouterr().err
    assert rc == 1 and "No space left on device" in err and "--resume" in err, err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not [p for p in out.iterdir() if p.name.endswith((".part", ".tmp"))]
    assert json.loads((out / "sweep.json").read_text())["complete"] is False  # not a complete-looking spec
    monkeypatch.setattr(os, "replace", real_replace)
    monkeypatch.setattr(sweep, "run_case", lambda k, spec: pytest.fail("a case was run again"))
    assert sweep.main(_argv(config, out, "--resume")) == 0
    assert _no_wall(_rows(out / "summary.csv")) == _no_wall(_rows(reference / "summary.csv"))
    assert json.loads((out / "sweep.json").read_text())["complete"] is True


def test_an_integer_draw_beyond_int64_is_stored(config, tmp_path, capsys):
    """The parquet writer raised OverflowError after every case ran: no sweep.json."""
    out = tmp_path / "out"
    rc = sweep.main([str(config), "--vary", "scenario.real_time_factor=choice(2, 99999999999999999999)", "-n", "6",
                     "--workers", "0", "--out", str(out), "--quiet"])
    assert rc == 1, capsys.readouterr().err
    rows = _rows(out / "summary.csv")
    huge = [r for r in rows if r["scenario.real_time_factor"] == "99999999999999999999"]
    assert huge and all(r["status"] == "failed" for r in huge)
    from astrodyn.scenario import ScenarioError, load_dict

    config_dict = sweep.make_spec(config, ["scenario.real_time_factor=2"], n=1).config
    config_dict["scenario"]["real_time_factor"] = 99999999999999999999
    with pytest.raises(ScenarioError) as info:  # the validator's own answer for those cases
        load_dict(config_dict, source="x", base_dir=str(config.parent))
    failures = {r["case"]: r["error"] for r in _rows(out / "failures.csv")}
    for r in huge:
        assert str(info.value).split(": ", 1)[1] in failures[r["case"]]
    assert json.loads((out / "sweep.json").read_text())["cases_run"] == 6


def test_an_interrupted_sweep_leaves_no_case_file_without_a_row(config, tmp_path, monkeypatch, capsys):
    """Cases that finished while the interrupted sweep closed left case-K.mcap files its table lacks."""
    from astrodyn.signals import Interrupted

    original = sweep.write_case_mcap

    def then_interrupted(path, scenario, result, draws, k):
        original(path, scenario, result, draws, k)
        if k == 1:  # its file is in place, its row not yet in the table
            raise Interrupted(signal.SIGINT)

    monkeypatch.setattr(sweep, "write_case_mcap", then_interrupted)
    out = tmp_path / "out"
    assert sweep.main(_argv(config, out, "--mcap")) == 130
    table = [r["case"] for r in _rows(out / "summary.csv")]
    assert table == ["0"]
    assert sorted(p.name for p in (out / "mcap").iterdir()) == ["case-000000.mcap"]
    capsys.readouterr()


# --------------------------------------------------------------------------- F10, F11: --scheduler


def _server(reply: bytes | None) -> tuple[int, threading.Event]:
    """A TCP server on 127.0.0.1 that accepts, sends ``reply`` (or nothing), and holds the
    connection for 20 s at most."""
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(8)
    stop = threading.Event()

    def serve() -> None:
        srv.settimeout(0.2)
        held = []
        deadline = time.monotonic() + 20
        while not stop.is_set() and time.monotonic() < deadline:
            try:
                conn, _ = srv.accept()
            except TimeoutError:
                continue
            if reply:
                conn.sendall(reply)
            held.append(conn)
        for c in held:
            c.close()
        srv.close()

    threading.Thread(target=serve, daemon=True).start()
    return srv.getsockname()[1], stop


@pytest.mark.parametrize("reply", [None, b"\xff" * 64], ids=["never-answers", "junk"])
def test_a_scheduler_address_that_is_not_a_dask_scheduler_is_one_line(config, tmp_path, monkeypatch, capsys, reply):
    pytest.importorskip("distributed")
    monkeypatch.setattr(sweep, "SCHEDULER_TIMEOUT_S", 1.0)
    monkeypatch.setattr(sweep, "SCHEDULER_GRACE_S", 1.0, raising=False)
    port, stop = _server(reply)
    out = tmp_path / "out"
    t0 = time.monotonic()
    try:
        rc = sweep.main([str(config), "--vary", VARY, "-n", "2", "--scheduler", f"tcp://127.0.0.1:{port}",
                         "--out", str(out), "--quiet"])
    finally:
        stop.set()
    err = capsys.readouterr().err
    assert rc == 2 and f"--scheduler tcp://127.0.0.1:{port}" in err and "Traceback" not in err, err
    assert time.monotonic() - t0 < 10
    assert not out.exists()


# --------------------------------------------------------------------------- F8, F9: tampered sweep directories


def test_a_case_rerun_into_a_tampered_table_is_refused_before_running(config, reference, tmp_path, monkeypatch,
                                                                       capsys):
    out = tmp_path / "out"
    shutil.copytree(reference, out)
    text = (out / "summary.csv").read_text().splitlines()
    text[2] = "one" + text[2][1:]  # case 1's number
    (out / "summary.csv").write_text("\n".join(text) + "\n")
    monkeypatch.setattr(sweep, "run_case", lambda k, spec: pytest.fail("ran before checking the tables"))
    rc = sweep.main(_argv(config, out, "--case", "0"))
    err = capsys.readouterr().err
    assert rc == 2 and "summary.csv" in err and "'one'" in err and len(err.strip().splitlines()) == 1, err


def test_analyze_of_tampered_sweep_directories_is_one_line(tmp_path, capsys):
    from astrodyn.analysis import main as analyze

    d = tmp_path / "d"
    d.mkdir()
    (d / "summary.csv").write_text("a,b\n1,2\n3,4\n")  # a foreign CSV
    assert analyze([str(d), "--out", str(tmp_path / "r1")]) == 1
    err = capsys.readouterr().err
    assert "summary.csv" in err and "'case'" in err and len(err.strip().splitlines()) == 1, err
    (d / "summary.csv").write_text("case,status,x\n0,ok,1.5\n1,failed,\n")
    (d / "failures.csv").write_text("x,y\n1,2\n")  # no case column
    assert analyze([str(d), "--out", str(tmp_path / "r2")]) == 1
    err = capsys.readouterr().err
    assert "failures.csv" in err and len(err.strip().splitlines()) == 1, err
    (d / "failures.csv").unlink()
    os.mkfifo(d / "sweep.json")  # never opened
    from astrodyn.analysis.sweep import MAX_TABLE_BYTES

    with open(d / "summary.csv", "r+b") as f:  # sparse: read whole, it filled the memory
        f.truncate(MAX_TABLE_BYTES + 1)
    assert analyze([str(d), "--out", str(tmp_path / "r3")]) == 1
    err = capsys.readouterr().err
    assert f"at most {MAX_TABLE_BYTES} bytes" in err and len(err.strip().splitlines()) == 1, err
