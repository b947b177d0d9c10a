"""The simulated drive: the first-order response against its analytic step response, the acceleration limits
and the dead band, the exact model of ``--ideal-dynamics``, slip as odometry drift, and determinism."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from gndreplay.config import preset
from gndreplay.robot import RobotConfig
from gndreplay.sim import ClosedLoop, SimParams, simulate_scenario
from gndreplay.sim.dynamics import (
    DEADBAND_MPS,
    SlipNoise,
    SlipState,
    next_velocity,
    speed_bound,
    step_toward,
)
from gndreplay.sim.scenario import OdometryNoise
from gndreplay.sim.scenario_file import parse_scenario

FAST = RobotConfig(accel_mps2=50.0, alpha_radps2=100.0, tau_v_s=0.3, tau_w_s=0.2)


def respond(robot: RobotConfig, cmd: tuple[float, float, float], pieces: list[float], *,
            holonomic: bool = False, ideal: bool = False) -> list[tuple[float, float, float]]:
    vel = (0.0, 0.0, 0.0)
    out = []
    for h in pieces:
        vel = next_velocity(vel, cmd, h, robot, holonomic=holonomic, ideal=ideal)
        out.append(vel)
    return out


def test_the_first_order_response_is_the_analytic_step_response_whatever_the_pieces() -> None:
    regular = respond(FAST, (0.3, 0.0, 0.5), [0.01] * 50)
    for k, (v, vy, w) in enumerate(regular, start=1):
        t = 0.01 * k
        assert v == pytest.approx(0.3 * (1.0 - math.exp(-t / 0.3)), rel=1e-12)
        assert w == pytest.approx(0.5 * (1.0 - math.exp(-t / 0.2)), rel=1e-12)
        assert vy == 0.0
    # the exact discretisation: pieces of any length reach the same velocity at the same time
    rng = np.random.default_rng(3)
    cuts = rng.uniform(0.001, 0.02, 40)
    uneven = respond(FAST, (0.3, 0.0, 0.5), list(cuts))
    t = float(cuts.sum())
    assert uneven[-1][0] == pytest.approx(0.3 * (1.0 - math.exp(-t / 0.3)), rel=1e-12)


def test_the_acceleration_limit_still_binds_and_the_dead_band_reaches_the_command() -> None:
    slow = dataclasses.replace(FAST, accel_mps2=0.5, tau_v_s=0.05)
    v = [s[0] for s in respond(slow, (0.3, 0.0, 0.0), [0.01] * 100)]
    assert v[9] == pytest.approx(0.05, abs=1e-12)  # 0.5 m/s^2 for 0.1 s: the lag alone would give 0.26 m/s
    assert np.all(np.diff(v) <= 0.5 * 0.01 + 1e-12)
    assert v[-1] == 0.3  # exactly: the last error fell within the dead band
    stop = [next_velocity((0.5, 0.0, 1.0), (0.0, 0.0, 0.0), 0.01, FAST, holonomic=False, ideal=False)]
    for _ in range(400):
        stop.append(next_velocity(stop[-1], (0.0, 0.0, 0.0), 0.01, FAST, holonomic=False, ideal=False))
    assert stop[-1] == (0.0, 0.0, 0.0)
    first_zero = next(k for k, s in enumerate(stop) if s[0] == 0.0)  # after first_zero + 1 pieces
    assert 0.5 * math.exp(-first_zero * 0.01 / 0.3) > DEADBAND_MPS  # it snapped only within the band


def test_a_holonomic_base_limits_its_velocity_change_as_a_vector() -> None:
    robot = dataclasses.replace(FAST, accel_mps2=1.0, tau_v_s=0.0)
    vx, vy, _ = next_velocity((0.0, 0.0, 0.0), (0.3, 0.4, 0.0), 0.1, robot, holonomic=True, ideal=False)
    assert math.hypot(vx, vy) == pytest.approx(0.1, rel=1e-12) and vy / vx == pytest.approx(4 / 3)


def test_ideal_dynamics_is_the_exact_model_at_the_acceleration_limits() -> None:
    robot = preset("wheelchair").robot
    got = respond(robot, (0.3, 0.0, 0.5), [0.01] * 100, ideal=True)
    v = w = 0.0
    for vel in got:
        v, w = step_toward(v, 0.3, robot.accel_mps2 * 0.01), step_toward(w, 0.5, robot.alpha_radps2 * 0.01)
        assert vel == (v, 0.0, w)
    assert got[-1] == (0.3, 0.0, 0.5)  # in 0.6 s and 0.5 s: no lag
    # the time constants do not reach the exact model
    other = dataclasses.replace(robot, tau_v_s=2.0, tau_w_s=0.0)
    assert respond(other, (0.3, 0.0, 0.5), [0.01] * 100, ideal=True) == got


def test_slip_is_seeded_bounded_and_skids_outward() -> None:
    noise = SlipNoise(v_sigma=0.5, w_sigma=0.5, skid_sigma=0.0, clip=0.3)
    a = SlipState(noise, np.random.default_rng(1))
    b = SlipState(noise, np.random.default_rng(1))
    for _ in range(200):
        a.advance(0.01)
        b.advance(0.05)  # another piece length: three draws each, the same stream position
        vx, vy, w = a.executed(1.0, 0.0, 1.0)
        assert 0.7 - 1e-12 <= vx <= 1.3 + 1e-12 and 0.7 - 1e-12 <= w <= 1.3 + 1e-12
        assert vy == pytest.approx(-noise.skid_s * 1.0 * 1.0)  # to the right of a left turn
    assert a.rng.bit_generator.state == b.rng.bit_generator.state
    reach = 0.8
    bound = speed_bound(FAST, reach, noise, ideal=False)
    vx, vy, w = a.executed(FAST.vmax_mps, 0.0, FAST.wmax_radps)
    assert math.hypot(vx, vy) + abs(w) * reach <= bound


def test_the_slip_stream_leaves_the_laser_and_odometry_streams_as_they_were() -> None:
    two, three = np.random.SeedSequence(9).spawn(2), np.random.SeedSequence(9).spawn(3)
    for a, b in zip(two, three[:2], strict=True):
        assert np.random.default_rng(a).random(5).tolist() == np.random.default_rng(b).random(5).tolist()


STRAIGHT = {"name": "straight", "preset": "xr4000", "start": [0.0, 0.0, 0.0], "goal": [8.0, 0.0],
            "time_limit": 30, "world": {"walls": {"left": [-1.0, 3.0, 10.0, 3.0],
                                                  "right": [-1.0, -3.0, 10.0, -3.0],
                                                  "end": [10.0, -3.0, 10.0, 3.0]}}}


def drift(*, ideal: bool, seed: int = 0) -> float:
    """Largest distance [m] between the odometry (no wheel errors) and the truth while driving a left arc."""
    spec = parse_scenario(STRAIGHT, "straight.yaml")
    cfg = preset("wheelchair")
    params = SimParams(odometry=OdometryNoise(left_scale=0.0, right_scale=0.0, wheelbase_scale=0.0,
                                              wheel_sigma_m_per_sqrt_m=0.0, slip_bias_sigma_radps=0.0))
    loop = ClosedLoop(spec, cfg, seed=seed, params=params, ideal_dynamics=ideal)
    loop.cmd = (0.3, 0.0, 0.3)
    worst = 0.0
    for k in range(1, 41):
        loop._advance(round(k * 0.1 * 1e9))
        worst = max(worst, float(np.hypot(*(loop.odom[:2] - loop.pose[:2]))))
    assert loop.outcome is None
    return worst


def test_slip_shows_as_odometry_drift_against_the_truth() -> None:
    assert drift(ideal=True) < 1e-9  # the wheels are the body
    slipping = drift(ideal=False)
    assert slipping > 0.005  # 4 s of a 1 m arc: centimetres
    assert drift(ideal=False, seed=1) != slipping


def test_a_run_with_dynamics_is_a_pure_function_of_its_seed(tmp_path: Path) -> None:
    spec = parse_scenario(STRAIGHT, "straight.yaml")

    def run(name: str, seed: int, *, ideal: bool = False) -> tuple[bytes, bytes]:
        out = simulate_scenario(spec, out_dir=tmp_path / name, seed=seed, time_limit_s=4.0, figures=False,
                                ideal_dynamics=ideal)
        run_dir = out.out_dir
        return (run_dir / "commands.csv").read_bytes(), (run_dir / "trajectory_truth.tum").read_bytes()

    a, b, c = run("a", 3), run("b", 3), run("c", 4)
    assert a == b
    assert a[1] != c[1]
    assert run("i", 3, ideal=True)[1] != a[1]  # the dynamics change the motion
