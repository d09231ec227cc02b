"""A file's encoding as liblensfun reads it: GMarkup reads every file as UTF-8.

liblensfun (``lfDatabase::Load`` in ``libs/lensfun/database.cpp``) hands the
file's bytes to ``g_markup_parse_context_parse`` with no encoding of its own;
GMarkup reads UTF-8 only, takes an XML declaration for a processing
instruction (liblensfun's parser has no ``passthrough`` callback, so it is
dropped unread) and refuses bytes that are not UTF-8. So:

- a file declared ISO-8859-1 (or windows-1252, US-ASCII) whose bytes are
  UTF-8 loads, with the names the bytes spell in UTF-8 ("Görlitz"): the
  reader gives the same names to every command, and ``check`` says that the
  declaration disagrees (``encoding-mismatch``, a warning on its line);
- a file whose bytes are not UTF-8 is refused at the first such byte, whether
  it declares ISO-8859-1 or nothing: ``check`` says so at liblensfun's line;
- a UTF-16 or UTF-32 file, with a byte-order mark or without, is refused on
  its first line, and ``check`` names its encoding.

Every verdict is liblensfun master's own, loaded through ctypes.
"""

from __future__ import annotations

import csv
import json
import os
from pathlib import Path

import pytest
from click.testing import CliRunner

import liblensfun_load
import liblensfun_master
from lensaudit import read
from lensaudit.check import LIBLENSFUN_REFUSES, check
from lensaudit.check.rules.encoding_mismatch import ENCODING_MISMATCH as MISMATCH
from lensaudit.cli import main

#: A lens that folds (so that check names it), whose maker is not ASCII.
LENS = """<lens>
  <maker>Meyer-Optik G\u00f6rlitz</maker>
  <model>Trioplan 100mm f/2.8</model>
  <mount>M42</mount>
  <cropfactor>1</cropfactor>
  <calibration>
    <distortion model="poly3" focal="100" k1="-0.9"/>
  </calibration>
</lens>
"""
PLAIN = LENS.replace("Meyer-Optik G\u00f6rlitz", "Zeiss").replace("Trioplan", "Tessar")
BODY = f'<lensdatabase version="2">\n{PLAIN}{LENS}{PLAIN}</lensdatabase>\n'
MAKER = "Meyer-Optik G\u00f6rlitz"
#: What a reader that follows a declaration of ISO-8859-1 makes of the UTF-8 bytes.
MISREAD = MAKER.encode("utf-8").decode("latin-1")


def declared(encoding: str, body: str = BODY) -> str:
    return f'<?xml version="1.0" encoding="{encoding}"?>\n{body}'


def write(tmp_path: Path, data: bytes, name: str = "test.xml") -> Path:
    directory = tmp_path / "db"
    directory.mkdir(exist_ok=True)
    path = directory / name
    path.write_bytes(data)
    return path


def makers_of_liblensfun(data: bytes) -> list[str]:
    return [lens["maker"] for lens in liblensfun_master.lenses(data)]


def reader_verdict(data: bytes) -> tuple[int | None, int | None]:
    refusal = read.read_bytes(data, "test.xml", refusals=True).refusal
    return (None, None) if refusal is None else (refusal[0], refusal[2])


def liblensfun_verdict(data: bytes) -> tuple[int | None, int | None]:
    result, lenses = liblensfun_load.load_and_lenses(data)
    return (None, None) if result.ok else (liblensfun_load.stop_line(result), lenses)


# -- UTF-8 bytes that declare another encoding ---------------------------------------

DISAGREEING = ["ISO-8859-1", "windows-1252", "US-ASCII", "KOI8-R", "x-no-such-encoding"]


@pytest.mark.parametrize("encoding", DISAGREEING)
def test_utf8_bytes_declared_otherwise_give_the_names_liblensfun_gives(encoding):
    data = declared(encoding).encode("utf-8")
    assert liblensfun_verdict(data) == (None, None)  # liblensfun loads the file
    expected = makers_of_liblensfun(data)
    assert expected[1] == MAKER
    assert [lens.maker for lens in read.read_bytes(data, "test.xml").lenses] == expected


def names_of_reader(lens) -> tuple:
    """A reader's lens as :func:`names_of_liblensfun` gives liblensfun's: its
    maker, model, and their translations by language."""
    translated: dict[str, dict[str, str]] = {"maker": {}, "model": {}}
    for tag, attributes, text in lens.content:
        language = dict(attributes).get("lang")
        if tag in translated and language is not None:
            translated[tag][language] = text
    return lens.maker, lens.model, translated["maker"], translated["model"]


def names_of_liblensfun(lens: dict) -> tuple:
    return lens["maker"], lens["model"], lens["maker_translations"], lens["model_translations"]


@pytest.mark.parametrize("name", ["slr-ussr.xml", "misc.xml", "compact-nikon.xml"])
def test_real_files_declared_iso_8859_1_give_the_names_liblensfun_gives(tmp_path, name):
    lensfunpy = pytest.importorskip("lensfunpy")
    original = (Path(os.path.dirname(lensfunpy.__file__)) / "db_files" / name).read_bytes()
    data = b'<?xml version="1.0" encoding="ISO-8859-1"?>\n' + original
    expected = [names_of_liblensfun(lens) for lens in liblensfun_master.lenses(data)]
    found = [names_of_reader(lens) for lens in read.read_bytes(data, name).lenses]
    assert found == expected
    assert not repr(found).isascii()  # names that a reader of ISO-8859-1 reads otherwise
    findings = check([write(tmp_path, data, name)]).findings
    assert [f.line for f in findings if f.code == MISMATCH.code] == [1]


@pytest.mark.parametrize("encoding", DISAGREEING)
def test_check_says_the_declaration_disagrees_with_the_bytes(tmp_path, encoding):
    path = write(tmp_path, declared(encoding).encode("utf-8"))
    result = check([path])
    [finding] = [f for f in result.findings if f.code == MISMATCH.code]
    assert (finding.severity, finding.file, finding.line) == ("warning", str(path), 1)
    assert f"encoding='{encoding}'" in finding.message and "UTF-8" in finding.message
    if encoding in ("ISO-8859-1", "windows-1252"):
        line = declared(encoding).splitlines().index(f"  <maker>{MAKER}</maker>") + 1
        assert f"'G\u00f6rlitz' at line {line}" in finding.message
        assert f"as '{MISREAD.split()[-1]}'" in finding.message
    # The entry that folds is named as liblensfun names its lens.
    folds = [f for f in result.findings if f.code == "fold-in-image"]
    assert len(folds) == 3 and MAKER in folds[1].message
    assert not any(MISREAD in f.message for f in result.findings)


@pytest.mark.parametrize(
    "data",
    [
        declared("ISO-8859-1", BODY.replace("\u00f6", "o")).encode("utf-8"),  # ASCII only
        declared("UTF-8").encode("utf-8"),
        declared("utf8").encode("utf-8"),
        BODY.encode("utf-8"),
    ],
    ids=["ascii-declared-latin-1", "utf-8-declared", "utf8-declared", "undeclared"],
)
def test_no_finding_where_the_declaration_reads_as_liblensfun_reads(tmp_path, data):
    assert not [f for f in check([write(tmp_path, data)]).findings if f.code == MISMATCH.code]


def test_scan_check_and_report_name_the_lens_as_liblensfun_does(tmp_path):
    data = declared("ISO-8859-1").encode("utf-8")
    path = write(tmp_path, data)
    runner = CliRunner()
    scanned = runner.invoke(main, ["scan", str(path.parent), "-f", "json", "--no-cache"])
    assert scanned.exit_code == 0, scanned.output
    assert [e["maker"] for e in json.loads(scanned.output)["entries"]] == [
        "Zeiss",
        MAKER,
        "Zeiss",
    ]
    checked = runner.invoke(main, ["check", str(path.parent), "-f", "json", "--no-cache"])
    findings = json.loads(checked.output)["findings"]
    assert any(MAKER in f["message"] for f in findings if f["code"] == "fold-in-image")
    assert [f["line"] for f in findings if f["code"] == MISMATCH.code] == [1]
    out = tmp_path / "report"
    reported = runner.invoke(main, ["report", str(path.parent), "-o", str(out), "--no-cache"])
    assert reported.exit_code == 0, reported.output
    with open(out / "entries.csv", encoding="utf-8", newline="") as rows:
        assert [row["maker"] for row in csv.DictReader(rows)] == ["Zeiss", MAKER, "Zeiss"]
    assert MISREAD not in (out / "report.html").read_text(encoding="utf-8")


def test_the_cache_keeps_the_names_and_the_finding_read_as_utf8(tmp_path, monkeypatch):
    data = declared("ISO-8859-1").encode("utf-8")
    path = write(tmp_path, data)
    cache = tmp_path / "cache"
    runner = CliRunner()
    arguments = ["--cache-dir", str(cache), "-f", "json", str(path.parent)]
    cold = runner.invoke(main, ["scan", *arguments])
    assert cold.exit_code == 0, cold.output

    def no_parsing(*args, **kwargs):
        raise AssertionError("parsed again: the cache was not used")

    # check judges what liblensfun refuses, which scan does not: it reads once more,
    # and keeps that in the cache; a second check takes everything from it.
    runner.invoke(main, ["check", *arguments])
    monkeypatch.setattr(read.xml, "parse", no_parsing)
    warm = runner.invoke(main, ["scan", *arguments])
    entries = json.loads(warm.output)["entries"]
    assert entries == json.loads(cold.output)["entries"]
    assert [e["maker"] for e in entries] == ["Zeiss", MAKER, "Zeiss"]
    checked = runner.invoke(main, ["check", *arguments])
    findings = json.loads(checked.output)["findings"]
    assert [f["code"] for f in findings if f["code"] == MISMATCH.code] == [MISMATCH.code]
    assert any(MAKER in f["message"] for f in findings)


# -- bytes that are not UTF-8 --------------------------------------------------------


@pytest.mark.parametrize("declaration", ["ISO-8859-1", "windows-1252", None])
def test_bytes_not_utf8_are_refused_where_liblensfun_refuses_them(tmp_path, declaration):
    body = BODY if declaration is None else declared(declaration)
    data = body.encode("latin-1")
    expected = liblensfun_verdict(data)
    assert expected[0] is not None  # GMarkup refuses them, whatever the declaration says
    assert expected == (data[: data.index(b"\xf6")].count(b"\n") + 1, 1)
    assert reader_verdict(data) == expected
    findings = check([write(tmp_path, data)]).findings
    said = [f for f in findings if f.code in (LIBLENSFUN_REFUSES, "xml-error")]
    assert [(f.code, f.line) for f in said] == [
        (LIBLENSFUN_REFUSES if declaration else "xml-error", expected[0])
    ]
    assert "0xF6" in said[0].message and "is not UTF-8" in said[0].message
    if declaration is not None:
        # Read as declared, to audit what it holds; liblensfun reads none of it.
        assert declaration in said[0].message and "reads every file as UTF-8" in said[0].message
        assert read.read_bytes(data, "test.xml").lenses[1].maker == MAKER
        assert "1 lens before" in said[0].message and "2 lenses from there on" in said[0].message
    assert not [f for f in findings if f.code == MISMATCH.code]


# -- UTF-16 and UTF-32 ------------------------------------------------------------


WIDE = [
    ("utf-16", "UTF-16 (byte-order mark FF FE)"),
    ("utf-16-le", "UTF-16LE (no byte-order mark)"),
    ("utf-16-be", "UTF-16BE (no byte-order mark)"),
    ("utf-32", "UTF-32 (byte-order mark FF FE 00 00)"),
    ("utf-32-be", "UTF-32BE (no byte-order mark)"),
]


@pytest.mark.parametrize("declaration", [True, False], ids=["declared", "undeclared"])
@pytest.mark.parametrize(("codec", "named"), WIDE, ids=[codec for codec, _ in WIDE])
def test_a_utf16_or_utf32_file_is_refused_and_its_encoding_named(
    tmp_path, codec, named, declaration
):
    name = codec.upper()[:6]
    text = declared(name) if declaration else BODY
    data = text.encode(codec)
    expected = liblensfun_verdict(data)
    assert expected == (1, 0)  # refused on its first line, no lens held
    assert reader_verdict(data) == expected
    result = check([write(tmp_path, data)])
    [refusal] = [f for f in result.findings if f.code == LIBLENSFUN_REFUSES]
    assert refusal.line == 1 and f"the file is {named}" in refusal.message
    assert "3 lenses from there on are lost" in refusal.message
    assert not [f for f in result.findings if f.code in (MISMATCH.code, "xml-error")]
    # What the file holds is read as its encoding spells it, and audited.
    assert [lens.maker for lens in read.read_bytes(data, "test.xml").lenses][1] == MAKER
    assert [f.code for f in result.findings].count("fold-in-image") == 3
