"""The quantities each model conserves, and how far a recording drifts from them.

One table for the end-of-run summary of ``astrodyn run`` and for ``astrodyn analyze``:
each row names the quantity, its unit, its initial value and its largest drift over the
recording, so a drift is read against the model's own physics (a J2 orbit does not
conserve the two-body energy: its summary shows the energy *with* the zonal potential).

Orbit (per model; ``V`` the gravitational potential, acceleration ``= grad V``):

* ``kepler`` -- specific energy ``E = |v|^2/2 - mu/|r|`` (J/kg) and angular momentum
  ``h = r x v`` (m^2/s, vector): two-body constants (Vallado 4th ed. sec. 1.3).
* ``j2`` / ``zonal`` (no third body) -- ``E = |v|^2/2 - mu/|r| - V_zonal(r)`` (J/kg) with
  the zonal potential of :func:`astrodyn.orbit.zonal_potential` (J2..Jn of the central
  body, axisymmetric about the frame's z axis), and ``h_z`` (m^2/s), the polar component
  of ``h``: a zonal field exerts no torque about z.
* ``third_body`` -- none: the third body moves, so no energy or momentum of the orbit is
  constant (the row says so).

Attitude (H. Baruh, *Analytical Dynamics*, ch. 8-10; ``C(q)`` with ``v_body = C v_inertial``):

* ``torque_free`` -- kinetic energy ``T = w.Iw/2`` (J) and inertial angular momentum
  ``H_i = C^T I w`` (N m s, vector).
* ``gyrostat`` (rotor momentum ``h`` constant relative to the body) -- ``T = w.Iw/2``
  (J; ``d/dt`` of it is ``-w.(w x (Iw + h)) = 0``) and ``H_i = C^T (I w + h)`` (N m s).
* ``heavy_top`` (fixed point, body axis 3 along the centre of mass at ``cm`` m, gravity
  ``g`` along -Z inertial) -- energy ``T + m g cm (C^T e3)_z`` (J), the vertical momentum
  ``L_z = (C^T I w)_z`` and, for a symmetric top (I1 = I2), the spin momentum
  ``H_3 = (I w)_3`` (N m s; Baruh sec. 10.3).
* ``gravity_gradient``, ``user`` -- none beyond the unit norm of ``q``.
* ``flexible`` (a hub with assumed-mode beams, :mod:`astrodyn.attitude.flexible`; the
  state rebuilt from the attitude and appendages channels, the linear momentum zero) --
  the inertial angular momentum of hub plus beams ``H_i`` (N m s) and, with undamped
  beams, the energy ``T + V`` (J, kinetic plus strain); with damped beams the energy may
  only fall, and the row is its largest rise above ``E_0`` (0 when it fell monotonically
  from the first state).

An actuated orbit (a closed loop's impulses or thrust, docs/control.md) keeps its model's
quantities only between burns: given the coast arcs (``arc_starts``, from the recorded
actuators and applied commands, :class:`astrodyn.analysis.closed_loop.OrbitActuation`),
its rows are named ``... between burns`` and their drift is taken over each coast arc from
that arc's first state (:func:`astrodyn.analysis.metrics.drift_over_arcs`), the largest
over the arcs; what a burn changes (by ``v.dv + |dv|^2/2`` for an impulse) is not drift.

Every attitude row list ends with ``|q| - 1`` (absolute).  Drifts are
``max_k |x_k - x_0| / scale`` with ``scale = |x_0|`` (vectors: Euclidean norms), except
where ``|x_0|`` is not the size of the terms: orbit energies use ``mu / |r_0|`` when
``|E_0| < 1e-6 mu/|r_0|`` (near-parabolic), ``h_z`` uses ``|h_0|``, ``L_z`` and ``H_3``
use ``|H_0|``, the top's energy uses ``T_0 + m g cm`` -- the row's ``scale`` says which.
A scale of 0 (a body at rest: ``T_0 = 0``, ``H_0 = 0``) gives the absolute drift in the
row's unit, its scale ``absolute (|T0| = 0)`` (was inf).
"""

from __future__ import annotations

import functools
import json
from dataclasses import dataclass

import numpy as np

from astrodyn.analysis.metrics import drift_against, drift_over_arcs, inertial_from_body
from astrodyn.orbit import zonal_potential
from astrodyn.rotation import dcm_from_quat

__all__ = ["Invariant", "BETWEEN_BURNS", "OrbitQuantities", "orbit_quantities", "recorded_orbit_quantities",
           "energy_scale", "orbit_invariants", "attitude_invariants", "flexible_invariants", "rolling_invariants",
           "recorded_invariants", "appendage_arrays", "own_state_arrays", "recorded_spacecraft", "recorded_rolling_disk",
           "flexible_states"]


@dataclass(frozen=True)
class Invariant:
    """One conserved quantity of a body's model and its drift over a recording."""

    name: str  #: e.g. "E (two-body)", "h_z"
    unit: str  #: SI unit of the quantity, e.g. "J/kg"
    initial: float  #: value (norm, for vectors) at the first recorded state
    drift: float  #: largest deviation from the initial value, divided by ``scale``
    scale: str  #: what the drift is relative to ("|E0|", "mu/r0", "absolute", ...)
    conserved: bool = True  #: False: a row that says the model conserves nothing

    def as_dict(self) -> dict:
        return {"name": self.name, "unit": self.unit, "initial": self.initial, "drift": self.drift,
                "scale": self.scale, "conserved": self.conserved}


def _row(name: str, unit: str, initial: float, x: np.ndarray, scale: float, scale_name: str) -> Invariant:
    """The row of quantity ``x`` (samples along axis 0) and its drift relative to ``scale``
    (named ``scale_name``); a zero scale (a body at rest, ``T0 = H0 = 0``) gives the absolute
    drift in ``unit``, named ``absolute (<scale_name> = 0)`` (:func:`~astrodyn.analysis.
    metrics.drift_against`)."""
    drift, relative = drift_against(x, scale)
    return Invariant(name, unit, initial, drift, scale_name if relative else f"absolute ({scale_name} = 0)")


def _norm0(x: np.ndarray) -> float:
    x = np.asarray(x, dtype=np.float64)
    return float(np.linalg.norm(x[0]))


def _energy_row(name: str, energy: np.ndarray, mu: float, r0: float) -> Invariant:
    e0 = float(energy[0])
    terms = mu / r0
    if abs(e0) < 1e-6 * terms:
        return _row(name, "J/kg", e0, energy, terms, "mu/r0")
    return _row(name, "J/kg", e0, energy, abs(e0), "|E0|")


#: What the rows of an actuated orbit are named after (module docstring): their quantity holds between burns.
BETWEEN_BURNS = "between burns"


def energy_scale(energy: np.ndarray, mu: float, rn: np.ndarray) -> np.ndarray:
    """Per state, the scale an orbit energy's drift from that state is relative to: ``|E|``,
    or ``mu/|r|`` where ``|E| < 1e-6 mu/|r|`` (near parabolic: the size of the terms)."""
    terms = mu / rn
    return np.where(np.abs(energy) < 1e-6 * terms, terms, np.abs(energy))


def _arc_rows(energy_name: str, energy: np.ndarray, momentum_name: str, momentum: np.ndarray, h_norm: np.ndarray,
              rn: np.ndarray, mu: float, arc_starts: np.ndarray) -> list[Invariant]:
    """The energy and momentum rows of an actuated orbit: each drift over every coast arc
    from its first state (:func:`~astrodyn.analysis.metrics.drift_over_arcs`), relative to
    that state's ``|E|`` (``mu/|r|`` where ``|E| < 1e-6 mu/|r|``, near parabolic) and ``|h|``."""
    e_scale = energy_scale(energy, mu, rn)
    rows = []
    for name, unit, x, initial, scales, scale_name in (
            (energy_name, "J/kg", energy, float(energy[0]), e_scale, "|E0| of its coast arc"),
            (momentum_name, "m^2/s", momentum, float(np.linalg.norm(momentum[0])), h_norm, "|h0| of its coast arc")):
        drift, relative = drift_over_arcs(x, arc_starts, scales)
        rows.append(Invariant(f"{name} {BETWEEN_BURNS}", unit, initial, drift,
                              scale_name if relative else f"absolute ({scale_name.split()[0]} = 0 on a coast arc)"))
    return rows


def orbit_invariants(model: str, r: np.ndarray, v: np.ndarray, mu: float, *, radius: float | None = None,
                     j: tuple[float, ...] | list[float] = (), degree: int = 0,
                     third_body: bool = False, arc_starts: np.ndarray | None = None) -> list[Invariant]:
    """The invariants of orbit ``model`` over states ``r`` (m), ``v`` (m/s), shape (n, 3).

    ``mu`` m^3/s^2; for zonal models ``radius`` (m, the J's reference radius), ``j`` the
    coefficients J2, J3, ... and ``degree`` the highest degree the run used (2 for
    ``j2``).  ``third_body``: the orbit had a third-body perturbation (no invariant).
    ``arc_starts`` (n,) bool, for an orbit that burns moved: True at each state that begins
    a coast arc; the rows are then ``... between burns``, their drift over each arc from
    its first state (module docstring).  None: one arc, no burn.
    """
    r = np.asarray(r, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    if r.ndim != 2 or r.shape[-1] != 3 or r.shape != v.shape or r.shape[0] == 0:
        raise ValueError(f"r, v: expected matching (n, 3) arrays with n >= 1, got {r.shape} and {v.shape}")
    if third_body or model == "third_body":
        return [Invariant("none (a third body moves: no orbit invariant)", "-", float("nan"), float("nan"), "-",
                          conserved=False)]
    if arc_starts is not None and np.shape(arc_starts) != r.shape[:1]:
        raise ValueError(f"arc_starts: expected one flag per state, shape {r.shape[:1]}, got {np.shape(arc_starts)}")
    quantities = orbit_quantities(model, r, v, mu, radius=radius, j=j, degree=degree)
    rn = np.linalg.norm(r, axis=-1)
    h_norm = np.linalg.norm(np.cross(r, v), axis=-1)
    if arc_starts is not None:
        return _arc_rows(quantities.energy_name, quantities.energy, quantities.momentum_name, quantities.momentum,
                         h_norm, rn, mu, arc_starts)
    momentum = quantities.momentum
    initial = _norm0(momentum) if momentum.ndim > 1 else float(momentum[0])
    return [_energy_row(quantities.energy_name, quantities.energy, mu, float(rn[0])),
            _row(quantities.momentum_name, "m^2/s", initial, momentum, float(h_norm[0]), "|h0|")]


@dataclass(frozen=True)
class OrbitQuantities:
    """The energy and angular momentum an orbit model conserves, per state (module docstring)."""

    energy_name: str  #: "E (two-body)", "E (with J2)", "E (with J2..Jn)"
    energy: np.ndarray  #: (n,) J/kg
    energy_scale: np.ndarray  #: (n,) J/kg: what a drift from each state is relative to (:func:`energy_scale`)
    momentum_name: str  #: "h" (the vector r x v) or "h_z" (its polar component)
    momentum: np.ndarray  #: (n, 3) or (n,) m^2/s
    momentum_scale: np.ndarray  #: (n,) m^2/s: |h| of each state, what a drift from it is relative to


def orbit_quantities(model: str, r: np.ndarray, v: np.ndarray, mu: float, *, radius: float | None = None,
                     j: tuple[float, ...] | list[float] = (), degree: int = 0) -> OrbitQuantities:
    """The conserved quantities of orbit ``model`` (not ``third_body``: none) at each state
    ``r`` (m), ``v`` (m/s), shape (n, 3): for ``kepler`` or ``degree < 2`` the two-body
    ``E = |v|^2/2 - mu/|r|`` and ``h = r x v``; for a zonal field of ``degree`` >= 2
    (``radius`` m, ``j`` = J2, J3, ...) ``E = |v|^2/2 - mu/|r| - V_zonal(r)`` and ``h_z``.
    The rows of :func:`orbit_invariants` and the curves of the report's orbit-drift figure."""
    rn = np.linalg.norm(r, axis=-1)
    kinetic = 0.5 * np.einsum("ij,ij->i", v, v)
    h = np.cross(r, v)
    h_norm = np.linalg.norm(h, axis=-1)
    if model == "kepler" or degree < 2:
        energy = kinetic - mu / rn
        return OrbitQuantities("E (two-body)", energy, energy_scale(energy, mu, rn), "h", h, h_norm)
    if radius is None or len(j) < degree - 1:
        raise ValueError(f"orbit_invariants({model!r}): expected radius and J2..J{degree}, got radius={radius}, j={j}")
    energy = kinetic - (mu / rn + zonal_potential(r, mu, radius, tuple(j[: degree - 1])))
    return OrbitQuantities(f"E (with J2..J{degree})" if degree > 2 else "E (with J2)", energy,
                           energy_scale(energy, mu, rn), "h_z", h[:, 2], h_norm)


def attitude_invariants(model: str, q: np.ndarray, w: np.ndarray, inertia: np.ndarray | None, *,
                        rotor_momentum: np.ndarray | None = None, mass: float | None = None,
                        cm: float | None = None, g: float | None = None) -> list[Invariant]:
    """The invariants of attitude ``model`` over ``q`` (n, 4, scalar first) and body rates
    ``w`` (n, 3, rad/s); ``inertia`` (3, 3) kg m^2 in body axes (about the fixed point for a
    top); ``rotor_momentum`` (3,) N m s, the gyrostat's constant rotor momentum relative to
    the body; ``mass`` kg, ``cm`` m, ``g`` m/s^2 for a heavy top."""
    q = np.asarray(q, dtype=np.float64)
    w = np.asarray(w, dtype=np.float64)
    if q.ndim != 2 or q.shape[-1] != 4 or w.shape != (q.shape[0], 3) or q.shape[0] == 0:
        raise ValueError(f"q, w: expected (n, 4) and (n, 3) with n >= 1, got {q.shape} and {w.shape}")
    qn = np.linalg.norm(q, axis=-1)
    rows: list[Invariant] = []
    if inertia is not None and model in ("torque_free", "gyrostat", "heavy_top"):
        inertia = np.asarray(inertia, dtype=np.float64).reshape(3, 3)
        hb = w @ inertia.T
        energy = 0.5 * np.einsum("ij,ij->i", w, hb)
        c = dcm_from_quat(q / qn[:, None])
        if model == "gyrostat" and rotor_momentum is not None:
            hb = hb + np.asarray(rotor_momentum, dtype=np.float64)
        hi = inertial_from_body(q, hb)  # C^T H_b, as the report's attitude table
        if model == "heavy_top":
            m, l, gg = float(mass or 0.0), float(cm or 0.0), float(g or 0.0)
            height = c[:, 2, 2]  # (C^T e3)_z: the vertical component of body axis 3
            total = energy + m * gg * l * height
            scale = float(energy[0]) + m * gg * l
            rows.append(_row("E = T + m g cm cos(theta)", "J", float(total[0]), total, scale, "T0 + m g cm"))
            h0 = _norm0(hi)
            rows.append(_row("L_z", "N m s", float(hi[0, 2]), hi[:, 2], h0, "|H0|"))
            if abs(inertia[0, 0] - inertia[1, 1]) <= 1e-12 * abs(inertia[0, 0]) and not inertia[0, 1] and not inertia[0, 2] \
                    and not inertia[1, 2]:
                rows.append(_row("H_3 (spin)", "N m s", float(hb[0, 2]), hb[:, 2], h0, "|H0|"))
        else:
            t0 = float(energy[0])
            rows.append(_row("T", "J", t0, energy, abs(t0), "|T0|"))
            rows.append(_row("H_i", "N m s", _norm0(hi), hi, _norm0(hi), "|H0|"))
    rows.append(Invariant("|q| - 1", "-", float(qn[0] - 1.0), float(np.max(np.abs(qn - 1.0))), "absolute"))
    return rows


def flexible_states(spacecraft, q, w, eta, eta_dot) -> np.ndarray:
    """Full state vectors ``(n, 13 + 2 n_elastic)`` of a flexible spacecraft from recorded
    hub states and appendage coordinates (the linear momentum zero, as the service runs it;
    the position of the hub's centre, which no invariant needs, at the origin)."""
    from astrodyn.attitude import flexible as fx

    return np.stack([fx.make_state(spacecraft, q=q[k], w=w[k], eta=eta[k], eta_dot=eta_dot[k]) for k in range(len(q))])


def flexible_invariants(spacecraft, q: np.ndarray, w: np.ndarray, eta: np.ndarray, eta_dot: np.ndarray) -> list[Invariant]:
    """The invariants of a flexible spacecraft (:class:`astrodyn.attitude.flexible.
    FlexibleSpacecraft`) over hub states ``q`` (n, 4), ``w`` (n, 3, rad/s, body) and the
    appendages' ``eta``, ``eta_dot`` (n, n_elastic; m, m/s): ``H_i``, and ``T + V`` (its
    largest rise above the first value when any beam is damped)."""
    from astrodyn.attitude import flexible as fx

    q, w = np.asarray(q, dtype=np.float64), np.asarray(w, dtype=np.float64)
    eta, eta_dot = np.asarray(eta, dtype=np.float64), np.asarray(eta_dot, dtype=np.float64)
    n = q.shape[0]
    if n == 0 or w.shape != (n, 3) or eta.shape != (n, spacecraft.n_elastic) or eta_dot.shape != eta.shape:
        raise ValueError(f"q, w, eta, eta_dot: expected (n, 4), (n, 3), (n, {spacecraft.n_elastic}) x 2 with n >= 1, "
                         f"got {q.shape}, {w.shape}, {eta.shape}, {eta_dot.shape}")
    states = flexible_states(spacecraft, q, w, eta, eta_dot)
    energy = fx.spacecraft_energy(spacecraft, states)
    _, hi = fx.spacecraft_momentum(spacecraft, states)
    e0, h0 = float(energy[0]), _norm0(hi)
    rows = [_row("H_i (hub + appendages)", "N m s", h0, hi, h0, "|H0|")]
    if spacecraft.damped:  # a rise from E0 = 0 (at rest, undeformed) is given in J: relative to 0 it is inf
        rise = max(float(np.max(energy - e0)), 0.0)
        rows.append(Invariant("E = T + V: rise (damped)", "J", e0, rise / abs(e0) if e0 else rise,
                              "|E0|" if e0 else "absolute (|E0| = 0)"))
    else:
        rows.append(_row("E = T + V", "J", e0, energy, abs(e0), "|E0|"))
    qn = np.linalg.norm(q, axis=-1)
    rows.append(Invariant("|q| - 1", "-", float(qn[0] - 1.0), float(np.max(np.abs(qn - 1.0))), "absolute"))
    return rows


@functools.lru_cache(maxsize=8)
def _recorded_constants(text: str) -> tuple[dict, dict[str, dict]]:
    """(central body, body name -> body) of a recording's config JSON, parsed once per
    recording (a summary asks for each body, block by block)."""
    try:
        meta = json.loads(text)
    except (TypeError, ValueError, RecursionError):
        meta = {}
    meta = meta if isinstance(meta, dict) else {}
    central = meta.get("central_body") if isinstance(meta.get("central_body"), dict) else {}
    bodies = {}
    for b in meta.get("bodies") or []:
        if isinstance(b, dict) and isinstance(b.get("name"), str):
            bodies.setdefault(b["name"], b)
    return central, bodies


def rolling_invariants(disk, q: np.ndarray, lean: np.ndarray, u: np.ndarray) -> list[Invariant]:
    """The invariants of a rolling disk (:class:`astrodyn.attitude.rolling_disk.RollingDisk`)
    over recorded leans (n,) rad and generalized speeds ``u`` (n, 3) rad/s: the energy
    ``T + m g R cos theta`` (J; the rolling constraint does no work), and ``|q| - 1``."""
    from astrodyn.attitude.rolling_disk import energy

    lean, u = np.asarray(lean, dtype=np.float64).reshape(-1), np.asarray(u, dtype=np.float64)
    if lean.size == 0 or u.shape != (lean.size, 3) or np.shape(q) != (lean.size, 4):
        raise ValueError(f"q, lean, u: expected (n, 4), (n,) and (n, 3) with n >= 1, got {np.shape(q)}, {lean.shape}, "
                         f"{u.shape}")
    states = np.zeros((lean.size, 8))
    states[:, 3], states[:, 5:8] = lean, u
    e = energy(disk, states)
    qn = np.linalg.norm(q, axis=-1)
    return [_row("E = T + m g R cos(theta)", "J", float(e[0]), e, abs(float(e[0])), "|E0|"),
            Invariant("|q| - 1", "-", float(qn[0] - 1.0), float(np.max(np.abs(qn - 1.0))), "absolute")]


def own_state_arrays(model: str, track) -> dict[str, np.ndarray] | None:
    """The arrays of a flexible or rolling body's own channel (``load(path).bodies[b].
    appendages`` / ``.rolling``) its invariants need: ``eta``, ``eta_dot``, ``tip`` or
    ``lean``, ``u``; None when absent or not in one layout."""
    if track is None or not len(track):
        return None
    if model == "flexible":
        arrays = appendage_arrays(track)
        return None if arrays is None else dict(zip(("eta", "eta_dot", "tip"), arrays))
    if model == "rolling_disk" and "lean" in track.fields and "u" in track.fields:
        return {"lean": np.asarray(track.lean, dtype=np.float64), "u": np.asarray(track.u, dtype=np.float64)}
    return None


def recorded_invariants(scenario: dict, body: str, *, orbit: tuple | None = None,
                        attitude: tuple | None = None, own: dict | None = None,
                        orbit_arc_starts: np.ndarray | None = None) -> dict[str, list[Invariant]]:
    """The invariant rows of one recorded body, its models and constants taken from the
    recording's ``scenario`` metadata (``load(path).scenario``: the config as run).

    ``orbit = (model, r, v)``, ``attitude = (model, q, w)`` (arrays as recorded), for a
    flexible or rolling body ``own`` the arrays of its own key at the same samples
    (:func:`own_state_arrays`); ``orbit_arc_starts``: the coast arcs of an orbit that
    burns moved (:func:`orbit_invariants`, ``arc_starts``);
    returns ``{"orbit": [...], "attitude": [...]}`` for the kinds given.  Constants missing
    from the metadata (a recording of another tool) leave only the rows that need none."""
    text = scenario.get("json") or "{}"
    central, bodies = _recorded_constants(text if isinstance(text, str) else "{}")
    bm = bodies.get(body, {})
    out: dict[str, list[Invariant]] = {}
    if orbit is not None:
        model, r, v = orbit
        constants = _orbit_constants(scenario, body, model)
        if constants is not None:
            out["orbit"] = orbit_invariants(model, r, v, **constants, arc_starts=orbit_arc_starts)
    if attitude is not None:
        model, q, w = attitude
        am = bm.get("attitude") if isinstance(bm.get("attitude"), dict) else {}
        inertia = None
        try:
            inertia = np.asarray(am["inertia"], dtype=np.float64).reshape(3, 3)
        except (KeyError, TypeError, ValueError):
            pass
        h = None
        try:
            rotors = am.get("rotors") or []
            if rotors:
                h = sum((np.asarray(rt["axis"], dtype=np.float64).reshape(3) * float(rt["h"]) for rt in rotors), np.zeros(3))
        except (KeyError, TypeError, ValueError):
            h = None
        sc = recorded_spacecraft(text, body) if model == "flexible" and own is not None else None
        disk = recorded_rolling_disk(text, body) if model == "rolling_disk" and own is not None else None
        if sc is not None and own["eta"].shape[-1] == sc.n_elastic:
            out["attitude"] = flexible_invariants(sc, q, w, own["eta"], own["eta_dot"])
        elif disk is not None:
            out["attitude"] = rolling_invariants(disk, q, own["lean"], own["u"])
        else:
            out["attitude"] = attitude_invariants(model, q, w, inertia, rotor_momentum=h, mass=am.get("mass"),
                                                  cm=am.get("cm"), g=am.get("g"))
    return out


def _orbit_constants(scenario: dict, body: str, model: str) -> dict | None:
    """The keyword arguments of :func:`orbit_invariants` for ``body``'s orbit of ``model``
    from a recording's scenario metadata (``mu``, ``radius``, ``j``, ``degree``,
    ``third_body``); None without a positive ``mu``.  Zonal constants not recorded: two-body."""
    text = scenario.get("json") or "{}"
    central, bodies = _recorded_constants(text if isinstance(text, str) else "{}")
    bm = bodies.get(body, {})
    om = bm.get("orbit") if isinstance(bm.get("orbit"), dict) else {}
    mu = central.get("mu")
    if not isinstance(mu, (int, float)) or isinstance(mu, bool) or not mu > 0:
        return None
    try:
        degree = int(om.get("degree") or (2 if model == "j2" else 0))
    except (TypeError, ValueError, OverflowError):
        degree = 0
    j = central.get("j") or ()
    if degree >= 2 and (central.get("radius") is None or not isinstance(j, list) or len(j) < degree - 1):
        degree = 0  # constants not recorded: two-body rows only
    return {"mu": float(mu), "radius": central.get("radius"), "j": j, "degree": degree,
            "third_body": bool(om.get("perturbers"))}


def recorded_orbit_quantities(scenario: dict, body: str, model: str, r: np.ndarray,
                              v: np.ndarray) -> OrbitQuantities | None:
    """:func:`orbit_quantities` of ``body``'s recorded orbit states, its constants from the
    recording's ``scenario`` metadata as :func:`recorded_invariants` takes them (so the
    report's orbit-drift figure draws the quantities of its "conserved quantities" rows);
    None when the model conserves none (a third body) or the metadata give no ``mu``."""
    constants = _orbit_constants(scenario, body, model)
    if constants is None or constants.pop("third_body") or model == "third_body":
        return None
    return orbit_quantities(model, np.asarray(r, dtype=np.float64), np.asarray(v, dtype=np.float64), **constants)


def appendage_arrays(track) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """``(eta, eta_dot, tip)`` of a recorded appendages track (``load(path).bodies[b].
    appendages``): ``(n, n_elastic)`` each appendage's coordinates side by side (m, m/s)
    and ``(n, N, 3)`` tip displacements (m); None when the rows do not share one layout."""
    try:
        eta = np.array([np.concatenate(row) for row in track.eta], dtype=np.float64)
        eta_dot = np.array([np.concatenate(row) for row in track.eta_dot], dtype=np.float64)
        tip = np.array([row for row in track.tip], dtype=np.float64)
    except (TypeError, ValueError):
        return None
    if eta.ndim != 2 or eta_dot.shape != eta.shape or tip.ndim != 3 or tip.shape[0] != eta.shape[0]:
        return None
    return eta, eta_dot, tip


@functools.lru_cache(maxsize=8)
def recorded_spacecraft(text: str, body: str):
    """The flexible spacecraft of ``body`` from a recording's config JSON (``load(path).
    scenario["json"]``), or None when the metadata does not describe one (a recording of
    another tool, a hostile file)."""
    from astrodyn.scenario.appendages import Appendage, flexible_spacecraft

    am = _recorded_constants(text)[1].get(body, {}).get("attitude")
    try:
        if len(am["appendages"]) > 32:  # astrodyn.scenario.appendages.MAX_APPENDAGES
            return None
        apps = tuple(Appendage(root=np.asarray(a["root"], dtype=np.float64).reshape(3),
                               axis=np.asarray(a["axis"], dtype=np.float64).reshape(3),
                               normal=np.asarray(a["normal"], dtype=np.float64).reshape(3),
                               length=float(a["length"]), mass_per_length=float(a["mass_per_length"]),
                               bending_stiffness=float(a["bending_stiffness"]), modes=int(a["modes"]),
                               damping_ratio=float(a["damping_ratio"])) for a in am["appendages"])
        return flexible_spacecraft(float(am["mass"]), np.asarray(am["inertia"], dtype=np.float64).reshape(3, 3), apps,
                                   bool(am.get("stiffening", True)))
    except (KeyError, TypeError, ValueError, IndexError, OverflowError):
        return None


@functools.lru_cache(maxsize=8)
def recorded_rolling_disk(text: str, body: str):
    """The rolling disk of ``body`` from a recording's config JSON, or None when the
    metadata does not describe one."""
    from astrodyn.attitude.rolling_disk import RollingDisk

    am = _recorded_constants(text)[1].get(body, {}).get("attitude")
    try:
        r = am["rolling"]
        return RollingDisk(float(r["radius"]), float(r["mass"]), float(r["A"]), float(r["C"]), float(r["g"]))
    except (KeyError, TypeError, ValueError, OverflowError):
        return None
