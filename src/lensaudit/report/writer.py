"""Write a report directory: CSV, JSON, Markdown tables, Figure 5 and report.html.

Existing files are replaced only when asked (``force``); every file is
written to a temporary name first and renamed, so that an interrupted run
never leaves a half-written file under a report name. ``entries.csv`` is
``scan``'s CSV; every other CSV file is written by
:func:`lensaudit.formats.csv_format.write_rows`.
"""

from __future__ import annotations

import io
import json
import math
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..formats import writer
from ..version import __version__
from ..writing import OutputSet
from . import calibrations, provenance, tables

if TYPE_CHECKING:
    from ..pipeline import Audit
    from .audits import ReportAudits
    from .drawing import Figure5Drawing
    from .histogram import Histogram
    from .provenance import Provenance

#: Files of every report, in the order they are written.
REPORT_FILES = (
    "entries.csv",
    "summary.json",
    "table1.md",
    "table1.csv",
    "table2.md",
    "table2.csv",
    "folding.csv",
    "vignetting.csv",
    "tca.csv",
    "fig5_r_normalized.csv",
    "fig5_r_normalized.png",
    "fig5_r_normalized.svg",
    "report.html",
)
#: Written with ``paper`` values only.
PAPER_FILE = "paper_comparison.md"

FOLDING_COLUMNS = (
    "file",
    "line",
    "maker",
    "lens",
    "type",
    "focal",
    "crop_factor",
    "aspect_ratio",
    "model",
    "r_max",
    "d_max",
    "r_normalized",
    "r_normalized_paper",
)


class ReportExistsError(Exception):
    """The output directory already holds report files (and ``force`` was not given)."""

    def __init__(self, directory: Path, existing: list[str]) -> None:
        super().__init__(
            f"{directory} already holds {', '.join(existing)}; use --force to replace them"
        )
        self.existing = existing


def planned_files(paper: bool = False) -> list[str]:
    """Names of the files a report writes."""
    return list(REPORT_FILES) + ([PAPER_FILE] if paper else [])


def _json_ready(value: Any) -> Any:
    if isinstance(value, float):
        if math.isnan(value):
            return None
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
    if isinstance(value, dict):
        return {k: _json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_ready(v) for v in value]
    return value


def folding_columns(audit: Audit) -> list[list[Any]]:
    """``folding.csv``'s columns: the entries that fold inside their image, by r_normalized."""
    folding = audit.summary.folding
    return [[column[i] for i in folding] for column in map(audit.column, FOLDING_COLUMNS)]


def write_report(
    audits: ReportAudits,
    directory: str | os.PathLike[str],
    force: bool = False,
    paper_values: dict[str, Any] | None = None,
    drawing: Figure5Drawing | None = None,
) -> list[Path]:
    """Write the report of a database's ``audits`` (see
    :func:`lensaudit.report.audit`) into ``directory`` (created if needed).

    Raises :class:`ReportExistsError` when a report file is already there and
    ``force`` is false; ``OSError`` when the directory cannot be written.
    With ``paper_values`` (see :func:`lensaudit.report.paper.load_values`)
    the paper comparison is added. Figure 5 is drawn by ``drawing`` (see
    :mod:`lensaudit.report.drawing`; here without it). Returns the paths written.
    """
    # numpy: `report --help` (this package) imports no heavy module; matplotlib
    # is imported where Figure 5 is drawn (report.drawing)
    from . import histogram, html
    from .drawing import Figure5Drawing

    audit = audits.distortion
    directory = Path(directory)
    _prepare_directory(directory, planned_files(paper_values is not None), force)

    facts = provenance.collect(audit)
    table1 = tables.table1_rows(audit.summary)
    table2 = tables.table2_rows(audit.summary)
    fig5 = histogram.figure5(audit)
    if drawing is None:
        drawing = Figure5Drawing()
    drawing.send(fig5)
    comparison = None
    if paper_values is not None:
        from . import paper  # numpy: `report --help` (this package) imports no heavy module

        comparison = paper.compare(
            audit, paper_values, paper.omitted_coefficients(audit, audits.files)
        )

    written = []
    # All files or none: each is written beside its name, all renamed at the end.
    with OutputSet() as outputs:
        for name, text in _data_files(audits, facts, table1, table2, fig5).items():
            outputs.write_text(directory / name, text)
            written.append(directory / name)
        # The page around Figure 5 is made while the figure is drawn.
        before, after = html.render_around_figure5(
            audit,
            facts,
            fig5,
            table1,
            table2,
            comparison,
            calibrations.section(audits.vignetting, audits.tca),
        )
        png_bytes, svg = drawing.result()
        png = directory / "fig5_r_normalized.png"
        outputs.write_bytes(png, png_bytes)
        # Drawn once as SVG: the same text is the .svg file and the page's figure.
        outputs.write_text(directory / "fig5_r_normalized.svg", svg)
        written += [png, directory / "fig5_r_normalized.svg"]
        outputs.write_text(directory / "report.html", before + html.inline_svg(svg, "fig5") + after)
        written.append(directory / "report.html")
        if comparison is not None:
            from . import paper  # numpy: `report --help` (this package) imports no heavy module

            outputs.write_text(directory / PAPER_FILE, paper.markdown(comparison))
            written.append(directory / PAPER_FILE)
    return written


def check_directory(directory: str | os.PathLike[str], names: list[str], force: bool) -> None:
    """Raise :class:`ReportExistsError` when ``directory`` holds any of ``names``
    (report files) and ``force`` is false: asked before the work as well."""
    directory = Path(directory)
    existing = [n for n in names if (directory / n).exists()]
    if existing and not force:
        raise ReportExistsError(directory, existing)


def _prepare_directory(directory: Path, names: list[str], force: bool) -> None:
    """Create ``directory``; refuse one that holds any of ``names``, unless ``force``."""
    if directory.exists() and not directory.is_dir():
        raise NotADirectoryError(f"{directory} exists and is not a directory")
    check_directory(directory, names, force)
    directory.mkdir(parents=True, exist_ok=True)


def _data_files(
    audits: ReportAudits,
    facts: Provenance,
    table1: list[tuple[Any, ...]],
    table2: list[tuple[Any, ...]],
    fig5: Histogram,
) -> dict[str, str]:
    """The report's text files other than report.html, by name, in the order written."""
    audit = audits.distortion
    buffer = io.StringIO()
    writer("csv")(audit, buffer)
    return {
        "entries.csv": buffer.getvalue(),
        "summary.json": _summary_json(audit, facts, fig5),
        "table1.md": tables.to_markdown(tables.TABLE1_HEADER, table1, tables.TABLE1_CAPTION),
        "table1.csv": tables.to_csv(tables.TABLE1_HEADER, table1),
        "table2.md": tables.to_markdown(tables.TABLE2_HEADER, table2, tables.TABLE2_CAPTION),
        "table2.csv": tables.to_csv(tables.TABLE2_HEADER, table2),
        "folding.csv": tables.csv_text(FOLDING_COLUMNS, folding_columns(audit)),
        "vignetting.csv": calibrations.csv_text(audits.vignetting),
        "tca.csv": calibrations.csv_text(audits.tca),
        "fig5_r_normalized.csv": tables.csv_text(
            ("bin_low", "bin_high", "count", "count_paper_units"), zip(*fig5.rows(), strict=True)
        ),
    }


def _summary_json(audit: Audit, facts: Provenance, fig5: Histogram) -> str:
    """``summary.json``: provenance without the date, the summary, Figure 5's counts
    and where the folding entries are."""
    from . import histogram  # numpy: `report --help` (this package) imports no heavy module

    summary = audit.summary
    document = {
        "lensaudit": __version__,
        # Without the date: the same database gives the same bytes.
        # The date is on report.html only.
        "provenance": {k: v for k, v in facts.to_dict().items() if k != "generated"},
        "summary": summary.to_dict(),
        "figure5": {
            "population": histogram.POPULATION,
            "entries": fig5.entries,
            "below_one": fig5.below_one,
            "below_one_paper": fig5.below_one_paper,
        },
        "folding": [f"{audit.entries[i].file}:{audit.entries[i].line}" for i in summary.folding],
    }
    return json.dumps(_json_ready(document), indent=1, allow_nan=False) + "\n"
