"""CSV: one row per distortion entry, columns as :data:`lensaudit.columns.COLUMNS`.

Floats are written in shortest round-trip form, ``inf`` for infinite values
and empty for values that do not apply; booleans as ``true``/``false``. Text
is quoted as RFC 4180 says (only where it holds a comma, quote or line break).

Rows are rendered file by file: the text an entry gives (:func:`row_texts`,
which needs no metrics, so that it can be done while files are still being
parsed), joined with the text of its metrics (:func:`metric_texts`) into
whole rows (:func:`rows`). The audit keeps each file's rows, and the parse
cache stores them, so that an unchanged database is written by
concatenation.
"""

from __future__ import annotations

import re

from ..columns import (
    COLUMNS,
    FLOAT_COLUMNS,
    LEADING_COLUMNS,
    TAIL_NAMES,
    TRAILING_COLUMNS,
    format_floats,
)
from . import interleaved, metric_fields, split_rows

# typing only for type checkers: a scan from the cache never imports it.
TYPE_CHECKING = False
if TYPE_CHECKING:
    from typing import TextIO

    from ..pipeline import Audit

_BOOLEAN = {True: "true", False: "false", None: ""}
_NEEDS_QUOTES = re.compile(r'[,"\r\n]')
HEADER = ",".join(COLUMNS) + "\n"


def _quoted(text: str) -> str:
    return '"' + text.replace('"', '""') + '"' if _NEEDS_QUOTES.search(text) else text


def text_column(values: list) -> list[str]:
    """Values as CSV fields; the common column that needs no quoting costs one scan."""
    texts = [v if isinstance(v, str) else str(v) for v in values]
    if _NEEDS_QUOTES.search("\0".join(texts)):
        return [_quoted(text) for text in texts]
    return texts


def _fields(name: str, values: list) -> list[str]:
    if name in FLOAT_COLUMNS:
        return format_floats(values)
    if name == "line":
        return list(map(str, values))
    return text_column(values)


def row_texts(columns: dict[str, list]) -> tuple[list[str], list[str]]:
    """Each row's text before its metrics and after them, from the entry columns
    (:data:`~lensaudit.columns.LEADING_COLUMNS` and ``TRAILING_COLUMNS``)."""
    return split_rows(columns, _fields, ",".join, ",".join)


def file_rows(columns: dict[str, list], metrics: dict[str, list]) -> str:
    """Whole rows, as :func:`rows` gives them, from the entry columns and the
    metric columns of the same entries."""
    fields = [_fields(name, columns[name]) for name in LEADING_COLUMNS]
    fields += _metric_fields(metrics, columns["status"])
    fields += [_fields(name, columns[name]) for name in TRAILING_COLUMNS]
    return interleaved(["", *[","] * (len(fields) - 1), "\n"], fields)


def _metric_fields(metrics: dict[str, list], statuses: list[str]) -> list[list[str]]:
    return metric_fields(metrics, statuses, format_floats, TAIL_NAMES, _BOOLEAN, "")


def metric_texts(metrics: dict[str, list], statuses: list[str]) -> list[str]:
    """Each entry's metric fields, from the metric columns and the statuses (an
    entry that was not audited has no ``folds_in_image``)."""
    return list(map(",".join, zip(*_metric_fields(metrics, statuses), strict=True)))


def rows(leading: list[str], metrics: list[str], trailing: list[str]) -> str:
    """Whole rows, each ending in a line break, from :func:`row_texts` and
    :func:`metric_texts` of the same entries."""
    if not leading:
        return ""
    return "\n".join(map(",".join, zip(leading, metrics, trailing, strict=True))) + "\n"


def join(texts: list[str]) -> str:
    """The rows of several files as one text."""
    return "".join(texts)


def write(audit: Audit, stream: TextIO) -> None:
    stream.write(HEADER)
    for text in audit.rows("csv"):
        stream.write(text)
