"""JSON: the database, the summary (Tables 1 and 2) and every entry.

Non-finite floats are written as the strings ``"inf"``/``"-inf"`` and values
that do not apply as ``null``, so that the output is strict JSON.
"""

from __future__ import annotations

import json
import math
from typing import TYPE_CHECKING, Any, TextIO

from .. import __version__
from ..pipeline import COLUMNS, FLOAT_COLUMNS

if TYPE_CHECKING:
    from ..pipeline import Audit


def _json_float(value: float) -> float | str | None:
    if value != value:
        return None
    if math.isinf(value):
        return "inf" if value > 0 else "-inf"
    return value


def _clean(value: Any) -> Any:
    if isinstance(value, float):
        return _json_float(value)
    if isinstance(value, dict):
        return {k: _clean(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_clean(v) for v in value]
    return value


def document(audit: Audit) -> dict[str, Any]:
    """The JSON document as Python data."""
    columns = audit.columns()
    for name in FLOAT_COLUMNS:
        columns[name] = [_json_float(v) for v in columns[name]]
    entries = [dict(zip(COLUMNS, row, strict=True)) for row in zip(*columns.values(), strict=True)]
    return {
        "lensaudit": __version__,
        "database": {
            "label": audit.source.label,
            "paths": [str(p) for p in audit.source.paths],
            "files": [
                {"file": f.name, "entries": f.entries, "error": f.error} for f in audit.files
            ],
        },
        "summary": _clean(audit.summary.to_dict()),
        "entries": entries,
    }


def write(audit: Audit, stream: TextIO) -> None:
    json.dump(document(audit), stream, indent=1, allow_nan=False)
    stream.write("\n")
