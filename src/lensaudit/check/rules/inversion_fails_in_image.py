"""inversion-fails-in-image: where liblensfun's reverse transform cannot
invert an entry's model inside its image (see :mod:`lensaudit.inversion`).

An entry that folds inside its image is ``fold-in-image`` already, and the
fold is the finding: it is not reported twice.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

from ...read.records import STATUS_OK, DistortionEntry
from ..result import Finding, Identified, entry_finding
from . import WARNING, Context, Rule
from ._identity import entry_identified
from .fold import folds_in_image

ORDER = 30

INVERSION_FAILS_IN_IMAGE = Rule(
    "inversion-fails-in-image",
    WARNING,
    "entry",
    "liblensfun's reverse transform cannot invert the model by its Newton steps inside the image",
    "liblensfun's reverse transform (an undistorted image made to look as if shot with the "
    "lens) cannot invert the model by its Newton steps at some radius inside the image, and "
    "sets the pixel to NaN (poly3) or leaves it uncorrected (ptlens, poly5) there; not "
    "reported for an entry that is `fold-in-image` (see "
    "[below](#inversion-liblensfun-cannot-finish))",
    "liblensfun inverts a model by at most six Newton steps from r_d; where they do not "
    "converge to its tolerance, the pixel is lost. The band where that happens is proven, "
    "not sampled.",
    fails=(
        "slr-nikon.xml:4521, AF DX Fisheye-Nikkor 10.5mm f/2.8G ED, crop 1: the Newton steps "
        "fail from r_d = 1.382, 0.766 of the half diagonal"
    ),
    passes=(
        "the same lens at crop 1.523 (slr-nikon.xml:4507): the inversion converges out to 4 "
        "times the half diagonal"
    ),
)
RULES = (INVERSION_FAILS_IN_IMAGE,)


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

    from ... import inversion
    from ...metrics import image_radius, is_circular_fisheye

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
            INVERSION_FAILS_IN_IMAGE.severity,
            INVERSION_FAILS_IN_IMAGE.code,
            entry,
            f"liblensfun's reverse transform cannot invert the model inside the image: "
            f"its Newton steps do not converge at r_d = {found.r_fail[index]:.4g} "
            f"(Hugin units), {found.fraction[index]:.3f} of the {image}, where it "
            f"{_WHAT[outcome]}",
        )
    return findings


def find(context: Context) -> Iterable[tuple[int, Identified]]:
    """The warning of each entry whose inversion fails inside the image, but
    for those that fold inside it (the fold is their finding)."""
    found = inversion_findings([entry for _, entry in context.entries])
    for (index, entry), metrics, finding in zip(
        context.entries, context.metrics, found, strict=True
    ):
        if finding is not None and not folds_in_image(metrics):
            yield index, entry_identified(finding, entry, context.read[index].source.file_name)
