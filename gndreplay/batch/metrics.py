"""The numbers a batch row reports and thresholds check, taken from a run's summary.json.

Metric names carry their unit: ``<module>_<stat>_ms`` for latencies (module: match, model, planner, reactor,
stack = model + planner + reactor, total; stat: median, p90, p99, max), plain counts of ticks on which a
flag fired (``emergency_stops``, ``no_region``, ...), and ``match_*`` relation errors when the input has a
relations file.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from ..evaluation import RelationStats

__all__ = [
    "COUNT_METRICS",
    "LATENCY_METRICS",
    "RELATION_METRICS",
    "metrics_from_summary",
    "relation_metrics",
]

LATENCY_MODULES = ("match", "model", "planner", "reactor", "stack", "total")
LATENCY_STATS = ("median", "p90", "p99", "max")
#: ``<module>_<stat>_ms`` -> (module, stat) in summary.json's ``latency_ms``.
LATENCY_METRICS: Mapping[str, tuple[str, str]] = {
    f"{m}_{s}_ms": (m, s) for m in LATENCY_MODULES for s in LATENCY_STATS
}
#: Count metric -> the flag it counts (ticks on which the flag fired).
COUNT_METRICS: Mapping[str, str] = {
    "match_failures": "MATCH_FAILED",
    "planner_no_path": "PLANNER_NO_PATH",
    "planner_timeouts": "PLANNER_TIMEOUT",
    "goal_in_obstacle": "GOAL_IN_OBSTACLE",
    "no_region": "REACTOR_NO_REGION",
    "emergency_stops": "EMERGENCY_STOP",
    "stale_scans": "STALE_SCAN",
    "traps": "TRAP_DETECTED",
    "match_over_budget": "MATCH_OVER_BUDGET",
    "model_over_budget": "MODEL_OVER_BUDGET",
    "planner_over_budget": "PLANNER_OVER_BUDGET",
    "reactor_over_budget": "REACTOR_OVER_BUDGET",
}
#: Relation-error metrics (inputs with a relations file; see ``gndreplay.evaluation.relation_errors``).
RELATION_METRICS: tuple[str, ...] = (
    "match_trans_err_mean_m",
    "match_trans_err_max_m",
    "match_rot_err_mean_deg",
    "match_rot_err_max_deg",
    "relations_matched",
)


def metrics_from_summary(data: Mapping[str, Any]) -> dict[str, float]:
    """Flatten summary.json into the batch metrics: ``ticks``, latencies [ms] and flag counts.

    A latency module missing from the summary (no ticks) gives no metric; a flag missing counts 0.
    """
    out: dict[str, float] = {"ticks": int(data.get("ticks", 0))}
    latency = data.get("latency_ms") or {}
    for name, (module, stat) in LATENCY_METRICS.items():
        value = (latency.get(module) or {}).get(stat)
        if value is not None:
            out[name] = float(value)
    flags = data.get("flags") or {}
    for name, flag in COUNT_METRICS.items():
        out[name] = int(flags.get(flag, 0))
    return out


def relation_metrics(stats: RelationStats) -> dict[str, float]:
    """Relation-error metrics of a trajectory (errors are nan when no relation matched)."""
    return {
        "match_trans_err_mean_m": stats.trans_mean_m,
        "match_trans_err_max_m": stats.trans_max_m,
        "match_rot_err_mean_deg": stats.rot_mean_deg,
        "match_rot_err_max_deg": stats.rot_max_deg,
        "relations_matched": stats.matched,
    }
