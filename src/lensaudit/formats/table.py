"""The terminal summary: database, Tables 1 and 2, and the entries that fold."""

from __future__ import annotations

from collections.abc import Sequence

from ..version import __version__
from . import printable

# typing only for type checkers: a scan from the cache never imports it.
TYPE_CHECKING = False
if TYPE_CHECKING:
    from typing import TextIO

    from ..pipeline import Audit

#: How many not-audited entries are listed by name before the rest are counted.
PROBLEMS_SHOWN = 10


def text_table(
    header: Sequence[str], rows: Sequence[Sequence[object]], right: Sequence[bool] | None = None
) -> list[str]:
    """Rows aligned in columns under a header; numbers right-aligned by default."""
    cells = [[str(c) for c in header]] + [[str(c) for c in row] for row in rows]
    widths = [max(len(row[i]) for row in cells) for i in range(len(header))]
    if right is None:
        right = [i > 0 for i in range(len(header))]
    lines = []
    for row in cells:
        parts = [
            cell.rjust(w) if r else cell.ljust(w)
            for cell, w, r in zip(row, widths, right, strict=True)
        ]
        lines.append("  ".join(parts).rstrip())
    return lines


def _percent(value: float) -> str:
    return "-" if value != value else f"{value:.2f}%"


def _focal(value: float) -> str:
    return f"{value:g}"


def lines(audit: Audit) -> list[str]:
    """The summary as lines of text."""
    summary = audit.summary
    out = [
        f"lensaudit {__version__}: {printable(audit.source.label)}",
        f"{summary.files} file{'s' if summary.files != 1 else ''}, "
        f"{summary.entries} distortion entries, {summary.audited} audited",
        "",
    ]

    out.append("Table 1: entries whose distortion folds back (finite r_max)")
    out += text_table(
        ["model", "finite", "infinite", "%finite", "total"],
        [
            [r.model, r.finite, r.infinite, _percent(r.percent_finite), r.total]
            for r in summary.rows
        ],
    )
    out.append("")
    out.append("Table 2: where D(r) goes beyond r_max (negative: back through the image)")
    out += text_table(
        ["model", "positive", "negative", "%negative", "total"],
        [
            [r.model, r.positive, r.negative, _percent(r.percent_negative), r.finite]
            for r in summary.rows
        ],
    )
    out.append("")

    folding = summary.folding
    out.append(
        "Entries that fold inside their own image, D(r_max) < image corner "
        f"(or circle, for circular fisheyes): {len(folding)}"
    )
    if folding:
        r_normalized = audit.metric_columns()["r_normalized"]
        rows = []
        for i in folding:
            # One entry at a time: a warm scan then builds no other entry object.
            entry = audit.entry(i)
            rows.append(
                [
                    f"{r_normalized[i]:.3f}",
                    printable(entry.maker),
                    printable(entry.lens),
                    _focal(entry.focal),
                    f"{entry.crop_factor:g}",
                    printable(entry.type),
                    printable(f"{entry.file}:{entry.line}"),
                ]
            )
        out += text_table(
            ["r_normalized", "maker", "lens", "focal", "crop", "type", "where"],
            rows,
            right=[True, False, False, True, True, False, False],
        )
    out.append(
        f"(With the paper's mixed-unit image corner, hypot(18, 12) / (crop * focal), "
        f"{summary.folding_paper_units_rectilinear} rectilinear entries would be "
        f"flagged instead; see column r_normalized_paper.)"
    )

    out += _not_audited(audit)
    out.append("")
    out.append(
        "Next: every entry with its numbers, `lensaudit scan --format csv`; "
        + ("refit the folds, `lensaudit fix`; " if folding else "")
        + "a gate for database changes, `lensaudit check`."
    )
    return out


def _not_audited(audit: Audit) -> list[str]:
    """The lines on the entries that were not audited (none if every one was)."""
    problems = [i for i, status in enumerate(audit.column("status")) if status != "ok"]
    if not problems:
        return []
    counts = ", ".join(f"{n} {s}" for s, n in audit.summary.statuses.items() if s != "ok")
    out = ["", f"Not audited: {len(problems)} entries ({counts})"]
    for entry in map(audit.entry, problems[:PROBLEMS_SHOWN]):
        where = printable(f"{entry.file}:{entry.line}")
        out.append(f"  {where}: {entry.status}: {printable(entry.message)}")
    if len(problems) > PROBLEMS_SHOWN:
        out.append(f"  ... and {len(problems) - PROBLEMS_SHOWN} more (all of them: --format csv)")
    return out


def write(audit: Audit, stream: TextIO) -> None:
    stream.write("\n".join(lines(audit)) + "\n")
