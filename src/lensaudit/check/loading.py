"""``liblensfun-refuses``: the first spot of a file where Lensfun master's
liblensfun stops loading it.

The reader records that spot (:attr:`lensaudit.read.FileTables.refusal`,
judged by :mod:`lensaudit.read.liblensfun`): an element, attribute or value
liblensfun does not know, an element in the wrong parent, text where none
may stand, a lens, camera or mount definition its ``Check()`` refuses, a
database version it does not read, a byte-order mark. liblensfun keeps the
lenses it completed before that spot and loses every one after it, so one
error hides the rest of the file from every program that uses Lensfun.

A file that is not well-formed XML is ``xml-error`` alone: GMarkup refuses
such markup too, and the finding is not repeated, unless liblensfun stops
at an earlier line for a reason of its own. A file whose root is not
``<lensdatabase>`` is ``not-a-database`` alone. Where the entries of the
file already say what liblensfun refuses, they say it alone: a
``<distortion>``, ``<vignetting>`` or ``<tca>`` outside a lens is
``no-lens`` (liblensfun: "Inappropriate context"), and the entries of a
lens whose crop factor is not positive are ``bad-value`` (liblensfun:
"Invalid lens definition"); liblensfun stops reading the file at the first
of them. The finding is matched against a baseline by the file's name and
the reason, not by its line.
"""

from __future__ import annotations

from collections.abc import Iterable

from ..read import FileTables
from ..read.liblensfun import NOT_WELL_FORMED
from ..read.records import STATUS_BAD_VALUE, STATUS_NO_LENS
from .parsing import ParsedSource
from .result import (
    LIBLENSFUN_REFUSES,
    NOT_A_DATABASE,
    SEVERITY_ERROR,
    UNREADABLE,
    Finding,
    Identified,
    clip,
)


def liblensfun_refusals(file: ParsedSource) -> Iterable[Identified]:
    """The ``liblensfun-refuses`` finding of one file, if liblensfun refuses it
    for a reason no other file-level finding gives."""
    refusal = file.tables.refusal
    if refusal is None:
        return
    line, reason, kept = refusal
    problem = file.problem
    if problem is not None and (
        problem.code in (NOT_A_DATABASE, UNREADABLE) or reason.startswith(NOT_WELL_FORMED)
    ):
        return
    if _told_by_entries(file.tables, refusal):
        return
    lost = len(file.tables.lenses) - kept
    message = clip(
        f"liblensfun (Lensfun master's) stops reading at line {line}: {reason}; "
        f"{_lenses(lost)} from there on {'are' if lost != 1 else 'is'} lost to its users"
        f" (it keeps the {_lenses(kept)} before)"
    )
    finding = Finding(SEVERITY_ERROR, LIBLENSFUN_REFUSES, file.source.display, line, 0, message)
    identity = (SEVERITY_ERROR, LIBLENSFUN_REFUSES, file.source.file_name, reason)
    yield Identified(finding, (identity,), (file.source.file_name,))


#: The entries whose place liblensfun checks, and lensaudit too (``no-lens``).
_ENTRIES = ("distortion", "vignetting", "tca")


def _told_by_entries(tables: FileTables, refusal: tuple[int, str, int]) -> bool:
    """Whether entry findings of the file say why liblensfun refuses it: an
    entry outside a lens (``no-lens`` at the spot), or a lens crop factor
    that is not positive (``bad-value`` on an entry of the refused lens)."""
    line, reason, kept = refusal
    tables_of = (
        (tables.distortion, tables.lens_of_row),
        (tables.vignetting or [], tables.lens_of_vignetting or []),
        (tables.tca or [], tables.lens_of_tca or []),
    )
    if any(reason.startswith(f"<{entry}> in the wrong place") for entry in _ENTRIES):
        # liblensfun's line is just past the start tag, the entry's that of its start tag.
        return any(
            row[-2] == STATUS_NO_LENS and row[0] in (line, line - 1)
            for rows, _ in tables_of
            for row in rows
        )
    if reason.startswith("a <lens> whose crop factor"):
        return any(
            lens == kept and row[-2] == STATUS_BAD_VALUE and "crop factor" in row[-1]
            for rows, lens_of in tables_of
            for row, lens in zip(rows, lens_of, strict=True)
        )
    return False


def _lenses(count: int) -> str:
    return f"{count} lens" if count == 1 else f"{count} lenses"


__all__ = ["liblensfun_refusals"]
