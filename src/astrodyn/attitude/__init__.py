"""Rigid-body attitude dynamics (numeric core: numpy/numba, SI units, no I/O).

Conventions (docs/architecture.md, section 2; H. Baruh, *Analytical Dynamics*, ch. 7-10):
principal moments of inertia in kg m^2, body angular velocity ``w`` in rad/s
(body components), Euler parameters ``q = (e0, e1, e2, e3)`` scalar first with
``v_body = C(q) @ v_inertial`` and ``dC/dt = -[w x] C``.

* :func:`torque_free` -- exact torque-free motion (Jacobi elliptic functions
  and Carlson integrals; valid on every polhode, the separatrix and the
  intermediate-axis spin included), with :func:`polhode`, :func:`herpolhode`,
  :func:`rate_period`, :func:`flip_period` for analysis
  (:mod:`astrodyn.attitude.torque_free`).
* :mod:`astrodyn.attitude.elliptic` -- ``sn, cn, dn``, ``K``, ``F``, ``Pi`` and
  Carlson ``R_F, R_D, R_J`` taking ``m`` and ``m1 = 1 - m`` separately.
"""

from astrodyn.attitude.torque_free import flip_period, herpolhode, polhode, rate_period, torque_free

__all__ = ["torque_free", "polhode", "herpolhode", "rate_period", "flip_period"]

# --- other attitude modules: append their imports (and extend __all__) below this line ---
from astrodyn.attitude.euler import (
    angular_acceleration,
    attitude_state_rates,
    body_momentum_rates,
    euler_rates,
    inertia_tensor,
    principal_axes,
)
from astrodyn.attitude.flexible import Appendage, BeamModes, FlexibleSpacecraft, beam_matrices, propagate_spacecraft
from astrodyn.attitude.gyrocompass import Gyrocompass
from astrodyn.attitude.gyroscopes import FreeGyroscope, SingleAxisGyro, propagate_free_gyro, propagate_single_axis
from astrodyn.attitude.gyrostat import Gyrostat, spin_stability_product, spin_transverse_rate
from astrodyn.attitude.integrators import propagate_attitude
from astrodyn.attitude.rolling_disk import RollingDisk, propagate_rolling_disk
from astrodyn.attitude.top import HeavyTop
from astrodyn.attitude.torques import (
    ConstantTorque,
    GravityGradientTorque,
    TorqueSum,
    UniformGravityTorque,
    gravity_gradient_torque,
)

# one line per source module: fmt: skip keeps that grouping
__all__ += [
    "attitude_state_rates", "body_momentum_rates", "angular_acceleration", "euler_rates", "inertia_tensor", "principal_axes",
    "Gyrocompass", "Gyrostat", "spin_stability_product", "spin_transverse_rate", "propagate_attitude", "HeavyTop",
    "ConstantTorque", "GravityGradientTorque", "TorqueSum", "UniformGravityTorque", "gravity_gradient_torque",
    "RollingDisk", "propagate_rolling_disk",
    "Appendage", "BeamModes", "FlexibleSpacecraft", "beam_matrices", "propagate_spacecraft",
    "FreeGyroscope", "SingleAxisGyro", "propagate_free_gyro", "propagate_single_axis",
]  # fmt: skip
