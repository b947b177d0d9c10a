"""The vehicle description shared by C-space, the ND+ reactor and the supervisor."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from . import detmath as dm

__all__ = [
    "CIRCLE_VERTICES", "COMPACT_LASER", "COMPACT_ROBOT", "WHEELCHAIR_LASER", "WHEELCHAIR_ROBOT",
    "XR4000_LASER", "XR4000_ROBOT", "LaserConfig", "RobotConfig", "footprint_outline",
]


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
        accel_mps2, alpha_radps2: acceleration limits (linear, angular); they set the braking horizon and
            bound the simulated motion.
        tau_v_s, tau_w_s: time constants of the drive's first-order velocity response (linear, angular)
            [s]: the simulated base follows a command step by 63 % in tau (``gndreplay.sim.dynamics``).
        laser_x_m, laser_y_m, laser_theta_rad: laser pose in the robot frame: where the simulator mounts
            the laser, and, with ``mounting_fallback``, the mounting of a replayed log that records none.
        mounting_fallback: read a log that records no laser mounting (a CARMEN log without laser offset
            PARAMs, a bag without a base -> laser transform) with this robot's laser pose; false reads it
            with the laser at the rotation centre (a log of another robot: this robot's mounting would be
            wrong for it). A log's own mounting always wins; the read report says which applied.

    The allowed range of every field (and ``front_m + rear_m > 0`` for a rectangle) is checked when a
    configuration is loaded: ``gndreplay.config.RANGES`` and ``CROSS_CHECKS``.
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
    # choice: the wheelchair paper gives no acceleration; a chair carrying a person accelerates gently
    accel_mps2: float = 0.5
    alpha_radps2: float = 1.0
    # choice: a powered wheelchair's controller smooths the joystick; 0.3 s is a gentle, typical response
    tau_v_s: float = 0.3
    tau_w_s: float = 0.3
    laser_x_m: float = 0.72
    laser_y_m: float = 0.0
    laser_theta_rad: float = 0.0
    mounting_fallback: bool = False

    @property
    def laser_pose(self) -> tuple[float, float, float]:
        """The laser pose in the robot frame (x [m], y [m], theta [rad])."""
        return (self.laser_x_m, self.laser_y_m, self.laser_theta_rad)

    @property
    def inner_radius_m(self) -> float:
        """Radius of the largest circle about the rotation centre inside the footprint (C-space dilation)."""
        return self.radius_m if self.shape == "circle" else self.width_m / 2.0

    @property
    def inscribed_radius_m(self) -> float:
        """Radius of the largest circle about the rotation centre inside the footprint, whatever its
        dimensions (a rectangle's rear or front edge may be nearer than half its width)."""
        if self.shape == "circle":
            return self.radius_m
        return min(self.width_m / 2.0, self.front_m, self.rear_m)

    @property
    def outer_radius_m(self) -> float:
        """Radius of the smallest circle about the rotation centre that contains the footprint."""
        if self.shape == "circle":
            return self.radius_m
        lon, lat = max(self.front_m, self.rear_m), self.width_m / 2.0
        return math.sqrt(lon * lon + lat * lat)


WHEELCHAIR_ROBOT = RobotConfig()
# GND paper: accelerations of up to 1.5 m/s^2 (the angular limit is a choice; so are the time constants:
# 0.2 s, a servo-controlled research base, stiffer than the chair)
XR4000_ROBOT = RobotConfig(
    shape="circle", radius_m=0.3, drive="holonomic", vmax_mps=0.5, wmax_radps=1.57,
    accel_mps2=1.5, alpha_radps2=3.0, tau_v_s=0.2, tau_w_s=0.2, laser_x_m=0.0, front_m=0.3, rear_m=0.3,
    width_m=0.6,
)
# a small fast outdoor-capable differential base (**choice**, a generic research platform of its class):
# 0.508 x 0.43 m, turning about its centre, up to 2 m/s and 4 rad/s; accelerations and time constants of
# a stiff geared base (2 m/s^2, 6 rad/s^2, 0.1 s), the laser 0.12 m ahead of the centre on the top plate
COMPACT_ROBOT = RobotConfig(
    shape="rectangle", width_m=0.43, front_m=0.254, rear_m=0.254, drive="differential", vmax_mps=2.0,
    wmax_radps=4.0, accel_mps2=2.0, alpha_radps2=6.0, tau_v_s=0.1, tau_w_s=0.1, laser_x_m=0.12,
)


@dataclass(frozen=True, slots=True)
class LaserConfig:
    """The robot's 2D laser as the simulator renders it (a replayed log brings its own geometry).

    The mounting is ``RobotConfig.laser_x_m / laser_y_m / laser_theta_rad`` (one place for it).

    Attributes:
        beams: readings per scan, evenly spread over ``fov_deg`` (first beam at -fov/2, right to left).
        fov_deg: field of view [deg].
        max_range_m: readings at or beyond this are no-returns [m].
        noise_std_m: standard deviation of the Gaussian range noise [m].
        dropout_prob: probability that a beam returns nothing although it hits something (real lasers
            drop single beams on dark or glancing surfaces; the model builder must not clear through them).
        period_s: time between scans [s].

    Allowed ranges: ``gndreplay.config.RANGES``.
    """

    beams: int = 361
    fov_deg: float = 180.0
    max_range_m: float = 32.0
    noise_std_m: float = 0.01
    dropout_prob: float = 0.002
    period_s: float = 0.2


# the papers' SICK: 180 deg, 361 beams (0.5 deg), 32 m; 0.2 s on the chair, 0.15 s on the XR4000
WHEELCHAIR_LASER = LaserConfig()
XR4000_LASER = LaserConfig(period_s=0.15)
# the compact base's 270 deg laser: 720 beams (0.375 deg), 30 m, 20 Hz
COMPACT_LASER = LaserConfig(beams=720, fov_deg=270.0, max_range_m=30.0, period_s=0.05)


CIRCLE_VERTICES = 32
"""Vertices of a circular footprint's outline."""


def footprint_outline(robot: RobotConfig) -> NDArray[np.float64]:
    """(K, 2) vertices of the footprint in the robot frame, counter-clockwise (a 32-gon for a circle)."""
    if robot.shape == "circle":
        a = np.arange(CIRCLE_VERTICES) * (2.0 * math.pi / CIRCLE_VERTICES)
        return np.column_stack([robot.radius_m * dm.cos_a(a), robot.radius_m * dm.sin_a(a)])
    hw = robot.width_m / 2.0
    return np.array([[robot.front_m, -hw], [robot.front_m, hw], [-robot.rear_m, hw], [-robot.rear_m, -hw]])
