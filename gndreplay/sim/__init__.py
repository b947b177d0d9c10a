"""Simulated worlds and logs (sample logs with ground truth, closed-loop scenarios).

:mod:`.world` holds the geometry (segments, dynamic elements, ray casting, the laser model, footprints);
:mod:`.scenario` the route follower, the odometry error model, named scenarios and :func:`simulate`.
"""

from .scenario import (
    SCENARIOS,
    DriveParams,
    OdometryNoise,
    Scenario,
    SimulatedRun,
    corrupt_odometry,
    follow_route,
    iter_odometry,
    iter_ticks,
    run_scenario,
    simulate,
)
from .world import DynamicElement, LaserModel, MovingPolygon, SwingingDoor, World, cast_rays, simulate_ranges

__all__ = [
    "SCENARIOS",
    "DriveParams",
    "DynamicElement",
    "LaserModel",
    "MovingPolygon",
    "OdometryNoise",
    "Scenario",
    "SimulatedRun",
    "SwingingDoor",
    "World",
    "cast_rays",
    "corrupt_odometry",
    "follow_route",
    "iter_odometry",
    "iter_ticks",
    "run_scenario",
    "simulate",
    "simulate_ranges",
]
