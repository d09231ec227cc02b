"""Duplicates: a lens defined twice, and two ``<distortion>`` entries for one
focal length of a calibration. Errors, or warnings when the two are
identical, since liblensfun then loses nothing by keeping one of them.

A duplicate is reported on the second of the two in reading order, naming
the first; with a baseline (:class:`Known`), on the one the change added:
when the baseline has the second and not the first (a new lens written
above an old one), the finding is on the first, naming the second, so that
it points at what the change touched.

What a lens is made of comes from the reader: its elements other than its
untranslated names and its calibrations (:attr:`lensaudit.read.records.Lens.content`),
and its own distortion entries' values (:func:`lens_contents`).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import replace

from ..read.cache import content_hasher
from ..read.records import DistortionEntry
from .matching import entry_content, lens_identity, lens_key
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
)


class Known:
    """What a baseline holds, as the duplicate rules place their findings:
    its lenses (name key and :func:`lens_contents`) and its distortion
    entries (lens by name and :func:`entry_content`). Worked out only when a
    duplicate asks, and then only for the lenses of its name: a database has
    thousands of entries, and hardly a duplicate."""

    def __init__(self, read: Sequence[ParsedSource] = ()) -> None:
        self._read = [file for file in read if file.problem is None]
        self._entries: dict[tuple, list[DistortionEntry]] | None = None
        self._lenses: dict[tuple, list[tuple[ParsedSource, int]]] | None = None
        self._contents: dict[int, list[bytes]] = {}

    def has_entry(self, name: tuple, content: tuple) -> bool:
        """Whether the baseline has a distortion entry of this content for a
        lens of this name (:func:`~.matching.lens_identity`)."""
        if self._entries is None:
            self._entries = {}
            for file in self._read:
                for entry in file.entries:
                    key = lens_identity(entry.maker, entry.lens)
                    self._entries.setdefault(key, []).append(entry)
        return any(entry_content(entry) == content for entry in self._entries.get(name, ()))

    def has_lens(self, key: tuple, content: bytes) -> bool:
        """Whether the baseline has a lens of this name key with this content."""
        if self._lenses is None:
            self._lenses = {}
            for file in self._read:
                for lens in file.lenses:
                    self._lenses.setdefault(lens_key(lens), []).append((file, lens.index))
        for file, index in self._lenses.get(key, ()):
            if id(file) not in self._contents:
                self._contents[id(file)] = lens_contents(file)
            if self._contents[id(file)][index] == content:
                return True
        return False


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
                severity = SEVERITY_WARNING
                text = (
                    f"a second distortion entry for {entry.focal:g} mm in the same "
                    f"calibration, identical to the one at line {first_line}: one of "
                    f"them can go"
                )
            else:
                severity = SEVERITY_ERROR
                which = "first" if first_line < entry.line else "other"
                text = (
                    f"a second distortion entry for {entry.focal:g} mm in the same "
                    f"calibration (the {which} is at line {first_line}); liblensfun keeps "
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
                severity = SEVERITY_WARNING
                text = f"lens {name} ({crop}) is defined identically at {where}: one can go"
            else:
                severity = SEVERITY_ERROR
                also = "already" if there is earlier else "also"
                text = (
                    f"lens {name} ({crop}) is {also} defined at {where}; "
                    f"liblensfun keeps only one of them"
                )
            finding = Finding(
                severity,
                DUPLICATE_LENS,
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
                DUPLICATE_LENS,
                lens.crop_factor,
                *sorted((content, first_content), key=repr),
            )
            keys = ((*pair, key), pair, (severity, DUPLICATE_LENS, key))
            names = (here_file.source.file_name, there_file.source.file_name)
            yield here_index, Identified(finding, keys, names)


def lens_contents(file: ParsedSource) -> list[bytes]:
    """What each lens of a file is made of, in order, as a digest: its
    elements other than its untranslated names and its calibrations, the
    values of its own distortion entries
    (:func:`~lensaudit.check.matching.entry_content`: without names or
    lines), and those of its vignetting and TCA entries (without their lines
    and names), each in document order. Two lenses made of the same values
    have the same digest, and (but for a BLAKE2b collision) no others: a
    digest costs 16 bytes where the values would cost the file's size again,
    in a database whose lenses are all duplicated."""
    tables = file.tables
    made = [content_hasher(_text(lens.content)) for lens in file.lenses]
    for entry, lens in zip(file.entries, file.lens_of_entry, strict=True):
        if lens is not None:
            made[lens].update(b"d" + _text(entry_content(entry)))
    for kind, rows, lenses in ((b"v", tables.vignetting, tables.lens_of_vignetting),
                               (b"t", tables.tca, tables.lens_of_tca)):  # fmt: skip
        for row, lens in zip(rows or (), lenses or (), strict=True):
            if lens is not None:  # without line, maker and lens
                made[lens].update(kind + _text(row[3:]))
    return [hasher.digest() for hasher in made]


def _text(values: tuple) -> bytes:
    """``values`` as bytes that no other values give, their length first. Floats
    are written as they compare: NaN (a field left out) as None, -0.0 as 0.0."""
    text = repr(
        tuple(None if v != v else v + 0.0 if v.__class__ is float else v for v in values)
    ).encode()
    return b"%d:%s" % (len(text), text)
