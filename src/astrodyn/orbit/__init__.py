"""Two-body orbit core: Kepler solvers, exact propagation on every conic, elements, perturbations.

Pure numeric code (numpy + numba), SI units (m, m/s, s, m^3/s^2), angles in
radians, arrays of shape ``(..., 3)`` in and out; a single state works too
(docs/architecture.md, section 2).

* :func:`propagate` -- ``(r, v)`` after ``dt`` on ellipse, parabola or hyperbola
  (:mod:`astrodyn.orbit.universal`).
* :func:`propagate_scalar` -- one state as six floats in and out (the cheap call of a control loop).
* :func:`lagrange_coefficients` -- the ``f, g, fdot, gdot`` behind it.
* :func:`stumpff` -- Stumpff functions ``c2, c3`` of the universal variable.
* :func:`solve_kepler`, :func:`solve_kepler_hyperbolic` -- Kepler's equation
  (:mod:`astrodyn.orbit.kepler`; its floating-point toolkit: :mod:`astrodyn.orbit.floating`).
* elements and anomalies (:mod:`astrodyn.orbit.elements`), perturbations and the
  perturbed propagator (:mod:`astrodyn.orbit.perturbations`), manoeuvres
  (:mod:`astrodyn.orbit.maneuvers`).
* the argument checks of the whole core (:mod:`astrodyn.inputs`): real numbers only
  (:class:`~astrodyn.inputs.NonRealInputError`, a ``TypeError``, naming the argument for
  ``None``, complex, strings, bools, object arrays holding anything but ints and floats)
  and ``ValueError`` naming each argument and its shape when shapes do not broadcast.
"""

from astrodyn.orbit import elements, perturbations
from astrodyn.orbit.elements import *  # noqa: F403 - re-export: elements.__all__ is the public list
from astrodyn.orbit.kepler import solve_kepler, solve_kepler_hyperbolic
from astrodyn.orbit.perturbations import *  # noqa: F403 - re-export: perturbations.__all__ is the public list
from astrodyn.orbit.universal import lagrange_coefficients, propagate, propagate_scalar, stumpff

__all__ = [
    "propagate",
    "propagate_scalar",
    "lagrange_coefficients",
    "stumpff",
    "solve_kepler",
    "solve_kepler_hyperbolic",
    *elements.__all__,
    *perturbations.__all__,
]
