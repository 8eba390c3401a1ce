"""Eigenaxis slew with three reaction wheels: quaternion-feedback PD (B. Wie, *Space Vehicle
Dynamics and Control*, 2nd ed., sec. 7.3.1; Wie, Weiss & Arapostathis 1989).

Control torque on the body ``u = -K sgn(e0) e - C w`` with ``e`` the vector part of the
error quaternion ``q_err = q_target^-1 (x) q`` (scalar first), ``w`` the measured body
rates; the wheels make it: wheel k (spin axis a_k) is commanded ``g_k = -a_k . u`` (the
body feels ``-g_k a_k``), so with orthogonal wheels along the body axes ``g = -u``.  The
wheels saturate (the plant clips at their torque and speed limits and records it).

Run it:  astrodyn run configs/slew.toml --controller "python examples/slew_pd.py"
Options (environment): SLEW_K (N m, default 2.0), SLEW_C (N m s, default 20.0),
SLEW_BODY (default "sc"), SLEW_TARGET (q as "e0,e1,e2,e3", default 90 deg about z).
Reads the star tracker and gyro when the body has them, else the true attitude.
"""

import math
import os

from astrodyn_link import Link


def quat_conj(q):
    return [q[0], -q[1], -q[2], -q[3]]


def quat_mul(p, q):  # scalar first, p (x) q
    return [p[0] * q[0] - p[1] * q[1] - p[2] * q[2] - p[3] * q[3],
            p[0] * q[1] + p[1] * q[0] + p[2] * q[3] - p[3] * q[2],
            p[0] * q[2] - p[1] * q[3] + p[2] * q[0] + p[3] * q[1],
            p[0] * q[3] + p[1] * q[2] - p[2] * q[1] + p[3] * q[0]]


def main():
    k_gain = float(os.environ.get("SLEW_K", "2.0"))
    c_gain = float(os.environ.get("SLEW_C", "20.0"))
    body = os.environ.get("SLEW_BODY", "sc")
    half = math.radians(90.0) / 2
    target = [float(x) for x in os.environ.get("SLEW_TARGET", f"{math.cos(half)},0,0,{math.sin(half)}").split(",")]
    with Link() as link:
        while (tick := link.wait_tick()) is not None:
            tracker, gyro = link.latest(body, "star_tracker"), link.latest(body, "gyro")
            truth = link.latest(body, "attitude")
            q = tracker["q"] if tracker else truth["q"]
            w = gyro["w"] if gyro else truth["w"]
            err = quat_mul(quat_conj(target), q)
            sign = 1.0 if err[0] >= 0 else -1.0
            u = [-k_gain * sign * err[i + 1] - c_gain * w[i] for i in range(3)]
            link.command(body, tick["t"], wheel_torque=[-x for x in u])
            link.done(tick)


if __name__ == "__main__":
    main()
