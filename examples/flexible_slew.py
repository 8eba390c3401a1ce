"""Rest-to-rest slew of a spacecraft with flexible solar arrays, then the arrays' residual
vibration (configs/flexible-slew.toml; B. Wie, *Space Vehicle Dynamics and Control*, 2nd
ed., sec. 7.3 and ch. 9 on flexible spacecraft).

The slew is an eigenaxis rotation about the fixed body axis ``n`` by the angle ``Theta``
that takes the first measured attitude to the target, on a bang-bang profile: constant
acceleration ``u0 / J`` for half the time ``T = 2 sqrt(Theta J / u0)``, deceleration for
the other half (``J`` the composite inertia about ``n``, hub and arrays).  Feed-forward
``u0 n`` plus Wie's quaternion-feedback PD about the reference attitude ``q_ref(t)``:

    u = u_ff n - K sgn(e0) e - C (w - w_ref n),   e = vector part of q_ref^-1 (x) q

made by the wheels (wheel k commanded ``-a_k . u``: with wheels along the body axes ``-u``).
The profile's torque steps excite the arrays; at ``T`` the controller lets the wheels
coast (zero motor torque), so what the recording shows after it is the free residual
vibration of hub and arrays, decaying at the arrays' structural damping.

Run it:  astrodyn run configs/flexible-slew.toml --controller "python examples/flexible_slew.py"
Options (environment): FLEX_TORQUE (u0, N m, default 0.8), FLEX_INERTIA (J, kg m^2,
default 686.67: the config's hub 400 + arrays 2 x 2 kg/m x ((1 + 5)^3 - 1) / 3),
FLEX_K (N m, default 124), FLEX_C (N m s, default 288: ~0.3 rad/s, damping 0.7),
FLEX_BODY (default "sc"), FLEX_TARGET (q as "e0,e1,e2,e3", default 30 deg about z),
FLEX_HOLD ("1": keep the PD on the target after T instead of coasting).
"""

import math
import os

from astrodyn_link import Link
from slew_pd import quat_conj, quat_mul


def profile(t, theta, alpha, T):
    """Angle (rad) and rate (rad/s) of the bang-bang rest-to-rest profile at ``t``, and its acceleration."""
    if t <= 0.0:
        return 0.0, 0.0, alpha
    if t < T / 2:
        return 0.5 * alpha * t * t, alpha * t, alpha
    if t < T:
        return theta - 0.5 * alpha * (T - t) ** 2, alpha * (T - t), -alpha
    return theta, 0.0, 0.0


def measured(link, body):
    """The step's attitude and rates: the star tracker's and the gyro's when the body has them, else the truth."""
    tracker, gyro, truth = (link.latest(body, kind) for kind in ("star_tracker", "gyro", "attitude"))
    return (tracker or truth)["q"], (gyro or truth)["w"]


def main():
    env = os.environ
    u0, J = float(env.get("FLEX_TORQUE", "0.8")), float(env.get("FLEX_INERTIA", "686.67"))
    k_gain, c_gain = float(env.get("FLEX_K", "124")), float(env.get("FLEX_C", "288"))
    body, hold = env.get("FLEX_BODY", "sc"), env.get("FLEX_HOLD", "") == "1"
    settle = float(env.get("FLEX_SETTLE", "15"))
    half = math.radians(30.0) / 2
    target = [float(x) for x in env.get("FLEX_TARGET", f"{math.cos(half)},0,0,{math.sin(half)}").split(",")]
    q0 = slew = None
    coasting = False
    with Link() as link:
        while (tick := link.wait_tick()) is not None:
            q, w = measured(link, body)
            t = tick["t"]
            if q0 is None:  # the eigenaxis n and angle Theta: target = q0 (x) (cos Theta/2, n sin Theta/2)
                q0 = q
                d = quat_mul(quat_conj(q0), target)
                d = d if d[0] >= 0 else [-x for x in d]
                s = math.sqrt(d[1] ** 2 + d[2] ** 2 + d[3] ** 2)
                n = [x / s for x in d[1:]] if s > 0 else [0.0, 0.0, 1.0]
                theta = 2.0 * math.atan2(s, d[0])
                alpha = u0 / J
                slew = (t, n, theta, alpha, 2.0 * math.sqrt(theta / alpha))
            t0, n, theta, alpha, T = slew
            if t - t0 >= T + settle and not hold:
                if not coasting:
                    link.command(body, t, wheel_torque=[0.0, 0.0, 0.0])  # held: the wheels coast from T on
                    coasting = True
                link.done(tick)
                continue
            angle, rate, accel = profile(t - t0, theta, alpha, T)
            ref = quat_mul(q0, [math.cos(angle / 2)] + [math.sin(angle / 2) * x for x in n])
            err = quat_mul(quat_conj(ref), q)
            sign = 1.0 if err[0] >= 0 else -1.0
            u = [J * accel * n[i] - k_gain * sign * err[i + 1] - c_gain * (w[i] - rate * n[i]) for i in range(3)]
            link.command(body, t, wheel_torque=[-x for x in u])
            link.done(tick)


if __name__ == "__main__":
    main()
