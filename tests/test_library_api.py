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


def test_a_path_given_as_bytes_is_read_as_the_same_path_as_text(folding_db):
    import os

    as_text = lensaudit.audit(str(folding_db))
    as_bytes = lensaudit.audit(os.fsencode(folding_db))
    assert list(as_bytes.r_max) == list(as_text.r_max) and len(as_text) > 0
    assert list(lensaudit.audit([os.fsencode(folding_db)]).file) == list(as_text.file)


def test_paths_that_name_nothing_are_refused_in_one_line(folding_db):
    import pytest

    from lensaudit.check import check
    from lensaudit.read import LoadError

    # An empty list is not "no argument": the default database would hide a
    # filter that left nothing.
    for call in (lensaudit.audit, lensaudit.run, check):
        with pytest.raises(LoadError, match="no path given"):
            call([])
        with pytest.raises(LoadError, match="NUL character"):
            call(str(folding_db) + "\0x")
        with pytest.raises(TypeError, match="paths must be a path or a sequence of paths"):
            call(5)
