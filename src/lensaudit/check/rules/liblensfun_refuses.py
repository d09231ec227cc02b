"""``liblensfun-refuses``: where Lensfun master's liblensfun stops loading a
file (see :mod:`lensaudit.check.loading`)."""

from __future__ import annotations

from collections.abc import Iterable

from ..loading import liblensfun_refusals
from ..result import Identified
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
    "definition it refuses, a database version it does not read, a byte-order mark): it keeps "
    "the lenses before and loses every one after; not repeated where the file is `xml-error` "
    "at that spot (see [below](#what-liblensfun-refuses-to-load))",
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


def find(context: Context) -> Iterable[tuple[int, Identified]]:
    """Where liblensfun stops loading each file."""
    for index, file in enumerate(context.read):
        for item in liblensfun_refusals(file):
            yield index, item
