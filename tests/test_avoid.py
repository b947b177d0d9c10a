"""The route a trap was detected on, avoided (``planner.AvoidMarks``, ``RouteParams.avoid_cost``): the
marks follow the course the reactor was given, widen it, move with the grid and expire; NF1 weighs them,
so a short way through a gap the robot could not pass gives way to the way round, while a passage that is
the only way stays on the route; the stack marks on a tick whose supervisor detected a trap; the warm-up
compiles the weighted wave."""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import numpy as np
import pytest
from numba.core.registry import CPUDispatcher
from numpy.typing import NDArray

from gndreplay.config import CliOverrides, configure
from gndreplay.pipeline.model import FREE, OCCUPIED
from gndreplay.pipeline.nf1 import Nf1Params, Nf1Planner
from gndreplay.pipeline.planner import AvoidMarks, PlanResult, RouteParams
from gndreplay.pipeline.stack import NavigationStack
from gndreplay.replay import warm_up_all
from gndreplay.sim import load_scenario, simulate_scenario
from gndreplay.sim.fields import generate_fields

CELL_M = 0.05
INFLATE_M = 0.15
ROUTE = RouteParams()
GOAL = (30.5, 150.5)
START = (30, 20)


def gap_world(way_round: bool = True) -> NDArray[np.uint8]:
    """120 x 170 cells: a wall 1 m thick across the robot's way (columns 78 to 97) with a passage on the
    robot-goal line; with ``way_round`` the wall ends at row 100, leaving a way round below it (about
    3.5 m longer)."""
    cells = np.full((120, 170), FREE, dtype=np.uint8)
    cells[:, 78:98] = OCCUPIED
    cells[24:37, 78:98] = FREE  # the passage: 13 cells wide, free for the 3-cell C-space disc
    if way_round:
        cells[100:, 78:98] = FREE
    return cells


def through_gap(res: PlanResult) -> bool:
    rows = res.path_cells[(res.path_cells[:, 1] >= 78) & (res.path_cells[:, 1] <= 97), 0]
    return bool(rows.size) and bool(rows.max() < 40)


def planner(route: RouteParams = ROUTE) -> Nf1Planner:
    return Nf1Planner(Nf1Params(), cell_m=CELL_M, inflate_m=INFLATE_M, unknown_is_free=True, route=route)


def marks_of(res: PlanResult, route: RouteParams = ROUTE, offset: tuple[int, int] = (0, 0)) -> AvoidMarks:
    marks = AvoidMarks(route, cell_m=CELL_M, radius_m=0.2)
    marks.mark(res, offset, t_ns=0)
    return marks


def test_a_marked_gap_gives_way_to_the_way_round() -> None:
    cells = gap_world()
    p = planner()
    first = p.plan(cells, START, GOAL, offset_rc=(0, 0))
    assert first.ok and through_gap(first)
    # the trap: the robot stands before the gap, on the route
    at_gap = (30, 70)
    before = p.plan(cells, at_gap, GOAL, offset_rc=(0, 0))
    avoid = marks_of(before, RouteParams(avoid_m=2.0)).mask(cells.shape, (0, 0), t_ns=1)
    assert avoid is not None and avoid[30, 80]  # the gap's cells are marked
    after = p.plan(cells, at_gap, GOAL, offset_rc=(0, 0), avoid=avoid)
    assert after.ok and not through_gap(after)
    assert after.length_m > before.length_m + 3.0  # the way round, not a line skirting the mark


def test_a_passage_that_is_the_only_way_stays_on_the_route() -> None:
    cells = gap_world(way_round=False)
    p = planner()
    before = p.plan(cells, (30, 70), GOAL, offset_rc=(0, 0))
    avoid = marks_of(before).mask(cells.shape, (0, 0), t_ns=1)
    after = p.plan(cells, (30, 70), GOAL, offset_rc=(0, 0), avoid=avoid)
    assert after.ok and through_gap(after)
    assert after.cost_m > before.cost_m  # its steps through the mark cost more


def test_avoid_cost_one_plans_as_the_papers_nf1() -> None:
    cells = gap_world()
    pure = RouteParams(avoid_cost=1.0)
    before = planner(pure).plan(cells, (30, 70), GOAL, offset_rc=(0, 0))
    avoid = marks_of(before).mask(cells.shape, (0, 0), t_ns=1)
    after = planner(pure).plan(cells, (30, 70), GOAL, offset_rc=(0, 0), avoid=avoid)
    assert np.array_equal(after.path_cells, before.path_cells) and after.cost_m == before.cost_m


def test_marks_cover_the_course_ahead_widened_move_with_the_grid_and_expire() -> None:
    route = RouteParams(avoid_m=1.0, avoid_s=5.0)
    res = planner().plan(gap_world(), START, GOAL, offset_rc=(0, 0))
    marks = AvoidMarks(route, cell_m=CELL_M, radius_m=0.1)
    marks.mark(res, (100, -50), t_ns=10**9)
    shape = (120, 170)
    here = marks.mask(shape, (100, -50), t_ns=2 * 10**9)
    assert here is not None
    rows, cols = np.nonzero(here)
    # 1 m of course (20 cells) ahead of the robot, widened by 2 cells, nothing behind it
    assert cols.min() == START[1] - 2 and cols.max() == START[1] + 20 + 2
    assert rows.min() == START[0] - 2 and rows.max() == START[0] + 2
    # the grid re-centred 7 rows up and 3 columns left: the same world cells
    moved = marks.mask(shape, (107, -53), t_ns=2 * 10**9)
    assert moved is not None and np.array_equal(moved[:-7, 3:], here[7:, :-3])
    assert marks.mask(shape, (100, -50), t_ns=6 * 10**9 + 1) is None  # held avoid_s
    assert not marks


def test_bad_avoid_settings() -> None:
    for bad in ({"avoid_cost": 0.5}, {"avoid_m": 0.0}, {"avoid_s": -1.0}):
        with pytest.raises(ValueError, match=next(iter(bad))):
            RouteParams(**bad)  # type: ignore[arg-type]


def _signatures() -> dict[str, int]:
    out: dict[str, int] = {}
    for name, module in list(sys.modules.items()):
        if name.startswith("gndreplay") and module is not None:
            for attr, value in vars(module).items():
                if isinstance(value, CPUDispatcher):
                    out[f"{name}.{attr}"] = len(value.signatures)
    return out


def test_the_warm_up_compiled_the_weighted_wave_of_a_route_to_avoid() -> None:
    cfg = configure(preset_name="compact", overrides=CliOverrides())
    warm_up_all(cfg)
    before = _signatures()
    stack = NavigationStack(cfg.stack_params())
    cells = stack.grid.cells
    cells[:] = FREE
    r0, c0 = cells.shape[0] // 2 - 30, cells.shape[1] // 2 - 70
    cells[r0 : r0 + 120, c0 : c0 + 170] = gap_world()
    start, goal = (r0 + 30, c0 + 70), (r0 + GOAL[0], c0 + GOAL[1])
    marks = AvoidMarks(cfg.stack_params().planner, cell_m=CELL_M, radius_m=0.2)
    for beyond in (False, True):  # a goal in the grid and one beyond it (NF1's frontier goal)
        g = (goal[0], goal[1] + cells.shape[1]) if beyond else goal
        planned = planner().plan(cells, start, g, offset_rc=(0, 0))
        marks.mark(planned, (0, 0), t_ns=0)
        avoid = marks.mask(cells.shape, (0, 0), t_ns=1)
        assert avoid is not None
        nf1 = Nf1Planner(Nf1Params(), cell_m=CELL_M, inflate_m=0.265, unknown_is_free=True)
        assert nf1.plan(cells, start, g, offset_rc=(0, 0), avoid=avoid).ok
    grown = {k: (before.get(k, 0), n) for k, n in _signatures().items() if n > before.get(k, 0)}
    assert grown == {}, f"compiled after the warm-up: {grown}"


def test_a_robot_wedged_in_a_gap_takes_the_way_round(tmp_path: Path) -> None:
    """The class, closed loop: generated field 0 (field seed 0), the compact preset at 0.5 m/s, seed 0.
    The planner's way between two clusters is a gap the 0.43 m wide rectangle does not negotiate: without
    the marks it is still wedged there at 60 s (trap escapes and creeping); with them the route leaves the
    gap after a trap and the robot reaches the goal."""
    cfg = configure(preset_name="compact", overrides=CliOverrides(sets=("robot.vmax_mps=0.5",)))
    _, files = generate_fields(tmp_path / "fields", count=1, seed=0, robot=cfg.robot, preset_name="compact")
    spec = load_scenario(files[0])
    on = simulate_scenario(spec, out_dir=tmp_path / "on", cfg=cfg, seed=0, figures=False, time_limit_s=60.0)
    off_cfg = configure(preset_name="compact",
                        overrides=CliOverrides(sets=("robot.vmax_mps=0.5", "planner.avoid_cost=1.0")))
    off = simulate_scenario(spec, out_dir=tmp_path / "off", cfg=off_cfg, seed=0, figures=False,
                            time_limit_s=60.0)
    assert off.outcome == "timeout"
    assert on.outcome == "success"
    with open(tmp_path / "on" / "commands.csv", newline="") as f:
        assert any("TRAP_DETECTED" in row["flags"] for row in csv.DictReader(f))
