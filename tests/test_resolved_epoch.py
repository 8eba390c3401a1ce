"""A supervisor converts its scene's epoch once and hands the result to the processes it
starts (``astrodyn.scenario.RESOLVED_EPOCH_ENV``), so that none of them imports astropy.time to
convert it again (about 0.4 s of CPU each at start-up).  The epoch a process gets must be
the one astropy gives, and an entry for another epoch, or one not of the expected shape,
must change nothing.

References: astropy's own conversion in a process without the entry."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from astrodyn.scenario import RESOLVED_EPOCH_ENV, loads, resolved_epoch_environment

SCENE = """
[scenario]
name = "ep"
epoch = "{epoch}"
duration = "10 s"
rate = "1 Hz"
[central_body]
name = "earth"
[[bodies]]
name = "sat"
[bodies.orbit]
a = "7000 km"
e = 0.001
"""

CHILD = """
import json, sys
from astrodyn.scenario import loads
sc = loads(sys.stdin.read())
print(json.dumps([sc.epoch_unix_ns, "astropy.time" in sys.modules]))
"""


def _load_in_a_process(text: str, entry: str | None) -> tuple[int, bool]:
    """(epoch unix ns, whether astropy.time was imported) of ``text`` loaded in a new process
    whose environment has ``entry`` as RESOLVED_EPOCH_ENV (none: not set)."""
    import os

    env = {k: v for k, v in os.environ.items() if k != RESOLVED_EPOCH_ENV}
    if entry is not None:
        env[RESOLVED_EPOCH_ENV] = entry
    out = subprocess.run([sys.executable, "-c", CHILD], input=text, capture_output=True, text=True, env=env,
                         timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    ns, astropy_loaded = json.loads(out.stdout)
    return ns, astropy_loaded


@pytest.mark.parametrize("epoch", ["2026-03-20T12:00:00 TDB", "2016-12-31T23:59:60 UTC", "2000-01-01 TT"])
def test_a_process_given_the_supervisors_epoch_loads_the_same_instant_without_astropy(monkeypatch, epoch):
    text = SCENE.format(epoch=epoch)
    monkeypatch.delenv(RESOLVED_EPOCH_ENV, raising=False)
    scenario = loads(text)  # the supervisor: astropy converts
    (name, entry), = resolved_epoch_environment(scenario).items()
    assert name == RESOLVED_EPOCH_ENV
    ns, astropy_loaded = _load_in_a_process(text, entry)
    assert ns == scenario.epoch_unix_ns and not astropy_loaded
    reference, astropy_loaded = _load_in_a_process(text, None)  # astropy, in a process of its own
    assert reference == ns and astropy_loaded


@pytest.mark.parametrize("entry", [
    json.dumps(["2026-03-20T12:00:01 TDB", "tdb", 1]),  # another epoch: not taken
    json.dumps(["2026-03-20T12:00:00 TDB", "utc", 1]),  # another scale
    json.dumps(["2026-03-20T12:00:00 TDB", "tdb", -1]),  # before 1970
    json.dumps(["2026-03-20T12:00:00 TDB", "tdb", 2**63]),  # past int64
    json.dumps(["2026-03-20T12:00:00 TDB", "tdb", 1.5]),  # not an integer
    json.dumps(["2026-03-20T12:00:00 TDB", "tdb", True]),
    json.dumps({"epoch": 1}), "not json", "[" * 10_000,
])
def test_an_entry_for_another_epoch_or_of_another_shape_changes_nothing(entry):
    text = SCENE.format(epoch="2026-03-20T12:00:00 TDB")
    reference, _ = _load_in_a_process(text, None)
    ns, astropy_loaded = _load_in_a_process(text, entry)
    assert ns == reference and astropy_loaded
