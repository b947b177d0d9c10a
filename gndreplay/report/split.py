"""Drawing on two cores: ``run_split`` runs a list of independent drawing jobs (each draws and saves one
file) partly in a forked child process, partly here, when two CPUs are free for it.

A fork shares everything already imported and loaded (matplotlib, fonts, the run's data), so the child
starts drawing at once, where a fresh interpreter would first spend seconds importing. Each file is written
by one process only, atomically (``save_figure``), so the files are the same bytes whichever process drew
them. A child that fails leaves its jobs to this process, which runs them again and raises what they raise.
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Callable, Sequence

__all__ = ["run_split", "split_jobs", "splitting"]

Job = Callable[[], object]
EXACT_JOBS = 12


def splitting() -> bool:
    """Whether drawing is split across two processes here: POSIX fork, at least two CPUs this process may
    use, and not inside a worker process of a pool (whose workers already share out the cores)."""
    if not hasattr(os, "fork") or multiprocessing.parent_process() is not None:
        return False
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return cpus >= 2


def split_jobs(weights: Sequence[float]) -> tuple[list[int], list[int]]:
    """The indices of jobs of ``weights`` (estimated costs) for the child and for this process, each side in
    the original order: the best balance of all the splits for up to ``EXACT_JOBS`` jobs (the figures; on a
    tie the child, which also starts, gets the lighter side), else greedily, the heaviest first to the lighter
    side (the snapshots, of one cost each)."""
    n = len(weights)
    if n <= EXACT_JOBS:
        total = float(sum(weights))

        def excess(m: int) -> tuple[float, float, int]:  # the child's share over half: least, then lighter
            d = 2.0 * sum(weights[i] for i in range(n) if m >> i & 1) - total
            return abs(d), d, m

        best = min(range(1 << n), key=excess)
        theirs = [i for i in range(n) if best >> i & 1]
        return theirs, [i for i in range(n) if not best >> i & 1]
    sides: tuple[list[int], list[int]] = ([], [])
    load = [0.0, 0.0]
    for i in sorted(range(n), key=lambda k: (-weights[k], k)):
        side = 0 if load[0] < load[1] else 1
        sides[side].append(i)
        load[side] += weights[i]
    return sorted(sides[0]), sorted(sides[1])


def run_split(jobs: Sequence[Job], weights: Sequence[float] | None = None, *, split: bool | None = None
              ) -> None:
    """Run every job of ``jobs``: with ``split`` (None: ``splitting()``) and two or more jobs, those of
    ``split_jobs`` in a forked child while this process runs the others, waiting for the child before
    returning or raising; the child's jobs are run again here if it did not finish them all."""
    w = list(weights) if weights is not None else [1.0] * len(jobs)
    if split is None:
        split = splitting()
    if not split or len(jobs) < 2:
        for job in jobs:
            job()
        return
    theirs, ours = split_jobs(w)
    try:
        pid = os.fork()
    except OSError:  # no process to spare (EAGAIN, ENOMEM): all of them here
        for job in jobs:
            job()
        return
    if pid == 0:  # the child: never returns into the caller's code
        code = 1
        try:
            for i in theirs:
                jobs[i]()
            code = 0
        finally:
            os._exit(code)
    try:
        for i in ours:
            jobs[i]()
    finally:
        _, status = os.waitpid(pid, 0)
    if not (os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0):
        for i in theirs:
            jobs[i]()
