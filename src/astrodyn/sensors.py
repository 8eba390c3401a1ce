"""Sensor models with seeded noise: rate gyro, star tracker, position/velocity receiver,
wheel tachometer (closed-loop groundwork; truth stays on the state keys).

Every model is a pure function of the true state and of ``(seed, step)``: sample ``k`` of
a sensor draws from ``numpy.random.default_rng([seed, stream, k])`` (``stream`` fixed per
model; ``seed`` an int or a tuple of ints, e.g. ``(scene seed, body index)`` so that two
bodies' sensors have independent noise), so a run is reproducible whatever the order or the number of samples taken, and a
re-simulation from recorded commands gives the same measurements bit for bit.

Conventions (docs/architecture.md, section 2): SI units; body rates in body axes (rad/s);
Euler parameters scalar first with ``v_body = C(q) v_inertial``; positions and velocities
in the inertial frame of the central body.

* :class:`RateGyro` -- ``w_meas = w + bias + n``, ``n ~ N(0, sigma^2)`` per axis (rad/s);
  the bias is constant (a bias step is a new ``bias`` from its time on).
* :class:`StarTracker` -- ``C(q_meas) = C(d) C(q)``: the true attitude followed by a small
  rotation ``d`` about body axes whose rotation vector has independent ``N(0, sigma^2)``
  components (rad); the error angle ``|d|`` then follows a chi distribution with 3
  degrees of freedom (mean ``2 sigma sqrt(2 / pi)``).  Output sign: ``e0 >= 0``.
* :class:`PositionReceiver` -- ``r + N(0, sigma_r^2)``, ``v + N(0, sigma_v^2)`` per axis.
* :class:`WheelTachometer` -- wheel speeds ``+ N(0, sigma^2)`` (rad/s).

A model with ``dropout=True`` returns None (the sample is missing) -- the fault-injection
hook of a closed loop.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from astrodyn.rotation import quat_from_rotvec, quat_multiply

__all__ = ["RateGyro", "StarTracker", "PositionReceiver", "WheelTachometer"]

_STREAMS = {"gyro": 1, "star_tracker": 2, "position": 3, "tachometer": 4}


def _rng(seed: int | tuple[int, ...], stream: str, step: int) -> np.random.Generator:
    if not (isinstance(step, (int, np.integer)) and step >= 0):
        raise ValueError(f"step: expected an integer sample index >= 0, got {step!r}")
    entropy = [int(x) for x in seed] if isinstance(seed, tuple) else [int(seed)]
    return np.random.default_rng([*entropy, _STREAMS[stream], int(step)])


def _sigma(value, name: str) -> float:
    x = float(value)
    if not (np.isfinite(x) and x >= 0):
        raise ValueError(f"{name}: expected a finite standard deviation >= 0, got {value!r}")
    return x


@dataclass(frozen=True)
class RateGyro:
    """Three-axis rate gyro: ``sigma`` rad/s white noise per sample, ``bias`` (3,) rad/s."""

    sigma: float
    bias: tuple = (0.0, 0.0, 0.0)
    seed: int = 0
    dropout: bool = False

    def __post_init__(self):
        _sigma(self.sigma, "sigma")
        b = np.asarray(self.bias, dtype=np.float64).reshape(3)
        if not np.all(np.isfinite(b)):
            raise ValueError(f"bias: expected 3 finite numbers in rad/s, got {b.tolist()}")
        object.__setattr__(self, "bias", b)

    def sample(self, w, step: int):
        """The measured body rates (3,) rad/s for true rates ``w`` at sample ``step``."""
        if self.dropout:
            return None
        return np.asarray(w, dtype=np.float64) + self.bias + _rng(self.seed, "gyro", step).normal(0.0, self.sigma, 3)


@dataclass(frozen=True)
class StarTracker:
    """Attitude sensor: ``sigma`` rad per body axis (see the module docstring)."""

    sigma: float
    seed: int = 0
    dropout: bool = False

    def __post_init__(self):
        _sigma(self.sigma, "sigma")

    def sample(self, q, step: int):
        """The measured Euler parameters (4,) for the true ``q`` at sample ``step``."""
        if self.dropout:
            return None
        d = quat_from_rotvec(_rng(self.seed, "star_tracker", step).normal(0.0, self.sigma, 3))
        out = quat_multiply(d, np.asarray(q, dtype=np.float64))
        return -out if out[0] < 0 else out


@dataclass(frozen=True)
class PositionReceiver:
    """GPS-like receiver: ``sigma_r`` m and ``sigma_v`` m/s per inertial axis."""

    sigma_r: float
    sigma_v: float
    seed: int = 0
    dropout: bool = False

    def __post_init__(self):
        _sigma(self.sigma_r, "sigma_r")
        _sigma(self.sigma_v, "sigma_v")

    def sample(self, r, v, step: int):
        """``(r_meas, v_meas)`` (3,) each for the true state at sample ``step``."""
        if self.dropout:
            return None
        n = _rng(self.seed, "position", step).normal(0.0, 1.0, 6)
        return (np.asarray(r, dtype=np.float64) + self.sigma_r * n[:3],
                np.asarray(v, dtype=np.float64) + self.sigma_v * n[3:])


@dataclass(frozen=True)
class WheelTachometer:
    """Wheel speed sensor: ``sigma`` rad/s per wheel."""

    sigma: float
    seed: int = 0
    dropout: bool = False

    def __post_init__(self):
        _sigma(self.sigma, "sigma")

    def sample(self, speeds, step: int):
        """Measured wheel speeds (n,) rad/s at sample ``step``."""
        if self.dropout:
            return None
        s = np.asarray(speeds, dtype=np.float64)
        return s + _rng(self.seed, "tachometer", step).normal(0.0, self.sigma, s.shape)
