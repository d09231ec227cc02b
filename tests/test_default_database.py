"""One default database for every command: inside a Lensfun checkout the
checkout, else the database bundled with lensfunpy; every --help says so in
the same words, and every command names the database it read in its first
line (or, where its output is data, on standard error; or in its error)."""

from __future__ import annotations

import re

import pytest
from click.testing import CliRunner

from lensaudit.cli import main

RULE = (
    "the database of the Lensfun checkout around the working directory, else the one "
    "bundled with lensfunpy"
)
CHECKOUT = "the Lensfun checkout around the working directory"
BUNDLED = "Lensfun database bundled with lensfunpy"


def said(words: list[str]) -> str:
    return " ".join(CliRunner().invoke(main, words).output.split())


@pytest.mark.parametrize(
    "command", [["scan"], ["check"], ["fix"], ["report"], ["plot", "curve"], ["project"]]
)
def test_every_help_states_the_rule_in_the_same_words(command):
    assert RULE in said([*command, "--help"])


def test_history_help_says_its_default_repository():
    text = said(["history", "--help"])
    assert "without REPO, the Lensfun checkout around the working directory" in text


def first_lines(words: list[str]) -> tuple[int, str, str]:
    result = CliRunner().invoke(main, words)
    return result.exit_code, result.stdout.split("\n", 1)[0], result.stderr


def runs(tmp_path, tokina: str) -> dict[str, tuple[int, str, str]]:
    out = tmp_path / "out"
    points = tmp_path / "points.csv"
    points.write_text("x,y,z\n0.1,0.1,1\n")
    return {
        "scan": first_lines(["scan", "--no-cache"]),
        "check": first_lines(["check", "--no-cache"]),
        "fix": first_lines(["fix", "--no-cache", "--lens", "Tokina 11-16", "--focal", "11"]),
        "report": first_lines(["report", "--no-cache", "-o", str(out)]),
        "plot": first_lines(["plot", "curve", tokina, "-o", str(tmp_path / "c.png")]),
        "project": first_lines(["project", str(points), "--entry", tokina, "--size", "6000x4000"]),
    }


def assert_named(found: dict, expected: str) -> None:
    for command, (code, first, errors) in found.items():
        assert code in (0, 1), (command, errors)
        named = errors if command == "project" else first
        assert expected in named, (command, first, errors)


def test_outside_a_checkout_every_command_names_the_bundled_database(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert_named(runs(tmp_path, "slr-tokina.xml:17"), BUNDLED)


def test_inside_a_checkout_every_command_names_and_reads_the_checkout(
    lensfun_head, tmp_path, monkeypatch
):
    monkeypatch.chdir(lensfun_head.parents[1])
    tokina = (lensfun_head / "slr-tokina.xml").read_text().splitlines()
    line = next(i for i, text in enumerate(tokina, 1) if re.search(r"<distortion ", text))
    found = runs(tmp_path, f"slr-tokina.xml:{line}")
    assert_named(found, CHECKOUT)
    code, first, _ = first_lines(["history", "-o", str(tmp_path / "h"), "--no-cache"])
    assert code == 0 and first.startswith(f"data/db in {lensfun_head.parents[1]}")


def test_an_entry_not_found_names_the_database_searched(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    result = CliRunner().invoke(
        main, ["plot", "curve", "slr-tokina.xml:99999", "-o", str(tmp_path / "c.png")]
    )
    assert result.exit_code == 2 and BUNDLED in result.stderr
    result = CliRunner().invoke(
        main, ["project", "-", "--entry", "no-such.xml:3", "--size", "6000x4000"], input=""
    )
    assert result.exit_code == 2 and BUNDLED in result.stderr


def test_history_outside_a_checkout_without_repo_says_what_to_give(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    result = CliRunner().invoke(main, ["history", "-o", str(tmp_path / "h")])
    assert result.exit_code == 2 and "give REPO" in result.stderr
