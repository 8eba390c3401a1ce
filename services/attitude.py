"""Attitude propagator process: publishes every attitude state of a scenario on Zenoh.

    python services/attitude.py configs/demo.toml --connect tcp/127.0.0.1:7447 [--real-time-factor 10]

The same as ``python -m astrodyn.service.propagator attitude ...`` (what ``astrodyn run`` /
``serve`` start). Keys, batching and pacing: astrodyn.service.propagator.
"""

import sys

from astrodyn.service.propagator import service_main

if __name__ == "__main__":
    sys.exit(service_main("attitude"))
