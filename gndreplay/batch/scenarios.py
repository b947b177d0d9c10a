"""Closed-loop scenarios as batch inputs: how a scenario run is configured and run in a worker, and the
scores read back from its run directory.

A scenario job runs ``gndreplay.sim.simulate_scenario`` (the same run directory as ``gndreplay simulate``:
summary.json, result.json, sim_timing.json, log.mcap, ...). Its stack configuration is resolved in the
worker, where the scenario file is read, by ``sim.closedloop.configure_scenario`` as ``gndreplay simulate``
does: ``--preset`` / ``--config`` / ``--set`` apply as to logs, and without ``--preset`` the scenario's own
``preset:`` is used; ``--mode`` / ``--local`` / ``--subgoals`` replace the scenario's own keys.
A bad scenario file is therefore that scenario's "error" row, never the batch's.

Importing this module is cheap (no numpy / simulator code): the worker imports it before pinning threads.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..errors import ConfigError
from .jobs import Job
from .metrics import metrics_from_result, outcome_note

if TYPE_CHECKING:
    from collections.abc import Mapping

    from ..config import CliOverrides
    from ..types import Subgoal


__all__ = [
    "ScenarioRun",
    "SimOptions",
    "run_scenario",
    "scenario_scores",
]


@dataclass(frozen=True, slots=True)
class SimOptions:
    """How the scenario inputs of a batch run (picklable; paths absolute once ``make_tasks`` has run).

    Attributes:
        latency_s: seconds from a scan to its command taking effect; None: the stack's measured time (not
            deterministic).
        perfect_odometry: no odometry drift.
        ideal_dynamics: the exact motion model (no response lag, no slip).
        time_limit_s: overrides every scenario's own time limit (None: the scenario's).
        figures: draw each run's figures (fig_world.png and the run figures).
        config: TOML overriding the preset (``--config``), or None.
        preset: preset of every scenario (``--preset``); None: each scenario's own ``preset:``.
        overrides: the command line's configuration options (``--planner``, ``--set``, ``--no-selector``;
            ``--mode`` and ``--local`` in place of each scenario's own keys); None: none.
        subgoals: subgoals (``--subgoals``, parsed) in place of each scenario's; empty: the scenario's.
    """

    latency_s: float | None = 0.0
    perfect_odometry: bool = False
    time_limit_s: float | None = None
    figures: bool = True
    ideal_dynamics: bool = False
    config: Path | None = None
    preset: str | None = None
    overrides: CliOverrides | None = None
    subgoals: tuple[Subgoal, ...] = ()


@dataclass(frozen=True, slots=True)
class ScenarioRun:
    """What ``run_scenario`` returns (a ``RunOutcome``): the run directory and its summary.json."""

    out_dir: Path
    ticks: int
    data: Mapping[str, Any]


def run_scenario(job: Job, run_dir: Path, sim: SimOptions) -> ScenarioRun:
    """Run one scenario job (a seed of a scenario) in closed loop and write its run directory.

    Raises:
        ConfigError: a bad scenario file (one line naming the file and the key) or configuration, or a mode
            the scenario cannot run (teleop without an operator, follow without subgoals).
    """
    from ..config import CliOverrides
    from ..report.rundir import SUMMARY_FILE
    from ..sim import load_scenario, resolve_scenario, simulate_scenario
    from ..sim.closedloop import configure_scenario

    spec = resolve_scenario(job.scenario) if job.scenario else load_scenario(job.path)
    spec, cfg = configure_scenario(spec, config=sim.config, preset=sim.preset,
                                   overrides=sim.overrides or CliOverrides(), subgoals=sim.subgoals)
    out = simulate_scenario(
        spec,
        out_dir=run_dir,
        cfg=cfg,
        seed=job.seed,
        latency_s=sim.latency_s,
        perfect_odometry=sim.perfect_odometry,
        time_limit_s=sim.time_limit_s,
        figures=sim.figures,
        ideal_dynamics=sim.ideal_dynamics,
    )
    data = _read_json(Path(out.out_dir) / SUMMARY_FILE)
    return ScenarioRun(Path(out.out_dir), int(data.get("ticks", out.ticks)), data)


def _read_json(path: Path) -> dict[str, Any]:
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise ConfigError(f"{path}: missing from the scenario's run directory") from None
    except (OSError, ValueError) as err:
        raise ConfigError(f"{path}: cannot read it: {err}") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: expected a JSON object")
    return data


def scenario_scores(run_dir: Path) -> tuple[dict[str, float], str]:
    """A scenario run's metrics (``SCENARIO_METRICS``) and how it ended in words, from the result.json and
    sim_timing.json of its run directory.

    Raises:
        ConfigError: either file is missing or not a JSON object.
    """
    from ..sim.runner import RESULT_FILE, TIMING_FILE

    result = _read_json(run_dir / RESULT_FILE)
    timing = _read_json(run_dir / TIMING_FILE)
    return metrics_from_result(result, timing), outcome_note(result)
