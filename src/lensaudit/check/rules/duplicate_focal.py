"""``duplicate-focal``: a second ``<distortion>`` for one focal length of a
calibration (the entries of one ``<lens>`` with the same crop factor and
aspect ratio, those a ``<calibration>`` element may override). An error, or
a warning when the two are identical, since liblensfun then loses nothing
by keeping one of them.

A duplicate is reported on the second of the two in reading order, naming
the first; with a baseline (:class:`~lensaudit.check.known.Known`), on the
one the change added, so that it points at what the change touched.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import replace

from ...read.records import DistortionEntry
from ..known import Known
from ..matching import entry_content, lens_identity
from ..parsing import ParsedSource
from ..result import Identified, entry_finding, none_if_nan
from . import ERROR, WARNING, Context, Rule

ORDER = 60

DUPLICATE_FOCAL = Rule(
    "duplicate-focal",
    ERROR,
    "entry",
    "two distortion entries for one focal length of one calibration",
    "a second `<distortion>` for the same focal length in one calibration (one lens, one crop "
    "factor and aspect ratio); a warning when the two entries have the same values "
    "(liblensfun keeps one of two equal things)",
    "liblensfun keeps one of the two, so the other's values are lost to every program; with "
    "a baseline, the finding goes on the one of the two the change added.",
    fails=(
        "compact-panasonic.xml:681, Leica DMC-FZ28 (Standard) at 8.2 mm: a second entry with "
        "other a, b, c than line 680"
    ),
    passes=(
        "the same lens at 6.9 mm (compact-panasonic.xml:679): the same coefficients as at 6.1 "
        "mm, at another focal length"
    ),
    lesser="when the two entries have the same values",
    lesser_severity=WARNING,
)
RULES = (DUPLICATE_FOCAL,)


def duplicate_focals(
    read: Sequence[ParsedSource], known: Known | None = None
) -> Iterable[tuple[int, Identified]]:
    """A second ``<distortion>`` for a focal length of the same calibration.

    A calibration is the entries of one ``<lens>`` with the same crop factor
    and aspect ratio (those a ``<calibration>`` element may override). The
    finding is an error, or a warning when the two entries are identical; it
    is on the one of the two ``known`` does not have, if only one.
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
            if known is not None and content != first_content:
                name = lens_identity(entry.maker, entry.lens)
                if known.has_entry(name, content) and not known.has_entry(name, first_content):
                    # The change added the first: the finding goes there.
                    entry, earlier = earlier, entry
                    first_line, first_content, content = earlier.line, content, first_content
            if content == first_content:
                severity = DUPLICATE_FOCAL.lesser_severity
                text = (
                    f"a second distortion entry for {entry.focal:g} mm in the same "
                    f"calibration, identical to the one at line {first_line}: one of "
                    f"them can go"
                )
            else:
                severity = DUPLICATE_FOCAL.severity
                which = "first" if first_line < entry.line else "other"
                text = (
                    f"a second distortion entry for {entry.focal:g} mm in the same "
                    f"calibration (the {which} is at line {first_line}); liblensfun keeps "
                    f"only one of them"
                )
            finding = replace(
                entry_finding(severity, DUPLICATE_FOCAL.code, entry, text),
                related=((file.source.display, first_line),),
            )
            # The pair, in either order (a reordering may swap which comes
            # first), of the lens by name; then the pair alone, when the lens
            # was renamed; then the lens and focal length, when one of the
            # pair or the lens's crop factor or aspect ratio was edited.
            pair = (severity, DUPLICATE_FOCAL.code, *sorted((content, first_content), key=repr))
            lens_name = lens_identity(entry.maker, entry.lens)
            keys = (
                (*pair, lens_name),
                pair,
                (severity, DUPLICATE_FOCAL.code, lens_name, entry.focal),
            )
            yield index, Identified(finding, keys, (file.source.file_name,))


def find(context: Context) -> Iterable[tuple[int, Identified]]:
    """Each second entry for a focal length of a calibration."""
    return duplicate_focals(context.read, context.known)
