"""Output formats of an audit: one module per format, each with ``write(audit, stream)``.

Formats that write a row per entry (:data:`ROW_FORMATS`) also render them
file by file: ``file_rows(columns, metrics)`` a file's whole rows from its
entry and metric columns at once, or in parts, where the metrics come later:
``row_texts(columns)`` gives each row's text before and after its metrics,
``metric_texts(metrics, statuses)`` that of its metrics, and
``rows(leading, metrics, trailing)`` whole rows; ``join(texts)`` gives the
rows of several files as one text (see :meth:`lensaudit.pipeline.Audit.rows`).
"""

from __future__ import annotations

from collections.abc import Callable
from importlib import import_module
from itertools import chain
from types import ModuleType

from ..columns import LEADING_COLUMNS, METRIC_COLUMNS, TRAILING_COLUMNS
from ..loader import STATUS_OK

# typing only for type checkers: a scan from the cache never imports it.
TYPE_CHECKING = False
if TYPE_CHECKING:
    from typing import TextIO

    from ..pipeline import Audit

#: Format name -> module under lensaudit.formats.
FORMATS = {"table": "table", "csv": "csv_format", "json": "json_format"}
#: Formats whose rows are rendered per file, ahead of time, and cached.
ROW_FORMATS = ("csv", "json")


def writer(name: str) -> Callable[[Audit, TextIO], None]:
    """The ``write(audit, stream)`` function of the named format."""
    return import_module(f"{__name__}.{FORMATS[name]}").write


def split_rows(
    columns: dict[str, list],
    fields: Callable[[str, list], list[str]],
    leading: Callable[[tuple[str, ...]], str],
    trailing: Callable[[tuple[str, ...]], str],
) -> tuple[list[str], list[str]]:
    """Each row's text before its metrics and after them, for ``row_texts``:
    ``fields(name, values)`` renders a column, ``leading`` and ``trailing``
    join a row's fields of :data:`~lensaudit.columns.LEADING_COLUMNS` and
    ``TRAILING_COLUMNS``."""
    before = [fields(name, columns[name]) for name in LEADING_COLUMNS]
    after = [fields(name, columns[name]) for name in TRAILING_COLUMNS]
    return list(map(leading, zip(*before, strict=True))), list(
        map(trailing, zip(*after, strict=True))
    )


def interleaved(literals: list[str], fields: list[list[str]]) -> str:
    """Every row's ``literals[0] + fields[0][i] + literals[1] + ... + literals[-1]``, as one text.

    ``literals`` has one more item than ``fields``. The pieces are joined in
    one pass at C speed, without a text per row in between.
    """
    count = len(fields[0]) if fields else 0
    pieces: list[list[str]] = []
    for literal, column in zip(literals[:-1], fields, strict=True):
        if literal:
            pieces.append([literal] * count)
        pieces.append(column)
    if literals[-1]:
        pieces.append([literals[-1]] * count)
    return "".join(chain.from_iterable(zip(*pieces, strict=True)))


def metric_fields(
    metrics: dict[str, list],
    statuses: list[str],
    floats: Callable[[list[float]], list[str]],
    tails: dict[int, str],
    booleans: dict[bool, str],
    not_audited: str,
) -> list[list[str]]:
    """The metric columns as texts, for ``metric_texts``: ``tail`` through
    ``tails``, ``folds_in_image`` through ``booleans`` (``not_audited`` for an
    entry that was not audited), the others through ``floats``."""
    fields: list[list[str]] = []
    for name in METRIC_COLUMNS:
        values = metrics[name]
        if name == "tail":
            fields.append(list(map(tails.__getitem__, values)))
        elif name == "folds_in_image":
            fields.append(
                [
                    booleans[bool(fold)] if status == STATUS_OK else not_audited
                    for fold, status in zip(values, statuses, strict=True)
                ]
            )
        else:
            fields.append(floats(values))
    return fields


def row_format(name: str) -> ModuleType:
    """The module of a format in :data:`ROW_FORMATS`."""
    if name not in ROW_FORMATS:
        raise ValueError(f"{name!r} is not one of {', '.join(ROW_FORMATS)}")
    return import_module(f"{__name__}.{FORMATS[name]}")
