"""report/: map rasters (MapSink, maps.npz), reading a run directory back, the figures and report.md."""

from __future__ import annotations

import json
import math
import struct
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from gndreplay.errors import OutputError
from gndreplay.fsutil import RUN_MARKER, write_marker
from gndreplay.geometry import compose, transform_points
from gndreplay.pipeline.model import FREE, OCCUPIED, UNKNOWN, GridParams, RobotCentredGrid
from gndreplay.pipeline.nd import Situation
from gndreplay.pipeline.stack import TickResult
from gndreplay.report import (
    FIGURES,
    HitRaster,
    MapSink,
    RunDirError,
    build_report,
    load_maps,
    load_run,
)
from gndreplay.report.figures import TRUTH_FIGURES
from gndreplay.report.markdown import trajectory_gap
from gndreplay.report.plots import hit_image, plot_bands
from gndreplay.report.rundir import runs
from gndreplay.types import Command, Flag, Mode, Pose2D, Scan, Tick

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
ROOM = (-2.0, 8.0, -3.0, 3.0)  # x0, x1, y0, y1 of a rectangular room [m]
LASER = Pose2D(0.3, 0.0, 0.0)  # laser 0.3 m ahead of the axle
PERIOD_S = 0.2
T0_NS = 1_000_000_000_000


def room_ranges(laser: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """Exact ranges from a laser pose (inside ROOM) to its walls."""
    a = laser[2] + angles
    dx, dy = np.cos(a), np.sin(a)
    with np.errstate(divide="ignore"):
        tx = np.where(dx > 0, (ROOM[1] - laser[0]) / dx, (ROOM[0] - laser[0]) / dx)
        ty = np.where(dy > 0, (ROOM[3] - laser[1]) / dy, (ROOM[2] - laser[1]) / dy)
    return np.minimum(np.abs(tx), np.abs(ty))


def true_pose(k: int) -> Pose2D:
    return Pose2D(0.025 * k, 0.4 * math.sin(0.02 * k), 0.1 * math.sin(0.02 * k))


def odom_pose(k: int) -> Pose2D:
    """Odometry with a heading drift of 0.002 rad per tick (integrated into position)."""
    p = true_pose(k)
    drift = 0.002 * k
    c, s = math.cos(drift), math.sin(drift)
    return Pose2D(c * p.x - s * p.y, s * p.x + c * p.y, p.theta + drift)


def make_tick(k: int) -> Tick:
    angles = np.linspace(-math.pi / 2, math.pi / 2, 181)
    laser = compose(true_pose(k).as_array(), LASER.as_array())
    t_ns = T0_NS + round(k * PERIOD_S * 1e9)
    scan = Scan(t_ns, room_ranges(laser, angles), angles, max_range_m=30.0, sensor_pose=LASER)
    return Tick(k, t_ns, scan, odom_pose(k))


MODES = (Mode.MPND, Mode.MPND, Mode.MND, Mode.ROTATE, Mode.MPND)
SITUATIONS = (Situation.HSWR, Situation.HSGR, Situation.LS1, Situation.NONE, Situation.HSNR)


def make_result(tick: Tick, pose: Pose2D) -> TickResult:
    k = tick.index
    flags = Flag.NONE
    if k % 7 == 3:
        flags |= Flag.PLANNER_NO_PATH
    if k % 11 == 5:
        flags |= Flag.EMERGENCY_STOP | Flag.MATCH_FAILED
    path = np.column_stack([np.linspace(pose.x, pose.x + 2.0, 9), np.full(9, pose.y)])
    return TickResult(
        t_ns=tick.t_ns, pose_corrected=pose, command=Command(tick.t_ns, 0.3 * math.cos(0.05 * k),
                                                             0.2 * math.sin(0.05 * k)),
        mode=MODES[(k // 10) % 5], situation=SITUATIONS[(k // 8) % 5],
        flags=flags, direction_rad=0.0, goal=(pose.x + 3.0, pose.y), path_xy=path,
        timings_ms={"match": 1.0 + 0.01 * k, "model": 0.5, "planner": 2.0 + (k % 5), "reactor": 0.3},
    )


def tum(t_ns: int, p: Pose2D) -> str:
    return (f"{t_ns // 10**9}.{t_ns % 10**9:09d} {p.x!r} {p.y!r} 0.0 0.0 0.0 {math.sin(p.theta / 2)!r} "
            f"{math.cos(p.theta / 2)!r}\n")


def write_run(run_dir: Path, n: int = 120, sinks: tuple = ()) -> dict:
    """A run directory written like replay.py does, from synthetic ticks (stack every tick)."""
    run_dir.mkdir(parents=True, exist_ok=True)
    grid = RobotCentredGrid(GridParams(size_cells=100, cell_m=0.1))
    cmd = ["t,v,vy,w,mode,situation,flags\n"]
    tim = ["t,match_ms,model_ms,planner_ms,reactor_ms,total_ms\n"]
    odom, cor = ["# timestamp tx ty tz qx qy qz qw\n"], ["# timestamp tx ty tz qx qy qz qw\n"]
    modes: dict[str, int] = {}
    planner = []
    for k in range(n):
        tick = make_tick(k)
        pose = true_pose(k)
        odom.append(tum(tick.t_ns, tick.odom))
        cor.append(tum(tick.t_ns, pose))
        for s in sinks:
            s.add_scan(tick, pose)
        grid.integrate(tick.scan, pose)
        r = make_result(tick, pose)
        for s in sinks:
            s.add_result(tick, r, grid)
        ms = [r.timings_ms[m] for m in ("match", "model", "planner", "reactor")]
        planner.append(ms[2])
        c = r.command
        cmd.append(f"{r.t_ns / 1e9:.9f},{c.v_mps:.6f},{c.vy_mps:.6f},{c.w_radps:.6f},{r.mode.value},"
                   f"{r.situation.name},{'|'.join(r.flags.names())}\n")
        tim.append(f"{r.t_ns / 1e9:.9f}," + ",".join(f"{x:.4f}" for x in ms) + f",{sum(ms):.4f}\n")
        modes[r.mode.value] = modes.get(r.mode.value, 0) + 1
    (run_dir / "commands.csv").write_text("".join(cmd))
    (run_dir / "timing.csv").write_text("".join(tim))
    (run_dir / "trajectory_odom.tum").write_text("".join(odom))
    (run_dir / "trajectory_corrected.tum").write_text("".join(cor))
    q = np.percentile(planner, [50, 90, 99])
    summary = {
        "gndreplay_version": "0.1.0", "log": "synthetic.clf", "ticks": n, "duration_s": (n - 1) * PERIOD_S,
        "modes": dict(sorted(modes.items())), "situations": {"HSWR": 30, "NONE": 20},
        "flags": {"MATCH_FAILED": 11, "PLANNER_NO_PATH": 17, "EMERGENCY_STOP": 11, "GOAL_REACHED": 0},
        "agreement": {"ticks_compared": n - 5, "heading_err_median_deg": 12.345},
        "read_report": {"scans": n, "skipped_lines": 0},
        "options": {"goal": None, "goal_ahead_m": 5.0, "until_s": None, "every": 1},
        "config": {"scanmatch": {"method": "idc"},
                   "supervisor": {"budget_match_s": 0.05, "budget_model_s": 0.05, "budget_planner_s": 0.08,
                                  "budget_reactor_s": 0.02}},
        "latency_ms": {"planner": {"median": float(q[0]), "p90": float(q[1]), "p99": float(q[2]),
                                   "max": float(max(planner))},
                       "total": {"median": 7.25, "p90": 8.5, "p99": 9.125, "max": 9.5}},
    }
    (run_dir / "summary.json").write_text(json.dumps(summary, indent=2))
    for s in sinks:
        s.finish(run_dir)
    return summary


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("run") / "synthetic"
    write_run(d, sinks=(MapSink(cell_m=0.05),))
    build_report(d)
    return d


def png_size(path: Path) -> tuple[int, int]:
    head = path.read_bytes()[:24]
    assert head[:8] == PNG_SIGNATURE and head[12:16] == b"IHDR"
    return struct.unpack(">II", head[16:24])


# ---- rasters ----------------------------------------------------------------------------------------------


def test_hit_raster_counts_points_in_their_cells_across_tiles() -> None:
    r = HitRaster(0.1, tile_cells=4)
    r.add(np.array([[0.05, 0.05], [0.05, 0.05], [-0.05, 0.35], [1.23, -0.91], [np.nan, 0.0]]))
    a, (x0, y0) = r.to_array()
    assert (x0, y0) == pytest.approx((-0.1, -1.0))
    assert a.sum() == 4 and a.dtype == np.uint16
    assert a[int((0.05 - y0) // 0.1), int((0.05 - x0) // 0.1)] == 2
    assert a[int((0.35 - y0) // 0.1), int((-0.05 - x0) // 0.1)] == 1
    assert a[int((-0.91 - y0) // 0.1), int((1.23 - x0) // 0.1)] == 1
    assert r.n_tiles == 3  # only the tiles touched: (0, 0), (0, -1), (-3, 3) in 0.4 m tile units


def test_hit_raster_memory_follows_area_not_count() -> None:
    r = HitRaster(0.05)
    pts = np.random.default_rng(0).uniform(-5.0, 5.0, size=(500, 2))
    for _ in range(200):
        r.add(pts)
    tiles = r.n_tiles
    r.add(pts)
    assert r.n_tiles == tiles <= 9  # 10 m square in 12.8 m tiles
    assert r.to_array()[0].sum() == 201 * 500


def test_map_sink_places_hits_at_pose_times_sensor_pose(tmp_path: Path) -> None:
    sink = MapSink(cell_m=0.05)
    tick = make_tick(40)
    corrected = Pose2D(1.0, 2.0, 0.7)
    sink.add_scan(tick, corrected)
    sink.finish(tmp_path)
    maps = load_maps(tmp_path / "maps.npz")
    pts = tick.scan.points()
    for hits, origin, pose in ((maps.corrected_hits, maps.corrected_origin_xy, corrected),
                               (maps.raw_hits, maps.raw_origin_xy, tick.odom)):
        world = transform_points(compose(pose.as_array(), LASER.as_array()), pts)
        rows = np.floor(world[:, 1] / 0.05).astype(int) - round(origin[1] / 0.05)
        cols = np.floor(world[:, 0] / 0.05).astype(int) - round(origin[0] / 0.05)
        expected = np.zeros_like(hits, dtype=np.int64)
        np.add.at(expected, (rows, cols), 1)
        assert np.array_equal(hits, expected)
    assert maps.scans == 1 and maps.snapshot is None


def _feed(sink: MapSink, n: int) -> None:
    grid = RobotCentredGrid(GridParams(size_cells=20, cell_m=0.1))
    for k in range(n):
        tick = make_tick(k)
        sink.add_scan(tick, true_pose(k))
        grid.cells[:] = UNKNOWN
        grid.cells[k % 20, :] = OCCUPIED
        sink.add_result(tick, make_result(tick, true_pose(k)), grid)
        assert sink.candidates <= sink.max_snapshots


@pytest.mark.parametrize("n", [1, 2, 37, 500, 1001])
def test_snapshot_is_near_the_middle_of_the_run_with_bounded_memory(n: int) -> None:
    sink = MapSink(max_snapshots=8)
    _feed(sink, n)
    snap = sink.snapshot()
    assert snap is not None
    duration = (n - 1) * PERIOD_S
    assert abs(snap.elapsed_s - duration / 2) <= max(PERIOD_S, duration / 8)
    assert snap.tick == round(snap.elapsed_s / PERIOD_S)
    assert np.all(snap.cells[snap.tick % 20] == OCCUPIED)  # a copy taken at that tick


def test_snapshot_at_a_given_time_or_the_last_tick() -> None:
    sink = MapSink(snapshot_at_s=10.0)
    _feed(sink, 200)
    snap = sink.snapshot()
    assert snap is not None and snap.tick == 50 and snap.elapsed_s == pytest.approx(10.0)
    short = MapSink(snapshot_at_s=1e6)
    _feed(short, 30)
    last = short.snapshot()
    assert last is not None and last.tick == 29
    assert last.mode == make_result(make_tick(29), true_pose(29)).mode.value


def test_maps_npz_round_trip(run_dir: Path) -> None:
    maps = load_maps(run_dir / "maps.npz")
    assert maps.scans == 120 and maps.cell_m == 0.05
    assert maps.corrected_hits.dtype == np.uint16 and maps.corrected_hits.sum() == 120 * 181
    # corrected hits lie on the room's walls (the forward-looking laser never sees the wall behind x = 0)
    x0, x1, y0, y1 = maps.corrected_extent
    assert (x1, y0, y1) == pytest.approx(ROOM[1:], abs=0.06) and x0 == pytest.approx(0.3, abs=0.06)
    # the drifting odometry smears the raw map over a larger area
    assert maps.raw_hits.size > maps.corrected_hits.size
    snap = maps.snapshot
    assert snap is not None and snap.cells.shape == (100, 100) and snap.cell_m == 0.1
    assert set(np.unique(snap.cells).tolist()) <= {int(UNKNOWN), int(FREE), int(OCCUPIED)}
    assert snap.path_xy.shape == (9, 2) and abs(snap.elapsed_s - 119 * PERIOD_S / 2) < 119 * PERIOD_S / 16


# ---- reading back -----------------------------------------------------------------------------------------


def test_load_run_reads_the_tables(run_dir: Path) -> None:
    data = load_run(run_dir)
    c = data.commands
    assert len(c) == 120 and c.t_s[1] - c.t_s[0] == pytest.approx(PERIOD_S)
    assert c.v_mps[0] == pytest.approx(0.3) and c.modes[25] == "mND" and c.situations[0] == "HSWR"
    assert np.count_nonzero(c.flags["PLANNER_NO_PATH"]) == len(range(3, 120, 7))
    assert np.array_equal(np.flatnonzero(c.flags["EMERGENCY_STOP"]), np.arange(5, 120, 11))
    assert data.timing.ms["planner"][4] == pytest.approx(6.0)
    assert data.traj_corrected.shape == (120, 4)
    assert data.traj_odom[50, 3] == pytest.approx(odom_pose(50).theta)


def test_load_run_errors_name_the_file(tmp_path: Path) -> None:
    d = tmp_path / "run"
    write_run(d, n=5)
    header = "t,v,vy,w,mode,situation,flags\n"
    (d / "commands.csv").write_text(header + "1.0,0.1,0.0,0.2,mpND,HSWR,\n2.0,x,0,0,mpND,HSWR,\n")
    with pytest.raises(RunDirError, match=r"commands.csv line 3: expected 7 fields"):
        load_run(d)
    (d / "commands.csv").unlink()
    with pytest.raises(RunDirError, match=r"commands.csv: missing"):
        build_report(d)
    with pytest.raises(RunDirError, match="not a directory"):
        load_run(tmp_path / "nope")


# ---- figures and report.md --------------------------------------------------------------------------------


def test_build_report_writes_the_pngs_and_the_report(run_dir: Path) -> None:
    drawn = [name for name in FIGURES if name not in TRUTH_FIGURES]  # the run has no ground truth
    assert not any((run_dir / name).exists() for name in TRUTH_FIGURES)
    sizes = {name: png_size(run_dir / name) for name in drawn}
    assert sizes["fig_commands.png"][0] == 1440 and sizes["fig_timing.png"] == (1440, 966)  # 5 panels
    assert sizes["fig_model.png"][0] == 1560 and sizes["fig_raw.png"][0] == 1080
    assert sizes["fig_modes.png"][0] >= 1440  # the timeline, with its legend beside it
    for w, h in sizes.values():
        assert 500 <= h <= 1300 and w >= 1000
    text = (run_dir / "report.md").read_text()
    for name in FIGURES:
        assert (f"]({name})" in text) == (name in drawn)
    summary = json.loads((run_dir / "summary.json").read_text())
    q = summary["latency_ms"]["planner"]
    assert f"| planner | {q['median']:.2f} | {q['p90']:.2f} | {q['p99']:.2f} | {q['max']:.2f} | 80 |" in text
    assert "| total | 7.25 | 8.50 | 9.12 | 9.50 |" in text
    for mode, count in summary["modes"].items():
        assert f"| {mode} | {count} |" in text
    assert "| PLANNER_NO_PATH | 17 |" in text and "Never fired: GOAL_REACHED." in text
    assert "| matcher | idc |" in text and "| match failures (MATCH_FAILED) | 11 of 120 ticks |" in text
    assert "| heading_err_median_deg | 12.345 |" in text
    assert "| ticks (stack runs) | 120 |" in text and "| scan period (median) | 200.0 ms |" in text
    # a run directory written before the audit (no desired/active columns, no interventions) still reads
    assert "## Interventions\n\nNot recorded (a run written before the assisted-navigation audit)." in text


def test_figures_show_the_data(run_dir: Path) -> None:
    from matplotlib.image import imread

    raw = imread(run_dir / "fig_raw.png")[..., :3]
    model = imread(run_dir / "fig_model.png")[..., :3]
    dark = lambda img: np.mean(img.max(axis=2) < 0.35)  # noqa: E731
    assert dark(raw) > 0.002 and dark(model) > 0.002  # walls are drawn
    orange = lambda img: np.mean((img[..., 0] > 0.9) & (img[..., 1] > 0.4) & (img[..., 1] < 0.6)  # noqa: E731
                                 & (img[..., 2] < 0.2))
    assert orange(raw) > 0.0002  # the odometry trajectory
    grey = lambda img: np.mean(np.all(np.abs(img - 158 / 255) < 0.02, axis=2))  # noqa: E731
    assert grey(model) > 0.01  # the unknown cells of the robot-centred grid panel


def test_build_report_is_deterministic_and_needs_only_the_files(run_dir: Path, tmp_path: Path) -> None:
    copy = tmp_path / "copy"
    copy.mkdir()
    for name in ("commands.csv", "timing.csv", "trajectory_odom.tum", "trajectory_corrected.tum",
                 "summary.json", "maps.npz"):
        (copy / name).write_bytes((run_dir / name).read_bytes())
    written = build_report(copy)
    drawn = [n for n in FIGURES if n not in TRUTH_FIGURES]  # the run has no ground truth
    assert [p.name for p in written] == [*drawn, "report.md"]
    for name in drawn:
        assert (copy / name).read_bytes() == (run_dir / name).read_bytes(), name
    report = (copy / "report.md").read_text()
    assert report.replace("copy", "synthetic") == (run_dir / "report.md").read_text()


def test_build_report_without_maps(tmp_path: Path) -> None:
    d = tmp_path / "nomaps"
    write_run(d, n=10)
    written = build_report(d)
    assert all(p.read_bytes()[:8] == PNG_SIGNATURE for p in written[:4])


def test_trajectory_gap_anchors_at_the_first_pose() -> None:
    t = np.arange(3.0)
    odom = np.array([[0, 1.0, 1.0, math.pi / 2], [1, 1.0, 2.0, math.pi / 2], [2, 1.0, 3.0, math.pi / 2]])
    cor = np.array([[0, 0.0, 0.0, 0.0], [1, 1.0, 0.0, 0.0], [2, 2.0, 0.5, 0.0]])
    odom[:, 0] = cor[:, 0] = t
    gap = trajectory_gap(odom, cor)
    assert gap["path_odom_m"] == pytest.approx(2.0) and gap["final_gap_m"] == pytest.approx(0.5)
    assert gap["max_gap_m"] == pytest.approx(0.5)
    assert gap["path_corrected_m"] == pytest.approx(1 + math.hypot(1, 0.5))


# ---- plot helpers -----------------------------------------------------------------------------------------


def test_runs_and_bands() -> None:
    from matplotlib.collections import PolyCollection
    from matplotlib.figure import Figure

    start, end = runs(np.array(["a", "a", "b", "a", "a", "a"]))
    assert start.tolist() == [0, 2, 3] and end.tolist() == [2, 3, 6]
    ax = Figure().subplots()
    plot_bands(ax, np.arange(6.0), ["a", "a", "b", "a", "a", "a"], colors={"a": "red", "b": "blue"})
    polys = [c for c in ax.collections if isinstance(c, PolyCollection)]
    assert [len(p.get_paths()) for p in polys] == [2, 1]
    b = polys[1].get_paths()[0].vertices
    assert b[:, 0].min() == 2.0 and b[:, 0].max() == 3.0


def test_hit_image_keeps_thin_walls_when_downsampling() -> None:
    hits = np.zeros((1000, 1000), dtype=np.uint16)
    hits[500, :] = 1  # a one-cell wall seen once
    hits[:, 10] = 1000  # a wall seen a thousand times
    img = hit_image(hits, max_pixels=100)
    assert img.shape == (100, 100)
    assert np.all(img[50, :] > 0.0) and np.all(img[:, 1] == 1.0) and img[0, 50] == 0.0


# ---- end to end (replay.run_log with the sinks) ---------------------------------------------------------

SAMPLE_LOG = Path(__file__).resolve().parents[1] / "sample_logs" / "office.clf.bz2"


def _replay_with_sinks(log: Path, out: Path, until_s: float) -> int:
    from gndreplay.config import Config
    from gndreplay.replay import RunOptions, run_log
    from gndreplay.report import McapSink, ReportSink

    drawn: list[bool] = []
    with McapSink() as mcap:  # ReportSink draws inside the staging directory: the run appears complete
        summary = run_log(log, Config(), out, options=RunOptions(until_s=until_s),
                          sinks=[MapSink(), mcap, ReportSink(on_draw=lambda: drawn.append(True))])
    assert drawn == [True] and summary.out_dir == out
    assert (out / "report.md").read_text().startswith(f"# gndreplay run: {out.name}\n")
    return summary.ticks


def _figures_of(out: Path) -> list[str]:
    """The figures a run directory holds: fig_error.png only with ground truth."""
    truth = (out / "trajectory_truth.tum").is_file()
    names = [n for n in FIGURES if truth or n not in TRUTH_FIGURES]
    assert sorted(names) == sorted(p.name for p in out.glob("fig_*.png"))
    return names


def _check_run_dir(out: Path, ticks: int) -> None:
    from rosbags.highlevel import AnyReader

    for name in _figures_of(out):
        assert png_size(out / name)[0] >= 1000
    assert "## Latency per tick [ms]" in (out / "report.md").read_text()
    with AnyReader([out / "results.mcap"]) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
    assert counts["/gndreplay/odom"] == counts["/cmd_vel"] == counts["/tf"] == ticks
    assert 1 <= counts["/gndreplay/grid"] <= ticks  # the grid of each tick that changed it
    maps = load_maps(out / "maps.npz")
    assert maps.scans == ticks and maps.snapshot is not None
    # report rebuilds the same figures from the files alone
    before = {name: (out / name).read_bytes() for name in _figures_of(out)}
    build_report(out)
    assert all((out / name).read_bytes() == data for name, data in before.items())


def test_replay_of_the_sample_log_writes_figures_report_and_mcap(tmp_path: Path) -> None:
    out = tmp_path / "office"
    ticks = _replay_with_sinks(SAMPLE_LOG, out, until_s=30.0)
    assert ticks > 100
    assert "fig_error.png" in _figures_of(out)  # the sample has ground truth
    _check_run_dir(out, ticks)


@pytest.mark.slow
def test_cli_run_mcap_on_aces_writes_figures_report_and_mcap(datasets: Path, tmp_path: Path) -> None:
    """`gndreplay run --mcap` on the whole ACES log (CARMEN form), then `gndreplay report` on the result."""
    from typer.testing import CliRunner

    from gndreplay.cli import app

    out = tmp_path / "aces"
    result = CliRunner().invoke(app, ["run", str(datasets / "carmen" / "aces.clf.bz2"), "--mcap", "--out",
                                      str(out), "--quiet"])
    assert result.exit_code == 0, result.output
    ticks = json.loads((out / "summary.json").read_text())["ticks"]
    assert ticks == 7374 == len((out / "commands.csv").read_text().splitlines()) - 1
    _check_run_dir(out, ticks)
    before = {name: (out / name).read_bytes() for name in _figures_of(out)}
    for name in before:
        (out / name).unlink()
    again = CliRunner().invoke(app, ["report", str(out)])
    assert again.exit_code == 0, again.output
    assert all((out / name).read_bytes() == data for name, data in before.items())


# ---- review F1: never over the user's files; malformed summary.json ---------------------------------------


def _copy_run(src: Path, dst: Path) -> Path:
    dst.mkdir()
    for name in ("commands.csv", "timing.csv", "trajectory_odom.tum", "trajectory_corrected.tum",
                 "summary.json"):
        (dst / name).write_bytes((src / name).read_bytes())
    return dst


def test_report_never_overwrites_a_file_gndreplay_did_not_write(run_dir: Path, tmp_path: Path) -> None:
    nomark = _copy_run(run_dir, tmp_path / "nomark")  # no marker: any existing target is the user's
    (nomark / "report.md").write_text("my own report\n")
    with pytest.raises(OutputError, match=r"nomark/report\.md: exists and was not written by gndreplay"):
        build_report(nomark)
    assert (nomark / "report.md").read_text() == "my own report\n"
    assert not any(nomark.glob("fig_*.png"))  # refused before anything was drawn
    marked = _copy_run(run_dir, tmp_path / "marked")
    write_marker(marked)  # the run's files are gndreplay's, a figure added later is not
    (marked / "fig_raw.png").write_bytes(b"mine")
    with pytest.raises(OutputError, match=r"fig_raw\.png: exists and was not written by gndreplay"):
        build_report(marked)
    assert (marked / "fig_raw.png").read_bytes() == b"mine"
    (marked / "fig_raw.png").unlink()
    build_report(marked)
    build_report(marked)  # its own figures (now listed in the marker) are redrawn
    assert "fig_raw.png" in (marked / RUN_MARKER).read_text().splitlines()


def test_a_failed_figure_leaves_the_previous_file(run_dir: Path, tmp_path: Path,
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    d = _copy_run(run_dir, tmp_path / "r")
    write_marker(d)
    build_report(d)
    before = (d / "fig_model.png").read_bytes()

    def half_then_fail(self: Any, fname: Any, **kw: Any) -> None:
        Path(fname).write_bytes(b"\x89PNG half")
        raise OSError("disk full")

    monkeypatch.setattr("matplotlib.figure.Figure.savefig", half_then_fail)
    with pytest.raises(OSError, match="disk full"):
        build_report(d)
    assert (d / "fig_model.png").read_bytes() == before
    assert sorted(p.name for p in d.iterdir() if p.name.startswith(".")) == [RUN_MARKER]  # no temporaries


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("[1, 2]", r"summary\.json: expected a JSON object, got list"),
        ('{"ticks": "x"}', r"summary\.json: key 'ticks' must be a count"),
        ('{"flags": [1]}', r"summary\.json: key 'flags' must be a table of counts"),
        ('{"options": {"goal": "north"}}', r"summary\.json: key 'options' must be a table"),
        ('{"config": {"supervisor": 3}}', r"summary\.json: key 'config' must be a table"),
        ('{"latency_ms": {"match": {"p99": "slow"}}}', r"summary\.json: key 'latency_ms'"),
        ('{"options": null}', r"summary\.json: key 'options' must be a table"),
        ('{"matcher_health": {"scans": "many"}}', r"summary\.json: key 'matcher_health' must be a table"),
        ('{"matcher_health": {"worst_window": {"sigmas": "4"}}}', r"key 'matcher_health'"),
        ('{"matcher_health": {"warning": 3}}', r"key 'matcher_health'"),
    ],
)
def test_a_malformed_summary_is_one_run_dir_error(run_dir: Path, tmp_path: Path, text: str,
                                                  match: str) -> None:
    d = _copy_run(run_dir, tmp_path / "r")
    (d / "summary.json").write_text(text)
    with pytest.raises(RunDirError, match=match):
        build_report(d)
    assert not any(d.glob("fig_*.png")) and not (d / "report.md").exists()


# ---- drawing fast: two processes, lines kept to what shows ----------------------------------------------


def test_figures_drawn_in_two_processes_are_the_bytes_drawn_in_one(run_dir: Path, tmp_path: Path) -> None:
    from gndreplay.report.figures import build_figures

    data = load_run(run_dir)
    one, two = tmp_path / "one", tmp_path / "two"
    one.mkdir()
    two.mkdir()
    names = [p.name for p in build_figures(data, one, split=False)]
    assert [p.name for p in build_figures(data, two, split=True)] == names
    assert len(names) >= 5
    for name in names:
        assert (one / name).read_bytes() == (two / name).read_bytes(), name
    assert sorted(p.name for p in two.iterdir()) == sorted(names)  # no temporary file left behind


def test_run_split_redoes_what_the_child_failed_and_raises_what_this_process_raises(tmp_path: Path) -> None:
    import os

    from gndreplay.report.split import run_split, split_jobs

    assert split_jobs([1.0, 3.0, 1.0, 1.0]) == ([1], [0, 2, 3])  # the best balance
    assert split_jobs([1.4, 1.2, 2.2, 2.0, 1.3]) == ([0, 1, 4], [2, 3])
    many = split_jobs([1.0] * 40)
    assert sorted(many[0] + many[1]) == list(range(40)) and len(many[0]) == len(many[1]) == 20
    parent = os.getpid()

    def write(k: int, fail_in_child: bool = False) -> None:
        if fail_in_child and os.getpid() != parent:
            raise RuntimeError("child failed")
        (tmp_path / f"{k}.txt").write_text(f"{k} by {'parent' if os.getpid() == parent else 'child'}")

    run_split([lambda k=k: write(k, fail_in_child=True) for k in range(4)], split=True)
    assert sorted(p.read_text() for p in tmp_path.iterdir()) == [f"{k} by parent" for k in range(4)]

    def boom() -> None:
        if os.getpid() == parent:
            raise ValueError("parent job failed")
        write(9)

    with pytest.raises(ValueError, match="parent job failed"):
        run_split([boom, boom], split=True)
    assert (tmp_path / "9.txt").read_text() == "9 by child"  # the child was waited for


def test_run_split_runs_every_job_here_when_no_process_can_be_forked(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import os

    from gndreplay.report.split import run_split

    def no_fork() -> int:
        raise BlockingIOError(11, "Resource temporarily unavailable")

    monkeypatch.setattr(os, "fork", no_fork)
    jobs = [lambda k=k: (tmp_path / f"{k}.txt").write_text(str(os.getpid())) for k in range(3)]
    run_split(jobs, split=True)
    assert sorted(p.read_text() for p in tmp_path.iterdir()) == [str(os.getpid())] * 3


def test_column_extremes_keep_every_columns_least_and_largest_value() -> None:
    from gndreplay.report.plots import column_extremes

    rng = np.random.default_rng(3)
    t = np.sort(rng.uniform(-5.0, 105.0, 20_000))
    y = rng.lognormal(size=t.size)
    y[[100, 7000, 15000]] = [1e4, 1e-6, np.nan]
    keep = column_extremes(t, y, span=(0.0, 100.0), columns=300)
    assert keep.size <= 4 * 302 and np.all(np.diff(keep) > 0)
    assert {100, 7000} <= set(keep.tolist())
    col = np.clip(np.floor(t * 3.0), -1, 300).astype(int)
    for c in np.unique(col):
        inside, kept = col == c, col[keep] == c
        assert np.nanmax(y[inside]) == np.nanmax(y[keep][kept])
        assert np.nanmin(y[inside]) == np.nanmin(y[keep][kept])
        assert t[inside][0] == t[keep][kept][0] and t[inside][-1] == t[keep][kept][-1]
    np.testing.assert_array_equal(column_extremes(t[:50], y[:50], span=(0.0, 100.0), columns=300),
                                  np.arange(50))
