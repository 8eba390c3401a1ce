"""Real numbers only in :mod:`astrodyn.attitude.gyroscopes` and :mod:`astrodyn.attitude.flexible`
(docs/architecture.md, section 2, bad numbers; :mod:`astrodyn.inputs`).

Both modules kept their own checks: ``float(value)`` (which parses ``"3.0"`` and reads a bool
as 1), ``np.asarray(value, dtype=float)`` (which parses strings too, and drops an imaginary
part), or a dtype test that refused object arrays of ints.  Now every numeric argument of
their public functions goes through :func:`astrodyn.inputs.real_array` /
:func:`~astrodyn.inputs.real_scalar`: ints and floats of any width (and object arrays of
them) become float64; ``None``, complex numbers, strings, bytes, dates, bools and other
objects raise :class:`~astrodyn.inputs.NonRealInputError` naming the function and the
argument (``"beam_matrices: EI: expected real numbers, got None"``).
"""

from __future__ import annotations

import datetime as dt

import numpy as np
import pytest

from _hostile_calls import assert_refused_quickly, time_bound
from astrodyn.attitude import flexible as fx, gyroscopes as g
from astrodyn.inputs import NonRealInputError

C, A, SPIN = 1e-4, 6e-5, 2000.0
GIM = (2e-5, 3e-5, 2e-5)
FREE = g.FreeGyroscope(C, A, GIM, 1e-5)
SA = g.SingleAxisGyro(C, A, SPIN, GIM, 0.5, 1e-3)
S6 = [0.1, 1.4, 0.2, 0.01, -0.02, 2000.0]
S3 = [0.01, -0.2, SPIN]
BASE = g.constant_base_rate([0.01, -0.02, 0.03])
T = [0.0, 0.01]
TT = np.linspace(0.0, 1.0, 6)
RATES = np.full((6, 3), 0.01)

BEAM = fx.beam_matrices(2, 100.0, 1.0, 2.0)
BEAM_ARGS = dict(n_modes=2, EI=100.0, rho=1.0, L=2.0)
Q4 = [0.01, -0.02, 0.1, 0.0]
S8 = [0.1, 0.5, 0.01, -0.02, 0.1, 0.0]
APP = fx.Appendage(BEAM, [1, 0, 0], [0, 1, 0])
SC = fx.FlexibleSpacecraft(10.0, [10.0, 12.0, 8.0], (APP,))
Y = fx.make_state(SC, w=[0.01, 0.02, 0.3])

# values that are not real numbers: each must be refused, naming the function and the argument
NOT_REAL_SCALARS = [None, 1j, 2.0 + 0j, "1.0", b"1", True, np.bool_(False), np.datetime64("2020-01-01"),
                    dt.date(2020, 1, 1), object()]


def _vector_forms(n):
    """Sequences of ``n`` values that are not real numbers (a bad element, or a bad dtype)."""
    ones = [1.0] * n
    return [[None] + ones[1:], ["1.0"] * n, [True] * n, np.ones(n, dtype=complex), np.ones(n, dtype=bool),
            np.array([1.0] * (n - 1) + [None], dtype=object), ones[:-1] + [1j]]


# (function, argument, call taking the value of that argument, "scalar" (or "optional": None is the
# default) or the vector length); a time in a list goes in twice ([v, v]): numpy reads a bool among
# floats ([0.0, True]) as a float array, which the dtype test cannot see (astrodyn.inputs)
ENTRIES = [
    # gyroscopes
    ("FreeGyroscope", "rotor_axial", lambda v: g.FreeGyroscope(v, A), "scalar"),
    ("FreeGyroscope", "rotor_transverse", lambda v: g.FreeGyroscope(C, v), "scalar"),
    ("FreeGyroscope", "inner_gimbal", lambda v: g.FreeGyroscope(C, A, v), 3),
    ("FreeGyroscope", "outer_gimbal", lambda v: g.FreeGyroscope(C, A, GIM, v), "scalar"),
    ("FreeGyroscope.outer_inertia", "theta", lambda v: FREE.outer_inertia(v), "scalar"),
    ("free_gyro_state", "spin", lambda v: g.free_gyro_state(FREE, v), "scalar"),
    ("free_gyro_state", "theta", lambda v: g.free_gyro_state(FREE, 100.0, theta=v), "scalar"),
    ("free_gyro_state", "phi", lambda v: g.free_gyro_state(FREE, 100.0, phi=v), "scalar"),
    ("free_gyro_rates", "t", lambda v: g.free_gyro_rates(FREE, v, S6), "scalar"),
    ("free_gyro_rates", "state", lambda v: g.free_gyro_rates(FREE, 0.0, v), 6),
    ("propagate_free_gyro", "state0", lambda v: g.propagate_free_gyro(FREE, v, T), 6),
    ("propagate_free_gyro", "t", lambda v: g.propagate_free_gyro(FREE, S6, [v, v]), "scalar"),
    ("propagate_free_gyro", "rtol", lambda v: g.propagate_free_gyro(FREE, S6, T, rtol=v), "scalar"),
    ("propagate_free_gyro", "atol", lambda v: g.propagate_free_gyro(FREE, S6, T, atol=v), "scalar"),
    ("free_gyro_energy", "states", lambda v: g.free_gyro_energy(FREE, v), 6),
    ("free_gyro_integrals", "states", lambda v: g.free_gyro_integrals(FREE, v), 6),
    ("free_gyro_momentum", "states", lambda v: g.free_gyro_momentum(FREE, v), 6),
    ("nutation_frequency", "h", lambda v: g.nutation_frequency(FREE, v), "scalar"),
    ("nutation_frequency", "theta0", lambda v: g.nutation_frequency(FREE, 0.2, v), "scalar"),
    ("fast_rotor_nutation_frequency", "spin", lambda v: g.fast_rotor_nutation_frequency(FREE, v), "scalar"),
    ("free_gyro_linear", "h", lambda v: g.free_gyro_linear(FREE, v, T), "scalar"),
    ("free_gyro_linear", "t", lambda v: g.free_gyro_linear(FREE, 0.2, v), 3),
    ("free_gyro_linear", "inner_rate", lambda v: g.free_gyro_linear(FREE, 0.2, T, inner_rate=v), "scalar"),
    ("free_gyro_linear", "outer_torque", lambda v: g.free_gyro_linear(FREE, 0.2, T, outer_torque=v), "scalar"),
    ("SingleAxisGyro", "spin_inertia", lambda v: g.SingleAxisGyro(v, A, SPIN), "scalar"),
    ("SingleAxisGyro", "spin_rate", lambda v: g.SingleAxisGyro(C, A, v), "scalar"),
    ("SingleAxisGyro", "gimbal_inertia", lambda v: g.SingleAxisGyro(C, A, SPIN, v), 3),
    ("SingleAxisGyro", "spring", lambda v: g.SingleAxisGyro(C, A, SPIN, spring=v), "scalar"),
    ("SingleAxisGyro", "damping", lambda v: g.SingleAxisGyro(C, A, SPIN, damping=v), "scalar"),
    ("SingleAxisGyro.rate_gyro", "spring", lambda v: g.SingleAxisGyro.rate_gyro(C, A, SPIN, v, 1e-3), "scalar"),
    ("SingleAxisGyro.rate_integrating", "damping", lambda v: g.SingleAxisGyro.rate_integrating(C, A, SPIN, v),
     "scalar"),
    ("constant_base_rate", "w", lambda v: g.constant_base_rate(v), 3),
    ("sampled_base_rate", "times", lambda v: g.sampled_base_rate(v, RATES), 6),
    ("sampled_base_rate", "rates", lambda v: g.sampled_base_rate(TT, np.stack([v] * 6)), 3),
    ("sampled_base_rate", "mount", lambda v: g.sampled_base_rate(TT, RATES, np.stack([v] * 3)), 3),
    ("single_axis_rates", "t", lambda v: g.single_axis_rates(SA, v, S3, BASE), "scalar"),
    ("single_axis_rates", "state", lambda v: g.single_axis_rates(SA, 0.0, v, BASE), 3),
    ("propagate_single_axis", "t", lambda v: g.propagate_single_axis(SA, BASE, [v, v]), "scalar"),
    ("propagate_single_axis", "theta0", lambda v: g.propagate_single_axis(SA, BASE, T, theta0=v), "scalar"),
    ("propagate_single_axis", "spin0", lambda v: g.propagate_single_axis(SA, BASE, T, spin0=v), "optional"),
    ("propagate_single_axis", "rtol", lambda v: g.propagate_single_axis(SA, BASE, T, rtol=v), "scalar"),
    ("error_torques", "states", lambda v: g.error_torques(SA, v, S3, S3), 3),
    ("error_torques", "w", lambda v: g.error_torques(SA, S3, v, S3), 3),
    ("error_torques", "w_dot", lambda v: g.error_torques(SA, S3, S3, v), 3),
    ("steady_state_angle", "w", lambda v: g.steady_state_angle(SA, v), 3),
    ("single_axis_energy", "states", lambda v: g.single_axis_energy(SA, v, S3), 3),
    ("single_axis_energy", "w", lambda v: g.single_axis_energy(SA, S3, v), 3),
    ("single_axis_jacobi_integral", "w", lambda v: g.single_axis_jacobi_integral(SA, S3, v), 3),
    ("single_axis_momentum", "states", lambda v: g.single_axis_momentum(SA, v, S3), 3),
    # flexible
    ("beam_matrices", "EI", lambda v: fx.beam_matrices(**{**BEAM_ARGS, "EI": v}), "scalar"),
    ("beam_matrices", "rho", lambda v: fx.beam_matrices(**{**BEAM_ARGS, "rho": v}), "scalar"),
    ("beam_matrices", "L", lambda v: fx.beam_matrices(**{**BEAM_ARGS, "L": v}), "scalar"),
    ("beam_matrices", "r", lambda v: fx.beam_matrices(**BEAM_ARGS, r=v), "scalar"),
    ("beam_matrices", "damping_ratio", lambda v: fx.beam_matrices(**BEAM_ARGS, damping_ratio=v), "scalar"),
    ("shape_functions", "x", lambda v: fx.shape_functions(BEAM, v), 3),
    ("natural_frequencies", "spin", lambda v: fx.natural_frequencies(BEAM, v), "scalar"),
    ("tip_deflection", "q", lambda v: fx.tip_deflection(BEAM, v), 2),
    ("krb_spinup", "t", lambda v: fx.krb_spinup(v), 3),
    ("krb_spinup", "omega_s", lambda v: fx.krb_spinup(1.0, v), "scalar"),
    ("krb_spinup", "T", lambda v: fx.krb_spinup(1.0, 6.0, v), "scalar"),
    ("planar_prescribed_rates", "t", lambda v: fx.planar_prescribed_rates(BEAM, v, Q4, fx.krb_spinup), "scalar"),
    ("planar_prescribed_rates", "state", lambda v: fx.planar_prescribed_rates(BEAM, 1.0, v, fx.krb_spinup), 4),
    ("propagate_planar_prescribed", "state0", lambda v: fx.propagate_planar_prescribed(BEAM, fx.krb_spinup, v, T), 4),
    ("propagate_planar_prescribed", "t", lambda v: fx.propagate_planar_prescribed(BEAM, fx.krb_spinup, Q4, [v, v]),
     "scalar"),
    ("propagate_planar_prescribed", "rtol", lambda v: fx.propagate_planar_prescribed(BEAM, fx.krb_spinup, Q4, T,
                                                                                      rtol=v), "scalar"),
    ("planar_free_rates", "hub_inertia", lambda v: fx.planar_free_rates(BEAM, v, S8), "scalar"),
    ("planar_free_rates", "state", lambda v: fx.planar_free_rates(BEAM, 5.0, v), 6),
    ("planar_free_rates", "torque", lambda v: fx.planar_free_rates(BEAM, 5.0, S8, v), "scalar"),
    ("propagate_planar_free", "hub_inertia", lambda v: fx.propagate_planar_free(BEAM, v, S8, T), "scalar"),
    ("propagate_planar_free", "state0", lambda v: fx.propagate_planar_free(BEAM, 5.0, v, T), 6),
    ("propagate_planar_free", "t", lambda v: fx.propagate_planar_free(BEAM, 5.0, S8, [v, v]), "scalar"),
    ("propagate_planar_free", "atol", lambda v: fx.propagate_planar_free(BEAM, 5.0, S8, T, atol=v), "scalar"),
    ("planar_energy", "hub_inertia", lambda v: fx.planar_energy(BEAM, v, S8), "scalar"),
    ("planar_energy", "state", lambda v: fx.planar_energy(BEAM, 5.0, v), 6),
    ("planar_angular_momentum", "state", lambda v: fx.planar_angular_momentum(BEAM, 5.0, v), 6),
    ("Appendage", "axis", lambda v: fx.Appendage(BEAM, v, [0, 1, 0]), 3),
    ("Appendage", "normal", lambda v: fx.Appendage(BEAM, [1, 0, 0], v), 3),
    ("Appendage", "root", lambda v: fx.Appendage(BEAM, [1, 0, 0], [0, 1, 0], v), 3),
    ("FlexibleSpacecraft", "hub_mass", lambda v: fx.FlexibleSpacecraft(v, [10.0, 12.0, 8.0], (APP,)), "scalar"),
    ("FlexibleSpacecraft", "hub_inertia", lambda v: fx.FlexibleSpacecraft(10.0, v, (APP,)), 3),
    ("make_state", "q", lambda v: fx.make_state(SC, q=v), 4),
    ("make_state", "w", lambda v: fx.make_state(SC, w=v), 3),
    ("make_state", "r", lambda v: fx.make_state(SC, r=v), 3),
    ("make_state", "v", lambda v: fx.make_state(SC, v=v), 3),
    ("make_state", "eta", lambda v: fx.make_state(SC, eta=v), 4),
    ("make_state", "eta_dot", lambda v: fx.make_state(SC, eta_dot=v), 4),
    ("spacecraft_rates", "t", lambda v: fx.spacecraft_rates(SC, v, Y), "scalar"),
    ("spacecraft_rates", "state", lambda v: fx.spacecraft_rates(SC, 0.0, v), 21),
    ("spacecraft_rates_reference", "state", lambda v: fx.spacecraft_rates_reference(SC, 0.0, v), 21),
    ("spacecraft_energy", "state", lambda v: fx.spacecraft_energy(SC, v), 21),
    ("spacecraft_momentum", "state", lambda v: fx.spacecraft_momentum(SC, v), 21),
    ("spacecraft_energy_reference", "state", lambda v: fx.spacecraft_energy_reference(SC, v), 21),
    ("spacecraft_momentum_reference", "state", lambda v: fx.spacecraft_momentum_reference(SC, v), 21),
    ("tip_deflections", "state", lambda v: fx.tip_deflections(SC, v), 21),
    ("propagate_spacecraft", "state0", lambda v: fx.propagate_spacecraft(SC, v, T), 21),
    ("propagate_spacecraft", "t", lambda v: fx.propagate_spacecraft(SC, Y, [v, v]), "scalar"),
    ("propagate_spacecraft", "rtol", lambda v: fx.propagate_spacecraft(SC, Y, T, rtol=v), "scalar"),
]  # fmt: skip

_FORMS = {"scalar": NOT_REAL_SCALARS, "optional": [v for v in NOT_REAL_SCALARS if v is not None]}
CASES = [(who, arg, call, bad) for who, arg, call, kind in ENTRIES for bad in _FORMS.get(kind) or _vector_forms(kind)]


@pytest.mark.parametrize("who, arg, call, bad", CASES,
                         ids=[f"{who}-{arg}-{i}" for i, (who, arg, _, _) in enumerate(CASES)])
def test_values_that_are_not_real_numbers_name_the_function_and_the_argument(who, arg, call, bad):
    """One rule (astrodyn.inputs): NonRealInputError, a TypeError and a ValueError, whose
    text starts with the function and the argument, quickly."""
    with time_bound(20.0):  # some of these used to run: a date read as a time span of days
        assert_refused_quickly(lambda: call(bad), rf"^{who}: {arg}: expected real numbers", NonRealInputError)


def test_the_error_is_a_type_error_and_still_a_value_error():
    for error in (TypeError, ValueError):
        with pytest.raises(error, match=r"^beam_matrices: EI: expected real numbers, got None"):
            fx.beam_matrices(2, None, 1.0, 2.0)
        with pytest.raises(error, match=r"^propagate_free_gyro: t: expected real numbers, got list of str"):
            g.propagate_free_gyro(FREE, S6, ["0", "0.01"])  # numpy used to parse these strings


# ---------------------------------------------------------------------------
# ints and floats of any width are real numbers: as float64, the same answers


def test_ints_and_floats_of_any_width_and_object_arrays_of_them_are_taken():
    # object arrays holding ints used to be refused (the old dtype test)
    w = g.constant_base_rate(np.array([0, 1, 0], dtype=object))(0.0)[0]
    assert w.dtype == np.float64 and np.array_equal(w, [0.0, 1.0, 0.0])
    assert np.array_equal(g.free_gyro_rates(FREE, np.int8(0), np.array(S6, dtype=object)), g.free_gyro_rates(FREE, 0.0, S6))
    assert g.free_gyro_state(FREE, np.uint16(100)).tolist() == g.free_gyro_state(FREE, 100.0).tolist()
    assert np.array_equal(fx.make_state(SC, w=np.array([0, 0, 1], dtype=np.int8)), fx.make_state(SC, w=[0.0, 0.0, 1.0]))
    b16 = fx.beam_matrices(2, np.float16(100.0), np.int32(1), np.uint8(2))
    assert np.array_equal(b16.K, BEAM.K) and np.array_equal(b16.M, BEAM.M)


def test_a_float32_hub_inertia_is_converted_before_it_is_used():
    """``hub_inertia`` went into the planar sums as given: a float32 plus the beam's Python
    floats stayed float32 (numpy's scalar promotion), rounding the hub's moment to 7 digits.
    5.0 is exact in float32, so the answer must be the float64 one, bit for bit."""
    for fn in (fx.planar_free_rates, fx.planar_energy, fx.planar_angular_momentum):
        assert np.array_equal(fn(BEAM, np.float32(5.0), S8), fn(BEAM, 5.0, S8)), fn.__name__


# ---------------------------------------------------------------------------
# integer arguments: bools are not counts


def test_bools_are_not_counts_or_orders():
    with pytest.raises(NonRealInputError, match=r"^beam_matrices: n_modes: expected an integer from 1 to 24, got True"):
        fx.beam_matrices(True, 100.0, 1.0, 2.0)  # used to build a 1-mode beam
    with pytest.raises(NonRealInputError, match=r"^shape_functions: derivative: expected an integer >= 0, got True"):
        fx.shape_functions(BEAM, [0.5, 1.0], True)  # used to be read as the first derivative
    for bad in (-1, 1.5, None, "1"):
        with pytest.raises(ValueError, match=r"^derivative: expected an integer >= 0"):
            fx.shape_functions(BEAM, [0.5, 1.0], bad)
    assert np.array_equal(fx.shape_functions(BEAM, [0.5, 1.0], np.int64(2)), fx.shape_functions(BEAM, [0.5, 1.0], 2))
