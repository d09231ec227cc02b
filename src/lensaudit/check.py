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
  are counted but not checked further), ``not-a-database`` (well-formed, but
  its root is not ``<lensdatabase>``), ``unreadable``, ``missing-attribute``,
  ``bad-value`` (not a finite number, focal or crop factor <= 0),
  ``unknown-model``, ``no-lens``, ``r-max-not-computable``.
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
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Hashable, Iterable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import NamedTuple

import numpy as np

from . import calibrations, database, loader
from . import git as gitlayer
from .loader import LoadError
from .metrics import is_circular_fisheye

SEVERITY_ERROR = "error"
SEVERITY_WARNING = "warning"
SEVERITY_NOTICE = "notice"
SEVERITIES = (SEVERITY_ERROR, SEVERITY_WARNING, SEVERITY_NOTICE)

#: r_normalized below which a fold just outside the image is a warning.
DEFAULT_MARGIN = 1.1

#: How many commits that changed a file are searched for a version that parses,
#: when the baseline's version does not.
HISTORY_DEPTH = 50

FOLD_IN_IMAGE = "fold-in-image"
FOLD_NEAR_IMAGE = "fold-near-image"
FOLD_OUTSIDE_IMAGE = "fold-outside-image"
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

#: Findings about a whole file.
FILE_CODES = frozenset({XML_ERROR, NOT_A_DATABASE, UNREADABLE})

_STATUS_CODES = {
    loader.STATUS_MISSING_ATTRIBUTE: MISSING_ATTRIBUTE,
    loader.STATUS_BAD_VALUE: BAD_VALUE,
    loader.STATUS_UNKNOWN_MODEL: UNKNOWN_MODEL,
    loader.STATUS_NO_LENS: NO_LENS,
    loader.STATUS_UNREADABLE: UNREADABLE,
    loader.STATUS_NOT_DATABASE: NOT_A_DATABASE,
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


@dataclass(frozen=True)
class GitOrigin:
    """Where a file of a git baseline comes from: repository, commit, path in it."""

    repository: Path
    commit: str
    path: str


@dataclass(frozen=True)
class Source:
    """The bytes of one database file, wherever they come from.

    ``name`` identifies the file across revisions (relative to the database
    path given), ``display`` is how it is shown, ``path`` is where it is on
    disk (None for a file read from git, which has an ``origin`` instead).
    ``data`` is None when the file could not be read, and ``error`` says why.
    """

    name: str
    display: str
    path: Path | None
    data: bytes | None
    error: str = ""
    origin: GitOrigin | None = None

    @property
    def file_name(self) -> str:
        """The name without directories: what matches a file across revisions."""
        return Path(self.name).name


class Identified(NamedTuple):
    """A finding with what matches it against a baseline's findings.

    ``keys`` are its identities from the most to the least specific, each
    starting with the severity and the code (see :func:`_compare`).
    ``names`` are the names of the files the finding is about, its own first.
    """

    finding: Finding
    keys: tuple[Hashable, ...]
    names: tuple[str, ...]


def check(
    paths: Sequence[str | os.PathLike[str]] | str | os.PathLike[str] | None = None,
    baseline: str | os.PathLike[str] | None = None,
    margin: float = DEFAULT_MARGIN,
    verbose: bool = False,
) -> CheckResult:
    """Check a Lensfun database: directories and/or XML files, where a Lensfun
    checkout means its ``data/db``; None: the checkout around the working
    directory, else the database bundled with lensfunpy.

    ``baseline``
    is an existing directory or file, or else a git revision of the
    repository holding the paths. ``margin`` (>= 1) is the r_normalized
    below which a fold outside the image is a warning; ``verbose`` adds the
    notices about folds. Raises :class:`lensaudit.loader.LoadError`
    (:class:`CheckError` included) when the input or the baseline cannot be
    read at all.
    """
    if not margin >= 1 or math.isinf(margin):
        raise CheckError(f"margin {margin} must be a finite number >= 1")
    if isinstance(paths, (str, os.PathLike)):
        paths = [paths]
    # resolve() maps a Lensfun checkout to its data/db (database.database_directory),
    # for the baseline too, which is read at the same paths.
    source = database.resolve(list(paths) if paths else None)
    sources = sources_from_paths(source.paths)
    if all(s.data is None for s in sources):
        raise CheckError(
            "no file could be read: " + "; ".join(f"{s.display}: {s.error}" for s in sources)
        )
    read = [_read(s) for s in sources]
    files, current = _analyse(read, margin, verbose)
    if baseline is None:
        return CheckResult(source.label, None, margin, files, [c.finding for c in current])
    label = os.fspath(baseline)
    before_read = [_read(s) for s in baseline_sources(label, source.paths)]
    before_read, kept, replaced, incomparable = _readable_baseline(before_read)
    _, before = _analyse(before_read, margin, verbose)
    findings, resolved = _compare(current, before + kept, read, incomparable)
    notices = _baseline_notices(read, label, replaced, incomparable)
    if notices:
        order = {f.source.display: index for index, f in enumerate(read)}
        findings = sorted(notices + findings, key=lambda f: (order.get(f.file, len(read)), f.line))
    return CheckResult(source.label, label, margin, files, findings, resolved)


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
            targets = [(file, file.name, loader.display_path(file)) for file in files]
        elif given.exists():
            targets = [(given, str(given), loader.display_path(given))]
        else:
            raise CheckError(f"{given}: no such file or directory")
        for file, name, display in targets:
            resolved = file.resolve()
            if resolved in seen:
                continue
            seen.add(resolved)
            try:
                data, error = loader.read_regular_file(file), ""
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


def _git_call(call, *arguments):
    """``call(*arguments)`` of :mod:`lensaudit.git`; git that cannot run at all
    is a :class:`CheckError`."""
    try:
        return call(*arguments)
    except gitlayer.GitUnavailable as error:
        raise CheckError(f"cannot run git to read the baseline: {error}") from None


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
            top = _git_call(gitlayer.top_level, directory)
        except gitlayer.GitError:
            raise CheckError(
                f"--baseline {revision}: not an existing directory, and "
                f"{given} is not inside a git repository"
            ) from None
        try:
            commit = _git_call(gitlayer.resolve_commit, top, revision)
        except gitlayer.GitError:
            raise CheckError(
                f"--baseline {revision}: not an existing directory, nor a "
                f"revision of the git repository at {top}"
            ) from None
        relative = Path(os.path.relpath(given.resolve(), top.resolve())).as_posix()
        if given.is_dir():
            spec = [] if relative == "." else [relative + "/"]
        else:
            spec = [relative]
        try:
            listing = _git_call(gitlayer.list_tree, top, commit, spec)
        except gitlayer.GitError as error:
            raise CheckError(f"--baseline {revision}: cannot list {given}: {error}") from None
        blobs = []
        for item in listing:
            if item.type != "blob" or item.mode not in ("100644", "100755"):
                continue
            filename = item.path.rsplit("/", 1)[-1]
            if given.is_dir() and not filename.lower().endswith(".xml"):
                continue
            name = filename if given.is_dir() else str(given)
            blobs.append((name, item.oid, item.path))
        blobs.sort()
        try:
            contents = _cat_file([oid.encode() for _, oid, _ in blobs], top)
        except gitlayer.GitError as error:
            raise CheckError(f"--baseline {revision}: cannot read {given}: {error}") from None
        for (name, _, repository_path), data in zip(blobs, contents, strict=True):
            if data is None:
                raise CheckError(f"--baseline {revision}: cannot read {name}: object missing")
            origin = GitOrigin(top, commit, repository_path)
            sources.append(Source(name, f"{revision}:{name}", None, data, origin=origin))
    return sources


def _cat_file(objects: list[bytes], repository: Path) -> list[bytes | None]:
    """Contents of the given blobs (ids or ``rev:path``), through one
    ``git cat-file --batch``; None for an object that does not exist or is
    not a blob."""
    return [
        answer[2] if answer is not None and answer[1] == "blob" else None
        for answer in _git_call(lambda: list(gitlayer.objects(repository, objects)))
    ]


def _last_readable(source: Source) -> tuple[Source, str] | None:
    """The newest version of a git baseline's file that parses, among the last
    :data:`HISTORY_DEPTH` commits that changed it, and that commit's id."""
    from lxml import etree

    origin = source.origin
    if origin is None:
        return None
    try:
        commits = _git_call(
            gitlayer.log, origin.repository, origin.commit, origin.path, HISTORY_DEPTH
        )
        contents = _cat_file([f"{c}:{origin.path}".encode() for c in commits], origin.repository)
    except (gitlayer.GitError, UnicodeDecodeError):
        return None
    tried: set[bytes] = {source.data or b""}
    for commit, data in zip(commits, contents, strict=True):
        if data is None or data in tried:
            continue
        tried.add(data)
        try:
            root = etree.fromstring(data, loader.make_parser())
        except etree.XMLSyntaxError:
            continue
        if etree.QName(root).localname != loader.DATABASE_ROOT:
            continue
        return replace(source, data=data, origin=replace(origin, commit=commit)), commit
    return None


# ---------------------------------------------------------------------------
# Reading files: the loader's records, plus the structure the rules need


@dataclass(frozen=True)
class _Lens:
    line: int
    maker: str
    model: str
    crop_factor: float | str | None  # the number, the text if not a number, None if absent
    element: object = field(default=None, compare=False, repr=False)


@dataclass
class _File:
    source: Source
    entries: list[loader.DistortionEntry]
    problem: Finding | None = None  # the file-level finding, if any
    problem_text: str = ""  # the problem without its position, to match baselines
    lens_of_entry: list[int | None] | None = None  # index into ``lenses``, per entry
    lenses: tuple[_Lens, ...] = ()
    # <vignetting> and <tca> records of a file that parsed, by kind
    calibrations: dict[str, list] = field(default_factory=dict)


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

    display = source.display
    if source.data is None:
        problem = Finding(SEVERITY_ERROR, UNREADABLE, display, 0, 0, f"{display}: {source.error}")
        return _File(source, [], problem, source.error)
    data = source.data
    try:
        root = etree.fromstring(data, loader.make_parser())
    except etree.XMLSyntaxError as error:
        # The loader's records: one for the file, then what recovery mode salvages.
        entries, load_error = loader.read_bytes(data, display)
        if load_error:
            entries = entries[1:]
        line, column, text = _syntax_error(data, error)
        message = _clip(f"XML is not well-formed at line {line}, column {column}: {text}")
        problem = Finding(SEVERITY_ERROR, XML_ERROR, display, line, column, message)
        return _File(source, entries, problem, text)
    if b"xmlns" in data:
        loader.use_local_names(root)  # as the loader reads it: liblensfun ignores namespaces
    if root.tag != loader.DATABASE_ROOT:
        entries, load_error = loader.read_bytes(data, display)
        line = entries[0].line if entries else 1
        problem = Finding(SEVERITY_ERROR, NOT_A_DATABASE, display, line, 0, _clip(load_error))
        return _File(source, entries[1:], problem, load_error)
    entries = list(loader.entries_from_tree(root, display))
    lenses, lens_of_element = _lens_structure(root)
    elements = list(root.iter("distortion"))
    lens_of_entry = None
    if len(elements) == len(entries) and all(
        (element.sourceline or 0) == entry.line
        for element, entry in zip(elements, entries, strict=True)
    ):
        lens_of_entry = [lens_of_element.get(element) for element in elements]
    vignetting, tca = calibrations.entries_from_tree(root, display)
    return _File(
        source,
        entries,
        lens_of_entry=lens_of_entry,
        lenses=lenses,
        calibrations={calibrations.VIGNETTING: vignetting, calibrations.TCA: tca},
    )


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
            if crop != crop:
                crop = crop_text  # NaN would never equal itself as a key
        lenses.append(
            _Lens(
                element.sourceline or 0,
                _untranslated(element, "maker") or "",
                _untranslated(element, "model") or "",
                crop,
                element,
            )
        )
        for distortion in element.iter("distortion"):
            lens_of_element[distortion] = index  # the innermost lens wins: iterated last
    return tuple(lenses), lens_of_element


def _element_content(element, skip_names: bool = False) -> tuple:
    """An element's tag, attributes, text (white space collapsed) and child
    elements, recursively; comments left out. ``skip_names`` leaves out the
    untranslated ``<maker>`` and ``<model>`` children."""
    children = []
    for child in element:
        if not isinstance(child.tag, str):
            continue  # a comment or processing instruction
        if skip_names and child.tag in ("maker", "model") and child.get("lang") is None:
            continue
        children.append(_element_content(child))
    text = " ".join((element.text or "").split())
    return (element.tag, tuple(sorted(element.attrib.items())), text, tuple(children))


# ---------------------------------------------------------------------------
# The rules


def analyse(
    sources: Sequence[Source], margin: float = DEFAULT_MARGIN, verbose: bool = False
) -> tuple[list[CheckedFile], list[Identified]]:
    """Files and findings of one database, each finding with what matches it
    against a baseline's (see :class:`Identified`)."""
    return _analyse([_read(source) for source in sources], margin, verbose)


def _analyse(
    read: Sequence[_File], margin: float, verbose: bool
) -> tuple[list[CheckedFile], list[Identified]]:
    files = [
        CheckedFile(
            f.source.display, f.source.path, len(f.entries), f.problem.message if f.problem else ""
        )
        for f in read
    ]
    ordered: list[tuple[tuple[int, int, int], Identified]] = []

    def add(file_index: int, item: Identified) -> None:
        ordered.append(((file_index, item.finding.line, len(ordered)), item))

    for index, file in enumerate(read):
        if file.problem is not None:
            add(index, _file_identified(file))

    entries = [
        (index, entry)
        for index, file in enumerate(read)
        if file.problem is None
        for entry in file.entries
    ]
    metrics = _metrics([entry for _, entry in entries])
    for position, (index, entry) in enumerate(entries):
        if entry.status != loader.STATUS_OK:
            code = _STATUS_CODES.get(entry.status, BAD_VALUE)
            finding = _entry_finding(SEVERITY_ERROR, code, entry, entry.message)
        else:
            finding = _fold_finding(entry, metrics[position], margin, verbose)
            if finding is None:
                continue
        content = (finding.severity, finding.code, _entry_content(entry))
        # The lens by name first; then by content alone, for a renamed lens.
        keys = ((*content, _lens_identity(entry.maker, entry.lens)), content)
        add(index, Identified(finding, keys, (read[index].source.file_name,)))

    for index, item in _calibration_findings(read, verbose):
        add(index, item)
    for index, item in _duplicate_focals(read):
        add(index, item)
    for index, item in _duplicate_lenses(read):
        add(index, item)
    ordered.sort(key=lambda pair: pair[0])
    return files, [item for _, item in ordered]


def _file_identified(file: _File) -> Identified:
    """A file-level finding: the file's name and the problem, without its position."""
    problem = file.problem
    assert problem is not None
    identity = (problem.severity, problem.code, file.source.file_name, file.problem_text)
    return Identified(problem, (identity,), (file.source.file_name,))


def entry_key(entry: loader.DistortionEntry) -> tuple:
    """(maker, lens, crop factor, model, focal): how an entry is named in
    output. NaN values are None."""
    return (entry.maker, entry.lens, _number(entry.crop_factor), entry.model, _number(entry.focal))


def _number(value: float) -> float | None:
    return None if value != value else value


def _identity_name(text: str) -> str:
    """A maker or model name as identities compare it: without case or any
    white space, so that "RF200-800mm" and "RF 200-800mm" are one lens."""
    return "".join(text.split()).casefold()


def _lens_identity(maker: str, model: str) -> tuple[str, str]:
    return _identity_name(maker), _identity_name(model)


_LINE_NUMBER = re.compile(r"\bline \d+")


def _entry_content(entry: loader.DistortionEntry) -> tuple:
    """An entry's own values, without its lens's name, file or line."""
    message = "" if entry.status == loader.STATUS_OK else _LINE_NUMBER.sub("line", entry.message)
    return (
        entry.model,
        entry.type,
        entry.status,
        message,
        *(
            _number(getattr(entry, name))
            for name in ("focal", "crop_factor", "aspect_ratio", "real_focal")
        ),
        *(_number(getattr(entry, name)) for name in ("a", "b", "c", "k1", "k2")),
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
    image = "image circle" if is_circular_fisheye(entry.lens, entry.type) else "image corner"
    where = (
        f"D(r) peaks at D(r_max) = {m.d_max:.4g} for r_max = {m.r_max:.4g}, "
        f"{m.r_normalized:.3f} times the {image} {m.r_corner:.4g} (Hugin units)"
    )
    if m.r_normalized < 1:
        return _entry_finding(
            SEVERITY_ERROR,
            FOLD_IN_IMAGE,
            entry,
            f"the model folds back inside its own image: {where}; "
            f"undistortion mirrors pixels beyond that radius; {_fix_suggestion(entry)}",
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


def _fix_suggestion(entry: loader.DistortionEntry) -> str:
    """The ``lensaudit fix`` command that refits this entry, on the same database.

    The lens name goes in double quotes (single-quoted text is what messages
    shorten), with the characters a POSIX shell expands there escaped.
    """
    lens = re.sub(r'([\\"$`])', r"\\\1", entry.lens)
    return f'`lensaudit fix --lens "{lens}" --focal {entry.focal:g}` refits it'


def _calibration_findings(read: Sequence[_File], verbose: bool) -> Iterable[tuple[int, Identified]]:
    """Findings of the vignetting and TCA audits in the files that parsed.

    Their identity is content, as for distortion entries: the kind, the
    entry's own values, then its lens by name.
    """
    from . import tca, vignetting

    shown = {SEVERITY_ERROR, SEVERITY_WARNING} | ({SEVERITY_NOTICE} if verbose else set())
    for kind, module in ((calibrations.VIGNETTING, vignetting), (calibrations.TCA, tca)):
        owners = [
            index
            for index, file in enumerate(read)
            if file.problem is None
            for _ in file.calibrations.get(kind, ())
        ]
        entries = [
            entry
            for file in read
            if file.problem is None
            for entry in file.calibrations.get(kind, ())
        ]
        if not entries:
            continue
        with np.errstate(all="ignore"):
            audit = module.audit_entries(entries)
        severities = audit.metrics["severity"].tolist()
        for position, entry in enumerate(entries):
            if entry.status == loader.STATUS_OK:
                if severities[position] not in shown:
                    continue
            elif entry.status not in calibrations.STATUS_CODES:
                continue
            record = _calibration_record(audit, position)
            for severity, code, _, _, message in module.findings([record]):
                finding = Finding(
                    severity,
                    code,
                    entry.file,
                    entry.line,
                    0,
                    _clip(message),
                    _clip_key(
                        (
                            entry.maker,
                            entry.lens,
                            _number(entry.crop_factor),
                            entry.model,
                            _number(entry.focal),
                        )
                    ),
                )
                content = (severity, code, kind, _calibration_content(entry))
                keys = ((*content, _lens_identity(entry.maker, entry.lens)), content)
                index = owners[position]
                yield index, Identified(finding, keys, (read[index].source.file_name,))


def _calibration_record(audit: calibrations.CalibrationAudit, position: int) -> dict:
    """One entry of a vignetting or TCA audit as the dict its ``records()`` gives."""
    entry = audit.entries[position]
    ok = entry.status == loader.STATUS_OK
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


_CALIBRATION_SKIPPED = frozenset({"file", "line", "maker", "lens"})


def _calibration_content(entry: object) -> tuple:
    """A vignetting or TCA record's own values, without its lens's name, file
    or line (NaN as None, line numbers left out of the message)."""
    from dataclasses import fields

    values = []
    for item in fields(entry):  # type: ignore[arg-type]
        if item.name in _CALIBRATION_SKIPPED:
            continue
        value = getattr(entry, item.name)
        if item.name == "message":
            value = _LINE_NUMBER.sub("line", value)
        elif isinstance(value, float):
            value = _number(value)
        values.append(value)
    return tuple(values)


def _duplicate_focals(read: Sequence[_File]) -> Iterable[tuple[int, Identified]]:
    """A second ``<distortion>`` for a focal length of the same calibration.

    A calibration is the entries of one ``<lens>`` with the same crop factor
    and aspect ratio (those a ``<calibration>`` element may override). The
    finding is an error, or a warning when the two entries are identical.
    """
    for index, file in enumerate(read):
        if file.problem is not None or file.lens_of_entry is None:
            continue
        first: dict[tuple, tuple[int, tuple]] = {}
        for entry, lens in zip(file.entries, file.lens_of_entry, strict=True):
            if lens is None or entry.focal != entry.focal:
                continue
            calibration = (
                lens,
                _number(entry.crop_factor),
                _number(entry.aspect_ratio),
                entry.focal,
            )
            content = _entry_content(entry)
            if calibration not in first:
                first[calibration] = (entry.line, content)
                continue
            first_line, first_content = first[calibration]
            if content == first_content:
                severity = SEVERITY_WARNING
                text = (
                    f"a second distortion entry for {entry.focal:g} mm in the same "
                    f"calibration, identical to the one at line {first_line}: one of "
                    f"them can go"
                )
            else:
                severity = SEVERITY_ERROR
                text = (
                    f"a second distortion entry for {entry.focal:g} mm in the same "
                    f"calibration (the first is at line {first_line}); liblensfun keeps "
                    f"only one of them"
                )
            finding = replace(
                _entry_finding(severity, DUPLICATE_FOCAL, entry, text),
                related=((file.source.display, first_line),),
            )
            # The pair, in either order (a reordering may swap which comes
            # first), of the lens by name; then the pair alone, when the lens
            # was renamed; then the lens and focal length, when one of the
            # pair or the lens's crop factor or aspect ratio was edited.
            pair = (severity, DUPLICATE_FOCAL, *sorted((content, first_content), key=repr))
            lens_name = _lens_identity(entry.maker, entry.lens)
            keys = ((*pair, lens_name), pair, (severity, DUPLICATE_FOCAL, lens_name, entry.focal))
            yield index, Identified(finding, keys, (file.source.file_name,))


def _normalized_name(text: str) -> str:
    return " ".join(text.split()).casefold()


def _duplicate_lenses(read: Sequence[_File]) -> Iterable[tuple[int, Identified]]:
    """A ``<lens>`` whose maker, model and crop factor an earlier one has, in any file.

    An error, or a warning when the two lenses are identical but for the
    case and spacing of their names.
    """
    first: dict[tuple, tuple[_File, _Lens]] = {}
    contents: dict[int, tuple] = {}  # lens content by id(lens), computed for duplicates only

    def content_of(lens: _Lens) -> tuple:
        if id(lens) not in contents:
            contents[id(lens)] = _element_content(lens.element, skip_names=True)
        return contents[id(lens)]

    for index, file in enumerate(read):
        if file.problem is not None:
            continue
        for lens in file.lenses:
            key = (_normalized_name(lens.maker), _normalized_name(lens.model), lens.crop_factor)
            earlier_file, earlier = first.setdefault(key, (file, lens))
            if earlier is lens:
                continue
            content = content_of(lens)
            where = f"{earlier_file.source.display}:{earlier.line}"
            crop = (
                f"crop factor {lens.crop_factor:g}"
                if isinstance(lens.crop_factor, float)
                else "no crop factor"
                if lens.crop_factor is None
                else f"crop factor {_clip(lens.crop_factor, 20)!r}"
            )
            name = _lens_name(lens.maker, lens.model)
            if content == content_of(earlier):
                severity = SEVERITY_WARNING
                text = f"lens {name} ({crop}) is defined identically at {where}: one can go"
            else:
                severity = SEVERITY_ERROR
                text = (
                    f"lens {name} ({crop}) is already defined at {where}; "
                    f"liblensfun keeps only one of them"
                )
            finding = Finding(
                severity,
                DUPLICATE_LENS,
                file.source.display,
                lens.line,
                0,
                _clip(text),
                _clip_key((lens.maker, lens.model, lens.crop_factor)),
                related=((earlier_file.source.display, earlier.line),),
            )
            # The name and the pair of lenses, in either order; then the pair
            # alone, when both were renamed; then the name alone, when one of
            # the pair was edited.
            pair = (
                severity,
                DUPLICATE_LENS,
                lens.crop_factor,
                *sorted((content, content_of(earlier)), key=repr),
            )
            keys = ((*pair, key), pair, (severity, DUPLICATE_LENS, key))
            names = (file.source.file_name, earlier_file.source.file_name)
            yield index, Identified(finding, keys, names)


# ---------------------------------------------------------------------------
# Comparing with the baseline


def _readable_baseline(
    read: list[_File],
) -> tuple[list[_File], list[Identified], list[tuple[str, str]], set[str]]:
    """The baseline's files with each one that cannot be parsed replaced by its
    last readable version from git.

    Also returns the file-level findings of the replaced files (the baseline
    had them, whatever the older version holds), the (name, commit) of each
    replacement, and the names of files left without a readable version.
    """
    read = list(read)
    kept: list[Identified] = []
    replaced: list[tuple[str, str]] = []
    incomparable: set[str] = set()
    for index, file in enumerate(read):
        if file.problem is None:
            continue
        older = _last_readable(file.source)
        if older is None:
            incomparable.add(file.source.file_name)
            continue
        kept.append(_file_identified(file))
        read[index] = _read(older[0])
        replaced.append((file.source.file_name, older[1]))
    return read, kept, replaced, incomparable


def _compare(
    current: list[Identified],
    before: list[Identified],
    read: Sequence[_File],
    incomparable: set[str],
) -> tuple[list[Finding], int]:
    """The current findings with those the baseline has marked known, and the
    number of the baseline's findings that are gone (resolved).

    Matching goes from the most specific key to the least: first every
    finding that has an unmatched baseline finding with its first key, then
    those left by their second key, and so on; each baseline finding matches
    once. Findings in a file whose baseline could not be read are known too,
    but for its own file-level finding.
    """
    used = [False] * len(before)
    known = [False] * len(current)
    tiers = max((len(item.keys) for item in (*current, *before)), default=0)
    for tier in range(tiers):
        pool: dict[Hashable, list[int]] = {}
        for position, item in enumerate(before):
            if not used[position] and tier < len(item.keys):
                pool.setdefault(item.keys[tier], []).append(position)
        for position, item in enumerate(current):
            if known[position] or tier >= len(item.keys):
                continue
            candidates = pool.get(item.keys[tier])
            if candidates:
                used[candidates.pop(0)] = True
                known[position] = True
    for position, item in enumerate(current):
        if item.finding.code not in FILE_CODES and incomparable.intersection(item.names):
            known[position] = True
    findings = [
        replace(item.finding, known=True) if is_known else item.finding
        for item, is_known in zip(current, known, strict=True)
    ]
    # Entries of a file that no longer parses are not checked: their findings
    # are not gone, only unseen.
    unseen = {f.source.file_name for f in read if f.problem is not None}
    resolved = sum(
        not used[position] and not unseen.intersection(item.names)
        for position, item in enumerate(before)
    )
    return findings, resolved


def _baseline_notices(
    read: Sequence[_File], label: str, replaced: list[tuple[str, str]], incomparable: set[str]
) -> list[Finding]:
    """A notice for each readable file whose baseline version could not be parsed."""
    readable = {f.source.file_name: f.source.display for f in read if f.problem is None}
    notices = []
    for name, commit in replaced:
        if name in readable:
            text = (
                f"the baseline's version ({label}) could not be parsed; compared with the "
                f"last version that can, of commit {commit[:12]}"
            )
            notices.append(
                Finding(SEVERITY_NOTICE, BASELINE_UNREADABLE, readable[name], 0, 0, text)
            )
    for name in sorted(incomparable):
        if name in readable:
            text = (
                f"the baseline's version ({label}) could not be parsed, and no earlier "
                f"version that can was found: the findings in this file are not counted as new"
            )
            notices.append(
                Finding(SEVERITY_NOTICE, BASELINE_UNREADABLE, readable[name], 0, 0, text)
            )
    return [replace(n, message=_clip(n.message)) for n in notices]
