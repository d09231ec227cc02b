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
``<lensdatabase>`` is ``not-a-database`` alone. An entry finding that
names the same fault (``no-lens`` for a ``<distortion>`` outside a lens,
``bad-value`` on the entries of a lens whose crop factor is not positive)
says what is wrong with the entry, not that liblensfun drops the file from
there on: the refusal is reported beside it, with the lenses lost. The
finding is matched against a baseline by the file's name and the reason,
not by its line.
"""

from __future__ import annotations

from collections.abc import Iterable

from ...read.liblensfun import NOT_WELL_FORMED
from ..parsing import ParsedSource
from ..result import NOT_A_DATABASE, UNREADABLE, Finding, Identified, clip
from . import ERROR, Context, Rule

ORDER = 130
ACROSS_FILES = True

LIBLENSFUN_REFUSES = Rule(
    "liblensfun-refuses",
    ERROR,
    "file",
    "liblensfun master stops loading the file there and loses the lenses after it",
    "Lensfun master's liblensfun stops loading the file at this line (an unknown element or "
    "attribute, an element in the wrong parent, a bad value, a lens, camera or mount "
    "definition it refuses, a database version it does not read, a byte-order mark, bytes "
    "that are not UTF-8 whatever the file declares, a UTF-16 or UTF-32 file): it keeps the "
    "lenses before and loses every one after; not repeated where the file is `xml-error` at "
    "that spot (see [below](#what-liblensfun-refuses-to-load))",
    "One error hides the rest of the file from every program that uses Lensfun.",
    fails=(
        "actioncams.xml:167 of lensfunpy 1.18.0's database: <real-focal-length>, which Lensfun "
        "master no longer reads; 10 lenses after it are lost"
    ),
    passes=(
        "the same lens on Lensfun master (actioncams.xml:218), where the element is a "
        "real-focal= attribute"
    ),
)
RULES = (LIBLENSFUN_REFUSES,)


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
        + (f" (it keeps the {_lenses(kept)} before)" if kept else " (it keeps no lens before)")
    )
    rule = LIBLENSFUN_REFUSES
    finding = Finding(rule.severity, rule.code, file.source.display, line, 0, message)
    identity = (rule.severity, rule.code, file.source.file_name, reason)
    yield Identified(finding, (identity,), (file.source.file_name,))


def _lenses(count: int) -> str:
    return f"{count} lens" if count == 1 else f"{count} lenses"


def find(context: Context) -> Iterable[tuple[int, Identified]]:
    """Where liblensfun stops loading each file."""
    for index, file in enumerate(context.read):
        for item in liblensfun_refusals(file):
            yield index, item
