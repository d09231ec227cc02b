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
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import normalizer
from .solver import kernel
from .solver.arrays import min_positive_root

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
    is increasing on (0, inf), NaN for NaN coefficients.
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

    For models whose cubic overflows binary64 (coefficients near 1e308):
    the cubic is formed exactly, scaled as w = 2^k v so that its coefficients
    fit (k <= 0, even for w = r^2), rounded once and solved; d_max = D(r_max)
    is evaluated exactly and rounded once, so no intermediate overflows.
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
    normalized = [x / cubic[0] for x in cubic[1:]]
    k = 0
    for m, x in enumerate(normalized, start=1):
        if x != 0:
            size = x.numerator.bit_length() - x.denominator.bit_length()  # log2|x| within 1
            k = min(k, (1000 - size) // m)
    k -= k % power
    scaled = [_nearest_double(x * Fraction(2) ** (m * k)) for m, x in enumerate(normalized, 1)]
    w = min_positive_root(*scaled)
    r_max = math.ldexp(w, k) if power == 1 else math.ldexp(math.sqrt(w), k // 2)
    if not math.isfinite(r_max):
        return r_max, r_max, 0
    r = Fraction(r_max)
    d_max = Fraction(0)
    for x in distortion:
        d_max = d_max * r + x
    return r_max, _nearest_double(d_max), tail


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
    model = np.asarray(model)
    audited = np.asarray(audited, dtype=bool)
    size = model.shape[0]
    r_max = np.full(size, np.nan)
    d_max = np.full(size, np.nan)
    tail = np.zeros(size, dtype=np.int8)
    columns = {
        name: np.asarray(values, dtype=np.float64)
        for name, values in dict(a=a, b=b, c=c, k1=k1, k2=k2).items()
    }
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
            r_max[rows], d_max[rows], tail[rows] = model_r_max(build(rows))
        # Coefficients near the top of the binary64 range overflow the cubic or
        # D(r_max) on the way: those rows again, exactly (few, if any).
        overflowed = rows[
            np.isnan(r_max[rows]) | (np.isfinite(r_max[rows]) & ~np.isfinite(d_max[rows]))
        ]
        for row in overflowed:
            raw = [float(columns[n][row]) for n in ("a", "b", "c", "k1", "k2")]
            used = {"ptlens": raw[:3], "poly3": raw[3:4], "poly5": raw[3:]}[name]
            if all(math.isfinite(x) for x in used):
                exact = exact_distortion(name, *raw)
                r_max[row], d_max[row], tail[row] = exact_model_r_max(
                    exact, 1 if name == "ptlens" else 2
                )
    r_corner = np.where(audited, image_radius(aspect_ratio, circular), np.nan)
    r_corner_paper = np.where(audited, paper_image_corner(crop_factor, focal), np.nan)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        r_normalized = d_max / r_corner
        r_normalized_paper = d_max / r_corner_paper
    folds = audited & np.isfinite(r_max) & (r_normalized < 1)
    return Metrics(
        r_max, d_max, tail, r_corner, r_normalized, r_corner_paper, r_normalized_paper, folds
    )
