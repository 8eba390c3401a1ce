"""The prepared-body path of the exact torque-free solution (issue 15): PreparedBody (the
per-body constants set once) and the single-body scalar path of torque_free, checked
against the general batched path (bit for bit: same formulas, different loops) and against
the 30-digit mpmath Taylor reference of astrodyn.reference.attitude_mp."""

from __future__ import annotations

import functools

import numpy as np
import pytest

from astrodyn.attitude import torque_free
from astrodyn.attitude.torque_free import BODY_DTYPE, PreparedBody
from astrodyn.reference.attitude_mp import torque_free_reference
from astrodyn.rotation import dcm_from_quat

EPS = np.finfo(float).eps
Q0 = np.array([0.9, 0.1, -0.3, 0.2]) / np.linalg.norm([0.9, 0.1, -0.3, 0.2])

# (name, inertia, w0): every mode and family of the solution
CASES = [
    ("triaxial major-axis family", (1.0, 2.0, 3.0), (0.3, 0.2, 1.0)),
    ("triaxial minor-axis family", (1.0, 2.0, 3.0), (1.0, 0.2, 0.3)),
    ("Dzhanibekov, near the separatrix", (1.0, 2.0, 3.0), (1e-3, 1.0, 1e-3)),
    ("moments in any order", (3.0, 1.0, 2.0), (0.2, 0.7, -0.4)),
    ("axisymmetric", (2.0, 2.0, 3.0), (0.3, 0.2, 1.0)),
    ("near-axisymmetric, Pi form", (1.0, 1.0 + 1e-9, 2.0), (0.3, 0.2, 1.0)),
    ("pure spin about the intermediate axis", (1.0, 2.0, 3.0), (0.0, 1.0, 0.0)),
    ("zero rates", (1.0, 2.0, 3.0), (0.0, 0.0, 0.0)),
    ("sphere", (2.0, 2.0, 2.0), (0.3, -0.2, 0.5)),
]
TIMES = np.array([0.0, 0.5, 3.0, 17.25])


@functools.cache
def _reference(inertia, w0):
    w, C, _ = torque_free_reference(inertia, w0, Q0, TIMES, dps=30, order=28)
    return w, C


@pytest.mark.parametrize("name, inertia, w0", CASES, ids=[c[0] for c in CASES])
def test_prepared_and_scalar_paths_against_mpmath(name, inertia, w0):
    """Both paths within 100x the one-ulp sensitivity of the 30-digit reference (the
    tolerances of test_torque_free: |w| (1 + |w| t) eps for the rates, (1 + |w| t + K) eps
    for the attitude, K <= 10 for these cases)."""
    w_ref, C_ref = _reference(inertia, w0)
    wmag = max(1e-300, float(np.linalg.norm(w0)))
    w_p, q_p = PreparedBody(inertia, w0, Q0).states(TIMES)
    for i, t in enumerate(TIMES):
        w_s, q_s = torque_free(np.array(inertia), np.array(w0), Q0, float(t))
        tol_w = 100 * EPS * wmag * (1 + wmag * t)
        tol_C = 100 * EPS * (1 + wmag * t + 10.0)
        for w, q in ((w_p[i], q_p[i]), (w_s, q_s)):
            assert np.abs(w - w_ref[i]).max() <= tol_w, (name, t)
            assert np.abs(dcm_from_quat(q) - C_ref[i]).max() <= tol_C, (name, t)


@pytest.mark.parametrize("name, inertia, w0", CASES, ids=[c[0] for c in CASES])
def test_scalar_path_equals_batched_path(name, inertia, w0):
    """The one-body kernel and the batched setup/evaluate loops give the same bits."""
    batch_w, batch_q = torque_free(np.array([inertia, inertia]), np.array([w0, w0]), Q0, TIMES)
    for i, t in enumerate(TIMES):
        w_s, q_s = torque_free(np.array(inertia), np.array(w0), Q0, float(t))
        np.testing.assert_array_equal(w_s, batch_w[1, i])
        np.testing.assert_array_equal(q_s, batch_q[1, i])


def test_prepared_body_reused_equals_fresh_calls():
    """A body prepared once and evaluated at many separate times equals fresh general calls,
    for a batch of bodies with broadcast inputs (shapes as torque_free)."""
    rng = np.random.default_rng(11)
    w0 = rng.normal(size=(5, 3))
    inertia = np.array([1.0, 2.5, 3.0])
    prepared = PreparedBody(inertia, w0, Q0)
    assert prepared.shape == (5,) and prepared.bodies.dtype == BODY_DTYPE
    for t in (0.0, -4.0, 1e5, np.nan):
        w, q = prepared.states(t)
        w_ref, q_ref = torque_free(inertia, w0, Q0, np.array([t]))
        assert w.shape == (5, 3) and q.shape == (5, 4)
        np.testing.assert_array_equal(w, w_ref[:, 0])
        np.testing.assert_array_equal(q, q_ref[:, 0])
    w, q = prepared.states(TIMES)
    assert w.shape == (5, len(TIMES), 3) and q.shape == (5, len(TIMES), 4)


def test_scalar_path_bad_inputs():
    with pytest.raises(ValueError, match="inertia: expected finite positive principal moments"):
        torque_free(np.array([1.0, -2.0, 3.0]), np.array([0.1, 0.2, 0.3]), Q0, 1.0)
    with pytest.raises(ValueError, match="inertia: expected finite positive principal moments"):
        torque_free(np.array([1.0, np.nan, 3.0]), np.array([0.1, 0.2, 0.3]), Q0, 1.0)
    w, q = torque_free(np.array([1.0, 2.0, 3.0]), np.array([0.1, np.nan, 0.3]), Q0, 1.0)
    assert np.isnan(w).all() and np.isnan(q).all()
    w, q = torque_free(np.array([1.0, 2.0, 3.0]), np.array([0.1, 0.2, 0.3]), Q0, float("nan"))
    assert np.isnan(w).all() and np.isnan(q).all()
    with pytest.raises(ValueError, match="w0: expected body rates of shape"):
        PreparedBody([1.0, 2.0, 3.0], [0.1, 0.2], Q0)
