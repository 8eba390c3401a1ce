"""The progress line of ``astrodyn run`` (issue 17 section 2): it says why the simulated
time does not move while a propagator compiles, and it reports the time every propagator
has passed (the slowest one), from the heartbeats the processes send."""

from astrodyn.service.runner import progress_line


def test_a_compiling_propagator_is_named_and_the_slowest_time_is_shown():
    last = {"orbit": {"t": 120.0, "step": 121}, "attitude": {"t": 0.0, "step": 0, "preparing": True},
            "logger": {"messages": 242, "t": 120.0}}
    line = progress_line(last, ["orbit", "attitude"], 5580.0, 1.0, 0)
    assert "sim t        0.0 / 5580.0 s" in line and "logged       242" in line
    assert "[attitude: loading numeric kernels (compiled on the first run only" in line and "orbit" not in line.split("[")[1]


def test_once_every_propagator_publishes_the_line_moves_and_the_note_goes():
    last = {"orbit": {"t": 130.0}, "attitude": {"t": 125.0}, "logger": {"messages": 510}}
    line = progress_line(last, ["orbit", "attitude"], 5580.0, 2.0, 410)
    assert "sim t      125.0 / 5580.0 s" in line and "(  2.2 %)" in line and "50 msg/s" in line
    assert "numeric kernels" not in line


def test_a_propagator_not_heard_from_yet_counts_as_compiling():
    line = progress_line({"logger": {"messages": 0}}, ["orbit"], 60.0, 0.5, 0)
    assert "[orbit: loading numeric kernels" in line and "sim t        0.0" in line


def test_a_busy_propagator_says_what_it_computes_not_that_it_loads_kernels():
    """A restarted cross-check integrating REBOUND again from t = 0 beats with ``busy`` and
    ``preparing`` (horizons probe F6: the line said "loading numeric kernels" for minutes)."""
    busy = {"what": "orbit: cross-check: REBOUND integrates again from t = 0 to the restart step",
            "t": 1.5e8, "to": 4.0e9}
    last = {"orbit": {"t": 0.0, "preparing": True, "busy": busy}, "attitude": {"t": 10.0}}
    line = progress_line(last, ["orbit", "attitude"], 7.9e9, 1.0, 0)
    assert "loading numeric kernels" not in line
    assert "[orbit: cross-check: REBOUND integrates again from t = 0 to the restart step: " \
           "sim t 1.5e+08 of 4e+09 s]" in line
