"""Pose2D's scalar frame changes give the bits of the array functions they stand for (``geometry``)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gndreplay.geometry import compose, inverse, transform_points, wrap_angle, wrap_scalar
from gndreplay.types import Pose2D

EDGES = [0.0, -0.0, math.pi, -math.pi, 2 * math.pi, -2 * math.pi, 3 * math.pi, 1e-300, -1e-300, 1e10, -1e10,
         math.nextafter(math.pi, 0.0), math.nextafter(-math.pi, 0.0), math.inf, -math.inf, math.nan]


def _same(a: float, b: float) -> bool:
    return (a == b and math.copysign(1.0, a) == math.copysign(1.0, b)) or (math.isnan(a) and math.isnan(b))


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # numpy's mod of an infinity
def test_wrap_scalar_is_wrap_angle_bit_for_bit() -> None:
    rng = np.random.default_rng(0)
    for a in [*EDGES, *rng.uniform(-10.0, 10.0, 20000), *rng.uniform(-1e6, 1e6, 2000)]:
        assert _same(wrap_scalar(float(a)), float(wrap_angle(a))), a


@pytest.mark.parametrize("seed", range(3))
def test_pose_compose_inverse_and_to_local_are_the_array_functions_bit_for_bit(seed: int) -> None:
    rng = np.random.default_rng(seed)

    def from_array(a: np.ndarray) -> tuple[float, float, float]:
        return float(a[0]), float(a[1]), float(wrap_angle(a[2]))

    for k in range(3000):
        theta = float(rng.uniform(-7.0, 7.0)) if k % 4 else float(rng.choice(EDGES[:11]))
        p = Pose2D(*map(float, rng.uniform(-500.0, 500.0, 2)), wrap_scalar(theta))
        q = Pose2D(*map(float, rng.uniform(-50.0, 50.0, 2)), wrap_scalar(float(rng.uniform(-4.0, 4.0))))
        inv = p.inverse()
        assert (inv.x, inv.y, inv.theta) == from_array(inverse(p.as_array()))
        both = p.compose(q)
        assert (both.x, both.y, both.theta) == from_array(compose(p.as_array(), q.as_array()))
        x, y = map(float, rng.uniform(-100.0, 100.0, 2))
        assert p.to_local(x, y) == tuple(transform_points(inv.as_array(), [[x, y]])[0])
