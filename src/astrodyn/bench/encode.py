"""Encoding benchmark: compiled shortest float formatting and the batch message encoders.

``python -m astrodyn.bench.encode [--bodies N] [--repeat K]`` prints

* ns per float64: :func:`astrodyn.messages.shortest.format_floats` against Python's ``repr``
  on three value sets (random bit patterns, positions ~7e6 m, quaternion components);
* us per message for N bodies at one instant (constellation-like states):
  the former pure-Python encoder (f-strings of ``repr``, reproduced here as the
  baseline), :func:`astrodyn.messages.encode_orbit_batch` / ``encode_attitude_batch``
  (list of payloads), the list plus :func:`~astrodyn.messages.encode_batch` framing
  (what the propagator did before), and the framed encoders plus
  :func:`~astrodyn.messages.batch_envelope` (what it does now).

Every timing is the best of K repeats (the machine is shared; the best is the least
disturbed).  The outputs are compared byte for byte before timing.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from astrodyn import messages as m
from astrodyn.bench import cpu_model
from astrodyn.messages import shortest

MU_EARTH = 3.986004418e14


def _best(fn, repeat: int) -> float:
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def _fstring_orbit(t, seq, model, r, v, mu, frame="GCRF"):
    """The encoder as it was before the compiled one (repr per float), the baseline."""
    head = f'{{"t":{t!r},"seq":'
    mid = f',"model":"{model}","r":['
    tail = f'],"mu":{mu!r},"frame":"{frame}"}}'
    return [f"{head}{seq}{mid}{ri[0]!r},{ri[1]!r},{ri[2]!r}],\"v\":[{vi[0]!r},{vi[1]!r},{vi[2]!r}{tail}".encode()
            for ri, vi in zip(r.tolist(), v.tolist())]


def _fstring_attitude(t, seq, model, q, w):
    head = f'{{"t":{t!r},"seq":'
    mid = f',"model":"{model}","q":['
    return [f"{head}{seq}{mid}{qi[0]!r},{qi[1]!r},{qi[2]!r},{qi[3]!r}],\"w\":[{wi[0]!r},{wi[1]!r},{wi[2]!r}]}}".encode()
            for qi, wi in zip(q.tolist(), w.tolist())]


def float_rows(repeat: int, n: int = 200_000) -> list[tuple[str, float, float]]:
    rng = np.random.default_rng(1)
    bits = rng.integers(0, 2**64, size=n, dtype=np.uint64).view(np.float64)
    sets = {"random bit patterns": bits[np.isfinite(bits)], "positions (normal x 7e6 m)": rng.normal(size=n) * 7e6,
            "quaternion components (uniform -1..1)": rng.uniform(-1, 1, n)}
    rows = []
    for name, x in sets.items():
        values = x.tolist()
        assert shortest.format_floats(x)[0].tobytes() == "".join(map(repr, values)).encode()
        compiled = _best(lambda: shortest.format_floats(x), repeat) / x.size * 1e9
        python = _best(lambda: [repr(v) for v in values], repeat) / x.size * 1e9
        rows.append((name, compiled, python))
    return rows


def message_rows(n: int, repeat: int) -> list[tuple[str, str, float]]:
    rng = np.random.default_rng(2)
    r, v = rng.normal(size=(n, 3)) * 7e6, rng.normal(size=(n, 3)) * 7.5e3
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1)[:, None]
    w = rng.normal(size=(n, 3)) * 1e-3
    t, seq = 1234.5, 12345
    okeys = [m.orbit_key("bench", f"sat-{i}") for i in range(n)]
    akeys = [m.attitude_key("bench", f"sat-{i}") for i in range(n)]
    opacked, apacked = m.BatchKeys(okeys), m.BatchKeys(akeys)
    cases = {
        "orbit": (lambda: _fstring_orbit(t, seq, "kepler", r, v, MU_EARTH),
                  lambda: m.encode_orbit_batch(t, seq, "kepler", r, v, MU_EARTH),
                  lambda: m.encode_batch(zip(okeys, m.encode_orbit_batch(t, seq, "kepler", r, v, MU_EARTH))),
                  lambda: m.batch_envelope([(m.frame_orbit_batch(opacked, t, seq, "kepler", r, v, MU_EARTH), n)])),
        "attitude": (lambda: _fstring_attitude(t, seq, "torque_free", q, w),
                     lambda: m.encode_attitude_batch(t, seq, "torque_free", q, w),
                     lambda: m.encode_batch(zip(akeys, m.encode_attitude_batch(t, seq, "torque_free", q, w))),
                     lambda: m.batch_envelope([(m.frame_attitude_batch(apacked, t, seq, "torque_free", q, w), n)])),
    }
    rows = []
    for kind, (before, after, listed_env, framed_env) in cases.items():
        assert before() == after() and listed_env() == framed_env()
        for label, fn in (("python repr f-strings (before)", before), ("encode_*_batch, compiled (list)", after),
                          ("list + encode_batch envelope", listed_env), ("frame_*_batch + batch_envelope", framed_env)):
            rows.append((kind, label, _best(fn, repeat) / n * 1e6))
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="astrodyn bench encode", description=__doc__.splitlines()[0])
    ap.add_argument("--bodies", type=int, default=1000, help="bodies per batch (default 1000)")
    ap.add_argument("--repeat", type=int, default=7, help="repeats; the best is reported (default 7)")
    args = ap.parse_args(argv)
    print(f"# encode benchmark on {cpu_model()}, load average {os.getloadavg()[0]:.1f} (best of {args.repeat})")
    print("\n| values | compiled ns/float | repr ns/float | ratio |\n|---|---|---|---|")
    for name, compiled, python in float_rows(args.repeat):
        print(f"| {name} | {compiled:.1f} | {python:.1f} | {python / compiled:.1f}x |")
    print(f"\n| message ({args.bodies} bodies per call) | path | us/message |\n|---|---|---|")
    for kind, label, us in message_rows(args.bodies, args.repeat):
        print(f"| {kind} | {label} | {us:.3f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
