"""The audit of every revision of a Lensfun database kept in git.

:func:`audit_history` walks the commits of a repository oldest to newest and,
for each commit that changes the database (``data/db`` by default), counts
its distortion entries per model, those with a finite r_max and those that
fold inside their own image (in Hugin units, and in the paper's mixed units).
For the newest revision it names the commit that introduced the current
coefficients of every entry with a finite r_max.

Revisions are read through git's plumbing (``git log``, ``git cat-file``):
nothing is checked out and the work tree, the index and the refs are left
as they are. Each distinct file version (blob) is read once, through
:mod:`lensaudit.read` as any database file is, with the one cache
(:class:`lensaudit.read.Cache`), which keeps its tables and metrics by
content between runs and between commands; the history's index keeps the
last run whole (:mod:`.index`).

Entries are followed across revisions by identity, not by line: maker, lens
name, crop factor, model and focal length, plus the coefficients. An entry's
coefficients were introduced by the oldest commit in an unbroken chain of
ancestors holding an identical entry (through the first parent that holds
one, like ``git blame``), so that moving a lens to another file, renaming a
file or reformatting it introduces nothing. While a file version is not
well-formed XML, its entries are taken to be those of the file's last
readable version, so that the commit which repairs the file introduces only
what it really changes.

The audit is a pipeline of stages, one module each: :mod:`.commits` (the
commits selected, through git), :mod:`.blobs` (the file versions of each
commit), :mod:`.versions` (each file version read through
:mod:`lensaudit.read` and summarized, on every core), :mod:`.audit` (the
summaries counted per revision), :mod:`.introduced` (who introduced each
entry) and :mod:`.outputs` (CSV and the trend figure); :mod:`.results`
holds what they give and :mod:`.index` what is kept of a run.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .. import read
from ..pipeline import Audit, audit_database, file_metrics
from . import blobs, commits, events, introduced, versions
from .audit import Interner
from .commits import Commit, HistoryError
from .index import Index, audits_kept, caches, history_data, history_from_data, keep_audits
from .outputs import PAPER_SNAPSHOT, trend_figure
from .results import (
    COUNT_COLUMNS,
    HISTORY_COLUMNS,
    INTRODUCED_COLUMNS,
    MODELS,
    History,
    IntroducedEntry,
    Revision,
)
from .versions import entry_identity

if TYPE_CHECKING:
    from ..pipeline import Audit

__all__ = [
    "COUNT_COLUMNS",
    "DEFAULT_PATH",
    "HISTORY_COLUMNS",
    "INTRODUCED_COLUMNS",
    "MODELS",
    "PAPER_SNAPSHOT",
    "Commit",
    "History",
    "HistoryError",
    "IntroducedEntry",
    "Revision",
    "audit_history",
    "audit_revision",
    "entry_identity",
    "trend_figure",
]

#: Where the database lives in the Lensfun repository.
DEFAULT_PATH = "data/db"


def audit_history(
    repository: str | os.PathLike[str],
    path: str = DEFAULT_PATH,
    *,
    revision: str = "HEAD",
    since: str | None = None,
    until: str | None = None,
    first_parent: bool = False,
    cache: bool | str | os.PathLike[str] | None = None,
    progress: Callable[[int, int], None] | None = None,
    revisions_read: Callable[[Commit, list[Revision]], object] | None = None,
) -> History:
    """Audit every revision of the database at ``path`` in a git repository.

    ``path`` is a directory of ``*.xml`` files (or one XML file), relative to
    the repository root. Commits are those of ``git log REVISION`` between
    ``since`` and ``until`` (ISO 8601 dates, committer time; a bare date
    means the whole day), or only the first-parent line with
    ``first_parent``. ``cache`` is the one cache's directory, or True for
    lensaudit's (see :func:`lensaudit.read.cache.cache_dir`): file versions
    read are kept there, and the run in the history's index. ``progress(done,
    total)`` is called as file versions are read; ``revisions_read(newest,
    revisions)`` with the newest commit and the revisions of the result as
    soon as they are counted, before the introducers of the newest entries
    and the fold events are worked out (not for a run the index keeps whole).

    Raises :class:`HistoryError` when git cannot run, the directory is not a
    repository, the revision or a date is invalid, no commit is selected, or
    the database path holds no XML file at any selected commit.
    """
    started = time.perf_counter()
    db_path = commits.normalized_path(path)
    git = commits.Git(repository)
    tip = git.resolve_commit(revision)
    filters = commits.selection(since, until)
    store, index = caches(cache)
    warnings = index.warnings if index is not None else []
    # A commit and where its history stops (a shallow clone, grafts) name that history.
    boundary = git.boundary()
    run_key = repr((tip, boundary, db_path, filters, first_parent, time.tzname, time.timezone))
    found = _last_run(index, run_key)
    if found is not None:
        again = {"repository": Path(repository), "revision": revision, "warnings": warnings}
        return replace(found, seconds=time.perf_counter() - started, **again)
    # 1. The commits, and the file versions of the database at each.
    selected, mainline, outside, files = _commits(
        git, tip, filters, first_parent, revision, db_path
    )
    # 2. Each file version read once; 3. the revisions, and who introduced what.
    by_hash = {c.hash: c for c in selected}
    newest = by_hash[mainline[0]]
    full, audits, reused, identities = _read_versions(
        git, files, files[newest.hash], (store, index), progress
    )
    revisions = introduced.revisions(selected, files, first_parent, set(mainline), audits)
    if revisions_read is not None:
        revisions_read(newest, revisions)
    if index is not None:  # kept once the revisions are handed over
        keep_audits(index, identities, audits)
    result = History(
        repository=Path(repository),
        path=db_path,
        revision=revision,
        first_parent=first_parent,
        revisions=revisions,
        newest=newest,
        introduced=_introducers(
            (selected, outside, newest.hash), files, first_parent, (audits, identities), full
        ),
        commits=len(selected),
        blobs=len(audits),
        blobs_read=len(audits) - reused,
        blobs_reused=reused,
        seconds=time.perf_counter() - started,
        warnings=warnings,
        events=_events(git, mainline, by_hash, files, audits, identities),
    )
    if index is not None:
        index.put("run", run_key, history_data(result))
    return result


def _introducers(
    walked: tuple[list[Commit], list[str], str],
    files: dict[str, dict[str, str]],
    first_parent: bool,
    audited: tuple[dict[str, Any], list[tuple]],
    full: dict[str, tuple[read.FileTables, dict[str, list]]],
) -> list[IntroducedEntry]:
    """The entries of the newest commit with a finite r_max, each with the
    commit that introduced it: from the commits selected, their parents
    outside the selection and the newest commit (``walked``), the audits of
    every file version and the identities their numbers stand for
    (``audited``), and the newest files read in full (``full``, by blob)."""
    selected, outside, newest = walked
    audits, identities = audited
    states = introduced.walk(selected, outside, files, first_parent, audits, identities)
    return introduced.introduced_entries(
        {name: full[blob] for name, blob in files[newest].items()}, states[newest], selected
    )


def _events(
    git: commits.Git,
    mainline: list[str],
    by_hash: dict[str, Commit],
    files: dict[str, dict[str, str]],
    audits: dict[str, Any],
    identities: list,
) -> list:
    """Where entries start and stop folding along the first-parent line."""
    line = [by_hash[h] for h in reversed(mainline)]
    return events.fold_events(
        line, files, audits, identities, lambda merge: _merged(git, merge, by_hash)
    )


def _merged(git: commits.Git, merge: Commit, by_hash: dict[str, Commit]) -> list[Commit]:
    """The selected commits a merge brings in, oldest first."""
    hashes = git.run(
        "rev-list", "--reverse", "--topo-order", merge.parents[1], f"^{merge.parents[0]}"
    )
    return [by_hash[h] for h in hashes.split() if h in by_hash]


def _commits(
    git: commits.Git,
    tip: str,
    filters: Any,
    first_parent: bool,
    revision: str,
    db_path: str,
) -> tuple[list, list, list[str], dict[str, dict[str, str]]]:
    """The commits selected, the mainline, the parents outside the selection,
    and the file versions (name -> blob) of the database at each of them."""
    selected, mainline = commits.log(git, tip, filters, first_parent, revision)
    position = {c.hash: i for i, c in enumerate(selected)}
    outside = sorted(
        {p for c in selected for p in introduced.parents_of(c, first_parent) if p not in position}
    )
    files, present = blobs.file_maps(
        git, [c.hash for c in selected] + outside, db_path, len(tip) // 2
    )
    if not any(files[c.hash] for c in selected):
        problem = "holds no *.xml file" if present & position.keys() else "does not exist"
        raise HistoryError(
            f"{db_path or '.'!r} {problem} at any of the {len(selected):,} "
            f"commits of {revision} selected"
        )
    return selected, mainline, outside, files


def _last_run(index: Any, run_key: str) -> History | None:
    """The history the index keeps for this run, or None."""
    stored = index.get("run", run_key) if index is not None else None
    if stored is None:
        return None
    try:
        return history_from_data(stored)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return None  # not what this code keeps: audited again


def _read_versions(
    git: commits.Git,
    files: dict[str, dict[str, str]],
    newest_files: dict[str, str],
    kept_in: tuple[read.Cache | None, Index | None],
    progress: Callable[[int, int], None] | None,
) -> tuple[dict[str, tuple[read.FileTables, dict[str, list]]], dict[str, Any], int, list]:
    """Each file version read once: the newest revision's in full, through the
    one cache (its entries are reported), the others taken from the index's
    audits of the last run, or read and summarized on every core. (The
    newest files' tables and metrics by blob, the audit of every version by
    blob, how many were taken from the index, and the identities the
    audits' numbers stand for.)"""
    store, index = kept_in
    every_blob = sorted({blob for m in files.values() for blob in m.values()})
    names = {blob: name for m in files.values() for name, blob in m.items()}
    names.update((blob, name) for name, blob in newest_files.items())
    interner = Interner()
    kept = audits_kept(index, interner)
    full_set = set(newest_files.values())
    newest = sorted(full_set)
    reused = [blob for blob in every_blob if blob in kept and blob not in full_set]
    audits = {blob: kept[blob] for blob in reused}
    if progress is not None:
        progress(len(audits), len(every_blob))
    full: dict[str, tuple[read.FileTables, dict[str, list]]] = {}

    def read_newest() -> None:  # by this process, while the others read the rest
        full.update(_read_in_full(git, newest, names, store))

    # In the order the commits bring them (oldest first): git reads a version
    # most cheaply after the one it is stored as a change of.
    in_order = dict.fromkeys(blob for m in files.values() for blob in m.values())
    audits |= versions.read_versions(
        git,
        [blob for blob in in_order if blob not in audits and blob not in full_set],
        names,
        interner,
        None
        if progress is None
        else lambda done: progress(len(reused) + len(full) + done, len(every_blob)),
        read_newest,
    )
    audits.update(
        (blob, interner.audit(*versions.summarize(*found))) for blob, found in full.items()
    )
    audits = {blob: audits[blob] for blob in every_blob}
    return full, audits, len(reused), interner.values


def _read_in_full(
    git: commits.Git, blobs: list[str], names: dict[str, str], cache: read.Cache | None
) -> dict[str, tuple[read.FileTables, dict[str, list]]]:
    """{blob: (tables, metric columns)} of file versions, read through the one cache."""
    contents = [(data, names[blob], None) for blob, data in _contents(git, blobs)]
    found = {
        blob: (tables, file_metrics(tables, cache))
        for blob, tables in zip(blobs, read.read_contents(contents, cache), strict=True)
    }
    if cache is not None:
        cache.save()
    return found


def _contents(git: commits.Git, blobs: list[str]) -> list[tuple[str, bytes]]:
    """(blob, content) of each of ``blobs``; HistoryError if git cannot give one."""
    found = []
    for blob, answer in zip(blobs, git.objects(blobs), strict=True):
        if answer is None:
            raise HistoryError(f"git cannot read object {blob} of {git.repository}")
        found.append((blob, answer[2]))
    return found


def audit_revision(
    repository: str | os.PathLike[str], revision: str = "HEAD", path: str = DEFAULT_PATH
) -> Audit:
    """Audit the database at one revision, read through git, from scratch.

    The usual :class:`lensaudit.pipeline.Audit` of the ``*.xml`` files at
    ``path`` in ``revision``; files are named relative to ``path``. Raises
    :class:`HistoryError` when the revision or the path does not exist.
    """
    db_path = commits.normalized_path(path)
    git = commits.Git(repository)
    commit = git.resolve_commit(revision)
    maps, present = blobs.file_maps(git, [commit], db_path, len(commit) // 2)
    files = maps[commit]
    if not files:
        problem = "holds no *.xml file" if present else "does not exist"
        raise HistoryError(f"{db_path or '.'!r} {problem} at {revision}")
    names = sorted(files)
    contents = _contents(git, [files[name] for name in names])
    found = read.read_contents(
        [
            (data, name, Path(repository) / db_path / name)
            for name, (_, data) in zip(names, contents, strict=True)
        ]
    )
    source = read.DatabaseSource(
        (Path(repository),), f"{db_path} at {revision} ({commit[:7]}) of {repository}"
    )
    return audit_database(read.Database(source, found))
