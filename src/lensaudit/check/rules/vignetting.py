"""``vignetting-zero-in-image``, ``vignetting-low-in-image``,
``vignetting-brightens``, ``vignetting-not-monotone``: what a ``<vignetting>``
model's correction C(r) = 1 + k1 r^2 + k2 r^4 + k3 r^6 does inside the image
(r = 1 at half the diagonal), from :mod:`lensaudit.vignetting`'s exact audit."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from ... import vignetting as audit
from ...read.tables import VIGNETTING
from ..result import Identified
from . import ERROR, NOTICE, WARNING, Context, Rule
from ._calibrations import calibration_findings, findings_of

ORDER = 40

ZERO_IN_IMAGE = Rule(
    "vignetting-zero-in-image",
    ERROR,
    "entry",
    "C(r) <= 0 inside the image: the correction divides by zero or flips sign",
    "a vignetting model's C(r) = 1 + k1 r² + k2 r⁴ + k3 r⁶ reaches 0 inside the image "
    "(r = 1 at the corner): the correction divides by zero or flips the sign of pixels",
    "liblensfun divides each pixel by C(r): at a zero the gain is infinite, beyond it the "
    "pixel's sign flips. Decided exactly (Sturm sequences over rationals).",
    fails=(
        "compact-canon.xml:1990, PowerShot SX220 HS at 5 mm f/7.9: C(1) = -0.026, zero at r = "
        "0.9966"
    ),
    passes="the same lens at 5 mm f/3.1 (compact-canon.xml:1984): C(1) = 0.0213",
)
LOW_IN_IMAGE = Rule(
    "vignetting-low-in-image",
    WARNING,
    "entry",
    "C(r) < 0.1 inside the image: a gain above 10",
    "C(r) < 0.1 inside the image: a correction gain above 10",
    "A gain above 10 multiplies the noise of those pixels as much.",
    fails=(
        "compact-canon.xml:1984, PowerShot SX220 HS at 5 mm f/3.1: C falls to 0.0213, a gain of "
        "46.9"
    ),
    passes="the same lens at 5.6 mm f/3.2 (compact-canon.xml:1992): C stays above 0.150",
)
BRIGHTENS = Rule(
    "vignetting-brightens",
    WARNING,
    "entry",
    "C(r) > 1.05 inside the image: brighter than the centre, which no lens is",
    "C(r) > 1.05 inside the image: brighter than the centre, which no lens is",
    "Vignetting darkens towards the corners; a model brighter off-centre darkens the image "
    "there when corrected.",
    fails=(
        "compact-canon.xml:2525, PowerShot G1X Mark II at 22.8 mm f/16: C rises to 1.058 at r = "
        "0.935"
    ),
    passes="the same lens at 22.8 mm f/10 (compact-canon.xml:2523): C at most 1.037",
)
NOT_MONOTONE = Rule(
    "vignetting-not-monotone",
    NOTICE,
    "entry",
    "C(r) turns inside the image",
    "C(r) turns inside the image (only with `--verbose`)",
    "A turning brightness model is possible (a mechanical vignetting edge) but unusual.",
    fails="compact-canon.xml:2523, PowerShot G1X Mark II at 22.8 mm f/10: C turns at r = 0.349",
    passes=(
        "the same lens at 15.5 mm f/16 (compact-canon.xml:2515): C falls from 1 to 0.650 at the "
        "corner"
    ),
    verbose=True,
)
RULES = (ZERO_IN_IMAGE, LOW_IN_IMAGE, BRIGHTENS, NOT_MONOTONE)


def find(context: Context) -> Iterable[tuple[int, Identified]]:
    """The findings of every ``<vignetting>`` of the files that parsed."""
    return calibration_findings(context, VIGNETTING, audit, wording)


def findings(records: Iterable[dict[str, Any]]) -> list[tuple]:
    """(severity, code, file, line, message) for each audited record with a
    finding, and an error for each record that could not be audited (except
    whole-file problems, which the distortion check reports once per file).
    ``records`` are dicts as :meth:`lensaudit.vignetting.VignettingAudit.records`
    gives them."""
    return findings_of(records, VIGNETTING, wording)


def wording(record: dict[str, Any]) -> tuple[str, str, str] | None:
    """(severity, code, text) of an audited record, or None."""
    severity = record["severity"]
    if not severity:
        return None
    c_min, r_min, r_corner = record["c_min"], record["r_min"], record["r_corner"]
    where = "the frame corner" if r_corner == 1 else "the image circle"
    at = f"r = {r_min:.3g} (r = 1 at half the diagonal; image to {r_corner:.3g}, {where})"
    if severity == ERROR:
        rule = ZERO_IN_IMAGE
        r_zero = record["r_zero"]
        crossing = (
            f"crossing zero at r = {r_zero:.4g}"
            if r_zero <= r_corner
            else "touching zero without crossing"
        )
        text = (
            f"C(r) = 1 + k1 r^2 + k2 r^4 + k3 r^6 reaches {c_min:.4g} at {at}, "
            f"{crossing}: the correction divides by zero there and flips the sign "
            "of the pixels where C < 0"
        )
    elif severity == WARNING and record["low_in_image"]:
        rule = LOW_IN_IMAGE
        text = (
            f"C(r) falls to {c_min:.4g} at {at}: the correction multiplies those pixels "
            f"(and their noise) by {1 / c_min:.3g}"
        )
    elif severity == WARNING:
        rule = BRIGHTENS
        at = f"r = {record['r_cmax']:.3g} (r = 1 at half the diagonal; image to {r_corner:.3g})"
        text = (
            f"C(r) rises to {record['c_max']:.4g} at {at}: the model has that part of the "
            f"image {record['c_max']:.3g} times as bright as its centre, which no lens is; "
            "the correction darkens it"
        )
    else:
        rule = NOT_MONOTONE
        text = (
            f"C(r) turns at r = {record['r_turn']:.4g}, inside the image "
            f"(to {r_corner:.3g}): the brightness model is not monotone"
        )
    return rule.severity, rule.code, text
