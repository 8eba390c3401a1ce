"""Hostile calls to the public API of ``astrodyn.orbit`` (the findings of an API probe):
each one is refused in bounded time with a one-line ``ValueError`` / ``TypeError`` /
``RuntimeError`` whose text names the argument (docs/architecture.md, section 2,
"Bad numbers").

* A perturbation with a non-finite acceleration (a third body on the spacecraft, a NaN
  ephemeris) used to hang ``propagate_perturbed`` inside scipy's step-rejection loop; those
  calls run under a ``SIGALRM`` time bound here, so a regression fails instead of hanging.
* Eccentricities outside the domain of the anomaly helpers, ``None`` / complex / strings /
  object arrays / bools for numeric arguments, ``propagate_scalar`` with ints and float32,
  shapes that do not broadcast, and the remaining arguments of the perturbed propagator.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from _hostile_calls import time_bound
from astrodyn import orbit as o
from astrodyn.inputs import NonRealInputError

MU = 3.986004418e14
R0 = np.array([7000e3, 0.0, 0.0])
V0 = np.array([0.0, 7.5e3, 1e3])


def refused(call, error, match, seconds: float = 20.0):
    """``call()`` raises ``error`` matching ``match`` within ``seconds``; returns the message."""
    start = time.perf_counter()
    with time_bound(seconds), pytest.raises(error, match=match) as info:
        call()
    assert time.perf_counter() - start < seconds
    text = str(info.value)
    assert "\n" not in text, text  # one line
    return text


# --------------------------------------------------------------------------- 1. the hang


def pp(perts, t=(0.0, 60.0), **kw):
    return lambda: o.propagate_perturbed(R0, V0, list(t), MU, perts, **kw)


@pytest.fixture(scope="module", autouse=True)
def compiled():
    """Valid calls first, outside the time bounds: a cold numba cache compiles the kernels
    (tens of seconds on a shared machine), which is not what the bounds are about."""
    for method in ("cowell", "encke"):
        pp([o.EARTH_WGS84.zonal(), o.ThirdBody(o.MOON.mu, [3.84e8, 0.0, 0.0])], method=method,
           error_estimate=False)()
    o.propagate_scalar(7e6, 0.0, 0.0, 0.0, 7500.0, 0.0, 60.0, MU)


@pytest.mark.parametrize("method", ["cowell", "encke"])
def test_third_body_on_the_spacecraft_raises_naming_it(method):
    text = refused(pp([o.ThirdBody(o.MOON.mu, R0)], method=method, max_steps=200), RuntimeError,
                   r"ThirdBody.*not finite at t = 0")
    assert "propagate_perturbed" in text


def test_third_body_ephemeris_returning_nan_raises_naming_it():
    refused(pp([o.ThirdBody(o.MOON.mu, lambda t: np.full(3, np.nan))]), RuntimeError, r"ThirdBody.*not finite at t =")


def test_user_perturbation_returning_nan_raises_naming_it():
    class Broken:
        def acceleration(self, t, r, v):
            return np.full_like(r, np.nan if t > 1.0 else 0.0)

    refused(pp([o.Zonal(MU, 6378e3, (1e-3,)), Broken()]), RuntimeError, r"Broken.*not finite at t = ")


@pytest.mark.parametrize("J", [(np.nan,), (1e-3, np.inf)])
def test_zonal_refuses_non_finite_j(J):
    refused(lambda: o.Zonal(MU, 6378e3, J), ValueError, r"Zonal: J .*finite")


@pytest.mark.parametrize("mu3", [-o.MOON.mu, np.nan, np.inf])
def test_third_body_refuses_bad_mu3(mu3):
    refused(lambda: o.ThirdBody(mu3, [3.84e8, 0.0, 0.0]), ValueError, r"ThirdBody: mu3 .*>= 0")


@pytest.mark.parametrize("pos", [[1.0, 2.0], [np.nan, 0.0, 0.0], [[3.84e8, 0.0, 0.0]]])
def test_third_body_refuses_bad_constant_position(pos):
    refused(lambda: o.ThirdBody(o.MOON.mu, pos), ValueError, r"ThirdBody: r3_of_t")


def test_third_body_position_callable_of_the_wrong_shape_is_named():
    refused(pp([o.ThirdBody(o.MOON.mu, lambda t: np.array([3.84e8, 0.0]))]), ValueError,
            r"ThirdBody: r3_of_t\(t\) .*shape \(3,\).*got shape \(2,\)")


@pytest.mark.parametrize("ratio", [-1.0, 0.0, np.nan, np.inf])
def test_rectify_ratio_is_checked_up_front(ratio):
    zonal = o.EARTH_WGS84.zonal()
    refused(pp([zonal], (0.0, 6000.0), method="encke", rectify_ratio=ratio), ValueError, r"rectify_ratio", 5.0)


@pytest.mark.parametrize(("steps", "error"), [(0, ValueError), (-1, ValueError), (1.5, TypeError), (True, TypeError),
                                              ("10", TypeError)])
def test_max_steps_is_an_integer_of_at_least_one(steps, error):
    refused(pp([o.EARTH_WGS84.zonal()], (0.0, 6000.0), max_steps=steps), error, r"max_steps", 5.0)


# --------------------------------------------------------------------------- 2. anomaly domains

ELLIPTIC = [o.eccentric_from_true, o.true_from_eccentric, o.mean_from_eccentric]
HYPERBOLIC = [o.hyperbolic_from_true, o.true_from_hyperbolic, o.mean_from_hyperbolic]


@pytest.mark.parametrize("fn", ELLIPTIC)
@pytest.mark.parametrize("e", [-0.5, 1.0, 1.5, [0.3, 1.0]])
def test_elliptic_anomaly_helpers_refuse_e_outside_0_1(fn, e):
    text = refused(lambda: fn(1.0, e), ValueError, r"e must satisfy 0 <= e < 1 \(elliptic\)")
    assert text.startswith(fn.__name__)


@pytest.mark.parametrize("fn", HYPERBOLIC)
@pytest.mark.parametrize("e", [0.5, 1.0, -1.0, [1.5, 0.9]])
def test_hyperbolic_anomaly_helpers_refuse_e_at_most_1(fn, e):
    text = refused(lambda: fn(1.0, e), ValueError, r"e must satisfy e > 1 \(hyperbolic\)")
    assert text.startswith(fn.__name__)


@pytest.mark.parametrize(("fn", "e", "bad"), [(f, 0.3, 1.0) for f in ELLIPTIC] + [(f, 1.5, 1.0) for f in HYPERBOLIC])
def test_anomaly_helpers_treat_nan_e_like_solve_kepler(fn, e, bad):
    """NaN or infinite e gives a non-finite element (no error), as in solve_kepler; a finite e
    out of the domain anywhere in the array raises."""
    with np.errstate(invalid="ignore"):  # sqrt(-inf): the NaN is the point
        out = fn(np.array([1.0, 1.0, 1.0, 1.0]), np.array([e, np.nan, -np.inf, e]))
    assert np.isfinite(out[0]) and np.isfinite(out[3]) and np.isnan(out[1]) and not np.isfinite(out[2])
    refused(lambda: fn(np.ones(3), np.array([e, np.nan, bad])), ValueError, r"e must satisfy .*got e = 1\.0$")


# --------------------------------------------------------------------------- 3. non-real numbers

NOT_REAL = [(None, "None"), (1 + 1j, "complex"), ("7", "str"), (True, "bool"), (np.bool_(False), "bool"),
            (np.array([1.0, None], dtype=object), "object array holding None"),
            (np.array([1.0, True], dtype=object), "object array holding bool")]


@pytest.mark.parametrize(("bad", "kind"), NOT_REAL)
def test_propagate_dt_and_mu_refuse_non_real_numbers(bad, kind):
    refused(lambda: o.propagate(R0, V0, bad, MU), NonRealInputError, rf"propagate: dt: expected real numbers, got .*{kind}")
    refused(lambda: o.propagate(R0, V0, 60.0, bad), NonRealInputError, rf"propagate: mu: expected real numbers, got .*{kind}")


@pytest.mark.parametrize("bad", [R0 + 1j, np.array([7e6, 0.0, "0"], dtype=object), [7e6, 0.0, None], ["7e6", "0", "0"],
                                 np.array([True, False, False])])
def test_state_vectors_refuse_non_real_numbers(bad):
    refused(lambda: o.propagate(bad, V0, 60.0, MU), NonRealInputError, r"propagate: r0: expected real numbers")
    refused(lambda: o.propagate(R0, bad, 60.0, MU), NonRealInputError, r"propagate: v0: expected real numbers")
    refused(lambda: o.elements_from_state(bad, V0, MU), NonRealInputError, r"elements_from_state: r: expected real numbers")
    refused(lambda: o.elements_from_state(R0, V0, 1j), NonRealInputError, r"elements_from_state: mu: expected real numbers")


@pytest.mark.parametrize("k", range(7))
def test_state_from_elements_names_the_non_real_argument(k):
    names = ["p", "e", "i", "raan", "argp", "nu", "mu"]
    args = [7e6, 0.1, 0.5, 1.0, 2.0, 0.3, MU]
    for bad in (None, 0.1 + 1j, "1"):
        args_k = list(args)
        args_k[k] = bad
        refused(lambda a=args_k: o.state_from_elements(*a), NonRealInputError,
                rf"state_from_elements: {names[k]}: expected real numbers")


def test_kepler_and_anomaly_helpers_name_the_non_real_argument():
    refused(lambda: o.solve_kepler(1 + 1j, 0.5), NonRealInputError, r"solve_kepler: M: expected real numbers, got complex")
    refused(lambda: o.solve_kepler(1.0, None), NonRealInputError, r"solve_kepler: e: expected real numbers, got None")
    refused(lambda: o.solve_kepler_hyperbolic("1", 1.5), NonRealInputError, r"solve_kepler_hyperbolic: M: expected real")
    refused(lambda: o.stumpff(1 + 1j), NonRealInputError, r"stumpff: z: expected real numbers, got complex")
    for fn, x in [(o.eccentric_from_true, "nu"), (o.true_from_eccentric, "E"), (o.mean_from_eccentric, "E"),
                  (o.mean_from_true, "nu"), (o.true_from_mean, "M")]:
        refused(lambda f=fn: f(None, 0.3), NonRealInputError, rf"{fn.__name__}: {x}: expected real numbers, got None")
        refused(lambda f=fn: f(1.0, 0.3 + 0j), NonRealInputError, rf"{fn.__name__}: e: expected real numbers, got complex")
    for fn, x in [(o.hyperbolic_from_true, "nu"), (o.true_from_hyperbolic, "F"), (o.mean_from_hyperbolic, "F")]:
        refused(lambda f=fn: f(1j, 1.5), NonRealInputError, rf"{fn.__name__}: {x}: expected real numbers, got complex")


def test_object_arrays_of_ints_and_floats_convert_as_numbers():
    """The one rule (astrodyn.inputs): an object array holding only ints and floats is real numbers."""
    r_obj, v_obj = np.array([7000000, 0, 0.0], dtype=object), np.array([0.0, 7.5e3, 1e3], dtype=object)
    r, v = o.propagate(R0, V0, np.array([60.0, 120.0]), MU)
    r2, v2 = o.propagate(r_obj, v_obj, np.array([60, 120.0], dtype=object), MU)
    assert np.array_equal(r, r2) and np.array_equal(v, v2)


# --------------------------------------------------------------------------- 4. propagate_scalar


def test_propagate_scalar_takes_ints_and_float32_without_compiling():
    ref = o.propagate_scalar(7e6, 0.0, 0.0, 0.0, 7500.0, 0.0, 60.0, MU)  # float64 (compiled by the fixture)
    start = time.perf_counter()
    with time_bound(20.0):
        ints = o.propagate_scalar(7000000, 0, 0, 0, 7500, 0, 60, 398600441800000)
        f32 = o.propagate_scalar(*np.float32([7e6, 0, 0, 0, 7500, 0]), np.float32(60), MU)
        mixed = o.propagate_scalar(7e6, 0.0, 0, 0.0, 7500.0, np.int64(0), 60.0, MU)
    assert time.perf_counter() - start < 1.0  # no new specialization to compile (was 11 s each)
    assert ints == ref and f32 == ref and mixed == ref  # exact conversions: the same bits


def test_propagate_scalar_names_a_non_real_argument():
    refused(lambda: o.propagate_scalar(7e6, 0.0, 1j, 0.0, 7500.0, 0.0, 60.0, MU), NonRealInputError,
            r"propagate_scalar: rz: expected a real number, got complex")
    refused(lambda: o.propagate_scalar(7e6, 0.0, 0.0, 0.0, 7500.0, 0.0, None, MU), NonRealInputError,
            r"propagate_scalar: dt: expected a real number, got None")


# --------------------------------------------------------------------------- 5. broadcasting


@pytest.mark.parametrize(("call", "match"), [
    (lambda: o.solve_kepler(np.ones(2), np.full(3, 0.5)), r"solve_kepler: shapes do not broadcast: M \(2,\), e \(3,\)"),
    (lambda: o.solve_kepler_hyperbolic(np.ones(2), np.full(3, 1.5)), r"M \(2,\), e \(3,\)"),
    (lambda: o.elements_from_state(np.ones((2, 3)), np.ones((5, 3)), MU),
     r"elements_from_state: leading shapes do not broadcast: r \(2, 3\), v \(5, 3\), mu \(\)"),
    (lambda: o.elements_from_state(np.tile(R0, (2, 1)), np.tile(V0, (2, 1)), np.full(5, MU)),
     r"r \(2, 3\), v \(2, 3\), mu \(5,\)"),
    (lambda: o.equinoctial_from_state(np.ones((2, 3)), np.ones((5, 3)), MU), r"r \(2, 3\), v \(5, 3\)"),
    (lambda: o.state_from_elements(np.ones(2) * 7e6, np.ones(3) * 0.1, 0.5, 1.0, 2.0, 3.0, MU),
     r"state_from_elements: shapes do not broadcast: p \(2,\), e \(3,\), i \(\)"),
    (lambda: o.state_from_equinoctial(np.ones(2) * 7e6, np.ones(3) * 0.1, 0.0, 0.0, 0.0, 1.0, MU),
     r"p \(2,\), f \(3,\)"),
    (lambda: o.third_body_acceleration(np.ones((2, 3)), np.ones((5, 3)), o.MOON.mu), r"r \(2, 3\), s \(5, 3\)"),
    (lambda: o.point_mass_difference(np.ones((2, 3)), np.ones((5, 3)), MU), r"x \(2, 3\), dx \(5, 3\)"),
])
def test_broadcast_mismatch_names_each_argument_and_its_shape(call, match):
    refused(call, ValueError, match)


@pytest.mark.parametrize("fn", ELLIPTIC + HYPERBOLIC + [o.mean_from_true, o.true_from_mean])
def test_anomaly_helpers_broadcast_mismatch_names_both_arguments(fn):
    e = 0.5 if fn in ELLIPTIC or fn in (o.mean_from_true, o.true_from_mean) else 1.5
    refused(lambda: fn(np.ones(2), np.full(3, e)), ValueError, rf"{fn.__name__}: shapes do not broadcast: \w+ \(2,\), e \(3,\)")


# --------------------------------------------------------------------------- 6. the rest of the probe's table


def test_kepler_orbit_called_with_an_array_names_t():
    orbit = o.KeplerOrbit([3.84e8, 0.0, 0.0], [0.0, 1e3, 0.0], MU + o.MOON.mu)
    refused(lambda: orbit(np.array([10.0, 20.0])), ValueError, r"KeplerOrbit: t: expected a scalar .*shape \(2,\)")


def test_propagate_perturbed_names_mu_and_rtol():
    zonal = o.EARTH_WGS84.zonal()
    refused(lambda: o.propagate_perturbed(R0, V0, [0.0, 60.0], np.array([MU, MU]), [zonal]), ValueError,
            r"propagate_perturbed: mu: expected a scalar .*shape \(2,\)", 5.0)
    refused(pp([zonal], rtol="1e-9"), NonRealInputError, r"propagate_perturbed: rtol: expected real numbers, got str", 5.0)
    refused(pp([zonal], atol=math.nan), ValueError, r"propagate_perturbed: atol", 5.0)


@pytest.mark.parametrize("degree, error", [(-3, ValueError), (0, ValueError), (1, ValueError), (7, ValueError),
                                           (2.5, TypeError), (3.0, TypeError), (True, TypeError), ("3", TypeError)])
def test_central_body_zonal_names_degree_and_the_range(degree, error):
    # -3, 0, 1 and True (read as 1) used to give an empty zonal model silently, 2.5 a TypeError about slices
    text = refused(lambda: o.EARTH_EGM2008.zonal(degree), error,
                   r"^zonal: degree: expected an int from 2 to 6 \(Earth \(EGM2008\) has J2\.\.J6\), got ", 5.0)
    assert text.endswith(repr(degree) if error is TypeError else str(degree)), text
    refused(lambda: o.SUN.zonal(2), ValueError, r"^zonal: degree: expected None \(Sun has no zonal coefficients\), got 2")


def test_central_body_zonal_takes_every_degree_it_has():
    body = o.EARTH_EGM2008
    for degree in range(2, len(body.J) + 2):
        for d in (degree, np.int64(degree)):
            assert body.zonal(d).J == body.J[: degree - 1]
    assert body.zonal().J == body.J and o.SUN.zonal().J == ()
