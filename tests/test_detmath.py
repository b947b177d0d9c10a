"""gndreplay.detmath against the system's libm: within 1 ulp everywhere a robot's angles and exponents go,
the C99 special cases, and small solves as LAPACK's up to rounding."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gndreplay import detmath as dm

RNG = np.random.default_rng(7)


def ulps(got: np.ndarray, ref: np.ndarray) -> float:
    return float(np.max(np.abs(got - ref) / np.spacing(np.abs(ref))))


@pytest.mark.parametrize("scale", [1e-7, 0.7, 3.2, 40.0, 1e5])
def test_sin_cos_within_one_ulp(scale: float) -> None:
    x = RNG.uniform(-scale, scale, 50_000)
    assert ulps(dm.sin_a(x), np.array([math.sin(v) for v in x])) <= 1.0
    assert ulps(dm.cos_a(x), np.array([math.cos(v) for v in x])) <= 1.0


@pytest.mark.parametrize("scale", [1e-9, 1.0, 50.0, 1e12])
def test_atan2_within_one_ulp_in_every_quadrant(scale: float) -> None:
    y, x = RNG.uniform(-scale, scale, (2, 50_000))
    assert ulps(dm.atan2_a(y, x), np.array([math.atan2(a, b) for a, b in zip(y, x, strict=True)])) <= 1.0


def test_exp_within_one_ulp() -> None:
    x = np.concatenate([RNG.uniform(-740.0, 709.0, 20_000), RNG.uniform(-2.0, 2.0, 20_000)])
    assert ulps(np.array([dm.exp(v) for v in x]), np.exp(x)) <= 1.0


@pytest.mark.parametrize("y", [0.0, -0.0, 1.0, -1.0, math.inf, -math.inf, 1e-300, 1e300])
@pytest.mark.parametrize("x", [0.0, -0.0, 1.0, -1.0, math.inf, -math.inf, 1e-300, 1e300])
def test_atan2_special_cases_are_c99s(y: float, x: float) -> None:
    got, ref = dm.atan2(y, x), math.atan2(y, x)
    assert got == ref and math.copysign(1.0, got) == math.copysign(1.0, ref)


def test_non_finite_arguments() -> None:
    assert math.isnan(dm.sin(math.inf)) and math.isnan(dm.cos(-math.inf)) and math.isnan(dm.sin(math.nan))
    assert dm.exp(1000.0) == math.inf and dm.exp(-1000.0) == 0.0 and math.isnan(dm.exp(math.nan))
    assert dm.atan(math.inf) == math.pi / 2 and math.isnan(dm.atan2(math.nan, 1.0))


def test_huge_angles_stay_bounded_and_deterministic() -> None:
    """Beyond 2^19 pi the reduction is modulo the double nearest 2 pi: not accurate, but the same bits."""
    for x in (1e7, -3e12, 1e300):
        assert -1.0 <= dm.sin(x) <= 1.0 and dm.sin(x) == dm.sin(x)
        assert dm.sin(x) ** 2 + dm.cos(x) ** 2 == pytest.approx(1.0)


def test_powi_is_repeated_multiplication() -> None:
    assert dm.powi(0.97, 0) == 1.0 and dm.powi(3.0, 5) == 243.0
    assert dm.powi(0.97, 1000) == pytest.approx(0.97**1000, rel=1e-12)


def test_solve_agrees_with_lapack_and_refuses_a_singular_matrix() -> None:
    for n in (2, 3, 5):
        a = RNG.normal(size=(n, n)) + n * np.eye(n)
        b = RNG.normal(size=n)
        np.testing.assert_allclose(dm.solve(a, b), np.linalg.solve(a, b), rtol=1e-12, atol=1e-12)
    with pytest.raises(np.linalg.LinAlgError):
        dm.solve(np.array([[1.0, 2.0], [2.0, 4.0]]), np.array([1.0, 1.0]))
    pivot_needed = np.array([[0.0, 1.0], [1.0, 0.0]])
    np.testing.assert_array_equal(dm.solve(pivot_needed, np.array([2.0, 3.0])), [3.0, 2.0])


def test_sqdist_is_the_rows_squared_norm() -> None:
    p = RNG.normal(size=(100, 2))
    np.testing.assert_array_equal(dm.sqdist(p), p[:, 0] * p[:, 0] + p[:, 1] * p[:, 1])
