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

    [inputs."u_trap"]            # closed-loop scenarios (a table matches the scenario's name, its runs'
                                 # names u_trap-s1, ..., or its path): each run (scenario x seed) ...
    min_success = false          # ... need not reach the goal (default: every run must, min_success = 1)
    collisions = 0               # ... must never touch anything
    min_clearance_m = 0.05
    min_success_rate = 0.8       # per scenario over its seeds: at least 80 % of the runs reach the goal

Upper-limit keys are the metric names of :mod:`gndreplay.batch.metrics` (``<module>_<stat>_ms``, the flag
counts, the ``match_*`` relation errors, the scenario scores ``collisions``, ``goal_missed``,
``timeouts``, ``takeovers``, ``time_to_goal_s``, ...); lower limits are ``min_ticks``,
``min_relations_matched``, ``min_success`` and ``min_clearance_m``. A threshold on a metric an input
does not have (relation errors without a relations file, scenario scores of a log) is not checked; a
metric that is nan (relations given but none matched) fails. ``AGGREGATE_KEYS`` (``min_success_rate``,
``collision_rate``, ``goal_missed_rate``, ``timeout_rate``, ``mean_time_to_goal_s``) bound a scenario's
aggregate over its seeds. ``relations`` and ``goal`` apply to logs only (a scenario has its own goal and
ground truth).
"""

from __future__ import annotations

import difflib
import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from fnmatch import fnmatchcase
from pathlib import Path
from typing import Any

from ..errors import ConfigError
from .jobs import Job
from .metrics import COUNT_METRICS, LATENCY_METRICS, RELATION_METRICS, SCENARIO_METRICS

__all__ = [
    "AGGREGATE_KEYS",
    "DEFAULT_LIMITS",
    "MIN_KEYS",
    "THRESHOLD_KEYS",
    "InputRule",
    "Thresholds",
    "check_limits",
    "load_thresholds",
]

#: Lower-limit keys -> the metric they bound.
MIN_KEYS: Mapping[str, str] = {
    "min_ticks": "ticks",
    "min_relations_matched": "relations_matched",
    "min_success": "success",
    "min_clearance_m": "clearance_m",
    "min_success_rate": "success_rate",
}
#: Keys checked on a scenario's aggregate over its seeds (not on single runs).
AGGREGATE_KEYS: tuple[str, ...] = (
    "min_success_rate",
    "collision_rate",
    "goal_missed_rate",
    "timeout_rate",
    "mean_time_to_goal_s",
)
_MAX_KEYS: tuple[str, ...] = (
    *LATENCY_METRICS,
    *COUNT_METRICS,
    *(m for m in RELATION_METRICS if m != "relations_matched"),
    *(m for m in SCENARIO_METRICS if m not in ("success", "clearance_m")),
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

    A limit on a metric that is absent is not checked; a nan metric fails (``"... not measured"``).
    """
    failures: list[str] = []
    notes = notes or {}
    for key in THRESHOLD_KEYS:
        if key not in limits:
            continue
        limit = limits[key]
        metric = MIN_KEYS.get(key, key)
        if metric not in metrics:
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
    close = difflib.get_close_matches(key, known, n=1)
    hint = f" (did you mean {close[0]!r}?)" if close else ""
    return ConfigError(f"{path}: {where} unknown key {key!r}{hint}; known keys: {', '.join(known)}")


def _limit(path: Path, where: str, key: str, value: Any, *, allow_off: bool) -> float | None:
    if value is False and allow_off:
        return None
    integer = key in _INTEGER_KEYS
    ok = isinstance(value, int) if integer else isinstance(value, int | float)
    if isinstance(value, bool) or not ok or not math.isfinite(value) or value < 0:
        kind = "a non-negative integer" if integer else "a non-negative number"
        off = " or false" if allow_off else ""
        raise ConfigError(f"{path}: {where} {key} must be {kind}{off}, got {value!r}")
    if key in _RATE_KEYS and value > 1:
        raise ConfigError(f"{path}: {where} {key} is a fraction of the runs, from 0 to 1, got {value!r}")
    return value


def _limits(path: Path, where: str, table: Mapping[str, Any], *, allow_off: bool) -> dict[str, float | None]:
    out: dict[str, float | None] = {}
    for key, value in table.items():
        if key not in THRESHOLD_KEYS:
            raise _unknown(path, where, key, THRESHOLD_KEYS)
        out[key] = _limit(path, where, key, value, allow_off=allow_off)
    return out


def _table(path: Path, where: str, value: Any) -> Mapping[str, Any]:
    if not isinstance(value, dict):
        raise ConfigError(f"{path}: {where} must be a table, got {value!r}")
    return value


def _rule(path: Path, pattern: str, table: Mapping[str, Any]) -> InputRule:
    where = f"[inputs.{pattern!r}]"
    relations: Path | None = None
    goal: tuple[float, float] | None = None
    limit_items: dict[str, Any] = {}
    for key, value in table.items():
        if key == "relations":
            if not isinstance(value, str):
                raise ConfigError(f"{path}: {where} relations must be a path string, got {value!r}")
            relations = path.parent / value
            if not relations.is_file():
                raise ConfigError(f"{path}: {where} relations file not found: {relations}")
        elif key == "goal":
            if not (
                isinstance(value, list)
                and len(value) == 2
                and all(isinstance(v, int | float) and not isinstance(v, bool) for v in value)
            ):
                raise ConfigError(f"{path}: {where} goal must be [x, y] in metres, got {value!r}")
            goal = (float(value[0]), float(value[1]))
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
    try:
        with open(path, "rb") as f:
            doc = tomllib.load(f)
    except OSError as err:
        raise ConfigError(f"{path}: cannot read thresholds file ({err.strerror})") from err
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{path}: not valid TOML ({err})") from err
    for key in doc:
        if key not in ("thresholds", "inputs"):
            raise _unknown(path, "top level:", key, ("thresholds", "inputs"))
    limits: dict[str, float | None] = dict(DEFAULT_LIMITS)
    limits.update(
        _limits(path, "[thresholds]", _table(path, "[thresholds]", doc.get("thresholds", {})), allow_off=True)
    )
    rules = tuple(
        _rule(path, pattern, _table(path, f"[inputs.{pattern!r}]", table))
        for pattern, table in _table(path, "[inputs]", doc.get("inputs", {})).items()
    )
    return Thresholds(limits={k: v for k, v in limits.items() if v is not None}, inputs=rules, source=path)
