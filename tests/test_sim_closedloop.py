"""Closed-loop simulation: exact rays and contacts with known answers, events and movers at their times,
yielding, scenario-file validation, determinism, the CLI, and every shipped scenario running once."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from typer.testing import CliRunner

from gndreplay.cli import app
from gndreplay.config import preset
from gndreplay.errors import ConfigError
from gndreplay.sim import ClosedLoop, shipped_scenarios, simulate_scenario
from gndreplay.sim.closedloop import _World, arc_step
from gndreplay.sim.geometry import Shapes, box_vertices, cast, footprint_clearance, wall_vertices
from gndreplay.sim.scenario_file import load_scenario, parse_scenario, resolve_scenario

WHEELCHAIR = preset("wheelchair")
XR4000 = preset("xr4000")


def spec(world: dict[str, Any], **kw: Any) -> Any:
    doc = {"name": "t", "start": [0.0, 0.0, 0.0], "goal": [50.0, 0.0], "time_limit": 60, "world": world}
    doc.update(kw)
    return parse_scenario(doc, "test.yaml")


def shapes_of(s: Any, t: float = 0.0) -> Shapes:
    w = _World(s)
    return w.shapes(t, w.mover_xy)


def drive(s: Any, cfg: Any, cmd: tuple[float, float, float], until_s: float, *,
          pose: tuple[float, float, float] | None = None) -> ClosedLoop:
    """The robot already moving at ``cmd`` (no acceleration phase), advanced until ``until_s``; the exact
    motion model (no lag, no slip), so contacts have known answers."""
    loop = ClosedLoop(s, cfg, seed=0, ideal_dynamics=True)
    if pose is not None:
        loop.pose = np.array(pose, dtype=np.float64)
    loop.vel = loop.cmd = cmd
    loop._advance(round(until_s * 1e9))
    return loop


# --------------------------------------------------------------------------------------------- rays


def test_rays_against_a_thick_wall_its_end_face_and_a_bare_segment() -> None:
    s = spec({"walls": {"across": [2.0, -1.0, 2.0, 1.0, 0.2], "along": [0.0, 3.0, 4.0, 3.0],
                        "bare": [0.0, -3.0, 4.0, -3.0, 0.0]}})
    sh = shapes_of(s)
    r = cast((0.0, 0.0), np.array([0.0]), sh, 30.0)
    assert r[0] == pytest.approx(1.9, abs=1e-12)  # the face 0.1 m before the segment
    # seen edge-on from its axis, a thick wall shows its end face (at x = 0, not extended past it)
    r = cast((-2.0, 3.0), np.array([0.0]), sh, 30.0)
    assert r[0] == pytest.approx(2.0, abs=1e-12)
    r = cast((-2.0, 3.049), np.array([0.0]), sh, 30.0)
    assert r[0] == pytest.approx(2.0, abs=1e-12)
    # a zero-thickness wall seen edge-on is invisible (the artefact thick walls avoid)
    r = cast((-2.0, -3.0), np.array([0.0]), sh, 30.0)
    assert math.isinf(r[0])
    # straight up from the origin: the long wall's lower face at 3 - 0.05
    r = cast((1.0, 0.0), np.array([math.pi / 2]), sh, 30.0)
    assert r[0] == pytest.approx(2.95, abs=1e-12)


def test_rays_against_boxes_and_exact_circles() -> None:
    s = spec({"boxes": {"b": [5.0, 0.0, 2.0, 1.0, 0.0], "r": [0.0, 5.0, 2.0, 1.0, math.pi / 2]},
              "circles": {"c": [-5.0, 0.0, 1.0]}})
    sh = shapes_of(s)
    r = cast((0.0, 0.0), np.array([0.0, math.pi / 2, math.pi]), sh, 30.0)
    np.testing.assert_allclose(r, [4.0, 4.0, 4.0], atol=1e-12)
    # an offset ray hits the circle at the analytic chord point: y = 0.6 -> x = -5 + 0.8
    r = cast((0.0, 0.6), np.array([math.pi]), sh, 30.0)
    assert r[0] == pytest.approx(5.0 - 0.8, abs=1e-12)
    # from inside the circle the ray hits its far side; a ray that misses returns nothing
    r = cast((-5.0, 0.5), np.array([math.pi / 2, 0.0]), sh, 30.0)
    assert r[0] == pytest.approx(0.5, abs=1e-12)
    r = cast((0.0, 1.01), np.array([math.pi]), sh, 30.0)
    assert math.isinf(r[0])
    # max range: beyond it nothing
    assert math.isinf(cast((0.0, 0.0), np.array([0.0]), sh, 3.9)[0])


def test_clearance_of_footprints_known_distances() -> None:
    sh = Shapes.build([wall_vertices(2.0, -1.0, 2.0, 1.0, 0.1), box_vertices(0.0, -3.0, 1.0, 1.0, 0.0)],
                      [0, 1],
                      [(0.0, 3.0, 0.5)], [2])
    c = footprint_clearance((0.0, 0.0, 0.0), None, 0.3, sh)
    assert c.distance_m == pytest.approx(1.65) and c.element == 0
    assert c.on_robot == pytest.approx((0.3, 0.0)) and c.on_shape == pytest.approx((1.95, 0.0))
    local = np.array([[0.8, -0.35], [0.8, 0.35], [-0.4, 0.35], [-0.4, -0.35]])
    c = footprint_clearance((0.0, 0.0, 0.0), local, 0.0, sh)
    assert c.distance_m == pytest.approx(1.15) and c.element == 0
    c = footprint_clearance((0.0, 1.5, math.pi / 2), local, 0.0, sh)  # front edge at y = 2.3: circle at 2.5
    assert c.distance_m == pytest.approx(0.2) and c.element == 2
    # overlapping (a footprint inside a box) counts as 0
    c = footprint_clearance((0.0, -3.0, 0.0), None, 0.1, sh)
    assert c.distance_m == 0.0 and c.element == 1


def test_arc_step_is_the_exact_circle() -> None:
    p = arc_step(np.zeros(3), 0.5, 0.0, 0.5, 2.0 * math.pi)  # radius 1, half a turn
    np.testing.assert_allclose(p, [0.0, 2.0, math.pi], atol=1e-12)
    p = arc_step(np.array([1.0, 0.0, math.pi / 2]), 0.0, 0.3, 0.0, 2.0)  # holonomic sideways (to -x)
    np.testing.assert_allclose(p, [0.4, 0.0, math.pi / 2], atol=1e-12)


# --------------------------------------------------------------------------------------------- contact


def test_circle_robot_stops_exactly_at_touching_distance() -> None:
    s = spec({"walls": {"wall": [2.0, -2.0, 2.0, 2.0]}})
    loop = drive(s, XR4000, (0.5, 0.0, 0.0), 20.0)
    assert loop.outcome == "collision"
    c = loop.contact
    assert c is not None and c["object"] == "wall" and c["robot_moving"] and not c["hit_by_mover"]
    assert loop.pose[0] == pytest.approx(1.95 - 0.3, abs=2e-4)
    assert c["t_s"] == pytest.approx(1.65 / 0.5, abs=1e-3)
    assert c["contact_world"] == pytest.approx([1.95, 0.0], abs=2e-4)
    assert c["contact_robot"] == pytest.approx([0.3, 0.0], abs=2e-4)


def test_a_fast_robot_does_not_tunnel_through_a_thin_wall() -> None:
    s = spec({"walls": {"thin": [1.0, -2.0, 1.0, 2.0, 0.0]}})
    loop = drive(s, XR4000, (0.5, 0.0, 0.0), 5.0, pose=(0.0, 0.0, 0.0))
    assert loop.outcome == "collision" and loop.pose[0] == pytest.approx(0.7, abs=2e-4)


def test_rectangle_front_edge_touches_a_box_at_its_front_distance() -> None:
    s = spec({"boxes": {"box": [3.0, 0.0, 1.0, 2.0, 0.0]}})
    loop = drive(s, WHEELCHAIR, (0.3, 0.0, 0.0), 20.0)
    assert loop.outcome == "collision" and loop.contact is not None
    assert loop.pose[0] == pytest.approx(2.5 - 0.8, abs=2e-4)
    assert loop.contact["contact_robot"][0] == pytest.approx(0.8, abs=2e-4)
    assert abs(loop.contact["contact_robot"][1]) <= 0.35 + 1e-9


def test_rectangle_turning_in_place_sweeps_its_rear_corner_into_a_wall_behind() -> None:
    # wall face at x = -0.45, 5 cm behind the rear edge; turning left swings the rear-left corner
    # (-0.4, 0.35) outwards: contact when 0.4 cos(a) + 0.35 sin(a) = 0.45
    s = spec({"walls": {"behind": [-0.5, -3.0, -0.5, 3.0]}})
    loop = drive(s, WHEELCHAIR, (0.0, 0.0, 0.5), 5.0)
    r, phi = math.hypot(0.4, 0.35), math.atan2(0.35, 0.4)
    a = phi - math.acos(0.45 / r)
    assert loop.outcome == "collision" and loop.contact is not None
    assert loop.contact["object"] == "behind"
    assert loop.pose[2] == pytest.approx(a, abs=1e-3)
    assert loop.contact["t_s"] == pytest.approx(a / 0.5, abs=2e-3)
    assert loop.contact["contact_robot"] == pytest.approx([-0.4, 0.35], abs=1e-3)
    assert loop.contact["contact_world"][0] == pytest.approx(-0.45, abs=2e-4)
    # turning the other way frees that corner and swings the rear-right one in symmetrically
    loop = drive(s, WHEELCHAIR, (0.0, 0.0, -0.5), 5.0)
    assert loop.pose[2] == pytest.approx(-a, abs=1e-3)
    assert loop.contact is not None
    assert loop.contact["contact_robot"] == pytest.approx([-0.4, -0.35], abs=1e-3)


def test_a_robot_clear_of_everything_reaches_the_goal() -> None:
    s = spec({"walls": {"far": [0.0, 5.0, 10.0, 5.0]}}, goal=[3.0, 0.0])
    loop = drive(s, WHEELCHAIR, (0.3, 0.0, 0.0), 30.0)
    assert loop.outcome == "success"
    assert loop.end_t_s == pytest.approx((3.0 - WHEELCHAIR.supervisor.goal_tolerance_m) / 0.3, abs=0.011)


# --------------------------------------------------------------------------------------------- events, movers


def test_events_appear_remove_slide_and_swing_at_their_times() -> None:
    s = spec({"walls": {"slider": [0.0, 2.0, 2.0, 2.0], "swinger": [5.0, 0.0, 6.0, 0.0, 0.0]}},
             events=[{"at": 1.0, "add": {"circles": {"pop": [0.0, -3.0, 0.5]}}}, {"at": 4.0, "remove": "pop"},
                     {"at": 2.0, "close": "slider", "over": 2.0},
                     {"at": 1.0, "close": "swinger", "over": 1.0, "swing": 90}])
    w = _World(s)
    up = np.array([math.pi / 2])

    def ray(t: float, origin: tuple[float, float], angles: Any) -> Any:
        return cast(origin, angles, w.shapes(t, w.mover_xy), 30.0)

    # the circle exists on [1, 4)
    assert math.isinf(ray(0.99, (0.0, 0.0), -up)[0])
    assert ray(1.0, (0.0, 0.0), -up)[0] == pytest.approx(2.5)
    assert ray(3.99, (0.0, 0.0), -up)[0] == pytest.approx(2.5)
    assert math.isinf(ray(4.0, (0.0, 0.0), -up)[0])
    # the sliding leaf grows from (0, 2): half way at t = 3, so x = 1.5 is covered only after 3.5 s
    assert math.isinf(ray(2.0, (0.5, 0.0), up)[0])
    assert ray(3.0, (0.5, 0.0), up)[0] == pytest.approx(1.95)
    assert math.isinf(ray(3.4, (1.5, 0.0), up)[0])
    assert ray(3.6, (1.5, 0.0), up)[0] == pytest.approx(1.95)
    # the swinging leaf (hinged at (5, 0)) points north when open, east when closed, 45 deg half way
    assert ray(0.0, (4.0, 0.5), np.array([0.0]))[0] == pytest.approx(1.0)
    assert ray(1.5, (5.0, 2.0), np.array([-math.pi / 2]))[0] == pytest.approx(2.0)  # hinge only
    d = ray(1.5, (5.3, 0.0), up)[0]
    assert d == pytest.approx(0.3, abs=1e-9)  # the 45 deg leaf over x = 5.3 at y = 0.3
    assert ray(2.0, (5.5, 1.0), -up)[0] == pytest.approx(1.0)


def test_a_mover_walks_its_path_at_its_speed_from_its_start_time() -> None:
    path = [[5.0, 5.0], [7.0, 5.0], [7.0, 8.0]]
    s = spec({}, movers=[{"id": "p", "radius": 0.2, "speed": 0.5, "path": path,
                          "start_at": 2.0, "yield_m": 0.3}])
    loop = drive(s, WHEELCHAIR, (0.0, 0.0, 0.0), 1.9)
    np.testing.assert_allclose(loop.world.mover_xy[0], [5.0, 5.0])
    loop._advance(round(4.0 * 1e9))  # 2 s walking: 1 m
    np.testing.assert_allclose(loop.world.mover_xy[0], [6.0, 5.0], atol=1e-9)
    loop._advance(round(9.0 * 1e9))  # 3.5 m: round the corner, 1.5 m up
    np.testing.assert_allclose(loop.world.mover_xy[0], [7.0, 6.5], atol=1e-9)
    loop._advance(round(30.0 * 1e9))  # not looping: stays at the end
    np.testing.assert_allclose(loop.world.mover_xy[0], [7.0, 8.0], atol=1e-9)


def test_a_yielding_mover_stops_and_a_blind_one_hits_the_stopped_robot() -> None:
    walk = {"id": "p", "radius": 0.25, "speed": 1.0, "path": [[4.0, 0.0], [-4.0, 0.0]], "start_at": 0.0}
    s = spec({}, movers=[{**walk, "yield_m": 0.3}])
    loop = drive(s, XR4000, (0.0, 0.0, 0.0), 10.0)
    assert loop.outcome is None  # still running: no contact
    gap = math.hypot(*loop.world.mover_xy[0]) - 0.25 - 0.3
    assert 0.3 - 1e-9 <= gap < 0.3 + 0.0101  # waits within one 10 ms step outside its yield distance
    s = spec({}, movers=[{**walk, "yield_m": 0.0}])
    loop = drive(s, XR4000, (0.0, 0.0, 0.0), 10.0)
    assert loop.outcome == "collision" and loop.contact is not None
    assert loop.contact["object"] == "p" and loop.contact["hit_by_mover"] and not loop.contact["robot_moving"]
    assert loop.contact["t_s"] == pytest.approx(4.0 - 0.55, abs=1e-3)


# --------------------------------------------------------------------------------------------- files


@pytest.mark.parametrize(
    ("doc", "key"),
    [
        ({"colour": 1}, "colour"),
        ({"world": {"walls": {"w": [0, 0, 1]}}}, "world.walls.w"),
        ({"world": {"hedges": {}}}, "world.hedges"),
        ({"events": [{"at": 1.0, "remove": "ghost"}]}, "events[0].remove"),
        ({"events": [{"at": 1.0, "close": "w", "over": 1, "speed": 2}]}, "events[0].speed"),
        ({"movers": [{"id": "m", "radius": 0.2, "speed": 1, "path": [[0, 0]], "yeild_m": 1}]},
         "movers[0].yeild_m"),
        ({"time_limit": -1}, "time_limit"),
        ({"preset": "tank"}, "preset"),
    ],
)
def test_a_bad_scenario_names_the_file_and_the_key(doc: dict[str, Any], key: str) -> None:
    base: dict[str, Any] = {"name": "t", "start": [0, 0, 0], "goal": [1, 1], "time_limit": 10,
                            "world": {"walls": {"w": [0, 0, 1, 0]}}}
    base.update(doc)
    with pytest.raises(ConfigError) as err:
        parse_scenario(base, "mine.yaml")
    assert str(err.value).startswith(f"mine.yaml: {key}")
    assert "\n" not in str(err.value)


def test_cli_bad_scenario_exits_2_with_one_line(tmp_path: Path) -> None:
    f = tmp_path / "bad.yaml"
    f.write_text("name: x\nstart: [0, 0, 0]\ngoal: [1, 1]\ntime_limit: 5\nworld: {}\nmovers: [{id: a}]\n")
    r = CliRunner().invoke(app, ["simulate", str(f), "--out", str(tmp_path / "run")])
    assert r.exit_code == 2
    assert r.stderr.strip().count("\n") == 0 and "bad.yaml: movers[0].radius: missing" in r.stderr
    assert not (tmp_path / "run").exists()
    f.write_text("name: [unclosed\n")
    r = CliRunner().invoke(app, ["simulate", str(f)])
    assert r.exit_code == 2 and "bad.yaml: not valid YAML" in r.stderr


def test_cli_list_names_every_shipped_scenario() -> None:
    r = CliRunner().invoke(app, ["simulate", "--list"])
    assert r.exit_code == 0
    names = shipped_scenarios()
    assert len(names) >= 10
    for name in names:
        assert name in r.stdout


# --------------------------------------------------------------------------------------------- runs


def test_same_seed_gives_byte_identical_log_and_result_and_the_log_replays(tmp_path: Path) -> None:
    args = ["simulate", "gnd_fig2_person_crossing", "--seed", "5", "--time-limit", "3", "--no-figures"]
    runner = CliRunner()
    r1 = runner.invoke(app, [*args, "--out", str(tmp_path / "a")])
    r2 = runner.invoke(app, [*args, "--out", str(tmp_path / "b")])
    assert r1.exit_code == 1 and r2.exit_code == 1, r1.output  # a time-out is a failure
    for name in ("log.mcap", "result.json", "commands.csv"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes(), name
    res = json.loads((tmp_path / "a" / "result.json").read_text())
    assert res["outcome"] == "timeout" and res["ticks"] == 20 and res["seed"] == 5
    r3 = runner.invoke(app, [*args[:2], "--seed", "6", "--time-limit", "3", "--no-figures", "--out",
                             str(tmp_path / "c")])
    assert r3.exit_code == 1
    assert (tmp_path / "c" / "log.mcap").read_bytes() != (tmp_path / "a" / "log.mcap").read_bytes()
    # gndreplay run replays the log: same scans, same stack -> (nearly: float32 ranges) the same commands
    r = runner.invoke(app, ["run", str(tmp_path / "a" / "log.mcap"), "--preset", "xr4000", "--goal", "9,0",
                            "--out", str(tmp_path / "replay"), "--no-figures", "-q"])
    assert r.exit_code == 0, r.output
    a = np.genfromtxt(tmp_path / "a" / "commands.csv", delimiter=",", skip_header=1, usecols=(0, 1, 3))
    b = np.genfromtxt(tmp_path / "replay" / "commands.csv", delimiter=",", skip_header=1, usecols=(0, 1, 3))
    assert a.shape == b.shape
    np.testing.assert_allclose(a, b, atol=0.02)


def test_every_shipped_scenario_runs_and_scores(tmp_path: Path) -> None:
    for name in shipped_scenarios():
        out = simulate_scenario(name, out_dir=tmp_path / name, seed=1, time_limit_s=2.0, figures=False)
        res = json.loads((out.out_dir / "result.json").read_text())
        assert res["outcome"] in ("success", "collision", "goal_missed", "timeout")
        assert res["scenario"] == name and res["ticks"] >= 1
        for key in ("path_length_m", "time_inside_security_pct", "mean_abs_dw_dt_radps2", "longest_stall_s"):
            assert isinstance(res[key], float) and math.isfinite(res[key]), key
        assert (out.out_dir / "log.mcap").stat().st_size > 0
        assert out.sim_ms_per_step > 0 and out.stack_ms_per_tick > 0


def test_the_exit_code_follows_the_outcome_and_the_world_is_drawn(tmp_path: Path) -> None:
    f = tmp_path / "box.yaml"  # a user's file: the robot starts 1 cm from a wall
    f.write_text("name: box\npreset: xr4000\nstart: [0, 0, 0]\ngoal: [0, 3]\ntime_limit: 1.5\n"
                 "world: {walls: {w: [-0.36, -2, -0.36, 2]}, circles: {c: [2, 0, 0.3]}}\n")
    r = CliRunner().invoke(app, ["simulate", str(f), "--out", str(tmp_path / "run"), "--json"])
    res = json.loads(r.stdout)
    assert r.exit_code == (0 if res["outcome"] == "success" else 1)
    assert (tmp_path / "run" / "fig_world.png").stat().st_size > 0
    assert load_scenario(f).name == "box"


def test_scenario_lookup_errors_name_the_input(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"no_such: no such scenario file or shipped scenario \(shipped: "):
        resolve_scenario("no_such")
    with pytest.raises(ConfigError, match=r"missing\.yaml: scenario file not found"):
        resolve_scenario(tmp_path / "missing.yaml")
    assert resolve_scenario("u_trap").name == "u_trap"


def arc_ticks(s: Any, cfg: Any, cmd: tuple[float, float, float], n: int, **kw: Any) -> list[Any]:
    """``n + 1`` ticks of a robot driving the constant arc ``cmd`` (the stack left out)."""
    loop = ClosedLoop(s, cfg, seed=3, **kw)
    ticks = loop.ticks()
    out = [next(ticks)]
    loop.vel = loop.cmd = cmd
    for _ in range(n):
        loop.pending = (cmd, loop.t_ns)
        loop._got_command = True
        out.append(next(ticks))
    return out


def test_odometry_drifts_unless_perfect_and_matches_the_truth_at_the_start() -> None:
    s = spec({"walls": {"far": [0.0, 8.0, 30.0, 8.0]}})
    for cfg, cmd in ((WHEELCHAIR, (0.3, 0.0, 0.1)), (XR4000, (0.3, 0.2, 0.1))):
        ticks = arc_ticks(s, cfg, cmd, 50)
        assert ticks[0].odom == ticks[0].truth
        last = ticks[-1]
        err = math.hypot(last.odom.x - last.truth.x, last.odom.y - last.truth.y)
        travelled = math.hypot(last.truth.x, last.truth.y)
        assert travelled > 2.0
        assert 1e-4 < err < 0.05 * travelled  # drifts, but like wheels do: a few percent at most
        last = arc_ticks(s, cfg, cmd, 50, perfect_odometry=True)[-1]
        assert last.odom == last.truth


def test_a_door_leaf_closing_onto_a_robot_in_the_doorway_waits_for_it() -> None:
    # the leaf slides down x = 1 from y = 3 toward y = -3 in 3 s; the robot stands in its way at (1, 0)
    s = spec({"walls": {"leaf": [1.0, 3.0, 1.0, -3.0]}}, events=[{"at": 0.5, "close": "leaf", "over": 3.0}])
    loop = drive(s, XR4000, (0.0, 0.0, 0.0), 10.0, pose=(1.0, 0.0, 0.0))
    assert loop.outcome is None
    assert 0.3 - 1e-9 <= loop.rec.min_clearance_m < 0.3 + 0.021  # a 10 ms step of a 2 m/s leaf tip
    # once the robot is out of the way the leaf closes
    loop.pose = np.array([-2.0, 0.0, 0.0])
    loop._advance(round(20.0 * 1e9))
    w = loop.world
    r = cast((0.0, -2.5), np.array([0.0]), w.shapes(20.0, w.mover_xy), 30.0)
    assert r[0] == pytest.approx(0.95)


def test_longest_stall_known_answer() -> None:
    from gndreplay.sim.closedloop import longest_stall

    t = np.arange(0.0, 20.0001, 0.01)
    poses = np.zeros((len(t), 3))
    # still for 6 s, then 0.1 m/s for 10 s (0.2 m every 2 s), then turning in place at 0.1 rad/s
    poses[:, 0] = np.clip(t - 6.0, 0.0, 10.0) * 0.1
    poses[:, 2] = np.clip(t - 16.0, 0.0, None) * 0.1
    # the longest stretch starts at t = 0 and ends when x reaches 0.2 m, at 8 s; the turn (45 deg takes
    # 7.9 s) is cut by the end of the run after 4 s
    assert longest_stall(t, poses) == pytest.approx(8.0, abs=0.011)


def test_cli_office_still_writes_carmen_logs_only(tmp_path: Path) -> None:
    # `simulate office` keeps its scripted CARMEN path (the sample log); a wrong suffix is refused early
    r = CliRunner().invoke(app, ["simulate", "office", "--out", str(tmp_path / "office.txt")])
    assert r.exit_code == 2 and "simulated logs are written as CARMEN" in r.stderr
    assert not (tmp_path / "office.txt").exists()


# --------------------------------------------------------------------------------------------- review fixes


def test_an_instant_door_action_applies_from_its_time_and_over_defaults_to_zero() -> None:
    s = spec({"walls": {"w": [2.0, -2.0, 2.0, 2.0]}}, events=[{"at": 1.0, "close": "w"},
                                                               {"at": 3.0, "open": "w", "over": 0}])
    leaf = next(e for e in s.elements if e.id == "w")
    assert [(a.t0_s, a.t1_s) for a in leaf.door] == [(1.0, 1.0), (3.0, 3.0)]
    assert [leaf.closed_fraction(t) for t in (0.999, 1.0, 2.0, 2.999, 3.0, 4.0)] == [0, 1, 1, 1, 0, 0]
    # a timed motion still starts at its t0 (0 there) and is interpolated
    slow = spec({"walls": {"w": [2.0, -2.0, 2.0, 2.0]}}, events=[{"at": 1.0, "close": "w", "over": 2.0}])
    e = slow.elements[0]
    assert [e.closed_fraction(t) for t in (1.0, 2.0, 3.0)] == [0.0, 0.5, 1.0]


@pytest.mark.parametrize("delay_s", [0.0, 0.005])
def test_a_door_closing_instantly_ahead_of_a_moving_robot_is_hit(delay_s: float) -> None:
    # the leaf across x = 2 (faces at 1.95 / 2.05) shuts at t = 1 s while the 0.3 m robot drives at
    # 0.5 m/s from x = 0; a far wall keeps the clearance large before: contact at x = 1.65, t = 3.3 s.
    # delay_s > 0: the leaf's step falls off the scenario's break times (as when the person moving a leaf
    # waited); the simulator must see it all the same.
    s = spec({"walls": {"far": [30.0, -5.0, 30.0, 5.0], "w": [2.0, -2.0, 2.0, 2.0]}},
             events=[{"at": 1.0, "close": "w"}])
    loop = ClosedLoop(s, XR4000, seed=0, ideal_dynamics=True)  # the exact motion: a known contact time
    loop.world.door_delay[[e.id for e in s.elements].index("w")] = delay_s
    loop.vel = loop.cmd = (0.5, 0.0, 0.0)
    loop._advance(round(6.0 * 1e9))
    assert loop.outcome == "collision", loop.pose
    c = loop.contact
    assert c is not None and c["object"] == "w" and c["robot_moving"]
    assert c["t_s"] == pytest.approx(3.3, abs=1e-3) and loop.pose[0] == pytest.approx(1.65, abs=2e-4)


def test_a_door_closing_instantly_onto_the_robot_is_a_contact_at_that_time() -> None:
    s = spec({"walls": {"far": [30.0, -5.0, 30.0, 5.0], "w": [1.0, -2.0, 1.0, 2.0]}},
             events=[{"at": 1.0, "close": "w"}])
    loop = drive(s, XR4000, (0.0, 0.0, 0.0), 3.0, pose=(1.0, 0.0, 0.0))
    assert loop.outcome == "collision"
    c = loop.contact
    assert c is not None and c["object"] == "w" and c["t_s"] == 1.0 and c["hit_by_mover"]


@pytest.mark.parametrize("name", ["/tmp/x/abs", "../../../escaped", "a/b", ".hidden", "-opt", "", "a b", 3])
def test_a_scenario_name_must_be_a_plain_name(name: Any) -> None:
    with pytest.raises(ConfigError, match=r"^test\.yaml: name: expected a plain name"):
        spec({"walls": {"w": [2.0, -2.0, 2.0, 2.0]}}, name=name)


def test_cli_a_scenario_name_cannot_escape_the_output_folder(tmp_path: Path, monkeypatch: Any) -> None:
    cwd = tmp_path / "a" / "b" / "c"  # deep enough that even an escaping name stays inside tmp_path
    cwd.mkdir(parents=True)
    monkeypatch.chdir(cwd)
    f = cwd / "esc.yaml"
    f.write_text("name: ../../../escaped\nstart: [0, 0, 0]\ngoal: [1, 0]\ntime_limit: 1\n"
                 "world: {walls: {w: [3, -2, 3, 2]}}\n")
    r = CliRunner().invoke(app, ["simulate", str(f), "--no-figures"])
    assert r.exit_code == 2 and isinstance(r.exception, SystemExit)
    assert "esc.yaml: name: expected a plain name" in r.stderr and "Traceback" not in r.output
    assert sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*")) == [
        "a", "a/b", "a/b/c", "a/b/c/esc.yaml"]


def test_result_flags_are_deterministic_and_match_commands_csv(tmp_path: Path) -> None:
    from gndreplay.config import apply_overrides

    tiny = {f"budget_{m}_s": 1e-6 for m in ("match", "model", "planner", "reactor")}
    cfg = apply_overrides(XR4000, {"supervisor": tiny})
    out = simulate_scenario("u_trap", out_dir=tmp_path / "run", cfg=cfg, seed=0, time_limit_s=1.0,
                            figures=False)
    res = json.loads((out.out_dir / "result.json").read_text())
    timing = (out.out_dir / "timing.csv").read_text()
    assert "OVER_BUDGET" in timing  # the budgets were exceeded (wall clock) ...
    assert not any("OVER_BUDGET" in k for k in res["flags"])  # ... which result.json does not count
    counts: dict[str, int] = {}
    head, *lines = (out.out_dir / "commands.csv").read_text().splitlines()
    col = head.split(",").index("flags")
    for line in lines:
        for name in filter(None, line.split(",")[col].split("|")):
            counts[name] = counts.get(name, 0) + 1
    assert res["flags"] == dict(sorted(counts.items()))


def test_the_run_directory_is_published_with_its_figures_and_report(tmp_path: Path, monkeypatch: Any) -> None:
    import gndreplay.fsutil as fsutil

    seen: list[set[str]] = []
    publish = fsutil.publish_dir

    def spy(tmp: Path, out: Path, **kw: Any) -> None:
        seen.append({p.name for p in Path(tmp).iterdir()})
        publish(tmp, out, **kw)

    monkeypatch.setattr(fsutil, "publish_dir", spy)
    out = simulate_scenario("u_trap", out_dir=tmp_path / "run", seed=0, time_limit_s=0.5, figures=True)
    assert len(seen) == 1
    assert {"report.md", "fig_world.png", "result.json", "log.mcap"} <= seen[0]
    assert seen[0] == {p.name for p in out.out_dir.iterdir()}  # nothing written after publishing


def test_odom_twist_in_the_log_is_the_measured_velocity(tmp_path: Path) -> None:
    from rosbags.highlevel import AnyReader

    # the exact motion model: the body moves as the wheels, so the truth's speed checks the reported one
    out = simulate_scenario("gnd_fig2_person_crossing", out_dir=tmp_path / "run", seed=0, time_limit_s=3.0,
                            figures=False, ideal_dynamics=True)
    odom, truth = [], []
    with AnyReader([out.out_dir / "log.mcap"]) as reader:
        for conn, _, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            if conn.topic == "/odom":
                odom.append(math.hypot(msg.twist.twist.linear.x, msg.twist.twist.linear.y))
            elif conn.topic == "/ground_truth":
                truth.append((msg.pose.position.x, msg.pose.position.y))
    v = np.asarray(odom)
    xy = np.asarray(truth)
    assert v[0] == 0.0 and v.max() > 0.2  # starts at rest, then drives
    # the speed changes monotonically between scans (acceleration-limited toward one command): the mean
    # speed over a scan period lies between the velocities reported at its two ends
    mean = np.hypot(*np.diff(xy, axis=0).T) / 0.15
    lo, hi = np.minimum(v[:-1], v[1:]), np.maximum(v[:-1], v[1:])
    assert np.all((mean >= lo - 2e-3) & (mean <= hi + 2e-3)), np.column_stack([lo, mean, hi])
