"""IDC scan-to-local-map matcher (Lu & Milios 1997 correspondence rules, wheelchair paper's odometry fix).

Each scan is matched against a *local map*: the points of the last ``map_keyframes`` keyframes in the
corrected frame, rendered as a polar reference scan seen from the predicted laser pose (previous corrected
pose ∘ odometry increment). IDC's two rules then align the scan with that reference: closest point on the
reference polyline for the translation, matching range point in a shrinking angular window for the rotation.
Matching against a map of several keyframes instead of the previous scan is what keeps the drift low: the
reference only changes slowly, and the averaged map is less noisy than one scan.

A match fails (odometry increment kept, MATCH_FAILED) on too few pairs, a large residual, a degenerate
geometry (corridor: translation along it unobservable), or a correction implausibly far from odometry.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..geometry import compose, inverse, transform_points
from ..types import Pose2D, Scan
from . import _idc_kernels as k
from .base import MatchResult

__all__ = ["IdcMatcher", "IdcParams"]

F64 = NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class IdcParams:
    """Constants of the IDC matcher (defaults tuned on the MIT CSAIL and ACES logs, see benchmarks/)."""

    # beams used: CARMEN no-return values are already +inf; far returns are sparse and noisy
    min_range_m: float = 0.05
    max_range_m: float = 40.0
    # local map: a keyframe every 0.3 m or 10 deg of corrected motion, the newest 20 kept (~6 m of path)
    keyframe_dist_m: float = 0.3
    keyframe_angle_rad: float = math.radians(10.0)
    map_keyframes: int = 20
    # reference rendering: 0.25 deg bins (finer than the 0.5-1 deg beams, so map points keep their detail);
    # points within 5 cm behind the nearest one of a bin are averaged (same wall seen by several keyframes)
    n_bins: int = 1440
    blend_m: float = 0.05
    # polyline continuity: consecutive bins are one surface when closer than 0.2 m + 5 % of range per bin
    # gap (a 0.25 deg step at 10 m is 4.4 cm; a wall at 80 deg incidence stretches it ~6x), up to 4 bins gap
    seg_abs_m: float = 0.2
    seg_rel: float = 0.05
    gap_bins: int = 4
    # IDC iterations: window Bw(k) = max(win_min, B0 exp(-k / tau)) (Lu & Milios: B0 ~ 20-30 deg, tau 10).
    # With the odometry prior B0 only has to cover the odometry's rotation error, which grows with the
    # rotation increment: B0 = win0 + win_rel |odometry rotation increment|, at most win_max.
    max_iterations: int = 40
    win0_rad: float = math.radians(5.0)
    win_rel: float = 0.5
    win_max_rad: float = math.radians(30.0)
    win_tau: float = 5.0
    win_min_rad: float = math.radians(1.0)
    mrp_stride: int = 2
    # rotation = weighted mean of the matching-range-point bearing offsets d = (r - rho) / rho'; the weight is
    # 1 / var(d) = rho'^2 / (sigma_r^2 + sigma_a^2 rho'^2): a wall facing the beam (rho' ~ 0) says little
    # about the rotation, a slanted one a lot, up to the bearing quantisation of the reference
    sigma_range_m: float = 0.02
    sigma_bearing_rad: float = math.radians(0.25)
    robust_rotation: bool = True
    fit: int = 0
    # closest-point gate shrinks with the same time constant from gate0 to gate_min
    gate0_m: float = 0.5
    gate_min_m: float = 0.1
    tol_m: float = 1e-4
    tol_rad: float = 1e-4
    max_cp_bins: int = 120  # closest-point search never looks further than +-30 deg of bearing
    # acceptance gates
    min_pairs: int = 40
    min_pair_fraction: float = 0.3
    max_residual_m: float = 0.08
    degenerate_ratio: float = 0.0  # smallest / largest eigenvalue of the translational information
    # a correction beyond 0.3 m / 10 deg plus 50 % of the odometry increment is not believed (CSAIL's
    # odometry under-reports fast turns by up to half)
    max_correction_m: float = 0.3
    max_correction_rad: float = math.radians(10.0)
    max_correction_rel: float = 0.5
    # odometry stalls (see IdcMatcher._priors): constant velocity while the pose repeats after a step of at
    # least 0.1 m or 5 deg (a robot slowing down to a real stop moves less than that per scan)
    handle_stalls: bool = True
    stall_min_step_m: float = 0.1
    stall_min_step_rad: float = math.radians(5.0)
    fallback_priors: int = 2  # after a failed match, retry from constant velocity, then from no motion
    reset_after_failures: int = 5  # consecutive failures -> restart the map from the current scan


class IdcMatcher:
    """Stateful IDC corrector; see the module docstring."""

    name = "idc"

    def __init__(self, params: IdcParams | None = None) -> None:
        self.params = params if params is not None else IdcParams()
        self._prev_pose: F64 | None = None
        self._anchor_pose: F64 | None = None
        self._anchor_odom: F64 | None = None
        self._last_incr = np.zeros(3)
        self._stalled = False
        self._kf_xy = np.zeros((self.params.map_keyframes, 0, 2))
        self._kf_n = np.zeros(self.params.map_keyframes, dtype=np.int64)
        self._kf_next = 0
        self._kf_pose: F64 | None = None
        self._failures = 0

    # -- map -------------------------------------------------------------------------------------------
    def _reset_map(self) -> None:
        self._kf_n[:] = 0
        self._kf_next = 0
        self._kf_pose = None

    def _add_keyframe(self, laser_pose: F64, pts: F64) -> None:
        if pts.shape[0] > self._kf_xy.shape[1]:
            grown = np.zeros((self._kf_xy.shape[0], pts.shape[0], 2))
            grown[:, : self._kf_xy.shape[1]] = self._kf_xy
            self._kf_xy = grown
        slot = self._kf_next
        self._kf_xy[slot, : pts.shape[0]] = transform_points(laser_pose, pts)
        self._kf_n[slot] = pts.shape[0]
        self._kf_next = (slot + 1) % self._kf_xy.shape[0]
        self._kf_pose = laser_pose

    def _is_keyframe(self, laser_pose: F64) -> bool:
        if self._kf_pose is None:
            return True
        d = compose(inverse(self._kf_pose), laser_pose)
        p = self.params
        return bool(math.hypot(d[0], d[1]) >= p.keyframe_dist_m or abs(d[2]) >= p.keyframe_angle_rad)

    # -- update ----------------------------------------------------------------------------------------
    def _priors(self, odom_a: F64) -> list[tuple[F64, F64]]:
        """Predicted robot poses for this scan (best first), each with the odometry increment it assumes.

        The first is the previous corrected pose ∘ odometry increment. Odometry can *stall*: MIT CSAIL's
        pose repeats for ~1 s during fast turns, then jumps. While it repeats and the robot was clearly
        moving, the first prior repeats the previous corrected increment (constant velocity); the first fresh
        odometry is then composed from the last fresh scan (the anchor), so the stalled motion is not counted
        twice. The others (constant velocity, no motion) are only tried when the first one fails.
        """
        assert self._prev_pose is not None and self._anchor_odom is not None and self._anchor_pose is not None
        p = self.params
        cv = compose(self._prev_pose, self._last_incr)
        still = (self._prev_pose, np.zeros(3))
        if p.handle_stalls and np.array_equal(odom_a, self._anchor_odom):
            fast = (math.hypot(self._last_incr[0], self._last_incr[1]) >= p.stall_min_step_m
                    or abs(self._last_incr[2]) >= p.stall_min_step_rad)
            if self._stalled or fast:
                self._stalled = True
                return [(cv, self._last_incr), still]
        self._stalled = False
        incr = compose(inverse(self._anchor_odom), odom_a)
        return [(compose(self._anchor_pose, incr), incr), (cv, self._last_incr), still]

    def update(self, scan: Scan, odom: Pose2D) -> MatchResult:
        """Correct the pose of this scan (see the module docstring); scans must come in time order."""
        p = self.params
        r = scan.ranges_m
        use = np.isfinite(r) & (r >= max(p.min_range_m, scan.min_range_m)) & (r <= p.max_range_m)
        pr = np.ascontiguousarray(r[use])
        pa = np.ascontiguousarray(scan.angles_rad[use])
        px, py = pr * np.cos(pa), pr * np.sin(pa)
        pts = np.column_stack([px, py])
        sensor = scan.sensor_pose.as_array()
        odom_a = odom.as_array()
        if self._prev_pose is None:
            self._prev_pose = self._anchor_pose = self._anchor_odom = odom_a
            self._add_keyframe(compose(odom_a, sensor), pts)
            return MatchResult(odom, True, 0, float("nan"), 0)
        priors = self._priors(odom_a)
        prior = priors[0][0]
        iters_total = 0
        first: tuple[F64, int, float, int, str] | None = None
        for k_h, (hyp, incr) in enumerate(priors[: 1 + p.fallback_priors]):
            res = self._match(px, py, pr, pa, compose(hyp, sensor), incr)
            iters_total += res[3]
            if first is None:
                first = res
            if not res[4]:
                break
            if k_h == 0 and res[1] < 0.5 * max(p.min_pairs, 1) and res[3] == 0:
                break  # nothing to match (too few beams): other priors will not help
        else:
            res = first
        assert res is not None
        est_laser, pairs, resid, _, reason = res
        if reason:
            pose = prior
            self._failures += 1
            if self._failures >= p.reset_after_failures:
                self._reset_map()
                self._add_keyframe(compose(prior, sensor), pts)
                self._failures = 0
        else:
            self._failures = 0
            pose = compose(est_laser, inverse(sensor))
            if self._is_keyframe(est_laser):
                self._add_keyframe(est_laser, pts)
        self._last_incr = compose(inverse(self._prev_pose), pose)
        self._prev_pose = pose
        if not self._stalled:
            self._anchor_pose, self._anchor_odom = pose, odom_a
        return MatchResult(Pose2D.from_array(pose), not reason, pairs, resid, iters_total, reason)

    def _match(self, px: F64, py: F64, pr: F64, pa: F64, laser_prior: F64,
               incr: F64) -> tuple[F64, int, float, int, str]:
        p = self.params
        n = px.shape[0]
        need = max(p.min_pairs, math.ceil(p.min_pair_fraction * n))
        if n < need:
            return laser_prior, 0, math.nan, 0, f"too few valid beams: {n} < {need}"
        ref_x, ref_y, ok, nxt = k.render_reference(
            self._kf_xy, self._kf_n, laser_prior[0], laser_prior[1], laser_prior[2], p.n_bins,
            p.min_range_m, p.max_range_m + p.gate0_m, p.blend_m, p.seg_abs_m, p.seg_rel, p.gap_bins)
        win0 = min(p.win_max_rad, p.win0_rad + p.win_rel * abs(incr[2]))
        x, y, th, iters, _ = k.idc_align(
            px, py, pr, pa, ref_x, ref_y, ok, nxt, p.max_iterations, win0, p.win_tau, p.win_min_rad,
            p.gate0_m, p.gate_min_m, p.tol_m, p.tol_rad, p.max_cp_bins, p.gap_bins, p.mrp_stride,
            p.sigma_range_m, p.sigma_bearing_rad, p.robust_rotation, p.fit)
        pairs, resid, info = k.match_quality(px, py, x, y, th, ref_x, ref_y, ok, nxt, p.gate_min_m,
                                             p.max_cp_bins, p.gap_bins)
        est = compose(laser_prior, np.array([x, y, th]))
        corr_m = math.hypot(x, y)
        if pairs < need:
            return est, pairs, resid, iters, f"too few pairs: {pairs} < {need}"
        if resid > p.max_residual_m:
            return est, pairs, resid, iters, f"residual {resid:.3f} m > {p.max_residual_m} m"
        max_m = p.max_correction_m + p.max_correction_rel * math.hypot(incr[0], incr[1])
        max_rad = p.max_correction_rad + p.max_correction_rel * abs(incr[2])
        if corr_m > max_m or abs(th) > max_rad:
            return est, pairs, resid, iters, (f"correction {corr_m:.3f} m, {math.degrees(th):.1f} deg "
                                              "too far from odometry")
        if p.degenerate_ratio > 0.0:
            ev = np.linalg.eigvalsh(info[:2, :2])
            if ev[1] <= 0.0 or ev[0] < p.degenerate_ratio * ev[1]:
                return est, pairs, resid, iters, "degenerate geometry (translation unobservable)"
        return est, pairs, resid, iters, ""
