"""The solver's private kernel: the metrics of one entry at a time in plain
Python, where the solver's fast path proves them.

:func:`lensaudit.metrics.compute` works on numpy arrays; importing numpy
takes a fresh ``lensaudit scan`` about as long as parsing the database.
The kernel shares the array code's constants (:mod:`lensaudit.solver.constants`).
:func:`entry_metrics` gives the same metrics for one audited entry without
numpy, operation for operation as the array code computes them (the same
IEEE operations on the same values, in the same order), so that its results
are the array code's bit for bit. It covers the common case only: the
certified fast path of :mod:`lensaudit.solver` (step 1 of its docstring),
with the certificate checked as there. Wherever the array code would take
another path (an uncertain sign, a root to polish, coefficients near the
ends of the binary64 range, an overflow on the way), it answers None, and
the caller computes that entry with :func:`lensaudit.metrics.compute`.

tests/test_scalar.py holds it to the array code bit for bit: on every entry
of the bundled database and of file versions across the Lensfun history (it
answers every one of them), and on coefficients drawn from the whole
binary64 range.
"""

from __future__ import annotations

import math
import struct

from ..columns import METRIC_COLUMNS
from .constants import ABSENT as _ABSENT
from .constants import EPS as _EPS
from .constants import HALF_DIAGONAL_MM
from .constants import HALF_WIDTH as _HALF_WIDTH
from .constants import MAX as _MAX
from .constants import PLAIN_NEWTON_STEPS as _PLAIN_NEWTON_STEPS
from .constants import ROOTS_IN_RANGE as _ROOTS_IN_RANGE
from .constants import SAFE_SCALED as _SAFE_SCALED
from .constants import SMALLEST_NORMAL as _SMALLEST_NORMAL
from .constants import SPLITTER as _SPLITTER
from .constants import WELL_CONDITIONED as _WELL_CONDITIONED

_TINY_ROOT = 2.0**-300
_INF = math.inf
_NAN = math.nan

#: Metrics of one entry, in the order of :data:`lensaudit.columns.METRIC_COLUMNS`:
#: r_max, d_max, tail, r_corner, r_normalized, r_corner_paper,
#: r_normalized_paper, folds_in_image (0 or 1).
EntryMetrics = tuple[float, float, int, float, float, float, float, int]

_isfinite = math.isfinite
_sqrt = math.sqrt
_frexp = math.frexp
_copysign = math.copysign


def ldexp(x: float, exponent: int) -> float:
    """x * 2^exponent as numpy.ldexp gives it: infinite on overflow rather than
    math.ldexp's error."""
    try:
        return math.ldexp(x, exponent)
    except OverflowError:
        return math.copysign(_INF, x)


def _divide(x: float, y: float) -> float:
    """x / y as numpy divides: +-inf or NaN for a zero divisor, never an error."""
    if y:
        return x / y
    if x != x or x == 0:
        return _NAN
    return _INF if (x > 0) == (math.copysign(1.0, y) > 0) else -_INF


def _fmin(x: float, y: float) -> float:
    """numpy.fmin of two floats that are not both zero: the smaller, ignoring NaN."""
    if x != x:
        return y
    if y != y:
        return x
    return x if x < y else y


def _q_compensated(x: float, A: float, B: float, C: float) -> float:
    """solver._q_compensated for one x: q(x) as accurate as in twice the precision."""
    s = x + A
    z = s - x
    error = (x - (s - z)) + (A - z)
    for coefficient in (B, C):
        product = s * x
        t = _SPLITTER * s
        sh = t - (t - s)
        sl = s - sh
        t = _SPLITTER * x
        xh = t - (t - x)
        xl = x - xh
        product_error = sl * xl - (((product - sh * xh) - sl * xh) - sh * xl)
        s = product + coefficient
        z = s - product
        sum_error = (product - (s - z)) + (coefficient - z)
        error = error * x + (product_error + sum_error)
    return s + error


def _q_sign(x: float, A: float, B: float, C: float) -> int:
    """solver._q_sign for one x: +1, -1, or 0 where even compensated arithmetic cannot tell."""
    ax = abs(x)
    magnitude = ((ax + abs(A)) * ax + abs(B)) * ax + abs(C)
    value = ((x + A) * x + B) * x + C
    bound = 7 * _EPS * magnitude
    if value > bound:
        return 1
    if value < -bound:
        return -1
    value = _q_compensated(x, A, B, C)
    bound = 40 * _EPS**2 * magnitude
    return 1 if value > bound else -1 if value < -bound else 0


def _sqrt_or_nan(x: float) -> float:
    """numpy.sqrt: NaN below zero rather than an error."""
    return _NAN if x < 0 else _sqrt(x)


def _cube_root_above(y: float) -> float:
    """solver._cube_root_above of one finite y >= 0."""
    if not y > 0:
        return y
    z = ldexp(1.0, -((-_frexp(y)[1]) // 3))
    for _ in range(2):
        z = (2 * z + y / (z * z)) / 3
    return z


def _root_guess(m: float, s: float) -> float:
    """solver._positive_root_guess for one element (m <= 0, s >= 0)."""
    return _fmin(_sqrt_or_nan(_divide(-m, s)), _cube_root_above(-m))


def _scale_exponent(a: float, b: float, c: float) -> int:
    """solver._scale_exponent of one cubic."""
    largest = _ABSENT
    if a != 0:
        largest = _frexp(a)[1]
    if b != 0:
        exponent = _frexp(_sqrt(abs(b)))[1]
        largest = exponent if exponent > largest else largest
    if c != 0:
        exponent = -((-_frexp(c)[1]) // 3)
        largest = exponent if exponent > largest else largest
    return 0 if largest == _ABSENT else -largest


def _min_root_scaled(A: float, B: float, C: float) -> float | None:
    """solver._min_root_scaled for one cubic; None where the array code would polish
    the root or decide a sign by compensated or exact arithmetic."""
    critical_disc = A * A - 3 * B
    has_critical = critical_disc > 0
    root_disc = _sqrt(critical_disc) if has_critical else 0.0
    big = -(A + _copysign(root_disc, A))
    first = big / 3
    second = B / (big if big != 0 else 1.0)
    # np.minimum and np.maximum of two finite floats; equal values are the same float
    # here unless they are zeros of two signs, which the caller cannot tell apart.
    x_max = first if first < second else second
    x_min = second if first < second else first
    q_at_min = ((x_min + A) * x_min + B) * x_min + C
    if has_critical and not (x_min == 0 and C == 0):
        ax = abs(x_min)
        magnitude = ((ax + abs(A)) * ax + abs(B)) * ax + abs(C)
        if abs(q_at_min) <= 4 * _EPS * magnitude:
            return None  # decided by compensated or exact arithmetic there
    right = has_critical and q_at_min < 0
    left = has_critical and not right
    if right:
        positive = x_min >= 0 or C < 0
    elif left:
        positive = x_max > 0 and C < 0
    else:
        positive = C < 0
    if not positive:
        return 0.0
    if right:
        guess = x_min + _root_guess(q_at_min if q_at_min < 0.0 else 0.0, root_disc)
    elif left:
        q_at_max = ((x_max + A) * x_max + B) * x_max + C
        guess = x_max - _root_guess(-(q_at_max if q_at_max > 0.0 else 0.0), root_disc)
    else:
        inflection = -A / 3
        q_at_inflection = ((inflection + A) * inflection + B) * inflection + C
        slope_at_inflection = B - A * A / 3
        if not slope_at_inflection > 0.0:
            slope_at_inflection = 0.0 if slope_at_inflection == slope_at_inflection else _NAN
        size = abs(q_at_inflection)
        towards = _fmin(_divide(size, slope_at_inflection), _cube_root_above(size))
        guess = inflection - _copysign(towards, q_at_inflection)
    if not guess >= 0.0:  # np.maximum(guess, 0.0), NaN kept
        guess = 0.0 if guess == guess else _NAN
    lower = (x_min if x_min > 0.0 else 0.0) if right else 0.0
    if left:
        upper = x_max
    else:
        upper = 1.0 + max(abs(A), abs(B), abs(C))
    if not (_isfinite(guess) and lower <= guess <= upper):
        guess = (lower + upper) / 2
    x = guess
    step = 0.0
    for _ in range(_PLAIN_NEWTON_STEPS):
        slope = (3 * x + 2 * A) * x + B
        value = ((x + A) * x + B) * x + C
        step = value / slope if slope else _divide(value, slope)
        if step - step == 0:  # finite
            x = x - step
    ax = abs(x)
    slope = abs((3 * x + 2 * A) * x + B) * ax
    magnitude = ((ax + abs(A)) * ax + abs(B)) * ax + abs(C)
    if abs(step) <= 1e-8 * ax and magnitude <= _WELL_CONDITIONED * slope:
        return x
    return None  # polished by the array code


def _certainly_infinite_scaled(A: float, B: float, C: float) -> bool:
    """solver._certainly_infinite_scaled for one cubic."""
    if C > 0 and (A < 0 or B < 0):
        AB, AAC, BB = A * B, A * A * C, B * B
        t0, t1, t2, t3, t4 = 18 * AB * C, -4 * BB * B, AB * AB, -4 * AAC * A, -27 * C * C
        total = t0 + t1 + t2 + t3 + t4
        size = abs(t0) + abs(t1) + t2 + abs(t3) - t4
        return total < -8 * _EPS * size
    if C == 0 and B > 0 and A < 0:
        return A * A - 4 * B < -3 * _EPS * (A * A + 4 * B)
    return A >= 0 and B >= 0 and C >= 0


def min_positive_root(a: float, b: float, c: float) -> float | None:
    """:func:`lensaudit.solver.min_positive_root` of finite a, b, c where its fast
    path proves the root (the same float); None where another path decides it."""
    if a >= 0 and b >= 0 and c >= 0:
        # p(w) >= 1 for w > 0: the array code finds no sign change either (its
        # fast path, or its exact decision where the fast path is not safe).
        return _INF
    if b == 0 and c == 0:  # linear: one division rounds -1/a correctly
        w = -1 / a if a < 0 else _INF
        if w < _MAX or a >= 0:
            return w
    t = _scale_exponent(a, b, c)
    # At most 1 in size: no overflow (math.ldexp's error); underflow rounds as numpy's.
    A, B, C = math.ldexp(a, t), math.ldexp(b, 2 * t), math.ldexp(c, 3 * t)
    if (
        (a != 0 and not abs(A) >= _SAFE_SCALED)
        or (b != 0 and not abs(B) >= _SAFE_SCALED)
        or (c != 0 and not abs(C) >= _SAFE_SCALED)
    ):
        return None
    # The array code asks this only where it found no root; but where it holds,
    # p has no sign change at all, which no path of the array code contradicts
    # (its certificate proves a sign change, its exact decision agrees): inf.
    if _certainly_infinite_scaled(A, B, C):
        return _INF
    x = _min_root_scaled(A, B, C)
    if x is None or x == 0:
        return None
    if not x > 0:
        return None
    return _certified(x, A, B, C, t)


def _certified(x: float, A: float, B: float, C: float, t: int) -> float | None:
    """solver._certified_fast for one root x > 0: w = 2^t / x where proven, else None."""
    if not x >= _TINY_ROOT:
        return None
    lo = x * (1 - _HALF_WIDTH)
    hi = x * (1 + _HALF_WIDTH)
    ahi = abs(hi)
    slope = (3 * hi + 2 * A) * hi + B
    slope_size = (3 * ahi + 2 * abs(A)) * ahi + abs(B)
    if not slope > 5 * _EPS * slope_size:
        return None
    convex = 3 * hi + A > 3 * _EPS * (3 * ahi + abs(A))
    no_critical = A * A - 3 * B < -3 * _EPS * (A * A + 3 * abs(B))
    if not (convex or no_critical):
        return None
    if not (ldexp(1 / hi, t) >= 2 * _SMALLEST_NORMAL and ldexp(1 / lo, t) <= _MAX * (1 - 8 * _EPS)):
        return None
    if _q_sign(hi, A, B, C) > 0 and _q_sign(lo, A, B, C) < 0:
        return ldexp(1 / x, t)
    return None


def _cubic(model: str, a: float, b: float, c: float, k1: float, k2: float) -> tuple:
    """normalizer.ptlens, poly3 or poly5 of one entry: (a, b, c, power, slope at
    the centre, coefficients of D(r) highest power first, and whether the cubic
    lost digits: metrics.subnormal_cubic)."""
    if model == "ptlens":
        # normalizer.ptlens_constant: 1 - a - b - c with error-free sums.
        total = 1.0 - a
        z = total - 1.0
        error = (1.0 - (total - z)) + (-a - z)
        partial = total
        total = partial - b
        z = total - partial
        e2 = (partial - (total - z)) + (-b - z)
        partial = total
        total = partial - c
        z = total - partial
        e3 = (partial - (total - z)) + (-c - z)
        d = total + (error + e2 + e3)
        x1, x2, x3 = _divide(2 * c, d), _divide(3 * b, d), _divide(4 * a, d)
        # A term of D that is not 0 whose coefficient in the cubic is subnormal or
        # 0, or a subnormal D'(0) (a cubic coefficient is 0 where its term is).
        lost = (
            -_SMALLEST_NORMAL < d < _SMALLEST_NORMAL
            or (c != 0 and abs(x1) < _SMALLEST_NORMAL)
            or (b != 0 and abs(x2) < _SMALLEST_NORMAL)
            or (a != 0 and abs(x3) < _SMALLEST_NORMAL)
        )
        return x1, x2, x3, 1, d, (a, b, c, d, 0.0), lost
    if model == "poly3":
        d = 1.0 - k1
        x1 = _divide(3 * k1, d)
        lost = k1 != 0 and abs(x1) < _SMALLEST_NORMAL
        return x1, 0.0, 0.0, 2, d, (k1, 0.0, d, 0.0), lost
    x1, x2 = 3 * k1, 5 * k2
    lost = (k1 != 0 and abs(x1) < _SMALLEST_NORMAL) or (k2 != 0 and abs(x2) < _SMALLEST_NORMAL)
    return x1, x2, 0.0, 2, 1.0, (k2, 0.0, k1, 0.0, 1.0, 0.0), lost


def _roots_in_range(a: float, b: float, c: float) -> bool:
    """metrics.roots_in_range of one cubic with a negative coefficient (the same operations)."""
    if c != 0:
        bound = max(abs(_divide(1.0, c)), abs(a / c), abs(b / c))
    elif b != 0:
        bound = max(abs(_divide(1.0, b)), abs(a / b))
    else:
        bound = abs(_divide(1.0, a))
    return 1 + bound <= _ROOTS_IN_RANGE


def is_circular_fisheye(lens: str, lens_type: str) -> bool:
    """Whether the database says the lens draws an image circle inside the frame.

    Lensfun has no element for it; it says so in the lens name ("Sigma 8mm
    f/3.5 EX DG Circular", "... circular fisheye") of a non-rectilinear lens.
    """
    return lens_type != "rectilinear" and "circular" in lens.lower()


def image_corner(aspect_ratio: float) -> float:
    """metrics.image_corner of one aspect ratio: hypot(aspect, 1), portrait taken as landscape."""
    inverse = _divide(1.0, aspect_ratio)
    return math.hypot(aspect_ratio if aspect_ratio >= inverse else inverse, 1.0)


def entry_metrics(
    model: str,
    a: float,
    b: float,
    c: float,
    k1: float,
    k2: float,
    crop_factor: float,
    aspect_ratio: float,
    focal: float,
    circular: bool,
) -> EntryMetrics | None:
    """:func:`lensaudit.metrics.compute` of one audited entry (the same floats), or
    None where the array code decides it by another path than the fast one."""
    cubic_a, cubic_b, cubic_c, power, slope, distortion, lost = _cubic(model, a, b, c, k1, k2)
    if slope > 0:
        if not (_isfinite(cubic_a) and _isfinite(cubic_b) and _isfinite(cubic_c)):
            return None  # overflowed: the exact path
        if lost:
            return None  # digits lost in the cubic: the exact path (metrics.subnormal_cubic)
        w = min_positive_root(cubic_a, cubic_b, cubic_c)
        if w is None:
            return None
        if (
            w == _INF
            and power == 2
            and not (cubic_a >= 0 and cubic_b >= 0 and cubic_c >= 0)
            and not _roots_in_range(cubic_a, cubic_b, cubic_c)
        ):
            return None  # perhaps a root beyond 1.8e308: the exact path
        r_max = _sqrt(w) if power == 2 else w
    elif slope == slope:
        r_max = 0.0
    else:
        return None
    if r_max == _INF:
        d_max, tail = r_max, 0
    else:
        d_max = 0.0
        for coefficient in distortion:
            d_max = d_max * r_max + coefficient
        if not _isfinite(d_max):
            return None  # overflowed: the exact path
        tail = 0
        for coefficient in distortion:
            if coefficient != 0:
                tail = 1 if coefficient > 0 else -1
                break
    if circular:
        r_corner = 1.0
    else:
        r_corner = _CORNERS.get(aspect_ratio)
        if r_corner is None:
            r_corner = image_corner(aspect_ratio)
            # A database has a handful of ratios; 0.0 and -0.0 (one key, two
            # corners) are not kept.
            if aspect_ratio and len(_CORNERS) < 64:
                _CORNERS[aspect_ratio] = r_corner
    size = crop_factor * focal
    r_corner_paper = HALF_DIAGONAL_MM / size if size else _divide(HALF_DIAGONAL_MM, size)
    r_normalized = d_max / r_corner if r_corner else _divide(d_max, r_corner)
    folds = 1 if r_max != _INF and r_normalized < 1 else 0
    return (
        r_max,
        d_max,
        tail,
        r_corner,
        r_normalized,
        r_corner_paper,
        d_max / r_corner_paper if r_corner_paper else _divide(d_max, r_corner_paper),
        folds,
    )


#: image_corner of the aspect ratios met so far.
_CORNERS: dict[float, float] = {}


#: The metrics of an entry that is not audited.
NOT_AUDITED: EntryMetrics = (_NAN, _NAN, 0, _NAN, _NAN, _NAN, _NAN, 0)
_INPUTS = ("model", "a", "b", "c", "k1", "k2", "crop_factor", "aspect_ratio", "focal")
#: The float inputs of an entry as bytes: its key in a memo (0.0 and -0.0 apart).
_PACK_INPUTS = struct.Struct("<8d").pack
#: A memo of :func:`column_metrics` is emptied when it holds more entries than this.
MEMO_ENTRIES = 1 << 18


def column_metrics(
    columns: dict[str, list], audited: str, memo: dict[tuple, EntryMetrics] | None = None
) -> dict[str, list] | None:
    """The metrics of entries given as columns (as :func:`lensaudit.pipeline.row_columns`
    gives them), as lists by metric column (``tail`` -1/0/1, ``folds_in_image`` 0/1);
    only entries whose ``status`` is ``audited`` are computed. None if any of
    them is left to the array code.

    With ``memo``, an entry whose inputs are bit for bit those of one in the
    memo takes its metrics from it (:func:`entry_metrics` is a function of
    the bits of its inputs); those computed are added, the memo emptied past
    :data:`MEMO_ENTRIES`."""
    found = []
    append = found.append
    pack = _PACK_INPUTS
    if memo is not None and len(memo) > MEMO_ENTRIES:
        memo.clear()
    for status, lens, lens_type, model, *inputs in zip(
        columns["status"],
        columns["lens"],
        columns["type"],
        *map(columns.get, _INPUTS),
        strict=True,
    ):
        if status != audited:
            append(NOT_AUDITED)
            continue
        circular = is_circular_fisheye(lens, lens_type)
        if memo is None:
            metrics = entry_metrics(model, *inputs, circular)
        else:
            key = (model, circular, pack(*inputs))
            metrics = memo.get(key)
            if metrics is None:
                metrics = memo[key] = entry_metrics(model, *inputs, circular)  # type: ignore[assignment]
        if metrics is None:
            return None
        append(metrics)
    if not found:
        return {name: [] for name in METRIC_COLUMNS}
    return dict(zip(METRIC_COLUMNS, map(list, zip(*found, strict=True)), strict=True))
