"""A cache of parsed and audited database files, keyed by their content.

Each file's entries, and their metrics once computed, are stored with a
BLAKE2b digest of the file's bytes. A file is trusted to be unchanged only
when its bytes hash to the stored digest: its size and modification time
prove nothing (``git checkout``, ``rsync -t`` and ``tar`` restore times, and
an edit may keep the size). Scanning an unchanged database still reads and
hashes every file (a few milliseconds for Lensfun's 4 MB), but parses no XML
and imports no numpy. On a miss the file is parsed from the very bytes that
were hashed, so that a digest is never stored beside another content's
entries.

Metrics are valid only for the code that computed them: every cache file is
tied to lensaudit's version, the record layout and a digest of the package's
top-level modules (the loader, the solver, the metrics and what they use).

Where: ``$LENSAUDIT_CACHE_DIR`` if set, else ``$XDG_CACHE_HOME/lensaudit``
(if that is an absolute path, as the XDG specification requires), else
``~/.cache/lensaudit``. One cache file, ``parsed-<digest>.cache``, per set of
input files. After each write, the least recently used cache files beyond
:data:`MAX_CACHE_FILES` files or :data:`MAX_CACHE_BYTES` bytes in total are
removed (the one just written is kept), and so are temporary files left
behind for more than an hour. Within a cache file, records of files not seen
in the run that writes it are dropped.

Integrity: a cache file is a fixed header, a BLAKE2b checksum, then the
records as :mod:`marshal` data. The checksum covers the records and the
format described above, and is verified before anything is unmarshalled: a
flipped byte, a truncated file or a file written by another version is
ignored. The cache is an optimization only: any problem reading or writing
it (unreadable or read-only directory, full disk, garbage) means parsing as
if it were not there, without a message.

Records hold each column of a file's entries as one object (a block of
doubles, or texts joined into one string), so reading the cache creates no
object per value until the entries are built, and it cannot run code.
"""

from __future__ import annotations

import marshal
import os
import stat as stat_module
import time
from array import array
from dataclasses import fields
from itertools import islice
from operator import attrgetter
from pathlib import Path

try:  # BLAKE2 alone: hashlib would also load OpenSSL, a few ms a warm scan does not need
    from _blake2 import blake2b
except ImportError:
    from hashlib import blake2b

from . import __version__
from .loader import DistortionEntry, read_bytes, read_file
from .pipeline import METRIC_FLOAT_COLUMNS

#: Cache files kept in the cache directory, at most (least recently used go first).
MAX_CACHE_FILES = 16
#: Total size of the cache files kept, at most, in bytes (the newest is always kept).
MAX_CACHE_BYTES = 64 * 1024 * 1024

_PREFIX = "parsed-"
_SUFFIX = ".cache"
_TEMPORARY_SUFFIX = ".tmp"
_ABANDONED_SECONDS = 3600  # a temporary file this old belongs to no running writer
_MAGIC = b"lensaudit parse cache\n"
_CHECKSUM_SIZE = 32
_DIGEST_SIZE = 16  # of file contents: collisions by chance are out of the question


def _kind(annotation: object) -> str:
    return annotation if isinstance(annotation, str) else getattr(annotation, "__name__", "")


_FIELDS = tuple(f.name for f in fields(DistortionEntry))
#: How each entry field is stored; ``file`` is not: it is the name given at reading.
_KINDS = {f.name: _kind(f.type) for f in fields(DistortionEntry) if f.name != "file"}
_KNOWN_KINDS = {"float", "int", "str", "tuple[str, ...]"}
_PACKABLE = _FIELDS[0] == "file" and set(_KINDS.values()) <= _KNOWN_KINDS
_METRIC_FLAGS = ("tail", "folds_in_image")  # small integers
_SEPARATOR = "\0"


def _code_digest() -> str:
    """Digest of the package's top-level modules, which decide entries and metrics.

    All of them, not a chosen few: a module the loader or the metrics start
    to rely on must not be forgotten here.
    """
    digest = blake2b(digest_size=16)
    for module in sorted(Path(__file__).parent.glob("*.py")):
        try:
            digest.update(module.name.encode() + b"\0" + module.read_bytes())
        except OSError:  # not installed from source files: the version must do
            pass
    return digest.hexdigest()


# Changes with the package version, the record layout and the auditing code.
_FORMAT = (
    f"lensaudit parse cache 4 {__version__} {_code_digest()} "
    f"{' '.join(f'{name}:{kind}' for name, kind in _KINDS.items())} "
    f"{' '.join(METRIC_FLOAT_COLUMNS)} {' '.join(_METRIC_FLAGS)}"
).encode()


def _checksum(body: bytes) -> bytes:
    digest = blake2b(_FORMAT, digest_size=_CHECKSUM_SIZE)
    digest.update(body)
    return digest.digest()


def content_digest(data: bytes) -> bytes:
    """The digest a file's bytes are cached under (BLAKE2b, 16 bytes)."""
    return blake2b(data, digest_size=_DIGEST_SIZE).digest()


def _join(values: list[str]) -> str | list[str]:
    """Texts as one string, or as the list itself when a text holds the separator."""
    joined = _SEPARATOR.join(values)
    if joined.count(_SEPARATOR) != max(len(values) - 1, 0):
        return values
    return joined


def _split(stored: str | list[str], count: int) -> list[str]:
    if isinstance(stored, list):
        values = stored
    else:
        values = stored.split(_SEPARATOR) if count else []
    if len(values) != count:
        raise ValueError("inconsistent cache record")
    return values


def _pack(entries: list[DistortionEntry]) -> dict[str, object]:
    """Entries as columns: numbers as blocks of bytes, texts joined."""
    packed: dict[str, object] = {"count": len(entries)}
    for name, kind in _KINDS.items():
        values = list(map(attrgetter(name), entries))
        if kind == "float":
            packed[name] = array("d", values).tobytes()
        elif kind == "int":
            packed[name] = array("q", values).tobytes()
        elif kind == "str":
            packed[name] = _join(values)
        else:  # tuples of texts: their lengths, then all texts in a row
            packed[name] = (
                array("q", map(len, values)).tobytes(),
                _join([text for group in values for text in group]),
            )
    return packed


def _unpack(packed: dict, name: str) -> list[DistortionEntry]:
    """The entries of a packed record, reported as file ``name``."""
    count = packed["count"]
    if not isinstance(count, int) or count < 0:
        raise ValueError("inconsistent cache record")
    columns: dict[str, list] = {"file": [name] * count}
    for field, kind in _KINDS.items():
        stored = packed[field]
        if kind == "float":
            values = array("d", stored).tolist()
        elif kind == "int":
            values = array("q", stored).tolist()
        elif kind == "str":
            values = _split(stored, count)
        else:
            lengths = array("q", stored[0])
            if any(length < 0 for length in lengths):
                raise ValueError("inconsistent cache record")
            texts = iter(_split(stored[1], sum(lengths)))
            values = [tuple(islice(texts, length)) for length in lengths]
        if len(values) != count:
            raise ValueError("inconsistent cache record")
        columns[field] = values
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
#: A record: content digest, packed entries, file error, packed metrics or None.
_Record = tuple[bytes, dict, str, "dict | None"]
#: What unpacking a damaged or foreign record can raise.
_RECORD_ERRORS = (KeyError, TypeError, ValueError, AttributeError, IndexError, OverflowError)


def cache_dir() -> Path:
    """Directory holding lensaudit's caches.

    ``$LENSAUDIT_CACHE_DIR`` if set and not empty; else ``lensaudit`` in
    ``$XDG_CACHE_HOME`` if that is an absolute path; else ``~/.cache/lensaudit``.
    """
    explicit = os.environ.get("LENSAUDIT_CACHE_DIR")
    if explicit:
        return Path(explicit)
    base = os.environ.get("XDG_CACHE_HOME", "")
    if not os.path.isabs(base):  # the XDG specification says to ignore relative paths
        base = os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "lensaudit"


def _valid_record(record: object) -> bool:
    return (
        isinstance(record, tuple)
        and len(record) == 4
        and isinstance(record[0], bytes)
        and len(record[0]) == _DIGEST_SIZE
        and isinstance(record[1], dict)
        and isinstance(record[2], str)
        and (record[3] is None or isinstance(record[3], dict))
    )


def _read_records(path: Path) -> dict[bytes, _Record]:
    """The records of a cache file; empty if it is missing, damaged or foreign."""
    try:
        # Non-blocking, and regular files only: a FIFO put here must not hang a scan.
        handle = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except OSError:
        return {}
    try:
        status = os.fstat(handle)
        if not stat_module.S_ISREG(status.st_mode) or status.st_size > MAX_CACHE_BYTES:
            return {}
        with os.fdopen(handle, "rb") as stream:
            handle = -1
            data = stream.read()
    except OSError:
        return {}
    finally:
        if handle != -1:
            os.close(handle)
    start = len(_MAGIC) + _CHECKSUM_SIZE
    body = memoryview(data)[start:]
    if not data.startswith(_MAGIC) or data[len(_MAGIC) : start] != _checksum(body):
        return {}
    try:
        records = marshal.loads(body)
    except (EOFError, ValueError, TypeError):
        return {}
    if not isinstance(records, dict):
        return {}
    return {
        key: record
        for key, record in records.items()
        if isinstance(key, bytes) and _valid_record(record)
    }


def _evict(directory: Path, keep: Path) -> None:
    """Remove the least recently used cache files beyond the limits, and abandoned ones."""
    now = time.time()
    found = []
    for candidate in directory.glob(f"{_PREFIX}*"):
        try:
            status = candidate.stat()
            if candidate.name.endswith(_TEMPORARY_SUFFIX):
                if now - status.st_mtime > _ABANDONED_SECONDS:
                    candidate.unlink(missing_ok=True)
                continue
            if candidate != keep and stat_module.S_ISREG(status.st_mode):
                found.append((status.st_mtime_ns, status.st_size, candidate))
        except OSError:
            continue
    try:
        count, total = 1, keep.stat().st_size
    except OSError:
        count, total = 0, 0
    full = False
    for _, size, candidate in sorted(found, key=lambda item: item[0], reverse=True):
        count, total = count + 1, total + size
        # Least recently used first out: once one does not fit, no older one is kept.
        full = full or count > MAX_CACHE_FILES or total > MAX_CACHE_BYTES
        if full:
            try:
                candidate.unlink(missing_ok=True)
            except OSError:
                pass


class ParseCache:
    """Parsed entries and metrics of files, keyed by absolute path, valid while
    the file's content hashes to the stored digest."""

    def __init__(self, paths: list[Path], directory: Path | None = None) -> None:
        """The cache of the set of files ``paths`` (in :func:`cache_dir` by default)."""
        # path (os.fsencode of the absolute path) -> record
        self._records: dict[bytes, _Record] = {}
        self._seen: set[bytes] = set()
        self._changed = False
        self.path: Path | None = None
        if not _PACKABLE:  # entries of a layout this module cannot store
            return
        try:
            # os.fsencode keeps file names that are not UTF-8 (surrogate escapes) as bytes.
            key = b"\0".join(sorted(os.fsencode(p.resolve()) for p in paths))
            name = blake2b(key, digest_size=8).hexdigest()
            self.path = (directory or cache_dir()) / f"{_PREFIX}{name}{_SUFFIX}"
        except (OSError, RuntimeError, ValueError):
            return
        self._records = _read_records(self.path)
        if self._records:
            try:  # recently used: last to be evicted
                os.utime(self.path)
            except OSError:
                pass

    def get(self, path: Path, stat: os.stat_result, name: str) -> CachedFile:
        """Entries and file error of the file at absolute ``path``, reported as ``name``.

        The file is read (as :func:`lensaudit.loader.read_file` reads it) and
        hashed; if its content is not the stored one, it is parsed here from
        those bytes and stored. Raises OSError when the file cannot be read,
        as reading it without the cache would. ``stat`` is not used: a file's
        size and time do not prove it unchanged.
        """
        key = os.fsencode(path)
        self._seen.add(key)
        try:
            data = read_file(path)
        except OSError:
            self._forget(key)
            raise
        digest = content_digest(data)
        record = self._records.get(key)
        if record is not None and record[0] == digest:
            try:
                return _unpack(record[1], name), record[2]
            except _RECORD_ERRORS:
                pass
        entries, error = read_bytes(data, name)
        if self.path is not None:
            try:
                self._records[key] = (digest, _pack(entries), error, None)
                self._changed = True
            except _RECORD_ERRORS:  # entries that cannot be stored are parsed every time
                self._forget(key)
        return entries, error

    def put(
        self, path: Path, stat: os.stat_result, entries: list[DistortionEntry], error: str
    ) -> None:
        """Store nothing: which bytes ``entries`` were parsed from is not known here.

        :meth:`get` parses and stores the files it does not find, so this is
        only called by loaders that parse on their own.
        """

    def _forget(self, key: bytes) -> None:
        if self._records.pop(key, None) is not None:
            self._changed = True

    def audited(self, targets: list[tuple[Path, str]]) -> list[CachedFile] | None:
        """Entries and errors of every target, if all are unchanged and audited before.

        Every file is read and hashed; no XML is parsed.
        """
        found = []
        for path, name in targets:
            try:
                path = path.resolve()
                key = os.fsencode(path)
                record = self._records.get(key)
                if record is None or record[3] is None:
                    return None
                if content_digest(read_file(path)) != record[0]:
                    return None
                found.append((_unpack(record[1], name), record[2]))
            except (OSError, RuntimeError, *_RECORD_ERRORS):
                return None
            self._seen.add(key)
        return found

    def metrics(self, targets: list[tuple[Path, str]]) -> list[dict[str, list]] | None:
        """The stored metric columns of every target (call after :meth:`audited`)."""
        try:
            return [
                _unpack_metrics(record[3], record[1]["count"])
                for record in (self._records[os.fsencode(path.resolve())] for path, _ in targets)
            ]
        except (OSError, RuntimeError, *_RECORD_ERRORS):
            return None

    def put_metrics(self, path: Path, columns: dict[str, list]) -> None:
        """Store the metrics of a file whose entries were given by :meth:`get` in this run."""
        try:
            key = os.fsencode(path.resolve())
            record = self._records.get(key)
            if record is None or any(len(v) != record[1]["count"] for v in columns.values()):
                return
            self._records[key] = (*record[:3], pack_metrics(columns))
            self._changed = True
        except (OSError, RuntimeError, *_RECORD_ERRORS):
            pass

    def save(self) -> None:
        """Write the cache if anything changed, then evict; silently skipped when not possible.

        Files not seen in this run (removed from the database) are dropped.
        """
        stale = self._records.keys() - self._seen
        if self.path is None or not (self._changed or stale):
            return
        kept = {k: v for k, v in self._records.items() if k in self._seen}
        import tempfile  # only here: a warm scan writes nothing

        temporary = None
        try:
            body = marshal.dumps(kept)
            if len(body) > MAX_CACHE_BYTES:  # it would be evicted, and never read
                return
            self.path.parent.mkdir(parents=True, exist_ok=True)
            handle, temporary = tempfile.mkstemp(
                dir=self.path.parent, prefix=_PREFIX, suffix=_TEMPORARY_SUFFIX
            )
            with os.fdopen(handle, "wb") as stream:
                stream.write(_MAGIC + _checksum(body))
                stream.write(body)
            os.replace(temporary, self.path)
            temporary = None
            _evict(self.path.parent, self.path)
        except (OSError, ValueError):
            pass
        finally:
            if temporary is not None:
                try:
                    os.unlink(temporary)
                except OSError:
                    pass
