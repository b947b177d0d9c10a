"""Model-builder and C-space speed: grid integration per scan and free C-space per tick.

Targets: integration <= 1 ms per 361-beam scan on 400 x 400 (one core); C-space a few ms or less. The
C-space is timed per tick along the drive as the planner follows it (``CSpaceTracker``, checked equal to
``free_cspace`` on every tick) and afresh (``free_cspace``'s disc sweep), and on the final grid three ways
that give the same free mask (the disc sweep, and a threshold of the numba and the scipy distance
transforms).
Synthetic scans are ray-cast in a hall with rooms and pillars (ranges up to the 30 m max range, 1 % invalid
beams) along a 60 m drive that re-centres the grid many times. When ``gndreplay.io.read_ticks`` exists and
../shared/datasets is present, the real MIT CSAIL log (361 beams) is replayed on its raw odometry too.

Run: ``python benchmarks/model.py [--scans N]``. Prints medians (and p95 / max) in microseconds.
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Callable, Iterable
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage as ndi

from gndreplay.errors import GndReplayError
from gndreplay.pipeline.cspace import CSpaceTracker, free_cspace, obstacle_distance_m, squared_distance_cells
from gndreplay.pipeline.model import GRID_200, GRID_400, OCCUPIED, GridParams, RobotCentredGrid
from gndreplay.types import Pose2D, Scan

DATASETS = Path(__file__).resolve().parents[1].parent / "shared" / "datasets"
LASER = Pose2D(0.72, 0.0, 0.0)  # the wheelchair's laser mounting


def hall_segments() -> NDArray[np.float64]:
    """(S, 4) wall segments x0, y0, x1, y1 [m]: a 70 x 24 m hall, two rooms with doors, square pillars."""
    segs: list[tuple[float, float, float, float]] = [
        (-10, -12, 60, -12), (60, -12, 60, 12), (60, 12, -10, 12), (-10, 12, -10, -12),
        (5, 3, 5, 12), (5, 3, 9, 3), (10, 3, 15, 3), (15, 3, 15, 12),  # room with a 1 m door
        (30, -12, 30, -4), (30, -4, 34, -4), (35.2, -4, 38, -4), (38, -4, 38, -12),
    ]
    for cx in range(0, 60, 8):
        for cy in (-6.0, 6.5):
            x0, y0, x1, y1 = cx + 2.0, cy, cx + 2.6, cy + 0.6
            segs += [(x0, y0, x1, y0), (x1, y0, x1, y1), (x1, y1, x0, y1), (x0, y1, x0, y0)]
    return np.asarray(segs, dtype=np.float64)


def raycast(
    origin: tuple[float, float], angles: NDArray[np.float64], segs: NDArray[np.float64], max_range: float
) -> NDArray[np.float64]:
    """(N,) ranges [m] from ``origin`` along world ``angles`` to the nearest segment; inf beyond max_range."""
    d = np.stack([np.cos(angles), np.sin(angles)], axis=1)[:, None, :]  # (N, 1, 2)
    p = segs[None, :, :2]
    e = (segs[:, 2:] - segs[:, :2])[None]  # (1, S, 2)
    w = p - np.asarray(origin)
    den = d[..., 0] * e[..., 1] - d[..., 1] * e[..., 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (w[..., 0] * e[..., 1] - w[..., 1] * e[..., 0]) / den
        u = (w[..., 0] * d[..., 1] - w[..., 1] * d[..., 0]) / den
    ok = (den != 0) & (t > 0) & (u >= 0) & (u <= 1)
    r = np.where(ok, t, np.inf).min(axis=1)
    r[r >= max_range] = np.inf
    return r


def synthetic_run(n_scans: int, rng: np.random.Generator) -> list[tuple[Scan, Pose2D]]:
    """Scans along a wavy 60 m drive through the hall, 361 beams over 180 degrees, 30 m max range."""
    segs = hall_segments()
    angles = np.linspace(-math.pi / 2, math.pi / 2, 361)
    out = []
    for k in range(n_scans):
        s = 58.0 * k / max(n_scans - 1, 1)
        pose = Pose2D(s - 8.0, 1.5 * math.sin(s / 5.0) - 1.0, 0.3 * math.cos(s / 5.0))
        laser = pose.compose(LASER)
        r = raycast((laser.x, laser.y), angles + laser.theta, segs, 30.0)
        r = r + rng.normal(0.0, 0.01, r.shape)
        r[rng.random(r.shape) < 0.01] = np.nan
        out.append((Scan(k, r, angles, 30.0, sensor_pose=LASER), pose))
    return out


def summary(name: str, samples_ns: Iterable[int]) -> None:
    a = np.asarray(list(samples_ns), dtype=np.float64) / 1e3
    print(f"  {name:<44s} median {np.median(a):8.1f} us   p95 {np.percentile(a, 95):8.1f} us"
          f"   max {a.max():8.1f} us   (n={a.size})")


def time_integration(params: GridParams, run: list[tuple[Scan, Pose2D]]) -> RobotCentredGrid:
    grid = RobotCentredGrid(params, centre_xy=(run[0][1].x, run[0][1].y))
    grid.integrate(run[0][0], run[0][1])  # compile / load the numba cache outside the timing
    grid = RobotCentredGrid(params, centre_xy=(run[0][1].x, run[0][1].y))
    all_ns, shift_ns = [], []
    tracker = CSpaceTracker(cell_m=params.cell_m, inflate_m=0.4)
    tracked_ns, sweep_ns = [], []
    for scan, pose in run:
        t0 = time.perf_counter_ns()
        stats = grid.integrate(scan, pose)
        dt = time.perf_counter_ns() - t0
        all_ns.append(dt)
        if stats.shifted_cells != (0, 0):
            shift_ns.append(dt)
        t0 = time.perf_counter_ns()
        tracked = tracker.free(grid.cells, grid.offset_cells)
        tracked_ns.append(time.perf_counter_ns() - t0)
        t0 = time.perf_counter_ns()
        swept = free_cspace(grid.cells, cell_m=params.cell_m, inflate_m=0.4)
        sweep_ns.append(time.perf_counter_ns() - t0)
        if not np.array_equal(tracked, swept):
            raise SystemExit("CSpaceTracker and free_cspace differ: a bug")
    n = params.size_cells
    summary(f"integrate {n}x{n}, all scans", all_ns)
    if shift_ns:
        summary(f"integrate {n}x{n}, scans with a re-centring", shift_ns)
    # the first tick counts the discs afresh (and compiles): left out
    summary(f"C-space per tick {n}x{n}: CSpaceTracker", tracked_ns[1:])
    summary(f"C-space per tick {n}x{n}: free_cspace sweep", sweep_ns[1:])
    return grid


def time_call(name: str, fn: Callable[[], object], repeats: int = 50) -> None:
    fn()
    ns = []
    for _ in range(repeats):
        t0 = time.perf_counter_ns()
        fn()
        ns.append(time.perf_counter_ns() - t0)
    summary(name, ns)


def time_cspace(cells: NDArray[np.uint8], c: float, what: str) -> None:
    """free_cspace (exact integer disc sweep) beside the same free mask thresholded from a distance
    transform (numba FH EDT, scipy EDT): the three give identical masks, checked here."""
    n = cells.shape[0]
    occ = cells == OCCUPIED
    print(f"  {what} {n}x{n}: {int(occ.sum())} occupied, {int((cells == 0).sum())} unknown cells")
    r_eff = 0.4 / c - 0.5  # free_cspace's sub-cell rule: d_centre > inflate - cell / 2 [cells]
    ours = free_cspace(cells, cell_m=c, inflate_m=0.4)
    same_fh = np.array_equal(ours, squared_distance_cells(occ) > r_eff * r_eff * (1.0 + 1e-9))
    same_scipy = np.array_equal(ours, ndi.distance_transform_edt(~occ) > r_eff * (1.0 + 1e-9))
    print(f"  free masks identical: numba FH EDT {same_fh}, scipy EDT {same_scipy}")
    time_call(f"free_cspace {n}x{n} (inflate 0.40 m, disc sweep)",
              lambda: free_cspace(cells, cell_m=c, inflate_m=0.4))
    time_call(f"free_cspace {n}x{n} unknown as obstacle",
              lambda: free_cspace(cells, cell_m=c, inflate_m=0.4, unknown_is_free=False))
    time_call(f"numba FH EDT {n}x{n} + threshold", lambda: squared_distance_cells(occ) > r_eff * r_eff)
    time_call(f"scipy distance_transform_edt {n}x{n} + threshold",
              lambda: ndi.distance_transform_edt(~occ) > r_eff)
    time_call(f"obstacle_distance_m {n}x{n} (numba FH EDT, metres)",
              lambda: obstacle_distance_m(occ, cell_m=c))


def real_log(max_scans: int) -> None:
    path = DATASETS / "carmen" / "mit-csail.clf.bz2"
    try:
        from gndreplay.io import read_ticks  # type: ignore[attr-defined]
    except ImportError:
        print("  skipped: gndreplay.io.read_ticks does not exist yet")
        return
    if not path.is_file():
        print(f"  skipped: {path} not found")
        return
    run: list[tuple[Scan, Pose2D]] = []
    try:
        for tick in read_ticks(path):
            run.append((tick.scan, tick.odom))
            if len(run) >= max_scans:
                break
    except (TypeError, OSError, GndReplayError) as err:  # reader API not what this benchmark expects
        print(f"  skipped: read_ticks({path.name}) failed: {err}")
        return
    if not run:
        print(f"  skipped: no scans read from {path.name}")
        return
    print(f"  {path.name}: {len(run)} scans of {run[0][0].ranges_m.size} beams, raw odometry poses")
    for params in (GRID_400, GRID_200):
        grid = time_integration(params, run)
        if params is GRID_400:
            time_cspace(grid.cells, grid.params.cell_m, "grid after the log")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scans", type=int, default=600, help="synthetic scans (default 600)")
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    run = synthetic_run(args.scans, rng)
    finite = np.concatenate([s.ranges_m[np.isfinite(s.ranges_m)] for s, _ in run])
    print(f"synthetic hall: {len(run)} scans x 361 beams, ranges median {np.median(finite):.1f} m, "
          f"max {finite.max():.1f} m, 30 m max range, 1 % nan")
    grid400 = time_integration(GRID_400, run)
    time_integration(GRID_200, run)
    time_cspace(grid400.cells, 0.05, "grid after the drive")
    clutter = np.where(rng.random((400, 400)) < 0.02, OCCUPIED, grid400.cells).astype(np.uint8)
    time_cspace(clutter, 0.05, "same grid + 2 % random occupied cells (worst case)")
    print("real log (MIT CSAIL):")
    real_log(2000)


if __name__ == "__main__":
    main()
