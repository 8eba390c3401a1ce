"""Propagators whose blocks take long: output steps far apart (docs/reliability.md, hung processes).

* A propagator's heartbeat goes out every 0.5 s also while it computes (REBOUND cross-check, a J2
  orbit, gravity-gradient attitude): an engine call spans a bounded amount of work (output steps
  further apart are integrated through waypoints), REBOUND beats between its parts.  Before, nothing
  was sent while a block was computed, so a supervisor killed a busy propagator as hung (probe F6).
* ``propagate_perturbed``'s ``max_steps`` applies per revolution / output interval, not to the whole
  span: a J2 orbit at a long output spacing no longer dies of it (probe F7).

The results are checked against independent facts: the J2 energy and z angular momentum, and
REBOUND IAS15 (the cross-check's own differences, and a REBOUND J2 twin).
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

SCENE = "busy"

# One cross-checked LEO (REBOUND: ~17 revolutions per output step), a J2 Molniya (DOP853: ~2.3
# revolutions per step) and a gravity-gradient boom (splitting: ~2800 steps per output step), 1e5 s
# apart; in blocks of 60 steps one block took 2.5-3 s (unloaded) of computing without a heartbeat before.
CONFIG = """
[scenario]
name = "busy"
epoch = "2026-03-20T00:00:00 UTC"
duration = "1.19e7 s"
rate = "1e-5 Hz"

[central_body]
name = "earth"

[[bodies]]
name = "leo"
cross_check = true
[bodies.orbit]
a = "7000 km"
e = 0.001
i = "51 deg"
nu = "0 deg"

[[bodies]]
name = "molniya"
[bodies.orbit]
a = "26600 km"
e = 0.74
i = "63.4 deg"
raan = "0 deg"
argp = "270 deg"
M = "0 deg"
model = "j2"

[[bodies]]
name = "gg-boom"
[bodies.orbit]
r = ["6878.137 km", "0 km", "0 km"]
v = [0.0, 4727.787690, 5966.993497]
[bodies.attitude]
q = [0.6772827812781391, -0.20319457223102283, -0.6569959419530261, 0.2614504393900611]
w = ["3e-3 rad/s", "-1.1067834e-3 rad/s", "1e-3 rad/s"]
inertia = ["150 kg m2", "140 kg m2", "20 kg m2"]
model = "gravity_gradient"
"""


def _j2_invariants(r: np.ndarray, v: np.ndarray, mu: float, j2: float, radius: float):
    """Energy per unit mass with the J2 potential, and h_z (both conserved by the J2 problem)."""
    rn = np.linalg.norm(r, axis=-1)
    z2 = (r[..., 2] / rn) ** 2
    energy = 0.5 * np.einsum("...i,...i->...", v, v) - mu / rn + mu * j2 * radius**2 / (2 * rn**3) * (3 * z2 - 1)
    hz = r[..., 0] * v[..., 1] - r[..., 1] * v[..., 0]
    return energy, hz


def test_busy_propagators_beat_while_they_compute_and_their_results_hold(tmp_path, hub):
    """The orbit and attitude propagators run against the test's bus (a stand-in logger token),
    in blocks of 60 output steps 1e5 s apart: after their first state, no heartbeat gap exceeds
    1.5 s (before: 2.5-3 s unloaded, the whole block); the J2 orbit keeps its energy and h_z, and
    REBOUND agrees with the cross-checked Kepler orbit to < 1 m after 138 days."""
    from astrodyn import bus, messages
    from astrodyn.scenario import load

    session, endpoint = hub
    cfg = tmp_path / "busy.toml"
    cfg.write_text(CONFIG)
    scenario = load(cfg)
    beats: dict[str, list] = {"orbit": [], "attitude": []}
    states: dict[str, list] = {"molniya": [], "leo-x": []}

    def on_beat(sample):
        body = json.loads(sample.payload.to_bytes())
        beats[body["process"]].append((time.monotonic(), body))

    def on_state(name):
        return lambda sample: states[name].append(json.loads(sample.payload.to_bytes()))

    def on_status(query):  # the stand-in logger holds everything: the propagators end without waiting
        query.reply(messages.status_key(SCENE), json.dumps({"ended": {"orbit": {}, "attitude": {}}}))

    with bus.declare_alive(session, SCENE, "logger"), \
            session.declare_queryable(messages.status_key(SCENE), on_status), \
            session.declare_subscriber(bus.heartbeat_key(SCENE, "x").rsplit("/", 1)[0] + "/*", on_beat), \
            session.declare_subscriber(messages.orbit_key(SCENE, "molniya"), on_state("molniya")), \
            session.declare_subscriber(messages.crosscheck_key(SCENE, "leo"), on_state("leo-x")):
        procs = {kind: subprocess.Popen([sys.executable, "-m", "astrodyn.service.propagator", kind, str(cfg),
                                         "--connect", endpoint, "--block", "60"],
                                        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
                 for kind in ("orbit", "attitude")}
        try:
            outs = {kind: p.communicate(timeout=240) for kind, p in procs.items()}
        finally:
            for p in procs.values():
                if p.poll() is None:
                    p.kill()
        time.sleep(0.3)  # the last samples in flight
    for kind, p in procs.items():
        assert p.returncode == 0, outs[kind][1][-2000:]
        summary = json.loads(outs[kind][0].strip().splitlines()[-1])
        assert summary["steps"] == scenario.n_steps == 120
        # from its first heartbeat after the numeric kernels are loaded to its last one
        first = next(i for i, (_, b) in enumerate(beats[kind]) if not b.get("preparing"))
        gaps = np.diff([t for t, _ in beats[kind][first:]])
        assert gaps.size >= 2 and gaps.max() < 1.5, \
            f"{kind}: heartbeat gaps of up to {gaps.max():.2f} s while it computed: {np.round(gaps, 2).tolist()}"
    # the J2 orbit, integrated through waypoints: its two conserved quantities
    cb = scenario.central_body
    mol = sorted(states["molniya"], key=lambda m: m["seq"])
    assert [m["seq"] for m in mol] == list(range(120))
    r, v = np.array([m["r"] for m in mol]), np.array([m["v"] for m in mol])
    energy, hz = _j2_invariants(r, v, cb.mu, cb.J[0], cb.radius)
    assert np.max(np.abs(energy - energy[0])) / abs(energy[0]) < 1e-8
    assert np.max(np.abs(hz - hz[0])) / np.linalg.norm(np.cross(r[0], v[0])) < 1e-8
    # REBOUND, advanced in parts with heartbeats between: still the independent Kepler reference
    xc = sorted(states["leo-x"], key=lambda m: m["seq"])
    assert [m["seq"] for m in xc] == list(range(120))
    assert max(m["dr_norm"] for m in xc) < 1.0


def test_a_long_j2_span_is_not_refused_by_max_steps():
    """One output 3e5 s (52 LEO revolutions, ~2500 DOP853 steps) after the epoch with
    max_steps=200: the cap holds per revolution now (before: RuntimeError after 200 steps of the
    whole span); the state keeps the J2 energy and h_z and agrees with REBOUND's J2 twin; a
    collapsing step size (5 steps per revolution) is still caught."""
    from astrodyn.crosscheck import ReboundScene
    from astrodyn.orbit.perturbations import EARTH_WGS84 as EARTH, propagate_perturbed

    mu, j2, re = EARTH.mu, EARTH.J[0], EARTH.radius
    r0 = np.array([7000e3, 0.0, 0.0])
    vc = math.sqrt(mu / 7000e3)
    v0 = np.array([0.0, vc * math.cos(0.9), vc * math.sin(0.9)])
    out = propagate_perturbed(r0, v0, 3e5, mu, EARTH.zonal(2), rtol=1e-12, atol=1e-14,
                              error_estimate=False, max_steps=200)
    assert out.nsteps > 2000
    e0, hz0 = _j2_invariants(r0, v0, mu, j2, re)
    e1, hz1 = _j2_invariants(out.r, out.v, mu, j2, re)
    assert abs(e1 - e0) / abs(e0) < 1e-10 and abs(hz1 - hz0) / abs(hz0) < 1e-10
    ref = ReboundScene(r0, v0, mu, model="j2", j2=j2, body_radius=re)
    r_reb, _ = ref.advance_to(3e5)
    assert np.linalg.norm(out.r - r_reb[0]) < 1.0
    with pytest.raises(RuntimeError, match="max_steps=5 .*within one revolution"):
        propagate_perturbed(r0, v0, 3e5, mu, EARTH.zonal(2), max_steps=5)


@pytest.mark.slow
def test_a_cross_checked_run_with_blocks_longer_than_the_stall_timeout_ends_without_a_restart(tmp_path):
    """`astrodyn run` of the scene above for 1600 steps, in 1000-step blocks (20-50 s of computing
    each) with --stall-timeout 8: no process is taken for hung (before: killed as stalled in its
    second block, which is no longer under the start-up allowance), the run ends 0 with every state."""
    from astrodyn.recording import load as load_run

    cfg = tmp_path / "busy.toml"
    cfg.write_text(CONFIG.replace('duration = "1.19e7 s"', 'duration = "1.599e8 s"'))
    out = tmp_path / "busy.mcap"
    astrodyn = Path(sys.executable).with_name("astrodyn")
    p = subprocess.run([str(astrodyn), "run", str(cfg), "--out", str(out), "--stall-timeout", "8", "--timeout", "600"],
                       capture_output=True, text=True, timeout=700)
    assert p.returncode == 0, p.stderr[-3000:]
    assert "stalled" not in p.stderr and "restarted" not in p.stderr, p.stderr[-3000:]
    run = load_run(out)
    assert all(len(b.orbit) == 1600 for b in run.bodies.values() if b.orbit is not None)
