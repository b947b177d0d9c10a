"""The vehicle description shared by C-space, the ND+ reactor and the supervisor."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

__all__ = ["WHEELCHAIR_ROBOT", "XR4000_ROBOT", "RobotConfig"]


@dataclass(frozen=True, slots=True)
class RobotConfig:
    """The vehicle: shape, kinematics, limits and laser mounting.

    Attributes:
        shape: "circle" (radius_m) or "rectangle" (front_m + rear_m long, width_m wide).
        radius_m: circle radius [m].
        width_m: rectangle width [m].
        front_m: distance from the rotation centre (driving axle) forward to the front edge [m].
        rear_m: distance from the rotation centre backward to the rear edge [m].
        drive: "differential" (v, w) or "holonomic" (vx, vy, w).
        vmax_mps, wmax_radps: velocity limits.
        laser_x_m, laser_y_m, laser_theta_rad: laser pose in the robot frame (used when the log gives none).
    """

    shape: Literal["circle", "rectangle"] = "rectangle"
    radius_m: float = 0.3
    width_m: float = 0.7
    # choice: the wheelchair paper gives 1.2 x 0.7 m, driving wheels in the back and the laser at the
    # front, 0.72 m ahead of the axle; we put the axle 0.4 m from the rear edge (0.8 m to the front).
    front_m: float = 0.8
    rear_m: float = 0.4
    drive: Literal["differential", "holonomic"] = "differential"
    vmax_mps: float = 0.3
    wmax_radps: float = 0.5
    laser_x_m: float = 0.72
    laser_y_m: float = 0.0
    laser_theta_rad: float = 0.0

    @property
    def inner_radius_m(self) -> float:
        """Radius of the largest circle about the rotation centre inside the footprint (C-space dilation)."""
        return self.radius_m if self.shape == "circle" else self.width_m / 2.0

    @property
    def outer_radius_m(self) -> float:
        """Radius of the smallest circle about the rotation centre that contains the footprint."""
        if self.shape == "circle":
            return self.radius_m
        return float((max(self.front_m, self.rear_m) ** 2 + (self.width_m / 2.0) ** 2) ** 0.5)


WHEELCHAIR_ROBOT = RobotConfig()
XR4000_ROBOT = RobotConfig(
    shape="circle", radius_m=0.3, drive="holonomic", vmax_mps=0.5, wmax_radps=1.57,
    laser_x_m=0.0, front_m=0.3, rear_m=0.3, width_m=0.6,
)

