"""The audit pipeline: database -> entries -> cubic form -> roots -> metrics.

:func:`run` gives an :class:`Audit`, plain columns that the output formats
and :func:`lensaudit.audit` (a pandas DataFrame) are made from.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from functools import cached_property
from operator import attrgetter
from typing import TYPE_CHECKING, Any

from . import database, loader
from .loader import STATUS_OK, DistortionEntry, SourceFile

# numpy (and so the metrics) is imported where it is first needed, so that
# run() can start reading the database while numpy is still being imported.
if TYPE_CHECKING:
    import numpy as np
    import pandas

    from . import metrics
    from .summary import Summary

#: Output columns, in order, for every format (CSV header, JSON keys, DataFrame).
COLUMNS = (
    "file",
    "line",
    "maker",
    "lens",
    "type",
    "crop_factor",
    "aspect_ratio",
    "model",
    "focal",
    "real_focal",
    "a",
    "b",
    "c",
    "k1",
    "k2",
    "r_max",
    "d_max",
    "tail",
    "r_corner",
    "r_normalized",
    "r_corner_paper",
    "r_normalized_paper",
    "folds_in_image",
    "status",
    "message",
)

#: Columns computed by the audit; the others are read from the database.
METRIC_COLUMNS = (
    "r_max", "d_max", "tail", "r_corner", "r_normalized", "r_corner_paper",
    "r_normalized_paper", "folds_in_image",
)  # fmt: skip
ENTRY_COLUMNS = tuple(name for name in COLUMNS if name not in METRIC_COLUMNS)
#: Columns holding numbers (written as shortest round-trip floats, inf, or empty).
FLOAT_COLUMNS = frozenset(COLUMNS) - {
    "file", "line", "maker", "lens", "type", "model", "tail", "folds_in_image", "status",
    "message",
}  # fmt: skip

_TAIL_NAMES = {1: "positive", -1: "negative", 0: ""}  # metrics.TAIL_POSITIVE, ...
#: The metric columns that hold floats (the others: tail, folds_in_image).
METRIC_FLOAT_COLUMNS = tuple(
    name for name in METRIC_COLUMNS if name not in ("tail", "folds_in_image")
)


class Audit:
    """The audit of one database: its source, files, entries and metrics.

    Metrics come as :class:`lensaudit.metrics.Metrics` (numpy arrays), or as
    plain lists per metric column when read back from the cache; either form
    gives the other on demand.
    """

    def __init__(
        self,
        source: database.DatabaseSource,
        files: list[SourceFile],
        entries: list[DistortionEntry],
        metrics: metrics.Metrics | None = None,
        metric_columns: dict[str, list] | None = None,
    ) -> None:
        if metrics is None and metric_columns is None:
            raise ValueError("an Audit needs its metrics")
        self.source = source
        self.files = files
        self.entries = entries
        self._metric_columns = metric_columns
        if metrics is not None:
            self.__dict__["metrics"] = metrics

    def __len__(self) -> int:
        return len(self.entries)

    @cached_property
    def metrics(self) -> metrics.Metrics:
        """The metrics as numpy arrays, one element per entry."""
        import numpy as np

        from .metrics import Metrics

        columns = self._metric_columns
        assert columns is not None
        return Metrics(
            **{name: np.array(columns[name], dtype=np.float64) for name in METRIC_FLOAT_COLUMNS},
            tail=np.array(columns["tail"], dtype=np.int8),
            folds_in_image=np.array(columns["folds_in_image"], dtype=bool),
        )

    def metric_columns(self) -> dict[str, list]:
        """The metrics as lists: floats, ``tail`` as -1/0/1, ``folds_in_image`` as 0/1."""
        if self._metric_columns is None:
            m = self.metrics
            self._metric_columns = {
                name: getattr(m, name).tolist() for name in METRIC_FLOAT_COLUMNS
            }
            self._metric_columns["tail"] = m.tail.tolist()
            self._metric_columns["folds_in_image"] = m.folds_in_image.astype(int).tolist()
        return self._metric_columns

    @cached_property
    def audited(self) -> np.ndarray:
        """Boolean mask of entries with status ``ok``."""
        import numpy as np

        return np.array(list(map(attrgetter("status"), self.entries)), dtype=object) == STATUS_OK

    def column(self, name: str) -> list[Any]:
        """One output column as a Python list (floats NaN where empty).

        ``tail`` is "positive", "negative" or ""; ``folds_in_image`` is a bool,
        or None for entries that were not audited.
        """
        if name in ENTRY_COLUMNS:
            return list(map(attrgetter(name), self.entries))
        values = self.metric_columns()[name]
        if name == "tail":
            return [_TAIL_NAMES[t] for t in values]
        if name == "folds_in_image":
            statuses = map(attrgetter("status"), self.entries)
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
        from .summary import summarize

        return summarize(self)

    def to_dataframe(self) -> pandas.DataFrame:
        """The entries as a pandas DataFrame with :data:`COLUMNS`."""
        import pandas

        frame = pandas.DataFrame(self.columns(), columns=list(COLUMNS))
        frame["line"] = frame["line"].astype("int64")
        frame["folds_in_image"] = frame["folds_in_image"].astype("boolean")
        return frame


def run(
    paths: Sequence[str | os.PathLike[str]] | str | os.PathLike[str] | None = None,
    *,
    cache: bool = False,
) -> Audit:
    """Audit a Lensfun database: directories and/or XML files, or the bundled one.

    With ``cache``, files parsed by an earlier run and unchanged since are
    read from lensaudit's parse cache (see :mod:`lensaudit.cache`). Raises
    :class:`lensaudit.loader.LoadError` when the paths cannot be read at all;
    problems inside files become entries with a status instead.
    """
    if isinstance(paths, (str, os.PathLike)):
        paths = [paths]
    source = database.resolve(list(paths) if paths else None)
    targets = loader.expand(source.paths)
    parse_cache = None
    if cache:
        from .cache import ParseCache

        parse_cache = ParseCache([path for path, _ in targets])
        audited = parse_cache.audited(targets)
        stored = parse_cache.metrics(targets) if audited is not None else None
        if audited is not None and stored is not None:
            # Nothing changed since the last audit: no parsing, no numpy.
            return _from_cache(source, targets, audited, stored)
    # libxml2 parses without holding the GIL: read the files while numpy imports.
    pending = loader.load_files_in_background(targets, parse_cache)
    from . import metrics  # noqa: F401  (the import is the point)

    loaded = pending()
    audit = audit_entries(loaded.entries, source, loaded.files)
    if parse_cache is not None:
        columns = audit.metric_columns()
        start = 0
        for file in loaded.files:
            end = start + file.entries
            parse_cache.put_metrics(file.path, {k: v[start:end] for k, v in columns.items()})
            start = end
        parse_cache.save()
    return audit


def _from_cache(source, targets, audited, stored) -> Audit:
    """An audit put together from the cache's entries and metrics, file by file."""
    files, entries = [], []
    columns: dict[str, list] = {}
    for (path, name), (file_entries, error), file_columns in zip(
        targets, audited, stored, strict=True
    ):
        files.append(SourceFile(name, path.resolve(), len(file_entries), error))
        entries.extend(file_entries)
        for key, values in file_columns.items():
            columns.setdefault(key, []).extend(values)
    return Audit(source, files, entries, metric_columns=columns)


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
    result = metrics.compute(
        list(map(attrgetter("model"), entries)),
        floats("a"),
        floats("b"),
        floats("c"),
        floats("k1"),
        floats("k2"),
        floats("crop_factor"),
        floats("aspect_ratio"),
        floats("focal"),
        audited,
        [metrics.is_circular_fisheye(e.lens, e.type) for e in entries],
    )
    if source is None:
        source = database.DatabaseSource((), "entries given in memory")
    return Audit(source, files or [], entries, result)


def format_float(value: float) -> str:
    """A float as the text formats write it: shortest round-trip, inf, or empty for NaN."""
    text = repr(value)
    return "" if text == "nan" else text


def format_floats(values: list[float]) -> list[str]:
    """:func:`format_float` over a list, at C speed for the common case."""
    texts = list(map(repr, values))
    if "nan" in texts:
        texts = ["" if text == "nan" else text for text in texts]
    return texts
