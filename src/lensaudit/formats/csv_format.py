"""CSV: one row per distortion entry, columns as :data:`lensaudit.pipeline.COLUMNS`.

Floats are written in shortest round-trip form, ``inf`` for infinite values
and empty for values that do not apply; booleans as ``true``/``false``. Text
is quoted as RFC 4180 says (only where it holds a comma, quote or line break).
"""

from __future__ import annotations

import re
from typing import TYPE_CHECKING, TextIO

from ..pipeline import COLUMNS, FLOAT_COLUMNS, format_floats

if TYPE_CHECKING:
    from ..pipeline import Audit

_BOOLEAN = {True: "true", False: "false", None: ""}
_NEEDS_QUOTES = re.compile(r'[,"\r\n]')


def _quoted(text: str) -> str:
    return '"' + text.replace('"', '""') + '"' if _NEEDS_QUOTES.search(text) else text


def text_column(values: list) -> list[str]:
    """Values as CSV fields; the common column that needs no quoting costs one scan."""
    texts = [v if isinstance(v, str) else str(v) for v in values]
    if _NEEDS_QUOTES.search("\0".join(texts)):
        return [_quoted(text) for text in texts]
    return texts


#: Rows formatted at a time: the text of a whole database at once costs more
#: memory, and in a fresh process memory costs time.
CHUNK_ROWS = 256


def _fields(name: str, values: list) -> list[str]:
    if name in FLOAT_COLUMNS:
        return format_floats(values)
    if name == "folds_in_image":
        return [_BOOLEAN[v] for v in values]
    if name == "line":
        return list(map(str, values))
    return text_column(values)


def write(audit: Audit, stream: TextIO) -> None:
    columns = [audit.column(name) for name in COLUMNS]
    stream.write(",".join(COLUMNS) + "\n")
    for start in range(0, len(audit), CHUNK_ROWS):
        fields = [
            _fields(name, values[start : start + CHUNK_ROWS])
            for name, values in zip(COLUMNS, columns, strict=True)
        ]
        stream.write("\n".join(map(",".join, zip(*fields, strict=True))) + "\n")
