"""Scan matching: odometry correctors behind one ``Matcher`` protocol.

- ``idc``: our Iterative Dual Correspondence (Lu & Milios 1997) against a local map of keyframes.
- ``kiss-icp``: the KISS-ICP adapter (points lifted to z = 0).
- ``odom``: raw odometry, the baseline.

>>> matcher = make_matcher("idc")                                   # doctest: +SKIP
>>> for tick in ticks:                                              # doctest: +SKIP
...     res = matcher.update(tick.scan, tick.odom)                  # res.pose, res.ok, res.reason
"""

from __future__ import annotations

from .ahead import MatchAhead
from .base import Matcher, MatchResult, OdomMatcher
from .idc import IdcMatcher, IdcParams
from .kiss import KissIcpMatcher, KissParams
from .run import (
    METHODS,
    CorrectedTrajectory,
    MatcherReport,
    correct_trajectories,
    correct_trajectory,
    health_params,
    interleave_bearings,
    keep_by_travel,
    make_matcher,
    matcher_report,
    run_scanmatch,
    timed_matches,
    warm_up_matcher,
)

__all__ = [
    "METHODS",
    "CorrectedTrajectory",
    "IdcMatcher",
    "IdcParams",
    "KissIcpMatcher",
    "KissParams",
    "MatchAhead",
    "MatchResult",
    "Matcher",
    "MatcherReport",
    "OdomMatcher",
    "correct_trajectories",
    "correct_trajectory",
    "health_params",
    "interleave_bearings",
    "keep_by_travel",
    "make_matcher",
    "matcher_report",
    "run_scanmatch",
    "timed_matches",
    "warm_up_matcher",
]
