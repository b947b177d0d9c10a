"""IDC scan-to-local-map matcher: Lu & Milios' Iterative Dual Correspondence, as the wheelchair paper uses it.

Each scan is matched against a *local map*: the points of the last ``map_keyframes`` keyframes in the
corrected frame, rendered as a polar reference scan seen from the predicted laser pose (previous corrected
pose ∘ odometry increment). IDC then aligns the scan with that reference: closest point on the reference
polyline for the translation, matching range point in a shrinking bearing window for the rotation. Matching
against a map of many keyframes rather than the previous scan is what keeps the drift low: the reference
changes slowly, and the averaged map is less noisy than one scan.

IDC converges fast from far (a 20 deg rotation error) but creeps at the end: the point-to-point fit of the
closest-point pairs penalises sliding along walls. A few Gauss-Newton steps on the same closest-point pairs
with the point-to-line distance (``polish_iterations``; 0 = pure IDC) finish the alignment; they carry a
weak odometry prior so that directions the scan cannot observe follow the odometry. This departure from the
paper is deliberate: on the dev logs the polish lowers the error of the relations between scans less than
1 s apart from 0.031 to 0.025 m (CSAIL), and the mean relation error from 0.078 to 0.052 m (CSAIL) and from
0.106 to 0.042 m (ACES) (benchmarks/scanmatch.py prints both, with and without it).

Wrong basins, and the rule behind the fix: IDC converges only towards the basin its start lies in, and its
matching-range rule sees rotations within its bearing window (20 deg). Odometry that is wrong by more (on
the Intel log it stalls, lags or jumps back by 30 deg within one second in fast turns) starts IDC outside
the right basin, and it either fails or settles in a neighbouring one (errors of 10-30 deg that every later
scan inherits). So the *start* must come from the scan, not the odometry, whenever the odometry may be that
far off: before IDC, a correlative search over +-45 deg (``coarse_window_rad``) scores each rotation by the
fraction of the scan's overlapping points whose range agrees with the map (a fraction, not a count: a count
prefers the rotation that overlaps the map most, any rotation in a round hall), and IDC also starts from
the best one; that match wins only when it fits clearly better (``coarse_margin``), so a symmetric place
with several equal basins keeps the prediction's.

Never worse than odometry (``_guard``): the odometry has an error model (``odo_sigma_*``, sigma = 0.1 m / 3.3
deg + 1/6 of the increment, scaled per robot by the learnt RMS of the corrections of accepted matches: the
translation only widens, the rotation may also narrow, down to sigma = 1 deg + 5 % of the turn). A match
beyond 2 sigmas of it (``guard_sigmas``) needs a second opinion: the match from the odometry's prediction in a
narrow window. The far match is believed when that second match fails, lands near it, or fits clearly worse;
when the second one fits clearly better it is taken instead (the far one was a wrong basin); when both fit
alike, the scan cannot tell, and the odometry increment is kept with MATCH_FAILED ("unconfirmed match"). The
rotation model narrows because a robot whose odometry turns well (ACES: corrections of ~0.5 deg per scan)
otherwise accepted, unchecked, matches 3-5 deg off it that settled in a poorer fit next to the right one (more
residual, 15 % fewer pairs: ACES scans 5263 and 5273, Intel 8421), the worst relations under 1 s (3.9 and 3.8
deg). The second opinion is asked from 2 sigmas, not 3: single matches a little inside 3 sigmas were wrong
basins too (a turn on ACES, 2.8 sigmas and a relation under 1 s 4.8 deg off; the XR4000 in the simulator's
people room, 0.26 m back along a lane at 2.4 sigmas, a keyframe taken there and the goal then missed by 0.4
m). Alike is judged against the best fit of the scan, not only the winning match: when another accepted
match of the scan (from another prior) fits clearly better than the second opinion, that match is taken.
In a fast turn that the odometry under-reports, the match from constant velocity's prediction wins for
being near its own prior, the one from the odometry's prediction fits best; judging the first alone kept
the odometry, 9 deg off over 0.4 s (CSAIL sampled by distance, from scan 3).

Scans that do not follow the odometry (a stale record: on Intel, scans 11550-11554 repeat the view of
~40 deg earlier in a turn, 11552 and 11554 with fresh odometry): such a scan is placed where its content
was seen, so the next scan's priors are all off by that jump and its right match lies far from every one
of them. A match near its own prior is normally preferred, but not over one that fits clearly better (mean
truncated pair distance lower by ``coarse_margin``): in a place whose walls fit many headings (a round
hall, a cluttered lab) the match near a wrong prior is a poor fit between two basins, and taking it put
every later scan ~40 deg off until the map was rebuilt (a relation 0.01 s long with 35 deg of error). The
clearly better far match still needs the guard's second opinion.

Logs sampled by distance and long gaps: keyframes are taken by corrected motion (0.5 m / 10 deg) or a drop
in overlap, never by scan count, so the map does not depend on the scan rate. After a gap longer than
``map_max_gap_s`` a scan that fails to match restarts the map from itself at once (the map no longer
describes where the robot is); a gap where the robot stood still keeps the map (restarting after every
long gap raised ACES' error from 0.11 to 0.69 m once decimated to one scan per 0.2 m / 5 deg).

A drop in overlap is measured against the most points any match paired since the newest keyframe, and must
last three matches. Against the previous match alone (as before), a view that changes slowly in front of a
robot that hardly moves never entered the map: a door slides shut ahead of a chair in a dead-end passage,
each scan pairs a few points fewer than the last, and the chair moves too little for a keyframe. The map
kept seeing through the door, the door's points stayed unpaired, and the scan was left with the passage's
side walls, which say nothing along it: backing out, the pose stuck to the last keyframe's, 0.5 m lost over
0.5 m reversed (gnd_exp1_three_traps, wheelchair; tests/test_scanmatch.py has the case). One match that
pairs fewer points is as often a poorer fit as a changed view, and a keyframe taken on it puts its error
into the map for every later scan (Intel scan 8671 of one run: 5 deg); a changed world stays changed, so
three matches in a row are asked for.

Measured over 16 start scans (0-15), this rule with the guard at 2 sigmas against the previous rule with
3: median relation error ACES 0.064 -> 0.062 m, CSAIL 0.058 -> 0.053 m, Intel 0.160 -> 0.147 m; starts
whose worst relation under 1 s is above 3 deg ACES 2 -> 1, CSAIL 0 -> 0, Intel 2 -> 2; the worst such
relation ACES 3.7 -> 3.1, CSAIL 2.1 -> 2.3, Intel 4.5 -> 4.0 deg. The rule alone (guard at 3 sigmas) put
Intel above 3 deg on 4 starts.

Backing up, a keyframe every ``keyframe_back_m`` (0.15 m) along the newest keyframe's heading, backwards. A
laser that sees no further back than sideways (the papers' 180 deg SICK) sees, as it backs up, the walls
beside it that no keyframe held: every keyframe was taken further forward, where they lay behind its view.
They are the scan's nearest returns, and IDC pairs them with the mapped part of the same wall, a few
decimetres along it: the chair backing out of gnd_exp1_three_traps' closed side passage had 0.5 m of the
passage's wall beside its laser unmapped, the match slid 0.2 m into the passage (at 1.9 sigmas, inside the
guard), its residual a third of the right pose's, whose unmapped returns were unpaired, and the goal was
missed by 0.5 m. Driving forwards uncovers nothing beside the laser, so the rule only fires backing up;
CSAIL's and ACES' robots never back up 0.15 m (the results there are the same bit for bit), Intel's does
(46 m in 467 steps): median relation error over 16 start scans 0.147 -> 0.160 m, starts whose worst
relation under 1 s is above 3 deg 2 -> 0, the worst such relation 4.0 -> 2.6 deg.

De-skewing interlaced scans (``deskew``, IdcMatcher._learn_skew): a SICK LMS at 0.5 deg takes the even and
the odd beams in two sweeps ~13 ms apart, so in a turn at 100 deg/s the two half-scans disagree by 1.3 deg;
the map then holds walls drawn twice, and matches in fast turns were off by up to 3.8 deg over relations
shorter than 1 s (CSAIL, relation 824 in a 100 deg/s turn). Each scan is motion-compensated to the mean
time of its beams with the last corrected velocity and the delay of the odd beams. No log says whether its
scanner interlaces (CARMEN's FLASER has no timing), so the delay is learnt from the data: after each
accepted match in a turn, the rotation the odd half-scan still needs against the map minus the even half's,
divided by the turn rate, measures the delay not yet compensated. Their running mean is applied only once
it is clearly non-zero: CSAIL learns 12.6 ms (two 75 Hz sweeps are 13.3 ms apart) and its worst relation
under 1 s drops from 3.1-3.8 to 1.7-2.0 deg over five start scans; ACES and Intel (1 deg beams, one sweep)
learn nothing and are matched exactly as without de-skewing. Per-beam times from a reader (ROS
``time_increment``) would also allow de-skewing within a sweep; Scan does not carry them yet.

Surfaces the map holds only in part (``_idc_kernels.unseen_ends``): each keyframe keeps its view (laser pose,
bearing span, range limit), and an end of a reference polyline whose continuation lies in no keyframe's view
is where the map's knowledge of that surface stops, not where the surface stops. IDC's closest-point rule
leaves out the pairs whose closest point is such an end (Rusinkiewicz & Levoy 2001: pairs on the
reference's boundary bias the fit when the overlap is partial); the point-to-line polish keeps them, the
surface's line being what the point lies on. Without this, a robot turning on the spot with its laser
0.72 m ahead of the axle, at a corridor's end, saw the wall's far part come into view scan after scan; its
new points paired with the end of the mapped part and pulled the pose 0.15 m along the wall in 1.2 s while
the odometry (right) said it stood (the bundled sample at 45-49 s: ATE RMSE 0.063 m and max 0.101 m,
now 0.025 and 0.037 m against its ground truth). Ends that a keyframe saw past (a door jamb, a corner) keep
their pairs: they observe the motion along the wall. A match from the odometry's prediction that fails for
degenerate geometry is not retried from the fallback priors: the place, not the start, leaves the
translation unobservable, and a fallback that scraped over the threshold there jumped the pose (the sample,
4 cm at 47.4 s).

A match fails (odometry increment kept, MATCH_FAILED, ``reason`` says why) on too few pairs, a large
residual, a degenerate geometry (a featureless corridor: translation along it unobservable), or an
unconfirmed correction far from odometry.

While odometry repeats after slow motion the robot stands still, and the corrected pose is the running mean
of the matches since it stopped: each scan then measures the same pose against the same map, and taking the
last one alone let the heading wander by up to +-2 deg in a crowded hall (ACES), an error the rest of the
run inherits.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from .. import detmath as dm
from ..geometry import transform_points
from ..types import Pose2D, Scan
from . import _idc_kernels as k
from .base import MatchResult

__all__ = ["IdcMatcher", "IdcParams"]

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]


@dataclass(frozen=True, slots=True)
class IdcParams:
    """Constants of the IDC matcher (defaults chosen on the MIT CSAIL and ACES logs, see benchmarks/)."""

    # beams used: CARMEN no-return values are already +inf; returns beyond 40 m are few and sparse
    min_range_m: float = 0.05
    max_range_m: float = 40.0
    # local map: a keyframe every 0.5 m or 10 deg of corrected motion, the newest 40 kept (~20 m of path):
    # the longer the map remembers, the less often its reference changes, the less the pose drifts
    keyframe_dist_m: float = 0.5
    keyframe_angle_rad: float = math.radians(10.0)
    # ... or 0.15 m backwards along the newest keyframe's heading: a laser that sees no further back than
    # sideways (180 deg) uncovers, backing up, the surfaces beside it that no keyframe saw, at close range,
    # where they pull the match hardest (see the module docstring); 0 disables
    keyframe_back_m: float = 0.15
    # ... or when 3 matches in a row pair fewer than 90 % of the most any match paired since the newest
    # keyframe: the view has changed (passing close to an obstacle, a door closing ahead, a person
    # stepping in) and the map must take in the new part (see the module docstring)
    keyframe_pair_ratio: float = 0.9
    keyframe_pair_scans: int = 3
    map_keyframes: int = 40
    # the map is trusted for 10 s without a scan: after a longer gap (a recording paused; a log sampled by
    # distance has gaps while the robot stands, and its map stays good) the scan is matched as usual, but if
    # the match fails the map restarts from it at the odometry's prediction at once, instead of after
    # reset_after_failures failures (restarting after every long gap: ACES decimated 0.69 m against 0.11)
    map_max_gap_s: float = 10.0
    # reference rendering: 0.25 deg bins (finer than the 0.5-1 deg beams, so map points keep their detail);
    # points within 5 cm behind the nearest one of a bin are averaged (same wall seen by several keyframes)
    n_bins: int = 1440
    blend_m: float = 0.05
    # polyline continuity: consecutive bins are one surface when closer than 0.2 m + 5 % of range per bin
    # (a 0.25 deg step at 10 m is 4.4 cm; a wall at 80 deg incidence stretches it ~6x), up to 4 bins apart
    # (ACES' 1 deg beams leave 3 empty bins between the points of one scan)
    seg_abs_m: float = 0.2
    seg_rel: float = 0.05
    gap_bins: int = 4
    normal_chord_m: float = 0.1  # surface normals across >= 10 cm of polyline (see _idc_kernels.segments)
    # IDC: bearing window Bw(k) = max(win_min, win0 exp(-k / tau)) as Lu & Milios (B0 20-30 deg); 20 deg
    # covers CSAIL's odometry, off by up to ~15 deg per scan in fast turns. The polish finishes the
    # alignment, so IDC stops at 3 mm / 3 mrad changes (1 mm cost 25 % more time and was not more accurate
    # over five start scans of both dev logs) or after 12 iterations.
    max_iterations: int = 12
    win0_rad: float = math.radians(20.0)
    win_tau: float = 4.0
    win_min_rad: float = math.radians(1.0)
    # IDC pairs every k-th point so that about 180 remain (361 beams: k = 2); the matching-range rule, the
    # costly one (wide windows early), every k-th of those so that about 90 remain
    idc_points: int = 180
    mrp_points: int = 90
    # closest-point gate shrinks with the same time constant from gate0 to gate_min
    gate0_m: float = 0.5
    gate_min_m: float = 0.1
    tol_m: float = 3e-3
    tol_rad: float = 3e-3
    max_cp_bins: int = 120  # closest-point search never looks further than +-30 deg of bearing
    # point-to-line polish of the closest-point pairs after IDC (0 = pure IDC), up to 12 Gauss-Newton steps
    # until a step is below the same tolerance
    polish_iterations: int = 12
    # odometry prior of the polish, in units of one pair (sigma 3 cm): sigma = 5 cm + 20 % of the step,
    # 1 deg + 50 % of the turn (CSAIL's odometry under-reports fast turns by up to half)
    pair_sigma_m: float = 0.03
    prior_sigma_m: float = 0.05
    prior_sigma_rel: float = 0.2
    prior_sigma_rad: float = math.radians(1.0)
    prior_sigma_rel_rad: float = 0.5
    # acceptance gates
    min_pairs: int = 40
    min_pair_fraction: float = 0.3
    max_residual_m: float = 0.08
    # degenerate geometry: the smallest eigenvalue of the translational point-to-line information counts the
    # pairs that constrain the weakest direction; the dev logs never go below 31, a bare corridor is ~0
    degenerate_min_info: float = 5.0
    # consistency guard (see IdcMatcher._guard). The odometry's error model: sigma = odo_sigma_m +
    # odo_sigma_rel * step and odo_sigma_rad + odo_sigma_rel_rad * turn, times a per-robot scale learnt
    # online: the running RMS of the normalised corrections of accepted matches (weight odo_learn_rate, each
    # clipped at odo_learn_clip sigmas), never below 1 for the translation, and for the rotation never below
    # 1 deg / odo_sigma_rad (0.3, see _ODO_SIGMA_MIN_RAD: good odometry is held to 2 deg). A match
    # beyond guard_sigmas of it is suspicious: the fallback priors are tried too, and the winner needs a
    # second opinion, the match from the odometry's prediction in a guard_window_rad bearing window. The
    # defaults put 2 sigmas at 0.2 m / 6.7 deg + 33 % of the increment
    odo_sigma_m: float = 0.1
    odo_sigma_rel: float = 1.0 / 6.0
    odo_sigma_rad: float = math.radians(10.0 / 3.0)
    odo_sigma_rel_rad: float = 1.0 / 6.0
    guard_sigmas: float = 2.0  # 3 before: wrong basins at 2-3 sigmas (see the module docstring)
    odo_learn_rate: float = 0.02
    odo_learn_clip: float = 10.0
    guard_window_rad: float = math.radians(3.0)
    guard_gain: float = 0.03
    guard_agree_m: float = 0.05
    guard_agree_rad: float = math.radians(1.0)
    # odometry stalls (see IdcMatcher._priors): while the pose repeats after a corrected step of at least
    # 0.1 m or 5 deg, constant velocity competes with no motion (a robot slowing down to a real stop moves
    # less than that per scan)
    handle_stalls: bool = True
    stall_min_step_m: float = 0.1
    stall_min_step_rad: float = math.radians(5.0)
    # odometry that repeats after a last step below 1 cm and 0.5 deg (a robot coming to rest; odometry that
    # freezes while the robot moves stops after a larger step): the robot stands, each scan measures the same
    # pose against the same map, and the corrected pose is their running mean, as long as the matches stay
    # within 0.1 m / 5 deg of where it stopped (see IdcMatcher._standing_mean)
    average_when_still: bool = True
    still_entry_m: float = 0.01
    still_entry_rad: float = math.radians(0.5)
    still_max_m: float = 0.1
    still_max_rad: float = math.radians(5.0)
    # after a failed (or suspiciously weak, see recheck_pair_ratio) match: constant velocity, then no motion
    # coarse rotation search (see _idc_kernels.coarse_rotation): the rotation within +-45 deg of the prior
    # (2 deg steps, ~90 points) whose range profile agrees best with the map; when its agreeing fraction
    # beats the prior's by coarse_min_gain, IDC also starts from it, and that match wins if its mean
    # truncated pair distance is lower by coarse_margin. Measured over five start scans of each log: a 3 %
    # margin raised CSAIL's median from 0.050 to 0.060 m (switching basins on noise), 20 % cost Intel 0.194
    # against 0.176 m; 1 deg steps gave Intel 0.227 m. The same margin lets a match far from its prior win
    # over a plausible one that fits worse (see IdcMatcher._clearly_better)
    coarse_window_rad: float = math.radians(45.0)
    coarse_step_rad: float = math.radians(2.0)
    coarse_points: int = 90
    coarse_tol_m: float = 0.05
    coarse_tol_rel: float = 0.02
    coarse_min_gain: float = 0.05
    coarse_margin: float = 0.4
    fallback_priors: int = 2
    # a match pairing fewer than this fraction of the previous match's pairs may sit in a wrong basin (a fast
    # turn): the fallback priors are tried too and the match with most pairs wins
    recheck_pair_ratio: float = 0.75
    reset_after_failures: int = 5  # consecutive failures -> restart the map from the current scan
    # motion compensation of interlaced scans (see IdcMatcher._learn_skew): each scan is de-skewed with the
    # last corrected velocity and the interlace delay learnt online
    deskew: bool = True
    # the learnt rotational error model of the odometry may narrow below its defaults, to sigma = 1 deg
    # (see _ODO_SIGMA_MIN_RAD); False: it only widens (relations < 1 s up to 3.9 deg on ACES and Intel, less
    # drift: benchmarks/scanmatch.py measures both)
    narrow_rotation_guard: bool = True


P3 = tuple[float, float, float]  # a pose (x, y, theta) as plain floats: the per-scan bookkeeping below costs
# ~1 us per composition this way, ~5 us with small numpy arrays


def _compose(a: P3, b: P3) -> P3:
    """a ∘ b, theta in [-pi, pi]."""
    c, s = dm.cos(a[2]), dm.sin(a[2])
    return a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], math.remainder(a[2] + b[2], 2.0 * math.pi)


def _inverse(a: P3) -> P3:
    c, s = dm.cos(a[2]), dm.sin(a[2])
    return -(c * a[0] + s * a[1]), s * a[0] - c * a[1], -a[2]


def _pose(a: P3) -> Pose2D:
    return Pose2D(a[0], a[1], a[2] if a[2] > -math.pi else a[2] + 2.0 * math.pi)


ZERO: P3 = (0.0, 0.0, 0.0)
# the learnt rotational error model of the odometry narrows to 1 deg (+ 5 % of the turn) at most, i.e. 2
# sigmas = 2 deg: a robot whose odometry turns well has a match more than 2 deg off it checked by the
# guard's second opinion (IdcMatcher._guard); the translational model only widens
_ODO_SIGMA_MIN_RAD = math.radians(1.0)
# de-skewing (IdcMatcher._learn_skew): the velocity is taken from corrected increments over 20 ms to 1 s
# (a shorter one, Intel's repeated stamps 1 ms apart, is noise); the interlace delay is learnt from scans
# taken while turning at 30 deg/s or more (10 ms then skews a scan by 0.3 deg), each measurement clipped to
# +-50 ms, and only when the turn rate assumed agrees within 25 % with the rate the match found (a turn that
# changes direction between two scans gives the opposite skew); it is applied from 2 ms (0.2 deg at 100
# deg/s, below the matches' noise) once 20 scans measured it
_SKEW_MIN_S = 0.002
_SKEW_MIN_SCANS = 20
_SKEW_FORGET = 0.97
_SKEW_RATE_AGREE = 0.25
_VEL_MIN_GAP_S = 0.02
_VEL_MAX_GAP_S = 1.0
_SKEW_MIN_RATE = math.radians(30.0)
_SKEW_MAX_S = 0.05


_DEGENERATE = "degenerate geometry"


class _Outcome(NamedTuple):
    laser: P3  # estimated laser pose (corrected frame)
    pairs: int
    residual_m: float
    iterations: int
    reason: str  # "" when accepted
    half_rot: float = math.nan  # odd beams' rotation against the map minus the even ones' [rad]


class IdcMatcher:
    """Stateful IDC corrector; see the module docstring. One instance per log, ``update`` in time order."""

    name = "idc"

    def __init__(self, params: IdcParams | None = None) -> None:
        self.params = params if params is not None else IdcParams()
        self._started = False
        self._prev_pose = ZERO
        self._anchor_pose = ZERO  # corrected pose and odometry of the last scan with fresh odometry
        self._anchor_odom = ZERO
        self._last_incr = ZERO  # previous corrected increment (constant-velocity prediction)
        self._stalled = False
        self._failures = 0
        self._last_pairs = 0
        self._kf_pairs = 0  # the most points a match paired since the newest keyframe
        self._kf_short = 0  # how many matches in a row paired fewer than keyframe_pair_ratio of that
        self._last_t_ns = 0
        self._odo_ms = (1.0, 1.0)  # running mean square of the normalised corrections (see _guard)
        self._odo_scale = (1.0, 1.0)  # learnt scale of the odometry's error model
        self._still_ref = ZERO  # standstill averaging (see _standing_mean)
        self._still_sum = [0.0, 0.0, 0.0]
        self._still_n = 0
        self._odom_step_small = True  # the odometry's last change (none yet) was a robot coming to rest
        self._vel = ZERO  # laser velocity (vx, vy, w) in its own frame from the last corrected increment
        self._skew_s = 0.0  # learnt delay of the odd beams after the even ones, 0 until sure (_learn_skew)
        self._skew_sums = (0.0, 0.0, 0.0, 0)  # sum of w², w² d, w² d² over the delays d seen, their count
        # keyframe ring: points in the corrected frame, their count, next slot, pose of the newest
        self._kf_xy = np.zeros((self.params.map_keyframes, 0, 2))
        self._kf_n = np.zeros(self.params.map_keyframes, dtype=np.int64)
        # each keyframe's view in the corrected frame (see _idc_kernels.unseen_ends)
        self._kf_view = np.zeros((self.params.map_keyframes, 7))
        self._view: tuple[F64, float] = (np.zeros(0), 0.0)  # the current scan's bearings and range limit
        self._kf_next = 0
        self._kf_pose: P3 | None = None

    @property
    def interlace_delay_s(self) -> float:
        """The learnt delay of the odd beams after the even ones that de-skewing applies [s] (0 until the
        matcher is sure of one, and for a scanner that does not interlace; see _learn_skew)."""
        return self._skew_s

    # -- map -------------------------------------------------------------------------------------------
    def _reset_map(self) -> None:
        self._kf_n[:] = 0
        self._kf_next = 0
        self._kf_pose = None

    def _add_keyframe(self, laser_pose: P3, pts: F64) -> None:
        if pts.shape[0] > self._kf_xy.shape[1]:
            grown = np.zeros((self._kf_xy.shape[0], pts.shape[0], 2))
            grown[:, : self._kf_xy.shape[1]] = self._kf_xy
            self._kf_xy = grown
        slot = self._kf_next
        self._kf_xy[slot, : pts.shape[0]] = transform_points(laser_pose, pts)
        self._kf_n[slot] = pts.shape[0]
        bearings, max_r = self._view
        if bearings.shape[0]:
            self._kf_view[slot] = k.view_row(*laser_pose, float(bearings.min()), float(bearings.max()), max_r)
        else:
            self._kf_view[slot] = k.view_row(*laser_pose, 0.0, 0.0, 0.0)
        self._kf_next = (slot + 1) % self._kf_xy.shape[0]
        self._kf_pose = laser_pose
        self._kf_pairs = self._kf_short = 0

    def _is_keyframe(self, laser_pose: P3) -> bool:
        if self._kf_pose is None:
            return True
        d = _compose(_inverse(self._kf_pose), laser_pose)
        p = self.params
        return bool(math.hypot(d[0], d[1]) >= p.keyframe_dist_m or abs(d[2]) >= p.keyframe_angle_rad
                    or (p.keyframe_back_m > 0.0 and -d[0] >= p.keyframe_back_m))

    # -- update ----------------------------------------------------------------------------------------
    def _priors(self, odom_a: P3) -> tuple[list[tuple[P3, P3]], int, bool]:
        """Predicted robot poses for this scan, best first, each with the increment it assumes; how many
        of them to match before choosing (the others are fallbacks, tried only when these fail or pair
        suspiciously few points, see ``recheck_pair_ratio``); and whether the first is the odometry's own
        prediction (fresh odometry, no stall before it).

        Normally the previous corrected pose ∘ odometry increment. Odometry can *stall*: MIT CSAIL's pose
        repeats for ~1 s during fast turns, then jumps. While it repeats and the robot was clearly moving,
        two priors compete (the match with more pairs wins): constant velocity (the previous corrected
        increment again) and no motion. Constant velocity alone would be self-sustaining: a robot that
        really stopped after a fast turn in ACES' round hall kept "turning" by a radian per scan, since a
        round room matches at any heading. On the first fresh odometry after a stall the anchor (last scan
        with fresh odometry) ∘ the odometry since then, which does not count the stalled motion twice but
        inherits the odometry's error over the whole stall, competes with constant velocity. Fallbacks:
        constant velocity, then no motion.
        """
        p = self.params
        cv = (_compose(self._prev_pose, self._last_incr), self._last_incr)
        still = (self._prev_pose, ZERO)
        if p.handle_stalls and odom_a == self._anchor_odom:
            fast = (math.hypot(self._last_incr[0], self._last_incr[1]) >= p.stall_min_step_m
                    or abs(self._last_incr[2]) >= p.stall_min_step_rad)
            if self._stalled or fast:
                self._stalled = True
                return [cv, still], 2, False
        resumed = self._stalled
        self._stalled = False
        incr = _compose(_inverse(self._anchor_odom), odom_a)
        odo = (_compose(self._anchor_pose, incr), incr)
        return [odo, cv, still], (2 if resumed else 1), not resumed

    def update(self, scan: Scan, odom: Pose2D) -> MatchResult:
        """Correct the pose of this scan (see the module docstring); scans must come in time order."""
        p = self.params
        px, py, pr, par = k.scan_points(scan.ranges_m, scan.angles_rad,
                                        max(p.min_range_m, scan.min_range_m), p.max_range_m)
        sp = scan.sensor_pose
        sensor = (sp.x, sp.y, sp.theta)
        odom_a = (odom.x, odom.y, odom.theta)
        self._view = (scan.angles_rad, min(p.max_range_m, scan.max_range_m))  # spanned at a keyframe only
        gap_s = (scan.t_ns - self._last_t_ns) * 1e-9
        self._last_t_ns = scan.t_ns
        vel = self._vel if p.deskew else ZERO
        skew = self._skew_s
        px, py, pr = k.deskew_points(px, py, pr, par, skew, vel[0], vel[1], vel[2])
        if not self._started:
            self._started = True
            self._prev_pose = self._anchor_pose = self._anchor_odom = odom_a
            self._add_keyframe(_compose(odom_a, sensor), np.column_stack([px, py]))
            return MatchResult(odom, True, 0, math.nan, 0)  # the first scan defines the corrected frame
        priors, compete, fresh = self._priors(odom_a)
        pa = dm.atan2_a(py, px)
        odo_laser = _compose(priors[0][0], sensor)
        standing = (p.average_when_still and odom_a == self._anchor_odom and not self._stalled
                    and self._odom_step_small)
        if not standing:
            self._still_n = 0
        iterations = 0
        outcomes: list[_Outcome] = []
        plausible: list[_Outcome] = []  # accepted and near its own prior or near the odometry's prediction
        for h, (hyp, incr) in enumerate(priors[: max(compete, 1 + p.fallback_priors)]):
            out = self._match(px, py, pr, pa, par, _compose(hyp, sensor), incr, coarse=True)
            iterations += out.iterations
            outcomes.append(out)
            if not out.reason:
                if not self._suspicious(out.laser, _compose(hyp, sensor), incr) or (
                        fresh and not self._suspicious(out.laser, odo_laser, priors[0][1])):
                    plausible.append(out)
                elif not fresh:  # no odometry to ask (stalled): a match far from its prior is not believed
                    outcomes[-1] = out._replace(reason="correction too far from the prior (odometry "
                                                       "stalled)")
            if out.iterations == 0:
                break  # nothing to match (too few beams): another prior will not help
            if h == 0 and fresh and out.reason.startswith(_DEGENERATE):
                break  # the place, not the start, leaves the translation unobservable
            if h + 1 >= compete and any(o.pairs >= p.recheck_pair_ratio * self._last_pairs
                                        for o in plausible):
                break
        accepted = [o for o in outcomes if not o.reason]
        # the plausible match with most pairs (then the smallest residual), else the first failure. Fallbacks
        # only run when the first match failed, was suspicious or paired suspiciously few points, so a
        # fallback far from odometry may win (CSAIL's odometry under-reports turns; requiring it to be near
        # odometry too raised the median relation error over ten start scans from 0.054 to 0.070 m). A match
        # far from its prior and from the odometry is only taken when no other is plausible or when it fits
        # clearly better (a stale scan before this one, see the module docstring). Whichever wins, far from
        # the odometry it needs the guard's second opinion
        pool = plausible or accepted
        res = min(pool, key=lambda o: (-o.pairs, o.residual_m)) if pool else outcomes[0]
        res = self._clearly_better(res, accepted, px.shape[0])
        if fresh and not res.reason:
            res, extra = self._guard(res, accepted, px, py, pr, pa, par, odo_laser, priors[0][1])
            iterations += extra
        if res.reason:
            pose = priors[0][0]
            self._failures += 1
            if gap_s > p.map_max_gap_s:  # the map is past its validity and does not fit: start a new one
                return self._restart(odom_a, sensor, px, py, f"{res.reason} after a gap of {gap_s:.1f} s: "
                                                             f"map restarted", res, iterations)
            if self._failures >= p.reset_after_failures:
                self._reset_map()
                self._add_keyframe(_compose(pose, sensor), np.column_stack([px, py]))
                self._failures = 0
                self._last_pairs = 0
        else:
            self._failures = 0
            self._kf_short = self._kf_short + 1 if res.pairs < p.keyframe_pair_ratio * self._kf_pairs else 0
            overlap_drop = self._kf_short >= p.keyframe_pair_scans
            self._last_pairs = res.pairs
            self._kf_pairs = max(self._kf_pairs, res.pairs)
            pose = _compose(res.laser, _inverse(sensor))
            laser = res.laser
            if standing:
                pose = self._standing_mean(pose)
                laser = _compose(pose, sensor)
            if overlap_drop or self._is_keyframe(laser):
                self._add_keyframe(laser, np.column_stack([px, py]))
        self._last_incr = _compose(_inverse(self._prev_pose), pose)
        self._prev_pose = pose
        if p.deskew and _VEL_MIN_GAP_S <= gap_s <= _VEL_MAX_GAP_S:
            d = _compose(_inverse(sensor), _compose(self._last_incr, sensor))
            self._vel = (d[0] / gap_s, d[1] / gap_s, d[2] / gap_s)
            # a measurement of the delay needs the turn rate it was de-skewed with to be the one that followed
            if not res.reason and abs(self._vel[2] - vel[2]) <= _SKEW_RATE_AGREE * abs(vel[2]):
                self._learn_skew(res.half_rot, vel[2], skew)
        if not self._stalled:
            if odom_a != self._anchor_odom:
                step = _compose(_inverse(self._anchor_odom), odom_a)
                self._odom_step_small = (math.hypot(step[0], step[1]) < p.still_entry_m
                                         and abs(step[2]) < p.still_entry_rad)
            self._anchor_pose, self._anchor_odom = pose, odom_a
        return MatchResult(_pose(pose), not res.reason, res.pairs, res.residual_m, iterations,
                           res.reason)

    def _restart(self, odom_a: P3, sensor: P3, px: F64, py: F64, reason: str, res: _Outcome,
                 iterations: int) -> MatchResult:
        """Restart the map from this scan at the odometry's prediction (the previous corrected pose ∘ the
        odometry increment) and forget the motion state; the scan itself is not matched (MATCH_FAILED,
        ``reason``)."""
        pose = _compose(self._anchor_pose, _compose(_inverse(self._anchor_odom), odom_a))
        self._reset_map()
        self._add_keyframe(_compose(pose, sensor), np.column_stack([px, py]))
        self._failures = 0
        self._last_pairs = 0
        self._last_incr = ZERO
        self._stalled = False
        self._still_n = 0
        self._odom_step_small = True
        self._prev_pose = self._anchor_pose = pose
        self._anchor_odom = odom_a
        self._vel = ZERO
        return MatchResult(_pose(pose), False, res.pairs, res.residual_m, iterations, reason)

    def _learn_skew(self, half_rot: float, w: float, applied_s: float) -> None:
        """Learn the interlace delay online from an accepted match of a scan taken while turning at ``w``
        rad/s and de-skewed with a delay of ``applied_s``.

        A scanner that interlaces (a SICK LMS at 0.5 deg takes the even and the odd beams in two sweeps
        13 ms apart) skews a scan taken in a turn: the odd half-scan is rotated by -w times the delay
        against the even one (1.3 deg at 100 deg/s, CSAIL). The match leaves a rotation ``half_rot``
        between the halves of w times the delay still missing, so each such scan gives one measurement of
        the delay, applied_s + half_rot / w. The estimate is their mean weighted by w² (a fast turn tells
        more) and by a factor ``_SKEW_FORGET`` per newer measurement: the map holds the scans taken before
        the delay was known, skewed, which pull the halves together, so the first measurements fall short
        and the estimate converges as the map is renewed (a plain mean stayed at 60 % of the delay). It is
        applied once ``_SKEW_MIN_SCANS`` scans have measured it and it is at least
        ``_SKEW_MIN_S`` and three standard errors from 0. A scanner that does not interlace has halves that
        agree: its delay stays 0 and its scans are left as they are.
        """
        if abs(w) < _SKEW_MIN_RATE or not math.isfinite(half_rot):
            return
        d = min(_SKEW_MAX_S, max(-_SKEW_MAX_S, applied_s + half_rot / w))
        s0, s1, s2, n = self._skew_sums
        w2 = w * w
        f = _SKEW_FORGET
        s0, s1, s2, n = f * s0 + w2, f * s1 + w2 * d, f * s2 + w2 * d * d, n + 1
        self._skew_sums = (s0, s1, s2, n)
        mean = s1 / s0
        n_eff = (1.0 - dm.powi(f, n)) / (1.0 - f)
        se = math.sqrt(max(0.0, s2 / s0 - mean * mean) / n_eff)
        sure = n >= _SKEW_MIN_SCANS and abs(mean) >= max(_SKEW_MIN_S, 3.0 * se)
        self._skew_s = mean if sure else 0.0

    def _standing_mean(self, pose: P3) -> P3:
        """The mean of this standstill's matched poses (the last moving one included): while the robot
        stands, every scan measures the same pose against the same map. A match further than
        ``still_max_m`` / ``still_max_rad`` from where the robot stopped says it is moving after all (the
        odometry lags or stalls): it is taken as it is, and a new standstill may start from it."""
        p = self.params
        if self._still_n == 0:
            self._still_ref = self._prev_pose
            self._still_sum = [0.0, 0.0, 0.0]
            self._still_n = 1
        d = _compose(_inverse(self._still_ref), pose)
        if math.hypot(d[0], d[1]) > p.still_max_m or abs(d[2]) > p.still_max_rad:
            self._still_n = 0
            return pose
        for i in range(3):
            self._still_sum[i] += d[i]
        self._still_n += 1
        n = self._still_n
        sx, sy, sth = self._still_sum
        return _compose(self._still_ref, (sx / n, sy / n, sth / n))

    def _cost(self, o: _Outcome, n: int) -> float:
        """Mean truncated distance of the n points at a match: a pair's distance, gate_min_m for a point
        left unpaired (lower is better; compares two poses of one scan against one map)."""
        gate = self.params.gate_min_m
        return (o.residual_m * o.pairs + gate * (n - o.pairs)) / n

    def _clearly_better(self, res: _Outcome, accepted: list[_Outcome], n: int) -> _Outcome:
        """The accepted match that fits clearly better than ``res`` (mean truncated distance lower by
        ``coarse_margin``, the best such), else ``res``. A match near its own prior is preferred to one far
        from it, but not when it fits much worse: after a scan that does not follow the odometry (a stale
        record repeating an earlier view, Intel) every prior is off by that scan's jump, and the match near
        a prior can be a poor fit between two basins while the far one fits as well as the scans before.
        A far match still needs the guard's second opinion."""
        if res.reason:
            return res
        limit = (1.0 - self.params.coarse_margin) * self._cost(res, n)
        better = [o for o in accepted if self._cost(o, n) < limit]
        return min(better, key=lambda o: self._cost(o, n)) if better else res

    def _odo_sigmas(self, incr: P3) -> tuple[float, float]:
        """The odometry's error model for an increment: (translation sigma [m], rotation sigma [rad])."""
        p = self.params
        return (p.odo_sigma_m + p.odo_sigma_rel * math.hypot(incr[0], incr[1]),
                p.odo_sigma_rad + p.odo_sigma_rel_rad * abs(incr[2]))

    def _z(self, laser: P3, odo_laser: P3, incr: P3) -> tuple[float, float]:
        """How far a laser pose is from the odometry's prediction, in sigmas of the odometry's error model
        (translation, rotation), and before the learnt scale."""
        corr = _compose(_inverse(odo_laser), laser)
        s_t, s_r = self._odo_sigmas(incr)
        return math.hypot(corr[0], corr[1]) / s_t, abs(corr[2]) / s_r

    def _suspicious(self, laser: P3, odo_laser: P3, incr: P3) -> bool:
        """Whether a match is beyond ``guard_sigmas`` of the learnt odometry error model."""
        z_t, z_r = self._z(laser, odo_laser, incr)
        g = self.params.guard_sigmas
        return z_t > g * self._odo_scale[0] or z_r > g * self._odo_scale[1]

    def _guard(self, res: _Outcome, accepted: list[_Outcome], px: F64, py: F64, pr: F64, pa: F64, par: I64,
               odo_laser: P3, incr: P3) -> tuple[_Outcome, int]:
        """Never worse than odometry: a match within ``guard_sigmas`` of the odometry's prediction (in the
        learnt error model, see IdcParams) is taken and teaches the model; a match further away needs a
        second opinion, the match from the odometry's prediction in a narrow bearing window. The far match
        is believed when the odometry's neighbourhood does not fit the map (that match fails its gates) or
        when it pairs ``guard_gain`` of the points more; otherwise the odometry is kept (MATCH_FAILED).
        When the far match is no better than the near one but another accepted match of this scan
        (``accepted``, from another prior) fits clearly better than the near one, the odometry's basin is
        not where the scan fits best, and that match is taken (a fast turn that the odometry
        under-reports: the match from constant velocity's prediction was preferred for being near its own
        prior, the one from the odometry's prediction fits better). Returns the outcome and the iterations
        the second opinion took."""
        p = self.params
        corr = _compose(_inverse(odo_laser), res.laser)
        z_t, z_r = self._z(res.laser, odo_laser, incr)
        if self._suspicious(res.laser, odo_laser, incr):
            near = self._match(px, py, pr, pa, par, odo_laser, incr, p.guard_window_rad)
            extra = near.iterations
            # the near match went most of the way from the odometry to the far one: the map agrees with it
            if not near.reason and not self._agree(near, res, corr):
                n = px.shape[0]
                c_far, c_near = self._cost(res, n), self._cost(near, n)
                if c_near < (1.0 - p.guard_gain) * c_far:
                    return near, extra  # a better match near the odometry: the far one was a wrong basin
                if c_far >= (1.0 - p.guard_gain) * c_near:
                    seconds = [o for o in accepted if o is not res
                               and self._cost(o, n) < (1.0 - p.guard_gain) * c_near]
                    if not seconds:
                        return _Outcome(odo_laser, near.pairs, near.residual_m, res.iterations + extra,
                                        f"unconfirmed match: {math.hypot(corr[0], corr[1]):.3f} m, "
                                        f"{math.degrees(corr[2]):.1f} deg from odometry ({max(z_t, z_r):.1f} "
                                        f"sigma) and no better than the match near odometry"), extra
                    res = min(seconds, key=lambda o: self._cost(o, n))
                    z_t, z_r = self._z(res.laser, odo_laser, incr)  # the model learns from what is taken
        else:
            extra = 0
        a = p.odo_learn_rate
        c2 = p.odo_learn_clip * p.odo_learn_clip
        self._odo_ms = ((1.0 - a) * self._odo_ms[0] + a * min(z_t * z_t, c2),
                        (1.0 - a) * self._odo_ms[1] + a * min(z_r * z_r, c2))
        floor = (min(1.0, _ODO_SIGMA_MIN_RAD / p.odo_sigma_rad)
                 if p.narrow_rotation_guard and p.odo_sigma_rad > 0.0 else 1.0)
        self._odo_scale = (max(1.0, math.sqrt(self._odo_ms[0])), max(floor, math.sqrt(self._odo_ms[1])))
        return res, extra

    def _agree(self, a: _Outcome, b: _Outcome, corr: P3) -> bool:
        """Whether two matches of one scan are within ``guard_agree_*`` or half the correction ``corr``
        (the far match's, from the odometry's prediction) of each other."""
        p = self.params
        d = _compose(_inverse(a.laser), b.laser)
        return (math.hypot(d[0], d[1]) <= max(p.guard_agree_m, 0.5 * math.hypot(corr[0], corr[1]))
                and abs(d[2]) <= max(p.guard_agree_rad, 0.5 * abs(corr[2])))

    def _match(self, px: F64, py: F64, pr: F64, pa: F64, par: I64, laser_prior: P3, incr: P3,
               win0_rad: float | None = None, coarse: bool = False) -> _Outcome:
        """Align the scan with the map rendered at ``laser_prior`` and apply the acceptance gates.

        The correction gate accepts a pose near the prior itself or near ``gate`` (the laser pose that fresh
        odometry predicts, and its increment): a fallback prior (no motion) that finds the pose odometry
        roughly agrees with must not be refused for being far from its own guess (ACES, a 17 deg turn),
        while constant velocity must still rescue a fast turn that CSAIL's odometry under-reports."""
        p = self.params
        n = px.shape[0]
        need = max(p.min_pairs, math.ceil(p.min_pair_fraction * n))
        if n < need:
            return _Outcome(laser_prior, 0, math.nan, 0, f"too few valid beams: {n} < {need}")
        stride = max(1, n // p.idc_points)
        w_t = w_r = 0.0
        if p.polish_iterations > 0:
            r_t = p.pair_sigma_m / (p.prior_sigma_m + p.prior_sigma_rel * math.hypot(incr[0], incr[1]))
            r_r = p.pair_sigma_m / (p.prior_sigma_rad + p.prior_sigma_rel_rad * abs(incr[2]))
            w_t, w_r = r_t * r_t, r_r * r_r
        bin_rad = 2.0 * math.pi / p.n_bins
        coarse_step = max(1, round(p.coarse_step_rad / bin_rad))
        coarse_bins = min(round(p.coarse_window_rad / bin_rad), p.n_bins // 2) if coarse else 0
        win0 = p.win0_rad if win0_rad is None else win0_rad
        x, y, th, iters, pairs, resid, _info, weakest, half_rot = k.match_scan(
            self._kf_xy, self._kf_n, self._kf_view, laser_prior[0], laser_prior[1], laser_prior[2],
            px, py, pr, p.n_bins,
            p.min_range_m, p.max_range_m + p.gate0_m, p.blend_m, p.seg_abs_m, p.seg_rel, p.gap_bins,
            p.normal_chord_m, p.max_iterations, win0, p.win_tau, p.win_min_rad, p.gate0_m, p.gate_min_m,
            p.tol_m, p.tol_rad, p.max_cp_bins, stride, max(1, n // (stride * p.mrp_points)),
            p.polish_iterations, w_t, w_r, pa, coarse_bins, coarse_step, max(1, n // p.coarse_points),
            p.coarse_tol_m, p.coarse_tol_rel, p.coarse_min_gain, p.coarse_margin, par)
        est = _compose(laser_prior, (x, y, th))
        if pairs < need:
            return _Outcome(est, pairs, resid, iters, f"too few pairs: {pairs} < {need}")
        if resid > p.max_residual_m:
            return _Outcome(est, pairs, resid, iters, f"residual {resid:.3f} m > {p.max_residual_m} m")
        if weakest < p.degenerate_min_info:
            return _Outcome(est, pairs, resid, iters,
                            f"{_DEGENERATE}: translation unobservable (information {weakest:.1f} "
                            f"< {p.degenerate_min_info})")
        return _Outcome(est, pairs, resid, iters, "", half_rot)
