"""Hostile and broken input: never a traceback, never a leak, always a clear message.

Each hostile database is run through every output format of `lensaudit
check` and of `lensaudit scan`; the secret must appear in none of them and
no command may end in an exception other than its exit status.
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from click.testing import CliRunner

import liblensfun_load
from conftest import lens_xml
from lensaudit.check import MESSAGE_LIMIT, check
from lensaudit.check.rules.fold import SUGGESTED_NAME_LIMIT
from lensaudit.cli import main

SECRET = "TOPSECRET-4c1d"
FOLDING = '<distortion model="poly3" focal="10" k1="-0.3"/>'

CHECK_RUNS = [
    ["--format", "text"],
    ["--format", "text", "--verbose"],
    ["--format", "json", "--verbose"],
    ["--format", "github", "--verbose"],
    ["--format", "junit", "--verbose"],
]
SCAN_RUNS = [["--format", "csv"], ["--format", "json"], ["--format", "table"]]


@pytest.fixture
def secret_files(tmp_path) -> dict[str, Path]:
    """A secret as plain text, as a DTD declaring an entity, and as an XML fragment."""
    secret = tmp_path / "secret"
    secret.mkdir()
    text = secret / "secret.txt"
    text.write_text(SECRET)
    dtd = secret / "secret.dtd"
    dtd.write_text(f'<!ENTITY leak "{SECRET}">\n<!ENTITY % inner "{SECRET}">\n')
    fragment = secret / "fragment.xml"
    fragment.write_text(f"<maker>{SECRET}</maker>")
    return {"text": text, "dtd": dtd, "fragment": fragment}


def hostile_documents(files: dict[str, Path]) -> dict[str, str]:
    """Ways a Lensfun file could try to pull the secret into the output."""
    text, dtd, fragment = (files[k].as_uri() for k in ("text", "dtd", "fragment"))
    folding = lens_xml(FOLDING)

    def with_maker(maker: str, doctype: str) -> str:
        return doctype + "\n" + folding.replace("<maker>Test</maker>", f"<maker>{maker}</maker>")

    return {
        "external entity in text": with_maker("&x;", f'<!DOCTYPE d [<!ENTITY x SYSTEM "{text}">]>'),
        "external entity in attribute": with_maker(
            "Test", f'<!DOCTYPE d [<!ENTITY x SYSTEM "{text}">]>'
        ).replace('k1="-0.3"', 'k1="&x;"'),
        "external DTD": with_maker("&leak;", f'<!DOCTYPE lensdatabase SYSTEM "{dtd}">'),
        "parameter entity": with_maker(
            "&leak;", f'<!DOCTYPE d [<!ENTITY % p SYSTEM "{dtd}"> %p;]>'
        ),
        "entity from an entity file": with_maker(
            "&frag;", f'<!DOCTYPE d [<!ENTITY frag SYSTEM "{fragment}">]>'
        ),
        "xinclude": with_maker(
            f'<xi:include xmlns:xi="http://www.w3.org/2001/XInclude" href="{text}" parse="text"/>',
            "",
        ),
    }


def outputs(database: Path) -> list[tuple[list[str], object]]:
    """(arguments, result) of every check and scan format on the database."""
    runner = CliRunner()
    runs = [["check", str(database), *a] for a in CHECK_RUNS]
    runs += [["scan", str(database), *a] for a in SCAN_RUNS]
    return [(arguments, runner.invoke(main, arguments)) for arguments in runs]


def assert_clean_exit(arguments, result) -> None:
    """Exit status 0, 1 or 2 and no exception escaping the command."""
    assert result.exit_code in (0, 1, 2), (arguments, result.output)
    if result.exception is not None:
        assert isinstance(result.exception, SystemExit), (arguments, result.exception)


@pytest.mark.parametrize(
    "case",
    [
        "external entity in text",
        "external entity in attribute",
        "external DTD",
        "parameter entity",
        "entity from an entity file",
        "xinclude",
    ],
)
def test_secret_file_never_reaches_any_output(tmp_path, secret_files, case):
    database = tmp_path / "db"
    database.mkdir()
    (database / "hostile.xml").write_text(hostile_documents(secret_files)[case])
    (database / "plain.xml").write_text(lens_xml(FOLDING))  # so scan has a readable file
    for arguments, result in outputs(database):
        assert_clean_exit(arguments, result)
        assert SECRET not in result.output, arguments


class Listener:
    """A TCP port on 127.0.0.1 that counts the connections made to it."""

    def __init__(self) -> None:
        self.server = socket.create_server(("127.0.0.1", 0))
        self.server.settimeout(0.05)
        self.port = self.server.getsockname()[1]
        self.connections = 0
        self.running = True
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _serve(self) -> None:
        while self.running:
            try:
                connection, _ = self.server.accept()
            except OSError:
                continue
            self.connections += 1
            connection.close()

    def close(self) -> int:
        self.running = False
        self.thread.join()
        self.server.close()
        return self.connections


def test_nothing_is_fetched_from_the_network(tmp_path):
    listener = Listener()
    url = f"http://127.0.0.1:{listener.port}"
    try:
        database = tmp_path / "db"
        database.mkdir()
        documents = {
            "dtd.xml": f'<!DOCTYPE lensdatabase SYSTEM "{url}/a.dtd">\n' + lens_xml(FOLDING),
            "entity.xml": f'<!DOCTYPE d [<!ENTITY x SYSTEM "{url}/x">]>\n'
            + lens_xml(FOLDING).replace("<maker>Test</maker>", "<maker>&x;</maker>"),
            "parameter.xml": f'<!DOCTYPE d [<!ENTITY % p SYSTEM "{url}/p"> %p;]>\n'
            + lens_xml(FOLDING),
        }
        for name, text in documents.items():
            (database / name).write_text(text)
        for arguments, result in outputs(database):
            assert_clean_exit(arguments, result)
    finally:
        connections = listener.close()
    assert connections == 0


def entity_bomb(where: str) -> str:
    """A billion-laughs document with the expansion in element text or an attribute."""
    entities = '<!ENTITY l0 "lol">' + "".join(
        f'<!ENTITY l{i} "{("&l" + str(i - 1) + ";") * 10}">' for i in range(1, 10)
    )
    body = lens_xml(FOLDING)
    if where == "text":
        body = body.replace("<maker>Test</maker>", "<maker>&l9;</maker>")
    else:
        body = body.replace('model="poly3"', 'model="&l9;"')
    return f"<!DOCTYPE d [{entities}]>\n{body}"


@pytest.mark.parametrize("where", ["text", "attribute"])
def test_entity_expansion_bomb_is_not_expanded(tmp_path, where):
    database = tmp_path / "db"
    database.mkdir()
    (database / "bomb.xml").write_text(entity_bomb(where))
    (database / "plain.xml").write_text(lens_xml(FOLDING))
    for arguments, result in outputs(database):
        assert_clean_exit(arguments, result)
        assert "lollollol" not in result.output and len(result.output) < 100_000, arguments


def test_bomb_in_an_attribute_is_reported_as_refused(write_xml):
    [finding] = check(write_xml(entity_bomb("attribute"))).findings
    assert finding.code == "xml-error"
    assert "reference to the entity &" in finding.message
    assert "liblensfun refuses the file" in finding.message


# -- broken files: one clear finding each -------------------------------------------


def only_finding(path: Path):
    result = check(path)
    assert len(result.findings) == 1, result.findings
    return result.findings[0]


def test_empty_file_says_it_is_empty(write_xml):
    finding = only_finding(write_xml(b""))
    assert (finding.code, finding.line, finding.column) == ("xml-error", 1, 1)
    assert "the file is empty" in finding.message


def test_whitespace_only_file_says_it_is_empty(write_xml):
    assert "the file is empty" in only_finding(write_xml(b"  \n\n ")).message


def test_non_utf8_file_names_the_byte_and_the_encoding_expected(write_xml):
    xml = lens_xml(FOLDING).replace("<maker>Test</maker>", "<maker>Caf\u00e9</maker>")
    data = xml.encode("latin-1")
    finding = only_finding(write_xml(data))
    offset = data.index(b"\xe9")
    assert finding.code == "xml-error" and finding.line == 3
    assert f"byte 0xE9 at offset {offset} is not UTF-8" in finding.message
    assert "Lensfun database files are UTF-8" in finding.message


def test_utf16_file_with_a_byte_order_mark_is_read(write_xml):
    text = lens_xml(FOLDING)
    fold_line = next(n for n, line in enumerate(text.splitlines(), 1) if FOLDING in line)
    data = text.encode("utf-16")
    result = check(write_xml(data))
    # liblensfun reads UTF-8 only: it refuses the file from its first byte.
    loaded, _ = liblensfun_load.load_and_lenses(data)
    assert not loaded.ok
    assert [(f.code, f.line) for f in result.findings] == [
        ("liblensfun-refuses", liblensfun_load.stop_line(loaded)),
        ("fold-in-image", fold_line),
    ]


def test_binary_garbage_is_an_xml_error(write_xml):
    finding = only_finding(write_xml(bytes(range(256)) * 4))
    assert finding.code == "xml-error" and finding.line >= 1


def test_attribute_value_over_the_size_limit_is_refused_clearly(write_xml):
    huge = "1" * 11_000_000
    finding = only_finding(write_xml(lens_xml(f'<distortion model="poly3" focal="{huge}"/>')))
    assert finding.code == "xml-error"
    assert "over 10 MB" in finding.message and "XML_PARSE_HUGE" not in finding.message
    assert len(finding.message) <= MESSAGE_LIMIT


@pytest.mark.parametrize("attribute", ["focal", "k1"])
def test_huge_number_below_the_limit_gives_a_short_message(write_xml, attribute):
    huge = "9" * 1_000_000
    distortion = '<distortion model="poly3" focal="10" k1="0.1"/>'.replace(
        f'{attribute}="', f'{attribute}="{huge}'
    )
    finding = only_finding(write_xml(lens_xml(distortion)))
    assert finding.code == "bad-value" and "overflows a double" in finding.message
    assert len(finding.message) <= MESSAGE_LIMIT


def test_huge_lens_name_is_shortened_in_messages(write_xml):
    name = "N" * 1_000_000
    xml = lens_xml(FOLDING).replace("<model>Test 10mm</model>", f"<model>{name}</model>")
    path = write_xml(xml)
    finding = only_finding(path)
    assert finding.code == "fold-in-image"
    # The command to paste is kept whole beyond the limit: a name cut to
    # SUGGESTED_NAME_LIMIT characters, the focal length and the file.
    head, mark, command = finding.message.rpartition("`lensaudit fix ")
    assert mark and len(head) <= MESSAGE_LIMIT
    assert len(command) <= SUGGESTED_NAME_LIMIT + len(str(path)) + 60


def test_huge_output_of_the_cli_stays_short(write_xml):
    path = write_xml(lens_xml(f'<distortion model="{"m" * 1_000_000}" focal="10"/>'))
    for arguments, result in outputs(path.parent):
        assert_clean_exit(arguments, result)
        if arguments[0] == "check":
            assert len(result.output) < 20_000, arguments


@pytest.mark.parametrize(
    ("value", "shown"),
    [
        ("NaN", "'NaN'"),
        ("nan", "'nan'"),
        ("inf", "'inf'"),
        ("-Infinity", "'-Infinity'"),
        ("+INF", "'+INF'"),
    ],
)
def test_nan_and_inf_as_text_are_not_finite_numbers(write_xml, value, shown):
    finding = only_finding(
        write_xml(lens_xml(f'<distortion model="poly3" focal="10" k1="{value}"/>'))
    )
    assert finding.code == "bad-value"
    assert f"k1={shown} is not a finite number" in finding.message


def test_nan_focal_is_not_a_finite_number(write_xml):
    finding = only_finding(write_xml(lens_xml('<distortion model="poly3" focal="nan" k1="0"/>')))
    assert "focal='nan' is not a finite number" in finding.message


def test_nesting_too_deep_is_refused_clearly(write_xml):
    finding = only_finding(write_xml("<a>" * 1000 + "</a>" * 1000))
    assert finding.code == "xml-error" and "nesting over 256 levels" in finding.message


def test_empty_directory_exits_2_with_a_clear_message(tmp_path):
    result = CliRunner().invoke(main, ["check", str(tmp_path)])
    assert result.exit_code == 2
    assert result.output.strip() == (
        f"lensaudit: error: {tmp_path}: directory holds no *.xml files "
        "(give a Lensfun database directory, a Lensfun checkout, or XML files)"
    )


def test_directory_without_xml_exits_2_with_a_clear_message(tmp_path):
    (tmp_path / "timestamp.txt").write_text("1")
    (tmp_path / "sub.xml").mkdir()  # a directory, not a file
    result = CliRunner().invoke(main, ["check", str(tmp_path)])
    assert result.exit_code == 2
    assert "directory holds no *.xml files" in result.output


def test_unreadable_file_is_a_finding_and_the_others_are_checked(write_xml, monkeypatch):
    write_xml(lens_xml(FOLDING), "a.xml")
    path = write_xml(lens_xml(FOLDING), "b.xml")
    original = os.open

    def open_file(file, *arguments, **keywords):
        # The lowest level a file is opened at, whoever reads it.
        if Path(file).name == "b.xml":
            raise PermissionError(13, "Permission denied")
        return original(file, *arguments, **keywords)

    monkeypatch.setattr(os, "open", open_file)
    result = check(path.parent)
    assert [(f.code, Path(f.file).name) for f in result.findings] == [
        ("fold-in-image", "a.xml"),
        ("unreadable", "b.xml"),
    ]
    assert "Permission denied" in result.findings[1].message


def test_no_readable_file_at_all_exits_2(write_xml, monkeypatch):
    path = write_xml(lens_xml(FOLDING))
    original = os.open

    def open_file(file, *arguments, **keywords):
        if Path(file).name == path.name:
            raise PermissionError(13, "Permission denied")
        return original(file, *arguments, **keywords)

    monkeypatch.setattr(os, "open", open_file)
    result = CliRunner().invoke(main, ["check", str(path)])
    assert result.exit_code == 2
    assert result.output.startswith("lensaudit: error: no file could be read:")


def test_file_name_cannot_inject_workflow_commands(tmp_path, monkeypatch):
    database = tmp_path / "db"
    database.mkdir()
    (database / "a,b:c\n::error ::x.xml").write_text(lens_xml(FOLDING))
    monkeypatch.setenv("GITHUB_WORKSPACE", str(tmp_path))
    result = CliRunner().invoke(main, ["check", str(database), "--format", "github"])
    commands = [line for line in result.output.splitlines() if line.startswith("::")]
    assert len(commands) == 1
    assert commands[0].startswith("::error file=db/a%2Cb%3Ac%0A%3A%3Aerror %3A%3Ax.xml,line=10,")


def test_control_characters_in_a_lens_name_do_not_reach_the_terminal(write_xml):
    # U+009B is a C1 control character (CSI) that XML 1.0 allows.
    xml = lens_xml(FOLDING).replace("<model>Test 10mm</model>", "<model>A\u009b2JB</model>")
    result = CliRunner().invoke(main, ["check", str(write_xml(xml))])
    assert "\u009b" not in result.output and "A\\x9b2JB" in result.output


def test_control_characters_from_a_database_are_escaped_in_the_scan_table(write_xml):
    # A line end and a CSI in a lens name, a BEL in a file name, an override in a
    # message: none may move the cursor or make a row of its own.
    name = "A&#13;FAKE&#10;  0.000  Spoofed\u009b31m\u202eolleh"
    write_xml(lens_xml(FOLDING).replace("<model>Test 10mm</model>", f"<model>{name}</model>"))
    write_xml("<lensdatabase><lens>\u202e</lensdatabase>", "bel\a.xml")
    result = CliRunner().invoke(main, ["scan", str(write_xml(lens_xml(FOLDING), "c.xml").parent)])
    assert result.exit_code == 0, result.output
    assert not set(result.output) & {"\r", "\a", "\x1b", "\u009b", "\u202e"}
    assert "A\\x0dFAKE\\x0a  0.000  Spoofed\\x9b31m\\u202eolleh" in result.output
    assert "bel\\x07.xml:1: xml_error:" in result.output


def test_a_distortion_in_a_file_that_is_not_well_formed_is_counted_not_checked(write_xml):
    xml = lens_xml(FOLDING, '<distortion model="poly3" focal="11" k1="-0.3">')  # not closed
    result = check(write_xml(xml))
    assert [f.code for f in result.findings] == ["xml-error"]
    assert result.files[0].entries == 2


def test_scan_reports_content_after_the_root_element(write_xml):
    xml = lens_xml(FOLDING) + '<tca model="linear" focal="10" kr="1" kb="1"/>\n'
    path = write_xml(xml)
    plain = write_xml(lens_xml(FOLDING), "plain.xml")
    result = CliRunner().invoke(main, ["scan", str(plain.parent), "-f", "json"])
    statuses = {(e["file"], e["status"]) for e in json.loads(result.output)["entries"]}
    assert (path.name, "xml_error") in statuses


def test_scan_reports_a_repeated_attribute_in_an_unread_element(write_xml):
    xml = lens_xml(FOLDING, '<tca model="linear" model="poly3" focal="10"/>')
    path = write_xml(xml)
    plain = write_xml(lens_xml(FOLDING), "plain.xml")
    result = CliRunner().invoke(main, ["scan", str(plain.parent), "-f", "json"])
    statuses = {(e["file"], e["status"]) for e in json.loads(result.output)["entries"]}
    assert statuses == {(path.name, "xml_error"), (plain.name, "ok")}


def test_no_output_format_leaks_environment_or_traceback(write_xml, monkeypatch):
    monkeypatch.setenv("LENSAUDIT_TEST_SECRET", SECRET)
    path = write_xml(b"\x00\xff<lensdatabase")
    plain = write_xml(lens_xml(FOLDING), "plain.xml")
    assert os.environ["LENSAUDIT_TEST_SECRET"] == SECRET
    for arguments, result in outputs(plain.parent):
        assert_clean_exit(arguments, result)
        assert "Traceback" not in result.output and SECRET not in result.output
    assert path.exists()


@pytest.mark.parametrize("element", ["focal", "distortion"])
def test_an_element_with_a_third_of_a_million_attributes_is_judged_at_once(write_xml, element):
    # Each lxml attribute value is found by a search of the element's attributes:
    # reading them all would take time quadratic in their number (hours here).
    many = " ".join(f'x{i}="1"' for i in range(300_000))
    if element == "focal":
        text = lens_xml(FOLDING).replace("<mount>", f'<focal min="10" {many}/><mount>', 1)
    else:
        text = lens_xml(FOLDING.replace("/>", f" {many}/>"))
    path = write_xml(text)
    process = subprocess.run(
        [sys.executable, "-m", "lensaudit", "check", "--no-cache", "-f", "json", str(path)],
        capture_output=True,
        timeout=120,
    )
    assert process.returncode == 1, process.stderr
    found = json.loads(process.stdout)["findings"]
    refusal = [f for f in found if f["code"] == "liblensfun-refuses"]
    message = refusal[0]["message"]
    assert len(refusal) == 1 and "attribute x0=" in message and f"on <{element}>" in message
    assert [f["code"] for f in found if f["code"].startswith("fold")] == ["fold-in-image"]


def test_an_apostrophe_inside_a_word_opens_no_quoted_value():
    from lensaudit.check.result import QUOTED_LIMIT, clip

    text = "liblensfun (Lensfun master's) stops reading at line 6: bad attribute x0='1' on <focal>"
    assert clip(text) == text
    long = "9" * 500
    shortened = f"a (b's) c x='{'9' * QUOTED_LIMIT}\u2026' overflows"
    assert clip(f"a (b's) c x='{long}' overflows") == shortened
