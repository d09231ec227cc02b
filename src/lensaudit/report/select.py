"""Name one distortion entry: by ``FILE:LINE`` or by a lens query.

``FILE`` is the file name as the audit reports it (``slr-tokina.xml``) and
``LINE`` the line of the ``<distortion>`` element. A query matches every
word of ``lens`` (case-insensitive) in "maker lens", and optionally the
focal length (mm) and crop factor exactly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import PurePath
from typing import TYPE_CHECKING

from ..read.records import STATUS_OK, DistortionEntry

if TYPE_CHECKING:
    from ..pipeline import Audit


class SelectionError(Exception):
    """No entry, or more than one, answers the request; ``candidates`` lists the latter."""

    def __init__(self, message: str, candidates: list[int] | None = None) -> None:
        super().__init__(message)
        self.candidates = candidates or []


@dataclass(frozen=True)
class Query:
    """What the user asked for; empty fields match anything."""

    lens: str = ""
    focal: float | None = None
    crop: float | None = None

    def __bool__(self) -> bool:
        return bool(self.lens.strip()) or self.focal is not None or self.crop is not None

    def describe(self) -> str:
        parts = [f"lens {self.lens!r}"] if self.lens.strip() else []
        if self.focal is not None:
            parts.append(f"focal {self.focal:g} mm")
        if self.crop is not None:
            parts.append(f"crop {self.crop:g}")
        return ", ".join(parts)


def parse_location(text: str) -> tuple[str, int] | None:
    """``("file.xml", 17)`` from ``"file.xml:17"``; None when it is not of that form."""
    file, sep, line = text.rpartition(":")
    if not sep or not file or not line.isdigit():
        return None
    return file, int(line)


def describe(entry: DistortionEntry) -> str:
    """One line naming an entry: lens, focal, crop, model and where it is."""
    name = entry.lens
    if entry.maker and not entry.lens.lower().startswith(entry.maker.lower()):
        name = f"{entry.maker} {entry.lens}"
    return (
        f"{name.strip()} at {entry.focal:g} mm, crop {entry.crop_factor:g}, "
        f"{entry.model} ({entry.file}:{entry.line})"
    )


def by_location(audit: Audit, file: str, line: int) -> int:
    """Index of the entry at ``file:line``; ``file`` may be a path ending in the name."""
    wanted = PurePath(file)
    matches = [
        i
        for i, e in enumerate(audit.entries)
        if e.line == line and (e.file == file or PurePath(e.file).name == wanted.name)
    ]
    if not matches:
        raise SelectionError(
            f"no <distortion> entry at {file}:{line} (give the line of the <distortion> element)"
        )
    if len(matches) > 1:
        raise SelectionError(
            f"{file}:{line} names several entries; give the path as the audit shows it", matches
        )
    return _audited(audit, matches[0])


def by_query(audit: Audit, query: Query) -> int:
    """Index of the one audited entry matching ``query``."""
    words = query.lens.lower().split()
    matches = []
    for index, entry in enumerate(audit.entries):
        if entry.status != STATUS_OK:
            continue
        name = f"{entry.maker} {entry.lens}".lower()
        if not all(word in name for word in words):
            continue
        if query.focal is not None and not math.isclose(entry.focal, query.focal, abs_tol=1e-9):
            continue
        if query.crop is not None and not math.isclose(entry.crop_factor, query.crop, abs_tol=1e-9):
            continue
        matches.append(index)
    if not matches:
        raise SelectionError(f"no audited entry matches {query.describe()}")
    if len(matches) > 1:
        raise SelectionError(
            f"{len(matches)} entries match {query.describe()}; name one as "
            f"FILE:LINE or narrow the query (--focal, --crop)",
            matches,
        )
    return matches[0]


def _audited(audit: Audit, index: int) -> int:
    entry = audit.entries[index]
    if entry.status != STATUS_OK:
        raise SelectionError(
            f"{entry.file}:{entry.line} was not audited ({entry.status}: {entry.message})"
        )
    return index
