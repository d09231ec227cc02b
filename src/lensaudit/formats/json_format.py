"""JSON: the database, the summary (Tables 1 and 2) and every entry.

Non-finite floats are written as the strings ``"inf"``/``"-inf"`` and values
that do not apply as ``null``, so that the output is strict JSON.

The document is laid out as ``json.dump(document(audit), stream, indent=1)``
lays it out, except that each entry is one line, as ``json.dumps(entry,
separators=(", ", ": "))`` writes it: grep and diff show an entry whole, and
the text is an eighth shorter than with a line per key. The entries are
rendered all at once, column by column, as the CSV rows are (:func:`rows`).
"""

from __future__ import annotations

import json
import math
from json.encoder import encode_basestring_ascii

from ..columns import (
    COLUMNS,
    FLOAT_COLUMNS,
    LEADING_COLUMNS,
    METRIC_COLUMNS,
    TAIL_NAMES,
    TRAILING_COLUMNS,
    float_texts,
)
from ..version import __version__
from . import interleaved, metric_fields

# typing only for type checkers: a scan from the cache never imports it.
TYPE_CHECKING = False
if TYPE_CHECKING:
    from typing import Any, TextIO

    from ..pipeline import Audit

# An entry is a line of its own, two levels down the document: indented by 2,
# items separated by ", ".
_OPEN, _CLOSE, _SEPARATOR = "  {", "}", ", "
_SPECIAL_FLOATS = {"nan": "null", "inf": '"inf"', "-inf": '"-inf"'}
_TAILS = {sign: encode_basestring_ascii(name) for sign, name in TAIL_NAMES.items()}
_BOOLEAN = {True: "true", False: "false"}
_ENTRIES_END = '"entries": []\n}'


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


def _floats(values: list[float]) -> list[str]:
    # float.__repr__ is what json writes for a finite float.
    return float_texts(values, _SPECIAL_FLOATS)


def _values(name: str, values: list) -> list[str]:
    """One entry column as JSON values."""
    if name in FLOAT_COLUMNS:
        return _floats(values)
    if name == "line":
        return list(map(int.__repr__, values))
    return list(map(encode_basestring_ascii, values))


def _template(names: tuple[str, ...], first: bool, last: bool) -> str:
    """The text of a run of an entry's items, with ``%s`` where the values go."""
    items = _SEPARATOR.join(f"{encode_basestring_ascii(name)}: %s" for name in names)
    return (_OPEN if first else "") + items + (_CLOSE if last else _SEPARATOR)


_LEADING = _template(LEADING_COLUMNS, first=True, last=False)
_METRICS = _template(METRIC_COLUMNS, first=False, last=False)
_TRAILING = _template(TRAILING_COLUMNS, first=False, last=True)


#: The text of an entry around its values, with ",\n" after it (see :func:`rows`).
_LITERALS = (_LEADING + _METRICS + _TRAILING + ",\n").split("%s")


def rows(columns: dict[str, list], metrics: dict[str, list]) -> str:
    """Whole entries, separated by ",\\n", from the entry columns (with
    ``file``) and the metric columns of the same entries."""
    if not columns["status"]:
        return ""
    fields = [_values(name, columns[name]) for name in LEADING_COLUMNS]
    fields += metric_fields(metrics, columns["status"], _floats, _TAILS, _BOOLEAN, "null")
    fields += [_values(name, columns[name]) for name in TRAILING_COLUMNS]
    return interleaved(_LITERALS, fields)[:-2]  # no ",\n" after the last


def _head(audit: Audit) -> dict[str, Any]:
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
    }


def document(audit: Audit) -> dict[str, Any]:
    """The JSON document as Python data."""
    columns = audit.columns()
    for name in FLOAT_COLUMNS:
        columns[name] = [_json_float(v) for v in columns[name]]
    entries = [dict(zip(COLUMNS, row, strict=True)) for row in zip(*columns.values(), strict=True)]
    return {**_head(audit), "entries": entries}


def write(audit: Audit, stream: TextIO) -> None:
    head = json.dumps({**_head(audit), "entries": []}, indent=1, allow_nan=False)
    assert head.endswith(_ENTRIES_END)
    columns = {name: audit.entry_column(name) for name in (*LEADING_COLUMNS, *TRAILING_COLUMNS)}
    text = rows(columns, audit.metric_columns())
    if not text:
        stream.write(head + "\n")
        return
    # As json.dump lays out a list that is not empty.
    stream.write(head[: -len("[]\n}")] + "[\n")
    stream.write(text)
    stream.write("\n ]\n}\n")
