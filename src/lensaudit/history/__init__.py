"""The audit of every revision of a Lensfun database kept in git.

:func:`audit_history` walks the commits of a repository oldest to newest and,
for each commit that changes the database (``data/db`` by default), counts
its distortion entries per model, those with a finite r_max and those that
fold inside their own image (in Hugin units, and in the paper's mixed units).
For the newest revision it names the commit that introduced the current
coefficients of every entry with a finite r_max.

Revisions are read through git's plumbing (``git log``, ``git cat-file``):
nothing is checked out and the work tree, the index and the refs are left
as they are. Each distinct file version (blob) is parsed and audited once,
and the result can be kept in an on-disk cache between runs, so a history of
thousands of commits costs about as much as its distinct file versions.

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
commit, and their contents), :mod:`.parse` (each file version as plain data,
piece by piece, in worker processes), :mod:`.audit` (each distinct model
audited once, counted per file version and revision), :mod:`.introduced`
(who introduced each entry) and :mod:`.outputs` (CSV and the trend figure);
:mod:`.results` holds what they give and :mod:`.cache` what is kept between
runs.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from .. import loader
from . import audit, blobs, commits, introduced, parse
from .cache import HistoryCache, default_cache_dir
from .commits import Commit, HistoryError
from .outputs import PAPER_SNAPSHOT, trend_figure
from .parse import entry_identity
from .results import (
    COUNT_COLUMNS,
    HISTORY_COLUMNS,
    INTRODUCED_COLUMNS,
    MODELS,
    History,
    IntroducedEntry,
    Revision,
)

# numpy (and the modules that need it) is imported where used: file versions
# are parsed in forked worker processes, which must be started before numpy
# starts its threads.
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
    "default_cache_dir",
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
    cache_dir: str | os.PathLike[str] | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> History:
    """Audit every revision of the database at ``path`` in a git repository.

    ``path`` is a directory of ``*.xml`` files (or one XML file), relative to
    the repository root. Commits are those of ``git log REVISION`` between
    ``since`` and ``until`` (ISO 8601 dates, committer time; a bare date
    means the whole day), or only the first-parent line with
    ``first_parent``. ``cache_dir`` keeps file-version audits between runs.
    ``progress(done, total)`` is called as file versions are parsed.

    Raises :class:`HistoryError` when git cannot run, the directory is not a
    repository, the revision or a date is invalid, no commit is selected, or
    the database path holds no XML file at any selected commit.
    """
    started = time.perf_counter()
    started = time.perf_counter()
    db_path = commits.normalized_path(path)
    git = commits.Git(repository)
    tip = git.resolve_commit(revision)
    filters = commits.selection(since, until)
    warnings: list[str] = []
    auditor = audit.Auditor()
    cache = HistoryCache(Path(cache_dir), auditor.idents, warnings) if cache_dir else None
    # A commit names its whole history: the same selection of it gives the same audit.
    run_key = repr((tip, db_path, filters, first_parent, time.tzname, time.timezone))
    stored = cache.get_run(run_key) if cache else None
    if stored is not None:
        return replace(
            stored,
            repository=Path(repository),
            revision=revision,
            blobs_parsed=0,
            blobs_cached=stored.blobs,
            seconds=time.perf_counter() - started,
            warnings=warnings,
        )

    # 1. The commits, and the file versions of the database at each.
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

    # 2. Each file version parsed and audited once. The newest revision's files
    # are parsed even when cached: their entries are reported in full.
    newest = selected[position[mainline[0]]]
    newest_files = files[newest.hash]
    every_blob = sorted({blob for m in files.values() for blob in m.values()})
    names = {blob: name for m in files.values() for name, blob in m.items()}
    names.update((blob, name) for name, blob in newest_files.items())
    audits = cache.get(every_blob) if cache else {}
    cached = len(audits)
    keep = set(newest_files.values())
    to_parse = [b for b in every_blob if b not in audits or b in keep]
    sizes = git.object_sizes(to_parse)
    missing = next((blob for blob, size in zip(to_parse, sizes, strict=True) if size is None), None)
    if missing is not None:
        raise HistoryError(f"git cannot read object {missing} of {git.repository}")
    reader = git.blob_reader()
    try:
        parsed = parse.parse_blobs(to_parse, sizes, names, keep, auditor, reader, progress)
    finally:
        reader.close()
    fresh = auditor.finish(parsed)
    if cache:
        cache.put({blob: a for blob, a in fresh.items() if blob not in audits}, every_blob)
    audits.update(fresh)

    # 3. The revisions, walking parents before children, and who introduced what.
    states, revisions = introduced.walk(
        selected, outside, files, first_parent, set(mainline), audits
    )
    result = History(
        repository=Path(repository),
        path=db_path,
        revision=revision,
        first_parent=first_parent,
        revisions=revisions,
        newest=newest,
        introduced=introduced.introduced_entries(
            newest_files, states[newest.hash], parsed, auditor, selected
        ),
        commits=len(selected),
        blobs=len(every_blob),
        blobs_parsed=len(parsed),
        blobs_cached=cached,
        seconds=time.perf_counter() - started,
        warnings=warnings,
    )
    if cache:
        cache.put_run(run_key, result)
    return result


def audit_revision(
    repository: str | os.PathLike[str], revision: str = "HEAD", path: str = DEFAULT_PATH
) -> Audit:
    """Audit the database at one revision, read through git, from scratch.

    The usual :class:`lensaudit.pipeline.Audit` of the ``*.xml`` files at
    ``path`` in ``revision``; files are named relative to ``path``. Raises
    :class:`HistoryError` when the revision or the path does not exist.
    """
    from ..database import DatabaseSource
    from ..loader import DistortionEntry, SourceFile
    from ..pipeline import audit_entries

    db_path = commits.normalized_path(path)
    git = commits.Git(repository)
    commit = git.resolve_commit(revision)
    maps, present = blobs.file_maps(git, [commit], db_path, len(commit) // 2)
    files = maps[commit]
    if not files:
        problem = "holds no *.xml file" if present else "does not exist"
        raise HistoryError(f"{db_path or '.'!r} {problem} at {revision}")
    names = sorted(files)
    entries: list[DistortionEntry] = []
    sources = []
    for name, answer in zip(names, git.objects([files[n] for n in names]), strict=True):
        if answer is None:
            raise HistoryError(f"git cannot read {name} of {revision}")
        file_entries, error = loader.read_bytes(answer[2], name)
        entries.extend(file_entries)
        sources.append(
            SourceFile(name, Path(repository) / db_path / name, len(file_entries), error)
        )
    source = DatabaseSource(
        (Path(repository),), f"{db_path} at {revision} ({commit[:7]}) of {repository}"
    )
    return audit_entries(entries, source, sources)
