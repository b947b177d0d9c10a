"""Run configuration: frozen sections per stage, presets, and TOML loading with validation.

Stage-specific parameter dataclasses live next to the code that uses them (model, scanmatch, planners, nd,
supervisor) so a stage receives only its own section; this module composes them into one ``Config``,
owns the presets (case-insensitive names) and the TOML loader (unknown keys and wrong types are errors
naming the key and file), and holds the physical range of every numeric setting in one table, ``RANGES``,
plus the constraints between fields, ``CROSS_CHECKS``: every loaded configuration is checked against both
(``[robot] vmax_mps = -1`` -> "cfg.toml: robot.vmax_mps must be in (0, 10], got -1.0"). The file is read
through :mod:`gndreplay.io.userfile` (a regular file of at most 1 MB, nesting bounded), and each number
goes through ``userfile.check_number`` with its range as it is read, before any section is built from it.
"""

from __future__ import annotations

import dataclasses
import json
import math
import tomllib
import types
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, Union, get_args, get_origin, get_type_hints

from .errors import ConfigError, did_you_mean
from .io.base import MAX_BEAMS
from .io.userfile import brief, check_number, load_toml
from .pipeline.follow import FollowParams
from .pipeline.local import LOCAL_STRATEGIES, LocalParams
from .pipeline.model import GRID_400, GridParams
from .pipeline.nd import NdParams
from .pipeline.nf1 import Nf1Params
from .pipeline.planner import RouteParams
from .pipeline.planners import PLANNERS, PlannerParams
from .pipeline.stack import NAV_MODES, StackParams
from .pipeline.supervisor import SupervisorParams
from .pipeline.tunnel import TunnelParams
from .robot import (
    COMPACT_LASER,
    COMPACT_ROBOT,
    WHEELCHAIR_LASER,
    WHEELCHAIR_ROBOT,
    XR4000_LASER,
    XR4000_ROBOT,
    LaserConfig,
    RobotConfig,
)
from .scanmatch import METHODS as MATCHER_METHODS
from .scanmatch import IdcParams, KissParams

__all__ = [
    "CROSS_CHECKS",
    "NO_OVERRIDES",
    "PRESETS",
    "RANGES",
    "CliOverrides",
    "Config",
    "CspaceConfig",
    "LaserConfig",
    "NavigationConfig",
    "Range",
    "RobotConfig",
    "ScanMatchConfig",
    "apply_cli",
    "apply_overrides",
    "check_local_option",
    "choose",
    "config_to_dict",
    "config_to_toml",
    "configure",
    "load_config",
    "local_strategy_used",
    "navigation_choices",
    "numeric_fields",
    "parse_set",
    "preset",
    "range_of",
    "scaled_to_robot",
    "validate_config",
]


@dataclass(frozen=True, slots=True)
class CspaceConfig:
    """How the planner's configuration space is made from the grid.

    Attributes:
        margin_m: added to the robot's inner radius when dilating obstacles [m].
        unknown_is_free: plan through UNKNOWN cells (**choice**, GND: the environment is discovered as the
            robot goes).
    """

    margin_m: float = 0.05
    unknown_is_free: bool = True


@dataclass(frozen=True, slots=True)
class NavigationConfig:
    """The multi-loop architecture: which mode is desired, whether the mode selector arbitrates, and the
    local navigation and path following settings.

    Attributes:
        mode: "gnd" (the default: GND to the goal), "teleop" (the recorded or scripted velocity commands),
            "follow" (path following of subgoals), "local" (local navigation alone).
        selector: the mode selector: the desired mode's command wins unless the area it sweeps is occupied,
            then local navigation wins for that tick. False: the desired command goes out unchanged.
        selector_margin_m: the mode selector's tolerance [m]: the desired command's swept area counts as
            occupied when an obstacle comes within this much more than the reflexive loop's
            emergency_margin_m (**choice**: 0.05 m; the paper estimates the area "within certain
            tolerances"), so local navigation takes over before the emergency brake would fire.
        cmd_timeout_s: a teleoperation command older than this at the tick's time is no command: stand
            still ("teleop: command stale"; **choice**: 0.5 s, a few command periods of a joystick).
        selector_hold_s: after a takeover, local navigation keeps the robot until the desired command's
            swept area has been clear for this long (and while that command moves); 0 is the paper's rule
            tick by tick ("as soon as the locally desired path is free"), which hands back for single
            ticks round an obstacle (``selector.arbitrate``; **choice**: 0.6 s, three 5 Hz ticks). After
            a blind side turn first, the hold also lasts until local navigation made its way
            (``selector.look_hold``), whatever this setting.
        local: local navigation ([navigation.local]).
        follow: path following ([navigation.follow]).
    """

    mode: Literal["gnd", "teleop", "follow", "local"] = "gnd"
    selector: bool = True
    selector_margin_m: float = 0.05
    cmd_timeout_s: float = 0.5
    selector_hold_s: float = 0.6
    local: LocalParams = LocalParams()
    follow: FollowParams = FollowParams()


@dataclass(frozen=True, slots=True)
class ScanMatchConfig:
    """Which matcher corrects odometry, and its settings."""

    method: Literal["idc", "kiss-icp", "odom"] = "idc"
    idc: IdcParams = IdcParams()
    kiss: KissParams = KissParams()


@dataclass(frozen=True, slots=True)
class Config:
    """The resolved configuration of a run: one frozen section per stage (pickles for batch workers)."""

    preset: str = "wheelchair"
    robot: RobotConfig = WHEELCHAIR_ROBOT
    laser: LaserConfig = WHEELCHAIR_LASER
    grid: GridParams = GRID_400
    cspace: CspaceConfig = CspaceConfig()
    planner: PlannerParams = PlannerParams()
    reactor: NdParams = NdParams()
    supervisor: SupervisorParams = SupervisorParams()
    scanmatch: ScanMatchConfig = ScanMatchConfig()
    navigation: NavigationConfig = NavigationConfig()

    def stack_params(self) -> StackParams:
        """The sections the navigation stack needs, with the constants that scale with the robot resolved
        (``scaled_to_robot``)."""
        planner, reactor, supervisor, follow = scaled_to_robot(self)
        return StackParams(
            robot=self.robot,
            grid=self.grid,
            planner=planner,
            reactor=reactor,
            supervisor=supervisor,
            cspace_margin_m=self.cspace.margin_m,
            unknown_is_free=self.cspace.unknown_is_free,
            nav_mode=self.navigation.mode,
            selector=self.navigation.selector,
            selector_margin_m=self.navigation.selector_margin_m,
            cmd_timeout_s=self.navigation.cmd_timeout_s,
            selector_hold_s=self.navigation.selector_hold_s,
            local=self.navigation.local,
            follow=follow,
        )


def _ticks(duration_s: float | None, ticks: int, period_s: float, least: int = 1) -> int:
    """``ticks``, or ``duration_s`` in ticks of ``period_s`` (at least ``least``) when given."""
    return ticks if duration_s is None else max(least, round(duration_s / period_s))


def scaled_to_robot(cfg: Config) -> tuple[PlannerParams, NdParams, SupervisorParams, FollowParams]:
    """The planner, reactor, supervisor and path-following sections with the robot-scaled keys resolved.

    The papers' constants assumed a slow chair on a 5 Hz cycle; these keys scale them with the robot
    (docs/robots.md). Each resolved value is written into its fixed key and the scaling key cleared, so a
    section handed on holds the values in force:

    * ``planner.lookahead_m`` and ``navigation.follow.lookahead_m``: at least ``lookahead_s * vmax_mps``;
    * ``reactor.security_m``: plus ``security_time_s * vmax_mps``;
    * ``supervisor.trap_window`` / ``unreachable_ticks`` / ``escape_ticks``: from ``trap_window_s`` /
      ``unreachable_s`` / ``escape_s`` in ticks of ``laser.period_s`` when given.

    With the scaling keys at their defaults (0, None) every section is returned unchanged.
    """
    vmax, period = cfg.robot.vmax_mps, cfg.laser.period_s
    planner, reactor, sup = cfg.planner, cfg.reactor, cfg.supervisor
    follow = cfg.navigation.follow
    if planner.lookahead_s > 0.0:
        ahead = max(planner.lookahead_m, planner.lookahead_s * vmax)
        planner = dataclasses.replace(planner, lookahead_m=ahead, lookahead_s=0.0)
    if follow.lookahead_s > 0.0:
        follow = dataclasses.replace(follow, lookahead_m=max(follow.lookahead_m, follow.lookahead_s * vmax),
                                     lookahead_s=0.0)
    if reactor.security_time_s > 0.0:
        reactor = dataclasses.replace(reactor, security_m=reactor.security_m + reactor.security_time_s * vmax,
                                      security_time_s=0.0)
    if (sup.trap_window_s, sup.unreachable_s, sup.escape_s) != (None, None, None):
        sup = dataclasses.replace(
            sup, trap_window=_ticks(sup.trap_window_s, sup.trap_window, period, sup.trap_count),
            unreachable_ticks=_ticks(sup.unreachable_s, sup.unreachable_ticks, period),
            escape_ticks=_ticks(sup.escape_s, sup.escape_ticks, period),
            trap_window_s=None, unreachable_s=None, escape_s=None)
    return planner, reactor, sup, follow


PRESETS: dict[str, Config] = {
    # the wheelchair paper: 1.2 x 0.7 m, differential drive, laser 0.72 m ahead of the axle,
    # (vmax, wmax) = (0.3 m/s, 0.5 rad/s), 400 x 400 x 0.05 m grid, time-outs 0.05 / 0.08 / 0.02 s
    "wheelchair": Config(),
    # GND on the Nomadic XR4000: circular holonomic base, 5 cm cells. Grid 20 x 20 m (**choice**, sized for
    # its speed; GND used 10 x 10 m): the robot stays in the central quarter, so the grid reaches at least
    # 3/8 of its side around it. 10 m gives 3.75 m, 7.5 s at 0.5 m/s (the chair's 20 m grid: 7.5 m, 25 s at
    # 0.3 m/s); 20 m gives 7.5 m, 15 s, and nearly holds the free space a no-return clears (grid.free_clip_m,
    # 8 m) from anywhere in the zone. Braking (0.08 m from 0.5 m/s at 1.5 m/s^2) is far below either.
    # Cost on ACES (xr4000, goal 5 m ahead, median per tick): planner 0.29 -> 0.61 ms, stack 0.75 -> 1.20 ms.
    "xr4000": Config(preset="xr4000", robot=XR4000_ROBOT, laser=XR4000_LASER, grid=GRID_400),
    # a small fast differential base (docs/robots.md): 0.508 x 0.43 m, 2 m/s, a 270 deg laser at 20 Hz.
    # The papers' slow-chair constants scaled with speed (**choice** each): Ds 0.2 m + 0.2 s * vmax (0.6 m
    # at 2 m/s), half of it behind (ND+'s perimeter needs Ds - rear Ds below the 0.508 m length); the
    # look-ahead 1 s of
    # travel (2 m); trap window 8 s, unreachable 5 s, escape 2 s at 0.15 vmax (0.6 m, the escape
    # clearance) as the chair's 40 / 25 / 10 ticks at 5 Hz; the braking horizon includes the drive's lag.
    # Grid 20 m (7.5 m, 3.75 s at 2 m/s to the zone's edge; braking from 2 m/s takes 1 m).
    "compact": Config(
        preset="compact", robot=COMPACT_ROBOT, laser=COMPACT_LASER, grid=GRID_400,
        planner=PlannerParams(lookahead_s=1.0),
        reactor=NdParams(security_m=0.2, security_time_s=0.2, security_rear_ratio=0.5),
        supervisor=SupervisorParams(trap_window_s=8.0, unreachable_s=5.0, escape_s=2.0, escape_v_frac=0.15,
                                    brake_lag=True),
        navigation=NavigationConfig(follow=FollowParams(lookahead_s=1.0)),
    ),
}


def _preset_key(name: str) -> str:
    """Preset names are case-insensitive (``XR4000`` is ``xr4000``)."""
    return name.strip().lower()


def preset(name: str) -> Config:
    """A named preset (any case); ConfigError lists the known names."""
    try:
        return PRESETS[_preset_key(name)]
    except KeyError:
        raise ConfigError(f"unknown preset {brief(name)}{did_you_mean(name, PRESETS)}; known: "
                          f"{', '.join(sorted(PRESETS))}") from None


# --------------------------------------------------------------------------------------------------
# Physical ranges: one table for every numeric field of every section (a test checks none is missing)


@dataclass(frozen=True, slots=True)
class Range:
    """Allowed values of a numeric setting: ``lo`` to ``hi``, each end closed unless ``*_open``.

    Both ends are finite, so nan and inf are always refused.
    """

    lo: float
    hi: float
    lo_open: bool = False
    hi_open: bool = False

    def __contains__(self, value: float) -> bool:
        above = value > self.lo if self.lo_open else value >= self.lo
        below = value < self.hi if self.hi_open else value <= self.hi
        return bool(above and below)

    def __str__(self) -> str:
        return f"{'(' if self.lo_open else '['}{_num(self.lo)}, {_num(self.hi)}{')' if self.hi_open else ']'}"


def _num(x: float) -> str:
    """A range end as written in a config file: ``250``, ``0.001``, ``6.28319``."""
    return str(int(x)) if x == int(x) and abs(x) < 1e15 else f"{x:g}"


def _pos(hi: float) -> Range:
    """(0, hi]: a strictly positive quantity (speed, size, time)."""
    return Range(0.0, hi, lo_open=True)


def _nonneg(hi: float) -> Range:
    """[0, hi]: a quantity that may be zero (margin, tolerance, distance that disables a feature)."""
    return Range(0.0, hi)


def _count(lo: int = 1, hi: int = 1_000_000) -> Range:
    """An integer count in [lo, hi]."""
    return Range(lo, hi)


_UNIT = Range(0.0, 1.0)  # probabilities, ratios and fractions
_FRAC = _pos(1.0)  # fractions that must not be zero (a zero speed fraction would never move)
_TURN = _pos(2.0 * math.pi)  # an angle magnitude up to a full turn
_ANGLE = Range(-2.0 * math.pi, 2.0 * math.pi)  # a signed angle
_LEN = 100.0  # [m] no robot-scale length, gate or tolerance is longer
_RANGE_M = 1000.0  # [m] no 2D laser reaches further
_TIME = 60.0  # [s] per-tick budgets and periods

#: (section dataclass, field) -> allowed values; applied by the loader to every resolved config.
RANGES: dict[tuple[type, str], Range] = {
    # robot: a footprint of at most 10 m, speeds and accelerations of a ground robot
    (RobotConfig, "radius_m"): _pos(10.0),
    (RobotConfig, "width_m"): _pos(10.0),
    (RobotConfig, "front_m"): _nonneg(10.0),
    (RobotConfig, "rear_m"): _nonneg(10.0),
    (RobotConfig, "vmax_mps"): _pos(10.0),
    (RobotConfig, "wmax_radps"): _pos(20.0),
    (RobotConfig, "accel_mps2"): _pos(50.0),
    (RobotConfig, "alpha_radps2"): _pos(100.0),
    (RobotConfig, "tau_v_s"): _nonneg(5.0),
    (RobotConfig, "tau_w_s"): _nonneg(5.0),
    (RobotConfig, "laser_x_m"): Range(-10.0, 10.0),
    (RobotConfig, "laser_y_m"): Range(-10.0, 10.0),
    (RobotConfig, "laser_theta_rad"): _ANGLE,
    (LaserConfig, "beams"): _count(2, MAX_BEAMS),
    (LaserConfig, "fov_deg"): _pos(360.0),
    (LaserConfig, "max_range_m"): _pos(_RANGE_M),
    (LaserConfig, "noise_std_m"): _nonneg(10.0),
    (LaserConfig, "dropout_prob"): Range(0.0, 1.0, hi_open=True),
    (LaserConfig, "period_s"): _pos(_TIME),
    # grid: 4 to 4000 cells a side (4000^2 cells and the planner's float arrays still fit in memory)
    (GridParams, "size_cells"): _count(4, 4000),
    (GridParams, "cell_m"): Range(0.001, 10.0),
    (GridParams, "control_zone_m"): _nonneg(10_000.0),
    (GridParams, "free_clip_m"): _nonneg(_RANGE_M),
    (CspaceConfig, "margin_m"): _nonneg(10.0),
    (RouteParams, "lookahead_m"): _pos(_LEN),
    (RouteParams, "lookahead_s"): _nonneg(_TIME),
    (RouteParams, "route_keep_ratio"): Range(0.0, 10.0),
    (RouteParams, "route_keep_m"): _nonneg(_LEN),
    (RouteParams, "avoid_cost"): Range(1.0, 100.0),
    (RouteParams, "avoid_m"): _pos(_LEN),
    (RouteParams, "avoid_s"): _pos(3600.0),
    (Nf1Params, "escape_m"): _nonneg(_LEN),
    (Nf1Params, "border_search_m"): _nonneg(_LEN),
    (Nf1Params, "unknown_cost"): Range(1.0, 100.0),
    (TunnelParams, "margin_m"): _nonneg(10.0),
    (TunnelParams, "n_rays"): _count(8, 100_000),
    (TunnelParams, "jump_m"): _pos(_LEN),
    (TunnelParams, "advance_m"): _pos(_LEN),
    (TunnelParams, "passage_max_m"): _pos(_LEN),
    (TunnelParams, "spacing_m"): _pos(_LEN),
    (TunnelParams, "max_expansions"): _count(1, 1_000_000),
    (TunnelParams, "heuristic_weight"): Range(1.0, 100.0),
    (TunnelParams, "escape_m"): _nonneg(_LEN),
    (TunnelParams, "border_search_m"): _nonneg(_LEN),
    (NdParams, "n_sectors"): _count(8, 3600),
    (NdParams, "security_m"): _pos(10.0),
    (NdParams, "security_rear_ratio"): _FRAC,
    (NdParams, "max_range_m"): _pos(_RANGE_M),
    (NdParams, "smax_rad"): Range(0.0, 2.0 * math.pi, lo_open=True, hi_open=True),
    (NdParams, "gap_m"): _pos(10.0),
    (NdParams, "contact_m"): _pos(1.0),
    (NdParams, "commit_rad"): Range(0.0, math.pi),
    (NdParams, "security_time_s"): _nonneg(5.0),
    (SupervisorParams, "budget_match_s"): _pos(_TIME),
    (SupervisorParams, "budget_model_s"): _pos(_TIME),
    (SupervisorParams, "budget_planner_s"): _pos(_TIME),
    (SupervisorParams, "budget_reactor_s"): _pos(_TIME),
    (SupervisorParams, "rotate_w_frac"): _FRAC,
    (SupervisorParams, "goal_tolerance_m"): _pos(_LEN),
    (SupervisorParams, "goal_arrive_frac"): _FRAC,
    (SupervisorParams, "goal_settle_s"): _nonneg(_TIME),
    (SupervisorParams, "stale_scan_s"): _pos(3600.0),
    (SupervisorParams, "reaction_s"): _nonneg(_TIME),
    (SupervisorParams, "emergency_margin_m"): _nonneg(10.0),
    (SupervisorParams, "trap_window"): _count(),
    (SupervisorParams, "trap_count"): _count(),
    (SupervisorParams, "trap_progress_m"): _nonneg(_LEN),
    (SupervisorParams, "trap_turn_rad"): _TURN,
    (SupervisorParams, "trap_w_frac"): _FRAC,
    (SupervisorParams, "unreachable_ticks"): _count(),
    (SupervisorParams, "escape_ticks"): _count(),
    (SupervisorParams, "trap_window_s"): _pos(3600.0),
    (SupervisorParams, "unreachable_s"): _pos(3600.0),
    (SupervisorParams, "escape_s"): _pos(_TIME),
    (SupervisorParams, "escape_v_frac"): _FRAC,
    (SupervisorParams, "escape_clearance_m"): _nonneg(_LEN),
    (SupervisorParams, "manoeuvre_nodes"): _count(0, 100_000),
    (SupervisorParams, "manoeuvre_after_s"): _pos(_TIME),
    (SupervisorParams, "blind_memory_s"): _nonneg(3600.0),
    (SupervisorParams, "doubt_window_s"): _nonneg(3600.0),
    (SupervisorParams, "doubt_tol_m"): _nonneg(_LEN),
    (SupervisorParams, "doubt_tol_frac"): _nonneg(10.0),
    (NavigationConfig, "selector_margin_m"): _nonneg(10.0),
    (NavigationConfig, "cmd_timeout_s"): _pos(_TIME),
    (NavigationConfig, "selector_hold_s"): _nonneg(_TIME),
    (IdcParams, "min_range_m"): _nonneg(_RANGE_M),
    (IdcParams, "max_range_m"): _pos(_RANGE_M),
    (IdcParams, "keyframe_dist_m"): _pos(_LEN),
    (IdcParams, "keyframe_angle_rad"): _TURN,
    (IdcParams, "keyframe_back_m"): _nonneg(_LEN),
    (IdcParams, "keyframe_pair_ratio"): _UNIT,
    (IdcParams, "keyframe_pair_scans"): _count(1, 10_000),
    (IdcParams, "map_keyframes"): _count(1, 10_000),
    (IdcParams, "map_max_gap_s"): _pos(3600.0),
    (IdcParams, "n_bins"): _count(8, 100_000),
    (IdcParams, "blend_m"): _nonneg(_LEN),
    (IdcParams, "seg_abs_m"): _nonneg(_LEN),
    (IdcParams, "seg_rel"): _nonneg(10.0),
    (IdcParams, "gap_bins"): _count(1, 100_000),
    (IdcParams, "normal_chord_m"): _nonneg(_LEN),
    (IdcParams, "max_iterations"): _count(1, 10_000),
    (IdcParams, "win0_rad"): _TURN,
    (IdcParams, "win_tau"): _pos(10_000.0),
    (IdcParams, "win_min_rad"): _TURN,
    (IdcParams, "idc_points"): _count(),
    (IdcParams, "mrp_points"): _count(),
    (IdcParams, "gate0_m"): _pos(_LEN),
    (IdcParams, "gate_min_m"): _pos(_LEN),
    (IdcParams, "tol_m"): _pos(1.0),
    (IdcParams, "tol_rad"): _pos(1.0),
    (IdcParams, "max_cp_bins"): _count(1, 100_000),
    (IdcParams, "polish_iterations"): _count(0, 10_000),
    (IdcParams, "pair_sigma_m"): _pos(_LEN),
    (IdcParams, "prior_sigma_m"): _pos(_LEN),
    (IdcParams, "prior_sigma_rel"): _nonneg(100.0),
    (IdcParams, "prior_sigma_rad"): _TURN,
    (IdcParams, "prior_sigma_rel_rad"): _nonneg(100.0),
    (IdcParams, "min_pairs"): _count(),
    (IdcParams, "min_pair_fraction"): _UNIT,
    (IdcParams, "max_residual_m"): _pos(_LEN),
    (IdcParams, "degenerate_min_info"): _nonneg(1e9),
    (IdcParams, "odo_sigma_m"): _pos(_LEN),
    (IdcParams, "odo_sigma_rel"): _nonneg(100.0),
    (IdcParams, "odo_sigma_rad"): _TURN,
    (IdcParams, "odo_sigma_rel_rad"): _nonneg(100.0),
    (IdcParams, "coarse_margin"): _UNIT,
    (IdcParams, "guard_sigmas"): _pos(100.0),
    (IdcParams, "odo_learn_rate"): _UNIT,
    (IdcParams, "odo_learn_clip"): _pos(1000.0),
    (IdcParams, "guard_window_rad"): _TURN,
    (IdcParams, "guard_gain"): _UNIT,
    (IdcParams, "guard_agree_m"): _nonneg(_LEN),
    (IdcParams, "guard_agree_rad"): Range(0.0, 2.0 * math.pi),
    (IdcParams, "coarse_window_rad"): Range(0.0, math.pi),  # 0: no coarse rotation search; half a turn
    (IdcParams, "coarse_step_rad"): _TURN,
    (IdcParams, "coarse_points"): _count(),
    (IdcParams, "coarse_tol_m"): _nonneg(_LEN),
    (IdcParams, "coarse_tol_rel"): _nonneg(10.0),
    (IdcParams, "coarse_min_gain"): _UNIT,
    (IdcParams, "stall_min_step_m"): _nonneg(_LEN),
    (IdcParams, "stall_min_step_rad"): Range(0.0, 2.0 * math.pi),
    (IdcParams, "still_entry_m"): _nonneg(_LEN),
    (IdcParams, "still_entry_rad"): Range(0.0, 2.0 * math.pi),
    (IdcParams, "still_max_m"): _nonneg(_LEN),
    (IdcParams, "still_max_rad"): Range(0.0, 2.0 * math.pi),
    (IdcParams, "fallback_priors"): _count(0, 2),  # constant velocity, then no motion
    (IdcParams, "recheck_pair_ratio"): _UNIT,
    (IdcParams, "reset_after_failures"): _count(),
    # navigation.follow (path following)
    (FollowParams, "reach_m"): _pos(_LEN),
    (FollowParams, "heading_tol_rad"): Range(0.0, math.pi, lo_open=True),
    (FollowParams, "stop_v_mps"): _pos(10.0),
    (FollowParams, "deviation_m"): _pos(_LEN),
    (FollowParams, "lookahead_m"): _pos(_LEN),
    (FollowParams, "lookahead_s"): _nonneg(_TIME),
    (FollowParams, "sample_m"): Range(0.001, 10.0),
    (FollowParams, "kappa_max"): _pos(1000.0),
    (FollowParams, "extend_m"): _pos(_LEN),
    (FollowParams, "stabilise_m"): _pos(_LEN),
    (FollowParams, "settle_m"): _nonneg(_LEN),
    (FollowParams, "brake_frac"): _FRAC,
    (FollowParams, "creep_frac"): _UNIT,
    (FollowParams, "k_x"): _nonneg(100.0),
    (FollowParams, "k_y"): _pos(1000.0),
    (FollowParams, "k_theta"): _pos(1000.0),
    (FollowParams, "k_rho"): _pos(100.0),
    (FollowParams, "k_alpha"): _pos(100.0),
    (FollowParams, "k_phi"): _pos(100.0),
    (FollowParams, "k_turn"): _pos(100.0),
    (FollowParams, "turn_tol_rad"): Range(0.0, math.pi, lo_open=True),
    (FollowParams, "replace_search_m"): _pos(_LEN),
    (FollowParams, "horizon_m"): _pos(_LEN),
    # navigation.local (local navigation strategies)
    (LocalParams, "n_sectors"): _count(8, 3600),
    (LocalParams, "max_range_m"): _pos(_RANGE_M),
    (LocalParams, "safety_m"): _nonneg(10.0),
    (LocalParams, "approach_s"): _pos(_TIME),
    (LocalParams, "wall_distance_m"): _nonneg(_LEN),
    (LocalParams, "contour_distance_m"): _nonneg(_LEN),
    (LocalParams, "distance_gain_per_m"): _pos(100.0),
    (LocalParams, "max_correction_rad"): Range(0.0, math.pi / 2.0, lo_open=True),
    (LocalParams, "side_window_rad"): Range(0.0, math.pi, lo_open=True),
    (LocalParams, "free_margin_m"): _nonneg(10.0),
    (LocalParams, "deep_ratio"): _FRAC,
    (LocalParams, "target_weight"): _UNIT,
    (LocalParams, "clear_m"): _pos(_LEN),
    (LocalParams, "side_hysteresis_rad"): Range(0.0, math.pi),
    (LocalParams, "rotation_step_rad"): Range(0.0, 0.1, lo_open=True),
    # end of navigation
    (KissParams, "voxel_m"): _pos(_LEN),
    (KissParams, "max_range_m"): _pos(_RANGE_M),
    (KissParams, "min_range_m"): _nonneg(_RANGE_M),
    (KissParams, "max_points_per_voxel"): _count(1, 100_000),
    (KissParams, "initial_threshold_m"): _pos(_LEN),
    (KissParams, "min_motion_m"): _nonneg(_LEN),
    (KissParams, "fixed_threshold_m"): _pos(_LEN),
    (KissParams, "max_num_iterations"): _count(1, 100_000),
    (KissParams, "convergence"): _pos(1.0),
    (KissParams, "max_num_threads"): _count(1, 1024),
}

Check = Callable[[Any], bool]

#: (section dataclass, fields named in the message, predicate, what must hold): constraints between fields.
CROSS_CHECKS: tuple[tuple[type, str, Check, str], ...] = (
    (RobotConfig, "front_m, rear_m", lambda r: r.shape != "rectangle" or r.front_m + r.rear_m > 0.0,
     "a rectangle needs front_m + rear_m > 0"),
    (IdcParams, "min_range_m, max_range_m", lambda p: p.min_range_m < p.max_range_m,
     "min_range_m must be below max_range_m"),
    (IdcParams, "win_min_rad, win0_rad", lambda p: p.win_min_rad <= p.win0_rad,
     "win_min_rad must not exceed win0_rad"),
    (IdcParams, "gate_min_m, gate0_m", lambda p: p.gate_min_m <= p.gate0_m,
     "gate_min_m must not exceed gate0_m"),
    (KissParams, "min_range_m, max_range_m", lambda p: p.min_range_m < p.max_range_m,
     "min_range_m must be below max_range_m"),
    (SupervisorParams, "trap_count, trap_window", lambda s: s.trap_count <= s.trap_window,
     "trap_count must not exceed trap_window"),
)


def _sections(obj: Any, prefix: str) -> Iterator[tuple[str, Any]]:
    """(dotted name, dataclass) of ``obj`` and every section below it."""
    yield prefix, obj
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if dataclasses.is_dataclass(value):
            yield from _sections(value, f"{prefix}.{f.name}" if prefix else f.name)


def numeric_fields(section: type) -> list[str]:
    """Fields of a section dataclass holding a number (int or float, optional or not; not bool or Literal)."""
    hints = get_type_hints(section)
    out = []
    for f in dataclasses.fields(section):
        tp = hints[f.name]
        alts = get_args(tp) if get_origin(tp) in (types.UnionType, Union) else (tp,)
        if any(a in (int, float) for a in alts):
            out.append(f.name)
    return out


def range_of(section: type, name: str) -> Range | None:
    """The range of ``section.name``, inherited from a base section (PlannerParams from RouteParams)."""
    for cls in section.__mro__:
        if (cls, name) in RANGES:
            return RANGES[(cls, name)]
    return None


def _check_range(value: Any, where: str, allowed: Range, *, as_float: bool = False) -> float:
    """``value`` as a float when :func:`~gndreplay.io.userfile.check_number` takes it (a number, not a bool,
    no integer too long for a float, finite) and it lies in ``allowed``.

    Raises:
        ConfigError: "<where> must be in <range>, got <value>", the value quoted as the float the setting
            would hold when ``as_float`` (``-1`` -> ``-1.0``) and bounded whatever it is.
    """
    try:
        x = check_number(value, where, allowed.lo, allowed.hi)
    except ConfigError:
        x = math.nan
    if x not in allowed:
        raise ConfigError(f"{where} must be in {allowed}, got {_quoted(value, as_float)}")
    return x


def _quoted(value: Any, as_float: bool) -> str:
    """A refused number as the setting would hold it, bounded (an integer beyond a float stays an integer)."""
    if as_float and isinstance(value, int) and not isinstance(value, bool):
        try:
            return brief(float(value))
        except OverflowError:
            pass
    return brief(value)


def validate_config(cfg: Config) -> Config:
    """``cfg`` if every number is in its physical range (:data:`RANGES`) and the cross-field constraints
    (:data:`CROSS_CHECKS`) hold; else ConfigError naming the first bad key (``robot.vmax_mps``)."""
    for where, section in _sections(cfg, ""):
        for name in numeric_fields(type(section)):
            value = getattr(section, name)
            allowed = range_of(type(section), name)
            if value is not None and allowed is not None:
                _check_range(value, f"{where}.{name}" if where else name, allowed)
        for cls, keys, holds, what in CROSS_CHECKS:
            if type(section) is cls and not holds(section):
                raise ConfigError(f"[{where}] {keys}: {what}")
    return cfg


# --------------------------------------------------------------------------------------------------
# TOML: load with validation, dump the resolved configuration

MAX_CONFIG_BYTES = 1 << 20
"""Largest config file read (1 MB: a resolved configuration is about 10 KB)."""


def _check_value(value: Any, tp: Any, where: str, allowed: Range | None) -> Any:
    """Validate one TOML value against a field type and, for a number, its range ``allowed`` (checked here,
    before the section is built from it); returns the value converted (int -> float)."""
    origin = get_origin(tp)
    if origin is Literal:
        if value not in get_args(tp):
            allowed_values = ", ".join(repr(a) for a in get_args(tp))
            raise ConfigError(f"{where}: expected one of {allowed_values}, got {brief(value)}")
        return value
    if origin in (types.UnionType, Union):
        errors = []
        for alt in get_args(tp):
            if alt is type(None):
                continue
            try:
                return _check_value(value, alt, where, allowed)
            except ConfigError as err:
                errors.append(str(err))
        raise ConfigError(errors[0] if errors else f"{where}: unexpected value {brief(value)}")
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{where}: expected true or false, got {brief(value)}")
        return value
    if tp is int or tp is float:
        if isinstance(value, bool) or not isinstance(value, int if tp is int else int | float):
            kind = "an integer" if tp is int else "a number"
            raise ConfigError(f"{where}: expected {kind}, got {brief(value)}")
        if allowed is None:
            x = check_number(value, where)
        else:
            x = _check_range(value, where, allowed, as_float=tp is float)
        return value if tp is int else x
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{where}: expected a string, got {brief(value)}")
        return value
    if dataclasses.is_dataclass(tp):
        if not isinstance(value, dict):
            raise ConfigError(f"{where}: expected a table [{where}], got {brief(value)}")
        return value
    raise ConfigError(f"{where}: unsupported setting type {tp!r}")  # pragma: no cover


#: Keys of a section an unknown-key error lists (the rest counted), so the error stays one readable line.
MAX_KEYS_LISTED = 20


def _sub_table_of(obj: Any, key: str, prefix: str) -> str:
    """`` (a key of [section.table])`` when ``key`` is not a key of section ``obj`` but of one of its tables
    (``[planner] connectivity`` is NF1's: ``[planner.nf1]``), else ``""``."""
    for f in dataclasses.fields(obj):
        sub = getattr(obj, f.name)
        if dataclasses.is_dataclass(sub) and key in {g.name for g in dataclasses.fields(sub)}:
            return f" (a key of [{prefix}.{f.name}])" if prefix else f" (a key of [{f.name}])"
    return ""


def _override(obj: Any, table: dict[str, Any], prefix: str) -> Any:
    """A copy of dataclass ``obj`` with the keys of ``table`` replaced, validated recursively."""
    hints = get_type_hints(type(obj))
    names = {f.name for f in dataclasses.fields(obj)}
    changes: dict[str, Any] = {}
    for key, value in table.items():
        where = f"{prefix}.{key}" if prefix else key
        if key not in names:
            known = sorted(names)
            listed = ", ".join(known[:MAX_KEYS_LISTED]) + (
                f", ... ({len(known) - MAX_KEYS_LISTED} more)" if len(known) > MAX_KEYS_LISTED else "")
            hint = did_you_mean(key, known) or _sub_table_of(obj, key, prefix)
            raise ConfigError(f"unknown key {brief(where)}{hint} "
                              f"(known in [{prefix or 'top level'}]: {listed})")
        tp = hints[key]
        checked = _check_value(value, tp, where, range_of(type(obj), key))
        if dataclasses.is_dataclass(tp):
            checked = _override(getattr(obj, key), checked, where)
        changes[key] = checked
    try:
        return dataclasses.replace(obj, **changes)
    except (ValueError, TypeError, ConfigError) as err:
        raise ConfigError(f"[{prefix or 'top level'}] {err}") from None


def apply_overrides(base: Config, table: dict[str, Any]) -> Config:
    """``base`` with a nested dict of overrides applied (unknown keys / wrong types: ConfigError)."""
    table = dict(table)
    table.pop("preset", None)
    return validate_config(_override(base, table, ""))


# --------------------------------------------------------------------------------------------------
# Command-line overrides: the named options and ``--set section.key=value``, through the same validator


@dataclass(frozen=True, slots=True)
class CliOverrides:
    """What a command line changes in the configuration, applied over the preset and ``--config`` file.

    Attributes:
        planner: ``--planner`` ([planner] kind).
        matcher: ``--matcher`` ([scanmatch] method).
        enforce_budgets: ``--enforce-budgets`` ([supervisor] enforce_budgets = true).
        mode: ``--mode`` ([navigation] mode).
        local: ``--local`` ([navigation.local] strategy; refused for a navigation that runs no local
            strategy).
        no_selector: ``--no-selector`` ([navigation] selector = false).
        sets: ``--set section.key=value`` pairs, applied after the named options, in order (a later pair
            wins).
    """

    planner: str | None = None
    matcher: str | None = None
    enforce_budgets: bool = False
    mode: str | None = None
    local: str | None = None
    no_selector: bool = False
    sets: tuple[str, ...] = ()


#: No command-line override.
NO_OVERRIDES = CliOverrides()


def choose(option: str, value: str | None, choices: Sequence[str]) -> str | None:
    """``value`` stripped and lower-cased when it is one of ``choices`` (None passes).

    Raises:
        ConfigError: "<option>: expected one of ..., got '...'" with the closest choice.
    """
    if value is None:
        return None
    if value.strip().lower() not in choices:
        raise ConfigError(f"{option}: expected one of {', '.join(choices)}, got {brief(value)}"
                          f"{did_you_mean(value.strip(), choices)}")
    return value.strip().lower()


def navigation_choices(mode: str | None, local: str | None) -> tuple[str | None, str | None]:
    """``--mode`` and ``--local`` checked against the navigation modes and local strategies."""
    return choose("--mode", mode, NAV_MODES), choose("--local", local, LOCAL_STRATEGIES)


def parse_set(text: str) -> dict[str, Any]:
    """One ``--set section.key=value`` as a nested table (``{"section": {"key": value}}``).

    The value is read as a TOML value (``0.4``, ``8``, ``true``, ``"nf1"``, ``[1, 2]``); a bare word that is
    not one (``tunnel``) is a string.

    Raises:
        ConfigError: no ``=``, an empty or malformed key path (one line quoting the pair).
    """
    key, sep, raw = text.partition("=")
    path = [part.strip() for part in key.split(".")]
    if not sep or not all(part.replace("_", "").replace("-", "").isalnum() for part in path):
        raise ConfigError(f"--set: expected section.key=value (e.g. reactor.security_m=0.4), "
                          f"got {brief(text)}")
    value: Any
    try:
        value = tomllib.loads(f"v = {raw.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw.strip()
    table: dict[str, Any] = {path[-1]: value}
    for part in reversed(path[:-1]):
        table = {part: table}
    return table


def _merge(into: dict[str, Any], table: dict[str, Any]) -> dict[str, Any]:
    """``into`` with ``table`` merged in, recursively (``table`` wins)."""
    out = dict(into)
    for key, value in table.items():
        old = out.get(key)
        out[key] = _merge(old, value) if isinstance(old, dict) and isinstance(value, dict) else value
    return out


def _option_table(ov: CliOverrides) -> dict[str, Any]:
    """The named options of ``ov`` as one nested table of overrides, each value checked by name first."""
    table: dict[str, Any] = {}
    if (kind := choose("--planner", ov.planner, tuple(PLANNERS))) is not None:
        table["planner"] = {"kind": kind}
    if (method := choose("--matcher", ov.matcher, MATCHER_METHODS)) is not None:
        table["scanmatch"] = {"method": method}
    if ov.enforce_budgets:
        table["supervisor"] = {"enforce_budgets": True}
    mode, local = navigation_choices(ov.mode, ov.local)
    nav: dict[str, Any] = {}
    if mode is not None:
        nav["mode"] = mode
    if local is not None:
        nav["local"] = {"strategy": local}
    if ov.no_selector:
        nav["selector"] = False
    if nav:
        table["navigation"] = nav
    return table


def apply_cli(cfg: Config, ov: CliOverrides) -> Config:
    """``cfg`` with the command line's named options, then its ``--set`` pairs, applied and validated as a
    TOML file's keys are (``apply_overrides``).

    Raises:
        ConfigError: a bad option value or ``--set`` pair (naming the option or key), or ``--local`` for a
            navigation that runs no local strategy.
    """
    out = apply_overrides(cfg, table) if (table := _option_table(ov)) else cfg
    for text in ov.sets:
        table = parse_set(text)
        try:
            out = apply_overrides(out, table)
        except ConfigError as err:
            raise ConfigError(f"--set {brief(text)}: {err}") from None
    check_local_option(out, ov.local)
    return out


def configure(path: Path | None = None, *, preset_name: str | None = None,
              overrides: CliOverrides = NO_OVERRIDES) -> Config:
    """The configuration of a command: the preset, the ``--config`` file over it, the command line over
    both (``load_config`` then ``apply_cli``)."""
    return apply_cli(load_config(path, preset_name=preset_name), overrides)


def local_strategy_used(cfg: Config) -> bool:
    """Whether ``cfg``'s navigation runs a local strategy: mode "local", or "teleop" / "follow" with the
    mode selector (local navigation takes over); never "gnd" (GND's own ND+, no selector)."""
    nav = cfg.navigation
    return nav.mode == "local" or (nav.mode in ("teleop", "follow") and nav.selector)


def check_local_option(cfg: Config, local: str | None) -> None:
    """Refuse ``--local`` given (``local`` not None) for a navigation that runs no local strategy.

    Raises:
        ConfigError: one line naming the option and the mode.
    """
    if local is not None and not local_strategy_used(cfg):
        nav = cfg.navigation
        why = f"mode {nav.mode}" + (" without the mode selector" if nav.mode != "gnd" else "")
        raise ConfigError(f"--local {local}: {why} runs no local strategy (mode local, or teleop / follow "
                          "with the selector, do): drop --local")


def load_config(path: Path | None = None, *, preset_name: str | None = None) -> Config:
    """The resolved config: a preset (file's ``preset`` key, else ``preset_name``, else wheelchair)
    with the TOML file's tables applied. Errors name the file and the key."""
    table: dict[str, Any] = {}
    if path is not None:
        table = load_toml(Path(path), "config file", MAX_CONFIG_BYTES)
    name = preset_name or table.get("preset") or "wheelchair"
    if not isinstance(name, str):
        raise ConfigError(f"{path}: preset: expected a string, got {brief(name)}")
    in_file = table.get("preset")
    if preset_name and in_file is not None and (
        not isinstance(in_file, str) or _preset_key(in_file) != _preset_key(preset_name)
    ):
        raise ConfigError(f"{path}: preset {brief(in_file)} conflicts with --preset {preset_name}")
    try:
        cfg = apply_overrides(preset(name), table)
    except ConfigError as err:
        raise ConfigError(f"{path}: {err}" if path else str(err)) from None
    return dataclasses.replace(cfg, preset=_preset_key(name))


def config_to_dict(cfg: Any) -> dict[str, Any]:
    """Nested plain dict of a (config) dataclass, for JSON."""
    return dataclasses.asdict(cfg)


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int | float):
        return repr(v)
    return json.dumps(v)


def config_to_toml(cfg: Config) -> str:
    """The resolved configuration as TOML that ``load_config`` reads back to an equal Config."""
    lines = [f"# gndreplay resolved configuration\npreset = {json.dumps(cfg.preset)}\n"]

    def section(obj: Any, name: str) -> None:
        scalars, tables = [], []
        for f in dataclasses.fields(obj):
            v = getattr(obj, f.name)
            if dataclasses.is_dataclass(v):
                tables.append((f.name, v))
            elif v is not None:  # None means "derived default": leave the key out
                scalars.append(f"{f.name} = {_toml_value(v)}")
        lines.append(f"\n[{name}]\n" + "\n".join(scalars) + "\n")
        for sub, v in tables:
            section(v, f"{name}.{sub}")

    for f in dataclasses.fields(cfg):
        v = getattr(cfg, f.name)
        if dataclasses.is_dataclass(v):
            section(v, f.name)
    return "".join(lines)
