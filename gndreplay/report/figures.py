"""The figure set of a run directory (the wheelchair paper's Fig. 5b-e), built from the run's files alone.

Figures are ``matplotlib.figure.Figure`` objects rendered by the Agg canvas: no pyplot, no global backend
switch, no window. PNGs are saved at a fixed dpi without metadata, so the same files give the same bytes.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from numpy.typing import NDArray

from ..evaluation import TrajectoryErrors, align_origin, associate, trajectory_errors
from ..fsutil import atomic_path
from ..geometry import compose
from ..types import REFLEXIVE_MODES
from .plots import (
    COMMAND_COLORS,
    FLAG_COLORS,
    MIN_BAND_FRACTION,
    MODE_COLORS,
    NAV_MODE_COLORS,
    SITUATION_COLORS,
    Bands,
    band_spans,
    flag_labels,
    plot_bands,
    plot_commands,
    plot_flags,
    plot_grid,
    plot_hit_raster,
    plot_pose,
    plot_series,
    plot_timing,
    plot_trajectory,
)
from .rundir import TIMING_MODULES, RunData, TimeWindow, episodes, time_origin

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = [
    "DPI",
    "FIGURES",
    "FIGURE_MAKERS",
    "TRUTH_FIGURES",
    "WINDOW_FIGURES",
    "budgets_ms",
    "build_figures",
    "figure_commands",
    "figure_error",
    "figure_model",
    "figure_modes",
    "figure_names",
    "figure_raw",
    "figure_timing",
    "save_figure",
    "scan_period_s",
    "truth_errors",
    "truth_on_corrected",
    "window_figure_name",
]

DPI = 120
PNG_COMPRESS_LEVEL = 1
FIGURES: Mapping[str, str] = {
    "fig_model.png": "Model: scan hits placed at the corrected poses, corrected and raw trajectories (and "
    "the ground truth, when the log has it, started on the corrected pose), and the robot-centred grid at "
    "one tick (Fig. 5b).",
    "fig_raw.png": "Raw laser data placed with the raw odometry, and the odometry trajectory (Fig. 5c).",
    "fig_commands.png": "Motion commands v and w over time, GND mode and ND+ situation bands, and the "
    "ticks where each flag fired (Fig. 5d).",
    "fig_timing.png": "Computation time of each module per tick, with the time-out budgets and the log's "
    "scan period (Fig. 5e).",
    "fig_modes.png": "Intervention timeline: the commands with the takeovers shaded, the desired and the "
    "active navigation mode, and the reflexive overrides (emergency stops, safe replacements, stale data, "
    "trap escapes).",
    "fig_error.png": "Error against the ground truth over time (when the log has it): position and "
    "heading error of the odometry and of the corrected trajectory, each after its SE(2) alignment to the "
    "truth, with the ticks where the match failed (MATCH_FAILED) marked.",
}
#: The figures drawn for a time window (``build_figures`` of a windowed run): the time series, and the maps
#: zoomed to the poses of the window.
WINDOW_FIGURES = ("fig_commands.png", "fig_timing.png", "fig_modes.png", "fig_model.png", "fig_raw.png")
COLUMNS = 1000
"""Pixel columns of a time axis (fewer than the axes' 1100-odd pixels): a series with more ticks is drawn
as its range and mean per column (``plots.plot_series``)."""
LegendLoc = Literal["outside right upper", "outside right center"]
Box = tuple[float, float, float, float]  # x0, x1, y0, y1 [m]
_START, _END, _GOAL = "#2ca02c", "#d62728", "#ffbf00"
_CORRECTED, _RAW, _TRUTH = "#1f77b4", "#ff7f0e", "#222222"


def budgets_ms(summary: Mapping[str, Any]) -> dict[str, float]:
    """Per-module budgets [ms] from summary.json's ``config.supervisor.budget_<module>_s`` (those present)."""
    sup = summary.get("config", {}).get("supervisor", {}) or {}
    out: dict[str, float] = {}
    for m in TIMING_MODULES:
        b = sup.get(f"budget_{m}_s")
        if isinstance(b, int | float) and np.isfinite(b) and b > 0:
            out[m] = 1e3 * float(b)
    return out


def scan_period_s(t_s: NDArray[np.float64]) -> float | None:
    """The log's scan period [s]: median spacing of the scan stamps (None with fewer than two)."""
    if t_s.size < 2:
        return None
    d = np.diff(np.sort(t_s))
    d = d[d > 0]
    return float(np.median(d)) if d.size else None


def _bounds(*boxes: tuple[float, float, float, float] | None, margin: float = 0.03
            ) -> tuple[float, float, float, float]:
    """The union of (x0, x1, y0, y1) boxes (None and non-finite skipped), grown by ``margin`` of its size."""
    b = np.array([x for x in boxes if x is not None and np.all(np.isfinite(x))], dtype=np.float64)
    if b.size == 0:
        return (-1.0, 1.0, -1.0, 1.0)
    x0, x1, y0, y1 = b[:, 0].min(), b[:, 1].max(), b[:, 2].min(), b[:, 3].max()
    m = margin * max(x1 - x0, y1 - y0, 1.0)
    return (float(x0 - m), float(x1 + m), float(y0 - m), float(y1 + m))


def _box(xy: NDArray[np.float64]) -> tuple[float, float, float, float] | None:
    if xy.shape[0] == 0:
        return None
    return (float(xy[:, 0].min()), float(xy[:, 0].max()), float(xy[:, 1].min()), float(xy[:, 1].max()))


def _window_box(traj: NDArray[np.float64], min_side_m: float = 6.0) -> Box | None:
    """The box of a window's poses (M, 4) t, x, y, yaw, at least ``min_side_m`` on a side (around a short
    stretch, its surroundings)."""
    b = _box(traj[:, 1:3])
    if b is None:
        return None
    cx, cy = 0.5 * (b[0] + b[1]), 0.5 * (b[2] + b[3])
    hx, hy = max(0.5 * (b[1] - b[0]), 0.5 * min_side_m), max(0.5 * (b[3] - b[2]), 0.5 * min_side_m)
    return (cx - hx, cx + hx, cy - hy, cy + hy)


def _map_box(data: RunData, extent: Box | None, *trajs: NDArray[np.float64]) -> Box:
    """A map figure's box: the map's ``extent`` and the trajectories; of a window, its first trajectory's
    poses (``_window_box``), or the whole map when the window holds no pose."""
    if data.window is not None and trajs[0].shape[0]:
        return _bounds(_window_box(trajs[0]))
    return _bounds(extent, *(_box(tr[:, 1:3]) for tr in trajs))


def _hits(ax: Axes, data: RunData, hits: NDArray[Any], extent: Box, box: Box) -> None:
    """A hit raster; of a window, only its cells inside ``box`` (so zooming in keeps the map's cells)."""
    if data.window is not None:
        x0, x1, y0, y1 = extent
        h, w = hits.shape
        cx, cy = max(x1 - x0, 1e-9) / max(w, 1), max(y1 - y0, 1e-9) / max(h, 1)
        c0, c1 = (int(np.clip(f((v - x0) / cx), 0, w)) for f, v in ((np.floor, box[0]), (np.ceil, box[1])))
        r0, r1 = (int(np.clip(f((v - y0) / cy), 0, h)) for f, v in ((np.floor, box[2]), (np.ceil, box[3])))
        if c1 <= c0 or r1 <= r0:
            return
        hits, extent = hits[r0:r1, c0:c1], (x0 + c0 * cx, x0 + c1 * cx, y0 + r0 * cy, y0 + r1 * cy)
    plot_hit_raster(ax, hits, extent, max_pixels=_raster_pixels(ax, hits.shape, extent, box))


def _raster_pixels(ax: Axes, shape: tuple[int, ...], extent: Box, box: Box, most: int = 1600) -> int:
    """``hit_image``'s ``max_pixels`` for a raster of ``shape`` over ``extent`` drawn in ``box``: pooled
    no further than one cell per pixel of the saved PNG (the axes at ``DPI``, before the layout, which only
    shrinks them), so the figure shows the same, and matplotlib never resamples more cells than that
    (its working copies are several times the image); at most ``most``."""
    bb = ax.get_window_extent()  # display pixels at the figure's dpi
    scale = DPI / ax.figure.dpi
    share_x = min(1.0, (extent[1] - extent[0]) / max(box[1] - box[0], 1e-9))
    share_y = min(1.0, (extent[3] - extent[2]) / max(box[3] - box[2], 1e-9))
    px_w = max(1.0, bb.width * scale * share_x)
    px_h = max(1.0, bb.height * scale * share_y)
    f = max(1, math.floor(min(shape[1] / px_w, shape[0] / px_h)))
    return min(most, -(-max(shape) // f))


def _set_box(ax: Axes, box: tuple[float, float, float, float]) -> None:
    ax.set_xlim(box[0], box[1])
    ax.set_ylim(box[2], box[3])


def _map_height(box: tuple[float, float, float, float], width_in: float, lo: float = 3.5, hi: float = 9.0
                ) -> float:
    """Height [in] of an equal-aspect map panel ``width_in`` wide showing ``box``, clamped to [lo, hi]."""
    ratio = (box[3] - box[2]) / max(box[1] - box[0], 1e-9)
    return float(np.clip(width_in * ratio, lo, hi))


def _new_figure(w: float, h: float, *, left: float = 0.9, right: float = 0.2, bottom: float = 0.6,
                top: float = 0.4) -> Figure:
    """A ``w`` x ``h`` inch figure on the Agg canvas whose subplots fill it less fixed margins [in]: the
    layout is set here once, not searched for at every draw (as constrained layout does)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(w, h))
    FigureCanvasAgg(fig)
    fig.subplots_adjust(left=left / w, right=1.0 - right / w, bottom=bottom / h, top=1.0 - top / h)
    return fig


def _gaps(fig: Figure, ratios: list[float], gap_in: float) -> float:
    """``hspace`` (a fraction of the mean axes height) that leaves ``gap_in`` inches between the rows of a
    column of ``len(ratios)`` axes in ``fig``'s subplot area."""
    p, n = fig.subplotpars, len(ratios)
    height = (p.top - p.bottom) * fig.get_figheight()
    mean = max(height - (n - 1) * gap_in, 0.1) / n
    return gap_in / mean


def _text_in(fig: Figure, texts: list[str], size: float) -> float:
    """The width [in] of the widest of ``texts`` at font ``size`` [pt] (0 for none): margins made to fit
    labels, measured once instead of by a layout engine at each draw."""
    if not texts:
        return 0.0
    from matplotlib.font_manager import FontProperties

    renderer = fig.canvas.get_renderer()  # type: ignore[attr-defined]
    prop = FontProperties(size=size)
    px = max(renderer.get_text_width_height_descent(t, prop, ismath=False)[0] for t in texts)
    return float(px) / fig.dpi


def _legend_in(fig: Figure, names: list[str], title: str, size: float = 8.0) -> float:
    """The width [in] of a frameless figure legend of ``names`` (handle length 1) titled ``title``."""
    return max(_text_in(fig, names, size) + 2.4 * size / 72.0, _text_in(fig, [title], size)) + 0.12


SideLegend = tuple[list[Any], list[str], str, LegendLoc]  # handles, names, title, where


def _fit_rows(fig: Figure, ratios: list[float], *, left: float, right: float, bottom: float, top: float,
              gap_in: float = 0.1, legends: tuple[SideLegend, ...] = ()) -> None:
    """Place a column of axes (height ``ratios``) inside fixed margins [in], ``gap_in`` apart, and the
    ``legends`` in the right margin, which is widened to the widest of them."""
    w, h = fig.get_figwidth(), fig.get_figheight()
    right = max([right] + [_legend_in(fig, names, title) + 0.1 for _, names, title, _ in legends])
    fig.subplots_adjust(left=left / w, right=1.0 - right / w, bottom=bottom / h, top=1.0 - top / h)
    fig.subplots_adjust(hspace=_gaps(fig, ratios, gap_in))
    x = 1.0 - (right - 0.1) / w
    for handles, names, title, where in legends:
        upper = where == "outside right upper"
        y = 1.0 - top / h if upper else 0.5 * (1.0 - top / h + bottom / h)
        fig.legend(handles, names, loc="upper left" if upper else "center left", bbox_to_anchor=(x, y),
                   title=title, fontsize=8, title_fontsize=8, frameon=False, handlelength=1.0,
                   borderaxespad=0.0)


def _pixel_columns(fig: Figure, ax: Axes, dpi: int | None = None) -> int:
    """The pixel columns ``ax`` spans when ``fig`` is saved at ``dpi`` (default ``DPI``)."""
    return max(1, int(np.ceil(ax.get_position().width * fig.get_figwidth() * (dpi or DPI))))


def _legend_below(fig: Figure, ax: Axes, *, ncol: int, handles: list[Any] | None = None,
                  gap_in: float = 0.5) -> None:
    """The legend of a map panel centred ``gap_in`` inches below it (under its x label, whatever the height
    its equal aspect gives it)."""
    from matplotlib.transforms import offset_copy

    below = offset_copy(ax.transAxes, fig=fig, x=0.0, y=-gap_in, units="inches")
    kw: dict[str, Any] = {} if handles is None else {"handles": handles}
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, 0.0), bbox_transform=below, ncol=ncol, fontsize=8,
              frameon=False, **kw)


def _ends(ax: Axes, traj: NDArray[np.float64]) -> None:
    if traj.shape[0]:
        ax.plot(traj[0, 1], traj[0, 2], "o", color=_START, markersize=8, markeredgecolor="k", label="start",
                zorder=6)
        ax.plot(traj[-1, 1], traj[-1, 2], "s", color=_END, markersize=7, markeredgecolor="k", label="end",
                zorder=6)


def _no_data(ax: Axes, text: str) -> None:
    ax.text(0.5, 0.5, text, transform=ax.transAxes, ha="center", va="center", fontsize=9, color="0.4")


def truth_on_corrected(data: RunData) -> NDArray[np.float64] | None:
    """The ground-truth trajectory ((M, 4) t, x, y, yaw) in the corrected frame: moved rigidly so that its
    first pose paired with a corrected pose (nearest stamp, ``evaluation.associate``) lies on that pose,
    so the gap between the two lines is the corrected trajectory's drift. None without truth or pair."""
    truth = data.traj_truth
    if truth is None or truth.shape[0] == 0 or data.traj_corrected.shape[0] == 0:
        return None
    ic, it = associate(_stamps_ns(data.traj_corrected), _stamps_ns(truth))
    if ic.size == 0:
        return None
    first = int(np.argmin(truth[it, 0]))
    move = align_origin(truth[it[first], 1:], data.traj_corrected[ic[first], 1:])
    return np.column_stack([truth[:, 0], compose(move, truth[:, 1:]).reshape(-1, 3)])


def _stamps_ns(traj: NDArray[np.float64]) -> NDArray[np.int64]:
    return np.round(np.asarray(traj[:, 0]) * 1e9).astype(np.int64)


def truth_errors(data: RunData) -> dict[str, TrajectoryErrors] | None:
    """The SE(2)-aligned errors of the odometry ("odometry") and the corrected trajectory ("corrected")
    against the run's ground truth (``evaluation.trajectory_errors``, as summary.json's ``truth``); None
    without truth."""
    truth = data.traj_truth
    if truth is None or truth.shape[0] == 0:
        return None
    ref = (_stamps_ns(truth), truth[:, 1:])
    return {name: trajectory_errors(_stamps_ns(traj), traj[:, 1:], *ref)
            for name, traj in (("odometry", data.traj_odom), ("corrected", data.traj_corrected))}


def figure_model(data: RunData) -> Figure:
    """Fig. 5b: the global model map with both trajectories, and the robot-centred grid at one tick (of a
    window: the map around the window's poses, the grid only when its tick lies in the window)."""
    maps = data.maps
    snap = maps.snapshot if maps is not None else None
    w = data.window
    if snap is not None and w is not None and not w.start_s <= snap.elapsed_s <= w.end_s:
        snap = None
    truth = truth_on_corrected(data)
    box = _map_box(data, maps.corrected_extent if maps is not None else None, data.traj_corrected,
                   data.traj_odom, *(() if truth is None else (truth,)))
    ax_g: Axes | None = None
    if w is not None and snap is None:
        fig = _new_figure(9.0, _map_height(box, 8.4) + 1.3, left=0.8, bottom=1.0, top=0.35)
        ax = fig.subplots()
    else:
        fig = _new_figure(13.0, max(6.0, _map_height(box, 7.6) + 1.4), left=0.8, right=0.15, bottom=1.2,
                          top=0.55)
        ax, ax_g = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1.7, 1.0], "wspace": 0.2})
    if maps is not None:
        _hits(ax, data, maps.corrected_hits, maps.corrected_extent, box)
    else:
        _no_data(ax, "maps.npz missing: no map")
    plot_trajectory(ax, data.traj_odom[:, 1:3], label="raw odometry", style="--", color=_RAW, linewidth=1.0,
                    alpha=0.9)
    plot_trajectory(ax, data.traj_corrected[:, 1:3], label="corrected", color=_CORRECTED, linewidth=1.4)
    if truth is not None:
        plot_trajectory(ax, truth[:, 1:3], label="ground truth", style=":", color=_TRUTH, linewidth=1.4)
    _ends(ax, data.traj_corrected)
    goal = data.summary.get("options", {}).get("goal")
    if goal:
        ax.plot(goal[0], goal[1], "*", color=_GOAL, markersize=14, markeredgecolor="k", label="goal",
                zorder=6)
    if snap is not None:
        plot_pose(ax, snap.pose, length_m=0.04 * max(box[1] - box[0], box[3] - box[2]), color="#c51b7d",
                  label=f"robot at t = {snap.elapsed_s:.1f} s (right)")
    _set_box(ax, box)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m] (corrected frame)")
    ax.set_ylabel("y [m]")
    cell = f", {maps.cell_m * 100:.0f} cm cells" if maps is not None else ""
    ax.set_title(f"Model: scan hits at the corrected poses{cell}{_window_title(w)}", fontsize=10)
    _legend_below(fig, ax, ncol=5)

    if ax_g is None:
        return fig
    if snap is None:
        _no_data(ax_g, "no robot-centred grid snapshot")
        ax_g.set_axis_off()
        return fig
    x0, x1, y0, y1 = snap.extent
    plot_grid(ax_g, snap.cells, snap.extent)
    if snap.path_xy.shape[0]:
        plot_trajectory(ax_g, snap.path_xy, label="planned path", color="#1f77b4", linewidth=1.6, zorder=4)
    gx, gy = float(snap.goal_xy[0]), float(snap.goal_xy[1])
    inside = x0 <= gx <= x1 and y0 <= gy <= y1
    gx, gy = float(np.clip(gx, x0, x1)), float(np.clip(gy, y0, y1))
    ax_g.plot(gx, gy, "*", color=_GOAL, markersize=14, markeredgecolor="k",
              label="goal" if inside else "goal (outside, on the border)", zorder=6)
    plot_pose(ax_g, snap.pose, length_m=0.05 * (x1 - x0), color="#c51b7d", label="robot")
    ax_g.set_xlim(x0, x1)
    ax_g.set_ylim(y0, y1)
    ax_g.set_xlabel("x [m]")
    ax_g.set_ylabel("y [m]")
    flags = f"\nflags: {snap.flags.replace('|', ', ')}" if snap.flags else ""
    ax_g.set_title(f"Robot-centred grid at t = {snap.elapsed_s:.1f} s (tick {snap.tick}): "
                   f"{snap.mode}, {snap.situation}{flags}", fontsize=10)
    from matplotlib.patches import Patch

    handles, _ = ax_g.get_legend_handles_labels()
    handles += [Patch(facecolor=c, edgecolor="0.3", label=n)
                for c, n in (("#9e9e9e", "unknown"), ("#ffffff", "free"), ("#000000", "occupied"))]
    _legend_below(fig, ax_g, handles=handles, ncol=3)
    return fig


def figure_raw(data: RunData) -> Figure:
    """Fig. 5c: every scan placed with the raw odometry, and the odometry trajectory."""
    box = _map_box(data, data.maps.raw_extent if data.maps is not None else None, data.traj_odom)
    fig = _new_figure(9.0, _map_height(box, 8.4) + 1.3, left=0.8, bottom=1.0, top=0.35)
    ax = fig.subplots()
    _set_box(ax, box)
    if data.maps is not None:
        _hits(ax, data, data.maps.raw_hits, data.maps.raw_extent, box)
    else:
        _no_data(ax, "maps.npz missing: no raw map")
    plot_trajectory(ax, data.traj_odom[:, 1:3], label="raw odometry", color=_RAW, linewidth=1.2)
    _ends(ax, data.traj_odom)
    _set_box(ax, box)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m] (odometry frame)")
    ax.set_ylabel("y [m]")
    ax.set_title(f"Raw laser data and trajectory from the odometry alone{_window_title(data.window)}",
                 fontsize=10)
    _legend_below(fig, ax, ncol=3)
    return fig


def _time_axis(data: RunData, t: NDArray[np.float64]) -> tuple[float, float]:
    """The x range of a time-series figure [s since the first tick]: the window, else the first to the last
    tick padded by 0.5 %."""
    if data.window is not None:
        return data.window.start_s, data.window.end_s
    if t.size == 0:
        return 0.0, 1.0
    pad = 0.005 * max(float(t[-1] - t[0]), 1e-3)
    return float(t[0]) - pad, float(t[-1]) + pad


def _min_width(span: tuple[float, float]) -> float:
    return MIN_BAND_FRACTION * (span[1] - span[0])


def _window_title(window: TimeWindow | None) -> str:
    return "" if window is None else f", from {window.start_s:g} to {window.end_s:g} s"


def _logged(data: RunData) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
    """The log's recorded (v, w) per tick, None when the run's commands.csv has no such columns."""
    c = data.commands
    return (c.log_v_mps, c.log_w_radps) if c.log_v_mps.shape == c.t_s.shape else None


def _envelope_note(n: int) -> str:
    return "; per pixel column: range shaded, mean as the line" if n > COLUMNS else ""


def figure_commands(data: RunData) -> Figure:
    """Fig. 5d: v and w over time (the log's recorded v and w behind, lighter), mode and situation bands
    (an episode of one tick still a visible mark), flag markers."""
    c = data.commands
    t = c.t_s - time_origin(data)
    span = _time_axis(data, t)
    n_flags = max(1, sum(1 for m in c.flags.values() if np.any(m)))
    fig = _new_figure(12.0, 5.6 + 0.2 * n_flags)
    ratios = [3.0, 3.0, 0.45, 0.45, 0.5 + 0.3 * n_flags]
    axes = fig.subplots(5, 1, sharex=True, gridspec_kw={"height_ratios": ratios})
    ax_v, ax_w, ax_m, ax_s, ax_f = axes
    if len(c) == 0:
        _no_data(ax_v, "no tick")
    plot_commands(ax_v, ax_w, t, c.v_mps, c.w_radps, vy=c.vy_mps, logged=_logged(data), span=span,
                  columns=COLUMNS)
    strips: tuple[tuple[Axes, NDArray[np.str_], Mapping[str, str], str, LegendLoc], ...] = (
        (ax_m, c.modes, MODE_COLORS, "GND mode", "outside right upper"),
        (ax_s, c.situations, SITUATION_COLORS, "ND+ situation", "outside right center"),
    )
    legends: list[SideLegend] = []
    for ax, labels, colors, name, where in strips:
        plot_bands(ax, t, labels, colors=colors, legend=False, min_width=_min_width(span))
        ax.set_ylabel(name.split()[-1], rotation=0, ha="right", va="center", fontsize=8)
        handles, names = ax.get_legend_handles_labels()
        if handles:
            legends.append((handles, names, name, where))
    plot_flags(ax_f, t, c.flags)
    left = max(0.9, _text_in(fig, flag_labels(c.flags), 7.0) + 0.2)
    _fit_rows(fig, ratios, left=left, right=0.2, bottom=0.5, top=0.3, legends=tuple(legends))
    ax_f.set_xlabel("time since the first scan [s]")
    ax_f.set_xlim(*span)
    ax_v.set_title(f"Motion commands ({len(c)} ticks{_window_title(data.window)}{_envelope_note(len(c))})",
                   fontsize=10)
    return fig


def figure_modes(data: RunData) -> Figure:
    """The assisted-navigation audit: v and w over time with each takeover shaded, bands of the desired and
    the active navigation mode, and a band per reflexive override in the colour of its rule (an episode
    of one tick still a visible mark)."""
    c = data.commands
    t = c.t_s - time_origin(data)
    span = _time_axis(data, t)
    min_width = _min_width(span)
    fig = _new_figure(12.0, 4.8)
    ratios = [3.0, 0.45, 0.45, 0.45]
    ax_c, ax_d, ax_a, ax_r = fig.subplots(4, 1, sharex=True, gridspec_kw={"height_ratios": ratios})
    if len(c) == 0:
        _no_data(ax_c, "no tick")
    for y, key, label in ((c.v_mps, "v", "v [m/s]"), (c.w_radps, "w", "w [rad/s]")):
        plot_series(ax_c, t, y, span=span, columns=COLUMNS, color=COMMAND_COLORS[key], label=label)
    ax_c.axhline(0.0, color="0.6", linewidth=0.6, zorder=0)
    ax_c.grid(True, linewidth=0.3, alpha=0.6)
    taken = np.where(c.active != c.desired, "takeover", "")
    shaded = band_spans(t, taken, min_width=min_width)
    _shade(ax_c, shaded, "takeover", color="#e41a1c", alpha=0.15)
    ax_c.legend(loc="upper right", fontsize=7, ncol=3)
    rules = np.where(np.isin(c.modes, REFLEXIVE_MODES), c.modes, "")
    strips: tuple[tuple[Axes, NDArray[np.str_], Mapping[str, str], str], ...] = (
        (ax_d, c.desired, NAV_MODE_COLORS, "desired"),
        (ax_a, c.active, NAV_MODE_COLORS, "active"),
        (ax_r, rules, MODE_COLORS, "reflexive"),
    )
    for ax, labels, colors, name in strips:
        plot_bands(ax, t, labels, colors=colors, legend=False, skip=("",), min_width=min_width)
        ax.set_ylabel(name, rotation=0, ha="right", va="center", fontsize=8)
    sides: tuple[tuple[Axes, str, LegendLoc], ...] = (
        (ax_a, "navigation mode", "outside right upper"), (ax_r, "reflexive rule", "outside right center"))
    legends = tuple((*ax.get_legend_handles_labels(), title, where) for ax, title, where in sides)
    _fit_rows(fig, ratios, left=0.85, right=0.2, bottom=0.5, top=0.3, gap_in=0.12,
              legends=tuple(lg for lg in legends if lg[0]))
    if not np.any(rules != ""):
        ax_r.text(0.5, 0.5, "no reflexive override", transform=ax_r.transAxes, ha="center", va="center",
                  fontsize=7, color="0.4")
    ax_r.set_xlabel("time since the first scan [s]")
    ax_r.set_xlim(*span)
    n_taken, n_reflex = int(np.count_nonzero(taken != "")), int(np.count_nonzero(rules != ""))
    n_episodes = int(np.count_nonzero(shaded.labels == "takeover"))
    n_rules = len(episodes(rules.tolist()))
    ax_c.set_title(f"Interventions{_window_title(data.window)}: {n_episodes} takeover"
                   f"{'s' * (n_episodes != 1)} ({n_taken} ticks), {n_rules} reflexive override"
                   f"{'s' * (n_rules != 1)} ({n_reflex} ticks){_envelope_note(len(c))}", fontsize=10)
    return fig


def _shade(ax: Axes, bands: Bands, label: str, *, legend: str | None = None, **style: Any) -> None:
    """Shade the ``label`` bands of ``bands`` (``band_spans``) across ``ax``, the first one named in the
    legend (``legend``, default the label)."""
    for k, i in enumerate(np.flatnonzero(bands.labels == label)):
        x0 = float(bands.x0[i])
        ax.axvspan(x0, x0 + float(bands.width[i]), linewidth=0, label=(legend or label) if k == 0 else None,
                   **style)


def figure_error(data: RunData) -> Figure:
    """The position and heading error of the odometry and the corrected trajectory against the ground truth
    over time, each after its SE(2) alignment (``truth_errors``), with the MATCH_FAILED ticks shaded and
    marked below (commands.csv's flags)."""
    errors = truth_errors(data) or {}
    c = data.commands
    origin = time_origin(data)
    failed = np.asarray(c.flags.get("MATCH_FAILED", np.zeros(len(c), dtype=bool)), dtype=bool)
    t_ticks = c.t_s - origin
    series = {name: ((e.t_ns / 1e9) - origin, e) for name, e in errors.items()}
    t_all = np.concatenate([t_ticks, *(t for t, _ in series.values())]) if series else t_ticks
    span = _time_axis(data, np.sort(t_all))
    fig = _new_figure(12.0, 6.2)
    ratios = [3.0, 3.0, 0.5]
    ax_p, ax_h, ax_f = fig.subplots(3, 1, sharex=True, gridspec_kw={"height_ratios": ratios})
    bands = band_spans(t_ticks, np.where(failed, "failed", ""), min_width=_min_width(span))
    for ax in (ax_p, ax_h):
        _shade(ax, bands, "failed", legend="MATCH_FAILED", color=FLAG_COLORS["MATCH_FAILED"], alpha=0.12,
               zorder=0)
    styles = {"odometry": (_RAW, "raw odometry"), "corrected": (_CORRECTED, "corrected")}
    for name, (t, e) in series.items():
        color, label = styles[name]
        plot_series(ax_p, t, e.ate_m, span=span, columns=COLUMNS, color=color,
                    label=f"{label} (RMSE {e.ate_rmse_m:.3f} m, max {e.ate_max_m:.3f} m)")
        plot_series(ax_h, t, e.yaw_err_deg, span=span, columns=COLUMNS, color=color, label=label)
    if not series:
        _no_data(ax_p, "no ground truth")
    ax_h.axhline(0.0, color="0.6", linewidth=0.6, zorder=0)
    for ax, unit in ((ax_p, "position error [m]"), (ax_h, "heading error [deg]")):
        ax.set_ylabel(unit)
        ax.grid(True, linewidth=0.3, alpha=0.6)
    if series or np.any(failed):
        ax_p.legend(loc="best", fontsize=8)
    ax_p.set_ylim(bottom=0.0)
    plot_flags(ax_f, t_ticks, {"MATCH_FAILED": failed})
    _fit_rows(fig, ratios, left=max(0.9, _text_in(fig, flag_labels({"MATCH_FAILED": failed}), 7.0) + 0.2),
              right=0.2, bottom=0.5, top=0.3, gap_in=0.12)
    ax_f.set_xlabel("time since the first scan [s]")
    ax_f.set_xlim(*span)
    ax_p.set_title(f"Error against the ground truth, each trajectory aligned to it (SE(2) least squares)"
                   f"{_window_title(data.window)}: {int(np.count_nonzero(failed))} of {len(c)} ticks "
                   "MATCH_FAILED", fontsize=10)
    return fig


def _timing_stats(ms: NDArray[np.float64], budget: float | None) -> str:
    if ms.size == 0:
        return ""
    q = np.percentile(ms, [50, 99])
    text = f"median {q[0]:.2f}, p99 {q[1]:.2f}, max {ms.max():.1f} ms"
    if budget is not None:
        text += f"; budget {budget:g} ms, over it: {int(np.count_nonzero(ms > budget))} ticks"
    return text


def figure_timing(data: RunData) -> Figure:
    """Fig. 5e: per-module time per tick (one panel each, shared log axis), with each module's budget and
    the scan period; the last panel is the total (match + model + planner + reactor + supervisor)."""
    from matplotlib.lines import Line2D

    tm = data.timing
    t = tm.t_s - time_origin(data)
    modules = [m for m in (*TIMING_MODULES, "total") if m in tm.ms]
    fig = _new_figure(12.0, 1.3 + 1.35 * len(modules))
    axes = np.atleast_1d(fig.subplots(len(modules), 1, sharex=True, sharey=True))
    _fit_rows(fig, [1.0] * len(modules), left=0.85, right=0.2, bottom=0.75, top=0.3, gap_in=0.12)
    period = scan_period_s(data.traj_corrected[:, 0])
    if period is None:
        period = scan_period_s(tm.t_s)
    period_ms = None if period is None else 1e3 * period
    budgets = budgets_ms(data.summary)
    span = _time_axis(data, t)
    columns = _pixel_columns(fig, axes[0])
    for ax, m in zip(axes, modules, strict=True):
        b = budgets.get(m)
        plot_timing(ax, t, {m: tm.ms[m]}, budgets_ms={m: b} if b else None, scan_period_ms=period_ms,
                    ylabel=f"{m} [ms]", span=span, columns=columns)
        ax.text(0.005, 0.96, _timing_stats(tm.ms[m], b), transform=ax.transAxes, ha="left", va="top",
                fontsize=8, bbox={"facecolor": "white", "edgecolor": "none", "alpha": 0.8, "pad": 1.5})
    if t.size == 0:
        _no_data(axes[0], "no tick")
    axes[-1].set_xlim(*span)
    top = max([float(np.max(tm.ms[m])) for m in modules if tm.ms[m].size] + [period_ms or 1.0, 1.0])
    axes[0].set_ylim(top=top * 3.0)
    axes[-1].set_xlabel("time since the first scan [s]")
    axes[0].set_title(f"Computation time per tick{_window_title(data.window)}", fontsize=10)
    proxies = [Line2D([], [], color="0.3", linewidth=0.8, label="time per tick"),
               Line2D([], [], color="0.3", linestyle="--", linewidth=1.0, label="budget (time-out)")]
    if period_ms is not None:
        proxies.append(Line2D([], [], color="black", linestyle=":", linewidth=1.2,
                              label=f"scan period {period_ms:.0f} ms"))
    fig.legend(handles=proxies, loc="lower center", bbox_to_anchor=(0.5, 0.0), ncol=len(proxies), fontsize=8,
               frameon=False)
    return fig


def save_figure(fig: Figure, path: Path, *, dpi: int = DPI) -> Path:
    """Save as PNG at ``dpi`` with no metadata (byte-identical for the same figure), atomically: a failure
    leaves the previous file (or none), never half a PNG. zlib's fastest level: a third less time than its
    default for files about a tenth larger."""
    with atomic_path(Path(path)) as tmp:
        fig.savefig(tmp, dpi=dpi, format="png", metadata={"Software": None},
                    pil_kwargs={"compress_level": PNG_COMPRESS_LEVEL})
    return path


#: The figures ``build_figures`` draws, by file name.
FIGURE_MAKERS: Mapping[str, Callable[[RunData], Figure]] = {
    "fig_model.png": figure_model,
    "fig_raw.png": figure_raw,
    "fig_commands.png": figure_commands,
    "fig_timing.png": figure_timing,
    "fig_modes.png": figure_modes,
    "fig_error.png": figure_error,
}
#: Figures drawn only when the run has ground truth (trajectory_truth.tum).
TRUTH_FIGURES = ("fig_error.png",)


def window_figure_name(name: str, window: TimeWindow) -> str:
    """The file a figure of a window is written to: ``fig_commands.png`` -> ``fig_commands_<from>-<to>.png``
    (never the whole run's file)."""
    stem, dot, ext = name.rpartition(".")
    return f"{stem}_{window.tag}{dot}{ext}"


def figure_names(window: TimeWindow | None, *, truth: bool = False) -> dict[str, Callable[[RunData], Figure]]:
    """The files ``build_figures`` writes for the whole run (``FIGURE_MAKERS``; ``TRUTH_FIGURES`` only with
    ``truth``) or for a window (``WINDOW_FIGURES``, named by ``window_figure_name``), with their makers."""
    if window is None:
        return {n: make for n, make in FIGURE_MAKERS.items() if truth or n not in TRUTH_FIGURES}
    return {window_figure_name(n, window): FIGURE_MAKERS[n] for n in WINDOW_FIGURES}


#: Relative cost of drawing each figure, about a tenth of a second each on the Intel log (``build_figures``
#: shares them out between two processes by it).
FIGURE_WEIGHTS: Mapping[Callable[[RunData], Figure], float] = {
    figure_model: 1.4, figure_raw: 1.2, figure_commands: 2.2, figure_timing: 2.0, figure_modes: 1.3,
    figure_error: 1.5,
}


def import_agg() -> None:
    """Import matplotlib's Figure and Agg canvas (before the drawing is split, so that it is paid once)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: F401
    from matplotlib.figure import Figure  # noqa: F401


def build_figures(data: RunData, out_dir: Path, *, dpi: int = DPI, split: bool | None = None) -> list[Path]:
    """Draw the figures of ``data`` into ``out_dir`` under the names of ``figure_names`` (fig_error.png when
    the run has ground truth), replacing earlier ones (the caller checks they are gndreplay's:
    ``fsutil.check_may_write``). ``split``: draw some in a second process (``split.run_split``; None:
    where two CPUs are free); the files are the same bytes either way."""
    from functools import partial

    from .split import run_split

    def draw(make: Callable[[RunData], Figure], path: Path) -> None:
        save_figure(make(data), path, dpi=dpi)

    makers = figure_names(data.window, truth=data.has_truth)
    paths = [Path(out_dir) / name for name in makers]
    import_agg()
    run_split([partial(draw, make, path) for make, path in zip(makers.values(), paths, strict=True)],
              [FIGURE_WEIGHTS.get(make, 2.0) for make in makers.values()], split=split)
    return paths
