"""The navigation stack on simulated scenes with known answers: modes, flags, reflexes, no NaN."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from gndreplay.config import PRESETS, Config
from gndreplay.geometry import compose
from gndreplay.pipeline.nd import Situation
from gndreplay.pipeline.selector import _intention_changed, intention_xy
from gndreplay.pipeline.stack import MODULES, NavigationStack, StackParams, TickResult, make_planner
from gndreplay.sim.world import box, cast_rays, polygon, regular_polygon, wall
from gndreplay.types import Command, Flag, Mode, Pose2D, Scan

FRONT = np.linspace(-math.pi / 2, math.pi / 2, 361)  # a SICK-like 180 deg laser
AROUND = np.linspace(-math.pi, math.pi, 720, endpoint=False)  # 360 deg: the robot sees it is enclosed


def scan_of(
    segments: np.ndarray, pose: Pose2D, sensor: Pose2D, t_ns: int, beams: np.ndarray, max_range: float = 8.0
) -> Scan:
    laser = compose(pose.as_array(), sensor.as_array())
    ranges = cast_rays(laser[:2], beams + laser[2], segments, max_range_m=max_range)
    return Scan(t_ns=t_ns, ranges_m=ranges, angles_rad=beams, max_range_m=max_range, sensor_pose=sensor)


def run(
    cfg: Config,
    segments: np.ndarray,
    pose: Pose2D,
    goal: tuple[float, float],
    n: int = 3,
    dt_s: float = 0.2,
    beams: np.ndarray = FRONT,
    params: StackParams | None = None,
) -> list[TickResult]:
    """n ticks of a robot standing at ``pose`` (the grid fills up, the reactor sees the model)."""
    stack = NavigationStack(params or cfg.stack_params())
    sensor = Pose2D(cfg.robot.laser_x_m, cfg.robot.laser_y_m, cfg.robot.laser_theta_rad)
    out = []
    for i in range(n):
        t = 1_000_000_000 + int(i * dt_s * 1e9)
        out.append(stack.step(scan_of(segments, pose, sensor, t, beams), pose, goal))
    return out


ROOM = np.vstack([polygon([(-6, -6), (12, -6), (12, 6), (-6, 6)])])
PRESET_NAMES = sorted(PRESETS)


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_open_room_goal_ahead_drives_straight(name: str) -> None:
    cfg = PRESETS[name]
    r = run(cfg, ROOM, Pose2D(0, 0, 0), (4.0, 0.0))[-1]
    assert r.mode is Mode.MPND
    assert r.situation is Situation.HSGR
    assert r.command.v_mps == pytest.approx(cfg.robot.vmax_mps, rel=1e-6)
    assert abs(r.command.w_radps) < 1e-6
    assert r.flags == Flag.NONE
    assert set(r.timings_ms) == set(MODULES)
    assert r.path_xy.shape[1] == 2 and np.allclose(r.path_xy[-1], (4.0, 0.0), atol=0.06)


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_goal_inside_an_obstacle_switches_to_mnd(name: str) -> None:
    cfg = PRESETS[name]
    world = np.vstack([ROOM, box(3.0, 0.0, 1.0, 1.0)])
    # the goal on the box face the laser sees (its far side is unknown, hence free, to the planner)
    r = run(cfg, world, Pose2D(0, 0, 0), (2.5, 0.0))[-1]
    assert r.flags & Flag.GOAL_IN_OBSTACLE
    assert r.mode is Mode.MND
    assert r.path_xy.shape == (0, 2)


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_enclosed_robot_stops_and_rotates(name: str) -> None:
    cfg = PRESETS[name]
    ring = regular_polygon(0.0, 0.0, cfg.robot.outer_radius_m + 0.15, sides=24)
    results = run(cfg, np.vstack([ROOM, ring]), Pose2D(0, 0, 0), (4.0, 0.0), n=4, beams=AROUND)
    for r in results:
        assert r.flags & Flag.PLANNER_NO_PATH
        assert r.flags & Flag.REACTOR_NO_REGION
        assert r.mode is Mode.ROTATE  # GND: no free walking area -> stop and rotate
        assert r.command.v_mps == 0.0 and r.command.vy_mps == 0.0
        assert r.command.w_radps == pytest.approx(cfg.supervisor.rotate_w_frac * cfg.robot.wmax_radps)


def test_half_seen_enclosure_plans_through_the_unknown_side() -> None:
    """With a 180 deg laser the back of the ring is UNKNOWN, i.e. free to the planner (GND's choice)."""
    cfg = PRESETS["wheelchair"]
    ring = regular_polygon(0.0, 0.0, cfg.robot.outer_radius_m + 0.15, sides=24)
    r = run(cfg, np.vstack([ROOM, ring]), Pose2D(0, 0, 0), (4.0, 0.0))[-1]
    assert not r.flags & Flag.PLANNER_NO_PATH
    assert r.command.v_mps == pytest.approx(0.0, abs=0.05)


def test_wall_close_ahead_makes_nd_turn_in_place() -> None:
    cfg = PRESETS["wheelchair"]
    # a wall 0.15 m in front of the wheelchair's front edge, with the goal straight through it
    world = np.vstack([ROOM, wall(0.95, -3.0, 0.95, 3.0)])
    r = run(cfg, world, Pose2D(0, 0, 0), (4.0, 0.0))[-1]
    assert r.situation in (Situation.LS1, Situation.LSG, Situation.LS2)
    assert r.command.v_mps == pytest.approx(0.0, abs=1e-6) and r.command.w_radps != 0.0
    assert not r.flags & Flag.EMERGENCY_STOP  # turning in place sweeps nothing of the wall


def test_reflexive_brake_overrides_a_colliding_reactor_command(monkeypatch: pytest.MonkeyPatch) -> None:
    """If the reactor commanded full speed into a close wall, the reflexive loop brakes on the raw scan."""
    import gndreplay.pipeline.stack as stack_module

    cfg = PRESETS["wheelchair"]
    real = stack_module.nd_step

    def reckless(*args: object, **kwargs: object):  # type: ignore[no-untyped-def]
        import dataclasses

        return dataclasses.replace(real(*args, **kwargs), v_mps=cfg.robot.vmax_mps, w_radps=0.0)

    monkeypatch.setattr(stack_module, "nd_step", reckless)
    # a wall 0.04 m beyond the chair's front edge (0.8 m): no slower arc or turn is safe -> stop
    world = np.vstack([ROOM, wall(0.84, -3.0, 0.84, 3.0)])
    r = run(cfg, world, Pose2D(0, 0, 0), (4.0, 0.0))[-1]
    assert r.mode is Mode.EMERGENCY and r.flags & Flag.EMERGENCY_STOP
    assert (r.command.v_mps, r.command.w_radps) == (0.0, 0.0)
    # 0.15 m beyond it, half speed still stops in time: the command is slowed, not replaced by a stop
    world = np.vstack([ROOM, wall(0.95, -3.0, 0.95, 3.0)])
    r = run(cfg, world, Pose2D(0, 0, 0), (4.0, 0.0))[-1]
    assert r.mode is Mode.SAFE_SLOW and r.command.v_mps == pytest.approx(cfg.robot.vmax_mps / 2)


def test_stale_scan_stops_the_robot() -> None:
    cfg = PRESETS["wheelchair"]
    results = run(cfg, ROOM, Pose2D(0, 0, 0), (4.0, 0.0), n=2, dt_s=cfg.supervisor.stale_scan_s + 0.5)
    assert results[0].mode is Mode.MPND
    assert results[1].mode is Mode.STALE and results[1].flags & Flag.STALE_SCAN
    assert (results[1].command.v_mps, results[1].command.w_radps) == (0.0, 0.0)


def test_goal_reached_stops() -> None:
    r = run(PRESETS["wheelchair"], ROOM, Pose2D(1.0, 1.0, 0.3), (1.1, 1.0))[-1]
    assert r.mode is Mode.GOAL and r.flags & Flag.GOAL_REACHED
    assert (r.command.v_mps, r.command.vy_mps, r.command.w_radps) == (0.0, 0.0, 0.0)


def test_goal_behind_turns_in_place_differential() -> None:
    r = run(PRESETS["wheelchair"], ROOM, Pose2D(0, 0, 0), (-4.0, 0.5))[-1]
    assert r.command.v_mps == pytest.approx(0.0, abs=1e-9)
    assert r.command.w_radps > 0.0


@pytest.mark.parametrize("seed", range(6))
def test_random_clutter_never_produces_nan(seed: int) -> None:
    rng = np.random.default_rng(seed)
    boxes = [box(*rng.uniform(-4, 8, 2), *rng.uniform(0.2, 1.5, 2)) for _ in range(25)]
    cfg = PRESETS["wheelchair" if seed % 2 else "xr4000"]
    goal = tuple(rng.uniform(-10, 10, 2))
    for r in run(cfg, np.vstack([ROOM, *boxes]), Pose2D(0, 0, rng.uniform(-3, 3)), goal, n=3):
        assert all(math.isfinite(x) for x in (r.command.v_mps, r.command.vy_mps, r.command.w_radps))
        assert abs(r.command.v_mps) <= cfg.robot.vmax_mps + 1e-9
        assert abs(r.command.w_radps) <= cfg.robot.wmax_radps + 1e-9


def test_enforced_planner_budget_falls_back_to_mnd() -> None:
    import dataclasses

    base = PRESETS["wheelchair"]
    sup = dataclasses.replace(base.supervisor, enforce_budgets=True, budget_planner_s=0.0)
    r = run(dataclasses.replace(base, supervisor=sup), ROOM, Pose2D(0, 0, 0), (4.0, 1.0))[-1]
    assert r.flags & Flag.PLANNER_OVER_BUDGET and r.flags & Flag.PLANNER_TIMEOUT
    assert r.mode is Mode.MND


def _numba_signatures() -> dict[str, int]:
    from gndreplay.pipeline import cspace, model, nd, nf1

    return {
        f"{mod.__name__}.{name}": len(obj.signatures)
        for mod in (model, cspace, nf1, nd)
        for name, obj in vars(mod).items()
        if hasattr(obj, "signatures")
    }


def test_warm_up_compiles_what_real_ticks_need() -> None:
    """After warm_up, ticks from a real reader (read-only shared beam angles) compile nothing new, so no
    JIT time is ever reported as model/planner/reactor time."""
    from pathlib import Path

    from gndreplay.io import read_ticks
    from gndreplay.pipeline.stack import warm_up

    cfg = PRESETS["wheelchair"]
    warm_up(cfg.stack_params())
    before = _numba_signatures()
    stack = NavigationStack(cfg.stack_params())
    sample = Path(__file__).resolve().parents[1] / "sample_logs" / "office.clf.bz2"
    for tick, _ in zip(read_ticks(sample), range(5), strict=False):
        stack.step(tick.scan, tick.odom, (tick.odom.x + 3.0, tick.odom.y))
    assert _numba_signatures() == before


def tunnel_params(cfg: Config) -> StackParams:
    import dataclasses

    params = cfg.stack_params()
    return dataclasses.replace(params, planner=dataclasses.replace(params.planner, kind="tunnel"))


def test_make_planner_builds_the_kind_named() -> None:
    import dataclasses

    from gndreplay.pipeline.nf1 import Nf1Planner
    from gndreplay.pipeline.tunnel import TunnelPlanner

    base = PRESETS["wheelchair"].stack_params()
    assert isinstance(make_planner(base), Nf1Planner)  # the default
    assert isinstance(make_planner(tunnel_params(PRESETS["wheelchair"])), TunnelPlanner)
    with pytest.raises(ValueError, match="kind: expected one of nf1, tunnel, got 'rrt'"):
        dataclasses.replace(base.planner, kind="rrt")


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_planner_statistics_per_tick(name: str) -> None:
    cfg = PRESETS[name]
    nf1 = run(cfg, ROOM, Pose2D(0, 0, 0), (4.0, 0.0))[-1]
    tunnel = run(cfg, ROOM, Pose2D(0, 0, 0), (4.0, 0.0), params=tunnel_params(cfg))[-1]
    assert nf1.planner_nodes > 4.0 / cfg.grid.cell_m  # the wave labelled at least the cells on the way
    assert math.isnan(nf1.tunnel_width_m)
    assert tunnel.planner_nodes == 1  # the goal is in sight of the robot's own node
    assert tunnel.tunnel_width_m == pytest.approx(2 * (cfg.robot.inner_radius_m + 0.025))
    for r in (nf1, tunnel):
        assert r.planner_length_m == pytest.approx(4.0, abs=0.1)
        assert r.mode is Mode.MPND and r.situation is Situation.HSGR
        assert np.allclose(r.path_xy[-1], (4.0, 0.0), atol=0.06)
    assert tunnel.path_xy.shape == (2, 2)  # one straight tunnel
    assert (tunnel.command.v_mps, tunnel.command.w_radps) == pytest.approx(
        (nf1.command.v_mps, nf1.command.w_radps), abs=1e-6)


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_tunnel_planner_enclosed_goal_goes_to_mnd(name: str) -> None:
    """The goal inside a closed 2 m box the robot has seen from every side: no tunnel reaches it, the
    supervisor runs mND (the reactor still has free space around the robot)."""
    cfg = PRESETS[name]
    world = np.vstack([ROOM, box(4.0, 0.0, 2.0, 2.0)])
    stack = NavigationStack(tunnel_params(cfg))
    sensor = Pose2D(cfg.robot.laser_x_m, cfg.robot.laser_y_m, cfg.robot.laser_theta_rad)
    results = []
    for i, a in enumerate(np.linspace(-math.pi, math.pi, 9)):  # look at the box from all around it
        pose = Pose2D(4.0 + 3.0 * math.cos(a), 3.0 * math.sin(a), a + math.pi / 2)
        t = 1_000_000_000 + i * 100_000_000
        results.append(stack.step(scan_of(world, pose, sensor, t, AROUND), pose, (4.0, 0.0)))
    r = results[-1]
    assert r.flags & Flag.PLANNER_NO_PATH and not r.flags & Flag.GOAL_IN_OBSTACLE
    assert r.mode is Mode.MND
    assert r.path_xy.shape == (0, 2) and math.isnan(r.planner_length_m)
    assert r.planner_nodes > 1


def test_tunnel_course_steers_the_reactor_out_of_a_u() -> None:
    """Fig. 3b in the stack: inside a U whose bottom faces the goal, the tunnel's course makes mpND head
    back out of the U's mouth."""
    cfg = PRESETS["xr4000"]
    u = np.vstack([wall(1.2, -1.5, 1.2, 1.5), wall(-1.5, -1.5, 1.2, -1.5), wall(-1.5, 1.5, 1.2, 1.5)])
    world = np.vstack([ROOM, u])
    r = run(cfg, world, Pose2D(0, 0, 0), (3.5, 0.0), beams=AROUND, params=tunnel_params(cfg))[-1]
    assert r.mode is Mode.MPND and not r.flags & Flag.PLANNER_NO_PATH
    assert r.path_xy[1, 0] < -1.5  # the first tunnel ends outside the U's mouth
    assert abs(r.direction_rad) > math.pi / 2  # ND+ drives backwards, towards the mouth


def test_warm_up_compiles_what_the_tunnel_planner_needs() -> None:
    """After warm_up (NF1 chosen) and warm_up_planners, a stack running the tunnel planner on real ticks
    compiles nothing new: warm_up_planners alone covers the tunnel planner's kernels."""
    from pathlib import Path

    from gndreplay.io import read_ticks
    from gndreplay.pipeline import cspace, nf1, tunnel
    from gndreplay.pipeline.stack import warm_up

    def signatures() -> dict[str, int]:
        return {
            f"{mod.__name__}.{name}": len(obj.signatures)
            for mod in (cspace, nf1, tunnel)
            for name, obj in vars(mod).items()
            if hasattr(obj, "signatures")
        }

    params = tunnel_params(PRESETS["wheelchair"])
    warm_up(PRESETS["wheelchair"].stack_params())
    tunnel.warm_up_planners(params.planner.tunnel)
    before = signatures()
    stack = NavigationStack(params)
    sample = Path(__file__).resolve().parents[1] / "sample_logs" / "office.clf.bz2"
    for i, (tick, _) in enumerate(zip(read_ticks(sample), range(40), strict=False)):
        goal = (tick.odom.x + 3.0, tick.odom.y) if i % 2 else (tick.odom.x - 4.0, tick.odom.y + 6.0)
        stack.step(tick.scan, tick.odom, goal)
    assert signatures() == before


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_goal_in_enclosed_box_is_held_unreachable(name: str) -> None:
    """NF1, the goal inside a closed box seen from every side: mND while the planner finds no path, then
    (after unreachable_ticks) ROTATE for one full turn in place, then standing still; never a trap escape.
    A plan found again (here: the goal moved out of the box) ends it."""
    cfg = PRESETS[name]
    params = dataclasses.replace(
        cfg.stack_params(), supervisor=dataclasses.replace(cfg.supervisor, unreachable_ticks=5)
    )
    world = np.vstack([ROOM, box(4.0, 0.0, 2.0, 2.0)])
    stack = NavigationStack(params)
    sensor = Pose2D(cfg.robot.laser_x_m, cfg.robot.laser_y_m, cfg.robot.laser_theta_rad)
    t = 1_000_000_000

    def step(pose: Pose2D, goal: tuple[float, float]) -> TickResult:
        nonlocal t
        t += 200_000_000
        return stack.step(scan_of(world, pose, sensor, t, AROUND), pose, goal)

    for a in np.linspace(-math.pi, math.pi, 9):  # look at the box from all around it
        step(Pose2D(4.0 + 3.0 * math.cos(a), 3.0 * math.sin(a), a + math.pi / 2), (4.0, 0.0))
    pose = Pose2D(0.0, 0.0, 0.0)
    results = []
    for _ in range(150):  # the robot turns as commanded
        r = step(pose, (4.0, 0.0))
        results.append(r)
        pose = Pose2D(pose.x, pose.y, pose.theta + r.command.w_radps * 0.2)
    assert all(r.flags & Flag.PLANNER_NO_PATH for r in results)
    assert not any(r.flags & Flag.TRAP_DETECTED for r in results)
    held = [i for i, r in enumerate(results) if r.mode is Mode.ROTATE]
    assert held and held == list(range(held[0], len(results)))  # once held, held for good
    assert all(r.mode is Mode.MND for r in results[: held[0]])
    assert all(r.command.v_mps == 0.0 and r.command.vy_mps == 0.0 for r in results[held[0]:])
    turned = sum(abs(r.command.w_radps) * 0.2 for r in results)
    assert turned == pytest.approx(2.0 * math.pi, abs=0.2 * cfg.robot.wmax_radps)  # one full look around
    assert results[-1].command.w_radps == 0.0 and results[-10].command.w_radps == 0.0
    assert step(pose, (0.0, 3.0)).mode is Mode.MPND  # a reachable goal: planning again at once


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_enclosed_robot_with_goal_beyond_the_grid_stops_after_one_turn(name: str) -> None:
    """The robot inside a closed ring, the goal far beyond the grid: no border cell is reachable, so the
    goal is held unreachable too (ROTATE one full turn, then still), unlike a NO_REGION ROTATE forever."""
    cfg = PRESETS[name]
    params = dataclasses.replace(
        cfg.stack_params(), supervisor=dataclasses.replace(cfg.supervisor, unreachable_ticks=2)
    )
    ring = regular_polygon(0.0, 0.0, cfg.robot.outer_radius_m + 0.15, sides=24)
    world = np.vstack([ROOM, ring])
    stack = NavigationStack(params)
    sensor = Pose2D(cfg.robot.laser_x_m, cfg.robot.laser_y_m, cfg.robot.laser_theta_rad)
    pose, results = Pose2D(0.0, 0.0, 0.0), []
    for i in range(160):
        t = 1_000_000_000 + i * 200_000_000
        r = stack.step(scan_of(world, pose, sensor, t, AROUND), pose, (100.0, 3.0))
        results.append(r)
        pose = Pose2D(0.0, 0.0, pose.theta + r.command.w_radps * 0.2)
    assert all(r.mode is Mode.ROTATE and r.command.v_mps == 0.0 for r in results)
    assert all(r.command.w_radps >= 0.0 for r in results)  # one direction, no dithering
    step = 0.2 * cfg.supervisor.rotate_w_frac * cfg.robot.wmax_radps  # one tick's turn
    turned = sum(r.command.w_radps * 0.2 for r in results)  # the ticks before the hold turn too (NO_REGION)
    assert 2.0 * math.pi - step <= turned <= 2.0 * math.pi + (params.supervisor.unreachable_ticks + 3) * step
    assert results[-1].command.w_radps == 0.0


@pytest.mark.parametrize(("mode", "strategy"),
                         [("teleop", "nd"), ("teleop", "wall-left"), ("follow", "free-space")])
def test_warm_up_compiles_what_the_multi_loop_modes_need(mode: str, strategy: str) -> None:
    """After warm_up with a teleop / follow configuration, real ticks (read-only beam angles) and a
    takeover by the local strategy in front of a wall compile nothing new in any pipeline module."""
    from pathlib import Path

    from gndreplay.io import read_ticks
    from gndreplay.pipeline import cspace, follow, local, model, nd, nf1, selector, supervisor
    from gndreplay.pipeline.stack import warm_up
    from gndreplay.types import Subgoal

    def signatures() -> dict[str, int]:
        return {
            f"{mod.__name__}.{name}": len(obj.signatures)
            for mod in (model, cspace, nf1, nd, local, follow, selector, supervisor)
            for name, obj in vars(mod).items()
            if hasattr(obj, "signatures")
        }

    cfg = PRESETS["wheelchair"]
    base = cfg.stack_params()
    local_params = dataclasses.replace(base.local, strategy=strategy)
    params = dataclasses.replace(base, nav_mode=mode, local=local_params)
    warm_up(params)
    before = signatures()
    subgoals = (Subgoal(2.0, 0.0, 0.0), Subgoal(3.0, 1.0, 1.0, "stop")) if mode == "follow" else ()
    stack = NavigationStack(params, subgoals)
    sample = Path(__file__).resolve().parents[1] / "sample_logs" / "office.clf.bz2"
    for tick, _ in zip(read_ticks(sample), range(5), strict=False):
        stack.step(tick.scan, tick.odom, (tick.odom.x + 3.0, tick.odom.y),
                   cmd=Command(tick.t_ns, cfg.robot.vmax_mps, 0.1))
    world = np.vstack([ROOM, wall(cfg.robot.front_m + 0.15, -3.0, cfg.robot.front_m + 0.15, 3.0)])
    stack = NavigationStack(dataclasses.replace(params, nav_mode="teleop"))
    sensor, pose = Pose2D(cfg.robot.laser_x_m, 0.0, 0.0), Pose2D(0.0, 0.0, 0.0)
    for i in range(2):
        t = 1_000_000_000 + i * 200_000_000
        r = stack.step(scan_of(world, pose, sensor, t, FRONT), pose, (4.0, 0.0),
                       cmd=Command(t, cfg.robot.vmax_mps, 0.0))
    assert r.active_mode == "local"
    assert signatures() == before


# ---- the multi-loop modes: command age, trap escape, reflexive loop, follower wiring --------------------


def _multi(cfg: Config, mode: str, **changes: object) -> StackParams:
    return dataclasses.replace(cfg.stack_params(), nav_mode=mode, **changes)  # type: ignore[arg-type]


def _scan(cfg: Config, segments: np.ndarray, pose: Pose2D, t_ns: int) -> Scan:
    sensor = Pose2D(cfg.robot.laser_x_m, cfg.robot.laser_y_m, cfg.robot.laser_theta_rad)
    return scan_of(segments, pose, sensor, t_ns, FRONT)


@pytest.mark.parametrize("age_s", [0.0, 0.3, 0.5, 0.6, 60.0])
def test_teleop_command_older_than_the_timeout_stands_still(age_s: float) -> None:
    cfg = PRESETS["wheelchair"]
    params = _multi(cfg, "teleop", cmd_timeout_s=0.5)
    stack, pose = NavigationStack(params), Pose2D(0.0, 0.0, 0.0)
    t = 100_000_000_000
    cmd = Command(t - round(age_s * 1e9), 0.3, 0.1)
    r = stack.step(_scan(cfg, ROOM, pose, t), pose, (5.0, 0.0), cmd=cmd)
    assert r.active_mode == "teleop"
    if age_s > params.cmd_timeout_s:
        assert (r.command.v_mps, r.command.vy_mps, r.command.w_radps) == (0.0, 0.0, 0.0)
        assert r.takeover_reason == "teleop: command stale"
    else:
        assert (r.command.v_mps, r.command.w_radps) == (0.3, 0.1) and r.takeover_reason == ""


def test_no_trap_escape_for_a_driver_but_for_local_navigation(monkeypatch: pytest.MonkeyPatch) -> None:
    """Whatever the trap detector says, a teleop command is never replaced by the escape (the driver's
    dithering is the driver's); under local navigation the escape runs and the mode column says so."""
    cfg = PRESETS["wheelchair"]
    pose, w = Pose2D(0.0, 0.0, 0.0), 0.5 * cfg.robot.wmax_radps
    for mode in ("teleop", "local"):
        stack = NavigationStack(_multi(cfg, mode))
        monkeypatch.setattr(stack.supervisor._trap, "update", lambda *_a: True)  # a trap every tick
        out = []
        for k in range(6):
            t = 1_000_000_000 + k * 200_000_000
            cmd = Command(t, 0.0, w if k % 2 == 0 else -w)  # turning left and right in place
            out.append(stack.step(_scan(cfg, ROOM, pose, t), pose, (4.0, 0.5), cmd=cmd))
        if mode == "teleop":
            assert all(r.mode is not Mode.ESCAPE and r.command.v_mps == 0.0 for r in out)
            assert all(not r.flags & Flag.TRAP_DETECTED for r in out)
            assert [r.command.w_radps for r in out] == [w if k % 2 == 0 else -w for k in range(6)]
        else:
            assert any(r.mode is Mode.ESCAPE and r.flags & Flag.TRAP_DETECTED for r in out)
            assert all(r.active_mode == "local" for r in out)


def test_an_escape_begun_under_local_navigation_ends_when_the_driver_has_the_robot() -> None:
    cfg = PRESETS["wheelchair"]
    stack, pose = NavigationStack(_multi(cfg, "teleop")), Pose2D(0.0, 0.0, 0.0)
    stack.supervisor._escape_left, stack.supervisor._escape_v = 5, 0.1  # an escape in progress
    t = 1_000_000_000
    r = stack.step(_scan(cfg, ROOM, pose, t), pose, (4.0, 0.0), cmd=Command(t, 0.0, 0.2))
    assert r.mode is not Mode.ESCAPE and (r.command.v_mps, r.command.w_radps) == (0.0, 0.2)


@pytest.mark.parametrize("selector", [True, False])
def test_local_mode_keeps_the_reflexive_loop_without_the_selector(selector: bool) -> None:
    """Local navigation has no selector: ``selector=False`` leaves its stale-data stop and its safety
    check in place."""
    cfg = PRESETS["wheelchair"]
    stack = NavigationStack(_multi(cfg, "local", selector=selector))
    pose = Pose2D(0.0, 0.0, 0.0)
    r0 = stack.step(_scan(cfg, ROOM, pose, 1_000_000_000), pose, (5.0, 0.0))
    assert r0.mode is not Mode.STALE
    r1 = stack.step(_scan(cfg, ROOM, pose, 6_000_000_000), pose, (5.0, 0.0))  # 5 s later
    assert r1.mode is Mode.STALE and r1.flags & Flag.STALE_SCAN
    assert (r1.command.v_mps, r1.command.w_radps) == (0.0, 0.0)


def test_multi_loop_tick_gathers_the_safety_points_once(monkeypatch: pytest.MonkeyPatch) -> None:
    cfg = PRESETS["wheelchair"]
    stack, pose = NavigationStack(_multi(cfg, "teleop")), Pose2D(0.0, 0.0, 0.0)
    calls = []
    orig = stack.supervisor._points
    monkeypatch.setattr(stack.supervisor, "_points", lambda *a: calls.append(1) or orig(*a))
    world = np.vstack([ROOM, wall(cfg.robot.front_m + 0.15, -3.0, cfg.robot.front_m + 0.15, 3.0)])
    for k in range(3):
        t = 1_000_000_000 + k * 200_000_000
        r = stack.step(_scan(cfg, world, pose, t), pose, (4.0, 0.0), cmd=Command(t, cfg.robot.vmax_mps, 0.0))
        assert len(calls) == k + 1
    assert r.active_mode == "local"  # the selector and the reflexive loop both ran on them


def test_follower_is_told_the_command_executed_last_tick() -> None:
    """After a takeover the follower regenerates its trajectory from the motion actually executed: the
    stack passes the last command out, v and w, and the new trajectory starts with its curvature."""
    from gndreplay.pipeline.follow import PathFollower
    from gndreplay.types import Subgoal

    cfg = PRESETS["xr4000"]
    stack = NavigationStack(_multi(cfg, "follow"), (Subgoal(4.0, 0.0, 0.0, "stop"),))
    seen: list[tuple[float | None, float | None]] = []
    overridden: list[bool] = []
    follower = stack._follower
    assert isinstance(follower, PathFollower)
    orig = follower.step

    def spy(pose: Pose2D, grid: object, *, v_mps: float | None = None,
            w_radps: float | None = None, overridden: bool = False) -> object:
        seen.append((v_mps, w_radps))
        told.append(overridden)
        return orig(pose, grid, v_mps=v_mps, w_radps=w_radps,  # type: ignore[arg-type]
                    overridden=overridden)

    told = overridden

    follower.step = spy  # type: ignore[method-assign]
    pose, out = Pose2D(0.0, 0.0, 0.0), []
    for k in range(4):
        t = 1_000_000_000 + k * 200_000_000
        out.append(stack.step(_scan(cfg, ROOM, pose, t), pose, (0.0, 0.0)))
        pose = Pose2D(pose.x + 0.05, pose.y, pose.theta)
    assert seen[0] == (0.0, 0.0)
    assert seen[1:] == [(r.command.v_mps, r.command.w_radps) for r in out[:-1]]
    # ... and whether that command was its own (not taken over nor replaced by the reflexive loop)
    assert told == [False] + [r.active_mode != "follow" or r.mode is not Mode.FOLLOW for r in out[:-1]]
    # a push off the trajectory: the new one starts with the executed curvature (w / v, within kappa_max)
    stack._v_out, stack._w_out = 0.4, 0.2
    t = 1_000_000_000 + 4 * 200_000_000
    stack.step(_scan(cfg, ROOM, Pose2D(0.2, 1.0, 0.0), t), Pose2D(0.2, 1.0, 0.0), (0.0, 0.0))
    assert follower.trajectory is not None and follower.trajectory.kappa[0] == pytest.approx(0.5)


def test_a_counter_steering_driver_keeps_the_held_teleop_target() -> None:
    """teleop_into_wall: local navigation turns the chair left round the cabinet and the driver, still
    aiming down his line, steers right (w changes sign). Re-aiming the held target on that change swung it
    from side to side with the chair, and ND+ turned it left and right in place for 80 s. The target is
    aimed again only when his intention points elsewhere (over 45 deg from it) or he reverses."""
    turned = 0.4  # the chair turned 0.4 rad left since the takeover: the held target is 0.4 rad right
    held = 4.0 * np.array([math.cos(-turned), math.sin(-turned)])
    before, after = (0.3, 0.0, 0.0), (0.3, 0.0, -0.1)  # straight on, then steering back towards the line
    rel = intention_xy(*after, 1.0)
    assert rel is not None
    assert not _intention_changed(before, after, held, rel)
    away = intention_xy(0.0, 0.0, 0.5, 1.0)  # a turn in place to the left: he wants to go elsewhere
    assert away is not None and _intention_changed(before, (0.0, 0.0, 0.5), held, away)
    back = intention_xy(-0.3, 0.0, 0.0, 1.0)  # reversing
    assert back is not None and _intention_changed(before, (-0.3, 0.0, 0.0), held, back)


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_a_goal_nd_reaches_through_a_door_the_planner_closes_is_not_held_unreachable(name: str) -> None:
    """The goal in view 2 m beyond a door the planner's inflated C-space closes (narrower than twice its
    inflation) but ND+ finds navigable (wider than the robot): the planner finds no path tick after tick,
    yet ND+ to the goal chooses the goal's own region (HSGR / LSG), so GND's mND goes on and the goal is
    never held unreachable (no ROTATE, no stop). The other side of the rule, a goal hidden inside a closed
    box while ND+ finds gaps round it, is ``test_goal_in_enclosed_box_is_held_unreachable``."""
    cfg = PRESETS[name]
    params = dataclasses.replace(
        cfg.stack_params(), supervisor=dataclasses.replace(cfg.supervisor, unreachable_ticks=3)
    )
    robot = cfg.robot
    nd_gap = robot.width_m if robot.shape == "rectangle" else 2.0 * robot.radius_m
    door = 0.5 * (nd_gap + 2.0 * (robot.inner_radius_m + params.cspace_margin_m))
    sensor = Pose2D(robot.laser_x_m, robot.laser_y_m, robot.laser_theta_rad)
    x_wall = robot.front_m + 1.0
    room = polygon([(-2.0, -2.5), (x_wall + 3.0, -2.5), (x_wall + 3.0, 2.5), (-2.0, 2.5)])  # all in view
    world = np.vstack([room, wall(x_wall, -2.5, x_wall, -door / 2), wall(x_wall, door / 2, x_wall, 2.5)])
    stack = NavigationStack(params)
    pose, results = Pose2D(0.0, 0.0, 0.0), []
    for i in range(12):  # the robot stands still: the same view every tick
        t = 1_000_000_000 + i * 200_000_000
        results.append(stack.step(scan_of(world, pose, sensor, t, AROUND), pose, (x_wall + 2.0, 0.0)))
    assert all(r.flags & Flag.PLANNER_NO_PATH for r in results), "the door is open to the planner"
    assert all(r.mode is Mode.MND and r.situation in (Situation.HSGR, Situation.LSG) for r in results)
    assert all(r.command.v_mps > 0.0 for r in results)


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_tunnel_fallback_is_flagged_per_tick(name: str) -> None:
    """A tick whose plan came from the tunnel planner's complete fallback (NF1 on the same C-space) says so
    in its flags; with the paper's node search alone the same budget is a planner time-out, unflagged."""
    import dataclasses

    from gndreplay.pipeline.tunnel import TunnelParams

    cfg = PRESETS[name]
    world = np.vstack([ROOM, polygon([(1.5, -1.0), (1.7, -1.0), (1.7, 1.0), (1.5, 1.0)])])
    flags = []
    for complete in (True, False):
        base = tunnel_params(cfg)
        planner = dataclasses.replace(base.planner, tunnel=TunnelParams(max_expansions=1, complete=complete))
        params = dataclasses.replace(base, planner=planner)
        flags.append(run(cfg, world, Pose2D(0, 0, 0), (4.0, 0.0), params=params)[-1].flags)
    assert flags[0] & Flag.PLANNER_FALLBACK and not flags[0] & Flag.PLANNER_TIMEOUT
    assert flags[1] & Flag.PLANNER_TIMEOUT and not flags[1] & Flag.PLANNER_FALLBACK
