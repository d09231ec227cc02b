"""Property-based tests: real Lensfun files, mutated, must never crash the tools,
and every ``<distortion>`` element must be accounted for exactly once.

The rule, per file (``lensaudit.read.read_bytes``, ``lensaudit scan``, ``lensaudit check``):

- A file that is well-formed XML (as judged by the standard library's expat
  parser) yields exactly one record per ``<distortion>`` element, in
  document order, at the line where its start tag ends (libxml2's
  convention), and no ``xml_error`` record. ``check`` counts them all and
  reports each record that could not be audited with exactly one input
  finding at its line.
- A well-formed file whose root element is not ``<lensdatabase>`` yields one
  file-level ``not_database`` record followed by one record per
  ``<distortion>`` element, all ``not_database``.
- A file that is not well-formed yields one file-level ``xml_error`` record
  (no model, no focal) followed by one record for each ``<distortion>``
  element libxml2's recovery mode still finds, each marked ``xml_error``.
  ``check`` reports one ``xml-error`` finding for the file, with a line and
  a column, and counts the salvaged records.

Hypothesis runs a fixed, derandomized set of examples, so that a run is
reproducible and bounded. Any warning (a numpy RuntimeWarning, say) fails a test.
"""

from __future__ import annotations

import json
import re
import tempfile
import xml.parsers.expat
from collections import Counter
from pathlib import Path

import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from lxml import etree

from lensaudit.cli import main
from lensaudit.read import read_bytes
from lensaudit.read.paths import bundled_database_path

pytestmark = pytest.mark.filterwarnings("error")

#: Real files of the bundled database: small, with tca and vignetting, one that folds.
FILES = ("6x6.xml", "actioncams.xml", "compact-samsung.xml", "slr-vivitar.xml")
ORIGINAL = {name: (bundled_database_path() / name).read_bytes() for name in FILES}
#: An untouched file beside the mutated one, so that `scan` always has a readable file.
ANCHOR = "contax.xml"

INPUT_CODES = {"missing-attribute", "bad-value", "unknown-model", "no-lens"}

VALUES = [
    "",
    " ",
    "0",
    "-0",
    "-1",
    "1e308",
    "-1e308",
    "1e-320",
    "1e999",
    "nan",
    "NaN",
    "inf",
    "-Infinity",
    "abc",
    "1,5",
    " 2 ",
    "0x10",
    "1_0",
    "\u0661",
    "9" * 400,
    "&amp;",
    "&lt;",
    "ptlens",
    "poly3",
    "poly5",
    "acm",
    "4:3",
    "1:0",
    "0:0",
]

SETTINGS = settings(
    max_examples=60,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)


# -- mutations ----------------------------------------------------------------------


# Positions come from a Random that Hypothesis seeds: uniform over the file,
# where drawn integers would favour its first bytes.


def _span(draw, rng, data: bytes) -> tuple[int, int]:
    start = rng.randrange(len(data)) if data else 0
    return start, min(len(data), start + draw(st.integers(1, 40)))


def delete_characters(draw, rng, data: bytes) -> bytes:
    start, end = _span(draw, rng, data)
    return data[:start] + data[end:]


def duplicate_characters(draw, rng, data: bytes) -> bytes:
    start, end = _span(draw, rng, data)
    return data[:end] + data[start:end] + data[end:]


def insert_characters(draw, rng, data: bytes) -> bytes:
    position = rng.randint(0, len(data))
    syntax = st.sampled_from(list("<>/=\"'&;#!?-[] \n\tabc019.:"))
    text = draw(
        st.one_of(
            st.text(syntax, min_size=1, max_size=8).map(str.encode),
            st.binary(min_size=1, max_size=4),
            st.text(min_size=1, max_size=4).map(lambda t: t.encode("utf-8", "surrogatepass")),
        )
    )
    return data[:position] + text + data[position:]


def _lines(data: bytes) -> list[bytes]:
    return data.splitlines(keepends=True) or [b""]


def delete_line(draw, rng, data: bytes) -> bytes:
    lines = _lines(data)
    del lines[rng.randrange(len(lines))]
    return b"".join(lines)


def duplicate_line(draw, rng, data: bytes) -> bytes:
    lines = _lines(data)
    index = rng.randrange(len(lines))
    lines.insert(index, lines[index])
    return b"".join(lines)


def move_line(draw, rng, data: bytes) -> bytes:
    lines = _lines(data)
    line = lines.pop(rng.randrange(len(lines)))
    lines.insert(rng.randint(0, len(lines)), line)
    return b"".join(lines)


_ATTRIBUTE_VALUE = re.compile(
    rb'<(?:distortion|calibration)\b[^>]*?="([^"]*)"|'
    rb"<(?:cropfactor|aspect-ratio)>([^<]*)<"
)


def change_value(draw, rng, data: bytes) -> bytes:
    """Replace one distortion/calibration attribute value or crop/aspect text."""
    matches = list(_ATTRIBUTE_VALUE.finditer(data))
    if not matches:
        return data
    match = rng.choice(matches)
    group = 1 if match.group(1) is not None else 2
    value = draw(st.one_of(st.sampled_from(VALUES), st.floats().map(repr)))
    return data[: match.start(group)] + value.encode() + data[match.end(group) :]


def truncate(draw, rng, data: bytes) -> bytes:
    return data[: rng.randint(0, len(data))]


def flip_bits(draw, rng, data: bytes) -> bytes:
    """Flip one bit in each of a few random bytes, as a bad disk or transfer does."""
    mutable = bytearray(data)
    for _ in range(draw(st.integers(1, 4)) if mutable else 0):
        mutable[rng.randrange(len(mutable))] ^= 1 << rng.randrange(8)
    return bytes(mutable)


MUTATIONS = (
    delete_characters,
    duplicate_characters,
    insert_characters,
    delete_line,
    duplicate_line,
    move_line,
    change_value,
    change_value,
    truncate,
    flip_bits,
)


@st.composite
def mutated_files(draw) -> tuple[str, bytes]:
    name = draw(st.sampled_from(FILES))
    rng = draw(st.randoms(use_true_random=True))
    data = ORIGINAL[name]
    for _ in range(draw(st.integers(1, 3))):
        data = draw(st.sampled_from(MUTATIONS))(draw, rng, data)
    return name, data


# -- the independent count ------------------------------------------------------------


def _start_tag_end_line(data: bytes, offset: int, line: int) -> int:
    """Line of the ``>`` that ends the start tag beginning at byte ``offset``."""
    quote = None
    for position in range(offset, len(data)):
        byte = data[position : position + 1]
        if quote:
            quote = None if byte == quote else quote
        elif byte in (b'"', b"'"):
            quote = byte
        elif byte == b">":
            return line + data.count(b"\n", offset, position)
    raise AssertionError("start tag without end in a well-formed document")


def line_ends_normalized(data: bytes) -> bytes:
    """The document as an XML processor reads it: CR LF and a lone CR are line ends
    (XML 1.0, section 2.11), so that a file with CR-only line ends has its lines."""
    return data.replace(b"\r\n", b"\n").replace(b"\r", b"\n")


def expat_root_and_distortion_lines(data: bytes) -> tuple[str, list[int]] | None:
    """Local name of the root element and lines of the <distortion> elements per
    expat, or None if not well-formed."""
    data = line_ends_normalized(data)
    parser = xml.parsers.expat.ParserCreate()
    lines: list[int] = []
    roots: list[str] = []

    def start(name, attributes):
        if not roots:
            roots.append(name.rpartition(":")[2])
        if name == "distortion":
            lines.append(
                _start_tag_end_line(data, parser.CurrentByteIndex, parser.CurrentLineNumber)
            )

    parser.StartElementHandler = start
    try:
        parser.Parse(data, True)
    except xml.parsers.expat.ExpatError:
        return None
    return roots[0], lines


def expat_distortion_lines(data: bytes) -> list[int] | None:
    """Lines of the <distortion> elements per expat, or None if not well-formed."""
    found = expat_root_and_distortion_lines(data)
    return None if found is None else found[1]


def recovered_distortion_lines(data: bytes) -> list[int]:
    """Lines of the <distortion> elements libxml2's recovery mode finds."""
    data = line_ends_normalized(data)
    parser = etree.XMLParser(recover=True, resolve_entities=False, no_network=True, load_dtd=False)
    try:
        root = etree.fromstring(data, parser)
    except etree.XMLSyntaxError:
        return []
    return [] if root is None else [e.sourceline for e in root.iter("distortion")]


# -- the properties ---------------------------------------------------------------------


def assert_records_account_for_every_distortion(records: list[dict], data: bytes) -> None:
    """``records``: (line, status, model, focal) dicts of one file, in output order."""
    found = expat_root_and_distortion_lines(data)
    if found is not None and found[0] != "lensdatabase":
        head, *inside = records
        assert head["status"] == "not_database" and head["focal"] is None
        assert [r["line"] for r in inside] == found[1]
        assert all(r["status"] == "not_database" for r in inside)
    elif found is not None:
        assert [r["line"] for r in records] == found[1]
        assert all(r["status"] != "xml_error" for r in records)
    else:
        head, *salvaged = records
        assert head["status"] == "xml_error" and head["model"] == "" and head["focal"] is None
        assert [r["line"] for r in salvaged] == recovered_distortion_lines(data)
        assert all(r["status"] == "xml_error" for r in salvaged)


def _reader_records(data: bytes) -> list[dict]:
    entries = read_bytes(data, "mutated.xml").entries()
    return [
        dict(
            line=e.line,
            status=e.status,
            model=e.model,
            focal=None if e.focal != e.focal else e.focal,
        )
        for e in entries
    ]


def _run(arguments: list[str]):
    result = CliRunner().invoke(main, arguments)
    assert result.exception is None or isinstance(result.exception, SystemExit), (
        arguments,
        result.exception,
    )
    return result


#: Files that no random mutation is likely to give: every line end a lone CR.
CR_ONLY = ("6x6.xml", ORIGINAL["6x6.xml"].replace(b"\n", b"\r"))
CR_ONLY_BROKEN = ("6x6.xml", CR_ONLY[1].replace(b"</lens>", b"</len>", 1))


@SETTINGS
@given(mutated_files())
@example(CR_ONLY)
@example(CR_ONLY_BROKEN)
def test_the_reader_accounts_for_every_distortion_of_a_mutated_file(mutated):
    _, data = mutated
    assert_records_account_for_every_distortion(_reader_records(data), data)


@SETTINGS
@given(mutated_files())
@example(CR_ONLY)
def test_scan_and_check_never_crash_and_account_for_every_distortion(mutated):
    name, data = mutated
    with tempfile.TemporaryDirectory() as directory:
        database = Path(directory)
        (database / name).write_bytes(data)
        (database / ANCHOR).write_bytes((bundled_database_path() / ANCHOR).read_bytes())

        scan = _run(["scan", str(database), "--format", "json"])
        assert scan.exit_code == 0, scan.output
        records = [r for r in json.loads(scan.output)["entries"] if r["file"] == name]
        assert_records_account_for_every_distortion(records, data)

        check = _run(["check", str(database), "--format", "json", "--verbose"])
        assert check.exit_code in (0, 1), check.output
        document = json.loads(check.output)
        [checked] = [f for f in document["files"] if Path(f["file"]).name == name]
        findings = [f for f in document["findings"] if Path(f["file"]).name == name]
        well_formed = expat_distortion_lines(data)
        if well_formed is not None:
            assert checked["entries"] == len(well_formed) and checked["error"] == ""
            assert not any(f["code"] == "xml-error" for f in findings)
            not_audited = Counter(r["line"] for r in records if r["status"] != "ok")
            # Findings of <vignetting> and <tca> elements name their element.
            reported = Counter(
                f["line"]
                for f in findings
                if f["code"] in INPUT_CODES
                and "<vignetting>" not in f["message"]
                and "<tca>" not in f["message"]
            )
            assert reported == not_audited
        else:
            assert checked["entries"] == len(recovered_distortion_lines(data))
            # liblensfun may stop earlier, for a reason of its own (markup it
            # refuses before the point libxml2 calls not well-formed).
            refused = [f for f in findings if f["code"] == "liblensfun-refuses"]
            findings = [f for f in findings if f["code"] != "liblensfun-refuses"]
            assert [(f["code"], f["line"] >= 1, f["column"] >= 1) for f in findings] == [
                ("xml-error", True, True)
            ]
            assert len(refused) <= 1 and all(f["line"] < findings[0]["line"] for f in refused)
            assert checked["error"] == findings[0]["message"]
