"""Two-body orbit core: Kepler solvers, exact propagation on every conic, elements, perturbations.

Pure numeric code (numpy + numba), SI units (m, m/s, s, m^3/s^2), angles in
radians, arrays of shape ``(..., 3)`` in and out; a single state works too
(docs/architecture.md, section 2).

* :func:`propagate` -- ``(r, v)`` after ``dt`` on ellipse, parabola or hyperbola
  (:mod:`astrodyn.orbit.universal`).
* :func:`lagrange_coefficients` -- the ``f, g, fdot, gdot`` behind it.
* :func:`stumpff` -- Stumpff functions ``c2, c3`` of the universal variable.
* :func:`solve_kepler`, :func:`solve_kepler_hyperbolic` -- Kepler's equation
  (:mod:`astrodyn.orbit.kepler`; its floating-point toolkit: :mod:`astrodyn.orbit.floating`).
* elements and anomalies (:mod:`astrodyn.orbit.elements`), perturbations and the
  perturbed propagator (:mod:`astrodyn.orbit.perturbations`), manoeuvres
  (:mod:`astrodyn.orbit.maneuvers`).
"""

from astrodyn.orbit.elements import (
    SINGULAR_TOLERANCE,
    Elements,
    ModifiedEquinoctial,
    eccentric_from_true,
    elements_from_state,
    equinoctial_from_state,
    hyperbolic_from_true,
    mean_from_eccentric,
    mean_from_hyperbolic,
    mean_from_true,
    state_from_elements,
    state_from_equinoctial,
    true_from_eccentric,
    true_from_hyperbolic,
    true_from_mean,
)
from astrodyn.orbit.kepler import solve_kepler, solve_kepler_hyperbolic
from astrodyn.orbit.perturbations import (
    EARTH_EGM2008,
    EARTH_WGS84,
    MOON,
    SUN,
    CentralBody,
    KeplerOrbit,
    PerturbedStates,
    ThirdBody,
    Zonal,
    point_mass_difference,
    propagate_perturbed,
    third_body_acceleration,
    zonal_acceleration,
    zonal_potential,
)
from astrodyn.orbit.universal import lagrange_coefficients, propagate, stumpff

__all__ = [
    "propagate",
    "lagrange_coefficients",
    "stumpff",
    "solve_kepler",
    "solve_kepler_hyperbolic",
    # astrodyn.orbit.elements
    "SINGULAR_TOLERANCE",
    "Elements",
    "ModifiedEquinoctial",
    "elements_from_state",
    "state_from_elements",
    "equinoctial_from_state",
    "state_from_equinoctial",
    "eccentric_from_true",
    "true_from_eccentric",
    "hyperbolic_from_true",
    "true_from_hyperbolic",
    "mean_from_eccentric",
    "mean_from_hyperbolic",
    "mean_from_true",
    "true_from_mean",
    # astrodyn.orbit.perturbations
    "CentralBody",
    "EARTH_EGM2008",
    "EARTH_WGS84",
    "MOON",
    "SUN",
    "Zonal",
    "ThirdBody",
    "KeplerOrbit",
    "PerturbedStates",
    "zonal_acceleration",
    "zonal_potential",
    "third_body_acceleration",
    "point_mass_difference",
    "propagate_perturbed",
]
