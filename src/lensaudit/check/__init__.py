"""Findings about a Lensfun database, or about a change to one: the CI gate.

:func:`check` audits a database and turns what it finds into
:class:`Finding` records, each with a severity, a code, ``file:line`` and one
sentence. Errors make the check fail; warnings and notices do not.

- Folds (entries that load and were audited): ``fold-in-image`` (error) when
  the model folds back inside its own image, r_normalized < 1;
  ``fold-near-image`` (warning) when the fold lies just outside, r_normalized
  below the margin; ``fold-outside-image`` (notice, only when asked for) for
  any other finite r_max. r_normalized = D(r_max) / hypot(aspect, 1), both in
  Hugin units (1 = half the short side of the calibration image).
- Zooms as liblensfun interpolates them (see :mod:`lensaudit.check.between`):
  ``fold-between-calibrations`` (error) when, at some focal length between
  two calibrations of a lens that do not fold themselves, the model
  liblensfun interpolates folds back inside the image; proven over every
  focal length, not sampled.
- Input (errors): ``xml-error`` (the file is not well-formed XML; its entries
  are counted but not checked further), ``not-a-database`` (well-formed, but
  its root is not ``<lensdatabase>``), ``unreadable``, ``missing-attribute``,
  ``bad-value`` (not a finite number, focal or crop factor <= 0),
  ``unknown-model``, ``no-lens``, ``r-max-not-computable``,
  ``liblensfun-refuses`` (Lensfun master's liblensfun stops loading the file
  there and loses the lenses after it; see :mod:`lensaudit.check.loading`;
  not repeated for a file that is ``xml-error`` at that spot).
- ``encoding-mismatch`` (warning): the file's XML declaration names an
  encoding its bytes are not in; liblensfun reads them as UTF-8, as lensaudit
  does, a reader that follows the declaration reads other names.
- Vignetting and TCA (see :mod:`lensaudit.vignetting` and :mod:`lensaudit.tca`):
  ``vignetting-zero-in-image`` (error) when the correction's C(r) reaches 0
  inside the image, ``vignetting-low-in-image`` (warning) when it falls below
  0.1, ``vignetting-not-monotone`` (notice, only when asked for) when it turns,
  ``tca-fold-in-image`` (error) when a colour channel folds inside the image;
  a ``<vignetting>`` or ``<tca>`` element that cannot be audited is one of the
  input errors above, its message naming the element.
- Duplicates: ``duplicate-lens`` (maker, model and crop factor of an earlier
  ``<lens>``, names compared ignoring letter case and runs of white space)
  and ``duplicate-focal`` (a second ``<distortion>`` for the same focal
  length in one calibration) are errors, or warnings when the two are
  identical, since liblensfun then loses nothing by keeping one of them.
- Metadata Lensfun's own CI does not check (warnings, see
  :mod:`lensaudit.check.metadata`): ``undefined-mount``,
  ``conflicting-calibration``, ``vignetting-starting-values``.
- Inversion (warning, see :mod:`lensaudit.check.inversion`):
  ``inversion-fails-in-image`` where liblensfun's reverse transform cannot
  invert the model by its Newton steps inside the image (not reported for an
  entry that is ``fold-in-image``).
- Focal series (a warning, see :mod:`lensaudit.check.series`):
  ``focal-series-outlier``, a distortion entry whose displacement D(r) - r
  lies far from what its neighbours in focal length predict.

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
:mod:`~lensaudit.check.findings` and :mod:`~lensaudit.check.duplicates` (the
rules, with :mod:`~lensaudit.check.metadata` and :mod:`~lensaudit.check.series`),
:mod:`~lensaudit.check.matching` (what the baseline already has) and
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
from .duplicates import Known
from .inputs import (
    HISTORY_DEPTH,
    GitOrigin,
    Source,
    baseline_sources,
    sources_from_git,
    sources_from_paths,
)
from .matching import baseline_notices, compare, readable_baseline
from .parsing import ParsedSource, parse_sources
from .result import (
    BAD_VALUE,
    BASELINE_UNREADABLE,
    CONFLICTING_CALIBRATION,
    DEFAULT_MARGIN,
    DUPLICATE_FOCAL,
    DUPLICATE_LENS,
    ENCODING_MISMATCH,
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
    "_fix_suggestion": "fix_suggestion",  # by the private name some callers use
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
    "ENCODING_MISMATCH",
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

    ``baseline``
    is an existing directory or file, or else a git revision of the
    repository holding the paths. ``margin`` (>= 1) is the r_normalized
    below which a fold outside the image is a warning; ``verbose`` adds the
    notices about folds. With ``cache``, the reader's tables of files with
    the same bytes as in an earlier run are reused, and those read now kept
    (:class:`lensaudit.read.Cache`); the result is the same either way.
    Raises :class:`lensaudit.read.LoadError` (:class:`CheckError` included)
    when the input or the baseline cannot be read at all.
    """
    if not margin >= 1 or math.isinf(margin):
        raise CheckError(f"margin {margin} must be a finite number >= 1")
    # resolve() maps a Lensfun checkout to its data/db (read.paths.database_directory),
    # for the baseline too, which is read at the same paths.
    source = reader.resolve(paths)
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
    own: dict[bytes, list] = {}  # what each file makes alone, by its bytes' digest
    files, current = analyse_parsed(read, margin, verbose, cache, Known(before_read), own)
    # The baseline's files the change left alone make what they made in the database.
    _, before = analyse_parsed(before_read, margin, verbose, cache, None, own)
    findings, resolved = compare(current, before + kept, read, incomparable)
    notices = baseline_notices(read, label, replaced, incomparable)
    if notices:
        order = {f.source.display: index for index, f in enumerate(read)}
        findings = sorted(notices + findings, key=lambda f: (order.get(f.file, len(read)), f.line))
    return CheckResult(source.label, label, margin, files, findings, resolved)
