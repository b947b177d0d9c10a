"""Gazebo / SDF worlds as closed-loop worlds: the box, cylinder and sphere collision geometry of static
models, seen from above.

A collision's pose in the world is its model's pose (nested models composed), then its link's, then its
own, each in its parent's frame: the default frame of SDF 1.6 (no ``frame`` attribute, or ``frame=''``)
and of SDF 1.7 and later (no ``relative_to``, or one naming the parent). Only x, y and yaw are used (a
pose may also give ``degrees="true"``); z is ignored, so every shape is an obstacle whatever its height.
A box becomes a rectangle (its size's x and y), a cylinder or a sphere a circle of its radius. Skipped,
and named together in one warning: models that are not static, meshes, planes, heightmaps and every other
shape, ``<include>``, shapes turned by a roll or a pitch, and poses relative to other frames.

Element ids are the names along the way, ``model/link/collision`` (nested models first), so scenario
events can remove them. The file is read as a user file (bounded in size); a document type declaration
(entities) is refused, SDF has none.
"""

from __future__ import annotations

import logging
import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from .. import detmath as dm
from ..errors import ConfigError, one_line
from ..io.userfile import brief, read_text
from .geometry import box_vertices

__all__ = ["MAX_SDF_BYTES", "SdfShape", "SdfWorld", "read_sdf_world"]

log = logging.getLogger(__name__)
F64 = NDArray[np.float64]
#: Largest SDF file read, most shapes kept, longest name path (an element id) and bound of its numbers.
MAX_SDF_BYTES = 16 * 1024 * 1024
MAX_SDF_SHAPES = 10_000
MAX_SDF_ID_CHARS = 100
MAX_SDF_COORD_M = 1e5
_TILT_RAD = 1e-9
_Pose = tuple[float, float, float]


@dataclass(frozen=True, slots=True, eq=False)
class SdfShape:
    """One collision shape: a rectangle (``vertices`` ``(4, 2)``) or a circle ``(cx, cy, r)``."""

    id: str
    vertices: F64 | None = None
    circle: tuple[float, float, float] | None = None


@dataclass(frozen=True, slots=True, eq=False)
class SdfWorld:
    """The shapes read and what was skipped (one entry per skipped thing, ``"mesh a/b/c"``)."""

    shapes: tuple[SdfShape, ...]
    skipped: tuple[str, ...]

    def warning(self, source: str) -> str | None:
        """The one warning line naming what was skipped (None when nothing was)."""
        if not self.skipped:
            return None
        shown = ", ".join(self.skipped[:8]) + (f", ... ({len(self.skipped)} in all)" if len(self.skipped) > 8
                                               else "")
        return (f"{source}: skipped (only static box, cylinder and sphere collisions without roll or pitch "
                f"are read): {shown}")


def _compose(a: _Pose, b: _Pose) -> _Pose:
    c, s = dm.cos(a[2]), dm.sin(a[2])
    return a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], a[2] + b[2]


class _Reader:
    def __init__(self, source: str) -> None:
        self.source = source
        self.shapes: list[SdfShape] = []
        self.skipped: list[str] = []
        self.ids: set[str] = set()

    def err(self, where: str, message: str) -> ConfigError:
        return ConfigError(f"{self.source}: {where}: {message}")

    def numbers(self, node: ET.Element, where: str, count: int) -> list[float]:
        text = (node.text or "").split()
        if len(text) != count:
            raise self.err(where, f"expected {count} numbers, got {brief(node.text)}")
        try:
            out = [float(t) for t in text]
        except ValueError:
            raise self.err(where, f"expected {count} numbers, got {brief(node.text)}") from None
        if not all(math.isfinite(v) and abs(v) <= MAX_SDF_COORD_M for v in out):
            raise self.err(where, f"numbers must be finite and within +-{MAX_SDF_COORD_M:g}, got "
                                  f"{brief(node.text)}")
        return out

    def pose(self, node: ET.Element, where: str, parents: tuple[str, ...]) -> _Pose | None:
        """The node's ``<pose>`` in its parent's frame (None, with the reason recorded, when it is relative
        to another frame or tilted)."""
        p = node.find("pose")
        if p is None:
            return (0.0, 0.0, 0.0)
        frame = p.get("relative_to", p.get("frame", ""))
        if frame not in ("", *parents):
            self.skipped.append(f"pose relative to {frame} {where}")
            return None
        if p.get("rotation_format", "euler_rpy") != "euler_rpy":
            self.skipped.append(f"{p.get('rotation_format')} pose {where}")
            return None
        x, y, _z, roll, pitch, yaw = self.numbers(p, f"{where}: pose", 6)
        if p.get("degrees", "false").strip().lower() in ("true", "1"):
            roll, pitch, yaw = math.radians(roll), math.radians(pitch), math.radians(yaw)
        if abs(roll) > _TILT_RAD or abs(pitch) > _TILT_RAD:
            self.skipped.append(f"roll/pitch {where}")
            return None
        return (x, y, yaw)

    def model(self, m: ET.Element, parent: _Pose, prefix: str, static: bool, parent_names: tuple[str, ...]
              ) -> None:
        name = self.name(m, prefix)
        own = m.findtext("static", "").strip().lower() in ("true", "1")
        pose = self.pose(m, name, parent_names)
        if pose is None:
            return
        at = _compose(parent, pose)
        for inc in m.findall("include"):
            self.skipped.append(f"include {inc.findtext('uri', '?').strip()}")
        for sub in m.findall("model"):
            self.model(sub, at, name + "/", static or own, ("__model__", m.get("name", "")))
        if not (static or own):
            if m.findall("link"):
                self.skipped.append(f"non-static model {name}")
            return
        for link in m.findall("link"):
            lname = self.name(link, name + "/")
            lpose = self.pose(link, lname, ("__model__", m.get("name", "")))
            if lpose is None:
                continue
            lat = _compose(at, lpose)
            for col in link.findall("collision"):
                self.collision(col, lat, lname, link.get("name", ""))

    def name(self, node: ET.Element, prefix: str) -> str:
        n = node.get("name")
        if not n:
            raise self.err(prefix.rstrip("/") or node.tag, f"a <{node.tag}> without a name")
        return prefix + n

    def collision(self, col: ET.Element, parent: _Pose, prefix: str, link_name: str) -> None:
        cid = self.name(col, prefix + "/")
        pose = self.pose(col, cid, (link_name,))
        if pose is None:
            return
        geom = col.find("geometry")
        shape = None if geom is None else next(iter(geom), None)
        if shape is None:
            self.skipped.append(f"empty geometry {cid}")
            return
        if shape.tag not in ("box", "cylinder", "sphere"):
            self.skipped.append(f"{shape.tag} {cid}")
            return
        if len(cid) > MAX_SDF_ID_CHARS:
            raise self.err(cid[:40] + "...", f"a name path of more than {MAX_SDF_ID_CHARS} characters")
        if cid in self.ids:
            raise self.err(cid, "a second collision of that name")
        if len(self.shapes) >= MAX_SDF_SHAPES:
            raise self.err(cid, f"more than the {MAX_SDF_SHAPES:,} shapes a world may have")
        x, y, yaw = _compose(parent, pose)
        if shape.tag == "box":
            size = shape.find("size")
            if size is None:
                raise self.err(cid, "a box without <size>")
            sx, sy, _ = self.numbers(size, f"{cid}: size", 3)
            if sx <= 0.0 or sy <= 0.0:
                raise self.err(cid, f"box size must be > 0, got {brief(size.text)}")
            self.shapes.append(SdfShape(cid, vertices=box_vertices(x, y, sx, sy, yaw)))
        else:
            rad = shape.find("radius")
            if rad is None:
                raise self.err(cid, f"a {shape.tag} without <radius>")
            (r,) = self.numbers(rad, f"{cid}: radius", 1)
            if r <= 0.0:
                raise self.err(cid, f"radius must be > 0, got {r:g}")
            self.shapes.append(SdfShape(cid, circle=(x, y, r)))
        self.ids.add(cid)


def read_sdf_world(path: Path) -> SdfWorld:
    """The shapes of an SDF world file (``<sdf><world>`` or ``<sdf><model>``); see the module docstring.
    What was skipped is logged as one warning and returned.

    Raises:
        ConfigError: not SDF, malformed XML, a bad number or a missing size; one line naming the file.
    """
    path = Path(path)
    text = read_text(path, "SDF world", MAX_SDF_BYTES)
    if "<!DOCTYPE" in text or "<!ENTITY" in text:
        raise ConfigError(f"{path}: a document type declaration (entities); SDF files have none")
    try:
        root = ET.fromstring(text)
    except ET.ParseError as e:
        raise ConfigError(f"{path}: not valid XML: {one_line(e, 200)}") from None
    if root.tag != "sdf":
        raise ConfigError(f"{path}: not an SDF file (the root element is <{brief(root.tag)}>, not <sdf>)")
    r = _Reader(str(path))
    worlds = root.findall("world")
    models = root.findall("model")
    if not worlds and not models:
        raise ConfigError(f"{path}: no <world> or <model> in the SDF file")
    origin = (0.0, 0.0, 0.0)
    for w in worlds:
        for inc in w.findall("include"):
            r.skipped.append(f"include {inc.findtext('uri', '?').strip()}")
        for m in w.findall("model"):
            r.model(m, origin, "", False, ("world",))
    for m in models:
        r.model(m, origin, "", False, ("world",))
    out = SdfWorld(tuple(r.shapes), tuple(r.skipped))
    msg = out.warning(str(path))
    if msg is not None:
        log.warning("%s", msg)
    return out
