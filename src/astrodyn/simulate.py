"""A scenario's dynamics, in process: the glue between a validated
:class:`~astrodyn.scenario.Scenario` and the numeric core.

Both propagator processes (``services/orbit.py``, ``services/attitude.py``), the
in-process headless run and the tests use the same engines, so what the bus carries is
exactly what :func:`simulate` returns for the same scenario.

* :class:`OrbitEngine` -- every orbit of the scene at a block of output times.  Bodies
  whose model is ``kepler`` (after :func:`astrodyn.scenario.plan` dropped perturbations
  that are identically zero) are evaluated exactly from their initial state at each
  time, vectorized over bodies (no accumulated error, cost independent of t).  Perturbed
  bodies (``j2``, ``zonal``, ``third_body``) are integrated with
  :func:`astrodyn.orbit.perturbations.propagate_perturbed`, block after block, each
  block continuing from the last state of the previous one.
* :class:`AttitudeEngine` -- every attitude.  ``torque_free`` bodies use the exact
  solution :func:`astrodyn.attitude.torque_free` from the initial state (never
  integrated); torqued bodies (gravity gradient, gyrostat, heavy top, user torque) use
  :func:`astrodyn.attitude.integrators.propagate_attitude` (structure-preserving
  splitting) block after block.  Gravity-gradient torque takes the body's position from
  the same :class:`OrbitEngine` code the orbit process publishes from, evaluated at the
  integrator's own kick times (between output instants too), so the attitude sees exactly
  the published orbit.  ``flexible`` bodies (a hub with assumed-mode beams,
  :mod:`astrodyn.attitude.flexible`) and ``rolling_disk`` bodies
  (:mod:`astrodyn.attitude.rolling_disk`) integrate their full state with DOP853 block
  after block (:class:`ExtendedBody`: :class:`FlexibleBody`, :class:`RollingBody`) and
  publish what ``(q, w)`` cannot hold on their own key
  (:meth:`AttitudeEngine.own_channels`).

Third bodies (``model = "third_body"``) move on the two-body conic fitted to their
geocentric (central-body-centric) state at the epoch, taken from astropy's built-in
ephemeris (ERFA ``epv00`` / ``moon98``, :mod:`astrodyn.scenario.ephemeris`): a deliberate approximation, stated in the run
summary, that needs no ephemeris download.

Units: SI; times in s since the scenario epoch; quaternions scalar first with
``v_body = C(q) v_inertial``; body rates in body axes (the axes the config used).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from astrodyn.messages import ACTUATED_MODEL, GIMBALS_KIND
from astrodyn.orbit import propagate
from astrodyn.orbit.perturbations import KeplerOrbit, ThirdBody, propagate_perturbed
from astrodyn.rotation import dcm_from_quat, quat_from_dcm
from astrodyn.scenario import CENTRAL_BODIES, Plan, Scenario, plan as make_plan
from astrodyn.scenario.ephemeris import third_body_state

__all__ = ["OrbitEngine", "AttitudeEngine", "ExtendedBody", "FlexibleBody", "RollingBody", "GyroSet", "ModelEnded",
           "SimulationResult", "SIMULATE_BLOCK",
           "simulate", "third_body_state"]


# --------------------------------------------------------------------------- orbits


@dataclass
class _PerturbedGroup:
    """Bodies sharing one perturbation set, integrated together from (t0, r0, v0)."""

    index: np.ndarray
    perturbations: tuple
    t0: float
    r0: np.ndarray
    v0: np.ndarray
    error_r: np.ndarray = field(default_factory=lambda: np.zeros(0))


class OrbitEngine:
    """Orbits of the bodies of ``scenario`` that have one (in scenario order).

    ``names``, ``models`` (per body, as the plan decided), ``mu``, ``frame``.
    :meth:`states` returns positions and velocities at a block of increasing times.
    """

    def __init__(self, scenario: Scenario, plan: Plan | None = None, rtol: float = 1e-12, atol: float = 1e-14):
        plan = plan or make_plan(scenario)
        models = {bp.name: bp.orbit_model for bp in plan.bodies}
        bodies = [b for b in scenario.bodies if b.orbit is not None and models[b.name] != ACTUATED_MODEL]
        self.scenario = scenario
        self.names = [b.name for b in bodies]
        self.models = [models[b.name] for b in bodies]
        self.mu = scenario.central_body.mu
        self.frame = scenario.frame
        self.rtol, self.atol = rtol, atol
        self.r0 = np.array([b.orbit.r0 for b in bodies], dtype=np.float64).reshape(-1, 3)
        self.v0 = np.array([b.orbit.v0 for b in bodies], dtype=np.float64).reshape(-1, 3)
        self.kepler = np.array([m == "kepler" for m in self.models], dtype=bool)
        self.groups: list[_PerturbedGroup] = []
        self.notes: list[str] = []
        groups: dict[tuple, list[int]] = {}
        for k, b in enumerate(bodies):
            if not self.kepler[k]:
                groups.setdefault((self.models[k], b.orbit.degree, b.orbit.perturbers), []).append(k)
        for (model, degree, perturbers), idx in groups.items():
            perts = self._perturbations(model, degree, perturbers)
            index = np.array(idx)
            self.groups.append(_PerturbedGroup(index, perts, 0.0, self.r0[index].copy(), self.v0[index].copy()))

    def _perturbations(self, model: str, degree: int, perturbers: tuple[str, ...]) -> tuple:
        cb = self.scenario.central_body
        if model == "j2":
            return (cb.zonal(2),)
        if model == "zonal":
            return (cb.zonal(max(2, degree)),)
        if model == "third_body":
            out = []
            for name in perturbers:
                mu3 = CENTRAL_BODIES[name][0]
                r3, v3 = third_body_state(name, cb.name, self.scenario.epoch_unix_ns)
                out.append(ThirdBody(mu3, KeplerOrbit(r3, v3, cb.mu + mu3)))
                self.notes.append(f"third body {name}: two-body conic fitted to astropy's built-in ephemeris at the epoch")
            return tuple(out)
        raise ValueError(f"orbit model: expected kepler | j2 | zonal | third_body, got {model!r}")

    def states(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(r, v)`` of shape ``(len(times), n_bodies, 3)`` at increasing ``times`` (s).

        Perturbed groups continue from the last block's final state, so blocks must come
        in increasing time order (a time before the last block's end raises ValueError).
        """
        times = np.asarray(times, dtype=np.float64).reshape(-1)
        T, N = times.shape[0], len(self.names)
        r = np.empty((T, N, 3))
        v = np.empty((T, N, 3))
        if T == 0 or N == 0:
            return r, v
        if self.kepler.any():
            k = self.kepler
            rk, vk = propagate(self.r0[k][None, :, :], self.v0[k][None, :, :], times[:, None], self.mu)
            r[:, k], v[:, k] = rk, vk
        for g in self.groups:
            if times[0] < g.t0:
                raise ValueError(f"times: perturbed orbits continue forward only; got {times[0]} s before {g.t0} s")
            out = propagate_perturbed(g.r0, g.v0, times - g.t0, self.mu, g.perturbations,
                                      method="cowell", rtol=self.rtol, atol=self.atol, error_estimate=False)
            r[:, g.index] = np.moveaxis(out.r, -2, 0)
            v[:, g.index] = np.moveaxis(out.v, -2, 0)
            g.t0, g.r0, g.v0 = float(times[-1]), r[-1, g.index].copy(), v[-1, g.index].copy()
        return r, v

    def resume(self, t: float, states: dict[str, dict]) -> list[str]:
        """Continue the integrated (perturbed) bodies from recorded states at time ``t`` (s).

        ``states`` maps body name -> ``{"r": (3,), "v": (3,)}`` (m, m/s), e.g. the last
        state a killed run logged.  Kepler bodies need nothing (they are exact from the
        initial state at any t, so a resumed run reproduces them bit for bit); every
        perturbed body must be given (ValueError naming the missing ones).  Returns the
        names of the bodies that took a state.
        """
        taken = []
        for g in self.groups:
            names = [self.names[i] for i in g.index]
            missing = [n for n in names if n not in states]
            if missing:
                raise ValueError(f"resume state: expected r and v of the integrated bodies {missing} at t = {t} s")
            g.t0 = float(t)
            g.r0 = np.array([states[n]["r"] for n in names], dtype=np.float64).reshape(-1, 3)
            g.v0 = np.array([states[n]["v"] for n in names], dtype=np.float64).reshape(-1, 3)
            taken += names
        return taken

    def position_function(self, body: str):
        """``r(t)`` (m) of one body at an array of times, from the same code as :meth:`states`.

        Kepler bodies: exact at any t.  Perturbed bodies: integrated from the epoch with a
        cache of the last state, so increasing calls cost only the new span.
        """
        k = self.names.index(body)
        r0, v0, mu = self.r0[k], self.v0[k], self.mu
        if self.kepler[k]:
            return lambda t: propagate(r0, v0, np.asarray(t, dtype=np.float64), mu)[0]
        group = next(g for g in self.groups if k in g.index)
        cache = {"t": 0.0, "r": r0.copy(), "v": v0.copy()}

        def position(t):
            t = np.asarray(t, dtype=np.float64)
            flat = t.reshape(-1)
            start = cache["t"] if flat.size and flat.min() >= cache["t"] else 0.0
            rs, vs = (cache["r"], cache["v"]) if start else (r0, v0)
            out = propagate_perturbed(rs, vs, flat - start, mu, group.perturbations, method="cowell",
                                      rtol=self.rtol, atol=self.atol, error_estimate=False)
            if flat.size:
                last = int(np.argmax(flat))
                cache.update(t=float(flat[last]), r=out.r[last].copy(), v=out.v[last].copy())
            return out.r.reshape(t.shape + (3,))

        return position


# --------------------------------------------------------------------------- attitudes


class ModelEnded(Exception):
    """A body's model cannot go on (a rolling disk fell flat: its equations are singular
    there and it has no impact model).  ``rows``: the output times of the block that were
    computed (``q``, ``w`` hold those rows for every body); ``str()`` names the body and
    the time."""

    def __init__(self, message: str, rows: int, q: np.ndarray, w: np.ndarray):
        super().__init__(message)
        self.rows, self.q, self.w = rows, q, w


class ExtendedBody:
    """A body whose state does not fit ``(q, w)`` alone (flexible spacecraft, rolling disk):
    it integrates its full state vector block after block with DOP853 at its config's
    ``tolerance`` (absolute: 1e-3 of it), publishes ``(q, w)`` on its attitude key and the
    rest on its own key, kind :attr:`kind` (:data:`astrodyn.messages.MODEL_STATE_KINDS`),
    at the same seq.  Subclasses give the integration (:meth:`_propagate`), the message of
    one sample (:meth:`message`), the hub's or disk's ``q, w`` of states
    (:meth:`attitude_of`) and the state vector from a recorded one (:meth:`state_from`)."""

    kind = ""
    #: the fields of the kind's message a resume needs (besides the attitude's q, w)
    resume_fields: tuple[str, ...] = ()

    def __init__(self, y0: np.ndarray, rtol: float):
        self.y, self.rtol = np.asarray(y0, dtype=np.float64), float(rtol)
        self.t0 = 0.0
        self.first = True  # the first block includes t0 itself
        self.last: np.ndarray | None = None  # full states at the last block's times
        self.nfev = 0
        self.ended: str | None = None  # why the model cannot go on (then states() returned fewer rows)

    def resume(self, t: float, q: np.ndarray, w: np.ndarray, recorded: dict) -> None:
        """Continue from a recorded state at ``t`` (s): the attitude's ``q``, ``w`` and the
        fields :attr:`resume_fields` of the body's own message."""
        self.y = self.state_from(q, w, recorded)
        self.t0, self.first = float(t), False

    def states(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(q, w)`` at ``times`` (increasing, after the last block's end); the full states
        go to :attr:`last`.  Fewer rows than ``times`` when the model ended inside the
        block (:attr:`ended` says why)."""
        rel = np.asarray(times, dtype=np.float64) - self.t0
        if rel[0] < 0 or (rel[0] == 0 and not self.first):
            raise ValueError(f"times: a {self.kind} body continues forward only, after t = {self.t0} s; got {times[0]} s")
        prepend = rel[0] > 0  # the integration starts at the state's own time
        grid = np.concatenate([[0.0], rel]) if prepend else rel
        y, info = self._propagate(grid)
        if "flat_at" in info:
            self.ended = (f"the rolling disk lies flat (|lean| = 90 deg) at t = {self.t0 + info['flat_at']:.9g} s: "
                          "the model (no impact with the plane) ends there")
        if prepend:
            y = y[1:]
        self.nfev += int(info["nfev"])
        if y.shape[0] == 0:  # ended before the block's first time
            return self.attitude_of(np.zeros((0, self.y.size)))
        self.first, self.t0, self.y, self.last = False, float(times[-1]), y[-1].copy(), y
        return self.attitude_of(y)

    def _propagate(self, grid: np.ndarray) -> tuple[np.ndarray, dict]:
        raise NotImplementedError

    def attitude_of(self, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError

    def state_from(self, q: np.ndarray, w: np.ndarray, recorded: dict) -> np.ndarray:
        raise NotImplementedError

    def message(self, j: int, t: float, seq: int) -> dict:
        """The message of row ``j`` of :attr:`last` on the body's own key (docs/architecture.md, section 5)."""
        raise NotImplementedError


class FlexibleBody(ExtendedBody):
    """A flexible spacecraft (``model = "flexible"``): :func:`astrodyn.attitude.flexible.
    propagate_spacecraft` on the hub's attitude, rates, the centre's motion and the
    appendages' modal coordinates.  The linear momentum is zero (the system's mass centre
    at rest, :func:`~astrodyn.attitude.flexible.make_state`); the hub's attitude and rates
    are in the config's body axes.  Its own key carries :class:`astrodyn.messages.AppendageState`."""

    kind = "appendages"
    resume_fields = ("eta", "eta_dot")

    def __init__(self, spacecraft, q0: np.ndarray, w0: np.ndarray, rtol: float):
        from astrodyn.attitude import flexible as fx

        self.sc = spacecraft
        self.layout = fx.state_layout(spacecraft)
        super().__init__(fx.make_state(spacecraft, q=q0, w=w0), rtol)
        self._tip: tuple[int, np.ndarray] | None = None

    def _propagate(self, grid):
        from astrodyn.attitude import flexible as fx

        self._tip = None
        return fx.propagate_spacecraft(self.sc, self.y, grid, rtol=self.rtol, atol=1e-3 * self.rtol)

    def attitude_of(self, y):
        return y[:, self.layout["q"]], y[:, self.layout["w"]]

    def state_from(self, q, w, recorded):
        from astrodyn.attitude import flexible as fx

        flat = [np.concatenate([np.asarray(x, dtype=np.float64) for x in recorded[f]]) for f in self.resume_fields]
        return fx.make_state(self.sc, q=q, w=w, eta=flat[0], eta_dot=flat[1])

    def message(self, j, t, seq):
        from astrodyn.attitude import flexible as fx
        from astrodyn.scenario.appendages import appendage_message

        if self._tip is None:  # tip displacements of the whole block, once
            self._tip = fx.tip_deflections(self.sc, self.last)
        return appendage_message(self.sc, self.last[j], t, seq, self._tip[j])


class RollingBody(ExtendedBody):
    """A disk rolling on the plane z = 0 (``model = "rolling_disk"``):
    :func:`astrodyn.attitude.rolling_disk.propagate_rolling_disk` on ``(x, y, psi, theta,
    phi, u1, u2, u3)``.  Its own key carries :class:`astrodyn.messages.RollingState`."""

    kind = "rolling"
    resume_fields = ("contact", "heading", "lean", "spin_angle", "u")

    def __init__(self, disk, y0: np.ndarray, rtol: float):
        self.disk = disk
        super().__init__(y0, rtol)

    def _propagate(self, grid):
        from astrodyn.attitude.rolling_disk import propagate_rolling_disk

        return propagate_rolling_disk(self.disk, self.y, grid, rtol=self.rtol, atol=1e-3 * self.rtol)

    def attitude_of(self, y):
        from astrodyn.attitude.rolling_disk import disk_body_rates, disk_quaternion

        return disk_quaternion(y), disk_body_rates(y)

    def state_from(self, q, w, recorded):
        r = recorded
        return np.array([*r["contact"], r["heading"], r["lean"], r["spin_angle"], *r["u"]], dtype=np.float64)

    def message(self, j, t, seq):
        from astrodyn.attitude.rolling_disk import center_position

        y = self.last[j]
        return {"t": t, "seq": seq, "contact": y[0:2].tolist(), "center": center_position(self.disk, y).tolist(),
                "heading": float(y[2]), "lean": float(y[3]), "spin_angle": float(y[4]), "u": y[5:8].tolist()}


class GyroSet:
    """The single-axis gyroscopes mounted on one body (``[[bodies.gyros]]``, Baruh 10.7.3;
    their gimbals an :class:`astrodyn.scenario.gyros.GimbalBank`), integrated block after
    block on the body's rates at the output times (a cubic spline through them, continued
    across blocks from the previous block's last samples).  Published on ``<body>/gimbals``
    (:class:`astrodyn.messages.GimbalState`)."""

    kind = GIMBALS_KIND
    resume_fields = ("angle", "angle_rate")

    def __init__(self, gyros, w0: np.ndarray):
        from astrodyn.scenario.gyros import GimbalBank

        self.bank = GimbalBank(gyros, w0)
        self.t0 = 0.0
        self.tail_t, self.tail_w = np.zeros(0), np.zeros((0, 3))  # the previous block's last samples
        self.last: np.ndarray | None = None  # (T, n, 2) states at the last block's times

    def resume(self, t: float, recorded: dict) -> None:
        """Continue from recorded gimbal angles and rates at ``t`` (s); the body's rate
        ``w`` there (body axes, as recorded on its attitude key) starts the base's samples."""
        self.bank.state = np.column_stack([np.asarray(recorded["angle"], dtype=np.float64),
                                           np.asarray(recorded["angle_rate"], dtype=np.float64)])
        self.t0 = float(t)
        self.tail_t, self.tail_w = np.array([self.t0]), np.asarray(recorded["w"], dtype=np.float64).reshape(1, 3)

    @staticmethod
    def _base(times: np.ndarray, w: np.ndarray, mount: np.ndarray):
        """``t -> (w, w')`` in the gyro's case axes from body-rate samples at absolute times."""
        from astrodyn.attitude.gyroscopes import sampled_base_rate

        if times.size >= 4:
            return sampled_base_rate(times, w, mount)
        wc = w @ mount.T  # too few samples for a spline: piecewise linear
        slopes = np.diff(wc, axis=0) / np.diff(times)[:, None] if times.size > 1 else np.zeros((1, 3))

        def base(t):
            if times.size == 1:
                return wc[0], np.zeros(3)
            i = int(np.clip(np.searchsorted(times, t) - 1, 0, times.size - 2))
            return wc[i] + slopes[i] * (t - times[i]), slopes[i]

        return base

    def advance(self, times: np.ndarray, w: np.ndarray) -> None:
        """Integrate every gimbal to ``times`` (increasing, after :attr:`t0`) on the body's
        rates ``w`` (len(times), 3) there (rad/s, body axes)."""
        times = np.asarray(times, dtype=np.float64)
        rel = times - self.t0
        prepend = rel[0] > 0
        grid = np.concatenate([[0.0], rel]) if prepend else rel
        if prepend:  # the previous block's last samples (they end at t0), or the resumed state's rate
            samples_t, samples_w = np.concatenate([self.tail_t, times]), np.concatenate([self.tail_w, w])
        else:
            samples_t, samples_w = times, w
        t0 = self.t0
        bases = []
        for mount in self.bank.mounts:
            base_abs = self._base(samples_t, samples_w, mount)
            bases.append(lambda t, base_abs=base_abs: base_abs(t0 + t))
        out = self.bank.advance(bases, grid)
        self.t0, self.last = float(times[-1]), out[1:] if prepend else out
        keep = max(0, samples_t.size - 3)
        self.tail_t, self.tail_w = samples_t[keep:], samples_w[keep:]

    def message(self, j: int, t: float, seq: int) -> dict:
        """The ``GimbalState`` of row ``j`` of the last block."""
        angle, rate = self.last[j, :, 0], self.last[j, :, 1]
        return {"t": t, "seq": seq, "angle": angle.tolist(), "angle_rate": rate.tolist(),
                "indicated": self.bank.indicated(angle).tolist()}


#: ``max_steps`` of the engine's splitting calls (one block of output times per call).  The
#: callers bound a call's span themselves -- the service to ATTITUDE_STEPS_PER_CALL steps of
#: the fastest body between heartbeats, :func:`simulate` to one block of the config's own
#: output grid -- and the shipped configs take at most ~2e4 steps per call; the cap (100x the
#: integrator's default, ~10-90 s of kernel time) only refuses a config whose rates make one
#: block absurdly long (e.g. 1e6 rad/s), with the integrator's message, instead of running
#: for hours.
ENGINE_MAX_STEPS = 100_000_000


@dataclass
class _AttitudeBody:
    name: str
    model: str
    inertia: np.ndarray  # principal moments (3,)
    axes: np.ndarray  # body components of the principal axes (columns); identity if diagonal
    w0: np.ndarray  # principal-frame rates at t0
    q0: np.ndarray  # principal-frame Euler parameters at t0
    t0: float = 0.0
    torque: object = None
    top: object = None  # HeavyTop for a symmetric heavy top (its own exact-free-flow splitting)
    rotor_momentum: np.ndarray | None = None
    extended: ExtendedBody | None = None  # flexible, rolling_disk: integrates its own full state
    gyros: GyroSet | None = None  # single-axis gyroscopes mounted on it
    error: float = 0.0
    steps: int = 0


class AttitudeEngine:
    """Attitudes of the bodies of ``scenario`` that are propagated (model != none).

    Internally every body is propagated in its principal frame (the exact solution and
    the splitting both want principal moments); :meth:`states` returns ``q`` and ``w`` in
    the body axes of the config.
    """

    def __init__(self, scenario: Scenario, plan: Plan | None = None, orbits: OrbitEngine | None = None,
                 step: float | None = None):
        plan = plan or make_plan(scenario)
        models = {bp.name: bp.attitude_model for bp in plan.bodies}
        self.scenario = scenario
        self.step = step
        self.free_bodies = None  # PreparedBody of the torque-free bodies, set up at the first states() call
        self.bodies: list[_AttitudeBody] = []
        for b in scenario.bodies:
            model = models.get(b.name)
            if b.attitude is None or model is None or model == ACTUATED_MODEL:  # the plant's (astrodyn.plant)
                continue
            a = b.attitude
            axes = np.asarray(a.principal_axes, dtype=np.float64)
            c_pb = axes.T  # body -> principal components
            q0 = quat_from_dcm(c_pb @ dcm_from_quat(a.q0))
            body = _AttitudeBody(b.name, model, np.asarray(a.principal_moments, dtype=np.float64), axes,
                                 c_pb @ a.w0, q0)
            if model == "gravity_gradient":
                from astrodyn.attitude.torques import GravityGradientTorque

                if b.orbit is None:
                    raise ValueError(f"bodies.{b.name}.attitude.model: gravity_gradient needs an orbit for the body")
                orbits = orbits or OrbitEngine(scenario, plan)
                k = orbits.names.index(b.name)
                mu = scenario.central_body.mu
                if orbits.kepler[k]:
                    # the same two-body orbit the orbit process publishes, evaluated inside the
                    # integrator's compiled kernel (exact nodes + quintic Hermite between them)
                    body.torque = GravityGradientTorque.kepler(mu, orbits.r0[k], orbits.v0[k], body.inertia)
                else:
                    body.torque = GravityGradientTorque(mu, orbits.position_function(b.name), body.inertia)
            elif model == "heavy_top":
                from astrodyn.attitude.top import HeavyTop
                from astrodyn.attitude.torques import UniformGravityTorque

                body.torque = UniformGravityTorque(a.mass, c_pb @ np.array([0.0, 0.0, a.cm]), (0.0, 0.0, -a.g))
                I = body.inertia
                if np.array_equal(body.axes, np.eye(3)) and I[0] == I[1]:
                    # symmetric top: the exact free symmetric-top flow keeps J w3 to round-off
                    body.top = HeavyTop(mass=a.mass, cm_distance=a.cm, transverse_inertia=I[0],
                                        axial_inertia=I[2], gravity=a.g)
            elif model == "user":
                from astrodyn.attitude.torques import ConstantTorque

                body.torque = ConstantTorque(c_pb @ a.torque, frame="body")
            elif model == "gyrostat":
                h = sum((r.h * np.asarray(r.axis, dtype=np.float64) for r in a.rotors), np.zeros(3))
                body.rotor_momentum = c_pb @ h
            elif model == "flexible":  # the hub's full inertia tensor, in the config's body axes
                from astrodyn.scenario.appendages import flexible_spacecraft

                sc = flexible_spacecraft(a.mass, a.inertia, a.appendages, a.stiffening)
                body.axes, body.q0, body.w0 = np.eye(3), np.asarray(a.q0, dtype=np.float64), np.asarray(a.w0, dtype=np.float64)
                body.extended = FlexibleBody(sc, body.q0, body.w0, a.tolerance)
            elif model == "rolling_disk":
                from astrodyn.scenario.rolling import rolling_disk, rolling_state0

                body.axes = np.eye(3)
                body.extended = RollingBody(rolling_disk(a.rolling), rolling_state0(a.rolling), a.tolerance)
            if b.gyros:  # their base: the body's rates in the config's body axes, as published
                body.gyros = GyroSet(b.gyros, a.w0)
            self.bodies.append(body)
        self.names = [b.name for b in self.bodies]
        self.models = [b.model for b in self.bodies]

    def own_channels(self) -> list[tuple[int, ExtendedBody | GyroSet]]:
        """``(body index, source)`` of every further state channel of the bodies (their
        kinds: ``BodyPlan.own_kinds``): each source's ``kind`` and ``message(j, t, seq)`` give
        the messages of the last :meth:`states` call's row ``j``."""
        out: list[tuple[int, ExtendedBody | GyroSet]] = []
        for k, b in enumerate(self.bodies):
            out += [(k, src) for src in (b.extended, b.gyros) if src is not None]
        return out

    def resume(self, t: float, states: dict[str, dict]) -> list[str]:
        """Continue the torqued (integrated) bodies from recorded states at time ``t`` (s).

        ``states`` maps body name -> ``{"q": (4,), "w": (3,)}`` in the config's body axes
        (as published; a flexible or rolling body also the fields of its own key that its
        :class:`ExtendedBody` names, e.g. ``"eta"``, ``"eta_dot"``).  Torque-free bodies
        need nothing (exact from the initial state); every integrated body must be given
        (ValueError naming the missing ones).  Returns the names of the bodies that took a state.
        """
        integrated = [b for b in self.bodies if b.model != "torque_free" or b.gyros is not None]
        missing = [b.name for b in integrated if b.name not in states
                   or (b.extended is not None and not set(b.extended.resume_fields) <= set(states[b.name]))
                   or (b.gyros is not None and not set(b.gyros.resume_fields) <= set(states[b.name]))]
        if missing:
            raise ValueError(f"resume state: expected q and w (and the fields of their own key for flexible and "
                             f"rolling bodies and gyroscopes) of the integrated bodies {missing} at t = {t} s")
        for b in integrated:
            if b.gyros is not None:
                b.gyros.resume(t, states[b.name])
                if b.model == "torque_free":
                    continue
            q = np.asarray(states[b.name]["q"], dtype=np.float64)
            w = np.asarray(states[b.name]["w"], dtype=np.float64)
            if b.extended is not None:
                b.extended.resume(t, q, w, states[b.name])
                continue
            c_pb = b.axes.T  # body -> principal components
            b.t0 = float(t)
            b.q0 = q.copy() if np.array_equal(b.axes, np.eye(3)) else quat_from_dcm(c_pb @ dcm_from_quat(q))
            b.w0 = w.copy() if np.array_equal(b.axes, np.eye(3)) else c_pb @ w
        return [b.name for b in integrated]

    def states(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(q, w)`` of shapes ``(len(times), n_bodies, 4)`` and ``(..., 3)`` at increasing times."""
        from astrodyn.attitude.integrators import propagate_attitude
        from astrodyn.attitude.torque_free import PreparedBody

        times = np.asarray(times, dtype=np.float64).reshape(-1)
        T, N = times.shape[0], len(self.bodies)
        q = np.empty((T, N, 4))
        w = np.empty((T, N, 3))
        ended = (T, "")  # (rows computed, why) when a body's model ends inside the block
        free = [k for k, b in enumerate(self.bodies) if b.model == "torque_free"]
        if free and T:
            # one batched call for every torque-free body (exact from its initial state); their
            # constants (the elliptic setup) are computed once per engine, not per block
            if self.free_bodies is None:
                self.free_bodies = PreparedBody(np.array([self.bodies[k].inertia for k in free]),
                                                np.array([self.bodies[k].w0 for k in free]),
                                                np.array([self.bodies[k].q0 for k in free]))
            wf, qf = self.free_bodies.states(times)
            q[:, free], w[:, free] = np.swapaxes(qf, 0, 1), np.swapaxes(wf, 0, 1)
        for k, b in enumerate(self.bodies):
            if T == 0:
                break
            if b.model == "torque_free":
                if np.array_equal(b.axes, np.eye(3)):
                    continue
                qp, wp = q[:, k].copy(), w[:, k].copy()
            else:
                if times[0] < b.t0:
                    raise ValueError(f"times: torqued attitudes continue forward only; got {times[0]} s before {b.t0} s")
                if b.extended is not None:
                    qe, we = b.extended.states(times)
                    rows = qe.shape[0]
                    q[:rows, k], w[:rows, k] = qe, we
                    if rows < T:
                        ended = min(ended, (rows, f"{b.name}: {b.extended.ended}"))
                    continue
                if b.top is not None:
                    wp, qp, info = b.top.simulate(b.w0, b.q0, times - b.t0, method="top4", step=self.step,
                                                  error_estimate=False, max_steps=ENGINE_MAX_STEPS)
                else:
                    torque = _shifted(b.torque, b.t0)
                    wp, qp, info = propagate_attitude(b.inertia, b.w0, b.q0, times - b.t0, torque=torque,
                                                      rotor_momentum=b.rotor_momentum, method="split4",
                                                      step=self.step, error_estimate=False,
                                                      max_steps=ENGINE_MAX_STEPS)
                b.t0, b.w0, b.q0 = float(times[-1]), wp[-1].copy(), qp[-1].copy()
                b.steps += int(info.get("n_steps", 0))
            # principal -> body axes: C_BI = C_BP C_PI with C_BP = axes
            if np.array_equal(b.axes, np.eye(3)):
                q[:, k], w[:, k] = qp, wp
            else:
                q[:, k] = quat_from_dcm(b.axes @ dcm_from_quat(qp))
                w[:, k] = wp @ b.axes.T
        rows = ended[0]
        for k, b in enumerate(self.bodies):
            if b.gyros is not None and rows:
                b.gyros.advance(times[:rows], w[:rows, k])
        if rows < T:
            raise ModelEnded(ended[1], rows, q[:rows], w[:rows])
        return q, w


def _shifted(model, t0: float):
    """The torque model as seen from a block starting at ``t0`` (block-relative times).

    Built-in models stay built-in types so the integrator keeps its compiled path: uniform
    gravity and body-fixed constant torques do not depend on t; gravity gradient moves its
    orbit's clock (:meth:`GravityGradientTorque.shifted`).
    """
    from astrodyn.attitude.torques import GravityGradientTorque

    if model is None or t0 == 0.0:
        return model
    if isinstance(model, GravityGradientTorque):
        return model.shifted(t0)
    return model


# --------------------------------------------------------------------------- whole run


@dataclass
class SimulationResult:
    """Arrays of a whole run: ``t (T,)``; ``orbit_names``, ``r, v (T, N, 3)``;
    ``attitude_names``, ``q (T, M, 4)``, ``w (T, M, 3)``; ``plan``."""

    t: np.ndarray
    orbit_names: list[str]
    r: np.ndarray
    v: np.ndarray
    attitude_names: list[str]
    q: np.ndarray
    w: np.ndarray
    plan: Plan


#: Output steps :func:`simulate` has the engines compute at a time (its blocks' working arrays).
SIMULATE_BLOCK = 1000


def simulate(scenario: Scenario, block: int = SIMULATE_BLOCK) -> SimulationResult:
    """Run ``scenario`` in this process (no bus, no file) and return every output state.

    Memory: the whole run's arrays (:class:`SimulationResult`: 8 bytes per output step for
    ``t``, 48 per orbit and 56 per attitude), held twice while the blocks are joined."""
    p = make_plan(scenario)
    orbits = OrbitEngine(scenario, p)
    attitudes = AttitudeEngine(scenario, p)
    t = scenario.output_times()
    rs, vs, qs, ws = [], [], [], []
    for s in range(0, t.shape[0], block):
        tb = t[s : s + block]
        r, v = orbits.states(tb)
        q, w = attitudes.states(tb)
        rs.append(r), vs.append(v), qs.append(q), ws.append(w)
    def cat(xs, n, d):
        return np.concatenate(xs) if xs else np.empty((0, n, d))
    return SimulationResult(t, orbits.names, cat(rs, len(orbits.names), 3), cat(vs, len(orbits.names), 3),
                            attitudes.names, cat(qs, len(attitudes.names), 4), cat(ws, len(attitudes.names), 3), p)
