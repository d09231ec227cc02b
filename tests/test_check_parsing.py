"""`lensaudit check` reads files as `lensaudit scan` does, through the one
reader: the same files, the same counts of `<distortion>` elements, the same
lens names; and duplicate lenses are compared on what the reader gives of
them (a lens's elements and its own distortion entries).

Expected counts come from a plain regular expression over each file's
bytes, never from the reader."""

from __future__ import annotations

import json
import os
import re
import tempfile
from pathlib import Path

import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from lensaudit.check import check
from lensaudit.cli import main

_COMMENT = re.compile(rb"<!--.*?-->", re.DOTALL)
_DISTORTION = re.compile(rb"<distortion\b")

COMMENT_IN_MAKER = b"""\
<lensdatabase>
    <lens>
        <maker>Tok<!---->ina</maker>
        <model>AT-X 11-16</model>
        <mount>M</mount>
        <cropfactor>1.5</cropfactor>
        <calibration><distortion model="poly3" focal="11" k1="0.01"/></calibration>
    </lens>
    <lens>
        <maker>ina</maker>
        <model>AT-X 11-16</model>
        <mount>M</mount>
        <cropfactor>1.5</cropfactor>
        <calibration><distortion model="poly3" focal="11" k1="0.01"/></calibration>
    </lens>
    <lens>
        <maker>Tokina</maker>
        <model>AT-X 11-16</model>
        <mount>M</mount>
        <cropfactor>1.5</cropfactor>
        <calibration><distortion model="poly3" focal="11" k1="0.01"/></calibration>
    </lens>
</lensdatabase>
"""


def distortion_elements(data: bytes) -> int:
    """``<distortion`` tags outside comments."""
    return len(_DISTORTION.findall(_COMMENT.sub(b"", data)))


@pytest.fixture
def broken_inputs(tmp_path: Path, bundled_db: Path) -> Path:
    """A good bundled file, a truncated copy of another, a file that is not a
    database and one with a comment inside a <maker>."""
    database = tmp_path / "db"
    database.mkdir()
    (database / "contax.xml").write_bytes((bundled_db / "contax.xml").read_bytes())
    whole = (bundled_db / "slr-tokina.xml").read_bytes()
    cut = whole.index(b"<tca", len(whole) // 2) + len(b"<tca model")  # inside a <tca>
    (database / "truncated.xml").write_bytes(whole[:cut])
    (database / "foreign.xml").write_bytes(
        b"<html>\n<distortion model='poly3' focal='10' k1='0.1'/>\n"
        b"<p><distortion model='poly3' focal='12' k1='0.1'/></p>\n</html>\n"
    )
    (database / "comment.xml").write_bytes(COMMENT_IN_MAKER)
    return database


def scan_json(path: Path) -> dict:
    result = CliRunner().invoke(main, ["scan", "--no-cache", "--format", "json", str(path)])
    assert result.exit_code == 0, result.output
    return json.loads(result.output)


def test_scan_and_check_count_the_same_distortion_elements_of_each_file(broken_inputs, bundled_db):
    expected = {
        path.name: distortion_elements(path.read_bytes())
        for path in sorted(broken_inputs.glob("*.xml"))
    }
    assert expected["comment.xml"] == 3 and expected["foreign.xml"] == 2
    whole = distortion_elements((bundled_db / "slr-tokina.xml").read_bytes())
    assert 0 < expected["truncated.xml"] < whole
    # scan has one row per element, and one more for a file it cannot use as a whole.
    scanned = {
        f["file"]: f["entries"] - bool(f["error"])
        for f in scan_json(broken_inputs)["database"]["files"]
    }
    checked = {Path(f.file).name: f.entries for f in check(broken_inputs).files}
    assert scanned == checked == expected


def test_scan_and_check_find_the_same_problems_in_the_same_files(broken_inputs):
    scanned = {f["file"]: f["error"] for f in scan_json(broken_inputs)["database"]["files"]}
    result = check(broken_inputs)
    checked = {Path(f.file).name: f.error for f in result.files}
    assert scanned == checked
    file_codes = ("xml-error", "not-a-database", "unreadable")
    problems = {Path(f.file).name: f.code for f in result.findings if f.code in file_codes}
    assert problems == {"truncated.xml": "xml-error", "foreign.xml": "not-a-database"}


def test_a_lens_is_named_as_scan_names_it_when_a_comment_splits_its_maker(broken_inputs):
    path = broken_inputs / "comment.xml"
    # As liblensfun reads it: the text after the comment.
    assert [e["maker"] for e in scan_json(path)["entries"]] == ["ina", "ina", "Tokina"]
    duplicates = [f for f in check(path).findings if f.code == "duplicate-lens"]
    assert [(f.severity, f.line, f.entry_key) for f in duplicates] == [
        ("warning", 9, ("ina", "AT-X 11-16", 1.5))
    ]
    assert duplicates[0].related == ((str(path), 2),)


def test_an_unreadable_file_is_reported_as_scan_reports_it(tmp_path):
    (tmp_path / "a.xml").write_text("<lensdatabase/>\n")
    os.mkfifo(tmp_path / "pipe.xml")
    scanned = {f["file"]: f["error"] for f in scan_json(tmp_path)["database"]["files"]}
    result = check(tmp_path)
    assert scanned["pipe.xml"].startswith("cannot read file: ")
    assert [(Path(f.file).name, f.code, f.message) for f in result.findings] == [
        ("pipe.xml", "unreadable", f"{tmp_path / 'pipe.xml'}: {scanned['pipe.xml']}")
    ]
    assert [(Path(f.file).name, f.entries) for f in result.files] == [("a.xml", 0), ("pipe.xml", 0)]


# -- duplicate lenses ------------------------------------------------------------------

LENS = """<lens>
        <maker>Test</maker>
        <model>{model}</model>
        <mount>{mount}</mount>
        <cropfactor>1.5</cropfactor>{extra}
        <calibration{calibration}><distortion model="poly3" focal="10" k1="{k1}"/></calibration>
    </lens>"""


def lens(
    model: str = "L", k1: str = "0.01", mount: str = "M", extra: str = "", calibration: str = ""
) -> str:
    return LENS.format(model=model, k1=k1, mount=mount, extra=extra, calibration=calibration)


def database(*lenses: str, namespace: str = "") -> bytes:
    return f"<lensdatabase{namespace}>\n{chr(10).join(lenses)}\n</lensdatabase>\n".encode()


def duplicate_severities(path: Path) -> list[tuple[str, int]]:
    return [(f.severity, f.line) for f in check(path).findings if f.code == "duplicate-lens"]


def test_a_lens_defined_twice_alike_is_a_warning_at_the_second(tmp_path):
    path = tmp_path / "a.xml"
    path.write_bytes(database(lens(model="L"), lens(model="l ")))
    assert duplicate_severities(path) == [("warning", 9)]


def test_the_same_values_written_differently_are_alike(tmp_path):
    # liblensfun reads the numbers, not how they are written, and ignores comments.
    path = tmp_path / "a.xml"
    second = lens(k1="1.0e-2", mount="<!-- the same -->M").replace("/>", "   />")
    path.write_bytes(database(lens(k1="0.01"), second))
    assert duplicate_severities(path) == [("warning", 9)]


@pytest.mark.parametrize(
    "second",
    [
        lens(k1="0.02"),  # a coefficient
        lens(mount="N"),  # a mount
        lens(extra='\n        <model lang="de">Anders</model>'),  # a translated name
        lens(extra="\n        <type>fisheye</type>"),  # the lens type
        lens(calibration=' aspect-ratio="4:3"'),  # what its calibration overrides
        lens(k1="0.01").replace(
            "</calibration>", '<distortion model="poly3" focal="12"/></calibration>'
        ),
    ],
    ids=["coefficient", "mount", "translation", "type", "calibration", "entry"],
)
def test_a_lens_defined_twice_differently_is_an_error(tmp_path, second):
    path = tmp_path / "a.xml"
    path.write_bytes(database(lens(), second))
    assert duplicate_severities(path) == [("error", 9)]


def test_a_lens_whose_vignetting_differs_is_not_alike(tmp_path):
    vignetting = '<vignetting model="pa" focal="10" aperture="2" distance="10" k1="{}"/>'
    path = tmp_path / "a.xml"
    path.write_bytes(
        database(
            lens().replace("</calibration>", vignetting.format("-0.1") + "</calibration>"),
            lens().replace("</calibration>", vignetting.format("-0.2") + "</calibration>"),
        )
    )
    assert duplicate_severities(path) == [("error", 9)]


def test_lenses_in_a_default_namespace_compare_as_without_it(tmp_path):
    path = tmp_path / "a.xml"
    path.write_bytes(database(lens(), lens(), namespace=' xmlns="http://example.com/lensfun"'))
    assert duplicate_severities(path) == [("warning", 9)]


def test_duplicates_in_two_files_are_compared_on_each_file(tmp_path):
    (tmp_path / "a.xml").write_bytes(database(lens(k1="0.01")))
    (tmp_path / "b.xml").write_bytes(database("\n\n" + lens(k1="0.03")))
    (tmp_path / "c.xml").write_bytes(database(lens(k1="0.01")))
    found = [(f.severity, Path(f.file).name, f.line) for f in check(tmp_path).findings]
    assert found == [("error", "b.xml", 4), ("warning", "c.xml", 2)]


def test_a_known_duplicate_moved_and_reformatted_is_known_to_the_baseline(tmp_path):
    (tmp_path / "before").mkdir()
    (tmp_path / "after").mkdir()
    (tmp_path / "before" / "a.xml").write_bytes(database(lens(), lens(k1="0.02")))
    moved = database("<!-- moved -->\n", lens(k1="1e-2"), "", lens(k1="2e-2"))
    (tmp_path / "after" / "a.xml").write_bytes(moved)
    result = check(tmp_path / "after", baseline=tmp_path / "before")
    assert [(f.code, f.severity, f.known) for f in result.findings] == [
        ("duplicate-lens", "error", True)
    ]
    assert not result.failed and result.resolved == 0


# Pieces of markup that break a file, or make it mean something else, where they land.
_SNIPPETS = [b"<", b">", b"</lens>", b"<lens>", b"<!--", b"-->", b"&x;", b"<distortion/>",
             b'"', b"\x00", b"\xff", b"<![CDATA[", b"]]>", b"<?pi ?>"]  # fmt: skip


@settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(data=st.data())
def test_scan_and_check_count_the_same_entries_of_any_mutated_file(bundled_db, tmp_path, data):
    original = (bundled_db / "slr-tokina.xml").read_bytes()
    cut = data.draw(st.integers(0, len(original)), label="cut")
    kind = data.draw(st.sampled_from(["truncate", "delete", "insert"]), label="kind")
    if kind == "truncate":
        mutated = original[:cut]
    elif kind == "delete":
        mutated = original[:cut] + original[cut + data.draw(st.integers(1, 400)) :]
    else:
        mutated = original[:cut] + data.draw(st.sampled_from(_SNIPPETS)) + original[cut:]
    folder = Path(tempfile.mkdtemp(dir=tmp_path))
    (folder / "a.xml").write_bytes(mutated)
    (folder / "b.xml").write_bytes((bundled_db / "6x6.xml").read_bytes())  # one file that reads
    scanned, _ = scan_json(folder)["database"]["files"]
    checked, _ = check(folder).files
    assert scanned["entries"] - bool(scanned["error"]) == checked.entries
    assert scanned["error"] == checked.error


def _changed_copy(bundled_db: Path, target: Path) -> Path:
    """The bundled database with one distortion entry of one file made to fold."""
    target.mkdir()
    for path in sorted(bundled_db.glob("*.xml")):
        (target / path.name).write_bytes(path.read_bytes())
    tokina = target / "slr-tokina.xml"
    data = tokina.read_bytes()
    start = data.index(b"<distortion")
    end = data.index(b"/>", start)
    focal = re.search(rb'focal="([^"]*)"', data[start:end]).group(1)
    # poly3, k1 = -0.5: D(r) = r (1.5 - 0.5 r^2) peaks at r = 1, inside any image
    folding = b'<distortion model="poly3" focal="' + focal + b'" k1="-0.5"'
    tokina.write_bytes(data[:start] + folding + data[end:])
    return target


def test_a_baseline_file_with_the_same_bytes_is_not_parsed_again(
    bundled_db: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import lensaudit.read as reader

    changed = _changed_copy(bundled_db, tmp_path / "db")
    parsed_names: list[list[str]] = []
    read_contents = reader.read_contents

    def spy(contents, *args, **kwargs):
        parsed_names.append([Path(name).name for _, name, _ in contents])
        return read_contents(contents, *args, **kwargs)

    monkeypatch.setattr(reader, "read_contents", spy)
    check(changed, baseline=bundled_db)
    assert len(parsed_names) == 2
    assert len(parsed_names[0]) == len(list(bundled_db.glob("*.xml")))
    assert parsed_names[1] == ["slr-tokina.xml"]  # the only file whose bytes differ


def test_a_baseline_read_from_the_database_tables_checks_as_one_parsed_anew(
    bundled_db: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import lensaudit.check as checking

    changed = _changed_copy(bundled_db, tmp_path / "db")
    shared = check(changed, baseline=bundled_db)
    parse_sources = checking.parse_sources
    monkeypatch.setattr(
        checking,
        "parse_sources",
        lambda sources, cache=None, parsed=(), meanwhile=None: parse_sources(
            sources, cache, meanwhile=meanwhile
        ),
    )
    anew = check(changed, baseline=bundled_db)
    assert shared.findings == anew.findings
    assert shared.resolved == anew.resolved
    assert [f.code for f in shared.findings if not f.known]  # the change is found
