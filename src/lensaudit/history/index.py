"""The history's index: what the last run gave, in one small file beside the
one cache.

The files of the newest revision are kept by the one cache
(:class:`lensaudit.read.Cache`: a record per content, with the reader's
tables and the pipeline's metrics), as a scan of them would keep them. The
index keeps what a run made of the history, each entry under a name and a
key: the summary of every file version (``versions``: its error, counts
and the identities of its entries, not its tables), so that a run after a
new commit reads only the versions it adds; the last :class:`History`
(``run``, keyed by the commit, path and selection) and the trend figures
drawn from it (``trend``, keyed by what they show), so that the same run
again costs two small file reads. It is the directory ``history`` of the
cache directory (``--cache DIR``: of DIR), a file per name, so that an
entry is read or written without the others (the summaries are most of it).

A file starts with a fixed header and the fingerprint of the code that
wrote it (:func:`fingerprint`), then the BLAKE2b digest of its body, a
:mod:`marshal` pair ``(key, value)``; a damaged, truncated or foreign file
reads as no entry, and one that is not a regular file is not opened (a FIFO
would block). It is written whole to a temporary file and renamed. An index
that cannot be written gives one warning, never an error.
"""

from __future__ import annotations

import functools
import marshal
import os
from dataclasses import fields
from pathlib import Path

from .. import read
from ..read.paths import read_descriptor, read_file
from ..read.records import DistortionEntry
from ..writing import remove_abandoned, write_file
from .audit import BlobAudit, Interner
from .commits import Commit
from .results import COUNT_COLUMNS, FoldEvent, History, IntroducedEntry, Revision

try:  # BLAKE2 alone, as the one cache: hashlib would also load OpenSSL
    from _blake2 import blake2b
except ImportError:  # pragma: no cover - every CPython has _blake2
    from hashlib import blake2b

#: The index's file name, in the cache directory.
NAME = "history"
_MAGIC = b"lensaudit history index 2\n"
_EARLIER_MAGIC = b"lensaudit history index 1\n"
_DIGEST_SIZE = 16
#: The code that decides what a run gives, besides the reader's (which the
#: one cache's fingerprint covers).
_CODE = ("history/*.py", "solver/*.py", "pipeline.py", "columns.py")
#: Files of earlier layouts of the history's cache, removed when the index is written.
_LEGACY = ("history-*.cache", "history-*.sqlite3", "history-trend-*.png", "history-trend-*.svg")
_ERRORS = (OSError, ValueError, EOFError, TypeError, KeyError, IndexError)


def fingerprint() -> bytes:
    """What an index is valid for: the one cache's fingerprint (lensaudit's
    version and the reader's code) and the history's own code."""
    return read.cache.fingerprint() + _code_digest()


@functools.cache
def _code_digest() -> bytes:
    package = Path(__file__).resolve().parent.parent
    digest = blake2b(digest_size=_DIGEST_SIZE)
    for pattern in _CODE:
        for path in sorted(package.glob(pattern)):
            digest.update(path.name.encode() + b"\0" + path.read_bytes())
    return digest.digest()


def key_of(*texts: str) -> str:
    """A short key for what ``texts`` say together."""
    digest = blake2b(digest_size=_DIGEST_SIZE)
    for text in texts:
        data = text.encode("utf-8", "surrogatepass")
        digest.update(len(data).to_bytes(8, "little") + data)
    return digest.hexdigest()


def caches(cache: bool | str | os.PathLike[str] | None) -> tuple[read.Cache | None, Index | None]:
    """The one cache and the history's index that ``cache`` names: True for
    lensaudit's cache directory, a path for that directory, None or False
    for none."""
    if cache is None or cache is False:
        return None, None
    if cache is True:
        return read.Cache(), Index(read.cache.cache_dir() / NAME)
    return read.Cache(cache), Index(Path(cache) / NAME)


class Index:
    """The index directory at ``path``: :meth:`get` an entry, :meth:`put` one
    (written at once). Problems writing add a message to :attr:`warnings`."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.warnings: list[str] = []

    def get(self, name: str, key: str) -> object | None:
        """The value kept under ``name`` if it was kept for ``key``; else None."""
        try:
            data = read_file(self.path / name)  # never blocks on a FIFO put in its place
            head = len(_MAGIC) + 2 * _DIGEST_SIZE
            body = memoryview(data)[head + _DIGEST_SIZE :]
            if (
                data[: len(_MAGIC)] != _MAGIC
                or data[len(_MAGIC) : head] != fingerprint()
                or data[head : head + _DIGEST_SIZE]
                != blake2b(body, digest_size=_DIGEST_SIZE).digest()
            ):
                return None
            found = marshal.loads(body)
        except _ERRORS:
            return None
        if isinstance(found, tuple) and len(found) == 2 and found[0] == key:
            return found[1]
        return None

    def put(self, name: str, key: str, value: object) -> None:
        """Keep ``value`` (plain data) under ``name`` for ``key``, replacing what was there."""
        try:
            body = marshal.dumps((key, value))
            seal = blake2b(body, digest_size=_DIGEST_SIZE).digest()
            if self.path.is_file() and _earlier_layout(self.path):
                self.path.unlink()
            self.path.mkdir(parents=True, exist_ok=True)
            remove_abandoned(self.path)  # left by a run killed with SIGKILL
            # Its temporary file removed whatever ends the writing, SIGTERM included.
            write_file(self.path / name, _MAGIC + fingerprint() + seal + body)
            for pattern in _LEGACY:
                for stale in self.path.parent.glob(pattern):
                    stale.unlink(missing_ok=True)
        except (OSError, ValueError) as error:
            if not self.warnings:  # one line says it
                self.warnings.append(f"cache {self.path} not used: {error}")


def _earlier_layout(path: Path) -> bool:
    """Whether the file at ``path`` is the history's index of the earlier layout
    (one file): only that is removed in its place, no file of anyone else."""
    try:
        with open(read_descriptor(path), "rb") as stream:
            return stream.read(len(_EARLIER_MAGIC)) == _EARLIER_MAGIC
    except OSError:
        return False


#: The key of the file versions' summaries (the index's fingerprint covers their shape).
_VERSIONS_KEY = "summaries"


def audits_kept(index: Index | None, interner: Interner) -> dict[str, BlobAudit]:
    """The audits of the file versions of the last run, by blob, their
    identities interned by ``interner`` (none without an index, or in one
    that does not hold them)."""
    stored = index.get("versions", _VERSIONS_KEY) if index is not None else None
    if stored is None:
        return {}
    try:
        values, kept = stored  # type: ignore[misc]
        numbers = list(map(interner, values))
        same = numbers == list(range(len(numbers)))  # a new interner: numbers kept as they are
        found = {
            blob: BlobAudit(
                error,
                tuple(counts),
                idents if same else tuple(numbers[i] for i in idents),
                folding if same else tuple(numbers[i] for i in folding),
            )
            for blob, (error, counts, idents, folding) in kept.items()
        }
    except (TypeError, ValueError, IndexError, AttributeError):
        return {}
    if any(len(audit.counts) != len(COUNT_COLUMNS) for audit in found.values()):
        return {}
    return found


def keep_audits(index: Index, identities: list[tuple], audits: dict[str, BlobAudit]) -> None:
    """Keep the audits of a run's file versions (by blob), the identities their
    numbers stand for, in the index in place of the last run's."""
    kept = {
        blob: (audit.error, audit.counts, audit.idents, audit.folding)
        for blob, audit in audits.items()
    }
    index.put("versions", _VERSIONS_KEY, (identities, kept))


def _commit_data(commit: Commit | None) -> tuple | None:
    return None if commit is None else tuple(getattr(commit, f.name) for f in fields(Commit))


def history_data(history: History) -> tuple:
    """A history as marshal data (what the index keeps of a run)."""
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
        [
            (_commit_data(e.commit), e.event, e.identity, _commit_data(e.branch_commit))
            for e in history.events
        ],
    )


def history_from_data(data: tuple) -> History:
    """The history :func:`history_data` kept (repository and timings to be filled in).
    Raises TypeError or ValueError for data of another shape."""
    path, first_parent, revisions, newest, introduced, commits, blobs, events = data
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
        blobs_read=0,
        blobs_reused=blobs,
        seconds=0.0,
        events=[
            FoldEvent(commit(c), event, identity, commit(b)) for c, event, identity, b in events
        ],
    )
