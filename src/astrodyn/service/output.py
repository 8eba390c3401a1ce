"""Output paths of a run: checked before anything starts.

A recording never overwrites an input or anything that is not a recording: ``--out`` that
names the config, another input file of the run, or an existing file that is not an MCAP
file is refused (exit 2, nothing written).  The logger writes ``NAME.partial.mcap`` and
renames it over ``NAME.mcap`` only when the file is finished, so a failed or killed run
leaves the previous recording intact and its own partial file for ``astrodyn recover``.
"""

from __future__ import annotations

import os
from pathlib import Path

from astrodyn.recording.reader import MCAP_MAGIC, RecordingError, open_recording
from astrodyn.recording.writer import being_written, partial_path
from astrodyn.scenario import ScenarioError

__all__ = ["check_output_path"]


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return False


def check_output_path(path: Path, inputs: tuple = ()) -> None:
    """Raise :class:`~astrodyn.scenario.ScenarioError` naming ``--out`` unless ``path`` is a
    file path in an existing, writable directory that is none of ``inputs`` (the config and
    any other file the run reads), is not an existing file other than an MCAP recording,
    and has no partial recording of a killed run beside it."""
    path = Path(path)
    parent = path.resolve().parent
    if not parent.is_dir():
        raise ScenarioError(f"--out {path}: expected a file in an existing directory, got missing directory {parent}")
    if not os.access(parent, os.W_OK):
        raise ScenarioError(f"--out {path}: expected a writable directory, {parent} is not writable")
    if path.is_dir():
        raise ScenarioError(f"--out {path}: expected a file path, got a directory")
    for given in inputs:
        if given is not None and (_same_file(path, Path(given)) or path.resolve() == Path(given).resolve()):
            raise ScenarioError(f"--out {path}: names an input of the run ({given}); expected a new .mcap path")
    if path.exists():
        try:  # non-blocking (a FIFO would hang the read), regular files only (a device is never a recording)
            f, _ = open_recording(str(path))
        except RecordingError as exc:  # "<path>: cannot open: <why>"
            why = str(exc).rpartition(": cannot open: ")[2]
            raise ScenarioError(f"--out {path}: exists and is not an MCAP recording ({why}); it is never written "
                                f"to (expected a new path or an earlier recording to replace)") from None
        with f:
            head = f.read(len(MCAP_MAGIC))
        if head != MCAP_MAGIC:
            raise ScenarioError(f"--out {path}: exists and is not an MCAP recording; it is never overwritten "
                                f"(expected a new path or an earlier recording to replace)")
    partial = Path(partial_path(path))
    if being_written(partial):
        raise ScenarioError(f"--out {path}: {partial} is being recorded right now by another run or serve (its "
                            f"logger holds it); choose another --out, or stop that one first")
    if partial.exists():
        raise ScenarioError(f"--out {path}: {partial} exists, the partial recording of a killed run; finish it with "
                            f"`astrodyn recover {partial}` (or remove it) before recording to {path} again")
