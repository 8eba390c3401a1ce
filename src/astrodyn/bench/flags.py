"""Argparse ``type`` helpers of the benchmark suites: every flag of ``astrodyn bench SUITE``
is hostile input, checked when it is parsed.

Each helper returns a callable for ``add_argument(type=...)``: it turns the flag's text into
the value, or raises :class:`argparse.ArgumentTypeError` with one line naming the allowed
values and what was given; argparse prints it with the flag's name and exits 2, e.g.::

    astrodyn bench encode: error: argument --bodies: expected an integer 1 <= N <= 1000000, got '0'

Numbers are bounded on both sides (an upper bound keeps a run's memory and time within a
laptop's reach; each suite states its bounds in ``--help``), finite (``nan``, ``inf`` and
``1e400`` are refused) and, for integers, whole (``1e6`` is accepted, ``1.5`` is not).
Argparse also applies ``type`` to a string default, so a default goes through the same
check as a given value.

``astrodyn.service.children.wall_seconds`` (``--timeout``, ``--max-wall``) and
``astrodyn.bus.local_port`` are the service layer's own flag types; they have no upper bound
and no general range, so they are not reused here.  The conventions are the same: the text
as given (``repr``, cut to :data:`SHOWN_CHARS`) after ``got``.
"""

from __future__ import annotations

import argparse
import math
import os
from collections.abc import Callable

__all__ = ["SHOWN_CHARS", "existing_file", "float_in", "int_in", "int_list_in", "output_dir", "output_file",
           "parse_int", "problem", "scenario_file", "source_tree"]

SHOWN_CHARS = 40
"""At most this many characters of a refused value are echoed in the message."""


def _shown(text: str) -> str:
    text = str(text)
    return repr(text if len(text) <= SHOWN_CHARS else text[:SHOWN_CHARS] + "...")


def parse_int(text: str) -> int | None:
    """The whole number ``text`` spells (``42``, ``+42``, ``1_000``, ``1e6``, ``2.0``), or
    ``None`` (not a number, not whole, not finite).  Python's limit on the digits of an
    integer string (4300) bounds the work on a huge argument."""
    text = str(text)
    try:
        return int(text)
    except ValueError:
        pass
    try:
        value = float(text)
    except ValueError:
        return None
    return int(value) if math.isfinite(value) and value.is_integer() else None


def int_in(lo: int, hi: int) -> Callable[[str], int]:
    """Argparse type: an integer ``lo <= N <= hi``."""

    def parse(text: str) -> int:
        value = parse_int(text)
        if value is None or not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"expected an integer {lo} <= N <= {hi}, got {_shown(text)}")
        return value

    parse.__name__ = f"int_in({lo}, {hi})"
    return parse


def float_in(lo: float, hi: float) -> Callable[[str], float]:
    """Argparse type: a finite number ``lo <= X <= hi`` (``nan``, ``inf`` refused)."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not lo <= value <= hi:  # nan fails every comparison; inf is past any finite hi
            raise argparse.ArgumentTypeError(f"expected a number {lo:g} <= X <= {hi:g}, got {_shown(text)}")
        return value

    parse.__name__ = f"float_in({lo:g}, {hi:g})"
    return parse


def int_list_in(lo: int, hi: int, most: int = 20) -> Callable[[str], list[int]]:
    """Argparse type: 1 to ``most`` comma-separated integers, each ``lo <= N <= hi``
    (``"1,1000,1e6"``; spaces around the items are ignored, an empty item is refused)."""

    def parse(text: str) -> list[int]:
        items = str(text).split(",")
        values = [parse_int(item) for item in items[:most + 1]]
        out = [v for v in values if v is not None and lo <= v <= hi]
        if len(items) > most or len(out) != len(items):
            raise argparse.ArgumentTypeError(f"expected 1 to {most} comma-separated integers {lo} <= N <= {hi}, "
                                             f"got {_shown(text)}")
        return out

    parse.__name__ = f"int_list_in({lo}, {hi})"
    return parse


def _nearest_existing(path: str) -> str:
    """``path`` or its nearest ancestor that exists."""
    path = os.path.abspath(path)
    while not os.path.exists(path):
        parent = os.path.dirname(path)
        if parent == path:
            break
        path = parent
    return path


def output_file(text: str) -> str:
    """Argparse type: a file to write at the end of a run (``--md``, ``--json``,
    ``--markdown``): not a directory, in an existing writable directory.  Checked before
    the run, so a long benchmark does not end in a traceback with its results lost."""
    text = str(text)
    parent = os.path.dirname(os.path.abspath(text)) if text else ""
    if not text or os.path.isdir(text) or not os.path.isdir(parent) or not os.access(parent, os.W_OK):
        raise argparse.ArgumentTypeError(f"expected a file path in an existing writable directory, got {_shown(text)}")
    return text


def output_dir(text: str) -> str:
    """Argparse type: a directory to write into (``--out``, ``--keep``): an existing
    writable directory, or a path whose nearest existing ancestor is one (it is created
    when the run starts)."""
    text = str(text)
    base = _nearest_existing(text) if text else ""
    if not text or not os.path.isdir(base) or not os.access(base, os.W_OK | os.X_OK):
        raise argparse.ArgumentTypeError(f"expected a writable directory (or one that can be created), "
                                         f"got {_shown(text)}")
    return text


def existing_file(text: str) -> str:
    """Argparse type: an existing readable file (``--config``)."""
    text = str(text)
    if not text or not os.path.isfile(text) or not os.access(text, os.R_OK):
        raise argparse.ArgumentTypeError(f"expected an existing readable file, got {_shown(text)}")
    return text


def scenario_file(text: str) -> str:
    """Argparse type: a scenario config that loads (:func:`astrodyn.scenario.load`; its
    one-line error otherwise), so a run does not start on one its children refuse."""
    text = existing_file(text)
    from astrodyn.scenario import ScenarioError, load

    try:
        load(text)
    except ScenarioError as exc:
        raise argparse.ArgumentTypeError(f"expected a scenario config that loads: {exc}") from None
    return text


def source_tree(text: str) -> str:
    """Argparse type: a source tree holding ``astrodyn/__init__.py`` (``--baseline``: an older
    tree to time against, e.g. the ``src/`` of a ``git archive`` of a commit)."""
    text = str(text)
    if not text or not os.path.isfile(os.path.join(text, "astrodyn", "__init__.py")):
        raise argparse.ArgumentTypeError(f"expected a source tree holding astrodyn/__init__.py, got {_shown(text)}")
    return text


def problem(flag_type: Callable[[str], object], text: str) -> str | None:
    """What ``flag_type`` (one of the helpers above) says of ``text``, or ``None`` if it takes
    it: for a check after parsing that reports one line and returns exit status 2 itself."""
    try:
        flag_type(text)
    except argparse.ArgumentTypeError as exc:
        return str(exc)
    return None
