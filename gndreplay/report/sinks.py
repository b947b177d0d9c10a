"""``default_sinks``: the one list of sinks a replay writes its run directory's extra files with, for
``gndreplay run``, ``gndreplay simulate`` and ``gndreplay batch`` alike."""

from __future__ import annotations

from collections.abc import Callable, Sequence

from ..config import Config
from .build import ReportSink
from .maps import MapSink
from .mcap_export import GridEvery, McapSink
from .rundir import RunSink
from .snapshots import SnapshotOptions, SnapshotSink

__all__ = ["default_sinks"]


def default_sinks(
    *,
    figures: bool,
    mcap: bool = False,
    enforce_budgets: bool = False,
    config: Config | None = None,
    mcap_grid: GridEvery = "change",
    extra: Sequence[RunSink] = (),
    on_draw: Callable[[], None] | None = None,
    snapshots: SnapshotOptions | None = None,
) -> list[RunSink]:
    """The sinks of a run, in the order they finish: with ``figures`` the map rasters (maps.npz) first,
    then the caller's ``extra`` sinks (a simulation's result.json, log.mcap, ...), the results MCAP with
    ``mcap`` (its flags topic records what commands.csv records, so it needs ``enforce_budgets``; its
    footprint and decision markers need the run's ``config``; ``mcap_grid``: how often it writes the
    robot-centred grid, ``McapSink``'s ``grid_every``), and with ``figures`` the figures and report.md last,
    drawn inside the staging directory from the files the others wrote (``on_draw`` is called just before
    drawing). With ``snapshots``, the key events' snapshots/ come just before the figures (report.md links
    them)."""
    sinks: list[RunSink] = [MapSink()] if figures else []
    sinks += extra
    if mcap:
        sinks.append(McapSink(config, grid_every=mcap_grid, enforce_budgets=enforce_budgets))
    sinks += [SnapshotSink(snapshots)] if snapshots is not None else []
    if figures:
        sinks.append(ReportSink(on_draw=on_draw))
    return sinks
