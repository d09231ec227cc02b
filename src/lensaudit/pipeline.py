"""The audit: read -> normalize -> solve -> metrics -> :class:`Audit`.

:func:`run` reads a database through :mod:`lensaudit.read`, computes the
metrics of its distortion rows (:func:`metric_columns`: the normalizer's
cubic, the solver's r_max, the image corner) and gives an :class:`Audit`:
plain columns, from which the output formats and :func:`lensaudit.audit`
(a pandas DataFrame) are made. With the cache, a file whose bytes were
audited before is neither parsed nor solved again.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from functools import cached_property
from operator import attrgetter

from . import read
from .columns import COLUMNS, ENTRY_COLUMNS, METRIC_COLUMNS, METRIC_FLOAT_COLUMNS, TAIL_NAMES
from .read.records import ROW_FIELDS, STATUS_OK, DistortionEntry, SourceFile
from .solver.kernel import column_metrics
from .summary import summarize

# typing only for type checkers: numpy and pandas are imported where needed.
TYPE_CHECKING = False
if TYPE_CHECKING:
    from typing import Any

    import numpy as np
    import pandas

    from . import metrics
    from .summary import Summary

#: The row fields the metrics are computed from.
_INPUTS = ("model", "a", "b", "c", "k1", "k2", "crop_factor", "aspect_ratio", "focal")


def metric_columns(columns: dict[str, list], memo: dict | None = None) -> dict[str, list]:
    """The metric columns of distortion rows given as columns (see
    :data:`~lensaudit.read.records.ROW_FIELDS`): lists of floats, ``tail``
    -1/0/1, ``folds_in_image`` 0/1; rows whose status is not ``ok`` get NaN
    and 0. The solver's scalar kernel answers nearly every database without
    numpy; the array code takes the rest. ``memo`` is the kernel's (see
    :func:`lensaudit.solver.kernel.column_metrics`), for many files in one run."""
    found = column_metrics(columns, STATUS_OK, memo)
    if found is not None:
        return found
    import numpy as np  # numpy: only where arrays are needed, not on importing this module

    from . import metrics  # numpy

    audited = np.array(columns["status"], dtype=object) == STATUS_OK
    circular = list(map(metrics.is_circular_fisheye, columns["lens"], columns["type"]))
    floats = [np.array(columns[name], dtype=np.float64) for name in _INPUTS[1:]]
    return _metric_lists(metrics.compute(columns["model"], *floats, audited, circular))


def _metric_lists(m: metrics.Metrics) -> dict[str, list]:
    columns = {name: getattr(m, name).tolist() for name in METRIC_FLOAT_COLUMNS}
    columns["tail"] = m.tail.tolist()
    columns["folds_in_image"] = m.folds_in_image.astype(int).tolist()
    return columns


def row_columns(rows: list[tuple]) -> dict[str, list]:
    """Distortion rows as columns: field name -> one value per row (no ``file``)."""
    if not rows:
        return {name: [] for name in ROW_FIELDS}
    return dict(zip(ROW_FIELDS, map(list, zip(*rows, strict=True)), strict=True))


def file_metrics(
    tables: read.FileTables, cache: read.Cache | None, memo: dict | None = None
) -> dict[str, list]:
    """The metric columns of one file's distortion rows, from the cache where it
    has them; ``memo`` as for :func:`metric_columns`."""
    if cache is not None and tables.digest:
        found = cache.get(tables.digest, "metrics")
        if isinstance(found, dict) and all(
            isinstance(found.get(name), list) and len(found[name]) == len(tables.distortion)
            for name in METRIC_COLUMNS
        ):
            return found
    computed = metric_columns(row_columns(tables.distortion), memo)
    if cache is not None and tables.digest:
        cache.put(tables.digest, "metrics", computed)
    return computed


def run(
    paths: Sequence[str | os.PathLike[str]] | str | os.PathLike[str] | None = None,
    *,
    cache: bool | read.Cache = False,
) -> Audit:
    """Audit a Lensfun database: directories and/or XML files, where a Lensfun
    checkout means its ``data/db``; None: the checkout around the working
    directory, else the database bundled with lensfunpy.

    With ``cache`` (True for lensaudit's cache directory, or a
    :class:`~lensaudit.read.Cache`), unchanged files are neither parsed nor
    solved again. Raises :class:`lensaudit.read.LoadError` when the paths
    cannot be read at all; problems inside files become entries with a
    status instead.
    """
    store = read.Cache() if cache is True else (cache or None)
    return audit_database(read.read(paths, cache=store), store)


def audit_database(database: read.Database, cache: read.Cache | None = None) -> Audit:
    """The audit of a database read (see :func:`lensaudit.read.read`); with
    ``cache``, the metrics of unchanged files are taken from it, and those
    computed are kept there (the cache is saved)."""
    found = [file_metrics(tables, cache) for tables in database.files]
    if cache is not None:
        cache.save()
    return Audit.of_files(database.source, database.files, found)


class Audit:
    """The audit of one database: its source, files, entries and metrics.

    Entries are held as columns (:data:`~lensaudit.columns.ENTRY_COLUMNS`),
    metrics as lists per metric column; entry objects, numpy arrays and a
    DataFrame are made from them when asked for.
    """

    def __init__(
        self,
        source: read.DatabaseSource,
        files: list[SourceFile],
        entry_columns: dict[str, list],
        metric_lists: dict[str, list],
    ) -> None:
        self.source = source
        self.files = files
        self._entry_columns = entry_columns
        self._metric_columns = metric_lists

    @classmethod
    def of_files(
        cls,
        source: read.DatabaseSource,
        files: list[read.FileTables],
        metrics: list[dict[str, list]],
    ) -> Audit:
        """The audit of files read, with the metric columns of each."""
        rows = [row for tables in files for row in tables.distortion]
        columns = row_columns(rows)
        columns["file"] = [tables.name for tables in files for _ in tables.distortion]
        joined = {name: [v for m in metrics for v in m[name]] for name in METRIC_COLUMNS}
        return cls(source, [tables.source_file() for tables in files], columns, joined)

    def __len__(self) -> int:
        return len(self._entry_columns["status"])

    @cached_property
    def entries(self) -> list[DistortionEntry]:
        """The entries, one object each."""
        columns = self._entry_columns
        return list(map(DistortionEntry, columns["file"], *(columns[f] for f in ROW_FIELDS)))

    def entry(self, index: int) -> DistortionEntry:
        """Entry ``index`` (as ``entries[index]``)."""
        return self.entries[index]

    @cached_property
    def metrics(self) -> metrics.Metrics:
        """The metrics as numpy arrays, one element per entry."""
        import numpy as np  # numpy: only where arrays are needed, not on importing this module

        from .metrics import Metrics  # numpy

        columns = self._metric_columns
        return Metrics(
            **{name: np.array(columns[name], dtype=np.float64) for name in METRIC_FLOAT_COLUMNS},
            tail=np.array(columns["tail"], dtype=np.int8),
            folds_in_image=np.array(columns["folds_in_image"], dtype=bool),
        )

    def metric_columns(self) -> dict[str, list]:
        """The metrics as lists: floats, ``tail`` as -1/0/1, ``folds_in_image`` as 0/1;
        kept, so callers must not change them."""
        return self._metric_columns

    def entry_column(self, name: str) -> list[Any]:
        """An entry column, kept: callers must not change it."""
        return self._entry_columns[name]

    @cached_property
    def audited(self) -> np.ndarray:
        """Boolean mask of entries with status ``ok``."""
        import numpy as np  # numpy: only where arrays are needed, not on importing this module

        return np.array(self._entry_columns["status"], dtype=object) == STATUS_OK

    def column(self, name: str) -> list[Any]:
        """One output column as a Python list (floats NaN where empty).

        ``tail`` is "positive", "negative" or ""; ``folds_in_image`` is a bool,
        or None for entries that were not audited.
        """
        if name in ENTRY_COLUMNS:
            return list(self._entry_columns[name])
        values = self._metric_columns[name]
        if name == "tail":
            return [TAIL_NAMES[t] for t in values]
        if name == "folds_in_image":
            statuses = self._entry_columns["status"]
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

    @cached_property
    def summary(self) -> Summary:
        """Tables 1 and 2, status counts and the folding entries (see :mod:`lensaudit.summary`)."""
        return summarize(self)

    def to_dataframe(self) -> pandas.DataFrame:
        """The entries as a pandas DataFrame with :data:`COLUMNS`."""
        import pandas  # pandas: only for a DataFrame, which no command needs

        frame = pandas.DataFrame(self.columns(), columns=list(COLUMNS))
        frame["line"] = frame["line"].astype("int64")
        frame["folds_in_image"] = frame["folds_in_image"].astype("boolean")
        return frame


def audit_entries(
    entries: list[DistortionEntry],
    source: read.DatabaseSource | None = None,
    files: list[SourceFile] | None = None,
) -> Audit:
    """The audit of entries already read (or made by hand)."""
    fields = ("file", *ROW_FIELDS)
    columns = {name: list(map(attrgetter(name), entries)) for name in fields}
    if source is None:
        source = read.DatabaseSource((), "entries given in memory")
    return Audit(source, files or [], columns, metric_columns(columns))
