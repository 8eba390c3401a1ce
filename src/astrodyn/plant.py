"""The closed loop's plant: the bodies a scene gives actuators or sensors, stepped with the
commands of outside controllers (docs/control.md).  Pure: states, commands and sensor
samples in and out, no bus, no files; :mod:`astrodyn.service.plant` wires it to Zenoh
and ``run --commands`` re-simulates from a recording with the same code.

One output step ``k`` (``t_k = k / rate``, ``dt = 1 / rate``) of a body:

1. faults that begin at ``t_k`` take effect (:meth:`Plant.faults_at`);
2. its states and due sensor samples at ``t_k`` are read off (:meth:`PlantBody.sensor_samples`);
3. commands that apply at ``t_k`` are applied (:meth:`PlantBody.apply`): ``torque``,
   ``wheel_torque`` and ``thrust`` replace the held values (zero-order hold), ``dv`` is
   added to the velocity at ``t_k``;
4. the body is advanced to ``t_k + dt`` with the held values (:meth:`PlantBody.advance`):
   attitude with reaction wheels by :func:`astrodyn.attitude.wheels.step_with_wheels`
   (momentum of body plus wheels conserved to round-off under internal torques), with only
   an external torque by the same compiled exact-rotation splitting
   (:class:`astrodyn.attitude.integrators.HeldInputsBody`), without either by the exact
   torque-free solution; the orbit by the exact
   two-body propagation, or under thrust by :func:`astrodyn.orbit.propagate_perturbed`
   (mass falls at ``|F| / (isp g0)``): an inertial thrust held fixed
   (:class:`astrodyn.orbit.maneuvers.ConstantThrust`); a body-axis thrust turning with the
   body (:class:`astrodyn.orbit.maneuvers.RotatingThrust`), from ``C(q(t_k))^T f`` at the
   step's start to ``C(q(t_k + dt))^T f`` at its end, uniformly about the axis of the body's
   inertial rotation over the step (its whole turns counted from the rates at both ends):
   exact for a spin about a fixed axis at a constant rate, both ends exact otherwise.
   A flexible body (``attitude.model = "flexible"``: a rigid hub with cantilevered beams,
   :mod:`astrodyn.attitude.flexible`) advances its whole state (hub attitude and rates,
   the appendages' modal coordinates) with the same held commands: :class:`FlexiblePlantBody`.

Limits, applied to each command (after which it is valid): external torque clipped to the
actuators' ``torque`` per body axis; wheel torques saturated per step by
:meth:`astrodyn.attitude.wheels.ReactionWheels.saturate` (torque and speed limits; the
clipped wheels are reported); ``|dv|`` and ``|thrust|`` scaled down to their limits.
A command for an actuator the body does not have is refused with the reason.

Deterministic: the same initial state and the same commands applied at the same steps
give the same floats, bit for bit (what ``run --commands REC`` relies on).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

import numpy as np

from astrodyn.attitude import flexible as fx, propagate_attitude, torque_free
from astrodyn.attitude.integrators import HeldInputsBody
from astrodyn.attitude.torques import ConstantTorque
from astrodyn.attitude.wheels import HeldInputsBatch, ReactionWheels, step_with_wheels
from astrodyn.orbit import propagate
from astrodyn.orbit.maneuvers import G0, ConstantThrust, RotatingThrust
from astrodyn.orbit.perturbations import propagate_perturbed
from astrodyn.rotation import dcm_from_quat, quat_conjugate, quat_multiply, rotvec_from_quat
from astrodyn.scenario import Body, Scenario
from astrodyn.scenario.appendages import DEFAULT_TOLERANCE, appendage_message, flexible_spacecraft
from astrodyn.scenario.control import Fault, Sensor
from astrodyn.scenario.gyros import GimbalBank
from astrodyn.sensors import PositionReceiver, RateGyro, StarTracker, WheelTachometer
from astrodyn.simulate import ENGINE_MAX_STEPS

__all__ = ["CommandRefused", "PlantBody", "FlexiblePlantBody", "Plant", "command_id", "limited", "plant_body"]


class CommandRefused(ValueError):
    """A command the plant does not apply; ``str`` says why (counted, never fatal)."""


def command_id(sender: str, seq: int) -> str:
    """``sender#seq``: how an actuator state names the commands applied at its step."""
    return f"{sender}#{seq}"


def limited(vector, limit: float) -> np.ndarray:
    """``vector`` (3,) scaled down to magnitude ``limit`` if longer, direction kept; the
    norm taken without overflow (components up to the float64 maximum)."""
    v = np.asarray(vector, dtype=np.float64)
    big = float(np.max(np.abs(v)))
    if big == 0.0:
        return v.copy()
    unit = v / big
    n = float(np.linalg.norm(unit))  # |v| = big n, which may overflow: compare, never form v / |v| from it
    return unit * (limit / n) if big * n > limit else v.copy()


def _body_turn(q0, w0, q1, w1, dt: float) -> np.ndarray:
    """The rotation vector ``v`` (rad, inertial axes) of a body's turn over a step of ``dt`` s
    from attitude ``q0`` (rates ``w0``, body axes) to ``q1`` (``w1``): ``C(q1)^T C(q0) =
    exp([v x])``, the active rotation that takes the body's axes at the start (inertial
    components) to those at the end, by ``|v|`` about ``v`` (right-handed).

    ``C(q0)^T C(q1) = C(conj(q0) q1)`` gives the axis ``n`` and the angle ``theta`` in
    ``[0, pi]``; the rotation vectors of that rotation are ``n (theta + 2 pi j)``, ``j``
    any integer (those with ``j < 0`` the turns the other way about ``-n``).  The body may
    turn more than pi in a step, so ``j`` is the one closest to the estimate ``dt (C(q0)^T
    w0 + C(q1)^T w1) / 2`` (the trapezoid rule on the inertial rate): ``j = round((s -
    theta) / (2 pi))``, ``s`` the estimate's component along ``n``.  Near a whole number of
    turns (``theta < 1e-6``) ``n`` is round-off (``~eps / theta``): the estimate's
    direction is taken instead (the end attitude then met to ``theta``)."""
    r = rotvec_from_quat(quat_multiply(quat_conjugate(q0), q1))  # C(q0)^T C(q1) = exp(-[r x])
    est = 0.5 * dt * (dcm_from_quat(q0).T @ w0 + dcm_from_quat(q1).T @ w1)
    theta = float(np.linalg.norm(r))
    if theta > 1e-6:
        n = r / theta
    else:
        big = float(np.linalg.norm(est))
        if not big > math.pi:  # less than half a turn (or none): the small rotation itself
            return r
        n = est / big
        theta = float(r @ n)
    j = round((float(est @ n) - theta) / (2.0 * math.pi))
    return n * (theta + 2.0 * math.pi * j)


@dataclass
class _Faults:
    gyro_bias: np.ndarray | None = None
    dropouts: dict = field(default_factory=dict)  # sensor kind -> first output step k after it (inf: for ever)
    failed_wheels: set = field(default_factory=set)
    stuck_wheels: set = field(default_factory=set)
    efficiency: float = 1.0


class PlantBody:
    """One actuated body: its state, its held commands and its sensors (module docstring)."""

    def __init__(self, body: Body, mu: float, seed: tuple[int, ...]):
        self.name = body.name
        self.mu = float(mu)
        self.seed = tuple(int(x) for x in seed)  # (scene seed, body index): independent noise per body
        self.index = self.seed[1]
        act = body.actuators
        self.limits = act
        self.has_orbit = body.orbit is not None
        a = body.attitude
        self.has_attitude = a is not None and a.model != "none"
        self.r = np.array(body.orbit.r0, dtype=np.float64) if self.has_orbit else None
        self.v = np.array(body.orbit.v0, dtype=np.float64) if self.has_orbit else None
        self.q = np.array(a.q0, dtype=np.float64) if self.has_attitude else None
        self.w = np.array(a.w0, dtype=np.float64) if self.has_attitude else None
        self.inertia = np.array(a.inertia, dtype=np.float64) if self.has_attitude else None
        self._diagonal = self.has_attitude and not np.any(self.inertia - np.diag(np.diag(self.inertia)))
        self.wheels = None
        self.h = None
        if act is not None and act.wheels:
            self.wheels = ReactionWheels(np.array([wh.axis for wh in act.wheels]), [wh.inertia for wh in act.wheels],
                                         [wh.max_torque for wh in act.wheels], [wh.max_speed for wh in act.wheels])
            self.h = self.wheels.absolute_momentum([wh.speed for wh in act.wheels], self.w)
        self._held = None
        if self.has_attitude:  # the compiled held-input step, its principal frame set up once
            self._held = HeldInputsBody(self.inertia if self.wheels is None else self.wheels.kinematic_inertia(self.inertia))
        n = 0 if self.wheels is None else self.wheels.n
        self.torque = np.zeros(3)  # held external torque, body axes, N m (after the limit)
        self.wheel_command = np.zeros(n)  # held motor torque commands, N m (saturated each step)
        self.thrust = np.zeros(3)  # held thrust, N
        self.thrust_frame = "inertial"
        self.mass = None if act is None else act.mass
        self.dv_total = 0.0
        self.sensors: tuple[Sensor, ...] = body.sensors.present() if body.sensors is not None else ()
        self.sensor_counts = {s.kind: 0 for s in self.sensors}
        # a dynamic gyro sensor: three rate gyros' gimbals, driven by the body's rate step by step
        gyro = body.sensors.gyro if body.sensors is not None else None
        self.gimbals = GimbalBank(gyro.dynamics, self.w) if gyro is not None and gyro.dynamics else None
        self.faults = _Faults()
        # what the last advance applied (for the actuator state of the step)
        self.applied_wheel = np.zeros(n)
        self.clipped: list[int] = []
        self.step_dv: np.ndarray | None = None
        self.step_dv_t = 0.0  # when the step's impulse was applied, s
        self.step_applied: list[str] = []
        self.step_applied_ids: list[tuple[str, int]] = []  # (sender, seq) of step_applied

    # ------------------------------------------------------------------ commands
    def apply(self, cmd: dict, at: float | None = None) -> None:
        """Apply a decoded :class:`astrodyn.messages.Command` now, at simulated time ``at``
        (s; the command's own ``t`` when None), recorded as the impulse's time (raise CommandRefused)."""
        why = self.refusal(cmd)
        if why is not None:
            raise CommandRefused(why)
        act = self.limits
        if "torque" in cmd:
            torque = np.asarray(cmd["torque"], dtype=np.float64)
            self.torque = np.minimum(np.maximum(torque, -act.torque), act.torque)  # np.clip, without its overhead
        if "wheel_torque" in cmd:
            self.wheel_command = np.asarray(cmd["wheel_torque"], dtype=np.float64)
        if "thrust" in cmd:
            self.thrust = limited(cmd["thrust"], act.thrust)
            self.thrust_frame = cmd.get("frame", "inertial")
        if "dv" in cmd:
            dv = limited(cmd["dv"], act.dv) * self.faults.efficiency
            self.v = self.v + dv
            self.dv_total += float(np.linalg.norm(dv))
            if self.mass is not None and math.isfinite(act.isp):  # the rocket equation, m1 = m0 exp(-|dv| / (isp g0))
                self.mass *= math.exp(-float(np.linalg.norm(dv)) / (act.isp * G0))
            self.step_dv = dv if self.step_dv is None else self.step_dv + dv
            self.step_dv_t = float(cmd["t"] if at is None else at)
        self.step_applied.append(command_id(cmd["sender"], cmd["seq"]))
        self.step_applied_ids.append((cmd["sender"], cmd["seq"]))

    def refusal(self, cmd: dict) -> str | None:
        """Why this body cannot apply the decoded command ``cmd`` at all, whenever it comes (an
        actuator it does not have, one value per wheel not given, body-frame thrust without an
        attitude); None when it can."""
        act = self.limits
        if act is None:
            return f"body {self.name} has no actuators (only sensors)"
        lacks = (("torque", act.torque is None, "no torque actuator (actuators.torque)"),
                 ("wheel_torque", self.wheels is None, "no reaction wheels"),
                 ("dv", act.dv is None, "no impulsive dv capability (actuators.dv)"),
                 ("thrust", act.thrust is None, "no thrusters (actuators.thrust)"))
        for name, lacking, what in lacks:
            if lacking and name in cmd:
                return f"body {self.name} has {what}; it has {self.actuators_text()}"
        if "wheel_torque" in cmd and len(cmd["wheel_torque"]) != self.wheels.n:
            return f"wheel_torque: expected {self.wheels.n} values (one per wheel), got {len(cmd['wheel_torque'])}"
        if "thrust" in cmd and cmd.get("frame", "inertial") == "body" and not self.has_attitude:
            return f"thrust in body axes needs an attitude; body {self.name} has none"
        return None

    def actuators_text(self) -> str:
        """What this body can be commanded to do, with the command field of each and its
        limit, e.g. ``3 reaction wheels (wheel_torque)`` (a refusal names it)."""
        act = self.limits
        have = [] if self.wheels is None else [f"{self.wheels.n} reaction wheel{'s' if self.wheels.n > 1 else ''} (wheel_torque)"]
        if act is not None and act.torque is not None:
            have.append(f"a torque actuator (torque, up to {act.torque:g} N m per axis)")
        if act is not None and act.dv is not None:
            have.append(f"impulsive dv (dv, up to {act.dv:g} m/s per command)")
        if act is not None and act.thrust is not None:
            have.append(f"thrusters (thrust, up to {act.thrust:g} N)")
        return ", ".join(have) or "no actuators"

    def seize_wheel(self, k: int) -> None:
        """Wheel ``k``'s rotor seizes: from now on it turns with the body (relative speed 0).
        Internal, so the total angular momentum is kept: ``(I_kin + J_k a_k a_k^T) w' =
        I_kin w + h_k a_k`` (body axes), then ``h_k = J_k a_k . w'``; the body becomes a
        rigid body of inertia ``I_kin`` plus the locked rotors'."""
        if self.wheels is None or k in self.faults.stuck_wheels:
            return
        a, J = self.wheels.axes, self.wheels.rotor_inertia
        locked = sorted(self.faults.stuck_wheels | {k})
        free = [j for j in range(self.wheels.n) if j not in locked]
        i_eff = self.wheels.kinematic_inertia(self.inertia) + np.einsum("k,ki,kj->ij", J[locked], a[locked], a[locked])
        H = self.wheels.kinematic_inertia(self.inertia) @ self.w + self.h @ a  # body axes, before
        self.w = np.linalg.solve(i_eff, H - self.h[free] @ a[free])
        self.h = self.h.copy()
        self.h[locked] = J[locked] * (a[locked] @ self.w)
        self.faults.stuck_wheels.add(k)
        self._held_locked = HeldInputsBody(i_eff)

    # ------------------------------------------------------------------ motion
    def _thrust_inertial(self, q) -> np.ndarray:
        """The held thrust in inertial axes (N) with the body at attitude ``q``."""
        f = self.thrust * self.faults.efficiency
        if self.thrust_frame == "body" and self.has_attitude:
            f = dcm_from_quat(q).T @ f  # v_inertial = C^T v_body
        return f

    def _turning_thrust(self) -> bool:
        """Whether a body-axis thrust turns with the body in this step."""
        return self.thrust_frame == "body" and self.has_attitude and self.has_orbit and bool(self.thrust.any())

    def step_start(self) -> tuple[np.ndarray, np.ndarray] | None:
        """``(q, w)`` now, before the attitude advances, if :meth:`advance_orbit` needs them
        (a body-axis thrust), else None."""
        return (self.q.copy(), self.w.copy()) if self._turning_thrust() else None

    def advance(self, dt: float) -> None:
        """Move the body from t to t + dt with the held commands (and a dynamic gyro's gimbals)."""
        w_before = None if self.gimbals is None else self.w.copy()
        start = self.step_start()
        if self.has_attitude:
            self.advance_attitude(dt)
        if self.has_orbit:
            self.advance_orbit(dt, start)
        if w_before is not None and dt > 0:
            self.advance_gimbals(w_before, dt)

    def batched(self) -> bool:
        """Whether :meth:`Plant.advance` steps this body's attitude in its compiled batch:
        the held-input step with wheels (none seized) or a torque, what :meth:`advance_attitude`
        does with :func:`step_with_wheels` / :class:`HeldInputsBody` (torque-free bodies keep
        the exact solution)."""
        return self.has_attitude and not self.faults.stuck_wheels and (self.wheels is not None or bool(self.torque.any()))

    def wheel_command_applied(self) -> np.ndarray:
        """The held wheel commands, failed wheels' zeroed (what the motors are asked for)."""
        if not self.faults.failed_wheels:
            return self.wheel_command
        cmd = self.wheel_command.copy()
        for k in self.faults.failed_wheels:
            cmd[k] = 0.0
        return cmd

    def advance_attitude(self, dt: float) -> None:
        """The attitude part of :meth:`advance`, one body."""
        torqued = bool(np.any(self.torque))
        if self.wheels is not None and self.faults.stuck_wheels:
            self._advance_with_locked_wheels(dt, torqued)
        elif self.wheels is not None:
            cmd = self.wheel_command_applied()
            s = step_with_wheels(self.inertia, self.wheels, self.w, self.q, self.h, cmd, dt,
                                 external_torque=ConstantTorque(self.torque) if torqued else None, body=self._held,
                                 max_steps=ENGINE_MAX_STEPS)
            self.w, self.q, self.h = s.w, s.q, s.h
            self.applied_wheel = s.torque
            self.clipped = [int(i) for i in np.flatnonzero(s.clipped & (cmd != 0))]
        elif torqued:
            self.w, self.q = self._held.step_held(self.w, self.q, float(dt), tau=self.torque, max_steps=ENGINE_MAX_STEPS)
        elif self._diagonal:
            w1, q1 = torque_free(np.diag(self.inertia).copy(), self.w, self.q, float(dt))
            self.w, self.q = np.asarray(w1), np.asarray(q1)
        else:
            w1, q1, _ = propagate_attitude(self.inertia, self.w, self.q, float(dt), method="exact", error_estimate=False)
            self.w, self.q = np.asarray(w1), np.asarray(q1)

    def advance_orbit(self, dt: float, start: tuple[np.ndarray, np.ndarray] | None = None) -> None:
        """The orbit part of :meth:`advance`, after the attitude: ``start`` the ``(q, w)`` of
        :meth:`step_start` before it (a body-axis thrust turns with the body from ``q`` to the
        current :attr:`q`, module docstring; without ``start`` it is held at the current one)."""
        q0 = self.q if start is None else start[0]
        f = self._thrust_inertial(q0) if np.any(self.thrust) else None
        if f is not None and np.any(f):
            if start is not None:  # a body-axis thrust (step_start)
                v = _body_turn(q0, start[1], self.q, self.w, float(dt))
                angle = float(np.linalg.norm(v))
                axis, rate = (v / angle, angle / dt) if angle > 0.0 and dt > 0 else ((0.0, 0.0, 1.0), 0.0)
                burn = RotatingThrust(f, self.mass, self.limits.isp, axis, rate)
            else:
                burn = ConstantThrust(f, self.mass, self.limits.isp)
            out = propagate_perturbed(self.r, self.v, float(dt), self.mu, [burn], rtol=1e-13, atol=1e-15,
                                      error_estimate=False)
            r1, v1 = np.asarray(out.r).reshape(3), np.asarray(out.v).reshape(3)
            # the rocket equation per step, ln(m0 / m1) = -log1p(-mdot dt / m0): accurate to
            # round-off where log(m0 / m1) of a ratio near 1 would lose digits
            self.dv_total += float(np.linalg.norm(f)) / self.mass * dt if math.isinf(self.limits.isp) else \
                -self.limits.isp * G0 * math.log1p(-burn.mdot * dt / self.mass)
            self.mass = burn.mass_at(dt)
            self.r, self.v = r1, v1
        else:
            r1, v1 = propagate(self.r, self.v, float(dt), self.mu)
            self.r, self.v = np.asarray(r1), np.asarray(v1)

    def _advance_with_locked_wheels(self, dt: float, torqued: bool) -> None:
        """:meth:`advance`'s attitude with seized wheels: the free wheels as in
        :func:`astrodyn.attitude.wheels.step_with_wheels`, the seized ones part of the body."""
        a, J = self.wheels.axes, self.wheels.rotor_inertia
        free = np.ones(self.wheels.n, dtype=bool)
        free[sorted(self.faults.stuck_wheels)] = False
        cmd = self.wheel_command.copy()
        for k in self.faults.failed_wheels | self.faults.stuck_wheels:
            cmd[k] = 0.0
        g, clipped = self.wheels.saturate(cmd, self.h, self.w, dt)
        g = np.where(free, g, 0.0)
        self.w, self.q = self._held_locked.step_held(self.w, self.q, float(dt), tau=self.torque if torqued else None,
                                                      h0=(self.h * free) @ a, hdot=g @ a, max_steps=ENGINE_MAX_STEPS)
        self.h = np.where(free, self.h + g * dt, J * (a @ self.w))
        self.applied_wheel = g
        self.clipped = [int(i) for i in np.flatnonzero(clipped & (cmd != 0))]

    # ------------------------------------------------------------------ outputs
    def wheel_speeds(self) -> np.ndarray | None:
        return None if self.wheels is None else self.wheels.speeds(self.h, self.w)

    def advance_gimbals(self, w_before: np.ndarray, dt: float) -> None:
        """The dynamic gyro sensor's gimbals over the step just taken, on the body rate
        linear between ``w_before`` and the new :attr:`w` (exact for a constant torque on a
        spherical body; otherwise the rate's curvature within one output step is left out)."""
        slope = (self.w - w_before) / dt
        bases = [lambda t, m=m: (m @ (w_before + slope * t), m @ slope) for m in self.gimbals.mounts]
        self.gimbals.advance(bases, np.array([0.0, dt]))

    def gyro_input(self) -> np.ndarray:
        """What the gyro sensor measures before bias and noise: the body rate, or with
        ``dynamics`` the three rate gyros' indications (body axes x, y, z)."""
        return self.w if self.gimbals is None else self.gimbals.indicated()

    def due(self, s: Sensor, k: int, t: float) -> bool:
        """Whether sensor ``s`` gives a sample at output step ``k`` (time ``t``): its rate, no dropout."""
        return not k % s.every and k >= self.faults.dropouts.get(s.kind, -1)

    def sensor_samples(self, k: int, t: float) -> list[tuple[str, dict]]:
        """``(kind, fields)`` of each sensor due at output step ``k`` (time ``t``), noise from
        ``(scene seed, body index, sensor, k)``; a sensor in a dropout gives nothing.  One
        body's share of :meth:`Plant.sensor_samples` (the same values, bit for bit)."""
        return [(s.kind, {name: x[0] for name, x in _sensor_fields(s.kind, [(self, s)], k).items()})
                for s in self.sensors if self.due(s, k, t)]

    def actuator_state(self) -> dict:
        """The fields of the :class:`astrodyn.messages.ActuatorState` of the step just advanced
        (call after :meth:`advance`; wheel speeds are those at the step's start, passed in
        by :meth:`Plant.step`)."""
        out: dict = {"torque": self.torque}
        if self.wheels is not None:
            out["wheel_torque"] = self.applied_wheel
            out["wheel_speed"] = self._speeds_at_start
            if self.clipped:
                out["clipped"] = self.clipped
        if self.step_dv is not None:
            out["dv"] = self.step_dv
            out["dv_t"] = self.step_dv_t
        if self.has_orbit and self.limits is not None and self.limits.thrust is not None:
            out["thrust"] = self._thrust_applied
        if self.mass is not None:
            out["mass"] = self._mass_at_start
        if self.limits is not None and (self.limits.dv is not None or self.limits.thrust is not None):
            out["dv_total"] = self._dv_total_at_start
        if self.step_applied:
            out["applied"] = list(self.step_applied)
        return out

    def begin_step(self, speeds: np.ndarray | None = None) -> None:
        """Note what the step's actuator state reports about its start, and clear the step's
        records.  ``speeds``: the wheel speeds now, if the caller has them (:meth:`Plant.begin_step`)."""
        self._speeds_at_start = self.wheel_speeds() if speeds is None else speeds
        self._mass_at_start = self.mass
        self.step_dv = None
        self.step_applied = []
        self.step_applied_ids = []

    def finish_commands(self) -> None:
        """After the step's commands: the thrust and dv budget the step starts with (the
        thrust in inertial axes, the one applied at the step's time ``t``: a body-axis thrust
        at the attitude of ``t``, from where it turns with the body through the step)."""
        self._thrust_applied = self._thrust_inertial(self.q) if self.has_orbit else None
        self._dv_total_at_start = self.dv_total


def _hub_torque(tau_ext, h0, hdot):
    """The hub torque of a flexible body with reaction wheels over one step of held inputs
    (:class:`FlexiblePlantBody`): ``torque(s, y) = tau_ext - hdot - w x (h0 + hdot s)``,
    ``s`` s from the step's start, ``w = y[4:7]`` the hub's rates; written out in floats
    (called at every evaluation of the compiled right-hand side)."""
    c0, c1, c2 = (float(x) for x in np.asarray(tau_ext, dtype=np.float64) - hdot)
    a0, a1, a2 = (float(x) for x in h0)
    b0, b1, b2 = (float(x) for x in hdot)

    def torque(s, y):
        w0, w1, w2 = y[4], y[5], y[6]
        h0_, h1_, h2_ = a0 + b0 * s, a1 + b1 * s, a2 + b2 * s
        return (c0 - (w1 * h2_ - w2 * h1_), c1 - (w2 * h0_ - w0 * h2_), c2 - (w0 * h1_ - w1 * h0_))

    return torque


class FlexiblePlantBody(PlantBody):
    """An actuated flexible spacecraft (``attitude.model = "flexible"``): a rigid hub with
    cantilevered Euler-Bernoulli appendages (:mod:`astrodyn.attitude.flexible`, Baruh ch. 11),
    commanded like any actuated body (external ``torque``, reaction wheels; sensors see the
    hub).

    Reaction wheels are axisymmetric rotors whose transverse inertia (and mass) belongs to
    the hub: the spacecraft the equations integrate has the hub inertia ``I_kin = inertia -
    sum_k J_k a_k a_k^T`` (``inertia`` the config's hub tensor with the wheels held fixed,
    as for a rigid body), and the wheels enter through their absolute axial momenta
    ``h_k = J_k (a_k . w + Omega_k)`` (body components ``h_w = sum_k h_k a_k``).  With the
    motor torques ``tau_m = sum_k g_k a_k`` held over a step (after
    :meth:`astrodyn.attitude.wheels.ReactionWheels.saturate`, the rigid path's torque and
    speed limits, failed wheels giving none), ``dh_k/dt = g_k`` gives exactly
    ``h_w(t) = h_w0 + tau_m (t - t0)``, and Lagrange's equation for the hub's rates
    (``dT/dw = H + h_w``, the wheels' energy free of the elastic coordinates) gives the
    hub the torque

        tau_hub = tau_ext - tau_m - w x h_w(t)

    (body components), exact for held inputs: each step is one
    :func:`astrodyn.attitude.flexible.propagate_spacecraft` call (DOP853 at the config's
    ``tolerance``) with that torque, and ``h_k`` then advance by ``g_k dt`` as the rigid
    plant's do.  Without wheels and torque the hub is torque-free.  The inertial angular
    momentum ``C^T (H + h_w)`` is conserved under wheel torques to the integration tolerance.

    A seized wheel (``wheel_stuck``) joins the hub: the internal impulse that stops the
    rotor acts on the hub's rates only (the generalized momenta of the elastic coordinates
    and of the centre's motion are unchanged), so the velocities jump by ``s du`` with
    ``du`` the response of the state rates to a unit hub torque along ``a_k`` (the rates
    are affine in the torque) and ``s = J_k Omega_k / (1 + J_k a_k . dw)``; the hub's
    inertia gains ``J_k a_k a_k^T``.
    """

    def __init__(self, body: Body, mu: float, seed: tuple[int, ...]):
        super().__init__(body, mu, seed)
        a = body.attitude
        self._hub = (a.mass, a.inertia, a.appendages, a.stiffening)
        self.rtol = float(a.tolerance if a.tolerance is not None else DEFAULT_TOLERANCE)
        self.sc = self._spacecraft()
        self.layout = fx.state_layout(self.sc)
        self.y = fx.make_state(self.sc, q=self.q, w=self.w)
        self.q, self.w = self.y[0:4].copy(), self.y[4:7].copy()
        self.nfev = 0

    def _spacecraft(self) -> fx.FlexibleSpacecraft:
        """The model with the hub's inertia without the free wheels' axial moments."""
        mass, inertia, appendages, stiffening = self._hub
        inertia = np.asarray(inertia, dtype=np.float64)
        if self.wheels is not None:
            free = [k for k in range(self.wheels.n) if k not in self.faults.stuck_wheels]
            a, J = self.wheels.axes[free], self.wheels.rotor_inertia[free]
            inertia = inertia - np.einsum("k,ki,kj->ij", J, a, a)
        return flexible_spacecraft(mass, inertia, appendages, stiffening)

    def batched(self) -> bool:
        return False  # its own integration (advance_attitude)

    def _free(self) -> np.ndarray:
        free = np.ones(self.wheels.n, dtype=bool)
        free[sorted(self.faults.stuck_wheels)] = False
        return free

    def advance_attitude(self, dt: float) -> None:
        """Hub, appendages and wheels over ``dt`` s with the held commands (class docstring)."""
        h0 = hdot = np.zeros(3)
        if self.wheels is not None:
            a = self.wheels.axes
            free = self._free()
            cmd = self.wheel_command.copy()
            for k in self.faults.failed_wheels | self.faults.stuck_wheels:
                cmd[k] = 0.0
            g, clipped = self.wheels.saturate(cmd, self.h, self.w, dt)
            g = np.where(free, g, 0.0)
            h0, hdot = (self.h * free) @ a, g @ a
        states, info = fx.propagate_spacecraft(self.sc, self.y, np.array([0.0, float(dt)]),
                                               torque=_hub_torque(self.torque, h0, hdot), rtol=self.rtol,
                                               atol=1e-3 * self.rtol)
        self.nfev += int(info["nfev"])
        self.y = states[-1].copy()
        self.q, self.w = self.y[0:4].copy(), self.y[4:7].copy()
        if self.wheels is not None:
            self.h = np.where(free, self.h + g * dt, self.wheels.rotor_inertia * (a @ self.w))
            self.applied_wheel = g
            self.clipped = [int(i) for i in np.flatnonzero(clipped & (cmd != 0))]

    def seize_wheel(self, k: int) -> None:
        """Wheel ``k``'s rotor seizes and joins the hub (class docstring): the total angular
        momentum, the elastic coordinates' and the centre's momenta kept."""
        if self.wheels is None or k in self.faults.stuck_wheels:
            return
        a, J = self.wheels.axes[k], float(self.wheels.rotor_inertia[k])
        unit = fx.spacecraft_rates(self.sc, 0.0, self.y, lambda t, y: a)
        du = unit - fx.spacecraft_rates(self.sc, 0.0, self.y, None)  # zero but in the velocities' rates
        omega = float(self.h[k] / J - a @ self.w)
        self.y = self.y + (J * omega / (1.0 + J * float(a @ du[4:7]))) * du
        self.faults.stuck_wheels.add(k)
        self.sc = self._spacecraft()
        self.q, self.w = self.y[0:4].copy(), self.y[4:7].copy()
        locked = sorted(self.faults.stuck_wheels)
        self.h = self.h.copy()
        self.h[locked] = self.wheels.rotor_inertia[locked] * (self.wheels.axes[locked] @ self.w)

    def appendage_state(self, t: float, seq: int) -> dict:
        """The fields of the :class:`astrodyn.messages.AppendageState` now (time ``t``): per
        appendage its modal coordinates, their rates and the tip's displacement (m, body),
        as the attitude process publishes them (:func:`astrodyn.scenario.appendages.appendage_message`)."""
        return appendage_message(self.sc, self.y, t, seq)


def plant_body(body: Body, mu: float, seed: tuple[int, ...]) -> PlantBody:
    """The plant's body for config body ``body``: flexible or rigid."""
    flexible = body.attitude is not None and body.attitude.model == "flexible"
    return (FlexiblePlantBody if flexible else PlantBody)(body, mu, seed)


def _sensor_fields(kind: str, due: list[tuple[PlantBody, Sensor]], k: int) -> dict[str, np.ndarray]:
    """The fields of sample ``k`` of the sensors ``due`` (all of one ``kind``; for the
    tachometer, bodies with the same number of wheels), one row per body: every body's
    noise in one call (:mod:`astrodyn.sensors`)."""
    seed = due[0][0].seed[0]
    bodies = [b.index for b, _ in due]
    sigma = np.array([s.sigma for _, s in due])
    if kind == "gyro":
        bias = np.array([s.bias if b.faults.gyro_bias is None else b.faults.gyro_bias for b, s in due], dtype=np.float64)
        return {"w": RateGyro.samples(seed, bodies, k, np.array([b.gyro_input() for b, _ in due]), sigma, bias)}
    if kind == "star_tracker":
        return {"q": StarTracker.samples(seed, bodies, k, np.array([b.q for b, _ in due]), sigma)}
    if kind == "gps":
        r, v = PositionReceiver.samples(seed, bodies, k, np.array([b.r for b, _ in due]), np.array([b.v for b, _ in due]),
                                        sigma, np.array([s.sigma_v for _, s in due]))
        return {"r": r, "v": v}
    return {"speeds": WheelTachometer.samples(seed, bodies, k, np.array([b.wheel_speeds() for b, _ in due]), sigma)}


class Plant:
    """Every actuated body of ``scenario`` (its bodies with actuators or sensors).

    :meth:`sensor_samples` and :meth:`advance` work on all the bodies of a step at once:
    one noise call per kind of sensor, one compiled held-input step for every body whose
    attitude takes it (:meth:`PlantBody.batched`); the others step one by one."""

    def __init__(self, scenario: Scenario):
        if scenario.control is None:
            raise ValueError("scenario: expected a [control] table (a closed-loop scene)")
        self.scenario = scenario
        self.control = scenario.control
        self.rate = scenario.rate
        self.bodies = {b.name: plant_body(b, scenario.central_body.mu, (self.control.seed, index))
                       for index, b in enumerate(scenario.bodies) if b.in_plant}
        self._faults = list(self.control.faults)
        self._attitude = [b for b in self.bodies.values() if b.has_attitude]
        for row, b in enumerate(self._attitude):
            b.row = row
        self._batch = None  # HeldInputsBatch of self._attitude, built at the first step that needs it
        self._sensors = {}  # (kind, wheels) -> [(body, sensor)], in body order
        for b in self.bodies.values():
            for s in b.sensors:
                self._sensors.setdefault((s.kind, b.wheels.n if s.kind == "tachometer" else 0), []).append((b, s))

    def sensor_samples(self, k: int, t: float) -> list[tuple[str, list[str], dict[str, np.ndarray]]]:
        """The sensor samples due at output step ``k`` (time ``t``) of every body, by kind:
        ``(kind, body names, fields)`` with each field an array of one row per body, the rows
        those :meth:`PlantBody.sensor_samples` gives."""
        out = []
        for (kind, _), pairs in self._sensors.items():
            due = [(b, s) for b, s in pairs if b.due(s, k, t)]
            if due:
                out.append((kind, [b.name for b, _ in due], _sensor_fields(kind, due, k)))
        return out

    def begin_step(self) -> None:
        """:meth:`PlantBody.begin_step` of every body, the wheel speeds of all computed at once."""
        wheeled = [b for b in self._attitude if b.wheels is not None]
        speeds = None
        if wheeled:
            batch = self._held_batch()
            rows = [b.row for b in wheeled]
            h = np.ones((len(wheeled), batch.m))
            w = np.array([b.w for b in wheeled])
            for i, b in enumerate(wheeled):
                h[i, :b.wheels.n] = b.h
            speeds = batch.wheel_speeds(rows, w, h)
            for i, b in enumerate(wheeled):
                b.begin_step(speeds[i, :b.wheels.n])
        for b in self.bodies.values():
            if b.wheels is None:
                b.begin_step()

    def _held_batch(self) -> HeldInputsBatch:
        if self._batch is None:
            self._batch = HeldInputsBatch([b.inertia for b in self._attitude], [b.wheels for b in self._attitude])
        return self._batch

    def advance(self, bodies: list[PlantBody], dt: float) -> None:
        """:meth:`PlantBody.advance` of each of ``bodies`` by ``dt`` s; the attitudes that take
        the held-input step (:meth:`PlantBody.batched`) in one compiled call, to round-off
        the same as one by one."""
        before = {id(b): b.w.copy() for b in bodies if b.gimbals is not None}
        start = {id(b): b.step_start() for b in bodies if b.has_orbit}  # before any attitude moves
        group = [b for b in bodies if b.batched()]
        if group:
            self._advance_batch(group, dt)
        batched = set(map(id, group))
        for b in bodies:
            if b.has_attitude and id(b) not in batched:
                b.advance_attitude(dt)
        for b in bodies:
            if b.has_orbit:
                b.advance_orbit(dt, start[id(b)])
        for b in bodies:
            if b.gimbals is not None and dt > 0:
                b.advance_gimbals(before[id(b)], dt)

    def _advance_batch(self, group: list[PlantBody], dt: float) -> None:
        batch = self._held_batch()
        n, m = len(group), batch.m
        w, q = np.array([b.w for b in group]), np.array([b.q for b in group])
        h, cmd = np.zeros((n, m)), np.zeros((n, m))
        for i, b in enumerate(group):
            if b.wheels is not None:
                h[i, :b.wheels.n] = b.h
                cmd[i, :b.wheels.n] = b.wheel_command_applied()
        g, clipped = batch.step([b.row for b in group], w, q, h, cmd, np.array([b.torque for b in group]), dt,
                                max_steps=ENGINE_MAX_STEPS)
        clipped &= cmd != 0
        any_clipped = clipped.any(axis=1).tolist()
        for i, b in enumerate(group):
            b.w, b.q = w[i], q[i]
            if b.wheels is not None:
                nw = b.wheels.n
                b.h, b.applied_wheel = h[i, :nw], g[i, :nw]
                b.clipped = [int(j) for j in np.flatnonzero(clipped[i, :nw])] if any_clipped[i] else []

    def faults_at(self, t: float) -> list[Fault]:
        """Faults whose time is at or before output step ``t`` and have not begun yet:
        applied, returned.  A fault begins at the first output step at or after its ``t``
        (within 1e-9 of a step, for a time computed as ``t_k + dt``); a dropout lasts
        ``duration`` from that step, counted in whole steps (the sensor is silent at the
        steps before ``t_k + duration``), so a re-simulation from the ``fault`` event (at
        ``t_k``) silences the same samples; a dropout never shortens one already on."""
        eps = 1e-9 / self.rate
        begun = [f for f in self._faults if f.t <= t + eps]
        self._faults = [f for f in self._faults if f.t > t + eps]
        k = round(t * self.rate)
        for f in begun:
            b = self.bodies[f.body]
            if f.fault == "gyro_bias":
                b.faults.gyro_bias = np.asarray(f.value, dtype=np.float64)
            elif f.fault == "sensor_dropout":
                span = f.duration * self.rate - 1e-9  # steps; beyond 2**53 (or inf) it is "for good"
                steps = math.ceil(span) if span < 2.0**53 else math.inf
                b.faults.dropouts[f.sensor] = max(b.faults.dropouts.get(f.sensor, -1), k + steps)
            elif f.fault == "wheel_failed":
                b.faults.failed_wheels.add(int(f.wheel))
            elif f.fault == "wheel_stuck":
                b.seize_wheel(int(f.wheel))
            else:
                b.faults.efficiency = float(f.value)
        return begun

    def set_faults(self, faults) -> None:
        """Replace the config's faults (a re-simulation takes the recorded ones)."""
        self._faults = sorted(faults, key=lambda f: f.t)

    def inject(self, fault: Fault) -> None:
        """A fault from outside (the ``fault`` control verb), beginning at the next step."""
        self._faults.append(fault)
        self._faults.sort(key=lambda f: f.t)

    @staticmethod
    def fault_detail(f: Fault) -> str:
        """The detail of the ``fault`` event (JSON)."""
        d = {"body": f.body, "fault": f.fault}
        for key in ("value", "sensor", "wheel"):
            if getattr(f, key) is not None:
                d[key] = getattr(f, key)
        if math.isfinite(f.duration):
            d["duration"] = f.duration
        return json.dumps(d, separators=(",", ":"))
