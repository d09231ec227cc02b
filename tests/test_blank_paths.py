"""An empty or blank path is bad usage, never the working directory.

``"$VAR"`` with VAR unset gives an empty word, which ``Path("")`` reads as
``.``: a scan of whatever is there, a report written into it, a baseline that
is the checkout being checked (every finding known, the gate passing). Every
path a command takes, and every library function taking a database path,
refuses an empty or blank one in one line. The working directory here is a
Lensfun checkout with a folding entry, so that reading it would succeed.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest

from conftest import FOLDING_LENS, GIT_ENVIRONMENT
from lensaudit import audit
from lensaudit.check import CheckError, check
from lensaudit.console import dispatch
from lensaudit.history import HistoryError, audit_history
from lensaudit.read import LoadError, resolve
from lensaudit.read.paths import expand

BLANKS = ("", "  ")


@pytest.fixture
def checkout(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A git repository laid out as a Lensfun checkout (data/db/a.xml folds),
    committed and made the working directory; the cache kept under tmp_path."""
    root = tmp_path / "lensfun"
    (root / "data" / "db").mkdir(parents=True)
    (root / "data" / "db" / "a.xml").write_text(FOLDING_LENS)
    if shutil.which("git"):
        environment = {**os.environ, **GIT_ENVIRONMENT}
        for words in (["init", "-q"], ["add", "-A"], ["commit", "-qm", "a"]):
            subprocess.run(["git", *words], cwd=root, env=environment, check=True)
    monkeypatch.chdir(root)
    monkeypatch.setenv("LENSAUDIT_CACHE_DIR", str(tmp_path / "cache"))
    return root


#: (command line with BLANK where the blank value goes, how click names it).
COMMAND_LINES = [
    (["scan", "BLANK"], "[PATH ...]"),
    (["scan", "-o", "BLANK", "data/db"], "--output"),
    (["scan", "--cache-dir", "BLANK", "data/db"], "--cache-dir"),
    (["scan", "-f", "csv", "data/db", "BLANK"], "[PATH ...]"),
    (["check", "BLANK"], "[PATH ...]"),
    (["check", "-o", "BLANK", "data/db"], "--output"),
    (["check", "--baseline", "BLANK", "data/db"], "--baseline"),
    (["check", "--baseline", "BLANK"], "--baseline"),
    (["report", "-o", "out", "BLANK"], "[PATH ...]"),
    (["report", "-o", "BLANK", "data/db"], "--output"),
    (["fix", "BLANK"], "[PATH ...]"),
    (["fix", "-o", "BLANK", "data/db"], "--output"),
    (["plot", "curve", "a.xml:10", "-o", "BLANK", "--db", "data/db"], "--output"),
    (["plot", "curve", "a.xml:10", "-o", "out.png", "--db", "BLANK"], "--db"),
    (["project", "BLANK", "--entry", "data/db/a.xml:10"], "[POINTS]"),
    (["project", "--entry", "a.xml:10", "--db", "BLANK"], "--db"),
    (["project", "--entry", "data/db/a.xml:10", "-o", "BLANK"], "--output"),
    (["history", "BLANK", "-o", "out"], "[REPO]"),
    (["history", ".", "-o", "BLANK"], "--output"),
    (["history", ".", "--path", "BLANK", "-o", "out"], "--path"),
]


@pytest.mark.parametrize("blank", BLANKS, ids=("empty", "blank"))
@pytest.mark.parametrize(
    ("words", "option"), COMMAND_LINES, ids=[" ".join(words) for words, _ in COMMAND_LINES]
)
def test_a_blank_path_on_the_command_line_is_bad_usage(checkout, capsys, words, option, blank):
    status = dispatch([blank if word == "BLANK" else word for word in words])
    captured = capsys.readouterr()
    assert status == 2, captured.err
    lines = captured.err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("lensaudit: error: "), captured.err
    assert option in lines[0] and "is blank (an unset variable?)" in lines[0]
    assert "Traceback" not in captured.err
    # Nothing was written where the working directory would have stood for the path.
    assert sorted(p.name for p in checkout.iterdir() if p.name != ".git") == ["data"]


@pytest.mark.parametrize("blank", [*BLANKS, b""], ids=("empty", "blank", "bytes"))
def test_the_library_refuses_a_blank_database_path(checkout, blank):
    for call in (
        lambda: resolve(blank),
        lambda: resolve(["data/db", blank]),
        lambda: expand([blank]),
        lambda: audit(blank),
        lambda: check(blank),
    ):
        with pytest.raises(LoadError, match="empty or blank"):
            call()


@pytest.mark.parametrize("blank", [*BLANKS, b""], ids=("empty", "blank", "bytes"))
def test_check_refuses_a_blank_baseline_before_reading(checkout, blank):
    for paths in ("data/db", None):
        with pytest.raises(CheckError, match="--baseline .* is blank .*git revision"):
            check(paths, baseline=blank)


@pytest.mark.skipif(shutil.which("git") is None, reason="git is not installed")
@pytest.mark.parametrize("blank", BLANKS, ids=("empty", "blank"))
def test_history_refuses_a_blank_repository_or_database_path(checkout, blank):
    with pytest.raises(HistoryError, match="empty or blank"):
        audit_history(blank)
    with pytest.raises(HistoryError, match="empty or blank"):
        audit_history(checkout, path=blank)
