"""JSON: the verdict, counts, files and every finding (strict JSON, no NaN).

``summary.failed`` is the verdict; ``files[].entries`` counts each file's
``<distortion>`` elements; ``findings[].entry_key`` is [maker, lens, crop
factor, model, focal] for an entry, [maker, lens, crop factor] for a lens
and [] for a file; ``findings[].related`` lists the ``{"file", "line"}`` of
the entry or lens that a duplicate repeats.
"""

from __future__ import annotations

import json
import math
from typing import TYPE_CHECKING, Any, TextIO

from ..version import __version__

if TYPE_CHECKING:
    from ..check import CheckResult


def _value(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return None if value != value else ("inf" if value > 0 else "-inf")
    return value


def document(result: CheckResult) -> dict[str, Any]:
    """The JSON document as Python data."""
    counts = result.counts()
    return {
        "lensaudit": __version__,
        "database": result.database,
        "baseline": result.baseline,
        "margin": result.margin,
        "summary": {
            "failed": result.failed,
            "files": len(result.files),
            "entries": result.entries,
            "errors": counts["error"],
            "warnings": counts["warning"],
            "notices": counts["notice"],
            "known": counts["known"],
            "resolved": result.resolved,
        },
        "files": [{"file": f.file, "entries": f.entries, "error": f.error} for f in result.files],
        "findings": [
            {
                "severity": f.severity,
                "code": f.code,
                "file": f.file,
                "line": f.line,
                "column": f.column,
                "message": f.message,
                "entry_key": [_value(v) for v in f.entry_key],
                "known": f.known,
                "fails": f.fails,
                "related": [{"file": file, "line": line} for file, line in f.related],
            }
            for f in result.findings
        ],
    }


def write(result: CheckResult, stream: TextIO) -> None:
    json.dump(document(result), stream, indent=1, allow_nan=False)
    stream.write("\n")
