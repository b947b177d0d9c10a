"""Simulated worlds and logs (sample logs with ground truth, closed-loop scenarios).

:mod:`.world` holds the segment geometry of the scripted sample (ray casting, the laser model, footprints);
:mod:`.scenario` the route follower, the odometry error model, named scenarios and :func:`simulate`.
Closed loop: :mod:`.scenario_file` reads scenario YAML files, :mod:`.geometry` the exact shapes and
kernels, :mod:`.closedloop` drives the stack in the world, :mod:`.teleop` is the scripted operator of
teleop scenarios, :mod:`.runner` writes the run directory (:func:`simulate_scenario`).
"""

from .closedloop import ClosedLoop, SimParams
from .runner import SimOutcome, simulate_scenario
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
from .scenario_file import ScenarioSpec, load_scenario, resolve_scenario, shipped_scenarios
from .world import DynamicElement, LaserModel, MovingPolygon, SwingingDoor, World, cast_rays, simulate_ranges

__all__ = [
    "SCENARIOS",
    "ClosedLoop",
    "DriveParams",
    "DynamicElement",
    "LaserModel",
    "MovingPolygon",
    "OdometryNoise",
    "Scenario",
    "ScenarioSpec",
    "SimOutcome",
    "SimParams",
    "SimulatedRun",
    "SwingingDoor",
    "World",
    "cast_rays",
    "corrupt_odometry",
    "follow_route",
    "iter_odometry",
    "iter_ticks",
    "load_scenario",
    "resolve_scenario",
    "run_scenario",
    "shipped_scenarios",
    "simulate",
    "simulate_ranges",
    "simulate_scenario",
]
