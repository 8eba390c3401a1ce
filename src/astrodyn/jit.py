"""The one place that holds astrodyn's numba settings.

Every compiled kernel in the numeric core is decorated with :func:`jit` (serial)
or :func:`pjit` (``parallel=True`` for ``prange`` loops over many states).

* ``cache=True``: compiled machine code is stored next to the sources (or, where
  they are read-only, in numba's user cache directory, ``$NUMBA_CACHE_DIR`` or
  ``~/.cache``), so only the first import on a machine pays the compile time.  Where
  neither is writable (a read-only install run with a read-only home: a locked-down
  container, a service account) the kernels are compiled without a cache, in every
  process, and :func:`compile_kernel` says so once on stderr instead of failing at import.
* ``fastmath=False`` (numba's default, stated explicitly): fast-math lets LLVM
  reassociate and contract floating-point operations, which breaks the
  compensated / cancellation-free formulas the error analysis relies on.
* ``error_model="numpy"``: division by zero gives inf/nan like numpy instead of
  raising, so NaN inputs propagate to NaN outputs.

Thread policy (docs/benchmarks.md, "Threads"), decided here and nowhere else:

* **Kernels go parallel only when the work pays for it.**  Every ``prange`` kernel has
  a serial twin compiled from the same loop body; the public wrapper calls
  :func:`parallel_pays` with the kernel's work (number of independent evaluations)
  and its measured threshold from :data:`PARALLEL_MIN`.  Below the threshold a
  parallel launch costs more than it saves (the thread team's wake-up and barrier,
  10-50 us on this machine, and far more when another process holds the other
  core); the thresholds come from a sweep of batch sizes at 1 and 2 threads
  (``astrodyn bench calls --sweep``).  With one numba thread every call is serial.
* **Service processes run one numba thread each** (:func:`service_threads`,
  :func:`set_threads`): the propagators and the logger share the cores with each
  other, and two processes whose parallel regions spin for the same cores slow each
  other down by 7x to 18x (issue 15).  The count comes from the process's
  ``--threads`` option, else the environment variable ``ASTRODYN_THREADS`` (an
  integer >= 1, or ``all`` for every core numba may use), else 1.  Library use
  (``import astrodyn`` in a notebook) keeps numba's default: every core.
"""

from __future__ import annotations

import os
import sys
import types

# Idle OpenMP threads sleep instead of spinning (libgomp reads this when numba first
# launches its thread pool, after this import): a spinning team takes the core another
# service process needs, and a parallel region whose partner thread was descheduled
# waits a whole time slice (5 ms measured, docs/benchmarks.md "Threads").  A value
# already in the environment wins.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numba

_COMMON = dict(cache=True, fastmath=False, error_model="numpy", nogil=True)

#: Whether a kernel of this process could not be cached (:func:`compile_kernel` said so).
_UNCACHED_NOTICE = {"said": False}


def kernels_uncached() -> bool:
    """Whether a kernel compiled in this process found no writable cache (so every process
    compiles its kernels again: a progress note should not promise "cached afterwards")."""
    return _UNCACHED_NOTICE["said"]


def compile_kernel(fn, **opts):
    """``numba.njit(**opts)(fn)``; when ``opts`` asks for ``cache=True`` and numba finds no
    writable place for the cache (its "no locator available" RuntimeError), ``fn`` is
    compiled without one and a one-line notice goes to stderr, once per process."""
    try:
        return numba.njit(**opts)(fn)
    except RuntimeError as exc:
        if not opts.get("cache") or "no locator available" not in str(exc):
            raise
    if not _UNCACHED_NOTICE["said"]:
        _UNCACHED_NOTICE["said"] = True
        print(f"astrodyn: numba cannot cache compiled kernels here (neither {os.path.dirname(fn.__code__.co_filename)} "
              f"nor numba's user cache directory is writable): they are compiled in every process, which takes a "
              f"while; set NUMBA_CACHE_DIR to a private writable directory to keep them", file=sys.stderr, flush=True)
    return numba.njit(**{**opts, "cache": False})(fn)


def jit(*args, **kwargs):
    """``numba.njit`` with astrodyn's settings (serial kernel)."""
    opts = {**_COMMON, **kwargs}
    if args and callable(args[0]):
        return compile_kernel(args[0], **opts)
    _keywords_only(args)
    return lambda fn: compile_kernel(fn, **opts)


def pjit(*args, **kwargs):
    """``numba.njit(parallel=True)`` with astrodyn's settings (use ``numba.prange``)."""
    opts = {**_COMMON, "parallel": True, **kwargs}
    if args and callable(args[0]):
        return compile_kernel(args[0], **opts)
    _keywords_only(args)
    return lambda fn: compile_kernel(fn, **opts)


def _keywords_only(args: tuple) -> None:
    if args:
        raise TypeError("astrodyn.jit: options are keywords only (kernels compile lazily from the types of their calls)")


prange = numba.prange


class ParallelKernel:
    """A ``prange`` loop compiled twice, serial and parallel, called through the policy.

    ``kernel(work, *args)`` runs the parallel compilation when :func:`parallel_pays`
    ``(work, name)``, else the serial one (``prange`` is ``range`` there); ``work`` is the
    number of independent evaluations of the call.  The two compilations cache under
    different names, so neither loads the other's machine code.
    """

    def __init__(self, fn, name: str):
        if name not in PARALLEL_MIN:
            raise KeyError(f"kernel {name!r}: no measured threshold in astrodyn.jit.PARALLEL_MIN")
        twin = types.FunctionType(fn.__code__, fn.__globals__, fn.__name__ + "_serial", fn.__defaults__, fn.__closure__)
        twin.__qualname__ = fn.__qualname__ + "_serial"
        twin.__module__ = fn.__module__
        self.name = name
        self.serial = compile_kernel(twin, **_COMMON)
        self.parallel = compile_kernel(fn, **_COMMON, parallel=True)
        self.__doc__ = fn.__doc__

    def __call__(self, work: int, *args):
        return (self.parallel if parallel_pays(work, self.name) else self.serial)(*args)


def parallel_kernel(name: str):
    """Decorator: a :class:`ParallelKernel` under the threshold ``PARALLEL_MIN[name]``."""
    return lambda fn: ParallelKernel(fn, name)


#: Measured work (independent evaluations per call) from which each kernel's parallel
#: version is faster than its serial twin at 2 threads (the sweep of ``astrodyn bench
#: calls --sweep``, docs/benchmarks.md "Threads"): with sleeping OpenMP threads a
#: parallel launch costs about 60 us, so it pays from about 150-200 us of serial work
#: (1.2x-1.4x at the threshold, 2x for large batches).  The orbit kernels keep their own
#: measured thresholds (``orbit.universal.PROPAGATE_PARALLEL_MIN`` = 2048 states,
#: ``orbit.kepler.PARALLEL_MIN`` = 4096 elements), the same rule.
PARALLEL_MIN: dict[str, int] = {
    "torque_free": 1024,  # (body, time) evaluations of attitude.torque_free (240 ns each)
    "torque_free_setup": 256,  # bodies set up by attitude.torque_free (the elliptic constants, 790 ns each)
    "elliptic": 2048,  # elements of the attitude.elliptic array functions (ellipj, elliprj: 40-80 ns each)
}

#: Environment variable holding a service process's numba thread count.
THREADS_ENV = "ASTRODYN_THREADS"


def parallel_pays(work: int, kernel: str) -> bool:
    """True when ``work`` evaluations of ``kernel`` should use the parallel version:
    at least :data:`PARALLEL_MIN` ``[kernel]`` of them and more than one numba thread."""
    return work >= PARALLEL_MIN[kernel] and numba.get_num_threads() > 1


def max_threads() -> int:
    """The most numba threads this process may use (``NUMBA_NUM_THREADS``, by default the cores)."""
    return int(numba.config.NUMBA_NUM_THREADS)


def service_threads(option: str | int | None = None) -> int:
    """A service process's numba thread count: ``option`` (its ``--threads``), else
    ``$ASTRODYN_THREADS``, else 1; ``"all"`` means :func:`max_threads`.  Raises
    ``ValueError`` with a one-line message naming the source and the allowed values."""
    source, value = ("--threads", option) if option is not None else (THREADS_ENV, os.environ.get(THREADS_ENV))
    if value is None or (isinstance(value, str) and value.strip() == ""):
        return 1
    text = str(value).strip().lower()
    if text == "all":
        return max_threads()
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise ValueError(f"{source}: expected an integer >= 1 or 'all' (numba threads), got {str(value)[:40]!r}")
    return min(n, max_threads())


def set_threads(n: int) -> int:
    """Set this thread's numba thread count to ``n`` (clamped to 1 .. :func:`max_threads`); returns it."""
    n = max(1, min(int(n), max_threads()))
    numba.set_num_threads(n)
    return n
