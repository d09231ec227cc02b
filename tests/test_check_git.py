"""`lensaudit check --baseline REV` on a real git repository built in a temporary directory.

The repository holds a few files of the bundled Lensfun database in
``data/db`` (the layout of a Lensfun checkout). A second commit adds an entry
that folds inside its image and a malformed one: the check must fail on
exactly those two, at their lines, and pass on the baseline itself.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest
from click.testing import CliRunner

import liblensfun_load
from conftest import GIT_ENVIRONMENT
from lensaudit.check import CheckError, check
from lensaudit.cli import main

pytestmark = pytest.mark.skipif(shutil.which("git") is None, reason="git is not installed")

BASELINE_FILES = ("6x6.xml", "actioncams.xml", "slr-vivitar.xml")
CHANGED_FILE = "actioncams.xml"
FOLDING = '<distortion model="poly3" focal="123.5" k1="-0.3"/>'  # r_normalized < 0.63
MALFORMED = '<distortion model="poly3" focal="124.5" k1="NaN"/>'


def git(repository: Path, *arguments: str) -> str:
    completed = subprocess.run(
        ["git", *arguments],
        cwd=repository,
        capture_output=True,
        text=True,
        check=True,
        env={**os.environ, **GIT_ENVIRONMENT},
    )
    return completed.stdout.strip()


def insert_after_first_distortion(path: Path, *lines: str) -> list[int]:
    """Insert lines after the file's first <distortion>, same indent; their line numbers."""
    text = path.read_text(encoding="utf-8").splitlines(keepends=True)
    index = next(i for i, line in enumerate(text) if "<distortion " in line)
    indent = re.match(r"\s*", text[index]).group()
    text[index + 1 : index + 1] = [f"{indent}{line}\n" for line in lines]
    path.write_text("".join(text), encoding="utf-8")
    return [index + 2 + offset for offset in range(len(lines))]


class Repository:
    """A Lensfun-like checkout: ``root/data/db/*.xml``, with a baseline commit."""

    def __init__(self, root: Path, bundled_db: Path) -> None:
        self.root = root
        self.db = root / "data" / "db"
        self.db.mkdir(parents=True)
        for name in BASELINE_FILES:
            shutil.copy(bundled_db / name, self.db / name)
        git(root, "init", "-q", "-b", "main")
        git(root, "add", "data")
        git(root, "commit", "-q", "-m", "baseline")
        self.baseline = git(root, "rev-parse", "HEAD")

    def commit_change(self) -> list[int]:
        lines = insert_after_first_distortion(self.db / CHANGED_FILE, FOLDING, MALFORMED)
        git(self.root, "commit", "-q", "-am", "add two entries")
        return lines


@pytest.fixture
def repository(tmp_path, bundled_db) -> Repository:
    return Repository(tmp_path / "lensfun", bundled_db)


@pytest.fixture
def runner():
    return CliRunner()


def test_the_baseline_checked_against_itself_passes(repository, runner):
    result = runner.invoke(main, ["check", str(repository.db), "--baseline", repository.baseline])
    assert result.exit_code == 0, result.output
    assert "lensaudit check passed" in result.output


def test_commit_with_a_folding_and_a_malformed_entry_fails_on_exactly_those(repository):
    fold_line, malformed_line = repository.commit_change()
    result = check(repository.db, baseline=repository.baseline)
    failing = [(Path(f.file).name, f.line, f.code) for f in result.findings if f.fails]
    assert failing == [
        (CHANGED_FILE, fold_line, "fold-in-image"),
        (CHANGED_FILE, malformed_line, "bad-value"),
    ]
    assert all(f.known for f in result.findings if not f.fails and f.severity == "error")
    assert result.failed


def test_cli_exits_1_and_prints_file_and_line_of_both(repository, runner):
    fold_line, malformed_line = repository.commit_change()
    result = runner.invoke(main, ["check", str(repository.db), "--baseline", repository.baseline])
    assert result.exit_code == 1
    path = repository.db / CHANGED_FILE
    new = [line for line in result.output.splitlines() if line.startswith(str(path))]
    assert [line.split(" [")[0] for line in new] == [
        f"{path}:{fold_line}: error",
        f"{path}:{malformed_line}: error",
    ]
    assert "k1='NaN' is not a finite number" in new[1]


def test_github_annotations_carry_the_path_from_the_repository_root(
    repository, runner, monkeypatch
):
    fold_line, malformed_line = repository.commit_change()
    monkeypatch.delenv("GITHUB_WORKSPACE", raising=False)
    monkeypatch.chdir(repository.root)
    result = runner.invoke(
        main, ["check", "data/db", "--baseline", repository.baseline, "--format", "github"]
    )
    assert result.exit_code == 1
    annotations = ("::error ", "::warning ", "::notice ")
    commands = [line for line in result.output.splitlines() if line.startswith(annotations)]
    assert [line.split("::")[1] for line in commands] == [
        f"error file=data/db/{CHANGED_FILE},line={fold_line},title=lensaudit fold-in-image",
        f"error file=data/db/{CHANGED_FILE},line={malformed_line},title=lensaudit bad-value",
    ]


def test_after_the_commit_head_is_a_baseline_that_passes(repository, runner):
    repository.commit_change()
    result = runner.invoke(main, ["check", str(repository.db), "--baseline", "HEAD"])
    assert result.exit_code == 0, result.output
    alone = runner.invoke(main, ["check", str(repository.db), "--format", "json"]).output
    every = len(json.loads(alone)["findings"])  # all of them known: nothing new
    assert every > 0
    assert result.output.strip().endswith(
        f"0 errors, 0 warnings; {every} known from baseline HEAD, 0 resolved"
    )


def test_baseline_is_read_from_git_not_from_the_work_tree(repository):
    # An uncommitted change is the current state; HEAD (the baseline) does not have it.
    index = repository.root / ".git" / "index"
    insert_after_first_distortion(repository.db / CHANGED_FILE, FOLDING)
    status_before = git(repository.root, "status", "--porcelain")
    index_before = index.read_bytes(), index.stat().st_mtime_ns
    result = check(repository.db, baseline="HEAD")
    assert [f.code for f in result.findings if f.fails] == ["fold-in-image"]
    assert (index.read_bytes(), index.stat().st_mtime_ns) == index_before
    assert git(repository.root, "status", "--porcelain") == status_before


def test_broken_file_in_a_commit_fails_with_line_and_column(repository):
    path = repository.db / "slr-vivitar.xml"
    lines = path.read_text(encoding="utf-8").splitlines(keepends=True)
    lines[5] = lines[5].replace(">", "", 1)  # the first ">" of line 6 is gone
    path.write_text("".join(lines), encoding="utf-8")
    git(repository.root, "commit", "-q", "-am", "break a file")
    result = check(repository.db, baseline=repository.baseline)
    [failing] = [f for f in result.findings if f.fails]
    assert (Path(failing.file).name, failing.code) == ("slr-vivitar.xml", "xml-error")
    assert failing.line >= 6 and failing.column > 0
    assert f"line {failing.line}, column {failing.column}" in failing.message
    # Every other file is still checked.
    assert [f.entries > 0 for f in result.files] == [True, True, True]


def test_a_file_given_directly_is_compared_with_the_same_file_at_the_revision(repository):
    repository.commit_change()
    result = check(repository.db / CHANGED_FILE, baseline=repository.baseline)
    assert [f.code for f in result.findings if f.fails] == ["fold-in-image", "bad-value"]


def test_database_that_did_not_exist_at_the_revision_is_all_new(repository, bundled_db):
    extra = repository.root / "more"
    extra.mkdir()
    shutil.copy(bundled_db / "slr-tokina.xml", extra / "slr-tokina.xml")
    result = check(extra, baseline=repository.baseline)
    assert result.failed and not any(f.known for f in result.findings)


def test_unknown_revision_exits_2_with_one_line(repository, runner):
    result = runner.invoke(main, ["check", str(repository.db), "--baseline", "no-such-rev"])
    assert result.exit_code == 2
    assert result.output.strip().splitlines() == [
        f"lensaudit: error: --baseline no-such-rev: not an existing directory, nor a "
        f"revision of the git repository at {repository.root.resolve()}"
    ]


def test_revision_that_looks_like_an_option_is_not_one(repository):
    with pytest.raises(CheckError, match="nor a revision"):
        check(repository.db, baseline="--output=/tmp/x")


def test_revision_for_a_path_outside_any_repository_exits_2(tmp_path, bundled_db, runner):
    outside = tmp_path / "plain"
    outside.mkdir()
    shutil.copy(bundled_db / "6x6.xml", outside)
    result = runner.invoke(main, ["check", str(outside), "--baseline", "HEAD"])
    assert result.exit_code == 2
    assert "is not inside a git repository" in result.output


# -- the pre-commit hook ------------------------------------------------------------


def hook_definition() -> dict[str, str]:
    """The flat ``key: value`` pairs of the hook in .pre-commit-hooks.yaml."""
    text = (Path(__file__).parent.parent / ".pre-commit-hooks.yaml").read_text()
    pairs = re.findall(r"^(?:- )?\s*([a-z_]+): (.+)$", text, re.MULTILINE)
    return dict(pairs)


def test_pre_commit_hook_runs_lensaudit_check_on_database_files():
    hook = hook_definition()
    assert hook["id"] == "lensaudit-check"
    assert hook["entry"] == "lensaudit check"
    files = re.compile(hook["files"])
    assert files.search("data/db/slr-canon.xml")
    assert not files.search("data/db/timestamp.txt") and not files.search("docs/a.xml")


def test_pre_commit_hook_command_fails_a_staged_folding_entry(repository, runner, monkeypatch):
    hook = hook_definition()
    arguments = hook["args"].strip("[]").split(", ")
    monkeypatch.chdir(repository.root)
    assert runner.invoke(main, ["check", *arguments]).exit_code == 0
    insert_after_first_distortion(repository.db / CHANGED_FILE, FOLDING)
    git(repository.root, "add", "data")
    assert runner.invoke(main, ["check", *arguments]).exit_code == 1


# -- a baseline whose file cannot be parsed -------------------------------------------


def break_file(path: Path) -> None:
    """Delete the first ">" of line 6, as an unfinished edit would."""
    lines = path.read_text(encoding="utf-8").splitlines(keepends=True)
    lines[5] = lines[5].replace(">", "", 1)
    path.write_text("".join(lines), encoding="utf-8")


@pytest.fixture
def repaired(repository) -> tuple[Repository, str, list[int]]:
    """A fold committed, then its file broken, then repaired (uncommitted).

    Returns the repository, the commit with the fold, and the fold's line.
    """
    path = repository.db / CHANGED_FILE
    fold_lines = insert_after_first_distortion(path, FOLDING)
    git(repository.root, "commit", "-q", "-am", "a fold")
    with_fold = git(repository.root, "rev-parse", "HEAD")
    good = path.read_bytes()
    break_file(path)
    git(repository.root, "commit", "-q", "-am", "break the file")
    path.write_bytes(good)
    return repository, with_fold, fold_lines


def refused_line(path: Path) -> int:
    """Where liblensfun master stops loading the file (the bundled database's
    actioncams.xml has a <real-focal-length>, which master no longer reads)."""
    loaded, _ = liblensfun_load.load_and_lenses(path.read_bytes())
    assert not loaded.ok
    return liblensfun_load.stop_line(loaded)


def test_repairing_a_broken_file_keeps_its_old_findings_known(repaired):
    repository, with_fold, [fold_line] = repaired
    result = check(repository.db, baseline="HEAD")
    assert not result.failed
    assert [(f.code, f.line, f.known) for f in result.findings if f.severity == "error"] == [
        ("fold-in-image", fold_line, True),
        ("liblensfun-refuses", refused_line(repository.db / CHANGED_FILE), True),
    ]


def test_the_repaired_file_gets_a_notice_naming_the_version_compared_with(repaired):
    repository, with_fold, _ = repaired
    [notice] = [f for f in check(repository.db, baseline="HEAD").findings if f.severity == "notice"]
    assert notice.code == "baseline-unreadable"
    assert Path(notice.file).name == CHANGED_FILE
    assert f"of commit {with_fold[:12]}" in notice.message


def test_a_fold_added_while_repairing_a_file_is_new(repaired):
    repository, _, _ = repaired
    [new_line] = insert_after_first_distortion(repository.db / CHANGED_FILE, MALFORMED)
    result = check(repository.db, baseline="HEAD")
    assert [(f.code, f.line) for f in result.findings if f.fails] == [("bad-value", new_line)]


def test_without_a_readable_version_the_findings_of_the_file_are_not_new(repaired, monkeypatch):
    from lensaudit import check as checking

    repository, _, [fold_line] = repaired
    monkeypatch.setattr(checking, "HISTORY_DEPTH", 1)  # only the broken version is searched
    result = check(repository.db, baseline="HEAD")
    assert not result.failed
    assert [(f.code, f.line, f.known) for f in result.findings if f.severity == "error"] == [
        ("fold-in-image", fold_line, True),
        ("liblensfun-refuses", refused_line(repository.db / CHANGED_FILE), True),
    ]
    [notice] = [f for f in result.findings if f.severity == "notice"]
    assert "not counted as new" in notice.message


def test_a_broken_file_unchanged_since_the_baseline_is_known(repaired):
    repository, _, _ = repaired
    break_file(repository.db / CHANGED_FILE)  # the same breakage as the baseline's
    result = check(repository.db, baseline="HEAD")
    assert [(f.code, f.known) for f in result.findings if f.severity == "error"] == [
        ("xml-error", True)
    ]


# -- paths as CI systems expect them -------------------------------------------------


def test_github_workspace_does_not_override_the_repository_holding_path(
    repository, runner, monkeypatch
):
    fold_line, _ = repository.commit_change()
    monkeypatch.setenv("GITHUB_WORKSPACE", str(repository.root.parent))
    result = runner.invoke(
        main, ["check", str(repository.db), "--baseline", repository.baseline, "-f", "github"]
    )
    first = result.output.splitlines()[0]
    assert first.startswith(f"::error file=data/db/{CHANGED_FILE},line={fold_line},")


def test_junit_file_paths_are_relative_to_the_repository_root(
    repository, runner, monkeypatch, tmp_path
):
    import xml.etree.ElementTree as StdlibET

    repository.commit_change()
    monkeypatch.delenv("GITHUB_WORKSPACE", raising=False)
    monkeypatch.chdir(tmp_path)  # outside the repository: paths given are absolute
    result = runner.invoke(
        main, ["check", str(repository.db), "--baseline", repository.baseline, "-f", "junit"]
    )
    root = StdlibET.fromstring(result.output)
    failing = [case for case in root.iter("testcase") if case.find("failure") is not None]
    assert {case.get("file") for case in failing} == {f"data/db/{CHANGED_FILE}"}
    assert {suite.get("name") for suite in root.iter("testsuite")} == {
        f"data/db/{name}" for name in BASELINE_FILES
    }


def test_a_checkout_root_given_as_path_is_compared_at_its_data_db(repository):
    fold_line, malformed_line = repository.commit_change()
    result = check(repository.root, baseline=repository.baseline)
    assert [(Path(f.file).name, f.line) for f in result.findings if f.fails] == [
        (CHANGED_FILE, fold_line),
        (CHANGED_FILE, malformed_line),
    ]
    assert len(result.files) == len(BASELINE_FILES)
