"""Time the figures of a run directory: each figure's make and save, the whole ``build_figures``, the
import of matplotlib and the report, and the decision snapshots.

    python benchmarks/figures.py RUN_DIR [--repeats 5] [--snapshots 40]

Prints per figure the median over ``--repeats`` of the make (the maker's Figure) and of the save (the PNG),
then the median of ``build_figures`` as a run calls it (its own scheduling: in parallel where it does) and
of the import of matplotlib's Figure and Agg canvas after gndreplay's CLI in a fresh interpreter (paid once
by a run that draws figures). The decision snapshots are drawn from the run's grid snapshot (maps.npz) at
the ticks of snapshots/index.csv (their commands and modes from commands.csv), ``--snapshots`` of them, as
``SnapshotSink`` draws them. Only files in a temporary folder are written; RUN_DIR is read.
"""

from __future__ import annotations

import argparse
import inspect
import math
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from gndreplay.config import load_config
from gndreplay.report.rundir import CONFIG_FILE, RunData, load_run, time_origin
from gndreplay.types import Command, Pose2D

IMPORT_CODE = (
    "import time, gndreplay.cli, gndreplay.report.figures; t = time.perf_counter(); "
    "from matplotlib.figure import Figure; from matplotlib.backends.backend_agg import FigureCanvasAgg; "
    "print(time.perf_counter() - t)"
)


def median_ms(samples: list[float]) -> float:
    return 1e3 * statistics.median(samples)


def import_s(repeats: int) -> float:
    """Median seconds to import matplotlib's Figure and Agg canvas in a fresh interpreter that has imported
    gndreplay's CLI and figures module (what a run pays on top when it draws figures)."""
    out = []
    for _ in range(repeats):
        res = subprocess.run([sys.executable, "-c", IMPORT_CODE], capture_output=True, text=True, check=True)
        out.append(float(res.stdout.strip().splitlines()[-1]))
    return statistics.median(out)


def time_figures(data: RunData, repeats: int, tmp: Path) -> dict[str, tuple[float, float]]:
    """Per figure name, the median make and save [ms]."""
    from gndreplay.report.figures import figure_names, save_figure

    out: dict[str, tuple[list[float], list[float]]] = {}
    for _ in range(repeats):
        for name, make in figure_names(data.window, truth=data.has_truth).items():
            t0 = time.perf_counter()
            fig = make(data)
            t1 = time.perf_counter()
            save_figure(fig, tmp / name)
            t2 = time.perf_counter()
            mk, sv = out.setdefault(name, ([], []))
            mk.append(t1 - t0)
            sv.append(t2 - t1)
    return {n: (median_ms(m), median_ms(s)) for n, (m, s) in out.items()}


def _split_kw(func: Any, split: bool | None) -> dict[str, Any]:
    """``{"split": split}`` when ``func`` takes it (a tree that draws in two processes), else nothing."""
    return {"split": split} if split is not None and "split" in inspect.signature(func).parameters else {}


def time_build(data: RunData, repeats: int, tmp: Path, split: bool | None = None) -> float:
    """Median ms of ``build_figures`` (all the figures, as a run draws them; ``split``: forced on or off
    where the tree can draw in two processes)."""
    from gndreplay.report.figures import build_figures

    out = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        build_figures(data, tmp, **_split_kw(build_figures, split))
        out.append(time.perf_counter() - t0)
    return median_ms(out)


def snapshot_inputs(data: RunData, count: int) -> list[tuple[Any, str]]:
    """Decision inputs at up to ``count`` ticks (those of snapshots/index.csv, else spread over the run), each
    with the run's grid snapshot placed at that tick's pose and its command, mode and flags; the scan is the
    grid's occupied cells within 8 m. Empty without a grid snapshot in maps.npz."""
    from gndreplay.report.decision import DecisionInput
    from gndreplay.report.snapshots import read_snapshot_index

    snap = data.maps.snapshot if data.maps is not None else None
    c = data.commands
    if snap is None or len(c) == 0 or count <= 0:
        return []
    t = c.t_s - time_origin(data)
    index = read_snapshot_index(data.run_dir) or []
    when = [e.elapsed_s for e in index][:count] or list(np.linspace(t[0], t[-1], count))
    n = snap.cells.shape[0]
    rows, cols = np.nonzero(snap.cells == 2)
    occ = np.column_stack([snap.origin_xy[0] + (cols + 0.5) * snap.cell_m,
                           snap.origin_xy[1] + (rows + 0.5) * snap.cell_m])
    centre = np.array([snap.origin_xy[0] + 0.5 * n * snap.cell_m, snap.origin_xy[1] + 0.5 * n * snap.cell_m])
    out = []
    for k, ts in enumerate(when):
        i = int(np.clip(np.searchsorted(t, ts), 0, len(c) - 1))
        theta = float(snap.pose[2]) + 0.7 * k
        rel = occ - centre
        rel = rel[np.hypot(rel[:, 0], rel[:, 1]) < 8.0]
        cs, sn = math.cos(theta), math.sin(theta)
        scan = np.column_stack([cs * rel[:, 0] + sn * rel[:, 1], -sn * rel[:, 0] + cs * rel[:, 1]])
        flags = tuple(f for f, m in c.flags.items() if m[i] and not f.endswith("OVER_BUDGET"))
        t_ns = round(float(c.t_s[i]) * 1e9)
        inp = DecisionInput(
            t_ns=t_ns, t_s=float(t[i]), pose=Pose2D(float(centre[0]), float(centre[1]), theta),
            cells=snap.cells, origin_xy=snap.origin_xy, cell_m=snap.cell_m, scan_xy=scan,
            path_xy=snap.path_xy,
            goal_xy=(float(snap.goal_xy[0]), float(snap.goal_xy[1])),
            command=Command(t_ns, float(c.v_mps[i]), float(c.w_radps[i])), mode=str(c.modes[i]),
            situation=str(c.situations[i]), flags=flags, desired_mode=str(c.desired[i]),
            active_mode=str(c.active[i]))
        out.append((inp, f"benchmark snapshot {k + 1} ({inp.mode})"))
    return out


def time_snapshots(data: RunData, count: int, repeats: int, tmp: Path, split: bool | None = None
                   ) -> tuple[int, float]:
    """The number of snapshots and the median ms of ``SnapshotSink.finish`` drawing them into ``tmp``
    (``split`` as in ``time_build``)."""
    from gndreplay.report import snapshots

    inputs = snapshot_inputs(data, count)
    if not inputs:
        return 0, math.nan
    cfg = load_config(data.run_dir / CONFIG_FILE)
    out = []
    for _ in range(repeats):
        sink = snapshots.SnapshotSink(snapshots.SnapshotOptions(), cfg,
                                      **_split_kw(snapshots.SnapshotSink, split))
        # the ticks a replay would have kept (the sink's own list: there is no public way in from a run dir)
        sink._pending = [snapshots._Pending(inp, [snapshots.Event("mode", headline)])
                         for inp, headline in inputs]
        t0 = time.perf_counter()
        sink.finish(tmp)
        out.append(time.perf_counter() - t0)
    return len(inputs), median_ms(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run_dir", type=Path)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--snapshots", type=int, default=40, help="decision snapshots to draw (0: none)")
    args = ap.parse_args()
    from gndreplay.report import snapshots
    from gndreplay.report.figures import build_figures

    t0 = time.perf_counter()
    data = load_run(args.run_dir)
    load_ms = 1e3 * (time.perf_counter() - t0)
    imp = import_s(args.repeats)
    print(f"{args.run_dir}: {len(data.commands)} ticks; load_run {load_ms:.0f} ms (once); "
          f"medians of {args.repeats} repeats")
    print(f"import of matplotlib (Figure, Agg) after gndreplay.cli: {1e3 * imp:7.0f} ms")
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        time_build(data, 1, tmp, False)  # warm-up: fonts, caches
        per = time_figures(data, args.repeats, tmp)
        print(f"{'figure':<22}{'make ms':>9}{'save ms':>9}{'sum ms':>9}")
        for name, (mk, sv) in per.items():
            print(f"{name:<22}{mk:9.0f}{sv:9.0f}{mk + sv:9.0f}")
        total = sum(mk + sv for mk, sv in per.values())
        print(f"{'sum of the figures':<22}{'':>18}{total:9.0f}")
        for split in (None, False):
            label = "as a run draws them" if split is None else "in one process"
            if split is not None and not _split_kw(build_figures, split):
                continue
            ms = time_build(data, args.repeats, tmp, split)
            print(f"build_figures ({label}): {ms:7.0f} ms; with the import: {ms + 1e3 * imp:7.0f} ms")
        for split in (None, False):
            label = "as a run draws them" if split is None else "in one process"
            if split is not None and not _split_kw(snapshots.SnapshotSink, split):
                continue
            n, ms = time_snapshots(data, args.snapshots, args.repeats, tmp, split)
            if n:
                print(f"decision snapshots ({label}): {n} in {ms:.0f} ms ({ms / n:.0f} ms each)")
            else:
                print("decision snapshots: none (no grid snapshot in maps.npz)")


if __name__ == "__main__":
    main()
