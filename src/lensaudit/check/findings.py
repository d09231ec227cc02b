"""The rules: from parsed files to findings, each with the identities that
match it against a baseline's (:class:`lensaudit.check.result.Identified`).

Input problems, folds and failed inversions (:mod:`lensaudit.check.inversion`)
of the distortion entries, the vignetting and TCA audits' findings, then the
duplicates (:mod:`lensaudit.check.duplicates`), the zooms' folds between
calibrations (:mod:`lensaudit.check.between`), the metadata Lensfun's own CI
does not check (:mod:`lensaudit.check.metadata`) and the entries that break
their lens's focal series (:mod:`lensaudit.check.series`).
"""

from __future__ import annotations

import math
import re
import shlex
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Any

from .. import calibrations, pipeline, tca, vignetting
from ..metrics import is_circular_fisheye
from ..read import Cache, parallel
from ..read.records import (
    STATUS_BAD_VALUE,
    STATUS_MISSING_ATTRIBUTE,
    STATUS_NO_LENS,
    STATUS_NOT_DATABASE,
    STATUS_OK,
    STATUS_UNKNOWN_MODEL,
    STATUS_UNREADABLE,
    DistortionEntry,
)
from ..read.tables import TCA, VIGNETTING
from .between import folds_between
from .duplicates import Known, duplicate_focals, duplicate_lenses
from .inputs import Source
from .inversion import inversion_findings
from .loading import liblensfun_refusals
from .matching import calibration_content, entry_content, file_identified, lens_identity
from .metadata import conflicting_calibrations, starting_values, undefined_mounts
from .parsing import ParsedSource, parse_sources
from .result import (
    BAD_VALUE,
    DEFAULT_MARGIN,
    FOLD_IN_IMAGE,
    FOLD_NEAR_IMAGE,
    FOLD_OUTSIDE_IMAGE,
    MISSING_ATTRIBUTE,
    NO_LENS,
    NOT_A_DATABASE,
    NOT_COMPUTABLE,
    SEVERITY_ERROR,
    SEVERITY_NOTICE,
    SEVERITY_WARNING,
    UNKNOWN_MODEL,
    UNREADABLE,
    CheckedFile,
    Finding,
    Identified,
    clip,
    clip_key,
    entry_finding,
    entry_key,
)
from .series import series_outliers

#: Vignetting or TCA records audited in one batch of arrays.
_RECORDS_AT_ONCE = 16384

_STATUS_CODES = {
    STATUS_MISSING_ATTRIBUTE: MISSING_ATTRIBUTE,
    STATUS_BAD_VALUE: BAD_VALUE,
    STATUS_UNKNOWN_MODEL: UNKNOWN_MODEL,
    STATUS_NO_LENS: NO_LENS,
    STATUS_UNREADABLE: UNREADABLE,
    STATUS_NOT_DATABASE: NOT_A_DATABASE,
}


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
    own: dict[bytes, list[Identified]] | None = None,
) -> tuple[list[CheckedFile], list[Identified]]:
    """:func:`analyse` of files already parsed; findings in file and line order.
    The metrics of a file come from ``cache`` where it has them (see
    :func:`lensaudit.pipeline.file_metrics`); ``known``, what a baseline
    holds, places each duplicate on the one of its two the change added.

    ``own`` maps the digest of a file's bytes to the findings it makes alone
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

    def across() -> list[tuple[int, tuple]]:
        """The findings of the rules that look across files, as plain data."""
        found = [*duplicate_lenses(read, known), *undefined_mounts(read)]
        found += [(i, item) for i, file in enumerate(read) for item in liblensfun_refusals(file)]
        return [(index, _plain(item)) for index, item in found]

    for index, file in enumerate(read):
        if file.problem is not None:
            add(index, file_identified(file))
    own_findings, across_files = file_findings(read, margin, verbose, cache, known, own, across)
    # Each file's own findings, in the order the rules make them: a file's
    # findings on one line keep that order.
    for index, items in enumerate(own_findings):
        for item in items:
            add(index, item)
    for index, item in across_files:
        add(index, _identified(item))
    ordered.sort(key=lambda pair: pair[0])
    return files, [item for _, item in ordered]


def file_findings(
    read: Sequence[ParsedSource],
    margin: float,
    verbose: bool,
    cache: Cache | None = None,
    known: Known | None = None,
    own: dict[bytes, list[Identified]] | None = None,
    besides: Callable[[], list] = list,
) -> tuple[list[list[Identified]], list]:
    """The findings each file makes alone, per file: its distortion entries,
    vignetting and TCA records, duplicate focal lengths, conflicting
    calibrations, vignetting at the calibration script's starting values and
    focal-series outliers (none for a file with a file-level problem); and
    what ``besides()`` gives (plain data), worked out beside them, on the
    first core free. A file whose digest ``own`` holds has the findings it
    holds there (the same bytes make the same findings); the others are
    worked out and added to ``own``."""
    if own is None:
        return _file_findings(read, margin, verbose, cache, known, besides)
    found: list[list[Identified]] = [[] for _ in read]
    todo = []
    for index, file in enumerate(read):
        digest = file.digest
        if digest and digest in own:
            found[index] = list(own[digest])
        else:
            todo.append(index)
    made, also = _file_findings(
        [read[index] for index in todo], margin, verbose, cache, known, besides
    )
    for index, items in zip(todo, made, strict=True):
        found[index] = items
        if read[index].digest:
            own[read[index].digest] = items
    return found, also


def _file_findings(
    read: Sequence[ParsedSource],
    margin: float,
    verbose: bool,
    cache: Cache | None,
    known: Known | None,
    besides: Callable[[], list] = list,
) -> tuple[list[list[Identified]], list]:
    """:func:`file_findings` of files, every one worked out: the rules on
    every core where that pays, each core a share of the files (what a file
    makes alone does not depend on the others; see
    :func:`lensaudit.read.parallel.map_sized`), and ``besides()`` as one more
    item, taken by the first core free. The metrics of the entries are
    worked out with the rules, or first here with a ``cache``, which this
    process keeps."""
    found: list[list[Identified]] = [[] for _ in read]
    parsed = [index for index, file in enumerate(read) if file.problem is None]
    if not parsed:
        return found, besides()  # numpy and the audits are not needed
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
        return [[_plain(item) for item in items] for items in made]

    def job(batch: list[int] | None) -> list:
        return besides() if batch is None else batch_findings(batch)

    sizes = [read[index].size for index in parsed]
    batches = [[parsed[p] for p in share] for share in parallel.shares(sizes, parallel.cpus())]
    batch_sizes = [sum(read[index].size for index in batch) for batch in batches]
    # The rules across files cost a fraction of a share's: taken last, by the first core free.
    *made, also = parallel.map_sized(job, [*batches, None], [*batch_sizes, 0])
    for batch, items_of in zip(batches, made, strict=True):
        for index, items in zip(batch, items_of, strict=True):
            found[index] = [_identified(item) for item in items]
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


def _plain(item: Identified) -> tuple:
    """A finding as plain data (what a process sends back; see :func:`_identified`)."""
    return (tuple(vars(item.finding).values()), item.keys, item.names)


def _identified(plain: tuple) -> Identified:
    """The finding :func:`_plain` made plain data of."""
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
    metrics and r_corner of each one's entries (``solved``)."""
    found: list[list[Identified]] = [[] for _ in read]
    entries = [(index, entry) for index, file in enumerate(read) for entry in file.entries]
    metrics = [m for file_metrics, _ in solved for m in file_metrics]
    corners = [c for _, file_corners in solved for c in file_corners]
    inversions = inversion_findings([entry for _, entry in entries])
    for position, (index, entry) in enumerate(entries):
        if entry.status != STATUS_OK:
            code = _STATUS_CODES.get(entry.status, BAD_VALUE)
            made = [entry_finding(SEVERITY_ERROR, code, entry, entry.message)]
        else:
            entry_metrics = metrics[position]
            fold = None
            if entry_metrics is not None:  # None: never folds
                fold = _fold_finding(entry, entry_metrics, margin, verbose)
            made = [fold, inversions[position]]
            if fold is not None and fold.code == FOLD_IN_IMAGE:
                made = [fold]  # the fold is the finding; its inversion fails too, for that
        for finding in made:
            if finding is None:
                continue
            content = (finding.severity, finding.code, entry_content(entry))
            # The lens by name first; then by content alone, for a renamed lens.
            keys = ((*content, lens_identity(entry.maker, entry.lens)), content)
            found[index].append(Identified(finding, keys, (read[index].source.file_name,)))
    for index, item in calibration_findings(read, verbose):
        found[index].append(item)
    for index, item in duplicate_focals(read, known):
        found[index].append(item)
    names = [read[index].source.file_name for index, _ in entries]
    folding = [m is not None and not m.r_normalized >= 1 for m in metrics]
    for position, item in folds_between([e for _, e in entries], corners, folding, names, verbose):
        found[entries[position][0]].append(item)
    for index, item in series_outliers(read):
        found[index].append(item)
    for index, file in enumerate(read):
        found[index] += conflicting_calibrations(file)
        found[index] += starting_values(file)
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


def _fold_finding(
    entry: DistortionEntry, m: _EntryMetrics, margin: float, verbose: bool
) -> Finding | None:
    if m.problem or m.r_max != m.r_max:
        reason = m.problem or "the solver returned no value"
        return entry_finding(
            SEVERITY_ERROR, NOT_COMPUTABLE, entry, f"r_max could not be computed ({reason})"
        )
    if math.isinf(m.r_max):
        return None
    if m.r_max == 0:
        return entry_finding(
            SEVERITY_ERROR,
            FOLD_IN_IMAGE,
            entry,
            "D(r) decreases from the image centre (D'(0) <= 0): the model folds back at once",
        )

    image = "image circle" if is_circular_fisheye(entry.lens, entry.type) else "image corner"
    where = (
        f"D(r) peaks at D(r_max) = {m.d_max:.4g} for r_max = {m.r_max:.4g}, "
        f"{m.r_normalized:.3f} times the {image} {m.r_corner:.4g} (Hugin units)"
    )
    if m.r_normalized < 1:
        return entry_finding(
            SEVERITY_ERROR,
            FOLD_IN_IMAGE,
            entry,
            f"the model folds back inside its own image: {where}; "
            f"undistortion mirrors pixels beyond that radius; {fix_suggestion(entry)}",
        )
    if m.r_normalized < margin:
        return entry_finding(
            SEVERITY_WARNING,
            FOLD_NEAR_IMAGE,
            entry,
            f"the model folds back just outside its image, within the margin {margin:g}: {where}",
        )
    if verbose:
        return entry_finding(
            SEVERITY_NOTICE,
            FOLD_OUTSIDE_IMAGE,
            entry,
            f"the model folds back outside its image: {where}",
        )
    return None


#: Longest lens name a suggested command carries; a prefix selects the lens as well.
SUGGESTED_NAME_LIMIT = 100


def fix_suggestion(entry: DistortionEntry) -> str:
    """The ``lensaudit fix`` command that refits this entry, on the same database.

    ``--lens`` matches a part of the name, with runs of white space as one
    space: the command names the lens so (check prints a finding on one
    line), up to its first control character and at most
    :data:`SUGGESTED_NAME_LIMIT` characters, shell-quoted (``shlex.quote``),
    so that it can be pasted into a POSIX shell as it is printed.
    """
    name = re.split(r"[\x00-\x1f\x7f-\x9f]", " ".join(entry.lens.split()), maxsplit=1)[0]
    name = name[:SUGGESTED_NAME_LIMIT].strip()
    words = ["lensaudit", "fix", *(["--lens", name] if name else []), "--focal"]
    return f"`{shlex.join(words)} {entry.focal:g}` refits it"


def calibration_findings(
    read: Sequence[ParsedSource], verbose: bool
) -> Iterable[tuple[int, Identified]]:
    """Findings of the vignetting and TCA audits in the files that parsed.

    Their identity is content, as for distortion entries: the kind, the
    entry's own values, then its lens by name.
    """
    shown = {SEVERITY_ERROR, SEVERITY_WARNING} | ({SEVERITY_NOTICE} if verbose else set())
    parsed = [(index, file) for index, file in enumerate(read) if file.problem is None]
    for kind, module in ((VIGNETTING, vignetting), (TCA, tca)):
        parts = [file.calibrations[kind] for _, file in parsed if kind in file.calibrations]
        records = calibrations.CalibrationRecords.joined(kind, parts)
        if not records:
            continue
        owners = [
            index for index, file in parsed for _ in range(len(file.calibrations.get(kind, ())))
        ]
        # Each record is audited alone: a part at a time, the audit's arrays stay small.
        for start in range(0, len(records), _RECORDS_AT_ONCE):
            part = records.part(start, start + _RECORDS_AT_ONCE)
            for position, item in _calibration_findings(kind, module, part, shown):
                index = owners[start + position]
                yield index, item._replace(names=(read[index].source.file_name,))


def _calibration_findings(
    kind: str, module: Any, records: calibrations.CalibrationRecords, shown: set[str]
) -> Iterable[tuple[int, Identified]]:
    """(position in ``records``, finding) of each of the vignetting or TCA
    audit's findings whose severity is ``shown``; its file names come later."""
    import numpy as np  # numpy: only where arrays are needed, not on importing this module

    with np.errstate(all="ignore"):
        audit = module.audit_entries(records)
    severities = audit.metrics["severity"].tolist()
    # Entry objects only for the records with a finding: a database has tens of thousands.
    for position, status in enumerate(records.column("status")):
        if status == STATUS_OK:
            if severities[position] not in shown:
                continue
        elif status not in calibrations.STATUS_CODES:
            continue
        entry = records[position]
        record = _calibration_record(audit, position)
        for severity, code, _, _, message in module.findings([record]):
            finding = Finding(
                severity,
                code,
                entry.file,
                entry.line,
                0,
                clip(message),
                clip_key(entry_key(entry)),  # the same fields as a distortion entry's
            )
            content = (severity, code, kind, calibration_content(entry))
            keys = ((*content, lens_identity(entry.maker, entry.lens)), content)
            yield position, Identified(finding, keys, ())


def _calibration_record(audit: calibrations.CalibrationAudit, position: int) -> dict:
    """One entry of a vignetting or TCA audit as the dict its ``records()`` gives."""
    entry = audit.entries[position]
    ok = entry.status == STATUS_OK
    record = {}
    for name in audit.COLUMNS:
        if name not in audit.METRIC_COLUMNS:
            record[name] = getattr(entry, name)
        elif name in audit.BOOL_COLUMNS:
            record[name] = bool(audit.metrics[name][position]) if ok else None
        else:
            value = audit.metrics[name][position]
            record[name] = value.item() if hasattr(value, "item") else value
    return record
