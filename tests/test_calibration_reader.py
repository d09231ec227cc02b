"""The ``<vignetting>`` and ``<tca>`` reader against an independent one.

The reference here is built on the standard library's expat and on the
rules as Lensfun's data and liblensfun define them (the defaults of
``libs/lensfun/database.cpp``; a number is a plain finite decimal): every
element gives one record, in document order, with the line its start tag
ends on (as libxml2 counts), its lens, its model and values, and the same
verdict, audited (``ok``) or not and why. Nothing here calls the reader's
own helpers.
"""

from __future__ import annotations

import math
import re
import xml.parsers.expat
from dataclasses import dataclass, field

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lensaudit import calibrations
from lensaudit.read import read_bytes
from lensaudit.read.paths import bundled_database_path
from test_fuzz_mutations import _start_tag_end_line

#: Per kind: model -> coefficient attributes and their defaults; the attributes
#: every element needs (positive numbers); the record's fields after ``focal``.
MODELS = {
    "vignetting": {"pa": {"k1": 0.0, "k2": 0.0, "k3": 0.0}},
    "tca": {
        "poly3": {"vr": 1.0, "vb": 1.0, "cr": 0.0, "cb": 0.0, "br": 0.0, "bb": 0.0},
        "linear": {"kr": 1.0, "kb": 1.0},
    },
}
REQUIRED = {"vignetting": ("focal", "aperture", "distance"), "tca": ("focal",)}
FIELDS = {
    "vignetting": ("aperture", "distance", "k1", "k2", "k3"),
    "tca": ("kr", "kb", "vr", "vb", "cr", "cb", "br", "bb"),
}
#: Of several problems, the status names the first of these.
PRIORITY = ("no_lens", "missing_attribute", "unknown_model", "bad_value")

_PLAIN = re.compile(r"[ \t\n\r]*[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?[ \t\n\r]*\Z")


def number(text: str | None) -> float | None:
    """A plain decimal, finite as a double; None for anything else."""
    if text is None or not _PLAIN.match(text):
        return None
    value = float(text)
    return value if math.isfinite(value) else None


def positive(text: str | None) -> float | None:
    value = number(text)
    return value if value is not None and value > 0 else None


def ratio(text: str | None) -> float | None:
    """An aspect ratio, ``N:M`` or a decimal; None unless positive and finite."""
    if text is None:
        return None
    if ":" in text:
        numerator, denominator = text.split(":", 1)
        top, bottom = number(numerator), number(denominator)
        value = None if top is None or not bottom else top / bottom
    else:
        value = number(text)
    return value if value is not None and 0 < value < math.inf else None


@dataclass
class Node:
    tag: str
    attributes: dict[str, str]
    line: int
    children: list[Node] = field(default_factory=list)
    #: The pieces of its own text: markup inside it (a child, a comment, a
    #: processing instruction, a CDATA section) ends one piece.
    pieces: list[str] = field(default_factory=list)
    open: bool = False  # whether text now continues the last piece

    def add_text(self, text: str) -> None:
        if self.open:
            self.pieces[-1] += text
        else:
            self.pieces.append(text)
            self.open = True

    def content(self) -> str:
        """The text as liblensfun takes it (GMarkup hands each piece over on its
        own, and the last that is not blank stays): stripped."""
        return next((p.strip() for p in reversed(self.pieces) if p.strip()), "")


def start_tag_end_lines(data: bytes, starts: list[int]) -> list[int]:
    """For each start tag at these byte offsets (increasing), the line of its ``>``."""
    lines, line, position = [], 1, 0
    for start in starts:
        line += data.count(b"\n", position, start)
        position = start
        lines.append(_start_tag_end_line(data, start, line))
    return lines


def parse(data: bytes) -> Node:
    """The element tree of a well-formed file, lines as libxml2 gives them."""
    parser = xml.parsers.expat.ParserCreate()
    top = Node("", {}, 0)
    stack, nodes, starts = [top], [], []

    def markup(*_: object) -> None:
        stack[-1].open = False

    def begin(tag: str, attributes: dict[str, str]) -> None:
        markup()
        node = Node(tag, attributes, 0)
        stack[-1].children.append(node)
        stack.append(node)
        nodes.append(node)
        starts.append(parser.CurrentByteIndex)

    def end(tag: str) -> None:
        stack.pop()
        markup()

    parser.StartElementHandler = begin
    parser.EndElementHandler = end
    parser.CharacterDataHandler = lambda text: stack[-1].add_text(text)
    parser.CommentHandler = markup
    parser.ProcessingInstructionHandler = markup
    parser.StartCdataSectionHandler = markup
    parser.EndCdataSectionHandler = markup
    parser.Parse(data, True)
    for node, line in zip(nodes, start_tag_end_lines(data, starts), strict=True):
        node.line = line
    return top.children[0]


def lens_of(lens: Node | None, parent: Node) -> tuple[tuple, list[str]]:
    """(maker, model, type, crop factor, aspect ratio) an element's lens and
    ``<calibration>`` parent give it, and the statuses of their problems."""
    if lens is None:
        return ("", "", "rectilinear", 1.0, 1.5), ["no_lens"]
    texts: dict[str, str] = {}
    for child in lens.children:
        if "lang" not in child.attributes:  # the last untranslated one counts
            texts[child.tag] = child.content()
    crop, aspect, problems = 1.0, 1.5, []
    if "cropfactor" in texts:
        crop = positive(texts["cropfactor"])
        problems += [] if crop is not None else ["bad_value"]
    if "aspect-ratio" in texts:
        aspect = ratio(texts["aspect-ratio"])
        problems += [] if aspect is not None else ["bad_value"]
    if parent.tag == "calibration":
        if "cropfactor" in parent.attributes:
            crop = positive(parent.attributes["cropfactor"])
            problems += [] if crop is not None else ["bad_value"]
        if "aspect-ratio" in parent.attributes:
            aspect = ratio(parent.attributes["aspect-ratio"])
            problems += [] if aspect is not None else ["bad_value"]
        for child in parent.children:
            if child.tag == "real-focal-length":
                focal = number(child.attributes.get("focal"))
                real = positive(child.attributes.get("real-focal"))
                problems += [] if focal is not None and real is not None else ["bad_value"]
    names = (texts.get("maker") or "", texts.get("model") or "", texts.get("type") or "rectilinear")
    return (*names, crop, aspect), problems


def reference_record(kind: str, element: Node, lens: Node | None, parent: Node) -> tuple:
    """(line, maker, lens, type, status, then, when ok, crop factor, aspect
    ratio, model, focal and the fields) of one element."""
    attributes = element.attributes
    lens_values, problems = lens_of(lens, parent)
    model = (attributes.get("model") or "").strip()
    if not model:
        problems.append("missing_attribute")
    values: dict[str, float | None] = {}
    for name in REQUIRED[kind]:
        if name not in attributes:
            problems.append("missing_attribute")
            continue
        values[name] = positive(attributes[name])
        if values[name] is None:
            problems.append("bad_value")
    if model and model not in MODELS[kind]:
        problems.append("unknown_model")
    for name, default in MODELS[kind].get(model, {}).items():
        values[name] = number(attributes[name]) if name in attributes else default
        if values[name] is None:
            problems.append("bad_value")
    status = min(problems, key=PRIORITY.index) if problems else "ok"
    head = (element.line, *lens_values[:3], status)
    if status != "ok":
        return head
    fields = [values.get(name, math.nan) for name in FIELDS[kind]]
    return (*head, *lens_values[3:], model, values["focal"], *fields)


def reference(data: bytes) -> dict[str, list[tuple]]:
    """Every ``<vignetting>`` and ``<tca>`` of a well-formed database, in document order."""
    found: dict[str, list[tuple]] = {"vignetting": [], "tca": []}

    def walk(node: Node, lens: Node | None) -> None:
        for child in node.children:
            if child.tag in found:
                found[child.tag].append(reference_record(child.tag, child, lens, node))
            walk(child, child if child.tag == "lens" else lens)

    walk(parse(data), None)
    return found


def as_read(record: object, kind: str) -> tuple:
    """A record of the reader in the reference's form."""
    head = (record.line, record.maker, record.lens, record.type, record.status)
    if record.status != "ok":
        return head
    values = (record.crop_factor, record.aspect_ratio, record.model, record.focal)
    return (*head, *values, *(getattr(record, name) for name in FIELDS[kind]))


def read_records(data: bytes, name: str = "x.xml"):
    """The vignetting and TCA records of one file's content, and its error."""
    tables = read_bytes(data, name, calibrations=True)
    return (
        calibrations.CalibrationRecords.of_file("vignetting", name, tables.vignetting),
        calibrations.CalibrationRecords.of_file("tca", name, tables.tca),
        tables.error,
    )


def assert_reads_as_the_reference(data: bytes) -> None:
    vignetting, tca, error = read_records(data)
    assert error == ""
    expected = reference(data)
    for kind, records in (("vignetting", vignetting), ("tca", tca)):
        # repr: NaN equals NaN, and 0.0 differs from -0.0.
        assert [repr(as_read(r, kind)) for r in records] == list(map(repr, expected[kind]))


BUNDLED = sorted(p.name for p in bundled_database_path().glob("*.xml"))


@pytest.mark.parametrize("name", BUNDLED)
def test_every_bundled_file_reads_as_the_independent_reader_reads_it(name):
    assert_reads_as_the_reference((bundled_database_path() / name).read_bytes())


# --- real files with values replaced ----------------------------------------

MUTATED_FILES = ("actioncams.xml", "slr-vivitar.xml", "compact-sony.xml")
_VALUE = re.compile(rb'<(?:vignetting|tca|calibration|real-focal-length)\b[^>]*?="([^"]*)"')
_LENS_TEXT = re.compile(rb"<(?:cropfactor|aspect-ratio|type)>([^<]*)<")
SPECIAL = ["", "0", "-0", "-1", "+2", " 2.5 ", ".5", "5.", "1e308", "1e999", "1e-320", "nan"]
SPECIAL += [
    "inf",
    "-Infinity",
    "1_0",
    "\u0663",
    "abc",
    "1,5",
    "4:3",
    "3:0",
    "pa",
    "poly3",
    "linear",
]
SPECIAL += ["acm", " pa ", "fisheye"]
values = st.one_of(
    st.sampled_from(SPECIAL),
    st.floats().map(repr),
    st.decimals(allow_nan=False, allow_infinity=False).map(str),
    st.text(
        st.characters(min_codepoint=0x20, max_codepoint=0x7E, exclude_characters='<>&"'), max_size=6
    ),
)


@st.composite
def mutated(draw) -> bytes:
    data = (bundled_database_path() / draw(st.sampled_from(MUTATED_FILES))).read_bytes()
    for _ in range(draw(st.integers(1, 6))):
        pattern = draw(st.sampled_from([_VALUE, _VALUE, _LENS_TEXT]))
        matches = list(pattern.finditer(data))
        match = matches[draw(st.integers(0, len(matches) - 1))]
        value = draw(values)
        data = data[: match.start(1)] + value.encode() + data[match.end(1) :]
    return data


@settings(max_examples=40, deadline=None)
@given(mutated())
def test_a_file_with_any_values_reads_as_the_independent_reader_reads_it(data):
    assert_reads_as_the_reference(data)


@settings(max_examples=300, deadline=None)
@given(
    st.sampled_from(["vignetting", "tca"]),
    st.sampled_from(["pa", "poly3", "linear", " linear", "acm", ""]),
    st.dictionaries(
        st.sampled_from(["focal", "aperture", "distance", "k1", "k2", "k3", "kr", "kb", "vr"]),
        # Mostly plain numbers, so that most elements are audited and their values compared.
        st.one_of(st.floats(0.01, 100).map(repr), st.floats(0.01, 100).map(repr), values),
    ),
)
def test_any_element_in_a_lens_reads_as_the_independent_reader_reads_it(kind, model, attributes):
    text = " ".join(f'{k}="{v}"' for k, v in attributes.items())
    data = (
        "<lensdatabase><lens><maker>M</maker><model>L</model><cropfactor>1.5</cropfactor>\n"
        f'<calibration><{kind} model="{model}" {text}/></calibration></lens></lensdatabase>'
    ).encode()
    assert_reads_as_the_reference(data)


def test_the_independent_reader_counts_lines_as_libxml2_does():
    data = b'<lensdatabase>\n<lens><calibration>\n<vignetting\n model="pa"\n focal="1"/>'
    data += b"</calibration></lens>\n</lensdatabase>"
    assert [r[0] for r in reference(data)["vignetting"]] == [5]  # where the start tag ends


@pytest.mark.parametrize(
    "lens_text",
    [
        "<type>rectilinear<!---->fisheye</type>",
        "<cropfactor>1.5<!-- was 2 -->2</cropfactor>",
        "<cropfactor>2<!---->  </cropfactor>",
        "<aspect-ratio>4:3<!---->x</aspect-ratio>",
    ],
)
def test_lens_text_split_by_a_comment_reads_as_the_independent_reader_reads_it(lens_text):
    data = (
        f"<lensdatabase><lens><maker>M</maker><model>L</model>{lens_text}\n"
        '<calibration><tca model="linear" focal="10" kr="1" kb="1"/>'
        '<vignetting model="pa" focal="10" aperture="4" distance="10"/>'
        "</calibration></lens></lensdatabase>"
    ).encode()
    assert_reads_as_the_reference(data)


def test_an_element_outside_a_lens_is_no_lens_in_both_readers():
    data = b'<lensdatabase><tca model="linear" focal="10" kr="1" kb="1"/></lensdatabase>'
    assert [r[4] for r in reference(data)["tca"]] == ["no_lens"]
    assert_reads_as_the_reference(data)


def test_a_record_is_made_only_when_it_is_asked_for():
    made = []
    records = read_records(
        (bundled_database_path() / "compact-sony.xml").read_bytes(), "compact-sony.xml"
    )[1]
    entry = records._entry
    records._entry = lambda *values: made.append(values) or entry(*values)
    assert len(records.column("status")) == len(records) > 0
    assert made == []
    assert records[0].file == "compact-sony.xml" and len(made) == 1


def test_records_from_entry_objects_are_those_entries(bundled_db):
    database = calibrations.load(bundled_db / "compact-sony.xml")
    entries = list(calibrations.CalibrationRecords("tca", *database.rows("tca")))
    again = calibrations.CalibrationRecords.of_entries("tca", entries)
    assert list(map(repr, again)) == list(map(repr, entries))
    assert again.column("file") == [e.file for e in entries]
