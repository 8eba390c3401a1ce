"""Hostile configs and command-line flags found by fuzzing (random structured mutations of
configs/*.toml fed to the loader, and hostile flags of ``run``, ``serve`` and ``sweep``).

The contract (docs/architecture.md, section 6; tests/test_hostile_configs.py): a bad config
or flag ends with one line naming the field or flag, what was expected and what was given,
exit status 2, in seconds, and nothing written or overwritten.  Each test feeds the exact
input that used to crash, hang or write.
"""

from __future__ import annotations

import subprocess
import sys
import time
import tomllib
from pathlib import Path

import pytest

from _config_text import assert_config_error, edited
from astrodyn import sweep
from astrodyn.scenario import ScenarioError, load_dict, loads
from astrodyn.scenario.fields import flag_quantity
from astrodyn.service import runner, serve

CONFIGS = Path(__file__).resolve().parent.parent / "configs"
DEMO = (CONFIGS / "demo.toml").read_text()
SHORT = ('[scenario]\nname = "short"\nepoch = "2026-03-20T12:00:00 UTC"\nduration = "5 s"\nrate = "1 Hz"\n'
         '[[bodies]]\nname = "sat"\n[bodies.orbit]\na = "7000 km"\n')


@pytest.fixture
def short(tmp_path):
    cfg = tmp_path / "short.toml"
    cfg.write_text(SHORT)
    return cfg


def _nested(depth: int, leaf=1):
    for _ in range(depth):
        leaf = [leaf]
    return leaf


# --------------------------------------------------------------------------- the loader


def test_a_deeply_nested_value_is_refused_naming_the_field():
    """A value 5000 lists deep where a model name belongs (load_dict, as ``astrodyn sweep``
    calls it) raised RecursionError while the error message printed the value."""
    cfg = tomllib.loads(DEMO)
    cfg["bodies"][0]["attitude"]["model"] = _nested(5000)
    with pytest.raises(ScenarioError) as info:
        load_dict(cfg, source="x.toml")
    msg = str(info.value)
    assert "bodies[0] (iss).attitude.model: expected one of none, torque_free, gravity_gradient" in msg, msg
    assert "nested" in msg and len(msg) < 400, msg


def test_the_deepest_nesting_toml_parses_is_refused_naming_the_field():
    """A fault value nested just less deep than tomllib's own limit (494 lists from the
    command line) crashed ``astrodyn run`` with RecursionError; the depth is found here
    from the top, as it depends on the stack the test runs on."""
    det = (CONFIGS / "detumble.toml").read_text()
    old = 'value = ["2e-4 rad/s", "-1e-4 rad/s", 0]'
    for depth in range(560, 400, -1):
        text = edited(det, **{old: "value = " + "[" * depth + "1" + "]" * depth})
        with pytest.raises(ScenarioError) as info:
            loads(text, source="x.toml")
        if "nesting too deep" not in str(info.value):
            break
    message = str(info.value)
    assert "x.toml: control.faults[0].value: expected a list of 3 values, each an angular velocity" in message, message
    assert "nested more than" in message and len(message) < 400 and "\n" not in message, message


def test_a_megabyte_unknown_key_is_named_in_a_short_line():
    """An unknown key of 10^6 characters was echoed twice into a 2 MB error line; a key
    with a newline (a TOML quoted key) split the message over two lines."""
    text = edited(DEMO, **{'rate = "1 Hz"': 'rate = "1 Hz"\n' + "x" * 1_000_000 + " = 1"})
    message = assert_config_error(text, "scenario.xxxxxxxx", "expected one of the keys name, description, epoch")
    assert len(message) < 600, len(message)
    text = edited(DEMO, **{'rate = "1 Hz"': 'rate = "1 Hz"\n"rat\\ne" = 1'})
    assert_config_error(text, "scenario.rat\\ne: expected one of the keys name, description", 'unknown key "rat\\ne"')


def test_more_bodies_than_channels_are_refused_before_reading_them():
    """65,534 [[bodies]] (each records at least one state channel; MCAP channel ids are
    uint16, two of them taken by events and status) were all parsed first: about 47 s for
    100,000 bodies before the refusal."""
    body = {"name": "b", "orbit": {"a": "7000 km"}}
    cfg = {"scenario": tomllib.loads(SHORT)["scenario"], "bodies": [body] * 65_534}
    t0 = time.monotonic()
    with pytest.raises(ScenarioError) as info:
        load_dict(cfg, source="x.toml")
    assert time.monotonic() - t0 < 2
    msg = str(info.value)
    assert "x.toml: bodies: expected at most 65533 bodies" in msg and "got 65534 bodies" in msg, msg


def test_thousands_of_copies_of_one_body_are_refused_at_the_first_copy():
    """60,000 copies of one body: refused at bodies[1] (was: after parsing all 60,000)."""
    cfg = tomllib.loads(DEMO)
    cfg["bodies"] = [cfg["bodies"][1]] * 60_000
    t0 = time.monotonic()
    with pytest.raises(ScenarioError) as info:
        load_dict(cfg, source="x.toml")
    assert time.monotonic() - t0 < 2
    assert 'bodies[1].name: expected a unique body name (also bodies[0]), got "cubesat"' in str(info.value)


# --------------------------------------------------------------------------- astrodyn run


def test_run_json_naming_the_config_is_refused_before_the_run(short, capsys):
    """``run CFG --json CFG`` overwrote the config with the result after the run (exit 0)."""
    before = short.read_bytes()
    assert runner.main([str(short), "--out", str(short.parent / "o.mcap"), "--json", str(short)]) == 2
    err = capsys.readouterr().err
    assert f"--json {short}: names a file of the run" in err and "expected a new .json path" in err, err
    assert short.read_bytes() == before
    assert list(short.parent.iterdir()) == [short]


@pytest.mark.parametrize("json_path,says", [
    ("nodir/x.json", "expected a file in an existing, writable directory"),  # was: FileNotFoundError after the run
    (".", "expected a file path, got a directory"),  # was: IsADirectoryError after the run
    ("short.toml.bak", "exists and is not an earlier JSON result; it is never overwritten"),
])
def test_run_json_path_is_checked_before_the_run(short, capsys, json_path, says):
    (short.parent / "short.toml.bak").write_text("keep me\n")
    out = short.parent / "o.mcap"
    assert runner.main([str(short), "--out", str(out), "--json", str(short.parent / json_path)]) == 2
    err = capsys.readouterr().err
    assert "--json" in err and says in err, err
    assert not out.exists() and (short.parent / "short.toml.bak").read_text() == "keep me\n"


@pytest.mark.parametrize("value", ["nan", "-1", "0"])
def test_run_timeout_must_be_positive_wall_seconds(short, capsys, value):
    """``--timeout nan`` meant no timeout; -1 and 0 started the run and failed it at once,
    leaving a partial recording (exit 1)."""
    with pytest.raises(SystemExit) as info:
        runner.main([str(short), "--out", str(short.parent / "o.mcap"), "--timeout", value])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert f"argument --timeout: expected wall seconds, a finite number > 0, got '{value}'" in err, err
    assert list(short.parent.iterdir()) == [short]


@pytest.mark.parametrize("argv,says", [
    (["--connect", "garbage"], "--connect: expected Zenoh endpoints like 'tcp/127.0.0.1:7447', got 'garbage'"),
    (["--out", "x" * 300 + ".mcap"], ": expected a usable file path, got File name too long"),
    (["--out", ""], "--out: expected a file path, got an empty string"),
    (["--resume", ""], "--resume: expected the MCAP recording to continue, got an empty string"),  # was: ignored
])
def test_run_flags_refused_before_anything_starts(short, capsys, monkeypatch, argv, says):
    """A bad --connect restarted the logger 5 times for 20 s (exit 1); a 300-character --out
    raised OSError with a traceback; --out '' silently recorded to <scenario>.mcap."""
    monkeypatch.chdir(short.parent)
    assert runner.main([str(short), *(["--out", "o.mcap"] if "--out" not in argv else []), *argv]) == 2
    err = capsys.readouterr().err
    assert says in err, err
    assert list(short.parent.iterdir()) == [short]


# --------------------------------------------------------------------------- astrodyn serve


@pytest.mark.parametrize("argv,says", [
    (["--roll-size", "1"], "--roll-size: expected bytes 1048576 (1 MiB) <= N <= 1125899906842624 (1 PiB), got 1"),
    (["--roll-size", "-5"], "--roll-size: expected bytes 1048576 (1 MiB) <= N"),  # was: the logger crashed 5 times
    (["--roll-interval", "nan"], "--roll-interval: expected wall seconds 1 <= S <= 7.8894e+09, got nan"),
    (["--roll-interval", "0.001"], "--roll-interval: expected wall seconds 1 <= S"),  # was: a file per flush
    (["--roll-interval", "0.5 s"], "--roll-interval: expected wall seconds 1 <= S <= 7.8894e+09, got 0.5"),
    (["--roll-size", "1 KiB"], "--roll-size: expected bytes 1048576 (1 MiB) <= N <= 1125899906842624 (1 PiB), got 1024"),
    (["--port", "70000"], "--port: expected a port 0..65535 (0: a free one), got 70000"),  # was: BusError traceback
    (["--connect", "garbage"], "--connect: expected Zenoh endpoints like 'tcp/127.0.0.1:7447', got 'garbage'"),
    (["--out", "short.toml/x.mcap"], "--out short.toml/x.mcap: expected a file path in a directory that can be created"),
    (["--out", "newdir/sub/x.mcap", "--loggers", "99"], "--loggers: expected 1 <= N <= 8, got 99"),  # left newdir/sub
])
def test_serve_flags_refused_before_anything_starts(short, capsys, monkeypatch, argv, says):
    monkeypatch.chdir(short.parent)
    assert serve.main([str(short.name), *(["--out", "o.mcap"] if "--out" not in argv else []), *argv]) == 2
    err = capsys.readouterr().err
    assert says in err, err
    assert list(short.parent.iterdir()) == [short], "a refused serve wrote something"


@pytest.mark.parametrize("value", ["1e400", "nan", "0", "Infinity"])
def test_serve_rate_is_a_real_time_factor_or_the_word_inf(short, capsys, value):
    """``--rate 1e400`` (float() gives inf) ran as fast as possible, while 1e12 was refused."""
    with pytest.raises(SystemExit) as info:
        serve.main([str(short), "--out", str(short.parent / "o.mcap"), "--rate", value])
    assert info.value.code == 2
    assert f'argument --rate: expected a real-time factor with 0.001 <= x <= 1e+06 or "inf", got {value!r}' in \
        capsys.readouterr().err
    assert list(short.parent.iterdir()) == [short]


@pytest.mark.parametrize("value", ["nan", "-1"])
def test_serve_max_wall_must_be_positive_wall_seconds(short, capsys, value):
    """``--max-wall nan`` never stopped; ``--max-wall -1`` hung for a minute in stop()."""
    with pytest.raises(SystemExit) as info:
        serve.main([str(short), "--out", str(short.parent / "o.mcap"), "--max-wall", value])
    assert info.value.code == 2
    assert f"argument --max-wall: expected wall seconds, a finite number > 0, got '{value}'" in capsys.readouterr().err
    assert list(short.parent.iterdir()) == [short]


# --------------------------------------------------------------------------- astrodyn sweep


def test_sweep_local_workers_are_bounded(short, capsys):
    """``--workers 100000`` started a LocalCluster of 100,000 processes (hung the machine)."""
    import os

    argv = [str(short), "--vary", "bodies.sat.orbit.e=uniform(0, 0.1)", "-n", "1", "--out", str(short.parent / "sw")]
    assert sweep.main([*argv, "--workers", "100000"]) == 2
    err = capsys.readouterr().err
    assert f"--workers: expected at most {4 * (os.cpu_count() or 1)} local worker processes" in err, err
    assert "got 100000" in err
    assert list(short.parent.iterdir()) == [short]


@pytest.mark.parametrize("flags,says", [
    (["--chunk", "0"], "--chunk: expected an integer >= 1, got 0"),  # created --out first
    (["--case", "5"], "--case: expected 0 <= K < 2 (the sweep's -n), got 5"),  # created --out first
    (["--out", "short.toml/x"], "--out short.toml/x: expected a directory that can be created, got Not a directory"),
])
def test_sweep_refusals_create_nothing(short, capsys, monkeypatch, flags, says):
    monkeypatch.chdir(short.parent)
    argv = [short.name, "--vary", "bodies.sat.orbit.e=uniform(0, 0.1)", "-n", "2", "--workers", "0"]
    assert sweep.main([*argv, *(["--out", "sw"] if "--out" not in flags else []), *flags]) == 2
    assert says in capsys.readouterr().err
    assert list(short.parent.iterdir()) == [short]


# --------------------------------------------------------------------------- the command line


def test_cli_run_json_naming_the_config_exits_2_and_keeps_it(short):
    """The same through ``astrodyn run``: exit 2, one line, no traceback, the config kept."""
    before = short.read_bytes()
    proc = subprocess.run([sys.executable, "-m", "astrodyn", "run", str(short), "--out", str(short.parent / "o.mcap"),
                           "--json", str(short), "--timeout", "20"], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr and "--json" in proc.stderr, proc.stderr
    assert short.read_bytes() == before
    assert list(short.parent.iterdir()) == [short]


@pytest.mark.parametrize("command", ["serve", "replay"])
def test_a_foxglove_port_in_use_is_refused_before_anything_starts(tmp_path, command):
    """``--foxglove PORT`` on a port another process listens on: the view's own process
    would fail to bind it, unseen (replay printed the ws:// URL and served nothing); now
    the flag is refused, exit 2, naming the port.  Checked by parsing alone (in process)."""
    import socket

    from astrodyn.service import replay

    with socket.socket() as listener:
        listener.bind(("127.0.0.1", 0))
        listener.listen()
        port = listener.getsockname()[1]
        main = serve.main if command == "serve" else replay.main
        with pytest.raises(SystemExit) as exit_info:
            main([str(tmp_path / "x.toml" if command == "serve" else tmp_path / "x.mcap"), "--foxglove", str(port)])
    assert exit_info.value.code == 2
    assert not list(tmp_path.iterdir())  # nothing written


@pytest.mark.parametrize("command", ["run", "serve"])
@pytest.mark.parametrize("value", ["nan", "-1", "inf", "1e999", "x"])
def test_stall_timeout_must_be_finite_wall_seconds(short, capsys, command, value):
    """``--stall-timeout`` (0: never) refuses what is not a finite number >= 0, before anything starts."""
    main = runner.main if command == "run" else serve.main
    with pytest.raises(SystemExit) as info:
        main([str(short), "--out", str(short.parent / "o.mcap"), "--stall-timeout", value])
    assert info.value.code == 2
    assert (f"argument --stall-timeout: expected wall seconds, a finite number >= 0 (0: never), got '{value}'"
            in capsys.readouterr().err)
    assert list(short.parent.iterdir()) == [short]


@pytest.mark.parametrize("args, error", [(["--figures-for", "-1"], "--figures-for: expected an integer >= 0, got -1"),
                                         (["--bodies", "nope*"], "--bodies: 'nope*' matches no body of the recording"),
                                         (["--figures-for", "x"], "argument --figures-for: invalid int value: 'x'")])
def test_analyze_bad_body_and_figure_flags_are_clear(tmp_path, capsys, args, error):
    """Hostile ``analyze`` flags: an error naming the flag, no report directory written."""
    from _recordings import LEO_TWO_BODIES, record
    from astrodyn import analysis

    path = tmp_path / "two.mcap"
    record(path, LEO_TWO_BODIES.format(name="two", duration="20 s", rate="1 Hz"))
    try:
        code = analysis.main([str(path), "--out", str(tmp_path / "rep"), *args])
    except SystemExit as exc:  # argparse's own refusals
        code = exc.code
    assert code in (1, 2) and error in capsys.readouterr().err
    assert not (tmp_path / "rep").exists()


@pytest.mark.parametrize("size_text,interval_text,size,interval", [
    ("256 MB", "1 h", 256_000_000, 3600.0),  # what the config takes (newcomer walk: "invalid int value")
    ("1 GiB", "90min", 2**30, 5400.0),
    ("1048576", "30", 2**20, 30.0),  # plain bytes and seconds as before
    ("1.5e6", "2.5", 1_500_000, 2.5),
])
def test_serve_roll_flags_take_the_configs_quantities(size_text, interval_text, size, interval):
    got_size = flag_quantity("bytes", "bytes")(size_text)
    assert got_size == size and type(got_size) is int  # the logger's --roll-size is an int
    assert flag_quantity("time", "seconds")(interval_text) == interval


@pytest.mark.parametrize("argv,says", [
    (["--roll-interval", "1 hx"], 'argument --roll-interval: expected a time, e.g. "90 min", or a number of seconds'),
    (["--roll-size", "12 parsecs"], 'argument --roll-size: expected a size, e.g. "256 MB", or a number of bytes'),
])
def test_serve_roll_flags_that_are_no_quantity_say_what_they_take(short, capsys, monkeypatch, argv, says):
    monkeypatch.chdir(short.parent)
    with pytest.raises(SystemExit) as exited:
        serve.main([str(short.name), "--out", "o.mcap", *argv])
    assert exited.value.code == 2
    err = capsys.readouterr().err
    assert says in err and "Traceback" not in err, err
    assert list(short.parent.iterdir()) == [short]
