"""The summary (Tables 1 and 2, statuses, folds) adds up the tallies of the files
however they were made: in workers while parsing, from the cache, by numpy's
array code, or over entries given in memory. The reference is counted here
from the audit's rows, one entry at a time."""

from __future__ import annotations

import math
from collections import Counter
from pathlib import Path

import pytest

from conftest import lens_xml
from lensaudit.pipeline import audit_entries, run
from lensaudit.read import read
from lensaudit.summary import MODELS, TOTAL

#: Only numpy's array code audits this one (a tangency, 1 - 3 w + 2.25 w^2).
TANGENT = '<distortion model="poly5" focal="10" k1="-1" k2="0.45"/>'
FOLDING = '<distortion model="poly3" focal="10" k1="-0.2"/>'


def counted(records: list[dict]) -> dict:
    """What the summary must say of these rows, counted plainly."""
    rows = {name: [0, 0, 0, 0] for name in (*MODELS, TOTAL)}
    not_audited: Counter[str] = Counter()
    paper = 0
    for record in records:
        model = record["model"]
        if record["status"] != "ok":
            not_audited[model or "(none)"] += 1
            continue
        finite = math.isfinite(record["r_max"])
        for key in (model, TOTAL) if model in MODELS else (TOTAL,):
            row = rows[key]
            row[0 if finite else 1] += 1
            if finite and record["tail"] == "positive":
                row[2] += 1
            if finite and record["tail"] == "negative":
                row[3] += 1
        if finite and record["type"] == "rectilinear" and record["r_normalized_paper"] < 1:
            paper += 1
    folding = [i for i, record in enumerate(records) if record["folds_in_image"]]
    folding.sort(key=lambda i: records[i]["r_normalized"])
    statuses = Counter(record["status"] for record in records)
    return {
        "entries": len(records),
        "audited": statuses["ok"],
        "statuses": dict(statuses),
        "rows": {name: tuple(counts) for name, counts in rows.items()},
        "folding": folding,
        "folding_rectilinear": sum(records[i]["type"] == "rectilinear" for i in folding),
        "paper": paper,
        "not_audited": dict(not_audited),
    }


def said(audit) -> dict:
    """What the audit's summary says, in the form of :func:`counted`."""
    summary = audit.summary
    return {
        "entries": summary.entries,
        "audited": summary.audited,
        "statuses": summary.statuses,
        "rows": {r.model: (r.finite, r.infinite, r.positive, r.negative) for r in summary.rows},
        "folding": summary.folding,
        "folding_rectilinear": summary.folding_rectilinear,
        "paper": summary.folding_paper_units_rectilinear,
        "not_audited": summary.models_not_audited,
    }


@pytest.fixture
def mixed_db(tmp_path: Path, bundled_db: Path) -> Path:
    """The bundled database, with a file that only the array code audits, one
    whose entry folds, and a broken one."""
    database = tmp_path / "db"
    database.mkdir()
    for source in bundled_db.glob("*.xml"):
        (database / source.name).write_bytes(source.read_bytes())
    (database / "tangent.xml").write_text(lens_xml(TANGENT, FOLDING))
    (database / "folds.xml").write_text(lens_xml(FOLDING, FOLDING))
    (database / "broken.xml").write_text(lens_xml(FOLDING)[:-30])
    return database


def test_the_summary_counts_what_the_rows_say_without_the_cache(mixed_db):
    audit = run(mixed_db, cache=False)
    assert said(audit) == counted(audit.records())


def test_the_summary_from_the_cache_counts_what_the_rows_say(mixed_db):
    cold = run(mixed_db, cache=False)
    run(mixed_db, cache=True)
    warm = run(mixed_db, cache=True)
    assert said(warm) == counted(cold.records())


def test_the_summary_of_entries_in_memory_counts_what_the_rows_say(mixed_db):
    audit = audit_entries(read(mixed_db).entries())
    assert audit.summary.files == 0
    assert said(audit) == counted(audit.records())


def test_the_folds_found_are_listed_by_r_normalized(mixed_db):
    audit = run(mixed_db, cache=False)
    folding = audit.summary.folding
    r_normalized = audit.column("r_normalized")
    assert len(folding) >= 4
    assert [r_normalized[i] for i in folding] == sorted(r_normalized[i] for i in folding)
