"""Hostile input to the public attitude and rotation API (docs/architecture.md, section 2, bad numbers).

Each test is a reproducer of a fault the API probe found: a call that ran without bound, a
silent wrong result, or an error from deep inside numpy that did not name the argument.  The
contract: a non-finite (or empty) output or a one-line ``ValueError`` / ``TypeError`` naming
the argument, and nothing runs without bound.  The formerly unbounded calls run under
:func:`_hostile_calls.time_bound`: the splitting kernel returns to Python between chunks of steps, so an
alarm stops a run that would otherwise take months, and the test fails instead of hanging.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from _hostile_calls import time_bound
from astrodyn.attitude import (
    ConstantTorque,
    Gyrocompass,
    HeavyTop,
    UniformGravityTorque,
    angular_acceleration,
    body_momentum_rates,
    gravity_gradient_torque,
    inertia_tensor,
    polhode,
    propagate_attitude,
    torque_free,
)
from astrodyn.inputs import NonRealInputError
from astrodyn.rotation import (
    attitude_difference,
    axis_angle_from_quat,
    dcm_from_euler,
    dcm_from_quat,
    elementary_dcm,
    euler_from_dcm,
    euler_rates,
    omega_from_euler_rates,
    omega_from_quat_rate,
    quat_from_axis_angle,
    quat_from_dcm,
    quat_multiply,
    quat_normalize,
    quat_propagate_constant_rate,
    quat_rotate,
    rotvec_from_quat,
    slerp,
)

MU = 3.986004418e14
I3 = np.array([1.0, 2.0, 3.0])
W0 = np.array([0.1, 0.2, 0.3])
Q1 = np.array([1.0, 0.0, 0.0, 0.0])
QA = quat_from_axis_angle([0.0, 0.0, 1.0], 0.5)
V = np.array([1.0, 2.0, 3.0])
ZERO_Q = np.zeros(4)


# ---------------------------------------------------------------------------
# report #2 / #10: propagate_attitude's work is bounded before it starts


def test_tiny_step_is_refused_before_the_kernel_starts():
    # formerly 1e13 splitting steps (months); now refused in milliseconds
    tick = time.perf_counter()
    with time_bound(5.0), pytest.raises(ValueError, match=r"^step: 1e-09 s over the 10000 s span of t needs 1e\+13 steps, "
                                                         r"more than max_steps=1000000; .*max_steps="):
        propagate_attitude(I3, W0, Q1, [0.0, 1e4], torque=ConstantTorque([1e-3, 0, 0]), step=1e-9)
    assert time.perf_counter() - tick < 2.0


def test_fast_spin_with_the_default_step_is_refused():
    # 1e6 rad/s: the default step is 3.3e-8 s, 3.0e7 steps for 1 s (15 s of wall time, silently)
    with time_bound(5.0), pytest.raises(ValueError, match=r"^step: 3\.31\d+e-08 s \(the default: .*\) over the 1 s span "
                                                         r"of t needs 3\.01975e\+07 steps, more than max_steps=1000000"):
        propagate_attitude(I3, [1e6, 0.0, 1e6], Q1, [0.0, 1.0], torque=ConstantTorque([1e-3, 0, 0]))


def test_max_steps_counts_the_steps_the_run_takes_and_can_be_raised():
    tq = ConstantTorque([1e-3, 0, 0])
    t = [0.0, 0.5, 1.0]  # 2 x 50 steps of 0.01 s (even for the error estimate)
    w, q, info = propagate_attitude(I3, W0, Q1, t, torque=tq, step=0.01, max_steps=100)
    assert info["n_steps"] == 100
    with pytest.raises(ValueError, match=r"needs 100 steps, more than max_steps=99; .*max_steps=100 to run it"):
        propagate_attitude(I3, W0, Q1, t, torque=tq, step=0.01, max_steps=99)
    # the default applies unless raised, and raising it runs the same steps as before
    w2, q2, _ = propagate_attitude(I3, W0, Q1, t, torque=tq, step=0.01, max_steps=10**7)
    assert np.array_equal(w, w2) and np.array_equal(q, q2)
    for bad in (0, -1, 1.5, True, "100", None):
        with pytest.raises(ValueError, match="^max_steps: expected an int >= 1"):
            propagate_attitude(I3, W0, Q1, t, torque=tq, step=0.01, max_steps=bad)


def test_dop853_refuses_non_positive_tolerances_and_is_bounded():
    tq = ConstantTorque([1e-3, 0, 0])
    for rtol, atol in ((-1.0, 1e-14), (0.0, 1e-14), (1e-9, -1.0), (math.nan, 1e-14)):
        with pytest.raises(ValueError, match="^rtol and atol: expected finite tolerances > 0"):
            propagate_attitude(I3, W0, Q1, [0.0, 10.0], torque=tq, method="dop853", rtol=rtol, atol=atol)
    with time_bound(5.0), pytest.raises(RuntimeError, match="dop853 needs more than max_steps=2 steps"):
        propagate_attitude(I3, W0, Q1, [0.0, 10.0], torque=tq, method="dop853", max_steps=2)


def test_heavy_top_and_gyrocompass_splitting_are_bounded_too():
    top = HeavyTop(mass=0.5, cm_distance=0.04, transverse_inertia=2e-3, axial_inertia=1e-3)
    wt, qt = top.state_from_euler(0.0, 0.5, 0.0, 0.0, 0.0, 60.0)
    with time_bound(5.0), pytest.raises(ValueError, match="more than max_steps=1000000"):
        top.simulate(wt, qt, [1e4], step=1e-9)
    gc = Gyrocompass(gimbal_inertia=0.05, rotor_inertia=0.02, spin=2000.0, latitude=0.5)
    with time_bound(5.0), pytest.raises(ValueError, match="more than max_steps=1000000"):
        gc.simulate(0.1, 0.0, [1e4], step=1e-9)


def test_empty_times_with_a_torque_give_empty_arrays_as_the_exact_path_does():
    tq = ConstantTorque([1e-3, 0, 0])
    for method in ("split4", "dop853"):
        w, q, info = propagate_attitude(I3, W0, Q1, np.zeros(0), torque=tq, method=method)
        assert w.shape == (0, 3) and q.shape == (0, 4), method
    w, q, _ = propagate_attitude(I3, W0, Q1, np.zeros(0))
    assert w.shape == (0, 3) and q.shape == (0, 4)


# ---------------------------------------------------------------------------
# report #3: one quaternion rule (non-unit -> the rotation of q/|q|, zero -> ValueError)


def test_quat_rotate_gives_the_rotation_of_a_non_unit_quaternion_and_keeps_unit_bits():
    np.testing.assert_allclose(quat_rotate(2.0 * QA, V), dcm_from_quat(QA) @ V, rtol=0, atol=4e-15)
    rng = np.random.default_rng(7)
    q = rng.normal(size=(200, 4)) * 10.0 ** rng.uniform(-3, 3, (200, 1))
    v = rng.normal(size=(200, 3))
    ref = np.einsum("nij,nj->ni", dcm_from_quat(q), v)
    np.testing.assert_allclose(quat_rotate(q, v), ref, rtol=0, atol=1e-14)
    assert all(np.array_equal(quat_rotate(q[k], v[k]), quat_rotate(q[k : k + 1], v[k : k + 1])[0]) for k in range(20))
    # unit quaternions: the same bits as the unit-norm expansion C v = v - e0 t + e x t, t = 2 e x v
    qn = quat_normalize(q)
    e0, e = qn[:, :1], qn[:, 1:]
    t = 2.0 * np.cross(e, v)
    assert np.array_equal(quat_rotate(qn, v), v - e0 * t + np.cross(e, t))


@pytest.mark.parametrize(
    "call, name",
    [
        (lambda: quat_rotate(ZERO_Q, V), "q"),
        (lambda: quat_rotate(np.zeros((2, 4)), V), "q"),
        (lambda: attitude_difference(ZERO_Q, QA), "qa"),
        (lambda: attitude_difference(QA, ZERO_Q), "qb"),
        (lambda: axis_angle_from_quat(ZERO_Q), "q"),
        (lambda: rotvec_from_quat(ZERO_Q), "q"),
        (lambda: quat_multiply(ZERO_Q, QA), "q2"),
        (lambda: quat_multiply(QA, ZERO_Q), "q1"),
        (lambda: omega_from_quat_rate(ZERO_Q, [0.0, 1.0, 0.0, 0.0]), "q"),
        (lambda: quat_propagate_constant_rate(ZERO_Q, V, 1.0), "q"),
        (lambda: slerp(ZERO_Q, QA, 0.5), "q0"),
        (lambda: slerp(QA, ZERO_Q, 0.5), "q1"),
    ],
)
def test_zero_quaternions_raise_naming_the_argument(call, name):
    with pytest.raises(ValueError, match=rf"^{name} must be nonzero"):
        call()


def test_non_unit_quaternions_read_as_their_rotation():
    assert attitude_difference(2.0 * QA, QA) == 0.0
    np.testing.assert_allclose(attitude_difference(3.0 * QA, [1.0, 0, 0, 0]), 0.5, rtol=1e-15)
    ax, ang = axis_angle_from_quat(5.0 * QA)
    np.testing.assert_allclose(ang, 0.5, rtol=1e-15)
    np.testing.assert_allclose(rotvec_from_quat(0.1 * QA), [0.0, 0.0, 0.5], rtol=1e-15)
    with pytest.raises(ValueError, match="^qa must be nonzero"):  # named for attitude_difference's own argument
        attitude_difference(ZERO_Q, QA)


@pytest.mark.parametrize("C", [np.zeros((3, 3)), np.diag([1.0, 1.0, -1.0]), 2.0 * np.eye(3), np.eye(3) + 1e-4])
def test_matrices_that_are_not_rotations_are_refused(C):
    with pytest.raises(ValueError, match=r"^C must be a rotation matrix"):
        quat_from_dcm(C)
    with pytest.raises(ValueError, match=r"^C must be a rotation matrix"):
        euler_from_dcm(C, "321")
    with pytest.raises(ValueError, match=r"^C must be a rotation matrix"):
        quat_from_dcm(np.stack([np.eye(3), C]))


def test_nearly_orthogonal_and_non_finite_matrices_still_convert():
    C = dcm_from_euler([0.3, -0.2, 1.1], "321")
    q32 = quat_from_dcm(C.astype(np.float32).astype(np.float64))  # float32 round trip: ~1e-7 off
    assert attitude_difference(q32, quat_from_dcm(C)) < 1e-6
    assert np.isnan(quat_from_dcm(np.full((3, 3), np.nan))).all()
    with np.errstate(invalid="ignore"):
        assert not np.isfinite(euler_from_dcm(np.full((3, 3), np.inf), "313")).all()  # passes through, as before
    # ... and a reflection is refused (det C = -1), not returned as the identity
    with pytest.raises(ValueError, match="det C = -1"):
        quat_from_dcm(np.diag([1.0, 1.0, -1.0]))


# ---------------------------------------------------------------------------
# report #4: physical parameters at every entry point, one inertia checker


def test_gravity_gradient_torque_needs_one_positive_mu():
    with pytest.raises(ValueError, match="^mu: expected a positive gravitational parameter"):
        gravity_gradient_torque([7e6, 1e5, 1e5], I3, -MU)
    with pytest.raises(ValueError, match="^mu: expected a positive"):
        gravity_gradient_torque([7e6, 1e5, 1e5], I3, 0.0)
    with pytest.raises(ValueError, match=r"^gravity_gradient_torque: mu: expected a scalar, got shape \(2,\)"):
        gravity_gradient_torque([7e6, 1e5, 1e5], I3, [MU, MU])
    with pytest.raises(ValueError, match=r"^r_body: expected a \(\.\.\., 3\) position"):
        gravity_gradient_torque([7e6, 1e5, 1e5, 1.0], I3, MU)


@pytest.mark.parametrize("moments, why", [([1.0, -2.0, 0.0], "not positive"), ([0.0, 1.0, 1.0], "not positive"),
                                          ([1.0, 1.0, 10.0], "no rigid body"), ([1.0, np.nan, 2.0], "not finite")])
def test_every_entry_point_refuses_the_same_moments(moments, why):
    calls = [
        lambda: angular_acceleration(moments, W0),
        lambda: body_momentum_rates(moments, [1.0, 1.0, 1.0]),
        lambda: torque_free(moments, W0, Q1, [0.0, 10.0]),
        lambda: torque_free(moments, W0, Q1, 10.0),  # the one-body, one-time compiled path
        lambda: torque_free(np.array([I3, moments]), W0, Q1, [0.0, 10.0]),  # a batch with one bad body
        lambda: propagate_attitude(moments, W0, Q1, [0.0, 10.0]),
    ]
    for call in calls:
        with pytest.raises(ValueError, match=r"^inertia"):
            call()
    if why != "not finite":  # inertia_tensor refuses non-finite tensors before the eigenvalues
        with pytest.raises(ValueError, match=why):
            inertia_tensor(moments)


def _refused(fn, *args):
    try:
        fn(*args)
    except ValueError:
        return True
    return False


def test_torque_free_and_propagate_attitude_agree_on_valid_bodies():
    # random moments: some are a rigid body's, some violate the triangle inequality
    for m in np.random.default_rng(3).uniform(1.0, 5.0, (60, 3)):
        a, b, c = sorted(m)
        assert _refused(torque_free, m, W0, Q1, 1.0) == _refused(propagate_attitude, m, W0, Q1, [1.0]) == (a + b < c), m


def test_uniform_gravity_torque_refuses_a_negative_mass_and_bad_vectors():
    with pytest.raises(ValueError, match="^mass: expected a finite non-negative mass"):
        UniformGravityTorque(-1.0, [0.0, 0.0, 1.0])
    with pytest.raises(ValueError, match=r"^center_of_mass: expected a \(3,\) body vector"):
        UniformGravityTorque(1.0, [0.0, 1.0])
    with pytest.raises(ValueError, match=r"^torque: expected a \(3,\) torque"):
        ConstantTorque([1.0, 2.0])


# ---------------------------------------------------------------------------
# report #6: None, complex, strings, object arrays -> TypeError naming the argument


@pytest.mark.parametrize(
    "call, name",
    [
        (lambda: quat_rotate(QA + 1j, V), "quat_rotate: q"),
        (lambda: quat_rotate(QA, V + 0j), "quat_rotate: v"),
        (lambda: quat_multiply(QA + 1j, QA), "quat_multiply: q2"),
        (lambda: quat_rotate(np.array([1, None, 0, 0], dtype=object), V), "quat_rotate: q"),
        (lambda: quat_rotate(QA, np.array([True, False, False])), "quat_rotate: v"),
        (lambda: quat_rotate(QA, [True, False, False]), "quat_rotate: v"),
        (lambda: dcm_from_quat("abcd"), "dcm_from_quat: q"),
        (lambda: torque_free(I3, W0, Q1, None), "torque_free: t"),
        (lambda: torque_free(I3, W0, Q1, [1 + 1j]), "torque_free: t"),
        (lambda: torque_free(I3, [0.1, None, 0.3], Q1, [1.0]), "torque_free: w0"),
        (lambda: torque_free(I3, W0, Q1, True), "torque_free: t"),
        (lambda: propagate_attitude(I3, W0, Q1, None), "propagate_attitude: t"),
        (lambda: propagate_attitude(I3, W0, Q1 + 0j, [1.0]), "propagate_attitude: q0"),
        (lambda: propagate_attitude(I3, W0, Q1, [1.0], torque=ConstantTorque([1e-3, 0, 0]), step=True),
         "propagate_attitude: step"),
        (lambda: angular_acceleration(I3, [1j, 0, 0]), "angular_acceleration: w"),
        (lambda: quat_propagate_constant_rate(QA, V, 1j), "quat_propagate_constant_rate: dt"),
    ],
)
def test_non_real_input_raises_type_error_naming_the_argument(call, name):
    with pytest.raises(NonRealInputError, match=rf"^{name}: expected real numbers, got "):
        call()


def test_non_real_input_error_is_also_a_value_error():
    # callers that caught the ValueError these inputs used to give keep working
    assert issubclass(NonRealInputError, TypeError) and issubclass(NonRealInputError, ValueError)
    with pytest.raises(ValueError, match="^dcm_from_euler: angles: expected real numbers, got str"):
        dcm_from_euler("abc", "321")
    # real numbers of any kind still convert: ints, unsigned ints, float32, object arrays of ints and floats
    np.testing.assert_array_equal(quat_rotate(np.array([1, 0, 0, 0], dtype=object), [np.uint8(1), 2, np.float32(3)]), V)


# ---------------------------------------------------------------------------
# report #8 / #9: errors that name the argument instead of numpy's internals


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda: torque_free(np.ones((2, 3)) * I3, np.ones((5, 3)) * W0, Q1, [0.0, 1.0]),
         r"torque_free: leading shapes do not broadcast: inertia \(2, 3\), w0 \(5, 3\), q0 \(4,\)"),
        (lambda: quat_multiply(np.ones((2, 4)), np.ones((5, 4))),
         r"quat_multiply: leading shapes do not broadcast: q2 \(2, 4\), q1 \(5, 4\)"),
        (lambda: quat_rotate(np.ones((2, 4)), np.ones((5, 3))),
         r"quat_rotate: leading shapes do not broadcast: q \(2, 4\), v \(5, 3\)"),
        (lambda: slerp(np.ones((2, 4)), np.ones((2, 4)), np.ones(5)),
         r"slerp: leading shapes do not broadcast: q0 \(2, 4\), q1 \(2, 4\), tau \(5,\)"),
        (lambda: euler_rates(np.zeros((2, 3)), np.zeros((5, 3)), "321"),
         r"euler_rates: leading shapes do not broadcast: angles \(2, 3\), w \(5, 3\)"),
        (lambda: omega_from_euler_rates(np.zeros((2, 3)), np.zeros((5, 3)), "321"),
         r"omega_from_euler_rates: leading shapes do not broadcast: angles \(2, 3\), rates \(5, 3\)"),
        (lambda: angular_acceleration(I3, np.zeros((2, 3)), np.zeros((5, 3))),
         r"angular_acceleration: leading shapes do not broadcast: w \(2, 3\), torque \(5, 3\)"),
        (lambda: angular_acceleration(I3, W0, torque=[1.0, 2.0]),
         r"angular_acceleration: torque: expected a scalar or an array of shape"),
    ],
)
def test_errors_name_the_argument(call, message):
    with pytest.raises(ValueError, match="^" + message):
        call()


def test_axes_and_sample_counts_must_be_integers():
    with pytest.raises(ValueError, match=r"^axis must be 1, 2 or 3 \(an int\), got 3\.0"):
        elementary_dcm(3.0, 0.1)
    with pytest.raises(ValueError, match=r"^axis must be 1, 2 or 3 \(an int\), got True"):
        elementary_dcm(True, 0.1)
    with pytest.raises(ValueError, match=r"^n: expected a positive integer number of samples, got 2\.7"):
        polhode(I3, W0, 2.7)  # formerly 2 samples, silently
    np.testing.assert_array_equal(elementary_dcm(np.int64(3), 0.1), elementary_dcm(3, 0.1))
    assert polhode(I3, W0, np.int64(5)).shape == (5, 3)


# ---------------------------------------------------------------------------
# report #10: the two q0 conventions are documented where they apply


def test_q0_conventions_are_documented_in_both_entry_points():
    tf, pa = " ".join(torque_free.__doc__.split()), " ".join(propagate_attitude.__doc__.split())
    assert "Any nonzero ``q0`` is accepted and normalised" in tf and "propagate_attitude" in tf
    assert "Must be a unit quaternion to 1e-6" in pa and "torque_free" in pa
