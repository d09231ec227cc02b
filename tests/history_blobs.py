"""File versions of Lensfun's database from its history bundle, for tests that
hold lensaudit to a reference on real data of every era."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from conftest import GIT_ENVIRONMENT, HISTORY_BUNDLE


def file_versions(directory: Path, revisions: int = 25, by_file: bool = False) -> list[bytes]:
    """The distinct ``data/db/*.xml`` file versions at ``revisions`` commits spread
    evenly over the history (the bundle cloned into ``directory``); with
    ``by_file``, file by file, each file's oldest first (as the history reads
    them), else in no particular order. The test skips without the bundle."""
    if not HISTORY_BUNDLE.is_file():
        pytest.skip(f"no Lensfun history bundle at {HISTORY_BUNDLE}")
    clone = directory / "lensfun"
    subprocess.run(
        ["git", "clone", "--quiet", "--bare", str(HISTORY_BUNDLE), str(clone)],
        check=True,
        capture_output=True,
    )

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
