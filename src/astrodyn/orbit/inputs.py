"""Argument checks shared by the public functions of :mod:`astrodyn.orbit`.

The contract is docs/architecture.md, section 2 ("Bad numbers"): a bad argument raises a
one-line ``TypeError`` / ``ValueError`` that names it.  Every public orbit function
converts its numeric arguments here, so the rules are the same everywhere:

* **Real numbers only** (:func:`real_array`, :func:`real_scalar`): Python and numpy ints,
  unsigned ints and floats of any width are converted to float64 exactly as
  ``np.asarray(x, dtype=np.float64)`` would.  ``None``, complex numbers, strings, bytes,
  object arrays (e.g. a list holding ``None``), dates and **bools** raise ``TypeError``
  (``"propagate: dt: expected real numbers, got None"``): numpy would turn ``None`` into
  NaN, drop an imaginary part with only a warning, parse ``"7e6"`` and read ``True`` as 1,
  and each of those is a silent wrong answer.  (:func:`astrodyn.orbit.propagate_scalar`,
  the compiled scalar call, converts what numba converts, bools included: see its doc.)
* **Named broadcasting** (:func:`broadcast_shapes_named`): shapes that do not broadcast
  raise ``ValueError`` listing every argument with its shape
  (``"solve_kepler: shapes do not broadcast: M (2,), e (3,)"``).

Both cost O(1) per call (a dtype test and a shape comparison, no pass over the elements);
a float64 array is returned as is, without a copy.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

__all__ = ["real_array", "real_scalar", "broadcast_shapes_named"]

_F64 = np.dtype(np.float64)
_KIND_NAMES = {"b": "bool", "c": "complex", "O": "object", "U": "str", "S": "bytes", "M": "datetime64",
               "m": "timedelta64", "V": "void"}


def _prefix(who: str, name: str) -> str:
    return f"{who}: {name}" if who else name


def _describe(x, a: np.ndarray) -> str:
    """What a refused argument is, in a few words: ``None``, ``complex``, ``complex128 array``,
    ``list of object``."""
    if x is None:
        return "None"
    kind = _KIND_NAMES.get(a.dtype.kind, str(a.dtype))
    if isinstance(x, np.ndarray):
        return f"{a.dtype if a.dtype.kind in 'bcmM' else kind} array"
    if a.ndim == 0:
        return type(x).__name__
    return f"{type(x).__name__} of {kind}"


def real_array(x, name: str, who: str = "") -> np.ndarray:
    """``x`` as a float64 array (``np.asarray(x, dtype=np.float64)``, no copy for a float64
    array) after checking that it holds real numbers: ints or floats of any width.

    Raises ``TypeError`` naming ``who: name`` for anything else (module docstring), and
    ``ValueError`` for a ragged nested sequence."""
    if type(x) is np.ndarray and x.dtype == _F64:  # the common case, first and cheapest (numba's arrays
        return x  # carry a float64 dtype equal to, but not the same object as, numpy's)
    if type(x) is float:
        return np.asarray(x, dtype=np.float64)
    if type(x) is int:  # (bool is not int here)
        try:
            return np.asarray(x, dtype=np.float64)
        except OverflowError:
            raise ValueError(f"{_prefix(who, name)}: an int of {x.bit_length()} bits is beyond float64") from None
    try:
        a = np.asarray(x)
    except ValueError as exc:  # ragged nesting: "inhomogeneous shape"
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ValueError(f"{_prefix(who, name)}: expected real numbers in a rectangular array ({reason})") from None
    if a.dtype.kind not in "iuf":
        raise TypeError(f"{_prefix(who, name)}: expected real numbers, got {_describe(x, a)}")
    return np.asarray(a, dtype=np.float64)


def real_scalar(x, name: str, who: str = "", unit: str = "") -> float:
    """``x`` as a Python float, after :func:`real_array`'s check; ``ValueError`` naming the
    argument when it is not a single number (shape ``()``)."""
    if isinstance(x, float):  # a Python float or np.float64 (a float subclass): the common cases
        return float(x)
    a = real_array(x, name, who)
    if a.ndim != 0:
        raise ValueError(f"{_prefix(who, name)}: expected a scalar{f' ({unit})' if unit else ''}, got shape {a.shape}")
    return float(a)


def broadcast_shapes_named(who: str, shapes: Mapping[str, tuple], shown: Mapping[str, tuple] | None = None,
                           what: str = "shapes") -> tuple:
    """The broadcast of ``shapes`` (argument name -> shape), as ``np.broadcast_shapes``.

    When they do not broadcast: ``ValueError("<who>: <what> do not broadcast: a (2,), b (3,)")``
    naming every argument with its shape (the shape from ``shown`` where given, e.g. the
    full ``(..., 3)`` shape of a vector whose leading shape is broadcast).  Equal shapes and
    ``()`` are resolved without numpy (the common call costs a few tuple comparisons)."""
    out = ()
    for s in shapes.values():
        if s == () or s == out:
            continue
        if out != ():
            break
        out = s
    else:
        return tuple(out)
    try:
        return np.broadcast_shapes(*shapes.values())
    except ValueError:
        shown = shown or {}
        listing = ", ".join(f"{k} {tuple(shown.get(k, s))}" for k, s in shapes.items())
        raise ValueError(f"{who}: {what} do not broadcast: {listing}") from None
