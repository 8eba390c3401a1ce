"""The plant's many-body paths against independent references.

* The noise generator (astrodyn.sensors): its Philox4x64-10 blocks are numpy's ``Philox``
  bit generator's (and Random123's known answer), its normals the Box-Muller transform of
  those blocks computed here in numpy; the draws are N(0, 1) (moments within their
  sampling error, Kolmogorov-Smirnov distance below its 1e-6 critical value) and
  uncorrelated across bodies, steps and sensors.
* One compiled held-input step for many bodies (HeldInputsBatch, Plant.advance) against
  the one-body path it replaces (step_with_wheels, HeldInputsBody, PlantBody.advance),
  kept as the reference: the same to round-off, the same saturation and clipping; and the
  total angular momentum of body plus wheels under internal torques conserved to round-off.
* Every body's sensor samples of a step at once (Plant.sensor_samples) against each
  body's own (PlantBody.sensor_samples): bit for bit.
* The message encoders of the plant's hot path (encode_stamped, encode_commands, the
  actuator states) against astrodyn.messages.encode: byte for byte.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from _scenes import fault_table, wheel_tables
from astrodyn import messages
from astrodyn.attitude import ConstantTorque
from astrodyn.attitude.integrators import HeldInputsBody
from astrodyn.attitude.wheels import HeldInputsBatch, ReactionWheels, step_with_wheels
from astrodyn.bench.controller import answer
from astrodyn.plant import Plant
from astrodyn.rotation import dcm_from_quat, quat_from_euler
from astrodyn.scenario import loads
from astrodyn.sensors import STREAMS, RateGyro, philox4x64, standard_normals
from astrodyn.service.plant import encode_commands, encode_stamped

EPS = np.finfo(float).eps


# ------------------------------------------------------------------ noise


def test_philox_blocks_are_numpys_and_random123s():
    # Random123 kat_vectors: philox4x64 10 rounds, counter 0, key 0
    assert [int(x) for x in philox4x64([0, 0, 0, 0], [0, 0])] == [
        0x16554D9ECA36314C, 0xDB20FE9D672D0FDC, 0xD7E772CEE186176B, 0x7E68B68AEC7BA23B]
    rng = np.random.default_rng(7)
    for _ in range(200):
        counter = rng.integers(0, 2**63, 4, dtype=np.uint64)
        key = rng.integers(0, 2**63, 2, dtype=np.uint64) * np.uint64(2) + rng.integers(0, 2, 2, dtype=np.uint64)
        # numpy's Philox steps its counter before the first block
        ref = np.random.Philox(counter=counter, key=key).random_raw(4)
        assert np.array_equal(philox4x64(counter + np.array([1, 0, 0, 0], dtype=np.uint64), key), ref)


def test_normals_are_the_box_muller_transform_of_the_documented_blocks():
    seed, step, bodies = 2**63 - 5, 123_456, np.array([0, 7, 999])
    z = standard_normals(seed, "position", step, bodies, 6)
    for i, b in enumerate(bodies):
        expected = []
        for blk in range(2):
            x = philox4x64([blk, step, b, 0], [seed, STREAMS["position"]])
            for a, c in ((x[0], x[1]), (x[2], x[3])):
                u1 = (float(a >> np.uint64(11)) + 1.0) * 2.0**-53
                u2 = float(c >> np.uint64(11)) * 2.0**-53
                r = math.sqrt(-2.0 * math.log(u1))
                expected += [r * math.cos(2.0 * math.pi * u2), r * math.sin(2.0 * math.pi * u2)]
        assert np.array_equal(z[i], np.array(expected[:6])), (z[i], expected)


def test_normals_are_standard_and_independent():
    n_bodies, n_steps = 2000, 10
    z = np.stack([standard_normals(3, "gyro", k, np.arange(n_bodies), 3) for k in range(n_steps)])  # (steps, bodies, 3)
    x = z.reshape(-1)
    N = x.size
    assert abs(x.mean()) < 5 / math.sqrt(N)
    assert abs(np.mean(x * x) - 1.0) < 5 * math.sqrt(2.0 / N)  # chi-square with N degrees, over N
    # Kolmogorov-Smirnov: the critical distance at significance 1e-6 is sqrt(ln(2e6) / (2N))
    assert stats.kstest(x, "norm").statistic < math.sqrt(math.log(2e6) / (2 * N))
    # uncorrelated: axes, consecutive steps, neighbouring bodies, other sensors of the same body and step
    bound = 5 / math.sqrt(n_bodies * n_steps)
    flat = z.reshape(-1, 3)
    c = np.corrcoef(flat.T)
    assert np.all(np.abs(c[np.triu_indices(3, 1)]) < bound)
    assert abs(np.corrcoef(z[1:].reshape(-1), z[:-1].reshape(-1))[0, 1]) < 5 / math.sqrt(z[1:].size)
    assert abs(np.corrcoef(z[:, 1:].reshape(-1), z[:, :-1].reshape(-1))[0, 1]) < 5 / math.sqrt(z[:, 1:].size)
    other = np.stack([standard_normals(3, "star_tracker", k, np.arange(n_bodies), 3) for k in range(n_steps)])
    assert abs(np.corrcoef(z.reshape(-1), other.reshape(-1))[0, 1]) < 5 / math.sqrt(N)


def test_many_bodies_samples_are_each_bodys_own_bit_for_bit():
    w = np.random.default_rng(1).normal(size=(50, 3))
    bias = np.random.default_rng(2).normal(size=(50, 3)) * 1e-3
    batch = RateGyro.samples(9, np.arange(50), 17, w, 1e-4, bias)
    for i in range(50):
        assert np.array_equal(batch[i], RateGyro(1e-4, bias[i], (9, i)).sample(w[i], 17))
    # the same body in another scene position draws other noise; so does another scene seed
    assert not np.array_equal(RateGyro(1e-4, seed=(9, 1)).sample(np.zeros(3), 0), RateGyro(1e-4, seed=(9, 2)).sample(np.zeros(3), 0))
    assert not np.array_equal(RateGyro(1e-4, seed=(9, 1)).sample(np.zeros(3), 0), RateGyro(1e-4, seed=(8, 1)).sample(np.zeros(3), 0))


# ------------------------------------------------------------------ dynamics


def _unit(a):
    return a / np.linalg.norm(a, axis=1)[:, None]


def _bodies(n, seed=0):
    rng = np.random.default_rng(seed)
    inertias, wheels = [], []
    for i in range(n):
        A = rng.normal(size=(3, 3))
        inertias.append(np.diag(rng.uniform(90, 130, 3)) + (A + A.T if i % 2 else 0.0))
        m = (0, 1, 3, 4)[i % 4]
        wheels.append(None if m == 0 else ReactionWheels(_unit(rng.normal(size=(m, 3))), rng.uniform(0.01, 0.1, m),
                                                         0.2, rng.uniform(50, 600)))
    return inertias, wheels


def _state(wheels, m, rng, rate, speeds):
    """Random body rates (rad/s, ``rate`` per axis), attitudes, and wheel momenta for the
    relative speeds ``speeds(wheels)`` (rad/s), columns padded to ``m``."""
    n = len(wheels)
    w = rng.normal(size=(n, 3)) * rate
    q = np.array([quat_from_euler(rng.normal(size=3), "321") for _ in range(n)])
    h = np.zeros((n, m))
    for i, wh in enumerate(wheels):
        if wh is not None:
            h[i, :wh.n] = wh.absolute_momentum(speeds(wh), w[i])
    return w, q, h


def test_the_batch_step_is_the_one_body_step_to_round_off():
    n = 40
    inertias, wheels = _bodies(n)
    batch = HeldInputsBatch(inertias, wheels)
    rng = np.random.default_rng(5)
    w, q, h = _state(wheels, batch.m, rng, 0.05, lambda wh: rng.uniform(-0.9, 0.9, wh.n) * wh.max_speed)
    cmd = rng.uniform(-0.3, 0.3, (n, batch.m))  # some beyond max_torque, some into the speed limit
    tau = rng.uniform(-0.05, 0.05, (n, 3))
    ref = [(w[i].copy(), q[i].copy(), h[i].copy()) for i in range(n)]
    clipped_any = False
    for _ in range(20):
        g, clipped = batch.step(np.arange(n), w, q, h, cmd, tau, 0.1)
        for i, wh in enumerate(wheels):
            wi, qi, hi = ref[i]
            if wh is None:
                w1, q1 = HeldInputsBody(inertias[i]).step_held(wi, qi, 0.1, tau=tau[i])
                ref[i] = (w1, q1, hi)
                continue
            s = step_with_wheels(inertias[i], wh, wi, qi, hi[:wh.n], cmd[i, :wh.n], 0.1, external_torque=ConstantTorque(tau[i]))
            assert np.array_equal(s.clipped, clipped[i, :wh.n])
            assert np.allclose(s.torque, g[i, :wh.n], rtol=4 * EPS, atol=0)
            clipped_any |= bool(s.clipped.any())
            ref[i] = (s.w, s.q, np.concatenate([s.h, hi[wh.n:]]))
        for i in range(n):
            wi, qi, hi = ref[i]
            # a few roundings per step, accumulated over the steps
            assert np.max(np.abs(w[i] - wi)) < 200 * EPS * np.max(np.abs(wi)), i
            assert np.max(np.abs(q[i] - qi)) < 200 * EPS, i
            assert np.max(np.abs(h[i] - hi), initial=0.0) < 200 * EPS * np.max(np.abs(hi), initial=1.0), i
    assert clipped_any


def test_internal_wheel_torques_in_the_batch_conserve_total_momentum():
    n = 12
    inertias, wheels = _bodies(n, seed=3)
    wheels = [wh if wh is not None else ReactionWheels(np.eye(3), 0.05, 0.2, 600.0) for wh in wheels]
    batch = HeldInputsBatch(inertias, wheels)
    rng = np.random.default_rng(8)
    w, q, h = _state(wheels, batch.m, rng, 0.03, lambda wh: rng.uniform(-100, 100, wh.n))

    def total(i):
        wh = wheels[i]
        return dcm_from_quat(q[i]).T @ (wh.kinematic_inertia(inertias[i]) @ w[i] + wh.momentum(h[i, :wh.n]))

    H0 = [total(i) for i in range(n)]
    worst = 0.0
    for _ in range(1000):
        batch.step(np.arange(n), w, q, h, rng.uniform(-0.3, 0.3, (n, batch.m)), np.zeros((n, 3)), 0.1)
        worst = max(worst, max(np.linalg.norm(total(i) - H0[i]) / np.linalg.norm(H0[i]) for i in range(n)))
    assert worst < 1000 * 10 * EPS, worst  # as tests/test_wheels.py: 10 eps per step, linearly


SCENE_TEMPLATE = """
[scenario]
name = "many"
epoch = "2026-03-20T12:00:00 UTC"
duration = "10 s"
rate = "10 Hz"
[control]
seed = 42
{faults}

[[bodies]]
name = "w3"
orbit = { r = [7000e3, 0, 0], v = [0, 7546, 0] }
attitude = { w = [0.01, -0.02, 0.015], inertia = [100, 120, 80] }
[bodies.actuators]
torque = "0.05 N m"
{wheels3}[bodies.sensors]
gyro = { sigma = 1e-6, bias = [1e-5, 0, 0] }
star_tracker = { sigma = "5 arcsec", rate = "5 Hz" }
gps = { sigma_r = "5 m", sigma_v = "0.05 m/s" }
tachometer = { sigma = 0.1 }

[[bodies]]
name = "w4"
[bodies.attitude]
w = [0.02, 0.01, -0.01]
inertia = [[100, 2, -1], [2, 120, 0.5], [-1, 0.5, 80]]
[bodies.actuators]
{wheels2}[bodies.sensors]
gyro = { sigma = 1e-5 }
tachometer = { sigma = 0.1 }

[[bodies]]
name = "t"
[bodies.attitude]
w = [0.01, 0.0, 0.2]
inertia = [[100, 3, 0], [3, 90, 1], [0, 1, 70]]
[bodies.actuators]
torque = "0.05 N m"
[bodies.sensors]
gyro = { sigma = 1e-6 }

[[bodies]]
name = "free"
[bodies.attitude]
w = [0.01, 0.03, -0.02]
inertia = [100, 120, 80]
[bodies.sensors]
gyro = { sigma = 1e-6 }
"""
FAULTS = [("0.3 s", "w3", "wheel_failed", 1), ("0.5 s", "w4", "wheel_stuck", 0)]
SCENE = SCENE_TEMPLATE.replace(
    "{faults}", "".join(fault_table(t, f, body=b, wheel=k) for t, b, f, k in FAULTS)).replace(
    "{wheels3}", wheel_tables(np.eye(3).tolist(), 0.05, 0.2, 60)).replace(
    "{wheels2}", wheel_tables([[0.5**0.5, 0, 0.5**0.5], [0, 0.5**0.5, 0.5**0.5]], 0.02, 0.1, 300))


def _commands(k, rng):
    out = {"w3": {"torque": list(rng.uniform(-0.1, 0.1, 3)), "wheel_torque": list(rng.uniform(-0.3, 0.3, 3))},
           "w4": {"wheel_torque": list(rng.uniform(-0.2, 0.2, 2))}}
    if k % 3:
        out["t"] = {"torque": list(rng.uniform(-0.05, 0.05, 3))}
    else:
        out["t"] = {"torque": [0.0, 0.0, 0.0]}  # torque-free steps in between
    return out


def test_plant_advance_and_samples_are_each_bodys_own():
    """Two plants of one scene: one stepped by Plant (batched), one body by body; the
    samples of the first, all at once and body by body."""
    many, each = Plant(loads(SCENE)), Plant(loads(SCENE))
    rng_a, rng_b = np.random.default_rng(4), np.random.default_rng(4)
    clipped = False
    for k in range(60):
        t = k * 0.1
        many.faults_at(t), each.faults_at(t)
        many.begin_step()
        for b in each.bodies.values():
            b.begin_step()
        batch_samples = {(name, kind): {f: x[i] for f, x in fields.items()}
                         for kind, names, fields in many.sensor_samples(k, t) for i, name in enumerate(names)}
        # the same plant's bodies one by one: the same state, the same samples
        one_samples = {(name, kind): fields for name, b in many.bodies.items() for kind, fields in b.sensor_samples(k, t)}
        assert batch_samples.keys() == one_samples.keys()
        for key, fields in one_samples.items():
            for f, x in fields.items():
                assert np.array_equal(batch_samples[key][f], x), (k, key)
        for plant, rng in ((many, rng_a), (each, rng_b)):
            for name, fields in _commands(k, rng).items():
                plant.bodies[name].apply({"t": t, "seq": k, "sender": "c", **fields})
            for b in plant.bodies.values():
                b.finish_commands()
        many.advance(list(many.bodies.values()), 0.1)
        for b in each.bodies.values():
            b.advance(0.1)
        for name, b in each.bodies.items():
            m = many.bodies[name]
            assert np.max(np.abs(m.w - b.w)) < 1e-13 * max(1e-3, np.max(np.abs(b.w))), (k, name)
            assert np.max(np.abs(m.q - b.q)) < 1e-13, (k, name)
            if b.wheels is not None:
                assert np.max(np.abs(m.h - b.h)) < 1e-13 * np.max(np.abs(b.h)) + 1e-15, (k, name)
                assert np.allclose(m.applied_wheel, b.applied_wheel, rtol=1e-12, atol=1e-15) and m.clipped == b.clipped, (k, name)
            if b.has_orbit:
                assert np.array_equal(m.r, b.r) and np.array_equal(m.v, b.v)
        clipped |= any(b.clipped for b in many.bodies.values())
    assert many.bodies["w4"].faults.stuck_wheels == {0} and many.bodies["w3"].faults.failed_wheels == {1}
    assert clipped


# ------------------------------------------------------------------ encoders


def test_encode_stamped_is_messages_encode_byte_for_byte():
    rng = np.random.default_rng(0)
    values = np.concatenate([rng.normal(size=(40, 3)) * 10.0 ** rng.integers(-320, 300, (40, 1)),
                             np.array([[0.0, -0.0, 1e16], [1e-5, 5e-324, -1.7976931348623157e308]])])
    t = 12.300000000000002
    seqs = list(range(len(values)))
    extra = [{"applied": ["pd#3"]}, {"clipped": [0, 2], "applied": ["a#1", "b.c-d_e#2"]}, {}, {"applied": ['q"x#1']}] * 11
    for n in (1, 2, 3, len(values)):  # fewer than FEW one by one, the rest in one compiled pass
        for rest in (None, extra[:n]):
            got = encode_stamped(t, seqs[:n], {"w": values[:n], "speeds": values[:n, :2]}, rest)
            assert len(got) == n
            for i, p in enumerate(got):
                msg = {"t": t, "seq": seqs[i], "w": values[i], "speeds": values[i, :2], **(rest[i] if rest else {})}
                assert p == messages.encode(msg), (p, messages.encode(msg))
    bad = values.copy()
    bad[1, 1] = np.nan
    for n in (2, len(values)):
        with pytest.raises(messages.MessageError, match="w"):
            encode_stamped(t, 0, {"w": bad[:n]})


def test_encode_commands_is_messages_encode_byte_for_byte():
    cmds = [{"t": 0.1 * k, "seq": k, "sender": "pd" if k % 2 else "other", "torque": [1e-5 * k, -0.0, 3.0]} for k in range(6)]
    cmds += [{"t": 1.0, "seq": 9, "sender": "pd", "wheel_torque": [0.1, 0.2], "dv": [1.0, 2.0, 3.0]},
             {"t": 2.0, "seq": 10, "sender": "pd", "thrust": [1.0, 0.0, 0.0], "frame": "body"},
             {"t": 3.0, "seq": 11, "sender": "pd"}]
    decoded = [messages.decode(messages.encode(c), "command") for c in cmds]
    assert encode_commands(decoded) == [messages.encode(c) for c in decoded]


def test_the_bench_controllers_answer_is_valid_and_commands_every_gyro():
    samples = [("b0000/gyro", b'{"t":0.5,"seq":5,"w":[0.1,-0.2,1e-07]}'), ("b0000/attitude", b'{"t":0.5}'),
               ("b0001/gyro", b'{"t":0.5,"seq":5,"w":[0.0,0.0,-3.5]}')]
    tick = b'{"t":0.5,"seq":5,"step":5,"samples":{' + b",".join(b'"' + k.encode() + b'":' + p for k, p in samples) + b"}}"
    seqs = {"b0001": 7}
    commands, done = answer(tick, "astrodyn/s", "bench", seqs)
    assert [k for k, _ in commands] == ["astrodyn/s/b0000/command", "astrodyn/s/b0001/command"]
    decoded = [messages.decode(p, "command") for _, p in commands]
    assert decoded[0] == {"t": 0.5, "seq": 0, "sender": "bench", "torque": [-0.2, 0.4, -2e-07]}
    assert decoded[1]["seq"] == 7 and decoded[1]["torque"] == [-0.0, -0.0, 7.0]
    assert messages.decode(done, "done") == {"t": 0.5, "seq": 5, "sender": "bench", "commands": 2}
