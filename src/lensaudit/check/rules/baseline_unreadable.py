"""``baseline-unreadable``: the baseline's version of a file could not be
parsed. Made where the baseline is read (:func:`lensaudit.check.matching.baseline_notices`),
not by looking at the database checked: this family finds nothing there."""

from __future__ import annotations

from . import NOTICE, Rule

ORDER = 200

BASELINE_UNREADABLE = Rule(
    "baseline-unreadable",
    NOTICE,
    "baseline",
    "how a baseline file that cannot be parsed was replaced",
    "the baseline's version of this file could not be parsed: which version it was compared "
    "with instead, or that its findings are not counted as new",
    "A baseline file that cannot be parsed is replaced by its last readable version in git; "
    "without one, the file's findings are not counted as new.",
    fails=(
        "Lensfun 49d4e3b checked against its parent 37faac8, whose mil-panasonic.xml is not "
        "well-formed: compared with b72486d instead"
    ),
    passes="34482e5 checked against 49d4e3b, whose file parses",
)
RULES = (BASELINE_UNREADABLE,)
