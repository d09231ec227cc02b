"""`lensaudit report`: what it writes, where, and when it refuses to."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest
from click.testing import CliRunner

from conftest import lens_xml
from lensaudit.cli import main
from lensaudit.report import REPORT_FILES


@pytest.fixture
def runner():
    return CliRunner()


@pytest.fixture
def small_db(write_xml):
    path = write_xml(
        lens_xml(
            '<distortion model="poly3" focal="10" k1="-0.3"/>',
            '<distortion model="poly3" focal="20" k1="0.01"/>',
        )
    )
    return path.parent


def test_creates_the_directory_and_writes_every_file(runner, small_db, tmp_path):
    target = tmp_path / "nested" / "report"
    result = runner.invoke(main, ["report", str(small_db), "-o", str(target)])
    assert result.exit_code == 0, result.output
    assert sorted(p.name for p in target.iterdir()) == sorted(REPORT_FILES)
    assert "report.html" in result.output
    summary = json.loads((target / "summary.json").read_text())
    assert summary["summary"]["entries"] == 2
    assert summary["folding"] == ["test.xml:10"]
    assert (target / "entries.csv").read_text().splitlines()[0].startswith("file,line,maker")


def test_existing_files_are_kept_without_force(runner, small_db, tmp_path):
    target = tmp_path / "report"
    target.mkdir()
    (target / "table1.csv").write_text("mine\n")
    result = runner.invoke(main, ["report", str(small_db), "-o", str(target)])
    assert result.exit_code == 2
    assert "table1.csv" in result.output and "--force" in result.output
    assert result.output.strip().count("\n") == 0 and "Traceback" not in result.output
    assert (target / "table1.csv").read_text() == "mine\n"
    assert sorted(p.name for p in target.iterdir()) == ["table1.csv"]


def test_force_replaces_report_files_and_leaves_others(runner, small_db, tmp_path):
    target = tmp_path / "report"
    target.mkdir()
    (target / "table1.csv").write_text("mine\n")
    (target / "README.md").write_text("notes\n")
    result = runner.invoke(main, ["report", str(small_db), "-o", str(target), "--force"])
    assert result.exit_code == 0, result.output
    assert (target / "table1.csv").read_text().startswith("model,finite,infinite,%finite,total")
    assert (target / "README.md").read_text() == "notes\n"
    assert not list(target.glob(".*.tmp"))


def test_a_second_run_needs_force(runner, small_db, tmp_path):
    target = tmp_path / "report"
    assert runner.invoke(main, ["report", str(small_db), "-o", str(target)]).exit_code == 0
    again = runner.invoke(main, ["report", str(small_db), "-o", str(target)])
    assert again.exit_code == 2 and "entries.csv" in again.output


def test_output_that_is_a_file_is_an_input_error(runner, small_db, tmp_path):
    target = tmp_path / "file.txt"
    target.write_text("x")
    result = runner.invoke(main, ["report", str(small_db), "-o", str(target)])
    assert result.exit_code == 2 and "Traceback" not in result.output
    assert "not a directory" in result.output


def test_output_directory_is_required(runner, small_db):
    result = runner.invoke(main, ["report", str(small_db)])
    assert result.exit_code == 2 and "-o" in result.output


def test_missing_database_exits_2_and_writes_nothing(runner, tmp_path):
    target = tmp_path / "report"
    result = runner.invoke(main, ["report", str(tmp_path / "missing"), "-o", str(target)])
    assert result.exit_code == 2 and "no such file" in result.output
    assert not target.exists()


def test_unreadable_database_exits_2(runner, write_xml, tmp_path):
    path = write_xml("<lensdatabase>", "broken.xml")
    result = runner.invoke(main, ["report", str(path), "-o", str(tmp_path / "out")])
    assert result.exit_code == 2 and "broken.xml" in result.output


def test_tables_are_in_the_papers_layout(runner, small_db, tmp_path):
    target = tmp_path / "report"
    runner.invoke(main, ["report", str(small_db), "-o", str(target)])
    assert (target / "table1.csv").read_text().splitlines() == [
        "model,finite,infinite,%finite,total",
        "ptlens,0,0,,0",
        "poly3,1,1,50.00,2",
        "poly5,0,0,,0",
        "Total,1,1,50.00,2",
    ]
    assert (target / "table2.csv").read_text().splitlines() == [
        "model,positive,negative,%negative,total",
        "ptlens,0,0,,0",
        "poly3,0,1,100.00,1",
        "poly5,0,0,,0",
        "Total,0,1,100.00,1",
    ]
    markdown = (target / "table1.md").read_text().splitlines()
    assert markdown[2] == "| model  | finite | infinite | %finite | total |"
    assert markdown[-1] == "| Total  |      1 |        1 |  50.00% |     2 |"


def test_paper_option_adds_the_comparison(runner, small_db, tmp_path):
    target = tmp_path / "report"
    result = runner.invoke(main, ["report", str(small_db), "-o", str(target), "--paper"])
    assert result.exit_code == 0, result.output
    comparison = (target / "paper_comparison.md").read_text()
    assert "1141 | 0" in comparison.replace("\\|", "|")
    assert "Database version" in comparison
    assert 'id="paper"' in (target / "report.html").read_text()


CALIBRATED = (
    '<distortion model="poly3" focal="10" k1="-0.3"/>',
    '<vignetting model="pa" focal="10" aperture="2.8" distance="10" k1="-0.5"/>',
    '<tca model="poly3" focal="10" vr="1.001" vb="0.999"/>',
)


@pytest.fixture
def parses(monkeypatch):
    """The contents the reader's parser is given, in order."""
    from lensaudit.read import xml

    given = []
    parse = xml.parse

    def counted(data, *arguments, **options):
        given.append(data)
        return parse(data, *arguments, **options)

    monkeypatch.setattr(xml, "parse", counted)
    return given


def test_a_report_parses_each_file_once(runner, write_xml, tmp_path, parses):
    first = write_xml(lens_xml(*CALIBRATED), "a.xml")
    second = write_xml(lens_xml(*CALIBRATED[:2], cropfactor="1.5"), "b.xml")
    target = tmp_path / "report"
    arguments = ["report", "--no-cache", "--paper", str(first.parent), "-o", str(target)]
    result = runner.invoke(main, arguments)
    assert result.exit_code == 0, result.output
    assert sorted(parses) == sorted([first.read_bytes(), second.read_bytes()])
    # Distortion, vignetting and TCA all come from that one read.
    assert len((target / "entries.csv").read_text().splitlines()) == 3
    assert len((target / "vignetting.csv").read_text().splitlines()) == 3
    assert len((target / "tca.csv").read_text().splitlines()) == 2


def test_a_report_of_an_unchanged_database_parses_nothing_with_the_cache(
    runner, small_db, tmp_path, parses
):
    first = runner.invoke(main, ["report", str(small_db), "-o", str(tmp_path / "one")])
    assert first.exit_code == 0 and len(parses) == 1
    second = runner.invoke(main, ["report", str(small_db), "-o", str(tmp_path / "two")])
    assert second.exit_code == 0 and len(parses) == 1
    for name in ("entries.csv", "vignetting.csv", "tca.csv", "summary.json"):
        assert (tmp_path / "one" / name).read_bytes() == (tmp_path / "two" / name).read_bytes()


def test_default_is_the_bundled_database(runner, tmp_path):
    target = tmp_path / "report"
    result = runner.invoke(main, ["report", "-o", str(target)])
    assert result.exit_code == 0, result.output
    provenance = json.loads((target / "summary.json").read_text())["provenance"]
    assert provenance["database"].startswith("Lensfun database bundled with lensfunpy")


# Runs the command line in a fresh interpreter and prints, last, which heavy
# modules it imported.
IMPORTS_SCRIPT = """
import json, os, sys
from lensaudit.cli import main
from lensaudit.read import parallel
if "CPUS" in os.environ:  # as if this many CPUs were free
    parallel.cpus = lambda: int(os.environ["CPUS"])
try:
    main(sys.argv[1:], prog_name="lensaudit")
except SystemExit:
    pass
print(json.dumps(sorted(m for m in ("matplotlib", "pandas") if m in sys.modules)))
"""


def heavy_imports(arguments, tmp_path, cpus=None):
    environment = {"LENSAUDIT_CACHE_DIR": str(tmp_path / "cache")}
    if cpus is not None:
        environment["CPUS"] = str(cpus)
    result = subprocess.run(
        [sys.executable, "-c", IMPORTS_SCRIPT, *arguments],
        capture_output=True,
        text=True,
        timeout=300,
        check=True,
        env={**os.environ, **environment},
    )
    return json.loads(result.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize(
    "arguments",
    [["report", "--help"], ["plot", "--help"], ["plot", "warp", "--help"], ["scan", "DB"]],
)
def test_commands_that_draw_nothing_do_not_import_matplotlib(arguments, small_db, tmp_path):
    arguments = [str(small_db) if a == "DB" else a for a in arguments]
    assert heavy_imports(arguments, tmp_path) == []


@pytest.mark.parametrize(
    "cpus, imported",
    [
        (1, ["matplotlib"]),
        pytest.param(2, [], marks=pytest.mark.skipif(not hasattr(os, "fork"), reason="no os.fork")),
    ],
)
def test_a_report_imports_matplotlib_where_figure5_is_drawn_and_not_pandas(
    small_db, tmp_path, cpus, imported
):
    """With a CPU to spare, Figure 5 is drawn (matplotlib imported) in a forked
    process (lensaudit.report.drawing), not in the command's."""
    arguments = ["report", str(small_db), "-o", str(tmp_path / "out")]
    assert heavy_imports(arguments, tmp_path, cpus) == imported
    assert (tmp_path / "out" / "fig5_r_normalized.svg").read_text().count("<svg") == 1
