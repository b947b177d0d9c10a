"""Scripted teleoperation for closed-loop scenarios: the operator's command at each scan.

Two kinds of operator (``teleop:`` in a scenario file, see :mod:`.scenario_file`):

- a **script**: ``commands: [[t_s, v, w], ...]``, piecewise constant, each from its ``t_s`` (before the
  first: at rest); the script ends at its last entry's time, whose command must be a stop ``[t, 0, 0]``;
- a **track**: ``track: {points: [[x, y], ...], speed: v}``, a careless joystick driver: pure pursuit on
  the robot's TRUE pose along the polyline at ``speed`` (slower where the curvature asks more than the
  robot's turn rate, slowing to stop at its end; never turning on the spot), blind to obstacles. It ends
  when the true axle is within ``tolerance`` of the last point.

The operator's command becomes the ``Tick.cmd`` the stack sees, as a recorded command in a log would; in
teleop mode the stack's mode selector decides whether it goes out. Deterministic: a pure function of the
scan times and true poses it is given, in order.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .. import detmath as dm
from ..geometry import wrap_angle
from .scenario import _point_at, _polyline_lengths, _project

__all__ = ["DEFAULT_LOOKAHEAD_M", "TeleopDriver", "TeleopSpec"]

F64 = NDArray[np.float64]
DEFAULT_LOOKAHEAD_M = 0.8


@dataclass(frozen=True, slots=True, eq=False)
class TeleopSpec:
    """A scenario's operator: exactly one of ``commands`` (script) and ``track`` (points) is set.

    Attributes:
        commands: ``(K, 3)`` rows (t_s, v [m/s], w [rad/s]), t_s increasing; the last row is a stop.
        track: ``(P, 2)`` polyline [m] in the scenario's world frame.
        speed_mps: the track driver's cruise speed.
        lookahead_m: its pure-pursuit look-ahead.
        tolerance_m: the track ends when the true axle is this close to its last point (None: the
            supervisor's goal tolerance).
    """

    commands: F64 | None = None
    track: F64 | None = None
    speed_mps: float = 0.0
    lookahead_m: float = DEFAULT_LOOKAHEAD_M
    tolerance_m: float | None = None

    @property
    def kind(self) -> str:
        return "script" if self.commands is not None else "track"

    def end_xy(self) -> tuple[float, float] | None:
        """The track's last point (None for a script)."""
        if self.track is None:
            return None
        return float(self.track[-1, 0]), float(self.track[-1, 1])


class TeleopDriver:
    """The operator of one run (state: progress along the track)."""

    def __init__(self, spec: TeleopSpec, *, wmax_radps: float, accel_mps2: float, tolerance_m: float) -> None:
        self.spec = spec
        self.wmax, self.accel = wmax_radps, accel_mps2
        self.tolerance = spec.tolerance_m if spec.tolerance_m is not None else tolerance_m
        self._s = 0.0
        if spec.track is not None:
            self._cum = _polyline_lengths(spec.track)

    def command(self, t_s: float, pose: F64) -> tuple[float, float]:
        """The operator's (v, w) at time ``t_s`` [s since the start] with the robot truly at ``pose``."""
        cmds = self.spec.commands
        if cmds is not None:
            k = int(np.searchsorted(cmds[:, 0], t_s + 1e-9, side="right")) - 1
            return (0.0, 0.0) if k < 0 else (float(cmds[k, 1]), float(cmds[k, 2]))
        return self._pursue(pose)

    def _pursue(self, pose: F64) -> tuple[float, float]:
        track, cum, sp = self.spec.track, self._cum, self.spec
        assert track is not None
        self._s = _project(track, cum, pose[:2], self._s)
        end = track[-1]
        to_end = math.hypot(end[0] - pose[0], end[1] - pose[1])
        if to_end <= self.tolerance:
            return 0.0, 0.0
        remaining = max(float(cum[-1]) - self._s, to_end)
        target = _point_at(track, cum, self._s + sp.lookahead_m)
        dx, dy = float(target[0] - pose[0]), float(target[1] - pose[1])
        dist = math.hypot(dx, dy)
        alpha = float(wrap_angle(dm.atan2(dy, dx) - pose[2])) if dist > 1e-6 else 0.0
        kappa = 2.0 * dm.sin(alpha) / max(dist, 1e-6)
        v = min(sp.speed_mps, math.sqrt(2.0 * self.accel * remaining))
        if abs(kappa) * v > self.wmax:
            v = self.wmax / abs(kappa)
        return v, v * kappa

    def ended(self, t_s: float, pose: F64) -> bool:
        """The script's time is over, or the true axle reached the track's end."""
        cmds = self.spec.commands
        if cmds is not None:
            return t_s >= float(cmds[-1, 0])
        end = self.spec.track[-1]  # type: ignore[index]
        return math.hypot(float(end[0]) - pose[0], float(end[1]) - pose[1]) <= self.tolerance
