"""Known-answer tests of the GND supervision rules and the reflexive loop."""

from __future__ import annotations

import numpy as np
import pytest

from gndreplay.pipeline.supervisor import (
    Mode,
    SupervisorParams,
    TrapDetector,
    budget_flags,
    escape_command,
    footprint_contains,
    gnd_mode,
    rotate_command,
    swept_collision,
)
from gndreplay.robot import WHEELCHAIR_ROBOT, XR4000_ROBOT
from gndreplay.types import Flag

P = SupervisorParams()


@pytest.mark.parametrize(
    ("planner_ok", "has_region", "mode"),
    [
        (True, True, Mode.MPND),
        (False, True, Mode.MND),
        (True, False, Mode.ROTATE),
        (False, False, Mode.ROTATE),
    ],
)
def test_gnd_modes(planner_ok: bool, has_region: bool, mode: Mode) -> None:
    assert gnd_mode(planner_ok, has_region) is mode


def test_rotate_turns_towards_the_goal_side() -> None:
    assert rotate_command(0.3, WHEELCHAIR_ROBOT, P) == pytest.approx(0.5 * 0.5)
    assert rotate_command(-2.0, WHEELCHAIR_ROBOT, P) == pytest.approx(-0.25)


def test_footprint_rectangle_and_circle() -> None:
    pts = np.array([[0.79, 0.0], [0.81, 0.0], [-0.39, 0.34], [-0.41, 0.0], [0.0, 0.36]])
    assert footprint_contains(pts, WHEELCHAIR_ROBOT, 0.0).tolist() == [True, False, True, False, False]
    pts = np.array([[0.29, 0.0], [0.0, -0.31], [0.2, 0.2]])
    assert footprint_contains(pts, XR4000_ROBOT, 0.0).tolist() == [True, False, True]


def test_swept_collision_straight_ahead() -> None:
    # horizon at 0.3 m/s: 0.3 s + 0.6 s = 0.9 s -> 0.27 m of travel; front edge at 0.8 m (+ 0.02 margin)
    near = np.array([[1.0, 0.0]])
    far = np.array([[1.2, 0.0]])
    assert swept_collision(near, 0.3, 0.0, WHEELCHAIR_ROBOT, P)
    assert not swept_collision(far, 0.3, 0.0, WHEELCHAIR_ROBOT, P)
    assert not swept_collision(near, 0.0, 0.0, WHEELCHAIR_ROBOT, P)  # standing still sweeps nothing new
    assert not swept_collision(np.zeros((0, 2)), 0.3, 0.0, WHEELCHAIR_ROBOT, P)


def test_swept_collision_rotation_sweeps_the_rectangle_corners() -> None:
    # a point just beside the front-left corner is hit when the wheelchair turns left in place
    corner = np.array([[0.70, 0.45]])
    assert not swept_collision(corner, 0.0, 0.0, WHEELCHAIR_ROBOT, P)
    assert swept_collision(corner, 0.0, 0.5, WHEELCHAIR_ROBOT, P)
    # the circular robot rotating in place sweeps nothing
    assert not swept_collision(np.array([[0.35, 0.0]]), 0.0, 1.5, XR4000_ROBOT, P)


def test_swept_collision_holonomic_sideways() -> None:
    left = np.array([[0.0, 0.45]])
    assert swept_collision(left, 0.0, 0.0, XR4000_ROBOT, P, vy_mps=0.3)
    assert not swept_collision(left, 0.0, 0.0, XR4000_ROBOT, P, vy_mps=-0.3)


def test_escape_prefers_forward_then_backward() -> None:
    v, ok = escape_command(np.array([[3.0, 0.0]]), WHEELCHAIR_ROBOT, P)
    assert ok and v == pytest.approx(0.3 * 0.3)
    v, ok = escape_command(np.array([[1.0, 0.0]]), WHEELCHAIR_ROBOT, P)
    assert ok and v == pytest.approx(-0.09)
    v, ok = escape_command(np.array([[1.0, 0.0], [-0.6, 0.1]]), WHEELCHAIR_ROBOT, P)
    assert not ok and v == 0.0


def test_trap_detector_needs_alternating_stopped_rotations() -> None:
    det = TrapDetector(SupervisorParams(trap_window=20, trap_count=4))
    # rotating steadily one way is not a trap
    assert not any(det.update(Mode.ROTATE, 0.25) for _ in range(10))
    det = TrapDetector(SupervisorParams(trap_window=20, trap_count=4))
    seen = [det.update(Mode.ROTATE, w) for w in (0.25, -0.25, 0.25, -0.25)]
    assert seen == [False, False, False, True]


def test_trap_detector_counts_emergencies() -> None:
    det = TrapDetector(SupervisorParams(trap_window=10, trap_count=3))
    seen = [det.update(m, 0.0) for m in (Mode.EMERGENCY, Mode.MPND, Mode.EMERGENCY, Mode.EMERGENCY)]
    assert seen == [False, False, False, True]


def test_budget_flags() -> None:
    flags = budget_flags({"match": 0.001, "model": 0.06, "planner": 0.01, "reactor": 0.03}, P)
    assert flags == Flag.MODEL_OVER_BUDGET | Flag.REACTOR_OVER_BUDGET
    assert budget_flags({}, P) == Flag.NONE
