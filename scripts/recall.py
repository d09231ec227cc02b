#!/usr/bin/env python
"""Recall of `lensaudit check` against what Lensfun's maintainers corrected.

    python scripts/recall.py /tmp/lensfun-db              # the whole first-parent line
    python scripts/recall.py /tmp/lensfun-db --since REV  # the commits after REV

A calibration element is a ``<distortion>``, ``<tca>`` or ``<vignetting>``
of a lens. It is identified by its kind, its lens (maker and model, without
case or white space, and crop factor) and its calibration point (focal
length; with aperture and distance for vignetting); its values are its
model and coefficients (and whether it loads), numbers compared as numbers:
a commit that only adds a lens type, an aspect ratio or a real focal length
corrects nothing.

For each first-parent commit C with parent P that changes a ``*.xml`` file
of the database directory, the elements of the changed files at P are
compared with those at C; a file that is not a well-formed database at P
or at C is left out (breaking or repairing a file corrects nothing). An
element is *corrected* by C when

- C has an element of the same identity, but none with its values
  (its values changed), or
- C has no element of its identity and none of its kind, calibration
  point and values under another identity (it was removed, not moved to
  a renamed lens or another crop factor).

Where one identity is held by several elements (a duplicate), they are
matched with C's elements of that identity one to one by value. A
*correction event* is a commit that corrects at least one element.

An element is *flagged* at P by a code when ``lensaudit check`` of the
database at P (no baseline, default margin) has an error or a warning of
that code on its line (or, for a finding about two elements, on the other
one's), on its lens's ``<lens>`` or ``<mount>`` line (a finding about the
lens, such as ``duplicate-lens`` or ``undefined-mount``), or on its whole
file (``xml-error``). Recall is the share of corrected elements flagged; the
base rate, the share of all elements of the database at those parents
(counted once per correction event) flagged, is printed beside it, so that
a rule that flags everything cannot look good.

The read cache lives in a temporary directory unless LENSAUDIT_CACHE_DIR is
set; the repository is only read (``git cat-file``), never checked out.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from collections import Counter, defaultdict
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from lensaudit import git as gitlayer  # noqa: E402
from lensaudit import read as reader  # noqa: E402
from lensaudit.check.findings import analyse_parsed  # noqa: E402
from lensaudit.check.inputs import Source  # noqa: E402
from lensaudit.check.matching import identity_name  # noqa: E402
from lensaudit.check.parsing import ParsedSource, parse_sources  # noqa: E402
from lensaudit.check.result import (  # noqa: E402
    DEFAULT_MARGIN,
    FILE_CODES,
    FOCAL_SERIES_OUTLIER,
    SEVERITY_ERROR,
    SEVERITY_WARNING,
    Finding,
)
from lensaudit.read.paths import loaded_name  # noqa: E402
from lensaudit.read.tables import SPECS, TCA, VIGNETTING  # noqa: E402

DB_DIR = "data/db"
DISTORTION = "distortion"
KINDS = (DISTORTION, TCA, VIGNETTING)
#: The values of each kind: its model and coefficients (not its lens type,
#: aspect ratio or real focal length, which metadata commits add or fix).
VALUES = {
    DISTORTION: ("model", "a", "b", "c", "k1", "k2", "status"),
    **{
        kind: ("model", *(f for f in spec.fields if f not in ("aperture", "distance")), "status")
        for kind, spec in SPECS.items()
    },
}


@dataclass(frozen=True)
class Element:
    """One calibration element of a file: kind, identity (see the module's
    docstring), values, file (as shown), line, its lens's index in the file
    and its aspect ratio (None if not a number)."""

    kind: str
    identity: tuple
    values: tuple
    file: str
    line: int
    lens: int | None
    aspect: float | None = None

    @property
    def point(self) -> tuple:
        """Kind, calibration point and values: what a moved element keeps."""
        return (self.kind, self.identity[-1], self.values)


@dataclass
class Change:
    """A first-parent commit that changes database files: its parent, the
    elements of those files before and after, and the corrected ones."""

    parent: str
    commit: str
    before: list[ParsedSource]
    after: list[ParsedSource]
    corrected: list[Element] = field(default_factory=list)


def git(repository: Path, *arguments: str) -> str:
    """Output of a git command, as text (:func:`lensaudit.git.run`)."""
    return gitlayer.run(repository, *arguments).decode("utf-8", "replace")


def _number(value: object) -> object:
    return None if isinstance(value, float) and value != value else value


def elements(file: ParsedSource) -> list[Element]:
    """The calibration elements of a parsed file (for a file that is not
    well-formed, the distortion entries recovery finds)."""
    found = []
    display = file.source.display
    for entry, lens in zip(file.entries, file.lens_of_entry, strict=True):
        identity = (identity_name(entry.maker), identity_name(entry.lens),
                    _number(entry.crop_factor), (_number(entry.focal),))  # fmt: skip
        values = tuple(_number(getattr(entry, name)) for name in VALUES[DISTORTION])
        aspect = _number(entry.aspect_ratio)
        found.append(Element(DISTORTION, identity, values, display, entry.line, lens, aspect))
    if file.problem is not None:
        return found
    tables = file.tables
    for kind, rows, owners in (
        (TCA, tables.tca, tables.lens_of_tca),
        (VIGNETTING, tables.vignetting, tables.lens_of_vignetting),
    ):
        names = SPECS[kind].row_fields
        point_names = ("focal", "aperture", "distance") if kind == VIGNETTING else ("focal",)
        for row, lens in zip(rows or (), owners or (), strict=True):
            record = dict(zip(names, row, strict=True))
            identity = (identity_name(record["maker"]), identity_name(record["lens"]),
                        _number(record["crop_factor"]),
                        tuple(_number(record[n]) for n in point_names))  # fmt: skip
            values = tuple(_number(record[name]) for name in VALUES[kind])
            aspect = _number(record["aspect_ratio"])
            found.append(Element(kind, identity, values, display, record["line"], lens, aspect))
    return found


def corrected(before: Sequence[Element], after: Sequence[Element]) -> list[Element]:
    """The elements of ``before`` that ``after`` corrects (see the module's docstring)."""
    remaining: dict[tuple, Counter] = defaultdict(Counter)
    for element in after:
        remaining[(element.kind, element.identity)][element.values] += 1
    points = {element.point for element in after}
    found = []
    for element in before:
        values = remaining.get((element.kind, element.identity))
        if values is not None and values[element.values] > 0:
            values[element.values] -= 1
        elif values is not None or element.point not in points:
            found.append(element)
    return found


def first_parent_line(repository: Path, since: str | None = None) -> list[tuple[str, str]]:
    """(parent, commit) of each first-parent commit after ``since`` (all if
    None), oldest first; root commits are left out."""
    window = f"{since}..HEAD" if since else "HEAD"
    pairs = []
    for line in git(repository, "rev-list", "--first-parent", "--parents", "--reverse",
                    window).splitlines():  # fmt: skip
        commit, *parents = line.split()
        if parents:
            pairs.append((parents[0], commit))
    return pairs


def read_files(repository: Path, revision: str, names: Sequence[str], cache) -> list[ParsedSource]:
    """The database files ``names`` at ``revision``, parsed; shown as
    ``revision:name``, as :func:`lensaudit.check.sources_from_git` shows them.
    A file absent at ``revision`` is left out."""
    requests = [f"{revision}:{DB_DIR}/{name}".encode() for name in names]
    sources = []
    for name, answer in zip(names, gitlayer.objects(repository, requests), strict=True):
        if answer is not None and answer[1] == "blob":
            sources.append(Source(name, f"{revision}:{name}", None, answer[2]))
    return parse_sources(sources, cache)


def changes(repository: Path, cache, since: str | None = None) -> Iterator[Change]:
    """Each first-parent commit (after ``since``) that changes a database
    file, with the elements it corrects."""
    for parent, commit in first_parent_line(repository, since):
        names = sorted(
            Path(path).name
            for path in git(
                repository, "diff", "--name-only", parent, commit, "--", DB_DIR
            ).splitlines()  # fmt: skip
            if loaded_name(Path(path).name) and str(Path(path).parent) == DB_DIR
        )
        if not names:
            continue
        before = read_files(repository, parent, names, cache)
        after = read_files(repository, commit, names, cache)
        # A file that does not parse on either side says nothing of its
        # elements there: breaking or repairing one corrects nothing.
        broken = {f.source.name for f in (*before, *after) if f.problem is not None}
        change = Change(parent, commit, before, after)
        change.corrected = corrected(
            [e for f in before if f.source.name not in broken for e in elements(f)],
            [e for f in after if f.source.name not in broken for e in elements(f)],
        )
        yield change


def whole_database(repository: Path, revision: str, cache) -> list[ParsedSource]:
    """Every ``*.xml`` of the database directory at ``revision``, parsed."""
    listing = git(repository, "ls-tree", "--name-only", f"{revision}:{DB_DIR}").split()
    names = [name for name in listing if loaded_name(name)]
    return read_files(repository, revision, sorted(names), cache)


def flags(read: list[ParsedSource], findings: Sequence[Finding]) -> dict[tuple, set[str]]:
    """{(file, line): codes} of the errors and warnings on each element of
    ``read`` (see the module's docstring)."""
    on_line: dict[tuple, set[str]] = defaultdict(set)
    on_file: dict[str, set[str]] = defaultdict(set)
    for finding in findings:
        if finding.severity not in (SEVERITY_ERROR, SEVERITY_WARNING):
            continue
        if finding.code in FILE_CODES:
            on_file[finding.file].add(finding.code)
            continue
        for file, line in ((finding.file, finding.line), *finding.related):
            on_line[(file, line)].add(finding.code)
    found: dict[tuple, set[str]] = {}
    for file in read:
        display = file.source.display
        lens_lines = [
            [lens.line, *(lens.line + offset for offset in lens.mount_lines)]
            for lens in file.tables.lenses
        ]
        for element in elements(file):
            codes = set(on_file.get(display, ())) | on_line.get((display, element.line), set())
            if element.lens is not None:
                for line in lens_lines[element.lens]:
                    codes |= on_line.get((display, line), set())
            found[(display, element.line, element.kind)] = codes
    return found


@dataclass
class Tally:
    """Counts of one row of the table."""

    corrected: int = 0
    flagged: int = 0
    elements: int = 0
    elements_flagged: int = 0

    def row(self, name: str) -> str:
        recall = f"{self.flagged / self.corrected:.1%}" if self.corrected else "-"
        base = f"{self.elements_flagged / self.elements:.2%}" if self.elements else "-"
        return f"{name:<34} {self.corrected:>9} {self.flagged:>8} {recall:>7} {base:>10}"


def measure(repository: Path, since: str | None = None) -> dict:
    """Corrected elements and correction events, flagged or not, by kind and
    by code, with the base rates; "without" repeats the kinds' counts with
    the focal-series-outlier findings left out."""
    cache = reader.Cache()
    by_kind: dict[str, Tally] = {kind: Tally() for kind in (*KINDS, "all")}
    by_code: dict[str, Tally] = defaultdict(Tally)
    without_series: dict[str, Tally] = {kind: Tally() for kind in (*KINDS, "all")}
    events = Counter()
    for change in changes(repository, cache, since):
        if not change.corrected:
            continue
        read = whole_database(repository, change.parent, cache)
        _, items = analyse_parsed(read, DEFAULT_MARGIN, False, cache)
        flagged = flags(read, [item.finding for item in items])
        events["events"] += 1
        event_flagged = event_flagged_without = False
        for element in change.corrected:
            codes = flagged.get((element.file, element.line, element.kind), set())
            others = codes - {FOCAL_SERIES_OUTLIER}
            for kind in (element.kind, "all"):
                by_kind[kind].corrected += 1
                by_kind[kind].flagged += bool(codes)
                without_series[kind].corrected += 1
                without_series[kind].flagged += bool(others)
            for code in codes:
                by_code[code].flagged += 1
            event_flagged |= bool(codes)
            event_flagged_without |= bool(others)
        events["flagged"] += event_flagged
        events["flagged without series"] += event_flagged_without
        seen_codes: Counter = Counter()
        for (_, _, kind), codes in flagged.items():
            others = codes - {FOCAL_SERIES_OUTLIER}
            for name in (kind, "all"):
                by_kind[name].elements += 1
                by_kind[name].elements_flagged += bool(codes)
                without_series[name].elements += 1
                without_series[name].elements_flagged += bool(others)
            seen_codes.update(codes)
        for code, count in seen_codes.items():
            by_code[code].elements_flagged += count
    for tally in by_code.values():
        tally.corrected = by_kind["all"].corrected
        tally.elements = by_kind["all"].elements
    cache.save()
    return {"kind": by_kind, "code": dict(by_code), "without": without_series, "events": events}


def table(measured: dict) -> str:
    """The measurement as a text table."""
    head = f"{'':<34} {'corrected':>9} {'flagged':>8} {'recall':>7} {'base rate':>10}"
    lines = [head]
    lines += [measured["kind"][kind].row(kind) for kind in (*KINDS, "all")]
    lines += [measured["without"][kind].row(f"{kind}, without {FOCAL_SERIES_OUTLIER}")
              for kind in (DISTORTION, "all")]  # fmt: skip
    lines.append("by code:")
    for code in sorted(measured["code"], key=lambda c: -measured["code"][c].flagged):
        lines.append(measured["code"][code].row(f"  {code}"))
    events = measured["events"]
    lines.append(
        f"correction events: {events['events']}, with a flagged element: {events['flagged']} "
        f"({events['flagged'] / max(events['events'], 1):.1%}); without "
        f"{FOCAL_SERIES_OUTLIER}: {events['flagged without series']}"
    )
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("repository", type=Path, help="a clone of Lensfun's database history")
    parser.add_argument("--since", help="only the first-parent commits after this revision")
    arguments = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as scratch:
        os.environ.setdefault("LENSAUDIT_CACHE_DIR", scratch)
        head = git(arguments.repository, "rev-parse", "--short", "HEAD").strip()
        print(f"{arguments.repository} at {head}, first-parent commits after "
              f"{arguments.since or 'the root'}")  # fmt: skip
        print(table(measure(arguments.repository, arguments.since)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
