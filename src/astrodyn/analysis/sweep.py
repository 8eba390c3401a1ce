"""Plots and statistics of an ``astrodyn sweep`` output directory (``summary.csv`` + ``sweep.json``).

>>> from astrodyn.analysis.sweep import sweep_report
>>> report = sweep_report("sweep-leo", "sweep-leo/report")     # doctest: +SKIP

Writes into ``out`` (default ``<dir>/report``):

* ``metrics-hist.png`` -- a histogram per metric that varies across the cases (at most
  :data:`MAX_PANELS` per figure: ``metrics-hist-2.png`` ... for more);
* ``scatter-<parameter>.png`` -- per dispersed parameter, the metrics most correlated
  with it (Spearman rank correlation, at most 6) against it; failed cases are marked as
  red ticks on the parameter axis;
* ``report.md`` -- counts, the statistics table (n, mean, std, min, 5 %, median, 95 %,
  max of every numeric column), the first failures, and the figures;
* ``report.json`` -- the same numbers.

The files are written in a work directory inside ``out`` and moved into place only once
every one is complete (pages last), so an interrupted or failed report leaves an earlier one
there whole (:func:`astrodyn.recording.outputs.staging_directory`).

Units come from ``sweep.json`` (``columns``: column -> SI unit); plots show lengths in km,
angles in deg and rates in deg/s (axis labels say so); the tables keep SI.  matplotlib
with the Agg backend (no display needed).
"""

from __future__ import annotations

import csv
import json
import math
import os
import re
from pathlib import Path

import numpy as np

from astrodyn.recording.outputs import staging_directory
from astrodyn.signals import deferred_interrupts

__all__ = ["sweep_report", "is_sweep_dir", "MAX_PANELS", "MAX_TABLE_BYTES", "MAX_SPEC_BYTES", "read_sweep_table",
           "read_sweep_spec"]

MAX_TABLE_BYTES = 512 * 2**20  #: largest summary.csv / failures.csv read back (~500,000 cases of ~1 kB)
MAX_SPEC_BYTES = 64 * 2**20  #: largest sweep.json read back (it holds the config, not the cases)

MAX_PANELS = 16  #: histogram panels per figure
ROUND_OFF = 1e-13  #: a metric whose relative spread is below this (~450 ulp) is reported as constant
_DISPLAY = {"m": (1e-3, "km"), "rad": (180.0 / math.pi, "deg"), "rad/s": (180.0 / math.pi, "deg/s")}
_SKIP = {"case", "status"}


def is_sweep_dir(path: str | os.PathLike) -> bool:
    """True when ``path`` is a directory holding a sweep's ``summary.csv``."""
    p = Path(path)
    return p.is_dir() and (p / "summary.csv").is_file()


def _bounded_file(path: Path, limit: int, what: str):
    """``path`` opened for text reading once it is a regular file (symlinks followed) of at
    most ``limit`` bytes; ValueError naming it otherwise (a FIFO blocked the reader, /dev/zero
    or a huge file filled the memory)."""
    from astrodyn.files import regular_file_problem

    if problem := regular_file_problem(path):
        raise ValueError(f"{path}: {problem} ({what})")
    size = os.path.getsize(path)
    if size > limit:
        raise ValueError(f"{path}: expected {what} of at most {limit} bytes, got {size} bytes")
    return open(path, newline="", encoding="utf-8")


def read_sweep_table(path: str | os.PathLike, key: str = "case") -> list[dict[str, str]]:
    """Rows of a sweep table (summary.csv, failures.csv) as dicts of strings, each with an
    integer ``key`` cell; ValueError (one line naming the file) for anything else: not a
    regular file, over :data:`MAX_TABLE_BYTES`, not UTF-8 CSV, no or a non-integer ``key``."""
    path = Path(path)
    what = "the table of a sweep (UTF-8 CSV)"
    try:
        with _bounded_file(path, MAX_TABLE_BYTES, what) as fh:
            reader = csv.DictReader(fh)
            fields = reader.fieldnames or []
            if fields and key not in fields:
                raise ValueError(f"{path}: expected {what} with a {key!r} column, got the columns "
                                 f"{', '.join(map(str, fields[:8]))[:200]}")
            rows = []
            for row in reader:
                cell = row.get(key)
                if not (isinstance(cell, str) and re.fullmatch(r"\d{1,18}", cell.strip())):
                    raise ValueError(f"{path}: line {reader.line_num}: expected a case number in the {key!r} column, "
                                     f"got {str(cell)[:40]!r}")
                row[key] = cell.strip()
                rows.append({str(k): v for k, v in row.items() if k is not None})
            return rows
    except (UnicodeDecodeError, csv.Error) as exc:
        raise ValueError(f"{path}: expected {what}, got {' '.join(str(exc).split())[:200]}") from None
    except OSError as exc:
        raise ValueError(f"{path}: cannot read {what}: {exc.strerror or exc}") from None


def read_sweep_spec(path: str | os.PathLike) -> dict | None:
    """``sweep.json`` as a dict; None when it is missing, not a regular file, over
    :data:`MAX_SPEC_BYTES`, not JSON or not an object (never a read without limit)."""
    try:
        with _bounded_file(Path(path), MAX_SPEC_BYTES, "the spec of a sweep") as fh:
            doc = json.loads(fh.read())
    except (OSError, ValueError, RecursionError):
        return None
    return doc if isinstance(doc, dict) else None


def _load(dir_: Path) -> tuple[list[dict], dict]:
    rows = read_sweep_table(dir_ / "summary.csv")
    spec = read_sweep_spec(dir_ / "sweep.json") or {}
    return rows, spec


def _numeric_columns(rows: list[dict]) -> dict[str, np.ndarray]:
    """Columns whose non-empty cells are all numbers, as float arrays (NaN for empty)."""
    out = {}
    if not rows:
        return out
    for col in rows[0]:
        if col in _SKIP:
            continue
        vals = []
        for r in rows:
            cell = r.get(col, "")
            if cell == "":
                vals.append(math.nan)
                continue
            try:
                vals.append(float(cell))
            except ValueError:
                break
        else:
            out[col] = np.array(vals, dtype=np.float64)
    return out


def _label(col: str, unit: str) -> tuple[str, float]:
    """Axis label with the display unit, and the factor SI -> display."""
    factor, shown = _DISPLAY.get(unit, (1.0, unit))
    base = re.sub(r" \[[^\[\]]*\]$", "", col)
    if unit in ("1", "") or unit is None:
        return f"{base} (dimensionless)" if unit == "1" else base, 1.0
    if unit == "SI":
        return f"{base} (SI)", 1.0
    return f"{base} [{shown}]", factor


def _spearman(x: np.ndarray, y: np.ndarray) -> float:
    """Spearman rank correlation of the finite pairs (ties get ordinal ranks; 0 if undefined)."""
    ok = np.isfinite(x) & np.isfinite(y)
    if ok.sum() < 3:
        return 0.0
    rx = np.argsort(np.argsort(x[ok])).astype(float)
    ry = np.argsort(np.argsort(y[ok])).astype(float)
    if rx.std() == 0 or ry.std() == 0:
        return 0.0
    return float(np.corrcoef(rx, ry)[0, 1])


def _stats(x: np.ndarray) -> dict:
    f = x[np.isfinite(x)]
    if f.size == 0:
        return {"n": 0}
    p5, p50, p95 = np.percentile(f, [5, 50, 95])
    return {"n": int(f.size), "mean": float(f.mean()), "std": float(f.std(ddof=1)) if f.size > 1 else 0.0,
            "min": float(f.min()), "p05": float(p5), "median": float(p50), "p95": float(p95), "max": float(f.max())}


def sweep_report(dir: str | os.PathLike, out: str | os.PathLike | None = None) -> dict:
    """Histograms, scatter plots and a statistics table of the sweep in ``dir`` (module docstring).

    Returns ``{"cases", "ok", "failed", "stats": {column: {...}}, "figures": [paths],
    "report": path}``.  ValueError if ``dir`` holds no ``summary.csv``.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    dir_ = Path(dir)
    if not is_sweep_dir(dir_):
        raise ValueError(f"dir: expected a sweep output directory with summary.csv, got {dir_}")
    final = Path(out) if out is not None else dir_ / "report"
    rows, spec = _load(dir_)
    # written in a work directory inside the report directory and moved into place once
    # complete, pages last: an interrupt or a failure leaves an earlier report whole
    # (astrodyn.recording.outputs, as for the report of a recording)
    with staging_directory(final, "analyze") as out_:
        result = _write_report(dir_, out_, final, rows, spec, plt)
        with deferred_interrupts():
            for f in sorted(out_.iterdir(), key=lambda f: (f.name.startswith("report."), f.name)):
                os.replace(f, final / f.name)
    return result


def _write_report(dir_: Path, out_: Path, final: Path, rows: list[dict], spec: dict, plt) -> dict:
    """Write the figures, report.md and report.json of the sweep in ``dir_`` into ``out_``
    (the paths they name: in ``final``, where they are moved)."""
    units: dict[str, str] = ({str(k): v for k, v in spec["columns"].items() if isinstance(v, str)}
                             if isinstance(spec.get("columns"), dict) else {})
    varies = [v for v in spec.get("varies", []) if isinstance(v, dict)] if isinstance(spec.get("varies"), list) else []
    csv_columns = spec.get("cases_csv_columns") if isinstance(spec.get("cases_csv_columns"), list) else []
    varied = {v.get("path") for v in varies if isinstance(v.get("path"), str)} | {str(c) for c in csv_columns}
    status = np.array([r.get("status") == "ok" for r in rows], dtype=bool)
    cols = _numeric_columns(rows)
    is_param = {c: re.sub(r"\[\d+\]$", "", re.sub(r" \[[^\[\]]*\]$", "", c)) in varied for c in cols}
    params = [c for c in cols if is_param[c] and np.nanstd(cols[c]) > 0]
    metrics, constant = [], []
    for c in cols:
        x = cols[c][status]
        if is_param[c] or not np.any(np.isfinite(x)):
            continue
        lo, hi = np.nanmin(x), np.nanmax(x)
        # a spread of a few ulp is round-off (e.g. a Kepler orbit's final a): nothing to plot
        (metrics if hi - lo > ROUND_OFF * max(abs(lo), abs(hi)) else constant).append(c)
    stats = {c: _stats(cols[c][status] if not is_param[c] else cols[c]) for c in cols}
    figures: list[Path] = []

    # histograms of the metrics over the successful cases
    for page in range(0, len(metrics), MAX_PANELS):
        chunk = metrics[page: page + MAX_PANELS]
        ncol = min(4, len(chunk))
        nrow = math.ceil(len(chunk) / ncol)
        fig, axes = plt.subplots(nrow, ncol, figsize=(3.6 * ncol, 2.9 * nrow), squeeze=False)
        for ax, c in zip(axes.flat, chunk):
            label, f = _label(c, units.get(c, ""))
            x = cols[c][status] * f
            ax.hist(x[np.isfinite(x)], bins=max(5, min(40, int(np.sqrt(status.sum())) + 1)), color="tab:blue", alpha=0.8)
            ax.set_xlabel(label, fontsize=8)
            ax.set_ylabel("cases")
            ax.tick_params(labelsize=7)
        for ax in list(axes.flat)[len(chunk):]:
            ax.axis("off")
        fig.suptitle(f"sweep metrics, {int(status.sum())} successful cases of {len(rows)}")
        fig.tight_layout()
        path = out_ / ("metrics-hist.png" if page == 0 else f"metrics-hist-{page // MAX_PANELS + 1}.png")
        fig.savefig(path, dpi=90)
        plt.close(fig)
        figures.append(path)

    # per parameter: the most correlated metrics against it
    correlations: dict[str, dict[str, float]] = {}
    for p in params:
        ranked = sorted(((abs(_spearman(cols[p][status], cols[m][status])), m) for m in metrics if m != "wall_s"),
                        reverse=True)
        correlations[p] = {m: round(r, 4) for r, m in ranked}
        pick = [m for _, m in ranked[:6]]
        if not pick:
            continue
        ncol = min(3, len(pick))
        nrow = math.ceil(len(pick) / ncol)
        fig, axes = plt.subplots(nrow, ncol, figsize=(4.2 * ncol, 3.3 * nrow), squeeze=False)
        plabel, pf = _label(p, units.get(p, ""))
        for ax, m in zip(axes.flat, pick):
            mlabel, mf = _label(m, units.get(m, ""))
            ax.scatter(cols[p][status] * pf, cols[m][status] * mf, s=8, alpha=0.7, label="ok")
            if (~status).any():
                ax.plot(cols[p][~status] * pf, np.full((~status).sum(), np.nanmin(cols[m][status] * mf)), "|",
                        color="tab:red", markersize=12, label="failed")
                ax.legend(fontsize=7)
            ax.set_xlabel(plabel, fontsize=8)
            ax.set_ylabel(mlabel, fontsize=8)
            ax.set_title(f"Spearman rho = {_spearman(cols[p][status], cols[m][status]):+.2f}", fontsize=8)
            ax.tick_params(labelsize=7)
        for ax in list(axes.flat)[len(pick):]:
            ax.axis("off")
        fig.tight_layout()
        safe = re.sub(r"[^A-Za-z0-9_.-]+", "_", re.sub(r" \[[^\[\]]*\]$", "", p)).strip("_")
        path = out_ / f"scatter-{safe}.png"
        fig.savefig(path, dpi=90)
        plt.close(fig)
        figures.append(path)

    failures = [r for r in rows if r.get("status") != "ok"]
    errors = {}
    if failures and (dir_ / "failures.csv").exists():
        errors = {r["case"]: str(r.get("error") or "") for r in read_sweep_table(dir_ / "failures.csv")}
    lines = [f"# Sweep report: {dir_}", "",
             f"{len(rows)} cases, {int(status.sum())} ok, {len(failures)} failed; seed {spec.get('seed', '?')}, "
             f"config {spec.get('source', '?')}.", ""]
    if varies:
        lines += ["Dispersions:", ""] + [f"- `{v.get('text')}`" for v in varies] + [""]
    lines += ["| column | unit | n | mean | std | min | 5 % | median | 95 % | max |", "|---|---|---|---|---|---|---|---|---|---|"]
    for c, s in stats.items():
        if s.get("n"):
            lines.append(f"| {c} | {units.get(c, '')} | {s['n']} | " + " | ".join(
                f"{s[k]:.6g}" for k in ("mean", "std", "min", "p05", "median", "p95", "max")) + " |")
    if constant:
        lines += ["", f"Constant over the successful cases (spread below {ROUND_OFF:g} relative, round-off): "
                  + ", ".join(constant) + "."]
    if failures:
        lines += ["", "## Failures", ""]
        lines += [f"- case {r['case']}: {errors.get(r['case'], '')[:300]}" for r in failures[:20]]
        if len(failures) > 20:
            lines.append(f"- ... {len(failures) - 20} more in failures.csv")
    lines += ["", "## Figures", ""] + [f"![{p.stem}]({p.name})" for p in figures]
    (out_ / "report.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    result = {"cases": len(rows), "ok": int(status.sum()), "failed": len(failures), "stats": stats, "constant": constant,
              "correlations": correlations, "figures": [str(final / p.name) for p in figures],
              "report": str(final / "report.md")}
    (out_ / "report.json").write_text(json.dumps(result, indent=1), encoding="utf-8")
    return result
