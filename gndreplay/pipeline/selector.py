"""The mode selector of the multi-loop architecture (the paper's section 3.4): small pure functions, and
``ModeSelector``, which carries a takeover and its target from tick to tick.

The desired navigation mode (teleoperation or path following) proposes a command every tick. The selector
estimates, "within certain tolerances", the area that command sweeps: the real footprint moved along the
commanded arc over the braking horizon (``supervisor.swept_touch``, the very test the reflexive loop
applies), grown by ``selector_margin_m``. If the raw scan or the grid's occupied cells lie in that area,
local navigation wins the tick and steers towards the desired mode's intention (``intention_xy`` for
teleoperation, the follower's target point for path following). The teleoperation module's own command is
``teleop_command``: the driver's, clipped to the robot's limits.

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
from ..geometry import transform_points
from ..robot import RobotConfig
from ..types import Command, Pose2D
from .follow import first_free_point
from .model import RobotCentredGrid
from .supervisor import SupervisorParams, swept_touch, unconfirmed_cells

__all__ = [
    "TELEOP_REACH", "TELEOP_REAIM_RAD", "Hold", "ModeSelector", "Takeover", "arbitrate", "intention_xy",
    "look_hold", "select_mode", "swept_area_occupied", "teleop_command", "turned_first",
]


def swept_area_occupied(
    v_mps: float, vy_mps: float, w_radps: float, scan_xy: NDArray[np.float64], grid_xy: NDArray[np.float64],
    robot: RobotConfig, params: SupervisorParams, *, cell_m: float, margin_m: float
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


TELEOP_REACH = 4.0
"""How far a takeover's target may lie along the driver's command, in look-ahead distances."""
TELEOP_REAIM_RAD = 0.25 * math.pi
"""A held takeover target is aimed again when the driver's intention points this far from it [rad]
(**choice**: a quarter turn is a new request, a counter-steer is not)."""


def teleop_command(cmd: Command | None, robot: RobotConfig, *, t_ns: int | None = None,
                   timeout_s: float = math.inf) -> tuple[float, float, float, str]:
    """(v, vy, w, reason) of a teleoperation command: clipped to the robot's velocity limits (vy only for
    a holonomic base); none, one not finite, or one older than ``timeout_s`` at time ``t_ns`` (a driver who
    let go, a log whose commands stopped: ``Tick.cmd`` is the last one at or before the tick) is standing
    still with the reason ("teleop: no command", "teleop: command stale")."""
    if cmd is None:
        return 0.0, 0.0, 0.0, "teleop: no command"
    if t_ns is not None and (t_ns - cmd.t_ns) / 1e9 > timeout_s:
        return 0.0, 0.0, 0.0, "teleop: command stale"
    if not (math.isfinite(cmd.v_mps) and math.isfinite(cmd.vy_mps) and math.isfinite(cmd.w_radps)):
        return 0.0, 0.0, 0.0, "teleop: command not finite"
    vmax, wmax = robot.vmax_mps, robot.wmax_radps
    vy = min(max(cmd.vy_mps, -vmax), vmax) if robot.drive == "holonomic" else 0.0
    return min(max(cmd.v_mps, -vmax), vmax), vy, min(max(cmd.w_radps, -wmax), wmax), ""


def _intention_changed(a: tuple[float, float, float], b: tuple[float, float, float],
                       held_rel: NDArray[np.float64], rel: NDArray[np.float64]) -> bool:
    """The driver asked for something else: the direction of travel reversed (a sign of v or vy changed),
    or the new command's intention (robot frame) points more than ``TELEOP_REAIM_RAD`` away from the held
    target. Compared as bearings, not as commands: a driver who counter-steers while local navigation turns
    the robot away from his line changes w, even its sign, yet still points at the same place; re-aiming
    then would swing the target from side to side with the robot and ND+ would dither in front of the
    obstacle (teleop_into_wall)."""
    if any(np.sign(x) != np.sign(y) for x, y in zip(a[:2], b[:2], strict=True)):
        return True
    diff = dm.atan2(rel[1], rel[0]) - dm.atan2(held_rel[1], held_rel[0])
    return abs(math.remainder(diff, math.tau)) > TELEOP_REAIM_RAD


class ModeSelector:
    """The mode selector from tick to tick: the takeover in progress (its hold) and, while local navigation
    has taken over from the driver, the target it steers to (``teleop_target``).

    ``select`` arbitrates a tick (``swept_area_occupied`` on the obstacles the reflexive loop checks too,
    then ``arbitrate``); ``settle`` ends it once the reflexive loop has spoken (``turned_first``)."""

    def __init__(self, robot: RobotConfig, params: SupervisorParams, *, cell_m: float, margin_m: float,
                 hold_s: float, lookahead_m: float, inflate_m: float) -> None:
        self._robot = robot
        self._params = params
        self._cell_m = cell_m
        self._margin_m = margin_m  # the selector's tolerance on the swept area
        self._hold_s = hold_s
        self._lookahead_m = lookahead_m  # the driver's intention lies this far along his command
        self._inflate_m = inflate_m  # the C-space growth a takeover's target must be free in
        self._takeover: Takeover | None = None
        self._intent: tuple[NDArray[np.float64], tuple[float, float, float]] | None = None  # held teleop
        # target (world) of the takeover in progress, and the driver's command it was aimed from

    def select(self, desired: str, cmd: tuple[float, float, float], near_xy: NDArray[np.float64],
               grid_xy: NDArray[np.float64], *, t_ns: int, xy: tuple[float, float]) -> tuple[str, str]:
        """(active mode, takeover reason) for the desired module's command ``cmd`` (v, vy, w) with the
        raw hits ``near_xy`` and occupied cells ``grid_xy`` near the robot (robot frame), the robot at
        ``xy`` (any fixed frame) at ``t_ns``."""
        v, vy, w = cmd
        p, robot = self._params, self._robot
        where = swept_area_occupied(v, vy, w, near_xy, grid_xy, robot, p,
                                    cell_m=self._cell_m, margin_m=self._margin_m)
        active, why, self._takeover = arbitrate(
            desired, where, t_ns=t_ns, held=self._takeover,
            hold=look_hold(self._hold_s, robot, p),
            moving=v != 0.0 or vy != 0.0 or w != 0.0, xy=xy)
        return active, why

    def settle(self, active: str, looking: bool, xy: tuple[float, float], t_ns: int) -> None:
        """End the tick: with the desired mode active no takeover is held, nor a teleop target; under local
        navigation a turn first of the reflexive loop (``looking``) is remembered (``turned_first``)."""
        if active != "local":
            self._takeover = None
            self._intent = None
        elif looking:
            self._takeover = turned_first(self._takeover, xy, t_ns)

    def teleop_target(self, pose: Pose2D, cmd: tuple[float, float, float],
                      grid: RobotCentredGrid) -> NDArray[np.float64] | None:
        """Local navigation's target (robot frame) while it has taken over from the driver.

        Where the driver's command heads (``intention_xy``), searched along that bearing from the
        look-ahead distance to ``TELEOP_REACH`` times it for the first point free in C-space with unknown
        cells counted as blocked (known free space past the obstacle, not the obstacle's unseen inside),
        else the far end. It is fixed in the world when the takeover starts and kept while it lasts: a
        target in the robot frame turns with the robot, so local navigation, turning to pass the obstacle,
        would never see it move aside and would only dither in front of it. It is aimed again when the
        driver asks for something else (``_intention_changed``: travel reversed, or his intention points
        away from the held target), not merely because he counter-steers."""
        rel = intention_xy(*cmd, self._lookahead_m)
        if rel is None:
            self._intent = None
            return None
        to_robot = pose.inverse().as_array()
        if self._intent is not None:
            held = transform_points(to_robot, self._intent[0][None, :])[0]
            if not _intention_changed(self._intent[1], cmd, held, rel):
                return held
        bearing = dm.atan2(rel[1], rel[0])
        dists = np.arange(self._lookahead_m, TELEOP_REACH * self._lookahead_m + 1e-9, self._cell_m)
        ray = np.column_stack([dists * dm.cos(bearing), dists * dm.sin(bearing)])
        world = transform_points(pose.as_array(), ray)
        i = first_free_point(world, grid, inflate_m=self._inflate_m, unknown_is_free=False)
        target = world[-1 if i is None else i]
        self._intent = (target, cmd)
        return transform_points(to_robot, target[None, :])[0]
