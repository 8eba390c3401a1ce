"""Sensor models with seeded noise: rate gyro, star tracker, position/velocity receiver,
wheel tachometer (closed-loop groundwork; truth stays on the state keys).

Every model is a pure function of the true state and of ``(seed, body, step)``: the noise
of sample ``k`` of a sensor is counter-based, :func:`standard_normals` of ``(seed, stream,
body, k)`` (``stream`` fixed per model; ``seed`` the scene's, ``body`` the body's index in
the scene, so that two bodies' sensors have independent noise), so a run is reproducible
whatever the order or the number of samples taken, and a re-simulation from recorded
commands gives the same measurements bit for bit.  Counter-based, the noise of every
body's sensor of one step comes out of one compiled call (:func:`standard_normals` with an
array of bodies); the models' ``samples`` methods take those arrays, ``sample`` is one body.

The generator: component ``j`` of the draw is the Box-Muller normal of the Philox4x64-10
block (J. K. Salmon et al., "Parallel random numbers: as easy as 1, 2, 3", SC11; the bit
generator numpy calls ``Philox``) with counter ``(j // 4, k, body, 0)`` and key ``(seed,
stream)``: its four 64-bit words ``x0..x3`` give ``u1 = (x0 >> 11 + 1) 2^-53`` in (0, 1],
``u2 = (x1 >> 11) 2^-53`` and ``sqrt(-2 ln u1) (cos, sin)(2 pi u2)`` for components
``4 (j // 4) + 0, 1``, the same from ``x2, x3`` for ``+ 2, 3``.

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

import math
from dataclasses import dataclass

import numpy as np

from astrodyn.jit import jit
from astrodyn.rotation import quat_from_rotvec, quat_multiply

__all__ = ["NoisySensor", "RateGyro", "StarTracker", "PositionReceiver", "WheelTachometer", "STREAMS", "philox4x64", "standard_normals"]

#: The noise stream of each model (the second word of the generator's key).
STREAMS = {"gyro": 1, "star_tracker": 2, "position": 3, "tachometer": 4}

_M0, _M1 = np.uint64(0xD2E7470EE14C6C93), np.uint64(0xCA5A826395121157)  # Philox4x64 multipliers
_W0, _W1 = np.uint64(0x9E3779B97F4A7C15), np.uint64(0xBB67AE8584CAA73B)  # Weyl key increments
_LOW32, _S32, _S11 = np.uint64(0xFFFFFFFF), np.uint64(32), np.uint64(11)
_ONE = np.uint64(1)
_TWO_M53 = 2.0**-53
_TWO_PI = 2.0 * math.pi


@jit(inline="always")
def _mulhilo(a, b):
    """``(hi, lo)`` 64-bit words of the 128-bit product ``a b`` (uint64), from 32-bit limbs."""
    a0, a1, b0, b1 = a & _LOW32, a >> _S32, b & _LOW32, b >> _S32
    p00, p01, p10, p11 = a0 * b0, a0 * b1, a1 * b0, a1 * b1
    mid = (p00 >> _S32) + (p01 & _LOW32) + (p10 & _LOW32)
    return p11 + (p01 >> _S32) + (p10 >> _S32) + (mid >> _S32), a * b


@jit(inline="always")
def _philox(c0, c1, c2, c3, k0, k1):
    """Philox4x64-10 of counter ``(c0..c3)`` and key ``(k0, k1)`` (uint64 words)."""
    for r in range(10):
        if r > 0:
            k0 += _W0
            k1 += _W1
        hi0, lo0 = _mulhilo(_M0, c0)
        hi1, lo1 = _mulhilo(_M1, c2)
        c0, c1, c2, c3 = hi1 ^ c1 ^ k0, lo1, hi0 ^ c3 ^ k1, lo0
    return c0, c1, c2, c3


@jit
def _philox_block(counter, key, out):
    out[0], out[1], out[2], out[3] = _philox(counter[0], counter[1], counter[2], counter[3], key[0], key[1])


def philox4x64(counter, key) -> np.ndarray:
    """The Philox4x64-10 block (4,) uint64 of ``counter`` (4 words) and ``key`` (2 words)."""
    out = np.empty(4, np.uint64)
    _philox_block(np.asarray(counter, dtype=np.uint64), np.asarray(key, dtype=np.uint64), out)
    return out


@jit
def _normals(seed, stream, step, bodies, out):
    k0, k1, c1 = np.uint64(seed), np.uint64(stream), np.uint64(step)
    width = out.shape[1]
    for i in range(bodies.shape[0]):
        c2 = np.uint64(bodies[i])
        for blk in range((width + 3) // 4):
            x0, x1, x2, x3 = _philox(np.uint64(blk), c1, c2, np.uint64(0), k0, k1)
            for half in range(2):
                a, b = (x0, x1) if half == 0 else (x2, x3)
                r = math.sqrt(-2.0 * math.log(float((a >> _S11) + _ONE) * _TWO_M53))
                phi = _TWO_PI * (float(b >> _S11) * _TWO_M53)
                j = 4 * blk + 2 * half
                if j < width:
                    out[i, j] = r * math.cos(phi)
                if j + 1 < width:
                    out[i, j + 1] = r * math.sin(phi)


def standard_normals(seed: int, stream: str, step: int, bodies, width: int) -> np.ndarray:
    """``(len(bodies), width)`` independent N(0, 1) draws: row ``i`` is the noise of sample
    ``step`` of sensor ``stream`` on body ``bodies[i]`` (module docstring), for scene ``seed``."""
    if not (isinstance(step, (int, np.integer)) and step >= 0):
        raise ValueError(f"step: expected an integer sample index >= 0, got {step!r}")
    b = np.ascontiguousarray(bodies, dtype=np.int64).reshape(-1)
    out = np.empty((b.shape[0], int(width)))
    _normals(int(seed), STREAMS[stream], int(step), b, out)
    return out


def _seed_body(seed) -> tuple[int, int]:
    """``(scene seed, body index)`` from an int (body 0) or a pair."""
    s = tuple(int(x) for x in seed) if isinstance(seed, tuple) else (int(seed), 0)
    if len(s) != 2 or not all(0 <= x < 2**64 for x in s):
        raise ValueError(f"seed: expected an integer or a pair (scene seed, body index) in [0, 2**64), got {seed!r}")
    return s


def _sigma(value, name: str) -> float:
    x = float(value)
    if not (np.isfinite(x) and x >= 0):
        raise ValueError(f"{name}: expected a finite standard deviation >= 0, got {value!r}")
    return x


def _sigmas(sigma, n: int) -> np.ndarray:
    return np.broadcast_to(np.asarray(sigma, dtype=np.float64).reshape(-1, 1), (n, 1))


@dataclass(frozen=True)
class RateGyro:
    """Three-axis rate gyro: ``sigma`` rad/s white noise per sample, ``bias`` (3,) rad/s.
    ``seed``: the scene's seed, or ``(scene seed, body index)``."""

    sigma: float
    bias: tuple = (0.0, 0.0, 0.0)
    seed: int | tuple = 0
    dropout: bool = False

    def __post_init__(self):
        _sigma(self.sigma, "sigma")
        _seed_body(self.seed)
        b = np.asarray(self.bias, dtype=np.float64).reshape(3)
        if not np.all(np.isfinite(b)):
            raise ValueError(f"bias: expected 3 finite numbers in rad/s, got {b.tolist()}")
        object.__setattr__(self, "bias", b)

    def sample(self, w, step: int):
        """The measured body rates (3,) rad/s for true rates ``w`` at sample ``step``."""
        if self.dropout:
            return None
        seed, body = _seed_body(self.seed)
        return RateGyro.samples(seed, [body], step, np.reshape(w, (1, 3)), self.sigma, self.bias)[0]

    @staticmethod
    def samples(seed: int, bodies, step: int, w, sigma, bias) -> np.ndarray:
        """Sample ``step`` of the gyros of ``bodies`` (n,) at once: true rates ``w`` (n, 3),
        ``sigma`` (n,) or one, ``bias`` (n, 3) or (3,); (n, 3) rad/s."""
        w = np.asarray(w, dtype=np.float64)
        return w + bias + _sigmas(sigma, w.shape[0]) * standard_normals(seed, "gyro", step, bodies, 3)


@dataclass(frozen=True)
class NoisySensor:
    """A sensor with one white-noise level ``sigma`` (in its unit), the ``seed`` of its
    noise (the scene's seed, or ``(scene seed, body index)``) and ``dropout`` (no samples)."""

    sigma: float
    seed: int | tuple = 0
    dropout: bool = False

    def __post_init__(self):
        _sigma(self.sigma, "sigma")
        _seed_body(self.seed)

    def sample(self, true, step: int):
        """This sensor's measurement of the ``true`` value (one row of its subclass's
        ``samples``: a star tracker's Euler parameters (4,), a tachometer's wheel speeds (n,))
        at sample ``step``; None while it drops out."""
        if self.dropout:
            return None
        seed, body = _seed_body(self.seed)
        return self.samples(seed, [body], step, np.asarray(true, dtype=np.float64).reshape(1, -1), self.sigma)[0]


@dataclass(frozen=True)
class StarTracker(NoisySensor):
    """Attitude sensor: ``sigma`` rad per body axis (see the module docstring); ``sample(q,
    step)`` gives the measured Euler parameters (4,) for the true ``q``."""

    @staticmethod
    def samples(seed: int, bodies, step: int, q, sigma) -> np.ndarray:
        """Sample ``step`` of the star trackers of ``bodies`` (n,): true ``q`` (n, 4); (n, 4)."""
        q = np.asarray(q, dtype=np.float64)
        d = quat_from_rotvec(_sigmas(sigma, q.shape[0]) * standard_normals(seed, "star_tracker", step, bodies, 3))
        out = quat_multiply(d, q)
        return np.where(out[:, :1] < 0, -out, out)


@dataclass(frozen=True)
class PositionReceiver:
    """GPS-like receiver: ``sigma_r`` m and ``sigma_v`` m/s per inertial axis."""

    sigma_r: float
    sigma_v: float
    seed: int | tuple = 0
    dropout: bool = False

    def __post_init__(self):
        _sigma(self.sigma_r, "sigma_r")
        _sigma(self.sigma_v, "sigma_v")
        _seed_body(self.seed)

    def sample(self, r, v, step: int):
        """``(r_meas, v_meas)`` (3,) each for the true state at sample ``step``."""
        if self.dropout:
            return None
        seed, body = _seed_body(self.seed)
        r1, v1 = PositionReceiver.samples(seed, [body], step, np.reshape(r, (1, 3)), np.reshape(v, (1, 3)),
                                          self.sigma_r, self.sigma_v)
        return r1[0], v1[0]

    @staticmethod
    def samples(seed: int, bodies, step: int, r, v, sigma_r, sigma_v) -> tuple[np.ndarray, np.ndarray]:
        """Sample ``step`` of the receivers of ``bodies`` (n,): ``(r, v)`` (n, 3) each."""
        r, v = np.asarray(r, dtype=np.float64), np.asarray(v, dtype=np.float64)
        n = standard_normals(seed, "position", step, bodies, 6)
        return r + _sigmas(sigma_r, r.shape[0]) * n[:, :3], v + _sigmas(sigma_v, v.shape[0]) * n[:, 3:]


@dataclass(frozen=True)
class WheelTachometer(NoisySensor):
    """Wheel speed sensor: ``sigma`` rad/s per wheel; ``sample(speeds, step)`` gives the
    measured wheel speeds (n,) rad/s for the true ``speeds``."""

    @staticmethod
    def samples(seed: int, bodies, step: int, speeds, sigma) -> np.ndarray:
        """Sample ``step`` of the tachometers of ``bodies`` (n,), each with the same number
        of wheels: ``speeds`` (n, wheels) rad/s."""
        s = np.asarray(speeds, dtype=np.float64)
        return s + _sigmas(sigma, s.shape[0]) * standard_normals(seed, "tachometer", step, bodies, s.shape[1])
