"""SE(2) helpers over numpy arrays: poses are ``(..., 3)`` arrays of (x [m], y [m], theta [rad]).

Conventions: x forward, y left, angles counter-clockwise, wrapped to (-pi, pi]. ``compose(a, b)`` is
a ∘ b (b expressed in a's frame, mapped to a's parent frame).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import detmath as dm

__all__ = ["compose", "inverse", "relative", "rotation", "transform_points", "wrap_angle"]

F64 = NDArray[np.float64]


def wrap_angle(a: ArrayLike) -> F64 | float:
    """Wrap angles [rad] to (-pi, pi]; scalars in, float out."""
    w = np.pi - np.mod(np.pi - np.asarray(a, dtype=np.float64), 2.0 * np.pi)
    return float(w) if np.ndim(w) == 0 else w


def wrap_scalar(a: float) -> float:
    """``wrap_angle`` of one float, without numpy: the same bits (Python's float ``%`` is numpy's ``mod``:
    fmod, then the divisor's sign)."""
    return math.pi - (math.pi - a) % (2.0 * math.pi)


def rotation(theta: float) -> F64:
    """2x2 rotation matrix of angle ``theta`` [rad]."""
    c, s = dm.cos_a(theta), dm.sin_a(theta)
    return np.array([[c, -s], [s, c]])


def compose(a: ArrayLike, b: ArrayLike) -> F64:
    """a ∘ b for poses of shape (3,) or (N, 3) (broadcasting)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    c, s = dm.cos_a(a[..., 2]), dm.sin_a(a[..., 2])
    x = a[..., 0] + c * b[..., 0] - s * b[..., 1]
    y = a[..., 1] + s * b[..., 0] + c * b[..., 1]
    th = wrap_angle(a[..., 2] + b[..., 2])
    return np.stack([x, y, np.asarray(th)], axis=-1)


def inverse(a: ArrayLike) -> F64:
    """Inverse pose: ``compose(inverse(a), a) == 0``."""
    a = np.asarray(a, dtype=np.float64)
    c, s = dm.cos_a(a[..., 2]), dm.sin_a(a[..., 2])
    x = -(c * a[..., 0] + s * a[..., 1])
    y = s * a[..., 0] - c * a[..., 1]
    return np.stack([x, y, np.asarray(wrap_angle(-a[..., 2]))], axis=-1)


def relative(a: ArrayLike, b: ArrayLike) -> F64:
    """Pose of b in the frame of a: ``inverse(a) ∘ b``."""
    return compose(inverse(a), b)


def transform_points(pose: ArrayLike, points: ArrayLike) -> F64:
    """Map ``(N, 2)`` points from the frame of ``pose`` (shape (3,)) to its parent frame."""
    p = np.asarray(pose, dtype=np.float64)
    pts = np.asarray(points, dtype=np.float64)
    c, s = dm.cos_a(p[2]), dm.sin_a(p[2])
    out = np.empty_like(pts)
    out[:, 0] = p[0] + c * pts[:, 0] - s * pts[:, 1]
    out[:, 1] = p[1] + s * pts[:, 0] + c * pts[:, 1]
    return out
