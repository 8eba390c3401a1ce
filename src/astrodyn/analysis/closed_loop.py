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
* delta-v: the budget spent (``dv_total``), each impulse;
* orbit across burns: the coast arcs of the orbit between its burns
  (:class:`OrbitActuation`) and how much each burn changed the specific energy ``E`` (J/kg)
  and angular momentum ``h`` (m^2/s), from the states on either side (an impulse: by
  ``v.dv + |dv|^2/2``).

Everything from the file is hostile: a channel that is missing, short or holds other
fields leaves its part of the section out, never a traceback.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from astrodyn.rotation import dcm_from_quat
from astrodyn.scenario.recorded import recorded_body

__all__ = ["closed_loop_section", "CLOSED_LOOP_FIGURES", "OrbitActuation", "burn_changes"]

CLOSED_LOOP_FIGURES = {
    "wheel-torque": "wheel torque commanded (held) and applied, per wheel",
    "wheel-speed": "wheel speeds and their limits",
    "momentum": "angular momentum of body, wheels and their sum, inertial frame",
    "pointing": "pointing knowledge: star tracker vs truth",
    "delta-v": "delta-v spent",
}


def _finite_rows(track, field: str) -> np.ndarray | None:
    """A 3-vector field of a recorded track as an (n, 3) float array (a message without the
    field: a NaN row), or None when the track has no such field."""
    if track is None or field not in getattr(track, "fields", {}):
        return None
    try:
        rows = np.asarray(getattr(track, field), dtype=np.float64)
    except (TypeError, ValueError):
        return None
    return rows if rows.ndim == 2 and rows.shape[1] == 3 and rows.shape[0] == len(track) else None


class OrbitActuation:
    """When burns moved a body's orbit, gathered from its recorded closed-loop channels
    (docs/control.md): the impulses (sim times, s) and the intervals of held thrust
    (``[start, end)`` s, ``end`` inf while held), from both the actuator states
    (``<body>/actuators``: ``dv`` with its ``dv_t``, and ``thrust`` over the output step
    starting at ``t``) and the applied commands (``<body>/command``, the plant's copies: a
    ``dv`` at ``t``, a ``thrust`` held from ``t`` until a command changes it).  Both are
    kept (a thrust command inside a step shows in the actuator state only from the next
    step; a late command of free mode applies after its ``t``): more breaks only shorten
    the coast arcs.  Fed block by block (:meth:`add`, in log-time order, as
    :func:`astrodyn.recording.load_blocks` gives them); memory grows with the number of
    burns, not of steps.  Everything from the file is hostile: a field that is missing or
    not a number is left out."""

    def __init__(self):
        self.impulses: list[float] = []  #: sim times of the impulses, s
        self.thrust: list[list[float]] = []  #: [start, end) of thrust, s, from both channels
        self._held_by_actuators: list[float] | None = None  # the open interval of each source
        self._held_by_commands: list[float] | None = None
        self._command_thrust: tuple[float, bool] | None = None  # (t, on) of the last thrust command seen

    def __bool__(self) -> bool:
        return bool(self.impulses or self.thrust)

    def add(self, actuators=None, commands=None) -> None:
        """Fold one block of the body's ``actuators`` and applied ``commands`` tracks (either None)."""
        if actuators is not None and len(actuators):
            t = np.asarray(actuators.t, dtype=np.float64)
            dv = _finite_rows(actuators, "dv")
            if dv is not None:
                hit = np.isfinite(dv).all(axis=1)
                at = np.asarray(actuators.dv_t, dtype=np.float64) if "dv_t" in actuators.fields else np.full(t.shape, np.nan)
                self.impulses += [float(a if np.isfinite(a) else s) for s, a in zip(t[hit], at[hit])]
            thrust = _finite_rows(actuators, "thrust")
            if thrust is not None:
                on = np.isfinite(thrust).all(axis=1) & np.any(thrust != 0, axis=1)
                for tk, is_on in zip(t, on):
                    self._held_by_actuators = self._hold(self._held_by_actuators, float(tk), bool(is_on))
        if commands is not None and len(commands):
            t = np.asarray(commands.t, dtype=np.float64)
            order = np.argsort(t, kind="stable")
            dv = _finite_rows(commands, "dv")
            if dv is not None:
                self.impulses += [float(x) for x in t[np.isfinite(dv).all(axis=1)]]
            thrust = _finite_rows(commands, "thrust")
            if thrust is not None:
                for k in order:
                    if np.isfinite(thrust[k]).all() and np.isfinite(t[k]):
                        self._held_by_commands = self._hold(self._held_by_commands, float(t[k]), bool(np.any(thrust[k] != 0)))
        self.impulses = sorted(set(x for x in self.impulses if np.isfinite(x)))

    def _hold(self, held: list[float] | None, t: float, on: bool) -> list[float] | None:
        """One source's thrust from ``t`` on: opens an interval (end inf) or closes the open one at ``t``."""
        if on and held is None:
            held = [t, np.inf]
            self.thrust.append(held)
        elif not on and held is not None:
            held[1] = max(t, held[0])
            held = None
        return held

    def arc_starts(self, t: np.ndarray, t_before: float | None = None) -> np.ndarray:
        """(n,) bool for states at sim times ``t`` (s, increasing): True where a coast arc
        begins, i.e. where a burn lies between the state and the one before it (the state at
        ``t_before`` for the first; None: the first state of the orbit, which begins one).
        An impulse at ``tau`` separates states at ``a <= tau <= b`` (the state at ``tau``
        itself, before or after the impulse by the plant's order of work, is an arc of its
        own), thrust over ``[s, e)`` separates ``a`` and ``b`` when it overlaps ``(a, b)``."""
        t = np.asarray(t, dtype=np.float64).reshape(-1)
        before = np.concatenate([[np.nan if t_before is None else t_before], t[:-1]])
        starts = np.zeros(t.shape, dtype=bool)
        if self.impulses:
            tau = np.asarray(self.impulses)
            starts |= np.searchsorted(tau, t, side="right") > np.searchsorted(tau, before, side="left")
        if self.thrust:
            spans = sorted((s, e) for s, e in self.thrust)
            merged: list[list[float]] = []
            for s, e in spans:  # disjoint, sorted: ends increase with starts
                if merged and s <= merged[-1][1]:
                    merged[-1][1] = max(merged[-1][1], e)
                else:
                    merged.append([s, e])
            lo, hi = np.array([m[0] for m in merged]), np.array([m[1] for m in merged])
            k = np.searchsorted(lo, t, side="left") - 1  # the last interval starting before b
            starts |= (k >= 0) & (hi[np.maximum(k, 0)] > before)
        if t_before is None and t.size:
            starts[0] = True
        return starts


def burn_changes(t: np.ndarray, r: np.ndarray, v: np.ndarray, mu: float, arc_starts: np.ndarray,
                 limit: int = 100) -> list[dict]:
    """What each burn changed, from the recorded states on either side of it: per run of
    consecutive coast-arc starts (``arc_starts``, :meth:`OrbitActuation.arc_starts`; states
    within a burn are arcs of one state each) the times of the states before and after,
    the change of the specific energy ``E = |v|^2/2 - mu/|r|`` (J/kg) and of
    ``h = r x v`` (m^2/s, the norm of the vector change).  For an impulse ``dv`` applied
    at velocity ``v`` the energy changes by ``v.dv + |dv|^2/2`` (vis-viva); the first
    ``limit`` burns."""
    t, r, v = np.asarray(t, dtype=np.float64), np.asarray(r, dtype=np.float64), np.asarray(v, dtype=np.float64)
    energy = 0.5 * np.einsum("ij,ij->i", v, v) - mu / np.linalg.norm(r, axis=1)
    h = np.cross(r, v)
    breaks = np.flatnonzero(np.asarray(arc_starts, dtype=bool)[1:]) + 1
    out = []
    k = 0
    while k < breaks.size and len(out) < limit:
        first = last = breaks[k]
        while k + 1 < breaks.size and breaks[k + 1] == last + 1:
            k += 1
            last = breaks[k]
        before, after = first - 1, last
        out.append({"from t (s)": float(t[before]), "to t (s)": float(t[after]),
                    "E change (J/kg)": float(energy[after] - energy[before]),
                    "|h change| (m^2/s)": float(np.linalg.norm(h[after] - h[before]))})
        k += 1
    return out


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
    orbit = run.channels.get(prefix + "orbit")
    if orbit is not None and len(orbit) > 1 and "mu" in orbit.fields:
        actuation = OrbitActuation()
        actuation.add(act, cmd)
        if actuation:
            numbers["orbit change across each burn"] = burn_changes(orbit.t, orbit.r, orbit.v, float(orbit.mu[0]),
                                                                   actuation.arc_starts(orbit.t))
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
