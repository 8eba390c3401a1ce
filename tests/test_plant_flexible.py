"""A flexible spacecraft in the closed loop (astrodyn.plant.FlexiblePlantBody): a wheel slew
of a hub with two solar arrays (configs/flexible-slew.toml, examples/flexible_slew.py) run
by the real processes, and the plant's flexible body in-process.

The references are independent of the plant:

* angular momentum: with wheels only (no external torque) the inertial angular momentum of
  hub, arrays and wheels, ``C^T (H + sum_k h_k a_k)``, is conserved; ``H`` is the model's
  (:func:`astrodyn.attitude.flexible.spacecraft_momentum` of the recorded hub attitude,
  rates and modal coordinates), ``h_k = J_k (a_k . w + Omega_k)`` from the recorded wheel
  speeds and the config's wheels, the hub's inertia the config's less the wheels' axial
  moments (the free rotors' spin is theirs);
* the residual vibration's frequency: the exact Euler-Bernoulli frequency equation of a
  rigid hub (moment of inertia ``J_h`` about the slew axis, root radius ``r``) carrying two
  clamped beams vibrating antisymmetrically, the hub free to counter-rotate (below,
  :func:`_hub_beam_mode`): the beams' absolute deflection ``Y(x) = A cosh bx + B sinh bx +
  C cos bx + D sin bx`` with ``Y(0) = r theta``, ``Y'(0) = theta``, ``Y''(L) = Y'''(L) = 0``
  and the hub's ``-omega^2 J_h theta = 2 EI (Y''(0) - r Y'''(0))``; with ``J_h`` infinite it
  is the clamped-free beam (``b L = 1.875104``).  The model's two assumed modes per plane
  (Rayleigh-Ritz) bound it from above by about the clamped beam's Ritz error (computed here);
* its decay: the arrays' modal damping is defined on their clamped modes (``c_j = 2 zeta
  omega_j``), so the hub-and-arrays mode decays at ``zeta_eff = (u.C u) / (2 omega u.M u)``
  (first-order perturbation), evaluated with the exact mode above projected on the exact
  clamped-free modes;
* the stiff limit: a rigid body with the composite inertia (hub plus undeformed slender
  beams, ``rho ((r + L)^3 - r^3) / 3`` each about the two axes normal to them).
"""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import brentq, curve_fit

from astrodyn.attitude import flexible as fx
from astrodyn.plant import FlexiblePlantBody, Plant
from astrodyn.recording import load
from astrodyn.recording.stream import open_stream
from astrodyn.scenario import load as load_config, loads
from astrodyn.scenario.appendages import flexible_spacecraft

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _config_text import edited

pytestmark = pytest.mark.network
ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "configs" / "flexible-slew.toml"
CONTROLLER = f"python {ROOT / 'examples' / 'flexible_slew.py'}"
RUN = [sys.executable, "-m", "astrodyn", "run"]
TOPIC = "astrodyn/flexible-slew/sc"
# the config's arrays and hub (checked against the loaded config in _config_numbers)
R, L, RHO, EI, ZETA = 1.0, 5.0, 2.0, 2000.0, 0.005
BETA1L = 1.875104  # the clamped-free beam's first root of cos bL cosh bL = -1


def _run(args: list, timeout: float = 240) -> None:
    proc = subprocess.run([*RUN, *map(str, args), "--quiet"], capture_output=True, text=True, timeout=timeout, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-3000:]


def _payloads(path: Path) -> dict[str, list[bytes]]:
    out: dict[str, list[bytes]] = {}
    with open_stream(path) as s:
        for m in s.messages():
            if m.topic.startswith(TOPIC + "/"):
                out.setdefault(m.topic, []).append(bytes(m.data))
    return out


def _recorded(path: Path) -> dict:
    run = load(path)
    body, act = run.bodies["sc"], run.channels[f"{TOPIC}/actuators"]
    app = body.appendages
    return {"t": np.asarray(body.attitude.t, dtype=np.float64), "q": np.asarray(body.attitude.q, dtype=np.float64),
            "w": np.asarray(body.attitude.w, dtype=np.float64),
            "eta": np.array([np.concatenate(r) for r in app.eta]), "eta_dot": np.array([np.concatenate(r) for r in app.eta_dot]),
            "tip": np.asarray([r for r in app.tip], dtype=np.float64), "app_seq": np.asarray(app.seq),
            "att_seq": np.asarray(body.attitude.seq),
            "wheel_speed": np.stack(act.wheel_speed), "wheel_torque": np.stack(act.wheel_torque)}


@pytest.fixture(scope="module")
def slew(tmp_path_factory):
    """The config's slew, run with its controller, and re-simulated from its commands."""
    tmp = tmp_path_factory.mktemp("flexslew")
    a, c = tmp / "a.mcap", tmp / "c.mcap"
    _run([CONFIG, "--out", a, "--controller", CONTROLLER])
    _run([CONFIG, "--out", c, "--commands", a])
    return a, c


def _hub_beam_matrix(b: float, J_h: float) -> np.ndarray:
    """The homogeneous system in (A, B, C, D, theta) of the hub-and-two-beams mode (module docstring)."""
    ch, sh, c, s = math.cosh(b * L), math.sinh(b * L), math.cos(b * L), math.sin(b * L)
    w2 = EI * b**4 / RHO
    return np.array([[1.0, 0.0, 1.0, 0.0, -R], [0.0, b, 0.0, b, -1.0], [ch, sh, -c, -s, 0.0], [sh, ch, s, -c, 0.0],
                     [2 * EI * b**2, -2 * EI * R * b**3, -2 * EI * b**2, 2 * EI * R * b**3, w2 * J_h]])


def _hub_beam_mode(J_h: float) -> tuple[float, float]:
    """``(omega, zeta_eff)`` of the first antisymmetric mode of a free hub with the two
    clamped beams (module docstring): the root of the determinant, then the damping of the
    exact mode shape through the clamped modes' ``2 zeta omega_j`` (j = 1, 2: the model's)."""

    def det(b):
        m = _hub_beam_matrix(b, J_h)
        return np.linalg.det(m / np.linalg.norm(m, axis=1, keepdims=True))

    grid = np.linspace(0.5, 4.0, 800) / L
    vals = [det(b) for b in grid]
    b = next(brentq(det, grid[i], grid[i + 1], xtol=1e-14) for i in range(len(grid) - 1) if vals[i] * vals[i + 1] < 0)
    omega = math.sqrt(EI / RHO) * b * b
    A, B, C, D, theta = np.linalg.svd(_hub_beam_matrix(b, J_h))[2][-1]
    x = np.linspace(0.0, L, 20001)
    Y = A * np.cosh(b * x) + B * np.sinh(b * x) + C * np.cos(b * x) + D * np.sin(b * x)
    W = Y - (R + x) * theta  # the deflection relative to the hub (the elastic coordinate's field)
    dissipation = 0.0
    for bl in (BETA1L, 4.694091):  # the clamped-free modes
        k = bl / L
        psi = np.cosh(k * x) - np.cos(k * x) - (math.cosh(bl) + math.cos(bl)) / (math.sinh(bl) + math.sin(bl)) * (
            np.sinh(k * x) - np.sin(k * x))
        m = np.trapezoid(RHO * psi**2, x)
        c = np.trapezoid(RHO * psi * W, x) / m
        dissipation += 2 * (2 * ZETA * math.sqrt(EI / RHO) * k * k) * m * c * c  # two beams
    mass = J_h * theta**2 + 2 * np.trapezoid(RHO * Y**2, x)
    return omega, dissipation / (2 * omega * mass)


def _config_numbers():
    scn = load_config(CONFIG)
    body = scn.bodies[0]
    for a in body.attitude.appendages:
        assert (a.length, a.mass_per_length, a.bending_stiffness, a.damping_ratio) == (L, RHO, EI, ZETA)
        assert abs(a.root @ a.axis) == R and a.modes == 2
    return scn, body


def _inertial_momentum(body, rec) -> np.ndarray:
    """``C^T (H + sum_k h_k a_k)`` at every recorded step (module docstring)."""
    wheels = body.actuators.wheels
    axes, J = np.array([wh.axis for wh in wheels]), np.array([wh.inertia for wh in wheels])
    a = body.attitude
    sc = flexible_spacecraft(a.mass, a.inertia - np.einsum("k,ki,kj->ij", J, axes, axes), a.appendages, a.stiffening)
    states = np.array([fx.make_state(sc, q=q, w=w, eta=e, eta_dot=ed)
                       for q, w, e, ed in zip(rec["q"], rec["w"], rec["eta"], rec["eta_dot"])])
    _, H = fx.spacecraft_momentum(sc, states)
    h = J * (rec["w"] @ axes.T + rec["wheel_speed"])
    hw = h @ axes
    return H + _inertial(rec["q"], hw), np.abs(hw).max()


def _inertial(q, v) -> np.ndarray:
    """``C(q)^T v`` (body to inertial components; ``v_body = C(q) v_inertial``, q scalar first):
    ``v (e0^2 - e.e) + 2 (e.v) e + 2 e0 e x v``; rows of ``q`` and ``v`` alike."""
    q, v = np.atleast_2d(q), np.atleast_2d(v)
    e0, e = q[:, :1], q[:, 1:]
    return v * (e0**2 - np.sum(e * e, axis=1, keepdims=True)) + 2 * np.sum(e * v, axis=1, keepdims=True) * e \
        + 2 * e0 * np.cross(e, v)


def _release(rec) -> int:
    """The first step from which the wheels coast (zero motor torque to the end)."""
    busy = np.flatnonzero(np.any(rec["wheel_torque"] != 0, axis=1))
    return int(busy[-1]) + 1


# --------------------------------------------------------------------------- the slew


def test_the_slew_resimulates_bit_for_bit_and_publishes_the_appendages(slew):
    a, c = slew
    pa, pc = _payloads(a), _payloads(c)
    kinds = ("attitude", "appendages", "gyro", "star_tracker", "tachometer", "actuators", "command")
    assert set(pa) == {f"{TOPIC}/{k}" for k in kinds}
    assert pa == pc  # re-simulated from the commands alone: every payload identical
    rec = _recorded(a)
    assert len(rec["t"]) == 1201 and np.array_equal(rec["app_seq"], rec["att_seq"])
    assert b'"model":"actuated"' in pa[f"{TOPIC}/attitude"][0]


def test_the_slew_reaches_the_target_attitude(slew):
    scn, body = _config_numbers()
    rec = _recorded(slew[0])
    target = np.asarray(body.pointing.target, dtype=np.float64)
    err = np.degrees(2 * np.arccos(np.minimum(1.0, np.abs(rec["q"] @ target))))
    assert err[0] == pytest.approx(30.0, abs=1e-9)
    k = _release(rec)
    T = 2 * math.sqrt(math.radians(30) * 686.67 / 0.8)  # the controller's bang-bang profile, ~42.4 s
    assert 0.5 * T < rec["t"][k] - 15.0 < T + 0.2  # the wheels coast 15 s after the profile's end
    # settled within the config's tolerance from the profile's end on, coasting included
    after = err[rec["t"] >= T + 2.0]
    assert after.max() < math.degrees(body.pointing.tolerance), after.max()
    assert err[-1] < 0.05, err[-1]


def test_residual_vibration_rings_at_the_hub_and_arrays_frequency_and_decays_at_its_damping(slew):
    scn, body = _config_numbers()
    rec = _recorded(slew[0])
    J_h = body.attitude.inertia[2, 2] - body.actuators.wheels[2].inertia  # the z wheel coasts: its spin is its own
    omega_ref, zeta_ref = _hub_beam_mode(J_h)
    omega_clamped = BETA1L**2 * math.sqrt(EI / (RHO * L**4))
    assert omega_ref / omega_clamped - 1 > 0.2  # the hub's correction matters (0.90 Hz against 0.71 Hz)
    beam = fx.beam_matrices(2, EI, RHO, L, r=R)
    ritz = beam.omega0[0] / omega_clamped - 1  # the two-mode Rayleigh-Ritz error of the clamped beam (+0.48 %)
    assert 0 < ritz < 0.01
    k = _release(rec)
    t, tip = rec["t"][k:], rec["tip"][k:, 0, 0]
    assert np.allclose(rec["tip"][k:, 1, 0], -tip, rtol=0, atol=1e-9 * np.abs(tip).max())  # antisymmetric
    assert 1e-5 < np.abs(tip[:20]).max() < 1e-3  # visible: tens of micrometres after a 30 deg slew
    # zero crossings by linear interpolation: the frequency over the whole coast
    s = np.flatnonzero(np.sign(tip[:-1]) != np.sign(tip[1:]))
    crossings = t[s] - tip[s] * (t[s + 1] - t[s]) / (tip[s + 1] - tip[s])
    span = crossings[-1] - crossings[0]
    omega_zc = math.pi * (len(crossings) - 1) / span
    dt = t[1] - t[0]
    sampling = dt / span  # one sample's timing error over the record
    omega_d_ref = omega_ref * math.sqrt(1 - zeta_ref**2)
    assert -sampling < omega_zc / omega_d_ref - 1 < ritz + sampling, (omega_zc, omega_d_ref, ritz)
    # a damped sinusoid fitted to the coast: frequency and log decrement
    t0 = t[0]

    def model(tt, amp, sigma, om, ph):
        return amp * np.exp(-sigma * (tt - t0)) * np.cos(om * (tt - t0) + ph)

    p, _ = curve_fit(model, t, tip, p0=[np.abs(tip[:20]).max(), 0.03, omega_zc, 0.0])
    amp, sigma, om, _ = p
    if amp < 0:
        amp = -amp
    residual = tip - model(t, *p)
    assert np.sqrt(np.mean(residual**2)) < 1e-3 * np.abs(tip).max()  # one mode: the higher ones are not seen
    delta = 2 * math.pi * sigma / om  # log decrement per cycle
    zeta = delta / math.sqrt(4 * math.pi**2 + delta**2)
    assert -sampling < om / omega_d_ref - 1 < ritz + sampling
    assert zeta == pytest.approx(zeta_ref, rel=0.03), (zeta, zeta_ref)  # Ritz's 0.5 % in the modes' omega_j, the fit
    assert abs(zeta / ZETA - 1) > 0.1  # the configured ratio is the clamped modes': the coupled mode's differs


# --------------------------------------------------------------------------- momentum


def test_wheels_alone_conserve_the_inertial_angular_momentum_of_hub_arrays_and_wheels(tmp_path):
    undamped = edited(CONFIG.read_text(), **{'duration = "120 s"': 'duration = "70 s"'}).replace(
        "damping_ratio = 0.005", "damping_ratio = 0")
    cfg = tmp_path / "flexible-slew.toml"
    cfg.write_text(undamped)
    out = tmp_path / "m.mcap"
    _run([cfg, "--out", out, "--controller", CONTROLLER])
    scn = loads(undamped)
    body = scn.bodies[0]
    rec = _recorded(out)
    H, hw_max = _inertial_momentum(body, rec)
    assert hw_max > 10.0  # the wheels carried the slew's momentum (N m s)
    drift = np.linalg.norm(H - H[0], axis=1).max()
    # DOP853's local error per output step within rtol (1e-10) of the state: n steps of it
    assert drift < len(H) * body.attitude.tolerance * hw_max, drift
    assert np.linalg.norm(H[0]) == 0.0  # from rest
    # analyze's closed-loop section reports the same conservation (hub + arrays + wheels), not a
    # rigid hub's momentum
    from astrodyn.analysis import analyze

    section = analyze(out, tmp_path / "report")["bodies"]["sc"]["closed loop"]
    assert section["max |H - H0| of body + wheels, inertial (N m s)"] < len(H) * body.attitude.tolerance * hw_max


# --------------------------------------------------------------------------- in-process


def _plant_scene(ei: float | None, stuck: bool = False) -> str:
    """The config's body, 20 s, flexible with arrays of stiffness ``ei`` or (None) rigid with
    the composite inertia; no sensors, no controller."""
    text = CONFIG.read_text()
    text = text.split("[bodies.sensors]")[0].replace('duration = "120 s"', 'duration = "20 s"')
    text = text.replace('controllers = ["slew"]', "controllers = []")
    if stuck:
        text = text.replace("seed = 1\n", 'seed = 1\n[[control.faults]]\nt = "10 s"\nbody = "sc"\nfault = "wheel_stuck"\nwheel = 2\n')
    if ei is not None:
        return text.replace('bending_stiffness = "2000 N m2"', f'bending_stiffness = "{ei!r} N m2"')
    beams = 2 * RHO * ((R + L) ** 3 - R**3) / 3  # two slender beams along y: about x and z
    head, rest = text.split("[[bodies.attitude.appendages]]", 1)
    head = "".join(line for line in head.splitlines(keepends=True) if not line.startswith(("model =", "mass =")))
    head = edited(head, **{'inertia = ["300 kg m2", "250 kg m2", "400 kg m2"]':
                           f"inertia = [{300 + beams!r}, 250.0, {400 + beams!r}]"})
    return head + "[bodies.actuators]" + rest.split("[bodies.actuators]", 1)[1]


def _commanded(text: str, steps: int = 200) -> tuple[np.ndarray, object]:
    plant = Plant(loads(text))
    b = plant.bodies["sc"]
    for k in range(steps):
        t = 0.1 * k
        for f in plant.faults_at(t):
            assert f.fault == "wheel_stuck"
        plant.begin_step()
        b.apply({"t": t, "seq": k, "sender": "x", "wheel_torque": [0.3 * math.sin(0.2 * t), -0.5, 0.8 * math.cos(0.1 * t)]})
        b.finish_commands()
        plant.advance([b], 0.1)
    return b.q.copy(), b


def test_very_stiff_arrays_move_as_the_rigid_body_of_the_same_composite_inertia():
    q_rigid, rigid = _commanded(_plant_scene(None))
    assert not isinstance(rigid, FlexiblePlantBody)
    q_stiff, stiff = _commanded(_plant_scene(2e6))
    q_soft, _ = _commanded(_plant_scene(2000.0))
    assert isinstance(stiff, FlexiblePlantBody)

    def angle(p, q):  # the rotation between two attitudes, accurate when small: |p -+ q| = 2 sin(angle / 4)
        return 4 * math.asin(min(np.linalg.norm(p - q), np.linalg.norm(p + q)) / 2)

    turned = angle(q_rigid, np.array([1.0, 0, 0, 0]))
    assert turned > 0.05  # the commands turned it (rad)
    soft, hard = angle(q_soft, q_rigid), angle(q_stiff, q_rigid)
    assert soft > 1e-6  # the flexible arrays do make a difference
    # quasi-static deflections go as 1 / EI: 1000 times stiffer, ~1000 times closer
    assert hard < 3e-3 * soft and hard < 1e-6 * turned, (hard, soft)


def test_a_seized_wheel_keeps_the_inertial_angular_momentum():
    text = _plant_scene(2000.0, stuck=True).replace("damping_ratio = 0.005", "damping_ratio = 0")
    body = loads(text).bodies[0]
    wheels = body.actuators.wheels
    axes, J = np.array([wh.axis for wh in wheels]), np.array([wh.inertia for wh in wheels])
    a = body.attitude

    def momentum(b, locked):
        free = [k for k in range(3) if k not in locked]
        inertia = a.inertia - np.einsum("k,ki,kj->ij", J[free], axes[free], axes[free])
        sc = flexible_spacecraft(a.mass, inertia, a.appendages, a.stiffening)
        return fx.spacecraft_momentum(sc, b.y)[1] + _inertial(b.q, b.h[free] @ axes[free])[0]

    plant = Plant(loads(text))
    b = plant.bodies["sc"]
    h0 = None
    for k in range(200):
        t = 0.1 * k
        plant.faults_at(t)
        locked = sorted(b.faults.stuck_wheels)
        if h0 is None:
            h0 = momentum(b, locked)
        assert np.linalg.norm(momentum(b, locked) - h0) < 1e-9, (t, locked)
        plant.begin_step()
        b.apply({"t": t, "seq": k, "sender": "x", "wheel_torque": [0.3, -0.5, 0.8]})
        b.finish_commands()
        plant.advance([b], 0.1)
    assert b.faults.stuck_wheels == {2} and b.wheel_speeds()[2] == pytest.approx(0.0, abs=1e-9)
    assert abs(b.wheel_speeds()[0]) > 10  # the free wheels went on
