"""``animate_run``: the decision view (``report.decision``) tick after tick over a window of a run, as a GIF
(Pillow) or an MP4 (when ffmpeg is installed).

The frames come from the run directory's results.mcap (``gndreplay run --mcap``): the corrected pose and
the command (/gndreplay/odom, /cmd_vel), the goal, the planned path, the robot-centred grid (the latest one:
it is recorded at intervals), mode, situation, flags, the active mode and the takeover reason, and the scan
when the file has a sensor_msgs/LaserScan topic (placed with /tf_static). The robot and the stack's settings
come from the run's config.toml. The frames show ND+'s diagram of the grid (sectors, gaps, security zone)
without its chosen region and direction (the /gndreplay/decision markers hold them; they are not read here).

Memory stays bounded: the file is read as a stream, one tick's messages at a time, and each frame goes to
the encoder as it is drawn (the GIF is written frame by frame, ``_gif_stream``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from io import BytesIO
from pathlib import Path
from typing import IO, Any

import numpy as np
from numpy.typing import NDArray

from ..config import load_config
from ..errors import ConfigError, OutputError
from ..fsutil import add_to_marker, atomic_path, check_may_write
from ..geometry import transform_points, wrap_angle
from ..types import NS_PER_S, Command, Pose2D
from .decision import DecisionInput, clear_decision, decision_figure, decision_view, draw_decision
from .mcap_export import MCAP_FILE
from .rundir import CONFIG_FILE, RunDirError

__all__ = ["ANIMATION_FILE", "ANIMATION_SUFFIXES", "animate_run"]

ANIMATION_FILE = "animation.gif"
"""The animation's default name in the run directory."""
ANIMATION_SUFFIXES = (".gif", ".mp4")
LASERSCAN = "sensor_msgs/msg/LaserScan"
#: topics of results.mcap a frame needs
_TICK_TOPICS = ("/gndreplay/odom", "/cmd_vel", "/gndreplay/goal", "/gndreplay/mode", "/gndreplay/situation",
                "/gndreplay/flags", "/gndreplay/active_mode", "/gndreplay/takeover")
_HELD_TOPICS = ("/gndreplay/grid", "/gndreplay/path")  # recorded at intervals: the latest one holds
_TICK = "/gndreplay/odom"


def _yaw(q: Any) -> float:
    return float(wrap_angle(2.0 * math.atan2(float(q.z), float(q.w))))


def _grid_cells(msg: Any) -> tuple[NDArray[np.uint8], tuple[float, float], float]:
    """An OccupancyGrid (-1 / 0 / 100) as 0 unknown / 1 free / 2 occupied cells, origin and cell side."""
    info = msg.info
    data = np.asarray(msg.data, dtype=np.int16).reshape(int(info.height), int(info.width))
    cells = np.where(data < 0, 0, np.where(data >= 50, 2, 1)).astype(np.uint8)
    return cells, (float(info.origin.position.x), float(info.origin.position.y)), float(info.resolution)


def _scan_points(msg: Any, laser: tuple[float, float, float]) -> NDArray[np.float64]:
    """A LaserScan's hits in the robot frame (the laser at ``laser`` on the robot)."""
    r = np.asarray(msg.ranges, dtype=np.float64)
    a = float(msg.angle_min) + float(msg.angle_increment) * np.arange(r.size)
    ok = np.isfinite(r) & (r >= float(msg.range_min)) & (r < float(msg.range_max))
    pts = np.column_stack([r[ok] * np.cos(a[ok]), r[ok] * np.sin(a[ok])])
    return transform_points(np.asarray(laser, dtype=np.float64), pts)


def _gif_stream(fps: float) -> Any:
    """A matplotlib movie writer writing a looping GIF frame by frame through Pillow's GIF encoder (each
    frame with its own 256-colour palette), so memory does not grow with the number of frames
    (matplotlib's PillowWriter keeps every frame until the end)."""
    from matplotlib.animation import AbstractMovieWriter

    class GifStream(AbstractMovieWriter):
        def setup(self, fig: Any, outfile: Any, dpi: float | None = None) -> None:
            super().setup(fig, outfile, dpi=dpi)
            self._fp: IO[bytes] = open(outfile, "wb")  # noqa: SIM115 - closed by finish
            self.frames = 0

        def grab_frame(self, **savefig_kwargs: Any) -> None:
            from PIL import GifImagePlugin, Image

            buf = BytesIO()
            self.fig.savefig(buf, format="rgba", dpi=self.dpi)
            im = Image.frombuffer("RGBA", self.frame_size, buf.getvalue(), "raw", "RGBA", 0, 1)
            frame = im.convert("RGB").quantize(colors=256, method=Image.Quantize.MEDIANCUT,
                                               dither=Image.Dither.NONE)
            if self.frames == 0:
                self._fp.writelines(GifImagePlugin.getheader(frame, info={"loop": 0})[0])
            self._fp.writelines(GifImagePlugin.getdata(frame, duration=duration_ms, include_color_table=True))
            self.frames += 1

        def finish(self) -> None:
            with self._fp:
                self._fp.write(b";")  # the GIF trailer

    duration_ms = max(20, round(1000.0 / fps))  # GIF delays are whole hundredths of a second
    return GifStream(fps=max(1, round(fps)))


def _writer(suffix: str, fps: float) -> Any:
    """The movie writer for ``suffix``.

    Raises:
        OutputError: not .gif or .mp4, or .mp4 without ffmpeg.
    """
    if suffix == ".gif":
        return _gif_stream(fps)
    if suffix == ".mp4":
        from matplotlib.animation import FFMpegWriter

        if not FFMpegWriter.isAvailable():
            raise OutputError("an MP4 needs ffmpeg, which is not installed: write a .gif instead")
        # the temporary file the encoder writes has no .mp4 suffix: name the format
        return FFMpegWriter(fps=max(1, round(fps)), extra_args=["-f", "mp4"])
    raise OutputError(f"animation: {suffix or 'no suffix'}: expected {' or '.join(ANIMATION_SUFFIXES)}")


def _window_ns(stamps: NDArray[np.int64], t_from: float | None, t_to: float | None) -> tuple[int, int]:
    """[start, stop) in ns of the window [t_from, t_to] (seconds since the first tick)."""
    for name, v in (("--from", t_from), ("--to", t_to)):
        if v is not None and not (math.isfinite(v) and v >= 0.0):
            raise ConfigError(f"{name} {v}: expected seconds since the first tick (>= 0)")
    if t_from is not None and t_to is not None and t_to <= t_from:
        raise ConfigError(f"--to {t_to:g} must be after --from {t_from:g}")
    t0 = int(stamps[0])
    start = t0 + round(t_from * NS_PER_S) if t_from is not None else t0
    stop = t0 + round(t_to * NS_PER_S) + 1 if t_to is not None else int(stamps[-1]) + 1
    return start, stop


class _Reader:
    """results.mcap through rosbags: the connections by topic, the messages of a time range; what the reader
    library raises on a damaged file is one RunDirError naming it."""

    def __init__(self, reader: Any, path: Path) -> None:
        from ..io.rosbag import rosbags_errors

        self.r = reader
        self.path = path
        self.errors = rosbags_errors()
        self.conns: dict[str, Any] = {c.topic: c for c in reader.connections}
        missing = [t for t in (*_TICK_TOPICS, *_HELD_TOPICS) if t not in self.conns]
        if missing:
            raise RunDirError(f"{path}: no topic {', '.join(missing)} (not written by gndreplay run --mcap?)")
        self.scan = next((c for c in reader.connections if c.msgtype == LASERSCAN), None)

    def _error(self, err: BaseException) -> RunDirError:
        return RunDirError(f"{self.path}: cannot be read ({type(err).__name__}: {str(err)[:120]})")

    def messages(self, conns: list[Any], start: int | None = None,
                 stop: int | None = None) -> Iterator[tuple[Any, int, bytes]]:
        it = iter(self.r.messages(connections=conns, start=start, stop=stop))
        while True:
            try:
                item = next(it)
            except StopIteration:
                return
            except self.errors as err:
                raise self._error(err) from err
            yield item

    def decode(self, conn: Any, raw: bytes) -> Any:
        try:
            return self.r.deserialize(raw, conn.msgtype)
        except self.errors as err:
            raise self._error(err) from err

    def stamps(self) -> NDArray[np.int64]:
        """The tick times (one /gndreplay/odom message per tick)."""
        return np.fromiter((t for _, t, _ in self.messages([self.conns[_TICK]])), dtype=np.int64)

    def laser_poses(self) -> dict[str, tuple[float, float, float]]:
        """Child frame -> its pose on the robot, from /tf_static."""
        out: dict[str, tuple[float, float, float]] = {}
        conn = self.conns.get("/tf_static")
        for c, _, raw in self.messages([conn]) if conn is not None else ():
            for tf in self.decode(c, raw).transforms:
                tr = tf.transform
                out[tf.child_frame_id] = (float(tr.translation.x), float(tr.translation.y), _yaw(tr.rotation))
        return out

    def held_before(self, start: int) -> dict[str, tuple[Any, bytes]]:
        """The latest grid and path message before ``start`` (raw)."""
        last: dict[str, tuple[Any, bytes]] = {}
        conns = [self.conns[t] for t in _HELD_TOPICS]
        for c, _, raw in self.messages(conns, stop=start):
            last[c.topic] = (c, raw)
        return last

    def ticks(self, start: int, stop: int) -> Iterator[tuple[int, dict[str, tuple[Any, bytes]]]]:
        """(time, topic -> raw message) per tick time in [start, stop), in time order."""
        conns = [self.conns[t] for t in (*_TICK_TOPICS, *_HELD_TOPICS)]
        conns += [self.scan] if self.scan is not None else []
        t_cur: int | None = None
        group: dict[str, tuple[Any, bytes]] = {}
        for c, t, raw in self.messages(conns, start, stop):
            if t != t_cur and group:
                assert t_cur is not None
                yield t_cur, group
                group = {}
            t_cur = t
            group[c.topic] = (c, raw)
        if group and t_cur is not None:
            yield t_cur, group


def _frames(rd: _Reader, start: int, stop: int, keep: set[int], t0: int) -> Iterator[DecisionInput]:
    """The facts of each kept tick in [start, stop), from the tick's messages and the latest grid / path."""
    held = rd.held_before(start)
    decoded: dict[str, tuple[bytes, Any]] = {}
    lasers = rd.laser_poses() if rd.scan is not None else {}

    def latest(topic: str) -> Any:
        c, raw = held[topic]
        if topic not in decoded or decoded[topic][0] is not raw:
            decoded[topic] = (raw, rd.decode(c, raw))
        return decoded[topic][1]

    for t, msgs in rd.ticks(start, stop):
        held.update({k: v for k, v in msgs.items() if k in _HELD_TOPICS})
        if t not in keep or _TICK not in msgs or "/gndreplay/grid" not in held:
            continue
        m = {k: rd.decode(c, raw) for k, (c, raw) in msgs.items() if k in _TICK_TOPICS}
        if any(k not in m for k in _TICK_TOPICS):
            continue
        p, goal = m[_TICK].pose.pose, m["/gndreplay/goal"].pose.position
        tw = m["/cmd_vel"].twist
        cells, origin, cell_m = _grid_cells(latest("/gndreplay/grid"))
        path = np.zeros((0, 2))
        if "/gndreplay/path" in held:
            path = np.array([[q.pose.position.x, q.pose.position.y] for q in latest("/gndreplay/path").poses],
                            dtype=np.float64).reshape(-1, 2)
        scan = np.zeros((0, 2))
        if rd.scan is not None and rd.scan.topic in msgs:
            sc = rd.decode(*msgs[rd.scan.topic])
            scan = _scan_points(sc, lasers.get(sc.header.frame_id, (0.0, 0.0, 0.0)))
        yield DecisionInput(
            t_ns=t, t_s=(t - t0) / NS_PER_S,
            pose=Pose2D(float(p.position.x), float(p.position.y), _yaw(p.orientation)),
            cells=cells, origin_xy=origin, cell_m=cell_m, scan_xy=scan, path_xy=path,
            goal_xy=(float(goal.x), float(goal.y)),
            command=Command(t, float(tw.linear.x), float(tw.angular.z), float(tw.linear.y)),
            mode=m["/gndreplay/mode"].data, situation=m["/gndreplay/situation"].data,
            flags=tuple(f for f in m["/gndreplay/flags"].data.split("|") if f),
            active_mode=m["/gndreplay/active_mode"].data, takeover_reason=m["/gndreplay/takeover"].data,
        )


def animate_run(
    run_dir: Path,
    out_path: Path,
    *,
    t_from: float | None = None,
    t_to: float | None = None,
    fps: float | None = None,
    on_progress: Callable[[int, int], None] | None = None,
    radius_m: float = 5.0,
    dpi: float = 72.0,
    max_frames: int = 1500,
) -> Path:
    """Write an animation of the decision view over [``t_from``, ``t_to``] (seconds since the first tick;
    None: the run's start / end) of ``run_dir`` to ``out_path`` (.gif, or .mp4 when ffmpeg is installed):
    one frame per tick, or every k-th tick when the window holds more than ``max_frames`` ticks. ``fps``
    (None: real time, the ticks' median rate) sets the playback rate. ``on_progress(done, total)`` hears
    each frame. Written beside its place and renamed there; into a gndreplay folder (the run directory)
    only over a file gndreplay wrote, and listed in its marker.

    Returns:
        ``out_path``.

    Raises:
        RunDirError: no results.mcap ("run with --mcap") or config.toml, or results.mcap unreadable.
        ConfigError: a bad window or fps; config.toml malformed.
        OutputError: an unknown suffix, .mp4 without ffmpeg, ``out_path`` exists and gndreplay did not
            write it, no tick in the window, or the disk is full.
    """
    from rosbags.highlevel import AnyReader

    from ..io.rosbag import rosbags_errors

    run_dir, out_path = Path(run_dir), Path(out_path)
    mcap = run_dir / MCAP_FILE
    if not mcap.is_file():
        raise RunDirError(f"{mcap}: missing; the animation is drawn from it: run with --mcap")
    if not (run_dir / CONFIG_FILE).is_file():
        raise RunDirError(f"{run_dir / CONFIG_FILE}: missing (is {run_dir} a gndreplay run directory?)")
    if fps is not None and not (math.isfinite(fps) and 0.1 <= fps <= 100.0):
        raise ConfigError(f"fps {fps}: expected 0.1 to 100 frames per second")
    if max_frames < 1:
        raise ConfigError(f"max_frames {max_frames}: expected at least 1")
    suffix = out_path.suffix.lower()
    _writer(suffix, 1.0)  # an unknown suffix or a missing encoder fails before any work
    cfg = load_config(run_dir / CONFIG_FILE)
    check_may_write(out_path.parent, [out_path.name])
    reader = AnyReader([mcap])
    try:
        reader.open()
    except rosbags_errors() as err:
        raise RunDirError(f"{mcap}: cannot be read ({type(err).__name__}: {str(err)[:120]})") from err
    try:
        rd = _Reader(reader, mcap)
        stamps = rd.stamps()
        if stamps.size == 0:
            raise OutputError(f"{mcap}: no tick recorded; nothing to animate")
        start, stop = _window_ns(stamps, t_from, t_to)
        window = stamps[(stamps >= start) & (stamps < stop)]
        if window.size == 0:
            until = "the end" if t_to is None else f"{t_to:g} s"
            raise OutputError(f"{mcap}: no tick from {t_from or 0.0:g} s to {until} "
                              f"(the run lasts {(stamps[-1] - stamps[0]) / NS_PER_S:.1f} s)")
        stride = -(-window.size // max_frames)
        kept = window[::stride]
        period_s = float(np.median(np.diff(window))) / NS_PER_S * stride if window.size > 1 else 1.0
        rate = fps if fps is not None else min(max(1.0 / max(period_s, 1e-3), 0.1), 100.0)
        fig, ax = decision_figure()
        writer = _writer(suffix, rate)
        with atomic_path(out_path) as tmp, writer.saving(fig, tmp, dpi):
            for k, inp in enumerate(_frames(rd, start, stop, set(kept.tolist()), int(stamps[0])), 1):
                clear_decision(ax)
                draw_decision(ax, decision_view(inp, cfg, radius_m=radius_m))
                writer.grab_frame()
                if on_progress is not None:
                    on_progress(k, int(kept.size))
    finally:
        reader.close()
    add_to_marker(out_path.parent, [out_path.name])
    return out_path
