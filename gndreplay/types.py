"""The records that flow between stages: Pose2D, Scan, Odometry, Command, Subgoal, Tick; the tick's
exception ``Flag`` and the ``Mode`` that produced its command, with their groups.

Times are int nanoseconds (``t_ns``) everywhere inside; ``t_s`` properties convert at the edges. Every
record is a frozen dataclass; arrays inside are not copied, treat them as read-only.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from . import detmath as dm
from .geometry import wrap_angle, wrap_scalar

__all__ = [
    "BUDGET_FLAGS",
    "REFLEXIVE_MODES",
    "Command",
    "Flag",
    "Mode",
    "Odometry",
    "Pose2D",
    "Scan",
    "Subgoal",
    "SubgoalKind",
    "Tick",
]

NS_PER_S = 1_000_000_000


class Flag(enum.IntFlag):
    """Exception flags a tick can raise (several at once). Names are what reports and CSVs show."""

    NONE = 0
    MATCH_FAILED = enum.auto()
    PLANNER_NO_PATH = enum.auto()
    PLANNER_TIMEOUT = enum.auto()
    GOAL_IN_OBSTACLE = enum.auto()
    REACTOR_NO_REGION = enum.auto()
    EMERGENCY_STOP = enum.auto()
    STALE_SCAN = enum.auto()
    TRAP_DETECTED = enum.auto()
    GOAL_REACHED = enum.auto()
    MATCH_OVER_BUDGET = enum.auto()
    MODEL_OVER_BUDGET = enum.auto()
    PLANNER_OVER_BUDGET = enum.auto()
    REACTOR_OVER_BUDGET = enum.auto()
    PLANNER_FALLBACK = enum.auto()  # the tunnel planner's node search failed; NF1's complete plan was used

    def names(self) -> list[str]:
        """Member names set in this value, in declaration order (stable for CSV output). Tested on the
        integer value: every tick's CSV rows ask, and the enum's own ``&`` builds a member each time."""
        value = int(self)
        return [name for bit, name in _FLAG_BITS if value & bit == bit]


_FLAG_BITS: tuple[tuple[int, str], ...] = tuple((int(m), str(m.name)) for m in Flag if m.value and m.name)
"""(value, name) of the single flags, in declaration order (``Flag.names``)."""


#: Flags that depend on wall-clock time: recorded in timing.csv, not in commands.csv (unless enforced).
BUDGET_FLAGS = (
    Flag.MATCH_OVER_BUDGET | Flag.MODEL_OVER_BUDGET | Flag.PLANNER_OVER_BUDGET | Flag.REACTOR_OVER_BUDGET
)


class Mode(enum.Enum):
    """What produced the tick's command (GND modes, then reflexive overrides)."""

    MPND = "mpND"  # planner OK, reactor follows the instantaneous path direction
    MND = "mND"  # planner failed, reactor goes to the goal itself
    ROTATE = "ROTATE"  # reactor found no free walking area: stop and rotate
    EMERGENCY = "EMERGENCY"  # reflexive: every admissible command would touch an obstacle, stop
    SAFE_SLOW = "SAFE_SLOW"  # reflexive: the command would touch; a slower motion along the same arc
    SAFE_TURN = "SAFE_TURN"  # reflexive: the command would touch; straight on, or the other turn direction
    # (or, travelling into stale blind space, a turn in place towards it: turn first)
    SAFE_REVERSE = "SAFE_REVERSE"  # reflexive: the command would touch; a short reverse through known free
    STALE = "STALE"  # reflexive: sensor data too old, stop
    ESCAPE = "ESCAPE"  # reflexive: trap escape, a manoeuvre of arcs and turns (rectangle) or slow straight
    GOAL = "GOAL"  # goal reached, stop
    TELEOP = "TELEOP"  # multi-loop: the driver's command, unchanged
    FOLLOW = "FOLLOW"  # multi-loop: the path follower's command, unchanged
    LOCAL = "LOCAL"  # multi-loop: a local navigation strategy's command (ND+ itself reports mND / ROTATE)


#: The reflexive loop's overrides (the audit's "emergencies"): the rule that replaced or stopped a command.
REFLEXIVE_MODES: tuple[str, ...] = tuple(m.value for m in (
    Mode.EMERGENCY, Mode.SAFE_SLOW, Mode.SAFE_TURN, Mode.SAFE_REVERSE, Mode.STALE, Mode.ESCAPE))


@dataclass(frozen=True, slots=True)
class Pose2D:
    """A planar pose: x, y [m], theta [rad] wrapped to (-pi, pi]."""

    x: float
    y: float
    theta: float

    @staticmethod
    def from_array(a: NDArray[np.float64]) -> Pose2D:
        return Pose2D(float(a[0]), float(a[1]), float(wrap_angle(a[2])))

    def as_array(self) -> NDArray[np.float64]:
        return np.array([self.x, self.y, self.theta], dtype=np.float64)

    def compose(self, other: Pose2D) -> Pose2D:
        """self ∘ other (``geometry.compose`` in scalars: the same bits)."""
        c, s = dm.cos(self.theta), dm.sin(self.theta)
        return Pose2D(self.x + c * other.x - s * other.y, self.y + s * other.x + c * other.y,
                      wrap_scalar(wrap_scalar(self.theta + other.theta)))

    def inverse(self) -> Pose2D:
        """``geometry.inverse`` in scalars: the same bits."""
        c, s = dm.cos(self.theta), dm.sin(self.theta)
        return Pose2D(-(c * self.x + s * self.y), s * self.x - c * self.y,
                      wrap_scalar(wrap_scalar(-self.theta)))

    def to_local(self, x: float, y: float) -> tuple[float, float]:
        """The world point (x, y) in this pose's frame: ``transform_points(inverse(pose), [(x, y)])`` in
        scalars, the same bits."""
        inv = self.inverse()
        c, s = dm.cos(inv.theta), dm.sin(inv.theta)
        return inv.x + c * x - s * y, inv.y + s * x + c * y


IDENTITY = Pose2D(0.0, 0.0, 0.0)


@dataclass(frozen=True, slots=True, eq=False)
class Scan:
    """One 2D laser scan in the sensor frame.

    Attributes:
        t_ns: sensor time of the scan (header stamp / CARMEN ipc_timestamp), int ns.
        ranges_m: (N,) float64. A finite value in [min_range_m, max_range_m) is a hit; ``+inf`` is a
            no-return beam (at/beyond max range, or the log's no-return marker); ``nan`` is an invalid
            beam (negative, below min range, corrupt). Neither inf nor nan adds an obstacle.
        angles_rad: (N,) float64 beam bearings in the sensor frame, counter-clockwise, 0 ahead.
        max_range_m: the sensor's maximum range [m].
        min_range_m: the sensor's minimum range [m].
        sensor_pose: the laser pose in the robot (base) frame.
    """

    t_ns: int
    ranges_m: NDArray[np.float64]
    angles_rad: NDArray[np.float64]
    max_range_m: float
    min_range_m: float = 0.0
    sensor_pose: Pose2D = IDENTITY

    def __post_init__(self) -> None:
        # numba kernels index both arrays by beam without bounds checks
        if self.ranges_m.ndim != 1 or self.ranges_m.shape != self.angles_rad.shape:
            raise ValueError(f"scan at {self.t_ns} ns: ranges of shape {self.ranges_m.shape} but angles of "
                             f"shape {self.angles_rad.shape}")

    @property
    def t_s(self) -> float:
        return self.t_ns / NS_PER_S

    @property
    def hits(self) -> NDArray[np.bool_]:
        """(N,) mask of beams that returned an obstacle."""
        return np.isfinite(self.ranges_m)

    def points(self) -> NDArray[np.float64]:
        """(M, 2) hit points in the sensor frame."""
        ok = self.hits
        r, a = self.ranges_m[ok], self.angles_rad[ok]
        return np.column_stack([r * dm.cos_a(a), r * dm.sin_a(a)])


@dataclass(frozen=True, slots=True)
class Odometry:
    """A robot odometry sample: pose in the odometry frame, optional twist (v [m/s], w [rad/s])."""

    t_ns: int
    pose: Pose2D
    v_mps: float = float("nan")
    w_radps: float = float("nan")


@dataclass(frozen=True, slots=True)
class Command:
    """A velocity command: forward v [m/s], lateral vy [m/s] (holonomic only), turn rate w [rad/s]."""

    t_ns: int
    v_mps: float
    w_radps: float
    vy_mps: float = 0.0


SubgoalKind = Literal["stop", "forward", "reverse"]
"""How a subgoal is reached (the multi-loop paper): at rest, or passing with the heading asked, driving
forwards or backwards."""


@dataclass(frozen=True, slots=True)
class Subgoal:
    """One subgoal of the functional loop: a pose (x, y [m], theta [rad]) in the corrected odometry frame
    and how to reach it."""

    x: float
    y: float
    theta: float
    kind: SubgoalKind = "forward"


@dataclass(frozen=True, slots=True, eq=False)
class Tick:
    """One step of a replay: a scan with the odometry interpolated at its stamp.

    Attributes:
        index: 0-based position in the time-ordered stream.
        t_ns: the scan's sensor time.
        scan: the scan.
        odom: robot pose in the odometry frame at ``t_ns`` (interpolated).
        cmd: the last recorded velocity command at or before ``t_ns``, if the log has any.
        truth: a ground-truth / reference pose at ``t_ns`` if the log has one.
    """

    index: int
    t_ns: int
    scan: Scan
    odom: Pose2D
    cmd: Command | None = None
    truth: Pose2D | None = None
    extra: dict[str, float] = field(default_factory=dict)

    @property
    def t_s(self) -> float:
        return self.t_ns / NS_PER_S
