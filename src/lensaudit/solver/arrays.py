"""The solver's array code: :func:`min_positive_root` over numpy arrays (see
:mod:`lensaudit.solver` for how it proves its answers)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .constants import ABSENT as _ABSENT
from .constants import EPS as _EPS
from .constants import HALF_WIDTH as _HALF_WIDTH
from .constants import MAX as _MAX
from .constants import MAX_BITS, bits_float, float_bits
from .constants import PLAIN_NEWTON_STEPS as _PLAIN_NEWTON_STEPS
from .constants import SAFE_SCALED as _SAFE_SCALED
from .constants import SMALLEST_NORMAL as _SMALLEST_NORMAL
from .constants import SPLITTER as _SPLITTER
from .constants import WELL_CONDITIONED as _WELL_CONDITIONED

# Exact arithmetic is imported where it is needed: few inputs ever take that path.
if TYPE_CHECKING:
    from fractions import Fraction

FloatArray = NDArray[np.float64]
#: Mantissas and exponents of a, b, c, as numpy.frexp gives them.
_Frexps = tuple[
    FloatArray, NDArray[np.int32], FloatArray, NDArray[np.int32], FloatArray, NDArray[np.int32]
]

_NEWTON_ROUNDS = 80
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


def _exact_discriminant_sign(A: float, B: float, C: float) -> int:
    """Sign of the discriminant of x^3 + A x^2 + B x + C, in exact arithmetic."""
    from fractions import Fraction  # fractions: only for the exact fallback, rarely reached

    A, B, C = Fraction(A), Fraction(B), Fraction(C)
    value = 18 * A * B * C - 4 * A**3 * C + A * A * B * B - 4 * B**3 - 27 * C * C
    return (value > 0) - (value < 0)


def _q_plain(x: FloatArray, A: FloatArray, B: FloatArray, C: FloatArray) -> FloatArray:
    return ((x + A) * x + B) * x + C


def _cube_root_above(y: FloatArray) -> FloatArray:
    """About cbrt(y) for finite y >= 0, from above (within 11 %), by basic operations alone.

    numpy's cbrt differs from one machine to the next (SIMD versions round
    differently), and the fast path's answer must be the same float wherever
    it runs (:mod:`lensaudit.solver.kernel` repeats it): the power of two 2^k just
    above cbrt(y) (at most twice it), then two of Newton's steps, which
    approach the root from above.
    """
    e = np.frexp(y)[1]
    z = np.ldexp(1.0, -((-e) // 3))  # y < 2^e <= 2^(3k), k = ceil(e / 3)
    for _ in range(2):
        z = (2 * z + y / (z * z)) / 3
    return np.where(y > 0, z, y)


def _scale_exponent(a: FloatArray, b: FloatArray, c: FloatArray) -> NDArray[np.int32]:
    """t such that |a| 2^t, |b| 2^2t and |c| 2^3t are at most 1, the largest at
    least 1/8: minus the exponent (as frexp gives it) of max(|a|, sqrt|b|,
    cbrt|c|), that of cbrt|c| computed exactly from c's. 0 if all are zero."""
    exponents = [
        np.where(a != 0, np.frexp(a)[1], _ABSENT),
        np.where(b != 0, np.frexp(np.sqrt(np.abs(b)))[1], _ABSENT),
        np.where(c != 0, -((-np.frexp(c)[1]) // 3), _ABSENT),
    ]
    largest = np.maximum(exponents[0], np.maximum(exponents[1], exponents[2]))
    return np.where(largest == _ABSENT, 0, -largest)


def _positive_root_guess(m: FloatArray, s: FloatArray) -> FloatArray:
    """An upper bound, within 30 %, of the positive root of t^3 + s t^2 + m = 0 (m <= 0, s >= 0).

    Both terms of the cubic are non-negative at t = min(sqrt(-m/s), cbrt(-m)),
    so the root lies below it; and it is at most 2^(1/3) times too large.
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.fmin(np.sqrt(-m / s), _cube_root_above(-m))


def _min_root_scaled(A: FloatArray, B: FloatArray, C: FloatArray) -> FloatArray:
    """Largest x > 0 below which q(x) = x^3 + A x^2 + B x + C is negative; 0 if none.

    Coefficients are at most 1 in magnitude (scaled per degree by :func:`_solve`).
    """
    size = A.shape[0]
    has_critical, root_disc, x_max, x_min = _critical_points(A, B)
    # Is the local minimum below zero? Then the largest crossing root lies to
    # its right; otherwise, left of the local maximum.
    q_at_min = _q_at_local_minimum(x_min, has_critical, A, B, C)
    right = has_critical & (q_at_min < 0)
    left = has_critical & ~right

    # Is that root positive? q increases through it from its bracket's lower end.
    positive = np.where(right, (x_min >= 0) | (C < 0), np.where(left, (x_max > 0) & (C < 0), C < 0))
    result = np.zeros(size)
    work = np.flatnonzero(positive)
    if work.size == 0:
        return result
    A, B, C = A[work], B[work], C[work]
    right, left = right[work], left[work]
    x_max, x_min, root_disc, q_at_min = x_max[work], x_min[work], root_disc[work], q_at_min[work]

    guess, lower, upper = _newton_start(A, B, C, right, left, x_max, x_min, root_disc, q_at_min)
    x, settled = _plain_newton(guess, A, B, C)
    result[work] = x
    polish = np.flatnonzero(~settled)
    if polish.size:
        result[work[polish]] = _polish(
            x[polish], lower[polish], upper[polish], A[polish], B[polish], C[polish]
        )
    return result


def _critical_points(
    A: FloatArray, B: FloatArray
) -> tuple[NDArray[np.bool_], FloatArray, FloatArray, FloatArray]:
    """(has_critical, root_disc, x_max, x_min) of q: whether it has a local maximum
    and minimum, sqrt(A^2 - 3B) (0 where it has none), and where they lie."""
    # Critical points of q: 3x^2 + 2A x + B = 0, x = (-A -+ sqrt(A^2 - 3B)) / 3.
    critical_disc = A * A - 3 * B
    has_critical = critical_disc > 0
    root_disc = np.sqrt(np.where(has_critical, critical_disc, 0.0))
    big = -(A + np.copysign(root_disc, A))
    first = big / 3
    second = B / np.where(big != 0, big, 1.0)
    x_max = np.minimum(first, second)  # local maximum of q
    x_min = np.maximum(first, second)  # local minimum of q
    return has_critical, root_disc, x_max, x_min


def _q_at_local_minimum(
    x_min: FloatArray, has_critical: NDArray[np.bool_], A: FloatArray, B: FloatArray, C: FloatArray
) -> FloatArray:
    """q(x_min), its sign certain wherever q has critical points."""
    # Decide with plain arithmetic where its error bound allows, else
    # compensated, else exactly.
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
    return q_at_min


def _newton_start(
    A: FloatArray,
    B: FloatArray,
    C: FloatArray,
    right: NDArray[np.bool_],
    left: NDArray[np.bool_],
    x_max: FloatArray,
    x_min: FloatArray,
    root_disc: FloatArray,
    q_at_min: FloatArray,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(guess, lower, upper): a start for Newton's method and a bracket around the root
    (right of the local minimum, left of the local maximum, or q monotone)."""
    # A start on the side of the root from which Newton's method converges
    # monotonically: q is convex right of its inflection point, concave left.
    q_at_max = _q_plain(x_max, A, B, C)
    inflection = -A / 3
    q_at_inflection = _q_plain(inflection, A, B, C)
    slope_at_inflection = np.maximum(B - A * A / 3, 0.0)
    # From the inflection point, q(x_i + t) = t^3 + P t + q(x_i) with P >= 0 here.
    with np.errstate(divide="ignore", invalid="ignore"):
        towards = np.fmin(
            np.abs(q_at_inflection) / slope_at_inflection, _cube_root_above(np.abs(q_at_inflection))
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
    return guess, lower, upper


def _plain_newton(
    guess: FloatArray, A: FloatArray, B: FloatArray, C: FloatArray
) -> tuple[FloatArray, NDArray[np.bool_]]:
    """(x, settled): x after plain Newton steps from guess; settled where x needs no polish."""
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
    return x, settled


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


# -- the fast path: certificate ------------------------------------------------------

#: Absolute allowance for underflow in evaluations scaled so that the largest
#: term is at least 1/16: every rounding below the normal range costs < 2^-1074.
_UNDERFLOW_SLOP = 2.0**-1060


def _reliably(value: FloatArray, bound: FloatArray) -> NDArray[np.int8]:
    """+1 or -1 where |value| exceeds its error bound, 0 where the sign is uncertain."""
    return np.where(value > bound, 1, np.where(value < -bound, -1, 0)).astype(np.int8)


def _q_sign(x: FloatArray, A: FloatArray, B: FloatArray, C: FloatArray) -> NDArray[np.int8]:
    """Sign of q(x) = x^3 + A x^2 + B x + C, 0 where even compensated arithmetic cannot tell.

    Valid where no intermediate underflows (see :data:`_SAFE_SCALED`).
    """
    magnitude = _magnitude(x, A, B, C)
    # Horner's rule in n = 3 steps errs by at most gamma_6 = 6 eps / (1 - 6 eps)
    # times the magnitude; compensated Horner by eps |q| + gamma_6^2 magnitude.
    sign = _reliably(_q_plain(x, A, B, C), 7 * _EPS * magnitude)
    unsure = np.flatnonzero(sign == 0)
    if unsure.size:
        xs, As, Bs, Cs = x[unsure], A[unsure], B[unsure], C[unsure]
        sign[unsure] = _reliably(_q_compensated(xs, As, Bs, Cs), 40 * _EPS**2 * magnitude[unsure])
    return sign


def _certified_fast(
    x: FloatArray, A: FloatArray, B: FloatArray, C: FloatArray, t: NDArray[np.int32]
) -> tuple[FloatArray, NDArray[np.bool_]]:
    """(w = 2^t / x, proven) for roots x > 0 of the scaled reversed cubic.

    Proven where q < 0 at x (1 - h) and q, q' > 0 at x (1 + h), h = 2^-44, and
    q' cannot vanish beyond: q'' > 0 there too, or q' has no real root. Then q
    stays positive beyond, and the last sign change lies in between. w must
    also be a normal double with room to spare.
    """
    lo = x * (1 - _HALF_WIDTH)
    hi = x * (1 + _HALF_WIDTH)
    # x below 2^-300 would take intermediates near underflow; no such root
    # exists when every coefficient is at least 2^-250 (see _SAFE_SCALED).
    proven = x >= 2.0**-300
    ahi = np.abs(hi)
    slope = (3 * hi + 2 * A) * hi + B
    slope_size = (3 * ahi + 2 * np.abs(A)) * ahi + np.abs(B)
    proven &= slope > 5 * _EPS * slope_size
    # q' stays positive beyond hi: past the inflection point, or q' has no root.
    convex = 3 * hi + A > 3 * _EPS * (3 * ahi + np.abs(A))
    no_critical = A * A - 3 * B < -3 * _EPS * (A * A + 3 * np.abs(B))
    proven &= convex | no_critical
    w = np.ldexp(1 / x, t)
    proven &= (np.ldexp(1 / hi, t) >= 2 * _SMALLEST_NORMAL) & (
        np.ldexp(1 / lo, t) <= _MAX * (1 - 8 * _EPS)
    )
    check = np.flatnonzero(proven)
    if check.size:
        Ac, Bc, Cc = A[check], B[check], C[check]
        proven[check] = (_q_sign(hi[check], Ac, Bc, Cc) > 0) & (_q_sign(lo[check], Ac, Bc, Cc) < 0)
    return w, proven


# -- exact decision ------------------------------------------------------------------

# Which root is wanted, as decided from the coefficients' signs and the
# discriminant (see the module docstring). The test "root <= X" is:
_INFINITE = 0  # no sign change on (0, inf)
_ONE = 1  # one crossing: p(X) <= 0
_SECOND_OF_THREE = 2  # c > 0, roots r1 < 0 < r2 < r3: p(X) <= 0 or X past the larger critical point
_FIRST_OF_THREE = 3  # c < 0, roots 0 < r1 < r2 < r3: p(X) <= 0 or X past the smaller one
_FIRST_OF_TWO = 4  # c = 0, roots 0 < r1 < r2: p(X) <= 0 or X past the critical point
_REPEATED = 5  # zero discriminant with a crossing: a rational root (exact path only)
_UNDECIDED = -1  # the discriminant's sign was too close to call in floating point


def _sum_of_terms_sign(
    terms: list[tuple[FloatArray, NDArray[np.int32]]], rounding: float
) -> NDArray[np.int8]:
    """Sign of sum m_k 2^e_k without overflow or underflow; 0 where uncertain.

    Each mantissa m_k carries a relative error of at most ``rounding``; the
    sum is taken relative to the largest term, and terms too small to matter
    there flush to zero within :data:`_UNDERFLOW_SLOP`.
    """
    exponents = [np.where(m != 0, e, _ABSENT) for m, e in terms]
    largest = exponents[0]
    for e in exponents[1:]:
        largest = np.maximum(largest, e)
    scaled = [np.ldexp(m, e - largest) for (m, _), e in zip(terms, exponents, strict=True)]
    total = scaled[0]
    magnitude = np.abs(scaled[0])
    for s in scaled[1:]:
        total = total + s
        magnitude = magnitude + np.abs(s)
    bound = (rounding + len(terms) * _EPS) * magnitude + _UNDERFLOW_SLOP
    return _reliably(total, bound)


def _classify(
    a: FloatArray,
    b: FloatArray,
    c: FloatArray,
    frexps: _Frexps,
) -> NDArray[np.int8]:
    """The kind of each cubic (see _INFINITE ... _UNDECIDED), from signs and discriminants."""
    ma, ea, mb, eb, mc, ec = frexps
    kind = np.full(a.shape, _INFINITE, dtype=np.int8)
    kind[(c < 0) | ((c == 0) & (b < 0)) | ((c == 0) & (b == 0) & (a < 0))] = _ONE
    # Three real roots (discriminant > 0) make Descartes' count exact: with c < 0
    # one or three positive roots, with c > 0 none or two.
    three = (c < 0) & (a < 0) & (b > 0)
    two = (c > 0) & ((a < 0) | (b < 0))
    need = np.flatnonzero(three | two)
    if need.size:
        sa, sb, sc = ma[need], mb[need], mc[need]
        xa, xb, xc = ea[need], eb[need], ec[need]
        # Discriminant of c w^3 + b w^2 + a w + 1, term by term.
        sign = _sum_of_terms_sign(
            [
                (18 * sa * sb * sc, xa + xb + xc),
                (-4 * sb * sb * sb, 3 * xb),
                ((sa * sb) * (sa * sb), 2 * xa + 2 * xb),
                (-4 * sa * sa * sa * sc, 3 * xa + xc),
                (-27 * sc * sc, 2 * xc),
            ],
            3 * _EPS,
        )
        is_three = three[need]
        kind[need] = np.where(
            sign == 0,
            _UNDECIDED,
            np.where(
                is_three,
                np.where(sign > 0, _FIRST_OF_THREE, _ONE),
                np.where(sign > 0, _SECOND_OF_THREE, _INFINITE),
            ),
        )
    # A quadratic with b > 0 crosses only through two positive roots (a < 0, a^2 > 4b).
    pair = np.flatnonzero((c == 0) & (b > 0) & (a < 0))
    if pair.size:
        sa, sb = ma[pair], mb[pair]
        sign = _sum_of_terms_sign([(sa * sa, 2 * ea[pair]), (-4 * sb, eb[pair])], _EPS)
        kind[pair] = np.where(sign == 0, _UNDECIDED, np.where(sign > 0, _FIRST_OF_TWO, _INFINITE))
    return kind


# -- signs at any scale: estimates proven, and bisection ---------------------------


def _horner_signs(
    u: FloatArray, coefficients: list[FloatArray], inexact: FloatArray | None = None
) -> NDArray[np.int8]:
    """Sign of sum coefficients[k] u^k (highest power first), 0 where uncertain.

    Coefficients are at most a few units in size with the largest term at least
    1/16, u in [1/2, 1); ``inexact`` is the part of the magnitude whose
    coefficients were rounded (relative error eps). Plain Horner first,
    compensated Horner where that cannot tell.
    """
    value = coefficients[0]
    magnitude = np.abs(coefficients[0])
    for coefficient in coefficients[1:]:
        value = value * u + coefficient
        magnitude = magnitude * u + np.abs(coefficient)
    steps = len(coefficients) - 1
    extra = 0.0 if inexact is None else _EPS * inexact
    plain_bound = (2 * steps + 1) * _EPS * magnitude + extra + _UNDERFLOW_SLOP
    sign = _reliably(value, plain_bound)
    unsure = np.flatnonzero(sign == 0)
    if unsure.size and inexact is None:
        us = u[unsure]
        s = coefficients[0][unsure]
        error = np.zeros_like(us)
        for coefficient in coefficients[1:]:
            product, product_error = _two_product(s, us)
            s, sum_error = _two_sum(product, coefficient[unsure])
            error = error * us + (product_error + sum_error)
        bound = 40 * _EPS**2 * magnitude[unsure] + _UNDERFLOW_SLOP
        sign[unsure] = _reliably(s + error, bound)
    return sign


def _at_scale(
    u_exponent: NDArray[np.int32], terms: list[tuple[FloatArray, NDArray[np.int32], int]]
) -> list[FloatArray]:
    """Coefficients of sum m_k 2^e_k X^k as a polynomial in u = X / 2^ex, over 2^E.

    ``terms`` are (m_k, e_k, k), highest power first; E is the exponent of the
    largest term, so that no coefficient overflows.
    """
    exponents = [np.where(m != 0, e + k * u_exponent, _ABSENT) for m, e, k in terms]
    largest = exponents[0]
    for e in exponents[1:]:
        largest = np.maximum(largest, e)
    return [np.ldexp(m, e - largest) for (m, _, _), e in zip(terms, exponents, strict=True)]


def _root_at_most(
    x: FloatArray,
    kind: NDArray[np.int8],
    frexps: _Frexps,
) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """(wanted root <= x, certain) for x > 0, from the signs of p, p' and p'' at x."""
    ma, ea, mb, eb, mc, ec = frexps
    u, ex = np.frexp(x)
    one = np.full_like(u, 0.5)
    p_sign = _horner_signs(
        u,
        _at_scale(
            ex,
            [(mc, ec, 3), (mb, eb, 2), (ma, ea, 1), (one, np.ones_like(ex), 0)],
        ),
    )
    at_most = p_sign < 0
    certain = p_sign != 0
    # Past a critical point: only asked where p(x) > 0 and two or three roots.
    ask = np.flatnonzero((p_sign > 0) & (kind >= _SECOND_OF_THREE))
    if ask.size:
        us, xs, ks = u[ask], ex[ask], kind[ask]
        sa, sb, sc = ma[ask], mb[ask], mc[ask]
        three_c = 3 * sc  # rounded: its error enters the bound
        slope_coefficients = _at_scale(
            xs, [(three_c, ec[ask], 2), (sb, eb[ask] + 1, 1), (sa, ea[ask], 0)]
        )
        slope = _horner_signs(us, slope_coefficients, np.abs(slope_coefficients[0]) * us * us)
        bend_coefficients = _at_scale(xs, [(three_c, ec[ask], 1), (sb, eb[ask], 0)])
        bend = _horner_signs(us, bend_coefficients, np.abs(bend_coefficients[0]) * us)
        past_larger = ((slope > 0) & (bend > 0), (slope < 0) | (bend < 0))
        past_smaller = ((slope > 0) | (bend < 0), (slope < 0) & (bend > 0))
        past_only = (slope > 0, slope < 0)
        yes = np.where(
            ks == _SECOND_OF_THREE,
            past_larger[0],
            np.where(ks == _FIRST_OF_THREE, past_smaller[0], past_only[0]),
        )
        no = np.where(
            ks == _SECOND_OF_THREE,
            past_larger[1],
            np.where(ks == _FIRST_OF_THREE, past_smaller[1], past_only[1]),
        )
        at_most[ask] = yes
        certain[ask] = yes | no
    return at_most, certain


def _at_scale_cubic(x: FloatArray, frexps: _Frexps) -> tuple[FloatArray, list[FloatArray]]:
    """(u, coefficients): p(x) = 2^E sum coefficients[k] u^(3-k), x = u 2^ex, u in [1/2, 1)."""
    ma, ea, mb, eb, mc, ec = frexps
    u, ex = np.frexp(x)
    one = np.full_like(u, 0.5)
    terms = [(mc, ec, 3), (mb, eb, 2), (ma, ea, 1), (one, np.ones_like(ex), 0)]
    return u, _at_scale(ex, terms)


def _newton_at_scale(x: FloatArray, frexps: _Frexps, steps: int) -> FloatArray:
    """Plain Newton steps on p from x > 0, each at the scale of its iterate."""
    for _ in range(steps):
        u, (c3, c2, c1, c0) = _at_scale_cubic(x, frexps)
        value = ((c3 * u + c2) * u + c1) * u + c0
        slope = (3 * c3 * u + 2 * c2) * u + c1
        moved = np.ldexp(u - value / slope, np.frexp(x)[1])
        x = np.where(np.isfinite(moved) & (moved > 0), moved, x)
    return x


def _lower_cluster_roots(frexps: _Frexps) -> tuple[FloatArray, FloatArray]:
    """Roots of a + b w + c w^2, NaN where not positive and finite.

    Where the constant 1 of p is negligible (roots much larger than those of
    the fast path's scale), these approximate the roots of p. Computed from
    mantissas and exponents, scaled so that nothing overflows.
    """
    ma, ea, mb, eb, mc, ec = frexps
    s = (ea - ec) // 2  # w = 2^s v balances a and c w^2
    beta = np.ldexp(mb, eb + s - ea)
    gamma = np.ldexp(mc, ec + 2 * s - ea)
    disc = beta * beta - 4 * ma * gamma
    q = -(beta + np.copysign(np.sqrt(disc), beta)) / 2
    # b dominant (or a or c zero): one root near -a/b, one near -b/c.
    apart = (np.abs(beta) > 2.0**500) | (ma == 0) | (mc == 0)
    first = np.where(apart, np.ldexp(-ma / mb, ea - eb - s), ma / q)
    second = np.where(apart, np.ldexp(-mb / mc, eb - ec - s), q / gamma)
    roots = []
    for v in (first, second):
        w = np.ldexp(v, s)
        roots.append(np.where(np.isfinite(w) & (w > 0), w, np.nan))
    return roots[0], roots[1]


def _certify_estimates(x: FloatArray, kind: NDArray[np.int8], frexps: _Frexps) -> NDArray[np.bool_]:
    """True where the wanted root provably lies within 64 doubles either side of x > 0."""
    bits = x.view(np.int64)
    below = np.maximum(bits - 64, 1).view(np.float64)
    above = np.minimum(bits + 64, MAX_BITS).view(np.float64)
    proven = np.isfinite(x) & (x > 0)
    check = np.flatnonzero(proven)
    parts = tuple(v[check] for v in frexps)
    at_most, certain = _root_at_most(below[check], kind[check], parts)
    proven[check] = ~at_most & certain
    check = check[proven[check]]
    parts = tuple(v[check] for v in frexps)
    at_most, certain = _root_at_most(above[check], kind[check], parts)
    proven[check] = at_most & certain
    return proven


_SEARCH_BEYOND, _SEARCH_ESTIMATE, _SEARCH_BISECT, _SEARCH_UNSURE = range(4)


def _search(
    a: FloatArray, b: FloatArray, c: FloatArray, kind: NDArray[np.int8], frexps: _Frexps
) -> tuple[FloatArray, NDArray[np.int8]]:
    """(roots, outcome) for cubics known to change sign somewhere on (0, inf).

    Outcome _SEARCH_BEYOND: the root exceeds the largest double (inf).
    Otherwise estimates (the fast path with negligible coefficients dropped,
    and the roots of a + b w + c w^2), polished at their own scale, are
    proven by the exact test a few doubles either side (_SEARCH_ESTIMATE);
    the others are left to bisection (_SEARCH_BISECT), or to exact arithmetic
    where the test at the largest double was too close to call.
    """
    size = a.size
    result = np.full(size, np.inf)
    at_max, certain = _root_at_most(np.full(size, _MAX), kind, frexps)
    outcome = np.where(certain, _SEARCH_BEYOND, _SEARCH_UNSURE).astype(np.int8)
    open_ = np.flatnonzero(certain & at_max)
    if open_.size == 0:
        return result, outcome
    outcome[open_] = _SEARCH_BISECT

    ao, bo, co = a[open_], b[open_], c[open_]
    parts = tuple(v[open_] for v in frexps)
    t = _scale_exponent(ao, bo, co)
    A, B, C = (
        np.where(np.abs(v) >= _SAFE_SCALED, v, 0.0)
        for v in (np.ldexp(ao, t), np.ldexp(bo, 2 * t), np.ldexp(co, 3 * t))
    )
    x = _min_root_scaled(A, B, C)
    top = np.where(x > 0, np.ldexp(1 / np.where(x > 0, x, 1.0), t), np.nan)
    pending = np.arange(open_.size)
    for estimate in (top, *_lower_cluster_roots(parts)):
        usable = pending[np.isfinite(estimate[pending])]
        if usable.size == 0:
            continue
        sub = tuple(v[usable] for v in parts)
        polished = _newton_at_scale(estimate[usable], sub, 4)
        proven = _certify_estimates(polished, kind[open_[usable]], sub)
        result[open_[usable[proven]]] = polished[proven]
        outcome[open_[usable[proven]]] = _SEARCH_ESTIMATE
        pending = np.setdiff1d(pending, usable[proven], assume_unique=True)
    return result, outcome


def _bisect(kind: NDArray[np.int8], frexps: _Frexps) -> tuple[FloatArray, NDArray[np.bool_]]:
    """(root, found) by bisection over the bit patterns of positive doubles.

    For roots known to lie at or below the largest double. The root is the
    upper end of the final pair of adjacent doubles. Not found where a sign
    was too close to call (the root is then the bracket's upper end so far).
    """
    size = kind.shape[0]
    result = np.full(size, np.inf)
    found = np.ones(size, dtype=bool)
    active = np.arange(size)
    lo = np.zeros(size, dtype=np.int64)  # the bits of 0.0, below the root
    hi = np.full(size, MAX_BITS, dtype=np.int64)  # at or above it
    while active.size:
        middle = lo + (hi - lo) // 2
        parts = tuple(v[active] for v in frexps)
        at_most, certain = _root_at_most(middle.view(np.float64), kind[active], parts)
        hi = np.where(at_most, middle, hi)
        lo = np.where(at_most, lo, middle)
        found[active[~certain]] = False
        done = ~certain | (hi - lo <= 1)
        result[active[done]] = hi[done].view(np.float64)
        keep = ~done
        active, lo, hi = active[keep], lo[keep], hi[keep]
    return result, found


# -- exact arithmetic ------------------------------------------------------------------


def _integer_cubic(a: float, b: float, c: float) -> tuple[int, int, int, int]:
    """Integers (P0, P1, P2, P3) proportional to (1, a, b, c), with a positive factor."""
    ratios = [x.as_integer_ratio() for x in (1.0, a, b, c)]
    denominator = max(d for _, d in ratios)  # all powers of two
    return tuple(n * (denominator // d) for n, d in ratios)  # type: ignore[return-value]


def _exact_kind(P0: int, P1: int, P2: int, P3: int) -> int:
    """The kind of the cubic (see _INFINITE ...), exactly."""
    if P3 != 0:
        three = P3 < 0 and P1 < 0 and P2 > 0
        two = P3 > 0 and (P1 < 0 or P2 < 0)
        if not (three or two):
            return _ONE if P3 < 0 else _INFINITE
        discriminant = (
            18 * P3 * P2 * P1 * P0
            - 4 * P2**3 * P0
            + P2 * P2 * P1 * P1
            - 4 * P3 * P1**3
            - 27 * P3 * P3 * P0 * P0
        )
        if two:
            return _SECOND_OF_THREE if discriminant > 0 else _INFINITE
        if discriminant == 0:
            return _REPEATED
        return _FIRST_OF_THREE if discriminant > 0 else _ONE
    if P2 < 0:
        return _ONE
    if P2 > 0:
        return _FIRST_OF_TWO if P1 < 0 and P1 * P1 > 4 * P2 * P0 else _INFINITE
    return _ONE if P1 < 0 else _INFINITE


def _exact_at_most(P: tuple[int, int, int, int], kind: int, n: int, d: int) -> bool:
    """Whether the wanted root is at most n / d (d > 0), exactly."""
    P0, P1, P2, P3 = P
    value = ((P3 * n + P2 * d) * n + P1 * d * d) * n + P0 * d * d * d
    if value <= 0 or kind == _ONE:
        return value <= 0
    slope = P1 * d * d + 2 * P2 * n * d + 3 * P3 * n * n  # p'(n/d) d^2
    if kind == _FIRST_OF_TWO:
        return slope > 0
    bend = P2 * d + 3 * P3 * n  # p''(n/d) d / 2
    if kind == _SECOND_OF_THREE:
        return slope > 0 and bend > 0
    return slope > 0 or bend < 0  # _FIRST_OF_THREE


def _round_exact(root: Fraction) -> float:
    return math.inf if root > _MAX else float(root)  # int / int rounds correctly


def _exact_min_positive_root(a: float, b: float, c: float, estimate: float = math.nan) -> float:
    """The root in exact integer arithmetic on the binary64 inputs, correctly rounded.

    ``estimate`` only saves time: the search starts around it.
    """
    from fractions import Fraction  # fractions: only for the exact fallback, rarely reached

    P = _integer_cubic(a, b, c)
    P0, P1, P2, P3 = P
    kind = _exact_kind(*P)
    if kind == _INFINITE:
        return math.inf
    if kind == _REPEATED:
        # A double root r and a simple one s (c < 0, all positive), or a triple root.
        curvature = P2 * P2 - 3 * P3 * P1
        if curvature == 0:
            return _round_exact(Fraction(-P2, 3 * P3))
        simple = Fraction(4 * P3 * P2 * P1 - 9 * P3 * P3 * P0 - P2**3, P3 * curvature)
        return _round_exact(simple)

    def at_most(bits: int) -> bool:
        n, d = bits_float(bits).as_integer_ratio()
        return _exact_at_most(P, kind, n, d)

    if not at_most(MAX_BITS):
        return math.inf
    lo, hi = 0, MAX_BITS
    if math.isfinite(estimate) and estimate > 0:
        # Gallop out from the estimate until the root is bracketed.
        start = min(float_bits(estimate), MAX_BITS)
        step = 1
        if at_most(start):
            hi = start
            while hi - step > 0 and at_most(hi - step):
                hi, step = hi - step, step * 2
            lo = max(hi - step, 0)
        else:
            lo = start
            while lo + step < MAX_BITS and not at_most(lo + step):
                lo, step = lo + step, step * 2
            hi = min(lo + step, MAX_BITS)
    while hi - lo > 1:
        middle = (lo + hi) // 2
        if at_most(middle):
            hi = middle
        else:
            lo = middle
    # The root lies in (below, above]: round to the nearer, ties to even.
    below, above = Fraction(bits_float(lo)), Fraction(bits_float(hi))
    halfway = (below + above) / 2
    if not _exact_at_most(P, kind, halfway.numerator, halfway.denominator):
        return bits_float(hi)
    n, d = halfway.numerator, halfway.denominator
    if ((P3 * n + P2 * d) * n + P1 * d * d) * n + P0 * d * d * d == 0:
        return bits_float(hi if hi % 2 == 0 else lo)
    return bits_float(lo)


# -- the solver ------------------------------------------------------------------------

#: Names of the paths of :func:`min_positive_root_paths`, by code.
PATHS = ("no coefficients", "fast", "decided infinite", "proven estimate", "bisection", "exact")
_PATH_TRIVIAL, _PATH_FAST, _PATH_DECIDED, _PATH_ESTIMATE, _PATH_BISECTION, _PATH_EXACT = range(6)


def _fast(
    a: FloatArray, b: FloatArray, c: FloatArray
) -> tuple[FloatArray, NDArray[np.bool_], FloatArray]:
    """(roots, proven, estimates): the fast path, for finite coefficients.

    Where not proven, the root is unknown; the estimate is the fast path's
    unproven root (NaN if it found none), a start for the exact search.
    """
    # One power of two per element, applied per degree: w = 2^t v.
    t = _scale_exponent(a, b, c)
    A, B, C = np.ldexp(a, t), np.ldexp(b, 2 * t), np.ldexp(c, 3 * t)
    safe = (
        ((a == 0) | (np.abs(A) >= _SAFE_SCALED))
        & ((b == 0) | (np.abs(B) >= _SAFE_SCALED))
        & ((c == 0) | (np.abs(C) >= _SAFE_SCALED))
    )
    roots = np.full(a.shape, np.nan)
    is_proven = np.zeros(a.shape, dtype=bool)
    # Linear (Lensfun's poly3): one division rounds -1/a correctly. A result of
    # exactly the largest double may stand for a root just beyond it: not proven.
    linear = (b == 0) & (c == 0)
    if linear.any():
        w = np.where(a < 0, -1 / a, np.inf)
        done = linear & ((w < _MAX) | (a >= 0))
        roots[done] = w[done]
        is_proven[done] = True
        safe &= ~done
    if safe.all():  # the usual case: no gathering needed
        fast = np.arange(a.size)
    else:
        fast = np.flatnonzero(safe)
        A, B, C, t = A[fast], B[fast], C[fast], t[fast]
    x = _min_root_scaled(A, B, C)
    claimed = np.flatnonzero(x > 0)
    w, proven = _certified_fast(x[claimed], A[claimed], B[claimed], C[claimed], t[claimed])
    roots[fast[claimed]] = w
    is_proven[fast[claimed[proven]]] = True
    none = np.flatnonzero(x == 0)
    infinite = none[_certainly_infinite_scaled(A[none], B[none], C[none])]
    roots[fast[infinite]] = np.inf
    is_proven[fast[infinite]] = True
    return roots, is_proven, np.where(is_proven, np.nan, roots)


def _certainly_infinite_scaled(A: FloatArray, B: FloatArray, C: FloatArray) -> NDArray[np.bool_]:
    """True where 1 + A v + B v^2 + C v^3 certainly has no sign change on (0, inf).

    The decision of :func:`_classify`, for scaled coefficients of the fast
    path: at least 2^-250 where not zero, so that no product of up to four of
    them underflows and the discriminant can be taken directly.
    """
    # No negative coefficient: no positive root at all (Descartes).
    infinite = (A >= 0) & (B >= 0) & (C >= 0)
    two = (C > 0) & ((A < 0) | (B < 0))
    pair = (C == 0) & (B > 0) & (A < 0)
    ask = np.flatnonzero(two)
    if ask.size:
        As, Bs, Cs = A[ask], B[ask], C[ask]
        AB, AAC, BB = As * Bs, As * As * Cs, Bs * Bs
        # The discriminant's terms 18ABC, -4B^3, A^2B^2, -4A^3C, -27C^2.
        terms = (18 * AB * Cs, -4 * BB * Bs, AB * AB, -4 * AAC * As, -27 * Cs * Cs)
        total = terms[0] + terms[1] + terms[2] + terms[3] + terms[4]
        size = np.abs(terms[0]) + np.abs(terms[1]) + terms[2] + np.abs(terms[3]) - terms[4]
        # Zero or negative: one real root (negative, as c > 0) or a repeated one.
        infinite[ask] = total < -8 * _EPS * size
    ask = np.flatnonzero(pair)
    if ask.size:
        As, Bs = A[ask], B[ask]
        infinite[ask] = As * As - 4 * Bs < -3 * _EPS * (As * As + 4 * Bs)
    return infinite


def _robust(
    a: FloatArray, b: FloatArray, c: FloatArray, estimates: FloatArray
) -> tuple[FloatArray, NDArray[np.int8]]:
    """(roots, path codes) by exact decision, bisection and exact arithmetic."""
    result = np.full(a.shape, np.inf)
    path = np.full(a.shape, _PATH_DECIDED, dtype=np.int8)
    ma, ea = np.frexp(a)
    mb, eb = np.frexp(b)
    mc, ec = np.frexp(c)
    frexps = (ma, ea, mb, eb, mc, ec)
    kind = np.empty(a.shape, dtype=np.int8)
    for start in range(0, a.size, _CHUNK):
        part = slice(start, start + _CHUNK)
        kind[part] = _classify(a[part], b[part], c[part], tuple(v[part] for v in frexps))
    search = np.flatnonzero(kind > _INFINITE)
    exact = [np.flatnonzero(kind == _UNDECIDED)]
    outcome = np.empty(search.size, dtype=np.int8)
    for start in range(0, search.size, _CHUNK):
        part = search[start : start + _CHUNK]
        result[part], outcome[start : start + _CHUNK] = _search(
            a[part], b[part], c[part], kind[part], tuple(v[part] for v in frexps)
        )
    path[search] = np.array(
        [_PATH_DECIDED, _PATH_ESTIMATE, _PATH_BISECTION, _PATH_EXACT], dtype=np.int8
    )[outcome]
    exact.append(search[outcome == _SEARCH_UNSURE])
    # Few are left to bisect: all at once, not per chunk.
    bisect = search[outcome == _SEARCH_BISECT]
    for start in range(0, bisect.size, _CHUNK):
        part = bisect[start : start + _CHUNK]
        roots, found = _bisect(kind[part], tuple(v[part] for v in frexps))
        result[part] = roots
        exact.append(part[~found])
        # Where bisection stopped, its bracket is the better start.
        estimates[part[~found]] = roots[~found]
    exact = np.concatenate(exact)
    for i in exact:
        path[i] = _PATH_EXACT
        result[i] = _exact_min_positive_root(float(a[i]), float(b[i]), float(c[i]), estimates[i])
    return result, path


def min_positive_root_paths(
    a: ArrayLike, b: ArrayLike, c: ArrayLike
) -> tuple[FloatArray, NDArray[np.int8]]:
    """:func:`min_positive_root` over flat arrays, with the path each element took.

    Path codes index :data:`PATHS`: 0 all coefficients zero or not finite,
    1 the certified fast path, 2 decided to have no sign change, 3 an
    estimate proven by the exact test, 4 bisection with floating-point
    signs, 5 exact integer arithmetic. For benchmarks and tests of the solver
    itself.
    """
    a, b, c = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (a, b, c)))
    a, b, c = (np.ravel(v) for v in (a, b, c))
    result = np.empty(a.shape)
    path = np.empty(a.shape, dtype=np.int8)
    with np.errstate(all="ignore"):
        finite = np.isfinite(a) & np.isfinite(b) & np.isfinite(c)
        all_finite = bool(finite.all())
        if not all_finite:
            a, b, c = (np.where(finite, v, 0.0) for v in (a, b, c))
        rest, estimates = [], []
        # Slices, not gathered indices: views, no copies. All-zero coefficients
        # go through the fast path too and come out infinite.
        for start in range(0, a.size, _CHUNK):
            chunk = slice(start, start + _CHUNK)
            roots, proven, estimate = _fast(a[chunk], b[chunk], c[chunk])
            result[chunk] = roots
            path[chunk] = np.where(proven, _PATH_FAST, _PATH_DECIDED)
            unproven = np.flatnonzero(~proven)
            if unproven.size:
                rest.append(unproven + start)
                estimates.append(estimate[unproven])
        if rest:
            rest = np.concatenate(rest)
            result[rest], path[rest] = _robust(a[rest], b[rest], c[rest], np.concatenate(estimates))
        path[(a == 0) & (b == 0) & (c == 0)] = _PATH_TRIVIAL
        if not all_finite:
            result[~finite] = np.nan
            path[~finite] = _PATH_TRIVIAL
    return result, path


def min_positive_root(a: ArrayLike, b: ArrayLike, c: ArrayLike) -> float | FloatArray:
    """Smallest w > 0 at which p(w) = 1 + a w + b w^2 + c w^3 changes sign.

    Arguments broadcast together; a float comes back for scalar input, an
    array otherwise. Since p(0) = 1, this is the first w at which p goes
    negative: a root of odd multiplicity. A double (tangent) root, where p
    touches zero and turns back up, is not one. ``inf`` where p stays
    non-negative on (0, inf), or first changes sign beyond the largest
    double; NaN where a coefficient is NaN or infinite. Exact decision and a
    relative error under 2^-43 for every finite input (see the module
    docstring). Never emits numpy warnings for any input.
    """
    scalar = np.ndim(a) == 0 and np.ndim(b) == 0 and np.ndim(c) == 0
    shape = np.broadcast_shapes(np.shape(a), np.shape(b), np.shape(c))
    result = min_positive_root_paths(a, b, c)[0]
    if scalar:
        return float(result[0])
    return result.reshape(shape)


def min_positive_root_paper(a: float, b: float, c: float) -> float:
    """The paper's Algorithm 1 (MinPosRoot), as printed, in plain floating point.

    Kept as the reference the robust :func:`min_positive_root` is measured
    against. Note that it tests "positive root", not "sign change", and has
    no guard for the rounding issues discussed in the module docstring.
    Its arithmetic is IEEE's, as in :func:`min_positive_root_paper_vectorized`:
    a division by zero or an overflow gives inf or NaN, not an exception.
    """
    a, b, c = np.float64(a), np.float64(b), np.float64(c)
    with np.errstate(all="ignore"):
        return float(_paper_algorithm(a, b, c))


def _paper_algorithm(a: np.float64, b: np.float64, c: np.float64) -> float:
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
