"""The reflexive loop's pose doubt: where the matcher's corrected motion and the odometry's disagree, a grid
cell seen before the disagreement is also checked where it lies if the odometry is right (issue 10: the
matcher held the chair's pose in a passage while the chair backed 0.5 m into a wall its grid put further)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from gndreplay.config import PRESETS
from gndreplay.geometry import compose
from gndreplay.pipeline.stack import MatchInfo, NavigationStack
from gndreplay.pipeline.supervision import Proposal
from gndreplay.pipeline.supervisor import (
    Mode,
    SupervisorParams,
    doubt_transforms,
    doubted_cells,
    seen_through,
)
from gndreplay.types import Command, Pose2D, Scan

P = SupervisorParams()
S = 1_000_000_000  # ns per s
ODOM0 = np.array([3.0, -2.0, 0.7])  # the odometry frame differs from the corrected one


def _track(odom_back_m: float, corrected_back_m: float, n: int = 11) -> tuple[np.ndarray, np.ndarray]:
    """n poses while the robot backs along -x: the corrected ones cover ``corrected_back_m``, the odometry
    (in its own frame) ``odom_back_m``."""
    s = np.linspace(0.0, 1.0, n)[:, None]
    corrected = np.hstack([-corrected_back_m * s, np.zeros((n, 2))])
    odom = compose(ODOM0, np.hstack([-odom_back_m * s, np.zeros((n, 2))]))
    return corrected, odom


def test_motions_that_agree_within_the_odometry_error_are_not_in_doubt() -> None:
    corrected, odom = _track(0.50, 0.48)  # 2 cm apart over 0.5 m: within 0.05 m + 10 %
    transforms, doubted = doubt_transforms(corrected, odom, P)
    assert not doubted.any()
    assert np.allclose(transforms[-1], 0.0)  # since now: no motion at all


def test_a_stuck_matcher_puts_old_cells_where_the_odometry_says() -> None:
    """The matcher holds the pose (corrected motion 0) while the odometry backs 0.5 m: a wall 1.0 m behind
    the robot in the grid, seen before the stretch, lies 0.5 m behind it if the odometry is right."""
    corrected, odom = _track(0.50, 0.0)
    transforms, doubted = doubt_transforms(corrected, odom, P)
    assert doubted[0] and not doubted[-1]
    stamps = np.arange(11, dtype=np.int64) * S
    wall = np.array([[-1.0, -0.3], [-1.0, 0.0], [-1.0, 0.3]])
    moved = doubted_cells(wall, np.full(3, -5 * S, dtype=np.int64), stamps, transforms, doubted)
    assert np.allclose(moved, wall + np.array([0.5, 0.0]), atol=1e-9), moved
    # a cell seen at the stretch's last tick has no disagreement behind it; one seen half-way, half of it
    late = doubted_cells(wall[:1], np.array([10 * S]), stamps, transforms, doubted)
    assert late.shape == (0, 2)
    half = doubted_cells(wall[:1], np.array([5 * S]), stamps, transforms, doubted)
    assert np.allclose(half, [[-0.75, -0.3]], atol=1e-9), half


def test_the_frames_offset_and_a_turn_are_handled() -> None:
    """The odometry turns 90 deg in place and the matcher agrees: nothing in doubt, whatever the frames."""
    n = 9
    th = np.linspace(0.0, math.pi / 2, n)
    corrected = np.column_stack([np.full(n, 5.0), np.full(n, 1.0), th])
    odom = compose(ODOM0, np.column_stack([np.zeros(n), np.zeros(n), th]))
    _, doubted = doubt_transforms(corrected, odom, P)
    assert not doubted.any()


CHAIR = PRESETS["wheelchair"]
ANGLES = np.linspace(-math.pi / 2, math.pi / 2, 361)


def _scan(t_s: float, wall_x: float, pose: Pose2D) -> Scan:
    """A scan of a wall across the world at x = ``wall_x`` (robot at ``pose``, laser at the chair's
    mounting): beams that do not meet it return nothing."""
    sp = CHAIR.robot.laser_x_m
    lx = pose.x + sp * math.cos(pose.theta)
    bearing = pose.theta + ANGLES
    with np.errstate(divide="ignore"):
        r = (wall_x - lx) / np.cos(bearing)
    r = np.where((r > 0.0) & (r < 8.0), r, np.inf)
    return Scan(t_ns=round(t_s * S), ranges_m=r, angles_rad=ANGLES, max_range_m=8.0,
                sensor_pose=Pose2D(sp, 0.0, 0.0))


def test_seen_through_keeps_only_what_the_scan_cannot_refute() -> None:
    """Beams every 10 deg over the front half, laser 0.5 m ahead of the rotation centre: a point in view
    with the beam returning beyond it is seen through (also a no-return); one behind the return (in its
    shadow), one a nan beam covers, one out of view, are not."""
    angles = np.radians(np.arange(-90.0, 91.0, 10.0))
    ranges = np.full(angles.shape, 3.0)
    ranges[angles.shape[0] // 2] = np.inf  # straight ahead: no return
    ranges[angles.shape[0] // 2 + 3] = np.nan  # 30 deg left: invalid
    laser = (0.5, 0.0, 0.0)

    def at(r: float, deg: float) -> list[float]:  # robot frame, from the laser's range and bearing
        return [0.5 + r * math.cos(math.radians(deg)), r * math.sin(math.radians(deg))]

    # within the tolerance of the return; the no-return; in the shadow; the nan beam; behind; seen through
    pts = np.array([at(2.97, -20.0), at(1.0, 0.0), at(3.5, 10.0), at(1.0, 30.0), [-1.0, 0.0], at(2.0, -40.0)])
    got = seen_through(pts, ranges, angles, laser, 0.05)
    assert got.tolist() == [False, True, False, False, False, True]
    # a clockwise scan reads the same
    assert seen_through(pts, ranges[::-1], angles[::-1], laser, 0.05).tolist() == got.tolist()


def _reverse_check(doubt_window_s: float, w: float = 0.0, v_frac: float = -1.0) -> Mode | None:
    """The chair looked back at a wall 1.6 m behind its axle (now in the grid, out of the laser's view),
    then backed 1.15 m by its odometry while the matcher held its pose (the corrected pose stays at the
    origin, facing away from the wall): by the grid the wall is 1.2 m behind the rear edge, by the
    odometry 0.05 m. The reflexive loop's rule for a reverse at the creep speed (None: it goes out)."""
    sup = dataclasses.replace(CHAIR.supervisor, doubt_window_s=doubt_window_s)
    stack = NavigationStack(dataclasses.replace(CHAIR.stack_params(), supervisor=sup))
    look = Pose2D(1.0, 0.0, math.pi)  # the look back traces the floor behind the chair's rear edge too
    stack.grid.integrate(_scan(0.0, -1.6, look), look)
    here = Pose2D(0.0, 0.0, 0.0)
    for k in range(11):
        t = 1.0 + 0.2 * k
        odom = Pose2D.from_array(compose(ODOM0, [-0.115 * k, 0.0, 0.0]))
        scan = _scan(t, -1.6, here)
        stack._model(scan, here, odom, MatchInfo())  # the cycle's start: the scan into the grid, the track
    v = v_frac * sup.escape_v_frac * CHAIR.robot.vmax_mps
    out = stack.supervisor.supervise(Proposal(Mode.MPND, Command(scan.t_ns, v, w)))
    return None if out.mode is Mode.MPND and (out.command.v_mps, out.command.w_radps) == (v, w) else out.mode


def test_backing_towards_a_remembered_wall_stops_when_the_matcher_holds_the_pose() -> None:
    """The cause (doubt_window_s = 0, the old loop): the wall 1.2 m behind by the grid, the reverse goes
    out and the chair backs into it. With the pose doubt the wall is also checked where the odometry puts
    it, 5 cm behind the rear edge, and no reverse is admissible."""
    assert _reverse_check(0.0) is None
    assert _reverse_check(CHAIR.supervisor.doubt_window_s) is Mode.EMERGENCY


def test_the_doubt_does_not_stop_turning_or_driving_on() -> None:
    """Only travel out of the laser's view is held to the moved cells: a turn in place (how the chair
    looks) and driving forwards (the scan sees where it goes) go out as before."""
    assert _reverse_check(CHAIR.supervisor.doubt_window_s, w=0.5, v_frac=0.0) is None
    assert _reverse_check(CHAIR.supervisor.doubt_window_s, v_frac=1.0) is None
