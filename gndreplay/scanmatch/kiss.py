"""kiss-icp adapter: a 2D scan lifted to z = 0 and registered by KISS-ICP (Vizzo et al. 2023).

kiss-icp estimates the laser pose against its own voxel map; by default it predicts with a constant-velocity
model and never sees the odometry (as its authors run it). ``KissParams.odom_prior`` replaces that
prediction with the odometry increment, the same prior the IDC matcher gets. Deskewing needs per-beam
times, which ``Scan`` does not carry, so it is always off. kiss-icp reports neither pairs nor residuals:
``pairs`` is the number of points registered, ``residual_m`` is nan, ``iterations`` 0, and it never fails.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .. import detmath as dm
from ..errors import ScanMatchError
from ..geometry import compose, inverse
from ..types import Pose2D, Scan
from .base import MatchResult

__all__ = ["KissIcpMatcher", "KissParams"]

F64 = NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class KissParams:
    """kiss-icp settings, all explicit (its defaults assume a 100 m outdoor 3D lidar).

    Defaults are the best setting found on the MIT CSAIL and ACES logs (benchmarks/scanmatch.py
    --kiss-sweep): with the odometry prior kiss-icp errs 6-60x less there than without it.
    """

    voxel_m: float = 0.25  # map voxel; registration points are downsampled at 1.5 x voxel
    max_range_m: float = 40.0
    min_range_m: float = 0.1
    max_points_per_voxel: int = 20
    initial_threshold_m: float = 0.5  # adaptive correspondence threshold before any motion is seen
    min_motion_m: float = 0.1  # motion below this does not update the adaptive threshold
    fixed_threshold_m: float | None = None  # set to disable the adaptive threshold
    max_num_iterations: int = 500
    convergence: float = 1e-4
    max_num_threads: int = 1  # process-global TBB limit, set by the first KissICP built
    odom_prior: bool = True  # predict with the odometry increment instead of constant velocity

    def to_config(self) -> Any:
        """The equivalent ``kiss_icp`` config object."""
        from kiss_icp.config.config import (
            AdaptiveThresholdConfig,
            DataConfig,
            MappingConfig,
            RegistrationConfig,
        )
        from kiss_icp.config.parser import KISSConfig

        return KISSConfig(
            data=DataConfig(max_range=self.max_range_m, min_range=self.min_range_m, deskew=False),
            mapping=MappingConfig(voxel_size=self.voxel_m, max_points_per_voxel=self.max_points_per_voxel),
            registration=RegistrationConfig(max_num_iterations=self.max_num_iterations,
                                            convergence_criterion=self.convergence,
                                            max_num_threads=self.max_num_threads),
            adaptive_threshold=AdaptiveThresholdConfig(fixed_threshold=self.fixed_threshold_m,
                                                       initial_threshold=self.initial_threshold_m,
                                                       min_motion_th=self.min_motion_m),
        )


def _se2_to_mat(p: F64) -> F64:
    c, s = dm.cos_a(p[2]), dm.sin_a(p[2])
    m = np.eye(4)
    m[0, 0], m[0, 1], m[1, 0], m[1, 1] = c, -s, s, c
    m[0, 3], m[1, 3] = p[0], p[1]
    return m


def _mat_to_se2(m: F64) -> F64:
    return np.array([m[0, 3], m[1, 3], dm.atan2_a(m[1, 0], m[0, 0])])


class KissIcpMatcher:
    """Stateful kiss-icp corrector; see the module docstring.

    Raises:
        ScanMatchError: kiss-icp is not installed (constructor).
    """

    name = "kiss-icp"

    def __init__(self, params: KissParams | None = None) -> None:
        self.params = params if params is not None else KissParams()
        try:
            from kiss_icp.kiss_icp import KissICP
        except ImportError as err:  # pragma: no cover - kiss-icp is a dependency
            raise ScanMatchError("the kiss-icp matcher needs the kiss-icp package: pip install kiss-icp") \
                from err
        self._kiss = KissICP(self.params.to_config())
        self._origin: F64 | None = None  # laser pose (odometry frame) of the first scan
        self._prev_odom: F64 | None = None
        self._no_times = np.zeros(0, dtype=np.float64)

    def update(self, scan: Scan, odom: Pose2D) -> MatchResult:
        """Register this scan; returns the corrected robot pose (scans in time order)."""
        sensor = scan.sensor_pose.as_array()
        odom_a = odom.as_array()
        pts = scan.points()
        xyz = np.zeros((pts.shape[0], 3))
        xyz[:, :2] = pts
        if self._origin is None:
            self._origin = compose(odom_a, sensor)
        if self.params.odom_prior and self._prev_odom is not None:
            # laser increment predicted by odometry: S⁻¹ (o_prev⁻¹ o) S
            incr = compose(compose(inverse(sensor), compose(inverse(self._prev_odom), odom_a)), sensor)
            self._kiss.last_delta = _se2_to_mat(incr)
        self._prev_odom = odom_a
        _, source = self._kiss.register_frame(xyz, self._no_times)
        laser = compose(self._origin, _mat_to_se2(self._kiss.last_pose))
        pose = compose(laser, inverse(sensor))
        return MatchResult(Pose2D.from_array(pose), True, len(source), float("nan"), 0)
