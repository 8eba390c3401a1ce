"""One schedule for every process of a scene after a rate change or a resume
(:meth:`Pacer.set_factor` / :meth:`Pacer.resume` with the supervisor's ``anchor``).

At ``rate inf`` each propagator runs as fast as it can, so orbit and attitude drift apart
(hours of sim time after seconds); when the rate became finite again each paced from its own
sim time, and the bus carried a scene whose channels stayed hours apart for good.  With the
anchor ``(wall, t)`` the schedule is ``t + factor * (now - wall)`` for all: a process behind it
has nothing to wait for until it is back on it; one on it waits as ``factor`` says."""

from __future__ import annotations

import time

import pytest

from astrodyn.service.propagator import Pacer, command_anchor


def test_a_process_behind_the_anchor_runs_until_it_is_on_the_schedule_then_paces():
    behind, ahead = Pacer(10.0), Pacer(10.0)
    now = time.monotonic()
    for pacer, own_t in ((behind, 100.0), (ahead, 1000.0)):
        pacer.set_factor(10.0, own_t, anchor=(now, 1000.0))
    assert behind.wait_time(100.0) == 0.0 and behind.wait_time(999.0) == 0.0  # catching up: no wait
    # on the schedule: sim t 1010 is due 1 s after the anchor's wall time (10 sim s per wall s)
    for pacer in (behind, ahead):
        assert 0.9 < pacer.wait_time(1010.0) <= 1.0
    # without an anchor a process paces from its own t: 110 due 1 s from now, 100 s of sim behind
    own = Pacer(10.0)
    own.set_factor(10.0, 100.0)
    assert 0.9 < own.wait_time(110.0) <= 1.0


def test_resume_takes_the_anchor_too():
    pacer = Pacer(5.0)
    pacer.pause()
    now = time.monotonic()
    pacer.resume(0.0, anchor=(now - 2.0, 50.0))  # the schedule says 60 is due now
    assert not pacer.paused and pacer.wait_time(59.0) == 0.0 and 0.9 < pacer.wait_time(65.0) <= 1.0


@pytest.mark.parametrize("anchor", [[1.0], [1.0, 2.0, 3.0], "1,2", [1.0, float("nan")], [1.0, "2"], [True, 2.0],
                                    {"wall": 1.0}])
def test_a_malformed_anchor_is_refused(anchor):
    with pytest.raises(ValueError, match=r"^anchor: expected \[wall s, sim t s\]"):
        command_anchor({"verb": "rate", "factor": 10, "anchor": anchor})


def test_no_anchor_is_none_and_a_good_one_is_two_floats():
    assert command_anchor({"verb": "rate", "factor": 10}) is None
    assert command_anchor({"verb": "resume", "anchor": [12, 3.5]}) == (12.0, 3.5)


def test_a_process_ahead_of_the_anchor_goes_on_from_its_own_time_without_waiting():
    """The supervisor's sim t comes from heartbeats (up to half a second old): a process
    that ran on past it paces from its own t, never waits for the schedule to reach it."""
    pacer = Pacer(10.0)
    pacer.set_factor(10.0, 5000.0, anchor=(time.monotonic(), 1000.0))
    assert 0.9 < pacer.wait_time(5010.0) <= 1.0  # from its own 5000, not 400 s later
