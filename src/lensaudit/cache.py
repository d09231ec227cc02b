"""A cache of parsed database files, so that an unchanged database is not parsed again.

Entries of each file are stored with the file's size and modification time
(the check git and make rely on); a file whose size or time changed is parsed
again. The cache lives in ``$LENSAUDIT_CACHE_DIR``, else
``$XDG_CACHE_HOME/lensaudit``, else ``~/.cache/lensaudit``; one cache file per
set of input paths, written atomically. It is an optimization only: any
problem reading or writing it means parsing as if it were not there.

The format is :mod:`marshal` of a few large objects per file: each column of
the entries as one joined string or one block of doubles. Reading it creates
no object per value until the entries are built, and it cannot run code.
"""

from __future__ import annotations

import marshal
import os
import zlib
from array import array
from dataclasses import fields
from operator import attrgetter
from pathlib import Path

from . import __version__
from .loader import DistortionEntry

_FIELDS = tuple(f.name for f in fields(DistortionEntry))
_NUMBERS = ("crop_factor", "aspect_ratio", "focal", "real_focal", "a", "b", "c", "k1", "k2")
_TEXTS = ("maker", "lens", "type", "model", "status", "message")
# Bumped with the package version and with the record layout.
_FORMAT = f"lensaudit-parse-cache 2 {__version__} {' '.join(_FIELDS)}"
_SEPARATOR = "\0"


def _pack(entries: list[DistortionEntry]) -> dict[str, object]:
    """Entries as columns: doubles as bytes, texts joined, mounts joined twice."""
    packed: dict[str, object] = {"count": len(entries)}
    packed["line"] = array("q", map(attrgetter("line"), entries)).tobytes()
    for name in _NUMBERS:
        packed[name] = array("d", map(attrgetter(name), entries)).tobytes()
    for name in _TEXTS:
        packed[name] = _SEPARATOR.join(map(attrgetter(name), entries))
    packed["mounts"] = "\2".join("\1".join(e.mounts) for e in entries)
    return packed


def _unpack(packed: dict, name: str) -> list[DistortionEntry]:
    count = packed["count"]
    if count == 0:
        return []
    columns: dict[str, list] = {"file": [name] * count}
    columns["line"] = array("q", packed["line"]).tolist()
    for column in _NUMBERS:
        columns[column] = array("d", packed[column]).tolist()
    for column in _TEXTS:
        columns[column] = packed[column].split(_SEPARATOR)
    columns["mounts"] = [tuple(m.split("\1")) if m else () for m in packed["mounts"].split("\2")]
    if any(len(values) != count for values in columns.values()):
        raise ValueError("inconsistent cache record")
    return list(map(DistortionEntry, *(columns[f] for f in _FIELDS)))


CachedFile = tuple[list[DistortionEntry], str]


def cache_dir() -> Path:
    """Directory holding lensaudit's caches."""
    explicit = os.environ.get("LENSAUDIT_CACHE_DIR")
    if explicit:
        return Path(explicit)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "lensaudit"


def _stamp(stat: os.stat_result) -> tuple[int, int]:
    return stat.st_size, stat.st_mtime_ns


class ParseCache:
    """Parsed entries of files, keyed by absolute path, valid while size and mtime hold."""

    def __init__(self, paths: list[Path], directory: Path | None = None) -> None:
        key = "\0".join(sorted(str(p.resolve()) for p in paths))
        # A checksum is enough: the entries inside are keyed by absolute path.
        name = f"parsed-{zlib.crc32(key.encode()):08x}.marshal"
        self.path = (directory or cache_dir()) / name
        self._stored: dict[str, tuple[tuple[int, int], dict, str]] = {}
        self._seen: set[str] = set()
        self._changed = False
        try:
            with open(self.path, "rb") as stream:
                data = marshal.load(stream)
            if isinstance(data, tuple) and len(data) == 2 and data[0] == _FORMAT:
                self._stored = data[1]
        except (OSError, EOFError, ValueError, TypeError):
            self._stored = {}

    def get(self, path: Path, stat: os.stat_result, name: str) -> CachedFile | None:
        """Entries and file error stored for ``path``, if it has not changed since.

        ``name`` is how the file is reported this time.
        """
        key = str(path)
        self._seen.add(key)
        found = self._stored.get(key)
        if found is None or tuple(found[0]) != _stamp(stat):
            return None
        try:
            return _unpack(found[1], name), found[2]
        except (KeyError, TypeError, ValueError, AttributeError):
            return None

    def put(
        self, path: Path, stat: os.stat_result, entries: list[DistortionEntry], error: str
    ) -> None:
        self._stored[str(path)] = (_stamp(stat), _pack(entries), error)
        self._seen.add(str(path))
        self._changed = True

    def save(self) -> None:
        """Write the cache if anything changed; silently skipped when not possible.

        Files not seen in this run (removed from the database) are dropped.
        """
        stale = self._stored.keys() - self._seen
        if not (self._changed or stale):
            return
        kept = {k: v for k, v in self._stored.items() if k in self._seen}
        import tempfile

        temporary = None
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            handle, temporary = tempfile.mkstemp(dir=self.path.parent, suffix=".tmp")
            with os.fdopen(handle, "wb") as stream:
                marshal.dump((_FORMAT, kept), stream)
            os.replace(temporary, self.path)
            temporary = None
        except (OSError, ValueError):
            pass
        finally:
            if temporary is not None:
                Path(temporary).unlink(missing_ok=True)
