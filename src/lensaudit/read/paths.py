"""Which files a database is: the default database, directories, display names, bytes.

Without paths, a command reads the database of the Lensfun checkout the
working directory is in, else the copy of the Lensfun database that ships
with lensfunpy (``lensfunpy/db_files``), located without importing
lensfunpy, so that finding it does not load liblensfun.
"""

from __future__ import annotations

import os
import re
import stat
import sys
from collections import namedtuple
from collections.abc import Iterable, Sequence
from importlib.util import find_spec
from pathlib import Path

from .records import LoadError

#: Larger files are not read: Lensfun's largest database file is about 2 MB.
MAX_FILE_BYTES = 256 << 20
#: Where a Lensfun checkout keeps its database, relative to the checkout.
CHECKOUT_DATABASE = Path("data", "db")

Paths = Sequence[str | bytes | os.PathLike[str]] | str | bytes | os.PathLike[str] | None


class DatabaseSource(
    namedtuple("DatabaseSource", ("paths", "label", "bundled"), defaults=(False,))
):
    """What was read: the ``paths`` (a tuple), a human-readable ``label``, and
    whether it is the database ``bundled`` with lensfunpy."""

    __slots__ = ()


def display_path(path: str | os.PathLike[str]) -> str:
    """A path as printed: bytes that are not valid in the file system's
    encoding (a file name that is not UTF-8) as backslash escapes."""
    return os.fsencode(path).decode(sys.getfilesystemencoding(), "backslashreplace")


def bundled_database_path() -> Path:
    """Directory of the Lensfun database installed with lensfunpy."""
    spec = find_spec("lensfunpy")
    if spec is None or not spec.submodule_search_locations:
        raise LoadError(
            "lensfunpy is not installed: give a database path, "
            "or install it with `pip install lensfunpy`"
        )
    path = Path(next(iter(spec.submodule_search_locations))) / "db_files"
    if not path.is_dir():
        raise LoadError(f"lensfunpy is installed but has no database at {path}")
    return path


def in_bundled_database(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` (by any name) is the database bundled with lensfunpy, or in it."""
    try:
        bundled = Path(os.path.realpath(bundled_database_path()))
    except LoadError:
        return False
    return Path(os.path.realpath(path)).is_relative_to(bundled)


def lensfunpy_version() -> str:
    """Installed lensfunpy version, or "" when it is not installed.

    Read from lensfunpy's ``_version.py`` when it has one: importing
    importlib.metadata costs more than the rest of finding the database.
    """
    spec = find_spec("lensfunpy")
    if spec is None or not spec.submodule_search_locations:
        return ""
    version_file = Path(next(iter(spec.submodule_search_locations))) / "_version.py"
    try:
        match = re.search(r"""__version__\s*=\s*["']([^"']+)["']""", version_file.read_text())
    except OSError:
        match = None
    if match:
        return match.group(1)
    # importlib.metadata: slow to import, only for provenance
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("lensfunpy")
    except PackageNotFoundError:
        return ""


def resolve(paths: Paths) -> DatabaseSource:
    """The database to read.

    ``paths`` if given, where a Lensfun checkout (or its ``data`` directory)
    stands for its ``data/db``; with None, the database of the Lensfun
    checkout the working directory is in, else lensfunpy's bundled one.
    A path may be ``str``, ``bytes`` or ``os.PathLike``. Raises
    :class:`LoadError` for an empty sequence of paths (reading the default
    database instead would hide a filter that left nothing) and for a path
    holding a NUL character or empty (or blank: ``Path("")`` would be the
    working directory); ``TypeError`` for what is not a path.
    """
    if isinstance(paths, (str, bytes, os.PathLike)):
        paths = [paths]
    if paths is not None:
        try:
            given = _unique(_path(p) for p in paths)
        except TypeError as error:
            raise TypeError(f"paths must be a path or a sequence of paths: {error}") from None
        if not given:
            raise LoadError("no path given (None reads the default database)")
        resolved = tuple(database_directory(p) for p in given)
        return DatabaseSource(resolved, ", ".join(map(_describe, given, resolved)))
    here = enclosing_database()
    if here is not None:
        label = _describe(here, here, "the Lensfun checkout around the working directory")
        return DatabaseSource((here,), label)
    path = bundled_database_path()
    return DatabaseSource(
        (path,),
        f"Lensfun database bundled with lensfunpy {lensfunpy_version()} ({path})",
        bundled=True,
    )


def _path(given: str | bytes | os.PathLike) -> Path:
    """One path given, as a Path (bytes decoded as the file system does)."""
    text = os.fsdecode(given)
    if not text.strip():
        # Path("") is the working directory: an unset variable would read whatever is there.
        raise LoadError(f"{text!r}: an empty or blank path names no database (give a path)")
    path = Path(text)
    if "\0" in text:
        raise LoadError(f"{display_path(path)}: a path cannot hold a NUL character")
    return path


def _unique(paths: Iterable[Path]) -> tuple[Path, ...]:
    """Paths without repeats: a database named twice is read once."""
    seen: dict[str, Path] = {}
    for path in paths:
        seen.setdefault(os.path.realpath(path), path)
    return tuple(seen.values())


def is_database_directory(path: Path) -> bool:
    """Whether ``path`` is a directory holding Lensfun database files: one of
    the first few files liblensfun reads there (:func:`database_entries`)
    names ``<lensdatabase`` in its first kilobyte."""
    try:
        candidates = [name for name, _ in database_entries(path)[:3]]
    except OSError:
        return False
    for name in candidates:
        try:
            with open(read_descriptor(path / name), "rb") as stream:
                if b"<lensdatabase" in stream.read(1024):
                    return True
        except OSError:
            continue
    return False


def database_directory(path: Path) -> Path:
    """The database a path designates: ``data/db`` of a Lensfun checkout (or of
    its ``data`` directory), else ``path`` itself."""
    for candidate in (path / CHECKOUT_DATABASE, path / CHECKOUT_DATABASE.name):
        if is_database_directory(candidate):
            return candidate
    return path


def enclosing_database(start: Path | None = None) -> Path | None:
    """``data/db`` of the Lensfun checkout that ``start`` (the working directory)
    is in, looking at it and its parents; None outside a Lensfun checkout."""
    try:
        start = (start or Path.cwd()).resolve()
    except OSError:  # the working directory was removed
        return None
    for directory in (start, *start.parents):
        if directory.parts[-2:] == CHECKOUT_DATABASE.parts and is_database_directory(directory):
            return directory
        if is_database_directory(directory / CHECKOUT_DATABASE):
            return directory / CHECKOUT_DATABASE
    return None


def git_commit(directory: Path) -> str:
    """Short id of the commit checked out in the git repository holding
    ``directory``, with ``+changes`` when the directory differs from it; ""
    outside a git repository or without git."""
    import subprocess  # subprocess: only to ask git, which a scan does not

    environment = {**os.environ, "GIT_OPTIONAL_LOCKS": "0", "LC_ALL": "C"}
    try:
        commit = subprocess.run(
            ["git", "-C", os.fspath(directory), "rev-parse", "--short=10", "HEAD"],
            capture_output=True, env=environment, timeout=10, check=True,
        ).stdout.decode("ascii").strip()  # fmt: skip
        changed = subprocess.run(
            ["git", "-C", os.fspath(directory), "status", "--porcelain", "--", "."],
            capture_output=True, env=environment, timeout=30, check=True,
        ).stdout.strip()  # fmt: skip
    except (OSError, subprocess.SubprocessError, UnicodeDecodeError):
        return ""
    return commit + ("+changes" if changed else "")


def _describe(given: Path, directory: Path, origin: str = "") -> str:
    """How a database is named in output: the path, and where it comes from."""
    if directory != given:
        origin = f"Lensfun checkout: {display_path(directory)}"
    text = display_path(given) + (f" ({origin})" if origin else "")
    if directory.parts[-2:] == CHECKOUT_DATABASE.parts and directory.is_dir():
        commit = git_commit(directory)
        if commit:
            text += f" at git commit {commit}"
    return text


def timestamp(directory: Path) -> str:
    """Content of Lensfun's ``timestamp.txt`` in a database directory, or ""."""
    try:
        return (directory / "timestamp.txt").read_text(encoding="ascii").strip()
    except (OSError, UnicodeDecodeError):
        return ""


def reason(error: OSError) -> str:
    """An OS error in words."""
    return error.strerror or str(error)


def loaded_name(name: str) -> bool:
    """Whether liblensfun reads an entry of a database directory so named.

    lfDatabase::Load matches each name in a directory against GLib's pattern
    ``*.xml``: case-sensitive (``A.XML`` is not read), hidden names included
    (``.a.xml``, even ``.xml``), and a directory so named is read as a
    database directory in turn.
    """
    return name.endswith(".xml")


def _loaded_children(directory: Path) -> list[tuple[str, bool, bool]]:
    """(name, whether a directory, whether a link) of the entries of one
    directory that liblensfun reads (:func:`loaded_name`), sorted by name; a
    link counts as what it leads to, as GLib's test for a directory does."""
    found = []
    with os.scandir(directory) as entries:
        for item in entries:
            if not loaded_name(item.name):
                continue
            try:
                is_directory = item.is_dir()
            except OSError:  # a link loop: is_dir() gives up, stat() would raise
                is_directory = False
            found.append((item.name, is_directory, item.is_symlink()))
    return sorted(found)


def database_entries(directory: str | os.PathLike[str]) -> list[tuple[str, bool]]:
    """(name relative to ``directory``, whether a link leads to it) of every
    file liblensfun reads from a database directory, in name order.

    As lfDatabase::Load, each entry named ``*.xml`` (:func:`loaded_name`) that
    is not a directory, and the files of each directory so named, read the
    same way (``sub.xml/a.xml``, links followed). Anything so named but a
    directory is listed, and so is a subdirectory that cannot be listed, so
    that a FIFO, a device, a dangling link or a link loop is reported as
    unreadable rather than silently skipped. A link back to a directory being
    listed is not followed: liblensfun reads the same files again there, until
    the path is too long. Raises ``OSError`` when ``directory`` itself cannot
    be listed.
    """
    found: list[tuple[str, bool]] = []
    root = Path(directory)
    # (relative name, path to list or None for a file, reached through a link, real paths above)
    stack: list[tuple[str, Path | None, bool, frozenset[str]]] = [
        ("", root, False, frozenset({os.path.realpath(root)}))
    ]
    while stack:
        name, path, link, above = stack.pop()
        if path is None:
            found.append((name, link))
            continue
        try:
            children = _loaded_children(path)
        except OSError:
            if path is root:
                raise
            found.append((name, link))  # reading it says why it cannot be listed
            continue
        for child, is_directory, is_link in reversed(children):
            relative = f"{name}/{child}" if name else child
            if not is_directory:
                stack.append((relative, None, link or is_link, above))
                continue
            real = os.path.realpath(path / child)
            if real not in above:
                stack.append((relative, path / child, link or is_link, above | {real}))
    return found


def expand(paths: Paths) -> list[tuple[Path, str]]:
    """(path, display name) of every XML file the paths designate: the files
    liblensfun reads from each directory (:func:`database_entries`), and the
    files given directly, whatever their names.

    Directory entries are named relative to the directory given; files given
    directly keep the path as given. Paths are resolved where they can be: a
    link that leads nowhere keeps its own path, to be reported when it is
    read. Raises :class:`LoadError` when a path does not exist, is empty or
    a directory holds no XML, and for Gyroflow lens profiles
    (:func:`database_format`), which :func:`gyroflow_files` lists instead.
    """
    if isinstance(paths, (str, bytes, os.PathLike)):
        paths = [paths]
    if paths and database_format(paths) == GYROFLOW:
        raise LoadError(_not_lensfun(paths))
    targets: list[tuple[Path, str]] = []
    seen: set[str] = set()
    for given in map(_path, paths or ()):
        for real, name in _files_of(given):
            # The same file named twice (db and db/x.xml, or a link) is read once.
            if real not in seen:
                seen.add(real)
                targets.append((Path(real), name))
    return targets


def _files_of(given: Path) -> list[tuple[str, str]]:
    """(real path, display name) of the files one given path designates."""
    shown = display_path(given)
    try:
        mode = os.stat(given).st_mode
    except FileNotFoundError:
        raise LoadError(f"{shown}: no such file or directory") from None
    except OSError as error:
        raise LoadError(f"{shown}: {reason(error)}") from None
    if stat.S_ISREG(mode):
        return [(os.path.realpath(given), shown)]
    if not stat.S_ISDIR(mode):
        raise LoadError(f"{shown}: not a regular file or directory")
    try:
        entries = database_entries(given)
    except OSError as error:
        raise LoadError(f"{shown}: cannot list directory: {reason(error)}") from None
    if not entries:
        raise LoadError(f"{shown}: directory holds no *.xml files {_no_files_hint(given)}")
    # The directory resolved once: a file in it that is not a link resolves to
    # the directory's real path and its own name.
    base = os.path.realpath(given)
    return [
        (_real(given / name) if link else os.path.join(base, name), display_path(name))
        for name, link in entries
    ]


def _no_files_hint(directory: Path) -> str:
    """What to give instead of a directory without files liblensfun reads,
    naming a file whose suffix is ``.xml`` in another case (``A.XML``)."""
    try:
        other = sorted(name for name in os.listdir(directory) if name.lower().endswith(".xml"))
    except OSError:
        other = []
    if other and not loaded_name(other[0]):
        return f"(liblensfun reads names ending in lower-case .xml, not {display_path(other[0])})"
    return "(give a Lensfun database directory, a Lensfun checkout, or XML files)"


def _real(path: Path) -> str:
    """The real path of a link, or, for a link loop or one leading nowhere,
    its own absolute path (reading it then says what is wrong)."""
    try:
        return os.path.realpath(path, strict=True)
    except (OSError, RuntimeError):
        return os.path.abspath(path)


# ---------------------------------------------------------------------------
# Which format a path is: Lensfun's XML or Gyroflow's JSON lens profiles
# ---------------------------------------------------------------------------

#: A Lensfun database (XML): what every command reads.
LENSFUN = "lensfun"
#: Gyroflow lens profiles (JSON, :mod:`lensaudit.read.gyroflow`).
GYROFLOW = "gyroflow"
#: How many of a directory's JSON files are looked at, in name order, for a
#: profile before it is said to hold none.
PROFILES_LOOKED_AT = 16


def database_format(paths: Paths) -> str:
    """:data:`LENSFUN` or :data:`GYROFLOW`: which database the paths are.

    A directory is a Lensfun database where liblensfun reads files there (or
    it is a Lensfun checkout), as every command has it; else Gyroflow lens
    profiles where one of its JSON files (:func:`gyroflow_entries`) is a
    profile by content. A file given is Gyroflow's where it is a profile by
    content or named ``*.json`` and not XML, else Lensfun's (read as XML,
    whatever its name, as before). None is the default Lensfun database.
    Raises :class:`LoadError` for a directory that is neither and for both
    formats given together; a path that does not exist counts as Lensfun's
    (reading it says so).
    """
    if paths is None:
        return LENSFUN
    if isinstance(paths, (str, bytes, os.PathLike)):
        paths = [paths]
    found: dict[str, Path] = {}
    for given in map(_path, paths):
        found.setdefault(format_of(given)[0], given)
    if not found:
        raise LoadError("no path given (None reads the default database)")
    if len(found) > 1:
        raise LoadError(
            f"{display_path(found[LENSFUN])} is a Lensfun database and "
            f"{display_path(found[GYROFLOW])} Gyroflow lens profiles: "
            "give one kind of database at a time"
        )
    return next(iter(found))


def format_of(given: Path) -> tuple[str, list[tuple[str, bool]]]:
    """(format, JSON entries) of one path: the format as :func:`database_format`
    says it, and for a directory of Gyroflow lens profiles its
    :func:`gyroflow_entries` (else []). Raises :class:`LoadError` for a
    directory that holds neither Lensfun's files nor a Gyroflow profile."""
    try:
        mode = os.stat(given).st_mode
    except (OSError, ValueError):
        return LENSFUN, []  # reading it says what is wrong
    if not stat.S_ISDIR(mode):
        return (_file_format(given) if stat.S_ISREG(mode) else LENSFUN), []
    try:
        if database_entries(given) or is_database_directory(given / CHECKOUT_DATABASE):
            return LENSFUN, []
        entries = gyroflow_entries(given)
    except OSError:
        return LENSFUN, []  # listing it says what is wrong
    if _profile_among(given, entries):
        return GYROFLOW, entries
    hint = _no_files_hint(given)
    if entries:
        hint = (
            "(and its *.json files are not Gyroflow lens profiles: give a Lensfun database "
            "directory, a Lensfun checkout, XML files or Gyroflow lens profiles)"
        )
    raise LoadError(f"{display_path(given)}: directory holds no *.xml files {hint}")


def _file_format(path: Path) -> str:
    """The format of a file given directly: Gyroflow's where it is a profile
    by content, or named ``*.json`` and not XML; Lensfun's otherwise."""
    from .gyroflow import MAX_PROFILE_BYTES, is_profile

    try:
        with open(read_descriptor(path), "rb") as stream:
            head = stream.read(MAX_PROFILE_BYTES + 1)
    except OSError:
        return LENSFUN  # reading it says why it cannot be read
    if head.lstrip(b"\xef\xbb\xbf \t\r\n")[:1] == b"<":
        return LENSFUN
    if path.name.lower().endswith(".json") or is_profile(head):
        return GYROFLOW
    return LENSFUN


def _profile_among(directory: Path, entries: list[tuple[str, bool]]) -> bool:
    """Whether one of the first JSON files of a directory is a Gyroflow lens profile."""
    from .gyroflow import MAX_PROFILE_BYTES, is_profile

    for name, _ in entries[:PROFILES_LOOKED_AT]:
        try:
            if is_profile(read_file(directory / name, MAX_PROFILE_BYTES)):
                return True
        except OSError:
            continue
    return False


def _not_lensfun(paths: Sequence[str | bytes | os.PathLike[str]]) -> str:
    """Why Gyroflow lens profiles are refused where a Lensfun database is read,
    saying how many profile files there are."""
    shown = ", ".join(display_path(_path(given)) for given in paths)
    files = len(gyroflow_files(paths))
    return (
        f"{shown}: Gyroflow lens profiles ({files} file{'s' if files != 1 else ''}); "
        "lensaudit's commands read Lensfun databases "
        "(lensaudit.read.read_gyroflow reads Gyroflow profiles)"
    )


def gyroflow_name(name: str) -> bool:
    """Whether a file so named in a directory of Gyroflow lens profiles is read:
    ``*.json`` in any case (Gyroflow's repository names every profile so).
    Hidden names (``.github``, ``.git``) are never read: they are the
    repository's, not profiles."""
    return name.lower().endswith(".json") and not name.startswith(".")


def gyroflow_entries(directory: str | os.PathLike[str]) -> list[tuple[str, bool]]:
    """(name relative to ``directory``, whether a link leads to it) of every
    file read from a directory of Gyroflow lens profiles, in name order: each
    :func:`gyroflow_name` in it and in its subdirectories at any depth (the
    repository keeps profiles by brand, phones by maker under ``Mobile
    phones``), links followed, but not back to a directory being listed.
    Anything so named but a directory is listed, and so is a subdirectory
    that cannot be listed, so that reading it says why. Raises ``OSError``
    when ``directory`` itself cannot be listed."""
    root = os.fspath(directory)
    found: list[tuple[str, bool]] = []
    stack: list[tuple[str, str, bool, frozenset[str]]] = [
        ("", root, False, frozenset({os.path.realpath(root)}))
    ]
    while stack:
        name, path, link, above = stack.pop()
        prefix = f"{name}/" if name else ""
        try:
            with os.scandir(path) as listing:
                children = [item for item in listing if not item.name.startswith(".")]
        except OSError:
            if path is root:
                raise
            found.append((name, link))
            continue
        for item in children:
            try:
                is_directory = item.is_dir()
            except OSError:  # a link loop: is_dir() gives up, stat() would raise
                is_directory = False
            if not is_directory:
                if gyroflow_name(item.name):
                    found.append((prefix + item.name, link or item.is_symlink()))
                continue
            real = os.path.realpath(item.path)
            if real not in above:
                stack.append(
                    (prefix + item.name, item.path, link or item.is_symlink(), above | {real})
                )
    found.sort()
    return found


def gyroflow_files(paths: Paths) -> list[tuple[str, str]]:
    """(real path, display name) of every Gyroflow lens profile file the
    paths designate: each directory's :func:`gyroflow_entries`, named
    relative to it, and files given directly, named as given; a file named
    twice is read once. Paths are strings: a tree holds some ten thousand
    profiles, and a Path each costs more than reading them. Raises
    :class:`LoadError` for a path that does not exist, a Lensfun database, a
    directory without profiles, and no paths."""
    if isinstance(paths, (str, bytes, os.PathLike)):
        paths = [paths]
    if not paths:
        raise LoadError("no path given: give a directory of Gyroflow lens profiles or profiles")
    targets: list[tuple[str, str]] = []
    seen: set[str] = set()
    for given in map(_path, paths):
        shown = display_path(given)
        if not os.path.lexists(given):
            raise LoadError(f"{shown}: no such file or directory")
        kind, entries = format_of(given)
        if kind != GYROFLOW and os.path.isdir(given):
            raise LoadError(f"{shown}: a Lensfun database, not Gyroflow lens profiles")
        if kind != GYROFLOW and os.path.isfile(given):
            raise LoadError(f"{shown}: XML or not JSON, not a Gyroflow lens profile")
        base = os.path.realpath(given)
        # Joined by hand: os.path.join costs as much as reading a profile's bytes.
        found = (
            [(base, display_path(given))]
            if not entries
            else [
                (
                    _real(given / name) if link else f"{base}{os.sep}{name}",
                    name if name.isascii() else display_path(name),
                )
                for name, link in entries
            ]
        )
        for real, name in found:
            if real not in seen:
                seen.add(real)
                targets.append((real, name))
    return targets


def read_descriptor(path: str | os.PathLike[str]) -> int:
    """A descriptor of ``path`` opened for reading without ever blocking (a FIFO
    cannot hang the run); the caller closes it."""
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0)
    return os.open(path, flags | getattr(os, "O_CLOEXEC", 0))


def read_file(path: str | os.PathLike[str], limit: int = MAX_FILE_BYTES) -> bytes:
    """The bytes of a regular file.

    Raises ``OSError`` for a FIFO, device, socket or directory (opened
    non-blocking and refused), a link that leads nowhere or in a loop, and a
    file larger than ``limit`` (:data:`MAX_FILE_BYTES`).
    """
    descriptor = read_descriptor(path)
    try:
        info = os.fstat(descriptor)
        if not stat.S_ISREG(info.st_mode):
            raise OSError(0, "not a regular file")
        if info.st_size > limit:
            raise OSError(0, f"larger than {_size(limit)}, not a database file")
        # os.read, not a file object, which costs as much as the reading of a
        # small file; on to the end, for a file that grows or tells no size (/proc).
        chunks = [os.read(descriptor, info.st_size + 1)]
        while chunks[-1]:
            chunks.append(os.read(descriptor, max(info.st_size, 1 << 16)))
        return chunks[0] if len(chunks) == 2 else b"".join(chunks)
    finally:
        os.close(descriptor)


def _size(limit: int) -> str:
    """A size limit in words: MiB, else KiB."""
    return f"{limit >> 20} MiB" if limit >= 1 << 20 else f"{limit >> 10} KiB"
