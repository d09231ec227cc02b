"""Stage 2, blobs: which file versions (git blobs) make up the database at each
commit, through one ``git cat-file --batch`` (their contents are read by the
parse stage, in whichever process parses each)."""

from __future__ import annotations

import functools
import re
from pathlib import PurePosixPath

from ..read.paths import display_path, loaded_name
from .commits import Git


@functools.cache
def _tree_entries(oid_size: int) -> re.Pattern[bytes]:
    """The entries of a raw git tree object: mode, name, object id (``oid_size``
    bytes). Each entry starts where the one before it ends, so that the
    pattern's matches, one after another, are the entries."""
    return re.compile(rb"[0-7]+ [^\0]*\0.{%d}" % oid_size, re.DOTALL)


def _tree_files(
    data: bytes, oid_size: int, known: dict[bytes, tuple]
) -> tuple[dict[str, str], list[tuple[str, str]]]:
    """{name: blob id} of the files liblensfun reads directly in a raw git tree
    object (:func:`lensaudit.read.paths.loaded_name`), and (name, tree id) of
    its subdirectories so named, which liblensfun reads in turn; ``known``
    keeps what each entry met is (the trees of a history share nearly all
    their entries).

    Symbolic links and submodules are not read (a link's target is a path
    in a checkout, not in git's objects).
    """
    found = {}
    subtrees = []
    for entry in _tree_entries(oid_size).findall(data):
        item = known.get(entry)
        if item is None:
            mode, _, rest = entry.partition(b" ")
            # A name that is not UTF-8 as lensaudit shows one, with backslash escapes.
            name = rest[: -oid_size - 1].decode("utf-8", "backslashreplace")
            kind = "file" if mode.startswith(b"100") else "tree" if mode == b"40000" else ""
            loaded = kind and loaded_name(name)
            item = known[entry] = (kind, name, entry[-oid_size:].hex()) if loaded else ()
        if item and item[0] == "file":
            found[item[1]] = item[2]
        elif item:
            subtrees.append(item[1:])
    return found, subtrees


def _database_files(
    git: Git, tree: tuple[str, bytes], oid_size: int, known: dict, by_tree: dict
) -> dict[str, str]:
    """{name relative to the tree: blob id} of the files liblensfun reads from
    a git tree (``tree``: its id and raw content), its subdirectories named
    ``*.xml`` included, in name order; ``by_tree`` keeps each tree's."""
    oid, data = tree
    if oid not in by_tree:
        files, subtrees = _tree_files(data, oid_size, known)
        if subtrees:
            answers = list(git.objects([sub for _, sub in subtrees]))
            for (name, _), answer in zip(subtrees, answers, strict=True):
                if answer is not None and answer[1] == "tree":
                    inner = _database_files(git, (answer[0], answer[2]), oid_size, known, by_tree)
                    files.update((f"{name}/{path}", blob) for path, blob in inner.items())
            files = dict(sorted(files.items()))
        by_tree[oid] = files
    return by_tree[oid]


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
            maps[commit] = _database_files(git, (oid, data), oid_size, entries, by_tree)
        elif kind == "blob":
            maps[commit] = {display_path(PurePosixPath(db_path).name): oid}
        else:
            maps[commit] = {}
    return maps, present
