"""serve's logger restart reads only the tail of the dead logger's file
(:func:`astrodyn.recording.tail.channel_tails`, :func:`astrodyn.service.resume.tail_resume_point`).

Reference: the full reader's answer on the same bytes -- :func:`astrodyn.recording.load`
with :func:`astrodyn.service.resume.last_common_step` and :func:`states_at`, the path
``run --resume`` uses -- for the complete file and for prefixes cut at random offsets
(what a SIGKILLed logger leaves)."""

from __future__ import annotations

import json
import random
import sys
from pathlib import Path

import pytest

from astrodyn.recording import load
from astrodyn.recording.tail import channel_tails
from astrodyn.service.resume import last_common_step, state_topics, states_at, tail_resume_point
from astrodyn.service.supervision import part_number, plan_part_restart

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _recordings import leo_recording


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    path = tmp_path_factory.mktemp("tail") / "rp.mcap"
    sc, _ = leo_recording(path, duration="120 s", rate="4 Hz")
    return path, sc


def _state_topic(topic: str) -> bool:
    return topic.endswith(("/orbit", "/attitude", "/crosscheck"))


def test_the_tail_resume_point_is_the_full_readers(recording, tmp_path):
    path, sc = recording
    data = path.read_bytes()
    rng = random.Random(5)
    cuts = [len(data), *sorted(rng.randrange(200, len(data)) for _ in range(25))]
    checked = 0
    for cut in cuts:
        cut_path = tmp_path / "cut.mcap"
        cut_path.write_bytes(data[:cut])
        run = load(cut_path)
        tails = channel_tails(cut_path, _state_topic)
        for kind in ("orbit", "attitude"):
            topics = list(state_topics(sc, kind).values())
            step = last_common_step(run, topics)
            point = tail_resume_point(tails, sc, kind)
            if step is None:
                assert point is None, (cut, kind)
                continue
            assert point is not None and point[0] == step, (cut, kind, point and point[0], step)
            t, states = states_at(run, sc, kind, step)
            assert (point[1], point[2]) == (t, states), (cut, kind)
            checked += 1
    assert checked > 20


def test_a_hostile_tail_is_never_a_state_to_continue_from(recording, tmp_path):
    """Payloads that are not valid states of their channel (NaN text, a wrong type) are
    skipped: the resume point is the last step with valid states, or none."""
    path, sc = recording
    tails = channel_tails(path, _state_topic)
    topic = next(iter(state_topics(sc, "orbit").values()))
    good = tail_resume_point(tails, sc, "orbit")
    assert good is not None
    tails[topic] = [b'{"t":NaN}', b"\xff\xfe", b"[]"] + tails[topic][:-1]
    point = tail_resume_point(tails, sc, "orbit")
    assert point is not None and point[0] == good[0] - 1
    tails[topic] = [b"{}"]
    assert tail_resume_point(tails, sc, "orbit") is None


def test_a_part_restart_plans_the_next_part_and_seeds_every_state_channel(recording, tmp_path):

    path, sc = recording
    dead = tmp_path / "served.partial.mcap"
    dead.write_bytes(path.read_bytes()[: path.stat().st_size * 2 // 3])
    run = load(dead)
    plan = plan_part_restart(sc, tmp_path / "served.mcap", str(dead), [], ["orbit", "attitude"], 1, tmp_path)
    assert plan.part == 1 and plan.final == str(tmp_path / "served.mcap")
    seeds = json.loads(Path(plan.logger_args[plan.logger_args.index("--resume-seqs") + 1]).read_text())
    assert seeds == {topic: int(track.seq.max()) + 1 for topic, track in run.channels.items() if _state_topic(topic)}
    for kind in ("orbit", "attitude"):
        step = last_common_step(run, list(state_topics(sc, kind).values()))
        assert plan.propagator_args[kind]["--start-step"] == step + 1
    assert part_number(str(tmp_path / "served-0007.partial-3.mcap"), tmp_path / "served.mcap") == 7
    child = plan.finish_in_background(tmp_path)
    assert child.proc.wait(timeout=120) == 0, child.stderr_tail()
    child.close()
    assert not dead.exists() and load(tmp_path / "served.mcap").messages == run.messages


@pytest.mark.parametrize("content, says", [
    (None, "FileNotFoundError"), ("{{{", "JSONDecodeError"), ("[1, 2]", "expected a JSON object"),
    ('{"astrodyn/x/sat/orbit": -1}', "expected an integer seq"), ('{"astrodyn/x/sat/orbit": true}', "expected an integer seq"),
    ('{"astrodyn/x/sat/nokind": 3}', "key: expected"), ("[" * 100000, "RecursionError"),
])
def test_a_hostile_resume_seqs_file_is_refused_before_anything_is_written(tmp_path, content, says):
    import subprocess

    seeds = tmp_path / "seeds.json"
    if content is not None:
        seeds.write_text(content)
    out = tmp_path / "z.mcap"
    proc = subprocess.run([sys.executable, "-m", "astrodyn.service.logger", "--scenario", "x", "--out", str(out),
                           "--epoch-ns", "0", "--resume-seqs", str(seeds)], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2 and "--resume-seqs" in proc.stderr and says in proc.stderr, proc.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == (["seeds.json"] if content is not None else [])


def test_serve_finds_only_its_own_logger_parts(tmp_path):
    """The files serve restarts from are the ones its loggers reported creating, newest
    first, followed by identity (st_dev, st_ino) through a rename; never a file that only
    has the name of a part: another user's serve recording ``served-0002.partial.mcap`` in
    the same directory (serve took such a file for its dead logger's, resumed from it and
    recorded another config's states: crossing probe, session 16), a standby logger's file,
    or a file put where a reported one was."""
    import os

    from astrodyn.service.supervision import LoggerFiles

    def make(name: str) -> Path:
        (tmp_path / name).write_text("x")
        return tmp_path / name

    report = tmp_path / "own-files"
    own = [make("served.partial.mcap"), make("served-0001.partial.mcap")]
    with open(report, "w") as f:
        for path in own:
            st = os.stat(path)
            f.write(json.dumps({"file": str(path), "dev": st.st_dev, "ino": st.st_ino}) + "\n")
    for name in ("served-0002.partial.mcap", "served.logger-2.partial.mcap", "served-0003.mcap"):
        make(name)  # named like parts, not reported: another recorder's
    files = LoggerFiles(report)
    assert [where for _, where in files.newest_first()] == [str(own[1]), str(own[0])]
    os.rename(own[0], tmp_path / "served.mcap")  # the first part finished: followed by identity
    assert [where for _, where in files.newest_first()] == [str(own[1]), str(tmp_path / "served.mcap")]
    assert files.owns(tmp_path / "served-0002.partial.mcap") is None
    assert files.owns(tmp_path / "served.mcap") is not None
    os.unlink(own[1])  # held open by `files`: its inode number cannot be reused meanwhile
    make("served-0001.partial.mcap")  # another file where a reported one was: not the logger's
    assert [where for _, where in files.newest_first()] == [str(tmp_path / "served.mcap")]
    assert files.owns(tmp_path / "served-0001.partial.mcap") is None
    files.close()


@pytest.mark.parametrize("channel, says", [
    ("astrodyn/x/sat/orbit#orbit", "only an event key takes a #process"),
    ("astrodyn/x/@event#bad name", "the process: expected a name"),
    ("astrodyn/x/@event#", "the process: expected a name"),
])
def test_a_resume_seqs_entry_for_an_event_channel_names_an_event_key_and_a_process(tmp_path, channel, says):
    from astrodyn.service.logger import read_seed_table

    seeds = tmp_path / "seeds.json"
    seeds.write_text(json.dumps({"astrodyn/x/@event#orbit": 4, channel: 3}))
    with pytest.raises(ValueError, match="--resume-seqs") as refused:
        read_seed_table(str(seeds))
    assert says in str(refused.value)
    seeds.write_text(json.dumps({"astrodyn/x/@event#orbit": 4, "astrodyn/x/@event#logger": 0}))
    assert read_seed_table(str(seeds)) == {"astrodyn/x/@event#orbit": 4, "astrodyn/x/@event#logger": 0}
