"""From parsed files to findings, each with the identities that match it
against a baseline's (:class:`lensaudit.check.result.Identified`): the
registry's rules (:mod:`lensaudit.check.rules`) run on every core, those that
look at each file alone on a share of the files each, those that look across
files once, beside them; the metrics of the distortion entries worked out
first (or taken from the cache).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from .. import pipeline
from ..read import Cache, parallel
from ..read.records import DistortionEntry
from . import rules
from .inputs import Source
from .known import Known
from .parsing import ParsedSource, parse_sources
from .result import DEFAULT_MARGIN, CheckedFile, Finding, Identified
from .rules.fold import fix_suggestion

__all__ = ["analyse", "analyse_parsed", "file_findings", "fix_suggestion"]


def analyse(
    sources: Sequence[Source], margin: float = DEFAULT_MARGIN, verbose: bool = False
) -> tuple[list[CheckedFile], list[Identified]]:
    """Files and findings of one database, each finding with what matches it
    against a baseline's (see :class:`Identified`)."""
    return analyse_parsed(parse_sources(sources), margin, verbose)


def analyse_parsed(
    read: Sequence[ParsedSource],
    margin: float,
    verbose: bool,
    cache: Cache | None = None,
    known: Known | None = None,
    by_digest: dict[bytes, list[Identified]] | None = None,
) -> tuple[list[CheckedFile], list[Identified]]:
    """:func:`analyse` of files already parsed; findings in file and line order.
    The metrics of a file come from ``cache`` where it has them (see
    :func:`lensaudit.pipeline.file_metrics`); ``known``, what a baseline
    holds, places each duplicate on the one of its two the change added.

    ``by_digest`` maps the digest of a file's bytes to the findings it makes alone
    (:func:`file_findings`): those of a file it holds are taken from it, not
    worked out again (a baseline shares most of its files with the database
    checked), and those worked out are added to it."""
    files = [
        CheckedFile(
            f.source.display, f.source.path, f.count, f.problem.message if f.problem else ""
        )
        for f in read
    ]
    ordered: list[tuple[tuple[int, int, int], Identified]] = []

    def add(file_index: int, item: Identified) -> None:
        ordered.append(((file_index, item.finding.line, len(ordered)), item))

    def rules_across_files() -> list[tuple[int, tuple]]:
        """The findings of the rules that look across files, as plain data."""
        context = rules.Context(read, margin, verbose, known)
        return [(index, _as_data(item)) for index, item in rules.run(rules.families(True), context)]

    own_findings, across_found = file_findings(
        read, margin, verbose, cache, known, by_digest, rules_across_files
    )
    # Each file's own findings, in the order the rules make them: a file's
    # findings on one line keep that order.
    for index, items in enumerate(own_findings):
        for item in items:
            add(index, item)
    for index, item in across_found:
        add(index, _from_data(item))
    ordered.sort(key=lambda pair: pair[0])
    return files, [item for _, item in ordered]


def file_findings(
    read: Sequence[ParsedSource],
    margin: float,
    verbose: bool,
    cache: Cache | None = None,
    known: Known | None = None,
    by_digest: dict[bytes, list[Identified]] | None = None,
    across_files: Callable[[], list] = list,
) -> tuple[list[list[Identified]], list]:
    """The findings each file makes alone, per file: its distortion entries,
    vignetting and TCA records, duplicate focal lengths, conflicting
    calibrations, vignetting at the calibration script's starting values and
    focal-series outliers (none for a file with a file-level problem); and
    what ``across_files()`` gives (plain data), worked out beside them, on the
    first core free. A file whose digest ``by_digest`` holds has the findings it
    holds there (the same bytes make the same findings); the others are
    worked out and added to ``by_digest``."""
    if by_digest is None:
        return _file_findings(read, margin, verbose, cache, known, across_files)
    found: list[list[Identified]] = [[] for _ in read]
    todo = []
    for index, file in enumerate(read):
        digest = file.digest
        if digest and digest in by_digest:
            found[index] = list(by_digest[digest])
        else:
            todo.append(index)
    made, also = _file_findings(
        [read[index] for index in todo], margin, verbose, cache, known, across_files
    )
    for index, items in zip(todo, made, strict=True):
        found[index] = items
        if read[index].digest:
            by_digest[read[index].digest] = items
    return found, also


def _file_findings(
    read: Sequence[ParsedSource],
    margin: float,
    verbose: bool,
    cache: Cache | None,
    known: Known | None,
    across_files: Callable[[], list] = list,
) -> tuple[list[list[Identified]], list]:
    """:func:`file_findings` of files, every one worked out: the rules on
    every core where that pays, each core a share of the files (what a file
    makes alone does not depend on the others; see
    :func:`lensaudit.read.parallel.map_sized`), and ``across_files()`` as one more
    item, taken by the first core free. The metrics of the entries are
    worked out with the rules, or first here with a ``cache``, which this
    process keeps."""
    found: list[list[Identified]] = [[] for _ in read]
    parsed = [index for index, file in enumerate(read) if file.problem is None]
    if not parsed:
        return found, across_files()  # numpy and the audits are not needed
    solved = None  # with a cache: index into read -> the metrics of its entries
    if cache is not None:
        solved = dict(zip(parsed, _solved([read[index] for index in parsed], cache), strict=True))

    def batch_findings(batch: list[int]) -> list[list[tuple]]:
        """The findings of the files of ``batch`` (indices into ``read``), as plain data."""
        files = [read[i] for i in batch]
        made = _rules(
            files,
            _solved(files, None) if solved is None else [solved[i] for i in batch],
            margin,
            verbose,
            known,
        )
        return [[_as_data(item) for item in items] for items in made]

    def job(batch: list[int] | None) -> list:
        return across_files() if batch is None else batch_findings(batch)

    sizes = [read[index].size for index in parsed]
    batches = [[parsed[p] for p in share] for share in parallel.shares(sizes, parallel.cpus())]
    batch_sizes = [sum(read[index].size for index in batch) for batch in batches]
    # The rules across files cost a fraction of a share's: taken last, by the first core free.
    *made, also = parallel.map_sized(job, [*batches, None], [*batch_sizes, 0])
    for batch, items_of in zip(batches, made, strict=True):
        for index, items in zip(batch, items_of, strict=True):
            found[index] = [_from_data(item) for item in items]
    return found, also


def _solved(
    files: list[ParsedSource], cache: Cache | None
) -> list[tuple[list[_EntryMetrics | None], list[float]]]:
    """The metrics and r_corner of each file's entries (see :func:`_metrics`)."""
    metrics, corners = _metrics(files, [entry for file in files for entry in file.entries], cache)
    solved = []
    start = 0
    for file in files:
        end = start + len(file.entries)
        solved.append((metrics[start:end], corners[start:end]))
        start = end
    return solved


def _as_data(item: Identified) -> tuple:
    """A finding as plain data (what a process sends back; see :func:`_from_data`)."""
    return (tuple(vars(item.finding).values()), item.keys, item.names)


def _from_data(plain: tuple) -> Identified:
    """The finding :func:`_as_data` made plain data of."""
    fields, keys, names = plain
    return Identified(Finding(*fields), keys, names)


def _rules(
    read: Sequence[ParsedSource],
    solved: Sequence[tuple[list[_EntryMetrics | None], list[float]]],
    margin: float,
    verbose: bool,
    known: Known | None,
) -> list[list[Identified]]:
    """The findings each of ``read`` (files that parsed) makes alone, given the
    metrics and r_corner of each one's entries (``solved``): the registry's
    rules that look at each file alone (:func:`lensaudit.check.rules.families`)."""
    found: list[list[Identified]] = [[] for _ in read]
    context = rules.Context(read, margin, verbose, known, solved)
    for index, item in rules.run(rules.families(False), context):
        found[index].append(item)
    return found


@dataclass(frozen=True)
class _EntryMetrics:
    r_max: float
    d_max: float
    r_corner: float
    r_normalized: float
    problem: str = ""


def _metrics(
    files: list[ParsedSource], entries: list[DistortionEntry], cache: Cache | None
) -> tuple[list[_EntryMetrics | None], list[float]]:
    """r_max and the rest for each entry of ``files`` (``entries``, those of
    files without a file-level problem), None where r_max is infinite, and
    each entry's r_corner: the pipeline's metrics of each file, from the
    cache where it has them; entry by entry where they cannot be had."""
    try:
        found, corners = [], []
        for file in files:
            m = pipeline.file_metrics(file.tables, cache)
            values = zip(m["r_max"], m["d_max"], m["r_corner"], m["r_normalized"], strict=True)
            # None for the common case, a model that never folds: nothing to report.
            found += [None if v[0] == math.inf else _EntryMetrics(*v) for v in values]
            corners += m["r_corner"]
        return found, corners
    except Exception:  # noqa: BLE001 - one bad entry must not hide the others' findings
        found = _entry_metrics(entries)
        return found, [math.nan if m is None else m.r_corner for m in found]


def _entry_metrics(entries: list[DistortionEntry]) -> list[_EntryMetrics | None]:
    """:func:`_metrics` of entries, in one batch, or entry by entry if it fails."""
    import numpy as np  # numpy: only where arrays are needed, not on importing this module

    def batch(chunk: list[DistortionEntry]) -> list[_EntryMetrics | None]:
        with np.errstate(all="ignore"):  # a bad entry is a finding, not a warning
            m = pipeline.audit_entries(chunk).metrics
        values = zip(
            m.r_max.tolist(),
            m.d_max.tolist(),
            m.r_corner.tolist(),
            m.r_normalized.tolist(),
            strict=True,
        )
        # None for the common case, a model that never folds: nothing to report.
        return [None if v[0] == math.inf else _EntryMetrics(*v) for v in values]

    try:
        return batch(entries)
    except Exception:  # noqa: BLE001 - one bad entry must not hide the others' findings
        pass
    results = []
    for entry in entries:
        try:
            results.extend(batch([entry]))
        except Exception as error:  # noqa: BLE001
            nan = math.nan
            results.append(_EntryMetrics(nan, nan, nan, nan, f"{type(error).__name__}: {error}"))
    return results
