"""The mode selector of the multi-loop architecture (the paper's section 3.4), as small pure functions.

The desired navigation mode (teleoperation or path following) proposes a command every tick. The selector
estimates, "within certain tolerances", the area that command sweeps: the real footprint moved along the
commanded arc over the braking horizon (``supervisor.swept_touch``, the very test the reflexive loop
applies), grown by ``selector_margin_m``. If the raw scan or the grid's occupied cells lie in that area,
local navigation wins the tick and steers towards the desired mode's intention (``intention_xy`` for
teleoperation, the follower's target point for path following).

Handing back (``arbitrate``): the paper returns to the desired mode "as soon as the locally desired path is
free". Taken tick by tick (``hold_s = 0``, that rule exactly) a hand-back often lasts a single tick: local
navigation turns the robot away, the desired command from the new heading sweeps clear for one tick and
turns it back in, and the timeline shows many one-tick takeovers round one obstacle where the paper's
Fig. 7 shows three local episodes. So we read "free" as "free for a while" (the paper's "within certain
tolerances"): local navigation keeps the robot until the desired command's swept area has been clear for
``hold.clear_s`` (**choice**, ``navigation.selector_hold_s``), and, after the reflexive loop made local
navigation turn first to look where it goes (the blind side rule), until it has made its way (``Hold``).
A takeover still starts on the very tick the area is occupied (safety is not delayed), and a desired
command that stands still (the driver let go, the follower stopped) ends the hold at once: a hold never
moves a robot its driver or follower wants still.
(The path follower itself plans anew from the robot's pose after every tick it was overridden,
``PathFollower.step``: steering back onto its old trajectory, through the obstacle, was the main source of
the alternation.)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from .. import detmath as dm
from ..robot import RobotConfig
from .supervisor import SupervisorParams, swept_touch, unconfirmed_cells

__all__ = [
    "Hold", "Takeover", "arbitrate", "intention_xy", "look_hold", "select_mode", "swept_area_occupied",
    "turned_first",
]


def swept_area_occupied(
    v_mps: float,
    vy_mps: float,
    w_radps: float,
    scan_xy: NDArray[np.float64],
    grid_xy: NDArray[np.float64],
    robot: RobotConfig,
    params: SupervisorParams,
    *,
    cell_m: float,
    margin_m: float,
) -> str:
    """Where the area the command sweeps is occupied: "scan" (a raw hit of the current scan), "grid" (an
    OCCUPIED cell, grown by half a cell: the obstacle lies anywhere in it) or "" (clear).

    Both point sets are in the robot frame. The area is the footprint swept along the commanded arc over
    ``supervisor.braking_time_s``, within emergency_margin_m + ``margin_m`` (the selector's tolerance on
    top of the reflexive loop's, so the selector hands over before the emergency brake would fire). As in
    ``supervisor.safe_command``, a cell holding a hit of the current scan is checked through the hit
    (``unconfirmed_cells``), so the two differ by ``margin_m`` only (grown cells alone leave the 0.7 m
    chair less than a centimetre per side in a 0.85 m door, the hits 7.5 cm). A still command sweeps
    nothing."""
    if v_mps == 0.0 and vy_mps == 0.0 and w_radps == 0.0:
        return ""  # before the cell filter, which costs cells x hits
    cells = unconfirmed_cells(grid_xy, scan_xy, cell_m)
    return swept_touch(v_mps, vy_mps, w_radps, scan_xy, cells, robot, params, cell_m=cell_m,
                       margin_m=margin_m)


def intention_xy(
    v_mps: float, vy_mps: float, w_radps: float, lookahead_m: float
) -> NDArray[np.float64] | None:
    """Where a velocity command is heading, as a target for local navigation (robot frame, (2,)).

    A moving command: the point ``lookahead_m`` away along the chord of its arc after travelling
    ``lookahead_m`` (straight ahead for a straight forward command, behind the robot for a reverse one,
    bent towards the turn for an arc). A pure rotation: the point ``lookahead_m`` to the side it turns to.
    A still command has no intention (None)."""
    speed = math.hypot(v_mps, vy_mps)
    if speed > 0.0:
        heading = dm.atan2(vy_mps, v_mps)
        turn = w_radps * lookahead_m / speed  # heading change over the lookahead distance
        bearing = heading + 0.5 * max(-math.pi, min(math.pi, turn))  # the chord bisects the turn
    elif w_radps != 0.0:
        bearing = math.copysign(0.5 * math.pi, w_radps)
    else:
        return None
    return np.array([lookahead_m * dm.cos(bearing), lookahead_m * dm.sin(bearing)])


@dataclass(frozen=True, slots=True)
class Takeover:
    """A takeover in progress, carried from tick to tick by the caller.

    Attributes:
        last_occupied_ns: the last tick at which the desired command's swept area was occupied.
        look: where and when (x, y, t_ns; any fixed frame) the reflexive loop last replaced local
            navigation's command by the blind side rule's turn first (``turned_first``); None: not since
            the takeover began.
    """

    last_occupied_ns: int
    look: tuple[float, float, int] | None = None


@dataclass(frozen=True, slots=True)
class Hold:
    """How long local navigation keeps the robot after a takeover (``arbitrate``).

    Attributes:
        clear_s: until the desired command's swept area has been clear this long
            (``navigation.selector_hold_s``; 0: the paper's rule, tick by tick).
        look_m, look_s: after a turn first, until local navigation has moved ``look_m`` from where it
            last turned first, or ``look_s`` has passed since (``look_hold``).
    """

    clear_s: float = 0.0
    look_m: float = 0.0
    look_s: float = 0.0


def look_hold(clear_s: float, robot: RobotConfig, params: SupervisorParams) -> Hold:
    """The hold with the turn first's part set from the robot: one footprint diameter (2 * outer radius)
    or the time of one full ROTATE turn (**choice**: local navigation has then either passed the obstacle
    or found no way, and the selector decides again)."""
    return Hold(clear_s, 2.0 * robot.outer_radius_m,
                2.0 * math.pi / (params.rotate_w_frac * robot.wmax_radps))


def turned_first(held: Takeover | None, xy: tuple[float, float], t_ns: int) -> Takeover | None:
    """The takeover after the reflexive loop replaced local navigation's command by the blind side rule's
    turn first at ``xy`` and ``t_ns`` (none in progress: still none)."""
    return None if held is None else replace(held, look=(xy[0], xy[1], t_ns))


def select_mode(desired: str, occupied: str) -> tuple[str, str]:
    """(active mode, takeover reason) by the paper's rule, tick by tick: the desired mode unless its swept
    area is occupied (``occupied`` as ``swept_area_occupied`` returns it), then "local" with the reason,
    e.g. "teleop: swept area occupied (scan)". ``arbitrate`` without a hold."""
    active, reason, _ = arbitrate(desired, occupied, t_ns=0, held=None, hold=Hold(), moving=True)
    return active, reason


def arbitrate(desired: str, occupied: str, *, t_ns: int, held: Takeover | None, hold: Hold, moving: bool,
              xy: tuple[float, float] = (0.0, 0.0)) -> tuple[str, str, Takeover | None]:
    """(active mode, takeover reason, takeover to pass back next tick): the one rule for handing back.

    ``occupied`` (``swept_area_occupied``): "local" with "<desired>: swept area occupied (<where>)", the
    takeover's last occupied time set to ``t_ns``. Clear: while a takeover is ``held`` and the desired
    command is ``moving``, local navigation keeps the robot

    - until ``hold.clear_s`` after the last occupied tick, reason "<desired>: swept area clear for less
      than <clear_s> s (hold)";
    - after a turn first (``turned_first``), until the robot (at ``xy``, the frame of ``turned_first``'s)
      has moved ``hold.look_m`` from where it turned first or ``hold.look_s`` has passed, reason
      "<desired>: swept area clear since local navigation turned first (hold)". The turn itself clears
      the desired command's swept area (the robot now faces away from the obstacle); handing back then
      turns the robot back into it, and the takeover begins again, turn after turn (measured:
      follow_unknown_obstacle on the XR4000 timed out).

    Else the desired mode, no reason, no takeover. A desired command that stands still (the driver let
    go, the follower stopped) ends any hold: a hold never moves a robot its driver or follower wants still.
    ``Hold()`` is the paper's rule tick by tick. Pure."""
    if occupied:
        return "local", f"{desired}: swept area occupied ({occupied})", Takeover(
            t_ns, None if held is None else held.look)
    if held is None or not moving:
        return desired, "", None
    if t_ns - held.last_occupied_ns < round(hold.clear_s * 1e9):
        return "local", f"{desired}: swept area clear for less than {hold.clear_s:g} s (hold)", held
    if held.look is not None:
        x, y, t_look = held.look
        if math.hypot(xy[0] - x, xy[1] - y) < hold.look_m and t_ns - t_look <= round(hold.look_s * 1e9):
            return "local", f"{desired}: swept area clear since local navigation turned first (hold)", held
    return desired, "", None
