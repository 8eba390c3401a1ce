"""Attitude propagator process: publishes every attitude of a scenario on Zenoh.

    python services/attitude.py configs/demo.toml --connect tcp/127.0.0.1:7447 [--real-time-factor 10]

One message per body per output step on ``astrodyn/<scenario>/<body>/attitude`` (batched per
step on the bus, see astrodyn.propagator). Gravity-gradient torque uses the same orbit
engine as services/orbit.py. Started by ``astrodyn run`` / ``astrodyn serve``.
"""

import sys

from astrodyn.propagator import service_main

if __name__ == "__main__":
    sys.exit(service_main("attitude"))
