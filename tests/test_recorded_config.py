"""One answer to "is this recording of this config?" (:mod:`astrodyn.scenario.recorded`).

``run --resume``, ``run --commands`` and serve's restart from its rolled parts
(:func:`astrodyn.service.supervision.holds_config`) all ask
:func:`~astrodyn.scenario.recorded.config_difference`.  The spec (docs/reliability.md,
the crossing-serves row: "compared as ``run --resume`` does"): the same config read from
another path (a copy) is the same config; another rate is another config, and the refusal
names the key as the TOML writes it (``scenario.rate``) with both values.  Before, serve's
check compared the metadata's JSON whole, so a copy of the config (whose ``source`` path
differs) was taken for another config.
"""

from __future__ import annotations

import sys
from pathlib import Path

from astrodyn.scenario import load
from astrodyn.scenario.recorded import config_difference
from astrodyn.service.supervision import holds_config

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _recordings import LEO_TWO_BODIES, record

CONFIGS = Path(__file__).resolve().parents[1] / "configs"


def _copies(tmp_path: Path, name: str, text: str) -> tuple[Path, Path]:
    """``text`` written as ``name`` into two directories of ``tmp_path``."""
    paths = []
    for where in ("first", "second"):
        (tmp_path / where).mkdir()
        paths.append(tmp_path / where / name)
        paths[-1].write_text(text)
    return paths[0], paths[1]


def test_the_same_config_from_two_paths_is_the_same_config_and_another_rate_is_named(tmp_path):
    original = CONFIGS / "demo.toml"
    text = original.read_text()
    first, second = _copies(tmp_path, original.name, text)
    a, b = load(first), load(second)
    assert a.source != b.source  # the copies are named differently, their text is one
    assert config_difference(a.to_metadata(), b) is None
    assert config_difference(b.to_metadata(), a) is None
    assert config_difference(load(original).to_metadata(), a) is None

    assert 'rate = "1 Hz"' in text  # demo.toml's rate, as written
    faster = tmp_path / "faster.toml"
    faster.write_text(text.replace('rate = "1 Hz"', 'rate = "2 Hz"', 1))
    problem = config_difference(a.to_metadata(), load(faster))
    assert problem is not None
    assert 'scenario.rate is "2 Hz" here, "1 Hz" in the recording' in problem, problem


def test_holds_config_takes_a_copy_of_the_config_and_refuses_another_rate(tmp_path):
    text = LEO_TWO_BODIES.format(name="held", duration="4 s", rate="1 Hz")
    recording = tmp_path / "held.mcap"
    recorded, _ = record(recording, text)  # its scenario record names the config's source "<string>"
    first, second = _copies(tmp_path, "held.toml", text)
    for path in (first, second):
        sc = load(path)
        assert sc.source != recorded.source
        assert holds_config(recording, sc), path

    other_rate = tmp_path / "other-rate.toml"
    other_rate.write_text(LEO_TWO_BODIES.format(name="held", duration="4 s", rate="2 Hz"))
    assert not holds_config(recording, load(other_rate))
    other_name = tmp_path / "other-name.toml"
    other_name.write_text(LEO_TWO_BODIES.format(name="other", duration="4 s", rate="1 Hz"))
    assert not holds_config(recording, load(other_name))


def test_where_a_config_records_is_not_what_it_simulates(tmp_path):
    """A relative ``[output] path`` resolves against the config's directory, and a config may
    name another file or rolling: none of that changes what is simulated."""
    text = (CONFIGS / "demo.toml").read_text()
    first, second = _copies(tmp_path, "demo.toml", text + '\n[output]\npath = "out/here.mcap"\n')
    a, b = load(first), load(second)
    assert a.output_path != b.output_path  # resolved against two directories
    assert config_difference(a.to_metadata(), b) is None
    other = tmp_path / "other-output.toml"
    other.write_text(text + '\n[output]\npath = "elsewhere.mcap"\nroll_size = "64 MB"\n')
    assert config_difference(a.to_metadata(), load(other)) is None
