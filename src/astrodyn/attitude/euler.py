"""Euler's equations of rigid-body motion in state form, with torques and rotors.

Following H. Baruh, *Analytical Dynamics*, ch. 8 (Euler's equations, sec. 8.5-8.7;
state form for numerical integration) and ch. 10 (gyrostats).  Conventions are
those of docs/architecture.md (section 2):

* ``w``: body angular velocity in **body** components, rad/s.
* Euler parameters ``q = (e0, e1, e2, e3)``, scalar first, with
  ``v_body = C(q) @ v_inertial`` and ``dC/dt = -[w x] C``; the kinematic equation
  is then ``dq/dt = 1/2 q (x) (0, w)`` (Hamilton product), i.e. Baruh eq. (7.9x)
  ``e0' = -1/2 w.e``, ``e' = 1/2 (e0 w + e x w)``.
* ``inertia``: either the three principal moments ``(I1, I2, I3)`` (body axes are
  principal axes) or a full symmetric inertia tensor ``(3, 3)`` in body axes,
  kg m^2, about the centre of mass (or about the fixed point for a top).
* ``torque``: external torque in body components, N m.
* ``rotor_momentum`` ``h``: angular momentum of the rotors (momentum wheels,
  dual-spin rotor) *relative to the body*, body components, N m s.  The total
  angular momentum in body components is ``H = I w + h`` and Euler's equations of
  a gyrostat read (Baruh ch. 10; Hughes, *Spacecraft Attitude Dynamics*, ch. 7)::

      I w' + w x (I w + h) = tau - h'

  or, in momentum form, ``H' = H x w + tau`` with ``w = I^{-1} (H - h)``.

Everything is vectorized over leading axes ``(..., 3)``; a single state returns
``(3,)``.  NaN inputs give NaN outputs.
"""

from __future__ import annotations

import math

import numpy as np

from astrodyn.inputs import broadcast_named, real_array
from astrodyn.rotation import quat_rate

__all__ = [
    "TRIANGLE_SLACK",
    "check_principal_moments",
    "inertia_tensor",
    "principal_axes",
    "angular_acceleration",
    "euler_rates",
    "body_momentum_rates",
    "attitude_state_rates",
]


def _as_vec3(x, name, who):
    a = real_array(x, name, who)
    if a.shape[-1:] != (3,):
        raise ValueError(f"{who}: {name}: expected an array of shape (..., 3), got shape {a.shape}")
    return a


#: Relative slack of the triangle inequality ``I1 + I2 >= I3 (1 - slack)`` (round-off of
#: moments computed from a mass distribution, or of an eigen-decomposition).
TRIANGLE_SLACK = 1e-12


def check_principal_moments(moments, name="inertia"):
    """Refuse principal moments of inertia no rigid body can have; returns them unchanged.

    ``moments`` ``(..., 3)`` kg m^2, any order (a float64 array).  Every row must be
    finite and positive and satisfy the triangle inequalities ``I_i + I_j >= I_k``
    (checked on the sorted moments, ``I1 + I2 >= I3 (1 - 1e-12)``: the moments of any
    mass distribution do, with equality for a flat body).  Otherwise ``ValueError``
    naming ``name`` and the first offending row.  The one checker of the attitude
    package: :func:`inertia_tensor` (on the eigenvalues of a tensor),
    :func:`angular_acceleration`, :func:`body_momentum_rates`,
    :func:`~astrodyn.attitude.torque_free.torque_free` and
    :func:`~astrodyn.attitude.integrators.propagate_attitude` all use it.
    """
    if moments.shape == (3,):  # one body: plain floats (cheap on the per-call paths)
        row = moments.tolist()
        why = _moments_problem(row)
    else:
        m = np.sort(moments, axis=-1)
        ok = np.all(np.isfinite(m), axis=-1) & (m[..., 0] > 0.0)
        ok &= ~(m[..., 0] + m[..., 1] < m[..., 2] * (1.0 - TRIANGLE_SLACK))
        if np.all(ok):
            return moments
        row = moments[~ok][0].tolist()
        why = _moments_problem(row)
    if why is not None:
        raise ValueError(f"{name}: expected finite positive principal moments (kg m^2) obeying the triangle "
                         f"inequality I1 + I2 >= I3, got {row} ({why})")
    return moments


def _moments_problem(row):
    """Why three principal moments (floats) are not a rigid body's, or None (same tests as
    the vectorized path of :func:`check_principal_moments`, in the same arithmetic)."""
    if not all(math.isfinite(x) for x in row):
        return "not finite"
    a, b, c = sorted(row)
    if not a > 0.0:
        return "not positive"
    if a + b < c * (1.0 - TRIANGLE_SLACK):
        return f"{a!r} + {b!r} < {c!r}: no rigid body has these"
    return None


def inertia_tensor(inertia) -> np.ndarray:
    """The ``(3, 3)`` inertia tensor from principal moments ``(3,)`` or a tensor ``(3, 3)``.

    Checks that the tensor is symmetric (to 1e-12 relative) and physically
    realisable: its eigenvalues pass :func:`check_principal_moments` (positive,
    triangle inequalities ``I1 + I2 >= I3`` cyclic, with a 1e-12 relative slack for
    round-off).  Raises ``ValueError`` naming ``inertia`` otherwise.
    """
    a = real_array(inertia, "inertia", "inertia_tensor")
    if a.shape == (3,):
        J = np.diag(a)
    elif a.shape == (3, 3):
        J = a.copy()
    else:
        raise ValueError(f"inertia: expected principal moments (3,) or a tensor (3, 3), got shape {a.shape}")
    if not np.all(np.isfinite(J)):
        raise ValueError("inertia: must be finite")
    scale = np.max(np.abs(J))
    if np.max(np.abs(J - J.T)) > 1e-12 * scale:
        raise ValueError("inertia: tensor must be symmetric")
    J = 0.5 * (J + J.T)
    check_principal_moments(np.linalg.eigvalsh(J))
    return J


def principal_axes(inertia):
    """Principal moments and axes: ``inertia = P @ diag(moments) @ P.T``.

    Returns ``(moments (3,), P (3, 3))``.  The columns of ``P`` are the principal
    axes in body components and ``det P = +1`` (a proper rotation), so a body
    vector maps to principal-axis components as ``v_principal = P.T @ v_body``.
    For a diagonal input ``P`` is the identity and the moments keep their order.
    """
    J = inertia_tensor(inertia)
    if np.count_nonzero(J - np.diag(np.diag(J))) == 0:
        return np.diag(J).copy(), np.eye(3)
    m, P = np.linalg.eigh(J)
    if np.linalg.det(P) < 0.0:
        P[:, 2] = -P[:, 2]
    return m, P


def angular_acceleration(inertia, w, torque=0.0, rotor_momentum=0.0, rotor_momentum_rate=0.0):
    """Body angular acceleration ``w'`` from Euler's equations (rad/s^2).

    ``I w' = tau - h' - w x (I w + h)`` (Baruh eq. 8.5x for ``h = 0``; gyrostat
    form of ch. 10).  ``inertia`` principal moments ``(3,)`` (the classic
    component form ``I1 w1' = (I2 - I3) w2 w3 + tau1`` ...) or a full tensor
    ``(3, 3)``, both checked as :func:`inertia_tensor` checks them
    (:func:`check_principal_moments`); ``w, torque, rotor_momentum,
    rotor_momentum_rate`` ``(..., 3)`` (the last three may be scalars) broadcast over
    leading axes (``ValueError`` naming them if not).
    """
    who = "angular_acceleration"
    w = _as_vec3(w, "w", who)
    tau = _vec3_or_scalar(torque, "torque", who)
    h = _vec3_or_scalar(rotor_momentum, "rotor_momentum", who)
    hd = _vec3_or_scalar(rotor_momentum_rate, "rotor_momentum_rate", who)
    a = real_array(inertia, "inertia", who)
    try:
        if a.shape == (3,):
            check_principal_moments(a)
            H = a * w + h
            rhs = tau - hd - np.cross(w, H)
            return rhs / a
        J = inertia_tensor(a)
        H = w @ J.T + h
        rhs = tau - hd - np.cross(w, H)
        return rhs @ np.linalg.inv(J).T
    except ValueError:
        named = [("w", w), ("torque", tau), ("rotor_momentum", h), ("rotor_momentum_rate", hd)]
        broadcast_named(who, *((n, x, 1 if x.ndim else 0) for n, x in named))
        raise


def _vec3_or_scalar(x, name, who):
    """A body vector ``(..., 3)`` or a scalar (broadcast to every component), as float64."""
    a = real_array(x, name, who)
    if a.ndim and a.shape[-1] != 3:
        raise ValueError(f"{who}: {name}: expected a scalar or an array of shape (..., 3), got shape {a.shape}")
    return a


euler_rates = angular_acceleration
"""Deprecated old name of :func:`angular_acceleration` (``astrodyn.rotation.euler_rates`` is the
rate of the Euler *angles*)."""


def body_momentum_rates(inertia, H, torque=0.0, rotor_momentum=0.0):
    """``H' = H x w + tau`` with ``w = I^{-1} (H - h)``: Euler's equations in momentum form.

    ``H`` total angular momentum in body components (N m s), ``rotor_momentum``
    ``h`` the rotors' momentum relative to the body; ``inertia`` as in
    :func:`angular_acceleration` (checked the same way).  Returns ``(H', w)``.  This
    form needs no ``h'`` (a commanded rotor speed enters only through ``h(t)``)
    and is the Lie-Poisson form the splitting integrator preserves.
    """
    who = "body_momentum_rates"
    H = _as_vec3(H, "H", who)
    a = real_array(inertia, "inertia", who)
    h = _vec3_or_scalar(rotor_momentum, "rotor_momentum", who)
    tau = _vec3_or_scalar(torque, "torque", who)
    try:
        rel = H - h
        if a.shape == (3,):
            w = rel / check_principal_moments(a)
        else:
            J = inertia_tensor(a)
            w = rel @ np.linalg.inv(J).T
        return np.cross(H, w) + tau, w
    except ValueError:
        named = [("H", H), ("torque", tau), ("rotor_momentum", h)]
        broadcast_named(who, *((n, x, 1 if x.ndim else 0) for n, x in named))
        raise


def attitude_state_rates(t, state, inertia, torque=None, rotor_momentum=None):
    """State-form right-hand side ``x' = f(t, x)`` with ``x = (q, w)`` of shape ``(..., 7)``.

    Baruh ch. 8 state form: Euler parameters (scalar first) and body rates.
    ``torque`` is ``None`` or a callable ``torque(t, q, w) -> (..., 3)`` body
    torque (N m); ``rotor_momentum`` is ``None``, a constant ``(3,)`` or a
    callable ``h(t) -> (3,)`` (its rate is then taken by a central difference
    of step ``1e-6 * max(1, |t|)`` s; pass constant rotors where possible).
    """
    x = real_array(state, "state", "attitude_state_rates")
    if x.shape[-1:] != (7,):
        raise ValueError(f"attitude_state_rates: state: expected shape (..., 7) = (q, w), got {x.shape}")
    q, w = x[..., :4], x[..., 4:]
    tau = 0.0 if torque is None else torque(t, q, w)
    h, hd = 0.0, 0.0
    if callable(rotor_momentum):
        d = 1e-6 * max(1.0, abs(t))
        h = np.asarray(rotor_momentum(t), dtype=np.float64)
        hd = (np.asarray(rotor_momentum(t + d)) - np.asarray(rotor_momentum(t - d))) / (2 * d)
    elif rotor_momentum is not None:
        h = np.asarray(rotor_momentum, dtype=np.float64)
    wd = angular_acceleration(inertia, w, tau, h, hd)
    return np.concatenate([quat_rate(q, w), wd], axis=-1)
