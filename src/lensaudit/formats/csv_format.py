"""CSV: one row per distortion entry, columns as :data:`lensaudit.columns.COLUMNS`.

Floats are written in shortest round-trip form, ``inf`` for infinite values
and empty for values that do not apply; booleans as ``true``/``false``. Text
is quoted as RFC 4180 says (only where it holds a comma, quote or line break).

Every CSV lensaudit writes goes through :func:`write_rows`, which renders
every row at once, column by column. Text is kept byte for byte: a cell that
begins with ``=``, ``+``, ``-`` or ``@`` is not altered for spreadsheets,
which is the reader's to import as text (docs/input.md says why).
"""

from __future__ import annotations

import re

from ..columns import (
    COLUMNS,
    format_float,
    format_floats,
)

# typing only for type checkers: a scan from the cache never imports it.
TYPE_CHECKING = False
if TYPE_CHECKING:
    from collections.abc import Iterable, Sequence
    from typing import TextIO

    from ..pipeline import Audit

_BOOLEAN = {True: "true", False: "false", None: ""}
_NEEDS_QUOTES = re.compile(r'[,"\r\n]')


def _quoted(text: str) -> str:
    return '"' + text.replace('"', '""') + '"' if _NEEDS_QUOTES.search(text) else text


def text_column(values: list, all_text: bool = False) -> list[str]:
    """Values as CSV fields (``all_text``: they are all ``str`` already); the
    common column that needs no quoting costs one scan, and a column that
    does is quoted once per distinct text (lens names and messages repeat)."""
    texts = values if all_text else [v if isinstance(v, str) else str(v) for v in values]
    if _NEEDS_QUOTES.search("\0".join(texts)) is None:
        return texts
    quoted = {text: _quoted(text) for text in dict.fromkeys(texts)}
    return list(map(quoted.__getitem__, texts))


def write_rows(stream: TextIO, header: Sequence[str], columns: Iterable[Iterable]) -> None:
    """Write a header line and the rows of ``columns`` (the values of each
    column, all of one length) as CSV, each line ending in ``\\n``.

    Values are written as this module writes them: floats in shortest
    round-trip form, ``inf``, or empty for NaN; booleans ``true``/``false``;
    None empty; ints as decimals; text quoted as RFC 4180 says. A column
    of one kind costs one pass.
    """
    fields = []
    for column in columns:
        values = list(column)
        kinds = set(map(type, values))
        if kinds <= {float}:
            fields.append(format_floats(values))
        elif kinds <= {bool, type(None)}:
            fields.append(list(map(_BOOLEAN.__getitem__, values)))
        elif kinds <= {str}:
            fields.append(text_column(values, all_text=True))
        elif kinds <= {int}:
            fields.append(list(map(int.__repr__, values)))
        elif kinds <= {str, int}:
            fields.append(text_column(values))
        else:  # mixed: each value as its kind is written
            fields.append(
                text_column(
                    [
                        _BOOLEAN[v]
                        if v is None or isinstance(v, bool)
                        else format_float(float(v))
                        if isinstance(v, float)
                        else v
                        for v in values
                    ]
                )
            )
    if len(fields) == 1:  # an empty field alone is quoted: an empty line would be no row
        fields[0] = [text or '""' for text in fields[0]]
    stream.write(",".join(text_column(list(header))) + "\n")
    if fields and fields[0]:  # a line per row: cheaper than interleaving every field
        stream.write("\n".join(map(",".join, zip(*fields, strict=True))) + "\n")


def write(audit: Audit, stream: TextIO) -> None:
    """Every entry of an audit, a row each, under a header of
    :data:`~lensaudit.columns.COLUMNS`."""
    write_rows(stream, COLUMNS, audit.columns().values())
