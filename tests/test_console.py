"""The console command's own reading of ``lensaudit scan``, against click's.

A scan whose command line is plain runs without click; these tests hold that
reading to click's on the same words (what it accepts, refuses or answers
with help), and the scan it runs to the click command's output and status.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import click
import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import lens_xml
from lensaudit import commands
from lensaudit.cli import main
from lensaudit.cli.scan import scan as scan_command
from lensaudit.console import ScanArguments, scan_arguments


def test_scan_options_are_the_commands_own():
    options = [p for p in scan_command.params if isinstance(p, click.Option)]
    names = {name: option.is_flag for option in options for name in option.opts}
    names |= {name: True for option in options for name in option.secondary_opts}
    assert set(commands.SCAN_OPTIONS) == set(names)
    assert {name for name, flag in names.items() if flag} == set(commands.SCAN_FLAGS)


WORD = st.sampled_from(
    [
        "db",
        "a.xml",
        "",
        "-",
        "--",
        "-f",
        "--format",
        "--format=csv",
        "-fjson",
        "--format=",
        "csv",
        "json",
        "table",
        "xml",
        "-k",
        "--kind=tca",
        "-kvignetting",
        "vignetting",
        "distortion",
        "-o",
        "-oout.csv",
        "out.csv",
        "--output=x",
        "--output=",
        ".",  # a directory: not an output file
        "--cache",
        "--no-cache",
        "--no-cache=1",
        "--cache-dir",
        "--cache-dir=cache",
        "--cache-dir=",
        "-h",
        "--help",
        "--version",
        "-x",
        "-fk",
        "-f=csv",
        "-o=x",
        "-k=tca",
        "--form",
        "--format=json=",
    ]
)


def click_reading(words: list[str]) -> ScanArguments | None:
    """What click makes of ``scan WORDS...``: the arguments, or None if it
    refuses them or answers with help."""
    try:
        context = scan_command.make_context("scan", list(words))
    except (click.exceptions.Exit, click.UsageError):
        return None
    found = context.params
    return ScanArguments(
        tuple(str(path) for path in found["paths"]),
        found["output_format"],
        found["kind"],
        None if found["output"] is None else str(found["output"]),
        found["cache"],
    )


@settings(max_examples=600, deadline=None)
@given(st.lists(WORD, max_size=8))
def test_scan_arguments_are_what_click_reads(words):
    ours = scan_arguments(words)
    theirs = click_reading(words)
    if ours is None:
        return  # click's own reading: help, its messages
    assert theirs is not None, f"click refuses {words}, the console would run them"
    assert (ours.output_format, ours.kind, ours.cache) == (
        theirs.output_format,
        theirs.kind,
        theirs.cache,
    )
    assert list(map(Path, ours.paths)) == list(map(Path, theirs.paths))  # "" is "."
    assert (ours.output is None) == (theirs.output is None)
    if ours.output is not None:
        assert Path(ours.output) == Path(theirs.output)


def test_plain_command_lines_are_read_without_click():
    assert scan_arguments([]) == ScanArguments()
    assert scan_arguments(["db", "-fcsv", "--no-cache", "-o", "x.csv"]) == ScanArguments(
        ("db",), "csv", "distortion", "x.csv", False
    )
    assert scan_arguments(["--", "--help"]) == ScanArguments(("--help",))
    assert scan_arguments(["-o=x"]) == ScanArguments(output="=x")  # as click reads it
    for words in (["--help"], ["-f", "xml"], ["--kind"], ["-o", "."], ["--unknown"], ["-f=csv"]):
        assert scan_arguments(words) is None


def run_console(*words: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    code = "import sys; from lensaudit.console import run; sys.argv[0] = 'lensaudit'; run()"
    return subprocess.run(
        [sys.executable, "-c", code, *words],
        capture_output=True,
        timeout=120,
        cwd=cwd,
        env={**os.environ, "PYTHONWARNINGS": "error"},
    )


def click_result(*words: str) -> click.testing.Result:
    return CliRunner().invoke(main, list(words))


@pytest.mark.parametrize(
    "words",
    [
        ["-f", "csv"],
        ["-f", "json", "--no-cache"],
        ["--kind", "vignetting", "-f", "csv"],
        ["-k", "tca"],
    ],
)
def test_direct_scan_writes_what_the_click_command_writes(write_xml, words):
    path = write_xml(
        lens_xml(
            '<distortion model="poly3" focal="10" k1="-0.5"/>',
            '<vignetting model="pa" focal="10" aperture="2" distance="10" '
            'k1="-2" k2="0.5" k3="0"/>',
            '<tca model="poly3" focal="10" br="0.001" vr="1.001" bb="0" vb="0.999"/>',
        )
    )
    direct = run_console("scan", *words, str(path))
    through_click = click_result("scan", *words, str(path))
    assert direct.returncode == through_click.exit_code == 0, direct.stderr
    assert direct.stdout.decode() == through_click.stdout


@pytest.mark.parametrize(
    "words",
    [
        ["/no/such/database"],
        ["-o", "/no/such/directory/out.csv"],
        ["--no-cache", "empty"],
    ],
)
def test_direct_scan_fails_as_the_click_command_fails(tmp_path, words):
    (tmp_path / "empty").mkdir()
    direct = run_console("scan", *words, cwd=tmp_path)
    previous = Path.cwd()
    os.chdir(tmp_path)
    try:
        through_click = click_result("scan", *words)
    finally:
        os.chdir(previous)
    assert direct.returncode == through_click.exit_code == 2
    assert direct.stderr.decode() == through_click.stderr
    assert len(direct.stderr.decode().splitlines()) == 1


def test_help_and_bad_usage_still_go_to_click():
    helped = run_console("scan", "--help")
    assert helped.returncode == 0
    assert b"Compute r_max" in helped.stdout
    refused = run_console("scan", "-f", "xml")
    assert refused.returncode == 2
    assert b"'xml' is not one of" in refused.stderr
