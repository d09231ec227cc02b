"""`lensaudit.git`: the read-only git layer that check and history share.

Expected object ids are computed independently (SHA-1 of git's object
header and content), expected commits by running git directly.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import GIT_ENVIRONMENT
from lensaudit import git

pytestmark = pytest.mark.skipif(shutil.which("git") is None, reason="git is not installed")


def _git(path: Path, *args: str) -> str:
    done = subprocess.run(
        ["git", "-C", str(path), *args],
        check=True,
        capture_output=True,
        text=True,
        env=dict(os.environ, **GIT_ENVIRONMENT),
    )
    return done.stdout.strip()


def blob_id(data: bytes) -> str:
    """git's id of a blob: SHA-1 of "blob <size>\\0" and the content."""
    return hashlib.sha1(b"blob %d\0" % len(data) + data).hexdigest()  # noqa: S324


FIRST = b"<lensdatabase/>\n"
SECOND = b"<lensdatabase>\n  <lens/>\n</lensdatabase>\n"
BINARY = bytes(range(256)) * 3 + b"\n\n"


@pytest.fixture(scope="module")
def repo(tmp_path_factory) -> dict:
    path = tmp_path_factory.mktemp("git") / "repo"
    (path / "data" / "db").mkdir(parents=True)
    _git(path, "init", "-q", "-b", "main")
    (path / "data" / "db" / "a.xml").write_bytes(FIRST)
    (path / "README").write_bytes(BINARY)
    _git(path, "add", "-A")
    _git(path, "commit", "-q", "-m", "first")
    first = _git(path, "rev-parse", "HEAD")
    (path / "data" / "db" / "a.xml").write_bytes(SECOND)
    _git(path, "commit", "-q", "-am", "second")
    second = _git(path, "rev-parse", "HEAD")
    (path / "README").write_bytes(b"readme\n")
    _git(path, "commit", "-q", "-am", "third, not the database")
    third = _git(path, "rev-parse", "HEAD")
    _git(path, "tag", "-a", "-m", "a tag", "v1", first)
    return {"path": path, "first": first, "second": second, "third": third}


def test_run_gives_git_standard_output(repo):
    assert git.run(repo["path"], "rev-parse", "HEAD").decode().strip() == repo["third"]


def test_run_raises_git_error_with_gits_last_message_line(repo):
    with pytest.raises(git.GitError, match="^fatal: Not a valid object name no-such-object$"):
        git.run(repo["path"], "cat-file", "-t", "no-such-object")


def test_run_without_git_raises_git_unavailable(repo, monkeypatch, tmp_path):
    monkeypatch.setenv("PATH", str(tmp_path))  # a directory without git
    with pytest.raises(git.GitUnavailable):
        git.run(repo["path"], "status")


def test_commands_run_in_the_safe_environment(repo):
    # An alias run through git shows the environment git gives its children.
    script = "import os; print(os.environ['GIT_OPTIONAL_LOCKS'], os.environ['LC_ALL'])"
    shown = git.run(repo["path"], "-c", f'alias.env=!"{sys.executable}" -c "{script}"', "env")
    assert shown.decode().split() == ["0", "C"]


def test_top_level_of_a_subdirectory_is_the_work_tree(repo):
    top = git.top_level(repo["path"] / "data" / "db")
    assert top.resolve() == repo["path"].resolve()


def test_top_level_outside_any_repository_raises_git_error(tmp_path, monkeypatch):
    monkeypatch.setenv("GIT_CEILING_DIRECTORIES", str(tmp_path))
    (tmp_path / "plain").mkdir()
    with pytest.raises(git.GitError):
        git.top_level(tmp_path / "plain")


def test_resolve_commit_gives_the_full_id_and_follows_tags(repo):
    assert git.resolve_commit(repo["path"], "HEAD~2") == repo["first"]
    assert git.resolve_commit(repo["path"], "v1") == repo["first"]  # annotated tag: its commit
    assert git.resolve_commit(repo["path"], repo["second"][:8]) == repo["second"]


@pytest.mark.parametrize("revision", ["no-such-branch", "--all", "-h", "HEAD:README"])
def test_resolve_commit_refuses_what_names_no_commit(repo, revision):
    with pytest.raises(git.GitError):
        git.resolve_commit(repo["path"], revision)


def test_list_tree_of_a_directory_gives_its_blobs_with_their_ids(repo):
    entries = git.list_tree(repo["path"], repo["first"], ["data/db/"])
    assert entries == [git.TreeEntry("100644", "blob", blob_id(FIRST), "data/db/a.xml")]


def test_list_tree_without_paths_gives_the_top_level(repo):
    entries = git.list_tree(repo["path"], repo["third"])
    assert [(e.type, e.path) for e in entries] == [("blob", "README"), ("tree", "data")]


def test_list_tree_of_an_absent_path_is_empty(repo):
    assert git.list_tree(repo["path"], repo["first"], ["nothing/"]) == []


def test_log_gives_the_commits_that_change_a_path_newest_first(repo):
    assert git.log(repo["path"], repo["third"], "data/db/a.xml") == [repo["second"], repo["first"]]
    assert git.log(repo["path"], repo["third"], "data/db/a.xml", max_count=1) == [repo["second"]]
    assert git.log(repo["path"], repo["third"]) == [repo["third"], repo["second"], repo["first"]]


def test_objects_answer_ids_and_revision_paths_in_order(repo):
    names = [
        f"{repo['second']}:data/db/a.xml",
        blob_id(FIRST),
        "no-such-object",
        f"{repo['first']}:README",
        f"{repo['first']}:data",
    ]
    answers = list(git.objects(repo["path"], names))
    assert answers[0] == (blob_id(SECOND), "blob", SECOND)
    assert answers[1] == (blob_id(FIRST), "blob", FIRST)
    assert answers[2] is None
    assert answers[3] == (blob_id(BINARY), "blob", BINARY)
    assert answers[4] is not None and answers[4][1] == "tree"


def test_objects_accept_bytes_names(repo):
    assert list(git.objects(repo["path"], [blob_id(FIRST).encode()])) == [
        (blob_id(FIRST), "blob", FIRST)
    ]


def test_objects_answer_many_requests_through_one_process(repo):
    names = [blob_id(BINARY), blob_id(FIRST)] * 3000  # more than a pipe holds either way
    answers = list(git.objects(repo["path"], names))
    assert len(answers) == len(names)
    assert all(a == (blob_id(BINARY), "blob", BINARY) for a in answers[::2])


def test_objects_of_nothing_start_no_git(repo, monkeypatch, tmp_path):
    monkeypatch.setenv("PATH", str(tmp_path))
    assert list(git.objects(repo["path"], [])) == []


def test_reading_leaves_the_index_as_it_is(repo):
    index = repo["path"] / ".git" / "index"
    before = index.stat().st_mtime_ns, index.read_bytes()
    (repo["path"] / "README").touch()  # a stat change git status would refresh
    try:
        git.run(repo["path"], "status", "--porcelain")
        list(git.objects(repo["path"], [f"{repo['third']}:README"]))
        assert (index.stat().st_mtime_ns, index.read_bytes()) == before
    finally:
        _git(repo["path"], "checkout", "-q", "--", "README")


def test_object_sizes_are_the_contents_lengths(repo):
    names = [blob_id(SECOND), "no-such-object", blob_id(BINARY)]
    assert git.object_sizes(repo["path"], names) == [len(SECOND), None, len(BINARY)]
    assert git.object_sizes(repo["path"], []) == []
