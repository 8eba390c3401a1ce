"""Tests of astrodyn.rotation against independent constructions.

References used (none of them calls the code under test to make its expected
value): the elementary matrices of docs/architecture.md written out by hand, the
Euler-parameter DCM of Baruh ch. 7 in its textbook form
``(e0^2 - e.e) I + 2 e e^T - 2 e0 [e x]``, Rodrigues' formula, the matrix
exponential ``expm(-[w x] t)`` (scipy.linalg), a DOP853 integration of the
kinematic ODE, finite differences of ``C(t)``, mpmath at 40 digits for the small
angle series, and scipy's ``Rotation`` (active, scalar-last) built from its own
``from_euler`` / ``from_rotvec`` constructors.

Tolerances: ``EPS`` = 2.2e-16 is one ulp at 1.  Each bound below states its
conditioning argument next to it (about 100x the change a one-ulp input
perturbation causes, unless a tighter few-ulp claim is being tested).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, strategies as st
from scipy.integrate import solve_ivp
from scipy.linalg import expm
from scipy.spatial.transform import Rotation

from astrodyn import rotation as rot
from astrodyn.rotation import (
    EULER_SEQUENCES,
    EulerSingularityError,
    axis_angle_from_quat,
    dcm_from_euler,
    dcm_from_quat,
    elementary_dcm,
    euler_from_dcm,
    euler_from_quat,
    euler_rates,
    euler_singular,
    from_scipy_rotation,
    omega_from_euler_rates,
    omega_from_quat_rate,
    quat_conjugate,
    quat_from_axis_angle,
    quat_from_dcm,
    quat_from_euler,
    quat_from_rotvec,
    quat_from_scalar_last,
    quat_inverse,
    quat_multiply,
    quat_normalize,
    quat_propagate_constant_rate,
    quat_rate,
    quat_rotate,
    quat_to_scalar_last,
    rotvec_from_quat,
    slerp,
    to_scipy_rotation,
)

EPS = np.finfo(np.float64).eps
ASYMMETRIC = [s for s in EULER_SEQUENCES if s[0] != s[2]]
SYMMETRIC = [s for s in EULER_SEQUENCES if s[0] == s[2]]


# ---------------------------------------------------------------------------
# independent hand-written references


def C1(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, s], [0.0, -s, c]])


def C2(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])


def C3(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])


HAND = {1: C1, 2: C2, 3: C3}


def hand_skew(v):
    x, y, z = v
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def baruh_dcm(q):
    """Baruh ch. 7 textbook form, unit q assumed."""
    e0, e = q[0], np.asarray(q[1:])
    return (e0 * e0 - e @ e) * np.eye(3) + 2.0 * np.outer(e, e) - 2.0 * e0 * hand_skew(e)


def rodrigues_frame(n, phi):
    """Frame rotated by phi about unit n: C = cos I + (1 - cos) n n^T - sin [n x]."""
    n = np.asarray(n, float) / np.linalg.norm(n)
    return np.cos(phi) * np.eye(3) + (1 - np.cos(phi)) * np.outer(n, n) - np.sin(phi) * hand_skew(n)


def wrap(a):
    """Angle difference wrapped to (-pi, pi]."""
    return np.angle(np.exp(1j * np.asarray(a)))


def random_quats(n, seed):
    q = np.random.default_rng(seed).normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def random_angles(n, seq, rng):
    a = rng.uniform(-np.pi, np.pi, size=(n, 3))
    if seq[0] == seq[2]:
        a[:, 1] = rng.uniform(0.0, np.pi, n)
    else:
        a[:, 1] = rng.uniform(-np.pi / 2, np.pi / 2, n)
    return a


def align_sign(q, ref):
    return np.where(np.sum(q * ref, axis=-1, keepdims=True) < 0, -q, q)


def rotation_angle_between(qa, qb):
    """Angle of the relative rotation, from the hand DCMs (independent of quat_multiply)."""
    R = np.einsum("...ij,...kj->...ik", np.array([baruh_dcm(x) for x in np.atleast_2d(qa)]), np.array([baruh_dcm(x) for x in np.atleast_2d(qb)]))
    # angle from the skew part (accurate for small angles) and the trace (accurate near pi)
    sk = 0.5 * np.stack([R[:, 1, 2] - R[:, 2, 1], R[:, 2, 0] - R[:, 0, 2], R[:, 0, 1] - R[:, 1, 0]], -1)
    return np.arctan2(np.linalg.norm(sk, axis=-1), 0.5 * (np.trace(R, axis1=1, axis2=2) - 1.0))


# ---------------------------------------------------------------------------
# conventions


@pytest.mark.parametrize("axis", [1, 2, 3])
def test_elementary_rotations_equal_design_md_matrices(axis):
    a = np.array([-2.5, -0.3, 0.0, 0.7, 3.0])
    got = elementary_dcm(axis, a)
    for n, ang in enumerate(a):
        # entries are single cos/sin evaluations: exact equality up to the sign of zero
        np.testing.assert_array_equal(got[n], HAND[axis](ang))
    # Euler angles with a single nonzero angle reduce to the elementary rotation
    for seq in EULER_SEQUENCES:
        if seq[0] == str(axis):
            np.testing.assert_allclose(dcm_from_euler([0.7, 0.0, 0.0], seq), HAND[axis](0.7), rtol=0, atol=2 * EPS)


def test_frame_rotated_about_axis_3_geometrically():
    # Turn a frame by a about inertial z.  Its x axis points at (cos a, sin a, 0) and its
    # y axis at (-sin a, cos a, 0) in inertial components; expressed in the body frame these
    # vectors must be (1, 0, 0) and (0, 1, 0).  An inertial vector along x is seen at -a.
    a = 0.4
    bx = np.array([np.cos(a), np.sin(a), 0.0])
    by = np.array([-np.sin(a), np.cos(a), 0.0])
    q = quat_from_axis_angle([0.0, 0.0, 1.0], a)
    for C in (elementary_dcm(3, a), dcm_from_quat(q), dcm_from_euler([a, 0, 0], "321")):
        np.testing.assert_allclose(C @ bx, [1, 0, 0], rtol=0, atol=2 * EPS)  # few ulp: one 3-term dot product
        np.testing.assert_allclose(C @ by, [0, 1, 0], rtol=0, atol=2 * EPS)
        np.testing.assert_allclose(C @ [1.0, 0, 0], [np.cos(-a), np.sin(-a), 0], rtol=0, atol=2 * EPS)
    np.testing.assert_allclose(quat_rotate(q, bx), [1, 0, 0], rtol=0, atol=4 * EPS)
    # Euler parameters of this rotation (Baruh: e0 = cos(phi/2), e = n sin(phi/2))
    np.testing.assert_allclose(q, [np.cos(a / 2), 0, 0, np.sin(a / 2)], rtol=0, atol=EPS)


def test_dcm_from_quat_matches_baruh_form_and_is_orthonormal():
    q = random_quats(500, 1)
    C = dcm_from_quat(q)
    ref = np.array([baruh_dcm(x) for x in q])
    # both forms are O(1)-conditioned polynomials of q: a few ulp apart
    assert np.abs(C - ref).max() <= 8 * EPS
    CCt = np.einsum("nij,nkj->nik", C, C)
    assert np.abs(CCt - np.eye(3)).max() <= 6 * EPS  # few ulp, as docs/architecture.md asks
    np.testing.assert_allclose(np.linalg.det(C), 1.0, rtol=0, atol=8 * EPS)
    # q and -q (and a scaled q) are the same attitude
    np.testing.assert_array_equal(dcm_from_quat(-q), C)
    assert np.abs(dcm_from_quat(3.7 * q) - C).max() <= 4 * EPS


def test_quat_rotate_and_conjugate_agree_with_dcm():
    rng = np.random.default_rng(2)
    q = random_quats(200, 3)
    v = rng.normal(size=(200, 3))
    C = np.array([baruh_dcm(x) for x in q])
    # relative to |v|: a handful of roundings in each path
    np.testing.assert_allclose(quat_rotate(q, v), np.einsum("nij,nj->ni", C, v), rtol=0, atol=10 * EPS * np.abs(v).max())
    np.testing.assert_allclose(quat_rotate(quat_conjugate(q), v), np.einsum("nji,nj->ni", C, v), rtol=0, atol=10 * EPS * np.abs(v).max())
    np.testing.assert_allclose(dcm_from_quat(quat_conjugate(q)), np.swapaxes(C, 1, 2), rtol=0, atol=8 * EPS)
    # |2q|^2 carries a few roundings (4-term sum of squares + division): 8 ulp relative
    np.testing.assert_allclose(quat_inverse(2.0 * q), quat_conjugate(q) / 2.0, rtol=8 * EPS)
    # broadcasting: one q, many v
    np.testing.assert_allclose(quat_rotate(q[0], v), v @ C[0].T, rtol=0, atol=10 * EPS * np.abs(v).max())


def test_quat_multiply_is_matrix_order_composition():
    qa, qb = random_quats(300, 4), random_quats(300, 5)
    Ca = np.array([baruh_dcm(x) for x in qa])
    Cb = np.array([baruh_dcm(x) for x in qb])
    # product of two O(1) matrices: few ulp
    assert np.abs(dcm_from_quat(quat_multiply(qa, qb)) - Ca @ Cb).max() <= 16 * EPS
    # elementary frame chain: 3-2-1 Euler angles built by composition equal the matrix product
    q = quat_multiply(quat_from_axis_angle([1, 0, 0], 0.3), quat_multiply(quat_from_axis_angle([0, 1, 0], -0.2), quat_from_axis_angle([0, 0, 1], 1.1)))
    np.testing.assert_allclose(dcm_from_quat(q), C1(0.3) @ C2(-0.2) @ C3(1.1), rtol=0, atol=8 * EPS)


# ---------------------------------------------------------------------------
# quaternion <-> DCM


def test_quat_from_dcm_random_and_canonical_sign():
    q = random_quats(2000, 6)
    C = np.array([baruh_dcm(x) for x in q])
    got = quat_from_dcm(C)
    assert np.all(got[:, 0] >= 0)
    # C -> q is O(1)-conditioned with Shepperd's branch choice: a few ulp
    assert np.abs(got - np.where(q[:, :1] < 0, -q, q)).max() <= 8 * EPS
    np.testing.assert_allclose(np.linalg.norm(got, axis=-1), 1.0, rtol=0, atol=2 * EPS)
    # independent: scipy's Rotation (active) of C^T has the same quaternion up to sign
    sp = Rotation.from_matrix(np.swapaxes(C, 1, 2)).as_quat()
    assert np.abs(align_sign(quat_from_scalar_last(sp), got) - got).max() <= 8 * EPS


@pytest.mark.parametrize("e0", [0.0, 1e-12, 1e-8, 1e-4])
def test_quat_from_dcm_near_180_degrees(e0):
    rng = np.random.default_rng(7)
    e = rng.normal(size=(500, 3))
    e *= np.sqrt(1 - e0 * e0) / np.linalg.norm(e, axis=-1, keepdims=True)
    q = np.column_stack([np.full(500, e0), e])
    C = np.array([baruh_dcm(x) for x in q])
    got = quat_from_dcm(C)
    # near 180 deg the large diagonal entry is used: still a few ulp (a trace-based
    # e0 = sqrt(1 + tr)/2 formula would lose everything below sqrt(eps))
    assert np.abs(align_sign(got, q) - q).max() <= 8 * EPS
    assert np.abs(dcm_from_quat(got) - C).max() <= 8 * EPS


# ---------------------------------------------------------------------------
# Euler angles


@pytest.mark.parametrize("seq", EULER_SEQUENCES)
def test_dcm_from_euler_is_the_hand_product(seq):
    rng = np.random.default_rng(8)
    a = rng.uniform(-4, 4, size=(50, 3))
    i, j, k = (int(c) for c in seq)
    ref = np.array([HAND[k](x[2]) @ HAND[j](x[1]) @ HAND[i](x[0]) for x in a])
    assert np.abs(dcm_from_euler(a, seq) - ref).max() <= 4 * EPS
    # quaternion composed from elementary Euler parameters: same matrix
    assert np.abs(dcm_from_quat(quat_from_euler(a, seq)) - ref).max() <= 16 * EPS


def _angle_tolerances(a, seq):
    """100 x the change a one-ulp perturbation of C causes in each angle.

    a2 moves by ~eps; a1 and a3 by ~eps / |cos a2| (asymmetric) or eps / |sin a2|
    (symmetric), the conditioning of the sequence at that attitude.
    """
    cond = np.abs(np.cos(a[:, 1])) if seq[0] != seq[2] else np.abs(np.sin(a[:, 1]))
    t13 = 100 * EPS * (1 + 1 / cond)
    return t13, np.full_like(t13, 100 * EPS), t13


def _check_round_trip(a, seq, C):
    got = euler_from_dcm(C, seq)
    # C -> angles -> C: a few ulp everywhere, gimbal lock included: 8 ulp of round-off in
    # the two 3x3 products, plus (only inside the lock band) the dropped a3, which moves C
    # by at most GIMBAL_LOCK_TOL = 4 ulp
    back = dcm_from_euler(got, seq)
    assert np.abs(back - C).max() <= 8 * EPS + rot.GIMBAL_LOCK_TOL, seq
    # ranges
    assert np.all(np.abs(got[:, [0, 2]]) <= np.pi)
    if seq[0] == seq[2]:
        assert np.all((got[:, 1] >= 0) & (got[:, 1] <= np.pi))
    else:
        assert np.all(np.abs(got[:, 1]) <= np.pi / 2)
    return got


@pytest.mark.parametrize("seq", EULER_SEQUENCES)
def test_euler_round_trip_generic(seq):
    rng = np.random.default_rng(abs(hash(seq)) % 2**32)
    a = random_angles(1000, seq, rng)
    C = dcm_from_quat(quat_from_euler(a, seq))  # entries carry ~eps of noise, as real data would
    got = _check_round_trip(a, seq, C)
    t1, t2, t3 = _angle_tolerances(a, seq)
    assert np.all(np.abs(wrap(got[:, 0] - a[:, 0])) <= t1)
    assert np.all(np.abs(got[:, 1] - a[:, 1]) <= t2)
    assert np.all(np.abs(wrap(got[:, 2] - a[:, 2])) <= t3)
    # random DCMs that were never Euler angles
    C = dcm_from_quat(random_quats(1000, 9))
    _check_round_trip(None, seq, C)
    np.testing.assert_allclose(euler_from_quat(random_quats(10, 9), seq), euler_from_dcm(C[:10], seq), rtol=0, atol=0)


def _locks(seq):
    return [0.0, np.pi] if seq[0] == seq[2] else [np.pi / 2, -np.pi / 2]


@pytest.mark.parametrize("seq", EULER_SEQUENCES)
def test_euler_exact_gimbal_lock(seq):
    rng = np.random.default_rng(10)
    for lock in _locks(seq):
        a = rng.uniform(-np.pi, np.pi, size=(200, 3))
        a[:, 1] = lock
        for C in (dcm_from_euler(a, seq), dcm_from_quat(quat_from_euler(a, seq))):
            got = _check_round_trip(a, seq, C)
            assert np.all(got[:, 2] == 0.0), "gimbal lock must return a3 = 0"
            assert np.all(np.abs(got[:, 1] - lock) <= 4 * EPS)
            # only the combination a1 +- a3 is defined: with a3 = 0, the matrix fixes a1;
            # check it against the hand product with the original angles
            i, j, k = (int(c) for c in seq)
            ref = np.array([HAND[k](x[2]) @ HAND[j](x[1]) @ HAND[i](x[0]) for x in a])
            assert np.abs(dcm_from_euler(got, seq) - ref).max() <= 16 * EPS


@pytest.mark.parametrize("seq", EULER_SEQUENCES)
@pytest.mark.parametrize("delta", [1e-13, 1e-9, 1e-6])
def test_euler_near_gimbal_lock(seq, delta):
    rng = np.random.default_rng(11)
    for lock in _locks(seq):
        inward = -np.sign(lock) if lock != 0 else 1.0  # stay inside the documented range
        a = rng.uniform(-np.pi, np.pi, size=(300, 3))
        a[:, 1] = lock + inward * delta
        C = dcm_from_quat(quat_from_euler(a, seq))
        got = _check_round_trip(a, seq, C)
        t1, t2, t3 = _angle_tolerances(a, seq)
        # 1e-9 from the lock a1, a3 are still resolved (errors up to ~100 eps/1e-9 = 2e-5 allowed)
        assert np.all(np.abs(wrap(got[:, 0] - a[:, 0])) <= t1)
        assert np.all(np.abs(got[:, 1] - a[:, 1]) <= t2)
        assert np.all(np.abs(wrap(got[:, 2] - a[:, 2])) <= t3)


@pytest.mark.slow
@pytest.mark.parametrize("seq", EULER_SEQUENCES)
def test_euler_sweep_towards_lock(seq):
    rng = np.random.default_rng(12)
    for lock in _locks(seq):
        inward = -np.sign(lock) if lock != 0 else 1.0
        for delta in np.logspace(-16, 0, 65):
            a = rng.uniform(-np.pi, np.pi, size=(2000, 3))
            a[:, 1] = lock + inward * delta
            C = dcm_from_quat(quat_from_euler(a, seq))
            got = _check_round_trip(a, seq, C)
            t1, t2, t3 = _angle_tolerances(a, seq)
            assert np.all(np.abs(got[:, 1] - a[:, 1]) <= t2)
            if delta > 1e-14:
                assert np.all(np.abs(wrap(got[:, 0] - a[:, 0])) <= t1)
                assert np.all(np.abs(wrap(got[:, 2] - a[:, 2])) <= t3)


# ---------------------------------------------------------------------------
# axis-angle, rotation vector


def test_axis_angle_against_rodrigues():
    rng = np.random.default_rng(13)
    n = rng.normal(size=(200, 3))
    phi = rng.uniform(-7, 7, 200)
    q = quat_from_axis_angle(n, phi)
    ref = np.array([rodrigues_frame(x, p) for x, p in zip(n, phi)])
    assert np.abs(dcm_from_quat(q) - ref).max() <= 16 * EPS
    axis, angle = axis_angle_from_quat(q)
    assert np.all((angle >= 0) & (angle <= np.pi))
    # same rotation back (axis may flip with the angle): compare matrices
    ref2 = np.array([rodrigues_frame(x, p) for x, p in zip(axis, angle)])
    assert np.abs(ref2 - ref).max() <= 32 * EPS
    np.testing.assert_allclose(np.linalg.norm(axis, axis=-1), 1.0, rtol=0, atol=2 * EPS)
    ax0, an0 = axis_angle_from_quat([1.0, 0, 0, 0])
    np.testing.assert_array_equal(ax0, [1, 0, 0])
    assert an0 == 0.0
    _, api = axis_angle_from_quat([0.0, 0, 1, 0])
    assert api == np.pi


def test_rotvec_against_expm_and_mpmath_series():
    mpmath = pytest.importorskip("mpmath")
    mpmath.mp.dps = 40
    rng = np.random.default_rng(14)
    r = rng.normal(size=(100, 3))
    r *= rng.uniform(0, np.pi, (100, 1)) / np.linalg.norm(r, axis=-1, keepdims=True)
    q = quat_from_rotvec(r)
    ref = np.array([expm(-hand_skew(x)) for x in r])  # C = exp(-[r x])
    assert np.abs(dcm_from_quat(q) - ref).max() <= 32 * EPS  # expm itself is good to ~10 eps
    np.testing.assert_allclose(rotvec_from_quat(q), r, rtol=0, atol=16 * EPS)
    # tiny angles on both sides of the series switch (|r|/2 = 1e-4): full relative accuracy.
    # Reference: q = (cos(|r|/2), r sin(|r|/2)/|r|) at 40 digits.
    u = np.array([0.48, -0.6, 0.64])  # unit
    for mag in [1e-300, 1e-20, 1e-8, 1.999e-4, 2.001e-4, 1e-2]:
        rv = mag * u
        got = quat_from_rotvec(rv)
        m = mpmath.mpf(mag)
        fac = mpmath.sin(m / 2) / m
        want = np.array([float(mpmath.cos(m / 2))] + [float(fac * mpmath.mpf(x) * m) for x in u])
        # each component is a product of a few correctly rounded factors: 4 ulp relative
        np.testing.assert_allclose(got, want, rtol=4 * EPS, atol=0)
        # and back: r recovered to a few ulp relative even at 1e-300
        np.testing.assert_allclose(rotvec_from_quat(got), rv, rtol=8 * EPS, atol=0)
    # q and -q give the same rotation vector, |r| <= pi
    np.testing.assert_allclose(rotvec_from_quat(-q), rotvec_from_quat(q), rtol=0, atol=0)


# ---------------------------------------------------------------------------
# slerp


def test_slerp_endpoints_sign_and_constant_speed():
    q0, q1 = random_quats(50, 15), random_quats(50, 16)
    np.testing.assert_allclose(slerp(q0, q1, 0.0), q0, rtol=0, atol=4 * EPS)
    np.testing.assert_allclose(slerp(q0, q1, 1.0), align_sign(q1, q0), rtol=0, atol=4 * EPS)
    np.testing.assert_allclose(slerp(q0, -q1, 0.37), slerp(q0, q1, 0.37), rtol=0, atol=4 * EPS)
    total = rotation_angle_between(q1, q0)
    assert np.all(total <= np.pi + 1e-12)  # shorter arc
    for tau in (0.1, 0.25, 0.5, 0.9):
        ang0 = rotation_angle_between(slerp(q0, q1, tau), q0)
        ang1 = rotation_angle_between(q1, slerp(q0, q1, tau))
        # angle from a DCM is ~eps/sin conditioned; 1e-12 covers it away from 0 and pi
        np.testing.assert_allclose(ang0, tau * total, rtol=0, atol=1e-12)
        np.testing.assert_allclose(ang1, (1 - tau) * total, rtol=0, atol=1e-12)
    # nearly equal endpoints: no 0/0, result on the arc
    qa = random_quats(1, 17)[0]
    qb = quat_multiply(quat_from_rotvec([1e-17, 0, 0]), qa)
    np.testing.assert_allclose(slerp(qa, qb, 0.5), qa, rtol=0, atol=4 * EPS)
    # broadcasting tau
    assert slerp(q0[0], q1[0], np.linspace(0, 1, 7)).shape == (7, 4)


quat_strategy = st.lists(st.floats(-1, 1, allow_nan=False), min_size=4, max_size=4).filter(lambda v: np.linalg.norm(v) > 0.1).map(lambda v: np.array(v) / np.linalg.norm(v))


@given(quat_strategy, quat_strategy, quat_strategy)
def test_property_composition_associative(a, b, c):
    left = quat_multiply(quat_multiply(a, b), c)
    right = quat_multiply(a, quat_multiply(b, c))
    # two products of unit quaternions, each entry a 4-term sum: a few ulp
    np.testing.assert_allclose(left, right, rtol=0, atol=8 * EPS)


@given(quat_strategy, quat_strategy)
def test_property_inverse(a, b):
    np.testing.assert_allclose(quat_multiply(a, quat_inverse(a)), [1, 0, 0, 0], rtol=0, atol=4 * EPS)
    np.testing.assert_allclose(quat_multiply(quat_inverse(a), a), [1, 0, 0, 0], rtol=0, atol=4 * EPS)
    # (ab)^-1 = b^-1 a^-1
    np.testing.assert_allclose(quat_inverse(quat_multiply(a, b)), quat_multiply(quat_inverse(b), quat_inverse(a)), rtol=0, atol=8 * EPS)


@given(quat_strategy, quat_strategy, st.floats(0, 1))
def test_property_slerp_constant_angular_speed(a, b, tau):
    q = slerp(a, b, tau)
    np.testing.assert_allclose(np.linalg.norm(q), 1.0, rtol=0, atol=4 * EPS)
    total = 2 * np.arctan2(np.linalg.norm(a - align_sign(b, a)), np.linalg.norm(a + align_sign(b, a)))
    part = 2 * np.arctan2(np.linalg.norm(a - align_sign(q, a)), np.linalg.norm(a + align_sign(q, a)))
    # angle in R^4 of unit vectors via atan2 of chord lengths: ~eps absolute
    assert abs(part - tau * total) <= 64 * EPS
    np.testing.assert_allclose(slerp(a, b, 0.0), a, rtol=0, atol=4 * EPS)
    np.testing.assert_allclose(slerp(a, b, 1.0), align_sign(b, a), rtol=0, atol=4 * EPS)


# ---------------------------------------------------------------------------
# kinematics


def test_quat_rate_is_dcm_kinematics_by_finite_differences():
    rng = np.random.default_rng(18)
    q = random_quats(20, 19)
    w = rng.normal(size=(20, 3))
    qd = quat_rate(q, w)
    h = 1e-5
    # central difference of the (independent) textbook DCM along qdot: truncation
    # h^2 |C'''| / 6 ~ 2e-11, round-off eps / h ~ 2e-11; 1e-8 is a safe 100x-ish bound
    fd = np.array([(baruh_dcm(x + h * d) - baruh_dcm(x - h * d)) / (2 * h) for x, d in zip(q, qd)])
    want = -np.einsum("nij,njk->nik", np.array([hand_skew(x) for x in w]), np.array([baruh_dcm(x) for x in q]))
    np.testing.assert_allclose(fd, want, rtol=0, atol=1e-8)
    # the rate keeps |q| (tangent to the unit sphere) and inverts exactly
    np.testing.assert_allclose(np.sum(q * qd, axis=-1), 0.0, rtol=0, atol=4 * EPS * np.abs(w).max())
    np.testing.assert_allclose(omega_from_quat_rate(q, qd), w, rtol=0, atol=8 * EPS * np.abs(w).max())
    np.testing.assert_allclose(omega_from_quat_rate(2.5 * q, quat_rate(2.5 * q, w)), w, rtol=0, atol=16 * EPS * np.abs(w).max())


def test_constant_rate_closed_form_against_dop853_and_expm():
    w = np.array([0.3, -0.5, 0.7])
    q0 = random_quats(1, 20)[0]
    t = np.linspace(0.0, 10.0, 11)
    sol = solve_ivp(lambda _t, y: quat_rate(y, w), (0, 10), q0, method="DOP853", rtol=1e-13, atol=1e-16, t_eval=t)
    assert sol.success
    got = quat_propagate_constant_rate(q0, w, t)
    # DOP853 at rtol 1e-13 on this linear ODE over ~9 rad of rotation: global error ~1e-12
    np.testing.assert_allclose(got, sol.y.T, rtol=0, atol=2e-12)
    # exact reference: C(t) = exp(-[w x] t) C(0), the frame turned by |w| t about w, in
    # Rodrigues' closed form (scipy's expm loses ~100 ulp here to scaling and squaring at
    # 7-9 rad, so it serves only for t <= 1).  Few roundings in O(1) entries: 8 ulp.
    C0 = baruh_dcm(q0)
    for tn, qn in zip(t, got):
        assert np.abs(baruh_dcm(qn) - rodrigues_frame(w, np.linalg.norm(w) * tn) @ C0).max() <= 8 * EPS
    assert np.abs(baruh_dcm(got[1]) - expm(-hand_skew(w) * t[1]) @ C0).max() <= 16 * EPS
    np.testing.assert_allclose(np.linalg.norm(got, axis=-1), 1.0, rtol=0, atol=2 * EPS)
    # same as composing the rotation-vector quaternion (frame turned by w dt)
    np.testing.assert_allclose(got[3], quat_multiply(quat_from_rotvec(w * t[3]), q0), rtol=0, atol=8 * EPS)
    # backward in time undoes forward
    np.testing.assert_allclose(quat_propagate_constant_rate(got[-1], w, -10.0), q0, rtol=0, atol=8 * EPS)


def test_constant_rate_small_steps_and_series_branch():
    mpmath = pytest.importorskip("mpmath")
    mpmath.mp.dps = 40
    q0 = random_quats(1, 21)[0]
    u = np.array([2.0, -3.0, 6.0]) / 7.0
    # |w| dt / 2 on both sides of the 1e-4 series switch, and far below it
    for half in [1e-20, 1e-9, 0.99e-4, 1.01e-4, 0.3]:
        w, dt = 2 * half * u, 1.0
        got = quat_propagate_constant_rate(q0, w, dt)
        # mpmath: q1 = cos(h) q0 + sin(h)/|w| Omega(w) q0 at 40 digits
        h = mpmath.mpf(half)
        c, f = mpmath.cos(h), mpmath.sin(h) / (2 * h)
        e0, e = [mpmath.mpf(x) for x in q0[:1]][0], [mpmath.mpf(x) for x in q0[1:]]
        wm = [mpmath.mpf(x) for x in w]
        om0 = -(e[0] * wm[0] + e[1] * wm[1] + e[2] * wm[2])
        cr = [e[1] * wm[2] - e[2] * wm[1], e[2] * wm[0] - e[0] * wm[2], e[0] * wm[1] - e[1] * wm[0]]
        want = [c * e0 + f * om0] + [c * e[m] + f * (e0 * wm[m] + cr[m]) for m in range(3)]
        # a handful of roundings in an O(1)-conditioned sum: 8 ulp
        np.testing.assert_allclose(got, [float(x) for x in want], rtol=0, atol=8 * EPS)
    # many exact steps = one exact step; |q| stays 1 to 1 ulp (renormalized every step: without
    # it the c, sin(h)/|w| roundings drift |q| by ~3e-13 over these 5000 steps)
    q0 = random_quats(200, 28)
    w = np.random.default_rng(29).normal(size=(200, 3))
    q = q0.copy()
    for _ in range(5000):
        q = quat_propagate_constant_rate(q, w, 0.1)
    np.testing.assert_allclose(np.linalg.norm(q, axis=-1), 1.0, rtol=0, atol=2 * EPS)
    # 5000 steps each with a few-ulp error in the angle: random walk ~ sqrt(5000) * 4 eps ~ 6e-14,
    # systematic at worst 5000 * 4 eps = 4.4e-12; 1e-11 bounds it
    np.testing.assert_allclose(q, quat_propagate_constant_rate(q0, w, 500.0), rtol=0, atol=1e-11)


def test_constant_rate_batched_shapes_and_kernel():
    q = random_quats(6, 22).reshape(2, 3, 4)
    w = np.random.default_rng(23).normal(size=(3, 3))
    dt = np.array([[0.1], [0.2]])
    got = quat_propagate_constant_rate(q, w, dt)
    assert got.shape == (2, 3, 4)
    out = rot._quat_step_kernel(*q[1, 2], *w[2], 0.2)
    np.testing.assert_array_equal(got[1, 2], out)
    assert quat_propagate_constant_rate([1.0, 0, 0, 0], [0, 0, 0], 5.0).tolist() == [1.0, 0.0, 0.0, 0.0]


@pytest.mark.parametrize("seq", EULER_SEQUENCES)
def test_euler_rates_against_finite_differences(seq):
    rng = np.random.default_rng(24)
    a = random_angles(20, seq, rng)
    if seq[0] == seq[2]:
        a[:, 1] = np.clip(a[:, 1], 0.2, np.pi - 0.2)
    else:
        a[:, 1] = np.clip(a[:, 1], -1.3, 1.3)
    rates = rng.normal(size=(20, 3))
    i, j, k = (int(c) for c in seq)

    def hand(x):
        return HAND[k](x[2]) @ HAND[j](x[1]) @ HAND[i](x[0])

    h = 1e-5
    for x, r, w in zip(a, rates, omega_from_euler_rates(a, rates, seq)):
        Cd = (hand(x + h * r) - hand(x - h * r)) / (2 * h)
        W = -Cd @ hand(x).T  # [w x] = -dC/dt C^T
        w_fd = np.array([W[2, 1], W[0, 2], W[1, 0]])
        # central difference: truncation ~h^2 * |rates|^3 ~ 1e-9, round-off eps/h ~ 2e-11
        np.testing.assert_allclose(w, w_fd, rtol=0, atol=1e-8)
    # inverse map, away from the singularity: exact up to round-off amplified by 1/|cos a2|
    # (|cos a2| >= cos 1.3 = 0.27 here, so ~4x): 64 eps
    back = euler_rates(a, omega_from_euler_rates(a, rates, seq), seq)
    np.testing.assert_allclose(back, rates, rtol=0, atol=64 * EPS * np.abs(rates).max())


@pytest.mark.parametrize("seq", EULER_SEQUENCES)
def test_euler_rate_singularities_flagged(seq):
    lock = _locks(seq)[0]
    a = np.array([[0.3, lock, -0.4], [0.3, 1.0, -0.4], [0.1, lock + 1e-10, 0.2]])
    w = np.array([0.1, 0.2, 0.3])
    mask = euler_singular(a, seq)
    np.testing.assert_array_equal(mask, [True, False, True])
    with pytest.raises(EulerSingularityError, match=seq):
        euler_rates(a, w, seq)
    with pytest.raises(ValueError):  # EulerSingularityError is a ValueError
        euler_rates(a[0], w, seq)
    got = euler_rates(a, w, seq, on_singular="nan")
    assert np.all(np.isnan(got[mask])) and np.all(np.isfinite(got[~mask]))
    np.testing.assert_allclose(got[1], euler_rates(a[1], w, seq), rtol=0, atol=0)
    # the forward map is fine at the singular attitude
    assert np.all(np.isfinite(omega_from_euler_rates(a, [0.1, 0.2, 0.3], seq)))


# ---------------------------------------------------------------------------
# edges: scalar-last, scipy


def test_scalar_last_order():
    np.testing.assert_array_equal(quat_to_scalar_last([1.0, 2, 3, 4]), [2, 3, 4, 1])
    np.testing.assert_array_equal(quat_from_scalar_last([2.0, 3, 4, 1]), [1, 2, 3, 4])
    q = random_quats(10, 25)
    np.testing.assert_array_equal(quat_from_scalar_last(quat_to_scalar_last(q)), q)


def test_scipy_conversion_pinned_by_independent_construction():
    # Independent construction: scipy's own active rotation of vectors by +a about z.
    # Applied to the inertial basis it gives the body axes of a frame turned by +a about z,
    # whose DCM (v_body = C v_inertial) is C_3(a) of docs/architecture.md; its matrix is C_3(a)^T.
    a = 0.7
    R = Rotation.from_euler("z", a)
    np.testing.assert_allclose(R.as_matrix(), C3(a).T, rtol=0, atol=2 * EPS)
    q = from_scipy_rotation(R)
    np.testing.assert_allclose(dcm_from_quat(q), C3(a), rtol=0, atol=4 * EPS)
    np.testing.assert_allclose(align_sign(q, np.array([1.0, 0, 0, 0])), [np.cos(a / 2), 0, 0, np.sin(a / 2)], rtol=0, atol=2 * EPS)
    # general case: R.as_matrix() == C.T, R.apply(v_body) = v_inertial
    qs = random_quats(50, 26)
    Rs = to_scipy_rotation(qs)
    C = np.array([baruh_dcm(x) for x in qs])
    np.testing.assert_allclose(Rs.as_matrix(), np.swapaxes(C, 1, 2), rtol=0, atol=8 * EPS)
    v = np.random.default_rng(27).normal(size=(50, 3))
    np.testing.assert_allclose(Rs.apply(quat_rotate(qs, v)), v, rtol=0, atol=16 * EPS * np.abs(v).max())
    # rotation vectors agree with scipy's from_rotvec (active by r == frame turned by r)
    r = np.array([0.2, -1.1, 0.4])
    np.testing.assert_allclose(dcm_from_quat(quat_from_rotvec(r)), Rotation.from_rotvec(r).as_matrix().T, rtol=0, atol=8 * EPS)
    with pytest.raises(ValueError, match="R must be"):
        from_scipy_rotation(np.eye(3))


# ---------------------------------------------------------------------------
# bad input, NaN


def test_bad_input_messages():
    with pytest.raises(ValueError, match=r"q must have shape \(\.\.\., 4\)"):
        dcm_from_quat([1.0, 0, 0])
    with pytest.raises(ValueError, match=r"C must have shape \(\.\.\., 3, 3\)"):
        quat_from_dcm(np.eye(4))
    with pytest.raises(ValueError, match="seq must be one of"):
        dcm_from_euler([0, 0, 0], "122")
    with pytest.raises(ValueError, match="seq must be one of"):
        euler_from_dcm(np.eye(3), "xyz")
    with pytest.raises(ValueError, match="q must be nonzero"):
        dcm_from_quat([0.0, 0, 0, 0])
    with pytest.raises(ValueError, match="q must be nonzero"):
        quat_normalize(np.zeros((2, 4)))
    with pytest.raises(ValueError, match="axis must be a nonzero"):
        quat_from_axis_angle([0, 0, 0], 1.0)
    with pytest.raises(ValueError, match="axis must be 1, 2 or 3"):
        elementary_dcm(4, 0.1)
    with pytest.raises(ValueError, match="w must have shape"):
        quat_rate([1, 0, 0, 0], [1, 2])
    with pytest.raises(ValueError, match="on_singular"):
        euler_rates([0, 1, 0], [0, 0, 0], "321", on_singular="ignore")
    with pytest.raises(ValueError, match="^dcm_from_euler: angles: expected real numbers, got str"):
        dcm_from_euler("abc", "321")


def test_nan_in_nan_out():
    nq = np.array([np.nan, 0, 0, 1.0])
    assert np.isnan(dcm_from_quat(nq)).any() and np.isnan(quat_rotate(nq, [1.0, 2, 3])).all()
    assert np.isnan(quat_from_dcm(np.full((3, 3), np.nan))).all()
    assert np.isnan(euler_from_dcm(np.full((3, 3), np.nan), "313")).all()
    assert np.isnan(quat_propagate_constant_rate(nq, [0.1, 0, 0], 1.0)).all()
    assert np.isnan(quat_propagate_constant_rate([1.0, 0, 0, 0], [np.nan, 0, 0], 1.0)).all()
    assert np.isnan(rotvec_from_quat(nq)).any()
    assert np.isnan(slerp(nq, [1.0, 0, 0, 0], 0.5)).all()
    # a NaN a2 reaches the two rates that depend on it (da2/dt does not involve a2)
    assert np.isnan(euler_rates([0.1, np.nan, 0.2], [0.1, 0.2, 0.3], "321", on_singular="nan")[[0, 2]]).all()
    assert np.isnan(euler_rates([0.1, 0.3, 0.2], [np.nan, 0.2, 0.3], "313")).all()
