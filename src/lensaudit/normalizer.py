"""Map distortion models onto the polynomial 1 + c1 w + ... + cn w^n whose roots bound r_max.

For a radial model D(r) = r F(r), the first local maximum of D is the first
positive root of D'(r) at which D' changes sign. For every Lensfun model here D'(r),
divided by its constant term D'(0), is a cubic in w, with w = r (ptlens, the
basic polynomial) or w = r^2 (poly3, poly5, Brown-Conrady). This module gives
that cubic (paper Eqs. 26-28, 5 and 6) together with D itself, so that the
solver and the metrics share one description of each model. OpenCV's
fisheye model (Gyroflow) is a quartic in w = theta^2: a :class:`Polynomial`,
the general description, of which :func:`as_polynomial` makes any cubic one.

All functions are vectorized: coefficients may be scalars or numpy arrays.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Cubic:
    """D'(r) / D'(0) = 1 + a w + b w^2 + c w^3, with w = r**power (power 1 or 2).

    ``slope_at_centre`` is D'(0); where it is not positive the model is not
    increasing at the centre of the image and has no valid domain at all.
    ``distortion`` holds the coefficients of D(r) as a polynomial in r,
    highest power first (as numpy.polyval expects), one row per entry.
    """

    a: FloatArray
    b: FloatArray
    c: FloatArray
    power: int
    slope_at_centre: FloatArray
    distortion: FloatArray


@dataclass(frozen=True)
class Polynomial:
    """D'(r) / D'(0) = 1 + c1 w + ... + cn w^n, with w = r**power: a model's description.

    ``coefficients`` holds c1 ... cn along its last axis, lowest power first,
    as :func:`lensaudit.solver.polynomial.first_sign_change` takes them;
    ``slope_at_centre`` is D'(0) and ``distortion`` the coefficients of D(r)
    in r, highest power first, as in :class:`Cubic`. A model is this
    description and nothing more: the one solver finds its fold
    (:func:`lensaudit.solver.fold.first_fold`).
    """

    coefficients: FloatArray
    power: int
    slope_at_centre: FloatArray
    distortion: FloatArray


def as_polynomial(cubic: Cubic) -> Polynomial:
    """The cubic 1 + a w + b w^2 + c w^3 as a :class:`Polynomial` (n = 3)."""
    coefficients = np.stack(np.broadcast_arrays(cubic.a, cubic.b, cubic.c), axis=-1)
    return Polynomial(coefficients, cubic.power, cubic.slope_at_centre, cubic.distortion)


def opencv_fisheye(k1: ArrayLike, k2: ArrayLike, k3: ArrayLike, k4: ArrayLike) -> Polynomial:
    """OpenCV's fisheye model, Gyroflow's lens profiles: theta_d = theta (1 + k1 theta^2 + k2
    theta^4 + k3 theta^6 + k4 theta^8).

    theta is the angle from the optical axis and theta_d the distorted one, in
    radians (a pixel lies at f theta_d from the principal point). d theta_d /
    d theta = 1 + 3 k1 u + 5 k2 u^2 + 7 k3 u^3 + 9 k4 u^4 with u = theta^2:
    power 2, slope 1 at the centre. The products 3 k1 ... 9 k4 are each
    rounded once (relative error at most 2^-53); ``distortion`` holds the k
    themselves, exactly.
    """
    ks = np.broadcast_arrays(*(np.asarray(k, np.float64) for k in (k1, k2, k3, k4)))
    zero = np.zeros_like(ks[0])
    one = np.ones_like(ks[0])
    k1, k2, k3, k4 = ks
    distortion = np.stack((k4, zero, k3, zero, k2, zero, k1, zero, one, zero), axis=-1)
    with np.errstate(over="ignore"):
        coefficients = np.stack((3 * k1, 5 * k2, 7 * k3, 9 * k4), axis=-1)
    return Polynomial(coefficients, power=2, slope_at_centre=one, distortion=distortion)


def _two_sum(x: FloatArray, y: FloatArray) -> tuple[FloatArray, FloatArray]:
    """x + y as an unevaluated sum (s, e), exactly (Knuth's error-free transform)."""
    s = x + y
    z = s - x
    return s, (x - (s - z)) + (y - z)


def ptlens_constant(a: ArrayLike, b: ArrayLike, c: ArrayLike) -> FloatArray:
    """d = 1 - a - b - c of the ptlens model, accurate to about one rounding.

    Summed with error-free transformations because d divides every
    coefficient of the cubic, and for strong distortion a, b, c are large
    and of mixed sign.
    """
    a, b, c = (np.asarray(x, dtype=np.float64) for x in (a, b, c))
    with np.errstate(all="ignore"):  # inf or NaN where it overflows: the metrics see to it
        total, error = _two_sum(np.ones_like(a + b + c), -a)
        total, e2 = _two_sum(total, -b)
        total, e3 = _two_sum(total, -c)
        return total + (error + e2 + e3)


def ptlens(a: ArrayLike, b: ArrayLike, c: ArrayLike) -> Cubic:
    """Lensfun ptlens: D(r) = r (a r^3 + b r^2 + c r + d), d = 1 - a - b - c.

    D'(r) = 4a r^3 + 3b r^2 + 2c r + d, so w = r and the cubic is
    1 + (2c/d) w + (3b/d) w^2 + (4a/d) w^3 (paper Eq. 26).
    """
    a, b, c = (np.asarray(x, dtype=np.float64) for x in (a, b, c))
    d = ptlens_constant(a, b, c)
    with np.errstate(all="ignore"):  # inf or NaN where it overflows: the metrics see to it
        cubic = (2 * c / d, 3 * b / d, 4 * a / d)
    zero = np.zeros_like(d)
    distortion = np.stack(np.broadcast_arrays(a, b, c, d, zero), axis=-1)
    return Cubic(*cubic, power=1, slope_at_centre=d, distortion=distortion)


def poly3(k1: ArrayLike) -> Cubic:
    """Lensfun poly3: D(r) = r (1 - k1 + k1 r^2).

    D'(r) = (1 - k1) + 3 k1 r^2, so w = r^2 and the cubic is the linear
    1 + (3 k1 / (1 - k1)) w (paper Eq. 27).
    """
    k1 = np.asarray(k1, dtype=np.float64)
    d = 1.0 - k1
    zero = np.zeros_like(d)
    with np.errstate(all="ignore"):
        a = 3 * k1 / d
    distortion = np.stack(np.broadcast_arrays(k1, zero, d, zero), axis=-1)
    return Cubic(a, zero, zero, power=2, slope_at_centre=d, distortion=distortion)


def poly5(k1: ArrayLike, k2: ArrayLike) -> Cubic:
    """Lensfun poly5: D(r) = r (1 + k1 r^2 + k2 r^4).

    D'(r) = 1 + 3 k1 r^2 + 5 k2 r^4: w = r^2, cubic 1 + 3 k1 w + 5 k2 w^2
    (paper Eq. 28).
    """
    k1, k2 = np.broadcast_arrays(np.asarray(k1, np.float64), np.asarray(k2, np.float64))
    zero = np.zeros_like(k1)
    one = np.ones_like(k1)
    distortion = np.stack((k2, zero, k1, zero, one, zero), axis=-1)
    with np.errstate(over="ignore"):
        return Cubic(3 * k1, 5 * k2, zero, power=2, slope_at_centre=one, distortion=distortion)


def basic_polynomial(k1: ArrayLike, k2: ArrayLike, k3: ArrayLike) -> Cubic:
    """The paper's basic model F(r) = 1 + k1 r + k2 r^2 + k3 r^3 (Eq. 3).

    D'(r) = 1 + 2 k1 r + 3 k2 r^2 + 4 k3 r^3 (Eq. 5): w = r.
    """
    k1, k2, k3 = np.broadcast_arrays(*(np.asarray(k, np.float64) for k in (k1, k2, k3)))
    zero = np.zeros_like(k1)
    one = np.ones_like(k1)
    distortion = np.stack((k3, k2, k1, one, zero), axis=-1)
    with np.errstate(over="ignore"):
        return Cubic(2 * k1, 3 * k2, 4 * k3, power=1, slope_at_centre=one, distortion=distortion)


def brown_conrady(k1: ArrayLike, k2: ArrayLike, k3: ArrayLike) -> Cubic:
    """Brown-Conrady radial part F(r) = 1 + k1 r^2 + k2 r^4 + k3 r^6 (Eq. 4).

    D'(r) = 1 + 3 k1 r^2 + 5 k2 r^4 + 7 k3 r^6 (Eq. 6): w = r^2. These are
    OpenCV's k1, k2, k3 in normalized (x/z, y/z) camera coordinates.
    """
    k1, k2, k3 = np.broadcast_arrays(*(np.asarray(k, np.float64) for k in (k1, k2, k3)))
    zero = np.zeros_like(k1)
    one = np.ones_like(k1)
    distortion = np.stack((k3, zero, k2, zero, k1, zero, one, zero), axis=-1)
    with np.errstate(over="ignore"):
        return Cubic(3 * k1, 5 * k2, 7 * k3, power=2, slope_at_centre=one, distortion=distortion)


def evaluate(distortion: FloatArray, r: ArrayLike) -> FloatArray:
    """D(r) for coefficient rows (highest power first) and radii, by Horner."""
    r = np.asarray(r, dtype=np.float64)
    result = np.zeros(np.broadcast_shapes(distortion.shape[:-1], r.shape))
    with np.errstate(invalid="ignore", over="ignore"):
        for index in range(distortion.shape[-1]):
            result = result * r + distortion[..., index]
    return result


def leading_sign(distortion: FloatArray) -> NDArray[np.int8]:
    """Sign of D(r) as r -> +inf: the sign of its highest nonzero coefficient."""
    nonzero = distortion != 0
    first = np.argmax(nonzero, axis=-1)
    leading = np.take_along_axis(distortion, first[..., None], axis=-1)[..., 0]
    return np.sign(leading).astype(np.int8)
