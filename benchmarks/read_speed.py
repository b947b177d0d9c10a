"""Reading speed of each reader on the dev logs: scans/s (median of several runs), ticks fully built.

A run opens the log and streams every Tick (ranges and angles as numpy arrays, odometry interpolated at the
scan stamp), exactly what a replay consumes. Targets: >= 20,000 scans/s for bags / MCAP, >= 5,000 for CARMEN.
Wall-clock rates swing with the machine's load; the CPU-time rate (process time) is the steadier number.

    /work/venv/bin/python benchmarks/read_speed.py [--runs 5] [--datasets ../shared/datasets]
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

from gndreplay.io import open_log

LOGS = [
    ("carmen/mit-csail.clf.bz2", 5_000),
    ("carmen/aces.clf.bz2", 5_000),
    ("rosbag1/mit-csail.sort.bag", 20_000),
    ("rosbag1/aces.sort.bag", 20_000),
    ("rosbag2/mit-csail.sort.ros2_sqlite3", 20_000),
    ("rosbag2/mit-csail.sort.ros2_mcap", 20_000),
    ("rosbag2/mit-csail.sort.ros2_mcap/mit-csail.sort.ros2_mcap.mcap", 20_000),
]


def read_once(path: Path) -> tuple[int, float, float]:
    """(scans, wall seconds, CPU seconds) for one full pass, opening included."""
    t0, c0 = time.perf_counter(), time.process_time()
    n = 0
    with open_log(path) as log:
        for _ in log.ticks():
            n += 1
    return n, time.perf_counter() - t0, time.process_time() - c0


def main() -> None:
    default = Path(__file__).resolve().parents[2] / "shared" / "datasets"
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--datasets", type=Path, default=default)
    args = ap.parse_args()
    head = ("log", "format", "scans", "median s", "scans/s", "cpu/s", "target")
    print("{:66s} {:8s} {:>6s} {:>9s} {:>9s} {:>9s} {:>7s}".format(*head))
    for rel, target in LOGS:
        path = args.datasets / rel
        if not path.exists():
            print(f"{rel:66s} (missing)")
            continue
        read_once(path)  # warm the page cache and imports
        runs = [read_once(path) for _ in range(args.runs)]
        n = runs[0][0]
        med = statistics.median(wall for _, wall, _ in runs)
        cpu = statistics.median(c for _, _, c in runs)
        with open_log(path) as log:
            fmt = log.format_name
        flag = "ok" if n / med >= target else ("ok (cpu)" if n / cpu >= target else "BELOW")
        print(f"{rel:66s} {fmt:8s} {n:6d} {med:9.3f} {n / med:9.0f} {n / cpu:9.0f} {target:7d} {flag}")


if __name__ == "__main__":
    main()
