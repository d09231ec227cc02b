"""The report's vignetting and TCA section, and the vignetting.csv and tca.csv files.

The audits (see :mod:`lensaudit.calibrations`) are made from the same read
of the database as the distortion audit (:mod:`lensaudit.report.audits`);
the section gives the counts by severity and the worst entries.
"""

from __future__ import annotations

from html import escape
from typing import TYPE_CHECKING, Any

from . import tables

if TYPE_CHECKING:
    from ..tca import TCAAudit
    from ..vignetting import VignettingAudit

#: How many of the worst vignetting entries the page lists.
WORST_SHOWN = 40


def csv_text(calibration_audit: Any) -> str:
    """Every entry of one kind as CSV, the columns of ``scan --kind``."""
    return tables.csv_text(calibration_audit.COLUMNS, calibration_audit.columns().values())


def _rows_table(table_id: str, caption: str, header: list[str], rows: list[list[str]]) -> str:
    numeric = [h in NUMERIC for h in header]
    head = "".join(
        f'<th scope="col"{" class=n" if n else ""}>{escape(h)}</th>'
        for h, n in zip(header, numeric, strict=True)
    )
    # The page's stylesheet keeps a file:line (class "where") on one line.
    cell_classes = [
        " class=n" if n else (" class=where" if h == "where" else "")
        for h, n in zip(header, numeric, strict=True)
    ]
    body = "".join(
        "<tr>"
        + "".join(
            f"<td{cell_class}>{escape(c)}</td>"
            for c, cell_class in zip(row, cell_classes, strict=True)
        )
        + "</tr>"
        for row in rows
    )
    return (
        f'<div class="scroll"><table id="{table_id}"><caption>{escape(caption)}</caption>'
        f"<thead><tr>{head}</tr></thead><tbody>{body}</tbody></table></div>"
    )


NUMERIC = frozenset(
    {"entries", "audited", "error", "warning", "notice", "c_min", "r_zero", "r_min", "focal"}
    | {"f/", "distance", "r_fold_red", "r_fold_blue", "r_corner", "not audited"}
)


def _counts(vignetting_audit: VignettingAudit, tca_audit: TCAAudit) -> str:
    v, t = vignetting_audit.summary(), tca_audit.summary()
    rows = [
        [
            "vignetting",
            str(v["entries"]),
            str(v["audited"]),
            str(v["severities"]["error"]),
            str(v["severities"]["warning"]),
            str(v["severities"]["notice"]),
        ],
        [
            "tca",
            str(t["entries"]),
            str(t["audited"]),
            str(t["severities"]["error"]),
            str(t["severities"]["warning"]),
            str(t["severities"]["notice"]),
        ],
    ]
    return _rows_table(
        "calibration-counts",
        "Entries by severity: vignetting error C <= 0 inside the image, warning C < 0.1, "
        "notice C not monotone; TCA error a channel folds inside the image.",
        ["kind", "entries", "audited", "error", "warning", "notice"],
        rows,
    )


def _worst(vignetting_audit: VignettingAudit) -> str:
    worst = vignetting_audit.worst()
    if not worst:
        return '<p id="vignetting-worst">No vignetting entry falls below 0.1 inside its image.</p>'
    header = ["c_min", "r_zero", "r_min", "maker", "lens", "focal", "f/", "distance", "where"]
    rows = [
        [cells[h] for h in header]
        for cells in map(vignetting_audit.worst_cells, worst[:WORST_SHOWN])
    ]
    more = len(worst) - len(rows)
    caption = f"The {len(rows)} lowest minima of C inside the image" + (
        f" ({more} more in vignetting.csv)" if more else ""
    )
    return _rows_table("vignetting-worst", caption, header, rows)


def _tca_folding(tca_audit: TCAAudit) -> str:
    folding = tca_audit.folding()
    if not folding:
        return (
            '<p id="tca-folding">No TCA entry folds inside its image: every channel\'s '
            "r_d increases up to the image corner (or circle).</p>"
        )
    from ..tca import FOLDING_HEADER  # numpy: `report --help` imports no heavy module

    return _rows_table(
        "tca-folding",
        "TCA entries with a channel that folds inside the image",
        list(FOLDING_HEADER),
        list(map(tca_audit.folding_row, folding)),
    )


def section(vignetting_audit: VignettingAudit, tca_audit: TCAAudit) -> str:
    """The report's section on vignetting and TCA, as HTML."""
    v = vignetting_audit.summary()
    problems = [
        f"{kind}: {sum(n for s, n in counts.items() if s != 'ok')} not audited"
        for kind, counts in (("vignetting", v["statuses"]), ("tca", tca_audit.statuses()))
        if any(s != "ok" for s in counts)
    ]
    problems_html = (
        f'<p class="note">{escape("; ".join(problems))} (see the status column of '
        "vignetting.csv and tca.csv).</p>"
        if problems
        else ""
    )
    return f"""<section id="vignetting-tca"><h2>Vignetting and TCA</h2>
<p class="note">Vignetting: the correction divides each pixel by C(r) = 1 + k1 r^2 + k2 r^4 +
k3 r^6, with r = 1 at half the diagonal (the frame corner; a circular fisheye is judged at its
image circle). Where C &lt;= 0 the correction divides by zero or flips the pixel's sign
(liblensfun writes black); below 0.1 it multiplies the pixel and its noise more than tenfold.
{v["zero_in_image"]} entries reach C &lt;= 0 inside their image, {v["low_in_image"]} fall
below 0.1, and in {v["not_monotone"]} C turns inside the image. TCA: each of red and blue is
scaled radially, r_d = r (b r^2 + c r + v) in Hugin units; a channel whose r_d stops increasing
inside the image folds.</p>
{_counts(vignetting_audit, tca_audit)}
{problems_html}
<h3>Vignetting entries below 0.1</h3>
{_worst(vignetting_audit)}
<h3>TCA entries that fold</h3>
{_tca_folding(tca_audit)}
</section>"""
