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
- GMarkup's own errors: a file that does not start with ``<`` (a byte-order
  mark), bytes that are not UTF-8, and markup that is not well-formed (which
  lensaudit reports as ``xml-error`` already).

Lines are those GMarkup reports: where it stands when it gives up, that is
just past the ``>`` of the start or end tag at fault, or at the ``<`` that
ends a text (a line break right after a ``>`` already counts as the next
line). What is not seen here: focal lengths liblensfun guesses from a lens's
name (only those of its calibrations are used), text inside CDATA sections
(GMarkup skips it; lxml gives it as text), the tails of the children of a
root other than ``<lensdatabase>``.
"""

from __future__ import annotations

import math
import re
import struct

# typing only for type checkers: a scan from the cache never imports it.
TYPE_CHECKING = False
if TYPE_CHECKING:
    from collections.abc import Callable
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

# C's strtod/atof: the longest prefix that is a number, else 0.
_ATOF = re.compile(
    r"[ \t\n\v\f\r]*([+-]?(?:(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?|inf(?:inity)?|nan))",
    re.IGNORECASE | re.ASCII,
)
_ATOI = re.compile(r"[ \t\n\v\f\r]*([+-]?\d+)", re.ASCII)


def atof(text: str) -> float:
    """A text as C's ``atof`` reads it: its longest numeric prefix, else 0."""
    found = _ATOF.match(text)
    return float(found.group(1)) if found else 0.0


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


def leading_refusal(data: bytes) -> Refusal | None:
    """Where GMarkup refuses a file before any element: one that does not
    start with ``<`` after white space (a byte-order mark, say), or (in a
    file that is otherwise well-formed) bytes that are not UTF-8."""
    start = len(data) - len(data.lstrip(b" \t\n\r"))
    if start < len(data) and data[start] != 0x3C:  # "<"
        line = data.count(b"\n", 0, start) + 1
        what = "a byte-order mark" if data.startswith(b"\xef\xbb\xbf") else "text"
        return line, f"the file starts with {what}, not with an element"
    if not data.isascii():
        try:
            data.decode("utf-8")
        except UnicodeDecodeError as error:
            line = data.count(b"\n", 0, error.start) + 1
            return line, f"byte 0x{data[error.start]:02X} is not UTF-8"
    return None


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
        for attribute, value in attributes.items():
            if attribute != "version":
                return f"bad attribute {_shown(attribute, value)} on <{name}>"
            version = atoi(value)
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
    for attribute, value in attributes.items():
        if attribute not in allowed:
            if unknown_attributes:
                return f"unknown attribute {_clip(attribute)}= on <{name}>"
            return f"bad attribute {_shown(attribute, value)} on <{name}>"
        values = allowed[attribute]
        if values is not None and value not in values:
            return f"bad attribute {_shown(attribute, value)} on <{name}>"
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

    __slots__ = ("kind", "texts", "focal", "aperture", "crop", "aspect", "calibrated", "guesses")

    def __init__(self, kind: str) -> None:
        self.kind = kind
        self.texts: set[str] = set()  # the elements that gave a text
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

    def text(self, name: str, text: str) -> str | None:
        """Take a text of element ``name``; why liblensfun refuses it, or None."""
        self.texts.add(name)
        if name == "cropfactor":
            self.crop = single(atof(text))
        elif name == "aspect-ratio" and self.kind == "lens":
            numerator, colon, denominator = text.partition(":")
            ratio = _ratio(atof(numerator), atof(denominator)) if colon else atof(text)
            self.aspect = single(ratio)
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
        given from the calibrations (``lfLens::GuessParameters``)."""
        focal, aperture = list(self.focal), list(self.aperture)
        if not aperture[0] or not focal[0]:
            ranges = {"focal": [_FLT_MAX, _FLT_MIN], "aperture": [_FLT_MAX, _FLT_MIN]}
            for what, value in self.guesses:
                low_high = ranges[what]
                if value < low_high[0]:
                    low_high[0] = value
                if value > low_high[1]:
                    low_high[1] = value
            for pair, (low, high) in ((focal, ranges["focal"]), (aperture, ranges["aperture"])):
                if low != _FLT_MAX and not pair[0]:
                    pair[0] = low
                if high != _FLT_MIN and not pair[1]:
                    pair[1] = high
        if not focal[1]:
            focal[1] = focal[0]
        return focal, aperture


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
            problem = definition.text(name, text)
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
