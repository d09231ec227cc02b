"""The audit pipeline: database -> entries -> cubic form -> roots -> metrics.

:func:`run` gives an :class:`Audit`, plain columns that the output formats
and :func:`lensaudit.audit` (a pandas DataFrame) are made from.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
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


@dataclass(frozen=True)
class Audit:
    """The audit of one database: its source, files, entries and metrics."""

    source: database.DatabaseSource
    files: list[SourceFile]
    entries: list[DistortionEntry]
    metrics: metrics.Metrics

    def __len__(self) -> int:
        return len(self.entries)

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
        if name == "tail":
            return [_TAIL_NAMES[t] for t in self.metrics.tail.tolist()]
        if name == "folds_in_image":
            return [
                bool(f) if ok else None
                for f, ok in zip(
                    self.metrics.folds_in_image.tolist(), self.audited.tolist(), strict=True
                )
            ]
        return getattr(self.metrics, name).tolist()

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
    # libxml2 parses without holding the GIL: read the files while numpy imports.
    pending = loader.load_files_in_background(targets, parse_cache)
    from . import metrics  # noqa: F401  (the import is the point)

    loaded = pending()
    if parse_cache is not None:
        parse_cache.save()
    return audit_entries(loaded.entries, source, loaded.files)


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
