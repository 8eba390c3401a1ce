"""Sweep throughput: cases per second serially and on a Dask LocalCluster of 1 and 2 workers.

    python -m astrodyn.bench.sweep [--repeat 2] [--quick] [--out docs/bench-sweep.md]

Two scenes: ``configs/demo.toml`` (three bodies, orbit and attitude, 93 min at 1 Hz,
one body with J2: about 0.3 s a case) dispersed in the ISS's eccentricity and the
cubesat's rates, and an orbit-only scene (two Kepler orbits, 93 min at 1 Hz: a few ms a
case, so Dask's per-task overhead shows; also with ``--chunk 10``).  ``cases/s`` is n / wall
time on a warmed-up cluster (started, and every worker has already run cases, so imports
and the numba cache are loaded; that time is reported separately).  Scaling
efficiency = rate(2 workers) / (2 x rate(1 worker)).  The machine is shared: each
configuration runs ``--repeat`` times and the best is kept.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

from astrodyn.bench.flags import int_in, output_file
from astrodyn.sweep import local_cluster, make_spec, run_cases

ORBIT_ONLY = """
[scenario]
name = "orbit-only"
epoch = "2026-03-20T12:00:00 TDB"
duration = "93 min"
rate = "1 Hz"

[[bodies]]
name = "sat1"
[bodies.orbit]
a = "6795 km"
e = 0.0005
i = "51.64 deg"

[[bodies]]
name = "sat2"
[bodies.orbit]
a = "7000 km"
e = 0.01
i = "97 deg"
"""

_DEMO_VARY = ["bodies.iss.orbit.e=uniform(0.0001, 0.01)", "bodies.cubesat.attitude.w=normal([0.001, 0.3, 0.002], 0.01)"]
_ORBIT_VARY = ["bodies.sat1.orbit.e=uniform(0, 0.1)", "bodies.sat2.orbit.i=normal(97, 1) deg"]
# name -> (config text or None for configs/demo.toml, dispersions, cases, cases per Dask task)
SCENES = {
    "demo": (None, _DEMO_VARY, 24, 1),
    "orbit-only": (ORBIT_ONLY, _ORBIT_VARY, 200, 1),
    "orbit-only, --chunk 10": (ORBIT_ONLY, _ORBIT_VARY, 200, 10),
}
QUICK_CASES_MIN = 4  #: fewest cases of a scene with --quick (a tenth of its cases otherwise)


def measure(config: Path, varies: list[str], n: int, workers: int, chunk: int = 1) -> dict:
    """Cases/s of ``n`` cases: serially (``workers=0``) or on a warmed-up LocalCluster.

    The cluster is started and every worker has run cases (numba cache loaded) before the
    clock starts; its start-up time is reported separately.
    """
    spec = make_spec(config, varies, n=n, seed=1)
    if workers == 0:
        list(run_cases(spec, range(2), workers=0))  # warm-up: imports, numba cache
        t0 = time.perf_counter()
        failed = sum(r["status"] != "ok" for r in run_cases(spec, range(n), workers=0))
        return {"cases_per_s": n / (time.perf_counter() - t0), "startup_s": 0.0, "failed": failed}
    t0 = time.perf_counter()
    with local_cluster(workers) as cluster:
        address = cluster.scheduler_address
        list(run_cases(spec, range(4 * workers), scheduler=address))  # warm-up on every worker
        startup = time.perf_counter() - t0
        t1 = time.perf_counter()
        failed = sum(r["status"] != "ok" for r in run_cases(spec, range(n), scheduler=address, chunk=chunk))
        rate = n / (time.perf_counter() - t1)
    return {"cases_per_s": rate, "startup_s": startup, "failed": failed}


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """The options of ``astrodyn bench sweep``, checked (argparse's usage error, exit 2)."""
    ap = argparse.ArgumentParser(prog="astrodyn bench sweep", description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int_in(1, 10), default=2,
                    help="runs of each configuration, best kept, 1..10 (each starts its Dask clusters; default 2)")
    ap.add_argument("--out", default=None, type=output_file, help="Markdown file for the table (default: print only)")
    ap.add_argument("--quick", action="store_true",
                    help=f"a smoke run: a tenth of the cases (at least {QUICK_CASES_MIN}) and one run of each configuration")
    return ap.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    from astrodyn.scenario.catalogue import config_path

    repeat = 1 if args.quick else args.repeat
    results: dict[tuple[str, int], dict] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for scene, (text, varies, n, chunk) in SCENES.items():
            n = max(QUICK_CASES_MIN, n // 10) if args.quick else n
            if text is None:
                config = config_path("demo")
            else:
                config = Path(tmp) / "orbit-only.toml"
                config.write_text(text)
            for workers in (0, 1, 2):
                best = None
                for _ in range(repeat):
                    r = measure(config, varies, n, workers, chunk)
                    if best is None or r["cases_per_s"] > best["cases_per_s"]:
                        best = r
                results[(scene, workers)] = best | {"n": n}
                print(f"{scene:<11} workers={workers}: {best['cases_per_s']:8.2f} cases/s, "
                      f"start-up + warm-up {best['startup_s']:.1f} s, {n} cases, {best['failed']} failed",
                      file=sys.stderr, flush=True)
    lines = [
        "# Sweep throughput (`astrodyn sweep`)", "",
        f"Measured with `python -m astrodyn.bench.sweep {'--quick' if args.quick else f'--repeat {repeat}'}` on "
        f"{platform.machine()} ({os.cpu_count()} logical CPUs, shared with other users: load average "
        f"{', '.join(f'{x:.1f}' for x in os.getloadavg())} at the end), best of {repeat} runs.",
        "Rates are n / wall time on a warmed-up cluster (started, and every worker has run cases so "
        "imports and the numba cache are loaded; that start-up + warm-up time is listed separately).  Serial = `--workers 0` (in this process, "
        "numba may use both cores for the vectorized kernels); 1 and 2 = Dask LocalCluster worker "
        "processes, one thread and one numba thread each.", "",
        "| scene | cases | serial cases/s | 1 worker cases/s | 2 workers cases/s | scaling efficiency 2 vs 1 | start-up + warm-up s (1 / 2 workers) |",
        "|---|---|---|---|---|---|---|",
    ]
    for scene in SCENES:
        s, w1, w2 = (results[(scene, w)] for w in (0, 1, 2))
        eff = w2["cases_per_s"] / (2 * w1["cases_per_s"])
        lines.append(f"| {scene} | {s['n']} | {s['cases_per_s']:.2f} | {w1['cases_per_s']:.2f} | {w2['cases_per_s']:.2f} "
                     f"| {eff:.0%} | {w1['startup_s']:.1f} / {w2['startup_s']:.1f} |")
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        Path(args.out).write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
