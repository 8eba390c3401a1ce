"""Output paths of a run: checked before anything starts."""

from __future__ import annotations

import os
from pathlib import Path

from astrodyn.scenario import ScenarioError

__all__ = ["check_output_path"]


def check_output_path(path: Path) -> None:
    """Raise :class:`~astrodyn.scenario.ScenarioError` naming ``--out`` unless ``path`` is a
    file path in an existing, writable directory."""
    parent = path.resolve().parent
    if not parent.is_dir():
        raise ScenarioError(f"--out {path}: expected a file in an existing directory, got missing directory {parent}")
    if not os.access(parent, os.W_OK):
        raise ScenarioError(f"--out {path}: expected a writable directory, {parent} is not writable")
    if path.is_dir():
        raise ScenarioError(f"--out {path}: expected a file path, got a directory")
