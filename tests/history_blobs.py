"""File versions of Lensfun's database from its history bundle, for tests that
hold lensaudit to a reference on real data of every era.

The bundle is cloned once a session, each list of versions is made once, and
each version's plain read from scratch (the reference several tests compare
with) is made once: the tests that share them ask for the same data."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from conftest import GIT_ENVIRONMENT, HISTORY_BUNDLE
from lensaudit import read
from lensaudit.read.records import FileTables

#: The one bare clone of the bundle, once made.
_clone: list[Path] = []
#: The versions, by (revisions, by_file).
_versions: dict[tuple[int, bool], list[bytes]] = {}
#: Each content's plain read (no calibrations, no refusals) from scratch, by content.
_plain: dict[bytes, FileTables] = {}


def _bare_clone(directory: Path) -> Path:
    """The session's bare clone of the bundle, made in ``directory`` the first time."""
    if not _clone or not _clone[0].is_dir():
        clone = directory / "lensfun"
        subprocess.run(
            ["git", "clone", "--quiet", "--bare", str(HISTORY_BUNDLE), str(clone)],
            check=True,
            capture_output=True,
        )
        _clone[:] = [clone]
    return _clone[0]


def file_versions(directory: Path, revisions: int = 25, by_file: bool = False) -> list[bytes]:
    """The distinct ``data/db/*.xml`` file versions at ``revisions`` commits spread
    evenly over the history (the bundle cloned into ``directory`` unless this
    session has cloned it already); with ``by_file``, file by file, each file's
    oldest first (as the history reads them), else in no particular order. The
    test skips without the bundle."""
    if not HISTORY_BUNDLE.is_file():
        pytest.skip(f"no Lensfun history bundle at {HISTORY_BUNDLE}")
    key = (revisions, by_file)
    if key not in _versions:
        _versions[key] = _read_versions(_bare_clone(directory), revisions, by_file)
    return list(_versions[key])


def _read_versions(clone: Path, revisions: int, by_file: bool) -> list[bytes]:
    def git(*arguments: str, stdin: bytes | None = None) -> bytes:
        done = subprocess.run(
            ["git", "-C", str(clone), *arguments],
            input=stdin,
            check=True,
            capture_output=True,
            env=GIT_ENVIRONMENT,
        )
        return done.stdout

    commits = git("rev-list", "--reverse", "HEAD", "--", "data/db").split()
    by_name: dict[bytes, dict[bytes, None]] = {}
    for commit in commits[:: max(1, len(commits) // revisions)]:
        for line in git("ls-tree", commit.decode(), "data/db/").splitlines():
            mode_type_oid, _, name = line.partition(b"\t")
            if name.endswith(b".xml"):
                by_name.setdefault(name, {})[mode_type_oid.split()[2]] = None
    blobs = dict.fromkeys(blob for versions in by_name.values() for blob in versions)
    order = list(blobs) if by_file else sorted(blobs)
    answer = git("cat-file", "--batch", stdin=b"".join(blob + b"\n" for blob in order))
    versions, position = [], 0
    while position < len(answer):
        header_end = answer.index(b"\n", position)
        size = int(answer[position:header_end].split()[2])
        versions.append(answer[header_end + 1 : header_end + 1 + size])
        position = header_end + 2 + size
    assert len(versions) == len(blobs)
    return versions


def read_alone(
    contents: list[bytes], calibrations: bool = False, refusals: bool = False
) -> list[FileTables]:
    """Each content read from scratch as "f.xml", with no memo of pieces and no
    cache (:func:`lensaudit.read.read_contents`, on every core); the plain
    reads are kept for the session."""
    plain = not calibrations and not refusals
    todo = list(dict.fromkeys(d for d in contents if not plain or d not in _plain))
    options = {"calibrations": calibrations, "refusals": refusals}
    tables = read.read_contents([(d, "f.xml", None) for d in todo], **options)
    made = dict(zip(todo, tables, strict=True))
    if plain:
        _plain.update(made)
        made = _plain
    return [made[d] for d in contents]
