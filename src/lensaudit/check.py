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
- Input (errors): ``xml-error`` (the file is not well-formed XML; its entries
  are counted but not checked further), ``unreadable``, ``missing-attribute``,
  ``bad-value`` (not a finite number, focal or crop factor <= 0),
  ``unknown-model``, ``no-lens``, ``duplicate-lens`` (maker, model and crop
  factor of an earlier ``<lens>``, names compared ignoring letter case and
  runs of white space), ``duplicate-focal`` (a second ``<distortion>`` for
  the same focal length in one calibration), ``r-max-not-computable``.

With a baseline (a directory, or a git revision of the repository that holds
the database, read with ``git ls-tree`` and ``git cat-file`` so that the work
tree is never touched), a finding that the baseline has too is marked
``known`` and does not fail the check. Entries are matched by (maker, lens,
crop factor, model, focal), not by line: a finding is known when an entry
with the same key and the same values had the same finding in the baseline,
so only new and changed entries can fail.
"""

from __future__ import annotations

import math
import os
import re
import subprocess
from collections.abc import Hashable, Iterable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from . import database, loader
from .loader import LoadError

SEVERITY_ERROR = "error"
SEVERITY_WARNING = "warning"
SEVERITY_NOTICE = "notice"
SEVERITIES = (SEVERITY_ERROR, SEVERITY_WARNING, SEVERITY_NOTICE)

#: r_normalized below which a fold just outside the image is a warning.
DEFAULT_MARGIN = 1.1

FOLD_IN_IMAGE = "fold-in-image"
FOLD_NEAR_IMAGE = "fold-near-image"
FOLD_OUTSIDE_IMAGE = "fold-outside-image"
NOT_COMPUTABLE = "r-max-not-computable"
XML_ERROR = "xml-error"
UNREADABLE = "unreadable"
MISSING_ATTRIBUTE = "missing-attribute"
BAD_VALUE = "bad-value"
UNKNOWN_MODEL = "unknown-model"
NO_LENS = "no-lens"
DUPLICATE_LENS = "duplicate-lens"
DUPLICATE_FOCAL = "duplicate-focal"

_STATUS_CODES = {
    loader.STATUS_MISSING_ATTRIBUTE: MISSING_ATTRIBUTE,
    loader.STATUS_BAD_VALUE: BAD_VALUE,
    loader.STATUS_UNKNOWN_MODEL: UNKNOWN_MODEL,
    loader.STATUS_NO_LENS: NO_LENS,
    loader.STATUS_UNREADABLE: UNREADABLE,
}

#: Longest name and message put into a finding; hostile files can hold megabytes.
NAME_LIMIT = 80
MESSAGE_LIMIT = 400
QUOTED_LIMIT = 40
_QUOTED = re.compile(rf"'([^']{{{QUOTED_LIMIT}}})[^']{{2,}}'")


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
    never fail the check.
    """

    severity: str
    code: str
    file: str
    line: int
    column: int
    message: str
    entry_key: tuple = ()
    known: bool = False

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

    def relative_to(self, root: str | os.PathLike[str]) -> CheckResult:
        """The same result with file paths relative to ``root`` where they lie under it.

        GitHub places annotations by paths relative to the repository root.
        """
        root = Path(root).resolve()
        names = {}
        for file in self.files:
            if file.path is not None and file.path.is_relative_to(root):
                names[file.file] = file.path.relative_to(root).as_posix()
        files = [replace(f, file=names.get(f.file, f.file)) for f in self.files]
        findings = [replace(f, file=names.get(f.file, f.file)) for f in self.findings]
        return replace(self, files=files, findings=findings)


@dataclass(frozen=True)
class Source:
    """The bytes of one database file, wherever they come from.

    ``name`` identifies the file across revisions (relative to the database
    path given), ``display`` is how it is shown, ``path`` is where it is on
    disk (None for a file read from git). ``data`` is None when the file
    could not be read, and ``error`` says why.
    """

    name: str
    display: str
    path: Path | None
    data: bytes | None
    error: str = ""


def check(
    paths: Sequence[str | os.PathLike[str]] | str | os.PathLike[str] | None = None,
    baseline: str | os.PathLike[str] | None = None,
    margin: float = DEFAULT_MARGIN,
    verbose: bool = False,
) -> CheckResult:
    """Check a Lensfun database (directories and/or XML files; None: the bundled one).

    ``baseline`` is an existing directory or file, or else a git revision of
    the repository holding the paths. ``margin`` (>= 1) is the r_normalized
    below which a fold outside the image is a warning; ``verbose`` adds the
    notices. Raises :class:`lensaudit.loader.LoadError` (:class:`CheckError`
    included) when the input or the baseline cannot be read at all.
    """
    if not margin >= 1 or math.isinf(margin):
        raise CheckError(f"margin {margin} must be a finite number >= 1")
    if isinstance(paths, (str, os.PathLike)):
        paths = [paths]
    source = database.resolve(list(paths) if paths else None)
    sources = sources_from_paths(source.paths)
    if all(s.data is None for s in sources):
        raise CheckError(
            "no file could be read: " + "; ".join(f"{s.display}: {s.error}" for s in sources)
        )
    files, current = analyse(sources, margin, verbose)
    findings = [finding for finding, _, _ in current]
    resolved = 0
    baseline_label = None
    if baseline is not None:
        baseline_label = os.fspath(baseline)
        _, before = analyse(baseline_sources(baseline_label, source.paths), margin, verbose)
        remaining: dict[Hashable, list[str]] = {}
        for _, identity, name in before:
            remaining.setdefault(identity, []).append(name)
        for index, (finding, identity, _) in enumerate(current):
            if remaining.get(identity):
                remaining[identity].pop()
                findings[index] = replace(finding, known=True)
        # Entries of a file that no longer parses are not checked: their
        # findings are not gone, only unseen.
        broken = {name for finding, _, name in current if finding.code == XML_ERROR}
        resolved = sum(name not in broken for names in remaining.values() for name in names)
    return CheckResult(source.label, baseline_label, margin, files, findings, resolved)


# ---------------------------------------------------------------------------
# Sources: files on disk, or blobs of a git revision


def sources_from_paths(paths: Iterable[str | os.PathLike[str]]) -> list[Source]:
    """The XML files that directories and files designate, read into memory.

    Files of a directory (``*.xml`` directly inside it) are named relative to
    it. Raises :class:`CheckError` for a path that does not exist and a
    directory without XML files; a file that cannot be read becomes a
    :class:`Source` without data.
    """
    sources: list[Source] = []
    seen: set[Path] = set()
    for given in map(Path, paths):
        if given.is_dir():
            try:
                files = loader.xml_files(given)
            except OSError as error:
                raise CheckError(
                    f"{given}: cannot list directory: {error.strerror or error}"
                ) from None
            if not files:
                raise CheckError(
                    f"{given}: directory holds no *.xml files "
                    f"(a Lensfun database is a directory of XML files)"
                )
            targets = [(file, file.name, str(file)) for file in files]
        elif given.exists():
            targets = [(given, str(given), str(given))]
        else:
            raise CheckError(f"{given}: no such file or directory")
        for file, name, display in targets:
            resolved = file.resolve()
            if resolved in seen:
                continue
            seen.add(resolved)
            try:
                data, error = file.read_bytes(), ""
            except OSError as os_error:
                data, error = None, f"cannot read file: {os_error.strerror or os_error}"
            sources.append(Source(name, display, resolved, data, error))
    return sources


def baseline_sources(baseline: str, paths: Sequence[str | os.PathLike[str]]) -> list[Source]:
    """The baseline's files: ``baseline`` itself if it exists on disk, else the
    same ``paths`` at git revision ``baseline``."""
    if Path(baseline).exists():
        return sources_from_paths([baseline])
    return sources_from_git(paths, baseline)


_GIT_ENVIRONMENT = {"GIT_OPTIONAL_LOCKS": "0", "GIT_TERMINAL_PROMPT": "0", "LC_ALL": "C"}


class _GitFailed(Exception):
    pass


def _git(arguments: list[str], cwd: Path, stdin: bytes | None = None) -> bytes:
    try:
        completed = subprocess.run(
            ["git", *arguments],
            cwd=cwd,
            input=stdin,
            capture_output=True,
            check=False,
            env={**os.environ, **_GIT_ENVIRONMENT},
        )
    except OSError as error:
        raise CheckError(
            f"cannot run git to read the baseline: {error.strerror or error}"
        ) from None
    if completed.returncode != 0:
        lines = completed.stderr.decode("utf-8", "replace").strip().splitlines()
        raise _GitFailed(lines[-1] if lines else f"git {arguments[0]} failed")
    return completed.stdout


def sources_from_git(paths: Sequence[str | os.PathLike[str]], revision: str) -> list[Source]:
    """The files ``paths`` designate, as they are at git ``revision``.

    Read with ``git ls-tree`` and ``git cat-file --batch`` from the
    repository holding each path, without touching its work tree or index.
    A path that did not exist at that revision contributes no file.
    """
    sources: list[Source] = []
    for given in map(Path, paths):
        directory = given if given.is_dir() else given.parent
        try:
            top = Path(os.fsdecode(_git(["rev-parse", "--show-toplevel"], directory).strip()))
        except _GitFailed:
            raise CheckError(
                f"--baseline {revision}: not an existing directory, and "
                f"{given} is not inside a git repository"
            ) from None
        try:
            commit = (
                _git(
                    [
                        "rev-parse",
                        "--verify",
                        "--quiet",
                        "--end-of-options",
                        f"{revision}^{{commit}}",
                    ],
                    top,
                )
                .decode()
                .strip()
            )
        except _GitFailed:
            raise CheckError(
                f"--baseline {revision}: not an existing directory, nor a "
                f"revision of the git repository at {top}"
            ) from None
        relative = Path(os.path.relpath(given.resolve(), top.resolve())).as_posix()
        if given.is_dir():
            spec = [] if relative == "." else ["--", relative + "/"]
        else:
            spec = ["--", relative]
        try:
            listing = _git(["ls-tree", "-z", commit, *spec], top)
        except _GitFailed as error:
            raise CheckError(f"--baseline {revision}: cannot list {given}: {error}") from None
        blobs = []
        for record in listing.split(b"\0"):
            meta, _, path = record.partition(b"\t")
            fields = meta.split()
            if len(fields) != 3 or fields[1] != b"blob" or fields[0] not in (b"100644", b"100755"):
                continue
            filename = os.fsdecode(path).rsplit("/", 1)[-1]
            if given.is_dir() and not filename.lower().endswith(".xml"):
                continue
            name = filename if given.is_dir() else str(given)
            blobs.append((name, fields[2]))
        blobs.sort()
        try:
            contents = _cat_file([oid for _, oid in blobs], top)
        except _GitFailed as error:
            raise CheckError(f"--baseline {revision}: cannot read {given}: {error}") from None
        for (name, _), data in zip(blobs, contents, strict=True):
            sources.append(Source(name, f"{revision}:{name}", None, data))
    return sources


def _cat_file(object_ids: list[bytes], repository: Path) -> list[bytes]:
    """Contents of the given blobs, through one ``git cat-file --batch``."""
    if not object_ids:
        return []
    output = _git(["cat-file", "--batch"], repository, b"".join(o + b"\n" for o in object_ids))
    contents, position = [], 0
    for object_id in object_ids:
        end = output.index(b"\n", position)
        header = output[position:end].split()
        if len(header) != 3 or header[0] != object_id:
            raise _GitFailed(f"object {object_id.decode()} is missing")
        size = int(header[2])
        contents.append(output[end + 1 : end + 1 + size])
        position = end + 1 + size + 1
    return contents


# ---------------------------------------------------------------------------
# Reading files: the loader's records, plus the structure the rules need


@dataclass(frozen=True)
class _Lens:
    line: int
    maker: str
    model: str
    crop_factor: float | str | None  # the number, the text if not a number, None if absent


@dataclass
class _File:
    source: Source
    entries: list[loader.DistortionEntry]
    problem: Finding | None = None  # the file-level finding, if any
    problem_text: str = ""  # the problem without its position, to match baselines
    lens_of_entry: list[int | None] | None = None  # index into ``lenses``, per entry
    lenses: tuple[_Lens, ...] = ()


_POSITION = re.compile(r",? ?(?:\(<string>, )?line (\d+), column (\d+)\)?\s*$")
_PARSER_HINTS = re.compile(
    r",? *(?:try XML_PARSE_HUGE|use XML_PARSE_HUGE option"
    r"|see xmlCtxtSetMaxAmplification)\.?\s*"
)


def _syntax_error(data: bytes, error: Exception) -> tuple[int, int, str]:
    """(line, column, sentence) for a libxml2 error, in words a user can act on."""
    text = (getattr(error, "msg", None) or str(error)).strip()
    match = _POSITION.search(text)
    if match:
        line, column, text = int(match.group(1)), int(match.group(2)), text[: match.start()]
    else:
        line = getattr(error, "lineno", 0) or 0
        column = (getattr(error, "offset", 0) or 0) + 1
    hinted = _PARSER_HINTS.search(text) is not None
    text = " ".join(_PARSER_HINTS.sub(" ", text).split())
    if not data.strip():
        return 1, 1, "the file is empty; a Lensfun database file holds a <lensdatabase> element"
    if hinted and "amplification" in text:
        text += " (entities are never expanded)"
    elif hinted:
        text += " (values and text over 10 MB and nesting over 256 levels are refused)"
    elif "encoding" in text.lower() or "utf-8" in text.lower():
        try:
            data.decode("utf-8")
        except UnicodeDecodeError as decode_error:
            text += (
                f" (byte 0x{data[decode_error.start]:02X} at offset {decode_error.start}"
                f" is not UTF-8; Lensfun database files are UTF-8)"
            )
    return line, column, text


def _read(source: Source) -> _File:
    """The records of one file, its file-level finding and its lens structure."""
    from lxml import etree

    if source.data is None:
        problem = Finding(
            SEVERITY_ERROR, UNREADABLE, source.display, 0, 0, f"{source.display}: {source.error}"
        )
        return _File(source, [], problem, source.error)
    data = source.data
    entries, load_error = loader.read_bytes(data, source.display)
    if load_error:
        entries = entries[1:]  # the file-level record; the finding replaces it
    try:
        root = etree.fromstring(data, loader.make_parser())
        position = None
    except etree.XMLSyntaxError as error:
        root = None
        position = _syntax_error(data, error)
    if position is None and load_error:
        match = re.search(r"line (\d+), column (\d+): (.*)", load_error, re.DOTALL)
        position = (
            (int(match.group(1)), int(match.group(2)), match.group(3))
            if match
            else (0, 0, load_error)
        )
    if position is not None:
        line, column, text = position
        if not load_error:
            # The whole file is judged, also where the loader's shortcut saw no error.
            note = f"file is not well-formed XML (line {line}, column {column}: {text})"
            entries = [
                replace(
                    e,
                    status=loader.STATUS_XML_ERROR,
                    message="; ".join(filter(None, (e.message, note))),
                )
                for e in entries
            ]
        message = _clip(f"XML is not well-formed at line {line}, column {column}: {text}")
        problem = Finding(SEVERITY_ERROR, XML_ERROR, source.display, line, column, message)
        return _File(source, entries, problem, text)
    lenses, lens_of_element = _lens_structure(root)
    elements = list(root.iter("distortion"))
    lens_of_entry = None
    if len(elements) == len(entries) and all(
        (element.sourceline or 0) == entry.line
        for element, entry in zip(elements, entries, strict=True)
    ):
        lens_of_entry = [lens_of_element.get(element) for element in elements]
    return _File(source, entries, lens_of_entry=lens_of_entry, lenses=lenses)


def _untranslated(element, tag: str) -> str | None:
    """Text of the last ``tag`` child without ``lang``, as liblensfun keeps it."""
    text = None
    for child in element.iterchildren(tag):
        if child.get("lang") is None:
            text = (child.text or "").strip()
    return text


def _lens_structure(root) -> tuple[tuple[_Lens, ...], dict]:
    """Every ``<lens>`` in document order, and the lens index of each ``<distortion>``."""
    lenses: list[_Lens] = []
    lens_of_element = {}
    for index, element in enumerate(root.iter("lens")):
        crop_text = _untranslated(element, "cropfactor")
        crop: float | str | None = crop_text
        if crop_text is not None:
            try:
                crop = loader.parse_number(crop_text)
            except ValueError:
                pass
        lenses.append(
            _Lens(
                element.sourceline or 0,
                _untranslated(element, "maker") or "",
                _untranslated(element, "model") or "",
                crop,
            )
        )
        for distortion in element.iter("distortion"):
            lens_of_element[distortion] = index  # the innermost lens wins: iterated last
    return tuple(lenses), lens_of_element


# ---------------------------------------------------------------------------
# The rules


def analyse(
    sources: Sequence[Source], margin: float = DEFAULT_MARGIN, verbose: bool = False
) -> tuple[list[CheckedFile], list[tuple[Finding, Hashable, str]]]:
    """Files and findings of one database.

    Each finding comes with the identity that matches it against a
    baseline's, and the name of its file.
    """
    read = [_read(source) for source in sources]
    files = [
        CheckedFile(
            f.source.display, f.source.path, len(f.entries), f.problem.message if f.problem else ""
        )
        for f in read
    ]
    ordered: list[tuple[tuple[int, int, int], Finding, Hashable]] = []

    def add(file_index: int, finding: Finding, identity: Hashable) -> None:
        ordered.append(((file_index, finding.line, len(ordered)), finding, identity))

    for index, file in enumerate(read):
        if file.problem is not None:
            add(
                index,
                file.problem,
                (file.problem.code, Path(file.source.name).name, file.problem_text),
            )

    entries = [
        (index, entry)
        for index, file in enumerate(read)
        if file.problem is None
        for entry in file.entries
    ]
    metrics = _metrics([entry for _, entry in entries])
    for position, (index, entry) in enumerate(entries):
        key = entry_key(entry)
        identity = (key, _fingerprint(entry))
        if entry.status != loader.STATUS_OK:
            code = _STATUS_CODES.get(entry.status, BAD_VALUE)
            add(index, _entry_finding(SEVERITY_ERROR, code, entry, entry.message), (code, identity))
            continue
        finding = _fold_finding(entry, metrics[position], margin, verbose)
        if finding is not None:
            add(index, finding, (finding.code, identity))

    for index, finding, identity in _duplicate_focals(read):
        add(index, finding, identity)
    for index, finding, identity in _duplicate_lenses(read):
        add(index, finding, identity)
    ordered.sort(key=lambda item: item[0])
    return files, [
        (finding, identity, Path(read[key[0]].source.name).name)
        for key, finding, identity in ordered
    ]


def entry_key(entry: loader.DistortionEntry) -> tuple:
    """(maker, lens, crop factor, model, focal): how an entry is matched across
    revisions. NaN values are None."""
    return (entry.maker, entry.lens, _number(entry.crop_factor), entry.model, _number(entry.focal))


def _number(value: float) -> float | None:
    return None if value != value else value


def _fingerprint(entry: loader.DistortionEntry) -> tuple:
    """What makes two entries with the same key the same entry."""
    return (
        entry.type,
        entry.status,
        *(
            _number(getattr(entry, name))
            for name in ("aspect_ratio", "real_focal", "a", "b", "c", "k1", "k2")
        ),
    )


@dataclass(frozen=True)
class _EntryMetrics:
    r_max: float
    d_max: float
    r_corner: float
    r_normalized: float
    problem: str = ""


def _metrics(entries: list[loader.DistortionEntry]) -> list[_EntryMetrics]:
    """r_max and the rest for each entry; entry by entry if the batch fails."""
    from .pipeline import audit_entries

    def batch(chunk: list[loader.DistortionEntry]) -> list[_EntryMetrics]:
        with np.errstate(all="ignore"):
            m = audit_entries(chunk).metrics
        return [
            _EntryMetrics(*values)
            for values in zip(
                m.r_max.tolist(),
                m.d_max.tolist(),
                m.r_corner.tolist(),
                m.r_normalized.tolist(),
                strict=True,
            )
        ]

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


def _clip(text: str, limit: int = MESSAGE_LIMIT) -> str:
    """``text`` on one line, at most ``limit`` characters.

    Quoted values are shortened first, so that the words after a huge value
    (``'999...' overflows a double``) survive.
    """
    text = _QUOTED.sub(lambda m: f"'{m.group(1)[:QUOTED_LIMIT]}\u2026'", " ".join(text.split()))
    return text if len(text) <= limit else text[: limit - 1] + "\u2026"


def _clip_key(key: tuple) -> tuple:
    """An entry key fit for output: strings cut to :data:`NAME_LIMIT` characters."""
    return tuple(
        v[: NAME_LIMIT - 1] + "\u2026" if isinstance(v, str) and len(v) > NAME_LIMIT else v
        for v in key
    )


def describe(entry: loader.DistortionEntry) -> str:
    """Short name of an entry: lens, model, focal and crop factor, as far as known."""
    name = _lens_name(entry.maker, entry.lens)
    details = []
    if entry.model:
        details.append(_clip(entry.model, 20))
    if entry.focal == entry.focal:
        details.append(f"{entry.focal:g} mm")
    if entry.crop_factor == entry.crop_factor:
        details.append(f"crop {entry.crop_factor:g}")
    if entry.type and entry.type != loader.DEFAULT_LENS_TYPE:
        details.append(_clip(entry.type, 20))
    return f"{name} ({', '.join(details)})" if details else name


def _lens_name(maker: str, lens: str) -> str:
    """ "Maker Model", or the model alone when it starts with the maker's name."""
    name = (
        lens if _normalized_name(lens).startswith(_normalized_name(maker)) else (f"{maker} {lens}")
    )
    return _clip(name, NAME_LIMIT) or "unnamed lens"


def _entry_finding(severity: str, code: str, entry: loader.DistortionEntry, text: str) -> Finding:
    return Finding(
        severity,
        code,
        entry.file,
        entry.line,
        0,
        _clip(f"{describe(entry)}: {text}"),
        _clip_key(entry_key(entry)),
    )


def _fold_finding(
    entry: loader.DistortionEntry, m: _EntryMetrics, margin: float, verbose: bool
) -> Finding | None:
    if m.problem or m.r_max != m.r_max:
        reason = m.problem or "the solver returned no value"
        return _entry_finding(
            SEVERITY_ERROR, NOT_COMPUTABLE, entry, f"r_max could not be computed ({reason})"
        )
    if math.isinf(m.r_max):
        return None
    if m.r_max == 0:
        return _entry_finding(
            SEVERITY_ERROR,
            FOLD_IN_IMAGE,
            entry,
            "D(r) decreases from the image centre (D'(0) <= 0): the model folds back at once",
        )
    where = (
        f"D(r) peaks at D(r_max) = {m.d_max:.4g} for r_max = {m.r_max:.4g}, "
        f"{m.r_normalized:.3f} times the image corner {m.r_corner:.4g} (Hugin units)"
    )
    if m.r_normalized < 1:
        return _entry_finding(
            SEVERITY_ERROR,
            FOLD_IN_IMAGE,
            entry,
            f"the model folds back inside its own image: {where}; "
            f"undistortion mirrors pixels beyond that radius",
        )
    if m.r_normalized < margin:
        return _entry_finding(
            SEVERITY_WARNING,
            FOLD_NEAR_IMAGE,
            entry,
            f"the model folds back just outside its image, within the margin {margin:g}: {where}",
        )
    if verbose:
        return _entry_finding(
            SEVERITY_NOTICE,
            FOLD_OUTSIDE_IMAGE,
            entry,
            f"the model folds back outside its image: {where}",
        )
    return None


def _duplicate_focals(read: list[_File]) -> Iterable[tuple[int, Finding, Hashable]]:
    """A second ``<distortion>`` for a focal length of the same calibration.

    A calibration is the entries of one ``<lens>`` with the same crop factor
    and aspect ratio (those a ``<calibration>`` element may override).
    """
    for index, file in enumerate(read):
        if file.problem is not None or file.lens_of_entry is None:
            continue
        first_line: dict[tuple, int] = {}
        for entry, lens in zip(file.entries, file.lens_of_entry, strict=True):
            if lens is None or entry.focal != entry.focal:
                continue
            calibration = (
                lens,
                _number(entry.crop_factor),
                _number(entry.aspect_ratio),
                entry.focal,
            )
            first = first_line.get(calibration)
            if first is None:
                first_line[calibration] = entry.line
                continue
            text = (
                f"a second distortion entry for {entry.focal:g} mm in the same "
                f"calibration (the first is at line {first}); liblensfun keeps "
                f"only one of them"
            )
            finding = _entry_finding(SEVERITY_ERROR, DUPLICATE_FOCAL, entry, text)
            yield index, finding, (DUPLICATE_FOCAL, (entry_key(entry), _fingerprint(entry)))


def _normalized_name(text: str) -> str:
    return " ".join(text.split()).casefold()


def _duplicate_lenses(read: list[_File]) -> Iterable[tuple[int, Finding, Hashable]]:
    """A ``<lens>`` whose maker, model and crop factor an earlier one has, in any file."""
    first: dict[tuple, tuple[str, int]] = {}
    for index, file in enumerate(read):
        if file.problem is not None:
            continue
        for lens in file.lenses:
            key = (_normalized_name(lens.maker), _normalized_name(lens.model), lens.crop_factor)
            where = first.setdefault(key, (file.source.display, lens.line))
            if where == (file.source.display, lens.line):
                continue
            crop = (
                f"crop factor {lens.crop_factor:g}"
                if isinstance(lens.crop_factor, float)
                else "no crop factor"
                if lens.crop_factor is None
                else f"crop factor {_clip(lens.crop_factor, 20)!r}"
            )
            name = _lens_name(lens.maker, lens.model)
            text = (
                f"lens {name} ({crop}) is already defined at {where[0]}:{where[1]}; "
                f"liblensfun keeps only one of them"
            )
            finding = Finding(
                SEVERITY_ERROR,
                DUPLICATE_LENS,
                file.source.display,
                lens.line,
                0,
                _clip(text),
                _clip_key((lens.maker, lens.model, lens.crop_factor)),
            )
            yield index, finding, (DUPLICATE_LENS, key)
