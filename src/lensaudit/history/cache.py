"""The history's cache: audits of file versions, keyed by blob id (a git blob
id is a digest of the content), and the last run, in store files of
lensaudit's cache directory (:mod:`lensaudit.store`, bounded with the parse
cache's files by :data:`lensaudit.cache.MAX_CACHE_FILES` and
:data:`lensaudit.cache.MAX_CACHE_BYTES`).

``history-blobs.cache`` holds ``(identities, records)``: every distinct entry
identity once, and per blob id its file error, :data:`COUNT_COLUMNS` and the
indices of its audited entries' identities (a block of 32-bit integers).
``history-run.cache`` holds the key of the last run and its :class:`History`
as plain data. Both are tied to :func:`fingerprint`: a file written by other
code, damaged or truncated reads as no file, and the history is computed
again. A directory that cannot be used gives a warning, never an error.
"""

from __future__ import annotations

import marshal
from array import array
from collections.abc import Collection
from dataclasses import fields
from pathlib import Path
from typing import TYPE_CHECKING

from .. import __version__
from ..loader import DistortionEntry
from .audit import BlobAudit, Interner
from .commits import Commit
from .results import COUNT_COLUMNS, History, IntroducedEntry, Revision

if TYPE_CHECKING:
    from ..store import RecordFile

_KIND = "history"
#: Files of earlier layouts of this cache, removed when seen.
_LEGACY = ("history-*.sqlite3", "history-trend-*.png", "history-trend-*.svg")
_INDEX = "I"  # array type of identity indices


def default_cache_dir() -> Path:
    """lensaudit's cache directory (see :func:`lensaudit.cache.cache_dir`)."""
    from ..cache import cache_dir

    return cache_dir()


#: The code that decides what a file version holds: how it is read and
#: audited, and the history's own stages.
_CODE = ("loader.py", "normalizer.py", "solver.py", "metrics.py", "history/*.py")


def fingerprint() -> str:
    """lensaudit's version and the code that decides what a file version holds.

    A cached audit is valid only for the code that made it; the version alone
    would not change while that code does. The files are read, not imported:
    importing the solver would start numpy's threads before the parsing
    workers are forked.
    """
    from ..store import code_digest

    return f"{__version__}-{code_digest(Path(__file__).parent.parent, _CODE)}"


def store_format() -> bytes:
    """What the history's store files are valid for: the code and the record layout."""
    entry = " ".join(DistortionEntry._fields)
    return f"lensaudit history 1 {fingerprint()} {' '.join(COUNT_COLUMNS)} {entry}".encode()


class HistoryCache:
    """The history's store files in ``directory``; blob audits are read with
    identities interned by ``interner``. Any problem writing them means working
    without them, with one message added to ``warnings``."""

    def __init__(self, directory: Path, interner: Interner, warnings: list[str]) -> None:
        from ..cache import record_file

        self.interner = interner
        self.warnings = warnings
        self.stored: dict[str, BlobAudit] = {}
        fmt = store_format()
        self.blobs_file = record_file(_KIND, "blobs", fmt, directory)
        self.run_file = record_file(_KIND, "run", fmt, directory)
        self.usable = True
        try:
            directory.mkdir(parents=True, exist_ok=True)
            for pattern in _LEGACY:
                for stale in directory.glob(pattern):
                    stale.unlink(missing_ok=True)
        except OSError as error:
            self._disable(self.blobs_file.path, error)

    def _disable(self, path: Path, error: Exception) -> None:
        self.warnings.append(f"cache {path} not used: {error}")
        self.usable = False

    def get_run(self, key: str) -> History | None:
        """The history the last run gave, if its key is ``key``; else None."""
        from ..cache import RECORD_ERRORS

        if not self.usable:
            return None
        try:
            stored_key, data = self.run_file.read()  # type: ignore[misc]
            return history_from_data(data) if stored_key == key else None
        except RECORD_ERRORS:
            return None

    def put_run(self, key: str, history: History) -> None:
        """Keep the history of a run; only the latest run is kept."""
        if self.usable:
            self._write(self.run_file, marshal.dumps((key, history_data(history))))

    def get(self, oids: Collection[str]) -> dict[str, BlobAudit]:
        """The stored audits of the file versions ``oids`` (those held)."""
        from ..cache import RECORD_ERRORS

        if not self.usable:
            return {}
        try:
            self.stored = self._decode(self.blobs_file.read())
        except RECORD_ERRORS:
            self.stored = {}
        return {oid: self.stored[oid] for oid in oids if oid in self.stored}

    def _decode(self, value: object) -> dict[str, BlobAudit]:
        table, records = value  # type: ignore[misc]
        ids = [self.interner(identity) for identity in table]
        audits = {}
        for oid, (error, counts, indices) in records.items():
            if not (isinstance(oid, str) and isinstance(error, str)):
                raise TypeError("not a blob audit")
            if len(counts) != len(COUNT_COLUMNS):
                raise ValueError("not a blob audit")
            idents = tuple(map(ids.__getitem__, array(_INDEX, indices)))
            audits[oid] = BlobAudit(error, tuple(counts), idents)
        return audits

    def put(self, fresh: dict[str, BlobAudit], used: Collection[str]) -> None:
        """Keep the audits of new file versions beside those stored. When all of
        them would take more than half the cache's bound, only the file
        versions ``used`` by this run are kept."""
        if not self.usable or not fresh:
            return
        every = {**self.stored, **fresh}
        body = self._encode(every)
        if len(body) > self.blobs_file.max_bytes // 2:
            body = self._encode({oid: every[oid] for oid in used if oid in every})
        self._write(self.blobs_file, body)

    def _encode(self, audits: dict[str, BlobAudit]) -> bytes:
        index: dict[int, int] = {}  # interned identity -> its place in the table
        records = {
            oid: (
                audit.error,
                audit.counts,
                array(_INDEX, [index.setdefault(i, len(index)) for i in audit.idents]).tobytes(),
            )
            for oid, audit in audits.items()
        }
        values = self.interner.values
        return marshal.dumps(([values[i] for i in index], records))

    def _write(self, file: RecordFile, body: bytes) -> None:
        try:
            file.write_body(body)
        except (OSError, ValueError) as error:
            self._disable(file.path, error)


def _commit_data(commit: Commit | None) -> tuple | None:
    return None if commit is None else tuple(getattr(commit, f.name) for f in fields(Commit))


def history_data(history: History) -> tuple:
    """A history as marshal data (what a run's cache keeps)."""
    return (
        history.path,
        history.first_parent,
        [
            (_commit_data(r.commit), r.mainline, r.files, tuple(r.counts.values()), r.errors)
            for r in history.revisions
        ],
        _commit_data(history.newest),
        [
            (
                tuple(i.entry),
                i.r_max,
                i.d_max,
                i.r_normalized,
                i.r_normalized_paper,
                i.folds_in_image,
                _commit_data(i.commit),
            )
            for i in history.introduced
        ],
        history.commits,
        history.blobs,
    )


def history_from_data(data: tuple) -> History:
    """The history :func:`history_data` kept (repository and timings to be filled in)."""
    path, first_parent, revisions, newest, introduced, commits, blobs = data
    commit_of: dict[tuple, Commit] = {}

    def commit(values: tuple | None) -> Commit | None:
        if values is None:
            return None
        if values not in commit_of:
            commit_of[values] = Commit(*values)
        return commit_of[values]

    return History(
        repository=Path(),
        path=path,
        revision="",
        first_parent=first_parent,
        revisions=[
            Revision(
                commit(c), mainline, files, dict(zip(COUNT_COLUMNS, counts, strict=True)), errors
            )
            for c, mainline, files, counts, errors in revisions
        ],
        newest=commit(newest),
        introduced=[
            IntroducedEntry(DistortionEntry(*entry), *values, commit(c))
            for entry, *values, c in introduced
        ],
        commits=commits,
        blobs=blobs,
        blobs_parsed=0,
        blobs_cached=blobs,
        seconds=0.0,
    )
