"""The run directory: its format (:mod:`.rundir`: file names, columns, writers and readers; :mod:`.summary`:
summary.json), its figures, report.md and the results MCAP.

A replay feeds the sinks while it streams (``MapSink`` -> maps.npz, ``McapSink`` -> results.mcap and its
Foxglove layout, ``SnapshotSink`` -> snapshots/; ``default_sinks`` lists a run's); ``build_report(run_dir)``
then draws fig_model.png, fig_raw.png, fig_commands.png, fig_timing.png, fig_modes.png (fig_error.png with
ground truth) and report.md from the run's files alone (``ReportSink`` does it inside the replay's staging
directory, ``gndreplay report RUN_DIR`` afterwards). ``decision_view`` / ``draw_decision`` picture one
decision (the snapshots' and ``animate_run``'s view).
matplotlib and rosbags are imported only when a figure or the MCAP is made.
"""

from __future__ import annotations

from .animate import ANIMATION_FILE, animate_run
from .build import REPORT_FILE, ReportSink, build_report
from .decision import DecisionInput, DecisionView, decision_input, decision_view, draw_decision
from .figures import FIGURES
from .foxglove import LAYOUT_FILE
from .maps import MAPS_FILE, GridSnapshot, HitRaster, MapsData, MapSink, load_maps
from .mcap_export import MCAP_FILE, McapSink, grid_to_occupancy
from .rundir import RunData, RunDirError, RunSink, load_run
from .sinks import default_sinks
from .snapshots import SNAPSHOTS_DIR, SnapshotOptions, SnapshotSink, read_snapshot_index, tick_events

__all__ = [
    "ANIMATION_FILE",
    "FIGURES",
    "LAYOUT_FILE",
    "MAPS_FILE",
    "MCAP_FILE",
    "REPORT_FILE",
    "SNAPSHOTS_DIR",
    "DecisionInput",
    "DecisionView",
    "GridSnapshot",
    "HitRaster",
    "MapSink",
    "MapsData",
    "McapSink",
    "ReportSink",
    "RunData",
    "RunDirError",
    "RunSink",
    "SnapshotOptions",
    "SnapshotSink",
    "animate_run",
    "build_report",
    "decision_input",
    "decision_view",
    "default_sinks",
    "draw_decision",
    "grid_to_occupancy",
    "load_maps",
    "load_run",
    "read_snapshot_index",
    "tick_events",
]
