"""The world at the start of a run: is the task well posed? The robot's footprint must not touch anything
at its start, and the goal must not lie inside an obstacle that stays, unless the scenario says
``expect: unreachable`` (a test of how the stack faces an impossible task)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from ..errors import ConfigError
from .geometry import Shapes, footprint_clearance

__all__ = ["Task", "WorldSnapshots", "check_endpoints"]
F64 = NDArray[np.float64]


class _Element(Protocol):
    @property
    def remove_s(self) -> float | None: ...

    @property
    def door(self) -> tuple[object, ...]: ...


class Task(Protocol):
    """What the checks read of a scenario (``scenario_file.ScenarioSpec``)."""

    @property
    def source(self) -> str: ...

    @property
    def start(self) -> tuple[float, float, float]: ...

    @property
    def goal(self) -> tuple[float, float]: ...

    @property
    def expect(self) -> str: ...

    @property
    def elements(self) -> Sequence[_Element]: ...

    def element_ids(self) -> list[str]: ...


class WorldSnapshots(Protocol):
    """A world over time: its shapes at ``t_s`` with the movers at ``mover_xy`` (the closed loop's)."""

    mover_xy: F64

    def shapes(self, t_s: float, mover_xy: F64) -> Shapes: ...


def check_endpoints(spec: Task, world: WorldSnapshots | Shapes, local: F64 | None, radius_m: float,
                    contact_m: float) -> None:
    """Refuse a scenario whose start or goal is in an obstacle of ``world`` at t = 0 (movers included).

    Args:
        local: the footprint's vertices in the robot frame (None: a disc of ``radius_m``).
        contact_m: the simulator's contact distance: a start clearance at or below it is a contact, a goal
            that close to (or inside) an element present from the start and never removed nor moved (a
            door leaf) is inside an obstacle.

    Raises:
        ConfigError: one line naming the scenario file, the point and the element.
    """
    if spec.expect == "unreachable":
        return
    shapes = world if isinstance(world, Shapes) else world.shapes(0.0, world.mover_xy)
    ids = spec.element_ids()
    c = footprint_clearance(spec.start, local, radius_m, shapes)
    if c.distance_m <= contact_m:
        x, y, th = spec.start
        raise ConfigError(f"{spec.source}: start: the robot at ({x:g}, {y:g}, {th:g}) touches "
                          f"{_name(ids, c.element)} (clearance {c.distance_m:.3g} m); a scenario about an "
                          "impossible task says expect: unreachable")
    fixed = [i for i, e in enumerate(spec.elements) if e.remove_s is None and not e.door]
    gx, gy = spec.goal
    g = footprint_clearance((gx, gy, 0.0), None, 0.0, shapes.of_elements(fixed))
    if g.distance_m <= contact_m:
        raise ConfigError(f"{spec.source}: goal: ({gx:g}, {gy:g}) is inside {_name(ids, g.element)}; a "
                          "scenario about an impossible task says expect: unreachable")


def _name(ids: list[str], element: int) -> str:
    return repr(ids[element]) if 0 <= element < len(ids) else "an element"
