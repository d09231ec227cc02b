"""Findings about a Lensfun database, or about a change to one: the CI gate.

:func:`check` audits a database and turns what it finds into
:class:`Finding` records, each with a severity, a code, ``file:line`` and one
sentence. Errors make the check fail; warnings and notices do not.

The rules are the registry of :mod:`lensaudit.check.rules`: one record per
finding code (its severity, scope, summary and documentation) and one module
per family of codes, named after them; ``lensaudit check --help`` and
docs/ci.md list them.

With a baseline (a directory, or a git revision of the repository that holds
the database, read with ``git ls-tree`` and ``git cat-file`` so that the work
tree is never touched), a finding is new only when the baseline has no
finding of the same severity and code with the same identity; the others are
``known`` and never fail the check. Identity is content, never position or
line: an entry is its lens (maker and model, compared ignoring case and all
white space) and its own values (model, focal length, crop factor, aspect
ratio, type, coefficients); a duplicate is its lens or calibration and the
pair it is made of; a file-level finding is the file's name and the problem.
What the baseline does not match exactly may still match less specifically:
an entry or a duplicate by its values alone (its lens was renamed), then a
duplicate by its lens and focal length, or its name, alone (one of the pair
was edited). Each baseline finding
matches one finding only, so that a copy of a known entry under a new lens,
or a third definition of a known duplicate lens, is new.

A baseline file that cannot be parsed is replaced by its last readable
version in the git history (among the last :data:`HISTORY_DEPTH` commits that
changed it), and a ``baseline-unreadable`` notice says so. Without one (or
for a directory baseline), the findings in that file are not counted as new,
and the notice says that too.

The stages, one module each: :mod:`~lensaudit.check.inputs` (the files
checked and the baseline's), :mod:`~lensaudit.check.parsing` (each file
read once by :mod:`lensaudit.read`, the one reader every command uses),
:mod:`~lensaudit.check.findings` (the registry's rules run on the parsed
files, on every core), :mod:`~lensaudit.check.matching` and
:mod:`~lensaudit.check.known` (what the baseline already has) and
:mod:`~lensaudit.check.result` (the records); the output formats are
:mod:`lensaudit.check_formats`. With ``cache=True``, the reader's tables of
each file are kept by the content of its bytes (:class:`lensaudit.read.Cache`,
shared with every other command) and reused for the same bytes, in the
database or in a baseline; the findings are worked out again every time.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from typing import Any

from .. import read as reader
from .inputs import (
    HISTORY_DEPTH,
    GitOrigin,
    Source,
    baseline_label,
    baseline_sources,
    sources_from_git,
    sources_from_paths,
)
from .known import Known
from .matching import baseline_notices, compare, readable_baseline
from .parsing import ParsedSource, parse_sources
from .result import (
    BAD_VALUE,
    BASELINE_UNREADABLE,
    CONFLICTING_CALIBRATION,
    DEFAULT_MARGIN,
    DUPLICATE_FOCAL,
    DUPLICATE_LENS,
    FILE_CODES,
    FOCAL_SERIES_OUTLIER,
    FOLD_BETWEEN_CALIBRATIONS,
    FOLD_IN_IMAGE,
    FOLD_NEAR_IMAGE,
    FOLD_OUTSIDE_IMAGE,
    INVERSION_FAILS_IN_IMAGE,
    LIBLENSFUN_REFUSES,
    MESSAGE_LIMIT,
    MISSING_ATTRIBUTE,
    NAME_LIMIT,
    NO_LENS,
    NOT_A_DATABASE,
    NOT_COMPUTABLE,
    QUOTED_LIMIT,
    SEVERITIES,
    SEVERITY_ERROR,
    SEVERITY_NOTICE,
    SEVERITY_WARNING,
    UNDEFINED_MOUNT,
    UNKNOWN_MODEL,
    UNREADABLE,
    VIGNETTING_STARTING_VALUES,
    XML_ERROR,
    CheckedFile,
    CheckError,
    CheckResult,
    Finding,
    Identified,
    describe,
    entry_key,
)

#: What :mod:`~lensaudit.check.findings` gives this package, loaded when first
#: asked for: the rules import numpy, which reading the files does not need, so
#: that a check imports it while the files are read (see :func:`check`).
_FROM_FINDINGS = {
    "analyse": "analyse",
    "analyse_parsed": "analyse_parsed",
    "fix_suggestion": "fix_suggestion",
}


def __getattr__(name: str) -> Any:
    if name in _FROM_FINDINGS:
        from . import findings

        return getattr(findings, _FROM_FINDINGS[name])
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _load_rules() -> None:
    """Import the rules (and numpy with them): done while the files are read."""
    from . import findings  # noqa: F401


__all__ = [
    "BAD_VALUE",
    "BASELINE_UNREADABLE",
    "CONFLICTING_CALIBRATION",
    "DEFAULT_MARGIN",
    "DUPLICATE_FOCAL",
    "DUPLICATE_LENS",
    "FILE_CODES",
    "FOCAL_SERIES_OUTLIER",
    "FOLD_BETWEEN_CALIBRATIONS",
    "FOLD_IN_IMAGE",
    "FOLD_NEAR_IMAGE",
    "FOLD_OUTSIDE_IMAGE",
    "HISTORY_DEPTH",
    "INVERSION_FAILS_IN_IMAGE",
    "LIBLENSFUN_REFUSES",
    "MESSAGE_LIMIT",
    "MISSING_ATTRIBUTE",
    "NAME_LIMIT",
    "NO_LENS",
    "NOT_A_DATABASE",
    "NOT_COMPUTABLE",
    "QUOTED_LIMIT",
    "SEVERITIES",
    "SEVERITY_ERROR",
    "SEVERITY_NOTICE",
    "SEVERITY_WARNING",
    "UNDEFINED_MOUNT",
    "UNKNOWN_MODEL",
    "UNREADABLE",
    "VIGNETTING_STARTING_VALUES",
    "XML_ERROR",
    "CheckError",
    "CheckResult",
    "CheckedFile",
    "Finding",
    "GitOrigin",
    "Identified",
    "Source",
    "analyse",
    "baseline_label",
    "baseline_sources",
    "check",
    "describe",
    "entry_key",
    "fix_suggestion",
    "sources_from_git",
    "sources_from_paths",
]


def check(
    paths: Sequence[str | os.PathLike[str]] | str | os.PathLike[str] | None = None,
    baseline: str | os.PathLike[str] | None = None,
    margin: float = DEFAULT_MARGIN,
    verbose: bool = False,
    cache: bool = False,
) -> CheckResult:
    """Check a Lensfun database: directories and/or XML files, where a Lensfun
    checkout means its ``data/db``; None: the checkout around the working
    directory, else the database bundled with lensfunpy.

    ``baseline`` is an existing directory or file, or else a git revision
    of the repository holding the paths; it is refused (:class:`CheckError`)
    when empty or blank, and when on disk it holds any of the files checked.
    ``margin`` (>= 1) is the r_normalized below which a fold outside the
    image is a warning; ``verbose`` adds the notices about folds. With
    ``cache``, the reader's tables of files with the same bytes as in an
    earlier run are reused, and those read now kept
    (:class:`lensaudit.read.Cache`); the result is the same either way.
    Raises :class:`lensaudit.read.LoadError` (:class:`CheckError` included)
    when the input or the baseline cannot be read at all.
    """
    if not margin >= 1 or math.isinf(margin):
        raise CheckError(f"margin {margin} must be a finite number >= 1")
    # resolve() maps a Lensfun checkout to its data/db (read.paths.database_directory),
    # for the baseline too, which is read at the same paths.
    source = reader.resolve(paths)
    if baseline is not None:  # refused before any file is read
        baseline = baseline_label(baseline, source.paths)
    sources = sources_from_paths(source.paths)
    if all(s.data is None for s in sources):
        raise CheckError(
            "no file could be read: " + "; ".join(f"{s.display}: {s.error}" for s in sources)
        )
    store = reader.Cache() if cache else None  # one for the database and its baseline
    read = parse_sources(sources, store, meanwhile=_load_rules)
    del sources  # their bytes: the files are read, and memory is for what they hold
    try:
        return _check(source, read, baseline, margin, verbose, store)
    finally:
        if store is not None:
            store.save()  # the metrics worked out by the rules


def _check(
    source: reader.DatabaseSource,
    read: list[ParsedSource],
    baseline: str | os.PathLike[str] | None,
    margin: float,
    verbose: bool,
    cache: reader.Cache | None,
) -> CheckResult:
    # inputs -> parsing (done) -> findings (-> matching, with a baseline) -> CheckResult
    from .findings import analyse_parsed

    if baseline is None:
        files, current = analyse_parsed(read, margin, verbose, cache)
        return CheckResult(source.label, None, margin, files, [c.finding for c in current])
    label = os.fspath(baseline)
    # A baseline file with the same bytes as one of the database is not parsed again.
    before_read = parse_sources(baseline_sources(label, source.paths), cache, read)
    before_read, kept, replaced, incomparable = readable_baseline(before_read, HISTORY_DEPTH, cache)
    # What the baseline holds places each duplicate on the one of its two the change added.
    by_digest: dict[bytes, list] = {}  # what each file makes alone, by its bytes' digest
    files, current = analyse_parsed(read, margin, verbose, cache, Known(before_read), by_digest)
    # The baseline's files the change left alone make what they made in the database.
    _, before = analyse_parsed(before_read, margin, verbose, cache, None, by_digest)
    findings, resolved = compare(current, before + kept, read, incomparable)
    notices = baseline_notices(read, label, replaced, incomparable)
    if notices:
        order = {f.source.display: index for index, f in enumerate(read)}
        findings = sorted(notices + findings, key=lambda f: (order.get(f.file, len(read)), f.line))
    return CheckResult(source.label, label, margin, files, findings, resolved)
