"""Per-scenario aggregates of a batch: the runs of one scenario over its seeds, scored together and checked
against the ``AGGREGATE_KEYS`` thresholds (``min_success_rate``, ...).

Rates are fractions of the runs that completed (an "error" run, e.g. a crash or a worker time-out, is
counted apart: it already makes the batch exit 2); the mean time to goal is over the successes, the
clearance the smallest of any run, the stack p99 latency the worst run's; the mean challenge metric is over
the runs that have one (an optimal path exists), a failure counting 0.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from .thresholds import Thresholds, check_limits
from .worker import InputResult, Status

__all__ = ["ScenarioAggregate", "aggregate_scenarios"]


@dataclass(frozen=True, slots=True)
class ScenarioAggregate:
    """One scenario over its seeds.

    Attributes:
        scenario: its name in the batch (the runs' ``group``).
        path: its file.
        seeds: the seeds run, in batch order.
        runs, errors: runs in the batch, and those that ended in an error (not scored).
        successes, collisions, goal_missed, timeouts: completed runs by outcome (goal_missed: the stack
            stopped at what it believed the goal, the true axle outside the tolerance).
        metrics: ``AGGREGATE_METRICS`` (absent when nothing to aggregate) and ``stack_p99_ms`` (worst run).
        limits: the aggregate thresholds checked (empty: none asked for).
        failures: one message per aggregate threshold exceeded.
        run_failures: runs whose own thresholds failed (status "fail").
        variant: the sweep combination ("" outside a sweep): a scenario is aggregated per combination.
    """

    scenario: str
    path: str
    seeds: tuple[int, ...]
    runs: int
    errors: int
    successes: int
    collisions: int
    timeouts: int
    goal_missed: int = 0
    metrics: Mapping[str, float] = field(default_factory=dict)
    limits: Mapping[str, float] = field(default_factory=dict)
    failures: tuple[str, ...] = ()

    run_failures: int = 0
    variant: str = ""

    @property
    def label(self) -> str:
        """Its name in the batch: ``variant/scenario`` in a sweep, else ``scenario``."""
        return f"{self.variant}/{self.scenario}" if self.variant else self.scenario

    @property
    def status(self) -> Status:
        """The worst of its runs and its aggregate check: "error" when a run ended in an error, "fail" when
        a run or an aggregate threshold failed, else "pass"."""
        if self.errors:
            return "error"
        return "fail" if self.failures or self.run_failures else "pass"


def _count(rows: Sequence[InputResult], metric: str) -> int:
    return sum(int(r.metrics.get(metric, 0)) for r in rows)


def _metrics(done: Sequence[InputResult]) -> dict[str, float]:
    n = len(done)
    out: dict[str, float] = {}
    for rate, metric in (("success_rate", "success"), ("collision_rate", "collisions"),
                         ("goal_missed_rate", "goal_missed"), ("timeout_rate", "timeouts")):
        out[rate] = _count(done, metric) / n if n else math.nan
    times = [r.metrics["time_to_goal_s"] for r in done if "time_to_goal_s" in r.metrics]
    if times:
        out["mean_time_to_goal_s"] = statistics.fmean(times)
    scores = [r.metrics["challenge_metric"] for r in done if "challenge_metric" in r.metrics]
    if scores:
        out["mean_challenge_metric"] = statistics.fmean(scores)
    for name, pick in (("clearance_m", min), ("stack_p99_ms", max)):
        values = [r.metrics[name] for r in done if name in r.metrics]
        if values:
            out[name] = pick(values)
    return out


def aggregate_scenarios(
    results: Sequence[InputResult], thresholds: Thresholds | None = None
) -> tuple[ScenarioAggregate, ...]:
    """One aggregate per scenario of ``results`` (rows with a ``group``) and sweep combination, in order of
    first appearance, checked against the aggregate limits of ``thresholds`` (None: the defaults, which have
    none)."""
    thresholds = thresholds if thresholds is not None else Thresholds()
    groups: dict[tuple[str, str], list[InputResult]] = {}
    for r in results:
        if r.group:
            groups.setdefault((r.variant, r.group), []).append(r)
    out = []
    for (variant, name), rows in groups.items():
        done = [r for r in rows if r.status != "error"]
        metrics = _metrics(done)
        limits = thresholds.aggregate_limits(name, Path(rows[0].path))
        out.append(
            ScenarioAggregate(
                scenario=name,
                path=rows[0].path,
                seeds=tuple(r.seed for r in rows),
                runs=len(rows),
                errors=len(rows) - len(done),
                successes=_count(done, "success"),
                collisions=_count(done, "collisions"),
                timeouts=_count(done, "timeouts"),
                goal_missed=_count(done, "goal_missed"),
                metrics=metrics,
                limits=limits,
                failures=check_limits(metrics, limits),
                run_failures=sum(r.status == "fail" for r in rows),
                variant=variant,
            )
        )
    return tuple(out)
