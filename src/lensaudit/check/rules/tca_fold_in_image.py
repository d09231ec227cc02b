"""``tca-fold-in-image``: a ``<tca>`` colour channel whose radial scaling
folds inside the image, from :mod:`lensaudit.tca`'s exact audit."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from ... import tca as audit
from ...read.tables import TCA
from ..result import Identified
from . import ERROR, Context, Rule
from ._calibrations import calibration_findings, findings_of

ORDER = 50

TCA_FOLD_IN_IMAGE = Rule(
    "tca-fold-in-image",
    ERROR,
    "entry",
    "a colour channel folds inside the image",
    "a colour channel's radial scaling r (b r² + c r + v) folds inside the image",
    "liblensfun scales the red and blue channels radially; a scaling that folds maps two "
    "radii onto one and mirrors the channel beyond.",
    fails=(
        "the PowerShot A640's <tca> br=-0.0002379 with three zeros lost (br=-0.2379): the red "
        "channel peaks at r = 1.184 of 1.667 (no Lensfun entry folds)"
    ),
    passes=(
        "compact-canon.xml:2211, the A640's <tca> as written: the red channel folds at 37.4, 22 "
        "times its corner"
    ),
)
RULES = (TCA_FOLD_IN_IMAGE,)


def find(context: Context) -> Iterable[tuple[int, Identified]]:
    """The findings of every ``<tca>`` of the files that parsed."""
    return calibration_findings(context, TCA, audit, wording)


def findings(records: Iterable[dict[str, Any]]) -> list[tuple]:
    """(severity, code, file, line, message) for each audited record that
    folds inside its image, and an error for each record that could not be
    audited (whole-file problems are left to the file's own finding).
    ``records`` are dicts as :meth:`lensaudit.tca.TCAAudit.records` gives them."""
    return findings_of(records, TCA, wording)


def wording(record: dict[str, Any]) -> tuple[str, str, str] | None:
    """(severity, code, text) of an audited record, or None."""
    if not record["folds_in_image"]:
        return None
    r_corner = record["r_corner"]
    parts = []
    for channel in audit.CHANNELS:
        radius = record[f"r_fold_{channel}"]
        if radius == 0:
            parts.append(f"the {channel} channel's r_d decreases from the centre")
        elif radius < r_corner:
            parts.append(f"the {channel} channel's r_d peaks at r = {radius:.4g}")
    text = (
        f"{' and '.join(parts)}, inside the image (to r = {r_corner:.4g}, Hugin units): "
        "the correction maps two radii onto one and mirrors that channel beyond"
    )
    return TCA_FOLD_IN_IMAGE.severity, TCA_FOLD_IN_IMAGE.code, text
