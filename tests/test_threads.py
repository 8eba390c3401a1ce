"""Thread policy (astrodyn.jit, issue 15): service thread count from option / environment,
serial and parallel compilations of a kernel agree, bad values give one-line errors."""

from __future__ import annotations

from pathlib import Path

import numba
import numpy as np
import pytest

from astrodyn import jit
from astrodyn.attitude.elliptic import ellipj
from astrodyn.attitude.torque_free import torque_free


def test_service_threads_default_env_and_option(monkeypatch):
    monkeypatch.delenv(jit.THREADS_ENV, raising=False)
    assert jit.service_threads() == 1
    monkeypatch.setenv(jit.THREADS_ENV, "all")
    assert jit.service_threads() == jit.max_threads()
    monkeypatch.setenv(jit.THREADS_ENV, "1")
    assert jit.service_threads() == 1
    assert jit.service_threads("all") == jit.max_threads()  # the option wins over the environment
    monkeypatch.setenv(jit.THREADS_ENV, "1000")
    assert jit.service_threads() == jit.max_threads()  # clamped to what numba may use


@pytest.mark.parametrize("value", ["0", "-2", "two", "1.5", "1e3"])
def test_service_threads_rejects(monkeypatch, value):
    monkeypatch.setenv(jit.THREADS_ENV, value)
    with pytest.raises(ValueError, match=r"ASTRODYN_THREADS: expected an integer >= 1 or 'all'"):
        jit.service_threads()
    with pytest.raises(ValueError, match=r"--threads: expected"):
        jit.service_threads(value)


def test_parallel_pays_follows_threshold_and_threads():
    before = numba.get_num_threads()
    try:
        jit.set_threads(1)
        assert not jit.parallel_pays(10**9, "torque_free")
        if jit.max_threads() > 1:
            jit.set_threads(2)
            assert jit.parallel_pays(jit.PARALLEL_MIN["torque_free"], "torque_free")
            assert not jit.parallel_pays(jit.PARALLEL_MIN["torque_free"] - 1, "torque_free")
    finally:
        numba.set_num_threads(before)
    with pytest.raises(KeyError):
        jit.ParallelKernel(lambda: None, "no-such-kernel")


def test_serial_and_parallel_paths_agree():
    """Above and below every threshold, with 1 and all threads, the results are the same bits:
    each element is computed by the same compiled scalar code whichever loop runs it."""
    rng = np.random.default_rng(5)
    n = 2 * max(jit.PARALLEL_MIN.values())
    w0 = np.array([1e-3, 1.0, 1e-3]) + rng.normal(scale=1e-2, size=(n, 3))
    u, m = rng.uniform(-5.0, 5.0, n), rng.uniform(0.0, 1.0, n)
    before = numba.get_num_threads()
    out = {}
    try:
        for threads in (1, jit.max_threads()):
            jit.set_threads(threads)
            out[threads] = (torque_free([1.0, 2.0, 3.0], w0, [1.0, 0.0, 0.0, 0.0], 7.5),
                            torque_free([1.0, 2.0, 3.0], w0[:3], [1.0, 0.0, 0.0, 0.0], np.linspace(0, 50, n)),
                            ellipj(u, m))
    finally:
        numba.set_num_threads(before)
    a, b = out[1], out[jit.max_threads()]
    np.testing.assert_array_equal(np.concatenate([np.ravel(v) for r in a for v in r]),
                                  np.concatenate([np.ravel(v) for r in b for v in r]))


def test_propagator_rejects_bad_threads(capsys):
    from astrodyn.service.propagator import service_main

    config = Path(__file__).resolve().parents[1] / "configs" / "dzhanibekov.toml"
    rc = service_main("attitude", [str(config), "--threads", "zero"])
    err = capsys.readouterr().err.strip()
    assert rc == 2
    assert err.count("\n") == 0 and "--threads: expected an integer >= 1 or 'all'" in err


def test_bench_calls_refuses_a_bad_baseline(tmp_path, capsys):
    from astrodyn.bench.calls import main

    assert main(["--baseline", str(tmp_path / "nowhere")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "--baseline: expected a source tree holding astrodyn/" in err
