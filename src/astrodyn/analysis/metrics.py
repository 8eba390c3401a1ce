"""Numbers of the analysis report, computed from the recorded arrays (no plotting here).

Orbit (two-body quantities, whatever the orbit's model, Vallado 4th ed. sec. 1.3 / 2.2; the
quantities each model conserves, with J2 for a J2 orbit, are
:mod:`astrodyn.analysis.invariants`): specific energy
``E = |v|^2 / 2 - mu / |r|`` (J/kg) and specific angular momentum ``h = r x v`` (m^2/s);
their drifts are ``max_k |E_k - E_0| / |E_0|`` and ``max_k |h_k - h_0| / |h_0|``
(exact constants for a Kepler orbit; for a perturbed orbit the drift *is* the
perturbation's effect, reported as such).  A quantity that starts at 0 (``E_0 = 0`` on a
parabola, ``T_0 = H_0 = 0`` for a body at rest) has its drift reported as the absolute
``max_k |x_k - x_0|`` in its unit instead (``*_drift_max_abs``; :func:`drift_against`).
Elements: :func:`astrodyn.orbit.elements_from_state`.

Attitude (Baruh ch. 7-8): kinetic energy ``T = w . I w / 2`` (J), body angular momentum
``H_b = I w`` (kg m^2/s), inertial ``H_i = C(q)^T H_b`` (``v_body = C(q) v_inertial``,
:func:`inertial_from_body`); these are the rigid body's ``T`` and ``H_i``,
which the report labels so (a gyrostat's conserved ``H_i`` adds its rotors' momentum: the
report's "conserved quantities", :mod:`astrodyn.analysis.invariants`);
for torque-free motion ``T`` and ``H_i`` are constants and their drifts are relative
like the orbit's.  ``|q| - 1`` is reported as the largest absolute deviation.  Tops
(body axis 3 the symmetry axis, gravity along -Z inertial): the 3-1-3 Euler angles of
``C(q)`` are precession ``phi``, nutation ``theta`` and spin ``psi`` (Baruh sec. 10.x,
Goldstein sec. 5.7).

Ground track (Earth only): geocentric latitude ``asin(z / r)`` and longitude
``atan2(y, x) - GMST``, with GMST from the IAU 1982 formula (Vallado 4th ed. eq. 3-47)
of UT1 taken equal to UTC (the POSIX log time), and the inertial frame treated as the
true-of-date frame: precession since J2000 shifts longitudes by up to about 0.4 deg
in 2026, invisible on a whole-Earth map.
"""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np

from astrodyn.orbit import elements_from_state
from astrodyn.rotation import dcm_from_quat, euler_from_quat

__all__ = [
    "relative_drift", "drift_against", "drift_summary", "coast_arc_first", "drift_over_arcs", "relative_drift_over_arcs",
    "radius_of", "time_span", "inertial_from_body", "orbit_metrics", "attitude_metrics", "gmst_rad",
    "ground_track", "BodyInertia", "inertia_from_scenario", "central_body_from_scenario",
]

_J2000_JD = 2451545.0
_UNIX_EPOCH_JD = 2440587.5


def relative_drift(x: np.ndarray) -> np.ndarray:
    """``|x_k - x_0| / |x_0|`` per sample (vectors: Euclidean norms); 0/0 -> 0, and inf
    where x moved from ``x_0 = 0`` (the report's numbers use :func:`drift_against` there)."""
    x = np.asarray(x, dtype=np.float64)
    d = x - x[:1]
    num = np.linalg.norm(d, axis=-1) if x.ndim > 1 else np.abs(d)
    den = np.linalg.norm(x[0]) if x.ndim > 1 else abs(x[0])
    if den == 0:
        return np.where(num == 0, 0.0, np.inf)
    return num / den


def drift_against(x: np.ndarray, scale: float) -> tuple[float, bool]:
    """The largest drift of ``x`` (samples along axis 0; vectors: Euclidean norms) from
    ``x[0]``: ``(max_k |x_k - x_0| / scale, True)``, or, when ``scale`` is 0 -- a body at
    rest (``T_0 = 0``, ``H_0 = 0``), a parabola (``E_0 = 0``), a radial orbit (``h_0 = 0``),
    where a relative drift is 0/0 or inf -- ``(max_k |x_k - x_0|, False)``, in the unit of
    ``x``.  The one rule of every drift the report and the run summary give."""
    x = np.asarray(x, dtype=np.float64)
    d = x - x[:1]
    dev = float(np.max(np.linalg.norm(d, axis=-1) if x.ndim > 1 else np.abs(d))) if x.shape[0] else 0.0
    if scale == 0:
        return dev, False
    return dev / scale, True


def drift_summary(name: str, x: np.ndarray) -> dict[str, float]:
    """The report's number for the drift of ``x`` from ``x[0]`` (:func:`drift_against`
    relative to ``|x_0|``): ``{name + "_drift_max": relative}``, or when ``x_0 = 0``
    ``{name + "_drift_max_abs": absolute}`` in the unit of ``x`` (the report's labels give it)."""
    x = np.asarray(x, dtype=np.float64)
    scale = float(np.linalg.norm(x[0])) if x.shape[0] else 1.0
    value, relative = drift_against(x, scale)
    return {f"{name}_drift_max" if relative else f"{name}_drift_max_abs": value}


def coast_arc_first(arc_starts: np.ndarray) -> np.ndarray:
    """For each sample, the index of the first sample of its coast arc.  ``arc_starts``
    (n,) bool: True where an arc begins (an orbit's states between two burns,
    :class:`astrodyn.analysis.closed_loop.OrbitActuation`); the first sample always
    begins one, whatever ``arc_starts[0]`` says."""
    starts = np.asarray(arc_starts, dtype=bool).copy()
    if starts.size:
        starts[0] = True
    index = np.where(starts, np.arange(starts.size), 0)
    return np.maximum.accumulate(index) if starts.size else index


def drift_over_arcs(x: np.ndarray, arc_starts: np.ndarray, scales: np.ndarray | None = None) -> tuple[float, bool]:
    """:func:`drift_against` on each coast arc on its own, the largest over the arcs: the
    drift of a quantity that only burns change (an actuated orbit's energy and angular
    momentum), ``max_k |x_k - x_a(k)| / scale_a(k)`` with ``a(k)`` the first sample of the
    arc of sample ``k`` (:func:`coast_arc_first`) and ``scale_a`` that arc's scale
    (``scales``: one per sample, read at each arc's first sample; default ``|x_a|``).
    ``(drift, True)``, or ``(max_k |x_k - x_a(k)|, False)`` in the unit of ``x`` when
    some arc's scale is 0 (as :func:`drift_against` for a single arc)."""
    x = np.asarray(x, dtype=np.float64)
    if not x.shape[0]:
        return 0.0, True
    first = coast_arc_first(arc_starts)
    d = x - x[first]
    dev = np.linalg.norm(d, axis=-1) if x.ndim > 1 else np.abs(d)
    scale = (np.linalg.norm(x, axis=-1) if x.ndim > 1 else np.abs(x)) if scales is None \
        else np.asarray(scales, dtype=np.float64)
    scale = scale[first]
    if np.any(scale == 0):
        return float(np.max(dev)), False
    return float(np.max(dev / scale)), True


def relative_drift_over_arcs(x: np.ndarray, arc_starts: np.ndarray | None, scales: np.ndarray | None = None) -> np.ndarray:
    """:func:`relative_drift` per sample with ``x_0`` the first sample of its coast arc
    (:func:`coast_arc_first`; ``arc_starts`` None: one arc, from the first sample):
    ``|x_k - x_a(k)| / s_a(k)``, 0/0 -> 0, inf where x moved from ``s = 0``.  The scale
    ``s`` is ``|x|`` or, given, ``scales`` (one per sample, read at each arc's first
    sample: an energy near 0 drifts relative to ``mu/|r|``, ``h_z`` relative to ``|h|``)."""
    x = np.asarray(x, dtype=np.float64)
    first = coast_arc_first(np.zeros(x.shape[0], dtype=bool) if arc_starts is None else arc_starts)
    d = x - x[first]
    num = np.linalg.norm(d, axis=-1) if x.ndim > 1 else np.abs(d)
    den = ((np.linalg.norm(x, axis=-1) if x.ndim > 1 else np.abs(x)) if scales is None
           else np.asarray(scales, dtype=np.float64))[first]
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den == 0, np.where(num == 0, 0.0, np.inf), num / np.where(den == 0, 1.0, den))


def radius_of(r: np.ndarray) -> np.ndarray:
    """``|r|`` of each row of ``r`` (n, 3), without overflow: a finite ``r`` of 1e308 m has
    the finite norm 1.7e308 m (``np.linalg.norm`` squares it to inf)."""
    r = np.asarray(r, dtype=np.float64)
    return np.hypot(np.hypot(r[..., 0], r[..., 1]), r[..., 2])


def time_span(t: np.ndarray) -> float:
    """The span of the times ``t`` (s): ``max - min`` (0 for none), the extent of the
    report's time axes; ``t[-1] - t[0]`` when t increases with seq, as the recording's
    contract says (a channel that breaks it is named by
    :func:`astrodyn.recording.reader.time_order`)."""
    return float(np.max(t) - np.min(t)) if np.size(t) else 0.0


def inertial_from_body(q: np.ndarray, x_body: np.ndarray) -> np.ndarray:
    """Body-axis vectors ``x_body`` (n, 3) in inertial axes, ``C(q)^T x_body``, ``q`` (n, 4)
    Euler parameters, scalar first (:func:`astrodyn.rotation.dcm_from_quat`: a proper
    rotation for any nonzero q, a recorded ``|q|`` being 1 within 1e-9).  The one
    ``H_i = C^T H_b`` of the report's attitude table and of its conserved quantities, so
    both give one value for one drift (they differed in the last digits)."""
    return np.einsum("kji,kj->ki", dcm_from_quat(q), np.asarray(x_body, dtype=np.float64))


def orbit_metrics(t: np.ndarray, r: np.ndarray, v: np.ndarray, mu: float, arc_starts: np.ndarray | None = None) -> dict:
    """Energy, angular momentum (and their drifts), elements over time.

    ``arc_starts`` (n,) bool, for an orbit that burns moved (impulses, thrust: True where a
    coast arc begins, :class:`astrodyn.analysis.closed_loop.OrbitActuation`): the drifts
    are taken over each coast arc from its own first state (:func:`drift_over_arcs`) and
    the summary's keys say so (``energy_coast_drift_max``, ``h_coast_drift_max``; the
    ``_abs`` variants when an arc starts at 0), with the number of ``coast_arcs`` of two
    states or more (a state alone is at or inside a burn): the changes the burns make are
    not drift."""
    rn = radius_of(r)
    energy = 0.5 * np.einsum("ij,ij->i", v, v) - mu / rn
    h = np.cross(r, v)
    el = elements_from_state(r, v, mu)
    if arc_starts is None:
        e_drift = relative_drift(energy)
        h_drift = relative_drift(h)
        drifts = {**(drift_summary("energy", energy) if t.size else {"energy_drift_max": 0.0}),
                  **(drift_summary("h", h) if t.size else {"h_drift_max": 0.0})}
    else:
        e_drift = relative_drift_over_arcs(energy, arc_starts)
        h_drift = relative_drift_over_arcs(h, arc_starts)
        arcs = np.bincount(coast_arc_first(arc_starts), minlength=t.size) if t.size else np.zeros(0, dtype=int)
        drifts = {"coast_arcs": int(np.count_nonzero(arcs >= 2))}  # a state alone is at or inside a burn
        for name, x in (("energy", energy), ("h", h)):
            value, relative = drift_over_arcs(x, arc_starts)
            drifts[f"{name}_coast_drift_max" if relative else f"{name}_coast_drift_max_abs"] = value
    return {
        "t": t, "energy": energy, "h": h, "energy_drift": e_drift, "h_drift": h_drift, "elements": el,
        "radius": rn,
        "summary": {
            "states": int(t.size),
            "t_span_s": time_span(t),
            **drifts,
            "r_min_m": float(rn.min()) if t.size else 0.0,
            "r_max_m": float(rn.max()) if t.size else 0.0,
        },
    }


@dataclass
class BodyInertia:
    """Inertia (body frame, kg m^2), and for heavy tops m, cm distance (m) and g (m/s^2)."""

    inertia: np.ndarray
    model: str = ""
    mass: float | None = None
    cm: float | None = None
    g: float | None = None

    @property
    def is_top(self) -> bool:
        return self.model == "heavy_top" or (self.mass is not None and self.cm is not None)


def _scenario_json(scenario: dict) -> dict:
    try:
        data = json.loads(scenario.get("json", "{}"))
        return data if isinstance(data, dict) else {}
    except (TypeError, ValueError, RecursionError):  # the file's metadata: any text, nested past the parser's depth
        return {}


def inertia_from_scenario(scenario: dict) -> dict[str, BodyInertia]:
    """Per body with an attitude: its inertia (and top parameters) from the scenario metadata."""
    out = {}
    bodies = _scenario_json(scenario).get("bodies")
    for b in bodies if isinstance(bodies, list) else []:
        att = b.get("attitude") if isinstance(b, dict) else None
        if not isinstance(att, dict) or att.get("inertia") is None or not isinstance(b.get("name"), str):
            continue
        try:
            inertia = np.array(att["inertia"], dtype=np.float64).reshape(3, 3)
        except (ValueError, TypeError):
            continue
        out[b["name"]] = BodyInertia(inertia, str(att.get("model_used") or att.get("model") or ""),
                                     att.get("mass"), att.get("cm"), att.get("g"))
    return out


def central_body_from_scenario(scenario: dict) -> dict:
    """``{"name", "mu", "radius"}`` of the scenario's central body ({} when unknown)."""
    cb = _scenario_json(scenario).get("central_body") or {}
    return {k: cb[k] for k in ("name", "mu", "radius") if k in cb} if isinstance(cb, dict) else {}


def attitude_metrics(t: np.ndarray, q: np.ndarray, w: np.ndarray, seq: str,
                     body: BodyInertia | None = None) -> dict:
    """Euler angles (``seq``), ``|q| - 1``, and with the inertia: T, H_b, H_i and drifts."""
    angles = euler_from_quat(q, seq)
    out = {"t": t, "euler": angles, "seq": seq}
    summary = {
        "states": int(t.size),
        "t_span_s": time_span(t),
        "quat_norm_error_max": float(np.max(np.abs(np.linalg.norm(q, axis=-1) - 1.0))) if t.size else 0.0,
        "rate_max_rad_s": float(np.max(np.linalg.norm(w, axis=-1))) if t.size else 0.0,
    }
    if body is not None:
        hb = w @ body.inertia.T
        energy = 0.5 * np.einsum("ij,ij->i", w, hb)
        hi = inertial_from_body(q, hb)
        out.update(kinetic_energy=energy, h_body=hb, h_inertial=hi,
                   energy_drift=relative_drift(energy), h_inertial_drift=relative_drift(hi))
        if t.size:
            summary.update(drift_summary("kinetic_energy", energy), **drift_summary("h_inertial", hi))
        if body.is_top:
            e313 = euler_from_quat(q, "313")
            out.update(precession=np.unwrap(e313[:, 0]), nutation=e313[:, 1])
            summary.update(nutation_min_deg=float(np.degrees(e313[:, 1].min())),
                           nutation_max_deg=float(np.degrees(e313[:, 1].max())))
    out["summary"] = summary
    return out


def gmst_rad(unix_ns: np.ndarray) -> np.ndarray:
    """Greenwich mean sidereal time (rad, in [0, 2 pi)) at POSIX times, UT1 = UTC.

    IAU 1982 (Vallado 4th ed. eq. 3-47): GMST = 67310.54841 s + (876600 h + 8640184.812866 s) T
    + 0.093104 s T^2 - 6.2e-6 s T^3, T Julian centuries of UT1 from J2000.
    """
    ns = np.asarray(unix_ns)
    if ns.dtype.kind != "u":  # Track.log_time is uint64 (to 2554): int64 would wrap times after 2262-04-11
        ns = ns.astype(np.int64)
    days = (ns // 86_400_000_000_000).astype(np.float64) + (ns % 86_400_000_000_000) / 8.64e13
    tu = (days + (_UNIX_EPOCH_JD - _J2000_JD)) / 36525.0
    sec = 67310.54841 + (876600.0 * 3600.0 + 8640184.812866) * tu + 0.093104 * tu**2 - 6.2e-6 * tu**3
    return np.mod(np.radians(np.mod(sec, 86400.0) / 240.0), 2 * np.pi)


def ground_track(r: np.ndarray, unix_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(longitude, geocentric latitude) in rad, longitude in [-pi, pi) (see module docstring)."""
    lon = np.arctan2(r[:, 1], r[:, 0]) - gmst_rad(unix_ns)
    lon = np.mod(lon + np.pi, 2 * np.pi) - np.pi
    lat = np.arcsin(np.clip(r[:, 2] / np.linalg.norm(r, axis=-1), -1.0, 1.0))
    return lon, lat
