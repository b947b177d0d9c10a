"""The door class: a door only ``spare`` (0.15 m) wider than the robot, approached from the side.

A hall 10 x 4 m (a wide corridor) runs along a wall; the door is in that wall, a room 6 x 4 m behind it,
the goal 2 m inside the room. The robot starts 2 m before the point 1.4 m in front of the door, heading
``angle`` to the wall (0: driving along it, the door on its left; 90: straight at it), shifted sideways
(perpendicular to its heading) by ``offset``. Per case: reached or not, time to goal, the longest stall
(no 0.2 m and no 45 deg net for that long; the bound is 10 s) and trap detections.

    PYTHONPATH=$PWD .venv/bin/python benchmarks/doors.py [--preset wheelchair] [--seeds 3]
        [--angles 0,30,60,90] [--offsets -0.4,0,0.4] [--spare 0.15] [--planner nf1] [--out DIR]

tests/test_door_class.py runs a few of these cases.
"""

from __future__ import annotations

import argparse
import math
import os
import tempfile
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("MPLBACKEND", "Agg")

from gndreplay.config import CliOverrides, configure
from gndreplay.robot import RobotConfig
from gndreplay.sim import simulate_scenario
from gndreplay.sim.scenario_file import parse_scenario

HALL_HALF_M = 5.0  # the hall runs x in [-5, 5], y in [0, 4]; the door wall is y = 4
WALL_Y_M = 4.0
ROOM_HALF_M = 3.0  # the room: x in [-3, 3], y in [4, 8]
ROOM_DEPTH_M = 4.0
APPROACH_Y_M = 2.6  # the point the approach aims at: 1.4 m in front of the door
RUN_UP_M = 2.0  # the start lies this far before it
GOAL_IN_M = 2.0  # the goal's depth in the room
TIME_LIMIT_S = 120.0
STALL_BOUND_S = 10.0


def door_width_m(robot: RobotConfig, spare_m: float) -> float:
    """The robot's width (a circle's diameter) plus ``spare_m``."""
    return 2.0 * robot.inner_radius_m + spare_m


def door_case(angle_deg: float, offset_m: float, robot: RobotConfig, *, spare_m: float = 0.15,
              preset_name: str = "wheelchair") -> dict[str, Any]:
    """The scenario document of one case (``parse_scenario`` reads it)."""
    half = 0.5 * door_width_m(robot, spare_m)
    a = math.radians(angle_deg)
    x = -RUN_UP_M * math.cos(a) - offset_m * math.sin(a)
    y = APPROACH_Y_M - RUN_UP_M * math.sin(a) + offset_m * math.cos(a)
    top = WALL_Y_M + ROOM_DEPTH_M
    return {
        "name": f"door_{angle_deg:g}deg_{'m' if offset_m < 0 else 'p'}{abs(offset_m):g}m",
        "description": f"a door {spare_m:g} m wider than the robot, approached at {angle_deg:g} deg",
        "preset": preset_name,
        "start": [round(x, 6), round(y, 6), round(a, 6)],
        "goal": [0.0, WALL_Y_M + GOAL_IN_M],
        "time_limit": TIME_LIMIT_S,
        "world": {"walls": {
            "hall_s": [-HALL_HALF_M, 0.0, HALL_HALF_M, 0.0],
            "hall_w": [-HALL_HALF_M, 0.0, -HALL_HALF_M, WALL_Y_M],
            "hall_e": [HALL_HALF_M, 0.0, HALL_HALF_M, WALL_Y_M],
            "wall_w": [-HALL_HALF_M, WALL_Y_M, -half, WALL_Y_M],
            "wall_e": [half, WALL_Y_M, HALL_HALF_M, WALL_Y_M],
            "room_w": [-ROOM_HALF_M, WALL_Y_M, -ROOM_HALF_M, top],
            "room_e": [ROOM_HALF_M, WALL_Y_M, ROOM_HALF_M, top],
            "room_n": [-ROOM_HALF_M, top, ROOM_HALF_M, top],
        }},
    }


def run_case(angle_deg: float, offset_m: float, seed: int, out: Path, *, preset_name: str = "wheelchair",
             planner: str | None = None, spare_m: float = 0.15, sets: tuple[str, ...] = ()) -> dict[str, Any]:
    """One case in closed loop (default dynamics); its result.json numbers plus the case. ``sets``:
    ``--set`` pairs over the preset."""
    cfg = configure(preset_name=preset_name, overrides=CliOverrides(planner=planner, sets=sets))
    doc = door_case(angle_deg, offset_m, cfg.robot, spare_m=spare_m, preset_name=preset_name)
    spec = parse_scenario(doc, f"{doc['name']}.yaml")
    res = simulate_scenario(spec, out_dir=out / f"{doc['name']}-{seed}", cfg=cfg, seed=seed, figures=False,
                            overwrite=True)
    r = dict(res.result)
    r.update(angle_deg=angle_deg, offset_m=offset_m, seed=seed)
    return r


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--preset", default="wheelchair")
    ap.add_argument("--planner", default=None)
    ap.add_argument("--seeds", type=int, default=3, help="seeds 0 .. N-1")
    ap.add_argument("--angles", default="0,30,60,90")
    ap.add_argument("--offsets", default="-0.4,0,0.4")
    ap.add_argument("--spare", type=float, default=0.15)
    ap.add_argument("--out", default="")
    ap.add_argument("--set", dest="sets", action="append", default=[],
                    help="section.key=value over the preset")
    a = ap.parse_args()
    out = Path(a.out or tempfile.mkdtemp(prefix="doors-"))
    print("| angle deg | offset m | seed | outcome | time s | longest stall s | traps | wall s |")
    print("|---|---|---|---|---|---|---|---|")
    fails = 0
    for ang in (float(s) for s in a.angles.split(",")):
        for off in (float(s) for s in a.offsets.split(",")):
            for seed in range(a.seeds):
                t0 = time.perf_counter()
                r = run_case(ang, off, seed, out, preset_name=a.preset, planner=a.planner, spare_m=a.spare,
                             sets=tuple(a.sets))
                ok = r["outcome"] == "success" and r["longest_stall_s"] <= STALL_BOUND_S
                fails += not ok
                ttg = r.get("time_to_goal_s")
                print(f"| {ang:g} | {off:+g} | {seed} | {r['outcome']}{'' if ok else ' FAIL'} | "
                      f"{'-' if ttg is None else f'{ttg:.1f}'} | {r['longest_stall_s']:.1f} | "
                      f"{r['trap_count']} | {time.perf_counter() - t0:.1f} |",
                      flush=True)
    print(f"\n{fails} failing case(s); runs in {out}")


if __name__ == "__main__":
    main()
