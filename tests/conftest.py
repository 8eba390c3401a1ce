"""Shared test configuration.

* Offline: astropy never downloads IERS tables.
* Hypothesis: deterministic (derandomized) and bounded, so CI time is stable.
"""

import os

from hypothesis import HealthCheck, settings

try:  # astropy is only at the edges, but never let a test reach the network
    from astropy.utils import iers

    iers.conf.auto_download = False
except Exception:  # pragma: no cover - astropy missing means those tests fail on import anyway
    pass

settings.register_profile(
    "ci",
    max_examples=200,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow],
)
settings.register_profile("dev", max_examples=50, deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))
