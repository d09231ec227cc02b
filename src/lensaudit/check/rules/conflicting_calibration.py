"""``conflicting-calibration``: within one ``<lens>`` (liblensfun puts every
calibration of a lens into one set, ``lfLens::GetCalibrationSetForAttributes``),
a second ``<distortion>``, ``<tca>`` or ``<vignetting>`` for the same crop
factor and focal length (and aperture and distance, for vignetting) whose
model or coefficients differ from the first one's: liblensfun takes the first
exact match and never sees the other.

Two distortion entries of one calibration (same crop factor and aspect ratio)
are ``duplicate-focal``'s (an error), and two ``<lens>`` elements of one name
and crop factor are ``duplicate-lens``'s (an error when they differ at all):
neither is reported again here.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import replace
from typing import Any

from ...read.records import STATUS_OK
from ...read.tables import SPECS, TCA, VIGNETTING
from ..matching import calibration_content, entry_content, lens_identity
from ..parsing import ParsedSource
from ..result import (
    Finding,
    Identified,
    clip,
    clip_key,
    entry_finding,
    entry_key,
    lens_name,
    none_if_nan,
)
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

DISTORTION = "distortion"


def conflicting_calibrations(file: ParsedSource) -> Iterable[Identified]:
    """Second calibrations of one lens, crop factor and calibration point whose
    model or coefficients differ from the first's, in a file that parsed
    (see the module's docstring for what ``duplicate-focal`` keeps)."""
    if file.problem is not None:
        return
    yield from _conflicting_distortion(file)
    tables = file.tables
    lens_of = {VIGNETTING: tables.lens_of_vignetting, TCA: tables.lens_of_tca}
    for kind, records in file.calibrations.items():
        # Keys from the columns; entry objects only for the repeats (a file has thousands).
        lenses = lens_of[kind] or []
        # Each lens's first calibration of each crop factor and point, kept until
        # its last row (a lens's rows come together: few are kept at once).
        last = {lens: position for position, lens in enumerate(lenses)}
        first: dict[int | None, dict[tuple, int]] = {}
        names = ("focal", "aperture", "distance") if kind == VIGNETTING else ("focal",)
        points = zip(*map(records.each, names), strict=True)
        statuses, crops = records.each("status"), records.each("crop_factor")
        for position, (lens, status, crop, point) in enumerate(
            zip(lenses, statuses, crops, points, strict=False)
        ):
            if lens is None or status != STATUS_OK:
                continue
            own = first.setdefault(lens, {})
            earlier_position = own.setdefault((crop, point), position)
            if last[lens] == position:
                del first[lens]
            if earlier_position == position:
                continue
            entry, earlier = records[position], records[earlier_position]
            if _coefficients(kind, entry) == _coefficients(kind, earlier):
                continue
            content, first_content = calibration_content(entry), calibration_content(earlier)
            yield _conflict(file, kind, entry, earlier.line, point, content, first_content)


#: The coefficients of each kind, by name (the rest of its fields are where it applies).
_COEFFICIENTS = {
    DISTORTION: ("a", "b", "c", "k1", "k2"),
    **{
        kind: tuple(f for f in spec.fields if f not in ("aperture", "distance"))
        for kind, spec in SPECS.items()
    },
}


def _coefficients(kind: str, entry: Any) -> tuple:
    """The model and coefficients of an entry (NaN, a coefficient its model
    does not have, as None)."""
    return (entry.model, *(none_if_nan(getattr(entry, n)) for n in _COEFFICIENTS[kind]))


def _conflicting_distortion(file: ParsedSource) -> Iterable[Identified]:
    seen_calibration: set[tuple] = set()  # what duplicate_focals groups by
    first: dict[tuple, Any] = {}
    for entry, lens in zip(file.entries, file.lens_of_entry, strict=True):
        if lens is None or entry.focal != entry.focal:
            continue
        crop = none_if_nan(entry.crop_factor)
        calibration = (lens, crop, none_if_nan(entry.aspect_ratio), entry.focal)
        if calibration in seen_calibration:
            continue  # a duplicate-focal
        seen_calibration.add(calibration)
        if entry.status != STATUS_OK:
            continue
        earlier = first.setdefault((lens, crop, entry.focal), entry)
        if earlier is entry:
            continue
        if _coefficients(DISTORTION, entry) == _coefficients(DISTORTION, earlier):
            continue
        content, first_content = entry_content(entry), entry_content(earlier)
        yield _conflict(
            file, DISTORTION, entry, earlier.line, (entry.focal,), content, first_content
        )


def _conflict(
    file: ParsedSource,
    kind: str,
    entry: Any,
    first_line: int,
    point: tuple,
    content: tuple,
    first_content: tuple,
) -> Identified:
    rule = CONFLICTING_CALIBRATION
    where = point_text(point)
    text = (
        f"a second <{kind}> for {where} of this lens and crop factor, with another model "
        f"or other coefficients than the one at line {first_line}: liblensfun uses only "
        f"the first; keep the better one"
    )
    if kind == DISTORTION:
        finding = entry_finding(rule.severity, rule.code, entry, text)
    else:
        name = (
            f"{lens_name(entry.maker, entry.lens)} (<{kind}>, {where}, crop {entry.crop_factor:g})"
        )
        finding = Finding(
            rule.severity,
            rule.code,
            entry.file,
            entry.line,
            0,
            clip(f"{name}: {text}"),
            clip_key(entry_key(entry)),
        )
    finding = replace(finding, related=((file.source.display, first_line),))
    # The pair, in either order, of the lens by name; then the pair alone (the
    # lens was renamed); then the lens and the calibration point (one of the
    # pair was edited).
    pair = (rule.severity, rule.code, kind,
            *sorted((content, first_content), key=repr))  # fmt: skip
    lens = lens_identity(entry.maker, entry.lens)
    keys = ((*pair, lens), pair, (rule.severity, rule.code, kind, lens, point))
    return Identified(finding, keys, (file.source.file_name,))


def calibration_name(entry: Any, kind: str, where: str) -> str:
    """A vignetting or TCA entry in words: its lens, element, point and crop factor."""
    return f"{lens_name(entry.maker, entry.lens)} (<{kind}>, {where}, crop {entry.crop_factor:g})"


def point_text(point: tuple) -> str:
    """A calibration point in words: focal length, and aperture and distance."""
    text = f"{point[0]:g} mm"
    if len(point) == 3:
        text += f", f/{point[1]:g}, {point[2]:g} m"
    return text


def find(context: Context) -> Iterable[tuple[int, Identified]]:
    """Each second calibration that contradicts the first, file by file."""
    for index, file in enumerate(context.read):
        for item in conflicting_calibrations(file):
            yield index, item
