"""Per-entry fold-back metrics: r_max, d_max, tail, r_corner, r_normalized.

Units. Lensfun's ptlens, poly3 and poly5 models work in "Hugin units": r = 1
is half the SHORT side of the calibration image, for every focal length. The
undistorted r_max and the distorted d_max = D(r_max) are in those units, and
the corner of the calibration image is at r_corner = hypot(aspect, 1).

The paper compares d_max with hypot(18, 12) / (crop * focal), a radius in
focal-length units. That mixes units; it is kept, labelled ``*_paper``, only
to reproduce the paper's Figure 5.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import normalizer
from .solver import kernel
from .solver.arrays import min_positive_root
from .solver.constants import ROOTS_IN_RANGE, SMALLEST_NORMAL

# Exact arithmetic is imported where it is needed: few inputs ever take that path.
if TYPE_CHECKING:
    from fractions import Fraction

FloatArray = NDArray[np.float64]

#: Half diagonal of Lensfun's 36 x 24 mm reference sensor, in millimetres.
HALF_DIAGONAL_MM = kernel.HALF_DIAGONAL_MM

TAIL_POSITIVE = "positive"
TAIL_NEGATIVE = "negative"


@dataclass(frozen=True)
class Metrics:
    """Metric columns, one element per entry (NaN where not computed).

    ``tail`` is +1 (D -> +inf), -1 (D -> -inf) or 0 (r_max infinite or not
    computed). ``folds_in_image`` is False where r_max is infinite.
    """

    r_max: FloatArray
    d_max: FloatArray
    tail: NDArray[np.int8]
    r_corner: FloatArray
    r_normalized: FloatArray
    r_corner_paper: FloatArray
    r_normalized_paper: FloatArray
    folds_in_image: NDArray[np.bool_]


def cubic_r_max(cubic: normalizer.Cubic) -> FloatArray:
    """r_max of a normalized model: where D' first changes sign from + to -.

    0 where D'(0) <= 0 (the model decreases from the centre), ``inf`` where D
    is increasing on (0, inf) or first turns beyond the largest double, NaN
    for NaN coefficients and where the cubic overflows (coefficients beyond
    about 1e307). The float answer of a cubic whose coefficients are
    subnormal, or whose first turn is beyond w = 1.8e308, may be wrong:
    :func:`compute` decides those exactly, as it does overflows.
    """
    w = min_positive_root(cubic.a, cubic.b, cubic.c)
    w = np.asarray(w, dtype=np.float64)
    r_max = np.sqrt(w) if cubic.power == 2 else w
    slope = np.broadcast_to(cubic.slope_at_centre, r_max.shape)
    return np.where(slope > 0, r_max, np.where(np.isnan(slope), np.nan, 0.0))


def model_r_max(cubic: normalizer.Cubic) -> tuple[FloatArray, FloatArray, NDArray[np.int8]]:
    """(r_max, d_max, tail sign) for a normalized model."""
    with np.errstate(all="ignore"):
        r_max = cubic_r_max(cubic)
        finite = np.isfinite(r_max)
        d_max = np.where(
            finite, normalizer.evaluate(cubic.distortion, np.where(finite, r_max, 0)), r_max
        )
    tail = np.where(finite, normalizer.leading_sign(cubic.distortion), 0).astype(np.int8)
    return r_max, d_max, tail


def roots_in_range(a: FloatArray, b: FloatArray, c: FloatArray) -> NDArray[np.bool_]:
    """Where 1 + a w + b w^2 + c w^3 certainly changes sign at no w beyond the
    largest double: no coefficient is negative (no positive root at all), or
    Cauchy's bound on the roots, 1 + max |other coefficient / leading one|,
    stays below :data:`~lensaudit.solver.constants.ROOTS_IN_RANGE`. (Elsewhere
    a float answer of inf may be a root beyond the largest double.)"""
    with np.errstate(all="ignore"):
        cubic = np.maximum(np.maximum(abs(1 / c), abs(a / c)), abs(b / c))
        quadratic = np.maximum(abs(1 / b), abs(a / b))
        bound = 1 + np.where(c != 0, cubic, np.where(b != 0, quadratic, abs(1 / a)))
    return ((a >= 0) & (b >= 0) & (c >= 0)) | (bound <= ROOTS_IN_RANGE)


def needs_exact(cubic: normalizer.Cubic, r_max: ArrayLike, d_max: ArrayLike) -> NDArray[np.bool_]:
    """Where (r_max, d_max) of :func:`model_r_max` may be wrong, for
    :func:`exact_model_r_max` to decide: the cubic or D(r_max) overflowed
    (coefficients near 1e308), the cubic lost digits (:func:`subnormal_cubic`),
    or r_max is inf where, for w = r^2, the first turn may lie beyond w =
    1.8e308 (:func:`roots_in_range`)."""
    r_max, d_max = np.asarray(r_max, dtype=np.float64), np.asarray(d_max, dtype=np.float64)
    found = np.isnan(r_max) | (np.isfinite(r_max) & ~np.isfinite(d_max))
    if cubic.power == 2:
        found = found | (np.isinf(r_max) & ~roots_in_range(cubic.a, cubic.b, cubic.c))
    return found | subnormal_cubic(cubic)


def subnormal_cubic(cubic: normalizer.Cubic) -> NDArray[np.bool_]:
    """Where the cubic's float coefficients may have lost digits: D'(0) or a
    coefficient is subnormal, or a coefficient underflowed to 0 from a term of
    D that is not 0."""
    distortion = cubic.distortion
    degree = distortion.shape[-1] - 1
    found = _subnormal(cubic.slope_at_centre)
    for m, x in enumerate((cubic.a, cubic.b, cubic.c), start=1):
        power = cubic.power * m + 1  # the term of D whose derivative is w^m's
        given = distortion[..., degree - power] != 0 if power <= degree else False
        found = found | _subnormal(x) | ((x == 0) & given)
    return found


def _subnormal(x: ArrayLike) -> NDArray[np.bool_]:
    magnitude = np.abs(np.asarray(x, dtype=np.float64))
    return (magnitude > 0) & (magnitude < SMALLEST_NORMAL)


def exact_distortion(
    model: str, a: float, b: float, c: float, k1: float, k2: float
) -> list[Fraction]:
    """Coefficients of a Lensfun model's D(r) as written, highest power first, exactly.

    ``model`` is "ptlens" (a, b, c used), "poly3" (k1) or "poly5" (k1, k2).
    """
    from fractions import Fraction  # fractions: only for the exact fallback, rarely reached

    if model == "ptlens":
        a_, b_, c_ = Fraction(a), Fraction(b), Fraction(c)
        return [a_, b_, c_, 1 - a_ - b_ - c_, Fraction(0)]
    if model == "poly3":
        return [Fraction(k1), Fraction(0), 1 - Fraction(k1), Fraction(0)]
    return [Fraction(k2), Fraction(0), Fraction(k1), Fraction(0), Fraction(1), Fraction(0)]


def _nearest_double(x: Fraction) -> float:
    """x rounded to binary64; +-inf beyond the largest double."""
    try:
        return float(x)
    except OverflowError:  # not copysign(inf, x): that converts x to a float again
        return math.inf if x > 0 else -math.inf


def exact_model_r_max(distortion: list[Fraction], power: int) -> tuple[float, float, int]:
    """(r_max, d_max, tail sign) of one model from its exact coefficients.

    ``distortion`` holds D(r)'s coefficients, highest power first, as in
    :attr:`normalizer.Cubic.distortion`; w = r**power in the cubic.

    For models whose cubic overflows binary64 (coefficients near 1e308) or
    loses digits in it (subnormal coefficients), or whose first turn may lie
    beyond w = 1.8e308: the cubic is formed exactly, scaled as w = 2^k v so
    that its coefficients fit (k as near 0 as leaves none overflowing or
    subnormal; even for w = r^2), rounded once and solved, and solved again
    scaled as far down as it fits where it has no root below the largest
    double; d_max = D(r_max) is evaluated exactly and rounded once, so no
    intermediate overflows.
    """
    from fractions import Fraction  # fractions: only for the exact fallback, rarely reached

    degree = len(distortion) - 1
    # D'(r), lowest power first; its powers of w are every power-th one.
    slope = [(j + 1) * distortion[degree - j - 1] for j in range(degree)]
    cubic = (slope[::power] + [Fraction(0)] * 4)[:4]
    leading = next((x for x in distortion if x != 0), Fraction(0))
    tail = (leading > 0) - (leading < 0)
    if cubic[0] <= 0:  # not increasing at the centre: no valid domain
        return 0.0, 0.0, tail
    r_max = _first_turn([x / cubic[0] for x in cubic[1:]], power)
    if not math.isfinite(r_max):
        return r_max, r_max, 0
    r = Fraction(r_max)
    d_max = Fraction(0)
    for x in distortion:
        d_max = d_max * r + x
    return r_max, _nearest_double(d_max), tail


def _first_turn(normalized: list[Fraction], power: int) -> float:
    """r_max of 1 + x1 w + x2 w^2 + x3 w^3 (the exact x's, w = r**power), as
    :func:`exact_model_r_max` finds it."""
    from fractions import Fraction  # fractions: only for the exact fallback, rarely reached

    # The scales that overflow no coefficient (k <= highest) and leave none
    # subnormal (k >= lowest); log2|x| is size within 1.
    highest = lowest = None
    for m, x in enumerate(normalized, start=1):
        if x != 0:
            size = x.numerator.bit_length() - x.denominator.bit_length()
            top, bottom = (1000 - size) // m, -((1000 + size) // m)
            highest = top if highest is None else min(highest, top)
            lowest = bottom if lowest is None else max(lowest, bottom)
    k = 0 if highest is None or lowest is None else min(max(0, lowest), highest)
    w, k = _scaled_root(normalized, k - k % power)
    if w == math.inf and highest is not None and highest - highest % power > k:
        w, k = _scaled_root(normalized, highest - highest % power)  # a root beyond 1.8e308?
    if w == math.inf and power == 2 and normalized[1] != 0 and normalized[2] == 0:
        # 1 + w (x1 + x2 w) with coefficients too far apart to scale into binary64:
        # where w x1 exceeds 2^1000, 1 is nothing beside it, and the sign changes
        # at -x1 / x2 within a part in 2^1000.
        turn = -normalized[0] / normalized[1]
        if turn > Fraction(2) ** (k + 1000):
            half = (turn.numerator.bit_length() - turn.denominator.bit_length()) // 2
            return kernel.ldexp(math.sqrt(float(turn / Fraction(4) ** half)), half)
    return kernel.ldexp(w, k) if power == 1 else kernel.ldexp(math.sqrt(w), k // 2)


def _scaled_root(normalized: list[Fraction], k: int) -> tuple[float, int]:
    """The smallest positive sign change v of the cubic scaled as w = 2^k v,
    its coefficients rounded once; and k."""
    from fractions import Fraction  # fractions: only for the exact fallback, rarely reached

    scaled = [_nearest_double(x * Fraction(2) ** (m * k)) for m, x in enumerate(normalized, 1)]
    return float(min_positive_root(*scaled)), k


def image_corner(aspect_ratio: ArrayLike) -> FloatArray:
    """Corner radius of the calibration image in Hugin units: hypot(aspect, 1).

    Aspect ratios below 1 (portrait) are taken as their inverse, since r = 1
    is half the short side either way.
    """
    aspect = np.asarray(aspect_ratio, dtype=np.float64)
    # math.hypot, once per distinct ratio: numpy's hypot is the C library's,
    # which may round differently, and kernel.entry_metrics must agree.
    values = aspect.ravel().tolist()
    corners = {x: kernel.image_corner(x) for x in dict.fromkeys(values)}
    # 0.0 and -0.0 are one key but two ratios (+inf and -inf inverted): those directly.
    radii = [corners[x] if x else kernel.image_corner(x) for x in values]
    return np.array(radii, dtype=np.float64).reshape(aspect.shape)


#: Radius of a circular fisheye's image circle in Hugin units: the circle
#: inscribed in the frame's short side (r = 1), which the circle cannot exceed.
IMAGE_CIRCLE = 1.0


#: Whether the database says a lens draws an image circle inside the frame.
is_circular_fisheye = kernel.is_circular_fisheye


def image_radius(aspect_ratio: ArrayLike, circular: ArrayLike | None = None) -> FloatArray:
    """Radius of the image a model must not fold inside, in Hugin units.

    The frame's corner, hypot(aspect, 1); for a circular fisheye, its image
    circle, taken as the circle inscribed in the short side (r = 1).
    """
    corner = image_corner(aspect_ratio)
    if circular is None:
        return corner
    return np.where(np.asarray(circular, dtype=bool), IMAGE_CIRCLE, corner)


def paper_image_corner(crop_factor: ArrayLike, focal: ArrayLike) -> FloatArray:
    """The paper's Eq. 29: hypot(18, 12) / (crop * focal), in focal-length units."""
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        return HALF_DIAGONAL_MM / (np.asarray(crop_factor, np.float64) * np.asarray(focal))


def _column(name: str, values: ArrayLike, size: int, dtype: type = np.float64) -> NDArray[Any]:
    """A column of :func:`compute`: one value per entry (a single value standing for all)."""
    found = np.asarray(values, dtype=dtype)
    if found.shape not in ((), (1,), (size,)):
        raise ValueError(f"{name} has shape {found.shape}: one value per entry needs ({size},)")
    return np.broadcast_to(found, (size,))


def compute(
    model: NDArray[np.str_] | list[str],
    a: ArrayLike,
    b: ArrayLike,
    c: ArrayLike,
    k1: ArrayLike,
    k2: ArrayLike,
    crop_factor: ArrayLike,
    aspect_ratio: ArrayLike,
    focal: ArrayLike,
    audited: ArrayLike,
    circular: ArrayLike | None = None,
) -> Metrics:
    """Metrics for entries given as columns; only ``audited`` entries are computed.

    ``model`` is "ptlens", "poly3" or "poly5" per entry; coefficients a, b, c
    (ptlens), k1 (poly3, poly5) and k2 (poly5) are raw Lensfun values.
    ``circular`` marks circular fisheyes, judged against their image circle
    (see :func:`image_radius`) rather than the frame's corner.
    """
    model = np.atleast_1d(np.asarray(model))
    size = model.shape[0]
    if model.ndim != 1:
        raise ValueError(f"model must be one column of names, not of shape {model.shape}")

    audited = _column("audited", audited, size, bool)
    r_max = np.full(size, np.nan)
    d_max = np.full(size, np.nan)
    tail = np.zeros(size, dtype=np.int8)
    given = dict(a=a, b=b, c=c, k1=k1, k2=k2, crop_factor=crop_factor, aspect_ratio=aspect_ratio)
    columns = {
        name: _column(name, values, size) for name, values in dict(given, focal=focal).items()
    }
    if circular is not None:
        circular = _column("circular", circular, size, bool)
    builders = {
        "ptlens": lambda rows: normalizer.ptlens(*(columns[n][rows] for n in "abc")),
        "poly3": lambda rows: normalizer.poly3(columns["k1"][rows]),
        "poly5": lambda rows: normalizer.poly5(columns["k1"][rows], columns["k2"][rows]),
    }
    for name, build in builders.items():
        rows = np.flatnonzero(audited & (model == name))
        if not rows.size:
            continue
        with np.errstate(all="ignore"):  # overflow in the cubic is handled below
            cubic = build(rows)
            r_max[rows], d_max[rows], tail[rows] = model_r_max(cubic)
        # Coefficients near the ends of the binary64 range overflow the cubic or
        # D(r_max) on the way, or lose digits in the cubic, and a first turn
        # beyond w = 1.8e308 is inf as a float: those rows again, exactly (few,
        # if any).
        for row in rows[needs_exact(cubic, r_max[rows], d_max[rows])]:
            raw = [float(columns[n][row]) for n in ("a", "b", "c", "k1", "k2")]
            used = {"ptlens": raw[:3], "poly3": raw[3:4], "poly5": raw[3:]}[name]
            if all(math.isfinite(x) for x in used):
                exact = exact_distortion(name, *raw)
                r_max[row], d_max[row], tail[row] = exact_model_r_max(
                    exact, 1 if name == "ptlens" else 2
                )
    r_corner = np.where(audited, image_radius(columns["aspect_ratio"], circular), np.nan)
    r_corner_paper = np.where(
        audited, paper_image_corner(columns["crop_factor"], columns["focal"]), np.nan
    )
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        r_normalized = d_max / r_corner
        r_normalized_paper = d_max / r_corner_paper
    folds = audited & np.isfinite(r_max) & (r_normalized < 1)
    return Metrics(
        r_max, d_max, tail, r_corner, r_normalized, r_corner_paper, r_normalized_paper, folds
    )
