"""The one place that holds astrodyn's numba settings.

Every compiled kernel in the numeric core is decorated with :func:`jit` (serial)
or :func:`pjit` (``parallel=True`` for ``prange`` loops over many states).

* ``cache=True``: compiled machine code is stored next to the sources, so only
  the first import on a machine pays the compile time.
* ``fastmath=False`` (numba's default, stated explicitly): fast-math lets LLVM
  reassociate and contract floating-point operations, which breaks the
  compensated / cancellation-free formulas the error analysis relies on.
* ``error_model="numpy"``: division by zero gives inf/nan like numpy instead of
  raising, so NaN inputs propagate to NaN outputs.
"""

from __future__ import annotations

import numba

_COMMON = dict(cache=True, fastmath=False, error_model="numpy", nogil=True)


def jit(*args, **kwargs):
    """``numba.njit`` with astrodyn's settings (serial kernel)."""
    opts = {**_COMMON, **kwargs}
    if args and callable(args[0]):
        return numba.njit(**opts)(args[0])
    return numba.njit(*args, **opts)


def pjit(*args, **kwargs):
    """``numba.njit(parallel=True)`` with astrodyn's settings (use ``numba.prange``)."""
    opts = {**_COMMON, "parallel": True, **kwargs}
    if args and callable(args[0]):
        return numba.njit(**opts)(args[0])
    return numba.njit(*args, **opts)


prange = numba.prange
