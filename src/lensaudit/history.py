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
"""

from __future__ import annotations

import hashlib
import marshal
import os
import re
import sqlite3
import time
import zlib
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field, fields, replace
from datetime import datetime
from operator import attrgetter
from pathlib import Path, PurePosixPath
from typing import TYPE_CHECKING, Any, TextIO

from . import __version__, loader
from . import git as gitlayer
from .columns import COLUMNS, FLOAT_COLUMNS
from .loader import MODEL_COEFFICIENTS, STATUS_OK, DistortionEntry

# numpy (and the modules that need it) is imported where used: file versions
# are parsed in forked worker processes, which must be started before numpy
# starts its threads.
if TYPE_CHECKING:
    import pandas
    from matplotlib.figure import Figure

    from . import metrics
    from .pipeline import Audit

#: Where the database lives in the Lensfun repository.
DEFAULT_PATH = "data/db"

#: The day the paper's snapshot of the Lensfun database was taken.
PAPER_SNAPSHOT = "2021-05-30"

MODELS = tuple(MODEL_COEFFICIENTS)

#: Counts kept per file version and summed per revision, in this order.
COUNT_COLUMNS = (
    "entries",
    "audited",
    "ptlens",
    "poly3",
    "poly5",
    "finite",
    "ptlens_finite",
    "poly3_finite",
    "poly5_finite",
    "folds_in_image",
    "folds_in_image_rectilinear",
    "folds_in_image_paper_units_rectilinear",
)

#: Columns of ``history.csv``: one row per commit that changes the database.
HISTORY_COLUMNS = (
    "commit",
    "date",
    "author_date",
    "author",
    "subject",
    "merge",
    "mainline",
    "files",
    "files_with_errors",
    *COUNT_COLUMNS[:2],
    "not_audited",
    *COUNT_COLUMNS[2:6],
    "share_finite",
    *COUNT_COLUMNS[6:],
    "errors",
)

#: Columns of ``introduced.csv``: one row per entry of the newest revision
#: with a finite r_max, and the commit that introduced its coefficients.
INTRODUCED_COLUMNS = tuple(
    name for name in COLUMNS
    if name not in {"real_focal", "tail", "r_corner", "r_corner_paper", "status", "message"}
) + ("commit", "date", "author", "subject")  # fmt: skip

_FLOAT_INTRODUCED = FLOAT_COLUMNS & frozenset(INTRODUCED_COLUMNS)

# Index into a history's commits meaning "already there before the first commit examined".
_BEFORE = -1


class HistoryError(Exception):
    """The history cannot be audited: no git, not a repository, no database in it."""


@dataclass(frozen=True)
class Commit:
    """A commit: full hash, parent hashes, ISO 8601 dates, author name, subject.

    ``date`` is the committer date, the one ``--since``/``--until`` select on.
    """

    hash: str
    parents: tuple[str, ...]
    date: str
    author_date: str
    author: str
    subject: str

    @property
    def short(self) -> str:
        return self.hash[:7]


@dataclass(frozen=True)
class Revision:
    """The database at one commit that changes it: counts over all its files.

    ``counts`` holds :data:`COUNT_COLUMNS`; ``mainline`` says whether the
    commit is on the first-parent line of the revision audited (a commit of
    a merged branch is not). ``errors`` lists files that are not well-formed.
    """

    commit: Commit
    mainline: bool
    files: int
    counts: dict[str, int]
    errors: tuple[str, ...] = ()

    def __getitem__(self, name: str) -> Any:
        return self.record()[name]

    @property
    def share_finite(self) -> float:
        """Share of audited entries with a finite r_max (0 to 1; NaN if none)."""
        audited = self.counts["audited"]
        return self.counts["finite"] / audited if audited else float("nan")

    def record(self) -> dict[str, Any]:
        """The row of ``history.csv`` as a dict, keys in :data:`HISTORY_COLUMNS` order."""
        c = self.commit
        values = dict(
            self.counts,
            commit=c.hash,
            date=c.date,
            author_date=c.author_date,
            author=c.author,
            subject=c.subject,
            merge=len(c.parents) > 1,
            mainline=self.mainline,
            files=self.files,
            files_with_errors=len(self.errors),
            not_audited=self.counts["entries"] - self.counts["audited"],
            share_finite=self.share_finite,
            errors="; ".join(self.errors),
        )
        return {name: values[name] for name in HISTORY_COLUMNS}


@dataclass(frozen=True)
class IntroducedEntry:
    """An entry of the newest revision with a finite r_max, and who introduced it.

    ``commit`` is None when the coefficients were already there before the
    oldest commit examined (a history cut by ``since``). r_max and d_max are
    in Hugin units; ``r_normalized_paper`` uses the paper's mixed units.
    """

    entry: DistortionEntry
    r_max: float
    d_max: float
    r_normalized: float
    r_normalized_paper: float
    folds_in_image: bool
    commit: Commit | None

    def record(self) -> dict[str, Any]:
        """The row of ``introduced.csv`` as a dict, keys in :data:`INTRODUCED_COLUMNS` order."""
        e, c = self.entry, self.commit
        values = {name: getattr(e, name) for name in INTRODUCED_COLUMNS[:14]}
        values.update(
            r_max=self.r_max,
            d_max=self.d_max,
            r_normalized=self.r_normalized,
            r_normalized_paper=self.r_normalized_paper,
            folds_in_image=self.folds_in_image,
            commit=c.hash if c else "",
            date=c.date if c else "",
            author=c.author if c else "",
            subject=c.subject if c else "",
        )
        return values


@dataclass
class History:
    """The audit of a database's history (see :func:`audit_history`).

    ``revisions`` are the commits that change the database, oldest first;
    ``newest`` is the newest commit on the first-parent line, whose entries
    ``introduced`` describes. The remaining fields say what the run cost.
    """

    repository: Path
    path: str
    revision: str
    first_parent: bool
    revisions: list[Revision]
    newest: Commit
    introduced: list[IntroducedEntry]
    commits: int
    blobs: int
    blobs_parsed: int
    blobs_cached: int
    seconds: float
    warnings: list[str] = field(default_factory=list)

    def records(self) -> list[dict[str, Any]]:
        """Rows of ``history.csv``, oldest commit first."""
        return [revision.record() for revision in self.revisions]

    def introduced_records(self) -> list[dict[str, Any]]:
        """Rows of ``introduced.csv``, in database order (file, then line)."""
        return [entry.record() for entry in self.introduced]

    def to_dataframe(self) -> pandas.DataFrame:
        """``history.csv`` as a DataFrame; ``date`` and ``author_date`` as UTC datetimes."""
        import pandas

        frame = pandas.DataFrame(self.records(), columns=list(HISTORY_COLUMNS))
        for name in ("date", "author_date"):
            frame[name] = pandas.to_datetime(frame[name], utc=True)
        return frame

    def introduced_dataframe(self) -> pandas.DataFrame:
        """``introduced.csv`` as a DataFrame."""
        import pandas

        return pandas.DataFrame(self.introduced_records(), columns=list(INTRODUCED_COLUMNS))

    def write_csv(self, stream: TextIO) -> None:
        """Write ``history.csv``: floats round-trip, booleans ``true``/``false``."""
        _write_csv(stream, HISTORY_COLUMNS, self.records(), frozenset({"share_finite"}))

    def write_introduced_csv(self, stream: TextIO) -> None:
        """Write ``introduced.csv``: floats round-trip, ``inf`` for infinite values."""
        _write_csv(stream, INTRODUCED_COLUMNS, self.introduced_records(), _FLOAT_INTRODUCED)


def _write_csv(
    stream: TextIO,
    columns: Sequence[str],
    records: list[dict[str, Any]],
    float_columns: frozenset[str],
) -> None:
    import csv

    from .pipeline import format_float

    out = csv.writer(stream, lineterminator="\n")
    out.writerow(columns)
    for record in records:
        out.writerow(
            [
                format_float(value)
                if name in float_columns
                else ("true" if value else "false")
                if isinstance(value, bool)
                else value
                for name, value in record.items()
            ]
        )


# --------------------------------------------------------------------------- git


class _Git:
    """One repository, read through :mod:`lensaudit.git`; git's failures as
    :class:`HistoryError`."""

    def __init__(self, repository: str | os.PathLike[str]) -> None:
        self.repository = Path(repository)
        self.given = repository  # as the user wrote it, for messages
        if not self.repository.is_dir():
            problem = "not a directory" if self.repository.exists() else "no such directory"
            raise HistoryError(f"{repository}: {problem}")
        try:
            self.run("rev-parse", "--git-dir")
        except HistoryError:
            raise HistoryError(f"{repository}: not a git repository") from None

    def run(self, *args: str) -> str:
        """Standard output of ``git ARGS``; HistoryError with git's message on failure."""
        try:
            return gitlayer.run(self.repository, *args).decode("utf-8", "replace")
        except gitlayer.GitUnavailable as error:
            raise HistoryError(f"cannot run git: {error}") from None
        except gitlayer.GitError as error:
            raise HistoryError(str(error)) from None

    def resolve_commit(self, revision: str) -> str:
        """The full id of the commit ``revision`` names; HistoryError if none."""
        try:
            return gitlayer.resolve_commit(self.repository, revision)
        except gitlayer.GitUnavailable as error:
            raise HistoryError(f"cannot run git: {error}") from None
        except gitlayer.GitError:
            raise HistoryError(f"{revision!r} is not a commit of {self.given}") from None

    def objects(self, names: Sequence[str]) -> Iterator[tuple[str, str, bytes] | None]:
        """(object id, type, content) for each name (``<rev>:<path>`` or an id),
        or None, through one ``git cat-file --batch`` (see :func:`lensaudit.git.objects`)."""
        try:
            yield from gitlayer.objects(self.repository, names)
        except gitlayer.GitUnavailable as error:
            raise HistoryError(f"cannot run git: {error}") from None
        except gitlayer.GitError as error:
            raise HistoryError(str(error)) from None


def _tree_files(data: bytes, oid_size: int) -> dict[str, str]:
    """{name: blob id} of the ``*.xml`` files directly in a raw git tree object.

    Subdirectories, symbolic links and submodules are not database files.
    """
    files = {}
    position, end = 0, len(data)
    while position < end:
        space = data.index(b" ", position)
        nul = data.index(b"\0", space)
        start = nul + 1
        mode, name = data[position:space], data[space + 1 : nul]
        position = start + oid_size
        if mode.startswith(b"100") and name.lower().endswith(b".xml"):
            files[name.decode("utf-8", "surrogateescape")] = data[start:position].hex()
    return files


def _normalized_path(path: str) -> str:
    parts = [p for p in PurePosixPath(path.replace("\\", "/")).parts if p not in ("", ".")]
    if ".." in parts or any("\n" in p for p in parts) or path.startswith("/"):
        raise HistoryError(f"{path!r}: give the database path relative to the repository root")
    return "/".join(parts)


_ISO_DATE = re.compile(r"\d{4}-\d{2}-\d{2}(?:[T ]\d{2}:\d{2}(?::\d{2})?(?:Z|[+-]\d{2}:?\d{2})?)?\Z")


def _git_date(text: str | None, *, end_of_day: bool) -> str | None:
    """An ISO 8601 date or date-time for git; a bare date means its start or end.

    git would read almost anything as a date (an unknown word as "now"), so
    only ISO 8601 is accepted. A time without a zone is local time, as in git.
    """
    if text is None:
        return None
    text = text.strip()
    try:
        if not _ISO_DATE.match(text):
            raise ValueError(text)
        datetime.fromisoformat(text.replace("Z", "+00:00"))  # month 13, day 32
    except ValueError:
        raise HistoryError(
            f"{text!r} is not a date: use YYYY-MM-DD or YYYY-MM-DDTHH:MM[:SS][+HH:MM]"
        ) from None
    if len(text) == 10:  # git reads a bare date as that day at the current time
        text += "T23:59:59" if end_of_day else "T00:00:00"
    return text


_LOG_FORMAT = "%H%x1f%P%x1f%cI%x1f%aI%x1f%an%x1f%s%x1e"


def _commits(git: _Git, revision: str, filters: list[str]) -> list[Commit]:
    """Commits of ``git log`` (with ``filters``), parents before children, oldest first."""
    text = git.run(
        "log", "--date-order", "--reverse", f"--format={_LOG_FORMAT}", *filters, revision, "--"
    )
    commits = []
    for record in text.split("\x1e"):
        record = record.strip("\n")
        if not record:
            continue
        hash_, parents, date, author_date, author, subject = record.split("\x1f")
        commits.append(Commit(hash_, tuple(parents.split()), date, author_date, author, subject))
    return commits


# ------------------------------------------------------------------ file versions


@dataclass(frozen=True)
class _BlobAudit:
    """What one file version holds: its error, :data:`COUNT_COLUMNS`, and the
    identities (interned) of its audited entries, in file order."""

    error: str
    counts: tuple[int, ...]
    idents: tuple[int, ...]


class _Interner:
    """Small integers for equal tuples: identities compared and hashed cheaply."""

    def __init__(self) -> None:
        self.ids: dict[tuple, int] = {}
        self.values: list[tuple] = []

    def __call__(self, value: tuple) -> int:
        found = self.ids.get(value)
        if found is None:
            found = self.ids[value] = len(self.values)
            self.values.append(value)
        return found


def _coefficient_getter(names: tuple[str, ...]) -> Callable[[DistortionEntry], tuple]:
    getter = attrgetter(*names)
    return getter if len(names) > 1 else lambda entry: (getter(entry),)


# model -> function giving an entry's coefficients of that model, as a tuple.
_COEFFICIENTS = {model: _coefficient_getter(names) for model, names in MODEL_COEFFICIENTS.items()}


def entry_identity(entry: DistortionEntry) -> tuple:
    """How an entry is recognised in another revision: maker, lens, crop factor,
    model, focal (mm) and the model's coefficients."""
    return (
        entry.maker,
        entry.lens,
        entry.crop_factor,
        entry.model,
        entry.focal,
        _COEFFICIENTS[entry.model](entry),
    )


@dataclass
class _Parsed:
    """One file version just parsed: its audited entries as interned identities
    and audit keys; the entries themselves only when asked to keep them."""

    entries: int
    error: str
    idents: list[int]
    audit_keys: list[int]
    rectilinear: list[bool]
    kept: list[DistortionEntry] | None = None


#: What a run of entries holds, as plain data (a worker process sends it back
#: marshalled): the number of entries, then, per audited entry, its identity,
#: its audit key and whether its lens is rectilinear.
_Summary = tuple[int, list[tuple], list[tuple], list[bool]]


def _summary(entries: Sequence[DistortionEntry]) -> _Summary:
    from .metrics import is_circular_fisheye

    identities, keys, rectilinear = [], [], []
    for entry in entries:
        if entry.status != STATUS_OK:
            continue
        identity = entry_identity(entry)
        identities.append(identity)
        # What the metrics depend on: model, coefficients, crop, aspect, focal
        # and whether the image is a circle.
        keys.append(
            (
                entry.model,
                identity[5],
                entry.crop_factor,
                entry.aspect_ratio,
                entry.focal,
                is_circular_fisheye(entry.lens, entry.type),
            )
        )
        rectilinear.append(entry.type == "rectilinear")
    return len(entries), identities, keys, rectilinear


#: The top-level elements a file version is cut into: lenses, cameras, mounts.
_PIECE = re.compile(rb"<(lens|camera|mount)>")
_PLACEHOLDER_TAG = "lensaudit-piece"
_PLACEHOLDER = f"<{_PLACEHOLDER_TAG}/>".encode()
_DECLARED_ENCODING = re.compile(rb"""\A(?:\xef\xbb\xbf)?<\?xml[^>]*?encoding\s*=\s*["']([^"']*)""")

#: A parsed file version as plain data (a worker process sends it back
#: marshalled): its error or "", the digests of its pieces in order (empty:
#: the file was read whole), and the summaries this process made for pieces
#: it had not seen before (the whole file's under the digest b"").
_Pieces = tuple[str, list[bytes], list[tuple[bytes, _Summary]]]


def _internal_subset(data: bytes) -> bool:
    """Whether the document type declares anything itself (entities, say); an
    external one is never loaded."""
    doctype = data.find(b"<!DOCTYPE")
    return doctype >= 0 and b"[" in data[doctype : data.find(b">", doctype)]


def _piece_spans(data: bytes) -> list[tuple[int, int]]:
    """(start, end) of each ``<lens>...</lens>`` (camera, mount) in the text."""
    spans = []
    position = 0
    while match := _PIECE.search(data, position):
        closing = b"</" + match.group(1) + b">"
        end = data.find(closing, match.end())
        if end < 0:
            break  # the skeleton will not parse
        position = end + len(closing)
        spans.append((match.start(), position))
    return spans


def _parse_blob(data: bytes, name: str, seen: dict[bytes, bool]) -> _Pieces:
    """What one file version holds, reading each distinct piece of it once.

    Successive versions of a file share most of their lenses, so the file is
    cut into its top-level ``<lens>``, ``<camera>`` and ``<mount>`` elements
    (the pieces) by their text, each known by a digest of its bytes. The
    rest of the file, with a placeholder element for each piece, must parse
    as a ``<lensdatabase>`` whose children include exactly those
    placeholders, and each piece must parse alone; then the file is
    well-formed and its entries are those of its pieces in order, since an
    entry's context comes from its own ``<lens>``. ``seen`` maps the digests
    of the pieces this process has parsed to whether they parsed. A file
    that does not qualify (not well-formed, namespaces, declarations in its
    document type, an encoding other than UTF-8, entries outside the pieces)
    is read whole, as the loader reads it.
    """
    from lxml import etree

    made: list[tuple[bytes, _Summary]] = []

    def whole() -> _Pieces:
        entries, error = loader.read_bytes(data, name)
        made.append((b"", _summary(entries)))
        return error, [], made

    declared = _DECLARED_ENCODING.match(data)
    if (
        b"xmlns" in data
        or _internal_subset(data)
        or _PLACEHOLDER_TAG.encode() in data
        or (declared is not None and declared.group(1).lower() not in (b"utf-8", b"utf8"))
    ):
        return whole()
    spans = _piece_spans(data)
    if not spans:
        return whole()
    parser = loader.make_parser()
    skeleton, position = [], 0
    for start, end in spans:
        skeleton += (data[position:start], _PLACEHOLDER)
        position = end
    skeleton.append(data[position:])
    try:
        root = etree.fromstring(b"".join(skeleton), parser)
    except etree.XMLSyntaxError:
        return whole()
    if (
        root.tag != loader.DATABASE_ROOT
        or sum(child.tag == _PLACEHOLDER_TAG for child in root) != len(spans)
        or next(root.iter("distortion"), None) is not None
    ):
        return whole()
    digests = []
    for start, end in spans:
        piece = data[start:end]
        digest = hashlib.blake2b(piece, digest_size=16).digest()
        parsed = seen.get(digest)
        if parsed is None:
            try:
                element = etree.fromstring(b"<lensdatabase>" + piece + b"</lensdatabase>", parser)
            except etree.XMLSyntaxError:
                element = None
            seen[digest] = parsed = element is not None
            if element is not None:
                made.append((digest, _summary(list(loader.entries_from_tree(element, name)))))
        if not parsed:
            return whole()
        digests.append(digest)
    return "", digests, made


class _Auditor:
    """Parses file versions, then audits each distinct (model, coefficients,
    crop factor, aspect ratio, focal, image circle) once, however many versions
    repeat it."""

    def __init__(self) -> None:
        self.idents = _Interner()
        self.audit_keys = _Interner()
        self.metrics: metrics.Metrics | None = None
        # piece digest -> (entries, interned identities, audit keys, rectilinear)
        self.pieces: dict[bytes, tuple[int, list[int], list[int], list[bool]]] = {}

    def parse(self, data: bytes, name: str, keep: bool = False) -> _Parsed:
        entries, error = loader.read_bytes(data, name)
        count, identities, keys, rectilinear = _summary(entries)
        return _Parsed(
            count,
            error,
            [self.idents(i) for i in identities],
            [self.audit_keys(k) for k in keys],
            rectilinear,
            [e for e in entries if e.status == STATUS_OK] if keep else None,
        )

    def _intern(self, summary: _Summary) -> tuple[int, list[int], list[int], list[bool]]:
        count, identities, keys, rectilinear = summary
        return (
            count,
            [self.idents(tuple(i)) for i in identities],
            [self.audit_keys(tuple(k)) for k in keys],
            list(rectilinear),
        )

    def add_pieces(self, made: list[tuple[bytes, _Summary]]) -> None:
        """Intern the summaries of pieces (see :func:`_parse_blob`) not seen yet."""
        for digest, summary in made:
            if digest and digest not in self.pieces:
                self.pieces[digest] = self._intern(summary)

    def assemble(self, result: _Pieces) -> _Parsed:
        """A file version from :func:`_parse_blob`, once :meth:`add_pieces` has
        seen the summaries of every file version of the run."""
        error, digests, made = result
        if not digests:
            count, idents, keys, rectilinear = self._intern(dict(made)[b""])
            return _Parsed(count, error, idents, keys, rectilinear)
        parsed = _Parsed(0, error, [], [], [])
        for digest in digests:
            count, idents, keys, rectilinear = self.pieces[digest]
            parsed.entries += count
            parsed.idents.extend(idents)
            parsed.audit_keys.extend(keys)
            parsed.rectilinear.extend(rectilinear)
        return parsed

    def finish(self, parsed: dict[str, _Parsed]) -> dict[str, _BlobAudit]:
        """Compute the metrics of every audit key at once, then count per file version."""
        import numpy as np

        from . import metrics

        keys = self.audit_keys.values
        size = len(keys)
        columns = {name: np.full(size, np.nan) for name in ("a", "b", "c", "k1", "k2")}
        for index, (model, coefficients, *_) in enumerate(keys):
            for name, value in zip(MODEL_COEFFICIENTS[model], coefficients, strict=True):
                columns[name][index] = value
        crop, aspect, focal = (np.array([k[i] for k in keys], dtype=np.float64) for i in (2, 3, 4))
        result = self.metrics = metrics.compute(
            np.array([k[0] for k in keys], dtype=object),
            *columns.values(),
            crop,
            aspect,
            focal,
            np.ones(size, dtype=bool),
            np.array([k[5] for k in keys], dtype=bool),
        )
        finite = np.isfinite(result.r_max)
        folds = result.folds_in_image
        with np.errstate(invalid="ignore"):
            folds_paper = finite & (result.r_normalized_paper < 1)
        model_index = np.array([MODELS.index(k[0]) for k in keys], dtype=np.intp)
        audits = {}
        for oid, blob in parsed.items():
            keys_of = np.array(blob.audit_keys, dtype=np.intp)
            rectilinear = np.array(blob.rectilinear, dtype=bool)
            models = model_index[keys_of]
            fin, fold, paper = finite[keys_of], folds[keys_of], folds_paper[keys_of]
            counts = (
                blob.entries,
                len(keys_of),
                *(int((models == m).sum()) for m in range(len(MODELS))),
                int(fin.sum()),
                *(int((fin & (models == m)).sum()) for m in range(len(MODELS))),
                int(fold.sum()),
                int((fold & rectilinear).sum()),
                int((paper & rectilinear).sum()),
            )
            audits[oid] = _BlobAudit(blob.error, counts, tuple(blob.idents))
        return audits


def default_cache_dir() -> Path:
    """lensaudit's cache directory (see :func:`lensaudit.cache.cache_dir`)."""
    from .cache import cache_dir

    return cache_dir()


def _fingerprint() -> str:
    """lensaudit's version and the code that decides what a file version holds.

    A cached audit is valid only for the code that made it; the version alone
    would not change while that code does.
    """
    from importlib.util import find_spec

    digest = hashlib.sha256(__version__.encode())
    # Found, not imported: importing the solver would start numpy's threads
    # before the parsing workers are forked.
    for module in ("loader", "normalizer", "solver", "metrics"):
        spec = find_spec(f"{__package__}.{module}")
        if spec is not None and spec.origin:
            digest.update(Path(spec.origin).read_bytes())
    digest.update(Path(__file__).read_bytes())
    return f"{__version__}-{digest.hexdigest()[:16]}"


class _BlobCache:
    """Audits of file versions on disk, keyed by blob id, in one SQLite file per
    code fingerprint (older ones are removed). Any problem reading or writing
    it means working without it, with a warning."""

    PREFIX = "history-"

    def __init__(self, directory: Path, interner: _Interner, warnings: list[str]) -> None:
        self.path = directory / f"{self.PREFIX}{_fingerprint()}.sqlite3"
        self.interner = interner
        self.warnings = warnings
        self.connection: sqlite3.Connection | None = None
        try:
            directory.mkdir(parents=True, exist_ok=True)
            for stale in directory.glob(f"{self.PREFIX}*.sqlite3"):
                if stale != self.path:
                    stale.unlink(missing_ok=True)
            self.connection = sqlite3.connect(self.path, timeout=10)
            self.connection.execute(
                "CREATE TABLE IF NOT EXISTS blob (oid TEXT PRIMARY KEY, audit BLOB NOT NULL)"
            )
            self.connection.execute(
                "CREATE TABLE IF NOT EXISTS run (key TEXT PRIMARY KEY, history BLOB NOT NULL)"
            )
        except (OSError, sqlite3.Error) as error:
            self._disable(error)

    def _disable(self, error: Exception) -> None:
        self.warnings.append(f"cache {self.path} not used: {error}")
        if self.connection is not None:
            self.connection.close()
        self.connection = None

    def get(self, oids: list[str]) -> dict[str, _BlobAudit]:
        found: dict[str, _BlobAudit] = {}
        if self.connection is None:
            return found
        try:
            for start in range(0, len(oids), 500):
                chunk = oids[start : start + 500]
                rows = self.connection.execute(
                    f"SELECT oid, audit FROM blob WHERE oid IN ({','.join('?' * len(chunk))})",
                    chunk,
                )
                for oid, stored in rows:
                    error, counts, idents = marshal.loads(zlib.decompress(stored))
                    found[oid] = _BlobAudit(error, tuple(counts), tuple(map(self.interner, idents)))
        except (sqlite3.Error, zlib.error, ValueError, EOFError, TypeError) as error:
            self._disable(error)
            return {}
        return found

    def put(self, audits: dict[str, _BlobAudit]) -> None:
        if self.connection is None or not audits:
            return
        values = self.interner.values
        rows = [
            (
                oid,
                zlib.compress(
                    marshal.dumps((a.error, a.counts, tuple(values[i] for i in a.idents))), 1
                ),
            )
            for oid, a in audits.items()
        ]
        try:
            with self.connection:
                self.connection.executemany(
                    "INSERT OR REPLACE INTO blob (oid, audit) VALUES (?, ?)", rows
                )
        except sqlite3.Error as error:
            self._disable(error)

    def get_run(self, key: str) -> History | None:
        """The history a run with this key gave, or None."""
        if self.connection is None:
            return None
        try:
            row = self.connection.execute(
                "SELECT history FROM run WHERE key = ?", (key,)
            ).fetchone()
            return (
                None if row is None else _history_from_data(marshal.loads(zlib.decompress(row[0])))
            )
        except (sqlite3.Error, zlib.error, ValueError, EOFError, TypeError) as error:
            self._disable(error)
            return None

    def put_run(self, key: str, history: History) -> None:
        """Keep the history of a run; only the latest run is kept."""
        if self.connection is None:
            return
        try:
            stored = zlib.compress(marshal.dumps(_history_data(history)), 1)
            with self.connection:
                self.connection.execute("DELETE FROM run")
                self.connection.execute(
                    "INSERT INTO run (key, history) VALUES (?, ?)", (key, stored)
                )
        except (sqlite3.Error, ValueError) as error:
            self._disable(error)

    def close(self) -> None:
        if self.connection is not None:
            self.connection.close()


def _commit_data(commit: Commit | None) -> tuple | None:
    return None if commit is None else tuple(getattr(commit, f.name) for f in fields(Commit))


def _history_data(history: History) -> tuple:
    """A history as marshal data (what a run's cache keeps)."""
    entry_fields = [f.name for f in fields(DistortionEntry)]
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
                tuple(getattr(i.entry, name) for name in entry_fields),
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


def _history_from_data(data: tuple) -> History:
    """The history :func:`_history_data` kept (repository and timings to be filled in)."""
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


# ----------------------------------------------------------------- introductions


class _FileState:
    """One file of one revision, as the history sees it: its blob, the
    identities of its entries and, for each, the commit that introduced it."""

    __slots__ = ("blob", "idents", "introducers", "_index")

    def __init__(self, blob: str, idents: tuple[int, ...], introducers: tuple[int, ...]):
        self.blob = blob
        self.idents = idents
        self.introducers = introducers
        self._index: dict[int, int] | None = None

    def introducer(self, ident: int) -> int | None:
        """Introducer of the first entry with this identity, or None."""
        if self._index is None:
            # Built reversed, so that the first occurrence of an identity wins.
            self._index = dict(zip(reversed(self.idents), reversed(self.introducers), strict=True))
        return self._index.get(ident)


_State = dict[str, _FileState]


def _find_introducer(ident: int, path: str, parents: list[_State]) -> int | None:
    """Introducer of an identical entry in the first parent that has one (same
    file first), or None when no parent has it."""
    for parent in parents:
        same = parent.get(path)
        if same is not None:
            found = same.introducer(ident)
            if found is not None:
                return found
        for name, state in parent.items():
            if name != path:
                found = state.introducer(ident)
                if found is not None:
                    return found
    return None


def _next_state(
    index: int, files: dict[str, str], parents: list[_State], audits: dict[str, _BlobAudit]
) -> _State:
    """The file states of commit ``index``, given those of its parents."""
    first = parents[0] if parents else {}
    state: _State = {}
    for path, blob in files.items():
        previous = first.get(path)
        if previous is not None and previous.blob == blob:
            state[path] = previous
            continue
        audit = audits[blob]
        if audit.error:
            # Unreadable: keep the entries of the file's last readable version.
            carried = next((p[path] for p in parents if path in p), None)
            state[path] = _FileState(
                blob, carried.idents if carried else (), carried.introducers if carried else ()
            )
            continue
        introducers = []
        for ident in audit.idents:
            found = _find_introducer(ident, path, parents)
            introducers.append(index if found is None else found)
        state[path] = _FileState(blob, audit.idents, tuple(introducers))
    return state


# ------------------------------------------------------------------------- audit


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
    db_path = _normalized_path(path)
    git = _Git(repository)
    tip = git.resolve_commit(revision)
    filters = [f"--since={d}" for d in [_git_date(since, end_of_day=False)] if d]
    filters += [f"--until={d}" for d in [_git_date(until, end_of_day=True)] if d]
    warnings: list[str] = []
    auditor = _Auditor()
    cache = _BlobCache(Path(cache_dir), auditor.idents, warnings) if cache_dir else None
    # A commit names its whole history: the same selection of it gives the same audit.
    run_key = repr((tip, db_path, filters, first_parent, time.tzname, time.timezone))
    if cache:
        stored = cache.get_run(run_key)
        if stored is not None:
            cache.close()
            return replace(
                stored,
                repository=Path(repository),
                revision=revision,
                blobs_parsed=0,
                blobs_cached=stored.blobs,
                seconds=time.perf_counter() - started,
                warnings=warnings,
            )
    commits = _commits(git, tip, filters + (["--first-parent"] if first_parent else []))
    mainline = git.run("rev-list", "--first-parent", *filters, tip, "--").split()
    if not commits or not mainline:
        raise HistoryError(f"no commit of {revision} between the dates given")
    position = {c.hash: i for i, c in enumerate(commits)}

    def parents_of(commit: Commit) -> tuple[str, ...]:
        return commit.parents[:1] if first_parent else commit.parents

    outside = sorted({p for c in commits for p in parents_of(c) if p not in position})
    files, present = _file_maps(git, [c.hash for c in commits] + outside, db_path, len(tip) // 2)
    if not any(files[c.hash] for c in commits):
        problem = "holds no *.xml file" if present & position.keys() else "does not exist"
        raise HistoryError(
            f"{db_path or '.'!r} {problem} at any of the {len(commits):,} "
            f"commits of {revision} selected"
        )

    # The newest revision's files are parsed even when cached: their entries
    # are reported in full. Every other file version is parsed at most once.
    newest = commits[position[mainline[0]]]
    newest_files = files[newest.hash]
    blobs = sorted({blob for m in files.values() for blob in m.values()})
    names = {blob: name for m in files.values() for name, blob in m.items()}
    names.update((blob, name) for name, blob in newest_files.items())
    audits = cache.get(blobs) if cache else {}
    cached = len(audits)
    keep = set(newest_files.values())
    to_parse = [b for b in blobs if b not in audits or b in keep]
    parsed = _parse_blobs(git, to_parse, names, keep, auditor, progress)
    fresh = auditor.finish(parsed)
    if cache:
        cache.put({blob: audit for blob, audit in fresh.items() if blob not in audits})
    audits.update(fresh)

    # Walk parents before children, keeping each commit's file states.
    states: dict[str, _State] = {
        p: {
            name: _FileState(blob, audits[blob].idents, (_BEFORE,) * len(audits[blob].idents))
            for name, blob in files[p].items()
        }
        for p in outside
    }
    mainline_set = set(mainline)
    revisions = []
    for index, commit in enumerate(commits):
        parent_hashes = parents_of(commit)
        mine = files[commit.hash]
        if parent_hashes and files[parent_hashes[0]] == mine:
            states[commit.hash] = states[parent_hashes[0]]
            continue
        states[commit.hash] = _next_state(index, mine, [states[p] for p in parent_hashes], audits)
        revisions.append(_revision(commit, commit.hash in mainline_set, mine, audits))

    introduced = _introduced(newest_files, states[newest.hash], parsed, auditor, commits)
    result = History(
        repository=Path(repository),
        path=db_path,
        revision=revision,
        first_parent=first_parent,
        revisions=revisions,
        newest=newest,
        introduced=introduced,
        commits=len(commits),
        blobs=len(blobs),
        blobs_parsed=len(parsed),
        blobs_cached=cached,
        seconds=time.perf_counter() - started,
        warnings=warnings,
    )
    if cache:
        cache.put_run(run_key, result)
        cache.close()
    return result


def _parse_blobs(
    git: _Git,
    blobs: list[str],
    names: dict[str, str],
    keep: set[str],
    auditor: _Auditor,
    progress: Callable[[int, int], None] | None,
) -> dict[str, _Parsed]:
    """Parse file versions: read through one ``git cat-file --batch``, then
    parsed in worker processes (:mod:`lensaudit.workers`) while this process
    parses those whose entries are kept (the newest revision's)."""
    from . import workers

    contents: dict[str, bytes] = {}
    for done, (blob, answer) in enumerate(zip(blobs, git.objects(blobs), strict=True), 1):
        if answer is None:
            raise HistoryError(f"git cannot read object {blob} of {git.repository}")
        contents[blob] = answer[2]
        if progress is not None:
            progress(done, len(blobs))
    others = [blob for blob in blobs if blob not in keep]
    jobs = [workers.Job(Path(names[blob]), names[blob], contents[blob]) for blob in others]
    seen: dict[bytes, bool] = {}  # pieces parsed, per process (each worker has its copy)
    parsed: dict[str, _Parsed] = {}

    def parse_kept() -> None:
        for blob in blobs:
            if blob in keep:
                parsed[blob] = auditor.parse(contents[blob], names[blob], keep=True)

    results = workers.parse_all(
        jobs, lambda job: _parse_blob(job.data or b"", job.name, seen), parse_kept
    )
    for result in results:
        auditor.add_pieces(result[2])
    for blob, result in zip(others, results, strict=True):
        parsed[blob] = auditor.assemble(result)
    return parsed


def _file_maps(
    git: _Git, hashes: list[str], db_path: str, oid_size: int
) -> tuple[dict[str, dict[str, str]], set[str]]:
    """{commit: {file name: blob id}} of the database at each commit ({} if absent),
    and the commits where the path exists at all."""
    by_tree: dict[str, dict[str, str]] = {}
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
                by_tree[oid] = _tree_files(data, oid_size)
            maps[commit] = by_tree[oid]
        elif kind == "blob":
            maps[commit] = {PurePosixPath(db_path).name: oid}
        else:
            maps[commit] = {}
    return maps, present


def _revision(
    commit: Commit, mainline: bool, files: dict[str, str], audits: dict[str, _BlobAudit]
) -> Revision:
    totals = [0] * len(COUNT_COLUMNS)
    errors = []
    for name in sorted(files):
        audit = audits[files[name]]
        totals = [t + c for t, c in zip(totals, audit.counts, strict=True)]
        if audit.error:
            errors.append(f"{name}: {audit.error}")
    return Revision(
        commit, mainline, len(files), dict(zip(COUNT_COLUMNS, totals, strict=True)), tuple(errors)
    )


def _introduced(
    files: dict[str, str],
    state: _State,
    parsed: dict[str, _Parsed],
    auditor: _Auditor,
    commits: list[Commit],
) -> list[IntroducedEntry]:
    """Entries of the newest revision with a finite r_max, with their introducers."""
    import numpy as np

    m = auditor.metrics
    assert m is not None
    introduced = []
    for name in sorted(files):
        blob = parsed[files[name]]
        if blob.error or blob.kept is None:
            continue  # an unreadable file has no audited entry
        for entry, key, introducer in zip(
            blob.kept, blob.audit_keys, state[name].introducers, strict=True
        ):
            if not np.isfinite(m.r_max[key]):
                continue
            if entry.file != name:  # the same content under two names
                entry = replace(entry, file=name)
            introduced.append(
                IntroducedEntry(
                    entry,
                    float(m.r_max[key]),
                    float(m.d_max[key]),
                    float(m.r_normalized[key]),
                    float(m.r_normalized_paper[key]),
                    bool(m.folds_in_image[key]),
                    None if introducer == _BEFORE else commits[introducer],
                )
            )
    return introduced


def audit_revision(
    repository: str | os.PathLike[str], revision: str = "HEAD", path: str = DEFAULT_PATH
) -> Audit:
    """Audit the database at one revision, read through git, from scratch.

    The usual :class:`lensaudit.pipeline.Audit` of the ``*.xml`` files at
    ``path`` in ``revision``; files are named relative to ``path``. Raises
    :class:`HistoryError` when the revision or the path does not exist.
    """
    from .database import DatabaseSource
    from .loader import SourceFile
    from .pipeline import audit_entries

    db_path = _normalized_path(path)
    git = _Git(repository)
    commit = git.resolve_commit(revision)
    maps, present = _file_maps(git, [commit], db_path, len(commit) // 2)
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


# ------------------------------------------------------------------------ figure


def trend_figure(history_frame: pandas.DataFrame, title: str | None = None) -> Figure:
    """The database over time: entries, share with finite r_max, folds.

    ``history_frame`` is :meth:`History.to_dataframe` (or ``history.csv``
    read with pandas). Only first-parent ("mainline") commits are drawn, so
    that a branch merged later does not zigzag the curves, in date order. The top panel
    shows entries audited and the share of them with a finite r_max; the
    bottom one counts entries folding inside their own image, in Hugin units
    and in the paper's mixed units (rectilinear lenses, as in the paper).
    The paper's snapshot date is marked on both.
    """
    import numpy as np
    import pandas
    from matplotlib.figure import Figure

    rows = history_frame
    if "mainline" in rows:
        rows = rows[rows["mainline"].astype(str).str.lower().isin(["true", "1"])]
    # By date: a rebased commit may keep a committer date older than its parent's.
    rows = rows.assign(date=pandas.to_datetime(rows["date"], utc=True)).sort_values(
        "date", kind="stable"
    )
    dates = rows["date"].dt.tz_convert(None).to_numpy()
    figure = Figure(figsize=(9, 6.5), layout="constrained")
    top, bottom = figure.subplots(2, 1, sharex=True)
    if title:
        figure.suptitle(title)

    top.step(dates, rows["audited"], where="post", color="C0", label="entries audited")
    top.set_ylabel("entries audited")
    share = top.twinx()
    share.step(
        dates,
        100 * rows["share_finite"].astype(float),
        where="post",
        color="C1",
        label="with finite r_max (%)",
    )
    share.set_ylabel("with finite r_max (%)")
    share.set_ylim(0, 100)
    handles = top.get_legend_handles_labels()[0] + share.get_legend_handles_labels()[0]
    top.legend(handles=handles, loc="upper left")

    for column, label, style in (
        ("folds_in_image", "inside own image (Hugin units), all types", "-"),
        ("folds_in_image_rectilinear", "inside own image (Hugin units), rectilinear", "--"),
        ("folds_in_image_paper_units_rectilinear", "paper's mixed units, rectilinear", ":"),
    ):
        bottom.step(dates, rows[column], where="post", linestyle=style, label=label)
    bottom.set_ylabel("entries folding")
    highest = int(rows["folds_in_image"].max()) if len(rows) else 0
    bottom.set_ylim(-0.3, 1.6 * highest + 1.5)  # room for the legend above the curves
    bottom.legend(loc="upper left")

    snapshot = np.datetime64(PAPER_SNAPSHOT)
    for axes in (top, bottom):
        axes.axvline(snapshot, color="0.35", linewidth=1, linestyle="-.")
        axes.grid(alpha=0.3)
    top.annotate(
        f"paper's snapshot {PAPER_SNAPSHOT}",
        (snapshot, 1),
        xycoords=("data", "axes fraction"),
        xytext=(-4, -4),
        textcoords="offset points",
        ha="right",
        va="top",
        fontsize=8,
        color="0.35",
    )
    if len(dates) == 0:
        bottom.text(0.5, 0.5, "no revision", transform=bottom.transAxes, ha="center")
    return figure
