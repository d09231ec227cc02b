"""A cache of parsed and audited database files, keyed by their content.

Each file's entries, their metrics once computed, and the rows output
formats render from them are stored with a BLAKE2b digest of the file's
bytes. A file is trusted to be unchanged only when its bytes hash to the
stored digest: its size and modification time prove nothing (``git
checkout``, ``rsync -t`` and ``tar`` restore times, and an edit may keep the
size). Scanning an unchanged database still reads and hashes every file (a
few milliseconds for Lensfun's 4 MB), but parses no XML and imports no numpy.

The cache never reads or parses a database file itself: its caller hashes
the bytes it read (:func:`content_digest`), asks for a record with that
digest, and on a miss stores what it parsed from those very bytes, so that a
digest is never stored beside another content's entries.

Metrics and rendered rows are valid only for the code that made them: every
cache file is tied to lensaudit's version, the record layout and a digest of
the package's top-level modules and output formats (the loader, the solver,
the metrics, the CSV and JSON writers and what they use). Rendered rows also
name their file as it was shown when they were made, and serve only a scan
that shows it the same way.

Where: ``$LENSAUDIT_CACHE_DIR`` if set, else ``$XDG_CACHE_HOME/lensaudit``
(if that is an absolute path, as the XDG specification requires), else
``~/.cache/lensaudit``. One cache file, ``parsed-<digest>.cache``, per set of
input files, a file of :mod:`lensaudit.store` like every cache of lensaudit
(:func:`record_file`): after each write, the least recently used store files
of the directory beyond :data:`MAX_CACHE_FILES` files or :data:`MAX_CACHE_BYTES`
bytes in total are removed (the one just written is kept), and so are
temporary files left behind for more than an hour. Within a cache file,
records of files not seen in the run that writes it are dropped.

Integrity: a cache file is a file of sealed parts (see :mod:`lensaudit.store`):
a fixed header, a BLAKE2b checksum, a head naming each file's path and
content digest with the seal of its record, then the records, each as
:mod:`marshal` data of its own. The checksum covers the head and the format
described above, and is verified before anything is unmarshalled; a record
is unmarshalled only once its bytes match its seal (BLAKE2b-256). A flipped
byte, a truncated file or a file written by another version is ignored, as
is a damaged record. Records are sealed by the process that makes them (a
worker, as it parses), so that saving the cache is mostly writing bytes.
The cache is an optimization only: any problem reading or writing it
(unreadable or read-only directory, full disk, garbage) means parsing as if
it were not there, without a message.

Records hold each column of a file's entries as one object (a block of
doubles, or texts joined into one string): reading the cache creates no
object per value until a column is asked for, and it cannot run code. The
same packed columns carry parsed files between processes
(:mod:`lensaudit.workers`).
"""

from __future__ import annotations

import functools
import os
from array import array
from collections import namedtuple
from collections.abc import Callable
from itertools import islice
from operator import attrgetter
from pathlib import Path

try:  # BLAKE2 alone: hashlib would also load OpenSSL, a few ms a warm scan does not need
    from _blake2 import blake2b
except ImportError:
    from hashlib import blake2b

from . import __version__, store
from .columns import METRIC_FLAG_COLUMNS, METRIC_FLOAT_COLUMNS
from .loader import ENTRY_FIELDS, DistortionEntry

#: Cache files kept in the cache directory, at most (least recently used go first).
MAX_CACHE_FILES = 16
#: Total size of the cache files kept, at most, in bytes (the newest is always kept).
MAX_CACHE_BYTES = 64 * 1024 * 1024

_KIND = "parsed"  # cache files are parsed-<digest>.cache (see lensaudit.store)
_DIGEST_SIZE = 16  # of file contents: collisions by chance are out of the question


_FIELDS = tuple(ENTRY_FIELDS)
#: How each entry field is stored; ``file`` is not: it is the name given at reading.
_KINDS = {name: kind for name, kind in ENTRY_FIELDS.items() if name != "file"}
_KNOWN_KINDS = {"float", "int", "str", "tuple[str, ...]"}
_PACKABLE = _FIELDS[0] == "file" and set(_KINDS.values()) <= _KNOWN_KINDS
_SEPARATOR = "\0"
#: Where the code that makes entries, metrics and rendered rows lives.
_CODE = ("*.py", "formats/*.py")


def _code_digest(package: Path = Path(__file__).parent) -> str:
    """Digest of the package's top-level modules and output formats.

    All of them, not a chosen few: a module the loader, the metrics or a
    format start to rely on must not be forgotten here.
    """
    return store.code_digest(package, _CODE)


@functools.cache
def fingerprint() -> bytes:
    """What the parse cache's files are valid for: the package version, the
    record layout and the auditing code. Computed when a cache is first used,
    not at import: a scan without the cache reads no source file for it."""
    return (
        f"lensaudit parse cache 6 {__version__} {_code_digest()} "
        f"{' '.join(f'{name}:{kind}' for name, kind in _KINDS.items())} "
        f"{' '.join(METRIC_FLOAT_COLUMNS)} {' '.join(METRIC_FLAG_COLUMNS)} rows"
    ).encode()


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


def entry_columns(entries: list[DistortionEntry]) -> dict[str, list]:
    """The entries as columns: field name -> one value per entry (``file`` left out)."""
    return {name: list(map(attrgetter(name), entries)) for name in _KINDS}


def pack_columns(columns: dict[str, list], count: int) -> dict[str, object]:
    """Entry columns (as :func:`entry_columns` gives them) packed: numbers as
    blocks of bytes, texts joined."""
    packed: dict[str, object] = {"count": count}
    for name, kind in _KINDS.items():
        values = columns[name]
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


def pack_entries(entries: list[DistortionEntry]) -> dict[str, object]:
    """Entries as packed columns (see :func:`pack_columns`)."""
    return pack_columns(entry_columns(entries), len(entries))


def packed_count(packed: dict) -> int:
    """The number of entries in packed columns, once every column is checked to hold
    that many; raises ValueError (or another of :data:`RECORD_ERRORS`) otherwise."""
    count = packed["count"]
    if not isinstance(count, int) or count < 0:
        raise ValueError("inconsistent cache record")
    for field, kind in _KINDS.items():
        stored = packed[field]
        if kind in ("float", "int"):
            if not isinstance(stored, bytes) or len(stored) != 8 * count:
                raise ValueError("inconsistent cache record")
        elif kind == "str":
            _check_texts(stored, count)
        else:
            lengths, texts = stored
            if not isinstance(lengths, bytes) or len(lengths) != 8 * count:
                raise ValueError("inconsistent cache record")
            lengths = array("q", lengths)
            if lengths and min(lengths) < 0:
                raise ValueError("inconsistent cache record")
            _check_texts(texts, sum(lengths))
    return count


def _check_texts(stored: object, count: int) -> None:
    if isinstance(stored, str):
        if (stored.count(_SEPARATOR) + 1 if count else len(stored)) != count:
            raise ValueError("inconsistent cache record")
    elif not (
        isinstance(stored, list)
        and len(stored) == count
        and all(isinstance(text, str) for text in stored)
    ):
        raise ValueError("inconsistent cache record")


def unpack_column(packed: dict, field: str, name: str) -> list:
    """One column of packed entries; ``file`` is ``name`` for every entry."""
    count = packed["count"]
    if field == "file":
        return [name] * count
    kind = _KINDS[field]
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
    return values


def unpack_entries(packed: dict, name: str) -> list[DistortionEntry]:
    """The entries of packed columns, reported as file ``name``."""
    columns = [unpack_column(packed, field, name) for field in _FIELDS]
    return list(map(DistortionEntry, *columns))


def pack_metrics(columns: dict[str, list]) -> dict[str, bytes]:
    """One file's metric columns (see :data:`lensaudit.columns.METRIC_COLUMNS`) as bytes."""
    packed = {name: array("d", columns[name]).tobytes() for name in METRIC_FLOAT_COLUMNS}
    packed.update({name: array("b", columns[name]).tobytes() for name in METRIC_FLAG_COLUMNS})
    return packed


def unpack_metrics(packed: dict[str, bytes], count: int) -> dict[str, list]:
    """Metric columns packed by :func:`pack_metrics`, checked to hold ``count`` values each."""
    check_metrics(packed, count)
    columns = {name: array("d", packed[name]).tolist() for name in METRIC_FLOAT_COLUMNS}
    columns.update({name: array("b", packed[name]).tolist() for name in METRIC_FLAG_COLUMNS})
    return columns


def check_metrics(packed: dict[str, bytes], count: int) -> None:
    """Raise ValueError (or another of :data:`RECORD_ERRORS`) unless ``packed``
    holds every metric column packed by :func:`pack_metrics`, ``count`` values each."""
    for names, size in ((METRIC_FLOAT_COLUMNS, 8), (METRIC_FLAG_COLUMNS, 1)):
        for name in names:
            stored = packed[name]
            if not isinstance(stored, bytes) or len(stored) != size * count:
                raise ValueError("inconsistent cache record")


#: A record: content digest, packed entries, file error, packed metrics or None,
#: the file name rendered rows show, rendered rows by format name, and the
#: file's tally for the summary (:func:`lensaudit.summary.tally`) or None.
_Record = tuple[bytes, dict, str, "dict | None", str, "dict[str, str]", "tuple | None"]
#: What unpacking a damaged or foreign record can raise.
RECORD_ERRORS = (KeyError, TypeError, ValueError, AttributeError, IndexError, OverflowError)


class CachedFile(
    namedtuple("CachedFile", ("packed", "count", "error", "metrics", "rows", "tally"))
):
    """What the cache holds for one file's content.

    ``packed`` are its entries (see :func:`pack_columns`), ``count`` of them;
    ``metrics`` their metric columns as :func:`pack_metrics` packs them
    (checked to hold ``count`` values each), or None if not audited yet; ``rows``
    the rendered rows by format name, for the file name asked for; ``tally``
    the file's counts for the summary, or None.
    """

    __slots__ = ()


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
        and len(record) == 7
        and isinstance(record[0], bytes)
        and len(record[0]) == _DIGEST_SIZE
        and isinstance(record[1], dict)
        and isinstance(record[2], str)
        and (record[3] is None or isinstance(record[3], dict))
        and isinstance(record[4], str)
        and isinstance(record[5], dict)
        and all(isinstance(k, str) and isinstance(v, str) for k, v in record[5].items())
        and (record[6] is None or isinstance(record[6], tuple))
    )


def sealed_record(
    digest: bytes,
    packed: dict,
    error: str,
    metrics: dict[str, list] | None,
    name: str,
    rows: dict[str, str],
    tally: tuple | None,
) -> tuple[bytes, bytes]:
    """What the cache stores of one file, as the sealed part of a cache file:
    ``(seal, body)`` (see :func:`lensaudit.store.sealed`), for
    :meth:`ParseCache.store_sealed`. Made where the file is parsed: a worker
    process seals its records while the others parse. Raises ValueError (or
    another of :data:`RECORD_ERRORS`) for what cannot be stored."""
    packed_metrics = None if metrics is None else pack_metrics(metrics)
    return store.sealed((digest, packed, error, packed_metrics, name, rows, tally))


class _Held:
    """A record the cache holds: its file's content digest, the seal and bytes
    of its part (None until sealed), and the record itself (None until
    read from those bytes)."""

    __slots__ = ("digest", "seal", "body", "record")

    def __init__(
        self,
        digest: bytes,
        seal: bytes | None,
        body: bytes | memoryview | None,
        record: _Record | None,
    ) -> None:
        self.digest = digest
        self.seal = seal
        self.body = body
        self.record = record


def _read_records(file: store.RecordFile) -> dict[bytes, _Held]:
    """The records of a cache file, not yet unsealed; empty if it is missing,
    damaged or foreign."""
    found = file.read_parts()
    if found is None:
        return {}
    head, parts = found
    if not isinstance(head, list) or len(head) != len(parts):
        return {}
    held = {}
    for item, (part_seal, body) in zip(head, parts, strict=True):
        if (
            isinstance(item, tuple)
            and len(item) == 2
            and isinstance(item[0], bytes)
            and isinstance(item[1], bytes)
        ):
            held[item[0]] = _Held(item[1], part_seal, body, None)
    return held


def record_file(
    kind: str, name: str, fingerprint: bytes | Callable[[], bytes], directory: Path | None = None
) -> store.RecordFile:
    """The store file ``<kind>-<name>.cache`` (see :class:`lensaudit.store.RecordFile`)
    in :func:`cache_dir` by default, bounded by :data:`MAX_CACHE_FILES` and
    :data:`MAX_CACHE_BYTES`."""
    return store.RecordFile(
        directory or cache_dir(),
        kind,
        name,
        fingerprint,
        max_files=MAX_CACHE_FILES,
        max_bytes=MAX_CACHE_BYTES,
    )


def _set_name(paths: list[Path]) -> str:
    """The name of the store file of a set of files."""
    # os.fsencode keeps file names that are not UTF-8 (surrogate escapes) as bytes.
    return blake2b(b"\0".join(sorted(map(os.fsencode, paths))), digest_size=8).hexdigest()


class ParseCache:
    """Parsed entries, metrics and rendered rows of files, keyed by absolute path,
    valid while the file's content hashes to the stored digest.

    Paths are absolute and resolved (``Path.resolve()``); digests are
    :func:`content_digest` of the bytes the caller read.
    """

    def __init__(self, paths: list[Path], directory: Path | None = None) -> None:
        """The cache of the set of files ``paths``, resolved (as
        :func:`lensaudit.loader.expand` gives them), in :func:`cache_dir` by default."""
        # path (os.fsencode of the absolute path) -> record
        self._records: dict[bytes, _Held] = {}
        self._seen: set[bytes] = set()
        self._changed = False
        self._file: store.RecordFile | None = None
        self.path: Path | None = None
        if not _PACKABLE:  # entries of a layout this module cannot store
            return
        try:
            # The fingerprint reads the package's sources: not before it is needed.
            self._file = record_file(_KIND, _set_name(paths), fingerprint, directory)
        except (OSError, RuntimeError, ValueError):
            return
        self.path = self._file.path
        self._records = _read_records(self._file)

    def knows(self, path: Path) -> bool:
        """Whether a record of ``path`` is held (so that hashing the file may pay)."""
        return os.fsencode(path) in self._records

    def _record(self, key: bytes, digest: bytes) -> _Record | None:
        """The record held for ``key`` if it is of content ``digest`` and intact."""
        held = self._records.get(key)
        if held is None or held.digest != digest:
            return None
        if held.record is None:
            assert held.seal is not None and held.body is not None
            record = store.unseal(held.seal, held.body)
            if not _valid_record(record) or record[0] != digest:  # type: ignore[index]
                del self._records[key]
                self._changed = True
                return None
            held.record = record  # type: ignore[assignment]
        return held.record

    def find(self, path: Path, digest: bytes, name: str) -> CachedFile | None:
        """What is stored for ``path`` if its content has ``digest``, else None.

        Rendered rows come only if they were rendered for the file name ``name``.
        """
        key = os.fsencode(path)
        self._seen.add(key)
        record = self._record(key, digest)
        if record is None:
            return None
        try:
            count = packed_count(record[1])
            metrics = record[3]
            if metrics is not None:
                check_metrics(metrics, count)
        except RECORD_ERRORS:
            return None
        same_name = record[4] == name
        return CachedFile(
            record[1],
            count,
            record[2],
            metrics,
            record[5] if same_name else {},
            record[6] if metrics is not None else None,
        )

    def store(
        self,
        path: Path,
        digest: bytes,
        packed: dict,
        error: str,
        metrics: dict[str, list] | None = None,
        name: str = "",
        rows: dict[str, str] | None = None,
        tally: tuple | None = None,
    ) -> None:
        """Keep what was made of ``path``'s content with ``digest`` (sealed when
        the cache is saved).

        ``rows`` (rendered rows by format, for file name ``name``) are added to
        those stored for the same content and name; metrics and tally kept
        from them where none are given.
        """
        if self._file is None:
            return
        key = os.fsencode(path)
        self._seen.add(key)
        try:
            packed_metrics = None if metrics is None else pack_metrics(metrics)
        except RECORD_ERRORS:
            packed_metrics = tally = None
        old = self._record(key, digest)
        kept_rows: dict[str, str] = {}
        if old is not None and old[4] == name:
            kept_rows = dict(old[5])
            if packed_metrics is None:
                packed_metrics, tally = old[3], old[6]
        kept_rows.update(rows or {})
        record = (digest, packed, error, packed_metrics, name, kept_rows, tally)
        if old != record:
            self._records[key] = _Held(digest, None, None, record)
            self._changed = True

    def store_sealed(self, path: Path, part_seal: bytes, body: bytes, record: _Record) -> None:
        """Keep a record sealed where it was made (see :func:`sealed_record`):
        ``body`` is its bytes, ``record`` what they hold."""
        if self._file is None:
            return
        key = os.fsencode(path)
        self._seen.add(key)
        self._records[key] = _Held(record[0], part_seal, body, record)
        self._changed = True

    def forget(self, path: Path) -> None:
        """Drop the record of ``path`` (a file that could not be read)."""
        if self._records.pop(os.fsencode(path), None) is not None:
            self._changed = True

    def get(self, path: Path, data: bytes, name: str) -> tuple[list[DistortionEntry], str] | None:
        """Entries and file error of the file at ``path`` whose bytes are ``data``,
        reported as ``name``; None if that content was not stored."""
        found = self.find(path, content_digest(data), name)
        if found is None:
            return None
        try:
            return unpack_entries(found.packed, name), found.error
        except RECORD_ERRORS:
            return None

    def put(self, path: Path, data: bytes, entries: list[DistortionEntry], error: str) -> None:
        """Store the entries and file error parsed from ``data``, the bytes of ``path``."""
        try:
            packed = pack_entries(entries)
        except RECORD_ERRORS:  # entries that cannot be stored are parsed every time
            self.forget(path)
            return
        self.store(path, content_digest(data), packed, error)

    def save(self) -> None:
        """Write the cache if anything changed, then evict; silently skipped when not possible.

        Files not seen in this run (removed from the database) are dropped.
        Records already sealed (read from the cache file, or sealed by a
        worker) are written as they are.
        """
        stale = self._records.keys() - self._seen
        if self._file is None or not (self._changed or stale):
            return
        head = []
        parts = []
        try:
            for key, held in self._records.items():
                if key not in self._seen:
                    continue
                if held.seal is None or held.body is None:
                    held.seal, held.body = store.sealed(held.record)
                head.append((key, held.digest))
                parts.append((held.seal, held.body))
            self._file.write_parts(head, parts)
        except (OSError, ValueError):
            pass
