"""Output formats of an audit: one module per format, each with one entry
point, ``write(audit, stream)``.

The row formats (CSV, JSON) render every row at once, column by column: each
column's values become texts in one pass (:mod:`lensaudit.columns`); a CSV
line is its fields joined by commas, a JSON entry the fields interleaved
with the literals between them (:func:`interleaved`).
"""

from __future__ import annotations

import re
from collections.abc import Callable
from importlib import import_module
from itertools import chain

from ..columns import METRIC_COLUMNS
from ..read.records import STATUS_OK

# typing only for type checkers: a scan from the cache never imports it.
TYPE_CHECKING = False
if TYPE_CHECKING:
    from typing import TextIO

    from ..pipeline import Audit

#: Format name -> module under lensaudit.formats.
FORMATS = {"table": "table", "csv": "csv_format", "json": "json_format"}


def writer(name: str) -> Callable[[Audit, TextIO], None]:
    """The ``write(audit, stream)`` function of the named format."""
    return import_module(f"{__name__}.{FORMATS[name]}").write


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


# C0 and C1 control characters, DEL, the line and paragraph separators, the
# marks and overrides of bidirectional text, and lone surrogates (undecodable
# bytes of a file name): text from a database must not move a terminal's
# cursor, split a line, show itself in another order or fail to encode.
UNPRINTABLE = re.compile(
    "[\x00-\x1f\x7f-\x9f\u061c\u200e\u200f\u2028-\u202e\u2066-\u2069\ud800-\udfff]"
)


# The same, but the tab: a diff's lines keep their indentation.
_CONTROL_BUT_TAB = re.compile(
    "[\x00-\x08\x0a-\x1f\x7f-\x9f\u061c\u200e\u200f\u2028-\u202e\u2066-\u2069\ud800-\udfff]"
)


def printable(text: str, tabs: bool = False) -> str:
    """``text`` with control characters shown as ``\\xNN`` escapes (with
    ``tabs``, tabs kept): every text from a database, a file name or the
    command line that reaches a terminal goes through it."""
    return (_CONTROL_BUT_TAB if tabs else UNPRINTABLE).sub(
        lambda m: (
            f"\\x{ord(m.group()):02x}" if ord(m.group()) < 256 else f"\\u{ord(m.group()):04x}"
        ),
        text,
    )
