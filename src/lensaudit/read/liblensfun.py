"""Where liblensfun (Lensfun master) stops loading a file, and why.

liblensfun reads a database file with GLib's GMarkup and its own callbacks
(``libs/lensfun/database.cpp``, ``lfDatabase::Load``) and gives up at the
first thing it does not accept; the lenses completed before that point stay
in its database, every lens from there on is lost to its users. What it does
not accept:

- an element it does not know, an attribute an element does not take, or a
  value outside an attribute's list (``model=`` of a calibration, ``mode=``
  of a crop);
- an element in the wrong parent (``<lens>`` outside ``<lensdatabase>``,
  ``<distortion>`` outside ``<calibration>``...), attributes on an element
  that takes none, nesting deeper than :data:`MAX_DEPTH` elements;
- ``<lensdatabase version=>`` outside :data:`VERSIONS` (read as C's
  ``atoi`` reads it, so ``"2.5"`` is 2 and ``"x"`` is 0);
- text where nothing may stand (``<maker>`` text outside a lens or camera,
  ``<compat>`` outside a mount...), a ``<type>`` it does not know;
- at ``</lens>``, ``</camera>`` and ``</mount>``, a definition its
  ``Check()`` refuses: a lens without model or mount, with a minimum focal
  length or aperture above its maximum, or a crop factor not positive or an
  aspect ratio below 1 (``lens.cpp``); a camera without maker, model, mount
  or a positive crop factor (``camera.cpp``); a mount without a name;
- GMarkup's own errors: a UTF-16 or UTF-32 file, a file that does not
  start with ``<`` (a byte-order mark), bytes that are not UTF-8 whatever
  the XML declaration says (GMarkup reads every file as UTF-8 and takes the
  declaration for a processing instruction), and markup that is not
  well-formed (which lensaudit reports as ``xml-error`` already).

Lines are those GMarkup reports: where it stands when it gives up, that is
just past the ``>`` of the start or end tag at fault, or at the ``<`` that
ends a text (a line break right after a ``>`` already counts as the next
line). Numbers are read as C's ``atof`` reads them (hexadecimal included)
and kept in single precision; where a lens does not give its focal length
or aperture range, it is guessed from its model's name and calibrations as
liblensfun guesses it. What is not seen here: text inside CDATA sections
(GMarkup skips it; lxml gives it as text), the tails of the children of a
root other than ``<lensdatabase>``, the ``lang=`` of an empty element (which
liblensfun applies to the next text it reads).

Walking every element in Python would cost more than reading the file, so
:func:`shaped_until` first looks at the file's bytes at once: up to the
line it gives, every top-level element has a shape liblensfun accepts
whatever its values (known elements in their places, known attributes,
known ``model=`` and ``<type>`` values, positive crop factors, no text
where none may stand). Of such an element only the values a reader's
record holds are left to judge (:func:`lens_accepted`,
:func:`camera_accepted`, :func:`mount_accepted`); anything else is walked.
"""

from __future__ import annotations

import math
import re
import struct

from .xml import declared_encoding, declares_other_encoding, wide_encoding

# typing only for type checkers: a scan from the cache never imports it.
TYPE_CHECKING = False
if TYPE_CHECKING:
    from collections.abc import Callable, Sequence
    from typing import Any

#: What a refusal is: (line, reason), the reason in liblensfun's terms.
Refusal = tuple  # (int, str)

#: How the reason of a refusal at markup that is not well-formed starts.
NOT_WELL_FORMED = "not well-formed XML"
#: The database versions liblensfun master reads (LF_MIN..LF_MAX_DATABASE_VERSION).
VERSIONS = range(0, 3)
#: The deepest nesting liblensfun's element stack holds.
MAX_DEPTH = 16

_ROOT = "lensdatabase"
#: GMarkup's white space, and what liblensfun strips from the start of a text.
_SPACE = " \t\n\r"

# Each element liblensfun knows: the parents it may have (None: any), and its
# attributes: None for none at all, else a dict of name -> the values allowed
# (None: any value); an attribute not in it is "unknown" (``unk_attr``) for
# the calibration elements, a "bad attribute" (``bad_attr``) for the others.
_CALIBRATION = ("calibration",)
_LANG = {"lang": None}
_ELEMENTS: dict[str, tuple[tuple[str, ...] | None, dict | None, bool]] = {
    "mount": ((_ROOT, "camera", "lens"), None, False),
    "camera": ((_ROOT,), None, False),
    "lens": ((_ROOT,), None, False),
    "focal": (("lens",), dict.fromkeys(("min", "max", "value")), False),
    "aperture": (("lens",), dict.fromkeys(("min", "max", "value")), False),
    "center": (("lens",), dict.fromkeys(("x", "y")), False),
    "type": (("lens",), None, False),
    "calibration": (("lens",), dict.fromkeys(("cropfactor", "aspect-ratio")), False),
    "distortion": (
        _CALIBRATION,
        {
            "model": ("none", "poly3", "poly5", "ptlens", "acm"),
            **dict.fromkeys(("focal", "real-focal", "a", "k1", "b", "k2", "c", "k3", "k4", "k5")),
        },
        True,
    ),
    "tca": (
        _CALIBRATION,
        {
            "model": ("none", "linear", "poly3", "acm"),
            **dict.fromkeys(
                ("focal", "kr", "vr", "alpha0", "kb", "vb", "beta0", "cr", "alpha1", "cb", "beta1")
                + ("br", "alpha2", "bb", "beta2", "alpha3", "beta3", "alpha4", "beta4")
                + ("alpha5", "beta5")
            ),
        },
        True,
    ),
    "vignetting": (
        _CALIBRATION,
        {
            "model": ("none", "pa", "acm"),
            **dict.fromkeys(
                ("focal", "aperture", "distance", "k1", "alpha1", "k2", "alpha2", "k3", "alpha3")
            ),
        },
        True,
    ),
    "crop": (
        _CALIBRATION,
        {
            "mode": ("no_crop", "crop_rectangle", "crop_circle"),
            **dict.fromkeys(("focal", "left", "right", "top", "bottom")),
        },
        True,
    ),
    "field_of_view": (_CALIBRATION, dict.fromkeys(("focal", "fov")), True),
    "maker": (None, _LANG, True),
    "model": (None, _LANG, True),
    "variant": (None, _LANG, True),
    "name": (None, _LANG, True),
    "compat": (None, None, False),
    "cropfactor": (None, None, False),
    "aspect-ratio": (None, None, False),
}
#: The calibration entries, which liblensfun adds to a lens's calibration set.
_ENTRIES = frozenset(("distortion", "tca", "vignetting", "crop", "field_of_view"))
#: Which definition a text may stand in, by the element it is in.
_TEXT_OWNERS = {
    "name": ("mount",),
    "maker": ("camera", "lens"),
    "model": ("camera", "lens"),
    "variant": ("camera",),
    "mount": ("camera", "lens"),
    "compat": ("mount",),
    "cropfactor": ("camera", "lens"),
    "aspect-ratio": ("lens",),
    "type": ("lens",),
}
#: The lens types of ``<type>``, compared as liblensfun compares them.
LENS_TYPES = frozenset(
    ("rectilinear", "fisheye", "panoramic", "equirectangular", "orthographic")
    + ("stereographic", "equisolid", "fisheye_thoby")
)
#: The float limits liblensfun's guesses start from (C's FLT_MAX and FLT_MIN).
_FLT_MAX = 3.4028234663852886e38
_FLT_MIN = 1.1754943508222875e-38

# C's strtod/atof: the longest prefix that is a number (decimal, hexadecimal,
# infinity or NaN), else 0.
_ATOF = re.compile(
    r"[ \t\n\v\f\r]*([+-]?)"
    r"(?:(0[xX](?:[0-9a-fA-F]+\.?[0-9a-fA-F]*|\.[0-9a-fA-F]+)(?:[pP][+-]?\d+)?)"
    r"|((?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)|(inf(?:inity)?|nan(?:\([0-9A-Za-z_]*\))?))",
    re.IGNORECASE | re.ASCII,
)
_ATOI = re.compile(r"[ \t\n\v\f\r]*([+-]?\d+)", re.ASCII)


def atof(text: str) -> float:
    """A text as C's ``atof`` reads it: its longest numeric prefix (``"0x10"``
    is 16, ``"2.8/50"`` is 2.8), else 0."""
    found = _ATOF.match(text)
    if found is None:
        return 0.0
    sign, hexadecimal, decimal, special = found.groups()
    if decimal is not None:
        value = float(decimal)
    elif special is not None:
        value = math.inf if special[0] in "iI" else math.nan
    else:
        digits = hexadecimal[2:]
        try:
            value = float.fromhex(digits if "p" in digits.lower() else digits + "p0")
        except OverflowError:
            value = math.inf
    return -value if sign == "-" else value


def atoi(text: str) -> int:
    """A text as glibc's ``atoi`` reads it: ``strtol``'s value, clamped to a
    long and truncated to an int."""
    found = _ATOI.match(text)
    if not found:
        return 0
    value = max(-(1 << 63), min((1 << 63) - 1, int(found.group(1))))
    return (value + (1 << 31)) % (1 << 32) - (1 << 31)


def single(value: float) -> float:
    """A double as liblensfun keeps it in a float (too large: infinite)."""
    try:
        return struct.unpack("f", struct.pack("f", value))[0]
    except OverflowError:
        return math.copysign(math.inf, value)


def stripped(text: str | None) -> str:
    """A text without the white space liblensfun skips at its start."""
    return text.lstrip(_SPACE) if text else ""


def leading_refusal(data: bytes, utf8_checked: bool = False) -> tuple | None:
    """(line, reason, lenses kept) where GMarkup refuses a file for its bytes,
    whatever its elements: a UTF-16 or UTF-32 file (on its first line:
    GMarkup reads UTF-8 only), one that does not start with ``<`` after
    white space (a byte-order mark, say), or (in a file that is otherwise
    well-formed) the first byte that is not UTF-8, whatever the XML
    declaration says, where it keeps the lenses ended before; with
    ``utf8_checked``, the bytes are known to be UTF-8 already."""
    wide = wide_encoding(data)
    if wide is not None:
        return 1, wide[1], 0
    start = _LEADING_SPACE.match(data).end()  # type: ignore[union-attr]
    if start < len(data) and data[start] != 0x3C:  # "<"
        line = data.count(b"\n", 0, start) + 1
        what = "a byte-order mark" if data.startswith(b"\xef\xbb\xbf") else "text"
        return line, f"the file starts with {what}, not with an element", 0
    if not utf8_checked and not data.isascii():
        try:
            data.decode("utf-8")
        except UnicodeDecodeError as error:
            line = data.count(b"\n", 0, error.start) + 1
            said = (
                f" (the file declares {declared_encoding(data)}; liblensfun reads every "
                f"file as UTF-8)"
                if declares_other_encoding(data)
                else ""
            )
            reason = f"byte 0x{data[error.start]:02X} is not UTF-8{said}"
            return line, reason, data.count(b"</lens>", 0, error.start)
    return None


_LEADING_SPACE = re.compile(rb"[ \t\n\r]*+")


def root_refusal(root: Any, line: int) -> Refusal | None:
    """Where liblensfun refuses a document's root element (its start tag and
    its first text); ``line`` is the line of the end of its start tag."""
    name = root.tag if isinstance(root.tag, str) else ""
    problem = start_problem(name, None, root.attrib, 1)
    if problem is not None:
        return _after_start(root, line), problem
    text = stripped(root.text)
    if text and name in _TEXT_OWNERS:
        return line + (root.text or "").count("\n"), _text_context(name, text)
    return None


def start_problem(name: str, parent: str | None, attributes: Any, depth: int) -> str | None:
    """Why liblensfun refuses the start tag of element ``name`` (in ``parent``,
    None for the root; ``depth`` 1 for the root), or None."""
    if depth > MAX_DEPTH:
        return f"<{name}> is nested deeper than {MAX_DEPTH} elements"
    if name == _ROOT:
        if parent is not None:
            return f"<{name}> in the wrong place (inside <{parent}>)"
        version = 0
        # By name, each value fetched only where needed: lxml fetches a value by
        # searching the element's attributes, so that items() takes time
        # quadratic in their number (a start tag with 100,000 of them).
        for attribute in attributes.keys():
            if attribute != "version":
                return f"bad attribute {_shown(attribute, attributes[attribute])} on <{name}>"
            version = atoi(attributes[attribute])
        if version not in VERSIONS:
            return f"database version {version} is not one of 0, 1, 2"
        return None
    known = _ELEMENTS.get(name)
    if known is None:
        return f"unknown element <{_clip(name)}>"
    parents, allowed, unknown_attributes = known
    if parents is not None and parent not in parents:
        where = f"inside <{parent}>" if parent is not None else "as the root"
        return f"<{name}> in the wrong place ({where})"
    if allowed is None:
        if len(attributes):
            return f"<{name}> takes no attributes (has {_clip(next(iter(attributes)))}=)"
        return None
    for attribute in attributes.keys():  # by name, as above
        if attribute not in allowed:
            if unknown_attributes:
                return f"unknown attribute {_clip(attribute)}= on <{name}>"
            return f"bad attribute {_shown(attribute, attributes[attribute])} on <{name}>"
        values = allowed[attribute]
        if values is not None and attributes[attribute] not in values:
            return f"bad attribute {_shown(attribute, attributes[attribute])} on <{name}>"
    return None


def _ratio(numerator: float, denominator: float) -> float:
    """``numerator / denominator`` as C divides doubles (no exception)."""
    try:
        return numerator / denominator
    except ZeroDivisionError:
        if numerator == 0 or math.isnan(numerator):
            return math.nan
        return math.copysign(math.inf, numerator) * math.copysign(1.0, denominator)
    except OverflowError:
        return math.copysign(math.inf, numerator) * math.copysign(1.0, denominator)


def _clip(text: str) -> str:
    return text if len(text) <= 40 else text[:40] + "..."


def _shown(attribute: str, value: str) -> str:
    return f"{_clip(attribute)}={_clip(value)!r}"


def _text_context(name: str, text: str) -> str:
    return f"text {_clip(text.strip())!r} in <{name}> where no definition takes it"


def _after_start(element: Any, line: int) -> int:
    """GMarkup's line just past a start tag's ``>`` (which ends on ``line``)."""
    text = element.text
    return line + 1 if text and text[0] == "\n" else line


class _Definition:
    """What liblensfun has gathered of the lens, camera or mount being read."""

    __slots__ = (
        "kind", "texts", "model", "focal", "aperture", "crop", "aspect", "calibrated", "guesses",
    )  # fmt: skip

    def __init__(self, kind: str) -> None:
        self.kind = kind
        self.texts: set[str] = set()  # the elements that gave a text
        # The lens's model as liblensfun keeps it: the last text without lang=,
        # or, before any, the language code of the first translation.
        self.model: str | None = None
        self.focal = [0.0, 0.0]
        self.aperture = [0.0, 0.0]
        # The camera's crop factor starts at 0, the lens's at 1 (aspect ratio 1.5).
        self.crop = 0.0 if kind == "camera" else 1.0
        self.aspect = 1.5
        self.calibrated: tuple[float, float] | None = None  # the calibration set's attributes
        self.guesses: list[tuple[str, float]] = []  # ("focal" / "aperture", value)

    def start(self, name: str, attributes: Any) -> None:
        """What a start tag inside the definition gives it."""
        if name in ("focal", "aperture"):
            pair = self.focal if name == "focal" else self.aperture
            for attribute, value in attributes.items():
                number = single(atof(value))
                if attribute == "min":
                    pair[0] = number
                elif attribute == "max":
                    pair[1] = number
                else:
                    pair[0] = pair[1] = number
        elif name in _ENTRIES:
            self.calibrated = (self.crop, self.aspect)
            focal = attributes.get("focal")
            self.guesses.append(("focal", single(atof(focal)) if focal is not None else 0.0))
            if name == "vignetting":
                aperture = attributes.get("aperture")
                number = single(atof(aperture)) if aperture is not None else 0.0
                self.guesses.append(("aperture", number))

    def text(self, name: str, text: str, lang: str | None) -> str | None:
        """Take a text of element ``name`` (with its ``lang=``); why liblensfun
        refuses it, or None."""
        self.texts.add(name)
        if name == "model":
            if lang is None or self.model is None:
                self.model = text if lang is None else lang
        elif name == "cropfactor":
            self.crop = single(atof(text))
        elif name == "aspect-ratio" and self.kind == "lens":
            self.aspect = _aspect_ratio(text)
        elif name == "type" and " ".join(text.split()).lower() not in LENS_TYPES:
            return f"lens type {_clip(text.strip())!r} is not one liblensfun knows"
        return None

    def problem(self) -> str | None:
        """Why ``Check()`` refuses the definition at its end tag, or None."""
        if self.kind == "mount":
            return None if "name" in self.texts else "a <mount> without a <name>"
        if self.kind == "camera":
            missing = [n for n in ("maker", "model", "mount") if n not in self.texts]
            if missing:
                return f"a <camera> without {', '.join(f'<{n}>' for n in missing)}"
            if self.crop <= 0:
                return "a <camera> whose crop factor is not positive"
            return None
        if "model" not in self.texts:
            return "a <lens> without a <model>"
        if "mount" not in self.texts:
            return "a <lens> without a <mount>"
        focal, aperture = self._guessed()
        if focal[0] > focal[1]:
            return f"a <lens> whose minimum focal length {focal[0]:g} exceeds its maximum"
        if aperture[1] and aperture[0] > aperture[1]:
            return f"a <lens> whose minimum aperture {aperture[0]:g} exceeds its maximum"
        for crop, aspect in (self.calibrated or (1.0, 1.5), (self.crop, self.aspect)):
            if crop <= 0:
                return f"a <lens> whose crop factor {crop:g} is not positive"
            if aspect < 1:
                return f"a <lens> whose aspect ratio {aspect:g} is below 1"
        return None

    def _guessed(self) -> tuple[list[float], list[float]]:
        """Focal length and aperture ranges after liblensfun fills in those not
        given from the model's name and the calibrations
        (``lfLens::GuessParameters``)."""
        focal, aperture = list(self.focal), list(self.aperture)
        if aperture[0] and focal[0]:
            if not focal[1]:
                focal[1] = focal[0]
            return focal, aperture
        low_focal, high_focal = _FLT_MAX, _FLT_MIN
        low_aperture, high_aperture = _FLT_MAX, _FLT_MIN
        named = name_guess(self.model) if self.model is not None else None
        if named is not None:
            low, high, widest = named
            low_focal = low if low is not None else low_focal
            high_focal = high if high is not None else high_focal
            low_aperture = widest if widest is not None else low_aperture
        for what, value in self.guesses:
            if what == "focal":
                low_focal = value if value < low_focal else low_focal
                high_focal = value if value > high_focal else high_focal
            else:
                low_aperture = value if value < low_aperture else low_aperture
                high_aperture = value if value > high_aperture else high_aperture
        for pair, low, high in (
            (focal, low_focal, high_focal),
            (aperture, low_aperture, high_aperture),
        ):
            if low != _FLT_MAX and not pair[0]:
                pair[0] = low
            if high != _FLT_MIN and not pair[1]:
                pair[1] = high
        if not focal[1]:
            focal[1] = focal[0]
        return focal, aperture


#: Models whose name liblensfun does not guess from.
_NOT_GUESSED = ("adapter", "reducer", "booster", "extender", "converter", "magnifier")
# liblensfun's patterns for a model name (``lens.cpp``), matched against the
# whole name in bytes as ``std::regex`` does: "." takes no line end, and
# [[:space:]] is C's white space. Each: the groups of min focal, max focal
# and min aperture. ("[0.9]" is liblensfun's own, a class of "0", "." and "9".)
_ANY = rb"[^\n\r]"
_C_SPACE = rb"[ \t\n\v\f\r]"
_EXTENDER = re.compile(_ANY + rb"*?[0-9](\.[0.9]+)?x" + _ANY + rb"*")
_NAME_PATTERNS = (
    (
        re.compile(
            rb"[^:]*?([0-9]+[0-9.]*)[-]?([0-9]+[0-9.]*)?(mm)" + _C_SPACE
            + rb"+(f/|f|1/|1:)?([0-9.]+)(-[0-9.]+)?" + _ANY + rb"*"
        ),
        (1, 2, 5),
    ),
    (
        re.compile(
            _ANY + rb"*?1:([0-9.]+)[-]?([0-9.]+)?" + _C_SPACE
            + rb"+([0-9.]+)[-]?([0-9.]+)?(mm)?" + _ANY + rb"*"
        ),
        (3, 4, 1),
    ),
    (
        re.compile(
            _ANY + rb"*?([0-9.]+)[-]?([0-9.]+)?" + _C_SPACE + rb"*/" + _C_SPACE
            + rb"*([0-9.]+)[-]?([0-9.]+)?" + _ANY + rb"*"
        ),
        (3, 4, 1),
    ),
)  # fmt: skip


def name_guess(model: str) -> tuple[float | None, float | None, float | None] | None:
    """(min focal, max focal, min aperture) liblensfun reads from a lens's
    model name, each None where the name gives none; None where it reads
    nothing (no pattern fits, or the name says adapter, converter...)."""
    if any(word in model for word in _NOT_GUESSED):
        return None
    return _name_numbers(model)


def _name_numbers(model: str) -> tuple[float | None, float | None, float | None] | None:
    """:func:`name_guess` without the names liblensfun leaves out."""
    name = model.encode("utf-8", "surrogateescape")
    if _EXTENDER.fullmatch(name) is not None:
        return None
    for pattern, groups in _NAME_PATTERNS:
        found = pattern.fullmatch(name)
        if found is not None:
            texts = [found.group(group) for group in groups]
            return tuple(  # type: ignore[return-value]
                single(atof(text.decode("ascii"))) if text is not None else None for text in texts
            )
    return None


def piece_refusal(piece: Any, line_of: Callable[[Any], int]) -> Refusal | None:
    """Where liblensfun refuses a child of the root (with everything in it),
    or None: judged in its parent (the root), as liblensfun reads it after
    everything before it was accepted."""
    parent = piece.getparent()
    parent_name = parent.tag if parent is not None and isinstance(parent.tag, str) else None
    return _Walk(line_of).element(piece, parent_name, 2, None)


class _Walk:
    """One piece walked in document order, as liblensfun's callbacks see it."""

    __slots__ = ("line_of",)

    def __init__(self, line_of: Callable[[Any], int]) -> None:
        self.line_of = line_of

    def element(
        self, element: Any, parent: str | None, depth: int, definition: _Definition | None
    ) -> Refusal | None:
        name = element.tag
        if not isinstance(name, str):  # a comment or processing instruction: skipped
            return None
        attributes = element.attrib
        problem = start_problem(name, parent, attributes, depth)
        if problem is not None:
            return _after_start(element, self.line_of(element)), problem
        own = None
        if depth == 2 and name in ("lens", "camera", "mount") and parent == _ROOT:
            definition = own = _Definition(name)
        elif definition is not None and definition.kind == "lens":
            definition.start(name, attributes)
        # The texts: before the first child, and after each child.
        refusal = self.text(element, name, element.text, definition, None)
        if refusal is not None:
            return refusal
        for child in element:
            refusal = self.element(child, name, depth + 1, definition)
            if refusal is None:
                refusal = self.text(element, name, child.tail, definition, child)
            if refusal is not None:
                return refusal
        if own is not None:
            problem = own.problem()
            if problem is not None:
                line = self.end_line(element)
                tail = element.tail
                return (line + 1 if tail and tail[0] == "\n" else line), problem
        return None

    def text(
        self,
        element: Any,
        name: str,
        text: str | None,
        definition: _Definition | None,
        after: Any,
    ) -> Refusal | None:
        """Judge the text of ``element`` that starts after child ``after`` (None:
        after its start tag)."""
        owners = _TEXT_OWNERS.get(name)
        if owners is None or not text:
            return None
        text = stripped(text)
        if not text:
            return None
        if definition is None or definition.kind not in owners:
            problem: str | None = _text_context(name, text)
        else:
            problem = definition.text(name, text, element.get("lang"))
        if problem is None:
            return None
        start = self.line_of(element) if after is None else self.end_line(after)
        return start + (element.text if after is None else after.tail).count("\n"), problem

    def end_line(self, element: Any) -> int:
        """The line of the ``>`` that ends an element (a comment's, an
        instruction's own line is that of its end already)."""
        if not isinstance(element.tag, str):
            return element.sourceline or 0
        if len(element) == 0:
            return self.line_of(element) + (element.text or "").count("\n")
        last = element[-1]
        return self.end_line(last) + (last.tail or "").count("\n")


# ---------------------------------------------------------------------------
# The screen: shapes liblensfun accepts whatever their values
# ---------------------------------------------------------------------------

#: More than any file has: every line of a file that passes the screen.
EVERY_LINE = 1 << 62

_S = rb"[ \t\r\n]"
_VALUE = rb"""(?:"[^"<]*+"|'[^'<]*+')"""


def _one_of(words: Sequence[str]) -> bytes:
    return b"(?:" + b"|".join(re.escape(word).encode() for word in words) + b")"


def _attributes(name: str) -> bytes:
    """Any number of the attributes element ``name`` takes (those with a list
    of values: one of them, as written), then white space."""
    allowed = _ELEMENTS[name][1] if name != _ROOT else {"version": None}
    branches = [
        _one_of([a for a, values in allowed.items() if values is None])
        + _S
        + rb"*+="
        + _S
        + rb"*+"
        + _VALUE
    ]
    for attribute, values in allowed.items():
        if values is not None:
            listed = _one_of(values)
            branches.append(
                re.escape(attribute).encode() + _S + rb"*+=" + _S + rb"*+"
                + rb'(?:"' + listed + rb'"|\'' + listed + rb"')"
            )  # fmt: skip
    return rb"(?:" + _S + rb"++(?:" + b"|".join(branches) + rb"))*+" + _S + rb"*+"


def _usual_entry(name: str, order: tuple[str, ...]) -> bytes:
    """A calibration entry written the usual way (one space, double quotes, the
    attributes in ``order``, each optional): a quicker path for the common case."""
    allowed = _ELEMENTS[name][1]
    parts = []
    for attribute in order:
        values = allowed[attribute]  # type: ignore[index]
        value = rb'"' + _one_of(values) + rb'"' if values is not None else rb'"[^"<]*+"'
        parts.append(b"(?: " + re.escape(attribute).encode() + b"=" + value + b"|)")
    return b"<" + name.encode() + b"".join(parts) + rb" ?/>"


def _empty(name: str) -> bytes:
    return (
        b"<"
        + name.encode()
        + _attributes(name)
        + rb"(?:/>|>"
        + _S
        + rb"*+</"
        + name.encode()
        + _S
        + rb"*+>)"
    )


def _text(name: str, text: bytes) -> bytes:
    """An element of text ``text``; with ``lang=``, text that is not blank (else
    liblensfun would apply its language to the next text)."""
    tag = name.encode()
    end = rb"</" + tag + _S + rb"*+>"
    shape = b"<" + tag + _S + rb"*+(?:/>|>" + text + end + b")"
    if _ELEMENTS[name][1] is _LANG:
        shape += (
            b"|<" + tag + _S + rb"++lang" + _S + rb"*+=" + _S + rb"*+" + _VALUE + _S + rb"*+>"
            + _S + rb"*+[^<&\s]" + text + end
        )  # fmt: skip
    return shape


_MISC = rb"(?:<!--(?:[^-]++|-(?!->))*+-->|<\?(?:[^?]++|\?(?!>))*+\?>)"
_PLAIN = rb"[^<]*+"
# A model's text, which liblensfun matches against its name patterns: no line
# end, written or as a character reference ("." of a pattern takes none).
_NAME = rb"[^<&\r\n]*+(?:&(?:amp|lt|gt|quot|apos);[^<&\r\n]*+)*+"
# A crop factor liblensfun reads as positive, also in single precision.
_POSITIVE = rb"[ \t\r\n]*+(?:[1-9][0-9]{0,9}(?:\.[0-9]*+)?|0?\.0{0,6}[1-9][0-9]*+)[ \t\r\n]*+"
_TYPE = rb"[ \t\r\n]*+" + _one_of(sorted(LENS_TYPES)) + rb"[ \t\r\n]*+"
# The attributes of calibration entries in the order Lensfun's files mostly
# have them (any order is accepted, more slowly).
_USUAL_ORDER = {
    "vignetting": ("model", "focal", "aperture", "distance", "k1", "k2", "k3"),
    "distortion": ("model", "focal", "real-focal", "a", "b", "c", "k1", "k2"),
    "tca": ("model", "focal", "br", "cr", "vr", "bb", "cb", "vb", "kr", "kb"),
}


def _shapes() -> tuple[re.Pattern[bytes], re.Pattern[bytes]]:
    """The screen's patterns: a document up to the first element of a shape
    it does not vouch for, and the end of a document."""

    def content(name: str, children: list[bytes], text: bytes = rb"[^<]++") -> bytes:
        tag = name.encode()
        inner = b"|".join([text, *children, _MISC])
        return b"<" + tag + _S + rb"*+>(?:" + inner + rb")*+</" + tag + _S + rb"*+>"

    entries = [_usual_entry(name, order) for name, order in _USUAL_ORDER.items()]
    entries += [_empty(name) for name in sorted(_ENTRIES)]
    calibration = (
        rb"<calibration" + _attributes("calibration") + rb"(?:/>|>(?:[^<]++|"
        + b"|".join([*entries, _MISC]) + rb")*+</calibration" + _S + rb"*+>)"
    )  # fmt: skip
    lens = content(
        "lens",
        [
            calibration,
            _text("model", _NAME),
            _text("maker", _PLAIN),
            _text("mount", _PLAIN),
            _text("cropfactor", _POSITIVE),
            _empty("focal"),
            _empty("aperture"),
            _text("aspect-ratio", _PLAIN),
            _text("type", _TYPE),
            _empty("center"),
        ],
    )
    camera = content(
        "camera",
        [
            _text("maker", _PLAIN),
            _text("model", _PLAIN),
            _text("variant", _PLAIN),
            _text("mount", _PLAIN),
            _text("cropfactor", _POSITIVE),
        ],
    )
    mount = content("mount", [_text("name", _PLAIN), _text("compat", _PLAIN)], _S + b"++")
    document = re.compile(
        rb"(?:[^<]++|<!DOCTYPE[^\[>]*+>|" + _MISC + rb")*+<" + _ROOT.encode()
        + _attributes(_ROOT) + rb">(?:[^<]++|" + b"|".join([lens, camera, mount, _MISC]) + rb")*+"
    )  # fmt: skip
    end = re.compile(rb"</" + _ROOT.encode() + _S + rb"*+>(?:" + _S + rb"++|" + _MISC + rb")*+")
    return document, end


_SHAPED, _END = _shapes()


def shaped_until(data: bytes) -> int:
    """The line before which every top-level element of a well-formed document
    ``data`` (line ends normalized) has a shape liblensfun accepts whatever
    its values (see the module's description): :data:`EVERY_LINE` for the
    whole document, 0 for none of it."""
    found = _SHAPED.match(data)
    if found is None:
        return 0
    stop = found.end()
    if _END.fullmatch(data, stop) is not None:
        return EVERY_LINE
    return data.count(b"\n", 0, stop) + 1


def lens_accepted(model: str, mounts: Sequence[str], content: Sequence[tuple]) -> bool:
    """Whether ``Check()`` accepts a lens of a shape :func:`shaped_until`
    vouches for, judged on what the reader keeps of it: its model (the last
    without ``lang=``), the texts of its mounts, and its other children as
    (tag, sorted attributes, text). False where that does not tell."""
    if not model or not any(mounts):
        return False
    focal = [0.0, 0.0]
    aperture = [0.0, 0.0]
    for tag, attributes, text in content:
        if tag == "focal" or tag == "aperture":
            pair = focal if tag == "focal" else aperture
            if len(attributes) > 1 and any(name == "value" for name, _ in attributes):
                return False  # their order counts, and is not kept
            for name, value in attributes:
                number = single(atof(value))
                if name != "max":
                    pair[0] = number
                if name != "min":
                    pair[1] = number
        elif tag == "aspect-ratio" and not _aspect_ratio(text) >= 1:
            return False
    if aperture[0] and focal[0]:  # nothing is guessed
        return (not focal[1] or focal[0] <= focal[1]) and (
            not aperture[1] or aperture[0] <= aperture[1]
        )
    # Guessed from the name and calibrations: a range not given at all comes
    # out in order, but for a name whose focal lengths are out of order.
    if focal[0] or focal[1]:
        if not (focal[0] and focal[1] and focal[0] <= focal[1]):
            return False
    elif "-" in model and _maybe_decreasing(model):
        named = _name_numbers(model)
        if named is not None and named[1] is not None and not named[0] <= named[1]:  # type: ignore[operator]
            return False
    if aperture[0] or aperture[1]:
        return bool(aperture[0] and aperture[1] and aperture[0] <= aperture[1])
    return True


# A range in a name: the numbers before and after a "-".
_RANGE = re.compile(r"(?<![0-9.])([0-9.]+)-(?=([0-9.]+))", re.ASCII)


def _maybe_decreasing(model: str) -> bool:
    """Whether the focal lengths liblensfun reads from a model's name may be out
    of order: its patterns read a maximum only after a "-", as the whole run
    of digits and dots there, the minimum as the whole run before it (or
    that run from its first digit). False only where no range is."""
    for before, after in _RANGE.findall(model):
        try:
            low = max(float(before), float(before.lstrip(".")))
            high = float(after)
        except ValueError:
            return True
        if not low <= high:
            return True
    return False


def camera_accepted(maker: str, model: str, mounts: Sequence[str], crop_text: str | None) -> bool:
    """Whether ``Check()`` accepts a camera of a shape :func:`shaped_until`
    vouches for (whose crop factors are positive): it has a maker, model,
    mount and crop factor. False where that does not tell."""
    return bool(maker and model and any(mounts) and crop_text)


def mount_accepted(names: Sequence[str]) -> bool:
    """Whether ``Check()`` accepts a top-level mount whose names without
    ``lang=`` are ``names``: it has one. False where that does not tell."""
    return any(names)


def _aspect_ratio(text: str) -> float:
    """An ``<aspect-ratio>`` as liblensfun reads it ("4:3" or a number)."""
    numerator, colon, denominator = text.partition(":")
    return single(_ratio(atof(numerator), atof(denominator)) if colon else atof(text))
