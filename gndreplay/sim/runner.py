"""``gndreplay simulate SCENARIO``: one closed-loop run written as a run directory.

:func:`simulate_scenario` wires a :class:`~.closedloop.ClosedLoop` into :func:`gndreplay.replay.run_replay`
(matcher -> stack -> commands.csv, timing.csv, summary.json, ...) and adds, through a ``RunSink``:

- ``result.json``   the outcome and scores (deterministic with a fixed latency);
- ``log.mcap``      /scan (LaserScan), /odom (Odometry, drifting), /cmd_vel (TwistStamped, the stack's
                    commands), /ground_truth (PoseStamped), /tf_static (base_link -> laser); ``gndreplay run``
                    replays it;
- ``fig_world.png`` the true world, the trajectory with the footprint every second, events, movers, contact;
- ``sim_timing.json`` wall-clock: simulator ms per step, stack (matcher included) ms per tick.
"""

from __future__ import annotations

import json
import math
import shutil
import tempfile
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..config import Config, preset
from ..errors import ConfigError
from ..io.userfile import brief
from .closedloop import ClosedLoop, SimParams
from .figure import draw_world
from .geometry import warm_up as warm_up_geometry
from .scenario_file import ScenarioSpec, resolve_scenario, scenario_ref

if TYPE_CHECKING:
    from ..report.mcap_export import GridEvery
    from ..report.snapshots import SnapshotOptions

__all__ = [
    "RESULT_FILE", "SimOutcome", "SimSink", "parse_latency", "simulate_scenario",
    "write_sim_mcap",
]

RESULT_FILE = "result.json"
LOG_FILE = "log.mcap"
FIGURE_FILE = "fig_world.png"
TIMING_FILE = "sim_timing.json"


@dataclass(frozen=True, slots=True)
class SimOutcome:
    """What one closed-loop run gives (the fields of result.json, plus the wall-clock timings).

    ``outcome`` is success, collision, goal_missed (the stack stopped at what it believed the goal, the true
    axle outside the tolerance; ``goal_missed`` says how far) or timeout. ``active_modes`` counts ticks per
    active navigation mode, ``takeovers`` the onsets of an active mode other than the desired one (see
    :meth:`ClosedLoop.result`)."""

    scenario: str
    preset: str
    seed: int
    outcome: str
    end_time_s: float
    time_to_goal_s: float | None
    collision: dict[str, Any] | None
    path_length_m: float
    min_clearance_m: float | None
    time_inside_security_pct: float
    mean_abs_dw_dt_radps2: float
    longest_stall_s: float
    trap_count: int
    ticks: int
    modes: dict[str, int]
    flags: dict[str, int]
    result: dict[str, Any]
    out_dir: Path
    sim_ms_per_step: float
    stack_ms_per_tick: float
    active_modes: dict[str, int] = field(default_factory=dict)
    takeovers: int = 0
    goal_missed: dict[str, Any] | None = None
    optimal_path_m: float | None = None
    challenge_metric: float | None = None
    narrowest_passage_m: float | None = None
    passage_warning: str | None = None

    @property
    def success(self) -> bool:
        return self.outcome == "success"


class SimSink:
    """A ``RunSink`` writing result.json, log.mcap, fig_world.png and sim_timing.json at the end."""

    def __init__(self, loop: ClosedLoop, *, figure: bool = True) -> None:
        self.loop, self.figure = loop, figure

    def add_scan(self, tick: Any, pose_corrected: Any) -> None:
        """Nothing per scan: the loop records what it needs."""

    def add_result(self, tick: Any, result: Any, grid: Any) -> None:
        """Nothing per tick."""

    def finish(self, run_dir: Path) -> None:
        run_dir = Path(run_dir)
        result = self.loop.result()
        (run_dir / RESULT_FILE).write_text(json.dumps(result, indent=2) + "\n")
        write_sim_mcap(run_dir / LOG_FILE, self.loop)
        (run_dir / TIMING_FILE).write_text(json.dumps(timings(self.loop), indent=2) + "\n")
        if self.figure:
            draw_world(run_dir / FIGURE_FILE, self.loop, result)

    def abort(self) -> None:
        """Nothing held."""


def timings(loop: ClosedLoop) -> dict[str, float]:
    """Mean wall time of the simulator per step and of the robot side (matcher + stack) per tick [ms]."""
    sim = np.asarray(loop.rec.sim_ns, dtype=np.float64) / 1e6
    stack = np.asarray(loop.rec.stack_ms, dtype=np.float64)
    return {
        "sim_ms_per_step": float(sim.mean()) if sim.size else 0.0,
        "sim_ms_per_step_median": float(np.median(sim)) if sim.size else 0.0,
        "stack_ms_per_tick": float(stack.mean()) if stack.size else 0.0,
        "stack_ms_per_tick_median": float(np.median(stack)) if stack.size else 0.0,
        "steps": int(sim.size),
    }


def write_sim_mcap(path: Path, loop: ClosedLoop) -> None:
    """The simulated run as a bare ROS 2 MCAP file (topics in the module docstring)."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    from ..report.mcap_export import RosMessages

    ts = get_typestore(Stores.ROS2_HUMBLE)
    m = RosMessages(ts)
    T = ts.types
    rec, laser, mount = loop.rec, loop.laser, loop.mount
    n = laser.n_beams
    inc = laser.fov_rad / (n - 1)
    topics = {
        "/scan": "sensor_msgs/msg/LaserScan",
        "/odom": "nav_msgs/msg/Odometry",
        "/cmd_vel": "geometry_msgs/msg/TwistStamped",
        "/ground_truth": "geometry_msgs/msg/PoseStamped",
        "/tf_static": "tf2_msgs/msg/TFMessage",
    }
    # beside the target (the run's staging folder), so a killed run leaves nothing in $TMPDIR
    tmp = Path(tempfile.mkdtemp(prefix=".simlog-", dir=path.parent))
    try:
        writer = Writer(tmp / "log", version=9, storage_plugin=StoragePlugin.MCAP)
        writer.open()
        conns = {t: writer.add_connection(t, ty, typestore=ts) for t, ty in topics.items()}

        def put(topic: str, t: int, msg: Any) -> None:
            writer.write(conns[topic], t, ts.serialize_cdr(msg, topics[topic]))

        zero = np.zeros(36, dtype=np.float64)
        for k, t in enumerate(rec.scan_t_ns):
            if k == 0:
                put("/tf_static", t, m.tf(t, ("base_link", "laser", mount.x, mount.y, mount.theta)))
            scan = T["sensor_msgs/msg/LaserScan"](
                header=m.hdr(t, "laser"), angle_min=-laser.fov_rad / 2.0, angle_max=laser.fov_rad / 2.0,
                angle_increment=inc, time_increment=0.0, scan_time=loop.period_ns / 1e9, range_min=0.0,
                range_max=laser.max_range_m, ranges=np.asarray(rec.scan_ranges[k], dtype=np.float32),
                intensities=np.zeros(0, dtype=np.float32))
            put("/scan", t, scan)
            ox, oy, oth = rec.scan_odom[k]
            # the twist odometry reports: the robot's actual velocity at the scan, not the command
            mv, mvy, mw = rec.scan_vel[k]
            odom = T["nav_msgs/msg/Odometry"](
                header=m.hdr(t, "odom"), child_frame_id="base_link",
                pose=m["PoseWithCovariance"](pose=m.pose(ox, oy, oth), covariance=zero),
                twist=m["TwistWithCovariance"](twist=m.twist(mv, mvy, mw), covariance=zero))
            put("/odom", t, odom)
            gx, gy, gth = rec.scan_truth[k]
            put("/ground_truth", t, m["PoseStamped"](header=m.hdr(t, "map"), pose=m.pose(gx, gy, gth)))
            if k < len(rec.cmd):
                _, v, vy, w = rec.cmd[k]
                put("/cmd_vel", t, m["TwistStamped"](header=m.hdr(t, "base_link"), twist=m.twist(v, vy, w)))
        writer.close()
        files = sorted((tmp / "log").glob("*.mcap"))
        shutil.move(str(files[0]), str(path))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def parse_latency(text: str) -> float | None:
    """``--latency``: seconds in [0, 10), or ``"measured"`` (None: the stack's own time).

    Raises:
        ConfigError: anything else.
    """
    if text == "measured":
        return None
    try:
        value = float(text)
    except ValueError:
        raise ConfigError(f"--latency must be seconds or 'measured', got {brief(text)}") from None
    if not (math.isfinite(value) and 0.0 <= value < 10.0):
        raise ConfigError(f"--latency must be in [0, 10) s, got {brief(text)}")
    return value


def _outcome(result: dict[str, Any], out_dir: Path, t: dict[str, float]) -> SimOutcome:
    names = {f.name for f in fields(SimOutcome)}
    kw = {k: v for k, v in result.items() if k in names}
    return SimOutcome(**kw, result=result, out_dir=out_dir, sim_ms_per_step=t["sim_ms_per_step"],
                      stack_ms_per_tick=t["stack_ms_per_tick"])


def simulate_scenario(
    scenario: str | Path | ScenarioSpec,
    *,
    out_dir: Path,
    cfg: Config | None = None,
    seed: int = 0,
    latency_s: float | None = 0.0,
    perfect_odometry: bool = False,
    time_limit_s: float | None = None,
    figures: bool = True,
    overwrite: bool = False,
    on_tick: Any = None,
    params: SimParams | None = None,
    run_kwargs: dict[str, Any] | None = None,
    snapshots: SnapshotOptions | None = None,
    mcap: bool = False,
    mcap_grid: GridEvery = "change",
    ideal_dynamics: bool = False,
) -> SimOutcome:
    """Run one scenario in closed loop and write its run directory.

    Args:
        scenario: a shipped scenario's name, a scenario file, or a parsed spec.
        out_dir: the run directory (written by ``run_replay``: staged, moved into place at the end).
        cfg: configuration; default: the scenario's preset. The scenario's ``mode`` / ``local`` override
            its ``[navigation]`` (see ``closedloop.navigation_config``).
        seed: laser noise and odometry errors.
        latency_s: command latency [s]; None = the stack's measured time (not deterministic).
        perfect_odometry: no odometry drift.
        time_limit_s: overrides the scenario's time limit (e.g. short CI runs).
        figures: draw fig_world.png and the run's standard figures.
        overwrite: replace an earlier run at ``out_dir`` (otherwise ``run_replay`` writes beside it,
            ``out_dir-2``, ...; the outcome's ``out_dir`` says where).
        on_tick: also called with each TickResult (progress bars).
        run_kwargs: extra keyword arguments for ``run_replay`` (e.g. ``on_stage``).
        snapshots: write snapshots/ of the key events (``report.snapshots``); None: none.
        mcap: also write results.mcap (``report.mcap_export``; its robot-centred grid per ``mcap_grid``), from
            which ``gndreplay report --animate`` draws.
        ideal_dynamics: the exact motion model: no response lag, no slip (``sim.dynamics``).

    Raises:
        ConfigError: a bad scenario file (one line naming the file and the key).
    """
    from ..replay import RunOptions, run_replay
    from ..report.sinks import default_sinks

    spec = scenario if isinstance(scenario, ScenarioSpec) else resolve_scenario(scenario)
    cfg = cfg if cfg is not None else preset(spec.preset)
    warm_up_geometry()
    loop = ClosedLoop(spec, cfg, seed=seed, latency_s=latency_s, perfect_odometry=perfect_odometry,
                      time_limit_s=time_limit_s, params=params or SimParams(), ideal_dynamics=ideal_dynamics)

    def tick_done(r: Any) -> None:
        loop.on_tick(r)
        if on_tick is not None:
            on_tick(r)

    sinks = default_sinks(figures=figures, extra=[SimSink(loop, figure=figures)], snapshots=snapshots,
                          mcap=mcap, config=loop.cfg, mcap_grid=mcap_grid)
    source = {"kind": "scenario", "scenario": scenario_ref(spec), "seed": seed, "latency_s": latency_s,
              "perfect_odometry": perfect_odometry, "time_limit_s": time_limit_s,
              "ideal_dynamics": ideal_dynamics,
              "default_sim_params": params is None or params == SimParams()}
    summary = run_replay(loop.ticks(), loop.cfg, Path(out_dir), log=Path(spec.source),
                         options=RunOptions(goal_xy=spec.goal, subgoals=spec.subgoals), on_tick=tick_done,
                         sinks=sinks, overwrite=overwrite, source=source, **(run_kwargs or {}))
    return _outcome(loop.result(), summary.out_dir, timings(loop))
