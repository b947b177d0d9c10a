"""The numbers a batch row reports and thresholds check, taken from a run's summary.json.

Metric names carry their unit: ``<module>_<stat>_ms`` for latencies (module: match, model, planner, reactor,
stack = model + planner + reactor, total; stat: median, p90, p99, max), plain counts of ticks on which a
flag fired (``emergency_stops``, ``no_region``, ...), ``match_*`` relation errors when the input has a
relations file, and the errors of the corrected trajectory against ground truth (``TRUTH_METRICS``) when
the input has it. A closed-loop scenario run adds the scores of its result.json and sim_timing.json
(``SCENARIO_METRICS``); the per-scenario aggregates over seeds are ``AGGREGATE_METRICS``.
"""

from __future__ import annotations

from collections.abc import Mapping
from math import nan
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from ..evaluation import RelationStats

__all__ = [
    "AGGREGATE_METRICS",
    "COUNT_METRICS",
    "LATENCY_METRICS",
    "RELATION_METRICS",
    "SCENARIO_METRICS",
    "TRUTH_METRICS",
    "metrics_from_result",
    "metrics_from_summary",
    "outcome_note",
    "relation_metrics",
]

LATENCY_MODULES = ("match", "model", "planner", "reactor", "supervisor", "stack", "total")
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


#: Ground-truth metric -> its key in summary.json's ``truth.corrected.aligned``: the corrected trajectory
#: after the SE(2) alignment to the truth, ATE RMSE [m] and the RMSE of the 1 s RPE [m], [deg]
#: (``gndreplay.evaluation.trajectory_errors``). An input without ground truth has none of them.
TRUTH_METRICS: Mapping[str, str] = {
    "ate_m": "ate_rmse_m",
    "rpe_m": "rpe_trans_rmse_m",
    "rpe_deg": "rpe_rot_rmse_deg",
}


def metrics_from_summary(data: Mapping[str, Any]) -> dict[str, float]:
    """Flatten summary.json into the batch metrics: ``ticks``, latencies [ms], flag counts (the
    ``*_OVER_BUDGET`` counts from its ``over_budget`` table, the others from ``flags``) and, with ground
    truth, ``TRUTH_METRICS``.

    A latency module missing from the summary (no ticks) gives no metric; a flag missing counts 0; without
    truth (``truth`` null) there is no truth metric, and one that is not a number (no pose paired with the
    truth) is nan.
    """
    out: dict[str, float] = {"ticks": int(data.get("ticks", 0))}
    latency = data.get("latency_ms") or {}
    for name, (module, stat) in LATENCY_METRICS.items():
        value = (latency.get(module) or {}).get(stat)
        if value is not None:
            out[name] = float(value)
    flags = data.get("flags") or {}
    over = data.get("over_budget") or {}  # the wall-clock *_OVER_BUDGET counts (always recorded here)
    for name, flag in COUNT_METRICS.items():
        out[name] = int(over[flag] if flag in over else flags.get(flag, 0))
    truth = data.get("truth")
    if isinstance(truth, Mapping):
        aligned = (truth.get("corrected") or {}).get("aligned") or {}
        for name, key in TRUTH_METRICS.items():
            value = aligned.get(key)
            if isinstance(value, bool) or not isinstance(value, int | float):
                value = nan
            out[name] = float(value)
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


#: Scenario run metric -> where it comes from: the outcome (1 or 0), a result.json field, or a
#: sim_timing.json field (wall clock). A field that is null (no time to goal after a collision, no obstacle
#: ever in range) gives no metric. ``goal_missed``: the stack reported GOAL_REACHED and stopped with the true
#: axle outside the goal tolerance (its localisation error), apart from the time-outs; ``takeovers``: onsets
#: of an active navigation mode other than the desired one; ``local_ticks_pct``: share of ticks local
#: navigation was the active mode [%]; ``optimal_path_m``: the robot's inscribed circle's shortest path from
#: the start to the goal in the static world at t = 0; ``challenge_metric``: the navigation-challenge metric,
#: success * OT / clip(time to goal, 2 OT, 8 OT), OT the optimal path at 2 m/s (0 for a failure; none without
#: an optimal path; ``gndreplay.sim.score``).
SCENARIO_METRICS: Mapping[str, str] = {
    "success": "outcome == success",
    "collisions": "outcome == collision",
    "goal_missed": "outcome == goal_missed",
    "timeouts": "outcome == timeout",
    "goal_miss_m": "goal_missed.true_distance_m",
    "takeovers": "takeovers",
    "local_ticks_pct": "100 * active_modes.local / ticks",
    "time_to_goal_s": "time_to_goal_s",
    "clearance_m": "min_clearance_m",
    "path_length_m": "path_length_m",
    "optimal_path_m": "optimal_path_m",
    "challenge_metric": "challenge_metric",
    "security_time_pct": "time_inside_security_pct",
    "sim_ms_per_step": "sim_ms_per_step",
    "stack_ms_per_tick": "stack_ms_per_tick",
}
_OUTCOME_COUNTS = {"success": "success", "collisions": "collision", "goal_missed": "goal_missed",
                   "timeouts": "timeout"}
#: Metrics of one scenario over its seeds (runs that did not end in an error): the fractions of runs that
#: reached the goal, collided, stopped short of it (goal missed), timed out; the mean time to goal of the
#: successes; the smallest clearance; the mean challenge metric (a failure counts 0; runs without an optimal
#: path apart).
AGGREGATE_METRICS: tuple[str, ...] = (
    "success_rate",
    "collision_rate",
    "goal_missed_rate",
    "timeout_rate",
    "mean_time_to_goal_s",
    "min_clearance_m",
    "mean_challenge_metric",
)


def metrics_from_result(result: Mapping[str, Any], timing: Mapping[str, Any]) -> dict[str, float]:
    """The ``SCENARIO_METRICS`` of one closed-loop run from its result.json and sim_timing.json."""
    outcome = result.get("outcome")
    out: dict[str, float] = {name: int(outcome == value) for name, value in _OUTCOME_COUNTS.items()}
    missed = result.get("goal_missed")
    ticks = result.get("ticks")
    active = result.get("active_modes")
    derived = {
        "goal_miss_m": missed.get("true_distance_m") if isinstance(missed, Mapping) else None,
        "local_ticks_pct": (100.0 * float(active.get("local", 0)) / ticks if isinstance(active, Mapping)
                            and isinstance(ticks, int) and ticks > 0 else None),
    }
    for name, key in SCENARIO_METRICS.items():
        if name in out:
            continue
        value = derived[name] if name in derived else result.get(key, timing.get(key))
        if isinstance(value, int | float) and not isinstance(value, bool):
            out[name] = float(value)
    return out


def outcome_note(result: Mapping[str, Any]) -> str:
    """How a run ended, in words: ``"collision with door at 12.34 s"``, ``"timeout at 60.0 s"``, ..."""
    outcome = str(result.get("outcome"))
    end = result.get("end_time_s")
    at = f" at {end:.2f} s" if isinstance(end, int | float) else ""
    contact = result.get("collision")
    if outcome == "collision" and isinstance(contact, Mapping):
        who = "hit by" if contact.get("hit_by_mover") else "collision with"
        t = contact.get("t_s", end)
        return f"{who} {contact.get('object')}" + (f" at {t:.2f} s" if isinstance(t, int | float) else "")
    if outcome == "timeout":
        return f"timeout{at}: goal not reached"
    missed = result.get("goal_missed")
    if outcome == "goal_missed" and isinstance(missed, Mapping):
        d, tol = missed.get("true_distance_m"), missed.get("tolerance_m")
        far = (f": the stack stopped at the goal, the true axle {d:.3f} m from it (tolerance {tol:g} m)"
               if isinstance(d, int | float) and isinstance(tol, int | float) else "")
        return f"goal missed{at}{far}"
    return f"{outcome}{at}"
