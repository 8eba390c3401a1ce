"""A flexible spacecraft in a config: the hub's ``appendages`` (``model = "flexible"``).

The model is :mod:`astrodyn.attitude.flexible` (H. Baruh, *Analytical Dynamics*, ch. 11;
assumed modes with the centrifugal stiffening of Kane, Ryan and Banerjee 1987).  The
attitude table describes the rigid hub (``inertia`` about the hub's mass centre, body
axes; ``mass`` the hub's mass) and lists its cantilevered beams::

    [bodies.attitude]
    model = "flexible"
    inertia = ["6.3 kg m2", "6.3 kg m2", "4.2 kg m2"]   # the hub alone
    mass = "20 kg"                                     # the hub alone
    w = [0.7, 0, 6.283]
    stiffening = true            # false: the classical linear model (no foreshortening)
    tolerance = 1e-9             # relative tolerance of the DOP853 integration (default 1e-10)
    [[bodies.attitude.appendages]]
    root = ["0.2 m", 0, 0]       # clamped end, body components, from the hub's mass centre
    axis = [1, 0, 0]             # undeformed beam direction e (default: along root)
    normal = [0, 0, 1]           # first bending direction f (perpendicular to e); g = e x f
    length = "2 m"
    mass_per_length = "0.3 kg/m"
    bending_stiffness = "34 N m2"
    modes = 1                    # assumed modes per bending plane, 1 to 8 (default 2)
    damping_ratio = 0.5          # modal damping of every mode (default 0: undamped)

The appendages' elastic state is published on ``<body>/appendages`` (``AppendageState``:
modal coordinates, their rates, tip displacements) at every output step, the hub's
attitude on ``<body>/attitude``.  Errors name the field, e.g. ``bodies[0] (sc).attitude.
appendages[1].normal: expected a direction perpendicular to axis, got [1, 0, 0]``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from astrodyn.scenario.fields import Ctx, Table, check, integer, quantity, vector

__all__ = ["Appendage", "parse_appendages", "MAX_APPENDAGES", "MAX_MODES", "DEFAULT_MODES",
           "DEFAULT_TOLERANCE", "parse_tolerance", "flexible_spacecraft", "appendage_message"]

#: Most appendages of one body, and modes per bending plane of each (the model's cost
#: grows with both: a scene pays for what it configures; docs/benchmarks.md).
MAX_APPENDAGES = 32
MAX_MODES = 8
DEFAULT_MODES = 2
#: Relative tolerance of the flexible model's DOP853 integration (absolute: 1e-3 of it).
DEFAULT_TOLERANCE = 1e-10

_KEYS = ("root", "axis", "normal", "length", "mass_per_length", "bending_stiffness", "modes", "damping_ratio")


@dataclass(frozen=True, eq=False)
class Appendage:
    """One cantilevered Euler-Bernoulli beam of a flexible spacecraft: ``root`` (m, body
    components from the hub's mass centre), unit ``axis`` e and ``normal`` f (body),
    ``length`` m, ``mass_per_length`` kg/m, ``bending_stiffness`` EI N m^2, ``modes`` per
    bending plane, ``damping_ratio`` of every mode."""

    root: np.ndarray
    axis: np.ndarray
    normal: np.ndarray
    length: float
    mass_per_length: float
    bending_stiffness: float
    modes: int = DEFAULT_MODES
    damping_ratio: float = 0.0


def _direction(ctx: Ctx, value: Any, path: str) -> np.ndarray:
    d = vector(ctx, value, "dimensionless", 3, path)
    n = float(np.linalg.norm(d))
    check(ctx, n > 0, path, "a non-zero direction (body components; normalized on load)", value)
    return d / n


def parse_appendages(ctx: Ctx, data: Any, path: str) -> tuple[Appendage, ...]:
    """The ``appendages`` list of a flexible body's attitude table (module docstring)."""
    if not isinstance(data, list) or not 1 <= len(data) <= MAX_APPENDAGES:
        raise ctx.error(path, f"a list of 1 to {MAX_APPENDAGES} appendage tables "
                        f"{{root, axis, normal, length, mass_per_length, bending_stiffness, modes, damping_ratio}}", data)
    out = []
    for k, item in enumerate(data):
        p = f"{path}[{k}]"
        tb = Table(ctx, item, p, _KEYS)
        root = vector(ctx, tb.get("root"), "length", 3, f"{p}.root")
        if tb.has("axis"):
            axis = _direction(ctx, tb.get("axis"), f"{p}.axis")
        else:
            n = float(np.linalg.norm(root))
            check(ctx, n > 0, f"{p}.axis", "an axis (it defaults to the root's direction, and root is at the origin)",
                  "nothing")
            axis = root / n
        normal = _direction(ctx, tb.get("normal"), f"{p}.normal")
        check(ctx, abs(float(axis @ normal)) <= 1e-9, f"{p}.normal",
              f"a direction perpendicular to axis {np.round(axis, 12).tolist()} (cos <= 1e-9)", tb.get("normal"))
        length = quantity(ctx, tb.get("length"), "length", f"{p}.length")
        check(ctx, length > 0, f"{p}.length", "length > 0", tb.get("length"))
        rho = quantity(ctx, tb.get("mass_per_length"), "linear_density", f"{p}.mass_per_length")
        check(ctx, rho > 0, f"{p}.mass_per_length", "mass_per_length > 0", tb.get("mass_per_length"))
        ei = quantity(ctx, tb.get("bending_stiffness"), "bending_stiffness", f"{p}.bending_stiffness")
        check(ctx, ei > 0, f"{p}.bending_stiffness", "bending_stiffness > 0", tb.get("bending_stiffness"))
        modes = integer(ctx, tb.get("modes", DEFAULT_MODES), f"{p}.modes", 1, MAX_MODES)
        raw_zeta = tb.get("damping_ratio", 0.0)
        zeta = quantity(ctx, raw_zeta, "dimensionless", f"{p}.damping_ratio")
        check(ctx, 0 <= zeta <= 10, f"{p}.damping_ratio", "0 <= damping_ratio <= 10", raw_zeta)
        out.append(Appendage(root=root, axis=axis, normal=normal - (normal @ axis) * axis, length=length,
                             mass_per_length=rho, bending_stiffness=ei, modes=modes, damping_ratio=zeta))
    return tuple(out)


def parse_tolerance(ctx: Ctx, value: Any, path: str) -> float:
    """The flexible model's relative integration tolerance, 1e-13 to 1e-3."""
    tol = quantity(ctx, value, "dimensionless", path)
    check(ctx, 1e-13 <= tol <= 1e-3, path, "a relative tolerance 1e-13 <= tolerance <= 1e-3", value)
    return tol


def flexible_spacecraft(hub_mass: float, hub_inertia: np.ndarray, appendages: tuple[Appendage, ...],
                        stiffening: bool = True):
    """The :class:`astrodyn.attitude.flexible.FlexibleSpacecraft` of a config's flexible
    body (modal basis; the root distance along the axis is the beam's hub radius)."""
    from astrodyn.attitude import flexible as fx

    apps = []
    for a in appendages:
        r = max(float(a.root @ a.axis), 0.0)
        beam = fx.beam_matrices(a.modes, a.bending_stiffness, a.mass_per_length, a.length, r=r,
                                damping_ratio=a.damping_ratio)
        apps.append(fx.Appendage(beam, a.axis, a.normal, root=a.root))
    return fx.FlexibleSpacecraft(hub_mass, hub_inertia, tuple(apps), stiffening=stiffening)


def appendage_message(spacecraft, y: np.ndarray, t: float, seq: int, tip: np.ndarray | None = None) -> dict:
    """The :class:`astrodyn.messages.AppendageState` of the flexible spacecraft's state ``y``
    (:func:`astrodyn.attitude.flexible.state_layout`) at ``t``: per appendage its modal
    coordinates, their rates and the tip's displacement (m, body axes; ``tip`` when already
    computed, else from ``y``).  The attitude process and the closed loop's plant both
    publish it."""
    from astrodyn.attitude import flexible as fx

    lay = fx.state_layout(spacecraft)
    tip = fx.tip_deflections(spacecraft, y) if tip is None else tip
    return {"t": t, "seq": seq, "eta": [y[s].tolist() for s in lay["eta_k"]],
            "eta_dot": [y[s].tolist() for s in lay["eta_dot_k"]], "tip": np.asarray(tip).tolist()}
