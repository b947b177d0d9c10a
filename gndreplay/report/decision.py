"""One decision of the stack as a picture, as the papers explain behaviour (GND Fig. 2 and 3, the wheelchair
paper's Fig. 3c-d): the robot-centred grid around the robot, the scan, the planned path and the goal, ND+'s
sectors, gaps, security zone and chosen region, the motion direction, the footprint and the area the
command sweeps over the braking horizon, titled with the time, the mode and why.

- ``DecisionInput``: what the stack saw and decided at one tick, taken from a replay's tick, result and
  grid (``decision_input``) or read back from results.mcap (``report.animate``).
- ``decision_geometry``: what the configuration says about a tick (ND+'s diagram of the grid's obstacles,
  ``pipeline.nd.nd_diagram``; the poses of the swept-area check, ``pipeline.supervisor.arc_poses`` over
  ``braking_time_s``); results.mcap's decision markers are drawn from it too.
- ``decision_view``: that tick with its geometry and the footprint, cropped to the view.
- ``draw_decision``: the view on a matplotlib Axes. The view is world-aligned and centred on the robot, as
  the grid is; the robot-frame parts (scan, diagram, footprint, swept area, direction) are turned by the
  robot's heading.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from ..config import Config
from ..geometry import transform_points
from ..pipeline.model import GridParams, RobotCentredGrid
from ..pipeline.nd import NdDiagram, nd_diagram
from ..pipeline.stack import TickResult
from ..pipeline.supervisor import arc_poses, braking_time_s, footprint_signed_distance
from ..robot import RobotConfig
from ..types import BUDGET_FLAGS, NS_PER_S, REFLEXIVE_MODES, Command, Pose2D, Tick
from .plots import MODE_COLORS, plot_grid

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = ["DecisionInput", "DecisionView", "clear_decision", "decision_figure", "decision_geometry",
           "decision_input", "decision_reason", "decision_view", "draw_decision", "grid_from_cells"]

F64 = NDArray[np.float64]

_SCAN, _PATH, _GOAL, _DIRECTION = "#e41a1c", "#1f77b4", "#ffbf00", "#c51b7d"
_REGION, _GAP, _SECURITY, _FOOTPRINT, _SWEEP = "#4daf4a", "#984ea3", "#ff7f00", "#08306b", "#17becf"
_SWEEP_STEP_M = 0.02  # raster pitch of the swept area's outline [m]
_GAP_MARK_M = 1.0  # a gap is drawn from its near side this far towards its far side [m]


@dataclass(frozen=True, slots=True, eq=False)
class DecisionInput:
    """What the stack saw and decided at one tick: the facts a decision picture is drawn from.

    Attributes:
        t_ns: the tick's time; t_s: seconds since the run's first scan.
        pose: the corrected pose (world frame).
        cells: (N, N) the robot-centred grid (0 unknown, 1 free, 2 occupied), ``cells[row, col]``, row
            along world y; origin_xy: world position of the outer corner of cell (0, 0); cell_m: its side.
        scan_xy: (M, 2) the scan's hits in the robot frame.
        path_xy: (K, 2) the planned path (world; empty without one); goal_xy: the goal (world).
        command: the command out; mode, situation, flags: as in commands.csv.
        direction_rad: ND+'s motion direction (robot frame; nan when unknown or no region).
        nd_region: ND+'s chosen region (first, last sector), None when unknown or none.
        nd_target_xy: where GND's reactor steered to (robot frame), None when unknown.
        desired_mode, active_mode, takeover_reason: the audit ("" when not recorded).
    """

    t_ns: int
    t_s: float
    pose: Pose2D
    cells: NDArray[np.uint8]
    origin_xy: tuple[float, float]
    cell_m: float
    scan_xy: F64
    path_xy: F64
    goal_xy: tuple[float, float]
    command: Command
    mode: str
    situation: str = "NONE"
    flags: tuple[str, ...] = ()
    direction_rad: float = math.nan
    nd_region: tuple[int, int] | None = None
    nd_target_xy: tuple[float, float] | None = None
    desired_mode: str = ""
    active_mode: str = ""
    takeover_reason: str = ""


def decision_input(tick: Tick, result: TickResult, grid: RobotCentredGrid, *, t0_ns: int) -> DecisionInput:
    """The facts of a replay's tick (the grid copied: the stack goes on changing it); ``t0_ns`` is the
    run's first scan. The wall-clock ``*_OVER_BUDGET`` flags are left out (the picture is deterministic)."""
    scan = tick.scan
    return DecisionInput(
        t_ns=result.t_ns, t_s=(result.t_ns - t0_ns) / NS_PER_S, pose=result.pose_corrected,
        cells=grid.cells.copy(), origin_xy=grid.origin_xy, cell_m=grid.params.cell_m,
        scan_xy=transform_points(scan.sensor_pose.as_array(), scan.points()),
        path_xy=np.asarray(result.path_xy, dtype=np.float64).reshape(-1, 2), goal_xy=result.goal,
        command=result.command, mode=result.mode.value, situation=result.situation.name,
        flags=tuple((result.flags & ~BUDGET_FLAGS).names()), direction_rad=result.direction_rad,
        nd_region=result.nd_region, nd_target_xy=result.nd_target_xy, desired_mode=result.desired_mode,
        active_mode=result.active_mode, takeover_reason=result.takeover_reason,
    )


def grid_from_cells(cells: NDArray[np.uint8], origin_xy: tuple[float, float],
                    cell_m: float) -> RobotCentredGrid:
    """A ``RobotCentredGrid`` holding ``cells`` (N, N) at ``origin_xy``, to ask it what the stack asks
    (``occupied_points``)."""
    n = int(cells.shape[0])
    if cells.ndim != 2 or cells.shape[1] != n:
        raise ValueError(f"the grid must be square, got shape {cells.shape}")
    half = n // 2 + 0.5  # a centre inside cell (n // 2, n // 2) gives the grid its origin back
    grid = RobotCentredGrid(GridParams(size_cells=n, cell_m=cell_m),
                            centre_xy=(origin_xy[0] + half * cell_m, origin_xy[1] + half * cell_m))
    grid.cells = cells
    return grid


def decision_reason(inp: DecisionInput) -> str:
    """One line of why the command is what it is: mode, ND+ situation, flags, takeover."""
    parts = [inp.mode]
    if inp.situation and inp.situation != "NONE":
        parts.append(f"ND+ {inp.situation}")
    parts += list(inp.flags)
    if inp.takeover_reason:
        parts.append(f"{inp.active_mode or 'active'}: {inp.takeover_reason}")
    return " · ".join(parts)


@dataclass(frozen=True, slots=True, eq=False)
class DecisionView:
    """A decision ready to draw (``draw_decision``).

    Attributes:
        tick: the facts (``DecisionInput``).
        cells: the grid cropped to the view; extent: its (x0, x1, y0, y1) [m] relative to the robot.
        radius_m: half the side of the (square) view.
        robot: the vehicle (footprint).
        diagram: ND+'s sectors, gaps and security zone for the grid's obstacles around the robot.
        region: (n_sectors,) mask of the chosen region's sectors (all False without one).
        sweep: (P, 3) robot-frame poses x, y, theta of the footprint along the command's arc over the
            braking horizon (the reflexive check's swept area); (0, 3) for a still command.
        sweep_margin_m: the check's margin around the footprint.
        title: time, what happened and why.
    """

    tick: DecisionInput
    cells: NDArray[np.uint8]
    extent: tuple[float, float, float, float]
    radius_m: float
    robot: RobotConfig
    diagram: NdDiagram
    region: NDArray[np.bool_]
    sweep: F64
    sweep_margin_m: float
    title: str


def _crop(inp: DecisionInput, radius_m: float) -> tuple[NDArray[np.uint8], tuple[float, float, float, float]]:
    """The cells within ``radius_m`` (a square) of the robot and their extent relative to it."""
    c, n = inp.cell_m, inp.cells.shape[0]
    col = (inp.pose.x - inp.origin_xy[0]) / c
    row = (inp.pose.y - inp.origin_xy[1]) / c
    h = math.ceil(radius_m / c) + 1
    r0, r1 = max(math.floor(row) - h, 0), min(math.floor(row) + h + 1, n)
    c0, c1 = max(math.floor(col) - h, 0), min(math.floor(col) + h + 1, n)
    if r0 >= r1 or c0 >= c1:
        return np.zeros((1, 1), dtype=np.uint8), (0.0, 0.0, 0.0, 0.0)
    x0, y0 = inp.origin_xy[0] + c0 * c - inp.pose.x, inp.origin_xy[1] + r0 * c - inp.pose.y
    return inp.cells[r0:r1, c0:c1], (x0, x0 + (c1 - c0) * c, y0, y0 + (r1 - r0) * c)


def decision_geometry(grid: RobotCentredGrid, pose: Pose2D, command: Command,
                      cfg: Config) -> tuple[NdDiagram, F64]:
    """ND+'s diagram of the grid's occupied cells within the reactor's range at ``pose`` (what GND's reactor
    sees), and the robot-frame poses (P, 3) x, y, theta of the footprint along the command's arc over the
    reflexive check's braking horizon ((0, 3) for a still command)."""
    stack = cfg.stack_params()  # the reactor and supervisor with the robot-scaled keys in force
    diagram = nd_diagram(grid.occupied_points(pose, stack.reactor.max_range_m), cfg.robot, stack.reactor)
    c = command
    if c.v_mps == 0.0 and c.vy_mps == 0.0 and c.w_radps == 0.0:
        return diagram, np.zeros((0, 3))
    t_end = braking_time_s(c.v_mps, c.vy_mps, c.w_radps, cfg.robot, stack.supervisor)
    return diagram, np.column_stack(arc_poses(c.v_mps, c.vy_mps, c.w_radps, t_end, cfg.robot))


def decision_view(inp: DecisionInput, cfg: Config, *, headline: str = "",
                  radius_m: float = 5.0) -> DecisionView:
    """The view of ``inp`` under the run's configuration: ND+'s diagram of the grid's occupied cells within
    the reactor's range (what GND's reactor sees), the footprint swept along the command's arc over the
    reflexive check's braking horizon, the grid cropped to a square of ``radius_m``. ``headline`` (the
    event) leads the title."""
    grid = grid_from_cells(inp.cells, inp.origin_xy, inp.cell_m)
    diagram, sweep = decision_geometry(grid, inp.pose, inp.command, cfg)
    cells, extent = _crop(inp, radius_m)
    head = f"t = {inp.t_s:.2f} s" + (f"  —  {headline}" if headline else "")
    return DecisionView(
        tick=inp, cells=cells, extent=extent, radius_m=radius_m, robot=cfg.robot, diagram=diagram,
        region=diagram.region_mask(inp.nd_region), sweep=sweep,
        sweep_margin_m=cfg.supervisor.emergency_margin_m, title=f"{head}\n{decision_reason(inp)}",
    )


# ---- drawing --------------------------------------------------------------------------------------------


def _turn(theta: float, xy: F64) -> F64:
    """Robot-frame points (..., 2) into the view (world-aligned, robot at the origin)."""
    c, s = math.cos(theta), math.sin(theta)
    return np.stack([c * xy[..., 0] - s * xy[..., 1], s * xy[..., 0] + c * xy[..., 1]], axis=-1)


def _polar(r: F64, a: F64) -> F64:
    return np.column_stack([r * np.cos(a), r * np.sin(a)])


def _swept_distance(view: DecisionView) -> tuple[F64, F64, F64]:
    """Robot-frame raster X, Y around the swept poses and the signed distance from each raster point to the
    nearest footprint along the sweep (``footprint_signed_distance``; <= margin: inside the swept area)."""
    p, robot = view.sweep, view.robot
    pad = robot.outer_radius_m + view.sweep_margin_m + 2 * _SWEEP_STEP_M
    xs = np.arange(p[:, 0].min() - pad, p[:, 0].max() + pad, _SWEEP_STEP_M)
    ys = np.arange(p[:, 1].min() - pad, p[:, 1].max() + pad, _SWEEP_STEP_M)
    X, Y = np.meshgrid(xs, ys)
    dx, dy = X[None] - p[:, 0, None, None], Y[None] - p[:, 1, None, None]
    ct, st = np.cos(p[:, 2])[:, None, None], np.sin(p[:, 2])[:, None, None]
    local = np.stack([ct * dx + st * dy, -st * dx + ct * dy], axis=-1)
    return X, Y, footprint_signed_distance(local, robot).min(axis=0)


def _footprint(ax: Axes, robot: RobotConfig, x: float, y: float, theta: float, **style: Any) -> None:
    """The footprint outline at (x, y, theta) of the view."""
    from matplotlib.patches import Circle, Patch, Rectangle
    from matplotlib.transforms import Affine2D

    patch: Patch
    if robot.shape == "circle":
        patch = Circle((0.0, 0.0), robot.radius_m, fill=False, **style)
    else:
        patch = Rectangle((-robot.rear_m, -robot.width_m / 2.0), robot.front_m + robot.rear_m, robot.width_m,
                          fill=False, **style)
    patch.set_transform(Affine2D().rotate(theta).translate(x, y) + ax.transData)
    ax.add_patch(patch)


def _draw_diagram(ax: Axes, view: DecisionView, theta: float, reach: float) -> None:
    """ND+: the chosen region as a fan out to its obstacles, the gaps (discontinuities) as radial segments,
    the security zone as a dashed outline."""
    d = view.diagram
    a = d.bisectors_rad
    r = np.minimum(d.dist_m, reach)
    if view.region.any():
        idx = np.flatnonzero(view.region)
        if not view.region.all():  # start the fan at the region's first sector (it may wrap)
            first = int(np.flatnonzero(view.region & ~np.roll(view.region, 1))[0])
            idx = (first + np.arange(idx.size)) % a.size
        fan = np.vstack([[0.0, 0.0], _turn(theta, _polar(r[idx], a[idx])), [0.0, 0.0]])
        ax.fill(fan[:, 0], fan[:, 1], color=_REGION, alpha=0.25, lw=0, zorder=2, label="ND+ chosen region")
    gaps = np.flatnonzero(d.gaps)
    if gaps.size:
        nxt = (gaps + 1) % a.size
        edge = a[gaps] + math.pi / a.size  # the boundary between sector i and i + 1
        inner = np.minimum(r[gaps], r[nxt])
        outer = np.minimum(np.maximum(r[gaps], r[nxt]), inner + _GAP_MARK_M)
        segs = np.stack([_turn(theta, _polar(inner, edge)), _turn(theta, _polar(outer, edge))], axis=1)
        from matplotlib.collections import LineCollection

        ax.add_collection(LineCollection(list(segs), colors=_GAP, linewidths=1.6, zorder=4, label="ND+ gaps"))
    zone = _turn(theta, _polar(np.append(d.security_m, d.security_m[0]), np.append(a, a[0])))
    ax.plot(zone[:, 0], zone[:, 1], "--", color=_SECURITY, lw=0.9, zorder=4, label="security zone")


def draw_decision(ax: Axes, view: DecisionView) -> None:
    """Draw ``view`` on ``ax``: grid (grey unknown, white free, black occupied), ND+'s chosen region, gaps
    and security zone, the swept area and the footprint, the scan, the planned path, the goal, the motion
    direction, and the command in a corner; world-aligned, the robot at the origin."""
    inp, R = view.tick, view.radius_m
    theta = inp.pose.theta
    if view.cells.size > 1:
        plot_grid(ax, view.cells, view.extent)
    _draw_diagram(ax, view, theta, reach=1.5 * R)
    if view.sweep.shape[0]:
        X, Y, D = _swept_distance(view)
        V = _turn(theta, np.stack([X, Y], axis=-1))
        ax.contourf(V[..., 0], V[..., 1], D, levels=[-1e9, view.sweep_margin_m], colors=[_SWEEP], alpha=0.45,
                    zorder=3)
        ax.fill([], [], color=_SWEEP, alpha=0.45, label="swept over braking")
        ex, ey = _turn(theta, view.sweep[-1, :2]).tolist()
        _footprint(ax, view.robot, ex, ey, theta + float(view.sweep[-1, 2]), ec=_FOOTPRINT, lw=0.7, ls=":",
                   zorder=5)
    _footprint(ax, view.robot, 0.0, 0.0, theta, ec=_FOOTPRINT, lw=1.4, zorder=6, label="footprint")
    front = view.robot.radius_m if view.robot.shape == "circle" else view.robot.front_m
    ax.plot([0.0, front * math.cos(theta)], [0.0, front * math.sin(theta)], "-", color=_FOOTPRINT, lw=1.4,
            zorder=6)
    if inp.scan_xy.shape[0]:
        s = _turn(theta, inp.scan_xy)
        ax.plot(s[:, 0], s[:, 1], ".", color=_SCAN, ms=2.0, zorder=7, label="scan")
    if inp.path_xy.shape[0]:
        ax.plot(inp.path_xy[:, 0] - inp.pose.x, inp.path_xy[:, 1] - inp.pose.y, "-", color=_PATH, lw=1.4,
                zorder=6, label="planned path")
    gx, gy = inp.goal_xy[0] - inp.pose.x, inp.goal_xy[1] - inp.pose.y
    far = max(abs(gx), abs(gy)) / (0.96 * R)
    ax.plot([gx / max(far, 1.0)], [gy / max(far, 1.0)], "*", ms=12, zorder=8, mec="#7f5f00",
            mfc=_GOAL if far <= 1.0 else "none", label="goal" if far <= 1.0 else "goal (beyond the view)")
    if inp.nd_target_xy is not None:
        t = _turn(theta, np.asarray(inp.nd_target_xy, dtype=np.float64))
        ax.plot([t[0]], [t[1]], "x", color=_DIRECTION, ms=7, mew=1.5, zorder=8, label="reactor target")
    if math.isfinite(inp.direction_rad):
        tip = _turn(theta, _polar(np.array([0.5 * R]), np.array([inp.direction_rad])))[0]
        ax.annotate("", xy=(float(tip[0]), float(tip[1])), xytext=(0.0, 0.0), zorder=9,
                    arrowprops={"arrowstyle": "-|>", "color": _DIRECTION, "lw": 2.0})
        ax.plot([], [], "-", color=_DIRECTION, lw=2.0, label="ND+ direction")
    c = inp.command
    text = f"v {c.v_mps:+.2f} m/s   w {c.w_radps:+.2f} rad/s" + (f"   vy {c.vy_mps:+.2f}" if c.vy_mps else "")
    if inp.active_mode:
        text += f"\nactive: {inp.active_mode}" + (f" (desired {inp.desired_mode})"
                                                 if inp.desired_mode and inp.desired_mode != inp.active_mode
                                                 else "")
    color = MODE_COLORS.get(inp.mode, "#555555")
    ax.text(0.01, 0.99, text, transform=ax.transAxes, va="top", ha="left", fontsize=7, zorder=10,
            bbox={"boxstyle": "round,pad=0.3", "fc": "white", "ec": color, "lw": 1.5 if inp.mode in
                  REFLEXIVE_MODES else 0.8, "alpha": 0.9})
    ax.set_xlim(-R, R)
    ax.set_ylim(-R, R)
    ax.set_aspect("equal")
    ax.set_xlabel("x - x_robot [m] (world-aligned)", fontsize=7)
    ax.set_ylabel("y - y_robot [m]", fontsize=7)
    ax.tick_params(labelsize=7)
    ax.set_title(view.title, fontsize=8, loc="left", color="black")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.07), ncol=4, fontsize=7, frameon=False,
              handlelength=1.5, columnspacing=1.2)


def clear_decision(ax: Axes) -> None:
    """Remove what ``draw_decision`` drew on ``ax`` (images, lines, collections, patches, texts, legend,
    title), keeping the axes, their limits and their ticks: the next decision is drawn on the same axes
    without building them again (the picture is the same as on fresh axes)."""
    for artist in (*ax.images, *ax.lines, *ax.collections, *ax.patches, *ax.texts):
        artist.remove()
    if ax.legend_ is not None:
        ax.legend_.remove()
    ax.set_title("", loc="left")


def decision_figure() -> tuple[Figure, Axes]:
    """A figure with one Axes for ``draw_decision``, at a fixed place (title above, legend below), so that
    every snapshot and every frame of an animation has the same layout."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7.0, 8.0))
    ax = fig.add_axes((0.1, 0.16, 0.86, 0.75))
    return fig, ax
