"""Fuzz the log readers: 10,000+ mutated logs of every format, read in-process, and the table of outcomes.

The inputs come from ``tests/fuzzing.py`` (seeded mutations of small logs written there: CARMEN plain / .gz /
.bz2, ROS1 bags, ROS2 sqlite3 and mcap folders, metadata.yaml, bare MCAP). Each is read as the CLI reads it
(``open_log`` + every tick, then ``log_info``) and counted as read OK, project error (a one-line
GndReplayError naming the file), other exception (anything else, an unclear message, a leaked warning, or a
tick outside the reader contract) or hang (over ``--timeout`` seconds). Peak MB is the largest per-input
rise of the resident set (the kernel's high-water mark, reset before each input). The address space is
capped at its size + 3 GB so a runaway input fails instead of taking the machine down. Every input is a pure
function of (format, index, --seed).

    .venv/bin/python benchmarks/fuzz.py [--total 10000] [--seed 12] [--timeout 20] [--formats carmen,ros1]
"""

from __future__ import annotations

import argparse
import logging
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

import fuzzing  # noqa: E402

#: Share of the inputs per format (roughly the issue's mix; the slow container formats get fewer).
WEIGHTS = {
    "carmen": 0.25,
    "carmen.gz": 0.12,
    "carmen.bz2": 0.10,
    "ros1": 0.20,
    "ros2-db3": 0.09,
    "ros2-yaml": 0.08,
    "ros2-mcap": 0.06,
    "mcap": 0.10,
}
LABELS = {
    "carmen": "CARMEN plain",
    "carmen.gz": "CARMEN .gz",
    "carmen.bz2": "CARMEN .bz2",
    "ros1": "ROS1 .bag",
    "ros2-db3": "ROS2 sqlite3 .db3",
    "ros2-yaml": "ROS2 metadata.yaml",
    "ros2-mcap": "ROS2 mcap folder",
    "mcap": "bare MCAP",
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--total", type=int, default=10_000)
    ap.add_argument("--seed", type=int, default=12)
    ap.add_argument("--timeout", type=float, default=20.0, help="seconds before an input is a hang")
    ap.add_argument("--formats", default=",".join(fuzzing.FORMATS))
    ap.add_argument("--show", type=int, default=20, help="failures listed in detail")
    args = ap.parse_args()
    formats = [f for f in args.formats.split(",") if f]
    weight = sum(WEIGHTS[f] for f in formats)
    counts = {f: max(1, round(args.total * WEIGHTS[f] / weight)) for f in formats}
    logging.disable(logging.CRITICAL)  # the readers' warnings (index clock, zero stamps) are not results
    rows, failures = [], []
    t_all = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="gndreplay-fuzz-") as tmp, fuzzing.memory_guard():
        seeds = fuzzing.Seeds(Path(tmp) / "seeds", args.seed)
        for fmt in formats:
            kinds: Counter[str] = Counter()
            peak, t0 = 0.0, time.perf_counter()
            for i in range(counts[fmt]):
                seed = fuzzing.make_input(seeds, fmt, i, args.seed)
                out = fuzzing.run_input(seed, fmt, i, Path(tmp) / "in", timeout_s=args.timeout)
                kinds[out.kind] += 1
                peak = max(peak, out.peak_mb)
                if out.kind in ("other", "hang"):
                    failures.append(f"{fmt} #{i} {out.kind}: {out.detail}")
            rows.append((fmt, counts[fmt], kinds, peak, time.perf_counter() - t0))
            print(f"  {fmt}: {counts[fmt]} inputs in {rows[-1][4]:.1f} s", file=sys.stderr, flush=True)
    head = ("format", "inputs", "read OK", "project error", "other exception", "hangs", "peak MB", "s")
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    total: Counter[str] = Counter()
    for fmt, n, kinds, peak, secs in rows:
        total.update(kinds)
        print(
            f"| {LABELS[fmt]} | {n} | {kinds['ok']} | {kinds['error']} | {kinds['other']} | {kinds['hang']} "
            f"| {peak:.1f} | {secs:.0f} |"
        )
    n_all = sum(r[1] for r in rows)
    peak_all = max((r[3] for r in rows), default=0.0)
    print(
        f"| **all** | {n_all} | {total['ok']} | {total['error']} | {total['other']} | {total['hang']} "
        f"| {peak_all:.1f} | {time.perf_counter() - t_all:.0f} |"
    )
    for line in failures[: args.show]:
        print(line)
    if total["other"] or total["hang"]:
        sys.exit(1)


if __name__ == "__main__":
    main()
