"""results.mcap: the replay as standard ROS 2 messages, and a Foxglove layout that shows it.

Written with the rosbags rosbag2 writer (MCAP storage, zstd chunks) as a stream: messages go out as each
tick arrives (memory does not grow with the log; the accumulated map grows with the explored area). The
writer produces a bag *folder*; the sink stages it in a temporary folder inside the replay's staging
directory (``start``; nothing in $TMPDIR) and moves the single ``.mcap`` file to ``run_dir/results.mcap``,
then writes ``results.foxglove.json`` (``foxglove.LAYOUT_FILE``) referring to the topics the file holds.

Frames: ``map`` is the corrected odometry frame (scan matching), ``odom`` the raw odometry frame,
``base_link`` the robot (its rotation centre), ``laser`` the scanner, ``truth`` the log's ground-truth frame
(placed so that the first ground-truth pose coincides with the corrected pose of that tick). Stamps (header
and log time) are the tick times, except the accumulated map's (the first tick's).

Topics (per tick = every tick the stack ran; a topic with nothing to say is not in the file):
    /tf                   tf2_msgs/TFMessage        per tick: map -> odom (the correction), odom -> base_link
                                                    (raw odometry); so base_link in map = the corrected pose
    /tf_static            tf2_msgs/TFMessage        latched: base_link -> laser (first tick), map -> truth
                                                    (again with both when ground truth first appears)
    /scan                 sensor_msgs/LaserScan     per tick: the log's ranges in the laser frame
                                                    (``scan_beams``: unevenly spaced beams)
    /odom                 nav_msgs/Odometry         per tick: measured odometry (odom); twist: the motion
                                                    from the previous tick over its duration (base_link)
    /gndreplay/odom       nav_msgs/Odometry         per tick: corrected pose (map); twist as /odom
    /ground_truth         geometry_msgs/PoseStamped ticks with a ground-truth pose (truth)
    /cmd_vel              geometry_msgs/TwistStamped per tick: our command v, vy, w (base_link)
    /cmd_vel_recorded     geometry_msgs/TwistStamped ticks with a recorded command: the log's (base_link)
    /gndreplay/footprint  geometry_msgs/PolygonStamped per tick: the robot's outline (base_link)
    /gndreplay/goal       geometry_msgs/PoseStamped per tick: the tick's goal (map)
    /gndreplay/path       nav_msgs/Path             per tick (or every ``path_every_s``): planned path (map)
    /gndreplay/path_status std_msgs/String          per tick: "ok", or why there is no path (the planner's
                                                    flags, or the navigation mode that plans none)
    /gndreplay/grid       nav_msgs/OccupancyGrid    ``grid_every``: the robot-centred grid (map), -1 unknown
                                                    / 0 free / 100 occupied
    /gndreplay/map        nav_msgs/OccupancyGrid    once, at the end (stamped with the first tick): every
                                                    scan's hits placed with the corrected pose (``MAP_STEP``)
    /gndreplay/decision   visualization_msgs/MarkerArray per tick (base_link): ``decision_markers``
    /gndreplay/mode, /gndreplay/situation, /gndreplay/flags   std_msgs/String per tick ("|"-joined flags)
    /gndreplay/active_mode, /gndreplay/takeover               std_msgs/String per tick: the navigation mode
                                                    whose command won, and the takeover reason (why the
                                                    active mode is not the desired one, or why the desired
                                                    module stood still, e.g. "teleop: no command"; "" when
                                                    the desired module's own command won)

Every message is a pure function of the log and the configuration (module times are in timing.csv).
"""

from __future__ import annotations

import functools
import math
import shutil
import struct
import tempfile
import weakref
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from .. import detmath as dm
from ..config import Config
from ..geometry import compose, inverse, relative, transform_points
from ..pipeline.model import RobotCentredGrid
from ..pipeline.nd import NdDiagram, sector_angles
from ..pipeline.stack import TickResult
from ..robot import RobotConfig, footprint_outline
from ..types import REFLEXIVE_MODES, Flag, Pose2D, Tick
from .decision import decision_geometry
from .foxglove import LAYOUT_FILE, LayoutSpec, write_layout
from .maps import HitRaster
from .rundir import recorded_flags

__all__ = [
    "MCAP_FILE", "TOPICS", "GridEvery", "Marker", "McapSink", "RosMessages", "decision_markers",
    "grid_to_occupancy", "hits_to_occupancy", "layout_spec", "marker_array_cdr",
    "path_status", "region_labels", "scan_beams",
]

MCAP_FILE = "results.mcap"
TOPICS: dict[str, str] = {
    "/tf": "tf2_msgs/msg/TFMessage",
    "/tf_static": "tf2_msgs/msg/TFMessage",
    "/scan": "sensor_msgs/msg/LaserScan",
    "/odom": "nav_msgs/msg/Odometry",
    "/gndreplay/odom": "nav_msgs/msg/Odometry",
    "/ground_truth": "geometry_msgs/msg/PoseStamped",
    "/cmd_vel": "geometry_msgs/msg/TwistStamped",
    "/cmd_vel_recorded": "geometry_msgs/msg/TwistStamped",
    "/gndreplay/footprint": "geometry_msgs/msg/PolygonStamped",
    "/gndreplay/goal": "geometry_msgs/msg/PoseStamped",
    "/gndreplay/path": "nav_msgs/msg/Path",
    "/gndreplay/path_status": "std_msgs/msg/String",
    "/gndreplay/grid": "nav_msgs/msg/OccupancyGrid",
    "/gndreplay/map": "nav_msgs/msg/OccupancyGrid",
    "/gndreplay/decision": "visualization_msgs/msg/MarkerArray",
    "/gndreplay/mode": "std_msgs/msg/String",
    "/gndreplay/situation": "std_msgs/msg/String",
    "/gndreplay/flags": "std_msgs/msg/String",
    "/gndreplay/active_mode": "std_msgs/msg/String",
    "/gndreplay/takeover": "std_msgs/msg/String",
}
MAP, ODOM, BASE, LASER, TRUTH = "map", "odom", "base_link", "laser", "truth"
GridEvery = int | Literal["change"]
"""How often the robot-centred grid is written: every N-th tick, or each tick it differs from the last."""
MAP_STEP = 25
"""/gndreplay/map's occupancy per hit: a cell hit once is 25, four times or more 100; no hit is -1."""
EVEN_BEAMS = 0.01
"""Beams are evenly spaced when every angle is within this fraction of the increment of the lattice."""
PATH_FLAGS = Flag.PLANNER_NO_PATH | Flag.PLANNER_TIMEOUT | Flag.GOAL_IN_OBSTACLE | Flag.GOAL_REACHED
"""The flags that say why a tick has no planned path."""
_OCCUPANCY = np.array([-1, 0, 100], dtype=np.int8)  # UNKNOWN, FREE, OCCUPIED


def grid_to_occupancy(cells: NDArray[np.uint8]) -> NDArray[np.int8]:
    """(N, M) UNKNOWN / FREE / OCCUPIED cells -> row-major int8 OccupancyGrid data (-1 / 0 / 100)."""
    c = np.asarray(cells)
    if c.ndim != 2 or (c.size and int(c.max()) > 2):
        raise ValueError(f"cells must be 2-D with values 0, 1, 2; got shape {c.shape}")
    return np.take(_OCCUPANCY, c).ravel()


def hits_to_occupancy(hits: NDArray[np.unsignedinteger[Any]]) -> NDArray[np.int8]:
    """(H, W) hit counts -> row-major int8 OccupancyGrid data: ``MAP_STEP`` per hit up to 100, -1 unhit.

    Converted a block of cells at a time, so the only full-size array is the int8 result."""
    h = np.asarray(hits).reshape(-1)
    out = np.empty(h.size, dtype=np.int8)
    block = 1 << 20
    for a in range(0, h.size, block):
        part = h[a : a + block]
        occ = np.minimum(part, -(-100 // MAP_STEP)).astype(np.int16) * MAP_STEP
        out[a : a + block] = np.where(part > 0, np.minimum(occ, 100), -1)
    return out


def scan_beams(angles: NDArray[np.float64],
               ranges: NDArray[np.float64]) -> tuple[float, float, float, NDArray[np.float32]]:
    """A scan as LaserScan's (angle_min, angle_max, angle_increment, ranges).

    Evenly spaced beams (every angle within ``EVEN_BEAMS`` of an increment of the first-to-last lattice)
    keep their ranges as they are, in their order (a negative increment for a clockwise scan). Other beams
    are put on the lattice of their median spacing from the smallest to the largest angle (at most 16
    slots per beam), each in its nearest slot; when two share a slot the nearer return is kept, and a slot
    without a beam (or with invalid beams only) is NaN. +inf (no return) stays +inf."""
    a = np.asarray(angles, dtype=np.float64)
    r = np.asarray(ranges, dtype=np.float64)
    n = a.size
    if n < 2:
        a0 = float(a[0]) if n else 0.0
        return a0, a0, 0.0, r.astype(np.float32)
    inc = float(a[-1] - a[0]) / (n - 1)
    if inc != 0.0 and np.all(np.abs(a - (a[0] + inc * np.arange(n))) <= EVEN_BEAMS * abs(inc)):
        return float(a[0]), float(a[-1]), inc, r.astype(np.float32)
    lo, hi = float(a.min()), float(a.max())
    steps = np.diff(np.unique(a))
    if steps.size == 0:  # every beam at one angle
        return lo, lo, 0.0, np.array([np.nanmin(r) if np.any(~np.isnan(r)) else np.nan], dtype=np.float32)
    m = min(round((hi - lo) / float(np.median(steps))) + 1, 16 * n)
    inc = (hi - lo) / (m - 1)
    slot = np.clip(np.rint((a - lo) / inc).astype(np.intp), 0, m - 1)
    best = np.full(m, np.inf)
    np.minimum.at(best, slot, np.where(np.isnan(r), np.inf, r))
    valid = np.zeros(m, dtype=bool)
    valid[slot[~np.isnan(r)]] = True
    return lo, lo + inc * (m - 1), inc, np.where(valid, best, np.nan).astype(np.float32)


class RosMessages:
    """Planar ROS 2 message builders over a rosbags typestore; ``t`` is int ns."""

    def __init__(self, ts: Any) -> None:
        self.T = ts.types
        self._cov = np.zeros(36, dtype=np.float64)

    def __getitem__(self, name: str) -> Any:
        return self.T[name if "/" in name else f"geometry_msgs/msg/{name}"]

    def stamp(self, t: int) -> Any:
        return self.T["builtin_interfaces/msg/Time"](sec=t // 10**9, nanosec=t % 10**9)

    def hdr(self, t: int, frame: str) -> Any:
        return self.T["std_msgs/msg/Header"](stamp=self.stamp(t), frame_id=frame)

    def v3(self, x: float = 0.0, y: float = 0.0, z: float = 0.0) -> Any:
        return self["Vector3"](x=x, y=y, z=z)

    def quat(self, yaw: float) -> Any:
        return self["Quaternion"](x=0.0, y=0.0, z=dm.sin(yaw / 2), w=dm.cos(yaw / 2))

    def pose(self, x: float, y: float, yaw: float) -> Any:
        return self["Pose"](position=self["Point"](x=x, y=y, z=0.0), orientation=self.quat(yaw))

    def twist(self, v: float, vy: float, w: float) -> Any:
        return self["Twist"](linear=self.v3(x=v, y=vy), angular=self.v3(z=w))

    def tf(self, t: int, *edges: tuple[str, str, float, float, float]) -> Any:
        return self["tf2_msgs/msg/TFMessage"](transforms=[
            self["TransformStamped"](header=self.hdr(t, p), child_frame_id=c, transform=self["Transform"](
                translation=self.v3(x, y), rotation=self.quat(yaw)))
            for p, c, x, y, yaw in edges])

    def odometry(self, t: int, frame: str, pose: Pose2D, v: float, vy: float, w: float) -> Any:
        return self["nav_msgs/msg/Odometry"](
            header=self.hdr(t, frame), child_frame_id=BASE,
            pose=self["PoseWithCovariance"](pose=self.pose(pose.x, pose.y, pose.theta), covariance=self._cov),
            twist=self["TwistWithCovariance"](twist=self.twist(v, vy, w), covariance=self._cov))

    def pose_stamped(self, t: int, frame: str, x: float, y: float, yaw: float) -> Any:
        return self["PoseStamped"](header=self.hdr(t, frame), pose=self.pose(x, y, yaw))

    def twist_stamped(self, t: int, v: float, vy: float, w: float) -> Any:
        return self["TwistStamped"](header=self.hdr(t, BASE), twist=self.twist(v, vy, w))

    def path(self, t: int, xy: NDArray[np.float64]) -> Any:
        p = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        yaw = np.zeros(p.shape[0])
        if p.shape[0] > 1:
            d = np.diff(p, axis=0)
            yaw[:-1] = dm.atan2_a(d[:, 1], d[:, 0])
            yaw[-1] = yaw[-2]
        hdr = self.hdr(t, MAP)
        poses = [self["PoseStamped"](header=hdr, pose=self.pose(x, y, a))
                 for x, y, a in zip(p[:, 0].tolist(), p[:, 1].tolist(), yaw.tolist(), strict=True)]
        return self["nav_msgs/msg/Path"](header=hdr, poses=poses)

    def occupancy(self, t: int, data: NDArray[np.int8], shape: tuple[int, ...],
                  origin_xy: tuple[float, float], cell_m: float) -> Any:
        """An OccupancyGrid in the map frame; ``data`` row-major, row 0 at ``origin_xy`` (minimum y)."""
        info = self["nav_msgs/msg/MapMetaData"](
            map_load_time=self.stamp(t), resolution=float(cell_m), width=int(shape[1]), height=int(shape[0]),
            origin=self.pose(float(origin_xy[0]), float(origin_xy[1]), 0.0))
        return self["nav_msgs/msg/OccupancyGrid"](header=self.hdr(t, MAP), info=info, data=data)

    def grid(self, t: int, cells: NDArray[np.uint8], origin_xy: tuple[float, float], cell_m: float) -> Any:
        return self.occupancy(t, grid_to_occupancy(cells), cells.shape, origin_xy, cell_m)

    def laser_scan(self, t: int, angles: NDArray[np.float64], ranges: NDArray[np.float64], range_min: float,
                   range_max: float) -> Any:
        a0, a1, inc, r = scan_beams(angles, ranges)
        return self["sensor_msgs/msg/LaserScan"](
            header=self.hdr(t, LASER), angle_min=a0, angle_max=a1, angle_increment=inc, time_increment=0.0,
            scan_time=0.0, range_min=float(range_min), range_max=float(range_max), ranges=r,
            intensities=np.zeros(0, dtype=np.float32))

    def polygon(self, t: int, frame: str, xy: NDArray[np.float64]) -> Any:
        pts = [self["Point32"](x=x, y=y, z=0.0) for x, y in np.asarray(xy, dtype=np.float32).tolist()]
        return self["PolygonStamped"](header=self.hdr(t, frame), polygon=self["Polygon"](points=pts))

    def string(self, text: str) -> Any:
        return self.T["std_msgs/msg/String"](data=text)


# ---- markers: visualization_msgs/MarkerArray encoded from arrays ------------------------------------

ARROW, SPHERE, LINE_STRIP, LINE_LIST, TEXT_VIEW_FACING, TRIANGLE_LIST = 0, 2, 4, 5, 9, 11
ADD, DELETEALL = 0, 3
RGBA = tuple[float, float, float, float]
_NO_POINTS = np.zeros((0, 3), dtype=np.float64)


@dataclass(frozen=True, slots=True, eq=False)
class Marker:
    """One visualization_msgs/Marker (pose: identity; lifetime: until replaced; not frame-locked).

    Attributes:
        ns: namespace (one marker per namespace and tick; id 0).
        type: ARROW, SPHERE, LINE_STRIP, LINE_LIST, TEXT_VIEW_FACING or TRIANGLE_LIST.
        points: (K, 3) [m] in the marker's frame.
        colors: (K, 4) RGBA per point, or None for ``color`` throughout.
        color: RGBA.
        scale: line width / arrow shaft, head diameter, head length / sphere size / text height [m].
        position: where a SPHERE or TEXT_VIEW_FACING is placed.
        text: TEXT_VIEW_FACING's text.
        action: ADD, or DELETEALL (clears every marker of the topic).
    """

    ns: str
    type: int
    points: NDArray[np.float64] = field(default_factory=lambda: _NO_POINTS)
    colors: NDArray[np.float32] | None = None
    color: RGBA = (1.0, 1.0, 1.0, 1.0)
    scale: tuple[float, float, float] = (0.02, 0.0, 0.0)
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    text: str = ""
    action: int = ADD


class _Cdr:
    """Little-endian CDR (the ROS 2 serialisation): values aligned to their size from the end of the 4-byte
    encapsulation header; arrays of fixed-size records written whole from numpy."""

    def __init__(self) -> None:
        self.buf = bytearray(b"\x00\x01\x00\x00")

    def align(self, n: int) -> None:
        self.buf += bytes(-(len(self.buf) - 4) % n)

    def pack(self, fmt: str, align: int, *values: float | int | bool) -> None:
        self.align(align)
        self.buf += struct.pack("<" + fmt, *values)

    def string(self, text: str) -> None:
        data = text.encode() + b"\x00"
        self.pack("I", 4, len(data))
        self.buf += data

    def array(self, records: NDArray[Any], align: int) -> None:
        """A sequence of (K, fields) records of one little-endian type."""
        self.pack("I", 4, records.shape[0])
        if records.shape[0]:
            self.align(align)
            self.buf += np.ascontiguousarray(records).tobytes()


_EMPTY = struct.pack("<I", 1) + b"\x00"  # an empty string (4-aligned)
# the unused fields after ``colors`` (whose end is 4-aligned; none of them needs more): texture_resource,
# texture (CompressedImage: header stamp, frame_id, format, data[]), uv_coordinates[] ...
_BEFORE_TEXT = _EMPTY + bytes(3) + bytes(8) + (_EMPTY + bytes(3)) * 2 + bytes(8)
# ... and after ``text``: mesh_resource, mesh_file (filename, data[]), mesh_use_embedded_materials
_AFTER_TEXT = (_EMPTY + bytes(3)) * 2 + bytes(4) + b"\x00"


def _put_marker(c: _Cdr, sec: int, nsec: int, frame: str, m: Marker) -> None:
    c.pack("iI", 4, sec, nsec)
    c.string(frame)
    c.string(m.ns)
    c.pack("iii", 4, 0, m.type, m.action)
    c.pack("10d", 8, *m.position, 0.0, 0.0, 0.0, 1.0, *m.scale)  # pose (position, orientation), scale
    c.pack("4fiI?", 4, *m.color, 0, 0, False)  # color, lifetime 0 (until replaced), frame_locked
    c.array(np.asarray(m.points, dtype="<f8").reshape(-1, 3), 8)
    colors = np.zeros((0, 4)) if m.colors is None else m.colors
    c.array(np.asarray(colors, dtype="<f4").reshape(-1, 4), 4)
    c.buf += _BEFORE_TEXT
    c.string(m.text)
    c.align(4)
    c.buf += _AFTER_TEXT


def marker_array_cdr(t_ns: int, frame: str, markers: list[Marker]) -> bytes:
    """A visualization_msgs/MarkerArray, CDR-serialised (the bytes rosbags' serialiser gives for it, built
    from the point arrays without a Python object per point), every marker stamped ``t_ns`` in ``frame``."""
    c = _Cdr()
    sec, nsec = divmod(int(t_ns), 10**9)
    c.pack("I", 4, len(markers))
    for m in markers:
        _put_marker(c, sec, nsec, frame, m)
    return bytes(c.buf)


_CHOSEN: RGBA = (0.2, 0.8, 0.3, 0.4)
_DANGEROUS: RGBA = (0.95, 0.2, 0.15, 0.5)
_REGIONS = np.array([(0.55, 0.55, 0.6, 0.15), (0.35, 0.35, 0.4, 0.15)], dtype=np.float32)
_GAP: RGBA = (0.85, 0.2, 0.85, 1.0)
_SECURITY: RGBA = (1.0, 0.6, 0.1, 1.0)
_DIRECTION: RGBA = (0.1, 0.45, 1.0, 1.0)
_SWEPT: RGBA = (1.0, 0.85, 0.1, 0.9)
_RULE: RGBA = (1.0, 0.15, 0.1, 1.0)
_Z = 0.02  # markers drawn just above the grids
MARKER_RESOLUTION_M = 1.0 / 1024.0
"""Marker coordinates are multiples of this (under a millimetre): they then compress to a third."""
DIRECTION_M = 1.0
"""Length of the chosen-direction arrow [m]."""
SWEPT_POSES = 6
"""Footprints drawn along the command's arc over its braking horizon (the first now, the last at its end)."""


@functools.lru_cache(maxsize=4)
def _sector_trig(n: int) -> tuple[NDArray[np.float64], ...]:
    """cos and sin of the right and left edges and of the bisector of each of ``n`` ND+ sectors."""
    b = sector_angles(n)
    lo, hi = b - math.pi / n, b + math.pi / n
    return dm.cos_a(lo), dm.sin_a(lo), dm.cos_a(hi), dm.sin_a(hi), dm.cos_a(b), dm.sin_a(b)


def _xyz(x: NDArray[np.float64], y: NDArray[np.float64]) -> NDArray[np.float64]:
    """Marker points at height _Z, rounded to ``MARKER_RESOLUTION_M`` (a short mantissa: they compress)."""
    out = np.empty((x.shape[0], 3))
    out[:, 0], out[:, 1], out[:, 2] = x, y, _Z
    out[:, :2] = np.rint(out[:, :2] / MARKER_RESOLUTION_M) * MARKER_RESOLUTION_M
    return out


def region_labels(gaps: NDArray[np.bool_]) -> NDArray[np.int64]:
    """(n,) the ND+ region of each sector: the spans between consecutive gaps (``gaps[i]``: a gap between
    sector i and i + 1, mod n), numbered from 0; the span through the -pi / pi wrap is one region."""
    g = np.asarray(gaps, dtype=bool)
    labels = np.concatenate([[0], np.cumsum(g[:-1])]).astype(np.int64)
    if g.any() and not g[-1]:  # no gap between the last sector and the first: one region across
        labels[labels == labels[-1]] = 0
    return labels


def decision_markers(result: TickResult, diagram: NdDiagram, sweep: NDArray[np.float64], robot: RobotConfig,
                     max_range_m: float) -> list[Marker]:
    """The tick's decision as markers in the robot frame (``diagram`` and ``sweep``: the tick's
    ``decision.decision_geometry``), after a DELETEALL that clears the previous tick's:

    - ``nd_sectors`` (TRIANGLE_LIST): each ND+ sector as a wedge out to its obstacle (a free one to
      ``max_range_m``); the chosen region (the free walking area) green, sectors whose obstacle is inside
      the security zone red, the other regions (``region_labels``) in alternating greys;
    - ``nd_gaps`` (LINE_LIST): each gap along its sector boundary, from the nearer side to the farther;
    - ``security_zone`` (LINE_STRIP): the security perimeter;
    - ``direction`` (ARROW, ``DIRECTION_M`` long) and ``target`` (SPHERE): where ND+ steered, when it did;
    - ``swept`` (LINE_LIST): the footprint at ``SWEPT_POSES`` poses along the command's arc up to its
      braking horizon (red when a reflexive rule replaced the command; none for a still command);
    - ``rule`` (TEXT_VIEW_FACING): the reflexive rule that fired, when one did."""
    g = diagram
    n = g.bisectors_rad.size
    r = np.where(np.isfinite(g.dist_m), g.dist_m, max_range_m)
    clo, slo, chi, shi, cb, sb = _sector_trig(n)
    origin = _xyz(np.zeros(n), np.zeros(n))
    wedges = np.stack([origin, _xyz(r * clo, r * slo), _xyz(r * chi, r * shi)], axis=1)
    colors = _REGIONS[region_labels(g.gaps) % 2]
    colors[g.region_mask(result.nd_region)] = _CHOSEN
    colors[g.dist_m <= g.security_m] = _DANGEROUS
    gi = np.flatnonzero(g.gaps)  # between sector i and i + 1: along the boundary at hi[i]
    near, far = np.minimum(r[gi], r[(gi + 1) % n]), np.maximum(r[gi], r[(gi + 1) % n])
    gaps = np.stack([_xyz(near * chi[gi], near * shi[gi]), _xyz(far * chi[gi], far * shi[gi])], axis=1)
    ring = np.r_[np.arange(n), 0]
    security = _xyz(g.security_m[ring] * cb[ring], g.security_m[ring] * sb[ring])
    poses = sweep[np.unique(np.rint(np.linspace(0, sweep.shape[0] - 1, min(sweep.shape[0], SWEPT_POSES))))
                  .astype(np.intp)]
    outline = footprint_outline(robot)
    c, s = dm.cos_a(poses[:, 2])[:, None], dm.sin_a(poses[:, 2])[:, None]
    px = poses[:, :1] + c * outline[:, 0] - s * outline[:, 1]
    py = poses[:, 1:2] + s * outline[:, 0] + c * outline[:, 1]
    edges = np.stack([px, py, np.roll(px, -1, axis=1), np.roll(py, -1, axis=1)], axis=-1).reshape(-1, 2)
    mode = str(result.mode.value)
    rule = mode if mode in REFLEXIVE_MODES else ""
    out = [
        Marker("", ARROW, action=DELETEALL),
        Marker("nd_sectors", TRIANGLE_LIST, wedges.reshape(-1, 3), np.repeat(colors, 3, axis=0),
               scale=(1.0, 1.0, 1.0)),
        Marker("nd_gaps", LINE_LIST, gaps.reshape(-1, 3), color=_GAP, scale=(0.04, 0.0, 0.0)),
        Marker("security_zone", LINE_STRIP, security, color=_SECURITY, scale=(0.02, 0.0, 0.0)),
        Marker("swept", LINE_LIST, _xyz(edges[:, 0], edges[:, 1]), color=_RULE if rule else _SWEPT,
               scale=(0.02, 0.0, 0.0)),
    ]
    direction = float(result.direction_rad)
    if math.isfinite(direction):
        tip = _xyz(np.array([0.0, DIRECTION_M * dm.cos(direction)]),
                   np.array([0.0, DIRECTION_M * dm.sin(direction)]))
        out.append(Marker("direction", ARROW, tip, color=_DIRECTION, scale=(0.05, 0.12, 0.15)))
    if result.nd_target_xy is not None:
        tx, ty = result.nd_target_xy
        out.append(Marker("target", SPHERE, color=_DIRECTION, scale=(0.12, 0.12, 0.12),
                          position=(tx, ty, _Z)))
    if rule:
        out.append(Marker("rule", TEXT_VIEW_FACING, color=_RULE, scale=(0.0, 0.0, 0.35),
                          position=(0.0, 0.0, 1.0), text=rule))
    return out


# ---- the layout -------------------------------------------------------------------------------------


def layout_spec() -> LayoutSpec:
    """The Foxglove view of results.mcap: a 3D panel following base_link (scan, grids, footprint, path,
    goal, decision markers, ground truth), v and w of our command against the log's recorded one and the
    measured odometry, the modes and path status over time, the flags and takeover reason as messages."""
    def cloud(color: str) -> dict[str, Any]:
        return {"colorMode": "flat", "flatColor": color, "pointSize": 4}

    return LayoutSpec(
        frame=BASE,
        scene={
            "/gndreplay/map": {"colorMode": "map", "alpha": 0.5},
            "/gndreplay/grid": {"colorMode": "map", "alpha": 0.7},
            "/scan": cloud("#e8412c"),
            "/gndreplay/path": {"type": "line", "lineWidth": 0.04, "gradient": ["#2f7bffff", "#2f7bffff"]},
            "/gndreplay/goal": {"type": "arrow", "color": "#19c37dff"},
            "/gndreplay/footprint": {"color": "#ffffffff", "lineWidth": 0.03},
            "/gndreplay/decision": {},
            "/ground_truth": {"type": "arrow", "color": "#a0a0a0ff"},
        },
        plots=(
            ("v [m/s]", (("/cmd_vel.twist.linear.x", "ours"),
                         ("/cmd_vel_recorded.twist.linear.x", "recorded"),
                         ("/odom.twist.twist.linear.x", "odometry"))),
            ("w [rad/s]", (("/cmd_vel.twist.angular.z", "ours"),
                           ("/cmd_vel_recorded.twist.angular.z", "recorded"),
                           ("/odom.twist.twist.angular.z", "odometry"))),
        ),
        states=(("/gndreplay/mode.data", "mode"), ("/gndreplay/situation.data", "situation"),
                ("/gndreplay/active_mode.data", "active"), ("/gndreplay/path_status.data", "path")),
        raw=("/gndreplay/flags", "/gndreplay/takeover"),
    )


# ---- the sink -----------------------------------------------------------------------------------------


def _latched_qos() -> list[Any]:
    from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime

    inf = QosTime(sec=2147483647, nsec=4294967295)  # ROS 2 "infinite" duration
    return [Qos(QosHistory.KEEP_LAST, 1, QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL, inf, inf,
                QosLiveliness.AUTOMATIC, inf, False)]


def _due(t_ns: int, next_ns: int | None, every_s: float) -> tuple[bool, int | None]:
    """Whether a periodic message is due at ``t_ns``, and the next due time on the lattice
    first + k * every_s (so the rate is 1 / every_s on average, not slower)."""
    if next_ns is not None and t_ns < next_ns:
        return False, next_ns
    step = round(every_s * 1e9)
    if step <= 0:
        return True, None
    nxt = t_ns + step if next_ns is None else next_ns + step
    if nxt <= t_ns:  # a gap longer than the period: restart the lattice here
        nxt = t_ns + step
    return True, nxt


def path_status(result: TickResult) -> str:
    """"ok" when the tick has a planned path, else why not: the planner's flags (``PATH_FLAGS``), or the
    navigation mode when it plans no path ("no planner (teleop)"), else "no path"."""
    if result.path_xy.shape[0]:
        return "ok"
    why = (result.flags & PATH_FLAGS).names()
    if why:
        return "|".join(why)
    return "no path" if result.desired_mode in ("gnd", "follow") else f"no planner ({result.desired_mode})"


class McapSink:
    """A ``RunSink`` writing ``results.mcap`` (topics in the module docstring) and its Foxglove layout.

    The bag is staged in a temporary directory while the replay streams: inside the replay's staging
    directory (``start``, called by ``run_replay``), else under ``staging_dir`` (default the system's);
    ``finish`` moves the file into the run directory. If the replay fails before
    ``finish``, call ``close()`` (or use the sink as a context manager) to remove the staging directory; it
    is also removed when the sink is garbage-collected.

    Args:
        config: the run's configuration: the footprint and the decision markers need the robot, the
            reactor's and the supervisor's settings; without it those two topics are left out.
        grid_every: the robot-centred grid every N-th tick (the first included), or "change": each tick its
            cells or origin differ from the last one written.
        path_every_s: period of the planned-path messages [s of log time]; 0 = every tick.
        map_cell_m: cell side of the accumulated map [m].
        compress: zstd chunk compression.
        staging_dir: where to create the temporary bag folder.
        enforce_budgets: /gndreplay/flags records the flags commands.csv records (``rundir.recorded_flags``):
            without budgets enforced the wall-clock ``*_OVER_BUDGET`` flags are left out. None: the
            ``config``'s setting (False without one).
    """

    def __init__(self, config: Config | None = None, *, grid_every: GridEvery = "change",
                 path_every_s: float = 0.0, map_cell_m: float = 0.05, compress: bool = True,
                 staging_dir: Path | None = None, enforce_budgets: bool | None = None) -> None:
        if grid_every != "change" and not (isinstance(grid_every, int) and grid_every >= 1):
            raise ValueError(f"grid_every must be an integer >= 1 or 'change', got {grid_every!r}")
        if not path_every_s >= 0.0:
            raise ValueError(f"path_every_s must be >= 0, got {path_every_s!r}")
        self.config = config
        self.grid_every = grid_every
        self.path_every_s = path_every_s
        self.compress = compress
        self.staging_dir = staging_dir
        self.enforce_budgets = (config is not None and config.supervisor.enforce_budgets
                                if enforce_budgets is None else enforce_budgets)
        self.counts: dict[str, int] = dict.fromkeys(TOPICS, 0)
        self._map = HitRaster(map_cell_m)
        self._outline = footprint_outline(config.robot) if config is not None else None
        self._writer: Any = None
        self._conns: dict[str, Any] = {}
        self._tmp: Path | None = None
        self._cleanup: weakref.finalize[Any, Any] | None = None
        self._static: list[tuple[str, str, float, float, float]] = []
        self._t0_ns: int | None = None
        self._ticks = 0
        self._prev: tuple[int, NDArray[np.float64], NDArray[np.float64]] | None = None  # t, odom, corrected
        self._last_grid: tuple[NDArray[np.uint8], tuple[float, float]] | None = None
        self._next_path_ns: int | None = None

    # ---- writer lifecycle ---------------------------------------------------------------------------

    def _open(self) -> None:
        from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer
        from rosbags.typesys import Stores, get_typestore

        self._tmp = Path(tempfile.mkdtemp(prefix="gndreplay-mcap-", dir=self.staging_dir))
        self._cleanup = weakref.finalize(self, shutil.rmtree, self._tmp, True)
        self._ts = get_typestore(Stores.ROS2_HUMBLE)
        self._m = RosMessages(self._ts)
        writer = Writer(self._tmp / "results", version=9, storage_plugin=StoragePlugin.MCAP)
        if self.compress:
            writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        writer.open()
        self._writer = writer

    def _conn(self, topic: str) -> Any:
        """The topic's connection, added on its first message (a topic never written is not in the file)."""
        conn = self._conns.get(topic)
        if conn is None:
            qos = _latched_qos() if topic == "/tf_static" else ()
            conn = self._conns[topic] = self._writer.add_connection(
                topic, TOPICS[topic], typestore=self._ts, offered_qos_profiles=qos)
        return conn

    def _put(self, topic: str, t_ns: int, msg: Any) -> None:
        self._write(topic, t_ns, self._ts.serialize_cdr(msg, TOPICS[topic]))

    def _write(self, topic: str, t_ns: int, data: bytes | memoryview) -> None:
        self._writer.write(self._conn(topic), t_ns, data)
        self.counts[topic] += 1

    def close(self) -> None:
        """Close the writer (if open) and remove the staging directory."""
        if self._writer is not None:
            self._writer.close()
            self._writer = None
        if self._cleanup is not None:
            self._cleanup()

    def abort(self) -> None:
        """RunSink hook for a failed replay: close the writer and remove the staging directory (never
        raises: the replay's own error is the one to report)."""
        try:
            self.close()
        except Exception:  # a half-written bag in a folder being removed anyway
            self._writer = None
            if self._cleanup is not None:
                self._cleanup()

    def __enter__(self) -> McapSink:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    # ---- RunSink ------------------------------------------------------------------------------------

    def start(self, staging: Path, target: Path) -> None:
        """``StagedSink`` hook: keep the temporary bag inside the replay's staging directory."""
        self.staging_dir = Path(staging)

    def add_scan(self, tick: Tick, pose_corrected: Pose2D) -> None:
        """Place the scan's hits in the accumulated map with the corrected pose (every scan, also those
        ``every`` skips, as maps.npz does)."""
        scan = tick.scan
        pts = scan.points()
        if pts.shape[0]:
            laser = compose(pose_corrected.as_array(), scan.sensor_pose.as_array())
            self._map.add(transform_points(laser, pts))

    def _static_edges(self, t: int, tick: Tick, pose: Pose2D) -> None:
        """The latched transforms: base_link -> laser at the first tick, map -> truth at the first tick with
        a ground-truth pose (placing it on the corrected pose); /tf_static again with every edge so far
        when one is added."""
        new: list[tuple[str, str, float, float, float]] = []
        if not self._static:
            s = tick.scan.sensor_pose
            new.append((BASE, LASER, s.x, s.y, s.theta))
        if tick.truth is not None and not any(e[1] == TRUTH for e in self._static):
            x, y, yaw = (float(v) for v in compose(pose.as_array(), inverse(tick.truth.as_array())))
            new.append((MAP, TRUTH, x, y, yaw))
        if new:
            self._static += new
            self._put("/tf_static", t, self._m.tf(t, *self._static))

    def _twists(self, t: int, odom: NDArray[np.float64],
                corrected: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(v, vy, w) of the measured and of the corrected pose: the motion since the previous tick over its
        duration, in the robot frame (0 at the first tick)."""
        zero = np.zeros(3)
        prev, self._prev = self._prev, (t, odom, corrected)
        if prev is None or t <= prev[0]:
            return zero, zero
        dt = (t - prev[0]) / 1e9
        return relative(prev[1], odom) / dt, relative(prev[2], corrected) / dt

    def _grid_due(self, grid: RobotCentredGrid) -> bool:
        if self.grid_every != "change":
            return (self._ticks - 1) % self.grid_every == 0
        origin = (float(grid.origin_xy[0]), float(grid.origin_xy[1]))
        last = self._last_grid
        if last is not None and last[1] == origin and np.array_equal(last[0], grid.cells):
            return False
        self._last_grid = (grid.cells.copy(), origin)
        return True

    def add_result(self, tick: Tick, result: TickResult, grid: RobotCentredGrid) -> None:
        """Write the tick's messages (the grid and the path when due)."""
        if self._writer is None:
            self._open()
        m, t = self._m, int(result.t_ns)
        self._ticks += 1
        if self._t0_ns is None:
            self._t0_ns = t
        p, o, c = result.pose_corrected, tick.odom, result.command
        self._static_edges(t, tick, p)
        correction = compose(p.as_array(), inverse(o.as_array()))  # map -> odom
        self._put("/tf", t, m.tf(t, (MAP, ODOM, float(correction[0]), float(correction[1]),
                                     float(correction[2])), (ODOM, BASE, o.x, o.y, o.theta)))
        scan = tick.scan
        self._put("/scan", t, m.laser_scan(t, scan.angles_rad, scan.ranges_m, scan.min_range_m,
                                           scan.max_range_m))
        measured, moved = self._twists(t, o.as_array(), p.as_array())
        self._put("/odom", t, m.odometry(t, ODOM, o, *(float(v) for v in measured)))
        self._put("/gndreplay/odom", t, m.odometry(t, MAP, p, *(float(v) for v in moved)))
        if tick.truth is not None:
            g = tick.truth
            self._put("/ground_truth", t, m.pose_stamped(t, TRUTH, g.x, g.y, g.theta))
        self._put("/cmd_vel", t, m.twist_stamped(t, c.v_mps, c.vy_mps, c.w_radps))
        if tick.cmd is not None:
            r = tick.cmd
            self._put("/cmd_vel_recorded", t, m.twist_stamped(t, r.v_mps, r.vy_mps, r.w_radps))
        if self._outline is not None:
            self._put("/gndreplay/footprint", t, m.polygon(t, BASE, self._outline))
        gx, gy = (float(v) for v in result.goal)
        self._put("/gndreplay/goal", t, m.pose_stamped(t, MAP, gx, gy, 0.0))
        due, self._next_path_ns = _due(t, self._next_path_ns, self.path_every_s)
        if due:
            self._put("/gndreplay/path", t, m.path(t, result.path_xy))
        self._put("/gndreplay/path_status", t, m.string(path_status(result)))
        if self._grid_due(grid):
            self._put("/gndreplay/grid", t, m.grid(t, grid.cells, grid.origin_xy, grid.params.cell_m))
        if self.config is not None:
            cfg = self.config
            diagram, sweep = decision_geometry(grid, result.pose_corrected, result.command, cfg)
            markers = decision_markers(result, diagram, sweep, cfg.robot, cfg.reactor.max_range_m)
            self._write("/gndreplay/decision", t, marker_array_cdr(t, BASE, markers))
        self._put("/gndreplay/mode", t, m.string(str(result.mode.value)))
        self._put("/gndreplay/situation", t, m.string(result.situation.name))
        self._put("/gndreplay/flags", t, m.string("|".join(
            recorded_flags(result.flags, enforce_budgets=self.enforce_budgets).names())))
        self._put("/gndreplay/active_mode", t, m.string(result.active_mode))
        self._put("/gndreplay/takeover", t, m.string(result.takeover_reason))

    def _put_map(self) -> None:
        """The accumulated map, stamped with the first tick so that it shows for the whole run."""
        if self._t0_ns is None or self._map.n_tiles == 0:
            return
        hits, origin = self._map.to_array()
        self._put("/gndreplay/map", self._t0_ns, self._m.occupancy(
            self._t0_ns, hits_to_occupancy(hits), hits.shape, origin, self._map.cell_m))

    def finish(self, run_dir: Path) -> None:
        """Close the bag, move its .mcap file to ``run_dir/results.mcap`` and write the layout
        (``foxglove.LAYOUT_FILE``) for the topics it holds."""
        if self._writer is None:
            self._open()
        assert self._tmp is not None
        self._put_map()
        self._writer.close()
        self._writer = None
        files = sorted((self._tmp / "results").glob("*.mcap"))
        if len(files) != 1:
            raise RuntimeError(f"expected one .mcap file in the staged bag, found {[f.name for f in files]}")
        shutil.move(str(files[0]), str(Path(run_dir) / MCAP_FILE))
        write_layout(Path(run_dir) / LAYOUT_FILE, layout_spec(), self._conns)
        self.close()
