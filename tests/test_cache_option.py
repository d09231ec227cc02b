"""One meaning of the cache options in every command: --cache/--no-cache
turns lensaudit's one cache on or off, --cache-dir DIR names its directory
(as $LENSAUDIT_CACHE_DIR does); a directory is never taken for a flag's
value, nor a flag's value for a database."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from conftest import FOLDING_LENS, git_repository
from lensaudit.cli import main

FOLDING = FOLDING_LENS


@pytest.fixture
def db(folding_db) -> Path:
    return folding_db


def records(directory: Path) -> list[str]:
    return sorted(p.name for p in (directory / "files").glob("*.rec"))


COMMANDS = {
    "scan": ["scan", "{db}"],
    "scan --kind": ["scan", "--kind", "vignetting", "{db}"],
    "check": ["check", "{db}"],
    "fix": ["fix", "{db}"],
    "report": ["report", "{db}", "-o", "{out}", "--force"],
    "plot": ["plot", "curve", "{db}/a.xml:10", "-o", "{out}.png"],
}


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_cache_dir_names_the_cache_of_every_command(command, db, tmp_path):
    words = [w.format(db=db, out=tmp_path / "out") for w in COMMANDS[command]]
    cache = tmp_path / "named"
    elsewhere = Path(os.environ["LENSAUDIT_CACHE_DIR"])  # conftest's, for this test
    result = CliRunner().invoke(main, [*words, "--cache-dir", str(cache)])
    assert result.exit_code in (0, 1), result.output
    assert records(cache)  # the file's record, in the directory named
    assert not elsewhere.exists() or not records(elsewhere)
    off = tmp_path / "off"
    result = CliRunner().invoke(main, [*words, "--no-cache", "--cache-dir", str(off)])
    assert result.exit_code in (0, 1), result.output
    assert not off.exists() or not records(off)


def test_the_plain_scan_reads_cache_dir_as_click_does(db, tmp_path):
    cache = tmp_path / "named"
    done = subprocess.run(
        [sys.executable, "-m", "lensaudit", "scan", str(db), "--cache-dir", str(cache)],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    assert records(cache)


def test_history_takes_the_same_options(tmp_path):
    repository = git_repository(tmp_path / "repo", {"data/db/a.xml": FOLDING})
    cache = tmp_path / "named"
    out = tmp_path / "out"
    result = CliRunner().invoke(
        main, ["history", str(repository), "-o", str(out), "-q", "--cache-dir", str(cache)]
    )
    assert result.exit_code == 0, result.output
    assert records(cache) and (cache / "history" / "trend").is_file()
    # --cache is a flag everywhere: what follows it is not its value.
    result = CliRunner().invoke(
        main, ["history", str(repository), "-o", str(out), "-q", "--cache", str(cache)]
    )
    assert result.exit_code == 2 and "unexpected extra argument" in result.output.lower()
