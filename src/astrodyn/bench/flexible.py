"""``astrodyn bench flexible``: cost and accuracy of the flexible spacecraft, the rolling
disk and the gyroscopes, against the rigid models, all in one process run.

Each model timed on its own fixed case (best of a few repeats; the machine is shared):

* **rigid body**: the flexible spacecraft below frozen (its hub plus undeformed antennas:
  the composite inertia), same initial rates and attitude, same span.  Propagated by
  :func:`astrodyn.attitude.torque_free` (exact), by :func:`astrodyn.attitude.propagate_attitude`
  (``split4``, and its ``dop853``), and by scipy's DOP853 directly on Euler's equations and
  the Euler-parameter kinematics written in plain Python floats (the cheapest right-hand side
  Python offers for these equations).  Errors against the exact solution.
* **flexible spacecraft** (:mod:`astrodyn.attitude.flexible`): the same spacecraft with its four
  antennas elastic (one assumed mode per bending plane, undamped so that the energy is an
  invariant), :func:`~astrodyn.attitude.flexible.propagate_spacecraft` (scipy DOP853 on
  :func:`~astrodyn.attitude.flexible.spacecraft_rates`) at several ``rtol``.  Errors against
  the same model at ``rtol`` 1e-13, plus the energy and angular-momentum drifts.
* **rolling disk** (:mod:`astrodyn.attitude.rolling_disk`): the general motion of
  docs/benchmarks.md's rolling-disk section, :func:`~astrodyn.attitude.propagate_rolling_disk`
  (its right-hand side in Python floats) at several ``rtol``, and scipy DOP853 on the same
  equations through the numpy :func:`~astrodyn.attitude.rolling_disk.rolling_disk_rates`.
  Errors against ``rtol`` 1e-13, and the energy drift.
* **gyroscopes** (:mod:`astrodyn.attitude.gyroscopes`, Baruh 10.7): a free gyroscope in
  massive gimbals (errors against ``rtol`` 1e-13, drifts of its three integrals) and a
  single-axis rate gyro on a steadily turning base (its settled gimbal angle against the
  exact steady state).

Reported per run: right-hand-side evaluations (``fev``; a DOP853 step is 12), wall time,
microseconds per evaluation (ns per step for the splitting method, per output time for the
exact solution), milliseconds of wall time per simulated second, the error, and two ratios
measured in this run: the cost per evaluation over that of the rigid plain-float right-hand
side, and the wall time per simulated second over that of scipy DOP853 on the rigid
equations at the same ``rtol`` (rigid and flexible rows share the case, so that ratio is
the price of the flexibility at equal tolerance).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time

import numpy as np

from astrodyn.bench.flags import int_in

__all__ = ["main", "explorer_spacecraft", "run"]

SPIN = 2.0 * math.pi  # rad/s: one turn per second
SPAN = 4.0  # s
N_OUT = 9
RTOLS = (1e-6, 1e-9, 1e-12)
DISK_STATE0 = (0.2, -0.1, 0.7, 0.35, 0.4, -0.8, 15.0, 3.0)  # docs/benchmarks.md, rolling disk
DISK_SPAN = 3.0


def explorer_spacecraft(damping_ratio: float = 0.0):
    """The minor-axis spinner of tests/test_flexible_energy_sink.py: a prolate hub (20 kg)
    with four 2 m antennas (0.3 kg/m, EI 34 N m^2, root radius 0.2 m) in its spin plane, one
    assumed mode per bending plane; composite inertia (12, 12, 8) kg m^2.  Returns
    ``(sc, y0, inertia, w0, q0)``: the spacecraft, its initial state (spin 2 pi rad/s about
    the minor axis, 10 deg nutation, antennas undeformed), the composite principal moments
    and the initial rates and attitude."""
    from astrodyn.attitude import flexible as fx

    rho, length, r, ei = 0.3, 2.0, 0.2, 34.0
    beam = fx.beam_matrices(1, ei, rho, length, r=r, damping_ratio=damping_ratio)
    axes = ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0])
    apps = tuple(fx.Appendage(beam, e, [0.0, 0.0, 1.0]) for e in axes)
    i_spin = 4.0 * rho * ((r + length) ** 3 - r**3) / 3.0  # the four rods about the spin axis
    it, i_s = 12.0, 8.0
    sc = fx.FlexibleSpacecraft(20.0, [it - i_spin / 2, it - i_spin / 2, i_s - i_spin], apps)
    q0 = np.array([0.9, 0.1, -0.3, 0.3]) / np.linalg.norm([0.9, 0.1, -0.3, 0.3])
    w0 = np.array([SPIN * i_s * math.tan(math.radians(10.0)) / it, 0.0, SPIN])
    return sc, fx.make_state(sc, q=q0, w=w0), np.array([it, it, i_s]), w0, q0


def _best(fn, repeats, warm=False):
    """Best wall time of ``repeats`` calls of ``fn`` (after one untimed call when ``warm``:
    compiled kernels, caches) and the last result."""
    best, out = math.inf, None
    if warm:
        fn()
    for _ in range(max(1, repeats)):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def _angle(qa, qb):
    """Rotation angle (rad) between the attitudes ``qa`` and ``qb`` (..., 4), from the vector
    part of the relative rotation (an arccos of the dot product is blind below ~3e-8 rad)."""
    from astrodyn.rotation import quat_conjugate, quat_multiply

    d = quat_multiply(np.asarray(qb, dtype=float), quat_conjugate(np.asarray(qa, dtype=float)))
    return 2.0 * np.arctan2(np.linalg.norm(d[..., 1:], axis=-1), np.abs(d[..., 0]))


def _rigid_rhs(inertia):
    i1, i2, i3 = (float(v) for v in inertia)
    k1, k2, k3 = (i2 - i3) / i1, (i3 - i1) / i2, (i1 - i2) / i3

    def rhs(_, y):  # Python floats: the cheapest right-hand side of these equations in Python
        e0, e1, e2, e3, w1, w2, w3 = y.tolist()
        return [
            -0.5 * (e1 * w1 + e2 * w2 + e3 * w3),
            0.5 * (e0 * w1 + e2 * w3 - e3 * w2),
            0.5 * (e0 * w2 + e3 * w1 - e1 * w3),
            0.5 * (e0 * w3 + e1 * w2 - e2 * w1),
            k1 * w2 * w3,
            k2 * w3 * w1,
            k3 * w1 * w2,
        ]

    return rhs


def _row(model, method, setting, states, span, sec, fev=None, steps=None, outputs=None, err="", drift=""):
    r = {
        "model": model,
        "method": method,
        "setting": setting,
        "states": states,
        "span": span,
        "seconds": sec,
        "fev": fev,
        "steps": steps,
        "outputs": outputs,
        "err": err,
        "drift": drift,
    }
    r["ms_per_sim_s"] = 1e3 * sec / span
    if fev:
        r["cost"], r["cost_unit"] = 1e6 * sec / fev, "us/fev"
    elif steps:
        r["cost"], r["cost_unit"] = 1e9 * sec / steps, "ns/step"
    else:
        r["cost"], r["cost_unit"] = 1e9 * sec / outputs, "ns/output"
    return r


def rigid_rows(repeats, rtols):
    from scipy.integrate import solve_ivp

    from astrodyn.attitude import propagate_attitude, torque_free

    _, _, inertia, w0, q0 = explorer_spacecraft()
    t = np.linspace(0.0, SPAN, N_OUT)
    w_ex, q_ex = torque_free(inertia, w0, q0, t)
    wscale = float(np.linalg.norm(w0))

    def errs(w, q):
        return f"{np.max(_angle(q, q_ex)):.1e} rad, rate {np.max(np.linalg.norm(w - w_ex, axis=-1)) / wscale:.1e}"

    def rigid(method, setting, sec, err, **cost):
        return _row("rigid", method, setting, 7, SPAN, sec, err=err, **cost)

    tt = np.linspace(0.0, SPAN, 20001)
    sec, _ = _best(lambda: torque_free(inertia, w0, q0, tt), repeats, warm=True)
    rows = [rigid("`torque_free` (exact)", "-", sec * N_OUT / tt.size, "reference (exact)", outputs=N_OUT)]
    # (method, setting, its options): the fixed steps of split4, then DOP853's tolerances
    runs = [("split4", f"h = {h:g} s", {"step": h, "error_estimate": False}) for h in (0.01, 0.002)]
    runs += [("dop853", f"rtol {rtol:g}", {"rtol": rtol, "atol": rtol * 1e-3}) for rtol in rtols]
    for method, setting, options in runs:

        def run(method=method, options=options):
            return propagate_attitude(inertia, w0, q0, t[1:], rotor_momentum=np.zeros(3), method=method, **options)

        sec, (w, q, info) = _best(run, repeats, warm=True)
        cost = {"steps": info["n_steps"]} if method == "split4" else {"fev": info["nfev"]}
        rows.append(rigid(f"`propagate_attitude` {method}", setting, sec, errs(np.vstack([w0, w]), np.vstack([q0, q])),
                          **cost))
    rhs = _rigid_rhs(inertia)
    y0 = np.concatenate([q0, w0])
    for rtol in rtols:

        def run(rtol=rtol):
            return solve_ivp(rhs, (0.0, SPAN), y0, method="DOP853", t_eval=t, rtol=rtol, atol=rtol * 1e-3)

        sec, sol = _best(run, repeats, warm=True)
        q = sol.y[:4].T / np.linalg.norm(sol.y[:4].T, axis=1, keepdims=True)
        rows.append(rigid("scipy DOP853, plain-float rhs", f"rtol {rtol:g}", sec, errs(sol.y[4:].T, q), fev=sol.nfev))
    return rows


def flexible_rows(repeats, rtols):
    from astrodyn.attitude import flexible as fx, torque_free

    sc, y0, inertia, w0, q0 = explorer_spacecraft(0.0)
    t = np.linspace(0.0, SPAN, N_OUT)
    n = y0.size
    ref, _ = fx.propagate_spacecraft(sc, y0, t, rtol=1e-13, atol=1e-16)
    wscale = float(np.linalg.norm(w0))
    rows = []
    for rtol in rtols:

        def run(rtol=rtol):
            return fx.propagate_spacecraft(sc, y0, t, rtol=rtol, atol=rtol * 1e-3)

        # the tight runs take seconds each: fewer repeats there
        sec, (y, info) = _best(run, repeats if rtol >= 1e-9 else max(1, repeats // 2))
        ea = float(np.max(_angle(y[:, :4], ref[:, :4])))
        ew = float(np.max(np.linalg.norm(y[:, 4:7] - ref[:, 4:7], axis=1))) / wscale
        ee = float(np.max(np.abs(y[:, 13:] - ref[:, 13:])))
        rows.append(
            _row(
                "flexible (4 antennas)",
                "`propagate_spacecraft` (scipy DOP853)",
                f"rtol {rtol:g}",
                n,
                SPAN,
                sec,
                fev=info["nfev"],
                err=f"{ea:.1e} rad, rate {ew:.1e}, eta {ee:.1e} m",
                drift=f"E {info['energy_drift']:.1e}, H {info['momentum_drift']:.1e}",
            )
        )
    # modelling error against integration error: the flexible attitude against the rigid composite's
    _, q_rigid = torque_free(inertia, w0, q0, t)
    model_gap = float(np.max(_angle(ref[:, :4], q_rigid)))
    return rows, model_gap


def disk_rows(repeats, rtols):
    from scipy.integrate import solve_ivp

    from astrodyn.attitude.rolling_disk import RollingDisk, energy, propagate_rolling_disk, rolling_disk_rates

    disk = RollingDisk(radius=0.1, mass=0.5)
    y0 = np.array(DISK_STATE0)
    t = np.linspace(0.0, DISK_SPAN, N_OUT)
    ref, _ = propagate_rolling_disk(disk, y0, t, rtol=1e-13, atol=1e-15)

    def err(y):
        return f"{np.max(np.abs(y - ref)):.1e} (m, rad)"

    rows = []
    for rtol in rtols:

        def run(rtol=rtol):
            return propagate_rolling_disk(disk, y0, t, rtol=rtol, atol=rtol * 1e-2)

        sec, (y, info) = _best(run, repeats, warm=True)
        rows.append(
            _row(
                "rolling disk",
                "`propagate_rolling_disk` (plain-float rhs)",
                f"rtol {rtol:g}",
                8,
                DISK_SPAN,
                sec,
                fev=info["nfev"],
                err=err(y),
                drift=f"E {info['energy_drift']:.1e}",
            )
        )

    def rhs(_, y):
        return rolling_disk_rates(disk, y)

    for rtol in rtols[1:2]:

        def run(rtol=rtol):
            return solve_ivp(rhs, (0.0, DISK_SPAN), y0, method="DOP853", t_eval=t, rtol=rtol, atol=rtol * 1e-2)

        sec, sol = _best(run, repeats, warm=True)
        y = sol.y.T
        e = energy(disk, y)
        rows.append(
            _row(
                "rolling disk",
                "scipy DOP853, numpy `rolling_disk_rates`",
                f"rtol {rtol:g}",
                8,
                DISK_SPAN,
                sec,
                fev=sol.nfev,
                err=err(y),
                drift=f"E {np.max(np.abs(e - e[0])) / abs(e[0]):.1e}",
            )
        )
    return rows


GYRO_SPAN = 1.0  # s


def gyro_rows(repeats, rtols):
    """The gyroscopes of Baruh 10.7: a free gyroscope in massive gimbals nutating at its
    working attitude (errors against rtol 1e-13, drifts of its three integrals), and a
    single-axis rate gyro on a base turning at a constant rate (error: the settled gimbal
    angle against the exact steady state, :func:`steady_state_angle`)."""
    from astrodyn.attitude import gyroscopes as gy

    free = gy.FreeGyroscope(rotor_axial=2e-4, rotor_transverse=1.2e-4, inner_gimbal=(5e-5, 6e-5, 4e-5),
                            outer_gimbal=1e-4)
    y0 = gy.free_gyro_state(free, spin=2 * math.pi * 200, theta=0.5 * math.pi + 0.05, theta_dot=2.0, psi_dot=0.5)
    t = np.linspace(0.0, GYRO_SPAN, N_OUT)
    ref, _ = gy.propagate_free_gyro(free, y0, t, rtol=1e-13, atol=1e-15)
    ints0 = gy.free_gyro_integrals(free, y0)
    rows = []
    for rtol in rtols:

        def run(rtol=rtol):
            return gy.propagate_free_gyro(free, y0, t, rtol=rtol, atol=rtol * 1e-3)

        sec, (y, info) = _best(run, repeats, warm=True)
        ints = gy.free_gyro_integrals(free, y)
        drift = max(float(np.max(np.abs(x - x0))) / abs(float(x0)) for x, x0 in zip(ints, ints0))
        rows.append(_row("free gyroscope (gimbals)", "`propagate_free_gyro` (plain-float rhs)", f"rtol {rtol:g}", 6,
                         GYRO_SPAN, sec, fev=info["nfev"], err=f"{np.max(np.abs(y[:, :3] - ref[:, :3])):.1e} rad",
                         drift=f"T, p_psi, h {drift:.1e}"))
    # a rate gyro: 400 Hz rotor, gimbal at 30 Hz with damping ratio 0.7, on a base turning at
    # 0.2 rad/s about its input axis and 0.05 about the others
    C, A = 1e-4, 6e-5
    wn, zeta = 2 * math.pi * 30, 0.7
    k = wn * wn * A
    rate = gy.SingleAxisGyro.rate_gyro(C, A, 2 * math.pi * 400, k, 2 * zeta * math.sqrt(k * A))
    w = (0.2, 0.05, 0.05)
    exact = gy.steady_state_angle(rate, w)
    base = gy.constant_base_rate(w)
    t = np.linspace(0.0, GYRO_SPAN, N_OUT)
    for rtol in rtols:

        def run(rtol=rtol):
            return gy.propagate_single_axis(rate, base, t, rtol=rtol, atol=rtol * 1e-3)

        sec, (y, info) = _best(run, repeats, warm=True)
        rows.append(_row("rate gyro (single axis)", "`propagate_single_axis` (plain-float rhs)", f"rtol {rtol:g}", 3,
                         GYRO_SPAN, sec, fev=info["nfev"],
                         err=f"settled angle {abs(y[-1, 0] - exact) / abs(exact):.1e} rel. to the exact steady state"))
    return rows


def run(repeats: int = 3, quick: bool = False) -> dict:
    """All rows, in one process run; returns ``{"rows", "model_gap", "load", "seconds"}``."""
    rtols = RTOLS[:2] if quick else RTOLS
    t0 = time.perf_counter()
    load0 = os.getloadavg()
    print("[bench flexible] rigid ...", file=sys.stderr, flush=True)
    rows = rigid_rows(repeats, rtols)
    print("[bench flexible] flexible spacecraft ...", file=sys.stderr, flush=True)
    flex, gap = flexible_rows(repeats, rtols)
    rows += flex
    print("[bench flexible] rolling disk ...", file=sys.stderr, flush=True)
    rows += disk_rows(repeats, rtols)
    print("[bench flexible] gyroscopes ...", file=sys.stderr, flush=True)
    rows += gyro_rows(repeats, rtols)
    base_fev = min(r["cost"] for r in rows if r["method"].startswith("scipy DOP853, plain") and r["model"] == "rigid")
    rigid_dop = {r["setting"]: r["ms_per_sim_s"] for r in rows if r["method"].startswith("scipy DOP853, plain")}
    for r in rows:
        r["x_fev"] = r["cost"] / base_fev if r["cost_unit"] == "us/fev" else None
        r["x_sim"] = (
            r["ms_per_sim_s"] / rigid_dop[r["setting"]]
            if r["model"] in ("rigid", "flexible (4 antennas)") and r["setting"] in rigid_dop
            else None
        )
    return {"rows": rows, "model_gap": gap, "load": (load0[0], os.getloadavg()[0]), "seconds": time.perf_counter() - t0}


def table(result: dict, repeats: int) -> str:
    from astrodyn.bench import cpu_model

    rows = result["rows"]
    lines = [
        f"`astrodyn bench flexible`, {time.strftime('%Y-%m-%d %H:%M')}, {cpu_model()}, {os.cpu_count()} cores,"
        f" load average {result['load'][0]:.2f} at the start and {result['load'][1]:.2f} at the end,"
        f" best of {repeats} repeats ({result['seconds']:.0f} s in all).",
        "",
        "| model | method | setting | states | fev | wall (ms) | cost | ms per simulated s | error | drift"
        " | cost / rigid fev | time / rigid DOP853 same rtol |",
        "| --- | --- | --- | ---: | ---: | ---: | ---: | ---: | --- | --- | ---: | ---: |",
    ]
    for r in rows:
        fev = str(r["fev"]) if r["fev"] else (f"{r['steps']} steps" if r["steps"] else f"{r['outputs']} outputs")
        x_fev = f"{r['x_fev']:.1f}" if r["x_fev"] is not None else ""
        x_sim = f"{r['x_sim']:.3g}" if r["x_sim"] is not None else ""
        lines.append(
            f"| {r['model']} | {r['method']} | {r['setting']} | {r['states']} | {fev} | {1e3 * r['seconds']:.4g}"
            f" | {r['cost']:.3g} {r['cost_unit']} | {r['ms_per_sim_s']:.3g} | {r['err']} | {r['drift']}"
            f" | {x_fev} | {x_sim} |"
        )
    lines += [
        "",
        f"Rigid and flexible rows: the same spacecraft over {SPAN:g} s ({SPAN:g} spin turns); errors of the rigid rows"
        " against the exact solution, of the flexible rows against the flexible model at rtol 1e-13 (atol 1e-16),"
        " relative rate error over |w0|; a DOP853 step is 12 fev.  The flexible model's own attitude departs from the rigid composite's"
        f" by {result['model_gap']:.1e} rad over the span (modelling, not integration).  Rolling disk: {DISK_SPAN:g} s"
        " of the general motion of the rolling-disk section, errors against rtol 1e-13.  Gyroscopes:"
        f" {GYRO_SPAN:g} s; the free gyroscope (200 Hz rotor, massive gimbals, nutating from 0.05 rad off its"
        " working attitude) against rtol 1e-13, the rate gyro's settled angle against the exact steady state"
        " (30 Hz gimbal, damping ratio 0.7).  atol = 1e-3 rtol (1e-2 rtol for the disk).",
    ]
    return "\n".join(lines)


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """The options of ``astrodyn bench flexible``, checked (argparse's usage error, exit 2)."""
    p = argparse.ArgumentParser(prog="astrodyn bench flexible", description=__doc__.split("\n\n")[0])
    p.add_argument("--repeats", type=int_in(1, 20), default=3,
                   help="timing repeats, best kept, 1..20 (the tight runs take seconds each; default 3; half for rtol 1e-12)")
    p.add_argument("--quick", action="store_true", help="rtol 1e-6 and 1e-9 only, one repeat (a smoke run)")
    return p.parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(argv)
    repeats = 1 if args.quick else args.repeats
    result = run(repeats, args.quick)
    print(table(result, repeats))
    return 0


if __name__ == "__main__":
    sys.exit(main())
