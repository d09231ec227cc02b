"""`import lensaudit`: the DataFrame API."""

from __future__ import annotations

import lensaudit
from lensaudit.pipeline import COLUMNS


def test_audit_returns_a_dataframe_with_the_columns(bundled_db):
    frame = lensaudit.audit(bundled_db)
    assert list(frame.columns) == list(COLUMNS)
    assert len(frame) == sum(
        1
        for f in bundled_db.glob("*.xml")
        for line in f.read_text().splitlines()
        if "<distortion" in line and "<!--" not in line
    )
    assert frame["folds_in_image"].dtype.name == "boolean"


def test_audit_without_path_uses_the_bundled_database(bundled_db):
    assert len(lensaudit.audit()) == len(lensaudit.audit(bundled_db))


def test_the_paper_tokina_example_has_the_papers_mixed_unit_value(bundled_db):
    # Paper, Figure 6b: Tokina AF AT-X Pro DX at 11 mm, r_normalized = 0.858 (its units).
    frame = lensaudit.audit(bundled_db)
    tokina = frame[
        frame.lens.str.startswith("Tokina 11-16mm") & (frame.focal == 11) & (frame.crop_factor == 1)
    ]
    assert len(tokina) == 1
    assert round(float(tokina.r_normalized_paper.iloc[0]), 3) == 0.858
    assert bool(tokina.folds_in_image.iloc[0])
