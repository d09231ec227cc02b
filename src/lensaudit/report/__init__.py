"""Reports of an audit: the paper's tables and figures, and a self-contained HTML page.

:func:`audit` reads a database once and makes the audits a report shows
(:class:`ReportAudits`); :func:`write_report` writes them as a report
directory. The stages it uses are importable on their own:
:mod:`~lensaudit.report.tables` (Tables 1-2),
:mod:`~lensaudit.report.histogram` (Figure 5 data),
:mod:`~lensaudit.report.figures` (matplotlib drawing),
:mod:`~lensaudit.report.html` (the page), :mod:`~lensaudit.report.paper`
(the paper's printed values beside an audit), plus the per-entry views
:mod:`~lensaudit.report.curves`, :mod:`~lensaudit.report.warp` and
:mod:`~lensaudit.report.rmax_map` used by ``lensaudit plot``.
"""

from __future__ import annotations

from .audits import ReportAudits, audit
from .writer import REPORT_FILES, ReportExistsError, planned_files, write_report

__all__ = [
    "REPORT_FILES",
    "ReportAudits",
    "ReportExistsError",
    "audit",
    "planned_files",
    "write_report",
]
