"""The mode selector (issue 14 item 4) on scripted scans, in a kinematic loop: the robot moves exactly as
commanded, the laser is ray cast from the new pose each tick."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from gndreplay.config import PRESETS, Config
from gndreplay.errors import ConfigError
from gndreplay.geometry import compose
from gndreplay.pipeline.selector import (
    Hold,
    Takeover,
    arbitrate,
    intention_xy,
    look_hold,
    select_mode,
    swept_area_occupied,
    teleop_command,
    turned_first,
)
from gndreplay.pipeline.stack import NavigationStack, StackParams, TickResult
from gndreplay.pipeline.supervisor import braking_time_s, footprint_signed_distance
from gndreplay.sim.closedloop import arc_step
from gndreplay.sim.world import box, cast_rays, polygon, wall
from gndreplay.types import Command, Flag, Mode, Pose2D, Scan, Subgoal

FRONT = np.linspace(-math.pi / 2, math.pi / 2, 361)  # the papers' SICK: 180 deg, 0.5 deg
ROOM = polygon([(-6, -6), (14, -6), (14, 6), (-6, 6)])
PRESET_NAMES = sorted(PRESETS)
T0 = 1_000_000_000


def teleop_params(cfg: Config, **changes: object) -> StackParams:
    return dataclasses.replace(cfg.stack_params(), nav_mode="teleop", **changes)  # type: ignore[arg-type]


def clearance(segments: np.ndarray, pose: np.ndarray, cfg: Config) -> float:
    """Smallest signed distance [m] from the footprint at ``pose`` to the walls (sampled every 5 mm)."""
    pts = []
    for x0, y0, x1, y1 in segments:
        n = max(2, math.ceil(math.hypot(x1 - x0, y1 - y0) / 0.005) + 1)
        t = np.linspace(0.0, 1.0, n)[:, None]
        pts.append(np.column_stack([x0 + t[:, 0] * (x1 - x0), y0 + t[:, 0] * (y1 - y0)]))
    world = np.vstack(pts)
    c, s = math.cos(pose[2]), math.sin(pose[2])
    d = world - pose[:2]
    local = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]])
    return float(np.min(footprint_signed_distance(local, cfg.robot)))


def drive(
    cfg: Config,
    segments: np.ndarray,
    start: tuple[float, float, float],
    command: Command | None,
    n: int,
    params: StackParams,
    subgoals: tuple[Subgoal, ...] = (),
    goal: tuple[float, float] = (0.0, 0.0),
) -> tuple[list[TickResult], list[np.ndarray]]:
    """``n`` ticks: scan at the pose, step the stack with ``command`` as the teleop command, move the robot
    exactly by the stack's command for one laser period. Returns the results and the pose of each tick."""
    stack = NavigationStack(params, subgoals)
    sensor = Pose2D(cfg.robot.laser_x_m, cfg.robot.laser_y_m, cfg.robot.laser_theta_rad)
    dt = cfg.laser.period_s
    pose = np.array(start, dtype=np.float64)
    results, poses = [], []
    for i in range(n):
        t = T0 + round(i * dt * 1e9)
        laser = compose(pose, sensor.as_array())
        ranges = cast_rays(laser[:2], FRONT + laser[2], segments, max_range_m=8.0)
        scan = Scan(t_ns=t, ranges_m=ranges, angles_rad=FRONT, max_range_m=8.0, sensor_pose=sensor)
        p = Pose2D.from_array(pose)
        cmd = None if command is None else dataclasses.replace(command, t_ns=t)  # the driver holds it
        r = stack.step(scan, p, goal, cmd=cmd)
        results.append(r)
        poses.append(pose)
        pose = arc_step(pose, r.command.v_mps, r.command.vy_mps, r.command.w_radps, dt)
    return results, poses


# ---- the pure functions ------------------------------------------------------------------------------


def test_intention_points_along_the_commanded_motion() -> None:
    ahead = intention_xy(0.3, 0.0, 0.0, 1.0)
    behind = intention_xy(-0.3, 0.0, 0.0, 1.0)
    left = intention_xy(0.0, 0.0, 0.5, 1.0)
    right_arc = intention_xy(0.3, 0.0, -0.3, 1.0)
    assert ahead is not None and np.allclose(ahead, [1.0, 0.0])
    assert behind is not None and np.allclose(behind, [-1.0, 0.0], atol=1e-12)
    assert left is not None and np.allclose(left, [0.0, 1.0], atol=1e-12)
    # an arc to the right: the chord after 1 m turns by half of the 1 rad heading change
    assert right_arc is not None and np.allclose(right_arc, [math.cos(-0.5), math.sin(-0.5)])
    assert intention_xy(0.0, 0.0, 0.0, 1.0) is None


def test_select_mode_takes_over_only_when_occupied() -> None:
    assert select_mode("teleop", "") == ("teleop", "")
    assert select_mode("teleop", "scan") == ("local", "teleop: swept area occupied (scan)")
    assert select_mode("follow", "grid") == ("local", "follow: swept area occupied (grid)")


def _timeline(occupied: list[str], moving: list[bool], hold_s: float, dt_s: float = 0.2) -> list[str]:
    """Active modes of ``arbitrate`` over a scripted sequence of ticks (path following desired)."""
    held: Takeover | None = None
    out = []
    for k, (occ, mov) in enumerate(zip(occupied, moving, strict=True)):
        active, reason, held = arbitrate("follow", occ, t_ns=round(k * dt_s * 1e9), held=held,
                                         hold=Hold(hold_s), moving=mov)
        assert (active == "local") == bool(reason)
        out.append(active)
    return out


def test_hold_keeps_local_navigation_until_the_area_has_been_clear_for_hold_s() -> None:
    """The paper's rule (hold 0) hands back on the first clear tick: the chattering round an obstacle, one
    takeover per occupied tick. A 0.5 s hold (0.2 s ticks) keeps local navigation for the clear ticks
    less than 0.5 s after the last occupied one: one takeover, ending 0.6 s after the last occupied tick."""
    occ = ["scan", "", "grid", "", "scan", "", "", "", "", ""]
    moving = [True] * len(occ)
    paper = _timeline(occ, moving, 0.0)
    assert paper == ["local" if o else "follow" for o in occ]
    held = _timeline(occ, moving, 0.5)
    assert held == ["local"] * 7 + ["follow"] * 3
    onsets = [k for k in range(len(held)) if held[k] == "local" and (k == 0 or held[k - 1] != "local")]
    assert onsets == [0]


def test_hold_never_delays_a_takeover_nor_moves_a_still_desired_command() -> None:
    """A takeover starts on the very tick the area is occupied, however long the hold; a desired command
    that stands still (the driver let go, the follower stopped) ends the hold at once; a clear area with
    no takeover in progress is never held."""
    assert _timeline(["", "", "scan"], [True] * 3, 10.0) == ["follow", "follow", "local"]
    assert _timeline(["scan", "", "", ""], [True, True, False, True], 10.0) == ["local", "local", "follow",
                                                                              "follow"]
    active, reason, held = arbitrate("teleop", "", t_ns=5, held=Takeover(0), hold=Hold(1.0), moving=True)
    assert (active, held) == ("local", Takeover(0)) and reason.startswith("teleop: swept area clear")
    assert arbitrate("teleop", "", t_ns=10**9, held=Takeover(0), hold=Hold(1.0), moving=True) == (
        "teleop", "", None)


def test_after_a_turn_first_local_navigation_keeps_the_robot_until_it_made_its_way() -> None:
    """The blind side rule's turn first clears the desired command's sweep by itself: the hold then lasts
    until the robot moved ``look_m`` from where it turned first or ``look_s`` passed, whichever first,
    and an occupied tick in between keeps the turn first's place; a still desired command ends it too."""
    hold = Hold(clear_s=0.5, look_m=1.0, look_s=10.0)
    s = 10**9
    held = turned_first(Takeover(0), (0.0, 0.0), 1 * s)
    assert turned_first(None, (0.0, 0.0), s) is None  # no takeover in progress, nothing to hold

    def at(t_s: float, x: float, occupied: str = "", moving: bool = True) -> tuple[str, str, Takeover | None]:
        return arbitrate("follow", occupied, t_ns=round(t_s * 1e9), held=held, hold=hold, moving=moving,
                         xy=(x, 0.0))

    active, reason, kept = at(2.0, 0.5)  # clear for 2 s (past clear_s), moved 0.5 m of 1 m: held
    assert (active, kept) == ("local", held) and reason == (
        "follow: swept area clear since local navigation turned first (hold)")
    assert at(2.0, 1.0) == ("follow", "", None)  # moved look_m
    assert at(11.5, 0.2) == ("follow", "", None)  # look_s passed
    assert at(2.0, 0.5, moving=False) == ("follow", "", None)
    active, _, again = at(3.0, 0.5, occupied="grid")
    assert active == "local" and again == Takeover(3 * s, held.look if held else None)
    # without a turn first, the same clear tick hands back
    assert arbitrate("follow", "", t_ns=2 * s, held=Takeover(0), hold=hold, moving=True, xy=(0.5, 0.0)) == (
        "follow", "", None)


def test_look_hold_is_a_footprint_diameter_or_one_rotate_turn() -> None:
    for cfg in PRESETS.values():
        h = look_hold(0.6, cfg.robot, cfg.supervisor)
        assert h.clear_s == 0.6 and h.look_m == pytest.approx(2.0 * cfg.robot.outer_radius_m)
        assert h.look_s * cfg.supervisor.rotate_w_frac * cfg.robot.wmax_radps == pytest.approx(2.0 * math.pi)


def test_swept_area_reports_where_it_is_occupied() -> None:
    cfg = PRESETS["wheelchair"]
    sup, robot = cfg.supervisor, cfg.robot
    ahead = np.array([[robot.front_m + 0.1, 0.0]])
    none = np.zeros((0, 2))
    kw = {"cell_m": 0.05, "margin_m": 0.05}
    assert swept_area_occupied(0.3, 0.0, 0.0, ahead, none, robot, sup, **kw) == "scan"
    assert swept_area_occupied(0.3, 0.0, 0.0, none, ahead, robot, sup, **kw) == "grid"
    assert swept_area_occupied(-0.3, 0.0, 0.0, ahead, ahead, robot, sup, **kw) == ""  # backing away
    assert swept_area_occupied(0.0, 0.0, 0.0, ahead, ahead, robot, sup, **kw) == ""  # standing still


def test_teleop_command_is_clipped_and_none_stands_still() -> None:
    robot = PRESETS["wheelchair"].robot
    assert teleop_command(Command(0, 5.0, -9.0, 1.0), robot) == (robot.vmax_mps, 0.0, -robot.wmax_radps, "")
    assert teleop_command(None, robot) == (0.0, 0.0, 0.0, "teleop: no command")
    assert teleop_command(Command(0, math.nan, 0.0), robot)[:3] == (0.0, 0.0, 0.0)


# ---- teleoperation in a kinematic loop -----------------------------------------------------------------


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_teleop_at_a_wall_is_taken_over_at_the_braking_distance(name: str) -> None:
    """Full speed straight at a wall 3 m ahead: local navigation takes over on the first tick the swept
    area (braking horizon, emergency + selector margins) reaches the wall, and the robot never touches."""
    cfg = PRESETS[name]
    p = teleop_params(cfg)
    v = cfg.robot.vmax_mps
    x_wall = cfg.robot.front_m + 3.013  # not on a cell boundary
    world = np.vstack([ROOM, wall(x_wall, -3.0, x_wall, 3.0)])
    results, poses = drive(cfg, world, (0.0, 0.0, 0.0), Command(0, v, 0.0), 60, p)
    taken = [i for i, r in enumerate(results) if r.active_mode == "local"]
    assert taken, "never taken over"
    k = taken[0]
    assert all(r.active_mode == "teleop" and r.mode is not Mode.EMERGENCY for r in results[:k])
    assert results[k].desired_mode == "teleop" and results[k].takeover_reason.startswith("teleop: swept area")
    gap = x_wall - (poses[k][0] + cfg.robot.front_m)  # heading 0 until the takeover
    predicted = v * braking_time_s(v, 0.0, 0.0, cfg.robot, cfg.supervisor) + (
        cfg.supervisor.emergency_margin_m + p.selector_margin_m)
    step = v * cfg.laser.period_s  # the robot moves this much per tick: the takeover falls within a step
    cell = cfg.grid.cell_m  # an occupied cell counts grown by half a cell, its centre is within half a cell
    assert predicted - step - 1e-9 < gap <= predicted + cell + 1e-9
    assert min(clearance(world, q, cfg) for q in poses) > 0.0


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_teleop_parallel_to_a_wall_is_never_taken_over(name: str) -> None:
    cfg = PRESETS[name]
    side = cfg.robot.width_m / 2 if cfg.robot.shape == "rectangle" else cfg.robot.radius_m
    y_wall = side + 0.25
    world = np.vstack([ROOM, wall(-2.0, y_wall, 12.0, y_wall)])
    results, poses = drive(cfg, world, (0.0, 0.0, 0.0), Command(0, cfg.robot.vmax_mps, 0.0), 40,
                           teleop_params(cfg))
    assert all(r.active_mode == "teleop" and r.takeover_reason == "" for r in results)
    assert all(r.command.v_mps == cfg.robot.vmax_mps and r.command.w_radps == 0.0 for r in results)
    assert poses[-1][0] > 0.9 * 39 * cfg.robot.vmax_mps * cfg.laser.period_s


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_without_the_selector_the_command_goes_out_unchanged_and_collides(name: str) -> None:
    """The same drive at the wall, selector off: the command is never changed, and the robot hits the
    wall (so the selector is what keeps the robot clear in the test above)."""
    cfg = PRESETS[name]
    v = cfg.robot.vmax_mps
    x_wall = cfg.robot.front_m + 3.013
    world = np.vstack([ROOM, wall(x_wall, -3.0, x_wall, 3.0)])
    results, poses = drive(cfg, world, (0.0, 0.0, 0.0), Command(0, v, 0.0), 60,
                           teleop_params(cfg, selector=False))
    assert all((r.command.v_mps, r.command.vy_mps, r.command.w_radps) == (v, 0.0, 0.0) for r in results)
    assert all(r.active_mode == "teleop" and r.desired_mode == "teleop" for r in results)
    assert min(clearance(world, q, cfg) for q in poses) < 0.0


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_teleop_resumes_once_the_obstacle_is_passed(name: str) -> None:
    """A box partly across the straight drive: local navigation deviates around it, teleoperation wins
    again as soon as its straight sweep is clear, and the robot passes the box without touching it (and is
    driven by teleoperation once past it: later, a fast robot's deviated heading may bring the room's wall
    into its sweep, which is another takeover)."""
    cfg = PRESETS[name]
    side = cfg.robot.width_m / 2 if cfg.robot.shape == "rectangle" else cfg.robot.radius_m
    bx = cfg.robot.front_m + 2.5
    obstacle = box(bx, side + 0.1, 0.4, 0.6)  # its near edge 0.2 m inside the swept band
    world = np.vstack([ROOM, obstacle])
    results, poses = drive(cfg, world, (0.0, 0.0, 0.0), Command(0, cfg.robot.vmax_mps, 0.0), 90,
                           teleop_params(cfg))
    active = [r.active_mode for r in results]
    first = active.index("local")
    assert "teleop" in active[first:], "teleoperation never won again"
    back = first + active[first:].index("teleop")
    past = next(k for k, q in enumerate(poses) if q[0] > bx + 0.5)  # past the box
    assert all(a == "teleop" for a in active[past:past + 10])
    assert min(clearance(world, q, cfg) for q in poses) > 0.0
    assert back > first


def test_no_teleop_command_stands_still_with_the_reason() -> None:
    cfg = PRESETS["wheelchair"]
    results, _ = drive(cfg, ROOM, (0.0, 0.0, 0.0), None, 3, teleop_params(cfg))
    assert all((r.command.v_mps, r.command.w_radps) == (0.0, 0.0) for r in results)
    assert all(r.takeover_reason == "teleop: no command" and r.active_mode == "teleop" for r in results)


def test_gnd_mode_records_gnd_and_no_selector() -> None:
    cfg = PRESETS["wheelchair"]
    results, _ = drive(cfg, ROOM, (0.0, 0.0, 0.0), Command(0, 0.3, 0.0), 3, cfg.stack_params(),
                       goal=(4.0, 0.0))
    assert all(r.desired_mode == r.active_mode == "gnd" and r.takeover_reason == "" for r in results)
    assert all(r.subgoal_index == -1 for r in results)


def test_follow_without_subgoals_is_a_config_error() -> None:
    with pytest.raises(ConfigError, match="subgoals"):
        NavigationStack(dataclasses.replace(PRESETS["wheelchair"].stack_params(), nav_mode="follow"))


# ---- path following ----------------------------------------------------------------------------------


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_follow_reaches_the_final_subgoal_and_stops(name: str) -> None:
    cfg = PRESETS[name]
    params = dataclasses.replace(cfg.stack_params(), nav_mode="follow")
    subgoals = (Subgoal(2.0, 0.0, 0.0), Subgoal(4.0, 1.5, math.pi / 2),
                Subgoal(4.0, 3.5, math.pi / 2, "stop"))
    results, poses = drive(cfg, ROOM, (0.0, 0.0, 0.0), None, 250, params, subgoals)
    done = [i for i, r in enumerate(results) if r.flags & Flag.GOAL_REACHED]
    assert done, f"final subgoal not reached; last subgoal index {results[-1].subgoal_index}"
    k = done[0]
    assert results[k].mode is Mode.GOAL
    assert (results[k].command.v_mps, results[k].command.w_radps) == (0.0, 0.0)
    assert results[k].subgoal_index == len(subgoals)
    assert [r.subgoal_index for r in results[:k]] == sorted(r.subgoal_index for r in results[:k])
    _at_the_final_stop(cfg, results, poses, k, subgoals[-1])
    assert all(r.desired_mode == "follow" for r in results)


def _at_the_final_stop(cfg: Config, results: list[TickResult], poses: list[np.ndarray], k: int,
                       goal: Subgoal) -> None:
    """Tick k reports the path done: the robot is within reach of the final stop subgoal, with the heading
    asked, at rest (the command executed on the tick before, which moved it there, within stop_v_mps), and
    stays still."""
    follow = cfg.stack_params().follow
    last = poses[k]
    assert math.hypot(last[0] - goal.x, last[1] - goal.y) <= follow.reach_m + 1e-9
    assert abs(math.remainder(last[2] - goal.theta, math.tau)) <= follow.heading_tol_rad
    assert abs(results[k - 1].command.v_mps) <= follow.stop_v_mps
    assert all((r.command.v_mps, r.command.w_radps) == (0.0, 0.0) for r in results[k:])
    assert all(r.mode is Mode.GOAL for r in results[k:])


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_follow_deviates_round_an_unknown_obstacle_and_resumes(name: str) -> None:
    """The paper's Fig. 7 in a kinematic loop: a box on the straight path between two subgoals; local
    navigation takes over in front of it, path following resumes once its sweep is clear, and the final
    subgoal is reached without touching anything."""
    cfg = PRESETS[name]
    params = dataclasses.replace(cfg.stack_params(), nav_mode="follow")
    subgoals = (Subgoal(3.0, 0.0, 0.0), Subgoal(7.0, 0.0, 0.0, "stop"))
    world = np.vstack([ROOM, box(4.6, 0.15, 0.4, 0.5)])
    results, poses = drive(cfg, world, (0.0, 0.0, 0.0), None, 400, params, subgoals)
    active = [r.active_mode for r in results]
    assert "local" in active and all(r.takeover_reason.startswith("follow: swept area") for r in results
                                     if r.active_mode == "local")
    first = active.index("local")
    assert "follow" in active[first:]
    done = [i for i, r in enumerate(results) if r.flags & Flag.GOAL_REACHED]
    assert done, f"final subgoal not reached; last subgoal index {results[-1].subgoal_index}"
    assert min(clearance(world, q, cfg) for q in poses[: done[0] + 1]) > 0.0
    _at_the_final_stop(cfg, results, poses, done[0], subgoals[-1])


@pytest.mark.parametrize("strategy", ["free-space", "contour"])
def test_a_local_strategy_takes_over_at_the_wall_without_contact(strategy: str) -> None:
    cfg = PRESETS["wheelchair"]
    p = teleop_params(cfg, local=dataclasses.replace(cfg.stack_params().local, strategy=strategy))
    x_wall = cfg.robot.front_m + 2.013
    world = np.vstack([ROOM, wall(x_wall, -3.0, x_wall, 3.0)])
    results, poses = drive(cfg, world, (0.0, 0.0, 0.0), Command(0, cfg.robot.vmax_mps, 0.0), 50, p)
    assert any(r.active_mode == "local" for r in results)
    assert min(clearance(world, q, cfg) for q in poses) > 0.0


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_local_mode_alone_reaches_the_goal(name: str) -> None:
    cfg = PRESETS[name]
    params = dataclasses.replace(cfg.stack_params(), nav_mode="local")
    world = np.vstack([ROOM, box(2.5, 0.0, 0.4, 0.6)])
    results, poses = drive(cfg, world, (0.0, 0.0, 0.0), None, 300, params, goal=(5.0, 0.0))
    assert all(r.desired_mode == r.active_mode == "local" for r in results)
    done = [i for i, r in enumerate(results) if r.flags & Flag.GOAL_REACHED]
    assert done and results[done[0]].mode is Mode.GOAL
    assert min(clearance(world, q, cfg) for q in poses[: done[0] + 1]) > 0.0


# ---- the hold and the follower's replan, in the stack --------------------------------------------------


def _onsets(results: list[TickResult], mode: str) -> list[int]:
    active = [r.active_mode for r in results]
    return [k for k in range(1, len(active)) if active[k] == mode and active[k - 1] != mode]


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_the_stack_hands_back_only_after_the_hold(name: str) -> None:
    """The box across the straight drive of ``test_teleop_resumes_once_the_obstacle_is_passed``: with
    selector_hold_s every hand-back to the driver comes at least that long after the last tick whose sweep
    was occupied, and the clear ticks in between are recorded as the hold; with 0 (the paper's rule) no
    tick is held for the clear time, and the robot passes the box either way without touching it."""
    cfg = PRESETS[name]
    side = cfg.robot.width_m / 2 if cfg.robot.shape == "rectangle" else cfg.robot.radius_m
    bx = cfg.robot.front_m + 2.5
    world = np.vstack([ROOM, box(bx, side + 0.1, 0.4, 0.6)])
    cmd = Command(0, cfg.robot.vmax_mps, 0.0)
    for hold_s in (0.6, 0.0):
        params = teleop_params(cfg, selector_hold_s=hold_s)
        results, poses = drive(cfg, world, (0.0, 0.0, 0.0), cmd, 90, params)
        assert min(clearance(world, q, cfg) for q in poses) > 0.0 and poses[-1][0] > bx + 0.5
        backs = _onsets(results, "teleop")
        assert backs, "teleoperation never won again"
        held = [r for r in results if r.takeover_reason.endswith("s (hold)")]
        assert bool(held) == (hold_s > 0.0)
        for k in backs:
            last = max(j for j in range(k) if "occupied" in results[j].takeover_reason)
            assert results[k].t_ns - results[last].t_ns >= round(hold_s * 1e9)
            assert all(results[j].active_mode == "local" for j in range(last, k))


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_the_follower_plans_anew_from_the_pose_after_a_takeover(name: str) -> None:
    """The paper's Fig. 7: given control back, the path follower executes a newly planned trajectory from
    where local navigation left the robot (its first point is the robot's position), not its old one
    through the obstacle."""
    cfg = PRESETS[name]
    params = dataclasses.replace(cfg.stack_params(), nav_mode="follow")
    subgoals = (Subgoal(3.0, 0.0, 0.0), Subgoal(7.0, 0.0, 0.0, "stop"))
    world = np.vstack([ROOM, box(4.6, 0.15, 0.4, 0.5)])
    results, poses = drive(cfg, world, (0.0, 0.0, 0.0), None, 400, params, subgoals)
    backs = _onsets(results, "follow")
    assert backs, "path following never won again"
    for k in backs:
        assert results[k].path_xy.shape[0] > 1
        assert np.allclose(results[k].path_xy[0], poses[k][:2], atol=1e-9)
        # while it had the robot before the takeover, the follower tracked a trajectory from elsewhere
    first = _onsets(results, "local")[0]
    assert not np.allclose(results[first - 1].path_xy[0], poses[first - 1][:2], atol=1e-3)
