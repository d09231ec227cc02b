"""The reader's promises about hostile and unusual files, each against an
independent reference: Lensfun master's liblensfun (through ctypes, skipped
with a reason where it cannot be built), or positions counted in the text.
"""

from __future__ import annotations

import csv
import io
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import lens_xml
from lensaudit.read import read, read_bytes, xml
from lensaudit.read.records import parse_number

DISTORTION = '<distortion model="ptlens" focal="10" a="0.01" b="-0.02" c="0.03"/>'


def scan_rows(*arguments: str, timeout: float = 60) -> tuple[int, list[dict[str, str]]]:
    """``lensaudit scan --format csv`` in a fresh process: its exit status and rows."""
    result = subprocess.run(
        [sys.executable, "-m", "lensaudit", "scan", "--no-cache", "--format", "csv", *arguments],
        capture_output=True,
        timeout=timeout,
        check=False,
    )
    return result.returncode, list(csv.DictReader(io.StringIO(result.stdout.decode())))


def distortion_lines(text: bytes) -> list[int]:
    """The line on which each ``<distortion`` start tag ends, counted in the text."""
    return lines_of(text, rb"<distortion\b[^>]*>", end=True)


def lines_of(text: bytes, pattern: bytes, end: bool = False) -> list[int]:
    """The line of each match of ``pattern`` in the text (where it starts, or
    with ``end`` where it ends), counted from one match to the next."""
    lines, line, position = [], 1, 0
    for match in re.finditer(pattern, text):
        at = match.end() if end else match.start()
        line += text.count(b"\n", position, at)
        position = at
        lines.append(line)
    return lines


# --- DTDs and entities -------------------------------------------------------------------


@pytest.mark.parametrize(
    "doctype",
    [
        '<!DOCTYPE lensdatabase SYSTEM "{fifo}">',
        '<!DOCTYPE lensdatabase [<!ENTITY % p SYSTEM "{fifo}"> %p;]>',
        '<!DOCTYPE lensdatabase [<!ENTITY e SYSTEM "{fifo}">]>',
    ],
)
def test_a_fifo_named_as_a_dtd_or_entity_is_never_opened(tmp_path, doctype):
    fifo = tmp_path / "dtd.fifo"
    os.mkfifo(fifo)
    database = tmp_path / "db"
    database.mkdir()
    text = lens_xml(DISTORTION).replace('<lensdatabase version="2">', "", 1)
    (database / "a.xml").write_text(doctype.format(fifo=fifo) + '<lensdatabase version="2">' + text)
    status, rows = scan_rows(str(database), timeout=30)  # a FIFO opened would block forever
    assert status == 0
    assert [row["status"] for row in rows] == ["ok"]


def test_an_attlist_default_is_not_applied_as_liblensfun_does_not(write_xml):
    from liblensfun_master import lenses

    text = lens_xml('<distortion model="ptlens" focal="10" b="-0.02" c="0.03"/>').replace(
        '<lensdatabase version="2">',
        '<!DOCTYPE lensdatabase [<!ATTLIST distortion a CDATA "0.5">]>\n<lensdatabase version="2">',
    )
    [lens] = lenses(text.encode())
    [theirs] = lens["distortion"]
    [entry] = read_bytes(text.encode(), "a.xml").entries()
    assert entry.status == "ok"
    assert entry.a == theirs["terms"][0] == 0.0


@pytest.mark.parametrize(
    "maker, refused",
    [
        ("&x;", True),  # an entity the internal subset declares
        ("T&#111;kina", False),  # a character reference
        ("A&amp;B&lt;C&gt;D&quot;E&apos;F", False),  # the five predefined entities
    ],
)
def test_entity_references_are_refused_where_liblensfun_refuses_them(maker, refused):
    from liblensfun_master import lenses, load_verdict

    text = (
        lens_xml(DISTORTION)
        .replace(
            '<lensdatabase version="2">',
            '<!DOCTYPE lensdatabase [<!ENTITY x "Foo">]>\n<lensdatabase version="2">',
        )  # fmt: skip
        .replace("<maker>Test</maker>", f"<maker>{maker}</maker>")
    ).encode()
    loaded, _ = load_verdict(text)
    tables = read_bytes(text, "a.xml")
    assert loaded is not refused
    assert (tables.status == "xml_error") is refused
    if refused:
        assert "&x;" in tables.error and "liblensfun refuses" in tables.error
        assert tables.line == text.count(b"\n", 0, text.index(b"&x;</maker>")) + 1
    else:
        [lens] = lenses(text)
        assert tables.lenses[0].maker == lens["maker"]


def test_an_entity_in_an_attribute_never_gives_a_value():
    text = lens_xml('<distortion model="ptlens" focal="10" a="&x;" b="0" c="0"/>').replace(
        '<lensdatabase version="2">',
        '<!DOCTYPE lensdatabase SYSTEM "nowhere.dtd">\n<lensdatabase version="2">',
    )
    tables = read_bytes(text.encode(), "a.xml")
    assert tables.status == "xml_error"
    assert all(row[-2] == "xml_error" for row in tables.distortion)


def test_an_unused_internal_subset_changes_nothing(bundled_db):
    data = (bundled_db / "slr-tokina.xml").read_bytes()
    declaration = b'<!DOCTYPE lensdatabase [<!ENTITY x "Foo"><!ATTLIST lens q CDATA "5">]>\n'
    start = data.index(b"<lensdatabase")
    declared = data[:start] + declaration + data[start:]
    plain = read_bytes(data, "a.xml")
    with_subset = read_bytes(declared, "a.xml")
    assert with_subset.status == "ok"
    # The same rows, one line further down.
    shifted = [(row[0] + 1, *row[1:]) for row in plain.distortion]
    assert repr(with_subset.distortion) == repr(shifted)


# --- line numbers ------------------------------------------------------------------------


def test_lines_of_a_file_with_cr_only_line_ends_are_its_lines(bundled_db):
    data = (bundled_db / "slr-tokina.xml").read_bytes()
    assert b"\r" not in data
    expected = distortion_lines(data)
    for ends in (b"\r", b"\r\n"):
        tables = read_bytes(data.replace(b"\n", ends), "a.xml")
        assert [row[0] for row in tables.distortion] == expected


@pytest.mark.parametrize(
    "padding", [b"\n" * 70_000, b"<!-- -->\n" * 70_000], ids=["blank lines", "comments"]
)
@pytest.mark.parametrize(
    "root", [b"<lensdatabase", b'<lensdatabase xmlns="http://x.org"'], ids=["plain", "namespaced"]
)
def test_lines_beyond_65535_are_counted(bundled_db, padding, root):
    # A default namespace has the file read as one tree rather than piece by piece.
    data = (bundled_db / "slr-tokina.xml").read_bytes().replace(b"<lensdatabase", root, 1)
    start = data.index(b">", data.index(b"<lensdatabase")) + 1
    long = data[:start] + padding + data[start:]
    tables = read_bytes(long, "a.xml")
    lines = [row[0] for row in tables.distortion]
    assert lines == distortion_lines(long)
    assert min(lines) > 70_000
    assert [lens.line for lens in tables.lenses] == lines_of(long, rb"<lens>")


def test_lines_beyond_65535_of_a_start_tag_over_two_lines_are_where_it_ends(bundled_db):
    body = "\n".join(
        [f'<distortion model="poly3" focal="{f}"\n k1="-0.01"/>' for f in range(1, 40_000)]
    )
    text = lens_xml(body).encode()
    tables = read_bytes(text, "a.xml")
    assert [row[0] for row in tables.distortion] == distortion_lines(text)


def test_a_piece_of_200000_lines_is_read_in_time_linear_in_its_size(tmp_path):
    # One <lens> of 200,000 lines: letting go of the line numbers of its elements
    # once it was cut out of the tree took time in its elements squared (hours
    # here), where reading it now takes seconds. Read in a process of its own,
    # which the timeout ends however long lxml works in C.
    rows = (
        f'<distortion model="ptlens" focal="{focal / 1000 + 10:.3f}" a="0.01" b="-0.02" c="0"/>'
        for focal in range(200_000)
    )
    text = lens_xml(*rows).encode()
    path = tmp_path / "a.xml"
    path.write_bytes(text)
    program = (
        "import sys; from lensaudit.read import read_bytes\n"
        "tables = read_bytes(open(sys.argv[1], 'rb').read(), 'a.xml')\n"
        "print(tables.status, *(row[0] for row in tables.distortion))\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", program, str(path)],
        capture_output=True,
        timeout=180,
        check=True,
    )
    status, *lines = result.stdout.split()
    expected = distortion_lines(text)
    assert expected[-1] > 200_000
    assert status == b"ok"
    assert [int(line) for line in lines] == expected


# --- directories ----------------------------------------------------------------------------


def test_a_link_loop_and_a_dangling_link_are_status_rows_of_their_own(tmp_path):
    database = tmp_path / "db"
    database.mkdir()
    (database / "good.xml").write_text(lens_xml(DISTORTION))
    (database / "loop.xml").symlink_to(database / "loop.xml")
    (database / "gone.xml").symlink_to(tmp_path / "nowhere.xml")
    status, rows = scan_rows(str(database))
    assert status == 0
    by_file = {row["file"]: row for row in rows}
    assert by_file["good.xml"]["status"] == "ok"
    assert by_file["loop.xml"]["status"] == "unreadable"
    assert "symbolic links" in by_file["loop.xml"]["message"]
    assert by_file["gone.xml"]["status"] == "unreadable"
    assert "No such file" in by_file["gone.xml"]["message"]


# --- numbers --------------------------------------------------------------------------------


@pytest.mark.parametrize("text", ["1\u00a0", "\u00a01.5", "\uff11.5", "1\u0660", "\u0661"])
def test_a_no_break_space_or_a_digit_that_is_not_ascii_is_not_a_number(text):
    float(text)  # Python itself would take it
    with pytest.raises(ValueError, match="is not a number"):
        parse_number(text)


def test_each_file_is_parsed_once(bundled_db, monkeypatch):
    calls = []
    parse = xml.parse

    def counted(data, *arguments):
        calls.append(len(data))
        return parse(data, *arguments)

    monkeypatch.setattr(xml, "parse", counted)
    monkeypatch.setattr("lensaudit.read.parallel.cpus", lambda: 1)  # counted in this process
    database = read(bundled_db, calibrations=True)
    assert len(calls) == len(database.files) == len(list(Path(bundled_db).glob("*.xml")))
