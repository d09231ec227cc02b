"""What a baseline holds, as the duplicate rules place their findings on the
one of two elements a change added (:class:`Known`), and what a lens is made
of (:func:`lens_contents`): its elements other than its untranslated names
and its calibrations (:attr:`lensaudit.read.records.Lens.content`), and its
own calibrations' values."""

from __future__ import annotations

from collections.abc import Sequence

from ..read.cache import content_hasher
from ..read.records import DistortionEntry
from .matching import entry_content, lens_identity, lens_key
from .parsing import ParsedSource


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
