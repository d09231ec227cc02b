"""`lensaudit scan`: outputs, columns, exit codes."""

from __future__ import annotations

import csv
import io
import json
import math

import pytest
from click.testing import CliRunner

from conftest import lens_xml
from lensaudit.cli import main
from lensaudit.pipeline import COLUMNS

EXPECTED_HEADER = (
    "file,line,maker,lens,type,crop_factor,aspect_ratio,model,focal,real_focal,"
    "a,b,c,k1,k2,r_max,d_max,tail,r_corner,r_normalized,r_corner_paper,"
    "r_normalized_paper,folds_in_image,status,message"
)


@pytest.fixture
def runner():
    return CliRunner()


@pytest.fixture
def small_db(write_xml):
    path = write_xml(
        lens_xml(
            '<distortion model="poly3" focal="10" k1="-0.3"/>',
            '<distortion model="poly3" focal="20" k1="0.01"/>',
            '<distortion model="acm" focal="30" k1="0.01"/>',
            '<distortion model="ptlens" focal="40" a="x"/>',
        )
    )
    return path.parent


def test_csv_header_is_the_documented_columns(runner, small_db):
    result = runner.invoke(main, ["scan", str(small_db), "--format", "csv"])
    assert result.exit_code == 0, result.output
    assert result.output.splitlines()[0] == EXPECTED_HEADER
    assert ",".join(COLUMNS) == EXPECTED_HEADER


def test_every_entry_appears_in_csv_with_status(runner, small_db):
    result = runner.invoke(main, ["scan", str(small_db), "-f", "csv"])
    rows = list(csv.DictReader(io.StringIO(result.output)))
    assert [(r["focal"], r["status"]) for r in rows] == [
        ("10.0", "ok"),
        ("20.0", "ok"),
        ("30.0", "unknown_model"),
        ("40.0", "bad_value"),
    ]
    assert rows[0]["folds_in_image"] == "true" and rows[0]["tail"] == "negative"
    assert (
        rows[1]["r_max"] == "inf" and rows[1]["tail"] == "" and rows[1]["folds_in_image"] == "false"
    )
    assert rows[2]["r_max"] == "" and rows[2]["folds_in_image"] == ""
    assert rows[0]["file"] == "test.xml" and int(rows[0]["line"]) == 10


def test_csv_floats_round_trip(runner, small_db):
    result = runner.invoke(main, ["scan", str(small_db), "-f", "csv"])
    row = next(csv.DictReader(io.StringIO(result.output)))
    k1 = -0.3
    expected = math.sqrt((1 - k1) / (-3 * k1))
    assert float(row["r_max"]) == pytest.approx(expected, rel=1e-14)


def test_json_has_entries_and_summary(runner, small_db):
    result = runner.invoke(main, ["scan", str(small_db), "-f", "json"])
    document = json.loads(result.output)
    assert [list(e) for e in document["entries"]] == [list(COLUMNS)] * 4
    assert document["entries"][1]["r_max"] == "inf"
    total = document["summary"]["table1"][-1]
    assert (total["model"], total["finite"], total["infinite"], total["total"]) == (
        "Total",
        1,
        1,
        2,
    )
    assert document["summary"]["statuses"] == {"ok": 2, "bad_value": 1, "unknown_model": 1}


def test_table_names_the_database_and_lists_folding_entries(runner, small_db):
    result = runner.invoke(main, ["scan", str(small_db)])
    assert result.exit_code == 0
    assert str(small_db) in result.output.splitlines()[0]
    assert "Table 1" in result.output and "Table 2" in result.output
    assert "test.xml:10" in result.output
    assert "Not audited: 2 entries" in result.output


def test_output_file_option_writes_the_file(runner, small_db, tmp_path):
    target = tmp_path / "out.csv"
    result = runner.invoke(main, ["scan", str(small_db), "-f", "csv", "-o", str(target)])
    assert result.exit_code == 0 and result.output == ""
    assert target.read_text().splitlines()[0] == EXPECTED_HEADER


def test_missing_path_exits_2_with_one_line(runner, tmp_path):
    result = runner.invoke(main, ["scan", str(tmp_path / "missing")])
    assert result.exit_code == 2
    assert result.output.strip().count("\n") == 0 and "no such file" in result.output
    assert "Traceback" not in result.output


def test_unknown_format_is_a_usage_error(runner, small_db):
    result = runner.invoke(main, ["scan", str(small_db), "-f", "xls"])
    assert result.exit_code == 2


def test_only_unreadable_files_exit_2(runner, write_xml):
    path = write_xml("<lensdatabase>", "broken.xml")
    result = runner.invoke(main, ["scan", str(path)])
    assert result.exit_code == 2 and "broken.xml" in result.output


def test_default_is_the_bundled_database(runner, bundled_db):
    result = runner.invoke(main, ["scan"])
    assert result.exit_code == 0
    assert "bundled with lensfunpy" in result.output.splitlines()[0]
    assert str(bundled_db) in result.output.splitlines()[0]
