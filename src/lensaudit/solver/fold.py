"""The first fold of any model described by :class:`lensaudit.normalizer.Polynomial`.

A model D(r) folds back where D' first changes sign: its first local
maximum. The model describes D'(r) / D'(0) as a polynomial in w = r**power
and D itself; :func:`lensaudit.solver.polynomial.first_sign_change` finds
the root, and D is evaluated there with compensated arithmetic.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..normalizer import Polynomial, opencv_fisheye
from .arrays import _two_product, _two_sum
from .polynomial import first_sign_change

FloatArray = NDArray[np.float64]


def _evaluate_compensated(distortion: FloatArray, r: FloatArray) -> FloatArray:
    """D(r) by compensated Horner (coefficients highest power first): the terms of D
    often alternate in sign, and this keeps the result within about one ulp
    of D(r) unless D(r) is tiny next to its terms. Plain Horner where an
    intermediate overflows."""
    value = distortion[..., 0] * np.ones_like(r)
    error = np.zeros_like(value)
    plain = value
    for index in range(1, distortion.shape[-1]):
        coefficient = distortion[..., index]
        product, product_error = _two_product(value, r)
        value, sum_error = _two_sum(product, coefficient)
        error = error * r + (product_error + sum_error)
        plain = plain * r + coefficient
    result = value + error
    return np.where(np.isfinite(result), result, plain)


def first_fold(model: Polynomial) -> tuple[FloatArray, FloatArray]:
    """(r_fold, D(r_fold)): where D first stops increasing, and its value there.

    Units are the model's (radians for OpenCV's fisheye: theta and theta_d).
    r_fold = w^(1/power) for w the first sign change of D'(r) / D'(0), within
    one ulp of it for power 1 and about one ulp for power 2 (a correctly
    rounded square root). D is stationary at its maximum, so D(r_fold) errs
    by little more than its compensated evaluation: a few ulps. Where D'
    never changes sign, D increases without bound: (inf, inf). NaN where a
    coefficient is not finite or D'(0) is not positive (no valid domain).
    Arrays of the model's shape (without its last axis); floats for one model.
    """
    with np.errstate(all="ignore"):
        w = np.asarray(first_sign_change(model.coefficients), dtype=np.float64)
        roots = {1: w, 2: np.sqrt(w)}  # exact, and correctly rounded
        r = roots[model.power] if model.power in roots else w ** (1.0 / model.power)
        d = _evaluate_compensated(model.distortion, r)
        d = np.where(np.isinf(r), np.inf, d)
        valid = np.asarray(model.slope_at_centre > 0) & np.isfinite(model.distortion).all(axis=-1)
        r, d = np.where(valid, r, np.nan), np.where(valid, d, np.nan)
    if r.ndim == 0:
        return float(r), float(d)
    return r, d


def opencv_fisheye_fold(
    k1: ArrayLike, k2: ArrayLike, k3: ArrayLike, k4: ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """(theta_fold, theta_d at the fold), in radians, of OpenCV's fisheye model.

    theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8)
    (Gyroflow's lens profiles' distortion_coeffs). theta_fold is the first
    angle past which theta_d decreases, the square root of the first sign
    change of 1 + 3 k1 u + 5 k2 u^2 + 7 k3 u^3 + 9 k4 u^4; (inf, inf) where
    theta_d increases everywhere. Sony a7 IV with Sigma 28-70 at 70 mm, k =
    (0.303, 9.42, -168.1, 297.7): theta_fold = 0.36607 rad (20.97 degrees).
    """
    return first_fold(opencv_fisheye(k1, k2, k3, k4))
