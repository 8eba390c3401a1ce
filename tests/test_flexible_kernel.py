"""The compiled rates, energy and momenta of a flexible spacecraft (``spacecraft_rates``,
``spacecraft_energy``, ``spacecraft_momentum``) against the same
equations written with numpy calls on the assembled blocks (``spacecraft_rates_reference``,
the readable derivation of astrodyn.attitude.flexible), on random states of a spacecraft
whose appendages differ in mode count, damping, orientation and root: any term the kernel
drops or mis-indexes shows at O(1), agreement is to round-off (a few ulp of the largest
rate; the 6x6 Schur solve amplifies by its condition number, ~1e2 here)."""

from __future__ import annotations

import numpy as np
import pytest

from astrodyn.attitude import flexible as fx


def _spacecraft(stiffening: bool):
    b3 = fx.beam_matrices(3, 50.0, 0.4, 3.0, r=0.5, damping_ratio=0.02)
    b1 = fx.beam_matrices(1, 34.0, 0.3, 2.0, r=0.2, damping_ratio=0.5)
    b2 = fx.beam_matrices(2, 5.0, 0.1, 1.5, basis="monomial")
    apps = (fx.Appendage(b3, [1, 0, 0], [0, 1, 0], root=[0.5, 0.0, 0.1]),
            fx.Appendage(b1, [0, -1, 0], [0, 0, 1]),
            fx.Appendage(b2, [0, 0.6, 0.8], [1, 0, 0], root=[0.0, 0.3, 0.4]))
    return fx.FlexibleSpacecraft(40.0, [[8.0, 0.2, 0.0], [0.2, 6.0, 0.1], [0.0, 0.1, 5.0]], apps, stiffening=stiffening)


@pytest.mark.parametrize("stiffening", [True, False])
def test_compiled_rates_equal_the_numpy_reference(stiffening):
    sc = _spacecraft(stiffening)
    rng = np.random.default_rng(7)
    for _ in range(40):
        y = fx.make_state(sc, q=rng.normal(size=4), w=rng.normal(size=3) * 3, r=rng.normal(size=3),
                          eta=0.2 * rng.normal(size=sc.n_elastic), eta_dot=rng.normal(size=sc.n_elastic))
        y[10:13] += rng.normal(size=3)  # a moving centre too (nonzero linear momentum)
        tau = rng.normal(size=3)
        fast = fx.spacecraft_rates(sc, 0.0, y, lambda t, s, tau=tau: tau)
        ref = fx.spacecraft_rates_reference(sc, 0.0, y, lambda t, s, tau=tau: tau)
        assert np.max(np.abs(fast - ref)) <= 1e-13 * np.max(np.abs(ref))
        e, e_ref = fx.spacecraft_energy(sc, y), fx.spacecraft_energy_reference(sc, y)
        assert abs(e - e_ref) <= 1e-14 * abs(e_ref)
        (p, h), (p_ref, h_ref) = fx.spacecraft_momentum(sc, y), fx.spacecraft_momentum_reference(sc, y)
        assert np.max(np.abs(p - p_ref)) <= 1e-14 * np.max(np.abs(p_ref))
        assert np.max(np.abs(h - h_ref)) <= 1e-14 * np.max(np.abs(h_ref))


def test_one_appendage_and_non_finite_states_propagate():
    sc = fx.FlexibleSpacecraft(10.0, [3.0, 3.0, 2.0], (fx.Appendage(fx.beam_matrices(2, 10.0, 0.2, 1.0), [1, 0, 0],
                                                                     [0, 0, 1]),))
    y = fx.make_state(sc, w=[0.1, 0.2, 1.0], eta=[0.01, 0.0, 0.0, 0.02])
    assert np.allclose(fx.spacecraft_rates(sc, 0.0, y), fx.spacecraft_rates_reference(sc, 0.0, y), rtol=1e-12,
                       atol=1e-14)
    y[5] = np.nan
    assert np.all(np.isnan(fx.spacecraft_rates(sc, 0.0, y)[4:7]))
