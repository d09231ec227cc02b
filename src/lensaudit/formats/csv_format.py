"""CSV: one row per distortion entry, columns as :data:`lensaudit.pipeline.COLUMNS`.

Floats are written in shortest round-trip form, ``inf`` for infinite values
and empty for values that do not apply; booleans as ``true``/``false``.
"""

from __future__ import annotations

import csv
from typing import TYPE_CHECKING, TextIO

from ..pipeline import COLUMNS, FLOAT_COLUMNS, format_floats

if TYPE_CHECKING:
    from ..pipeline import Audit

_BOOLEAN = {True: "true", False: "false", None: ""}


def write(audit: Audit, stream: TextIO) -> None:
    columns = []
    for name in COLUMNS:
        values = audit.column(name)
        if name in FLOAT_COLUMNS:
            values = format_floats(values)
        elif name == "folds_in_image":
            values = [_BOOLEAN[v] for v in values]
        columns.append(values)
    out = csv.writer(stream, lineterminator="\n")
    out.writerow(COLUMNS)
    out.writerows(zip(*columns, strict=True))
