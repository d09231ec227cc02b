"""A baseline on disk that is the very files checked is refused.

Compared with itself, a database has every finding known: a change adding a
folding entry would pass with exit 0. Whatever the name the baseline reaches
the checked files by (the same directory, ``.``, a relative form, a link, the
Lensfun checkout whose data/db is checked, a directory holding a checked
file, a hard link), the check refuses it with exit 2 and a line saying what
to give instead. A git revision (HEAD for uncommitted work) and a real copy
of the database before the change stay legitimate.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest

from conftest import FOLDING_LENS, GIT_ENVIRONMENT, lens_xml
from lensaudit.check import CheckError, check
from lensaudit.console import dispatch

REFUSED = "holds the very files checked"


@pytest.fixture
def checkout(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A Lensfun checkout whose data/db/a.xml folds (a new error against any
    baseline without it); the cache kept under tmp_path."""
    root = tmp_path / "lensfun"
    (root / "data" / "db").mkdir(parents=True)
    (root / "data" / "db" / "a.xml").write_text(FOLDING_LENS)
    monkeypatch.setenv("LENSAUDIT_CACHE_DIR", str(tmp_path / "cache"))
    return root


def same_files(root: Path) -> list[tuple[str, str]]:
    """(paths checked, baseline) pairs naming the same files in several ways."""
    db = root / "data" / "db"
    link = root.parent / "link-to-db"
    link.symlink_to(db, target_is_directory=True)
    hard = root.parent / "hard"
    hard.mkdir()
    os.link(db / "a.xml", hard / "a.xml")
    return [
        (str(db), str(db)),
        (str(db), str(db) + "/."),
        (str(db), str(db / ".." / "db")),
        (str(db), str(root)),  # the checkout stands for its data/db
        (str(db), str(root / "data")),
        (str(root), str(db)),
        (str(db), str(link)),
        (str(link), str(db)),
        (str(db / "a.xml"), str(db)),  # a directory holding the file checked
        (str(db / "a.xml"), str(db / "a.xml")),
        (str(db / "a.xml"), str(link / "a.xml")),
        (str(db), str(hard)),  # a hard link is the same file
    ]


def test_check_refuses_a_baseline_that_is_the_files_checked(checkout):
    for paths, baseline in same_files(checkout):
        with pytest.raises(CheckError, match=REFUSED + ".*git revision"):
            check(paths, baseline=baseline)


def test_relative_forms_and_the_default_database_are_refused(checkout, monkeypatch):
    monkeypatch.chdir(checkout / "data" / "db")
    for paths, baseline in ((".", "."), (None, "."), (None, "../.."), ("a.xml", "../db")):
        with pytest.raises(CheckError, match=REFUSED):
            check(paths, baseline=baseline)


def test_the_command_exits_2_in_one_line(checkout, capsys):
    for paths, baseline in same_files(checkout):
        assert dispatch(["check", "--baseline", baseline, paths]) == 2
        lines = capsys.readouterr().err.splitlines()
        assert len(lines) == 1 and REFUSED in lines[0] and "--baseline" in lines[0], lines


def test_a_copy_of_the_database_is_a_baseline(checkout, tmp_path):
    copy = tmp_path / "before"
    shutil.copytree(checkout / "data" / "db", copy)
    result = check(checkout / "data" / "db", baseline=copy)
    assert not result.failed and [f.known for f in result.findings] == [True]
    # Without the folding entry, its finding is new.
    (copy / "a.xml").write_text(lens_xml('<distortion model="poly3" focal="16" k1="0.01"/>'))
    assert check(checkout / "data" / "db", baseline=copy).failed


@pytest.mark.skipif(shutil.which("git") is None, reason="git is not installed")
def test_head_is_a_baseline_for_uncommitted_work(checkout, monkeypatch):
    environment = {**os.environ, **GIT_ENVIRONMENT}
    for words in (["init", "-q"], ["add", "-A"], ["commit", "-qm", "a"]):
        subprocess.run(["git", *words], cwd=checkout, env=environment, check=True)
    monkeypatch.chdir(checkout)
    assert not check("data/db", baseline="HEAD").failed
    new = FOLDING_LENS.replace("Test", "Other")
    (checkout / "data" / "db" / "b.xml").write_text(new)
    assert check("data/db", baseline="HEAD").failed
    assert check(None, baseline="HEAD").failed
