"""A UTF-8 byte order mark at the start of a config or a cases CSV (Windows editors and
spreadsheets write one) is not part of the text: the file reads as the same text without
it.  Before, the config failed ("Invalid statement (at line 1, column 1)") and the CSV's first
column was named "\\ufeffbodies..." (an unknown key)."""

from __future__ import annotations

from pathlib import Path

from astrodyn.scenario import load
from astrodyn.sweep import read_cases_csv

BOM = b"\xef\xbb\xbf"
DEMO = Path(__file__).resolve().parents[1] / "configs" / "demo.toml"


def test_a_config_with_a_byte_order_mark_is_the_same_config(tmp_path):
    (tmp_path / "plain").mkdir()
    (tmp_path / "marked").mkdir()
    plain, marked = tmp_path / "plain" / "demo.toml", tmp_path / "marked" / "demo.toml"
    plain.write_bytes(DEMO.read_bytes())
    marked.write_bytes(BOM + DEMO.read_bytes())
    ours, theirs = load(marked).to_dict(), load(plain).to_dict()
    assert ours.pop("source") != theirs.pop("source")  # two paths, one text
    assert ours == theirs


def test_a_cases_csv_with_a_byte_order_mark_has_the_same_columns(tmp_path):
    text = "bodies.iss.orbit.e,bodies.iss.orbit.i\n0.001,0.9\n0.002,0.91\n"
    plain, marked = tmp_path / "plain.csv", tmp_path / "marked.csv"
    plain.write_text(text)
    marked.write_bytes(BOM + text.encode())
    assert read_cases_csv(marked) == read_cases_csv(plain)
    assert read_cases_csv(marked)[0][0] == "bodies.iss.orbit.e"
