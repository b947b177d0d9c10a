"""ND+ stalls of the rectangular chair (issue 10): a goal within the chair's length beside it.

The tests run ``nd_step`` in a small closed loop (unicycle kinematics, static obstacle points in the world
frame, the memory passed back as the stack does, the reflexive check after it) and check the outcome, not
the internals."""

from __future__ import annotations

import math

import numpy as np

from gndreplay.config import preset
from gndreplay.pipeline.nd import NdMemory, nd_step
from gndreplay.pipeline.supervisor import SupervisorParams, footprint_signed_distance, safe_command

CHAIR = preset("wheelchair").robot
DT = 0.2


def _line(x0: float, y0: float, x1: float, y1: float, step: float = 0.025) -> np.ndarray:
    n = max(int(math.hypot(x1 - x0, y1 - y0) / step), 1) + 1
    return np.column_stack([np.linspace(x0, x1, n), np.linspace(y0, y1, n)])


def _circle(cx: float, cy: float, r: float, step: float = 0.025) -> np.ndarray:
    a = np.linspace(0.0, 2.0 * math.pi, max(int(2.0 * math.pi * r / step), 8), endpoint=False)
    return np.column_stack([cx + r * np.cos(a), cy + r * np.sin(a)])


def _to_robot(pose: np.ndarray, xy: np.ndarray) -> np.ndarray:
    c, s = math.cos(pose[2]), math.sin(pose[2])
    d = xy - pose[:2]
    return np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]])


def _drive(pose: np.ndarray, world: np.ndarray, goal: np.ndarray, ticks: int,
           stop_m: float = 0.3) -> tuple[list[np.ndarray], list[float], float]:
    """Closed loop: poses, commanded v per tick and the smallest footprint clearance. The reactor's memory
    is carried over as the stack does (its sub-goal held as a world bearing), and its command goes through
    the reflexive check (``safe_command``, the points as both scan and grid, everything else known free)."""
    poses, vs, clear = [pose.copy()], [], math.inf
    held: float | None = None
    for _ in range(ticks):
        if math.hypot(*(goal - pose[:2])) <= stop_m:
            break
        prev = None
        if held is not None:
            prev = NdMemory(math.remainder(held - pose[2], math.tau))
        res = nd_step(_to_robot(pose, world), _to_robot(pose, goal[None, :])[0], CHAIR, prev=prev)
        held = None if res.memory is None else pose[2] + res.memory.subgoal_rad
        pts = _to_robot(pose, world)
        near = pts[np.hypot(pts[:, 0], pts[:, 1]) <= 3.0]
        safe = safe_command(res.v_mps, 0.0, res.w_radps, near, near, CHAIR, SupervisorParams(), cell_m=0.05,
                            unknown_xy=lambda: np.zeros((0, 2)))
        v, w = safe.v_mps, safe.w_radps
        if abs(w) > 1e-9:
            pose = pose + np.array([v / w * (math.sin(pose[2] + w * DT) - math.sin(pose[2])),
                                    -v / w * (math.cos(pose[2] + w * DT) - math.cos(pose[2])), w * DT])
        else:
            pose = pose + np.array([v * DT * math.cos(pose[2]), v * DT * math.sin(pose[2]), 0.0])
        poses.append(pose.copy())
        vs.append(v)
        clear = min(clear, float(np.min(footprint_signed_distance(_to_robot(pose, world), CHAIR))))
    return poses, vs, clear


def test_goal_beside_the_chair_between_wall_and_person_is_reached() -> None:
    """gnd_exp2_people_room: the goal 0.32 m beside the chair's axle, a person (waiting for the chair)
    0.6 m beyond it, a wall on the other side. The pair person / wall is a "passage" around the body, and
    pursuing its axis drove the chair along past the goal and back, for minutes; a goal nearer than the
    chair's front is steered to directly."""
    world = np.vstack([_line(-4.0, 0.68, 4.0, 0.68), _circle(0.0, -0.92, 0.25)])
    goal = np.array([0.0, -0.32])
    for x0 in (-1.0, -0.6, -0.3):  # approaching it from behind, still 0.3 m short of abeam
        poses, _, clear = _drive(np.array([x0, 0.0, 0.0]), world, goal, 150)
        assert math.hypot(*(goal - poses[-1][:2])) <= 0.3, x0
        assert clear > 0.0


def test_door_ahead_keeps_the_passage_axis() -> None:
    """The same rule leaves a passage the chair must cross alone: a goal beyond a 0.9 m door entered
    0.3 m off its axis is reached through the door without touching a jamb."""
    jambs = np.vstack([_line(1.5, 0.45, 1.5, 3.0), _line(1.5, -0.45, 1.5, -3.0),
                       _line(1.5, 0.45, 1.7, 0.45), _line(1.5, -0.45, 1.7, -0.45),
                       _line(1.7, 0.45, 1.7, 3.0), _line(1.7, -0.45, 1.7, -3.0)])
    goal = np.array([3.5, 0.0])
    poses, _, clear = _drive(np.array([0.0, -0.3, 0.0]), jambs, goal, 400)
    assert math.hypot(*(goal - poses[-1][:2])) <= 0.3
    assert clear > 0.0
