"""``astrodyn demo``: the README's main job.

Runs ``configs/demo.toml`` (three spacecraft, orbit and attitude, one ISS orbit at 1 Hz)
through the full service -- logger, orbit and attitude processes on loopback Zenoh --
into ``out/demo.mcap``, then prints the per-body summary and how to look at the file.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from astrodyn.scenario.catalogue import config_path
from astrodyn.service import runner


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="astrodyn demo", description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default="out/demo.mcap", help="MCAP file to write (default out/demo.mcap)")
    ap.add_argument("--config", default=None, help="scenario (default configs/demo.toml)")
    args = ap.parse_args(argv)
    config = Path(args.config) if args.config else config_path("demo")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    rc = runner.main([str(config), "--out", str(out), "--cross-check"], prog="astrodyn demo")
    if rc == 0:
        print(f"\nRecorded {out}. Next: `astrodyn analyze {out}` for a report with plots, "
              f"`astrodyn replay {out}` to republish it on Zenoh, or open it in Foxglove.")
    return rc
