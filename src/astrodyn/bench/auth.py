"""Cost of the run's message authentication (``astrodyn bench auth``).

Measured in one process, on the payloads the propagators really publish:

* one state message on its own key (scenes up to ``BATCH_THRESHOLD`` bodies): encode the
  JSON payload, sign it (:meth:`astrodyn.auth.Signer.attachment`), verify it
  (:meth:`astrodyn.auth.Verifier.verify`);
* one batch envelope of N states (large scenes): the same per envelope, reported per state.

Output: a Markdown table (us per message / per state) for docs/benchmarks.md. The
service-level cost (``constellation-1000`` real-time factor with and without
authentication, in one run) is in ``astrodyn bench service``.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from astrodyn import auth, messages
from astrodyn.bench import best_seconds_per_call, print_table
from astrodyn.bench.flags import int_in


def _best(fn, repeat: int, number: int) -> float:
    """Best of ``repeat`` timings of ``number`` calls, in seconds per call."""
    return best_seconds_per_call(fn, number, repeat)


def measure(bodies: int = 1000, repeat: int = 5) -> list[dict]:
    rng = np.random.default_rng(7)
    secret = auth.RunSecret.generate()
    signer = auth.Signer(secret, "orbit")
    r = rng.normal(scale=7e6, size=(bodies, 3))
    v = rng.normal(scale=7e3, size=(bodies, 3))
    names = [f"sat{i:04d}" for i in range(bodies)]
    keys = [messages.orbit_key("bench", n) for n in names]
    payloads = messages.encode_orbit_batch(12.5, 125, "kepler", r, v, 3.986004418e14, "GCRF")
    one_key, one = keys[0], payloads[0]
    envelope = messages.encode_batch(list(zip(keys, payloads)))
    rows = []
    batch_key = "astrodyn/bench/@batch/orbit"

    def verify_cost(key: str, payload: bytes, number: int) -> float:
        """Seconds per verification: fresh authenticators (increasing counters), as on the bus."""
        best = float("inf")
        for _ in range(repeat):
            verifier = auth.Verifier(secret)
            atts = [signer.attachment(key, payload) for _ in range(number)]
            t0 = time.perf_counter()
            for a in atts:
                verifier.verify(key, payload, a)
            best = min(best, (time.perf_counter() - t0) / number)
        return best

    encode_one = _best(lambda: messages.encode_orbit_batch(12.5, 125, "kepler", r[:1], v[:1], 3.986004418e14, "GCRF"),
                       repeat, 2000)
    sign_one = _best(lambda: signer.attachment(one_key, one), repeat, 20000)
    rows.append({"case": f"one state message ({len(one)} B)", "encode_us": encode_one * 1e6,
                 "sign_us": sign_one * 1e6, "verify_us": verify_cost(one_key, one, 20000) * 1e6, "per": "message"})
    encode_env = _best(lambda: messages.encode_batch(list(zip(keys, messages.encode_orbit_batch(
        12.5, 125, "kepler", r, v, 3.986004418e14, "GCRF")))), repeat, 20)
    sign_env = _best(lambda: signer.attachment(batch_key, envelope), repeat, 200)
    rows.append({"case": f"envelope of {bodies} states ({len(envelope) / 1e3:.0f} kB)",
                 "encode_us": encode_env * 1e6 / bodies, "sign_us": sign_env * 1e6 / bodies,
                 "verify_us": verify_cost(batch_key, envelope, 200) * 1e6 / bodies, "per": "state"})
    return rows


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """The options of ``astrodyn bench auth``, checked (argparse's usage error, exit 2)."""
    ap = argparse.ArgumentParser(prog="astrodyn bench auth", description=__doc__.split("\n\n")[0])
    ap.add_argument("--bodies", type=int_in(1, 100_000), default=1000,
                    help="states per envelope, 1..100000 (an envelope of 100000 is about 23 MB; default 1000)")
    ap.add_argument("--repeat", type=int_in(1, 100), default=5, help="best of this many timings, 1..100 (default 5)")
    return ap.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    rows = measure(args.bodies, args.repeat)
    print_table(["case", "encode (us)", "sign (us)", "verify (us)", "per", "sign / encode"],
                ([row["case"], f"{row['encode_us']:.3f}", f"{row['sign_us']:.3f}", f"{row['verify_us']:.3f}", row["per"],
                  f"{row['sign_us'] / row['encode_us']:.2f}"] for row in rows), align="lrrrlr")
    return 0


if __name__ == "__main__":
    sys.exit(main())
