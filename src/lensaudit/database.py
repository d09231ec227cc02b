"""Where a Lensfun database is: paths given by the user, or the bundled one.

lensfunpy ships a copy of the Lensfun database (``lensfunpy/db_files``). It is
located here without importing lensfunpy, so that finding it does not load
liblensfun.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from importlib.util import find_spec
from pathlib import Path

from .loader import LoadError


@dataclass(frozen=True)
class DatabaseSource:
    """What was audited: the paths and a human-readable description."""

    paths: tuple[Path, ...]
    label: str
    bundled: bool = False


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
    """The database to audit: ``paths`` if given, else lensfunpy's bundled one."""
    if paths:
        resolved = tuple(Path(p) for p in paths)
        return DatabaseSource(resolved, ", ".join(str(p) for p in resolved))
    path = bundled_database_path()
    return DatabaseSource(
        (path,),
        f"Lensfun database bundled with lensfunpy {lensfunpy_version()} ({path})",
        bundled=True,
    )


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
        digest.update(file.name.encode() + b"\0")
        digest.update(file.read_bytes())
    return digest.hexdigest()
