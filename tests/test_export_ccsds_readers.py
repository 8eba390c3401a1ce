"""CCSDS exports read by an independent reader: the ``ccsds-ndm`` package (not ours).

``ccsds-ndm`` reads OEM version 3 and AEM version 1 but not AEM version 2 (the default
export), so ``--format aem1`` exists for it.  Each number it reads back is compared with
the message payloads read by the plain ``mcap`` reader (JSON decoded here), to the last
bit for the quaternion components (written with the shortest round-trip repr) and to
1e-12 relative for the OEM's km / km/s (a division by 1000, one rounding).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

ccsds_ndm = pytest.importorskip("ccsds_ndm.ndm_io")

from astrodyn.recording.export import export  # noqa: E402 - after the importorskip: no reader, no test

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _recordings import leo_recording  # noqa: E402 - the tests/ helpers, importable once on sys.path


def _payloads(path: Path, suffix: str) -> list[dict]:
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        return [json.loads(m.data) for _, ch, m in make_reader(f).iter_messages() if ch.topic.endswith(suffix)]


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    base = tmp_path_factory.mktemp("ccsds")
    path = base / "c.mcap"
    leo_recording(path, name="c", duration="30 s", rate="1 Hz")
    return base, path


def test_aem_version_1_is_read_by_ccsds_ndm_with_every_quaternion_exact(recording):
    base, path = recording
    files = export(path, "aem1", base / "aem1")
    assert [f.name for f in files] == ["leo.aem"]
    aem = ccsds_ndm.NdmIo().from_path(files[0])
    seg = aem.body.segment[0]
    meta = seg.metadata
    assert (meta.object_name, meta.ref_frame_a, meta.ref_frame_b) == ("leo", "GCRF", "SC_BODY_1")
    assert meta.attitude_dir.value == "A2B" and meta.quaternion_type.value.startswith("LAST")
    recorded = _payloads(path, "/leo/attitude")
    states = seg.data.attitude_state
    assert len(states) == len(recorded) == 31
    for st, msg in zip(states, recorded):
        q = st.quaternion_state.quaternion
        assert [q.qc, q.q1, q.q2, q.q3] == msg["q"]  # scalar first in astrodyn, QC last on the line


def test_oem_is_read_by_ccsds_ndm(recording):
    base, path = recording
    files = {f.name: f for f in export(path, "oem", base / "oem")}
    oem = ccsds_ndm.NdmIo().from_path(files["leo.oem"])
    recorded = _payloads(path, "/leo/orbit")
    lines = oem.body.segment[0].data.state_vector
    assert len(lines) == len(recorded)
    got = np.array([[s.x.value, s.y.value, s.z.value, s.x_dot.value, s.y_dot.value, s.z_dot.value] for s in lines])
    want = np.array([m["r"] + m["v"] for m in recorded]) / 1e3
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=0)
