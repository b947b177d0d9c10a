"""results.mcap: the replay as standard ROS 2 messages (opens in Foxglove, reads back with rosbags).

Written with the rosbags rosbag2 writer (MCAP storage, zstd chunks). The writer produces a bag *folder*; the
sink stages it in a temporary folder inside the replay's staging directory (``start``; nothing in $TMPDIR)
and moves the single ``.mcap`` file to ``run_dir/results.mcap``.

Frames: ``map`` is the corrected odometry frame (scan matching), ``odom`` the raw odometry frame,
``base_link`` the robot, ``laser`` the scanner. Stamps (header and log time) are the tick times.

Topics (per tick = every tick the stack ran):
    /tf                  tf2_msgs/TFMessage         per tick: map -> odom (the correction), odom -> base_link
                                                    (raw odometry); so base_link in map = the corrected pose
    /tf_static           tf2_msgs/TFMessage         once, latched: base_link -> laser
    /gndreplay/odom      nav_msgs/Odometry          per tick: corrected pose (map), commanded twist
    /cmd_vel             geometry_msgs/TwistStamped per tick: v, vy, w (frame base_link)
    /gndreplay/goal      geometry_msgs/PointStamped per tick: the tick's goal (map)
    /gndreplay/path      nav_msgs/Path              per tick (or every ``path_every_s``): planned path (map)
    /gndreplay/grid      nav_msgs/OccupancyGrid     every ``grid_every_s`` (first tick included): the
                                                    robot-centred grid, -1 unknown / 0 free / 100 occupied
    /gndreplay/timing    std_msgs/Float64MultiArray per tick: match, model, planner, reactor [ms]
    /gndreplay/mode, /gndreplay/situation, /gndreplay/flags   std_msgs/String per tick ("|"-joined flags)
    /gndreplay/active_mode, /gndreplay/takeover               std_msgs/String per tick: the navigation mode
                                                    whose command won, and the takeover reason (why the
                                                    active mode is not the desired one, or why the desired
                                                    module stood still, e.g. "teleop: no command"; "" when
                                                    the desired module's own command won)
"""

from __future__ import annotations

import shutil
import tempfile
import weakref
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .. import detmath as dm
from ..geometry import compose, inverse
from ..pipeline.model import RobotCentredGrid
from ..pipeline.stack import MODULES, TickResult
from ..types import Pose2D, Tick
from .rundir import recorded_flags

__all__ = ["MCAP_FILE", "TOPICS", "McapSink", "RosMessages", "grid_to_occupancy"]

MCAP_FILE = "results.mcap"
TOPICS: dict[str, str] = {
    "/tf": "tf2_msgs/msg/TFMessage",
    "/tf_static": "tf2_msgs/msg/TFMessage",
    "/gndreplay/odom": "nav_msgs/msg/Odometry",
    "/cmd_vel": "geometry_msgs/msg/TwistStamped",
    "/gndreplay/goal": "geometry_msgs/msg/PointStamped",
    "/gndreplay/path": "nav_msgs/msg/Path",
    "/gndreplay/grid": "nav_msgs/msg/OccupancyGrid",
    "/gndreplay/timing": "std_msgs/msg/Float64MultiArray",
    "/gndreplay/mode": "std_msgs/msg/String",
    "/gndreplay/situation": "std_msgs/msg/String",
    "/gndreplay/flags": "std_msgs/msg/String",
    "/gndreplay/active_mode": "std_msgs/msg/String",
    "/gndreplay/takeover": "std_msgs/msg/String",
}
MAP, ODOM, BASE, LASER = "map", "odom", "base_link", "laser"
_OCCUPANCY = np.array([-1, 0, 100], dtype=np.int8)  # UNKNOWN, FREE, OCCUPIED


def grid_to_occupancy(cells: NDArray[np.uint8]) -> NDArray[np.int8]:
    """(N, M) UNKNOWN / FREE / OCCUPIED cells -> row-major int8 OccupancyGrid data (-1 / 0 / 100)."""
    c = np.asarray(cells)
    if c.ndim != 2 or (c.size and int(c.max()) > 2):
        raise ValueError(f"cells must be 2-D with values 0, 1, 2; got shape {c.shape}")
    return _OCCUPANCY[c].ravel()


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

    def odom(self, t: int, pose: Pose2D, v: float, vy: float, w: float) -> Any:
        return self["nav_msgs/msg/Odometry"](
            header=self.hdr(t, MAP), child_frame_id=BASE,
            pose=self["PoseWithCovariance"](pose=self.pose(pose.x, pose.y, pose.theta), covariance=self._cov),
            twist=self["TwistWithCovariance"](twist=self.twist(v, vy, w), covariance=self._cov))

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

    def grid(self, t: int, cells: NDArray[np.uint8], origin_xy: tuple[float, float], cell_m: float) -> Any:
        info = self["nav_msgs/msg/MapMetaData"](
            map_load_time=self.stamp(t), resolution=float(cell_m), width=int(cells.shape[1]),
            height=int(cells.shape[0]), origin=self.pose(float(origin_xy[0]), float(origin_xy[1]), 0.0))
        return self["nav_msgs/msg/OccupancyGrid"](header=self.hdr(t, MAP), info=info,
                                                  data=grid_to_occupancy(cells))

    def string(self, text: str) -> Any:
        return self.T["std_msgs/msg/String"](data=text)

    def timing(self, ms: list[float]) -> Any:
        n = len(ms)
        dim = self.T["std_msgs/msg/MultiArrayDimension"](label=",".join(MODULES), size=n, stride=n)
        layout = self.T["std_msgs/msg/MultiArrayLayout"](dim=[dim], data_offset=0)
        return self.T["std_msgs/msg/Float64MultiArray"](layout=layout, data=np.asarray(ms, dtype=np.float64))


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


class McapSink:
    """A ``RunSink`` writing ``results.mcap`` (topics in the module docstring).

    The bag is staged in a temporary directory while the replay streams: inside the replay's staging
    directory (``start``, called by ``run_replay``), else under ``staging_dir`` (default the system's);
    ``finish`` moves the file into the run directory. If the replay fails before
    ``finish``, call ``close()`` (or use the sink as a context manager) to remove the staging directory; it
    is also removed when the sink is garbage-collected.

    Args:
        grid_every_s: period of the OccupancyGrid messages [s of log time] (the first tick always has one).
        path_every_s: period of the planned-path messages [s]; 0 = every tick.
        compress: zstd chunk compression.
        staging_dir: where to create the temporary bag folder.
        enforce_budgets: the run's ``supervisor.enforce_budgets``: /gndreplay/flags records the flags
            commands.csv records (``rundir.recorded_flags``), so without it the wall-clock
            ``*_OVER_BUDGET`` flags are left out and the bag is a pure function of the log and config.
    """

    def __init__(self, *, grid_every_s: float = 1.0, path_every_s: float = 0.0, compress: bool = True,
                 staging_dir: Path | None = None, enforce_budgets: bool = False) -> None:
        if not grid_every_s >= 0.0 or not path_every_s >= 0.0:
            raise ValueError(f"grid_every_s and path_every_s must be >= 0, got {grid_every_s!r}, "
                             f"{path_every_s!r}")
        self.grid_every_s = grid_every_s
        self.path_every_s = path_every_s
        self.compress = compress
        self.staging_dir = staging_dir
        self.enforce_budgets = enforce_budgets
        self.counts: dict[str, int] = dict.fromkeys(TOPICS, 0)
        self._writer: Any = None
        self._conns: dict[str, Any] = {}
        self._tmp: Path | None = None
        self._cleanup: weakref.finalize[Any, Any] | None = None
        self._static_done = False
        self._next_grid_ns: int | None = None
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
        for topic, msgtype in TOPICS.items():
            qos = _latched_qos() if topic == "/tf_static" else ()
            self._conns[topic] = writer.add_connection(topic, msgtype, typestore=self._ts,
                                                       offered_qos_profiles=qos)

    def _put(self, topic: str, t_ns: int, msg: Any) -> None:
        self._writer.write(self._conns[topic], t_ns, self._ts.serialize_cdr(msg, TOPICS[topic]))
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
        """Nothing per scan (the topics follow the ticks the stack ran)."""

    def add_result(self, tick: Tick, result: TickResult, grid: RobotCentredGrid) -> None:
        """Write the tick's messages (and the grid / path when due)."""
        if self._writer is None:
            self._open()
        m, t = self._m, int(result.t_ns)
        if not self._static_done:
            s = tick.scan.sensor_pose
            self._put("/tf_static", t, m.tf(t, (BASE, LASER, s.x, s.y, s.theta)))
            self._static_done = True
        p, c = result.pose_corrected, result.command
        correction = compose(p.as_array(), inverse(tick.odom.as_array()))  # map -> odom
        o = tick.odom
        self._put("/tf", t, m.tf(t, (MAP, ODOM, float(correction[0]), float(correction[1]),
                                     float(correction[2])), (ODOM, BASE, o.x, o.y, o.theta)))
        self._put("/gndreplay/odom", t, m.odom(t, p, c.v_mps, c.vy_mps, c.w_radps))
        twist = m.twist(c.v_mps, c.vy_mps, c.w_radps)
        self._put("/cmd_vel", t, m["TwistStamped"](header=m.hdr(t, BASE), twist=twist))
        gx, gy = (float(v) for v in result.goal)
        goal = m["Point"](x=gx, y=gy, z=0.0)
        self._put("/gndreplay/goal", t, m["PointStamped"](header=m.hdr(t, MAP), point=goal))
        due, self._next_path_ns = _due(t, self._next_path_ns, self.path_every_s)
        if due:
            self._put("/gndreplay/path", t, m.path(t, result.path_xy))
        due, self._next_grid_ns = _due(t, self._next_grid_ns, self.grid_every_s)
        if due:
            self._put("/gndreplay/grid", t, m.grid(t, grid.cells, grid.origin_xy, grid.params.cell_m))
        self._put("/gndreplay/timing", t, m.timing([float(result.timings_ms.get(k, 0.0)) for k in MODULES]))
        self._put("/gndreplay/mode", t, m.string(str(result.mode.value)))
        self._put("/gndreplay/situation", t, m.string(result.situation.name))
        self._put("/gndreplay/flags", t, m.string("|".join(
            recorded_flags(result.flags, enforce_budgets=self.enforce_budgets).names())))
        self._put("/gndreplay/active_mode", t, m.string(result.active_mode))
        self._put("/gndreplay/takeover", t, m.string(result.takeover_reason))

    def finish(self, run_dir: Path) -> None:
        """Close the bag and move its .mcap file to ``run_dir/results.mcap``."""
        if self._writer is None:
            self._open()
        assert self._tmp is not None
        self._writer.close()
        self._writer = None
        files = sorted((self._tmp / "results").glob("*.mcap"))
        if len(files) != 1:
            raise RuntimeError(f"expected one .mcap file in the staged bag, found {[f.name for f in files]}")
        shutil.move(str(files[0]), str(Path(run_dir) / MCAP_FILE))
        self.close()
