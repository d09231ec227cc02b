"""``duplicate-focal``: a second ``<distortion>`` for one focal length of one
calibration (see :func:`lensaudit.check.duplicates.duplicate_focals`)."""

from __future__ import annotations

from collections.abc import Iterable

from ..duplicates import duplicate_focals
from ..result import Identified
from . import ERROR, WARNING, Context, Rule

ORDER = 60

DUPLICATE_FOCAL = Rule(
    "duplicate-focal",
    ERROR,
    "entry",
    "two distortion entries for one focal length of one calibration",
    "a second `<distortion>` for the same focal length in one calibration (one lens, one crop "
    "factor and aspect ratio); a warning when the two entries have the same values "
    "(liblensfun keeps one of two equal things)",
    "liblensfun keeps one of the two, so the other's values are lost to every program; with "
    "a baseline, the finding goes on the one of the two the change added.",
    fails=(
        "compact-panasonic.xml:681, Leica DMC-FZ28 (Standard) at 8.2 mm: a second entry with "
        "other a, b, c than line 680"
    ),
    passes=(
        "the same lens at 6.9 mm (compact-panasonic.xml:679): the same coefficients as at 6.1 "
        "mm, at another focal length"
    ),
    lesser="when the two entries have the same values",
    lesser_severity=WARNING,
)
RULES = (DUPLICATE_FOCAL,)


def find(context: Context) -> Iterable[tuple[int, Identified]]:
    """Each second entry for a focal length of a calibration."""
    return duplicate_focals(context.read, context.known)
