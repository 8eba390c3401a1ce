"""astrodyn.messages.shortest: compiled shortest round-trip formatting against Python's ``repr``.

The reference is CPython's ``repr(float)`` (David Gay's ``dtoa``, mode 0, bignum
arithmetic), an implementation independent of the Ryu algorithm under test; every check
is byte equality, so there is no tolerance to choose.  Each case also reads the text
back with ``float()`` (round trip) where that adds something.
"""

from __future__ import annotations

import math
import sys

import numpy as np
import pytest
from hypothesis import given, strategies as st

from astrodyn.messages import shortest as sh


def reference(values) -> bytes:
    return "".join(map(repr, np.asarray(values, dtype=np.float64).reshape(-1).tolist())).encode()


def assert_same_as_repr(values) -> None:
    x = np.asarray(values, dtype=np.float64).reshape(-1)
    buf, offsets = sh.format_floats(x)
    got = buf.tobytes()
    if got == reference(x) and offsets[-1] == len(got):
        # boundaries too: each text where repr's text is
        lengths = np.fromiter((len(repr(v)) for v in x.tolist()), dtype=np.int64, count=x.size)
        assert np.array_equal(np.diff(offsets), lengths)
        return
    for i, v in enumerate(x.tolist()):  # name the first value that differs
        assert buf[offsets[i]:offsets[i + 1]].tobytes().decode() == repr(v), (i, v, float(v).hex())
    raise AssertionError("texts equal one by one but not joined")  # pragma: no cover


def random_finite_bits(n: int, seed: int) -> np.ndarray:
    x = np.random.default_rng(seed).integers(0, 2**64, size=n, dtype=np.uint64, endpoint=False).view(np.float64)
    return x[np.isfinite(x)]


# ------------------------------------------------------------------------ single values


@given(st.floats(allow_nan=False, allow_infinity=False))
def test_hypothesis_floats(x):
    assert sh.shortest_repr(x) == repr(x)


@given(st.floats(min_value=-1e20, max_value=1e20, allow_nan=False))
def test_hypothesis_floats_near_the_fixed_notation_range(x):
    text = sh.shortest_repr(x)
    assert text == repr(x)
    assert float(text) == x and math.copysign(1.0, float(text)) == math.copysign(1.0, x)


def test_zeros_and_signs():
    assert sh.shortest_repr(0.0) == "0.0"
    assert sh.shortest_repr(-0.0) == "-0.0"
    assert_same_as_repr([0.0, -0.0, 1.0, -1.0, 0.5, -0.5, 0.1, -0.1])


def test_switch_between_fixed_and_exponent_notation():
    cases = [1e-4, 9.999999999999999e-05, 1e16, 9999999999999998.0, 1e-5, 1e15, 1.5e16, 1.0000000000000002e-4]
    cases += [np.nextafter(c, d) for c in (1e-4, 1e16) for d in (0.0, np.inf)]
    assert_same_as_repr(cases + [-c for c in cases])
    # the layout itself, spelled out (Python's format_float_short rules, not our output)
    assert sh.shortest_repr(1e-4) == "0.0001"
    assert sh.shortest_repr(9.999999999999999e-05) == "9.999999999999999e-05"
    assert sh.shortest_repr(1e16) == "1e+16"
    assert sh.shortest_repr(9999999999999998.0) == "9999999999999998.0"


def test_extremes_and_subnormals():
    largest_subnormal = np.uint64((1 << 52) - 1).view(np.float64)
    smallest_normal = sys.float_info.min
    assert float(largest_subnormal) == smallest_normal - 5e-324
    cases = [5e-324, 1e-323, largest_subnormal, smallest_normal, np.nextafter(smallest_normal, 1.0),
             sys.float_info.max, np.nextafter(sys.float_info.max, 0.0), 2.2250738585072014e-308]
    assert_same_as_repr(cases + [-c for c in cases])
    assert sh.shortest_repr(5e-324) == "5e-324"
    assert sh.shortest_repr(1.7976931348623157e308) == "1.7976931348623157e+308"


def test_every_power_of_two_and_neighbours():
    p2 = np.ldexp(1.0, np.arange(-1074, 1024))
    up, down = np.nextafter(p2, np.inf), np.nextafter(p2, 0.0)  # the asymmetric-interval case
    assert_same_as_repr(np.concatenate([p2, up, down, -p2]))


def test_every_power_of_ten_and_neighbours():
    p10 = np.array([float(f"1e{k}") for k in range(-323, 309)])
    near = np.concatenate([p10, np.nextafter(p10, np.inf), np.nextafter(p10, 0.0)])
    near = near[np.isfinite(near)]
    assert_same_as_repr(np.concatenate([near, -near]))


def test_integers_up_to_2_pow_53():
    small = np.arange(0, 100_001, dtype=np.float64)
    top = 2.0**53 - np.arange(0, 10_000, dtype=np.float64)
    rng = np.random.default_rng(11)
    scattered = rng.integers(0, 2**53, size=100_000, endpoint=True).astype(np.float64)
    tens = np.array([float(d * 10**k) for k in range(16) for d in range(1, 10)])
    assert_same_as_repr(np.concatenate([small, top, scattered, tens, -scattered]))


def test_exponent_field_edges():
    """Each edge of the exponent field with mantissa 0, 1, max and random (Ryu's mmShift cases)."""
    rng = np.random.default_rng(5)
    mantissas = np.concatenate([[0, 1, (1 << 52) - 1], rng.integers(0, 1 << 52, size=40)]).astype(np.uint64)
    fields = np.array([0, 1, 2, 3, 4, 5, 1021, 1022, 1023, 1024, 1075, 1076, 2043, 2044, 2045, 2046], dtype=np.uint64)
    bits = (fields[:, None] << np.uint64(52)) | mantissas[None, :]
    assert_same_as_repr(bits.reshape(-1).view(np.float64))


def test_ryu_regression_inputs():
    """Inputs from Ryu's own test suite (d2s_test.cc: Regression, LooksLikePow5, ...); expected = repr."""
    patterns = [0x4830F0CF064DD592, 0x4840F0CF064DD592, 0x4850F0CF064DD592, 0x0010000000000000,
                0x0020000000000000, 0x000FFFFFFFFFFFFF, 0x7FEFFFFFFFFFFFFF, 0x3FF0000000000001]
    values = [-2.109808898695963e16, 4.940656e-318, 1.18575755e-316, 2.989102097996e-312,
              9.0608011534336e15, 4.708356024711512e18, 9.409340012568248e18, 1.2345678, 1.9430376160308388e16,
              -6.9741824662760956e19, 4.3816050601147837e18, 2.98023223876953125e-8, 1.8531501765868567e21,
              -3.347727380279489e33, 1.9234651e16, 0.3, 2.0 / 3.0, 1.0 / 3.0]
    assert_same_as_repr(np.concatenate([np.array(patterns, dtype=np.uint64).view(np.float64), values]))


def test_random_bit_patterns_one_million():
    x = random_finite_bits(1_000_000, seed=2024)
    assert x.size > 990_000
    assert_same_as_repr(x)


@pytest.mark.slow
def test_random_bit_patterns_ten_million():
    for seed in range(10):
        assert_same_as_repr(random_finite_bits(1_000_000, seed=100 + seed))


def test_typical_message_values():
    """Values like those the encoders write: positions, velocities, quaternions, small rates."""
    rng = np.random.default_rng(3)
    x = np.concatenate([rng.normal(size=50_000) * 7e6, rng.normal(size=50_000) * 7.5e3,
                        rng.uniform(-1, 1, 50_000), rng.normal(size=50_000) * 1e-3,
                        np.arange(0, 5000) / 10.0, np.round(rng.normal(size=5000), 3)])
    assert_same_as_repr(x)


# ------------------------------------------------------------------------ array interface


def test_shapes_and_empty():
    buf, offsets = sh.format_floats(np.zeros((0, 3)))
    assert buf.size == 0 and offsets.tolist() == [0]
    x = np.arange(12.0).reshape(2, 2, 3) / 7
    buf, offsets = sh.format_floats(x)
    assert buf.tobytes() == reference(x)
    assert offsets.shape == (13,)
    assert sh.format_floats(2.5)[0].tobytes() == b"2.5"  # a scalar works


def test_non_finite_do_not_hang_and_read_like_repr():
    """Callers reject non-finite values; the formatter still terminates and writes repr's text."""
    x = np.array([np.inf, -np.inf, np.nan, -np.nan, np.uint64(0x7FF0000000000001).view(np.float64)])
    buf, offsets = sh.format_floats(x)
    texts = [buf[offsets[i]:offsets[i + 1]].tobytes().decode() for i in range(x.size)]
    assert texts == [repr(v) for v in x.tolist()] == ["inf", "-inf", "nan", "nan", "nan"]


def test_longest_text_fits_the_documented_bound():
    x = random_finite_bits(200_000, seed=9)
    _, offsets = sh.format_floats(x)
    assert np.diff(offsets).max() <= sh.MAX_REPR_LEN
    assert len(repr(-2.2250738585072014e-308)) == sh.MAX_REPR_LEN


def test_write_uint_matches_str():
    buf = np.zeros(32, np.uint8)
    for v in [0, 1, 9, 10, 99, 100, 12345, 2**53 - 1, 2**53, 10**17, 2**63 - 1]:
        end = sh.write_uint(v, buf, 3)
        assert buf[3:end].tobytes() == str(v).encode()


def exact_midpoint_decimals(count: int, seed: int) -> np.ndarray:
    """Doubles on both sides of a short decimal d = c 10**j that lies exactly halfway between them.

    d's odd part has 54 bits (one more than a double holds), so d is a midpoint; float(d)
    is the neighbour with the even mantissa (round half even), which accepts d as its
    shortest text: the hardest case of the shortest/nearest rules (Ryu's vmIsTrailingZeros
    and round-to-even branches).  Built exactly with Python integers.
    """
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < 2 * count:
        j = int(rng.integers(0, 23))
        bits_c = 54 - (5**j).bit_length()
        if bits_c < 1:
            continue
        c = int(rng.integers(1 << (bits_c - 1), 1 << bits_c)) | 1  # odd, so odd(d) = c 5**j
        d = c * 10**j
        odd = c * 5**j
        if odd.bit_length() != 54:
            continue
        x_even = float(d)
        x_other = float(np.nextafter(x_even, np.inf if x_even < d else 0.0))
        assert 2 * d == int(x_even) + int(x_other)  # really the midpoint
        out += [x_even, x_other]
    return np.array(out)


def test_short_decimals_at_exact_midpoints():
    x = exact_midpoint_decimals(20_000, seed=1)
    assert_same_as_repr(np.concatenate([x, -x, x * 2.0**-60, x * 2.0**200]))


# ------------------------------------------------------------------------ records and the encoders


def test_format_records_template():
    seqs = np.array([0, 7, 2**53 - 1])
    values = np.array([[0.1, -0.0], [1e16, 5e-324], [123.0, 1e-4]])
    template = sh.RecordTemplate([b"<", b"|", b"|", b",", b"|", b">"], [sh.shared(0), sh.SEQ, 0, 1, sh.shared(1)])
    data, offsets = sh.format_records(template, seqs, values, (2.5e-7, -1e300))
    expected = [f"<2.5e-07|{s}|{a!r},{b!r}|-1e+300>".encode() for s, (a, b) in zip(seqs.tolist(), values.tolist())]
    assert data == b"".join(expected)
    assert np.diff(offsets).tolist() == [len(e) for e in expected]
    with pytest.raises(ValueError, match="pieces: expected 6 byte strings for 5 slots"):
        sh.RecordTemplate([b"<", b">"], [sh.shared(0), sh.SEQ, 0, 1, sh.shared(1)])
    with pytest.raises(ValueError, match="values: expected 2 columns and 2 shared values, got 2 and 1"):
        sh.format_records(template, seqs, values, (1.0,))


def random_unit_quats(rng, n):
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1)[:, None]


def test_encoders_equal_encode_of_the_message_on_random_bit_patterns():
    """Any finite value (subnormal, huge, -0.0, 17 digits) gives json.dumps/repr's bytes."""
    from astrodyn import messages as m

    rng = np.random.default_rng(17)
    r = random_finite_bits(3100, seed=3)[:3000].reshape(-1, 3)
    v = random_finite_bits(3100, seed=4)[:3000].reshape(-1, 3)
    n = r.shape[0]
    seqs = rng.integers(0, 2**53, size=n)
    mu, t = 3.986004418e14, float(random_finite_bits(10, seed=5)[0])
    got = m.encode_orbit_batch(t, seqs, "j2", r, v, mu, "EME2000")
    assert got == [m.encode(m.orbit_message(t, int(s), "j2", ri, vi, mu, "EME2000")) for s, ri, vi in zip(seqs, r, v)]
    q = random_unit_quats(rng, n)
    got = m.encode_attitude_batch(t, seqs, "gyrostat", q, v)
    assert got == [m.encode(m.attitude_message(t, int(s), "gyrostat", qi, wi)) for s, qi, wi in zip(seqs, q, v)]


def test_framed_encoders_equal_encode_batch_of_the_payloads():
    from astrodyn import messages as m

    rng = np.random.default_rng(23)
    n = 300
    r, v, w = rng.normal(size=(n, 3)) * 7e6, rng.normal(size=(n, 3)) * 7.5e3, rng.normal(size=(n, 3)) * 1e-3
    q = random_unit_quats(rng, n)
    okeys = [m.orbit_key("scen", f"sat-{i}") for i in range(n)]
    akeys = [f"astrodyn/scen/s\u00e4t{i}/attitude" for i in range(n)]  # non-ASCII: UTF-8 byte lengths
    orbit = m.frame_orbit_batch(okeys, 4.5, 9, "kepler", r, v, 3.986004418e14)
    att = m.frame_attitude_batch(akeys, 4.5, np.arange(n), "torque_free", q, w)
    extra = m.frame_entries([(m.crosscheck_key("scen", "x"), b"{}")])
    env = m.batch_envelope([(orbit, n), (att, n), extra])
    items = (list(zip(okeys, m.encode_orbit_batch(4.5, 9, "kepler", r, v, 3.986004418e14)))
             + list(zip(akeys, m.encode_attitude_batch(4.5, np.arange(n), "torque_free", q, w)))
             + [(m.crosscheck_key("scen", "x"), b"{}")])
    assert env == m.encode_batch(items)
    assert m.decode_batch(env) == items
    packed = m.BatchKeys(okeys)  # packed once, reused at every step
    for _ in range(2):
        assert m.frame_orbit_batch(packed, 4.5, 9, "kepler", r, v, 3.986004418e14) == orbit
    assert m.batch_envelope([(m.frame_orbit_batch([], 0.0, 0, "kepler", np.zeros((0, 3)), np.zeros((0, 3)), 1.0), 0)]) == m.encode_batch([])


def test_framed_encoders_reject_bad_keys_and_values_like_the_plain_ones():
    from astrodyn import messages as m

    ones = np.ones((2, 3))
    with pytest.raises(m.MessageError, match=r"batch.keys: expected a sequence of 2 key strings, got 1"):
        m.frame_orbit_batch(["a"], 0.0, 0, "kepler", ones, ones, 1.0)
    with pytest.raises(m.MessageError, match=r"batch\[1\].key: expected a string"):
        m.frame_orbit_batch(["a", b"b"], 0.0, 0, "kepler", ones, ones, 1.0)
    with pytest.raises(m.MessageError, match=r"batch\[0\]: expected key <= 65535 bytes"):
        m.frame_orbit_batch(["a" * 70000, "b"], 0.0, 0, "kepler", ones, ones, 1.0)
    bad = ones.copy()
    bad[1, 2] = np.nan
    with pytest.raises(m.MessageError, match=r"orbit.v\[1\]: expected array of 3 finite numbers"):
        m.frame_orbit_batch(["a", "b"], 0.0, 0, "kepler", ones, bad, 1.0)
    with pytest.raises(m.MessageError, match=r"attitude.q\[0\]: expected a unit quaternion"):
        m.frame_attitude_batch(["a", "b"], 0.0, 0, "torque_free", np.ones((2, 4)), ones)
