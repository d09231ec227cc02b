"""`lensaudit check`: the vignetting and TCA findings, alone and against a baseline.

Expected verdicts come from closed forms evaluated with exact fractions or
mpmath: for C(r) = 1 + k1 r^2 (k2 = k3 = 0) the minimum over the image is
C(1) = 1 + k1 at the frame corner, and for r_d = r (v + b r^2) the fold is
where r_d' = v + 3 b r^2 vanishes, r = sqrt(-v / (3 b)).
"""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import mpmath
import pytest
from click.testing import CliRunner

from lensaudit.check import check
from lensaudit.cli import main

CORNER_3_2 = mpmath.sqrt(mpmath.mpf(1.5) ** 2 + 1)  # TCA image corner, Hugin units


def vignetting(k1: str, k2: str = "0", focal: str = "10", aperture: str = "2.8") -> str:
    return (
        f'<vignetting model="pa" focal="{focal}" aperture="{aperture}" distance="10" '
        f'k1="{k1}" k2="{k2}" k3="0"/>'
    )


def tca(br: str, focal: str = "10") -> str:
    return f'<tca model="poly3" focal="{focal}" vr="1" vb="1" br="{br}" bb="0"/>'


def lens(model: str, *elements: str, maker: str = "Test") -> str:
    body = "".join(f"      {e}\n" for e in elements)
    return (
        f"  <lens>\n    <maker>{maker}</maker>\n    <model>{model}</model>\n"
        f"    <mount>Mount</mount>\n    <cropfactor>1.5</cropfactor>\n"
        f"    <calibration>\n{body}    </calibration>\n  </lens>\n"
    )


def xml(*lenses: str) -> str:
    return '<lensdatabase version="2">\n' + "".join(lenses) + "</lensdatabase>\n"


def database(tmp_path: Path, name: str, text: str) -> Path:
    directory = tmp_path / name
    directory.mkdir()
    (directory / "a.xml").write_text(text, encoding="utf-8")
    return directory


def found(result) -> list[tuple[str, str, int]]:
    return [(f.severity, f.code, f.line) for f in result.findings]


def new(result) -> list[tuple[str, int]]:
    return [(f.code, f.line) for f in result.findings if not f.known]


ZERO = vignetting("-1.25")  # C(1) = -1/4
LOW = vignetting("-0.95")  # C(1) = 1/20
TURNING = vignetting("-0.5", "0.4")  # C'(w) = -1/2 + 4/5 w: turns at w = 5/8, C >= 27/32
FINE = vignetting("-0.31")  # C(1) = 69/100, decreasing (not the script's -0.3 start)
TCA_FOLD = tca("-0.2")  # folds at r = sqrt(5/3) < 1.803
LINE = 8  # line of the first element of the first lens()


def test_reference_values_put_the_examples_where_the_tests_need_them():
    assert 1 + Fraction("-1.25") <= 0
    assert 0 < 1 + Fraction("-0.95") < Fraction(1, 10)
    w_turn = Fraction(1, 2) / Fraction(8, 10)
    assert 0 < w_turn < 1
    c_min = 1 - Fraction(1, 2) * w_turn + Fraction(4, 10) * w_turn**2
    assert c_min > Fraction(1, 10)
    assert 1 + Fraction("-0.3") > Fraction(1, 10)
    assert mpmath.sqrt(mpmath.mpf(1) / (3 * mpmath.mpf("0.2"))) < CORNER_3_2


def test_vignetting_that_reaches_zero_inside_the_image_is_an_error_that_fails(tmp_path):
    result = check(database(tmp_path, "db", xml(lens("Lens", ZERO))))
    assert found(result) == [("error", "vignetting-zero-in-image", LINE)]
    assert result.failed


def test_vignetting_zero_finding_names_where_c_crosses_zero(tmp_path):
    result = check(database(tmp_path, "db", xml(lens("Lens", ZERO))))
    r_zero = mpmath.sqrt(mpmath.mpf(1) / mpmath.mpf("1.25"))
    assert f"crossing zero at r = {float(r_zero):.4g}" in result.findings[0].message


def test_vignetting_below_a_tenth_inside_the_image_is_a_warning_that_passes(tmp_path):
    result = check(database(tmp_path, "db", xml(lens("Lens", LOW))))
    assert found(result) == [("warning", "vignetting-low-in-image", LINE)]
    assert not result.failed
    gain = 1 / (1 + Fraction("-0.95"))
    assert f"by {float(gain):.3g}" in result.findings[0].message


def test_vignetting_brighter_than_the_centre_is_a_warning_that_passes(tmp_path):
    # C(1) = 1 + 1/10 - 1/25 = 53/50 > 21/20; decreasing nowhere inside (C' > 0).
    result = check(database(tmp_path, "db", xml(lens("Lens", vignetting("0.1", "-0.04")))))
    assert found(result) == [("warning", "vignetting-brightens", LINE)]
    assert not result.failed
    assert "1.06 times as bright as its centre" in result.findings[0].message
    # Just below the threshold at the corner: C(1) = 1 + 9/100 - 1/25 = 105/100, not above.
    result = check(database(tmp_path, "db2", xml(lens("Lens", vignetting("0.09", "-0.04")))))
    assert found(result) == []


def test_vignetting_that_turns_inside_the_image_is_a_notice_only_when_verbose(tmp_path):
    path = database(tmp_path, "db", xml(lens("Lens", TURNING)))
    assert found(check(path)) == []
    result = check(path, verbose=True)
    assert found(result) == [("notice", "vignetting-not-monotone", LINE)]
    assert not result.failed


def test_monotone_vignetting_above_a_tenth_gives_no_finding(tmp_path):
    assert found(check(database(tmp_path, "db", xml(lens("Lens", FINE))), verbose=True)) == []


def test_tca_that_folds_inside_the_image_is_an_error_that_fails(tmp_path):
    result = check(database(tmp_path, "db", xml(lens("Lens", TCA_FOLD))))
    assert found(result) == [("error", "tca-fold-in-image", LINE)]
    assert result.failed
    r_fold = mpmath.sqrt(mpmath.mpf(1) / (3 * mpmath.mpf("0.2")))
    assert f"peaks at r = {float(r_fold):.4g}" in result.findings[0].message


def test_tca_that_does_not_fold_gives_no_finding(tmp_path):
    assert found(check(database(tmp_path, "db", xml(lens("Lens", tca("0.01")))))) == []


@pytest.mark.parametrize(
    ("element", "code"),
    [
        ('<vignetting model="pa" focal="10" aperture="2.8" k1="-0.1"/>', "missing-attribute"),
        (
            '<vignetting model="pa" focal="10" aperture="2.8" distance="1" k1="x"/>',
            "bad-value",
        ),
        ('<vignetting model="acm" focal="10" aperture="2.8" distance="1"/>', "unknown-model"),
        ('<tca model="poly3" focal="10" vr="nan"/>', "bad-value"),
        ('<tca model="poly3" vr="1"/>', "missing-attribute"),
        ('<tca model="acm" focal="10"/>', "unknown-model"),
    ],
)
def test_calibration_element_that_cannot_be_audited_is_an_error_naming_it(tmp_path, element, code):
    result = check(database(tmp_path, "db", xml(lens("Lens", element))))
    assert found(result) == [("error", code, LINE)]
    tag = element.split()[0][1:]
    assert f"<{tag}>" in result.findings[0].message


def test_calibration_element_outside_a_lens_is_a_no_lens_error_where_liblensfun_stops(tmp_path):
    text = '<lensdatabase version="2">\n  ' + ZERO + "\n</lensdatabase>\n"
    result = check(database(tmp_path, "db", text))
    assert found(result) == [("error", "no-lens", 2), ("error", "liblensfun-refuses", 2)]


def test_broken_file_gives_its_xml_error_and_no_calibration_finding(tmp_path):
    text = xml(lens("Lens", ZERO, TCA_FOLD)).replace("</lensdatabase>", "<lens>")
    result = check(database(tmp_path, "db", text))
    assert [f.code for f in result.findings] == ["xml-error"]


def test_known_vignetting_error_stays_known_when_lines_move(tmp_path):
    before = database(tmp_path, "before", xml(lens("Lens", ZERO)))
    after = database(tmp_path, "after", xml(lens("Other", FINE), lens("Lens", ZERO)))
    result = check(after, baseline=before)
    assert found(result) == [("error", "vignetting-zero-in-image", LINE + 9)]
    assert new(result) == [] and not result.failed


def test_known_tca_fold_stays_known_when_its_lens_is_renamed(tmp_path):
    before = database(tmp_path, "before", xml(lens("Lens", TCA_FOLD)))
    after = database(tmp_path, "after", xml(lens("Lens Mark II", TCA_FOLD)))
    result = check(after, baseline=before)
    assert new(result) == [] and not result.failed


def test_edited_vignetting_coefficient_makes_its_error_new(tmp_path):
    before = database(tmp_path, "before", xml(lens("Lens", ZERO)))
    after = database(tmp_path, "after", xml(lens("Lens", vignetting("-1.5"))))
    result = check(after, baseline=before)
    assert new(result) == [("vignetting-zero-in-image", LINE)]
    assert result.failed


def test_vignetting_error_added_beside_a_known_one_is_new(tmp_path):
    before = database(tmp_path, "before", xml(lens("Lens", ZERO)))
    after = database(tmp_path, "after", xml(lens("Lens", ZERO, TCA_FOLD)))
    result = check(after, baseline=before)
    assert new(result) == [("tca-fold-in-image", LINE + 1)]


def test_copy_of_a_known_vignetting_error_under_another_lens_is_new(tmp_path):
    before = database(tmp_path, "before", xml(lens("Lens", ZERO)))
    after = database(tmp_path, "after", xml(lens("Lens", ZERO), lens("Copy", ZERO)))
    result = check(after, baseline=before)
    assert new(result) == [("vignetting-zero-in-image", LINE + 9)]


def test_known_tca_fold_does_not_make_a_vignetting_error_known(tmp_path):
    # A TCA fold in the baseline does not make a vignetting error known.
    before = database(tmp_path, "before", xml(lens("Lens", TCA_FOLD)))
    after = database(tmp_path, "after", xml(lens("Lens", ZERO)))
    result = check(after, baseline=before)
    assert new(result) == [("vignetting-zero-in-image", LINE)]
    assert result.resolved == 1


def test_cli_check_exits_1_on_a_vignetting_error_and_prints_its_line(tmp_path, monkeypatch):
    monkeypatch.setenv("LENSAUDIT_CACHE_DIR", str(tmp_path / "cache"))
    path = database(tmp_path, "db", xml(lens("Lens", ZERO)))
    outcome = CliRunner().invoke(main, ["check", str(path)])
    assert outcome.exit_code == 1
    assert f"a.xml:{LINE}: error [vignetting-zero-in-image]" in outcome.output


def test_bundled_vignetting_errors_are_the_entries_whose_c_reaches_zero(bundled_db):
    """An entry of the bundled database is a vignetting error exactly when C,
    sampled on 4,097 radii over the frame (numpy, independent of the audit's
    exact solver), reaches 0. Circular fisheyes, judged on their image
    circle, are left out of both counts."""
    import xml.etree.ElementTree as StdlibET

    import numpy as np

    w = np.linspace(0.0, 1.0, 4097)  # w = r^2, the frame corner at 1
    expected = 0
    for file in bundled_db.glob("*.xml"):
        for lens_element in StdlibET.parse(file).getroot().iter("lens"):
            if "circular" in (lens_element.findtext("model") or "").lower():
                continue
            for element in lens_element.iter("vignetting"):
                k1, k2, k3 = (float(element.get(f"k{i}", "0")) for i in (1, 2, 3))
                expected += bool((1 + w * (k1 + w * (k2 + w * k3))).min() <= 0)
    result = check(bundled_db)
    got = sum(
        f.code == "vignetting-zero-in-image" and "circular" not in f.entry_key[1].lower()
        for f in result.findings
    )
    assert expected > 0 and got == expected
