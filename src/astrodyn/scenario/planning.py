"""What a run of a scenario needs: the cheapest exact model per body and the processes to
start (:func:`plan`), with the expected size of its recording (:class:`Plan`).

A perturbation that is identically zero for the scene is dropped (the exact model is
used instead), and the closed loop's bodies are given to the plant; docs/architecture.md,
section 9 (where to add a model) says what a new model adds here.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from astrodyn.messages import ACTUATED_MODEL, CROSSCHECK_MODELS, GIMBALS_KIND, MODEL_STATE_KINDS

if TYPE_CHECKING:
    from astrodyn.scenario import OrbitSpec, Scenario

__all__ = ["BodyPlan", "Plan", "plan", "state_kinds_text", "counted", "BYTES_PER_STATE", "ORBIT_METHODS", "ATTITUDE_METHODS",
           "EXACT_ATTITUDE_MODEL", "periapsis_radius"]

#: The exact attitude model a torque that is zero for the body falls back to.
EXACT_ATTITUDE_MODEL = "torque_free"


@dataclass(frozen=True)
class BodyPlan:
    """What runs for one body: orbit/attitude model used (None if absent), the method, notes."""

    name: str
    orbit_model: str | None
    orbit_method: str
    attitude_model: str | None
    attitude_method: str
    notes: tuple[str, ...] = ()
    #: kinds of the body's further state channels, published by the attitude process at the
    #: same seq as its attitude: a flexible or rolling body's own, its gyroscopes' gimbals
    own_kinds: tuple[str, ...] = ()


@dataclass(frozen=True)
class Plan:
    """Processes to start and per-body models; :meth:`text` is the human-readable form."""

    scenario: str
    processes: tuple[str, ...]
    bodies: tuple[BodyPlan, ...]
    n_steps: int
    messages: int  #: every message the run records: states plus cross-checks
    warnings: tuple[str, ...] = ()
    crosscheck_messages: int = 0  #: of ``messages``: the REBOUND cross-check messages
    model_state_messages: int = 0  #: of ``messages``: the bodies' further state channels (``BodyPlan.own_kinds``)

    @property
    def state_messages(self) -> int:
        """Orbit and attitude state messages (``messages`` without the cross-checks and
        the bodies' further state channels)."""
        return self.messages - self.crosscheck_messages - self.model_state_messages

    @property
    def estimated_file_bytes(self) -> int:
        """Expected size of the recording: :data:`BYTES_PER_STATE` per state message."""
        return int(self.messages * BYTES_PER_STATE)

    def text(self, max_bodies: int = 20) -> str:
        size = self.estimated_file_bytes
        xc = f" + {self.crosscheck_messages} cross-check messages" if self.crosscheck_messages else ""
        xc += (f" + {self.model_state_messages} appendage / rolling / gimbal states (the bodies' own keys)"
               if self.model_state_messages else "")
        kinds = state_kinds_text(sum(bp.orbit_model is not None for bp in self.bodies),
                                 sum(bp.attitude_model is not None for bp in self.bodies))
        lines = [f"scenario {self.scenario}: {counted(len(self.bodies), 'body', 'bodies')}, "
                 f"{counted(self.n_steps, 'output step')}, {counted(self.state_messages, 'state message')} ({kinds}){xc}",
                 f"expected recording: about {_human_bytes(size)} ({BYTES_PER_STATE} bytes per state message after zstd)",
                 f"processes: {', '.join(self.processes)}"]
        groups: dict[tuple, list[str]] = {}
        for bp in self.bodies:
            groups.setdefault((bp.orbit_model, bp.orbit_method, bp.attitude_model, bp.attitude_method, bp.notes), []).append(bp.name)
        shown = 0
        for (om, ometh, am, ameth, notes), names in groups.items():
            if shown >= max_bodies:
                lines.append(f"  ... {counted(len(self.bodies) - shown, 'more body', 'more bodies')}")
                break
            who = ", ".join(names) if len(names) <= 3 else f"{names[0]}, {names[1]}, ..., {names[-1]} ({len(names)} bodies)"
            lines.append(f"  {who}:")
            lines.append(f"    orbit:    {om or '-'}{' (' + ometh + ')' if om else ''}")
            lines.append(f"    attitude: {am or '-'}{' (' + ameth + ')' if am else ''}")
            lines += [f"    note: {n}" for n in notes]
            shown += len(names)
        return "\n".join(lines)


def counted(n: int, singular: str, plural: str | None = None) -> str:
    """``n`` and the noun in the number it takes: ``counted(1, "body", "bodies")`` is
    "1 body", ``counted(3, "output step")`` is "3 output steps" (``plural`` defaults to the
    singular + "s")."""
    return f"{n} {singular if n == 1 else (plural or singular + 's')}"


def state_kinds_text(orbits: int, attitudes: int) -> str:
    """What the state messages of a plan or a recording are, from how many orbit and
    attitude channels (or messages) there are: "orbit + attitude", "orbit", "attitude"
    ("none" for neither)."""
    return " + ".join(k for k, n in (("orbit", orbits), ("attitude", attitudes)) if n) or "none"


#: Bytes per state message in a recording after zstd: 87 measured on a Kepler + torque-free
#: scene of 240,002 states (20.9 MB; payloads 175-200 B), rounded up.
BYTES_PER_STATE = 90


def _human_bytes(n: float) -> str:
    for unit in ("B", "kB", "MB", "GB", "TB"):
        if n < 1000 or unit == "TB":
            return f"{n:.3g} {unit}"
        n /= 1000.0
    return f"{n:.3g} TB"  # pragma: no cover


ORBIT_METHODS = {
    "kepler": "analytic two-body, universal variables: exact",
    "j2": "numerical, two-body + J2",
    "zonal": "numerical, two-body + zonal harmonics",
    "third_body": "numerical, two-body + third bodies",
    ACTUATED_MODEL: "closed loop: analytic two-body between commands, impulses and burns (astrodyn.plant)",
}
ATTITUDE_METHODS = {
    "torque_free": "analytic, Jacobi elliptic functions: exact",
    "gravity_gradient": "numerical splitting, gravity-gradient torque from the published orbit",
    "gyrostat": "numerical splitting, gyrostat with rotors",
    "heavy_top": "numerical splitting, heavy top in uniform gravity",
    "user": "numerical splitting, constant body torque",
    "flexible": "numerical, DOP853: rigid hub + assumed-mode beams with centrifugal stiffening (Baruh ch. 11)",
    "rolling_disk": "numerical, DOP853: Kane's equations of a disk rolling without slipping (Baruh 10.6)",
    ACTUATED_MODEL: "closed loop, step by step with the commands held (astrodyn.plant)",
}


def plan(scenario: Scenario, cross_check_all: bool = False) -> Plan:
    """The cheapest exact model per body and the processes a run needs.

    ``cross_check_all``: the run checks every orbit against REBOUND (``run --cross-check``),
    counted in ``crosscheck_messages`` like the bodies whose config asks for it; only orbits
    of a model REBOUND's twin runs (:data:`astrodyn.messages.CROSSCHECK_MODELS`) are checked,
    the others noted as not cross-checked (a warning when their config asked for it).

    A perturbation that is identically zero for the scene is dropped: j2/zonal with all
    needed J_n = 0 -> kepler; gravity gradient on an inertially spherical body, a heavy
    top with cm = 0 or g = 0, a user torque of 0, or a gyrostat whose rotors have h = 0
    -> torque_free. A body with actuators or sensors is ``actuated`` (moved by the plant).
    Processes: ``orbit`` if any other body has an orbit, ``attitude`` if any other
    attitude is propagated, ``plant`` if any body is actuated, ``logger`` always.
    """
    cb = scenario.central_body
    out = []
    warnings: list[str] = []
    for b in scenario.bodies:
        notes: list[str] = []
        om = am = None
        if b.orbit is not None:
            om = b.orbit.model
            if om in ("j2", "zonal") and not any(cb.J[: b.orbit.degree - 1]):
                notes.append(f"{om} requested but J2..J{b.orbit.degree} of {cb.name} are 0: analytic kepler is exact")
                om = "kepler"
            rp = periapsis_radius(b.orbit, cb.mu)
            if rp is not None and rp < cb.radius:
                notes.append(f"periapsis {rp / 1e3:.6g} km is below the surface of {cb.name} (radius {cb.radius / 1e3:.6g} km)")
                warnings.append(f"bodies[{len(out)}] ({b.name}).orbit: periapsis radius {rp / 1e3:.6g} km is below "
                                f"the surface of {cb.name} (radius {cb.radius / 1e3:.6g} km): the orbit meets the central "
                                f"body; check a / rp / e or r, v")
        if b.attitude is not None and b.attitude.model != "none":
            a = b.attitude
            am = a.model
            pm = a.principal_moments
            if am == "gravity_gradient" and np.ptp(pm) <= 1e-15 * np.max(pm):
                notes.append("gravity gradient on a spherical inertia is zero: exact torque_free")
                am = EXACT_ATTITUDE_MODEL
            elif am == "heavy_top" and (a.cm == 0 or a.g == 0):
                notes.append("heavy top with cm = 0 or g = 0 has no torque: exact torque_free")
                am = EXACT_ATTITUDE_MODEL
            elif am == "user" and a.torque is not None and not np.any(a.torque):
                notes.append("user torque is zero: exact torque_free")
                am = EXACT_ATTITUDE_MODEL
            elif am == "gyrostat" and all(r.h == 0 for r in a.rotors):
                notes.append("all rotors have h = 0: exact torque_free")
                am = EXACT_ATTITUDE_MODEL
        if b.in_plant:  # the closed loop moves it (astrodyn.plant): commands make every model moot
            om = ACTUATED_MODEL if b.orbit is not None else None
            am = ACTUATED_MODEL if am is not None else None
            notes = ["closed loop: moved by the plant with its controllers' commands (docs/control.md)"]
        if om is not None and (b.cross_check or cross_check_all):
            if om in CROSSCHECK_MODELS:
                notes.append("cross-checked against REBOUND IAS15")
            else:  # REBOUND's twin carries a point mass and J2 only (astrodyn.crosscheck)
                notes.append(f"not cross-checked: REBOUND's twin runs {' and '.join(CROSSCHECK_MODELS)} orbits only")
                if b.cross_check:
                    warnings.append(f"bodies[{len(out)}] ({b.name}).cross_check: its orbit model {om} cannot be "
                                    f"cross-checked (REBOUND's twin runs {', '.join(CROSSCHECK_MODELS)} only); the run "
                                    f"goes on without a cross-check for it")
        # a flexible body keeps its appendages channel in the closed loop too (the plant publishes it)
        config_model = b.attitude.model if b.attitude is not None else None
        own = (MODEL_STATE_KINDS[config_model],) if am is not None and config_model in MODEL_STATE_KINDS else ()
        if b.gyros and am not in (None, ACTUATED_MODEL):
            own += (GIMBALS_KIND,)
            notes.append(f"{len(b.gyros)} single-axis gyroscope(s) on board, on {b.name}/{GIMBALS_KIND}")
        out.append(BodyPlan(
            name=b.name, orbit_model=om, orbit_method=ORBIT_METHODS.get(om, ""),
            attitude_model=am, attitude_method=ATTITUDE_METHODS.get(am, ""), notes=tuple(notes), own_kinds=own,
        ))
    processes = []
    if any(bp.orbit_model not in (None, ACTUATED_MODEL) for bp in out):
        processes.append("orbit")
    if any(bp.attitude_model not in (None, ACTUATED_MODEL) for bp in out):
        processes.append("attitude")
    if any(ACTUATED_MODEL in (bp.orbit_model, bp.attitude_model) for bp in out):
        processes.append("plant")
    processes.append("logger")
    n = scenario.n_steps
    # flexible and rolling bodies, and bodies with gyroscopes, publish more state messages per step
    flexible = sum(len(bp.own_kinds) for bp in out)
    states = sum((bp.orbit_model is not None) + (bp.attitude_model is not None) for bp in out) + flexible
    checked = sum(bp.orbit_model in CROSSCHECK_MODELS and (cross_check_all or b.cross_check)
                  for bp, b in zip(out, scenario.bodies))
    return Plan(scenario=scenario.name, processes=tuple(processes), bodies=tuple(out), n_steps=n,
                messages=n * (states + checked), warnings=tuple(warnings), crosscheck_messages=n * checked,
                model_state_messages=n * flexible)


def periapsis_radius(orbit: OrbitSpec, mu: float) -> float | None:
    """Periapsis radius p / (1 + e) of the initial osculating conic (m), from r0, v0
    (h = r x v, p = h^2 / mu, e from the eccentricity vector; Vallado sec. 2.5)."""
    r, v = orbit.r0, orbit.v0
    h = np.cross(r, v)
    h2 = float(h @ h)
    rn = float(np.linalg.norm(r))
    if rn == 0:
        return None
    e_vec = np.cross(v, h) / mu - r / rn
    e = float(np.linalg.norm(e_vec))
    p = h2 / mu
    return p / (1.0 + e)
