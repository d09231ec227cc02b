"""`lensaudit check`: metadata Lensfun's own CI does not check (issue 24, item 5):
undefined mounts, conflicting calibrations, vignetting at the calibration
script's starting values. All three are warnings: they never fail a check."""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

import pytest
from click.testing import CliRunner

from lensaudit.check import check
from lensaudit.check.rules.undefined_mount import is_fixed_lens_mount, mount_key
from lensaudit.cli import main

MOUNTS = "  <mount><name>Pentax K</name></mount>\n  <mount><name>Canon EF</name></mount>\n"
NEW_CODES = ("undefined-mount", "conflicting-calibration", "vignetting-starting-values")


def lens(model: str, *elements: str, mount: str = "Pentax K", crop: str = "1") -> str:
    body = "".join(f"      {e}\n" for e in elements)
    return (
        f"  <lens>\n    <maker>Test</maker>\n    <model>{model}</model>\n"
        f"    <mount>{mount}</mount>\n    <cropfactor>{crop}</cropfactor>\n"
        f"    <calibration>\n{body}    </calibration>\n  </lens>\n"
    )


def camera(model: str, mount: str) -> str:
    return (
        f"  <camera>\n    <maker>Test</maker>\n    <model>{model}</model>\n"
        f"    <mount>{mount}</mount>\n    <cropfactor>1.5</cropfactor>\n  </camera>\n"
    )


def database(directory: Path, *parts: str, mounts: str = MOUNTS) -> Path:
    directory.mkdir(parents=True, exist_ok=True)
    text = '<lensdatabase version="2">\n' + mounts + "".join(parts) + "</lensdatabase>\n"
    (directory / "db.xml").write_text(text)
    return directory


def found(result, code: str | None = None) -> list[tuple[str, str, int]]:
    return [
        (f.severity, f.code, f.line)
        for f in result.findings
        if f.code in NEW_CODES and (code is None or f.code == code)
    ]


def tca(focal: str, vr: str = "1.0002") -> str:
    return f'<tca model="poly3" focal="{focal}" vr="{vr}" vb="0.9998"/>'


def vignetting(k1: str, k2: str = "0", k3: str = "0", focal: str = "50", aperture="2.8") -> str:
    return (
        f'<vignetting model="pa" focal="{focal}" aperture="{aperture}" distance="10" '
        f'k1="{k1}" k2="{k2}" k3="{k3}"/>'
    )


# -- undefined-mount ------------------------------------------------------------


def test_a_lens_of_a_mount_defined_nowhere_is_a_warning_on_its_mount_line(tmp_path):
    result = check(database(tmp_path / "db", lens("50mm", mount="Pentak K")))
    assert found(result) == [("warning", "undefined-mount", 7)]  # the <mount> element's line
    assert '"Pentak K"' in result.findings[0].message
    assert 'did you mean "Pentax K"' in result.findings[0].message
    assert not result.failed


def test_a_camera_of_a_mount_defined_nowhere_is_a_warning(tmp_path):
    result = check(database(tmp_path / "db", camera("Body", "Fujifilm G")))
    assert found(result) == [("warning", "undefined-mount", 7)]
    assert result.findings[0].message.startswith("camera Test Body")


def test_mount_names_compare_as_liblensfun_compares_them(tmp_path):
    result = check(database(tmp_path / "db", lens("50mm", mount="  pentax   k "), lens("85mm")))
    assert found(result) == []
    assert mount_key(" Canon\tEF ") == mount_key("canon ef")


def test_a_fixed_lens_cameras_own_mount_is_never_reported(tmp_path):
    result = check(
        database(tmp_path / "db", camera("Compact", "canonG3"), lens("Std", mount="canonG3"))
    )
    assert found(result) == []
    assert is_fixed_lens_mount("canonG3") and not is_fixed_lens_mount("Canon EF")


def test_a_mount_defined_in_another_file_counts(tmp_path):
    directory = database(tmp_path / "db", lens("50mm", mount="Sony E"))
    (directory / "mounts.xml").write_text(
        '<lensdatabase version="2"><mount><name>Sony E</name></mount></lensdatabase>'
    )
    assert found(check(directory)) == []


def test_files_that_define_no_mount_are_a_fragment_and_give_no_mount_finding(tmp_path):
    result = check(database(tmp_path / "db", lens("50mm", mount="Pentak K"), mounts=""))
    assert found(result) == []


def test_a_known_undefined_mount_stays_known_when_lines_move(tmp_path):
    before = database(tmp_path / "before", lens("50mm", mount="Pentak K"))
    after = database(tmp_path / "after", lens("35mm"), lens("50mm", mount="Pentak K"))
    result = check(after, baseline=before)
    assert [f.known for f in result.findings if f.code == "undefined-mount"] == [True]


# -- conflicting-calibration -------------------------------------------------------


def test_two_different_tca_for_one_focal_length_are_a_warning_on_the_second(tmp_path):
    result = check(database(tmp_path / "db", lens("50mm", tca("50"), tca("50", vr="1.0003"))))
    assert found(result) == [("warning", "conflicting-calibration", 11)]
    assert result.findings[0].related[0][1] == 10
    assert not result.failed


def test_identical_or_other_focal_tca_are_no_conflict(tmp_path):
    result = check(database(tmp_path / "db", lens("50mm", tca("50"), tca("50"), tca("85"))))
    assert found(result) == []


def test_vignetting_conflicts_only_at_the_same_focal_aperture_and_distance(tmp_path):
    same = lens("50mm", vignetting("-0.5"), vignetting("-0.4"))
    other = lens("85mm", vignetting("-0.5"), vignetting("-0.4", aperture="4"))
    result = check(database(tmp_path / "db", same, other))
    assert found(result) == [("warning", "conflicting-calibration", 11)]


def test_a_different_crop_factor_is_another_calibration(tmp_path):
    two = (
        "  <lens>\n    <maker>Test</maker>\n    <model>50mm</model>\n"
        "    <mount>Pentax K</mount>\n    <cropfactor>1</cropfactor>\n"
        f"    <calibration>{tca('50')}</calibration>\n"
        f'    <calibration cropfactor="1.5">{tca("50", vr="1.0003")}</calibration>\n'
        "  </lens>\n"
    )
    assert found(check(database(tmp_path / "db", two))) == []


def test_two_distortions_of_one_calibration_stay_a_duplicate_focal_only(tmp_path):
    entries = ('<distortion model="ptlens" focal="50" a="0" b="0.01" c="0"/>',
               '<distortion model="ptlens" focal="50" a="0" b="0.02" c="0"/>')  # fmt: skip
    result = check(database(tmp_path / "db", lens("50mm", *entries)))
    assert found(result) == []
    assert [(f.severity, f.code) for f in result.findings] == [("error", "duplicate-focal")]


def test_twin_lenses_stay_a_duplicate_lens_only(tmp_path):
    result = check(
        database(tmp_path / "db", lens("50mm", tca("50")), lens("50MM", tca("50", "1.1")))
    )
    assert found(result) == []
    assert [f.code for f in result.findings] == ["duplicate-lens"]


def test_a_known_conflict_stays_known_and_a_new_one_is_new(tmp_path):
    before = database(tmp_path / "before", lens("50mm", tca("50"), tca("50", vr="1.0003")))
    after = database(
        tmp_path / "after",
        lens("50mm", tca("50"), tca("50", vr="1.0003"), tca("70"), tca("70", vr="1.0004")),
    )
    result = check(after, baseline=before)
    assert [(f.line, f.known) for f in result.findings] == [(11, True), (13, False)]
    assert not result.failed  # a warning


# -- vignetting-starting-values ----------------------------------------------------


def test_vignetting_at_the_scripts_starting_values_is_a_warning(tmp_path):
    written = vignetting("-0.3000000", "0.0000000", "-0.0000000")  # as calibrate.py writes it
    result = check(database(tmp_path / "db", lens("50mm", written)))
    assert found(result) == [("warning", "vignetting-starting-values", 10)]
    assert "calibrate.py" in result.findings[0].message
    assert not result.failed


@pytest.mark.parametrize(
    "k1, k2, k3", [("-0.3", "0.001", "0"), ("-0.31", "0", "0"), ("-0.3", "0", "1e-9")]
)
def test_vignetting_near_the_starting_values_is_not_reported(tmp_path, k1, k2, k3):
    result = check(database(tmp_path / "db", lens("50mm", vignetting(k1, k2, k3))))
    assert found(result, "vignetting-starting-values") == []


def test_a_known_starting_value_entry_is_known_from_the_baseline(tmp_path):
    before = database(tmp_path / "before", lens("50mm", vignetting("-0.3")))
    after = database(tmp_path / "after", lens("35mm"), lens("50mm", vignetting("-0.3")))
    result = check(after, baseline=before)
    assert [f.known for f in result.findings if f.code == "vignetting-starting-values"] == [True]


# -- through the command line ---------------------------------------------------------


def test_the_command_line_reports_all_three_and_exits_0(tmp_path):
    directory = database(
        tmp_path / "db",
        lens("50mm", tca("50"), tca("50", vr="1.0003"), vignetting("-0.3"), mount="Pentak K"),
    )
    result = CliRunner().invoke(main, ["check", str(directory), "--format", "json"])
    assert result.exit_code == 0, result.output
    codes = [f["code"] for f in json.loads(result.output)["findings"]]
    assert sorted(codes) == sorted(NEW_CODES)


def test_a_baseline_that_has_the_findings_makes_them_known_on_the_command_line(tmp_path):
    part = lens("50mm", tca("50"), tca("50", vr="1.0003"), vignetting("-0.3"), mount="Pentak K")
    before = database(tmp_path / "before", part)
    after = database(tmp_path / "after", lens("35mm"), part)
    result = CliRunner().invoke(main, ["check", str(after), "--baseline", str(before)])
    assert result.exit_code == 0, result.output
    assert result.output.rstrip().endswith(
        "0 errors, 0 warnings; 3 known from baseline " + str(before) + ", 0 resolved"
    )


# -- the counts quoted in issue 24 and docs/ci.md ------------------------------------


def counts(directory: Path) -> Counter:
    result = check(directory)
    tally: Counter = Counter(f.code for f in result.findings if f.code in NEW_CODES)
    conflicts = [f for f in result.findings if f.code == "conflicting-calibration"]
    tally["tca lenses"] = len({f.entry_key[:3] for f in conflicts if "<tca>" in f.message})
    tally["distortion lenses"] = len(
        {
            f.entry_key[:3]
            for f in result.findings
            if f.code == "duplicate-focal" and f.severity == "error"
        }
        | {f.entry_key[:3] for f in conflicts if "<distortion>" in f.message}
    )
    return tally


def test_the_counts_at_lensfun_master_are_the_independent_counts(lensfun_head):
    # Issue 24: 8 undefined mounts, 25 lenses with conflicting TCA, 2 with
    # conflicting distortion (both duplicate-focal errors), 9 starting-value entries.
    tally = counts(lensfun_head)
    assert tally["undefined-mount"] == 8
    assert tally["tca lenses"] == 25
    assert tally["conflicting-calibration"] == 89  # TCA entries, in those 25 lenses
    assert tally["distortion lenses"] == 2
    assert tally["vignetting-starting-values"] == 9


def test_the_counts_on_the_bundled_database(bundled_db):
    tally = counts(bundled_db)
    assert tally["undefined-mount"] == 10  # "Fujifilm G" is defined only later
    assert (tally["tca lenses"], tally["conflicting-calibration"]) == (25, 89)
    assert tally["distortion lenses"] == 1
    assert tally["vignetting-starting-values"] == 5
