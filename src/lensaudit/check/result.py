"""The records of a check: findings, the files checked, the result, and how
findings are worded (clipped to a length a terminal and CI systems show)."""

from __future__ import annotations

import os
import re
from collections.abc import Hashable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import NamedTuple

from ..columns import FOLD_MARGIN
from ..read.records import DEFAULT_LENS_TYPE, DistortionEntry, LoadError

SEVERITY_ERROR = "error"
SEVERITY_WARNING = "warning"
SEVERITY_NOTICE = "notice"
SEVERITIES = (SEVERITY_ERROR, SEVERITY_WARNING, SEVERITY_NOTICE)

#: r_normalized below which a fold just outside the image is a warning (the
#: margin ``fix`` refits to, :data:`lensaudit.columns.FOLD_MARGIN`).
DEFAULT_MARGIN = FOLD_MARGIN


FOLD_IN_IMAGE = "fold-in-image"
FOLD_NEAR_IMAGE = "fold-near-image"
FOLD_OUTSIDE_IMAGE = "fold-outside-image"
FOLD_BETWEEN_CALIBRATIONS = "fold-between-calibrations"
NOT_COMPUTABLE = "r-max-not-computable"
XML_ERROR = "xml-error"
NOT_A_DATABASE = "not-a-database"
UNREADABLE = "unreadable"
MISSING_ATTRIBUTE = "missing-attribute"
BAD_VALUE = "bad-value"
UNKNOWN_MODEL = "unknown-model"
NO_LENS = "no-lens"
DUPLICATE_LENS = "duplicate-lens"
DUPLICATE_FOCAL = "duplicate-focal"
BASELINE_UNREADABLE = "baseline-unreadable"
UNDEFINED_MOUNT = "undefined-mount"
CONFLICTING_CALIBRATION = "conflicting-calibration"
VIGNETTING_STARTING_VALUES = "vignetting-starting-values"
INVERSION_FAILS_IN_IMAGE = "inversion-fails-in-image"
FOCAL_SERIES_OUTLIER = "focal-series-outlier"
LIBLENSFUN_REFUSES = "liblensfun-refuses"

#: Findings about a whole file.
FILE_CODES = frozenset({XML_ERROR, NOT_A_DATABASE, UNREADABLE})


#: Longest name and message put into a finding; hostile files can hold megabytes.
NAME_LIMIT = 80
MESSAGE_LIMIT = 400
QUOTED_LIMIT = 40
#: A quoted value longer than QUOTED_LIMIT: its opening quote follows no letter
#: or digit, so that the apostrophe of "master's" opens nothing.
_QUOTED = re.compile(rf"(?<!\w)'([^']{{{QUOTED_LIMIT}}})[^']{{2,}}'")
#: Where a message ends with a command to paste (``lensaudit.check.rules.fold.fix_suggestion``):
#: :func:`clip` keeps it byte for byte.
COMMAND_MARK = "`lensaudit fix "


class CheckError(LoadError):
    """The check cannot run: no readable input, or a baseline that cannot be read."""


@dataclass(frozen=True)
class Finding:
    """One thing the check found.

    ``file`` is the path as shown to the user, ``line`` and ``column`` count
    from 1 (0 when unknown). ``entry_key`` is (maker, lens, crop factor,
    model, focal) for an entry, (maker, lens, crop factor) for a lens and ()
    for a whole file; NaN values are None, names over :data:`NAME_LIMIT`
    characters are cut. ``known`` findings were already in the baseline and
    never fail the check. ``related`` holds the (file, line) of the other
    element a duplicate repeats.
    """

    severity: str
    code: str
    file: str
    line: int
    column: int
    message: str
    entry_key: tuple = ()
    known: bool = False
    related: tuple[tuple[str, int], ...] = ()

    @property
    def fails(self) -> bool:
        """True for an error that is not known from the baseline."""
        return self.severity == SEVERITY_ERROR and not self.known


@dataclass(frozen=True)
class CheckedFile:
    """A file of the database: how it is shown, where it is, what it held.

    ``entries`` counts its ``<distortion>`` elements (for a file that is not
    well-formed, those libxml2's recovery mode still finds); ``error`` says
    why the file could not be read or parsed, or is "".
    """

    file: str
    path: Path | None
    entries: int
    error: str = ""


@dataclass(frozen=True)
class CheckResult:
    """Everything :func:`check` found, in file and line order."""

    database: str
    baseline: str | None
    margin: float
    files: list[CheckedFile]
    findings: list[Finding]
    resolved: int = 0  # findings of the baseline that are gone

    @property
    def entries(self) -> int:
        """Distortion entries checked (salvaged ones of broken files included)."""
        return sum(f.entries for f in self.files)

    @property
    def failed(self) -> bool:
        """True when a finding fails the check (exit status 1)."""
        return any(f.fails for f in self.findings)

    def counts(self) -> dict[str, int]:
        """New findings by severity (``error``, ``warning``, ``notice``) and ``known``."""
        counts = dict.fromkeys(SEVERITIES, 0)
        counts["known"] = 0
        for finding in self.findings:
            counts["known" if finding.known else finding.severity] += 1
        return counts

    def relative_to(self, *roots: str | os.PathLike[str]) -> CheckResult:
        """The same result with file paths relative to the deepest of ``roots``
        that holds each file; files under none of them keep their paths.

        CI systems (GitHub's annotations, JUnit viewers) place findings by
        paths relative to the repository root.
        """
        resolved = sorted((Path(r).resolve() for r in roots), key=lambda p: len(p.parts))
        names = {}
        for file in self.files:
            if file.path is None:
                continue
            for root in reversed(resolved):
                if file.path.is_relative_to(root):
                    names[file.file] = file.path.relative_to(root).as_posix()
                    break

        def moved(finding: Finding) -> Finding:
            related = tuple((names.get(f, f), line) for f, line in finding.related)
            return replace(finding, file=names.get(finding.file, finding.file), related=related)

        files = [replace(f, file=names.get(f.file, f.file)) for f in self.files]
        return replace(self, files=files, findings=[moved(f) for f in self.findings])


class Identified(NamedTuple):
    """A finding with what matches it against a baseline's findings.

    ``keys`` are its identities from the most to the least specific, each
    starting with the severity and the code (see :func:`compare`).
    ``names`` are the names of the files the finding is about, its own first.
    """

    finding: Finding
    keys: tuple[Hashable, ...]
    names: tuple[str, ...]


def clip(text: str, limit: int = MESSAGE_LIMIT) -> str:
    """``text`` on one line, at most ``limit`` characters.

    Quoted values are shortened first, so that the words after a huge value
    (``'999...' overflows a double``) survive. A command to paste that ends
    the message (after :data:`COMMAND_MARK`) is kept whole, beyond the limit:
    it names a file, and the words before it must not depend on how long
    that file's path is.
    """
    head, mark, command = text.rpartition(COMMAND_MARK)
    if not mark:
        head, command = text, ""
    else:
        # The command ends the message, shell-quoted and on one line already:
        # shortened or respaced, it would no longer select its entry.
        command = mark + command
    spaced = " ".join(head.split()) + (" " if command and head[-1:].isspace() else "")
    head = _QUOTED.sub(lambda m: f"'{m.group(1)[:QUOTED_LIMIT]}\u2026'", spaced)
    return (head if len(head) <= limit else head[: limit - 1] + "\u2026") + command


def clip_key(key: tuple) -> tuple:
    """An entry key fit for output: strings cut to :data:`NAME_LIMIT` characters."""
    return tuple(
        v[: NAME_LIMIT - 1] + "\u2026" if isinstance(v, str) and len(v) > NAME_LIMIT else v
        for v in key
    )


def none_if_nan(value: float) -> float | None:
    """``value``, or None for NaN, which would never equal itself in a key."""
    return None if value != value else value


def normalized_name(text: str) -> str:
    """A name without case, and with runs of white space as one space."""
    return " ".join(text.split()).casefold()


def lens_name(maker: str, lens: str) -> str:
    """ "Maker Model", or the model alone when it starts with the maker's name."""
    name = lens if normalized_name(lens).startswith(normalized_name(maker)) else (f"{maker} {lens}")
    return clip(name, NAME_LIMIT) or "unnamed lens"


def entry_key(entry: DistortionEntry) -> tuple:
    """(maker, lens, crop factor, model, focal): how an entry is named in
    output. NaN values are None."""
    return (
        entry.maker,
        entry.lens,
        none_if_nan(entry.crop_factor),
        entry.model,
        none_if_nan(entry.focal),
    )


def describe(entry: DistortionEntry) -> str:
    """Short name of an entry: lens, model, focal and crop factor, as far as known."""
    name = lens_name(entry.maker, entry.lens)
    details = []
    if entry.model:
        details.append(clip(entry.model, 20))
    if entry.focal == entry.focal:
        details.append(f"{entry.focal:g} mm")
    if entry.crop_factor == entry.crop_factor:
        details.append(f"crop {entry.crop_factor:g}")
    if entry.type and entry.type != DEFAULT_LENS_TYPE:
        details.append(clip(entry.type, 20))
    return f"{name} ({', '.join(details)})" if details else name


def entry_finding(severity: str, code: str, entry: DistortionEntry, text: str) -> Finding:
    """A finding about one distortion entry, ``text`` led by :func:`describe`."""
    return Finding(
        severity,
        code,
        entry.file,
        entry.line,
        0,
        clip(f"{describe(entry)}: {text}"),
        clip_key(entry_key(entry)),
    )
