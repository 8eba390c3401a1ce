"""Gyrostats: a rigid body carrying axisymmetric rotors (momentum wheels, dual-spin satellites).

Model (H. Baruh, *Analytical Dynamics*, ch. 10, gyroscopic systems; P. C. Hughes,
*Spacecraft Attitude Dynamics*, ch. 7): rotors ``k = 1..n`` spin about fixed
body axes ``a_k`` (unit, body components) with axial moments ``I_k`` (kg m^2)
and speeds ``Omega_k`` (rad/s) **relative to the body**.  ``inertia`` is the
inertia tensor of the whole vehicle with the rotors held fixed (kg m^2, body
axes, about the centre of mass).  The total angular momentum in body axes is

    H = inertia @ w + h,    h = sum_k I_k Omega_k a_k

and Euler's equations read ``inertia w' + w x (inertia w + h) = tau - h'``.

Two ways to drive the rotors:

* **commanded speed** ``Omega_k(t)`` (an ideal speed loop): ``h(t)`` is known and
  the body sees ``H = inertia w + h(t)``;
* **given motor torque** ``g_k`` (constant, N m, acting on rotor k, reacting on
  the body): the rotor's *absolute* axial momentum ``h_k^abs = I_k (a_k.w + Omega_k)``
  obeys ``dh_k^abs/dt = g_k`` exactly, so ``h_k^abs(t) = h_k^abs(0) + g_k t`` and
  ``H = (inertia - sum_k I_k a_k a_k^T) w + sum_k h_k^abs(t) a_k``.

Both reduce to the same form ``H = I_kin w + h(t)`` with known ``h(t)``, which the
splitting integrator handles with exact rotations
(:func:`~astrodyn.attitude.integrators.propagate_attitude` with ``rotor_momentum``).

Linear stability of a steady spin ``w = Omega e_i`` about principal axis ``i``
with rotor momentum ``h`` along the same axis (Hughes ch. 7; Baruh ch. 10): with
``j, k`` the other two axes,

    (h + (I_i - I_j) Omega) (h + (I_i - I_k) Omega) > 0.

For ``h = 0`` this is the rigid body's rule (spin about the major or minor axis);
a large enough ``h`` stabilises spin about the intermediate axis.  The transverse
motion then oscillates at ``sqrt(product / (I_j I_k))`` rad/s, or grows like
``exp(sqrt(-product / (I_j I_k)) t)`` when the product is negative.
"""

from __future__ import annotations

import numpy as np

from astrodyn.attitude.euler import inertia_tensor

__all__ = ["Gyrostat", "spin_stability_product", "spin_transverse_rate"]


def spin_stability_product(inertia, spin, rotor_momentum, axis):
    """``(h + (I_i - I_j) Omega)(h + (I_i - I_k) Omega)`` (N^2 m^2 s^2): > 0 stable, < 0 unstable.

    ``inertia`` principal moments ``(3,)`` kg m^2, ``spin`` ``Omega`` rad/s about
    principal ``axis`` (0, 1 or 2), ``rotor_momentum`` ``h`` N m s along that axis.
    Vectorized over ``spin`` and ``rotor_momentum``.
    """
    I = np.asarray(inertia, dtype=np.float64)
    if I.shape != (3,):
        raise ValueError(f"inertia: expected principal moments (3,), got shape {I.shape}")
    if axis not in (0, 1, 2):
        raise ValueError(f"axis: expected 0, 1 or 2, got {axis!r}")
    i, j, k = axis, (axis + 1) % 3, (axis + 2) % 3
    w = np.asarray(spin, dtype=np.float64)
    h = np.asarray(rotor_momentum, dtype=np.float64)
    return (h + (I[i] - I[j]) * w) * (h + (I[i] - I[k]) * w)


def spin_transverse_rate(inertia, spin, rotor_momentum, axis):
    """Transverse rate of the linearised motion (rad/s): ``sqrt(|product| / (I_j I_k))``.

    An oscillation frequency when :func:`spin_stability_product` is positive, an
    exponential growth rate when it is negative.
    """
    I = np.asarray(inertia, dtype=np.float64)
    j, k = (axis + 1) % 3, (axis + 2) % 3
    return np.sqrt(np.abs(spin_stability_product(I, spin, rotor_momentum, axis)) / (I[j] * I[k]))


class Gyrostat:
    """A rigid body with rotors about fixed body axes.

    Parameters
    ----------
    inertia : array_like
        ``(3,)`` principal moments or ``(3, 3)`` tensor of the whole vehicle, rotors
        locked, body axes, kg m^2.
    rotor_axes : array_like ``(n, 3)``
        Rotor spin axes in body components (normalised here).
    rotor_inertia : array_like ``(n,)``
        Axial moment of each rotor, kg m^2.
    """

    def __init__(self, inertia, rotor_axes, rotor_inertia):
        self.inertia = inertia_tensor(inertia)
        a = np.atleast_2d(np.asarray(rotor_axes, dtype=np.float64))
        if a.ndim != 2 or a.shape[1] != 3:
            raise ValueError(f"rotor_axes: expected shape (n, 3) body unit vectors, got {np.shape(rotor_axes)}")
        n = np.linalg.norm(a, axis=1)
        if not np.all(n > 0):
            raise ValueError("rotor_axes: every axis must be a nonzero vector")
        self.rotor_axes = a / n[:, None]
        Ik = np.atleast_1d(np.asarray(rotor_inertia, dtype=np.float64))
        if Ik.shape != (len(a),) or not np.all(Ik > 0):
            raise ValueError(f"rotor_inertia: expected {len(a)} positive axial moments (kg m^2), got {rotor_inertia!r}")
        self.rotor_inertia = Ik

    def _rotor_array(self, x, name):
        x = np.asarray(x, dtype=np.float64)
        if x.shape[-1:] != (len(self.rotor_inertia),):
            raise ValueError(f"{name}: expected one value per rotor, shape (..., {len(self.rotor_inertia)}), got {x.shape}")
        return x

    def rotor_momentum(self, rotor_speed):
        """``h = sum_k I_k Omega_k a_k`` (N m s, body axes) from relative rotor speeds ``(..., n)`` rad/s."""
        return (self._rotor_array(rotor_speed, "rotor_speed") * self.rotor_inertia) @ self.rotor_axes

    def propagate(self, w0, q0, t, rotor_speed=None, motor_torque=None, rotor_speed0=None, torque=None, method="split4", **kwargs):
        """Propagate with commanded ``rotor_speed`` **or** constant ``motor_torque``.

        ``rotor_speed``: ``(n,)`` constant or callable ``Omega(t) -> (len(t), n)``
        rad/s relative to the body.  ``motor_torque``: ``(n,)`` N m on the rotors,
        with ``rotor_speed0`` ``(n,)`` the initial relative speeds.  Other
        arguments as :func:`~astrodyn.attitude.integrators.propagate_attitude`.
        Returns ``(w, q, rotor_speed, info)``; rotor speeds ``(len(t), n)`` rad/s.
        """
        from astrodyn.attitude.integrators import propagate_attitude

        t_arr = np.atleast_1d(np.asarray(t, dtype=np.float64))
        if (rotor_speed is None) == (motor_torque is None):
            raise ValueError("rotor_speed, motor_torque: give exactly one (commanded speed or constant motor torque)")
        if rotor_speed is not None:
            if callable(rotor_speed):

                def h_of_t(tt):
                    return self.rotor_momentum(rotor_speed(np.atleast_1d(tt)))

                speeds = self._rotor_array(rotor_speed(t_arr), "rotor_speed")
            else:
                hc = self.rotor_momentum(rotor_speed)
                speeds = np.broadcast_to(self._rotor_array(rotor_speed, "rotor_speed"), (len(t_arr), len(self.rotor_inertia)))
                h_of_t = hc
            w, q, info = propagate_attitude(self.inertia, w0, q0, t_arr, torque=torque, rotor_momentum=h_of_t, method=method, **kwargs)
            return w, q, np.array(speeds), info
        g = self._rotor_array(motor_torque, "motor_torque")
        if rotor_speed0 is None:
            raise ValueError("rotor_speed0: needed with motor_torque (initial rotor speeds relative to the body, rad/s)")
        s0 = self._rotor_array(rotor_speed0, "rotor_speed0")
        Ik, A = self.rotor_inertia, self.rotor_axes
        habs0 = Ik * (A @ np.asarray(w0, dtype=np.float64) + s0)
        I_kin = self.inertia - (A.T * Ik) @ A

        def habs(tt):
            return habs0 + np.asarray(tt, dtype=np.float64)[..., None] * g

        w, q, info = propagate_attitude(I_kin, w0, q0, t_arr, torque=torque, rotor_momentum=lambda tt: habs(tt) @ A, method=method, **kwargs)
        speeds = habs(t_arr) / Ik - w @ A.T
        return w, q, speeds, info
