"""fig_world.png: the true world of a closed-loop run (a map's occupied cells as an image under their
boundary, drawn as one line collection however many edges), the trajectory with the footprint every second,
events (elements that appear, vanish or move drawn dashed), movers' paths and positions, the contact; in
the multi-loop modes the subgoals (arrows), the operator's track (dashed) and, thick, the stretches driven
by local navigation (as the multi-loop paper's Fig. 7)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..geometry import compose
from ..robot import footprint_outline

if TYPE_CHECKING:
    from .closedloop import ClosedLoop
    from .scenario_file import Element


def _draw_map(ax: Any, e: Element, style: dict[str, Any]) -> None:
    """A map element: its obstacle cells as an image (the unknown ones lighter, free cells transparent)
    and their boundary."""
    from matplotlib.collections import LineCollection
    from matplotlib.colors import ListedColormap
    from matplotlib.transforms import Affine2D

    grid, groups = e.grid, e.groups
    if grid is None or groups is None:
        return
    ox, oy, yaw = grid.origin
    h, w = grid.occupied.shape
    res = grid.resolution_m
    place = Affine2D().rotate_around(ox, oy, yaw) + ax.transData
    shade = grid.occupied.astype(np.uint8) * 2
    if grid.unknown is not None:
        shade[grid.occupied & grid.unknown] = 1
    ax.imshow(shade, origin="lower", extent=(ox, ox + w * res, oy, oy + h * res), interpolation="nearest",
              cmap=ListedColormap([(1.0, 1.0, 1.0, 0.0), "#e4e4e4", style["facecolor"]]), vmin=0, vmax=2,
              transform=place, zorder=0.5)
    segs = list(groups.edges.reshape(-1, 2, 2))
    ax.add_collection(LineCollection(segs, colors=style["edgecolor"], linewidths=0.5,
                                     linestyles=style.get("ls", "-")), autolim=True)


def _draw_modes(ax: Any, loop: ClosedLoop, truth: np.ndarray, tt: np.ndarray) -> None:
    """Subgoals, the teleop track, and the local-navigation stretches of the trajectory (thick)."""
    for k, g in enumerate(loop.spec.subgoals):
        ax.arrow(g.x, g.y, 0.4 * math.cos(g.theta), 0.4 * math.sin(g.theta), width=0.02, color="#a65628",
                 label="subgoals" if k == 0 else None)
        ax.annotate(f"sg{k}{' stop' if g.kind == 'stop' else ''}", (g.x, g.y), fontsize=6, color="#a65628")
    tel = loop.spec.teleop
    if tel is not None and tel.track is not None:
        ax.plot(tel.track[:, 0], tel.track[:, 1], "--", color="#999999", lw=0.8, label="operator's track")
    period = loop.period_ns / 1e9
    first = True
    for mode, a, b in loop.rec.mode_stretches:
        if mode != "local" or mode == loop.nav_mode or not len(tt):
            continue
        sel = (tt >= a) & (tt <= b + period)
        ax.plot(truth[sel, 0], truth[sel, 1], "-", color="#e41a1c", lw=3.0, alpha=0.7,
                label="local navigation" if first else None)
        first = False


def draw_world(path: Path, loop: ClosedLoop, result: dict[str, Any]) -> Path:
    """Draw and save the figure; returns ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle, Polygon

    spec = loop.spec
    rec = loop.rec
    fig = Figure(figsize=(9, 7))
    ax = fig.add_subplot(1, 1, 1)
    ax.set_aspect("equal")
    t_end = result["end_time_s"] or 0.0
    for e in spec.elements:
        changes = e.appear_s is not None or e.remove_s is not None or bool(e.door)
        style: dict[str, Any] = {"facecolor": "#bbbbbb", "edgecolor": "#333333", "lw": 0.8}
        if changes:
            style = {"facecolor": "none", "edgecolor": "#984ea3", "lw": 1.0, "ls": "--"}
        if e.grid is not None:
            _draw_map(ax, e, style)
        elif e.circle is not None:
            ax.add_patch(Circle(e.circle[:2], e.circle[2], **style))
        elif e.vertices is not None:
            if e.door:  # the leaf open and closed
                for t in (0.0, t_end):
                    v = e.outline_at(t)
                    if isinstance(v, np.ndarray) and len(v) >= 2:
                        ax.add_patch(Polygon(v, closed=True, **style))
                for a in e.door:
                    ax.annotate(f"{'close' if a.closed else 'open'} {a.t0_s:g}s", e.vertices[0],
                                fontsize=6, color="#984ea3")
            else:
                ax.add_patch(Polygon(e.vertices, closed=True, **style))
            if e.appear_s is not None or e.remove_s is not None:
                label = (f"+{e.appear_s:g}s" if e.appear_s is not None else "") + (
                    f" -{e.remove_s:g}s" if e.remove_s is not None else "")
                ax.annotate(label.strip(), e.vertices.mean(axis=0), fontsize=6, color="#984ea3")
    for j, m in enumerate(spec.movers):
        p = np.vstack([m.path, m.path[:1]]) if m.loop else m.path
        ax.plot(p[:, 0], p[:, 1], ":", color="#ff7f00", lw=0.8)
        if rec.movers_xy:
            xy = np.array([row[j] for row in rec.movers_xy])
            ax.plot(xy[:, 0], xy[:, 1], ".", color="#ff7f00", ms=2)
            ax.add_patch(Circle(tuple(xy[-1]), m.radius_m, facecolor="#fdd0a2", edgecolor="#ff7f00"))
        ax.annotate(m.id, tuple(m.path[0]), fontsize=6, color="#ff7f00")
    truth = np.asarray(rec.truth).reshape(-1, 3)
    tt = np.asarray(rec.truth_t)
    ax.plot(truth[:, 0], truth[:, 1], "-", color="#377eb8", lw=1.2, label="trajectory (truth)")
    _draw_modes(ax, loop, truth, tt)
    outline = footprint_outline(loop.cfg.robot)
    local = np.column_stack([outline, np.zeros(len(outline))])
    for t in np.arange(0.0, (tt[-1] if len(tt) else 0.0) + 1e-9, 1.0):
        k = min(int(np.searchsorted(tt, t)), len(truth) - 1)
        world = compose(truth[k], local)[:, :2]
        ax.add_patch(Polygon(world, closed=True, facecolor="none", edgecolor="#377eb8", lw=0.4, alpha=0.6))
    if len(truth):
        world = compose(truth[-1], local)[:, :2]
        ax.add_patch(Polygon(world, closed=True, facecolor="#9ecae1", edgecolor="#08519c", lw=1.0))
    sx, sy, sth = spec.start
    ax.plot([sx], [sy], "o", color="#4daf4a", label="start")
    ax.arrow(sx, sy, 0.5 * math.cos(sth), 0.5 * math.sin(sth), width=0.03, color="#4daf4a")
    ax.plot([spec.goal[0]], [spec.goal[1]], "*", ms=14, color="#e41a1c", label="goal")
    c = result.get("collision")
    if c:
        ax.plot([c["contact_world"][0]], [c["contact_world"][1]], "x", ms=12, mew=2.5, color="#e41a1c",
                label=f"contact with {c['object']} at {c['t_s']:.2f} s")
    ax.autoscale_view()
    ax.set_title(f"{spec.name} ({loop.cfg.preset}, seed {loop.seed}): {result['outcome']} "
                 f"at {t_end:.1f} s", fontsize=10)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.legend(loc="best", fontsize=7)
    ax.grid(True, lw=0.3, alpha=0.5)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    return path
