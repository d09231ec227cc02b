"""The smallest positive root at which 1 + a w + b w^2 + c w^3 changes sign.

Every distortion model here reduces r_max to that root (see
:mod:`lensaudit.normalizer`). The paper's Algorithm 1 computes it with the
cubic formula alone; in floating point that loses the root when c is tiny
next to a and b, when roots cluster, and it counts a double (tangent) root,
where the polynomial touches zero without crossing, as a fold.

Method, for p(w) = 1 + a w + b w^2 + c w^3:

1. Scale w by a power of two so that the coefficients are at most 1 in size
   (exact, no rounding).
2. Work with the reversed, monic cubic q(x) = x^3 + A x^2 + B x + C,
   x = 1/w: p(w) has the sign of q(1/w) for w > 0, so the first sign change
   of p is the largest x > 0 below which q is negative. q never degenerates:
   a vanishing c only puts a root at x = 0, that is w = infinity.
3. Decide where that root lies from the critical points of q (a quadratic,
   solved without cancellation) and the sign of q at its local minimum,
   evaluated with compensated (error-free) Horner arithmetic. Where that sign
   is too close to call in floating point, the exact discriminant decides,
   in rational arithmetic. A tangent root is thus never taken for a crossing,
   and a pair of close simple roots never missed.
4. Start from the closed-form root (or -C/B for a root near zero) inside the
   bracket where q is monotonic, and polish with Newton steps on q evaluated
   with compensated Horner, falling back to bisection inside the bracket.

Accuracy: a relative error of a few units in the last place for roots that
are not clustered; the finite/infinite decision is exact for binary64 inputs.
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]

_EPS = np.finfo(np.float64).eps
_SPLITTER = 134217729.0  # 2**27 + 1, for Veltkamp's split
_NEWTON_ROUNDS = 80
_PLAIN_NEWTON_STEPS = 5
# Roots whose condition number (sum of |terms| over |x q'(x)|) is below this
# are accurate to 1e-13 after plain Newton steps; others are polished.
_WELL_CONDITIONED = 1e3
_CHUNK = 1 << 15  # elements per pass: keeps numpy's temporaries in cache


def _two_sum(x: FloatArray, y: FloatArray) -> tuple[FloatArray, FloatArray]:
    s = x + y
    z = s - x
    return s, (x - (s - z)) + (y - z)


def _split(x: FloatArray) -> tuple[FloatArray, FloatArray]:
    t = _SPLITTER * x
    high = t - (t - x)
    return high, x - high


def _two_product(x: FloatArray, y: FloatArray) -> tuple[FloatArray, FloatArray]:
    product = x * y
    xh, xl = _split(x)
    yh, yl = _split(y)
    return product, xl * yl - (((product - xh * yh) - xl * yh) - xh * yl)


def _q_compensated(x: FloatArray, A: FloatArray, B: FloatArray, C: FloatArray) -> FloatArray:
    """q(x) = ((x + A) x + B) x + C, as accurate as in twice the precision."""
    s, error = _two_sum(x, A)
    for coefficient in (B, C):
        product, product_error = _two_product(s, x)
        s, sum_error = _two_sum(product, coefficient)
        error = error * x + (product_error + sum_error)
    return s + error


def _q_bound(x: FloatArray, A: FloatArray, B: FloatArray, C: FloatArray) -> FloatArray:
    """A bound on the error of :func:`_q_compensated` at x (second order in eps)."""
    ax = np.abs(x)
    magnitude = ((ax + np.abs(A)) * ax + np.abs(B)) * ax + np.abs(C)
    return 16 * _EPS * _EPS * magnitude


def _scale(a: FloatArray, b: FloatArray, c: FloatArray) -> FloatArray:
    """A power of two s making max(|a s|, |b s^2|^(1/2), |c s^3|^(1/3)) lie in [1/2, 1)."""
    size = np.maximum(np.abs(a), np.maximum(np.sqrt(np.abs(b)), np.cbrt(np.abs(c))))
    _, exponent = np.frexp(size)
    return np.ldexp(1.0, -exponent)


def _exact_discriminant_sign(A: float, B: float, C: float) -> int:
    """Sign of the discriminant of x^3 + A x^2 + B x + C, in exact arithmetic."""
    A, B, C = Fraction(A), Fraction(B), Fraction(C)
    value = 18 * A * B * C - 4 * A**3 * C + A * A * B * B - 4 * B**3 - 27 * C * C
    return (value > 0) - (value < 0)


def _q_plain(x: FloatArray, A: FloatArray, B: FloatArray, C: FloatArray) -> FloatArray:
    return ((x + A) * x + B) * x + C


def _positive_root_guess(m: FloatArray, s: FloatArray) -> FloatArray:
    """An upper bound, within 30 %, of the positive root of t^3 + s t^2 + m = 0 (m <= 0, s >= 0).

    Both terms of the cubic are non-negative at t = min(sqrt(-m/s), cbrt(-m)),
    so the root lies below it; and it is at most 2^(1/3) times too large.
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.fmin(np.sqrt(-m / s), np.cbrt(-m))


def _min_root_scaled(A: FloatArray, B: FloatArray, C: FloatArray) -> FloatArray:
    """Largest x > 0 below which q(x) = x^3 + A x^2 + B x + C is negative; 0 if none.

    Coefficients are at most 1 in magnitude (see :func:`_scale`).
    """
    size = A.shape[0]
    # Critical points of q: 3x^2 + 2A x + B = 0, x = (-A -+ sqrt(A^2 - 3B)) / 3.
    critical_disc = A * A - 3 * B
    has_critical = critical_disc > 0
    root_disc = np.sqrt(np.where(has_critical, critical_disc, 0.0))
    big = -(A + np.copysign(root_disc, A))
    first = big / 3
    second = B / np.where(big != 0, big, 1.0)
    x_max = np.minimum(first, second)  # local maximum of q
    x_min = np.maximum(first, second)  # local minimum of q

    # Is the local minimum below zero? Then the largest crossing root lies to
    # its right; otherwise, left of the local maximum. Decide with plain
    # arithmetic where its error bound allows, else compensated, else exactly.
    q_at_min = _q_plain(x_min, A, B, C)
    # With C = 0 and the minimum at x = 0 (so B = 0 too), q = x^2 (x + A) touches
    # zero exactly there: certain, and common (Lensfun's poly3, ptlens with a = 0).
    touches_at_zero = (x_min == 0) & (C == 0)
    uncertain = np.flatnonzero(
        has_critical
        & ~touches_at_zero
        & (np.abs(q_at_min) <= 4 * _EPS * _magnitude(x_min, A, B, C))
    )
    if uncertain.size:
        xs, As, Bs, Cs = x_min[uncertain], A[uncertain], B[uncertain], C[uncertain]
        precise = _q_compensated(xs, As, Bs, Cs)
        for i in np.flatnonzero(np.abs(precise) <= _q_bound(xs, As, Bs, Cs)):
            # Too close to call: q has three distinct real roots exactly when
            # the discriminant is positive, and then its local minimum is negative.
            sign = _exact_discriminant_sign(float(As[i]), float(Bs[i]), float(Cs[i]))
            precise[i] = -1.0 if sign > 0 else 1.0
        q_at_min[uncertain] = precise
    right = has_critical & (q_at_min < 0)
    left = has_critical & ~right
    monotone = ~has_critical

    # Is that root positive? q increases through it from its bracket's lower end.
    positive = np.where(right, (x_min >= 0) | (C < 0), np.where(left, (x_max > 0) & (C < 0), C < 0))
    result = np.zeros(size)
    work = np.flatnonzero(positive)
    if work.size == 0:
        return result
    A, B, C = A[work], B[work], C[work]
    right, left, monotone = right[work], left[work], monotone[work]
    x_max, x_min, root_disc, q_at_min = x_max[work], x_min[work], root_disc[work], q_at_min[work]

    # A start on the side of the root from which Newton's method converges
    # monotonically: q is convex right of its inflection point, concave left.
    q_at_max = _q_plain(x_max, A, B, C)
    inflection = -A / 3
    q_at_inflection = _q_plain(inflection, A, B, C)
    slope_at_inflection = np.maximum(B - A * A / 3, 0.0)
    # From the inflection point, q(x_i + t) = t^3 + P t + q(x_i) with P >= 0 here.
    with np.errstate(divide="ignore", invalid="ignore"):
        towards = np.fmin(
            np.abs(q_at_inflection) / slope_at_inflection, np.cbrt(np.abs(q_at_inflection))
        )
    guess = np.where(
        right,
        x_min + _positive_root_guess(np.minimum(q_at_min, 0.0), root_disc),
        np.where(
            left,
            x_max - _positive_root_guess(-np.maximum(q_at_max, 0.0), root_disc),
            inflection - np.copysign(towards, q_at_inflection),
        ),
    )
    guess = np.maximum(guess, 0.0)
    lower = np.where(right, np.maximum(x_min, 0.0), 0.0)
    upper = np.where(left, x_max, 1.0 + np.maximum(np.abs(A), np.maximum(np.abs(B), np.abs(C))))
    guess = np.where(
        np.isfinite(guess) & (guess >= lower) & (guess <= upper), guess, (lower + upper) / 2
    )

    # Plain Newton steps: fast, and enough where the root is well conditioned.
    x = guess
    step = np.zeros_like(x)
    for _ in range(_PLAIN_NEWTON_STEPS):
        slope = (3 * x + 2 * A) * x + B
        with np.errstate(divide="ignore", invalid="ignore"):
            step = _q_plain(x, A, B, C) / slope
        x = np.where(np.isfinite(step), x - step, x)
    slope = np.abs((3 * x + 2 * A) * x + B) * np.abs(x)
    settled = (np.abs(step) <= 1e-8 * np.abs(x)) & (
        _magnitude(x, A, B, C) <= _WELL_CONDITIONED * slope
    )
    result[work] = x
    polish = np.flatnonzero(~settled)
    if polish.size:
        result[work[polish]] = _polish(
            x[polish], lower[polish], upper[polish], A[polish], B[polish], C[polish]
        )
    return result


def _magnitude(x: FloatArray, A: FloatArray, B: FloatArray, C: FloatArray) -> FloatArray:
    """Sum of the absolute values of the terms of q(x)."""
    ax = np.abs(x)
    return ((ax + np.abs(A)) * ax + np.abs(B)) * ax + np.abs(C)


def _polish(
    x: FloatArray, lo: FloatArray, hi: FloatArray, A: FloatArray, B: FloatArray, C: FloatArray
) -> FloatArray:
    """Newton's method with compensated residuals, kept inside [lo, hi] by bisection."""
    result = np.array(x)
    active = np.arange(x.size)
    for _ in range(_NEWTON_ROUNDS):
        if active.size == 0:
            break
        value = _q_compensated(x, A, B, C)
        # q increases through the bracket: shrink it around the root.
        below = value < 0
        lo = np.where(below, np.maximum(x, lo), lo)
        hi = np.where(below, hi, np.minimum(x, hi))
        slope = (3 * x + 2 * A) * x + B
        with np.errstate(divide="ignore", invalid="ignore"):
            candidate = x - value / slope
        # Converged when Newton's step no longer moves x (checked before the
        # bracket, which a step of under one ulp can no longer get inside).
        converged = (value == 0) | (np.abs(candidate - x) <= 2 * _EPS * np.abs(x))
        inside = (candidate > lo) & (candidate < hi) & np.isfinite(candidate)
        new_x = np.where(inside, candidate, lo + (hi - lo) / 2)
        done = converged | (hi - lo <= 2 * _EPS * np.abs(hi))
        finished = np.where(value == 0, x, np.where(converged, candidate, new_x))
        result[active[done]] = finished[done]
        keep = ~done
        active = active[keep]
        x, lo, hi = new_x[keep], lo[keep], hi[keep]
        A, B, C = A[keep], B[keep], C[keep]
    if active.size:  # not reached in practice; the bracket is tight by now
        result[active] = x
    return result


def min_positive_root(a: ArrayLike, b: ArrayLike, c: ArrayLike) -> float | FloatArray:
    """Smallest w > 0 at which p(w) = 1 + a w + b w^2 + c w^3 changes sign.

    Arguments broadcast together; a float comes back for scalar input, an
    array otherwise. Since p(0) = 1, this is the first w at which p goes
    negative: a root of odd multiplicity. A double (tangent) root, where p
    touches zero and turns back up, is not one. ``inf`` where p stays
    non-negative on (0, inf); NaN where a coefficient is NaN or infinite.
    Never emits numpy warnings for any input.
    """
    scalar = np.ndim(a) == 0 and np.ndim(b) == 0 and np.ndim(c) == 0
    a, b, c = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (a, b, c)))
    shape = a.shape
    a, b, c = (np.ravel(v) for v in (a, b, c))
    result = np.full(a.shape, np.inf)
    with np.errstate(all="ignore"):
        finite = np.isfinite(a) & np.isfinite(b) & np.isfinite(c)
        result[~finite] = np.nan
        work = np.flatnonzero(finite & ((a != 0) | (b != 0) | (c != 0)))
        for start in range(0, work.size, _CHUNK):
            chunk = work[start : start + _CHUNK]
            ac, bc, cc = a[chunk], b[chunk], c[chunk]
            s = _scale(ac, bc, cc)
            root = _min_root_scaled(ac * s, bc * s * s, cc * s * s * s)
            result[chunk] = np.where(root > 0, s / np.where(root > 0, root, 1.0), np.inf)
    if scalar:
        return float(result[0])
    return result.reshape(shape)


def min_positive_root_paper(a: float, b: float, c: float) -> float:
    """The paper's Algorithm 1 (MinPosRoot), as printed, in plain floating point.

    Kept as the reference the robust :func:`min_positive_root` is measured
    against. Note that it tests "positive root", not "sign change", and has
    no guard for the rounding issues discussed in the module docstring.
    """
    r = math.inf
    if c != 0:
        beta = 2 * b**3 - 9 * a * b * c + 27 * c**2
        gamma = b**2 - 3 * a * c
        delta = beta**2 - 4 * gamma**3
        if delta > 0:
            u = math.copysign(
                abs((beta + math.sqrt(delta)) / 2) ** (1 / 3), (beta + math.sqrt(delta)) / 2
            )
            r = ((gamma / u) + u + b) / (-3 * c)
        else:
            theta = math.atan2(math.sqrt(-delta), beta)
            for t in (-1, 0, 1):
                s = (2 * math.sqrt(gamma) * math.cos((theta + 2 * math.pi * t) / 3) + b) / (-3 * c)
                if r > s > 0:
                    r = s
    elif b != 0:
        delta = a**2 - 4 * b
        if delta > 0:
            delta = math.sqrt(delta) - a
            if delta > 0:
                r = 2 / delta
    elif a < 0:
        r = 1 / -a
    return r


def min_positive_root_paper_vectorized(a: ArrayLike, b: ArrayLike, c: ArrayLike) -> FloatArray:
    """:func:`min_positive_root_paper` over arrays with numpy, branch for branch."""
    a, b, c = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (a, b, c)))
    r = np.full(a.shape, np.inf)
    with np.errstate(all="ignore"):
        beta = 2 * b**3 - 9 * a * b * c + 27 * c**2
        gamma = b**2 - 3 * a * c
        delta = beta**2 - 4 * gamma**3
        half = (beta + np.sqrt(delta)) / 2
        u = np.copysign(np.abs(half) ** (1 / 3), half)  # as the scalar version does
        one = ((gamma / u) + u + b) / (-3 * c)
        theta = np.arctan2(np.sqrt(-delta), beta)
        three = np.full(a.shape, np.inf)
        for t in (-1, 0, 1):
            s = (2 * np.sqrt(gamma) * np.cos((theta + 2 * np.pi * t) / 3) + b) / (-3 * c)
            three = np.where((s < three) & (s > 0), s, three)
        cubic = np.where(delta > 0, one, three)
        qdelta = a**2 - 4 * b
        qroot = np.sqrt(qdelta) - a
        quadratic = np.where((qdelta > 0) & (qroot > 0), 2 / qroot, np.inf)
        linear = np.where(a < 0, 1 / -a, np.inf)
        r = np.where(c != 0, cubic, np.where(b != 0, quadratic, linear))
    return r
