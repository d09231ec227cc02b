"""Audit Lensfun's transverse chromatic aberration (TCA) models for fold-back.

Lensfun corrects TCA by scaling the red and blue channels radially against
green. ``poly3`` gives, per channel, r_d = r (b r^2 + c r + v); ``linear``
gives r_d = k r (liblensfun's ``libs/lensfun/mod-subpix.cpp``). The radius
is in Hugin units, as for distortion: r = 1 is half the short side of the
calibration image (liblensfun scales ``c`` and ``b`` from that unit in
``rescale_polynomial_coefficients``), so the frame corner is at
hypot(aspect, 1); a circular fisheye is judged at its image circle, r = 1,
as the distortion audit does.

Like a distortion model, a channel's r_d must increase over the image, or
the correction maps two radii onto one and mirrors that channel beyond.
Per channel, ``r_fold`` is the first local maximum of r_d: the first r > 0
where r_d'(r) = v + 2 c r + 3 b r^2 changes sign from + to -; 0 when r_d
does not increase from the centre (v < 0, say); ``inf`` when it never
folds. ``folds_in_image`` (r_fold < r_corner for either channel) is decided
exactly on the coefficients as written
(:func:`lensaudit.calibrations.as_written`), and is an error.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .calibrations import (
    SEVERITY_ERROR,
    TCA,
    CalibrationAudit,
    sign_change_before,
)
from .columns import LENS_COLUMNS, LENS_FLOAT_COLUMNS, STATUS_COLUMNS
from .formats.table import text_table
from .metrics import image_radius

FloatArray = NDArray[np.float64]


CHANNELS = ("red", "blue")

#: The coefficient columns, in the order of :class:`~lensaudit.calibrations.TCAEntry`.
COEFFICIENTS = ("kr", "kb", "vr", "vb", "cr", "cb", "br", "bb")
METRIC_COLUMNS = ("r_corner", "r_fold_red", "r_fold_blue", "folds_in_image", "severity")
COLUMNS = (*LENS_COLUMNS, *COEFFICIENTS, *METRIC_COLUMNS, *STATUS_COLUMNS)
BOOL_COLUMNS = frozenset({"folds_in_image"})
FLOAT_COLUMNS = LENS_FLOAT_COLUMNS | set(COEFFICIENTS) | {"r_corner", "r_fold_red", "r_fold_blue"}

#: The columns of the tables of folding entries (terminal and report).
FOLDING_HEADER = ("r_fold_red", "r_fold_blue", "r_corner", "maker", "lens", "focal", "where")

#: What each column means, for --help and docs/vignetting.md.
COLUMN_HELP = {
    "r_corner": "radius of the image judged, Hugin units: hypot(aspect, 1), "
    "or 1 for a circular fisheye",
    "r_fold_red": "first local maximum of the red channel's r_d (inf: never; 0: decreasing "
    "from the centre)",
    "r_fold_blue": "the same for blue",
    "folds_in_image": "a channel folds inside the image, r_fold < r_corner (error)",
    "severity": "error or empty",
}


def r_fold(
    v: ArrayLike, c: ArrayLike, b: ArrayLike, r_corner: ArrayLike
) -> tuple[FloatArray, NDArray[np.bool_]]:
    """(r_fold, folds): first local maximum of r (b r^2 + c r + v), and whether it
    lies inside the image, r_fold < r_corner (exactly).

    r_fold is 0 where r_d does not increase from the centre (the first
    non-zero of v, c, b is negative, or all are 0), ``inf`` where r_d never
    folds. Any finite coefficients.
    """
    v, c, b, r_corner = np.broadcast_arrays(
        *(np.atleast_1d(np.asarray(x, dtype=np.float64)) for x in (v, c, b, r_corner))
    )
    # The sign of r_d' just right of 0: that of its first non-zero coefficient.
    start = np.where(v != 0, np.sign(v), np.where(c != 0, np.sign(c), np.sign(b)))
    x, before = sign_change_before(v, c, b, r_corner)
    decreasing = start <= 0
    return np.where(decreasing, 0.0, x), decreasing | before


def compute(
    model: Sequence[str],
    kr: ArrayLike,
    kb: ArrayLike,
    vr: ArrayLike,
    vb: ArrayLike,
    cr: ArrayLike,
    cb: ArrayLike,
    br: ArrayLike,
    bb: ArrayLike,
    r_corner: ArrayLike,
) -> dict[str, NDArray[Any]]:
    """The metric columns of finite coefficients, one element per entry."""
    linear = np.asarray(model) == "linear"
    arrays = {
        name: np.asarray(values, dtype=np.float64)
        for name, values in dict(kr=kr, kb=kb, vr=vr, vb=vb, cr=cr, cb=cb, br=br, bb=bb).items()
    }
    result: dict[str, NDArray[Any]] = {"r_corner": np.asarray(r_corner, dtype=np.float64)}
    folds = np.zeros(linear.shape, dtype=bool)
    for channel, (k, v, c, b) in zip(
        CHANNELS, (("kr", "vr", "cr", "br"), ("kb", "vb", "cb", "bb")), strict=True
    ):
        values = np.where(linear, arrays[k], arrays[v])
        first = np.where(linear, 0.0, arrays[c])
        second = np.where(linear, 0.0, arrays[b])
        radius, inside = r_fold(values, first, second, r_corner)
        result[f"r_fold_{channel}"] = radius
        folds |= inside
    result["folds_in_image"] = folds
    result["severity"] = np.where(folds, SEVERITY_ERROR, "").astype(object)
    return result


class TCAAudit(CalibrationAudit):
    """The audit of every ``<tca>`` entry (see :func:`audit`)."""

    kind = TCA
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
        with np.errstate(all="ignore"):
            radius = image_radius(floats("aspect_ratio"), circular)
        return compute(values("model"), *map(floats, COEFFICIENTS), radius)

    def ratios(self) -> FloatArray:
        """Per entry: the nearer channel's r_fold over r_corner (below 1: folds inside)."""
        m = self.metrics
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.minimum(m["r_fold_red"], m["r_fold_blue"]) / m["r_corner"]

    def folding(self) -> list[int]:
        """Indices of the entries that fold inside their image, by r_fold / r_corner."""
        ratio = self.ratios()
        folds = self.metrics["folds_in_image"]
        rows = [i for i, ok in enumerate(self.audited) if ok and folds[i]]
        return sorted(rows, key=lambda i: (ratio[i], self.entries[i].file, self.entries[i].line))

    def folding_row(self, index: int) -> list[str]:
        """One entry's texts in the tables of folding entries (:data:`FOLDING_HEADER`)."""
        m, entry = self.metrics, self.entries[index]
        return [
            f"{m['r_fold_red'][index]:.4g}",
            f"{m['r_fold_blue'][index]:.4g}",
            f"{m['r_corner'][index]:.4g}",
            entry.maker,
            entry.lens,
            f"{entry.focal:g}",
            f"{entry.file}:{entry.line}",
        ]

    def nearest(self) -> int | None:
        """Index of the audited entry whose fold is nearest its image (None: none folds)."""
        ratio = self.ratios()
        finite = [i for i, ok in enumerate(self.audited) if ok and np.isfinite(ratio[i])]
        return min(finite, key=lambda i: (ratio[i], i)) if finite else None

    def summary(self) -> dict[str, Any]:
        summary = super().summary()
        models: dict[str, int] = {}
        for model, ok in zip(self.entries.column("model"), self.audited, strict=True):
            if ok:
                models[model] = models.get(model, 0) + 1
        folding = self.folding()
        nearest = self.nearest()
        summary.update(
            models=models,
            folds_in_image=len(folding),
            folding=[f"{self.entries[i].file}:{self.entries[i].line}" for i in folding],
            nearest_fold=None
            if nearest is None
            else {
                "where": f"{self.entries[nearest].file}:{self.entries[nearest].line}",
                "r_fold_over_r_corner": float(self.ratios()[nearest]),
            },
        )
        return summary

    def lines(self) -> list[str]:
        summary = self.summary()
        models = ", ".join(f"{n} {m}" for m, n in summary["models"].items())
        out = self.head_lines(summary, "TCA entries")
        if models:
            out[-1] += f" ({models})"
        out += [
            "",
            "TCA r_d = r (b r^2 + c r + v) per channel, Hugin units (corner at hypot(aspect, 1))",
            f"Entries with a channel that folds inside the image: {summary['folds_in_image']}",
        ]
        nearest = self.nearest()
        if nearest is not None:
            entry = self.entries[nearest]
            out.append(
                f"Nearest fold: {self.ratios()[nearest]:.3g} times the image radius "
                f"({entry.lens} at {entry.focal:g} mm, {entry.file}:{entry.line})"
            )
        folding = self.folding()
        if folding:
            out += text_table(
                list(FOLDING_HEADER),
                list(map(self.folding_row, folding)),
                right=[True, True, True, False, False, True, False],
            )
        return out + self.problem_lines()


# The module's entry points are the audit class's.
audit_entries = TCAAudit.of_entries
audit = TCAAudit.read
of_database = TCAAudit.of_database
