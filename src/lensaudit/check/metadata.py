"""Metadata Lensfun's own CI does not check (its ``check_database.py`` runs
xmllint against the schema and looks for duplicate keys only): calibrations
that contradict each other, and vignetting left at the calibration script's
starting values. Both are warnings.

- ``conflicting-calibration``: within one ``<lens>`` (liblensfun puts every
  calibration of a lens into one set, ``lfLens::GetCalibrationSetForAttributes``),
  a second ``<distortion>``, ``<tca>`` or ``<vignetting>`` for the same crop
  factor and focal length (and aperture and distance, for vignetting) whose
  model or coefficients differ from the first one's: liblensfun takes the
  first exact match and never sees the other. Two distortion entries of one
  calibration (same crop factor and aspect ratio) are ``duplicate-focal``'s
  (an error), and two ``<lens>`` elements of one name and crop factor are
  ``duplicate-lens``'s (an error when they differ at all): neither is
  reported again here.
- ``vignetting-starting-values``: a ``<vignetting>`` whose k1, k2 and k3 are
  exactly -0.3, 0 and 0, the values ``tools/calibrate/calibrate.py`` starts
  its fit from, left when the fit fails.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import replace
from typing import Any

from ..read.records import STATUS_OK
from ..read.tables import SPECS, TCA, VIGNETTING
from .matching import calibration_content, entry_content, lens_identity
from .parsing import ParsedSource
from .result import (
    CONFLICTING_CALIBRATION,
    SEVERITY_WARNING,
    VIGNETTING_STARTING_VALUES,
    Finding,
    Identified,
    clip,
    clip_key,
    entry_finding,
    entry_key,
    lens_name,
    none_if_nan,
)

#: k1, k2, k3 that ``tools/calibrate/calibrate.py`` starts its vignetting fit from.
STARTING_VALUES = (-0.3, 0.0, 0.0)

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
        first: dict[tuple, Any] = {}
        statuses = records.column("status")
        for position, lens in enumerate(lens_of[kind] or ()):
            if lens is None or statuses[position] != STATUS_OK:
                continue
            entry = records[position]
            point = (
                (entry.focal, entry.aperture, entry.distance)
                if kind == VIGNETTING
                else (entry.focal,)
            )
            earlier = first.setdefault((lens, entry.crop_factor, point), entry)
            if earlier is entry:
                continue
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
    where = _point(point)
    text = (
        f"a second <{kind}> for {where} of this lens and crop factor, with another model "
        f"or other coefficients than the one at line {first_line}: liblensfun uses only "
        f"the first; keep the better one"
    )
    if kind == DISTORTION:
        finding = entry_finding(SEVERITY_WARNING, CONFLICTING_CALIBRATION, entry, text)
    else:
        name = (
            f"{lens_name(entry.maker, entry.lens)} (<{kind}>, {where}, crop {entry.crop_factor:g})"
        )
        finding = Finding(
            SEVERITY_WARNING,
            CONFLICTING_CALIBRATION,
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
    pair = (SEVERITY_WARNING, CONFLICTING_CALIBRATION, kind,
            *sorted((content, first_content), key=repr))  # fmt: skip
    lens = lens_identity(entry.maker, entry.lens)
    keys = ((*pair, lens), pair, (SEVERITY_WARNING, CONFLICTING_CALIBRATION, kind, lens, point))
    return Identified(finding, keys, (file.source.file_name,))


def _calibration_name(entry: Any, kind: str, where: str) -> str:
    """A vignetting or TCA entry in words: its lens, element, point and crop factor."""
    return f"{lens_name(entry.maker, entry.lens)} (<{kind}>, {where}, crop {entry.crop_factor:g})"


def _point(point: tuple) -> str:
    """A calibration point in words: focal length, and aperture and distance."""
    text = f"{point[0]:g} mm"
    if len(point) == 3:
        text += f", f/{point[1]:g}, {point[2]:g} m"
    return text


def starting_values(file: ParsedSource) -> Iterable[Identified]:
    """Each ``<vignetting>`` of a file that parsed whose k1, k2, k3 are the
    calibration script's starting values, -0.3, 0 and 0, exactly."""
    if file.problem is not None or VIGNETTING not in file.calibrations:
        return
    records = file.calibrations[VIGNETTING]
    columns = zip(*map(records.column, ("status", "k1", "k2", "k3")), strict=True)
    for position, (status, *coefficients) in enumerate(columns):
        if status != STATUS_OK or tuple(coefficients) != STARTING_VALUES:
            continue
        entry = records[position]
        where = _point((entry.focal, entry.aperture, entry.distance))
        name = _calibration_name(entry, VIGNETTING, where)
        text = (
            "k1=-0.3, k2=0, k3=0 are the values Lensfun's calibration script "
            "(tools/calibrate/calibrate.py) starts its fit from, left when the fit fails: "
            "this entry measures nothing; calibrate it again or remove it"
        )
        finding = Finding(
            SEVERITY_WARNING,
            VIGNETTING_STARTING_VALUES,
            entry.file,
            entry.line,
            0,
            clip(f"{name}: {text}"),
            clip_key(entry_key(entry)),
        )
        content = (SEVERITY_WARNING, VIGNETTING_STARTING_VALUES, calibration_content(entry))
        keys = ((*content, lens_identity(entry.maker, entry.lens)), content)
        yield Identified(finding, keys, (file.source.file_name,))


__all__ = [
    "STARTING_VALUES",
    "conflicting_calibrations",
    "starting_values",
]
