"""astrodyn: orbital and attitude dynamics, exact where physics allows it.

Numeric core (pure numpy/numba, SI units, vectorized over leading axes):

* :mod:`astrodyn.orbit`     two-body propagation on every conic, Kepler solvers, elements, perturbations
* :mod:`astrodyn.rotation`  Euler parameters (scalar first), direction cosines, Euler angles
* :mod:`astrodyn.attitude`  rigid-body dynamics, exact torque-free motion, tops, gyrostats, torques

Thin layers around it: :mod:`astrodyn.scenario` (config), :mod:`astrodyn.messages`,
:mod:`astrodyn.bus` (Zenoh), :mod:`astrodyn.recording` (MCAP), :mod:`astrodyn.analysis`,
:mod:`astrodyn.bench`, :mod:`astrodyn.cli`.
"""

__version__ = "0.1.0"
