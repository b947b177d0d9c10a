"""GND supervision and the reflexive loop of the multi-loop architecture.

GND (Minguez & Montano) chooses one of three modes per tick from what the planner and the reactor
return: mpND (planner OK: the reactor steers to the instantaneous path direction), mND (planner failed:
the reactor steers to the goal itself) and ROTATE (no free walking area: stop and rotate until the model
changes). The multi-loop paper adds a reflexive loop below them that overrides everything: brake on an
imminent collision seen in the *raw* current scan, stop on stale sensor data, and escape a trap (repeated
stopped rotations or emergencies) with a slow straight motion where the scan shows room.
"""

from __future__ import annotations

import enum
from collections import deque
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..robot import RobotConfig
from ..types import Flag

__all__ = [
    "Mode",
    "SupervisorParams",
    "TrapDetector",
    "budget_flags",
    "escape_command",
    "footprint_contains",
    "gnd_mode",
    "rotate_command",
    "swept_collision",
]


class Mode(enum.Enum):
    """What produced the tick's command (GND modes, then reflexive overrides)."""

    MPND = "mpND"  # planner OK, reactor follows the instantaneous path direction
    MND = "mND"  # planner failed, reactor goes to the goal itself
    ROTATE = "ROTATE"  # reactor found no free walking area: stop and rotate
    EMERGENCY = "EMERGENCY"  # reflexive: imminent collision in the raw scan, brake
    STALE = "STALE"  # reflexive: sensor data too old, stop
    ESCAPE = "ESCAPE"  # reflexive: trap detected, slow straight escape
    GOAL = "GOAL"  # goal reached, stop


@dataclass(frozen=True, slots=True)
class SupervisorParams:
    """Supervisor constants.

    Attributes:
        budget_match_s, budget_model_s, budget_planner_s, budget_reactor_s: per-module time-outs (the
            wheelchair paper: model 0.05 s, planner 0.08 s, reactor 0.02 s; matching is part of the model
            builder in the paper, so its budget is reported separately with the same order of magnitude).
        enforce_budgets: False (default, **choice**) reports *_OVER_BUDGET flags without changing the
            result, so replays are deterministic; True applies the papers' exception path (a planner over
            budget counts as a planner failure, a reactor over budget stops the vehicle for the tick).
        rotate_w_frac: turn rate of ROTATE, as a fraction of wmax (**choice**: 0.5).
        goal_tolerance_m: distance at which the goal counts as reached.
        stale_scan_s: a scan older than this at tick time (gap to the previous scan) stops the robot.
        brake_decel_mps2, reaction_s: braking model for the swept-area check: horizon =
            reaction_s + v / brake_decel_mps2 (**choice**: 0.5 m/s^2 and 0.3 s, a cautious wheelchair).
        emergency_margin_m: extra margin around the footprint in the swept-area check.
        trap_window: number of recent ticks inspected for a trap.
        trap_count: stopped rotations with alternating sign, or emergencies, within the window that
            make a trap (the multi-loop paper's "repetitive stopped rotation").
        escape_ticks: how many ticks the escape motion lasts once triggered.
        escape_v_frac: escape speed, as a fraction of vmax (**choice**: 0.3).
        escape_clearance_m: free distance the raw scan must show ahead/behind to escape that way.
    """

    budget_match_s: float = 0.05
    budget_model_s: float = 0.05
    budget_planner_s: float = 0.08
    budget_reactor_s: float = 0.02
    enforce_budgets: bool = False
    rotate_w_frac: float = 0.5
    goal_tolerance_m: float = 0.3
    stale_scan_s: float = 1.0
    brake_decel_mps2: float = 0.5
    reaction_s: float = 0.3
    emergency_margin_m: float = 0.02
    trap_window: int = 40
    trap_count: int = 6
    escape_ticks: int = 10
    escape_v_frac: float = 0.3
    escape_clearance_m: float = 0.6


def gnd_mode(planner_ok: bool, reactor_has_region: bool) -> Mode:
    """GND's mode from the planner and reactor outcomes (no free area wins over everything)."""
    if not reactor_has_region:
        return Mode.ROTATE
    return Mode.MPND if planner_ok else Mode.MND


def rotate_command(goal_bearing_rad: float, robot: RobotConfig, params: SupervisorParams) -> float:
    """Turn rate of ROTATE: towards the goal side, at rotate_w_frac * wmax [rad/s]."""
    sign = 1.0 if goal_bearing_rad >= 0.0 else -1.0
    return sign * params.rotate_w_frac * robot.wmax_radps


def footprint_contains(
    points_xy: NDArray[np.float64], robot: RobotConfig, margin_m: float
) -> NDArray[np.bool_]:
    """(M,) mask of points (robot frame) inside the footprint grown by ``margin_m``."""
    if robot.shape == "circle":
        return np.hypot(points_xy[:, 0], points_xy[:, 1]) <= robot.radius_m + margin_m
    x, y = points_xy[:, 0], points_xy[:, 1]
    return (
        (x <= robot.front_m + margin_m)
        & (x >= -robot.rear_m - margin_m)
        & (np.abs(y) <= robot.width_m / 2.0 + margin_m)
    )


def swept_collision(
    points_xy: NDArray[np.float64],
    v_mps: float,
    w_radps: float,
    robot: RobotConfig,
    params: SupervisorParams,
    *,
    vy_mps: float = 0.0,
    n_steps: int = 12,
) -> bool:
    """True when the footprint swept along the commanded motion over the braking horizon hits a point.

    ``points_xy``: (M, 2) raw scan hits in the robot frame (the reflexive loop uses raw data). The motion
    is integrated exactly as a constant-twist arc; the horizon is reaction_s + |v| / brake_decel_mps2.
    A pure rotation sweeps the rotating footprint (it matters for the rectangular wheelchair).
    """
    if points_xy.shape[0] == 0:
        return False
    speed = float(np.hypot(v_mps, vy_mps))
    horizon = params.reaction_s + speed / params.brake_decel_mps2
    ts = np.linspace(0.0, horizon, n_steps)
    th = w_radps * ts
    # constant-twist integration (exact for an arc); the limit w -> 0 is a straight line
    if abs(w_radps) > 1e-9:
        s, c1 = np.sin(th) / w_radps, (1.0 - np.cos(th)) / w_radps
    else:
        s, c1 = ts, np.zeros_like(ts)
    px = v_mps * s - vy_mps * c1
    py = v_mps * c1 + vy_mps * s
    # points expressed in each future robot frame: R(-th) (p - t)
    dx = points_xy[None, :, 0] - px[:, None]
    dy = points_xy[None, :, 1] - py[:, None]
    ct, st = np.cos(th)[:, None], np.sin(th)[:, None]
    local = np.stack([ct * dx + st * dy, -st * dx + ct * dy], axis=-1).reshape(-1, 2)
    return bool(footprint_contains(local, robot, params.emergency_margin_m).any())


def escape_command(
    points_xy: NDArray[np.float64], robot: RobotConfig, params: SupervisorParams
) -> tuple[float, bool]:
    """The trap escape: slow straight motion forward, else backward, where the raw scan shows room.

    Returns (v [m/s], possible). The laser sees only the front half on the wheelchair, so "backward"
    relies on the footprint check alone (the model's memory is not used by the reflexive loop).
    """
    v = params.escape_v_frac * robot.vmax_mps
    for direction in (1.0, -1.0):
        reach = params.escape_clearance_m
        if direction > 0:
            ahead = (points_xy[:, 0] > 0) & (points_xy[:, 0] < robot.front_m + reach)
        else:
            ahead = (points_xy[:, 0] < 0) & (points_xy[:, 0] > -robot.rear_m - reach)
        lateral = np.abs(points_xy[:, 1]) <= robot.width_m / 2.0 + params.emergency_margin_m
        if robot.shape == "circle":
            lateral = np.abs(points_xy[:, 1]) <= robot.radius_m + params.emergency_margin_m
        if not np.any(ahead & lateral):
            return direction * v, True
    return 0.0, False


class TrapDetector:
    """Counts stopped rotations with alternating sign and emergency stops over a sliding window.

    Holds only the recent history; ``update`` returns True when the multi-loop paper's trap condition
    holds (repeated stopped rotations to the left and right, or frequent imminent collisions).
    """

    def __init__(self, params: SupervisorParams) -> None:
        self._p = params
        self._events: deque[int] = deque(maxlen=params.trap_window)  # -1/+1 rotation, 2 emergency, 0 else

    def update(self, mode: Mode, w_radps: float) -> bool:
        if mode is Mode.ROTATE:
            self._events.append(1 if w_radps >= 0 else -1)
        elif mode is Mode.EMERGENCY:
            self._events.append(2)
        else:
            self._events.append(0)
        ev = np.fromiter(self._events, dtype=np.int8)
        emergencies = int(np.count_nonzero(ev == 2))
        rot = ev[(ev == 1) | (ev == -1)]
        sign_changes = int(np.count_nonzero(np.diff(rot) != 0)) if rot.size > 1 else 0
        trapped = emergencies >= self._p.trap_count or (
            rot.size >= self._p.trap_count and sign_changes >= 2
        )
        if trapped:
            self._events.clear()
        return trapped


def budget_flags(timings_s: dict[str, float], params: SupervisorParams) -> Flag:
    """*_OVER_BUDGET flags for the modules whose time exceeded their budget."""
    flags = Flag.NONE
    for name, budget, flag in (
        ("match", params.budget_match_s, Flag.MATCH_OVER_BUDGET),
        ("model", params.budget_model_s, Flag.MODEL_OVER_BUDGET),
        ("planner", params.budget_planner_s, Flag.PLANNER_OVER_BUDGET),
        ("reactor", params.budget_reactor_s, Flag.REACTOR_OVER_BUDGET),
    ):
        if timings_s.get(name, 0.0) > budget:
            flags |= flag
    return flags
