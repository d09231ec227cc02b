"""Duplicates: a lens defined twice, and two ``<distortion>`` entries for one
focal length of a calibration. Errors, or warnings when the two are
identical, since liblensfun then loses nothing by keeping one of them.

What a lens is made of comes from the reader: its elements other than its
untranslated names and its calibrations (:attr:`lensaudit.read.records.Lens.content`),
and its own distortion entries' values (:func:`lens_contents`).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import replace

from ..read.records import DistortionEntry
from .matching import entry_content, lens_identity
from .parsing import LensRecord, ParsedSource
from .result import (
    DUPLICATE_FOCAL,
    DUPLICATE_LENS,
    SEVERITY_ERROR,
    SEVERITY_WARNING,
    Finding,
    Identified,
    clip,
    clip_key,
    entry_finding,
    lens_name,
    none_if_nan,
    normalized_name,
)


def duplicate_focals(read: Sequence[ParsedSource]) -> Iterable[tuple[int, Identified]]:
    """A second ``<distortion>`` for a focal length of the same calibration.

    A calibration is the entries of one ``<lens>`` with the same crop factor
    and aspect ratio (those a ``<calibration>`` element may override). The
    finding is an error, or a warning when the two entries are identical.
    """
    for index, file in enumerate(read):
        if file.problem is not None:
            continue
        first: dict[tuple, DistortionEntry] = {}
        for entry, lens in zip(file.entries, file.lens_of_entry, strict=True):
            if lens is None or entry.focal != entry.focal:
                continue
            calibration = (
                lens,
                none_if_nan(entry.crop_factor),
                none_if_nan(entry.aspect_ratio),
                entry.focal,
            )
            earlier = first.setdefault(calibration, entry)
            if earlier is entry:
                continue
            # Contents only for duplicates: a database has thousands of entries.
            first_line, first_content = earlier.line, entry_content(earlier)
            content = entry_content(entry)
            if content == first_content:
                severity = SEVERITY_WARNING
                text = (
                    f"a second distortion entry for {entry.focal:g} mm in the same "
                    f"calibration, identical to the one at line {first_line}: one of "
                    f"them can go"
                )
            else:
                severity = SEVERITY_ERROR
                text = (
                    f"a second distortion entry for {entry.focal:g} mm in the same "
                    f"calibration (the first is at line {first_line}); liblensfun keeps "
                    f"only one of them"
                )
            finding = replace(
                entry_finding(severity, DUPLICATE_FOCAL, entry, text),
                related=((file.source.display, first_line),),
            )
            # The pair, in either order (a reordering may swap which comes
            # first), of the lens by name; then the pair alone, when the lens
            # was renamed; then the lens and focal length, when one of the
            # pair or the lens's crop factor or aspect ratio was edited.
            pair = (severity, DUPLICATE_FOCAL, *sorted((content, first_content), key=repr))
            lens_name = lens_identity(entry.maker, entry.lens)
            keys = ((*pair, lens_name), pair, (severity, DUPLICATE_FOCAL, lens_name, entry.focal))
            yield index, Identified(finding, keys, (file.source.file_name,))


def duplicate_lenses(read: Sequence[ParsedSource]) -> Iterable[tuple[int, Identified]]:
    """A ``<lens>`` whose maker, model and crop factor an earlier one has, in any file.

    An error, or a warning when the two lenses are identical but for the
    case and spacing of their names.
    """
    first: dict[tuple, tuple[ParsedSource, LensRecord]] = {}
    # Contents for duplicates only: they are rare.
    contents: dict[int, list[tuple]] = {}  # the contents of a file's lenses, by id(file)

    def content_of(file: ParsedSource, lens: LensRecord) -> tuple:
        if id(file) not in contents:
            contents[id(file)] = lens_contents(file)
        return contents[id(file)][lens.index]

    for index, file in enumerate(read):
        if file.problem is not None:
            continue
        for lens in file.lenses:
            key = (normalized_name(lens.maker), normalized_name(lens.model), lens.crop_factor)
            earlier_file, earlier = first.setdefault(key, (file, lens))
            if earlier is lens:
                continue
            content = content_of(file, lens)
            where = f"{earlier_file.source.display}:{earlier.line}"
            crop = (
                f"crop factor {lens.crop_factor:g}"
                if isinstance(lens.crop_factor, float)
                else "no crop factor"
                if lens.crop_factor is None
                else f"crop factor {clip(lens.crop_factor, 20)!r}"
            )
            name = lens_name(lens.maker, lens.model)
            if content == content_of(earlier_file, earlier):
                severity = SEVERITY_WARNING
                text = f"lens {name} ({crop}) is defined identically at {where}: one can go"
            else:
                severity = SEVERITY_ERROR
                text = (
                    f"lens {name} ({crop}) is already defined at {where}; "
                    f"liblensfun keeps only one of them"
                )
            finding = Finding(
                severity,
                DUPLICATE_LENS,
                file.source.display,
                lens.line,
                0,
                clip(text),
                clip_key((lens.maker, lens.model, lens.crop_factor)),
                related=((earlier_file.source.display, earlier.line),),
            )
            # The name and the pair of lenses, in either order; then the pair
            # alone, when both were renamed; then the name alone, when one of
            # the pair was edited.
            pair = (
                severity,
                DUPLICATE_LENS,
                lens.crop_factor,
                *sorted((content, content_of(earlier_file, earlier)), key=repr),
            )
            keys = ((*pair, key), pair, (severity, DUPLICATE_LENS, key))
            names = (file.source.file_name, earlier_file.source.file_name)
            yield index, Identified(finding, keys, names)


def lens_contents(file: ParsedSource) -> list[tuple]:
    """What each lens of a file is made of, in order: its elements other than
    its untranslated names and its calibrations, the values of its own
    distortion entries (:func:`~lensaudit.check.matching.entry_content`:
    without names or lines), and those of its vignetting and TCA entries
    (without their lines and names), each in document order."""
    tables = file.tables
    entries: list[list[tuple]] = [[] for _ in file.lenses]
    for entry, lens in zip(file.entries, file.lens_of_entry, strict=True):
        if lens is not None:
            entries[lens].append(entry_content(entry))
    calibrations: list[list[tuple]] = [[] for _ in file.lenses]
    for rows, lenses in ((tables.vignetting, tables.lens_of_vignetting),
                         (tables.tca, tables.lens_of_tca)):  # fmt: skip
        for row, lens in zip(rows or (), lenses or (), strict=True):
            if lens is not None:
                calibrations[lens].append(row[3:])  # without line, maker and lens
    return [
        (lens.content, tuple(own), tuple(more))
        for lens, own, more in zip(file.lenses, entries, calibrations, strict=True)
    ]
