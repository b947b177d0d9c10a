"""How to read a log: the one set of options every reader, ``open_log`` and ``log_info`` take."""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from typing import Any

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

    def to_dict(self) -> dict[str, Any]:
        """The options as JSON-ready data (summary.json's ``source``); :meth:`from_dict` reads it back."""
        return asdict(self) | {"default_sensor_pose": None if self.default_sensor_pose is None
                               else list(self.default_sensor_pose)}

    @classmethod
    def from_dict(cls, data: Any, where: str = "read options") -> ReadOptions:
        """Options from :meth:`to_dict`'s data.

        Raises:
            ConfigError: not a table of the fields (one line naming ``where`` and the field).
        """
        if not isinstance(data, dict):
            raise ConfigError(f"{where}: expected a table, got {brief(data)}")
        known = {f.name for f in fields(cls)}
        if unknown := [k for k in data if k not in known]:
            raise ConfigError(f"{where}: unknown field {unknown[0]!r}")
        given = dict(data)
        for name in ("fmt", "scan_topic", "odom_topic", "cmd_topic", "truth_topic"):
            if not (given.get(name) is None or isinstance(given[name], str)):
                raise ConfigError(f"{where}: {name} must be text or null, got {brief(given[name])}")
        if not isinstance(given.get("strict", False), bool):
            raise ConfigError(f"{where}: strict must be true or false, got {brief(given['strict'])}")
        pose = given.get("default_sensor_pose")
        if pose is not None:
            if not (isinstance(pose, list) and len(pose) == 3):
                raise ConfigError(f"{where}: default_sensor_pose must be [x, y, theta], got {brief(pose)}")
            given["default_sensor_pose"] = tuple(pose)
        sync = given.get("sync", {})
        bounds = {f.name for f in fields(SyncOptions)}
        if not (isinstance(sync, dict) and all(k in bounds and isinstance(v, int) and not isinstance(v, bool)
                                               for k, v in sync.items())):
            raise ConfigError(f"{where}: sync must be a table of integers, got {brief(sync)}")
        given["sync"] = SyncOptions(**sync)
        return cls(**given)

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
