"""Behaviour corpus: run a fixed set of replays and closed-loop scenarios and hash what they decided.

Two trees (or two machines) behave the same when their manifests are equal. The corpus is the dev logs in
``../shared/datasets/carmen`` (first 600 s, both planners, with results.mcap), the bundled sample (run and
scanmatch), and every shipped scenario x preset x planner for the seeds asked (a scenario in another
navigation mode than GND runs once per preset). The manifest lists the SHA-256 of every behaviour file:
commands.csv, the TUM trajectories, result.json, log.mcap, results.mcap, config.toml, maps.npz, and
summary.json without its wall-clock sections (``latency_ms``, ``over_budget``), and results.mcap's messages
(topic, stamp, payload: the same whatever the file's chunking). Timing files are left out.

The CLI is driven as a user runs it (``gndreplay.cli:main``, the console script's entry), so the same
script measures any tree:

    .venv/bin/python benchmarks/behaviour_corpus.py --out /tmp/after [--seeds 1,2,3] [--jobs 2]
    PYTHONPATH=/tmp/old .venv/bin/python benchmarks/behaviour_corpus.py --out /tmp/before
    diff /tmp/before/manifest.txt /tmp/after/manifest.txt && echo identical
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "datasets" / "carmen"
DEV_LOGS = ("mit-csail.clf.bz2", "aces.clf.bz2", "intel.clf.bz2")
PLANNERS = ("nf1", "tunnel")
PRESETS = ("wheelchair", "xr4000")
SKIP_FILES = {"timing.csv", "sim_timing.json", "report.md"}
WALL_CLOCK_KEYS = ("latency_ms", "over_budget")


def gnd(*args: str) -> list[str]:
    """A gndreplay command line run by this interpreter."""
    entry = "import sys; from gndreplay.cli import main; sys.argv[0] = 'gndreplay'; main()"
    return [sys.executable, "-c", entry, *args]


def scenario_modes() -> dict[str, str]:
    """Shipped scenario name -> its navigation mode (gnd when unset)."""
    from gndreplay.sim import resolve_scenario, shipped_scenarios

    return {name: resolve_scenario(name).mode or "gnd" for name in shipped_scenarios()}


def jobs_for(out: Path, seeds: list[int], with_logs: bool) -> list[tuple[str, list[str]]]:
    """(output folder name, command) for every run of the corpus."""
    jobs: list[tuple[str, list[str]]] = []
    if with_logs:
        for log in DEV_LOGS:
            if (DATA / log).is_file():
                for planner in PLANNERS:
                    name = f"log-{log.split('.')[0]}-{planner}"
                    jobs.append((name, gnd("run", str(DATA / log), "--until", "600", "--planner", planner,
                                           "--mcap", "--no-figures", "--quiet", "--out", str(out / name))))
    sample = out / "sample-run"
    jobs.append(("sample-run", gnd("run", "--mcap", "--no-figures", "--quiet", "--out", str(sample))))
    jobs.append(("sample-scanmatch", gnd("scanmatch", "sample_logs/office.clf.bz2", "--matcher", "idc",
                                         "--out", str(out / "sample-scanmatch"))))
    for name, mode in sorted(scenario_modes().items()):
        for preset in PRESETS:
            for planner in PLANNERS if mode == "gnd" else ("-",):
                for seed in seeds:
                    tag = f"sim-{name}-{preset}-{planner}-{seed}"
                    cmd = gnd("simulate", name, "--preset", preset, "--seed", str(seed), "--no-figures",
                              "--out", str(out / tag))
                    if planner != "-":
                        cmd += ["--planner", planner]
                    jobs.append((tag, cmd))
    return jobs


def mcap_digest(path: Path) -> str:
    """SHA-256 of an MCAP file's messages (topic, log time, payload) in file order."""
    from mcap.reader import make_reader

    h = hashlib.sha256()
    with open(path, "rb") as f:
        for _, channel, message in make_reader(f).iter_messages(log_time_order=False):
            h.update(channel.topic.encode() + message.log_time.to_bytes(8, "little") + message.data)
    return h.hexdigest()


def digest(path: Path) -> str:
    """SHA-256 of a behaviour file; summary.json without its wall-clock parts, results.mcap by message."""
    if path.name == "results.mcap":
        return mcap_digest(path)
    data = path.read_bytes()
    if path.name == "summary.json":
        doc = json.loads(data)
        for key in WALL_CLOCK_KEYS:
            doc.pop(key, None)
        data = json.dumps(doc, sort_keys=True).encode()
    return hashlib.sha256(data).hexdigest()


def manifest(out: Path) -> list[str]:
    """One line per behaviour file: digest and path relative to ``out``."""
    lines = []
    for p in sorted(out.rglob("*")):
        if p.is_file() and p.name not in SKIP_FILES and p.suffix != ".png" and p.name != "manifest.txt" \
                and not p.name.endswith(".status"):
            lines.append(f"{digest(p)}  {p.relative_to(out)}")
    return lines


def run_one(out: Path, job: tuple[str, list[str]]) -> str:
    """Run one command; its exit code is part of the behaviour (a scenario may fail on purpose)."""
    name, cmd = job
    r = subprocess.run(cmd, capture_output=True, text=True, env={**os.environ, "MPLBACKEND": "Agg"})
    if r.returncode not in (0, 1):
        return f"{name}: exit {r.returncode}: {r.stderr.strip()[-300:]}"
    (out / f"{name}.status").write_text(f"{r.returncode}\n")
    return ""


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--seeds", default="1,2,3")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--no-logs", action="store_true", help="skip the dev logs (sample and scenarios only)")
    ap.add_argument("--manifest-only", action="store_true", help="hash the runs in --out, run nothing")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    seeds = [int(s) for s in args.seeds.split(",")]
    jobs = jobs_for(args.out, seeds, not args.no_logs)
    errors: list[str] = []
    if not args.manifest_only:
        with ThreadPoolExecutor(args.jobs) as pool:
            errors = [e for e in pool.map(lambda j: run_one(args.out, j), jobs) if e]
    lines = manifest(args.out)
    statuses = [f"exit {(args.out / f'{n}.status').read_text().strip()}  {n}"
                for n, _ in jobs if (args.out / f"{n}.status").is_file()]
    (args.out / "manifest.txt").write_text("\n".join(lines + statuses) + "\n")
    print(f"{len(jobs)} runs, {len(lines)} files hashed -> {args.out / 'manifest.txt'}")
    for e in errors:
        print(e, file=sys.stderr)
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main())
