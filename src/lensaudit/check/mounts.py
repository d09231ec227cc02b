"""The mounts of a file: those it defines, and those its lenses and cameras
name, read with the one parser (:func:`lensaudit.read.xml.parse`). The
reader's tables hold a lens's mounts but neither cameras nor mount
definitions, which the ``undefined-mount`` rule
(:mod:`lensaudit.check.metadata`) needs."""

from __future__ import annotations

import functools
from dataclasses import astuple, dataclass
from pathlib import Path
from typing import Any

from ..read import Cache, xml
from ..read.cache import content_digest
from ..read.records import STATUS_OK, STATUS_XML_ERROR
from ..read.tables import text_of


@dataclass(frozen=True)
class MountUse:
    """A ``<mount>`` of a ``<lens>`` or ``<camera>`` (``kind``): its owner's
    maker and model (the untranslated names) and crop factor as written
    (None without one), the mount's name and line, and the owner's line."""

    kind: str
    maker: str
    model: str
    crop_text: str | None
    mount: str
    line: int
    owner_line: int


@dataclass(frozen=True)
class FileMounts:
    """The mounts a file defines (the ``<name>`` of each top-level ``<mount>``,
    without a ``lang``) and those its lenses and cameras name."""

    defined: tuple[str, ...] = ()
    uses: tuple[MountUse, ...] = ()


class _MountReader:
    """A visitor of :func:`lensaudit.read.xml.parse`: mount definitions, and the
    mounts of lenses and cameras, as liblensfun reads them (``database.cpp``):
    a lens has every ``<mount>`` it names, a camera the last one."""

    def __init__(self) -> None:
        self.defined: list[str] = []
        self.uses: list[MountUse] = []

    def add(self, piece: Any, line_of: Any) -> None:
        if piece.tag == "mount":
            self.defined += [
                text_of(name) for name in piece.iterchildren("name") if name.get("lang") is None
            ]
            return
        for owner in piece.iter("lens", "camera"):
            names: dict[str, str] = {}
            mounts = []
            for child in owner.iterchildren("maker", "model", "cropfactor", "mount"):
                if child.tag == "mount":
                    mounts.append((text_of(child), line_of(child)))
                elif child.get("lang") is None:
                    names[child.tag] = text_of(child)
            mounts = [(mount, line) for mount, line in mounts if mount]  # liblensfun skips ""
            if owner.tag == "camera":
                mounts = mounts[-1:]
            maker, model = names.get("maker", ""), names.get("model", "")
            crop_text, owner_line = names.get("cropfactor"), line_of(owner)
            self.uses += [
                MountUse(owner.tag, maker, model, crop_text, mount, line, owner_line)
                for mount, line in mounts
            ]


def file_mounts(data: bytes, digest: bytes = b"", cache: Cache | None = None) -> FileMounts:
    """The mounts of one file's content; for a file that is not well-formed,
    those libxml2's recovery mode finds. With ``cache``, they are kept in
    the record of the content's ``digest`` and not read again."""
    section = _section()
    if cache is not None and digest:
        stored = cache.get(digest, section)
        if stored is not None:
            try:
                defined, uses = stored  # type: ignore[misc]
                return FileMounts(tuple(defined), tuple(MountUse(*use) for use in uses))
            except (TypeError, ValueError):
                pass  # not what this code stores: read again
    parsed, found = xml.parse(data, _MountReader)
    mounts = FileMounts()
    if parsed.status in (STATUS_OK, STATUS_XML_ERROR):
        mounts = FileMounts(tuple(found.defined), tuple(found.uses))
    if cache is not None and digest:
        cache.put(digest, section, (mounts.defined, tuple(astuple(u) for u in mounts.uses)))
    return mounts


@functools.cache
def _section() -> str:
    """The cache section of mounts, named after this module's source: the
    cache's own fingerprint covers the reader, not this module."""
    return "check-mounts-" + content_digest(Path(__file__).read_bytes()).hex()[:16]
