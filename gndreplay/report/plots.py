"""Plot functions: each draws on a matplotlib ``Axes`` it is given, returns None and never opens a window.

Arrays are positional, options keyword-only. Colours of modes, situations and modules are fixed here so every
figure and report agrees.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .rundir import runs, tick_edges  # one definition of runs and tick spans, shared with the audit

if TYPE_CHECKING:
    from matplotlib.axes import Axes

__all__ = [
    "COMMAND_COLORS",
    "FLAG_COLORS",
    "FLAG_ORDER",
    "MIN_BAND_FRACTION",
    "MODE_COLORS",
    "MODULE_COLORS",
    "NAV_MODE_COLORS",
    "SITUATION_COLORS",
    "Bands",
    "band_spans",
    "column_envelope",
    "column_extremes",
    "flag_labels",
    "hit_image",
    "plot_bands",
    "plot_commands",
    "plot_flags",
    "plot_grid",
    "plot_hit_raster",
    "plot_pose",
    "plot_series",
    "plot_timing",
    "plot_trajectory",
    "runs",
    "tick_edges",
]

F64 = NDArray[np.float64]

MODE_COLORS: Mapping[str, str] = {
    "mpND": "#4daf4a",
    "mND": "#377eb8",
    "ROTATE": "#ff7f00",
    "SAFE_SLOW": "#fdb462",
    "SAFE_TURN": "#fb8072",
    "SAFE_REVERSE": "#bc80bd",
    "EMERGENCY": "#e41a1c",
    "STALE": "#999999",
    "ESCAPE": "#984ea3",
    "GOAL": "#222222",
    "TELEOP": "#1f78b4",
    "FOLLOW": "#a6761d",
    "LOCAL": "#ff7f00",
}
NAV_MODE_COLORS: Mapping[str, str] = {  # the navigation modes of the multi-loop architecture
    "gnd": "#4daf4a",
    "teleop": "#377eb8",
    "follow": "#a6761d",
    "local": "#ff7f00",
}
SITUATION_COLORS: Mapping[str, str] = {
    "HSGR": "#1b9e77",
    "HSWR": "#66c2a5",
    "HSNR": "#a6d854",
    "LSG": "#fdae61",
    "LS1": "#f46d43",
    "LS2": "#d53e4f",
    "NONE": "#bbbbbb",
}
MODULE_COLORS: Mapping[str, str] = {
    "match": "#984ea3",
    "model": "#377eb8",
    "planner": "#e41a1c",
    "reactor": "#4daf4a",
    "supervisor": "#ff7f00",
    "total": "#222222",
}
FLAG_ORDER: Sequence[str] = (
    "EMERGENCY_STOP",
    "PLANNER_NO_PATH",
    "PLANNER_TIMEOUT",
    "PLANNER_FALLBACK",
    "REACTOR_NO_REGION",
    "GOAL_IN_OBSTACLE",
    "TRAP_DETECTED",
    "STALE_SCAN",
    "GOAL_REACHED",
    "MATCH_FAILED",
    "MATCH_OVER_BUDGET",
    "MODEL_OVER_BUDGET",
    "PLANNER_OVER_BUDGET",
    "REACTOR_OVER_BUDGET",
)
FLAG_COLORS: Mapping[str, str] = {
    "EMERGENCY_STOP": "#e41a1c",
    "PLANNER_NO_PATH": "#377eb8",
    "PLANNER_TIMEOUT": "#377eb8",
    "PLANNER_FALLBACK": "#80b1d3",
    "REACTOR_NO_REGION": "#ff7f00",
    "GOAL_IN_OBSTACLE": "#8c6d31",
    "TRAP_DETECTED": "#984ea3",
    "STALE_SCAN": "#777777",
    "GOAL_REACHED": "#222222",
    "MATCH_FAILED": "#a65628",
    "MATCH_OVER_BUDGET": "#c51b7d",
    "MODEL_OVER_BUDGET": "#c51b7d",
    "PLANNER_OVER_BUDGET": "#c51b7d",
    "REACTOR_OVER_BUDGET": "#c51b7d",
}
_GRID_COLORS = ("#9e9e9e", "#ffffff", "#000000")  # UNKNOWN, FREE, OCCUPIED
#: the stack's command (dark) and the log's recorded one (the same hue, lighter, drawn behind)
COMMAND_COLORS: Mapping[str, str] = {
    "v": "#1f4e79", "w": "#7b1f3a", "vy": "#ff7f00", "log_v": "#9dc3e6", "log_w": "#e3a6b8",
}  # fmt: skip
MIN_BAND_FRACTION = 0.003
"""The narrowest band or shaded episode, as a fraction of the time axis: a one-tick episode of a long run
stays a visible mark (0.003 of an 1800 s axis is 5.4 s, about 3 pixels of a figure 1440 pixels wide)."""


def plot_trajectory(
    ax: Axes,
    xy: ArrayLike,
    *,
    label: str = "",
    style: str = "-",
    color: str | None = None,
    linewidth: float = 1.2,
    alpha: float = 1.0,
    zorder: float = 3.0,
) -> None:
    """A planar trajectory ``xy`` (M, 2) [m] (extra columns are ignored) as one line."""
    p = np.asarray(xy, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] < 2:
        raise ValueError(f"xy must be (M, 2), got shape {p.shape}")
    ax.plot(p[:, 0], p[:, 1], style, label=label or None, color=color, linewidth=linewidth, alpha=alpha,
            zorder=zorder)


def plot_pose(ax: Axes, pose: ArrayLike, *, length_m: float = 0.6, color: str = "#e41a1c", label: str = "",
              zorder: float = 5.0) -> None:
    """A robot pose (x, y, theta) as a dot with a heading arrow of ``length_m``."""
    x, y, th = (float(v) for v in np.asarray(pose, dtype=np.float64)[:3])
    ax.plot([x], [y], "o", color=color, markersize=5, label=label or None, zorder=zorder)
    ax.annotate("", xy=(x + length_m * np.cos(th), y + length_m * np.sin(th)), xytext=(x, y),
                arrowprops={"arrowstyle": "-|>", "color": color, "lw": 1.5}, zorder=zorder)


def hit_image(hits: ArrayLike, *, max_pixels: int = 1600) -> F64:
    """Hit counts (H, W) -> display darkness in [0, 1]: max-pooled so no side exceeds ``max_pixels``
    (thin walls survive the downsampling), then log-scaled and saturated at the 90th percentile of the
    non-zero cells, so walls seen once and walls seen a thousand times are both visible."""
    a = np.asarray(hits)
    if a.ndim != 2:
        raise ValueError(f"hits must be 2-D, got shape {a.shape}")
    f = max(1, -(-max(a.shape) // max_pixels))
    if f > 1:
        h, w = -(-a.shape[0] // f) * f, -(-a.shape[1] // f) * f
        pad = np.zeros((h, w), dtype=a.dtype)
        pad[: a.shape[0], : a.shape[1]] = a
        a = pad.reshape(h // f, f, w // f, f).max(axis=(1, 3))
    v = np.log1p(a.astype(np.float64))
    nz = v[v > 0]
    top = float(np.percentile(nz, 90)) if nz.size else 1.0
    return np.clip(v / max(top, 1e-9), 0.0, 1.0)


Extent = tuple[float, float, float, float]


def plot_hit_raster(ax: Axes, hits: ArrayLike, extent: Extent, *, cmap: str = "Greys",
                    max_pixels: int = 1600) -> None:
    """A hit-count raster (H, W), row 0 at the bottom, covering ``extent`` = (x0, x1, y0, y1) [m]."""
    img = hit_image(hits, max_pixels=max_pixels)
    ax.imshow(img, origin="lower", extent=extent, cmap=cmap, vmin=0.0, vmax=1.0,
              interpolation="nearest", zorder=1)
    ax.set_aspect("equal")


def plot_grid(ax: Axes, cells: ArrayLike, extent: Extent) -> None:
    """A robot-centred grid (N, N) of 0 unknown / 1 free / 2 occupied: grey / white / black."""
    from matplotlib.colors import ListedColormap

    c = np.asarray(cells)
    ax.imshow(c, origin="lower", extent=extent, cmap=ListedColormap(list(_GRID_COLORS)), vmin=-0.5,
              vmax=2.5, interpolation="nearest", zorder=1)
    ax.set_aspect("equal")


@dataclass(frozen=True, slots=True, eq=False)
class Bands:
    """The runs of equal consecutive labels as drawn: (R,) ``labels``, left edge ``x0`` and ``width`` in the
    time axis' unit, and ``widened``: the run was narrower than the minimum width and is drawn at it."""

    labels: NDArray[np.str_]
    x0: F64
    width: F64
    widened: NDArray[np.bool_]


def band_spans(t: ArrayLike, labels: ArrayLike, *, min_width: float = 0.0) -> Bands:
    """The bands of ``labels`` per tick (tick k spans [t_k, t_k+1), ``tick_edges``), one per run of equal
    labels; a run narrower than ``min_width`` is widened to it about its centre, so it stays visible."""
    tt = np.asarray(t, dtype=np.float64)
    lab = np.asarray(labels).astype(str)
    edges = tick_edges(tt)
    start, end = runs(lab)
    x0, width = edges[start], edges[end] - edges[start]
    widened = width < min_width
    return Bands(labels=lab[start], x0=np.where(widened, x0 - 0.5 * (min_width - width), x0),
                 width=np.maximum(width, min_width), widened=widened)


def plot_bands(ax: Axes, t: ArrayLike, labels: ArrayLike, *, colors: Mapping[str, str],
               legend: bool = True, legend_title: str = "", skip: Sequence[str] = (),
               min_width: float = 0.0) -> None:
    """A strip of coloured bands: tick k spans [t_k, t_k+1) in the colour of ``labels[k]``; a run narrower
    than ``min_width`` is drawn at that width, over its neighbours (``band_spans``).

    Labels missing from ``colors`` are drawn grey; labels in ``skip`` are left blank. The legend lists the
    labels present, in ``colors`` order.
    """
    lab = np.asarray(labels).astype(str)
    bands = band_spans(t, lab, min_width=min_width)
    present = [k for k in colors if np.any(lab == k)] + sorted(set(lab.tolist()) - set(colors))
    present = [k for k in present if k not in skip]
    for name in present:  # the legend follows the order drawn; the widened runs lie on top (zorder)
        label: str | None = name
        for widened in (False, True):
            sel = (bands.labels == name) & (bands.widened == widened)
            if np.any(sel):
                ax.broken_barh(list(zip(bands.x0[sel].tolist(), bands.width[sel].tolist(), strict=True)),
                               (0.0, 1.0), facecolors=colors.get(name, "#cccccc"), edgecolor="none",
                               label=label, zorder=1.0 + widened)
                label = None
    ax.set_ylim(0.0, 1.0)
    ax.set_yticks([])
    if legend and present:
        ax.legend(loc="center left", bbox_to_anchor=(1.005, 0.5), fontsize=7, frameon=False,
                  title=legend_title or None, title_fontsize=7, handlelength=1.0, borderaxespad=0.0)


def column_envelope(t: ArrayLike, y: ArrayLike, *, span: tuple[float, float], columns: int
                    ) -> tuple[F64, F64, F64, F64]:
    """A per-tick series (each value holds from its tick until the next) summarised over ``columns`` equal
    columns of the time ``span``: the (columns + 1,) column edges and, per column, the minimum, maximum
    and mean of the values it shows (its ticks' values and the one held into it from before; NaN values
    ignored). A column without a tick holds the value before it; NaN before the first tick. ``t`` ascending.
    """
    tt, yy = np.asarray(t, dtype=np.float64), np.asarray(y, dtype=np.float64)
    t0, t1 = span
    x = np.linspace(t0, t1, columns + 1)
    col = np.floor((tt - t0) * (columns / max(t1 - t0, 1e-12))).astype(np.intp)
    keep = (col >= 0) & (col < columns)
    tt, yy, col = tt[keep], yy[keep], col[keep]
    lo, hi, mean = np.full(columns, np.nan), np.full(columns, np.nan), np.full(columns, np.nan)
    if col.size == 0:
        return x, lo, hi, mean
    first = np.flatnonzero(np.r_[True, col[1:] != col[:-1]])
    cols = col[first]
    ok = np.isfinite(yy)
    count = np.add.reduceat(ok.astype(np.int64), first)
    total = np.add.reduceat(np.where(ok, yy, 0.0), first)
    mean[cols] = np.where(count > 0, total / np.maximum(count, 1), np.nan)
    held = np.r_[np.nan, yy][first]  # the value held into each column with ticks (NaN before the first)
    with np.errstate(invalid="ignore"):
        lo[cols] = np.fmin(np.fmin.reduceat(yy, first), held)
        hi[cols] = np.fmax(np.fmax.reduceat(yy, first), held)
    last = np.searchsorted(col, np.arange(columns), side="left") - 1  # the last tick before each column
    empty = np.ones(columns, dtype=bool)
    empty[cols] = False
    hold = empty & (last >= 0)
    lo[hold] = hi[hold] = mean[hold] = yy[last[hold]]
    return x, lo, hi, mean


def column_extremes(t: ArrayLike, y: ArrayLike, *, span: tuple[float, float], columns: int
                    ) -> NDArray[np.intp]:
    """The indices of the points of a line (``t`` ascending) that keep its look at ``columns`` pixel columns
    of ``span``: in each column its first and last point and those of its least and largest value (NaN
    ignored), in time order, so a one-tick spike is drawn as the full line draws it. At most 4 per column
    (and per stretch before and after the span)."""
    tt, yy = np.asarray(t, dtype=np.float64), np.asarray(y, dtype=np.float64)
    n = tt.size
    if n <= 4 * columns:
        return np.arange(n)
    t0, t1 = span
    col = np.clip(np.floor((tt - t0) * (columns / max(t1 - t0, 1e-12))), -1, columns).astype(np.intp)
    first = np.flatnonzero(np.r_[True, col[1:] != col[:-1]])
    last = np.r_[first[1:], n] - 1
    size = last - first + 1
    group = np.repeat(np.arange(first.size), size)
    finite = np.isfinite(yy)
    low = np.where(finite, yy, np.inf)
    high = np.where(finite, yy, -np.inf)
    lo_at = first + _first_true(low == np.repeat(np.minimum.reduceat(low, first), size), group, first.size)
    hi_at = first + _first_true(high == np.repeat(np.maximum.reduceat(high, first), size), group, first.size)
    return np.unique(np.concatenate([first, last, lo_at, hi_at]))


def _first_true(mask: NDArray[np.bool_], group: NDArray[np.intp], groups: int) -> NDArray[np.intp]:
    """Per group (``group``: ascending, contiguous), the offset in it of its first True (0 when none)."""
    start = np.searchsorted(group, np.arange(groups))
    hit = np.flatnonzero(mask)
    g, k = np.unique(group[hit], return_index=True)
    out = np.zeros(groups, dtype=np.intp)
    out[g] = hit[k] - start[g]
    return out


def plot_series(ax: Axes, t: ArrayLike, y: ArrayLike, *, span: tuple[float, float], columns: int,
                color: str, label: str | None = None, linewidth: float = 0.8, zorder: float = 2.0) -> None:
    """A per-tick series as a step line (a value holds until the next tick); with more ticks than
    ``columns`` (pixel columns), its range per column shaded and its mean per column as the line
    (``column_envelope``), so a long run is its trend and spread, not a solid block."""
    tt, yy = np.asarray(t, dtype=np.float64), np.asarray(y, dtype=np.float64)
    if tt.size <= columns:
        ax.step(tt, yy, where="post", color=color, linewidth=linewidth, label=label, zorder=zorder)
        return
    x, lo, hi, mean = column_envelope(tt, yy, span=span, columns=columns)
    ax.fill_between(x, np.r_[lo, lo[-1]], np.r_[hi, hi[-1]], step="post", color=color, alpha=0.35,
                    linewidth=0.0, zorder=zorder)
    ax.step(x, np.r_[mean, mean[-1]], where="post", color=color, linewidth=linewidth, label=label,
            zorder=zorder)


def plot_commands(ax_v: Axes, ax_w: Axes, t: ArrayLike, v: ArrayLike, w: ArrayLike, *,
                  vy: ArrayLike | None = None, logged: tuple[ArrayLike, ArrayLike] | None = None,
                  span: tuple[float, float] | None = None, columns: int = 1000) -> None:
    """v [m/s] (and vy when given and not all zero) on ``ax_v`` and w [rad/s] on ``ax_w`` as step lines (a
    command holds until the next tick), over ``span`` (default: the first tick to the end of the last);
    ``logged``: the log's recorded (v, w) per tick (NaN where none), drawn behind in lighter colours.
    More ticks than ``columns``: each series as its range and mean per column (``plot_series``)."""
    tt = np.asarray(t, dtype=np.float64)
    if span is None:
        edges = tick_edges(tt)
        span = (float(edges[0]), float(edges[-1]))
    series: list[tuple[Axes, ArrayLike, str, str, float]] = []  # axes, values, colour, label, line width
    if logged is not None:
        series += [(ax, y, COMMAND_COLORS[key], f"{key[-1]} recorded in the log", 1.2)
                   for ax, y, key in ((ax_v, logged[0], "log_v"), (ax_w, logged[1], "log_w"))
                   if np.any(np.isfinite(np.asarray(y, dtype=np.float64)))]
    series += [(ax_v, v, COMMAND_COLORS["v"], "v", 0.8), (ax_w, w, COMMAND_COLORS["w"], "w", 0.8)]
    if vy is not None and np.any(np.asarray(vy) != 0.0):
        series.append((ax_v, vy, COMMAND_COLORS["vy"], "vy", 0.8))
    for z, (ax, y, color, label, lw) in enumerate(series):  # in order: the log's behind the stack's
        plot_series(ax, tt, y, span=span, columns=columns, color=color, label=label, linewidth=lw,
                    zorder=1.5 + 0.1 * z)
    for ax, name in ((ax_v, "v [m/s]"), (ax_w, "w [rad/s]")):
        ax.axhline(0.0, color="0.6", linewidth=0.6, zorder=0)
        ax.set_ylabel(name)
        ax.grid(True, linewidth=0.3, alpha=0.6)
        handles, labels = ax.get_legend_handles_labels()
        if len(handles) > 1:  # the stack's command first, then the log's
            order = sorted(range(len(labels)), key=lambda i: "recorded" in labels[i])
            ax.legend([handles[i] for i in order], [labels[i] for i in order], loc="upper right", fontsize=7,
                      ncol=3)


def _fired(flags: Mapping[str, ArrayLike], order: Sequence[str]) -> list[str]:
    names = [n for n in order if n in flags and np.any(flags[n])]
    return names + sorted(n for n in flags if n not in order and np.any(flags[n]))


def flag_labels(flags: Mapping[str, ArrayLike], *, order: Sequence[str] = FLAG_ORDER) -> list[str]:
    """The row labels ``plot_flags`` gives the flags that fired: name and count of ticks."""
    return [f"{n} ({int(np.count_nonzero(flags[n]))})" for n in _fired(flags, order)]


def plot_flags(ax: Axes, t: ArrayLike, flags: Mapping[str, ArrayLike], *,
               order: Sequence[str] = FLAG_ORDER) -> None:
    """One row per flag that fired, a tick mark at each tick where it did (flags in ``order`` first)."""
    tt = np.asarray(t, dtype=np.float64)
    names = _fired(flags, order)
    if not names:
        ax.text(0.5, 0.5, "no flag fired", transform=ax.transAxes, ha="center", va="center", fontsize=8,
                color="0.4")
        ax.set_yticks([])
        return
    pos = [tt[np.asarray(flags[n], dtype=bool)] for n in names]
    offsets = [float(len(names) - 1 - k) for k in range(len(names))]
    ax.eventplot(pos, lineoffsets=offsets, linelengths=0.7, linewidths=0.8,
                 colors=[FLAG_COLORS.get(n, "#555555") for n in names])
    ax.set_yticks(offsets, flag_labels(flags, order=order), fontsize=7)
    ax.set_ylim(-0.6, len(names) - 0.4)
    ax.grid(True, axis="x", linewidth=0.3, alpha=0.6)


def plot_timing(ax: Axes, t: ArrayLike, timings_ms: Mapping[str, ArrayLike], *,
                budgets_ms: Mapping[str, float] | None = None, scan_period_ms: float | None = None,
                floor_ms: float = 1e-3, ylabel: str = "time per tick [ms]",
                span: tuple[float, float] | None = None, columns: int = 0) -> None:
    """Per-module computation time [ms] per tick on a log axis (values below ``floor_ms`` are drawn at it),
    each module's budget as a dashed line of its colour (one grey line for modules sharing a budget), and
    the scan period as a dotted black line. A "total" series is drawn fainter, behind the modules.
    With ``columns`` (the axes' pixel columns over ``span``), each line keeps only the points that show
    at that width (``column_extremes``: every spike stays). Tick labels are plain numbers (0.01, 1, 100)."""
    from matplotlib.ticker import FuncFormatter

    tt = np.asarray(t, dtype=np.float64)
    for name, ms in timings_ms.items():
        y = np.maximum(np.asarray(ms, dtype=np.float64), floor_ms)
        x = tt
        if columns > 0 and span is not None and tt.size == y.size:
            keep = column_extremes(tt, y, span=span, columns=columns)
            x, y = tt[keep], y[keep]
        ax.plot(x, y, color=MODULE_COLORS.get(name), linewidth=0.6 if name != "total" else 0.5,
                alpha=0.85 if name != "total" else 0.45, label=name, zorder=2 if name != "total" else 1.5)
    same: dict[float, list[str]] = {}  # modules sharing a budget share one line
    for name, b in (budgets_ms or {}).items():
        if b and np.isfinite(b):
            same.setdefault(float(b), []).append(name)
    for b, names in same.items():
        color = MODULE_COLORS.get(names[0], "0.3") if len(names) == 1 else "0.35"
        label = f"{' + '.join(names)} budget {b:g} ms"
        ax.axhline(b, color=color, linestyle="--", linewidth=1.0, label=label)
    if scan_period_ms is not None and np.isfinite(scan_period_ms) and scan_period_ms > 0:
        ax.axhline(scan_period_ms, color="black", linestyle=":", linewidth=1.2,
                   label=f"scan period {scan_period_ms:.0f} ms")
    ax.set_yscale("log")
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    ax.set_ylabel(ylabel)
    ax.grid(True, which="major", linewidth=0.3, alpha=0.6)
