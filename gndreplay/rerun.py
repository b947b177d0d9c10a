"""Re-run a run directory's input up to one tick and take the stack's decision there; and the whole of
``gndreplay compare``, whose snapshot (``fig_compare_snapshot.png``) draws both runs' decisions at their
first divergent tick.

A run's records are a pure function of its input and configuration (``report.rundir``): summary.json's
``source`` names the input (a log: its absolute path and read options, ``replay.log_source``; a scenario:
its name or file, seed, latency, odometry and time limit, ``sim.simulate_scenario``), summary.json's
``options`` the replay's options, config.toml the configuration. :func:`decision_at` streams the input
through ``replay.replay_steps`` up to the tick and checks the re-run's rows of that tick against the run's
commands.csv and stages.csv, so a snapshot never passes off another decision as the recorded one
unnoticed. The grid is not in the run directory: re-running is how it is had back, at the cost of
replaying the input up to the tick.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .config import Config, load_config
from .errors import ConfigError, GndReplayError
from .fsutil import check_output_dir, format_stamp
from .io.userfile import read_text
from .pipeline.model import RobotCentredGrid
from .pipeline.stack import TickResult
from .replay import Matched, RunOptions, replay_steps
from .report.compare import (
    COMPARE_SNAPSHOT,
    Comparison,
    SnapshotPanel,
    Tolerance,
    compare_runs,
    load_compare_run,
    read_tolerance,
    write_comparison,
)
from .report.decision import DecisionInput, decision_input
from .report.rundir import (
    COMMANDS_FILE,
    CONFIG_FILE,
    MAX_TABLE_BYTES,
    STAGES_FILE,
    SUMMARY_FILE,
    command_row,
    read_summary,
    stage_row,
)
from .types import Subgoal, Tick

__all__ = ["Rerun", "RerunError", "compare_dirs", "decision_at"]


class RerunError(GndReplayError):
    """A run cannot be re-run: its input is not recorded, not there, or the re-run has no such tick."""


@dataclass(frozen=True, slots=True, eq=False)
class Rerun:
    """The decision of a re-run at one tick, the run's configuration, and what to know about it
    (``notes``: the re-run differs from the recorded rows, or its commands depend on wall-clock time)."""

    decision: DecisionInput
    config: Config
    notes: tuple[str, ...] = ()


def _options(summary: dict[str, Any], where: Path) -> RunOptions:
    """The replay options summary.json recorded."""
    o = summary.get("options") or {}
    try:
        goal = o.get("goal")
        subgoals = tuple(Subgoal(float(x), float(y), float(th), kind)
                         for x, y, th, kind in o.get("subgoals", []))
        return RunOptions(goal_xy=None if goal is None else (float(goal[0]), float(goal[1])),
                          goal_ahead_m=float(o.get("goal_ahead_m", 5.0)), until_s=o.get("until_s"),
                          every=int(o.get("every", 1)), subgoals=subgoals)
    except (TypeError, ValueError) as err:
        raise RerunError(f"{where}: options: cannot read the replay options ({err})") from None


def _find(steps: Iterable[tuple[Matched, TickResult | None, RobotCentredGrid]], t_s: float,
          on_result: Any = None) -> tuple[DecisionInput, TickResult, Tick]:
    """The decision of the re-run's tick stamped ``t_s`` (as commands.csv prints it, read as a float)."""
    t0_ns: int | None = None
    for m, r, grid in steps:
        t0_ns = m.tick.t_ns if t0_ns is None else t0_ns
        if r is None:
            continue
        if on_result is not None:
            on_result(r)
        stamp = float(format_stamp(r.t_ns))
        if stamp == t_s:
            return decision_input(m.tick, r, grid, t0_ns=t0_ns), r, m.tick
        if stamp > t_s:
            break
    raise RerunError(f"the re-run has no tick at t={t_s:.6f}")


def _replay_log(source: dict[str, Any], cfg: Config, options: RunOptions, t_s: float,
                where: Path) -> tuple[DecisionInput, TickResult, Tick]:
    from .io import ReadOptions, open_log

    path = Path(str(source.get("path", "")))
    if not source.get("path") or not path.exists():
        raise RerunError(f"{where}: the run's log {path} is not there (moved or deleted)")
    read = ReadOptions.from_dict(source.get("read", {}), f"{where}: source.read")
    with open_log(path, options=read) as reader:
        return _find(replay_steps(reader.ticks(), cfg, options), t_s)


def _replay_scenario(source: dict[str, Any], cfg: Config, options: RunOptions, t_s: float,
                     where: Path) -> tuple[DecisionInput, TickResult, Tick]:
    from .sim import resolve_scenario
    from .sim.closedloop import ClosedLoop

    ref = source.get("scenario")
    if not isinstance(ref, str):
        raise RerunError(f"{where}: the run's scenario was not read from a file: it cannot be re-run")
    if not source.get("default_sim_params", True):
        raise RerunError(f"{where}: the run used its own simulator parameters: it cannot be re-run")
    # the navigation the run resolved (config.toml, the subgoals it was given) over the scenario's own
    spec = dataclasses.replace(resolve_scenario(ref), mode=cfg.navigation.mode,
                               local=cfg.navigation.local.strategy, subgoals=options.subgoals)
    latency = source.get("latency_s")
    loop = ClosedLoop(spec, cfg, seed=int(source.get("seed", 0)),
                      latency_s=None if latency is None else float(latency),
                      perfect_odometry=bool(source.get("perfect_odometry", False)),
                      time_limit_s=source.get("time_limit_s"))
    steps = replay_steps(loop.ticks(), loop.cfg, dataclasses.replace(options, goal_xy=spec.goal))
    return _find(steps, t_s, on_result=loop.on_tick)


def _recorded_row(path: Path, stamp: str) -> str | None:
    """The row of ``path`` (a run's table) for the tick ``stamp``, None when the file or the row is absent."""
    if not path.is_file():
        return None
    prefix = stamp + ","
    try:
        text = read_text(path, "run table", MAX_TABLE_BYTES)
    except ConfigError:
        return None
    return next((line + "\n" for line in text.splitlines() if line.startswith(prefix)), None)


def decision_at(run_dir: Path, t_s: float) -> Rerun:
    """Re-run ``run_dir``'s input up to its tick stamped ``t_s`` (seconds, as commands.csv prints the
    stamp) and take the stack's decision there (``report.decision.DecisionInput``).

    Raises:
        RerunError: summary.json records no input, the input is not there, or the re-run has no such tick.
        RunDirError, ConfigError: summary.json or config.toml cannot be read; the log, the scenario or the
            recorded options are unreadable (each one line naming the file).
    """
    run_dir = Path(run_dir)
    where = run_dir / SUMMARY_FILE
    summary = read_summary(where)
    cfg = load_config(run_dir / CONFIG_FILE)
    source = summary.get("source")
    if not isinstance(source, dict):
        raise RerunError(f"{where}: records no source to re-run the run from")
    options = _options(summary, where)
    if source.get("kind") == "log":
        decision, r, tick = _replay_log(source, cfg, options, t_s, where)
    elif source.get("kind") == "scenario":
        decision, r, tick = _replay_scenario(source, cfg, options, t_s, where)
    else:
        raise RerunError(f"{where}: source of unknown kind {source.get('kind')!r}")
    notes = []
    measured = source.get("kind") == "scenario" and source.get("latency_s") is None
    if cfg.supervisor.enforce_budgets or measured:
        notes.append("its commands depend on wall-clock time (enforced budgets or a measured latency): the "
                     "re-run may decide otherwise")
    enforce = cfg.supervisor.enforce_budgets
    stamp = format_stamp(r.t_ns)
    differs = [name for name, mine in ((COMMANDS_FILE, command_row(r, enforce, tick.cmd)),
                                       (STAGES_FILE, stage_row(r)))
               if (row := _recorded_row(run_dir / name, stamp)) is not None and row != mine]
    if differs:
        notes.append(f"the re-run's tick differs from its {' and '.join(differs)}: the snapshot may not show "
                     "the recorded decision")
    return Rerun(decision, cfg, tuple(notes))


def _panels(runs: Iterable[tuple[str, Path]], t_s: float) -> Iterator[tuple[SnapshotPanel, list[str]]]:
    """One snapshot panel per run (its decision at ``t_s``, or why there is none) and the notes for the
    comparison."""
    for label, run_dir in runs:
        try:
            rerun = decision_at(run_dir, t_s)
        except GndReplayError as err:
            yield (SnapshotPanel(f"{label} ({run_dir.name})", None, None, f"not re-run: {err}"),
                   [f"snapshot of run {label}: {err}"])
            continue
        notes = [f"snapshot of run {label}: {n}" for n in rerun.notes]
        yield SnapshotPanel(f"{label} ({run_dir.name})", rerun.decision, rerun.config,
                            "; ".join(rerun.notes)), notes


def compare_dirs(run_a: Path, run_b: Path, *, tolerance: Path | None = None, out: Path | None = None,
                 overwrite: bool = False, snapshot: bool | None = None) -> tuple[Comparison, Path | None]:
    """The whole of ``gndreplay compare``: compare run B against run A (``report.compare.compare_runs``)
    under the ``tolerance`` file's tolerances and, with ``out``, write compare.json, fig_compare.png and
    (``snapshot``; None: with ``out``) fig_compare_snapshot.png, both runs' decisions at the first divergent
    tick, re-run from their inputs. A run that cannot be re-run gets a note and an empty panel, never an
    error. Returns the comparison (its ``notes`` and ``snapshot`` saying what was drawn) and where it was
    written.

    Raises:
        RunDirError: a run directory cannot be read.
        ConfigError: the tolerance file is bad, or ``snapshot`` without ``out``.
        OutputError: ``out`` is unsafe to write (checked before any re-run).
    """
    if snapshot and out is None:
        raise ConfigError("--snapshot: give --out DIR to write fig_compare_snapshot.png into")
    tol = read_tolerance(tolerance) if tolerance is not None else Tolerance()
    a, b = load_compare_run(run_a), load_compare_run(run_b)
    c = compare_runs(a, b, tol)
    if out is None:
        return c, None
    inputs = [Path(run_a), Path(run_b)]
    check_output_dir(out, inputs=inputs, overwrite=overwrite)
    panels: list[SnapshotPanel] = []
    if snapshot is not False:
        if c.divergence is None:
            c = dataclasses.replace(c, notes=(*c.notes, "no divergent tick: no snapshot"))
        else:
            notes: list[str] = []
            for panel, more in _panels((("A", Path(run_a)), ("B", Path(run_b))), c.divergence.t_s):
                panels.append(panel)
                notes += more
            c = dataclasses.replace(c, notes=(*c.notes, *notes), snapshot=COMPARE_SNAPSHOT)
    written = write_comparison(out, a, b, c, overwrite=overwrite, inputs=inputs, snapshot=panels)
    return c, written
