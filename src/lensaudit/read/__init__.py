"""The reader: every command reads a Lensfun database through this package, once.

:func:`read` resolves the paths (the default database without them), reads
each file's bytes, parses each file once with the one safe parser
(:mod:`~lensaudit.read.xml`) and returns plain tables
(:class:`~lensaudit.read.records.FileTables`): the file's status, its lenses,
and its distortion, vignetting and TCA rows with their lines and lens
context (:mod:`~lensaudit.read.tables`). With a cache
(:class:`~lensaudit.read.cache.Cache`), a file whose bytes were read before
is not parsed again. :func:`read_bytes` reads one file's content from
anywhere (a git revision, a test).

Gyroflow's lens profiles (JSON) are read by :func:`read_gyroflow` (which
imports :mod:`~lensaudit.read.gyroflow` when called) into
:class:`~lensaudit.read.gyroflow.Profile` records; :func:`database_format`
tells which of the two a path is.

Nothing else in lensaudit touches XML.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from functools import partial
from pathlib import Path

from . import parallel, paths, xml
from .cache import Cache, content_digest
from .paths import (
    GYROFLOW,
    LENSFUN,
    DatabaseSource,
    Paths,
    database_format,
    display_path,
    expand,
    resolve,
)
from .records import (
    NOT_JUDGED,
    STATUS_OK,
    STATUS_UNREADABLE,
    DistortionEntry,
    FileTables,
    LoadError,
    SourceFile,
)
from .tables import KINDS, READ, SPECS, TCA, VIGNETTING, FileReader, distortion_of, error_row
from .xml import Pieces

__all__ = [
    "GYROFLOW",
    "KINDS",
    "LENSFUN",
    "TCA",
    "VIGNETTING",
    "Cache",
    "Database",
    "DatabaseSource",
    "DistortionEntry",
    "FileTables",
    "LoadError",
    "Pieces",
    "SourceFile",
    "database_format",
    "display_path",
    "read",
    "read_bytes",
    "read_contents",
    "read_pieces",
    "read_files",
    "read_gyroflow",
    "resolve",
]


class Database:
    """What :func:`read` found: the database ``source`` and its ``files``
    (:class:`FileTables`, in order)."""

    __slots__ = ("source", "files")

    def __init__(self, source: DatabaseSource, files: list[FileTables]) -> None:
        self.source = source
        self.files = files

    def entries(self) -> list[DistortionEntry]:
        """Every distortion row, as :class:`DistortionEntry` records, in order."""
        return [entry for file in self.files for entry in file.entries()]

    def source_files(self) -> list[SourceFile]:
        """The files as :class:`SourceFile` records."""
        return [file.source_file() for file in self.files]

    def rows(self, kind: str) -> tuple[list[str], list[tuple]]:
        """(file name of each row, rows) of ``vignetting`` or ``tca``, in order;
        the database must have been read with its calibrations."""
        names: list[str] = []
        rows: list[tuple] = []
        for file in self.files:
            found = file.vignetting if kind == VIGNETTING else file.tca
            assert found is not None, "read with calibrations=True"
            names += [file.name] * len(found)
            rows += found
        return names, rows


def read(
    paths_given: Paths = None,
    *,
    cache: Cache | None = None,
    calibrations: bool = False,
    refusals: bool = False,
) -> Database:
    """Read a Lensfun database: directories and/or XML files, where a Lensfun
    checkout means its ``data/db``; without paths, the checkout around the
    working directory, else the database bundled with lensfunpy.

    With ``calibrations``, vignetting and TCA rows are read too. Raises
    :class:`LoadError` when the paths cannot be read at all; problems inside
    files are statuses in their tables instead.
    """
    source = resolve(paths_given)
    return Database(source, read_files(expand(source.paths), cache, calibrations, refusals))


def read_gyroflow(paths_given: Paths) -> list:
    """Every Gyroflow lens profile of directories and files, in name order, as
    :class:`~lensaudit.read.gyroflow.Profile` records (see
    :func:`~lensaudit.read.paths.gyroflow_files` for which files): one per
    file, whatever its content; a file that cannot be read is one of status
    ``unreadable``. Raises :class:`LoadError` when the paths cannot be read
    at all or are not Gyroflow lens profiles."""
    from . import gyroflow  # json: a Lensfun database never needs it

    found = []
    for path, name in paths.gyroflow_files(paths_given):
        try:
            data = paths.read_file(path, gyroflow.MAX_PROFILE_BYTES)
        except OSError as error:
            found.append(
                gyroflow.refused(
                    name, STATUS_UNREADABLE, 0, f"cannot read file: {paths.reason(error)}"
                )
            )
            continue
        found.append(gyroflow.read_profile(data, name))
    return found


def read_files(
    targets: Iterable[tuple[Path, str]],
    cache: Cache | None = None,
    calibrations: bool = False,
    refusals: bool = False,
) -> list[FileTables]:
    """The tables of (path, display name) pairs, as :func:`expand` gives them;
    a file that cannot be read is a table of status ``unreadable``."""
    found: list[FileTables | tuple[bytes, str, Path]] = []
    for path, name in targets:
        try:
            found.append((paths.read_file(path), name, path))
        except OSError as error:
            found.append(unreadable(name, path, f"cannot read file: {paths.reason(error)}"))
    contents = [item for item in found if isinstance(item, tuple)]
    made = iter(read_contents(contents, cache, calibrations, refusals))
    return [item if isinstance(item, FileTables) else next(made) for item in found]


def read_contents(
    contents: Sequence[tuple[bytes, str, Path | None]],
    cache: Cache | None = None,
    calibrations: bool = False,
    refusals: bool = False,
    meanwhile: Callable[[], object] | None = None,
) -> list[FileTables]:
    """The tables of files' contents, given as (bytes, display name, path or
    None). Contents the cache does not know are parsed on every core
    (:func:`~lensaudit.read.parallel.map_sized`, which does ``meanwhile``
    here while the other processes start reading); with a cache, what is
    read is kept there and the cache saved."""
    found = _tables(contents, cache, calibrations, refusals, meanwhile=meanwhile)
    if cache is not None:
        cache.save()
    return found


def read_bytes(
    data: bytes,
    name: str,
    path: Path | None = None,
    *,
    cache: Cache | None = None,
    calibrations: bool = False,
    refusals: bool = False,
    pieces: Pieces | None = None,
) -> FileTables:
    """The tables of one file's content; ``name`` is how it is shown, ``path``
    where it is (None for a file read from git or memory). With ``cache``,
    what it holds for the same bytes is used, and what is read is kept (the
    caller saves the cache). With ``pieces``, lenses met before in other
    contents are not parsed again (see :class:`~lensaudit.read.xml.Pieces`)."""
    return _tables([(data, name, path)], cache, calibrations, refusals, pieces)[0]


def read_pieces(data: bytes, pieces: Pieces) -> list[list[tuple]] | None:
    """The distortion rows of each top-level piece of one file's content (see
    :class:`~lensaudit.read.xml.Pieces`), in order, where :func:`read_bytes`
    with ``pieces`` reads the content as nothing but those pieces, with no
    problem: its :attr:`FileTables.distortion` is then those rows one after
    the other, each with its line counted from its piece's first (rows hold
    their line first). None where it reads the content otherwise.

    For reading many versions of the same files (``lensaudit history``),
    where what is made of a piece's rows can be kept by piece: each piece met
    again gives the same list object."""
    placed = xml.read_pieces(data, partial(FileReader, False, False), pieces)
    return None if placed is None else list(map(distortion_of, placed))


def _tables(
    contents: Sequence[tuple[bytes, str, Path | None]],
    cache: Cache | None,
    calibrations: bool,
    refusals: bool = False,
    pieces: Pieces | None = None,
    meanwhile: Callable[[], object] | None = None,
) -> list[FileTables]:
    """The tables of contents: from the cache where it has them (each content's
    digest is taken only for it), else parsed and kept there."""
    found: list[FileTables | None] = []
    todo: list[tuple[bytes, str, Path | None, bytes]] = []
    for data, name, path in contents:
        digest = content_digest(data) if cache is not None else b""
        tables = _cached(digest, name, path, cache, calibrations, refusals)
        if tables is None:
            todo.append((data, name, path, digest))
        found.append(tables)
    if todo:
        parse = partial(_parsed_values, calibrations=calibrations, refusals=refusals, pieces=pieces)
        sizes = [len(data) for data, *_ in todo]
        values = parallel.map_sized(parse, [data for data, *_ in todo], sizes, meanwhile)
        made = iter(_made(todo, values, cache, calibrations))
        found = [tables if tables is not None else next(made) for tables in found]
    return found  # type: ignore[return-value]


def _cached(
    digest: bytes,
    name: str,
    path: Path | None,
    cache: Cache | None,
    calibrations: bool,
    refusals: bool = False,
) -> FileTables | None:
    """The tables the cache holds for the content of ``digest``, or None (also
    where ``refusals`` are asked for and the tables kept were read without)."""
    if cache is None:
        return None
    stored = cache.get(digest, "tables")
    stored_calibrations = cache.get(digest, "calibrations") if calibrations else None
    if stored is None or (calibrations and stored_calibrations is None):
        return None
    try:
        tables = FileTables(name, path, digest, stored)  # type: ignore[arg-type]
        if refusals and not tables.refusal_judged:
            return None  # read again, judged; kept so for the next run
        if calibrations:
            tables.set_calibrations(stored_calibrations)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return None  # not what this code stores: parsed again
    return tables


def _made(
    todo: list[tuple[bytes, str, Path | None, bytes]],
    values: list[tuple],
    cache: Cache | None,
    calibrations: bool,
) -> list[FileTables]:
    """Tables of contents parsed (``values``, as :func:`_parsed_values` gives
    them), kept in the cache."""
    made = []
    for (_, name, path, digest), (stored, calibration_rows) in zip(todo, values, strict=True):
        tables = FileTables(name, path, digest, stored)
        if calibrations:
            tables.set_calibrations(calibration_rows)
        if cache is not None:
            cache.put(digest, "tables", stored)
            if calibrations:
                cache.put(digest, "calibrations", calibration_rows)
        made.append(tables)
    return made


def _parsed_values(
    data: bytes, calibrations: bool, refusals: bool = False, pieces: Pieces | None = None
) -> tuple:
    """Parse one file's content: (its :attr:`FileTables.STORED` values, its
    calibrations (see :meth:`FileTables.set_calibrations`) or None), as plain
    data; with ``refusals``, where liblensfun stops reading it judged."""
    parsed, found = xml.parse(data, partial(FileReader, calibrations, refusals), READ, pieces)
    distortion, lens_of_row, omitted = found.distortion, found.lens_of_row, found.omitted
    vignetting, tca = found.vignetting, found.tca
    lens_of_vignetting, lens_of_tca = found.lens_of_vignetting, found.lens_of_tca
    if parsed.status != STATUS_OK:
        status, line, error, message = (
            parsed.status,
            parsed.line,
            parsed.error,
            parsed.entry_message,
        )
        distortion = [error_row(line, status, error), *_marked(distortion, status, message)]
        lens_of_row = [None, *lens_of_row]
        omitted = [(), *omitted]
        if vignetting is not None and tca is not None:
            vignetting = [SPECS[VIGNETTING].error_row(line, status, error),
                          *_marked(vignetting, status, message)]  # fmt: skip
            tca = [SPECS[TCA].error_row(line, status, error), *_marked(tca, status, message)]
            lens_of_vignetting = [None, *lens_of_vignetting]  # type: ignore[misc]
            lens_of_tca = [None, *lens_of_tca]  # type: ignore[misc]
    stored = (parsed.status, parsed.line, parsed.column, parsed.error, parsed.problem,
              found.lenses, distortion, lens_of_row, omitted, found.cameras,
              found.mount_names,
              _refusal(data, parsed, found) if refusals else NOT_JUDGED,
              xml.encoding_disagreement(data))  # fmt: skip
    if not calibrations:
        return stored, None
    return stored, (vignetting, tca, lens_of_vignetting, lens_of_tca)


def _refusal(data: bytes, parsed: xml.Parsed, found: FileReader) -> tuple[int, str, int] | None:
    """Where liblensfun stops reading a file, why, and how many lenses it holds
    then (see :attr:`FileTables.refusal`)."""
    from . import liblensfun  # only what is judged needs its rules

    # libxml2 has read a well-formed document as UTF-8 unless it was decoded first.
    utf8_checked = parsed.status == STATUS_OK and xml.decoded(data) is data
    leading = liblensfun.leading_refusal(data, utf8_checked)
    refusal = found.first_refusal()
    if leading is not None and (refusal is None or leading[0] <= refusal[0]):
        refusal = leading
    if parsed.status == xml.STATUS_XML_ERROR and (refusal is None or refusal[0] >= parsed.line):
        # What comes first is the markup itself (GMarkup refuses it too).
        # The lenses ended before the error's position, which liblensfun holds.
        offset = 0
        for _ in range(parsed.line - 1):
            offset = data.find(b"\n", offset) + 1
        kept = data.count(b"</lens>", 0, offset + max(parsed.column - 1, 0)) if offset >= 0 else 0
        return parsed.line, f"{liblensfun.NOT_WELL_FORMED}: {parsed.problem}", kept
    return refusal


def _marked(rows: list[tuple], status: str, message: str) -> list[tuple]:
    """Rows given a file-level status; for a file that is not well-formed, each
    row's own problems kept in front of ``message``."""
    if status == xml.STATUS_XML_ERROR:
        return [(*r[:-2], status, f"{r[-1]}; {message}" if r[-1] else message) for r in rows]
    return [(*r[:-2], status, message) for r in rows]


def unreadable(name: str, path: Path | None, message: str) -> FileTables:
    """The tables of a file that could not be read: one row that says why."""
    values = (STATUS_UNREADABLE, 0, 0, message, message, [],
              [error_row(0, STATUS_UNREADABLE, message)], [None], [()], [], [],
              None, None)  # fmt: skip
    tables = FileTables(name, path, b"", values)
    tables.set_calibrations(
        (
            [SPECS[VIGNETTING].error_row(0, STATUS_UNREADABLE, message)],
            [SPECS[TCA].error_row(0, STATUS_UNREADABLE, message)],
            [None],
            [None],
        )
    )
    return tables
