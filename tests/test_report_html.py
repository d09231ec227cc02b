"""report.html: one self-contained page, with provenance, tables, folding entries, escaping."""

from __future__ import annotations

import base64
import csv
import hashlib
import json
import re
import time

import pytest
from lxml import html as lxml_html

from lensaudit import __version__
from lensaudit.read.paths import lensfunpy_version
from lensaudit.report import audit, write_report

HOSTILE_LENS = "<script>document.body.setAttribute('data-pwned','1')</script>"
HOSTILE_MAKER = 'A&B "quoted" <b>bold</b>'
TIMESTAMP = "1577948414"

HOSTILE_XML = f"""<lensdatabase version="2">
    <lens>
        <maker>{HOSTILE_MAKER.replace("&", "&amp;").replace("<", "&lt;")}</maker>
        <model>{HOSTILE_LENS.replace("<", "&lt;")}</model>
        <mount>Test Mount</mount>
        <cropfactor>1</cropfactor>
        <calibration>
            <distortion model="poly3" focal="10" k1="-0.3"/>
            <distortion model="poly3" focal="20" k1="0.01"/>
            <distortion model="ptlens" focal="30" a="0" b="-0.1" c="0"/>
            <distortion model="acm" focal="40" k1="0.01"/>
        </calibration>
    </lens>
</lensdatabase>
"""


def line_of(text: str, needle: str) -> int:
    """1-based line of the first occurrence of ``needle``, counted independently."""
    return text[: text.index(needle)].count("\n") + 1


@pytest.fixture(scope="module")
def hostile_report(tmp_path_factory):
    root = tmp_path_factory.mktemp("hostile")
    database = root / "db"
    database.mkdir()
    (database / "hostile.xml").write_text(HOSTILE_XML, encoding="utf-8")
    (database / "timestamp.txt").write_text(TIMESTAMP + "\n", encoding="ascii")
    out = root / "report"
    write_report(audit(database), out)
    return database, out, (out / "report.html").read_text(encoding="utf-8")


@pytest.fixture(scope="module")
def page(hostile_report):
    return lxml_html.fromstring(hostile_report[2])


def test_page_loads_nothing_from_anywhere_else(hostile_report):
    text = hostile_report[2]
    assert "http://" not in text and "https://" not in text
    assert not re.search(r"<(link|img|iframe|object|embed|base)\b", text, re.IGNORECASE)
    assert not re.search(r"\b(src|href)\s*=\s*[\"']?\s*(//|[a-z]+:)", text, re.IGNORECASE)
    assert "@import" not in text and "url(" not in text.replace("url(#", "")
    scripts = re.findall(r"<script\b[^>]*>", text, re.IGNORECASE)
    assert len(scripts) == 2 and not any("src" in tag for tag in scripts)


def test_content_security_policy_allows_exactly_the_page_script(page):
    policy = page.xpath('//meta[@http-equiv="Content-Security-Policy"]/@content')[0]
    assert "default-src 'none'" in policy
    scripts = [s for s in page.xpath("//script") if not s.get("type")]
    assert len(scripts) == 1
    digest = base64.b64encode(hashlib.sha256(scripts[0].text.encode()).digest()).decode()
    assert f"script-src 'sha256-{digest}'" in policy


def test_tables_1_and_2_match_the_csv_files(hostile_report, page):
    out = hostile_report[1]
    for name in ("table1", "table2"):
        rows = list(csv.reader((out / f"{name}.csv").open()))
        cells = [
            [cell.text_content() for cell in row.xpath("./th|./td")]
            for row in page.xpath(f'//table[@id="{name}"]//tr')
        ]
        expected = [rows[0]] + [
            [v + "%" if i == 3 and v else v for i, v in enumerate(row)] for row in rows[1:]
        ]
        assert cells == expected


def test_table1_counts_the_hand_made_entries(page):
    total = page.xpath('//table[@id="table1"]//tr[td[1]="Total"]/td/text()')
    # poly3 k1=-0.3: r_max = sqrt(1.3 / 0.9); k1=0.01: no fold; ptlens b=-0.1:
    # r_max = sqrt(1.1 / 0.3). Both peak below the corner 1.80: D(r_max) 1.04 and 1.40.
    assert total == ["Total", "2", "1", "66.67%", "3"]


def test_provenance_names_the_database_and_its_content_hash(hostile_report, page):
    database = hostile_report[0]
    facts = dict(
        zip(
            page.xpath('//dl[@id="provenance"]/dt/text()'),
            page.xpath('//dl[@id="provenance"]/dd/text()'),
            strict=True,
        )
    )
    digest = hashlib.sha256(b"hostile.xml\0" + (database / "hostile.xml").read_bytes())
    assert facts["Content hash (SHA-256)"] == digest.hexdigest()
    assert facts["Files read"] == "1"
    assert facts["Location"] == str(database)
    assert facts["Lensfun timestamp.txt"].startswith(
        TIMESTAMP + time.strftime(" (%Y-%m-%d", time.gmtime(int(TIMESTAMP)))
    )
    assert facts["lensaudit"] == __version__
    assert facts["lensfunpy"] == lensfunpy_version()
    assert re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\dZ", facts["Generated"])


def test_folding_entries_are_shown_with_file_line_and_a_plot(page):
    cards = page.xpath('//article[@class="fold"]')
    folding_lines = [line_of(HOSTILE_XML, needle) for needle in ('k1="-0.3"', 'b="-0.1"')]
    expected = {f"hostile.xml:{line}" for line in folding_lines}
    assert {card.get("data-where") for card in cards} == expected
    for card in cards:
        assert card.xpath(".//svg/polyline")
        assert card.get("data-where") in card.text_content()


def test_every_entry_is_in_the_table_data_with_file_and_line(page):
    data = json.loads(page.xpath('//script[@id="entries-data"]')[0].text)
    where = [row[0] for row in data["rows"]]
    lines = [line_of(HOSTILE_XML, f'focal="{f}"') for f in (10, 20, 30, 40)]
    assert where == [f"hostile.xml:{n}" for n in lines]
    status = [row[[c[0] for c in data["columns"]].index("status")] for row in data["rows"]]
    assert status == ["ok", "ok", "ok", "unknown_model"]


def test_table_data_are_the_csv_values_to_six_digits(hostile_report, page):
    data = json.loads(page.xpath('//script[@id="entries-data"]')[0].text)
    names = [c[0] for c in data["columns"]]
    with (hostile_report[1] / "entries.csv").open(newline="") as stream:
        records = list(csv.DictReader(stream))
    assert len(records) == len(data["rows"])
    for row, record in zip(data["rows"], records, strict=True):
        shown = dict(zip(names, row, strict=True))
        for name in ("focal", "crop_factor", "aspect_ratio", "r_max", "d_max", "r_normalized"):
            text = record[name]
            if text in ("", "inf", "-inf"):
                assert shown[name] == (None if text == "" else text), name
            else:
                assert shown[name] == pytest.approx(float(text), rel=5e-6), name
        for name in ("maker", "lens", "type", "model", "tail", "status"):
            assert shown[name] == record[name], name
        folds = {"true": True, "false": False, "": None}[record["folds_in_image"]]
        assert shown["folds_in_image"] is folds
    # Each model's own coefficients as the XML writes them, and no others.
    coefficients = [row[names.index("coefficients")] for row in data["rows"]]
    assert coefficients == ["k1=-0.3", "k1=0.01", "a=0 b=-0.1 c=0", ""]


def test_names_from_the_xml_are_escaped(hostile_report, page):
    text = hostile_report[2]
    assert HOSTILE_LENS not in text and "<b>bold</b>" not in text
    assert "&lt;script&gt;document.body.setAttribute" in text
    # What a parser reads back is exactly the name in the XML, as text.
    titles = page.xpath('//article[@class="fold"]/h3')
    assert titles[0].text_content() == f"{HOSTILE_LENS} at 10 mm"
    assert page.xpath('//article[@class="fold"]//dd')[1].text_content() == HOSTILE_MAKER
    data_block = page.xpath('//script[@id="entries-data"]')[0].text
    assert "<" not in data_block and ">" not in data_block and "&" not in data_block
    assert json.loads(data_block)["rows"][0][2] == HOSTILE_LENS


def test_no_script_element_comes_from_the_data(page):
    assert len(page.xpath("//script")) == 2
    assert not page.xpath("//b")
