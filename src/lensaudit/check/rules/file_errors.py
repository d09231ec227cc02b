"""``xml-error``, ``not-a-database``, ``unreadable``: a file that is not a
database lensaudit can read. The reader says which (its tables' status); its
entries, as far as libxml2's recovery finds them, are counted and not checked
further."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from ...read.records import STATUS_NOT_DATABASE, STATUS_UNREADABLE, STATUS_XML_ERROR
from ..result import Identified
from . import ERROR, Context, Rule

ORDER = 0
#: Run with the rules across files: those get every file, the ones that failed to parse too.
ACROSS_FILES = True

XML_ERROR = Rule(
    "xml-error",
    ERROR,
    "file",
    "the file is not well-formed XML (line, column)",
    "the file is not well-formed XML; its entries are counted but not checked further",
    "libxml2 reports the first place the file stops being XML, with its line and column; "
    "GMarkup, liblensfun's parser, refuses such a file from that point on.",
    fails=(
        "mil-panasonic.xml:80 at Lensfun 8750c44, LUMIX G 14mm F2.5: a <distortion ...> with no "
        "closing slash (tag mismatch)"
    ),
    passes='the same element at 49d4e3b ("typo fix"), closed with />',
)
NOT_A_DATABASE = Rule(
    "not-a-database",
    ERROR,
    "file",
    "an XML file whose root is not <lensdatabase>",
    "a well-formed XML file whose root element is not `<lensdatabase>`",
    "liblensfun refuses a file whose root is anything but <lensdatabase>.",
    fails=(
        "mil-leica.xml as started in Lensfun 62f8a72, cut to its first block: a file whose root "
        "is <mount>"
    ),
    passes='the same file at e7ace6f ("Fix xml"), wrapped in <lensdatabase>',
)
UNREADABLE = Rule(
    "unreadable",
    ERROR,
    "file",
    "the file could not be read",
    "the file could not be read",
    "The operating system's reason is given (permission, a directory, a FIFO, ...).",
    fails="a database file that is a dangling symbolic link (no real database has one)",
    passes="the other files of the same directory, read as usual",
)
RULES = (XML_ERROR, NOT_A_DATABASE, UNREADABLE)

#: The rule of each file-level status of the reader.
STATUS_RULES = {
    STATUS_XML_ERROR: XML_ERROR,
    STATUS_NOT_DATABASE: NOT_A_DATABASE,
    STATUS_UNREADABLE: UNREADABLE,
}


def find(context: Context) -> Iterable[tuple[int, Identified]]:
    """The finding of each file of ``context`` that could not be parsed."""
    for index, file in enumerate(context.read):
        if file.problem is not None:
            yield index, file_identified(file)


def file_identified(file: Any) -> Identified:
    """A file-level finding: the file's name and the problem, without its position."""
    problem = file.problem
    assert problem is not None
    identity = (problem.severity, problem.code, file.source.file_name, file.problem_text)
    return Identified(problem, (identity,), (file.source.file_name,))
