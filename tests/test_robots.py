"""Robot presets and the constants that scale with the robot: the compact preset validates and drives a
shipped scenario at 2 m/s, the scaling keys resolve as documented and are range-checked, and the papers'
presets keep their constants."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import pytest

from gndreplay.config import PRESETS, apply_overrides, preset, scaled_to_robot, validate_config
from gndreplay.errors import ConfigError
from gndreplay.pipeline.supervisor import braking_time_s
from gndreplay.sim import simulate_scenario
from gndreplay.sim.scenario_file import parse_scenario

PAPER_PRESETS = ("wheelchair", "xr4000")


def test_compact_preset_is_a_small_fast_differential_base() -> None:
    cfg = validate_config(preset("compact"))
    r, laser = cfg.robot, cfg.laser
    assert r.shape == "rectangle" and r.drive == "differential"
    assert r.front_m + r.rear_m == pytest.approx(0.508) and r.width_m == pytest.approx(0.43)
    assert r.front_m == r.rear_m  # turns about its centre
    assert r.vmax_mps == 2.0
    assert laser.beams == 720 and laser.fov_deg == 270.0
    assert 20.0 <= 1.0 / laser.period_s <= 40.0


def test_every_preset_is_a_scenario_preset() -> None:
    for name in PRESETS:
        doc = {"name": "t", "preset": name, "start": [0.0, 0.0, 0.0], "goal": [5.0, 0.0], "time_limit": 10,
               "world": {"walls": {"w": [0.0, 2.0, 5.0, 2.0]}}}
        assert parse_scenario(doc, "t.yaml").preset == name


@pytest.mark.parametrize("name", PAPER_PRESETS)
def test_paper_presets_keep_the_papers_constants(name: str) -> None:
    cfg = preset(name)
    planner, reactor, sup, follow = scaled_to_robot(cfg)
    assert planner is cfg.planner and reactor is cfg.reactor and sup is cfg.supervisor
    assert follow is cfg.navigation.follow
    stack = cfg.stack_params()
    assert stack.reactor.security_m == 0.5  # the ND+ code's dsmax
    assert stack.planner.lookahead_m == 1.0  # GND's "first metre"
    assert (stack.supervisor.trap_window, stack.supervisor.unreachable_ticks,
            stack.supervisor.escape_ticks) == (40, 25, 10)
    assert not stack.supervisor.brake_lag


def test_compact_constants_scale_with_speed_and_cycle() -> None:
    cfg = preset("compact")
    vmax, period = cfg.robot.vmax_mps, cfg.laser.period_s
    stack = cfg.stack_params()
    assert stack.reactor.security_m == pytest.approx(
        cfg.reactor.security_m + cfg.reactor.security_time_s * vmax)
    assert stack.planner.lookahead_m == pytest.approx(max(1.0, cfg.planner.lookahead_s * vmax))
    assert stack.follow.lookahead_m == pytest.approx(cfg.navigation.follow.lookahead_s * vmax)
    sup = cfg.supervisor
    assert sup.trap_window_s is not None and sup.unreachable_s is not None and sup.escape_s is not None
    assert stack.supervisor.trap_window == round(sup.trap_window_s / period)
    assert stack.supervisor.unreachable_ticks == round(sup.unreachable_s / period)
    assert stack.supervisor.escape_ticks == round(sup.escape_s / period)
    # the scaling keys are cleared once resolved: a section handed on holds the values in force
    assert stack.reactor.security_time_s == 0.0 and stack.supervisor.trap_window_s is None


def test_brake_lag_adds_the_drive_time_constant() -> None:
    cfg = preset("compact")
    on = braking_time_s(1.0, 0.0, 0.5, cfg.robot, cfg.supervisor)
    off = braking_time_s(1.0, 0.0, 0.5, cfg.robot, dataclasses.replace(cfg.supervisor, brake_lag=False))
    assert on - off == pytest.approx(max(cfg.robot.tau_v_s, cfg.robot.tau_w_s))


def test_duration_keys_become_ticks_of_the_laser_period() -> None:
    cfg = apply_overrides(preset("wheelchair"), {"supervisor": {"trap_window_s": 3.0, "escape_s": 0.5},
                                                 "laser": {"period_s": 0.1}})
    sup = cfg.stack_params().supervisor
    assert (sup.trap_window, sup.escape_ticks, sup.unreachable_ticks) == (30, 5, 25)
    # the window never drops below the events that make a trap
    short = apply_overrides(cfg, {"supervisor": {"trap_window_s": 0.1}}).stack_params().supervisor
    assert short.trap_window == cfg.supervisor.trap_count


@pytest.mark.parametrize("table, key", [
    ({"reactor": {"security_time_s": -0.1}}, "reactor.security_time_s"),
    ({"reactor": {"security_time_s": 6.0}}, "reactor.security_time_s"),
    ({"planner": {"lookahead_s": -1.0}}, "planner.lookahead_s"),
    ({"navigation": {"follow": {"lookahead_s": 61.0}}}, "navigation.follow.lookahead_s"),
    ({"supervisor": {"trap_window_s": 0.0}}, "supervisor.trap_window_s"),
    ({"supervisor": {"unreachable_s": -5.0}}, "supervisor.unreachable_s"),
    ({"supervisor": {"escape_s": math.inf}}, "supervisor.escape_s"),
    ({"supervisor": {"brake_lag": 1}}, "supervisor.brake_lag"),
])
def test_scaling_keys_are_range_checked(table: dict[str, object], key: str) -> None:
    with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
        apply_overrides(preset("wheelchair"), table)


def test_compact_reaches_the_goal_of_a_shipped_scenario_at_2_mps(tmp_path: Path) -> None:
    cfg = preset("compact")
    out = simulate_scenario("gnd_exp1_three_traps", out_dir=tmp_path / "run", cfg=cfg, seed=0, figures=False,
                            time_limit_s=40.0)
    assert out.outcome == "success"
    # it drove as fast as the base allows: the straight stretches at 2 m/s
    assert out.path_length_m / out.time_to_goal_s > cfg.robot.vmax_mps / 2.0
