"""Pass/fail thresholds of a batch, read from a TOML file, with per-input overrides.

File format (every key optional; paths relative to the file's folder)::

    [thresholds]                 # all inputs; replaces the default of each key given
    reactor_p99_ms = 50.0        # <metric> = upper limit: fails when the metric exceeds it
    planner_p99_ms = 200.0
    emergency_stops = 0          # counts of ticks on which the flag fired
    stack_max_ms = false         # false switches a default threshold off
    min_ticks = 100              # min_<metric>: fails when the metric is below it

    [inputs."mit-csail*"]        # inputs whose name or path matches the glob (later tables win)
    relations = "../shared/datasets/relations/mit-csail.relations"
    goal = [12.0, -3.5]          # fixed goal [m] in the corrected odometry frame
    match_trans_err_mean_m = 0.15

    [inputs."office*"]           # a log with ground truth (CARMEN TRUEPOS, a truth topic)
    ate_m = 0.10                 # the corrected trajectory's aligned ATE RMSE [m]
    rpe_deg = 0.5                # ... and its RPE over 1 s, RMSE [deg] (rpe_m: [m])

    [inputs."u_trap"]            # closed-loop scenarios (a table matches the scenario's name, its runs'
                                 # names u_trap-s1, ..., or its path): each run (scenario x seed) ...
    min_success = false          # ... need not reach the goal (default: every run must, min_success = 1)
    collisions = 0               # ... must never touch anything
    min_clearance_m = 0.05
    min_success_rate = 0.8       # per scenario over its seeds: at least 80 % of the runs reach the goal

Upper-limit keys are the metric names of :mod:`gndreplay.batch.metrics` (``<module>_<stat>_ms``, the flag
counts, the ``match_*`` relation errors, the ground-truth errors ``ate_m``, ``rpe_m``, ``rpe_deg``, the
scenario scores ``collisions``, ``goal_missed``, ``timeouts``, ``takeovers``, ``time_to_goal_s``, ...);
lower limits are ``min_ticks``, ``min_relations_matched``, ``min_success`` and ``min_clearance_m``. A
threshold on a metric an input does not have (relation errors without a relations file, scenario scores of
a log) is not checked; a metric that is nan (relations given but none matched) fails. The ground-truth
errors are the exception: a limit on them asks for a measurement only the truth gives, so an input without
ground truth fails it, saying so (``ate_m = false`` in its ``[inputs]`` table switches the check off for
it): a CI gate on accuracy never passes for want of truth. ``AGGREGATE_KEYS`` (``min_success_rate``,
``collision_rate``, ``goal_missed_rate``, ``timeout_rate``, ``mean_time_to_goal_s``,
``min_mean_challenge_metric``) bound a scenario's aggregate over its seeds. ``relations`` and ``goal`` apply
to logs only (a scenario has its own goal and ground truth).

A limit is a non-negative number (an integer for a count) no larger than its metric can be
(``limit_bound``: a fraction at most 1, a latency at most an hour, a distance at most the readers' 1e6 m);
a goal is two finite numbers within 1e6 m. The file is read through :mod:`gndreplay.io.userfile` (a regular
file of at most 1 MB, nesting bounded).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from fnmatch import fnmatchcase
from pathlib import Path
from typing import Any

from ..errors import ConfigError, did_you_mean
from ..io.base import MAX_ABS_POSITION_M
from ..io.userfile import brief, check_number, check_regular_file, load_toml
from .jobs import Job
from .metrics import COUNT_METRICS, LATENCY_METRICS, RELATION_METRICS, SCENARIO_METRICS, TRUTH_METRICS

__all__ = [
    "AGGREGATE_KEYS",
    "DEFAULT_LIMITS",
    "MAX_THRESHOLDS_BYTES",
    "MIN_KEYS",
    "THRESHOLD_KEYS",
    "InputRule",
    "Thresholds",
    "check_limits",
    "limit_bound",
    "load_thresholds",
]

#: Lower-limit keys -> the metric they bound.
MIN_KEYS: Mapping[str, str] = {
    "min_ticks": "ticks",
    "min_relations_matched": "relations_matched",
    "min_success": "success",
    "min_clearance_m": "clearance_m",
    "min_success_rate": "success_rate",
    "min_mean_challenge_metric": "mean_challenge_metric",
}
#: Keys checked on a scenario's aggregate over its seeds (not on single runs).
AGGREGATE_KEYS: tuple[str, ...] = (
    "min_success_rate",
    "collision_rate",
    "goal_missed_rate",
    "timeout_rate",
    "mean_time_to_goal_s",
    "min_mean_challenge_metric",
)
_MAX_KEYS: tuple[str, ...] = (
    *LATENCY_METRICS,
    *COUNT_METRICS,
    *(m for m in RELATION_METRICS if m != "relations_matched"),
    *TRUTH_METRICS,
    *(m for m in SCENARIO_METRICS if m not in ("success", "clearance_m", "challenge_metric")),
    *(k for k in AGGREGATE_KEYS if k not in MIN_KEYS),
)
#: Every threshold key, in the order failures are listed.
THRESHOLD_KEYS: tuple[str, ...] = (*MIN_KEYS, *_MAX_KEYS)
_INTEGER_KEYS = frozenset(
    (*(k for k in MIN_KEYS if k not in ("min_clearance_m", "min_success_rate")), *COUNT_METRICS,
     "collisions", "goal_missed", "timeouts", "takeovers")
)
_RATE_KEYS = frozenset(("min_success_rate", "collision_rate", "goal_missed_rate", "timeout_rate"))
_INPUT_SETTINGS = ("relations", "goal")
MAX_THRESHOLDS_BYTES = 1 << 20
"""Largest thresholds file read (1 MB: thousands of input rules)."""
#: Physical bound of a limit by its metric's unit (the key's suffix): (largest limit, what it is).
_UNIT_BOUNDS: tuple[tuple[str, float, str], ...] = (
    ("_ms", 3_600_000.0, "ms (an hour)"),
    ("_ms_per_step", 3_600_000.0, "ms (an hour)"),
    ("_ms_per_tick", 3_600_000.0, "ms (an hour)"),
    ("_s", 1e7, "s (about four months)"),
    ("_m", MAX_ABS_POSITION_M, "m (the readers' bound on positions)"),
    ("_deg", 180.0, "deg (a half turn, the largest wrapped angle)"),
    ("_pct", 100.0, "%"),
)
_MAX_COUNT = 1e12
"""Largest count limit (ticks, flags, relations: a 1 kHz log of 30 years has fewer)."""

#: Thresholds when no file is given: generous bounds that catch a broken or badly slowed stack, not a tuning
#: regression. At least one tick; p99 latencies of the reactor 50 ms, the planner 200 ms and model + planner
#: + reactor 300 ms: 2.5x the default supervisor time-outs (20 / 80 / 150 ms) and 10x or more what the
#: dev logs measure (p99 reactor 0.5-5 ms, planner 2-7 ms, stack 2-9 ms, two workers on two cores).
#: Flag counts (real logs raise hundreds of emergency stops) and relation errors are only checked when a
#: thresholds file asks for them. Every closed-loop run must reach its goal (``min_success = 1``: a
#: collision, a goal missed or a time-out fails the run, with the reason).
DEFAULT_LIMITS: Mapping[str, float] = {
    "min_ticks": 1,
    "min_success": 1,
    "reactor_p99_ms": 50.0,
    "planner_p99_ms": 200.0,
    "stack_p99_ms": 300.0,
}


@dataclass(frozen=True, slots=True)
class InputRule:
    """Settings and threshold overrides for the inputs matching ``pattern``.

    Attributes:
        pattern: ``fnmatch`` glob tested (case-sensitively) against the input name (and a scenario run's
            scenario name) and its path.
        limits: threshold key -> limit, or None to switch that threshold off.
        relations: relations file for these inputs (absolute, or relative to the current folder; logs only).
        goal_xy: fixed goal [m] for these inputs (logs only).
    """

    pattern: str
    limits: Mapping[str, float | None] = field(default_factory=dict)
    relations: Path | None = None
    goal_xy: tuple[float, float] | None = None

    def matches(self, job: Job) -> bool:
        """True when the pattern matches the job's name, its scenario's name (a scenario run: ``u_trap``
        for ``u_trap-s3``) or its path (as written, with ``/``)."""
        names = (job.name, job.group, job.path.as_posix()) if job.group else (job.name, job.path.as_posix())
        return any(fnmatchcase(n, self.pattern) for n in names)


@dataclass(frozen=True, slots=True)
class Thresholds:
    """Global limits plus per-input rules (applied in order, later rules win).

    Attributes:
        limits: threshold key -> limit for every input (as given: ``DEFAULT_LIMITS`` when omitted;
            ``load_thresholds`` merges a file's ``[thresholds]`` over the defaults).
        inputs: per-input rules.
        source: the TOML file they came from, if any.
    """

    limits: Mapping[str, float] = field(default_factory=lambda: dict(DEFAULT_LIMITS))
    inputs: tuple[InputRule, ...] = ()
    source: Path | None = None

    def limits_for(self, job: Job) -> dict[str, float]:
        """The limits for ``job``: matching rules merged over the global ones, in ``THRESHOLD_KEYS`` order."""
        merged: dict[str, float | None] = dict(self.limits)
        for rule in self.inputs:
            if rule.matches(job):
                merged.update(rule.limits)
        return {k: v for k in THRESHOLD_KEYS if (v := merged.get(k)) is not None}

    def aggregate_limits(self, scenario: str, path: Path) -> dict[str, float]:
        """The ``AGGREGATE_KEYS`` limits of a scenario over its seeds: rules matched against the scenario's
        name in the batch (a run's ``group``) or its path."""
        limits = self.limits_for(Job(scenario, path, kind="scenario", group=scenario))
        return {k: v for k, v in limits.items() if k in AGGREGATE_KEYS}

    def apply(self, job: Job) -> Job:
        """``job`` with the relations file and goal of the matching rules (a job's own settings win;
        a scenario keeps its own goal and has no relations)."""
        if job.kind != "log":
            return job
        relations, goal = job.relations, job.goal_xy
        for rule in self.inputs:
            if not rule.matches(job):
                continue
            if job.relations is None and rule.relations is not None:
                relations = rule.relations
            if job.goal_xy is None and rule.goal_xy is not None:
                goal = rule.goal_xy
        return replace(job, relations=relations, goal_xy=goal)


def _fmt(x: float) -> str:
    return str(int(x)) if float(x).is_integer() else f"{x:.4g}"


def check_limits(
    metrics: Mapping[str, float], limits: Mapping[str, float], notes: Mapping[str, str] | None = None
) -> tuple[str, ...]:
    """The thresholds ``metrics`` violate, one message each (``"reactor_p99_ms 63.2 > 50"``), with
    ``notes[metric]`` appended in brackets when given (``"success 0 < 1 (collision with door at 3.10 s)"``).

    A limit on a metric that is absent is not checked, but for the ground-truth errors (``TRUTH_METRICS``),
    which fail: the input has no ground truth. A nan metric fails (``"... not measured"``).
    """
    failures: list[str] = []
    notes = notes or {}
    for key in THRESHOLD_KEYS:
        if key not in limits:
            continue
        limit = limits[key]
        metric = MIN_KEYS.get(key, key)
        if metric not in metrics:
            if metric in TRUTH_METRICS:
                failures.append(f"{metric} not measured: the input has no ground truth (limit "
                                f"{_fmt(limit)}; {key} = false in its [inputs] table skips the check)")
            continue
        value = metrics[metric]
        if math.isnan(value):
            failures.append(f"{metric} not measured (limit {_fmt(limit)})")
        elif key in MIN_KEYS and value < limit:
            failures.append(f"{metric} {_fmt(value)} < {_fmt(limit)}")
        elif key not in MIN_KEYS and value > limit:
            failures.append(f"{metric} {_fmt(value)} > {_fmt(limit)}")
        else:
            continue
        if notes.get(metric):
            failures[-1] += f" ({notes[metric]})"
    return tuple(failures)


def _unknown(path: Path, where: str, key: str, known: tuple[str, ...]) -> ConfigError:
    hint = did_you_mean(key, known)
    return ConfigError(f"{path}: {where} unknown key {brief(key)}{hint}; known keys: {', '.join(known)}")


def limit_bound(key: str) -> tuple[float, str]:
    """(largest value, how an error says it) of the threshold ``key``: a limit beyond it is a typo, and a
    metric never reaches it (a fraction of the runs is at most 1, a latency at most an hour)."""
    if key in _RATE_KEYS:
        return 1.0, "is a fraction of the runs, from 0 to 1"
    if key == "min_success":
        return 1.0, "must be 0 or 1 (a run reaches its goal or not)"
    if key == "min_mean_challenge_metric":
        return 0.5, "is a challenge metric, from 0 to 0.5"
    if key in _INTEGER_KEYS:
        return _MAX_COUNT, f"must be a count of at most {_MAX_COUNT:g}"
    for suffix, hi, unit in _UNIT_BOUNDS:
        if key.endswith(suffix):
            return hi, f"must be at most {hi:g} {unit}"
    raise KeyError(key)  # pragma: no cover - a test checks every threshold key has a bound


def _limit(path: Path, where: str, key: str, value: Any, *, allow_off: bool) -> float | None:
    """The limit ``value`` of ``key`` (None: switched off) if it is a non-negative number (an integer for a
    count) within the key's bound (:func:`limit_bound`), through ``check_number``."""
    if value is False and allow_off:
        return None
    integer = key in _INTEGER_KEYS
    hi, too_large = limit_bound(key)
    name = f"{path}: {where} {key}"
    try:
        check_number(value, name, 0.0, hi)
        ok = not integer or isinstance(value, int)
    except ConfigError:
        ok = False
    if ok:
        return value
    if isinstance(value, int | float) and not isinstance(value, bool) and value > hi:
        raise ConfigError(f"{name} {too_large}, got {brief(value)}")
    kind = "a non-negative integer" if integer else "a non-negative number"
    off = " or false" if allow_off else ""
    raise ConfigError(f"{name} must be {kind}{off}, got {brief(value)}")


def _limits(path: Path, where: str, table: Mapping[str, Any], *, allow_off: bool) -> dict[str, float | None]:
    out: dict[str, float | None] = {}
    for key, value in table.items():
        if key not in THRESHOLD_KEYS:
            raise _unknown(path, where, key, THRESHOLD_KEYS)
        out[key] = _limit(path, where, key, value, allow_off=allow_off)
    return out


def _table(path: Path, where: str, value: Any) -> Mapping[str, Any]:
    if not isinstance(value, dict):
        raise ConfigError(f"{path}: {where} must be a table, got {brief(value)}")
    return value


def _relations(path: Path, where: str, relations: Path) -> Path:
    """``relations`` if it is a regular file no larger than a relations file may be (read after the run)."""
    from ..evaluation import MAX_RELATIONS_BYTES

    try:
        check_regular_file(relations, "relations file", MAX_RELATIONS_BYTES)
    except ConfigError as err:
        raise ConfigError(f"{path}: {where} {err}") from None
    return relations


def _goal(path: Path, where: str, value: Any) -> tuple[float, float]:
    """A goal ``[x, y]`` of finite numbers within the readers' bound on positions [m]."""
    if not (isinstance(value, list) and len(value) == 2):
        raise ConfigError(f"{path}: {where} goal must be [x, y] in metres, got {brief(value)}")
    x, y = (check_number(v, f"{path}: {where} goal[{i}]", -MAX_ABS_POSITION_M, MAX_ABS_POSITION_M)
            for i, v in enumerate(value))
    return x, y


def _rule(path: Path, pattern: str, table: Mapping[str, Any]) -> InputRule:
    where = f"[inputs.{brief(pattern)}]"
    relations: Path | None = None
    goal: tuple[float, float] | None = None
    limit_items: dict[str, Any] = {}
    for key, value in table.items():
        if key == "relations":
            if not isinstance(value, str):
                raise ConfigError(f"{path}: {where} relations must be a path string, got {brief(value)}")
            relations = _relations(path, where, path.parent / value)
        elif key == "goal":
            goal = _goal(path, where, value)
        elif key in THRESHOLD_KEYS:
            limit_items[key] = value
        else:
            raise _unknown(path, where, key, (*_INPUT_SETTINGS, *THRESHOLD_KEYS))
    return InputRule(pattern, _limits(path, where, limit_items, allow_off=True), relations, goal)


def load_thresholds(path: Path | str) -> Thresholds:
    """Read a thresholds TOML file (format in the module docstring) over the defaults.

    Raises:
        ConfigError: unreadable file, TOML syntax error, unknown section or key (named, with the file),
            a limit that is not a non-negative number, a bad goal, or a missing relations file.
    """
    path = Path(path)
    doc = load_toml(path, "thresholds file", MAX_THRESHOLDS_BYTES)
    for key in doc:
        if key not in ("thresholds", "inputs"):
            raise _unknown(path, "top level:", key, ("thresholds", "inputs"))
    limits: dict[str, float | None] = dict(DEFAULT_LIMITS)
    limits.update(
        _limits(path, "[thresholds]", _table(path, "[thresholds]", doc.get("thresholds", {})), allow_off=True)
    )
    rules = tuple(
        _rule(path, pattern, _table(path, f"[inputs.{brief(pattern)}]", table))
        for pattern, table in _table(path, "[inputs]", doc.get("inputs", {})).items()
    )
    return Thresholds(limits={k: v for k, v in limits.items() if v is not None}, inputs=rules, source=path)
