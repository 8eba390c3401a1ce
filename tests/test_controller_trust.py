"""Controllers against forged and malformed bus traffic (docs/control.md, "Trusting what you
read"), with real processes.

The forger is a separate process that imports only zenoh (what any local user has), joins
the run's hub (the endpoint the run prints) and, while a lockstep loop runs, puts on the
run's ``@tick``, ``@event`` and sensor keys: well-formed ticks of made-up samples (unsigned,
with a forged ``ADA1`` authenticator, with an ``ADP1`` part signed with another control
token, with both, with a genuine tick's authenticator, and replays of genuine signed ticks),
the plant's ``stop`` event in its name (also with an ``ADP1`` part of another token),
payloads that are not JSON, not objects, hold NaN, 1e999 or a 400-digit integer, are nested
100,000 deep, or weigh 50 MB.  Controllers run with the run secret (``--controller``) and,
started by hand, with only the control token: both must drop all of it.  The controller is started through a
wrapper that only gates its first tick until the forger has begun (so the whole loop runs
under the attack) and keeps its stderr.

The reference is independent of the code under test: a lockstep run is deterministic, so
the attacked run's states, sensor samples, actuator states and commands must equal, byte
for byte, those of the same run without the forger; and the controller must end by itself
(exit 0), with a bounded report on stderr and no traceback.  The plant's checks of answers
are tested the same way: a controller that answers a tick never sent, answers twice, and
lets an unlisted name answer, while it answers the next ticks late: the states equal the
reference only if the plant ignored those answers and waited.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from _recordings import payloads_by_topic
from _serve_control import read_run_start
from astrodyn.plant import CommandRefused, Plant
from astrodyn.scenario import load

pytestmark = pytest.mark.network
ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
KINDS = ("/attitude", "/gyro", "/star_tracker", "/tachometer", "/actuators", "/command")

FORGER = textwrap.dedent(r'''
    """python forger.py ENDPOINT SCENARIO BODY SIGNALS MODE: waits for SIGNALS/subscribed,
    puts forged traffic (MODE "full": everything; "malformed": only what no controller may
    parse), touches SIGNALS/gate after its first round, stops at SIGNALS/stop or after 15 s."""
    import hashlib, hmac, json, os, sys, time, zenoh
    endpoint, scenario, body, signals, mode = sys.argv[1:6]
    base = f"astrodyn/{scenario}"
    other_key = hmac.new(b"not the run's token, 43 characters long....", b"ADP1 plant tick v1", hashlib.sha256).digest()

    def adp1(key, payload, counter):  # the plant's part for token holders, keyed by another token
        header = b"ADP1" + counter.to_bytes(8, "little")
        return header + hmac.new(other_key, header + f"{base}/{key}".encode() + b"\0" + payload, hashlib.sha256).digest()

    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    tick = lambda **f: {"t": 0.1, "seq": 1, "step": 1, "samples": {}, **f}
    MALFORMED = [b"\xff\xfe not JSON", b"[1, 2, 3]", b'"a string"', b"null", b"1e999", b"[" * 100000 + b"]" * 100000,
                 b'{"t": NaN, "seq": 1, "step": 1, "samples": {}}', b'{"t": 1e999, "seq": 1, "step": 1, "samples": {}}',
                 b'{"t": 0.1, "seq": ' + b"9" * 400 + b', "step": 1, "samples": {}}',
                 b'{"t": "0.1", "seq": 1.5, "step": 1, "samples": {}}', b'{"t": 0.1, "seq": 1, "step": 1, "samples": []}',
                 json.dumps(tick(samples={f"{body}/gyro": [1, 2]})).encode(),
                 json.dumps(tick(samples={f"{body}/gyro": {"t": 0.1, "seq": 1, "w": "x"}})).encode(),
                 json.dumps(tick(samples={f"{body}/gyro": {"t": 0.1, "seq": 1, "w": [1e308, -1e308, 1e308]}})).replace(
                     "1e+308", "1e999").encode(),
                 b'{"t": 0.1, "seq": 1, "process": 7, "kind": ["stop"]}', b'{"process": "plant"}']
    keys = ("@tick", "@event", f"{body}/gyro", f"{body}/star_tracker", f"{body}/attitude")
    big = b'{"t": 0.1, "seq": 1, "step": 1, "samples": {"pad": "' + b"x" * (50 << 20) + b'"}}'
    sent = {}
    with zenoh.open(conf) as s:
        pubs = {}
        def put(key, payload, attachment=None, what="?", block=False):
            # block: a forgery every controller must count is not dropped on the way when the
            # forger's own queue is full (after the 50 MB puts, under load); the malformed
            # flood may be dropped (DROP, zenoh's default), as a real flood would be
            if (key, block) not in pubs:
                cc = zenoh.CongestionControl.BLOCK if block else zenoh.CongestionControl.DROP
                pubs[key, block] = s.declare_publisher(f"{base}/{key}", congestion_control=cc)
            pubs[key, block].put(payload, attachment=attachment)
            sent[what] = sent.get(what, 0) + 1
        def put_whole(key, payload, what):  # not dropped on the way when a queue is full; at the lowest
            # priority, so that the hub's link to the controller, busy with 50 MB, still passes the
            # forgeries first (the run is over in a few hundred ms)
            s.put(f"{base}/{key}", payload, congestion_control=zenoh.CongestionControl.BLOCK,
                  priority=zenoh.Priority.BACKGROUND)
            sent[what] = sent.get(what, 0) + 1
        genuine = s.declare_subscriber(f"{base}/@tick", zenoh.handlers.RingChannel(64))
        deadline = time.monotonic() + 10
        while not os.path.exists(os.path.join(signals, "subscribed")) and time.monotonic() < deadline:
            time.sleep(0.01)
        time.sleep(0.3)  # the controller's subscriptions reach the hub
        captured, rounds, deadline = [], 0, time.monotonic() + 15
        while rounds < 1000 and time.monotonic() < deadline and not os.path.exists(os.path.join(signals, "stop")):
            rounds += 1
            while (smp := genuine.try_recv()) is not None:  # the plant's (our own forged ones have a zero instance)
                a = smp.attachment.to_bytes() if smp.attachment is not None else b""
                if a[:10] == b"ADA1\x05plant" and a[10:18] != bytes(8) and len(captured) < 4:
                    captured.append((smp.payload.to_bytes(), a))
            for payload in MALFORMED:
                for key in keys:
                    put(key, payload, what="malformed")
            if mode == "full":
                made_up = {"t": 0.05 * rounds, "seq": 1000 + rounds, "step": 1000 + rounds,
                           "samples": {f"{body}/gyro": {"t": 0.0, "seq": 0, "w": [1.0, 1.0, 1.0]},
                                       f"{body}/star_tracker": {"t": 0.0, "seq": 0, "q": [0.0, 1.0, 0.0, 0.0]},
                                       f"{body}/attitude": {"t": 0.0, "seq": 0, "model": "actuated",
                                                            "q": [0.0, 1.0, 0.0, 0.0], "w": [1.0, 1.0, 1.0]}}}
                payload = json.dumps(made_up).encode()
                put("@tick", payload, what="forged tick", block=True)
                forged_ada1 = b"ADA1\x05plant" + bytes(8) + rounds.to_bytes(8, "little") + bytes(32)
                put("@tick", payload, forged_ada1, what="forged authenticator", block=True)
                put("@tick", payload, adp1("@tick", payload, 2**40 + rounds), what="another token", block=True)
                put("@tick", payload, forged_ada1 + adp1("@tick", payload, 2**40 + rounds), what="forged both")
                for p, a in captured:
                    put("@tick", p, a, what="replayed tick", block=True)
                    put("@tick", payload, a, what="genuine authenticator, made-up tick")
                put(f"{body}/gyro", json.dumps({"t": 0.0, "seq": 0, "w": [1.0, 1.0, 1.0]}).encode(), what="forged sample")
                stop = json.dumps({"t": 0.0, "seq": 99, "process": "plant", "kind": "stop", "detail": "{}"}).encode()
                put("@event", stop, what="forged stop")
                put("@event", stop, adp1("@event", stop, 2**40 + rounds), what="forged stop")
            if rounds == 1:
                open(os.path.join(signals, "gate"), "w").close()
                for key in ("@tick", f"{body}/gyro"):  # after the first forgeries, not in front of them
                    put_whole(key, big, "50 MB")
            time.sleep(0.02)
    print(json.dumps({"rounds": rounds, "captured": len(captured), "sent": sent}), flush=True)
''')

GATED = textwrap.dedent(r'''
    """python gated.py SIGNALS SCRIPT: runs SCRIPT (a controller) with its stderr in
    SIGNALS/controller.err; once it has declared its @event subscriber (its last), touches
    SIGNALS/subscribed and holds it there until SIGNALS/gate exists (at most 10 s).  Writes
    SIGNALS/exit0 when SCRIPT returns."""
    import os, runpy, sys, time
    import zenoh
    signals, script = sys.argv[1], sys.argv[2]
    os.dup2(os.open(os.path.join(signals, "controller.err"), os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600), 2)
    sys.path.insert(0, os.path.dirname(script))
    sys.path.insert(0, EXAMPLES)
    real_open = zenoh.open

    class Gated:
        def __init__(self, session):
            self.session = session
        def __getattr__(self, name):
            return getattr(self.session, name)
        def __enter__(self):
            return self
        def __exit__(self, *exc):
            self.session.close()
        def declare_subscriber(self, key, *args, **kw):
            sub = self.session.declare_subscriber(key, *args, **kw)
            if key.endswith("/@event"):
                open(os.path.join(signals, "subscribed"), "w").close()
                deadline = time.monotonic() + 10
                while not os.path.exists(os.path.join(signals, "gate")) and time.monotonic() < deadline:
                    time.sleep(0.01)
            return sub

    zenoh.open = lambda conf: Gated(real_open(conf))
    runpy.run_path(script, run_name="__main__")
    open(os.path.join(signals, "exit0"), "w").close()
''').replace("EXAMPLES", repr(str(EXAMPLES)))


def _slew(tmp: Path) -> Path:
    path = tmp / "slew.toml"
    path.write_text((ROOT / "configs" / "slew.toml").read_text().replace('duration = "180 s"', 'duration = "3 s"'))
    return path


def _detumble(tmp: Path) -> Path:
    text = (ROOT / "configs" / "detumble.toml").read_text().replace('duration = "900 s"', 'duration = "3 s"')
    path = tmp / "detumble.toml"
    path.write_text(text[:text.index("[[control.faults]]")] + text[text.index("[[bodies]]"):])  # no faults
    return path


def _signals(tmp: Path, gate: bool) -> Path:
    """The folder through which forger, wrapper and test signal each other; ``gate``: no forger waits."""
    signals = tmp / "signals"
    signals.mkdir()
    (signals / "gated.py").write_text(GATED)
    if gate:
        (signals / "gate").touch()
    return signals


def _run(start, cfg: Path, out: Path, signals: Path, controller: Path | None, forger_mode: str | None = None,
         body: str = "sc", outside_env: dict | None = None) -> tuple[int, str, dict | None, int | None]:
    """``astrodyn run cfg`` (lockstep) with ``controller`` under the wrapper as its
    ``--controller`` (or, with ``outside_env``, started by hand with those variables), and
    the forger in ``forger_mode``.  Returns the run's exit status and stderr, the forger's
    report and the outside controller's exit status."""
    argv = [sys.executable, "-m", "astrodyn", "run", cfg, "--out", out, "--quiet"]
    if controller is not None and outside_env is None:
        argv += ["--controller", f"python {signals / 'gated.py'} {signals} {controller}"]
    run = start(argv, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True, cwd=ROOT)
    found = read_run_start(run.stderr)
    outside = None
    if outside_env is not None:
        env = {k: v for k, v in os.environ.items() if k != "ASTRODYN_RUN_SECRET_FILE"}
        env.update(outside_env, ASTRODYN_CONNECT=found["hub"], ASTRODYN_CONTROL_TOKEN_FILE=found["token"])
        outside = start([sys.executable, signals / "gated.py", signals, controller], env=env, cwd=ROOT)
    forger = None
    if forger_mode is not None:
        (signals / "forger.py").write_text(FORGER)
        forger = start([sys.executable, signals / "forger.py", found["hub"], cfg.stem, body, signals, forger_mode],
                       stdout=subprocess.PIPE, text=True)
    _, err = run.communicate(timeout=60)
    (signals / "stop").touch()
    report = json.loads(forger.communicate(timeout=30)[0]) if forger is not None else None
    if outside is not None:
        outside.wait(timeout=30)
    return run.returncode, found["lines"] + err, report, None if outside is None else outside.returncode


def _payloads(path: Path) -> dict[str, list[bytes]]:
    return payloads_by_topic(path, KINDS)


def _controller_report(signals: Path) -> list[str]:
    """The controller's stderr lines; asserts it returned (exit0) without a traceback."""
    lines = (signals / "controller.err").read_text().splitlines()
    assert (signals / "exit0").exists() and not any("Traceback" in x for x in lines), "\n".join(lines[:40])
    return lines


@pytest.fixture(scope="module")
def slew_reference(tmp_path_factory):
    """State payloads of the 3 s slew (examples/slew_pd.py), no forger: the reference."""
    tmp = tmp_path_factory.mktemp("reference")
    signals = _signals(tmp, gate=True)
    started: list[subprocess.Popen] = []

    def start(argv, **kw) -> subprocess.Popen:
        started.append(subprocess.Popen([str(a) for a in argv], **kw))
        return started[-1]

    try:
        rc, err, _, _ = _run(start, _slew(tmp), tmp / "ref.mcap", signals, EXAMPLES / "slew_pd.py")
    finally:
        for proc in started:  # by PID, only ours
            if proc.poll() is None:
                os.kill(proc.pid, signal.SIGKILL)
    assert rc == 0, err
    assert _controller_report(signals) == []  # nothing dropped, nothing said
    payloads = _payloads(tmp / "ref.mcap")
    assert len(payloads["astrodyn/slew/sc/attitude"]) == 31 and len(payloads["astrodyn/slew/sc/command"]) == 31
    return payloads


def test_the_example_link_drops_forged_ticks_and_malformed_samples_and_the_run_is_unchanged(
        tmp_path, processes, slew_reference):
    signals = _signals(tmp_path, gate=False)
    rc, err, forged, _ = _run(processes, _slew(tmp_path), tmp_path / "a.mcap", signals, EXAMPLES / "slew_pd.py", "full")
    assert forged["rounds"] >= 5 and forged["captured"] >= 1, forged  # the attack overlapped the loop
    assert rc == 3 and "ATTACKED" in err, err  # the run saw the forgery too (the logger rejects it)
    assert _payloads(tmp_path / "a.mcap") == slew_reference
    lines = _controller_report(signals)
    assert len(lines) == 2, lines  # the first drop and the counts at the end, not a line per sample
    assert lines[0].startswith("astrodyn_link: dropped a sample on 'astrodyn/slew/"), lines
    counts = dict((reason, int(n)) for n, reason in re.findall(r"(\d+) ([a-z-]+)", lines[1].split("(", 1)[1]))
    # each kind of forgery the forger sent, counted under its reason
    assert {"unsigned", "bad-mac", "replay", "too-large"} <= set(counts), lines
    assert sum(counts.values()) >= forged["sent"]["forged tick"], (counts, forged)


def test_an_outside_controller_with_only_the_token_drops_forged_ticks_and_the_run_is_unchanged(
        tmp_path, processes, slew_reference):
    """With only the control token the link checks the plant's ``ADP1`` part of each tick and
    of the stop event (docs/control.md, "Authentication"): forged, wrongly signed, replayed
    and malformed ticks never reach the controller, nor does the forged stop end it.  On the
    code before that part existed, the forged well-formed ticks were answered and the run
    failed."""
    signals = _signals(tmp_path, gate=False)
    rc, err, forged, outside_rc = _run(processes, _slew(tmp_path), tmp_path / "a.mcap", signals,
                                       EXAMPLES / "slew_pd.py", "full",
                                       outside_env={"ASTRODYN_SCENARIO": "slew", "ASTRODYN_CONTROLLER": "pd"})
    assert forged["rounds"] >= 5 and forged["captured"] >= 1, forged  # the attack overlapped the loop
    assert outside_rc == 0 and rc == 3 and "ATTACKED" in err, err
    assert _payloads(tmp_path / "a.mcap") == slew_reference
    lines = _controller_report(signals)
    assert len(lines) == 2, lines  # the first drop and the counts at the end
    # with the token it reads only ticks and the plant's events: nothing else can be checked
    assert lines[0].startswith(("astrodyn_link: dropped a sample on 'astrodyn/slew/@tick'",
                                "astrodyn_link: dropped a sample on 'astrodyn/slew/@event'")), lines
    counts = dict((reason, int(n)) for n, reason in re.findall(r"(\d+) ([a-z-]+)", lines[1].split("(", 1)[1]))
    assert {"unsigned", "bad-mac", "replay", "too-large"} <= set(counts), lines
    assert sum(counts.values()) >= forged["sent"]["forged tick"], (counts, forged)


@pytest.mark.parametrize("credential", ["secret", "token"])
def test_the_documented_controller_drops_forged_ticks_and_malformed_samples(tmp_path, processes, credential):
    """docs/control.md's self-contained controller, cut out of the page, under the forger,
    started by ``--controller`` (run secret) or by hand with only the control token.  Its
    law is the reference: one command per control step, ``torque = -5 w`` of the gyro
    sample of that step as the plant recorded it (a forged tick's gyro reads [1, 1, 1] and
    its time is not a step's), and it ends by itself."""
    block = re.search(r"## A complete controller.*?```python\n(.*?)```", (ROOT / "docs" / "control.md").read_text(),
                      re.S).group(1)
    signals = _signals(tmp_path, gate=False)
    (tmp_path / "ctl.py").write_text(block)
    outside = {"ASTRODYN_SCENARIO": "detumble", "ASTRODYN_CONTROLLER": "detumble"} if credential == "token" else None
    rc, err, forged, outside_rc = _run(processes, _detumble(tmp_path), tmp_path / "d.mcap", signals,
                                       tmp_path / "ctl.py", "full", outside_env=outside)
    assert forged["rounds"] >= 5 and forged["captured"] >= 1, forged
    assert rc == 3 and "ATTACKED" in err, err
    assert outside_rc in (None, 0), outside_rc
    lines = _controller_report(signals)
    assert len(lines) == 2 and lines[0].startswith("controller: dropped a sample on 'astrodyn/detumble/"), lines
    for reason in ("'unsigned'", "'bad MAC'", "'replayed'", "'too large'"):
        assert reason in lines[1], lines
    recorded = _payloads(tmp_path / "d.mcap")
    gyro = {m["t"]: m["w"] for m in map(json.loads, recorded["astrodyn/detumble/sc/gyro"])}
    commands = [json.loads(p) for p in recorded["astrodyn/detumble/sc/command"]]
    assert len(gyro) == 31 and [c["seq"] for c in commands] == list(range(31)), commands
    assert all(c["torque"] == [-5.0 * x for x in gyro[c["t"]]] for c in commands), commands


ANSWERS = textwrap.dedent(r'''
    """examples/slew_pd.py, with extra answers signed as the docs say (independent of the link):
    after its answer to tick 5, an answer to tick 8 (not sent yet), a second answer to tick 5
    and one of "intruder" (not a controller of the scene) with the control token; its own
    commands and answers to ticks 6, 7 and 8 come 0.3 s late; at the last tick it also commands a dv,
    which its body (three wheels) cannot do."""
    import hashlib, hmac, json, os, runpy, struct, sys, time
    from astrodyn_link import Link

    secret = open(os.environ["ASTRODYN_RUN_SECRET_FILE"], "rb").read()
    token = open(os.environ["ASTRODYN_CONTROL_TOKEN_FILE"], "rb").read().strip()
    instance, counter = os.urandom(8), [0]

    def signed(session, key, message):
        payload = json.dumps(message).encode()
        counter[0] += 1
        header = b"ADA1\x02pd" + instance + struct.pack("<Q", counter[0])
        session.put(key, payload, attachment=header + hmac.new(secret, header + key.encode() + b"\0" + payload,
                                                               hashlib.sha256).digest())

    take, answer = Link.wait_tick, Link.done

    def wait_tick(link, timeout=None):
        tick = take(link, timeout)
        if tick is not None and tick["seq"] in (6, 7, 8):
            time.sleep(0.3)  # commands and answer late
        return tick

    def done(link, tick):
        seq, key = tick["seq"], "astrodyn/slew/@done/pd"
        if tick["t"] >= 3.0:
            link.command("sc", tick["t"], dv=[1.0, 0.0, 0.0])
        answer(link, tick)
        if seq == 5:
            signed(link.session, key, {"t": 0.8, "seq": 8, "sender": "pd", "commands": 0})
            signed(link.session, key, {"t": tick["t"], "seq": 5, "sender": "pd", "commands": 0})
            link.session.put("astrodyn/slew/@done/intruder", json.dumps(
                {"t": tick["t"], "seq": 5, "sender": "intruder", "commands": 0}).encode(), attachment=b"ADT1" + token)

    Link.wait_tick, Link.done = wait_tick, done
    runpy.run_path(os.path.join(os.path.dirname(sys.modules["astrodyn_link"].__file__), "slew_pd.py"), run_name="__main__")
''')


def test_the_plant_rejects_answers_to_ticks_it_never_sent_repeated_and_unlisted_answers(
        tmp_path, processes, slew_reference):
    signals = _signals(tmp_path, gate=True)
    (tmp_path / "answers.py").write_text(ANSWERS)
    rc, err, _, _ = _run(processes, _slew(tmp_path), tmp_path / "a.mcap", signals, tmp_path / "answers.py")
    _controller_report(signals)
    assert rc == 3, err  # rejected answers are reported as an attack on the run, never fatal
    # the plant waited for the late answers as if the extra ones had not been sent
    assert _payloads(tmp_path / "a.mcap") == slew_reference
    attacked = next(line for line in err.splitlines() if "ATTACKED" in line)
    for reason in ("1 command unsent-tick", "1 command repeated-answer", "1 command unknown-controller"):
        assert reason in attacked, attacked
    # the dv the body cannot do: refused, naming the body and the actuators it has (configs/slew.toml: three wheels)
    assert ("refused: sc pd#31: body sc has no impulsive dv capability (actuators.dv); it has 3 reaction wheels "
            "(wheel_torque)") in err, err


def test_a_refusal_names_the_body_and_the_actuators_it_has():
    """The actuators of configs/slew.toml (three wheels) and configs/detumble.toml (a
    0.05 N m torque actuator), as the refusal of each command they cannot do names them."""
    wheels = Plant(load(ROOT / "configs" / "slew.toml")).bodies["sc"]
    torque = Plant(load(ROOT / "configs" / "detumble.toml")).bodies["sc"]
    cases = [(wheels, {"dv": [1.0, 0.0, 0.0]}, "body sc has no impulsive dv capability (actuators.dv); it has 3 reaction "
              "wheels (wheel_torque)"),
             (wheels, {"thrust": [1.0, 0.0, 0.0]}, "body sc has no thrusters (actuators.thrust); it has 3 reaction wheels"),
             (torque, {"dv": [1.0, 0.0, 0.0]}, "body sc has no impulsive dv capability (actuators.dv); it has a torque "
              "actuator (torque, up to 0.05 N m per axis)")]
    for body, fields, reason in cases:
        with pytest.raises(CommandRefused) as refused:
            body.apply({"t": 0.0, "seq": 0, "sender": "c", **fields})
        assert str(refused.value).startswith(reason), str(refused.value)
