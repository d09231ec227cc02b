"""The audit pipeline: database -> entries -> cubic form -> roots -> metrics.

:func:`run` gives an :class:`Audit`, plain columns that the output formats
and :func:`lensaudit.audit` (a pandas DataFrame) are made from.

An audit of a database is held file by file as columns (the packed form of
:mod:`lensaudit.cache`); entry objects, numpy arrays and rendered rows are
made from them when first asked for. That is what lets an unchanged
database be scanned from the cache without numpy, and a new one be parsed in
worker processes (:mod:`lensaudit.workers`). The metrics of a file are
computed as it is parsed, entry by entry in plain Python, by
:mod:`lensaudit.scalar` (the same floats as the array code); only a file
with an entry it leaves to the array code has its metrics computed with
numpy, once every file is parsed. A cold scan of Lensfun's database thus
never imports numpy.
"""

from __future__ import annotations

import os
from bisect import bisect_right
from collections.abc import Callable, Collection, Iterator, Sequence
from functools import cached_property, partial
from itertools import accumulate
from operator import attrgetter
from pathlib import Path

from . import database, loader
from .columns import (
    COLUMNS,
    ENTRY_COLUMNS,
    FLOAT_COLUMNS,
    LEADING_COLUMNS,
    METRIC_COLUMNS,
    METRIC_FLOAT_COLUMNS,
    TAIL_NAMES,
    TRAILING_COLUMNS,
    format_float,
    format_floats,
)
from .loader import STATUS_OK, DistortionEntry, SourceFile

# numpy (and so the metrics) is imported where it is first needed: an
# unchanged database is scanned without it, and a changed one mostly too
# (see lensaudit.scalar).
# typing only for type checkers: a scan from the cache never imports it.
TYPE_CHECKING = False
if TYPE_CHECKING:
    from typing import Any

    import numpy as np
    import pandas

    from . import metrics
    from .cache import ParseCache
    from .summary import Summary, Tally
    from .workers import Job

# The column names and float formatting live in lensaudit.columns; other
# modules also find them here.
__all__ = [
    "COLUMNS",
    "ENTRY_COLUMNS",
    "FLOAT_COLUMNS",
    "METRIC_COLUMNS",
    "METRIC_FLOAT_COLUMNS",
    "Audit",
    "FileColumns",
    "audit_entries",
    "format_float",
    "format_floats",
    "run",
]

#: The entry columns a row format renders (around the metrics).
_ROW_ENTRY_COLUMNS = LEADING_COLUMNS + TRAILING_COLUMNS
#: The entry columns a file's tally counts by (see :func:`lensaudit.summary.tally`).
_TALLIED = ("model", "status", "type")


class FileColumns:
    """One file of an audit: its entries as packed columns (see
    :func:`lensaudit.cache.pack_columns`), ``count`` of them, and what row
    formats rendered of them, by format name: whole ``rows``, or each row's
    text before and after its metrics (``row_texts``, rendered while parsing);
    its metric columns (or the same packed, ``packed_metrics``, as the cache
    holds them: see :meth:`metric_lists`) and its tally for the summary
    (:func:`lensaudit.summary.tally`), where known.
    """

    __slots__ = ("packed", "count", "rows", "row_texts", "metrics", "tally", "packed_metrics")

    def __init__(
        self,
        packed: dict,
        count: int,
        rows: dict[str, str] | None = None,
        row_texts: dict[str, tuple[list[str], list[str]]] | None = None,
        metrics: dict[str, list] | None = None,
        tally: Tally | None = None,
        packed_metrics: dict[str, bytes] | None = None,
    ) -> None:
        self.packed = packed
        self.count = count
        self.rows = {} if rows is None else rows
        self.row_texts = {} if row_texts is None else row_texts
        self.metrics = metrics
        self.tally = tally
        self.packed_metrics = packed_metrics

    def metric_lists(self) -> dict[str, list] | None:
        """The file's metric columns, unpacked when first asked for; None if not known."""
        if self.metrics is None and self.packed_metrics is not None:
            from .cache import unpack_metrics

            self.metrics = unpack_metrics(self.packed_metrics, self.count)
        return self.metrics


class Audit:
    """The audit of one database: its source, files, entries and metrics.

    Entries come as :class:`~lensaudit.loader.DistortionEntry` objects, or
    file by file as packed columns (``parts``, one :class:`FileColumns` per
    file); metrics as :class:`lensaudit.metrics.Metrics` (numpy arrays), as
    plain lists per metric column, or with each part. Each form gives the
    others on demand.
    """

    def __init__(
        self,
        source: database.DatabaseSource,
        files: list[SourceFile],
        entries: list[DistortionEntry] | None = None,
        metrics: metrics.Metrics | None = None,
        metric_columns: dict[str, list] | None = None,
        *,
        parts: list[FileColumns] | None = None,
    ) -> None:
        if (
            metrics is None
            and metric_columns is None
            and (
                parts is None
                or any(part.metrics is None and part.packed_metrics is None for part in parts)
            )
        ):
            raise ValueError("an Audit needs its metrics")
        if entries is None and parts is None:
            raise ValueError("an Audit needs its entries")
        self.source = source
        self.files = files
        self._parts = parts if entries is None else None
        self._metric_columns = metric_columns
        self._entry_columns: dict[str, list] = {}
        self._part_entries: dict[int, list[DistortionEntry]] = {}
        if entries is not None:
            self.__dict__["entries"] = entries
        if metrics is not None:
            self.__dict__["metrics"] = metrics

    def __len__(self) -> int:
        if self._parts is None:
            return len(self.entries)
        return sum(part.count for part in self._parts)

    @cached_property
    def entries(self) -> list[DistortionEntry]:
        """The entries, one object each."""
        from .cache import unpack_entries

        assert self._parts is not None
        entries: list[DistortionEntry] = []
        for file, part in zip(self.files, self._parts, strict=True):
            entries += unpack_entries(part.packed, file.name)
        return entries

    def entry(self, index: int) -> DistortionEntry:
        """Entry ``index`` (as ``entries[index]``), made from its file's columns alone."""
        if self._parts is None or "entries" in self.__dict__:
            return self.entries[index]
        starts = self._starts
        if not -starts[-1] <= index < starts[-1]:
            raise IndexError("entry index out of range")
        index %= starts[-1]
        part = bisect_right(starts, index) - 1
        found = self._part_entries.get(part)
        if found is None:
            from .cache import unpack_entries

            found = unpack_entries(self._parts[part].packed, self.files[part].name)
            self._part_entries[part] = found
        return found[index - starts[part]]

    @cached_property
    def _starts(self) -> list[int]:
        """Index of the first entry of each file, then the number of entries."""
        assert self._parts is not None
        return [0, *accumulate(part.count for part in self._parts)]

    @cached_property
    def metrics(self) -> metrics.Metrics:
        """The metrics as numpy arrays, one element per entry."""
        import numpy as np

        from .metrics import Metrics

        # Given as lists, or with each part (an audit made with neither has them as arrays).
        assert self._metric_columns is not None or self._parts is not None
        columns = self.metric_columns()
        return Metrics(
            **{name: np.array(columns[name], dtype=np.float64) for name in METRIC_FLOAT_COLUMNS},
            tail=np.array(columns["tail"], dtype=np.int8),
            folds_in_image=np.array(columns["folds_in_image"], dtype=bool),
        )

    def metric_columns(self) -> dict[str, list]:
        """The metrics as lists: floats, ``tail`` as -1/0/1, ``folds_in_image`` as 0/1."""
        if self._metric_columns is None:
            if "metrics" in self.__dict__ or self._parts is None:
                self._metric_columns = _metric_lists(self.metrics)
            else:
                columns: dict[str, list] = {name: [] for name in METRIC_COLUMNS}
                for part in self._parts:
                    lists = part.metric_lists()
                    assert lists is not None
                    for name, values in columns.items():
                        values += lists[name]
                self._metric_columns = columns
        return self._metric_columns

    def tallies(self) -> list[tuple[Tally, int]]:
        """Each file's tally for the summary (see :func:`lensaudit.summary.tally`),
        made now where not known, and its number of entries; for an audit of
        entries given in memory, one tally of them all."""
        from .summary import tally

        if self._parts is None:
            columns = [self._entry_column(name) for name in _TALLIED]
            return [(tally(*columns, self.metric_columns()), len(self))]
        found = []
        for index, (file, part) in enumerate(zip(self.files, self._parts, strict=True)):
            if part.tally is None:
                metrics = part.metric_lists()
                if metrics is None:
                    start, end = self._starts[index], self._starts[index + 1]
                    metrics = {k: v[start:end] for k, v in self.metric_columns().items()}
                columns = _unpacked(part, file.name, _TALLIED)
                part.tally = tally(*columns.values(), metrics)
            found.append((part.tally, part.count))
        return found

    @cached_property
    def audited(self) -> np.ndarray:
        """Boolean mask of entries with status ``ok``."""
        import numpy as np

        return np.array(self._entry_column("status"), dtype=object) == STATUS_OK

    def _entry_column(self, name: str) -> list[Any]:
        """An entry column, kept: callers must not change it."""
        values = self._entry_columns.get(name)
        if values is None:
            if self._parts is None:
                values = list(map(attrgetter(name), self.entries))
            else:
                from .cache import unpack_column

                values = []
                for file, part in zip(self.files, self._parts, strict=True):
                    values += unpack_column(part.packed, name, file.name)
            self._entry_columns[name] = values
        return values

    def column(self, name: str) -> list[Any]:
        """One output column as a Python list (floats NaN where empty).

        ``tail`` is "positive", "negative" or ""; ``folds_in_image`` is a bool,
        or None for entries that were not audited.
        """
        if name in ENTRY_COLUMNS:
            return list(self._entry_column(name))
        values = self.metric_columns()[name]
        if name == "tail":
            return [TAIL_NAMES[t] for t in values]
        if name == "folds_in_image":
            statuses = self._entry_column("status")
            return [
                bool(f) if s == STATUS_OK else None for f, s in zip(values, statuses, strict=True)
            ]
        return list(values)

    def columns(self) -> dict[str, list[Any]]:
        """All output columns, in :data:`COLUMNS` order."""
        return {name: self.column(name) for name in COLUMNS}

    def records(self) -> list[dict[str, Any]]:
        """One dict per entry, keys in :data:`COLUMNS` order."""
        columns = self.columns()
        return [dict(zip(COLUMNS, row, strict=True)) for row in zip(*columns.values(), strict=True)]

    def rows(self, format_name: str) -> Iterator[str]:
        """The entries rendered by a row format ("csv", "json"; see
        :mod:`lensaudit.formats`), one text per file, in order.

        Rows come from the cache or from :func:`run` when it rendered them;
        others are rendered here and kept.
        """
        from .formats import row_format

        module = row_format(format_name)
        if self._parts is None:
            leading, trailing = module.row_texts(
                {name: self._entry_column(name) for name in _ROW_ENTRY_COLUMNS}
            )
            metrics = module.metric_texts(self.metric_columns(), self._entry_column("status"))
            yield module.rows(leading, metrics, trailing)
            return
        starts = self._starts
        missing = [i for i, part in enumerate(self._parts) if format_name not in part.rows]
        every = None  # every entry's metric text, when most files need rows
        if 2 * sum(starts[i + 1] - starts[i] for i in missing) >= starts[-1]:
            every = module.metric_texts(self.metric_columns(), self._entry_column("status"))
        for index, (file, part) in enumerate(zip(self.files, self._parts, strict=True)):
            text = part.rows.get(format_name)
            if text is None:
                start, end = starts[index], starts[index + 1]
                if every is not None:
                    metrics = every[start:end]
                else:
                    metrics = module.metric_texts(
                        {k: v[start:end] for k, v in self.metric_columns().items()},
                        self._entry_column("status")[start:end],
                    )
                texts = part.row_texts.pop(format_name, None)
                if texts is None:
                    texts = module.row_texts(_unpacked(part, file.name, _ROW_ENTRY_COLUMNS))
                leading, trailing = texts
                text = module.rows(leading, metrics, trailing)
                part.rows[format_name] = text
            yield text

    @cached_property
    def summary(self) -> Summary:
        """Tables 1 and 2, status counts and the folding entries (see :mod:`lensaudit.summary`)."""
        from .summary import summarize

        return summarize(self)

    def to_dataframe(self) -> pandas.DataFrame:
        """The entries as a pandas DataFrame with :data:`COLUMNS`."""
        import pandas

        frame = pandas.DataFrame(self.columns(), columns=list(COLUMNS))
        frame["line"] = frame["line"].astype("int64")
        frame["folds_in_image"] = frame["folds_in_image"].astype("boolean")
        return frame


def _unpacked(part: FileColumns, name: str, fields: Sequence[str]) -> dict[str, list]:
    from .cache import unpack_column

    return {field: unpack_column(part.packed, field, name) for field in fields}


def _metric_lists(m: metrics.Metrics) -> dict[str, list]:
    columns = {name: getattr(m, name).tolist() for name in METRIC_FLOAT_COLUMNS}
    columns["tail"] = m.tail.tolist()
    columns["folds_in_image"] = m.folds_in_image.astype(int).tolist()
    return columns


def run(
    paths: Sequence[str | os.PathLike[str]] | str | os.PathLike[str] | None = None,
    *,
    cache: bool = False,
    formats: Collection[str] = (),
) -> Audit:
    """Audit a Lensfun database: directories and/or XML files, or the bundled one.

    With ``cache``, files audited by an earlier run and unchanged since are
    read from lensaudit's parse cache (see :mod:`lensaudit.cache`), and the
    others are stored there. ``formats`` names the row formats ("csv",
    "json") whose rows are wanted: they are rendered as files are parsed, and
    cached with them. Raises :class:`lensaudit.loader.LoadError` when the
    paths cannot be read at all; problems inside files become entries with a
    status instead.
    """
    from .formats import ROW_FORMATS

    if isinstance(paths, (str, os.PathLike)):
        paths = [paths]
    source = database.resolve(list(paths) if paths else None)
    targets = loader.expand(source.paths)
    store = None
    if cache:
        from .cache import ParseCache

        store = ParseCache([path for path, _ in targets])
    wanted = tuple(name for name in ROW_FORMATS if name in formats)
    return _audit_files(source, targets, store, wanted)


def _audit_files(
    source: database.DatabaseSource,
    targets: list[tuple[Path, str]],
    store: ParseCache | None,
    formats: tuple[str, ...],
) -> Audit:
    """The audit of ``targets``: from the cache ``store`` where it knows the
    content, parsed and audited (in workers, where a core is free) where not."""
    size = len(targets)
    files: list[SourceFile] = []
    parts: list[FileColumns] = []
    digests: list[bytes | None] = [None] * size
    cached_rows: list[frozenset[str]] = [frozenset()] * size
    jobs: list[tuple[int, tuple[Path, str, bytes | None]]] = []  # (index, job's fields)
    for index, (path, name) in enumerate(targets):  # paths resolved by loader.expand
        data = None
        if store is not None and store.knows(path):
            from .cache import content_digest

            try:
                data = loader.read_regular_file(path)
            except OSError:  # parsed below, where reading it fails again and is reported
                pass
            else:
                digest = content_digest(data)
                found = store.find(path, digest, name)
                if found is not None:
                    files.append(SourceFile(name, path, found.count, found.error))
                    parts.append(
                        FileColumns(
                            found.packed,
                            found.count,
                            dict(found.rows),
                            packed_metrics=found.metrics,
                            tally=found.tally,
                        )
                    )
                    digests[index] = digest
                    cached_rows[index] = frozenset(found.rows)
                    continue
        files.append(SourceFile(name, path, 0))  # placeholders, replaced below
        parts.append(FileColumns({}, 0))
        jobs.append((index, (path, name, data)))

    stored = set()  # files whose records are stored as their parse sealed them
    if jobs:
        parse = file_parser(formats, digests=store is not None)
        # numpy is not imported meanwhile: lensaudit.scalar computes the metrics
        # of nearly every database as files are parsed, and numpy only the rest.
        meanwhile = _nothing if store is None else _fingerprint
        # Imported only here: a scan that finds every file in the cache parses none.
        from .workers import Job, parse_all

        work = [Job(*fields) for _, fields in jobs]
        for (index, _), job, result in zip(
            jobs, work, parse_all(work, parse, meanwhile), strict=True
        ):
            if result[0] == _SEALED:
                assert store is not None
                files[index], parts[index], digests[index] = _unsealed(job, result, store)
                stored.add(index)
                continue
            _, digest, packed, count, error, file_metrics, texts, file_tally = result
            files[index] = SourceFile(job.name, job.path, count, error)
            if file_metrics is None:
                parts[index] = FileColumns(packed, count, row_texts=texts)
            else:
                parts[index] = FileColumns(
                    packed, count, rows=texts, metrics=file_metrics, tally=file_tally
                )
            digests[index] = digest

    computed = None
    missing = [
        index
        for index in range(size)
        if parts[index].metrics is None and parts[index].packed_metrics is None
    ]
    audited_now = {index for index, _ in jobs}.union(missing)
    if missing:
        computed = _compute([parts[index] for index in missing])
        start = 0
        lists = _metric_lists(computed)
        for index in missing:
            end = start + parts[index].count
            parts[index].metrics = {name: values[start:end] for name, values in lists.items()}
            start = end
    audit = Audit(
        source,
        files,
        metrics=computed if missing and len(missing) == size else None,
        parts=parts,
    )
    for name in formats:
        for _ in audit.rows(name):  # rendered now, to be cached
            pass
    if store is not None:
        if missing:
            audit.tallies()  # to be cached with the metrics
        for index, (file, part) in enumerate(zip(files, parts, strict=True)):
            digest = digests[index]
            new_rows = {k: v for k, v in part.rows.items() if k not in cached_rows[index]}
            if index in stored or digest is None or not (index in audited_now or new_rows):
                continue
            store.store(
                file.path,
                digest,
                part.packed,
                file.error,
                part.metric_lists(),
                file.name,
                new_rows,
                part.tally,
            )
        store.save()
    return audit


#: What :func:`_parse` gives: a record sealed for the cache, or the plain result.
_SEALED, _PLAIN = "sealed", "plain"


def _unsealed(job: Job, result: tuple, store: ParseCache) -> tuple[SourceFile, FileColumns, bytes]:
    """The file, its columns and its digest from a record :func:`_parse` sealed,
    which ``store`` keeps as it is."""
    import marshal

    _, part_seal, body = result
    record = marshal.loads(body)
    digest, packed, error, packed_metrics, _, rows, file_tally = record
    count = packed["count"]
    store.store_sealed(job.path, part_seal, body, record)
    part = FileColumns(packed, count, dict(rows), tally=file_tally, packed_metrics=packed_metrics)
    return SourceFile(job.name, job.path, count, error), part, digest


def _nothing() -> None:
    """What the caller does while workers parse: its share of the files, no more."""


def _fingerprint() -> None:
    """Compute what the cache will be saved under (it reads the package's
    sources), while workers parse rather than before or after."""
    from .cache import fingerprint

    fingerprint()


def file_parser(formats: tuple[str, ...], digests: bool) -> Callable[[Job], tuple]:
    """What parses a file for an audit (see :func:`_parse`), with what it needs
    imported, once, before any worker is forked."""
    from lxml import etree  # noqa: F401

    from . import cache, scalar, summary  # noqa: F401
    from .formats import row_format

    for name in formats:
        row_format(name)
    return partial(_parse, formats=formats, digests=digests)


def _parse(job: Job, formats: tuple[str, ...], digests: bool = True) -> tuple:
    """What the audit needs of one file.

    With ``digests`` (for the cache), and where :mod:`lensaudit.scalar` gives
    every metric: ``(_SEALED, seal, body)``, the file's cache record sealed
    (see :func:`lensaudit.cache.sealed_record`). Otherwise ``(_PLAIN, digest,
    packed, count, error, metrics, texts, tally)``: the digest of the bytes
    parsed (None if unreadable, or not wanted), packed entries, their count,
    the file error, the metrics (None if :mod:`lensaudit.scalar` leaves any
    entry to the array code), each row format's rows (with metrics) or,
    without them, its texts of every row before and after its metrics, and
    the file's tally for the summary (None without metrics)."""
    from .cache import RECORD_ERRORS, content_digest, pack_columns, sealed_record
    from .scalar import column_metrics
    from .summary import tally

    digest = None
    try:
        data = job.data if job.data is not None else loader.read_regular_file(job.path)
    except OSError as os_error:
        entries, error = loader.unreadable_file(job.name, os_error)
        rows = [entry[1:] for entry in entries]
    else:
        rows, error = loader.read_rows(data)
        if digests:
            digest = content_digest(data)
    columns = loader.row_columns(rows)
    packed = pack_columns(columns, len(rows))
    metrics = column_metrics(columns, STATUS_OK)
    file_tally = None
    if metrics is not None:
        file_tally = tally(*(columns[name] for name in _TALLIED), metrics)
    texts = {}
    if formats:
        from .formats import row_format

        columns["file"] = [job.name] * len(rows)
        for name in formats:
            module = row_format(name)
            if metrics is None:
                texts[name] = module.row_texts(columns)
            else:
                texts[name] = module.file_rows(columns, metrics)
    if digest is not None and metrics is not None:
        try:
            seal, body = sealed_record(digest, packed, error, metrics, job.name, texts, file_tally)
        except RECORD_ERRORS:  # stored later, or not at all, as the cache decides
            pass
        else:
            return _SEALED, seal, body
    return _PLAIN, digest, packed, len(rows), error, metrics, texts, file_tally


def _compute(parts: list[FileColumns]) -> metrics.Metrics:
    """The metrics of the entries of ``parts``, in order (as :func:`audit_entries`)."""
    import numpy as np

    from . import metrics
    from .cache import unpack_column

    def floats(name: str) -> np.ndarray:
        return np.frombuffer(b"".join(p.packed[name] for p in parts), dtype=np.float64).copy()

    def texts(name: str) -> list[str]:
        values: list[str] = []
        for part in parts:
            values += unpack_column(part.packed, name, "")
        return values

    audited = np.array(texts("status"), dtype=object) == STATUS_OK
    circular = list(map(metrics.is_circular_fisheye, texts("lens"), texts("type")))
    return _compute_columns(texts("model"), floats, audited, circular)


#: The float columns :func:`lensaudit.metrics.compute` takes, in its order.
_METRIC_INPUTS = ("a", "b", "c", "k1", "k2", "crop_factor", "aspect_ratio", "focal")


def _compute_columns(
    models: list[str],
    floats: Callable[[str], np.ndarray],
    audited: np.ndarray,
    circular: list[bool],
) -> metrics.Metrics:
    """:func:`lensaudit.metrics.compute` of entries whose float columns ``floats`` gives."""
    from . import metrics

    return metrics.compute(models, *map(floats, _METRIC_INPUTS), audited, circular)


def audit_entries(
    entries: list[DistortionEntry],
    source: database.DatabaseSource | None = None,
    files: list[SourceFile] | None = None,
) -> Audit:
    """Compute the metrics of already loaded entries."""
    import numpy as np

    from . import metrics

    size = len(entries)

    def floats(name: str) -> np.ndarray:
        return np.fromiter(map(attrgetter(name), entries), np.float64, size)

    audited = np.array(list(map(attrgetter("status"), entries)), dtype=object) == STATUS_OK
    circular = [metrics.is_circular_fisheye(e.lens, e.type) for e in entries]
    result = _compute_columns(list(map(attrgetter("model"), entries)), floats, audited, circular)
    if source is None:
        source = database.DatabaseSource((), "entries given in memory")
    return Audit(source, files or [], entries, result)
