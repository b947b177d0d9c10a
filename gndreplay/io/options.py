"""How to read a log: the one set of options every reader, ``open_log`` and ``log_info`` take."""

from __future__ import annotations

from dataclasses import dataclass

from ..errors import ConfigError
from ..types import Pose2D
from .base import check_pose
from .sync import DEFAULT_SYNC, SyncOptions
from .userfile import brief

__all__ = ["DEFAULT_READ", "ReadOptions"]


@dataclass(frozen=True, slots=True)
class ReadOptions:
    """How to open and stream a log (see :func:`gndreplay.io.open_log`).

    Attributes:
        fmt: a ``READERS`` name (or "rosbag") instead of detecting the format from the path.
        scan_topic, odom_topic, cmd_topic, truth_topic: streams to use instead of the auto-detected ones
            (ROS topics, or CARMEN message names such as ``FLASER`` / ``ODOM`` / ``TRUEPOS``).
        strict: a malformed record is an error instead of being skipped and counted.
        default_sensor_pose: the laser pose in the base frame (x [m], y [m], theta [rad]) to use when the
            log does not record one (a CARMEN log without laser offset PARAMs, a ROS bag without a
            base -> laser transform); None keeps the identity there. The read report's
            ``sensor_pose_source`` says which applied.
        sync: reorder and wait bounds of the time synchronisation.

    Raises:
        ConfigError: ``default_sensor_pose`` is not three finite numbers within the bounds of poses.
    """

    fmt: str | None = None
    scan_topic: str | None = None
    odom_topic: str | None = None
    cmd_topic: str | None = None
    truth_topic: str | None = None
    strict: bool = False
    default_sensor_pose: tuple[float, float, float] | None = None
    sync: SyncOptions = DEFAULT_SYNC

    def __post_init__(self) -> None:
        self.sensor_pose_fallback()

    def sensor_pose_fallback(self) -> Pose2D | None:
        """``default_sensor_pose`` as a Pose2D (theta wrapped to (-pi, pi]), or None.

        Raises:
            ConfigError: not three finite numbers within the bounds of poses.
        """
        if self.default_sensor_pose is None:
            return None
        try:
            x, y, theta = (float(v) for v in self.default_sensor_pose)
            return check_pose(x, y, theta, "default sensor pose")
        except (TypeError, ValueError) as err:
            raise ConfigError(f"default sensor pose {brief(self.default_sensor_pose)}: expected x, y, theta, "
                              f"finite and in range ({err})") from err


#: The default options (a module-level instance, so it can be a default argument).
DEFAULT_READ = ReadOptions()
