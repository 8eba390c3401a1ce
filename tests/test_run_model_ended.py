"""``run`` does not restart a propagator whose model ended (exit status MODEL_ENDED_EXIT: a
rolling disk that fell flat would fall there again), whichever of it and the logger the
supervisor sees exit first; any other death is handed to the restart logic.

Found under load: the runner saw the attitude process exit with status 4 before the
logger's own exit, restarted it, and the new one waited 30 s for a logger that had
already finished ("process 'logger' ... not alive after 30.0 s") instead of the run
failing with the disk's name and time."""

from types import SimpleNamespace

from astrodyn.service import runner
from astrodyn.service.children import MODEL_ENDED_EXIT, Child

TAIL = "attitude: model ended: coin: the rolling disk lies flat (|lean| = 90 deg) at t = 0.0437 s"


class FakeChild:
    how = Child.how  # the real wording of an exit
    kill_if_stalled = Child.kill_if_stalled
    outside_stop_signal = Child.outside_stop_signal  # (from its summary line: these print none)

    def __init__(self, pid: int, rc: int | None):
        self.pid, self.rc = pid, rc
        self.stalled_s = None
        self.lost_to_logger = None
        self.asked_to_stop, self._exit_reason = False, None

    def summary(self) -> dict | None:
        return None

    def poll(self) -> int | None:
        return self.rc

    def kill_if_lost_to_logger(self, beats, holes: bool = True) -> bool:
        return False  # (these tests give the logger nothing to report)

    def ended_cut_off_from_logger(self, beats) -> bool:
        return False

    def last_words(self, n: int = 3) -> str:
        return TAIL


def _watch(attitude_rc: int):
    scenario = SimpleNamespace(control=None, n_steps=251, rate=50.0)
    plan = SimpleNamespace(bodies=[SimpleNamespace(name="coin", orbit_model=None, attitude_model="rolling_disk")])
    children = {"logger": FakeChild(101, None), "attitude": FakeChild(102, attitude_rc)}  # the logger still runs
    beats = SimpleNamespace(poll=lambda: None, last={"attitude": {"t": 0.04}})
    alive = SimpleNamespace(poll=lambda: None)
    handed = []

    def on_death(name, rc):
        handed.append((name, rc))
        return f"{name}: not restarted in this test"

    failure = runner._watch(scenario, plan, children, beats, alive, False, 10.0, on_death=on_death)
    return failure, handed


def test_a_propagator_whose_model_ended_is_not_restarted():
    failure, handed = _watch(MODEL_ENDED_EXIT)
    assert handed == []
    assert failure == (f"process attitude (pid 102) exited with status {MODEL_ENDED_EXIT} (bodies: coin), "
                       f"sim t reached 0.04 s of 5 s: {TAIL}")


def test_any_other_death_of_a_propagator_goes_to_the_restart_logic():
    failure, handed = _watch(1)
    assert handed == [("attitude", 1)]
    assert failure == "attitude: not restarted in this test"
