"""Parsing the sources: each file read once by :mod:`lensaudit.read`, and its
tables (:class:`~lensaudit.read.FileTables`) made into what the rules need:
the file-level finding, the distortion entries with the lens of each, the
lenses, and the ``<vignetting>`` and ``<tca>`` records."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property

from .. import read as reader
from ..read.cache import content_digest
from ..read.records import (
    STATUS_OK,
    DistortionEntry,
    FileTables,
    Lens,
    parse_number,
)
from ..read.tables import KINDS, TCA, VIGNETTING
from .inputs import Source
from .result import Finding, clip
from .rules.file_errors import STATUS_RULES as FILE_STATUS_RULES
from .rules.file_errors import UNREADABLE

# typing only for type checkers: parsing needs no numpy (the audits do)
TYPE_CHECKING = False
if TYPE_CHECKING:
    from ..calibrations import CalibrationRecords


@dataclass(frozen=True)
class LensRecord:
    """A ``<lens>`` as the duplicate rules see it: where it is, its untranslated
    names and its crop factor (the key), which of its file's lenses it is, and
    its ``content`` (:attr:`lensaudit.read.records.Lens.content`)."""

    line: int
    maker: str
    model: str
    crop_factor: float | str | None  # the number, the text if not a number, None if absent
    index: int = field(default=0, compare=False)  # among the lenses of its file
    content: tuple = field(default=(), compare=False, repr=False)


def crop_factor_key(crop_text: str | None) -> float | str | None:
    """A ``<cropfactor>`` as the duplicate rules compare it: None without one,
    the number where it is one, else the text as written."""
    if crop_text is None:
        return None
    try:
        value = parse_number(crop_text)
    except ValueError:
        return crop_text
    return crop_text if value != value else value  # NaN would never equal itself as a key


def lens_record(lens: Lens, index: int) -> LensRecord:
    """The :class:`LensRecord` of the reader's ``index``-th lens of a file."""
    return LensRecord(
        lens.line, lens.maker, lens.model, crop_factor_key(lens.crop_text), index, lens.content
    )


@dataclass(eq=False)
class ParsedSource:
    """One file as the reader read it (``tables``), and its file-level finding
    (``problem``, None for a database that parsed).

    A file with a file-level problem starts its distortion rows with one that
    stands for the file; :attr:`entries` and :attr:`lens_of_entry` leave it
    out, so that they hold one item per ``<distortion>`` element found, as
    :attr:`count` counts them (for a file that is not well-formed, those
    libxml2's recovery mode still finds). ``digest`` is the digest of its
    bytes (b"" for a file that could not be read), ``size`` their number.
    """

    source: Source
    tables: FileTables
    problem: Finding | None = None
    digest: bytes = b""
    size: int = 0

    @property
    def count(self) -> int:
        """The number of ``<distortion>`` elements found in the file."""
        return self.tables.elements

    @property
    def problem_text(self) -> str:
        """The file's problem without its position ("" if none), to match baselines."""
        return self.tables.problem

    @property
    def _first(self) -> int:
        """Where the rows of the file's elements start: after the file's own row."""
        return int(self.tables.status != STATUS_OK)

    @cached_property
    def entries(self) -> list[DistortionEntry]:
        """Its distortion records, one per ``<distortion>`` element."""
        display = self.source.display
        return [DistortionEntry(display, *row) for row in self.tables.distortion[self._first :]]

    @cached_property
    def lens_of_entry(self) -> list[int | None]:
        """Index into :attr:`lenses` of each of :attr:`entries` (None outside a lens)."""
        return self.tables.lens_of_row[self._first :]

    @cached_property
    def lenses(self) -> tuple[LensRecord, ...]:
        """Its ``<lens>`` elements, in document order."""
        return tuple(lens_record(lens, index) for index, lens in enumerate(self.tables.lenses))

    @cached_property
    def calibrations(self) -> dict[str, CalibrationRecords]:
        """``<vignetting>`` and ``<tca>`` records of a file that parsed, by kind."""
        from ..calibrations import CalibrationRecords  # numpy: not needed to parse

        if self.problem is not None:
            return {}
        display = self.source.display
        rows = {VIGNETTING: self.tables.vignetting, TCA: self.tables.tca}
        return {kind: CalibrationRecords.of_file(kind, display, rows[kind] or []) for kind in KINDS}


def file_finding(tables: FileTables, display: str) -> Finding | None:
    """The error about a whole file (not well-formed, not a database, not
    readable) from its tables, or None for a database that parsed."""
    rule = FILE_STATUS_RULES.get(tables.status)
    if rule is None:
        return None
    message = f"{display}: {tables.error}" if rule is UNREADABLE else clip(tables.error)
    return Finding(rule.severity, rule.code, display, tables.line, tables.column, message)


def parse_sources(
    sources: Sequence[Source],
    cache: reader.Cache | None = None,
    parsed: Sequence[ParsedSource] = (),
    meanwhile: Callable[[], object] | None = None,
) -> list[ParsedSource]:
    """Every source read by :func:`lensaudit.read.read_contents`, on every core
    where that pays, with its vignetting and TCA rows; with a ``cache``,
    contents it has met are not parsed again. A source without data (it
    could not be read) is a file of status ``unreadable``. A source with the
    same bytes as one of ``parsed`` (files read before in this run, as a
    baseline shares most of its files with the database) takes its tables:
    the reader's tables are made of the bytes alone. ``meanwhile`` is done
    here while other processes read (see :func:`lensaudit.read.read_contents`)."""
    same = {file.digest: file.tables for file in parsed if file.digest}
    digests = [content_digest(s.data) if same and s.data is not None else b"" for s in sources]
    readable = [
        (s.data, s.display, s.path)
        for s, digest in zip(sources, digests, strict=True)
        if s.data is not None and digest not in same
    ]
    tables = iter(
        reader.read_contents(readable, cache, calibrations=True, refusals=True, meanwhile=meanwhile)
    )
    del readable  # the bytes of files on disk are not kept once read (see below)
    found_parsed = []
    for source, digest in zip(sources, digests, strict=True):
        if source.data is None:
            found = reader.unreadable(source.display, source.path, source.error)
        else:
            if digest in same:
                found = same[digest].named(source.display, source.path)
            else:
                found = next(tables)
            # The reader's, where a cache made it take one.
            digest = digest or found.digest or content_digest(source.data)
        size = len(source.data) if source.data is not None else 0
        if source.data is not None and source.origin is None:
            source = replace(source, data=b"")  # only a git baseline's bytes are looked at again
        found_parsed.append(
            ParsedSource(source, found, file_finding(found, source.display), digest, size)
        )
    return found_parsed
