"""Every flag of ``astrodyn bench SUITE`` is hostile input: a bad value is one line naming the
flag, what it accepts and what was given, exit status 2, no traceback, no allocation
(:mod:`astrodyn.bench.flags`).

No benchmark body runs here: each suite's ``parse_args`` is wrapped so that a value that got
through fails the test before ``main`` goes on.
"""

from __future__ import annotations

import importlib
import subprocess
import sys

import pytest

from astrodyn.bench import SUITES, main as bench_main, walker_planes
from astrodyn.bench.flags import float_in, int_in, int_list_in, parse_int

HUGE = "1" + "0" * 24  # past every bound, --seed's 2^64 - 1 too
# refused by every number flag: not finite, not a number, beyond any bound
ALWAYS_BAD = [HUGE, "1e400", "nan", "inf", "-inf", "abc", "", " ", "0x10", "1e999999"]
INT_BAD = [*ALWAYS_BAD, "1.5", "2e-1"]
LIST_BAD = [*INT_BAD, "1,,2", "1,", ",", "1,abc", f"1,{HUGE}", "1;2", ",".join(["1"] * 50)]

# suite -> [(flag, kind, lowest accepted)]; kind: int, float or list
NUMBER_FLAGS: dict[str, list[tuple[str, str, float]]] = {
    "orbit": [("--sizes", "list", 1), ("--sample", "int", 1), ("--compare", "int", 0), ("--seed", "int", 0),
              ("--repeats", "int", 1)],
    "attitude": [("--repeats", "int", 1)],
    "service": [("--duration", "float", 1), ("--load-duration", "float", 1), ("--small", "int", 1),
                ("--bodies", "int", 1), ("--flood-steps", "int", 0), ("--flood-queues", "list", 1)],
    "sweep": [("--repeat", "int", 1)],
    "soak": [("--minutes", "float", 0.5), ("--sample", "float", 1), ("--satellites", "int", 1),
             ("--kill-logger-every", "float", 5)],
    "encode": [("--bodies", "int", 1), ("--repeat", "int", 1)],
    "auth": [("--bodies", "int", 1), ("--repeat", "int", 1)],
    "calls": [("--repeat", "int", 1), ("--load-threads", "int", 1), ("--load-worker", "float", 1)],
    "view": [("--wall", "float", 1), ("--rounds", "int", 1)],
    "control": [("--bodies", "list", 1), ("--steps", "int", 50)],
    "flexible": [("--repeats", "int", 1)],
}


def _number_cases():
    for suite, flags in NUMBER_FLAGS.items():
        for flag, kind, lowest in flags:
            bad = {"int": INT_BAD, "float": ALWAYS_BAD, "list": LIST_BAD}[kind]
            below = {"-1", *(["0"] if lowest > 0 else []), str(lowest - 0.5) if kind == "float" else str(lowest - 1)}
            for value in [*sorted(below), *bad]:
                yield pytest.param(suite, flag, value, id=f"{suite} {flag}={value[:20]!r}")


@pytest.fixture
def no_run(monkeypatch):
    """Wrap every suite's ``parse_args``: options that parse fail the test (nothing runs)."""

    def guard(module):
        parse = module.parse_args

        def parse_args(argv=None):
            args = parse(argv)
            raise AssertionError(f"{module.__name__}: {argv} was accepted: {args}")

        return parse_args

    for name in SUITES.values():
        module = importlib.import_module(name)
        monkeypatch.setattr(module, "parse_args", guard(module))


def _refused(capsys, argv: list[str], suite: str) -> str:
    """Run ``astrodyn bench SUITE argv`` in this process; its stderr, checked to be
    argparse's usage error (exit 2)."""
    with pytest.raises(SystemExit) as exc:
        importlib.import_module(SUITES[suite]).main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return err


@pytest.mark.parametrize(("suite", "flag", "value"), list(_number_cases()))
def test_a_bad_number_is_refused_naming_the_flag(suite, flag, value, capsys, no_run):
    err = _refused(capsys, [f"{flag}={value}"], suite)
    assert f"astrodyn bench {suite}: error: argument {flag}: expected " in err, err
    assert f"got {value[:40]!r}" in err or f"got {value[:40] + '...'!r}" in err, err
    assert " <= N <= " in err or " <= X <= " in err, err  # the allowed values


@pytest.mark.parametrize(("suite", "flag", "value"), [
    ("encode", "--bodies", "0"), ("encode", "--bodies", "-1"), ("control", "--bodies", "-1"),
    ("auth", "--repeat", "-1"), ("soak", "--minutes", "-1"), ("view", "--rounds", "-5"),
])
def test_a_negative_number_as_its_own_argument(suite, flag, value, capsys, no_run):
    err = _refused(capsys, [flag, value], suite)
    assert f"argument {flag}: expected " in err and f"got {value!r}" in err, err


def test_a_huge_value_is_refused_before_any_allocation(capsys, no_run):
    err = _refused(capsys, ["--bodies", "100000000000"], "encode")  # was a 2 TiB allocation
    assert "expected an integer 1 <= N <= 1000000, got '100000000000'" in err
    long = "9" * 100_000  # far past Python's 4300-digit limit of int(str): refused, not converted
    err = _refused(capsys, ["--sizes", long], "orbit")
    assert "argument --sizes: expected" in err and len(err) < 2000  # the value is cut when echoed


def _path_cases(tmp):
    a_file = tmp / "a-file"
    a_file.write_text("x")
    missing = tmp / "missing" / "deeper"
    under_a_file = a_file / "sub"
    return {
        ("orbit", "--markdown"): ["", str(tmp), str(missing / "t.md"), str(under_a_file)],
        ("service", "--md"): ["", str(tmp), str(missing / "t.md")],
        ("service", "--json"): ["", str(tmp), str(under_a_file)],
        ("service", "--keep"): ["", str(a_file), str(under_a_file)],
        ("sweep", "--out"): ["", str(tmp), str(missing / "t.md")],
        ("attitude", "--out"): ["", str(a_file), str(under_a_file)],
        ("soak", "--out"): ["", str(a_file), str(under_a_file)],
        ("view", "--config"): ["", str(tmp), str(missing), str(a_file), "/dev/zero"],
        ("encode", "--baseline"): ["", str(tmp), str(missing)],
        ("view", "--subscribe"): ["", "2d", "ALL"],
    }


def test_a_bad_path_is_refused_naming_the_flag(tmp_path, capsys, no_run):
    for (suite, flag), values in _path_cases(tmp_path).items():
        for value in values:
            err = _refused(capsys, [f"{flag}={value}"], suite)
            assert f"astrodyn bench {suite}: error: argument {flag}: " in err, (suite, flag, value, err)


def test_calls_baseline_is_one_line_and_status_2(tmp_path, capsys, monkeypatch):
    from astrodyn.bench import calls

    monkeypatch.setattr(calls, "compare", lambda *a: pytest.fail("the comparison ran"))
    for value in ("", str(tmp_path), str(tmp_path / "nowhere")):
        assert calls.main(["--baseline", value]) == 2
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and err.startswith("astrodyn bench calls: --baseline: expected a source tree"), err


def test_the_flood_publisher_child_checks_its_arguments(capsys, monkeypatch):
    from astrodyn.bench import service

    monkeypatch.setattr(service, "flood_publisher", lambda *a: pytest.fail("the publisher ran"))
    for rest in ([], ["tcp/127.0.0.1:7447", "s", "10"], ["tcp/127.0.0.1:7447", "s", "0", "10"],
                 ["tcp/127.0.0.1:7447", "s", "10", HUGE], ["not an endpoint", "s", "10", "10"]):
        with pytest.raises(SystemExit) as exc:
            service.main(["--flood-publisher", *rest])
        assert exc.value.code == 2
        assert "Traceback" not in capsys.readouterr().err


def test_all_checks_every_suite_before_the_first_runs(capsys, monkeypatch):
    for name in SUITES.values():
        monkeypatch.setattr(importlib.import_module(name), "main", lambda argv=None: pytest.fail("a suite ran"))
    with pytest.raises(SystemExit) as exc:
        bench_main(["all", "--repeats", "0"])  # orbit's flag, refused by orbit
    assert exc.value.code == 2 and "argument --repeats: expected an integer 1 <= N <= 100, got '0'" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        bench_main(["all", "--quick", "--repeats", "3"])  # orbit takes --repeats, service does not: refused before orbit runs
    assert exc.value.code == 2 and "astrodyn bench service: error: unrecognized arguments: --repeats 3" in capsys.readouterr().err


def test_good_values_and_defaults_parse():
    from astrodyn.bench import control, orbit, service, soak

    args = orbit.parse_args(["--sizes", " 1, 1e3 ,4000000", "--seed", "0", "--compare", "0"])
    assert args.sizes == [1, 1000, 4_000_000] and args.seed == 0 and args.compare == 0
    assert orbit.parse_args([]).sizes == [1, 1000, 1_000_000]  # a string default goes through the type
    assert orbit.parse_args(["--quick"]).sizes == [1, 1000]
    assert control.parse_args([]).bodies == [1, 100, 1000]
    assert service.parse_args(["--flood-steps", "0"]).flood_queues == [65536, 64]
    assert soak.parse_args(["--minutes", "2", "--sample", "10", "--out", "soak-here-not-created"]).minutes == 2.0


def test_the_helpers():
    assert parse_int("1_000") == 1000 and parse_int("1e6") == 10**6 and parse_int("-2.0") == -2
    assert parse_int("1.5") is None and parse_int("nan") is None and parse_int("1e400") is None
    assert int_in(1, 10)("10") == 10
    assert float_in(0.5, 2)("0.5") == 0.5
    assert int_list_in(0, 5, most=3)("0,5,1") == [0, 5, 1]
    for fn, text in ((int_in(1, 10), "11"), (float_in(0.5, 2), "2.0001"), (int_list_in(0, 5, most=3), "1,2,3,4")):
        with pytest.raises(Exception, match="expected"):
            fn(text)


@pytest.mark.parametrize(("satellites", "most", "planes"), [(100, 10, 10), (25, 10, 1), (1000, 20, 20), (7, 20, 1),
                                                            (60, 10, 6), (2000, 10, 10), (1, 1, 1), (97, 97, 1)])
def test_walker_planes_divide_the_satellites(satellites, most, planes):
    assert walker_planes(satellites, most) == planes


@pytest.mark.parametrize("argv", [["encode", "--bodies", "0"], ["control", "--bodies", "abc"]])
def test_the_command_exits_2_without_a_traceback(argv):
    done = subprocess.run([sys.executable, "-m", "astrodyn", "bench", *argv], capture_output=True, text=True,
                          timeout=60, stdin=subprocess.DEVNULL)
    assert done.returncode == 2, done
    assert "Traceback" not in done.stderr and done.stdout == ""
    last = done.stderr.strip().splitlines()[-1]
    assert last.startswith(f"astrodyn bench {argv[0]}: error: argument --bodies: expected "), done.stderr
    assert last.endswith(f"got {argv[2]!r}"), done.stderr


@pytest.mark.parametrize("satellites", [1, 7, 25, 100])
def test_every_accepted_constellation_size_is_a_valid_scene(satellites, tmp_path):
    """``--small``, ``--bodies`` (service) and ``--satellites`` (soak) make Walker scenes:
    a size with no divisor near a tenth of it (a prime, < 20) is a single plane, phasing 0."""
    from astrodyn.bench.service import Scene, scene_config
    from astrodyn.bench.soak import _scene
    from astrodyn.scenario import load
    from astrodyn.scenario.catalogue import config_path

    template = config_path("constellation-1000").read_text()
    for planes in {walker_planes(satellites, 20), walker_planes(satellites, satellites)}:
        path = tmp_path / f"c{planes}.toml"
        path.write_text(scene_config(Scene("c", satellites, planes, 2.0), template))
        load(path)
    load(_scene(tmp_path, satellites))
