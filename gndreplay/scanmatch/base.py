"""The matcher contract shared by every scan matcher, and the raw-odometry matcher."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

from ..types import Pose2D, Scan

__all__ = ["MatchResult", "Matcher", "OdomMatcher"]


@dataclass(frozen=True, slots=True)
class MatchResult:
    """The outcome of one scan.

    Attributes:
        pose: corrected robot (base) pose in the corrected odometry frame for this scan. When ``ok`` is
            False it is the previous corrected pose composed with the odometry increment (the IDC matcher
            uses constant velocity instead while it sees the odometry stalled, see IdcMatcher._priors).
        ok: False when the match failed (the stack raises MATCH_FAILED).
        pairs: correspondences used by the final estimate (0 when nothing was matched).
        residual_m: mean distance of those pairs after alignment [m] (nan when not applicable).
        iterations: iterations run.
        reason: why the match failed ("" when ok), e.g. ``"too few pairs: 12 < 40"``.
    """

    pose: Pose2D
    ok: bool
    pairs: int
    residual_m: float
    iterations: int
    reason: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {"x": self.pose.x, "y": self.pose.y, "theta": self.pose.theta, "ok": self.ok,
                "pairs": self.pairs, "residual_m": self.residual_m, "iterations": self.iterations,
                "reason": self.reason}


@runtime_checkable
class Matcher(Protocol):
    """A stateful odometry corrector: called once per scan, in time order.

    ``update(scan, odom)`` takes the scan and the raw odometry pose at its stamp and returns the corrected
    robot pose. The first scan's corrected pose is its odometry pose.
    """

    name: str

    def update(self, scan: Scan, odom: Pose2D) -> MatchResult: ...


class OdomMatcher:
    """Raw odometry: the "corrected" pose is the odometry pose (the baseline every matcher must beat)."""

    name = "odom"

    def update(self, scan: Scan, odom: Pose2D) -> MatchResult:
        return MatchResult(odom, True, 0, float("nan"), 0)
