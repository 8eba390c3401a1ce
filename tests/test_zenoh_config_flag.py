"""``--zenoh-config`` (``run``, ``serve``, ``replay``) and ``router --config``, used against
astrodyn with real processes and real files.

* A supervisor reads the file once: a propagator it restarts after a crash loads the
  supervisor's copy in its work directory, not the user's file, which may have been
  deleted or replaced by a FIFO meanwhile (before: the restarted process re-read the user's
  file, failed, and the run or serve failed after its restart budget).
* One size cap (``astrodyn.bus.ZENOH_CONFIG_MAX_BYTES``) for every command (before:
  ``replay`` and ``router`` parsed a file of any size).
* Zenoh's refusal of a file is one line naming the flag and the file, with the line and
  column and what Zenoh expected (before: its JSON5 parser's several lines of quoted
  source and carets, or its Rust structures), exit 2 like every bad flag value.
* What the file may not decide: the endpoints, multicast scouting (``router --config``
  left multicast scouting on) and, for the processes of one run, a shared Zenoh ``id``.

Every process a test starts is stopped by its PID; ports are free ones picked at the start;
every wait is bounded.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from astrodyn import bus
from astrodyn.service.children import children_of

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _recordings import one_satellite_scene
from _serve_control import serve_status

pytestmark = pytest.mark.network

ASTRODYN = [sys.executable, "-m", "astrodyn"]
LEGACY = Path(__file__).resolve().parent / "fixtures" / "legacy-v0.mcap"  # a small recording to replay
#: Extra settings only (astrodyn sets mode, endpoints and scouting itself).
GOOD_CONFIG = "{\n  // extra settings only\n  transport: { unicast: { max_sessions: 64 } },\n}\n"


def _states(path: Path) -> dict[str, list[int]]:
    """topic -> the seqs of its state messages, in file order (plain mcap reader)."""
    from mcap.reader import make_reader

    out: dict[str, list[int]] = {}
    with open(path, "rb") as f:
        for _, channel, message in make_reader(f).iter_messages():
            if channel.topic.endswith(("/orbit", "/attitude")):
                out.setdefault(channel.topic, []).append(json.loads(message.data)["seq"])
    return out


def _children_running(supervisor: int, module: str, kind: str | None = None) -> dict[int, list[str]]:
    """PID -> argv of the supervisor's live children started as ``python -m module [kind]``."""
    found = {}
    for pid, argv in children_of(supervisor).items():
        if module in argv and (kind is None or argv[argv.index(module) + 1] == kind):
            found[pid] = argv
    return found


def _wait_for(ready, timeout_s: float, what: str):
    deadline = time.monotonic() + timeout_s
    while not (value := ready()):
        assert time.monotonic() < deadline, what
        time.sleep(0.05)
    return value


def _hub_of_run(run: subprocess.Popen) -> str:
    """The hub endpoint ``astrodyn run`` names on stderr at start (``  bus tcp/...: ...``);
    AssertionError with what it said if it ends first."""
    lines = []
    while line := run.stderr.readline():  # EOF when the run ends
        lines.append(line)
        if line.startswith("  bus "):
            return line.split()[1].rstrip(":")
    raise AssertionError("".join(lines))


def _zenoh_config_of(argv: list[str]) -> str:
    return argv[argv.index("--zenoh-config") + 1]


# --------------------------------------------------------------------------- read once, copied for every process


def test_serve_restarts_a_killed_propagator_from_its_own_copy_when_the_file_became_a_fifo(tmp_path, processes):
    """``serve --zenoh-config FILE``: FILE is replaced by a FIFO while serve runs, then the
    orbit propagator is SIGKILLed.  Serve restarts it with its copy of FILE (in its work
    directory), the new propagator goes on, and the recording holds every step once."""
    user_config = tmp_path / "zenoh.json5"
    user_config.write_text(GOOD_CONFIG)
    scene = tmp_path / "serve.toml"
    scene.write_text(one_satellite_scene("zcserve", "200000 s", "10 Hz"))
    out = tmp_path / "served.mcap"
    sup = processes([*ASTRODYN, "serve", scene, "--out", out, "--rate", "400", "--zenoh-config", user_config],
                    stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    hello = json.loads(sup.stdout.readline())
    assert hello["serving"] == "zcserve"
    with bus.open_session(connect=hello["hub"], mode="client") as session:
        status = serve_status(session, "zcserve", hello["control_token"])

        def orbit_t() -> float:
            return (status()["processes"].get("orbit") or {}).get("t") or 0.0

        _wait_for(lambda: orbit_t() > 10.0, 60, "the orbit propagator publishes nothing")
        (victim, argv), = _children_running(sup.pid, "astrodyn.service.propagator", "orbit").items()
        copy = Path(_zenoh_config_of(argv))
        copy_text, copy_mode = copy.read_text(), copy.stat().st_mode & 0o777
        user_config.unlink()
        os.mkfifo(user_config)  # a restarted process that opened it would block, or refuse it
        t_killed = orbit_t()
        os.kill(victim, signal.SIGKILL)
        new_orbit = _wait_for(lambda: {p: a for p, a in _children_running(sup.pid, "astrodyn.service.propagator",
                                                                          "orbit").items() if p != victim},
                              60, "the orbit propagator was not restarted")
        (restarted, new_argv), = new_orbit.items()
        # the restarted propagator works: its heartbeats go past the step of the kill
        _wait_for(lambda: status()["processes"]["orbit"]["pid"] == restarted and orbit_t() > t_killed + 20.0, 60,
                  "the restarted orbit propagator does not get past the kill")
    assert sup.poll() is None
    os.kill(sup.pid, signal.SIGTERM)  # = stop
    out_text, err = sup.communicate(timeout=120)
    summary = json.loads(out_text.strip().splitlines()[-1])
    assert sup.returncode == 0, err[-3000:]
    assert [(r["process"], r["old_pid"], r["new_pid"]) for r in summary["restarts"]] == [("orbit", victim, restarted)]
    recorded = _states(Path(summary["file"]))
    assert set(recorded) == {"astrodyn/zcserve/sat/orbit", "astrodyn/zcserve/sat/attitude"}
    for topic, seqs in recorded.items():  # no gap, no duplicate across the restart
        assert seqs == list(range(len(seqs))) and len(seqs) > 1000, (topic, len(seqs))
    # every process, the restarted one too, was given serve's private copy, never the user's file
    assert copy.parent.name.startswith(".astrodyn-serve-") and Path(_zenoh_config_of(new_argv)) == copy, argv
    assert copy_text == GOOD_CONFIG and copy_mode == 0o600
    assert not copy.exists()  # the work directory is gone with serve


@pytest.mark.slow  # CI time (9 s; run's restarts stay covered by test_reliability and test_supervision)
def test_run_restarts_a_killed_propagator_from_its_own_copy_when_the_file_was_deleted(tmp_path, processes):
    """``run --zenoh-config FILE``: FILE is deleted while the run goes on and the attitude
    propagator is SIGKILLed; the run restarts it from its copy and completes with every
    step of every channel, once."""
    user_config = tmp_path / "zenoh.json5"
    user_config.write_text(GOOD_CONFIG)
    scene = tmp_path / "run.toml"
    scene.write_text(one_satellite_scene("zcrun", "2000 s", "20 Hz"))
    out, result = tmp_path / "ran.mcap", tmp_path / "ran.json"
    sup = processes([*ASTRODYN, "run", scene, "--out", out, "--json", result, "--zenoh-config", user_config],
                    stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    with bus.open_session(connect=_hub_of_run(sup), mode="client") as session, bus.HeartbeatMonitor(session, "zcrun") as beats:

        def attitude_t() -> float:
            beats.poll()
            return beats.last.get("attitude", {}).get("t") or 0.0

        _wait_for(lambda: attitude_t() > 50.0, 60, "the attitude propagator publishes nothing")
        (victim, argv), = _children_running(sup.pid, "astrodyn.service.propagator", "attitude").items()
        user_config.unlink()
        os.kill(victim, signal.SIGKILL)
    _, err = sup.communicate(timeout=240)
    assert sup.returncode == 0, err[-3000:]
    restarts = json.loads(result.read_text())["restarts"]
    assert [(r["process"], r["old_pid"]) for r in restarts] == [("attitude", victim)], restarts
    recorded = _states(out)
    assert set(recorded) == {"astrodyn/zcrun/sat/orbit", "astrodyn/zcrun/sat/attitude"}
    for topic, seqs in recorded.items():
        assert seqs == list(range(40001)), (topic, len(seqs))
    assert Path(_zenoh_config_of(argv)).parent.name.startswith(".astrodyn-run-"), argv  # the run's copy


# --------------------------------------------------------------------------- one size cap, one-line refusals, exit 2


def _command(name: str, tmp_path: Path, zenoh_config: Path) -> tuple[list, str]:
    """The argv of ``name`` (run, serve, replay, router) given ``zenoh_config``, and its flag."""
    scene = tmp_path / "tiny.toml"
    scene.write_text(one_satellite_scene("zctiny", "10 s", "1 Hz"))
    if name in ("run", "serve"):
        return [*ASTRODYN, name, scene, "--out", tmp_path / f"{name}.mcap", "--zenoh-config", zenoh_config], \
            "--zenoh-config"
    if name == "replay":
        return [*ASTRODYN, "replay", LEGACY, "--wait", "0", "--rate", "inf", "--quiet", "--zenoh-config",
                zenoh_config], "--zenoh-config"
    return [*ASTRODYN, "router", "--listen", bus.loopback_endpoint(), "--config", zenoh_config], "--config"


COMMANDS = ("run", "serve", "replay", "router")


def test_a_zenoh_config_above_the_cap_is_refused_by_every_command(tmp_path):
    """A 1 MiB + 1 kB config: ``run`` and ``serve`` refused it, but ``replay`` parsed and used
    it (exit 0) and ``router`` ran on it.  Now every command refuses it with the one message
    of ``bus.ZENOH_CONFIG_MAX_BYTES``, exit 2, and nothing runs."""
    big = tmp_path / "big.json5"
    big.write_text(GOOD_CONFIG + "// padding\n" * ((2**20 + 1024) // 11))  # bus.ZENOH_CONFIG_MAX_BYTES + 1 kB
    for name in COMMANDS:
        argv, flag = _command(name, tmp_path, big)
        done = subprocess.run([str(a) for a in argv], capture_output=True, text=True, timeout=30)
        assert done.returncode == 2, (name, done.stderr[-2000:])
        assert (f"{flag} {big}: expected a Zenoh JSON5 configuration of at most 1 MiB (1048576 bytes), got "
                f"{big.stat().st_size} bytes") in done.stderr, (name, done.stderr)
        assert len(done.stderr.strip().splitlines()) == 1 and "Traceback" not in done.stderr
        assert not list(tmp_path.glob("*.mcap"))


def test_a_zenoh_config_nested_past_the_parsers_stack_is_refused_by_every_command(tmp_path):
    """``"[" * 50000`` (100 kB, under the size cap) made Zenoh's JSON5 parser recurse past the
    native stack: every command taking the file died of SIGSEGV with nothing printed
    (sweep probe, session 16).  Now each refuses it in one line, exit 2, before Zenoh reads it; brackets inside strings and
    comments are text, so a config with an IPv6 endpoint and a commented ``[`` still passes."""
    deep = tmp_path / "deep.json5"
    deep.write_text("[" * 50000 + "]" * 50000 + "\n")
    for name in ("run", "router"):  # serve and replay read it through the same bus._load_zenoh_config
        argv, flag = _command(name, tmp_path, deep)
        done = subprocess.run([str(a) for a in argv], capture_output=True, text=True, timeout=30)
        assert done.returncode == 2, (name, done.returncode, done.stderr[-2000:])
        assert done.stderr.strip().endswith(
            f"{flag} {deep}: expected a Zenoh configuration nested at most {bus.ZENOH_CONFIG_MAX_DEPTH} deep "
            f"('{{' and '['), got deeper"), (name, done.stderr)
        assert len(done.stderr.strip().splitlines()) == 1
    brackets_as_text = ('{\n  // [[[[ a comment\n  /* [[[[ */\n'
                        '  connect: { endpoints: ["tcp/[::1]:7447" ] },\n  id: null, // ' + "[" * 200 + "\n}\n")
    assert bus.zenoh_config_depth(brackets_as_text.encode()) == 3
    assert bus.zenoh_config_depth(b'{a: "' + b"[" * 300 + b'"}') == 1
    assert bus.zenoh_config_depth(b"/* " + b"[" * 300) == 0  # an unclosed comment ends the text


SYNTAX_ERROR = '{\n  transport: { unicast: { max_sessions: } },\n}\n'  # no value: JSON5 syntax
TYPE_ERROR = '{\n  scouting: { gossip: { enabled: "yes" } },\n}\n'  # valid JSON5, a string for a boolean


@pytest.mark.parametrize("name", COMMANDS)
def test_zenohs_refusal_of_a_config_is_one_line_naming_flag_file_line_and_column(name, tmp_path):
    """Zenoh's parse errors came out as several lines (quoted source, carets) or as Rust
    structures (``JSON error: Message { msg: ..., location: Some(Location { ... }) }``), and
    ``replay`` / ``router`` exited 1 for them.  Now: one line with the flag, the file, the
    line and column and what Zenoh expected; exit 2, as for every bad flag value."""
    for text, says in ((SYNTAX_ERROR, ": line 2, column 41: expected array, boolean, null, number, object, or string"),
                       (TYPE_ERROR, ': line 2, column 34: invalid type: string "yes", expected a boolean')):
        given = tmp_path / "zenoh.json5"
        given.write_text(text)
        argv, flag = _command(name, tmp_path, given)
        done = subprocess.run([str(a) for a in argv], capture_output=True, text=True, timeout=30)
        lines = done.stderr.strip().splitlines()
        assert done.returncode == 2 and len(lines) == 1, done.stderr
        assert f"{flag} {given}: expected a readable Zenoh JSON5 configuration{says}" in lines[0], lines
        assert not any(noise in lines[0] for noise in ("-->", "^", ".rs:", "JSON error", "Location", "Traceback"))


def test_a_config_zenoh_reads_but_cannot_open_with_ends_run_and_serve_in_one_line(tmp_path):
    """A config Zenoh parses but cannot open a session with (a user/password dictionary file
    that does not exist): the hub's session raised BusError through ``run`` and ``serve``, a
    traceback.  Now exit 1 with one ``error:`` line naming the cause."""
    given = tmp_path / "zenoh.json5"
    given.write_text(f'{{ transport: {{ auth: {{ usrpwd: {{ dictionary_file: "{tmp_path / "absent.txt"}" }} }} }} }}')
    for name in ("run", "serve"):
        argv, _ = _command(name, tmp_path, given)
        done = subprocess.run([str(a) for a in argv], capture_output=True, text=True, timeout=120)
        assert done.returncode == 1 and "Traceback" not in done.stderr, done.stderr[-3000:]
        assert f"astrodyn {name}: error: cannot open a Zenoh session" in done.stderr
        assert "Invalid user-password dictionary file" in done.stderr


# --------------------------------------------------------------------------- what the file does not decide


def test_a_zenoh_id_shared_by_the_processes_of_a_run_is_refused(tmp_path):
    """A config with ``id``: every process of the run had the same Zenoh id, so none linked
    to the hub; the run waited a minute for its logger, then failed.  Now refused at once."""
    given = tmp_path / "zenoh.json5"
    given.write_text('{ id: "aabbccdd" }')
    argv, _ = _command("run", tmp_path, given)
    done = subprocess.run([str(a) for a in argv], capture_output=True, text=True, timeout=30)
    assert done.returncode == 2, done.stderr[-2000:]
    assert f'--zenoh-config {given}: sets id "aabbccdd", which every process this command starts would share' \
        in done.stderr


def _sockets_of(pid: int) -> list[tuple[str, str, int]]:
    """(protocol, local address, port) of every TCP / UDP socket process ``pid`` holds
    (its ``/proc/PID/fd`` inodes looked up in ``/proc/PID/net``)."""
    import socket
    import struct

    inodes = set()
    for fd in os.listdir(f"/proc/{pid}/fd"):
        with contextlib.suppress(OSError):  # an fd closed meanwhile
            link = os.readlink(f"/proc/{pid}/fd/{fd}")
            if link.startswith("socket:["):
                inodes.add(link[8:-1])
    found = []
    for proto in ("tcp", "tcp6", "udp", "udp6"):
        with open(f"/proc/{pid}/net/{proto}") as f:
            for row in f.read().splitlines()[1:]:
                fields = row.split()
                if fields[9] not in inodes:
                    continue
                address, port = fields[1].split(":")
                raw = bytes.fromhex(address)
                if len(raw) == 4:
                    host = socket.inet_ntop(socket.AF_INET, struct.pack("<I", int(address, 16)))
                else:
                    host = socket.inet_ntop(socket.AF_INET6, b"".join(struct.pack("<I", int(address[i:i + 8], 16))
                                                                       for i in range(0, 32, 8)))
                found.append((proto, host, int(port, 16)))
    return found


def test_a_router_config_does_not_open_the_router_to_the_network(tmp_path, processes):
    """``router --config FILE`` where FILE listens on every interface and turns multicast
    scouting on: before, the file's scouting stayed on (a UDP socket on 224.0.0.224:7446
    announced the router on the LAN).  Now the router listens only where ``--listen`` says,
    scouts nothing, and a warning names the settings it replaced."""
    wide = bus.free_port()
    given = tmp_path / "router.json5"
    given.write_text(f'{{ listen: {{ endpoints: ["tcp/0.0.0.0:{wide}"] }}, scouting: {{ multicast: {{ enabled: true }} }} }}')
    endpoint = bus.loopback_endpoint()
    router = processes([*ASTRODYN, "router", "--listen", endpoint, "--config", given], stdout=subprocess.PIPE,
                       stderr=subprocess.PIPE, text=True)
    hello = json.loads(router.stdout.readline())
    assert hello["listen"] == [endpoint]
    time.sleep(1.5)  # zenoh opens its scouting socket in the background
    sockets = _sockets_of(router.pid)
    port = int(endpoint.rsplit(":", 1)[1])
    assert ("tcp", "127.0.0.1", port) in sockets, sockets
    assert all(proto.startswith("tcp") and host == "127.0.0.1" for proto, host, _ in sockets), sockets
    assert not any(p == wide or p == 7446 for _, _, p in sockets), sockets
    os.kill(router.pid, signal.SIGTERM)
    _, err = router.communicate(timeout=30)
    assert router.returncode == 0, err
    assert f'--config {given}: sets listen.endpoints ["tcp/0.0.0.0:{wide}"], scouting.multicast.enabled true, ' \
           f"which astrodyn replaces" in err, err
