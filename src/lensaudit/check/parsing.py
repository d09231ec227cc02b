"""Parsing the sources: the loader's records of each file's ``<distortion>``,
``<vignetting>`` and ``<tca>`` elements, its file-level problem, and the lens
structure the duplicate rules need, all from one parse of the file.

Files are parsed in worker processes where that pays, while the calling
process imports what the rules need (numpy, the audits); what a worker
returns is plain rows (:data:`FileParts`), made into records here.
"""

from __future__ import annotations

import marshal
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING

from .. import calibrations, loader
from .inputs import Source
from .result import NOT_A_DATABASE, SEVERITY_ERROR, UNREADABLE, XML_ERROR, Finding, clip

if TYPE_CHECKING:
    from ..workers import Job
    from .cache import CheckCache


@dataclass(frozen=True)
class LensRecord:
    """A ``<lens>`` as the duplicate rules see it: where it is, its untranslated
    names and its crop factor, and which of its file's lenses it is."""

    line: int
    maker: str
    model: str
    crop_factor: float | str | None  # the number, the text if not a number, None if absent
    index: int = field(default=0, compare=False)  # among the lenses of its file


@dataclass(eq=False)
class ParsedSource:
    """One parsed file: its file-level problem (if any), its lenses, and, made
    from its rows when first asked for, its records and the lens of each
    distortion entry when they line up.

    ``count`` is the number of its distortion records; ``digest`` the
    :func:`lensaudit.cache.content_digest` of its bytes when a cache is used
    (else b""); ``rows`` gives what :func:`read_parts` found in it.
    """

    source: Source
    count: int = 0
    problem: Finding | None = None  # the file-level finding, if any
    problem_text: str = ""  # the problem without its position, to match baselines
    lenses: tuple[LensRecord, ...] = ()
    digest: bytes = b""
    rows: Callable[[], FileParts | None] = field(default=lambda: None, repr=False)

    @cached_property
    def _records(self) -> tuple[list, list | None, dict]:
        parts = self.rows()
        if parts is None:
            return [], None, {}
        display = self.source.display
        code, rows = parts[0], parts[1]
        if code == NOT_A_DATABASE:
            rows = rows[1:]  # the first is the loader's record of the file itself
        entries = [loader.DistortionEntry(display, *row) for row in rows]
        if code:
            return entries, None, {}
        lens_of_entry, _, vignetting, tca = parts[2:]
        records = {
            kind: calibrations.CalibrationRecords.of_file(kind, display, kind_rows)
            for kind, kind_rows in zip(calibrations.KINDS, (vignetting, tca), strict=True)
        }
        return entries, lens_of_entry, records

    @property
    def entries(self) -> list[loader.DistortionEntry]:
        """Its distortion records (a file that is not a database: those after the first)."""
        return self._records[0]

    @property
    def lens_of_entry(self) -> list[int | None] | None:
        """Index into ``lenses`` of each distortion entry; None when they do not line up."""
        return self._records[1]

    @property
    def calibrations(self) -> dict[str, calibrations.CalibrationRecords]:
        """``<vignetting>`` and ``<tca>`` records of a file that parsed, by kind."""
        return self._records[2]


_POSITION = re.compile(r",? ?(?:\(<string>, )?line (\d+), column (\d+)\)?\s*$")
_PARSER_HINTS = re.compile(
    r",? *(?:try XML_PARSE_HUGE|use XML_PARSE_HUGE option"
    r"|see xmlCtxtSetMaxAmplification)\.?\s*"
)


def _syntax_error(data: bytes, error: Exception) -> tuple[int, int, str]:
    """(line, column, sentence) for a libxml2 error, in words a user can act on."""
    text = (getattr(error, "msg", None) or str(error)).strip()
    match = _POSITION.search(text)
    if match:
        line, column, text = int(match.group(1)), int(match.group(2)), text[: match.start()]
    else:
        line = getattr(error, "lineno", 0) or 0
        column = (getattr(error, "offset", 0) or 0) + 1
    hinted = _PARSER_HINTS.search(text) is not None
    text = " ".join(_PARSER_HINTS.sub(" ", text).split())
    if not data.strip():
        return 1, 1, "the file is empty; a Lensfun database file holds a <lensdatabase> element"
    if hinted and "amplification" in text:
        text += " (entities are never expanded)"
    elif hinted:
        text += " (values and text over 10 MB and nesting over 256 levels are refused)"
    elif "encoding" in text.lower() or "utf-8" in text.lower():
        try:
            data.decode("utf-8")
        except UnicodeDecodeError as decode_error:
            text += (
                f" (byte 0x{data[decode_error.start]:02X} at offset {decode_error.start}"
                f" is not UTF-8; Lensfun database files are UTF-8)"
            )
    return line, column, text


#: What the check needs of one file, as marshal data, so that it can be
#: worked out in a worker process (see :func:`read_parts`).
FileParts = tuple


def read_parts(job: Job) -> FileParts:
    """Parse the bytes of one file (``job.data``): (problem code, distortion
    rows, then the rest) as :func:`parsed_source` reads them.

    ``xml-error``: the rows recovery mode salvages, then the error's line,
    column and sentence; ``not-a-database``: the loader's rows (the file's
    first), then its message; "" (a database): the rows, the lens index of
    each (None if they cannot be matched up), the lenses as (line, maker,
    model, crop factor), the vignetting rows and the TCA rows.
    """
    from lxml import etree

    data = job.data or b""
    try:
        root = etree.fromstring(data, loader.make_parser())
    except etree.XMLSyntaxError as error:
        # The loader's records: one for the file, then what recovery mode salvages.
        rows, load_error = loader.read_rows(data)
        return (XML_ERROR, rows[1:] if load_error else rows, *_syntax_error(data, error))
    if b"xmlns" in data:
        loader.use_local_names(root)  # as the loader reads it: liblensfun ignores namespaces
    if root.tag != loader.DATABASE_ROOT:
        return (NOT_A_DATABASE, *loader.read_rows(data))
    rows = loader.rows_from_tree(root)
    lenses, lens_of_element = lens_structure(root)
    elements = list(root.iter("distortion"))
    lens_of_entry = None
    if len(elements) == len(rows) and all(
        (element.sourceline or 0) == row[0] for element, row in zip(elements, rows, strict=True)
    ):
        lens_of_entry = [lens_of_element.get(element) for element in elements]
    return ("", rows, lens_of_entry, lenses, *calibrations.rows_from_tree(root))


#: What a file is, whatever it is shown as: (number of distortion records,
#: its problem as (code, line, column, message, text) or None, its lenses as
#: (line, maker, model, crop factor)); marshal data, as the check's cache keeps it.
FileSummary = tuple


def summarize(parts: FileParts) -> FileSummary:
    """The :data:`FileSummary` of what :func:`read_parts` found in a file."""
    code, rows = parts[0], parts[1]
    if code == XML_ERROR:
        line, column, text = parts[2:]
        message = clip(f"XML is not well-formed at line {line}, column {column}: {text}")
        return len(rows), (XML_ERROR, line, column, message, text), []
    if code == NOT_A_DATABASE:
        load_error = parts[2]
        line = rows[0][0] if rows else 1
        return max(len(rows) - 1, 0), (NOT_A_DATABASE, line, 0, clip(load_error), load_error), []
    return len(rows), None, parts[3]


def summarized_source(
    source: Source,
    summary: FileSummary,
    rows: Callable[[], FileParts | None],
    digest: bytes = b"",
) -> ParsedSource:
    """A parsed file from its summary; ``rows()`` gives its rows when they are needed."""
    count, problem, lenses = summary
    finding = None
    text = ""
    if problem is not None:
        code, line, column, message, text = problem
        finding = Finding(SEVERITY_ERROR, code, source.display, line, column, message)
    return ParsedSource(
        source,
        count,
        finding,
        text,
        tuple(LensRecord(*lens, index) for index, lens in enumerate(lenses)),
        digest,
        rows,
    )


def parsed_source(source: Source, parts: FileParts | None) -> ParsedSource:
    """The records of one file, its file-level finding and its lens structure,
    from what :func:`read_parts` found in it (None for a file not read)."""
    if source.data is None or parts is None:
        display = source.display
        problem = Finding(SEVERITY_ERROR, UNREADABLE, display, 0, 0, f"{display}: {source.error}")
        return ParsedSource(source, problem=problem, problem_text=source.error)
    return summarized_source(source, summarize(parts), lambda: parts)


def parse_sources(
    sources: Sequence[Source],
    meanwhile: Callable[[], object] = lambda: None,
    cache: CheckCache | None = None,
) -> list[ParsedSource]:
    """Every source parsed, in worker processes where that pays, while
    ``meanwhile()`` runs here (see :func:`lensaudit.workers.parse_all`).

    With a ``cache``, files whose bytes it has met are not parsed again, and
    what is parsed is kept in it; ``meanwhile()`` then runs only if some file
    is parsed.
    """
    from ..workers import parse_all

    digests: dict[int, bytes] = {}
    known: dict[int, tuple] = {}
    if cache is not None:
        from ..cache import content_digest

        for index, source in enumerate(sources):
            if source.data is not None:
                digests[index] = content_digest(source.data)
                found = cache.file(digests[index])
                if found is not None:
                    known[index] = found
    todo = [i for i, s in enumerate(sources) if s.data is not None and i not in known]
    found: dict[int, bytes | FileParts] = {}
    if cache is None:
        parts = parse_all([_job(sources[i]) for i in todo], read_parts, meanwhile)
        found = dict(zip(todo, parts, strict=True))
    elif todo:
        # As marshal data, which the cache keeps as it is.
        packed = parse_all([_job(sources[i]) for i in todo], _packed, meanwhile)
        found = dict(zip(todo, packed, strict=True))
    parsed = []
    for index, source in enumerate(sources):
        digest = digests.get(index, b"")
        if index in known:
            summary, body = known[index]
            parsed.append(summarized_source(source, summary, _unpacker(source, body), digest))
        elif cache is not None and index in found:
            body = found[index]
            parts = marshal.loads(body)
            summary = summarize(parts)
            cache.put_file(digest, summary, body)
            parsed.append(summarized_source(source, summary, lambda parts=parts: parts, digest))
        else:
            parsed.append(parsed_source(source, found.get(index)))
    return parsed


def _packed(job: Job) -> bytes:
    """:func:`read_parts` as marshal data: kept as it is by the cache, unpacked once here."""
    return marshal.dumps(read_parts(job))


def _unpacker(source: Source, body: bytes) -> Callable[[], FileParts]:
    """The rows kept for a file, or, should they not unpack, the file parsed again."""

    def rows() -> FileParts:
        try:
            parts = marshal.loads(body)
            if isinstance(parts, tuple) and len(parts) >= 2 and isinstance(parts[1], list):
                return parts
        except (EOFError, ValueError, TypeError):
            pass
        return read_parts(_job(source))

    return rows


def parse_source(source: Source) -> ParsedSource:
    """One source parsed here."""
    return parsed_source(source, None if source.data is None else read_parts(_job(source)))


def _job(source: Source) -> Job:
    from ..workers import Job

    return Job(source.path or Path(source.name), source.display, source.data)


def lens_elements(source: Source) -> list:
    """The ``<lens>`` elements of a database file, in document order, parsed
    again: the duplicate rules compare the contents of the few that repeat."""
    from lxml import etree

    root = etree.fromstring(source.data or b"", loader.make_parser())
    if source.data and b"xmlns" in source.data:
        loader.use_local_names(root)
    return list(root.iter("lens"))


def _untranslated(element, tag: str) -> str | None:
    """Text of the last ``tag`` child without ``lang``, as liblensfun keeps it."""
    text = None
    for child in element.iterchildren(tag):
        if child.get("lang") is None:
            text = (child.text or "").strip()
    return text


def lens_structure(root) -> tuple[list[tuple], dict]:
    """Every ``<lens>`` in document order, as (line, maker, model, crop factor),
    and the lens index of each ``<distortion>``."""
    lenses: list[tuple] = []
    lens_of_element = {}
    for index, element in enumerate(root.iter("lens")):
        crop_text = _untranslated(element, "cropfactor")
        crop: float | str | None = crop_text
        if crop_text is not None:
            try:
                crop = loader.parse_number(crop_text)
            except ValueError:
                pass
            if crop != crop:
                crop = crop_text  # NaN would never equal itself as a key
        lenses.append(
            (
                element.sourceline or 0,
                _untranslated(element, "maker") or "",
                _untranslated(element, "model") or "",
                crop,
            )
        )
        for distortion in element.iter("distortion"):
            lens_of_element[distortion] = index  # the innermost lens wins: iterated last
    return lenses, lens_of_element


def element_content(element, skip_names: bool = False) -> tuple:
    """An element's tag, attributes, text (white space collapsed) and child
    elements, recursively; comments left out. ``skip_names`` leaves out the
    untranslated ``<maker>`` and ``<model>`` children."""
    children = []
    for child in element:
        if not isinstance(child.tag, str):
            continue  # a comment or processing instruction
        if skip_names and child.tag in ("maker", "model") and child.get("lang") is None:
            continue
        children.append(element_content(child))
    text = " ".join((element.text or "").split())
    return (element.tag, tuple(sorted(element.attrib.items())), text, tuple(children))
