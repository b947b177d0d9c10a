"""Fuzz every file a user hands gndreplay: 10,000+ mutated logs, scenarios, configs, thresholds files and run
folders, read in-process, and the table of outcomes.

The logs come from ``tests/fuzzing.py`` (seeded mutations of small logs written there: CARMEN plain / .gz /
.bz2, ROS1 bags, ROS2 sqlite3 and mcap folders, metadata.yaml, bare MCAP), the other files from
``tests/fuzz_files.py`` (mutated shipped scenarios, preset configs, a thresholds file and a run folder of the
sample log, with FIFOs, links to /dev/zero and links into a decoy tree planted among them). A log is read as
the CLI reads it (``open_log`` + every tick, then ``log_info``); a scenario is parsed and run for 0.6 s; a
config or thresholds file is loaded; a run folder is loaded as ``report`` does and sometimes redrawn. Each
is counted as read OK, project error (a one-line
GndReplayError naming the file), other exception (anything else, an unclear message, a leaked warning, or a
tick outside the reader contract) or hang (over ``--timeout`` seconds). Peak MB is the largest per-input
rise of the resident set (the kernel's high-water mark, reset before each input). The address space is
capped at its size + 3 GB so a runaway input fails instead of taking the machine down. Every input is a pure
function of (format, index, --seed). The decoy tree that planted links point to is hashed before and after
every input: a change is a failure ("decoy changed").

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

import fuzz_files  # noqa: E402
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
    "scenario": 0.08,
    "config": 0.08,
    "thresholds": 0.06,
    "rundir": 0.06,
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
    "scenario": "scenario YAML",
    "config": "config TOML",
    "thresholds": "thresholds TOML",
    "rundir": "run folder (report)",
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--total", type=int, default=10_000)
    ap.add_argument("--seed", type=int, default=12)
    ap.add_argument("--timeout", type=float, default=20.0, help="seconds before an input is a hang")
    ap.add_argument("--formats", default=",".join(fuzzing.FORMATS + fuzz_files.FILE_FORMATS))
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
        file_seeds = fuzz_files.FileSeeds.make(Path(tmp) / "file-seeds")
        decoy = fuzz_files.make_decoy(Path(tmp) / "decoy")  # beside "in": the planted links' target
        digest = fuzz_files.decoy_digest(decoy)
        for fmt in formats:
            kinds: Counter[str] = Counter()
            peak, t0 = 0.0, time.perf_counter()
            for i in range(counts[fmt]):
                seed = (fuzzing.make_input(seeds, fmt, i, args.seed) if fmt in fuzzing.FORMATS
                        else fuzz_files.make_file_input(file_seeds, fmt, i, args.seed))
                out = fuzzing.run_input(seed, fmt, i, Path(tmp) / "in", timeout_s=args.timeout)
                kinds[out.kind] += 1
                if fuzz_files.decoy_digest(decoy) != digest:
                    kinds["decoy"] += 1
                    failures.append(f"{fmt} #{i}: decoy changed ({out.kind}: {out.detail})")
                    fuzz_files.make_decoy(decoy)
                    digest = fuzz_files.decoy_digest(decoy)
                peak = max(peak, out.peak_mb)
                if out.kind in ("other", "hang"):
                    failures.append(f"{fmt} #{i} {out.kind}: {out.detail}")
            rows.append((fmt, counts[fmt], kinds, peak, time.perf_counter() - t0))
            print(f"  {fmt}: {counts[fmt]} inputs in {rows[-1][4]:.1f} s", file=sys.stderr, flush=True)
    head = ("format", "inputs", "read OK", "project error", "other exception", "hangs", "decoy changed",
            "peak MB", "s")
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    total: Counter[str] = Counter()
    for fmt, n, kinds, peak, secs in rows:
        total.update(kinds)
        print(
            f"| {LABELS[fmt]} | {n} | {kinds['ok']} | {kinds['error']} | {kinds['other']} | {kinds['hang']} "
            f"| {kinds['decoy']} | {peak:.1f} | {secs:.0f} |"
        )
    n_all = sum(r[1] for r in rows)
    peak_all = max((r[3] for r in rows), default=0.0)
    print(
        f"| **all** | {n_all} | {total['ok']} | {total['error']} | {total['other']} | {total['hang']} "
        f"| {total['decoy']} | {peak_all:.1f} | {time.perf_counter() - t_all:.0f} |"
    )
    for line in failures[: args.show]:
        print(line)
    if total["other"] or total["hang"] or total["decoy"]:
        sys.exit(1)


if __name__ == "__main__":
    main()
