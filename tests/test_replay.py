"""``astrodyn replay`` and the log-time-ordered stream under it.

Replays run as real child processes (``python -m astrodyn replay``) that connect to the
test's own Zenoh session on a free loopback port (multicast scouting off); the test
subscribes like a live consumer would and compares what arrives with the file as read
by mcap's own reader (independent of :mod:`astrodyn.recording.stream`).  Every wait is
bounded in time, and every child is killed by its PID at teardown.
"""

from __future__ import annotations

import json
import random
import subprocess
import sys
import time
from pathlib import Path

import pytest
import zenoh
from mcap.reader import make_reader
from mcap.stream_reader import StreamReader

from astrodyn import bus, messages
from astrodyn.recording import McapRecorder, RecordingError
from astrodyn.recording.stream import open_stream

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _recordings import leo_recording

pytestmark = pytest.mark.network
EPOCH_NS = 1_774_008_000_000_000_000


@pytest.fixture
def spawn(processes):
    """Start ``astrodyn replay ARGS...`` (conftest ``processes``: killed by PID at teardown)."""

    def start(*args, **kw) -> subprocess.Popen:
        return processes([sys.executable, "-m", "astrodyn", "replay", *args],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kw)

    return start


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """50 s at 2 Hz: 101 steps x 3 channels (leo orbit + attitude, geo orbit)."""
    path = tmp_path_factory.mktemp("replay") / "rp.mcap"
    sc, res = leo_recording(path, name="rp", duration="50 s", rate="2 Hz")
    return path, sc, res


def _file_messages(path: Path) -> list[tuple[str, int, bytes]]:
    """(topic, log_time, payload) in log-time order, read by mcap's seeking reader."""
    with open(path, "rb") as f:
        return [(ch.topic, m.log_time, m.data) for _, ch, m in make_reader(f).iter_messages(log_time_order=True)]


class Collector:
    """A consumer as written for the live service: subscribes and timestamps arrivals."""

    def __init__(self, session, scenario: str):
        self.subs = [session.declare_subscriber(k, zenoh.handlers.FifoChannel(1 << 16))
                     for k in (f"astrodyn/{scenario}/**", f"astrodyn/{scenario}/@batch/*")]
        self.got: list[tuple[float, str, bytes]] = []

    def drain(self) -> int:
        n = 0
        for sub in self.subs:
            while (s := sub.try_recv()) is not None:
                self.got.append((time.monotonic(), str(s.key_expr), s.payload.to_bytes()))
                n += 1
        return n

    def assert_quiet(self, settle_s: float, quiet_s: float, what: str) -> int:
        """After ``settle_s`` (puts in flight arrive), nothing more arrives for ``quiet_s``;
        the number of messages got."""
        time.sleep(settle_s)
        self.drain()
        n = len(self.got)
        time.sleep(quiet_s)
        self.drain()
        assert len(self.got) == n, f"messages arrived while {what}"
        return n

    def until_exit(self, proc: subprocess.Popen, timeout_s: float) -> None:
        deadline = time.monotonic() + timeout_s
        quiet_since = None
        while time.monotonic() < deadline:
            if self.drain():
                quiet_since = None
            elif proc.poll() is not None:
                quiet_since = quiet_since or time.monotonic()
                if time.monotonic() - quiet_since > 0.5:
                    return
            time.sleep(0.002)
        raise AssertionError(f"replay did not finish within {timeout_s} s")

    def close(self):
        for sub in self.subs:
            sub.undeclare()


def _control(session, verb, args=None, token=None):
    replies = bus.send_control(session, "rp", verb, args, timeout_s=5.0, token=token)
    assert len(replies) == 1, replies
    return replies[0]


def _wait(predicate, timeout_s, what):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return
        time.sleep(0.01)
    raise AssertionError(f"timed out after {timeout_s} s waiting for {what}")


# ------------------------------------------------------------------------ stream (in process)


def test_stream_merges_out_of_step_writers_into_log_time_order(tmp_path):
    """Two 'processes' far out of step (all orbit states written before any attitude
    state) with tiny chunks: the stream must interleave them by log time."""
    path = tmp_path / "skew.mcap"
    n = 300
    with McapRecorder(path, {"name": "skew"}, epoch_ns=EPOCH_NS, chunk_size=2048) as rec:
        for k in range(n):
            rec.write("astrodyn/skew/a/orbit", messages.orbit_message(k * 0.5, k, "kepler", [7e6, 0, 0], [0, 7.5e3, 0], 3.986e14))
        for k in range(n):
            rec.write("astrodyn/skew/a/attitude", messages.attitude_message(k * 0.5, k, "torque_free", [1, 0, 0, 0], [0, 0, 0.1]))
    with open(path, "rb") as f:  # independent: mcap's streaming reader in file order, then a stable sort
        raw = [(r.log_time, r.channel_id, r.data) for r in StreamReader(f).records if type(r).__name__ == "Message"]
    expected = [(lt, d) for lt, _, d in sorted(raw, key=lambda x: x[0])]
    with open_stream(path) as s:
        assert len(s.chunks) > 10  # the merge is exercised over many chunks
        got = [(m.log_time, m.data) for m in s.messages()]
        assert [lt for lt, _ in got] == sorted(lt for lt, _ in got)
        assert sorted(got) == sorted(expected) and len(got) == 2 * n
        # window and topic filter: t in [10, 20] inclusive is steps 20..40 -> 21 states per channel
        sub = list(s.messages("astrodyn/skew/*/orbit", start_t=10.0, end_t=20.0))
        assert len(sub) == 21 and {m.topic for m in sub} == {"astrodyn/skew/a/orbit"}
        assert sub[0].log_time == EPOCH_NS + 10_000_000_000 and sub[-1].log_time == EPOCH_NS + 20_000_000_000


def test_stream_rejects_non_mcap(tmp_path):
    bad = tmp_path / "notes.mcap"
    bad.write_text("hello, I am not an MCAP file\n")
    with pytest.raises(RecordingError, match="not an MCAP file"):
        open_stream(bad)
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    with pytest.raises(RecordingError, match="empty"):
        open_stream(empty)


# ------------------------------------------------------------------------ replay processes


def test_replay_republishes_every_message_in_order_with_same_payloads(hub, spawn, recording):
    session, endpoint = hub
    path, _, _ = recording
    expected = _file_messages(path)
    col = Collector(session, "rp")
    proc = spawn(path, "--rate", "inf", "--connect", endpoint, "--wait", "10", "--quiet")
    col.until_exit(proc, 60)
    assert proc.returncode == 0, proc.stderr.read()
    summary = json.loads(proc.stdout.read().strip().splitlines()[-1])
    assert summary["messages"] == len(expected) and summary["complete"] is True
    got = [(k, p) for _, k, p in col.got]
    # every message, per channel in the recorded order, byte-identical
    for topic in {t for t, _, _ in expected}:
        assert [p for k, p in got if k == topic] == [d for t, _, d in expected if t == topic]
    assert len(got) == len(expected)
    # and globally in log-time order (t decoded from the payloads never decreases)
    ts = [json.loads(p)["t"] for _, p in got]
    assert ts == sorted(ts)
    col.close()


def test_replay_batch_mode_sends_the_propagators_envelopes(hub, spawn, recording):
    session, endpoint = hub
    path, _, res = recording
    expected = _file_messages(path)
    col = Collector(session, "rp")
    proc = spawn(path, "--rate", "inf", "--batch", "--connect", endpoint, "--wait", "10", "--quiet")
    col.until_exit(proc, 60)
    assert proc.returncode == 0
    keys = {k for _, k, _ in col.got}
    assert keys == {"astrodyn/rp/@batch/orbit", "astrodyn/rp/@batch/attitude"}
    orbit_envelopes = [messages.decode_batch(p) for _, k, p in col.got if k.endswith("@batch/orbit")]
    assert len(orbit_envelopes) == res.t.size  # one envelope per instant, like the propagator
    items = [it for _, k, p in col.got for it in messages.decode_batch(p)]
    assert sorted(items) == sorted((t, d) for t, _, d in expected)
    col.close()


def test_replay_paces_at_the_requested_rate(hub, spawn, recording):
    """50 s of log time at 10x real time must take 5 s +- 5 % between first and last message."""
    session, endpoint = hub
    path, _, _ = recording
    col = Collector(session, "rp")
    proc = spawn(path, "--rate", "10", "--connect", endpoint, "--wait", "10", "--quiet")
    col.until_exit(proc, 60)
    assert proc.returncode == 0
    t_first = min(a for a, k, p in col.got if json.loads(p)["t"] == 0.0)
    t_last = max(a for a, k, p in col.got if json.loads(p)["t"] == 50.0)
    assert len(col.got) == 303
    # 5 %: the requirement of issue 5 (sleep granularity and bus latency are ~1 ms here)
    assert abs((t_last - t_first) - 5.0) < 0.25, t_last - t_first
    # the middle too: message at t = 25 s arrives 2.5 s after the first (no drift, no bunching)
    t_mid = min(a for a, k, p in col.got if json.loads(p)["t"] == 25.0)
    assert abs((t_mid - t_first) - 2.5) < 0.125
    col.close()


@pytest.mark.slow  # CI time (8 s; run's Ctrl-Z test (test_ctrl_z.py) covers the job control replay shares)
def test_ctrl_z_pauses_a_replay_and_fg_goes_on_at_its_rate(hub, spawn, recording):
    """Ctrl-Z (SIGTSTP) stops the replay, nothing is published while it is stopped, and after
    fg (SIGCONT) it goes on at x10 from where it was: before, it raced through the log time
    the pause would have covered (20 s of it in a burst after a 2 s pause)."""
    import os
    import signal

    session, endpoint = hub
    path, _, _ = recording
    col = Collector(session, "rp")
    proc = spawn(path, "--rate", "10", "--connect", endpoint, "--wait", "10", "--quiet")
    _wait(lambda: col.drain() or col.got, 30, "first replayed message")
    time.sleep(1.0)
    os.kill(proc.pid, signal.SIGTSTP)
    n_stopped = col.assert_quiet(0.3, 2.0, "stopped")
    resumed = time.monotonic()
    os.kill(proc.pid, signal.SIGCONT)
    col.until_exit(proc, 60)
    assert proc.returncode == 0 and len(col.got) == 303
    after = [(a, json.loads(p)["t"]) for a, _, p in col.got[n_stopped:]]
    first = min(t for _, t in after)
    covered = max(t for a, t in after if a < resumed + 1.0) - first
    assert covered < 15.0, covered  # ~10 s of log time in the first second at x10
    col.close()


def test_replay_pause_resume_rate_seek_stop_over_zenoh(hub, spawn, recording):
    session, endpoint = hub
    path, _, _ = recording
    col = Collector(session, "rp")
    proc = spawn(path, "--rate", "5", "--hold", "--connect", endpoint, "--wait", "10", "--quiet")
    token = json.loads(proc.stdout.readline())["control_token"]
    _wait(lambda: col.drain() or col.got, 20, "first replayed message")
    time.sleep(0.5)
    assert "unauthorised" in _control(session, "pause")["error"]  # no token: refused
    assert "unauthorised" in _control(session, "stop", token=token[::-1])["error"]
    assert "error" in _control(session, "rate", {"factor": 1e-300}, token=token)
    status = _control(session, "pause", token=token)
    assert status["state"] == "paused"
    n_paused = col.assert_quiet(0.2, 1.0, "paused")
    t_paused = _control(session, "status", token=token)["t"]
    assert 0 < t_paused < 50
    assert _control(session, "resume", token=token)["state"] == "running"
    _wait(lambda: col.drain() and False or len(col.got) > n_paused, 5, "messages after resume")
    assert "error" in _control(session, "rate", {"factor": "fast"}, token=token)
    assert "error" in _control(session, "seek", {"t": 1e6}, token=token)
    for t in (10**400, 1e308, -1e308, True, "40", [40]):  # the first three once ended in OverflowError
        assert "seek.t: expected a number of seconds" in _control(session, "seek", {"t": t}, token=token)["error"]
    assert _control(session, "status", token=token)["state"] == "running"  # and the replay goes on
    status = _control(session, "rate", {"factor": "inf"}, token=token)
    assert status["real_time_factor"] == "inf"
    _wait(lambda: _control(session, "status", token=token)["state"] == "finished", 20, "the end of the replay")
    n_end = (col.drain(), len(col.got))[1]
    assert n_end == 303
    # seek back to t = 40 s: steps 80..100 of 3 channels come again
    assert _control(session, "seek", {"t": 40.0}, token=token)["state"] == "running"
    _wait(lambda: _control(session, "status", token=token)["state"] == "finished", 20, "the end after the seek")
    time.sleep(0.3)
    col.drain()
    again = col.got[n_end:]
    assert len(again) == 63 and min(json.loads(p)["t"] for _, _, p in again) == 40.0
    final = _control(session, "stop", token=token)
    assert final["state"] == "stopped"
    proc.wait(timeout=10)
    assert proc.returncode == 0
    col.close()


def test_a_replay_waiting_for_a_subscriber_answers_and_stops_at_once(hub, spawn, recording):
    """While replay waits (``--wait``) for a subscriber, it answers its control verbs and a
    ``stop`` or SIGTERM ends it at once (before: nothing was answered and SIGTERM waited the
    whole ``--wait``, 59 s of 60)."""
    import signal

    session, endpoint = hub
    path, _, _ = recording
    for how in ("stop", "SIGTERM"):
        proc = spawn(path, "--connect", endpoint, "--wait", "120", "--quiet")
        token = json.loads(proc.stdout.readline())["control_token"]
        time.sleep(0.5)  # nobody subscribes: the replay is waiting
        status = _control(session, "status", token=token)
        assert status["messages"] == 0 and status["t"] == 0.0, status
        asked = time.monotonic()
        if how == "stop":
            assert _control(session, "stop", token=token)["state"] == "stopped"
        else:
            proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=20)
        assert time.monotonic() - asked < 10, how
        assert proc.returncode == 0, (how, proc.stderr.read())


def test_a_waiting_replay_stays_at_its_start_time_until_playback(hub, spawn, recording):
    """While replay waits for its first subscriber nothing is published, so ``t`` is the
    start time in every reply: ``pause`` and ``rate`` answered ``t`` = rate x wall time
    since launch (10.3 s after about 1 s at ``--rate 10``, with ``messages`` 0)
    (docs walk, code problem 2).  A ``seek`` meanwhile moves the start point."""
    session, endpoint = hub
    path, _, _ = recording
    proc = spawn(path, "--connect", endpoint, "--rate", "10", "--wait", "120", "--quiet")
    token = json.loads(proc.stdout.readline())["control_token"]
    time.sleep(1.0)  # nobody subscribes: the replay is waiting; its clock must not run
    for verb, args in (("status", None), ("rate", {"factor": 20}), ("pause", None), ("status", None),
                       ("resume", None)):
        reply = _control(session, verb, args, token=token)
        assert reply["messages"] == 0 and reply["t"] == reply["t_start"] == 0.0, (verb, reply)
        time.sleep(0.3)
    assert _control(session, "seek", {"t": 20.0}, token=token)["t"] == 20.0
    time.sleep(0.5)
    reply = _control(session, "pause", token=token)
    assert reply["messages"] == 0 and reply["t"] == 20.0, reply
    assert _control(session, "stop", token=token)["state"] == "stopped"
    proc.wait(timeout=20)
    assert proc.returncode == 0, proc.stderr.read()


def test_replay_starts_from_its_zenoh_config(spawn, recording, tmp_path):
    """``--zenoh-config`` (TLS, access control) was accepted and silently ignored by replay:
    it opened a plain session.  A file Zenoh cannot parse, or a FIFO (whose read would block
    for good), must now stop it with the option named; a valid one is used."""
    import os

    path, _, _ = recording
    broken = tmp_path / "broken.json5"
    broken.write_text("{ transport: { unicast: { max_sessions: } }")
    fifo = tmp_path / "zenoh.fifo"
    os.mkfifo(fifo)
    for given, says, rc in ((broken, "expected a readable Zenoh JSON5 configuration", 2),
                            (fifo, "expected a regular file, got a FIFO", 2)):
        proc = spawn(path, "--zenoh-config", str(given), "--wait", "0", "--rate", "inf", "--quiet")
        _, err = proc.communicate(timeout=30)
        assert proc.returncode == rc and f"--zenoh-config {given}: {says}" in err and "Traceback" not in err, err
    good = tmp_path / "good.json5"
    good.write_text("{ transport: { unicast: { max_sessions: 64 } } }")
    proc = spawn(path, "--zenoh-config", str(good), "--wait", "0", "--rate", "inf", "--quiet")
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err
    assert json.loads(out.strip().splitlines()[-1])["messages"] == 303


def test_replay_of_a_cut_file_sends_what_is_complete_and_says_so(hub, spawn, recording, tmp_path):
    session, endpoint = hub
    path, _, _ = recording
    data = path.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut_at = random.Random(5).randrange(len(data) // 3, 2 * len(data) // 3)
    cut.write_bytes(data[:cut_at])
    with open(cut, "rb") as f:  # independent count: mcap's streaming reader stops at the cut
        complete = []
        try:
            for r in StreamReader(f, skip_magic=False).records:
                if type(r).__name__ == "Message":
                    complete.append(r.data)
        except Exception:
            pass
    assert 0 < len(complete) < 303
    col = Collector(session, "rp")
    proc = spawn(cut, "--rate", "inf", "--connect", endpoint, "--wait", "10")
    col.until_exit(proc, 60)
    err = proc.stderr.read()
    assert proc.returncode == 0, err
    summary = json.loads(proc.stdout.read().strip().splitlines()[-1])
    assert summary["complete"] is False and "truncated" in summary["file_report"]
    assert "incomplete" in err and f"replayed the {len(complete)} complete messages" in err
    assert sorted(p for _, _, p in col.got) == sorted(complete)
    col.close()


@pytest.mark.parametrize("content", [b"", b"PK\x03\x04 a zip, not mcap" * 10, b"\x89MCAP0\r\n"[:5]])
def test_replay_of_a_non_mcap_file_is_a_clear_error(spawn, tmp_path, content):
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(content)
    proc = spawn(bad, "--rate", "inf", "--wait", "0")
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 1 and "Traceback" not in err
    if content == b"\x89MCAP0\r\n"[:5]:  # a file cut inside the magic: nothing to replay, said so
        assert f"astrodyn replay: error: {bad}: nothing to replay (file ends inside the opening magic" in err
    else:
        assert f"astrodyn replay: error: {bad}: not an MCAP file" in err


@pytest.mark.slow  # CI time (9 s; the flag checks stay covered by test_file_tool_flags)
def test_replay_bad_arguments_name_the_option(spawn, recording):
    import socket

    path, _, _ = recording
    taken = socket.socket()  # a port another process listens on (before: zenoh's error, with its source paths)
    taken.bind(("127.0.0.1", 0))
    taken.listen()
    port = taken.getsockname()[1]
    cases = [(["--rate", "0"], "--rate: expected a real-time factor with 0.001 <= x <= 1e+06"),
             (["--rate", "1e-300"], "--rate: expected a real-time factor with 0.001"),
             (["--rate", "x"], "--rate: expected"),
             (["--start", "30", "--end", "10"], "end: expected end >= start, got start=30, end=10"),
             # past the recording (t 0 .. 50 s): said "end: expected end >= start" for --start 60 --end 70
             (["--start", "60", "--end", "70"], "start: t = 60 s is after the recording's end (it covers t = 0 .. 50 s)"),
             (["--start", "60"], "start: t = 60 s is after the recording's end (it covers t = 0 .. 50 s)"),
             (["--end", "-5"], "end: t = -5 s is before the recording's start (it covers t = 0 .. 50 s)"),
             (["--start", "nan"], "--start: expected a finite number"),
             (["--port", str(port)], f"--port: expected a free port on 127.0.0.1, got {port} (Address already in use)"),
             (["--port", "65536"], "--port: expected a port 0..65535 (0: a free one), got 65536"),
             (["--rate", "1e400"], "--rate: expected a real-time factor"),  # was: taken as inf
             (["--wait", "1e11"], "--wait: expected wall seconds 0 <= S <= 86400 (a day)"),  # was: 3000 years
             (["--control-scenario", ""], "--control-scenario: expected a name matching"),  # was: the recorded one
             (["--topics", "["], "--topics '[': matches no topic of"),  # was: nothing replayed, exit 0
             (["--zenoh-config", "/dev/zero"], "expected a regular file, got a character device")]
    with taken:
        for args, needle in cases:
            proc = spawn(path, "--wait", "0", *args)  # the case's own flags come last and win
            _, err = proc.communicate(timeout=30)
            assert proc.returncode == 2 and needle in err and "Traceback" not in err, (args, err)
