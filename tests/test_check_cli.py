"""`lensaudit check` on the command line: options, outputs and exit codes."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from conftest import lens_xml
from lensaudit.cli import main

FOLDING = '<distortion model="poly3" focal="10" k1="-0.3"/>'  # r_normalized 0.578
NEAR = '<distortion model="poly3" focal="20" k1="-0.05"/>'  # r_normalized 1.027
OUTSIDE = '<distortion model="poly3" focal="30" k1="-0.03"/>'  # r_normalized 1.289
FINE = '<distortion model="poly3" focal="40" k1="0.01"/>'  # r_max infinite


@pytest.fixture
def runner():
    return CliRunner()


def run(runner, *arguments: str):
    return runner.invoke(main, ["check", *arguments])


def test_help_documents_the_exit_codes(runner):
    text = run(runner, "--help").output
    assert "Exit status:" in text
    for line in ("0  no finding fails", "1  at least one new error", "2  bad usage"):
        assert line in text


def test_clean_database_exits_0(runner, write_xml):
    result = run(runner, str(write_xml(lens_xml(FINE)).parent))
    assert result.exit_code == 0, result.output
    assert result.output.endswith("0 errors, 0 warnings\n")


def test_fold_in_the_image_exits_1_with_file_and_line(runner, write_xml):
    path = write_xml(lens_xml(FINE, FOLDING))
    result = run(runner, str(path.parent))
    assert result.exit_code == 1
    first, second = result.output.splitlines()[:2]
    assert first.startswith("lensaudit check: ") and str(path.parent) in first  # what was read
    assert second.startswith(f"{path}:11: error [fold-in-image] Test 10mm (poly3, 10 mm")


def test_warning_alone_exits_0(runner, write_xml):
    result = run(runner, str(write_xml(lens_xml(NEAR))))
    assert result.exit_code == 0
    assert "warning [fold-near-image]" in result.output


def test_margin_option_widens_the_warning_band(runner, write_xml):
    path = str(write_xml(lens_xml(OUTSIDE)))
    assert "fold-near-image" not in run(runner, path).output
    assert "fold-near-image" in run(runner, path, "--margin", "1.3").output


@pytest.mark.parametrize("margin", ["0.5", "nan", "inf", "abc"])
def test_margin_that_is_not_a_number_of_at_least_one_is_a_usage_error(runner, write_xml, margin):
    result = run(runner, str(write_xml(lens_xml(FINE))), "--margin", margin)
    assert result.exit_code == 2
    assert "--margin" in result.output


def test_verbose_adds_notices_that_do_not_fail(runner, write_xml):
    path = str(write_xml(lens_xml(OUTSIDE)))
    assert "notice" not in run(runner, path).output.split("\n", 1)[1]  # under the header
    result = run(runner, path, "--verbose")
    assert result.exit_code == 0
    assert "notice [fold-outside-image]" in result.output


@pytest.mark.parametrize("name", ["text", "json", "github", "junit"])
def test_every_format_gives_the_same_exit_code(runner, write_xml, name):
    path = str(write_xml(lens_xml(FOLDING)))
    assert run(runner, path, "--format", name).exit_code == 1


def test_json_output_file(runner, write_xml, tmp_path):
    out = tmp_path / "findings.json"
    result = run(runner, str(write_xml(lens_xml(FOLDING, NEAR))), "-f", "json", "-o", str(out))
    assert result.exit_code == 1 and result.output == ""
    document = json.loads(out.read_text())
    assert [f["code"] for f in document["findings"]] == ["fold-in-image", "fold-near-image"]


def test_github_paths_are_relative_to_the_workspace(runner, write_xml, tmp_path, monkeypatch):
    write_xml(lens_xml(FOLDING), "slr-test.xml")
    monkeypatch.setenv("GITHUB_WORKSPACE", str(tmp_path))
    result = run(runner, str(tmp_path / "db"), "--format", "github")
    assert result.output.splitlines()[0].startswith(
        "::error file=db/slr-test.xml,line=10,title=lensaudit fold-in-image::Test 10mm"
    )


def test_baseline_directory_makes_old_findings_known(runner, write_xml, tmp_path):
    old = tmp_path / "old"
    old.mkdir()
    (old / "test.xml").write_text(lens_xml(FOLDING))
    path = write_xml(lens_xml(FINE, FOLDING))
    result = run(runner, str(path.parent), "--baseline", str(old))
    assert result.exit_code == 0, result.output
    assert f"Known from baseline {old} (not failing):\n  {path}:11: error" in result.output


def test_missing_path_exits_2_with_one_line(runner, tmp_path):
    result = run(runner, str(tmp_path / "nope"))
    assert result.exit_code == 2
    assert result.output.strip().splitlines() == [
        f"lensaudit: error: {tmp_path / 'nope'}: no such file or directory"
    ]


def test_unknown_format_is_a_usage_error(runner, write_xml):
    assert run(runner, str(write_xml(lens_xml(FINE))), "--format", "html").exit_code == 2


def test_default_is_the_bundled_database(runner, bundled_db):
    result = run(runner, "-f", "json")
    document = json.loads(result.output)
    assert str(bundled_db) in document["database"]
    assert document["summary"]["files"] == len(list(bundled_db.glob("*.xml")))
