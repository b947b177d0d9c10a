"""The mode selector of the multi-loop architecture (the paper's section 3.4), as small pure functions.

The desired navigation mode (teleoperation or path following) proposes a command every tick. The selector
estimates, "within certain tolerances", the area that command sweeps: the real footprint moved along the
commanded arc over the braking horizon (``supervisor.swept_touch``, the very test the reflexive loop
applies), grown by ``selector_margin_m``. If the raw scan or the grid's occupied cells lie in that area,
local navigation wins the tick and steers towards the desired mode's intention (``intention_xy`` for
teleoperation, the follower's target point for path following); on the first tick the desired command's
area is clear again the desired mode wins again. No hysteresis: the paper's rule, tick by tick.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ..robot import RobotConfig
from .supervisor import SupervisorParams, swept_touch, unconfirmed_cells

__all__ = ["intention_xy", "select_mode", "swept_area_occupied"]


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


def select_mode(desired: str, occupied: str) -> tuple[str, str]:
    """(active mode, takeover reason): the desired mode unless its swept area is occupied (``occupied`` as
    ``swept_area_occupied`` returns it), then "local" with the reason, e.g. "teleop: swept area occupied
    (scan)"."""
    if not occupied:
        return desired, ""
    return "local", f"{desired}: swept area occupied ({occupied})"
