"""``missing-attribute``, ``bad-value``, ``unknown-model``, ``no-lens``: an
element the reader could not audit (its status), with the reader's message.
They apply to ``<vignetting>`` and ``<tca>`` elements too, whose families
report them with the element named."""

from __future__ import annotations

from collections.abc import Iterable

from ...read.records import (
    STATUS_BAD_VALUE,
    STATUS_MISSING_ATTRIBUTE,
    STATUS_NO_LENS,
    STATUS_NOT_DATABASE,
    STATUS_OK,
    STATUS_UNKNOWN_MODEL,
    STATUS_UNREADABLE,
)
from ..result import Identified, entry_finding
from . import ERROR, Context, Rule, file_errors
from ._identity import entry_identified

ORDER = 10

MISSING_ATTRIBUTE = Rule(
    "missing-attribute",
    ERROR,
    "entry",
    "an element without an attribute it needs (model=, focal=; a <vignetting>'s "
    "aperture= and distance=)",
    "a `<distortion>`, `<tca>` or `<vignetting>` without an attribute it needs: `model=`, "
    "`focal=`, and for `<vignetting>` `aperture=` and `distance=`",
    "liblensfun cannot place an entry without its model, its focal length or, for "
    "vignetting, its aperture and distance.",
    fails=(
        "slr-pentax.xml:851 at Lensfun f0e72d7, smc Pentax-FA 50mm f/1.4: a <vignetting> "
        "without distance="
    ),
    passes='the same element at 23416d4 with distance="1000" added',
)
BAD_VALUE = Rule(
    "bad-value",
    ERROR,
    "entry",
    "a value that is not a finite number, or <= 0",
    "a value that is not a finite number (`nan`, `inf`, `1,5`, `1e999`), a focal length or "
    "crop factor <= 0",
    "A value liblensfun would read as something else than what was meant, or not at all.",
    fails=(
        'slr-canon.xml:3848 at Lensfun bce0bb0, Canon EF 100-400mm II at 100 mm: a="0,.0029", '
        "not a number"
    ),
    passes='the same entry at aff79f6 ("Bugfix ... due to typos"), a="-0.00104"',
)
UNKNOWN_MODEL = Rule(
    "unknown-model",
    ERROR,
    "entry",
    "a model other than ptlens, poly3, poly5",
    "a model other than `ptlens`, `poly3`, `poly5` (`acm`, `none`, ...)",
    "lensaudit audits the three polynomial models Lensfun's database uses.",
    fails='a <distortion model="acm"> (liblensfun reads the model; no Lensfun file has used it)',
    passes="the ptlens entries of the same lens",
)
NO_LENS = Rule(
    "no-lens",
    ERROR,
    "entry",
    "a calibration element outside any <lens>",
    "a `<distortion>` outside any `<lens>`",
    'liblensfun stops reading the file there ("Inappropriate context").',
    fails=(
        "a <calibration> pasted after </lens>, directly inside <lensdatabase> (no Lensfun file "
        "has had one)"
    ),
    passes="the same <distortion> inside its lens's <calibration>",
)
RULES = (MISSING_ATTRIBUTE, BAD_VALUE, UNKNOWN_MODEL, NO_LENS)

#: The rule of each status of the reader (an unreadable or non-database
#: file's entries carry their file's status).
STATUS_RULES = {
    STATUS_MISSING_ATTRIBUTE: MISSING_ATTRIBUTE,
    STATUS_BAD_VALUE: BAD_VALUE,
    STATUS_UNKNOWN_MODEL: UNKNOWN_MODEL,
    STATUS_NO_LENS: NO_LENS,
    STATUS_UNREADABLE: file_errors.UNREADABLE,
    STATUS_NOT_DATABASE: file_errors.NOT_A_DATABASE,
}


def find(context: Context) -> Iterable[tuple[int, Identified]]:
    """An error for each distortion entry the reader could not audit."""
    for index, entry in context.entries:
        if entry.status != STATUS_OK:
            rule = STATUS_RULES.get(entry.status, BAD_VALUE)
            finding = entry_finding(rule.severity, rule.code, entry, entry.message)
            yield index, entry_identified(finding, entry, context.read[index].source.file_name)
