"""Small calls on busy cores (``astrodyn bench calls [--load]``): where the service lives.

The service calls the kernels with small batches once per step, from several processes
that share the cores.  This suite times, in one process and one run:

* exact torque-free, 1 body x 1001 times (the 1000 s Dzhanibekov flip), a new state each call;
* exact torque-free, 1000 bodies x 1 time;
* exact torque-free, one new state at one time (the scalar call);
* orbit ``propagate``, one state (the scalar call);
* peers on the same problems: heyoka's Taylor integrator (tolerance 1e-15; the batch mode,
  SIMD width 4, for 1000 bodies), and for the DOP853 row scipy's DOP853 against
  ``propagate_attitude(method="dop853")`` per function evaluation;

each with numba at 1 and at 2 threads, on an idle machine and -- with ``--load`` -- while
other astrodyn processes (one per core) run the service's kernels in a loop (started and
stopped by the benchmark, by PID).  Output: a Markdown table for docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import time

import numpy as np

from astrodyn.bench import best_seconds_per_call, call_in_tree, env_for_source, print_table
from astrodyn.bench.flags import float_in, int_in, problem, source_tree

DZHANIBEKOV = (np.array([1.0, 2.0, 3.0]), np.array([1e-3, 1.0, 1e-3]))


def _best(fn, repeat: int, number: int) -> float:
    """Best of ``repeat`` timings of ``number`` calls, in seconds per call."""
    return best_seconds_per_call(fn, number, repeat)


# --------------------------------------------------------------------------- load


def load_worker(seconds: float) -> None:
    """One background process of the load: the service's kernels in a loop, with the
    numba threads of a service process (:func:`astrodyn.jit.service_threads`: 1 unless
    ``$ASTRODYN_THREADS`` says otherwise; ``--load-threads`` sets it)."""
    from astrodyn.attitude import torque_free
    from astrodyn.jit import service_threads, set_threads
    from astrodyn.orbit import propagate

    set_threads(service_threads())
    rng = np.random.default_rng(os.getpid())
    r0 = np.array([7e6, 0.0, 0.0]) + rng.normal(scale=1e5, size=(1000, 3))
    v0 = np.array([0.0, 7.5e3, 1e3]) + rng.normal(scale=50.0, size=(1000, 3))
    inertia, w0 = DZHANIBEKOV
    w0s = w0 + rng.normal(scale=1e-3, size=(200, 3))
    end = time.monotonic() + seconds
    k = 0
    while time.monotonic() < end:
        propagate(r0, v0, 10.0 * k, 3.986004418e14)
        torque_free(inertia, w0s, np.array([1.0, 0.0, 0.0, 0.0]), 0.1 * k)
        k += 1


class Load:
    """``n`` background :func:`load_worker` processes for the duration of a ``with``."""

    def __init__(self, n: int, seconds: float = 3600.0, threads: int = 1, src: str | None = None):
        self.n, self.seconds, self.threads, self.src = n, seconds, threads, src
        self.procs: list[subprocess.Popen] = []

    def __enter__(self) -> Load:
        env = env_for_source(self.src, ASTRODYN_THREADS=str(self.threads))
        for _ in range(self.n):
            self.procs.append(subprocess.Popen([sys.executable, "-m", "astrodyn.bench.calls", "--load-worker",
                                                str(self.seconds)], stdin=subprocess.DEVNULL, env=env))
        time.sleep(20.0)  # past their kernels' first (cached) load
        return self

    def __exit__(self, *exc) -> None:
        for p in self.procs:
            if p.poll() is None:
                os.kill(p.pid, signal.SIGTERM)
        for p in self.procs:
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                os.kill(p.pid, signal.SIGKILL)
                p.wait(timeout=10)


# --------------------------------------------------------------------------- thresholds


def paired(fns, number: int, repeat: int = 7) -> list[float]:
    """Median seconds per call of each of ``fns``, timed alternately (``number`` calls of
    each in turn, ``repeat`` rounds), so a change of the machine's load hits all alike."""
    ts: list[list[float]] = [[] for _ in fns]
    for _ in range(repeat):
        for k, fn in enumerate(fns):
            t0 = time.perf_counter()
            for _ in range(number):
                fn()
            ts[k].append((time.perf_counter() - t0) / number)
    return [float(np.median(x)) for x in ts]


def sweep(sizes=(64, 256, 512, 1024, 2048, 4096, 16384)) -> list[tuple]:
    """Serial vs parallel (2 threads) compilation of each :class:`astrodyn.jit.ParallelKernel`
    over batch sizes: rows ``(n, kernel, serial s, parallel s)`` (medians of 7, alternated).  The
    thresholds of :data:`astrodyn.jit.PARALLEL_MIN` are where the parallel one wins."""
    import numba

    from astrodyn.attitude.elliptic import ellipj_loop, elliprj_loop
    from astrodyn.attitude.torque_free import PreparedBody, evaluate_all, setup_all

    inertia, w0 = DZHANIBEKOV
    rng = np.random.default_rng(0)
    numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
    rows = []
    for n in sizes:
        w = w0 + rng.normal(scale=1e-3, size=(n, 3))
        q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
        moments = np.tile(inertia, (n, 1))
        par = PreparedBody(moments, w, q).bodies
        t = np.array([12.5])
        u, m = rng.uniform(-3.0, 3.0, n), rng.uniform(0.0, 1.0, n)
        x, y, z, p = (rng.uniform(0.1, 2.0, n) for _ in range(4))
        out = [np.empty(n) for _ in range(3)]
        cases = {"torque_free": (evaluate_all, (par, t, np.empty((n, 1, 3)), np.empty((n, 1, 4)))),
                 "torque_free_setup": (setup_all, (moments, w, q, par)),
                 "elliptic (ellipj)": (ellipj_loop, (u, m, 1.0 - m, *out)),
                 "elliptic (elliprj)": (elliprj_loop, (x, y, z, p, out[0]))}
        number = max(10, 20000 // n)
        for name, (kernel, args) in cases.items():
            kernel.serial(*args)
            kernel.parallel(*args)
            ser, par_ = paired([lambda k=kernel, a=args: k.serial(*a), lambda k=kernel, a=args: k.parallel(*a)],
                               number)
            rows.append((n, name, ser, par_))
    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    return rows


# --------------------------------------------------------------------------- cases


def _astrodyn_cases(repeat: int) -> dict[str, float]:
    from astrodyn.attitude import torque_free
    from astrodyn.attitude.torque_free import PreparedBody
    from astrodyn.orbit import propagate, propagate_scalar

    inertia, w0 = DZHANIBEKOV
    q0 = np.array([1.0, 0.0, 0.0, 0.0])
    t1001 = np.linspace(0.0, 1000.0, 1001)
    states = [w0 * (1.0 + 1e-9 * k) for k in range(64)]
    w1000 = w0 + np.random.default_rng(1).normal(scale=1e-3, size=(1000, 3))
    prepared = PreparedBody(inertia, w1000, q0)
    r0, v0 = np.array([7e6, 1e5, -2e5]), np.array([10.0, 7.5e3, 1e3])
    rv0 = (*r0.tolist(), *v0.tolist())
    it = iter(range(10**12))
    out = {
        "torque-free 1 body x 1001 times": _best(lambda: torque_free(inertia, states[next(it) % 64], q0, t1001), repeat, 20),
        "torque-free 1000 bodies x 1 time": _best(lambda: torque_free(inertia, w1000, q0, 12.5), repeat, 20),
        "torque-free 1000 prepared bodies x 1 time": _best(lambda: prepared.states(12.5), repeat, 20),
        "torque-free scalar (new state, 1 time)": _best(lambda: torque_free(inertia, states[next(it) % 64], q0, 12.5),
                                                         repeat, 2000),
        "propagate scalar (1 state)": _best(lambda: propagate(r0, v0, 60.0, 3.986004418e14), repeat, 5000),
        "propagate_scalar (1 state, 6 floats in and out)": _best(lambda: propagate_scalar(*rv0, 60.0, 3.986004418e14),
                                                                  repeat, 5000),
        # what the harness itself costs per call in the rows above (a lambda and the pick of a
        # new state): nothing of astrodyn's
        "harness only (lambda + new-state pick)": _best(lambda: states[next(it) % 64], repeat, 5000),
        # the same call as a user writes it, without the harness's lambda and argument unpacking
        # (about 70 ns of the row above): timeit of the statement itself
        "propagate_scalar, direct call": _best_statement("f(x, y, z, vx, vy, vz, dt, mu)", {
            "f": propagate_scalar, **dict(zip(("x", "y", "z", "vx", "vy", "vz"), rv0)), "dt": 60.0,
            "mu": 3.986004418e14}, repeat, 5000),
    }
    return out


def _best_statement(statement: str, names: dict, repeat: int, number: int) -> float:
    """Best of ``repeat`` timings of ``number`` runs of ``statement`` (timeit, no wrapper
    call), in seconds per run."""
    import timeit

    return min(timeit.repeat(statement, globals=names, number=number, repeat=max(1, repeat))) / number


def _rigid_body_rhs(inertia):
    I1, I2, I3 = inertia

    def rhs(t, y):
        w1, w2, w3, e0, e1, e2, e3 = y
        return [(I2 - I3) / I1 * w2 * w3, (I3 - I1) / I2 * w3 * w1, (I1 - I2) / I3 * w1 * w2,
                -0.5 * (e1 * w1 + e2 * w2 + e3 * w3),
                0.5 * (e0 * w1 + e2 * w3 - e3 * w2),
                0.5 * (e0 * w2 + e3 * w1 - e1 * w3),
                0.5 * (e0 * w3 + e1 * w2 - e2 * w1)]

    return rhs


def _heyoka_cases(repeat: int) -> dict[str, float]:
    """heyoka on the same torque-free problem (Euler's equations + Euler-parameter
    kinematics of ``astrodyn.rotation.quat_rate``), tolerance 1e-15."""
    import heyoka as hy

    inertia, w0 = DZHANIBEKOV
    w1, w2, w3, e0, e1, e2, e3 = hy.make_vars("w1", "w2", "w3", "e0", "e1", "e2", "e3")
    f = _rigid_body_rhs(inertia)(0.0, [w1, w2, w3, e0, e1, e2, e3])
    sys_ = list(zip((w1, w2, w3, e0, e1, e2, e3), f))
    y0 = [*w0, 1.0, 0.0, 0.0, 0.0]
    ta = hy.taylor_adaptive(sys_, y0, tol=1e-15)
    t1001 = np.linspace(0.0, 1000.0, 1001)

    def one_body():
        ta.time = 0.0
        ta.state[:] = y0
        ta.propagate_grid(t1001)

    batch = hy.taylor_adaptive_batch(sys_, np.array([y0] * 4).T.copy(), tol=1e-15)
    w1000 = w0 + np.random.default_rng(1).normal(scale=1e-3, size=(1000, 3))

    def many_bodies():
        for k in range(0, 1000, 4):
            batch.set_time(0.0)
            batch.state[:3] = w1000[k:k + 4].T
            batch.state[3] = 1.0
            batch.state[4:] = 0.0
            batch.propagate_until(12.5)

    return {"torque-free 1 body x 1001 times": _best(one_body, repeat, 5),
            "torque-free 1000 bodies x 1 time": _best(many_bodies, repeat, 3)}


def _dop853_case(repeat: int) -> tuple[dict, dict]:
    """astrodyn's DOP853 vs scipy's on the same torque-free problem: seconds per function
    evaluation and the number of evaluations."""
    from scipy.integrate import solve_ivp

    from astrodyn.attitude import propagate_attitude

    inertia, w0 = DZHANIBEKOV
    q0 = np.array([1.0, 0.0, 0.0, 0.0])
    t = np.linspace(0.0, 100.0, 101)
    info = {}

    def ours():
        info.update(propagate_attitude(inertia, w0, q0, t, method="dop853", rtol=1e-12, atol=1e-14)[2])

    secs = _best(ours, repeat, 1)
    rhs = _rigid_body_rhs(inertia)
    sol = {}

    def scipy_run():
        sol["r"] = solve_ivp(rhs, (0.0, 100.0), [*w0, *q0], method="DOP853", t_eval=t, rtol=1e-12, atol=1e-14)

    secs_sp = _best(scipy_run, repeat, 1)
    return ({"s": secs, "nfev": info.get("nfev")}, {"s": secs_sp, "nfev": int(sol["r"].nfev)})


def measure(repeat: int, with_peers: bool = True) -> dict:
    import numba

    rows: dict = {}
    for threads in (1, 2):
        numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
        for name, s in _astrodyn_cases(repeat).items():
            rows.setdefault(name, {})[f"astrodyn {threads} thr"] = s
    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    if with_peers:
        try:
            for name, s in _heyoka_cases(repeat).items():
                rows.setdefault(name, {})["heyoka"] = s
        except ImportError:
            pass
        ours, sp = _dop853_case(repeat)
        rows["DOP853 torque-free 100 s, rtol 1e-12"] = {
            "astrodyn 2 thr": ours["s"], "scipy": sp["s"],
            "note": f"nfev {ours['nfev']} vs {sp['nfev']}; per evaluation "
                    f"{ours['s'] / max(1, ours['nfev'] or 1) * 1e6:.2f} vs {sp['s'] / sp['nfev'] * 1e6:.2f} us"}
    return rows


def public_api_cases(repeat: int, threads: int) -> dict[str, float]:
    """Seconds per call of the public calls that exist before and after issue 15, at
    ``threads`` numba threads.  Self-contained (imports inside) so that ``--baseline`` runs
    the same source against an older tree in a child process."""

    import numba
    import numpy as np

    from astrodyn.attitude import propagate_attitude, torque_free
    from astrodyn.orbit import propagate

    numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))

    def best(fn, number):
        return best_seconds_per_call(fn, number, repeat)

    inertia, w0 = np.array([1.0, 2.0, 3.0]), np.array([1e-3, 1.0, 1e-3])
    q0 = np.array([1.0, 0.0, 0.0, 0.0])
    t1001 = np.linspace(0.0, 1000.0, 1001)
    states = [w0 * (1.0 + 1e-9 * k) for k in range(64)]
    w1000 = w0 + np.random.default_rng(1).normal(scale=1e-3, size=(1000, 3))
    r0, v0 = np.array([7e6, 1e5, -2e5]), np.array([10.0, 7.5e3, 1e3])
    it = iter(range(10**12))
    out = {
        "torque-free 1 body x 1001 times": best(lambda: torque_free(inertia, states[next(it) % 64], q0, t1001), 20),
        "torque-free 1000 bodies x 1 time": best(lambda: torque_free(inertia, w1000, q0, 12.5), 20),
        "torque-free scalar (new state, 1 time)": best(lambda: torque_free(inertia, states[next(it) % 64], q0, 12.5), 2000),
        "propagate scalar (1 state)": best(lambda: propagate(r0, v0, 60.0, 3.986004418e14), 5000),
    }
    t = np.linspace(0.0, 100.0, 101)
    nfev = propagate_attitude(inertia, w0, q0, t, method="dop853", rtol=1e-12, atol=1e-14)[2]["nfev"]
    secs = best(lambda: propagate_attitude(inertia, w0, q0, t, method="dop853", rtol=1e-12, atol=1e-14), 1)
    out["DOP853 per evaluation (torque-free 100 s, rtol 1e-12)"] = secs / nfev
    return out


def _public_cases_in(src: str | None, repeat: int, threads: int) -> dict[str, float]:
    """:func:`public_api_cases` in a child process importing astrodyn from ``src``."""
    return call_in_tree(public_api_cases, (int(repeat), int(threads)), src)


def compare(baseline: str, repeat: int, rounds: int = 3) -> dict:
    """Before (``baseline`` source tree) against after (this tree), at 1 and 2 threads, in
    three regimes: idle; loaded by before-style services (the baseline's load workers: numba's
    default threads, spinning OpenMP); loaded by after-style services (one thread each).  Runs
    alternate before / after; each figure is the median of ``rounds`` child processes."""
    ncores = os.cpu_count() or 2
    regimes = {"idle": None,
               "loaded, services as before": Load(ncores, threads=2, src=baseline),
               "loaded, services as after": Load(ncores, threads=1)}
    table: dict = {}
    for regime, load in regimes.items():
        samples: dict = {}
        if load is not None:
            load.__enter__()
        try:
            for _ in range(rounds):
                for threads in (1, 2):
                    for label, src in (("before", baseline), ("after", None)):
                        for name, secs in _public_cases_in(src, repeat, threads).items():
                            samples.setdefault((name, f"{label} {threads} thr"), []).append(secs)
        finally:
            if load is not None:
                load.__exit__(None, None, None)
        for (name, col), xs in samples.items():
            table.setdefault((name, regime), {})[col] = float(np.median(xs))
    return table


def _fmt(s) -> str:
    if s is None or isinstance(s, str):
        return s or ""
    return f"{s * 1e3:.3f} ms" if s >= 1e-3 else f"{s * 1e6:.2f} us"


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """The options of ``astrodyn bench calls``, checked (argparse's usage error, exit 2);
    ``--baseline`` is checked by :func:`main` (one line, exit status 2)."""
    ap = argparse.ArgumentParser(prog="astrodyn bench calls", description=__doc__.split("\n\n")[0])
    ap.add_argument("--load", action="store_true", help="also measure while one astrodyn kernel loop per core runs")
    ap.add_argument("--repeat", type=int_in(1, 100), default=5, help="best of this many timings, 1..100 (default 5)")
    ap.add_argument("--load-threads", type=int_in(1, 64), default=1,
                    help="numba threads of each load process, 1..64 (default 1, the service default; 2: as before issue 15)")
    ap.add_argument("--sweep", action="store_true",
                    help="only the serial/parallel sweep of batch sizes behind astrodyn.jit.PARALLEL_MIN")
    ap.add_argument("--baseline", default=None, metavar="SRC",
                    help="also compare with an older source tree (e.g. git archive of a commit, its src/ directory)")
    # one background load process (Load starts it): its wall seconds, at most a day
    ap.add_argument("--load-worker", type=float_in(1.0, 86_400.0), default=None, help=argparse.SUPPRESS)
    return ap.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    if args.load_worker is not None:
        load_worker(args.load_worker)
        return 0
    if args.baseline is not None and (why := problem(source_tree, args.baseline)):
        print(f"astrodyn bench calls: --baseline: {why}", file=sys.stderr)
        return 2
    if args.sweep:
        regimes = {"idle": sweep()}
        if args.load:
            with Load(os.cpu_count() or 2, threads=args.load_threads):
                regimes["loaded"] = sweep()
        print(f"load average at the end: {os.getloadavg()[0]:.2f}; OMP_WAIT_POLICY={os.environ.get('OMP_WAIT_POLICY')}")
        print_table(["kernel", "n", "regime", "serial", "parallel (2 thr)", "serial / parallel"],
                    ([name, n, regime, _fmt(ser), _fmt(par_), f"{ser / par_:.2f}"]
                     for regime, rows in regimes.items() for n, name, ser, par_ in sorted(rows, key=lambda r: (r[1], r[0]))),
                    align="lrlrrr")
        return 0
    if args.baseline is not None:
        table = compare(os.path.abspath(args.baseline), args.repeat)
        cols = ["before 1 thr", "after 1 thr", "before 2 thr", "after 2 thr"]
        print(f"load average at the end: {os.getloadavg()[0]:.2f}")
        print_table(["case", "regime", *cols], ([name, regime, *(_fmt(row.get(c)) for c in cols)]
                                                for (name, regime), row in sorted(table.items())), align="ll" + "r" * len(cols))
        return 0
    regimes = {"idle": measure(args.repeat)}
    if args.load:
        with Load(os.cpu_count() or 2, threads=args.load_threads):
            regimes["loaded"] = measure(args.repeat)
    cols = ["astrodyn 1 thr", "astrodyn 2 thr", "heyoka", "scipy", "note"]
    print(f"load average at the end: {os.getloadavg()[0]:.2f}")
    print_table(["case", "regime", *cols], ([name, regime, *(_fmt(row.get(c)) for c in cols)]
                                            for regime, rows in regimes.items() for name, row in rows.items()),
                align="ll" + "r" * len(cols))
    return 0


if __name__ == "__main__":
    sys.exit(main())
