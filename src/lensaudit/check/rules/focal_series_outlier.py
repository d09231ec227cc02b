"""``focal-series-outlier``: a distortion entry far from what its neighbours
in focal length predict (see :mod:`lensaudit.check.series`)."""

from __future__ import annotations

from collections.abc import Iterable

from ..result import Identified
from ..series import series_outliers
from . import WARNING, Context, Rule

ORDER = 80

FOCAL_SERIES_OUTLIER = Rule(
    "focal-series-outlier",
    WARNING,
    "entry",
    "a distortion entry far from what its neighbours in focal length predict",
    "a `<distortion>` entry whose displacement D(r) - r lies far from what its neighbours in "
    "focal length predict (see [below](#focal-series-outliers))",
    "A calibration that breaks its lens's smooth course over focal length is often a "
    "mistyped coefficient or a calibration of another lens.",
    fails=(
        "slr-canon.xml:2126, Canon EF 35-80mm f/4-5.6 III at 80 mm (Lensfun issue 1024): 0.0569 "
        "off what 53 and 65 mm predict, 1.7 times the spread"
    ),
    passes="the same series at 53 mm (slr-canon.xml:2124): 0.0028 off, below the 0.01 minimum",
)
RULES = (FOCAL_SERIES_OUTLIER,)


def find(context: Context) -> Iterable[tuple[int, Identified]]:
    """Each outlier of its lens's focal series."""
    return series_outliers(context.read)
