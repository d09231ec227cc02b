"""``conflicting-calibration``: two calibrations of one lens for the same
point that disagree (see :func:`lensaudit.check.metadata.conflicting_calibrations`)."""

from __future__ import annotations

from collections.abc import Iterable

from ..metadata import conflicting_calibrations
from ..result import Identified
from . import WARNING, Context, Rule

ORDER = 90

CONFLICTING_CALIBRATION = Rule(
    "conflicting-calibration",
    WARNING,
    "entry",
    "two calibrations of one lens for the same focal length, aperture and distance; "
    "liblensfun uses the first",
    "a second `<distortion>`, `<tca>` or `<vignetting>` of one lens and crop factor for the "
    "same focal length (and aperture and distance, for vignetting) with another model or "
    "other coefficients: liblensfun uses only the first",
    "liblensfun takes the first exact match and never sees the other.",
    fails=(
        "compact-canon.xml:2218, PowerShot A640 <tca> at 17.3 mm: a second entry for 17.3 mm, "
        "br -0.0000765 against -0.0000452"
    ),
    passes="the same lens's <tca> at 14.9 mm (compact-canon.xml:2216), the only one there",
)
RULES = (CONFLICTING_CALIBRATION,)


def find(context: Context) -> Iterable[tuple[int, Identified]]:
    """Each second calibration that contradicts the first, file by file."""
    for index, file in enumerate(context.read):
        for item in conflicting_calibrations(file):
            yield index, item
