"""Orbit propagator process: publishes every orbit of a scenario on Zenoh.

    python services/orbit.py configs/demo.toml --connect tcp/127.0.0.1:7447 [--real-time-factor 10]

One message per body per output step on ``astrodyn/<scenario>/<body>/orbit`` (batched per
step on the bus, see astrodyn.propagator). Started by ``astrodyn run`` / ``astrodyn serve``.
"""

import sys

from astrodyn.propagator import service_main

if __name__ == "__main__":
    sys.exit(service_main("orbit"))
