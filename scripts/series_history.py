#!/usr/bin/env python
"""focal-series-outlier against what Lensfun's maintainers later corrected.

    python scripts/series_history.py /tmp/lensfun-db [--date 2021-05-30]

The revision R is the last first-parent commit whose committer date is on
or before ``--date`` (the end of that day, UTC). Elements, their identity
and when a commit *corrects* one are those of ``scripts/recall.py``
(coefficients changed, or the entry removed and not moved to a renamed lens).

(a) Precision over time: of the entries the rule flags in the database at
    R, how many a later first-parent commit corrects (the entry as it was
    at R: same identity and values).
(b) Recall of series corrections: a *series correction* is a first-parent
    commit after R that, in one series of an existing lens (the distortion
    entries of one lens, crop factor and aspect ratio in one file) of three
    or more focal lengths, changes the values of one or two entries and
    leaves the others and the set of focal lengths as they were. It is
    flagged when the rule, run on the files the commit changes as they are
    at its parent, flags one of the changed entries. Series of three are
    counted, though the rule judges series of four or more only.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from lensaudit import read as reader  # noqa: E402
from lensaudit.check.parsing import ParsedSource  # noqa: E402
from lensaudit.check.rules.focal_series_outlier import series_outliers  # noqa: E402
from recall import DISTORTION, Element, changes, elements, git, whole_database  # noqa: E402


@dataclass
class SeriesHistory:
    """What :func:`measure` found: the revision R, the entries flagged there
    and the commit that corrected each (None if none did), and the series
    corrections after R, each with whether the rule flagged it."""

    revision: str
    flagged: list[tuple[Element, str | None]]
    corrections: list[tuple[str, str, int, bool]]  # commit, lens, series size, flagged


def revision_at(repository: Path, date: str) -> str:
    """The last first-parent commit committed on or before ``date`` (YYYY-MM-DD, UTC)."""
    return git(repository, "rev-list", "--first-parent", "-1",
               f"--before={date} 23:59:59 +0000", "HEAD").strip()  # fmt: skip


def flagged_elements(read: Sequence[ParsedSource]) -> list[Element]:
    """The distortion elements of ``read`` that focal-series-outlier flags."""
    lines = {(item.finding.file, item.finding.line) for _, item in series_outliers(read)}
    return [
        element
        for file in read
        for element in elements(file)
        if element.kind == DISTORTION and (element.file, element.line) in lines
    ]


def _series(found: Sequence[Element]) -> dict[tuple, dict]:
    """{(file, lens identity, crop, aspect): {focal: values}} of distortion elements."""
    groups: dict[tuple, dict] = defaultdict(dict)
    for element in found:
        if element.kind != DISTORTION:
            continue
        name = element.file.split(":", 1)[-1]
        key = (name, *element.identity[:3], element.aspect)
        groups[key].setdefault(element.identity[3], element)
    return groups


def measure(repository: Path, date: str = "2021-05-30") -> SeriesHistory:
    """(a) and (b) of the module's docstring."""
    cache = reader.Cache()
    revision = revision_at(repository, date)
    at_revision = {(e.identity, e.values): e for e in
                   flagged_elements(whole_database(repository, revision, cache))}  # fmt: skip
    fixed: dict[tuple, str] = {}
    corrections = []
    for change in changes(repository, cache, since=revision):
        for element in change.corrected:
            key = (element.identity, element.values)
            if key in at_revision and key not in fixed:
                fixed[key] = change.commit
        broken = {f.source.name for f in (*change.before, *change.after) if f.problem is not None}
        before = [f for f in change.before if f.source.name not in broken]
        after = [f for f in change.after if f.source.name not in broken]
        if not before:
            continue
        after_series = _series([e for f in after for e in elements(f)])
        outliers = {(e.file, e.line) for e in flagged_elements(before)}
        for key, entries in _series([e for f in before for e in elements(f)]).items():
            later = after_series.get(key)
            if len(entries) < 3 or later is None or set(later) != set(entries):
                continue
            changed = [e for focal, e in entries.items() if later[focal].values != e.values]
            if 1 <= len(changed) <= 2:
                hit = any((e.file, e.line) in outliers for e in changed)
                corrections.append((change.commit, key[2], len(entries), hit))
    cache.save()
    flagged = [(e, fixed.get(key)) for key, e in at_revision.items()]
    return SeriesHistory(revision, flagged, corrections)


def table(found: SeriesHistory) -> str:
    """The measurement as text."""
    changed = sum(commit is not None for _, commit in found.flagged)
    hits = sum(hit for *_, hit in found.corrections)
    judged = [c for c in found.corrections if c[2] >= 4]
    lines = [
        f"R = {found.revision[:7]}",
        f"(a) flagged at R: {len(found.flagged)}, corrected later: {changed}",
    ]
    for element, commit in found.flagged:
        name = element.file.split(":", 1)[-1]
        lines.append(f"    {name}:{element.line} {element.identity[1]} "
                     f"{element.identity[3][0]:g} mm: {commit[:7] if commit else '-'}")  # fmt: skip
    lines.append(
        f"(b) series corrections after R: {len(found.corrections)} "
        f"({len(judged)} in series of 4 or more), flagged at the parent: {hits}"
    )
    for commit, lens, size, hit in found.corrections:
        lines.append(f"    {commit[:7]} {lens}, a series of {size}: {'flagged' if hit else '-'}")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("repository", type=Path, help="a clone of Lensfun's database history")
    parser.add_argument("--date", default="2021-05-30", help="R: the last commit on or before it")
    arguments = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as scratch:
        os.environ.setdefault("LENSAUDIT_CACHE_DIR", scratch)
        print(table(measure(arguments.repository, arguments.date)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
