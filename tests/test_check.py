"""`lensaudit.check`: the rules, each on a small database, and on the real one.

Reference values of r_normalized come from closed forms evaluated with
mpmath (poly3) or from numpy's companion-matrix roots of D'(r) (the bundled
database), never from lensaudit's own solver.
"""

from __future__ import annotations

import math
import shutil
import xml.etree.ElementTree as StdlibET
from pathlib import Path

import mpmath
import numpy as np
import pytest

import liblensfun_load
from conftest import lens_xml
from lensaudit import check as checking
from lensaudit.check import CheckError, check

CORNER_3_2 = mpmath.sqrt(mpmath.mpf(1.5) ** 2 + 1)  # image corner, aspect 3:2, Hugin units


def poly3_r_normalized(k1: float) -> mpmath.mpf:
    """D(r_max) / corner for poly3 D(r) = r (1 - k1 + k1 r^2), k1 < 0, aspect 3:2.

    D'(r) = 1 - k1 + 3 k1 r^2 vanishes at r_max^2 = (1 - k1) / (-3 k1), where
    D = r_max (1 - k1) (2/3).
    """
    with mpmath.workdps(40):
        k1 = mpmath.mpf(k1)
        r_max = mpmath.sqrt((1 - k1) / (-3 * k1))
        return r_max * (1 - k1) * 2 / 3 / CORNER_3_2


def poly3_db(write_xml, *k1_and_focal: tuple[str, str]) -> Path:
    lines = [f'<distortion model="poly3" focal="{focal}" k1="{k1}"/>' for k1, focal in k1_and_focal]
    return write_xml(lens_xml(*lines)).parent


def codes(result) -> list[tuple[str, str, int]]:
    return [(f.severity, f.code, f.line) for f in result.findings]


def test_reference_values_put_the_poly3_examples_where_the_tests_need_them():
    assert poly3_r_normalized(-0.3) < 1
    assert 1 < poly3_r_normalized(-0.05) < 1.1
    assert 1.1 < poly3_r_normalized(-0.03) < 1.3


def test_fold_inside_the_image_is_an_error_that_fails(write_xml):
    result = check(poly3_db(write_xml, ("-0.3", "10")))
    assert codes(result) == [("error", "fold-in-image", 10)]
    assert result.failed
    assert f"{float(poly3_r_normalized(-0.3)):.3f} times the image corner" in (
        result.findings[0].message
    )


def test_fold_within_the_margin_is_a_warning_that_does_not_fail(write_xml):
    result = check(poly3_db(write_xml, ("-0.05", "10")))
    assert codes(result) == [("warning", "fold-near-image", 10)]
    assert not result.failed
    assert f"{float(poly3_r_normalized(-0.05)):.3f} times" in result.findings[0].message


def test_margin_sets_how_far_outside_the_image_a_fold_is_warned_about(write_xml):
    db = poly3_db(write_xml, ("-0.03", "10"))
    assert check(db).findings == []
    assert codes(check(db, margin=1.3)) == [("warning", "fold-near-image", 10)]


def test_margin_below_one_is_refused(write_xml):
    with pytest.raises(CheckError, match="margin"):
        check(poly3_db(write_xml, ("-0.03", "10")), margin=0.9)


def test_fold_far_outside_the_image_is_a_notice_only_when_verbose(write_xml):
    db = poly3_db(write_xml, ("-0.03", "10"))
    assert check(db).findings == []
    result = check(db, verbose=True)
    assert codes(result) == [("notice", "fold-outside-image", 10)]
    assert not result.failed


def test_monotonic_model_has_no_finding_even_when_verbose(write_xml):
    assert check(poly3_db(write_xml, ("0.01", "10")), verbose=True).findings == []


def test_model_decreasing_from_the_centre_is_a_fold_in_the_image(write_xml):
    # poly3 with k1 > 1: D'(0) = 1 - k1 < 0.
    result = check(poly3_db(write_xml, ("1.5", "10")))
    assert codes(result) == [("error", "fold-in-image", 10)]
    assert "decreases from the image centre" in result.findings[0].message


def test_finding_names_lens_model_focal_and_crop_factor(write_xml):
    finding = check(poly3_db(write_xml, ("-0.3", "10"))).findings[0]
    assert finding.message.startswith("Test 10mm (poly3, 10 mm, crop 1): ")
    assert finding.entry_key == ("Test", "Test 10mm", 1.0, "poly3", 10.0)
    assert finding.file.endswith("test.xml") and Path(finding.file).exists()


@pytest.mark.parametrize(
    ("distortion", "code", "fragment"),
    [
        ('<distortion focal="10" k1="0.1"/>', "missing-attribute", "missing model="),
        ('<distortion model="poly3" k1="0.1"/>', "missing-attribute", "missing focal="),
        ('<distortion model="poly3" focal="10" k1="nan"/>', "bad-value", "'nan' is not a finite"),
        ('<distortion model="poly3" focal="10" k1="-inf"/>', "bad-value", "'-inf' is not a finite"),
        ('<distortion model="poly3" focal="10" k1="0,1"/>', "bad-value", "'0,1' is not a number"),
        ('<distortion model="ptlens" focal="10" a="1e999"/>', "bad-value", "overflows"),
        ('<distortion model="poly3" focal="0" k1="0.1"/>', "bad-value", "focal=0 is not positive"),
        ('<distortion model="poly3" focal="-8" k1="0.1"/>', "bad-value", "focal=-8 is not posit"),
        ('<distortion model="acm" focal="10" k1="0.1"/>', "unknown-model", "'acm' is not one of"),
    ],
)
def test_entry_that_cannot_be_audited_is_an_error(write_xml, distortion, code, fragment):
    result = check(write_xml(lens_xml(distortion)))
    assert codes(result) == [("error", code, 10)]
    assert fragment in result.findings[0].message


@pytest.mark.parametrize("crop", ["0", "-1.5"])
def test_crop_factor_not_above_zero_is_an_error(write_xml, crop):
    result = check(
        write_xml(lens_xml('<distortion model="poly3" focal="10" k1="0.1"/>', cropfactor=crop))
    )
    # liblensfun refuses the lens at its end tag, and the file from there on.
    assert codes(result) == [("error", "bad-value", 10), ("error", "liblensfun-refuses", 13)]
    assert "crop factor" in result.findings[0].message
    assert "1 lens from there on is lost" in result.findings[1].message


def test_distortion_outside_a_lens_is_an_error(write_xml):
    xml = '<lensdatabase>\n<distortion model="poly3" focal="10" k1="0.1"/>\n</lensdatabase>\n'
    # liblensfun: "Inappropriate context", at the entry (held to liblensfun elsewhere).
    assert codes(check(write_xml(xml))) == [
        ("error", "no-lens", 2),
        ("error", "liblensfun-refuses", 2),
    ]


def test_second_entry_for_a_focal_in_one_calibration_is_an_error(write_xml):
    result = check(
        write_xml(
            lens_xml(
                '<distortion model="poly3" focal="10" k1="0.01"/>',
                '<distortion model="poly3" focal="12" k1="0.01"/>',
                '<distortion model="ptlens" focal="10.0" a="0.01"/>',
            )
        )
    )
    assert codes(result) == [("error", "duplicate-focal", 12)]
    assert "(the first is at line 10)" in result.findings[0].message


CALIBRATIONS = """\
<lensdatabase>
  <lens>
    <maker>Test</maker><model>Zoom</model><cropfactor>1.5</cropfactor>
    <calibration>
      <distortion model="poly3" focal="10" k1="0.01"/>
    </calibration>
    <calibration cropfactor="1">
      <distortion model="poly3" focal="10" k1="0.02"/>
    </calibration>
    <calibration>
      <distortion model="poly3" focal="10" k1="0.03"/>
    </calibration>
  </lens>
</lensdatabase>
"""


def test_a_calibration_is_one_lens_with_one_crop_factor_and_aspect_ratio(write_xml):
    # The second <calibration> has its own crop factor: another calibration.
    # The third has the lens's: the same calibration as the first. (The lens
    # has no <mount>, so liblensfun refuses it at its end tag, line 14.)
    assert codes(check(write_xml(CALIBRATIONS))) == [
        ("error", "duplicate-focal", 11),
        ("error", "liblensfun-refuses", 14),
    ]


def lens(maker: str, model: str, crop: str, mount: str = "Mount A") -> str:
    return (
        f"  <lens>\n    <maker>{maker}</maker>\n    <model>{model}</model>\n"
        f"    <cropfactor>{crop}</cropfactor><mount>{mount}</mount>\n  </lens>\n"
    )


def database(*lenses: str) -> str:
    return "<lensdatabase>\n" + "".join(lenses) + "</lensdatabase>\n"


def test_lens_defined_twice_is_an_error_at_the_second_definition(write_xml):
    write_xml(database(lens("Test", "Lens A", "1.5")), "a.xml")
    db = write_xml(
        database(lens("Test", "Lens B", "1.5"), lens("Test", "Lens A", "1.50", "Mount B")), "b.xml"
    ).parent
    result = check(db)
    assert [(f.code, Path(f.file).name, f.line) for f in result.findings] == [
        ("duplicate-lens", "b.xml", 7)
    ]
    assert f"already defined at {db / 'a.xml'}:2" in result.findings[0].message
    assert result.findings[0].entry_key == ("Test", "Lens A", 1.5)


def test_lens_names_are_compared_ignoring_case_and_runs_of_spaces(write_xml):
    result = check(
        write_xml(database(lens("Test", "Lens  A", "1"), lens("TEST", " lens a ", "1", "Mount B")))
    )
    assert codes(result) == [("error", "duplicate-lens", 7)]


def test_same_lens_on_another_crop_factor_is_not_a_duplicate(write_xml):
    assert (
        check(
            write_xml(database(lens("Test", "Lens A", "1"), lens("Test", "Lens A", "1.5")))
        ).findings
        == []
    )


def test_broken_file_is_one_error_with_line_and_column_and_other_files_are_checked(write_xml):
    write_xml(lens_xml('<distortion model="poly3" focal="10" k1="-0.3"/>'), "a.xml")
    broken = lens_xml(
        '<distortion model="poly3" focal="10" k1="-0.3"',  # never closed
        '<distortion model="poly3" focal="12" k1="0.1"/>',
    )
    db = write_xml(broken, "b.xml").parent
    result = check(db)
    assert [(f.code, Path(f.file).name, f.line) for f in result.findings] == [
        ("fold-in-image", "a.xml", 10),
        ("xml-error", "b.xml", 11),
    ]
    xml_error = result.findings[1]
    # libxml2 stops at the "<" that cannot start an attribute name.
    column = broken.splitlines()[10].index("<distortion") + 1
    assert xml_error.column == column
    assert f"line 11, column {column}" in xml_error.message
    assert [(Path(f.file).name, f.entries, bool(f.error)) for f in result.files] == [
        ("a.xml", 1, False),
        ("b.xml", 2, True),
    ]


def test_well_formed_file_with_another_root_is_one_not_a_database_error(write_xml):
    xml = "<html>\n<body><distortion model='poly3' focal='10' k1='-0.3'/></body>\n</html>\n"
    result = check(write_xml(xml))
    assert codes(result) == [("error", "not-a-database", 1)]
    assert "root element is <html>" in result.findings[0].message
    assert result.files[0].entries == 1


def test_tca_after_the_root_element_is_an_xml_error(write_xml):
    # Not well-formed, whatever shortcut a parse may take past <tca> elements.
    xml = lens_xml('<distortion model="poly3" focal="10" k1="0.1"/>') + (
        '<tca model="linear" focal="10" kr="1" kb="1"/>\n'
    )
    result = check(write_xml(xml))
    assert codes(result) == [("error", "xml-error", 14)]
    assert result.files[0].entries == 1


def test_duplicate_attribute_in_tca_is_an_xml_error(write_xml):
    xml = lens_xml(
        '<distortion model="poly3" focal="10" k1="0.1"/>',
        '<tca model="linear" focal="10" kr="1" kr="1"/>',
    )
    assert codes(check(write_xml(xml))) == [("error", "xml-error", 11)]


def test_missing_path_and_directory_without_xml_cannot_be_checked(tmp_path):
    with pytest.raises(CheckError, match="no such file"):
        check(tmp_path / "nope")
    (tmp_path / "notes.txt").write_text("x")
    with pytest.raises(CheckError, match=r"no \*\.xml files"):
        check(tmp_path)


# -- baseline given as a directory ------------------------------------------------


@pytest.fixture
def two_databases(tmp_path):
    def make(before: list[str], after: list[str]) -> tuple[Path, Path]:
        for name, lines in (("before", before), ("after", after)):
            (tmp_path / name).mkdir(exist_ok=True)
            (tmp_path / name / "db.xml").write_text(lens_xml(*lines))
        return tmp_path / "before", tmp_path / "after"

    return make


FOLDING = '<distortion model="poly3" focal="10" k1="-0.3"/>'
FINE = '<distortion model="poly3" focal="20" k1="0.01"/>'


def test_finding_already_in_the_baseline_is_known_and_does_not_fail(two_databases):
    before, after = two_databases([FOLDING], [FINE, FOLDING])  # the folding entry moved
    result = check(after, baseline=before)
    assert [(f.code, f.line, f.known) for f in result.findings] == [("fold-in-image", 11, True)]
    assert not result.failed
    assert result.counts() == {"error": 0, "warning": 0, "notice": 0, "known": 1}


def test_new_entry_that_folds_fails_against_the_baseline(two_databases):
    before, after = two_databases([FINE], [FINE, FOLDING])
    result = check(after, baseline=before)
    assert [(f.code, f.line, f.known) for f in result.findings] == [("fold-in-image", 11, False)]
    assert result.failed


def test_changed_entry_that_still_folds_fails_against_the_baseline(two_databases):
    before, after = two_databases([FOLDING], [FOLDING.replace("-0.3", "-0.31")])
    result = check(after, baseline=before)
    assert [(f.code, f.known) for f in result.findings] == [("fold-in-image", False)]
    assert result.resolved == 1


def test_fixed_entry_counts_as_resolved(two_databases):
    before, after = two_databases([FOLDING], [FOLDING.replace("-0.3", "0.01")])
    result = check(after, baseline=before)
    assert result.findings == [] and result.resolved == 1 and not result.failed


def test_adding_a_third_entry_for_a_known_duplicate_focal_fails(two_databases):
    twice = [FINE, FINE.replace("0.01", "0.02")]
    before, after = two_databases(twice, twice + [FINE.replace("0.01", "0.03")])
    result = check(after, baseline=before)
    assert [(f.code, f.known) for f in result.findings] == [
        ("duplicate-focal", True),
        ("duplicate-focal", False),
    ]


def test_findings_of_a_file_that_no_longer_parses_are_not_counted_resolved(two_databases):
    before, after = two_databases([FOLDING], [FOLDING.replace("/>", ">")])
    result = check(after, baseline=before)
    assert [(f.code, f.known) for f in result.findings] == [("xml-error", False)]
    assert result.resolved == 0


def test_baseline_directory_without_xml_cannot_be_checked(two_databases, tmp_path):
    _, after = two_databases([FINE], [FINE])
    (tmp_path / "empty").mkdir()
    with pytest.raises(CheckError, match="no \\*.xml"):
        check(after, baseline=tmp_path / "empty")


def test_a_lensfun_checkout_given_as_baseline_directory_means_its_data_db(tmp_path):
    # A worktree of the database's repository at the base of a pull request.
    (tmp_path / "checkout" / "data" / "db").mkdir(parents=True)
    (tmp_path / "checkout" / "data" / "db" / "db.xml").write_text(lens_xml(FOLDING))
    (tmp_path / "after").mkdir()
    (tmp_path / "after" / "db.xml").write_text(lens_xml(FINE, FOLDING))
    result = check(tmp_path / "after", baseline=tmp_path / "checkout")
    assert [(f.code, f.known) for f in result.findings] == [("fold-in-image", True)]
    assert not result.failed


# -- the real database -------------------------------------------------------------


def _first_fold(derivative: np.ndarray) -> float:
    """Smallest positive r where D'(r) (coefficients, highest first) goes from + to -."""
    if np.polyval(derivative, 0.0) <= 0:
        return 0.0
    best = math.inf
    for root in np.roots(derivative):
        r = root.real
        if abs(root.imag) <= 1e-9 * max(1.0, abs(r)) and r > 0:
            if np.polyval(derivative, r * (1 + 1e-7)) < 0 < np.polyval(derivative, r * (1 - 1e-7)):
                best = min(best, r)
    return best


def reference_r_normalized(
    model: str, attributes: dict, aspect: float, circular: bool = False
) -> float:
    """D(r_max) / image radius from D(r) written out as a polynomial in r.

    The image radius is the frame's corner hypot(aspect, 1), or for a
    circular fisheye its image circle, inscribed in the short side (1).
    """
    value = {k: float(attributes.get(k, 0)) for k in ("a", "b", "c", "k1", "k2")}
    if model == "ptlens":
        a, b, c = value["a"], value["b"], value["c"]
        distortion = np.array([a, b, c, 1 - a - b - c, 0.0])
    elif model == "poly3":
        k1 = value["k1"]
        distortion = np.array([k1, 0.0, 1 - k1, 0.0])
    else:
        distortion = np.array([value["k2"], 0.0, value["k1"], 0.0, 1.0, 0.0])
    r_max = _first_fold(np.polyder(distortion))
    if math.isinf(r_max):
        return math.inf
    radius = 1.0 if circular else math.hypot(max(aspect, 1 / aspect), 1)
    return np.polyval(distortion, r_max) / radius


def _aspect(text: str | None) -> float:
    if text is None:
        return 1.5
    numerator, _, denominator = text.partition(":")
    return float(numerator) / float(denominator) if denominator else float(text)


def test_folds_in_the_bundled_database_are_those_an_independent_computation_finds(bundled_db):
    expected_errors, expected_warnings = set(), set()
    for file in sorted(bundled_db.glob("*.xml")):
        for lens_element in StdlibET.parse(file).getroot().iter("lens"):
            aspect = _aspect(lens_element.findtext("aspect-ratio"))
            # A non-rectilinear lens whose name says circular draws an image circle.
            name = next(m.text for m in lens_element.iter("model") if "lang" not in m.attrib)
            lens_type = lens_element.findtext("type") or "rectilinear"
            circular = lens_type != "rectilinear" and "circular" in name.lower()
            for distortion in lens_element.iter("distortion"):
                attributes = distortion.attrib
                r_normalized = reference_r_normalized(
                    attributes["model"], attributes, aspect, circular
                )
                assert not 0.999999 < r_normalized < 1.000001  # no borderline case
                key = (file.name, attributes["model"], float(attributes["focal"]))
                if r_normalized < 1:
                    expected_errors.add(key)
                elif r_normalized < 1.1:
                    expected_warnings.add(key)
    result = check(bundled_db)
    entries = {
        (Path(f.file).name, f.entry_key[3], f.entry_key[4]): f
        for f in result.findings
        if f.code.startswith("fold")
    }
    assert {k for k, f in entries.items() if f.code == "fold-in-image"} == expected_errors
    assert {k for k, f in entries.items() if f.code == "fold-near-image"} == expected_warnings
    assert ("slr-tokina.xml", "ptlens", 11.0) in expected_errors  # the paper's example


def test_bundled_database_counts_every_entry_and_has_no_input_errors(bundled_db):
    result = check(bundled_db)
    expected = sum(
        1
        for file in bundled_db.glob("*.xml")
        for _ in StdlibET.parse(file).getroot().iter("distortion")
    )
    assert result.entries == expected
    # The one input error: the files liblensfun master refuses (for
    # <real-focal-length>, which the bundled database still has), each at the
    # line liblensfun itself names.
    refused = set()
    for file in sorted(bundled_db.glob("*.xml")):
        loaded, _ = liblensfun_load.load_and_lenses(file.read_bytes())
        if not loaded.ok:
            refused.add((file.name, liblensfun_load.stop_line(loaded)))
    assert len(refused) == 8
    assert {
        (Path(f.file).name, f.line) for f in result.findings if f.code == "liblensfun-refuses"
    } == refused
    assert {f.code for f in result.findings} <= {
        "liblensfun-refuses",
        "fold-in-image",
        "fold-near-image",
        "duplicate-focal",
        "vignetting-zero-in-image",
        "vignetting-low-in-image",
        "vignetting-brightens",
        "conflicting-calibration",
        "vignetting-starting-values",
        "undefined-mount",
        "inversion-fails-in-image",
        "focal-series-outlier",
        "fixed-lens-crop-factor",
    }


def test_check_of_a_database_against_a_copy_of_itself_finds_everything_known(bundled_db, tmp_path):
    copy = shutil.copytree(bundled_db, tmp_path / "copy")
    result = check(bundled_db, baseline=copy)
    assert result.findings and all(f.known for f in result.findings)
    assert not result.failed and result.resolved == 0


def test_analyse_gives_each_finding_an_identity_for_baseline_matching(write_xml):
    path = write_xml(lens_xml(FOLDING))
    files, findings = checking.analyse(checking.sources_from_paths([path]))
    assert [f.entries for f in files] == [1]
    [(finding, keys, names)] = findings
    assert finding.code == "fold-in-image"
    assert [key[:2] for key in keys] == [("error", "fold-in-image")] * len(keys)
    assert names == (path.name,)


def test_entry_whose_r_max_cannot_be_computed_is_an_error_and_the_others_are_checked(
    write_xml, monkeypatch
):
    from lensaudit import pipeline

    real = pipeline.metric_columns

    def failing(columns):
        if 12 in columns["focal"]:
            raise FloatingPointError("solver failed")
        return real(columns)

    monkeypatch.setattr(pipeline, "metric_columns", failing)
    path = write_xml(lens_xml(FOLDING, '<distortion model="poly3" focal="12" k1="0.01"/>'))
    result = check(path)
    assert codes(result) == [("error", "fold-in-image", 10), ("error", "r-max-not-computable", 11)]
    assert "FloatingPointError: solver failed" in result.findings[1].message


def test_a_duplicate_focal_written_above_the_old_entry_is_reported_on_the_new_one(two_databases):
    old = '<distortion model="poly3" focal="20" k1="0.01"/>'
    new = '<distortion model="poly3" focal="20" k1="0.02"/>'
    before, after = two_databases([old], [new, old])  # the change adds line 10, above line 11
    (finding,) = check(after, baseline=before).findings
    assert (finding.code, finding.line, finding.known) == ("duplicate-focal", 10, False)
    assert finding.related == ((finding.file, 11),)
    (alone,) = check(after).findings  # without a baseline: on the second, naming the first
    assert (alone.line, alone.related) == (11, ((alone.file, 10),))


def test_a_duplicate_lens_written_above_the_old_one_is_reported_on_the_new_one(tmp_path):
    def lens(k1: str) -> str:
        return (
            "  <lens><maker>M</maker><model>Twin</model><mount>X</mount>"
            f'<cropfactor>1</cropfactor><calibration><distortion model="poly3" focal="20" '
            f'k1="{k1}"/></calibration></lens>\n'
        )

    for name, lenses in (("before", [lens("0.01")]), ("after", [lens("0.02"), lens("0.01")])):
        (tmp_path / name).mkdir()
        (tmp_path / name / "db.xml").write_text(
            '<lensdatabase version="2">\n' + "".join(lenses) + "</lensdatabase>\n"
        )
    (finding,) = check(tmp_path / "after", baseline=tmp_path / "before").findings
    assert (finding.code, finding.line, finding.known) == ("duplicate-lens", 2, False)
    assert finding.related == ((finding.file, 3),) and "also defined at" in finding.message


def test_a_new_twin_above_an_old_one_with_tca_is_placed_the_same_from_the_cache(tmp_path):
    """A <tca> record leaves fields out (NaN in its row): the baseline's lens
    must still be recognised, however the two readings were made (cold, or
    from the cache)."""

    def lens(k1: str) -> str:
        return (
            "  <lens><maker>M</maker><model>Twin</model><mount>X</mount>"
            f'<cropfactor>1</cropfactor><calibration><distortion model="poly3" focal="20" '
            f'k1="{k1}"/><tca model="poly3" focal="20" vr="1.0002" vb="0.9998"/>'
            "</calibration></lens>\n"
        )

    for name, lenses in (("before", [lens("0.01")]), ("after", [lens("0.02"), lens("0.01")])):
        (tmp_path / name).mkdir()
        (tmp_path / name / "db.xml").write_text(
            '<lensdatabase version="2">\n' + "".join(lenses) + "</lensdatabase>\n"
        )
    for run in ("cold", "warm"):
        result = check(tmp_path / "after", baseline=tmp_path / "before", cache=True)
        assert [(f.code, f.line) for f in result.findings] == [("duplicate-lens", 2)], run


def test_a_baseline_file_the_change_left_alone_is_not_analysed_again(tmp_path, monkeypatch):
    from lensaudit.check import findings

    for name in ("before", "after"):
        (tmp_path / name).mkdir()
        (tmp_path / name / "same.xml").write_text(lens_xml(FOLDING))
    (tmp_path / "before" / "changed.xml").write_text(lens_xml(FINE))
    (tmp_path / "after" / "changed.xml").write_text(lens_xml(FINE.replace("0.01", "0.02")))
    analysed: list[str] = []
    original = findings._file_findings

    def counted(read, *rest):
        analysed.extend(Path(file.source.display).name for file in read)
        return original(read, *rest)

    monkeypatch.setattr(findings, "_file_findings", counted)
    assert check(tmp_path / "after", baseline=tmp_path / "before").findings  # no cache
    assert sorted(analysed) == ["changed.xml", "changed.xml", "same.xml"]
    analysed.clear()
    result = check(tmp_path / "after", baseline=tmp_path / "before", cache=True)
    assert sorted(analysed) == ["changed.xml", "changed.xml", "same.xml"]
    assert ("fold-in-image", True) in [(f.code, f.known) for f in result.findings]
    assert all(f.known for f in result.findings) and result.resolved == 0
