"""Trajectory evaluation: the SLAM-benchmark relations metric and a TUM trajectory writer.

The relations metric is the one of Kümmerle et al., "On measuring the accuracy of SLAM algorithms" (Autonomous
Robots 2009): for each relation (t1, t2, δ*) with δ* the reference pose of the scan at t2 in the frame of the
scan at t1, the estimated relative pose is δ = pose(t1)⁻¹ ∘ pose(t2) and the error is δ*⁻¹ ∘ δ. Its
translational part is ‖R*ᵀ (t - t*)‖ = ‖t - t*‖ (a rotation keeps the norm, so the "difference of the
translation components" convention gives the same number) and its rotational part is |wrap(θ - θ*)|. The
benchmark reports the mean ± standard deviation of both over all relations (the "absolute" errors).

Scans are identified by their timestamp (CARMEN ipc_timestamp, ROS header stamp); a relation end matches the
nearest scan stamp within ``tol_s`` (the relation files print 1e-5 s or 1e-6 s).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import detmath as dm
from .errors import GndReplayError, one_line
from .fsutil import atomic_write_text, format_stamp
from .geometry import relative, wrap_angle
from .io.base import MAX_ABS_TIME_NS
from .io.userfile import brief, read_text

__all__ = ["MAX_RELATIONS_BYTES", "MAX_TUM_BYTES", "SPANS", "RelationStats", "Relations", "SpanStats",
           "load_relations", "read_tum", "relation_errors", "relations_from_trajectory", "write_tum"]

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
