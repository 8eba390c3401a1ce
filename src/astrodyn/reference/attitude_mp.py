"""Independent 30+ digit reference for torque-free rigid-body motion (mpmath Taylor series).

Integrates, in mpmath arithmetic, Euler's equations for a principal-axis body
together with the attitude kinematics of docs/architecture.md, section 2:

    I dw/dt + w x (I w) = 0,
    dq/dt = Omega(w) q / 2:  de0/dt = -e.w/2,  de/dt = (e0 w + e x w)/2,

the Euler-parameter form of ``dC/dt = -[w x] C`` (H. Baruh, *Analytical
Dynamics*, ch. 7 and 8; ``v_body = C(q) @ v_inertial``, ``w`` body rates in
rad/s).  Each step is a Taylor polynomial of fixed order whose coefficients
come from the recursion of the products (automatic differentiation by Cauchy
products, each one ``mpmath.fdot`` with a single rounding):

    L_{k+1} = sum_{j<=k} L_j x W_{k-j} / (k + 1),   W_k = L_k / I   (L = I w)
    Q_{k+1} = sum_{j<=k} Omega(W_{k-j}) Q_j / (2 (k + 1))

Step size ``h = rho / Omega`` with ``Omega = |w0| max(I)/min(I)`` (a bound on
``|w(t)|``) and ``rho = 0.2``: the rates are elliptic functions whose nearest
complex singularity is at least ``pi/(2 wp) >= pi/(2 Omega)`` away, so an
order-32 truncation leaves about ``(0.2 * 2/pi)^32 ~ 1e-29`` per step.  Steps
land exactly on the requested output times; ``q`` is never renormalised (its
norm drift stays at the working precision).

Shares no code with :mod:`astrodyn.attitude`; slow by design (about 10 ms per
step at order 32): use short spans and few output times.
"""

from __future__ import annotations

import mpmath as mp
import numpy as np

__all__ = ["torque_free_reference"]


def _dcm_from_quat_mp(q):
    """C(q) = (e0^2 - e.e) I + 2 e e^T - 2 e0 [e x] (Baruh ch. 7), in mpmath."""
    e0, e1, e2, e3 = q
    n = mp.sqrt(e0 * e0 + e1 * e1 + e2 * e2 + e3 * e3)
    e0, e1, e2, e3 = e0 / n, e1 / n, e2 / n, e3 / n
    d = e0 * e0 - e1 * e1 - e2 * e2 - e3 * e3
    return [
        [d + 2 * e1 * e1, 2 * (e1 * e2 + e0 * e3), 2 * (e1 * e3 - e0 * e2)],
        [2 * (e2 * e1 - e0 * e3), d + 2 * e2 * e2, 2 * (e2 * e3 + e0 * e1)],
        [2 * (e3 * e1 + e0 * e2), 2 * (e3 * e2 - e0 * e1), d + 2 * e3 * e3],
    ]


def _step(I, w, q, h, order):
    """Advance (w, q) by h with Taylor polynomials of the given order.

    Coefficient recursions (Cauchy products, each a single ``mp.fdot``):
    ``L = I w``, ``L' = L x w``; ``de0/dt = -e.w/2``, ``de/dt = (e0 w + e x w)/2``.
    """
    fdot = mp.fdot
    W = [list(w)]  # W[k][i]: k-th Taylor coefficient of w_i
    nW = [[-x for x in w]]
    L = [[I[i] * w[i] for i in range(3)]]
    Q = [list(q)]
    for k in range(order):
        rev = range(k, -1, -1)
        w0r = [W[j][0] for j in rev]
        w1r = [W[j][1] for j in rev]
        w2r = [W[j][2] for j in rev]
        n0r = [nW[j][0] for j in rev]
        n1r = [nW[j][1] for j in rev]
        n2r = [nW[j][2] for j in rev]
        L0 = [L[j][0] for j in range(k + 1)]
        L1 = [L[j][1] for j in range(k + 1)]
        L2 = [L[j][2] for j in range(k + 1)]
        e0 = [Q[j][0] for j in range(k + 1)]
        e1 = [Q[j][1] for j in range(k + 1)]
        e2 = [Q[j][2] for j in range(k + 1)]
        e3 = [Q[j][3] for j in range(k + 1)]
        # (L x w) Cauchy product
        c = k + 1
        Lk = [
            fdot(L1 + L2, w2r + n1r) / c,
            fdot(L2 + L0, w0r + n2r) / c,
            fdot(L0 + L1, w1r + n0r) / c,
        ]
        half = 2 * c
        Qk = [
            fdot(e1 + e2 + e3, n0r + n1r + n2r) / half,
            fdot(e0 + e2 + e3, w0r + w2r + n1r) / half,
            fdot(e0 + e3 + e1, w1r + w0r + n2r) / half,
            fdot(e0 + e1 + e2, w2r + w1r + n0r) / half,
        ]
        Wk = [Lk[i] / I[i] for i in range(3)]
        L.append(Lk)
        W.append(Wk)
        nW.append([-x for x in Wk])
        Q.append(Qk)
    wn = list(W[order])
    qn = list(Q[order])
    for k in range(order - 1, -1, -1):
        wn = [wn[i] * h + W[k][i] for i in range(3)]
        qn = [qn[i] * h + Q[k][i] for i in range(4)]
    return wn, qn


def torque_free_reference(inertia, w0, q0, t, dps=34, order=32, rho=0.2):
    """Torque-free ``(w, C, q)`` at the times ``t`` (s), integrated at ``dps`` digits.

    Parameters
    ----------
    inertia : (3,) principal moments (kg m^2).
    w0 : (3,) body rates at ``t = 0`` (rad/s).
    q0 : (4,) Euler parameters at ``t = 0``, scalar first (normalised here).
    t : (N,) output times (s), all ``>= 0`` or all ``<= 0``, any order.
    dps, order, rho : working decimal digits, Taylor order, step ``rho / Omega``.

    Returns float64 arrays ``w (N, 3)``, ``C (N, 3, 3)`` (``v_body = C v_inertial``)
    and ``q (N, 4)`` (the integrated Euler parameters, continuous in t, so the
    sign is that of ``q0`` carried along).
    """
    t = np.asarray(t, dtype=np.float64).reshape(-1)
    if np.any(t > 0) and np.any(t < 0):
        raise ValueError("t: expected all times >= 0 or all <= 0 (one integration direction)")
    with mp.workdps(dps):
        I = [mp.mpf(float(x)) for x in inertia]
        w = [mp.mpf(float(x)) for x in w0]
        q = [mp.mpf(float(x)) for x in q0]
        qn = mp.sqrt(sum(x * x for x in q))
        q = [x / qn for x in q]
        wmag = mp.sqrt(sum(x * x for x in w))
        omega = wmag * max(I) / min(I)
        hmax = rho / omega if omega > 0 else mp.inf
        order_idx = np.argsort(np.abs(t), kind="stable")
        out_w = np.empty((t.size, 3))
        out_C = np.empty((t.size, 3, 3))
        out_q = np.empty((t.size, 4))
        tcur = mp.mpf(0)
        for idx in order_idx:
            target = mp.mpf(float(t[idx]))
            span = target - tcur
            if span != 0:
                nsub = 1 if hmax == mp.inf else int(mp.ceil(abs(span) / hmax))
                h = span / nsub
                for _ in range(nsub):
                    w, q = _step(I, w, q, h, order)
                tcur = target
            out_w[idx] = [float(x) for x in w]
            out_C[idx] = [[float(x) for x in row] for row in _dcm_from_quat_mp(q)]
            out_q[idx] = [float(x) for x in q]
    return out_w, out_C, out_q
