"""``inversion-fails-in-image``: where liblensfun's reverse transform cannot
invert a distortion model inside the image (see :mod:`lensaudit.check.inversion`)."""

from __future__ import annotations

from collections.abc import Iterable

from ..inversion import inversion_findings
from ..result import Identified
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


def find(context: Context) -> Iterable[tuple[int, Identified]]:
    """The warning of each entry whose inversion fails inside the image, but
    for those that fold inside it (the fold is their finding)."""
    found = inversion_findings([entry for _, entry in context.entries])
    for (index, entry), metrics, finding in zip(
        context.entries, context.metrics, found, strict=True
    ):
        if finding is not None and not folds_in_image(metrics):
            yield index, entry_identified(finding, entry, context.read[index].source.file_name)
