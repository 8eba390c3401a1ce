"""Every ``>>>`` example in astrodyn's docstrings runs as written and prints what it shows
(doctest, over every module of the package).  An example that cannot run on its own (it
needs a file or a running service) is written as a plain code block, not as ``>>>`` lines
that a reader would paste and see fail (found by the Python API probe: the examples of
``astrodyn.recording.reader`` and ``astrodyn.analysis`` failed 6 of 6)."""

from __future__ import annotations

import doctest
import importlib
import pkgutil

import astrodyn

MODULES = sorted(m.name for m in pkgutil.walk_packages(astrodyn.__path__, "astrodyn.") if not m.name.endswith("__main__"))


def test_the_examples_of_every_module_run_as_written():
    failed, attempted = [], 0
    for name in MODULES:
        module = importlib.import_module(name)
        try:
            result = doctest.testmod(module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE,
                                     report=False, verbose=False)
        except ValueError as exc:  # a malformed example (a stray "doctest:" directive)
            failed.append(f"{name}: {exc}")
            continue
        attempted += result.attempted
        if result.failed:
            failed.append(f"{name}: {result.failed} of {result.attempted} examples fail")
    assert not failed, failed
    # the walk reached the core's examples: attitude.torque_free (6), attitude.elliptic (5), rotation (4)
    assert {"astrodyn.attitude.torque_free", "astrodyn.attitude.elliptic", "astrodyn.rotation"} <= set(MODULES)
    assert attempted >= 15
