"""The propagators' batched path (envelope entries written by the compiled encoders) end to end.

A 100-body Walker constellation (above propagator.BATCH_THRESHOLD = 64, so every step goes
out as one envelope per process) runs headless with ``--cross-check`` (cross-check pairs
join the same envelope through ``messages.frame_entries``).  The references are
independent of the compiled encoders: the logger's own accounting (every planned state
recorded, nothing missing or duplicated) and, for every payload in the MCAP, Python's
``json`` + ``repr`` re-encoding of the decoded message (``encode(decode(p)) == p``).
"""

import json
import subprocess
import sys
from pathlib import Path

import pytest

from astrodyn import messages
from astrodyn.scenario import load, plan
from astrodyn.service.propagator import BATCH_THRESHOLD

ROOT = Path(__file__).resolve().parents[1]

pytestmark = pytest.mark.network


@pytest.mark.slow  # CI time (9 s; the batch encoders stay checked field by field by test_encode_single and the batch tests)
def test_batched_constellation_payloads_are_canonical_and_complete(tmp_path):
    text = (ROOT / "configs" / "constellation-1000.toml").read_text()
    for old, new in (('name = "constellation-1000"', 'name = "c100"'), ("t = 1000", "t = 100"), ("p = 20", "p = 5"),
                     ('duration = "2 min"', 'duration = "2 s"')):
        assert old in text
        text = text.replace(old, new)
    config = tmp_path / "c100.toml"
    config.write_text(text)
    scn = load(config)
    assert len(scn.bodies) == 100 > BATCH_THRESHOLD
    out, res = tmp_path / "run.mcap", tmp_path / "result.json"
    proc = subprocess.run([sys.executable, "-m", "astrodyn", "run", str(config), "--out", str(out), "--quiet",
                           "--cross-check", "--json", str(res), "--timeout", "300"],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    logger = json.loads(res.read_text())["logger"]
    steps = plan(scn).n_steps
    assert logger["states"] == logger["expected_states"] == 3 * 100 * steps  # orbit, attitude, crosscheck
    assert logger["complete"]
    assert logger["missing"] == 0 and logger["malformed"] == 0 and logger["duplicates"] == 0
    assert logger["received"] < logger["messages"] / 50  # envelopes, not one sample per message

    from mcap.reader import make_reader

    counts = {}
    with open(out, "rb") as f:
        for _, channel, message in make_reader(f).iter_messages():
            kind = messages.kind_of_key(channel.topic)
            if kind in ("orbit", "attitude", "crosscheck"):
                assert messages.encode(messages.decode(message.data, kind)) == message.data
                counts[kind] = counts.get(kind, 0) + 1
    assert counts == {"orbit": 100 * steps, "attitude": 100 * steps, "crosscheck": 100 * steps}
