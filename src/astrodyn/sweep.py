"""``astrodyn sweep``: Monte Carlo dispersions and parameter sweeps of a scenario, on Dask.

    astrodyn sweep configs/leo.toml --vary 'bodies.sat1.orbit.e=uniform(0.1, 0.9)' \\
        --vary 'bodies.sat1.attitude.w=normal([0, 0, 0.1], 0.01)' -n 1000 --seed 7 --out sweep-leo

Each *case* is the scenario with some config values replaced by draws.  A case is run
headless in one process with the numeric core (:func:`astrodyn.simulate.simulate`, no
Zenoh), reduced to one row of summary metrics, and optionally recorded as its own MCAP.
Cases run on **Dask distributed**: a ``LocalCluster`` of ``--workers`` processes (default
2, one thread each) on this machine, or any running Dask scheduler given with
``--scheduler tcp://HOST:8786`` (reached with dask-jobqueue, dask-kubernetes, ``dask
scheduler`` + ``dask worker`` by hand: see ``docs/sweeps.md``); ``--chunk C`` puts C
cases in one Dask task when cases take only milliseconds.  ``--workers 0`` runs
serially in this process without importing Dask.

Dispersion specs (``--vary PATH=DIST [UNIT]``, parsed by a tiny parser: nothing is
evaluated)
    ``PATH`` is a key path into the config as the TOML file spells it:
    ``scenario.duration``, ``central_body.mu``, ``bodies[2].orbit.e`` (index) or
    ``bodies.sat1.orbit.e`` / ``bodies[sat.1].orbit.e`` (the body named so), and a
    trailing ``[k]`` picks one element of a vector (``bodies.sat1.attitude.w[2]``).
    ``DIST`` is one of

    * ``uniform(low, high)`` -- ``rng.uniform``; scalars or equal-length vectors;
    * ``normal(mean, sigma)`` -- ``rng.normal``; ``mean`` a scalar or vector, ``sigma``
      a scalar or a vector of the same length (sigma >= 0);
    * ``choice(v1, v2, ...)`` -- one of the values, equally likely (numbers, vectors,
      bare words or quoted strings such as ``choice(kepler, j2)``);
    * ``grid(low, high, n)`` -- ``n`` evenly spaced values (``numpy.linspace``) or
      ``grid([v1, v2, ...])`` -- these values; several grids form their Cartesian
      product (the first ``--vary`` varies slowest) and case ``k`` takes grid point
      ``k mod G`` (``G`` points); ``-n`` defaults to ``G``;
    * a plain value (``scenario.rate=5``): the same in every case.

    An optional ``UNIT`` after the distribution (``uniform(6800, 7200) km``) makes each
    drawn value the quantity string ``"<x> km"`` the scenario loader converts to SI;
    without it a draw is taken to be in SI units, like a bare number in the config.
``--cases FILE.csv``
    One case per row: the header holds key paths, each cell a value in the same syntax
    as a ``choice`` item (``0.3``, ``[0, 0, 0.1]``, ``"6800 km"``, ``j2``); an empty cell
    keeps the config's value.  Combines with random ``--vary`` draws (not with grids).

Reproducibility: case ``k`` draws from ``numpy.random.default_rng([seed, k])``, one
``--vary`` after the other in the order given, so it gets the same values on any machine
and with any number of workers, and ``--case k`` reruns exactly that case.

Each case: the draws are applied to a copy of the config dict and validated with
:func:`astrodyn.scenario.load_dict` -- an invalid draw makes the case *fail* with the
:class:`~astrodyn.scenario.ScenarioError` text (``... case 7: bodies[0].orbit.e: expected
0 <= e, got -0.1``) -- then simulated; any exception fails that case only.  A case whose
whole-run arrays would exceed the memory budget of a case (``--case-memory``; by default half
the machine's memory over the cases run at once: :func:`case_memory_need`,
:func:`default_case_memory`) fails before it makes them (:class:`CaseMemoryError`), and a sweep
no case of which fits is refused up front (:func:`check_case_memory`).  A ``--vary`` or
``--cases`` column that would fail *every* case (a misspelled key, a unit of the wrong kind)
is refused before any case runs, exit 2 (:func:`check_values_against_config`, which
``astrodyn sweep`` applies to the spec of :func:`make_spec`).  Metrics per
row (:data:`METRIC_UNITS` gives the unit of each column suffix):

* orbit, per body ``<b>``: osculating elements at the last output time
  (``<b>.a_final``, ``e_final``, ``i_final``, ``raan_final``, ``argp_final``,
  ``nu_final``; Vallado RV2COE via :func:`astrodyn.orbit.elements_from_state`), the
  smallest and largest sampled radius ``r_min``, ``r_max`` and altitude ``alt_min`` over
  the central body's equatorial radius (sampled at the output rate, not refined between
  samples), and the two-body conservation drifts ``energy_drift`` (max |E - E0| relative
  to mu / |r0|, the size of the terms) and ``h_drift`` (max |h - h0| / |h0|, the vector
  h = r x v; :func:`astrodyn.analysis.metrics.relative_drift`);
* pairs of bodies (2 to 100 orbits): ``min_separation`` (m, the miss distance over the
  sampled times), ``min_separation_t`` (s) and ``min_separation_pair``;
* attitude, per body: ``w_max`` and ``w_final`` (|w|, rad/s), ``q_norm_err``
  (max ||q| - 1|) and, for torque-free bodies, ``rot_energy_drift`` (max |T - T0| / T0)
  and ``H_drift`` (max |H_i - H_i0| / |H_i0|, inertial angular momentum);
* ``n_steps`` and ``wall_s`` (wall time of the case, s).

Output in ``--out DIR``: ``summary.csv`` (one row per case, sorted by case; floats
written with ``repr`` so they read back bit for bit), ``summary.parquet`` when pyarrow
is installed, ``failures.csv`` (case, error, the draws), ``failures/case-K.txt`` (the
traceback of an unexpected exception), ``sweep.json`` (the spec: config, dispersions,
seed, n, column units, versions, counts) and with ``--mcap`` one ``mcap/case-K.mcap``
per case; while it runs, ``rows.jsonl`` (each finished row, appended) and the lock
``.astrodyn-sweep.lock`` (one sweep per directory).  ``--case K`` (repeatable) reruns those
cases serially and updates the tables in ``DIR``; ``--resume`` runs the cases a killed or
interrupted sweep has no row for and completes its tables.  ``astrodyn analyze DIR`` plots the table (:mod:`astrodyn.analysis.sweep`).

Exit status: 0 every case ran, 1 some cases failed, 2 bad arguments, spec, config or
``--out``, or no case fits in the memory budget (nothing is created), 130 interrupted by Ctrl-C, 143 by SIGTERM (the finished
cases are written; nothing when none had finished).
"""

from __future__ import annotations

import argparse
import contextlib
import copy
import csv
import itertools
import json
import math
import os
import re
import signal
import sys
import threading
import time
import traceback
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from astrodyn.files import file_kind, path_argument
from astrodyn.recording.outputs import written_atomically
from astrodyn.signals import interruptible_main

__all__ = [
    "SweepError",
    "Vary",
    "SweepSpec",
    "parse_vary",
    "parse_value",
    "parse_path",
    "read_cases_csv",
    "make_spec",
    "check_values_against_config",
    "probe_values",
    "CaseMemoryError",
    "case_memory_need",
    "case_memory_problem",
    "check_case_memory",
    "machine_memory",
    "default_case_memory",
    "case_memory_here",
    "run_case",
    "run_chunk",
    "local_cluster",
    "start_local_cluster",
    "case_metrics",
    "run_cases",
    "write_tables",
    "read_table",
    "METRIC_UNITS",
    "SCHEDULER_PROTOCOLS",
    "check_scheduler_address",
    "RESULT_TABLES",
    "SPEC_KEYS",
    "earlier_results",
    "check_out_directory",
    "remove_earlier_results",
    "main",
]

MAX_CASES = 10_000_000  #: upper bound on -n (a sanity limit, not a resource estimate)
MAX_GRID = 1_000_000  #: most points a grid(...) may have
MAX_SPEC = 4096  #: longest --vary text
SCHEDULER_TIMEOUT_S = 30.0  #: how long to try reaching a --scheduler
SCHEDULER_GRACE_S = 5.0  #: beyond SCHEDULER_TIMEOUT_S, for Dask's handshake (which its timeout does not bound)

#: Unit of each metric column, by the suffix after the last "." of the column name.
METRIC_UNITS: dict[str, str] = {
    "a_final": "m", "e_final": "1", "i_final": "rad", "raan_final": "rad", "argp_final": "rad",
    "nu_final": "rad", "r_min": "m", "r_max": "m", "alt_min": "m", "energy_drift": "1", "h_drift": "1",
    "min_separation": "m", "min_separation_t": "s", "min_separation_pair": "",
    "w_max": "rad/s", "w_final": "rad/s", "q_norm_err": "1", "rot_energy_drift": "1", "H_drift": "1",
    "n_steps": "1", "wall_s": "s",
}
_FIXED_COLUMNS = ("case", "status")


class SweepError(ValueError):
    """A bad sweep specification or argument; the text names the argument and what was expected."""


# --------------------------------------------------------------------------- tiny parser

_TOKEN = re.compile(
    r"""\s*(?:
        (?P<num>[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?(?![A-Za-z0-9_]))
      | (?P<word>[A-Za-z_][A-Za-z0-9_.\-]*)
      | "(?P<dq>[^"\\]*)"
      | '(?P<sq>[^'\\]*)'
      | (?P<punct>[\[\](),])
    )""",
    re.VERBOSE,
)


class _Tokens:
    """Tokens of a value / distribution expression: numbers, words, strings, ``[ ] ( ) ,``."""

    def __init__(self, text: str, what: str):
        self.text, self.what, self.pos = text, what, 0

    def error(self, expected: str) -> SweepError:
        rest = self.text[self.pos:].strip()
        got = repr(rest[:20]) if rest else "the end"
        return SweepError(f"{self.what}: expected {expected} at character {self.pos + 1}, got {got}")

    def peek(self) -> tuple[str, Any] | None:
        m = _TOKEN.match(self.text, self.pos)
        if not m or m.end() == self.pos:
            return None
        kind = m.lastgroup
        raw = m.group(kind)
        if kind == "num":
            value: Any = float(raw) if any(c in raw for c in ".eE") else int(raw)
        elif kind in ("dq", "sq"):
            kind, value = "str", raw
        else:
            value = raw
        return kind, value

    def take(self) -> tuple[str, Any]:
        tok = self.peek()
        if tok is None:
            raise self.error("a number, a word, a string, '[', ']', '(', ')' or ','")
        self.pos = _TOKEN.match(self.text, self.pos).end()
        return tok

    def expect(self, punct: str) -> None:
        tok = self.peek()
        if tok != ("punct", punct):
            raise self.error(repr(punct))
        self.take()

    def at_end(self) -> bool:
        return not self.text[self.pos:].strip()


def _value(tk: _Tokens, depth: int = 0) -> Any:
    """value := number | word | string | '[' value (',' value)* ']'"""
    if depth > 8:
        raise tk.error("at most 8 nested lists")
    kind, value = tk.take()
    if kind in ("num", "str"):
        return value
    if kind == "word":
        if value in ("true", "false"):
            return value == "true"
        return value
    if value == "[":
        items = []
        if tk.peek() == ("punct", "]"):
            tk.take()
            return items
        while True:
            items.append(_value(tk, depth + 1))
            kind, value = tk.take()
            if value == "]" and kind == "punct":
                return items
            if value != "," or kind != "punct":
                raise tk.error("',' or ']'")
    raise tk.error("a value (number, [list], word or string)")


def parse_value(text: str, what: str = "value") -> Any:
    """A literal in the sweep syntax: ``0.3``, ``-2e3``, ``[0, 0, 0.1]``, ``j2``, ``"6800 km"``.

    Numbers become int or float, bare words and quoted strings str, ``[...]`` lists.
    SweepError (naming ``what``) for anything else; nothing is ever evaluated.
    """
    tk = _Tokens(str(text), what)
    if tk.at_end():
        raise tk.error("a value")
    out = _value(tk)
    if not tk.at_end():
        raise tk.error("the end of the value")
    return out


_PATH_SEGMENT = re.compile(r"\s*(?:\.?(?P<key>[A-Za-z_][A-Za-z0-9_\-]*)|\[(?P<idx>[^\[\]]+)\])")


def parse_path(text: str, what: str = "path") -> tuple[str | int, ...]:
    """Split a key path into segments: ``bodies[2].orbit.e`` -> ``("bodies", 2, "orbit", "e")``.

    ``[k]`` with an integer is a list index; ``[name]`` (or ``.name`` right after
    ``bodies``) is kept as a str and resolved against the config by :func:`make_spec`.
    """
    text = str(text).strip()
    if not text:
        raise SweepError(f"{what}: expected a key path like bodies.sat1.orbit.e, got ''")
    segs: list[str | int] = []
    pos = 0
    while pos < len(text):
        m = _PATH_SEGMENT.match(text, pos)
        if not m or (m.group("key") and pos > 0 and text[pos] != "." and not text[pos].isspace()) \
                or (m.group("key") and pos == 0 and text[0] == "."):
            raise SweepError(f"{what}: expected a key path like bodies.sat1.orbit.e or bodies[2].orbit.e, "
                             f"got {text!r} (bad at character {pos + 1})")
        if m.group("key") is not None:
            segs.append(m.group("key"))
        else:
            inner = m.group("idx").strip()
            segs.append(int(inner) if re.fullmatch(r"\d+", inner) else inner)
        pos = m.end()
    if not isinstance(segs[0], str):
        raise SweepError(f"{what}: expected a key path starting with a section name, got {text!r}")
    return tuple(segs)


# --------------------------------------------------------------------------- dispersions

_DISTRIBUTIONS = ("uniform", "normal", "choice", "grid")


def _is_number(x: Any) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def _numeric(x: Any, what: str) -> np.ndarray:
    """A finite float scalar or 1-D vector from a parsed value."""
    if _is_number(x):
        return np.float64(x)
    if isinstance(x, list) and x and all(_is_number(v) for v in x):
        return np.array(x, dtype=np.float64)
    raise SweepError(f"{what}: expected a finite number or a list of numbers, got {x!r}")


@dataclass(frozen=True)
class Vary:
    """One dispersion: ``path`` (as written and as segments), ``kind`` (uniform, normal,
    choice, grid, const), ``args`` (parsed literals), optional ``unit``."""

    text: str
    path: str
    segments: tuple
    kind: str
    args: tuple
    unit: str | None = None
    values: tuple = ()  #: grid points / choice options / (const,)

    @property
    def random(self) -> bool:
        return self.kind in ("uniform", "normal", "choice")

    def draw(self, rng: np.random.Generator) -> Any:
        """One draw (uses ``rng`` only for the random kinds)."""
        if self.kind == "uniform":
            lo, hi = self.args
            x = rng.uniform(lo, hi, size=np.shape(lo))
        elif self.kind == "normal":
            mean, sigma = self.args
            x = rng.normal(mean, sigma, size=np.broadcast(mean, sigma).shape)
        elif self.kind == "choice":
            return self.values[int(rng.integers(len(self.values)))]
        else:
            raise ValueError(f"{self.kind} values are not drawn")
        return float(x) if np.ndim(x) == 0 else [float(v) for v in x]

    def to_json(self) -> dict:
        return {"text": self.text, "path": self.path, "kind": self.kind, "unit": self.unit,
                "args": [a.tolist() if isinstance(a, np.ndarray) else a for a in self.args]}


def parse_vary(text: str) -> Vary:
    """Parse ``PATH=DIST [UNIT]`` (module docstring); SweepError with the reason otherwise."""
    what = f"--vary {text!r}"
    if not isinstance(text, str) or "=" not in text:
        raise SweepError(f"{what}: expected PATH=DISTRIBUTION, e.g. 'bodies.sat1.orbit.e=uniform(0.1, 0.9)'")
    if len(text) > MAX_SPEC:
        raise SweepError(f"{what[:60]}...: expected at most {MAX_SPEC} characters")
    path_text, expr = text.split("=", 1)
    segments = parse_path(path_text, what)
    tk = _Tokens(expr, what)
    head = tk.peek()
    if head and head[0] == "word" and head[1] in _DISTRIBUTIONS:
        kind = tk.take()[1]
        tk.expect("(")
        args: list[Any] = []
        if tk.peek() != ("punct", ")"):
            while True:
                args.append(_value(tk))
                tok = tk.peek()
                if tok == ("punct", ","):
                    tk.take()
                    continue
                if tok == ("punct", ")"):
                    break
                raise tk.error("',' or ')'")
        tk.expect(")")
    else:
        kind, args = "const", [_value(tk)]
        if tk.peek() == ("punct", "("):
            raise SweepError(f"{what}: unknown distribution {args[0]!r}; expected one of {', '.join(_DISTRIBUTIONS)} "
                             "or a plain value")
    unit = tk.text[tk.pos:].strip() or None
    if unit is not None:
        _check_unit(unit, what)
    return _build_vary(text, path_text.strip(), segments, kind, args, unit, what)


def _check_unit(unit: str, what: str) -> None:
    """Refuse a ``--vary`` unit the scenario loader would not know (astropy's units, ``rpm``
    and the English unit words of :data:`astrodyn.scenario.fields.UNIT_WORDS`), or one that
    starts with a number: astropy takes ``5 km`` as a unit 5 km long, so every draw would be
    multiplied by 5 (``1/s``, 1 over a unit, stays legal)."""
    from astrodyn.scenario.fields import scaled_unit_number, unit_text, units

    if scaled_unit_number(unit) is not None:
        raise SweepError(f"{what}: expected a unit without a number after the distribution (e.g. km, deg, rad/s, 1/s), "
                         f"got {unit!r}: a number there would scale every draw; write the unit alone and put the "
                         f"scale into the distribution's values")
    try:
        units().Unit(unit_text(unit), parse_strict="raise")
    except Exception:
        raise SweepError(f"{what}: expected a unit after the distribution (e.g. km, deg, rad/s), got {unit!r}") from None


def _build_vary(text: str, path: str, segments: tuple, kind: str, args: list, unit: str | None, what: str) -> Vary:
    n = len(args)
    values: tuple = ()
    if kind == "uniform":
        if n != 2:
            raise SweepError(f"{what}: uniform: expected 2 arguments (low, high), got {n}")
        lo, hi = _numeric(args[0], f"{what}: uniform low"), _numeric(args[1], f"{what}: uniform high")
        if np.shape(lo) != np.shape(hi):
            raise SweepError(f"{what}: uniform: expected low and high of the same shape, got {np.shape(lo)} and {np.shape(hi)}")
        if np.any(lo > hi):
            raise SweepError(f"{what}: uniform: expected low <= high, got {args[0]!r} > {args[1]!r}")
        args = [lo, hi]
    elif kind == "normal":
        if n != 2:
            raise SweepError(f"{what}: normal: expected 2 arguments (mean, sigma), got {n}")
        mean, sigma = _numeric(args[0], f"{what}: normal mean"), _numeric(args[1], f"{what}: normal sigma")
        if np.ndim(sigma) and np.shape(sigma) != np.shape(mean):
            raise SweepError(f"{what}: normal: expected sigma a scalar or of the shape of mean {np.shape(mean)}, got {np.shape(sigma)}")
        if np.any(sigma < 0):
            raise SweepError(f"{what}: normal: expected sigma >= 0, got {args[1]!r}")
        args = [mean, sigma]
    elif kind == "choice":
        if n < 1:
            raise SweepError(f"{what}: choice: expected at least one value")
        values = tuple(args)
    elif kind == "grid":
        if n == 1 and isinstance(args[0], list) and args[0]:
            values = tuple(args[0])
        elif n == 3:
            lo = _numeric(args[0], f"{what}: grid low")
            hi = _numeric(args[1], f"{what}: grid high")
            count = args[2]
            if not (isinstance(count, int) and not isinstance(count, bool) and 1 <= count <= MAX_GRID):
                raise SweepError(f"{what}: grid: expected a point count 1 <= n <= {MAX_GRID} as the third argument, got {count!r}")
            if np.shape(lo) != np.shape(hi):
                raise SweepError(f"{what}: grid: expected low and high of the same shape")
            pts = np.linspace(lo, hi, count)
            values = tuple(float(p) if np.ndim(p) == 0 else [float(x) for x in p] for p in pts)
        else:
            raise SweepError(f"{what}: grid: expected grid(low, high, n) or grid([v1, v2, ...]), got {n} arguments")
    else:  # const
        values = (args[0],)
    if unit is not None:
        for v in (values or [a.tolist() for a in args]):
            if not (_is_number(v) or (isinstance(v, list) and all(_is_number(x) for x in v))):
                raise SweepError(f"{what}: a unit applies to numbers only, got the value {v!r}")
    return Vary(text=text, path=path, segments=segments, kind=kind, args=tuple(args), unit=unit, values=values)


def read_cases_csv(path: str | os.PathLike) -> tuple[list[str], list[dict[str, Any]]]:
    """Header (key paths) and rows (path -> parsed value; empty cells omitted) of a cases CSV:
    a regular file of at most :data:`astrodyn.files.MAX_TEXT_INPUT_BYTES`."""
    from astrodyn.files import MAX_TEXT_INPUT_BYTES, regular_file_problem

    if problem := regular_file_problem(path):  # /dev/zero was read until the memory ran out
        raise SweepError(f"--cases {path}: {problem}")
    try:
        size = os.path.getsize(path)
        if size > MAX_TEXT_INPUT_BYTES:
            raise SweepError(f"--cases {path}: expected a CSV of at most {MAX_TEXT_INPUT_BYTES} bytes (4 MiB), got "
                             f"{size} bytes")
        with open(path, newline="", encoding="utf-8-sig") as fh:  # -sig: the byte order mark a spreadsheet writes
            reader = csv.reader(fh)
            header = next(reader, None)
            if not header:
                raise SweepError(f"--cases {path}: expected a header row of key paths, got an empty file")
            header = [h.strip() for h in header]
            rows = []
            for lineno, cells in enumerate(reader, start=2):
                if not any(c.strip() for c in cells):
                    continue
                if len(cells) != len(header):
                    raise SweepError(f"--cases {path}: line {lineno}: expected {len(header)} cells, got {len(cells)}")
                rows.append({h: parse_value(c, f"--cases {path}: line {lineno}, column {h!r}")
                             for h, c in zip(header, cells) if c.strip()})
    except OSError as exc:
        raise SweepError(f"--cases {path}: expected a readable CSV file ({exc.strerror or exc})") from None
    except UnicodeDecodeError as exc:
        raise SweepError(f"--cases {path}: expected UTF-8 text, got an invalid byte at offset {exc.start}") from None
    except csv.Error as exc:  # e.g. a cell over csv.field_size_limit() characters (131,072)
        raise SweepError(f"--cases {path}: expected a CSV file of cases: {exc}") from None
    for h in header:
        parse_path(h, f"--cases {path}: column {h!r}")
    if not rows:
        raise SweepError(f"--cases {path}: expected at least one case row")
    return header, rows


# --------------------------------------------------------------------------- spec


@dataclass
class SweepSpec:
    """Everything a worker needs to build and run case ``k`` (picklable, JSON-able)."""

    config: dict
    source: str
    base_dir: str
    varies: tuple[Vary, ...]
    n: int
    seed: int
    cases_header: tuple[str, ...] = ()
    cases_rows: tuple[dict, ...] = ()
    resolved: dict = field(default_factory=dict)  #: path text -> concrete segments
    grid_sizes: tuple[int, ...] = ()
    mcap_dir: str | None = None
    #: bytes one case may take (:func:`case_memory_need`); None: decided where the case runs
    #: (:func:`case_memory_here`)
    case_memory: int | None = None

    # ---- draws
    def draws(self, k: int) -> dict[str, Any]:
        """``{path: value}`` applied in case ``k`` (CSV row first, then --vary in order)."""
        if not 0 <= k < self.n:
            raise SweepError(f"--case: expected 0 <= case < {self.n}, got {k}")
        out: dict[str, Any] = {}
        if self.cases_rows:
            out.update(self.cases_rows[k % len(self.cases_rows)])
        rng = np.random.default_rng([self.seed, k])
        grid_index = _unravel(k % max(1, math.prod(self.grid_sizes)), self.grid_sizes)
        g = 0
        for vary in self.varies:
            if vary.random:
                value = vary.draw(rng)
            elif vary.kind == "grid":
                value = vary.values[grid_index[g]]
                g += 1
            else:
                value = vary.values[0]
            out[vary.path] = _with_unit(value, vary.unit)
        return out

    def case_config(self, k: int) -> tuple[dict, dict[str, Any]]:
        """The config dict of case ``k`` and its draws."""
        draws = self.draws(k)
        config = copy.deepcopy(self.config)
        for path, value in draws.items():
            _assign(config, self.resolved[path], value, path)
        return config, draws

    def to_json(self) -> dict:
        return {
            "format": "astrodyn.sweep/1", "source": self.source, "n": self.n, "seed": self.seed,
            "rng": "numpy.random.default_rng([seed, case])", "varies": [v.to_json() for v in self.varies],
            "cases_csv_columns": list(self.cases_header), "cases_csv_rows": len(self.cases_rows),
            "grid_sizes": list(self.grid_sizes), "config": self.config,
        } | ({"cases_csv_sha256": _cases_digest(self.cases_rows)} if self.cases_rows else {})


def _unravel(i: int, sizes: tuple[int, ...]) -> list[int]:
    """Mixed-radix digits of ``i`` (first size slowest), like ``itertools.product`` order."""
    out = []
    for s in reversed(sizes):
        i, r = divmod(i, s)
        out.append(r)
    return out[::-1]


def _with_unit(value: Any, unit: str | None) -> Any:
    if unit is None:
        return value
    if isinstance(value, list):
        return [f"{float(x)!r} {unit}" for x in value]
    return f"{float(value)!r} {unit}"


def _resolve(config: dict, segments: tuple, what: str) -> tuple:
    """Concrete segments (body names -> indices) checked against ``config``; the last key
    may be new (e.g. an element not given in the file), every container must exist."""
    node: Any = config
    out: list[str | int] = []
    for j, seg in enumerate(segments):
        last = j == len(segments) - 1
        if isinstance(node, list):
            if isinstance(seg, str) and all(isinstance(b, dict) for b in node):
                names = [b.get("name") for b in node]
                if seg not in names:
                    raise SweepError(f"{what}: no entry named {seg!r} in {_join(out)} "
                                     f"(names: {', '.join(map(str, names)) or 'none'})")
                seg = names.index(seg)
            if not isinstance(seg, int) or not 0 <= seg < len(node):
                raise SweepError(f"{what}: {_join(out)} has {len(node)} entries; expected an index 0..{len(node) - 1} "
                                 f"or a name, got {seg!r}")
        elif isinstance(node, dict):
            if not isinstance(seg, str):
                raise SweepError(f"{what}: {_join(out) or 'the config'} is a table; expected a key, got [{seg}]")
            if seg not in node and not last:
                raise SweepError(f"{what}: {_join(out + [seg])} is not in the config "
                                 f"(keys of {_join(out) or 'the config'}: {', '.join(node) or 'none'})")
        else:
            raise SweepError(f"{what}: {_join(out)} is a value ({node!r}), not a table or a list")
        out.append(seg)
        if not last:
            node = node[seg]
    return tuple(out)


def _join(segs: Iterable) -> str:
    s = ""
    for seg in segs:
        s += f"[{seg}]" if isinstance(seg, int) else (f".{seg}" if s else seg)
    return s


def _assign(config: dict, segments: tuple, value: Any, path: str) -> None:
    node: Any = config
    for seg in segments[:-1]:
        node = node[seg]
    last = segments[-1]
    if isinstance(node, list) and not (isinstance(last, int) and last < len(node)):
        raise SweepError(f"{path}: index {last} out of range")
    node[last] = value


def _check_overlaps(resolved: dict[str, tuple], flags: dict[str, str]) -> None:
    """Refuse two key paths that reach one config location (``bodies.sat1.orbit.e`` and
    ``bodies[0].orbit.e``) or one inside the other (``...attitude.w[0]`` and ``...attitude.w``):
    both were drawn and tabled, but only the one assigned last reached the simulation."""
    items = list(resolved.items())
    for i, (p1, s1) in enumerate(items):
        for p2, s2 in items[i + 1:]:
            short, long_ = (s1, s2) if len(s1) <= len(s2) else (s2, s1)
            if long_[:len(short)] == short:
                where = (f"the same config location {_join(s1)}" if s1 == s2 else
                         f"{_join(long_)}, which is inside {_join(short)}")
                raise SweepError(f"{flags[p1]} {p1!r} and {flags[p2]} {p2!r}: both set {where}; only one of them "
                                 f"would reach the simulation while the table lists both: vary each config value "
                                 f"once, under one spelling")


def _cases_digest(rows: tuple[dict, ...]) -> str:
    """SHA-256 of the parsed rows of a cases CSV (key order and spelling of numbers aside)."""
    import hashlib

    text = json.dumps([sorted(r.items()) for r in rows], separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def make_spec(config_path: str | os.PathLike, varies: Iterable[str], n: int | None = None, seed: int = 0,
              cases_csv: str | os.PathLike | None = None) -> SweepSpec:
    """Parse and check a sweep against the config file (SweepError / ScenarioError if bad)."""
    from astrodyn.scenario import ScenarioError, load

    try:
        base = load(config_path)  # the nominal scenario must be valid
    except ScenarioError:
        raise
    parsed = tuple(parse_vary(v) for v in varies)
    header: tuple[str, ...] = ()
    rows: tuple[dict, ...] = ()
    if cases_csv is not None:
        h, r = read_cases_csv(cases_csv)
        header, rows = tuple(h), tuple(r)
    if not parsed and not rows:
        raise SweepError("--vary / --cases: expected at least one dispersion (--vary PATH=DIST) or a cases CSV")
    paths = [v.path for v in parsed] + list(header)
    dup = sorted({p for p in paths if paths.count(p) > 1})
    if dup:
        raise SweepError(f"--vary / --cases: each key path at most once, got {', '.join(dup)} more than once")
    grids = tuple(len(v.values) for v in parsed if v.kind == "grid")
    if grids and rows:
        raise SweepError("--cases with grid(...): expected one of them (a cases CSV already enumerates cases)")
    if math.prod(grids) > MAX_CASES:
        raise SweepError(f"grid(...): the grids have {math.prod(grids)} points; expected at most {MAX_CASES}")
    if n is None:
        if grids:
            n = math.prod(grids)
        elif rows:
            n = len(rows)
        else:
            raise SweepError("-n: expected the number of cases (required unless grid(...) or --cases give it)")
    if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= MAX_CASES:
        raise SweepError(f"-n: expected an integer 1 <= n <= {MAX_CASES}, got {n!r}")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise SweepError(f"--seed: expected an integer >= 0, got {seed!r}")
    config = base.config
    resolved = {}
    for v in parsed:
        resolved[v.path] = _resolve(config, v.segments, f"--vary {v.text!r}")
    for h in header:
        resolved[h] = _resolve(config, parse_path(h), f"--cases column {h!r}")
    _check_overlaps(resolved, {v.path: "--vary" for v in parsed} | {h: "--cases column" for h in header})
    return SweepSpec(config=config, source=str(config_path), base_dir=str(Path(config_path).resolve().parent),
                     varies=parsed, n=n, seed=seed, cases_header=header, cases_rows=rows, resolved=resolved,
                     grid_sizes=grids)


PROBE_CASES = 4  #: joint cases tried before a dispersion no probe value of which validates is refused


def probe_values(vary: Vary) -> list[Any]:
    """A few values ``vary`` takes, before its unit, to check it against the scenario before any
    case runs: ``uniform``: low, middle, high; ``normal``: mean, mean - sigma, mean + sigma;
    ``choice`` / ``grid``: the first, middle and last value; a plain value: that value."""
    if vary.kind in ("uniform", "normal"):
        a, b = vary.args
        if vary.kind == "uniform":
            points = [a, (a + b) / 2, b]
        else:
            mean = np.broadcast_to(a, np.broadcast(a, b).shape)
            points = [mean, mean - b, mean + b]
        return [float(p) if np.ndim(p) == 0 else [float(x) for x in p] for p in points]
    values = vary.values
    return [values[i] for i in sorted({0, len(values) // 2, len(values) - 1})]


def check_values_against_config(spec: SweepSpec) -> None:
    """Refuse (:class:`SweepError`, before any case runs) a ``--vary`` or ``--cases`` column
    that would fail every case: a misspelled key (``bodies.iss.orbit.ecc``) or a unit of the
    wrong kind (``a=uniform(6800, 7200) deg``).

    Each dispersion alone is put into the nominal config at its :func:`probe_values` (a cases
    column: its values in the first, middle and last row), the config validated with
    :func:`astrodyn.scenario.load_dict`.  If none of them validates, and none of the first
    :data:`PROBE_CASES` cases (all dispersions together: a value may need another one, e.g. a
    model chosen alongside) validates either, the sweep is refused with the scenario's own
    message (the field, the allowed values).  A dispersion only some of whose values are
    invalid is accepted: those cases fail one by one, as the module docstring says."""
    from astrodyn.scenario import ScenarioError, load_dict

    def problem(config: dict, source: str) -> ScenarioError | None:
        try:
            load_dict(config, source=source, base_dir=spec.base_dir)
        except ScenarioError as exc:
            return exc
        return None

    joint_ok: bool | None = None
    for label, path, values in _probes(spec):
        errors = [problem(_config_with(spec, path, x), label) for x in values]
        if not values or not all(errors):
            continue
        if joint_ok is None:
            joint_ok = any(problem(spec.case_config(k)[0], label) is None for k in range(min(spec.n, PROBE_CASES)))
        if not joint_ok:
            tried = ", ".join(_shown_value(x) for x in values)
            raise SweepError(f"{errors[0]} (the values tried: {tried}; no case was run)")


def _probes(spec: SweepSpec) -> list[tuple[str, str, list]]:
    """``(label, path, values)`` the up-front checks put into the nominal config, one dispersion
    at a time: each ``--vary``'s :func:`probe_values` with its unit, each ``--cases`` column's
    values in the first, middle and last row."""
    probes = [(f"--vary {v.text!r}", v.path, [_with_unit(x, v.unit) for x in probe_values(v)]) for v in spec.varies]
    rows = spec.cases_rows
    picked = [rows[i] for i in sorted({0, len(rows) // 2, len(rows) - 1})] if rows else []
    probes += [(f"--cases column {h!r}", h, [r[h] for r in picked if h in r]) for h in spec.cases_header]
    return probes


def _config_with(spec: SweepSpec, path: str, value: Any) -> dict:
    """A copy of the nominal config with ``value`` at ``path`` (a --vary or --cases path)."""
    config = copy.deepcopy(spec.config)
    _assign(config, spec.resolved[path], value, path)
    return config


def _shown_value(value: Any) -> str:
    """A probe value for a message: a number or quantity string as is, shortened."""
    text = value if isinstance(value, str) else json.dumps(value, default=str)
    return text if len(text) <= 60 else text[:57] + "..."


# --------------------------------------------------------------------------- memory of a case

#: Share of the memory available to a case (its machine's over the cases run at once, or its
#: Dask worker's memory limit) its arrays may take by default: the rest is for the process,
#: its libraries and the machine's other programs.
CASE_MEMORY_FRACTION = 0.5
#: Scratch bytes per output step :func:`case_metrics` takes on top of the run's arrays, for
#: its per-body temporaries (at most 223 measured with tracemalloc, up to 20 bodies).
METRICS_BYTES_PER_STEP = 256
#: Bytes per output step of one orbit (r, v) and one attitude (q, w) in the whole-run arrays
#: (float64, :class:`astrodyn.simulate.SimulationResult`); the times take 8 more.
ORBIT_BYTES_PER_STEP = 48
ATTITUDE_BYTES_PER_STEP = 56


class CaseMemoryError(SweepError):
    """A case whose whole-run arrays would exceed the memory budget of a case (refused before
    anything of that size is made)."""


def _case_bodies(scenario) -> tuple[int, int]:
    """``(orbits, attitudes)`` :func:`astrodyn.simulate.simulate` propagates for ``scenario`` (at most)."""
    orbits = sum(b.orbit is not None for b in scenario.bodies)
    attitudes = sum(b.attitude is not None and b.attitude.model != "none" for b in scenario.bodies)
    return orbits, attitudes


def case_memory_need(scenario) -> int:
    """Bytes :func:`run_case` takes at its peak for ``scenario`` (an upper bound), from the
    counts alone (nothing of that size is made): the whole run's arrays
    (:func:`astrodyn.simulate.simulate`), per output step 8 bytes for the time and
    :data:`ORBIT_BYTES_PER_STEP` per orbit, :data:`ATTITUDE_BYTES_PER_STEP` per attitude,
    the states held twice while simulate joins its blocks, or once plus the metrics' scratch
    (:data:`METRICS_BYTES_PER_STEP`); over ``n_steps`` and one block of the engines' working
    arrays (:data:`astrodyn.simulate.SIMULATE_BLOCK` steps at most)."""
    from astrodyn.simulate import SIMULATE_BLOCK

    orbits, attitudes = _case_bodies(scenario)
    states = ORBIT_BYTES_PER_STEP * orbits + ATTITUDE_BYTES_PER_STEP * attitudes
    steps = scenario.n_steps + min(scenario.n_steps, SIMULATE_BLOCK)
    return steps * (8 + states + max(states, METRICS_BYTES_PER_STEP))


def machine_memory() -> int | None:
    """Bytes of memory of this machine (``SC_PHYS_PAGES`` x ``SC_PAGE_SIZE``), or the memory
    limit of this process's cgroup (a container's) when lower; None when unknown."""
    sizes = []
    with contextlib.suppress(ValueError, OSError, AttributeError):
        sizes.append(os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    for limit in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):  # cgroup v2, v1
        with contextlib.suppress(ValueError, OSError):
            sizes.append(int(Path(limit).read_text(encoding="ascii").strip()))  # "max": no limit (ValueError)
    sizes = [n for n in sizes if n > 0]
    return min(sizes) if sizes else None


def default_case_memory(cases_at_once: int) -> int | None:
    """The memory budget of a case run on this machine (bytes): :data:`CASE_MEMORY_FRACTION`
    of :func:`machine_memory` shared by the ``cases_at_once`` cases that run at once (the local
    worker processes; 1 serially); None when the machine's memory is unknown."""
    memory = machine_memory()
    return None if memory is None else int(memory * CASE_MEMORY_FRACTION) // max(1, cases_at_once)


def case_memory_here() -> int | None:
    """The memory budget of a case whose spec names none (a ``--scheduler`` worker's, where the
    sweep's machine is not the case's): :data:`CASE_MEMORY_FRACTION` of the Dask worker's memory
    limit (Dask's share of its machine per worker), else of this machine's memory."""
    if "distributed" in sys.modules:
        limit = None
        with contextlib.suppress(Exception):  # not in a Dask worker: ValueError
            from distributed import get_worker

            worker = get_worker()
            limit = getattr(getattr(worker, "memory_manager", worker), "memory_limit", None)  # distributed >= 2022.6
        if isinstance(limit, (int, float)) and limit > 0:
            return int(limit * CASE_MEMORY_FRACTION)
    return default_case_memory(1)


def _size_text(n: float) -> str:
    """``n`` bytes for a message, in binary units (``7.45 GiB``)."""
    for unit in ("bytes", "KiB", "MiB", "GiB", "TiB"):
        if n < 1024 or unit == "TiB":
            return f"{int(n)} bytes" if unit == "bytes" else f"{n:.3g} {unit}"
        n /= 1024
    raise AssertionError("unreachable")  # pragma: no cover


def case_memory_problem(scenario, budget: int | None) -> str | None:
    """Why ``scenario`` cannot run as a case within ``budget`` bytes (:func:`case_memory_need`):
    the estimate, the budget and what to change; None when it fits or there is no budget."""
    if budget is None:
        return None
    need = case_memory_need(scenario)
    if need <= budget:
        return None
    orbits, attitudes = _case_bodies(scenario)
    return (f"needs about {_size_text(need)} of memory for its whole-run arrays ({scenario.n_steps} output steps of "
            f"{orbits} orbit(s) and {attitudes} attitude(s)), over the memory budget of a case of "
            f"{_size_text(budget)}; shorten scenario.duration, lower scenario.rate or use fewer bodies (or raise "
            f"--case-memory, by default half the machine's memory over the cases run at once)")


def check_case_memory(spec: SweepSpec) -> list[str]:
    """Before any case runs: refuse (:class:`SweepError`) a sweep no case of which fits in the
    memory budget of a case (``spec.case_memory``; nothing is checked without one), and return
    one warning per ``--vary`` / ``--cases`` column some of whose values make a case too big
    (those cases will fail, the others run).

    Tried: the configs of :func:`check_values_against_config` (each dispersion alone at its
    probe values, the first :data:`PROBE_CASES` cases); the sweep is refused when every one of
    them that validates needs more than the budget (a grid whose every value is too long)."""
    from astrodyn.scenario import ScenarioError, load_dict

    budget = spec.case_memory
    if budget is None:
        return []
    fits = False

    def problem(config: dict) -> str | None:
        nonlocal fits
        try:
            scenario = load_dict(config, source=spec.source, base_dir=spec.base_dir)
        except ScenarioError:  # the loader's refusal is the case's own failure (check_values_against_config)
            return None
        found = case_memory_problem(scenario, budget)
        fits = fits or found is None
        return found

    first = None
    for k in range(min(spec.n, PROBE_CASES)):
        if found := problem(spec.case_config(k)[0]):
            first = first or f"case {k} {found}"
    warnings = []
    for label, path, values in _probes(spec):
        over = [(x, found) for x in values if (found := problem(_config_with(spec, path, x)))]
        if over:
            value, found = over[0]
            first = first or f"{label} at {_shown_value(value)}: a case {found}"
            warnings.append(f"{label}: a case at {_shown_value(value)} {found}: the cases at such values will fail, "
                            f"the others run")
    if first is not None and not fits:
        raise SweepError(f"no case fits in the memory budget of a case (tried: the first {min(spec.n, PROBE_CASES)} "
                         f"cases and a few values of each dispersion; no case was run): {first}")
    return warnings


# --------------------------------------------------------------------------- one case


def _draw_columns(draws: dict[str, Any], spec: SweepSpec) -> dict[str, Any]:
    """Table columns of the draws: vectors expand to ``path[i]``, a unit goes in the name."""
    units = {v.path: v.unit for v in spec.varies}
    out: dict[str, Any] = {}
    for path, value in draws.items():
        unit = units.get(path)
        name = f"{path} [{unit}]" if unit else path
        if isinstance(value, list):
            for i, x in enumerate(value):
                out[f"{name}[{i}]" if not unit else f"{path}[{i}] [{unit}]"] = _strip_unit(x, unit)
        else:
            out[name] = _strip_unit(value, unit)
    return out


def _strip_unit(x: Any, unit: str | None) -> Any:
    if unit and isinstance(x, str) and x.endswith(" " + unit):
        return float(x[: -len(unit) - 1])
    return x


def case_metrics(scenario, result) -> dict[str, Any]:
    """Summary metrics of one simulated case (module docstring; units in :data:`METRIC_UNITS`)."""
    from astrodyn.analysis.metrics import relative_drift
    from astrodyn.orbit import elements_from_state
    from astrodyn.rotation import dcm_from_quat

    row: dict[str, Any] = {"n_steps": int(result.t.shape[0])}
    cb = scenario.central_body
    mu = cb.mu
    for j, name in enumerate(result.orbit_names):
        r, v = result.r[:, j], result.v[:, j]
        rn = np.linalg.norm(r, axis=1)
        el = elements_from_state(r[-1], v[-1], mu)
        for key in ("a", "e", "i", "raan", "argp", "nu"):
            row[f"{name}.{key}_final"] = float(getattr(el, key))
        energy = 0.5 * np.einsum("ij,ij->i", v, v) - mu / rn
        row[f"{name}.r_min"] = float(rn.min())
        row[f"{name}.r_max"] = float(rn.max())
        row[f"{name}.alt_min"] = float(rn.min() - cb.radius)
        # relative to mu/|r0| (the size of the terms of E), not to E, which is ~0 near parabolic orbits
        row[f"{name}.energy_drift"] = float(np.max(np.abs(energy - energy[0])) * rn[0] / mu)
        row[f"{name}.h_drift"] = float(np.max(relative_drift(np.cross(r, v))))
    n_orb = len(result.orbit_names)
    if 2 <= n_orb <= 100:
        best = (math.inf, 0, 0, 0)
        for a, b in itertools.combinations(range(n_orb), 2):
            d = np.linalg.norm(result.r[:, a] - result.r[:, b], axis=1)
            i = int(np.argmin(d))
            if d[i] < best[0]:
                best = (float(d[i]), i, a, b)
        row["min_separation"] = best[0]
        row["min_separation_t"] = float(result.t[best[1]])
        row["min_separation_pair"] = f"{result.orbit_names[best[2]]}|{result.orbit_names[best[3]]}"
    models = {bp.name: bp.attitude_model for bp in result.plan.bodies}
    for j, name in enumerate(result.attitude_names):
        q, w = result.q[:, j], result.w[:, j]
        wn = np.linalg.norm(w, axis=1)
        row[f"{name}.w_max"] = float(wn.max())
        row[f"{name}.w_final"] = float(wn[-1])
        row[f"{name}.q_norm_err"] = float(np.max(np.abs(np.linalg.norm(q, axis=1) - 1.0)))
        if models.get(name) == "torque_free":
            J = np.asarray(scenario.body(name).attitude.inertia, dtype=np.float64)
            Hb = w @ J.T
            T = 0.5 * np.einsum("ij,ij->i", w, Hb)
            Hi = np.einsum("nji,nj->ni", dcm_from_quat(q), Hb)  # inertial components C^T H_body
            row[f"{name}.rot_energy_drift"] = float(np.max(relative_drift(T)))
            row[f"{name}.H_drift"] = float(np.max(relative_drift(Hi)))
    return row


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return text if text else type(exc).__name__


def run_case(k: int, spec: SweepSpec) -> dict[str, Any]:
    """Build, validate, simulate and summarize case ``k``; never raises for a case's own
    failure: returns a row with ``status = "failed"`` and ``error`` (plus ``traceback`` for
    an unexpected exception)."""
    from astrodyn.scenario import ScenarioError, load_dict
    from astrodyn.simulate import simulate

    started = time.perf_counter()
    row: dict[str, Any] = {"case": k, "status": "ok"}
    try:
        config, draws = spec.case_config(k)
        row.update(_draw_columns(draws, spec))
        scenario = load_dict(config, source=f"{spec.source} case {k}", base_dir=spec.base_dir)
        budget = spec.case_memory if spec.case_memory is not None else case_memory_here()
        if too_big := case_memory_problem(scenario, budget):  # before simulate makes the arrays
            raise CaseMemoryError(f"{spec.source} case {k}: {too_big}")
        result = simulate(scenario)
        row.update(case_metrics(scenario, result))
        if spec.mcap_dir:
            write_case_mcap(Path(spec.mcap_dir) / f"case-{k:06d}.mcap", scenario, result, draws, k)
    except (ScenarioError, CaseMemoryError) as exc:
        row.update(status="failed", error=_one_line(exc))
    except Exception as exc:  # a case's failure must not stop the sweep: report it
        row.update(status="failed", error=f"{type(exc).__name__}: {_one_line(exc)}", traceback=traceback.format_exc())
    row["wall_s"] = time.perf_counter() - started
    return row


def write_case_mcap(path: Path, scenario, result, draws: dict, k: int) -> None:
    """One case as an MCAP in the service's layout (docs/architecture.md, section 5): seq = output step."""
    from astrodyn import messages
    from astrodyn.recording.writer import McapRecorder

    path.parent.mkdir(parents=True, exist_ok=True)
    meta = scenario.to_metadata() | {"sweep_case": str(k), "sweep_draws": json.dumps(draws)}
    orbit_models = {bp.name: bp.orbit_model for bp in result.plan.bodies}
    att_models = {bp.name: bp.attitude_model for bp in result.plan.bodies}
    okeys = [messages.orbit_key(scenario.name, n) for n in result.orbit_names]
    akeys = [messages.attitude_key(scenario.name, n) for n in result.attitude_names]
    # one compiled encoder call per (step, model): bodies grouped by model
    ogroups = _index_groups([orbit_models[n] for n in result.orbit_names])
    agroups = _index_groups([att_models[n] for n in result.attitude_names])
    mu, frame = scenario.central_body.mu, scenario.frame
    # written as case-K.mcap.tmp, renamed once finished: an interrupted case leaves no
    # half-written (or cut but finished-looking) file under its name, nor replaces an earlier one
    with written_atomically(path) as tmp, McapRecorder(tmp, meta, epoch_ns=scenario.epoch_unix_ns,
                                                       flush_interval_s=3600.0) as rec:
        for s, t in enumerate(result.t):
            t = float(t)
            for model, ix in ogroups:
                payloads = messages.encode_orbit_batch(t, s, model, result.r[s, ix], result.v[s, ix], mu, frame)
                for j, payload in zip(ix, payloads):
                    rec.write_encoded(okeys[j], payload, t, s)
            for model, ix in agroups:
                payloads = messages.encode_attitude_batch(t, s, model, result.q[s, ix], result.w[s, ix])
                for j, payload in zip(ix, payloads):
                    rec.write_encoded(akeys[j], payload, t, s)


def _index_groups(labels: list[str]) -> list[tuple[str, list[int]]]:
    """``[(label, [indices with that label]), ...]`` in order of first appearance."""
    groups: dict[str, list[int]] = {}
    for i, label in enumerate(labels):
        groups.setdefault(label, []).append(i)
    return list(groups.items())


# --------------------------------------------------------------------------- many cases


def _failed_row(k: int, spec: SweepSpec, exc: BaseException) -> dict[str, Any]:
    row: dict[str, Any] = {"case": k, "status": "failed"}
    try:
        row.update(_draw_columns(spec.draws(k), spec))
    except Exception:
        pass
    row.update(error=f"{type(exc).__name__}: {_one_line(exc)}", wall_s=math.nan)
    return row


def local_cluster(workers: int):
    """A Dask ``LocalCluster`` of ``workers`` processes, one thread and one numba thread each
    (the workers are the parallelism), no dashboard, no log lines but critical ones: a case's
    failure is its row (a dead worker's too, ``KilledWorker``), and closing the cluster on an
    interrupt while workers still run cases made them log errors with tracebacks."""
    import logging

    from distributed import LocalCluster

    # Not distributed's "pre-spawn-environ" for NUMBA_NUM_THREADS: the nannies run in this
    # process and write it into *our* os.environ for good, and numba then refuses to run
    # here ("Cannot set NUMBA_NUM_THREADS to a different value ...").  run_chunk sets the
    # worker thread's numba thread count instead.
    environ = dict(os.environ)
    try:
        return LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                            dashboard_address=None, silence_logs=logging.CRITICAL)
    finally:  # the nannies also write PYTHONHASHSEED into this process's environment
        os.environ.clear()
        os.environ.update(environ)


def close_dask(part) -> None:
    """Close ``part``, a Dask ``Client`` or ``LocalCluster``, its event loop's error reports
    dropped from then on.  A close cuts what the loop was doing (a stop signal arrives while
    the spec is scattered to the workers: the scheduler, in this process, then replicates it
    to workers the close has removed), and asyncio printed the task's error when the task
    was collected, a 15-line "Task exception was never retrieved" traceback before the
    sweep's one line (Dask's own log lines are silenced by :func:`local_cluster`, asyncio's
    are not).  Nothing the loop reports after a close asked for by the sweep is news."""
    loop = getattr(getattr(part, "loop", None), "asyncio_loop", None)
    if loop is not None:
        loop.set_exception_handler(lambda loop, context: None)
    part.close()


def run_chunk(ks: list[int], spec: SweepSpec, numba_threads: int | None = None) -> list[dict[str, Any]]:
    """Rows of several cases run one after the other (one Dask task: less per-task overhead).

    ``numba_threads``: numba threads for this (worker) thread's kernels, 1 on Dask workers
    (the workers are the parallelism)."""
    if numba_threads is not None:
        import numba

        numba.set_num_threads(min(int(numba_threads), numba.config.NUMBA_NUM_THREADS))
    return [run_case(k, spec) for k in ks]


def _check_stop() -> None:
    """Raise the stop signal received under :func:`astrodyn.signals.interruptible` even if
    the :class:`~astrodyn.signals.Interrupted` raised for it was lost (raised inside a
    garbage-collector callback of Dask's, which Python prints and drops)."""
    from astrodyn.signals import Interrupted, interrupt_received

    if (signum := interrupt_received()) is not None:
        raise Interrupted(signum)


def _connect(scheduler: str):
    """A Dask ``Client`` of the scheduler at ``scheduler``, or SweepError (one line) within
    :data:`SCHEDULER_TIMEOUT_S` (+ :data:`SCHEDULER_GRACE_S`): Dask's own timeout bounds the TCP connect, not its
    handshake, and a port that accepts and never answers held the sweep for good.  The
    Client is made in a helper thread; this thread waits, so a stop signal is seen at once."""
    from distributed import Client

    got: dict[str, Any] = {}
    done = threading.Event()

    def connect() -> None:
        try:
            got["client"] = Client(scheduler, timeout=f"{SCHEDULER_TIMEOUT_S}s")
        except BaseException as exc:  # handed to the caller's thread
            got["error"] = exc
        finally:
            done.set()

    threading.Thread(target=connect, name="astrodyn-scheduler-connect", daemon=True).start()
    deadline = time.monotonic() + SCHEDULER_TIMEOUT_S + SCHEDULER_GRACE_S
    while not done.wait(0.05):
        _check_stop()
        if time.monotonic() > deadline:
            raise SweepError(f"--scheduler {scheduler}: no Dask scheduler answered within {SCHEDULER_TIMEOUT_S:.0f} s "
                             f"(something accepts connections there but does not speak Dask's protocol)")
    if "client" in got:
        return got["client"]
    exc = got["error"]
    if isinstance(exc, (OSError, TimeoutError)):
        raise SweepError(f"--scheduler {scheduler}: cannot reach a Dask scheduler ({_one_line(exc)})") from None
    if isinstance(exc, MemoryError) or not isinstance(exc, Exception):  # a junk frame length, say
        raise SweepError(f"--scheduler {scheduler}: what answered there is not a Dask scheduler "
                         f"({type(exc).__name__}: {_one_line(exc)[:200]})") from None
    hint = (" (TLS settings come from Dask's configuration, distributed.comm.tls.*)"
            if scheduler.startswith(("tls://", "wss://")) else "")
    raise SweepError(f"--scheduler {scheduler}: cannot use this Dask scheduler{hint}: "
                     f"{type(exc).__name__}: {_one_line(exc)[:300]}") from None


#: Dask tasks kept in flight per worker thread of the cluster (at least :data:`MIN_IN_FLIGHT`):
#: submitting one task per case at once held O(n) futures (GBs for 10^6 cases) before any ran.
IN_FLIGHT_PER_THREAD = 4
MIN_IN_FLIGHT = 16


def run_cases(spec: SweepSpec, cases: Iterable[int], workers: int = 2, scheduler: str | None = None,
              chunk: int = 1) -> Iterator[dict]:
    """Rows of ``cases`` as they finish: serially here (``workers=0`` and no scheduler), on
    a Dask ``LocalCluster`` of ``workers`` processes, or on the Dask ``scheduler`` address.
    ``chunk`` cases make one Dask task (for cases of a few ms, where the scheduler's
    per-task overhead of ~10-20 ms would dominate).  Tasks are submitted in a bounded
    window (:data:`IN_FLIGHT_PER_THREAD` per worker thread), so memory does not grow with
    the number of cases; a stop signal is checked between rows (:func:`_check_stop`)."""
    cases = list(cases)
    check_chunk(chunk)
    if not cases:  # a --resume of a sweep that has every row: no cluster to start
        return
    if workers == 0 and scheduler is None:
        for k in cases:
            _check_stop()
            yield run_case(k, spec)
        return
    try:
        from distributed import Client, as_completed
    except ImportError:
        raise SweepError("Dask is not installed: `pip install 'astrodyn[sweep]'` (or --workers 0 to run serially)") from None

    cluster = client = None
    submitted: list = []
    try:
        if scheduler is None:
            cluster = start_local_cluster(workers)
            client = Client(cluster)
        else:
            client = _connect(scheduler)
        spec_future = client.scatter(spec, broadcast=True)
        token = f"{os.getpid()}-{time.time_ns()}"
        groups = iter([cases[i:i + chunk] for i in range(0, len(cases), chunk)])
        try:
            threads = sum(client.nthreads().values())
        except Exception:
            threads = workers or 1
        window = max(MIN_IN_FLIGHT, IN_FLIGHT_PER_THREAD * max(threads, 1))
        group_of: dict = {}
        ac = as_completed()

        def submit(count: int) -> None:
            for g in itertools.islice(groups, count):
                fut = client.submit(run_chunk, g, spec=spec_future, numba_threads=1,
                                    key=f"astrodyn-cases-{g[0]}-{len(g)}-{token}", pure=False)
                group_of[fut.key] = g
                submitted.append(fut)
                ac.add(fut)

        try:
            submit(window)
            while not ac.is_empty():
                _check_stop()
                batch = ac.next_batch(block=False)
                if not batch:
                    with ac.thread_condition:
                        ac.thread_condition.wait(timeout=0.1)
                    continue
                for fut in batch:
                    try:
                        rows = fut.result()
                    except Exception as exc:  # worker died (KilledWorker), lost data, ...
                        rows = [_failed_row(k, spec, exc) for k in group_of[fut.key]]
                    del group_of[fut.key]
                    fut.release()
                    yield from rows
                submit(len(batch))
                submitted[:] = [f for f in submitted if f.key in group_of]
        except BaseException:
            client.cancel([f for f in submitted if f.key in group_of])
            raise
    finally:
        if client is not None:
            close_dask(client)
        if cluster is not None:
            close_dask(cluster)
            if spec.mcap_dir:  # what a worker stopped by the close was writing (write_case_mcap)
                for tmp in Path(spec.mcap_dir).glob("case-*.mcap.tmp"):
                    tmp.unlink(missing_ok=True)


def start_local_cluster(workers: int):
    """:func:`local_cluster` started so that a Ctrl-C, which a terminal sends to the whole
    process group, reaches this process only, at any moment: the cluster is started from a
    helper thread that blocks SIGINT, and the worker processes it spawns inherit that
    signal mask (a process keeps it across fork and exec), so they never act on it; this
    process's main thread keeps its handler (:func:`astrodyn.signals.interruptible`), so a
    Ctrl-C or SIGTERM while the cluster starts is seen at once: the start is let finish,
    the cluster is closed and the interrupt goes on (no worker left).  Before, SIGINT was
    ignored by the whole process while the cluster started (the workers inherited that),
    so a Ctrl-C in that second or so was lost and the sweep ran on."""
    started: dict[str, Any] = {}
    done = threading.Event()

    def start() -> None:
        from multiprocessing import resource_tracker

        try:
            # the tracker first: starting it unblocks SIGINT in the thread that starts it (CPython)
            resource_tracker.ensure_running()
            signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
            started["cluster"] = local_cluster(workers)
        except BaseException as exc:  # handed to the caller's thread
            started["error"] = exc
        finally:
            done.set()

    threading.Thread(target=start, name="astrodyn-cluster-start", daemon=True).start()
    try:
        # a stop signal's handler runs here, in the main thread (not Thread.join: on Python 3.11
        # a join cut by an exception marks the thread as ended while it still runs)
        while not done.wait(0.05):
            pass
    except BaseException:
        done.wait()
        if "cluster" in started:
            close_dask(started["cluster"])
        raise
    if "error" in started:
        raise started["error"]
    return started["cluster"]


class CaseProgress:
    """The sweep's progress on stderr through the one progress printer
    (:class:`astrodyn.progress.Progress`: in place on a terminal, every 5 s into a
    log): cases done and failed, rate, elapsed and remaining time, and a bar."""

    def __init__(self, total: int, enabled: bool = True, stream=None):
        from astrodyn.progress import Progress

        self.total = total
        self.done = self.failed = 0
        self.started = time.monotonic()
        self.printer = Progress(stream=stream, enabled=enabled)

    def line(self) -> str:
        elapsed = time.monotonic() - self.started
        rate = self.done / max(elapsed, 1e-9)
        eta = (self.total - self.done) / rate if rate > 0 else math.inf
        width = 30
        fill = int(width * self.done / max(self.total, 1))
        return (f"  [{'#' * fill}{'.' * (width - fill)}] {self.done}/{self.total} cases, {self.failed} failed, "
                f"{rate:.2f} cases/s, {elapsed:.0f} s elapsed, eta {eta:.0f} s")

    def update(self, row: dict) -> None:
        self.done += 1
        self.failed += row.get("status") != "ok"
        if self.done == self.total:
            self.printer.done(self.line())
        else:
            self.printer.show(self.line)


# --------------------------------------------------------------------------- tables


def _columns(rows: list[dict]) -> list[str]:
    """Column order: case, status, the draws and metrics in first-seen order, wall_s last."""
    cols: dict[str, None] = dict.fromkeys(_FIXED_COLUMNS)
    for row in rows:
        for key in row:
            if key not in ("error", "traceback", "wall_s"):
                cols.setdefault(key)
    cols["wall_s"] = None
    return list(cols)


def _cell(x: Any) -> str:
    if x is None:
        return ""
    if isinstance(x, float):
        return repr(x)
    if isinstance(x, (list, dict)):
        return json.dumps(x)
    return str(x)


def read_table(path: str | os.PathLike) -> list[dict[str, str]]:
    """Rows of a CSV written by :func:`write_tables` (cells as strings); ValueError (one line
    naming the file) for a file that is not such a table, not a regular file or too large
    (:func:`astrodyn.analysis.sweep.read_sweep_table`)."""
    from astrodyn.analysis.sweep import read_sweep_table

    return read_sweep_table(path)


def _written(path: Path, write, mode: str = "w") -> None:
    """``write(stream)`` into a new temporary file of ``path`` that takes the name only when
    complete (:func:`astrodyn.recording.outputs.written_atomically`, suffix ``.part``): a full
    disk or an interrupt leaves the earlier file whole and no temporary behind."""
    with written_atomically(path, ".part") as tmp:
        with open(tmp, mode, **({"newline": "", "encoding": "utf-8"} if "b" not in mode else {})) as fh:
            write(fh)


def _write_csv(path: Path, columns: list[str], rows: list[dict]) -> None:
    def write(fh) -> None:
        w = csv.writer(fh)
        w.writerow(columns)
        for row in rows:
            w.writerow([_cell(row.get(c)) for c in columns])

    _written(path, write)


def _draw_key(column: str, spec: SweepSpec) -> tuple[str, str] | None:
    """``(path, element)`` of a draw column: its ``--vary`` / ``--cases`` key path and ``"[i]"``
    for an element of a drawn vector (else ""); None for a metric column.
    ``bodies.sat1.attitude.w[2] [deg/s]`` -> ``("bodies.sat1.attitude.w", "[2]")``; a vector
    element drawn alone, ``bodies.sat1.attitude.w[0]``, is its own path (it was taken for
    an element of ``...attitude.w`` and left out of failures.csv and of the units)."""
    name = re.sub(r" \[[^\[\]]*\]$", "", column)
    if name in spec.resolved:
        return name, ""
    if (m := re.fullmatch(r"(.*)(\[\d+\])", name)) and m.group(1) in spec.resolved:
        return m.group(1), m.group(2)
    return None


#: a body's name in a key path of the scenario loader: ``bodies[0] (iss).orbit.e``
_LOADER_BODY_NAME = re.compile(r"\] \([^)]*\)")


def draw_units(spec: SweepSpec, columns: list[str], rows: list[dict]) -> dict[str, str]:
    """The unit of each draw column of ``columns`` (``sweep.json`` "columns"): the ``--vary``'s
    unit, in the column's name (``[km]``); else the SI unit in which the scenario loader reads
    that key (a draw without a unit is in SI, like a bare number in the config), found by
    loading case 0's config (the nominal one if case 0's fails) under
    :func:`astrodyn.scenario.fields.quantities_read`: ``m``, ``rad``, ``rad/s``, ``kg m2``, and
    ``1`` for a dimensionless quantity (``e``; a metric's ``e_final`` is ``1`` too).  ""
    for a key that is no quantity (a model name, a count) and for a ``--cases`` column whose
    cells carry their own units (``"7000 km"``).  Before, every such column said ``SI``."""
    from astrodyn.scenario import load_dict
    from astrodyn.scenario.fields import QUANTITY_KINDS, quantities_read

    kinds: dict[str, str] = {}
    for config in (lambda: spec.case_config(0)[0], lambda: spec.config):
        with quantities_read() as read:
            try:
                load_dict(config(), source=spec.source, base_dir=spec.base_dir)
            except Exception:  # a config that fails: its case's row says why
                continue
        kinds = {_LOADER_BODY_NAME.sub("]", key): values[0][0] for key, values in read.items()}
        break
    units: dict[str, str] = {}
    for c in columns:
        if (key := _draw_key(c, spec)) is None:
            continue
        if m := re.search(r" \[([^\[\]]+)\]$", c):
            units[c] = m.group(1)
        elif any(isinstance(r.get(c), str) for r in rows):
            units[c] = ""
        else:
            path, element = key
            kind = kinds.get(_join(spec.resolved[path]) + element)
            units[c] = "" if kind is None else (QUANTITY_KINDS[kind][0].replace(" / ", "/") or "1")
    return units


def _typed(value: Any) -> Any:
    """A cell as a number when it is one (for Parquet), else the string (empty -> None)."""
    if value is None or value == "":
        return None
    if isinstance(value, str):
        try:
            return int(value) if re.fullmatch(r"-?\d+", value) else float(value)
        except ValueError:
            return value
    return value


def _parquet_column(values: list) -> list:
    """A column for Parquet: numbers typed (:func:`_typed`); a column holding an integer
    beyond int64 (``choice(2, 99999999999999999999)``) as text, which Parquet can hold."""
    typed = [_typed(v) for v in values]
    if any(isinstance(x, int) and not isinstance(x, bool) and not -2**63 <= x < 2**63 for x in typed):
        return [None if x is None else str(x) for x in typed]
    return typed


def write_tables(out: Path, rows: list[dict], spec: SweepSpec, extra: dict | None = None) -> dict[str, Path]:
    """Write summary.csv (+ .parquet), failures.csv, failures/, sweep.json into ``out``, each
    through a temporary file renamed when complete.  An OSError (disk full, read-only)
    propagates, naming the file; what was written before it is complete."""
    if not out.is_dir():  # moved away or removed mid-sweep: not made again elsewhere
        raise FileNotFoundError(2, "the output directory is gone", str(out))
    rows = sorted(rows, key=lambda r: int(r["case"]))
    columns = _columns(rows)
    paths = {"summary": out / "summary.csv", "failures": out / "failures.csv", "spec": out / "sweep.json"}
    _write_csv(paths["summary"], columns, rows)
    failed = [r for r in rows if r.get("status") != "ok"]
    draw_cols = [c for c in columns if _draw_key(c, spec) is not None]
    _write_csv(paths["failures"], ["case", "error", *draw_cols], failed)
    for r in failed:
        if r.get("traceback"):
            (out / "failures").mkdir(exist_ok=True)
            _written(out / "failures" / f"case-{int(r['case']):06d}.txt", lambda fh, r=r: fh.write(r["traceback"]))
    for r in rows:  # a rerun that now succeeds: the traceback of its earlier failure goes
        if r.get("status") == "ok":
            (out / "failures" / f"case-{int(r['case']):06d}.txt").unlink(missing_ok=True)
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        pa = None
    if pa is not None:
        try:
            table = pa.table({c: _parquet_column([r.get(c) for r in rows]) for c in columns})
        except (pa.ArrowInvalid, pa.ArrowTypeError, OverflowError) as exc:  # mixed types in a column: keep the CSV
            print(f"astrodyn sweep: summary.parquet not written ({_one_line(exc)[:300]})", file=sys.stderr)
            (out / "summary.parquet").unlink(missing_ok=True)  # not one of an earlier table
        else:
            _written(out / "summary.parquet", lambda fh: pq.write_table(table, fh), "wb")
            paths["parquet"] = out / "summary.parquet"
    drawn = draw_units(spec, columns, rows)
    units = {c: drawn[c] if c in drawn else METRIC_UNITS.get(c.rsplit(".", 1)[-1], "") for c in columns}
    done = {int(r["case"]) for r in rows}
    doc = spec.to_json() | {"columns": units, "cases_run": len(rows), "failed": len(failed),
                            "complete": len(done) == spec.n} | (extra or {})
    _write_spec(paths["spec"], doc)
    return paths


def _write_spec(path: Path, doc: dict) -> None:
    text = json.dumps(doc, indent=1, default=str)
    _written(path, lambda fh: fh.write(text))


def _merge(earlier: list[dict], new_rows: list[dict]) -> list[dict]:
    """``earlier`` rows (:func:`_earlier_rows`) with ``new_rows`` replacing the same cases."""
    replaced = {int(r["case"]) for r in new_rows}
    return [r for r in earlier if int(r["case"]) not in replaced] + list(new_rows)


#: Finished rows of a sweep not yet in its tables, one JSON object a line, appended as
#: each case finishes and removed once the tables are written: what a killed sweep keeps.
JOURNAL = "rows.jsonl"
MAX_JOURNAL_LINE = 4 * 2**20  #: longest line of the journal read back (a row with its traceback)


def _earlier_rows(out: Path) -> list[dict]:
    """The rows a ``--case`` rerun / ``--resume`` keeps: ``summary.csv`` (with the errors of
    ``failures.csv``), then the journal of a sweep that did not write its tables (killed),
    later rows replacing earlier ones.  Read before any case runs; SweepError (one line)
    for tables that are not a sweep's (the rerun's cases were computed, then a traceback)."""
    rows: dict[int, dict] = {}
    try:
        if (out / "summary.csv").exists() or (out / "summary.csv").is_symlink():
            errors: dict[str, str] = {}
            if (out / "failures.csv").exists():
                errors = {r["case"]: str(r.get("error") or "") for r in read_table(out / "failures.csv")}
            for r in read_table(out / "summary.csv"):
                r = {k: v for k, v in r.items() if v not in ("", None)}
                if r.get("status") != "ok" and r["case"] in errors:
                    r["error"] = errors[r["case"]]
                rows[int(r["case"])] = r
    except ValueError as exc:
        raise SweepError(f"--out {out}: {exc}; this rerun would replace that table: restore it, or run the sweep "
                         f"again into a new --out") from None
    for row in _journal_rows(out / JOURNAL):
        rows[int(row["case"])] = row
    return list(rows.values())


def _journal_rows(path: Path) -> Iterator[dict]:
    """Rows of a journal (:data:`JOURNAL`); a line cut by a kill, or not a row, is skipped."""
    from astrodyn.files import regular_file_problem

    if not (path.exists() or path.is_symlink()):
        return
    if problem := regular_file_problem(path):
        raise SweepError(f"--out {path}: {problem}")
    try:
        with open(path, "rb") as fh:
            while line := fh.readline(MAX_JOURNAL_LINE + 1):
                try:
                    row = json.loads(line)
                except (ValueError, RecursionError):
                    continue
                if isinstance(row, dict) and isinstance(row.get("case"), int) and not isinstance(row["case"], bool) \
                        and row["case"] >= 0:
                    yield row
    except OSError as exc:
        raise SweepError(f"--out {path}: cannot read the rows of the earlier run ({exc.strerror or exc})") from None


class _Journal:
    """Appends each finished row to ``out/rows.jsonl`` (opened at the first row): a sweep
    that is killed (SIGKILL, the OOM killer, a power cut) keeps its finished cases, and
    ``--resume`` completes it.  A write that fails (disk full) is reported once; the sweep
    goes on with the rows in memory."""

    def __init__(self, out: Path):
        self.path = out / JOURNAL
        self.fh = None
        self.failed: str | None = None

    def append(self, row: dict) -> None:
        if self.failed:
            return
        try:
            if self.fh is None:
                self.fh = open(self.path, "a", encoding="utf-8")
            self.fh.write(json.dumps(row, default=str) + "\n")
            self.fh.flush()
        except OSError as exc:
            self.failed = exc.strerror or str(exc)
            print(f"astrodyn sweep: warning: {self.path}: cannot write ({self.failed}); the finished rows are kept in "
                  f"memory only (lost if the sweep is killed)", file=sys.stderr)

    def close(self) -> None:
        if self.fh is not None:
            with contextlib.suppress(OSError):
                self.fh.close()
            self.fh = None

    def remove(self) -> None:
        self.close()
        with contextlib.suppress(OSError):
            self.path.unlink()


# --------------------------------------------------------------------------- CLI


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="astrodyn sweep", description="Monte Carlo dispersions / parameter sweeps of a "
                                 "scenario on Dask (a LocalCluster by default).",
                                 epilog="Dispersion syntax and output files: docs/sweeps.md.")
    ap.add_argument("config", type=path_argument, help="scenario TOML file (the nominal case)")
    ap.add_argument("--vary", action="append", default=[], metavar="PATH=DIST",
                    help="a dispersion, e.g. 'bodies.sat1.orbit.e=uniform(0.1, 0.9)' (repeatable): uniform(lo, hi), "
                         "normal(mean, sigma), choice(a, b, ...), grid(lo, hi, n) or grid([a, b, ...]), a plain value; "
                         "optional unit after it")
    ap.add_argument("--cases", metavar="FILE.csv", type=path_argument, help="a CSV of cases: header = key paths, one row per case")
    ap.add_argument("-n", type=int, default=None, help="number of cases (default: the grid size or the CSV rows)")
    ap.add_argument("--seed", type=int, default=0, help="random seed (default 0); case k uses default_rng([seed, k])")
    ap.add_argument("--scheduler", metavar="ADDRESS", help="a running Dask scheduler, e.g. tcp://10.0.0.5:8786")
    ap.add_argument("--workers", type=int, default=2,
                    help="LocalCluster worker processes (default 2, 1 thread each); 0 = serial in this process")
    ap.add_argument("--chunk", type=int, default=1, metavar="C",
                    help="cases per Dask task (default 1; raise it for cases of a few ms)")
    ap.add_argument("--case", action="append", type=int, default=None, metavar="K",
                    help="rerun only case K (repeatable), serially, updating the tables in --out")
    ap.add_argument("--resume", action="store_true",
                    help="run the cases the sweep in --out has no row for (one that was killed or interrupted) "
                         "and complete its tables")
    ap.add_argument("--mcap", action="store_true", help="also write one MCAP per case into OUT/mcap/")
    ap.add_argument("--case-memory", type=case_memory_argument, default=None, metavar="SIZE",
                    help='memory one case may take ("4 GiB", "500 MB" or a number of bytes); a case whose whole-run '
                         "arrays need more fails without making them. Default: half the machine's memory over the "
                         "cases run at once (--workers; 1 serially); with --scheduler, half each Dask worker's "
                         "memory limit")
    ap.add_argument("--out", required=True, metavar="DIR", type=path_argument,
                    help="output directory; one holding an earlier sweep's results is refused (a new directory, "
                         "--case K to rerun cases of that sweep, or --overwrite)")
    ap.add_argument("--overwrite", action="store_true",
                    help="replace the results of an earlier sweep in --out (its tables and its per-case files)")
    ap.add_argument("--quiet", action="store_true", help="no progress line")
    return ap


def case_memory_argument(text: str) -> int:
    """``--case-memory``: a size (``"4 GiB"``, ``"500 MB"``, units of the config's sizes) or a
    number of bytes, at least 1 byte (argparse's error naming the flag otherwise)."""
    from astrodyn.scenario.fields import flag_quantity

    size = flag_quantity("bytes", "bytes")(text)
    if not (isinstance(size, int) and 1 <= size <= MAX_CASE_MEMORY):  # 1e30 B would turn the guard off
        raise argparse.ArgumentTypeError(f'expected a size of 1 byte .. {MAX_CASE_MEMORY} bytes (1 PiB), e.g. "4 GiB", '
                                         f"got {text!r}")
    return size


#: Largest ``--case-memory``: more than any machine or Dask worker has (a larger value would
#: turn the memory guard off without saying so).
MAX_CASE_MEMORY = 2**50


def check_chunk(chunk: Any) -> None:
    """``--chunk``: an integer >= 1 (SweepError naming it)."""
    if not (isinstance(chunk, int) and chunk >= 1):
        raise SweepError(f"--chunk: expected an integer >= 1, got {chunk!r}")


#: Dask's comm protocols a ``--scheduler`` address may name (``tcp`` when none is given);
#: all but ``inproc`` (a scheduler in this very process: ``inproc://IP/PID/N``) take HOST:PORT.
#: ``tls``/``wss`` take their certificates from Dask's configuration (``distributed.comm.tls.*``),
#: ``ucx`` needs ucx-py; an address Dask cannot use is one line, exit 2 (:func:`_connect`).
SCHEDULER_PROTOCOLS = ("tcp", "tls", "ws", "wss", "ucx", "inproc")


def check_scheduler_address(address: str) -> str:
    """``--scheduler``: ``[PROTOCOL://]HOST:PORT`` with PROTOCOL one of
    :data:`SCHEDULER_PROTOCOLS`, HOST an IPv4 address, [IPv6 address] or host name and PORT
    1..65535 (:func:`astrodyn.bus.host_port_problem`); SweepError naming the flag, at once
    (a bad address was found only after 30 s of trying to reach it)."""
    from astrodyn.bus import host_port_problem

    protocol, sep, rest = address.partition("://")
    if not sep:
        protocol, rest = "tcp", address
    if protocol not in SCHEDULER_PROTOCOLS:
        problem = f"protocol {protocol[:40]!r} is not one of {', '.join(SCHEDULER_PROTOCOLS)}"
    else:
        problem = None if protocol == "inproc" else host_port_problem(rest.rstrip("/"))
    if problem is not None:
        shown = address if len(address) <= 200 else address[:200] + "..."
        raise SweepError(f"--scheduler: expected a Dask scheduler address [PROTOCOL://]HOST:PORT (PROTOCOL one of "
                         f"{', '.join(SCHEDULER_PROTOCOLS)}; PORT 1..65535), e.g. tcp://10.0.0.5:8786, got {shown!r}: "
                         f"{problem}")
    return address


#: The tables a sweep writes into --out (:func:`write_tables`).
RESULT_TABLES = ("summary.csv", "summary.parquet", "failures.csv", "sweep.json")
_CASE_FILE = re.compile(r"^case-\d{6,}\.(txt|mcap)$")
#: Temporary files of a sweep's tables and case files (:func:`_written`, :func:`write_case_mcap`)
_TEMPORARY = re.compile(r"^(?:(?:summary|failures|sweep)\.\d+-[0-9a-f]{8}\.(?:csv|parquet|json)\.part"
                        r"|(?:summary|failures)\.csv\.part|case-\d{6,}\.\d+-[0-9a-f]{8}\.(?:mcap\.tmp|txt\.part))$")


def earlier_results(out: Path) -> list[Path]:
    """The files an earlier sweep wrote into ``out``: its tables (:data:`RESULT_TABLES`), the
    journal of one that was killed (:data:`JOURNAL`) and its per-case files
    (``failures/case-K.txt``, ``mcap/case-K.mcap``); nothing else."""
    found = [out / name for name in (*RESULT_TABLES, JOURNAL) if (out / name).is_file()]
    for sub in ("failures", "mcap"):
        if (out / sub).is_dir():
            found += sorted(p for p in (out / sub).iterdir() if _CASE_FILE.match(p.name) and p.is_file())
    return found


def remove_temporaries(out: Path) -> list[Path]:
    """Remove the temporary files of sweeps into ``out`` that did not end (killed: a
    ``mcap/case-K.<pid>-<random>.mcap.tmp`` of several MB, a ``summary.<pid>-<random>.csv.part``).
    Called with the directory's lock held (:func:`claim_directory`): no other sweep of this
    machine writes there.  Returns them."""
    removed = []
    for folder in (out, out / "mcap", out / "failures"):
        if folder.is_dir():
            for p in folder.iterdir():
                if _TEMPORARY.match(p.name) and p.is_file():
                    with contextlib.suppress(OSError):
                        p.unlink()
                        removed.append(p)
    return removed


#: The lock file of a sweep's --out, held (``flock``) while the sweep runs and removed at its end.
LOCK_NAME = ".astrodyn-sweep.lock"


def claim_directory(out: Path) -> int:
    """Take the exclusive lock of ``out`` (``flock`` on :data:`LOCK_NAME` inside it) and
    return its file descriptor (:func:`release_directory`).  SweepError when another sweep
    holds it: two sweeps into one directory overwrote each other's tables and case files.
    The lock goes with the process (a killed sweep's too); the file is removed by its
    holder at the end, so the lock taken is checked to be the one at that name."""
    import fcntl

    path = out / LOCK_NAME
    for _ in range(20):
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | getattr(os, "O_CLOEXEC", 0), 0o644)
        except OSError as exc:
            raise SweepError(f"--out {out}: cannot create its lock file {LOCK_NAME} ({exc.strerror or exc})") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            try:
                holder = os.read(fd, 32).decode("ascii", "replace").strip()
            except OSError:
                holder = ""
            os.close(fd)
            who = f" (pid {holder})" if holder.isdigit() else ""
            raise SweepError(f"--out {out}: another astrodyn sweep{who} is writing into this directory; wait for it "
                             f"to end or choose another --out") from None
        try:
            same = os.path.samestat(os.fstat(fd), os.stat(path, follow_symlinks=False))
        except OSError:
            same = False
        if same:
            with contextlib.suppress(OSError):
                os.ftruncate(fd, 0)
                os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
            return fd
        os.close(fd)  # its holder removed it meanwhile: take the new one
    raise SweepError(f"--out {out}: cannot take its lock ({LOCK_NAME} keeps changing)")


def release_directory(out: Path, fd: int | None) -> None:
    """Remove the lock file of ``out`` (still holding the lock) and release it."""
    if fd is None:
        return
    with contextlib.suppress(OSError):
        if os.path.samestat(os.fstat(fd), os.stat(out / LOCK_NAME, follow_symlinks=False)):
            os.unlink(out / LOCK_NAME)
    os.close(fd)


#: The keys of sweep.json that define which cases a sweep runs (its spec); a ``--case``
#: rerun must have the same, or its rows would join another sweep's table.
SPEC_KEYS = ("n", "seed", "varies", "cases_csv_columns", "cases_csv_rows", "cases_csv_sha256", "grid_sizes", "config")


def check_out_directory(out: Path, spec: SweepSpec, rerun: bool, overwrite: bool, flag: str = "--case") -> None:
    """``--out`` against what it already holds: a new sweep never replaces an earlier one's
    results without ``--overwrite`` (an interrupted sweep would leave a partial table in
    place of a complete one, and case files of two sweeps would mix); a ``--case`` rerun
    or ``--resume`` updates only a sweep of the same spec (:data:`SPEC_KEYS`).  SweepError
    naming the flag."""
    from astrodyn.analysis.sweep import read_sweep_spec

    if rerun and overwrite:
        raise SweepError(f"--overwrite: expected either --overwrite (a new sweep replacing an earlier one) or {flag} "
                         f"(rerun cases of the sweep in --out, updating its tables), not both")
    earlier = earlier_results(out) if out.is_dir() else []
    if rerun:
        recorded = read_sweep_spec(out / "sweep.json")
        if earlier and recorded is None:
            raise SweepError(f"{flag}: {out} holds sweep results without a readable sweep.json; the rerun cannot "
                             f"tell whether they are of this sweep (expected the --out of the sweep to rerun)")
        if recorded is not None:
            current = json.loads(json.dumps(spec.to_json(), default=str))
            differ = [k for k in SPEC_KEYS if recorded.get(k) != current.get(k)]
            if differ == ["cases_csv_sha256"] and "cases_csv_sha256" not in recorded:
                raise SweepError(f"{flag}: {out} holds a sweep of a cases CSV whose sweep.json predates the CSV's "
                                 f"digest (cases_csv_sha256), so this rerun cannot check that --cases holds the same "
                                 f"cases; run the sweep again into a new --out")
            if differ:
                raise SweepError(f"{flag}: {out} holds a sweep of another spec (it differs in {', '.join(differ)}); "
                                 f"rerun with the config, --vary, --cases (the same rows), -n and --seed of that "
                                 f"sweep, or choose a new --out")
        return
    if earlier and not overwrite:
        shown = ", ".join(str(p.relative_to(out)) for p in earlier[:4]) + (f", ... ({len(earlier)} files)"
                                                                         if len(earlier) > 4 else "")
        how = ("complete it with --resume, rerun cases of that sweep with --case K"
               if (out / "sweep.json").is_file() else "")
        raise SweepError(f"--out {out}: holds the results of an earlier sweep ({shown}); they are never overwritten: "
                         f"choose a new directory, {how + ', ' if how else ''}or pass --overwrite to replace them")


def remove_earlier_results(out: Path) -> list[Path]:
    """``--overwrite``: remove what :func:`earlier_results` lists (only those files), so the
    new sweep's tables and case files never mix with the earlier one's; returns them."""
    removed = earlier_results(out)
    for path in removed:
        path.unlink()
    return removed


def max_local_workers() -> int:
    """The most ``--workers`` of a LocalCluster: 4 per core of this machine (each worker is a
    process that imports the numeric core; more only thrash)."""
    return 4 * (os.cpu_count() or 1)


@interruptible_main("astrodyn sweep")
def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    from astrodyn.scenario import ScenarioError

    try:
        if args.workers < 0:
            raise SweepError(f"--workers: expected an integer >= 0, got {args.workers}")
        if args.scheduler is None and args.workers > max_local_workers():
            raise SweepError(f"--workers: expected at most {max_local_workers()} local worker processes (4 per core; "
                             f"{os.cpu_count()} cores here), got {args.workers}")
        check_chunk(args.chunk)
        if args.scheduler is not None:
            check_scheduler_address(args.scheduler)
        if args.resume and args.case is not None:
            raise SweepError("--resume: expected either --resume (every case without a row) or --case K, not both")
        spec = make_spec(args.config, args.vary, n=args.n, seed=args.seed, cases_csv=args.cases)
        check_values_against_config(spec)
        spec.case_memory = args.case_memory
        if spec.case_memory is None and (args.scheduler is None or args.case is not None):  # cases run here
            spec.case_memory = default_case_memory(args.workers if args.case is None else 1)
        # --case K: the rows of those cases say it; the check's sample values may not be theirs
        memory_warnings = check_case_memory(spec) if args.case is None else []
        cases = list(range(spec.n)) if args.case is None else sorted(set(args.case))
        for k in cases:
            if not 0 <= k < spec.n:
                raise SweepError(f"--case: expected 0 <= K < {spec.n} (the sweep's -n), got {k}")
    except (SweepError, ScenarioError) as exc:
        print(f"astrodyn sweep: {exc}", file=sys.stderr)
        return 2
    rerun = args.case is not None or args.resume
    out = Path(args.out)
    created = not out.exists() and not out.is_symlink()
    lock: int | None = None
    try:  # the last checks, under the directory's lock: a refused sweep creates nothing
        try:
            if not created and not out.is_dir():
                raise SweepError(f"--out {out}: expected a directory, got {file_kind(os.stat(out).st_mode)}")
            out.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise SweepError(f"--out {str(out)[:200]}: expected a directory that can be created, got "
                             f"{exc.strerror or exc}") from None
        if not os.access(out, os.W_OK):
            raise SweepError(f"--out {out}: expected a writable directory")
        lock = claim_directory(out)
        check_out_directory(out, spec, rerun=rerun, overwrite=args.overwrite,
                            flag="--resume" if args.resume else "--case")
        earlier = _earlier_rows(out) if rerun else []
        if args.resume:
            have = {int(r["case"]) for r in earlier}
            cases = [k for k in range(spec.n) if k not in have]
        if args.mcap:
            spec.mcap_dir = str((out / "mcap").resolve())
    except (SweepError, ScenarioError) as exc:
        release_directory(out, lock)
        _remove_if_empty(out, created)
        print(f"astrodyn sweep: {exc}", file=sys.stderr)
        return 2
    for line in memory_warnings:
        print(f"astrodyn sweep: {line}", file=sys.stderr)
    try:
        return _sweep(args, spec, cases, out, created, earlier)
    finally:
        release_directory(out, lock)
        _remove_if_empty(out, created)


def _sweep(args: argparse.Namespace, spec: SweepSpec, cases: list[int], out: Path, created: bool,
           earlier: list[dict]) -> int:
    """The sweep proper, ``out`` claimed (:func:`claim_directory`) and checked."""
    rerun = args.case is not None or args.resume
    remove_temporaries(out)
    if args.overwrite:
        removed = remove_earlier_results(out)
        if removed and not args.quiet:
            print(f"astrodyn sweep: --overwrite: removed the {len(removed)} result files of the earlier sweep in {out}",
                  file=sys.stderr)
    started_spec = None if rerun else out / "sweep.json"
    workers, scheduler = (0, None) if args.case is not None else (args.workers, args.scheduler)
    where = "serially in this process" if workers == 0 and scheduler is None else (
        f"on the Dask scheduler {scheduler}" if scheduler else f"on a Dask LocalCluster of {workers} worker processes")
    progress = CaseProgress(len(cases), enabled=not args.quiet)
    journal = _Journal(out)
    rows: list[dict] = []
    started = time.monotonic()
    interrupted = 0
    try:  # from the spec's writing on: a stop signal at any moment ends the sweep below (nothing left behind)
        if started_spec is not None:  # the spec first: a sweep killed later can be completed (--resume)
            try:
                _write_spec(started_spec, spec.to_json() | {"cases_run": 0, "complete": False, "running": True})
            except OSError as exc:
                print(f"astrodyn sweep: --out {out}: cannot write sweep.json ({exc.strerror or exc}); nothing was run",
                      file=sys.stderr)
                return 1
        if not args.quiet:
            print(f"astrodyn sweep: {len(cases)} case(s) of {spec.source} {where}, seed {spec.seed}", file=sys.stderr)
        for row in run_cases(spec, cases, workers=workers, scheduler=scheduler, chunk=args.chunk):
            rows.append(row)
            journal.append(row)
            progress.update(row)
            if args.case is not None:
                shown = {k: v for k, v in row.items() if k != "traceback"}
                print(json.dumps(shown, default=str), flush=True)
    except SweepError as exc:
        journal.close()
        if not rows:
            _forget_start(started_spec, journal)
        print(f"astrodyn sweep: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:  # Ctrl-C or SIGTERM (astrodyn.signals.interruptible)
        interrupted = int(getattr(exc, "signum", signal.SIGINT))
    journal.close()
    all_rows = _merge(earlier, rows)
    _remove_unlisted_case_files(spec, cases, all_rows)
    if interrupted:
        name = signal.Signals(interrupted).name
        if not rows:  # nothing finished (the cluster was starting, say): nothing is written, --out as it was
            _forget_start(started_spec, journal)
            print(f"\nastrodyn sweep: interrupted by {name}; no case had finished, nothing was written",
                  file=sys.stderr)
            return 128 + interrupted
        print(f"\nastrodyn sweep: interrupted by {name}; writing the {len(rows)} finished cases", file=sys.stderr)
    wall = time.monotonic() - started
    versions = {"astrodyn": _version(), "numpy": np.__version__}
    try:
        import distributed

        versions["distributed"] = distributed.__version__
    except ImportError:
        pass
    extra = {"wall_s": wall, "workers": workers, "scheduler": scheduler, "versions": versions,
             "cases_per_s": len(rows) / wall if wall > 0 else None, "interrupted": bool(interrupted)}
    if rerun:  # keep the full run's record, note the rerun
        from astrodyn.analysis.sweep import read_sweep_spec

        previous = read_sweep_spec(out / "sweep.json") or {}
        keep = ("wall_s", "workers", "scheduler", "versions", "cases_per_s", "interrupted")
        # a rerun is listed once its cases are written: an interrupted one lists those that finished
        finished = sorted({int(r["case"]) for r in rows})
        reruns = previous.get("reruns") if isinstance(previous.get("reruns"), list) else []
        extra = {k: previous[k] for k in keep if k in previous}
        if args.resume:
            resumes = previous.get("resumes") if isinstance(previous.get("resumes"), list) else []
            extra |= {"reruns": reruns, "resumes": resumes + [len(finished)]} if reruns else \
                {"resumes": resumes + [len(finished)]}
        else:
            extra |= {"reruns": reruns + [finished]}
    try:
        write_tables(out, all_rows, spec, extra=extra)
    except OSError as exc:
        where_ = f"{exc.filename}: " if exc.filename else ""
        kept = (f"the rows of the {len(rows)} cases run are kept in {out / JOURNAL}: once the cause is fixed, the "
                f"same command with --resume writes the tables (without running them again)"
                if rows and not journal.failed else f"the rows of the {len(rows)} cases run are lost")
        print(f"astrodyn sweep: cannot write the tables into {out} ({where_}{exc.strerror or exc}); {kept}",
              file=sys.stderr)
        return 1
    journal.remove()
    failed = [r for r in rows if r.get("status") != "ok"]
    if not args.quiet:
        print(f"astrodyn sweep: {len(rows) - len(failed)} ok, {len(failed)} failed in {wall:.1f} s "
              f"({len(rows) / max(wall, 1e-9):.2f} cases/s); tables in {out}/", file=sys.stderr)
        for r in failed[:10]:
            err = str(r.get("error"))
            print(f"  case {r['case']}: {err if len(err) <= 300 else err[:300] + ' ...'}", file=sys.stderr)
        if len(failed) > 10:
            print(f"  ... {len(failed) - 10} more in {out / 'failures.csv'}", file=sys.stderr)
        if failed:
            print("  rerun one with the same command and --case K", file=sys.stderr)
    if interrupted:
        return 128 + interrupted
    return 1 if failed else 0


def _forget_start(started_spec: Path | None, journal: _Journal) -> None:
    """A new sweep of which no case finished writes nothing: its early sweep.json goes."""
    if started_spec is not None:
        with contextlib.suppress(OSError):
            started_spec.unlink()
        journal.remove()


def _remove_unlisted_case_files(spec: SweepSpec, cases: list[int], rows: list[dict]) -> None:
    """Remove ``mcap/case-K.mcap`` of this run's cases that have no row in the table: cases a
    Dask worker finished while the interrupted sweep closed its cluster (their rows never
    came back).  A case a rerun did not finish keeps its earlier file (it has its row)."""
    if not spec.mcap_dir or len(rows) >= spec.n:
        return
    have = {int(r["case"]) for r in rows}
    for k in cases:
        if k not in have:
            with contextlib.suppress(OSError):
                (Path(spec.mcap_dir) / f"case-{k:06d}.mcap").unlink()


def _remove_if_empty(out: Path, created: bool) -> None:
    """Remove ``out`` when this sweep made it and wrote nothing into it."""
    if created:
        with contextlib.suppress(OSError):
            out.rmdir()


def _version() -> str:
    from astrodyn import __version__

    return __version__


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
