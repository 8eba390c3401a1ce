"""Hohmann transfer by two impulsive burns (Vallado, *Fundamentals of Astrodynamics and
Applications*, 4th ed., sec. 6.3.1, Algorithm 36).

At the first control step the controller reads the orbit (circular, radius r1), and
commands both burns at once: dv1 = sqrt(mu/r1) (sqrt(2 r2 / (r1 + r2)) - 1) along the
velocity at t0, and dv2 = sqrt(mu/r2) (1 - sqrt(2 r1 / (r1 + r2))) along the velocity at
apoapsis, half a transfer orbit later (tof = pi sqrt(a_t^3 / mu)), where the velocity is
opposite to the one at t0.  The plant applies each impulse at its own time, inside the
control step if need be; every later step is answered with no command.

Run it:  astrodyn run configs/hohmann.toml --controller "python examples/hohmann.py"
Options (environment): HOHMANN_R2 (target radius, m; default 42159485.57, Vallado's
Example 6-1 GEO), HOHMANN_BODY (default "sat").
"""

import math
import os

from astrodyn_link import Link


def main():
    r2 = float(os.environ.get("HOHMANN_R2", "42159485.57"))
    body = os.environ.get("HOHMANN_BODY", "sat")
    with Link() as link:
        planned = False
        while (tick := link.wait_tick()) is not None:
            if not planned:
                state = link.latest(body, "orbit")
                r, v, mu = state["r"], state["v"], state["mu"]
                r1 = math.sqrt(sum(x * x for x in r))
                speed = math.sqrt(sum(x * x for x in v))
                along = [x / speed for x in v]
                dv1 = math.sqrt(mu / r1) * (math.sqrt(2 * r2 / (r1 + r2)) - 1)
                dv2 = math.sqrt(mu / r2) * (1 - math.sqrt(2 * r1 / (r1 + r2)))
                tof = math.pi * math.sqrt((0.5 * (r1 + r2)) ** 3 / mu)
                link.command(body, tick["t"], dv=[dv1 * a for a in along])
                link.command(body, tick["t"] + tof, dv=[-dv2 * a for a in along])
                print(f"hohmann: r1 = {r1 / 1e3:.6f} km -> r2 = {r2 / 1e3:.6f} km: dv1 = {dv1:.6f} m/s, "
                      f"dv2 = {dv2:.6f} m/s at t = {tick['t'] + tof:.3f} s", flush=True)
                planned = True
            link.done(tick)


if __name__ == "__main__":
    main()
