"""Read Lensfun database XML into one :class:`DistortionEntry` per ``<distortion>``.

This is the first stage of the pipeline: files in, plain records out. Every
``<distortion>`` element found in the input produces exactly one record; the
ones that cannot be audited (unknown model, missing or non-numeric attribute,
file that is not well-formed XML) carry a ``status`` other than ``ok`` and a
``message`` saying why, so that nothing in the input is silently dropped.

Parsing is safe against hostile XML: no network access, no DTD loading, no
entity expansion (external or internal).
"""

from __future__ import annotations

import math
import os
import re
import stat
import sys
from collections import namedtuple
from collections.abc import Callable, Iterable, Iterator, Sequence
from operator import itemgetter
from pathlib import Path

# typing only for type checkers: a scan from the cache never imports it.
TYPE_CHECKING = False
if TYPE_CHECKING:
    from typing import Any, Protocol

    from lxml import etree

#: Distortion models lensaudit knows how to audit, and the coefficient
#: attributes each one reads (a missing coefficient means 0, as in liblensfun).
MODEL_COEFFICIENTS: dict[str, tuple[str, ...]] = {
    "ptlens": ("a", "b", "c"),
    "poly3": ("k1",),
    "poly5": ("k1", "k2"),
}

DEFAULT_CROP_FACTOR = 1.0
DEFAULT_ASPECT_RATIO = 1.5
DEFAULT_LENS_TYPE = "rectilinear"

# Status codes: "ok" means audited; everything else says why not.
STATUS_OK = "ok"
STATUS_UNKNOWN_MODEL = "unknown_model"
STATUS_MISSING_ATTRIBUTE = "missing_attribute"
STATUS_BAD_VALUE = "bad_value"
STATUS_NO_LENS = "no_lens"
STATUS_XML_ERROR = "xml_error"
STATUS_UNREADABLE = "unreadable"
STATUS_NOT_DATABASE = "not_database"

#: The root element of a Lensfun database file.
DATABASE_ROOT = "lensdatabase"
#: Larger files are not read: Lensfun's largest database file is about 2 MB.
MAX_FILE_BYTES = 256 << 20

NAN = math.nan

# A plain decimal number as Lensfun writes it. Python's float() also accepts
# "1_0", "nan" and "infinity", which are not numbers in a lens database.
_DECIMAL = re.compile(r"\s*[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?\s*\Z")
_NON_FINITE = re.compile(r"\s*[+-]?(?:nan|inf|infinity)\s*\Z", re.IGNORECASE)


class LoadError(Exception):
    """The input as a whole could not be read (no such path, no XML files)."""


#: The fields of a :class:`DistortionEntry`, in order, and the type of each.
ENTRY_FIELDS = {
    "file": "str",
    "line": "int",
    "maker": "str",
    "lens": "str",
    "mounts": "tuple[str, ...]",
    "type": "str",
    "crop_factor": "float",
    "aspect_ratio": "float",
    "model": "str",
    "focal": "float",
    "real_focal": "float",
    "a": "float",
    "b": "float",
    "c": "float",
    "k1": "float",
    "k2": "float",
    "status": "str",
    "message": "str",
}


class DistortionEntry(
    namedtuple(
        "DistortionEntry",
        tuple(ENTRY_FIELDS),
        defaults=(NAN, NAN, NAN, NAN, NAN, NAN, STATUS_OK, ""),
    )
):
    """One ``<distortion>`` element with the lens context it applies to: the
    fields of :data:`ENTRY_FIELDS`, in that order.

    A named tuple: immutable (``entry._replace(file=...)`` makes a changed
    copy), and cheap to make by the thousand. (A dataclass would also cost
    every scan the import of :mod:`dataclasses` and :mod:`inspect`.)

    ``file`` is the name the file is reported as, ``line`` the element's line.
    Coefficients are the raw model coefficients (``a b c`` for ptlens, ``k1``
    for poly3, ``k1 k2`` for poly5); coefficients the model does not use are
    NaN. ``real_focal`` is NaN when neither a ``real-focal`` attribute nor a
    ``<real-focal-length>`` for its focal length gives it. Lengths are in
    millimetres; crop factor and aspect ratio are plain numbers. ``status``
    is ``ok`` or why the entry is not audited, ``message`` says more.
    """

    __slots__ = ()


class SourceFile(namedtuple("SourceFile", ("name", "path", "entries", "error"), defaults=("",))):
    """A file that was read: its display ``name``, absolute ``path``, the number of
    ``entries`` read from it, and its ``error`` ("" if none).

    A named tuple rather than a dataclass: every scan imports this module, and
    making a dataclass costs a scan more than the class is worth.
    """

    __slots__ = ()


class LoadResult:
    """Records from every file (``entries``), and the list of ``files`` they came from."""

    __slots__ = ("entries", "files")

    def __init__(
        self, entries: list[DistortionEntry] | None = None, files: list[SourceFile] | None = None
    ) -> None:
        self.entries = [] if entries is None else entries
        self.files = [] if files is None else files


def parse_number(text: str | None) -> float:
    """Parse a decimal number as written in Lensfun XML.

    Raises ``ValueError`` with a short reason for anything else, including
    ``nan`` and ``inf`` spelled out, which Lensfun never means.
    """
    if text is None:
        raise ValueError("missing")
    try:
        value = float(text)
    except ValueError:
        value = None
    # float() alone is too lenient: it takes "1_0", "nan", "infinity" and
    # non-ASCII digits. Accept its answer only for plain finite ASCII numbers.
    if value is not None and value - value == 0 and text.isascii() and "_" not in text:
        return value
    if _DECIMAL.match(text):
        raise ValueError(f"{quoted(text)} overflows a double")
    if _NON_FINITE.match(text):
        raise ValueError(f"{quoted(text)} is not a finite number")
    raise ValueError(f"{quoted(text)} is not a number")


def quoted(text: str, limit: int = 40) -> str:
    """A value for a message: stripped, quoted, and cut short if long."""
    text = text.strip()
    if len(text) > limit:
        return repr(text[:limit]) + f"... ({len(text)} characters)"
    return repr(text)


def parse_aspect_ratio(text: str) -> float:
    """Parse ``N:M`` (``4:3``) or a decimal (``1.333``) aspect ratio."""
    numerator, sep, denominator = text.partition(":")
    if sep:
        divisor = parse_number(denominator)
        if divisor == 0:
            raise ValueError(f"{quoted(text)} divides by zero")
        value = parse_number(numerator) / divisor
    else:
        value = parse_number(text)
    if not value > 0 or not math.isfinite(value):
        raise ValueError(f"{text.strip()!r} is not a positive ratio")
    return value


def make_parser(target: object = None) -> etree.XMLParser:
    """An lxml parser that never touches the network, DTDs or entities (with
    ``target``, one that hands what it reads to that parser target)."""
    from lxml import etree

    return etree.XMLParser(
        target=target,
        resolve_entities=False,
        no_network=True,
        load_dtd=False,
        dtd_validation=False,
        huge_tree=False,
        remove_pis=True,
        collect_ids=False,  # no table of xml:id values: nothing looks them up
    )


def _text(element: etree._Element) -> str:
    """An element's text content, stripped (comments and PIs left out)."""
    if len(element) == 0:  # no child, comment or PI: the common case
        return (element.text or "").strip()
    return "".join(element.itertext()).strip()


class LensContext:
    """What a lens, and the ``<calibration>`` an entry is in, give each of its entries.

    ``problem`` is why entries of the lens cannot be audited ("" if they can),
    ``status`` the status it gives them; ``real_focals`` maps a focal length
    to its real focal length, from the ``<real-focal-length>`` elements of
    the calibration; ``lens_fields`` are maker, lens, mounts, type, crop
    factor and aspect ratio, the start of each record.

    A plain class (not a dataclass): every scan imports this module, and
    making a dataclass costs a scan more than the class is worth.
    """

    __slots__ = (
        "maker",
        "lens",
        "mounts",
        "type",
        "crop_factor",
        "aspect_ratio",
        "problem",
        "status",
        "real_focals",
        "lens_fields",
    )

    def __init__(
        self,
        maker: str,
        lens: str,
        mounts: tuple[str, ...],
        lens_type: str,
        crop_factor: float,
        aspect_ratio: float,
        problem: str = "",
        status: str = STATUS_BAD_VALUE,
        real_focals: dict[float, float] | None = None,
    ) -> None:
        self.maker = maker
        self.lens = lens
        self.mounts = mounts
        self.type = lens_type
        self.crop_factor = crop_factor
        self.aspect_ratio = aspect_ratio
        self.problem = problem
        self.status = status
        self.real_focals = {} if real_focals is None else real_focals
        self.lens_fields = (maker, lens, mounts, lens_type, crop_factor, aspect_ratio)

    def record(
        self,
        name: str,
        line: int,
        model: str,
        focal: float,
        real_focal: float,
        coefficients: list[float],
        status: str = STATUS_OK,
        message: str = "",
    ) -> DistortionEntry:
        """An entry of this lens; ``coefficients`` are a, b, c, k1, k2."""
        return DistortionEntry(
            name,
            line,
            *self.lens_fields,
            model,
            focal,
            real_focal,
            *coefficients,
            status,
            message,
        )


#: The children of a ``<lens>`` that make its context.
_LENS_CHILDREN = ("maker", "model", "mount", "type", "cropfactor", "aspect-ratio")
_LENS_CHILD_TAGS = frozenset(_LENS_CHILDREN)


def lens_context(lens: etree._Element | None) -> LensContext:
    """The context a ``<lens>`` gives its entries; for None (an entry outside
    any lens), one whose ``problem`` says so, status ``no_lens``."""
    if lens is None:
        return LensContext(
            "",
            "",
            (),
            DEFAULT_LENS_TYPE,
            DEFAULT_CROP_FACTOR,
            DEFAULT_ASPECT_RATIO,
            "not inside a <lens> element",
            STATUS_NO_LENS,
        )
    problems = []
    # One pass over the children. Of each tag, the text content of the last
    # child without a ``lang`` attribute: liblensfun keeps the last when a
    # lens repeats an element (two untranslated <model> names, say). The
    # whole text content, as any XML reader gives it: 1<!-- note -->.5 is 1.5.
    texts: dict[str, str] = {}
    mount_list = []
    for child in lens:  # all children, tested here: quicker than lxml's filter by six tags
        tag = child.tag
        if tag not in _LENS_CHILD_TAGS:  # comments and PIs have a function as tag
            continue
        if tag == "mount":
            mount_list.append(_text(child))
        elif child.get("lang") is None:
            texts[tag] = _text(child)
    maker = texts.get("maker") or ""
    model = texts.get("model") or ""
    mounts = tuple(mount_list)
    lens_type = texts.get("type") or DEFAULT_LENS_TYPE
    crop_factor = DEFAULT_CROP_FACTOR
    crop_text = texts.get("cropfactor")
    if crop_text is not None:
        try:
            crop_factor = _positive(parse_number(crop_text), "crop factor")
        except ValueError as error:
            problems.append(f"<cropfactor> {error}")
            crop_factor = NAN
    aspect_ratio = DEFAULT_ASPECT_RATIO
    aspect_text = texts.get("aspect-ratio")
    if aspect_text is not None:
        try:
            aspect_ratio = parse_aspect_ratio(aspect_text)
        except ValueError as error:
            problems.append(f"<aspect-ratio> {error}")
            aspect_ratio = NAN
    return LensContext(
        maker, model, mounts, lens_type, crop_factor, aspect_ratio, "; ".join(problems)
    )


def _positive(value: float, what: str) -> float:
    if value <= 0:
        raise ValueError(f"{what} {value:g} is not positive")
    return value


def calibration_context(calibration: etree._Element | None, lens: LensContext) -> LensContext:
    """Apply what ``<calibration>`` adds to the lens: ``cropfactor=`` and
    ``aspect-ratio=`` attributes, and ``<real-focal-length>`` elements (the
    form version 1 databases give the real focal length in)."""
    if calibration is None or calibration.tag != "calibration":
        return lens
    crop_text = calibration.get("cropfactor")
    aspect_text = calibration.get("aspect-ratio")
    real_focals = {}
    problems = [lens.problem] if lens.problem else []
    for element in calibration.iterchildren("real-focal-length"):
        try:
            focal = parse_number(element.get("focal"))
            real_focals[focal] = _positive(parse_number(element.get("real-focal")), "real focal")
        except ValueError as error:
            problems.append(f"<real-focal-length> on line {element.sourceline}: {error}")
    if (
        crop_text is None
        and aspect_text is None
        and not real_focals
        and len(problems) == bool(lens.problem)
    ):
        return lens
    crop_factor, aspect_ratio = lens.crop_factor, lens.aspect_ratio
    if crop_text is not None:
        try:
            crop_factor = _positive(parse_number(crop_text), "crop factor")
        except ValueError as error:
            problems.append(f"<calibration cropfactor> {error}")
    if aspect_text is not None:
        try:
            aspect_ratio = parse_aspect_ratio(aspect_text)
        except ValueError as error:
            problems.append(f"<calibration aspect-ratio> {error}")
    return LensContext(
        lens.maker,
        lens.lens,
        lens.mounts,
        lens.type,
        crop_factor,
        aspect_ratio,
        "; ".join(problems),
        lens.status,
        real_focals,
    )


#: When an entry has several problems, its status names the most basic one.
STATUS_PRIORITY = (
    STATUS_NO_LENS,
    STATUS_MISSING_ATTRIBUTE,
    STATUS_UNKNOWN_MODEL,
    STATUS_BAD_VALUE,
)


def attribute_number(
    attributes: Any, attribute: str, default: float | None, problems: list[tuple[str, str]]
) -> float:
    """An attribute's value as a number (``default`` if it is missing); a bad one,
    or a missing one without a default, appends (status, message) to
    ``problems`` and gives NaN."""
    text = attributes.get(attribute)
    if text is None:
        if default is None:
            problems.append((STATUS_MISSING_ATTRIBUTE, f"missing {attribute}="))
            return NAN
        return default
    try:
        value = parse_number(text)
    except ValueError as error:
        problems.append((STATUS_BAD_VALUE, f"{attribute}={error}"))
        return NAN
    return value


# Per model: the default of each coefficient attribute (a missing one is 0),
# and which of [focal, real focal, coefficients..., NaN] go to a, b, c, k1, k2.
_DEFAULTS = {model: ("0",) * len(names) for model, names in MODEL_COEFFICIENTS.items()}
_LAYOUT = {
    model: itemgetter(
        *(2 + names.index(n) if n in names else 2 + len(names) for n in ("a", "b", "c", "k1", "k2"))
    )
    for model, names in MODEL_COEFFICIENTS.items()
}


#: An entry as a plain tuple: the fields of :class:`DistortionEntry` after ``file``.
#: Reading a whole database makes thousands; tuples are what columns are made of.
EntryRow = tuple
#: The field names of an :data:`EntryRow`, in order.
ROW_FIELDS = tuple(ENTRY_FIELDS)[1:]


def row_columns(rows: list[EntryRow]) -> dict[str, list]:
    """Rows as columns: field name -> one value per row (``file`` left out)."""
    if not rows:
        return {name: [] for name in ROW_FIELDS}
    return dict(zip(ROW_FIELDS, map(list, zip(*rows, strict=True)), strict=True))


def _row(element: etree._Element, context: LensContext) -> EntryRow:
    """The row of one ``<distortion>`` element (see :data:`EntryRow`).

    The common case, a known model with plain numbers, takes a short path;
    anything else is examined in full by :func:`_checked_row`.
    """
    get = element.get
    model = get("model")
    names = MODEL_COEFFICIENTS.get(model)  # type: ignore[arg-type]
    focal_text = get("focal")
    if names is not None and focal_text is not None and not context.problem:
        real_text = get("real-focal")
        texts = [focal_text, "1" if real_text is None else real_text]
        texts += map(get, names, _DEFAULTS[model])  # type: ignore[index]
        joined = "".join(texts)
        # float() alone also takes "1_0", "nan", "inf" and non-ASCII digits.
        if joined.isascii() and "_" not in joined:
            try:
                values = list(map(float, texts))
            except ValueError:
                values = None
            if values is not None:
                total = sum(values)
                if total - total == 0 and values[0] > 0 and values[1] > 0:  # all finite
                    focal = values[0]
                    if real_text is None:
                        real_focal = context.real_focals.get(focal, NAN)
                    else:
                        real_focal = values[1]
                    values.append(NAN)
                    return (
                        element.sourceline or 0,
                        *context.lens_fields,
                        model,
                        focal,
                        real_focal,
                        *_LAYOUT[model](values),  # type: ignore[index]
                        STATUS_OK,
                        "",
                    )
    return _checked_row(element, context)


def _checked_row(element: etree._Element, context: LensContext) -> EntryRow:
    """The row of one ``<distortion>`` element, every problem noted."""
    # Without a real-focal= attribute, the <real-focal-length> of its focal length.
    required = (
        ("focal", None),
        ("real-focal", lambda values: context.real_focals.get(values["focal"], NAN)),
    )
    model, values, problems = checked_attributes(element, required, _MODEL_DEFAULTS, context)
    status, message = status_of(problems)
    return (
        element.sourceline or 0,
        *context.lens_fields,
        model,
        values["focal"],
        values["real-focal"],
        *(values.get(n, NAN) for n in ("a", "b", "c", "k1", "k2")),
        status,
        message,
    )


#: Per model, each coefficient attribute and its default.
_MODEL_DEFAULTS = {model: dict.fromkeys(names, 0.0) for model, names in MODEL_COEFFICIENTS.items()}

#: The default of a required attribute: None (it must be given), a number, or
#: a function of the values of the attributes before it.
AttributeDefault = float | Callable[[dict[str, float]], float] | None


def checked_attributes(
    element: etree._Element,
    required: Sequence[tuple[str, AttributeDefault]],
    models: dict[str, dict[str, float]],
    context: LensContext,
) -> tuple[str, dict[str, float], list[tuple[str, str]]]:
    """(model, values, problems) of a calibration element, every problem noted.

    Reads ``model=``, then each ``required`` attribute, which must be positive,
    then the coefficients of the model (``models``: model -> attribute ->
    default). ``problems`` are (status, message) pairs, the lens context's
    own problem last (see :func:`status_of`); a value that could not be read
    is NaN.
    """
    attributes = element.attrib
    problems: list[tuple[str, str]] = []
    model = (attributes.get("model") or "").strip()
    if not model:
        problems.append((STATUS_MISSING_ATTRIBUTE, "missing model="))
    values: dict[str, float] = {}
    for attribute, default in required:
        if callable(default):
            default = default(values)
        values[attribute] = attribute_number(attributes, attribute, default, problems)
    for attribute, _ in required:
        value = values[attribute]
        if value <= 0:
            problems.append((STATUS_BAD_VALUE, f"{attribute}={value:g} is not positive"))
    defaults = models.get(model)
    if defaults is not None:
        for attribute, default in defaults.items():
            values[attribute] = attribute_number(attributes, attribute, default, problems)
    elif model:
        known = ", ".join(models)
        problems.append((STATUS_UNKNOWN_MODEL, f"model {quoted(model)} is not one of {known}"))
    if context.problem:
        problems.append((context.status, context.problem))
    return model, values, problems


def status_of(problems: list[tuple[str, str]]) -> tuple[str, str]:
    """(status, message) of an entry with these (status, message) problems:
    the most basic status (see :data:`STATUS_PRIORITY`) and every message."""
    if not problems:
        return STATUS_OK, ""
    status = min((code for code, _ in problems), key=STATUS_PRIORITY.index)
    return status, "; ".join(text for _, text in problems)


def entries_from_tree(root: etree._Element, name: str) -> Iterator[DistortionEntry]:
    """Records for every ``<distortion>`` element under ``root``, in document order."""
    for row in rows_from_tree(root):
        yield DistortionEntry(name, *row)


def rows_from_tree(root: etree._Element) -> list[EntryRow]:
    """:func:`entries_from_tree` as rows (see :data:`EntryRow`)."""
    return [_row(element, context) for element, context in elements_in_context(root, _DISTORTION)]


_DISTORTION = ("distortion",)


def elements_in_context(
    root: etree._Element, tags: tuple[str, ...]
) -> Iterator[tuple[etree._Element, LensContext]]:
    """Each element under ``root`` named one of ``tags``, in document order, with
    the context it is read in: its lens's, with its ``<calibration>`` applied."""
    lens = calibration = None
    of_lens = context = lens_context(None)
    for element in root.iter("lens", "calibration", *tags):
        tag = element.tag
        if tag == "lens":
            lens, calibration = element, None
            of_lens = lens_context(lens)
        elif tag == "calibration":
            if element.getparent() is lens:
                calibration = element
                context = calibration_context(calibration, of_lens)
        # calibration is only ever set to a child of the current lens.
        elif calibration is None or lens is None or element.getparent() is not calibration:
            yield element, context_of(element)
        else:
            yield element, context


def context_of(element: etree._Element) -> LensContext:
    """The context of an element found outside ``<lens><calibration>`` (rare):
    that of the lens it is in, if any, with its parent's overrides if the
    parent is a ``<calibration>``."""
    parent = element.getparent()
    lens = next(element.iterancestors("lens"), None)
    base = lens_context(lens)
    return calibration_context(parent, base) if parent is not None else base


class ParsedFile(
    namedtuple(
        "ParsedFile",
        ("root", "status", "line", "error", "entry_message"),
        defaults=(STATUS_OK, 0, "", ""),
    )
):
    """A database file's XML tree (``root``), and what is wrong with the file as a whole.

    ``status`` is ``ok``, ``xml_error`` (not well-formed: ``root`` is then
    what libxml2's recovery mode can still read, or None) or
    ``not_database`` (the root is not ``<lensdatabase>``). ``error`` is the
    file's error message ("" if none), ``line`` where it is, and
    ``entry_message`` what each entry read from ``root`` is marked with.
    """

    __slots__ = ()


def parse_file(data: bytes) -> ParsedFile:
    """Parse one file's content safely (see :func:`make_parser`), as liblensfun
    reads it: without namespaces."""
    from lxml import etree  # imported here: a fully cached load never needs it

    try:
        root = etree.fromstring(data, make_parser())
    except etree.XMLSyntaxError as error:
        line, column, text = syntax_error_position(error)
        reason = f"line {line}, column {column}: {text}"
        return ParsedFile(
            _recovered_tree(data),
            STATUS_XML_ERROR,
            line,
            f"XML is not well-formed at {reason}",
            f"file is not well-formed XML ({reason}); entry read in recovery mode",
        )
    if b"xmlns" in data:
        use_local_names(root)
    if root.tag != DATABASE_ROOT:
        tag = root.tag if isinstance(root.tag, str) else "?"
        message = (
            f"root element is <{_clip(tag)}>, not <{DATABASE_ROOT}>: not a Lensfun database file"
        )
        return ParsedFile(root, STATUS_NOT_DATABASE, root.sourceline or 1, message, message)
    return ParsedFile(root)


#: A number as Lensfun writes one in a ``<vignetting/>`` or ``<tca/>`` attribute,
#: quoted: digits and points, a leading minus, an exponent; never two dashes in
#: a row. (The quantifiers are possessive: no backtracking, whatever the text.)
_NUMBER = rb'"-?[.0-9]*+(?:[eE][-+]?[0-9]++)?+"'
#: A ``<vignetting/>`` or ``<tca/>`` element exactly as Lensfun writes it, on one
#: line: its attributes in one of the orders Lensfun writes them, each once.
#: These are two thirds of a database's bytes, and the distortion audit reads
#: none of them.
_CALIBRATION_ELEMENT = re.compile(
    rb'<(?:vignetting model="[a-z0-9]*" focal=%(n)s aperture=%(n)s distance=%(n)s'
    rb" k1=%(n)s k2=%(n)s k3=%(n)s"
    rb'|tca model="[a-z0-9]*" focal=%(n)s (?:vr=%(n)s vb=%(n)s'
    rb"|br=%(n)s vr=%(n)s bb=%(n)s vb=%(n)s"
    rb"|br=%(n)s cr=%(n)s vr=%(n)s bb=%(n)s cb=%(n)s vb=%(n)s))/>" % {b"n": _NUMBER}
)
#: What stands in for each of them: an empty element of no meaning to the audit.
_PLACEHOLDER = b"<v/>"
_ENCODING_DECLARED = re.compile(rb"""\A(?:\xef\xbb\xbf)?<\?xml[^>]*?encoding\s*=\s*["']([^"']*)""")


def _distortion_file(data: bytes) -> ParsedFile:
    """:func:`parse_file` for the distortion audit: the same tree, but for the
    ``<vignetting/>`` and ``<tca/>`` elements it never reads.

    Each ``<vignetting/>`` and ``<tca/>`` element written as Lensfun writes it
    (:data:`_CALIBRATION_ELEMENT`) is replaced by :data:`_PLACEHOLDER` before
    the tree is built. The two are interchangeable wherever they stand: both
    are well-formed empty elements (the one replaced by its fixed form:
    distinct attribute names, values without ``<``, ``&``, quotes or two
    dashes); both start with ``<``, so that both are errors in an attribute
    value, inside a tag and beside the root element; neither holds ``--`` or
    ``?>``, so that both are allowed in a comment or a processing
    instruction; neither holds a line break, so that no line number moves.
    The text with the placeholders is therefore well-formed exactly when the
    file is, and its tree is the file's with each such element renamed and
    emptied: no element or text the audit reads changes. Files where text
    could mean something else are parsed whole: a document type (entities),
    CDATA sections, namespaces, an encoding other than UTF-8, and any file
    whose text with the placeholders does not parse as a database (then
    libxml2 says what is wrong with the file itself).
    """
    from lxml import etree

    start = data[3:] if data.startswith(b"\xef\xbb\xbf") else data
    declared = _ENCODING_DECLARED.match(data)
    if (
        not start.lstrip(b" \t\r\n").startswith(b"<")
        or start[1:2] == b"\0"
        or b"<!DOCTYPE" in data
        or b"<![CDATA[" in data
        or b"xmlns" in data
        or (declared is not None and declared.group(1).lower() not in (b"utf-8", b"utf8"))
    ):
        return parse_file(data)
    try:
        root = etree.fromstring(_CALIBRATION_ELEMENT.sub(_PLACEHOLDER, data), make_parser())
    except etree.XMLSyntaxError:
        return parse_file(data)  # and its message
    if root.tag != DATABASE_ROOT:
        return parse_file(data)
    return ParsedFile(root)


def _recovered_tree(data: bytes) -> etree._Element | None:
    """What libxml2's recovery mode can still read of a broken file, or None."""
    from lxml import etree

    parser = etree.XMLParser(
        recover=True,
        resolve_entities=False,
        no_network=True,
        load_dtd=False,
        huge_tree=False,
        collect_ids=False,
    )
    try:
        return etree.fromstring(data, parser)
    except etree.XMLSyntaxError:
        return None


def _error_row(line: int, status: str, message: str) -> EntryRow:
    """The row that stands for a whole file's problem: no lens, no model."""
    return (line, "", "", (), "", NAN, NAN, "", NAN, NAN, NAN, NAN, NAN, NAN, NAN, status, message)


def load_bytes(data: bytes, name: str) -> list[DistortionEntry]:
    """Records for one file's content; ``name`` is how the file is reported.

    See :func:`read_bytes`, which also returns the file-level error message.
    """
    return read_bytes(data, name)[0]


def read_bytes(data: bytes, name: str) -> tuple[list[DistortionEntry], str]:
    """Records for one file's content, and the file's error message or "".

    A file that is not well-formed XML yields one ``xml_error`` record at the
    error's line (with libxml2's message and column), followed by any entries
    libxml2's recovery mode can still read, each also marked ``xml_error``.
    A well-formed file whose root is not ``<lensdatabase>`` yields one
    ``not_database`` record, then one for each ``<distortion>`` in it, so
    that none is lost; none of them is audited.
    """
    rows, error = read_rows(data)
    return [DistortionEntry(name, *row) for row in rows], error


def read_rows(data: bytes) -> tuple[list[EntryRow], str]:
    """:func:`read_bytes` as rows (see :data:`EntryRow`), which name no file."""
    parsed = _distortion_file(data)
    rows = [] if parsed.root is None else rows_from_tree(parsed.root)
    if not parsed.error:
        return rows, ""
    status, message = parsed.status, parsed.entry_message
    head = _error_row(parsed.line, status, parsed.error)
    if status == STATUS_XML_ERROR:  # each entry's own problems kept in front
        rows = [
            (*row[:-2], status, f"{row[-1]}; {message}" if row[-1] else message) for row in rows
        ]
    else:
        rows = [(*row[:-2], status, message) for row in rows]
    return [head, *rows], parsed.error


def use_local_names(root: etree._Element) -> None:
    """Drop namespaces from element names, in place.

    liblensfun's parser does not know namespaces: to it, an element in a
    default namespace (``<lensdatabase xmlns="...">``) has its plain name.
    """
    for element in root.iter():
        tag = element.tag
        if isinstance(tag, str) and tag.startswith("{"):
            element.tag = tag.partition("}")[2]


def _clip(text: str, limit: int = 40) -> str:
    return text if len(text) <= limit else text[:limit] + "..."


def syntax_error_position(error: etree.XMLSyntaxError) -> tuple[int, int, str]:
    """(line, column, message) of a libxml2 error, columns counted from 1."""
    message = getattr(error, "msg", None) or str(error)
    # libxml2 ends its message with the position; lxml's offset is one less.
    match = re.search(r",? ?(?:\(<string>, )?line (\d+), column (\d+)\)?$", message)
    if match:
        return int(match.group(1)), int(match.group(2)), message[: match.start()].strip()
    return error.lineno or 0, (error.offset or 0) + 1, message.strip()


def xml_files(path: Path) -> list[Path]:
    """The ``*.xml`` files directly inside a database directory, sorted by name.

    Anything so named but a directory counts: a FIFO or a device named
    ``*.xml`` is then reported as unreadable rather than silently skipped.
    Raises ``OSError`` when the directory cannot be listed.
    """
    return [path / name for name, _ in _xml_entries(path)]


def _xml_entries(path: Path) -> list[tuple[str, bool]]:
    """(name, whether it is a symbolic link) of each file :func:`xml_files` gives."""
    with os.scandir(path) as found:
        return sorted(
            (item.name, item.is_symlink())
            for item in found
            if item.name.lower().endswith(".xml") and not item.is_dir()
        )


def display_path(path: str | os.PathLike[str]) -> str:
    """A path as printed: bytes that are not valid in the file system's
    encoding (a file name that is not UTF-8) as backslash escapes."""
    return os.fsencode(path).decode(sys.getfilesystemencoding(), "backslashreplace")


def _reason(error: OSError) -> str:
    return error.strerror or str(error)


def read_file(path: str | os.PathLike[str]) -> bytes:
    """The bytes of a regular file, read without ever blocking.

    Raises ``OSError`` for a FIFO, device, socket or directory (opened
    non-blocking and refused, so that a FIFO cannot hang the run), and for a
    file larger than :data:`MAX_FILE_BYTES`.
    """
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0)
    descriptor = os.open(path, flags | getattr(os, "O_CLOEXEC", 0))
    with open(descriptor, "rb", closefd=True) as stream:
        info = os.fstat(descriptor)
        if not stat.S_ISREG(info.st_mode):
            raise OSError(0, "not a regular file")
        if info.st_size > MAX_FILE_BYTES:
            raise OSError(0, f"larger than {MAX_FILE_BYTES >> 20} MiB, not a database file")
        return stream.read()


if TYPE_CHECKING:  # what load_files needs of a cache, for type checkers

    class EntryCache(Protocol):
        """Where :func:`load_files` may find files parsed before (see lensaudit.cache).

        Both methods are given the bytes :func:`load_files` read, so that a file
        is read once and what is stored was parsed from the very bytes it is
        stored under.
        """

        def get(
            self, path: Path, data: bytes, name: str
        ) -> tuple[list[DistortionEntry], str] | None: ...

        def put(
            self, path: Path, data: bytes, entries: list[DistortionEntry], error: str
        ) -> None: ...


def expand(
    paths: Sequence[str | os.PathLike[str]] | str | os.PathLike[str],
) -> list[tuple[Path, str]]:
    """(resolved path, display name) for every XML file the paths designate.

    Directory entries are named relative to the directory given; files given
    directly keep the path as given. Raises :class:`LoadError` when a path
    does not exist or a directory holds no XML.
    """
    if isinstance(paths, (str, os.PathLike)):
        paths = [paths]
    targets: list[tuple[Path, str]] = []
    seen: set[str] = set()
    for given in map(Path, paths):
        shown = display_path(given)
        try:
            mode = os.stat(given).st_mode
        except FileNotFoundError:
            raise LoadError(f"{shown}: no such file or directory") from None
        except OSError as error:
            raise LoadError(f"{shown}: {_reason(error)}") from None
        if stat.S_ISDIR(mode):
            try:
                entries = _xml_entries(given)
            except OSError as error:
                raise LoadError(f"{shown}: cannot list directory: {_reason(error)}") from None
            if not entries:
                raise LoadError(
                    f"{shown}: directory holds no *.xml files (give a Lensfun database "
                    "directory, a Lensfun checkout, or XML files)"
                )
            # The directory resolved once: a file in it that is not a link
            # resolves to the directory's real path and its own name.
            base = os.path.realpath(given)
            found = [
                (
                    os.path.realpath(given / name) if link else os.path.join(base, name),
                    display_path(name),
                )
                for name, link in entries
            ]
        elif stat.S_ISREG(mode):
            found = [(os.path.realpath(given), shown)]
        else:
            raise LoadError(f"{shown}: not a regular file or directory")
        for real, name in found:
            # The same file named twice (db and db/x.xml, or a link) is read once.
            if real not in seen:
                seen.add(real)
                targets.append((Path(real), name))
    return targets


def load(
    paths: Sequence[str | os.PathLike[str]] | str | os.PathLike[str],
    cache: EntryCache | None = None,
) -> LoadResult:
    """Load Lensfun XML from database directories and/or XML files.

    See :func:`expand` for how files are found and named; ``cache``, if
    given, supplies files parsed before and is given the ones parsed now.
    """
    return load_files(expand(paths), cache)


def read_regular_file(path: Path) -> bytes:
    """The bytes of the database file at ``path``, as :func:`load_files` reads it.

    Raises ``OSError`` when it cannot be read or is not a regular file (which
    is not even opened).
    """
    if not stat.S_ISREG(path.stat().st_mode):
        raise OSError(0, "not a regular file")
    return read_file(path)


def unreadable_file(name: str, error: OSError) -> tuple[list[DistortionEntry], str]:
    """The record and file error of a file that could not be read."""
    message = f"cannot read file: {_reason(error)}"
    return [DistortionEntry(name, *_error_row(0, STATUS_UNREADABLE, message))], message


def load_files(targets: Iterable[tuple[Path, str]], cache: EntryCache | None = None) -> LoadResult:
    """Load (path, display name) pairs; unreadable files become records."""
    result = LoadResult()
    for path, name in targets:
        path = path.resolve()
        try:
            data = read_regular_file(path)
        except OSError as os_error:
            entries, error = unreadable_file(name, os_error)
        else:
            cached = cache.get(path, data, name) if cache is not None else None
            if cached is not None:
                entries, error = cached
            else:
                entries, error = read_bytes(data, name)
                if cache is not None:
                    cache.put(path, data, entries, error)
        result.files.append(SourceFile(name, path, len(entries), error))
        result.entries.extend(entries)
    return result
