"""From a file's XML tree to plain tables: lenses, and distortion, vignetting
and TCA rows, each with its lens context.

A ``<lens>`` gives its entries maker, model, mounts, type, crop factor and
aspect ratio; a ``<calibration>`` may override crop factor and aspect ratio
(``cropfactor=``, ``aspect-ratio=``) and give real focal lengths
(``<real-focal-length>``, version 1 files). Attribute defaults are
liblensfun's (``libs/lensfun/database.cpp``): a missing distortion
coefficient is 0; a missing TCA ``vr``/``vb`` (``kr``/``kb`` for ``linear``)
is 1 and the other coefficients 0; a missing vignetting ``k1``/``k2``/``k3``
is 0. liblensfun reads a missing ``focal``, ``aperture`` or ``distance`` as
0, which no calibration means; here such an entry is ``missing_attribute``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from operator import itemgetter

from .records import (
    DEFAULT_ASPECT_RATIO,
    DEFAULT_CROP_FACTOR,
    DEFAULT_LENS_TYPE,
    MODEL_COEFFICIENTS,
    NAN,
    STATUS_BAD_VALUE,
    STATUS_MISSING_ATTRIBUTE,
    STATUS_NO_LENS,
    STATUS_OK,
    STATUS_UNKNOWN_MODEL,
    parse_aspect_ratio,
    parse_number,
    quoted,
)

# typing only for type checkers: a scan from the cache never imports it.
TYPE_CHECKING = False
if TYPE_CHECKING:
    from typing import Any

    from lxml import etree

    #: The function that gives an element's line (see :func:`lensaudit.read.xml.parse`).
    LineOf = Callable[[Any], int]

VIGNETTING = "vignetting"
TCA = "tca"
KINDS = (VIGNETTING, TCA)

#: When an entry has several problems, its status names the most basic one.
STATUS_PRIORITY = (STATUS_NO_LENS, STATUS_MISSING_ATTRIBUTE, STATUS_UNKNOWN_MODEL, STATUS_BAD_VALUE)


def text_of(element: etree._Element) -> str:
    """An element's text as liblensfun takes it: the last piece of text that is
    not blank (a comment between two pieces splits them), stripped."""
    if len(element) == 0:  # no child, comment or PI: the common case
        return (element.text or "").strip()
    pieces = [element.text, *(child.tail for child in element)]
    return next((p.strip() for p in reversed(pieces) if p and p.strip()), "")


class LensContext:
    """What a lens, and the ``<calibration>`` an entry is in, give its entries.

    ``problem`` is why entries of the lens cannot be audited ("" if they can),
    ``status`` the status it gives them; ``real_focals`` maps a focal length
    to its real focal length; ``index`` is the lens's place among the file's
    lenses (None outside a lens); ``fields`` are maker, lens, mounts, type,
    crop factor and aspect ratio, the start of each distortion row.
    """

    __slots__ = ("fields", "problem", "status", "real_focals", "index", "calibration_fields")

    def __init__(
        self,
        fields: tuple,
        problem: str = "",
        status: str = STATUS_BAD_VALUE,
        real_focals: dict[float, float] | None = None,
        index: int | None = None,
    ) -> None:
        self.fields = fields
        self.problem = problem
        self.status = status
        self.real_focals = {} if real_focals is None else real_focals
        self.index = index
        # What a vignetting or TCA row starts with: the fields without mounts.
        self.calibration_fields = (fields[0], fields[1], *fields[3:])


_NO_LENS = LensContext(
    ("", "", (), DEFAULT_LENS_TYPE, DEFAULT_CROP_FACTOR, DEFAULT_ASPECT_RATIO),
    "not inside a <lens> element",
    STATUS_NO_LENS,
)
#: The children of a ``<lens>`` that make its context.
_NAMED = frozenset(("maker", "model", "type", "cropfactor", "aspect-ratio"))


#: Attributes of a lens's child beyond which it is kept as its markup (see _attributes_of).
_MANY_ATTRIBUTES = 64


def _attributes_of(child: etree._Element) -> tuple[tuple[str, str], ...]:
    """A lens child's attributes as sorted (name, value) pairs. lxml finds each
    value by searching the element's attributes, so that reading them all
    takes time quadratic in their number: an element with more than
    :data:`_MANY_ATTRIBUTES` (liblensfun takes three at most) is kept as its
    markup instead, one pair named "" (its attributes in the order written)."""
    names = child.keys()
    if len(names) <= _MANY_ATTRIBUTES:
        return tuple(sorted(child.items()))
    from lxml import etree  # lxml: only to parse XML, which a warm scan does not

    return (("", etree.tostring(child, encoding="unicode", with_tail=False)),)


def read_lens(
    element: etree._Element, index: int, line: int, line_of: LineOf
) -> tuple[tuple, LensContext]:
    """A ``<lens>`` as a :class:`~lensaudit.read.records.Lens` row, and the
    context it gives its entries. Of each named child, the last without a
    ``lang`` attribute counts, as in liblensfun."""
    texts: dict[str, str] = {}
    mounts = []
    mount_lines = []
    content = []
    for child in element:
        tag = child.tag
        if not isinstance(tag, str) or tag == "calibration":  # comments have a function as tag
            continue
        if tag == "mount":
            mounts.append(text_of(child))
            mount_lines.append(line_of(child) - line)
        elif tag in _NAMED and child.get("lang") is None:
            texts[tag] = text_of(child)
            if tag in ("maker", "model"):
                continue
        content.append((tag, _attributes_of(child), " ".join(text_of(child).split())))
    problems = []
    crop_text = texts.get("cropfactor")
    crop_factor = DEFAULT_CROP_FACTOR
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
    maker, model = texts.get("maker") or "", texts.get("model") or ""
    lens_type = texts.get("type") or DEFAULT_LENS_TYPE
    fields = (maker, model, tuple(mounts), lens_type, crop_factor, aspect_ratio)
    problem = "; ".join(problems)
    row = (line, maker, model, tuple(mounts), lens_type, crop_factor,
           aspect_ratio, crop_text, problem, tuple(content), tuple(mount_lines))  # fmt: skip
    return row, LensContext(fields, problem, index=index)


def read_camera(element: etree._Element, line_of: LineOf) -> tuple:
    """A top-level ``<camera>`` as a :class:`~lensaudit.read.records.Camera` row."""
    line = line_of(element)
    texts: dict[str, str] = {}
    mounts, mount_lines = [], []
    for child in element.iterchildren("maker", "model", "mount", "cropfactor"):
        if child.tag == "mount":
            mounts.append(text_of(child))
            mount_lines.append(line_of(child) - line)
        elif child.get("lang") is None:
            texts[child.tag] = text_of(child)
    return (line, texts.get("maker", ""), texts.get("model", ""), tuple(mounts),
            tuple(mount_lines), texts.get("cropfactor"))  # fmt: skip


def mount_names(element: etree._Element, line_of: LineOf) -> list[tuple[int, str]]:
    """(line, name) of each untranslated ``<name>`` of a top-level ``<mount>``."""
    return [
        (line_of(name), text_of(name))
        for name in element.iterchildren("name")
        if name.get("lang") is None
    ]


def _positive(value: float, what: str) -> float:
    if value <= 0:
        raise ValueError(f"{what} {value:g} is not positive")
    return value


def calibration_context(
    calibration: etree._Element | None, lens: LensContext, line_of: LineOf
) -> LensContext:
    """Apply what a ``<calibration>`` adds to its lens's context: ``cropfactor=``
    and ``aspect-ratio=``, and ``<real-focal-length>`` elements."""
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
            problems.append(f"<real-focal-length> on line {line_of(element)}: {error}")
    if (
        crop_text is None
        and aspect_text is None
        and not real_focals
        and len(problems) == bool(lens.problem)
    ):
        return lens
    maker, model, mounts, lens_type, crop_factor, aspect_ratio = lens.fields
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
    fields = (maker, model, mounts, lens_type, crop_factor, aspect_ratio)
    return LensContext(fields, "; ".join(problems), lens.status, real_focals, lens.index)


def elements_in_context(
    piece: etree._Element, tags: tuple[str, ...], first_lens: int, line_of: LineOf
) -> tuple[list[tuple], list[tuple[etree._Element, LensContext]]]:
    """The lens rows of a piece of a document (its lenses numbered from
    ``first_lens``), and each element in it named one of ``tags``, in
    document order, with the context it is read in: its lens's (the
    innermost, for a lens inside a lens), with its ``<calibration>``."""
    lenses: list[tuple] = []
    contexts: dict[Any, LensContext] = {}  # lens element -> its context
    found = []
    lens = calibration = None
    context = of_lens = _NO_LENS
    for element in piece.iter("lens", "calibration", *tags):
        tag = element.tag
        if tag == "lens":
            row, context = read_lens(element, first_lens + len(lenses), line_of(element), line_of)
            lenses.append(row)
            contexts[element] = context
            lens, calibration, of_lens = element, None, context
        elif tag == "calibration":
            if element.getparent() is lens:
                calibration = element
                context = calibration_context(calibration, of_lens, line_of)
        # calibration is only ever set to a child of the current lens.
        elif calibration is None or lens is None or element.getparent() is not calibration:
            found.append((element, _context_of(element, contexts, line_of)))
        else:
            found.append((element, context))
    return lenses, found


def _context_of(element: etree._Element, contexts: dict, line_of: LineOf) -> LensContext:
    """The context of an element found outside ``<lens><calibration>`` (rare):
    that of the lens it is in, if any, with its parent's overrides if the
    parent is a ``<calibration>``."""
    lens = next(element.iterancestors("lens"), None)
    base = _NO_LENS if lens is None else contexts[lens]
    parent = element.getparent()
    return calibration_context(parent, base, line_of) if parent is not None else base


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
        return parse_number(text)
    except ValueError as error:
        problems.append((STATUS_BAD_VALUE, f"{attribute}={error}"))
        return NAN


#: The default of a required attribute: None (it must be given), or a function
#: of the values of the attributes before it.
AttributeDefault = Callable[[dict[str, float]], float] | None


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
    own problem last; a value that could not be read is NaN.
    """
    attributes = element.attrib
    problems: list[tuple[str, str]] = []
    model = (attributes.get("model") or "").strip()
    if not model:
        problems.append((STATUS_MISSING_ATTRIBUTE, "missing model="))
    values: dict[str, float] = {}
    for attribute, default in required:
        given = default(values) if default is not None else None
        values[attribute] = attribute_number(attributes, attribute, given, problems)
    for attribute, _ in required:
        value = values[attribute]
        if value <= 0:
            problems.append((STATUS_BAD_VALUE, f"{attribute}={value:g} is not positive"))
    defaults = models.get(model)
    if defaults is not None:
        for attribute, default_value in defaults.items():
            values[attribute] = attribute_number(attributes, attribute, default_value, problems)
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


# ---------------------------------------------------------------------------
# <distortion>
# ---------------------------------------------------------------------------

# Per model: which of [focal, real focal, coefficients..., NaN] go to a, b, c, k1, k2.
_LAYOUT = {
    model: itemgetter(
        *(2 + names.index(n) if n in names else 2 + len(names) for n in ("a", "b", "c", "k1", "k2"))
    )
    for model, names in MODEL_COEFFICIENTS.items()
}
#: Each model's name: every row of a model holds this one text, not a copy of its own.
_MODEL_NAMES = {model: model for model in MODEL_COEFFICIENTS}
#: Per model, each coefficient attribute and its default.
_MODEL_DEFAULTS = {model: dict.fromkeys(names, 0.0) for model, names in MODEL_COEFFICIENTS.items()}


def distortion_row(element: etree._Element, context: LensContext, line: int) -> tuple:
    """The row of one ``<distortion>`` element (see
    :data:`~lensaudit.read.records.ROW_FIELDS`). The common case, a known
    model with plain numbers, takes a short path; anything else is examined
    in full by :func:`_checked_distortion_row`, to the same result."""
    get = element.get
    model = _MODEL_NAMES.get(get("model"))  # type: ignore[arg-type]
    names = MODEL_COEFFICIENTS.get(model)  # type: ignore[arg-type]
    focal_text = get("focal")
    if names is not None and focal_text is not None and not context.problem:
        real_text = get("real-focal")
        texts = [focal_text, "1" if real_text is None else real_text]
        texts += (get(name, "0") for name in names)
        values = plain_numbers(texts)
        if values is not None and values[0] > 0 and values[1] > 0:
            focal = values[0]
            real_focal = context.real_focals.get(focal, NAN) if real_text is None else values[1]
            values.append(NAN)
            return (
                line,
                *context.fields,
                model,
                focal,
                real_focal,
                *_LAYOUT[model](values),  # type: ignore[index]
                STATUS_OK,
                "",
            )
    return _checked_distortion_row(element, context, line)


def plain_numbers(texts: list[str]) -> list[float] | None:
    """The numbers of ``texts`` where every one is a plain finite decimal (the
    common case), else None: float() alone also takes "1_0", "nan", "inf"
    and digits that are not ASCII, which :func:`parse_number` refuses."""
    joined = "".join(texts)
    if not joined.isascii() or "_" in joined:
        return None
    try:
        values = list(map(float, texts))
    except ValueError:
        return None
    total = sum(values)
    return values if total - total == 0 else None


def _checked_distortion_row(element: etree._Element, context: LensContext, line: int) -> tuple:
    """The row of one ``<distortion>`` element, every problem noted."""
    # Without a real-focal= attribute, the <real-focal-length> of its focal length.
    required = (
        ("focal", None),
        ("real-focal", lambda values: context.real_focals.get(values["focal"], NAN)),
    )
    model, values, problems = checked_attributes(element, required, _MODEL_DEFAULTS, context)
    status, message = status_of(problems)
    return (
        line,
        *context.fields,
        model,
        values["focal"],
        values["real-focal"],
        *(values.get(n, NAN) for n in ("a", "b", "c", "k1", "k2")),
        status,
        message,
    )


def omitted_coefficients(element: etree._Element) -> tuple[str, ...]:
    """The coefficient attributes of its model that a ``<distortion>`` leaves out."""
    names = MODEL_COEFFICIENTS.get(element.get("model") or "", ())
    return tuple(name for name in names if element.get(name) is None)


def error_row(line: int, status: str, message: str) -> tuple:
    """The distortion row that stands for a whole file's problem: no lens, no model."""
    return (line, "", "", (), "", NAN, NAN, "", NAN, NAN, NAN, NAN, NAN, NAN, NAN, status, message)


# ---------------------------------------------------------------------------
# <vignetting> and <tca>
# ---------------------------------------------------------------------------


class CalibrationSpec:
    """How one element kind is read: its ``models`` (model -> coefficient
    attributes and their defaults), the attributes every entry must have
    besides ``model=`` (``required``, which must be positive), and the row's
    fields between ``focal`` and ``status`` (``fields``)."""

    __slots__ = ("tag", "models", "required", "fields", "row_fields", "_fast")

    def __init__(
        self,
        tag: str,
        models: dict[str, dict[str, float]],
        required: tuple[str, ...],
        fields: tuple[str, ...],
    ) -> None:
        self.tag = tag
        self.models = models
        self.required = required
        self.fields = fields
        #: The names of a row's values.
        self.row_fields = (*CALIBRATION_HEAD, *fields, "status", "message")
        self._fast = {model: self._fast_path(model) for model in models}

    def _fast_path(self, model: str) -> tuple:
        """The attributes read for ``model``, in order, the text each defaults to
        (None: required), the getter of ``focal`` and the fields from their
        values (with NaN appended at the end), and the model's name: every
        row holds that one text, not a copy of its own."""
        coefficients = self.models[model]
        names = self.required + tuple(coefficients)
        defaults = (None,) * len(self.required) + tuple(repr(v) for v in coefficients.values())
        missing = len(names)
        wanted = ("focal", *self.fields)
        layout = itemgetter(*(names.index(n) if n in names else missing for n in wanted))
        return names, defaults, layout, model

    def row(
        self,
        element: etree._Element,
        context: LensContext,
        line: int,
        numbers: dict[str, float],
    ) -> tuple:
        """The row of one element. The common case (plain numbers) takes a short
        path; anything else is examined in full, to the same result.

        ``numbers`` holds the value of each text of a required attribute met
        before, plain and positive (a file's calibrations share a few focal
        lengths, apertures and distances): rows of one text hold one float,
        not a copy each, and the text is not read again."""
        get = element.get
        model = get("model")
        fast = self._fast.get(model)  # type: ignore[arg-type]
        if fast is not None and not context.problem:
            names, defaults, layout, model = fast
            texts = list(map(get, names, defaults))
            required = len(self.required)
            values = list(map(numbers.get, texts[:required]))  # type: ignore[arg-type]
            if None not in values:  # every required text met before
                coefficients = plain_numbers(texts[required:])
                values = None if coefficients is None else values + coefficients
            elif None not in texts:  # all required given
                values = plain_numbers(texts)
                if values is not None and min(values[:required]) > 0:
                    values[:required] = map(numbers.setdefault, texts[:required], values[:required])
                else:
                    values = None
            else:
                values = None
            if values is not None:
                values.append(NAN)
                return (
                    line,
                    *context.calibration_fields,
                    model,
                    *layout(values),
                    STATUS_OK,
                    "",
                )
        required = [(attribute, None) for attribute in self.required]
        model, values, problems = checked_attributes(element, required, self.models, context)
        return (
            line,
            *context.calibration_fields,
            model,
            values.get("focal", NAN),
            *[values.get(f, NAN) for f in self.fields],
            *status_of(problems),
        )

    def error_row(self, line: int, status: str, message: str) -> tuple:
        """The row that stands for a whole file's problem."""
        return (line, "", "", "", NAN, NAN, "", NAN, *(NAN,) * len(self.fields), status, message)


#: The fields every vignetting and TCA row starts with.
CALIBRATION_HEAD = (
    "line", "maker", "lens", "type", "crop_factor", "aspect_ratio", "model", "focal",
)  # fmt: skip

SPECS = {
    VIGNETTING: CalibrationSpec(
        "vignetting",
        {"pa": {"k1": 0.0, "k2": 0.0, "k3": 0.0}},
        ("focal", "aperture", "distance"),
        ("aperture", "distance", "k1", "k2", "k3"),
    ),
    TCA: CalibrationSpec(
        "tca",
        {
            "poly3": {"vr": 1.0, "vb": 1.0, "cr": 0.0, "cb": 0.0, "br": 0.0, "bb": 0.0},
            "linear": {"kr": 1.0, "kb": 1.0},
        },
        ("focal",),
        ("kr", "kb", "vr", "vb", "cr", "cb", "br", "bb"),
    ),
}

_DISTORTION = "distortion"


class FileReader:
    """Reads the pieces of one document (see :func:`lensaudit.read.xml.parse`)
    into its tables: lens rows, distortion rows with the lens index and
    omitted coefficients of each, and with ``calibrations``, vignetting and
    TCA rows (else None); with ``refusals``, where liblensfun stops reading
    it (see :mod:`lensaudit.read.liblensfun`)."""

    def __init__(self, calibrations: bool, refusals: bool = False) -> None:
        self.tags = (_DISTORTION, VIGNETTING, TCA) if calibrations else (_DISTORTION,)
        self.judge = refusals
        if refusals:  # only a reader that judges it needs liblensfun's rules
            from . import liblensfun

            self._liblensfun = liblensfun
        #: What a lens's tables depend on besides its tree (for :class:`~.xml.Pieces`).
        self.kind = (self.tags, refusals)
        self.lenses: list[tuple] = []
        self.distortion: list[tuple] = []
        self.lens_of_row: list[int | None] = []
        self.omitted: list[tuple[str, ...]] = []
        self.vignetting: list[tuple] | None = [] if calibrations else None
        self.tca: list[tuple] | None = [] if calibrations else None
        self.lens_of_vignetting: list[int | None] | None = [] if calibrations else None
        self.lens_of_tca: list[int | None] | None = [] if calibrations else None
        self.cameras: list[tuple] = []
        self.mount_names: list[tuple[int, str]] = []
        self._numbers: dict[str, float] = {}  # see CalibrationSpec.row
        #: Where liblensfun stops reading the pieces so far, why, and how many of
        #: the lenses before it holds: (line, reason, lenses kept), or None.
        self.refusal: tuple[int, str, int] | None = None
        self._root_refusal: tuple[int, str, int] | None = None
        # The pieces on lines before this are of shapes liblensfun accepts
        # whatever their values (see :meth:`document`).
        self._shaped_until = 0

    #: Whether pieces are screened before they are walked (off: every piece is walked).
    screen = True

    def document(self, data: bytes) -> None:
        """Look at the bytes of the document (well-formed, line ends normalized)
        whose pieces come next, for what liblensfun surely accepts."""
        if self.screen and self.judge:
            self._shaped_until = self._liblensfun.shaped_until(data)

    def root(self, element: etree._Element, line: int) -> None:
        """Judge the document's root element, whose start tag ends on ``line``
        (liblensfun reads it before any piece)."""
        if not self.judge:
            return
        found = self._liblensfun.root_refusal(element, line)
        self._root_refusal = (*found, 0) if found is not None else None

    def first_refusal(self) -> tuple[int, str, int] | None:
        """Where liblensfun stops reading the document, why, and the number of
        lenses it holds then; None if it reads every piece (see
        :mod:`lensaudit.read.liblensfun`)."""
        return self._root_refusal or self.refusal

    def add(self, piece: etree._Element, line_of: LineOf) -> None:
        """Read one piece of the document."""
        first_lens = len(self.lenses)
        accepted = False
        tag = piece.tag
        if tag == "camera":
            camera = read_camera(piece, line_of)
            self.cameras.append(camera)
            accepted = self.judge and self._liblensfun.camera_accepted(*camera[1:4], camera[5])
        elif tag == "mount":
            names = mount_names(piece, line_of)
            self.mount_names += names
            accepted = self.judge and self._liblensfun.mount_accepted([name for _, name in names])
        lenses, found = elements_in_context(piece, self.tags, first_lens, line_of)
        self.lenses += lenses
        if self.judge and self.refusal is None:
            if tag == "lens":  # its own row comes first
                row = lenses[0]
                accepted = self._liblensfun.lens_accepted(row[2], row[3], row[_LENS_CONTENT])
            if not accepted or line_of(piece) >= self._shaped_until:
                refusal = self._liblensfun.piece_refusal(piece, line_of)
                if refusal is not None:  # liblensfun holds the lenses of the pieces before
                    self.refusal = (*refusal, first_lens)
        rows = {VIGNETTING: self.vignetting, TCA: self.tca}
        lens_of = {VIGNETTING: self.lens_of_vignetting, TCA: self.lens_of_tca}
        numbers = self._numbers
        for element, context in found:
            tag = element.tag
            if tag == _DISTORTION:
                self.distortion.append(distortion_row(element, context, line_of(element)))
                self.lens_of_row.append(context.index)
                self.omitted.append(omitted_coefficients(element))
            else:
                rows[tag].append(SPECS[tag].row(element, context, line_of(element), numbers))  # type: ignore[union-attr]
                lens_of[tag].append(context.index)  # type: ignore[union-attr]

    def _tables(self) -> tuple[list | None, ...]:
        """Every table, in the order of :meth:`taken`: the rows that start with
        a line, the lens of each row, then omitted coefficients."""
        return (
            self.lenses, self.distortion, self.vignetting, self.tca, self.cameras,
            self.mount_names, self.lens_of_row, self.lens_of_vignetting, self.lens_of_tca,
            self.omitted,
        )  # fmt: skip

    def taken(self) -> tuple | None:
        """The tables read so far, for :meth:`extend` into another reader, as
        (position in :meth:`_tables`, rows) of each that holds any; None if a
        row is not ``ok`` (its message may name a line) or liblensfun refuses
        what was read."""
        tables = self._tables()
        if (
            self.refusal is not None
            or any(row[_LENS_PROBLEM] for row in self.lenses)
            or any(row[-2] != STATUS_OK for rows in tables[1:4] if rows for row in rows)
            or any(None in lens_of for lens_of in tables[6:9] if lens_of)
        ):
            return None
        return tuple((position, rows) for position, rows in enumerate(tables) if rows)

    def extend(self, taken: tuple, line: int) -> None:
        """Add what another reader read (:meth:`taken`), its lines counted from
        ``line`` and its lenses after this reader's."""
        first = len(self.lenses)
        tables = self._tables()
        for position, rows in taken:
            table = tables[position]
            if position < _FIRST_LENS_OF:  # rows that start with a line
                table += [(row[0] + line, *row[1:]) for row in rows]  # type: ignore[operator]
            elif position < _OMITTED:
                table += [index + first for index in rows]  # type: ignore[operator]
            else:
                table += rows  # type: ignore[operator]


#: Positions in :meth:`FileReader._tables`: the distortion rows, the first table
#: of the lens of each row, and the omitted coefficients.
_DISTORTION_ROWS, _FIRST_LENS_OF, _OMITTED = 1, 6, 9
_NO_ROWS: list[tuple] = []


def distortion_of(taken: tuple) -> list[tuple]:
    """The distortion rows of what :meth:`FileReader.taken` gave (the same list
    each time; not to be changed)."""
    for position, rows in taken:
        if position == _DISTORTION_ROWS:
            return rows
    return _NO_ROWS


#: Where a lens row (see :func:`read_lens`) says why its entries cannot be audited,
#: and where it holds its other children.
_LENS_PROBLEM = 8
_LENS_CONTENT = 9


#: The elements a :class:`FileReader` reads (what a root may be to be read whole).
READ = ("lens", "calibration", _DISTORTION, VIGNETTING, TCA)
