"""Shared test configuration.

* Offline: astropy never downloads IERS tables.
* Hypothesis: deterministic (derandomized) and bounded, so CI time is stable.
"""

import os
import os as _os
import signal as _signal
import subprocess as _subprocess

import pytest
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


# --------------------------------------------------------------------------- processes and the bus


@pytest.fixture
def hub():
    """(session, endpoint): the test's own loopback Zenoh session, which children connect to."""
    from astrodyn import bus

    endpoint = bus.loopback_endpoint()
    with bus.open_session(listen=endpoint) as session:
        yield session, endpoint


@pytest.fixture
def processes():
    """``start(argv, **popen_kwargs) -> Popen``: children started with subprocess (never
    fork); every one still running at teardown is killed by its PID, and its pipes closed."""
    children: list[_subprocess.Popen] = []

    def start(argv, **kw) -> _subprocess.Popen:
        proc = _subprocess.Popen([str(a) for a in argv], **kw)
        children.append(proc)
        return proc

    yield start
    for proc in children:
        if proc.poll() is None:
            _os.kill(proc.pid, _signal.SIGKILL)
        proc.wait(timeout=10)
        for stream in (proc.stdin, proc.stdout, proc.stderr):
            if stream is not None:
                stream.close()
