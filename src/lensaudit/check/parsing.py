"""Parsing a source: the loader's records of its ``<distortion>``,
``<vignetting>`` and ``<tca>`` elements, its file-level problem, and the lens
structure the duplicate rules need, all from one parse of the file."""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from .. import calibrations, loader
from .inputs import Source
from .result import NOT_A_DATABASE, SEVERITY_ERROR, UNREADABLE, XML_ERROR, Finding, clip


@dataclass(frozen=True)
class LensRecord:
    """A ``<lens>`` as the duplicate rules see it: where it is, its untranslated
    names and its crop factor, and the element for comparing contents."""

    line: int
    maker: str
    model: str
    crop_factor: float | str | None  # the number, the text if not a number, None if absent
    element: object = field(default=None, compare=False, repr=False)


@dataclass
class ParsedSource:
    """One parsed file: its records, its file-level problem (if any), and its
    lenses, with the lens of each distortion entry when they line up."""

    source: Source
    entries: list[loader.DistortionEntry]
    problem: Finding | None = None  # the file-level finding, if any
    problem_text: str = ""  # the problem without its position, to match baselines
    lens_of_entry: list[int | None] | None = None  # index into ``lenses``, per entry
    lenses: tuple[LensRecord, ...] = ()
    # <vignetting> and <tca> records of a file that parsed, by kind
    calibrations: dict[str, calibrations.CalibrationRecords] = field(default_factory=dict)


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


def parse_source(source: Source) -> ParsedSource:
    """The records of one file, its file-level finding and its lens structure."""
    from lxml import etree

    display = source.display
    if source.data is None:
        problem = Finding(SEVERITY_ERROR, UNREADABLE, display, 0, 0, f"{display}: {source.error}")
        return ParsedSource(source, [], problem, source.error)
    data = source.data
    try:
        root = etree.fromstring(data, loader.make_parser())
    except etree.XMLSyntaxError as error:
        # The loader's records: one for the file, then what recovery mode salvages.
        entries, load_error = loader.read_bytes(data, display)
        if load_error:
            entries = entries[1:]
        line, column, text = _syntax_error(data, error)
        message = clip(f"XML is not well-formed at line {line}, column {column}: {text}")
        problem = Finding(SEVERITY_ERROR, XML_ERROR, display, line, column, message)
        return ParsedSource(source, entries, problem, text)
    if b"xmlns" in data:
        loader.use_local_names(root)  # as the loader reads it: liblensfun ignores namespaces
    if root.tag != loader.DATABASE_ROOT:
        entries, load_error = loader.read_bytes(data, display)
        line = entries[0].line if entries else 1
        problem = Finding(SEVERITY_ERROR, NOT_A_DATABASE, display, line, 0, clip(load_error))
        return ParsedSource(source, entries[1:], problem, load_error)
    entries = list(loader.entries_from_tree(root, display))
    lenses, lens_of_element = lens_structure(root)
    elements = list(root.iter("distortion"))
    lens_of_entry = None
    if len(elements) == len(entries) and all(
        (element.sourceline or 0) == entry.line
        for element, entry in zip(elements, entries, strict=True)
    ):
        lens_of_entry = [lens_of_element.get(element) for element in elements]
    vignetting, tca = calibrations.entries_from_tree(root, display)
    return ParsedSource(
        source,
        entries,
        lens_of_entry=lens_of_entry,
        lenses=lenses,
        calibrations={calibrations.VIGNETTING: vignetting, calibrations.TCA: tca},
    )


def _untranslated(element, tag: str) -> str | None:
    """Text of the last ``tag`` child without ``lang``, as liblensfun keeps it."""
    text = None
    for child in element.iterchildren(tag):
        if child.get("lang") is None:
            text = (child.text or "").strip()
    return text


def lens_structure(root) -> tuple[tuple[LensRecord, ...], dict]:
    """Every ``<lens>`` in document order, and the lens index of each ``<distortion>``."""
    lenses: list[LensRecord] = []
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
            LensRecord(
                element.sourceline or 0,
                _untranslated(element, "maker") or "",
                _untranslated(element, "model") or "",
                crop,
                element,
            )
        )
        for distortion in element.iter("distortion"):
            lens_of_element[distortion] = index  # the innermost lens wins: iterated last
    return tuple(lenses), lens_of_element


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
