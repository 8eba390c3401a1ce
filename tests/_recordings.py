"""Small MCAP recordings for the replay / export / analysis tests.

A scenario (TOML text) is run in-process with :func:`astrodyn.simulate.simulate` and
its states are written with :class:`astrodyn.recording.McapRecorder`, exactly as the
logger lays them out (one channel per key, the scenario metadata record), without
starting the service.  ``SimulationResult`` arrays are returned alongside so tests can
compare what comes back out of the file with what went in.
"""

from __future__ import annotations

import sys
from pathlib import Path

from astrodyn import messages
from astrodyn.recording import McapRecorder
from astrodyn.scenario import loads
from astrodyn.simulate import simulate


def scenario_head(name: str, duration: str, rate: str, scale: str = "UTC", central_body: str | None = None) -> str:
    """TOML of a scenario's ``[scenario]`` table, epoch 2026-03-20T12:00:00 in the time
    ``scale``, ``duration`` and ``rate`` as quantity text (e.g. "60 s", "2 Hz"), and when
    ``central_body`` is named, its ``[central_body]`` table."""
    text = f"""
[scenario]
name = "{name}"
epoch = "2026-03-20T12:00:00 {scale}"
duration = "{duration}"
rate = "{rate}"
"""
    return text if central_body is None else text + f'\n[central_body]\nname = "{central_body}"\n'


def orbiter(name: str, a: str, e: float, i: str, raan: str = "0 deg", argp: str = "0 deg", nu: str = "0 deg",
            w: list[str] | None = None) -> str:
    """TOML of a ``[[bodies]]`` entry: a Kepler orbit from its elements (lengths and angles
    as quantity text, e.g. "7000 km", "51.6 deg") and, when the body rates ``w`` are given
    (3 quantity texts, body axes, e.g. "0.3 rad/s"), a torque-free attitude from
    q = [1, 0, 0, 0] with the principal inertia 0.03, 0.035, 0.01 kg m^2."""
    text = f"""[[bodies]]
name = "{name}"
[bodies.orbit]
a = "{a}"
e = {e}
i = "{i}"
raan = "{raan}"
argp = "{argp}"
nu = "{nu}"
"""
    if w is None:
        return text
    return text + f"""[bodies.attitude]
q = [1, 0, 0, 0]
w = ["{w[0]}", "{w[1]}", "{w[2]}"]
inertia = ["0.03 kg m2", "0.035 kg m2", "0.01 kg m2"]
"""


LEO_TWO_BODIES = scenario_head("{name}", "{duration}", "{rate}", central_body="earth") + "\n" + orbiter(
    "leo", "6800 km", 0.001, "51.6 deg", "30 deg", "40 deg", "10 deg", w=["0.001 rad/s", "0.3 rad/s", "0.002 rad/s"]
) + "\n" + orbiter("geo", "42164 km", 0.0, "0.1 deg")


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
    return scenario_head(name, duration, rate, "TDB") + f"""
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


def payloads_by_topic(path: Path, suffixes: tuple[str, ...]) -> dict[str, list[bytes]]:
    """topic -> the payloads recorded on it, in file order, for the topics ending with one of
    ``suffixes`` (read with astrodyn's crash-tolerant stream reader)."""
    from astrodyn.recording.stream import open_stream

    out: dict[str, list[bytes]] = {}
    with open_stream(path) as s:
        for m in s.messages():
            if m.topic.endswith(suffixes):
                out.setdefault(m.topic, []).append(bytes(m.data))
    return out


def children_by_kind(pid: int) -> dict[int, str]:
    """PID -> process kind (logger, orbit, attitude, ...) of the astrodyn processes that the
    supervisor ``pid`` (``run``, ``serve``) started, from their command lines."""
    import psutil

    out = {}
    for child in psutil.Process(pid).children():
        try:
            cmd = child.cmdline()
        except psutil.NoSuchProcess:
            continue
        module = next((c for c in cmd if c.startswith("astrodyn.service.")), "")
        if module:
            out[child.pid] = "logger" if module.endswith("logger") else cmd[cmd.index(module) + 1]
    return out


def run_while(argv: list[str], partial: Path, min_bytes: int, act, timeout_s: float = 180.0) -> tuple[int, str]:
    """Start ``astrodyn run`` with ``argv``, wait (at most 120 s) until its logger's file
    ``partial`` holds ``min_bytes`` (the recording is under way), call ``act(pid)`` with the
    supervisor's PID, and wait for the run to end; returns its exit status and stderr.  A run
    still alive at the end (a failed assertion in ``act``) is killed by its PID."""
    import subprocess
    import time

    proc = subprocess.Popen([sys.executable, "-m", "astrodyn", "run", *argv], stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and not (partial.exists() and partial.stat().st_size > min_bytes):
            assert proc.poll() is None, proc.stderr.read().decode()
            time.sleep(0.05)
        act(proc.pid)
        _, err = proc.communicate(timeout=timeout_s)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return proc.returncode, err.decode()


def assert_one_satellite_payloads(name: str, orbit: list[bytes], attitude: list[bytes]) -> None:
    """Each state payload recorded for body ``sat`` of :func:`one_satellite_scene` ``name``
    at 10 Hz (lists in seq order, from 0) is byte for byte the message of the state the
    numeric core computes for that step (:func:`astrodyn.simulate.simulate`)."""
    n = max(len(orbit), len(attitude))
    sc = loads(one_satellite_scene(name, f"{(n - 1) / 10} s", "10 Hz"))
    res = simulate(sc)
    (orbit_model, attitude_model), = [(bp.orbit_model, bp.attitude_model) for bp in res.plan.bodies]
    for k, payload in enumerate(orbit):
        expected = messages.orbit_message(float(res.t[k]), k, orbit_model, res.r[k, 0], res.v[k, 0],
                                          sc.central_body.mu, sc.frame)
        assert payload == messages.encode(expected), k
    for k, payload in enumerate(attitude):
        expected = messages.attitude_message(float(res.t[k]), k, attitude_model, res.q[k, 0], res.w[k, 0])
        assert payload == messages.encode(expected), k
