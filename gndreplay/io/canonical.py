"""One representation of what a tick carries, whatever the container it was read from.

The same recording read from a CARMEN file and from a ROS bag converted from it differs in the last bits:
a LaserScan stores ranges and its bearings' start and step as float32 where the CARMEN text has decimals,
a bag's odometry heading and its laser mounting went through a quaternion and back (1e-16 rad), and its
stamps through float seconds (+-120 ns at 1e9 s). The scan matcher's decisions (a point's bin, a pair's
gate) are discrete, so such differences grow into different trajectories within a hundred scans. Each tick
is therefore brought to one representation before anything computes on it: ranges and the bearings' start
and step at float32 (the precision of every laser driver's interface), poses (odometry, ground truth and
the laser's mounting) on a 1e-9 m / 1e-9 rad grid, and the clock at whole microseconds (CARMEN's
resolution; far below any scan period).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from ..types import Pose2D, Scan

__all__ = ["canonical_bearings", "canonical_pose", "canonical_scan", "canonical_stamp"]

F64 = NDArray[np.float64]
_NS_PER_US = 1000
_POSE_DIGITS = 9  # 1 nm, 1 nrad


def canonical_stamp(t_ns: int) -> int:
    """``t_ns`` rounded to the nearest microsecond (halves up)."""
    return (t_ns + _NS_PER_US // 2) // _NS_PER_US * _NS_PER_US


def canonical_pose(p: Pose2D) -> Pose2D:
    """``p`` on the 1e-9 grid (Python's correctly rounded ``round``: the same on every CPU); a heading that
    rounds past +-pi is pi (or -pi), so it stays in [-pi, pi]."""
    theta = min(math.pi, max(-math.pi, round(p.theta, _POSE_DIGITS)))
    return Pose2D(round(p.x, _POSE_DIGITS), round(p.y, _POSE_DIGITS), theta)


def canonical_bearings(angles: F64) -> F64:
    """Evenly spaced bearings as float32 start + i * float32 step (a LaserScan's own form); others as
    they are. Read-only, like the readers' shared bearing arrays."""
    n = angles.shape[0]
    if n < 2:
        return angles
    start = float(angles[0])
    step = (float(angles[-1]) - start) / (n - 1)
    grid = start + step * np.arange(n, dtype=np.float64)
    if not np.allclose(angles, grid, rtol=0.0, atol=1e-9):
        return angles
    out = float(np.float32(start)) + float(np.float32(step)) * np.arange(n, dtype=np.float64)
    out.flags.writeable = False
    return out


def canonical_scan(scan: Scan, bearings: dict[tuple[int, float, float], F64]) -> Scan:
    """``scan`` with its stamp, ranges, bearings and mounting in the canonical form; ``bearings`` caches the
    canonical bearings by (beams, first, last) across the scans of one log."""
    a = scan.angles_rad
    key = (a.shape[0], float(a[0]), float(a[-1])) if a.shape[0] else (0, math.nan, math.nan)
    angles = bearings.get(key)
    if angles is None:
        angles = canonical_bearings(a)
        if len(bearings) > 64:
            bearings.clear()
        bearings[key] = angles
    ranges = scan.ranges_m.astype(np.float32).astype(np.float64)
    return replace(scan, t_ns=canonical_stamp(scan.t_ns), ranges_m=ranges, angles_rad=angles,
                   sensor_pose=canonical_pose(scan.sensor_pose))
