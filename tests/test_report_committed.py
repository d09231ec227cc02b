"""reports/ holds the report of lensfunpy's bundled database; it must match a fresh audit.

Regenerate it with the command in reports/README.md when this fails because
the audit changed on purpose.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from lensaudit.pipeline import run
from lensaudit.read.paths import lensfunpy_version
from lensaudit.report import tables
from lensaudit.report.provenance import content_hash

REPORTS = Path(__file__).resolve().parents[1] / "reports"


@pytest.fixture(scope="module")
def committed():
    summary = json.loads((REPORTS / "summary.json").read_text())
    version = summary["provenance"]["lensfunpy_version"]
    if version != lensfunpy_version():
        pytest.skip(
            f"reports/ was made with lensfunpy {version}, "
            f"{lensfunpy_version() or 'none'} is installed"
        )
    return summary


@pytest.fixture(scope="module")
def audit(bundled_db, committed):
    return run(bundled_db)


def test_committed_report_is_of_the_installed_database(committed, audit):
    files = [f.path for f in audit.files]
    assert committed["provenance"]["content_hash"] == content_hash(files)


@pytest.mark.parametrize(
    "name, rows", [("table1", tables.table1_rows), ("table2", tables.table2_rows)]
)
def test_committed_tables_match_a_fresh_audit(audit, name, rows):
    committed = tables.read_csv((REPORTS / f"{name}.csv").read_text())
    header = tables.TABLE1_HEADER if name == "table1" else tables.TABLE2_HEADER
    fresh = tables.read_csv(tables.to_csv(header, rows(audit.summary)))
    assert committed == fresh


def test_committed_folding_entries_match_a_fresh_audit(audit, committed):
    with (REPORTS / "folding.csv").open(newline="") as stream:
        listed = [(row["file"], int(row["line"])) for row in csv.DictReader(stream)]
    fresh = [(audit.entries[i].file, audit.entries[i].line) for i in audit.summary.folding]
    assert listed == fresh
    assert committed["folding"] == [f"{file}:{line}" for file, line in fresh]


def test_committed_report_has_every_file():
    expected = {
        "entries.csv",
        "summary.json",
        "table1.md",
        "table1.csv",
        "table2.md",
        "table2.csv",
        "folding.csv",
        "fig5_r_normalized.csv",
        "fig5_r_normalized.png",
        "fig5_r_normalized.svg",
        "report.html",
        "paper_comparison.md",
        "README.md",
    }
    assert expected <= {p.name for p in REPORTS.iterdir()}
