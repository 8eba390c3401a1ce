"""Rate damping (detumbling) with a body torque and the rate gyro: u = -K w_gyro, clipped by
the plant to the torque actuator's limit per axis.  With u = -K w the rotational energy
decays (dT/dt = w . u = -K |w|^2 <= 0) whatever the inertia; the gyro's noise and bias
(a bias step is one of the faults configs/detumble.toml injects) set the floor.

Run it:  astrodyn run configs/detumble.toml --controller "python examples/detumble.py"
Options (environment): DETUMBLE_K (N m s, default 5.0), DETUMBLE_BODY (default "sc").
"""

import os

from astrodyn_link import Link


def main():
    gain = float(os.environ.get("DETUMBLE_K", "5.0"))
    body = os.environ.get("DETUMBLE_BODY", "sc")
    with Link() as link:
        while (tick := link.wait_tick()) is not None:
            gyro = link.latest(body, "gyro")
            if gyro is not None and gyro["t"] == tick["t"]:  # a fresh sample (none during a dropout)
                link.command(body, tick["t"], torque=[-gain * x for x in gyro["w"]])
            link.done(tick)


if __name__ == "__main__":
    main()
