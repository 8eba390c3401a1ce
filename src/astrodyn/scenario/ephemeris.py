"""Third-body states at the scenario epoch, from astropy's built-in ephemeris.

The scene layer's one use of astropy outside the config parser (docs/architecture.md,
section 1: astropy stays at the config edge, where the epoch lives): the state of a
perturbing body relative to the central body at the epoch, from which
:mod:`astrodyn.simulate` fits the two-body conic it moves on.  ERFA ``epv00`` / ``moon98``
through ``solar_system_ephemeris.set("builtin")``: no download.
"""

from __future__ import annotations

import numpy as np

__all__ = ["third_body_state"]


def third_body_state(name: str, central: str, epoch_unix_ns: int) -> tuple[np.ndarray, np.ndarray]:
    """Position (m) and velocity (m/s) of body ``name`` relative to ``central`` at the
    epoch (ns since the Unix epoch), ICRS-aligned axes, from astropy's built-in
    ephemeris (no download)."""
    from astropy.coordinates import get_body_barycentric_posvel, solar_system_ephemeris
    from astropy.time import Time

    t = Time(epoch_unix_ns // 1_000_000_000, epoch_unix_ns % 1_000_000_000 * 1e-9, format="unix")
    with solar_system_ephemeris.set("builtin"):
        p3, v3 = get_body_barycentric_posvel(name, t)
        pc, vc = get_body_barycentric_posvel(central, t)
    r = (p3 - pc).xyz.to_value("m")
    v = (v3 - vc).xyz.to_value("m/s")
    return np.asarray(r, dtype=np.float64), np.asarray(v, dtype=np.float64)
