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
``hold_s`` (**choice**, ``navigation.selector_hold_s``). A takeover still starts on the very tick the area
is occupied (safety is not delayed), and a desired command that stands still (the driver let go, the
follower stopped) ends the hold at once: a hold never moves a robot its driver or follower wants still.
(The path follower itself plans anew from the robot's pose after every tick it was overridden,
``PathFollower.step``: steering back onto its old trajectory, through the obstacle, was the main source of
the alternation.)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..robot import RobotConfig
from .supervisor import SupervisorParams, swept_touch, unconfirmed_cells

__all__ = ["Takeover", "arbitrate", "intention_xy", "select_mode", "swept_area_occupied"]


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
        heading = math.atan2(vy_mps, v_mps)
        turn = w_radps * lookahead_m / speed  # heading change over the lookahead distance
        bearing = heading + 0.5 * max(-math.pi, min(math.pi, turn))  # the chord bisects the turn
    elif w_radps != 0.0:
        bearing = math.copysign(0.5 * math.pi, w_radps)
    else:
        return None
    return np.array([lookahead_m * math.cos(bearing), lookahead_m * math.sin(bearing)])


@dataclass(frozen=True, slots=True)
class Takeover:
    """A takeover in progress, carried from tick to tick by the caller.

    Attributes:
        last_occupied_ns: the last tick at which the desired command's swept area was occupied.
    """

    last_occupied_ns: int


def select_mode(desired: str, occupied: str) -> tuple[str, str]:
    """(active mode, takeover reason) by the paper's rule, tick by tick: the desired mode unless its swept
    area is occupied (``occupied`` as ``swept_area_occupied`` returns it), then "local" with the reason,
    e.g. "teleop: swept area occupied (scan)". ``arbitrate`` with ``hold_s = 0``."""
    active, reason, _ = arbitrate(desired, occupied, t_ns=0, held=None, hold_s=0.0, moving=True)
    return active, reason


def arbitrate(desired: str, occupied: str, *, t_ns: int, held: Takeover | None, hold_s: float,
              moving: bool) -> tuple[str, str, Takeover | None]:
    """(active mode, takeover reason, takeover to pass back next tick) with a hold on handing back.

    ``occupied`` (``swept_area_occupied``): "local" with "<desired>: swept area occupied (<where>)", and the
    takeover's last occupied time set to ``t_ns``. Clear: local navigation keeps the robot, reason
    "<desired>: swept area clear for less than <hold_s> s (hold)", while a takeover is ``held``, the
    desired command is ``moving`` and ``t_ns`` is less than ``hold_s`` after the last occupied tick; else
    the desired mode, no reason, no takeover. ``hold_s = 0`` is the paper's rule tick by tick. Pure."""
    if occupied:
        return "local", f"{desired}: swept area occupied ({occupied})", Takeover(t_ns)
    if held is not None and moving and t_ns - held.last_occupied_ns < round(hold_s * 1e9):
        return "local", f"{desired}: swept area clear for less than {hold_s:g} s (hold)", held
    return desired, "", None
