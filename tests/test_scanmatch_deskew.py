"""De-skewing of interlaced scans (IdcMatcher._learn_skew): the delay is learnt from the data and applied only
when the scanner interlaces."""

from __future__ import annotations

import math

import numpy as np
from test_scanmatch import cast, compose, relative, room

from gndreplay.scanmatch import IdcMatcher, IdcParams
from gndreplay.scanmatch import _idc_kernels as kern
from gndreplay.types import Pose2D, Scan

DT_S = 0.2  # CSAIL's scan period
W = math.radians(100.0)  # a fast turn, as CSAIL's


def _interlaced(segs: np.ndarray, pose_at: list[np.ndarray], delay_s: float, w: float, v: float,
                t_ns: int) -> Scan:
    """A 361-beam scan whose even beams are taken delay/2 before the stamp and the odd ones delay/2 after,
    with the robot moving at (v, 0, w) (a SICK LMS interlacing two 1 deg sweeps into 0.5 deg)."""
    p = pose_at[0]
    even = cast(segs, compose(p, np.array([-v * delay_s / 2, 0.0, -w * delay_s / 2])), t_ns=t_ns)
    odd = cast(segs, compose(p, np.array([v * delay_s / 2, 0.0, w * delay_s / 2])), t_ns=t_ns)
    r = even.ranges_m.copy()
    r[1::2] = odd.ranges_m[1::2]
    return Scan(t_ns, r, even.angles_rad, even.max_range_m)


def _weave(n: int) -> list[tuple[float, float]]:
    """(v [m/s], w [rad/s]) per scan: in place and moving, turning one way then the other at 100 deg/s,
    with straight stretches (the map is then built from unskewed scans too)."""
    out = []
    for i in range(n):
        phase = (i // 4) % 4
        out.append((0.2, 0.0) if phase == 0 else (0.1, W) if phase in (1, 2) else (0.1, -W))
    return out


def _run(delay_s: float, params: IdcParams | None = None, n: int = 90) -> tuple[IdcMatcher, list[float]]:
    """Drive the weave with odometry that is right; returns the matcher and, per consecutive pair of scans,
    the rotational error [deg] of the corrected increment."""
    segs = room()
    truth = [np.array([1.0, 0.5, 0.0])]
    for v, w in _weave(n):
        truth.append(compose(truth[-1], np.array([v * DT_S, 0.0, w * DT_S])))
    m = IdcMatcher(params)
    est: list[np.ndarray] = []
    moves = [(0.0, 0.0), *_weave(n)]
    for i, tp in enumerate(truth):
        # the scan at the stamp sees the velocity of the step that leads to it
        v, w = moves[i]
        res = m.update(_interlaced(segs, [tp], delay_s, w, v, i * int(DT_S * 1e9)), Pose2D.from_array(tp))
        assert res.ok, (i, res.reason)
        est.append(res.pose.as_array())
    errs = []
    for i in range(1, len(truth)):
        e = relative(relative(truth[i - 1], truth[i]), relative(est[i - 1], est[i]))
        errs.append(abs(math.degrees(e[2])))
    return m, errs


def test_deskew_points_moves_odd_beams_by_the_turn_in_the_delay() -> None:
    px, py = np.array([1.0, 1.0, 0.0, 2.0]), np.array([0.0, 0.0, 1.0, 0.0])
    pr = np.hypot(px, py)
    par = np.array([0, 1, 0, 1], dtype=np.int64)
    qx, qy, qr = kern.deskew_points(px, py, pr, par, 0.0, 1.0, 0.0, 2.0)
    assert np.array_equal(qx, px) and np.array_equal(qy, py) and np.array_equal(qr, pr)  # no delay
    qx, qy, qr = kern.deskew_points(px, py, pr, par, 0.01, 0.0, 0.0, 2.0)
    # tau = -5 ms for even beams, +5 ms for odd ones: rotated by -/+ 0.01 rad about the laser
    assert math.isclose(math.atan2(qy[0], qx[0]), -0.01) and math.isclose(math.atan2(qy[1], qx[1]), 0.01)
    assert np.allclose(qr, pr)
    qx, _, _ = kern.deskew_points(px, py, pr, par, 0.01, 1.0, 0.0, 0.0)  # 1 m/s ahead: +-5 mm
    assert np.allclose(qx - px, [-0.005, 0.005, -0.005, 0.005])


def test_interlace_delay_is_learnt_from_the_halves_disagreement() -> None:
    """A scanner whose odd beams come 13 ms after the even ones (a SICK LMS interlacing two 75 Hz sweeps
    into 0.5 deg), turning at 100 deg/s one way and the other: the matcher learns the delay from the
    rotation between the halves that its matches leave, to within 25 %. (Its effect on accuracy is measured
    on the real interlaced log, CSAIL, in benchmarks/scanmatch.py: this clean room matches well even
    skewed.)"""
    delay_s = 0.0133
    m, errs = _run(delay_s)
    assert abs(m.interlace_delay_s - delay_s) < 0.25 * delay_s, m.interlace_delay_s
    assert max(errs) < 1.0, errs


def test_a_scanner_that_does_not_interlace_is_left_as_it_is() -> None:
    """Same turns, all beams at the stamp: no delay is learnt and the poses are those without de-skewing."""
    m, with_deskew = _run(0.0)
    assert m.interlace_delay_s == 0.0
    _, without = _run(0.0, IdcParams(deskew=False))
    assert with_deskew == without
