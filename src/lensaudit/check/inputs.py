"""The first stage of a check: what is checked and what it is compared with.

The database's files are found and read from disk into :class:`Source`
records by :mod:`lensaudit.read.paths`, as ``lensaudit scan`` finds and reads
them; a baseline is a directory, or a git revision read with ``git ls-tree``
and ``git cat-file`` (:mod:`lensaudit.git`), so that the work tree is never
touched.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, replace
from functools import cached_property
from pathlib import Path

from .. import git as gitlayer
from .. import read as reader
from ..read.paths import (
    database_directory,
    display_path,
    expand,
    loaded_name,
    read_file,
    reason,
)
from ..read.records import STATUS_OK, LoadError
from .result import CheckError

#: How many commits that changed a file are searched for a version that parses,
#: when the baseline's version does not.
HISTORY_DEPTH = 50


@dataclass(frozen=True)
class GitOrigin:
    """Where a file of a git baseline comes from: repository, commit, path in it."""

    repository: Path
    commit: str
    path: str


@dataclass(frozen=True)
class Source:
    """The bytes of one database file, wherever they come from.

    ``name`` identifies the file across revisions (relative to the database
    path given), ``display`` is how it is shown, ``path`` is where it is on
    disk (None for a file read from git, which has an ``origin`` instead).
    ``data`` is None when the file could not be read, and ``error`` says why;
    once parsed, a file on disk keeps no bytes (``data`` is then b"").
    """

    name: str
    display: str
    path: Path | None
    data: bytes | None
    error: str = ""
    origin: GitOrigin | None = None

    @cached_property
    def file_name(self) -> str:
        """The name without directories: what matches a file across revisions."""
        return Path(self.name).name


def sources_from_paths(paths: Iterable[str | os.PathLike[str]]) -> list[Source]:
    """The XML files that directories and files designate, read into memory.

    The files are those ``lensaudit scan`` reads (:func:`lensaudit.read.paths.expand`):
    in a directory, those liblensfun reads there (``*.xml``, and the files of
    subdirectories so named), named relative to it and shown under the
    directory as given; and files given directly, named as given.
    Raises :class:`CheckError` for a path that does not exist, is neither a
    file nor a directory, or is a directory without XML files; a file that
    cannot be read becomes a :class:`Source` without data.
    """
    sources: list[Source] = []
    seen: set[Path] = set()
    for given in map(Path, paths):
        try:
            targets = expand([given])
        except LoadError as error:
            raise CheckError(str(error)) from None
        directory = Path(display_path(given)) if given.is_dir() else None
        for path, name in targets:
            if path in seen:  # the same file named twice is read once
                continue
            seen.add(path)
            display = name if directory is None else str(directory / name)
            try:
                data, error = read_file(path), ""
            except OSError as os_error:
                data, error = None, f"cannot read file: {reason(os_error)}"
            sources.append(Source(name, display, path, data, error))
    return sources


def baseline_label(
    baseline: str | bytes | os.PathLike[str], paths: Sequence[str | os.PathLike[str]]
) -> str:
    """``baseline`` as text, refused with a :class:`CheckError` where it cannot
    tell what a change adds: empty or blank (what ``--baseline "$BASE"`` gives
    with BASE unset, which would be read as the working directory), or a
    directory or file on disk holding one of the files checked, by any name
    (a link, ``.``, the checkout whose data/db is checked, a hard link), whose
    findings would all be known. A git revision is never the files on disk.
    """
    label = os.fsdecode(baseline)
    if not label.strip():
        raise CheckError(
            f"--baseline {label!r} is blank (an unset variable?): give a git revision "
            "such as origin/master or HEAD, or a directory of the database before the change"
        )
    given = Path(label)
    if not given.exists():
        return label
    try:
        before = _identities(expand([database_directory(given) if given.is_dir() else given]))
        same = before & _identities(expand(paths))
    except LoadError:
        return label  # reading the baseline says what is wrong with it
    if same:
        raise CheckError(
            f"--baseline {display_path(label)} holds the very files checked, so every "
            "finding would be known: give a git revision such as HEAD or origin/master, "
            "or a copy of the database before the change"
        )
    return label


def _identities(files: Iterable[tuple[Path, str]]) -> set[tuple[int, int]]:
    """(device, inode) of each file that exists: the same file by any path."""
    found = set()
    for path, _ in files:
        try:
            info = os.stat(path)
        except OSError:
            continue
        found.add((info.st_dev, info.st_ino))
    return found


def baseline_sources(baseline: str, paths: Sequence[str | os.PathLike[str]]) -> list[Source]:
    """The baseline's files: ``baseline`` itself if it exists on disk (a
    Lensfun checkout meaning its ``data/db``), else the same ``paths`` at git
    revision ``baseline``."""
    given = Path(baseline)
    if given.exists():
        return sources_from_paths([database_directory(given) if given.is_dir() else given])
    return sources_from_git(paths, baseline)


def _git_call(call, *arguments):
    """``call(*arguments)`` of :mod:`lensaudit.git`; git that cannot run at all
    is a :class:`CheckError`."""
    try:
        return call(*arguments)
    except gitlayer.GitUnavailable as error:
        raise CheckError(f"cannot run git to read the baseline: {error}") from None


def sources_from_git(paths: Sequence[str | os.PathLike[str]], revision: str) -> list[Source]:
    """The files ``paths`` designate, as they are at git ``revision``.

    Read with ``git ls-tree`` and ``git cat-file --batch`` from the
    repository holding each path, without touching its work tree or index.
    In a directory, the files liblensfun reads there, as on disk; symbolic
    links are not followed. A path that did not exist at that revision
    contributes no file.
    """
    sources: list[Source] = []
    for given in map(Path, paths):
        directory = given if given.is_dir() else given.parent
        try:
            top = _git_call(gitlayer.top_level, directory)
        except gitlayer.GitError:
            raise CheckError(
                f"--baseline {revision}: not an existing directory, and "
                f"{given} is not inside a git repository"
            ) from None
        try:
            commit = _git_call(gitlayer.resolve_commit, top, revision)
        except gitlayer.GitError:
            raise CheckError(
                f"--baseline {revision}: not an existing directory, nor a "
                f"revision of the git repository at {top}"
            ) from None
        relative = Path(os.path.relpath(given.resolve(), top.resolve())).as_posix()
        if given.is_dir():
            spec = [] if relative == "." else [relative + "/"]
        else:
            spec = [relative]
        try:
            listing = _git_call(gitlayer.list_tree, top, commit, spec, given.is_dir())
        except gitlayer.GitError as error:
            raise CheckError(f"--baseline {revision}: cannot list {given}: {error}") from None
        blobs = []
        for item in listing:
            if item.type != "blob" or item.mode not in ("100644", "100755"):
                continue
            # In a directory, what liblensfun reads there: names relative to it.
            name = item.path[len(spec[0]) :] if spec else item.path
            if given.is_dir() and not all(map(loaded_name, name.split("/"))):
                continue
            blobs.append((name if given.is_dir() else str(given), item.oid, item.path))
        blobs.sort()
        try:
            contents = _cat_file([oid.encode() for _, oid, _ in blobs], top)
        except gitlayer.GitError as error:
            raise CheckError(f"--baseline {revision}: cannot read {given}: {error}") from None
        for (name, _, repository_path), data in zip(blobs, contents, strict=True):
            if data is None:
                raise CheckError(f"--baseline {revision}: cannot read {name}: object missing")
            origin = GitOrigin(top, commit, repository_path)
            sources.append(Source(name, f"{revision}:{name}", None, data, origin=origin))
    return sources


def _cat_file(objects: list[bytes], repository: Path) -> list[bytes | None]:
    """Contents of the given blobs (ids or ``rev:path``), through one
    ``git cat-file --batch``; None for an object that does not exist or is
    not a blob."""
    return [
        answer[2] if answer is not None and answer[1] == "blob" else None
        for answer in _git_call(lambda: list(gitlayer.objects(repository, objects)))
    ]


def last_readable(
    source: Source, depth: int = HISTORY_DEPTH, cache: reader.Cache | None = None
) -> tuple[Source, str] | None:
    """The newest version of a git baseline's file that the reader reads as a
    database (status ``ok``), among the last ``depth`` commits that changed
    it, and that commit's id. What is read is kept in ``cache``, if given."""
    origin = source.origin
    if origin is None:
        return None
    try:
        commits = _git_call(gitlayer.log, origin.repository, origin.commit, origin.path, depth)
        contents = _cat_file([f"{c}:{origin.path}".encode() for c in commits], origin.repository)
    except (gitlayer.GitError, UnicodeDecodeError):
        return None
    tried: set[bytes] = {source.data or b""}
    for commit, data in zip(commits, contents, strict=True):
        if data is None or data in tried:
            continue
        tried.add(data)
        tables = reader.read_bytes(
            data, source.display, cache=cache, calibrations=True, refusals=True
        )
        if tables.status == STATUS_OK:
            return replace(source, data=data, origin=replace(origin, commit=commit)), commit
    return None
