"""``astrodyn router``: processes that know only the router's endpoint make a complete run.

The logger, the orbit process and the attitude process are started as three separate
processes in Zenoh *client* mode (a client never listens, so it cannot have a direct
peer link: everything goes through the router), each given only ``--connect <router>``.
The file is read back with the plain ``mcap`` reader (independent of astrodyn's reader):
every channel of the scene is there, each with ``seq`` = 0 .. n_steps - 1 exactly once,
and the states equal the in-process numeric core (:func:`astrodyn.simulate.simulate`)
bit for bit (JSON carries floats with ``repr``, which round-trips).

Across two network namespaces (router and logger in one, the propagators in the other,
joined by a veth pair) when ``ip netns`` works (root + iproute2); skipped otherwise, with
the reason.  Every process a test starts is stopped by its PID; namespaces it creates
are deleted by name.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from astrodyn import auth, bus
from astrodyn.scenario import load
from astrodyn.service.router import is_wildcard
from astrodyn.simulate import simulate
from test_service import _stop  # stop a child by PID: SIGTERM, then SIGKILL (one helper)

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _recordings import one_satellite_scene

ROOT = Path(__file__).resolve().parents[1]
SERVICES = ROOT / "services"
PY = sys.executable

pytestmark = pytest.mark.network

TINY = one_satellite_scene("router-test", "20 s", "5 Hz", extra="""
[[bodies]]
name = "probe"
[bodies.orbit]
a = "8000 km"
""")


def _start(argv: list[str], log: Path, env: dict | None = None) -> subprocess.Popen:
    return subprocess.Popen(argv, stdout=open(log.with_suffix(".out"), "wb"), stderr=open(log.with_suffix(".err"), "wb"),
                            stdin=subprocess.DEVNULL, env=None if env is None else {**os.environ, **env})


def _wait_router(proc: subprocess.Popen, log: Path, timeout: float = 30.0) -> dict:
    """The router's start line (JSON on stdout), or fail with its stderr."""
    out = log.with_suffix(".out")
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        text = out.read_text() if out.exists() else ""
        if text.strip():
            return json.loads(text.splitlines()[0])
        if proc.poll() is not None:
            break
        time.sleep(0.1)
    pytest.fail(f"router did not start: {log.with_suffix('.err').read_text() if log.with_suffix('.err').exists() else ''}")


def _run_through_router(tmp: Path, endpoint: str, router_ns: list[str], logger_ns: list[str], prop_ns: list[str],
                        before_propagators=None) -> Path:
    """Router, logger, orbit, attitude as four processes; the last three know only ``endpoint``.
    ``before_propagators(config, scenario)`` is called once the logger is started."""
    config = tmp / "tiny.toml"
    config.write_text(TINY)
    scenario = load(config)
    out = tmp / "run.mcap"
    procs: list[subprocess.Popen] = []
    try:
        router = _start([*router_ns, PY, "-m", "astrodyn", "router", "--listen", endpoint], tmp / "router")
        procs.append(router)
        _wait_router(router, tmp / "router")
        client = ["--mode", "client", "--connect", endpoint]
        # the run's identity crosses the router: every process signs, the logger verifies
        env = {auth.SECRET_ENV: str(auth.RunSecret.generate().save(tmp))}
        logger = _start([*logger_ns, PY, str(SERVICES / "logger.py"), "--scenario", scenario.name, "--out", str(out),
                         "--epoch-ns", str(scenario.epoch_unix_ns), "--expect", "orbit", "--expect", "attitude",
                         "--config", str(config), "--max-seconds", "120", *client], tmp / "logger", env)
        procs.append(logger)
        if before_propagators is not None:
            before_propagators(config, scenario)
        props = [_start([*prop_ns, PY, str(SERVICES / f"{kind}.py"), str(config), *client], tmp / kind, env)
                 for kind in ("orbit", "attitude")]
        procs += props
        for kind, p in zip(("orbit", "attitude"), props):
            rc = p.wait(timeout=120)
            assert rc == 0, f"{kind}: exit {rc}: {(tmp / kind).with_suffix('.err').read_text()[-2000:]}"
        assert logger.wait(timeout=120) == 0, (tmp / "logger").with_suffix(".err").read_text()[-2000:]
        summary = json.loads((tmp / "logger").with_suffix(".out").read_text().strip().splitlines()[-1])
        assert summary["complete"] and summary["missing"] == 0, summary
        assert summary["rejected"] == {}, summary  # every sample verified after crossing the router
        with open(out, "rb") as f:
            trust = {m.name: m.metadata for m in make_reader(f).iter_metadata()}["rejected"]
        assert trust["authenticated"] == "true" and trust["scene_only"] == "true" and trust["total"] == "0"
    finally:
        for p in procs:
            _stop(p)
    return out


def _check_complete(path: Path, config: Path) -> None:
    """Every channel, seq 0..n-1 once each, states equal to the in-process core."""
    scenario = load(config)
    n = scenario.n_steps
    assert n == 101  # 20 s at 5 Hz, t = 0 included: independent of the code's count
    channels: dict[str, list] = {}
    with open(path, "rb") as f:
        for _schema, channel, message in make_reader(f).iter_messages(log_time_order=False):
            channels.setdefault(channel.topic, []).append(json.loads(message.data))
    expected = {"astrodyn/router-test/sat/orbit", "astrodyn/router-test/sat/attitude", "astrodyn/router-test/probe/orbit"}
    assert expected <= set(channels), sorted(channels)
    result = simulate(scenario)
    for topic in expected:
        msgs = sorted(channels[topic], key=lambda m: m["seq"])
        assert [m["seq"] for m in msgs] == list(range(n)), topic
        body, kind = topic.split("/")[2:4]
        if kind == "orbit":
            j = result.orbit_names.index(body)
            # exact: the orbit process runs the same engine; JSON repr round-trips float64
            np.testing.assert_array_equal(np.array([m["r"] for m in msgs]), result.r[:, j])
        else:
            j = result.attitude_names.index(body)
            np.testing.assert_array_equal(np.array([m["q"] for m in msgs]), result.q[:, j])


def test_wildcard_endpoints():
    assert is_wildcard("tcp/0.0.0.0:7447") and is_wildcard("tcp/[::]:7447")
    assert not is_wildcard("tcp/127.0.0.1:7447") and not is_wildcard("tcp/10.0.0.5:7447")


def test_router_rejects_a_bad_endpoint():
    p = subprocess.run([PY, "-m", "astrodyn", "router", "--listen", "localhost"], capture_output=True, text=True, timeout=60)
    assert p.returncode == 2
    assert "listen" in p.stderr and "tcp/127.0.0.1:7447" in p.stderr


def test_three_clients_through_a_router_on_loopback(tmp_path):
    """Also: while that run's logger is up, ``astrodyn run`` and ``astrodyn serve`` of the same
    scenario name joined to the router are refused before they start anything (exit 2, one
    line naming the scenario and the live processes; docs/multihost.md), so the run on the
    router ends unattacked (its logger's ``rejected`` stays empty).  Before: both started,
    and each logger rejected the other's samples: both ended ATTACKED, exit 3."""
    endpoint = bus.loopback_endpoint()
    refused = []

    def second_runs(config: Path, scenario) -> None:
        with bus.open_session(connect=[endpoint], mode="client") as session:
            bus.wait_for_process(session, scenario.name, "logger", timeout_s=60)
        for cmd in ("run", "serve"):
            p = subprocess.run([PY, "-m", "astrodyn", cmd, str(config), "--out", str(tmp_path / f"second-{cmd}.mcap"),
                                "--connect", endpoint], capture_output=True, text=True, timeout=120)
            refused.append((cmd, p.returncode, p.stderr))

    out = _run_through_router(tmp_path, endpoint, [], [], [], before_propagators=second_runs)
    _check_complete(out, tmp_path / "tiny.toml")
    for cmd, rc, err in refused:
        assert rc == 2 and "Traceback" not in err, (cmd, rc, err[-2000:])
        assert f"scenario 'router-test' is already running on the bus of --connect {endpoint}" in err, err
        assert "logger" in err.splitlines()[-1] and "own [scenario] name" in err, err
    assert not list(tmp_path.glob("second-*")), sorted(p.name for p in tmp_path.iterdir())


def _netns_reason() -> str | None:
    if sys.platform != "linux":
        return "network namespaces are Linux only"
    if os.geteuid() != 0:
        return "ip netns needs root"
    if shutil.which("ip") is None:
        return "iproute2 (ip) is not installed"
    probe = f"adr-probe-{os.getpid()}"
    r = subprocess.run(["ip", "netns", "add", probe], capture_output=True, text=True)
    if r.returncode != 0:
        return f"ip netns add failed: {r.stderr.strip()}"
    subprocess.run(["ip", "netns", "del", probe], capture_output=True)
    return None


def test_three_clients_through_a_router_across_two_namespaces(tmp_path):
    reason = _netns_reason()
    if reason:
        pytest.skip(f"no network namespaces here: {reason}")
    tag = f"{os.getpid() % 100000}"
    ns_a, ns_b = f"adr-a{tag}", f"adr-b{tag}"
    va, vb = f"adva{tag}", f"advb{tag}"
    cmds = [
        ["ip", "netns", "add", ns_a], ["ip", "netns", "add", ns_b],
        ["ip", "link", "add", va, "type", "veth", "peer", "name", vb],
        ["ip", "link", "set", va, "netns", ns_a], ["ip", "link", "set", vb, "netns", ns_b],
        ["ip", "-n", ns_a, "addr", "add", "10.231.0.1/24", "dev", va],
        ["ip", "-n", ns_b, "addr", "add", "10.231.0.2/24", "dev", vb],
        ["ip", "-n", ns_a, "link", "set", va, "up"], ["ip", "-n", ns_b, "link", "set", vb, "up"],
        ["ip", "-n", ns_a, "link", "set", "lo", "up"], ["ip", "-n", ns_b, "link", "set", "lo", "up"],
    ]
    try:
        for c in cmds:
            r = subprocess.run(c, capture_output=True, text=True)
            if r.returncode != 0:
                pytest.skip(f"cannot set up the namespaces ({' '.join(c)}: {r.stderr.strip()})")
        in_a = ["ip", "netns", "exec", ns_a]
        in_b = ["ip", "netns", "exec", ns_b]
        out = _run_through_router(tmp_path, "tcp/10.231.0.1:7447", in_a, in_a, in_b)
        _check_complete(out, tmp_path / "tiny.toml")
    finally:
        for ns in (ns_a, ns_b):  # deleting a namespace deletes its end of the veth pair
            subprocess.run(["ip", "netns", "del", ns], capture_output=True)


@pytest.mark.parametrize("argv,says", [
    (["--connect", ""], "argument --connect: expected Zenoh endpoints"),  # was: named "listen:"
    (["--status-interval", "-1"], "argument --status-interval: expected wall seconds"),  # was: silently never
    (["--status-interval", "nan"], "argument --status-interval: expected wall seconds"),
    (["--config", "/dev/zero"], "--config /dev/zero: expected a regular file, got a character device"),  # was: read to OOM
])
def test_router_flags_are_refused_by_name(argv, says):
    done = subprocess.run([sys.executable, "-m", "astrodyn", "router", *argv], capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and says in done.stderr and "Traceback" not in done.stderr, done.stderr
