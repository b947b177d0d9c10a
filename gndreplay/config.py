"""Run configuration (integration in progress): the robot description is re-exported from robot.py."""

from __future__ import annotations

from .robot import WHEELCHAIR_ROBOT, XR4000_ROBOT, RobotConfig

__all__ = ["WHEELCHAIR_ROBOT", "XR4000_ROBOT", "RobotConfig"]
