"""Compiled batch ingest: a whole ``@batch`` envelope checked and written into the open
MCAP chunk in one call.

The logger's Python path (:meth:`astrodyn.service.logger.Logger._record`) costs about
7 us per message: envelope split, the canonical-layout regex, float/int conversions, the
seq tracker and the record pack, each a few hundred ns of interpreter work.  For the
common case (a state in the batch encoders' canonical layout, on a known key, with the
next seq of its channel, at the same ``t`` as the entry before it) this module does the
same work compiled, and hands every other entry back to the Python path, one at a time,
in arrival order.  So the file is byte for byte what the Python path writes, and the
verdict on every payload is the Python path's:

* The grammar recognised here is the one of the regexes behind
  :data:`astrodyn.messages.FAST_CHECKS` (in :mod:`astrodyn.messages.codec`: numbers,
  seq, the model enums, the frame name).  Anything else returns :data:`SLOW`.
* The numeric rules are decided with an approximate parse (relative error < 1e-13,
  :func:`_approx_number`) and a margin: ``mu > 1e-300`` (then ``float(mu) > 0`` for sure)
  and ``| |q| - 1 | <= 0.999 * QUAT_NORM_TOL`` (then the exact check passes for sure).
  A value inside the margin goes to the exact Python check (:data:`SLOW`).
* ``t`` is not converted here: every entry's ``t`` text is compared with the text whose
  exact float and log_time the caller computed (:data:`NEED_T` asks for a new one), so
  ``log_time = epoch_ns + round(float(t) * 1e9)`` is the Python expression.
* ``seq`` (at most 16 digits, <= 2**53 - 1) is parsed exactly; a seq that is not the next
  one of its channel (gap, late, duplicate) goes to :class:`SeqTracker` (:data:`SLOW`).

Tested against the Python path entry by entry (tests/test_logger_hot_path.py).
"""

from __future__ import annotations

import numpy as np

from astrodyn.jit import jit

#: Return codes of :func:`ingest_batch` (with the index of the entry they concern).
DONE, SLOW, NEED_T, CHUNK_FULL = 0, 1, 2, 3
#: ``kinds`` codes of layout entries.
KIND_OTHER, KIND_ORBIT, KIND_ATTITUDE = 0, 1, 2

_MESSAGE_OPCODE = 5
_MAX_SEQ = 2**53 - 1


@jit
def frame_batch(buf, key_start, key_len, pay_start, pay_len):
    """Split an envelope (layout: :func:`astrodyn.messages.encode_batch`) into spans.

    Fills the four int64 arrays (capacity ``>= count``) and returns ``count``; returns
    ``-1`` for any damage or when the arrays are too small (the caller then runs
    :func:`astrodyn.messages.decode_batch` for the exact error).
    """
    size = buf.shape[0]
    if size < 8 or buf[0] != 65 or buf[1] != 68 or buf[2] != 66 or buf[3] != 49:  # b"ADB1"
        return -1
    count = _le_uint(buf, 4, 4)
    if count > key_start.shape[0]:
        return -1
    pos = 8
    for i in range(count):
        start, n = _prefixed_span(buf, pos, 2)  # the key, u16 length
        if start < 0:
            return -1
        key_start[i] = start
        key_len[i] = n
        start, n = _prefixed_span(buf, start + n, 4)  # the payload, u32 length
        if start < 0:
            return -1
        pay_start[i] = start
        pay_len[i] = n
        pos = start + n
    if pos != size:
        return -1
    return count


@jit(inline="always")
def _le_uint(buf, pos, width):
    """The unsigned little-endian integer of the ``width`` bytes of ``buf`` at ``pos`` (int64)."""
    n = np.int64(0)
    for j in range(width):
        n |= np.int64(buf[pos + j]) << (8 * j)
    return n


@jit(inline="always")
def _prefixed_span(buf, pos, width):
    """The span of bytes that a ``width``-byte little-endian length at ``pos`` heads:
    ``(start, length)``, or ``(-1, 0)`` when the length or the span runs past the end."""
    size = buf.shape[0]
    if pos + width > size:
        return -1, np.int64(0)
    n = _le_uint(buf, pos, width)
    if pos + width + n > size:
        return -1, np.int64(0)
    return pos + width, n


@jit
def same_keys(buf, key_start, key_len, count, blob, blob_start, blob_len):
    """True when the ``count`` keys of this envelope equal the layout's keys byte for byte."""
    if blob_start.shape[0] != count:
        return False
    for i in range(count):
        n = key_len[i]
        if n != blob_len[i]:
            return False
        a = key_start[i]
        b = blob_start[i]
        for j in range(n):
            if buf[a + j] != blob[b + j]:
                return False
    return True


@jit
def _literal(buf, pos, end, lit):
    """Position after ``lit`` if ``buf[pos:]`` starts with it, else -1 (also for ``pos < 0``)."""
    if pos < 0:
        return -1
    n = lit.shape[0]
    if pos + n > end:
        return -1
    for j in range(n):
        if buf[pos + j] != lit[j]:
            return -1
    return pos + n


@jit
def _digits(buf, pos, end):
    """Position after the run of ASCII digits starting at ``pos``."""
    while pos < end and 48 <= buf[pos] <= 57:
        pos += 1
    return pos


@jit
def _number(buf, pos, end):
    """Position after a number of the ``_FAST_NUM`` grammar starting at ``pos``, else -1.

    ``-?(?:(?:0|[1-9][0-9]{0,16})\\.[0-9]{1,24}
    |[0-9](?:\\.[0-9]{1,24})?[eE](?:-[0-9]{1,3}|\\+?(?:[0-9]{1,2}|[12][0-9]{2}|30[0-7])))``
    (the character after the number is never a digit, '.', 'e' or 'E' in the layouts, so
    the longest run decides).
    """
    if pos < end and buf[pos] == 45:  # '-'
        pos += 1
    p = _digits(buf, pos, end)
    n_int = p - pos
    if n_int == 0:
        return -1
    if p < end and buf[p] == 46:  # '.'
        f = _digits(buf, p + 1, end)
        n_frac = f - (p + 1)
        if n_frac < 1 or n_frac > 24:
            return -1
        p = f
        has_frac = True
    else:
        has_frac = False
    if p < end and (buf[p] == 101 or buf[p] == 69):  # exponent form: one mantissa digit
        if n_int != 1:
            return -1
        p += 1
        if p < end and buf[p] == 45:  # '-' and 1-3 digits
            e = _digits(buf, p + 1, end)
            n_exp = e - (p + 1)
            if n_exp < 1 or n_exp > 3:
                return -1
            return e
        if p < end and buf[p] == 43:  # '+'
            p += 1
        e = _digits(buf, p, end)
        n_exp = e - p
        if n_exp == 1 or n_exp == 2:
            return e
        if n_exp == 3:
            d0 = buf[p]
            if d0 == 49 or d0 == 50:  # [12][0-9]{2}
                return e
            if d0 == 51 and buf[p + 1] == 48 and buf[p + 2] <= 55:  # 30[0-7]
                return e
        return -1
    if not has_frac:
        return -1
    if n_int > 17 or (n_int > 1 and buf[pos] == 48):  # 0 | [1-9][0-9]{0,16}
        return -1
    return p


@jit
def _approx_number(buf, pos, end):
    """The value of a number already accepted by :func:`_number` in ``buf[pos:end]``,
    to a relative error below 1e-13 (at most 42 significant digits, each step of the
    accumulation and the power of ten rounded once)."""
    neg = False
    if buf[pos] == 45:
        neg = True
        pos += 1
    m = 0.0
    scale = 0
    seen_dot = False
    p = pos
    while p < end:
        c = buf[p]
        if c == 46:
            seen_dot = True
        elif 48 <= c <= 57:
            m = m * 10.0 + (c - 48)
            if seen_dot:
                scale -= 1
        else:
            break
        p += 1
    if p < end:  # exponent
        p += 1
        sign = 1
        if buf[p] == 45:
            sign = -1
            p += 1
        elif buf[p] == 43:
            p += 1
        e = 0
        while p < end:
            e = e * 10 + (buf[p] - 48)
            p += 1
        scale += sign * e
    if m == 0.0:
        v = 0.0
    elif scale >= 0:
        v = m * 10.0 ** scale
    else:
        v = m / 10.0 ** (-scale) if scale > -300 else (m / 1e300) / 10.0 ** (-scale - 300)
    return -v if neg else v


@jit
def _enum(buf, pos, end, names, name_start, name_len):
    """Position of the closing '"' if ``buf[pos:]`` is one of the names followed by '"', else -1."""
    q = pos
    while q < end and buf[q] != 34:
        q += 1
    if q >= end:
        return -1
    n = q - pos
    for k in range(name_start.shape[0]):
        if name_len[k] != n:
            continue
        s = name_start[k]
        ok = True
        for j in range(n):
            if buf[pos + j] != names[s + j]:
                ok = False
                break
        if ok:
            return q
    return -1


@jit
def _is_name_char(c):
    # [A-Za-z0-9_.-]
    return (48 <= c <= 57) or (65 <= c <= 90) or (97 <= c <= 122) or c == 95 or c == 46 or c == 45


@jit
def _check_entry(buf, pos, end, kind, lits, lit_start, lit_len, names, name_start, name_len, quat_tol, out):
    """Check one payload ``buf[pos:end]`` against the canonical layout of ``kind``.

    Returns True and ``out = (t_start, t_end, seq)`` when it matches and the numeric rules
    hold with margin; False otherwise.  ``lits`` holds the layout's literal pieces
    (``lit_start/lit_len`` index them: 0 ``{"t":``, 1 ``,"seq":``, 2 ``,"model":"``,
    3 ``","r":[``, 4 ``],"v":[``, 5 ``],"mu":``, 6 ``,"frame":"``, 7 ``"}``,
    8 ``","q":[``, 9 ``],"w":[``, 10 ``]}``); ``names`` the model enums (orbit models
    first: ``name_start[kind - 1]`` rows).
    """
    p = _literal(buf, pos, end, lits[lit_start[0]:lit_start[0] + lit_len[0]])
    if p < 0:
        return False
    t0 = p
    p = _number(buf, p, end)
    if p < 0:
        return False
    out[0] = t0
    out[1] = p
    p = _literal(buf, p, end, lits[lit_start[1]:lit_start[1] + lit_len[1]])
    if p < 0:
        return False
    s = _digits(buf, p, end)
    nd = s - p
    if nd < 1 or nd > 16 or (nd > 1 and buf[p] == 48):
        return False
    seq = np.int64(0)
    for j in range(p, s):
        seq = seq * 10 + (buf[j] - 48)
    if seq > _MAX_SEQ:
        return False
    out[2] = seq
    p = _literal(buf, s, end, lits[lit_start[2]:lit_start[2] + lit_len[2]])
    if p < 0:
        return False
    sumsq = np.zeros(1)
    row = kind - 1
    p = _enum(buf, p, end, names[row], name_start[row], name_len[row])
    if p < 0:
        return False
    if kind == 1:
        sumsq[0] = np.nan  # no squares needed
        p = _literal(buf, p, end, lits[lit_start[3]:lit_start[3] + lit_len[3]])
        p = _numbers(buf, p, end, 3, sumsq)
        p = _literal(buf, p, end, lits[lit_start[4]:lit_start[4] + lit_len[4]])
        p = _numbers(buf, p, end, 3, sumsq)
        p = _literal(buf, p, end, lits[lit_start[5]:lit_start[5] + lit_len[5]])
        m0 = p
        p = _number(buf, p, end) if p >= 0 else -1
        if p < 0 or not _approx_number(buf, m0, p) > 1e-300:
            return False
        p = _literal(buf, p, end, lits[lit_start[6]:lit_start[6] + lit_len[6]])
        if p < 0:
            return False
        f0 = p
        while p < end and _is_name_char(buf[p]):
            p += 1
        if p - f0 < 1 or p - f0 > 128:
            return False
        p = _literal(buf, p, end, lits[lit_start[7]:lit_start[7] + lit_len[7]])
        return p == end
    # attitude
    p = _literal(buf, p, end, lits[lit_start[8]:lit_start[8] + lit_len[8]])
    sumsq[0] = 0.0
    p = _numbers(buf, p, end, 4, sumsq)
    if p < 0 or not abs(np.sqrt(sumsq[0]) - 1.0) <= 0.999 * quat_tol:
        return False
    p = _literal(buf, p, end, lits[lit_start[9]:lit_start[9] + lit_len[9]])
    sumsq[0] = np.nan
    p = _numbers(buf, p, end, 3, sumsq)
    p = _literal(buf, p, end, lits[lit_start[10]:lit_start[10] + lit_len[10]])
    return p == end


@jit
def _numbers(buf, p, end, n, sumsq):
    """Position after ``n`` comma-separated numbers starting at ``p`` (-1 if ``p < 0`` or
    no match); adds their approximate squares to ``sumsq[0]`` unless it is NaN."""
    for j in range(n):
        if p < 0:
            return -1
        a = p
        p = _number(buf, p, end)
        if p < 0:
            return -1
        if sumsq[0] == sumsq[0]:
            x = _approx_number(buf, a, p)
            sumsq[0] += x * x
        if j < n - 1:
            if p < end and buf[p] == 44:
                p += 1
            else:
                return -1
    return p


@jit
# parameters one role a line: batch spans, grammar, times, seq accounting, chunk, result (fmt: skip)
def ingest_batch(
    buf, i, count, pay_start, pay_len, kinds, cids, slots,
    lits, lit_start, lit_len, names, name_start, name_len, quat_tol,
    t_text, log_time, publish_time,
    seq_next, seq_count,
    chunk, chunk_state, chunk_size, idx_channel, idx_time, idx_offset,
    result,
):  # fmt: skip
    """Check and write entries ``i, i + 1, ...`` of a framed envelope into the open chunk.

    Stops at the first entry it cannot take and returns ``(code, index)`` in ``result``:
    :data:`SLOW` (the Python path takes entry ``index``), :data:`NEED_T` (entry
    ``index``'s ``t`` text differs from ``t_text``: ``result[2:4]`` is its span),
    :data:`CHUNK_FULL` (the chunk holds more than ``chunk_size`` bytes, or entry ``index``
    does not fit in the buffer: finalize it and call again from ``index``) or
    :data:`DONE`.  ``chunk_state = [used bytes, index entries, messages written here]``.
    Each written entry is an MCAP Message record (opcode 5, length, channel id,
    ``seq mod 2**32``, log_time, publish_time, payload) with its index entry; its channel's
    ``seq_next``/``seq_count`` advance.
    """
    out = np.zeros(3, dtype=np.int64)
    nt = t_text.shape[0]
    cap = chunk.shape[0]
    used = chunk_state[0]
    n_idx = chunk_state[1]
    written = 0
    code = DONE
    while i < count:
        kind = kinds[i]
        if kind == 0:
            code = SLOW
            break
        a = pay_start[i]
        b = a + pay_len[i]
        if not _check_entry(buf, a, b, kind, lits, lit_start, lit_len, names, name_start, name_len, quat_tol, out):
            code = SLOW
            break
        same = out[1] - out[0] == nt
        if same:
            for j in range(nt):
                if buf[out[0] + j] != t_text[j]:
                    same = False
                    break
        if not same:
            code = NEED_T
            result[2] = out[0]
            result[3] = out[1]
            break
        slot = slots[i]
        seq = out[2]
        if seq != seq_next[slot]:
            code = SLOW
            break
        size = 31 + (b - a)
        if used + size > cap or n_idx >= idx_channel.shape[0]:
            code = CHUNK_FULL
            break
        cid = cids[i]
        # Message record: opcode u8, length u64, channel_id u16, sequence u32, log_time u64, publish_time u64
        chunk[used] = _MESSAGE_OPCODE
        ln = np.uint64(22 + (b - a))
        for j in range(8):
            chunk[used + 1 + j] = (ln >> np.uint64(8 * j)) & np.uint64(0xFF)
        chunk[used + 9] = cid & 0xFF
        chunk[used + 10] = (cid >> 8) & 0xFF
        s32 = np.uint64(seq) & np.uint64(0xFFFFFFFF)
        for j in range(4):
            chunk[used + 11 + j] = (s32 >> np.uint64(8 * j)) & np.uint64(0xFF)
        lt = np.uint64(log_time)
        pt = np.uint64(publish_time)
        for j in range(8):
            chunk[used + 15 + j] = (lt >> np.uint64(8 * j)) & np.uint64(0xFF)
            chunk[used + 23 + j] = (pt >> np.uint64(8 * j)) & np.uint64(0xFF)
        chunk[used + 31 : used + size] = buf[a:b]
        idx_channel[n_idx] = cid
        idx_time[n_idx] = log_time
        idx_offset[n_idx] = used
        n_idx += 1
        used += size
        seq_next[slot] = seq + 1
        seq_count[slot] += 1
        written += 1
        i += 1
        if used > chunk_size:
            code = CHUNK_FULL
            break
    chunk_state[0] = used
    chunk_state[1] = n_idx
    chunk_state[2] += written
    result[0] = code
    result[1] = i


_LITERALS = (
    b'{"t":', b',"seq":', b',"model":"', b'","r":[', b'],"v":[', b'],"mu":', b',"frame":"', b'"}',
    b'","q":[', b'],"w":[', b']}',
)


def grammar_tables(orbit_models, attitude_models):
    """The literal pieces and model enums :func:`ingest_batch` matches, as arrays:
    ``(lits, lit_start, lit_len, names, name_start, name_len)``; ``names`` has one row
    per kind (orbit, attitude), unused enum slots have length -1."""
    lits = np.frombuffer(b"".join(_LITERALS), dtype=np.uint8).copy()
    lit_len = np.array([len(x) for x in _LITERALS], dtype=np.int64)
    lit_start = np.concatenate([[0], np.cumsum(lit_len)[:-1]]).astype(np.int64)
    rows = [[m.encode() for m in orbit_models], [m.encode() for m in attitude_models]]
    width = max(sum(len(m) for m in row) for row in rows)
    k = max(len(row) for row in rows)
    names = np.zeros((2, width), dtype=np.uint8)
    name_start = np.zeros((2, k), dtype=np.int64)
    name_len = np.full((2, k), -1, dtype=np.int64)
    for r, row in enumerate(rows):
        at = 0
        for j, m in enumerate(row):
            names[r, at : at + len(m)] = np.frombuffer(m, dtype=np.uint8)
            name_start[r, j] = at
            name_len[r, j] = len(m)
            at += len(m)
    return lits, lit_start, lit_len, names, name_start, name_len


def warm_up(grammar) -> None:
    """Run every kernel once on a two-entry envelope with the argument types the logger
    uses, so a cold numba cache compiles (a few seconds, once per install) before the
    logger declares itself ready instead of while publishers wait on it."""
    payloads = [
        b'{"t":0.5,"seq":0,"model":"kepler","r":[1.0,0.0,0.0],"v":[0.0,1.0,0.0],"mu":1.0,"frame":"GCRF"}',
        b'{"t":0.5,"seq":0,"model":"torque_free","q":[1.0,0.0,0.0,0.0],"w":[0.0,0.0,0.1]}',
    ]
    env = b"ADB1" + (2).to_bytes(4, "little") + b"".join(
        (1).to_bytes(2, "little") + b"k" + len(p).to_bytes(4, "little") + p for p in payloads)
    buf = np.frombuffer(env, dtype=np.uint8)  # read-only, as the logger's payloads
    spans = tuple(np.zeros(4, dtype=np.int64) for _ in range(4))
    count = frame_batch(buf, *spans)
    blob = np.frombuffer(b"kk", dtype=np.uint8).copy()
    same_keys(buf, spans[0], spans[1], count, blob, np.array([0, 1], dtype=np.int64), np.ones(2, dtype=np.int64))
    ingest_batch(
        buf, 0, count, spans[2], spans[3], np.array([KIND_ORBIT, KIND_ATTITUDE], dtype=np.int8),
        np.ones(2, dtype=np.int64), np.arange(2, dtype=np.int64), *grammar, 1e-9,
        np.frombuffer(b"0.5", dtype=np.uint8).copy(), 1, 1, np.zeros(2, dtype=np.int64), np.zeros(2, dtype=np.int64),
        np.zeros(4096, dtype=np.uint8), np.zeros(3, dtype=np.int64), 2048, np.zeros(8, dtype=np.uint16),
        np.zeros(8, dtype=np.uint64), np.zeros(8, dtype=np.uint64), np.zeros(4, dtype=np.int64),
    )
