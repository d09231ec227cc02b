"""``encoding-mismatch``: a file liblensfun reads as UTF-8 whose XML
declaration names another encoding.

liblensfun (GLib's GMarkup) reads every file as UTF-8 and takes the XML
declaration for a processing instruction; so does the reader. A file
declared ISO-8859-1 whose bytes are UTF-8 loads, with the names meant, but
every reader that follows the declaration (Python's, libxml2's) reads other
names ("GÃ¶rlitz" for "Görlitz"): a warning on the declaration's line. Bytes
that are not UTF-8 are ``liblensfun-refuses``', as GMarkup refuses them.
"""

from __future__ import annotations

from collections.abc import Iterable

from ..parsing import ParsedSource
from ..result import Finding, Identified, clip
from . import WARNING, Context, Rule

ORDER = 135
ACROSS_FILES = True

ENCODING_MISMATCH = Rule(
    "encoding-mismatch",
    WARNING,
    "file",
    "the XML declaration names an encoding the bytes are not in: liblensfun reads UTF-8, "
    "other readers follow it",
    "the file's XML declaration names an encoding its bytes are not in "
    '(`encoding="ISO-8859-1"` on UTF-8 bytes): liblensfun reads them as UTF-8 ("Görlitz"), '
    "as lensaudit does, while a reader that follows the declaration reads other names "
    '("GÃ¶rlitz"); on the declaration\'s line (see [input.md](input.md#encodings))',
    "liblensfun loads such a file with the names meant; every other program that reads the "
    "database through a standard XML parser gets other names, and the lens search misses "
    "them. A warning: liblensfun itself is not misled.",
    fails=(
        'lensfunpy\'s slr-ussr.xml with encoding="ISO-8859-1" written into its declaration: '
        "its Cyrillic names read as Latin-1 by every reader but liblensfun"
    ),
    passes="slr-ussr.xml as Lensfun writes it, declared UTF-8",
)
RULES = (ENCODING_MISMATCH,)


def encoding_mismatches(file: ParsedSource) -> Iterable[Identified]:
    """The ``encoding-mismatch`` finding of one file whose XML declaration
    names an encoding its bytes are not in (see the module's docstring)."""
    found = file.tables.encoding
    if found is None:
        return
    line, problem = found
    rule = ENCODING_MISMATCH
    finding = Finding(rule.severity, rule.code, file.source.display, line, 0, clip(problem))
    # Matched by what the declaration says, not by the text it is first wrong on.
    said = problem.partition(":")[0]
    identity = (rule.severity, rule.code, file.source.file_name, said)
    yield Identified(finding, (identity,), (file.source.file_name,))


def find(context: Context) -> Iterable[tuple[int, Identified]]:
    """Each file whose declaration names an encoding its bytes are not in."""
    for index, file in enumerate(context.read):
        for item in encoding_mismatches(file):
            yield index, item
