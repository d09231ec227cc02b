"""``undefined-mount``: a lens or camera whose mount no file of the database
defines (see :func:`lensaudit.check.metadata.undefined_mounts`)."""

from __future__ import annotations

from collections.abc import Iterable

from ..metadata import undefined_mounts
from ..result import Identified
from . import WARNING, Context, Rule

ORDER = 120
ACROSS_FILES = True

UNDEFINED_MOUNT = Rule(
    "undefined-mount",
    WARNING,
    "lens",
    "a mount no <mount> of the database defines",
    "a `<lens>` or `<camera>` whose `<mount>` names a mount that no top-level `<mount><name>` "
    "of the database defines (see [below](#metadata-lensfuns-own-ci-does-not-check))",
    "Names are compared as liblensfun compares them; a lens on an undefined mount is not "
    "offered for the cameras of the mount meant.",
    fails=(
        "mil-fujifilm.xml:1744 of lensfunpy 1.18.0's database, Fujifilm GF23mmF4: mount "
        '"Fujifilm G" defined nowhere'
    ),
    passes='the same lens on Lensfun master, where 2e276b8 defines "Fujifilm G"',
)
RULES = (UNDEFINED_MOUNT,)


def find(context: Context) -> Iterable[tuple[int, Identified]]:
    """Each mount named and not defined, in any file of the database."""
    return undefined_mounts(context.read)
