"""``duplicate-lens``: a ``<lens>`` with the maker, model and crop factor of
an earlier one, in any file of the database (names compared ignoring case
and runs of white space). An error, or a warning when the two definitions
are the same but for the case and spacing of names and for comments
(:func:`~lensaudit.check.known.lens_contents`).

The finding is on the second of the two in reading order, naming the first;
with a baseline, on the one the change added (a new lens written above an
old one), so that it points at what the change touched.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

from ..known import Known, lens_contents
from ..matching import lens_key
from ..parsing import LensRecord, ParsedSource
from ..result import Finding, Identified, clip, clip_key, lens_name
from . import ERROR, WARNING, Context, Rule

ORDER = 110
ACROSS_FILES = True

DUPLICATE_LENS = Rule(
    "duplicate-lens",
    ERROR,
    "lens",
    "a lens defined twice (maker, model, crop factor)",
    "a `<lens>` with the maker, model and crop factor of an earlier one, in any file (names "
    "compared ignoring case and runs of white space); a warning when the two definitions are "
    "the same but for the case and spacing of names and for comments",
    "liblensfun finds one of the two by name and never the other's calibrations.",
    fails=(
        "slr-sigma.xml:405 before Lensfun e85c5bc: Sigma 18-200mm f/3.5-6.3 DC, crop 1.53, "
        "defined again after line 384"
    ),
    passes=(
        "the two Tokina 11-16mm of slr-tokina.xml, crop factors 1 and 1.53: two calibrations, "
        "not duplicates"
    ),
    lesser="when the two definitions are the same but for the case and spacing of names",
    lesser_severity=WARNING,
)
RULES = (DUPLICATE_LENS,)


def duplicate_lenses(
    read: Sequence[ParsedSource], known: Known | None = None
) -> Iterable[tuple[int, Identified]]:
    """A ``<lens>`` whose maker, model and crop factor an earlier one has, in any file.

    An error, or a warning when the two lenses are identical but for the
    case and spacing of their names; on the one of the two ``known`` does
    not have, if only one.
    """
    first: dict[tuple, tuple[int, ParsedSource, LensRecord]] = {}
    # Contents for duplicates only: they are rare.
    contents: dict[int, list[bytes]] = {}  # the contents of a file's lenses, by id(file)

    def content_of(file: ParsedSource, lens: LensRecord) -> bytes:
        if id(file) not in contents:
            contents[id(file)] = lens_contents(file)
        return contents[id(file)][lens.index]

    for index, file in enumerate(read):
        if file.problem is not None:
            continue
        for lens in file.lenses:
            key = lens_key(lens)
            earlier_index, earlier_file, earlier = first.setdefault(key, (index, file, lens))
            if earlier is lens:
                continue
            content = content_of(file, lens)
            first_content = content_of(earlier_file, earlier)
            here_index, here_file, here = index, file, lens
            there_file, there = earlier_file, earlier
            if (
                known is not None
                and known.has_lens(key, content)
                and not known.has_lens(key, first_content)
            ):
                # The change added the first: the finding goes there.
                here_index, here_file, here = earlier_index, earlier_file, earlier
                there_file, there = file, lens
            where = f"{there_file.source.display}:{there.line}"
            crop = (
                f"crop factor {lens.crop_factor:g}"
                if isinstance(lens.crop_factor, float)
                else "no crop factor"
                if lens.crop_factor is None
                else f"crop factor {clip(lens.crop_factor, 20)!r}"
            )
            name = lens_name(here.maker, here.model)
            if content == first_content:
                severity = DUPLICATE_LENS.lesser_severity
                text = f"lens {name} ({crop}) is defined identically at {where}: one can go"
            else:
                severity = DUPLICATE_LENS.severity
                also = "already" if there is earlier else "also"
                text = (
                    f"lens {name} ({crop}) is {also} defined at {where}; "
                    f"liblensfun keeps only one of them"
                )
            finding = Finding(
                severity,
                DUPLICATE_LENS.code,
                here_file.source.display,
                here.line,
                0,
                clip(text),
                clip_key((here.maker, here.model, here.crop_factor)),
                related=((there_file.source.display, there.line),),
            )
            # The name and the pair of lenses, in either order; then the pair
            # alone, when both were renamed; then the name alone, when one of
            # the pair was edited.
            pair = (
                severity,
                DUPLICATE_LENS.code,
                lens.crop_factor,
                *sorted((content, first_content), key=repr),
            )
            keys = ((*pair, key), pair, (severity, DUPLICATE_LENS.code, key))
            names = (here_file.source.file_name, there_file.source.file_name)
            yield here_index, Identified(finding, keys, names)


def find(context: Context) -> Iterable[tuple[int, Identified]]:
    """Each second definition of a lens, in any file of the database."""
    return duplicate_lenses(context.read, context.known)
