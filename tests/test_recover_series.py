"""``astrodyn recover NAME.mcap`` after a killed ``serve`` that rolled parts (probe A, F7).

A killed serve leaves its finished parts (``NAME.mcap``, ``NAME-0001.mcap``, ...) and its
last part partial (``NAME-000k.partial.mcap``).  ``recover NAME.mcap`` -- the --out path, as
its help says to give -- rewrote the finished first part in place and left the partial part
as it was, exit 0.  Now it finishes the series' partial parts and leaves a complete file
byte for byte; a complete file given alone is left as it is unless --out is given.

The files are written with the ``mcap`` package's writer; a partial part is a complete file
cut short, as a killed logger leaves it.  What must come out is the messages the writer put
in (read back with the plain ``mcap`` reader).
"""

from __future__ import annotations

import io
import json

from mcap.reader import make_reader
from mcap.writer import Writer

from astrodyn.recording.recover import is_complete, main as recover_main


def _recording(first: int, n: int = 30) -> bytes:
    buf = io.BytesIO()
    w = Writer(buf, chunk_size=200)
    w.start("x", "test")
    schema = w.register_schema("s", "jsonschema", b"{}")
    channel = w.register_channel("astrodyn/t/a/orbit", "json", schema)
    for i in range(first, first + n):
        w.add_message(channel, i, b'{"t":%d.0,"seq":%d}' % (i, i), i)
    w.finish()
    return buf.getvalue()


def _seqs(path) -> list[int]:
    with open(path, "rb") as f:
        return [json.loads(m.data)["seq"] for _, _, m in make_reader(f).iter_messages()]


def test_recover_of_the_out_path_finishes_the_series_partial_part_and_leaves_the_finished_ones(tmp_path, capsys):
    parts = {"t.mcap": _recording(0), "t-0001.mcap": _recording(30)}
    for name, data in parts.items():
        (tmp_path / name).write_bytes(data)
    cut = _recording(60)
    (tmp_path / "t-0002.partial.mcap").write_bytes(cut[:len(cut) * 2 // 3])  # a killed logger's part
    assert recover_main([str(tmp_path / "t.mcap")]) == 0
    for name, data in parts.items():
        assert (tmp_path / name).read_bytes() == data  # the finished parts untouched
    assert not (tmp_path / "t-0002.partial.mcap").exists() and is_complete(str(tmp_path / "t-0002.mcap"))
    got = _seqs(tmp_path / "t-0002.mcap")
    assert got == list(range(60, 60 + len(got))) and len(got) > 0  # what the cut file held, in order
    lines = [json.loads(x) for x in capsys.readouterr().out.splitlines()]
    assert [x.get("source") for x in lines] == [str(tmp_path / "t-0002.partial.mcap")]


def test_a_complete_file_is_left_as_it_is_unless_out_is_given(tmp_path, capsys):
    data = _recording(0)
    (tmp_path / "done.mcap").write_bytes(data)
    assert recover_main([str(tmp_path / "done.mcap")]) == 0
    assert (tmp_path / "done.mcap").read_bytes() == data
    assert json.loads(capsys.readouterr().out.splitlines()[0])["nothing_done"].startswith("the file is complete")
    assert recover_main([str(tmp_path / "done.mcap"), "--out", str(tmp_path / "again.mcap")]) == 0
    assert _seqs(tmp_path / "again.mcap") == list(range(30))


def test_a_cut_file_of_another_writer_is_still_finished_in_place(tmp_path):
    data = _recording(0)
    (tmp_path / "foreign.mcap").write_bytes(data[:len(data) // 2])
    assert recover_main([str(tmp_path / "foreign.mcap")]) == 0
    assert is_complete(str(tmp_path / "foreign.mcap"))
    got = _seqs(tmp_path / "foreign.mcap")
    assert got == list(range(len(got))) and len(got) > 0
