#!/usr/bin/env python
"""Regenerate the bundled sample logs in sample_logs/ (deterministic: same seed -> byte-identical files).

Usage: python scripts/make_sample_logs.py [--seed 0] [--out-dir sample_logs]
"""

from __future__ import annotations

import argparse
from pathlib import Path

from gndreplay.sim.scenario import simulate

#: (scenario, file name) of every bundled sample log.
SAMPLES = (("office", "office.clf.bz2"),)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0, the bundled logs')")
    parser.add_argument("--out-dir", type=Path, default=Path(__file__).resolve().parents[1] / "sample_logs",
                        help="output folder (default: the repository's sample_logs/)")
    args = parser.parse_args()
    args.out_dir.mkdir(parents=True, exist_ok=True)
    for scenario, name in SAMPLES:
        out = simulate(scenario, seed=args.seed, out=args.out_dir / name, overwrite=True)  # our own log
        print(f"{out}  {out.stat().st_size / 1024:.0f} KiB")


if __name__ == "__main__":
    main()
