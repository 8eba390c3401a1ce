"""``astrodyn bench orbit``: speed and error of two-body propagation, against REBOUND and scipy.

What is measured, all in one process and one run:

* :func:`astrodyn.orbit.propagate` on 1, 10^3 and 10^6 states of mixed conics
  (ns per state; warm-up call first so numba compilation is excluded; best of
  ``--repeats``).  The 1-state row is a scalar call (shape (3,)), i.e. latency.
* :func:`astrodyn.orbit.solve_kepler` alone (ns per call, 10^6 elliptic (M, e)).
* Accuracy on a sample (``--sample`` states): the final position against the
  50-digit mpmath reference :func:`astrodyn.reference.orbit_mp.propagate_mp`,
  as the max and median relative error |dr| / |r| and as ``err/floor``: the
  error divided by the float64 floor of the case, i.e. the change that a
  one-ulp perturbation of the inputs causes
  (:func:`astrodyn.reference.conditioning.ulp_sensitivity`).  For the
  step-by-step integrators the floor is
  :func:`~astrodyn.reference.conditioning.path_sensitivity` (the rounding of
  the periapsis state on the way counts too).  The stated accuracy target is
  ``err/floor <= 100`` (docs/architecture.md, section 6).
* REBOUND IAS15, REBOUND WHFast (bound orbits only: step = period / 20) and
  scipy's DOP853 (rtol 1e-12, atol 1e-12 x the initial |r| or |v|) on the first
  ``--compare`` states of that sample, the same initial states and times: one
  REBOUND simulation per state (central mass mu with G = 1, one test particle,
  ``sim.integrate(dt)`` with ``exact_finish_time=1``), timed including set-up.
  Ratios: "faster (batch)" = their ns/state over astrodyn's ns/state at the
  largest batch size; "faster (1 call)" = the same over astrodyn's scalar
  one-state call; "err ratio" = their max relative error over astrodyn's on
  the same states.

The states (seed ``--seed``): 60 % ellipses (half e uniform in [0, 0.999999],
half 1 - e log-uniform in [1e-6, 0.5]), 30 % hyperbolas (e - 1 log-uniform in
[1e-4, 99], so e in (1, 100]), 10 % near-parabolic (|e - 1| <= 1e-6, both
sides); periapsis radius uniform in [6.6e6, 4.2e7] m around the Earth (mu =
3.986004418e14 m^3/s^2), isotropic orientation, true anomaly uniform (inside
0.9 of the asymptote angle on open orbits); dt uniform in [-3, 3] periods
(open orbits: 2 pi sqrt(|a|^3 / mu), near-parabolic: 10 x 2 pi
sqrt(rp^3 / mu)), so backward propagation and several revolutions are included.

Threads: numba's parallel kernels use every core numba sees
(``numba.get_num_threads()`` is printed); nothing in the environment is set or
unset here, and OpenBLAS/MKL thread settings are irrelevant (no BLAS calls in
the timed paths).
"""

from __future__ import annotations

import argparse
import datetime as _dt
import math
import os
import platform
import sys
import time

import numpy as np

from astrodyn.bench.flags import int_in, int_list_in, output_file

MU_EARTH = 3.986004418e14
"""Earth's gravitational parameter [m^3/s^2] (WGS-84 / EGM96 value)."""

ACCURACY_TARGET = 100.0
"""Stated accuracy: error <= 100 x the one-ulp floor of the case (docs/architecture.md, section 6)."""

KIND_NAMES = ("ellipse", "hyperbola", "near-parabolic")


def mixed_conic_states(n: int, seed: int, mu: float = MU_EARTH):
    """Seeded random initial states and times of mixed conics (see the module docstring).

    Returns ``r0 (n, 3)`` [m], ``v0 (n, 3)`` [m/s], ``dt (n,)`` [s] and ``kind (n,)``
    (0 ellipse, 1 hyperbola, 2 near-parabolic).
    """
    from astrodyn.orbit import state_from_elements

    rng = np.random.default_rng(seed)
    u = rng.random(n)
    kind = np.where(u < 0.6, 0, np.where(u < 0.9, 1, 2))
    e = np.empty(n)
    ell, hyp, par = kind == 0, kind == 1, kind == 2
    m = int(ell.sum())
    e[ell] = np.where(
        rng.random(m) < 0.5,
        rng.uniform(0.0, 0.999999, m),
        1.0 - 10.0 ** rng.uniform(-6.0, math.log10(0.5), m),
    )
    e[hyp] = 1.0 + 10.0 ** rng.uniform(-4.0, math.log10(99.0), int(hyp.sum()))
    e[par] = 1.0 + rng.uniform(-1e-6, 1e-6, int(par.sum()))
    rp = rng.uniform(6.6e6, 4.2e7, n)
    inc = np.arccos(rng.uniform(-1.0, 1.0, n))
    raan = rng.uniform(0.0, 2.0 * np.pi, n)
    argp = rng.uniform(0.0, 2.0 * np.pi, n)
    nu_max = np.where(ell, np.pi, 0.9 * np.where(e > 1.0, np.arccos(-1.0 / np.maximum(e, 1.0)), np.pi))
    nu = rng.uniform(-1.0, 1.0, n) * nu_max
    r0, v0 = state_from_elements(rp * (1.0 + e), e, inc, raan, argp, nu, mu)
    with np.errstate(divide="ignore"):
        a_abs = np.abs(rp / (1.0 - e))
    t_scale = np.where(par, 10.0 * 2.0 * np.pi * np.sqrt(rp**3 / mu), 2.0 * np.pi * np.sqrt(a_abs**3 / mu))
    dt = rng.uniform(-3.0, 3.0, n) * t_scale
    return np.ascontiguousarray(r0), np.ascontiguousarray(v0), dt, kind


# ---------------------------------------------------------------- timing helpers


def _best_seconds(fn, repeats: int, inner: int = 1, cpu: dict | None = None) -> float:
    """Best wall time of ``repeats`` runs of ``inner`` calls of ``fn``, per call [s].

    With ``cpu`` (a dict), also stores the best CPU time of the process (all
    threads, ``time.process_time``) per call under ``cpu["seconds"]``: on a shared
    machine it is the steadier number (other users' load inflates wall time).
    """
    best = best_cpu = math.inf
    for _ in range(max(1, repeats)):
        c0 = time.process_time()
        t0 = time.perf_counter()
        for _ in range(inner):
            fn()
        best = min(best, (time.perf_counter() - t0) / inner)
        best_cpu = min(best_cpu, (time.process_time() - c0) / inner)
    if cpu is not None:
        cpu["seconds"] = best_cpu
    return best


def _rebound_one(r0, v0, dt, mu, integrator: str):
    import rebound

    sim = rebound.Simulation()
    sim.G = 1.0
    sim.integrator = integrator
    sim.add(m=mu)
    sim.add(m=0.0, x=r0[0], y=r0[1], z=r0[2], vx=v0[0], vy=v0[1], vz=v0[2])
    sim.N_active = 1
    if integrator == "whfast":
        a = -mu / (2.0 * (0.5 * float(v0 @ v0) - mu / float(np.linalg.norm(r0))))
        sim.dt = 2.0 * np.pi * math.sqrt(a**3 / mu) / 20.0
    sim.integrate(dt, exact_finish_time=1)
    p = sim.particles[1]
    return np.array(p.xyz), np.array(p.vxyz)


def _dop853_one(r0, v0, dt, mu):
    from scipy.integrate import solve_ivp

    def rhs(_t, y):
        r = y[:3]
        rn = math.sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2])
        k = -mu / (rn * rn * rn)
        return np.array([y[3], y[4], y[5], k * r[0], k * r[1], k * r[2]])

    atol = 1e-12 * np.r_[np.full(3, np.linalg.norm(r0)), np.full(3, np.linalg.norm(v0))]
    sol = solve_ivp(rhs, (0.0, dt), np.r_[r0, v0], method="DOP853", rtol=1e-12, atol=atol)
    y = sol.y[:, -1]
    return y[:3], y[3:]


def _run_each(fn, r0, v0, dt, mu, *args):
    r = np.empty_like(r0)
    v = np.empty_like(v0)
    for k in range(len(dt)):
        r[k], v[k] = fn(r0[k], v0[k], float(dt[k]), mu, *args)
    return r, v


def _timed_each(fn, r0, v0, dt, mu, repeats, *args):
    out = {}

    def run():
        out["rv"] = _run_each(fn, r0, v0, dt, mu, *args)

    return _best_seconds(run, repeats), out["rv"]


# ---------------------------------------------------------------- accuracy


def _reference(r0, v0, dt, mu):
    from astrodyn.reference.orbit_mp import propagate_mp

    r = np.empty_like(r0)
    v = np.empty_like(v0)
    for k in range(len(dt)):
        rk, vk = propagate_mp(r0[k], v0[k], float(dt[k]), mu, dps=50)
        r[k] = np.asarray(rk, dtype=np.float64)
        v[k] = np.asarray(vk, dtype=np.float64)
    return r, v


def _errors(r, r_ref, floor):
    err = np.linalg.norm(r - r_ref, axis=-1)
    rel = err / np.linalg.norm(r_ref, axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(err == 0.0, 0.0, err / floor)
    return rel, ratio


# ---------------------------------------------------------------- report


def machine_description() -> str:
    from astrodyn.bench import cpu_model

    model = cpu_model()
    import numba
    import rebound
    import scipy

    return (
        f"{os.cpu_count()} CPUs (nproc), {model}; numba threads {numba.get_num_threads()}; "
        f"Python {platform.python_version()}, numpy {np.__version__}, numba {numba.__version__}, "
        f"scipy {scipy.__version__}, rebound {rebound.__version__}"
    )


def _fmt(x, spec=".3g"):
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "-"
    return format(x, spec)


def _table(rows, headers) -> tuple[str, str]:
    cells = [[str(c) for c in row] for row in rows]
    widths = [max(len(h), *(len(r[i]) for r in cells)) for i, h in enumerate(headers)]
    def line(r):
        return "  ".join(c.rjust(w) if i else c.ljust(w) for i, (c, w) in enumerate(zip(r, widths)))
    text = "\n".join([line(headers), "  ".join("-" * w for w in widths), *(line(r) for r in cells)])
    md = "\n".join(
        [
            "| " + " | ".join(headers) + " |",
            "|" + "|".join(["---"] + ["---:"] * (len(headers) - 1)) + "|",
            *("| " + " | ".join(r) + " |" for r in cells),
        ]
    )
    return text, md


BRANCH_NAMES = {2: "ellipse", 3: "hyperbola", 4: "near-parabolic (universal)"}


def branch_timings(r0, v0, dt, mu: float, repeats: int) -> list[tuple[str, int, float, float]]:
    """Serial CPU ns/state of propagate's kernel on each branch of the given states.

    The states are split by the formulation :mod:`astrodyn.orbit.universal` picks
    for them (ellipse, hyperbola, near-parabolic universal variable), and the
    serial kernel ``propagate_rows`` (one thread, the same code each parallel
    worker runs) is timed on each subset and on all of them ("mixed").  CPU time
    of the process (``time.process_time``), best of ``repeats``: on a shared
    machine it is steadier than wall time.  Returns ``(name, count, cpu_ns,
    wall_ns)`` rows.
    """
    from astrodyn.orbit.universal import formulation_rows, propagate_rows

    n = len(dt)
    muf = np.full(n, mu)
    kinds = np.empty(n, dtype=np.int64)
    formulation_rows(r0, v0, dt, muf, kinds)
    subsets = [(name, kinds == k) for k, name in BRANCH_NAMES.items()] + [("mixed", np.ones(n, bool))]
    rows = []
    for name, sel in subsets:
        m = int(sel.sum())
        if m == 0:
            continue
        rr, vv, dd, mm = (np.ascontiguousarray(a[sel]) for a in (r0, v0, dt, muf))
        r = np.empty_like(rr)
        v = np.empty_like(vv)
        propagate_rows(rr[:2], vv[:2], dd[:2], mm[:2], r[:2], v[:2])  # compile / cache load
        cpu = {}
        wall = _best_seconds(lambda: propagate_rows(rr, vv, dd, mm, r, v), repeats, cpu=cpu)
        rows.append((name, m, cpu["seconds"] / m * 1e9, wall / m * 1e9))
    return rows


def _print_branches(args) -> int:
    n = max(args.sizes)
    r0, v0, dt, _ = mixed_conic_states(n, args.seed, MU_EARTH)
    load = os.getloadavg()
    rows = branch_timings(r0, v0, dt, MU_EARTH, args.repeats)
    print(f"astrodyn bench orbit --branches: {n:,} states, seed {args.seed}, serial kernel, best of {args.repeats}")
    print(f"load average (1, 5, 15 min) {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} before the timing")
    text, _ = _table(
        [[name, f"{m:,}", f"{100.0 * m / n:.1f}", f"{cpu:.1f}", f"{wall:.1f}"] for name, m, cpu, wall in rows],
        ["branch", "states", "% of mix", "CPU ns/state", "wall ns/state"],
    )
    print(text)
    return 0


SIZE_MAX = 4_000_000
"""Largest batch size of ``--sizes``: about 250 B per state at the peak (the states, their
generation and the result), 1 GB here."""


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """The options of ``astrodyn bench orbit``, checked (argparse's usage error, exit 2)."""
    ap = argparse.ArgumentParser(prog="astrodyn bench orbit", description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", type=int_list_in(1, SIZE_MAX), default="1,1000,1000000",
                    help=f"comma-separated batch sizes, each 1..{SIZE_MAX} (about 250 B per state; at most 20 sizes; "
                         "default 1,1000,1000000)")
    ap.add_argument("--sample", type=int_in(1, 10_000), default=200,
                    help="states checked against the mpmath reference, 1..10000 (default 200)")
    ap.add_argument("--compare", type=int_in(0, 1000), default=40,
                    help="of those, states run through REBOUND and DOP853, 0..1000 (at most --sample; default 40)")
    ap.add_argument("--seed", type=int_in(0, 2**64 - 1), default=20240601,
                    help="random seed of the states, 0..2^64-1 (default 20240601)")
    ap.add_argument("--repeats", type=int_in(1, 100), default=7, help="timing repeats, best is reported, 1..100 (default 7)")
    ap.add_argument("--quick", action="store_true", help="smoke test: sizes 1,1000, sample 8, compare 4, repeats 2")
    ap.add_argument("--branches", action="store_true", help="only the serial CPU ns/state of each branch (ellipse, hyperbola, near-parabolic, mixed) on the largest size")
    ap.add_argument("--markdown", metavar="FILE", type=output_file,
                    help="also write the table (markdown) with the machine description")
    args = ap.parse_args(argv)
    if args.quick:
        args.sizes, args.sample, args.compare, args.repeats = [1, 1000], 8, 4, 2
    args.compare = min(args.compare, args.sample)
    return args


def main(argv: list[str] | None = None) -> int:
    """``astrodyn bench orbit`` (module docstring): 0 when astrodyn's error on the sample
    is within :data:`ACCURACY_TARGET`, else 1."""
    args = parse_args(list(sys.argv[1:] if argv is None else argv))
    if args.branches:
        return _print_branches(args)
    mu = MU_EARTH
    n_max = max(max(args.sizes), args.sample)
    r0_all, v0_all, dt_all, kind_all = mixed_conic_states(n_max, args.seed, mu)
    print(f"astrodyn bench orbit: seed {args.seed}, {machine_description()}", flush=True)
    ns_astrodyn, cpu_ns, load_before = time_propagate(r0_all, v0_all, dt_all, mu, args.sizes, args.repeats)
    nk, ns_kepler = time_solve_kepler(args.sizes, args.seed, args.repeats)
    s = slice(0, args.sample)
    r0, v0, dt, kind = r0_all[s], v0_all[s], dt_all[s], kind_all[s]
    r_ref, rel_ad, ratio_ad = sample_errors(r0, v0, dt, mu)
    rows = astrodyn_rows(args.sizes, ns_astrodyn, rel_ad, ratio_ad, nk, ns_kepler)
    if args.compare:
        rows += competitor_rows(r0, v0, dt, mu, r_ref, rel_ad, ratio_ad, ns_astrodyn, args.compare, args.repeats)
    ok = bool(ratio_ad.max() <= ACCURACY_TARGET)
    headers = ["method", "states", "ns/state", "max rel err", "median rel err", "max err/floor", "astrodyn faster by (batch)", "astrodyn faster by (1 call)", "err ratio (them/astrodyn)"]
    text, md = _table(rows, headers)
    kinds = {KIND_NAMES[k]: int((kind == k).sum()) for k in range(3)}
    print()
    print(f"error sample: {args.sample} states {kinds}; floor = one-ulp sensitivity (path floor for integrators); target err/floor <= {ACCURACY_TARGET:g}")
    print(text)
    cpu_line = "; ".join(f"{n:,} states {cpu_ns[n]:.1f}" for n in sorted(cpu_ns))
    load_line = f"load average (1, 5, 15 min) {load_before[0]:.2f} {load_before[1]:.2f} {load_before[2]:.2f} before the timing"
    print(f"\nCPU time per state (process_time, all threads): {cpu_line}; {load_line}")
    verdict = "within" if ok else "ABOVE"
    print(f"\nastrodyn max err/floor {ratio_ad.max():.2f}: {verdict} the stated target {ACCURACY_TARGET:g}")
    if args.markdown:
        write_markdown(args, argv, md, kinds, f"{cpu_line}; {load_line}")
        print(f"table written to {args.markdown}")
    return 0 if ok else 1


def time_propagate(r0_all, v0_all, dt_all, mu: float, sizes: list[int], repeats: int):
    """Wall ns per state of :func:`astrodyn.orbit.propagate` at each batch size (size 1: a
    scalar call), CPU ns per state of the batch calls (all threads), and the load average
    before the timing; each size printed as it is done."""
    from astrodyn.orbit import propagate

    propagate(r0_all[0], v0_all[0], dt_all[0], mu)  # warm-up: numba compile / cache load
    propagate(r0_all[:2], v0_all[:2], dt_all[:2], mu)
    ns_astrodyn = {}
    cpu_ns = {}
    load_before = os.getloadavg()
    for n in sizes:
        if n == 1:
            r1, v1, d1 = r0_all[0], v0_all[0], float(dt_all[0])
            sec = _best_seconds(lambda: propagate(r1, v1, d1, mu), repeats, inner=2000)
        else:
            rr, vv, dd = r0_all[:n], v0_all[:n], dt_all[:n]
            inner = max(1, 200_000 // n)
            cpu = {}
            sec = _best_seconds(lambda: propagate(rr, vv, dd, mu), repeats, inner=inner, cpu=cpu) / n
            cpu_ns[n] = cpu["seconds"] / n * 1e9
        ns_astrodyn[n] = sec * 1e9
        extra = f" wall, {cpu_ns[n]:.1f} ns/state CPU (all threads)" if n in cpu_ns else ""
        print(f"  propagate x{n}: {ns_astrodyn[n]:.1f} ns/state{extra}", flush=True)
    return ns_astrodyn, cpu_ns, load_before


def time_solve_kepler(sizes: list[int], seed: int, repeats: int) -> tuple[int, float]:
    """``(count, ns per call)`` of :func:`astrodyn.orbit.solve_kepler` alone on up to 10^6
    elliptic ``(M, e)`` (seed ``seed + 1``), printed."""
    from astrodyn.orbit import solve_kepler

    nk = min(10**6, max(sizes) if max(sizes) > 1 else 1000)
    rng = np.random.default_rng(seed + 1)
    m_k = rng.uniform(-1e3, 1e3, nk)
    e_k = rng.uniform(0.0, 0.999999, nk)
    solve_kepler(m_k[:2], e_k[:2])
    ns_kepler = _best_seconds(lambda: solve_kepler(m_k, e_k), repeats, inner=max(1, 200_000 // nk)) / nk * 1e9
    print(f"  solve_kepler x{nk}: {ns_kepler:.1f} ns/call", flush=True)
    return nk, ns_kepler


def sample_errors(r0, v0, dt, mu: float):
    """On the accuracy sample: the 50-digit reference final positions (m), and astrodyn's
    relative error |dr| / |r| and error over the one-ulp floor of each state; the time
    taken printed."""
    from astrodyn.orbit import propagate
    from astrodyn.reference.conditioning import ulp_sensitivity

    t0 = time.perf_counter()
    r_ref, _ = _reference(r0, v0, dt, mu)
    floor_ulp, _ = ulp_sensitivity(r0, v0, dt, mu, dps=30)
    r_ad, _ = propagate(r0, v0, dt, mu)
    rel_ad, ratio_ad = _errors(np.asarray(r_ad), r_ref, floor_ulp)
    print(f"  reference + floors on {len(dt)} states: {time.perf_counter() - t0:.1f} s", flush=True)
    return r_ref, rel_ad, ratio_ad


def astrodyn_rows(sizes: list[int], ns_astrodyn: dict, rel_ad, ratio_ad, nk: int, ns_kepler: float) -> list[list[str]]:
    """Table rows of astrodyn: one per batch size (the errors on the largest), and solve_kepler."""
    batch_n = max(sizes)
    rows = []
    for n in sizes:
        is_top = n == batch_n
        rows.append(
            [
                "astrodyn propagate" + (" (scalar call)" if n == 1 else ""),
                f"{n:,}",
                _fmt(ns_astrodyn[n], ".1f"),
                _fmt(float(rel_ad.max())) if is_top else "",
                _fmt(float(np.median(rel_ad))) if is_top else "",
                _fmt(float(ratio_ad.max()), ".3g") if is_top else "",
                "1 (ref.)" if is_top else _fmt(ns_astrodyn[n] / ns_astrodyn[batch_n], ".3g") + " x the batch ns",
                "",
                "",
            ]
        )
    rows.append(["astrodyn solve_kepler (ns/call)", f"{nk:,}", _fmt(ns_kepler, ".1f"), "", "", "", "", "", ""])
    return rows


def competitor_rows(r0, v0, dt, mu: float, r_ref, rel_ad, ratio_ad, ns_astrodyn: dict, compare: int,
                    repeats: int) -> list[list[str]]:
    """Table rows of astrodyn, REBOUND IAS15, REBOUND WHFast (bound orbits) and scipy DOP853
    on the first ``compare`` states of the sample; errors over the path floor, ratios to
    astrodyn's batch and scalar ns and to its error on the same states."""
    from astrodyn.reference.conditioning import path_sensitivity

    c = slice(0, compare)
    rc0, vc0, dtc = r0[c], v0[c], dt[c]
    t0 = time.perf_counter()
    floor_path, _ = path_sensitivity(rc0, vc0, dtc, mu, dps=30)
    print(f"  path floors on {compare} states: {time.perf_counter() - t0:.1f} s", flush=True)
    bound = (0.5 * np.einsum("ij,ij->i", vc0, vc0) - mu / np.linalg.norm(rc0, axis=-1)) < 0
    ad_max_all = float(rel_ad[c].max())
    ad_max_bound = float(rel_ad[c][bound].max()) if bound.any() else math.nan
    rows = [["astrodyn on the compare states", f"{compare}", "", _fmt(ad_max_all), _fmt(float(np.median(rel_ad[c]))),
             _fmt(float(ratio_ad[c].max()), ".3g"), "", "", ""]]
    reps = min(repeats, 3)
    competitors = [
        ("REBOUND IAS15", np.ones(compare, bool), lambda a, b, d: _timed_each(_rebound_one, a, b, d, mu, reps, "ias15")),
        ("REBOUND WHFast (bound)", bound, lambda a, b, d: _timed_each(_rebound_one, a, b, d, mu, reps, "whfast")),
        ("scipy DOP853 rtol 1e-12", np.ones(compare, bool), lambda a, b, d: _timed_each(_dop853_one, a, b, d, mu, 1)),
    ]
    batch_n = max(ns_astrodyn)  # the largest batch size
    for name, sel, run in competitors:
        if not sel.any():
            continue
        t0 = time.perf_counter()
        sec, (r_c, _) = run(rc0[sel], vc0[sel], dtc[sel])
        rel, ratio = _errors(r_c, r_ref[c][sel], floor_path[sel])
        ns = sec / sel.sum() * 1e9
        ad_ref = ad_max_bound if name.startswith("REBOUND WHFast") else ad_max_all
        rows.append(
            [
                name,
                f"{int(sel.sum())}",
                _fmt(ns, ".0f"),
                _fmt(float(rel.max())),
                _fmt(float(np.median(rel))),
                _fmt(float(ratio.max()), ".3g"),
                _fmt(ns / ns_astrodyn[batch_n], ",.0f") + " x",
                _fmt(ns / ns_astrodyn[1], ",.3g") + " x" if 1 in ns_astrodyn else "",
                _fmt(float(rel.max()) / max(ad_ref, 1e-300), ".3g") + " x",
            ]
        )
        print(f"  {name}: {time.perf_counter() - t0:.1f} s", flush=True)
    return rows


def write_markdown(args, argv: list[str] | None, md: str, kinds: dict, cpu_and_load: str) -> None:
    """The table (markdown) into ``args.markdown`` with the command, date, machine and sample."""
    stamp = _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M UTC")
    cmd = "astrodyn bench orbit " + " ".join(argv if argv is not None else sys.argv[1:])
    with open(args.markdown, "w") as f:
        f.write(f"<!-- written by `{cmd.strip()}` on {stamp} -->\n")
        f.write(f"Machine: {machine_description()}\n\nDate: {stamp}; seed {args.seed}; best of {args.repeats} repeats.\n\n")
        f.write(f"Error sample: {args.sample} states {kinds}; REBOUND/DOP853 on the first {args.compare}.\n\n")
        f.write(md + "\n")
        f.write(f"\nCPU ns/state of the batch calls (process_time, all threads): {cpu_and_load}.\n")


if __name__ == "__main__":
    sys.exit(main())
