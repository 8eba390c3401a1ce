"""Logger process: record one scenario from the Zenoh bus into an MCAP file.

    python services/logger.py --scenario demo --out demo.mcap --epoch-ns 1774008000000000000 \
        --connect tcp/127.0.0.1:7447 --expect orbit --expect attitude --config configs/demo.toml

The same as ``python -m astrodyn.service.logger`` (what ``astrodyn run`` / ``serve`` start).
Behaviour, exit status and the end-of-run protocol: astrodyn.service.logger.
"""

import sys

from astrodyn.service.logger import main

if __name__ == "__main__":
    sys.exit(main())
