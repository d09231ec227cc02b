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


def write(audit: Audit, stream: TextIO) -> None:
    columns = []
    for name in COLUMNS:
        values = audit.column(name)
        if name in FLOAT_COLUMNS:
            columns.append(format_floats(values))
        elif name == "folds_in_image":
            columns.append([_BOOLEAN[v] for v in values])
        elif name == "line":
            columns.append(list(map(str, values)))
        else:
            columns.append(text_column(values))
    stream.write(",".join(COLUMNS) + "\n")
    if columns[0]:
        stream.write("\n".join(map(",".join, zip(*columns, strict=True))) + "\n")
