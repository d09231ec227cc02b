"""The worker that starts parsing before ``lensaudit scan`` has read its options.

Its guess of what the scan will parse is checked against click's own reading
of the same command line; the audit it helps make against one made without
it, when the guess is right, wrong, or only partly right.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys

import click
import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

from lensaudit import early, workers
from lensaudit.cli import main
from lensaudit.cli.scan import scan
from lensaudit.pipeline import run

pytestmark = pytest.mark.skipif(not hasattr(os, "fork"), reason="no os.fork on this system")


@pytest.fixture
def two_cpus(monkeypatch):
    """As if a second CPU were free, whatever this machine has."""
    monkeypatch.setattr(early, "_cpus", lambda: 2)
    monkeypatch.setattr(workers, "_cpus", lambda: 2)
    monkeypatch.setattr(workers, "_can_fork", lambda: True)


@pytest.fixture
def adoptions(monkeypatch) -> list:
    """What each adoption gave: the adopted worker's file count, or None."""
    found: list = []
    real = early.adopt

    def adopt(*arguments):
        adopted = real(*arguments)
        found.append(None if adopted is None else len(adopted.paths))
        return adopted

    monkeypatch.setattr(early, "adopt", adopt)
    return found


def test_scan_options_are_the_commands_own():
    options = [p for p in scan.params if isinstance(p, click.Option)]
    names = {name: option.is_flag for option in options for name in option.opts}
    names |= {name: True for option in options for name in option.secondary_opts}
    assert set(early.SCAN_OPTIONS) == set(names)
    assert {name for name, flag in names.items() if flag} == set(early.SCAN_FLAGS)


WORDS = st.lists(
    st.sampled_from(
        [
            "db",
            "a.xml",
            "-",
            "--",
            "-f",
            "--format",
            "--format=csv",
            "-fjson",
            "csv",
            "json",
            "table",
            "xml",
            "-k",
            "--kind=tca",
            "vignetting",
            "distortion",
            "-o",
            "out.csv",
            "--output=x",
            "--cache",
            "--no-cache",
            "--no-cache=1",
            "-h",
            "--help",
            "-x",
        ]
    ),
    max_size=8,
)


@settings(max_examples=400, deadline=None)
@given(WORDS)
def test_a_guess_is_what_click_reads(words):
    found = early.guess(words)
    try:
        context = scan.make_context("scan", list(words), resilient_parsing=False)
    except (click.exceptions.Exit, click.UsageError):
        return  # click refuses (or shows help): the worker is stopped, its guess unused
    options = context.params
    if options["kind"] != "distortion":
        assert found is None
        return
    assert found is not None
    assert found.paths == tuple(str(path) for path in options["paths"])
    assert found.cache == options["cache"]
    wanted = options["output_format"]
    assert found.formats == ((wanted,) if wanted in ("csv", "json") else ())


def test_help_and_other_kinds_are_not_guessed():
    assert early.guess(["--help"]) is None
    assert early.guess(["-k", "vignetting", "db"]) is None
    assert early.guess(["--unknown", "db"]) is None
    assert early.guess(["db", "-f"]) is None  # the value is missing


def output_of(runner_arguments: list[str]) -> str:
    """The scan's output made in this process, with no worker started early."""
    result = CliRunner().invoke(main, ["scan", *runner_arguments])
    assert result.exit_code == 0, result.output
    return result.output


@pytest.mark.parametrize("output_format", ["table", "csv", "json"])
def test_adopted_worker_gives_the_same_audit(bundled_db, two_cpus, adoptions, output_format):
    words = ["--no-cache", "-f", output_format, str(bundled_db)]
    expected = output_of(words)
    early.start(words)
    result = CliRunner().invoke(main, ["scan", *words])
    assert adoptions[-1] == len(list(bundled_db.glob("*.xml")))
    assert result.output == expected


def test_worker_parsing_another_way_is_not_adopted(bundled_db, two_cpus, adoptions):
    words = ["--no-cache", "-f", "csv", str(bundled_db)]
    expected = output_of(words)
    early.start(["--no-cache", "-f", "json", str(bundled_db)])  # guessed another format
    result = CliRunner().invoke(main, ["scan", *words])
    assert adoptions[-1] is None
    assert result.output == expected


def test_worker_that_listed_other_files_helps_with_the_common_ones(
    bundled_db, tmp_path, two_cpus, adoptions
):
    database = tmp_path / "db"
    shutil.copytree(bundled_db, database)
    other = tmp_path / "other"
    other.mkdir()
    for name in ("slr-canon.xml", "slr-nikon.xml"):
        shutil.copy(bundled_db / name, other / name)
    # The worker takes every file of both; the scan needs those of one.
    early.start(["--no-cache", "-f", "csv", str(database), str(other)])
    audit = run(database, formats=("csv",))
    assert adoptions == [len(list(database.glob("*.xml"))) + 2]
    assert "".join(audit.rows("csv")) == "".join(run(database, formats=("csv",)).rows("csv"))


def test_worker_that_listed_some_files_leaves_the_others_to_the_scan(
    bundled_db, tmp_path, two_cpus, adoptions
):
    other = tmp_path / "other"
    other.mkdir()
    for name in ("slr-canon.xml", "slr-nikon.xml"):
        shutil.copy(bundled_db / name, other / name)
    early.start(["--no-cache", "-f", "json", str(other)])  # the scan wants more
    audit = run([other, bundled_db], formats=("json",))
    assert adoptions == [2]
    assert "".join(audit.rows("json")) == "".join(
        run([other, bundled_db], formats=("json",)).rows("json")
    )


def test_a_database_the_cache_has_met_is_left_to_the_scan(
    bundled_db, tmp_path, two_cpus, adoptions
):
    database = tmp_path / "db"
    shutil.copytree(bundled_db, database)
    output_of(["-f", "csv", str(database)])  # the cache now knows every file
    changed = database / "slr-canon.xml"
    changed.write_bytes(changed.read_bytes().replace(b'a="0.0', b'a="0.1', 1))
    expected = output_of(["--no-cache", "-f", "csv", str(database)])
    early.start(["-f", "csv", str(database)])
    result = CliRunner().invoke(main, ["scan", "-f", "csv", str(database)])
    assert adoptions[-1] is None  # nothing to do: the changed file is parsed here
    assert result.output == expected


def test_worker_is_stopped_when_the_scan_does_not_parse(tmp_path, two_cpus):
    early.start(["--no-cache", str(tmp_path / "missing")])
    worker = early._started
    assert worker is not None
    early.stop()
    assert early._started is None
    with pytest.raises(ChildProcessError):
        os.waitpid(worker.pid, os.WNOHANG)  # reaped already


def test_console_command_with_the_worker_matches_the_library(bundled_db):
    command = [sys.executable, "-m", "lensaudit", "scan", "--no-cache", "-f", "csv"]
    result = subprocess.run([*command, str(bundled_db)], capture_output=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert result.stdout.decode() == output_of(["--no-cache", "-f", "csv", str(bundled_db)])
    missing = subprocess.run([*command, "/no/such/db"], capture_output=True, timeout=120)
    assert missing.returncode == 2
    assert len(missing.stderr.decode().strip().splitlines()) == 1


def test_worker_is_stopped_when_the_scan_fails_while_parsing(bundled_db, two_cpus, monkeypatch):
    early.start(["--no-cache", str(bundled_db)])
    pid = early._started.pid

    def failing_import() -> None:
        raise RuntimeError("numpy is broken")

    monkeypatch.setattr("lensaudit.pipeline._metrics", failing_import)
    with pytest.raises(RuntimeError, match="numpy is broken"):
        run(bundled_db)
    with pytest.raises(ChildProcessError):
        os.waitpid(pid, os.WNOHANG)  # stopped and reaped, not left writing to nobody
