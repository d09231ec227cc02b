"""A cache of parsed and audited database files: an unchanged file is not read again.

Entries of each file, and their metrics once computed, are stored with the
file's size and modification time (the check git and make rely on); a file
whose size or time changed is parsed and audited again. Metrics are kept only
for the code that computed them: the cache is keyed by a checksum of the
modules that read and audit entries, as well as by lensaudit's version.

The cache lives in ``$LENSAUDIT_CACHE_DIR``, else ``$XDG_CACHE_HOME/lensaudit``,
else ``~/.cache/lensaudit``; one cache file per set of input paths, written
atomically. It is an optimization only: any
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
from .pipeline import METRIC_FLOAT_COLUMNS

_FIELDS = tuple(f.name for f in fields(DistortionEntry))
_NUMBERS = ("crop_factor", "aspect_ratio", "focal", "real_focal", "a", "b", "c", "k1", "k2")
_TEXTS = ("maker", "lens", "type", "model", "status", "message")
_METRIC_FLAGS = ("tail", "folds_in_image")  # small integers
#: The modules whose code decides what a file's entries and metrics are.
_CODE = ("loader.py", "normalizer.py", "solver.py", "metrics.py", "cache.py")


def _code_checksum() -> int:
    checksum = 0
    for module in _CODE:
        try:
            checksum = zlib.crc32(Path(__file__).with_name(module).read_bytes(), checksum)
        except OSError:  # not installed from source files: the version must do
            pass
    return checksum


# Changes with the package version, the record layout and the auditing code.
_FORMAT = (
    f"lensaudit-cache 3 {__version__} {_code_checksum():08x} {' '.join(_FIELDS)} "
    f"{' '.join(METRIC_FLOAT_COLUMNS)}"
)
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


def pack_metrics(columns: dict[str, list]) -> dict[str, bytes]:
    """One file's metric columns (see :data:`lensaudit.pipeline.METRIC_COLUMNS`) as bytes."""
    packed = {name: array("d", columns[name]).tobytes() for name in METRIC_FLOAT_COLUMNS}
    packed.update({name: array("b", columns[name]).tobytes() for name in _METRIC_FLAGS})
    return packed


def _unpack_metrics(packed: dict[str, bytes], count: int) -> dict[str, list]:
    columns = {name: array("d", packed[name]).tolist() for name in METRIC_FLOAT_COLUMNS}
    columns.update({name: array("b", packed[name]).tolist() for name in _METRIC_FLAGS})
    if any(len(values) != count for values in columns.values()):
        raise ValueError("inconsistent cache record")
    return columns


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
        # path -> (size and time, entries, file error, metrics or None)
        self._stored: dict[str, tuple[tuple[int, int], dict, str, dict | None]] = {}
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
        self._stored[str(path)] = (_stamp(stat), _pack(entries), error, None)
        self._seen.add(str(path))
        self._changed = True

    def audited(self, targets: list[tuple[Path, str]]) -> list[CachedFile] | None:
        """Entries and errors of every target, if all are unchanged and audited before."""
        found = []
        for path, name in targets:
            path = path.resolve()
            record = self._stored.get(str(path))
            try:
                if record is None or record[3] is None or tuple(record[0]) != _stamp(path.stat()):
                    return None
                found.append((_unpack(record[1], name), record[2]))
            except (OSError, KeyError, TypeError, ValueError, AttributeError, IndexError):
                return None
            self._seen.add(str(path))
        return found

    def metrics(self, targets: list[tuple[Path, str]]) -> list[dict[str, list]] | None:
        """The stored metric columns of every target (call after :meth:`audited`)."""
        try:
            return [
                _unpack_metrics(record[3], record[1]["count"])
                for record in (self._stored[str(path.resolve())] for path, _ in targets)
            ]
        except (KeyError, TypeError, ValueError, AttributeError, IndexError):
            return None

    def put_metrics(self, path: Path, columns: dict[str, list]) -> None:
        """Store the metrics of a file whose entries are stored."""
        record = self._stored.get(str(path.resolve()))
        if record is not None:
            self._stored[str(path.resolve())] = (*record[:3], pack_metrics(columns))
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
