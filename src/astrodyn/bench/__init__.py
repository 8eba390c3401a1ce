"""Speed-against-error benchmarks: ``astrodyn bench SUITE`` (:data:`SUITES`; ``all`` runs every one but the soak).

Each benchmark module exposes ``main(argv) -> int``, prints a table of ns per
state (or step) and max error, and reports ratios against REBOUND / scipy
measured in the same process; and ``parse_args(argv)``, its options checked with the
types of :mod:`astrodyn.bench.flags` (a bad value: argparse's one-line error naming the
flag, exit 2).
"""

from __future__ import annotations

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


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        print("usage: astrodyn bench {" + "|".join([*SUITES, "all"]) + "} [OPTIONS]")
        return 0 if argv else 2
    name, rest = argv[0], argv[1:]
    names = [n for n in SUITES if n != "soak"] if name == "all" else [name]  # the soak takes an hour
    for n in names:
        if n not in SUITES:
            print(f"astrodyn bench: unknown suite {n!r}; expected one of: {', '.join(SUITES)}, all", file=sys.stderr)
            return 2
    if name == "all":  # every suite's options checked before the first runs (an error exits 2 here, not an hour in)
        for n in names:
            importlib.import_module(SUITES[n]).parse_args(rest)
    rc = 0
    for n in names:
        rc |= int(importlib.import_module(SUITES[n]).main(rest) or 0)
    return rc


if __name__ == "__main__":
    sys.exit(main())
