"""The first sign change on (0, inf) of p(w) = 1 + c1 w + c2 w^2 + ... + cn w^n, any degree.

:func:`first_sign_change` is the general form of
:func:`lensaudit.solver.min_positive_root` (the cubic, n = 3): a distortion
model describes its polynomial by its coefficients c1 ... cn, and this
solver finds the smallest w > 0 at which p changes sign, that is its smallest
positive root of odd multiplicity. A root of even multiplicity (p touches
zero and turns back) is not a fold. Degree four covers OpenCV's fisheye
model (Gyroflow's lens profiles, :func:`lensaudit.normalizer.opencv_fisheye`).

Every answer is proven before it is returned, on one of these paths:

1. Signs. With no negative coefficient, p >= 1 on (0, inf): no sign change
   (Descartes' rule of signs). Degree one: the root -1/c1, one correctly
   rounded division.
2. Fast path, over numpy arrays. Scale w = 2^-E v by a power of two per
   polynomial, so that every scaled coefficient C_k = c_k 2^(-kE) is at most
   1 and the largest at least 1/16 (exact: no coefficient may fall below
   2^-250, else this path is not taken). Every root of the scaled
   polynomial then lies in |v| >= 1/2. Approximate all n complex roots z_i
   (eigenvalues of the companion matrix of the reversed, monic polynomial)
   and enclose each in a disk |v - z_i| <= n |W_i|, W_i = p(z_i) /
   (C_n prod_{j != i} (z_i - z_j)) the Weierstrass correction, each
   quantity bounded with its rounding error. By Smith's theorem
   (B. T. Smith, 1970: Gershgorin's theorem applied to the polynomial's
   Weierstrass form) the disks hold every root, and a disk apart from all
   others holds exactly one. So where the disks are pairwise disjoint, the
   roots are simple; a disk centred on the real axis holds a real root (its
   conjugate lies in the same disk), and a disk that misses the real axis a
   non-real one. No disk on the positive axis proves that p never changes
   sign. Otherwise the first positive disk holds the wanted root: Newton's
   method with compensated (error-free) evaluation finds a double v, and
   the answer is accepted where p > 0 at v's lower neighbour and p < 0 at
   its upper neighbour, each sign beyond its rounding-error bound, and the
   upper neighbour lies before the next positive disk. The root then lies
   strictly between the neighbours of v, and w = 2^-E v exactly.
3. Exact, in Python integers and fractions on the binary64 inputs, for
   everything else (clustered and repeated roots, tangencies, coefficients
   too far apart in size, roots outside the normal range): Yun's
   square-free decomposition keeps the roots of odd multiplicity, Sturm's
   theorem counts them on (0, X] exactly, and bisection over the bit
   patterns of positive doubles brackets the first between two adjacent
   doubles; the result is correctly rounded (ties to even).

Accuracy: the decision finite or infinite is exact for every finite binary64
input; ``inf`` means no sign change up to the largest double. A finite
result is within one unit in the last place of the exact root: strictly
between the root's two neighbouring doubles on the fast path (relative
error below 2^-52) and correctly rounded on the other paths. A subnormal
root comes back finite and positive (exact path).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from fractions import Fraction

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .arrays import _two_product, _two_sum
from .constants import ABSENT, EPS, MAX, MAX_BITS, SMALLEST_NORMAL, bits_float, float_bits

FloatArray = NDArray[np.float64]

#: Names of the paths of :func:`first_sign_change_paths`, by code.
PATHS = ("constant", "signs", "fast", "exact")
_CONSTANT, _SIGNS, _FAST, _EXACT = range(4)

#: Nonzero scaled coefficients at least this large keep every intermediate of
#: the fast path, errors of error-free products included, far from underflow.
_SAFE_SCALED = 2.0**-250
#: Scaled roots beyond this are left to the exact path (their powers would near overflow).
_LARGEST_SCALED_ROOT = 2.0**200
#: Absolute allowance for an underflow inside a compensated evaluation.
_UNDERFLOW_SLOP = 2.0**-1000
_NEWTON_STEPS = 8
_CHUNK = 1 << 14  # polynomials per pass: keeps numpy's temporaries in cache


# -- the fast path ---------------------------------------------------------------------


def _scale(c: FloatArray) -> tuple[NDArray[np.int64], FloatArray, NDArray[np.bool_]]:
    """(E, C, safe): C_k = c_k 2^(-kE) with every |C_k| < 1 and the largest at least 2^-k.

    |c_k| < 2^e_k (numpy.frexp), so |c_k|^(1/k) < 2^ceil(e_k / k) <= 2^E. Safe
    where no nonzero C_k fell below :data:`_SAFE_SCALED` (then it is exact).
    """
    powers = np.arange(1, c.shape[1] + 1)
    exponents = np.frexp(c)[1].astype(np.int64)
    per_degree = np.where(c != 0, -((-exponents) // powers), ABSENT)
    E = per_degree.max(axis=1)
    scaled = np.ldexp(c, -powers * E[:, None])
    safe = np.all((c == 0) | (np.abs(scaled) >= _SAFE_SCALED), axis=1)
    return E, scaled, safe


def _approximate_roots(C: FloatArray) -> NDArray[np.complex128]:
    """All n roots of 1 + C_1 v + ... + C_n v^n (C_n != 0), approximately, as v = 1 / x.

    x runs over the eigenvalues of the companion matrix of the reversed
    polynomial x^n + C_1 x^(n-1) + ... + C_n, which is monic and exact.
    """
    m, n = C.shape
    companion = np.zeros((m, n, n))
    companion[:, 0, :] = -C
    below = np.arange(n - 1)
    companion[:, below + 1, below] = 1.0
    x = np.linalg.eigvals(companion).astype(np.complex128)
    return 1.0 / np.where(x != 0, x, np.nan)


def _evaluate_complex(C: FloatArray, z: NDArray[np.complex128]) -> tuple[FloatArray, FloatArray]:
    """(|p(z)| as computed, a bound on its rounding error), p = 1 + sum C_k z^k, per column of z."""
    n = C.shape[1]
    value = np.broadcast_to(C[:, n - 1 : n], z.shape).astype(np.complex128)
    size = np.abs(z)
    magnitude = np.broadcast_to(np.abs(C[:, n - 1 : n]), z.shape)
    for k in range(n - 2, -1, -1):
        value = value * z + C[:, k : k + 1]
        magnitude = magnitude * size + np.abs(C[:, k : k + 1])
    value = value * z + 1.0
    magnitude = magnitude * size + 1.0
    # Horner's rule in complex arithmetic errs by less than gamma_(4n+2) times
    # the magnitude; 10 n eps also covers the rounding of the magnitude itself.
    return np.abs(value), 10 * (n + 1) * EPS * magnitude


def _inclusion_radii(C: FloatArray, z: NDArray[np.complex128]) -> FloatArray:
    """Upper bounds of n |W_i|, the radii of Smith's disks around the z_i (inf if none).

    W_i = p(z_i) / (C_n prod_{j != i} (z_i - z_j)); every rounding is
    covered by a relative margin of 32 n eps on top of the evaluation's bound.
    """
    n = C.shape[1]
    value, error = _evaluate_complex(C, z)
    denominator = np.broadcast_to(np.abs(C[:, n - 1 : n]), z.shape).astype(np.float64)
    for shift in range(1, n):
        denominator = denominator * np.abs(z - np.roll(z, shift, axis=1))
    margin = 1 + 32 * n * EPS
    radii = n * (value + error) * margin / denominator * margin
    return np.where(np.isfinite(radii) & (denominator > 0), radii, np.inf)


def _disks(
    z: NDArray[np.complex128], radii: FloatArray
) -> tuple[NDArray[np.bool_], NDArray[np.bool_], FloatArray, FloatArray, FloatArray, FloatArray]:
    """(decided, none, start, low, high, next_start) from Smith's disks.

    Decided where the disks are pairwise disjoint, each either centred on the
    real axis or missing it, none reaching v = 0, all within
    :data:`_LARGEST_SCALED_ROOT`. ``none``: no root on (0, inf). Otherwise
    the first positive root lies in [low, high] around the centre ``start``,
    and no other positive root lies before ``next_start``.
    """
    n = z.shape[1]
    decided = np.all(np.isfinite(radii) & (np.abs(z) <= _LARGEST_SCALED_ROOT), axis=1)
    for shift in range(1, n):
        apart = np.abs(z - np.roll(z, shift, axis=1)) * (1 - 4 * EPS)
        decided &= np.all(apart > (radii + np.roll(radii, shift, axis=1)) * (1 + 2 * EPS), axis=1)
    real = z.imag == 0
    off_axis = np.abs(z.imag) * (1 - 2 * EPS) > radii
    low = (z.real - radii) * (1 - 2 * EPS)  # rounded towards zero: low > 0 stays true
    high = (z.real + radii) * (1 + 2 * EPS)
    positive = real & (low > 0)
    negative = real & (high < 0)
    decided &= np.all(off_axis | positive | negative, axis=1)
    starts = np.where(positive, z.real, np.inf)
    first = np.argmin(starts, axis=1)[:, None]
    none = ~positive.any(axis=1)
    after = np.where(positive, low, np.inf)
    np.put_along_axis(after, first, np.inf, axis=1)
    take = np.take_along_axis
    start, low, high = (take(v, first, axis=1)[:, 0] for v in (starts, low, high))
    return decided, none, start, low, high, after.min(axis=1)


def _horner_compensated(C: FloatArray, v: FloatArray) -> tuple[FloatArray, FloatArray]:
    """(p(v), a bound on its error) by compensated Horner, p = 1 + sum C_k v^k.

    The bound is Langlois and Louvet's eps |p| + gamma_2n^2 p~(|v|), doubled,
    plus an allowance for underflow in the error-free products.
    """
    n = C.shape[1]
    s = C[:, n - 1]
    error = np.zeros_like(v)
    magnitude = np.abs(s)
    size = np.abs(v)
    for k in range(n - 2, -2, -1):
        coefficient = C[:, k] if k >= 0 else np.ones_like(v)
        product, product_error = _two_product(s, v)
        s, sum_error = _two_sum(product, coefficient)
        error = error * v + (product_error + sum_error)
        magnitude = magnitude * size + np.abs(coefficient)
    value = s + error
    bound = 2 * EPS * np.abs(value) + 8 * (2 * n * EPS) ** 2 * magnitude + n * _UNDERFLOW_SLOP
    return value, bound


def _slope(C: FloatArray, v: FloatArray) -> FloatArray:
    """p'(v) in plain floating point: Newton's steps need no more."""
    n = C.shape[1]
    slope = n * C[:, n - 1]
    for k in range(n - 1, 0, -1):
        slope = slope * v + k * C[:, k - 1]
    return slope


def _newton(C: FloatArray, start: FloatArray, low: FloatArray, high: FloatArray) -> FloatArray:
    """The simple root in [low, high] by Newton's method from start, residuals compensated."""
    v = start
    for _ in range(_NEWTON_STEPS):
        value = _horner_compensated(C, v)[0]
        candidate = v - value / _slope(C, v)
        v = np.where(np.isfinite(candidate), np.clip(candidate, low, high), v)
    return v


def _fast(c: FloatArray) -> tuple[FloatArray, NDArray[np.bool_], FloatArray]:
    """(roots w, proven, estimates) for polynomials of degree n = c.shape[1] >= 2.

    Where not proven, the root is unknown, and the estimate (NaN if none) is
    a start for the exact search.
    """
    m = c.shape[0]
    roots = np.full(m, np.nan)
    proven = np.zeros(m, dtype=bool)
    E, C, safe = _scale(c)
    work = np.flatnonzero(safe)
    if work.size == 0:
        return roots, proven, roots.copy()
    C, E = C[work], E[work]
    z = _approximate_roots(C)
    decided, none, start, low, high, next_start = _disks(z, _inclusion_radii(C, z))
    infinite = decided & none
    roots[work[infinite]] = np.inf
    proven[work[infinite]] = True
    finite = np.flatnonzero(~none)
    v = _newton(C[finite], start[finite], low[finite], high[finite])
    below, above = np.nextafter(v, 0.0), np.nextafter(v, np.inf)
    value_below, bound_below = _horner_compensated(C[finite], below)
    value_above, bound_above = _horner_compensated(C[finite], above)
    shift = -E[finite]
    certain = (
        decided[finite]
        & (value_below > bound_below)
        & (value_above < -bound_above)
        & (above < next_start[finite])
        & (np.ldexp(below, shift) >= SMALLEST_NORMAL)
        & (np.ldexp(above, shift) <= MAX)
    )
    roots[work[finite]] = np.ldexp(v, shift)
    proven[work[finite]] = certain
    return roots, proven, np.where(proven, np.nan, roots)


def _linear(c: FloatArray) -> tuple[FloatArray, NDArray[np.bool_], FloatArray]:
    """(roots, proven, estimates) for 1 + c1 w with c1 < 0: -1/c1, correctly rounded.

    A result of exactly the largest double may stand for a root beyond it: not proven.
    """
    roots = -1.0 / c[:, 0]
    proven = roots != MAX
    return roots, proven, np.where(proven, np.nan, roots)


# -- the exact path ----------------------------------------------------------------------

_Poly = list[Fraction]  # coefficients, constant term first


def _trim(p: _Poly) -> _Poly:
    while p and p[-1] == 0:
        p = p[:-1]
    return p


def _derivative(p: _Poly) -> _Poly:
    return _trim([k * p[k] for k in range(1, len(p))])


def _divmod(n: _Poly, d: _Poly) -> tuple[_Poly, _Poly]:
    """Quotient and remainder of n by d (d nonzero)."""
    n = _trim(list(n))
    quotient = [Fraction(0)] * max(len(n) - len(d) + 1, 0)
    while len(n) >= len(d):
        factor = n[-1] / d[-1]
        shift = len(n) - len(d)
        quotient[shift] = factor
        n = _trim([x - factor * d[i - shift] if i >= shift else x for i, x in enumerate(n)])
    return quotient, n


def _gcd(p: _Poly, q: _Poly) -> _Poly:
    """Monic greatest common divisor."""
    while q:
        p, q = q, _divmod(p, q)[1]
    return [x / p[-1] for x in p]


def _odd_part(f: _Poly) -> _Poly:
    """The product of f's distinct irreducible factors of odd multiplicity (Yun's algorithm).

    f changes sign exactly at the roots of this square-free polynomial.
    """
    slope = _derivative(f)
    common = _gcd(f, slope)
    b = _divmod(f, common)[0]
    d = _trim([x - y for x, y in _padded(_divmod(slope, common)[0], _derivative(b))])
    odd: _Poly = [Fraction(1)]
    multiplicity = 1
    while len(b) > 1:
        factor = _gcd(b, d)
        if multiplicity % 2:
            odd = _multiply(odd, factor)
        b = _divmod(b, factor)[0]
        c = _divmod(d, factor)[0]
        d = _trim([x - y for x, y in _padded(c, _derivative(b))])
        multiplicity += 1
    return odd


def _padded(p: _Poly, q: _Poly) -> list[tuple[Fraction, Fraction]]:
    size = max(len(p), len(q))
    zero = Fraction(0)
    return [(p[i] if i < len(p) else zero, q[i] if i < len(q) else zero) for i in range(size)]


def _multiply(p: _Poly, q: _Poly) -> _Poly:
    product = [Fraction(0)] * (len(p) + len(q) - 1)
    for i, x in enumerate(p):
        for j, y in enumerate(q):
            product[i + j] += x * y
    return product


def _integers(p: _Poly) -> list[int]:
    """p times the positive least common multiple of its denominators: same signs everywhere."""
    scale = 1
    for x in p:
        scale = scale * x.denominator // math.gcd(scale, x.denominator)
    return [int(x * scale) for x in p]


def _sturm_sequence(p: _Poly) -> list[list[int]]:
    """Sturm's sequence of the square-free p, each member scaled to integers."""
    sequence = [p, _derivative(p)]
    while len(sequence[-1]) > 1:
        remainder = _divmod(sequence[-2], sequence[-1])[1]
        if not remainder:
            break
        sequence.append([-x for x in remainder])
    return [_integers(member) for member in sequence]


def _sign_at(p: list[int], n: int, d: int) -> int:
    """Sign of p(n / d), d > 0: of sum p_k n^k d^(deg - k)."""
    value = 0
    scale = 1
    for coefficient in reversed(p):
        value = value * n + coefficient * scale
        scale *= d
    return (value > 0) - (value < 0)


def _variations(signs: list[int]) -> int:
    nonzero = [s for s in signs if s]
    return sum(1 for x, y in zip(nonzero, nonzero[1:], strict=False) if x != y)


def _at_most_test(coefficients: tuple[float, ...]) -> tuple[Callable[[Fraction], bool], _Poly]:
    """(at_most, odd): at_most(X) tells, exactly, whether p changes sign on (0, X]."""
    f = _trim([Fraction(1)] + [Fraction(c) for c in coefficients])
    odd = _odd_part(f)
    sturm = _sturm_sequence(odd) if len(odd) > 1 else [_integers(odd)]
    at_zero = _variations([(member[0] > 0) - (member[0] < 0) for member in sturm])
    integer_odd = sturm[0]

    def at_most(x: Fraction) -> bool:
        n, d = x.numerator, x.denominator
        if _sign_at(integer_odd, n, d) == 0:
            return True
        return at_zero > _variations([_sign_at(member, n, d) for member in sturm])

    return at_most, odd


def exact_first_sign_change(coefficients: tuple[float, ...], estimate: float = math.nan) -> float:
    """:func:`first_sign_change` of one polynomial, in exact arithmetic alone.

    ``coefficients`` are finite floats c1 ... cn. The result is correctly
    rounded (ties to even), ``inf`` for no sign change up to the largest
    double. ``estimate`` only saves time: the search starts around it.
    """
    at_most_exact, odd = _at_most_test(coefficients)
    if len(odd) == 1:
        return math.inf

    def at_most(bits: int) -> bool:
        return at_most_exact(Fraction(bits_float(bits)))

    if not at_most(MAX_BITS):
        return math.inf
    lo, hi = _bracket(at_most, estimate)
    while hi - lo > 1:
        middle = (lo + hi) // 2
        if at_most(middle):
            hi = middle
        else:
            lo = middle
    # The root lies in (below, above]: round to the nearer, ties to even.
    halfway = (Fraction(bits_float(lo)) + Fraction(bits_float(hi))) / 2
    if not at_most_exact(halfway):
        return bits_float(hi)
    if _sign_at(_integers(odd), halfway.numerator, halfway.denominator) == 0:
        return bits_float(hi if hi % 2 == 0 else lo)
    return bits_float(lo)


def _bracket(at_most: Callable[[int], bool], estimate: float) -> tuple[int, int]:
    """Bit patterns lo < hi with not at_most(lo) and at_most(hi), galloping out from estimate."""
    if not (math.isfinite(estimate) and estimate > 0):
        return 0, MAX_BITS
    start = min(float_bits(estimate), MAX_BITS)
    step = 1
    if at_most(start):
        hi = start
        while hi - step > 0 and at_most(hi - step):
            hi, step = hi - step, step * 2
        return max(hi - step, 0), hi
    lo = start
    while lo + step < MAX_BITS and not at_most(lo + step):
        lo, step = lo + step, step * 2
    return lo, min(lo + step, MAX_BITS)


# -- the solver ----------------------------------------------------------------------------


def _degrees(c: FloatArray) -> NDArray[np.int64]:
    """Index of the highest nonzero coefficient plus one: the degree of p (0 if none)."""
    nonzero = c != 0
    if c.shape[1] == 0:
        return np.zeros(c.shape[0], dtype=np.int64)
    last = c.shape[1] - np.argmax(nonzero[:, ::-1], axis=1)
    return np.where(nonzero.any(axis=1), last, 0)


def _solve_degree(
    c: FloatArray, degree: int, rows: NDArray[np.intp], result: FloatArray, path: NDArray[np.int8]
) -> list[tuple[int, float]]:
    """Fills result and path for ``rows`` (all of this degree); returns what is left to
    the exact path, with estimates."""
    left: list[tuple[int, float]] = []
    for begin in range(0, rows.size, _CHUNK):
        part = rows[begin : begin + _CHUNK]
        solve = _linear if degree == 1 else _fast
        roots, proven, estimates = solve(c[part, :degree])
        result[part] = roots
        path[part] = np.where(proven, _FAST, _EXACT)
        left.extend(zip(part[~proven].tolist(), estimates[~proven].tolist(), strict=True))
    return left


def first_sign_change_paths(coefficients: ArrayLike) -> tuple[FloatArray, NDArray[np.int8]]:
    """:func:`first_sign_change` over flat rows, with the path each took.

    ``coefficients`` has shape (m, n); both results have shape (m,). Path
    codes index :data:`PATHS`: 0 all coefficients zero, or one not finite;
    1 decided by the coefficients' signs; 2 the certified fast path; 3 exact
    arithmetic. For benchmarks and tests of the solver itself.
    """
    c = np.array(coefficients, dtype=np.float64, ndmin=2)
    c = c.reshape(math.prod(c.shape[:-1]), c.shape[-1])
    result = np.full(c.shape[0], np.inf)
    path = np.full(c.shape[0], _CONSTANT, dtype=np.int8)
    with np.errstate(all="ignore"):
        finite = np.isfinite(c).all(axis=1)
        c = np.where(finite[:, None], c, 0.0)
        degree = _degrees(c)
        signs = (degree > 0) & (c >= 0).all(axis=1)
        path[signs] = _SIGNS
        left: list[tuple[int, float]] = []
        for d in range(1, c.shape[1] + 1):
            rows = np.flatnonzero((degree == d) & ~signs)
            left += _solve_degree(c, d, rows, result, path)
        for row, estimate in left:
            coefficients_row = tuple(c[row, : degree[row]].tolist())
            result[row] = exact_first_sign_change(coefficients_row, estimate)
        result[~finite] = np.nan
    return result, path


def first_sign_change(coefficients: ArrayLike) -> float | FloatArray:
    """Smallest w > 0 at which p(w) = 1 + c1 w + c2 w^2 + ... + cn w^n changes sign.

    Parameters
    ----------
    coefficients : array_like, shape (..., n)
        c1 ... cn along the last axis, lowest power first; any finite
        binary64 values, zeros included (the degree is that of the highest
        nonzero one). n = 4 for OpenCV's fisheye model, 3 for the cubic of
        :func:`lensaudit.solver.min_positive_root`.

    Returns
    -------
    float or ndarray, shape (...)
        The smallest positive root of odd multiplicity of p: where it first
        goes negative (p(0) = 1). A root of even multiplicity, where p
        touches zero and turns back up, is not one. ``inf`` where p stays
        non-negative on (0, inf) or first changes sign beyond the largest
        double (p constant included); NaN where a coefficient of the row is
        NaN or infinite. A float for one row of shape (n,).

    Notes
    -----
    The finite/infinite decision is exact, and a finite result lies
    strictly within one unit in the last place of the exact root of the
    binary64 inputs (correctly rounded where the exact path was taken);
    subnormal roots come back finite and positive. Never emits numpy
    warnings. See the module docstring for how each answer is proven.
    """
    c = np.asarray(coefficients, dtype=np.float64)
    if c.ndim == 0:
        raise ValueError("coefficients need a last axis: c1 ... cn")
    result = first_sign_change_paths(c)[0]
    if c.ndim == 1:
        return float(result[0])
    return result.reshape(c.shape[:-1])
