"""The closed loop in a recording (docs/control.md): commands, actuators, momentum, pointing, delta-v.

For each actuated body (one with a ``<body>/actuators`` or ``<body>/command`` channel):

* commands: how many, from whom; wheel torque commanded (each command held until the
  next, zero-order hold) against applied after saturation, per wheel;
* wheels: speeds relative to the body (rad/s) against their ``max_speed``, steps clipped;
* angular momentum, inertial frame (N m s): body ``C(q)^T I_kin w`` (a flexible body: its
  hub and appendages, :func:`astrodyn.attitude.flexible.spacecraft_momentum`), wheels
  ``C(q)^T sum_k h_k a_k`` with ``h_k = J_k (a_k . w + Omega_k)``, and their sum, which
  internal (wheel) torques cannot change: its drift is the check of a wheels-only loop;
* pointing knowledge: the angle between the true attitude and the star tracker's
  (``2 acos |q_true . q_meas|``, deg);
* delta-v: the budget spent (``dv_total``), each impulse.

Everything from the file is hostile: a channel that is missing, short or holds other
fields leaves its part of the section out, never a traceback.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from astrodyn.analysis.recorded_scenario import recorded_body
from astrodyn.rotation import dcm_from_quat

__all__ = ["closed_loop_section", "CLOSED_LOOP_FIGURES"]

CLOSED_LOOP_FIGURES = {
    "wheel-torque": "wheel torque commanded (held) and applied, per wheel",
    "wheel-speed": "wheel speeds and their limits",
    "momentum": "angular momentum of body, wheels and their sum, inertial frame",
    "pointing": "pointing knowledge: star tracker vs truth",
    "delta-v": "delta-v spent",
}


def _wheels(scenario_meta: dict, name: str):
    """The body's wheels from the recorded config: (axes (n, 3), J (n,), max_speed (n,),
    inertia (3, 3)) or None."""
    body = recorded_body(scenario_meta, name)  # None for a foreign or damaged scenario record
    wheels = body.actuators.wheels if body is not None and body.actuators is not None else ()
    if not wheels or body.attitude is None:
        return None
    return (np.array([w.axis for w in wheels]), np.array([w.inertia for w in wheels]),
            np.array([w.max_speed for w in wheels]), np.asarray(body.attitude.inertia, dtype=np.float64))


def _rows(track, field: str, n: int | None = None) -> np.ndarray | None:
    """A field of variable-length lists as an (m, n) float array (rows of other lengths: NaN)."""
    try:
        values = getattr(track, field)
    except AttributeError:
        return None
    values = list(values)
    n = n or max((len(v) for v in values if isinstance(v, (list, tuple, np.ndarray))), default=0)
    if n == 0:
        return None
    out = np.full((len(values), n), np.nan)
    for i, v in enumerate(values):
        if isinstance(v, (list, tuple, np.ndarray)) and len(v) == n:
            out[i] = np.asarray(v, dtype=np.float64)
    return out


def _flexible_hub_momentum(run, name: str, prefix: str, i_kin: np.ndarray, t: np.ndarray, q: np.ndarray,
                           w: np.ndarray) -> np.ndarray | None:
    """The inertial angular momentum (N m s) of a flexible body's hub and appendages at the
    recorded times ``t`` (its ``<body>/appendages`` states at the same times), with the
    hub inertia ``i_kin`` (the wheels' axial moments taken out, as the plant integrates
    it); None for a rigid body or when the record does not hold what it needs."""
    from astrodyn.analysis.invariants import appendage_arrays, flexible_states
    from astrodyn.attitude import flexible as fx
    from astrodyn.scenario.appendages import flexible_spacecraft

    body = recorded_body(run.scenario, name)
    app = run.channels.get(prefix + "appendages")
    if body is None or body.attitude is None or body.attitude.model != "flexible" or app is None or not len(app):
        return None
    arrays = appendage_arrays(app)
    a = body.attitude
    try:
        sc = flexible_spacecraft(a.mass, i_kin, a.appendages, a.stiffening)
    except ValueError:
        return None
    if arrays is None or arrays[0].shape[1] != sc.n_elastic:
        return None
    k = np.searchsorted(np.asarray(app.t), t)
    if np.any(k >= len(app)) or np.any(np.asarray(app.t)[np.minimum(k, len(app) - 1)] != t):
        return None
    _, h = fx.spacecraft_momentum(sc, flexible_states(sc, q, w, arrays[0][k], arrays[1][k]))
    return h


def closed_loop_section(run, name: str, stem: Path) -> tuple[dict, list[tuple[str, Path]]]:
    """``({"closed loop": numbers}, figures)`` for body ``name`` of ``run`` (a
    :class:`astrodyn.recording.reader.Run`), figures written as ``<stem>-<kind>.png``."""
    from astrodyn.analysis import figures as fg  # matplotlib: only when a report is drawn

    prefix = f"astrodyn/{run.scenario.get('name', '')}/{name}/"
    act, cmd = run.channels.get(prefix + "actuators"), run.channels.get(prefix + "command")
    if act is None and cmd is None:
        return {}, []
    numbers: dict = {}
    figs: list[tuple[str, Path]] = []
    if cmd is not None and len(cmd):
        numbers["commands"] = len(cmd)
        numbers["senders"] = sorted({str(s) for s in getattr(cmd, "sender", [])})
    if act is None or len(act) == 0:
        return {"closed loop": numbers}, figs
    t = np.asarray(act.t, dtype=np.float64)
    applied = _rows(act, "wheel_torque")
    speeds = _rows(act, "wheel_speed")
    geometry = _wheels(run.scenario, name)
    if applied is not None:
        n = applied.shape[1]
        commanded = np.full_like(applied, np.nan)
        if cmd is not None and len(cmd):
            wc = _rows(cmd, "wheel_torque", n)
            if wc is not None:
                order = np.argsort(np.asarray(cmd.t, dtype=np.float64), kind="stable")
                ct, wc = np.asarray(cmd.t, dtype=np.float64)[order], wc[order]
                have = ~np.isnan(wc[:, 0])
                ct, wc = ct[have], wc[have]
                idx = np.searchsorted(ct, t, side="right") - 1  # the command in force at each step (held)
                commanded[idx >= 0] = wc[idx[idx >= 0]]
        clipped = np.zeros(n, dtype=int)
        for c in getattr(act, "clipped", []):
            if isinstance(c, (list, tuple, np.ndarray)):
                for k in c:
                    if isinstance(k, (int, np.integer)) and not isinstance(k, bool) and 0 <= k < n:
                        clipped[k] += 1
        numbers["steps clipped per wheel"] = clipped.tolist()
        figs.append(("wheel-torque", fg.stacked_pairs(t, commanded, applied, "commanded (held)", "applied",
                                                      "wheel torque (N m)", f"{name}: wheel torques",
                                                      Path(f"{stem}-wheel-torque.png"))))
    if speeds is not None:
        peak = np.nanmax(np.abs(speeds), axis=0)
        numbers["peak wheel speed (rad/s)"] = [float(x) for x in peak]
        limits = geometry[2] if geometry is not None and geometry[2].shape[0] == speeds.shape[1] else None
        if limits is not None:
            numbers["wheel speed limit (rad/s)"] = [float(x) for x in limits]
        figs.append(("wheel-speed", fg.stacked_pairs(t, speeds, None if limits is None else np.broadcast_to(limits, speeds.shape),
                                                     "speed", "limit", "speed (rad/s)", f"{name}: wheel speeds",
                                                     Path(f"{stem}-wheel-speed.png"))))
    att = run.channels.get(prefix + "attitude")
    if att is not None and len(att) and speeds is not None and geometry is not None:
        axes, J, _, inertia = geometry
        k = np.searchsorted(np.asarray(att.t), t)
        ok = (k < len(att)) & ~np.isnan(speeds[:, 0])
        k, ts, sp = k[ok], t[ok], speeds[ok]
        ok2 = np.asarray(att.t)[k] == ts
        k, ts, sp = k[ok2], ts[ok2], sp[ok2]
        if ts.size and axes.shape[0] == sp.shape[1]:
            q, w = np.asarray(att.q)[k], np.asarray(att.w)[k]
            i_kin = inertia - np.einsum("k,ki,kj->ij", J, axes, axes)
            h = J * (w @ axes.T + sp)  # absolute axial momenta
            ct = np.transpose(dcm_from_quat(q), (0, 2, 1))  # C^T: body -> inertial
            h_body = np.einsum("nij,nj->ni", ct, w @ i_kin.T)
            flexible = _flexible_hub_momentum(run, name, prefix, i_kin, np.asarray(att.t)[k], q, w)
            if flexible is not None:  # hub + appendages (astrodyn.attitude.flexible), not the rigid hub alone
                h_body = flexible
            h_wheels = np.einsum("nij,nj->ni", ct, h @ axes)
            total = h_body + h_wheels
            drift = np.linalg.norm(total - total[0], axis=1)
            scale = max(float(np.max(np.linalg.norm(h_body, axis=1))), float(np.max(np.linalg.norm(h_wheels, axis=1))), 1e-300)
            numbers["max |H - H0| of body + wheels, inertial (N m s)"] = float(np.max(drift))
            numbers["relative to the largest |H_body|, |H_wheels|"] = float(np.max(drift) / scale)
            external = getattr(act, "torque", None)
            numbers["external torque applied"] = bool(external is not None and np.any(np.nan_to_num(np.asarray(external)) != 0))
            figs.append(("momentum", fg.stacked_pairs(
                ts, np.stack([np.linalg.norm(h_body, axis=1), np.linalg.norm(h_wheels, axis=1)], axis=1),
                np.stack([np.linalg.norm(total, axis=1)] * 2, axis=1), "|H| body, wheels", "|H| sum",
                "N m s", f"{name}: angular momentum (inertial)", Path(f"{stem}-momentum.png"))))
    tracker = run.channels.get(prefix + "star_tracker")
    if att is not None and tracker is not None and len(tracker) and len(att):
        k = np.searchsorted(np.asarray(att.t), np.asarray(tracker.t))
        ok = k < len(att)
        k, tt = k[ok], np.asarray(tracker.t)[ok]
        same = np.asarray(att.t)[k] == tt
        if np.any(same):
            qt, qm = np.asarray(att.q)[k[same]], np.asarray(tracker.q)[ok][same]
            dot = np.clip(np.abs(np.sum(qt * qm, axis=1)), 0.0, 1.0)
            angle = np.degrees(2.0 * np.arccos(dot))
            numbers["pointing knowledge error, median (deg)"] = float(np.median(angle))
            numbers["pointing knowledge error, max (deg)"] = float(np.max(angle))
            figs.append(("pointing", fg.stacked_pairs(tt[same], angle[:, None], None, "star tracker vs truth", "",
                                                      "angle (deg)", f"{name}: pointing knowledge",
                                                      Path(f"{stem}-pointing.png"))))
    dv_total = getattr(act, "dv_total", None) if "dv_total" in act.fields else None
    if dv_total is not None and np.any(~np.isnan(np.asarray(dv_total, dtype=np.float64))):
        dvt = np.asarray(dv_total, dtype=np.float64)
        numbers["delta-v spent (m/s)"] = float(np.nanmax(dvt))
        impulses = np.asarray(act.dv, dtype=np.float64) if "dv" in act.fields else np.empty((0, 3))
        if impulses.ndim == 2 and impulses.shape[1] == 3:
            hit = ~np.isnan(impulses[:, 0])
            applied = np.asarray(act.dv_t, dtype=np.float64) if "dv_t" in act.fields else np.full(len(t), np.nan)
            numbers["impulses"] = [{"step t (s)": float(tt), "applied at t (s)": None if np.isnan(at) else float(at),
                                    "dv (m/s)": float(np.linalg.norm(d))}
                                   for tt, at, d in zip(t[hit], applied[hit], impulses[hit])][:100]
        figs.append(("delta-v", fg.stacked_pairs(t, dvt[:, None], None, "dv spent", "", "m/s", f"{name}: delta-v",
                                                 Path(f"{stem}-delta-v.png"))))
    return {"closed loop": numbers}, figs
