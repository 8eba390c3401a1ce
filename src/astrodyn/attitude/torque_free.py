"""Exact torque-free motion of a rigid body: rates and attitude in closed form.

:func:`torque_free` returns the body rates ``w(t)`` and Euler parameters
``q(t)`` of a free rigid body for any array of times, without integrating.
Cost per (body, time) is the same at ``t = 1 s`` and ``t = 1e9 s``.  Bodies
evaluated again and again (a service's step loop) are set up once as a
:class:`PreparedBody` (the per-body constants, :data:`BODY_DTYPE`).

Conventions (docs/architecture.md, section 2): principal moments ``inertia`` (kg m^2, any
order), body rates ``w`` (rad/s, body components), Euler parameters
``q = (e0, e1, e2, e3)`` scalar first with ``v_body = C(q) @ v_inertial`` and
``dC/dt = -[w x] C`` (H. Baruh, *Analytical Dynamics*, ch. 7).

The solution (Baruh ch. 10; Landau & Lifshitz, *Mechanics*, sec. 37; Celledoni,
Fasso, Safstrom & Zanna, SIAM J. Sci. Comput. 30 (2008) 2084):

1. **Rates.**  Order the axes so that ``A <= B <= C`` along the polhode family
   that holds: if ``H^2 > 2 T B`` the rates circulate about the major axis
   (it plays "3"), otherwise about the minor axis (the axes are relabelled
   ``(3, 2, 1)`` with one sign flipped to keep a right-handed frame, and every
   formula below holds with all moment differences negative).  Then
   ``w1 = e a1 cn(tau)``, ``w2 = rho e s a2 sn(tau)``, ``w3 = s a3 dn(tau)``
   with ``tau = tau0 + wp t``, ``s = sign w3``, ``rho = sign(C - B)`` (``-1``
   on the relabelled family), ``e = +-1`` (``+1`` except on the separatrix
   itself), parameter ``m`` and complement ``m1`` (Landau eq. 37.10):

   * ``a1^2 = w1^2 + B(C-B)/(A(C-A)) w2^2``, ``a2^2 = w2^2 + A(C-A)/(B(C-B)) w1^2``,
     ``a3^2 = w3^2 + B(B-A)/(C(C-A)) w2^2`` (sums of like-signed terms);
   * ``wp^2 = (C-B)(H^2 - 2TA)/(ABC)``, ``m = (B-A)(2TC - H^2)/((C-B)(H^2 - 2TA))``;
   * ``m1 = (C-A)(H^2 - 2TB)/((C-B)(H^2 - 2TA))`` with
     ``H^2 - 2TB = C(C-B) w3^2 - A(B-A) w1^2`` formed from the inputs, so the
     separatrix distance is never ``1 - m`` (it reaches 1e-18 for
     ``w0 = (1e-9, 1, 1e-9)``, ``I = (1, 2, 3)``).

   The initial phase ``tau0`` comes from ``(sn, cn, dn)`` at ``t = 0`` through
   Carlson's ``R_F`` (``F(phi) = sn R_F(cn^2, dn^2, 1)``, DLMF 19.25.5) with the
   quadrant from the sign of ``cn``; no amplitude angle is formed.

2. **Attitude.**  ``C(t) = Q(t) @ C_a(psi(t)) @ C_B0``: ``Q(t)`` is the
   smallest rotation taking the circulation axis ``a = s e3`` to the unit
   angular momentum ``h = I w / H`` in body components (it never degenerates:
   ``a . h > 0`` on every polhode), ``C_a(psi)`` is the frame rotation by
   ``psi`` about ``a``, and ``C_B0`` is fixed by ``q0``.  Kinematics give
   ``psi' = (2T + H |w3|)/(H + C |w3|)``; the decomposition
   ``1/(H + C a3 dn) = (H - C a3 dn)/(A^2 a1^2 (1 - n sn^2))`` integrates it
   exactly:

   ``psi = H t / A + k [ (H/C) (J(tau) - J(tau0)) - a3 (G(tau) - G(tau0)) ]``

   with ``k = (C - A)/(A wp)``, the constant characteristic
   ``n = -C(B - A)/(A(C - B)) <= 0`` (independent of the initial state),
   ``J(tau) = Pi(n; am tau|m) - tau = (n/3) sn^3 R_J(cn^2, dn^2, 1, 1 - n sn^2)``
   (DLMF 19.25.14; the ``R_F`` part of ``Pi`` is ``tau`` itself) and
   ``G = int dphi/(1 - n sin^2 phi) = atan2(sqrt(1-n) sn, cn)/sqrt(1-n)``.
   For ``n < -1`` (in particular nearly equal ``B, C``: slow circulation,
   ``wp ~ sqrt(C - B)``, ``k ~ 1/wp`` huge) the same angle is written
   ``psi = H t / C + k [ (H/C) (P(tau) - P(tau0)) - a3 (G(tau) - G(tau0)) ]`` with
   ``P = Pi(n; am tau|m)`` itself, evaluated through the reciprocal
   characteristic ``n2 = m/n`` (DLMF 19.7.9):
   ``P = atan2(g sn, cn dn)/g - (n2/3) sn^3 R_J(cn^2, dn^2, 1, 1 - n2 sn^2)``,
   ``g = sqrt(1 + m - n - n2)``.  ``P ~ 1/sqrt(-n)`` is small, so ``k P`` carries
   no cancellation; ``k (J - J0)`` with ``J ~ -tau`` lost ``|k| eps`` (1e-11 rad
   at a moment gap of 1e-9).

3. **Any t at fixed cost.**  ``tau`` is reduced by the half period ``2K``
   (``sn, cn`` change sign); each half period adds the constants
   ``2(Pi(n|m) - K) = (2n/3) R_J(0, m1, 1, 1 - n)`` to ``J`` (``2 Pi(n|m)`` to ``P``) and
   ``pi/sqrt(1 - n)`` to ``G``, computed once per body.

Special cases: zero rates and every uniform rotation (``w x I w = 0`` exactly:
pure spin about any principal axis, the intermediate one included, any spin of
a sphere, spin in the degenerate plane of an axisymmetric body) rotate
uniformly, ``C(t) = exp(-[w x] t) C0``.  Axisymmetric bodies give ``m = n = 0``
(closed form); a sphere perturbed by one ulp keeps exact moment differences
(Sterbenz) and finite coefficients.  On the separatrix itself (``m1 == 0``)
``sn = tanh``, ``cn = dn = sech``, ``J`` is elementary and nothing is periodic.

NaN in ``w0``, ``q0`` or ``t`` gives NaN rows, and so does a zero ``q0`` (a batch
of bodies keeps its good rows); moments that are not a rigid body's (non-finite,
non-positive, or violating the triangle inequality ``I1 + I2 >= I3``) raise
``ValueError`` through :func:`astrodyn.attitude.euler.check_principal_moments`, the
checker :func:`~astrodyn.attitude.integrators.propagate_attitude` uses too.  Any
nonzero ``q0`` is normalised (the convention of this module; ``propagate_attitude``
instead requires ``|q0| = 1`` to 1e-6, see its docstring).

Example (Dzhanibekov flip: spin near the intermediate axis reverses every half
period)::

    >>> import numpy as np
    >>> from astrodyn.attitude.torque_free import torque_free, flip_period
    >>> I, w0 = [1.0, 2.0, 3.0], [1e-3, 1.0, 1e-3]
    >>> T = flip_period(I, w0)
    >>> w, q = torque_free(I, w0, [1.0, 0, 0, 0], [0.0, T / 2, T])
    >>> np.round(w[:, 1], 6)
    array([ 1., -1.,  1.])
"""

from __future__ import annotations

import math

import numpy as np

from astrodyn.attitude.elliptic import ellipk_scalar, elliprf_scalar, elliprj_scalar, reduce_half_period, sncndn_half
from astrodyn.attitude.euler import TRIANGLE_SLACK, check_principal_moments
from astrodyn.inputs import broadcast_named, real_array
from astrodyn.jit import jit, parallel_kernel, prange
from astrodyn.rotation import quat_hamilton_scalar

__all__ = ["torque_free", "PreparedBody", "BODY_DTYPE", "polhode", "herpolhode", "rate_period", "flip_period"]

#: The constants of one body's exact solution, set once per body (:class:`PreparedBody`,
#: :func:`setup_all`) and read by every evaluation; a numpy structured dtype whose fields
#: numba reads by name.  Symbols as in the module docstring.  Its type is ``np.record``, so
#: an element's fields are attributes in plain Python too (``NUMBA_DISABLE_JIT=1``).
BODY_DTYPE = np.dtype((np.record, [
    ("mode", np.int64),  # 0: NaN state, 1: uniform rotation, 2: elliptic
    ("ia", np.int64), ("ib", np.int64), ("ic", np.int64),  # body indices of the ordered axes (ic: circulation axis)
    ("sb", np.float64),  # sign applied to the body's ib component (keeps the ordered frame right-handed)
    ("sig", np.float64),  # s = sign of the circulation-axis rate
    ("eps1", np.float64),  # e = sign of the cn branch (+1 except on the separatrix)
    ("sns", np.float64),  # sign of the sn component: rho e s, rho = sign(C - B) (-1 on the minor-axis family)
    ("a1", np.float64), ("a2", np.float64), ("a3", np.float64),  # rate amplitudes (rad/s)
    ("wp", np.float64),  # rate of the elliptic argument tau (rad/s)
    ("m", np.float64), ("m1", np.float64), ("K", np.float64),  # parameter, complement, K(m)
    ("tau0", np.float64),  # initial phase
    ("hmag", np.float64),  # |H| (kg m^2/s)
    ("lin", np.float64),  # H / A (H / C in the Pi form): the secular rate of psi
    ("kj", np.float64), ("kg", np.float64),  # k H / C and k a3: the weights of J and G in psi
    ("n", np.float64), ("sq1n", np.float64),  # characteristic n and sqrt(1 - n)
    ("j0", np.float64), ("g0", np.float64),  # J and G at t = 0
    ("dj", np.float64), ("dg", np.float64),  # increments of J and G per half period 2K
    ("pi_form", np.int64),  # 1: J holds Pi(n; am tau|m) itself (n < -1, see _j_g), else 0
    ("gpf", np.float64),  # sqrt(1 + m - n - m/n) (Pi form)
    ("qb0", np.float64, (4,)),  # Euler parameters of C_B0 (uniform mode: q0)
    ("w", np.float64, (3,)),  # constant rates (uniform mode)
    ("inertia", np.float64, (3,)),  # principal moments (kg m^2), body order
]))


# ---------------------------------------------------------------------------
# the two integrals of the precession angle


@jit
def _j_g(s, c, d, r, n, sq1n, m1, m, pf, gpf):
    """J = Pi(n; am r|m) - r (or, Pi form, Pi(n; am r|m) itself) and G = int_0^{am r} dphi/(1 - n sin^2 phi), |r| <= K.

    Pi form (``pf == 1``, used for ``n < -1``, the slowly circulating
    near-symmetric bodies where ``k = (C - A)/(A wp)`` is huge): Pi through the
    reciprocal-characteristic relation (DLMF 19.7.9 with ``n2 = m/n``; the two
    ``F`` cancel analytically, and ``R_C`` reduces to an ``atan2`` because
    ``y - x = sn^2 (1 + m - n - n2)`` exactly):
    ``Pi(n) = atan2(g sn, cn dn)/g - (n2/3) sn^3 R_J(cn^2, dn^2, 1, 1 - n2 sn^2)``,
    ``g = sqrt(1 + m - n - n2)``.  ``Pi ~ 1/sqrt(-n)`` is small there, so ``k Pi``
    carries no cancellation (``k (Pi - r)`` would lose ``|k| eps`` absolute).
    """
    if m1 == 0.0:  # separatrix: Pi(n; r|1) = r/(1-n) - n/(1-n) atan(sqrt(-n) tanh r)/sqrt(-n)
        if n == 0.0:
            jv = 0.0
        else:
            sn_ = math.sqrt(-n)
            jv = n / (1.0 - n) * (r - math.atan(sn_ * s) / sn_)
    elif pf == 1:
        n2 = m / n
        jv = math.atan2(gpf * s, c * d) / gpf
        if n2 != 0.0 and s != 0.0:
            jv -= n2 / 3.0 * s * s * s * elliprj_scalar(c * c, d * d, 1.0, 1.0 - n2 * s * s)
    elif n == 0.0 or s == 0.0:
        jv = 0.0
    else:
        jv = n / 3.0 * s * s * s * elliprj_scalar(c * c, d * d, 1.0, 1.0 - n * s * s)
    gv = math.atan2(sq1n * s, c) / sq1n
    return jv, gv


@jit
def _phase(p, t):
    """Reduced phase: (sn, cn, dn) at tau = tau0 + wp t with J(tau), G(tau) including whole half periods."""
    tau = p.tau0 + p.wp * t
    if p.m1 == 0.0:
        th = math.tanh(tau)
        sech = 1.0 / math.cosh(tau) if abs(tau) < 710.0 else 0.0
        jv, gv = _j_g(th, sech, sech, tau, p.n, p.sq1n, p.m1, p.m, 0, 0.0)
        return th, sech, sech, jv, gv
    j, r = reduce_half_period(tau, p.K)
    s, c, d = sncndn_half(r, p.m, p.m1)
    jv, gv = _j_g(s, c, d, r, p.n, p.sq1n, p.m1, p.m, p.pi_form, p.gpf)
    jv += j * p.dj
    gv += j * p.dg
    if j % 2.0 != 0.0:
        s = -s
        c = -c
    return s, c, d, jv, gv


@jit(inline="always")
def _unit(r0, r1, r2, r3):
    nrm = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2 + r3 * r3)
    return r0 / nrm, r1 / nrm, r2 / nrm, r3 / nrm


@jit
def _elliptic_state(p, t, s, c, d, jv, gv):
    """Rates and Euler parameters ``(w0, w1, w2, q0, q1, q2, q3)`` of an elliptic-mode body at
    time ``t`` from its reduced phase (:func:`_phase`)."""
    ia, ib, ic = p.ia, p.ib, p.ic
    sig = p.sig
    va = p.eps1 * p.a1 * c  # the rates along the ordered axes a, b, c, put back in body order
    vb = p.sb * p.sns * p.a2 * s
    vc = sig * p.a3 * d
    w0 = va if ia == 0 else (vb if ib == 0 else vc)
    w1 = va if ia == 1 else (vb if ib == 1 else vc)
    w2 = va if ia == 2 else (vb if ib == 2 else vc)
    # precession angle about the circulation axis
    psi = p.lin * t + p.kj * (jv - p.j0) - p.kg * (gv - p.g0)
    # Q(t): smallest rotation a -> h, as Euler parameters (1 + a.h, h x a) / norm
    hm = p.hmag
    h0 = p.inertia[0] * w0 / hm
    h1 = p.inertia[1] * w1 / hm
    h2 = p.inertia[2] * w2 / hm
    # qm = (1 + s h_c, s h x e_c) with (h x e_c)[j1] = h[j2], [j2] = -h[j1] (j1, j2 cyclic after c)
    half = 0.5 * psi
    cps = math.cos(half)
    sps = sig * math.sin(half)
    if ic == 0:
        qm = (1.0 + sig * h0, 0.0, sig * h2, -sig * h1)
        qc = (cps, sps, 0.0, 0.0)
    elif ic == 1:
        qm = (1.0 + sig * h1, -sig * h2, 0.0, sig * h0)
        qc = (cps, 0.0, sps, 0.0)
    else:
        qm = (1.0 + sig * h2, sig * h1, -sig * h0, 0.0)
        qc = (cps, 0.0, 0.0, sps)
    # C_a(psi) above: frame rotation by psi about a = s e_c
    # q = qB0 (x) qc (x) qm   <=>   C = Q C_a(psi) C_B0
    x0, x1, x2, x3 = quat_hamilton_scalar(qc[0], qc[1], qc[2], qc[3], qm[0], qm[1], qm[2], qm[3])
    b = p.qb0
    r0, r1, r2, r3 = quat_hamilton_scalar(b[0], b[1], b[2], b[3], x0, x1, x2, x3)
    q0, q1, q2, q3 = _unit(r0, r1, r2, r3)
    return w0, w1, w2, q0, q1, q2, q3


@jit
def _evaluate(p, t):
    """Rates (rad/s) and Euler parameters ``(w0, w1, w2, q0, q1, q2, q3)`` of body ``p`` at time ``t`` (s)."""
    nan = math.nan
    if p.mode == 0 or not (t == t):
        return nan, nan, nan, nan, nan, nan, nan
    if p.mode == 1:  # uniform rotation: C(t) = exp(-[w x] t) C0, q = q0 (x) (cos, n sin)
        w0, w1, w2 = p.w[0], p.w[1], p.w[2]
        b = p.qb0
        wn = math.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
        if wn == 0.0:
            return w0, w1, w2, b[0], b[1], b[2], b[3]
        half = 0.5 * wn * t
        sh = math.sin(half) / wn
        r0, r1, r2, r3 = quat_hamilton_scalar(b[0], b[1], b[2], b[3], math.cos(half), w0 * sh, w1 * sh, w2 * sh)
        q0, q1, q2, q3 = _unit(r0, r1, r2, r3)
        return w0, w1, w2, q0, q1, q2, q3
    s, c, d, jv, gv = _phase(p, t)
    return _elliptic_state(p, t, s, c, d, jv, gv)


@jit
def _setup(inertia, w0, q0, p):
    """The constants of body ``(inertia, w0, q0)`` into the record ``p`` (:data:`BODY_DTYPE`):
    mode 0 (NaN states) for a non-finite or zero input, mode 1 for a uniform rotation,
    else mode 2 with the constants of the elliptic solution (module docstring, 1-3)."""
    clear_body(p, inertia)
    ok, qn = finite_state_norm(inertia, w0, q0)
    if not ok:
        return
    if is_uniform_rotation(inertia, w0):
        p.mode = 1
        for i in range(4):
            p.qb0[i] = q0[i] / qn
        for i in range(3):
            p.w[i] = w0[i]
        return
    p.mode = 2
    ia, ib, ic, sb, sep = ordered_axes(inertia, w0)
    set_rate_constants(p, inertia, w0, ia, ib, ic, sb, sep)
    set_half_period_increments(p)
    set_initial_attitude(p, q0, qn)


@jit(inline="always")
def clear_body(p, inertia):
    """Record ``p`` as a mode-0 body (NaN states) of principal moments ``inertia`` (kg m^2):
    every constant zero (signs +1, axes in body order)."""
    p.mode = 0
    p.ia, p.ib, p.ic = 0, 1, 2
    p.sb = p.sig = p.eps1 = p.sns = 1.0
    p.a1 = p.a2 = p.a3 = p.wp = p.m = p.m1 = p.K = p.tau0 = 0.0
    p.hmag = p.lin = p.kj = p.kg = p.n = p.sq1n = p.j0 = p.g0 = p.dj = p.dg = p.gpf = 0.0
    p.pi_form = 0
    for i in range(4):
        p.qb0[i] = 0.0
    for i in range(3):
        p.w[i] = 0.0
        p.inertia[i] = inertia[i]


@jit(inline="always")
def finite_state_norm(inertia, w0, q0):
    """``(ok, |q0|)``: ok when the moments, rates (rad/s) and Euler parameters are finite
    and ``q0`` is not zero."""
    ok = True
    for i in range(3):
        if not (math.isfinite(w0[i]) and math.isfinite(inertia[i])):
            ok = False
    qn = 0.0
    for i in range(4):
        if not math.isfinite(q0[i]):
            ok = False
        qn += q0[i] * q0[i]
    return ok and qn != 0.0, math.sqrt(qn)


@jit(inline="always")
def is_uniform_rotation(inertia, w0):
    """True when ``w x (I w) == 0`` exactly: the body spins uniformly about ``w0``."""
    I0, I1, I2 = inertia[0], inertia[1], inertia[2]
    W0, W1, W2 = w0[0], w0[1], w0[2]
    cx = W1 * I2 * W2 - W2 * I1 * W1
    cy = W2 * I0 * W0 - W0 * I2 * W2
    cz = W0 * I1 * W1 - W1 * I0 * W0
    return cx == 0.0 and cy == 0.0 and cz == 0.0


@jit(inline="always")
def ordered_axes(inertia, w0):
    """``(ia, ib, ic, sb, sep)``: the body indices of the ordered axes (``ic`` the
    circulation axis: the major one if ``sep = H^2 - 2TB >= 0``, else the minor one) and
    the sign ``sb`` applied to the ``ib`` component to keep ``(ia, ib, ic)`` right-handed."""
    # ascending order i1, i2, i3 (stable)
    i1, i2, i3 = 0, 1, 2
    if inertia[i2] < inertia[i1]:
        i1, i2 = i2, i1
    if inertia[i3] < inertia[i2]:
        i2, i3 = i3, i2
    if inertia[i2] < inertia[i1]:
        i1, i2 = i2, i1
    A, B, Cc = inertia[i1], inertia[i2], inertia[i3]
    sep = Cc * (Cc - B) * w0[i3] ** 2 - A * (B - A) * w0[i1] ** 2  # H^2 - 2TB
    if sep >= 0.0:
        ia, ib, ic = i1, i2, i3
    else:
        ia, ib, ic = i3, i2, i1
    # sign making (ia, ib, ic) right-handed: even permutation of (0, 1, 2) <=> ib == (ia + 1) % 3
    sb = 1.0 if ib == (ia + 1) % 3 else -1.0
    return ia, ib, ic, sb, sep


@jit(inline="always")
def rate_amplitudes(Ia, Ib, Ic, wa, wb, wc, sep):
    """``(a1, a2, a3, wp, m, m1)``: the rate amplitudes (rad/s), the rate of the elliptic
    argument (rad/s), the parameter and its complement (module docstring, 1), from the
    moments (kg m^2) and rates (rad/s) along the ordered axes and ``sep = H^2 - 2TB``."""
    d31 = Ic - Ia
    d32 = Ic - Ib
    d21 = Ib - Ia
    p13 = Ia * d31 * wa * wa + Ib * d32 * wb * wb  # 2TC - H^2
    p31 = Ib * d21 * wb * wb + Ic * d31 * wc * wc  # H^2 - 2TA
    a1 = math.sqrt(wa * wa + (Ib * d32) / (Ia * d31) * wb * wb)
    a2 = math.sqrt(wb * wb + (Ia * d31) / (Ib * d32) * wa * wa)
    a3 = math.sqrt(wc * wc + (Ib * d21) / (Ic * d31) * wb * wb)
    wp = math.sqrt(d32 * p31 / (Ia * Ib * Ic))
    m = d21 * p13 / (d32 * p31)
    m1 = d31 * sep / (d32 * p31)
    m = min(max(m, 0.0), 1.0)
    m1 = min(max(m1, 0.0), 1.0)
    return a1, a2, a3, wp, m, m1


@jit(inline="always")
def initial_phase(wa, wb, wc, a1, a2, a3, rho, m1, K):
    """``(tau0, sig, e1, sns)``: the initial phase from ``(sn, cn, dn)`` at ``t = 0``
    (``F = sn R_F(cn^2, dn^2, 1)``, quadrant from ``cn``) and the signs ``s``, ``e`` and
    ``rho e s`` (module docstring, 1); ``rho = sign(C - B)``."""
    sig = 1.0 if wc > 0.0 else -1.0
    e1 = 1.0
    if m1 == 0.0 and wa < 0.0:
        e1 = -1.0
    cn0 = e1 * wa / a1
    sns = rho * e1 * sig
    sn0 = sns * wb / a2
    nr = math.sqrt(cn0 * cn0 + sn0 * sn0)
    cn0 /= nr
    sn0 /= nr
    dn0 = min(abs(wc) / a3, 1.0)
    f = sn0 * elliprf_scalar(cn0 * cn0, dn0 * dn0, 1.0)
    if cn0 >= 0.0:
        tau0 = f
    else:
        tau0 = math.copysign(2.0 * K, sn0) - f
    return tau0, sig, e1, sns


@jit(inline="always")
def set_rate_constants(p, inertia, w0, ia, ib, ic, sb, sep):
    """The rate solution and the weights of the precession angle (module docstring, 1-2)
    of an elliptic-mode body into ``p``, from its ordered axes (:func:`ordered_axes`)."""
    Ia, Ib, Ic = inertia[ia], inertia[ib], inertia[ic]
    wa, wb, wc = w0[ia], sb * w0[ib], w0[ic]
    a1, a2, a3, wp, m, m1 = rate_amplitudes(Ia, Ib, Ic, wa, wb, wc, sep)
    K = ellipk_scalar(m1)
    tau0, sig, e1, sns = initial_phase(wa, wb, wc, a1, a2, a3, 1.0 if Ic - Ib > 0.0 else -1.0, m1, K)
    n = -Ic * (Ib - Ia) / (Ia * (Ic - Ib))
    hmag = math.sqrt((inertia[0] * w0[0]) ** 2 + (inertia[1] * w0[1]) ** 2 + (inertia[2] * w0[2]) ** 2)
    kco = (Ic - Ia) / (Ia * wp)
    p.ia, p.ib, p.ic = ia, ib, ic
    p.sb = sb
    p.sig = sig
    p.eps1 = e1
    p.sns = sns
    p.a1, p.a2, p.a3 = a1, a2, a3
    p.wp = wp
    p.m, p.m1, p.K = m, m1, K
    p.tau0 = tau0
    p.hmag = hmag
    p.lin = hmag / Ia
    p.kj = kco * hmag / Ic
    p.kg = kco * a3
    p.n = n
    p.sq1n = math.sqrt(1.0 - n)


@jit(inline="always")
def set_half_period_increments(p):
    """The increments of ``J`` and ``G`` per half period ``2K`` into ``p`` (module docstring,
    3), and for ``n < -1`` the Pi form (see :func:`_j_g`); nothing on the separatrix."""
    m, m1, n, sq1n = p.m, p.m1, p.n, p.sq1n
    if m1 > 0.0 and n < -1.0:
        # Pi form (see _j_g): psi = (H/C) t + k [(H/C)(Pi - Pi0) - a3 (G - G0)]
        # (H/A - k (H/C) wp = H/C); per half period Pi gains 2 Pi(n|m)
        n2 = m / n
        gpf = math.sqrt(1.0 + m - n - n2)
        p.pi_form = 1
        p.gpf = gpf
        p.lin = p.hmag / p.inertia[p.ic]
        pk = 0.5 * math.pi / gpf
        if n2 != 0.0:
            pk -= n2 / 3.0 * elliprj_scalar(0.0, m1, 1.0, 1.0 - n2)
        p.dj = 2.0 * pk
        p.dg = math.pi / sq1n
    elif m1 > 0.0:
        p.dj = 2.0 * n / 3.0 * elliprj_scalar(0.0, m1, 1.0, 1.0 - n) if n != 0.0 else 0.0
        p.dg = math.pi / sq1n


@jit(inline="always")
def set_initial_attitude(p, q0, qn):
    """``J``, ``G`` at ``t = 0`` and ``C_B0`` into ``p`` from the initial Euler parameters
    ``q0`` (norm ``qn``), so that ``psi(0) == 0`` and the state at ``t = 0`` is ``q0``."""
    # J, G at tau0 through the same reduction as every later time (psi(0) == 0 exactly)
    s_, c_, d_, j0, g0 = _phase(p, 0.0)
    p.j0 = j0
    p.g0 = g0
    # C_B0 = Q(0)^T C(q0): the state at t = 0 with qB0 = identity, then qB0 = q0 (x) conj(qm0)
    p.qb0[0] = 1.0
    _, _, _, m0, m1_, m2, m3 = _elliptic_state(p, 0.0, s_, c_, d_, j0, g0)
    r0, r1, r2, r3 = quat_hamilton_scalar(q0[0] / qn, q0[1] / qn, q0[2] / qn, q0[3] / qn, m0, -m1_, -m2, -m3)
    p.qb0[0], p.qb0[1], p.qb0[2], p.qb0[3] = r0, r1, r2, r3


@jit
def _valid_inertia(inertia):
    """The test of :func:`astrodyn.attitude.euler.check_principal_moments` in compiled form (the
    scalar path's; the same arithmetic, so the two agree): finite, positive, and the sorted
    moments ``a <= b <= c`` with ``a + b >= c (1 - TRIANGLE_SLACK)``."""
    a, b, c = inertia[0], inertia[1], inertia[2]
    if not (math.isfinite(a) and math.isfinite(b) and math.isfinite(c)):
        return False
    if a > b:  # sort the three (a sorting network)
        a, b = b, a
    if b > c:
        b, c = c, b
    if a > b:
        a, b = b, a
    return a > 0.0 and not (a + b < c * (1.0 - TRIANGLE_SLACK))


@parallel_kernel("torque_free_setup")
def setup_all(inertia, w0, q0, bodies):
    """The constants ``bodies[b]`` (:data:`BODY_DTYPE`) of bodies ``(inertia[b], w0[b], q0[b])``
    (rows of ``(n, 3)``, ``(n, 3)``, ``(n, 4)``); call as ``setup_all(n, ...)`` (the work
    decides serial or parallel, :mod:`astrodyn.jit`)."""
    for b in prange(inertia.shape[0]):
        _setup(inertia[b], w0[b], q0[b], bodies[b])


@parallel_kernel("torque_free")
def evaluate_all(bodies, t, w_out, q_out):
    """Rates ``w_out[b, i]`` and Euler parameters ``q_out[b, i]`` of the prepared ``bodies`` at the
    times ``t[i]``; call as ``evaluate_all(n_bodies * n_times, ...)``."""
    nb = bodies.shape[0]
    nt = t.shape[0]
    for k in prange(nb * nt):
        b = k // nt
        i = k - b * nt
        w, q = w_out[b, i], q_out[b, i]
        w[0], w[1], w[2], q[0], q[1], q[2], q[3] = _evaluate(bodies[b], t[i])


@jit
def _state_of_new_body(inertia, w0, q0, t, w, q):
    """One body, one time, set up and evaluated into ``w``, ``q`` in one compiled call (the
    scalar path of :func:`torque_free`); False (and NaN rows) for moments that must be refused."""
    body = np.empty(1, dtype=BODY_DTYPE)
    _setup(inertia, w0, q0, body[0])
    ok = _valid_inertia(inertia)
    if not ok:
        body[0].mode = 0
    w[0], w[1], w[2], q[0], q[1], q[2], q[3] = _evaluate(body[0], t)
    return ok


# ---------------------------------------------------------------------------
# public API


def _as_rows(inertia, w0, q0):
    inertia = real_array(inertia, "inertia", "torque_free")
    w0 = real_array(w0, "w0", "torque_free")
    q0 = real_array(q0, "q0", "torque_free")
    if inertia.ndim < 1 or inertia.shape[-1] != 3:
        raise ValueError(f"inertia: expected principal moments of shape (..., 3), three per body (kg m^2; not an "
                         f"inertia tensor), got shape {inertia.shape}")
    if w0.ndim < 1 or w0.shape[-1] != 3:
        raise ValueError(f"w0: expected body rates of shape (..., 3) rad/s, got shape {w0.shape}")
    if q0.ndim < 1 or q0.shape[-1] != 4:
        raise ValueError(f"q0: expected Euler parameters of shape (..., 4), scalar first, got shape {q0.shape}")
    _check_inertia(inertia)
    return inertia, w0, q0


def _check_inertia(inertia):
    """:func:`~astrodyn.attitude.euler.check_principal_moments`; for several rows the error says
    that they are read as several bodies: a ``(3, 3)`` inertia tensor passed here is taken as
    three bodies' principal moments, and its off-diagonal zeros were reported as a moment
    "not positive" with nothing saying why."""
    try:
        check_principal_moments(inertia, "inertia")
    except ValueError as exc:
        if inertia.ndim < 2:
            raise
        bodies = " x ".join(str(n) for n in inertia.shape[:-1])
        raise ValueError(f"{exc}; inertia of shape {inertia.shape} is read as the principal moments of {bodies} "
                         f"bodies, one row of 3 each: torque_free takes no inertia tensor (for a (3, 3) tensor, "
                         f"astrodyn.attitude.principal_axes gives its principal moments and axes; express w0 "
                         f"and q0 in those axes)") from None


def _times(t):
    t_arr = real_array(t, "t", "torque_free")
    if t_arr.ndim > 1:
        raise ValueError(f"t: expected a scalar or a 1-D array of times (s), got shape {t_arr.shape}")
    return t_arr.ndim == 0, np.ascontiguousarray(t_arr.reshape(-1))


class PreparedBody:
    """Torque-free bodies set up once, evaluated at any times: the per-body constants of
    the exact solution (ordered axes, amplitudes, ``m``, ``K(m)``, the initial phase, the
    ``J``/``G`` constants and ``C_B0``; :data:`BODY_DTYPE`) are computed here, and
    :meth:`states` evaluates only the time-dependent part (227 ns per body and time
    against 745 ns for a new state, one thread; docs/benchmarks.md).  A service holds one per scene for its torque-free bodies.

    ``inertia`` (..., 3) kg m^2, ``w0`` (..., 3) rad/s, ``q0`` (..., 4) scalar first: as
    :func:`torque_free`, whose results :meth:`states` reproduces bit for bit.
    """

    __slots__ = ("bodies", "shape")

    def __init__(self, inertia, w0, q0):
        inertia, w0, q0 = _as_rows(inertia, w0, q0)
        self.shape = broadcast_named("torque_free", ("inertia", inertia, 1), ("w0", w0, 1), ("q0", q0, 1))
        rows = [np.ascontiguousarray(np.broadcast_to(a, self.shape + (a.shape[-1],))).reshape(-1, a.shape[-1])
                for a in (inertia, w0, q0)]
        self.bodies = np.empty(rows[0].shape[0], dtype=BODY_DTYPE)
        setup_all(rows[0].shape[0], *rows, self.bodies)

    def states(self, t):
        """``(w, q)`` at the times ``t`` (s, scalar or 1-D): shapes ``(..., N, 3)`` and
        ``(..., N, 4)``, or ``(..., 3)`` and ``(..., 4)`` for a scalar ``t`` (as :func:`torque_free`)."""
        scalar_t, t_flat = _times(t)
        nb, nt = self.bodies.shape[0], t_flat.shape[0]
        w = np.empty((nb, nt, 3))
        q = np.empty((nb, nt, 4))
        evaluate_all(nb * nt, self.bodies, t_flat, w, q)
        if scalar_t:
            return w.reshape(self.shape + (3,)), q.reshape(self.shape + (4,))
        return w.reshape(self.shape + (nt, 3)), q.reshape(self.shape + (nt, 4))


def torque_free(inertia, w0, q0, t):
    """Exact torque-free rates and attitude of a rigid body at the times ``t``.

    Parameters
    ----------
    inertia : array_like, shape (..., 3)
        Principal moments of inertia (kg m^2), any order, finite, positive and
        satisfying the triangle inequality (a rigid body's; else ``ValueError``).
        The last axis holds the three moments of one body, every leading axis is a
        batch of bodies: a ``(3, 3)`` array is **three bodies**, not an inertia
        tensor (which :func:`~astrodyn.attitude.integrators.propagate_attitude` also
        takes).  For a tensor, :func:`astrodyn.attitude.principal_axes` gives its
        principal moments and axes ``P``; the rates and attitude here are then those
        of the principal-axis frame (``w0_principal = P.T @ w0_body``).
    w0 : array_like, shape (..., 3)
        Body angular velocity at ``t = 0`` (rad/s, body principal axes).
    q0 : array_like, shape (..., 4)
        Euler parameters at ``t = 0``, scalar first, ``v_body = C(q0) @ v_inertial``.
        Any nonzero ``q0`` is accepted and normalised (``q0 / |q0|`` is the initial
        attitude); a zero ``q0`` gives NaN rows.  Note the difference from
        :func:`~astrodyn.attitude.integrators.propagate_attitude`, which requires
        ``|q0| = 1`` to 1e-6 (and raises ``ValueError`` otherwise).
    t : array_like, shape (N,) or scalar
        Times (s) relative to the initial state; any sign, any order.

    Returns
    -------
    w : ndarray, shape (..., N, 3)   (``(..., 3)`` for scalar ``t``)
        Body rates (rad/s).
    q : ndarray, shape (..., N, 4)   (``(..., 4)`` for scalar ``t``)
        Euler parameters, unit to rounding.

    Leading (batch) axes of ``inertia``, ``w0``, ``q0`` broadcast; a single
    body gives ``(N, 3)`` and ``(N, 4)`` as in docs/architecture.md section 2.  The method
    and its accuracy are described in the module docstring.  One body at one time takes
    one compiled call; bodies evaluated again and again are cheaper as a :class:`PreparedBody`.
    """
    inertia = real_array(inertia, "inertia", "torque_free")
    w0 = real_array(w0, "w0", "torque_free")
    q0 = real_array(q0, "q0", "torque_free")
    if isinstance(t, (float, int)) and type(t) is not bool and inertia.shape == (3,) and w0.shape == (3,) and q0.shape == (4,):
        w, q = np.empty(3), np.empty(4)
        if not _state_of_new_body(inertia, w0, q0, float(t), w, q):
            _check_inertia(inertia)  # raises (the same test, with the message)
            raise AssertionError("unreachable: _valid_inertia and check_principal_moments disagree")
        return w, q
    return PreparedBody(inertia, w0, q0).states(t)


def rate_period(inertia, w0):
    """Period ``4 K(m) / wp`` (s) of the body rates along their polhode.

    ``inf`` on the separatrix (``m1 = 0``) and for uniform rotation (constant
    rates).  For an axisymmetric body it is ``2 pi / wp``, the period of the
    rates' precession about the symmetry axis.  Shape: the broadcast leading
    shape of ``inertia`` and ``w0``.
    """
    prepared = PreparedBody(inertia, w0, np.array([1.0, 0.0, 0.0, 0.0]))
    b = prepared.bodies
    out = np.where(
        b["mode"] == 2,
        4.0 * b["K"] / np.where(b["wp"] > 0, b["wp"], np.nan),
        np.where(b["mode"] == 1, np.inf, np.nan),
    )
    return out.reshape(prepared.shape) if prepared.shape else float(out[0])


def flip_period(inertia, w0):
    """Flip period ``4 K(m) / wp`` (s) of a spin near the intermediate axis (Dzhanibekov effect).

    The time for the rate along the intermediate axis to reverse and return;
    successive reversals are half of it apart.  The same number as
    :func:`rate_period` (given its own name for the intermediate-axis case).
    """
    return rate_period(inertia, w0)


def polhode(inertia, w0, n=256):
    """The polhode: ``n`` body-rate samples (rad/s, shape ``(n, 3)``) over one rate period.

    The curve traced by ``w`` on the intersection of the energy ellipsoid
    ``w . I w = 2T`` and the momentum sphere ``|I w| = H`` (Baruh ch. 10),
    equally spaced in time from ``w0``.  On the separatrix (infinite period)
    the samples cover ``tau0 +- 20`` in elliptic argument, which reaches the
    intermediate-axis equilibria to 1e-8; a uniform rotation gives ``n``
    copies of ``w0``.
    """
    inertia = real_array(inertia, "inertia", "polhode")
    w0 = real_array(w0, "w0", "polhode")
    if inertia.shape != (3,) or w0.shape != (3,):
        raise ValueError("inertia, w0: expected shape (3,) each (one body)")
    if isinstance(n, (bool, np.bool_)) or not isinstance(n, (int, np.integer)) or n < 1:
        raise ValueError(f"n: expected a positive integer number of samples, got {n!r}")
    n = int(n)
    prepared = PreparedBody(inertia, w0, np.array([1.0, 0.0, 0.0, 0.0]))
    p = prepared.bodies[0]
    if p["mode"] != 2:
        return np.tile(w0, (n, 1)) if p["mode"] == 1 else np.full((n, 3), np.nan)
    if p["m1"] == 0.0:
        t = (np.linspace(-20.0, 20.0, n) - p["tau0"]) / p["wp"]
    else:
        t = np.arange(n) * (4.0 * p["K"] / p["wp"] / n)
    return prepared.states(t)[0]


def herpolhode(inertia, w0, q0, t):
    """The herpolhode: angular velocity in inertial components ``C(q)^T w`` (rad/s) at ``t``.

    Its tip stays on the invariable plane ``w_inertial . H_hat = 2T / |H|``
    (Poinsot's construction, Baruh ch. 10).  Shape ``(len(t), 3)``.
    """
    from astrodyn.rotation import quat_conjugate, quat_rotate

    w, q = torque_free(inertia, w0, q0, t)
    return quat_rotate(quat_conjugate(q), w)
