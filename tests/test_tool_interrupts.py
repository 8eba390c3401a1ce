"""The file tools interrupted at a chosen moment by a real signal (docs/reliability.md).

Each test starts the command as its own process group (as a shell runs a foreground job),
waits until it is writing its output (its temporary file exists, or its earlier output
starts to change), then sends the signal: SIGINT to the group, as Ctrl-C from a terminal
does, SIGTERM / SIGHUP / SIGKILL to the PID.  Afterwards: exit 128 + signal with one line saying so
and no traceback, the input byte-identical, no half-written output under its final name,
an earlier output untouched, no temporary file left, no process of the group alive.
"""

from __future__ import annotations

import hashlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

#: the command with Ctrl-C at its default (a test run in the background inherits it ignored)
ASTRODYN = [sys.executable, "-c", "import os, signal, sys; signal.signal(signal.SIGINT, signal.SIG_DFL); "
            "os.execv(sys.executable, [sys.executable, '-m', 'astrodyn', *sys.argv[1:]])"]

WALKER = """
[scenario]
name = "walker"
epoch = "2026-03-20T12:00:00 UTC"
duration = "20 s"
rate = "10 Hz"

[central_body]
name = "earth"

[walker]
prefix = "sat"
i = "53 deg"
t = 300
p = 10
f = 1
altitude = "550 km"
model = "kepler"

[walker.attitude]
model = "torque_free"
q = [1, 0, 0, 0]
w = ["0.002 rad/s", "0.0005 rad/s", "0.001 rad/s"]
inertia = ["12 kg m2", "10 kg m2", "4 kg m2"]
"""


def _record(path: Path, text: str) -> Path:
    from astrodyn.scenario import loads
    from astrodyn.simulate import simulate
    from astrodyn.sweep import write_case_mcap

    scenario = loads(text)
    write_case_mcap(path, scenario, simulate(scenario), {}, 0)
    return path


@pytest.fixture(scope="module")
def data(tmp_path_factory) -> Path:
    """walker.toml; walker.mcap (300 bodies, orbit and attitude, 201 steps: 120,600 messages,
    about 6 MB); short.mcap (the same scene for 2 s)."""
    d = tmp_path_factory.mktemp("interrupts")
    (d / "walker.toml").write_text(WALKER)
    _record(d / "walker.mcap", WALKER)
    _record(d / "short.mcap", WALKER.replace('duration = "20 s"', 'duration = "2 s"'))
    return d


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _tree(d: Path) -> dict[str, str]:
    """Every file under ``d`` (hidden ones too) -> its sha256."""
    return {str(p.relative_to(d)): _sha(p) if p.is_file() else "dir" for p in sorted(d.rglob("*"))}


def _start(processes, *argv, cwd: Path | None = None) -> subprocess.Popen:
    return processes([*ASTRODYN, *argv], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                     start_new_session=True, cwd=cwd)


def _wait_for(proc: subprocess.Popen, condition, timeout: float = 60.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        if proc.poll() is not None:
            pytest.fail(f"the command ended (status {proc.returncode}) before the moment to interrupt it: "
                        f"{proc.stderr.read()[-2000:]}")
        if time.monotonic() > deadline:
            pytest.fail("the moment to interrupt never came")
        time.sleep(0.002)


def _interrupt(proc: subprocess.Popen, sig: int) -> str:
    """Send ``sig`` (SIGINT to the process group, as a terminal does); wait for the end; stderr."""
    if sig == signal.SIGINT:
        os.killpg(proc.pid, sig)
    else:
        os.kill(proc.pid, sig)
    return proc.communicate(timeout=60)[1]


def _ended_by(proc: subprocess.Popen, sig: int, err: str) -> None:
    """Exit 128 + signal, the last line of stderr saying so, no traceback."""
    assert "Traceback" not in err, err
    assert proc.returncode == 128 + sig, (proc.returncode, err)
    assert f"interrupted by {signal.Signals(sig).name}" in err.strip().splitlines()[-1], err


def _hidden_dirs(d: Path, prefix: str) -> list[Path]:
    return [p for p in d.iterdir() if p.name.startswith(prefix)] if d.is_dir() else []


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_an_interrupted_recover_leaves_its_input_as_it_was_and_no_temporary_file(tmp_path, data, processes, sig):
    """Before: SIGTERM left ``cut.mcap.recover-tmp`` (Python died without its cleanup) and
    Ctrl-C ended in a KeyboardInterrupt traceback."""
    cut = tmp_path / "cut.mcap"
    whole = (data / "walker.mcap").read_bytes()
    cut.write_bytes(whole[: len(whole) * 9 // 10])
    before = _sha(cut)
    proc = _start(processes, "recover", cut)  # in place
    _wait_for(proc, lambda: any(tmp_path.glob("cut.*.recover-tmp")))  # its own temporary name (pid, random part)
    err = _interrupt(proc, sig)
    assert _sha(cut) == before and sorted(p.name for p in tmp_path.iterdir()) == ["cut.mcap"]
    _ended_by(proc, sig, err)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP], ids=["SIGTERM", "SIGHUP"])
def test_a_merge_stopped_by_sigterm_or_a_closed_terminal_leaves_no_temporary_file(tmp_path, data, processes, sig):
    """Before: ``.m.mcap.merging`` stayed behind, exit -15 (-1 for SIGHUP)."""
    inputs = [data / "walker.mcap", data / "short.mcap"]
    before = [_sha(p) for p in inputs]
    proc = _start(processes, "merge", *inputs, "--out", tmp_path / "m.mcap")
    _wait_for(proc, lambda: any(tmp_path.glob(".m.*.merging")))
    err = _interrupt(proc, sig)
    assert [_sha(p) for p in inputs] == before and list(tmp_path.iterdir()) == []
    _ended_by(proc, sig, err)


def test_an_export_interrupted_by_ctrl_c_leaves_no_new_directory(tmp_path, data, processes):
    """Before: a KeyboardInterrupt traceback, and the new --out directory stayed, empty."""
    out = tmp_path / "new"
    proc = _start(processes, "export", data / "walker.mcap", "--format", "csv", "--out", out)
    _wait_for(proc, lambda: bool(_hidden_dirs(out, ".export-")))
    err = _interrupt(proc, signal.SIGINT)
    assert not out.exists()
    _ended_by(proc, signal.SIGINT, err)


def test_an_export_stopped_by_sigterm_keeps_the_earlier_export_and_leaves_no_work_directory(tmp_path, data,
                                                                                           processes):
    """Before: the work directory ``.export-*`` with the partial files stayed in --out."""
    from astrodyn.recording.export import export

    out = tmp_path / "out"
    export(data / "short.mcap", "csv", out)  # the earlier export: same file names, other content
    before = _tree(out)
    proc = _start(processes, "export", data / "walker.mcap", "--format", "csv", "--out", out)
    _wait_for(proc, lambda: any(any(w.iterdir()) for w in _hidden_dirs(out, ".export-")))
    err = _interrupt(proc, signal.SIGTERM)
    assert _tree(out) == before
    _ended_by(proc, signal.SIGTERM, err)


def test_a_signal_while_an_export_moves_its_files_into_place_leaves_all_or_none(tmp_path, data, processes):
    """The files of an export go into --out one rename at a time; a SIGTERM among them
    left part of the earlier export and part of the new one.  A signal there now takes
    effect once every file is in place."""
    from astrodyn.recording.export import export

    out = tmp_path / "out"
    export(data / "short.mcap", "csv", out)
    before = _tree(out)
    proc = _start(processes, "export", data / "walker.mcap", "--format", "csv", "--out", out)
    _wait_for(proc, lambda: len(_hidden_dirs(out, ".export-")) == 1)
    work, most = _hidden_dirs(out, ".export-")[0], 0

    def moving() -> bool:  # files leave the work directory: the moves have begun
        nonlocal most
        try:
            n = len(os.listdir(work))
        except FileNotFoundError:
            return True
        most = max(most, n)
        return n < most

    _wait_for(proc, moving)
    err = _interrupt(proc, signal.SIGTERM)
    after = _tree(out)
    replaced = [name for name in before if after.get(name) != before[name]]
    assert replaced == [] or len(replaced) == len(before), f"{len(replaced)} of {len(before)} files replaced"
    assert after.keys() == before.keys()  # no work directory left
    _ended_by(proc, signal.SIGTERM, err)


def test_the_work_directory_of_a_killed_export_is_removed_by_the_next_export(tmp_path, data, processes):
    """SIGKILL cannot be caught: the work directory stays (hidden, never under a final name);
    the next export into that directory removes it.  Before: it stayed for good."""
    from astrodyn.recording.export import export

    out = tmp_path / "out"
    proc = _start(processes, "export", data / "walker.mcap", "--format", "csv", "--out", out)
    _wait_for(proc, lambda: any(any(w.iterdir()) for w in _hidden_dirs(out, ".export-")))
    _interrupt(proc, signal.SIGKILL)
    assert proc.returncode == -signal.SIGKILL and _hidden_dirs(out, ".export-")  # what SIGKILL leaves
    export(data / "short.mcap", "oem", out)
    assert not _hidden_dirs(out, ".export-") and len(list(out.iterdir())) == len(list(out.glob("sat-*.oem"))) == 300


def _analyze_stopped_by_sigterm_keeps_the_earlier_report(processes, out: Path, earlier: list[str], *argv) -> None:
    """An earlier report (files ``earlier`` in ``out``); ``astrodyn analyze ARGV --out OUT``
    stopped by SIGTERM once it writes figures (into ``out`` or its hidden work directory):
    ``out`` holds the earlier report as it was, and the tool says it was interrupted."""
    out.mkdir()
    for name in earlier:
        (out / name).write_text(f"earlier {name}")
    before = _tree(out)

    def writing() -> bool:
        return _tree(out) != before or any(any(w.glob("*.png")) for w in _hidden_dirs(out, ".analyze-"))

    proc = _start(processes, "analyze", *argv, "--out", out)
    _wait_for(proc, writing)
    err = _interrupt(proc, signal.SIGTERM)
    assert _tree(out) == before
    _ended_by(proc, signal.SIGTERM, err)


def test_an_analyze_stopped_by_sigterm_keeps_the_earlier_report_whole(tmp_path, data, processes):
    """Before: the figures were written straight into the report directory, so an earlier
    report there had some figures replaced by the new run's and kept its old pages."""
    _analyze_stopped_by_sigterm_keeps_the_earlier_report(
        processes, tmp_path / "report",
        ["report.md", "report.html", "report.json", "sat-0-00-orbit3d.png", "sat-0-00-elements.png"],
        data / "walker.mcap", "--bodies", "sat-0-00", "--quiet")


@pytest.fixture(scope="module")
def earlier_sweep(data) -> Path:
    """A finished one-case sweep of walker.toml with its case MCAP (6 MB), run in-process."""
    from astrodyn import sweep

    out = data / "sweep"
    assert sweep.main([str(data / "walker.toml"), "--vary", "walker.altitude=550 km", "-n", "1", "--workers", "0",
                       "--mcap", "--out", str(out), "--quiet"]) == 0
    return out


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_an_interrupted_case_rerun_keeps_the_earlier_case_recording(tmp_path, data, earlier_sweep, processes, sig):
    """``sweep --case K --mcap`` rewrote ``mcap/case-K.mcap`` in place: Ctrl-C left it cut
    but finished (footer and summary: it looked complete), SIGTERM cut without a footer;
    either way the earlier recording of the case was gone.  And sweep.json listed the
    interrupted rerun under ``reruns`` as if it had been done: a rerun is listed once its
    cases are written, so with none finished the whole directory stays as it was."""
    import shutil

    out = tmp_path / "sweep"
    shutil.copytree(earlier_sweep, out)
    case = out / "mcap" / "case-000000.mcap"
    before, stat = _tree(out), case.stat()

    def writing() -> bool:
        now = case.stat()
        return (now.st_size, now.st_mtime_ns) != (stat.st_size, stat.st_mtime_ns) or len(list(case.parent.iterdir())) > 1

    proc = _start(processes, "sweep", data / "walker.toml", "--vary", "walker.altitude=550 km", "-n", "1",
                  "--mcap", "--out", out, "--quiet", "--case", "0")
    _wait_for(proc, writing)
    err = _interrupt(proc, sig)
    assert _tree(out) == before  # the tables, the case's recording and sweep.json (no "reruns" entry)
    _ended_by(proc, sig, err)


def test_ctrl_c_to_a_dask_sweep_ends_it_without_tracebacks_or_leftovers(tmp_path, data, processes):
    """Ctrl-C reaches every process of the group: before, each Dask worker died of it
    printing a traceback (and a case file being written was cut under its name).  Now the
    workers ignore it, the sweep cancels the cases, closes the cluster, writes the finished
    cases' tables and exits 130; no process of the group is left."""
    out = tmp_path / "sweep"
    proc = _start(processes, "sweep", data / "walker.toml", "--vary", "walker.altitude=uniform(540, 560) km",
                  "-n", "6", "--workers", "2", "--mcap", "--out", out, "--quiet")
    _wait_for(proc, lambda: (out / "mcap").is_dir() and any((out / "mcap").iterdir()))
    err = _interrupt(proc, signal.SIGINT)
    _ended_by(proc, signal.SIGINT, err)
    from astrodyn.recording import load

    assert not list((out / "mcap").glob("*.tmp"))
    for path in (out / "mcap").iterdir():  # only finished cases are left
        assert load(path).complete, path
    deadline = time.monotonic() + 10
    while True:
        try:
            os.killpg(proc.pid, 0)  # the group of the sweep: its workers, resource tracker
        except ProcessLookupError:
            break
        assert time.monotonic() < deadline, "a process of the sweep outlived it"
        time.sleep(0.05)


def _group(pgid: int) -> list[int]:
    """PIDs of the processes in process group ``pgid`` (its leader excluded), from /proc."""
    found = []
    for entry in os.listdir("/proc"):
        if entry.isdigit() and int(entry) != pgid:
            try:
                with open(f"/proc/{entry}/stat") as f:
                    fields = f.read().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[2]) == pgid:
                found.append(int(entry))
    return found


def _no_process_left(pgid: int, within: float = 10.0) -> None:
    deadline = time.monotonic() + within
    while True:
        try:
            os.killpg(pgid, 0)
        except ProcessLookupError:
            return
        assert time.monotonic() < deadline, "a process of the sweep outlived it"
        time.sleep(0.05)


def test_ctrl_c_while_the_dask_cluster_starts_ends_the_sweep_at_once_with_nothing_written(tmp_path, data, processes):
    """The LocalCluster was started with SIGINT ignored by the whole sweep (so its workers
    would inherit that), and a Ctrl-C in that second or so was lost: the sweep ran all its
    cases and exited 0.  Now only the workers are kept from it (a blocked signal mask); the
    sweep sees it at once, closes the cluster, writes nothing (no case had finished: no
    --out directory) and exits 130; no process of the group is left."""
    out = tmp_path / "sweep"
    proc = _start(processes, "sweep", data / "walker.toml", "--vary", "walker.altitude=uniform(540, 560) km",
                  "-n", "4", "--workers", "2", "--out", out, "--quiet")
    _wait_for(proc, lambda: bool(_group(proc.pid)))  # the cluster's first process: it is starting
    sent = time.monotonic()
    err = _interrupt(proc, signal.SIGINT)
    _ended_by(proc, signal.SIGINT, err)
    assert time.monotonic() - sent < 30, "the Ctrl-C was not seen while the cluster started"
    assert "nothing was written" in err and not out.exists()
    _no_process_left(proc.pid)


#: a sweep's table with 48 metric columns over 40 cases: 3 pages of histograms, 1 scatter figure
_METRICS = 48


@pytest.fixture(scope="module")
def sweep_table(data) -> Path:
    """A sweep directory as ``astrodyn sweep`` writes it (summary.csv, sweep.json): one
    dispersed parameter and 48 metrics that vary, so its report takes a few seconds."""
    import json

    import numpy as np

    d = data / "table"
    d.mkdir()
    rng = np.random.default_rng(3)
    columns = ["case", "status", "p", *[f"sat.m{k}" for k in range(_METRICS)], "wall_s"]
    lines = [",".join(columns)]
    for case in range(40):
        p = rng.uniform()
        lines.append(",".join([str(case), "ok", repr(p), *[repr(p * k + rng.normal()) for k in range(_METRICS)],
                               "0.01"]))
    (d / "summary.csv").write_text("\n".join(lines) + "\n")
    (d / "sweep.json").write_text(json.dumps({"seed": 0, "varies": [{"path": "p", "text": "p=uniform(0, 1)"}],
                                              "columns": {"p": "1", "wall_s": "s"}}))
    return d


def test_an_analyze_of_a_sweep_stopped_by_sigterm_keeps_the_earlier_report_whole(tmp_path, sweep_table, processes):
    """``astrodyn analyze SWEEP_DIR`` drew its figures straight into the report directory:
    a SIGTERM while it drew left an earlier report with some figures replaced and its old
    pages.  Now the report is made in a work directory and moved in once complete."""
    _analyze_stopped_by_sigterm_keeps_the_earlier_report(
        processes, tmp_path / "report", ["report.md", "report.json", "metrics-hist.png", "metrics-hist-2.png",
                                         "scatter-p.png"], sweep_table)


_SIGNAL_AS_AN_OUTPUT_IS_CREATED = """
import os, signal, sys
from astrodyn.recording import outputs
from astrodyn.signals import interruptible

real_close, real_mkdir = os.close, os.mkdir
def signal_self():
    os.kill(os.getpid(), getattr(signal, sys.argv[2]))

def close_then_signal(fd):  # the signal lands just after O_EXCL created the temporary file
    signal_self()
    real_close(fd)

def mkdir_then_signal(path, *args, **kwargs):  # the signal lands just after the work directory is made
    real_mkdir(path, *args, **kwargs)
    if os.path.basename(path).startswith(".analyze-"):
        signal_self()

def run():
    try:
        if sys.argv[3] == "merge":
            os.close = close_then_signal  # this process only
            outputs.write_atomically(sys.argv[1], lambda s: s.write(b"x"), suffix=".merging", hidden=True, replace=False)
        else:
            os.mkdir = mkdir_then_signal
            with outputs.staging_directory(sys.argv[1], "analyze") as work:
                (work / "report.md").write_text("x")
    finally:
        os.close, os.mkdir = real_close, real_mkdir
    return 0

sys.exit(interruptible(sys.argv[3], run))
"""


@pytest.mark.parametrize("sig", ["SIGHUP", "SIGTERM"])
@pytest.mark.parametrize(("tool", "out"), [("merge", "m.mcap"), ("analyze", "report")])
def test_a_signal_as_an_output_is_created_leaves_nothing(tmp_path, tool, out, sig):
    """A signal between the creation of an output's temporary file (merge: O_EXCL) or work
    directory (analyze: inside ``tempfile.mkdtemp``) and the moment its name is kept: it
    stayed behind although the tool said no output was left half-written (seen under three
    xdist workers as a merge's ``.m.*.mcap.merging``, and once in a fresh-clone run as an
    ``.analyze-PID-*`` in test_an_analyze_stopped_by_sigterm_keeps_the_earlier_report_whole,
    whose SIGTERM is sent when the work directory appears).  The signal is sent from inside
    the creation, every time, in a process of its own; the folder is left empty (analyze:
    neither the work directory nor the report directory made for it)."""
    proc = subprocess.run([sys.executable, "-c", _SIGNAL_AS_AN_OUTPUT_IS_CREATED, str(tmp_path / out), sig, tool],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 128 + getattr(signal, sig), proc.stderr[-2000:]
    assert list(tmp_path.iterdir()) == []
