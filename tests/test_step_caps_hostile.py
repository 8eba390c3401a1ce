"""The held-input steps (:meth:`HeldInputsBody.step_held`, :func:`step_with_wheels`) are
bounded as :func:`propagate_attitude` is (docs/architecture.md, section 2, bad numbers).

Each took a caller's ``dt`` and splitting ``step`` with no cap on the number of internal
steps: a tiny step over a long ``dt`` asked the kernel for ``dt / step`` steps (tables of
that many rows, then as many splitting steps), and a zero, negative or non-finite ``dt`` or
``step`` gave an error from deep inside (``ZeroDivisionError``, ``OverflowError``) or ran
silently.  Now ``max_steps`` (default :data:`MAX_STEPS`, 1e6) is checked before the kernel
runs, with an error naming the step and the steps it would need, and the closed loop's
plant passes the engine's cap (:data:`astrodyn.simulate.ENGINE_MAX_STEPS`), so that no
valid scene changes behaviour.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from _hostile_calls import time_bound
from astrodyn.attitude.integrators import MAX_STEPS, HeldInputsBody
from astrodyn.attitude.torques import ConstantTorque
from astrodyn.attitude.wheels import ReactionWheels, step_with_wheels
from astrodyn.inputs import NonRealInputError

I3 = np.array([1.0, 2.0, 3.0])
W0 = np.array([0.01, 0.02, 0.03])
Q1 = np.array([1.0, 0.0, 0.0, 0.0])
TAU = np.array([1e-3, 0.0, 0.0])
INERTIA = np.diag([2.0, 2.5, 3.0])


def _wheels():
    return ReactionWheels(np.eye(3), [0.01] * 3, [0.1] * 3, [600.0] * 3)


# ---------------------------------------------------------------------------
# HeldInputsBody.step_held


def test_step_held_refuses_a_tiny_step_before_the_kernel_runs():
    # formerly 1e13 steps asked of the kernel (tables of 1e13 rows: a MemoryError, or hours)
    tick = time.perf_counter()
    with time_bound(5.0), pytest.raises(ValueError, match=r"^step: 1e-09 s over dt = 10000 s needs 1e\+13 steps, "
                                                         r"more than max_steps=1000000; .*max_steps=10000000000000 "
                                                         r"to run it anyway"):
        HeldInputsBody(I3).step_held(W0, Q1, 1e4, tau=TAU, step=1e-9)
    assert time.perf_counter() - tick < 2.0


def test_step_held_refuses_rates_that_make_the_default_step_tiny():
    # 1e9 rad/s: the default step (1/60 of the fastest period) is ~1e-10 s, ~1e10 steps for 1 s
    with time_bound(5.0), pytest.raises(ValueError, match=r"^step: \S+ s \(the default: 1/60 of the fastest natural "
                                                         r"period\) over dt = 1 s needs \S+ steps, more than "
                                                         r"max_steps=1000000"):
        HeldInputsBody(I3).step_held([1e9, 0.0, 1e9], Q1, 1.0, tau=TAU)


def test_step_held_max_steps_counts_the_steps_and_can_be_raised():
    body = HeldInputsBody(I3)
    # 1 s in steps of 1/16 s: exactly 16 steps (binary fractions, no rounding in dt / step)
    w, q = body.step_held(W0, Q1, 1.0, tau=TAU, step=0.0625, max_steps=16)
    with pytest.raises(ValueError, match=r"needs 16 steps, more than max_steps=15; .*max_steps=16 to run it anyway"):
        body.step_held(W0, Q1, 1.0, tau=TAU, step=0.0625, max_steps=15)
    # the cap only refuses: below it, the same steps and the same floats as the default's
    for cap in (MAX_STEPS, 10**8):
        w2, q2 = body.step_held(W0, Q1, 1.0, tau=TAU, step=0.0625, max_steps=cap)
        assert np.array_equal(w, w2) and np.array_equal(q, q2)
    for bad in (0, -1, 1.5, True, "100", None):
        with pytest.raises(ValueError, match="^max_steps: expected an int >= 1"):
            body.step_held(W0, Q1, 1.0, tau=TAU, step=0.0625, max_steps=bad)


@pytest.mark.parametrize("dt", [0.0, -0.1, math.nan, math.inf, -math.inf])
def test_step_held_refuses_a_non_positive_or_non_finite_dt(dt):
    with time_bound(5.0), pytest.raises(ValueError, match=r"^dt: expected a finite step > 0 s"):
        HeldInputsBody(I3).step_held(W0, Q1, dt, tau=TAU)


@pytest.mark.parametrize("step", [0.0, -0.01, math.nan, math.inf])
def test_step_held_refuses_a_non_positive_or_non_finite_step(step):
    with time_bound(5.0), pytest.raises(ValueError, match=r"^step: expected a finite splitting step > 0 s"):
        HeldInputsBody(I3).step_held(W0, Q1, 0.1, tau=TAU, step=step)


@pytest.mark.parametrize("field, kwargs", [("dt", {"dt": "0.1"}), ("dt", {"dt": None}), ("dt", {"dt": True}),
                                           ("step", {"dt": 0.1, "step": "0.01"}), ("step", {"dt": 0.1, "step": 1j})])
def test_step_held_takes_real_numbers_only(field, kwargs):
    with pytest.raises(NonRealInputError, match=rf"^step_held: {field}: expected real numbers"):
        HeldInputsBody(I3).step_held(W0, Q1, **kwargs)


# ---------------------------------------------------------------------------
# step_with_wheels


def test_step_with_wheels_refuses_a_tiny_step_before_the_kernel_runs():
    with time_bound(5.0), pytest.raises(ValueError, match=r"^step: 1e-09 s over dt = 10000 s needs 1e\+13 steps, "
                                                         r"more than max_steps=1000000"):
        step_with_wheels(INERTIA, _wheels(), W0, Q1, np.zeros(3), np.zeros(3), 1e4, step=1e-9)


def test_step_with_wheels_passes_max_steps_to_either_path():
    wh, h, cmd = _wheels(), np.zeros(3), np.array([0.01, -0.01, 0.0])
    s = step_with_wheels(INERTIA, wh, W0, Q1, h, cmd, 1.0, step=0.0625, max_steps=16)
    with pytest.raises(ValueError, match=r"needs 16 steps, more than max_steps=15"):
        step_with_wheels(INERTIA, wh, W0, Q1, h, cmd, 1.0, step=0.0625, max_steps=15)
    s2 = step_with_wheels(INERTIA, wh, W0, Q1, h, cmd, 1.0, step=0.0625)
    assert np.array_equal(s.w, s2.w) and np.array_equal(s.q, s2.q) and np.array_equal(s.h, s2.h)
    # an inertial torque takes propagate_attitude: the same cap, its own message
    inertial = ConstantTorque([0.0, 1e-3, 0.0], "inertial")
    with time_bound(5.0), pytest.raises(ValueError, match=r"^step: .* needs 16 steps, more than max_steps=15"):
        step_with_wheels(INERTIA, wh, W0, Q1, h, cmd, 1.0, step=0.0625, external_torque=inertial, max_steps=15)
    with pytest.raises(ValueError, match="^max_steps: expected an int >= 1"):
        step_with_wheels(INERTIA, wh, W0, Q1, h, cmd, 1.0, max_steps=0)


@pytest.mark.parametrize("step", [0.0, -0.01, math.nan, math.inf])
def test_step_with_wheels_refuses_a_non_positive_or_non_finite_step(step):
    with time_bound(5.0), pytest.raises(ValueError, match=r"^step: expected a finite splitting step > 0 s"):
        step_with_wheels(INERTIA, _wheels(), W0, Q1, np.zeros(3), np.zeros(3), 0.1, step=step)


@pytest.mark.parametrize("field, dt, step", [("dt", "0.1", None), ("dt", None, None), ("step", 0.1, "0.01")])
def test_step_with_wheels_takes_real_numbers_only(field, dt, step):
    with pytest.raises(NonRealInputError, match=rf"^step_with_wheels: {field}: expected real numbers"):
        step_with_wheels(INERTIA, _wheels(), W0, Q1, np.zeros(3), np.zeros(3), dt, step=step)


# ---------------------------------------------------------------------------
# HeldInputsBatch.step (the plant's many bodies in one compiled call)


def _batch_inputs(rates):
    """Two bodies of ``INERTIA`` with the wheels of ``_wheels()``, body rates ``rates`` (2, 3)."""
    from astrodyn.attitude.wheels import HeldInputsBatch

    batch = HeldInputsBatch([INERTIA] * 2, [_wheels(), _wheels()])
    w = np.array(rates, dtype=np.float64)
    q, h = np.tile(Q1, (2, 1)), np.full((2, 3), 1e-3)
    return batch, w, q, h, np.full((2, 3), 0.01), np.tile(TAU, (2, 1))


def test_batch_step_refuses_rates_that_make_the_default_step_tiny_and_steps_nothing():
    # formerly ~1e10 splitting steps for the second body's 1 s, in one compiled call: no way out
    batch, w, q, h, cmd, tau = _batch_inputs([W0, [1e9, 0.0, 1e9]])
    before = (w.copy(), q.copy(), h.copy())
    with time_bound(5.0), pytest.raises(ValueError, match=r"^row 1 \(body 1\): step \S+ s \(the default: 1/60 of the "
                                                         r"fastest natural period\) over dt = 1 s needs \S+ steps, "
                                                         r"more than max_steps=1000000"):
        batch.step([0, 1], w, q, h, cmd, tau, 1.0)
    for a, b in zip((w, q, h), before):  # neither body moved: refused before any work
        assert np.array_equal(a, b)


def test_batch_step_counts_steps_as_step_held_does():
    """The batch refuses exactly the steps the one-body path refuses: the splitting step is
    1/60 of the fastest natural period, here 2 pi / (60 * 40) s for a 40 rad/s spin about
    the axis of least inertia (INERTIA with the wheels held: diag(1.99, 2.49, 2.99), so
    |I w| / I_min = 40 too), and 1 s takes ceil(1 / step) = ceil(381.97...) = 382 steps."""
    rates = [[40.0, 0.0, 0.0], W0]
    need = math.ceil(1.0 / (2.0 * math.pi / (60.0 * 40.0)))
    assert need == 382
    for cap in (need - 1, need):
        batch, w, q, h, cmd, tau = _batch_inputs(rates)
        refused_one = refused_batch = False
        try:
            HeldInputsBody(_wheels().kinematic_inertia(INERTIA)).step_held(w[0], q[0], 1.0, tau=TAU, max_steps=cap)
        except ValueError:
            refused_one = True
        try:
            batch.step([0, 1], w, q, h, cmd, tau, 1.0, max_steps=cap)
        except ValueError:
            refused_batch = True
        assert refused_one == refused_batch == (cap < need), cap
    with pytest.raises(ValueError, match="^max_steps: expected an int >= 1"):
        batch.step([0, 1], w, q, h, cmd, tau, 1.0, max_steps=0)


# ---------------------------------------------------------------------------
# the closed loop's plant passes the engine's cap


SCENE = """
[scenario]
name = "caps"
epoch = "2026-03-20T12:00:00 UTC"
duration = "2 s"
rate = "10 Hz"
[control]
seed = 1

[[bodies]]
name = "wheeled"
attitude = { w = [0.01, -0.02, 0.015], inertia = [100, 120, 80] }
[bodies.actuators]
torque = "0.05 N m"
[[bodies.actuators.wheels]]
axis = [1, 0, 0]
inertia = 0.05
max_torque = 0.2
max_speed = 60
[[bodies.actuators.wheels]]
axis = [0, 1, 0]
inertia = 0.05
max_torque = 0.2
max_speed = 60

[[bodies]]
name = "torqued"
attitude = { w = [0.01, 0.0, 0.2], inertia = [[100, 3, 0], [3, 90, 1], [0, 1, 70]] }
[bodies.actuators]
torque = "0.05 N m"
"""


def test_the_plant_passes_the_engine_cap_to_every_held_step(monkeypatch):
    """The plant's own steps are capped at ENGINE_MAX_STEPS (as the engine's splitting calls),
    not at the library default: a scene the plant stepped before is stepped the same."""
    from astrodyn import plant as plant_module
    from astrodyn.plant import Plant
    from astrodyn.scenario import loads
    from astrodyn.simulate import ENGINE_MAX_STEPS

    seen = []
    real_held, real_wheels = HeldInputsBody.step_held, plant_module.step_with_wheels

    def held(self, *args, **kwargs):
        seen.append(("step_held", kwargs.get("max_steps")))
        return real_held(self, *args, **kwargs)

    def wheels(*args, **kwargs):
        seen.append(("step_with_wheels", kwargs.get("max_steps")))
        return real_wheels(*args, **kwargs)

    monkeypatch.setattr(HeldInputsBody, "step_held", held)
    monkeypatch.setattr(plant_module, "step_with_wheels", wheels)
    p = Plant(loads(SCENE))
    wheeled, torqued = p.bodies["wheeled"], p.bodies["torqued"]
    torqued.apply({"t": 0.0, "seq": 0, "sender": "c", "torque": [0.01, 0.0, -0.01]})
    wheeled.apply({"t": 0.0, "seq": 1, "sender": "c", "torque": [0.01, 0.0, 0.0], "wheel_torque": [0.1, -0.1]})
    for b in (wheeled, torqued):
        b.finish_commands()
        b.advance(0.1)  # one body at a time: the one-body paths (PlantBody.advance_attitude)
    wheeled.seize_wheel(0)  # a seized wheel: the locked-wheel path
    wheeled.advance(0.1)
    assert {name for name, _ in seen} == {"step_held", "step_with_wheels"}
    assert seen and all(cap == ENGINE_MAX_STEPS for _, cap in seen), seen


def test_the_plant_passes_the_engine_cap_to_the_batched_step(monkeypatch):
    """Many bodies at once (Plant.advance: HeldInputsBatch.step) get the same cap."""
    from astrodyn.attitude.wheels import HeldInputsBatch
    from astrodyn.plant import Plant
    from astrodyn.scenario import loads
    from astrodyn.simulate import ENGINE_MAX_STEPS

    seen = []
    real = HeldInputsBatch.step

    def step(self, *args, **kwargs):
        seen.append(kwargs.get("max_steps"))
        return real(self, *args, **kwargs)

    monkeypatch.setattr(HeldInputsBatch, "step", step)
    p = Plant(loads(SCENE))
    bodies = list(p.bodies.values())
    for b in bodies:
        b.finish_commands()
    p.advance(bodies, 0.1)
    assert seen == [ENGINE_MAX_STEPS], seen
