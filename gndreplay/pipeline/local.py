"""Local navigation strategies of the multi-loop paper on a robot-centred polar occupancy map.

API skeleton (being implemented): ``polar_map`` and ``local_command``. ND+ (``nd.nd_step``) stays the
default local navigation; the strategies here are the paper's alternatives.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from ..robot import RobotConfig

__all__ = ["LOCAL_STRATEGIES", "LocalCommand", "LocalParams", "LocalStrategy", "PolarMap", "local_command",
           "polar_map"]

LocalStrategy = Literal["nd", "free-space", "wall-left", "wall-right", "contour"]
LOCAL_STRATEGIES: tuple[str, ...] = ("nd", "free-space", "wall-left", "wall-right", "contour")


@dataclass(frozen=True, slots=True)
class LocalParams:
    """Local navigation settings ([navigation.local])."""

    strategy: LocalStrategy = "nd"


@dataclass(frozen=True, slots=True, eq=False)
class PolarMap:
    """Robot-centred polar occupancy: per sector, the free distance from the footprint boundary [m]."""

    angles_rad: NDArray[np.float64]
    free_m: NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class LocalCommand:
    """A local strategy's motion and the direction it chose (robot frame)."""

    v_mps: float
    vy_mps: float
    w_radps: float
    direction_rad: float


def polar_map(obstacles_xy: NDArray[np.float64], robot: RobotConfig, params: LocalParams) -> PolarMap:
    """The polar occupancy map of obstacle points given in the robot frame."""
    raise NotImplementedError


def local_command(polar: PolarMap, target_xy: NDArray[np.float64] | None, robot: RobotConfig,
                  params: LocalParams) -> LocalCommand:
    """The motion the configured strategy (not "nd") chooses on ``polar``, biased towards ``target_xy``
    (robot frame) when one is given."""
    raise NotImplementedError
