"""Stage 2, blobs: which file versions (git blobs) make up the database at each
commit, through one ``git cat-file --batch`` (their contents are read by the
parse stage, in whichever process parses each)."""

from __future__ import annotations

import functools
import re
from pathlib import PurePosixPath

from ..read.paths import display_path
from .commits import Git


@functools.cache
def _tree_entries(oid_size: int) -> re.Pattern[bytes]:
    """The entries of a raw git tree object: mode, name, object id (``oid_size``
    bytes). Each entry starts where the one before it ends, so that the
    pattern's matches, one after another, are the entries."""
    return re.compile(rb"[0-7]+ [^\0]*\0.{%d}" % oid_size, re.DOTALL)


def _tree_files(data: bytes, oid_size: int, known: dict[bytes, tuple]) -> dict[str, str]:
    """{name: blob id} of the ``*.xml`` files directly in a raw git tree object;
    ``known`` keeps what each entry met is (the trees of a history share
    nearly all their entries).

    Subdirectories, symbolic links and submodules are not database files.
    """
    found = {}
    for entry in _tree_entries(oid_size).findall(data):
        file = known.get(entry)
        if file is None:
            mode, _, rest = entry.partition(b" ")
            name = rest[: -oid_size - 1]
            file = known[entry] = (
                # A name that is not UTF-8 as lensaudit shows one, with backslash escapes.
                (name.decode("utf-8", "backslashreplace"), entry[-oid_size:].hex())
                if mode.startswith(b"100") and name.lower().endswith(b".xml")
                else ()
            )
        if file:
            found[file[0]] = file[1]
    return found


def file_maps(
    git: Git, hashes: list[str], db_path: str, oid_size: int
) -> tuple[dict[str, dict[str, str]], set[str]]:
    """{commit: {file name: blob id}} of the database at each commit ({} if absent),
    and the commits where the path exists at all."""
    by_tree: dict[str, dict[str, str]] = {}
    entries: dict[bytes, tuple] = {}
    maps = {}
    present = set()
    requests = [f"{h}:{db_path}" for h in hashes]
    for commit, answer in zip(hashes, git.objects(requests), strict=True):
        if answer is None:
            maps[commit] = {}
            continue
        present.add(commit)
        oid, kind, data = answer
        if kind == "tree":
            if oid not in by_tree:
                by_tree[oid] = _tree_files(data, oid_size, entries)
            maps[commit] = by_tree[oid]
        elif kind == "blob":
            maps[commit] = {display_path(PurePosixPath(db_path).name): oid}
        else:
            maps[commit] = {}
    return maps, present
