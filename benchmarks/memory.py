"""Peak memory (max RSS) and wall time of ``gndreplay run`` on a long log that covers a large area.

    python benchmarks/memory.py [--log PATH] [--commands run,mcap,scanmatch] [--until S] [--budget-mb 500]

Without ``--log`` the input is the 1 km x 1 km synthetic city log of ``scripts/make_long_log.py``
(``out/long/city_1km.clf.gz``), generated first when it is missing (about two minutes). Each command runs
in a fresh process of this interpreter on this tree's code (``PYTHONPATH`` = the tree), writing into a
temporary folder, with default options and figures:

    run        gndreplay run LOG
    mcap       gndreplay run LOG --mcap
    scanmatch  gndreplay scanmatch LOG

Prints one line per command: its peak resident set size (the child's own ``ru_maxrss``, from ``wait4``),
wall time and exit code, and whether the peak is within ``--budget-mb``. Exit status 1 when a command
failed or went over the budget.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_LOG = ROOT / "out" / "long" / "city_1km.clf.gz"
CLI = "import sys; from gndreplay.cli import main; sys.argv[0] = 'gndreplay'; main()"
COMMANDS = {
    "run": ("run", "LOG", "--out", "OUT"),
    "mcap": ("run", "LOG", "--mcap", "--out", "OUT"),
    "scanmatch": ("scanmatch", "LOG", "--out", "OUT"),
}


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), *filter(None, [env.get("PYTHONPATH")])])
    for var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        env.setdefault(var, "1")
    return env


def measure(argv: list[str]) -> tuple[float, float, int]:
    """(peak RSS [MiB], wall time [s], exit code) of ``argv`` run as a child process (output discarded)."""
    start = time.perf_counter()
    proc = subprocess.Popen(argv, env=_env(), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    assert proc.stderr is not None
    err = proc.stderr.read()  # drained while it runs: a full pipe would block the child
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    wall = time.perf_counter() - start
    if proc.returncode:
        sys.stderr.write(err.decode(errors="replace")[-2000:])
    return usage.ru_maxrss / 1024.0, wall, proc.returncode  # ru_maxrss is in KiB on Linux


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--log", type=Path, default=None,
                        help=f"the log (default {DEFAULT_LOG.relative_to(ROOT)}, generated when missing)")
    parser.add_argument("--commands", default="run", help=f"comma-separated, of {', '.join(COMMANDS)}")
    parser.add_argument("--until", type=float, default=None, help="replay only this many seconds of log")
    parser.add_argument("--budget-mb", type=float, default=500.0, help="peak RSS allowed [MiB]")
    args = parser.parse_args()
    names = [c for c in args.commands.split(",") if c]
    unknown = [c for c in names if c not in COMMANDS]
    if unknown:
        parser.error(f"unknown command(s) {unknown}; expected some of {list(COMMANDS)}")
    log = args.log
    if log is None:
        log = DEFAULT_LOG
        if not log.exists():
            print(f"generating {log} ...", flush=True)
            peak, wall, code = measure([sys.executable, str(ROOT / "scripts" / "make_long_log.py"), str(log)])
            if code:
                return 1
            print(f"  generated in {wall:.0f} s (peak {peak:.0f} MiB)", flush=True)
    if not log.exists():
        parser.error(f"{log}: no such log")
    print(f"log: {log} ({log.stat().st_size / 2**20:.1f} MiB)")
    failed = False
    with tempfile.TemporaryDirectory(prefix="gndreplay-memory-") as tmp:
        for name in names:
            shown = list(COMMANDS[name])
            if args.until is not None and shown[0] == "run":
                shown += ["--until", f"{args.until:g}"]
            cmd = [str(log) if a == "LOG" else str(Path(tmp) / name) if a == "OUT" else a for a in shown]
            argv = [sys.executable, "-c", CLI, *cmd, "--progress", "none"]
            peak, wall, code = measure(argv)
            over = peak > args.budget_mb
            failed |= bool(code) or over
            verdict = "FAILED" if code else "OVER BUDGET" if over else "ok"
            print(f"gndreplay {' '.join(shown)}: peak RSS {peak:7.1f} MiB  wall {wall:6.1f} s  exit {code}  "
                  f"(budget {args.budget_mb:g} MiB: {verdict})", flush=True)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
