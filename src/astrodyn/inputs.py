"""Argument checks shared by the public functions of the core (:mod:`astrodyn.orbit`,
:mod:`astrodyn.rotation`, :mod:`astrodyn.attitude`).

The contract is docs/architecture.md, section 2 ("Bad numbers"): a bad argument raises a
one-line error that names the function and the argument.  Every public core function
converts its numeric arguments here, so one rule holds everywhere:

* **Real numbers only** (:func:`real_array`, :func:`real_scalar`): Python and numpy ints,
  unsigned ints and floats of any width, and object arrays holding only such ints and
  floats, are converted to float64 as ``np.asarray(x).astype(np.float64)`` converts them.
  ``None``, complex numbers (even with a zero imaginary part), strings, bytes, dates,
  **bools** and object arrays holding anything else raise :class:`NonRealInputError`
  (``"propagate: dt: expected real numbers, got None"``): numpy would turn ``None`` into
  NaN, drop an imaginary part with only a warning, parse ``"7e6"`` and read ``True`` as 1,
  and each of those is a silent wrong answer (a bool for a time, a moment or a quaternion
  is a bug).  A ragged nested sequence, an int beyond float64 and (for
  :func:`real_scalar`) an array raise ``ValueError`` naming the argument.  The test reads
  the dtype numpy gives the argument, so a bool inside a list of other numbers
  (``[True, 2]``, which numpy makes an int array) is not seen; a bool, a list of bools and
  a bool array are.
  (:func:`astrodyn.orbit.propagate_scalar`, the compiled scalar call, converts what numba
  converts, bools included: see its doc.)
* **Named broadcasting** (:func:`broadcast_named`): leading shapes that do not broadcast
  raise ``ValueError`` listing every argument with its shape
  (``"quat_rotate: leading shapes do not broadcast: q (2, 4), v (5, 3)"``).

Both cost O(1) per call for numeric input (a dtype test and a shape comparison, no pass
over the elements; only an object array is inspected element by element); a float64 array
is returned as is, without a copy.
"""

from __future__ import annotations

import numpy as np

__all__ = ["NonRealInputError", "real_array", "real_scalar", "broadcast_named"]

_F64 = np.dtype(np.float64)
_REAL_ELEMENT = (int, float, np.integer, np.floating)  # what an object array may hold (not bool, below)
_KIND_NAMES = {"b": "bool", "c": "complex", "O": "object", "U": "str", "S": "bytes", "M": "datetime64",
               "m": "timedelta64", "V": "void"}


class NonRealInputError(TypeError, ValueError):
    """An argument that is not real numbers: ``None``, complex, strings, bytes, dates, bools,
    objects (module docstring).

    A ``TypeError``; also a ``ValueError``, so callers that caught the ``ValueError`` these
    inputs used to give keep working.  The message names the function and the argument.
    """


def _prefix(who: str, name: str) -> str:
    return f"{who}: {name}" if who else name


def _is_real_element(e) -> bool:
    return isinstance(e, _REAL_ELEMENT) and not isinstance(e, bool)


def _describe(x, a: np.ndarray) -> str:
    """What a refused argument is, in a few words: ``None``, ``complex``, ``complex128 array``,
    ``list of str``, ``list holding None``, ``object array holding str``."""
    if x is None:
        return "None"
    if a.dtype.kind == "O" and a.ndim:
        bad = next(e for e in a.flat if not _is_real_element(e))
        what = "object array" if isinstance(x, np.ndarray) else type(x).__name__
        return f"{what} holding {'None' if bad is None else type(bad).__name__}"
    kind = _KIND_NAMES.get(a.dtype.kind, str(a.dtype))
    if isinstance(x, np.ndarray):
        return f"{a.dtype if a.dtype.kind in 'bcmM' else kind} array"
    if a.ndim == 0:
        return type(x).__name__
    return f"{type(x).__name__} of {kind}"


def _to_float64(a: np.ndarray, x, name: str, who: str) -> np.ndarray:
    try:
        return np.asarray(a, dtype=np.float64)
    except OverflowError:
        big = f"an int of {x.bit_length()} bits" if type(x) is int else "an int"
        raise ValueError(f"{_prefix(who, name)}: {big} is beyond float64") from None


def real_array(x, name: str, who: str = "") -> np.ndarray:
    """``x`` as a float64 array (no copy for a float64 array) after checking that it holds
    real numbers: ints or floats of any width, or an object array of those.

    Raises :class:`NonRealInputError` naming ``who: name`` for anything else (module
    docstring), and ``ValueError`` for a ragged nested sequence or an int beyond float64."""
    if type(x) is np.ndarray and x.dtype == _F64:  # the common case, first and cheapest (numba's arrays
        return x  # carry a float64 dtype equal to, but not the same object as, numpy's)
    if type(x) is float:
        return np.asarray(x, dtype=np.float64)
    if type(x) is int:  # (bool is not int here)
        return _to_float64(x, x, name, who)
    try:
        a = np.asarray(x)
    except ValueError as exc:  # ragged nesting: "inhomogeneous shape"
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ValueError(f"{_prefix(who, name)}: expected real numbers in a rectangular array ({reason})") from None
    kind = a.dtype.kind
    if kind in "iuf" or (kind == "O" and all(map(_is_real_element, a.flat))):
        return _to_float64(a, x, name, who)
    raise NonRealInputError(f"{_prefix(who, name)}: expected real numbers, got {_describe(x, a)}")


def real_scalar(x, name: str, who: str = "", unit: str = "") -> float:
    """``x`` as a Python float, after :func:`real_array`'s check; ``ValueError`` naming the
    argument when it is not a single number (shape ``()``)."""
    if isinstance(x, float):  # a Python float or np.float64 (a float subclass): the common cases
        return float(x)
    a = real_array(x, name, who)
    if a.ndim != 0:
        raise ValueError(f"{_prefix(who, name)}: expected a scalar{f' ({unit})' if unit else ''}, got shape {a.shape}")
    return float(a)


def broadcast_named(who: str, *args) -> tuple:
    """The broadcast leading shape of ``(name, array, n_trailing)`` triples, as
    ``np.broadcast_shapes``: the last ``n_trailing`` axes of each array are its own (a
    quaternion's 4, a vector's 3; 0 for an array that broadcasts whole), the axes before
    them must broadcast.

    When they do not: ``ValueError("<who>: shapes do not broadcast: M (2,), e (3,)")``, or
    ``"<who>: leading shapes do not broadcast: q (2, 4), v (5, 3)"`` when some argument has
    axes of its own, naming every argument with its full shape.  Equal shapes and ``()``
    are resolved without numpy (the common call costs a few tuple comparisons)."""
    leads = []
    out = ()
    broadcast = True
    for _, a, n in args:
        s = a.shape
        if n:
            s = s[: len(s) - n]
        leads.append(s)
        if s == () or s == out:
            continue
        if out != ():
            broadcast = False
        out = s
    if broadcast:
        return tuple(out)
    try:
        return np.broadcast_shapes(*leads)
    except ValueError:
        what = "leading shapes" if any(n for _, _, n in args) else "shapes"
        listing = ", ".join(f"{name} {tuple(a.shape)}" for name, a, _ in args)
        raise ValueError(f"{who}: {what} do not broadcast: {listing}") from None
