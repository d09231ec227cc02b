"""CSV: one row per distortion entry, columns as :data:`lensaudit.columns.COLUMNS`.

Floats are written in shortest round-trip form, ``inf`` for infinite values
and empty for values that do not apply; booleans as ``true``/``false``. Text
is quoted as RFC 4180 says (only where it holds a comma, quote or line break).

Every row is rendered at once, column by column (:func:`rows`).
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
from . import interleaved, metric_fields

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


def rows(columns: dict[str, list], metrics: dict[str, list]) -> str:
    """Whole rows, each ending in a line break, from the entry columns (with
    ``file``) and the metric columns of the same entries."""
    fields = [_fields(name, columns[name]) for name in LEADING_COLUMNS]
    fields += metric_fields(metrics, columns["status"], format_floats, TAIL_NAMES, _BOOLEAN, "")
    fields += [_fields(name, columns[name]) for name in TRAILING_COLUMNS]
    return interleaved(["", *[","] * (len(fields) - 1), "\n"], fields)


def write(audit: Audit, stream: TextIO) -> None:
    stream.write(HEADER)
    stream.write(rows(_entry_columns(audit), audit.metric_columns()))


def _entry_columns(audit: Audit) -> dict[str, list]:
    return {name: audit.entry_column(name) for name in (*LEADING_COLUMNS, *TRAILING_COLUMNS)}
