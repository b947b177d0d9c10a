"""``gndreplay batch``: many logs and closed-loop scenario runs in parallel worker processes, a summary row
and a JUnit test case per input (a scenario: per scenario and seed), per-scenario aggregates over seeds,
pass/fail thresholds, and a CI exit code.

>>> jobs = expand_inputs(["../shared/datasets/carmen", "run.bag", "mine.yaml"], scenarios=["all"],
...                      seeds=parse_seeds("1-20"))                       # doctest: +SKIP
>>> res = run_batch(jobs, cfg=cfg, options=RunOptions(until_s=60), thresholds=load_thresholds("ci.toml"),
...                 out_dir=Path("out/batch"), workers=2, junit=Path("out/batch/junit.xml"),
...                 sim=SimOptions(time_limit_s=60))
>>> res.exit_code                                                          # 0 pass, 1 threshold, 2 error

``run_batch(..., baseline=Baseline(Path("ci/baseline"), Tolerance()))`` checks every run against an earlier
batch folder; ``sweep=[Setting(point, cfg, sim) for point in sweep_points(sets)]`` runs every input under
each combination of a ``--set key=a,b`` sweep.

Importing this package is cheap (no numpy / numba / replay code): worker processes import it first and pin
the numeric libraries to one thread before the replay code is loaded.
"""

from .aggregate import ScenarioAggregate, aggregate_scenarios
from .baseline import DEFAULT_LATENCY_RATIO, BaselineCheck, check_baseline
from .jobs import (
    SCENARIO_SUFFIXES,
    Job,
    JobKind,
    expand_inputs,
    find_logs,
    input_stem,
    parse_seeds,
    safe_name,
    shipped_names,
    special_file_kind,
    unique_names,
)
from .merge import merge_batches
from .metrics import (
    AGGREGATE_METRICS,
    COUNT_METRICS,
    LATENCY_METRICS,
    RELATION_METRICS,
    SCENARIO_METRICS,
    metrics_from_result,
    metrics_from_summary,
)
from .record import BATCH_FILE, BatchRecord, read_record
from .report import CSV_COLUMNS, SCENARIO_CSV_COLUMNS, junit_xml, scenarios_csv, summary_csv, summary_md
from .run import (
    DASK_EXTRA_HINT,
    DEFAULT_TIMEOUT_S,
    Baseline,
    BatchResult,
    Setting,
    make_tasks,
    run_batch,
    run_tasks,
)
from .scenarios import SimOptions, run_scenario
from .shard import Shard, parse_shard, shard_indices
from .sweep import SweepPoint, sweep_points
from .thresholds import (
    AGGREGATE_KEYS,
    DEFAULT_LIMITS,
    THRESHOLD_KEYS,
    InputRule,
    Thresholds,
    check_limits,
    load_thresholds,
)
from .worker import InputResult, Runner, RunOutcome, Status, Task, execute, pin_threads, run_input

__all__ = [
    "AGGREGATE_KEYS",
    "AGGREGATE_METRICS",
    "BATCH_FILE",
    "COUNT_METRICS",
    "CSV_COLUMNS",
    "DASK_EXTRA_HINT",
    "DEFAULT_LATENCY_RATIO",
    "DEFAULT_LIMITS",
    "DEFAULT_TIMEOUT_S",
    "LATENCY_METRICS",
    "RELATION_METRICS",
    "SCENARIO_CSV_COLUMNS",
    "SCENARIO_METRICS",
    "SCENARIO_SUFFIXES",
    "THRESHOLD_KEYS",
    "Baseline",
    "BaselineCheck",
    "BatchRecord",
    "BatchResult",
    "InputResult",
    "InputRule",
    "Job",
    "JobKind",
    "RunOutcome",
    "Runner",
    "ScenarioAggregate",
    "Setting",
    "Shard",
    "SimOptions",
    "Status",
    "SweepPoint",
    "Task",
    "Thresholds",
    "aggregate_scenarios",
    "check_baseline",
    "check_limits",
    "execute",
    "expand_inputs",
    "find_logs",
    "input_stem",
    "junit_xml",
    "load_thresholds",
    "make_tasks",
    "merge_batches",
    "metrics_from_result",
    "metrics_from_summary",
    "parse_seeds",
    "parse_shard",
    "pin_threads",
    "read_record",
    "run_batch",
    "run_input",
    "run_scenario",
    "run_tasks",
    "safe_name",
    "scenarios_csv",
    "shard_indices",
    "shipped_names",
    "special_file_kind",
    "summary_csv",
    "summary_md",
    "sweep_points",
    "unique_names",
]
