"""What each command imports, in a fresh interpreter: heavy modules only where needed,
and modules that depend on each other one way only."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

HEAVY = ("numpy", "pandas", "matplotlib", "scipy", "lxml")

# Runs the command line in this interpreter as the console command does (a
# plain scan without click, the rest through it), then prints every module.
RUN_AND_LIST = (
    "import json, sys\n"
    "from lensaudit.console import dispatch\n"
    "status = dispatch(sys.argv[1:])\n"
    "assert not status, status\n"
    "print(json.dumps(sorted(sys.modules)))\n"
)


def imported_by(
    arguments: list[str], cache_dir: Path, watched: tuple[str, ...] = HEAVY
) -> set[str]:
    """The ``watched`` modules a fresh `lensaudit ARGUMENTS` has imported when it ends."""
    env = dict(os.environ, LENSAUDIT_CACHE_DIR=str(cache_dir))
    done = subprocess.run(
        [sys.executable, "-c", RUN_AND_LIST, *arguments],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    return set(json.loads(done.stdout.splitlines()[-1])) & set(watched)


def imported_modules(statement: str) -> set[str]:
    """Every module a fresh interpreter has imported after ``statement``."""
    code = f"import json, sys\n{statement}\nprint(json.dumps(sorted(sys.modules)))"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return set(json.loads(done.stdout))


@pytest.fixture
def cache_dir(tmp_path: Path) -> Path:
    return tmp_path / "cache"


@pytest.mark.parametrize("output_format", ["table", "csv", "json"])
def test_a_scan_never_imports_pandas_or_matplotlib(cache_dir, output_format):
    found = imported_by(["scan", "-f", output_format, "-o", os.devnull], cache_dir)
    assert "lxml" in found  # parsed: the check can fail
    assert not found & {"pandas", "matplotlib", "scipy"}


@pytest.mark.parametrize("output_format", ["table", "csv", "json"])
def test_a_cold_scan_of_the_bundled_database_audits_without_numpy(cache_dir, output_format):
    found = imported_by(["scan", "-f", output_format, "-o", os.devnull, "--no-cache"], cache_dir)
    assert found == {"lxml"}


def test_a_scan_imports_numpy_for_entries_the_plain_path_leaves_to_it(cache_dir, tmp_path):
    # 1 - 3 w + 2.25 w^2 = (1 - 1.5 w)^2 touches zero: the fast path cannot tell
    # its sign there, the exact path of the array code decides it.
    database = tmp_path / "db"
    database.mkdir()
    (database / "tangent.xml").write_text(
        "<lensdatabase><lens><maker>M</maker><model>L</model><mount>X</mount>"
        '<calibration><distortion model="poly5" focal="10" k1="-1" k2="0.45"/>'
        "</calibration></lens></lensdatabase>"
    )
    found = imported_by(["scan", str(database), "-o", os.devnull], cache_dir)
    assert "numpy" in found


@pytest.mark.parametrize("output_format", ["table", "csv", "json"])
def test_a_warm_scan_imports_no_heavy_module(cache_dir, output_format):
    arguments = ["scan", "-f", output_format, "-o", os.devnull]
    imported_by(arguments, cache_dir)  # fills the cache
    assert imported_by(arguments, cache_dir) == set()


@pytest.mark.parametrize("output_format", ["table", "csv", "json"])
def test_a_warm_scan_does_not_import_typing_dataclasses_or_inspect(cache_dir, output_format):
    # lensaudit's modules name types only for type checkers, and the records a
    # scan makes are not dataclasses (dataclasses imports inspect); lxml imports
    # typing and inspect, but a scan from the cache has no XML to parse.
    arguments = ["scan", "-f", output_format, "-o", os.devnull]
    imported_by(arguments, cache_dir)  # fills the cache
    watched = ("typing", "lxml", "dataclasses", "inspect")
    assert imported_by(arguments, cache_dir, watched) == set()
    assert "typing" in imported_by(arguments + ["--no-cache"], cache_dir, ("typing",))


def test_a_warm_scan_in_another_format_imports_no_heavy_module(cache_dir):
    imported_by(["scan", "-f", "csv", "-o", os.devnull], cache_dir)
    assert imported_by(["scan", "-f", "json", "-o", os.devnull], cache_dir) == set()


@pytest.mark.parametrize("command", ["scan", "report", "plot", "check", "history", "project"])
def test_help_imports_no_plotting_or_data_frames(cache_dir, command):
    found = imported_by([command, "--help"], cache_dir)
    assert not found & {"pandas", "matplotlib"}


def test_report_help_imports_no_heavy_module(cache_dir):
    assert imported_by(["report", "--help"], cache_dir) == set()


def test_the_cache_does_not_import_the_pipeline():
    found = imported_modules("import lensaudit.cache")
    assert "lensaudit.cache" in found and "lensaudit.pipeline" not in found


def test_the_summary_does_not_import_the_pipeline_or_numpy():
    found = imported_modules("import lensaudit.summary")
    assert "lensaudit.summary" in found
    assert not found & {"lensaudit.pipeline", "lensaudit.cache", "numpy"}


def test_the_output_formats_do_not_import_the_pipeline():
    found = imported_modules(
        "import lensaudit.formats.csv_format, lensaudit.formats.json_format, "
        "lensaudit.formats.table"
    )
    assert "lensaudit.formats.json_format" in found and "lensaudit.pipeline" not in found


def test_the_column_names_import_no_other_lensaudit_module():
    found = imported_modules("import lensaudit.columns")
    assert {m for m in found if m.startswith("lensaudit")} == {"lensaudit", "lensaudit.columns"}


def test_a_plain_scan_from_the_console_never_imports_click(cache_dir):
    found = imported_by(["scan", "-f", "csv", "-o", os.devnull], cache_dir, ("click", *HEAVY))
    assert "lxml" in found  # it did scan
    assert "click" not in found
