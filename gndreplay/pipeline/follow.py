"""The functional loop of the multi-loop paper: path manager, trajectory generator and tracking controller.

API skeleton (being implemented): ``PathFollower.step``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..robot import RobotConfig
from ..types import Pose2D, Subgoal
from .model import RobotCentredGrid

__all__ = ["FollowCommand", "FollowParams", "PathFollower"]


@dataclass(frozen=True, slots=True)
class FollowParams:
    """Path following settings ([navigation.follow])."""

    reach_m: float = 0.2


@dataclass(frozen=True, slots=True, eq=False)
class FollowCommand:
    """What the path follower would command this tick, and what the path manager did.

    Attributes:
        v_mps, w_radps: the tracking controller's command.
        subgoal_index: index of the current subgoal (len(subgoals) once the path is executed).
        done: the final subgoal is reached.
        event: "" or what the path manager did this tick: "reached", "skipped", "replaced", "replanned".
        target_xy: the point (corrected frame) the follower is heading to: local navigation's target when
            it takes over.
        trajectory_xy: (K, 2) the current smooth trajectory to the subgoal (corrected frame).
    """

    v_mps: float
    w_radps: float
    subgoal_index: int
    done: bool
    event: str
    target_xy: tuple[float, float]
    trajectory_xy: NDArray[np.float64] = field(repr=False)


class PathFollower:
    """Tracks a list of subgoals; state: the current subgoal, its trajectory."""

    def __init__(self, subgoals: Sequence[Subgoal], params: FollowParams, robot: RobotConfig, *,
                 inflate_m: float, unknown_is_free: bool = True) -> None:
        self.subgoals = list(subgoals)
        self.params = params
        self.robot = robot

    def step(self, pose: Pose2D, grid: RobotCentredGrid) -> FollowCommand:
        """The follower's command at ``pose`` (corrected frame) with the current model."""
        raise NotImplementedError
