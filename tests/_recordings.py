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


def copy_recording(src: Path, dst: Path, edit_metadata=None, edit_message=None) -> None:
    """Copy the MCAP recording ``src`` to ``dst`` record by record with the third-party
    ``mcap`` reader and writer (its header, schemas, channels, metadata records, and its
    messages in log-time order, the reader's default), through a test's edits:
    ``edit_metadata(name, metadata) -> metadata`` of each metadata record and
    ``edit_message(channel, message) -> data`` of each message (``mcap`` records;
    unchanged when not given)."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    with open(src, "rb") as f, open(dst, "wb") as g:
        reader = make_reader(f)
        header, summary = reader.get_header(), reader.get_summary()
        writer = Writer(g)
        writer.start(header.profile, header.library)
        schemas = {sid: writer.register_schema(s.name, s.encoding, s.data) for sid, s in summary.schemas.items()}
        channels = {cid: writer.register_channel(c.topic, c.message_encoding, schemas.get(c.schema_id, 0), c.metadata)
                    for cid, c in summary.channels.items()}
        for record in reader.iter_metadata():
            metadata = dict(record.metadata)
            if edit_metadata is not None:
                metadata = edit_metadata(record.name, metadata)
            writer.add_metadata(record.name, metadata)
        for _, channel, message in reader.iter_messages():
            data = message.data if edit_message is None else edit_message(channel, message)
            writer.add_message(channels[channel.id], message.log_time, data, message.publish_time, message.sequence)
        writer.finish()


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


def run_to_end(directory: Path, name: str, toml_text: str, *flags: str,
               timeout_s: float = 600.0) -> tuple[Path, dict, str]:
    """``astrodyn run`` of ``toml_text`` (written to ``directory/NAME.toml``) into
    ``directory/NAME.mcap``, its ``--json`` result to ``directory/result.json``, with the
    further ``flags``, waited for (at most ``timeout_s`` of wall time); it must exit 0 (else
    the test fails with the end of its stderr).  Returns (the recording, the result, stdout)."""
    import json
    import subprocess

    cfg, out, res = directory / f"{name}.toml", directory / f"{name}.mcap", directory / "result.json"
    cfg.write_text(toml_text)
    proc = subprocess.run([sys.executable, "-m", "astrodyn", "run", str(cfg), "--out", str(out), "--json", str(res),
                           *flags], capture_output=True, text=True, timeout=timeout_s)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return out, json.loads(res.read_text()), proc.stdout


def wait_for_recording(proc, partial: Path, min_bytes: int, timeout_s: float = 120.0, poll_s: float = 0.05) -> None:
    """Wait until the file ``partial`` (the recording the process ``proc`` makes) holds more
    than ``min_bytes``, polling every ``poll_s`` s, at most ``timeout_s`` s of wall time (then
    it returns, and what the test does next tells); the test fails, with the end of
    ``proc``'s stderr (a pipe), if ``proc`` ends first."""
    import time

    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and not (partial.exists() and partial.stat().st_size > min_bytes):
        if proc.poll() is not None:
            said = proc.stderr.read() if proc.stderr is not None else ""
            said = said.decode(errors="replace") if isinstance(said, bytes) else said
            raise AssertionError(f"ended (status {proc.returncode}) before {partial} held {min_bytes} bytes: "
                                 f"{said[-3000:]}")
        time.sleep(poll_s)


def run_while(argv: list[str], partial: Path, min_bytes: int, act, timeout_s: float = 180.0) -> tuple[int, str]:
    """Start ``astrodyn run`` with ``argv``, wait (at most 120 s) until its logger's file
    ``partial`` holds ``min_bytes`` (the recording is under way: :func:`wait_for_recording`),
    call ``act(pid)`` with the supervisor's PID, and wait for the run to end; returns its
    exit status and stderr.  A run still alive at the end (a failed assertion in ``act``) is
    killed by its PID."""
    import subprocess

    proc = subprocess.Popen([sys.executable, "-m", "astrodyn", "run", *argv], stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE)
    try:
        wait_for_recording(proc, partial, min_bytes)
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
