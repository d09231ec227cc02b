"""Tables 1 and 2 of the paper, in its layout, as Markdown and CSV text.

Table 1 counts audited entries per model by finite or infinite r_max;
Table 2 splits the finite ones by where D(r) goes beyond r_max. The rows come
from :mod:`lensaudit.summary`; this module only lays them out. Its
:func:`csv_text` makes the text of every CSV file of the report but
``entries.csv`` (``scan``'s CSV).
"""

from __future__ import annotations

import csv
import io
import re
from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING, Any

from ..formats.csv_format import write_rows

if TYPE_CHECKING:
    from ..summary import Summary

TABLE1_HEADER = ("model", "finite", "infinite", "%finite", "total")
TABLE2_HEADER = ("model", "positive", "negative", "%negative", "total")

TABLE1_CAPTION = "Table 1: entries with a finite maximum valid radius r_max (the model folds back)."
TABLE2_CAPTION = (
    "Table 2: entries with a finite r_max by the sign of D(r) beyond it "
    "(negative: D passes back through the image centre)."
)

Row = tuple[str, int, int, str, int]


def percent(value: float) -> str:
    """A percentage with two decimals as the paper prints it, "" when undefined (0 of 0)."""
    return "" if value != value else f"{value:.2f}"


def table1_rows(summary: Summary) -> list[Row]:
    """Table 1 rows: model, finite, infinite, %finite (two decimals), total."""
    return [
        (r.model, r.finite, r.infinite, percent(r.percent_finite), r.total) for r in summary.rows
    ]


def table2_rows(summary: Summary) -> list[Row]:
    """Table 2 rows: model, positive, negative, %negative (two decimals), total finite."""
    return [
        (r.model, r.positive, r.negative, percent(r.percent_negative), r.finite)
        for r in summary.rows
    ]


def csv_text(header: Sequence[str], columns: Iterable[Iterable[Any]]) -> str:
    """CSV text of a header line and columns of values, written by
    :func:`lensaudit.formats.csv_format.write_rows`."""
    out = io.StringIO()
    write_rows(out, header, columns)
    return out.getvalue()


def to_csv(header: Sequence[str], rows: Sequence[Sequence[object]]) -> str:
    """CSV text of a table with a header line; percentages without the % sign."""
    return csv_text(header, zip(*rows, strict=True))


def to_markdown(header: Sequence[str], rows: Sequence[Sequence[object]], caption: str = "") -> str:
    """A GitHub-flavoured Markdown table, numbers right-aligned, percentages with %."""
    cells = [
        [_markdown_cell(name, value) for name, value in zip(header, row, strict=True)]
        for row in rows
    ]
    widths = [max(len(str(h)), *(len(row[i]) for row in cells)) for i, h in enumerate(header)]
    lines = []
    if caption:
        lines += [caption, ""]
    lines.append("| " + " | ".join(h.ljust(w) for h, w in zip(header, widths, strict=True)) + " |")
    lines.append(
        "| "
        + " | ".join(("-" * (w - 1) + ":") if i else "-" * w for i, w in enumerate(widths))
        + " |"
    )
    for row in cells:
        lines.append(
            "| "
            + " | ".join(
                c.rjust(w) if i else c.ljust(w)
                for i, (c, w) in enumerate(zip(row, widths, strict=True))
            )
            + " |"
        )
    return "\n".join(lines) + "\n"


def _markdown_cell(column: str, value: object) -> str:
    text = str(value)
    if column.startswith("%") and re.fullmatch(r"-?\d+(\.\d+)?", text):
        return text + "%"
    return text.replace("|", "\\|")


def read_csv(text: str) -> list[list[str]]:
    """Rows of a table CSV (header first), for comparing tables as data."""
    return list(csv.reader(io.StringIO(text)))
