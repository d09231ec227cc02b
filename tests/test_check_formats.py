"""Output formats of `lensaudit check`: text, json, github annotations, JUnit XML."""

from __future__ import annotations

import io
import json
import xml.etree.ElementTree as StdlibET
from pathlib import Path

import pytest

from lensaudit.check import CheckedFile, CheckResult, Finding
from lensaudit.check_formats import FORMATS, printable, writer
from lensaudit.check_formats.github import annotation, escape_data, escape_property

FOLD = Finding(
    "error",
    "fold-in-image",
    "data/db/a.xml",
    12,
    0,
    "Lens (poly3, 10 mm): folds",
    ("Maker", "Lens", 1.5, "poly3", 10.0),
)
BROKEN = Finding("error", "xml-error", "data/db/b.xml", 3, 7, "XML is not well-formed at line 3")
NEAR = Finding("warning", "fold-near-image", "data/db/a.xml", 20, 0, "Lens: near", ("M", "L"))
KNOWN = Finding("error", "duplicate-focal", "data/db/a.xml", 30, 0, "Lens: twice", known=True)


def result(*findings: Finding, baseline: str | None = None) -> CheckResult:
    files = [
        CheckedFile("data/db/a.xml", Path("/repo/data/db/a.xml"), 3),
        CheckedFile("data/db/b.xml", Path("/repo/data/db/b.xml"), 0, "XML is not well-formed"),
        CheckedFile("data/db/c.xml", Path("/repo/data/db/c.xml"), 2),
    ]
    return CheckResult("test database", baseline, 1.1, files, list(findings))


def render(name: str, check_result: CheckResult) -> str:
    stream = io.StringIO()
    writer(name)(check_result, stream)
    return stream.getvalue()


# -- github ------------------------------------------------------------------------


def test_github_message_escapes_percent_carriage_return_and_line_feed():
    assert escape_data("100% sure\r\nnext: a, b") == "100%25 sure%0D%0Anext: a, b"


def test_github_property_also_escapes_colon_and_comma():
    assert escape_property("C:\\db,1%\n") == "C%3A\\db%2C1%25%0A"


def test_github_annotation_carries_file_line_column_and_title():
    assert annotation(BROKEN) == (
        "::error file=data/db/b.xml,line=3,col=7,title=lensaudit xml-error::"
        "XML is not well-formed at line 3"
    )
    assert annotation(NEAR).startswith(
        "::warning file=data/db/a.xml,line=20,title=lensaudit fold-near-image::"
    )


def test_github_annotation_cannot_be_split_by_hostile_text():
    hostile = Finding("error", "bad-value", "x,y:z.xml", 1, 0, "a\nb\r::error ::c%0A\x1b[31m")
    line = annotation(hostile)
    assert "\n" not in line and "\r" not in line and "\x1b" not in line
    assert line.startswith("::error file=x%2Cy%3Az.xml,line=1,title=")
    assert line.endswith("::a%0Ab%0D::error ::c%250A\\x1b[31m")


def test_github_annotates_new_findings_only_and_ends_with_the_verdict():
    text = render("github", result(FOLD, KNOWN, baseline="origin/main"))
    commands = [line for line in text.splitlines() if line.startswith("::")]
    assert commands[0] == annotation(FOLD)
    assert "data/db/a.xml:30: error [duplicate-focal] Lens: twice" in text
    assert text.splitlines()[-1].startswith("lensaudit check FAILED: 3 files, 5 distortion")


@pytest.mark.parametrize(
    "name",
    ["Lens ##[stop-commands]tok ##[error]pwned", "::error file=x.xml,line=1::pwned", "%0A::x::"],
)
def test_github_reads_no_command_in_a_known_finding(name):
    # GitHub reads "::command::" after leading spaces, and "##[command]" anywhere in
    # a line: the known findings are written with commands stopped around them.
    known = Finding("error", "fold-in-image", name, 9, 0, f"{name}: folds", known=True)
    lines = render("github", result(FOLD, known, baseline="HEAD")).splitlines()
    stop = next(i for i, line in enumerate(lines) if line.startswith("::stop-commands::"))
    token = lines[stop].removeprefix("::stop-commands::")
    end = lines.index(f"::{token}::")
    assert lines[:stop] == [annotation(FOLD)]
    assert any(name in line for line in lines[stop + 1 : end])
    assert not any(name in line or token in line for line in lines[end + 1 :])
    assert len(token) == 32 and all(token not in line for line in lines[stop + 1 : end])


# -- text --------------------------------------------------------------------------


def test_text_lists_new_findings_then_known_ones_then_the_verdict():
    lines = render("text", result(BROKEN, NEAR, KNOWN, baseline="HEAD")).splitlines()
    assert lines == [
        "lensaudit check: test database",
        "data/db/b.xml:3:7: error [xml-error] XML is not well-formed at line 3",
        "data/db/a.xml:20: warning [fold-near-image] Lens: near",
        "",
        "Known from baseline HEAD (not failing):",
        "  data/db/a.xml:30: error [duplicate-focal] Lens: twice",
        "",
        "lensaudit check FAILED: 3 files, 5 distortion entries; 1 error, 1 warning; "
        "1 known from baseline HEAD, 0 resolved",
    ]


def test_text_says_passed_when_only_warnings_are_new():
    assert render("text", result(NEAR)).splitlines()[-1] == (
        "lensaudit check passed: 3 files, 5 distortion entries; 0 errors, 1 warning"
    )


def test_text_shows_control_characters_as_escapes():
    hostile = Finding("error", "bad-value", "a.xml", 1, 0, "x\x1b[2Jy\x9b\u2028z\udcff")
    assert "x\\x1b[2Jy\\x9b\\u2028z\\udcff" in render("text", result(hostile))
    assert printable("plain \u00e9") == "plain \u00e9"
    # Bidirectional marks and overrides would show the text in another order.
    assert printable("rlo\u202egnp.exe \u2066x\u2069\u200f") == (
        "rlo\\u202egnp.exe \\u2066x\\u2069\\u200f"
    )


# -- json --------------------------------------------------------------------------


def test_json_has_verdict_counts_files_and_findings():
    document = json.loads(render("json", result(FOLD, NEAR, KNOWN, baseline="HEAD")))
    assert document["summary"] == {
        "failed": True,
        "files": 3,
        "entries": 5,
        "errors": 1,
        "warnings": 1,
        "notices": 0,
        "known": 1,
        "resolved": 0,
    }
    assert document["baseline"] == "HEAD" and document["margin"] == 1.1
    assert [f["entries"] for f in document["files"]] == [3, 0, 2]
    first = document["findings"][0]
    assert first == {
        "severity": "error",
        "code": "fold-in-image",
        "file": "data/db/a.xml",
        "line": 12,
        "column": 0,
        "message": "Lens (poly3, 10 mm): folds",
        "entry_key": ["Maker", "Lens", 1.5, "poly3", 10.0],
        "known": False,
        "fails": True,
        "related": [],
    }
    assert document["findings"][2]["known"] and not document["findings"][2]["fails"]


def test_json_is_strict_when_a_key_holds_nan():
    key = ("M", "L", 1.0, "", float("nan"))
    nan_key = Finding("error", "missing-attribute", "a.xml", 1, 0, "m", key)
    text = render("json", result(nan_key))
    assert json.loads(text)["findings"][0]["entry_key"] == ["M", "L", 1.0, "", None]
    assert "NaN" not in text


# -- junit -------------------------------------------------------------------------


def test_junit_has_a_suite_per_file_and_a_failure_per_failing_finding():
    root = StdlibET.fromstring(render("junit", result(FOLD, NEAR, KNOWN, BROKEN)))
    assert root.tag == "testsuites"
    assert (root.get("tests"), root.get("failures"), root.get("skipped")) == ("5", "2", "1")
    suites = {suite.get("name"): suite for suite in root.iter("testsuite")}
    assert list(suites) == ["data/db/a.xml", "data/db/b.xml", "data/db/c.xml"]
    cases = suites["data/db/a.xml"].findall("testcase")
    assert [c.get("name") for c in cases] == [
        "data/db/a.xml:12 fold-in-image",
        "data/db/a.xml:20 fold-near-image",
        "data/db/a.xml:30 duplicate-focal",
    ]
    assert cases[0].find("failure").get("type") == "fold-in-image"
    assert cases[1].find("failure") is None and "warning" in cases[1].find("system-out").text
    assert cases[2].find("skipped") is not None
    [clean] = suites["data/db/c.xml"].findall("testcase")
    assert len(clean) == 0  # passes: no failure, no skip


def test_junit_stays_well_formed_with_characters_xml_cannot_hold():
    hostile = Finding("error", "bad-value", "a\udcff.xml", 1, 0, "<&>\"' \x01 \ufffe")
    root = StdlibET.fromstring(render("junit", result(hostile)))
    failure = next(root.iter("failure"))
    assert failure.get("message") == "<&>\"' \ufffd \ufffd"


@pytest.mark.parametrize("name", sorted(FORMATS))
def test_every_format_writes_an_empty_result(name):
    assert render(name, CheckResult("db", None, 1.1, [], []))


def test_relative_to_rewrites_paths_under_the_root_only():
    outside = Finding("error", "bad-value", "/elsewhere/x.xml", 1, 0, "m")
    check_result = result(FOLD, outside)
    check_result = CheckResult(
        "db",
        None,
        1.1,
        [
            CheckedFile("data/db/a.xml", Path("/repo/data/db/a.xml").resolve(), 1),
            CheckedFile("/elsewhere/x.xml", Path("/elsewhere/x.xml"), 1),
        ],
        check_result.findings,
    )
    moved = check_result.relative_to("/repo/data")
    assert [f.file for f in moved.findings] == ["db/a.xml", "/elsewhere/x.xml"]
    assert [f.file for f in moved.files] == ["db/a.xml", "/elsewhere/x.xml"]


def test_relative_to_takes_the_deepest_root_holding_each_file():
    files = [
        CheckedFile("/repo/data/db/a.xml", Path("/repo/data/db/a.xml"), 1),
        CheckedFile("/repo/vendor/db/b.xml", Path("/repo/vendor/db/b.xml"), 1),
    ]
    duplicate = Finding(
        "error", "duplicate-lens", "/repo/vendor/db/b.xml", 2, 0, "m",
        related=(("/repo/data/db/a.xml", 5),),
    )  # fmt: skip
    moved = CheckResult("db", None, 1.1, files, [duplicate]).relative_to("/repo", "/repo/vendor")
    assert [f.file for f in moved.files] == ["data/db/a.xml", "db/b.xml"]
    assert moved.findings[0].file == "db/b.xml"
    assert moved.findings[0].related == (("data/db/a.xml", 5),)


def test_json_gives_the_place_a_duplicate_repeats():
    duplicate = Finding(
        "error", "duplicate-focal", "data/db/a.xml", 13, 0, "m", related=(("data/db/a.xml", 12),)
    )
    [finding] = json.loads(render("json", result(duplicate)))["findings"]
    assert finding["related"] == [{"file": "data/db/a.xml", "line": 12}]
