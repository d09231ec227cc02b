"""``fold-in-image``, ``fold-near-image``, ``fold-outside-image``,
``r-max-not-computable``: where a distortion entry's model folds back.

r_normalized = D(r_max) / r_corner, both in Hugin units (1 = half the short
side of the calibration image; the corner at hypot(aspect, 1), a circular
fisheye's image circle at 1). Below 1 the model folds inside the very image
it was calibrated on, and undistortion mirrors pixels beyond that radius.
"""

from __future__ import annotations

import math
import shlex
from collections.abc import Iterable
from typing import Any

from ...formats import UNPRINTABLE
from ...metrics import is_circular_fisheye
from ...read.records import STATUS_OK, DistortionEntry
from ..result import Finding, Identified, entry_finding
from . import ERROR, NOTICE, WARNING, Context, Rule
from ._identity import entry_identified

ORDER = 20

FOLD_IN_IMAGE = Rule(
    "fold-in-image",
    ERROR,
    "entry",
    "the model folds back inside its own image: D(r_max) < image corner hypot(aspect, 1) (a "
    "circular fisheye: its image circle, 1)",
    "the model folds back inside its own image: D(r_max) < image corner hypot(aspect, 1) "
    "(a circular fisheye's image circle, 1), or D decreases from the centre",
    "Points beyond the fold, outside the field of view, are projected into the image, and "
    "undistorting the image mirrors pixels into its corners. The message ends with the "
    "`lensaudit fix` command that refits the entry.",
    fails=(
        "slr-tokina.xml:17 of lensfunpy 1.18.0's database, Tokina 11-16mm f/2.8 AT-X 116 AF Pro "
        "DX, crop 1, ptlens at 11 mm: D(r_max) = 1.687 at r_max = 2.194, 0.936 of the corner 1.803"
    ),
    passes=(
        "the same lens at 12 mm (slr-tokina.xml:18): D(r_max) 1.247 times the corner; at 14 mm "
        "r_max is infinite"
    ),
)
FOLD_NEAR_IMAGE = Rule(
    "fold-near-image",
    WARNING,
    "entry",
    "D(r_max) below MARGIN times the image corner",
    "the fold lies just outside the image: D(r_max) below `--margin` (default 1.1) times the "
    "corner",
    "A crop of a slightly larger sensor, or a recalibration, can bring the fold into the image.",
    fails=(
        "slr-canon.xml:7291, Canon EF 15mm f/2.8 Fisheye, ptlens at 15 mm: D(r_max) = 1.913, "
        "1.061 times the corner 1.803, below the margin 1.1"
    ),
    passes=(
        "Canon EF 8-15mm f/4L Fisheye at 10 mm (slr-canon.xml:6999): D(r_max) 1.114 times the "
        "corner"
    ),
)
FOLD_OUTSIDE_IMAGE = Rule(
    "fold-outside-image",
    NOTICE,
    "entry",
    "any other finite r_max",
    "any other finite r_max (only with `--verbose`)",
    "The model folds somewhere beyond the image: harmless for the image, not for projecting "
    "points from outside the field of view.",
    fails=(
        "slr-tokina.xml:18, Tokina 11-16mm at 12 mm, crop 1: D(r_max) = 2.247, 1.247 times the "
        "corner"
    ),
    passes="the same lens at 14 mm (slr-tokina.xml:20): D rises at every radius, r_max infinite",
    verbose=True,
)
NOT_COMPUTABLE = Rule(
    "r-max-not-computable",
    ERROR,
    "entry",
    "r_max could not be computed for an entry that loaded",
    "r_max could not be computed for an entry that loaded",
    "The solver returned no value for coefficients that parsed (a defect of lensaudit's or an "
    "overflow it could not resolve): the entry is not audited.",
    fails=(
        "none known: it guards a defect of the solver, which no Lensfun entry, nor overflowing "
        "coefficients such as a = 1e308, has triggered"
    ),
    passes="every one of the 5,705 entries of lensfunpy's database and 6,430 of Lensfun master",
)
RULES = (FOLD_IN_IMAGE, FOLD_NEAR_IMAGE, FOLD_OUTSIDE_IMAGE, NOT_COMPUTABLE)


def find(context: Context) -> Iterable[tuple[int, Identified]]:
    """The fold finding of each audited distortion entry that has one."""
    for (index, entry), metrics in zip(context.entries, context.metrics, strict=True):
        if entry.status != STATUS_OK or metrics is None:  # None: never folds
            continue
        finding = fold_finding(entry, metrics, context.margin, context.verbose)
        if finding is not None:
            yield index, entry_identified(finding, entry, context.read[index].source.file_name)


def folds_in_image(metrics: Any) -> bool:
    """Whether an entry with these metrics (None: r_max infinite) is ``fold-in-image``."""
    if metrics is None or metrics.problem or metrics.r_max != metrics.r_max:
        return False
    return metrics.r_max == 0 or metrics.r_normalized < 1


def fold_finding(entry: DistortionEntry, m: Any, margin: float, verbose: bool) -> Finding | None:
    """The fold finding of an entry that loaded, given its metrics (r_max,
    d_max, r_corner, r_normalized, problem), or None."""
    if m.problem or m.r_max != m.r_max:
        reason = m.problem or "the solver returned no value"
        rule = NOT_COMPUTABLE
        return entry_finding(
            rule.severity, rule.code, entry, f"r_max could not be computed ({reason})"
        )
    if math.isinf(m.r_max):
        return None
    if m.r_max == 0:
        return entry_finding(
            FOLD_IN_IMAGE.severity,
            FOLD_IN_IMAGE.code,
            entry,
            "D(r) decreases from the image centre (D'(0) <= 0): the model folds back at once",
        )

    image = "image circle" if is_circular_fisheye(entry.lens, entry.type) else "image corner"
    where = (
        f"D(r) peaks at D(r_max) = {m.d_max:.4g} for r_max = {m.r_max:.4g}, "
        f"{m.r_normalized:.3f} times the {image} {m.r_corner:.4g} (Hugin units)"
    )
    if m.r_normalized < 1:
        return entry_finding(
            FOLD_IN_IMAGE.severity,
            FOLD_IN_IMAGE.code,
            entry,
            f"the model folds back inside its own image: {where}; "
            f"undistortion mirrors pixels beyond that radius; {fix_suggestion(entry)}",
        )
    if m.r_normalized < margin:
        return entry_finding(
            FOLD_NEAR_IMAGE.severity,
            FOLD_NEAR_IMAGE.code,
            entry,
            f"the model folds back just outside its image, within the margin {margin:g}: {where}",
        )
    if verbose:
        return entry_finding(
            FOLD_OUTSIDE_IMAGE.severity,
            FOLD_OUTSIDE_IMAGE.code,
            entry,
            f"the model folds back outside its image: {where}",
        )
    return None


#: Longest lens name a suggested command carries; a prefix selects the lens as well.
SUGGESTED_NAME_LIMIT = 100


def fix_suggestion(entry: DistortionEntry) -> str:
    """The ``lensaudit fix`` command that refits this entry, in the file it
    is in (``entry.file``, as the check names it), to paste into a POSIX
    shell as it is printed: shell-quoted (``shlex.quote``), the file after
    ``--`` (a name may start with a dash).

    ``--lens`` matches a part of the name, with runs of white space as one
    space: the command names the lens so (check prints a finding on one
    line), up to the first character a terminal is not shown as it is
    (:data:`lensaudit.formats.UNPRINTABLE`: a control character, a
    bidirectional mark) and at most :data:`SUGGESTED_NAME_LIMIT` characters.
    """
    name = UNPRINTABLE.split(" ".join(entry.lens.split()), maxsplit=1)[0]
    name = name[:SUGGESTED_NAME_LIMIT].strip()
    words = ["lensaudit", "fix", *(["--lens", name] if name else [])]
    words += ["--focal", f"{entry.focal:g}", "--", entry.file]
    return f"`{shlex.join(words)}` refits it"
