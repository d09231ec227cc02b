"""inversion-fails-in-image: where liblensfun's reverse transform cannot
invert an entry's model inside its image (see :mod:`lensaudit.inversion`).

An entry that folds inside its image is ``fold-in-image`` already, and the
fold is the finding: it is not reported twice.
"""

from __future__ import annotations

from collections.abc import Sequence

from ..read.records import STATUS_OK, DistortionEntry
from .result import INVERSION_FAILS_IN_IMAGE, SEVERITY_WARNING, Finding, entry_finding

_WHAT = {
    "NaN": "sets the pixel to NaN",
    "uncorrected": "leaves the pixel where it is, undistorted",
}


def inversion_findings(entries: Sequence[DistortionEntry]) -> list[Finding | None]:
    """One finding or None per entry: a warning where liblensfun's Newton
    inversion fails inside the image, naming the first distorted radius it
    fails at as a fraction of the half diagonal (the image corner; a circular
    fisheye's image circle) and what liblensfun does there."""
    import numpy as np  # numpy: only where arrays are needed, not on importing this module

    from .. import inversion
    from ..metrics import image_radius, is_circular_fisheye

    if not entries:
        return []
    column = {
        name: [getattr(e, name) for e in entries]
        for name in ("model", "a", "b", "c", "k1", "k2", "focal", "real_focal")
        + ("crop_factor", "aspect_ratio")
    }
    with np.errstate(all="ignore"):  # a bad value is another rule's finding, not a warning
        model = inversion.liblensfun_model(*column.values())
        model.kind[np.array([e.status != STATUS_OK for e in entries])] = -1
        circular = [is_circular_fisheye(e.lens, e.type) for e in entries]
        corner = image_radius(np.array(column["aspect_ratio"], dtype=np.float64), circular)
        found = inversion.inversion_failures(model, corner)
    findings: list[Finding | None] = [None] * len(entries)
    for index in np.flatnonzero(found.fails).tolist():
        entry = entries[index]
        image = "image circle" if circular[index] else "half diagonal"
        outcome = inversion.OUTCOME_NAMES[int(found.outcome[index])]
        findings[index] = entry_finding(
            SEVERITY_WARNING,
            INVERSION_FAILS_IN_IMAGE,
            entry,
            f"liblensfun's reverse transform cannot invert the model inside the image: "
            f"its Newton steps do not converge at r_d = {found.r_fail[index]:.4g} "
            f"(Hugin units), {found.fraction[index]:.3f} of the {image}, where it "
            f"{_WHAT[outcome]}",
        )
    return findings
