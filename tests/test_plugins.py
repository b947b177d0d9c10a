"""Planners and local navigation strategies are plug-ins: an entry in ``planners.PLANNERS`` or
``local.STRATEGIES`` is all the stack and the configuration need to run one."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import pytest
from numpy.typing import ArrayLike, NDArray

from gndreplay.config import PRESETS, apply_overrides
from gndreplay.errors import ConfigError
from gndreplay.geometry import compose
from gndreplay.pipeline import local, planners
from gndreplay.pipeline.local import LocalCommand, LocalParams, NdCall
from gndreplay.pipeline.planner import PlanResult
from gndreplay.pipeline.planners import PlannerGeometry, PlannerSpec
from gndreplay.pipeline.stack import NavigationStack, StackParams, TickResult
from gndreplay.robot import RobotConfig
from gndreplay.sim.world import cast_rays, polygon
from gndreplay.types import BUDGET_FLAGS, Flag, Mode, Pose2D, Scan

ROOM = polygon([(-6, -6), (12, -6), (12, 6), (-6, 6)])
BEAMS = np.linspace(-math.pi / 2, math.pi / 2, 361)
GOAL = (4.0, 0.0)
MARK_NODES, MARK_LENGTH_M, MARK_WIDTH_M = 4242, 1.234, 0.77  # values no real planner reports here


class StubPlanner:
    """Always a straight path from the robot cell to the goal cell, heading to the robot's left (``ok``);
    or never a path (not ``ok``). Records its calls."""

    no_path_is_no_border = False

    def __init__(self, geometry: PlannerGeometry, ok: bool, fallback: bool) -> None:
        self.geometry, self.ok, self.fallback = geometry, ok, fallback
        self.calls: list[tuple[int, int]] = []

    def plan(self, grid_cells: NDArray[np.uint8], start_rc: tuple[int, int], goal_rc_float: ArrayLike
             ) -> PlanResult:
        self.calls.append(start_rc)
        goal = np.floor(np.asarray(goal_rc_float, dtype=np.float64)).astype(np.int32)
        cells = np.array([start_rc, goal], dtype=np.int32)
        if not self.ok:
            return PlanResult(False, Flag.PLANNER_NO_PATH, (int(goal[0]), int(goal[1])), False,
                              np.zeros((0, 2), np.int32), 0, np.zeros((0, 2)), math.nan, math.nan, math.nan,
                              nodes_expanded=MARK_NODES)
        return PlanResult(True, Flag.NONE, (int(goal[0]), int(goal[1])), False, cells, 0,
                          cells.astype(np.float64), math.pi / 2, MARK_LENGTH_M, MARK_LENGTH_M,
                          nodes_expanded=MARK_NODES, width_m=MARK_WIDTH_M, fallback=self.fallback)


def register_stub(monkeypatch: pytest.MonkeyPatch, *, ok: bool = True,
                  fallback: bool = False) -> list[StubPlanner]:
    """Register planner kind "stub" (its settings: NF1's table, unused); returns the planners it builds."""
    built: list[StubPlanner] = []

    def build(settings: Any, geometry: PlannerGeometry) -> StubPlanner:
        built.append(StubPlanner(geometry, ok, fallback))
        return built[-1]

    monkeypatch.setitem(planners.PLANNERS, "stub", PlannerSpec("nf1", build))
    return built


def ticks(params: StackParams, n: int = 3) -> tuple[NavigationStack, list[TickResult]]:
    """``n`` ticks of a robot standing at the origin of an open room, the goal 4 m ahead."""
    robot = params.robot
    stack = NavigationStack(params)
    pose = Pose2D(0.0, 0.0, 0.0)
    sensor = Pose2D(robot.laser_x_m, robot.laser_y_m, robot.laser_theta_rad)
    laser = compose(pose.as_array(), sensor.as_array())
    out = []
    for i in range(n):
        t = 1_000_000_000 + i * 200_000_000
        ranges = cast_rays(laser[:2], BEAMS + laser[2], ROOM, max_range_m=8.0)
        scan = Scan(t_ns=t, ranges_m=ranges, angles_rad=BEAMS, max_range_m=8.0, sensor_pose=sensor)
        out.append(stack.step(scan, pose, GOAL, odom=pose))
    return stack, out


def stub_params(name: str) -> StackParams:
    """The preset with ``[planner] kind = "stub"``, through the configuration's own validation."""
    return apply_overrides(PRESETS[name], {"planner": {"kind": "stub"}}).stack_params()


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_a_registered_planner_drives_the_tick(monkeypatch: pytest.MonkeyPatch, name: str) -> None:
    built = register_stub(monkeypatch)
    params = stub_params(name)
    _, results = ticks(params)
    (stub,) = built
    assert len(stub.calls) == len(results)
    g = stub.geometry
    assert (g.cell_m, g.inner_radius_m, g.route.lookahead_m) == (
        params.grid.cell_m, params.robot.inner_radius_m, params.planner.lookahead_m)
    for r in results:
        assert r.mode is Mode.MPND and r.flags & ~BUDGET_FLAGS == Flag.NONE  # wall clock: not behaviour
        assert (r.planner_nodes, r.planner_length_m, r.tunnel_width_m) == (MARK_NODES, MARK_LENGTH_M,
                                                                          MARK_WIDTH_M)
        assert r.path_xy.shape == (2, 2) and np.allclose(r.path_xy[-1], GOAL, atol=params.grid.cell_m)
        # the reactor's target lies along the stub's course (left), not towards the goal (ahead)
        assert r.direction_rad > 1.0


def test_a_registered_planner_without_a_path_or_with_a_fallback(monkeypatch: pytest.MonkeyPatch) -> None:
    register_stub(monkeypatch, ok=False)
    r = ticks(stub_params("wheelchair"))[1][-1]
    assert r.mode is Mode.MND and r.flags & Flag.PLANNER_NO_PATH and r.planner_nodes == MARK_NODES
    assert r.path_xy.shape == (0, 2) and math.isnan(r.tunnel_width_m)
    register_stub(monkeypatch, fallback=True)
    r = ticks(stub_params("wheelchair"))[1][-1]
    assert r.mode is Mode.MPND and r.flags & ~BUDGET_FLAGS == Flag.PLANNER_FALLBACK


def test_an_unknown_planner_kind_is_a_one_line_config_error() -> None:
    with pytest.raises(ConfigError, match=r"^\[planner\] kind: expected one of nf1, tunnel, got 'stub'$"):
        apply_overrides(PRESETS["wheelchair"], {"planner": {"kind": "stub"}})


def test_every_planner_has_its_table() -> None:
    fields = {f.name: f.type for f in dataclasses.fields(planners.PlannerParams)}
    assert all(spec.section in fields for spec in planners.PLANNERS.values())


STUB_COMMAND = LocalCommand(0.05, 0.0, 0.02, 0.3, side=1)


def test_a_registered_local_strategy_drives_the_tick(monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[tuple[NDArray[np.float64], int]] = []

    def stub(obstacles_xy: NDArray[np.float64], target_xy: NDArray[np.float64], robot: RobotConfig,
             params: LocalParams, *, side_hint: int, nd: NdCall) -> LocalCommand:
        calls.append((target_xy.copy(), side_hint))
        return STUB_COMMAND

    monkeypatch.setitem(local.STRATEGIES, "stub", stub)
    navigation = {"mode": "local", "local": {"strategy": "stub"}}
    cfg = apply_overrides(PRESETS["wheelchair"], {"navigation": navigation})
    _, results = ticks(cfg.stack_params())
    assert len(calls) == len(results)
    assert np.allclose(calls[0][0], GOAL)  # towards the goal, in the robot frame
    assert [h for _, h in calls] == [0, 1, 1]  # told the side it kept the tick before
    for r in results:
        assert r.active_mode == "local" and r.mode is Mode.LOCAL
        c = r.command
        assert (c.v_mps, c.w_radps, r.direction_rad) == (STUB_COMMAND.v_mps, STUB_COMMAND.w_radps, 0.3)


def test_an_unknown_local_strategy_is_a_config_error() -> None:
    with pytest.raises(ConfigError, match=r"\[navigation\.local\] strategy: expected one of nd, "):
        apply_overrides(PRESETS["wheelchair"], {"navigation": {"local": {"strategy": "stub"}}})
    assert tuple(local.STRATEGIES) == local.LOCAL_STRATEGIES
