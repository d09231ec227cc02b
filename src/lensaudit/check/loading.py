"""What Lensfun master's liblensfun makes of a file: ``liblensfun-refuses``,
the first spot where it stops loading it, and ``encoding-mismatch``, a file
it reads as UTF-8 whose XML declaration says otherwise.

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
``<lensdatabase>`` is ``not-a-database`` alone. An entry finding that
names the same fault (``no-lens`` for a ``<distortion>`` outside a lens,
``bad-value`` on the entries of a lens whose crop factor is not positive)
says what is wrong with the entry, not that liblensfun drops the file from
there on: the refusal is reported beside it, with the lenses lost. The
finding is matched against a baseline by the file's name and the reason,
not by its line.

liblensfun (GLib's GMarkup) reads every file as UTF-8 and takes the XML
declaration for a processing instruction; so does the reader. A file
declared ISO-8859-1 whose bytes are UTF-8 loads, with the names meant, but
every reader that follows the declaration (Python's, libxml2's) reads other
names ("GÃ¶rlitz" for "Görlitz"): ``encoding-mismatch``, a warning on the
declaration's line. Bytes that are not UTF-8 are ``xml-error``, as GMarkup
refuses them.
"""

from __future__ import annotations

from collections.abc import Iterable

from ..read.liblensfun import NOT_WELL_FORMED
from .parsing import ParsedSource
from .result import (
    ENCODING_MISMATCH,
    LIBLENSFUN_REFUSES,
    NOT_A_DATABASE,
    SEVERITY_ERROR,
    SEVERITY_WARNING,
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
    lost = len(file.tables.lenses) - kept
    message = clip(
        f"liblensfun (Lensfun master's) stops reading at line {line}: {reason}; "
        f"{_lenses(lost)} from there on {'are' if lost != 1 else 'is'} lost to its users"
        f" (it keeps the {_lenses(kept)} before)"
    )
    finding = Finding(SEVERITY_ERROR, LIBLENSFUN_REFUSES, file.source.display, line, 0, message)
    identity = (SEVERITY_ERROR, LIBLENSFUN_REFUSES, file.source.file_name, reason)
    yield Identified(finding, (identity,), (file.source.file_name,))


def encoding_mismatches(file: ParsedSource) -> Iterable[Identified]:
    """The ``encoding-mismatch`` finding of one file whose XML declaration
    names an encoding its bytes are not in (see the module's description)."""
    found = file.tables.encoding
    if found is None:
        return
    line, problem = found
    finding = Finding(
        SEVERITY_WARNING, ENCODING_MISMATCH, file.source.display, line, 0, clip(problem)
    )
    # Matched by what the declaration says, not by the text it is first wrong on.
    said = problem.partition(":")[0]
    identity = (SEVERITY_WARNING, ENCODING_MISMATCH, file.source.file_name, said)
    yield Identified(finding, (identity,), (file.source.file_name,))


def _lenses(count: int) -> str:
    return f"{count} lens" if count == 1 else f"{count} lenses"


__all__ = ["encoding_mismatches", "liblensfun_refusals"]
