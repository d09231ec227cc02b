"""What the reader hands out: statuses, entries, lenses and one file's tables.

Every ``<distortion>``, ``<vignetting>`` and ``<tca>`` element of the input
gives exactly one row; one that cannot be audited (unknown model, missing or
non-numeric attribute, a file that is not well-formed) carries a status
other than ``ok`` and a message saying why, so that nothing in the input is
silently dropped. Rows are plain tuples: a database has tens of thousands,
and tuples are cheap to make, to cache and to turn into columns.
"""

from __future__ import annotations

import math
import re
from collections import namedtuple

#: Distortion models lensaudit audits, and the coefficient attributes each one
#: reads (a missing coefficient means 0, as in liblensfun).
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
#: A file that is not JSON (Gyroflow lens profiles), as ``xml_error`` is for XML.
STATUS_JSON_ERROR = "json_error"
STATUS_UNREADABLE = "unreadable"
STATUS_NOT_DATABASE = "not_database"

NAN = math.nan

# A plain decimal number as Lensfun writes it. Python's float() also accepts
# "1_0", "nan" and "infinity", which are not numbers in a lens database.
_DECIMAL = re.compile(r"\s*[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?\s*\Z", re.ASCII)
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
    """One ``<distortion>`` element with the lens context it applies to.

    ``file`` is the name the file is reported as, ``line`` the element's line.
    Coefficients are the raw model coefficients (``a b c`` for ptlens, ``k1``
    for poly3, ``k1 k2`` for poly5); those the model does not use are NaN.
    ``real_focal`` is NaN when neither a ``real-focal`` attribute nor a
    ``<real-focal-length>`` for its focal length gives it. Lengths are in
    millimetres. ``status`` is ``ok`` or why the entry is not audited,
    ``message`` says more.
    """

    __slots__ = ()


#: A distortion row: the fields of :class:`DistortionEntry` after ``file``.
ROW_FIELDS = tuple(ENTRY_FIELDS)[1:]


#: The stored refusal of tables read without judging what liblensfun refuses.
NOT_JUDGED = False


class SourceFile(namedtuple("SourceFile", ("name", "path", "entries", "error"), defaults=("",))):
    """A file that was read: its display ``name``, absolute ``path``, the number of
    distortion ``entries`` read from it, and its ``error`` ("" if none)."""

    __slots__ = ()


class Lens(
    namedtuple(
        "Lens",
        (
            "line",
            "maker",
            "model",
            "mounts",
            "type",
            "crop_factor",
            "aspect_ratio",
            "crop_text",
            "problem",
            "content",
            "mount_lines",
        ),
    )  # fmt: skip
):
    """One ``<lens>``: its line; maker and model (the untranslated names);
    mounts; type; crop factor and aspect ratio (NaN if not valid numbers);
    ``crop_text``, the ``<cropfactor>`` as written (None if there is none);
    ``problem``, why its entries cannot be audited ("" if they can); and
    ``content``, its elements other than its untranslated names and its
    calibrations, as (tag, sorted attributes, text) triples: with its
    calibration rows, what makes two lenses the same; ``mount_lines``, the
    line of each of its ``<mount>`` elements, counted from its own line."""

    __slots__ = ()


class Camera(
    namedtuple("Camera", ("line", "maker", "model", "mounts", "mount_lines", "crop_text"))
):
    """One top-level ``<camera>``: its line, maker and model (the untranslated
    names), its ``<mount>`` names and their lines (counted from its own), and
    its ``<cropfactor>`` as written (None if there is none)."""

    __slots__ = ()


class FileTables:
    """Everything the reader found in one file: its problem, lenses and rows.

    ``status`` is ``ok``, ``xml_error``, ``not_database`` or ``unreadable``;
    then ``line``, ``column``, ``error`` (the file's message, "" if none) and
    ``problem`` (the same without its position). ``lenses`` are
    :class:`Lens` records in document order; ``distortion`` the rows of its
    ``<distortion>`` elements (see :data:`ROW_FIELDS`), after one row that
    stands for the file when its status is not ``ok``; ``lens_of_row`` the
    index into ``lenses`` of each distortion row (None outside a lens);
    ``omitted`` the coefficient attributes each distortion row's element
    leaves out. ``cameras`` are :class:`Camera` records; ``mount_names`` the
    (line, name) of each untranslated ``<name>`` of a top-level ``<mount>``.
    ``refusal`` is (line, reason, lenses kept) of where liblensfun stops
    loading the file (:mod:`lensaudit.read.liblensfun`), with the number of
    ``lenses`` before that point, which liblensfun holds; None where it loads
    the file. For a file that is not well-formed, the line is libxml2's and
    the reason starts with "not well-formed XML", unless liblensfun stops
    earlier. It is judged only when asked for (``refusals=True`` of
    :func:`lensaudit.read.read` and the others); ``refusal_judged`` says
    whether it was.
    ``vignetting`` and ``tca`` are their rows (see
    :mod:`lensaudit.read.tables`), None until read; ``lens_of_vignetting`` and
    ``lens_of_tca`` the lens index of each. ``encoding`` is (line, problem)
    where the file's XML declaration names an encoding its bytes are not in
    (:func:`lensaudit.read.xml.encoding_disagreement`), None where it does not.

    ``name`` is how the file is shown, ``path`` where it is (None for a file
    read from git), ``digest`` the digest of its bytes (b"" if unreadable).
    """

    __slots__ = (
        "name", "path", "digest", "status", "line", "column", "error", "problem",
        "lenses", "distortion", "lens_of_row", "omitted", "cameras", "mount_names",
        "refusal", "refusal_judged", "vignetting", "tca", "lens_of_vignetting", "lens_of_tca",
        "encoding",
    )  # fmt: skip

    #: The fields that the cache keeps, in order (all but name, path and digest).
    STORED = (
        "status", "line", "column", "error", "problem",
        "lenses", "distortion", "lens_of_row", "omitted", "cameras", "mount_names",
        "refusal", "encoding",
    )  # fmt: skip

    def __init__(self, name: str, path: object, digest: bytes, values: tuple) -> None:
        self.name = name
        self.path = path
        self.digest = digest
        (
            self.status, self.line, self.column, self.error, self.problem,
            lenses, self.distortion, self.lens_of_row, self.omitted, cameras, self.mount_names,
            refusal, encoding,
        ) = values  # fmt: skip
        self.encoding: tuple | None = tuple(encoding) if encoding else None  # (line, problem)
        # NOT_JUDGED (False) where the reader was not asked to judge it.
        self.refusal_judged = refusal is not NOT_JUDGED
        self.refusal: tuple[int, str, int] | None = (
            tuple(refusal) if refusal not in (None, NOT_JUDGED) else None  # type: ignore[assignment]
        )
        self.lenses = [Lens(*lens) for lens in lenses]
        self.cameras = [Camera(*camera) for camera in cameras]
        self.vignetting: list[tuple] | None = None
        self.tca: list[tuple] | None = None
        self.lens_of_vignetting: list[int | None] | None = None
        self.lens_of_tca: list[int | None] | None = None

    def set_calibrations(self, values: tuple) -> None:
        """Set (vignetting rows, tca rows, lens index of each vignetting row, of
        each tca row), as the cache keeps them."""
        self.vignetting, self.tca, self.lens_of_vignetting, self.lens_of_tca = values

    def named(self, name: str, path: object) -> FileTables:
        """These tables for another file of the same bytes, shown as ``name``
        at ``path``: what they hold is shared, as it is made of the bytes alone."""
        tables = object.__new__(FileTables)
        for slot in FileTables.__slots__:
            setattr(tables, slot, getattr(self, slot))
        tables.name, tables.path = name, path
        return tables

    @property
    def elements(self) -> int:
        """The number of ``<distortion>`` elements found (the file's own row aside)."""
        return len(self.distortion) - (self.status != STATUS_OK)

    def entries(self) -> list[DistortionEntry]:
        """The distortion rows as :class:`DistortionEntry` records."""
        name = self.name
        return [DistortionEntry(name, *row) for row in self.distortion]

    def source_file(self) -> SourceFile:
        """The file as a :class:`SourceFile` record."""
        return SourceFile(self.name, self.path, len(self.distortion), self.error)


def parse_number(text: str | None) -> float:
    """Parse a decimal number as written in Lensfun XML.

    Raises ``ValueError`` with a short reason for anything else, including
    ``nan`` and ``inf`` spelled out, which Lensfun never means, and digits
    other than ASCII ones (a full-width digit, say) or a no-break space.
    """
    if text is None:
        raise ValueError("missing")
    try:
        value = float(text)
    except ValueError:
        value = None
    # float() alone is too lenient: it takes "1_0", "nan", "infinity",
    # non-ASCII digits and spaces. Accept its answer only for plain finite ASCII.
    if value is not None and value - value == 0 and text.isascii() and "_" not in text:
        return value
    if text.isascii() and _DECIMAL.match(text):
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
