"""``fold-between-calibrations``: a zoom whose model, as liblensfun
interpolates it between two calibrations that do not fold, folds inside the
image (see :mod:`lensaudit.check.between`)."""

from __future__ import annotations

from collections.abc import Iterable

from ..between import folds_between
from ..result import Identified
from . import ERROR, NOTICE, Context, Rule

ORDER = 70

FOLD_BETWEEN_CALIBRATIONS = Rule(
    "fold-between-calibrations",
    ERROR,
    "entry",
    "a zoom's model, as liblensfun interpolates it between two calibrations that do not fold, "
    "folds inside the image",
    "at a focal length between two calibrations of a zoom, neither of which folds, the model "
    "liblensfun interpolates folds back inside the image (see "
    "[below](#zooms-between-their-calibrations))",
    "liblensfun interpolates a zoom's coefficients with a spline through the calibrations "
    "either side and their neighbours; the spline can overshoot. Proven over every focal "
    "length of the interval, not sampled; a notice with --verbose where it cannot be decided.",
    fails=(
        "slr-nikon.xml:3085 at Lensfun 09ed743, AF Zoom-Nikkor 28-200mm G: the spline through "
        "28, 38 and a mistyped 48 mm entry folds at 33 mm, 0.753 of the image radius"
    ),
    passes=(
        "the same lens at b7364b6, the same day, with the 48 mm entry removed: nothing between "
        "28 and 38 mm folds"
    ),
    lesser="with --verbose, where whether it folds could not be decided",
    lesser_severity=NOTICE,
)
RULES = (FOLD_BETWEEN_CALIBRATIONS,)


def find(context: Context) -> Iterable[tuple[int, Identified]]:
    """Each interval between two calibrations of a zoom where the interpolated model folds."""
    entries = [entry for _, entry in context.entries]
    names = [context.read[index].source.file_name for index, _ in context.entries]
    folding = [m is not None and not m.r_normalized >= 1 for m in context.metrics]
    for position, item in folds_between(entries, context.corners, folding, names, context.verbose):
        yield context.entries[position][0], item
