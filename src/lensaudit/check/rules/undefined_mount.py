"""``undefined-mount``: a ``<lens>`` or ``<camera>`` whose ``<mount>`` names a
mount that no top-level ``<mount><name>`` of the database defines.

Lensfun's own CI (its ``check_database.py``) runs xmllint against the schema
and looks for duplicate keys only. Names are compared as liblensfun compares
them (``_lf_strcmp`` in ``libs/lensfun/auxfun.cpp``, used by
``lfDatabase::FindMount`` and by the lens search): without letter case,
leading and trailing white space, and with each run of white space as one
space. A name that starts with a lower-case letter is a fixed-lens camera's
own mount, which Lensfun never defines (``lfMount::Name`` in ``lensfun.h``),
and is not reported; nor is anything when the files checked define no mount
at all (a fragment). What each file defines and names comes from the
reader's tables (:attr:`lensaudit.read.FileTables.mount_names`, ``cameras``
and each lens's ``mounts`` and ``mount_lines``).
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from ..matching import lens_identity
from ..parsing import ParsedSource, crop_factor_key
from ..result import Finding, Identified, clip, clip_key, lens_name
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


@dataclass(frozen=True)
class MountUse:
    """A ``<mount>`` of a ``<lens>`` or ``<camera>`` (``kind``): its owner's
    maker and model (the untranslated names) and crop factor as written
    (None without one), the mount's name and line."""

    kind: str
    maker: str
    model: str
    crop_text: str | None
    mount: str
    line: int


def mount_uses(file: ParsedSource) -> list[MountUse]:
    """The mounts a file's lenses and cameras name, as liblensfun reads them
    (``database.cpp``): a lens has every ``<mount>`` it names, a camera the
    last one; an empty name is skipped."""
    found = []
    tables = file.tables
    owners = [("lens", lens, lens.crop_text) for lens in tables.lenses]
    owners += [("camera", camera, camera.crop_text) for camera in tables.cameras]
    for kind, owner, crop_text in owners:
        named = [(m, owner.line + offset) for m, offset in zip(owner.mounts, owner.mount_lines,
                                                                 strict=True) if m]  # fmt: skip
        if kind == "camera":
            named = named[-1:]
        found += [MountUse(kind, owner.maker, owner.model, crop_text, m, line) for m, line in named]
    return found


def mount_key(name: str) -> str:
    """A mount name as liblensfun compares it (``_lf_strcmp``): lower case,
    without leading or trailing white space, each run of white space one space."""
    return " ".join(name.split()).lower()


def is_fixed_lens_mount(name: str) -> bool:
    """True for a fixed-lens camera's own mount: its name starts with a
    lower-case letter, and Lensfun defines no such mount."""
    first = name.strip()[:1]
    return first.islower()


def undefined_mounts(read: Sequence[ParsedSource]) -> Iterable[tuple[int, Identified]]:
    """A lens or camera whose mount no file of ``read`` defines.

    Definitions count in every file that parses, or that libxml2's recovery
    mode reads (so that one broken file does not turn every lens of its
    mounts into a finding); lenses and cameras only in files that parse.
    Files that define no mount at all are a fragment of a database (one
    file of it, a hand-made example), not a database: nothing is reported.
    """
    defined: dict[str, str] = {}
    for file in read:
        for _, name in file.tables.mount_names:
            defined.setdefault(mount_key(name), name)
    if not defined:
        return
    for index, file in enumerate(read):
        if file.problem is not None:
            continue
        for use in mount_uses(file):
            key = mount_key(use.mount)
            if key in defined or is_fixed_lens_mount(use.mount):
                continue
            yield index, _undefined_mount(file, use, key, defined)


def _undefined_mount(
    file: ParsedSource, use: MountUse, key: str, defined: dict[str, str]
) -> Identified:
    close = difflib.get_close_matches(key, list(defined), n=1, cutoff=0.8)
    # Double quotes: clip() shortens text between single quotes.
    hint = f' (did you mean "{defined[close[0]]}"?)' if close else ""
    if use.kind == "lens":
        what = f"lens {lens_name(use.maker, use.model)}"
        effect = "a camera finds this lens only through a mount of exactly that name"
        owner = (use.maker, use.model, crop_factor_key(use.crop_text))
    else:
        what = f"camera {lens_name(use.maker, use.model)}"
        effect = "liblensfun knows no mount compatible with it"
        owner = (use.maker, use.model)
    text = (
        f'{what}: its mount "{clip(use.mount, 40)}" is defined nowhere in the database '
        f"(no top-level <mount> has that <name>, ignoring case and spacing){hint}: {effect}"
    )
    finding = Finding(
        UNDEFINED_MOUNT.severity,
        UNDEFINED_MOUNT.code,
        file.source.display,
        use.line,
        0,
        clip(text),
        clip_key(owner),
    )
    # The owner by name and the mount; then the mount alone, for a renamed owner.
    content = (UNDEFINED_MOUNT.severity, UNDEFINED_MOUNT.code, use.kind, key)
    keys = ((*content, lens_identity(use.maker, use.model)), content)
    return Identified(finding, keys, (file.source.file_name,))


def find(context: Context) -> Iterable[tuple[int, Identified]]:
    """Each mount named and not defined, in any file of the database."""
    return undefined_mounts(context.read)
