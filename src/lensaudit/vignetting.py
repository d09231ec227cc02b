"""Audit Lensfun's vignetting models: where the correction divides by zero.

Lensfun's ``pa`` model gives the brightness of the image relative to its
centre, C(r) = 1 + k1 r^2 + k2 r^4 + k3 r^6, and the correction divides
every pixel by C(r). Here r = 1 is half the diagonal of the calibration
sensor, whatever its aspect ratio: liblensfun converts the coefficients from
that unit, hypot(36, 24) / (2 crop) millimetres (``libs/lensfun/mod-color.cpp``,
``rescale_polynomial_coefficients``), and the liblensfun of lensfunpy puts
r = 1 on the corner pixels (tests/test_vignetting_liblensfun.py measures
it). So the frame corner is r = 1; for a circular fisheye, whose image circle
is inscribed in the short side, the audit judges the circle instead, at
r = 1 / hypot(aspect, 1), as the distortion audit does.

Per entry, with w = r^2 and C a cubic in w:

- ``r_zero``: the first radius where C changes sign, sqrt of
  :func:`lensaudit.solver.min_positive_root` (exact in kind; ``inf`` if never);
- ``c_min`` and ``r_min``: the minimum of C over the image, 0 <= r <=
  ``r_corner``, and where it is (at an end or where C'(w) = k1 + 2 k2 w +
  3 k3 w^2 vanishes);
- ``r_turn``: the first radius where C' changes sign (``inf`` if never);
  C is monotone over the image when that lies beyond it;
- ``c_max`` and ``r_cmax``: the maximum of C over the image, and where;
- ``zero_in_image`` (C <= 0 somewhere in the image: the correction divides
  by zero or flips the sign of pixels; liblensfun then writes black),
  ``low_in_image`` (C < 0.1: a correction gain above 10, which amplifies the
  noise tenfold), ``brightens`` (C > 1.05: the model has part of the image
  more than 5% brighter than its centre, which no lens is; the correction
  darkens it, as an FE 85 mm GM entry once did 3.4-fold at the corner,
  removed in Lensfun's 5599955b) and ``monotone``, each decided exactly on the coefficients
  as the database writes them (:func:`lensaudit.calibrations.as_written`):
  the float answer where it is far from the boundary, rational arithmetic
  otherwise.

Severity: ``error`` for zero_in_image, ``warning`` for low_in_image or
brightens, ``notice`` for a C that is not monotone over the image.
"""

from __future__ import annotations

from collections.abc import Callable
from fractions import Fraction
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .calibrations import (
    MARGIN,
    SEVERITY_ERROR,
    SEVERITY_NOTICE,
    SEVERITY_WARNING,
    VIGNETTING,
    CalibrationAudit,
    ExactTurn,
    as_written,
    exact_turning_points,
    sign_change_before,
    sign_of,
    sign_of_surd,
    to_float,
    turning_points,
)
from .columns import LENS_COLUMNS, LENS_FLOAT_COLUMNS, STATUS_COLUMNS
from .formats.table import text_table
from .metrics import image_corner
from .solver.arrays import min_positive_root

FloatArray = NDArray[np.float64]

#: C below this is a correction gain above 10 (a warning).
LOW_CORRECTION = 0.1
_LOW_EXACT = Fraction(1, 10)
#: C above this somewhere in the image: brighter than the centre by more than
#: calibration noise (a warning).
BRIGHTENING = 1.05
_BRIGHTENING_EXACT = Fraction(105, 100)


#: How many entries the terminal summary lists by name.
WORST_SHOWN = 15

METRIC_COLUMNS = (
    "r_corner", "r_zero", "c_min", "r_min", "c_max", "r_cmax", "r_turn", "zero_in_image",
    "low_in_image", "brightens", "monotone", "severity",
)  # fmt: skip
COLUMNS = (
    *LENS_COLUMNS, "aperture", "distance", "k1", "k2", "k3", *METRIC_COLUMNS, *STATUS_COLUMNS,
)  # fmt: skip
BOOL_COLUMNS = frozenset({"zero_in_image", "low_in_image", "brightens", "monotone"})
FLOAT_COLUMNS = (
    LENS_FLOAT_COLUMNS
    | {"aperture", "distance", "k1", "k2", "k3"}
    | {"r_corner", "r_zero", "c_min", "r_min", "c_max", "r_cmax", "r_turn"}
)

#: What each column means, for --help and docs/vignetting.md.
COLUMN_HELP = {
    "r_corner": "radius of the image judged, r = 1 at half the diagonal: 1 (frame corner), "
    "or the image circle 1/hypot(aspect, 1) of a circular fisheye",
    "r_zero": "first radius where C(r) changes sign (inf: never)",
    "c_min": "minimum of C(r) over the image, 0 <= r <= r_corner",
    "r_min": "where that minimum is",
    "c_max": "maximum of C(r) over the image (1 at the centre)",
    "r_cmax": "where that maximum is",
    "r_turn": "first radius where C'(r) changes sign (inf: never)",
    "zero_in_image": "C <= 0 somewhere in the image (error)",
    "low_in_image": "C < 0.1 somewhere in the image: correction gain above 10 (warning)",
    "brightens": "C > 1.05 somewhere in the image: brighter than the centre (warning)",
    "monotone": "C has no turning point inside the image (false: notice)",
    "severity": "error, warning, notice, or empty",
}


def image_radius(aspect_ratio: ArrayLike, circular: ArrayLike | None = None) -> FloatArray:
    """Radius of the image judged, in units of half the diagonal.

    1 (the frame corner); for a circular fisheye, the circle inscribed in the
    short side, 1 / hypot(aspect, 1).
    """
    corner = np.ones(np.shape(aspect_ratio))
    if circular is None:
        return corner
    with np.errstate(all="ignore"):
        circle = 1.0 / image_corner(aspect_ratio)
    return np.where(np.asarray(circular, dtype=bool), circle, corner)


def evaluate(k1: ArrayLike, k2: ArrayLike, k3: ArrayLike, r: ArrayLike) -> FloatArray:
    """C(r) = 1 + k1 r^2 + k2 r^4 + k3 r^6, elementwise (overflow gives inf, no warning)."""
    with np.errstate(all="ignore"):
        w = np.square(np.asarray(r, dtype=np.float64))
        return 1.0 + w * (np.asarray(k1) + w * (np.asarray(k2) + w * np.asarray(k3)))


def _cubic(k1: ArrayLike, k2: ArrayLike, k3: ArrayLike, w: ArrayLike) -> FloatArray:
    return 1.0 + w * (k1 + w * (k2 + w * k3))


def _remainder(k1: Fraction, k2: Fraction, k3: Fraction) -> tuple[Fraction, Fraction]:
    """(rho0, rho1): C(w) = Q(w) C'(w) + rho0 + rho1 w, so that C = rho0 + rho1 w
    wherever C' = 0 (C' of degree 1 or 2)."""
    numerator = [Fraction(1), k1, k2, k3]
    divisor = [k1, 2 * k2, 3 * k3]
    while divisor and divisor[-1] == 0:
        divisor.pop()
    while len(numerator) >= len(divisor):
        factor = numerator[-1] / divisor[-1]
        shift = len(numerator) - len(divisor)
        for index, coefficient in enumerate(divisor):
            numerator[shift + index] -= factor * coefficient
        numerator.pop()
    numerator += [Fraction(0)] * (2 - len(numerator))
    return numerator[0], numerator[1]


def _turns_inside(k1: float, k2: float, k3: float, w_image: Fraction) -> list[ExactTurn]:
    return [t for t in exact_turning_points(k1, k2, k3) if t.sign_minus(w_image) < 0]


def exact_below(
    k1: float, k2: float, k3: float, w_image: float, threshold: Fraction, strict: bool
) -> bool:
    """Whether min C over 0 <= w <= w_image is below ``threshold`` (< if ``strict``,
    else <=), exactly, for finite coefficients taken :func:`as_written`.
    ``threshold`` < 1."""
    return _exact_beyond(k1, k2, k3, w_image, threshold, strict, -1)


def exact_above(
    k1: float, k2: float, k3: float, w_image: float, threshold: Fraction, strict: bool
) -> bool:
    """Whether max C over 0 <= w <= w_image is above ``threshold`` (> if ``strict``,
    else >=), exactly, as :func:`exact_below`. ``threshold`` > 1."""
    return _exact_beyond(k1, k2, k3, w_image, threshold, strict, 1)


def _exact_beyond(
    k1: float,
    k2: float,
    k3: float,
    w_image: float,
    threshold: Fraction,
    strict: bool,
    side: int,
) -> bool:
    """Whether C - threshold takes the sign ``side`` (0 too unless ``strict``)
    somewhere in 0 <= w <= w_image: at w = 0 it does not (C = 1), so at the
    image's edge or at a turning point inside."""
    a1, a2, a3, limit = (as_written(v) for v in (k1, k2, k3, w_image))

    def hit(sign: int) -> bool:
        return sign * side > 0 if strict else sign * side >= 0

    if hit(sign_of(1 + limit * (a1 + limit * (a2 + limit * a3)) - threshold)):
        return True
    turns = _turns_inside(k1, k2, k3, limit)
    if not turns:
        return False
    rho0, rho1 = _remainder(a1, a2, a3)
    for turn in turns:
        # C(x) - threshold = (rho1 (p + e sqrt d) + (rho0 - threshold) q) / q
        sign = sign_of_surd(rho1 * turn.p + (rho0 - threshold) * turn.q, rho1 * turn.e, turn.d)
        if hit(sign * sign_of(turn.q)):
            return True
    return False


def exact_minimum(k1: float, k2: float, k3: float, w_image: float) -> tuple[float, float]:
    """(c_min, w where it is) over 0 <= w <= w_image, to about 1e-40 before rounding."""
    return _exact_extreme(k1, k2, k3, w_image, min)


def exact_maximum(k1: float, k2: float, k3: float, w_image: float) -> tuple[float, float]:
    """(c_max, w where it is) over 0 <= w <= w_image, as :func:`exact_minimum`."""
    return _exact_extreme(k1, k2, k3, w_image, max)


def _exact_extreme(
    k1: float, k2: float, k3: float, w_image: float, choose: Callable
) -> tuple[float, float]:
    a1, a2, a3, limit = (as_written(v) for v in (k1, k2, k3, w_image))
    candidates = [Fraction(0), limit] + [t.value() for t in _turns_inside(k1, k2, k3, limit)]
    values = [1 + w * (a1 + w * (a2 + w * a3)) for w in candidates]
    best = choose(range(len(values)), key=values.__getitem__)
    return to_float(values[best]), to_float(candidates[best])


def compute(
    k1: ArrayLike,
    k2: ArrayLike,
    k3: ArrayLike,
    r_corner: ArrayLike,
) -> dict[str, NDArray[Any]]:
    """The metric columns (see the module docstring) of finite coefficients;
    where a coefficient or ``r_corner`` is not finite, NaN, no finding.

    ``r_corner`` is the radius of the image judged, r = 1 at half the
    diagonal. Returns arrays keyed by column name, ``severity`` as text.
    """
    k1, k2, k3, r_corner = np.broadcast_arrays(
        *(np.atleast_1d(np.asarray(v, dtype=np.float64)) for v in (k1, k2, k3, r_corner))
    )
    w_image = np.square(r_corner)
    r_zero = np.sqrt(np.asarray(min_positive_root(k1, k2, k3), dtype=np.float64))
    c_min, w_min, c_max, w_max, doubtful = _extremes(k1, k2, k3, w_image)
    with np.errstate(all="ignore"):
        zero_in_image = c_min <= 0
        low_in_image = c_min < LOW_CORRECTION
        brightens = c_max > BRIGHTENING
    unknown = ~(np.isfinite(k1) & np.isfinite(k2) & np.isfinite(k3) & np.isfinite(w_image))
    for values in (c_min, w_min, c_max, w_max):
        values[unknown] = np.nan
    for flags in (zero_in_image, low_in_image, brightens):
        flags[unknown] = False
    for index in np.flatnonzero(doubtful & ~unknown):
        a, b, c, w = (float(v[index]) for v in (k1, k2, k3, w_image))
        zero_in_image[index] = exact_below(a, b, c, w, Fraction(0), strict=False)
        low_in_image[index] = exact_below(a, b, c, w, _LOW_EXACT, strict=True)
        brightens[index] = exact_above(a, b, c, w, _BRIGHTENING_EXACT, strict=True)
        c_min[index], w_min[index] = exact_minimum(a, b, c, w)
        c_max[index], w_max[index] = exact_maximum(a, b, c, w)

    w_turn, turns_inside = sign_change_before(k1, k2, k3, w_image)
    warned = low_in_image | brightens
    severity = np.where(
        zero_in_image,
        SEVERITY_ERROR,
        np.where(warned, SEVERITY_WARNING, np.where(turns_inside, SEVERITY_NOTICE, "")),
    ).astype(object)
    return {
        "r_corner": r_corner.copy(),
        "r_zero": r_zero,
        "c_min": c_min,
        "r_min": np.sqrt(w_min),
        "c_max": c_max,
        "r_cmax": np.sqrt(w_max),
        "r_turn": np.sqrt(w_turn),
        "zero_in_image": zero_in_image,
        "low_in_image": low_in_image,
        "brightens": brightens,
        "monotone": ~turns_inside,
        "severity": severity,
    }


def _extremes(
    k1: FloatArray, k2: FloatArray, k3: FloatArray, w_image: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, NDArray[np.bool_]]:
    """(c_min, w there, c_max, w there, doubtful) over 0 <= w <= w_image, in
    floats: at the ends and the turning points inside. ``doubtful`` marks the
    entries too near a threshold, or a turning point too near the edge, for
    the floats to decide them: those are decided exactly."""
    size = k1.shape[0]
    low, high, reliable = turning_points(k1, k2, k3)
    rows = np.arange(size)
    with np.errstate(all="ignore"):
        points = np.stack([np.zeros(size), w_image, low, high], axis=1)
        inside = np.ones(points.shape, dtype=bool)
        inside[:, 2:] = (points[:, 2:] > 0) & (points[:, 2:] < w_image[:, None])
        values = _cubic(k1[:, None], k2[:, None], k3[:, None], points)
        lowest = np.argmin(np.where(inside, values, np.inf), axis=1)
        highest = np.argmax(np.where(inside, values, -np.inf), axis=1)
        c_min, w_min = values[rows, lowest], points[rows, lowest]
        c_max, w_max = values[rows, highest], points[rows, highest]
        size_of_terms = 1 + np.abs(k1) * w_image + np.abs(k2) * w_image**2 + np.abs(k3) * w_image**3
        near_edge = (np.abs(low - w_image) <= MARGIN * w_image) | (
            np.abs(high - w_image) <= MARGIN * w_image
        )
        doubtful = (
            ~reliable
            | near_edge
            | ~np.isfinite(c_min)
            | ~np.isfinite(c_max)
            | ~np.isfinite(size_of_terms)
            | (np.abs(c_min) <= MARGIN * size_of_terms)
            | (np.abs(c_min - LOW_CORRECTION) <= MARGIN * size_of_terms)
            | (np.abs(c_max - BRIGHTENING) <= MARGIN * size_of_terms)
        )
    return c_min, w_min, c_max, w_max, doubtful


class VignettingAudit(CalibrationAudit):
    """The audit of every ``<vignetting>`` entry (see :func:`audit`)."""

    kind = VIGNETTING
    COLUMNS = COLUMNS
    METRIC_COLUMNS = METRIC_COLUMNS
    FLOAT_COLUMNS = FLOAT_COLUMNS
    BOOL_COLUMNS = BOOL_COLUMNS

    @staticmethod
    def compute_audited(
        values: Callable[[str], list[Any]],
        floats: Callable[[str], FloatArray],
        circular: list[bool],
    ) -> dict[str, NDArray[Any]]:
        """:func:`compute` of audited records, each judged over its image."""
        radius = image_radius(floats("aspect_ratio"), circular)
        return compute(floats("k1"), floats("k2"), floats("k3"), radius)

    def worst(self, limit: int | None = None) -> list[int]:
        """Indices of the entries with a finding, by increasing c_min."""
        c_min, low = self.metrics["c_min"], self.metrics["low_in_image"]
        flagged = [
            i
            for i, (severity, ok) in enumerate(
                zip(self.metrics["severity"].tolist(), self.audited, strict=True)
            )
            if ok and severity in (SEVERITY_ERROR, SEVERITY_WARNING) and low[i]
        ]
        flagged.sort(key=lambda i: (c_min[i], self.entries[i].file, self.entries[i].line))
        return flagged[:limit]

    def worst_cells(self, index: int) -> dict[str, str]:
        """One entry's texts in the tables of the worst entries, by column:
        ``c_min r_zero r_min maker lens focal f/ distance where``."""
        m, entry = self.metrics, self.entries[index]
        return {
            "c_min": f"{m['c_min'][index]:.3g}",
            "r_zero": f"{m['r_zero'][index]:.3f}",
            "r_min": f"{m['r_min'][index]:.3f}",
            "maker": entry.maker,
            "lens": entry.lens,
            "focal": f"{entry.focal:g}",
            "f/": f"{entry.aperture:g}",
            "distance": f"{entry.distance:g}",
            "where": f"{entry.file}:{entry.line}",
        }

    def summary(self) -> dict[str, Any]:
        summary = super().summary()
        audited = np.array(self.audited, dtype=bool)
        summary.update(
            zero_in_image=int(np.count_nonzero(self.metrics["zero_in_image"] & audited)),
            low_in_image=int(np.count_nonzero(self.metrics["low_in_image"] & audited)),
            brightens=int(np.count_nonzero(self.metrics["brightens"] & audited)),
            brightens_alone=int(
                np.count_nonzero(
                    self.metrics["brightens"] & ~self.metrics["low_in_image"] & audited
                )
            ),
            not_monotone=int(np.count_nonzero(~self.metrics["monotone"] & audited)),
            worst=[f"{self.entries[i].file}:{self.entries[i].line}" for i in self.worst(20)],
        )
        return summary

    def lines(self) -> list[str]:
        summary = self.summary()
        out = self.head_lines(summary, "vignetting entries") + [
            "",
            "Vignetting C(r) = 1 + k1 r^2 + k2 r^4 + k3 r^6, r = 1 at half the diagonal "
            "(the frame corner; a circular fisheye's image circle at 1/hypot(aspect, 1))",
        ]
        out += text_table(
            ["severity", "entries", "finding"],
            [
                [
                    "error",
                    summary["zero_in_image"],
                    "C <= 0 inside the image: the correction divides by zero or flips sign",
                ],
                [
                    "warning",
                    summary["low_in_image"] - summary["zero_in_image"],
                    "0 < C < 0.1 inside the image: a correction gain above 10",
                ],
                [
                    "warning",
                    summary["brightens_alone"],
                    f"C > {BRIGHTENING:g} inside the image: brighter than the centre "
                    "(and none of the above)",
                ],
                [
                    "notice",
                    summary["severities"]["notice"],
                    "C not monotone inside the image (and none of the above)",
                ],
            ],
            right=[False, True, False],
        )
        out.append(f"(C not monotone inside the image, whatever else: {summary['not_monotone']}.)")
        worst = self.worst()
        out.append("")
        out.append(f"Entries where C falls below 0.1 inside the image: {len(worst)}")
        if worst:
            shown = worst[:WORST_SHOWN]
            header = ["c_min", "r_zero", "maker", "lens", "focal", "f/", "distance", "where"]
            out += text_table(
                header,
                [[cells[h] for h in header] for cells in map(self.worst_cells, shown)],
                right=[True, True, False, False, True, True, True, False],
            )
            if len(worst) > len(shown):
                out.append(f"  ... and {len(worst) - len(shown)} more (all of them: --format csv)")
        return out + self.problem_lines()


# The module's entry points are the audit class's.
audit_entries = VignettingAudit.of_entries
audit = VignettingAudit.read
of_database = VignettingAudit.of_database
