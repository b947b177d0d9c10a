"""Occupancy-grid maps as closed-loop worlds: ROS map_server maps (a YAML file and a PGM / PNG image) and
CMU BeeSoft ``.dat[.gz]`` maps, rendered exactly as the boundaries of their occupied cells.

ROS maps follow ROS1 map_server's image loader: a pixel's colour average (over every channel in trinary
mode or without alpha, else over all but the alpha channel), inverted by ``negate``, gives
``p = (255 - average) / 255``; the cell is occupied (100) when ``p > occupied_thresh``, free (0) when
``p < free_thresh``, else unknown (-1) in trinary mode or where the last channel is 0, else the scale
mode's 1..99. ``raw`` mode takes the average (truncated) as the value itself. Image row 0 is the top of
the map; cell (col i, row j from the bottom) spans ``[i, i + 1] x [j, j + 1]`` cells from ``origin``'s
(x, y), turned by its yaw.

The simulator's world is binary: a cell is an obstacle when its value is 100 (raw: 100 to 254), unknown
when -1 (raw: 255), free otherwise. Unknown cells, and the ground beyond the map, are obstacles with
``unknown: occupied`` (the default: a one-cell frame closes the map) and free with ``unknown: free``.

The occupied cells become their boundary edges, merged along straight runs and grouped per 4-connected
component (its outer loop and its holes together), so the even-odd inside test of
:mod:`.geometry` is the component's: a few vectorised passes over the grid, no loop over cells.
"""

from __future__ import annotations

import io
import math
import warnings
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from .. import detmath as dm
from ..errors import ConfigError, one_line
from ..io.userfile import brief, check_number, load_yaml, read_bytes
from .geometry import EdgeGroups

__all__ = [
    "MAP_MODES",
    "MAX_MAP_BYTES",
    "MAX_MAP_PIXELS",
    "MAX_MAP_TEXT_BYTES",
    "OccupancyMap",
    "load_map",
    "occupancy_edges",
    "read_beesoft_map",
    "read_ros_map",
]

F64 = NDArray[np.float64]
BoolGrid = NDArray[np.bool_]
#: Largest map: pixels (cells) of the image or grid, bytes of a map file or image, and bytes of a BeeSoft
#: map's text once decompressed (a 16 Mpx map is 400 m across at 10 cm; beyond it a map is a mistake, or a
#: decompression bomb).
MAX_MAP_PIXELS = 16 * 1024 * 1024
MAX_MAP_BYTES = 64 * 1024 * 1024
MAX_MAP_TEXT_BYTES = 256 * 1024 * 1024
MAX_MAP_YAML_BYTES = 64 * 1024
MAX_RESOLUTION_M = 100.0
MAX_ORIGIN_M = 1e5
MAP_MODES = ("trinary", "scale", "raw")
#: BeeSoft maps store P(free); with p = 1 - value a cell is occupied when p exceeds the first, free when p
#: is below the second, unknown between (map_server's defaults; a scenario may set its own).
BEESOFT_OCCUPIED_THRESH = 0.65
BEESOFT_FREE_THRESH = 0.196
_ROS_KEYS = ("image", "resolution", "origin", "negate", "occupied_thresh", "free_thresh")
_HEADER_LINES = 100

Unknown = Literal["occupied", "free"]


@dataclass(frozen=True, slots=True, eq=False)
class OccupancyMap:
    """A binary occupancy grid placed in the world.

    Attributes:
        occupied: ``(H, W)`` obstacle cells, row 0 at the bottom (the image's last row).
        resolution_m: cell size.
        origin: ``(x, y, yaw)`` of the outer corner of cell (0, 0) [m, m, rad].
        frame: a one-cell obstacle frame closes the map (the ground beyond it is unknown = occupied).
        source: the map file (for errors and reports).
        unknown: ``(H, W)`` the cells the map does not know (drawn apart from the obstacles).
        warnings: what was read but ignored (one line each).
    """

    occupied: BoolGrid
    resolution_m: float
    origin: tuple[float, float, float]
    frame: bool
    source: str
    unknown: BoolGrid | None = None
    warnings: tuple[str, ...] = ()

    def edges(self) -> EdgeGroups:
        """The occupied cells' boundary (:func:`occupancy_edges`)."""
        return occupancy_edges(self.occupied, self.resolution_m, self.origin, frame=self.frame)

    def to_world(self, u: F64, v: F64) -> tuple[F64, F64]:
        """World (x, y) of grid coordinates in cells (``u`` along a row, ``v`` up the columns)."""
        ox, oy, yaw = self.origin
        return _to_world(u, v, self.resolution_m, ox, oy, yaw)


def _to_world(u: F64, v: F64, res: float, ox: float, oy: float, yaw: float) -> tuple[F64, F64]:
    if yaw == 0.0:
        return ox + u * res, oy + v * res
    c, s = dm.cos(yaw), dm.sin(yaw)
    return ox + c * (u * res) - s * (v * res), oy + s * (u * res) + c * (v * res)


# --------------------------------------------------------------------------------------------- edges


def _runs(t: NDArray[np.int8]) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.intp]]:
    """Maximal runs of equal non-zero values along each row of ``t`` (whose first and last columns are 0):
    (row, first column, last column) of each, in row-major order."""
    nz = t != 0
    start = nz.copy()
    start[:, 1:] &= t[:, 1:] != t[:, :-1]
    end = nz.copy()
    end[:, :-1] &= t[:, :-1] != t[:, 1:]
    r, c0 = np.nonzero(start)
    _, c1 = np.nonzero(end)
    return r, c0, c1


def occupancy_edges(occupied: BoolGrid, resolution_m: float, origin: tuple[float, float, float], *,
                    frame: bool = False) -> EdgeGroups:
    """The boundary of the occupied cells as edges merged along straight runs, grouped per 4-connected
    component (outer loop and holes; occupied on the left of each edge, so outer loops turn
    counter-clockwise).

    Args:
        occupied: ``(H, W)``, row 0 at the bottom.
        resolution_m: cell size; origin: ``(x, y, yaw)`` of cell (0, 0)'s outer corner.
        frame: add a one-cell occupied frame around the grid (outside ``origin``'s extent by one cell).
    """
    from scipy import ndimage

    occ = np.asarray(occupied, dtype=bool)
    shift = 1 if frame else 0
    if frame:
        occ = np.pad(occ, 1, constant_values=True)
    p = np.pad(occ, 1, constant_values=False)  # cell (r, c) of p spans [c, c+1] x [r, r+1] in p's units
    labels, _ = ndimage.label(p)  # 4-connected (the default cross)
    # horizontal edges on the line y = r + 1 between p[r] and p[r + 1]: +1 occupied below, -1 above
    below, above = p[:-1, :], p[1:, :]
    th = below.astype(np.int8) - above.astype(np.int8)
    hr, h0, h1 = _runs(th)
    hdir = th[hr, h0]
    h_lab = np.where(hdir > 0, labels[hr, h0], labels[hr + 1, h0])
    hy = (hr + 1).astype(np.float64)
    # occupied on the left: below -> run towards -x, above -> towards +x
    hx_a = np.where(hdir > 0, h1 + 1, h0).astype(np.float64)
    hx_b = np.where(hdir > 0, h0, h1 + 1).astype(np.float64)
    # vertical edges on the line x = c + 1 between p[:, c] and p[:, c + 1]: +1 occupied left, -1 right
    left, right = p[:, :-1], p[:, 1:]
    tv = (left.astype(np.int8) - right.astype(np.int8)).T  # rows = the vertical lines
    vc, v0, v1 = _runs(tv)
    vdir = tv[vc, v0]
    v_lab = np.where(vdir > 0, labels[v0, vc], labels[v0, vc + 1])
    vx = (vc + 1).astype(np.float64)
    vy_a = np.where(vdir > 0, v0, v1 + 1).astype(np.float64)
    vy_b = np.where(vdir > 0, v1 + 1, v0).astype(np.float64)
    ua = np.concatenate([hx_a, vx]) - (1 + shift)
    va = np.concatenate([hy, vy_a]) - (1 + shift)
    ub = np.concatenate([hx_b, vx]) - (1 + shift)
    vb = np.concatenate([hy, vy_b]) - (1 + shift)
    lab = np.concatenate([h_lab, v_lab])
    order = np.argsort(lab, kind="stable")
    ox, oy, yaw = origin
    xa, ya = _to_world(ua[order], va[order], resolution_m, ox, oy, yaw)
    xb, yb = _to_world(ub[order], vb[order], resolution_m, ox, oy, yaw)
    counts = np.bincount(lab, minlength=int(labels.max()) + 1)[1:]
    off = np.concatenate([[0], np.cumsum(counts[counts > 0])]).astype(np.int64)
    return EdgeGroups(np.column_stack([xa, ya, xb, yb]), off)


# --------------------------------------------------------------------------------------------- reading


def load_map(path: Path, *, unknown: Unknown = "occupied", occupied_thresh: float | None = None,
             free_thresh: float | None = None) -> OccupancyMap:
    """A ROS map (``.yaml`` / ``.yml``) or a BeeSoft map (``.dat``, ``.dat.gz``) by its name.

    Args:
        unknown: what unknown cells and the ground beyond the map are.
        occupied_thresh, free_thresh: a BeeSoft map's thresholds on P(occupied) (default
            BEESOFT_OCCUPIED_THRESH, BEESOFT_FREE_THRESH); a ROS map's are in its YAML file.

    Raises:
        ConfigError: one line naming the file.
    """
    path = Path(path)
    name = path.name.lower()
    if name.endswith((".yaml", ".yml")):
        if occupied_thresh is not None or free_thresh is not None:
            raise ConfigError(f"{path}: a ROS map's occupied_thresh and free_thresh are its YAML file's own")
        return read_ros_map(path, unknown=unknown)
    if name.endswith((".dat", ".dat.gz")):
        return read_beesoft_map(path, unknown=unknown, occupied_thresh=occupied_thresh,
                                free_thresh=free_thresh)
    raise ConfigError(f"{path}: not a map file (a ROS map's .yaml, or a BeeSoft .dat / .dat.gz)")


def _flag(v: Any, where: str) -> bool:
    """``negate``: 0 / 1 (as map_server reads it) or a boolean."""
    if isinstance(v, bool):
        return v
    if isinstance(v, int) and v in (0, 1):
        return bool(v)
    raise ConfigError(f"{where}: expected 0 or 1, got {brief(v)}")


def read_ros_map(path: Path, *, unknown: Unknown = "occupied") -> OccupancyMap:
    """A ROS map_server map: the YAML file (``image``, ``resolution``, ``origin`` [x, y, yaw], ``negate``,
    ``occupied_thresh``, ``free_thresh``, optional ``mode``) and its image (PGM, PNG, ... decoded by
    Pillow; a path relative to the YAML file's folder). See the module docstring for the cell values.

    Raises:
        ConfigError: a missing or bad key, an unreadable, truncated or too large image; one line naming
            the file.
    """
    path = Path(path)
    doc = load_yaml(path, "map file", MAX_MAP_YAML_BYTES)
    if not isinstance(doc, dict):
        raise ConfigError(f"{path}: expected a mapping of map keys ({', '.join(_ROS_KEYS)}), got "
                          f"{brief(doc)}")
    for k in _ROS_KEYS:
        if k not in doc:
            raise ConfigError(f"{path}: {k}: missing (a map file has {', '.join(_ROS_KEYS)})")
    ignored = [str(k) for k in doc if k not in (*_ROS_KEYS, "mode")]
    image = doc["image"]
    if not isinstance(image, str) or not image or "\0" in image:
        raise ConfigError(f"{path}: image: expected a file name, got {brief(image)}")
    res = check_number(doc["resolution"], f"{path}: resolution", 0.0, MAX_RESOLUTION_M)
    if res <= 0.0:
        raise ConfigError(f"{path}: resolution: must be > 0, got {res:g}")
    origin = doc["origin"]
    if not isinstance(origin, list) or len(origin) != 3:
        raise ConfigError(f"{path}: origin: expected [x, y, yaw], got {brief(origin)}")
    ox = check_number(origin[0], f"{path}: origin[0]", -MAX_ORIGIN_M, MAX_ORIGIN_M)
    oy = check_number(origin[1], f"{path}: origin[1]", -MAX_ORIGIN_M, MAX_ORIGIN_M)
    yaw = check_number(origin[2], f"{path}: origin[2]", -2.0 * math.pi, 2.0 * math.pi)
    negate = _flag(doc["negate"], f"{path}: negate")
    occ_th = check_number(doc["occupied_thresh"], f"{path}: occupied_thresh", 0.0, 1.0)
    free_th = check_number(doc["free_thresh"], f"{path}: free_thresh", 0.0, 1.0)
    mode = doc.get("mode", "trinary")
    if mode not in MAP_MODES:
        raise ConfigError(f"{path}: mode: expected one of {', '.join(MAP_MODES)}, got {brief(mode)}")
    img_path = path.parent / image
    pixels = _decode_image(img_path, read_bytes(img_path, "map image", MAX_MAP_BYTES))
    value = ros_cell_values(pixels, mode=mode, negate=negate, occupied_thresh=occ_th, free_thresh=free_th)
    occupied = (value >= 100) | ((value == -1) & (unknown == "occupied"))
    notes = (f"{path}: ignored keys {', '.join(sorted(ignored))}",) if ignored else ()
    return OccupancyMap(np.ascontiguousarray(occupied[::-1]), res, (ox, oy, yaw), unknown == "occupied",
                        str(path), np.ascontiguousarray(value[::-1] == -1), notes)


def _decode_image(path: Path, data: bytes) -> NDArray[np.uint8]:
    """``(H, W, C)`` 8-bit channels of an image (C = 1 grey, 2 grey + alpha, 3 RGB, 4 RGBA), its pixel
    count checked against MAX_MAP_PIXELS before anything is decoded."""
    from PIL import Image

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", Image.DecompressionBombWarning)
        try:
            im: Image.Image = Image.open(io.BytesIO(data))
            w, h = im.size
            if w * h > MAX_MAP_PIXELS:
                raise ConfigError(f"{path}: a map image of {w} x {h} pixels, more than the "
                                  f"{MAX_MAP_PIXELS:,} a map may have")
            if w == 0 or h == 0:
                raise ConfigError(f"{path}: an empty map image ({w} x {h} pixels)")
            im.load()
        except Image.DecompressionBombError:
            raise ConfigError(f"{path}: a map image of more than {MAX_MAP_PIXELS:,} pixels") from None
        except (OSError, SyntaxError, ValueError, EOFError, MemoryError) as e:
            raise ConfigError(f"{path}: not a readable map image: {one_line(e, 200)}") from None
    if im.mode == "1":
        im = im.convert("L")
    elif im.mode in ("P", "PA"):
        im = im.convert("RGBA" if im.mode == "PA" or "transparency" in im.info else "RGB")
    if im.mode not in ("L", "LA", "RGB", "RGBA"):
        raise ConfigError(f"{path}: a {im.mode} image; map images are 8-bit grey or colour (with alpha)")
    a = np.asarray(im, dtype=np.uint8)
    return a[:, :, None] if a.ndim == 2 else a


def ros_cell_values(pixels: NDArray[np.uint8], *, mode: str, negate: bool, occupied_thresh: float,
                    free_thresh: float) -> NDArray[np.int16]:
    """ROS1 map_server's occupancy values of ``(H, W, C)`` pixels (image rows, top first): 100, 0, -1,
    1..99 (scale) or, in raw mode, the truncated average 0..255 with 255 as -1 (as the int8 it is stored
    in reads)."""
    n = pixels.shape[2]
    has_alpha = n in (2, 4)
    avg_channels = n if (mode == "trinary" or not has_alpha) else n - 1
    avg = pixels[:, :, :avg_channels].sum(axis=2, dtype=np.int64) / float(avg_channels)
    alpha = np.full(avg.shape, 1.0) if n == 1 else pixels[:, :, n - 1].astype(np.float64)
    if negate:
        avg = 255.0 - avg
    if mode == "raw":
        v = np.floor(avg).astype(np.int16)
        return np.where(v == 255, np.int16(-1), v).astype(np.int16)
    occ = (255.0 - avg) / 255.0
    out = np.where(occ > occupied_thresh, 100, 0).astype(np.int16)
    between = (occ <= occupied_thresh) & ~(occ < free_thresh)
    unknown = between & ((mode == "trinary") | (alpha < 1.0))
    scaled = between & ~unknown
    if free_thresh != occupied_thresh:
        ratio = (occ - free_thresh) / (occupied_thresh - free_thresh)
        out[scaled] = (1.0 + 98.0 * ratio[scaled]).astype(np.int16)
    out[unknown] = -1
    return out


def read_beesoft_map(path: Path, *, unknown: Unknown = "occupied", occupied_thresh: float | None = None,
                     free_thresh: float | None = None) -> OccupancyMap:
    """A CMU BeeSoft map (``.dat``, or gzip-compressed ``.dat.gz``, recognised by content): header lines
    ``robot_specifications->KEY VALUE`` (``resolution`` in cm), then ``global_map[0]: W H`` and H lines of
    W values, each P(free) in [0, 1] or negative for unknown. Line k is the row at ``y = (H - 1 - k) *
    resolution``, value i the column at ``x = i * resolution`` (the first line is the top, as in an image);
    with ``p = 1 - value``, as a ROS map in trinary mode: occupied when ``p > occupied_thresh``, free when
    ``p < free_thresh``, else unknown (the defaults are map_server's, 0.65 and 0.196: a cell the map is not
    sure of is unknown, which ``unknown`` makes an obstacle or free ground).

    Raises:
        ConfigError: a missing header, a bad count or value, a too large map; one line naming the file.
    """
    path = Path(path)
    thresh = BEESOFT_OCCUPIED_THRESH if occupied_thresh is None else occupied_thresh
    free_th = BEESOFT_FREE_THRESH if free_thresh is None else free_thresh
    if free_th > thresh:
        raise ConfigError(f"{path}: free_thresh {free_th:g} is above occupied_thresh {thresh:g}")
    data = read_bytes(path, "map file", MAX_MAP_BYTES)
    if data[:2] == b"\x1f\x8b":
        data = _gunzip(path, data)
    try:
        text = data.decode("ascii")
    except UnicodeDecodeError as e:
        raise ConfigError(f"{path}: not a BeeSoft map (byte {e.start} is not ASCII text)") from None
    res_cm: float | None = None
    pos = 0
    for k in range(_HEADER_LINES + 1):
        nl = text.find("\n", pos)
        line = text[pos:] if nl < 0 else text[pos:nl]
        pos = len(text) if nl < 0 else nl + 1
        if line.startswith("global_map[0]:"):
            break
        parts = line.split()
        if len(parts) == 2 and parts[0] == "robot_specifications->resolution":
            try:
                res_cm = float(parts[1])
            except ValueError:
                raise ConfigError(f"{path}: line {k + 1}: resolution: not a number: "
                                  f"{brief(parts[1])}") from None
        if nl < 0 or k == _HEADER_LINES:
            raise ConfigError(f"{path}: not a BeeSoft map (no 'global_map[0]: W H' line in the first "
                              f"{_HEADER_LINES} lines)")
    if res_cm is None:
        raise ConfigError(f"{path}: not a BeeSoft map (no robot_specifications->resolution line)")
    res = check_number(res_cm, f"{path}: resolution [cm]", 0.0, MAX_RESOLUTION_M * 100.0) / 100.0
    if res <= 0.0:
        raise ConfigError(f"{path}: resolution: must be > 0, got {res_cm:g} cm")
    dims = line.split()[1:]
    if len(dims) != 2 or not all(d.isdigit() and len(d) < 10 for d in dims):
        raise ConfigError(f"{path}: global_map[0]: expected two sizes 'W H', got {brief(line)}")
    w, h = int(dims[0]), int(dims[1])
    if w * h > MAX_MAP_PIXELS or w * h == 0:
        raise ConfigError(f"{path}: a map of {w} x {h} cells (1 to {MAX_MAP_PIXELS:,} allowed)")
    try:
        values = np.array(text[pos:].split(), dtype=np.float64)
    except ValueError as e:
        raise ConfigError(f"{path}: a map value is not a number ({one_line(e, 100)})") from None
    if values.size != w * h:
        raise ConfigError(f"{path}: {values.size:,} map values, expected {h} lines of {w} ({w * h:,})")
    if not np.all(np.isfinite(values)) or np.any(values > 1.0):
        bad = values[~np.isfinite(values) | (values > 1.0)][0]
        raise ConfigError(f"{path}: map values are P(free) in [0, 1] or negative for unknown, got {bad!r}")
    grid = values.reshape(h, w)
    p = 1.0 - grid
    unk = (grid < 0.0) | ((p <= thresh) & ~(p < free_th))
    occupied = (~unk & (p > thresh)) | (unk & (unknown == "occupied"))
    return OccupancyMap(np.ascontiguousarray(occupied[::-1]), res, (0.0, 0.0, 0.0), unknown == "occupied",
                        str(path), np.ascontiguousarray(unk[::-1]))


def _gunzip(path: Path, data: bytes) -> bytes:
    """gzip data decompressed to at most MAX_MAP_TEXT_BYTES (a bomb is refused without being inflated)."""
    d = zlib.decompressobj(wbits=31)
    try:
        out = d.decompress(data, MAX_MAP_TEXT_BYTES)
    except zlib.error as e:
        raise ConfigError(f"{path}: not a readable gzip file: {one_line(e, 120)}") from None
    if d.unconsumed_tail:
        raise ConfigError(f"{path}: decompresses to more than {MAX_MAP_TEXT_BYTES >> 20} MB")
    if not d.eof:
        raise ConfigError(f"{path}: a truncated gzip file")
    return out
