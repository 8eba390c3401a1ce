"""Shortest round-trip formatting of float64 values, byte for byte Python's ``repr(float)``.

``repr(x)`` of a Python float is the shortest decimal string that reads back to the same
double (and, of the shortest ones, the one nearest to ``x``, ties to an even last digit).
Python computes it with David Gay's ``dtoa`` in mode 0 (bignum arithmetic), about 600 ns
per full-precision double.  This module computes the same digits with the Ryu algorithm
(Ulf Adams, "Ryu: fast float-to-string conversion", PLDI 2018, the ``d2d`` routine of the
reference implementation github.com/ulfjack/ryu ``d2s.c``) in numba-compiled code, then lays
them out by Python's rules (``Python/pystrtod.c``, ``format_float_short`` with ``'r'``):

* ``decpt`` is the position of the decimal point, ``x = 0.d1d2...dn x 10**decpt``;
* fixed notation when ``-4 < decpt <= 16`` (i.e. ``1e-4 <= |x| < 1e16``):
  ``0.000123``, ``12.5``, ``1e15`` -> ``1000000000000000.0`` (``.0`` added to integral
  values);
* otherwise exponent notation ``d.ddde-05`` / ``1e+16``: one digit before the point, the
  point only when more digits follow, ``e``, a sign, at least two exponent digits;
* ``0.0`` and ``-0.0``; non-finite values give ``inf``, ``-inf``, ``nan`` as ``repr`` does
  (callers that need finite values reject these themselves).

Ryu needs ``floor(2**k / 5**q) + 1`` and the top 125 bits of ``5**i`` to 125 bits; the two
tables are built here at import with Python integers (exact) and stored as ``(lo, hi)``
uint64 halves.  numba has no 128-bit integer: the 64 x 64 -> 128 bit products are formed
from 32-bit limbs (:func:`_umul128`).

Entry points: :func:`format_floats` (an array in, one byte buffer plus offsets out),
:func:`shortest_repr` (one float, for checks), :func:`format_records` (N texts of one
template -- constant pieces, an integer, floats -- optionally framed as batch-envelope
entries: the message batch encoders' one compiled pass) and, for compiled callers,
:func:`write_shortest` (one float64's bit pattern written into a uint8 buffer).

Speed (``python -m astrodyn.bench.encode``, shared 2-core EPYC at load ~2): 55-70 ns per
float against 610-1430 ns for ``repr``.
"""

from __future__ import annotations

from itertools import accumulate

import numpy as np

from astrodyn.jit import jit

__all__ = ["MAX_REPR_LEN", "SEQ", "RecordTemplate", "format_floats", "format_records", "pack_keys", "shared", "shortest_repr", "write_shortest", "write_uint"]

#: The longest ``repr`` of any float64, e.g. ``-2.2250738585072014e-308`` (24 bytes).
MAX_REPR_LEN = 24

# Ryu's double tables (d2s_full_table.h): DOUBLE_POW5_INV_SPLIT[q] = floor(2**j / 5**q) + 1
# with j = bitlen(5**q) - 1 + 125, q = 0..341; DOUBLE_POW5_SPLIT[i] = 5**i scaled to exactly
# 125 significant bits (truncated), i = 0..325.
_POW5_INV_BITCOUNT = 125
_POW5_BITCOUNT = 125
_POW5_INV_TABLE_SIZE = 342
_POW5_TABLE_SIZE = 326


def _pow5bits_py(e: int) -> int:
    """Ryu's pow5bits: bit length of 5**e for 0 <= e <= 3528 (same formula as the kernel)."""
    return ((e * 1217359) >> 19) + 1


def _build_tables() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    mask = (1 << 64) - 1
    inv_lo = np.empty(_POW5_INV_TABLE_SIZE, np.uint64)
    inv_hi = np.empty(_POW5_INV_TABLE_SIZE, np.uint64)
    for q in range(_POW5_INV_TABLE_SIZE):
        pow5 = 5**q
        bits = pow5.bit_length()
        assert bits == _pow5bits_py(q)  # the kernel's shift counts rely on it
        inv = (1 << (bits - 1 + _POW5_INV_BITCOUNT)) // pow5 + 1
        inv_lo[q], inv_hi[q] = inv & mask, inv >> 64
    pow_lo = np.empty(_POW5_TABLE_SIZE, np.uint64)
    pow_hi = np.empty(_POW5_TABLE_SIZE, np.uint64)
    for i in range(_POW5_TABLE_SIZE):
        pow5 = 5**i
        bits = pow5.bit_length()
        assert bits == _pow5bits_py(i)
        top = pow5 >> (bits - _POW5_BITCOUNT) if bits >= _POW5_BITCOUNT else pow5 << (_POW5_BITCOUNT - bits)
        pow_lo[i], pow_hi[i] = top & mask, top >> 64
    return inv_lo, inv_hi, pow_lo, pow_hi


_POW5_INV_LO, _POW5_INV_HI, _POW5_LO, _POW5_HI = _build_tables()

# uint64 constants for the kernels (numba reads module globals as compile-time constants)
_U0, _U1, _U2, _U4, _U5, _U10, _U100, _U32, _U52, _U63, _U64 = (np.uint64(k) for k in (0, 1, 2, 4, 5, 10, 100, 32, 52, 63, 64))
_M32 = np.uint64(0xFFFFFFFF)
_MANT_MASK = np.uint64((1 << 52) - 1)
_HIDDEN_BIT = np.uint64(1 << 52)
_EXP_MASK = np.uint64(0x7FF)
_DOUBLE_BIAS = 1023
_MANT_BITS = 52
_U1E8 = np.uint64(10**8)
_DIGIT_PAIRS = np.frombuffer("".join(f"{i:02d}" for i in range(100)).encode(), dtype=np.uint8).copy()
_POW10 = np.array([10**k for k in range(20)], dtype=np.uint64)

# ASCII codes
_ZERO = 48
_DOT = 46
_MINUS = 45
_PLUS = 43
_E = 101


@jit
def _umul128(a, b):
    """(hi, lo) of the exact 128-bit product of two uint64, from 32-bit limbs."""
    a_lo = a & _M32
    a_hi = a >> _U32
    b_lo = b & _M32
    b_hi = b >> _U32
    p00 = a_lo * b_lo
    p01 = a_lo * b_hi
    p10 = a_hi * b_lo
    p11 = a_hi * b_hi
    mid = (p00 >> _U32) + (p01 & _M32) + (p10 & _M32)  # < 3 * 2**32, no overflow
    lo = (p00 & _M32) | (mid << _U32)
    hi = p11 + (p01 >> _U32) + (p10 >> _U32) + (mid >> _U32)
    return hi, lo


@jit
def _mul_shift64(m, mul_lo, mul_hi, j):
    """floor(m * (mul_hi 2**64 + mul_lo) / 2**j) for m < 2**55, 64 < j < 128 (Ryu mulShift64)."""
    high1, low1 = _umul128(m, mul_hi)
    high0, _ = _umul128(m, mul_lo)
    total = high0 + low1
    if total < high0:
        high1 += _U1  # carry
    dist = np.uint64(j - 64)  # 0 < dist < 64 for every double (Ryu's bound)
    return (high1 << (_U64 - dist)) | (total >> dist)


@jit
def _pow5_factor(value):
    """Number of times 5 divides value (value > 0)."""
    count = 0
    while value > _U0:
        quotient = value // _U5
        if value - _U5 * quotient != _U0:
            break
        value = quotient
        count += 1
        if count > 30:  # 5**28 > 2**64: cannot happen for value > 0; a cap, not a case
            break
    return count


@jit
def _multiple_of_pow5(value, p):
    return _pow5_factor(value) >= p


@jit
def _multiple_of_pow2(value, p):
    return (value & ((_U1 << np.uint64(p)) - _U1)) == _U0


@jit
def _pow5bits(e):
    return ((e * 1217359) >> 19) + 1


@jit
def _log10_pow2(e):
    return (e * 78913) >> 18


@jit
def _log10_pow5(e):
    return (e * 732923) >> 20


@jit
def _decimal_length17(v):
    """Number of decimal digits of v < 10**17 (v >= 1)."""
    n = 1
    while n < 17 and v >= _POW10[n]:
        n += 1
    return n


@jit(inline="always")
def mul_shift_all64(m2, mm_shift, mul_lo, mul_hi, j):
    """Ryu's mulShiftAll64: ``(vr, vp, vm)``, the interval ``4 m2``, ``4 m2 + 2`` and
    ``4 m2 - 1 - mm_shift`` each multiplied by the 128-bit table entry ``(mul_hi, mul_lo)``
    and shifted right by ``j`` bits (:func:`_mul_shift64`)."""
    vr = _mul_shift64(_U4 * m2, mul_lo, mul_hi, j)
    vp = _mul_shift64(_U4 * m2 + _U2, mul_lo, mul_hi, j)
    vm = _mul_shift64(_U4 * m2 - _U1 - mm_shift, mul_lo, mul_hi, j)
    return vr, vp, vm


@jit(inline="always")
def drop_digits(vr, vp, vm, base):
    """``(vr, vp, vm) // base``: the last decimal digit (``base`` 10) or two (``base`` 100)
    removed from each bound of the interval."""
    return vr // base, vp // base, vm // base


@jit
def _d2d(ieee_mantissa, ieee_exponent):
    """Ryu d2d: the shortest, nearest decimal (digits, exponent10) of a finite nonzero double.

    ``ieee_mantissa`` (uint64, 52 bits) and ``ieee_exponent`` (int, 0..2046) are the
    fields of the double; the result ``(output, e10)`` means ``output * 10**e10``, output
    without trailing zeros only where Ryu removes them (callers count digits anyway).
    Follows d2s.c (github.com/ulfjack/ryu) line for line, the 128-bit products split into
    32-bit limbs.
    """
    if ieee_exponent == 0:
        e2 = 1 - _DOUBLE_BIAS - _MANT_BITS - 2
        m2 = ieee_mantissa
    else:
        e2 = ieee_exponent - _DOUBLE_BIAS - _MANT_BITS - 2
        m2 = _HIDDEN_BIT | ieee_mantissa
    even = (m2 & _U1) == _U0
    accept_bounds = even

    # Step 2: the interval of valid decimal representations, scaled by 4.
    mv = _U4 * m2
    mm_shift = _U1 if (ieee_mantissa != _U0 or ieee_exponent <= 1) else _U0

    # Step 3: convert to a decimal power base.
    vm_trailing_zeros = False
    vr_trailing_zeros = False
    if e2 >= 0:
        q = _log10_pow2(e2) - (1 if e2 > 3 else 0)
        e10 = q
        k = _POW5_INV_BITCOUNT + _pow5bits(q) - 1
        i = -e2 + q + k
        lo = _POW5_INV_LO[q]
        hi = _POW5_INV_HI[q]
        vr, vp, vm = mul_shift_all64(m2, mm_shift, lo, hi, i)
        if q <= 21:
            # Only one of mp, mv, mm can be a multiple of 5, if any.
            if mv % _U5 == _U0:
                vr_trailing_zeros = _multiple_of_pow5(mv, q)
            elif accept_bounds:
                vm_trailing_zeros = _multiple_of_pow5(mv - _U1 - mm_shift, q)
            elif _multiple_of_pow5(mv + _U2, q):
                vp -= _U1
    else:
        q = _log10_pow5(-e2) - (1 if -e2 > 1 else 0)
        e10 = q + e2
        i = -e2 - q
        k = _pow5bits(i) - _POW5_BITCOUNT
        j = q - k
        lo = _POW5_LO[i]
        hi = _POW5_HI[i]
        vr, vp, vm = mul_shift_all64(m2, mm_shift, lo, hi, j)
        if q <= 1:
            # mv = 4 m2 has at least two trailing zero bits.
            vr_trailing_zeros = True
            if accept_bounds:
                vm_trailing_zeros = mm_shift == _U1
            else:
                vp -= _U1
        elif q < 63:
            vr_trailing_zeros = _multiple_of_pow2(mv, q)

    # Step 4: the shortest representation in the interval (nearest, ties to even).
    removed = 0
    last_removed_digit = _U0
    if vm_trailing_zeros or vr_trailing_zeros:
        # General case (rare): track exactness of the removed digits.
        while vp // _U10 > vm // _U10:
            vm_trailing_zeros = vm_trailing_zeros and (vm % _U10 == _U0)
            vr_trailing_zeros = vr_trailing_zeros and (last_removed_digit == _U0)
            last_removed_digit = vr % _U10
            vr, vp, vm = drop_digits(vr, vp, vm, _U10)
            removed += 1
        if vm_trailing_zeros:
            while vm % _U10 == _U0 and vm > _U0:
                vr_trailing_zeros = vr_trailing_zeros and (last_removed_digit == _U0)
                last_removed_digit = vr % _U10
                vr, vp, vm = drop_digits(vr, vp, vm, _U10)
                removed += 1
        if vr_trailing_zeros and last_removed_digit == _U5 and vr % _U2 == _U0:
            last_removed_digit = _U4  # exactly halfway: round to even
        round_up = (vr == vm and (not accept_bounds or not vm_trailing_zeros)) or last_removed_digit >= _U5
        output = vr + (_U1 if round_up else _U0)
    else:
        # Common case.
        round_up = False
        if vp // _U100 > vm // _U100:
            round_up = vr % _U100 >= np.uint64(50)
            vr, vp, vm = drop_digits(vr, vp, vm, _U100)
            removed += 2
        while vp // _U10 > vm // _U10:
            round_up = vr % _U10 >= _U5
            vr, vp, vm = drop_digits(vr, vp, vm, _U10)
            removed += 1
        output = vr + (_U1 if (vr == vm or round_up) else _U0)
    return output, e10 + removed


@jit
def write_uint(value, buf, pos):
    """Write the decimal digits of an integer 0 <= value < 2**63 at ``buf[pos:]``; new pos."""
    n = 1
    v = value
    while v >= 10:
        v //= 10
        n += 1
    v = value
    for k in range(n - 1, -1, -1):
        buf[pos + k] = _ZERO + v % 10
        v //= 10
    return pos + n


@jit
def _write_below_1e8(v, end, buf):
    """Write the digits of v (uint64 < 10**8) ending just before buf[end], two at a time; start index."""
    while v >= _U100:
        pair = _U2 * (v % _U100)
        v //= _U100
        buf[end - 1] = _DIGIT_PAIRS[pair + 1]
        buf[end - 2] = _DIGIT_PAIRS[pair]
        end -= 2
    if v >= _U10:
        buf[end - 1] = _DIGIT_PAIRS[_U2 * v + _U1]
        buf[end - 2] = _DIGIT_PAIRS[_U2 * v]
        return end - 2
    buf[end - 1] = _ZERO + np.int64(v)
    return end - 1


@jit
def _write_digits(output, n, buf, pos):
    """Write the n decimal digits of output (uint64 < 10**17) at buf[pos:pos + n].

    Split into 8-digit blocks (exact integer division), each written two digits per step
    from a 100-entry pair table (as Ryu's d2s.c to_chars does): short dependency chains.
    """
    end = pos + n
    while output >= _U1E8:
        high = output // _U1E8
        block = output - high * _U1E8
        output = high
        for _ in range(4):  # exactly 8 digits, leading zeros included
            pair = _U2 * (block % _U100)
            block //= _U100
            buf[end - 1] = _DIGIT_PAIRS[pair + 1]
            buf[end - 2] = _DIGIT_PAIRS[pair]
            end -= 2
    _write_below_1e8(output, end, buf)


@jit
def _put3(buf, pos, a, b, c):
    """buf[pos:pos + 3] = (a, b, c); returns pos + 3."""
    buf[pos] = a
    buf[pos + 1] = b
    buf[pos + 2] = c
    return pos + 3


@jit
def write_shortest(bits, buf, pos):
    """Write ``repr`` of the float64 with bit pattern ``bits`` (uint64) at ``buf[pos:]``.

    ``buf`` is a uint8 array with at least :data:`MAX_REPR_LEN` bytes free from ``pos``.
    Returns the position after the last byte written.  Digits from :func:`_d2d` (Ryu),
    layout by Python's ``format_float_short`` rules (see the module docstring).
    """
    negative = (bits >> _U63) != _U0
    ieee_mantissa = bits & _MANT_MASK
    ieee_exponent = np.int64((bits >> _U52) & _EXP_MASK)
    if ieee_exponent == 2047:  # inf / nan, as repr writes them (repr ignores a NaN's sign)
        if ieee_mantissa != _U0:
            return _put3(buf, pos, 110, 97, 110)  # nan
        if negative:
            buf[pos] = _MINUS
            pos += 1
        return _put3(buf, pos, 105, 110, 102)  # inf
    if negative:
        buf[pos] = _MINUS
        pos += 1
    if ieee_exponent == 0 and ieee_mantissa == _U0:
        return _put3(buf, pos, _ZERO, _DOT, _ZERO)  # 0.0
    output, e10 = _d2d(ieee_mantissa, ieee_exponent)
    n = _decimal_length17(output)
    decpt = e10 + n  # x = 0.d1...dn * 10**decpt
    if decpt <= -4 or decpt > 16:
        # d[.ddd]e(+|-)XX
        if n == 1:
            buf[pos] = _ZERO + np.uint8(output)
            pos += 1
        else:
            _write_digits(output, n, buf, pos + 1)
            buf[pos] = buf[pos + 1]
            buf[pos + 1] = _DOT
            pos += n + 1
        exp10 = decpt - 1
        buf[pos] = _E
        if exp10 < 0:
            buf[pos + 1] = _MINUS
            exp10 = -exp10
        else:
            buf[pos + 1] = _PLUS
        pos += 2
        if exp10 >= 100:
            return _put3(buf, pos, _ZERO + exp10 // 100, _ZERO + (exp10 // 10) % 10, _ZERO + exp10 % 10)
        buf[pos] = _ZERO + exp10 // 10
        buf[pos + 1] = _ZERO + exp10 % 10
        return pos + 2
    if decpt <= 0:
        # 0.000ddd
        buf[pos] = _ZERO
        buf[pos + 1] = _DOT
        pos += 2
        for _ in range(-decpt):
            buf[pos] = _ZERO
            pos += 1
        _write_digits(output, n, buf, pos)
        return pos + n
    if decpt >= n:
        # ddd000.0
        _write_digits(output, n, buf, pos)
        pos += n
        for _ in range(decpt - n):
            buf[pos] = _ZERO
            pos += 1
        buf[pos] = _DOT
        buf[pos + 1] = _ZERO
        return pos + 2
    # dd.ddd: digits written one place right, the integer part moved left over the gap
    _write_digits(output, n, buf, pos + 1)
    for k in range(decpt):
        buf[pos + k] = buf[pos + k + 1]
    buf[pos + decpt] = _DOT
    return pos + n + 1


@jit
def _format_all(bits, buf, offsets):
    pos = 0
    offsets[0] = 0
    for i in range(bits.shape[0]):
        pos = write_shortest(bits[i], buf, pos)
        offsets[i + 1] = pos
    return pos


def format_floats(x) -> tuple[np.ndarray, np.ndarray]:
    """``repr`` of every element of ``x`` (any shape, C order), in one compiled pass.

    Returns ``(buf, offsets)``: ``buf`` a uint8 array holding the texts back to back,
    ``offsets`` int64 of length ``x.size + 1`` with element ``i`` at
    ``buf[offsets[i]:offsets[i + 1]]``.  ``buf.tobytes() == "".join(map(repr, x.flat))``
    byte for byte (tests/test_shortest.py).
    """
    a = np.ascontiguousarray(x, dtype=np.float64).reshape(-1)
    bits = a.view(np.uint64)
    buf = np.empty(a.size * MAX_REPR_LEN, np.uint8)
    offsets = np.empty(a.size + 1, np.int64)
    end = _format_all(bits, buf, offsets)
    return buf[:end], offsets


def shortest_repr(x: float) -> str:
    """``repr(float(x))`` computed by the compiled formatter (a check / convenience)."""
    buf, offsets = format_floats(np.array([x], dtype=np.float64))
    return buf.tobytes().decode("ascii")


# ---------------------------------------------------------------------------------------
# Records: many texts of one template (constant pieces, an integer, floats), in one pass


@jit
def _copy_into(src, start, stop, buf, pos):
    for k in range(start, stop):
        buf[pos] = src[k]
        pos += 1
    return pos


#: Slot code of the record's integer (``seqs[i]``) in a :class:`RecordTemplate`.
SEQ = -1


def shared(j: int) -> int:
    """Slot code of shared float ``j`` (the same value in every record, e.g. t or mu)."""
    return -2 - j


@jit
def _fill_records(seqs, bits, shared_bits, pieces, piece_offsets, slots, keys, key_offsets, buf, offsets):
    """Record i = piece 0, slot 0, piece 1, slot 1, ..., slot s-1, piece s (see RecordTemplate).

    Shared floats are formatted once into a scratch buffer and copied into each record.
    With keys (``key_offsets.size == n + 1``) each record is framed as an entry of
    :func:`astrodyn.messages.encode_batch`: u16 key length, key, u32 payload length
    (little-endian), payload.  ``offsets[i]:offsets[i + 1]`` spans record i.
    """
    n = bits.shape[0]
    n_slots = slots.shape[0]
    n_shared = shared_bits.shape[0]
    scratch = np.empty(n_shared * MAX_REPR_LEN, np.uint8)
    scratch_offsets = np.empty(n_shared + 1, np.int64)
    scratch_offsets[0] = 0
    for j in range(n_shared):
        scratch_offsets[j + 1] = write_shortest(shared_bits[j], scratch, scratch_offsets[j])
    framed = key_offsets.shape[0] == n + 1
    pos = 0
    len_at = 0
    for i in range(n):
        offsets[i] = pos
        if framed:
            klen = key_offsets[i + 1] - key_offsets[i]
            buf[pos] = klen & 0xFF
            buf[pos + 1] = (klen >> 8) & 0xFF
            pos = _copy_into(keys, key_offsets[i], key_offsets[i + 1], buf, pos + 2)
            len_at = pos
            pos += 4
        start = pos
        for k in range(n_slots):
            pos = _copy_into(pieces, piece_offsets[k], piece_offsets[k + 1], buf, pos)
            code = slots[k]
            if code >= 0:
                pos = write_shortest(bits[i, code], buf, pos)
            elif code == SEQ:
                pos = write_uint(seqs[i], buf, pos)
            else:
                j = -2 - code
                pos = _copy_into(scratch, scratch_offsets[j], scratch_offsets[j + 1], buf, pos)
        pos = _copy_into(pieces, piece_offsets[n_slots], piece_offsets[n_slots + 1], buf, pos)
        if framed:
            plen = pos - start
            for b in range(4):
                buf[len_at + b] = (plen >> (8 * b)) & 0xFF
    offsets[n] = pos
    return pos


def _concat(chunks: list[bytes]) -> tuple[np.ndarray, np.ndarray]:
    offsets = np.fromiter(accumulate(map(len, chunks), initial=0), np.int64, len(chunks) + 1)
    return np.frombuffer(b"".join(chunks), np.uint8), offsets


_NO_KEYS = (np.zeros(0, np.uint8), np.zeros(0, np.int64))


def pack_keys(keys: list[bytes]) -> tuple[np.ndarray, np.ndarray]:
    """Keys packed for :func:`format_records`: (uint8 buffer, int64 offsets), built once, reused."""
    return _concat(keys)


class RecordTemplate:
    """The fixed layout of a family of records: constant byte pieces between slots.

    A record is ``pieces[0] + slot 0 + pieces[1] + ... + slot s-1 + pieces[s]``
    (``len(pieces) == len(slots) + 1``); a slot is a column ``k >= 0`` of the per-record
    floats, :data:`SEQ` (the record's integer) or :func:`shared` ``(j)`` (shared float j).
    Build it once per layout (the message encoders cache one per model and frame).
    """

    def __init__(self, pieces: list[bytes], slots: list[int]):
        if len(pieces) != len(slots) + 1:
            raise ValueError(f"pieces: expected {len(slots) + 1} byte strings for {len(slots)} slots, got {len(pieces)}")
        self.columns = max([k + 1 for k in slots if k >= 0], default=0)
        self.n_shared = max([-1 - k for k in slots if k < SEQ], default=0)
        self.pieces, self.piece_offsets = _concat(pieces)
        self.slots = np.asarray(slots, dtype=np.int64)


def format_records(template: RecordTemplate, seqs, values, shared_values=(), keys=None) -> tuple[bytes, np.ndarray]:
    """N records of one template, written in one compiled pass.

    ``seqs`` integers 0 <= seq < 2**63 shape (N,); ``values`` finite float64 shape
    (N, template.columns), each written as ``repr`` would; ``shared_values`` the shared
    floats.  With ``keys`` (N UTF-8 byte strings < 65536 bytes, or :func:`pack_keys` of
    them) each record is framed as an ``encode_batch`` entry (u16 key length, key, u32
    payload length, payload).

    Returns ``(data, offsets)``: record ``i`` is ``data[offsets[i]:offsets[i + 1]]``.
    The caller validates the inputs (the message encoders do).
    """
    bits = np.ascontiguousarray(values, dtype=np.float64).view(np.uint64)
    n, m = bits.shape
    shared_bits = np.array(shared_values, dtype=np.float64).reshape(-1).view(np.uint64)
    if m != template.columns or shared_bits.shape[0] != template.n_shared:
        raise ValueError(f"values: expected {template.columns} columns and {template.n_shared} shared values, "
                         f"got {m} and {shared_bits.shape[0]}")
    if keys is None:
        key_buf, key_offsets = _NO_KEYS
    else:
        key_buf, key_offsets = keys if isinstance(keys, tuple) else _concat(keys)
        if key_offsets.shape != (n + 1,):
            raise ValueError(f"keys: expected {n} keys, got {key_offsets.shape[0] - 1}")
    per_record = len(template.pieces) + MAX_REPR_LEN * len(template.slots) + 6  # a seq slot: <= 19 digits
    buf = np.empty(n * per_record + len(key_buf), np.uint8)
    offsets = np.empty(n + 1, np.int64)
    end = _fill_records(np.ascontiguousarray(seqs, dtype=np.int64), bits, shared_bits, template.pieces,
                        template.piece_offsets, template.slots, key_buf, key_offsets, buf, offsets)
    return buf[:end].tobytes(), offsets
