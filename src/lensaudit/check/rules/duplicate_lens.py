"""``duplicate-lens``: a ``<lens>`` defined twice in the database (see
:func:`lensaudit.check.duplicates.duplicate_lenses`)."""

from __future__ import annotations

from collections.abc import Iterable

from ..duplicates import duplicate_lenses
from ..result import Identified
from . import ERROR, WARNING, Context, Rule

ORDER = 110
ACROSS_FILES = True

DUPLICATE_LENS = Rule(
    "duplicate-lens",
    ERROR,
    "lens",
    "a lens defined twice (maker, model, crop factor)",
    "a `<lens>` with the maker, model and crop factor of an earlier one, in any file (names "
    "compared ignoring case and runs of white space); a warning when the two definitions are "
    "the same but for the case and spacing of names and for comments",
    "liblensfun finds one of the two by name and never the other's calibrations.",
    fails=(
        "slr-sigma.xml:405 before Lensfun e85c5bc: Sigma 18-200mm f/3.5-6.3 DC, crop 1.53, "
        "defined again after line 384"
    ),
    passes=(
        "the two Tokina 11-16mm of slr-tokina.xml, crop factors 1 and 1.53: two calibrations, "
        "not duplicates"
    ),
    lesser="when the two definitions are the same but for the case and spacing of names",
    lesser_severity=WARNING,
)
RULES = (DUPLICATE_LENS,)


def find(context: Context) -> Iterable[tuple[int, Identified]]:
    """Each second definition of a lens, in any file of the database."""
    return duplicate_lenses(context.read, context.known)
