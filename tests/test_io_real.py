"""The real logs in ../shared/datasets: counts, the five forms of MIT CSAIL agree, ACES is time-ordered."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gndreplay.errors import LogFormatError
from gndreplay.io import ReadOptions, open_log
from gndreplay.types import NS_PER_S

pytestmark = pytest.mark.slow

MIT_FORMS = {
    "carmen": "carmen/mit-csail.clf.bz2",
    "rosbag1": "rosbag1/mit-csail.sort.bag",
    "rosbag2-sqlite3": "rosbag2/mit-csail.sort.ros2_sqlite3",
    "rosbag2-mcap": "rosbag2/mit-csail.sort.ros2_mcap",
    "mcap": "rosbag2/mit-csail.sort.ros2_mcap/mit-csail.sort.ros2_mcap.mcap",
}


def load(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, object]:
    """Stamps (N,), ranges (N, B), odometry (N, 3) and the read report."""
    t, r, o = [], [], []
    with open_log(path) as log:
        for tick in log.ticks():
            t.append(tick.t_ns)
            r.append(tick.scan.ranges_m)
            o.append(tick.odom.as_array())
        rep = log.report
    return np.array(t), np.array(r), np.array(o), rep


@pytest.fixture(scope="module")
def mit(datasets: Path) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray, object]]:
    return {name: load(datasets / rel) for name, rel in MIT_FORMS.items()}


def test_mit_csail_has_1988_scans_of_361_beams_in_every_form(mit: dict) -> None:
    for name, (t, r, _, rep) in mit.items():
        assert r.shape == (1988, 361), name
        assert np.all(np.diff(t) > 0), name
        assert rep.malformed == 0 and rep.late_dropped == 0, name


def test_mit_csail_forms_agree(mit: dict) -> None:
    """Ranges agree to float32 precision (rtol 1e-6: the bags store float32), odometry to 1e-6."""
    t0, r0, o0, _ = mit["carmen"]
    for name, (t, r, o, _) in mit.items():
        # the bags' stamps were converted through a float: within a microsecond of the CARMEN text
        assert np.max(np.abs(t - t0)) < 1_000, name
        np.testing.assert_array_equal(np.isnan(r), np.isnan(r0), err_msg=name)
        np.testing.assert_array_equal(np.isposinf(r), np.isposinf(r0), err_msg=name)
        ok = np.isfinite(r0)
        np.testing.assert_allclose(r[ok], r0[ok], rtol=1e-6, atol=0, err_msg=name)
        np.testing.assert_allclose(o[:, :2], o0[:, :2], rtol=0, atol=1e-6, err_msg=name)
        dth = np.angle(np.exp(1j * (o[:, 2] - o0[:, 2])))
        np.testing.assert_allclose(dth, 0.0, atol=1e-6, err_msg=name)


def test_mit_csail_no_return_is_the_81_91_marker(mit: dict) -> None:
    _, r, _, _ = mit["carmen"]
    assert np.isposinf(r).sum() == 23711  # every 81.91 in the file, nothing else
    assert not np.isnan(r).any()


@pytest.mark.parametrize("rel", ["carmen/aces.clf.bz2", "rosbag1/aces.sort.bag"])
def test_aces_is_time_ordered_although_the_file_is_not(datasets: Path, rel: str) -> None:
    t, r, _, rep = load(datasets / rel)
    assert r.shape == (7374, 180)
    assert np.all(np.diff(t) > 0)
    assert rep.late_dropped == 0 and rep.malformed == 0
    assert rep.scans_without_odom_before == 0 and rep.scans_without_odom_after == 0
    if rel.startswith("carmen"):
        assert rep.out_of_order == 161  # ODOM and FLASER lines interleave out of time order
        assert rep.time_reversals == 0  # each stream on its own is monotonic
        assert np.isposinf(r).sum() == 11139  # the 50.0 no-return marker


def test_aces_carmen_and_bag_agree(datasets: Path) -> None:
    """ODOM lines interpolated at the scan stamps give the bag's odometry: the two forms agree."""
    t0, r0, o0, _ = load(datasets / "carmen/aces.clf.bz2")
    t1, r1, o1, _ = load(datasets / "rosbag1/aces.sort.bag")
    assert np.max(np.abs(t1 - t0)) < 1_000
    np.testing.assert_array_equal(np.isposinf(r0), np.isposinf(r1))
    ok = np.isfinite(r0)
    np.testing.assert_allclose(r1[ok], r0[ok], rtol=1e-6)
    np.testing.assert_allclose(o1[:, :2], o0[:, :2], atol=1e-6)


def test_aces_odom_lines_beat_the_stale_flaser_triple(datasets: Path) -> None:
    """The FLASER odometry triple is the last ODOM sample before the scan (stale by ~0.1 s)."""
    p = datasets / "carmen/aces.clf.bz2"
    _, _, interp, _ = load(p)
    with open_log(p, options=ReadOptions(odom_topic="FLASER")) as log:
        embedded = np.array([t.odom.as_array() for t in log.ticks()])
    moved = np.hypot(*(interp[:, :2] - embedded[:, :2]).T)
    assert np.median(moved) > 0.005  # they differ while the robot moves


def test_laserazos_loads_with_nan_beams_invalid_and_an_index_clock(datasets: Path) -> None:
    t, r, o, rep = load(datasets / "robustness/laserazosSM3.log")
    assert r.shape == (778, 361)
    assert np.isnan(r).sum() == 19234  # every NaN of the file (grep -o NaN | wc -l), no other beam
    assert not np.isposinf(r).any()
    assert rep.index_clock and rep.warnings
    assert t[0] == NS_PER_S // 10 and np.all(np.diff(t) == NS_PER_S // 10)
    assert o[0] == pytest.approx([0.536604, -0.437674, -1.002273])


@pytest.mark.parametrize(
    ("rel", "message"),
    [
        ("robustness/loop5.log", r"loop5\.log: not a CARMEN log"),
        (
            "robustness/laser_scan_matcher_demo.bag",
            r"laser_scan_matcher_demo\.bag: the ROS bag reader \(rosbags\) "
            r"refuses it",
        ),
        (
            "robustness/laser_scan_splitter_demo.bag",
            r"laser_scan_splitter_demo\.bag: unsupported legacy ROS bag "
            r"format V1\.2",
        ),
    ],
)
def test_robustness_files_give_a_clear_error(datasets: Path, rel: str, message: str) -> None:
    with pytest.raises(LogFormatError, match=message), open_log(datasets / rel) as log:
        list(log.ticks())


def test_clf2bag_conversion_reads(datasets: Path) -> None:
    t, r, _, rep = load(datasets / "rosbag1/aces.clf2bag.bag")
    assert r.shape == (7374, 180)
    assert np.all(np.diff(t) > 0)
    assert rep.malformed == 0
