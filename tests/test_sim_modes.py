"""Navigation modes in the closed loop (issue 14): scenario keys (mode, local, subgoals, teleop), the scripted
operator whose command becomes ``Tick.cmd``, the success rules of teleop and follow runs, and the must-shows:
a careless driver saved by the mode selector (and crashing without it), and the paper's Fig. 7."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from gndreplay.config import apply_overrides, preset
from gndreplay.errors import ConfigError
from gndreplay.pipeline.nd import Situation
from gndreplay.pipeline.stack import TickResult
from gndreplay.sim import ClosedLoop, resolve_scenario, simulate_scenario
from gndreplay.sim.closedloop import navigation_config
from gndreplay.sim.scenario_file import parse_scenario
from gndreplay.sim.teleop import TeleopDriver, TeleopSpec
from gndreplay.types import Command, Flag, Mode, Tick

WHEELCHAIR = preset("wheelchair")
HALL = {"walls": {"n": [-2.0, 3.0, 13.0, 3.0], "s": [-2.0, -3.0, 13.0, -3.0]}}


def spec(**kw: Any) -> Any:
    doc: dict[str, Any] = {"name": "t", "start": [0.0, 0.0, 0.0], "time_limit": 60, "world": HALL}
    doc.update(kw)
    return parse_scenario(doc, "modes.yaml")


def echo(tick: Tick, *, desired: str = "teleop", active: str = "teleop", reason: str = "",
         subgoal: int = -1, flags: Flag = Flag.NONE) -> TickResult:
    """What a stack passing the operator's command straight out would return."""
    assert tick.cmd is not None and tick.truth is not None
    return TickResult(tick.t_ns, tick.truth, Command(tick.t_ns, tick.cmd.v_mps, tick.cmd.w_radps), Mode.MPND,
                      Situation.NONE, flags, math.nan, (0.0, 0.0), np.zeros((0, 2)), desired_mode=desired,
                      active_mode=active, takeover_reason=reason, subgoal_index=subgoal)


def run_echo(loop: ClosedLoop, **kw: Any) -> list[Tick]:
    ticks = []
    for tick in loop.ticks():
        ticks.append(tick)
        loop.on_tick(echo(tick, **kw))
    return ticks


# --------------------------------------------------------------------------------------------- the file


@pytest.mark.parametrize(
    ("doc", "key"),
    [
        ({"mode": "drive", "goal": [1, 0]}, "mode"),
        ({"local": "wander", "goal": [1, 0]}, "local"),
        ({"goal": [1, 0], "subgoals": [[1, 0, 0, "stop"]]}, "subgoals"),
        ({"mode": "follow", "goal": [1, 0]}, "subgoals"),
        ({"mode": "follow", "subgoals": [[1, 0, 0, "halt"]]}, "subgoals[0]"),
        ({"mode": "follow", "subgoals": [[1, 0]]}, "subgoals[0]"),
        ({"goal": [1, 0], "teleop": {"commands": [[0, 0.1, 0], [1, 0, 0]]}}, "teleop"),
        ({"mode": "teleop", "goal": [1, 0]}, "teleop"),
        ({"mode": "teleop", "goal": [1, 0], "teleop": {}}, "teleop"),
        ({"mode": "teleop", "goal": [1, 0], "teleop": {"joystick": 1}}, "teleop.joystick"),
        ({"mode": "teleop", "goal": [1, 0], "teleop": {"commands": [[0, 0.1, 0], [1, 0.1, 0]]}},
         "teleop.commands[1]"),
        ({"mode": "teleop", "goal": [1, 0], "teleop": {"commands": [[1, 0.1, 0], [1, 0, 0]]}},
         "teleop.commands"),
        ({"mode": "teleop", "goal": [1, 0], "teleop": {"commands": [[0, 0.1], [1, 0, 0]]}},
         "teleop.commands[0]"),
        ({"mode": "teleop", "teleop": {"track": {"points": [[0, 0]], "speed": 0.3}}}, "teleop.track.points"),
        ({"mode": "teleop", "teleop": {"track": {"points": [[0, 0], [1, 0]], "speed": 0}}},
         "teleop.track.speed"),
        ({"mode": "teleop", "teleop": {"track": {"points": [[0, 0], [1, 0]]}}}, "teleop.track.speed"),
        ({"mode": "teleop", "teleop": {"track": {"points": [[0, 0], [0, 0]], "speed": 0.3}}},
         "teleop.track.points"),
        ({"mode": "teleop", "teleop": {"commands": [[0, 0.1, 0], [1, 0, 0]]}}, "goal"),
        ({}, "goal"),
    ],
)
def test_a_bad_navigation_key_names_the_file_and_the_key(doc: dict[str, Any], key: str) -> None:
    with pytest.raises(ConfigError) as err:
        spec(**doc)
    assert str(err.value).startswith(f"modes.yaml: {key}")
    assert "\n" not in str(err.value)


def test_the_goal_defaults_to_the_last_subgoal_or_the_track_end() -> None:
    s = spec(mode="follow", subgoals=[[2, 0, 0, "forward"], [4, 1, 1.5, "stop"]])
    assert s.goal == (4.0, 1.0) and [g.kind for g in s.subgoals] == ["forward", "stop"]
    assert s.subgoals[1].theta == 1.5
    s = spec(mode="teleop", teleop={"track": {"points": [[0, 0], [3, 1], [6, 1]], "speed": 0.3}})
    assert s.goal == (6.0, 1.0) and s.teleop is not None and s.teleop.kind == "track"
    assert s.mode == "teleop" and s.local is None


def test_the_scenario_mode_overrides_the_config_and_a_mode_needs_its_inputs() -> None:
    s = spec(mode="teleop", local="free-space", teleop={"commands": [[0, 0.2, 0], [2, 0, 0]]}, goal=[5, 0])
    cfg = navigation_config(s, apply_overrides(WHEELCHAIR, {"navigation": {"mode": "follow",
                                                                            "selector": False}}))
    assert (cfg.navigation.mode, cfg.navigation.local.strategy, cfg.navigation.selector) == (
        "teleop", "free-space", False)  # the selector flag comes from the config (the CLI)
    plain = spec(goal=[5, 0])
    assert navigation_config(plain, WHEELCHAIR).navigation.mode == "gnd"
    for mode, key in (("teleop", "teleop"), ("follow", "subgoals")):
        cfg = apply_overrides(WHEELCHAIR, {"navigation": {"mode": mode}})
        with pytest.raises(ConfigError, match=rf"^modes\.yaml: {key}: missing"):
            ClosedLoop(plain, cfg, seed=0)


# --------------------------------------------------------------------------------------------- the operator


def test_a_script_is_piecewise_constant_and_becomes_tick_cmd() -> None:
    s = spec(mode="teleop", goal=[5, 0], teleop={"commands": [[0.5, 0.2, 0.0], [1.5, 0.1, 0.3], [3.0, 0, 0]]})
    loop = ClosedLoop(s, WHEELCHAIR, seed=0)
    ticks = run_echo(loop)
    t = np.array([(k.t_ns - ticks[0].t_ns) / 1e9 for k in ticks])
    cmd = np.array([(k.cmd.v_mps, k.cmd.w_radps) for k in ticks if k.cmd is not None])
    want = np.select([t < 0.5, t < 1.5, t < 3.0], [0.0, 0.2, 0.1], 0.0)
    np.testing.assert_allclose(cmd[:, 0], want)
    np.testing.assert_allclose(cmd[:, 1], np.where((t >= 1.5) & (t < 3.0), 0.3, 0.0))
    res = loop.result()
    # the script's time is the end: success at the first instant at or after 3 s, nothing touched
    assert res["outcome"] == "success" and res["end_time_s"] == pytest.approx(3.0, abs=0.011)
    assert res["navigation"]["teleop"] == "script" and res["active_modes"] == {"teleop": len(ticks)}
    assert res["takeovers"] == 0


def test_the_track_driver_pursues_the_polyline_on_the_true_pose() -> None:
    track = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 4.0]])
    d = TeleopDriver(TeleopSpec(track=track, speed_mps=0.3), wmax_radps=0.5, accel_mps2=0.5, tolerance_m=0.3)
    v, w = d.command(0.0, np.array([0.0, 0.0, 0.0]))
    assert (v, w) == (pytest.approx(0.3), pytest.approx(0.0))
    v, w = d.command(0.0, np.array([1.0, 0.2, 0.0]))  # left of the line: steer right, back onto it
    assert v > 0.0 and w < 0.0
    v, w = d.command(0.0, np.array([2.0, 0.0, 0.75 * math.pi]))  # facing away: the tightest turn it can
    assert w == pytest.approx(-0.5) and 0.0 < v < 0.3
    v, w = d.command(0.0, np.array([3.9, 0.0, 0.0]))  # the corner ahead: turn left
    assert w > 0.0
    assert not d.ended(0.0, np.array([3.9, 0.0, 0.0]))
    assert d.command(0.0, np.array([4.0, 3.8, 0.5 * math.pi])) == (0.0, 0.0)
    assert d.ended(0.0, np.array([4.0, 3.8, 0.5 * math.pi]))


def test_a_careless_driver_alone_ends_the_track_in_a_free_hall_and_hits_the_cabinet_otherwise() -> None:
    free = spec(mode="teleop", teleop={"track": {"points": [[0, 0], [6, 0]], "speed": 0.5}})
    loop = ClosedLoop(free, WHEELCHAIR, seed=3)
    run_echo(loop)
    res = loop.result()
    assert res["outcome"] == "success"
    assert res["final_goal_distance_m"] <= WHEELCHAIR.supervisor.goal_tolerance_m
    assert res["collision"] is None and abs(res["final_pose"][1]) < 0.05
    shipped = resolve_scenario("teleop_into_wall")
    loop = ClosedLoop(shipped, WHEELCHAIR, seed=3)
    run_echo(loop)
    res = loop.result()
    assert res["outcome"] == "collision" and res["collision"]["object"] == "cabinet"


def test_takeovers_and_mode_stretches_are_counted_from_the_tick_results() -> None:
    s = spec(mode="teleop", goal=[5, 0], teleop={"commands": [[0.0, 0.1, 0.0], [4.0, 0, 0]]})
    loop = ClosedLoop(s, WHEELCHAIR, seed=0)
    pattern = ["teleop", "local", "local", "teleop", "teleop", "local"]
    for k, tick in enumerate(loop.ticks()):
        active = pattern[k % len(pattern)]
        loop.on_tick(echo(tick, active=active, reason="swept area occupied" if active == "local" else ""))
    res = loop.result()
    n = res["ticks"]
    assert n == 20 and res["active_modes"] == {"local": 10, "teleop": 10}
    assert res["takeovers"] == 7 and res["navigation"]["takeover_reasons"] == {"swept area occupied": 7}
    stretches = res["navigation"]["mode_stretches"]
    assert [m for m, _, _ in stretches[:4]] == ["teleop", "local", "teleop", "local"]
    assert stretches[1][1:] == [pytest.approx(0.2), pytest.approx(0.4)]


@pytest.mark.parametrize("report", ["index", "flag"])
def test_a_follow_run_ends_when_the_stack_reports_the_final_subgoal(report: str) -> None:
    s = spec(mode="follow", subgoals=[[1, 0, 0, "forward"], [2, 0, 0, "stop"]])
    loop = ClosedLoop(s, WHEELCHAIR, seed=0)
    for k, tick in enumerate(loop.ticks()):
        index = min(k // 3, 2 if report == "index" else 1)
        flags = Flag.GOAL_REACHED if report == "flag" and k == 6 else Flag.NONE
        loop.on_tick(echo(tick, desired="follow", active="follow", subgoal=index, flags=flags))
    res = loop.result()
    assert res["outcome"] == "success" and res["ticks"] == 7 and res["end_time_s"] == pytest.approx(1.2)
    assert res["navigation"]["subgoal_index"] == (2 if report == "index" else 1)
    assert res["navigation"]["subgoals"] == 2


def test_result_json_of_a_teleop_run_holds_the_mode_counts(tmp_path: Path) -> None:
    out = simulate_scenario("teleop_into_wall", out_dir=tmp_path / "r", seed=0, time_limit_s=1.0,
                            figures=False)
    assert out.result["navigation"]["mode"] == "teleop" and out.ticks >= 1
    assert sum(out.active_modes.values()) == out.ticks and out.takeovers >= 0


# --------------------------------------------------------------------------------------------- must-shows


def stretches(res: dict[str, Any]) -> list[str]:
    return [m for m, _, _ in res["navigation"]["mode_stretches"]]


@pytest.mark.parametrize(("preset_name", "seed"), [("wheelchair", 0), ("wheelchair", 1), ("xr4000", 0)])
def test_the_mode_selector_saves_a_careless_driver(tmp_path: Path, preset_name: str, seed: int) -> None:
    out = simulate_scenario("teleop_into_wall", out_dir=tmp_path / "run", cfg=preset(preset_name), seed=seed,
                            figures=False)
    res = out.result
    assert res["collision"] is None, res["collision"]
    assert out.takeovers >= 1 and out.active_modes.get("local", 0) >= 1
    assert all(r.startswith("teleop") for r in res["navigation"]["takeover_reasons"])
    # the track's end beyond the cabinet, not a safe stand-still in front of it
    assert out.outcome == "success", (out.outcome, out.takeovers, out.active_modes, res["final_pose"])
    assert stretches(res)[0] == "teleop" and stretches(res)[-1] == "teleop"  # the driver ends it


@pytest.mark.parametrize("preset_name", ["wheelchair", "xr4000"])
def test_the_same_driver_without_the_mode_selector_hits_the_cabinet(tmp_path: Path, preset_name: str) -> None:
    cfg = apply_overrides(preset(preset_name), {"navigation": {"selector": False}})
    out = simulate_scenario("teleop_into_wall", out_dir=tmp_path / "run", cfg=cfg, seed=0, figures=False)
    assert out.outcome == "collision" and out.collision is not None
    assert out.collision["object"] == "cabinet" and out.collision["robot_moving"]
    assert out.takeovers == 0 and out.active_modes == {"teleop": out.ticks}


@pytest.mark.parametrize("seed", [0, 1])
def test_path_following_deviates_round_an_unknown_box_and_resumes(tmp_path: Path, seed: int) -> None:
    """The multi-loop paper's Fig. 7."""
    out = simulate_scenario("follow_unknown_obstacle", out_dir=tmp_path / "run", seed=seed, figures=False)
    res = out.result
    assert res["collision"] is None, res["collision"]
    assert out.outcome == "success" and res["navigation"]["subgoals"] == 4
    modes = stretches(res)
    first_local = modes.index("local")
    assert "follow" in modes[first_local:]  # following resumed after local navigation
    assert modes[-1] == "follow"
    # the stack's report agrees with the truth: the true axle at the final stop subgoal, with its heading
    assert res["final_goal_distance_m"] <= WHEELCHAIR.supervisor.goal_tolerance_m
    assert abs(res["final_pose"][2]) < math.radians(10.0)


# ------------------------------------------------------------------------------------ goal_missed (issue 10)


def creep_to_goal(loop: ClosedLoop, error_m: float) -> None:
    """A scripted GND stack whose corrected pose is the truth plus ``error_m`` along x: it creeps towards
    the goal at 0.05 m/s and stops with GOAL_REACHED once its *believed* pose is within the tolerance."""
    for tick in loop.ticks():
        assert tick.truth is not None
        believed = tick.truth.x + error_m
        at_goal = math.hypot(loop.goal[0] - believed, loop.goal[1] - tick.truth.y) <= loop.goal_tol
        r = echo(tick, desired="gnd", active="gnd", flags=Flag.GOAL_REACHED if at_goal else Flag.NONE)
        loop.on_tick(dataclasses.replace(r, command=Command(tick.t_ns, 0.0 if at_goal else 0.05, 0.0),
                                         mode=Mode.GOAL if at_goal else Mode.MPND))


@pytest.mark.parametrize(("error_m", "outcome"), [(0.05, "goal_missed"), (-0.05, "success")])
def test_a_stack_stopping_short_of_the_goal_is_goal_missed(error_m: float, outcome: str) -> None:
    # the stack believes it is 5 cm further on (stops 0.35 m short) or 5 cm behind (reaches 0.25 m)
    # the exact motion model: the robot stops where the scripted stack stops it
    loop = ClosedLoop(spec(start=[2.0, 0.0, 0.0], goal=[3.0, 0.0]), WHEELCHAIR, seed=0, perfect_odometry=True,
                      ideal_dynamics=True)
    creep_to_goal(loop, error_m)
    res = loop.result()
    assert res["outcome"] == outcome
    assert res["end_time_s"] < 30.0  # well before the 60 s limit: nothing waited out the time
    d = res["final_goal_distance_m"]
    if outcome == "success":
        assert d <= loop.goal_tol and res["goal_missed"] is None
        assert res["time_to_goal_s"] == res["end_time_s"]
        return
    miss = res["goal_missed"]
    assert 0.33 < d < 0.37 and miss["true_distance_m"] == d and miss["tolerance_m"] == loop.goal_tol
    assert res["time_to_goal_s"] is None
    # it ended one settle time after the robot came to rest with the stack reporting the goal
    assert miss["stack_goal_reached_s"] <= miss["stopped_s"]
    assert res["end_time_s"] == pytest.approx(miss["stopped_s"] + loop.params.goal_settle_s, abs=0.21)
