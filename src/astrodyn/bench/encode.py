"""Encoding benchmark: compiled shortest float formatting and the batch message encoders.

``python -m astrodyn.bench.encode [--bodies N] [--repeat K]`` prints

* ns per float64: :func:`astrodyn.messages.shortest.format_floats` against Python's ``repr``
  on three value sets (random bit patterns, positions ~7e6 m, quaternion components);
* us per message for N bodies at one instant (constellation-like states):
  the former pure-Python encoder (f-strings of ``repr``, reproduced here as the
  baseline), :func:`astrodyn.messages.encode_orbit_batch` / ``encode_attitude_batch``
  (list of payloads), the list plus :func:`~astrodyn.messages.encode_batch` framing
  (what the propagator did before), and the framed encoders plus
  :func:`~astrodyn.messages.batch_envelope` (what it does now);
* us per single message: ``encode`` without and with validation, ``decode`` (parse +
  validation), the builders and ``check_state``; with ``--baseline SRC`` also for the tree
  in ``SRC`` (before/after in one run, medians of 3 alternated rounds, and their ratio).

Every timing is the best of K repeats (the machine is shared; the best is the least
disturbed).  The outputs are compared byte for byte before timing.
"""

from __future__ import annotations

import argparse
import os
import statistics

import numpy as np

from astrodyn import messages as m
from astrodyn.bench import best_seconds_per_call, call_in_tree, cpu_model
from astrodyn.bench.flags import int_in, source_tree
from astrodyn.messages import codec, shortest

MU_EARTH = 3.986004418e14


def _best(fn, repeat: int) -> float:
    """Best of ``repeat`` single calls, in seconds."""
    return best_seconds_per_call(fn, 1, repeat)


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


def single_message_cases(repeat: int) -> dict[str, float]:
    """Seconds per message of the single-message calls that exist before and after issue 12
    (``encode(msg)``, ``encode(msg, kind)`` with validation, ``decode(payload, kind)`` =
    parse + validate, the builder (``orbit_message``, ...) and ``check_state`` on a canonical
    payload), for orbit, attitude and event messages.  The attitude message has a rate of
    3e-5 rad/s, which ``repr`` writes in exponent form; the "attitude, floats in 1e-4..1e16"
    rows have 3e-3 there.  Self-contained (imports inside) so that ``--baseline`` runs it
    against an older tree."""

    from astrodyn import messages as m

    def best(fn, number=20000):
        return best_seconds_per_call(fn, number, repeat)

    builders = {
        "orbit": lambda: m.orbit_message(1234.5, 12345, "kepler", [6878137.123456789, 1234.567890123, -98765.43210987],
                                         [-12.3456789, 7612.345678901, 1.234567e-3], 3.986004418e14),
        "attitude": lambda: m.attitude_message(1234.5, 12345, "torque_free",
                                               [0.9238795325112867, 0.0, 0.3826834323650898, 0.0], [0.1, -0.02, 3e-5]),
        "attitude, floats in 1e-4..1e16": lambda: m.attitude_message(
            1234.5, 12345, "torque_free", [0.9238795325112867, 0.0, 0.3826834323650898, 0.0], [0.1, -0.02, 3e-3]),
        "event": lambda: m.event_message(1234.5, 3, "orbit", "restart", "restarted from step 17 (pid 1234 -> 1240)"),
    }
    out = {}
    for label, build in builders.items():
        kind = label.split(",")[0]
        msg = build()
        data = m.encode(msg, kind)
        out[f"{label}: encode"] = best(lambda msg=msg: m.encode(msg))
        out[f"{label}: encode + validate"] = best(lambda msg=msg, kind=kind: m.encode(msg, kind))
        if label == kind:
            out[f"{kind}: decode + validate"] = best(lambda data=data, kind=kind: m.decode(data, kind))
            out[f"{kind}: build ({kind}_message)"] = best(build)
        if label in ("orbit", "attitude"):
            out[f"{kind}: check_state (canonical payload)"] = best(lambda data=data, kind=kind: m.check_state(data, kind))
    return out


BODIES_MAX = 1_000_000
"""Largest ``--bodies``: about 1.7 kB per body at the peak (the states, keys and the encoded
payloads of the before and after encoders side by side), 1.7 GB here."""


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """The options of ``astrodyn bench encode``, checked (argparse's usage error, exit 2)."""
    ap = argparse.ArgumentParser(prog="astrodyn bench encode", description=__doc__.splitlines()[0])
    ap.add_argument("--bodies", type=int_in(1, BODIES_MAX), default=1000,
                    help=f"bodies per batch, 1..{BODIES_MAX} (about 1.7 kB per body; default 1000)")
    ap.add_argument("--repeat", type=int_in(1, 100), default=7, help="repeats; the best is reported, 1..100 (default 7)")
    ap.add_argument("--baseline", default=None, metavar="SRC", type=source_tree,
                    help="also time the single-message calls with astrodyn imported from this source tree (before/after "
                         "in one run, alternated, in child processes)")
    return ap.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    print(f"# encode benchmark on {cpu_model()}, load average {os.getloadavg()[0]:.1f} (best of {args.repeat}); "
          f"float layout pass {'compiled' if codec.LAYOUT_COMPILED else 'NOT compiled (Python path)'}")
    print("\n| values | compiled ns/float | repr ns/float | ratio |\n|---|---|---|---|")
    for name, compiled, python in float_rows(args.repeat):
        print(f"| {name} | {compiled:.1f} | {python:.1f} | {python / compiled:.1f}x |")
    print(f"\n| message ({args.bodies} bodies per call) | path | us/message |\n|---|---|---|")
    for kind, label, us in message_rows(args.bodies, args.repeat):
        print(f"| {kind} | {label} | {us:.3f} |")
    trees = [("before", os.path.abspath(args.baseline)), ("after", None)] if args.baseline else [("now", None)]
    rounds: dict[str, dict[str, list[float]]] = {label: {} for label, _ in trees}
    for _ in range(3 if args.baseline else 1):  # alternated: a change of the machine's load hits both alike
        for label, src in trees:
            for case, secs in call_in_tree(single_message_cases, (args.repeat,), src).items():
                rounds[label].setdefault(case, []).append(secs)
    cases = list(rounds[trees[-1][0]])
    ratio = " before / after |" if args.baseline else ""
    print(f"\n| single message | {' | '.join(f'{label} us' for label, _ in trees)} |{ratio}\n"
          f"|---|{'---|' * (len(trees) + bool(ratio))}")
    for case in cases:
        medians = [statistics.median(rounds[label][case]) if case in rounds[label] else None for label, _ in trees]
        cells = [f"{x * 1e6:.2f}" if x is not None else "-" for x in medians]
        if ratio:
            cells.append(f"{medians[0] / medians[1]:.1f}x" if None not in medians else "-")
        print(f"| {case} | {' | '.join(cells)} |")
    print(f"\nload average at the end {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
