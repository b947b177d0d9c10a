"""Trajectory evaluation: the SLAM-benchmark relations metric, SE(2) ground-truth metrics (ATE, RPE) and
TUM trajectory reading and writing.

The relations metric is the one of Kümmerle et al., "On measuring the accuracy of SLAM algorithms" (Autonomous
Robots 2009): for each relation (t1, t2, δ*) with δ* the reference pose of the scan at t2 in the frame of the
scan at t1, the estimated relative pose is δ = pose(t1)⁻¹ ∘ pose(t2) and the error is δ*⁻¹ ∘ δ. Its
translational part is ‖R*ᵀ (t - t*)‖ = ‖t - t*‖ (a rotation keeps the norm, so the "difference of the
translation components" convention gives the same number) and its rotational part is |wrap(θ - θ*)|. The
benchmark reports the mean ± standard deviation of both over all relations (the "absolute" errors).

Scans are identified by their timestamp (CARMEN ipc_timestamp, ROS header stamp); a relation end matches the
nearest scan stamp within ``tol_s`` (the relation files print 1e-5 s or 1e-6 s).

Against a ground-truth trajectory (:func:`trajectory_errors`) each estimated pose is paired with the truth
pose nearest in time within ``tol_s`` (no interpolation: a run's truth is stamped at its scans, so pairs are
exact, and nothing is invented across a gap of the truth). The estimate is then aligned to the truth by the
closed-form SE(2) Umeyama fit (rotation about z and translation, no scale: :func:`align_se2`) or placed on
the truth's first paired pose (:func:`align_origin`). ATE is the translational distance of each aligned pose
from its truth pose; RPE compares the motion over each pair of poses ``delta_s`` apart (the first pose at or
after t + delta_s, kept when the pair spans at most 1.5 delta_s, so gaps do not make long pairs). RPE does not
depend on the alignment (a rigid transform of the whole estimate keeps its relative poses).
"""

from __future__ import annotations

import math
import os
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import detmath as dm
from .errors import GndReplayError, one_line
from .fsutil import atomic_write_text, format_stamp
from .geometry import compose, inverse, relative, wrap_angle
from .io.base import MAX_ABS_TIME_NS
from .io.userfile import brief, read_text

__all__ = ["ALIGNMENTS", "FAILURE_CATEGORIES", "MAX_RELATIONS_BYTES", "MAX_TUM_BYTES", "REFUSALS", "SPANS",
           "HealthParams", "MatcherHealth", "RelationStats", "Relations", "SpanStats", "TrajectoryErrors",
           "align_origin", "align_se2", "associate", "failure_category", "load_relations", "matcher_health",
           "read_tum", "relation_errors", "relations_from_trajectory", "trajectory_errors", "write_tum"]

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]
NS_PER_S = 1_000_000_000
MAX_RELATIONS_BYTES = 64 << 20
"""Largest relations file read (64 MB: the SLAM benchmark's files are a few MB)."""
MAX_TUM_BYTES = 256 << 20
"""Largest TUM trajectory read back (256 MB: about 2.5 million poses, a week of scans at 4 Hz)."""


@dataclass(frozen=True, eq=False)
class Relations:
    """Reference relative poses between pairs of scans.

    Attributes:
        t1_ns, t2_ns: (M,) int64 stamps of the two scans [ns].
        dx, dy: (M,) float64 translation of scan t2 in the frame of scan t1 [m].
        dyaw: (M,) float64 rotation of scan t2 in the frame of scan t1 [rad].
    """

    t1_ns: I64
    t2_ns: I64
    dx: F64
    dy: F64
    dyaw: F64

    def __len__(self) -> int:
        return int(self.t1_ns.shape[0])


def relations_from_trajectory(t_ns: ArrayLike, poses: ArrayLike, steps: tuple[int, ...] = (1,)) -> Relations:
    """Relations taken from a reference trajectory: between each pose and the one ``step`` poses later, for
    each step (e.g. a full-rate trajectory as the reference of a decimated run).

    Raises:
        ValueError: shapes disagree, or a step is not positive.
    """
    t, p = _trajectory_arrays(t_ns, poses)
    if any(st < 1 for st in steps):
        raise ValueError(f"steps must be positive, got {steps}")
    pairs = [(t[:-st], t[st:], relative(p[:-st], p[st:])) for st in steps if st < t.shape[0]]
    if not pairs:
        e = np.zeros(0)
        return Relations(np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), e, e.copy(), e.copy())
    d = np.concatenate([x[2] for x in pairs])
    return Relations(np.concatenate([x[0] for x in pairs]), np.concatenate([x[1] for x in pairs]),
                     d[:, 0].copy(), d[:, 1].copy(), d[:, 2].copy())


def _seconds_to_ns(text: str) -> int:
    """Exact decimal seconds -> int ns (no float rounding: stamps are ~1e9 s).

    Raises:
        ValueError: not a decimal number, or a stamp beyond the readers' bound (``MAX_ABS_TIME_NS``: the
            stamps are stored as int64 ns).
    """
    whole, _, frac = text.strip().partition(".")
    sign = -1 if whole.startswith("-") else 1
    frac_ns = int((frac + "000000000")[:9]) if frac else 0
    ns = int(whole) * NS_PER_S + sign * frac_ns
    if not -MAX_ABS_TIME_NS <= ns <= MAX_ABS_TIME_NS:
        raise ValueError(f"stamp {brief(text)} s out of range")
    return ns


def load_relations(path: str | os.PathLike[str]) -> Relations:
    """Read a SLAM-benchmark relations file: one ``t1 t2 x y z roll pitch yaw`` line per relation.

    Blank lines and lines starting with ``#`` are skipped; z, roll and pitch are ignored (planar).

    Raises:
        GndReplayError: the file is missing, not a regular file of at most ``MAX_RELATIONS_BYTES`` of UTF-8
            text, or a line does not have 8 numbers.
    """
    p = Path(path)
    text = read_text(p, "relations file", MAX_RELATIONS_BYTES)
    t1: list[int] = []
    t2: list[int] = []
    vals: list[tuple[float, float, float]] = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        tok = s.split()
        if len(tok) != 8:
            raise GndReplayError(f"{p} line {lineno}: expected 8 numbers 't1 t2 x y z roll pitch yaw', "
                                 f"found {len(tok)}")
        try:
            t1.append(_seconds_to_ns(tok[0]))
            t2.append(_seconds_to_ns(tok[1]))
            vals.append((float(tok[2]), float(tok[3]), float(tok[7])))
        except ValueError as err:
            raise GndReplayError(f"{p} line {lineno}: not a number ({one_line(err, 120)})") from err
    v = np.array(vals, dtype=np.float64).reshape(-1, 3)
    return Relations(np.array(t1, dtype=np.int64), np.array(t2, dtype=np.int64), v[:, 0].copy(),
                     v[:, 1].copy(), v[:, 2].copy())


#: relation spans reported apart [s]: below 1 s the error is the matches' own (local accuracy), beyond 10 s
#: mostly drift (loop-closing relations)
SPANS: tuple[tuple[str, float, float], ...] = (
    ("<1 s", 0.0, 1.0), ("1-10 s", 1.0, 10.0), (">10 s", 10.0, math.inf))


@dataclass(frozen=True)
class SpanStats:
    """Errors of the matched relations whose span |t2 - t1| lies in [lo_s, hi_s).

    Attributes:
        label: e.g. "<1 s".
        count: relations in the span.
        trans_mean_m, trans_max_m: translational error [m] (nan when count is 0).
        rot_mean_deg, rot_max_deg: rotational error [deg].
    """

    label: str
    lo_s: float
    hi_s: float
    count: int
    trans_mean_m: float
    trans_max_m: float
    rot_mean_deg: float
    rot_max_deg: float

    def to_dict(self) -> dict[str, Any]:
        return {"label": self.label, "count": self.count, "trans_mean_m": self.trans_mean_m,
                "trans_max_m": self.trans_max_m, "rot_mean_deg": self.rot_mean_deg,
                "rot_max_deg": self.rot_max_deg}


@dataclass(frozen=True, eq=False)
class RelationStats:
    """Relation errors of one trajectory.

    Attributes:
        matched, unmatched: relations whose two stamps were / were not both found in the trajectory.
        trans_mean_m, trans_std_m, trans_max_m: translational error statistics [m] (nan if none matched).
        rot_mean_deg, rot_std_deg, rot_max_deg: rotational error statistics [deg].
        index: (matched,) indices into the relations of the matched ones.
        trans_err_m: (matched,) translational error per matched relation [m].
        rot_err_deg: (matched,) rotational error per matched relation [deg].
        by_span: the same errors split by relation span (:data:`SPANS`).
    """

    matched: int
    unmatched: int
    trans_mean_m: float
    trans_std_m: float
    trans_max_m: float
    rot_mean_deg: float
    rot_std_deg: float
    rot_max_deg: float
    index: I64
    trans_err_m: F64
    rot_err_deg: F64
    by_span: tuple[SpanStats, ...] = ()

    def span(self, label: str) -> SpanStats:
        """The span statistics labelled ``label`` (one of :data:`SPANS`)."""
        for s in self.by_span:
            if s.label == label:
                return s
        raise KeyError(label)

    def to_dict(self) -> dict[str, Any]:
        """Summary numbers (no per-relation arrays), JSON-ready."""
        return {
            "matched": self.matched, "unmatched": self.unmatched,
            "trans_mean_m": self.trans_mean_m, "trans_std_m": self.trans_std_m,
            "trans_max_m": self.trans_max_m, "rot_mean_deg": self.rot_mean_deg,
            "rot_std_deg": self.rot_std_deg, "rot_max_deg": self.rot_max_deg,
            "by_span": [s.to_dict() for s in self.by_span],
        }


def _nearest(sorted_t: I64, q: I64) -> tuple[I64, I64]:
    """Index of the nearest value of ``sorted_t`` to each query and the absolute gap [ns]."""
    i = np.clip(np.searchsorted(sorted_t, q), 1, max(sorted_t.shape[0] - 1, 1))
    lo = np.maximum(i - 1, 0)
    d_lo = np.abs(q - sorted_t[lo])
    d_hi = np.abs(sorted_t[np.minimum(i, sorted_t.shape[0] - 1)] - q)
    pick = np.where(d_hi < d_lo, np.minimum(i, sorted_t.shape[0] - 1), lo)
    return pick, np.minimum(d_lo, d_hi)


def _stats(x: F64) -> tuple[float, float, float]:
    if x.size == 0:
        return math.nan, math.nan, math.nan
    return float(np.mean(x)), float(np.std(x)), float(np.max(x))


def _span_stats(span_s: F64, e_t: F64, e_r: F64) -> tuple[SpanStats, ...]:
    out = []
    for label, lo, hi in SPANS:
        m = (span_s >= lo) & (span_s < hi)
        t_mean, _, t_max = _stats(e_t[m])
        r_mean, _, r_max = _stats(e_r[m])
        out.append(SpanStats(label, lo, hi, int(m.sum()), t_mean, t_max, r_mean, r_max))
    return tuple(out)


def relation_errors(t_ns: ArrayLike, poses: ArrayLike, relations: Relations, *,
                    tol_s: float = 1e-4) -> RelationStats:
    """Errors of a trajectory against reference relations (Kümmerle et al. 2009).

    Args:
        t_ns: (N,) int scan stamps [ns], any order, unique.
        poses: (N, 3) estimated poses (x, y, theta) at those stamps.
        relations: the reference relations.
        tol_s: largest stamp difference [s] for a relation end to match a scan.

    Raises:
        ValueError: shapes disagree.
    """
    t, p = _trajectory_arrays(t_ns, poses)
    m = len(relations)
    empty = np.zeros(0)
    if t.size == 0 or m == 0:
        return RelationStats(0, m, math.nan, math.nan, math.nan, math.nan, math.nan, math.nan,
                             np.zeros(0, dtype=np.int64), empty, empty, _span_stats(empty, empty, empty))
    order = np.argsort(t, kind="stable")
    ts, ps = t[order], p[order]
    tol_ns = round(tol_s * NS_PER_S)
    i1, g1 = _nearest(ts, relations.t1_ns)
    i2, g2 = _nearest(ts, relations.t2_ns)
    ok = (g1 <= tol_ns) & (g2 <= tol_ns)
    est = relative(ps[i1[ok]], ps[i2[ok]])
    e_t = np.hypot(est[:, 0] - relations.dx[ok], est[:, 1] - relations.dy[ok])
    e_r = np.degrees(np.abs(np.asarray(wrap_angle(est[:, 2] - relations.dyaw[ok]))))
    tm, ts_, tx = _stats(e_t)
    rm, rs, rx = _stats(e_r)
    n_ok = int(ok.sum())
    index = np.flatnonzero(ok).astype(np.int64)
    span_s = np.abs(relations.t2_ns[ok] - relations.t1_ns[ok]) / NS_PER_S
    return RelationStats(n_ok, m - n_ok, tm, ts_, tx, rm, rs, rx, index, e_t, e_r,
                         _span_stats(span_s, e_t, e_r))


ALIGNMENTS = ("se2", "origin")
"""How :func:`trajectory_errors` aligns the estimate: SE(2) Umeyama fit, or its first pose on the truth's."""


@dataclass(frozen=True, eq=False)
class TrajectoryErrors:
    """Errors of an estimated trajectory against ground truth (:func:`trajectory_errors`).

    Attributes:
        alignment: one of :data:`ALIGNMENTS`.
        matched, unmatched: estimated poses with / without a truth pose within the tolerance.
        transform: (3,) the SE(2) transform (x, y [m], yaw [rad]) applied to the estimate.
        ate_rmse_m, ate_mean_m, ate_median_m, ate_max_m: translational error of the aligned poses [m]
            (nan when none matched).
        rpe_delta_s: the span of an RPE pair [s]; rpe_pairs: pose pairs that far apart.
        rpe_trans_rmse_m, rpe_trans_mean_m, rpe_trans_max_m: translational error of a pair's motion [m].
        rpe_rot_rmse_deg, rpe_rot_mean_deg, rpe_rot_max_deg: its rotational error [deg].
        t_ns: (matched,) stamps of the matched estimated poses; ate_m: (matched,) their error [m];
            yaw_err_deg: (matched,) their heading error (aligned minus truth, wrapped) [deg].
    """

    alignment: str
    matched: int
    unmatched: int
    transform: F64
    ate_rmse_m: float
    ate_mean_m: float
    ate_median_m: float
    ate_max_m: float
    rpe_delta_s: float
    rpe_pairs: int
    rpe_trans_rmse_m: float
    rpe_trans_mean_m: float
    rpe_trans_max_m: float
    rpe_rot_rmse_deg: float
    rpe_rot_mean_deg: float
    rpe_rot_max_deg: float
    t_ns: I64
    ate_m: F64
    yaw_err_deg: F64

    def to_dict(self) -> dict[str, Any]:
        """Summary numbers (no per-pose arrays), JSON-ready."""
        return {
            "alignment": self.alignment, "matched": self.matched, "unmatched": self.unmatched,
            "transform": [float(v) for v in self.transform],
            "ate_rmse_m": self.ate_rmse_m, "ate_mean_m": self.ate_mean_m, "ate_median_m": self.ate_median_m,
            "ate_max_m": self.ate_max_m, "rpe_delta_s": self.rpe_delta_s, "rpe_pairs": self.rpe_pairs,
            "rpe_trans_rmse_m": self.rpe_trans_rmse_m, "rpe_trans_mean_m": self.rpe_trans_mean_m,
            "rpe_trans_max_m": self.rpe_trans_max_m, "rpe_rot_rmse_deg": self.rpe_rot_rmse_deg,
            "rpe_rot_mean_deg": self.rpe_rot_mean_deg, "rpe_rot_max_deg": self.rpe_rot_max_deg,
        }


def associate(t_est: ArrayLike, t_ref: ArrayLike, *, tol_s: float = 0.01) -> tuple[I64, I64]:
    """Pair each estimated stamp with the nearest reference stamp within ``tol_s``: indices (into the
    arguments, any order) of the pairs, in the order of the estimate's stamps."""
    te = np.asarray(t_est, dtype=np.int64)
    tr = np.asarray(t_ref, dtype=np.int64)
    if te.size == 0 or tr.size == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    order_e = np.argsort(te, kind="stable")
    order_r = np.argsort(tr, kind="stable")
    j, gap = _nearest(tr[order_r], te[order_e])
    ok = gap <= round(tol_s * NS_PER_S)
    return order_e[ok].astype(np.int64), order_r[j[ok]].astype(np.int64)


def align_se2(est_xy: ArrayLike, ref_xy: ArrayLike) -> F64:
    """The SE(2) transform (x, y, yaw) T minimising sum ||ref - T(est)||² over paired (N, 2) positions:
    Umeyama's closed form restricted to a rotation about z (no scale). Identity for no pair; a single pair
    (or all estimated positions equal) fixes the translation only."""
    p = np.asarray(est_xy, dtype=np.float64).reshape(-1, 2)
    q = np.asarray(ref_xy, dtype=np.float64).reshape(-1, 2)
    if p.shape != q.shape:
        raise ValueError(f"paired positions must have one shape, got {p.shape} and {q.shape}")
    if p.shape[0] == 0:
        return np.zeros(3)
    mp, mq = p.mean(axis=0), q.mean(axis=0)
    pc, qc = p - mp, q - mq
    cross = float(np.sum(pc[:, 0] * qc[:, 1] - pc[:, 1] * qc[:, 0]))
    dot = float(np.sum(pc[:, 0] * qc[:, 0] + pc[:, 1] * qc[:, 1]))
    yaw = dm.atan2(cross, dot) if cross or dot else 0.0
    c, s = dm.cos(yaw), dm.sin(yaw)
    return np.array([mq[0] - (c * mp[0] - s * mp[1]), mq[1] - (s * mp[0] + c * mp[1]), yaw])


def align_origin(est_pose: ArrayLike, ref_pose: ArrayLike) -> F64:
    """The SE(2) transform that puts the estimated pose ``est_pose`` on ``ref_pose`` (the "unaligned"
    comparison: both trajectories start together)."""
    return compose(np.asarray(ref_pose, dtype=np.float64), inverse(np.asarray(est_pose, dtype=np.float64)))


def _rms_mean_median_max(x: F64) -> tuple[float, float, float, float]:
    if x.size == 0:
        return math.nan, math.nan, math.nan, math.nan
    return (float(np.sqrt(np.mean(x * x))), float(np.mean(x)), float(np.median(x)), float(np.max(x)))


def _pairs_apart(t_ns: I64, delta_s: float) -> tuple[I64, I64]:
    """Index pairs (i, j) of sorted stamps about ``delta_s`` apart: j the first pose at or after t_i +
    delta_s, kept when the pair spans at most 1.5 delta_s (no pair across a gap)."""
    d_ns = round(delta_s * NS_PER_S)
    j = np.searchsorted(t_ns, t_ns + d_ns, side="left")
    i = np.flatnonzero(j < t_ns.shape[0])
    j = j[i]
    keep = (t_ns[j] - t_ns[i]) <= round(1.5 * d_ns)
    return i[keep].astype(np.int64), j[keep].astype(np.int64)


def _motion_error(a: F64, b: F64, i: I64, j: I64) -> tuple[F64, F64]:
    """Translational [m] and rotational [rad, absolute] difference of trajectory b's motion from i to j
    against trajectory a's (``relative`` of the two relative poses)."""
    err = relative(relative(a[i], a[j]), relative(b[i], b[j])).reshape(-1, 3)
    return np.hypot(err[:, 0], err[:, 1]), np.abs(err[:, 2])


def _rpe(t_ns: I64, est: F64, ref: F64, delta_s: float) -> tuple[F64, F64]:
    """Translational [m] and rotational [deg] error of the motion over each pair of poses ``delta_s`` apart
    (sorted stamps, :func:`_pairs_apart`)."""
    e_t, e_r = _motion_error(ref, est, *_pairs_apart(t_ns, delta_s))
    return e_t, np.degrees(e_r)


def trajectory_errors(t_est: ArrayLike, est: ArrayLike, t_ref: ArrayLike, ref: ArrayLike, *,
                      alignment: str = "se2", tol_s: float = 0.01, rpe_delta_s: float = 1.0
                      ) -> TrajectoryErrors:
    """ATE and RPE of the estimated trajectory (``t_est`` (N,) int ns, ``est`` (N, 3)) against the truth
    (``t_ref``, ``ref``), paired by time within ``tol_s`` (:func:`associate`) and aligned by ``alignment``
    (see the module docstring).

    Raises:
        ValueError: shapes disagree, an unknown alignment, or a delta that is not positive.
    """
    te, pe = _trajectory_arrays(t_est, est)
    tr, pr = _trajectory_arrays(t_ref, ref)
    if alignment not in ALIGNMENTS:
        raise ValueError(f"alignment must be one of {', '.join(ALIGNMENTS)}, got {alignment!r}")
    if not rpe_delta_s > 0.0:
        raise ValueError(f"rpe_delta_s must be positive, got {rpe_delta_s}")
    ie, ir = associate(te, tr, tol_s=tol_s)
    t, p, q = te[ie], pe[ie], pr[ir]
    if t.size == 0:
        transform = np.zeros(3)
    elif alignment == "se2":
        transform = align_se2(p[:, :2], q[:, :2])
    else:
        transform = align_origin(p[0], q[0])
    aligned = compose(transform, p).reshape(-1, 3)
    ate = np.hypot(aligned[:, 0] - q[:, 0], aligned[:, 1] - q[:, 1])
    yaw_err = np.degrees(np.asarray(wrap_angle(aligned[:, 2] - q[:, 2])).reshape(-1))
    e_t, e_r = _rpe(t, p, q, rpe_delta_s)
    a = _rms_mean_median_max(ate)
    rt = _rms_mean_median_max(e_t)
    rr = _rms_mean_median_max(e_r)
    return TrajectoryErrors(alignment, int(t.size), int(te.size - t.size), transform, *a, rpe_delta_s,
                            int(e_t.size), rt[0], rt[1], rt[3], rr[0], rr[1], rr[3], t, ate, yaw_err)


# ---- scan-matcher health ----------------------------------------------------------------------------

#: The categories of a failed match, by the leading words of its reason (``MatchResult.reason``): the
#: matcher found no usable match (too few valid beams, too few pairs, a residual too large, a degenerate
#: geometry), or found one and refused it as inconsistent with the odometry or its prior (``REFUSALS``).
#: Any other reason is "other".
FAILURE_CATEGORIES: tuple[str, ...] = (
    "too few valid beams", "too few pairs", "residual", "degenerate geometry",
    "correction too far from the prior", "unconfirmed match",
)
#: The categories of a match found and refused (its correction disagreed with the odometry or its prior).
REFUSALS = frozenset(("correction too far from the prior", "unconfirmed match"))
#: What the IDC matcher appends to the reason of a failure after a gap in the log (its map restarts there).
_AFTER_GAP = " after a gap of "


def failure_category(reason: str) -> str:
    """The category of a failed match's ``reason`` (one of ``FAILURE_CATEGORIES``, else "other"; "" for an
    accepted match's empty reason)."""
    if not reason:
        return ""
    return next((c for c in FAILURE_CATEGORIES if reason.startswith(c)), "other")


class OdometrySigmas(Protocol):
    """An odometry error model per increment, as ``scanmatch.IdcParams`` states it."""

    @property
    def odo_sigma_m(self) -> float: ...

    @property
    def odo_sigma_rel(self) -> float: ...

    @property
    def odo_sigma_rad(self) -> float: ...

    @property
    def odo_sigma_rel_rad(self) -> float: ...


@dataclass(frozen=True, slots=True)
class HealthParams:
    """The odometry error model and the limits of :func:`matcher_health`'s warning.

    Over a window of ``window_s`` the matcher's motion may differ from the odometry's by sigma_t = sigma_m +
    sigma_rel * d in translation and sigma_r = sigma_rad + sigma_rel_rad * turn + sigma_rad_per_m * d in
    rotation, with d and turn the larger of the two trajectories' path length [m] and accumulated turn [rad]
    in the window (the true motion is unknown; with the larger one, odometry that stalled does not make the
    matcher look wrong). The defaults are the IDC matcher's own model of the odometry
    (``IdcParams.odo_sigma_*``, see :meth:`from_odometry`) plus 2 deg per metre driven. Measured on the dev
    logs (``gndreplay scanmatch``, docs/results.md) the worst 5 s window is 2.4 sigmas (MIT CSAIL, whose
    odometry under-reports turns) and a laser that repeats its last scan for 5 s while the robot drives
    1.5 m is 4.3.

    Attributes:
        window_s: the stretch compared [s]; max_sigmas: the disagreement that warns.
        max_failed_share: the share of failed matches that warns (the dev logs: at most 5 %).
        worse_margin_m, worse_margin_rel: with ground truth, the matcher warns when its aligned ATE RMSE
            exceeds the odometry's by more than max(worse_margin_m, worse_margin_rel * the odometry's).
    """

    sigma_m: float = 0.1
    sigma_rel: float = 1.0 / 6.0
    sigma_rad: float = math.radians(10.0 / 3.0)
    sigma_rel_rad: float = 1.0 / 6.0
    sigma_rad_per_m: float = math.radians(2.0)
    window_s: float = 5.0
    max_sigmas: float = 4.0
    max_failed_share: float = 0.2
    worse_margin_m: float = 0.02
    worse_margin_rel: float = 0.1

    @classmethod
    def from_odometry(cls, model: OdometrySigmas) -> HealthParams:
        """The defaults with the odometry error model of a matcher's parameters (``IdcParams``)."""
        return cls(sigma_m=model.odo_sigma_m, sigma_rel=model.odo_sigma_rel, sigma_rad=model.odo_sigma_rad,
                   sigma_rel_rad=model.odo_sigma_rel_rad)


@dataclass(frozen=True)
class MatcherHealth:
    """How a scan matcher did over a log (:func:`matcher_health`); times in seconds since the first scan.

    Attributes:
        matcher: its name; scans: scans matched.
        failed: failed matches (MATCH_FAILED: the odometry increment kept); refused: those of them whose
            match was found and refused (``REFUSALS``); after_gap: those after a gap in the log;
            reasons: failures per category (``failure_category``).
        steps: accepted matches whose increment is compared with the odometry's; step_trans_m,
            step_rot_deg: (median, p95, max) of that disagreement per scan [m], [deg].
        longest_start_s, longest_s, longest_scans: the longest run of consecutive failed matches: its first
            scan, its length (until the next accepted match; to one median scan period past the last scan
            when none follows) and its scans (0 and nan without a failure).
        window_start_s, window_trans_m, window_rot_deg, window_sigma_m, window_sigma_deg, window_sigmas:
            the window of ``HealthParams.window_s`` whose disagreement is the most sigmas of the odometry
            model: its start, the disagreement, the model's sigmas there and the ratio (nan without one).
        measured: whether ground truth decided the verdict; ate_odom_m, ate_matcher_m: then the aligned
            ATE RMSE of the odometry and of the matcher [m] (nan otherwise).
        warning: one line when the matcher likely hurts (see :func:`matcher_health`), else None.
    """

    matcher: str
    scans: int
    failed: int
    refused: int
    after_gap: int
    reasons: Mapping[str, int]
    steps: int
    step_trans_m: tuple[float, float, float]
    step_rot_deg: tuple[float, float, float]
    longest_start_s: float
    longest_s: float
    longest_scans: int
    window_s: float
    window_start_s: float
    window_trans_m: float
    window_rot_deg: float
    window_sigma_m: float
    window_sigma_deg: float
    window_sigmas: float
    measured: bool
    ate_odom_m: float
    ate_matcher_m: float
    warning: str | None

    @property
    def failed_share(self) -> float:
        return self.failed / self.scans if self.scans else math.nan

    def to_dict(self) -> dict[str, Any]:
        """summary.json's ``matcher_health`` (JSON-ready; nan where not measured)."""
        q = ("median", "p95", "max")
        return {
            "matcher": self.matcher, "scans": self.scans, "failed": self.failed,
            "failed_share": self.failed_share, "refused": self.refused, "after_gap": self.after_gap,
            "reasons": dict(self.reasons),
            "step_vs_odometry": {"scans": self.steps,
                                 **{f"trans_{k}_m": v for k, v in zip(q, self.step_trans_m, strict=True)},
                                 **{f"rot_{k}_deg": v for k, v in zip(q, self.step_rot_deg, strict=True)}},
            "longest_without_match": {"t_start_s": self.longest_start_s, "duration_s": self.longest_s,
                                      "scans": self.longest_scans},
            "worst_window": {"window_s": self.window_s, "t_start_s": self.window_start_s,
                             "trans_m": self.window_trans_m, "rot_deg": self.window_rot_deg,
                             "sigma_m": self.window_sigma_m, "sigma_deg": self.window_sigma_deg,
                             "sigmas": self.window_sigmas},
            "verdict": "measured" if self.measured else "estimated",
            "ate_odom_m": self.ate_odom_m, "ate_matcher_m": self.ate_matcher_m,
            "warning": self.warning,
        }


def _median_p95_max(x: F64) -> tuple[float, float, float]:
    if x.size == 0:
        return math.nan, math.nan, math.nan
    q = np.percentile(x, [50, 95])
    return float(q[0]), float(q[1]), float(np.max(x))


def _longest_failure(t_s: F64, ok: NDArray[np.bool_]) -> tuple[float, float, int]:
    """(start [s], length [s], scans) of the longest run of consecutive failed matches ((nan, 0, 0) without
    one): until the next accepted match, or one median scan period past the last scan."""
    bad = np.concatenate([[False], ~ok, [False]]).astype(np.int8)
    edges = np.flatnonzero(np.diff(bad))
    if edges.size == 0:
        return math.nan, 0.0, 0
    starts, ends = edges[0::2], edges[1::2]  # failed scans starts[k] .. ends[k] - 1
    period = float(np.median(np.diff(t_s))) if t_s.size > 1 else 0.0
    stop = np.where(ends < t_s.size, t_s[np.minimum(ends, t_s.size - 1)], t_s[-1] + period)
    length = stop - t_s[starts]
    k = int(np.argmax(ends - starts))
    return float(t_s[starts[k]]), float(length[k]), int(ends[k] - starts[k])


def _path(poses: F64) -> tuple[F64, F64]:
    """Cumulative path length [m] and accumulated absolute turn [rad] along a trajectory (0 at its start)."""
    inc = relative(poses[:-1], poses[1:]).reshape(-1, 3)
    zero = np.zeros(1)
    return (np.concatenate([zero, np.cumsum(np.hypot(inc[:, 0], inc[:, 1]))]),
            np.concatenate([zero, np.cumsum(np.abs(inc[:, 2]))]))


def _pct(x: float) -> str:
    return f"{100.0 * x:.0f} %"


_Window = tuple[float, float, float, float, float, float]


def _worst_window(t: I64, o: F64, c: F64, params: HealthParams) -> _Window:
    """The window of ``params.window_s`` (``_pairs_apart``) whose motion of ``c`` disagrees most with that of
    ``o`` in sigmas of the odometry model: (start [s since the first pose], translation [m], rotation [deg],
    sigma_t [m], sigma_r [deg], sigmas); nan without a window."""
    i, j = _pairs_apart(t, params.window_s)
    if i.size == 0:
        return math.nan, math.nan, math.nan, math.nan, math.nan, math.nan
    w_t, w_r = _motion_error(o, c, i, j)
    (d_o, r_o), (d_c, r_c) = _path(o), _path(c)
    dist = np.maximum(d_o[j] - d_o[i], d_c[j] - d_c[i])
    turn = np.maximum(r_o[j] - r_o[i], r_c[j] - r_c[i])
    sig_t = params.sigma_m + params.sigma_rel * dist
    sig_r = params.sigma_rad + params.sigma_rel_rad * turn + params.sigma_rad_per_m * dist
    z = np.maximum(w_t / sig_t, w_r / sig_r)
    k = int(np.argmax(z))
    return (float(t[i[k]] - t[0]) / NS_PER_S, float(w_t[k]), math.degrees(float(w_r[k])), float(sig_t[k]),
            math.degrees(float(sig_r[k])), float(z[k]))


def _estimated_warning(matcher: str, n: int, failed: int, counts: Mapping[str, int], window: _Window,
                       params: HealthParams) -> str | None:
    """The warning without ground truth: too many failures, or a window beyond the odometry model."""
    signs = []
    if n and failed > params.max_failed_share * n:
        why = ", ".join(f"{k} {v}" for k, v in counts.items())
        signs.append(f"{failed} of {n} matches failed ({_pct(failed / n)}: {why}), so the corrected poses "
                     "are mostly odometry")
    start, trans, rot, sig_t, sig_r, z = window
    if z > params.max_sigmas:
        signs.append(f"its motion disagreed with the odometry by {trans:.2f} m and {rot:.1f} deg over "
                     f"{params.window_s:g} s from t = {start:.1f} s, {z:.1f} sigmas of the odometry error "
                     f"model ({sig_t:.2f} m, {sig_r:.1f} deg)")
    if not signs:
        return None
    return f"scan matcher {matcher} likely hurts: {'; '.join(signs)} (estimated: no ground truth)"


def _measured_warning(matcher: str, ate_odom: float, ate_matcher: float, params: HealthParams) -> str | None:
    """The warning with ground truth: the matcher's aligned ATE RMSE worse than the odometry's."""
    worse = ate_matcher - ate_odom
    if not worse > max(params.worse_margin_m, params.worse_margin_rel * ate_odom):
        return None
    return (f"scan matcher {matcher} made the trajectory worse than the odometry: aligned ATE RMSE "
            f"{ate_matcher:.3f} m against {ate_odom:.3f} m (+{worse:.3f} m; measured against the ground "
            "truth)")


def matcher_health(t_ns: ArrayLike, odom: ArrayLike, poses: ArrayLike, ok: ArrayLike, reasons: Sequence[str],
                   *, matcher: str = "matcher", truth: tuple[ArrayLike, ArrayLike] | None = None,
                   params: HealthParams = HealthParams()) -> MatcherHealth:
    """How a scan matcher did over a log, from its corrected trajectory ``poses`` and the odometry ``odom``
    ((N, 3) at the scans' stamps ``t_ns``, in time order), whether each match was accepted (``ok``) and the
    failed ones' ``reasons``; vectorised over the arrays.

    The warning says the matcher likely hurts. With ``truth`` (stamps, (M, 3) poses) it is measured: the
    matcher's aligned ATE RMSE against the odometry's (``trajectory_errors``, SE(2) alignment), worse by more
    than ``params.worse_margin_*``. Without truth it is estimated from two signs: more than
    ``params.max_failed_share`` of the matches failed, or over a window of ``params.window_s`` its motion
    disagreed with the odometry's by more than ``params.max_sigmas`` of the odometry error model
    (:class:`HealthParams`). The disagreement per scan is that of the accepted matches' increments (a failed
    match keeps the odometry's).

    Raises:
        ValueError: shapes disagree.
    """
    t, o = _trajectory_arrays(t_ns, odom)
    _, c = _trajectory_arrays(t, poses)
    good = np.asarray(ok, dtype=bool).reshape(-1)
    if good.shape != t.shape or len(reasons) != t.size:
        raise ValueError(f"ok and reasons must have one entry per pose ({t.size}), got {good.shape[0]} and "
                         f"{len(reasons)}")
    n = int(t.size)
    bad = [r for r, g in zip(reasons, good.tolist(), strict=True) if not g]
    counts = dict(sorted(Counter(map(failure_category, bad)).items(), key=lambda kv: (-kv[1], kv[0])))
    failed = len(bad)
    step = np.flatnonzero(good[1:]) + 1  # the accepted matches' increments against the odometry's
    s_t, s_r = _motion_error(o, c, step - 1, step)
    window = _worst_window(t, o, c, params)
    ate_o = ate_m = math.nan
    if truth is not None:
        e_o, e_m = trajectory_errors(t, o, *truth), trajectory_errors(t, c, *truth)
        if min(e_o.matched, e_m.matched) >= 2:
            ate_o, ate_m = e_o.ate_rmse_m, e_m.ate_rmse_m
    measured = not math.isnan(ate_o)
    warning = (_measured_warning(matcher, ate_o, ate_m, params) if measured
               else _estimated_warning(matcher, n, failed, counts, window, params))
    start, length, scans = _longest_failure((t - (t[0] if n else 0)) / NS_PER_S, good)
    return MatcherHealth(
        matcher=matcher, scans=n, failed=failed, refused=sum(v for k, v in counts.items() if k in REFUSALS),
        after_gap=sum(1 for r in bad if _AFTER_GAP in r), reasons=counts, steps=int(step.size),
        step_trans_m=_median_p95_max(s_t), step_rot_deg=_median_p95_max(np.degrees(s_r)),
        longest_start_s=start, longest_s=length, longest_scans=scans, window_s=params.window_s,
        window_start_s=window[0], window_trans_m=window[1], window_rot_deg=window[2],
        window_sigma_m=window[3], window_sigma_deg=window[4], window_sigmas=window[5], measured=measured,
        ate_odom_m=ate_o, ate_matcher_m=ate_m, warning=warning)


def _trajectory_arrays(t_ns: ArrayLike, poses: ArrayLike) -> tuple[I64, F64]:
    """(N,) int64 stamps and (N, 3) float64 poses; ValueError when the shapes disagree."""
    t = np.asarray(t_ns, dtype=np.int64)
    p = np.asarray(poses, dtype=np.float64)
    if t.ndim != 1 or p.shape != (t.shape[0], 3):
        raise ValueError(f"poses must be (N, 3) with N = len(t_ns) = {t.shape[0]}, got shape {p.shape}")
    return t, p


def read_tum(path: str | os.PathLike[str]) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Read a planar TUM trajectory (``t x y z qx qy qz qw``, ``#`` comments): exact int-ns stamps and
    (N, 3) poses (x, y [m], yaw [rad] from qz, qw), the inverse of :func:`write_tum`.

    Raises:
        GndReplayError: unreadable file (not a regular file of at most ``MAX_TUM_BYTES`` of UTF-8 text), or a
            line without 8 numbers (the message names file and line).
    """
    p = Path(path)
    text = read_text(p, "trajectory", MAX_TUM_BYTES)
    t_ns: list[int] = []
    poses: list[tuple[float, float, float]] = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        tok = line.split()
        if not tok or tok[0].startswith("#"):
            continue
        try:
            if len(tok) != 8:
                raise ValueError(f"expected 8 fields, found {len(tok)}")
            x, y, qz, qw = float(tok[1]), float(tok[2]), float(tok[6]), float(tok[7])
            t_ns.append(_seconds_to_ns(tok[0]))
        except ValueError as err:
            raise GndReplayError(
                f"{p} line {lineno}: not a TUM pose 't x y z qx qy qz qw' ({one_line(err, 120)})"
            ) from err
        poses.append((x, y, 2.0 * dm.atan2(qz, qw)))
    return np.asarray(t_ns, dtype=np.int64), np.asarray(poses, dtype=np.float64).reshape(len(poses), 3)


def write_tum(path: str | os.PathLike[str], t_ns: ArrayLike, poses: ArrayLike) -> None:
    """Write a planar trajectory in TUM format (``t tx ty tz qx qy qz qw``), readable by evo.

    Timestamps are exact decimal seconds with nanosecond digits; z = 0 and the quaternion is a yaw rotation
    (xyzw order). The file is written to a temporary file in the same folder and renamed, so a reader never
    sees half a trajectory.

    Raises:
        ValueError: shapes disagree.
    """
    t, p = _trajectory_arrays(t_ns, poses)
    half = 0.5 * p[:, 2]
    qz, qw = dm.sin_a(half), dm.cos_a(half)
    lines = [f"{format_stamp(int(ti))} {x!r} {y!r} 0.0 0.0 0.0 {z!r} {w!r}\n"
             for ti, x, y, z, w in zip(t.tolist(), p[:, 0].tolist(), p[:, 1].tolist(), qz.tolist(),
                                       qw.tolist(), strict=True)]
    atomic_write_text(Path(path), "# timestamp tx ty tz qx qy qz qw\n" + "".join(lines))
