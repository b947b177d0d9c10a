"""Worlds from files: ROS map_server maps (PGM / PNG with negate, thresholds, modes, origin yaw), BeeSoft
maps, Gazebo SDF worlds, their exact rendering for the ray caster and the contact checker, the culled
clearance and the bucket-grid rays against brute force, start and goal checks, and the Wean Hall example."""

from __future__ import annotations

import gzip
import io
import json
import logging
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from PIL import Image

from gndreplay.config import preset
from gndreplay.errors import ConfigError
from gndreplay.sim import ClosedLoop, simulate_scenario
from gndreplay.sim.closedloop import _World
from gndreplay.sim.geometry import (
    Shapes,
    box_vertices,
    cast,
    footprint_clearance,
    footprint_vertices,
    wall_vertices,
)
from gndreplay.sim.maps import (
    MAX_MAP_PIXELS,
    load_map,
    occupancy_edges,
    read_beesoft_map,
    ros_cell_values,
)
from gndreplay.sim.scenario_file import load_scenario

WHEELCHAIR = preset("wheelchair")
ROOT = Path(__file__).resolve().parents[1]
WEAN_MAP = ROOT.parent / "shared" / "datasets" / "cmu-wean" / "wean.dat.gz"
EAST, NORTH, WEST, SOUTH = 0.0, math.pi / 2, math.pi, -math.pi / 2


def shapes_of(spec: Any, t: float = 0.0) -> Shapes:
    w = _World(spec)
    return w.shapes(t, w.mover_xy)


def ray(shapes: Shapes, origin: tuple[float, float], bearing: float, max_range: float = 50.0) -> float:
    return float(cast(origin, np.array([bearing]), shapes, max_range)[0])


def write_scenario(folder: Path, world: dict[str, Any], **kw: Any) -> Path:
    doc = {"name": "t", "start": [0.0, 0.0, 0.0], "goal": [0.5, 0.0], "time_limit": 5, "world": world, **kw}
    p = folder / "scenario.yaml"
    p.write_text(yaml.safe_dump(doc))
    return p


# ------------------------------------------------------------------------------------------- ROS maps

#: a 10 x 8 pixel room: a one-pixel wall all round, a one-pixel pillar at image row 2 (from the top),
#: column 6; 0 black = occupied, 254 white = free.
ROOM = np.full((8, 10), 254, dtype=np.uint8)
ROOM[0, :] = ROOM[-1, :] = ROOM[:, 0] = ROOM[:, -1] = 0
ROOM[2, 6] = 0


def ros_map(folder: Path, pixels: np.ndarray, *, fmt: str = "PGM", name: str = "room", **keys: Any) -> Path:
    img = folder / f"{name}.{fmt.lower()}"
    Image.fromarray(pixels).save(img, format="PPM" if fmt == "PGM" else fmt)  # Pillow writes PGM as PPM
    doc = {"image": img.name, "resolution": 0.5, "origin": [1.0, -2.0, 0.0], "negate": 0,
           "occupied_thresh": 0.65, "free_thresh": 0.196, **keys}
    p = folder / f"{name}.yaml"
    p.write_text(yaml.safe_dump(doc))
    return p


def map_shapes(path: Path, **kw: Any) -> Shapes:
    return Shapes.build([load_map(path, **kw).edges()], [0], [], [])


@pytest.mark.parametrize("fmt", ["PGM", "PNG"])
def test_a_ros_map_room_ranges_reach_the_cell_edges_exactly(tmp_path: Path, fmt: str) -> None:
    sh = map_shapes(ros_map(tmp_path, ROOM, fmt=fmt))
    # interior cells: columns 1..8, rows 1..6 from the bottom -> x 1.5..5.5, y -1.5..1.5
    o = (3.0, 0.25)
    assert ray(sh, o, EAST) == pytest.approx(2.5, abs=1e-12)
    assert ray(sh, o, WEST) == pytest.approx(1.5, abs=1e-12)
    assert ray(sh, o, SOUTH) == pytest.approx(1.75, abs=1e-12)
    # the pillar: image row 2 from the top = row 5 from the bottom (y 0.5..1.0), column 6 (x 4.0..4.5)
    assert ray(sh, (4.25, -1.0), NORTH) == pytest.approx(1.5, abs=1e-12)
    assert ray(sh, (3.0, 0.75), EAST) == pytest.approx(1.0, abs=1e-12)
    assert ray(sh, (3.0, 0.25), NORTH) == pytest.approx(1.25, abs=1e-12)  # below the pillar's row: the wall


def test_negate_origin_yaw_and_thresholds(tmp_path: Path) -> None:
    plain = map_shapes(ros_map(tmp_path, ROOM, name="plain"))
    negated = map_shapes(ros_map(tmp_path, 254 - ROOM, name="neg", negate=1))
    for b in (EAST, WEST, NORTH, SOUTH, 0.3):
        assert ray(negated, (3.0, 0.25), b) == ray(plain, (3.0, 0.25), b)
    # turned by 90 degrees about the origin (1, -2): the map's +x runs along the world's +y
    yaw = math.pi / 2
    turned = map_shapes(ros_map(tmp_path, ROOM, name="turned", origin=[1.0, -2.0, yaw]))
    u, v = 3.0 - 1.0, 0.25 + 2.0
    o = (1.0 + math.cos(yaw) * u - math.sin(yaw) * v, -2.0 + math.sin(yaw) * u + math.cos(yaw) * v)
    assert ray(turned, o, yaw + EAST) == pytest.approx(2.5, abs=1e-9)
    assert ray(turned, o, yaw + SOUTH) == pytest.approx(1.75, abs=1e-9)
    # a grey wall: p = (255 - 100) / 255 = 0.608 is occupied only below the threshold
    grey = ROOM.copy()
    grey[:, -1] = 100
    east = (ray(map_shapes(ros_map(tmp_path, grey, name=f"g{i}", occupied_thresh=th), unknown=unk),
                (3.0, 0.25), EAST) for i, (th, unk) in enumerate([(0.6, "occupied"), (0.65, "free"),
                                                                   (0.65, "occupied")]))
    assert next(east) == pytest.approx(2.5)  # occupied: p > 0.6
    assert next(east) == math.inf  # unknown (trinary) and free: nothing beyond the map on that side
    assert next(east) == pytest.approx(2.5)  # unknown taken as an obstacle


def test_ros_cell_values_follow_map_server() -> None:
    px = np.array([[[0, 0, 0, 255], [120, 120, 120, 255], [120, 120, 120, 0], [255, 255, 255, 255]]],
                  dtype=np.uint8)
    th = {"negate": False, "occupied_thresh": 0.65, "free_thresh": 0.196}
    # trinary averages all four channels: (0+0+0+255)/4 -> p 0.75 occupied; (360+255)/4 -> p 0.397 unknown
    assert ros_cell_values(px, mode="trinary", **th).tolist() == [[100, -1, -1, 0]]
    # scale averages without alpha: p 1.0 occupied; p 0.529 -> 1 + 98 * ratio; alpha 0 -> unknown
    ratio = ((255 - 120) / 255 - 0.196) / (0.65 - 0.196)
    assert ros_cell_values(px, mode="scale", **th).tolist() == [[100, int(1 + 98 * ratio), -1, 0]]
    # raw: the (truncated) average itself, 255 read as -1
    assert ros_cell_values(px, mode="raw", **th).tolist() == [[0, 120, 120, -1]]
    assert ros_cell_values(px, mode="raw", **{**th, "negate": True}).tolist() == [[-1, 135, 135, 0]]


def test_trinary_and_scale_maps_read_back(tmp_path: Path) -> None:
    grey = ROOM.copy()
    grey[:, -1] = 150  # p 0.41: unknown in trinary (an obstacle by default), free-ish (scale 1..99) in scale
    assert ray(map_shapes(ros_map(tmp_path, grey, name="tri")), (3.0, 0.25), EAST) == pytest.approx(2.5)
    # scale: the grey column is free, the frame beyond the map (unknown: occupied) stops the ray
    assert ray(map_shapes(ros_map(tmp_path, grey, name="sc", mode="scale")), (3.0, 0.25), EAST) == \
        pytest.approx(3.0)
    raw = ROOM.copy()
    raw[ROOM == 0] = 100  # raw 100: occupied
    raw[ROOM == 254] = 0
    assert ray(map_shapes(ros_map(tmp_path, raw, name="raw", mode="raw")), (3.0, 0.25), EAST) == \
        pytest.approx(2.5)


@pytest.mark.parametrize(("change", "says"), [
    ({"resolution": None}, "resolution: missing"),
    ({"resolution": -0.1}, "resolution"),
    ({"origin": [1.0, 2.0]}, "origin"),
    ({"negate": 2}, "negate"),
    ({"mode": "fancy"}, "mode"),
    ({"occupied_thresh": "high"}, "occupied_thresh"),
    ({"image": "missing.pgm"}, "not found"),
])
def test_a_malformed_map_yaml_is_one_line_naming_the_file(tmp_path: Path, change: dict[str, Any],
                                                          says: str) -> None:
    p = ros_map(tmp_path, ROOM)
    doc = yaml.safe_load(p.read_text())
    for k, v in change.items():
        if v is None:
            del doc[k]
        else:
            doc[k] = v
    p.write_text(yaml.safe_dump(doc))
    with pytest.raises(ConfigError) as e:
        load_map(p)
    assert says in str(e.value) and "\n" not in str(e.value)
    assert str(tmp_path) in str(e.value)


def test_truncated_huge_and_odd_images_are_one_line_errors(tmp_path: Path) -> None:
    p = ros_map(tmp_path, ROOM, fmt="PNG")
    img = tmp_path / "room.png"
    data = img.read_bytes()
    img.write_bytes(data[: len(data) // 2])
    with pytest.raises(ConfigError, match=r"room\.png: not a readable map image"):
        load_map(p)
    # a PGM header promising 100000 x 100000 pixels: refused before decoding (no DecompressionBomb warning)
    img.write_bytes(b"P5\n100000 100000\n255\n" + bytes(100))
    with pytest.raises(ConfigError, match=r"room.png: .*pixels") as e:
        load_map(p)
    assert "\n" not in str(e.value)
    side = math.isqrt(MAX_MAP_PIXELS) + 1
    img.write_bytes(f"P5\n{side} {side}\n255\n".encode() + bytes(100))
    with pytest.raises(ConfigError, match=f"{side} x {side} pixels, more than"):
        load_map(p)
    img.write_bytes(b"not an image at all")
    with pytest.raises(ConfigError, match="not a readable map image"):
        load_map(p)
    buf = io.BytesIO()
    Image.fromarray(np.zeros((4, 4), dtype=np.uint16)).save(buf, format="PNG")  # 16-bit grey
    img.write_bytes(buf.getvalue())
    with pytest.raises(ConfigError, match="8-bit"):
        load_map(p)


# ------------------------------------------------------------------------------------------- the edges


def test_edges_merge_runs_and_group_each_component_with_its_holes() -> None:
    occ = np.zeros((7, 9), dtype=bool)
    occ[1:4, 1:4] = True
    occ[2, 2] = False  # a ring: 4 outer and 4 inner merged edges
    occ[5, 6] = occ[6, 7] = True  # two cells touching at a corner: two components
    g = occupancy_edges(occ, 1.0, (0.0, 0.0, 0.0))
    sizes = sorted(np.diff(g.off).tolist())
    assert sizes == [4, 4, 8]
    ring = g.edges[g.off[np.argmax(np.diff(g.off))]:][:8]
    lengths = np.hypot(ring[:, 2] - ring[:, 0], ring[:, 3] - ring[:, 1])
    assert sorted(lengths.tolist()) == [1.0] * 4 + [3.0] * 4
    # occupied on the left: the outer loop turns counter-clockwise (positive area), the hole clockwise
    area = float(np.sum(g.edges[:, 0] * g.edges[:, 3] - g.edges[:, 2] * g.edges[:, 1])) / 2.0
    assert area == occ.sum()


def test_the_edges_are_exactly_the_occupied_cells(tmp_path: Path) -> None:
    rng = np.random.default_rng(5)
    occ = rng.random((30, 40)) < 0.35
    res, ox, oy = 0.25, -3.0, 2.0
    sh = Shapes.build([occupancy_edges(occ, res, (ox, oy, 0.0))], [0], [], [])
    # boundary length = number of occupied / free cell sides (the map's outside is free here)
    p = np.pad(occ, 1)
    sides = int(np.sum(p[1:, :] != p[:-1, :]) + np.sum(p[:, 1:] != p[:, :-1]))
    assert np.sum(np.hypot(sh.edges[:, 2] - sh.edges[:, 0], sh.edges[:, 3] - sh.edges[:, 1])) == \
        pytest.approx(sides * res)
    # a point is inside an obstacle (clearance 0) exactly when its cell is occupied
    for _ in range(400):
        r, c = rng.integers(0, 30), rng.integers(0, 40)
        fx, fy = rng.uniform(0.1, 0.9, 2)
        d = footprint_clearance((ox + (c + fx) * res, oy + (r + fy) * res, 0.0), None, 0.0, sh).distance_m
        assert (d == 0.0) == bool(occ[r, c])


def test_unknown_occupied_closes_the_map_with_a_frame(tmp_path: Path) -> None:
    free = np.full((6, 6), 254, dtype=np.uint8)
    p = ros_map(tmp_path, free)  # no obstacle cell: only the frame beyond the map's edge
    sh = map_shapes(p)
    assert ray(sh, (2.0, 0.0), EAST) == pytest.approx(2.0)  # x 1..4 is the map; the frame starts at 4
    assert ray(map_shapes(p, unknown="free"), (2.0, 0.0), EAST) == math.inf


# ------------------------------------------------------------------------------------------- BeeSoft


def beesoft(values: np.ndarray, res_cm: int = 10) -> str:
    h, w = values.shape
    head = [f"robot_specifications->global_mapsize_x  {w * res_cm}",
            f"robot_specifications->global_mapsize_y  {h * res_cm}",
            f"robot_specifications->resolution {res_cm}", "robot_specifications->autoshifted_x 0",
            "robot_specifications->autoshifted_y 0", "", f"global_map[0]: {w} {h}"]
    return "\n".join(head + [" ".join(f"{v:.3f}" for v in row) for row in values]) + "\n"


def test_a_beesoft_map_reads_p_free_top_line_first_gz_or_not(tmp_path: Path) -> None:
    v = np.ones((4, 5))
    v[0, 1] = 0.0  # the first line is the top row: y 0.3..0.4
    v[3, 4] = -1.0  # unknown, bottom right
    v[2, 2] = 0.4  # P(occupied) 0.6: between the default thresholds (unknown), free below free_thresh
    (tmp_path / "m.dat").write_text(beesoft(v))
    (tmp_path / "m.dat.gz").write_bytes(gzip.compress(beesoft(v).encode()))
    for name in ("m.dat", "m.dat.gz"):
        m = read_beesoft_map(tmp_path / name)
        assert m.resolution_m == 0.1 and m.occupied.shape == (4, 5)
        assert m.occupied[3, 1] and m.occupied[0, 4] and not m.occupied[0, 0]
        assert m.unknown is not None and m.unknown[0, 4] and m.unknown[1, 2] and m.occupied[1, 2]
    assert not read_beesoft_map(tmp_path / "m.dat", free_thresh=0.65).occupied[1, 2]
    assert read_beesoft_map(tmp_path / "m.dat", occupied_thresh=0.5, free_thresh=0.5).occupied[1, 2]
    free = read_beesoft_map(tmp_path / "m.dat", unknown="free")
    assert not free.occupied[0, 4] and not free.occupied[1, 2]
    with pytest.raises(ConfigError, match=r"m\.dat: free_thresh 0.7 is above occupied_thresh 0.65"):
        read_beesoft_map(tmp_path / "m.dat", free_thresh=0.7)


@pytest.mark.parametrize(("text", "says"), [
    ("robot_specifications->resolution 10\nglobal_map[0]: 2 2\n1 1 1\n", "3 map values, expected 2 lines"),
    ("robot_specifications->resolution 10\nglobal_map[0]: 2 1\n1 7\n", "P(free)"),
    ("robot_specifications->resolution 10\nglobal_map[0]: 2 1\n1 x\n", "not a number"),
    ("global_map[0]: 2 1\n1 1\n", "resolution"),
    ("robot_specifications->resolution 10\n1 1\n", "global_map"),
    ("robot_specifications->resolution 10\nglobal_map[0]: 99999 99999\n1\n", "cells"),
])
def test_a_malformed_beesoft_map_is_one_line(tmp_path: Path, text: str, says: str) -> None:
    p = tmp_path / "bad.dat"
    p.write_text(text)
    with pytest.raises(ConfigError, match=r"bad\.dat") as e:
        read_beesoft_map(p)
    assert says in str(e.value) and "\n" not in str(e.value)
    p.with_suffix(".dat.gz").write_bytes(gzip.compress(text.encode())[:-6])
    with pytest.raises(ConfigError, match=r"bad\.dat\.gz"):
        read_beesoft_map(p.with_suffix(".dat.gz"))


# ------------------------------------------------------------------------------------------- SDF

SDF = """<?xml version="1.0"?>
<sdf version="1.7">
  <world name="default">
    <include><uri>model://sun</uri></include>
    <model name="ground"><static>true</static>
      <link name="link"><collision name="c"><geometry><plane><normal>0 0 1</normal></plane></geometry>
      </collision></link></model>
    <model name="shelf"><static>true</static>
      <pose>4 0 0 0 0 1.5707963267948966</pose>
      <link name="link"><pose>1 0 0 0 0 0</pose>
        <collision name="collision"><pose relative_to="link">0 0 0.5 0 0 0</pose>
          <geometry><box><size>2 0.5 1</size></box></geometry></collision>
        <collision name="deco"><geometry><mesh><uri>model://x/m.dae</uri></mesh></geometry></collision>
      </link></model>
    <model name="bin"><static>1</static><pose frame="">0 5 0 0 0 0</pose>
      <link name="l"><collision name="c"><pose>2 0 0 0 0 0</pose>
        <geometry><cylinder><radius>0.3</radius><length>1</length></cylinder></geometry></collision>
      </link></model>
    <model name="ball"><static>true</static><pose degrees="true">-3 0 0 0 0 45</pose>
      <link name="l"><collision name="c"><geometry><sphere><radius>0.5</radius></sphere></geometry>
      </collision></link></model>
    <model name="cart"><pose>0 -5 0 0 0 0</pose>
      <link name="l"><collision name="c"><geometry><box><size>1 1 1</size></box></geometry></collision>
      </link></model>
    <model name="ramp"><static>true</static><pose>0 -8 0 0.3 0 0</pose>
      <link name="l"><collision name="c"><geometry><box><size>1 1 1</size></box></geometry></collision>
      </link></model>
  </world>
</sdf>
"""


def test_an_sdf_world_reads_back_exactly_and_skips_the_rest_with_one_warning(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    (tmp_path / "w.world").write_text(SDF)
    p = write_scenario(tmp_path, {"sdf": "w.world", "walls": {"w": [10.0, -9.0, 10.0, 9.0, 0.0]}},
                       events=[{"at": 1.0, "remove": "bin/l/c"}])
    with caplog.at_level(logging.WARNING, logger="gndreplay.sim.sdf"):
        spec = load_scenario(p)
    ids = [e.id for e in spec.elements]
    assert ids == ["shelf/link/collision", "bin/l/c", "ball/l/c", "w"]
    assert len(spec.world_warnings) == 1 and len(caplog.records) == 1
    for skipped in ("include model://sun", "plane ground/link/c", "mesh shelf/link/deco",
                    "non-static model cart", "roll/pitch ramp"):
        assert skipped in spec.world_warnings[0]
    loop = ClosedLoop(spec, WHEELCHAIR, seed=0)
    next(iter(loop.ticks()))
    assert loop.result()["world_warnings"] == list(spec.world_warnings)  # result.json carries them
    sh = shapes_of(spec)
    # the shelf: model yaw 90 deg turns the link's offset (1, 0) to (0, 1); the box's 2 m runs along y
    assert ray(sh, (0.0, 1.0), EAST) == pytest.approx(4.0 - 0.25, abs=1e-12)
    assert ray(sh, (4.0, 3.0), SOUTH) == pytest.approx(1.0, abs=1e-12)
    # the bin: a circle of 0.3 m at (2, 5), seen from 5 m away
    assert ray(sh, (2.0, 0.0), NORTH) == pytest.approx(5.0 - 0.3, abs=1e-12)
    assert ray(sh, (-3.0, 4.0), SOUTH) == pytest.approx(4.0 - 0.5, abs=1e-12)  # the ball at (-3, 0)
    assert ray(sh, (0.0, -5.0), WEST) == math.inf  # the cart is not static
    assert ray(shapes_of(spec, 2.0), (2.0, 0.0), NORTH) == math.inf  # the bin removed at t = 1


@pytest.mark.parametrize(("text", "says"), [
    ("<sdf><world name='w'><model name='m'><static>true</static><link name='l'><collision name='c'>"
     "<geometry><box><size>1 x 1</size></box></geometry></collision></link></model></world></sdf>", "size"),
    ("<sdf><world name='w'><model name='m'><static>true</static><link name='l'><collision name='c'>"
     "<geometry><box/></geometry></collision></link></model></world></sdf>", "without <size>"),
    ("<robot name='r'/>", "not an SDF file"),
    ("<sdf><world", "not valid XML"),
    ('<!DOCTYPE sdf [<!ENTITY a "aaaa">]><sdf/>', "document type"),
])
def test_a_malformed_sdf_is_one_line_naming_the_file(tmp_path: Path, text: str, says: str) -> None:
    (tmp_path / "w.sdf").write_text(text)
    p = write_scenario(tmp_path, {"sdf": "w.sdf"})
    with pytest.raises(ConfigError) as e:
        load_scenario(p)
    msg = str(e.value)
    assert "scenario.yaml: world.sdf:" in msg and "w.sdf" in msg and says in msg and "\n" not in msg


# ------------------------------------------------------------------------------------------- scenarios


def test_a_map_mixes_with_yaml_elements_and_paths_are_relative_to_the_scenario(tmp_path: Path) -> None:
    (tmp_path / "maps").mkdir()
    ros_map(tmp_path / "maps", ROOM)
    sub = tmp_path / "scen"
    sub.mkdir()
    p = write_scenario(sub, {"map": {"file": "../maps/room.yaml", "unknown": "free"},
                             "boxes": {"crate": [3.0, -1.0, 0.4, 0.4, 0.0]}},
                       start=[2.5, 0.25, 0.0], goal=[4.0, -0.5], events=[{"at": 1.0, "remove": "map"}])
    spec = load_scenario(p)
    assert [e.kind for e in spec.elements] == ["map", "box"]
    assert ray(shapes_of(spec), (3.0, 0.25), EAST) == pytest.approx(2.5)
    assert ray(shapes_of(spec), (3.0, 0.25), SOUTH) == pytest.approx(1.05)  # the crate's top face
    assert ray(shapes_of(spec, 2.0), (3.0, 0.25), EAST) == math.inf  # the map removed
    ClosedLoop(spec, WHEELCHAIR, seed=0)  # start and goal are free
    with pytest.raises(ConfigError, match=r"scenario.yaml: world.map: .*room.yaml"):
        load_scenario(write_scenario(sub, {"map": "room.yaml"}))
    with pytest.raises(ConfigError, match=r"world.map.unknown: expected one of occupied, free"):
        load_scenario(write_scenario(sub, {"map": {"file": "../maps/room.yaml", "unknown": "maybe"}}))


def test_start_in_collision_and_goal_in_an_obstacle_unless_expected_unreachable(tmp_path: Path) -> None:
    world = {"boxes": {"crate": [0.0, 0.0, 0.5, 0.5, 0.0]}}
    p = write_scenario(tmp_path, world, goal=[5.0, 0.0])
    with pytest.raises(ConfigError) as e:
        ClosedLoop(load_scenario(p), WHEELCHAIR, seed=0)
    assert str(e.value).startswith(f"{p}: start:") and "'crate'" in str(e.value)
    assert "\n" not in str(e.value)
    p = write_scenario(tmp_path, world, start=[-3.0, 0.0, 0.0], goal=[0.1, 0.1])
    with pytest.raises(ConfigError, match=r"scenario.yaml: goal: \(0.1, 0.1\) is inside 'crate'"):
        ClosedLoop(load_scenario(p), WHEELCHAIR, seed=0)
    # a start that touches a wall (footprint front edge exactly on it)
    front = WHEELCHAIR.robot.front_m
    p = write_scenario(tmp_path, {"walls": {"w": [front, -2.0, front, 2.0, 0.0]}}, goal=[-3.0, 0.0])
    with pytest.raises(ConfigError, match=r"start: .* touches 'w'"):
        ClosedLoop(load_scenario(p), WHEELCHAIR, seed=0)
    for start, goal in (([0.0, 0.0, 0.0], [5.0, 0.0]), ([-3.0, 0.0, 0.0], [0.1, 0.1])):
        ok = load_scenario(write_scenario(tmp_path, world, start=start, goal=goal, expect="unreachable"))
        ClosedLoop(ok, WHEELCHAIR, seed=0)
    # a goal in a box removed later is reachable then
    later = write_scenario(tmp_path, world, start=[-3.0, 0.0, 0.0], goal=[0.1, 0.1],
                           events=[{"at": 5.0, "remove": "crate"}])
    ClosedLoop(load_scenario(later), WHEELCHAIR, seed=0)
    with pytest.raises(ConfigError, match="expect: expected one of reachable, unreachable"):
        load_scenario(write_scenario(tmp_path, world, expect="maybe"))


# ------------------------------------------------------------------------------------------- speed-ups


def random_world(rng: np.random.Generator) -> Shapes:
    polys = [box_vertices(*rng.uniform(0, 20, 2), *rng.uniform(0.05, 3, 2), rng.uniform(-3, 3))
             for _ in range(rng.integers(1, 120))]
    polys += [wall_vertices(*rng.uniform(0, 20, 4), rng.choice([0.0, 0.1]))
              for _ in range(rng.integers(0, 20))]
    cells = rng.random((24, 24)) < 0.2
    groups = occupancy_edges(cells, 0.5, (float(rng.uniform(-2, 2)), float(rng.uniform(-2, 2)), 0.0))
    circles = [(*rng.uniform(0, 20, 2), 0.3) for _ in range(3)]
    return Shapes.build([*polys, groups], list(range(len(polys) + 1)), circles, [900, 901, 902])


def test_grid_rays_and_culled_clearance_equal_brute_force_bit_for_bit() -> None:
    rng = np.random.default_rng(11)
    fp = footprint_vertices(0.6, 0.3, 0.7)
    for _ in range(12):
        sh = random_world(rng)
        for k in range(40):
            o = (float(rng.uniform(-4, 24)), float(rng.uniform(-4, 24)))
            if k % 4 == 0:  # on cell corners of the map
                o = (float(rng.integers(-4, 24)) * 0.5, float(rng.integers(-4, 24)) * 0.5)
            angles = np.linspace(-math.pi, math.pi, 181) + rng.uniform(-1, 1)
            if k % 5 == 0:
                angles = np.array([EAST, NORTH, WEST, SOUTH, math.pi / 4, -3 * math.pi / 4])
            mr = float(rng.uniform(0.5, 40.0))
            assert np.array_equal(cast(o, angles, sh, mr, grid=True), cast(o, angles, sh, mr, grid=False))
            pose = (*o, float(rng.uniform(-3, 3)))
            for local in (fp, None):
                assert footprint_clearance(pose, local, 0.4, sh, cull=True) == \
                    footprint_clearance(pose, local, 0.4, sh, cull=False)


# ------------------------------------------------------------------------------------------- Wean Hall

needs_wean = pytest.mark.skipif(not WEAN_MAP.is_file(), reason="needs ../shared/datasets/cmu-wean")


@needs_wean
def test_the_wean_hall_example_parses_and_a_short_run_drives(tmp_path: Path) -> None:
    spec = load_scenario(ROOT / "examples" / "wean_hall.yaml")
    (m,) = spec.elements
    assert m.kind == "map" and m.groups is not None and m.groups.edges.shape[0] > 1000
    assert m.grid is not None and m.grid.occupied.shape == (800, 800)
    for name in ("wheelchair", "xr4000"):
        ClosedLoop(spec, preset(name), seed=0)  # start and goal are free for the footprint
    out = simulate_scenario(spec, out_dir=tmp_path / "wean", seed=0, time_limit_s=20.0, figures=False)
    result = json.loads((tmp_path / "wean" / "result.json").read_text())
    assert out.outcome == result["outcome"] == "timeout" and out.collision is None
    assert out.path_length_m > 0.5 and result["min_clearance_m"] > 0.0
