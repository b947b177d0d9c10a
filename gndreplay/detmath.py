"""Transcendental functions and small linear solves that give the same bits on every CPU.

Why: the stack's discrete decisions (accept a match, take a keyframe, pick a region) turn a last-bit
difference into a different trajectory. The system's own ``sin``, ``cos``, ``atan2``, ``exp`` and ``pow`` are
not bit-stable across machines: glibc picks an FMA variant of each at load time on CPUs that have FMA
(x86-64-v3 and up) and a plain SSE2 one elsewhere; numpy replaces ``arctan2``, ``exp``, ``log`` and ``power``
with its own SIMD versions on AVX-512 CPUs; OpenBLAS (``@``, ``dot``, ``linalg.solve``) picks its kernels by
CPU model. Each variant is accurate, none is correctly rounded, so they differ in the last bit now and then.

These are the fdlibm algorithms (Sun Microsystems, 1993; the versions of FreeBSD's msun): Cody-Waite
reduction by pi/2 in three parts, then minimax polynomials, evaluated in a fixed order with plain IEEE
double adds and multiplies (numba emits no fused multiply-add without ``fastmath``), so the result is the
same on every IEEE-754 machine. Errors are below 1 ulp of the exact value. Arguments beyond 2^19 pi (a
heading no robot reaches) are first reduced exactly modulo the double nearest 2 pi, which keeps the result
deterministic but not accurate there.

Scalar functions are numba kernels, callable from Python and from other kernels; ``*_a`` are ufuncs for
arrays (any shape, broadcasting).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, vectorize
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "atan", "atan2", "atan2_a", "cos", "cos_a", "exp", "powi", "sin", "sin_a", "solve", "solve_kernel",
    "sqdist",
]

F64 = NDArray[np.float64]

_PIO4 = 0.7853981633974483  # the double nearest pi/4
_INVPIO2 = 6.36619772367581382433e-01
_PIO2_1 = 1.57079632673412561417e00  # first 33 bits of pi/2
_PIO2_1T = 6.07710050650619224932e-11  # pi/2 - _PIO2_1
_PIO2_2 = 6.07710050630396597660e-11  # next 33 bits
_PIO2_2T = 2.02226624879595063154e-21
_PIO2_3 = 2.02226624871116645580e-21  # next 33 bits
_PIO2_3T = 8.47842766036889956997e-32
_TOINT = 6755399441055744.0  # 1.5 * 2^52: x + _TOINT - _TOINT rounds x to the nearest integer
_MEDIUM = 823549.6656214236  # 2^19 pi: n fits the 33-bit parts exactly below this
_TWO_PI = 6.283185307179586

_S1 = -1.66666666666666324348e-01
_S2 = 8.33333333332248946124e-03
_S3 = -1.98412698298579493134e-04
_S4 = 2.75573137070700676789e-06
_S5 = -2.50507602534068634195e-08
_S6 = 1.58969099521155010221e-10

_C1 = 4.16666666666666019037e-02
_C2 = -1.38888888888741095749e-03
_C3 = 2.48015872894767294178e-05
_C4 = -2.75573143513906633035e-07
_C5 = 2.08757232129817482790e-09
_C6 = -1.13596475577881948265e-11


@njit(cache=True, inline="always")
def _ksin(x: float, y: float) -> float:
    """sin(x + y) for |x| <= pi/4, y the tail of x (fdlibm __kernel_sin)."""
    z = x * x
    v = z * x
    r = _S2 + z * (_S3 + z * (_S4 + z * (_S5 + z * _S6)))
    return x - ((z * (0.5 * y - v * r) - y) - v * _S1)


@njit(cache=True, inline="always")
def _kcos(x: float, y: float) -> float:
    """cos(x + y) for |x| <= pi/4, y the tail of x (fdlibm __kernel_cos)."""
    z = x * x
    w = z * z
    r = z * (_C1 + z * (_C2 + z * _C3)) + w * w * (_C4 + z * (_C5 + z * _C6))
    hz = 0.5 * z
    w = 1.0 - hz
    return w + (((1.0 - w) - hz) + (z * r - x * y))


@njit(cache=True, inline="always")
def _rem_pio2(x: float) -> tuple[int, float, float]:
    """x = n pi/2 + (y0 + y1), |y0 + y1| <= pi/4 (about): the quadrant n mod 4 and the remainder as a
    head and a tail, with pi/2 in three 33-bit parts (fdlibm __ieee754_rem_pio2, medium range)."""
    if abs(x) > _MEDIUM:
        x = np.fmod(x, _TWO_PI)  # exact, and deterministic; accurate only for moderate x
    fn = (x * _INVPIO2 + _TOINT) - _TOINT
    r = x - fn * _PIO2_1
    w = fn * _PIO2_1T
    t = r
    w = fn * _PIO2_2
    r = t - w
    w = fn * _PIO2_2T - ((t - r) - w)
    t = r
    w = fn * _PIO2_3
    r = t - w
    w = fn * _PIO2_3T - ((t - r) - w)
    y0 = r - w
    y1 = (r - y0) - w
    return int(fn) & 3, y0, y1


@njit(cache=True, inline="always")
def _sin_quadrants(x: float, shift: int) -> float:
    """sin(x + shift pi/2): the kernel of the remainder's quadrant."""
    if not math.isfinite(x):
        return math.nan
    n, y0, y1 = (0, x, 0.0) if abs(x) <= _PIO4 else _rem_pio2(x)
    n = (n + shift) & 3
    if n == 0:
        return _ksin(y0, y1)
    if n == 1:
        return _kcos(y0, y1)
    if n == 2:
        return -_ksin(y0, y1)
    return -_kcos(y0, y1)


@njit("float64(float64)", cache=True)
def sin(x: float) -> float:
    """sin(x) [x in rad], the same bits on every CPU (nan for nan and +-inf)."""
    return _sin_quadrants(x, 0)


@njit("float64(float64)", cache=True)
def cos(x: float) -> float:
    """cos(x) [x in rad], the same bits on every CPU (nan for nan and +-inf)."""
    return _sin_quadrants(x, 1)


_ATANHI = (4.63647609000806093515e-01, 7.85398163397448278999e-01, 9.82793723247329054082e-01,
           1.57079632679489655800e00)
_ATANLO = (2.26987774529616870924e-17, 3.06161699786838301793e-17, 1.39033110312309984516e-17,
           6.12323399573676603587e-17)
_AT0 = 3.33333333333329318027e-01
_AT1 = -1.99999999998764832476e-01
_AT2 = 1.42857142725034663711e-01
_AT3 = -1.11111104054623557880e-01
_AT4 = 9.09088713343650656196e-02
_AT5 = -7.69187620504482999495e-02
_AT6 = 6.66107313738753120669e-02
_AT7 = -5.83357013379057348645e-02
_AT8 = 4.97687799461593236017e-02
_AT9 = -3.65315727442169155270e-02
_AT10 = 1.62858201153657823623e-02


@njit("float64(float64)", cache=True)
def atan(x: float) -> float:
    """atan(x) in [-pi/2, pi/2], the same bits on every CPU (fdlibm s_atan)."""
    if math.isnan(x):
        return x
    ax = abs(x)
    if ax >= 7.378697629483821e19:  # 2^66: atan is +-pi/2 to the last bit
        z = _ATANHI[3] + _ATANLO[3]
        return z if x > 0.0 else -z
    k = -1
    if ax < 0.4375:
        if ax < 3.725290298461914e-09:  # 2^-28
            return x
        t = x
    else:
        if ax < 1.1875:
            if ax < 0.6875:
                k = 0
                t = (2.0 * ax - 1.0) / (2.0 + ax)
            else:
                k = 1
                t = (ax - 1.0) / (ax + 1.0)
        elif ax < 2.4375:
            k = 2
            t = (ax - 1.5) / (1.0 + 1.5 * ax)
        else:
            k = 3
            t = -1.0 / ax
    z = t * t
    w = z * z
    s1 = z * (_AT0 + w * (_AT2 + w * (_AT4 + w * (_AT6 + w * (_AT8 + w * _AT10)))))
    s2 = w * (_AT1 + w * (_AT3 + w * (_AT5 + w * (_AT7 + w * _AT9))))
    if k < 0:
        return t - t * (s1 + s2)
    z = _ATANHI[k] - ((t * (s1 + s2) - _ATANLO[k]) - t)
    return z if x > 0.0 else -z


_PI = 3.1415926535897931160e00
_PI_LO = 1.2246467991473531772e-16
_TWO_60 = 1152921504606846976.0


@njit("float64(float64, float64)", cache=True)
def atan2(y: float, x: float) -> float:
    """atan2(y, x) in [-pi, pi] with the signed-zero and infinity cases of C99, the same bits on every CPU
    (fdlibm e_atan2)."""
    if math.isnan(x) or math.isnan(y):
        return x + y
    neg_y = math.copysign(1.0, y) < 0.0
    neg_x = math.copysign(1.0, x) < 0.0
    if x == 1.0:
        return atan(y)
    if y == 0.0:
        if not neg_x:
            return y
        return -_PI if neg_y else _PI
    if x == 0.0:
        return -0.5 * _PI if neg_y else 0.5 * _PI
    if math.isinf(x):
        z = (0.75 * _PI if neg_x else 0.25 * _PI) if math.isinf(y) else (_PI if neg_x else 0.0)
        return -z if neg_y else z
    if math.isinf(y):
        return -0.5 * _PI if neg_y else 0.5 * _PI
    ay = abs(y)
    ax = abs(x)
    if ay > _TWO_60 * ax:  # |y/x| > 2^60 (scaling by a power of 2 is exact; an overflow compares right)
        z = 0.5 * _PI + 0.5 * _PI_LO
        return -z if neg_y else z
    z = 0.0 if neg_x and _TWO_60 * ay < ax else atan(ay / ax)  # 0 where |y/x| < 2^-60 and x < 0
    if not neg_x:
        return -z if neg_y else z
    if not neg_y:
        return _PI - (z - _PI_LO)
    return (z - _PI_LO) - _PI


_LN2HI = 6.93147180369123816490e-01
_LN2LO = 1.90821492927058770002e-10
_INVLN2 = 1.44269504088896338700e00
_P1 = 1.66666666666666019037e-01
_P2 = -2.77777777770155933842e-03
_P3 = 6.61375632143793436117e-05
_P4 = -1.65339022054652515390e-06
_P5 = 4.13813679705723846039e-08


@njit("float64(float64)", cache=True)
def exp(x: float) -> float:
    """e^x, the same bits on every CPU (fdlibm e_exp; inf above 709.78, 0 below -745.13)."""
    if math.isnan(x):
        return x
    if x > 7.09782712893383973096e02:
        return math.inf
    if x < -7.45133219101941108420e02:
        return 0.0
    ax = abs(x)
    k = 0
    hi = 0.0
    lo = 0.0
    if ax > 0.34657359027997264:  # 0.5 ln 2
        if ax < 1.0397207708399179:  # 1.5 ln 2
            if x > 0.0:
                hi = x - _LN2HI
                lo = _LN2LO
                k = 1
            else:
                hi = x + _LN2HI
                lo = -_LN2LO
                k = -1
        else:
            k = int(_INVLN2 * x + (0.5 if x > 0.0 else -0.5))
            t = float(k)
            hi = x - t * _LN2HI
            lo = t * _LN2LO
        x = hi - lo
    elif ax < 3.725290298461914e-09:  # 2^-28
        return 1.0 + x
    t = x * x
    c = x - t * (_P1 + t * (_P2 + t * (_P3 + t * (_P4 + t * _P5))))
    if k == 0:
        return 1.0 - ((x * c) / (c - 2.0) - x)
    y = 1.0 - ((lo - (x * c) / (2.0 - c)) - hi)
    return math.ldexp(y, k)


@njit("float64(float64, int64)", cache=True)
def powi(x: float, n: int) -> float:
    """x^n for an integer n >= 0 by repeated squaring (``x ** n`` on floats calls the system's pow)."""
    out = 1.0
    while n > 0:
        if n & 1:
            out *= x
        x *= x
        n >>= 1
    return out


@vectorize(["float64(float64)"], cache=True)
def sin_a(x: float) -> float:  # pragma: no cover - compiled
    """sin of every element (a ufunc: arrays of any shape, scalars)."""
    return sin(x)


@vectorize(["float64(float64)"], cache=True)
def cos_a(x: float) -> float:  # pragma: no cover - compiled
    """cos of every element (a ufunc: arrays of any shape, scalars)."""
    return cos(x)


@vectorize(["float64(float64, float64)"], cache=True)
def atan2_a(y: float, x: float) -> float:  # pragma: no cover - compiled
    """atan2 of every pair of elements (a ufunc: broadcasting)."""
    return atan2(y, x)


def sqdist(points: ArrayLike) -> F64:
    """Squared norm of each row of an ``(N, 2)`` array, x² + y² in that order (no BLAS, no einsum)."""
    p = np.asarray(points, dtype=np.float64)
    return p[:, 0] * p[:, 0] + p[:, 1] * p[:, 1]


@njit(cache=True)
def solve_kernel(a: F64, b: F64) -> tuple[F64, bool]:
    """Gaussian elimination with partial pivoting in a fixed order: (x, True), or (zeros, False) when the
    matrix is singular (a zero or non-finite pivot)."""
    n = a.shape[0]
    m = a.copy()
    x = b.copy()
    for col in range(n):
        piv = col
        for r in range(col + 1, n):
            if abs(m[r, col]) > abs(m[piv, col]):
                piv = r
        p = m[piv, col]
        if p == 0.0 or not math.isfinite(p):
            return np.zeros(n), False
        if piv != col:
            for c in range(n):
                m[col, c], m[piv, c] = m[piv, c], m[col, c]
            x[col], x[piv] = x[piv], x[col]
        for r in range(col + 1, n):
            f = m[r, col] / p
            for c in range(col, n):
                m[r, c] -= f * m[col, c]
            x[r] -= f * x[col]
    for col in range(n - 1, -1, -1):
        acc = x[col]
        for c in range(col + 1, n):
            acc -= m[col, c] * x[c]
        x[col] = acc / m[col, col]
    return x, True


def solve(a: ArrayLike, b: ArrayLike) -> F64:
    """x with a x = b for a small square system, in a fixed order (LAPACK's result depends on the CPU's BLAS
    kernels); raises ``np.linalg.LinAlgError`` when a is singular, as ``np.linalg.solve``."""
    x, ok = solve_kernel(np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64))
    if not ok:
        raise np.linalg.LinAlgError("singular matrix")
    return np.asarray(x)
