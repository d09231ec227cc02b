"""What a report shows: the distortion, vignetting and TCA audits of one read of a database.

The database is read once, with its calibrations (:func:`lensaudit.read.read`);
the three audits and the coefficients each distortion entry leaves out (for
the paper comparison) are all made from those tables.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

from .. import pipeline, read

if TYPE_CHECKING:
    from ..pipeline import Audit
    from ..tca import TCAAudit
    from ..vignetting import VignettingAudit


class ReportAudits(NamedTuple):
    """The audits of one database: ``distortion`` (the entries of ``scan``),
    ``vignetting`` and ``tca``, and ``files``, the reader's tables they were
    made from (in the distortion audit's order)."""

    distortion: Audit
    vignetting: VignettingAudit
    tca: TCAAudit
    files: list[read.FileTables]

    @classmethod
    def of_database(cls, database: read.Database, cache: read.Cache | None = None) -> ReportAudits:
        """The audits of a database read with its calibrations; with ``cache``,
        the metrics of unchanged files are taken from it, and what is computed
        is kept there (the cache is saved)."""
        # numpy: `report --help` (this package) imports no heavy module
        from ..tca import TCAAudit
        from ..vignetting import VignettingAudit

        return cls(
            pipeline.audit_database(database, cache),
            VignettingAudit.of_database(database),
            TCAAudit.of_database(database),
            database.files,
        )


def audit(paths: read.Paths = None, *, cache: bool | read.Cache = False) -> ReportAudits:
    """Read a database once, with its calibrations, and audit it (see
    :func:`lensaudit.pipeline.run` for ``paths`` and ``cache``). Raises
    :class:`lensaudit.read.LoadError` when the paths cannot be read at all."""
    store = read.Cache() if cache is True else (cache or None)
    database = read.read(paths, cache=store, calibrations=True)
    return ReportAudits.of_database(database, store)
