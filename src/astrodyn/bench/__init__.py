"""Speed-against-error benchmarks: ``astrodyn bench SUITE`` (:data:`SUITES`; ``all`` runs every
one but those of :data:`LEFT_OUT_OF_ALL`, ``all --quick`` each in its smoke form,
:data:`QUICK_ARGS`).

Each benchmark module exposes ``main(argv) -> int``, prints a table of ns per
state (or step) and max error, and reports ratios against REBOUND / scipy
measured in the same process; and ``parse_args(argv)``, its options checked with the
types of :mod:`astrodyn.bench.flags` (a bad value: argparse's one-line error naming the
flag, exit 2).
"""

from __future__ import annotations

import argparse
import importlib
import inspect
import json
import os
import platform
import subprocess
import sys
from collections.abc import Iterable, Sequence

SUITES = {
    "orbit": "astrodyn.bench.orbit",
    "attitude": "astrodyn.bench.attitude",
    "service": "astrodyn.bench.service",
    "sweep": "astrodyn.bench.sweep",
    "soak": "astrodyn.bench.soak",
    "encode": "astrodyn.bench.encode",
    "auth": "astrodyn.bench.auth",
    "calls": "astrodyn.bench.calls",
    "view": "astrodyn.bench.view",
    "control": "astrodyn.bench.control",
    "flexible": "astrodyn.bench.flexible",
}

#: Suites ``astrodyn bench all`` does not run, and why.
LEFT_OUT_OF_ALL = {"soak": "a real-time soak of `astrodyn serve`, an hour by default: run `astrodyn bench soak` on its own"}

#: The options ``astrodyn bench all --quick`` gives each suite: its smoke form (seconds to a
#: minute or two each), placed before the options given to ``all`` (which win).
QUICK_ARGS: dict[str, list[str]] = {
    "orbit": ["--quick"],
    "attitude": ["--quick"],
    "service": ["--bodies", "10"],
    "sweep": ["--quick"],
    "encode": ["--bodies", "100", "--repeat", "1"],
    "auth": ["--bodies", "100", "--repeat", "1"],
    "calls": ["--repeat", "1"],
    "view": ["--wall", "1", "--rounds", "1"],
    "control": ["--bodies", "1,10", "--steps", "50"],
    "flexible": ["--quick"],
}


#: What ``astrodyn bench all --quick`` prints first and last: its figures are a smoke test's.
QUICK_NOTE = ("astrodyn bench all --quick: a smoke run (each suite in a small form): the figures are not "
              "representative and not comparable with docs/benchmarks.md (control's 50 steps are mostly start-up, "
              "view's one 1-s pair mostly noise, attitude's exact method unchecked); run a suite without --quick "
              "to measure")


def cpu_model() -> str:
    """The CPU model name from /proc/cpuinfo (``platform.processor()`` elsewhere)."""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def print_table(header: Sequence[str], rows: Iterable[Sequence[object]], align: str | None = None) -> None:
    """Print a Markdown table: the ``header`` cells, then one line per row of cells (already
    formatted; printed with ``str``).  ``align``: one letter per column, ``l`` (default) or
    ``r`` (right-aligned, for numbers)."""
    print("| " + " | ".join(header) + " |")
    print("| " + " | ".join("---:" if a == "r" else "---" for a in (align or "l" * len(header))) + " |")
    for row in rows:
        print("| " + " | ".join(str(cell) for cell in row) + " |")


def walker_planes(satellites: int, most: int) -> int:
    """Planes of a Walker constellation of ``satellites``: the largest divisor of it (the
    scenario wants equal planes) at most ``most`` and at most a tenth of it (at least 1)."""
    planes = max(1, min(most, satellites // 10))
    while satellites % planes:
        planes -= 1
    return planes


def env_for_source(src: str | None, **extra: str) -> dict:
    """Environment of a child process that imports astrodyn from the source tree ``src``
    (``None``: this one), plus ``extra`` variables."""
    env = {**os.environ, **extra}
    if src is not None:
        env["PYTHONPATH"] = src + os.pathsep + env.get("PYTHONPATH", "")
    return env


def best_seconds_per_call(fn, number: int, repeat: int) -> float:
    """Seconds per call of ``fn``: the best of ``repeat`` rounds of ``number`` calls, after
    one warm-up call (the least disturbed round on a shared machine)."""
    import time

    fn()
    out = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        for _ in range(number):
            fn()
        out = min(out, (time.perf_counter() - t0) / number)
    return out


def call_in_tree(fn, args: tuple, src: str | None, timeout_s: float = 900) -> object:
    """``fn(*args)`` in a child process importing astrodyn from the source tree ``src``: the
    before/after benchmarks time the same function against an older tree in one run.
    ``fn`` must be self-contained (imports inside; it may use :func:`best_seconds_per_call`,
    whose source goes along) and return something JSON can carry."""
    code = (inspect.getsource(best_seconds_per_call) + "\n" + inspect.getsource(fn)
            + f"\nimport json\nprint(json.dumps({fn.__name__}(*{args!r})))\n")
    done = subprocess.run([sys.executable, "-c", code], env=env_for_source(src), capture_output=True, text=True,
                          timeout=timeout_s, stdin=subprocess.DEVNULL)
    if done.returncode != 0:
        raise RuntimeError(f"{fn.__name__} in {src or 'this tree'}: child failed: {done.stderr.strip().splitlines()[-1:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def all_parser() -> argparse.ArgumentParser:
    """The options of ``astrodyn bench all`` itself (``--quick``, ``--help``); any other option
    is passed to every suite."""
    from astrodyn.bench.attitude import DEFAULT_OUT

    suites = [n for n in SUITES if n not in LEFT_OUT_OF_ALL]
    left_out = "; ".join(f"{n}: {why}" for n, why in LEFT_OUT_OF_ALL.items())
    ap = argparse.ArgumentParser(
        prog="astrodyn bench all", allow_abbrev=False, usage="%(prog)s [-h] [--quick] [SUITE OPTIONS]",
        description=f"Run the benchmark suites one after the other: {', '.join(suites)}. Left out: {left_out}.",
        epilog="Any other option is passed to every suite, so it must be one every suite takes (see astrodyn bench "
               "SUITE --help); every suite's options are checked before the first one runs. The attitude suite writes "
               f"bench-attitude.md and .png into ./{DEFAULT_OUT}. Exit status: 0 every suite passed, 1 a suite reported a "
               "failure, 2 a bad option.")
    ap.add_argument("--quick", action="store_true",
                    help="a smoke run: each suite in a small form, " + "; ".join(
                        f"{n} {' '.join(QUICK_ARGS[n])}" for n in suites))
    return ap


def suite_args(rest: list[str], quick: bool) -> dict[str, list[str]]:
    """The options ``astrodyn bench all`` gives each suite it runs: ``rest`` (the options
    not its own), after the suite's :data:`QUICK_ARGS` with ``quick``."""
    return {n: [*(QUICK_ARGS[n] if quick else []), *rest] for n in SUITES if n not in LEFT_OUT_OF_ALL}


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        print("usage: astrodyn bench {" + "|".join([*SUITES, "all"]) + "} [OPTIONS]\n"
              "  astrodyn bench SUITE --help: a suite's options; astrodyn bench all --help: what `all` runs "
              f"(every suite but {', '.join(LEFT_OUT_OF_ALL)}) and its --quick")
        return 0 if argv else 2
    name, rest = argv[0], argv[1:]
    if name != "all" and name not in SUITES:
        print(f"astrodyn bench: unknown suite {name!r}; expected one of: {', '.join(SUITES)}, all", file=sys.stderr)
        return 2
    if name != "all":
        return int(importlib.import_module(SUITES[name]).main(rest) or 0)
    own, rest = all_parser().parse_known_args(rest)
    runs = suite_args(rest, own.quick)
    for n, args in runs.items():  # every suite's options checked before the first runs (an error exits 2 here, not an hour in)
        importlib.import_module(SUITES[n]).parse_args(args)
    if own.quick:
        print(QUICK_NOTE, flush=True)
    rc = 0
    for n, args in runs.items():
        rc |= int(importlib.import_module(SUITES[n]).main(args) or 0)
    if own.quick:
        print(f"\n{QUICK_NOTE}")
    return rc


if __name__ == "__main__":
    sys.exit(main())
