"""The paper reproduced: its printed values, its Algorithm 1, and every difference explained."""

from __future__ import annotations

import importlib.util
import json
import math
import os
import subprocess
from pathlib import Path

import mpmath
import numpy as np
import pytest

from conftest import lens_xml
from lensaudit.report import audit, paper

ROOT = Path(__file__).resolve().parents[1]
BUNDLE = Path(
    os.environ.get(
        "LENSAUDIT_HISTORY_BUNDLE", ROOT.parent / "shared" / "data" / "lensfun-db-history.bundle"
    )
)


def load_script():
    spec = importlib.util.spec_from_file_location(
        "reproduce_paper", ROOT / "scripts" / "reproduce_paper.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


# The paper's printed numbers, copied here from the paper itself (Tables 1-2, Sec. 4.4).
PRINTED_TABLE1 = {
    "ptlens": (1141, 3055, "27.19", 4196),
    "poly3": (411, 461, "47.13", 872),
    "poly5": (2, 3, "40.00", 5),
    "Total": (1554, 3519, "30.63", 5073),
}
PRINTED_TABLE2 = {
    "ptlens": (27, 1114, "97.63", 1141),
    "poly3": (0, 411, "100.00", 411),
    "poly5": (0, 2, "100.00", 2),
    "Total": (27, 1527, "98.26", 1554),
}


def test_data_file_holds_the_printed_tables():
    values = paper.load_values()
    assert {
        r["model"]: (r["finite"], r["infinite"], r["percent_finite"], r["total"])
        for r in values["table1"]
    } == PRINTED_TABLE1
    assert {
        r["model"]: (r["positive"], r["negative"], r["percent_negative"], r["total"])
        for r in values["table2"]
    } == PRINTED_TABLE2
    assert values["rectilinear_finite"] == 1532 and values["rectilinear_below_one"] == 1
    named = {e["lens"]: e["r_normalized"] for e in values["named_entries"]}
    assert named == {"Tokina 11-16": 0.858, "Sigma 14mm f/1.8 DG HSM": 1.478}


def test_printed_tables_are_consistent_with_themselves():
    for finite, infinite, percent, total in PRINTED_TABLE1.values():
        assert finite + infinite == total and f"{100 * finite / total:.2f}" == percent
    for positive, negative, percent, total in PRINTED_TABLE2.values():
        assert positive + negative == total and f"{100 * negative / total:.2f}" == percent


def smallest_positive_root(a, b, c):
    """By mpmath at 50 digits: the smallest positive real root of 1 + a w + b w^2 + c w^3."""
    mpmath.mp.dps = 50
    coefficients = [c, b, a, 1]
    while coefficients and coefficients[0] == 0:
        coefficients = coefficients[1:]
    if len(coefficients) < 2:
        return math.inf
    roots = mpmath.polyroots([mpmath.mpf(x) for x in coefficients], maxsteps=200, extraprec=200)
    positive = [
        float(mpmath.re(r)) for r in roots if abs(mpmath.im(r)) < 1e-30 and mpmath.re(r) > 0
    ]
    return min(positive, default=math.inf)


def test_algorithm1_finds_the_smallest_positive_root():
    rng = np.random.default_rng(3)
    a, b, c = rng.uniform(-3, 3, (3, 300))
    c[:40] = 0  # quadratic
    b[:20] = 0  # linear
    found = paper.algorithm1(a, b, c)
    for i in range(a.size):
        expected = smallest_positive_root(a[i], b[i], c[i])
        if math.isinf(expected):
            assert math.isinf(found[i]), i
        else:
            assert found[i] == pytest.approx(expected, rel=1e-9), i


def test_algorithm1_reads_nan_as_no_root():
    assert math.isinf(paper.algorithm1(math.nan, 0.5, math.nan))
    assert math.isinf(paper.algorithm1(-1.0, math.nan, 0.0))


def test_omitted_coefficients_are_found_in_the_xml(write_xml):
    path = write_xml(
        lens_xml(
            '<distortion model="ptlens" focal="10" b="-0.02"/>',
            '<distortion model="ptlens" focal="20" a="0" b="0" c="0.01"/>',
            '<distortion model="poly5" focal="30" k1="0.1"/>',
            '<distortion model="poly5" focal="40" k1="x"/>',  # not audited: left out
        )
    )
    audits = audit(path.parent)
    omitted = paper.omitted_coefficients(audits.distortion, audits.files)
    assert omitted == {0: ("a", "c"), 2: ("k2",)}


def paper_values_for(counts, rectilinear_finite, below_one):
    """Printed-value file contents with the given Table 1/2 counts per model."""
    table1, table2 = [], []
    for model, (finite, infinite, positive, negative) in counts.items():
        total = finite + infinite
        table1.append(
            dict(
                model=model,
                finite=finite,
                infinite=infinite,
                total=total,
                percent_finite=f"{100 * finite / total:.2f}" if total else "",
            )
        )
        table2.append(
            dict(
                model=model,
                positive=positive,
                negative=negative,
                total=finite,
                percent_negative=f"{100 * negative / finite:.2f}" if finite else "",
            )
        )
    return dict(
        table1=table1,
        table2=table2,
        rectilinear_finite=rectilinear_finite,
        rectilinear_below_one=below_one,
        named_entries=[],
    )


@pytest.fixture
def omitting_db(write_xml):
    # ptlens b=-0.02 alone: D'(r) = 1.02 - 0.06 r^2, finite r_max = sqrt(17), negative tail.
    # poly3 k1=0.01: no fold. poly3 k1=-0.3: folds, negative tail.
    path = write_xml(
        lens_xml(
            '<distortion model="ptlens" focal="10" b="-0.02"/>',
            '<distortion model="poly3" focal="20" k1="0.01"/>',
            '<distortion model="poly3" focal="30" k1="-0.3"/>',
        )
    )
    return audit(path.parent)


def compare(audits, values):
    """The comparison as the report makes it."""
    omitted = paper.omitted_coefficients(audits.distortion, audits.files)
    return paper.compare(audits.distortion, values, omitted)


def test_a_difference_from_omitted_coefficients_is_explained(omitting_db):
    # As a pipeline reading omitted coefficients as NaN would count: the ptlens is infinite.
    values = paper_values_for(
        {
            "ptlens": (0, 1, 0, 0),
            "poly3": (1, 1, 0, 1),
            "poly5": (0, 0, 0, 0),
            "Total": (1, 2, 0, 1),
        },
        1,
        1,
    )
    comparison = compare(omitting_db, values)
    ptlens = [line for line in comparison.differences if line.startswith("Table 1, ptlens")]
    assert len(ptlens) == 1
    assert "1 of them omit a coefficient" in ptlens[0] and "test.xml:10" in ptlens[0]
    assert any(
        "reproduces the paper's Tables 1 and 2 exactly" in line for line in comparison.agreements
    )
    assert not any(line.startswith("Table 1, poly3") for line in comparison.differences)


def test_a_different_database_is_named_as_the_cause(omitting_db):
    values = paper.load_values()
    comparison = compare(omitting_db, values)
    assert comparison.differences[0].startswith("Database version")
    assert all(
        "not explained" not in line
        for line in comparison.differences[1:]
        if line.startswith("Table")
    )


def test_units_difference_lists_the_entries_that_fold_in_correct_units(omitting_db):
    values = paper_values_for(
        {
            "ptlens": (1, 0, 0, 1),
            "poly3": (1, 1, 0, 1),
            "poly5": (0, 0, 0, 0),
            "Total": (2, 1, 0, 2),
        },
        2,
        0,
    )
    comparison = compare(omitting_db, values)
    units = [line for line in comparison.differences if line.startswith("Units")]
    # poly3 k1=-0.3 at 30 mm: D(r_max) = 1.04 < 1.80 (Hugin units), yet above the paper's
    # corner hypot(18, 12) / 30 = 0.72.
    assert len(units) == 1 and "test.xml:12" in units[0]


def test_text_and_markdown_show_both_values(omitting_db):
    comparison = compare(omitting_db, paper.load_values())
    text = "\n".join(paper.text_lines(comparison))
    assert "1141 | 1" in text and "Differences" in text
    assert "1141 \\| 1" in paper.markdown(comparison)


@pytest.fixture(scope="module")
def history(tmp_path_factory):
    if not BUNDLE.is_file():
        pytest.skip(
            f"the Lensfun history bundle is not at {BUNDLE} "
            f"(set LENSAUDIT_HISTORY_BUNDLE to its path)"
        )
    clone = tmp_path_factory.mktemp("history") / "lensfun-db.git"
    subprocess.run(["git", "clone", "--bare", "--quiet", str(BUNDLE), str(clone)], check=True)
    return clone


def test_the_papers_snapshot_reproduces_the_paper_up_to_explained_differences(
    history, capsys, tmp_path
):
    script = load_script()
    assert (
        script.main(["--git", str(history), "--date", "2021-05-30", "-o", str(tmp_path / "out")])
        == 0
    )
    output = capsys.readouterr().out
    assert "Lensfun git revision 38f6d1f24384" in output
    assert "poly3     411 | 411    461 | 461" in output
    differences = output.split("Differences")[1].split("Agreements")[0]
    assert "Table 1, ptlens: finite 1144 here, 1141 in the paper: 3 of them omit" in differences
    assert "compact-nikon.xml:662, compact-nikon.xml:663, mil-olympus.xml:223" in differences
    assert "Rectilinear with finite r_max: 1535 here, 1532 in the paper" in differences
    assert "not explained by database version" not in differences
    assert "Tokina AF AT-X Pro DX, at a focal length of 11mm (slr-tokina.xml:19): 0.858" in output
    assert "reproduces the paper's Tables 1 and 2 exactly" in output
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["summary"]["entries"] == 5073
    assert (tmp_path / "out" / "paper_comparison.md").is_file()


def test_script_reports_a_bad_repository_with_exit_2(tmp_path, capsys):
    script = load_script()
    assert script.main(["--git", str(tmp_path / "nothing")]) == 2
    assert "reproduce_paper: error:" in capsys.readouterr().err
