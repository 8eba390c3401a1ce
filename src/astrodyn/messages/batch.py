"""Many messages at once: the batch encoders (one payload per body, payloads and framing in
one compiled pass) and the batch envelope (many ``(key, payload)`` pairs in one bus sample;
layout in :mod:`astrodyn.messages`)."""

from __future__ import annotations

import functools
import struct
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from astrodyn.messages.codec import attitude_message, checked_float, encode, orbit_message
from astrodyn.messages.errors import MessageError, show_value
from astrodyn.messages.keys import ATTITUDE_MODELS, MAX_SEQ, NAME_FULL_RE, NAME_PATTERN, ORBIT_MODELS, QUAT_NORM_TOL

# ---------------------------------------------------------------------------------------
# Fast batch encoders: one payload per body (per-body channels stay intact)


def _batch_arrays(kind: str, seqs: Any, arrays: dict[str, tuple[Any, int]]) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    n = None
    out = {}
    for field, (x, width) in arrays.items():
        a = np.asarray(x, dtype=float)
        if a.ndim != 2 or a.shape[1] != width or (n is not None and a.shape[0] != n):
            raise MessageError(f"{kind}.{field}: expected an array of shape (N, {width}) with the same N for every field, got shape {a.shape}")
        n = a.shape[0]
        if not np.isfinite(a).all():
            bad = int(np.argwhere(~np.isfinite(a))[0, 0])
            raise MessageError(f"{kind}.{field}[{bad}]: expected array of {width} finite numbers, got {show_value(a[bad].tolist())}")
        out[field] = a
    if isinstance(seqs, (int, np.integer)) and not isinstance(seqs, (bool, np.bool_)) and 0 <= seqs <= MAX_SEQ:
        return np.full(n, seqs, dtype=np.int64), out  # the common case: one valid seq for every body
    s = np.asarray(seqs)
    if s.ndim == 0:
        s = np.full(n, s)
    if s.shape != (n,) or not (np.issubdtype(s.dtype, np.integer) or (np.issubdtype(s.dtype, np.floating) and np.all(np.isfinite(s)) and np.all(s == np.round(s)))):
        raise MessageError(f"{kind}.seq: expected an integer or an array of {n} integers, got {show_value(s.tolist())}")
    if n and (s.min() < 0 or s.max() > MAX_SEQ):
        raise MessageError(f"{kind}.seq: expected integers 0 <= seq <= 2**53-1, got range [{s.min()}, {s.max()}]")
    return s.astype(np.int64), out


def _orbit_records(t: float, seqs: Any, model: str, r: Any, v: Any, mu: float, frame: str, keys: Any) -> tuple[bytes, np.ndarray]:
    """Validate like :func:`orbit_message`, then write every payload in one compiled pass."""
    from astrodyn.messages import shortest  # numba: loaded on first use, not with this module

    tf = checked_float(t, "orbit", "t")
    muf = checked_float(mu, "orbit", "mu")
    if muf <= 0:
        raise MessageError(f"orbit.mu: expected > 0, got {muf!r}")
    if model not in ORBIT_MODELS:
        raise MessageError(f"orbit.model: expected one of {', '.join(ORBIT_MODELS)}, got {show_value(model)}")
    if not isinstance(frame, str) or not NAME_FULL_RE.search(frame):
        raise MessageError(f"orbit.frame: expected a frame name matching {NAME_PATTERN}, got {show_value(frame)}")
    seq_arr, a = _batch_arrays("orbit", seqs, {"r": (r, 3), "v": (v, 3)})
    return shortest.format_records(_orbit_template(model, frame), seq_arr, np.concatenate([a["r"], a["v"]], axis=1),
                                    (tf, muf), _batch_keys(keys, seq_arr.shape[0]))


@functools.lru_cache(maxsize=256)
def _orbit_template(model: str, frame: str):
    """``{"t":T,"seq":S,"model":"<model>","r":[0,1,2],"v":[3,4,5],"mu":MU,"frame":"<frame>"}``."""
    from astrodyn.messages.shortest import SEQ, RecordTemplate, shared

    pieces = [b'{"t":', b',"seq":', f',"model":"{model}","r":['.encode(), b",", b",", b'],"v":[', b",", b",",
              b'],"mu":', f',"frame":"{frame}"}}'.encode()]
    return RecordTemplate(pieces, [shared(0), SEQ, 0, 1, 2, 3, 4, 5, shared(1)])


@functools.lru_cache(maxsize=64)
def _attitude_template(model: str):
    """``{"t":T,"seq":S,"model":"<model>","q":[0,1,2,3],"w":[4,5,6]}``."""
    from astrodyn.messages.shortest import SEQ, RecordTemplate, shared

    pieces = [b'{"t":', b',"seq":', f',"model":"{model}","q":['.encode(), b",", b",", b",", b'],"w":[', b",", b",",
              b"]}"]
    return RecordTemplate(pieces, [shared(0), SEQ, 0, 1, 2, 3, 4, 5, 6])


def _attitude_records(t: float, seqs: Any, model: str, q: Any, w: Any, keys: Any) -> tuple[bytes, np.ndarray]:
    """Validate like :func:`attitude_message`, then write every payload in one compiled pass."""
    from astrodyn.messages import shortest

    tf = checked_float(t, "attitude", "t")
    if model not in ATTITUDE_MODELS:
        raise MessageError(f"attitude.model: expected one of {', '.join(ATTITUDE_MODELS)}, got {show_value(model)}")
    seq_arr, a = _batch_arrays("attitude", seqs, {"q": (q, 4), "w": (w, 3)})
    qa = a["q"]
    if qa.size:
        err = np.abs(np.sqrt(np.einsum("ij,ij->i", qa, qa)) - 1.0)
        if not np.all(err <= QUAT_NORM_TOL):
            bad = int(np.argmax(err))
            raise MessageError(f"attitude.q[{bad}]: expected a unit quaternion (| |q| - 1 | <= {QUAT_NORM_TOL:g}), got |q| = {float(np.linalg.norm(qa[bad]))!r}")
    return shortest.format_records(_attitude_template(model), seq_arr, np.concatenate([qa, a["w"]], axis=1), (tf,),
                                    _batch_keys(keys, seq_arr.shape[0]))


class BatchKeys:
    """Channel keys checked and packed once for :func:`frame_orbit_batch` / :func:`frame_attitude_batch`.

    ``BatchKeys(keys)`` with ``keys`` a sequence of strings (UTF-8 <= 65535 bytes each, as
    :func:`encode_batch` requires); pass it instead of the list when the same keys are
    framed at every step (a propagator's bodies), which saves re-encoding them.
    """

    def __init__(self, keys: Sequence[str]):
        if isinstance(keys, (str, bytes)):
            raise MessageError(f"batch.keys: expected a sequence of key strings, got {show_value(keys)}")
        encoded = []
        for i, key in enumerate(keys):
            if not isinstance(key, str):
                raise MessageError(f"batch[{i}].key: expected a string, got {show_value(key)}")
            kb = key.encode("utf-8")
            if len(kb) > _MAX_KEY:
                raise MessageError(f"batch[{i}]: expected key <= 65535 bytes and payload < 4 GiB, got {len(kb)} and 0")
            encoded.append(kb)
        from astrodyn.messages import shortest

        self.count = len(encoded)
        self.packed = shortest.pack_keys(encoded)

    def __len__(self) -> int:
        return self.count


def _batch_keys(keys: Any, n: int) -> tuple[np.ndarray, np.ndarray] | None:
    """Packed UTF-8 keys for framed records (checked as :func:`encode_batch` checks them), or None."""
    if keys is None:
        return None
    if not isinstance(keys, BatchKeys):
        keys = BatchKeys(keys)
    if keys.count != n:
        raise MessageError(f"batch.keys: expected a sequence of {n} key strings, got {keys.count}")
    return keys.packed


def _split(data: bytes, offsets: np.ndarray) -> list[bytes]:
    o = offsets.tolist()
    return [data[o[i]:o[i + 1]] for i in range(len(o) - 1)]


#: Fewer bodies than this are encoded message by message (the builder and :func:`encode`:
#: about 2.3 us each) instead of in one compiled pass, whose set-up alone costs 9-13 us
#: (numba's dispatch of a dozen arrays); the bytes are the same (tests/test_batch_encode.py).
FEW_BODIES = 6


def _one_by_one(build: Any, seqs: Any, rows: tuple) -> list[bytes] | None:
    """``[encode(build(seq_i, *row_i)), ...]`` for 1 to ``FEW_BODIES - 1`` bodies (``rows``:
    one sequence per array argument, a row per body); None for more or for anything the
    builder refuses (the compiled path then gives its own verdict and error)."""
    try:
        n = len(rows[0])
        if not 0 < n < FEW_BODIES or any(len(a) != n for a in rows):
            return None
        seq_list = [seqs] * n if type(seqs) is int else list(seqs)
        if len(seq_list) != n:
            return None
        return [encode(build(seq, *row)) for seq, *row in zip(seq_list, *rows)]
    except (MessageError, TypeError, ValueError):
        return None


def encode_orbit_batch(t: float, seqs: Any, model: str, r: Any, v: Any, mu: float, frame: str = "GCRF") -> list[bytes]:
    """Encode N orbit states at one time ``t``: one JSON payload per body, in order.

    ``seqs`` is one integer (the same for every body) or N integers; ``r``, ``v`` shape
    (N, 3) in m and m/s. The bytes equal ``encode(orbit_message(...))`` for each body
    (tested): every float is written by a compiled shortest round-trip formatter that
    gives ``repr``'s bytes (:mod:`astrodyn.messages.shortest`), all N payloads in one pass
    (fewer than :data:`FEW_BODIES`: one by one, the same bytes).
    """
    few = _one_by_one(lambda seq, ri, vi: orbit_message(t, seq, model, ri, vi, mu, frame), seqs, (r, v))
    return few if few is not None else _split(*_orbit_records(t, seqs, model, r, v, mu, frame, None))


def encode_attitude_batch(t: float, seqs: Any, model: str, q: Any, w: Any) -> list[bytes]:
    """Encode N attitude states at one time ``t``: one JSON payload per body, in order.

    ``q`` shape (N, 4) scalar first, unit norm (checked to :data:`QUAT_NORM_TOL`); ``w``
    shape (N, 3) rad/s body axes. Bytes equal ``encode(attitude_message(...))`` per body
    (fewer than :data:`FEW_BODIES`: one by one).
    """
    few = _one_by_one(lambda seq, qi, wi: attitude_message(t, seq, model, qi, wi), seqs, (q, w))
    return few if few is not None else _split(*_attitude_records(t, seqs, model, q, w, None))


def frame_orbit_batch(keys: Sequence[str] | BatchKeys, t: float, seqs: Any, model: str, r: Any, v: Any, mu: float,
                      frame: str = "GCRF") -> bytes:
    """:func:`encode_orbit_batch` with each payload framed as an envelope entry under ``keys[i]``.

    ``keys``: N key strings, or a :class:`BatchKeys` of them packed once for reuse.
    Returns the entries back to back (``key_len u16, key, payload_len u32, payload``);
    :func:`batch_envelope` puts one or more such runs into an envelope, equal byte for
    byte to ``encode_batch(zip(keys, encode_orbit_batch(...)))`` (tested).
    """
    return _orbit_records(t, seqs, model, r, v, mu, frame, keys)[0]


def frame_attitude_batch(keys: Sequence[str] | BatchKeys, t: float, seqs: Any, model: str, q: Any, w: Any) -> bytes:
    """:func:`encode_attitude_batch` framed as envelope entries (see :func:`frame_orbit_batch`)."""
    return _attitude_records(t, seqs, model, q, w, keys)[0]


# ---------------------------------------------------------------------------------------
# Batch envelope (binary framing of many (key, payload) pairs in one bus sample)

BATCH_MAGIC = b"ADB1"
_U32 = struct.Struct("<I")
_U16 = struct.Struct("<H")
_MAX_KEY = 0xFFFF
_MAX_PAYLOAD = 0xFFFFFFFF


def encode_batch(items: Iterable[tuple[str, bytes]]) -> bytes:
    """Frame ``(key, payload)`` pairs into one envelope (layout in the module docstring)."""
    return batch_envelope([frame_entries(items)])


def frame_entries(items: Iterable[tuple[str, bytes]]) -> tuple[bytes, int]:
    """The entries of an envelope for ``(key, payload)`` pairs, without the header: (run, count)."""
    parts = []
    count = 0
    pack16, pack32 = _U16.pack, _U32.pack
    for item in items:
        try:
            key, payload = item
        except (TypeError, ValueError):
            raise MessageError(f"batch[{count}]: expected a (key, payload) pair, got {show_value(item)}") from None
        if not isinstance(key, str):
            raise MessageError(f"batch[{count}].key: expected a string, got {show_value(key)}")
        if not isinstance(payload, (bytes, bytearray, memoryview)):
            raise MessageError(f"batch[{count}].payload: expected bytes, got {type(payload).__name__}")
        kb = key.encode("utf-8")
        if len(kb) > _MAX_KEY or len(payload) > _MAX_PAYLOAD:
            raise MessageError(f"batch[{count}]: expected key <= 65535 bytes and payload < 4 GiB, got {len(kb)} and {len(payload)}")
        parts += (pack16(len(kb)), kb, pack32(len(payload)), payload)
        count += 1
    return b"".join(parts), count


def batch_envelope(runs: Iterable[tuple[bytes, int]]) -> bytes:
    """One envelope from runs of framed entries, each ``(run, count)``: :func:`frame_entries`'s
    result, or ``(frame_orbit_batch(keys, ...), len(keys))`` and likewise for attitude."""
    runs = list(runs)
    return b"".join([BATCH_MAGIC, _U32.pack(sum(c for _, c in runs))] + [r for r, _ in runs])


def _prefixed(buf: bytes, pos: int, prefix: struct.Struct, what: str) -> tuple[int, bytes]:
    """The bytes after the length prefix at ``pos`` (``prefix``: u16 or u32 little-endian)
    and the position after them; MessageError naming ``what`` if they do not fit."""
    size = len(buf)
    if pos + prefix.size > size:
        raise MessageError(f"{what}_len: expected {prefix.size} bytes, got {size - pos} (truncated)")
    (n,) = prefix.unpack_from(buf, pos)
    pos += prefix.size
    if pos + n > size:
        raise MessageError(f"{what}: expected {n} bytes, got {size - pos} (truncated)")
    return pos + n, buf[pos : pos + n]


def decode_batch(data: bytes | bytearray | memoryview) -> list[tuple[str, bytes]]:
    """Split an envelope back into ``(key, payload)`` pairs; MessageError on any damage.

    Errors name the entry and what was missing, e.g.
    ``batch[3].payload: expected 120 bytes, got 40 (truncated)``.
    """
    buf = bytes(data)
    size = len(buf)
    if size < 8:
        raise MessageError(f"batch: expected at least 8 header bytes, got {size} (truncated)")
    if buf[:4] != BATCH_MAGIC:
        raise MessageError(f"batch: expected magic {BATCH_MAGIC!r}, got {buf[:4]!r}")
    (count,) = _U32.unpack_from(buf, 4)
    if count > (size - 8) // 6:  # every entry needs at least 6 bytes of lengths
        raise MessageError(f"batch: expected at most {(size - 8) // 6} entries in {size} bytes, header says {count} (truncated or corrupt)")
    out = []
    pos = 8
    for i in range(count):
        pos, raw_key = _prefixed(buf, pos, _U16, f"batch[{i}].key")
        try:
            key = raw_key.decode("utf-8")
        except UnicodeDecodeError:
            raise MessageError(f"batch[{i}].key: expected UTF-8, got {raw_key[:40]!r}") from None
        pos, payload = _prefixed(buf, pos, _U32, f"batch[{i}].payload")
        out.append((key, payload))
    if pos != size:
        raise MessageError(f"batch: expected {count} entries ending at byte {pos}, got {size - pos} trailing bytes")
    return out
