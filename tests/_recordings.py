"""Small MCAP recordings for the replay / export / analysis tests.

A scenario (TOML text) is run in-process with :func:`astrodyn.simulate.simulate` and
its states are written with :class:`astrodyn.recording.McapRecorder`, exactly as the
logger lays them out (one channel per key, the scenario metadata record), without
starting the service.  ``SimulationResult`` arrays are returned alongside so tests can
compare what comes back out of the file with what went in.
"""

from __future__ import annotations

from pathlib import Path

from astrodyn import messages
from astrodyn.recording import McapRecorder
from astrodyn.scenario import loads
from astrodyn.simulate import simulate

LEO_TWO_BODIES = """
[scenario]
name = "{name}"
epoch = "2026-03-20T12:00:00 UTC"
duration = "{duration}"
rate = "{rate}"

[central_body]
name = "earth"

[[bodies]]
name = "leo"
[bodies.orbit]
a = "6800 km"
e = 0.001
i = "51.6 deg"
raan = "30 deg"
argp = "40 deg"
nu = "10 deg"
[bodies.attitude]
q = [1, 0, 0, 0]
w = ["0.001 rad/s", "0.3 rad/s", "0.002 rad/s"]
inertia = ["0.03 kg m2", "0.035 kg m2", "0.01 kg m2"]

[[bodies]]
name = "geo"
[bodies.orbit]
a = "42164 km"
e = 0.0
i = "0.1 deg"
raan = "0 deg"
argp = "0 deg"
nu = "0 deg"
"""


def record(path: Path, toml_text: str, chunk_size: int = 1 << 14):
    """Simulate ``toml_text`` and write every state to ``path``; returns (scenario, result)."""
    sc = loads(toml_text)
    res = simulate(sc)
    models = {bp.name: (bp.orbit_model, bp.attitude_model) for bp in res.plan.bodies}
    mu = sc.central_body.mu
    with McapRecorder(path, sc.to_metadata(), epoch_ns=sc.epoch_unix_ns, chunk_size=chunk_size) as rec:
        for k, t in enumerate(res.t):
            t = float(t)
            for i, name in enumerate(res.orbit_names):
                msg = messages.orbit_message(t, k, models[name][0], res.r[k, i], res.v[k, i], mu, sc.frame)
                rec.write(messages.orbit_key(sc.name, name), msg)
            for i, name in enumerate(res.attitude_names):
                msg = messages.attitude_message(t, k, models[name][1], res.q[k, i], res.w[k, i])
                rec.write(messages.attitude_key(sc.name, name), msg)
    return sc, res


def leo_recording(path: Path, name: str = "rp", duration: str = "60 s", rate: str = "2 Hz"):
    """Two Earth orbiters (one with a tumbling attitude): ``record`` of LEO_TWO_BODIES."""
    return record(path, LEO_TWO_BODIES.format(name=name, duration=duration, rate=rate))


def one_satellite_scene(name: str, duration: str, rate: str, extra: str = "") -> str:
    """TOML of a scene with one body ``sat`` (Kepler orbit, torque-free attitude), for the
    process tests; ``extra`` is appended (more bodies)."""
    return f"""
[scenario]
name = "{name}"
epoch = "2026-03-20T12:00:00 TDB"
duration = "{duration}"
rate = "{rate}"

[[bodies]]
name = "sat"
[bodies.orbit]
a = "7000 km"
e = 0.01
[bodies.attitude]
q = [1, 0, 0, 0]
w = [0.01, 0.2, 0.01]
inertia = [1.0, 2.0, 3.0]
{extra}"""
