"""The run directory: its format (:mod:`.rundir`: file names, columns, writers and readers; :mod:`.summary`:
summary.json), its figures, report.md and the results MCAP.

A replay feeds the sinks while it streams (``MapSink`` -> maps.npz, ``McapSink`` -> results.mcap;
``default_sinks`` lists a run's); ``build_report(run_dir)`` then draws fig_model.png, fig_raw.png,
fig_commands.png, fig_timing.png, fig_modes.png and report.md from the run's files alone (``ReportSink`` does
it inside the replay's staging directory, ``gndreplay report RUN_DIR`` afterwards). matplotlib and rosbags are
imported only when a figure or the MCAP is made.
"""

from __future__ import annotations

from .build import REPORT_FILE, ReportSink, build_report
from .figures import FIGURES
from .maps import MAPS_FILE, GridSnapshot, HitRaster, MapsData, MapSink, load_maps
from .mcap_export import MCAP_FILE, McapSink, grid_to_occupancy
from .rundir import RunData, RunDirError, RunSink, load_run
from .sinks import default_sinks

__all__ = [
    "FIGURES",
    "MAPS_FILE",
    "MCAP_FILE",
    "REPORT_FILE",
    "GridSnapshot",
    "HitRaster",
    "MapSink",
    "MapsData",
    "McapSink",
    "ReportSink",
    "RunData",
    "RunDirError",
    "RunSink",
    "build_report",
    "default_sinks",
    "grid_to_occupancy",
    "load_maps",
    "load_run",
]
