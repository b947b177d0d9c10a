"""The global planners by name: ``PLANNERS`` maps a ``[planner] kind`` to how that planner is built, and
``PlannerParams`` is the ``[planner]`` section: the kind, the settings every planner shares and one table of
settings per planner.

A planner is a module of its own implementing ``planner.Planner``; it joins with its ``PLANNERS`` entry and
its table here (a ``PlannerParams`` field, read from ``[planner.<table>]``). This module sits above the
planners (they import ``planner``, the protocol they implement), so the registry is not in ``planner``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import did_you_mean
from .cspace import free_cspace
from .model import UNKNOWN
from .nf1 import Nf1Params, Nf1Planner, plan
from .planner import Planner, RouteParams
from .tunnel import TunnelParams, TunnelPlanner, warm_up_planners

__all__ = ["PLANNERS", "PlannerGeometry", "PlannerParams", "PlannerSpec"]


@dataclass(frozen=True, slots=True)
class PlannerGeometry:
    """What every planner is built with besides its own settings: the grid, the robot and the ``[planner]``
    settings all planners share.

    Attributes:
        cell_m: cell side [m].
        inner_radius_m: the robot's inner radius (half its width for a rectangle) [m].
        cspace_margin_m: the ``[cspace]`` margin added to it for NF1's C-space [m] (the tunnel planner has
            its own).
        unknown_is_free: plan through UNKNOWN cells.
        route: the look-ahead of the course and the route hysteresis.
    """

    cell_m: float
    inner_radius_m: float
    cspace_margin_m: float
    unknown_is_free: bool
    route: RouteParams


def _no_warm_up(settings: Any, size_cells: int) -> None:
    """A planner whose kernels the stack's own warm-up ticks already compile."""


@dataclass(frozen=True, slots=True)
class PlannerSpec:
    """How the stack makes one planner (``PLANNERS``).

    Attributes:
        section: the ``PlannerParams`` field holding the planner's own settings (``[planner.<section>]``).
        build: the planner from those settings and the geometry.
        warm_up: compiles (or loads) the planner's kernels before the first timed tick, given those settings
            and the grid's side in cells (``stack.warm_up``).
        follows_grid: the planner's ``plan`` takes ``offset_rc``, the grid's world cell, and follows its
            C-space from tick to tick (``planner.Planner``); a planner without it is asked without it.
        avoids: the planner's ``plan`` takes ``avoid``, the cells of routes the robot was trapped on
            (``planner.AvoidMarks``); a planner without it plans without them.
    """

    section: str
    build: Callable[[Any, PlannerGeometry], Planner]
    warm_up: Callable[[Any, int], None] = _no_warm_up
    follows_grid: bool = False
    avoids: bool = False


def _nf1(settings: Nf1Params, geometry: PlannerGeometry) -> Planner:
    """GND's NF1 on the C-space of a disc of the robot's inner radius plus the ``[cspace]`` margin."""
    g = geometry
    return Nf1Planner(settings, cell_m=g.cell_m, inflate_m=g.inner_radius_m + g.cspace_margin_m,
                      unknown_is_free=g.unknown_is_free, route=g.route)


def _tunnel(settings: TunnelParams, geometry: PlannerGeometry) -> Planner:
    """The wheelchair paper's tunnel planner, on its own C-space margin."""
    g = geometry
    return TunnelPlanner(settings, cell_m=g.cell_m, inner_radius_m=g.inner_radius_m,
                         unknown_is_free=g.unknown_is_free, route=g.route)


def _warm_up_tunnel(settings: TunnelParams, size_cells: int) -> None:
    """The tunnel planner's search kernels, on cases the stack's synthetic scans may miss."""
    warm_up_planners(settings, size_cells=size_cells)


def _warm_up_nf1(settings: Nf1Params, size_cells: int) -> None:
    """What the stack's synthetic scans do not reach: the whole-grid C-space of NF1's route hysteresis
    (``cspace.free_cspace``, computed only on a tick whose held route the followed C-space blocks) and the
    weighted wave of a route to avoid (``RouteParams.avoid_cost``, only after a trap), to a goal in the grid
    and to one beyond it."""
    free_cspace(np.full((8, 8), UNKNOWN, dtype=np.uint8), cell_m=0.05, inflate_m=0.1, unknown_is_free=True)
    free = np.ones((8, 8), dtype=np.bool_)
    avoid = np.zeros((8, 8), dtype=np.bool_)
    avoid[2:6, 4] = True
    for goal in ((4.5, 7.5), (4.5, 20.0)):
        plan(free, (4, 1), goal, cell_m=0.05, params=settings, avoid=avoid, avoid_cost=2.0)


PLANNERS: dict[str, PlannerSpec] = {
    "nf1": PlannerSpec("nf1", _nf1, _warm_up_nf1, follows_grid=True, avoids=True),
    "tunnel": PlannerSpec("tunnel", _tunnel, _warm_up_tunnel, follows_grid=True),
}
"""Planner kinds (``[planner] kind``, ``--planner``) and how each is made."""


@dataclass(frozen=True, slots=True)
class PlannerParams(RouteParams):
    """The ``[planner]`` section: which planner runs, the settings every planner shares (``RouteParams``:
    ``lookahead_m``, ``route_keep_ratio``, ``route_keep_m``) and each planner's own table.

    Attributes:
        kind: the planner that runs, a key of ``PLANNERS``: "nf1" (GND) or "tunnel" (the wheelchair paper).
        nf1: NF1's settings (``[planner.nf1]``).
        tunnel: the tunnel planner's settings (``[planner.tunnel]``).
    """

    kind: str = "nf1"
    nf1: Nf1Params = Nf1Params()
    tunnel: TunnelParams = TunnelParams()

    def __post_init__(self) -> None:
        RouteParams.__post_init__(self)
        if self.kind not in PLANNERS:
            raise ValueError(f"kind: expected one of {', '.join(PLANNERS)}, got {self.kind!r}"
                             f"{did_you_mean(self.kind, PLANNERS)}")

    @property
    def settings(self) -> Any:
        """The settings of the planner that runs (its ``PlannerSpec.section``)."""
        return getattr(self, PLANNERS[self.kind].section)
