"""Rotation kinematics: Euler parameters, direction cosines, Euler angles.

Conventions follow H. Baruh, *Analytical Dynamics* (WCB/McGraw-Hill, 1999),
chapter 7, exactly as docs/architecture.md (section 2) fixes them.  Everything here
is a *frame* (passive) description of a body's attitude relative to an
inertial frame:

* **Direction cosine matrix** ``C`` (shape ``(..., 3, 3)``): components of one
  vector in the two frames are related by ``v_body = C @ v_inertial``.  Row
  ``n`` of ``C`` is the body unit vector ``b_n`` in inertial components.  If the
  body turns with angular velocity ``w`` (body components, rad/s),
  ``dC/dt = -[w x] C``.
* **Elementary rotations**: the frame turned by ``a`` about its own axis ``n``,
  ``C_3(a) = [[c, s, 0], [-s, c, 0], [0, 0, 1]]``,
  ``C_1(a) = [[1, 0, 0], [0, c, s], [0, -s, c]]``,
  ``C_2(a) = [[c, 0, -s], [0, 1, 0], [s, 0, c]]``  (``c = cos a, s = sin a``);
  see :func:`elementary_dcm`.
* **Euler parameters** ``q = (e0, e1, e2, e3)``, *scalar first*, shape
  ``(..., 4)``: a frame rotation by ``phi`` about the unit axis ``n`` (the same
  components in both frames) is ``e0 = cos(phi/2)``, ``(e1, e2, e3) =
  n sin(phi/2)``, and ``C(q) = (e0^2 - e.e) I + 2 e e^T - 2 e0 [e x]``
  (Baruh ch. 7, Euler parameters).  ``q`` and ``-q`` give the same ``C``.
* **Euler angles** for the 12 body-axis sequences ``"ijk"`` (``"121"``,
  ``"123"``, ..., ``"323"``): ``C = C_k(a3) @ C_j(a2) @ C_i(a1)``, i.e. turn
  about body axis ``i`` by ``a1``, then about the new axis ``j`` by ``a2``,
  then about the newest axis ``k`` by ``a3``.  Ranges returned by
  :func:`euler_from_dcm`: ``a1, a3`` in ``(-pi, pi]``; ``a2`` in
  ``[-pi/2, pi/2]`` for the asymmetric sequences (``i, j, k`` distinct) and in
  ``[0, pi]`` for the symmetric ones (``i == k``).
* **Composition** (:func:`quat_multiply`) is written in *matrix order*:
  ``quat_multiply(q_CB, q_BA) = q_CA`` with ``C(q_CA) = C(q_CB) @ C(q_BA)``
  (frame A -> B -> C; Shuster 1993's convention).  It equals the Hamilton
  product taken in the reverse order, ``q_BA (x)_Hamilton q_CB``.
* **Kinematics**: ``dq/dt = 0.5 * Omega(w) @ q`` with
  ``Omega(w) = [[0, -w^T], [w, -[w x]]]`` and ``w`` the body angular velocity
  in body components (Baruh ch. 7), i.e. ``de0/dt = -0.5 e.w``,
  ``de/dt = 0.5 (e0 w + e x w)``.

Edges: :func:`quat_to_scalar_last` gives the ``(x, y, z, w)`` order used by
Foxglove and REBOUND; for a Foxglove ``FrameTransform`` with parent = inertial,
child = body it is directly the ``rotation`` field.  :func:`to_scipy_rotation`
returns a ``scipy.spatial.transform.Rotation`` ``R`` with
``R.as_matrix() == C.T`` (scipy is active: ``R.apply(v_body) = v_inertial``).

All functions take float64 arrays with leading (batch) axes and broadcast them;
a single rotation is just the shape ``(4,)`` or ``(3, 3)`` case.  NaN inputs
give NaN outputs; malformed shapes, leading shapes that do not broadcast, unknown
sequences and zero quaternions or axes raise ``ValueError`` naming the argument;
``None``, complex numbers, strings, bools and non-numeric objects raise
:class:`astrodyn.inputs.NonRealInputError` (a ``TypeError``, and a ``ValueError`` for
callers that catch that) naming the function and the argument (the core's one input
rule, :mod:`astrodyn.inputs`).

One rule for quaternions: every function that reads ``q`` as an attitude uses the
rotation of ``q / |q|`` (so any nonzero ``q`` is accepted, as in
:func:`dcm_from_quat`) and raises ``ValueError`` for ``|q| = 0``.  The exceptions
are stated where they apply: the component shuffles (:func:`quat_conjugate`,
:func:`quat_to_scalar_last`, :func:`quat_from_scalar_last`) do not interpret
``q``; :func:`quat_multiply` returns the algebraic product (norm ``|q2| |q1|``,
whose rotation is the composition); :func:`quat_rate` is the linear right-hand side
``0.5 Omega(w) q`` of the given ``q``.  Matrices read as attitudes
(:func:`quat_from_dcm`, :func:`euler_from_dcm`) must be rotations to within
:data:`DCM_ORTHOGONALITY_TOL`.

Example: a body turned by 30 deg about the inertial z axis sees the inertial x
axis at -30 deg in its own frame::

    >>> import numpy as np
    >>> from astrodyn.rotation import quat_from_axis_angle, quat_rotate
    >>> q = quat_from_axis_angle([0, 0, 1], np.radians(30))
    >>> np.round(quat_rotate(q, [1.0, 0, 0]), 6)
    array([ 0.866025, -0.5     ,  0.      ])
"""

from __future__ import annotations

import math

import numpy as np

from astrodyn.inputs import broadcast_named, real_array
from astrodyn.jit import jit

__all__ = [
    "EULER_SEQUENCES",
    "GIMBAL_LOCK_TOL",
    "EULER_RATE_SINGULAR_TOL",
    "EulerSingularityError",
    "DCM_ORTHOGONALITY_TOL",
    "elementary_dcm",
    "skew",
    "quat_normalize",
    "quat_conjugate",
    "quat_inverse",
    "quat_multiply",
    "quat_hamilton_scalar",
    "quat_rotate",
    "attitude_difference",
    "dcm_from_quat",
    "quat_from_dcm",
    "dcm_from_euler",
    "euler_from_dcm",
    "quat_from_euler",
    "euler_from_quat",
    "quat_from_axis_angle",
    "axis_angle_from_quat",
    "quat_from_rotvec",
    "rotvec_from_quat",
    "slerp",
    "quat_rate",
    "omega_from_quat_rate",
    "euler_singular",
    "euler_rates",
    "omega_from_euler_rates",
    "quat_propagate_constant_rate",
    "quat_to_scalar_last",
    "quat_from_scalar_last",
    "to_scipy_rotation",
    "from_scipy_rotation",
]

EULER_SEQUENCES = ("121", "123", "131", "132", "212", "213", "231", "232", "312", "313", "321", "323")

#: :func:`euler_from_dcm` treats the attitude as gimbal locked (and returns
#: ``a3 = 0``) when ``|cos a2|`` (asymmetric sequences) or ``sin a2``
#: (symmetric ones), as read from the matrix, is at most this (4 ulp).  That is
#: the round-off level of the matrix entries: a matrix built at exact lock from
#: float64 angles or Euler parameters reads at most ~3.1 ulp there.  Dropping
#: ``a3`` inside this band moves the reconstructed matrix by at most this much,
#: so the round trip stays at ~10 ulp; anything farther from the lock keeps all
#: three angles (and round-trips to ~3 ulp).
GIMBAL_LOCK_TOL = 4.0 * np.finfo(np.float64).eps

#: Default threshold of :func:`euler_singular` / :func:`euler_rates`: the
#: angle rates are flagged singular when ``|cos a2|`` (asymmetric sequences) or
#: ``|sin a2|`` (symmetric) is below ``sqrt(eps) ~ 1.5e-8``.  There the rates
#: are amplified by more than ``1/sqrt(eps)`` and half of the float64 digits
#: are lost.
EULER_RATE_SINGULAR_TOL = float(np.sqrt(np.finfo(np.float64).eps))


#: :func:`quat_from_dcm` and :func:`euler_from_dcm` refuse a matrix with
#: ``max |C C^T - I| > DCM_ORTHOGONALITY_TOL`` (or ``det C < 0``, a reflection).  The
#: attitude read from a matrix ``d = max |C C^T - I|`` away from orthogonal is uncertain
#: by ``O(d)`` rad (its nearest rotation, Markley's normalized Shepperd answer and the
#: angles read from its columns differ at that order), so ``d`` is the accuracy the
#: answer can claim.  1e-6 admits every float64 construction (``d ~ 1e-15``) and a
#: float32 round trip (``d <= 2 x 2^-24 ~ 1.2e-7``), and refuses zero, scaled, sheared
#: and reflected matrices (``d`` or ``1 - det C`` of order 1), whose "attitude" would be
#: an arbitrary choice.
DCM_ORTHOGONALITY_TOL = 1e-6

# |q|^2 within this (8 ulp) of 1 counts as unit in quat_rotate: q is used as given (no
# division), so normalized quaternions (|q|^2 - 1 ~ 1e-16) give the bits they always gave;
# dividing by such |q|^2 would change the result by less than this (round-off) anyway.
_UNIT_NORM2_TOL = 8.0 * np.finfo(np.float64).eps


class EulerSingularityError(ValueError):
    """Euler angle rates requested at (or too near) the sequence's singular attitude."""


def _as_array(x, name, last_shape, who):
    a = real_array(x, name, who)
    n = len(last_shape)
    if a.ndim < n or a.shape[a.ndim - n :] != tuple(last_shape):
        want = "(..., " + ", ".join(map(str, last_shape)) + ")"
        raise ValueError(f"{who}: {name} must have shape {want}, got {a.shape}")
    return a


def _as_quat(q, who, name="q"):
    return _as_array(q, name, (4,), who)


def _as_vec3(v, name, who):
    return _as_array(v, name, (3,), who)


def _as_dcm(C, who, name="C"):
    return _as_array(C, name, (3, 3), who)


def _norm2_nonzero(q, name):
    """``|q|^2`` over the last axis (keepdims); ``ValueError`` naming ``name`` if any is 0 (NaN passes)."""
    n2 = np.einsum("...i,...i->...", q, q)[..., None]
    if np.any(n2 == 0.0):
        raise ValueError(f"{name} must be nonzero: got a quaternion of norm 0")
    return n2


def _orthogonality(c00, c01, c02, c10, c11, c12, c20, c21, c22, vmax):
    """``(max |C C^T - I|, det C)`` from the nine entries (floats, or arrays with ``vmax`` = np.maximum)."""
    g00 = c00 * c00 + c01 * c01 + c02 * c02 - 1.0
    g11 = c10 * c10 + c11 * c11 + c12 * c12 - 1.0
    g22 = c20 * c20 + c21 * c21 + c22 * c22 - 1.0
    g01 = c00 * c10 + c01 * c11 + c02 * c12
    g02 = c00 * c20 + c01 * c21 + c02 * c22
    g12 = c10 * c20 + c11 * c21 + c12 * c22
    err = vmax(vmax(vmax(abs(g00), abs(g11)), vmax(abs(g22), abs(g01))), vmax(abs(g02), abs(g12)))
    det = c00 * (c11 * c22 - c12 * c21) - c01 * (c10 * c22 - c12 * c20) + c02 * (c10 * c21 - c11 * c20)
    return err, det


def _check_rotation(C, name):
    """``ValueError`` naming ``name`` unless every finite ``C`` (``(..., 3, 3)``) is a rotation
    to :data:`DCM_ORTHOGONALITY_TOL` (non-finite matrices pass: they give NaN)."""
    if C.ndim == 2:
        entries = C.ravel().tolist()
        err, det = _orthogonality(*entries, max)
        bad = all(map(math.isfinite, entries)) and (err > DCM_ORTHOGONALITY_TOL or det < 0.0)
    else:
        flat = C.reshape(C.shape[:-2] + (9,))
        err, det = _orthogonality(*(flat[..., n] for n in range(9)), np.maximum)
        bad = np.isfinite(err) & ((err > DCM_ORTHOGONALITY_TOL) | (det < 0.0))
        if np.any(bad):
            err, det = err[bad].flat[0], det[bad].flat[0]
    if np.any(bad):
        raise ValueError(
            f"{name} must be a rotation matrix (max |C C^T - I| <= {DCM_ORTHOGONALITY_TOL:g} and det C = +1), "
            f"got max |C C^T - I| = {float(err):.3g} and det C = {float(det):.3g}"
        )


def _parse_seq(seq):
    """Zero-based axis indices (i, j, k) of an Euler sequence string."""
    if isinstance(seq, (int, np.integer)):
        seq = str(seq)
    if not isinstance(seq, str) or seq not in EULER_SEQUENCES:
        raise ValueError(f"seq must be one of the 12 body-axis sequences {EULER_SEQUENCES}, got {seq!r}")
    i, j, k = (int(ch) - 1 for ch in seq)
    return i, j, k


def _levi_civita(i, j, k):
    """epsilon_ijk for zero-based indices (+1 cyclic, -1 anticyclic, 0 repeated)."""
    return (i - j) * (j - k) * (k - i) // 2


def _sinc(x):
    """sin(x)/x, accurate for every real x (series below 1e-4, where the h^6 term is < 1e-25)."""
    x = np.asarray(x, dtype=np.float64)
    small = np.abs(x) < 1e-4
    xs = np.where(small, 1.0, x)
    x2 = x * x
    return np.where(small, 1.0 - x2 / 6.0 * (1.0 - x2 / 20.0), np.sin(xs) / xs)


# --------------------------------------------------------------------------
# basic building blocks


def skew(v):
    """Cross-product matrix ``[v x]`` with ``[v x] @ u = v x u``; shape ``(..., 3, 3)``."""
    v = _as_vec3(v, "v", "skew")
    z = np.zeros_like(v[..., 0])
    x, y, w = v[..., 0], v[..., 1], v[..., 2]
    return np.stack(
        [np.stack([z, -w, y], -1), np.stack([w, z, -x], -1), np.stack([-y, x, z], -1)],
        axis=-2,
    )


def elementary_dcm(axis, angle):
    """Elementary frame rotation ``C_axis(angle)`` (docs/architecture.md, section 2; Baruh ch. 7).

    ``axis`` is the int 1, 2 or 3; ``angle`` in rad, any shape; returns ``(..., 3, 3)``.
    ``C_3(a) = [[c, s, 0], [-s, c, 0], [0, 0, 1]]`` and cyclically
    ``C_1(a) = [[1, 0, 0], [0, c, s], [0, -s, c]]``,
    ``C_2(a) = [[c, 0, -s], [0, 1, 0], [s, 0, c]]``: components in the frame
    turned by ``a`` about its axis ``axis``.
    """
    if isinstance(axis, (bool, np.bool_)) or not isinstance(axis, (int, np.integer)) or axis not in (1, 2, 3):
        raise ValueError(f"axis must be 1, 2 or 3 (an int), got {axis!r}")
    return _elementary0(int(axis) - 1, real_array(angle, "angle", "elementary_dcm"))


def _elementary0(n, a):
    """C_{n+1}(a) for a zero-based axis index n: [p, q] = c delta_pq + s eps_npq (+ 1 on n, n)."""
    c, s = np.cos(a), np.sin(a)
    out = np.zeros(np.shape(a) + (3, 3))
    u, v = (n + 1) % 3, (n + 2) % 3
    out[..., n, n] = 1.0
    out[..., u, u] = c
    out[..., v, v] = c
    out[..., u, v] = s
    out[..., v, u] = -s
    return out


def _cross(a, b):
    """``a x b`` over the last axis (explicit components: ~6x faster than ``np.cross`` on batches)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    out[..., 0] = a1 * b2 - a2 * b1
    out[..., 1] = a2 * b0 - a0 * b2
    out[..., 2] = a0 * b1 - a1 * b0
    return out


def _transpose(M):
    return np.swapaxes(M, -1, -2)


# --------------------------------------------------------------------------
# Euler parameters


def quat_normalize(q):
    """``q / |q|`` (shape ``(..., 4)``); a zero quaternion raises ``ValueError``."""
    return _normalized(_as_quat(q, "quat_normalize"), "q")


def _normalized(q, name):
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    if np.any(n == 0.0):
        raise ValueError(f"{name} must be nonzero: got a quaternion of norm 0")
    return q / n


def quat_conjugate(q):
    """Conjugate ``(e0, -e1, -e2, -e3)``: the inverse rotation of ``q`` (``C(q*) = C(q)^T``).

    A sign change only: ``q`` is not interpreted (not normalized, zero passes through).
    """
    q = _as_quat(q, "quat_conjugate")
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def quat_inverse(q):
    """Inverse ``q* / |q|^2`` (equal to :func:`quat_conjugate` for unit ``q``); zero raises ``ValueError``."""
    q = _as_quat(q, "quat_inverse")
    n2 = np.sum(q * q, axis=-1, keepdims=True)
    if np.any(n2 == 0.0):
        raise ValueError("q must be nonzero: got a quaternion of norm 0")
    return quat_conjugate(q) / n2


@jit
def quat_hamilton_scalar(p0, p1, p2, p3, q0, q1, q2, q3):
    """Hamilton product ``p (x) q`` of two quaternions given by their scalar components.

    Returns the tuple ``(r0, r1, r2, r3)``: scalar ``p0 q0 - p.q``, vector
    ``p0 q + q0 p + p x q``.  In this module's frame convention
    ``C(p (x) q) = C(q) @ C(p)`` (so ``quat_multiply(q2, q1) = q1 (x) q2``).
    Compiled (numba) and callable from other kernels; the one scalar quaternion
    product of the package.
    """
    return (
        p0 * q0 - p1 * q1 - p2 * q2 - p3 * q3,
        p0 * q1 + p1 * q0 + p2 * q3 - p3 * q2,
        p0 * q2 - p1 * q3 + p2 * q0 + p3 * q1,
        p0 * q3 + p1 * q2 - p2 * q1 + p3 * q0,
    )


@jit
def _quat_multiply_loop(a, b, out):
    """``out[n] = a[n] (x) b[n]`` (Hamilton) over rows of ``(N, 4)`` arrays.

    Returns 1 if a row of ``a`` is the zero quaternion, 2 if one of ``b`` is (3: both),
    else 0; the products are written either way.
    """
    zero = 0
    for n in range(a.shape[0]):
        a0, a1, a2, a3 = a[n, 0], a[n, 1], a[n, 2], a[n, 3]
        b0, b1, b2, b3 = b[n, 0], b[n, 1], b[n, 2], b[n, 3]
        if a0 == 0.0 and a1 == 0.0 and a2 == 0.0 and a3 == 0.0:
            zero |= 1
        if b0 == 0.0 and b1 == 0.0 and b2 == 0.0 and b3 == 0.0:
            zero |= 2
        out[n, 0], out[n, 1], out[n, 2], out[n, 3] = quat_hamilton_scalar(a0, a1, a2, a3, b0, b1, b2, b3)
    return zero


def quat_multiply(q2, q1):
    """Compose two rotations in matrix order: ``C(quat_multiply(q2, q1)) = C(q2) @ C(q1)``.

    Frame chain: ``q1`` takes frame A to B, ``q2`` takes B to C, the result
    takes A to C (first rotation on the right, as with matrices).  This is
    Shuster's product (M. D. Shuster, "A survey of attitude representations",
    *J. Astronaut. Sci.* 41(4), 1993, 439-517):
    scalar ``a0 b0 - a.b`` and vector ``a0 b + b0 a - a x b`` for
    ``q2 = (a0, a)``, ``q1 = (b0, b)``; equivalently the Hamilton product
    ``q1 (x)_H q2`` (:func:`quat_hamilton_scalar`).  Broadcasts over leading axes
    (``ValueError`` naming both if they do not).

    The algebraic product: non-unit inputs give a product of norm ``|q2| |q1|``, whose
    rotation (read as every function here reads it, ``q / |q|``) is still the
    composition.  A zero ``q2`` or ``q1`` raises ``ValueError`` naming it.
    """
    q2 = _as_quat(q2, "quat_multiply", "q2")
    q1 = _as_quat(q1, "quat_multiply", "q1")
    try:
        shape = np.broadcast_shapes(q2.shape, q1.shape)
    except ValueError:
        broadcast_named("quat_multiply", ("q2", q2, 1), ("q1", q1, 1))  # raises, naming both
        raise
    return _product(q2, q1, shape, "q2", "q1")


def _product(q2, q1, shape, name2, name1):
    """:func:`quat_multiply` of checked arrays, broadcast to ``shape``; zero rows raise naming them."""
    a = np.ascontiguousarray(np.broadcast_to(q1, shape).reshape(-1, 4))
    b = np.ascontiguousarray(np.broadcast_to(q2, shape).reshape(-1, 4))
    out = np.empty_like(a)
    zero = _quat_multiply_loop(a, b, out)
    if zero:
        raise ValueError(f"{name1 if zero & 1 else name2} must be nonzero: got a quaternion of norm 0")
    return out.reshape(shape)


def _parts_broadcast_with(who: str, q: np.ndarray, v: np.ndarray, name: str):
    """``(e0, e, v)``: the scalar part ``(..., 1)`` and the vector part ``(..., 3)`` of the
    quaternions ``q``, the vector part broadcast with the vectors ``v`` ``(..., 3)`` (argument
    ``name`` of ``who``); a ValueError naming both arguments and their shapes when they do
    not broadcast."""
    e0, e = q[..., :1], q[..., 1:]
    try:
        e, v = np.broadcast_arrays(e, v)
    except ValueError:
        broadcast_named(who, ("q", q, 1), (name, v, 1))  # raises, naming both
        raise
    return e0, e, v


def quat_rotate(q, v):
    """Inertial -> body component transform ``C(q) @ v`` without forming ``C``.

    ``C v = v - e0 t + e x t`` with ``t = (2 / |q|^2) e x v`` (expansion of
    ``((e0^2 - e.e) v + 2 e (e.v) - 2 e0 e x v) / |q|^2``), so any nonzero ``q``
    gives the rotation of ``q / |q|``, as :func:`dcm_from_quat` does; a ``q`` with
    ``|q|^2`` within 8 ulp of 1 is used as given (``2 / |q|^2`` taken as 2: unit
    quaternions keep their bits, and the division would only move them by
    round-off).  A zero ``q`` raises ``ValueError``.  ``q``
    ``(..., 4)`` and ``v`` ``(..., 3)`` broadcast.  For body -> inertial use
    ``quat_rotate(quat_conjugate(q), v)``.
    """
    q = _as_quat(q, "quat_rotate")
    v = _as_vec3(v, "v", "quat_rotate")
    if q.shape == (4,) and v.shape == (3,):
        return _rotate_one(q, v)
    e0, e, v = _parts_broadcast_with("quat_rotate", q, v, "v")
    # the components summed left to right, as _rotate_one does: a row gives the same bits
    # through either path
    q0, q1, q2, q3 = q[..., :1], q[..., 1:2], q[..., 2:3], q[..., 3:]
    n2 = q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3
    dev = np.abs(n2 - 1.0)
    if dev.max(initial=0.0) <= _UNIT_NORM2_TOL:  # all unit (NaN fails the test)
        s = 2.0
    elif np.any(n2 == 0.0):
        raise ValueError("q must be nonzero: got a quaternion of norm 0")
    else:
        s = np.where(dev <= _UNIT_NORM2_TOL, 2.0, 2.0 / n2)
    t = s * _cross(e, v)
    return v - e0 * t + _cross(e, t)


def _rotate_one(q, v):
    """:func:`quat_rotate` of one ``(4,)`` and one ``(3,)`` in Python floats (the torque
    models' per-call case): the same operations in the same order, so the same bits."""
    e0, e1, e2, e3 = q.tolist()
    x, y, z = v.tolist()
    n2 = e0 * e0 + e1 * e1 + e2 * e2 + e3 * e3
    if n2 == 0.0:
        raise ValueError("q must be nonzero: got a quaternion of norm 0")
    s = 2.0 if abs(n2 - 1.0) <= _UNIT_NORM2_TOL else 2.0 / n2
    t0, t1, t2 = s * (e2 * z - e3 * y), s * (e3 * x - e1 * z), s * (e1 * y - e2 * x)
    return np.array([x - e0 * t0 + (e2 * t2 - e3 * t1), y - e0 * t1 + (e3 * t0 - e1 * t2), z - e0 * t2 + (e1 * t1 - e2 * t0)])


def dcm_from_quat(q):
    """Direction cosine matrix ``C`` (``v_body = C @ v_inertial``) from Euler parameters.

    ``C = (e0^2 - e.e) I + 2 e e^T - 2 e0 [e x]`` (Baruh ch. 7), evaluated
    with the unit-norm identity folded in and divided by ``|q|^2`` so any
    nonzero ``q`` (not only unit ones) gives a proper rotation: ``C[0, 0] = 1 - 2 (e2^2 + e3^2) / |q|^2``,
    ``C[0, 1] = 2 (e1 e2 + e0 e3) / |q|^2``, and so on.  ``q`` and ``-q`` give
    the same ``C``.  Zero ``q`` raises ``ValueError``.  Returns ``(..., 3, 3)``.
    """
    q = _as_quat(q, "dcm_from_quat")
    n2 = np.sum(q * q, axis=-1)
    if np.any(n2 == 0.0):
        raise ValueError("q must be nonzero: got a quaternion of norm 0")
    s = 2.0 / n2
    e0, e1, e2, e3 = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    C = np.empty(q.shape[:-1] + (3, 3))
    C[..., 0, 0] = 1.0 - s * (e2 * e2 + e3 * e3)
    C[..., 1, 1] = 1.0 - s * (e1 * e1 + e3 * e3)
    C[..., 2, 2] = 1.0 - s * (e1 * e1 + e2 * e2)
    C[..., 0, 1] = s * (e1 * e2 + e0 * e3)
    C[..., 1, 0] = s * (e1 * e2 - e0 * e3)
    C[..., 1, 2] = s * (e2 * e3 + e0 * e1)
    C[..., 2, 1] = s * (e2 * e3 - e0 * e1)
    C[..., 2, 0] = s * (e1 * e3 + e0 * e2)
    C[..., 0, 2] = s * (e1 * e3 - e0 * e2)
    return C


def quat_from_dcm(C):
    """Euler parameters from a direction cosine matrix; unit result with ``e0 >= 0``.

    Shepperd's method (S. W. Shepperd, *J. Guidance Control* 1(3), 1978,
    223-224) in Markley's form (F. L. Markley, *J. Guid. Control Dyn.* 31(2),
    2008, 440-442): of the four candidate vectors
    ``4 e_m (e0, e1, e2, e3)``, built from sums and differences of entries, take
    the one with the largest ``4 e_m^2`` (largest of trace, ``C00``, ``C11``,
    ``C22``), which is never smaller than 1, so no step divides by a small
    number; then normalize.  Accurate to a few ulp everywhere including near
    180 deg.  For a slightly non-orthogonal input the result is a nearby unit
    quaternion (Markley's normalization).  ``C`` is ``(..., 3, 3)``; a matrix that is
    not a rotation (``max |C C^T - I| >`` :data:`DCM_ORTHOGONALITY_TOL`, or ``det C <
    0``) raises ``ValueError`` naming ``C``; non-finite entries give NaN.
    """
    C = _as_dcm(C, "quat_from_dcm")
    _check_rotation(C, "C")
    c00, c01, c02 = C[..., 0, 0], C[..., 0, 1], C[..., 0, 2]
    c10, c11, c12 = C[..., 1, 0], C[..., 1, 1], C[..., 1, 2]
    c20, c21, c22 = C[..., 2, 0], C[..., 2, 1], C[..., 2, 2]
    tr = c00 + c11 + c22
    # with C = our (passive) matrix: C12 - C21 = 4 e0 e1, C20 - C02 = 4 e0 e2,
    # C01 - C10 = 4 e0 e3, C01 + C10 = 4 e1 e2, C02 + C20 = 4 e1 e3, C12 + C21 = 4 e2 e3
    cand = np.stack(
        [
            np.stack([1.0 + tr, c12 - c21, c20 - c02, c01 - c10], -1),
            np.stack([c12 - c21, 1.0 + 2.0 * c00 - tr, c01 + c10, c02 + c20], -1),
            np.stack([c20 - c02, c01 + c10, 1.0 + 2.0 * c11 - tr, c12 + c21], -1),
            np.stack([c01 - c10, c02 + c20, c12 + c21, 1.0 + 2.0 * c22 - tr], -1),
        ],
        axis=-2,
    )
    pick = np.argmax(np.stack([tr, c00, c11, c22], -1), axis=-1)
    q = np.take_along_axis(cand, pick[..., None, None], axis=-2)[..., 0, :]
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., :1] < 0.0, -q, q)


# --------------------------------------------------------------------------
# Euler angles


def dcm_from_euler(angles, seq):
    """``C = C_k(a3) @ C_j(a2) @ C_i(a1)`` for the body-axis sequence ``seq = "ijk"``.

    ``angles`` ``(..., 3)`` = ``(a1, a2, a3)`` in rad; ``seq`` one of
    :data:`EULER_SEQUENCES`.  Returns ``(..., 3, 3)`` (Baruh ch. 7, Euler angles).
    """
    i, j, k = _parse_seq(seq)
    a = _as_vec3(angles, "angles", "dcm_from_euler")
    return _elementary0(k, a[..., 2]) @ _elementary0(j, a[..., 1]) @ _elementary0(i, a[..., 0])


def euler_from_dcm(C, seq):
    """Euler angles ``(a1, a2, a3)`` of ``C`` for the body-axis sequence ``seq = "ijk"``.

    Ranges: ``a1, a3`` in ``(-pi, pi]``; ``a2`` in ``[-pi/2, pi/2]`` for the
    asymmetric sequences and ``[0, pi]`` for the symmetric ones.

    Method (every angle from ``atan2``, never ``asin``/``acos``): column ``i``
    of ``C`` is ``C_k(a3) C_j(a2) e_i`` and does not involve ``a1``.  With
    ``s = eps_ijk``:

    * asymmetric: ``C[i,i] = cos a2 cos a3``, ``C[j,i] = -s cos a2 sin a3``,
      ``C[k,i] = s sin a2``, so ``a2 = atan2(s C[k,i], hypot(C[i,i], C[j,i]))``
      and ``a3 = atan2(-s C[j,i], C[i,i])``;
    * symmetric (``l`` the third axis, ``s = eps_ijl``): ``C[i,i] = cos a2``,
      ``C[j,i] = sin a2 sin a3``, ``C[l,i] = s sin a2 cos a3``, so
      ``a2 = atan2(hypot(C[j,i], C[l,i]), C[i,i])``, ``a3 = atan2(C[j,i], s C[l,i])``.

    Then ``a1`` is read from ``M = (C_k(a3) C_j(a2))^T C``, which is ``C_i(a1)``
    up to round-off.  Near gimbal lock ``a1`` and ``a3`` are individually
    ill-conditioned (errors ~ eps/|cos a2| resp. eps/|sin a2|), but because
    ``a1`` is fitted to the computed ``a2, a3`` the round trip
    ``C -> angles -> C`` stays at a few ulp everywhere.  At gimbal lock
    (``|cos a2|``, resp. ``sin a2``, at most :data:`GIMBAL_LOCK_TOL`) the
    returned triple has ``a3 = 0`` and ``a1`` carries the whole rotation about
    the locked axis.  ``C`` is ``(..., 3, 3)``, a rotation to
    :data:`DCM_ORTHOGONALITY_TOL` (else ``ValueError`` naming ``C``, as
    :func:`quat_from_dcm`); returns ``(..., 3)``.
    """
    i, j, k = _parse_seq(seq)
    C = _as_dcm(C, "euler_from_dcm")
    _check_rotation(C, "C")
    return _euler_from_rotation(C, i, j, k)


def _euler_from_rotation(C, i, j, k):
    """:func:`euler_from_dcm` of a checked rotation matrix, axes ``(i, j, k)`` zero-based."""
    cii, cji = C[..., i, i], C[..., j, i]
    if i != k:
        s = _levi_civita(i, j, k)
        cos2 = np.hypot(cii, cji)
        a2 = np.arctan2(s * C[..., k, i], cos2)
        lock = cos2 <= GIMBAL_LOCK_TOL
        a3 = np.where(lock, 0.0, np.arctan2(-s * cji, cii))
    else:
        l = 3 - i - j
        s = _levi_civita(i, j, l)
        cli = C[..., l, i]
        sin2 = np.hypot(cji, cli)
        a2 = np.arctan2(sin2, cii)
        lock = sin2 <= GIMBAL_LOCK_TOL
        a3 = np.where(lock, 0.0, np.arctan2(cji, s * cli))
    M = _transpose(_elementary0(k, a3) @ _elementary0(j, a2)) @ C
    u, v = (i + 1) % 3, (i + 2) % 3
    a1 = np.arctan2(M[..., u, v] - M[..., v, u], M[..., u, u] + M[..., v, v])
    return np.stack([a1, a2, a3], axis=-1)


def quat_from_euler(angles, seq):
    """Euler parameters of ``dcm_from_euler(angles, seq)``, composed from elementary quaternions.

    ``q = q_k(a3) . q_j(a2) . q_i(a1)`` (matrix order, :func:`quat_multiply`),
    ``q_n(a) = (cos a/2, sin a/2 e_n)``.  Continuous in the angles; the sign is
    not canonicalized (``e0`` may be negative).
    """
    i, j, k = _parse_seq(seq)
    a = _as_vec3(angles, "angles", "quat_from_euler")
    return quat_multiply(_elementary_quat(k, a[..., 2]), quat_multiply(_elementary_quat(j, a[..., 1]), _elementary_quat(i, a[..., 0])))


def _elementary_quat(n, a):
    q = np.zeros(np.shape(a) + (4,))
    q[..., 0] = np.cos(0.5 * a)
    q[..., n + 1] = np.sin(0.5 * a)
    return q


def euler_from_quat(q, seq):
    """Euler angles of ``dcm_from_quat(q)`` (see :func:`euler_from_dcm` for ranges and gimbal lock)."""
    i, j, k = _parse_seq(seq)
    return _euler_from_rotation(dcm_from_quat(_as_quat(q, "euler_from_quat")), i, j, k)


# --------------------------------------------------------------------------
# axis-angle and rotation vector


def quat_from_axis_angle(axis, angle):
    """Euler parameters of a frame rotation by ``angle`` (rad) about ``axis``.

    ``q = (cos(angle/2), n sin(angle/2))`` with ``n = axis / |axis|``; the
    frame turns right-handedly about ``n`` (``C = C_3(angle)`` for
    ``axis = (0, 0, 1)``).  ``axis`` ``(..., 3)`` nonzero (zero raises
    ``ValueError``), ``angle`` broadcastable.  Not sign-canonicalized.
    """
    axis = _as_vec3(axis, "axis", "quat_from_axis_angle")
    angle = real_array(angle, "angle", "quat_from_axis_angle")
    broadcast_named("quat_from_axis_angle", ("axis", axis, 1), ("angle", angle, 0))
    n = np.linalg.norm(axis, axis=-1, keepdims=True)
    if np.any(n == 0.0):
        raise ValueError("axis must be a nonzero vector")
    half = 0.5 * angle[..., None]
    nhat = axis / n
    nhat, half = np.broadcast_arrays(nhat, half)
    return np.concatenate([np.cos(half[..., :1]), nhat * np.sin(half)], axis=-1)


def axis_angle_from_quat(q):
    """``(axis, angle)`` of a quaternion: unit axis ``(..., 3)``, angle in ``[0, pi]``.

    ``angle = 2 atan2(|e|, |e0|)`` (well conditioned at every angle) after
    flipping ``q`` to ``e0 >= 0``; ``axis = e / |e|``.  For the identity
    (``angle = 0``) the axis is undefined and ``(1, 0, 0)`` is returned.  Both
    are ratios of components, so a non-unit ``q`` gives the axis and angle of
    ``q / |q|``; a zero ``q`` raises ``ValueError``.
    """
    q = _as_quat(q, "axis_angle_from_quat")
    _norm2_nonzero(q, "q")
    q = np.where(q[..., :1] < 0.0, -q, q)
    e = q[..., 1:]
    ne = np.linalg.norm(e, axis=-1)
    angle = 2.0 * np.arctan2(ne, q[..., 0])
    zero = ne == 0.0
    axis = np.where(zero[..., None], np.array([1.0, 0.0, 0.0]), e / np.where(zero, 1.0, ne)[..., None])
    return axis, angle


def attitude_difference(qa, qb):
    """Rotation angle (rad, in ``[0, pi]``) between two attitudes ``qa``, ``qb`` ``(..., 4)``.

    The angle of ``qb (x) qa*``, ``2 atan2(|e|, |e0|)`` (the sign of either quaternion is
    irrelevant; well conditioned at every angle).  A ratio of components: non-unit
    inputs give the angle between ``qa / |qa|`` and ``qb / |qb|`` (no normalization
    needed); a zero ``qa`` or ``qb`` raises ``ValueError`` naming it, leading shapes that
    do not broadcast ``ValueError`` naming both.
    """
    qa = _as_quat(qa, "attitude_difference", "qa")
    qb = _as_quat(qb, "attitude_difference", "qb")
    shape = broadcast_named("attitude_difference", ("qa", qa, 1), ("qb", qb, 1)) + (4,)
    d = _product(qb, quat_conjugate(qa), shape, "qb", "qa")
    return 2.0 * np.arctan2(np.linalg.norm(d[..., 1:], axis=-1), np.abs(d[..., 0]))


def quat_from_rotvec(rotvec):
    """Euler parameters from the rotation vector ``r = angle * n`` (rad), ``C = exp(-[r x])``.

    ``q = (cos(|r|/2), r * 0.5 sinc(|r|/2))``, with a series for ``sinc`` near 0
    so tiny vectors keep full relative accuracy.  ``rotvec`` ``(..., 3)``.
    """
    r = _as_vec3(rotvec, "rotvec", "quat_from_rotvec")
    half = 0.5 * np.linalg.norm(r, axis=-1)
    return np.concatenate([np.cos(half)[..., None], r * (0.5 * _sinc(half))[..., None]], axis=-1)


def rotvec_from_quat(q):
    """Rotation vector ``r = angle * n`` with ``|r| <= pi`` (rad); inverse of :func:`quat_from_rotvec`.

    After flipping to ``e0 >= 0``: ``r = e * angle / |e|`` with
    ``angle / |e| = 2 atan2(|e|, e0) / |e|``, replaced near 0 by the series
    ``(2 / e0) (1 - x^2/3 + x^4/5)``, ``x = |e| / e0``, so tiny rotations keep
    full relative accuracy.  Ratios of components: a non-unit ``q`` gives the rotation
    vector of ``q / |q|``; a zero ``q`` raises ``ValueError``.
    """
    q = _as_quat(q, "rotvec_from_quat")
    _norm2_nonzero(q, "q")
    q = np.where(q[..., :1] < 0.0, -q, q)
    e0, e = q[..., 0], q[..., 1:]
    ne = np.linalg.norm(e, axis=-1)
    small = ne < 1e-4 * e0  # x < 1e-4: next series term x^6/7 < 1.5e-25
    x2 = np.where(small, (ne / np.where(small, e0, 1.0)) ** 2, 0.0)
    factor = np.where(
        small,
        2.0 / np.where(small, e0, 1.0) * (1.0 - x2 / 3.0 + x2 * x2 / 5.0),
        2.0 * np.arctan2(ne, e0) / np.where(small, 1.0, ne),
    )
    return e * factor[..., None]


def slerp(q0, q1, tau):
    """Spherical linear interpolation along the shorter arc (Shoemake 1985).

    ``q(tau) = [sin((1-tau) W) q0 + sin(tau W) q1'] / sin W`` where ``q1' = +-q1``
    is the sign closer to ``q0`` (so ``q`` and ``-q`` interpolate identically)
    and ``W = 2 atan2(|q0 - q1'|, |q0 + q1'|)`` is the angle between them in
    R^4 (half the rotation angle between the attitudes).  The weights are
    evaluated as ``(1-tau) sinc((1-tau) W) / sinc(W)`` so ``W -> 0`` is exact.
    The attitude turns at constant angular rate about a fixed axis,
    ``q(0) = q0``, ``q(1) = q1'``.  Inputs are normalized first (a zero ``q0`` or
    ``q1`` raises ``ValueError`` naming it); ``tau`` (any real, extrapolates outside
    [0, 1]) broadcasts with the leading axes (``ValueError`` naming all three if not).
    """
    q0 = _as_quat(q0, "slerp", "q0")
    q1 = _as_quat(q1, "slerp", "q1")
    tau = real_array(tau, "tau", "slerp")
    broadcast_named("slerp", ("q0", q0, 1), ("q1", q1, 1), ("tau", tau, 0))
    q0 = _normalized(q0, "q0")
    q1 = _normalized(q1, "q1")
    tau = tau[..., None]
    q1 = np.where(np.sum(q0 * q1, axis=-1, keepdims=True) < 0.0, -q1, q1)
    W = 2.0 * np.arctan2(np.linalg.norm(q0 - q1, axis=-1, keepdims=True), np.linalg.norm(q0 + q1, axis=-1, keepdims=True))
    sW = _sinc(W)
    w0 = (1.0 - tau) * _sinc((1.0 - tau) * W) / sW
    w1 = tau * _sinc(tau * W) / sW
    return quat_normalize(w0 * q0 + w1 * q1)


# --------------------------------------------------------------------------
# kinematics


def quat_rate(q, w):
    """Euler parameter rates ``dq/dt = 0.5 * Omega(w) @ q`` (Baruh ch. 7).

    ``Omega(w) = [[0, -w^T], [w, -[w x]]]``: ``de0/dt = -0.5 e.w``,
    ``de/dt = 0.5 (e0 w + e x w)``.  ``w`` is the body angular velocity in body
    components (rad/s), ``q`` ``(..., 4)``, ``w`` ``(..., 3)``; returns 1/s.
    Consistent with ``dC/dt = -[w x] C``.  Linear in ``q``: the rate of the
    given ``q`` (not normalized; this is the right-hand side an integrator of ``q``
    needs, and a zero ``q`` has zero rate).
    """
    q = _as_quat(q, "quat_rate")
    w = _as_vec3(w, "w", "quat_rate")
    e0, e, w = _parts_broadcast_with("quat_rate", q, w, "w")
    d0 = -0.5 * np.sum(e * w, axis=-1, keepdims=True)
    de = 0.5 * (e0 * w + _cross(e, w))
    return np.concatenate([d0, de], axis=-1)


def omega_from_quat_rate(q, qdot):
    """Body angular velocity (rad/s, body components) from Euler parameter rates.

    Inverse of :func:`quat_rate`: ``w = 2 (e0 de - de0 e - e x de) / |q|^2``
    (the vector part of ``2 conj(q) (x)_H qdot / |q|^2``).  Any component of
    ``qdot`` along ``q`` (a norm change) is ignored.  A zero ``q`` raises ``ValueError``.
    """
    q = _as_quat(q, "omega_from_quat_rate")
    qdot = _as_quat(qdot, "omega_from_quat_rate", "qdot")
    broadcast_named("omega_from_quat_rate", ("q", q, 1), ("qdot", qdot, 1))
    _norm2_nonzero(q, "q")
    e0, e = q[..., :1], q[..., 1:]
    d0, de = qdot[..., :1], qdot[..., 1:]
    e, de = np.broadcast_arrays(e, de)
    n2 = np.sum(q * q, axis=-1, keepdims=True)
    return 2.0 * (e0 * de - d0 * e - _cross(e, de)) / n2


def _euler_rate_trig(angles, seq, who):
    i, j, k = _parse_seq(seq)
    a = _as_vec3(angles, "angles", who)
    return a, (i, j, k), np.cos(a[..., 1]), np.sin(a[..., 1]), np.cos(a[..., 2]), np.sin(a[..., 2])


def euler_singular(angles, seq, tol=EULER_RATE_SINGULAR_TOL):
    """Boolean mask (shape ``(...)``): where the Euler angle rates of ``seq`` are singular.

    Singular means ``|cos a2| < tol`` (asymmetric sequences, ``a2 = +-pi/2``)
    or ``|sin a2| < tol`` (symmetric, ``a2 = 0, pi``); the default ``tol`` is
    :data:`EULER_RATE_SINGULAR_TOL` = sqrt(eps).
    """
    _, (i, j, k), c2, s2, _, _ = _euler_rate_trig(angles, seq, "euler_singular")
    return np.abs(c2 if i != k else s2) < tol


def omega_from_euler_rates(angles, rates, seq):
    """Body angular velocity ``w`` (rad/s, body components) from Euler angles and their rates.

    ``w = da1/dt C_k(a3) C_j(a2) e_i + da2/dt C_k(a3) e_j + da3/dt e_k``
    (Baruh ch. 7), written out per sequence class (``s = eps_ijk``, resp.
    ``eps_ijl`` for symmetric sequences with third axis ``l``).  Defined
    everywhere (no singularity in this direction).  ``angles``, ``rates``
    ``(..., 3)``.
    """
    angles, (i, j, k), c2, s2, c3, s3 = _euler_rate_trig(angles, seq, "omega_from_euler_rates")
    r = _as_vec3(rates, "rates", "omega_from_euler_rates")
    broadcast_named("omega_from_euler_rates", ("angles", angles, 1), ("rates", r, 1))
    d1, d2, d3 = r[..., 0], r[..., 1], r[..., 2]
    c2, s2, c3, s3, d1, d2, d3 = np.broadcast_arrays(c2, s2, c3, s3, d1, d2, d3)
    w = np.empty(c2.shape + (3,))
    if i != k:
        s = _levi_civita(i, j, k)
        w[..., i] = c2 * c3 * d1 + s * s3 * d2
        w[..., j] = -s * c2 * s3 * d1 + c3 * d2
        w[..., k] = s * s2 * d1 + d3
    else:
        l = 3 - i - j
        s = _levi_civita(i, j, l)
        w[..., i] = c2 * d1 + d3
        w[..., j] = s2 * s3 * d1 + c3 * d2
        w[..., l] = s * (s2 * c3 * d1 - s3 * d2)
    return w


def euler_rates(angles, w, seq, *, tol=EULER_RATE_SINGULAR_TOL, on_singular="raise"):
    """Euler angle rates ``(da1, da2, da3)/dt`` from the body angular velocity ``w`` (rad/s).

    Inverse of :func:`omega_from_euler_rates` (Baruh ch. 7), in closed form:

    * asymmetric: ``da1 = (c3 w_i - s s3 w_j) / c2``, ``da2 = s s3 w_i + c3 w_j``,
      ``da3 = w_k - s s2 da1``;
    * symmetric: ``da1 = (s3 w_j + s c3 w_l) / s2``, ``da2 = c3 w_j - s s3 w_l``,
      ``da3 = w_i - c2 da1``

    (``c2 = cos a2`` etc., ``s = eps_ijk`` resp. ``eps_ijl``).  The kinematic
    singularity (``|cos a2|`` resp. ``|sin a2|`` below ``tol``, see
    :func:`euler_singular`): ``on_singular="raise"`` (default) raises
    :class:`EulerSingularityError` if any element is singular;
    ``on_singular="nan"`` returns NaN rates for those elements and the finite
    rates elsewhere.
    """
    if on_singular not in ("raise", "nan"):
        raise ValueError(f"on_singular must be 'raise' or 'nan', got {on_singular!r}")
    angles, (i, j, k), c2, s2, c3, s3 = _euler_rate_trig(angles, seq, "euler_rates")
    w = _as_vec3(w, "w", "euler_rates")
    broadcast_named("euler_rates", ("angles", angles, 1), ("w", w, 1))
    wi, wj, wk = w[..., i], w[..., j], w[..., k]
    c2, s2, c3, s3, wi, wj, wk = np.broadcast_arrays(c2, s2, c3, s3, wi, wj, wk)
    den = c2 if i != k else s2
    singular = np.abs(den) < tol
    if on_singular == "raise" and np.any(singular):
        raise EulerSingularityError(
            f"Euler angle rates of sequence {seq!r} are singular at {int(np.count_nonzero(singular))} of "
            f"{singular.size} attitudes (|{'cos' if i != k else 'sin'} a2| < {tol:g}); "
            "use on_singular='nan' to get NaN there, or another sequence / Euler parameters"
        )
    den = np.where(singular, np.nan, den)
    out = np.empty(c2.shape + (3,))
    if i != k:
        s = _levi_civita(i, j, k)
        d1 = (c3 * wi - s * s3 * wj) / den
        out[..., 0] = d1
        out[..., 1] = s * s3 * wi + c3 * wj
        out[..., 2] = wk - s * s2 * d1
    else:
        l = 3 - i - j
        s = _levi_civita(i, j, l)
        wl = np.broadcast_to(w[..., l], c2.shape)
        d1 = (s3 * wj + s * c3 * wl) / den
        out[..., 0] = d1
        out[..., 1] = c3 * wj - s * s3 * wl
        out[..., 2] = wi - c2 * d1
    out[singular] = np.nan
    return out


# --------------------------------------------------------------------------
# exact constant-rate step (compiled)


@jit
def _quat_step_kernel(e0, e1, e2, e3, w1, w2, w3, dt):
    """Scalar kernel of :func:`quat_propagate_constant_rate`: returns the new ``(e0, e1, e2, e3)``.

    ``q(t+dt) = [cos(h) I + (sin(h)/|w|) Omega(w)] q(t)``, ``h = |w| dt / 2``,
    the exact solution of ``dq/dt = 0.5 Omega(w) q`` for constant ``w``
    (``Omega(w)^2 = -|w|^2 I``).  ``sin(h)/|w| = (dt/2) sinc(h)`` with a series
    for ``|h| < 1e-4``; the result is renormalized (one sqrt) so ``|q| = 1`` to
    1 ulp with no drift.  Callable from other numba kernels.
    """
    wn = np.sqrt(w1 * w1 + w2 * w2 + w3 * w3)
    h = 0.5 * wn * dt
    if abs(h) < 1e-4:
        h2 = h * h
        sc = 1.0 - h2 / 6.0 * (1.0 - h2 / 20.0)
    else:
        sc = np.sin(h) / h
    c = np.cos(h)
    f = 0.5 * dt * sc  # = sin(h) / |w|
    # Omega(w) q = (-e.w, e0 w + e x w)
    o0 = -(e1 * w1 + e2 * w2 + e3 * w3)
    o1 = e0 * w1 + e2 * w3 - e3 * w2
    o2 = e0 * w2 + e3 * w1 - e1 * w3
    o3 = e0 * w3 + e1 * w2 - e2 * w1
    n0 = c * e0 + f * o0
    n1 = c * e1 + f * o1
    n2 = c * e2 + f * o2
    n3 = c * e3 + f * o3
    inv = 1.0 / np.sqrt(n0 * n0 + n1 * n1 + n2 * n2 + n3 * n3)
    return n0 * inv, n1 * inv, n2 * inv, n3 * inv


@jit
def _quat_propagate_loop(q, w, dt, out):
    """Rows of :func:`quat_propagate_constant_rate`; returns True if a row of ``q`` is zero."""
    zero = False
    for n in range(q.shape[0]):
        e0, e1, e2, e3 = q[n, 0], q[n, 1], q[n, 2], q[n, 3]
        if e0 == 0.0 and e1 == 0.0 and e2 == 0.0 and e3 == 0.0:
            zero = True
        a, b, c, d = _quat_step_kernel(e0, e1, e2, e3, w[n, 0], w[n, 1], w[n, 2], dt[n])
        out[n, 0] = a
        out[n, 1] = b
        out[n, 2] = c
        out[n, 3] = d
    return zero


def quat_propagate_constant_rate(q, w, dt):
    """Exact attitude after ``dt`` seconds of constant body rate ``w`` (rad/s, body components).

    Closed-form solution of ``dq/dt = 0.5 Omega(w) q``: a frame rotation by
    ``|w| dt`` about ``w`` (fixed in both frames while ``w`` is constant),
    ``q(t+dt) = quat_multiply(quat_from_rotvec(w dt), q(t))``; evaluated by the
    compiled :func:`_quat_step_kernel` and renormalized, so ``|q| = 1`` to
    round-off.  ``q`` ``(..., 4)``, ``w`` ``(..., 3)`` and ``dt`` (s, any sign)
    broadcast (``ValueError`` naming all three if not).  The result is renormalized,
    so a non-unit ``q`` gives the propagated ``q / |q|``; a zero ``q`` raises
    ``ValueError``.
    """
    q = _as_quat(q, "quat_propagate_constant_rate")
    w = _as_vec3(w, "w", "quat_propagate_constant_rate")
    dt = real_array(dt, "dt", "quat_propagate_constant_rate")
    shape = broadcast_named("quat_propagate_constant_rate", ("q", q, 1), ("w", w, 1), ("dt", dt, 0))
    qb = np.ascontiguousarray(np.broadcast_to(q, shape + (4,)).reshape(-1, 4))
    wb = np.ascontiguousarray(np.broadcast_to(w, shape + (3,)).reshape(-1, 3))
    db = np.ascontiguousarray(np.broadcast_to(dt, shape).reshape(-1))
    out = np.empty_like(qb)
    if _quat_propagate_loop(qb, wb, db, out):
        raise ValueError("q must be nonzero: got a quaternion of norm 0")
    return out.reshape(shape + (4,))


# --------------------------------------------------------------------------
# edges: scalar-last order, scipy


def quat_to_scalar_last(q):
    """Scalar-first ``(e0, e1, e2, e3)`` -> scalar-last ``(x, y, z, w) = (e1, e2, e3, e0)``.

    Foxglove / REBOUND / scipy order.  The numbers are unchanged, only
    reordered: as an *active* rotation (Foxglove ``FrameTransform`` with
    parent = inertial, child = body) it maps body components to inertial ones,
    i.e. its matrix is ``C.T``.
    """
    q = _as_quat(q, "quat_to_scalar_last")
    return np.concatenate([q[..., 1:], q[..., :1]], axis=-1)


def quat_from_scalar_last(xyzw):
    """Scalar-last ``(x, y, z, w)`` -> scalar-first ``(e0, e1, e2, e3) = (w, x, y, z)``."""
    xyzw = _as_quat(xyzw, "quat_from_scalar_last", "xyzw")
    return np.concatenate([xyzw[..., 3:], xyzw[..., :3]], axis=-1)


def to_scipy_rotation(q):
    """``scipy.spatial.transform.Rotation`` of the same attitude.

    scipy's ``Rotation`` is active and scalar-last; the one returned satisfies
    ``R.as_matrix() == dcm_from_quat(q).T``: ``R.apply(v_body) = v_inertial``
    and ``R.inv().apply(v_inertial) = v_body``.  ``q`` ``(4,)`` or ``(N, 4)``
    (scipy's own batching rules).
    """
    from scipy.spatial.transform import Rotation

    q = _as_quat(q, "to_scipy_rotation")
    _norm2_nonzero(q, "q")
    return Rotation.from_quat(quat_to_scalar_last(q))


def from_scipy_rotation(R):
    """Euler parameters (scalar first) of a scipy ``Rotation`` ``R``: ``dcm_from_quat(q) == R.as_matrix().T``."""
    from scipy.spatial.transform import Rotation

    if not isinstance(R, Rotation):
        raise ValueError(f"R must be a scipy.spatial.transform.Rotation, got {type(R).__name__}")
    return quat_from_scalar_last(R.as_quat())
