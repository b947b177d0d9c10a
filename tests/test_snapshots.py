"""Event snapshots (report.snapshots), the decision view (report.decision), the animation (report.animate)."""

from __future__ import annotations

import csv
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from PIL import Image

from gndreplay.config import Config, preset
from gndreplay.errors import ConfigError, OutputError
from gndreplay.fsutil import RUN_MARKER
from gndreplay.pipeline.model import OCCUPIED, GridParams, RobotCentredGrid
from gndreplay.pipeline.nd import Situation
from gndreplay.pipeline.stack import TickResult
from gndreplay.report import (
    SNAPSHOTS_DIR,
    RunDirError,
    SnapshotOptions,
    animate_run,
    build_report,
    decision_input,
    decision_view,
    draw_decision,
    read_snapshot_index,
    tick_events,
)
from gndreplay.report.animate import _scan_points
from gndreplay.report.decision import decision_figure, grid_from_cells
from gndreplay.report.markdown import timeline_section
from gndreplay.report.snapshots import INDEX_FILE, INDEX_HEADER, EventGate, SnapshotEntry
from gndreplay.types import Command, Flag, Mode, Pose2D, Scan, Tick

SAMPLE_LOG = Path(__file__).resolve().parents[1] / "sample_logs" / "office.clf.bz2"
S = 1_000_000_000


def _r(mode: Mode = Mode.MPND, flags: Flag = Flag.NONE, *, t_s: float = 0.0, desired: str = "gnd",
       active: str = "gnd", reason: str = "", v: float = 0.2, w: float = 0.0,
       region: tuple[int, int] | None = None) -> TickResult:
    t = round(t_s * S)
    return TickResult(t_ns=t, pose_corrected=Pose2D(1.0, 2.0, 0.5), command=Command(t, v, w), mode=mode,
                      situation=Situation.HSGR, flags=flags, direction_rad=0.1, goal=(4.0, 2.0),
                      path_xy=np.array([[1.0, 2.0], [2.5, 2.0], [4.0, 2.0]]), desired_mode=desired,
                      active_mode=active, takeover_reason=reason, nd_region=region, nd_target_xy=(1.0, 0.1))


def _kinds(prev: TickResult | None, cur: TickResult) -> list[str]:
    return [e.kind for e in tick_events(prev, cur)]


# ---- event detection ----------------------------------------------------------------------------------


def test_mode_changes_between_gnd_modes_are_events_reflexive_ends_are_not() -> None:
    assert tick_events(_r(Mode.MPND), _r(Mode.MND))[0].reason == "mpND -> mND"
    assert _kinds(_r(Mode.MND), _r(Mode.ROTATE)) == ["mode"]
    assert _kinds(_r(Mode.TELEOP, desired="teleop", active="teleop"),
                  _r(Mode.ROTATE, desired="teleop", active="teleop")) == ["mode"]
    assert _kinds(_r(Mode.MPND), _r(Mode.MPND)) == []
    assert _kinds(None, _r(Mode.MND)) == []  # the first tick changes nothing
    assert _kinds(_r(Mode.SAFE_SLOW), _r(Mode.MPND)) == []  # a reflexive override ended: GND's mode stayed


def test_reflexive_rules_emergency_trap_and_escape_fire_at_their_onset() -> None:
    assert _kinds(_r(Mode.MPND), _r(Mode.EMERGENCY, Flag.EMERGENCY_STOP)) == ["emergency"]
    assert _kinds(_r(Mode.EMERGENCY, Flag.EMERGENCY_STOP), _r(Mode.EMERGENCY, Flag.EMERGENCY_STOP)) == []
    assert _kinds(_r(Mode.MPND), _r(Mode.MPND, Flag.EMERGENCY_STOP)) == ["emergency"]
    for rule in (Mode.SAFE_SLOW, Mode.SAFE_TURN, Mode.SAFE_REVERSE, Mode.STALE):
        assert _kinds(_r(Mode.MPND), _r(rule)) == ["reflexive"]
        assert _kinds(_r(rule), _r(rule)) == []
    assert _kinds(_r(Mode.SAFE_SLOW), _r(Mode.SAFE_TURN)) == ["reflexive"]  # another rule took over
    assert _kinds(_r(Mode.ROTATE), _r(Mode.ESCAPE, Flag.TRAP_DETECTED)) == ["trap", "escape"]
    assert _kinds(_r(Mode.ESCAPE, Flag.TRAP_DETECTED), _r(Mode.ESCAPE)) == []
    assert _kinds(_r(Mode.ROTATE), _r(Mode.ROTATE, Flag.TRAP_DETECTED)) == ["trap"]


@pytest.mark.parametrize("flag", [Flag.PLANNER_NO_PATH, Flag.GOAL_IN_OBSTACLE, Flag.PLANNER_TIMEOUT,
                                  Flag.PLANNER_FALLBACK])
def test_planner_failures_and_fallbacks_fire_when_they_begin(flag: Flag) -> None:
    events = tick_events(_r(Mode.MPND), _r(Mode.MPND, flag))
    assert [e.kind for e in events] == ["planner"] and flag.name in events[0].reason
    assert _kinds(_r(Mode.MPND, flag), _r(Mode.MPND, flag)) == []
    assert _kinds(_r(Mode.MPND, flag), _r(Mode.MPND, flag | Flag.MATCH_FAILED)) == []


def test_takeover_and_goal_fire_at_their_onset() -> None:
    teleop = _r(Mode.TELEOP, desired="teleop", active="teleop")
    taken = _r(Mode.MND, desired="teleop", active="local", reason="teleop: swept area occupied (scan)")
    events = tick_events(teleop, taken)
    assert [e.kind for e in events] == ["mode", "takeover"]
    assert events[1].reason == "local took over from teleop: teleop: swept area occupied (scan)"
    assert _kinds(taken, taken) == [] and _kinds(None, taken) == ["takeover"]
    assert _kinds(_r(Mode.MPND), _r(Mode.GOAL, Flag.GOAL_REACHED)) == ["goal"]
    assert _kinds(_r(Mode.GOAL, Flag.GOAL_REACHED), _r(Mode.GOAL, Flag.GOAL_REACHED)) == []


# ---- rate limit and cap ----------------------------------------------------------------------------------


def _admit(gate: EventGate, prev: TickResult, cur: TickResult) -> list[str]:
    return [e.kind for e in gate.admit(tick_events(prev, cur), cur.t_ns)]


def test_gate_limits_each_kind_per_interval_and_per_run() -> None:
    gate = EventGate(SnapshotOptions(min_interval_s=5.0, max_per_kind=3, max_snapshots=100))
    a, b = Mode.MPND, Mode.MND
    assert _admit(gate, _r(a), _r(b, t_s=0.0)) == ["mode"]
    assert _admit(gate, _r(b), _r(a, t_s=4.9)) == []  # within 5 s of the last mode snapshot
    assert _admit(gate, _r(a), _r(Mode.SAFE_SLOW, t_s=4.9)) == ["reflexive"]  # another kind is not limited
    assert _admit(gate, _r(a), _r(b, t_s=5.0)) == ["mode"]
    assert _admit(gate, _r(b), _r(a, t_s=10.0)) == ["mode"]
    assert _admit(gate, _r(a), _r(b, t_s=20.0)) == []  # max_per_kind reached
    assert gate.drawn == 4 and gate.dropped == 2


def test_gate_caps_the_run_and_events_of_one_tick_share_a_snapshot() -> None:
    gate = EventGate(SnapshotOptions(min_interval_s=0.0, max_snapshots=2))
    assert _admit(gate, _r(Mode.ROTATE), _r(Mode.ESCAPE, Flag.TRAP_DETECTED, t_s=1.0)) == ["trap", "escape"]
    assert gate.drawn == 1
    assert _admit(gate, _r(Mode.MPND), _r(Mode.MND, t_s=2.0)) == ["mode"]
    assert _admit(gate, _r(Mode.MND), _r(Mode.EMERGENCY, t_s=3.0)) == []  # two snapshots: the cap
    assert gate.drawn == 2 and gate.dropped == 1


def test_gate_draws_only_the_kinds_asked_for() -> None:
    gate = EventGate(SnapshotOptions(kinds=("emergency",)))
    assert _admit(gate, _r(Mode.MPND), _r(Mode.MND, t_s=1.0)) == []
    assert _admit(gate, _r(Mode.MND), _r(Mode.EMERGENCY, t_s=2.0)) == ["emergency"]


@pytest.mark.parametrize("kwargs", [{"min_interval_s": -1.0}, {"max_snapshots": -1}, {"max_per_kind": 1.5},
                                    {"kinds": ("modes",)}, {"radius_m": 0.1}, {"dpi": 5}])
def test_bad_snapshot_options_are_one_config_error(kwargs: dict[str, object]) -> None:
    with pytest.raises(ConfigError, match="snapshots: "):
        SnapshotOptions(**kwargs)  # type: ignore[arg-type]


# ---- the decision view --------------------------------------------------------------------------------


def _grid_with_wall() -> RobotCentredGrid:
    grid = RobotCentredGrid(GridParams(200, 0.05), centre_xy=(1.0, 2.0))
    angles = np.linspace(-math.pi / 2, math.pi / 2, 181)
    ranges = np.where(np.abs(angles) < 0.6, 2.0, np.inf)
    grid.integrate(Scan(0, ranges, angles, 8.0), Pose2D(1.0, 2.0, 0.5))
    return grid


def test_grid_from_cells_answers_what_the_stacks_grid_answers() -> None:
    grid = _grid_with_wall()
    again = grid_from_cells(grid.cells.copy(), grid.origin_xy, grid.params.cell_m)
    assert again.origin_xy == grid.origin_xy
    pose = Pose2D(1.3, 1.9, -0.4)
    np.testing.assert_array_equal(again.occupied_points(pose, 5.0), grid.occupied_points(pose, 5.0))
    assert grid.occupied_points(pose, 5.0).shape[0] > 10


def test_decision_view_holds_the_diagram_region_and_sweep() -> None:
    cfg = preset("xr4000")
    grid = _grid_with_wall()
    tick = Tick(0, 0, Scan(0, np.array([2.0, np.inf]), np.array([0.0, 0.1]), 8.0), Pose2D(1.0, 2.0, 0.5))
    inp = decision_input(tick, _r(region=(170, 10), flags=Flag.PLANNER_OVER_BUDGET), grid, t0_ns=-2 * S)
    assert inp.t_s == 2.0 and inp.flags == ()  # wall-clock flags never reach a picture
    np.testing.assert_allclose(inp.scan_xy, [[2.0, 0.0]])
    view = decision_view(inp, cfg, headline="mode: x", radius_m=3.0)
    n = cfg.reactor.n_sectors
    assert view.region.sum() == 21 and view.region[0] and view.region[170] and not view.region[90]
    assert view.diagram.bisectors_rad.size == n and np.isfinite(view.diagram.dist_m).any()
    assert view.sweep.shape[1] == 3 and view.sweep[-1, 0] > 0.0  # driving forward
    assert view.title.startswith("t = 2.00 s  —  mode: x\nmpND")
    side = 2 * (math.ceil(3.0 / 0.05) + 1) + 1
    assert view.cells.shape == (side, side)
    still = decision_view(decision_input(tick, _r(v=0.0), grid, t0_ns=0), cfg)
    assert still.sweep.shape == (0, 3)
    _fig, ax = decision_figure()
    draw_decision(ax, view)
    labels = ax.get_legend_handles_labels()[1]
    assert {"ND+ chosen region", "swept over braking", "footprint", "scan", "planned path"} <= set(labels)


# ---- snapshots of a replay and of a closed-loop run -----------------------------------------------------


def _index_rows(run_dir: Path) -> list[dict[str, str]]:
    text = (run_dir / SNAPSHOTS_DIR / INDEX_FILE).read_text()
    assert text.startswith(INDEX_HEADER)
    return list(csv.DictReader(text.splitlines()))


def _check_snapshots(run_dir: Path) -> list[dict[str, str]]:
    rows = _index_rows(run_dir)
    assert rows
    listed = set((run_dir / SNAPSHOTS_DIR / RUN_MARKER).read_text().split("\n"))
    for row in rows:
        png = run_dir / SNAPSHOTS_DIR / row["file"]
        with Image.open(png) as im:
            assert im.format == "PNG" and im.size == (700, 800)
        assert row["file"] in listed and row["kind"] and row["reason"]
    assert INDEX_FILE in listed
    return rows


def _replay(out: Path, until_s: float, *, overwrite: bool = False) -> None:
    from gndreplay.replay import RunOptions, run_log
    from gndreplay.report import default_sinks

    run_log(SAMPLE_LOG, Config(), out, options=RunOptions(until_s=until_s), overwrite=overwrite,
            sinks=default_sinks(figures=True, snapshots=SnapshotOptions(min_interval_s=2.0)))


def test_replay_with_snapshots_writes_pngs_index_and_the_timeline(tmp_path: Path) -> None:
    out = tmp_path / "office"
    _replay(out, 40.0)
    rows = _check_snapshots(out)
    assert any(r["kind"] == "reflexive" for r in rows)
    report = (out / "report.md").read_text()
    assert "## Timeline" in report
    for r in rows:
        assert f"[{r['file']}]({SNAPSHOTS_DIR}/{r['file']})" in report
    entries = read_snapshot_index(out)
    assert entries is not None and [e.file for e in entries] == [r["file"] for r in rows]
    # `gndreplay report` redraws report.md with the timeline, from the files alone
    (out / "report.md").unlink()
    build_report(out, require_marker=True)
    assert (out / "report.md").read_text() == report
    # the same run again, over the first (snapshots/ carries its marker): the same bytes
    before = {r["file"]: (out / SNAPSHOTS_DIR / r["file"]).read_bytes() for r in rows}
    _replay(out, 40.0, overwrite=True)
    assert {f: (out / SNAPSHOTS_DIR / f).read_bytes() for f in before} == before


def test_closed_loop_scenario_writes_snapshots(tmp_path: Path) -> None:
    from gndreplay.sim import simulate_scenario

    out = simulate_scenario("gnd_fig3_passage_closes", out_dir=tmp_path / "fig3", time_limit_s=15.0,
                            figures=False, snapshots=SnapshotOptions()).out_dir
    rows = _check_snapshots(out)
    # the passage closes at 12-13.5 s: the reflexive loop turns the robot round to look before it backs out
    assert any(r["kind"] == "reflexive" and 12.0 < float(r["elapsed_s"]) < 15.0 for r in rows)
    assert not (out / "report.md").exists()  # no figures: snapshots only


def test_snapshot_index_reading(tmp_path: Path) -> None:
    assert read_snapshot_index(tmp_path) is None and timeline_section(None) == []
    (tmp_path / SNAPSHOTS_DIR).mkdir()
    index = tmp_path / SNAPSHOTS_DIR / INDEX_FILE
    index.write_text(INDEX_HEADER)
    assert read_snapshot_index(tmp_path) == []
    assert "No key event" in "\n".join(timeline_section([]))
    index.write_text(INDEX_HEADER + "1.0,1.5,planner,PLANNER_NO_PATH|GOAL_IN_OBSTACLE (mND),001_a.png\n")
    entry = SnapshotEntry("1.0", 1.5, "planner", "PLANNER_NO_PATH|GOAL_IN_OBSTACLE (mND)", "001_a.png")
    assert read_snapshot_index(tmp_path) == [entry]
    row = "| 1.50 | planner | PLANNER_NO_PATH \\| GOAL_IN_OBSTACLE (mND) | [001_a.png](snapshots/001_a.png) |"
    assert row in timeline_section([entry])
    for bad in ("1.0,x,mode,r,001.png\n", "1.0,1,mode,r,../report.md\n", "1.0,1,mode,001.png\n"):
        index.write_text(INDEX_HEADER + bad)
        with pytest.raises(RunDirError, match=r"index\.csv line 2"):
            read_snapshot_index(tmp_path)


# ---- the animation ----------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def mcap_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A short replay of the sample log with results.mcap."""
    from gndreplay.replay import RunOptions, run_log
    from gndreplay.report import default_sinks

    out = tmp_path_factory.mktemp("anim") / "office"
    run_log(SAMPLE_LOG, Config(), out, options=RunOptions(until_s=12.0), sinks=default_sinks(figures=False,
                                                                                            mcap=True))
    return out


def _tick_times(run_dir: Path) -> np.ndarray:
    with open(run_dir / "commands.csv") as f:
        t = np.array([float(r["t"]) for r in csv.DictReader(f)])
    return t - t[0]


def test_animation_has_one_frame_per_tick_of_the_window(mcap_run: Path) -> None:
    seen: list[tuple[int, int]] = []
    out = animate_run(mcap_run, mcap_run / "animation.gif", t_from=2.0, t_to=6.0,
                      on_progress=lambda k, n: seen.append((k, n)))
    t = _tick_times(mcap_run)
    n = int(np.count_nonzero((t >= 2.0 - 1e-6) & (t <= 6.0 + 1e-6)))
    assert n == 21  # the sample log scans at 5 Hz
    with Image.open(out) as im:
        assert im.format == "GIF" and im.n_frames == n and im.size == (504, 576)
        assert im.info["duration"] == 200 and im.info["loop"] == 0  # real time
    assert seen[-1] == (n, n) and len(seen) == n
    assert "animation.gif" in (mcap_run / RUN_MARKER).read_text().split("\n")
    again = animate_run(mcap_run, mcap_run / "again.gif", t_from=2.0, t_to=6.0)
    assert again.read_bytes() == out.read_bytes()  # deterministic
    # more ticks than max_frames: every k-th tick, faster playback of the same time
    out = animate_run(mcap_run, mcap_run / "animation.gif", t_from=2.0, t_to=6.0, max_frames=5, fps=2.0)
    with Image.open(out) as im:
        assert im.n_frames == 5 and im.info["duration"] == 500


def test_animation_errors_are_one_line(mcap_run: Path, tmp_path: Path) -> None:
    from matplotlib.animation import FFMpegWriter

    with pytest.raises(OutputError, match=r"expected \.gif or \.mp4"):
        animate_run(mcap_run, tmp_path / "a.avi")
    if not FFMpegWriter.isAvailable():
        with pytest.raises(OutputError, match="ffmpeg"):
            animate_run(mcap_run, tmp_path / "a.mp4")
    with pytest.raises(ConfigError, match="--to 1 must be after --from 2"):
        animate_run(mcap_run, tmp_path / "a.gif", t_from=2.0, t_to=1.0)
    with pytest.raises(OutputError, match="no tick from 100 s"):
        animate_run(mcap_run, tmp_path / "a.gif", t_from=100.0)
    (tmp_path / "mine.gif").write_bytes(b"not gndreplay's")
    with pytest.raises(OutputError, match="not overwriting"):
        animate_run(mcap_run, tmp_path / "mine.gif")
    bare = tmp_path / "bare"
    bare.mkdir()
    (bare / "config.toml").write_text((mcap_run / "config.toml").read_text())
    with pytest.raises(RunDirError, match=r"results\.mcap: missing.*run with --mcap"):
        animate_run(bare, bare / "a.gif")
    assert not list(tmp_path.glob("*.gif.*"))  # no temporary file left


def test_laserscan_points_are_placed_with_the_mounting() -> None:
    msg = SimpleNamespace(ranges=[1.0, float("inf"), 0.01, 2.0], angle_min=0.0, angle_increment=math.pi / 2,
                          range_min=0.05, range_max=30.0)
    pts = _scan_points(msg, (0.5, 0.0, math.pi / 2))
    np.testing.assert_allclose(pts, [[0.5, 1.0], [2.5, 0.0]], atol=1e-12)  # beam 3 at -90 deg, turned


def test_grid_cells_are_read_back_from_the_occupancy_grid() -> None:
    from gndreplay.report.animate import _grid_cells

    cells = np.zeros((4, 4), dtype=np.uint8)
    cells[1, 2] = OCCUPIED
    cells[0, :] = 1
    data = np.array([-1, 0, 100], dtype=np.int8)[cells].ravel()
    info = SimpleNamespace(width=4, height=4, resolution=0.05,
                           origin=SimpleNamespace(position=SimpleNamespace(x=-0.1, y=0.2)))
    back, origin, cell_m = _grid_cells(SimpleNamespace(info=info, data=data))
    np.testing.assert_array_equal(back, cells)
    assert origin == (-0.1, 0.2) and cell_m == 0.05


def test_a_cleared_figure_draws_each_decision_as_a_fresh_one_does() -> None:
    import io

    from gndreplay.report.decision import clear_decision

    cfg = preset("xr4000")
    grid = _grid_with_wall()
    tick = Tick(0, 0, Scan(0, np.array([2.0, np.inf]), np.array([0.0, 0.1]), 8.0), Pose2D(1.0, 2.0, 0.5))
    views = [decision_view(decision_input(tick, _r(region=(170, 10)), grid, t0_ns=0), cfg, headline="a"),
             decision_view(decision_input(tick, _r(v=0.0, flags=Flag.EMERGENCY_STOP), grid, t0_ns=0), cfg)]

    def png(fig: object) -> bytes:
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=50)  # type: ignore[attr-defined]
        return buf.getvalue()

    fresh = []
    for view in views:
        fig, ax = decision_figure()
        draw_decision(ax, view)
        fresh.append(png(fig))
    assert fresh[0] != fresh[1]
    fig, ax = decision_figure()
    reused = []
    for view in (*views, views[0]):
        clear_decision(ax)
        draw_decision(ax, view)
        reused.append(png(fig))
    assert reused == [*fresh, fresh[0]]
