"""The files of a database directory are those liblensfun reads, in every command.

lfDatabase::Load (libs/lensfun/database.cpp of Lensfun master) reads each
entry of a directory whose name matches GLib's pattern ``*.xml``, which is
case-sensitive and takes hidden names, and reads an entry so named that is a
directory (through a link too) as a directory in turn. Here small directory
trees are made by hand, loaded by liblensfun master through ``lf_db_load_path``
(ctypes, :func:`liblensfun_master.directory_lenses`), and the set of lenses
each of lensaudit's ways in sees must be liblensfun's set: the reader (cold
and from the cache), scan's audit, check, report's audits, a git baseline and
the history.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest

import liblensfun_master
from conftest import GIT_ENVIRONMENT, lens_xml
from lensaudit import audit
from lensaudit.check import check, sources_from_git
from lensaudit.history import audit_history
from lensaudit.read import Cache, paths, read
from lensaudit.read.paths import expand, is_database_directory
from lensaudit.report.audits import audit as report_audit

needs_git = pytest.mark.skipif(shutil.which("git") is None, reason="git is not installed")


def lens(model: str) -> str:
    """A one-lens database file whose entry folds inside its image."""
    return lens_xml('<distortion model="poly3" focal="10" k1="-0.3"/>').replace("Test 10mm", model)


#: Files of the hand-made trees: path relative to the database -> the lens in it.
FILES = {
    "top.xml": "top",
    "sub.xml/in-sub.xml": "in a directory named *.xml",
    "sub.xml/deeper.xml/deep.xml": "two directories down",
    "sub.xml/plain/p.xml": "in a plain directory under one named *.xml",
    "sub.xml/inner.txt": "not *.xml in a directory named *.xml",
    "plain/q.xml": "in a plain directory",
    "UP.XML": "upper-case suffix",
    "Mixed.Xml": "mixed-case suffix",
    "notes.txt": "not *.xml",
    "backup.xml~": "a backup",
    "trailing.xml ": "a space after .xml",
    ".hidden.xml": "hidden",
    ".xml": "named .xml alone",
    "x.xml.d/r.xml": "in a directory named *.xml.d",
    "empty.xml/.keep": "",
}


def make_tree(root: Path, links: bool) -> Path:
    """The database ``root/db`` of :data:`FILES`; with ``links``, also links to
    a file, to a directory outside it, to itself, and one leading nowhere."""
    db = root / "db"
    for name, model in FILES.items():
        (db / name).parent.mkdir(parents=True, exist_ok=True)
        (db / name).write_text(lens(model) if model else "")
    if links:
        os.symlink("top.xml", db / "link.xml")
        os.symlink("nowhere.xml", db / "dangling.xml")
        os.symlink(".", db / "loop.xml")  # liblensfun reads db again, 40 links deep
        outside = root / "outside"
        outside.mkdir()
        (outside / "far.xml").write_text(lens("through a directory link"))
        (outside / "FAR.XML").write_text(lens("upper case through a directory link"))
        os.symlink(outside, db / "dirlink.xml")
        os.symlink(outside, db / "plainlink")
    return db


def liblensfun_set(path: Path) -> set[tuple[str, str]]:
    found = set(liblensfun_master.directory_lenses(path))
    assert found, "liblensfun loaded nothing: the reference is not running"
    return found


def lens_set(files) -> set[tuple[str, str]]:
    """(maker, model) of every lens in the reader's tables of some files."""
    return {(lens.maker, lens.model) for file in files for lens in file.lenses}


@pytest.fixture(params=[False, True], ids=["plain", "links"])
def tree(request, tmp_path) -> Path:
    if request.param and not hasattr(os, "symlink"):
        pytest.skip("no symbolic links here")
    return make_tree(tmp_path, links=request.param)


def test_liblensfun_reads_what_its_source_says(tree):
    models = {model for _, model in liblensfun_set(tree)}
    assert {"top", "in a directory named *.xml", "two directories down", "hidden"} <= models
    assert models.isdisjoint({"upper-case suffix", "in a plain directory", "not *.xml"})
    assert {paths.loaded_name(name) for name in ("a.xml", ".xml", ".a.xml")} == {True}
    assert {paths.loaded_name(name) for name in ("A.XML", "a.Xml", "a.xml~", "a.xml ", "a")} == {
        False
    }


def test_the_reader_sees_the_lenses_liblensfun_loads(tree, tmp_path):
    expected = liblensfun_set(tree)
    assert lens_set(read(tree).files) == expected
    cache = Cache(tmp_path / "cache")
    assert lens_set(read(tree, cache=cache).files) == expected
    cache.save()
    again = Cache(tmp_path / "cache")
    assert lens_set(read(tree, cache=again).files) == expected  # from the cache


def test_scan_check_and_report_see_the_lenses_liblensfun_loads(tree):
    expected = liblensfun_set(tree)
    scanned = audit(tree)
    scanned = scanned[scanned["lens"] != ""]  # not the row of a file that cannot be read
    assert set(zip(scanned["maker"], scanned["lens"], strict=True)) == expected
    result = check(tree)
    folds = {f.entry_key[:2] for f in result.findings if f.code == "fold-in-image"}
    assert folds == expected  # every lens folds: each is checked
    assert lens_set(report_audit(tree).files) == expected


def test_files_in_subdirectories_are_named_under_them(tree):
    names = [name for _, name in expand([tree])]
    assert "sub.xml/in-sub.xml" in names and "sub.xml/deeper.xml/deep.xml" in names
    assert not any(name.startswith(("plain", "x.xml.d")) for name in names)
    assert is_database_directory(tree)


def test_a_database_only_in_a_subdirectory_named_xml_is_a_database(tmp_path):
    checkout = tmp_path / "lensfun"
    (checkout / "data" / "db" / "all.xml").mkdir(parents=True)
    (checkout / "data" / "db" / "all.xml" / "a.xml").write_text(lens("nested only"))
    assert is_database_directory(checkout / "data" / "db")
    assert paths.database_entries(checkout / "data" / "db") == [("all.xml/a.xml", False)]
    # A checkout stands for its data/db, and the fold in the subdirectory fails the check.
    assert check(checkout).failed


def test_what_liblensfun_cannot_read_is_reported_not_skipped(tmp_path):
    if not hasattr(os, "symlink"):
        pytest.skip("no symbolic links here")
    db = make_tree(tmp_path, links=True)
    result = check(db)
    unreadable = {f.file for f in result.findings if f.code == "unreadable"}
    assert unreadable == {str(db / "dangling.xml")}
    assert result.failed


def test_links_back_up_the_tree_are_listed_once(tmp_path):
    # Two links back: liblensfun reads 2**40 paths (it is not asked here).
    db = make_tree(tmp_path, links=True)
    os.symlink("..", db / "sub.xml" / "up.xml")
    os.symlink("../..", db / "sub.xml" / "deeper.xml" / "top.xml")
    names = [name for name, _ in paths.database_entries(db)]
    assert len(names) == len(set(names)) and "sub.xml/in-sub.xml" in names
    assert not any("up.xml" in name or "loop.xml" in name for name in names)
    assert len(expand([db])) == len({path for path, _ in expand([db])})


@needs_git
def test_a_git_baseline_and_the_history_read_the_same_files(tmp_path):
    db = make_tree(tmp_path / "repo" / "data", links=False)
    repository = tmp_path / "repo"
    environment = {**os.environ, **GIT_ENVIRONMENT}
    for words in (["init", "-q"], ["add", "-A"], ["commit", "-qm", "tree"]):
        subprocess.run(["git", *words], cwd=repository, env=environment, check=True)
    expected = liblensfun_set(db)
    on_disk = sorted(name for _, name in expand([db]))
    in_git = sources_from_git([db], "HEAD")
    assert sorted(source.name for source in in_git) == on_disk
    # Against itself at HEAD, every fold is known; against nothing new, all are new.
    assert not check(db, baseline="HEAD").failed
    history = audit_history(repository)
    assert {(e.entry.maker, e.entry.lens) for e in history.introduced} == expected
