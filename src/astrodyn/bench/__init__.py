"""Speed-against-error benchmarks: ``astrodyn bench orbit|attitude|service|all``.

Each benchmark module exposes ``main(argv) -> int``, prints a table of ns per
state (or step) and max error, and reports ratios against REBOUND / scipy
measured in the same process.
"""

from __future__ import annotations

import importlib
import platform
import sys

SUITES = {
    "orbit": "astrodyn.bench.orbit",
    "attitude": "astrodyn.bench.attitude",
    "service": "astrodyn.bench.service",
    "sweep": "astrodyn.bench.sweep",
    "soak": "astrodyn.bench.soak",
    "encode": "astrodyn.bench.encode",
    "auth": "astrodyn.bench.auth",
    "calls": "astrodyn.bench.calls",
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
    rc = 0
    for n in names:
        rc |= int(importlib.import_module(SUITES[n]).main(rest) or 0)
    return rc


if __name__ == "__main__":
    sys.exit(main())
