"""``gndreplay batch``: many logs (later: closed-loop scenarios) in parallel worker processes, a summary row
and a JUnit test case per input, pass/fail thresholds, and a CI exit code.

>>> jobs = expand_inputs(["../shared/datasets/carmen", "run.bag"])        # doctest: +SKIP
>>> res = run_batch(jobs, cfg=cfg, options=RunOptions(until_s=60), thresholds=load_thresholds("ci.toml"),
...                 out_dir=Path("out/batch"), workers=2, junit=Path("out/batch/junit.xml"))
>>> res.exit_code                                                          # 0 pass, 1 threshold, 2 error

Importing this package is cheap (no numpy / numba / replay code): worker processes import it first and pin
the numeric libraries to one thread before the replay code is loaded.
"""

from .jobs import (
    LOG_SUFFIXES,
    Job,
    JobKind,
    expand_inputs,
    find_logs,
    input_stem,
    safe_name,
    special_file_kind,
    unique_names,
)
from .metrics import COUNT_METRICS, LATENCY_METRICS, RELATION_METRICS, metrics_from_summary
from .report import CSV_COLUMNS, junit_xml, summary_csv, summary_md
from .run import DASK_EXTRA_HINT, DEFAULT_TIMEOUT_S, BatchResult, make_tasks, run_batch, run_tasks
from .thresholds import DEFAULT_LIMITS, THRESHOLD_KEYS, InputRule, Thresholds, check_limits, load_thresholds
from .worker import InputResult, Runner, RunOutcome, Status, Task, execute, pin_threads, run_input

__all__ = [
    "COUNT_METRICS",
    "CSV_COLUMNS",
    "DASK_EXTRA_HINT",
    "DEFAULT_LIMITS",
    "DEFAULT_TIMEOUT_S",
    "LATENCY_METRICS",
    "LOG_SUFFIXES",
    "RELATION_METRICS",
    "THRESHOLD_KEYS",
    "BatchResult",
    "InputResult",
    "InputRule",
    "Job",
    "JobKind",
    "RunOutcome",
    "Runner",
    "Status",
    "Task",
    "Thresholds",
    "check_limits",
    "execute",
    "expand_inputs",
    "find_logs",
    "input_stem",
    "junit_xml",
    "load_thresholds",
    "make_tasks",
    "metrics_from_summary",
    "pin_threads",
    "run_batch",
    "run_input",
    "run_tasks",
    "safe_name",
    "special_file_kind",
    "summary_csv",
    "summary_md",
    "unique_names",
]
