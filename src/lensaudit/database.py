"""Where a Lensfun database is: paths given by the user, or the bundled one.

lensfunpy ships a copy of the Lensfun database (``lensfunpy/db_files``). It is
located here without importing lensfunpy, so that finding it does not load
liblensfun.
"""

from __future__ import annotations

import os
import re
from collections import namedtuple
from collections.abc import Iterable
from importlib.util import find_spec
from pathlib import Path

from .loader import LoadError, display_path


class DatabaseSource(
    namedtuple("DatabaseSource", ("paths", "label", "bundled"), defaults=(False,))
):
    """What was audited: the ``paths`` (a tuple), a human-readable ``label``, and
    whether it is the database ``bundled`` with lensfunpy. (A named tuple: a
    dataclass would cost every scan more than it is worth.)"""

    __slots__ = ()


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
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("lensfunpy")
    except PackageNotFoundError:
        return ""


def resolve(paths: tuple[str | os.PathLike[str], ...] | list[str] | None) -> DatabaseSource:
    """The database to audit.

    ``paths`` if given, where a Lensfun checkout (or its ``data`` directory)
    stands for its ``data/db``; without paths, the database of the Lensfun
    checkout the working directory is in, else lensfunpy's bundled one.
    """
    if paths:
        given = _unique(Path(p) for p in paths)
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


def _unique(paths: Iterable[Path]) -> tuple[Path, ...]:
    """Paths without repeats: a database named twice is audited once."""
    seen: dict[str, Path] = {}
    for path in paths:
        seen.setdefault(os.path.realpath(path), path)
    return tuple(seen.values())


#: Where a Lensfun checkout keeps its database, relative to the checkout.
CHECKOUT_DATABASE = Path("data", "db")


def is_database_directory(path: Path) -> bool:
    """Whether ``path`` is a directory holding Lensfun database files.

    A file counts when its first kilobyte names the ``<lensdatabase>`` root
    element; only the first few ``*.xml`` files are looked at.
    """
    try:
        candidates = sorted(p for p in os.listdir(path) if p.lower().endswith(".xml"))[:3]
    except OSError:
        return False
    for name in candidates:
        try:
            with open(path / name, "rb") as stream:
                if b"<lensdatabase" in stream.read(1024):
                    return True
        except OSError:
            continue
    return False


def database_directory(path: Path) -> Path:
    """The database a path designates: ``data/db`` of a Lensfun checkout, else ``path``.

    A checkout is recognized by its ``data/db`` holding Lensfun XML, so that
    ``lensaudit scan lensfun/`` audits a clone of the Lensfun repository (and
    ``lensfun/data`` works too). Anything else is returned unchanged.
    """
    for candidate in (path / CHECKOUT_DATABASE, path / CHECKOUT_DATABASE.name):
        if is_database_directory(candidate):
            return candidate
    return path


def enclosing_database(start: Path | None = None) -> Path | None:
    """``data/db`` of the Lensfun checkout that ``start`` (the working directory) is in.

    Looks at ``start`` and its parents; None outside a Lensfun checkout.
    """
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
    """Short id of the commit checked out in the git repository holding ``directory``.

    Adds ``+changes`` when the directory differs from that commit; "" when
    ``directory`` is not in a git repository or git is not available.
    """
    import subprocess

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


def content_hash(files: list[Path]) -> str:
    """SHA-256 over the names and bytes of the files, in the order given."""
    import hashlib

    digest = hashlib.sha256()
    for file in files:
        digest.update(os.fsencode(file.name) + b"\0")
        digest.update(file.read_bytes())
    return digest.hexdigest()
