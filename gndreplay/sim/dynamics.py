"""How the simulated base executes a velocity command: the drive's response and the slip of the wheels.

- **Response.** Each velocity axis (v, and vy on a holonomic base, and w) follows its command through a
  first-order lag, ``u += (cmd - u) * (1 - exp(-h / tau))`` over a piece of ``h`` seconds (the exact
  discretisation, so the response does not depend on how the time is cut), with ``tau`` the robot's
  ``tau_v_s`` / ``tau_w_s``; the change is still bounded by the acceleration limits (``accel_mps2 * h``,
  ``alpha_radps2 * h``; on a holonomic base the (vx, vy) change as a vector). A remaining error within
  the drive's dead band (``DEADBAND_MPS``, ``DEADBAND_RADPS``) closes at once: the velocity reaches a stop
  exactly, as a motor controller holding zero does.
- **Slip.** The wheels turn at that velocity (wheel odometry integrates it); the body moves with it
  corrupted: relative slips of v and w, each a first-order Gauss-Markov process (``SlipNoise``), and a
  lateral skid outward of the turn, ``-skid_s * v * w`` (proportional to the centripetal acceleration),
  whose coefficient varies by a third such process. Slip therefore shows as odometry drift against the
  truth.
- **Ideal** dynamics (``ideal=True``): the velocity moves toward the command at the acceleration limits and
  the body moves exactly as the wheels (the exact model; no slip draw is used).

Every random number comes from the slip stream, a fixed three standard normals per piece, so a run depends
on nothing but its seed and configuration.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import detmath as dm
from ..robot import RobotConfig

__all__ = [
    "DEADBAND_MPS", "DEADBAND_RADPS", "SlipNoise", "SlipState", "next_velocity", "speed_bound", "step_toward",
]

#: Velocity errors [m/s], [rad/s] the drive closes at once (its dead band).
DEADBAND_MPS = 0.002
DEADBAND_RADPS = 0.005

Twist = tuple[float, float, float]


@dataclass(frozen=True, slots=True)
class SlipNoise:
    """Slip and skid of the executed motion on a hard indoor floor.

    Attributes:
        v_sigma: stationary std of the relative slip of v and vy (executed / wheel - 1).
        w_sigma: stationary std of the relative slip of w (turning on castors and tyres skids more).
        skid_s: lateral skid [m/s] per unit of v * w [m/s * rad/s], outward of the turn.
        skid_sigma: stationary std of the relative variation of ``skid_s``.
        tau_s: correlation time of the three Gauss-Markov processes [s].
        clip: each relative slip is bounded by this (and the skid factor to 1 +- clip): the bound of every
            closing speed (``speed_bound``) holds.
    """

    v_sigma: float = 0.02
    w_sigma: float = 0.05
    skid_s: float = 0.02
    skid_sigma: float = 0.3
    tau_s: float = 1.0
    clip: float = 0.3


class SlipState:
    """The three slip processes (v, w, skid), started from their stationary laws."""

    def __init__(self, noise: SlipNoise, rng: np.random.Generator) -> None:
        self.noise, self.rng = noise, rng
        self._sigma = np.array([noise.v_sigma, noise.w_sigma, noise.skid_sigma], dtype=np.float64)
        self.s = self._sigma * rng.standard_normal(3)

    def advance(self, h: float) -> None:
        """The processes ``h`` seconds later (exact discretisation; three draws, whatever ``h``)."""
        z = self.rng.standard_normal(3)
        a = dm.exp(-h / self.noise.tau_s)
        self.s = a * self.s + self._sigma * math.sqrt(max(1.0 - a * a, 0.0)) * z

    def executed(self, vx: float, vy: float, w: float) -> Twist:
        """The body twist the wheel twist (vx, vy, w) gives with the current slip."""
        c = self.noise.clip
        sv, sw, sk = (min(max(float(x), -c), c) for x in self.s)
        skid = -self.noise.skid_s * (1.0 + sk) * vx * w
        return vx * (1.0 + sv), vy * (1.0 + sv) + skid, w * (1.0 + sw)


def _lag(u: float, cmd: float, h: float, tau: float) -> float:
    """The first-order change of ``u`` toward ``cmd`` over ``h`` seconds (all of it when ``tau`` is 0)."""
    return (cmd - u) * (1.0 - dm.exp(-h / tau)) if tau > 0.0 else cmd - u


def _bounded(u: float, du: float, step: float, cmd: float, deadband: float) -> float:
    """``u + du`` with ``|du| <= step``; the command itself when it is within the dead band of that."""
    nxt = u + min(max(du, -step), step)
    return cmd if abs(cmd - nxt) <= deadband else nxt


def step_toward(cur: float, target: float, step: float) -> float:
    """``cur`` moved toward ``target`` by at most ``step``."""
    return cur + min(max(target - cur, -step), step)


def next_velocity(vel: Twist, cmd: Twist, h: float, robot: RobotConfig, *, holonomic: bool,
                  ideal: bool) -> Twist:
    """The wheel velocity after a piece of ``h`` seconds under ``cmd`` (already clipped to the limits where
    ``ideal`` is False; see the module docstring)."""
    cv, cvy, cw = cmd
    vx, vy, w = vel
    if ideal:
        if holonomic:
            dvx, dvy = cv - vx, cvy - vy
            dn = math.hypot(dvx, dvy)
            step = robot.accel_mps2 * h
            if dn > step:
                dvx, dvy = dvx * step / dn, dvy * step / dn
            vx, vy = vx + dvx, vy + dvy
        else:
            vx, vy = step_toward(vx, cv, robot.accel_mps2 * h), 0.0
        return vx, vy, step_toward(w, cw, robot.alpha_radps2 * h)
    step = robot.accel_mps2 * h
    dvx = _lag(vx, cv, h, robot.tau_v_s)
    if holonomic:
        dvy = _lag(vy, cvy, h, robot.tau_v_s)
        dn = math.hypot(dvx, dvy)
        if dn > step:
            dvx, dvy = dvx * step / dn, dvy * step / dn
        vx = _bounded(vx, dvx, math.inf, cv, DEADBAND_MPS)
        vy = _bounded(vy, dvy, math.inf, cvy, DEADBAND_MPS)
    else:
        vx, vy = _bounded(vx, dvx, step, cv, DEADBAND_MPS), 0.0
    w = _bounded(w, _lag(w, cw, h, robot.tau_w_s), robot.alpha_radps2 * h, cw, DEADBAND_RADPS)
    return vx, vy, w


def speed_bound(robot: RobotConfig, reach_m: float, slip: SlipNoise, *, ideal: bool) -> float:
    """An upper bound [m/s] of the speed of any footprint point (``reach_m`` from the rotation centre)
    under any executed twist."""
    if ideal:
        return robot.vmax_mps + robot.wmax_radps * reach_m
    k = 1.0 + slip.clip
    skid = slip.skid_s * k * robot.vmax_mps * robot.wmax_radps
    return robot.vmax_mps * k + skid + robot.wmax_radps * k * reach_m
