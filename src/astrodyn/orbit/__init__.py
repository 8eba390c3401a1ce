"""Two-body orbit core: Kepler solvers, exact propagation on every conic, elements, perturbations.

Pure numeric code (numpy + numba), SI units (m, m/s, s, m^3/s^2), angles in
radians, arrays of shape ``(..., 3)`` in and out; a single state works too.

* :func:`propagate` -- ``(r, v)`` after ``dt`` on ellipse, parabola or hyperbola
  (:mod:`astrodyn.orbit.universal`).
* :func:`lagrange_coefficients` -- the ``f, g, fdot, gdot`` behind it.
* :func:`stumpff` -- Stumpff functions ``c2, c3`` of the universal variable.
* :func:`solve_kepler`, :func:`solve_kepler_hyperbolic` -- Kepler's equation
  (:mod:`astrodyn.orbit.kepler`).
"""

from astrodyn.orbit.kepler import solve_kepler, solve_kepler_hyperbolic
from astrodyn.orbit.universal import lagrange_coefficients, propagate, stumpff

__all__ = [
    "propagate",
    "lagrange_coefficients",
    "stumpff",
    "solve_kepler",
    "solve_kepler_hyperbolic",
]

# --- elements and perturbations (astrodyn.orbit.elements / .perturbations) -------------
# Another module owner appends its imports and extends __all__ below this line.
from astrodyn.orbit import elements as _elements, perturbations as _perturbations  # noqa: E402
from astrodyn.orbit.elements import *  # noqa: E402,F401,F403
from astrodyn.orbit.perturbations import *  # noqa: E402,F401,F403

__all__ += _elements.__all__ + _perturbations.__all__
