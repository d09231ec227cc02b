"""File versions of Lensfun's database from its history bundle, for tests that
hold lensaudit to a reference on real data of every era."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from conftest import GIT_ENVIRONMENT, HISTORY_BUNDLE


def file_versions(directory: Path, revisions: int = 25) -> list[bytes]:
    """The distinct ``data/db/*.xml`` file versions at ``revisions`` commits spread
    evenly over the history (the bundle cloned into ``directory``); the test
    skips without the bundle."""
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

    commits = git("rev-list", "HEAD", "--", "data/db").split()
    blobs = set()
    for commit in commits[:: max(1, len(commits) // revisions)]:
        for line in git("ls-tree", commit.decode(), "data/db/").splitlines():
            mode_type_oid, _, name = line.partition(b"\t")
            if name.endswith(b".xml"):
                blobs.add(mode_type_oid.split()[2])
    answer = git("cat-file", "--batch", stdin=b"".join(blob + b"\n" for blob in sorted(blobs)))
    versions, position = [], 0
    while position < len(answer):
        header_end = answer.index(b"\n", position)
        size = int(answer[position:header_end].split()[2])
        versions.append(answer[header_end + 1 : header_end + 1 + size])
        position = header_end + 2 + size
    assert len(versions) == len(blobs)
    return versions
