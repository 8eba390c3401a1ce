"""The same two-body scene in REBOUND, for tests and for the service's cross-check mode.

astrodyn propagates conics in closed form; REBOUND (Rein & Liu 2012) integrates
the same equations of motion numerically.  This module builds the REBOUND twin
of an astrodyn scene and reports how far apart the two are.

The scene
---------
One central body of gravitational parameter ``mu`` [m^3/s^2] at the origin and N
massless test particles with initial positions ``r0`` [m] and velocities ``v0``
[m/s] relative to it, in the scene's inertial frame (for J2, the frame's z axis is
the body's pole).  REBOUND runs in SI units with ``G = 1`` and the central mass
set to ``mu``, so no input is rescaled (rescaling would round every input by up
to half an ulp).  ``N_active = 1`` and zero test-particle masses mean the
particles neither attract each other nor move the central body: it stays at the
origin with zero velocity, so REBOUND's coordinates *are* astrodyn's
body-centred ones (no heliocentric-vs-barycentric shift to undo).

Integrators
-----------
``"ias15"`` (default): 15th-order adaptive Gauss-Radau (Rein & Spiegel 2015,
MNRAS 446, 1424), error at the float64 round-off level per step; its global
error then grows by Brouwer's law (energy as a random walk ~ eps sqrt(N_steps),
along-track phase faster), so long spans and e -> 1 orbits (hundreds of steps
per periapsis passage) drift above machine precision.  It handles every conic,
hyperbolic and near-parabolic included.

``"whfast"``: Wisdom-Holman with REBOUND's Kepler drift (Rein & Tamayo 2015,
MNRAS 452, 376), fixed step.  With test particles around one mass the
interaction step vanishes, so each step is one Kepler solve; the step is a
fraction of the shortest orbital period, which needs **bound orbits**: unbound
particles raise ``ValueError``.

Time
----
REBOUND's ``sim.t`` is the plain floating-point running sum of the steps taken,
so after N steps it is off from the time the particles actually sit at by about
sqrt(N) half-ulps of t (measured: 1.7e-8 s after 36,000 IAS15 steps over 1000
LEO orbits, as large as IAS15's own phase error there).  This module therefore
steps REBOUND itself, stops exactly at each requested time the way
``sim.integrate(t, exact_finish_time=1)`` does, and accumulates the step sizes
with a compensated (TwoSum) sum.  The elapsed time that REBOUND's state belongs
to is reported as ``elapsed``, and astrodyn is evaluated at that time; it
differs from the requested time by the accumulated rounding (``elapsed -
times``, typically 1e-12 relative).

Entry points
------------
* :func:`crosscheck` runs a whole comparison and returns a :class:`CrossCheckResult`.
* :class:`ReboundScene` is the streaming form: ``advance_to(t)`` returns all
  bodies' states at t, so a service can publish differences step by step.
"""

from __future__ import annotations

import ctypes
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from astrodyn.messages import CROSSCHECK_MODELS

__all__ = ["CrossCheckResult", "ReboundScene", "crosscheck", "MODELS", "INTEGRATORS"]

MODELS = CROSSCHECK_MODELS
"""Force models the REBOUND twin can carry: point mass, point mass + J2 zonal."""

INTEGRATORS = ("ias15", "whfast")

WHFAST_STEPS_PER_PERIOD = 20
"""Default WHFast step = shortest period / 20 (a few percent of the shortest
dynamical time, the usual WHFast advice; for pure Kepler test particles the
drift is exact and the step only sets how many round-offs accumulate)."""

_PARTICLE_DOUBLES = 14  # x y z vx vy vz ax ay az m r name ap sim: 14 8-byte slots


def _as_states(r0, v0) -> tuple[np.ndarray, np.ndarray]:
    r = np.asarray(r0, dtype=np.float64)
    v = np.asarray(v0, dtype=np.float64)
    if r.ndim == 1:
        r = r[None, :]
    if v.ndim == 1:
        v = v[None, :]
    if r.ndim != 2 or r.shape[-1] != 3:
        raise ValueError(f"r0: expected shape (3,) or (N, 3) positions in m, got {np.shape(r0)}")
    if v.shape != r.shape:
        raise ValueError(f"v0: expected the shape of r0 {r.shape} (velocities in m/s), got {np.shape(v0)}")
    if not (np.all(np.isfinite(r)) and np.all(np.isfinite(v))):
        raise ValueError("r0, v0: every component must be finite (REBOUND cannot integrate NaN/inf)")
    if np.any(np.einsum("ij,ij->i", r, r) == 0.0):
        raise ValueError("r0: a body sits at the centre of attraction (|r0| = 0)")
    return r, v


def _check_mu(mu) -> float:
    mu = float(mu)
    if not (math.isfinite(mu) and mu > 0.0):
        raise ValueError(f"mu: expected a finite positive gravitational parameter in m^3/s^2, got {mu!r}")
    return mu


def _check_choices(integrator: str, model: str) -> None:
    """ValueError unless ``integrator`` is one of :data:`INTEGRATORS` and ``model`` one of :data:`MODELS`."""
    if integrator not in INTEGRATORS:
        raise ValueError(f"integrator: expected one of {INTEGRATORS}, got {integrator!r}")
    if model not in MODELS:
        raise ValueError(f"model: expected one of {MODELS}, got {model!r}")


def _two_sum(a: float, b: float) -> tuple[float, float]:
    """Knuth's TwoSum: s = fl(a + b) and the exact rounding error e, a + b = s + e."""
    s = a + b
    bp = s - a
    return s, (a - (s - bp)) + (b - bp)


def _j2_force(j2: float, radius: float, mu: float):
    """REBOUND additional-force callback adding the J2 zonal acceleration.

    a = -(3/2) J2 mu R^2 / r^5 * [x (1 - 5 z^2/r^2), y (1 - 5 z^2/r^2), z (3 - 5 z^2/r^2)]
    (Vallado, *Fundamentals of Astrodynamics and Applications*, 4th ed., eq. 8-30;
    Curtis, *Orbital Mechanics for Engineering Students*, eq. 12.30), pole along z,
    applied to the test particles (index >= 1) about the central body at the origin.
    """
    k = -1.5 * j2 * mu * radius * radius

    def force(simp):
        sim = simp.contents
        n = sim.N
        if n < 2:
            return
        base = ctypes.addressof(sim._particles.contents)
        buf = (ctypes.c_double * (_PARTICLE_DOUBLES * n)).from_address(base)
        p = np.frombuffer(buf, dtype=np.float64).reshape(n, _PARTICLE_DOUBLES)[1:]
        x, y, z = p[:, 0], p[:, 1], p[:, 2]
        r2 = x * x + y * y + z * z
        zz = 5.0 * z * z / r2
        f = k / (r2 * r2 * np.sqrt(r2))
        p[:, 6] += f * x * (1.0 - zz)
        p[:, 7] += f * y * (1.0 - zz)
        p[:, 8] += f * z * (3.0 - zz)

    return force


class ReboundScene:
    """A REBOUND simulation of N test particles around one central mass, stepped on demand.

    Parameters
    ----------
    r0, v0 : array_like, shape (3,) or (N, 3)
        Initial positions [m] and velocities [m/s] relative to the central body,
        inertial frame, at scene time ``t0``.
    mu : float
        Central gravitational parameter [m^3/s^2] (REBOUND runs with G = 1, m = mu).
    t0 : float
        Scene time of the initial state [s]; :meth:`advance_to` takes scene times.
    integrator : {"ias15", "whfast"}
        See the module docstring; WHFast needs bound orbits.
    model : {"kepler", "j2"}
        Point mass, or point mass plus the J2 zonal (``j2``, ``body_radius`` [m],
        pole along z).
    whfast_dt : float, optional
        WHFast step [s]; default the shortest orbital period / 20.
    max_steps : int
        Cap on REBOUND steps per :meth:`advance_to` call (RuntimeError beyond).
    """

    def __init__(
        self,
        r0,
        v0,
        mu: float,
        *,
        t0: float = 0.0,
        integrator: str = "ias15",
        model: str = "kepler",
        j2: float | None = None,
        body_radius: float | None = None,
        whfast_dt: float | None = None,
        max_steps: int = 100_000_000,
    ) -> None:
        import rebound

        r, v = _as_states(r0, v0)
        self.mu = _check_mu(mu)
        _check_choices(integrator, model)
        if not math.isfinite(float(t0)):
            raise ValueError(f"t0: expected a finite scene time in s, got {t0!r}")
        self.t0 = float(t0)
        self.integrator = integrator
        self.model = model
        self.max_steps = int(max_steps)
        self.r0 = r.copy()
        self.v0 = v.copy()

        sim = rebound.Simulation()
        sim.G = 1.0
        sim.integrator = integrator
        sim.add(m=self.mu)
        for ri, vi in zip(r, v):
            sim.add(m=0.0, x=ri[0], y=ri[1], z=ri[2], vx=vi[0], vy=vi[1], vz=vi[2])
        sim.N_active = 1
        sim.testparticle_type = 0  # test particles do not pull on the central body

        if model == "j2":
            if j2 is None or body_radius is None:
                raise ValueError("model='j2' needs j2 (dimensionless) and body_radius (m)")
            if not (math.isfinite(j2) and math.isfinite(body_radius) and body_radius > 0):
                raise ValueError(f"j2, body_radius: expected finite values and body_radius > 0, got {j2!r}, {body_radius!r}")
            self._force = _j2_force(float(j2), float(body_radius), self.mu)  # keep a reference alive
            sim.additional_forces = self._force
            sim.force_is_velocity_dependent = 0
        self.j2, self.body_radius = j2, body_radius

        if integrator == "whfast":
            energy = 0.5 * np.einsum("ij,ij->i", v, v) - self.mu / np.linalg.norm(r, axis=-1)
            unbound = np.flatnonzero(energy >= 0.0)
            if unbound.size:
                raise ValueError(
                    f"r0, v0: integrator='whfast' needs bound orbits (specific energy < 0); "
                    f"bodies {unbound[:10].tolist()} are parabolic or hyperbolic; use integrator='ias15'"
                )
            a = -self.mu / (2.0 * energy)
            period = 2.0 * np.pi * np.sqrt(a**3 / self.mu)
            dt = float(whfast_dt) if whfast_dt is not None else float(period.min()) / WHFAST_STEPS_PER_PERIOD
            if not (math.isfinite(dt) and dt > 0):
                raise ValueError(f"whfast_dt: expected a positive step in s, got {whfast_dt!r}")
            sim.dt = dt
        self.sim = sim
        # Elapsed time since t0 that REBOUND's state belongs to, as hi + lo (TwoSum);
        # with IAS15, hi equals sim.t (REBOUND's own plain running sum of the steps).
        self._elapsed_hi = 0.0
        self._elapsed_lo = 0.0

    @property
    def n_bodies(self) -> int:
        """Number of test particles (the central body excluded)."""
        return self.sim.N - 1

    @property
    def elapsed(self) -> float:
        """Time since ``t0`` [s] that the current REBOUND state belongs to (compensated sum of steps)."""
        return self._elapsed_hi + self._elapsed_lo

    @property
    def t(self) -> float:
        """Scene time [s] of the current REBOUND state: ``t0 + elapsed``."""
        return self.t0 + self.elapsed

    @property
    def steps_done(self) -> int:
        """REBOUND steps taken so far."""
        return int(self.sim.steps_done)

    def states(self) -> tuple[np.ndarray, np.ndarray]:
        """Current positions [m] and velocities [m/s] of the N bodies, each shape (N, 3)."""
        n = self.sim.N
        buf = np.empty(6 * n, dtype=np.float64)
        self.sim.serialize_particle_data(xyzvxvyvz=buf)
        s = buf.reshape(n, 6)
        return s[1:, :3].copy(), s[1:, 3:].copy()

    def central_body_state(self) -> tuple[np.ndarray, np.ndarray]:
        """Position and velocity of the central body (stays exactly zero for test particles)."""
        p = self.sim.particles[0]
        return np.array(p.xyz), np.array(p.vxyz)

    def advance_to(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Integrate to scene time ``t`` [s] (forward or backward) and return :meth:`states`.

        Stops exactly at ``t - t0`` on REBOUND's clock (the last step is shortened,
        as ``exact_finish_time=1`` does, and the full step restored afterwards);
        :attr:`elapsed` then holds the compensated elapsed time of the state.
        """
        t = float(t)
        if not math.isfinite(t):
            raise ValueError(f"t: expected a finite scene time in s, got {t!r}")
        target = t - self.t0
        sim = self.sim
        remaining = target - sim.t
        if remaining == 0.0:
            return self.states()
        direction = 1.0 if remaining > 0 else -1.0
        if sim.dt * direction <= 0.0:
            sim.dt = abs(sim.dt) * direction if sim.dt != 0.0 else remaining
        # WHFast advances sim.t in two half steps, so a remainder of one ulp can
        # round away to nothing and never close; a gap of a few ulp of the target
        # is left (elapsed, not sim.t, is the time of the state anyway).
        close_enough = 4.0 * math.ulp(target)
        for _ in range(self.max_steps):
            remaining = target - sim.t
            if remaining * direction <= 0.0 or abs(remaining) <= close_enough:
                break
            proposal = sim.dt  # IAS15: its adaptive proposal; WHFast: the fixed step
            last = abs(proposal) >= abs(remaining)
            if last:
                sim.dt = remaining  # land on the target (REBOUND's exact_finish_time)
            sim.steps(1)
            self._elapsed_hi, err = _two_sum(self._elapsed_hi, sim.dt_last_done)
            self._elapsed_lo += err
            if last:
                sim.dt = proposal  # restore the full step, as sim.integrate does
        else:
            raise RuntimeError(f"REBOUND needed more than max_steps={self.max_steps} steps to reach t={t}")
        return self.states()


@dataclass(frozen=True)
class CrossCheckResult:
    """REBOUND and astrodyn states at the same times, and their differences.

    Shapes: T requested times, N bodies.  Units SI (s, m, m/s).

    Attributes
    ----------
    times : (T,) requested elapsed times since the initial state.
    elapsed : (T, N) the elapsed time each REBOUND state belongs to (compensated
        sum of its steps); astrodyn is evaluated here.  ``elapsed - times[:, None]``
        is REBOUND's clock rounding.
    r_rebound, v_rebound, r_astrodyn, v_astrodyn : (T, N, 3)
    position_error, velocity_error : (T, N) |astrodyn - REBOUND| in m and m/s.
    relative_position_error, relative_velocity_error : (T, N) the same divided by
        |r_rebound| and |v_rebound|.
    steps : (T,) cumulative REBOUND steps to reach each time (summed over
        forward and backward runs; per body in ``separate`` mode, summed over bodies).
    """

    times: np.ndarray
    elapsed: np.ndarray
    r_rebound: np.ndarray
    v_rebound: np.ndarray
    r_astrodyn: np.ndarray
    v_astrodyn: np.ndarray
    position_error: np.ndarray
    velocity_error: np.ndarray
    relative_position_error: np.ndarray
    relative_velocity_error: np.ndarray
    steps: np.ndarray
    integrator: str
    model: str
    mu: float

    max_position_error = property(lambda self: float(np.max(self.position_error)),
                                  doc="Largest |dr| over times and bodies [m].")
    max_velocity_error = property(lambda self: float(np.max(self.velocity_error)),
                                  doc="Largest |dv| over times and bodies [m/s].")
    max_relative_position_error = property(lambda self: float(np.max(self.relative_position_error)),
                                           doc="Largest |dr| / |r| over times and bodies.")
    max_relative_velocity_error = property(lambda self: float(np.max(self.relative_velocity_error)),
                                           doc="Largest |dv| / |v| over times and bodies.")

    @classmethod
    def of_states(cls, times, elapsed, r_rebound, v_rebound, r_astrodyn, v_astrodyn, steps, integrator: str,
                  model: str, mu: float) -> CrossCheckResult:
        """The result for these states (the attributes of the same names; SI units), with
        the errors, absolute and relative to REBOUND's |r| and |v|, computed from them."""
        dr = np.linalg.norm(r_astrodyn - r_rebound, axis=-1)
        dv = np.linalg.norm(v_astrodyn - v_rebound, axis=-1)
        return cls(times, elapsed, r_rebound, v_rebound, r_astrodyn, v_astrodyn, dr, dv,
                   dr / np.linalg.norm(r_rebound, axis=-1), dv / np.linalg.norm(v_rebound, axis=-1),
                   steps, integrator, model, mu)

    def per_body_max(self) -> dict[str, np.ndarray]:
        """Per-body maxima over time, each shape (N,)."""
        return {
            "position_error": self.position_error.max(axis=0),
            "velocity_error": self.velocity_error.max(axis=0),
            "relative_position_error": self.relative_position_error.max(axis=0),
            "relative_velocity_error": self.relative_velocity_error.max(axis=0),
        }

    def summary(self) -> str:
        """One line: integrator, sizes and the four maxima."""
        t, n = self.position_error.shape
        return (
            f"{self.integrator}/{self.model}: {n} bodies x {t} times, {int(self.steps.max()) if t else 0} steps; "
            f"max |dr| {self.max_position_error:.3e} m (rel {self.max_relative_position_error:.3e}), "
            f"max |dv| {self.max_velocity_error:.3e} m/s (rel {self.max_relative_velocity_error:.3e})"
        )


def _default_propagator(model: str) -> Callable:
    if model != "kepler":
        raise ValueError(
            f"model={model!r}: pass propagator=callable(r0, v0, dt, mu) -> (r, v) giving astrodyn's "
            f"{model} propagation to compare against"
        )
    from astrodyn.orbit import propagate

    return propagate


def _run_direction(r, v, mu, order_times, scene_kwargs):
    """Integrate one REBOUND scene through monotone times; return states, elapsed, steps."""
    scene = ReboundScene(r, v, mu, **scene_kwargs)
    nt, n = len(order_times), len(r)
    rr = np.empty((nt, n, 3))
    vv = np.empty((nt, n, 3))
    el = np.empty(nt)
    st = np.empty(nt, dtype=np.int64)
    for k, tk in enumerate(order_times):
        rr[k], vv[k] = scene.advance_to(tk)
        el[k] = scene.elapsed
        st[k] = scene.steps_done
    return rr, vv, el, st


def crosscheck(
    r0,
    v0,
    times,
    mu: float,
    *,
    integrator: str = "ias15",
    model: str = "kepler",
    separate: bool = False,
    propagator: Callable | None = None,
    j2: float | None = None,
    body_radius: float | None = None,
    whfast_dt: float | None = None,
    max_steps: int = 100_000_000,
) -> CrossCheckResult:
    """Propagate the same initial states with REBOUND and astrodyn; return both and the differences.

    Parameters
    ----------
    r0, v0 : array_like, shape (3,) or (N, 3)
        Initial positions [m] / velocities [m/s] relative to the central body.
    times : float or array_like (T,)
        Elapsed times since the initial state [s], any sign, any order.  Non-negative
        times run in one forward REBOUND simulation, negative ones in one backward
        simulation, both from the initial state.
    mu : float
        Central gravitational parameter [m^3/s^2].
    integrator : {"ias15", "whfast"}
        WHFast needs bound orbits (ValueError otherwise).
    model : {"kepler", "j2"}
        Force model of the REBOUND twin (J2: give ``j2`` and ``body_radius`` [m],
        pole along z).  For "kepler" astrodyn's side is
        :func:`astrodyn.orbit.propagate`; otherwise pass ``propagator``.
    separate : bool
        If True, every body gets its own REBOUND simulation (its own adaptive IAS15
        step).  In one shared simulation the hardest body sets everyone's step
        (more steps, more cost; the accuracy of the others stays at their floor).
    propagator : callable(r0, v0, dt, mu) -> (r, v), optional
        astrodyn's side of the comparison, vectorized over bodies like ``propagate``.
    whfast_dt : float, optional
        WHFast step [s] (default shortest period / 20).
    max_steps : int
        Cap on REBOUND steps per requested time.

    Returns
    -------
    CrossCheckResult
        Arrays of shape (T, N, ...) (a scalar ``times`` gives T = 1, a (3,) state N = 1).
    """
    r, v = _as_states(r0, v0)
    mu = _check_mu(mu)
    t = np.atleast_1d(np.asarray(times, dtype=np.float64))
    if t.ndim != 1:
        raise ValueError(f"times: expected a scalar or a 1-D array of elapsed times in s, got shape {np.shape(times)}")
    if not np.all(np.isfinite(t)):
        raise ValueError("times: every time must be finite")
    _check_choices(integrator, model)
    if model == "j2" and (j2 is None or body_radius is None):
        raise ValueError("model='j2' needs j2 (dimensionless) and body_radius (m)")
    prop = propagator if propagator is not None else _default_propagator(model)
    scene_kwargs = dict(
        integrator=integrator,
        model=model,
        j2=j2,
        body_radius=body_radius,
        whfast_dt=whfast_dt,
        max_steps=max_steps,
    )

    nt, n = t.size, r.shape[0]
    r_reb = np.empty((nt, n, 3))
    v_reb = np.empty((nt, n, 3))
    elapsed = np.empty((nt, n))
    steps = np.zeros(nt, dtype=np.int64)
    groups = [np.arange(n)[i : i + 1] for i in range(n)] if separate else [np.arange(n)]
    fwd = np.flatnonzero(t >= 0)
    bwd = np.flatnonzero(t < 0)
    fwd = fwd[np.argsort(t[fwd], kind="stable")]
    bwd = bwd[np.argsort(-t[bwd], kind="stable")]
    for idx in (fwd, bwd):
        if idx.size == 0:
            continue
        for g in groups:
            rr, vv, el, st = _run_direction(r[g], v[g], mu, t[idx], scene_kwargs)
            r_reb[np.ix_(idx, g)] = rr
            v_reb[np.ix_(idx, g)] = vv
            elapsed[np.ix_(idx, g)] = el[:, None]
            steps[idx] += st

    # astrodyn at the exact elapsed time of each REBOUND state.
    r_ad, v_ad = prop(np.broadcast_to(r, (nt, n, 3)), np.broadcast_to(v, (nt, n, 3)), elapsed, mu)
    r_ad = np.asarray(r_ad, dtype=np.float64).reshape(nt, n, 3)
    v_ad = np.asarray(v_ad, dtype=np.float64).reshape(nt, n, 3)
    return CrossCheckResult.of_states(t, elapsed, r_reb, v_reb, r_ad, v_ad, steps, integrator, model, mu)
